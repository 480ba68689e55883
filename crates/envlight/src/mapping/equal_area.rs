//! The equal-area octahedral mapping between the unit square and the sphere
//! (Clarberg 2008, "Fast equal-area mapping of the (hemi)sphere using SIMD"; the
//! parameterization PBRT-v4 stores environment maps in), z up.
//!
//! **Derivation.** Put `a = 2u - 1`, `b = 2v - 1` and work in the quadrant
//! `a, b ≥ 0` (the others follow by the signs of x and y). The diamond
//! `|a| + |b| ≤ 1` is the upper hemisphere, the four corner triangles the lower one.
//! Let `r = |a| + |b|` in the diamond and `r = 2 - (|a| + |b|)` outside it (so `r`
//! runs from 0 at the poles to 1 on the equator). Take
//!
//! ```text
//! z = ±(1 - r²)   (+ inside the diamond),   φ = (π/4) ((|b| - |a|) / r + 1) ∈ [0, π/2],
//! (x, y) = (±cos φ, ±sin φ) · r √(2 - r²)   (signs of a and b).
//! ```
//!
//! In the quadrant the set `r ≤ r₀` is a triangle of area `r₀²/2`, and it maps onto
//! a quarter of the cap `1 - |z| ≤ r₀²`, of solid angle `(π/2) r₀²`; along each level
//! line of `r`, φ is linear in arc length. So area in the `(a, b)` square maps to
//! solid angle at the constant rate `π`, and with `da db = 4 du dv`,
//!
//! ```text
//! dω = 4π du dv       (EQUAL_AREA_JACOBIAN)
//! ```
//!
//! everywhere, with no pole singularity. The inverse reads `r = √(1 - |z|)` (computed
//! as `√((x² + y²)/(1 + |z|))`, exact near the poles) and
//! `φ = atan2(|y|, |x|)`, then `|b| = r φ/(π/2)`, `|a| = r - |b|` in the upper
//! hemisphere, or the reflection `(|a|, |b|) → (1 - |b|, 1 - |a|)` in the lower.
//!
//! **Orientation** (image coordinates: u left→right, v top→bottom):
//! - the centre `(½, ½)` looks at +z, the four corners at −z; the diamond through
//!   the edge midpoints is the upper hemisphere, its boundary the equator;
//! - the right edge's midpoint `(1, ½)` is +x, the left `(0, ½)` is −x; the bottom
//!   edge's midpoint `(½, 1)` is +y, the top `(½, 0)` is −y;
//! - so the quadrant `u > ½, v > ½` (bottom right) holds `x > 0, y > 0`, the top
//!   right `x > 0, y < 0`, the bottom left `x < 0, y > 0`, the top left `x, y < 0`.
//!
//! This is the convention of PBRT-v4's `EqualAreaSquareToSphere` with its image
//! rows from the top, so equal-area squares written by PBRT-v4 read with the same
//! directions (and a lat-long map converted by it agrees with
//! [`crate::mapping`]'s equirectangular convention).
//!
//! **Edges.** The square's boundary is folded: the point `(1, v)` is the same
//! direction as `(1, 1 - v)` (each edge is folded about its midpoint, along a
//! meridian of the lower hemisphere), likewise `(0, v) ~ (0, 1 - v)`,
//! `(u, 0) ~ (1 - u, 0)`, `(u, 1) ~ (1 - u, 1)`, and all four corners are −z. The
//! mapping is continuous across these folds on the sphere.

use crate::image::{EnvImage, Lookup};
use crate::math::{atan2_pi, Vec3};
use rayon::prelude::*;
use std::f32::consts::{FRAC_PI_2, PI};

/// `dω / (du dv)` of the equal-area mapping: `4π` everywhere.
pub const EQUAL_AREA_JACOBIAN: f32 = 4.0 * PI;

/// The unit direction at square point `(u, v) ∈ [0, 1]²` (points outside are
/// clamped onto the square; NaN counts as 0). See the module docs for the
/// formula and the orientation.
#[inline]
pub fn square_to_sphere(u: f32, v: f32) -> Vec3 {
    let Polar {
        a,
        b,
        quarter,
        z,
        sin_theta,
    } = Polar::of(u, v);
    let phi = FRAC_PI_2 * quarter;
    let (sin_phi, cos_phi) = phi.clamp(0.0, FRAC_PI_2).sin_cos();
    Vec3::new(
        (cos_phi * sin_theta).copysign(a),
        (sin_phi * sin_theta).copysign(b),
        z,
    )
}

