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

/// Asks the CPU to bring the cache line holding `r` closer (a no-op on other
/// architectures).
#[inline(always)]
pub(crate) fn prefetch_read<T>(r: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint: it never faults and has no visible effect, and
    // the address comes from a live reference anyway. SSE, which provides it, is
    // part of the x86-64 baseline.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>((r as *const T).cast::<i8>());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = r;
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

/// `(sin πx, cos πx)`, inlined and branch-free, within 2.5 f32 ulps for `|x| < 2²²`
/// (libm's `sincosf` is a call costing as much as the rest of a light sample).
///
/// The argument is reduced exactly, `x = q/2 + r` with `q = round(2x)` and
/// `|r| ≤ 1/4`, so there is no rounding of `π x` to lose precision near multiples
/// of π (the poles of the lat-long map, where `sin θ` must keep its relative
/// accuracy). On `|r| ≤ 1/4`, `sin πr = r·P(r²)` and `cos πr = Q(r²)` with P of
/// degree 3 and Q of degree 4, fitted by iteratively reweighted least squares for
/// relative error 3·10⁻⁹ and absolute error 5·10⁻¹¹, far below f32 rounding; the
/// quadrant `q mod 4` then swaps and negates them.
#[inline(always)]
pub fn sin_cos_pi(x: f32) -> (f32, f32) {
    const P: [f32; 4] = [std::f32::consts::PI, -5.167_708, 2.549_761, -0.589_012_2];
    const Q: [f32; 5] = [1.0, -4.934_802, 4.058_707, -1.335_044_6, 0.231_329_71];
    // q = round(2x), clamped far outside the accurate range so the conversions
    // below are exact (NaN becomes -2³⁰ and yields NaN through r).
    #[allow(clippy::manual_clamp)] // clamp would keep NaN, which cannot be converted
    let y = (2.0 * x + 0.5).max(-1.0e9).min(1.0e9);
    // SAFETY: y is finite and within ±1e9, inside i32's range.
    let t = unsafe { y.to_int_unchecked::<i32>() };
    let q = t - (t as f32 > y) as i32;
    let r = x - 0.5 * q as f32;
    let r2 = r * r;
    // Estrin's scheme: pairs of terms in parallel, a shorter dependency chain than
    // Horner's on a sample's critical path.
    let r4 = r2 * r2;
    let sin = r * ((P[0] + P[1] * r2) + r4 * (P[2] + P[3] * r2));
    let cos = (Q[0] + Q[1] * r2) + r4 * ((Q[2] + Q[3] * r2) + r4 * Q[4]);
    // sin(π(q/2 + r)) and cos(...) for q = 0, 1, 2, 3 (mod 4) are
    // (s, c), (c, -s), (-s, -c), (-c, s): swap when q is odd, then flip signs. With
    // bit masks rather than branches, which a random quadrant would mispredict.
    let swap = 0u32.wrapping_sub(q as u32 & 1);
    let (sb, cb) = (sin.to_bits(), cos.to_bits());
    let a = (sb & !swap) | (cb & swap);
    let b = (cb & !swap) | (sb & swap);
    let a = a ^ ((q as u32 & 2) << 30);
    let b = b ^ (((q as u32).wrapping_add(1) & 2) << 30);
    (f32::from_bits(a), f32::from_bits(b))
}

/// `atan2(y, x)` in `(-π, π]`, about five times faster than libm's `atan2f` and
/// as accurate: evaluated in f64 after reduction to `[0, tan(π/8)]`, with a
/// near-minimax odd polynomial of degree 11 whose relative error is 6·10⁻¹⁰, far
/// below the f32 result's rounding. `atan2(0, 0)` is 0; NaN propagates.
#[inline(always)]
pub fn atan2_fast(y: f32, x: f32) -> f32 {
    use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};
    const TAN_PI_8: f64 = 0.414_213_562_373_095_03;
    // atan(t) = t·P(t²) on [0, tan(π/8)], fitted by iteratively reweighted least
    // squares on Chebyshev nodes.
    const P: [f64; 6] = [
        0.999_999_999_414_626_1,
        -0.333_333_081_092_851_2,
        0.199_982_391_292_769_2,
        -0.142_404_425_650_121_87,
        0.105_758_660_685_587_3,
        -0.060_403_409_485_716_31,
    ];
    let (ax, ay) = ((x as f64).abs(), (y as f64).abs());
    let (num, den, swapped) = if ay > ax {
        (ax, ay, true)
    } else {
        (ay, ax, false)
    };
    if den == 0.0 {
        return if x.is_nan() || y.is_nan() {
            f32::NAN
        } else {
            0.0
        };
    }
    // atan(t) for t = num/den ∈ [0, 1]; above tan(π/8) use
    // atan(t) = π/4 + atan((t - 1)/(t + 1)).
    let (arg, offset) = if num > TAN_PI_8 * den {
        ((num - den) / (num + den), FRAC_PI_4)
    } else {
        (num / den, 0.0)
    };
    let s = arg * arg;
    let poly = P[0] + s * (P[1] + s * (P[2] + s * (P[3] + s * (P[4] + s * P[5]))));
    let mut a = offset + arg * poly;
    if swapped {
        a = FRAC_PI_2 - a;
    }
    if x < 0.0 {
        a = PI - a;
    }
    if y < 0.0 {
        a = -a;
    }
    a as f32
}

/// A 3-vector of `f32` (a direction or a point). The frame is right-handed, z up.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
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
                assert!(err <= 2.5, "x={x}: {got} vs {exact} ({err} ulp)");
            }
        }
        println!("sin_cos_pi: worst error {worst:.3} ulp");
        // Exact values where the quadrants meet.
        assert_eq!(sin_cos_pi(0.0), (0.0, 1.0));
        assert_eq!(sin_cos_pi(0.5), (1.0, 0.0));
        assert_eq!(sin_cos_pi(1.0), (0.0, -1.0));
        assert_eq!(sin_cos_pi(1.5), (-1.0, 0.0));
        assert_eq!(sin_cos_pi(2.0), (0.0, 1.0));
    }

    #[test]
    fn atan2_fast_agrees_with_f64_atan2_to_f32_precision() {
        let mut rng = crate::rng::SplitMix64::new(5);
        let mut worst = 0.0f64;
        for k in 0..200_000 {
            let scale = if k % 3 == 0 { 1e-30 } else { 1.0 };
            let y = (rng.next_f32() * 2.0 - 1.0) * scale;
            let x = rng.next_f32() * 2.0 - 1.0;
            let exact = (y as f64).atan2(x as f64);
            let got = atan2_fast(y, x) as f64;
            // Within one f32 ulp of the exact angle (plus a hair for |angle| < 1).
            let ulp = (exact.abs().max(1e-38) as f32).to_bits();
            let ulp = (f32::from_bits(ulp + 1) - f32::from_bits(ulp)) as f64;
            worst = worst.max((got - exact).abs() / ulp);
        }
        assert!(worst <= 1.0, "worst error {worst} ulp");
        for (y, x) in [
            (0.0f32, 1.0f32),
            (1.0, 0.0),
            (0.0, -1.0),
            (-1.0, 0.0),
            (1.0, 1.0),
            (-1.0, -1.0),
        ] {
            assert!(
                (atan2_fast(y, x) - y.atan2(x)).abs() <= 2.0 * f32::EPSILON,
                "{y},{x}"
            );
        }
        assert_eq!(atan2_fast(0.0, 0.0), 0.0);
        assert!(atan2_fast(f32::NAN, 1.0).is_nan());
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
