//! Procedural environment maps that need no file, so every command works out of
//! the box. Names are given as `builtin:NAME`.

use crate::image::EnvImage;
use crate::mapping::equirect_to_direction;
use crate::math::Vec3;

/// The names of the built-in maps, for help text and errors.
pub const NAMES: [&str; 1] = ["sky"];

/// Default resolution of the built-in maps.
pub const DEFAULT_SIZE: (usize, usize) = (1024, 512);

/// Direction of the built-in sky's sun: 35° above the horizon, azimuth 60° from +x
/// towards +y.
pub fn sun_direction() -> Vec3 {
    let (elevation, azimuth) = (35f32.to_radians(), 60f32.to_radians());
    Vec3::new(
        elevation.cos() * azimuth.cos(),
        elevation.cos() * azimuth.sin(),
        elevation.sin(),
    )
}

/// Angular radius of the built-in sun disc, in radians (1°, about four times the real
/// sun so that it spans a few texels at the default resolution).
pub const SUN_ANGULAR_RADIUS: f32 = 0.017_453_3;

/// Radiance of the sun disc (linear RGB): warm white, about 10⁵ times the darkest
/// ground, and bright enough that the sun gives roughly 80% of the irradiance of an
/// upward-facing surface.
pub const SUN_RADIANCE: [f32; 3] = [52_000.0, 48_000.0, 42_000.0];

/// The built-in map called `name` (without the `builtin:` prefix) at the default
/// resolution, or `None` for an unknown name.
pub fn by_name(name: &str) -> Option<EnvImage> {
    match name {
        "sky" => Some(sky(DEFAULT_SIZE.0, DEFAULT_SIZE.1)),
        _ => None,
    }
}

/// A daylight sky at `width × height` (equirectangular, z up): a blue gradient
/// brightening towards a hazy horizon, a glow around a small, very bright sun, and a
/// darker textured ground below the horizon. Dynamic range about 10⁵.
///
/// Each texel is the mean of 4×4 sub-texel evaluations, so the sun disc has
/// anti-aliased edges and its energy does not depend much on the resolution.
///
/// # Panics
/// When a side is 0.
pub fn sky(width: usize, height: usize) -> EnvImage {
    assert!(width > 0 && height > 0, "the sky needs at least one texel");
    const SUB: usize = 4;
    let mut texels = vec![[0.0f32; 3]; width * height];
    use rayon::prelude::*;
    texels
        .par_chunks_mut(width)
        .enumerate()
        .for_each(|(y, row)| {
            for (x, texel) in row.iter_mut().enumerate() {
                let mut sum = [0.0f32; 3];
                for sy in 0..SUB {
                    for sx in 0..SUB {
                        let u = (x as f32 + (sx as f32 + 0.5) / SUB as f32) / width as f32;
                        let v = (y as f32 + (sy as f32 + 0.5) / SUB as f32) / height as f32;
                        let l = sky_radiance(equirect_to_direction(u, v).0);
                        for k in 0..3 {
                            sum[k] += l[k];
                        }
                    }
                }
                *texel = sum.map(|s| s / (SUB * SUB) as f32);
            }
        });
    EnvImage::new(width, height, texels).expect("the procedural sky is finite and non-negative")
}

/// Radiance of the built-in sky seen along the unit direction `d`.
fn sky_radiance(d: Vec3) -> [f32; 3] {
    let sun = sun_direction();
    let cos_sun = d.dot(sun).clamp(-1.0, 1.0);
    let angle = cos_sun.acos();
    if d.z < 0.0 {
        // Ground: a dim, slightly warm soil with a large checker texture, darker far
        // below the horizon; lit by the sun, so its brightness follows sun elevation.
        let phi = d.y.atan2(d.x);
        let theta = (-d.z).acos();
        let checker = ((phi * 8.0 / std::f32::consts::PI).floor() as i32
            + (theta * 12.0 / std::f32::consts::PI).floor() as i32)
            .rem_euclid(2) as f32;
        let k = 0.5 * (0.55 + 0.45 * checker) * (0.7 + 0.3 * (1.0 + d.z));
        return [0.55 * k, 0.42 * k, 0.30 * k];
    }
    if angle < SUN_ANGULAR_RADIUS {
        return SUN_RADIANCE;
    }
    // Sky: deep blue at the zenith, whitish haze at the horizon.
    let h = d.z.max(0.0);
    let haze = (1.0 - h).powi(4);
    let zenith = [0.18f32, 0.35, 0.85];
    let horizon = [0.85f32, 0.9, 1.0];
    let mut l = [0.0f32; 3];
    for k in 0..3 {
        l[k] = (zenith[k] + (horizon[k] - zenith[k]) * haze) * 1.2;
    }
    // Aureole: forward scattering around the sun, falling off over a few degrees.
    let glow = 60.0 * (-angle / 0.05).exp() + 2.0 * (-angle / 0.4).exp();
    let tint = [1.0f32, 0.9, 0.7];
    for k in 0..3 {
        l[k] += glow * tint[k];
    }
    l
}
