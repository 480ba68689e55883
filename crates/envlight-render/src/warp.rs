//! Warps from the unit square to directions, each with its solid-angle density.

use envlight::Vec3;
use std::f32::consts::{FRAC_1_PI, PI};

/// Concentric map of `[0, 1)²` onto the unit disc (Shirley & Chiu 1997): area
/// preserving up to a constant, low distortion.
#[inline]
pub fn square_to_disc_concentric(u: [f32; 2]) -> [f32; 2] {
    let (a, b) = (2.0 * u[0] - 1.0, 2.0 * u[1] - 1.0);
    if a == 0.0 && b == 0.0 {
        return [0.0, 0.0];
    }
    let (r, phi) = if a.abs() > b.abs() {
        (a, 0.25 * PI * (b / a))
    } else {
        (b, 0.5 * PI - 0.25 * PI * (a / b))
    };
    [r * phi.cos(), r * phi.sin()]
}

/// Cosine-weighted direction on the +z hemisphere (Malley's method).
#[inline]
pub fn square_to_cosine_hemisphere(u: [f32; 2]) -> Vec3 {
    let [x, y] = square_to_disc_concentric(u);
    let z = (1.0 - x * x - y * y).max(0.0).sqrt();
    Vec3::new(x, y, z)
}

/// Density of [`square_to_cosine_hemisphere`]: `max(0, cos θ) / π` per steradian.
#[inline]
pub fn cosine_hemisphere_pdf(w: Vec3) -> f32 {
    w.z.max(0.0) * FRAC_1_PI
}

/// Uniform direction on the whole sphere: `z = 1 - 2 u0`, `φ = 2π u1`.
pub use envlight::math::uniform_sphere as square_to_uniform_sphere;

/// Density of [`square_to_uniform_sphere`]: `1 / 4π` per steradian.
pub const UNIFORM_SPHERE_PDF: f32 = 0.25 * FRAC_1_PI;
