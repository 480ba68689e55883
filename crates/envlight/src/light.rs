//! The environment light: an equirectangular HDR image at infinity, importance
//! sampled in proportion to its luminance.
//!
//! Construction (DESIGN.md §4):
//! 1. importance `f[j][i] = Y(filtered radiance of texel (i, j)) · sin θ_j`, with
//!    `θ_j = π (j + ½) / h`. For bilinear lookups the filter is the exact texel-area
//!    average of the bilinear reconstruction, the separable `[1 6 1]/8` blur (wrap in
//!    u, clamp in v), so every direction where `radiance()` can be non-zero has
//!    `pdf() > 0`. Nearest lookups need no filter.
//! 2. a [`Distribution2D`] over `f`.
//!
//! Sampling maps `(u, v)` from the distribution to a direction and converts the
//! density to solid angle: `p(ω) = p(u, v) / (2π² sin θ)`.

use crate::color::luminance;
use crate::distribution::Distribution2D;
use crate::error::{Error, Result};
use crate::image::{EnvImage, Lookup};
use crate::mapping::{direction_to_equirect, equirect_to_direction, EQUIRECT_JACOBIAN};
use crate::math::{Rotation, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// How an [`EnvironmentLight`] is built and placed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightOptions {
    /// Multiplies every radiance value (not the sampling density). Finite, ≥ 0.
    pub scale: f32,
    /// Light-to-world rotation: the map's +z goes to `rotation.apply(+z)`.
    pub rotation: Rotation,
    /// How radiance is reconstructed between texels; the importance is filtered to
    /// cover this lookup's support.
    pub lookup: Lookup,
}

impl Default for LightOptions {
    fn default() -> Self {
        Self {
            scale: 1.0,
            rotation: Rotation::IDENTITY,
            lookup: Lookup::Bilinear,
        }
    }
}

/// A direction drawn from the light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LightSample {
    /// World-space unit direction towards the light.
    pub direction: Vec3,
    /// Solid-angle density of `direction`, per steradian (always > 0 and finite).
    pub pdf: f32,
    /// Radiance arriving from `direction` (linear RGB, scale applied).
    pub radiance: [f32; 3],
    /// The image point `[u, v]` the direction came from.
    pub uv: [f32; 2],
}

/// An importance-sampled environment light.
///
/// `Send + Sync`; all queries take `&self` and allocate nothing.
///
/// ```
/// use envlight::{EnvImage, EnvironmentLight, LightOptions};
/// // A 2×1 map: the upper hemisphere is bright, the lower dark.
/// let image = EnvImage::from_fn(8, 4, |_, y| if y < 2 { [1.0; 3] } else { [0.0; 3] }).unwrap();
/// let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
/// let s = light.sample([0.3, 0.6]).expect("a non-black map always samples");
/// assert!((light.pdf(s.direction) - s.pdf).abs() <= 1e-4 * s.pdf);
/// ```
#[derive(Debug, Clone)]
pub struct EnvironmentLight {
    image: EnvImage,
    options: LightOptions,
    world_to_light: Rotation,
    /// False for the identity rotation, which the hot paths then skip.
    rotated: bool,
    distribution: Distribution2D,
    /// `∫ L dω` of the unscaled image, per channel.
    integral_rgb: [f64; 3],
}

