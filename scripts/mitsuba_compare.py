"""envlight's Mitsuba emitter against Mitsuba's envmap: agreement, cost and error.

    python scripts/mitsuba_compare.py [--map MAP] [--out DIR] [--variant llvm_ad_rgb]
        [--width 96 --height 64 --spp 16 --seeds 16 --rounds 9] [--all-diffuse]

Renders one scene (diffuse spheres, a rough-plastic sphere, a diffuse ground plane;
with --all-diffuse the middle sphere is diffuse too) under MAP with Mitsuba's path
integrator, and prints a markdown sheet:

- agreement: envlight (sampling="light") against envmap at equal samples, from S
  independent renders of each: the image mean difference in standard errors and the
  share of 8x8 blocks whose mean differs by more than 4 standard errors;
- cost: seconds per render (after the first, which compiles; the median of
  --rounds renders of each emitter in turn, so that all see the same load),
  envlight over envmap;
- error at equal time: RMSE against a high-sample envmap reference for envmap,
  envlight with sampling="light" and envlight with sampling="product" (light x cos+
  at the normal), each given the samples that fit in envmap's time (spp scaled by
  the measured cost ratio).

With --out, writes the images (PNG, tone-mapped) and the sheet (compare.md) there.
Needs Mitsuba 3 (pip install mitsuba) and, for LLVM variants, DRJIT_LIBLLVM_PATH.
"""

import argparse
import os
import sys
import time

import numpy as np


def build_scene(mi, emitter, spp, width=96, height=64, integrator="path", max_depth=4, all_diffuse=False):
    integ = {"type": integrator}
    if integrator == "path":
        integ["max_depth"] = max_depth
    T = mi.ScalarTransform4f
    return mi.load_dict({
        "type": "scene",
        "integrator": integ,
        "sensor": {
            "type": "perspective", "fov": 45,
            "to_world": T().look_at(origin=[0, 1.2, 5], target=[0, 0.4, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": width, "height": height, "rfilter": {"type": "box"}},
            "sampler": {"type": "independent", "sample_count": spp},
        },
        "ground": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(10),
                   "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.5, 0.5, 0.5]}}},
        "left": {"type": "sphere", "center": [-1.1, 0.5, 0], "radius": 0.5,
                 "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.8, 0.3, 0.2]}}},
        "middle": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5,
                   "bsdf": {"type": "diffuse"} if all_diffuse else {"type": "roughplastic", "alpha": 0.2}},
        "right": {"type": "sphere", "center": [1.1, 0.5, 0], "radius": 0.5,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.2, 0.4, 0.8]}}},
        "sky": emitter,
    })


def render(mi, scene, seed, spp=None):
    import drjit as dr
    image = mi.render(scene, seed=seed, spp=spp or 0)
    dr.eval(image)
    dr.sync_thread()
    return np.array(image, dtype=np.float64)


def renders(mi, scene, seeds, spp=None):
    """(S, H, W, C) images for the given seeds, and the mean seconds per render
    (the first render, which compiles the kernel, is made and not timed)."""
    render(mi, scene, 10_000 + seeds[0], spp)
    out, start = [], time.perf_counter()
    for s in seeds:
        out.append(render(mi, scene, s, spp))
    return np.stack(out), (time.perf_counter() - start) / len(seeds)


def interleaved_seconds(mi, scenes, rounds):
    """Median seconds per render of each scene, rendering them in turn, round after
    round (each compiled first)."""
    times = {name: [] for name in scenes}
    for name, scene in scenes.items():
        render(mi, scene, 20_000)
    for r in range(rounds):
        for name, scene in scenes.items():
            start = time.perf_counter()
            render(mi, scene, 30_000 + r)
            times[name].append(time.perf_counter() - start)
    return {name: float(np.median(t)) for name, t in times.items()}


