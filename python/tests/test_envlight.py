"""The Python package against its contract: shapes and dtypes, pdf(sample)
consistency, the Rust CLI's numbers on the same inputs, from_array against a file,
the frames, every error path, and threads."""

import os
import pathlib
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import envlight
from _maps import sky

ROOT = pathlib.Path(__file__).resolve().parents[2]
ENVMAPS = ROOT.parent / "shared" / "envmaps"


def write_pfm(path, rgb):
    """A colour PFM (little-endian, rows stored bottom to top)."""
    h, w, _ = rgb.shape
    with open(path, "wb") as f:
        f.write(f"PF\n{w} {h}\n-1.0\n".encode())
        f.write(np.ascontiguousarray(rgb[::-1], dtype="<f4").tobytes())


def uniform_u(n, seed=0):
    return np.random.default_rng(seed).random((n, 2), dtype=np.float32)


def unit(v):
    v = np.asarray(v, np.float32)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@pytest.fixture(scope="module")
def light():
    return envlight.EnvironmentLight.from_array(sky())


def test_shapes_dtypes_and_properties(light):
    d, p, l = light.sample(uniform_u(1000))
    assert d.shape == (1000, 3) and p.shape == (1000,) and l.shape == (1000, 3)
    assert d.dtype == p.dtype == l.dtype == np.float32
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-5)
    assert (p > 0).all() and np.isfinite(l).all()
    assert light.width == 64 and light.height == 32
    assert len(light.integral_rgb) == 3 and light.integral_luminance > 0
    assert 0 < light.efficiency <= 1
    assert light.sampling_bytes > 0 and light.frame == "z-up"
    assert np.isclose(np.linalg.norm(light.brightest_direction), 1.0, atol=1e-5)
    assert "EnvironmentLight(64x32" in repr(light)
    assert light.pdf(np.zeros((0, 3), np.float32)).shape == (0,)


def test_pdf_of_samples_matches_and_radiance_is_the_maps(light):
    d, p, l = light.sample(uniform_u(20000, 3))
    assert np.allclose(light.pdf(d), p, rtol=1e-3)
    assert np.allclose(light.radiance(d), l, rtol=1e-3, atol=1e-6)
    # invert() maps the samples back to the u that drew them.
    back = light.invert(d)
    assert back.shape == (20000, 2)
    assert np.allclose(back, uniform_u(20000, 3), atol=1e-3)


def test_monte_carlo_integral(light):
    # E[Y/p] = ∫Y dω, within 5 standard errors.
    d, p, l = light.sample(uniform_u(200000, 5))
    y = l @ np.array([0.212671, 0.715160, 0.072169], np.float32)
    w = y / p
    assert abs(w.mean() - light.integral_luminance) < 5 * w.std() / np.sqrt(len(w))


def test_non_contiguous_inputs_are_accepted(light):
    u = np.asfortranarray(uniform_u(100))
    d, p, _ = light.sample(u)
    d2, p2, _ = light.sample(np.ascontiguousarray(u))
    assert np.array_equal(d, d2) and np.array_equal(p, p2)
    assert np.array_equal(light.pdf(d[::2]), light.pdf(np.ascontiguousarray(d[::2])))


def test_from_array_equals_the_same_texels_from_a_file(tmp_path):
    rgb = sky()
    path = tmp_path / "sky.pfm"
    write_pfm(path, rgb)
    a = envlight.EnvironmentLight.from_array(rgb)
    b = envlight.EnvironmentLight(path)
    c = envlight.EnvironmentLight(str(path))
    u = uniform_u(5000, 9)
    for x in (b, c):
        for got, want in zip(x.sample(u), a.sample(u)):
            assert np.array_equal(got, want)
        assert x.integral_rgb == a.integral_rgb



