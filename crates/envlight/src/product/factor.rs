//! [`Factor`]: what multiplies the light's radiance in a shading point's sampling
//! target.

use crate::math::Vec3;
use std::f64::consts::PI;

/// The factor `f(ω)` that multiplies the light's radiance in the sampling target
/// `L(ω) f(ω)` at a shading point. All vectors are in the world frame.
///
/// Inputs need not be unit length: every use normalises them first
/// ([`Factor::normalized`]). A factor whose normal (or outgoing direction) is zero
/// or not finite, or whose roughness is outside `(0, 1]`, is *invalid*: its value
/// is 0 everywhere and a shading point with it samples nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Factor {
    /// The clamped cosine of a diffuse surface with normal `n`:
    /// `f(ω) = max(0, n·ω)`.
    Cosine {
        /// The surface normal `n`.
        normal: Vec3,
    },
    /// The clamped cosine times a GGX reflection-lobe proxy:
    /// `f(ω) = max(0, n·ω) · D_α(γ(ω) / 2)`, with `r = 2 (n·ωo) n - ωo` the mirror
    /// direction of the outgoing direction `ωo`, `γ(ω)` the angle between `ω` and
    /// `r`, and `D_α(θ_h) = α² / (π (cos²θ_h (α² - 1) + 1)²)` the GGX normal
    /// distribution as a function of the half-angle.
    ///
    /// This is a *proxy* of the GGX BRDF lobe, used as a sampling target: its shape
    /// and width follow the lobe, but it is not the BRDF (no Fresnel, masking or
    /// `1/(4 cos θo)`, and `γ/2` equals the true half-angle, between `n` and the
    /// half-vector of `ω` and `ωo`, only in the plane of incidence). A renderer
    /// weights each sample by the true BSDF over this sampler's pdf. `D_α > 0`
    /// everywhere, so the pdf is positive wherever `L(ω) max(0, n·ω) > 0` and that
    /// estimate is unbiased for any BSDF over the upper hemisphere.
    Glossy {
        /// The surface normal `n`.
        normal: Vec3,
        /// The outgoing direction `ωo` (towards the viewer).
        outgoing: Vec3,
        /// The GGX roughness `α ∈ (0, 1]` (1 is a wide lobe, near 0 a mirror).
        roughness: f32,
    },
}

impl Factor {
    /// The clamped cosine about `normal`.
    pub fn cosine(normal: Vec3) -> Self {
        Factor::Cosine { normal }
    }

    /// The clamped cosine about `normal` times the GGX lobe proxy of roughness
    /// `roughness` about the mirror direction of `outgoing`.
    pub fn glossy(normal: Vec3, outgoing: Vec3, roughness: f32) -> Self {
        Factor::Glossy {
            normal,
            outgoing,
            roughness,
        }
    }

    /// The surface normal, as given.
    pub fn normal(&self) -> Vec3 {
        match *self {
            Factor::Cosine { normal } | Factor::Glossy { normal, .. } => normal,
        }
    }

    /// The same factor with unit vectors, or `None` when it is invalid (a zero or
    /// non-finite vector, or a roughness outside `(0, 1]`, NaN included).
    pub fn normalized(&self) -> Option<Factor> {
        match *self {
            Factor::Cosine { normal } => Some(Factor::Cosine {
                normal: normal.normalized()?,
            }),
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                if !(roughness > 0.0 && roughness <= 1.0) {
                    return None;
                }
                Some(Factor::Glossy {
                    normal: normal.normalized()?,
                    outgoing: outgoing.normalized()?,
                    roughness,
                })
            }
        }
    }

    /// `f(ω)` for the unit world direction `direction` (0 for an invalid factor).
    pub fn value(&self, direction: Vec3) -> f32 {
        match self.normalized() {
            Some(factor) => factor.unit_value(direction),
            None => 0.0,
        }
    }

    /// [`Self::value`] of a factor already normalised.
    pub(super) fn unit_value(&self, direction: Vec3) -> f32 {
        match *self {
            Factor::Cosine { normal } => normal.dot(direction).max(0.0),
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                let cos = normal.dot(direction);
                if !(cos > 0.0 && cos.is_finite()) {
                    return 0.0;
                }
                let r = reflect(outgoing, normal);
                let alpha2 = roughness as f64 * roughness as f64;
                (cos as f64 * lobe_proxy(alpha2, r.dot(direction) as f64)) as f32
            }
        }
    }

    /// The bits of an optional factor, for exact comparison (`-0.0` and `0.0`
    /// differ, NaNs compare by payload).
    pub(super) fn bits(factor: &Option<Factor>) -> Option<(u8, [u32; 7])> {
        let v = |v: Vec3| v.to_array().map(f32::to_bits);
        factor.map(|f| match f {
            Factor::Cosine { normal } => {
                let [x, y, z] = v(normal);
                (0, [x, y, z, 0, 0, 0, 0])
            }
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                let ([x, y, z], [a, b, c]) = (v(normal), v(outgoing));
                (1, [x, y, z, a, b, c, roughness.to_bits()])
            }
        })
    }
}

/// The mirror direction of the unit vector `outgoing` about the unit `normal`,
/// `2 (n·ωo) n - ωo`, renormalised against rounding (it is a unit vector).
pub(super) fn reflect(outgoing: Vec3, normal: Vec3) -> Vec3 {
    let r = normal * (2.0 * normal.dot(outgoing)) - outgoing;
    r.normalized().unwrap_or(normal)
}

/// The GGX lobe proxy `D_α(γ/2)` from `cos γ`, with `α² = alpha2`:
/// `cos²(γ/2) = (1 + cos γ) / 2`, so no trigonometry. Non-increasing in `γ`.
#[inline]
pub(super) fn lobe_proxy(alpha2: f64, cos_gamma: f64) -> f64 {
    let cos2_half = 0.5 * (1.0 + cos_gamma.clamp(-1.0, 1.0));
    let d = cos2_half * (alpha2 - 1.0) + 1.0;
    alpha2 / (PI * d * d)
}
