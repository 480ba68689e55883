"""light.sun() and light.sun_residual() (issue 24): a synthetic disc measured
against what the map holds, residual + disc against the map's irradiance, no sun
where there is none, the frames, rotate and scale, the CLI's JSON, a real map."""

import json
import pathlib
import subprocess

import numpy as np
import pytest

import envlight

ROOT = pathlib.Path(__file__).resolve().parents[2]
ENVMAPS = ROOT.parent / "shared" / "envmaps"
LUMA = np.array([0.212671, 0.715160, 0.072169])


def lat_long(h, w):
    """Texel centre directions (H, W, 3) and solid angles (H, 1) of a lat-long map."""
    theta = np.pi * (np.arange(h) + 0.5) / h
    phi = 2 * np.pi * (np.arange(w) + 0.5) / w
    d = np.stack(
        [
            np.sin(theta)[:, None] * np.cos(phi)[None, :],
            np.sin(theta)[:, None] * np.sin(phi)[None, :],
            np.repeat(np.cos(theta)[:, None], w, axis=1),
        ],
        axis=-1,
    )
    edges = np.pi * np.arange(h + 1) / h
    d_omega = (2 * np.pi / w) * (np.cos(edges[:-1]) - np.cos(edges[1:]))
    return d, d_omega[:, None]


def direction(elevation_deg, azimuth_deg):
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def disc_map(h, w, centre, radius_deg, power=1.5, k=8):
    """A blue sky with a uniform disc of luminance integral `power`, each texel's
    coverage supersampled k×k (solid-angle weighted). Returns the map (float32) and
    the disc's irradiance at normal incidence as the map holds it (RGB)."""
    d, d_omega = lat_long(h, w)
    sky = np.empty((h, w, 3))
    z = d[..., 2]
    t = np.clip((z + 0.1) / 0.2, 0, 1)
    t = t * t * (3 - 2 * t)
    glow = 1 + 0.6 * (1 - np.abs(z))
    sky[...] = np.array([0.12, 0.10, 0.08]) + t[..., None] * (
        glow[..., None] * np.array([0.35, 0.5, 0.9]) - np.array([0.12, 0.10, 0.08])
    )
    r = np.radians(radius_deg)
    omega = 2 * np.pi * (1 - np.cos(r))
    colour = np.array([1.0, 0.93, 0.8])
    sun = colour * power / (colour @ LUMA * omega)
    # Coverage of the texels whose centre is within r plus a texel of the centre.
    near = np.argwhere(np.arccos(np.clip(d @ centre, -1, 1)) < r + 1.5 * np.pi / h)
    off = (np.arange(k) + 0.5) / k
    coverage = np.zeros((h, w))
    for y, x in near:
        th = np.pi * (y + off) / h
        ph = 2 * np.pi * (x + off) / w
        sub = np.stack(
            [
                np.sin(th)[:, None] * np.cos(ph)[None, :],
                np.sin(th)[:, None] * np.sin(ph)[None, :],
                np.repeat(np.cos(th)[:, None], k, axis=1),
            ],
            axis=-1,
        )
        weight = np.repeat(np.sin(th)[:, None], k, axis=1)
        coverage[y, x] = (weight * (sub @ centre >= np.cos(r))).sum() / weight.sum()
    rgb = sky + coverage[..., None] * sun
    held = (coverage * d_omega * np.maximum(d @ centre, 0))[..., None] * sun
    return rgb.astype(np.float32), held.sum(axis=(0, 1))


def irradiance(rgb, normals):
    """E(n) = Σ L max(0, n·ω) ΔΩ per channel, for each normal (lat-long texel sums)."""
    h, w, _ = rgb.shape
    d, d_omega = lat_long(h, w)
    rgb = rgb.astype(np.float64)
    return np.array([((np.maximum(d @ n, 0) * d_omega)[..., None] * rgb).sum(axis=(0, 1)) for n in normals])


