// envlight on a GPU: sampling, pdf and radiance of an environment light over the
// flat tables of docs/gpu-tables.md (layout version 1). The CPU light builds the
// tables; this module only reads them, with the CPU's algorithms step for step:
//
// - the same fixed-point CDF search (ξ is put on the 2³²−1 scale exactly, with
//   integer arithmetic, so the cell a ξ picks is the CPU's);
// - the same alias test on a 48-bit fraction (exact integer arithmetic);
// - the same point placement and nudge into the chosen cell, in f32.
//
// Precision (WGSL has no f64): the returned direction is rounded in f32 as on the
// CPU, but from f32 trigonometry, whose round trip (point → direction → point)
// can carry a point near a cell edge into the neighbour cell. Two rules keep the
// pdf exact: a sampled point whose direction does not map back into its cell is
// nudged towards the cell's centre until it does (`settle_in_cell`), and a
// sample's pdf and radiance are then evaluated at the returned direction
// (`light_eval`), never taken from the chosen cell. So the pdf a caller gets is
// always the density where the direction landed, `light_pdf(sample.direction)
// == sample.pdf` on the GPU by construction, and it is the chosen cell's density,
// as on the CPU. Should a direction still land in a cell of zero density, the
// sample is reported as none (pdf 0).
//
// Library functions: `light_sample(xi) -> LightSample`, `light_pdf(d) -> f32`,
// `light_radiance(d) -> vec3<f32>`, `light_eval(d) -> Eval`. Entry points below
// run them over buffers (`sample_main`, `pdf_main`, `radiance_main`, `eval_main`).

// ---------------------------------------------------------------------------
// Bindings
// ---------------------------------------------------------------------------

// The parameter block (section 1): 64 words.
struct Params {
    light_to_world: array<vec4<f32>, 3>,
    world_to_light: array<vec4<f32>, 3>,
    version: u32,
    sampler: u32,
    density: u32,
    mapping: u32,
    lookup: u32,
    radiance_format: u32,
    rotated: u32,
    black: u32,
    image_width: u32,
    image_height: u32,
    table_width: u32,
    table_height: u32,
    scale: f32,
    integral_luminance: f32,
    marginal_cdf: u32,
    marginal_guide: u32,
    marginal_guide_shift: u32,
    conditional_cdf: u32,
    conditional_guide: u32,
    conditional_guide_bits: u32,
    alias_slots: u32,
    alias_func: u32,
    alias_offset_bits: u32,
    alias_inv_integral: f32,
    bilinear_values: u32,
    tables_words: u32,
    bilinear_v_nodes: u32,
    reserved1: u32,
    reserved: array<vec4<u32>, 3>,
}

