//! What the query examples and the benches share: queries drawn from fixed seeds,
//! and a sample folded into one number.

use envlight::{EnvironmentLight, LightSample, Vec3};
use std::hint::black_box;

/// The first `n` ξ of the sequence `seed`.
pub fn xi(seed: u64, n: usize) -> Vec<[f32; 2]> {
    (0..n as u64)
        .map(|k| envlight::rng::xi_2d(seed, k))
        .collect()
}

/// The directions, uniform on the sphere, that `xi` map to.
pub fn directions(xi: &[[f32; 2]]) -> Vec<Vec3> {
    xi.iter()
        .map(|&x| envlight::math::uniform_sphere(x))
        .collect()
}

/// Every output of a sample folded into one number, so that none of it can be
/// skipped (summing only the pdf let the compiler drop the radiance lookup and
/// the direction).
pub fn fold(d: Vec3, pdf: f32, l: [f32; 3]) -> f32 {
    pdf + d.x + d.y + d.z + l[0] + l[1] + l[2]
}

/// [`fold`] of one of envlight's samples.
pub fn fold_sample(s: LightSample) -> f32 {
    fold(s.direction, s.pdf, s.radiance)
}

/// The [`fold`]ed samples of `light` at every ξ of `xi`, summed.
pub fn sample_all(light: &EnvironmentLight, xi: &[[f32; 2]]) -> f32 {
    xi.iter()
        .map(|&x| light.sample(black_box(x)).map_or(0.0, fold_sample))
        .sum()
}
