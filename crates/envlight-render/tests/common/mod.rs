//! Helpers shared by the render tests (the chi-square test of BSDF sampling is
//! `envlight_verify::chi_square_warp`).

#![allow(dead_code)]

use envlight::Vec3;
use envlight_render::render::Rendered;

/// A unit direction at polar angle `theta_deg` from +z, in the xz plane.
pub fn polar(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}

/// Mean and standard error of the mean, per channel.
pub fn mean_and_error(values: &[[f32; 3]]) -> ([f64; 3], [f64; 3]) {
    let n = values.len() as f64;
    let mut mean = [0.0; 3];
    let mut se = [0.0; 3];
    for c in 0..3 {
        let m = values.iter().map(|v| v[c] as f64).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|v| (v[c] as f64 - m).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        mean[c] = m;
        se[c] = (var / n).sqrt();
    }
    (mean, se)
}

/// The image's mean over its pixels, per channel, and the standard error of that
/// mean from the render's per-pixel standard errors (pixels independent).
pub fn image_mean_and_error(r: &Rendered) -> ([f64; 3], [f64; 3]) {
    let n = r.image.pixels().len() as f64;
    let mut mean = [0.0f64; 3];
    let mut var = [0.0f64; 3];
    for (p, e) in r.image.pixels().iter().zip(r.std_error.pixels()) {
        for c in 0..3 {
            mean[c] += p[c] as f64 / n;
            var[c] += (e[c] as f64 / n).powi(2);
        }
    }
    (mean, var.map(f64::sqrt))
}