// One dispatch: `count` rows; `mode` 1 draws ξ from the seed (envlight::rng::xi_2d
// of `seed`, index `first + row`), 0 reads them from `inputs`.
struct Batch {
    count: u32,
    mode: u32,
    seed_lo: u32,
    seed_hi: u32,
    first_lo: u32,
    first_hi: u32,
    reserved0: u32,
    reserved1: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> tables: array<u32>;
@group(0) @binding(2) var<storage, read> radiance_texels: array<u32>;
@group(0) @binding(3) var<uniform> batch: Batch;
// sample: ξ as 2 floats per row; pdf, radiance, eval: directions as 4 floats per row (x, y, z, unused).
@group(0) @binding(4) var<storage, read> inputs: array<f32>;
// sample: 8 floats per row (x, y, z, pdf, r, g, b, 1 if sampled else 0);
// pdf: 1 per row; radiance: 4 per row (r, g, b, 0); eval: 4 per row (pdf, r, g, b).
@group(0) @binding(5) var<storage, read_write> outputs: array<f32>;

// ---------------------------------------------------------------------------
// Constants and small helpers
// ---------------------------------------------------------------------------

// dω / du dv of the equirectangular map, divided by sin θ.
const EQUIRECT_JACOBIAN: f32 = 19.7392088021787172;
// dω / du dv of the equal-area square.
const EQUAL_AREA_JACOBIAN: f32 = 12.5663706143591730;
// The largest f32 below 1.
const ONE_MINUS_EPSILON: f32 = 0x1.fffffep-1;
// 2⁻³²: CDF widths are probabilities on the 2³² − 1 scale; the difference from
// 2³² is 2⁻³² relative, far below f32's resolution.
const INV_CDF_ONE: f32 = 0x1p-32;
// The largest finite f32: radiance is clamped to it, as the CPU's lookups are.
const F32_MAX: f32 = 0x1.fffffep+127;

const SAMPLER_ALIAS: u32 = 1u;
const DENSITY_BILINEAR: u32 = 1u;
const MAPPING_EQUAL_AREA: u32 = 1u;
const LOOKUP_BILINEAR: u32 = 1u;
const LOOKUP_NODE: u32 = 2u;
const V_NODES_NODE_ROWS: u32 = 1u;
const RADIANCE_F16: u32 = 1u;

// (sin πx, cos πx) to about 2 f32 ulps, with no rounding of π x (full relative
// precision near the poles, as the CPU's sin_cos_pi): x = k/2 + r with k =
// round(2x) and |r| ≤ ¼ split exactly, then Taylor polynomials of sin πr (to
// degree 11) and cos πr (to degree 12), whose truncation errors are below 3e-9
// relative on |πr| ≤ π/4, and the quadrant k mod 4 by symmetry. (A table of
// angles, as the CPU uses, costs a GPU a copy of the table in every call.)
fn sin_cos_pi(x: f32) -> vec2<f32> {
    let k = round(2.0 * x);
    let r = x - 0.5 * k;
    let r2 = r * r;
    let s = r * (3.141592653589793 + r2 * (-5.167712780049969 + r2 * (2.550164039877345
        + r2 * (-0.5992645293207919 + r2 * (0.08214588661112819 + r2 * -0.007370430945714348)))));
    let c = 1.0 + r2 * (-4.934802200544679 + r2 * (4.058712126416768 + r2 * (-1.3352627688545893
        + r2 * (0.23533063035889312 + r2 * (-0.02580689139001405 + r2 * 0.001929574309403922)))));
    switch bitcast<u32>(i32(k)) & 3u {
        case 0u: { return vec2<f32>(s, c); }
        case 1u: { return vec2<f32>(c, -s); }
        case 2u: { return vec2<f32>(-s, -c); }
        default: { return vec2<f32>(-c, s); }
    }
}

// tan(π/8): above it, atan's argument is reflected about 1.
const TAN_PI_8: f32 = 0.41421356237309503;
const INV_PI: f32 = 0.31830988618379067;

// atan2(y, x) / π in (−1, 1] (0 for (0, 0)), to about an f32 ulp: the CPU's
// reduction to [0, tan(π/8)] and its degree-11 polynomial, in units of half
// turns so that the octant offsets (¼, ½, 1) are exact and u = φ / 2π, v = θ / π
// need no division by a rounded π.
fn atan2_pi(y: f32, x: f32) -> f32 {
    let ax = abs(x);
    let ay = abs(y);
    let swapped = ay > ax;
    let num = select(ay, ax, swapped);
    let den = select(ax, ay, swapped);
    if !(den > 0.0) {
        return 0.0;
    }
    var arg = num / den;
    var offset = 0.0;
    if num > TAN_PI_8 * den {
        arg = (num - den) / (num + den);
        offset = 0.25;
    }
    let s = arg * arg;
    let s2 = s * s;
    let poly = (0.9999999994146261 + -0.3333330810928512 * s)
        + s2 * ((0.1999823912927692 + -0.14240442565012187 * s)
        + s2 * (0.1057586606855873 + -0.06040340948571631 * s));
    var a = offset + arg * poly * INV_PI;
    if swapped {
        a = 0.5 - a;
    }
    if x < 0.0 {
        a = 1.0 - a;
    }
    if y < 0.0 {
        a = -a;
    }
    return a;
}

fn table_f32(at: u32) -> f32 {
    return bitcast<f32>(tables[at]);
}

// ⌊x⌋ clamped into [0, n − 1]; NaN gives 0 (the CPU's floor_index).
fn floor_index(x: f32, n: u32) -> u32 {
    if !(x > 0.0) {
        return 0u;
    }
    if x >= f32(n) {
        return n - 1u;
    }
    return min(u32(x), n - 1u);
}

// The cell of x ∈ [0, 1] on a grid of n cells: ⌊x n⌋ clamped.
fn cell_index(x: f32, n: u32) -> u32 {
    return floor_index(x * f32(n), n);
}

fn next_up(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) + 1u);
}

fn next_down(x: f32) -> f32 {
    if x <= 0.0 {
        return x;
    }
    return bitcast<f32>(bitcast<u32>(x) - 1u);
}

// Moves x (within a few ulps of cell `cell` of n) into that cell, and below 1.
fn nudge_into_cell(x_in: f32, cell: u32, n: u32) -> f32 {
    var x = min(x_in, ONE_MINUS_EPSILON);
    for (var k = 0; k < 4; k++) {
        let c = cell_index(x, n);
        if c > cell {
            x = next_down(x);
        } else if c < cell {
            x = next_up(x);
        } else {
            break;
        }
    }
    return x;
}

// |v| with the sign of s.
fn copysign(v: f32, s: f32) -> f32 {
    return bitcast<f32>((bitcast<u32>(v) & 0x7fffffffu) | (bitcast<u32>(s) & 0x80000000u));
}

// x clamped into [0, 1]; NaN gives 0.
fn unit_closed(x: f32) -> f32 {
    if x > 0.0 {
        return min(x, 1.0);
    }
    return 0.0;
}

// ---------------------------------------------------------------------------
// Fixed-point CDFs (sections 2–5)
// ---------------------------------------------------------------------------

// ξ on the CDF's fixed-point scale: t = ξ · (2³² − 1) = x + frac with x = ⌊t⌋.
// s = ξ · 2³² is exact in f32 (a power-of-two scaling), and t = s − ξ: its integer
// and fractional parts follow from those of s exactly, so x is the CPU's (which
// computes t in f64) bit for bit.
struct Fixed {
    x: u32,
    frac: f32,
}

fn to_fixed(xi: f32) -> Fixed {
    if !(xi > 0.0) {
        return Fixed(0u, 0.0);
    }
    if xi >= 1.0 {
        return Fixed(0xfffffffeu, 0.0);
    }
    let s = xi * 4294967296.0;
    let whole = floor(s);
    let fraction = s - whole;
    if fraction >= xi {
        return Fixed(u32(whole), fraction - xi);
    }
    // s > ξ and the fraction is smaller, so s ≥ 1.
    return Fixed(u32(whole) - 1u, fraction - xi + 1.0);
}

