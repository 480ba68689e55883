//! Small geometric types (a 3-vector and a rotation) and the few scalar functions
//! the hot paths need faster than libm gives them.

use std::ops::{Add, Mul, Neg, Sub};

/// `⌊x⌋` clamped into `[0, n - 1]`, as an index; NaN gives 0.
///
/// Three instructions on x86-64: Rust's saturating `as` adds a NaN and overflow fix-up
/// to every float-to-integer conversion, which the hot lookups would pay several
/// times per query; clamping first makes the plain truncation exact instead.
#[inline(always)]
pub(crate) fn floor_index(x: f32, n: usize) -> usize {
    // `max` also maps NaN to 0 (which `clamp` would keep as NaN); `min` keeps the
    // value far inside i64's range.
    #[allow(clippy::manual_clamp)]
    let y = x.max(0.0).min(1.0e18);
    // SAFETY: y is finite and in [0, 1e18], where truncation to i64 is defined, and
    // for y >= 0 truncation is the floor.
    let i = unsafe { y.to_int_unchecked::<i64>() };
    (i as usize).min(n - 1)
}

/// [`floor_index`] for `n < 2³¹` as an `i32` (`last = n - 1`), in operations a
/// loop over many of them turns into vector instructions (packed conversions
/// to 32-bit integers exist; to 64-bit ones do not before AVX-512). The same
/// value: clamping to the last index before or after truncation gives the same
/// integer.
#[inline(always)]
pub(crate) fn floor_index_i32(x: f32, last: i32) -> i32 {
    // `max` maps NaN to 0; the bound is the largest f32 below 2³¹.
    #[allow(clippy::manual_clamp)]
    let y = x.max(0.0).min(2_147_483_520.0);
    // SAFETY: y is finite and in [0, 2³¹), where truncation to i32 is defined (and,
    // for y >= 0, is the floor).
    let i = unsafe { y.to_int_unchecked::<i32>() };
    i.min(last)
}

/// `⌊x⌋` without a library call (f32::floor is one on the x86-64 baseline, which
/// has no rounding instruction), in operations that vectorize: exactly
/// `x.floor()` for every x (finite, ±∞ and NaN), except that -0 gives +0.
#[inline(always)]
pub(crate) fn floor_f32(x: f32) -> f32 {
    // Above 2²³ in magnitude every f32 is an integer.
    const BIG: f32 = 8_388_608.0;
    #[allow(clippy::manual_clamp)]
    let c = x.max(-BIG).min(BIG);
    // SAFETY: c is finite (max maps NaN to -BIG) and within ±2²³.
    let t = unsafe { c.to_int_unchecked::<i32>() } as f32;
    let floor = if t > c { t - 1.0 } else { t };
    if c.abs() < BIG {
        floor
    } else {
        x
    }
}

/// Asks the CPU to bring the cache line holding `r` closer (a no-op on other
/// architectures).
#[inline(always)]
pub(crate) fn prefetch_read<T>(r: &T) {
    prefetch_ptr(r as *const T);
}

/// [`prefetch_read`] for a raw pointer, which may point anywhere.
#[inline(always)]
pub(crate) fn prefetch_ptr<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults (one of an unmapped address is
    // dropped) and has no visible effect, and the pointer is never dereferenced.
    // SSE, which provides it, is part of the x86-64 baseline.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(p.cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Asks the kernel to back the memory of `data` with 2 MiB pages where it can
/// (Linux transparent huge pages in `madvise` mode, a common default). Random
/// lookups into tables of tens of megabytes miss the TLB on nearly every access
/// with 4 KiB pages; with 2 MiB pages a 64 MiB table needs 32 entries. Only the
/// 2 MiB-aligned part of the slice is advised, and only pages not yet touched
/// are affected, so call it between allocating and filling. A hint: ignored on
/// other systems, for small slices, and when the kernel declines.
pub(crate) fn advise_huge_pages<T>(data: &[T]) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        let start = data.as_ptr() as usize;
        let end = start + std::mem::size_of_val(data);
        let (first, last) = (start.next_multiple_of(HUGE), end / HUGE * HUGE);
        if last > first {
            // SAFETY: [first, last) lies inside `data`'s allocation, and
            // MADV_HUGEPAGE changes neither its contents nor its validity.
            unsafe {
                libc::madvise(
                    first as *mut libc::c_void,
                    last - first,
                    libc::MADV_HUGEPAGE,
                );
            }
        }
    }
    #[cfg(not(target_os = "linux"))]
    let _ = data;
}

