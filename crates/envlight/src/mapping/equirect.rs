//! The equirectangular (latitude-longitude) mapping between image coordinates and
//! directions, z up:
//!
//! ```text
//! θ = π v,  φ = 2π u,  ω = (sin θ cos φ, sin θ sin φ, cos θ)
//! dω = sin θ dθ dφ = 2π² sin θ du dv
//! ```
//!
//! So the top row looks at +z, `u = 0` at +x and `u = 0.25` at +y.

use crate::distribution::ONE_MINUS_EPSILON;
use crate::math::{atan2_pi_lanes, atan2_pi_pair, sin_cos_pi, Vec3};
use std::f32::consts::PI;

/// `dω / (du dv) = 2π² sin θ`: this constant times `sin θ`.
pub const EQUIRECT_JACOBIAN: f32 = 2.0 * PI * PI;

/// The unit direction at image point `(u, v)`, and `sin θ` at it.
#[inline(always)]
pub fn equirect_to_direction(u: f32, v: f32) -> (Vec3, f32) {
    let (sin_theta, cos_theta) = sin_cos_pi(v);
    let (sin_phi, cos_phi) = sin_cos_pi(2.0 * u);
    let sin_theta = sin_theta.max(0.0);
    (
        Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta),
        sin_theta,
    )
}

/// The image point `[u, v] ∈ [0, 1)×[0, 1]` looking along the unit direction `d`:
/// `v = θ/π = atan2(√(x² + y²), z)/π`, `u = φ/2π` with `φ = atan2(y, x)` wrapped to
/// `[0, 2π)`, in f32 ([`crate::math::atan2_pi`]: within 3·10⁻⁸ of the exact value, and with full
/// relative precision next to the poles, where `acos` of an f32 `z` would be good
/// to only about 3·10⁻⁴ rad).
///
/// The round trip image point → direction → image point is therefore good to a
/// few 10⁻⁸, not exact: a point drawn within that distance of a cell's edge can
/// come back in the neighbour cell. The light's sampling settles such points
/// inside their cell (`EnvironmentLight::sample`).
#[inline(always)]
pub fn direction_to_equirect(d: Vec3) -> [f32; 2] {
    direction_to_equirect_and_csc(d).0
}

/// [`direction_to_equirect`] and `1 / sin θ` at `d` (any non-zero length), read
/// off the direction as `|d| / √(x² + y²)` rather than recomputed from `v`: no
/// trigonometry, full relative precision next to the poles (+∞ on them), and as a
/// reciprocal it is ready long before the angles are, so that a pdf divided by the
/// Jacobian becomes a multiplication at the end of the query's critical path.
#[inline(always)]
pub fn direction_to_equirect_and_csc(d: Vec3) -> ([f32; 2], f32) {
    let (r, csc_theta) = radius_and_csc(d);
    let [v, half_turns] = atan2_pi_pair([r, d.y], [d.z, d.x]);
    ([u_of_half_turns(half_turns), v], csc_theta)
}

/// `√(x² + y²)` and `1 / sin θ = |d| / √(x² + y²)` of `d`, as
/// [`direction_to_equirect_and_csc`] computes them (bit for bit).
#[inline(always)]
pub(crate) fn radius_and_csc(d: Vec3) -> (f32, f32) {
    let r2 = d.x * d.x + d.y * d.y;
    let r = r2.sqrt();
    (r, (r2 + d.z * d.z).sqrt() / r)
}

/// `u = φ / 2π` in `[0, 1)` from `φ / π` in `[-1, 1]`.
#[inline(always)]
fn u_of_half_turns(half_turns: f32) -> f32 {
    let u = 0.5 * half_turns;
    let u = if half_turns < 0.0 { u + 1.0 } else { u };
    u.min(ONE_MINUS_EPSILON)
}

/// [`direction_to_equirect_and_csc`] for `N` directions given by their
/// coordinates (`x[i], y[i], z[i]`), as loops over the lanes that the compiler
/// vectorizes (16 lanes of f32 with AVX-512): the same operations in the same
/// order, so bit for bit the same values. Returns the `u`, `v` and `1 / sin θ` of
/// each.
#[inline(always)]
pub(crate) fn directions_to_equirect_and_csc<const N: usize>(
    x: &[f32; N],
    y: &[f32; N],
    z: &[f32; N],
) -> ([f32; N], [f32; N], [f32; N]) {
    let mut r = [0.0f32; N];
    let mut csc = [0.0f32; N];
    for i in 0..N {
        let r2 = x[i] * x[i] + y[i] * y[i];
        r[i] = r2.sqrt();
        csc[i] = (r2 + z[i] * z[i]).sqrt() / r[i];
    }
    let v = atan2_pi_lanes(&r, z);
    let mut u = atan2_pi_lanes(y, x);
    for u in &mut u {
        *u = u_of_half_turns(*u);
    }
    (u, v, csc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conventions_hold() {
        let (d, s) = equirect_to_direction(0.0, 0.0);
        assert!((d.z - 1.0).abs() < 1e-6 && s.abs() < 1e-6);
        let (d, _) = equirect_to_direction(0.0, 0.5);
        assert!((d.x - 1.0).abs() < 1e-6);
        let (d, _) = equirect_to_direction(0.25, 0.5);
        assert!((d.y - 1.0).abs() < 1e-6);
        let (d, _) = equirect_to_direction(0.7, 1.0);
        assert!((d.z + 1.0).abs() < 1e-6);
    }

    #[test]
    fn round_trip() {
        for i in 0..64 {
            for j in 1..32 {
                let (u, v) = ((i as f32 + 0.37) / 64.0, (j as f32 + 0.11) / 33.0);
                let (d, _) = equirect_to_direction(u, v);
                let [u2, v2] = direction_to_equirect(d);
                assert!(
                    (u - u2).abs() < 2e-6 && (v - v2).abs() < 2e-6,
                    "{u},{v} -> {u2},{v2}"
                );
            }
        }
        // Near the poles the polar angle keeps its precision.
        let tiny = 1e-6f32;
        let [_, v] = direction_to_equirect(Vec3::new(tiny, 0.0, (1.0 - tiny * tiny).sqrt()));
        assert!((v * PI / tiny - 1.0).abs() < 1e-4, "{v}");
        // Just below the seam stays just below 1, never reaches 1.
        let [u, _] = direction_to_equirect(Vec3::new(1.0, -1e-9, 0.0));
        assert!(u < 1.0);
    }
}
