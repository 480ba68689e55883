//! Reflection models. Every BSDF is a triplet over the same density: `eval`
//! (the BRDF value `f(ωo, ωi)`, without the cosine), `sample` (draws `ωi` and
//! reports `f` and the density), and `pdf` (the solid-angle density `sample`
//! produces). There are no delta lobes: even the near-mirror conductor is a GGX lobe
//! with a small roughness, so every path can be weighted by multiple importance
//! sampling.
//!
//! Directions are in the local shading frame: the normal is +z, both `ωo` (towards
//! the viewer) and `ωi` (towards the light) point away from the surface, and a
//! direction below the surface gets `f = 0` and `pdf = 0`.
//!
//! Microfacet lobes use the isotropic GGX (Trowbridge–Reitz) distribution with the
//! height-correlated Smith shadowing term and sample the distribution of visible
//! normals (Heitz 2018):
//!
//! ```text
//! D(m)   = α² / (π (cos²θm (α² − 1) + 1)²)
//! Λ(ω)   = (√(1 + α² tan²θ) − 1) / 2,   G1 = 1 / (1 + Λ(ωo)),   G2 = 1 / (1 + Λ(ωo) + Λ(ωi))
//! f      = D(ωh) G2 F(ωo·ωh) / (4 cosθo cosθi),   ωh = (ωo + ωi)/|ωo + ωi|
//! pdf(ωi) = D_ωo(ωh) / (4 ωo·ωh) = G1(ωo) D(ωh) / (4 cosθo)
//! ```
//!
//! so a sampled lobe has the weight `f cosθi / pdf = F G2 / G1 ≤ 1`.

use crate::rgb::{add, scale, Rgb};
use crate::warp::{cosine_hemisphere_pdf, square_to_cosine_hemisphere};
use envlight::color::luminance;
use envlight::{Factor, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};

/// The smallest GGX roughness used: below it `D` overflows `f32` near the peak.
pub const MIN_ALPHA: f32 = 1e-3;

/// A direction drawn from a BSDF.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BsdfSample {
    /// The incident direction `ωi` (local frame, `z > 0`).
    pub wi: Vec3,
    /// `f(ωo, ωi)` (without the cosine).
    pub f: Rgb,
    /// The solid-angle density of `ωi`, the full density of [`Bsdf::pdf`] (> 0).
    pub pdf: f32,
}

/// A BSDF instance at a surface point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bsdf {
    /// Lambertian reflection `f = ρ / π`, sampled by a cosine-weighted hemisphere.
    Diffuse {
        /// Albedo `ρ ∈ [0, 1]³`.
        albedo: Rgb,
    },
    /// A GGX metal with the exact Fresnel reflectance of a complex index of
    /// refraction `η + i k` (per RGB channel).
    Conductor {
        /// GGX roughness `α` (clamped to [`MIN_ALPHA`]).
        alpha: f32,
        /// Real part of the index of refraction, per channel.
        eta: Rgb,
        /// Absorption coefficient, per channel.
        k: Rgb,
    },
    /// A plastic-like coated material: a GGX dielectric specular layer (index `η`)
    /// over a Lambertian base,
    ///
    /// `f = D G2 F(ωo·ωh) / (4 cosθo cosθi) + (ρ/π) (1 − F(cosθi)) (1 − F(cosθo))`.
    ///
    /// The diffuse term is symmetric, hence reciprocal; light that the coating
    /// reflects at either crossing is taken from the base, so the directional
    /// albedo stays ≤ 1 (checked by the tests for ρ = 1). Sampling picks the
    /// specular lobe with a probability `P(ωo)` that depends only on `ωo`, and the
    /// density is the mixture `P pdf_ggx + (1 − P) cosθi / π`.
    Plastic {
        /// Albedo of the base `ρ ∈ [0, 1]³`.
        albedo: Rgb,
        /// GGX roughness of the coating (clamped to [`MIN_ALPHA`]).
        alpha: f32,
        /// Index of refraction of the coating (> 1).
        eta: f32,
    },
}

