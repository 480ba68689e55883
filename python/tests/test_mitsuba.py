"""envlight.mitsuba: the emitter "envlight" inside Mitsuba 3.

- the Dr.Jit evaluation of the exported tables against the CPU library, row for row,
  with the GPU's tolerances (envlight-gpu's agreement.rs), in scalar_rgb and
  llvm_ad_rgb, and a deliberately wrong table rejected by the same check;
- the emitter's queries (sample_direction, pdf_direction, eval, eval_direction)
  against the CPU in Mitsuba's frame, with to_world;
- images: envlight against envmap in the path and direct integrators (image mean
  within 3 SE, at most 5% of 8x8 blocks beyond 4 SE), to_world included, and a
  radiance 3% too bright rejected by the same test;
- errors as Mitsuba users get them from mi.load_dict.

Skipped (one line in the summary) where Mitsuba cannot be imported; the LLVM tests
are skipped (one line) where Dr.Jit finds no LLVM (set DRJIT_LIBLLVM_PATH).
"""

import copy
import gc
import os
import pathlib

import _maps
import numpy as np
import pytest

mi = pytest.importorskip("mitsuba", reason="mitsuba is not installed: envlight.mitsuba not tested")
import drjit as dr  # noqa: E402

import envlight  # noqa: E402
import envlight.mitsuba  # noqa: E402
from envlight._drjit_product import TableProduct  # noqa: E402
from envlight._drjit_tables import MAPPING_EQUAL_AREA, MAPPING_EQUIRECT, TableLight  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
SUNRISE = ROOT.parent / "shared" / "envmaps" / "sunrise.exr"

# envlight-gpu/src/agreement.rs: the GPU's promise, which this port keeps.
ANGLE_TOLERANCE = 2e-4
RELATIVE_TOLERANCE = 2e-3
REQUIRED_FRACTION = 0.999


def llvm_available():
    try:
        mi.set_variant("llvm_ad_rgb")
        return True
    except Exception:
        return False


VARIANTS = [
    "scalar_rgb",
    pytest.param(
        "llvm_ad_rgb",
        marks=pytest.mark.skipif(
            not llvm_available(), reason="Dr.Jit finds no LLVM (set DRJIT_LIBLLVM_PATH): llvm_ad_rgb not tested"
        ),
    ),
]


@pytest.fixture(params=VARIANTS)
def variant(request):
    mi.set_variant(request.param)
    envlight.mitsuba.register()
    return request.param


def llvm():
    if not llvm_available():
        pytest.skip("Dr.Jit finds no LLVM (set DRJIT_LIBLLVM_PATH): llvm_ad_rgb not tested")
    mi.set_variant("llvm_ad_rgb")
    envlight.mitsuba.register()


def sky(h=32, w=64, seed=1):
    """A small map: a smooth sky, a bright sun, some black texels, noise."""
    return _maps.sky(h, w, seed, noise=True)


def columns(values):
    return np.stack([np.array(c, dtype=np.float64) for c in values], axis=1)


def angle(a, b):
    a = a / np.maximum(np.linalg.norm(a, axis=1, keepdims=True), 1e-300)
    b = b / np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-300)
    return 2 * np.arcsin(np.clip(np.linalg.norm(a - b, axis=1) / 2, 0, 1))


def relative(a, b):
    return np.abs(a - b) / np.maximum(np.abs(b), 1e-30)


def disagreeing(d, pdf, rgb, d_cpu, pdf_cpu, rgb_cpu):
    """Rows that do not agree as agreement.rs defines it: both "no sample" (pdf 0), or
    directions within ANGLE_TOLERANCE, pdf and radiance (relative to the row's
    largest channel) within RELATIVE_TOLERANCE."""
    none = (pdf == 0) & (pdf_cpu == 0)
    bad = (
        (angle(d, d_cpu) > ANGLE_TOLERANCE)
        | (relative(pdf, pdf_cpu) > RELATIVE_TOLERANCE)
        | (np.abs(rgb - rgb_cpu).max(1) / np.maximum(rgb_cpu.max(1), 1e-30) > RELATIVE_TOLERANCE)
    )
    return bad & ~none


def table_rows(tl, u, q):
    """(directions, pdf, radiance) of sample(u) and (pdf, radiance) at q, from the tables."""
    if tl.jit:
        d, pdf, rgb, _ = tl.sample(mi.Float(u[:, 0]), mi.Float(u[:, 1]))
        p, r = tl.eval(mi.Float(q[:, 0]), mi.Float(q[:, 1]), mi.Float(q[:, 2]))
        return columns(d), np.array(pdf, np.float64), columns(rgb), np.array(p, np.float64), columns(r)
    s = [tl.sample(float(a), float(b)) for a, b in u]
    e = [tl.eval(*map(float, x)) for x in q]
    return (np.array([x[0] for x in s]), np.array([x[1] for x in s]), np.array([x[2] for x in s]),
            np.array([x[0] for x in e]), np.array([x[1] for x in e]))


CONFIGS = [
    {},
    {"density": "piecewise-constant"},
    {"mapping": "equal-area"},
    {"mapping": "equal-area", "density": "piecewise-constant"},
    {"lookup": "nearest"},
    {"rotate": 37.0, "scale": 2.5},
    {"table_width": 16},
    {"lookup": "node", "density": "piecewise-constant"},
    {"lookup": "node", "density": "piecewise-constant", "rotate": 80.0},
    {"lookup": "node", "density": "piecewise-bilinear"},
    {"lookup": "node", "density": "piecewise-bilinear", "rotate": 80.0},
]


