"""Portal sampling from Python (issue 25): shapes, every sample through a portal,
pdf(sample) consistency, pdf 0 elsewhere, an unbiased estimate, the CLI's numbers,
and the errors."""

import subprocess

import numpy as np
import pytest

import envlight

WINDOW = [[4, 1, 0.8], [4, 2.2, 0.8], [4, 2.2, 1.9], [4, 1, 1.9]]
SKYLIGHT = [[1.2, 1, 2.5], [2.4, 1, 2.5], [2.4, 2, 2.5], [1.2, 2, 2.5]]
PORTALS = np.array([WINDOW, SKYLIGHT], np.float32)


def sky(h=32, w=64):
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    rgb = np.empty((h, w, 3), np.float32)
    rgb[...] = (0.3 + np.cos(np.pi * v / 2))[:, None, None] * np.array([0.5, 0.7, 1.0], np.float32)
    rgb *= (1.0 + 0.5 * np.cos(2 * np.pi * u))[None, :, None]
    rgb[5:7, 40:42, :] = 200.0
    return rgb


def crosses(p, d, quad):
    """Whether rays p + t d (t > 0) cross the axis-aligned rectangle quad."""
    quad = np.asarray(quad, np.float64)
    axis = [a for a in range(3) if np.all(quad[:, a] == quad[0, a])][0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (quad[0, axis] - p[:, axis]) / d[:, axis]
    hit = p + t[:, None] * d
    ok = t > 0
    for a in range(3):
        if a != axis:
            ok &= (hit[:, a] >= quad[:, a].min() - 1e-5) & (hit[:, a] <= quad[:, a].max() + 1e-5)
    return ok


def test_samples_pass_through_and_pdf_agrees():
    light = envlight.EnvironmentLight.from_array(sky())
    n = 20000
    rng = np.random.default_rng(1)
    points = np.tile(np.array([[2.0, 1.5, 1.2]], np.float32), (n, 1))
    points[: n // 2] = [3.7, 1.5, 1.2]
    u = rng.random((n, 2), dtype=np.float32)
    d, pdf, rgb = light.sample_portal(points, u, PORTALS)
    assert d.shape == (n, 3) and pdf.shape == (n,) and rgb.shape == (n, 3)
    assert d.dtype == np.float32 and pdf.dtype == np.float32
    assert np.all(pdf > 0)
    p64, d64 = points.astype(np.float64), d.astype(np.float64)
    assert np.all(crosses(p64, d64, WINDOW) | crosses(p64, d64, SKYLIGHT))
    np.testing.assert_array_equal(light.pdf_portal(points, d, PORTALS), pdf)
    # Through no portal: pdf 0.
    down = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (n, 1))
    assert np.all(light.pdf_portal(points, down, PORTALS) == 0)
    # E[Y/p] equals the luminance integrated over the portals, estimated by
    # uniform sphere sampling masked by the portals (a looser, independent check).
    y = rgb @ np.array([0.212671, 0.715160, 0.072169], np.float32)
    centre = slice(n // 2, n)
    est = np.mean(y[centre] / pdf[centre])
    m = 400000
    z = rng.random(m) * 2 - 1
    phi = rng.random(m) * 2 * np.pi
    r = np.sqrt(1 - z * z)
    w = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1).astype(np.float32)
    pc = np.tile(np.array([[2.0, 1.5, 1.2]]), (m, 1))
    mask = crosses(pc, w.astype(np.float64), WINDOW) | crosses(pc, w.astype(np.float64), SKYLIGHT)
    yl = light.radiance(w) @ np.array([0.212671, 0.715160, 0.072169], np.float32)
    ref = 4 * np.pi * np.mean(yl * mask)
    assert abs(est / ref - 1) < 0.03, (est, ref)


def test_equal_to_the_rust_cli(tmp_path, envlight_cli):
    rgb = sky()
    path = tmp_path / "sky.pfm"
    h, w, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())
    quads = [";".join(",".join(str(c) for c in p) for p in q) for q in (WINDOW, SKYLIGHT)]
    out = subprocess.run(
        [envlight_cli, "sample", str(path), "-n", "500", "--portal", quads[0], "--portal", quads[1], "--at", "2,1.5,1.2"],
        check=True,
        capture_output=True,
        text=True,
    ).stdout
    rows = np.array([[float(x) for x in line.split(",")] for line in out.splitlines()[1:]], np.float32)
    light = envlight.EnvironmentLight(str(path))
    points = np.tile(np.array([[2.0, 1.5, 1.2]], np.float32), (len(rows), 1))
    pdf = light.pdf_portal(points, np.ascontiguousarray(rows[:, :3]), PORTALS)
    np.testing.assert_allclose(pdf, rows[:, 3], rtol=1e-6)


def test_errors():
    light = envlight.EnvironmentLight.from_array(sky())
    p = np.zeros((2, 3), np.float32)
    u = np.zeros((2, 2), np.float32)
    with pytest.raises(ValueError, match="shape"):
        light.sample_portal(p, u, np.zeros((1, 3, 3), np.float32))
    bent = np.array([WINDOW], np.float32)
    bent[0, 2, 0] = 4.5
    with pytest.raises(ValueError, match="not planar"):
        light.sample_portal(p, u, bent)
    with pytest.raises(ValueError, match="same length"):
        light.sample_portal(np.zeros((3, 3), np.float32), u, PORTALS)
    # A point that sees no portal: no samples, pdf 0.
    seen_from_nowhere = np.array([[4.0, 0.5, 2.5]] * 2, np.float32)
    d, pdf, _ = light.sample_portal(seen_from_nowhere, u + 0.5, PORTALS)
    assert np.all(pdf == 0) and np.all(d == 0)