def normals_around(c):
    """Six normals at 0°, 45°, 70°, 115°, 150°, 180° from c: none near grazing."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(c[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    a = np.cross(helper, c)
    a /= np.linalg.norm(a)
    b = np.cross(c, a)
    out = []
    for deg, t in [(0, a), (45, a), (70, b), (115, a), (150, b), (180, a)]:
        s, co = np.sin(np.radians(deg)), np.cos(np.radians(deg))
        out.append(co * c + s * t)
    return out


def residual_plus_disc_error(rgb, sun, residual, scale=1.0):
    c = np.array(sun["direction"], np.float64)
    normals = normals_around(c / np.linalg.norm(c))
    e_map = irradiance(rgb, normals)
    e_res = irradiance(residual, normals)
    e_disc = np.array([max(0.0, n @ c) for n in normals])[:, None] * np.array(sun["irradiance"]) / scale
    return np.abs((e_res + e_disc) / e_map - 1).max()


@pytest.fixture(scope="module")
def seam_disc():
    centre = direction(12.0, 0.2)  # straddles the φ = 0 seam
    rgb, held = disc_map(512, 1024, centre, 1.0)
    return rgb, held, centre


def test_a_known_disc_is_measured(seam_disc):
    rgb, held, centre = seam_disc
    light = envlight.EnvironmentLight.from_array(rgb)
    sun = light.sun()
    assert sun is not None
    assert set(sun) >= {
        "direction",
        "angular_radius_deg",
        "solid_angle_sr",
        "radiance",
        "irradiance",
        "power_fraction",
    }
    d = np.array(sun["direction"])
    error_deg = np.degrees(np.arccos(np.clip(d @ centre, -1, 1)))
    assert error_deg <= max(0.1, 180 / 512)
    omega = 2 * np.pi * (1 - np.cos(np.radians(1.0)))
    assert abs(sun["solid_angle_sr"] / omega - 1) <= 0.10
    assert np.abs(np.array(sun["irradiance"]) / held - 1).max() <= 0.03
    assert abs(sun["elevation_deg"] - 12.0) < 0.2
    assert sun["azimuth_deg"] < 0.5 or sun["azimuth_deg"] > 359.5
    assert 0 < sun["power_fraction"] < 1

    residual = light.sun_residual()
    assert residual.shape == rgb.shape and residual.dtype == np.float32
    assert np.isfinite(residual).all() and (residual >= 0).all()
    assert (residual != rgb).any(axis=2).sum() < 200  # only round the sun
    assert residual_plus_disc_error(rgb, sun, residual) <= 0.01
    # No disc left: near the sun the residual is no brighter than 3× the sky.
    dirs, _ = lat_long(512, 1024)
    angle = np.degrees(np.arccos(np.clip(dirs @ centre, -1, 1)))
    luminance = residual @ LUMA.astype(np.float32)
    ring = luminance[(angle > 3) & (angle < 6)].mean()
    assert luminance[angle < 2].max() <= 3 * ring


def test_frames_rotation_and_scale(seam_disc):
    rgb, _, _ = seam_disc
    base = envlight.EnvironmentLight.from_array(rgb).sun()
    turned = envlight.EnvironmentLight.from_array(rgb, rotate=90.0, scale=2.0)
    sun = turned.sun()
    x, y, z = base["direction"]
    assert np.allclose(sun["direction"], (-y, x, z), atol=1e-5)
    assert np.allclose(sun["irradiance"], 2 * np.array(base["irradiance"]), rtol=1e-9)
    assert np.allclose(sun["radiance"], 2 * np.array(base["radiance"]), rtol=1e-9)
    # The residual is in the map's own units, whatever the scale.
    assert np.array_equal(turned.sun_residual(), envlight.EnvironmentLight.from_array(rgb).sun_residual())
    y_up = envlight.EnvironmentLight.from_array(rgb, frame="y-up").sun()
    assert np.allclose(y_up["direction"], (y, z, -x), atol=1e-6)


@pytest.mark.parametrize(
    "name,rgb",
    [
        ("uniform", np.full((256, 512, 3), 0.8, np.float32)),
        ("black", np.zeros((64, 128, 3), np.float32)),
        ("1x1", np.full((1, 1, 3), 5.0, np.float32)),
        ("bright zenith", np.repeat(np.linspace(4, 1, 256, dtype=np.float32)[:, None, None], 512, axis=1).repeat(3, axis=2)),
    ],
)
def test_no_sun(name, rgb):
    light = envlight.EnvironmentLight.from_array(rgb)
    assert light.sun() is None, name
    assert np.array_equal(light.sun_residual(), rgb)


def write_pfm(path, rgb):
    h, w, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())


def read_pfm(path):
    data = pathlib.Path(path).read_bytes()
    header, rest = data.split(b"\n", 3)[:3], data.split(b"\n", 3)[3]
    w, h = map(int, header[1].split())
    order = "<f4" if float(header[2]) < 0 else ">f4"
    return np.frombuffer(rest, order).reshape(h, w, 3)[::-1]


def test_the_cli_agrees(seam_disc, tmp_path, envlight_cli):
    rgb, _, _ = seam_disc
    path = tmp_path / "disc.pfm"
    write_pfm(path, rgb)
    out = tmp_path / "residual.pfm"
    run = subprocess.run(
        [envlight_cli, "sun", str(path), "--json", "--residual", str(out)],
        capture_output=True,
        text=True,
        check=True,
    )
    cli = json.loads(run.stdout)["sun"]
    sun = envlight.EnvironmentLight.from_array(rgb).sun()
    assert np.allclose(cli["direction"], sun["direction"], atol=1e-6)
    for key in ["angular_radius_deg", "solid_angle_sr", "power_fraction"]:
        assert cli[key] == pytest.approx(sun[key], rel=1e-9)
    assert np.allclose(cli["irradiance"], sun["irradiance"], rtol=1e-9)
    assert np.array_equal(read_pfm(out), envlight.EnvironmentLight.from_array(rgb).sun_residual())


def test_real_map_sunrise():
    path = ENVMAPS / "sunrise.exr"
    if not path.is_file():
        pytest.skip(f"{path} not found (the real maps are optional)")
    light = envlight.EnvironmentLight(str(path))
    sun = light.sun()
    assert sun is not None and abs(sun["elevation_deg"] - 7.9) < 0.5
    residual = light.sun_residual()
    # The map's own texels: a light that emits nothing (scale 0) has no sun, so its
    # residual is the image unchanged.
    dark = envlight.EnvironmentLight(str(path), scale=0.0)
    assert dark.sun() is None
    original = dark.sun_residual()
    changed = (residual != original).any(axis=2).sum()
    assert 0 < changed < 1000
    assert residual_plus_disc_error(original, sun, residual) <= 0.01
