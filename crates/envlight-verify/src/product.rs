//! A product sampler at one shading point, as a [`SphereSampler`] (docs/design.md §6a).

use crate::integrand::Integrand;
use crate::sampler::{product_point_methods, sphere_sample, SphereSample, SphereSampler};
use envlight::{EnvironmentLight, Factor, ProductSampler, ShadingPoint, Vec3};

/// [`ProductSampler`] conditioned on one [`Factor`]: what the checks see of a
/// renderer's shading point. Its density follows [`Self::integrand`],
/// `Y(L(ω)) · f(ω)`; within each patch it follows the light's own density over
/// it reports as its [`Grid`](crate::Grid).
pub struct AtShadingPoint<'a> {
    point: ShadingPoint<'a>,
    sampler: &'a ProductSampler,
    factor: Factor,
}

impl<'a> AtShadingPoint<'a> {
    /// `sampler` at the shading point of `factor`.
    pub fn new(sampler: &'a ProductSampler, factor: Factor) -> Self {
        Self {
            point: sampler.at(&factor),
            sampler,
            factor,
        }
    }

    /// False when nothing the surface sees is lit (then nothing is sampled and
    /// the pdf is 0 everywhere).
    pub fn samples_anything(&self) -> bool {
        self.point.samples_anything()
    }

    /// The light behind the sampler.
    pub fn light(&self) -> &EnvironmentLight {
        self.sampler.light()
    }

    /// `Y(L(ω)) · f(ω)`, the integrand this sampler's pdf is meant to follow.
    pub fn integrand(&self) -> Integrand<'_> {
        let f = self.factor;
        let label = match f {
            Factor::Cosine { normal: n } => format!("Y·cos⁺ n=({:.2},{:.2},{:.2})", n.x, n.y, n.z),
            Factor::Glossy {
                normal: n,
                roughness,
                ..
            } => format!(
                "Y·cos⁺·GGX(α={roughness}) n=({:.2},{:.2},{:.2})",
                n.x, n.y, n.z
            ),
        };
        Integrand::luminance_times(label, move |d| f.value(d) as f64)
    }
}

impl SphereSampler for AtShadingPoint<'_> {
    fn name(&self) -> String {
        format!(
            "product {:?} with {}x{} patches ({}) over {}",
            self.factor,
            self.sampler.patches()[0],
            self.sampler.patches()[1],
            self.sampler.density().name(),
            SphereSampler::name(self.light())
        )
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        self.point.sample(xi).map(sphere_sample)
    }
    fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<SphereSample>]) {
        // `ProductSampler::sample_batch` is `sampler.at(factor).sample(ξ)` per
        // point, the very code of `self.point`: the same results, in parallel.
        let factors = vec![self.factor; xi.len()];
        let mut samples = vec![None; xi.len()];
        self.sampler.sample_batch(&factors, xi, &mut samples);
        for (o, s) in out.iter_mut().zip(samples) {
            *o = s.map(sphere_sample);
        }
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        self.point.pdf(direction)
    }
    product_point_methods!(horizon_band_of: point);
    fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        // As `sample_batch`: `sampler.at(factor).pdf(ω)` per direction.
        let factors = vec![self.factor; directions.len()];
        self.sampler.pdf_batch(&factors, directions, out)
    }
    fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        self.light().radiance_batch(directions, out)
    }
}

/// The normals the product examples measure at: up, down, towards and away from
/// `light`'s brightest texel, an oblique one, and `random` uniform ones (fixed
/// seed), each with a label.
pub fn product_normals(light: &EnvironmentLight, random: usize) -> Vec<(String, Vec3)> {
    let brightest = light.brightest().1;
    let k = 1.0 / 3f32.sqrt();
    let mut normals = vec![
        ("up".to_string(), Vec3::new(0.0, 0.0, 1.0)),
        ("down".to_string(), Vec3::new(0.0, 0.0, -1.0)),
        ("towards".to_string(), brightest),
        ("away".to_string(), -brightest),
        ("oblique".to_string(), Vec3::new(k, -k, k)),
    ];
    for i in 0..random {
        let xi = envlight::rng::xi_2d(77, i as u64);
        normals.push((format!("random {i}"), envlight::math::uniform_sphere(xi)));
    }
    normals
}
