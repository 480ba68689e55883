//! `--normal X,Y,Z`: sampling at a surface with that normal, by light × clamped
//! cosine (the product sampler, docs/design.md §6a), instead of by the light alone.

use std::sync::Arc;

use envlight::{
    EnvironmentLight, Factor, LightSample, ProductOptions, ProductSampler, ShadingPoint, Vec3,
};

/// The `--normal` option.
#[derive(Debug, Clone, clap::Args)]
pub struct NormalArgs {
    /// Sample (and report pdfs) for a surface with this normal, in proportion to
    /// radiance × max(0, n·ω) (docs/design.md §6a), instead of radiance alone: precomputed
    /// tables over patches of the map, and within a patch the light's own density
    /// (--density: piecewise-constant or piecewise-bilinear). Three comma-separated
    /// numbers in world space; any non-zero length (normalised).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_normal, allow_hyphen_values = true)]
    pub normal: Option<Vec3>,
}

/// A unit normal from `X,Y,Z`: three finite numbers, not all zero.
pub fn parse_normal(text: &str) -> Result<Vec3, String> {
    let v = crate::light_args::parse_xyz(text)?;
    v.normalized()
        .filter(|n| n.x.is_finite() && n.y.is_finite() && n.z.is_finite())
        .ok_or_else(|| "the normal has zero length".to_string())
}

/// The product sampler for `normal`, when one is given.
pub fn product_sampler(
    light: &Arc<EnvironmentLight>,
    normal: Option<Vec3>,
) -> Option<ProductSampler> {
    normal.map(|_| ProductSampler::new(Arc::clone(light), ProductOptions::default()))
}

/// What directions are drawn from: the light alone, or the product sampler at
/// one shading point.
pub enum Density<'a> {
    /// The light's own importance sampling.
    Light(&'a EnvironmentLight),
    /// The product sampler at the normal.
    Product(Box<ShadingPoint<'a>>),
}

impl<'a> Density<'a> {
    /// The product sampler at `normal` when both are given, else the light alone.
    pub fn new(
        light: &'a EnvironmentLight,
        product: Option<&'a ProductSampler>,
        normal: Option<Vec3>,
    ) -> Self {
        match (product, normal) {
            (Some(p), Some(n)) => Density::Product(Box::new(p.at(&Factor::cosine(n)))),
            _ => Density::Light(light),
        }
    }

    /// Draws a direction for `ξ` (see [`EnvironmentLight::sample`]).
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        match self {
            Density::Light(light) => light.sample(xi),
            Density::Product(point) => point.sample(xi),
        }
    }

    /// The solid-angle pdf of `direction`, per steradian.
    pub fn pdf(&self, direction: Vec3) -> f32 {
        match self {
            Density::Light(light) => light.pdf(direction),
            Density::Product(point) => point.pdf(direction),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normals_parse_and_normalise() {
        let n = parse_normal("0, 0, 2").unwrap();
        assert_eq!((n.x, n.y, n.z), (0.0, 0.0, 1.0));
        let n = parse_normal("-3,4,0").unwrap();
        assert!((n.x + 0.6).abs() < 1e-6 && (n.y - 0.8).abs() < 1e-6);
        for bad in [
            "", "1,2", "1,2,3,4", "a,0,1", "0,0,0", "nan,0,1", "inf,0,0", "1e39,0,0",
        ] {
            assert!(parse_normal(bad).is_err(), "{bad}");
        }
    }
}
