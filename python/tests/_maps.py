"""Synthetic maps shared by the test modules."""

import numpy as np


def sky(h=32, w=64, seed=1, noise=False):
    """A small map: a smooth sky, a bright sun, some black texels; with `noise`,
    each texel scaled by a random factor in [0.5, 1.5) as well."""
    rng = np.random.default_rng(seed)
    v = (np.arange(h) + 0.5) / h
    rgb = np.empty((h, w, 3), np.float32)
    rgb[...] = (0.2 + 0.8 * np.cos(np.pi * v / 2))[:, None, None] * np.array([0.5, 0.7, 1.0], np.float32)
    rgb[h // 2 :, :, :] *= 0.3
    rgb[5:7, 40:42, :] = 500.0
    if noise:
        rgb *= rng.uniform(0.5, 1.5, (h, w, 1)).astype(np.float32)
    rgb[rng.random((h, w)) < 0.05] = 0.0
    return rgb
