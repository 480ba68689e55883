//! How the environment light's contribution at a surface point is estimated, and
//! the MIS-compensated light distribution.

use envlight::{EnvironmentLight, LightSample, Vec3};
use std::fmt;
use std::str::FromStr;

/// A direct-lighting strategy. Every strategy traces the same paths (continuation
/// by BSDF sampling, next-event estimation towards the light, Russian roulette);
/// they differ in which techniques estimate the light arriving at each vertex:
///
/// | strategy | light-sampled shadow ray | BSDF-sampled ray that escapes |
/// |---|---|---|
/// | `uniform` | uniform sphere direction, weight 1 | weight 0 |
/// | `bsdf` | none | weight 1 |
/// | `light` | the light's importance sampling, weight 1 | weight 0 |
/// | `mis` | importance sampling, power heuristic | power heuristic |
/// | `mis-compensated` | compensated distribution, power heuristic | power heuristic |
/// | `product` | product sampling of `L ×` the BSDF's factor, weight 1 | weight 0 |
/// | `mis-product` | product sampling (diffuse: alone; plastic, and metals of GGX α < 0.1 under the bilinear density: power heuristic); other metals: the compensated distribution, power heuristic | as the shadow ray |
/// | `portal` | the portal light at the vertex, weight 1 | weight 0 |
/// | `mis-portal` | the portal light at the vertex, balance heuristic | balance heuristic |
/// | `mis-visibility` | as `mis-product`, with the product sampler replaced at diffuse and plastic vertices by the visibility cache's mixture (learned visibility × light × cosine, and the product) | as the shadow ray |
///
/// The product strategies draw the shadow ray's direction at each vertex from
/// [`envlight::ProductSampler`] with the target `L(ω) f(ω)`, where the factor `f` is
/// [`Bsdf::product_factor`](crate::Bsdf::product_factor): the clamped cosine for
/// diffuse surfaces (and plastic), the cosine times a GGX lobe proxy of the
/// surface's roughness for conductors (docs/design.md §6a). The factor is only the
/// sampling target: each light sample is weighted by the true BSDF value times the
/// cosine over the product pdf, and in `mis-product` both power-heuristic weights
/// (of the shadow ray and of the BSDF-sampled ray that escapes) use the product pdf
/// of the same shading point. Both stay unbiased because the product pdf is
/// positive wherever `L(ω) max(0, n·ω) > 0` (every factor is positive over the whole
/// upper hemisphere).
///
/// The portal strategies sample the light through the scene's openings
/// ([`Scene::portals`](crate::Scene::portals)) with an
/// [`envlight::portal::PortalLight`] at each vertex: only directions through an
/// opening, in proportion to the map's luminance seen through it, with the exact
/// mixture pdf of that vertex in both MIS weights. In a closed room every ray that
/// escapes passes through an opening, so the portal pdf is positive wherever the
/// unoccluded integrand is, and `portal` alone is unbiased. A scene without
/// portals has no openings to restrict to: there the portal strategies sample the
/// whole light (`portal` as `light`, `mis-portal` as `mis` with the balance
/// heuristic).
///
/// `mis-visibility` builds a [`envlight::VisibilityCache`] before rendering,
/// from the camera's first hits and the scene's own shadow rays (its cost counts
/// in the render's time), and samples at each vertex the exact mixture of what
/// the vertex's entry learned and the product sampler (docs/design.md §10): the
/// pdf is positive wherever the product's is, so it is as unbiased as
/// `mis-product`, whatever the cache saw.
///
/// Camera rays that escape always see `light.radiance(ω)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Strategy {
    /// Uniform sphere directions for the light (no importance sampling at all).
    Uniform,
    /// BSDF sampling only.
    Bsdf,
    /// Environment importance sampling only.
    Light,
    /// Light and BSDF sampling combined by the power heuristic (β = 2).
    #[default]
    Mis,
    /// As `Mis`, with the light sampled from [`CompensatedLight`].
    MisCompensated,
    /// Product sampling of the light times the BSDF's factor at the shading point
    /// only (like `Light`, BSDF-sampled rays that escape count 0).
    Product,
    /// Product sampling and BSDF sampling combined by the power heuristic (β = 2),
    /// both weights with the product pdf at the shading point.
    MisProduct,
    /// Sampling through the scene's portals only (like `Light`, BSDF-sampled rays
    /// that escape count 0).
    Portal,
    /// Portal sampling and BSDF sampling combined by the balance heuristic, both
    /// weights with the portal pdf at the shading point.
    MisPortal,
    /// As `MisProduct`, the light technique at diffuse and plastic vertices being
    /// the visibility cache's mixture at the vertex.
    MisVisibility,
}