@pytest.mark.parametrize("options", CONFIGS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "default")
def test_tables_equal_the_cpu_row_for_row(variant, options):
    rgb = sky()
    if options.get("mapping") == "equal-area":
        rgb = rgb[:, :32].copy()
    light = envlight.EnvironmentLight.from_array(rgb, **options)
    tl = TableLight(light.gpu_tables(), mi)
    n = 20000 if tl.jit else 400
    rng = np.random.default_rng(7)
    u = rng.random((n, 2), dtype=np.float32)
    q = rng.normal(size=(n, 3)).astype(np.float32)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    d, pdf, l, p, r = table_rows(tl, u, q)
    d_cpu, pdf_cpu, l_cpu = (x.astype(np.float64) for x in light.sample(u))
    p_cpu, r_cpu = light.pdf(q).astype(np.float64), light.radiance(q).astype(np.float64)
    bad_sample = disagreeing(d, pdf, l, d_cpu, pdf_cpu, l_cpu)
    bad_eval = disagreeing(q, p, r, q, p_cpu, r_cpu)
    assert bad_sample.mean() <= 1 - REQUIRED_FRACTION, (bad_sample.sum(), n)
    assert bad_eval.mean() <= 1 - REQUIRED_FRACTION, (bad_eval.sum(), n)
    # pdf(sample) is the density where the direction landed, by construction.
    if tl.jit:
        again = np.array(tl.pdf(*(mi.Float(d[:, k]) for k in range(3))), np.float64)
        assert (relative(again, pdf)[pdf > 0] < 1e-5).all()


def test_a_wrong_table_is_rejected(variant):
    """The row-for-row check fails on tables of a slightly different light."""
    rgb = sky()
    light = envlight.EnvironmentLight.from_array(rgb)
    brighter = rgb.copy()
    brighter[5:7, 40:42, :] *= 1.05  # the sun 5% brighter: other pdfs move by ~2%
    tl = TableLight(envlight.EnvironmentLight.from_array(brighter).gpu_tables(), mi)
    rng = np.random.default_rng(3)
    n = 4000 if tl.jit else 300
    u = rng.random((n, 2), dtype=np.float32)
    q = rng.normal(size=(n, 3)).astype(np.float32)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    d, pdf, l, p, r = table_rows(tl, u, q)
    bad = disagreeing(q, p, r, q, light.pdf(q).astype(np.float64), light.radiance(q).astype(np.float64))
    assert bad.mean() > 0.5


# -- product sampling: the cosine product's tables ----------------------------------------

PRODUCT_CONFIGS = [
    {},
    {"density": "piecewise-constant"},
    {"mapping": "equal-area"},
    {"mapping": "equal-area", "density": "piecewise-constant"},
    {"rotate": 37.0},
    {"lookup": "node", "density": "piecewise-constant"},
    {"lookup": "node", "density": "piecewise-bilinear"},
    {"lookup": "node", "density": "piecewise-bilinear", "rotate": 80.0},
]


def normals_and_u(n, seed):
    rng = np.random.default_rng(seed)
    normals = rng.normal(size=(n, 3)).astype(np.float32)
    return normals, rng.random((n, 2), dtype=np.float32)


def product_rows(tp, normals, u, q):
    """(directions, pdf, radiance) of the product's sample(u) at `normals`, and its pdf of q."""
    if tp.jit:
        F = mi.Float
        n = [F(normals[:, k]) for k in range(3)]
        d, pdf, rgb, _ = tp.sample(*n, F(u[:, 0]), F(u[:, 1]))
        p = tp.pdf(*n, *(F(q[:, k]) for k in range(3)))
        return columns(d), np.array(pdf, np.float64), columns(rgb), np.array(p, np.float64)
    rows = [tp.sample(*map(float, n), float(a), float(b)) for n, (a, b) in zip(normals, u)]
    p = [tp.pdf(*map(float, n), *map(float, x)) for n, x in zip(normals, q)]
    return (np.array([r[0] for r in rows]), np.array([r[1] for r in rows]), np.array([r[2] for r in rows]),
            np.array(p, np.float64))


def product_port(light):
    tl = TableLight(light.gpu_tables(), mi)
    return TableProduct(light.product_tables(), tl, mi)


@pytest.mark.parametrize("options", PRODUCT_CONFIGS, ids=lambda o: ",".join(f"{k}={v}" for k, v in o.items()) or "default")
def test_product_tables_equal_the_cpu_row_for_row(variant, options):
    """Product samples (light x cos+ at random normals) and pdfs from the exported
    tables, row for row against the CPU library, with the GPU's tolerances; the pdf
    of a sampled direction is the sample's pdf."""
    rgb = sky()
    if options.get("mapping") == "equal-area":
        rgb = rgb[:, :32].copy()
    light = envlight.EnvironmentLight.from_array(rgb, **options)
    tp = product_port(light)
    n = 20000 if tp.jit else 300
    normals, u = normals_and_u(n, 17)
    normals[:5] = [[0, 0, 1], [0, 0, -1], [1e-12, 0, 0], [0, 0, 0], [3, -4, 0]]
    d_cpu, pdf_cpu, l_cpu = (x.astype(np.float64) for x in light.sample_product(normals, u))
    d, pdf, l, p = product_rows(tp, normals, u, d_cpu.astype(np.float32))
    bad = disagreeing(d, pdf, l, d_cpu, pdf_cpu, l_cpu)
    assert bad.mean() <= 1 - REQUIRED_FRACTION, (bad.sum(), n)
    assert (pdf_cpu > 0).mean() > 0.8 and pdf[3] == 0 and pdf_cpu[3] == 0
    # The pdf at the CPU's sampled directions, and at directions of no sample.
    p_cpu = light.pdf_product(normals, d_cpu.astype(np.float32)).astype(np.float64)
    assert (relative(p, p_cpu)[p_cpu > 0] > RELATIVE_TOLERANCE).mean() <= 1 - REQUIRED_FRACTION
    if tp.jit:
        F = mi.Float
        again = np.array(tp.pdf(*(F(normals[:, k]) for k in range(3)), *(F(d[:, k]) for k in range(3))), np.float64)
        assert (relative(again, pdf)[pdf > 0] < 1e-5).all()


@pytest.mark.parametrize("options", [{}, {"lookup": "node", "density": "piecewise-bilinear"},
                                     {"density": "piecewise-constant"}], ids=["bilinear", "node", "constant"])
