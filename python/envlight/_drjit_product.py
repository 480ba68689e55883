"""envlight's cosine product sampler (docs/design.md §6a; the Rust module
``envlight::product``) evaluated with Dr.Jit operations over its exported tables
(``EnvironmentLight.product_tables()``, docs/gpu-tables.md, "Product tables").

A shading point with normal n draws directions with density ∝ L(ω) · max(0, n·ω)
(up to the tables' bounds) and reports that density exactly:

- the point's state, as ``ShadingPoint::move_to`` computes it: the normal's cell in
  the octahedral grid of normals and the bilinear weights of its four corner
  tables (f32 placement, f64 weights), and the bright patches' weights at n
  (f64, from their bounds over the patch in f32);
- a sample, as ``ShadingPoint::sample``: a table or a bright patch from ξ₀, a patch
  from the table's alias table (ξ₁), a texel from the patch's alias table and a
  point in it, every pick in f64 and integers as on the CPU;
- the direction of that point from the light port's f32 mapping (``TableLight``),
  settled into the sampled texel as the light's samples are, and its pdf evaluated
  at the returned direction, as ``ShadingPoint::pdf`` evaluates one;
- the horizon's band: a draw with −s < n̂·ω < 0 (s = ``horizon_band``, or less
  down to ``min_horizon_band`` to keep the lowest bright patch wholly above the
  horizon out of it) returned as its mirror image in the tangent plane, and the
  pdf of a direction within the band above the horizon holding its mirror
  image's density too.

In JIT variants the picks run in ``Float64`` and ``UInt32``, the placement in the
grid in ``Float`` (f32), as on the CPU; in scalar variants everything is a Python
number (f64). Both densities: the piecewise-constant one's cells are the texels,
the piecewise-bilinear one's the cells between its nodes, with a point placed in a
cell by inverting the bilinear function's marginal and conditional (f64).

The pdf is computed in f32 from records built once from the tables (numpy, f64,
rounded to f32): each cell's density given its patch (at its four corners for the
bilinear density), and each patch's width in the four corner tables of each cell
of the grid of normals; a direction reads one of each. A sample's pdf reuses what
its draw found (its cell's record and its patch), and the horizon band's second
density and a cell located afresh are computed in symbolic branches, which
packets of lanes that do not need them skip.
"""

import drjit as dr
import numpy as np

from ._drjit_tables import (
    _BRIGHT_BOX,
    _BRIGHT_CENTRE,
    _BRIGHT_CONE,
    _BRIGHT_HAS_BOX,
    _BRIGHT_PATCH,
    _BRIGHT_POWER,
    _BRIGHT_WORDS,
)

CDF_ONE = 4294967295.0
INV_CDF_ONE = 1.0 / CDF_ONE
# 1 − 2⁻⁵³: the largest f64 below 1.
BELOW_ONE = 1.0 - 2.0**-53
# Half an f32 quantum of ξ near 1 (f32::EPSILON / 4).
XI_HALF_QUANTUM = 2.0**-25
# One unit of a fixed-point CDF: the least share a component with weight keeps.
MIN_SHARE = 1.0 / CDF_ONE
NO_BRIGHT = 255