struct CdfSample {
    cell: u32,
    // Where ξ fell within the cell's CDF segment, in [0, 1].
    offset: f32,
}

// The cell of a CDF of n cells (words cdf..cdf+n+1) holding ξ, found from the guide
// table at `guide` (shift = 32 − log2 of its length), then a short forward scan.
fn cdf_sample(cdf: u32, guide: u32, shift: u32, n: u32, xi: f32) -> CdfSample {
    let f = to_fixed(xi);
    var slice = 0u;
    if shift < 32u {
        slice = f.x >> shift;
    }
    var o = tables[guide + slice];
    // c[n] = 2³² − 1 > x, so the scan ends by o = n − 1; the bound is a guard.
    while o + 1u < n && tables[cdf + o + 1u] <= f.x {
        o += 1u;
    }
    let lo = tables[cdf + o];
    let width = tables[cdf + o + 1u] - lo;
    var offset = 0.0;
    if width > 0u {
        offset = (f32(f.x - lo) + f.frac) / f32(width);
    }
    return CdfSample(o, offset);
}

// The widths [w_u, w_v] of cell (iu, iv) of the 2D table.
fn cell_widths(iu: u32, iv: u32) -> vec2<u32> {
    let row = params.conditional_cdf + iv * (params.table_width + 1u) + iu;
    let wu = tables[row + 1u] - tables[row];
    let m = params.marginal_cdf + iv;
    let wv = tables[m + 1u] - tables[m];
    return vec2<u32>(wu, wv);
}

// The probability of a cell from its CDF widths.
fn probability_of_widths(w: vec2<u32>) -> f32 {
    return (f32(w.x) * INV_CDF_ONE) * (f32(w.y) * INV_CDF_ONE);
}

// ξ → (cell, offsets): the marginal picks the row with ξ.y, the row's
// conditional the column with ξ.x.
struct CellSample {
    cell: vec2<u32>,
    offset: vec2<f32>,
}

fn sample_cell(xi: vec2<f32>) -> CellSample {
    let nu = params.table_width;
    let nv = params.table_height;
    let m = cdf_sample(params.marginal_cdf, params.marginal_guide, params.marginal_guide_shift, nv, xi.y);
    let bits = params.conditional_guide_bits;
    let row_cdf = params.conditional_cdf + m.cell * (nu + 1u);
    let row_guide = params.conditional_guide + m.cell * (1u << bits);
    let c = cdf_sample(row_cdf, row_guide, 32u - bits, nu, xi.x);
    return CellSample(vec2<u32>(c.cell, m.cell), vec2<f32>(c.offset, m.offset));
}

// ---------------------------------------------------------------------------
// Piecewise-constant density: inversion and alias
// ---------------------------------------------------------------------------

fn place_in_cell(cell: u32, offset: f32, n: u32) -> f32 {
    return nudge_into_cell((f32(cell) + offset) / f32(n), cell, n);
}

// A point drawn in the image and the cell (or bilinear patch) it was drawn in.
struct PlanarSample {
    uv: vec2<f32>,
    cell: vec2<u32>,
}

fn sample_inversion(xi: vec2<f32>) -> PlanarSample {
    let c = sample_cell(xi);
    let uv = vec2<f32>(
        place_in_cell(c.cell.x, c.offset.x, params.table_width),
        place_in_cell(c.cell.y, c.offset.y, params.table_height),
    );
    return PlanarSample(uv, c.cell);
}

fn pdf_constant(uv: vec2<f32>) -> f32 {
    let iu = cell_index(uv.x, params.table_width);
    let iv = cell_index(uv.y, params.table_height);
    if params.sampler == SAMPLER_ALIAS {
        let f = table_f32(params.alias_func + iv * params.table_width + iu);
        return f * params.alias_inv_integral;
    }
    let cells = f32(params.table_width) * f32(params.table_height);
    return probability_of_widths(cell_widths(iu, iv)) * cells;
}

// 48-bit unsigned integers as (low 32 bits, high bits).
fn lt48(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}

fn sub48(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x - b.x;
    let borrow = select(0u, 1u, a.x < b.x);
    return vec2<u32>(lo, a.y - b.y - borrow);
}

fn shl1_48(a: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x << 1u, (a.y << 1u) | (a.x >> 31u));
}

// The full 64-bit product of two u32, as (low, high).
fn mul_wide(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let p00 = a0 * b0;
    let p01 = a0 * b1;
    let p10 = a1 * b0;
    let p11 = a1 * b1;
    let mid = (p00 >> 16u) + (p01 & 0xffffu) + (p10 & 0xffffu);
    let lo = (p00 & 0xffffu) | (mid << 16u);
    let hi = p11 + (p01 >> 16u) + (p10 >> 16u) + (mid >> 16u);
    return vec2<u32>(lo, hi);
}

// ⌈threshold · 2⁴⁸⌉ for a threshold in [0, 1], exactly, from its bits. For an
// integer fraction F, F < threshold · 2⁴⁸ exactly when F < ⌈threshold · 2⁴⁸⌉.
fn keep_limit(threshold: f32) -> vec2<u32> {
    if !(threshold > 0.0) {
        return vec2<u32>(0u, 0u);
    }
    if threshold >= 1.0 {
        return vec2<u32>(0u, 0x10000u);
    }
    let bits = bitcast<u32>(threshold);
    let e = (bits >> 23u) & 0xffu;
    if e == 0u {
        // Subnormal: below 2⁻¹²⁶, so the product is below 1 and positive.
        return vec2<u32>(1u, 0u);
    }
    // threshold = m · 2^(e − 150), so threshold · 2⁴⁸ = m · 2^(e − 102).
    let m = (bits & 0x7fffffu) | 0x800000u;
    if e >= 102u {
        let s = e - 102u;
        var hi = 0u;
        if s > 0u {
            hi = m >> (32u - s);
        }
        return vec2<u32>(m << s, hi);
    }
    let r = 102u - e;
    if r >= 24u {
        return vec2<u32>(1u, 0u);
    }
    return vec2<u32>((m + (1u << r) - 1u) >> r, 0u);
}