def test_points_rounded_out_of_their_cell_are_moved_back(options):
    """Placing a sampled point (``Fine::place``; ``_nudge_into_cell`` for texels):
    where rounding to f32 takes a point of cell c into a neighbour, it is moved back
    by ulps. Every point on and within 10⁻⁹ of each cell's edges, on both axes, ends
    in its cell, at the f32 nearest its rounded value there (one ulp back towards
    that value leaves the cell); and some of them had to move."""
    llvm()
    light = envlight.EnvironmentLight.from_array(sky(), **options)
    tp = product_port(light)
    moved = 0
    for axis, n in ((0, tp.iw), (1, tp.ih)):
        if tp.bilinear:
            edges = tp._layout(n, axis == 1 and tp.node_rows)
        else:
            edges = np.arange(n + 1, dtype=np.float64) / n
        xs, cells = [], []
        for c in range(len(edges) - 1):
            lo, hi = edges[c], edges[c + 1]
            if hi <= lo:
                continue
            for x in (lo, lo + 1e-12, lo + 1e-10, lo + 1e-9, hi - 1e-9, hi - 1e-10, hi - 1e-12):
                if lo <= x < hi and x < 1.0:
                    xs.append(x)
                    cells.append(c)
        xs, cells = np.array(xs), np.array(cells, np.uint32)
        rounded = np.minimum(xs.astype(np.float32), np.float32(1.0) - np.float32(2.0**-24))
        if tp.bilinear:
            placed = np.array(tp._place(axis, mi.UInt32(cells), mi.Float64(xs)), np.float32)

            def cell_of(p):
                return np.array(tp._cell_axis(mi.Float(p), axis))
        else:
            placed = np.array(tp.light._nudge_into_cell(mi.Float(rounded), mi.UInt32(cells), n), np.float32)

            def cell_of(p):
                return np.array(tp.light._cell_index(mi.Float(p), n))
        assert np.array_equal(cell_of(placed), cells)
        away = placed != rounded
        back = np.nextafter(placed[away], rounded[away])
        assert (cell_of(back) != cells[away]).all()
        moved += int(away.sum())
    assert moved > 0


def test_a_wrong_product_table_is_rejected(variant):
    """The product's row-for-row check fails on the tables of a slightly different light."""
    rgb = sky()
    light = envlight.EnvironmentLight.from_array(rgb)
    brighter = rgb.copy()
    brighter[5:7, 40:42, :] *= 1.05
    tp = product_port(envlight.EnvironmentLight.from_array(brighter))
    n = 4000 if tp.jit else 300
    normals, u = normals_and_u(n, 4)
    d_cpu, pdf_cpu, l_cpu = (x.astype(np.float64) for x in light.sample_product(normals, u))
    d, pdf, l, p = product_rows(tp, normals, u, d_cpu.astype(np.float32))
    assert disagreeing(d, pdf, l, d_cpu, pdf_cpu, l_cpu).mean() > 0.3


def test_band_narrowing_skips_only_the_patches_that_cannot_narrow_it():
    """The horizon band at a normal whose horizon passes within 0.6° below a bright
    patch's centre is narrowed only by patches too small to reach below it (`tiny`);
    computing every patch's lower bound there (as the CPU does) gives the same band
    bit for bit, and leaving out the tiny ones changes it."""
    llvm()
    h, w = 256, 512
    rgb = np.ones((h, w, 3), np.float32)
    # Patches of 8 x 8 texels: bright texels at a patch's corner (a centre 0.35°
    # from its edges) and at patches' middles.
    for j, i, value in [(64, 96, 4000.0), (100, 300, 3000.0), (180, 20, 2500.0), (148, 404, 2000.0)]:
        rgb[j, i] = value
    light = envlight.EnvironmentLight.from_array(rgb, lookup="node", density="piecewise-bilinear")
    tp = product_port(light)
    assert 0 < sum(tp.tiny) < len(tp.tiny), tp.tiny
    every = copy.copy(tp)
    every.tiny = [True] * len(tp.tiny)
    none = copy.copy(tp)
    none.tiny = [False] * len(tp.tiny)
    # Normals at 90° − [−0.6°, 1.2°] from a bright centre (a tiny one for half
    # of them), and random ones.
    rng = np.random.default_rng(8)
    n = 100_000
    centres = np.array([item[2:5] for item in tp.bright])
    tiny = np.flatnonzero(tp.tiny)
    centres = centres[np.where(np.arange(n) % 2 == 0, rng.choice(tiny, n), rng.integers(len(centres), size=n))]
    t = rng.normal(size=(n, 3))
    t -= (t * centres).sum(1, keepdims=True) * centres
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    e = rng.uniform(-0.01, 0.02, (n, 1))
    normals = np.concatenate([t * np.sqrt(1 - e * e) + centres * e, rng.normal(size=(n, 3))])
    normals = [mi.Float(normals[:, k].astype(np.float32)) for k in range(3)]
    band, reference, without = (np.array(p.point(*normals)["band"]) for p in (tp, every, none))
    assert np.array_equal(band, reference)
    print(f"tiny {sum(tp.tiny)} of {len(tp.tiny)}; bands changed without them: {(band != without).sum()} of {len(band)}")
    assert (band != without).sum() > 0


def arriving(rng, n):
    """n surface interactions (JIT) whose wi are random directions (any length)."""
    q = rng.normal(size=(n, 3)).astype(np.float32)
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(q[:, 0], q[:, 1], q[:, 2])
    return si


def emitter(rgb, **params):
    return mi.load_dict({"type": "envlight", "bitmap": mi.Bitmap(rgb), **params})


LOOKUP_CASES = [
    ((32, 64), {}),
    ((32, 64), {"lookup": "nearest"}),
    ((32, 64), {"lookup": "node"}),
    ((32, 32), {"mapping": "equal-area"}),
    ((32, 32), {"mapping": "equal-area", "lookup": "nearest"}),
    ((1, 1), {}),
    ((1, 5), {"lookup": "node"}),
    ((7, 1), {}),
    ((2, 3), {"mapping": "equal-area"}),
]


