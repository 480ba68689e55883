"""envlight's batch calls against Mitsuba 3's `envmap` emitter (variant
`llvm_ad_rgb`), one thread each, on the same synthetic lat-long maps: a sky
gradient plus a 1° sun holding about 91% of the power.

Prints one table, per map size and envlight density: build, sample, pdf and
radiance as the ratio Mitsuba / envlight (above 1: envlight is faster) with both
sides' absolute times (ms per build, ns per direction). Each time is the best of
--repeat rounds, and every round runs Mitsuba and each density in turn, so load
from other processes falls on all of them alike. Both sides sample from the same
float32 array of u; each then evaluates pdf and radiance on the directions it
sampled itself (the frames differ, so the same directions would land on different
texels). Mitsuba's results stay in Dr.Jit arrays; envlight's are new numpy arrays.

A last row gives the physical floor of each query: the bytes it must stream per
direction (inputs read plus outputs written) over the bandwidth of a one-thread
numpy copy of a 256 MiB array, the best of the same number of rounds.

Started by `run_mitsuba.sh`, which sets up the environment.
"""

import argparse
import os
import platform
import sys
import tempfile
import time

import drjit as dr
import mitsuba as mi
import numpy as np

import envlight

mi.set_variant("llvm_ad_rgb")
dr.set_thread_count(1)

N = 1 << 20
DENSITIES = ("piecewise-constant", "piecewise-bilinear")
SIZES = ((1024, 512), (2048, 1024), (4096, 2048))
# Bytes per direction that each query must read and write, float32 throughout:
# sample reads u (2) and writes the direction (3), pdf (1) and radiance (3); pdf
# reads a direction and writes one value; radiance reads a direction, writes RGB.
STREAMED_BYTES = {"sample": 4 * (2 + 3 + 1 + 3), "pdf": 4 * (3 + 1), "radiance": 4 * (3 + 3)}
QUERIES = ("sample", "pdf", "radiance")


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


def timed_together(runs, repeat):
    """Best and worst time of each function in `runs`, over `repeat` rounds that
    each run every function once, in turn: on a noisy machine all of them see the
    same load, so their ratios hold."""
    times = [[] for _ in runs]
    for _ in range(repeat):
        for f, t in zip(runs, times):
            start = time.perf_counter()
            f()
            t.append(time.perf_counter() - start)
    return [(min(t), max(t)) for t in times]


def mitsuba_queries(rgb, u):
    """The (sample, pdf, radiance) callables of Mitsuba's envmap, kernels compiled."""
    emitter = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(rgb)})
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
    return run_sample, run_pdf, run_radiance


def envlight_queries(rgb, u, density):
    """The (sample, pdf, radiance) callables of envlight's batch calls."""
    # z-up: the y-up frame would add a copy of the directions in the binding.
    light = envlight.EnvironmentLight.from_array(rgb, density=density)
    d, _, _ = light.sample(u)
    return (lambda: light.sample(u), lambda: light.pdf(d), lambda: light.radiance(d))


def cpu_model():
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return platform.processor() or "unknown CPU"


def vector_width():
    """The widest vectors envlight's batch calls dispatch to on this CPU, by the
    rule of crates/envlight/src/light/batch.rs, with the flags it tests."""
    flags = set()
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("flags"):
                flags = set(line.split(":", 1)[1].split())
                break
    avx512 = ("avx512f", "avx512vl", "avx512dq", "avx512bw")
    if all(f in flags for f in avx512):
        return "AVX-512 (" + " ".join(avx512) + ")"
    if "avx2" in flags:
        return "AVX2 (no " + " ".join(f for f in avx512 if f not in flags) + ")"
    return "SSE2 (no avx2)"


def drjit_lanes():
    """The f32 lanes of Dr.Jit's LLVM kernels here, read from the IR it prints."""
    import re

    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    level = dr.log_level()
    with tempfile.TemporaryFile("w+") as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            dr.set_flag(dr.JitFlag.PrintIR, True)
            dr.set_log_level(dr.LogLevel.Info)
            x = mi.Float(np.arange(3, dtype=np.float32)) * 3.0
            dr.eval(x)
            dr.sync_thread()
        finally:
            dr.set_flag(dr.JitFlag.PrintIR, False)
            dr.set_log_level(level)
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
        log.seek(0)
        lanes = re.findall(r"<(\d+) x float>", log.read())
    return max(map(int, lanes)) if lanes else None