/// The square point `[u, v] ∈ [0, 1]²` looking along `d` (normalised here; a zero
/// or non-finite `d` gives the centre, +z). On the square's folded boundary one of
/// the two equivalent points is returned. All in f32 with the angle of
/// [`crate::math::atan2_pi`] and no branch, so the batch queries compute the
/// same values in vector lanes.
#[inline(always)]
pub fn sphere_to_square(d: Vec3) -> [f32; 2] {
    let len = d.length();
    let valid = len > 0.0 && len.is_finite();
    // The normalisation of `Vec3::normalized`, applied to a harmless vector when
    // `d` is invalid so that the lanes version needs no branch.
    let inv = 1.0 / if valid { len } else { 1.0 };
    let unit = d * inv;
    let [u, v] = unit_sphere_to_square(unit);
    if valid {
        [u, v]
    } else {
        [0.5, 0.5]
    }
}

/// [`sphere_to_square`] of `N` directions (`x[i], y[i], z[i]`), as a loop the
/// compiler vectorizes: bit for bit the single calls.
#[inline(always)]
pub(crate) fn spheres_to_square<const N: usize>(
    x: &[f32; N],
    y: &[f32; N],
    z: &[f32; N],
) -> ([f32; N], [f32; N]) {
    let (mut u, mut v) = ([0.0f32; N], [0.0f32; N]);
    for i in 0..N {
        [u[i], v[i]] = sphere_to_square(Vec3::new(x[i], y[i], z[i]));
    }
    (u, v)
}

/// [`sphere_to_square`] of the unit `d`.
#[inline(always)]
fn unit_sphere_to_square(d: Vec3) -> [f32; 2] {
    let (x, y, z) = (d.x.abs(), d.y.abs(), d.z.abs());
    // 1 - |z| = (x² + y²)/(1 + |z|) for a unit vector, without cancellation.
    let r = ((x * x + y * y) / (1.0 + z)).sqrt().min(1.0);
    // 2 atan2(y, x)/π: 0 on the x axis (and for x = y = 0), 1 on the y axis.
    let phi_fraction = (2.0 * atan2_pi(y, x)).clamp(0.0, 1.0);
    let abs_b = r * phi_fraction;
    let abs_a = r - abs_b;
    let (abs_a, abs_b) = if d.z < 0.0 {
        (1.0 - abs_b, 1.0 - abs_a)
    } else {
        (abs_a, abs_b)
    };
    let a = abs_a.copysign(d.x);
    let b = abs_b.copysign(d.y);
    [
        (0.5 * (a + 1.0)).clamp(0.0, 1.0),
        (0.5 * (b + 1.0)).clamp(0.0, 1.0),
    ]
}

/// A square size for resampling a `src_width × src_height` lat-long map with about
/// the same number of texels: `√(w h)` rounded to the nearest multiple of 2 (at
/// least 2). 4096×2048 gives 2896.
pub fn default_size(src_width: usize, src_height: usize) -> usize {
    let texels = src_width as f64 * src_height as f64;
    let side = (texels.sqrt() / 2.0).round() as usize * 2;
    side.max(2)
}

/// Resamples a lat-long (equirectangular) map to a `size × size` equal-area square
/// (a `size` of 0 counts as 1).
///
/// Texel `(i, j)` holds the mean radiance of `src` (reconstructed with `lookup`)
/// over the texel's solid angle. The mapping being equal-area, uniform points in
/// the texel's square are uniform in that solid angle, so the mean is taken over
/// `k × k` stratified points (the centres of a `k × k` grid in the texel), with
/// `k = max(2, ⌈2 · src_height / size⌉)` so the points are denser than the source's
/// rows and every source texel of non-negligible solid angle is hit. Each point is
/// looked up with `src.lookup` at
/// [`direction_to_equirect`](crate::mapping::direction_to_equirect)`(square_to_sphere(u, v))`
/// (computed in one step, without the trigonometry of the round trip).
/// Rows are computed in parallel; the result does not depend on the thread count.
///
/// Cost: `size² k²` lookups, about `4 w h` for the default size.
pub fn resample_equirect(src: &EnvImage, size: usize, lookup: Lookup) -> EnvImage {
    let size = size.max(1);
    let k = (2 * src.height()).div_ceil(size).max(2);
    let inv = 1.0 / (size * k) as f64;
    let weight = 1.0 / (k * k) as f64;
    let mut texels = vec![[0.0f32; 3]; size * size];
    texels
        .par_chunks_mut(size)
        .enumerate()
        .for_each(|(j, row)| {
            for (i, texel) in row.iter_mut().enumerate() {
                let mut sum = [0.0f64; 3];
                for b in 0..k {
                    let v = ((j * k + b) as f64 + 0.5) * inv;
                    for a in 0..k {
                        let u = ((i * k + a) as f64 + 0.5) * inv;
                        let [su, sv] = square_to_equirect(u as f32, v as f32);
                        let l = src.lookup(su, sv, lookup);
                        for c in 0..3 {
                            sum[c] += l[c] as f64;
                        }
                    }
                }
                *texel = sum.map(|s| (s * weight) as f32);
            }
        });
    // Means of finite non-negative lookups are finite and non-negative, and the
    // size is positive, so this cannot fail.
    match EnvImage::new(size, size, texels) {
        Ok(image) => image,
        Err(e) => unreachable!("resampled texels are valid: {e}"),
    }
}