// ⌊a · 2⁴⁸ / b⌋ for 0 ≤ a < b ≤ 2⁴⁸ (restoring division, one bit a step).
fn fraction48(a_in: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    var a = a_in;
    var q = vec2<u32>(0u, 0u);
    for (var k = 0; k < 48; k++) {
        a = shl1_48(a);
        q = shl1_48(q);
        if !lt48(a, b) {
            a = sub48(a, b);
            q.x = q.x | 1u;
        }
    }
    return q;
}

// A 48-bit integer (or fewer bits) as f32, times 2^-`bits`.
fn scaled48(a: vec2<u32>, bits: u32) -> f32 {
    let value = f32(a.y) * 4294967296.0 + f32(a.x);
    return value * exp2(-f32(bits));
}

fn fixed_24(xi: f32) -> u32 {
    if !(xi > 0.0) {
        return 0u;
    }
    return min(u32(xi * 16777216.0), 16777215u);
}

fn sample_alias(xi: vec2<f32>) -> PlanarSample {
    let nu = params.table_width;
    let nv = params.table_height;
    let n = nu * nv;
    // B = ⌊2²⁴ ξ0⌋ · 2²⁴ + ⌊2²⁴ ξ1⌋, and B n = slot · 2⁴⁸ + F, all exact.
    let a = fixed_24(xi.x);
    let b = fixed_24(xi.y);
    let b_lo = (a << 24u) | b;
    let b_hi = a >> 8u;
    let low = mul_wide(b_lo, n);
    let high = mul_wide(b_hi, n);
    let w1 = low.y + high.x;
    let carry = select(0u, 1u, w1 < low.y);
    let w2 = high.y + carry;
    let slot = (w1 >> 16u) | (w2 << 16u);
    let fraction = vec2<u32>(low.x, w1 & 0xffffu);
    let threshold = table_f32(params.alias_slots + 2u * slot);
    let keep = keep_limit(threshold);
    var index = slot;
    var above = fraction;
    var span = keep;
    if !lt48(fraction, keep) {
        index = tables[params.alias_slots + 2u * slot + 1u];
        above = sub48(fraction, keep);
        span = sub48(vec2<u32>(0u, 0x10000u), keep);
    }
    // The leftover above / span in [0, 1) as a 48-bit fraction: its top
    // `offset_bits` bits place the point along u, the rest along v.
    var q = vec2<u32>(0u, 0u);
    if lt48(above, span) {
        q = fraction48(above, span);
    }
    let k = params.alias_offset_bits;
    let s = 48u - k;
    var coarse = 0u;
    if s >= 32u {
        coarse = q.y >> (s - 32u);
    } else {
        coarse = (q.x >> s) | (q.y << (32u - s));
    }
    var rest = vec2<u32>(q.x, q.y);
    if s >= 32u {
        rest.y = q.y & ((1u << (s - 32u)) - 1u);
    } else {
        rest = vec2<u32>(q.x & ((1u << s) - 1u), 0u);
    }
    let du = f32(coarse) * exp2(-f32(k));
    let dv = min(scaled48(rest, s), ONE_MINUS_EPSILON);
    let iv = index / nu;
    let iu = index % nu;
    let uv = vec2<f32>(place_in_cell(iu, du, nu), place_in_cell(iv, dv, nv));
    return PlanarSample(uv, vec2<u32>(iu, iv));
}

// ---------------------------------------------------------------------------
// Piecewise-bilinear density
// ---------------------------------------------------------------------------

// Node j of an axis of n texels: 0, (j − ½)/n for 1 ≤ j ≤ n, 1.
fn node(j: u32, n: u32) -> f32 {
    if j == 0u {
        return 0.0;
    }
    if j > n {
        return 1.0;
    }
    return (f32(j) - 0.5) / f32(n);
}

// Width of patch j of an axis of n texels: ½ texel at either end, 1 inside.
fn patch_width(j: u32, n: u32) -> f32 {
    if j == 0u || j == n {
        return 0.5 / f32(n);
    }
    return 1.0 / f32(n);
}

// The patch holding x ∈ [0, 1] on an axis of n texels: ⌊x n + ½⌋ (at most n).
fn patch_of(x: f32, n: u32) -> u32 {
    return min(u32(x * f32(n) + 0.5), n);
}

// Along v the nodes are the texel centres as along u, or (`bilinear_v_nodes` 1,
// the node lookup) the rows from pole to pole: 0, 0, (k − 1)/(h − 1) for
// 1 ≤ k ≤ h, 1, whose end patches have zero width and are never found.
fn v_node(k: u32, h: u32) -> f32 {
    if params.bilinear_v_nodes != V_NODES_NODE_ROWS {
        return node(k, h);
    }
    if k == 0u {
        return 0.0;
    }
    if k > h {
        return 1.0;
    }
    return f32(k - 1u) / f32(h - 1u);
}