def copy_bandwidth(repeat):
    """Bytes read plus written per second by a one-thread numpy copy of 256 MiB."""
    src = np.ones(32 << 20, np.float64)
    dst = np.empty_like(src)
    np.copyto(dst, src)  # fault the pages in first
    (best, _), = timed_together([lambda: np.copyto(dst, src)], repeat)
    return 2 * src.nbytes / best


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--densities",
        default=",".join(DENSITIES),
        help="comma-separated envlight densities (default: both)",
    )
    parser.add_argument(
        "--sizes",
        default=",".join(f"{w}x{h}" for w, h in SIZES),
        help="comma-separated map sizes WxH (default: 1k, 2k and 4k)",
    )
    parser.add_argument("--repeat", type=int, default=9, help="rounds per figure (default 9)")
    args = parser.parse_args()
    densities = [d.strip() for d in args.densities.split(",") if d.strip()]
    for d in densities:
        if d not in DENSITIES:
            parser.error(f"unknown density {d!r}; choose from {', '.join(DENSITIES)}")
    try:
        sizes = [tuple(int(x) for x in s.split("x")) for s in args.sizes.split(",")]
    except ValueError:
        parser.error(f"sizes must read like 1024x512, not {args.sizes!r}")
    repeat = args.repeat

    started = time.time()
    load_start = os.getloadavg()
    lanes = drjit_lanes()
    bandwidth = copy_bandwidth(repeat)
    print(f"CPU: {cpu_model()}, {os.cpu_count()} logical cores; envlight vectors: {vector_width()}")
    print(
        f"Mitsuba {mi.__version__} (Dr.Jit {dr.__version__}, LLVM "
        f"{'.'.join(map(str, dr.detail.llvm_version()))}, "
        f"{lanes if lanes else '?'} f32 lanes); envlight {envlight.__version__} "
        f"({os.environ.get('ENVLIGHT_PEER_BUILT', 'build source not recorded')}); "
        f"numpy {np.__version__}"
    )
    print(
        f"{N} directions per query, one thread each, best of {repeat} rounds that run "
        "Mitsuba and envlight in turn; cells: Mitsuba / envlight = ratio (above 1: "
        "envlight faster), build in ms, queries in ns per direction; "
        f"load average at start {load_start[0]:.2f}"
    )
    print()
    print("| size | density | build | sample | pdf | radiance |")
    print("|---|---|---|---|---|---|")
    spreads = []
    for w, h in sizes:
        rgb = synthetic(w, h)
        u = np.random.default_rng(1).random((N, 2), dtype=np.float32)
        mi_runs = mitsuba_queries(rgb, u)
        ours = [envlight_queries(rgb, u, density) for density in densities]
        # The builds, in turn, for a best-of figure like the queries'.
        builds = timed_together(
            [lambda: mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(rgb)})]
            + [
                (lambda d=d: envlight.EnvironmentLight.from_array(rgb, density=d))
                for d in densities
            ],
            repeat,
        )
        # Per query, Mitsuba and every density in turn, round after round.
        timings = [
            timed_together([mi_runs[q]] + [runs[q] for runs in ours], repeat)
            for q in range(3)
        ]
        label = f"{w // 1024}k ({w}×{h})" if w % 1024 == 0 else f"{w}×{h}"
        for k, density in enumerate(densities):
            (mb, mb_hi), (ob, ob_hi) = builds[0], builds[1 + k]
            cells = [f"{mb * 1e3:.1f} / {ob * 1e3:.1f} ms = {mb / ob:.2f}×"]
            spread = [f"{mb_hi / mb:.2f}, {ob_hi / ob:.2f}"]
            for q in range(3):
                (m, m_hi), (o, o_hi) = timings[q][0], timings[q][1 + k]
                cells.append(f"{m * 1e9 / N:.1f} / {o * 1e9 / N:.1f} ns = {m / o:.2f}×")
                spread.append(f"{m_hi / m:.2f}, {o_hi / o:.2f}")
            print(f"| {label} | {density} | " + " | ".join(cells) + " |")
            spreads.append((label, density, spread))
        sys.stdout.flush()
    floor = [f"{STREAMED_BYTES[q]} B: {STREAMED_BYTES[q] / bandwidth * 1e9:.2f} ns" for q in QUERIES]
    print(f"| floor | copy at {bandwidth / 1e9:.1f} GB/s | — | " + " | ".join(floor) + " |")
    print()
    print(
        "Spread, worst / best of the rounds (Mitsuba, envlight); "
        f"load average at end {os.getloadavg()[0]:.2f}; {time.time() - started:.0f} s"
    )
    print()
    print("| size | density | build | sample | pdf | radiance |")
    print("|---|---|---|---|---|---|")
    for label, density, spread in spreads:
        print(f"| {label} | {density} | " + " | ".join(spread) + " |")


if __name__ == "__main__":
    main()
