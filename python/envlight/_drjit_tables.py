"""envlight's exported tables (docs/gpu-tables.md, layout version 1) evaluated with
Dr.Jit operations: a port of the WGSL module (crates/envlight-gpu/src/envlight.wgsl)
step for step, so that it traces into Mitsuba's kernels in every variant.

In JIT variants (``llvm_*``, ``cuda_*``) the arithmetic is the WGSL's, in f32, with
the same integer steps: ξ put on the CDF's 2³²−1 scale exactly, the same cell
found, the same point placed in it and nudged into it, the same settling of a
sampled direction into its cell, and the same polynomial trigonometry. In scalar
variants Dr.Jit's scalar types are Python numbers, so the same code runs in f64
(the integer steps are unchanged and exact).

Ported: the inversion sampler over both densities (piecewise-constant and
piecewise-bilinear), both mappings (equirectangular, equal-area), the nearest,
bilinear and node-centred lookups, f32 and f16 radiance. Not ported: the alias
sampler (its 48-bit arithmetic) and the hierarchical sampler (not exported).

Two departures from the WGSL are deliberate and change no result: the CDF search
walks forward from the guide table in a Dr.Jit loop (``dr.while_loop``), which is
the WGSL's scan; and in JIT variants the radiance lookup reads its texels from a
Dr.Jit texture over a bordered copy of them (``bordered_texture``), whose fetch
reads a texel's channels as one packet, and blends them with the same weights.
"""

import math

import drjit as dr
import numpy as np

# Parameter-block words (docs/gpu-tables.md, "Parameter block"): the constants of
# `envlight::gpu::param` (crates/envlight/src/gpu/mod.rs), lower-cased, which
# python/tests/test_gpu_tables.py checks these against. The two rotations take
# 12 words each (three rows `x, y, z, 0`).
_PARAMS_WORDS = 64
_LIGHT_TO_WORLD, _WORLD_TO_LIGHT = 0, 12
_W = {
    "version": 24, "sampler": 25, "density": 26, "mapping": 27, "lookup": 28,
    "radiance_format": 29, "rotated": 30, "black": 31, "image_width": 32,
    "image_height": 33, "table_width": 34, "table_height": 35, "scale": 36,
    "integral_luminance": 37, "marginal_cdf": 38, "marginal_guide": 39,
    "marginal_guide_shift": 40, "conditional_cdf": 41, "conditional_guide": 42,
    "conditional_guide_bits": 43, "bilinear_values": 48, "tables_words": 49,
    "bilinear_v_nodes": 50,
}
_F32_WORDS = {"scale", "integral_luminance"}

# A row of the product tables' `bright` array (f64, docs/gpu-tables.md, "Product
# tables"): one bright patch. `_BRIGHT_CONE` is the bounding cone (axis x, y, z,
# cos and sin of the half-angle); `_BRIGHT_BOX` the lat-long box when
# `_BRIGHT_HAS_BOX` is 1 (cos, sin of 2πu₀; cos, sin of 2πu₁; 1 if u₁ − u₀ < ½;
# sin, cos of πv₀; sin, cos of πv₁), else zeros (equal-area).
_BRIGHT_WORDS = 20
_BRIGHT_PATCH = 0
_BRIGHT_POWER = 1
_BRIGHT_CENTRE = slice(2, 5)
_BRIGHT_CONE = slice(5, 10)
_BRIGHT_HAS_BOX = 10
_BRIGHT_BOX = slice(11, 20)

SAMPLER_INVERSION, SAMPLER_ALIAS = 0, 1
DENSITY_CONSTANT, DENSITY_BILINEAR = 0, 1
MAPPING_EQUIRECT, MAPPING_EQUAL_AREA = 0, 1
LOOKUP_NEAREST, LOOKUP_BILINEAR, LOOKUP_NODE = 0, 1, 2
RADIANCE_F32, RADIANCE_F16 = 0, 1
V_NODES_TEXEL_CENTRES, V_NODES_NODE_ROWS = 0, 1

# dω / du dv of the equirectangular map over sin θ (2π²), and of the equal-area square (4π).
EQUIRECT_JACOBIAN = 19.7392088021787172
EQUAL_AREA_JACOBIAN = 12.5663706143591730
ONE_MINUS_EPSILON = float.fromhex("0x1.fffffep-1")
INV_CDF_ONE = 2.0**-32
F32_MAX = float.fromhex("0x1.fffffep+127")  # radiance is clamped to it, as on the CPU
TAN_PI_8 = 0.41421356237309503
INV_PI = 0.31830988618379067
SETTLE_STEPS = 6