fn v_patch_width(k: u32, h: u32) -> f32 {
    if params.bilinear_v_nodes != V_NODES_NODE_ROWS {
        return patch_width(k, h);
    }
    if k == 0u || k == h {
        return 0.0;
    }
    return 1.0 / f32(h - 1u);
}

// The patch holding v ∈ [0, 1]: 1 + min(⌊v (h − 1)⌋, h − 2) on the node rows.
fn v_patch_of(v: f32, h: u32) -> u32 {
    if params.bilinear_v_nodes != V_NODES_NODE_ROWS {
        return patch_of(v, h);
    }
    return 1u + min(u32(v * f32(h - 1u)), h - 2u);
}

// The corners (f00, f10, f01, f11) of patch (i, k).
fn corners(i: u32, k: u32) -> vec4<f32> {
    let mu = params.image_width + 2u;
    let top = params.bilinear_values + k * mu + i;
    let bottom = top + mu;
    return vec4<f32>(table_f32(top), table_f32(top + 1u), table_f32(bottom), table_f32(bottom + 1u));
}

// x ∈ [0, 1) from the density ∝ a (1 − x) + b x: the stable root of the CDF.
fn sample_linear(xi: f32, a: f32, b: f32) -> f32 {
    if a == b {
        return xi;
    }
    // The formula is homogeneous in (a, b): normalise against overflow.
    let m = max(a, b);
    let an = a / m;
    let bn = b / m;
    let denominator = an + sqrt((1.0 - xi) * an * an + xi * bn * bn);
    if !(denominator > 0.0) {
        return 0.0;
    }
    return clamp(xi * (an + bn) / denominator, 0.0, ONE_MINUS_EPSILON);
}

fn sample_bilinear(xi: vec2<f32>) -> PlanarSample {
    let c = sample_cell(xi);
    let i = c.cell.x;
    let k = c.cell.y;
    let f = corners(i, k);
    let y = sample_linear(c.offset.y, f.x + f.y, f.z + f.w);
    let x = sample_linear(c.offset.x, mix(f.x, f.z, y), mix(f.y, f.w, y));
    let w = params.image_width;
    let h = params.image_height;
    let u = mix(node(i, w), node(i + 1u, w), x);
    let v = mix(v_node(k, h), v_node(k + 1u, h), y);
    let uv = vec2<f32>(min(u, ONE_MINUS_EPSILON), min(v, ONE_MINUS_EPSILON));
    return PlanarSample(uv, c.cell);
}

// P · B(u, v) / M in the patch holding (u, v).
fn pdf_bilinear(uv: vec2<f32>) -> f32 {
    let w = params.image_width;
    let h = params.image_height;
    let u = unit_closed(uv.x);
    let v = unit_closed(uv.y);
    let i = patch_of(u, w);
    let k = v_patch_of(v, h);
    let f = corners(i, k);
    let left = max(u - node(i, w), 0.0);
    let right = max(node(i + 1u, w) - u, 0.0);
    let top = max(v - v_node(k, h), 0.0);
    let bottom = max(v_node(k + 1u, h) - v, 0.0);
    let weighted = bottom * (right * f.x + left * f.y) + top * (right * f.z + left * f.w);
    let area = patch_width(i, w) * v_patch_width(k, h);
    let denominator = area * area * (f.x + f.y + f.z + f.w);
    if !(denominator > 0.0) {
        return 0.0;
    }
    let probability = probability_of_widths(cell_widths(i, k));
    return 4.0 * probability * (weighted / denominator);
}

// ---------------------------------------------------------------------------
// Mappings
// ---------------------------------------------------------------------------

fn to_world(d: vec3<f32>) -> vec3<f32> {
    if params.rotated == 0u {
        return d;
    }
    let m = params.light_to_world;
    return vec3<f32>(dot(m[0].xyz, d), dot(m[1].xyz, d), dot(m[2].xyz, d));
}

fn to_light(d: vec3<f32>) -> vec3<f32> {
    if params.rotated == 0u {
        return d;
    }
    let m = params.world_to_light;
    return vec3<f32>(dot(m[0].xyz, d), dot(m[1].xyz, d), dot(m[2].xyz, d));
}

// The light-frame unit direction at image point uv.
fn uv_to_local(uv: vec2<f32>) -> vec3<f32> {
    if params.mapping == MAPPING_EQUAL_AREA {
        return square_to_sphere(uv);
    }
    let theta = sin_cos_pi(uv.y);
    let phi = sin_cos_pi(2.0 * uv.x);
    let sin_theta = max(theta.x, 0.0);
    return vec3<f32>(sin_theta * phi.y, sin_theta * phi.x, theta.y);
}

// The equal-area octahedral square to the sphere (crates/envlight/src/mapping/equal_area.rs).
fn square_to_sphere(uv: vec2<f32>) -> vec3<f32> {
    let a = 2.0 * unit_closed(uv.x) - 1.0;
    let b = 2.0 * unit_closed(uv.y) - 1.0;
    let abs_a = abs(a);
    let abs_b = abs(b);
    let sum = abs_a + abs_b;
    let upper = sum <= 1.0;
    let r = select(2.0 - sum, sum, upper);
    // φ in half turns: (1/4) ((|b| − |a|) / r + 1) ∈ [0, ½].
    var phi = 0.0;
    if r > 0.0 {
        phi = 0.25 * ((abs_b - abs_a) / r + 1.0);
    }
    let r2 = r * r;
    let z = select(r2 - 1.0, 1.0 - r2, upper);
    let sin_theta = r * sqrt(max(2.0 - r2, 0.0));
    let p = sin_cos_pi(clamp(phi, 0.0, 0.5));
    return vec3<f32>(copysign(p.y * sin_theta, a), copysign(p.x * sin_theta, b), z);
}