def test_equal_to_the_rust_cli(tmp_path, envlight_cli):
    cli = envlight_cli
    rgb = sky()
    path = tmp_path / "sky.pfm"
    write_pfm(path, rgb)
    light = envlight.EnvironmentLight(path, rotate=30.0, scale=2.0)
    d, p, l = light.sample(uniform_u(500, 4))
    dirs = tmp_path / "dirs.csv"
    np.savetxt(dirs, d, delimiter=",", header="x,y,z", comments="", fmt="%.9g")
    out = subprocess.run(
        [cli, "eval", str(path), "--rotate", "30", "--scale", "2", "--dirs", str(dirs)],
        check=True, capture_output=True, text=True,
    ).stdout
    rows = np.loadtxt(out.splitlines()[1:], delimiter=",", dtype=np.float64)
    # The CLI normalises the directions as written (9 digits): same texels, same pdf.
    assert np.allclose(rows[:, 3], p, rtol=1e-5)
    assert np.allclose(rows[:, 4:7], l, rtol=1e-4, atol=1e-6)
    # And the pdf of the directions it read, bit for bit.
    assert np.array_equal(light.pdf(rows[:, :3].astype(np.float32)), rows[:, 3].astype(np.float32))


def test_frames():
    rgb = sky()
    z = envlight.EnvironmentLight.from_array(rgb)
    y = envlight.EnvironmentLight.from_array(rgb, frame="y-up")
    assert y.frame == "y-up"
    u = uniform_u(2000, 2)
    dz, pz, lz = z.sample(u)
    dy, py_, ly = y.sample(u)
    # y-up is (y, z, -x) of z-up; the pdf per steradian is the same number.
    assert np.array_equal(dy, np.stack([dz[:, 1], dz[:, 2], -dz[:, 0]], axis=1))
    assert np.array_equal(py_, pz) and np.array_equal(ly, lz)
    assert np.array_equal(y.pdf(dy), z.pdf(dz))
    # The map's centre looks along +z in y-up (Mitsuba's envmap), -x in z-up.
    centre = np.array([[0.5, 0.5]], np.float32)
    uniform = envlight.EnvironmentLight.from_array(np.ones((8, 16, 3), np.float32), frame="y-up")
    inv = uniform.invert(np.array([[0.0, 0.0, 1.0]], np.float32))
    assert np.allclose(inv, centre, atol=1e-6)
    assert np.allclose(y.brightest_direction, [z.brightest_direction[1], z.brightest_direction[2], -z.brightest_direction[0]])


def test_product_sampling():
    light = envlight.EnvironmentLight.from_array(sky())
    n = 4000
    normals = unit(np.random.default_rng(1).normal(size=(n, 3)))
    d, p, l = light.sample_product(normals, uniform_u(n, 6))
    assert d.shape == (n, 3) and p.shape == (n,) and l.shape == (n, 3)
    ok = p > 0
    assert ok.mean() > 0.99
    assert np.allclose(light.pdf_product(normals[ok], d[ok]), p[ok], rtol=1e-3)
    # Nearly every sample lies above its surface.
    assert (np.sum(d[ok] * normals[ok], axis=1) > -1e-3).mean() > 0.95
    # A zero normal samples nothing.
    d0, p0, _ = light.sample_product(np.zeros((3, 3), np.float32), uniform_u(3))
    assert (p0 == 0).all() and (d0 == 0).all()
    # The glossy form: samples gather around the mirror direction.
    up = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (n, 1))
    wo = np.tile(unit([[0.6, 0.0, 0.8]]), (n, 1))
    d, p, _ = light.sample_product(up, uniform_u(n, 7), outgoing=wo, roughness=0.05)
    ok = p > 0
    assert np.allclose(light.pdf_product(up[ok], d[ok], outgoing=wo[ok], roughness=0.05), p[ok], rtol=1e-3)
    mirror = np.array([-0.6, 0.0, 0.8], np.float32)
    diffuse, _, _ = light.sample_product(up, uniform_u(n, 7))
    # A quarter of the glossy samples lie within 18° of the mirror direction (the
    # rest mostly on the sun, 28° from it), against about 1% of the cosine's.
    assert np.mean(d[ok] @ mirror > 0.95) > 10 * np.mean(diffuse @ mirror > 0.95)
    with pytest.raises(ValueError, match="together"):
        light.sample_product(up, uniform_u(n), roughness=0.1)
    with pytest.raises(ValueError, match="roughness"):
        light.sample_product(up, uniform_u(n), outgoing=wo, roughness=0.0)