def agreement(a, b, block=8):
    """Image mean difference of stacks a, b (S, H, W, C) in standard errors, and the
    share of block x block pixel blocks whose mean differs by more than 4 SE."""
    ya, yb = a.mean(axis=3), b.mean(axis=3)
    sa, sb = len(ya), len(yb)

    def z(xa, xb):
        diff = xa.mean(0) - xb.mean(0)
        se = np.sqrt(xa.var(0, ddof=1) / sa + xb.var(0, ddof=1) / sb)
        return diff / np.maximum(se, 1e-300), diff, se

    mean_z, diff, se = z(ya.mean(axis=(1, 2)), yb.mean(axis=(1, 2)))
    h, w = ya.shape[1] // block * block, ya.shape[2] // block * block

    def blocks(y):
        return y[:, :h, :w].reshape(len(y), h // block, block, w // block, block).mean(axis=(2, 4))

    bz, _, _ = z(blocks(ya), blocks(yb))
    return float(mean_z), float(diff), float(se), float((np.abs(bz) > 4).mean())


def rmse(stack, reference):
    return float(np.sqrt(((stack - reference[None]) ** 2).mean(axis=(1, 2, 3))).mean())


def save_png(mi, image, path):
    bitmap = mi.Bitmap(np.asarray(image, np.float32))
    bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = os.path.dirname(os.path.abspath(__file__))
    default_map = os.path.join(here, "..", "..", "shared", "envmaps", "sunrise.exr")
    parser.add_argument("--map", default=default_map)
    parser.add_argument("--variant", default="llvm_ad_rgb")
    parser.add_argument("--spp", type=int, default=16)
    parser.add_argument("--seeds", type=int, default=16, help="independent renders per emitter")
    parser.add_argument("--reference-spp", type=int, default=4096)
    parser.add_argument("--lookup", default="node")
    parser.add_argument("--density", default=None, help="envlight's density (default: the emitter's)")
    parser.add_argument("--out", default=None)
    parser.add_argument("--width", type=int, default=96)
    parser.add_argument("--height", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=9, help="interleaved timing rounds")
    parser.add_argument("--all-diffuse", action="store_true", help="the middle sphere diffuse too")
    args = parser.parse_args(argv)

    import mitsuba as mi
    mi.set_variant(args.variant)
    import envlight.mitsuba
    envlight.mitsuba.register()

    envmap = {"type": "envmap", "filename": args.map}
    light = {"type": "envlight", "filename": args.map, "lookup": args.lookup}
    if args.density:
        light["density"] = args.density
    product = dict(light, sampling="product")
    seeds = list(range(args.seeds))
    def build(em, spp):
        return build_scene(mi, em, spp, args.width, args.height, all_diffuse=args.all_diffuse)

    scenes = {name: build(em, args.spp) for name, em in
              [("envmap", envmap), ("envlight light", light), ("envlight product", product)]}
    stacks = {}
    for name, scene in scenes.items():
        # Independent seeds per emitter: the agreement's standard errors assume it.
        offset = 1000 * len(stacks)
        stacks[name], _ = renders(mi, scene, [offset + s for s in seeds])
    seconds = interleaved_seconds(mi, scenes, args.rounds)

    ref_scene = build(envmap, args.reference_spp)
    reference = render(mi, ref_scene, 123_456)

    density = args.density or "the emitter's default density"
    scene_kind = "all diffuse" if args.all_diffuse else "one rough-plastic sphere"
    lines = [f"map `{os.path.basename(args.map)}`, {args.variant}, path integrator (max_depth 4), "
             f"{args.width}x{args.height}, {scene_kind}, "
             f"lookup {args.lookup}, {density}, {args.spp} spp, {args.seeds} independent renders per emitter, reference envmap at "
             f"{args.reference_spp} spp", ""]
    lines.append("| emitter | s / render | cost vs envmap | mean diff vs envmap (SE) | 8x8 blocks > 4 SE | "
                 "RMSE equal spp | RMSE equal time | RMSE ratio equal time |")
    lines.append("|---|---|---|---|---|---|---|---|")
    base_time = seconds["envmap"]
    equal_time = {}
    for name, scene in scenes.items():
        ratio = seconds[name] / base_time
        spp = max(1, int(round(args.spp / ratio))) if name != "envmap" else args.spp
        stack = stacks[name] if spp == args.spp else renders(mi, scene, [5000 + s for s in seeds], spp)[0]
        equal_time[name] = (spp, rmse(stack, reference))
    for name in scenes:
        ratio = seconds[name] / base_time
        if name == "envmap":
            z = "—"
            blocks = "—"
        else:
            mz, _, _, share = agreement(stacks[name], stacks["envmap"])
            z, blocks = f"{mz:+.2f}", f"{100 * share:.1f}%"
        spp_t, err_t = equal_time[name]
        lines.append(f"| {name} | {seconds[name]:.3f} | {ratio:.2f}x | {z} | {blocks} | "
                     f"{rmse(stacks[name], reference):.4f} | {err_t:.4f} ({spp_t} spp) | "
                     f"{err_t / equal_time['envmap'][1]:.2f} |")
    sheet = "\n".join(lines)
    print(sheet)
    if args.out:
        os.makedirs(args.out, exist_ok=True)
        save_png(mi, reference, os.path.join(args.out, "reference.png"))
        for name in scenes:
            save_png(mi, stacks[name][0], os.path.join(args.out, name.replace(" ", "_") + ".png"))
        with open(os.path.join(args.out, "compare.md"), "w") as f:
            f.write(sheet + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
