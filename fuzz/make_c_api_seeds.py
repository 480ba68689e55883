# Writes fuzz/seeds/c_api/: small sun-and-sky maps with every sampler, density,
# mapping and lookup code (and out-of-range ones), a NaN texel, a black map, each
# followed by random and odd queries (NaN, infinite, zero). Layout: see
# fuzz_targets/c_api.rs. Run from fuzz/: python3 make_c_api_seeds.py
import math, random, struct

random.seed(4)


def sky(w, h):
    out = []
    for y in range(h):
        for x in range(w):
            v = 0.2 + 0.8 * math.sin(math.pi * (y + 0.5) / h)
            if x == w // 3 and y == h // 4:
                v = 500.0
            out += [v, v * 0.9, v * 0.7]
    return out


cases = []
for (w, h, opts) in [(8, 4, (0, 0, 0, 0)), (16, 8, (1, 0, 0, 1)), (12, 6, (2, 0, 1, 0)), (8, 8, (0, 1, 1, 0)),
                     (4, 2, (0, 1, 0, 0)), (1, 1, (0, 0, 0, 0)), (8, 4, (3, 0, 0, 0)), (8, 4, (1, 1, 0, 0))]:
    head = bytes([(w - 1) % 24, (h - 1) % 12]) + bytes(opts)
    tex = struct.pack('<%df' % (w * h * 3), *sky(w, h))
    q = []
    for k in range(12):
        q += [random.random(), random.random(), random.uniform(-1, 1)]
    q += [float('nan'), 0.5, 0.0, 1.0, 1.0, -0.0, 0.0, 0.0, 0.0, float('inf'), -1.0, 2.0]
    cases.append(head + tex + struct.pack('<%df' % len(q), *q))
w, h = 8, 4
cases.append(bytes([7, 3, 0, 0, 0, 0]) + struct.pack('<%df' % (w * h * 3), *([1.0] * 40 + [float('nan')] + [1.0] * 55)))
cases.append(bytes([7, 3, 0, 0, 0, 0]) + bytes(w * h * 12) + struct.pack('<6f', 0.5, 0.5, 0.0, 0.1, 0.9, 1.0))
for i, c in enumerate(cases):
    open(f'seeds/c_api/seed-{i:02d}.bin', 'wb').write(c)