/// `direction_to_equirect(square_to_sphere(u, v))` without forming the direction:
/// `θ = atan2(r √(2 - r²), ±(1 - r²))`, and φ is the quadrant angle reflected by
/// the signs of `a = 2u - 1`, `b = 2v - 1` (no sine or cosine needed).
#[inline]
fn square_to_equirect(u: f32, v: f32) -> [f32; 2] {
    let Polar {
        a,
        b,
        quarter,
        z,
        sin_theta,
    } = Polar::of(u, v);
    let theta = sin_theta.atan2(z);
    // φ within the quadrant as a fraction of a quarter turn, then the quadrant.
    let quarter = quarter.clamp(0.0, 1.0);
    let turns = match (a < 0.0, b < 0.0) {
        (false, false) => quarter,
        (true, false) => 2.0 - quarter,
        (true, true) => 2.0 + quarter,
        (false, true) => 4.0 - quarter,
    } * 0.25;
    // φ = 2π exactly (b = -0 side of the +x meridian) is the seam: wrap to 0.
    let eq_u = if turns >= 1.0 { 0.0 } else { turns };
    [eq_u, (theta * (1.0 / PI)).clamp(0.0, 1.0)]
}

/// A square point's place on the sphere before any sine or cosine: `a = 2u - 1`,
/// `b = 2v - 1`, `φ` within its quadrant as a fraction of a quarter turn (from
/// the radius `r` of its diamond), `z = cos θ` and `sin θ`.
struct Polar {
    a: f32,
    b: f32,
    quarter: f32,
    z: f32,
    sin_theta: f32,
}

impl Polar {
    #[inline(always)]
    fn of(u: f32, v: f32) -> Self {
        let a = 2.0 * unit(u) - 1.0;
        let b = 2.0 * unit(v) - 1.0;
        let (abs_a, abs_b) = (a.abs(), b.abs());
        let sum = abs_a + abs_b;
        let upper = sum <= 1.0;
        // Computed directly in each half (rather than as 1 - |1 - sum|) so no
        // bits are lost near the poles.
        let r = if upper { sum } else { 2.0 - sum };
        let quarter = if r > 0.0 {
            0.5 * ((abs_b - abs_a) / r + 1.0)
        } else {
            0.0
        };
        let r2 = r * r;
        let z = if upper { 1.0 - r2 } else { r2 - 1.0 };
        let sin_theta = r * (2.0 - r2).max(0.0).sqrt();
        Self {
            a,
            b,
            quarter,
            z,
            sin_theta,
        }
    }
}