impl Bsdf {
    /// `f(ωo, ωi)`, without the cosine; 0 when either direction is below the surface.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return [0.0; 3];
        }
        match *self {
            Bsdf::Diffuse { albedo } => scale(albedo, FRAC_1_PI),
            Bsdf::Conductor { alpha, eta, k } => {
                let Some(wh) = half_vector(wo, wi) else {
                    return [0.0; 3];
                };
                let ggx = Ggx::new(alpha);
                let common = ggx.d(wh) * ggx.g2(wo, wi) / (4.0 * wo.z * wi.z);
                let cos_h = wo.dot(wh);
                let f = [0, 1, 2].map(|c| fresnel_conductor(cos_h, eta[c], k[c]));
                scale(f, common)
            }
            Bsdf::Plastic { albedo, alpha, eta } => {
                let Some(wh) = half_vector(wo, wi) else {
                    return [0.0; 3];
                };
                let ggx = Ggx::new(alpha);
                let specular = ggx.d(wh) * ggx.g2(wo, wi) * fresnel_dielectric(wo.dot(wh), eta)
                    / (4.0 * wo.z * wi.z);
                let transmitted = (1.0 - fresnel_dielectric(wi.z, eta))
                    * (1.0 - fresnel_dielectric(wo.z, eta))
                    * FRAC_1_PI;
                add([specular; 3], scale(albedo, transmitted))
            }
        }
    }

    /// The solid-angle density with which [`Bsdf::sample`] produces `ωi` given `ωo`.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        match *self {
            Bsdf::Diffuse { .. } => cosine_hemisphere_pdf(wi),
            Bsdf::Conductor { alpha, .. } => Ggx::new(alpha).pdf_reflection(wo, wi),
            Bsdf::Plastic { albedo, alpha, eta } => {
                let p = plastic_specular_probability(wo, albedo, eta);
                p * Ggx::new(alpha).pdf_reflection(wo, wi) + (1.0 - p) * cosine_hemisphere_pdf(wi)
            }
        }
    }

    /// Draws `ωi` for `ωo`: `uc` chooses a lobe (where there are several), `u`
    /// places the direction. `None` when the draw falls below the surface (its
    /// contribution is 0) or `ωo` is below the surface.
    #[inline]
    pub fn sample(&self, wo: Vec3, uc: f32, u: [f32; 2]) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = match *self {
            Bsdf::Diffuse { .. } => square_to_cosine_hemisphere(u),
            Bsdf::Conductor { alpha, .. } => Ggx::new(alpha).sample_reflection(wo, u),
            Bsdf::Plastic { albedo, alpha, eta } => {
                if uc < plastic_specular_probability(wo, albedo, eta) {
                    Ggx::new(alpha).sample_reflection(wo, u)
                } else {
                    square_to_cosine_hemisphere(u)
                }
            }
        };
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        (pdf > 0.0 && pdf.is_finite()).then(|| BsdfSample {
            wi,
            f: self.eval(wo, wi),
            pdf,
        })
    }

    /// True for a Lambertian BSDF, whose product factor is its whole angular
    /// shape (the cosine).
    pub fn is_diffuse(&self) -> bool {
        matches!(self, Bsdf::Diffuse { .. })
    }

    /// True for a GGX metal.
    pub fn is_conductor(&self) -> bool {
        matches!(self, Bsdf::Conductor { .. })
    }

    /// A GGX metal's roughness `α` as its product factor takes it, `None` for others.
    pub fn conductor_roughness(&self) -> Option<f32> {
        match *self {
            Bsdf::Conductor { alpha, .. } => Some(factor_roughness(alpha)),
            _ => None,
        }
    }

    /// The factor `f` of the product sampler's target `L(ω) f(ω)` at a surface point
    /// with (world) normal `normal`, facing the viewer, and outgoing direction
    /// `wo_world` (docs/design.md §6a). Only a sampling target: a light sample drawn with
    /// it is weighted by the true `f(ωo, ωi) cos θi / p(ωi)`.
    ///
    /// - `Diffuse`: the clamped cosine `max(0, n·ω)`, which is exactly the BRDF
    ///   times the cosine up to the constant albedo.
    /// - `Conductor`: the cosine times the GGX lobe proxy about the mirror direction
    ///   of `ωo`, with the surface's roughness (clamped into `[MIN_ALPHA, 1]`, the
    ///   proxy's domain; at α = 1 the proxy is flat and the target is the cosine).
    /// - `Plastic`: the clamped cosine. The target is one lobe, and the base, which
    ///   returns most of a plastic's light except near grazing, spreads over the
    ///   whole hemisphere: a proxy of the coating's lobe (α = 0.08 on the `balls`
    ///   plastic) would put nearly every sample in the few patches around the mirror
    ///   direction and starve the base. The coating's highlight is left to BSDF
    ///   sampling, which `mis-product` combines with the product sample; for rough
    ///   coatings the proxy tends to the cosine anyway.
    #[inline]
    pub fn product_factor(&self, normal: Vec3, wo_world: Vec3) -> Factor {
        match *self {
            Bsdf::Diffuse { .. } | Bsdf::Plastic { .. } => Factor::cosine(normal),
            Bsdf::Conductor { alpha, .. } => {
                Factor::glossy(normal, wo_world, factor_roughness(alpha))
            }
        }
    }
}