impl Strategy {
    /// All strategies, in the order reports list them.
    pub const ALL: [Strategy; 10] = [
        Strategy::Uniform,
        Strategy::Bsdf,
        Strategy::Light,
        Strategy::Mis,
        Strategy::MisCompensated,
        Strategy::Product,
        Strategy::MisProduct,
        Strategy::Portal,
        Strategy::MisPortal,
        Strategy::MisVisibility,
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Uniform => "uniform",
            Strategy::Bsdf => "bsdf",
            Strategy::Light => "light",
            Strategy::Mis => "mis",
            Strategy::MisCompensated => "mis-compensated",
            Strategy::Product => "product",
            Strategy::MisProduct => "mis-product",
            Strategy::Portal => "portal",
            Strategy::MisPortal => "mis-portal",
            Strategy::MisVisibility => "mis-visibility",
        }
    }

    /// Whether a BSDF-sampled ray that escapes to the light contributes.
    #[inline]
    pub fn counts_escaped_bsdf_rays(self) -> bool {
        matches!(self, Strategy::Bsdf) || self.is_mis()
    }

    /// Whether the light and BSDF techniques are combined by the power heuristic.
    #[inline]
    pub fn is_mis(self) -> bool {
        matches!(
            self,
            Strategy::Mis
                | Strategy::MisCompensated
                | Strategy::MisProduct
                | Strategy::MisPortal
                | Strategy::MisVisibility
        )
    }

    /// Whether the light technique is the portal light at the shading point.
    #[inline]
    pub fn uses_portals(self) -> bool {
        matches!(self, Strategy::Portal | Strategy::MisPortal)
    }

    /// Whether the light technique is the product sampler at the shading point.
    #[inline]
    pub fn uses_product(self) -> bool {
        matches!(
            self,
            Strategy::Product | Strategy::MisProduct | Strategy::MisVisibility
        )
    }

    /// Whether it mixes product (or cache) samples with BSDF samples the way
    /// `mis-product` does: product samples alone at diffuse vertices, the
    /// compensated light at rough metals.
    #[inline]
    pub fn mixes_product(self) -> bool {
        matches!(self, Strategy::MisProduct | Strategy::MisVisibility)
    }

    /// Whether it builds a visibility cache before rendering.
    #[inline]
    pub fn uses_visibility(self) -> bool {
        self == Strategy::MisVisibility
    }
}

impl fmt::Display for Strategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The error of parsing an unknown strategy name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown strategy '{0}' (expected one of: uniform, bsdf, light, mis, mis-compensated, \
     product, mis-product, portal, mis-portal, mis-visibility)"
)]
pub struct UnknownStrategy(pub String);

impl FromStr for Strategy {
    type Err = UnknownStrategy;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Strategy::ALL
            .into_iter()
            .find(|k| k.name() == s)
            .ok_or_else(|| UnknownStrategy(s.to_string()))
    }
}