@pytest.mark.parametrize("density", ["piecewise-constant", "piecewise-bilinear"])
def test_product_tables(density):
    """product_tables(): the documented arrays, with shapes that fit each other, alias
    tables over fixed-point widths (each lit patch's cells and each non-empty node's
    patches sum to 2**32 - 1) and the bright patches where bright_of_patch says."""
    t = envlight.EnvironmentLight.from_array(sky(), density=density).product_tables()
    w, h = t["image"]
    cw, ch = t["cells"]
    assert t["density"] == density
    assert (cw, ch) == ((w, h) if density == "piecewise-constant" else (w + 1, h + 1))
    pw, ph = t["patches"]
    nodes = (t["grid"] + 1) ** 2
    assert t["cell_widths"].shape == (ch, cw) and t["cell_slots"].shape == (cw * ch, 2)
    assert t["spans"].shape == (pw * ph, 5) and t["table_widths"].shape == (pw * ph, nodes)
    assert t["table_slots"].shape == (nodes * pw * ph, 2) and t["node_totals"].shape == (nodes,)
    assert t["col_patch"].shape == (cw,) and t["row_patch"].shape == (ch,)
    one = 2**32 - 1
    widths = t["cell_widths"].astype(np.uint64)
    for x0, y0, cols, rows, _ in t["spans"]:
        assert int(widths[y0 : y0 + rows, x0 : x0 + cols].sum()) in (0, one)
    sums = t["table_widths"].astype(np.uint64).sum(axis=0)
    assert set(np.unique(sums).tolist()) <= {0, one}
    assert ((sums == 0) == t["node_empty"].astype(bool)).all()
    bright = t["bright"]
    assert bright.shape[1] == 20 and len(bright) >= 1  # the sky's sun
    for b, row in enumerate(bright):
        assert t["bright_of_patch"][int(row[0])] == b
    assert (t["bright_of_patch"] != 255).sum() == len(bright)
    if density == "piecewise-bilinear":
        assert t["node_values"].shape == (h + 2, w + 2) and t["v_nodes"].shape == (h + 2,)


def test_verify_passes():
    light = envlight.EnvironmentLight.from_array(sky())
    rows = light.verify(samples=20000)
    assert [r["check"] for r in rows][:4] == ["normalisation", "pdf consistency", "invert", "chi-square"]
    assert all(r["result"] in ("pass", "info") for r in rows), rows
    rows = light.verify(samples=20000, normal=(0.0, 0.6, 0.8))
    assert all(r["result"] in ("pass", "info", "skip") for r in rows), rows
    black = envlight.EnvironmentLight.from_array(np.zeros((4, 8, 3), np.float32))
    assert all(r["result"] == "skip" for r in black.verify())