class TableProduct:
    """Cosine product sampling at shading points, from a light's product tables.

    ``tables`` is the dict of ``EnvironmentLight.product_tables()``, ``light`` the
    ``TableLight`` of the same light's GPU tables (its mapping, rotation, settling
    and radiance lookup are used), ``mi`` the ``mitsuba`` module with a variant
    set. Normals and directions are in the world frame of the light's tables."""

    def __init__(self, tables, light, mi):
        self.light = light
        self.mi = mi
        self.jit = light.jit
        iw, ih = (int(x) for x in tables["image"])
        w, h = (int(x) for x in tables["cells"])
        pw, ph = (int(x) for x in tables["patches"])
        if (iw, ih) != (light.p["image_width"], light.p["image_height"]):
            raise ValueError("the product tables and the light's tables are of different maps")
        self.bilinear = tables["density"] == "piecewise-bilinear"
        # The bilinear density's nodes along v: texel centres, or the node lookup's
        # rows from pole to pole (a repeated first node), as the light's tables say.
        self.node_rows = self.bilinear and light.node_rows
        if self.bilinear and bool(np.asarray(tables["v_nodes"])[1] == 0.0) != self.node_rows:
            raise ValueError("the product tables' nodes and the light's tables disagree")
        # Cells: w × h (texels, or (iw + 1) × (ih + 1) between the bilinear nodes).
        self.iw, self.ih = iw, ih
        self.w, self.h, self.pw = w, h, pw
        self.patch_count = pw * ph
        self.grid = int(tables["grid"])
        self.nodes = (self.grid + 1) ** 2
        self.texel_scale = float(iw) * float(ih) / CDF_ONE
        self.bound_share = float(tables["bound_share"])
        self.box_slack = float(tables["box_slack"])
        self.horizon_band = float(tables["horizon_band"])
        self.min_horizon_band = float(tables["min_horizon_band"])
        empty = np.asarray(tables["node_empty"], dtype=bool)
        self.any_empty = bool(empty.any())
        # An empty table is one of total 0: the mix reads the totals only.
        if not np.array_equal(empty, np.asarray(tables["node_totals"]) == 0.0):
            raise ValueError("the product tables' empty nodes are not those of total 0")
        bright = np.asarray(tables["bright"], dtype=np.float64).reshape(-1, _BRIGHT_WORDS)
        # Python floats: numpy scalars would turn Dr.Jit arrays into numpy arrays.
        self.bright = [[float(x) for x in row] for row in bright]
        # The patches that can lie wholly above a horizon their centre is less than
        # asin(1.001 share) above (see `point`): those whose region holds no cap of
        # that radius (and 10⁻³ more, far beyond f32's rounding) around the centre.
        reach = np.arcsin(self.bound_share * 1.001) + 1e-3
        self.tiny = [bool(self._inscribed_radius(row) <= reach) for row in self.bright]

        def u32(a):
            return np.ascontiguousarray(np.asarray(a).reshape(-1), dtype=np.uint32)

        arrays = {
            "col_patch": u32(tables["col_patch"]),
            "row_patch": u32(tables["row_patch"]),
            "spans": u32(tables["spans"]),
            "bright_of_patch": u32(tables["bright_of_patch"]),
        }
        totals = np.ascontiguousarray(tables["node_totals"], dtype=np.float64)
        floats = {"node_totals": totals}
        cell_widths = np.asarray(tables["cell_widths"], dtype=np.float64).reshape(h, w)
        # The pdf's records, read with one gather each (f32: the pdf is f32).
        # A patch's widths in the four corner tables of each cell of the grid of
        # normals, over C: (patch, grid cell, corner) in `_mix`'s corner order.
        n = self.grid
        first = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).reshape(-1)
        corners = np.stack([first, first + 1, first + (n + 1), first + (n + 2)], axis=1)
        table_widths = np.asarray(tables["table_widths"], dtype=np.float64).reshape(self.patch_count, self.nodes)
        patch_tables = (table_widths[:, corners] * INV_CDF_ONE).astype(np.float32)
        if self.bilinear:
            # Node positions are computed, not read: check that the exported ones
            # are exactly the two layouts the light builds.
            for name, n, rows in (("u_nodes", iw, False), ("v_nodes", ih, self.node_rows)):
                want = self._layout(n, rows)
                if not np.array_equal(np.asarray(tables[name], np.float64), want):
                    raise ValueError(f"the product tables' {name} are not a layout this port computes")
            node_values = np.ascontiguousarray(tables["node_values"], dtype=np.float32).reshape(-1)
            # Each cell's density given its patch at its four corners (top left,
            # top right, bottom left, bottom right): the node values times the
            # cell's width over C and over the bilinear function's mass in (u, v).
            nv = node_values.astype(np.float64).reshape(ih + 2, iw + 2)
            a, b, c, d = nv[:-1, :-1], nv[:-1, 1:], nv[1:, :-1], nv[1:, 1:]
            mean = 0.25 * (((a + b) + c) + d)
            du = np.diff(self._layout(iw, False))
            dv = np.diff(self._layout(ih, self.node_rows))
            area = mean * dv[:, None] * du[None, :]
            ok = (mean > 0.0) & (area > 0.0)
            scale = np.where(ok, cell_widths * INV_CDF_ONE / np.where(ok, area, 1.0), 0.0)
            cell_density = np.stack([a * scale, b * scale, c * scale, d * scale], axis=-1).astype(np.float32)
        else:
            cell_density = (cell_widths * self.texel_scale).astype(np.float32)
        cell_density = np.ascontiguousarray(cell_density.reshape(-1))
        patch_tables = np.ascontiguousarray(patch_tables.reshape(-1))
        for name in ("cell_slots", "table_slots"):
            # (threshold, alias) pairs as one little-endian 64-bit word each.
            pairs = u32(tables[name])
            words = pairs.view(np.uint64) if pairs.size else np.zeros(1, np.uint64)
            setattr(self, name, mi.UInt64(words) if self.jit else words)
        if self.jit:
            U = mi.UInt32
            for name, a in arrays.items():
                setattr(self, name, U(a))
            for name, a in floats.items():
                setattr(self, name, mi.Float64(a))
            self.cell_density = mi.Float(cell_density)
            self.patch_tables = mi.Float(patch_tables)
        else:
            for name, a in arrays.items():
                setattr(self, name, a)
            for name, a in floats.items():
                setattr(self, name, a)
            self.cell_density = cell_density.astype(np.float64)
            self.patch_tables = patch_tables.astype(np.float64)

    @staticmethod
    def _inscribed_radius(item):
        """A lower bound of the angular radius of the largest cap around a bright
        patch's centre inside its region (radians; numpy, f64): the distances from
        the centre to the lat-long box's two parallels and, for a box narrower than
        a half turn, to its two meridians' great circles; or the cone's half-angle
        less the centre's angle from its axis."""
        cx, cy, cz = item[_BRIGHT_CENTRE]
        if item[_BRIGHT_HAS_BOX] == 0.0:
            ax, ay, az, cos_half, sin_half = item[_BRIGHT_CONE]
            half = np.arctan2(sin_half, cos_half)
            return half - np.arccos(np.clip(cx * ax + cy * ay + cz * az, -1.0, 1.0))
        e00, e01, e10, e11, narrow, s0, c0, s1, c1 = item[_BRIGHT_BOX]
        theta = np.arccos(np.clip(cz, -1.0, 1.0))
        radius = min(theta - np.arctan2(s0, c0), np.arctan2(s1, c1) - theta)
        if narrow != 0.0:
            # sin of the distance to a meridian's plane, signed positive inside.
            for side in (cy * e00 - cx * e01, cx * e11 - cy * e10):
                radius = min(radius, np.arcsin(np.clip(side, -1.0, 1.0)))
        return float(radius)

    # -- backend helpers ------------------------------------------------------------

    def _gather_u(self, table, index, active=True):
        if self.jit:
            return dr.gather(self.mi.UInt32, table, index, active)
        return int(table[int(index)]) if active else 0

    def _slot(self, slots, index):
        """(threshold, alias) of an alias-table slot, read as one 64-bit word."""
        if self.jit:
            word = dr.gather(self.mi.UInt64, slots, index)
            return self.mi.UInt32(word & 0xFFFFFFFF), self.mi.UInt32(word >> 32)
        word = int(slots[int(index)])
        return word & 0xFFFFFFFF, word >> 32

    def _gather4(self, table, index):
        """The four f32 words at 4 index of `table`."""
        if self.jit:
            a = dr.gather(self.mi.Array4f, table, index)
            return a[0], a[1], a[2], a[3]
        i = 4 * int(index)
        return tuple(float(x) for x in table[i : i + 4])

    def _gather_f(self, table, index):
        if self.jit:
            return dr.gather(self.mi.Float, table, index)
        return float(table[int(index)])

    def _gather_f64(self, table, index):
        if self.jit:
            return dr.gather(self.mi.Float64, table, index)
        return float(table[int(index)])

    def _where(self, cond, fn, otherwise, *args):
        return self.light._where(cond, fn, otherwise, *args)

    def _f64(self, x):
        return self.mi.Float64(x) if self.jit else float(x)

    def _f32(self, x):
        """An f64 rounded to f32 (an exact conversion of an f32)."""
        return self.mi.Float(x) if self.jit else float(np.float32(x))

    def _u(self, x):
        return self.mi.UInt32(x) if self.jit else int(x)

    def _not(self, mask):
        # (`~` of a Python bool is an int.)
        return ~mask if self.jit else not mask

    # -- the shading point ------------------------------------------------------------

    def _octahedral(self, x, y, z):
        """``sphere_to_octahedral``: (s, t) in [0, 1]² of a nonzero direction (f32)."""
        inv_l1 = 1.0 / ((dr.abs(x) + dr.abs(y)) + dr.abs(z))
        a = x * inv_l1
        b = y * inv_l1
        lower = z < 0.0
        a, b = (dr.select(lower, dr.copysign(1.0 - dr.abs(b), a), a),
                dr.select(lower, dr.copysign(1.0 - dr.abs(a), b), b))
        return dr.clip(0.5 * a + 0.5, 0.0, 1.0), dr.clip(0.5 * b + 0.5, 0.0, 1.0)

    def _mix(self, x, y, z):
        """``Tables::mix``: the four corner nodes of the direction's grid cell, their
        probabilities (f64), the last with weight and the nodes' totals."""
        n = self.grid
        s, t = self._octahedral(x, y, z)
        gx = s * float(n)
        gy = t * float(n)
        top = float(n - 1)
        i = self._u(dr.minimum(dr.maximum(gx, 0.0), top))
        j = self._u(dr.minimum(dr.maximum(gy, 0.0), top))
        fx = self._f64(dr.clip(gx - self.light._f(i), 0.0, 1.0))
        fy = self._f64(dr.clip(gy - self.light._f(j), 0.0, 1.0))
        first = j * (n + 1) + i
        cell = j * n + i
        node = [first, first + 1, first + (n + 1), first + (n + 2)]
        p = [(1.0 - fx) * (1.0 - fy), fx * (1.0 - fy), (1.0 - fx) * fy, fx * fy]
        totals = [self._gather_f64(self.node_totals, k) for k in node]
        if self.any_empty:
            p = [dr.select(t == 0.0, 0.0, q) for q, t in zip(p, totals)]
            total = ((p[0] + p[1]) + p[2]) + p[3]
            positive = total > 0.0
            safe = dr.select(positive, total, 1.0)
            p = [dr.select(positive, q / safe, 0.0) for q in p]
        last = 0 * i
        for m in (1, 2, 3):
            last = dr.select(p[m] > 0.0, m, last)
        return node, p, last, totals, cell

    @staticmethod
    def _pick4(values, m):
        """values[m] for a per-lane m in 0..3."""
        return dr.select(m == 0, values[0], dr.select(m == 1, values[1], dr.select(m == 2, values[2], values[3])))

    def _max_dot(self, item, v0, v1, v2, rho):
        """``Region::max_dot``: an upper bound of v·ω over the bright patch's
        directions (f32); ρ = |(v0, v1)|."""
        if item[_BRIGHT_HAS_BOX] != 0.0:
            e00, e01, e10, e11, narrow, s0, c0, s1, c1 = item[_BRIGHT_BOX]
            if narrow != 0.0:
                side0 = e00 * v1 - e01 * v0
                side1 = v0 * e11 - v1 * e10
                edges = dr.maximum(v0 * e00 + v1 * e01, v0 * e10 + v1 * e11)
                a = dr.select((side0 >= 0.0) & (side1 >= 0.0), rho, edges)
            else:
                a = rho
            b = v2
            inside_theta = ((a * c0 - b * s0) >= 0.0) & ((b * s1 - a * c1) >= 0.0)
            peak = dr.sqrt(a * a + b * b)
            ends = dr.maximum(a * s0 + b * c0, a * s1 + b * c1)
            return dr.select(inside_theta, peak, ends) + self.box_slack
        ax, ay, az, cos_half, sin_half = item[_BRIGHT_CONE]
        cos = (v0 * ax + v1 * ay) + v2 * az
        cx = v1 * az - v2 * ay
        cy = v2 * ax - v0 * az
        cz = v0 * ay - v1 * ax
        sin = dr.sqrt((cx * cx + cy * cy) + cz * cz)
        return dr.select(cos >= cos_half, 1.0, cos * cos_half + sin * sin_half)

    def point(self, nx, ny, nz):
        """``ShadingPoint::move_to`` for the cosine at normal (nx, ny, nz) (f32, any
        length): a dict of the point's state; ``anything`` False where it samples
        nothing (a zero or non-finite normal, or no light above its horizon)."""
        length = dr.sqrt((nx * nx + ny * ny) + nz * nz)
        ok = (length > 0.0) & (length < float("inf"))
        inv = 1.0 / dr.select(ok, length, 1.0)
        # The target's normal: normalised, then in the light's frame; the grid cell
        # from the normal as given in the light's frame (only its direction matters).
        ux, uy, uz = self.light.to_light(nx * inv, ny * inv, nz * inv)
        gx, gy, gz = self.light.to_light(nx, ny, nz)
        node, p, last, totals, cell = self._mix(dr.select(ok, gx, 0.0), dr.select(ok, gy, 0.0), dr.select(ok, gz, 1.0))
        p_last = self._pick4(p, last)
        tables = 0.0 * p[0]
        for m in range(4):
            tables = tables + p[m] * totals[m]
        tables = dr.select(p_last <= 0.0, 0.0, tables)
        # The bright patches' weights in f64 (as the CPU's: the picks and remaps
        # of ξ read them), their bounds over the patch in f32.
        v0, v1, v2 = ux, uy, uz
        w0, w1, w2 = self._f64(ux), self._f64(uy), self._f64(uz)
        rho = dr.sqrt(v0 * v0 + v1 * v1)
        share = self.bound_share
        weights = []
        # The horizon's band: narrowed to the lowest bright patch with weight that
        # lies wholly above the horizon (`Bright::lowest_above`): its lower bound
        # of n̂·ω, −max_dot(−n̂), if positive and below the band.
        lowest = 0.0 * v0 + self.horizon_band
        # One bound per patch is computed, at ±n̂: its weight reads the upper
        # bound only where n̂·centre < 1.001 share, and the lower bound is never
        # above n̂·centre where it is positive (the centre lies in the patch), so
        # it matters only where n̂·centre > 0. Where both hold (`rare`: a patch
        # whose centre is within 0.6° above the horizon), the lower bound is
        # computed in a branch, for the patches that can then lie wholly above the
        # horizon (`tiny`): any other reaches below it, and its lower bound is < 0.
        rare = v0 != v0
        for item, tiny in zip(self.bright, self.tiny):
            power = item[_BRIGHT_POWER]
            cx, cy, cz = item[_BRIGHT_CENTRE]
            value = (w0 * cx + w1 * cy) + w2 * cz
            floored = value < share * 1.001
            sign = dr.select(floored, 1.0, -1.0) if self.jit else (1.0 if floored else -1.0)
            bound = self._max_dot(item, sign * v0, sign * v1, sign * v2, rho)
            # The weight: power · max(n̂·c, share · max(upper, 0)) where floored,
            # which is 0 where upper ≤ 0 (then n̂·c < 0: the centre lies in the
            # patch); elsewhere power · n̂·c, which is above share · |bound|.
            o = power * dr.maximum(value, share * self._f64(dr.maximum(bound, 0.0)))
            weights.append(o)
            # Where not floored, n̂·c > 0: the weight is positive.
            lower = dr.select(floored, 2.0, -bound)
            lowest = dr.select((lower > 0.0) & (lower < lowest), lower, lowest)
            if tiny:
                rare = rare | (floored & (value > 0.0))
        if any(self.tiny):

            def narrow(lowest, v0, v1, v2, rho, w0, w1, w2):
                for item in (item for item, tiny in zip(self.bright, self.tiny) if tiny):
                    cx, cy, cz = item[_BRIGHT_CENTRE]
                    value = (w0 * cx + w1 * cy) + w2 * cz
                    lower = -self._max_dot(item, -v0, -v1, -v2, rho)
                    lowest = dr.select((value < share * 1.001) & (value > 0.0) & (lower > 0.0) & (lower < lowest),
                                       lower, lowest)
                return lowest

            lowest = self._where(rare, narrow, lambda lowest, *a: lowest, lowest, v0, v1, v2, rho, w0, w1, w2)
        bright = 0.0 * tables
        for o in weights:
            bright = bright + o
        band = dr.clip(self._f32(lowest), self.min_horizon_band, self.horizon_band)
        total = tables + bright
        anything = ok & (total > 0.0) & (total < float("inf"))
        # Shares, each with weight kept at least one CDF unit.
        only_tables = bright <= 0.0
        inv_total = 1.0 / dr.select(anything, total, 1.0)

        def floor(x):
            return dr.select(x > 0.0, dr.maximum(x, MIN_SHARE), 0.0)

        t_share = floor(tables * inv_total)
        floored = [floor(o * inv_total) for o in weights]
        s = t_share
        for o in floored:
            s = s + o
        inv_sum = 1.0 / dr.select(s > 0.0, s, 1.0)
        tables_share = dr.select(only_tables, 1.0, t_share * inv_sum)
        # (Where only the tables have weight, every bright weight and its floor is 0.)
        weights = [f * inv_sum for f in floored]
        tables_share = dr.select(anything, tables_share, 0.0)
        # The pdf's terms in f32: the tables' share times each corner's weight,
        # and the bright shares.
        return {"anything": anything, "node": node, "p": p, "last": last,
                "tables_share": tables_share, "bright": weights,
                "normal": (nx * inv, ny * inv, nz * inv), "band": band, "cell": cell,
                "tp": [self._f32(tables_share * q) for q in p],
                "bright32": [self._f32(o) for o in weights]}

    # -- picks ------------------------------------------------------------------------------

    def _alias_pick(self, slots, first, n, x):
        """``pick::pick`` over the n slots at slot `first` of `slots` (per lane)."""
        nf = self._f64(n)
        t = x * nf
        s = dr.minimum(self._u(t), n - 1)
        threshold_word, alias = self._slot(slots, first + s)
        units = (t - self._f64(s)) * CDF_ONE
        threshold = self._f64(threshold_word)
        keep = units < threshold
        index = dr.select(keep, s, alias)
        offset = dr.select(keep, units, units - threshold)
        width = dr.select(keep, threshold, CDF_ONE - threshold)
        safe = dr.select(width != 0.0, width, 1.0)
        remapped = dr.select(width != 0.0, offset / safe, 0.0)
        return index, dr.minimum(dr.maximum(remapped, 0.0), BELOW_ONE)

    def _patch_probability(self, state, k, b=None):
        """``ShadingPoint::patch_probability``: patch k's probability at the point (f32).
        ``b``: k's place among the bright patches (``NO_BRIGHT`` if none) where the
        caller knows it, else read from the table."""
        prob = self._tables_probability(state, k)
        if not self.bright:
            return prob
        if b is None:
            b = self._gather_u(self.bright_of_patch, k)
        for c, weight in enumerate(state["bright32"]):
            prob = dr.select(b == c, weight, prob)
        return prob

    def _tables_probability(self, state, k):
        """Patch k's probability from the tables' component (0 for a bright patch)."""
        w = self._gather4(self.patch_tables, k * (self.grid * self.grid) + state["cell"])
        tp = state["tp"]
        return (tp[0] * w[0] + tp[1] * w[1]) + (tp[2] * w[2] + tp[3] * w[3])

    @staticmethod
    def _clamp_xi(xi):
        return dr.minimum(dr.maximum(xi, 0.0) + XI_HALF_QUANTUM, BELOW_ONE)

    # -- cells ----------------------------------------------------------------------------

    def _cell_of(self, u, v):
        """``Fine::cell_of`` on both axes: the cell holding image point (u, v)."""
        return self._cell_axis(u, 0), self._cell_axis(v, 1)

    def _cell_axis(self, x, axis):
        """``Fine::cell_of`` along u (axis 0) or v (axis 1)."""
        n = self.iw if axis == 0 else self.ih
        if not self.bilinear:
            return self.light._cell_index(x, n)
        # In f32, from one fused multiply-add (the CPU's f64 differs only for
        # points within an f32 ulp of a cell's edge).
        if axis == 1 and self.node_rows:
            # The node lookup's rows along v (0, 0, j/(h − 1), 1, 1): cell k ≥ 1 is
            # [(k − 1)/(h − 1), k/(h − 1)); the zero-width end cells are never found.
            t = dr.maximum(x * float(n - 1), 0.0)
            return 1 + dr.minimum(self._u(t), n - 2)
        # Nodes at 0, (i + ½)/n, 1: cell i is [(i − ½)/n, (i + ½)/n).
        t = dr.maximum(dr.fma(x, float(n), 0.5), 0.0)
        return dr.minimum(self._u(t), n)

    @staticmethod
    def _layout(n, rows):
        """The light's node positions along an axis of n texels (numpy, f64):
        0, (k − ½)/n for 1 ≤ k ≤ n, 1; or the node rows 0, 0, j/(n − 1), 1, 1."""
        k = np.arange(1, n + 1, dtype=np.float64)
        inner = (k - 1.0) / float(n - 1) if rows else (k - 0.5) / float(n)
        return np.concatenate([[0.0], inner, [1.0]])

    def _node_at(self, k, n, rows):
        """Node k of `_layout(n, rows)` (f64; times the reciprocal of its divisor,
        within an ulp of the layout's quotient: the placement rounds to f32)."""
        x = (self._f64(k) - (1.0 if rows else 0.5)) * (1.0 / float(n - 1 if rows else n))
        return dr.select(k == 0, 0.0, dr.select(k > n, 1.0, x))

    def _nodes(self, i, j):
        iw, ih, rows = self.iw, self.ih, self.node_rows
        return (self._node_at(i, iw, False), self._node_at(i + 1, iw, False),
                self._node_at(j, ih, rows), self._node_at(j + 1, ih, rows))

    @staticmethod
    def _sample_linear(xi, a, b):
        """``bilinear::sample_linear`` in f64: x ∈ [0, 1) from the density ∝ a (1 − x) + b x."""
        # Not `_drjit_tables.TableLight._sample_linear` on purpose: that one is the
        # WGSL's (f32, normalised by max(a, b), clamped below 1 − 2⁻²⁴) for the
        # light's sampling; this is the CPU product sampler's, in f64, unnormalised,
        # clamped below 1 − 2⁻⁵³. Sharing one would change results in the last bits.
        denominator = a + dr.sqrt((1.0 - xi) * a * a + xi * b * b)
        ok = denominator > 0.0
        x = dr.clip(xi * (a + b) / dr.select(ok, denominator, 1.0), 0.0, BELOW_ONE)
        return dr.select(a == b, xi, dr.select(ok, x, 0.0))

    def _place(self, axis, cell, x):
        """``Fine::place``: x rounded to f32, then moved by ulps (at most 4) into `cell`."""
        p = dr.clip(self._f32(x), 0.0, float(np.float32(1.0) - np.float32(2.0**-24)))
        return self.light.into_cell(p, cell, lambda p: self._cell_axis(p, axis))

    def _axis_fraction(self, x, i, n, rows):
        """Where x lies in bilinear cell i of an axis of n texels, in [0, 1] (f32):
        nodes as `_layout(n, rows)`, from one fused multiply-add."""
        if rows:
            # Cells 1 ≤ i ≤ n − 1 of width 1/(n − 1), from (i − 1)/(n − 1).
            t = dr.fma(x, float(n - 1), -self.light._f(i - 1))
        else:
            # Cell 0 is [0, ½/n), cell n [(n − ½)/n, 1], the others (i ± ½)/n.
            ends = (i == 0) | (i == n)
            origin = dr.select(i == 0, 0.0, dr.select(i == n, float(n) - 0.5, self.light._f(i) - 0.5))
            t = dr.fma(x, float(n), -origin)
            t = dr.select(ends, 2.0 * t, t)
        return dr.clip(t, 0.0, 1.0)

    def _cell_record(self, i, j):
        """Cell (i, j)'s density record: its density (constant), or its density at
        its four corners (bilinear)."""
        index = j * self.w + i
        if not self.bilinear:
            return self._gather_f(self.cell_density, index)
        return self._gather4(self.cell_density, index)

    def _density_in_cell(self, i, j, u, v, record=None):
        """``Fine::locate``'s density at (u, v) of cell (i, j), given its patch (f32)."""
        if record is None:
            record = self._cell_record(i, j)
        if not self.bilinear:
            return record
        a, b, c, d = record
        x = self._axis_fraction(u, i, self.iw, False)
        y = self._axis_fraction(v, j, self.ih, self.node_rows)
        return (1.0 - y) * (a + (b - a) * x) + y * (c + (d - c) * x)

    def planar_pdf(self, state, u, v):
        """The density in (u, v) at the point (``ShadingPoint::pdf`` before dω)."""
        i, j = self._cell_of(u, v)
        k = self._gather_u(self.row_patch, j) * self.pw + self._gather_u(self.col_patch, i)
        planar = self._patch_probability(state, k) * self._density_in_cell(i, j, u, v)
        return dr.select(state["anything"], planar, 0.0)

    def _uv_pdf(self, state, u, v, inv_j):
        """The density of the draws before the horizon's reflection, per steradian,
        at the direction of image point (u, v) with du dv / dω = inv_j."""
        return self._finite_pdf(self.planar_pdf(state, u, v) * inv_j, inv_j)

    @staticmethod
    def _finite_pdf(pdf, inv_j):
        return dr.select((inv_j < float("inf")) & (pdf < float("inf")), pdf, 0.0)

    def _drawn_pdf(self, state, dx, dy, dz):
        """The density of the draws before the horizon's reflection."""
        return self._uv_pdf(state, *self.light.local_to_uv(*self.light.to_light(dx, dy, dz)))

    def _horizon(self, state, dx, dy, dz):
        """n̂·ω for a world direction, and its mirror image in the tangent plane."""
        mx, my, mz = state["normal"]
        c = (mx * dx + my * dy) + mz * dz
        twice = 2.0 * c
        return c, (dx - mx * twice, dy - my * twice, dz - mz * twice)

    def pdf(self, nx, ny, nz, dx, dy, dz, state=None):
        """The pdf per steradian of direction (dx, dy, dz) at normal (nx, ny, nz):
        the draws' density, plus its mirror image's within the horizon's band
        above the horizon, 0 within the band below (``ShadingPoint::pdf``)."""
        if state is None:
            state = self.point(nx, ny, nz)
        s = state["band"]
        c, mirror = self._horizon(state, dx, dy, dz)
        own = self._drawn_pdf(state, dx, dy, dz)
        band = (c < s) & (c > -s)
        both = own + self._where(band & (c >= 0.0), lambda x, y, z: self._drawn_pdf(state, x, y, z),
                                 lambda x, y, z: 0.0 * x, *mirror)
        return dr.select(band, dr.select(c < 0.0, 0.0 * own, both), own)

    def sample(self, nx, ny, nz, xi0, xi1, outer=None):
        """A direction for ξ ∈ [0, 1)² at normal (nx, ny, nz): ((x, y, z) world, pdf
        per steradian, (r, g, b), valid), as ``TableLight.sample`` returns one."""
        state = self.point(nx, ny, nz)
        x = self._clamp_xi(self._f64(xi0))
        y = self._clamp_xi(self._f64(xi1))
        ts = state["tables_share"]
        # A table of the mix (`sample_tables`).
        p = state["p"]
        xt = dr.minimum(x / dr.select(ts > 0.0, ts, 1.0), BELOW_ONE)
        ends = [p[0], p[0] + p[1], (p[0] + p[1]) + p[2]]
        passed = 0 * state["last"]
        for e in ends:
            passed = passed + dr.select(xt >= e, 1, 0)
        m = dr.minimum(passed, state["last"])
        below = dr.select(m == 0, 0.0, self._pick4([0.0 * xt, ends[0], ends[1], ends[2]], m))
        pm = self._pick4(p, m)
        xt = dr.clip((xt - below) / dr.select(pm > 0.0, pm, 1.0), 0.0, BELOW_ONE)
        node_m = self._pick4(state["node"], m)
        kt, yt = self._alias_pick(self.table_slots, node_m * self.patch_count, self.patch_count, y)
        # A bright patch: the first whose running sum passes x.
        b = 0 * state["last"]
        start = ts
        end = ts
        done = x < ts
        for c, weight in enumerate(state["bright"]):
            take = self._not(done) & (weight > 0.0)
            b = dr.select(take, c, b)
            start = dr.select(take, end, start)
            end = dr.select(take, end + weight, end)
            done = done | (take & (x < end))
        weight_b = 0.0 * x
        patch_b = 0 * b
        for c, weight in enumerate(state["bright"]):
            weight_b = dr.select(b == c, weight, weight_b)
            patch_b = dr.select(b == c, int(self.bright[c][_BRIGHT_PATCH]), patch_b)
        xb = dr.clip((x - start) / dr.select(weight_b > 0.0, weight_b, 1.0), 0.0, BELOW_ONE)
        in_tables = x < ts
        k = dr.select(in_tables, kt, patch_b)
        fx = dr.select(in_tables, xt, xb)
        fy = dr.select(in_tables, yt, y)
        # A texel of the patch and a point in it (`Fine::sample`).
        span = 5 * k
        x0 = self._gather_u(self.spans, span)
        y0 = self._gather_u(self.spans, span + 1)
        cols = self._gather_u(self.spans, span + 2)
        rows = self._gather_u(self.spans, span + 3)
        first = self._gather_u(self.spans, span + 4)
        cell, frac_u = self._alias_pick(self.cell_slots, first, cols * rows, fx)
        # (cell + ½)/cols is at least ½/cols from a whole number: f32 finds its floor.
        row = self._u((self.light._f(cell) + 0.5) / self.light._f(cols))
        column = cell - row * cols
        i = x0 + column
        j = y0 + row
        light = self.light
        if self.bilinear:
            # The cell's density record: its corners up to a common factor, which
            # the linear densities do not read.
            record = self._cell_record(i, j)
            a, b_, c, d = (self._f64(x) for x in record)
            ty = self._sample_linear(fy, a + b_, c + d)
            tx = self._sample_linear(frac_u, a + (c - a) * ty, b_ + (d - b_) * ty)
            u0, u1, v0, v1 = self._nodes(i, j)
            u = self._place(0, i, u0 + tx * (u1 - u0))
            v = self._place(1, j, v0 + ty * (v1 - v0))
            cu = self._f32(0.5 * (u0 + u1))
            cv = self._f32(0.5 * (v0 + v1))
        else:
            record = self._cell_record(i, j)
            u = light._nudge_into_cell(self._f32((self._f64(i) + frac_u) * (1.0 / self.iw)), i, self.iw)
            v = light._nudge_into_cell(self._f32((self._f64(j) + fy) * (1.0 / self.ih)), j, self.ih)
            cu = (light._f(i) + 0.5) / float(self.iw)
            cv = (light._f(j) + 0.5) / float(self.ih)
        (dx, dy, dz), bu, bv, inv_j = light.settle(u, v, i, j, cu, cv, self._cell_of, outer)
        # A draw just below the horizon is returned as its mirror image (in the
        # tables' world frame, inside any outer frame), with that direction's image
        # point and radiance. The pdf is `pdf` at the returned direction, from the
        # two densities it adds: the draws' density at the drawn direction t (its
        # image point is settle's, so it is not located again) and at the other
        # one of the pair (t's mirror image, or the returned direction when t is
        # reflected), which is located only where the horizon's band needs it.
        outer_to_world, outer_to_light = outer if outer is not None else (None, None)
        t = outer_to_light(dx, dy, dz) if outer is not None else (dx, dy, dz)
        s = state["band"]
        c, (rx, ry, rz) = self._horizon(state, *t)
        reflect = (c < 0.0) & (c > -s)
        r = outer_to_world(rx, ry, rz) if outer is not None else (rx, ry, rz)
        dx, dy, dz = (dr.select(reflect, a, b) for a, b in zip(r, (dx, dy, dz)))
        r_light = outer_to_light(*r) if outer is not None else r
        # n̂·ω of the returned direction, as `pdf` computes it there.
        c = dr.select(reflect, self._horizon(state, *r_light)[0], c)
        band = (c < s) & (c > -s)
        # The draws' density at t, as `pdf` computes it there: from the sampled
        # cell's record and patch where settle left its image point in that cell,
        # else located afresh (in a branch).
        ju, jv = self._cell_of(bu, bv)
        # The tables give the bright patches no weight: a patch drawn from them is
        # not one.
        prob = self._patch_probability(state, k, dr.select(in_tables, NO_BRIGHT, b))
        planar = dr.select(state["anything"], prob * self._density_in_cell(i, j, bu, bv, record), 0.0)
        known = self._finite_pdf(planar * inv_j, inv_j)
        drawn = self._where((ju != i) | (jv != j), lambda u, v, w, p: self._uv_pdf(state, u, v, w),
                            lambda u, v, w, p: p, bu, bv, inv_j, known)
        q = [dr.select(reflect, a, b) for a, b in zip(r_light, (rx, ry, rz))]

        def locate(x, y, z, bu, bv):
            ou, ov, oj = light.local_to_uv(*light.to_light(x, y, z))
            return ou, ov, self._uv_pdf(state, ou, ov, oj)

        ou, ov, other = self._where(band | reflect, locate, lambda x, y, z, bu, bv: (bu, bv, 0.0 * bu), *q, bu, bv)
        # A reflected draw's own density is read at the mirror image of the
        # returned direction, as `pdf` reads it (not at t, which it equals only up
        # to rounding).
        mirror = self._horizon(state, *r_light)[1]
        drawn = self._where(reflect, lambda x, y, z, p: self._drawn_pdf(state, x, y, z),
                            lambda x, y, z, p: p, *mirror, drawn)
        bu = dr.select(reflect, ou, bu)
        bv = dr.select(reflect, ov, bv)
        pdf = dr.select(band, dr.select(c < 0.0, 0.0 * drawn, drawn + other), dr.select(reflect, other, drawn))
        valid = state["anything"] & (pdf > 0.0) & (pdf < float("inf"))
        rgb = light.lookup(bu, bv)
        zero = 0.0 * inv_j
        pdf = dr.select(valid, pdf, 0.0)
        rgb = tuple(dr.select(valid, c, zero) for c in rgb)
        return (dx, dy, dz), pdf, rgb, valid
