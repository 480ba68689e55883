"""envlight's batch calls against Mitsuba 3's `envmap` emitter (variant
`llvm_ad_rgb`), one thread each, on the same synthetic lat-long maps: a sky
gradient plus a 1° sun holding about 91% of the power. Prints, per map and
density, the time per direction of each query for both and the ratio Mitsuba /
envlight (above 1: envlight is faster), as the minimum over several repetitions
with the spread. Started by `run_mitsuba.sh`, which sets up the environment.
"""

import sys
import time

import drjit as dr
import mitsuba as mi
import numpy as np

import envlight

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(1)

N = 1 << 20
REPEAT = 9


def synthetic(w, h):
    """Sky gradient plus a sun of 1° radius at θ = 60°, φ = 130°, holding ~91%."""
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    theta = np.pi * v[:, None]
    phi = 2 * np.pi * u[None, :]
    rgb = np.empty((h, w, 3), np.float32)
    sky = np.clip(np.cos(theta), 0.05, None)[:, :, None] * np.array([0.4, 0.6, 1.0])[None, None, :]
    rgb[...] = sky
    d = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta) + 0 * phi], -1)
    t0, p0 = np.radians(60.0), np.radians(130.0)
    sun = np.array([np.sin(t0) * np.cos(p0), np.sin(t0) * np.sin(p0), np.cos(t0)])
    inside = d @ sun > np.cos(np.radians(1.0))
    dw = (2 * np.pi / w) * (np.pi / h) * np.sin(theta) * np.ones_like(phi)
    sky_power = float((rgb.mean(-1) * dw).sum())
    sun_area = float(dw[inside].sum())
    rgb[inside] = 10.0 * sky_power / sun_area  # ~91% of the power in the sun
    return rgb


def timed_together(runs):
    """Best and worst time of each function in `runs`, over REPEAT rounds that
    each run every function once, in turn: on a noisy machine all of them see the
    same load, so their ratios hold."""
    times = [[] for _ in runs]
    for _ in range(REPEAT):
        for f, t in zip(runs, times):
            start = time.perf_counter()
            f()
            t.append(time.perf_counter() - start)
    return [(min(t), max(t)) for t in times]


def mitsuba_queries(rgb):
    """Build time and the (sample, pdf, radiance) callables of Mitsuba's envmap."""
    start = time.perf_counter()
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(rgb)})
    build = time.perf_counter() - start
    rng = np.random.default_rng(1)
    u = rng.random((N, 2), dtype=np.float32)
    sample = mi.Point2f(u[:, 0], u[:, 1])
    it = dr.zeros(mi.Interaction3f, N)

    def run_sample():
        ds, weight = emitter.sample_direction(it, sample)
        dr.eval(ds, weight)
        dr.sync_thread()
        return ds

    ds = run_sample()

    def run_pdf():
        p = emitter.pdf_direction(it, ds)
        dr.eval(p)
        dr.sync_thread()

    si = dr.zeros(mi.SurfaceInteraction3f, N)
    si.wi = -ds.d

    def run_radiance():
        l = emitter.eval(si)
        dr.eval(l)
        dr.sync_thread()

    for f in (run_sample, run_pdf, run_radiance):
        f()  # compile the kernels first
    return build, (run_sample, run_pdf, run_radiance)


def envlight_queries(rgb, density):
    """Build time and the (sample, pdf, radiance) callables of envlight's batch calls."""
    start = time.perf_counter()
    # z-up: the y-up frame would add a copy of the directions in the binding.
    light = envlight.EnvironmentLight.from_array(rgb, density=density)
    build = time.perf_counter() - start
    u = np.random.default_rng(1).random((N, 2), dtype=np.float32)
    d, _, _ = light.sample(u)
    return build, (lambda: light.sample(u), lambda: light.pdf(d), lambda: light.radiance(d))


def main():
    sizes = [(1024, 512), (2048, 1024), (4096, 2048)]
    if len(sys.argv) > 1:
        sizes = [tuple(int(x) for x in s.split("x")) for s in sys.argv[1:]]
    print(
        f"{N} directions per query, one thread each, best of {REPEAT} rounds that run "
        "Mitsuba and envlight in turn (spread, worst / best, in brackets); ns per direction"
    )
    print("| density | map | build ms (Mitsuba / ours) | sample | pdf | radiance |")
    print("|---|---|---|---|---|---|")
    densities = ("piecewise-constant", "piecewise-bilinear")
    for w, h in sizes:
        rgb = synthetic(w, h)
        _, mi_runs = mitsuba_queries(rgb)
        ours = [envlight_queries(rgb, density) for density in densities]
        # The builds again, in turn, for a best-of figure like the queries'.
        builds = timed_together(
            [lambda: mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(rgb)})]
            + [
                (lambda d=d: envlight.EnvironmentLight.from_array(rgb, density=d))
                for d in densities
            ]
        )
        mi_build = builds[0][0]
        # Per query, Mitsuba and both densities in turn, round after round.
        timings = [
            timed_together([mi_runs[q]] + [runs[q] for _, runs in ours]) for q in range(3)
        ]
        for k, density in enumerate(densities):
            cells = []
            for q in range(3):
                (m, m_hi), (o, o_hi) = timings[q][0], timings[q][1 + k]
                cells.append(
                    f"{m * 1e9 / N:.1f} / {o * 1e9 / N:.1f} ns = {m / o:.2f}× "
                    f"[{m_hi / m:.2f}, {o_hi / o:.2f}]"
                )
            ours_build = builds[1 + k][0]
            print(
                f"| {density} | {w}×{h} | {mi_build * 1e3:.0f} / {ours_build * 1e3:.0f} = "
                f"{mi_build / ours_build:.2f}× | " + " | ".join(cells) + " |"
            )


if __name__ == "__main__":
    main()