def test_options():
    rgb = sky()
    for kw in (
        dict(sampler="alias"),
        dict(sampler="hierarchical", mapping="equal-area"),
        dict(density="piecewise-bilinear"),
        dict(lookup="nearest", rotate=45.0, scale=3.0),
    ):
        light = envlight.EnvironmentLight.from_array(rgb, **kw)
        d, p, _ = light.sample(uniform_u(1000))
        assert np.allclose(light.pdf(d), p, rtol=1e-3), kw
    reduced = envlight.EnvironmentLight.from_array(rgb, table_width=rgb.shape[1] // 4)
    assert reduced.table_size == (rgb.shape[1] // 4, rgb.shape[0] // 4)
    full = envlight.EnvironmentLight.from_array(rgb, density="piecewise-constant")
    assert full.table_size == (rgb.shape[1], rgb.shape[0]) and full.full_table_efficiency is None
    assert reduced.efficiency < reduced.full_table_efficiency
    assert abs(reduced.full_table_efficiency / full.efficiency - 1) < 1e-6
    d, p, _ = reduced.sample(uniform_u(1000))
    assert np.allclose(reduced.pdf(d), p, rtol=1e-3)
    with pytest.raises(ValueError, match="widths that do are"):
        envlight.EnvironmentLight.from_array(rgb, table_width=rgb.shape[1] - 1)
    with pytest.raises(ValueError, match="alias sampler has no inverse"):
        envlight.EnvironmentLight.from_array(rgb, sampler="alias").invert(np.zeros((1, 3), np.float32))


def test_default_density_follows_the_sampler():
    rgb = sky()
    default = envlight.EnvironmentLight.from_array
    assert "piecewise-bilinear" in repr(default(rgb))
    assert "piecewise-constant" in repr(default(rgb, sampler="alias"))
    assert "piecewise-constant" in repr(default(rgb, sampler="hierarchical"))
    assert "piecewise-constant" in repr(default(rgb, table_width=rgb.shape[1] // 2))
    assert "piecewise-constant" in repr(default(rgb, density="piecewise-constant"))
    with pytest.raises(ValueError, match="inversion only"):
        default(rgb, sampler="alias", density="piecewise-bilinear")


def test_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="missing.exr"):
        envlight.EnvironmentLight(tmp_path / "missing.exr")
    garbage = tmp_path / "garbage.hdr"
    garbage.write_bytes(b"not an image at all")
    with pytest.raises(OSError, match="garbage.hdr"):
        envlight.EnvironmentLight(garbage)
    rgb = sky()
    rgb[3, 7, 1] = np.nan
    with pytest.raises(ValueError, match=r"texel \(7, 3\)"):
        envlight.EnvironmentLight.from_array(rgb)
    nan_file = tmp_path / "nan.pfm"
    write_pfm(nan_file, rgb)
    with pytest.raises(ValueError, match=r"nan.pfm.*\(7, 3\)"):
        envlight.EnvironmentLight(nan_file)
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        envlight.EnvironmentLight.from_array(np.ones((4, 8, 4), np.float32))
    with pytest.raises(TypeError, match="float32"):
        envlight.EnvironmentLight.from_array(np.ones((4, 8, 3), np.float64))
    light = envlight.EnvironmentLight.from_array(sky())
    with pytest.raises(ValueError, match=r"\(N, 2\)"):
        light.sample(np.ones((5, 3), np.float32))
    with pytest.raises(TypeError):
        light.sample(np.ones((5, 2), np.float64))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        light.pdf(np.ones((5, 2), np.float32))
    with pytest.raises(ValueError, match="same length"):
        light.pdf_product(np.ones((5, 3), np.float32), np.ones((4, 3), np.float32))
    for kw in (dict(sampler="bogus"), dict(frame="x-up"), dict(scale=-1.0), dict(rotate=float("nan"))):
        with pytest.raises(ValueError):
            envlight.EnvironmentLight.from_array(sky(), **kw)


HOSTILE = pathlib.Path(__file__).resolve().parents[2] / "fuzz/regressions/load/exr-chunk-size-1.9GB.exr"


@pytest.mark.skipif(sys.platform != "linux", reason="address-space limits are set with setrlimit on Linux")
def test_a_hostile_file_is_an_exception_under_a_512_mib_address_space_limit():
    # A 612-byte OpenEXR file (a fuzzing find) once made the loader reserve 1.9 GB,
    # which under an address-space limit aborted the interpreter: now an exception
    # naming the file, in a child process limited to 512 MiB.
    import resource

    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (512 << 20, 512 << 20))

    script = (
        "import sys, envlight\n"
        "try:\n"
        "    envlight.EnvironmentLight(sys.argv[1])\n"
        "except OSError as error:\n"
        "    print(type(error).__name__, error)\n"
        "    sys.exit(3)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script, str(HOSTILE)],
        capture_output=True,
        text=True,
        preexec_fn=limit,
        env={**os.environ, "OPENBLAS_NUM_THREADS": "1"},
    )
    assert out.returncode == 3, (out.returncode, out.stdout, out.stderr)
    assert HOSTILE.name in out.stdout, out.stdout


def test_threads_give_identical_results(light):
    u = uniform_u(100000, 8)
    want = light.sample(u)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: light.sample(u), range(8)))
    for got in results:
        for g, w in zip(got, want):
            assert np.array_equal(g, w)


