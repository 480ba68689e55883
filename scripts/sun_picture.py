#!/usr/bin/env python3
"""Makes docs/img/sun.png, the picture of sun extraction in docs/sun.md.

Every panel is the envlight tool's own picture: `envlight sun MAP --residual` writes
the map without its sun, `envlight importance` pictures the map (its sun ringed in
cyan) and the residual, at a panel width of 640 and, for the zoom, 4096. This script
only puts them side by side and crops the zoom (32° × 12° of the density panels
around the ring). Needs Pillow and numpy, and the binary (cargo build --release).

    python3 scripts/sun_picture.py [MAP] [OUT.png]
"""

import pathlib
import subprocess
import sys
import tempfile

import numpy as np
from PIL import Image, ImageDraw, ImageFont

ROOT = pathlib.Path(__file__).resolve().parents[1]
MAP = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "envmaps" / "sunrise.exr"
OUT = pathlib.Path(sys.argv[2]) if len(sys.argv) > 2 else ROOT / "docs" / "img" / "sun.png"
ENVLIGHT = str(ROOT / "target" / "release" / "envlight")
RING = [0, 230, 255]  # the importance picture's sun ring
BACKGROUND = (22, 22, 24)
INK = (225, 225, 225)


def run(*args):
    subprocess.run([ENVLIGHT, *map(str, args)], check=True, stdout=subprocess.DEVNULL)


with tempfile.TemporaryDirectory() as tmp:
    tmp = pathlib.Path(tmp)
    residual = tmp / f"{MAP.stem}_residual.exr"
    run("sun", MAP, "--residual", residual)
    pictures = {}
    for name, source in [("map", MAP), ("residual", residual)]:
        for width in (640, 4096):
            path = tmp / f"{name}_{width}.png"
            run("importance", source, "--width", width, "-o", path)
            pictures[name, width] = Image.open(path).convert("RGB")

    # The ring on the density panel (the lower half) of the wide map picture.
    wide = np.asarray(pictures["map", 4096])
    ys, xs = np.nonzero((wide == RING).all(axis=2))
    lower = ys > wide.shape[0] // 2
    cy, cx = int(ys[lower].mean()), int(xs[lower].mean())
    px_per_deg = 4096 / 360
    hw, hh = int(16 * px_per_deg), int(6 * px_per_deg)
    box = (cx - hw, cy - hh, cx + hw, cy + hh)

    small_map, small_residual = pictures["map", 640], pictures["residual", 640]
    w = small_map.width
    zoom_h = int(w * hh / hw)
    zooms = [pictures[n, 4096].crop(box).resize((w, zoom_h), Image.LANCZOS) for n in ("map", "residual")]
    gap = 12
    out = Image.new("RGB", (2 * w + gap, small_map.height + zoom_h + 34), BACKGROUND)
    out.paste(small_map, (0, 0))
    out.paste(small_residual, (w + gap, 0))
    y = small_map.height + 28
    out.paste(zooms[0], (0, y))
    out.paste(zooms[1], (w + gap, y))
    draw = ImageDraw.Draw(out)
    font = ImageFont.load_default(size=17)
    draw.text((10, y - 24), "zoom 32° x 12° on the sun, log pdf: the map, its disc ringed", fill=INK, font=font)
    draw.text((w + gap + 10, y - 24), "the residual (own colour scale): sun gone, glow kept", fill=INK, font=font)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    out.save(OUT, optimize=True)
    print(f"wrote {OUT} ({out.width}x{out.height})")
