//! How the environment light's contribution at a surface point is estimated, and
//! the MIS-compensated light distribution.

use envlight::distribution::Distribution2D;
use envlight::mapping::{equirect_to_direction, EQUIRECT_JACOBIAN};
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
}

impl Strategy {
    /// All strategies, in the order reports list them.
    pub const ALL: [Strategy; 5] = [
        Strategy::Uniform,
        Strategy::Bsdf,
        Strategy::Light,
        Strategy::Mis,
        Strategy::MisCompensated,
    ];

    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Uniform => "uniform",
            Strategy::Bsdf => "bsdf",
            Strategy::Light => "light",
            Strategy::Mis => "mis",
            Strategy::MisCompensated => "mis-compensated",
        }
    }

    /// Whether a BSDF-sampled ray that escapes to the light contributes.
    #[inline]
    pub fn counts_escaped_bsdf_rays(self) -> bool {
        matches!(
            self,
            Strategy::Bsdf | Strategy::Mis | Strategy::MisCompensated
        )
    }
}

impl fmt::Display for Strategy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The error of parsing an unknown strategy name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("unknown strategy '{0}' (expected one of: uniform, bsdf, light, mis, mis-compensated)")]
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

/// The environment light's sampling distribution with its average subtracted
/// (MIS compensation, Karlík et al. 2019, as in PBRT-v4's `ImageInfiniteLight`).
///
/// # What is subtracted
/// The light's importance is `f[j][i] = Ỹ[j][i] · sin θ_j`, where `Ỹ` is the
/// filtered luminance of texel `(i, j)` and `sin θ_j` its row's solid-angle factor.
/// The compensated importance subtracts the solid-angle mean of the luminance,
///
/// ```text
/// Ȳ = Σ_ij Ỹ[j][i] sin θ_j / (w Σ_j sin θ_j) = Σ_ij f[j][i] / (w Σ_j sin θ_j)
/// f'[j][i] = max(0, Ỹ[j][i] − Ȳ) · sin θ_j = max(0, f[j][i] − Ȳ sin θ_j)
/// ```
///
/// i.e. the mean *radiance* over the sphere, not the plain mean of the `f` values:
/// PBRT-v4 subtracts the plain mean because its equal-area octahedral map has a
/// constant Jacobian, where the two coincide; with the equirectangular map the plain
/// mean of `f` would amount to a latitude-dependent threshold `mean(f) / sin θ`
/// that removes everything near the poles. Values within a relative 10⁻⁵ of the
/// threshold count as zero (float rounding). If `f'` is zero everywhere (a constant
/// map) the light's own importance `f` is used instead.
///
/// # Why MIS with it stays unbiased
/// Sampling `f'` alone is biased: directions whose luminance is at most the mean
/// have density 0. In `mis-compensated` it is only ever one of two techniques: the
/// light sample is weighted `p'²/(p'² + p_bsdf²)` and the BSDF sample
/// `p_bsdf²/(p'² + p_bsdf²)`, both computed with the compensated density `p'`. The
/// weights sum to 1 wherever either density is positive, and every direction where
/// the integrand `L f cosθ` is non-zero has `p_bsdf > 0` (every BSDF here covers its
/// whole support), so the combined estimator is unbiased. Where `p' = 0` the BSDF
/// sample takes full weight; where the light is well above average, the light sample
/// dominates — the BSDF handles the "constant" part of the environment well, so the
/// light spends no samples on it.
#[derive(Debug, Clone)]
pub struct CompensatedLight<'a> {
    light: &'a EnvironmentLight,
    distribution: Distribution2D,
    mean_luminance: f64,
    fell_back: bool,
}

impl<'a> CompensatedLight<'a> {
    /// Builds the compensated distribution from `light`'s importance. `O(w h)`.
    pub fn new(light: &'a EnvironmentLight) -> Self {
        let base = light.distribution();
        let (nu, nv) = (base.nu(), base.nv());
        // Same row factors the light used to build its importance.
        let sin_theta: Vec<f64> = (0..nv)
            .map(|j| (std::f64::consts::PI * (j as f64 + 0.5) / nv as f64).sin())
            .collect();
        let f = base.func();
        let total_f: f64 = f.iter().map(|&x| x as f64).sum();
        let total_sin: f64 = sin_theta.iter().sum::<f64>() * nu as f64;
        let mean_luminance = if total_sin > 0.0 {
            total_f / total_sin
        } else {
            0.0
        };
        let mut compensated = vec![0.0f32; f.len()];
        let mut any_positive = false;
        for (j, (out_row, in_row)) in compensated.chunks_mut(nu).zip(f.chunks(nu)).enumerate() {
            let threshold = mean_luminance * sin_theta[j];
            for (o, &x) in out_row.iter_mut().zip(in_row) {
                // Within rounding of the threshold counts as not above it, so a
                // constant map (f = Ȳ sin θ up to f32 rounding) falls back cleanly.
                let v = if x as f64 > threshold * (1.0 + 1e-5) {
                    (x as f64 - threshold) as f32
                } else {
                    0.0
                };
                any_positive |= v > 0.0;
                *o = v;
            }
        }
        let fell_back = !any_positive;
        let distribution = if fell_back {
            base.clone()
        } else {
            Distribution2D::new(&compensated, nu)
        };
        Self {
            light,
            distribution,
            mean_luminance,
            fell_back,
        }
    }

    /// The subtracted solid-angle mean luminance `Ȳ` (of the light's filtered,
    /// unscaled importance).
    pub fn mean_luminance(&self) -> f64 {
        self.mean_luminance
    }

    /// Whether `f'` was zero everywhere and the light's own distribution is used.
    pub fn fell_back(&self) -> bool {
        self.fell_back
    }

    /// The compensated distribution over `[0, 1]²`.
    pub fn distribution(&self) -> &Distribution2D {
        &self.distribution
    }

    /// Draws a direction with density ∝ `f'`; `None` where the light would give none.
    #[inline]
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        let s = self.distribution.sample_continuous(xi);
        if s.pdf == 0.0 {
            return None;
        }
        let (_, sin_theta) = equirect_to_direction(s.uv[0], s.uv[1]);
        if sin_theta <= 0.0 {
            return None;
        }
        let pdf = s.pdf / (EQUIRECT_JACOBIAN * sin_theta);
        if !pdf.is_finite() {
            return None;
        }
        let options = self.light.options();
        let radiance = self
            .light
            .image()
            .lookup(s.uv[0], s.uv[1], options.lookup)
            .map(|c| c * options.scale);
        Some(LightSample {
            direction: self.light.uv_to_direction(s.uv),
            pdf,
            radiance,
            uv: s.uv,
        })
    }

    /// The solid-angle density (per steradian) of [`Self::sample`] at the world
    /// direction `direction`.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        let uv = self.light.direction_to_uv(direction);
        let sin_theta = (std::f32::consts::PI * uv[1]).sin();
        if sin_theta <= 0.0 {
            return 0.0;
        }
        let pdf = self.distribution.pdf(uv) / (EQUIRECT_JACOBIAN * sin_theta);
        if pdf.is_finite() {
            pdf
        } else {
            0.0
        }
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
    }

    #[test]
    fn constant_map_falls_back_and_bright_patch_is_kept() {
        let constant = EnvImage::from_fn(16, 8, |_, _| [1.0; 3]).unwrap();
        let light = EnvironmentLight::new(constant, LightOptions::default()).unwrap();
        let c = CompensatedLight::new(&light);
        assert!(c.fell_back());
        assert!(
            (c.mean_luminance() - 1.0).abs() < 1e-5,
            "{}",
            c.mean_luminance()
        );

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