/// The environment light re-built with MIS compensation (Karlík et al. 2019, as in
/// PBRT-v4's `ImageInfiniteLight`): the library's
/// [`LightOptions::mis_compensation`](envlight::LightOptions::mis_compensation),
/// with every other option of the base light (mapping, density, sampler, lookup,
/// rotation, scale).
///
/// # What is subtracted
/// The light's importance is `Ỹ · J`, the filtered luminance times the mapping's
/// area factor (`sin θ` for the lat-long map). The compensated importance subtracts
/// the solid-angle mean of the luminance, `max(0, Ỹ − Ȳ) · J` with
/// `Ȳ = Σ Ỹ J / Σ J`: the mean *radiance* over the sphere, not the plain mean of the
/// importance values, which with the lat-long map would act as a threshold
/// `mean / sin θ` growing towards the poles. If nothing is above the mean (a
/// constant map), the ordinary importance is kept.
///
/// # Why MIS with it stays unbiased
/// Sampling it alone is biased: directions whose luminance is at most the mean
/// have density 0. In `mis-compensated` it is only ever one of two techniques: the
/// light sample is weighted `p'²/(p'² + p_bsdf²)` and the BSDF sample
/// `p_bsdf²/(p'² + p_bsdf²)`, both with the compensated density `p'`. The weights
/// sum to 1 wherever either density is positive, and every direction where the
/// integrand `L f cosθ` is non-zero has `p_bsdf > 0` (every BSDF here covers its
/// whole support), so the combined estimator is unbiased. Where `p' = 0` the BSDF
/// sample takes full weight; where the light is well above average, the light
/// sample dominates: the BSDF handles the "constant" part of the environment well,
/// so the light spends no samples on it.
#[derive(Debug, Clone)]
pub struct CompensatedLight {
    light: EnvironmentLight,
}

impl CompensatedLight {
    /// Builds the compensated light from `base`'s image and options. `O(w h)`.
    pub fn new(base: &EnvironmentLight) -> Self {
        let mut options = *base.options();
        // The base light's image is already in its mapping.
        options.input_mapping = options.mapping;
        options.mis_compensation = true;
        let light = EnvironmentLight::new(base.image().clone(), options)
            .expect("the options of an existing light are valid");
        Self { light }
    }

    /// The compensated light.
    pub fn light(&self) -> &EnvironmentLight {
        &self.light
    }

    /// Whether nothing was above the mean and the ordinary importance is used.
    pub fn fell_back(&self) -> bool {
        !self.light.is_compensated()
    }

    /// Draws a direction with the compensated density; `None` where it gives none.
    #[inline]
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        self.light.sample(xi)
    }

    /// The solid-angle density (per steradian) of [`Self::sample`] at the world
    /// direction `direction`.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        self.light.pdf(direction)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use envlight::{EnvImage, LightOptions};

    #[test]
    fn names_round_trip() {
        for s in Strategy::ALL {
            assert_eq!(s.name().parse::<Strategy>().unwrap(), s);
        }
        assert!("MIS".parse::<Strategy>().is_err());
        // The error lists every name.
        let message = "x".parse::<Strategy>().unwrap_err().to_string();
        for s in Strategy::ALL {
            assert!(
                message.contains(&format!(" {},", s.name()))
                    || message.contains(&format!(" {})", s.name())),
                "{message}"
            );
        }
    }

    #[test]
    fn constant_map_falls_back_and_bright_patch_is_kept() {
        let constant = EnvImage::from_fn(16, 8, |_, _| [1.0; 3]).unwrap();
        let light = EnvironmentLight::new(constant, LightOptions::default()).unwrap();
        let c = CompensatedLight::new(&light);
        assert!(c.fell_back());

        let patch = EnvImage::from_fn(32, 16, |x, y| {
            if (10..14).contains(&x) && (4..7).contains(&y) {
                [50.0; 3]
            } else {
                [1.0; 3]
            }
        })
        .unwrap();
        let light = EnvironmentLight::new(patch, LightOptions::default()).unwrap();
        let c = CompensatedLight::new(&light);
        assert!(!c.fell_back());
        // Every sample lands in (the filtered footprint of) the patch, and the pdf
        // it reports is the one `pdf` gives.
        for k in 0..2000 {
            let s = c.sample(envlight::rng::xi_2d(3, k)).unwrap();
            let [u, v] = s.uv;
            assert!((9.0 / 32.0..15.0 / 32.0).contains(&u), "{u}");
            assert!((3.0 / 16.0..8.0 / 16.0).contains(&v), "{v}");
            let p = c.pdf(s.direction);
            assert!((p - s.pdf).abs() <= 1e-3 * s.pdf, "{p} vs {}", s.pdf);
        }
        // A dim direction has compensated density 0.
        assert_eq!(c.pdf(Vec3::new(0.0, 0.0, -1.0)), 0.0);
    }
}