// The sphere to the equal-area square; a zero direction gives the centre.
fn sphere_to_square(d_in: vec3<f32>) -> vec2<f32> {
    let len = length(d_in);
    if !(len > 0.0) {
        return vec2<f32>(0.5, 0.5);
    }
    let d = d_in / len;
    let x = abs(d.x);
    let y = abs(d.y);
    let z = abs(d.z);
    let r = min(sqrt((x * x + y * y) / (1.0 + z)), 1.0);
    var phi_fraction = 0.0;
    if x > 0.0 || y > 0.0 {
        phi_fraction = clamp(2.0 * atan2_pi(y, x), 0.0, 1.0);
    }
    var abs_b = r * phi_fraction;
    var abs_a = r - abs_b;
    if d.z < 0.0 {
        let t = abs_a;
        abs_a = 1.0 - abs_b;
        abs_b = 1.0 - t;
    }
    let a = copysign(abs_a, d.x);
    let b = copysign(abs_b, d.y);
    return vec2<f32>(clamp(0.5 * (a + 1.0), 0.0, 1.0), clamp(0.5 * (b + 1.0), 0.0, 1.0));
}

// The image point of a light-frame direction (any length), and du dv / dω there
// (0 at the poles of the lat-long map, where the density is not defined).
struct ImagePoint {
    uv: vec2<f32>,
    inv_jacobian: f32,
}

fn local_to_uv(d: vec3<f32>) -> ImagePoint {
    if params.mapping == MAPPING_EQUAL_AREA {
        return ImagePoint(sphere_to_square(d), 1.0 / EQUAL_AREA_JACOBIAN);
    }
    let r2 = d.x * d.x + d.y * d.y;
    let r = sqrt(r2);
    let v = atan2_pi(r, d.z);
    let half_turns = atan2_pi(d.y, d.x);
    var u = 0.5 * half_turns;
    if half_turns < 0.0 {
        u += 1.0;
    }
    u = min(u, ONE_MINUS_EPSILON);
    var inv_jacobian = 0.0;
    if r > 0.0 {
        // 1 / sin θ read off the direction, |d| / √(x² + y²).
        inv_jacobian = (sqrt(r2 + d.z * d.z) / r) * (1.0 / EQUIRECT_JACOBIAN);
    }
    return ImagePoint(vec2<f32>(max(u, 0.0), v), inv_jacobian);
}

// ---------------------------------------------------------------------------
// Radiance lookup (section 9)
// ---------------------------------------------------------------------------

fn texel(x: u32, y: u32) -> vec3<f32> {
    let i = y * params.image_width + x;
    if params.radiance_format == RADIANCE_F16 {
        let rg = radiance_texels[2u * i];
        let b = radiance_texels[2u * i + 1u];
        return vec3<f32>(half_to_f32(rg & 0xffffu), half_to_f32(rg >> 16u), half_to_f32(b & 0xffffu));
    }
    return vec3<f32>(
        bitcast<f32>(radiance_texels[3u * i]),
        bitcast<f32>(radiance_texels[3u * i + 1u]),
        bitcast<f32>(radiance_texels[3u * i + 2u]),
    );
}

// An IEEE binary16 value (the low 16 bits of h) as f32, exactly, with integer
// operations only (unpack2x16float needs a capability some devices lack).
fn half_to_f32(h: u32) -> f32 {
    let sign = (h & 0x8000u) << 16u;
    let e = (h >> 10u) & 0x1fu;
    let m = h & 0x3ffu;
    if e == 0u {
        // Zero or subnormal: m · 2⁻²⁴.
        return bitcast<f32>(bitcast<u32>(f32(m) * 0x1p-24) | sign);
    }
    if e == 31u {
        return bitcast<f32>(sign | 0x7f800000u | (m << 13u));
    }
    return bitcast<f32>(sign | ((e + 112u) << 23u) | (m << 13u));
}

// u reduced into [0, 1).
fn periodic(u: f32) -> f32 {
    if u >= 0.0 && u < 1.0 {
        return u;
    }
    let r = u - floor(u);
    return select(0.0, r, r < 1.0);
}

// The two texels around t on a clamped axis of n texels and the second's weight.
struct Pair {
    first: u32,
    second: u32,
    weight: f32,
}

fn clamped_pair(t: f32, n: u32) -> Pair {
    let s = t * f32(n) + 0.5;
    let i = floor_index(s, n + 1u);
    return Pair(max(i, 1u) - 1u, min(i, n - 1u), s - f32(i));
}

// The two rows around t when the n rows are nodes from t = 0 to t = 1 (row j at
// j/(n − 1)), and the second's weight; t clamped into [0, 1]. One row: (0, 0, 0).
fn node_pair(t: f32, n: u32) -> Pair {
    if n < 2u {
        return Pair(0u, 0u, 0.0);
    }
    let s = unit_closed(t) * f32(n - 1u);
    let i = floor_index(s, n - 1u);
    return Pair(i, i + 1u, s - f32(i));
}

