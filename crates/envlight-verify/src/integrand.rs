//! What a sampler's density is meant to follow.

use envlight::color::luminance;
use envlight::Vec3;

/// The integrand `g(ω) = Y(L(ω)) · f(ω)` a sampler is checked against: the
/// luminance of the radiance it reports, times a factor of the direction. A light
/// sampled alone follows `Y` (`f = 1`); a sampler conditioned on a shading point
/// follows `Y · max(0, n·ω)`, or `Y` times a BSDF lobe (docs/design.md §6a). The checks
/// use it for support (`p > 0` wherever `g > 0`), unbiasedness (`E[g/p] = ∫ g dω`)
/// and efficiency (`(∫ g)² / ∫ g²/p`), so a new kind of sampler needs no new check.
pub struct Integrand<'a> {
    label: String,
    factor: Option<Box<dyn Fn(Vec3) -> f64 + Sync + 'a>>,
}

impl std::fmt::Debug for Integrand<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.label)
    }
}

impl<'a> Integrand<'a> {
    /// `g = Y`: the light alone.
    pub fn luminance() -> Self {
        Self {
            label: "Y".into(),
            factor: None,
        }
    }

    /// `g = Y · max(0, n·ω)` for a unit normal `n`: irradiance at a surface.
    pub fn clamped_cosine(normal: Vec3) -> Self {
        Self::luminance_times(
            format!("Y·cos⁺ n=({:.3},{:.3},{:.3})", normal.x, normal.y, normal.z),
            move |d| normal.dot(d).max(0.0) as f64,
        )
    }

    /// `g = Y · factor(ω)`, with `factor ≥ 0`.
    pub fn luminance_times(
        label: impl Into<String>,
        factor: impl Fn(Vec3) -> f64 + Sync + 'a,
    ) -> Self {
        Self {
            label: label.into(),
            factor: Some(Box::new(factor)),
        }
    }

    /// What `g` is, for reports.
    pub fn label(&self) -> &str {
        &self.label
    }

    /// True for `g = Y` alone.
    pub fn is_luminance(&self) -> bool {
        self.factor.is_none()
    }

    /// The factor `f(ω)`.
    #[inline]
    pub fn factor(&self, direction: Vec3) -> f64 {
        self.factor.as_ref().map_or(1.0, |f| f(direction))
    }

    /// `g(ω) = Y(radiance) · f(ω)`.
    #[inline]
    pub fn value(&self, radiance: [f32; 3], direction: Vec3) -> f64 {
        let y = luminance(radiance) as f64;
        if y == 0.0 {
            return 0.0;
        }
        y * self.factor(direction)
    }
}
