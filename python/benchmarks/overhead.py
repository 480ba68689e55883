"""Per-direction cost of the batch calls through Python, to set beside the Rust
batch figures of `envlight bench MAP` (run both with RAYON_NUM_THREADS=1):

    RAYON_NUM_THREADS=1 python python/benchmarks/overhead.py MAP
    RAYON_NUM_THREADS=1 target/release/envlight bench MAP
"""

import sys
import time

import numpy as np

import envlight

N = 1 << 20
ROUNDS = 7


def best(f):
    times = []
    for _ in range(ROUNDS):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times) * 1e9 / N


def main():
    light = envlight.EnvironmentLight(sys.argv[1])
    u = np.random.default_rng(1).random((N, 2), dtype=np.float32)
    d, _, _ = light.sample(u)
    normals = np.repeat(np.array([[0.0, 0.0, 1.0]], np.float32), N, axis=0)
    print(f"{light!r}, {N} directions, ns per direction (best of {ROUNDS}):")
    print(f"  sample          {best(lambda: light.sample(u)):6.1f}")
    print(f"  pdf             {best(lambda: light.pdf(d)):6.1f}")
    print(f"  radiance        {best(lambda: light.radiance(d)):6.1f}")
    print(f"  sample_product  {best(lambda: light.sample_product(normals, u)):6.1f}")


if __name__ == "__main__":
    main()
