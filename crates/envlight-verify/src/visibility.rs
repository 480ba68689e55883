//! A visibility cache at one shading point, as a [`SphereSampler`]
//! (docs/design.md §10), with the deliberately broken variants its checks must
//! reject.
//!
//! The cache samples `L · cos⁺` as seen through what each entry learned, mixed
//! with the product sampler; its pdf must be exact and positive wherever
//! `Y · cos⁺ > 0`, whatever the learned visibility, so it is checked against the
//! unoccluded integrand `Y · cos⁺`, as the product sampler is.

use crate::integrand::Integrand;
use crate::sampler::{product_point_methods, sphere_sample, SphereSample, SphereSampler};
use envlight::visibility::{VisibilityCache, VisibilityPoint};
use envlight::{EnvironmentLight, Factor, ShadingPoint, Vec3};

/// What the pdf of an [`AtVisibilityPoint`] computes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VisibilityVariant {
    /// The cache's own pdf.
    Exact,
    /// **Broken**: the mixture's plain (product) share left out of the pdf,
    /// `α q_e(ω)` alone: it integrates to `α`, not 1.
    WithoutPlainShare,
    /// **Broken**: the pdf taken at the entry of another position (this one),
    /// while samples come from the shading point's own entry.
    EntryOf(Vec3),
}

/// A [`VisibilityCache`] at one shading point `(position, factor)`: samples from
/// the cache, pdf as the [`VisibilityVariant`] says.
pub struct AtVisibilityPoint<'a> {
    cache: &'a VisibilityCache,
    point: VisibilityPoint<'a>,
    /// The same point's product sampler alone (for the broken variants).
    product: ShadingPoint<'a>,
    /// Where the pdf is taken (the point itself unless broken).
    pdf_point: VisibilityPoint<'a>,
    position: Vec3,
    factor: Factor,
    variant: VisibilityVariant,
}

impl<'a> AtVisibilityPoint<'a> {
    /// `cache` at `position` with the factor `factor`.
    pub fn new(
        cache: &'a VisibilityCache,
        position: Vec3,
        factor: Factor,
        variant: VisibilityVariant,
    ) -> Self {
        let at = match variant {
            VisibilityVariant::EntryOf(other) => other,
            _ => position,
        };
        Self {
            cache,
            point: cache.at(position, &factor),
            product: cache.product().at(&factor),
            pdf_point: cache.at(at, &factor),
            position,
            factor,
            variant,
        }
    }

    /// The light behind the cache.
    pub fn light(&self) -> &EnvironmentLight {
        self.cache.product().light()
    }

    /// `α_e` at this point (0 where it has no entry).
    pub fn learned_share(&self) -> f32 {
        self.point.learned_share()
    }

    /// `Y(L(ω)) · cos⁺(n·ω)` (or the factor's lobe): what the pdf must cover.
    pub fn integrand(&self) -> Integrand<'_> {
        let f = self.factor;
        let n = f.normal();
        Integrand::luminance_times(
            format!("Y·f n=({:.2},{:.2},{:.2})", n.x, n.y, n.z),
            move |d| f.value(d) as f64,
        )
    }
}

impl SphereSampler for AtVisibilityPoint<'_> {
    fn name(&self) -> String {
        let p = self.position;
        let variant = match self.variant {
            VisibilityVariant::Exact => String::new(),
            VisibilityVariant::WithoutPlainShare => " [broken: no plain share in the pdf]".into(),
            VisibilityVariant::EntryOf(o) => format!(
                " [broken: pdf at the entry of ({:.2},{:.2},{:.2})]",
                o.x, o.y, o.z
            ),
        };
        format!(
            "visibility cache (α={:.2}) at ({:.2},{:.2},{:.2}) {:?} over {}{variant}",
            self.point.learned_share(),
            p.x,
            p.y,
            p.z,
            self.factor,
            SphereSampler::name(self.light())
        )
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        let mut s = self.point.sample(xi)?;
        // The sample's pdf is the variant's, as a caller with that pdf would see.
        s.pdf = self.pdf(s.direction);
        Some(sphere_sample(s))
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        match self.variant {
            VisibilityVariant::Exact => self.point.pdf(direction),
            VisibilityVariant::WithoutPlainShare => {
                let share = self.point.learned_share();
                (self.point.pdf(direction) - (1.0 - share) * self.product.pdf(direction)).max(0.0)
            }
            VisibilityVariant::EntryOf(_) => self.pdf_point.pdf(direction),
        }
    }
    // The fold is the product share's horizon band.
    product_point_methods!(horizon_band_of: product);
}