def read_params(words):
    """The parameter block (64 uint32 words) as a dict of Python numbers."""
    words = np.asarray(words, dtype=np.uint32)
    if words.shape != (_PARAMS_WORDS,):
        raise ValueError(f"the parameter block has {words.size} words, expected {_PARAMS_WORDS}")
    p = {}
    for name, at in _W.items():
        if name in _F32_WORDS:
            p[name] = float(words[at : at + 1].view(np.float32)[0])
        else:
            p[name] = int(words[at])
    # Python floats: numpy scalars would turn Dr.Jit arrays into numpy arrays.
    for name, at in (("light_to_world", _LIGHT_TO_WORLD), ("world_to_light", _WORLD_TO_LIGHT)):
        p[name] = words[at : at + 12].view(np.float32).reshape(3, 4)[:, :3].tolist()
    return p


class TableLight:
    """An environment light evaluated from its exported tables with Dr.Jit.

    ``tables`` is the dict of ``EnvironmentLight.gpu_tables()``; ``mi`` the
    ``mitsuba`` module with a variant set (its ``Float``/``UInt32`` are the types
    computed with). Directions are in the light's own z-up frame (docs/design.md §2)
    before its rotation; the rotation of the parameter block is applied.

    Raises ValueError for tables this port does not evaluate (alias sampler, an
    unknown layout version or lookup)."""

    def __init__(self, tables, mi):
        p = read_params(tables["params"])
        if p["version"] != 1:
            raise ValueError(f"GPU tables layout version {p['version']}, expected 1")
        if p["sampler"] != SAMPLER_INVERSION:
            raise ValueError('sampler "alias" is not ported to Dr.Jit; use sampler="inversion"')
        if p["lookup"] not in (LOOKUP_NEAREST, LOOKUP_BILINEAR, LOOKUP_NODE):
            raise ValueError(f"unknown lookup {p['lookup']} in the GPU tables")
        if p["bilinear_v_nodes"] not in (V_NODES_TEXEL_CENTRES, V_NODES_NODE_ROWS):
            raise ValueError(f"unknown bilinear_v_nodes {p['bilinear_v_nodes']} in the GPU tables")
        # Along v, the bilinear density's nodes are the texel centres or (the node
        # lookup's) the rows from pole to pole; a constant of the trace.
        self.node_rows = p["bilinear_v_nodes"] == V_NODES_NODE_ROWS
        self.p = p
        self.mi = mi
        self.jit = dr.is_jit_v(mi.Float)
        F, U = mi.Float, mi.UInt32
        words = np.ascontiguousarray(tables["tables"], dtype=np.uint32)
        radiance = tables["radiance"]
        if p["radiance_format"] == RADIANCE_F16:
            radiance = radiance[..., :3].astype(np.float32)
        radiance = np.ascontiguousarray(radiance, dtype=np.float32).reshape(-1)
        if p["density"] == DENSITY_BILINEAR:
            nodes = np.ascontiguousarray(tables["bilinear_values"], dtype=np.float32).reshape(-1)
        else:
            nodes = np.zeros(1, np.float32)
        if self.jit:
            self.words = U(words)
            self.nodes = F(nodes)
        else:
            self.words = words
            self.nodes = nodes
        self.scale = p["scale"]
        self.black = p["black"] != 0
        self.rotated = p["rotated"] != 0
        self.set_texels(F(radiance) if self.jit else radiance)

    def set_texels(self, texels):
        """The texels the radiance lookup reads: a flat array of the map's RGB
        triples, row by row (in JIT variants a Dr.Jit ``Float``, which may carry
        gradients: the lookups are differentiable in it)."""
        self.texels = texels
        self.texture = self.bordered_texture(texels, 3)

    def bordered_texture(self, values, channels):
        """What ``fetch`` reads the lookup's texels from, given a flat array of
        `channels` values per texel of the map, row by row. In scalar variants the
        array itself. In JIT variants a Dr.Jit texture over the texels with a
        one-texel border, laid out so that each pair of texels a lookup blends
        sits side by side (along u the last column before the first and the first
        after the last on a periodic axis, the equirectangular mapping's, each
        edge column repeated on a clamped one; along v each edge row repeated).
        Gradients of `values` flow through it.

        Why a texture: ``Texture2f.eval_fetch`` reads each texel's channels as one
        packet, where a gather per channel costs more (the RGB lookup alone about
        1.4×, and 0.05–0.19 of a whole render's time in light sampling)."""
        if not self.jit:
            return values, channels
        mi, U = self.mi, self.mi.UInt32
        w, h = self.p["image_width"], self.p["image_height"]
        # Entry j of the bordered texels: channel c of texel k = (row, column).
        j = dr.arange(U, (h + 2) * (w + 2) * channels)
        k = j // channels
        c = j - k * channels
        row = k // (w + 2)
        column = k - row * (w + 2)
        y = dr.minimum(dr.maximum(row, 1) - 1, h - 1)
        first, last = (w - 1, 0) if self.p["mapping"] != MAPPING_EQUAL_AREA else (0, w - 1)
        x = dr.select(column == 0, first, dr.select(column == w + 1, last, column - 1))
        flat = dr.gather(mi.Float, values, (y * w + x) * channels + c)
        return mi.Texture2f(mi.TensorXf(flat, shape=(h + 2, w + 2, channels)),
                            filter_mode=dr.FilterMode.Nearest, wrap_mode=dr.WrapMode.Clamp)

    # -- backend helpers: the same code over Dr.Jit arrays and Python scalars ----

    def _u(self, x):
        """A float (≥ 0, below 2³²) truncated to uint32."""
        return self.mi.UInt32(x) if self.jit else int(x)

    def _f(self, x):
        return self.mi.Float(x) if self.jit else float(x)

    def _word(self, index, active=True):
        if self.jit:
            return dr.gather(self.mi.UInt32, self.words, index, active)
        return int(self.words[int(index)]) if active else 0

    def _node_value(self, index):
        if self.jit:
            return dr.gather(self.mi.Float, self.nodes, index)
        return float(self.nodes[int(index)])

    def _next_up(self, x):
        if self.jit:
            U = self.mi.UInt32
            return dr.reinterpret_array(self.mi.Float, dr.reinterpret_array(U, x) + 1)
        return float(np.nextafter(np.float32(x), np.float32(np.inf)))

    def _next_down(self, x):
        if self.jit:
            U = self.mi.UInt32
            down = dr.reinterpret_array(self.mi.Float, dr.reinterpret_array(U, x) - 1)
            return dr.select(x <= 0.0, x, down)
        if x <= 0.0:
            return x
        return float(np.nextafter(np.float32(x), np.float32(-np.inf)))

    def _where(self, cond, fn, otherwise, *args):
        """fn(*args) where cond holds, else otherwise(*args): a symbolic branch in
        JIT variants (a packet of lanes none of which needs fn skips it)."""
        if not self.jit:
            return fn(*args) if cond else otherwise(*args)
        return dr.if_stmt(args=args, cond=cond, true_fn=fn, false_fn=otherwise)

    def _loop(self, state, cond, body):
        return dr.while_loop(state=state, cond=cond, body=body)

    # -- small helpers ---------------------------------------------------------

    def _floor_index(self, x, n):
        """⌊x⌋ clamped into [0, n − 1]; NaN gives 0."""
        x = dr.select(x > 0.0, x, 0.0)
        x = dr.minimum(x, float(n - 1))
        return dr.minimum(self._u(x), n - 1)

    def _cell_index(self, x, n):
        return self._floor_index(x * float(n), n)

    def _nudge_into_cell(self, x, cell, n):
        """Moves x (within a few ulps of cell `cell` of n) into that cell, and below 1."""
        return self.into_cell(dr.minimum(x, ONE_MINUS_EPSILON), cell, lambda p: self._cell_index(p, n))

    def into_cell(self, x, cell, cell_of):
        """x moved by ulps, at most 4, towards cell `cell` until ``cell_of`` finds it
        there (f32): a point that a rounding moved out of its cell, put back.
        (Unrolled: a symbolic loop that packets leave at once was no faster.)"""
        for _ in range(4):
            c = cell_of(x)
            x = dr.select(c > cell, self._next_down(x), dr.select(c < cell, self._next_up(x), x))
        return x

    @staticmethod
    def _unit_closed(x):
        return dr.select(x > 0.0, dr.minimum(x, 1.0), 0.0)

    @staticmethod
    def _sin_cos_pi(x):
        """(sin πx, cos πx) without rounding π x: the WGSL's polynomials."""
        k = dr.round(2.0 * x)
        r = x - 0.5 * k
        r2 = r * r
        s = r * (3.141592653589793 + r2 * (-5.167712780049969 + r2 * (2.550164039877345
            + r2 * (-0.5992645293207919 + r2 * (0.08214588661112819 + r2 * -0.007370430945714348)))))
        c = 1.0 + r2 * (-4.934802200544679 + r2 * (4.058712126416768 + r2 * (-1.3352627688545893
            + r2 * (0.23533063035889312 + r2 * (-0.02580689139001405 + r2 * 0.001929574309403922)))))
        # The quadrant k mod 4, from k − 4 ⌊k / 4⌋ (k is a small whole number).
        q = k - 4.0 * dr.floor(0.25 * k)
        sin = dr.select(q == 0.0, s, dr.select(q == 1.0, c, dr.select(q == 2.0, -s, -c)))
        cos = dr.select(q == 0.0, c, dr.select(q == 1.0, -s, dr.select(q == 2.0, -c, s)))
        return sin, cos

    @staticmethod
    def _atan2_pi(y, x):
        """atan2(y, x) / π in (−1, 1] (0 for (0, 0)): the WGSL's reduction and polynomial."""
        ax = dr.abs(x)
        ay = dr.abs(y)
        swapped = ay > ax
        num = dr.select(swapped, ax, ay)
        den = dr.select(swapped, ay, ax)
        ok = den > 0.0
        safe_den = dr.select(ok, den, 1.0)
        reflect = num > TAN_PI_8 * den
        arg = dr.select(reflect, (num - den) / dr.select(ok, num + den, 1.0), num / safe_den)
        offset = dr.select(reflect, 0.25, 0.0)
        s = arg * arg
        s2 = s * s
        poly = (0.9999999994146261 + -0.3333330810928512 * s) + s2 * (
            (0.1999823912927692 + -0.14240442565012187 * s)
            + s2 * (0.1057586606855873 + -0.06040340948571631 * s)
        )
        a = offset + arg * poly * INV_PI
        a = dr.select(swapped, 0.5 - a, a)
        a = dr.select(x < 0.0, 1.0 - a, a)
        a = dr.select(y < 0.0, -a, a)
        return dr.select(ok, a, 0.0)

    # -- fixed-point CDFs --------------------------------------------------------

    def _to_fixed(self, xi):
        """ξ · (2³² − 1) = x + frac, x = ⌊·⌋ exactly (the CPU's, bit for bit)."""
        positive = xi > 0.0
        at_one = xi >= 1.0
        xc = dr.select(positive & (xi < 1.0), xi, 0.5)
        s = xc * 4294967296.0
        whole = dr.floor(s)
        fraction = s - whole
        ge = fraction >= xc
        x = self._u(whole) - dr.select(ge, 0, 1)
        frac = dr.select(ge, fraction - xc, fraction - xc + 1.0)
        x = dr.select(positive, dr.select(at_one, 0xFFFFFFFE, x), 0)
        frac = dr.select(positive & (xi < 1.0), frac, 0.0)
        return x, frac

    def _cdf_sample(self, cdf, guide, shift, n, xi):
        """(cell, offset in it, its width) of ξ on the CDF of n cells at word `cdf`,
        found from the guide at word `guide` and a forward scan."""
        x, frac = self._to_fixed(xi)
        if isinstance(shift, int):
            slice_ = (x >> shift) if shift < 32 else 0 * x
        else:
            slice_ = dr.select(shift < 32, x >> dr.minimum(shift, 31), 0)
        o = self._word(guide + slice_)

        def cond(o):
            return (o + 1 < n) & (self._word(cdf + o + 1, o + 1 < n) <= x)

        def body(o):
            return (o + 1,)

        (o,) = self._loop((o,), cond, body)
        lo = self._word(cdf + o)
        width = self._word(cdf + o + 1) - lo
        positive = width > 0
        offset = (self._f(x - lo) + frac) / self._f(dr.select(positive, width, 1))
        return o, dr.select(positive, offset, 0.0), width

    def _cell_widths(self, iu, iv):
        p = self.p
        row = p["conditional_cdf"] + iv * (p["table_width"] + 1) + iu
        wu = self._word(row + 1) - self._word(row)
        m = p["marginal_cdf"] + iv
        wv = self._word(m + 1) - self._word(m)
        return wu, wv

    def _probability_of_widths(self, wu, wv):
        return (self._f(wu) * INV_CDF_ONE) * (self._f(wv) * INV_CDF_ONE)

    def _sample_cell(self, xi0, xi1):
        p = self.p
        nu, nv = p["table_width"], p["table_height"]
        mv, ov, wv = self._cdf_sample(p["marginal_cdf"], p["marginal_guide"], p["marginal_guide_shift"], nv, xi1)
        bits = p["conditional_guide_bits"]
        row_cdf = p["conditional_cdf"] + mv * (nu + 1)
        row_guide = p["conditional_guide"] + mv * (1 << bits)
        mu, ou, wu = self._cdf_sample(row_cdf, row_guide, 32 - bits, nu, xi0)
        # The cell's widths are those `_cell_widths(mu, mv)` reads.
        return mu, mv, ou, ov, (wu, wv)

    # -- densities -----------------------------------------------------------------

    def _place_in_cell(self, cell, offset, n):
        return self._nudge_into_cell((self._f(cell) + offset) / float(n), cell, n)

    def _sample_inversion(self, xi0, xi1):
        p = self.p
        iu, iv, ou, ov, widths = self._sample_cell(xi0, xi1)
        u = self._place_in_cell(iu, ou, p["table_width"])
        v = self._place_in_cell(iv, ov, p["table_height"])
        return u, v, iu, iv, widths

    def _pdf_constant(self, u, v):
        p = self.p
        iu = self._cell_index(u, p["table_width"])
        iv = self._cell_index(v, p["table_height"])
        return self._pdf_constant_in(self._cell_widths(iu, iv))

    def _pdf_constant_in(self, widths):
        """The piecewise-constant density in a cell of CDF widths (wu, wv)."""
        p = self.p
        cells = float(p["table_width"]) * float(p["table_height"])
        return self._probability_of_widths(*widths) * cells

    def _node(self, j, n):
        """Node j of an axis of n texels: 0, (j − ½)/n for 1 ≤ j ≤ n, 1."""
        inner = (self._f(j) - 0.5) / float(n)
        return dr.select(j == 0, 0.0, dr.select(j > n, 1.0, inner))

    @staticmethod
    def _patch_width(j, n):
        return dr.select((j == 0) | (j == n), 0.5 / n, 1.0 / n)

    def _patch_of(self, x, n):
        return dr.minimum(self._u(x * float(n) + 0.5), n)

    def _v_node(self, k, h):
        """Node k along v: `_node`, or on the node rows 0, (k − 1)/(h − 1) for
        1 ≤ k ≤ h, 1 (nodes 0 and 1 repeat the poles: zero-width end patches)."""
        if not self.node_rows:
            return self._node(k, h)
        inner = (self._f(k) - 1.0) / float(h - 1)
        return dr.select(k == 0, 0.0, dr.select(k > h, 1.0, inner))

    def _v_patch_width(self, k, h):
        if not self.node_rows:
            return self._patch_width(k, h)
        return dr.select((k == 0) | (k == h), 0.0, 1.0 / (h - 1))

    def _v_patch_of(self, v, h):
        """The patch holding v ∈ [0, 1]: `_patch_of`, or on the node rows
        1 + min(⌊v (h − 1)⌋, h − 2), never a zero-width end patch."""
        if not self.node_rows:
            return self._patch_of(v, h)
        return 1 + dr.minimum(self._u(v * float(h - 1)), h - 2)

    def _corners(self, i, k):
        mu = self.p["image_width"] + 2
        top = k * mu + i
        bottom = top + mu
        return (self._node_value(top), self._node_value(top + 1), self._node_value(bottom),
                self._node_value(bottom + 1))

    @staticmethod
    def _sample_linear(xi, a, b):
        """x ∈ [0, 1) from the density ∝ a (1 − x) + b x: the stable root of its CDF."""
        # The WGSL's `sample_linear` (f32, a and b normalised by their maximum, then
        # clamped below 1 − 2⁻²⁴), for the light's own bilinear sampling. Not the
        # same function as `_drjit_product.TableProduct._sample_linear` on purpose:
        # that one is the CPU's `bilinear::sample_linear` (f64, no normalisation,
        # clamped below 1 − 2⁻⁵³) that the product sampler uses; sharing one would
        # change results in the last bits.
        m = dr.maximum(a, b)
        m = dr.select(m > 0.0, m, 1.0)
        an = a / m
        bn = b / m
        denominator = an + dr.sqrt(dr.maximum((1.0 - xi) * an * an + xi * bn * bn, 0.0))
        ok = denominator > 0.0
        x = dr.clip(xi * (an + bn) / dr.select(ok, denominator, 1.0), 0.0, ONE_MINUS_EPSILON)
        return dr.select(a == b, xi, dr.select(ok, x, 0.0))

    def _sample_bilinear(self, xi0, xi1):
        i, k, ou, ov, widths = self._sample_cell(xi0, xi1)
        f00, f10, f01, f11 = corners = self._corners(i, k)
        y = self._sample_linear(ov, f00 + f10, f01 + f11)
        x = self._sample_linear(ou, dr.lerp(f00, f01, y), dr.lerp(f10, f11, y))
        w, h = self.p["image_width"], self.p["image_height"]
        u = dr.lerp(self._node(i, w), self._node(i + 1, w), x)
        v = dr.lerp(self._v_node(k, h), self._v_node(k + 1, h), y)
        return dr.minimum(u, ONE_MINUS_EPSILON), dr.minimum(v, ONE_MINUS_EPSILON), i, k, (corners, widths)

    def _pdf_bilinear(self, u, v):
        w, h = self.p["image_width"], self.p["image_height"]
        u = self._unit_closed(u)
        v = self._unit_closed(v)
        i = self._patch_of(u, w)
        k = self._v_patch_of(v, h)
        return self._pdf_bilinear_in(u, v, i, k, self._corners(i, k), self._cell_widths(i, k))

    def _pdf_bilinear_in(self, u, v, i, k, corners, widths):
        """The piecewise-bilinear density at (u, v) ∈ [0, 1]² in patch (i, k), of
        node values `corners` and CDF widths (wu, wv)."""
        w, h = self.p["image_width"], self.p["image_height"]
        f00, f10, f01, f11 = corners
        left = dr.maximum(u - self._node(i, w), 0.0)
        right = dr.maximum(self._node(i + 1, w) - u, 0.0)
        top = dr.maximum(v - self._v_node(k, h), 0.0)
        bottom = dr.maximum(self._v_node(k + 1, h) - v, 0.0)
        weighted = bottom * (right * f00 + left * f10) + top * (right * f01 + left * f11)
        area = self._patch_width(i, w) * self._v_patch_width(k, h)
        denominator = area * area * (f00 + f10 + f01 + f11)
        ok = denominator > 0.0
        probability = self._probability_of_widths(*widths)
        return dr.select(ok, 4.0 * probability * (weighted / dr.select(ok, denominator, 1.0)), 0.0)

    def planar_pdf(self, u, v):
        if self.p["density"] == DENSITY_BILINEAR:
            return self._pdf_bilinear(u, v)
        return self._pdf_constant(u, v)

    # -- mappings ------------------------------------------------------------------

    def _rotate(self, m, x, y, z):
        return (m[0][0] * x + m[0][1] * y + m[0][2] * z,
                m[1][0] * x + m[1][1] * y + m[1][2] * z,
                m[2][0] * x + m[2][1] * y + m[2][2] * z)

    def to_world(self, x, y, z):
        return self._rotate(self.p["light_to_world"], x, y, z) if self.rotated else (x, y, z)

    def to_light(self, x, y, z):
        return self._rotate(self.p["world_to_light"], x, y, z) if self.rotated else (x, y, z)

    def uv_to_local(self, u, v):
        if self.p["mapping"] == MAPPING_EQUAL_AREA:
            return self._square_to_sphere(u, v)
        sin_t, cos_t = self._sin_cos_pi(v)
        sin_p, cos_p = self._sin_cos_pi(2.0 * u)
        sin_t = dr.maximum(sin_t, 0.0)
        return sin_t * cos_p, sin_t * sin_p, cos_t

    def _square_to_sphere(self, u, v):
        a = 2.0 * self._unit_closed(u) - 1.0
        b = 2.0 * self._unit_closed(v) - 1.0
        abs_a = dr.abs(a)
        abs_b = dr.abs(b)
        total = abs_a + abs_b
        upper = total <= 1.0
        r = dr.select(upper, total, 2.0 - total)
        positive = r > 0.0
        phi = dr.select(positive, 0.25 * ((abs_b - abs_a) / dr.select(positive, r, 1.0) + 1.0), 0.0)
        r2 = r * r
        z = dr.select(upper, 1.0 - r2, r2 - 1.0)
        sin_theta = r * dr.sqrt(dr.maximum(2.0 - r2, 0.0))
        sp, cp = self._sin_cos_pi(dr.clip(phi, 0.0, 0.5))
        return dr.copysign(cp * sin_theta, a), dr.copysign(sp * sin_theta, b), z

    def _sphere_to_square(self, dx, dy, dz):
        length = dr.sqrt(dx * dx + dy * dy + dz * dz)
        ok = length > 0.0
        inv = 1.0 / dr.select(ok, length, 1.0)
        dx, dy, dz = dx * inv, dy * inv, dz * inv
        x, y, z = dr.abs(dx), dr.abs(dy), dr.abs(dz)
        r = dr.minimum(dr.sqrt((x * x + y * y) / (1.0 + z)), 1.0)
        phi_fraction = dr.select((x > 0.0) | (y > 0.0), dr.clip(2.0 * self._atan2_pi(y, x), 0.0, 1.0), 0.0)
        abs_b = r * phi_fraction
        abs_a = r - abs_b
        lower = dz < 0.0
        abs_a, abs_b = dr.select(lower, 1.0 - abs_b, abs_a), dr.select(lower, 1.0 - abs_a, abs_b)
        a = dr.copysign(abs_a, dx)
        b = dr.copysign(abs_b, dy)
        u = dr.clip(0.5 * (a + 1.0), 0.0, 1.0)
        v = dr.clip(0.5 * (b + 1.0), 0.0, 1.0)
        return dr.select(ok, u, 0.5), dr.select(ok, v, 0.5)

    def local_to_uv(self, dx, dy, dz):
        """(u, v, du dv / dω) of a light-frame direction of any length."""
        if self.p["mapping"] == MAPPING_EQUAL_AREA:
            u, v = self._sphere_to_square(dx, dy, dz)
            return u, v, 0.0 * u + 1.0 / EQUAL_AREA_JACOBIAN
        r2 = dx * dx + dy * dy
        r = dr.sqrt(r2)
        v = self._atan2_pi(r, dz)
        half_turns = self._atan2_pi(dy, dx)
        u = 0.5 * half_turns
        u = dr.select(half_turns < 0.0, u + 1.0, u)
        u = dr.minimum(u, ONE_MINUS_EPSILON)
        positive = r > 0.0
        inv_jacobian = dr.select(
            positive, (dr.sqrt(r2 + dz * dz) / dr.select(positive, r, 1.0)) * (1.0 / EQUIRECT_JACOBIAN), 0.0
        )
        return dr.maximum(u, 0.0), v, inv_jacobian

    # -- radiance --------------------------------------------------------------------

    @staticmethod
    def _periodic(u):
        r = u - dr.floor(u)
        inside = (u >= 0.0) & (u < 1.0)
        return dr.select(inside, u, dr.select(r < 1.0, r, 0.0))

    def _clamped_pair(self, t, n):
        s = t * float(n) + 0.5
        i = self._floor_index(s, n + 1)
        return dr.maximum(i, 1) - 1, dr.minimum(i, n - 1), s - self._f(i)

    def _periodic_pair(self, u, w, shift):
        """The two texels around u on a periodic axis of w texels whose first sits at
        u = shift / w, and the second's weight."""
        s = self._periodic(u) * float(w) - shift + float(w)
        i = self._floor_index(s, 2 * w)
        x0 = dr.select(i >= w, i - w, i)
        x1 = x0 + 1
        x1 = dr.select(x1 == w, 0, x1)
        return x0, x1, s - self._f(i)

    def lookup_texels(self, u, v):
        """The texels the radiance at image point (u, v) blends: a list of
        ``(x, y, weight)``, four for the bilinear lookups (weights summing to 1),
        one for the nearest."""
        p = self.p
        w, h = p["image_width"], p["image_height"]
        periodic_u = p["mapping"] != MAPPING_EQUAL_AREA
        if p["lookup"] == LOOKUP_NEAREST:
            uu = self._periodic(u) if periodic_u else u
            return [(self._floor_index(uu * float(w), w), self._floor_index(v * float(h), h), 1.0 + 0.0 * u)]
        if p["lookup"] == LOOKUP_NODE:
            # Texel centres at (i + ½)/w along u (periodic), rows as nodes from pole
            # to pole (row j at v = j/(h − 1)).
            x0, x1, fs = self._periodic_pair(u, w, 0.5)
            if h > 1:
                t = self._unit_closed(v) * float(h - 1)
                j = self._floor_index(t, h - 1)
                y0, y1, ft = j, dr.minimum(j + 1, h - 1), t - self._f(j)
            else:
                y0, y1, ft = 0 * x0, 0 * x0, 0.0 * fs
        else:
            if periodic_u:
                x0, x1, fs = self._periodic_pair(u, w, 0.5)
            else:
                x0, x1, fs = self._clamped_pair(u, w)
            y0, y1, ft = self._clamped_pair(v, h)
        gs = 1.0 - fs
        gt = 1.0 - ft
        return [(x0, y0, gs * gt), (x1, y0, fs * gt), (x0, y1, gs * ft), (x1, y1, fs * ft)]

    def fetch(self, texture, u, v):
        """The lookup at image point (u, v) over a ``bordered_texture``: a list of
        ``(values, weight)``, as ``lookup_texels`` lists the texels (four for the
        bilinear lookups, one for the nearest), each texel's channels read from
        the texture's 2×2 block that starts at it (scalar variants: from the
        array, texel by texel)."""
        mi = self.mi
        w, h = self.p["image_width"], self.p["image_height"]
        texels = self.lookup_texels(u, v)
        if not self.jit:
            values, channels = texture
            return [(tuple(float(values[(int(y) * w + int(x)) * channels + c]) for c in range(channels)), weight)
                    for x, y, weight in texels]
        (x0, y0, _), (x1, y1) = texels[0], (texels[-1][0], texels[-1][1])
        if len(texels) == 1:
            x1, y1 = x0 + 1, y0 + 1
        # The block's first texel: (x0, y0) one step into the border, or the border
        # itself for a clamped pair at the first column or row (x1 = x0 = 0).
        ox = dr.select((x1 == x0) & (x0 == 0), 0, x0 + 1)
        oy = dr.select((y1 == y0) & (y0 == 0), 0, y0 + 1)
        # At the block's centre, eval_fetch's floor of pos · size − ½ is that texel.
        pos = mi.Point2f((self._f(ox) + 1.0) / float(w + 2), (self._f(oy) + 1.0) / float(h + 2))
        corners = texture.eval_fetch(pos)
        channels = len(corners[0])
        return [(tuple(corner[c] for c in range(channels)), weight)
                for corner, (_, _, weight) in zip(corners, texels)]

    def lookup(self, u, v):
        """Radiance at image point (u, v), scale applied."""
        texels = self.fetch(self.texture, u, v)
        if len(texels) == 1:
            return tuple(dr.minimum(c * self.scale, F32_MAX) for c in texels[0][0])
        (a, wa), (b, wb), (c, wc), (d, wd) = texels
        # Clamped to the largest finite f32 after the blend and after the scale,
        # as the CPU's lookups are.
        return tuple(
            dr.minimum(
                dr.minimum((wa * a[ch] + wb * b[ch]) + (wc * c[ch] + wd * d[ch]), F32_MAX) * self.scale,
                F32_MAX,
            )
            for ch in range(3)
        )

    # -- the light ---------------------------------------------------------------------

    def _solid_angle_pdf(self, u, v, inv_jacobian):
        if self.black:
            return 0.0 * u
        return self.planar_pdf(u, v) * inv_jacobian

    def eval(self, dx, dy, dz):
        """(pdf per steradian, (r, g, b)) of a direction (world frame of the tables)."""
        u, v, inv_j = self.local_to_uv(*self.to_light(dx, dy, dz))
        return self._solid_angle_pdf(u, v, inv_j), self.lookup(u, v)

    def pdf(self, dx, dy, dz):
        u, v, inv_j = self.local_to_uv(*self.to_light(dx, dy, dz))
        return self._solid_angle_pdf(u, v, inv_j)

    def radiance(self, dx, dy, dz):
        u, v, _ = self.local_to_uv(*self.to_light(dx, dy, dz))
        return self.lookup(u, v)

    def _cell_of(self, u, v):
        p = self.p
        if p["density"] == DENSITY_BILINEAR:
            return (self._patch_of(self._unit_closed(u), p["image_width"]),
                    self._v_patch_of(self._unit_closed(v), p["image_height"]))
        return self._cell_index(u, p["table_width"]), self._cell_index(v, p["table_height"])

    def _centre_of(self, iu, iv):
        p = self.p
        if p["density"] == DENSITY_BILINEAR:
            w, h = p["image_width"], p["image_height"]
            return (0.5 * (self._node(iu, w) + self._node(iu + 1, w)),
                    0.5 * (self._v_node(iv, h) + self._v_node(iv + 1, h)))
        return ((self._f(iu) + 0.5) / float(p["table_width"]), (self._f(iv) + 0.5) / float(p["table_height"]))

    def settle(self, u, v, iu, iv, cu, cv, cell_of, outer=None):
        """The world direction of image point (u, v), drawn in cell (iu, iv), moved
        toward the cell's centre (cu, cv) until the direction maps back into the cell
        (at most SETTLE_STEPS times): ((x, y, z), u', v', du dv / dω) with (u', v')
        the image point the direction maps back to. ``cell_of(u, v)`` gives the cell
        of an image point; ``outer`` is as in ``sample``."""
        if outer is None:
            outer = (lambda x, y, z: (x, y, z), lambda x, y, z: (x, y, z))
        outer_to_world, outer_to_light = outer

        def settled(u, v):
            d = outer_to_world(*self.to_world(*self.uv_to_local(u, v)))
            bu, bv, inv_j = self.local_to_uv(*self.to_light(*outer_to_light(*d)))
            return d, bu, bv, inv_j

        d, bu, bv, inv_j = settled(u, v)

        def away(bu, bv):
            ju, jv = cell_of(bu, bv)
            return (ju != iu) | (jv != iv)

        def cond(k, u, v, step, dx, dy, dz, bu, bv, inv_j):
            return (k < SETTLE_STEPS) & away(bu, bv)

        def body(k, u, v, step, dx, dy, dz, bu, bv, inv_j):
            u = dr.lerp(u, cu, step)
            v = dr.lerp(v, cv, step)
            step = dr.minimum(4.0 * step, 1.0)
            (dx, dy, dz), bu, bv, inv_j = settled(u, v)
            return k + 1, u, v, step, dx, dy, dz, bu, bv, inv_j

        k0 = 0 * iu
        step0 = 0.0 * u + 1e-3
        state = self._loop((k0, u, v, step0, d[0], d[1], d[2], bu, bv, inv_j), cond, body)
        _, u, v, _, dx, dy, dz, bu, bv, inv_j = state
        return (dx, dy, dz), bu, bv, inv_j

    def sample(self, xi0, xi1, outer=None):
        """Draws a direction for ξ ∈ [0, 1)²: ((x, y, z) world, pdf per steradian,
        (r, g, b), valid). No sample (black light, a pole, a zero-density cell):
        valid False, pdf and radiance 0, the direction of the image point ξ.

        outer: an optional pair (to_world, to_light) of functions of (x, y, z) that
        a caller puts around the tables' own frame (a renderer's transform, rounded
        to its storage type). The direction is settled into its cell through them,
        so the caller's pdf(to_light(d)) finds the sampled cell too."""
        if self.black:
            outer_to_world = outer[0] if outer is not None else (lambda x, y, z: (x, y, z))
            d = outer_to_world(*self.to_world(*self.uv_to_local(xi0, xi1)))
            zero = 0.0 * xi0
            return d, zero, (zero, zero, zero), xi0 != xi0
        bilinear = self.p["density"] == DENSITY_BILINEAR
        if bilinear:
            u, v, iu, iv, (corners, widths) = self._sample_bilinear(xi0, xi1)
        else:
            u, v, iu, iv, widths = self._sample_inversion(xi0, xi1)
        cu, cv = self._centre_of(iu, iv)
        (dx, dy, dz), bu, bv, inv_j = self.settle(u, v, iu, iv, cu, cv, self._cell_of, outer)
        # The pdf at the settled image point, as `pdf` computes it: from the
        # sampled cell's node values and widths where the point lies in that cell
        # (settled), else located afresh (in a branch).
        ju, jv = self._cell_of(bu, bv)
        if bilinear:
            known = self._pdf_bilinear_in(self._unit_closed(bu), self._unit_closed(bv), iu, iv, corners, widths)
        else:
            known = self._pdf_constant_in(widths)
        planar = self._where((ju != iu) | (jv != iv), lambda u, v, p: self.planar_pdf(u, v),
                             lambda u, v, p: p, bu, bv, known)
        pdf = planar * inv_j
        valid = pdf > 0.0
        rgb = self.lookup(bu, bv)
        zero = 0.0 * pdf
        pdf = dr.select(valid, pdf, 0.0)
        rgb = tuple(dr.select(valid, c, zero) for c in rgb)
        return (dx, dy, dz), pdf, rgb, valid