/// A roughness clamped into `[MIN_ALPHA, 1]`, the product factor's lobe proxy's
/// domain.
#[inline]
fn factor_roughness(alpha: f32) -> f32 {
    alpha.clamp(MIN_ALPHA, 1.0)
}

/// Probability of sampling the coating of [`Bsdf::Plastic`]: its Fresnel
/// reflectance against the light the base returns, kept in `[0.25, 0.9]` so neither
/// lobe is starved. A function of `ωo` only, as the mixture density requires.
#[inline]
fn plastic_specular_probability(wo: Vec3, albedo: Rgb, eta: f32) -> f32 {
    let s = fresnel_dielectric(wo.z, eta);
    let d = luminance(albedo) * (1.0 - s);
    (s / (s + d)).clamp(0.25, 0.9)
}

/// `(ωo + ωi) / |ωo + ωi|`, `None` when they are opposite.
#[inline]
fn half_vector(wo: Vec3, wi: Vec3) -> Option<Vec3> {
    (wo + wi).normalized()
}

/// Mirror reflection of `wo` about `m`.
#[inline]
fn reflect(wo: Vec3, m: Vec3) -> Vec3 {
    m * (2.0 * wo.dot(m)) - wo
}

/// The isotropic GGX microfacet distribution of roughness `α`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ggx {
    alpha: f32,
}

impl Ggx {
    /// GGX with roughness `alpha` (clamped to [`MIN_ALPHA`]).
    #[inline]
    pub fn new(alpha: f32) -> Self {
        Self {
            alpha: alpha.max(MIN_ALPHA),
        }
    }

    /// Normal distribution `D(m)` (per steradian of microfacet normals, projected:
    /// `∫ D(m) cosθm dm = 1`).
    #[inline]
    pub fn d(&self, m: Vec3) -> f32 {
        if m.z <= 0.0 {
            return 0.0;
        }
        let a2 = self.alpha * self.alpha;
        let t = m.z * m.z * (a2 - 1.0) + 1.0;
        a2 / (PI * t * t)
    }

    /// Smith's `Λ(ω)`.
    #[inline]
    pub fn lambda(&self, w: Vec3) -> f32 {
        let cos2 = w.z * w.z;
        if cos2 <= 0.0 {
            return f32::INFINITY;
        }
        let tan2 = ((1.0 - cos2) / cos2).max(0.0);
        0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0)
    }

    /// Masking `G1(ω) = 1 / (1 + Λ(ω))`.
    #[inline]
    pub fn g1(&self, w: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(w))
    }

    /// Height-correlated masking-shadowing `G2 = 1 / (1 + Λ(ωo) + Λ(ωi))`.
    #[inline]
    pub fn g2(&self, wo: Vec3, wi: Vec3) -> f32 {
        1.0 / (1.0 + self.lambda(wo) + self.lambda(wi))
    }

    /// A microfacet normal drawn from the normals visible from `wo` (Heitz 2018),
    /// density `D_ωo(m) = G1(ωo) max(0, ωo·m) D(m) / cosθo`.
    #[inline]
    pub fn sample_visible_normal(&self, wo: Vec3, u: [f32; 2]) -> Vec3 {
        let a = self.alpha;
        // Stretch to the hemisphere configuration (α = 1).
        let vh = Vec3::new(a * wo.x, a * wo.y, wo.z)
            .normalized()
            .unwrap_or(Vec3::new(0.0, 0.0, 1.0));
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 {
            Vec3::new(-vh.y, vh.x, 0.0) * (1.0 / len2.sqrt())
        } else {
            Vec3::new(1.0, 0.0, 0.0)
        };
        let t2 = vh.cross(t1);
        // A uniform point on the disc, warped onto the visible half of the projected
        // hemisphere.
        let r = u[0].sqrt();
        let (sin_phi, cos_phi) = (2.0 * PI * u[1]).sin_cos();
        let p1 = r * cos_phi;
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * sin_phi;
        let nh = t1 * p1 + t2 * p2 + vh * (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt();
        // Unstretch.
        Vec3::new(a * nh.x, a * nh.y, nh.z.max(1e-6))
            .normalized()
            .unwrap_or(Vec3::new(0.0, 0.0, 1.0))
    }

    /// `ωi` reflected about a visible normal; may fall below the surface.
    #[inline]
    pub fn sample_reflection(&self, wo: Vec3, u: [f32; 2]) -> Vec3 {
        reflect(wo, self.sample_visible_normal(wo, u))
    }

    /// Density of [`Ggx::sample_reflection`] at `ωi` (both above the surface):
    /// `G1(ωo) D(ωh) / (4 cosθo)`.
    #[inline]
    pub fn pdf_reflection(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let Some(wh) = half_vector(wo, wi) else {
            return 0.0;
        };
        self.g1(wo) * self.d(wh) / (4.0 * wo.z)
    }
}