@pytest.mark.parametrize("shape,options", LOOKUP_CASES, ids=lambda c: str(c))
def test_texture_lookup_equals_the_texel_gathers(shape, options):
    """In JIT variants the radiance lookup reads its texels from a bordered texture
    (``TableLight.bordered_texture``): the same radiance, bit for bit, as blending
    the texels ``lookup_texels`` names, read from the map in numpy (f32, the same
    order), at points all over and beyond [0, 1]² and on its edges; for a bilinear
    lookup, a border laid out for the other kind of u axis is caught."""
    llvm()
    rng = np.random.default_rng(11)
    h, w = shape
    light = envlight.EnvironmentLight.from_array(rng.uniform(0, 10, (h, w, 3)).astype(np.float32), **options)
    tl = TableLight(light.gpu_tables(), mi)
    n = 100_000
    u = rng.uniform(-0.1, 1.1, n).astype(np.float32)
    v = rng.uniform(-0.1, 1.1, n).astype(np.float32)
    u[:8] = [0, 1, 0.5, np.nextafter(np.float32(1), 0), 0, 1, 0, 1]
    v[:8] = [0, 0, 0.5, 1, 1, 1, 1e-7, np.nextafter(np.float32(1), 0)]
    u, v = mi.Float(u), mi.Float(v)
    fetched = np.array(tl.lookup(u, v))
    rgb = np.array(tl.texels, np.float32).reshape(-1, 3)
    width = tl.p["image_width"]
    terms = [(rgb[np.array(y) * width + np.array(x)], np.array(weight, np.float32)[:, None])
             for x, y, weight in tl.lookup_texels(u, v)]
    big = np.float32(np.finfo(np.float32).max)
    if len(terms) == 1:
        gathered = np.minimum(terms[0][0] * np.float32(tl.scale), big)
    else:
        (a, wa), (b, wb), (c, wc), (d, wd) = terms
        blend = np.minimum((wa * a + wb * b) + (wc * c + wd * d), big)
        gathered = np.minimum(blend * np.float32(tl.scale), big)
    gathered = gathered.T
    assert np.array_equal(fetched, gathered)
    if w > 1 and options.get("lookup") != "nearest":
        # The other axis's border: the seam (or the edge columns) blend wrong texels
        # (the nearest lookup reads no border).
        mapping = tl.p["mapping"]
        tl.p["mapping"] = MAPPING_EQUIRECT if mapping == MAPPING_EQUAL_AREA else MAPPING_EQUAL_AREA
        tl.texture = tl.bordered_texture(tl.texels, 3)
        tl.p["mapping"] = mapping
        assert not np.array_equal(np.array(tl.lookup(u, v)), gathered)


def test_emitter_queries_equal_the_cpu_in_mitsubas_frame(variant):
    rgb = sky()
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    rotation = mi.ScalarTransform4f().rotate(axis.tolist(), 50.0)
    em = emitter(rgb, scale=3.0, to_world=rotation)
    cpu = envlight.EnvironmentLight.from_array(
        rgb, frame="y-up", scale=3.0, lookup="node", density="piecewise-bilinear"
    )
    m = np.array(rotation.matrix, dtype=np.float64)[:3, :3]
    n = 2000 if variant != "scalar_rgb" else 100
    rng = np.random.default_rng(11)
    u = rng.random((n, 2), dtype=np.float32)
    d_cpu, pdf_cpu, l_cpu = (x.astype(np.float64) for x in cpu.sample(u))
    if variant == "scalar_rgb":
        it = mi.Interaction3f()
        it.p = mi.Point3f(0.0)
        rows = [em.sample_direction(it, mi.Point2f(float(a), float(b))) for a, b in u]
        d = np.array([list(ds.d) for ds, _ in rows])
        pdf = np.array([ds.pdf for ds, _ in rows])
        weight = np.array([list(w) for _, w in rows])
        again = np.array([em.pdf_direction(it, ds) for ds, _ in rows])
        radiance = np.array([list(em.eval_direction(it, ds)) for ds, _ in rows])
    else:
        it = dr.zeros(mi.Interaction3f, n)
        ds, w = em.sample_direction(it, mi.Point2f(u[:, 0], u[:, 1]))
        d = columns(ds.d)
        pdf = np.array(ds.pdf, np.float64)
        weight = columns(w)
        again = np.array(em.pdf_direction(it, ds), np.float64)
        radiance = columns(em.eval_direction(it, ds))
    # Mitsuba's world direction is to_world of the CPU's y-up direction.
    d_cpu_world = d_cpu @ m.T
    bad = disagreeing(d, pdf, weight * pdf[:, None], d_cpu_world, pdf_cpu, l_cpu)
    assert bad.mean() <= 1 - REQUIRED_FRACTION, bad.sum()
    ok = pdf > 0
    assert ok.mean() > 0.9
    assert (relative(again, pdf)[ok] < 1e-5).all()
    assert (np.abs(radiance - weight * pdf[:, None]).max(1) <= 1e-4 * radiance.max(1) + 1e-6)[ok].all()
    # eval() of an escaping ray looks the same radiance up: si.wi points back.
    k = min(n, 50)
    if variant == "scalar_rgb":
        for row in range(k):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(-d[row])
            assert np.allclose(list(em.eval(si)), radiance[row], rtol=1e-4, atol=1e-6)
    else:
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = -ds.d
        assert np.allclose(columns(em.eval(si)), radiance, rtol=1e-4, atol=1e-6)