impl EnvironmentLight {
    /// Builds the light and its sampling distribution (rows in parallel).
    ///
    /// Time `O(w h)`; memory: the image plus 8 bytes per texel of sampling data.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] when `options.scale` is negative or not finite.
    pub fn new(image: EnvImage, options: LightOptions) -> Result<Self> {
        if !(options.scale >= 0.0 && options.scale.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "radiance scale must be finite and >= 0, got {}",
                options.scale
            )));
        }
        let (distribution, integral_rgb) = build_importance(&image, options.lookup);
        Ok(Self {
            world_to_light: options.rotation.inverse(),
            rotated: !options.rotation.is_identity(),
            image,
            options,
            distribution,
            integral_rgb,
        })
    }

    /// The image the light was built from.
    pub fn image(&self) -> &EnvImage {
        &self.image
    }

    /// The options the light was built with.
    pub fn options(&self) -> &LightOptions {
        &self.options
    }

    /// The sampling distribution over `[0, 1]²` (u along the width, v down).
    pub fn distribution(&self) -> &Distribution2D {
        &self.distribution
    }

    /// Bytes of sampling data (excluding the image).
    pub fn sampling_bytes(&self) -> usize {
        self.distribution.memory_bytes()
    }

    #[inline]
    fn to_world(&self, d: Vec3) -> Vec3 {
        if self.rotated {
            self.options.rotation.apply(d)
        } else {
            d
        }
    }

    #[inline]
    fn to_light(&self, d: Vec3) -> Vec3 {
        if self.rotated {
            self.world_to_light.apply(d)
        } else {
            d
        }
    }

    #[inline]
    fn lookup(&self, uv: [f32; 2]) -> [f32; 3] {
        let l = self.image.lookup(uv[0], uv[1], self.options.lookup);
        let s = self.options.scale;
        [l[0] * s, l[1] * s, l[2] * s]
    }

    /// Draws a direction for `ξ ∈ [0, 1)²` with density ∝ importance.
    ///
    /// Returns `None` when the map is black (pdf 0) or the point falls exactly on a
    /// pole, where the solid-angle density is unbounded (a set of measure zero).
    #[inline]
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        let s = self.distribution.sample_continuous(xi);
        if s.pdf == 0.0 {
            return None;
        }
        let (local, sin_theta) = equirect_to_direction(s.uv[0], s.uv[1]);
        if sin_theta <= 0.0 {
            return None;
        }
        let pdf = s.pdf / (EQUIRECT_JACOBIAN * sin_theta);
        if !pdf.is_finite() {
            return None;
        }
        Some(LightSample {
            direction: self.to_world(local),
            pdf,
            radiance: self.lookup(s.uv),
            uv: s.uv,
        })
    }

    /// The solid-angle density (per steradian) with which [`Self::sample`] produces
    /// the world-space unit direction `direction`; 0 where the light is black, at the
    /// poles, and for a black map.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        let uv = direction_to_equirect(self.to_light(direction));
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

    /// Radiance arriving from the world-space unit direction `direction` (for rays
    /// that escape the scene): the image lookup, times the scale.
    #[inline]
    pub fn radiance(&self, direction: Vec3) -> [f32; 3] {
        self.lookup(direction_to_equirect(self.to_light(direction)))
    }

    /// The image point `[u, v]` that looks along the world direction `direction`.
    #[inline]
    pub fn direction_to_uv(&self, direction: Vec3) -> [f32; 2] {
        direction_to_equirect(self.to_light(direction))
    }

    /// The world direction at image point `[u, v]`.
    #[inline]
    pub fn uv_to_direction(&self, uv: [f32; 2]) -> Vec3 {
        self.to_world(equirect_to_direction(uv[0], uv[1]).0)
    }

    /// [`Self::sample`] for every `ξ` in `xi`, written to `out` in order, in parallel.
    /// Each result depends only on its own `ξ`, so the output is the same for any
    /// thread count.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<LightSample>]) {
        batch(xi, out, |&x| self.sample(x));
    }

    /// [`Self::pdf`] for every direction in `directions`, in parallel.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        batch(directions, out, |&d| self.pdf(d));
    }

    /// [`Self::radiance`] for every direction in `directions`, in parallel.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        batch(directions, out, |&d| self.radiance(d));
    }

    /// The sample-space point `ξ` that [`Self::sample`] maps to `direction`
    /// (the exact inverse of sampling, up to float rounding).
    #[inline]
    pub fn invert(&self, direction: Vec3) -> [f32; 2] {
        self.distribution.invert(self.direction_to_uv(direction))
    }

    /// `∫ L dω` over the sphere per channel (scale applied), exact for the chosen
    /// lookup: each row's mean times the solid angle its reconstruction covers.
    pub fn integral_rgb(&self) -> [f64; 3] {
        let s = self.options.scale as f64;
        self.integral_rgb.map(|c| c * s)
    }

    /// `∫ Y dω` over the sphere (scale applied).
    pub fn integral_luminance(&self) -> f64 {
        let [r, g, b] = self.integral_rgb();
        let w = crate::color::LUMINANCE_WEIGHTS;
        w[0] as f64 * r + w[1] as f64 * g + w[2] as f64 * b
    }

    /// Power emitted into a scene of bounding radius `scene_radius`:
    /// `Φ = π r² ∫ L dω` per channel.
    pub fn power(&self, scene_radius: f64) -> [f64; 3] {
        let area = PI * scene_radius * scene_radius;
        self.integral_rgb().map(|c| c * area)
    }

    /// The brightest texel's luminance (scale applied) and the world direction of
    /// its centre.
    pub fn brightest(&self) -> (f32, Vec3) {
        let (w, h) = (self.image.width(), self.image.height());
        let (index, y) = self
            .image
            .texels()
            .par_iter()
            .map(|&t| luminance(t))
            .enumerate()
            .reduce(
                || (0, f32::NEG_INFINITY),
                |a, b| {
                    if b.1 > a.1 || (b.1 == a.1 && b.0 < a.0) {
                        b
                    } else {
                        a
                    }
                },
            );
        let uv = [
            ((index % w) as f32 + 0.5) / w as f32,
            ((index / w) as f32 + 0.5) / h as f32,
        ];
        (y * self.options.scale, self.uv_to_direction(uv))
    }

    /// Sampling efficiency `(∫ Y dω)² / ∫ (Y² / p) dω`: 1 when the pdf is exactly
    /// proportional to luminance; the variance of the estimator `Y/p` of `∫ Y dω`
    /// is `(1/efficiency - 1) (∫ Y dω)²` per sample. 0 for a black map or when the
    /// pdf misses light.
    ///
    /// Computed by quadrature (2×2 Gauss-Legendre points in each quarter of every
    /// texel, exact for bilinear radiance in u), in parallel. `O(16 w h)` lookups.
    pub fn efficiency(&self) -> f64 {
        let (ey, ey2p) = self.luminance_moments();
        if ey > 0.0 && ey2p.is_finite() && ey2p > 0.0 {
            ey * ey / ey2p
        } else {
            0.0
        }
    }

    /// `(∫ Y dω, ∫ Y²/p dω)` by quadrature (unscaled; efficiency is scale-free).
    fn luminance_moments(&self) -> (f64, f64) {
        let (w, h) = (self.image.width(), self.image.height());
        // Gauss-Legendre 2-point nodes on [0, 1], inside each quarter texel.
        let g = 0.5 / 3f64.sqrt();
        let nodes = [
            0.25 - 0.5 * g,
            0.25 + 0.5 * g,
            0.75 - 0.5 * g,
            0.75 + 0.5 * g,
        ];
        let jac = EQUIRECT_JACOBIAN as f64;
        (0..h)
            .into_par_iter()
            .map(|j| {
                let mut ey = 0.0f64;
                let mut ey2p = 0.0f64;
                for &tv in &nodes {
                    let v = (j as f64 + tv) / h as f64;
                    let sin_theta = (PI * v).sin();
                    for i in 0..w {
                        let p_uv = self.distribution.cell_pdf(i, j) as f64;
                        for &tu in &nodes {
                            let u = (i as f64 + tu) / w as f64;
                            let y = luminance(self.image.lookup(
                                u as f32,
                                v as f32,
                                self.options.lookup,
                            )) as f64;
                            let dw = jac * sin_theta;
                            ey += y * dw;
                            if y > 0.0 {
                                ey2p += if p_uv > 0.0 {
                                    y * y * dw * dw / p_uv
                                } else {
                                    f64::INFINITY
                                };
                            }
                        }
                    }
                }
                let cell = 1.0 / (16.0 * w as f64 * h as f64);
                (ey * cell, ey2p * cell)
            })
            .collect::<Vec<_>>()
            .into_iter()
            // Summed in row order so the result does not depend on the thread count.
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

/// Applies `f` element-wise from `input` to `out` in parallel chunks large enough
/// that scheduling costs little next to the work.
fn batch<I: Sync, O: Send>(input: &[I], out: &mut [O], f: impl Fn(&I) -> O + Sync) {
    assert_eq!(
        input.len(),
        out.len(),
        "batch input and output lengths differ"
    );
    const CHUNK: usize = 4096;
    out.par_chunks_mut(CHUNK)
        .zip(input.par_chunks(CHUNK))
        .for_each(|(o, i)| {
            for (dst, src) in o.iter_mut().zip(i) {
                *dst = f(src);
            }
        });
}

/// The importance distribution of DESIGN.md §4 step 1 and `∫ L dω`, in one
/// row-parallel pass over the texels.
///
/// Importance: `f[j][i] = Y(filtered) · sin θ_j`; for bilinear lookups the filter is
/// the `[1 6 1]/8` blur in v (clamped) then u (wrapped), whose three input rows come
/// from a rolling cache so each row's luminance is computed once per block.
///
/// Integral: along u, wrapped linear interpolation between texel centres integrates
/// to the row mean, so `∫ L dω = Σ_j W_j · mean_i L[j][i]` with `W_j` the solid angle
/// of row j's reconstruction weight ([`row_solid_angles`]); exact for either lookup.
fn build_importance(image: &EnvImage, lookup: Lookup) -> (Distribution2D, [f64; 3]) {
    let (w, h) = (image.width(), image.height());
    let (distribution, row_sums) = Distribution2D::from_rows_with(
        w,
        h,
        || LuminanceRows::new(w),
        |cache, j, out| {
            let sin_theta = (PI * (j as f64 + 0.5) / h as f64).sin() as f32;
            match lookup {
                Lookup::Nearest => {
                    let (luma, _) = cache.row(image, j);
                    for (o, &y) in out.iter_mut().zip(luma) {
                        *o = y * sin_theta;
                    }
                }
                Lookup::Bilinear => {
                    // Vertical [1 6 1]/8 (clamped) into `out`, then horizontal (wrapped).
                    out.copy_from_slice(cache.row(image, j.saturating_sub(1)).0);
                    for (o, &y) in out.iter_mut().zip(cache.row(image, (j + 1).min(h - 1)).0) {
                        *o += y;
                    }
                    for (o, &y) in out.iter_mut().zip(cache.row(image, j).0) {
                        *o = (*o + 6.0 * y) * 0.125;
                    }
                    let (first, last) = (out[0], out[w - 1]);
                    let mut prev = last;
                    for i in 0..w {
                        let next = if i + 1 < w { out[i + 1] } else { first };
                        let centre = out[i];
                        out[i] = (prev + 6.0 * centre + next) * 0.125 * sin_theta;
                        prev = centre;
                    }
                }
            }
            cache.row(image, j).1
        },
    );
    let weights = row_solid_angles(h, lookup);
    let mut integral = [0.0f64; 3];
    for (sums, weight) in row_sums.iter().zip(&weights) {
        for k in 0..3 {
            integral[k] += sums[k] / w as f64 * weight;
        }
    }
    (distribution, integral)
}

/// The luminance of the last three image rows a build task asked for, with each
/// row's RGB sums (f64), so the `[1 6 1]` filter computes every row's luminance once
/// per block of rows instead of three times.
struct LuminanceRows {
    slots: [(usize, Vec<f32>, [f64; 3]); 3],
}

impl LuminanceRows {
    fn new(w: usize) -> Self {
        Self {
            slots: std::array::from_fn(|_| (usize::MAX, vec![0.0; w], [0.0; 3])),
        }
    }

    /// Luminance and RGB sums of row `j`, computed unless cached.
    fn row(&mut self, image: &EnvImage, j: usize) -> (&[f32], [f64; 3]) {
        let slot = match self.slots.iter().position(|s| s.0 == j) {
            Some(slot) => slot,
            None => {
                // Rows are requested in increasing order: the lowest row is stale.
                let slot = (0..3)
                    .min_by_key(|&k| self.slots[k].0.wrapping_add(1))
                    .unwrap_or(0);
                let (id, luma, sums) = &mut self.slots[slot];
                *id = j;
                // Four partial sums per channel break the f64 add dependency chain.
                let mut partial = [[0.0f64; 3]; 4];
                for (k, (y, rgb)) in luma.iter_mut().zip(image.row(j)).enumerate() {
                    *y = luminance(*rgb);
                    let p = &mut partial[k & 3];
                    p[0] += rgb[0] as f64;
                    p[1] += rgb[1] as f64;
                    p[2] += rgb[2] as f64;
                }
                *sums = std::array::from_fn(|c| {
                    (partial[0][c] + partial[1][c]) + (partial[2][c] + partial[3][c])
                });
                slot
            }
        };
        let (_, luma, sums) = &self.slots[slot];
        (luma, *sums)
    }
}

/// Solid angle `W_j` attributed to each row by `lookup` (they sum to 4π).
pub(crate) fn row_solid_angles(h: usize, lookup: Lookup) -> Vec<f64> {
    let hf = h as f64;
    match lookup {
        Lookup::Nearest => (0..h)
            .map(|j| 2.0 * PI * ((PI * j as f64 / hf).cos() - (PI * (j + 1) as f64 / hf).cos()))
            .collect(),
        Lookup::Bilinear => {
            const GL_T: [f64; 4] = [
                0.069_431_844_202_973_71,
                0.330_009_478_207_571_9,
                0.669_990_521_792_428_1,
                0.930_568_155_797_026_3,
            ];
            const GL_W: [f64; 4] = [
                0.173_927_422_568_726_9,
                0.326_072_577_431_273_1,
                0.326_072_577_431_273_1,
                0.173_927_422_568_726_9,
            ];
            let mut weights = vec![0.0f64; h];
            for j in 0..h {
                let centre = (j as f64 + 0.5) / hf;
                // Upper half: between the top edge of texel j and its centre, the
                // neighbour is row j-1; lower half: row j+1 (clamped at the ends).
                for (lo, neighbour) in [
                    (j as f64 / hf, j.saturating_sub(1)),
                    (centre, (j + 1).min(h - 1)),
                ] {
                    let len = 0.5 / hf;
                    for (t, gw) in GL_T.iter().zip(GL_W) {
                        let v = lo + t * len;
                        let dw = 2.0 * PI * PI * (PI * v).sin() * gw * len;
                        let far = ((v - centre).abs() * hf).min(1.0);
                        weights[j] += (1.0 - far) * dw;
                        weights[neighbour] += far * dw;
                    }
                }
            }
            weights
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn row_solid_angles_sum_to_the_sphere() {
        for lookup in [Lookup::Nearest, Lookup::Bilinear] {
            for h in [1, 2, 3, 17, 512] {
                let total: f64 = row_solid_angles(h, lookup).iter().sum();
                assert!(
                    (total / (4.0 * PI) - 1.0).abs() < 1e-7,
                    "{lookup:?} h={h}: {total}"
                );
            }
        }
    }

    #[test]
    fn constant_map_integrates_to_4pi_and_has_uniform_pdf() {
        let image = EnvImage::from_fn(16, 8, |_, _| [2.0, 2.0, 2.0]).unwrap();
        let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
        let i = light.integral_rgb();
        assert!((i[0] - 8.0 * PI).abs() < 1e-6, "{i:?}");
        // Importance ∝ sin θ at row centres: pdf is uniform 1/4π up to the
        // piecewise-constant approximation of sin θ.
        let p = light.pdf(Vec3::new(1.0, 0.0, 0.0));
        // Importance is sin θ at row centres, so I = (1/h) Σ sin((j+½)π/h) =
        // 1 / (h sin(π/2h)), and at the equator (a row boundary for h = 8) the cell
        // holds sin(4.5π/8) while the true sin θ is 1.
        let integral = 1.0 / (8.0 * (PI / 16.0).sin());
        let expected = (4.5 * PI / 8.0).sin() / (integral * 2.0 * PI * PI);
        assert!(
            (p as f64 / expected - 1.0).abs() < 1e-5,
            "{p} vs {expected}"
        );
        // Analytic: (4π)² / (I (2π²)² Σ_j ∫_row sin²(πv) dv / sin θ_j) = 0.9678449 for
        // h = 8 (the piecewise-constant sin θ is the only mismatch).
        let e = light.efficiency();
        assert!((e - 0.967_844_9).abs() < 1e-5, "{e}");
    }

    #[test]
    fn rotation_moves_the_light() {
        // One bright column at u = 0 (+x); rotated by 90° it should sit at +y.
        let image =
            EnvImage::from_fn(8, 4, |x, _| if x == 0 { [1.0; 3] } else { [0.0; 3] }).unwrap();
        let options = LightOptions {
            rotation: Rotation::about_z_degrees(90.0),
            lookup: Lookup::Nearest,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image, options).unwrap();
        let d = Vec3::new(-0.02, 1.0, 0.1).normalized().unwrap();
        assert!(light.pdf(d) > 0.0 && light.radiance(d)[0] == 1.0);
        let x = Vec3::new(1.0, 0.02, 0.1).normalized().unwrap();
        assert_eq!(light.pdf(x), 0.0);
        let s = light.sample([0.5, 0.5]).unwrap();
        assert!(s.direction.y > 0.9, "{s:?}");
    }

    #[test]
    fn black_map_never_samples() {
        let image = EnvImage::from_fn(4, 2, |_, _| [0.0; 3]).unwrap();
        let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
        assert!(light.sample([0.5, 0.5]).is_none());
        assert_eq!(light.pdf(Vec3::new(0.0, 0.0, 1.0)), 0.0);
        assert_eq!(light.efficiency(), 0.0);
    }

    #[test]
    fn bad_scale_is_rejected() {
        let image = EnvImage::from_fn(1, 1, |_, _| [1.0; 3]).unwrap();
        for scale in [f32::NAN, -1.0, f32::INFINITY] {
            let options = LightOptions {
                scale,
                ..Default::default()
            };
            assert!(EnvironmentLight::new(image.clone(), options).is_err());
        }
    }
}