@pytest.mark.skipif(not (ENVMAPS / "sunrise.exr").exists(), reason="../shared/envmaps/sunrise.exr not found")
def test_real_map():
    light = envlight.EnvironmentLight(ENVMAPS / "sunrise.exr")
    d, p, _ = light.sample(uniform_u(10000))
    assert np.allclose(light.pdf(d), p, rtol=1e-3)
    # The default bilinear density follows the bilinear lookup: efficiency 1;
    # the piecewise-constant density's is lower on this map (0.79).
    assert light.efficiency > 0.999
    constant = envlight.EnvironmentLight(ENVMAPS / "sunrise.exr", density="piecewise-constant")
    assert 0.7 < constant.efficiency < 0.9


def test_pooled_outputs_are_independent_and_recycled():
    """Big batch outputs come from recycled buffers: a live array is never
    overwritten by a later call, a recycled buffer gives the same values as a
    fresh one, missing samples are zeros in it, and release_buffers frees them."""
    rgb = np.ones((32, 64, 3), np.float32)
    rgb[20, 10] = 500.0
    light = envlight.EnvironmentLight.from_array(rgb)
    black = envlight.EnvironmentLight.from_array(np.zeros((32, 64, 3), np.float32))
    n = 1 << 17  # above the pooled size for every output
    rng = np.random.default_rng(3)
    u1 = rng.random((n, 2), dtype=np.float32)
    u2 = rng.random((n, 2), dtype=np.float32)
    envlight.release_buffers()
    d1, p1, l1 = light.sample(u1)
    keep = (d1.copy(), p1.copy(), l1.copy())
    d2, p2, l2 = light.sample(u2)  # must not reuse the live arrays' memory
    for live, saved in zip((d1, p1, l1), keep):
        np.testing.assert_array_equal(live, saved)
    pdf1 = light.pdf(d1).copy()
    rad1 = light.radiance(d1).copy()
    del d1, p1, l1, d2, p2, l2
    # Recycled buffers now, holding the previous calls' values: every output
    # must be rewritten.
    d3, p3, l3 = light.sample(u1)
    for new, saved in zip((d3, p3, l3), keep):
        np.testing.assert_array_equal(new, saved)
    np.testing.assert_array_equal(light.pdf(d3), pdf1)
    np.testing.assert_array_equal(light.radiance(d3), rad1)
    del d3, p3, l3
    # A black map samples nothing: zeros, not the recycled values.
    d4, p4, l4 = black.sample(u1)
    assert not np.any(d4) and not np.any(p4) and not np.any(l4)
    del d4, p4, l4
    assert envlight.release_buffers() > 0
    assert envlight.release_buffers() == 0