fn lookup(uv: vec2<f32>) -> vec3<f32> {
    let w = params.image_width;
    let h = params.image_height;
    let periodic_u = params.mapping != MAPPING_EQUAL_AREA;
    if params.lookup != LOOKUP_BILINEAR && params.lookup != LOOKUP_NODE {
        var u = uv.x;
        if periodic_u {
            u = periodic(u);
        }
        return min(texel(floor_index(u * f32(w), w), floor_index(uv.y * f32(h), h)) * params.scale, vec3<f32>(F32_MAX));
    }
    var px: Pair;
    if periodic_u {
        let s = periodic(uv.x) * f32(w) - 0.5 + f32(w);
        let i = floor_index(s, 2u * w);
        var x0 = i;
        if i >= w {
            x0 = i - w;
        }
        var x1 = x0 + 1u;
        if x1 == w {
            x1 = 0u;
        }
        px = Pair(x0, x1, s - f32(i));
    } else {
        px = clamped_pair(uv.x, w);
    }
    var py: Pair;
    if params.lookup == LOOKUP_NODE {
        py = node_pair(uv.y, h);
    } else {
        py = clamped_pair(uv.y, h);
    }
    let fs = px.weight;
    let ft = py.weight;
    let gs = 1.0 - fs;
    let gt = 1.0 - ft;
    let a = texel(px.first, py.first);
    let b = texel(px.second, py.first);
    let c = texel(px.first, py.second);
    let d = texel(px.second, py.second);
    let l = min(((gs * gt) * a + (fs * gt) * b) + ((gs * ft) * c + (fs * ft) * d), vec3<f32>(F32_MAX));
    return min(l * params.scale, vec3<f32>(F32_MAX));
}

// ---------------------------------------------------------------------------
// The light
// ---------------------------------------------------------------------------

// The density over the image at uv (the light's planar density).
fn planar_pdf(uv: vec2<f32>) -> f32 {
    if params.density == DENSITY_BILINEAR {
        return pdf_bilinear(uv);
    }
    return pdf_constant(uv);
}

// pdf and radiance of a world direction.
struct Eval {
    pdf: f32,
    radiance: vec3<f32>,
}

fn light_eval(direction: vec3<f32>) -> Eval {
    let p = local_to_uv(to_light(direction));
    return Eval(solid_angle_pdf(p), lookup(p.uv));
}

// The solid-angle density at an image point: the planar density over dω/du dv;
// 0 for a black light and at the poles of a lat-long map.
fn solid_angle_pdf(p: ImagePoint) -> f32 {
    if params.black != 0u {
        return 0.0;
    }
    return planar_pdf(p.uv) * p.inv_jacobian;
}

// The solid-angle density (per steradian) of a world direction: 0 where the light
// is black, at the poles of a lat-long map, and for a black light.
fn light_pdf(direction: vec3<f32>) -> f32 {
    return solid_angle_pdf(local_to_uv(to_light(direction)));
}

// Radiance arriving from a world direction (scale applied).
fn light_radiance(direction: vec3<f32>) -> vec3<f32> {
    return lookup(local_to_uv(to_light(direction)).uv);
}

struct LightSample {
    // World-space unit direction.
    direction: vec3<f32>,
    // Its solid-angle density; 0 when there is no sample.
    pdf: f32,
    radiance: vec3<f32>,
    // True when a direction was drawn.
    valid: bool,
}

// The cell (piecewise-constant) or patch (piecewise-bilinear) holding uv.
fn cell_of(uv: vec2<f32>) -> vec2<u32> {
    if params.density == DENSITY_BILINEAR {
        return vec2<u32>(
            patch_of(unit_closed(uv.x), params.image_width),
            v_patch_of(unit_closed(uv.y), params.image_height),
        );
    }
    return vec2<u32>(cell_index(uv.x, params.table_width), cell_index(uv.y, params.table_height));
}

// The centre of a cell or patch, in the image.
fn centre_of(cell: vec2<u32>) -> vec2<f32> {
    if params.density == DENSITY_BILINEAR {
        let w = params.image_width;
        let h = params.image_height;
        return vec2<f32>(
            0.5 * (node(cell.x, w) + node(cell.x + 1u, w)),
            0.5 * (v_node(cell.y, h) + v_node(cell.y + 1u, h)),
        );
    }
    return (vec2<f32>(cell) + 0.5) / vec2<f32>(f32(params.table_width), f32(params.table_height));
}

// A sampled direction and its image point as `light_pdf` finds it.
struct Settled {
    direction: vec3<f32>,
    point: ImagePoint,
}

// The world direction of a point drawn in `s.cell`, settled so that the
// direction maps back into that cell. f32 trigonometry both ways moves a point
// by up to ~1e-6 of the image, which near a cell edge can carry the direction
// into the neighbour, whose density may differ by any factor. A point whose
// direction does not come back to its cell is moved towards the cell's centre
// (by 0.1%, then four times further each try) until it does: the density is
// unchanged inside the cell, and only a band of about 1e-6 of the cell along
// its edges is squeezed inward.
fn settle_in_cell(s: PlanarSample) -> Settled {
    var uv = s.uv;
    let centre = centre_of(s.cell);
    var step = 1e-3;
    var direction = to_world(uv_to_local(uv));
    var back = local_to_uv(to_light(direction));
    for (var k = 0; k < 6; k++) {
        if all(cell_of(back.uv) == s.cell) {
            break;
        }
        uv = mix(uv, centre, step);
        step = min(4.0 * step, 1.0);
        direction = to_world(uv_to_local(uv));
        back = local_to_uv(to_light(direction));
    }
    return Settled(direction, back);
}