/// `x` clamped into `[0, 1]`; NaN gives 0.
#[inline]
fn unit(x: f32) -> f32 {
    if x > 0.0 {
        x.min(1.0)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alias::test_support;
    use crate::mapping::{direction_to_equirect, equirect_to_direction};
    use crate::rng::{xi_2d, SplitMix64};

    /// Significance level of every chi-square test here.
    const ALPHA: f64 = 1e-3;

    fn near(d: Vec3, want: [f32; 3]) -> bool {
        d.dot(Vec3::from(want)) > 1.0 - 1e-6
    }

    #[test]
    fn orientation_is_as_documented() {
        assert!(near(square_to_sphere(0.5, 0.5), [0.0, 0.0, 1.0]));
        for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            assert!(
                near(square_to_sphere(u, v), [0.0, 0.0, -1.0]),
                "corner {u},{v}"
            );
        }
        assert!(near(square_to_sphere(1.0, 0.5), [1.0, 0.0, 0.0]));
        assert!(near(square_to_sphere(0.0, 0.5), [-1.0, 0.0, 0.0]));
        assert!(near(square_to_sphere(0.5, 1.0), [0.0, 1.0, 0.0]));
        assert!(near(square_to_sphere(0.5, 0.0), [0.0, -1.0, 0.0]));
        // Diamond vertices (edge midpoints) are on the equator; the diamond's
        // diagonal midpoints too, at 45° between the axes.
        let d = square_to_sphere(0.75, 0.75);
        let h = std::f32::consts::FRAC_1_SQRT_2;
        assert!(near(d, [h, h, 0.0]), "{d:?}");
        // Octants: sign of x from u - ½, of y from v - ½, of z from inside/outside
        // the diamond.
        let mut rng = SplitMix64::new(1);
        for _ in 0..10_000 {
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let d = square_to_sphere(u, v);
            let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
            if a.abs() > 1e-4 && b.abs() > 1e-4 && (a.abs() + b.abs() - 1.0).abs() > 1e-4 {
                assert_eq!(d.x > 0.0, u > 0.5, "{u},{v} → {d:?}");
                assert_eq!(d.y > 0.0, v > 0.5, "{u},{v} → {d:?}");
                assert_eq!(d.z > 0.0, a.abs() + b.abs() < 1.0, "{u},{v} → {d:?}");
            }
            assert!((d.length() - 1.0).abs() < 1e-5);
        }
    }

    #[test]
    fn round_trips_including_edges_and_corners() {
        // Square → sphere → square → sphere on a grid that includes the edges and
        // corners (where the square point is ambiguous, so directions are compared).
        let n = 200;
        for j in 0..=n {
            for i in 0..=n {
                let (u, v) = (i as f32 / n as f32, j as f32 / n as f32);
                let d = square_to_sphere(u, v);
                let [u2, v2] = sphere_to_square(d);
                let d2 = square_to_sphere(u2, v2);
                assert!(d.dot(d2) > 0.9999, "{u},{v} → {d:?} → {u2},{v2} → {d2:?}");
                // Inside the square, away from the folds, the point itself returns.
                if i > 0 && i < n && j > 0 && j < n {
                    assert!(
                        (u - u2).abs() < 1e-5 && (v - v2).abs() < 1e-5,
                        "{u},{v} → {u2},{v2}"
                    );
                }
            }
        }
        // Sphere → square → sphere, random and special directions.
        let mut rng = SplitMix64::new(2);
        let mut dirs: Vec<Vec3> = (0..20_000)
            .map(|_| {
                let z = 2.0 * rng.next_f32() - 1.0;
                let (s, c) = (2.0 * PI * rng.next_f32()).sin_cos();
                let r = (1.0 - z * z).max(0.0).sqrt();
                Vec3::new(r * c, r * s, z)
            })
            .collect();
        for &(x, y, z) in &[
            (0.0, 0.0, 1.0),
            (0.0, 0.0, -1.0),
            (1.0, 0.0, 0.0),
            (-1.0, 0.0, 0.0),
            (0.0, 1.0, 0.0),
            (0.0, -1.0, 0.0),
            (1e-7, 0.0, -1.0),
            (0.0, -1e-7, 1.0),
            (1.0, 1.0, 0.0),
            (-1.0, 1e-8, -1e-8),
        ] {
            dirs.push(Vec3::new(x, y, z).normalized().unwrap());
        }
        for d in dirs {
            let [u, v] = sphere_to_square(d);
            assert!((0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v));
            let d2 = square_to_sphere(u, v);
            assert!(d.dot(d2) > 0.9999, "{d:?} → {u},{v} → {d2:?}");
            assert!((d - d2).length() < 1e-5, "{d:?} → {u},{v} → {d2:?}");
        }
    }

    #[test]
    fn continuous_across_the_folded_edges() {
        // Points just inside opposite halves of an edge, mirrored about its
        // midpoint, are the same direction up to O(ε).
        let eps = 1e-4f32;
        for k in 0..=100 {
            let t = k as f32 / 100.0;
            let pairs = [
                ((1.0 - eps, t), (1.0 - eps, 1.0 - t)),
                ((eps, t), (eps, 1.0 - t)),
                ((t, eps), (1.0 - t, eps)),
                ((t, 1.0 - eps), (1.0 - t, 1.0 - eps)),
            ];
            for ((u1, v1), (u2, v2)) in pairs {
                let (d1, d2) = (square_to_sphere(u1, v1), square_to_sphere(u2, v2));
                assert!(
                    (d1 - d2).length() < 20.0 * eps,
                    "({u1},{v1}) {d1:?} vs ({u2},{v2}) {d2:?}"
                );
            }
        }
        // And inside the square, a small step is a small step (Lipschitz).
        let mut rng = SplitMix64::new(3);
        for _ in 0..10_000 {
            let (u, v) = (rng.next_f32(), rng.next_f32());
            let (du, dv) = (1e-4 * (rng.next_f32() - 0.5), 1e-4 * (rng.next_f32() - 0.5));
            let d = square_to_sphere(u, v) - square_to_sphere(u + du, v + dv);
            assert!(d.length() < 10.0 * (du.abs() + dv.abs()) + 1e-6, "{u},{v}");
        }
    }

    #[test]
    fn jacobian_is_four_pi() {
        // |∂ω/∂u × ∂ω/∂v| by central differences (in f64 around the f32 map) at
        // random points away from the folds, where the map is smooth.
        let mut rng = SplitMix64::new(4);
        let h = 1e-3f32;
        let mut checked = 0;
        for _ in 0..5000 {
            let (u, v) = (0.01 + 0.98 * rng.next_f32(), 0.01 + 0.98 * rng.next_f32());
            let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
            if a.abs() < 0.01 || b.abs() < 0.01 || (a.abs() + b.abs() - 1.0).abs() < 0.01 {
                continue;
            }
            let du = (square_to_sphere(u + h, v) - square_to_sphere(u - h, v)) * (0.5 / h);
            let dv = (square_to_sphere(u, v + h) - square_to_sphere(u, v - h)) * (0.5 / h);
            let jac = du.cross(dv).length();
            assert!(
                (jac / EQUAL_AREA_JACOBIAN - 1.0).abs() < 2e-2,
                "{u},{v}: {jac}"
            );
            checked += 1;
        }
        assert!(checked > 4000);
    }

    /// Chi-square of directions from uniform square points against uniform solid
    /// angle, over an equal-area grid of `nz` bands in z × `nphi` sectors in φ.
    fn uniformity_p_value(map: impl Fn(f32, f32) -> Vec3, n: u64, seed: u64) -> f64 {
        let (nz, nphi) = (20usize, 40usize);
        let mut counts = vec![0u64; nz * nphi];
        for k in 0..n {
            let [u, v] = xi_2d(seed, k);
            let d = map(u, v);
            let iz = (((d.z + 1.0) * 0.5 * nz as f32) as usize).min(nz - 1);
            let phi = d.y.atan2(d.x).rem_euclid(2.0 * PI);
            let ip = ((phi / (2.0 * PI) * nphi as f32) as usize).min(nphi - 1);
            counts[iz * nphi + ip] += 1;
        }
        let expected = vec![n as f64 / (nz * nphi) as f64; nz * nphi];
        test_support::chi_square(&counts, &expected).2
    }

    #[test]
    fn uniform_square_points_are_uniform_directions() {
        // α = 1e-3, N = 400 000, seed 5; 800 equal-solid-angle bins.
        let p = uniformity_p_value(square_to_sphere, 400_000, 5);
        assert!(p > ALPHA, "p = {p}");
        // A map with the wrong Jacobian (u squared first) is rejected.
        let p = uniformity_p_value(|u, v| square_to_sphere(u * u, v), 400_000, 5);
        assert!(p < ALPHA, "p = {p}");
    }

    #[test]
    fn direct_equirect_coordinates_match_the_round_trip() {
        let mut rng = SplitMix64::new(6);
        let mut points: Vec<(f32, f32)> = (0..20_000)
            .map(|_| (rng.next_f32(), rng.next_f32()))
            .collect();
        points.extend([
            (0.5, 0.5),
            (0.0, 0.0),
            (1.0, 0.5),
            (0.5, 0.0),
            (0.25, 0.75),
            (1.0, 1.0),
        ]);
        for (u, v) in points {
            let d = square_to_sphere(u, v);
            let [eu, ev] = square_to_equirect(u, v);
            let [wu, wv] = direction_to_equirect(d);
            assert!((ev - wv).abs() < 2e-6, "{u},{v}: v {ev} vs {wv}");
            // u is periodic, and meaningless at the poles.
            let du = (eu - wu).abs().min(1.0 - (eu - wu).abs());
            assert!(du * d.x.hypot(d.y) < 2e-6, "{u},{v}: u {eu} vs {wu}");
            assert!((0.0..1.0).contains(&eu) && (0.0..=1.0).contains(&ev));
            let back = equirect_to_direction(eu, ev).0;
            assert!(back.dot(d) > 1.0 - 1e-6);
        }
    }

    #[test]
    fn non_finite_and_degenerate_inputs() {
        for d in [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(f32::NAN, 0.0, 1.0),
            Vec3::new(f32::INFINITY, 0.0, 0.0),
        ] {
            assert_eq!(sphere_to_square(d), [0.5, 0.5]);
        }
        // Not unit length: normalised first.
        let [u, v] = sphere_to_square(Vec3::new(0.0, 0.0, -7.0));
        assert!(near(square_to_sphere(u, v), [0.0, 0.0, -1.0]));
        for (u, v) in [
            (f32::NAN, 0.5),
            (-3.0, 2.0),
            (f32::INFINITY, f32::NEG_INFINITY),
        ] {
            let d = square_to_sphere(u, v);
            assert!((d.length() - 1.0).abs() < 1e-5, "{d:?}");
        }
        assert_eq!(default_size(4096, 2048), 2896);
        assert_eq!(default_size(2, 1), 2);
        assert_eq!(default_size(1, 1), 2);
        assert_eq!(default_size(1000, 500) % 2, 0);
    }

    /// A smooth positive lat-long map.
    fn smooth_map(w: usize, h: usize) -> EnvImage {
        EnvImage::from_fn(w, h, |i, j| {
            let (d, _) =
                equirect_to_direction((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32);
            let base = 1.0 + 0.6 * d.z + 0.3 * d.x * d.y + 0.2 * (3.0 * d.y).sin();
            [base, 0.5 * base + 0.2 * d.x, 2.0 - d.z]
        })
        .unwrap()
    }

    /// `∫ L dω` of a lat-long map's lookup by a fine sin-weighted midpoint rule.
    fn equirect_integral(src: &EnvImage, lookup: Lookup) -> [f64; 3] {
        let (nu, nv) = (4 * src.width(), 4 * src.height());
        let mut sum = [0.0f64; 3];
        for j in 0..nv {
            let v = (j as f64 + 0.5) / nv as f64;
            let w = (std::f64::consts::PI * v).sin();
            for i in 0..nu {
                let u = (i as f64 + 0.5) / nu as f64;
                let l = src.lookup(u as f32, v as f32, lookup);
                for c in 0..3 {
                    sum[c] += l[c] as f64 * w;
                }
            }
        }
        let scale = 2.0 * std::f64::consts::PI.powi(2) / (nu * nv) as f64;
        sum.map(|s| s * scale)
    }

    fn equal_area_integral(img: &EnvImage) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for t in img.texels() {
            for c in 0..3 {
                sum[c] += t[c] as f64;
            }
        }
        let scale = EQUAL_AREA_JACOBIAN as f64 / img.texels().len() as f64;
        sum.map(|s| s * scale)
    }

    #[test]
    fn resampling_a_constant_map_is_constant() {
        let src = EnvImage::from_fn(64, 32, |_, _| [0.25, 1.0, 3.0]).unwrap();
        for lookup in [Lookup::Nearest, Lookup::Bilinear] {
            let img = resample_equirect(&src, 20, lookup);
            assert_eq!((img.width(), img.height()), (20, 20));
            for t in img.texels() {
                for (c, want) in t.iter().zip([0.25, 1.0, 3.0]) {
                    assert!((c - want).abs() < 1e-6 * want, "{t:?}");
                }
            }
        }
    }

    #[test]
    fn resampling_preserves_the_integral() {
        let src = smooth_map(128, 64);
        for lookup in [Lookup::Nearest, Lookup::Bilinear] {
            let want = equirect_integral(&src, lookup);
            let img = resample_equirect(&src, default_size(128, 64), lookup);
            let got = equal_area_integral(&img);
            for c in 0..3 {
                let rel = (got[c] - want[c]).abs() / want[c];
                println!("{lookup:?} channel {c}: relative error {rel:.2e}");
                assert!(
                    rel < 1e-3,
                    "{lookup:?} channel {c}: {} vs {} ({rel:.2e})",
                    got[c],
                    want[c]
                );
            }
        }
        // The same check catches a resampler that forgets the equal-area weighting
        // (here: reading the lat-long map over the square as if it were already
        // equal-area), on a map with L = 1 + z²: ∫ = 16π/3, but the mean over
        // lat-long rows is 3/2, not 4/3.
        let src = EnvImage::from_fn(128, 64, |_, j| {
            let z = (std::f32::consts::PI * (j as f32 + 0.5) / 64.0).cos();
            [1.0 + z * z; 3]
        })
        .unwrap();
        let want = equirect_integral(&src, Lookup::Bilinear);
        let right = equal_area_integral(&resample_equirect(&src, 90, Lookup::Bilinear));
        assert!((right[0] - want[0]).abs() / want[0] < 1e-3);
        let wrong = EnvImage::from_fn(90, 90, |i, j| {
            src.lookup(
                (i as f32 + 0.5) / 90.0,
                (j as f32 + 0.5) / 90.0,
                Lookup::Bilinear,
            )
        })
        .unwrap();
        let wrong = equal_area_integral(&wrong);
        assert!(
            (wrong[0] - want[0]).abs() / want[0] > 1e-3,
            "{wrong:?} vs {want:?}"
        );
    }

    #[test]
    fn resampled_texels_look_the_right_way() {
        // Upper hemisphere bright, lower dark: texels inside the diamond are bright,
        // outside dark (except the ones the equator crosses).
        let src =
            EnvImage::from_fn(64, 32, |_, j| if j < 16 { [1.0; 3] } else { [0.0; 3] }).unwrap();
        let n = 32;
        let img = resample_equirect(&src, n, Lookup::Nearest);
        for j in 0..n {
            for i in 0..n {
                let (a, b) = (
                    2.0 * (i as f32 + 0.5) / n as f32 - 1.0,
                    2.0 * (j as f32 + 0.5) / n as f32 - 1.0,
                );
                let l = img.texel(i, j)[0];
                if a.abs() + b.abs() < 1.0 - 2.0 / n as f32 {
                    assert_eq!(l, 1.0, "({i}, {j})");
                } else if a.abs() + b.abs() > 1.0 + 2.0 / n as f32 {
                    assert_eq!(l, 0.0, "({i}, {j})");
                }
            }
        }
        // +x bright column of the lat-long map (u = 0) lands at the right edge's middle.
        let src = EnvImage::from_fn(64, 32, |i, _| {
            if i == 0 || i == 63 {
                [1.0; 3]
            } else {
                [0.0; 3]
            }
        })
        .unwrap();
        let img = resample_equirect(&src, n, Lookup::Nearest);
        assert!(img.texel(n - 1, n / 2)[0] > 0.0 && img.texel(0, n / 2)[0] == 0.0);
    }

    #[test]
    fn resampling_is_independent_of_the_thread_count() {
        let src = smooth_map(64, 32);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let a = one.install(|| resample_equirect(&src, 30, Lookup::Bilinear));
        let b = resample_equirect(&src, 30, Lookup::Bilinear);
        assert_eq!(a, b);
    }

    /// Cost of the mapping and of resampling a 4096×2048 map at the default size.
    /// Run: `cargo test --release -p envlight --lib equal_area::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing() {
        let xi: Vec<[f32; 2]> = (0..2_000_000).map(|k| xi_2d(2, k)).collect();
        test_support::time_per_call("square_to_sphere", &xi, &|[u, v]| square_to_sphere(u, v).x);
        let dirs: Vec<Vec3> = xi.iter().map(|&[u, v]| square_to_sphere(u, v)).collect();
        test_support::time_per_call("sphere_to_square", &dirs, &|d| sphere_to_square(d)[0]);
        test_support::time_per_call("equirect_to_direction", &xi, &|[u, v]| {
            equirect_to_direction(u, v).0.x
        });
        test_support::time_per_call("direction_to_equirect", &dirs, &|d| {
            direction_to_equirect(d)[0]
        });
        let src = smooth_map(4096, 2048);
        let size = default_size(4096, 2048);
        let start = std::time::Instant::now();
        let img = resample_equirect(&src, size, Lookup::Bilinear);
        println!(
            "resample 4096x2048 → {size}²: {:?} ({} threads)",
            start.elapsed(),
            rayon::current_num_threads()
        );
        assert_eq!(img.width(), size);
    }
}