/// Unpolarised Fresnel reflectance of a dielectric of relative index `eta` for light
/// arriving from outside at `cos θi ∈ [0, 1]`.
#[inline]
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let r_parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let r_perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (r_parallel * r_parallel + r_perpendicular * r_perpendicular)
}

/// Unpolarised Fresnel reflectance of a conductor with complex index `eta + i k` at
/// `cos θi ∈ [0, 1]` (PBRT-v4 `FrComplex`).
#[inline]
pub fn fresnel_conductor(cos_i: f32, eta: f32, k: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let n = Complex::new(eta, k);
    let sin2_i = 1.0 - cos_i * cos_i;
    let sin2_t = Complex::new(sin2_i, 0.0).div(n.mul(n));
    let cos_t = Complex::new(1.0, 0.0).sub(sin2_t).sqrt();
    let ci = Complex::new(cos_i, 0.0);
    let r_parallel = n.mul(ci).sub(cos_t).div(n.mul(ci).add(cos_t));
    let r_perpendicular = ci.sub(n.mul(cos_t)).div(ci.add(n.mul(cos_t)));
    (0.5 * (r_parallel.norm() + r_perpendicular.norm())).min(1.0)
}

/// Just enough complex arithmetic for [`fresnel_conductor`].
#[derive(Debug, Clone, Copy)]
struct Complex {
    re: f32,
    im: f32,
}

impl Complex {
    fn new(re: f32, im: f32) -> Self {
        Self { re, im }
    }
    fn add(self, o: Self) -> Self {
        Self::new(self.re + o.re, self.im + o.im)
    }
    fn sub(self, o: Self) -> Self {
        Self::new(self.re - o.re, self.im - o.im)
    }
    fn mul(self, o: Self) -> Self {
        Self::new(
            self.re * o.re - self.im * o.im,
            self.re * o.im + self.im * o.re,
        )
    }
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self::new(
            (self.re * o.re + self.im * o.im) / d,
            (self.im * o.re - self.re * o.im) / d,
        )
    }
    /// `|z|²`.
    fn norm(self) -> f32 {
        self.re * self.re + self.im * self.im
    }
    /// Principal square root.
    fn sqrt(self) -> Self {
        let n = self.norm().sqrt();
        if n == 0.0 {
            return Self::new(0.0, 0.0);
        }
        let t1 = (0.5 * (n + self.re.abs())).sqrt();
        let t2 = 0.5 * self.im / t1;
        if self.re >= 0.0 {
            Self::new(t1, t2)
        } else {
            Self::new(t2.abs(), t1.copysign(self.im))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_matches_known_values() {
        // Glass at normal incidence: ((1.5 − 1)/(1.5 + 1))² = 0.04.
        assert!((fresnel_dielectric(1.0, 1.5) - 0.04).abs() < 1e-6);
        assert_eq!(fresnel_dielectric(0.0, 1.5), 1.0);
        // A conductor at normal incidence: ((η−1)² + k²) / ((η+1)² + k²).
        let (eta, k) = (0.2f32, 3.9f32);
        let expected = ((eta - 1.0).powi(2) + k * k) / ((eta + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, eta, k) - expected).abs() < 1e-5);
        // With k = 0 the conductor formula is the dielectric one.
        for c in [0.1, 0.5, 0.9] {
            assert!((fresnel_conductor(c, 1.5, 0.0) - fresnel_dielectric(c, 1.5)).abs() < 1e-5);
        }
    }

    #[test]
    fn ggx_d_is_normalised() {
        // ∫ D(m) cosθm dm = 1, by midpoint quadrature in cosθ (isotropic).
        for alpha in [0.05f32, 0.3, 0.8] {
            let ggx = Ggx::new(alpha);
            let n = 200_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                let c = (i as f64 + 0.5) / n as f64;
                let m = Vec3::new((1.0 - c * c).sqrt() as f32, 0.0, c as f32);
                sum += ggx.d(m) as f64 * c * 2.0 * std::f64::consts::PI / n as f64;
            }
            assert!((sum - 1.0).abs() < 2e-3, "α={alpha}: {sum}");
        }
    }
}