// Draws a direction for ξ ∈ [0, 1)² with density ∝ the light's importance. With no
// sample (a black light; a point on a pole; a direction rounded into a cell of zero
// density), `valid` is false, pdf and radiance 0, and the direction that of the
// image point ξ.
fn light_sample(xi: vec2<f32>) -> LightSample {
    if params.black != 0u {
        return LightSample(to_world(uv_to_local(xi)), 0.0, vec3<f32>(0.0), false);
    }
    var s: PlanarSample;
    if params.density == DENSITY_BILINEAR {
        s = sample_bilinear(xi);
    } else if params.sampler == SAMPLER_ALIAS {
        s = sample_alias(xi);
    } else {
        s = sample_inversion(xi);
    }
    let settled = settle_in_cell(s);
    let direction = settled.direction;
    // What light_eval(direction) gives, from the image point already found.
    let pdf = solid_angle_pdf(settled.point);
    if !(pdf > 0.0) {
        return LightSample(direction, 0.0, vec3<f32>(0.0), false);
    }
    return LightSample(direction, pdf, lookup(settled.point.uv), true);
}

// ---------------------------------------------------------------------------
// ξ from a seed: envlight::rng::xi_2d, with 64-bit integers as (low, high) pairs
// ---------------------------------------------------------------------------

fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    let carry = select(0u, 1u, lo < a.x);
    return vec2<u32>(lo, a.y + b.y + carry);
}

fn mul64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let w = mul_wide(a.x, b.x);
    return vec2<u32>(w.x, w.y + a.x * b.y + a.y * b.x);
}

// a ^ (a >> s) for 0 < s < 32.
fn xorshift64(a: vec2<u32>, s: u32) -> vec2<u32> {
    let shifted = vec2<u32>((a.x >> s) | (a.y << (32u - s)), a.y >> s);
    return a ^ shifted;
}

// The SplitMix64 finaliser (envlight::rng::mix64).
fn mix64(z_in: vec2<u32>) -> vec2<u32> {
    var z = mul64(xorshift64(z_in, 30u), vec2<u32>(0x1ce4e5b9u, 0xbf58476du));
    z = mul64(xorshift64(z, 27u), vec2<u32>(0x133111ebu, 0x94d049bbu));
    return xorshift64(z, 31u);
}

// The top 24 bits as a float in [0, 1).
fn unit_f32(bits: vec2<u32>) -> f32 {
    return f32(bits.y >> 8u) * 0x1p-24;
}

fn xi_2d(seed: vec2<u32>, index: vec2<u32>) -> vec2<f32> {
    let golden = vec2<u32>(0x7f4a7c15u, 0x9e3779b9u);
    let twice = vec2<u32>(index.x << 1u, (index.y << 1u) | (index.x >> 31u));
    let base = add64(mix64(seed ^ golden), twice);
    return vec2<f32>(unit_f32(mix64(base)), unit_f32(mix64(add64(base, vec2<u32>(1u, 0u)))));
}

// ---------------------------------------------------------------------------
// Entry points
// ---------------------------------------------------------------------------

const WORKGROUP: u32 = 64u;

fn row_index(gid: vec3<u32>, groups: vec3<u32>) -> u32 {
    return gid.x + gid.y * groups.x * WORKGROUP;
}

fn read_direction(row: u32) -> vec3<f32> {
    return vec3<f32>(inputs[4u * row], inputs[4u * row + 1u], inputs[4u * row + 2u]);
}

// Writes `v` to outputs[at], ..., outputs[at + 3].
fn write_vec4(at: u32, v: vec4<f32>) {
    outputs[at] = v.x;
    outputs[at + 1u] = v.y;
    outputs[at + 2u] = v.z;
    outputs[at + 3u] = v.w;
}

@compute @workgroup_size(64)
fn sample_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let row = row_index(gid, groups);
    if row >= batch.count {
        return;
    }
    var xi: vec2<f32>;
    if batch.mode == 1u {
        let index = add64(vec2<u32>(batch.first_lo, batch.first_hi), vec2<u32>(row, 0u));
        xi = xi_2d(vec2<u32>(batch.seed_lo, batch.seed_hi), index);
    } else {
        xi = vec2<f32>(inputs[2u * row], inputs[2u * row + 1u]);
    }
    let s = light_sample(xi);
    write_vec4(8u * row, vec4<f32>(s.direction, s.pdf));
    write_vec4(8u * row + 4u, vec4<f32>(s.radiance, select(0.0, 1.0, s.valid)));
}

@compute @workgroup_size(64)
fn pdf_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let row = row_index(gid, groups);
    if row >= batch.count {
        return;
    }
    outputs[row] = light_pdf(read_direction(row));
}

@compute @workgroup_size(64)
fn radiance_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let row = row_index(gid, groups);
    if row >= batch.count {
        return;
    }
    write_vec4(4u * row, vec4<f32>(light_radiance(read_direction(row)), 0.0));
}

@compute @workgroup_size(64)
fn eval_main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups: vec3<u32>) {
    let row = row_index(gid, groups);
    if row >= batch.count {
        return;
    }
    let e = light_eval(read_direction(row));
    write_vec4(4u * row, vec4<f32>(e.pdf, e.radiance));
}