def test_option_names_are_the_librarys():
    assert envlight.SAMPLERS == ("inversion", "alias", "hierarchical")
    assert envlight.DENSITIES == ("piecewise-constant", "piecewise-bilinear")
    assert envlight.MAPPINGS == ("equirectangular", "equal-area")
    assert envlight.LOOKUPS == ("nearest", "bilinear", "node")
    assert envlight.RADIANCE_FORMATS == ("f32", "f16")
    rgb = sky()
    # An unknown name is a ValueError naming the keyword and every accepted name.
    for keyword, names in (
        ("sampler", envlight.SAMPLERS),
        ("density", envlight.DENSITIES),
        ("mapping", envlight.MAPPINGS),
        ("input_mapping", envlight.MAPPINGS),
        ("lookup", envlight.LOOKUPS),
    ):
        with pytest.raises(ValueError, match=f"^{keyword} must be one of") as e:
            envlight.EnvironmentLight.from_array(rgb, **{keyword: "bogus"})
        assert all(name in str(e.value) for name in names), e.value
    with pytest.raises(ValueError, match="^radiance must be one of f32, f16"):
        envlight.EnvironmentLight.from_array(rgb).gpu_tables(radiance="f8")
    # The library's validation, naming the keyword.
    for kw, keyword in (
        (dict(scale=-1.0), "scale"),
        (dict(rotate=float("inf")), "rotate"),
        (dict(sampler="hierarchical", density="piecewise-bilinear"), "density"),
        (dict(lookup="node", mapping="equal-area"), "lookup"),
        (dict(input_mapping="equal-area", mapping="equirectangular"), "input_mapping"),
        (dict(mapping="equal-area", equal_area_size=0), "equal_area_size"),
        (dict(table_width=0), "table_width"),
    ):
        with pytest.raises(ValueError, match=f"^{keyword}: "):
            envlight.EnvironmentLight.from_array(rgb, **kw)


def test_input_mapping_and_equal_area_size():
    rgb = sky()
    h, w, _ = rgb.shape
    # A lat-long map resampled to a square of the size asked for, or about its
    # texel count.
    sized = envlight.EnvironmentLight.from_array(rgb, mapping="equal-area", equal_area_size=24)
    assert (sized.width, sized.height) == (24, 24)
    default = envlight.EnvironmentLight.from_array(rgb, mapping="equal-area")
    assert abs(default.width / np.sqrt(w * h) - 1) < 0.05 and default.width == default.height
    # A square given as an equal-area input is lit as it is: mapping follows
    # input_mapping when left out.
    square = np.ascontiguousarray(rgb[:24, :24])
    given = envlight.EnvironmentLight.from_array(square, input_mapping="equal-area")
    assert (given.width, given.height) == (24, 24) and "equal-area" in repr(given)
    d, p, _ = given.sample(uniform_u(1000))
    assert np.allclose(given.pdf(d), p, rtol=1e-3)
    # The equal-area size does not change a light that resamples nothing.
    plain = envlight.EnvironmentLight.from_array(rgb)
    assert envlight.EnvironmentLight.from_array(rgb, equal_area_size=24).width == plain.width
    # A non-square equal-area input is refused, naming its size.
    with pytest.raises(ValueError, match=f"square.*{w}x{h}"):
        envlight.EnvironmentLight.from_array(rgb, input_mapping="equal-area")


def test_mis_compensation_samples_only_above_the_mean():
    rgb = sky()
    plain = envlight.EnvironmentLight.from_array(rgb)
    compensated = envlight.EnvironmentLight.from_array(rgb, mis_compensation=True)
    d, p, _ = compensated.sample(uniform_u(4000))
    lit = p > 0
    assert lit.all() and np.allclose(compensated.pdf(d), p, rtol=1e-3)
    # Uniform directions: some land where the map is at or below its mean, which
    # the compensated density leaves to BSDF sampling, and the plain one does not.
    rng = np.random.default_rng(4)
    v = rng.normal(size=(4000, 3)).astype(np.float32)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    assert (compensated.pdf(v) == 0).mean() > 0.2
    assert (plain.pdf(v) == 0).mean() < 0.01
    # The radiance and its integral do not change, only the density.
    assert np.array_equal(compensated.radiance(v), plain.radiance(v))
    assert compensated.integral_rgb == plain.integral_rgb