/// `x > 0` and finite (not NaN, not +∞), as one integer comparison on the bits:
/// LLVM expands the two float comparisons (or `is_finite`) into a dozen
/// instructions of class tests.
#[inline(always)]
pub(crate) fn is_positive_finite(x: f32) -> bool {
    // Positive finite non-zero floats are exactly the bit patterns 1..=0x7f7f_ffff.
    x.to_bits().wrapping_sub(1) < 0x7f7f_ffff
}

/// The largest `f64` below 1 (`1 - 2⁻⁵³`): the clamp that keeps a rescaled sample
/// coordinate in `[0, 1)`.
pub(crate) const BELOW_ONE: f64 = 1.0 - f64::EPSILON / 2.0;

/// `ξ` clamped into `[0, 1)` as an `f64`; NaN gives 0.
#[inline(always)]
pub(crate) fn unit_interval(xi: f32) -> f64 {
    if xi > 0.0 {
        (xi as f64).min(BELOW_ONE)
    } else {
        0.0
    }
}

/// `a · b` of f64 3-vectors, summed left to right (`a₀b₀ + a₁b₁ + a₂b₂`).
#[inline(always)]
pub(crate) fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b` of f64 3-vectors.
#[inline(always)]
pub(crate) fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// The Euclidean length of an f64 3-vector, `√(a · a)` with [`dot3`].
#[inline(always)]
pub(crate) fn norm3(a: [f64; 3]) -> f64 {
    dot3(a, a).sqrt()
}

/// `n` as f32 by way of i64: one instruction on x86-64, where converting a `usize`
/// takes a sequence (it must handle values above `i64::MAX`).
#[inline]
pub(crate) fn len_f32(n: usize) -> f32 {
    n as i64 as f32
}

/// `n` as f64 by way of i64 (see [`len_f32`]).
#[inline]
pub(crate) fn len_f64(n: usize) -> f64 {
    n as i64 as f64
}

/// `(sin πx, cos πx)`, inlined and branch-free, within 2 f32 ulps for `|x| < 2¹⁵`
/// (libm's `sincosf` is a call costing as much as the rest of a light sample).
///
/// `x = k/128 + r` with `k = round(128 x)`, split exactly (no rounding of `π x` to
/// lose precision near multiples of π: the poles of the lat-long map, where `sin θ`
/// must keep its relative accuracy). The angle `πk/128` is read from a table of one
/// period (`k mod 256`); the rest, `δ = π r` with `|δ| ≤ π/256`, needs only
/// `sin δ ≈ δ - δ³/6` and `cos δ ≈ 1 - δ²/2` (truncation errors below 2·10⁻¹⁰
/// relative and 10⁻⁹ absolute); the angle-sum formulas then add the small
/// corrections to the table's values. About a third of the instructions of a
/// polynomial with quadrant swaps, and no branch.
#[inline(always)]
pub fn sin_cos_pi(x: f32) -> (f32, f32) {
    // Adding 1.5·2²³ rounds a value below 2²² in magnitude to an integer, which
    // then sits in the low bits of the sum's mantissa (two's complement, so the
    // mask below is k mod 256 for negative k too). NaN and ±∞ give NaN through δ.
    const SHIFTER: f32 = 12_582_912.0;
    let t = x * 128.0;
    let shifted = t + SHIFTER;
    let k = (shifted.to_bits() & 255) as usize;
    let delta = (t - (shifted - SHIFTER)) * (std::f32::consts::PI / 128.0);
    let d2 = delta * delta;
    let sin_d = delta - delta * d2 * (1.0 / 6.0);
    let cos_d_minus_1 = -0.5 * d2;
    let [s0, c0] = SIN_COS_PI_TABLE.0[k];
    (
        s0 + (c0 * sin_d + s0 * cos_d_minus_1),
        c0 + (c0 * cos_d_minus_1 - s0 * sin_d),
    )
}

/// `[sin, cos]` of `πk/128` for `k = 0..256`, each rounded to f32 (exactly 0 and
/// ±1 at the quadrant points), in 32 cache lines.
#[repr(align(64))]
struct SinCosTable([[f32; 2]; 256]);

static SIN_COS_PI_TABLE: SinCosTable = SinCosTable(sin_cos_pi_table());

/// [`SIN_COS_PI_TABLE`], computed by the compiler: Taylor series in f64 on the first
/// quadrant (terms to degree 31, far past f64 precision for angles below π/2), the
/// others by symmetry.
const fn sin_cos_pi_table() -> [[f32; 2]; 256] {
    let mut table = [[0.0f32; 2]; 256];
    let mut k = 0;
    while k < 256 {
        let a = (k % 64) as f64 * (std::f64::consts::PI / 128.0);
        // sin a = Σ (-1)ⁿ a²ⁿ⁺¹/(2n+1)!, cos a = Σ (-1)ⁿ a²ⁿ/(2n)!.
        let (mut sin, mut cos) = (0.0f64, 0.0f64);
        let (mut term_s, mut term_c) = (a, 1.0f64);
        let mut n = 0;
        while n < 16 {
            sin += term_s;
            cos += term_c;
            let m = (2 * n + 2) as f64;
            term_c = -term_c * a * a / (m * (m - 1.0));
            term_s = -term_s * a * a / (m * (m + 1.0));
            n += 1;
        }
        table[k] = match k / 64 {
            0 => [sin as f32, cos as f32],
            1 => [cos as f32, -sin as f32],
            2 => [-sin as f32, -cos as f32],
            _ => [-cos as f32, sin as f32],
        };
        k += 1;
    }
    table
}

/// `tan(π/8)`: above it, atan's argument is reflected about 1 (see [`atan2_pi`]).
pub(crate) const TAN_PI_8: f32 = 0.414_213_57;

/// `atan(t) = t·P(t²)` on `[0, tan(π/8)]`, fitted by iteratively reweighted least
/// squares on Chebyshev nodes (relative error 6·10⁻¹⁰, far below f32 rounding).
const ATAN_P: [f64; 6] = [
    0.999_999_999_414_626_1,
    -0.333_333_081_092_851_2,
    0.199_982_391_292_769_2,
    -0.142_404_425_650_121_87,
    0.105_758_660_685_587_3,
    -0.060_403_409_485_716_31,
];

/// [`ATAN_P`] divided by π and rounded to f32: `atan(t) / π = t·Q(t²)`.
pub(crate) const ATAN_PI_Q: [f32; 6] = {
    let pi = std::f64::consts::PI;
    [
        (ATAN_P[0] / pi) as f32,
        (ATAN_P[1] / pi) as f32,
        (ATAN_P[2] / pi) as f32,
        (ATAN_P[3] / pi) as f32,
        (ATAN_P[4] / pi) as f32,
        (ATAN_P[5] / pi) as f32,
    ]
};

/// `atan2(y, x) / π`, the angle in half turns, in `[-1, 1]`, all in f32 and
/// without a branch (selects only), so that a loop over lanes of it vectorizes:
/// 16 lanes per AVX-512 register where the f64 version it replaces had 8.
///
/// The argument is reduced to `t ∈ [0, tan(π/8)]` (swap so `|num| ≤ |den|`, then
/// `atan t = π/4 + atan((t − 1)/(t + 1))` above `tan(π/8)`), and `atan(t)/π` is the
/// odd polynomial `t·Q(t²)` of degree 11 in Estrin's scheme. Error against the
/// exact angle (`atan2_pi_error_bounds`, 4·10⁶ points at magnitudes 1e-30 to
/// 1e30, and every octant edge): at most 6.1·10⁻⁸ half turns (half an f32 ulp at
/// 1; 6·10⁻⁸ measured), and within 3 ulps of the result below 10⁻³ (2.2 measured),
/// which keeps the relative precision the lat-long map needs at its poles.
/// `atan2_pi(0, 0)` is 0; NaN propagates.
#[inline(always)]
pub fn atan2_pi(y: f32, x: f32) -> f32 {
    let (ax, ay) = (x.abs(), y.abs());
    let swapped = ay > ax;
    let num = if swapped { ax } else { ay };
    let den = if swapped { ay } else { ax };
    let big = num > TAN_PI_8 * den;
    let top = if big { num - den } else { num };
    let bottom = if big { num + den } else { den };
    // x = y = 0 divides 0 by the smallest normal (giving 0); a NaN denominator
    // stays NaN (the comparison is false).
    let bottom = if f32::MIN_POSITIVE > bottom {
        f32::MIN_POSITIVE
    } else {
        bottom
    };
    let t = top / bottom;
    let s = t * t;
    // Estrin's scheme: three multiplications deep instead of Horner's five.
    let (q, s2) = (&ATAN_PI_Q, s * s);
    let poly = (q[0] + q[1] * s) + s2 * ((q[2] + q[3] * s) + s2 * (q[4] + q[5] * s));
    let offset = if big { 0.25 } else { 0.0 };
    let a = offset + t * poly;
    let a = if swapped { 0.5 - a } else { a };
    let a = if x < 0.0 { 1.0 - a } else { a };
    if y < 0.0 {
        -a
    } else {
        a
    }
}

/// Two angles at once, `[atan2_pi(y₀, x₀), atan2_pi(y₁, x₁)]`, bit for bit: a
/// direction's image point needs two (θ and φ), which on x86-64 share the lanes
/// of one SSE register (part of the baseline) with selects where the scalar code
/// branches: half the instructions on a single query's critical path.
#[inline(always)]
pub fn atan2_pi_pair(y: [f32; 2], x: [f32; 2]) -> [f32; 2] {
    #[cfg(target_arch = "x86_64")]
    {
        atan2_pi_pair_sse(y, x)
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        [atan2_pi(y[0], x[0]), atan2_pi(y[1], x[1])]
    }
}

/// [`atan2_pi`]'s operations, in the same order, on two lanes.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn atan2_pi_pair_sse(y: [f32; 2], x: [f32; 2]) -> [f32; 2] {
    use std::arch::x86_64::*;
    // SAFETY: SSE is part of the x86-64 baseline; nothing here touches memory but
    // the final store into `out`.
    unsafe {
        let select = |mask: __m128, a: __m128, b: __m128| {
            _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b))
        };
        let yv = _mm_set_ps(0.0, 0.0, y[1], y[0]);
        let xv = _mm_set_ps(1.0, 1.0, x[1], x[0]);
        let sign = _mm_set1_ps(-0.0);
        let zero = _mm_setzero_ps();
        let (ax, ay) = (_mm_andnot_ps(sign, xv), _mm_andnot_ps(sign, yv));
        let swapped = _mm_cmpgt_ps(ay, ax);
        let num = select(swapped, ax, ay);
        let den = select(swapped, ay, ax);
        let big = _mm_cmpgt_ps(num, _mm_mul_ps(_mm_set1_ps(TAN_PI_8), den));
        let top = select(big, _mm_sub_ps(num, den), num);
        let bottom = select(big, _mm_add_ps(num, den), den);
        // maxps gives its first operand when it is greater, else the second (also
        // for NaN): the scalar `if MIN_POSITIVE > bottom`.
        let bottom = _mm_max_ps(_mm_set1_ps(f32::MIN_POSITIVE), bottom);
        let t = _mm_div_ps(top, bottom);
        let s = _mm_mul_ps(t, t);
        let s2 = _mm_mul_ps(s, s);
        let q = &ATAN_PI_Q;
        let pair = |k: usize| _mm_add_ps(_mm_set1_ps(q[k]), _mm_mul_ps(_mm_set1_ps(q[k + 1]), s));
        let poly = _mm_add_ps(
            pair(0),
            _mm_mul_ps(s2, _mm_add_ps(pair(2), _mm_mul_ps(s2, pair(4)))),
        );
        let offset = _mm_and_ps(big, _mm_set1_ps(0.25));
        let mut a = _mm_add_ps(offset, _mm_mul_ps(t, poly));
        a = select(swapped, _mm_sub_ps(_mm_set1_ps(0.5), a), a);
        a = select(_mm_cmplt_ps(xv, zero), _mm_sub_ps(_mm_set1_ps(1.0), a), a);
        a = select(_mm_cmplt_ps(yv, zero), _mm_xor_ps(a, sign), a);
        let mut out = [0.0f32; 4];
        _mm_storeu_ps(out.as_mut_ptr(), a);
        [out[0], out[1]]
    }
}

/// [`atan2_pi`] on each of `N` lanes, as a loop the compiler vectorizes: the
/// angle stage of the batch queries, bit for bit the scalar values.
#[inline(always)]
pub(crate) fn atan2_pi_lanes<const N: usize>(y: &[f32; N], x: &[f32; N]) -> [f32; N] {
    let mut out = [0.0f32; N];
    for i in 0..N {
        out[i] = atan2_pi(y[i], x[i]);
    }
    out
}

/// A uniformly distributed unit direction for `ξ ∈ [0, 1)²`: `z = 1 - 2ξ₀`,
/// `φ = 2πξ₁` (density `1 / 4π` per steradian).
#[inline]
pub fn uniform_sphere(xi: [f32; 2]) -> Vec3 {
    let z = 1.0 - 2.0 * xi[0];
    let r = (1.0 - z * z).max(0.0).sqrt();
    let (s, c) = (2.0 * std::f32::consts::PI * xi[1]).sin_cos();
    Vec3::new(r * c, r * s, z)
}

/// A 3-vector of `f32` (a direction or a point). The frame is right-handed, z up.
/// Laid out as three consecutive `f32` (`x`, `y`, `z`), so a slice of them can be
/// viewed as an `N × 3` array (the Python bindings do).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[repr(C)]
pub struct Vec3 {
    /// x component.
    pub x: f32,
    /// y component.
    pub y: f32,
    /// z component (up).
    pub z: f32,
}

impl Vec3 {
    /// Builds a vector from its components.
    #[inline]
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
    /// Dot product.
    #[inline]
    pub fn dot(self, o: Self) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product.
    #[inline]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Euclidean length.
    #[inline]
    pub fn length(self) -> f32 {
        self.dot(self).sqrt()
    }
    /// The vector scaled to unit length. A zero or non-finite vector gives `None`.
    #[inline]
    pub fn normalized(self) -> Option<Self> {
        let len = self.length();
        if len > 0.0 && len.is_finite() {
            Some(self * (1.0 / len))
        } else {
            None
        }
    }
    /// Components as an array `[x, y, z]`.
    #[inline]
    pub fn to_array(self) -> [f32; 3] {
        [self.x, self.y, self.z]
    }
}

impl From<[f32; 3]> for Vec3 {
    #[inline]
    fn from(a: [f32; 3]) -> Self {
        Self::new(a[0], a[1], a[2])
    }
}

impl Add for Vec3 {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Vec3 {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Mul<f32> for Vec3 {
    type Output = Self;
    #[inline]
    fn mul(self, s: f32) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Neg for Vec3 {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sin_cos_pi_matches_f64_to_f32_precision() {
        let ulp = |v: f64| {
            let bits = (v.abs().max(1e-38) as f32).to_bits();
            (f32::from_bits(bits + 1) - f32::from_bits(bits)) as f64
        };
        // The reference: f64 sin/cos of π times the distance to the nearest multiple
        // of 1/2 (exact in f64), so the reference itself is exact near the zeros,
        // where sin(π · x) in f64 would carry π's own rounding.
        let reference = |x: f32| {
            let x = x as f64;
            let q = (2.0 * x).round();
            let t = std::f64::consts::PI * (x - 0.5 * q);
            let (s, c) = (t.sin(), t.cos());
            match (q as i64).rem_euclid(4) {
                0 => (s, c),
                1 => (c, -s),
                2 => (-s, -c),
                _ => (-c, s),
            }
        };
        let mut rng = crate::rng::SplitMix64::new(8);
        let mut xs: Vec<f32> = (0..200_000).map(|_| rng.next_f32() * 4.0 - 1.0).collect();
        // Far from the lat-long range, up to the documented bound.
        xs.extend((0..20_000).map(|_| (rng.next_f32() * 2.0 - 1.0) * 32_000.0));
        // Around the zeros and quadrant edges, and tiny arguments.
        for k in -8..=8 {
            let edge = k as f32 * 0.25;
            xs.extend([
                edge,
                edge.next_up(),
                edge.next_down(),
                edge + 1e-6,
                edge - 1e-6,
            ]);
        }
        xs.extend([1e-30, -1e-20, 1e-7, f32::MIN_POSITIVE]);
        let mut worst = 0.0f64;
        for x in xs {
            let (s, c) = sin_cos_pi(x);
            let (rs, rc) = reference(x);
            for (got, exact) in [(s, rs), (c, rc)] {
                let err = (got as f64 - exact).abs() / ulp(exact);
                worst = worst.max(err);
                assert!(err <= 2.0, "x={x}: {got} vs {exact} ({err} ulp)");
            }
        }
        println!("sin_cos_pi: worst error {worst:.3} ulp");
        // Exact values where the quadrants meet.
        assert_eq!(sin_cos_pi(0.0), (0.0, 1.0));
        assert_eq!(sin_cos_pi(0.5), (1.0, 0.0));
        assert_eq!(sin_cos_pi(1.0), (0.0, -1.0));
        assert_eq!(sin_cos_pi(1.5), (-1.0, 0.0));
        assert_eq!(sin_cos_pi(2.0), (0.0, 1.0));
        assert_eq!(sin_cos_pi(-0.5), (-1.0, 0.0));
        let (s, c) = sin_cos_pi(f32::NAN);
        assert!(s.is_nan() && c.is_nan());
        let (s, c) = sin_cos_pi(f32::INFINITY);
        assert!(s.is_nan() && c.is_nan());
    }

    #[test]
    fn vector_friendly_floors_match_the_scalar_ones() {
        let mut rng = crate::rng::SplitMix64::new(3);
        let mut xs: Vec<f32> = (0..100_000)
            .map(|k| (rng.next_f32() * 2.0 - 1.0) * [1.0f32, 1e3, 1e7, 1e9, 1e-30][k % 5])
            .collect();
        xs.extend([
            0.0,
            1.0,
            -1.0,
            0.5,
            -0.5,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            -8_388_609.0,
            2_147_483_520.0,
            3e9,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ]);
        for &x in &xs {
            let (got, want) = (floor_f32(x), x.floor());
            assert!(
                got == want || (got.is_nan() && want.is_nan()),
                "floor {x}: {got}"
            );
            for n in [1usize, 7, 4096, 1 << 30] {
                assert_eq!(
                    floor_index_i32(x, n as i32 - 1) as usize,
                    floor_index(x, n),
                    "{x} {n}"
                );
            }
        }
    }

    #[test]
    fn positive_finite_is_what_it_says() {
        for x in [f32::MIN_POSITIVE, 1e-45, 1.0, f32::MAX] {
            assert!(is_positive_finite(x), "{x}");
        }
        for x in [
            0.0,
            -0.0,
            -1e-45,
            -1.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            -f32::NAN,
        ] {
            assert!(!is_positive_finite(x), "{x}");
        }
    }

    #[test]
    fn sin_cos_table_is_correctly_rounded() {
        for (k, &[s, c]) in SIN_COS_PI_TABLE.0.iter().enumerate() {
            let a = std::f64::consts::PI * k as f64 / 128.0;
            // Within half an f32 ulp of libm's f64 values (plus f64 noise).
            for (got, exact) in [(s, a.sin()), (c, a.cos())] {
                let below = (exact.abs() as f32).max(f32::MIN_POSITIVE);
                let half_ulp = (below.next_up() - below) as f64 / 2.0;
                assert!(
                    (got as f64 - exact).abs() <= half_ulp + 1e-15,
                    "k={k}: {got} vs {exact}"
                );
            }
        }
    }

    /// The error bound stated on [`atan2_pi`], against f64's `atan2` over a dense
    /// set of angles and every octant edge, at magnitudes from 1e-30 to 1e30.
    #[test]
    fn atan2_pi_error_bounds() {
        let mut cases: Vec<(f32, f32)> = Vec::new();
        // Dense in angle: 2²¹ angles around the circle, at three radii.
        let n = 1 << 21;
        for k in 0..n {
            let a = std::f64::consts::TAU * (k as f64 + 0.37) / n as f64;
            let r = [1.0, 3e-30, 7e29][k % 3];
            cases.push(((r * a.sin()) as f32, (r * a.cos()) as f32));
        }
        // Random components, and tiny angles (the poles of the lat-long map).
        let mut rng = crate::rng::SplitMix64::new(5);
        for k in 0..2_000_000 {
            let y = (rng.next_f32() * 2.0 - 1.0) * [1.0f32, 1e-6, 1e-30][k % 3];
            cases.push((y, rng.next_f32() * 2.0 - 1.0));
        }
        // Octant edges: where the reduction switches, and the axes.
        for &(y, x) in &[
            (1.0f32, 1.0f32),
            (0.414_213_57, 1.0),
            (1.0, 0.414_213_57),
            (0.0, 1.0),
            (1.0, 0.0),
            (0.0, -1.0),
            (-1.0, 0.0),
            (-0.0, -1.0),
            (1e-45, 1.0),
            (1.0, 1e-45),
        ] {
            for (sy, sx) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
                let (y, x) = (y * sy, x * sx);
                cases.push((y, x));
                cases.push((y.next_up(), x));
                cases.push((y.next_down(), x.next_up()));
            }
        }
        let (mut worst_abs, mut worst_rel) = (0.0f64, 0.0f64);
        for &(y, x) in &cases {
            let exact = (y as f64).atan2(x as f64) / std::f64::consts::PI;
            let got = atan2_pi(y, x) as f64;
            // ±1 is the same angle (atan2(-0, -1) is -π in f64, +1 here).
            let err = match (got - exact).abs() {
                d if d > 1.0 => (2.0 - d).abs(),
                d => d,
            };
            // The bound: 6.1e-8 absolute everywhere, 3 ulps of the result near 0.
            let ulp = (exact.abs() as f32).max(f32::MIN_POSITIVE);
            let ulp = (ulp.next_up() - ulp) as f64;
            assert!(
                err <= 6.1e-8 && (exact.abs() >= 1e-3 || err <= 3.0 * ulp),
                "atan2_pi({y}, {x}) = {got}, exact {exact}: error {err:e}"
            );
            worst_abs = worst_abs.max(err);
            if exact.abs() < 1e-3 && exact != 0.0 {
                worst_rel = worst_rel.max(err / ulp);
            }
        }
        eprintln!(
            "atan2_pi: worst absolute error {worst_abs:e} half turns, near 0 {worst_rel:.2} ulp"
        );
        assert_eq!(atan2_pi(0.0, 0.0), 0.0);
        assert_eq!(atan2_pi(0.0, 1.0), 0.0);
        assert_eq!(atan2_pi(0.0, -1.0), 1.0);
        assert_eq!(atan2_pi(1.0, 0.0), 0.5);
        assert_eq!(atan2_pi(-1.0, 0.0), -0.5);
        assert!(atan2_pi(f32::NAN, 1.0).is_nan() && atan2_pi(1.0, f32::NAN).is_nan());
    }

    /// The loop over lanes the batch queries run is bit for bit the scalar call,
    /// at every lane of a vector.
    #[test]
    fn atan2_pi_in_lanes_and_pairs_is_the_scalar_call() {
        let mut rng = crate::rng::SplitMix64::new(17);
        let mut ys = [0.0f32; 16];
        let mut xs = [0.0f32; 16];
        for round in 0..50_000 {
            for i in 0..16 {
                let scale = [1.0f32, 1e-30, 1e20, 0.0][(round + i) % 4];
                ys[i] = (rng.next_f32() * 2.0 - 1.0) * scale;
                xs[i] = rng.next_f32() * 2.0 - 1.0;
                if round % 97 == 0 {
                    (ys[i], xs[i]) =
                        [(f32::NAN, 1.0), (-0.0, -1.0), (0.0, 0.0), (1e-45, -0.0)][i % 4];
                }
            }
            let lanes = atan2_pi_lanes(&ys, &xs);
            for i in 0..16 {
                assert_eq!(lanes[i].to_bits(), atan2_pi(ys[i], xs[i]).to_bits());
                let j = (i + 5) % 16;
                let pair = atan2_pi_pair([ys[i], ys[j]], [xs[i], xs[j]]);
                for (got, k) in pair.into_iter().zip([i, j]) {
                    let (y, x) = (ys[k], xs[k]);
                    assert_eq!(got.to_bits(), lanes[k].to_bits(), "pair ({y}, {x})");
                }
            }
        }
    }
}

/// A rotation, stored as an orthonormal 3×3 matrix (rows). Applying it is a
/// matrix-vector product; its inverse is the transpose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rotation {
    m: [[f32; 3]; 3],
}

impl Default for Rotation {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Rotation {
    /// No rotation.
    pub const IDENTITY: Self = Self {
        m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// A rotation by `degrees` about +z, counter-clockwise seen from above
    /// (+x turns towards +y).
    pub fn about_z_degrees(degrees: f32) -> Self {
        let (s, c) = (degrees as f64).to_radians().sin_cos();
        let (s, c) = (s as f32, c as f32);
        Self {
            m: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// A rotation from its matrix rows. Returns `None` unless the matrix is
    /// orthonormal with determinant +1 (to 1e-4).
    pub fn from_rows(m: [[f32; 3]; 3]) -> Option<Self> {
        let r = Self { m };
        let rows = [Vec3::from(m[0]), Vec3::from(m[1]), Vec3::from(m[2])];
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                let error = (rows[i].dot(rows[j]) - want).abs();
                // Written so that a NaN entry is rejected too.
                if error.is_nan() || error >= 1e-4 {
                    return None;
                }
            }
        }
        let det = rows[0].dot(rows[1].cross(rows[2]));
        ((det - 1.0).abs() < 1e-4).then_some(r)
    }

    /// The composition `self ∘ other` (apply `other` first).
    pub fn then_after(self, other: Self) -> Self {
        let mut m = [[0.0f32; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.m[i][k] * other.m[k][j]).sum();
            }
        }
        Self { m }
    }

    /// The matrix rows: applying the rotation is `d'[i] = rows[i] · d`.
    #[inline]
    pub fn rows(&self) -> [[f32; 3]; 3] {
        self.m
    }

    /// The inverse rotation (the transpose).
    pub fn inverse(self) -> Self {
        let m = self.m;
        Self {
            m: [
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ],
        }
    }

    /// Applies the rotation to a vector.
    #[inline]
    pub fn apply(&self, v: Vec3) -> Vec3 {
        let m = &self.m;
        Vec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    }

    /// True when this is exactly the identity (lets hot paths skip the product).
    #[inline]
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }
}