def test_product_emitter_queries_equal_the_cpu_in_mitsubas_frame(variant):
    """sampling "product": samples and pdfs at each interaction's normal equal the CPU's
    product sampler at that normal (y-up frame, to_world applied); an interaction
    without a normal (in a medium) gets the light's own samples."""
    rgb = sky()
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    rotation = mi.ScalarTransform4f().rotate(axis.tolist(), 50.0)
    em = emitter(rgb, scale=3.0, to_world=rotation, sampling="product")
    cpu = envlight.EnvironmentLight.from_array(
        rgb, frame="y-up", scale=3.0, lookup="node", density="piecewise-bilinear"
    )
    m = np.array(rotation.matrix, dtype=np.float64)[:3, :3]
    n = 2000 if variant != "scalar_rgb" else 100
    normals, u = normals_and_u(n, 23)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[: n // 10] = 0.0  # in a medium
    local = (normals.astype(np.float64) @ m).astype(np.float32)  # m⁻¹ n for a rotation
    d_cpu, pdf_cpu, l_cpu = (x.astype(np.float64) for x in cpu.sample_product(local, u))
    light_rows = [x.astype(np.float64) for x in cpu.sample(u[: n // 10])]
    d_cpu[: n // 10], pdf_cpu[: n // 10], l_cpu[: n // 10] = light_rows
    if variant == "scalar_rgb":
        rows, again = [], []
        for k in range(n):
            it = mi.Interaction3f()
            it.p = mi.Point3f(0.0)
            it.n = mi.Normal3f(*map(float, normals[k]))
            ds, w = em.sample_direction(it, mi.Point2f(float(u[k, 0]), float(u[k, 1])))
            rows.append((list(ds.d), ds.pdf, list(w)))
            again.append(em.pdf_direction(it, ds))
        d = np.array([r[0] for r in rows])
        pdf = np.array([r[1] for r in rows])
        weight = np.array([r[2] for r in rows])
        again = np.array(again)
    else:
        it = dr.zeros(mi.Interaction3f, n)
        it.n = mi.Normal3f(normals[:, 0], normals[:, 1], normals[:, 2])
        ds, w = em.sample_direction(it, mi.Point2f(u[:, 0], u[:, 1]))
        d = columns(ds.d)
        pdf = np.array(ds.pdf, np.float64)
        weight = columns(w)
        again = np.array(em.pdf_direction(it, ds), np.float64)
    bad = disagreeing(d, pdf, weight * pdf[:, None], d_cpu @ m.T, pdf_cpu, l_cpu)
    assert bad.mean() <= 1 - REQUIRED_FRACTION, bad.sum()
    ok = pdf > 0
    assert ok.mean() > 0.8
    assert (relative(again, pdf)[ok] < 1e-5).all()
    # Product samples follow the normal: few below its horizon (the tables' floors
    # put some there, so that normals between grid nodes keep their support).
    cos = (d * normals).sum(1)[n // 10 :][ok[n // 10 :]]
    assert (cos < 0).mean() < 0.05


def jit_flags():
    return {flag: dr.flag(flag) for flag in dr.JitFlag.__members__.values()}


def test_register_changes_no_flag():
    llvm()
    before = jit_flags()
    envlight.mitsuba.register()
    em = emitter(sky())
    it = dr.zeros(mi.Interaction3f, 8)
    dr.eval(em.sample_direction(it, mi.Point2f(0.3, 0.6)))
    assert jit_flags() == before
    assert dr.flag(dr.JitFlag.SymbolicCalls) and dr.flag(dr.JitFlag.SymbolicLoops)


# -- images --------------------------------------------------------------------------


def scene(sky_emitter, spp, integrator="path", width=48, height=32):
    T = mi.ScalarTransform4f
    integ = {"type": integrator}
    if integrator in ("path", "volpath"):
        integ["max_depth"] = 4
    return mi.load_dict({
        "type": "scene",
        "integrator": integ,
        "sensor": {
            "type": "perspective", "fov": 50,
            "to_world": T().look_at(origin=[0, 1.2, 4.5], target=[0, 0.4, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "ground": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(10),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}},
        "left": {"type": "sphere", "center": [-0.6, 0.5, 0], "radius": 0.5,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.3, 0.2]}}},
        "right": {"type": "sphere", "center": [0.6, 0.5, 0], "radius": 0.5,
                  "bsdf": {"type": "roughplastic", "alpha": 0.2}},
        "sky": sky_emitter,
    })


def renders(sc, seeds):
    out = []
    for s in seeds:
        image = mi.render(sc, seed=s)
        out.append(np.array(image, np.float64).mean(axis=2))
    return np.stack(out)


def agreement(a, b, block=8):
    """(image mean difference in SE, share of block x block blocks beyond 4 SE)."""

    def z(xa, xb):
        se = np.sqrt(xa.var(0, ddof=1) / len(xa) + xb.var(0, ddof=1) / len(xb))
        return (xa.mean(0) - xb.mean(0)) / np.maximum(se, 1e-300)

    mean_z = z(a.mean(axis=(1, 2)), b.mean(axis=(1, 2)))
    h, w = a.shape[1] // block * block, a.shape[2] // block * block

    def blocks(y):
        return y[:, :h, :w].reshape(len(y), h // block, block, w // block, block).mean(axis=(2, 4))

    return float(mean_z), float((np.abs(z(blocks(a), blocks(b))) > 4).mean())


@pytest.fixture(scope="module")
def sunrise():
    if not SUNRISE.exists():
        pytest.skip(f"{SUNRISE} is missing")
    return str(SUNRISE)


@pytest.mark.parametrize("integrator", ["path", "direct", "volpath"])
def test_image_agrees_with_envmap(sunrise, integrator):
    llvm()
    rotation = mi.ScalarTransform4f().rotate([0, 1, 0], 70.0)
    seeds = range(12)
    envmap = renders(scene({"type": "envmap", "filename": sunrise, "to_world": rotation}, 16, integrator), seeds)
    light = {"type": "envlight", "filename": sunrise, "to_world": rotation}
    ours = renders(scene(light, 16, integrator), [100 + s for s in seeds])
    mean_z, beyond = agreement(ours, envmap)
    print(f"{integrator}: image mean {mean_z:+.2f} SE from envmap, {100 * beyond:.1f}% of 8x8 blocks beyond 4 SE")
    assert abs(mean_z) < 3 and beyond <= 0.05
    # The same test rejects a radiance 3% too bright.
    brighter = renders(scene(dict(light, scale=1.03), 16, integrator), [200 + s for s in seeds])
    assert abs(agreement(brighter, envmap)[0]) > 3


def pixel_variance(images):
    """The mean over pixels of each pixel's variance across renders."""
    return float(images.var(axis=0, ddof=1).mean())


@pytest.mark.parametrize("integrator", ["path", "direct"])
def test_product_image_agrees_with_envmap_and_has_lower_variance(sunrise, integrator):
    """sampling "product" renders envmap's image (mean within 3 SE, at most 5% of 8x8
    blocks beyond 4 SE) with lower variance at equal samples than envmap's and than
    envlight's light sampling (diffuse spheres and ground, one rough plastic)."""
    llvm()
    rotation = mi.ScalarTransform4f().rotate([0, 1, 0], 70.0)
    seeds = range(12)
    envmap = renders(scene({"type": "envmap", "filename": sunrise, "to_world": rotation}, 16, integrator), seeds)
    base = {"type": "envlight", "filename": sunrise, "to_world": rotation}
    product = renders(scene(dict(base, sampling="product"), 16, integrator), [300 + s for s in seeds])
    light = renders(scene(base, 16, integrator), [400 + s for s in seeds])
    mean_z, beyond = agreement(product, envmap)
    to_light = pixel_variance(product) / pixel_variance(light)
    to_envmap = pixel_variance(product) / pixel_variance(envmap)
    print(f"{integrator}: product image mean {mean_z:+.2f} SE from envmap, {100 * beyond:.1f}% of blocks "
          f"beyond 4 SE; pixel variance {to_light:.2f}x light's, {to_envmap:.2f}x envmap's")
    assert abs(mean_z) < 3 and beyond <= 0.05
    assert to_light < 0.85 and to_envmap < 0.85


def test_shadow_rays_reach_far_occluders(sunrise):
    """A roof 40 units above a small scene shadows it from the sky above: the
    emitter's shadow rays must reach it (a ray ending on a small sphere around the
    shading point would not), as envmap's do."""
    llvm()
    T = mi.ScalarTransform4f

    def roofed(sky):
        return mi.load_dict({
            "type": "scene",
            "integrator": {"type": "direct"},
            "sensor": {
                "type": "perspective", "fov": 40,
                "to_world": T().look_at(origin=[0, 3, 3], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": 24, "height": 16, "rfilter": {"type": "box"}},
                "sampler": {"type": "independent", "sample_count": 32},
            },
            "ground": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2),
                       "bsdf": {"type": "diffuse"}},
            "roof": {"type": "rectangle", "to_world": T().translate([0, 40, 0]).rotate([1, 0, 0], 90).scale(400),
                     "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}}},
            "sky": sky,
        })

    seeds = range(6)
    envmap = renders(roofed({"type": "envmap", "filename": sunrise}), seeds)
    ours = renders(roofed({"type": "envlight", "filename": sunrise}), [100 + s for s in seeds])
    mean_z, beyond = agreement(ours, envmap)
    assert abs(mean_z) < 3 and beyond <= 0.05, (mean_z, beyond)


def error_chain(info):
    chain, e = [], info.value
    while e is not None:
        chain.append(str(e))
        e = e.__cause__ or e.__context__
    return chain


def test_light_tracing_without_the_scenes_bounds_is_an_error_naming_the_fix(sunrise):
    llvm()
    gc.collect()  # no emitter of an earlier test left with bounds (see the bystander test)
    sc = scene({"type": "envlight", "filename": sunrise}, 4, "ptracer", 8, 8)
    with pytest.raises(Exception) as info:
        mi.render(sc)
    chain = error_chain(info)
    assert any("sample_ray" in m and "attach_bounds" in m for m in chain), chain


@pytest.mark.parametrize("how", ["attach_bounds", "parameters"])
def test_light_tracing_converges_to_the_path_tracers_image(sunrise, how):
    """ptracer with envlight (light leaving the scene's bounding disc, and the sky
    seen by the camera) against path with envmap: image mean within 3 SE, at most
    5% of 8x8 blocks beyond 4 SE; and a radiance 4% too bright is rejected."""
    llvm()
    rotation = mi.ScalarTransform4f().rotate([0, 1, 0], 70.0)
    seeds = range(10)
    envmap = renders(scene({"type": "envmap", "filename": sunrise, "to_world": rotation}, 16), seeds)
    light = {"type": "envlight", "filename": sunrise, "to_world": rotation}

    def traced(params, spp, seeds):
        if how == "parameters":
            sphere = scene({"type": "envmap", "filename": sunrise}, 1).bbox().bounding_sphere()
            params = dict(params, bounds_center=list(sphere.center), bounds_radius=float(sphere.radius) * 1.001)
        sc = scene(params, spp, "ptracer")
        if how == "attach_bounds":
            assert envlight.mitsuba.attach_bounds(sc) == 1
        return renders(sc, seeds)

    ours = traced(light, 128, [100 + s for s in seeds])
    mean_z, beyond = agreement(ours, envmap)
    print(f"ptracer ({how}): image mean {mean_z:+.2f} SE from path with envmap, {100 * beyond:.1f}% of blocks beyond 4 SE")
    assert abs(mean_z) < 3 and beyond <= 0.05
    brighter = traced(dict(light, scale=1.04), 128, [200 + s for s in seeds])
    assert abs(agreement(brighter, envmap)[0]) > 3


def test_an_emitter_without_bounds_beside_one_with_them(sunrise):
    """Dr.Jit traces sample_ray for every envlight emitter of the variant alive: one
    without bounds (another scene's, still held) beside the rendered scene's must not
    stop the render, and traces no light (the rendered image is the one rendered
    without it). In scalar variants nothing else is traced: no bounds is an error."""
    llvm()
    held = scene({"type": "envlight", "filename": sunrise}, 4, "ptracer", 8, 8)
    rendered = scene({"type": "envlight", "filename": sunrise}, 16, "ptracer", 16, 12)
    envlight.mitsuba.attach_bounds(rendered)
    with_bystander = np.array(mi.render(rendered, seed=3), np.float64)
    del held
    gc.collect()
    alone = np.array(mi.render(rendered, seed=3), np.float64)
    assert with_bystander.mean() > 0 and np.allclose(with_bystander, alone, rtol=1e-5, atol=1e-7)
    mi.set_variant("scalar_rgb")
    envlight.mitsuba.register()
    bounded = scene({"type": "envlight", "filename": sunrise}, 1, "ptracer", 2, 2)
    envlight.mitsuba.attach_bounds(bounded)
    unbounded = scene({"type": "envlight", "filename": sunrise}, 1, "ptracer", 2, 2)
    with pytest.raises(Exception) as info:
        mi.render(unbounded)
    assert any("attach_bounds" in m for m in error_chain(info))
    del bounded


def test_bad_bounds_raise_naming_them(variant):
    rgb = sky()
    with pytest.raises(Exception, match='"bounds_center" and "bounds_radius" must be given together'):
        emitter(rgb, bounds_radius=2.0)
    with pytest.raises(Exception, match='"bounds_radius" must be a finite number > 0'):
        emitter(rgb, bounds_center=[0, 0, 0], bounds_radius=-1.0)


# -- every variant: spectral, monochrome, polarized ---------------------------------------

LLVM_VARIANTS = ["llvm_ad_rgb", "llvm_ad_spectral", "llvm_ad_mono", "llvm_ad_spectral_polarized",
                 "llvm_ad_mono_polarized"]


def set_llvm_variant(name):
    if not llvm_available():
        pytest.skip("Dr.Jit finds no LLVM (set DRJIT_LIBLLVM_PATH): LLVM variants not tested")
    if name not in mi.variants():
        pytest.skip(f"Mitsuba was built without {name}")
    mi.set_variant(name)
    envlight.mitsuba.register()


def unpolarized(value):
    value = mi.unpolarized_spectrum(value) if mi.is_polarized else value
    return np.array(value, np.float64).reshape(-1, len(value[0]) if dr.is_jit_v(mi.Float) else 1)


def test_a_new_map_through_traverse_in_a_spectral_variant():
    """A new map through traverse rebuilds the spectra (eval as a fresh emitter's),
    and the map is not offered as differentiable there."""
    set_llvm_variant("llvm_ad_spectral")
    first, second = sky(seed=1), sky(seed=2)
    em, fresh = emitter(first), emitter(second)
    params = mi.traverse(em)
    assert params.flags("data") & int(mi.ParamFlags.NonDifferentiable)
    params["data"] = mi.TensorXf(second)
    params.update()
    n = 1000
    rng = np.random.default_rng(4)
    si = arriving(rng, n)
    lam = rng.uniform(360.0, 830.0, size=(4, n)).astype(np.float32)
    si.wavelengths = type(si.wavelengths)(*(mi.Float(lam[k]) for k in range(4)))
    updated, expected = np.array(em.eval(si)), np.array(fresh.eval(si))
    assert np.allclose(updated, expected, rtol=1e-6, atol=1e-9)
    assert not np.allclose(updated, np.array(emitter(first).eval(si)), rtol=1e-3)


@pytest.mark.parametrize("name", LLVM_VARIANTS + ["scalar_spectral", "scalar_spectral_polarized"])
def test_radiance_equals_envmaps_in_every_variant(name):
    """eval of random directions (random wavelengths in spectral variants) equals
    envmap's on the same map: RGB as is, the luminance in monochrome variants, the
    sRGB model's spectra blended as envmap blends them (times D65) in spectral ones."""
    if name.startswith("llvm"):
        set_llvm_variant(name)
    else:
        if name not in mi.variants():
            pytest.skip(f"Mitsuba was built without {name}")
        mi.set_variant(name)
        envlight.mitsuba.register()
    rgb = sky()
    axis = np.array([0.2, 1.0, 0.1]) / np.linalg.norm([0.2, 1.0, 0.1])
    rotation = mi.ScalarTransform4f().rotate(axis.tolist(), 33.0)
    ours, theirs = (mi.load_dict({"type": t, "bitmap": mi.Bitmap(rgb), "to_world": rotation, "scale": 1.5})
                    for t in ("envlight", "envmap"))
    rng = np.random.default_rng(3)
    jit = dr.is_jit_v(mi.Float)
    n = 4000 if jit else 40
    q = rng.normal(size=(n, 3)).astype(np.float32)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lam = rng.uniform(360.0, 830.0, size=(n, 4)).astype(np.float32)
    a, b = [], []
    for rows in ([slice(None)] if jit else [slice(k, k + 1) for k in range(n)]):
        count = q[rows].shape[0]
        si = dr.zeros(mi.SurfaceInteraction3f, count) if jit else dr.zeros(mi.SurfaceInteraction3f)
        col = (lambda x: mi.Float(x)) if jit else (lambda x: float(x[0]))
        si.wi = mi.Vector3f(*(col(q[rows, k]) for k in range(3)))
        if mi.is_spectral:
            si.wavelengths = type(si.wavelengths)(*(col(lam[rows, k]) for k in range(4)))
        a.append(unpolarized(ours.eval(si)).T.reshape(count, -1))
        b.append(unpolarized(theirs.eval(si)).T.reshape(count, -1))
    a, b = np.concatenate(a), np.concatenate(b)
    assert a.shape == b.shape and a.shape[1] == (3 if mi.is_rgb else 4 if mi.is_spectral else 1)
    close = np.abs(a - b) <= 2e-3 * np.maximum(np.abs(b).max(axis=1, keepdims=True), 1e-6)
    assert close.mean() >= 0.999, (close.size - close.sum(), close.size)


# (The spectral polarized variant renders the spectral one's images: its emission
# is that spectrum depolarized, which the monochrome polarized one covers.)
@pytest.mark.parametrize("name", ["llvm_ad_spectral", "llvm_ad_mono", "llvm_ad_mono_polarized"])
def test_image_agrees_with_envmap_in_every_variant(sunrise, name):
    """path with envlight (light and product sampling) and ptracer with envlight
    converge to path with envmap in spectral, monochrome and polarized variants:
    image mean within 3 SE, at most 5% of 8x8 blocks beyond 4 SE."""
    set_llvm_variant(name)
    rotation = mi.ScalarTransform4f().rotate([0, 1, 0], 70.0)
    seeds = range(10)
    envmap = renders(scene({"type": "envmap", "filename": sunrise, "to_world": rotation}, 16), seeds)
    base = {"type": "envlight", "filename": sunrise, "to_world": rotation}
    for offset, params, integrator, spp in [(100, base, "path", 16),
                                            (200, dict(base, sampling="product"), "path", 16),
                                            (300, base, "ptracer", 64)]:
        sc = scene(params, spp, integrator)
        envlight.mitsuba.attach_bounds(sc)
        ours = renders(sc, [offset + s for s in seeds])
        mean_z, beyond = agreement(ours, envmap)
        print(f"{name} {params.get('sampling', 'light')} {integrator}: image mean {mean_z:+.2f} SE, "
              f"{100 * beyond:.1f}% of blocks beyond 4 SE")
        assert abs(mean_z) < 3 and beyond <= 0.05, (params, integrator, mean_z, beyond)


def test_scalar_render_agrees_with_llvm(sunrise):
    """The scalar variant renders the same image as the LLVM one (within noise)."""
    llvm()
    seeds = range(6)
    reference = renders(scene({"type": "envlight", "filename": sunrise}, 16, "direct", 16, 12), seeds)
    mi.set_variant("scalar_rgb")
    envlight.mitsuba.register()
    ours = renders(scene({"type": "envlight", "filename": sunrise}, 16, "direct", 16, 12), [50 + s for s in seeds])
    assert abs(agreement(ours, reference)[0]) < 3.5


# -- errors -------------------------------------------------------------------------


@pytest.mark.parametrize(
    "params, message",
    [
        ({"filename": "no/such/sky.exr"}, 'environment map "no/such/sky.exr" not found'),
        ({}, 'a "filename" \\(or "bitmap"\\) parameter is required'),
        ({"filename": "x.exr", "bitmap": "bitmap"}, 'cannot specify both "bitmap" and "filename"'),
        ({"bitmap": "bitmap", "sampling": "bsdf"}, 'parameter "sampling" must be one of "light"'),
        ({"bitmap": "bitmap", "sampler": "alias"}, 'parameter "sampler" must be one of "inversion"'),
        ({"bitmap": "bitmap", "density": "smooth"}, 'parameter "density"'),
        ({"bitmap": "bitmap", "scale": -1.0}, '"scale" must be a finite number >= 0'),
        ({"bitmap": "bitmap", "colour": 1.0}, 'unreferenced property'),
    ],
)
def test_bad_parameters_raise_naming_what_is_wrong(variant, params, message):
    if params.get("bitmap") == "bitmap":
        params = dict(params, bitmap=mi.Bitmap(sky()))
    with pytest.raises(Exception, match=message):
        mi.load_dict({"type": "envlight", **params})


def test_a_bad_map_raises_naming_the_texel(variant, tmp_path):
    rgb = sky()
    rgb[3, 7, 1] = np.nan
    with pytest.raises(Exception, match="NaN|non-finite|not finite"):
        emitter(rgb)
    broken = tmp_path / "broken.exr"
    broken.write_bytes(b"not an exr file")
    with pytest.raises(Exception, match="broken.exr"):
        mi.load_dict({"type": "envlight", "filename": str(broken)})


def test_register_works_in_every_variant_of_the_build():
    for name in mi.variants():
        if name.startswith("cuda"):
            continue  # no GPU here: CUDA variants are written the same way, untested
        if name.startswith("llvm") and not llvm_available():
            continue
        mi.set_variant(name)
        envlight.mitsuba.register()
        em = emitter(sky())
        assert "EnvlightEmitter" in str(em)


# -- traverse / parameters_changed ------------------------------------------------------


def test_a_new_map_through_traverse_rebuilds_the_tables(variant):
    first, second = sky(seed=1), sky(seed=2)
    second[20:22, 10:12, :] = 800.0
    em = emitter(first)
    params = mi.traverse(em)
    assert {"scale", "data", "to_world"} <= set(params.keys())
    params["data"] = mi.TensorXf(second)
    params.update()
    fresh = emitter(second)
    rng = np.random.default_rng(5)
    u = rng.random((64, 2), dtype=np.float32)
    for a, b in u[: 64 if variant != "scalar_rgb" else 16]:
        it = dr.zeros(mi.Interaction3f)
        ds_updated, w_updated = em.sample_direction(it, mi.Point2f(float(a), float(b)))
        ds_fresh, w_fresh = fresh.sample_direction(it, mi.Point2f(float(a), float(b)))
        assert np.allclose(np.array(ds_updated.d), np.array(ds_fresh.d), atol=1e-6)
        assert np.allclose(np.array(ds_updated.pdf), np.array(ds_fresh.pdf), rtol=1e-6)
        assert np.allclose(np.array(w_updated), np.array(w_fresh), rtol=1e-5)
    # A scale and a rotation take effect without a rebuild.
    params["scale"] = 2.0
    rotation = mi.ScalarTransform4f().rotate([0, 1, 0], 90.0)
    params["to_world"] = rotation
    params.update()
    it = dr.zeros(mi.Interaction3f)
    ds, w = em.sample_direction(it, mi.Point2f(0.3, 0.7))
    ds0, w0 = fresh.sample_direction(it, mi.Point2f(0.3, 0.7))
    d0 = np.array(ds0.d).reshape(-1)
    assert np.allclose(np.array(ds.d).reshape(-1), [d0[2], d0[1], -d0[0]], atol=1e-5)
    assert np.allclose(np.array(w).reshape(-1), 2.0 * np.array(w0).reshape(-1), rtol=1e-5)
    # A map with a NaN texel is refused as a file would be, naming it.
    bad = second.copy()
    bad[3, 5, 0] = np.nan
    params["data"] = mi.TensorXf(bad)
    with pytest.raises(Exception, match="NaN|non-finite|not finite"):
        params.update()
    if variant != "scalar_rgb":
        # (Mitsuba's scalar variants refuse a new shape before the emitter sees it.)
        params["data"] = mi.TensorXf(np.zeros((4, 8, 4), np.float32))
        with pytest.raises(Exception, match=r"data has shape \(4, 8, 4\)"):
            params.update()


def test_eval_is_differentiable_in_the_map():
    """d Σ eval / d data: each lookup's bilinear weights sum to 1, so the gradient
    sums to (directions × channels × scale)."""
    llvm()
    em = emitter(sky(), scale=1.5)
    params = mi.traverse(em)
    dr.enable_grad(params["data"])
    params.update()
    n = 1000
    si = arriving(np.random.default_rng(2), n)
    value = em.eval(si)
    dr.backward(dr.sum(value[0] + value[1] + value[2]))
    grad = np.array(dr.grad(params["data"]))
    assert abs(grad.sum() - n * 3 * 1.5) < 1e-2 * n
    assert (grad >= 0).all() and (grad > 0).sum() > 100
