//! The environment light: an HDR image at infinity, importance sampled in
//! proportion to its luminance.
//!
//! Construction (DESIGN.md §4), for the default piecewise-constant density:
//! 1. importance `f[j][i] = Y(filtered radiance of texel (i, j)) · J_j`, where `J_j`
//!    is the mapping's area factor at the row centre (`sin θ_j` for the
//!    equirectangular map, 1 for the equal-area square). For bilinear lookups the
//!    filter is the exact texel-area average of the bilinear reconstruction, the
//!    separable `[1 6 1]/8` blur (u wraps or clamps with the mapping, v clamps), so
//!    every direction where `radiance()` can be non-zero has `pdf() > 0`. Nearest
//!    lookups need no filter.
//! 2. a 2D sampler over `f` ([`Sampler`]).
//!
//! The piecewise-bilinear density instead puts `Y · J` at the texel centres (the
//! nodes of the bilinear reconstruction) and samples the bilinear interpolation of
//! those values, so `L / p` is nearly constant.
//!
//! Sampling maps the image point `(u, v)` to a direction and converts the density to
//! solid angle: `p(ω) = p(u, v) / (dω / du dv)`, with `dω / du dv = 2π² sin θ`
//! (equirectangular) or `4π` (equal-area).

use crate::alias::AliasTable2D;
use crate::bilinear::BilinearDistribution2D;
use crate::color::luminance;
use crate::distribution::{cell_indices, for_each_row, Distribution2D, Sample2D, STAGED_BLOCK};
use crate::equal_area::{self, EQUAL_AREA_JACOBIAN};
use crate::error::{Error, Result};
use crate::hierarchical::Hierarchical2D;
use crate::image::{EnvImage, Lookup, WrapU};
use crate::mapping::{
    direction_to_equirect_and_csc, directions_to_equirect_and_csc, equirect_to_direction,
    EQUIRECT_JACOBIAN,
};
use crate::math::{is_positive_finite, Rotation, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// How directions are drawn from the density. All give the same density; they
/// differ in speed, memory and whether nearby `ξ` give nearby directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Sampler {
    /// CDF inversion (the seed's method): a row from the marginal, then a column
    /// from the row, each found with a guide table and a short scan of a fixed-point
    /// CDF. Keeps stratification; invertible; 5 to 6 bytes per texel.
    #[default]
    Inversion,
    /// Vose's alias table over all cells: O(1) per sample, but it breaks
    /// stratification (nearby `ξ` land anywhere), and it has no inverse.
    Alias,
    /// Hierarchical warping down a pyramid of sums: keeps stratification and is
    /// invertible; one step per pyramid level.
    Hierarchical,
}

/// The shape of the sampling density over the image.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Density {
    /// Constant over each texel (the seed's): `f[j][i]` as in the module docs.
    #[default]
    PiecewiseConstant,
    /// Bilinear between texel centres, proportional to the bilinear radiance
    /// reconstruction times the mapping's area factor at the nodes. Sampled by
    /// inversion only.
    PiecewiseBilinear,
}

/// How image points map to directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mapping {
    /// Latitude-longitude: `θ = π v`, `φ = 2π u` ([`crate::mapping`]).
    #[default]
    Equirectangular,
    /// The equal-area octahedral square ([`crate::equal_area`]): constant Jacobian
    /// `4π`, no pole singularity.
    EqualArea,
}

impl Sampler {
    /// Every sampler, for option parsers and tests.
    pub const ALL: [Sampler; 3] = [Sampler::Inversion, Sampler::Alias, Sampler::Hierarchical];
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Sampler::Inversion => "inversion",
            Sampler::Alias => "alias",
            Sampler::Hierarchical => "hierarchical",
        }
    }
}

impl Density {
    /// Every density, for option parsers and tests.
    pub const ALL: [Density; 2] = [Density::PiecewiseConstant, Density::PiecewiseBilinear];
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Density::PiecewiseConstant => "piecewise-constant",
            Density::PiecewiseBilinear => "piecewise-bilinear",
        }
    }
}

impl Mapping {
    /// Every mapping, for option parsers and tests.
    pub const ALL: [Mapping; 2] = [Mapping::Equirectangular, Mapping::EqualArea];
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mapping::Equirectangular => "equirectangular",
            Mapping::EqualArea => "equal-area",
        }
    }

    /// How u behaves at the image's left and right edges.
    fn wrap(self) -> WrapU {
        match self {
            Mapping::Equirectangular => WrapU::Periodic,
            Mapping::EqualArea => WrapU::Clamp,
        }
    }

    /// The unit direction at `uv` and `dω / du dv` there.
    #[inline(always)]
    fn to_direction(self, uv: [f32; 2]) -> (Vec3, f32) {
        match self {
            Mapping::Equirectangular => {
                let (d, sin_theta) = equirect_to_direction(uv[0], uv[1]);
                (d, EQUIRECT_JACOBIAN * sin_theta)
            }
            Mapping::EqualArea => (
                equal_area::square_to_sphere(uv[0], uv[1]),
                EQUAL_AREA_JACOBIAN,
            ),
        }
    }

    /// The image point looking along `d`, and `du dv / dω` there (the reciprocal
    /// of the Jacobian; +∞ at the poles of the lat-long map).
    #[inline(always)]
    fn to_uv(self, d: Vec3) -> ([f32; 2], f32) {
        match self {
            Mapping::Equirectangular => {
                let (uv, csc_theta) = direction_to_equirect_and_csc(d);
                (uv, csc_theta * (1.0 / EQUIRECT_JACOBIAN))
            }
            Mapping::EqualArea => (equal_area::sphere_to_square(d), 1.0 / EQUAL_AREA_JACOBIAN),
        }
    }

    /// The mapping's area factor `J` at image height `v`, relative to its maximum
    /// (`sin θ` for lat-long, 1 for equal-area): what importance is multiplied by.
    fn area_factor(self, v: f64) -> f64 {
        match self {
            Mapping::Equirectangular => (PI * v).sin(),
            Mapping::EqualArea => 1.0,
        }
    }
}

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
    /// How directions are drawn from the density.
    pub sampler: Sampler,
    /// The shape of the density.
    pub density: Density,
    /// The parameterization the light samples and looks up in. A lat-long input
    /// with [`Mapping::EqualArea`] is resampled to an equal-area square.
    pub mapping: Mapping,
    /// What the image given to [`EnvironmentLight::new`] is: a lat-long map (2:1 by
    /// convention) or an equal-area square (as PBRT-v4 writes them).
    pub input_mapping: Mapping,
    /// Side of the equal-area square a lat-long input is resampled to; `None` keeps
    /// about the input's texel count ([`equal_area::default_size`]).
    pub equal_area_size: Option<usize>,
    /// MIS compensation (Karlík et al. 2019, as in PBRT-v4): sample
    /// `max(0, Y − Ȳ) · J` instead of `Y · J`, where `Ȳ` is the map's mean
    /// luminance per unit solid angle. The light then spends no samples on the
    /// part of the environment that BSDF sampling handles well. **The density is 0
    /// wherever `Y ≤ Ȳ`**, so the light alone no longer covers the whole sphere; use
    /// it only as one technique in multiple importance sampling with a strategy that
    /// does (BSDF sampling), where the combination stays unbiased. A map with
    /// nothing above its mean (a constant map) keeps the ordinary density.
    pub mis_compensation: bool,
}

impl Default for LightOptions {
    fn default() -> Self {
        Self {
            scale: 1.0,
            rotation: Rotation::IDENTITY,
            lookup: Lookup::Bilinear,
            sampler: Sampler::Inversion,
            density: Density::PiecewiseConstant,
            mapping: Mapping::Equirectangular,
            input_mapping: Mapping::Equirectangular,
            equal_area_size: None,
            mis_compensation: false,
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
    /// The image point `[u, v]` the direction came from (in the light's mapping).
    pub uv: [f32; 2],
}

/// The 2D sampler over `[0, 1]²` behind a light.
#[derive(Debug, Clone)]
enum Planar {
    Inversion(Distribution2D),
    Alias(AliasTable2D),
    Hierarchical(Hierarchical2D),
    Bilinear(BilinearDistribution2D),
}

impl Planar {
    #[inline(always)]
    fn pdf(&self, uv: [f32; 2]) -> f32 {
        match self {
            Planar::Inversion(d) => d.pdf(uv),
            Planar::Alias(d) => d.pdf(uv),
            Planar::Hierarchical(d) => d.pdf(uv),
            Planar::Bilinear(d) => d.pdf(uv),
        }
    }

    #[inline]
    fn invert(&self, uv: [f32; 2]) -> Option<[f32; 2]> {
        match self {
            Planar::Inversion(d) => Some(d.invert(uv)),
            Planar::Alias(_) => None,
            Planar::Hierarchical(d) => Some(d.invert(uv)),
            Planar::Bilinear(d) => Some(d.invert(uv)),
        }
    }

    fn integral(&self) -> f64 {
        match self {
            Planar::Inversion(d) => d.integral(),
            Planar::Alias(d) => d.integral(),
            Planar::Hierarchical(d) => d.integral(),
            Planar::Bilinear(d) => d.integral(),
        }
    }

    fn memory_bytes(&self) -> usize {
        match self {
            Planar::Inversion(d) => d.memory_bytes(),
            Planar::Alias(d) => d.memory_bytes(),
            Planar::Hierarchical(d) => d.memory_bytes(),
            Planar::Bilinear(d) => d.memory_bytes(),
        }
    }
}

/// An importance-sampled environment light.
///
/// `Send + Sync`; all queries take `&self` and allocate nothing.
///
/// ```
/// use envlight::{EnvImage, EnvironmentLight, LightOptions};
/// // The upper hemisphere is bright, the lower dark.
/// let image = EnvImage::from_fn(8, 4, |_, y| if y < 2 { [1.0; 3] } else { [0.0; 3] }).unwrap();
/// let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
/// let s = light.sample([0.3, 0.6]).expect("a non-black map always samples");
/// assert!((light.pdf(s.direction) - s.pdf).abs() <= 1e-4 * s.pdf);
/// ```
#[derive(Debug, Clone)]
pub struct EnvironmentLight {
    /// The radiance image in the light's mapping (resampled if the input differs).
    image: EnvImage,
    options: LightOptions,
    world_to_light: Rotation,
    /// False for the identity rotation, which the hot paths then skip.
    rotated: bool,
    planar: Planar,
    /// `∫ L dω` of the unscaled image, per channel.
    integral_rgb: [f64; 3],
    /// Whether MIS compensation is in effect (asked for, and something was above
    /// the mean).
    compensated: bool,
}

impl EnvironmentLight {
    /// Builds the light and its sampling distribution (rows in parallel).
    ///
    /// Time `O(w h)` (plus the resampling for an equal-area light from a lat-long
    /// map); memory: the image plus the sampler's data, 5 to 6 bytes per texel for
    /// the default inversion sampler.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] when `options.scale` is negative or not finite, the
    /// bilinear density is asked of a sampler other than inversion, an equal-area
    /// input is not square, or an equal-area input is asked for a lat-long light.
    pub fn new(image: EnvImage, options: LightOptions) -> Result<Self> {
        Self::with_progress(image, options, &|_| {})
    }

    /// [`Self::new`], reporting progress for a front end's progress bar: the build
    /// calls `rows_done(k)` each time it has finished `k` more rows of the light's
    /// image ([`Self::image`], so for an equal-area light from a lat-long map, rows
    /// of the resampled square). Calls come from the worker threads, in no
    /// particular order; their counts add up to the image's height.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn with_progress(
        image: EnvImage,
        options: LightOptions,
        rows_done: &(dyn Fn(usize) + Sync),
    ) -> Result<Self> {
        if !(options.scale >= 0.0 && options.scale.is_finite()) {
            return Err(Error::InvalidOption(format!(
                "radiance scale must be finite and >= 0, got {}",
                options.scale
            )));
        }
        if options.density == Density::PiecewiseBilinear && options.sampler != Sampler::Inversion {
            return Err(Error::InvalidOption(format!(
                "the piecewise-bilinear density is sampled by inversion only, not by the {} sampler",
                options.sampler.name()
            )));
        }
        let image = match (options.input_mapping, options.mapping) {
            (Mapping::Equirectangular, Mapping::Equirectangular) => image,
            (Mapping::Equirectangular, Mapping::EqualArea) => {
                let size = options
                    .equal_area_size
                    .unwrap_or_else(|| equal_area::default_size(image.width(), image.height()));
                if size == 0 {
                    return Err(Error::InvalidOption(
                        "the equal-area size must be at least 1".into(),
                    ));
                }
                equal_area::resample_equirect(&image, size, options.lookup)
            }
            (Mapping::EqualArea, Mapping::EqualArea) => {
                if image.width() != image.height() {
                    return Err(Error::InvalidOption(format!(
                        "an equal-area map must be square, this one is {}x{}",
                        image.width(),
                        image.height()
                    )));
                }
                image
            }
            (Mapping::EqualArea, Mapping::Equirectangular) => {
                return Err(Error::InvalidOption(
                    "an equal-area input can only be lit with the equal-area mapping".into(),
                ))
            }
        };
        let (planar, integral_rgb, compensated) = build_sampler(&image, &options, rows_done);
        Ok(Self {
            world_to_light: options.rotation.inverse(),
            rotated: !options.rotation.is_identity(),
            image,
            options,
            planar,
            integral_rgb,
            compensated,
        })
    }

    /// The radiance image the light looks up, in its own mapping (for an
    /// equal-area light built from a lat-long map, the resampled square).
    pub fn image(&self) -> &EnvImage {
        &self.image
    }

    /// The options the light was built with.
    pub fn options(&self) -> &LightOptions {
        &self.options
    }

    /// The parameterization of [`Self::image`] and of the `uv` of samples.
    pub fn mapping(&self) -> Mapping {
        self.options.mapping
    }

    /// True when the density is MIS-compensated ([`LightOptions::mis_compensation`]
    /// was asked for and part of the map is above its mean luminance).
    pub fn is_compensated(&self) -> bool {
        self.compensated
    }

    /// True when the map emits no light: every pdf is 0 and nothing can be sampled.
    pub fn is_black(&self) -> bool {
        let integral = self.planar.integral();
        integral.is_nan() || integral <= 0.0
    }

    /// Bytes of sampling data (excluding the image).
    pub fn sampling_bytes(&self) -> usize {
        self.planar.memory_bytes()
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

    #[inline(always)]
    fn lookup(&self, uv: [f32; 2]) -> [f32; 3] {
        let l = self.image.lookup_wrapped(
            uv[0],
            uv[1],
            self.options.lookup,
            self.options.mapping.wrap(),
        );
        let s = self.options.scale;
        [l[0] * s, l[1] * s, l[2] * s]
    }

    /// Draws a direction for `ξ ∈ [0, 1)²` with density ∝ importance.
    ///
    /// Returns `None` when the map is black (pdf 0), or when the point falls exactly
    /// on a pole of the lat-long map, where the solid-angle density is unbounded (a
    /// set of measure zero: about one `ξ` in 2²⁴ when the top or bottom row is lit).
    #[inline(always)]
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        // One dispatch on the sampler, each arm inlined whole: a second `match` on
        // it further down (for the pdf) measured 2x slower on the default path.
        match &self.planar {
            Planar::Inversion(d) => {
                // The texels the radiance lookup will read start loading while the
                // row's CDF is searched.
                let s = d.sample_continuous_hinted(xi, |uv| self.image.prefetch(uv[0], uv[1]));
                self.finish_sample(s, false)
            }
            Planar::Alias(d) => {
                let s = d.sample_continuous_hinted(xi, |uv| self.image.prefetch(uv[0], uv[1]));
                self.finish_sample(s, false)
            }
            Planar::Hierarchical(d) => self.finish_sample(d.sample_continuous(xi), false),
            Planar::Bilinear(d) => self.finish_sample(d.sample_continuous(xi), true),
        }
    }

    /// The direction, pdf and radiance of the planar sample `s`. A continuous density
    /// changes across the f32 rounding of the direction (by up to ~1e-3 relative
    /// next to a bright texel), so its pdf is evaluated where the caller will
    /// evaluate it: at the returned direction, bit for bit what [`Self::pdf`] gives.
    /// A piecewise-constant density is exact at `s.uv`.
    #[inline(always)]
    fn finish_sample(&self, s: Sample2D, continuous_density: bool) -> Option<LightSample> {
        if s.pdf == 0.0 {
            return None;
        }
        let (local, jacobian) = self.options.mapping.to_direction(s.uv);
        let direction = self.to_world(local);
        let pdf = if continuous_density {
            self.pdf(direction)
        } else {
            s.pdf / jacobian
        };
        if !(jacobian > 0.0 && is_positive_finite(pdf)) {
            return None;
        }
        Some(LightSample {
            direction,
            pdf,
            radiance: self.lookup(s.uv),
            uv: s.uv,
        })
    }

    /// The solid-angle density (per steradian) with which [`Self::sample`] produces
    /// the world-space unit direction `direction`; 0 where the light is black, at the
    /// poles of a lat-long map, and for a black map.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        // One dispatch on the sampler, each arm inlined whole (see `sample`).
        match &self.planar {
            Planar::Inversion(d) => self.solid_angle_pdf(direction, |uv| d.pdf(uv)),
            Planar::Alias(d) => self.solid_angle_pdf(direction, |uv| d.pdf(uv)),
            Planar::Hierarchical(d) => self.solid_angle_pdf(direction, |uv| d.pdf(uv)),
            Planar::Bilinear(d) => self.solid_angle_pdf(direction, |uv| d.pdf(uv)),
        }
    }

    /// `planar_pdf(uv) / (dω/du dv)` at the image point of `direction`.
    #[inline(always)]
    fn solid_angle_pdf(&self, direction: Vec3, planar_pdf: impl Fn([f32; 2]) -> f32) -> f32 {
        let (uv, inv_jacobian) = self.options.mapping.to_uv(self.to_light(direction));
        solid_angle(planar_pdf(uv), inv_jacobian)
    }

    /// Radiance arriving from the world-space unit direction `direction` (for rays
    /// that escape the scene): the image lookup, times the scale.
    #[inline]
    pub fn radiance(&self, direction: Vec3) -> [f32; 3] {
        self.lookup(self.direction_to_uv(direction))
    }

    /// [`Self::sample`] for every `ξ` in `xi`, written to `out` in order, in parallel.
    /// Each result depends only on its own `ξ`, so the output is the same for any
    /// thread count.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<LightSample>]) {
        let one_by_one = |sample: &(dyn Fn([f32; 2]) -> Sample2D + Sync),
                          xi: &[[f32; 2]],
                          out: &mut [Sample2D]| {
            for (o, &x) in out.iter_mut().zip(xi) {
                *o = sample(x);
            }
        };
        match &self.planar {
            Planar::Inversion(d) => self.sample_blocks(xi, out, false, |xi, out| {
                d.sample_block(xi, out, |uv| self.image.prefetch(uv[0], uv[1]))
            }),
            Planar::Alias(d) => self.sample_blocks(xi, out, false, |xi, out| {
                one_by_one(
                    &|x| d.sample_continuous_hinted(x, |uv| self.image.prefetch(uv[0], uv[1])),
                    xi,
                    out,
                )
            }),
            Planar::Hierarchical(d) => self.sample_blocks(xi, out, false, |xi, out| {
                one_by_one(&|x| d.sample_continuous(x), xi, out)
            }),
            Planar::Bilinear(d) => self.sample_blocks(xi, out, true, |xi, out| {
                one_by_one(&|x| d.sample_continuous(x), xi, out)
            }),
        }
    }

    /// [`Self::sample_batch`] in two stages per block of samples: all the planar
    /// samples (`planar_block`, which may overlap their memory accesses, see
    /// [`Distribution2D::sample_block`]), then all the directions, pdfs and radiance
    /// lookups. A single sample is one long chain of dependent steps (CDF search,
    /// placement, sin/cos, texel loads) that the CPU cannot overlap with the next; a
    /// stage runs a block of independent short chains, which it can.
    #[inline(always)]
    fn sample_blocks(
        &self,
        xi: &[[f32; 2]],
        out: &mut [Option<LightSample>],
        continuous_density: bool,
        planar_block: impl Fn(&[[f32; 2]], &mut [Sample2D]) + Sync,
    ) {
        batch_chunks(xi, out, |xi, out| {
            let mut planar = [Sample2D::default(); STAGED_BLOCK];
            for (xi, out) in xi.chunks(STAGED_BLOCK).zip(out.chunks_mut(STAGED_BLOCK)) {
                let planar = &mut planar[..xi.len()];
                planar_block(xi, planar);
                for (o, &p) in out.iter_mut().zip(planar.iter()) {
                    *o = self.finish_sample(p, continuous_density);
                }
            }
        });
    }

    /// [`Self::pdf`] for every direction in `directions`, in parallel, bit for bit
    /// the single calls' values. Each thread works through blocks of directions
    /// whose angles and cells it computes side by side in vector lanes (AVX2
    /// where the CPU has it), several times cheaper per direction than single
    /// calls.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        self.run_batch(directions, out, Self::pdf_chunk, Self::pdf_chunk_avx2);
    }

    /// Hands matching chunks of `directions` and `out` to `kernel`, in parallel,
    /// or to `wide_kernel` (the same code compiled for AVX2) where the CPU has
    /// AVX2 (see [`wide_vectors`]).
    fn run_batch<O: Send>(
        &self,
        directions: &[Vec3],
        out: &mut [O],
        kernel: fn(&Self, &[Vec3], &mut [O]),
        wide_kernel: unsafe fn(&Self, &[Vec3], &mut [O]),
    ) {
        let wide = wide_vectors();
        batch_chunks(directions, out, |dirs, out| {
            if wide {
                // SAFETY: the wide kernels need AVX2, which the CPU supports.
                unsafe { wide_kernel(self, dirs, out) }
            } else {
                kernel(self, dirs, out)
            }
        });
    }

    /// [`Self::pdf_chunk`] compiled for AVX2 (see [`wide_vectors`]).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    fn pdf_chunk_avx2(&self, dirs: &[Vec3], out: &mut [f32]) {
        self.pdf_chunk(dirs, out)
    }

    /// [`Self::pdf_batch`] on one chunk, on the current thread. For the
    /// piecewise-constant samplers the cells of a block are found together too
    /// ([`cell_indices`]) and fetched a block ahead; the bilinear density reads
    /// its patches one at a time.
    #[inline(always)]
    fn pdf_chunk(&self, dirs: &[Vec3], out: &mut [f32]) {
        match &self.planar {
            Planar::Inversion(d) => self.pdf_cells(
                dirs,
                out,
                [d.nu(), d.nv()],
                |iu, iv| d.prefetch_cell(iu, iv),
                |iu, iv| d.cell_pdf_in_grid(iu, iv),
            ),
            Planar::Alias(d) => self.pdf_cells(
                dirs,
                out,
                [d.nu(), d.nv()],
                |iu, iv| d.prefetch_cell(iu, iv),
                |iu, iv| d.cell_pdf(iu, iv),
            ),
            Planar::Hierarchical(d) => self.pdf_cells(
                dirs,
                out,
                [d.nu(), d.nv()],
                |_, _| {},
                |iu, iv| d.cell_pdf(iu, iv),
            ),
            Planar::Bilinear(d) => self.uv_blocks(
                dirs,
                out,
                |block| *block,
                #[inline(always)]
                |block: &UvBlock, out| {
                    for (i, o) in out.iter_mut().enumerate() {
                        let uv = [block.u[i], block.v[i]];
                        *o = solid_angle(d.pdf(uv), block.inv_jacobian[i]);
                    }
                },
            ),
        }
    }

    /// The pdf stage of [`Self::pdf_batch`] for a piecewise-constant density over
    /// a `grid[0] × grid[1]` grid of cells: `cell_pdf` of the cell at each image
    /// point of [`Self::uv_blocks`], over the Jacobian. `prefetch` asks for a cell's
    /// data a block before `cell_pdf` reads it.
    #[inline(always)]
    fn pdf_cells(
        &self,
        dirs: &[Vec3],
        out: &mut [f32],
        [nu, nv]: [usize; 2],
        prefetch: impl Fn(usize, usize),
        cell_pdf: impl Fn(usize, usize) -> f32,
    ) {
        self.uv_blocks(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let (iu, iv) = (cell_indices(&block.u, nu), cell_indices(&block.v, nv));
                for (&iu, &iv) in iu.iter().zip(&iv) {
                    prefetch(iu as usize, iv as usize);
                }
                CellBlock {
                    iu,
                    iv,
                    inv_jacobian: block.inv_jacobian,
                }
            },
            #[inline(always)]
            |cells: &CellBlock, out| {
                for (i, o) in out.iter_mut().enumerate() {
                    let planar = cell_pdf(cells.iu[i] as usize, cells.iv[i] as usize);
                    *o = solid_angle(planar, cells.inv_jacobian[i]);
                }
            },
        );
    }

    /// Cuts `dirs` into blocks of [`QUERY_BLOCK`] directions and computes each
    /// block's image points and reciprocal Jacobians together
    /// ([`Self::to_uv_block`]). `prepare` then turns them into whatever `finish`
    /// needs and starts fetching the memory it will read; `finish` writes the
    /// results into the matching part of `out`, one block later: a block's cache
    /// misses are under way while the next block's angles are computed. The last
    /// block is padded; `out` is as long as the real part.
    #[inline(always)]
    fn uv_blocks<O, P>(
        &self,
        dirs: &[Vec3],
        out: &mut [O],
        prepare: impl Fn(&UvBlock) -> P,
        mut finish: impl FnMut(&P, &mut [O]),
    ) {
        // Coordinates in separate arrays, the layout vector instructions read. Each
        // block's arrays are written one block ahead: vector loads of data just
        // written by scalar stores wait for the stores to retire (they cannot be
        // forwarded), which cost about 5% of a batch pdf or radiance query.
        #[inline(always)]
        fn transpose(dirs: &[Vec3]) -> [[f32; QUERY_BLOCK]; 3] {
            let mut xyz = [
                [0.0f32; QUERY_BLOCK],
                [0.0; QUERY_BLOCK],
                [1.0; QUERY_BLOCK],
            ];
            for (i, d) in dirs.iter().enumerate() {
                (xyz[0][i], xyz[1][i], xyz[2][i]) = (d.x, d.y, d.z);
            }
            xyz
        }
        // Two slots used in turn: a block's prepared data stays where `prepare`
        // wrote it until `finish` reads it, one block later, rather than being
        // moved in and out of a single pending slot (a further 3-5%).
        let mut slots: [Option<(P, &mut [O])>; 2] = [None, None];
        let mut blocks = dirs.chunks(QUERY_BLOCK).zip(out.chunks_mut(QUERY_BLOCK));
        let mut next = blocks.next().map(|(d, o)| (transpose(d), o));
        let mut k = 0;
        while let Some(([x, y, z], out)) = next.take() {
            next = blocks.next().map(|(d, o)| (transpose(d), o));
            slots[k & 1] = Some((prepare(&self.to_uv_block(x, y, z)), out));
            if let Some((previous, previous_out)) = &mut slots[(k + 1) & 1] {
                finish(previous, previous_out);
            }
            slots[(k + 1) & 1] = None;
            k += 1;
        }
        if let Some((last, last_out)) = &mut slots[(k + 1) & 1] {
            finish(last, last_out);
        }
    }

    /// [`Mapping::to_uv`] of a block of world directions (rotated into the light's
    /// frame), as loops over the block that the compiler vectorizes: a query's
    /// angles are a long chain of dependent steps (square roots, a division, a
    /// polynomial) that one query at a time leaves the CPU waiting on; a block
    /// computes many side by side, several per instruction. Bit for bit the
    /// single-direction values.
    #[inline(always)]
    fn to_uv_block(
        &self,
        mut x: [f32; QUERY_BLOCK],
        mut y: [f32; QUERY_BLOCK],
        mut z: [f32; QUERY_BLOCK],
    ) -> UvBlock {
        if self.rotated {
            for i in 0..QUERY_BLOCK {
                let d = self.world_to_light.apply(Vec3::new(x[i], y[i], z[i]));
                (x[i], y[i], z[i]) = (d.x, d.y, d.z);
            }
        }
        match self.options.mapping {
            Mapping::Equirectangular => {
                let (u, v, mut inv_jacobian) = directions_to_equirect_and_csc(&x, &y, &z);
                for j in &mut inv_jacobian {
                    *j *= 1.0 / EQUIRECT_JACOBIAN;
                }
                UvBlock { u, v, inv_jacobian }
            }
            Mapping::EqualArea => {
                let (mut u, mut v) = ([0.0f32; QUERY_BLOCK], [0.0f32; QUERY_BLOCK]);
                for i in 0..QUERY_BLOCK {
                    [u[i], v[i]] = equal_area::sphere_to_square(Vec3::new(x[i], y[i], z[i]));
                }
                UvBlock {
                    u,
                    v,
                    inv_jacobian: [1.0 / EQUAL_AREA_JACOBIAN; QUERY_BLOCK],
                }
            }
        }
    }

    /// [`Self::radiance`] for every direction in `directions`, in parallel, bit for
    /// bit the single calls' values, computed in blocks like [`Self::pdf_batch`].
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        self.run_batch(
            directions,
            out,
            Self::radiance_chunk,
            Self::radiance_chunk_avx2,
        );
    }

    /// [`Self::radiance_chunk`] compiled for AVX2 (see [`wide_vectors`]).
    #[cfg_attr(target_arch = "x86_64", target_feature(enable = "avx2"))]
    fn radiance_chunk_avx2(&self, dirs: &[Vec3], out: &mut [[f32; 3]]) {
        self.radiance_chunk(dirs, out)
    }

    /// [`Self::radiance_batch`] on one chunk, on the current thread.
    #[inline(always)]
    fn radiance_chunk(&self, dirs: &[Vec3], out: &mut [[f32; 3]]) {
        self.uv_blocks(
            dirs,
            out,
            #[inline(always)]
            |block| {
                let (mode, wrap) = (self.options.lookup, self.options.mapping.wrap());
                let lookups = self.image.lookup_block(&block.u, &block.v, mode, wrap);
                self.image.prefetch_block(&lookups);
                lookups
            },
            #[inline(always)]
            |lookups: &crate::image::LookupBlock<QUERY_BLOCK>, out| {
                let s = self.options.scale;
                for (i, o) in out.iter_mut().enumerate() {
                    let l = self.image.fetch(lookups, i);
                    *o = [l[0] * s, l[1] * s, l[2] * s];
                }
            },
        )
    }

    /// The image point `[u, v]` (in the light's mapping) that looks along the world
    /// direction `direction`.
    #[inline]
    pub fn direction_to_uv(&self, direction: Vec3) -> [f32; 2] {
        self.options.mapping.to_uv(self.to_light(direction)).0
    }

    /// The world direction at image point `[u, v]` (in the light's mapping).
    #[inline]
    pub fn uv_to_direction(&self, uv: [f32; 2]) -> Vec3 {
        self.to_world(self.options.mapping.to_direction(uv).0)
    }

    /// The sample-space point `ξ` that [`Self::sample`] maps to `direction` (the
    /// exact inverse of sampling, up to float rounding); `None` for the alias
    /// sampler, which has no inverse.
    #[inline]
    pub fn invert(&self, direction: Vec3) -> Option<[f32; 2]> {
        self.planar.invert(self.direction_to_uv(direction))
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
        let (x, row, y) = self.image.brightest_texel();
        let uv = [(x as f32 + 0.5) / w as f32, (row as f32 + 0.5) / h as f32];
        (y * self.options.scale, self.uv_to_direction(uv))
    }

    /// Sampling efficiency `(∫ Y dω)² / ∫ (Y² / p) dω`: 1 when the pdf is exactly
    /// proportional to luminance; the variance of the estimator `Y/p` of `∫ Y dω`
    /// is `(1/efficiency - 1) (∫ Y dω)²` per sample. 0 for a black map or when the
    /// pdf misses light (as MIS compensation does on purpose).
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

    /// `(∫ Y dω, ∫ Y²/p dω)` by quadrature over the image (unscaled; efficiency is
    /// scale-free). Summed in row order, so independent of the thread count.
    ///
    /// Nodes: Gauss-Legendre, 2 points per quarter texel along each axis (each
    /// quarter lies inside one patch of the bilinear reconstruction), so 16 per
    /// texel. The luminance at the nodes is the lookup's reconstruction, computed
    /// row by row: for each node height, the two image rows' luminance is blended
    /// once, then read at the u nodes (luminance is linear in RGB). The pdf is read
    /// at every node for the bilinear density, and once per texel for the others,
    /// which are constant over each texel.
    fn luminance_moments(&self) -> (f64, f64) {
        let (w, h) = (self.image.width(), self.image.height());
        let nodes = efficiency_nodes();
        let (mapping, lookup) = (self.options.mapping, self.options.lookup);
        let periodic = mapping.wrap() == WrapU::Periodic;
        let jacobian_scale = match mapping {
            Mapping::Equirectangular => EQUIRECT_JACOBIAN as f64,
            Mapping::EqualArea => EQUAL_AREA_JACOBIAN as f64,
        };
        let constant_per_texel = !matches!(self.planar, Planar::Bilinear(_));
        // Rows go to each task in runs of neighbours, so a cache of the last three
        // rows' luminance computes each row's about once instead of three times.
        let init = || {
            (
                LuminanceRows::new(w),
                [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]],
            )
        };
        (0..h)
            .into_par_iter()
            .map_init(init, |(cache, [above, here, below]), j| {
                let (mut ey, mut ey2p) = (0.0f64, 0.0f64);
                // The reciprocal of each texel's (constant) pdf, +∞ where it is 0:
                // one division per texel instead of one per node. The densities'
                // grids are the image's, so texel (i, j) is cell (i, j).
                let reciprocal = |p: f32| {
                    if p > 0.0 {
                        1.0 / p as f64
                    } else {
                        f64::INFINITY
                    }
                };
                let inv_texel_pdf: Vec<f64> = match &self.planar {
                    Planar::Inversion(d) => (0..w).map(|i| reciprocal(d.cell_pdf(i, j))).collect(),
                    Planar::Alias(d) => (0..w).map(|i| reciprocal(d.cell_pdf(i, j))).collect(),
                    Planar::Hierarchical(d) => {
                        (0..w).map(|i| reciprocal(d.cell_pdf(i, j))).collect()
                    }
                    Planar::Bilinear(_) => Vec::new(),
                };
                // The neighbouring rows a node above or below the centre blends with
                // (clamped at the top and bottom).
                above.copy_from_slice(cache.row(&self.image, j.saturating_sub(1)).0);
                here.copy_from_slice(cache.row(&self.image, j).0);
                below.copy_from_slice(cache.row(&self.image, (j + 1).min(h - 1)).0);
                let (above, here, below) = (&*above, &*here, &*below);
                let mut blended = vec![0.0f32; w];
                for &tv in &nodes {
                    let v = (j as f64 + tv) / h as f64;
                    let dw = jacobian_scale * mapping.area_factor(v);
                    match lookup {
                        Lookup::Nearest => blended.copy_from_slice(here),
                        Lookup::Bilinear => {
                            let (other, t) = if tv < 0.5 {
                                (above, (0.5 - tv) as f32)
                            } else {
                                (below, (tv - 0.5) as f32)
                            };
                            for ((b, &y0), &y1) in blended.iter_mut().zip(here).zip(other) {
                                *b = y0 + t * (y1 - y0);
                            }
                        }
                    }
                    if constant_per_texel {
                        let (sum_y, sum_y2p) =
                            node_row_moments(&blended, &inv_texel_pdf, lookup, periodic);
                        ey += sum_y * dw;
                        ey2p += sum_y2p * (dw * dw);
                        continue;
                    }
                    for i in 0..w {
                        let left = if i > 0 {
                            blended[i - 1]
                        } else if periodic {
                            blended[w - 1]
                        } else {
                            blended[0]
                        };
                        let right = if i + 1 < w {
                            blended[i + 1]
                        } else if periodic {
                            blended[0]
                        } else {
                            blended[w - 1]
                        };
                        for &tu in &nodes {
                            let y = match lookup {
                                Lookup::Nearest => blended[i],
                                Lookup::Bilinear if tu < 0.5 => {
                                    let t = (0.5 - tu) as f32;
                                    blended[i] + t * (left - blended[i])
                                }
                                Lookup::Bilinear => {
                                    let t = (tu - 0.5) as f32;
                                    blended[i] + t * (right - blended[i])
                                }
                            } as f64;
                            ey += y * dw;
                            if y > 0.0 {
                                let u = ((i as f64 + tu) / w as f64) as f32;
                                let p_uv = self.planar.pdf([u, v as f32]) as f64;
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
            .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1))
    }
}

/// The efficiency quadrature's node positions within a texel, along each axis:
/// two Gauss-Legendre points in each half.
fn efficiency_nodes() -> [f64; 4] {
    let g = 0.5 / 3f64.sqrt();
    [
        0.25 - 0.5 * g,
        0.25 + 0.5 * g,
        0.75 - 0.5 * g,
        0.75 + 0.5 * g,
    ]
}

/// One row of quadrature nodes (at one height) of [`EnvironmentLight::efficiency`]
/// for a density that is constant over each texel: `(Σ_i Σ_nodes y, Σ_i Σ_nodes y² /
/// p_i)` over the texels' four u nodes, from the row's reconstructed luminance
/// `blended` at the texel centres and each texel's `1 / p` (+∞ where p = 0).
///
/// Within a texel, y is constant (nearest) or linear on each half (bilinear), and the
/// four Gauss-Legendre nodes, exact for cubics on each half, sum to closed forms:
/// `Σ y = 4 mean(y)` and `Σ y² = 4 mean(y²)`. The texels between the edges go
/// through a loop without branches, with four partial sums.
fn node_row_moments(
    blended: &[f32],
    inv_pdf: &[f64],
    lookup: Lookup,
    periodic: bool,
) -> (f64, f64) {
    let w = blended.len();
    let texel = |left: f32, centre: f32, right: f32, inv_pdf: f64| {
        let c = centre as f64;
        let (sum_y, sum_y2) = match lookup {
            Lookup::Nearest => (4.0 * c, 4.0 * c * c),
            Lookup::Bilinear => {
                let (l, r) = (0.5 * (left as f64 + c), 0.5 * (c + right as f64));
                // The mean of the square of a line from a to b is (a² + ab + b²) / 3.
                let square = |a: f64, b: f64| a * a + a * b + b * b;
                (l + 2.0 * c + r, (2.0 / 3.0) * (square(l, c) + square(c, r)))
            }
        };
        // A texel with no light adds nothing, even where the pdf is 0.
        (sum_y, if sum_y2 > 0.0 { sum_y2 * inv_pdf } else { 0.0 })
    };
    let (first, last) = (blended[0], blended[w - 1]);
    let (before_first, beyond_last) = if periodic {
        (last, first)
    } else {
        (first, last)
    };
    if w == 1 {
        return texel(before_first, first, beyond_last, inv_pdf[0]);
    }
    let mut partial = [(0.0f64, 0.0f64); 4];
    for (k, (window, &inv)) in blended.windows(3).zip(&inv_pdf[1..]).enumerate() {
        let (y, y2p) = texel(window[0], window[1], window[2], inv);
        let p = &mut partial[k & 3];
        p.0 += y;
        p.1 += y2p;
    }
    let edges = [
        texel(before_first, first, blended[1], inv_pdf[0]),
        texel(blended[w - 2], last, beyond_last, inv_pdf[w - 1]),
    ];
    let sum = |f: fn(&(f64, f64)) -> f64| {
        (f(&partial[0]) + f(&partial[1]))
            + (f(&partial[2]) + f(&partial[3]))
            + (f(&edges[0]) + f(&edges[1]))
    };
    (sum(|p| p.0), sum(|p| p.1))
}

/// Directions per block in the batch queries' vectorized stage
/// ([`EnvironmentLight::to_uv_block`]): enough for several vectors of the widest
/// kind, few enough that the block's arrays stay in registers and L1.
const QUERY_BLOCK: usize = 16;

/// A block of directions' image points (`u`, `v`) and reciprocal Jacobians,
/// lane by lane.
#[derive(Clone, Copy)]
struct UvBlock {
    u: [f32; QUERY_BLOCK],
    v: [f32; QUERY_BLOCK],
    inv_jacobian: [f32; QUERY_BLOCK],
}

/// A block's grid cells (`iu`, `iv`) and reciprocal Jacobians, lane by lane.
struct CellBlock {
    iu: [u32; QUERY_BLOCK],
    iv: [u32; QUERY_BLOCK],
    inv_jacobian: [f32; QUERY_BLOCK],
}

/// The solid-angle density from the planar one at a direction's image point and
/// the reciprocal Jacobian there: 0 at a pole (infinite `1/J`), for a NaN from a
/// degenerate direction, and for a NaN or infinite product.
#[inline(always)]
fn solid_angle(planar_pdf: f32, inv_jacobian: f32) -> f32 {
    let pdf = planar_pdf * inv_jacobian;
    if inv_jacobian < f32::INFINITY && pdf < f32::INFINITY {
        pdf
    } else {
        0.0
    }
}

/// Whether to run the batch kernels compiled for 256-bit vectors (AVX2, present
/// on x86-64 CPUs since 2013-2015). The library is built for the x86-64 baseline,
/// whose vectors (SSE2) hold two f64 where AVX2's hold four; the kernels are
/// `#[inline(always)]` all the way down so that the wider instructions reach
/// them. The results are the same either way: the kernels use no fused
/// multiply-add, only operations that round alike at any vector width.
#[inline]
fn wide_vectors() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Hands matching chunks of `input` and `out` to `f`, in parallel.
///
/// # Panics
/// When the slices differ in length.
fn batch_chunks<I: Sync, O: Send>(input: &[I], out: &mut [O], f: impl Fn(&[I], &mut [O]) + Sync) {
    assert_eq!(
        input.len(),
        out.len(),
        "batch input and output lengths differ"
    );
    const CHUNK: usize = 4096;
    out.par_chunks_mut(CHUNK)
        .zip(input.par_chunks(CHUNK))
        .for_each(|(o, i)| f(i, o));
}

/// The sampler for `options` over `image` (already in the light's mapping),
/// `∫ L dω` of the unscaled image, and whether MIS compensation took effect.
/// `rows_done` hears of every image row once its importance (or, for the bilinear
/// density, its sums) is done: the one pass over the texels.
fn build_sampler(
    image: &EnvImage,
    options: &LightOptions,
    rows_done: &(dyn Fn(usize) + Sync),
) -> (Planar, [f64; 3], bool) {
    let (w, h) = (image.width(), image.height());
    let mapping = options.mapping;
    let init = || LuminanceRows::new(w);
    let fill = |cache: &mut LuminanceRows, j: usize, out: &mut [f32]| {
        let sums = importance_row(image, options.lookup, mapping, cache, j, out);
        rows_done(1);
        sums
    };
    let integral = |row_sums: &[[f64; 3]]| integral_rgb(row_sums, w, options.lookup, mapping);
    match options.density {
        Density::PiecewiseConstant
            if options.sampler == Sampler::Inversion && !options.mis_compensation =>
        {
            // The default path: importance rows go straight into CDFs, never stored.
            let (distribution, row_sums) = Distribution2D::from_rows_with(w, h, init, fill);
            (Planar::Inversion(distribution), integral(&row_sums), false)
        }
        Density::PiecewiseConstant => {
            let mut values = vec![0.0f32; w * h];
            let mut rows: Vec<&mut [f32]> = values.chunks_mut(w).collect();
            let (_, row_sums) = for_each_row(w, init, fill, &mut rows, |row, out| {
                out.copy_from_slice(row);
                0.0
            });
            let subtracted = options
                .mis_compensation
                .then(|| compensate(&values, w, h, mapping))
                .flatten();
            let compensated = subtracted.is_some();
            let f = subtracted.as_deref().unwrap_or(&values);
            let planar = match options.sampler {
                Sampler::Inversion => Planar::Inversion(Distribution2D::new(f, w)),
                Sampler::Alias => Planar::Alias(AliasTable2D::new(f, w)),
                Sampler::Hierarchical => Planar::Hierarchical(Hierarchical2D::new(f, w)),
            };
            (planar, integral(&row_sums), compensated)
        }
        Density::PiecewiseBilinear => {
            let row_sums: Vec<[f64; 3]> = (0..h)
                .into_par_iter()
                .map(|j| rgb_sum(image.row(j)))
                .collect();
            let (mut values, u_nodes, v_nodes) = bilinear_nodes(image, mapping);
            let (mu, mv) = (u_nodes.len(), v_nodes.len());
            let mut compensated = false;
            if options.mis_compensation {
                // Nodes carry Y·J at their own v; subtract Ȳ·J node by node.
                let factors: Vec<f64> = v_nodes.iter().map(|&v| mapping.area_factor(v)).collect();
                if let Some(c) = compensate_rows(&values, mu, mv, &factors) {
                    values = c;
                    compensated = true;
                }
            }
            (
                Planar::Bilinear(BilinearDistribution2D::new(&values, &u_nodes, &v_nodes)),
                integral(&row_sums),
                compensated,
            )
        }
    }
}

/// MIS compensation of a texel-grid importance `f = Y · J_j`: `max(0, f − Ȳ J_j)`
/// with `Ȳ = Σ f / Σ J` (the solid-angle mean of the filtered luminance), or `None`
/// when nothing is above the mean (keep `f`).
fn compensate(f: &[f32], w: usize, h: usize, mapping: Mapping) -> Option<Vec<f32>> {
    let factors: Vec<f64> = (0..h)
        .map(|j| mapping.area_factor((j as f64 + 0.5) / h as f64))
        .collect();
    compensate_rows(f, w, h, &factors)
}

/// [`compensate`] for any grid of `rows` rows of `cols` values whose row `k` was
/// multiplied by `factors[k]`.
fn compensate_rows(f: &[f32], cols: usize, rows: usize, factors: &[f64]) -> Option<Vec<f32>> {
    let total_f: f64 = f.iter().map(|&x| x as f64).sum();
    let total_j: f64 = factors.iter().sum::<f64>() * cols as f64;
    if !(total_f > 0.0 && total_j > 0.0) {
        return None;
    }
    let mean = total_f / total_j;
    let mut out = vec![0.0f32; f.len()];
    let mut any = false;
    for k in 0..rows {
        let threshold = mean * factors[k];
        for (o, &x) in out[k * cols..(k + 1) * cols]
            .iter_mut()
            .zip(&f[k * cols..(k + 1) * cols])
        {
            // Within rounding of the threshold counts as not above it, so a constant
            // map (f = Ȳ J up to f32 rounding) keeps its ordinary density.
            if x as f64 > threshold * (1.0 + 1e-5) {
                *o = (x as f64 - threshold) as f32;
                any = true;
            }
        }
    }
    any.then_some(out)
}

/// Node values and positions of the piecewise-bilinear density: `Y · J` at every
/// texel centre, plus edge nodes at u = 0, 1 and v = 0, 1 that reproduce the
/// lookup's edge behaviour (the seam average for periodic u; a copy of the edge
/// texels for clamped u and for v). Returns `(values, u_nodes, v_nodes)`, values
/// row-major over `(h + 2) × (w + 2)` nodes.
fn bilinear_nodes(image: &EnvImage, mapping: Mapping) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
    let (w, h) = (image.width(), image.height());
    let centres = |n: usize| -> Vec<f64> {
        let mut nodes = Vec::with_capacity(n + 2);
        nodes.push(0.0);
        nodes.extend((0..n).map(|i| (i as f64 + 0.5) / n as f64));
        nodes.push(1.0);
        nodes
    };
    let (u_nodes, v_nodes) = (centres(w), centres(h));
    let mu = w + 2;
    let mut values = vec![0.0f32; mu * (h + 2)];
    values.par_chunks_mut(mu).enumerate().for_each(|(k, out)| {
        // Node row k sits at v_nodes[k]; its radiance is texel row k-1, clamped.
        let j = k.saturating_sub(1).min(h - 1);
        let factor = mapping.area_factor(v_nodes[k]) as f32;
        let row = image.row(j);
        for (o, t) in out[1..=w].iter_mut().zip(row) {
            *o = luminance(*t) * factor;
        }
        let (first, last) = (out[1], out[w]);
        let (left, right) = match mapping.wrap() {
            WrapU::Periodic => {
                let seam = 0.5 * (first + last);
                (seam, seam)
            }
            WrapU::Clamp => (first, last),
        };
        out[0] = left;
        out[w + 1] = right;
    });
    (values, u_nodes, v_nodes)
}

/// Row `j` of the texel-grid importance of DESIGN.md §4 step 1, written to `out`;
/// returns the row's RGB sums (for `∫ L dω`).
///
/// Importance: `f[j][i] = Y(filtered) · J_j`; for bilinear lookups the filter is
/// the `[1 6 1]/8` blur in v (clamped) then u (wrapped or clamped with the
/// mapping), whose three input rows come from a rolling cache so each row's
/// luminance is computed once per block of rows.
fn importance_row(
    image: &EnvImage,
    lookup: Lookup,
    mapping: Mapping,
    cache: &mut LuminanceRows,
    j: usize,
    out: &mut [f32],
) -> [f64; 3] {
    let (w, h) = (image.width(), image.height());
    let factor = mapping.area_factor((j as f64 + 0.5) / h as f64) as f32;
    match lookup {
        Lookup::Nearest => {
            let (luma, _) = cache.row(image, j);
            for (o, &y) in out.iter_mut().zip(luma) {
                *o = y * factor;
            }
        }
        Lookup::Bilinear => {
            // Vertical [1 6 1]/8 (clamped) into the cache's scratch row, then
            // horizontal into `out`: two passes without branches, which vectorize.
            cache.vertical_blur(image, j);
            let vertical = &cache.blurred;
            let (first, last) = (vertical[0], vertical[w - 1]);
            let (before_first, beyond_last) = match mapping.wrap() {
                WrapU::Periodic => (last, first),
                WrapU::Clamp => (first, last),
            };
            let blur =
                |prev: f32, centre: f32, next: f32| (prev + 6.0 * centre + next) * 0.125 * factor;
            if w == 1 {
                out[0] = blur(before_first, first, beyond_last);
            } else {
                for ((o, &centre), (&prev, &next)) in out[1..w - 1]
                    .iter_mut()
                    .zip(&vertical[1..w - 1])
                    .zip(vertical.iter().zip(&vertical[2..]))
                {
                    *o = blur(prev, centre, next);
                }
                out[0] = blur(before_first, first, vertical[1]);
                out[w - 1] = blur(vertical[w - 2], last, beyond_last);
            }
        }
    }
    cache.row(image, j).1
}

/// `∫ L dω` from each row's RGB sums.
///
/// Along u, linear interpolation between texel centres (wrapped, or clamped with
/// constant half-texels at the ends) integrates to the row mean, so
/// `∫ L dω = Σ_j W_j · mean_i L[j][i]` with `W_j` the solid angle of row j's
/// reconstruction weight ([`row_solid_angles`]); exact for either lookup.
fn integral_rgb(row_sums: &[[f64; 3]], w: usize, lookup: Lookup, mapping: Mapping) -> [f64; 3] {
    let h = row_sums.len();
    let weights = match mapping {
        Mapping::Equirectangular => row_solid_angles(h, lookup),
        // Constant Jacobian: every row covers the same solid angle, 4π/h, and the
        // clamped interpolation in v integrates to the mean like the one in u.
        Mapping::EqualArea => vec![4.0 * PI / h as f64; h],
    };
    let mut integral = [0.0f64; 3];
    for (sums, weight) in row_sums.iter().zip(&weights) {
        for k in 0..3 {
            integral[k] += sums[k] / w as f64 * weight;
        }
    }
    integral
}

/// Per-channel sums of a row of texels, in f64. The row is read as a flat run of
/// floats with twelve partial sums (four texels' worth, so that partial `k` holds
/// channel `k mod 3`): the adds are independent, and the loop vectorizes.
fn rgb_sum(row: &[[f32; 3]]) -> [f64; 3] {
    let flat = row.as_flattened();
    let mut partial = [0.0f64; 12];
    let chunks = flat.chunks_exact(12);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (p, &x) in partial.iter_mut().zip(chunk) {
            *p += x as f64;
        }
    }
    for (p, &x) in partial.iter_mut().zip(rest) {
        *p += x as f64;
    }
    std::array::from_fn(|c| (partial[c] + partial[c + 3]) + (partial[c + 6] + partial[c + 9]))
}

/// The luminance of the last three image rows a build task asked for, with each
/// row's RGB sums (f64), so the `[1 6 1]` filter computes every row's luminance once
/// per block of rows instead of three times.
struct LuminanceRows {
    slots: [(usize, Vec<f32>, [f64; 3]); 3],
    /// The vertically filtered luminance of the row being built.
    blurred: Vec<f32>,
}

impl LuminanceRows {
    fn new(w: usize) -> Self {
        Self {
            slots: std::array::from_fn(|_| (usize::MAX, vec![0.0; w], [0.0; 3])),
            blurred: vec![0.0; w],
        }
    }

    /// Fills `blurred` with the `[1 6 1]/8` filter in v of row `j`'s luminance (the
    /// rows above and below clamped to the image).
    fn vertical_blur(&mut self, image: &EnvImage, j: usize) {
        let h = image.height();
        // Each distinct row into the cache first; then all three are borrowed.
        for row in [j.saturating_sub(1), j, (j + 1).min(h - 1)] {
            self.row(image, row);
        }
        let slot = |j: usize| &self.slots.iter().find(|s| s.0 == j).expect("cached").1;
        let (above, centre, below) = (slot(j.saturating_sub(1)), slot(j), slot((j + 1).min(h - 1)));
        for (((b, &a), &c), &d) in self.blurred.iter_mut().zip(above).zip(centre).zip(below) {
            *b = (a + d + 6.0 * c) * 0.125;
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
                let row = image.row(j);
                for (y, rgb) in luma.iter_mut().zip(row) {
                    *y = luminance(*rgb);
                }
                *sums = rgb_sum(row);
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

// ---------------------------------------------------------------------------
// Crate-internal hooks for `crate::product`, kept together here on purpose: the
// product sampler builds its own fine level from this light's importance and maps
// image points to directions exactly as the light does.
// ---------------------------------------------------------------------------

impl EnvironmentLight {
    /// Rows `first_row..first_row + out.len() / w` of the texel-grid importance of
    /// DESIGN.md §4 step 1 (`Y(filtered) · J_j`, never MIS-compensated), `w` values
    /// per row, whatever the light's sampler and density.
    pub(crate) fn importance_rows(&self, first_row: usize, out: &mut [f32]) {
        let w = self.image.width();
        let mut cache = LuminanceRows::new(w);
        for (k, row) in out.chunks_exact_mut(w).enumerate() {
            let (lookup, mapping) = (self.options.lookup, self.options.mapping);
            importance_row(&self.image, lookup, mapping, &mut cache, first_row + k, row);
        }
    }

    /// The light-frame unit direction at image point `uv` and `dω / du dv` there.
    #[inline(always)]
    pub(crate) fn uv_to_local(&self, uv: [f32; 2]) -> (Vec3, f32) {
        self.options.mapping.to_direction(uv)
    }

    /// The image point of a light-frame direction and `du dv / dω` there.
    #[inline(always)]
    pub(crate) fn local_to_uv(&self, d: Vec3) -> ([f32; 2], f32) {
        self.options.mapping.to_uv(d)
    }

    /// A light-frame direction in the world frame.
    #[inline(always)]
    pub(crate) fn local_to_world(&self, d: Vec3) -> Vec3 {
        self.to_world(d)
    }

    /// A world direction in the light frame.
    #[inline(always)]
    pub(crate) fn world_to_local(&self, d: Vec3) -> Vec3 {
        self.to_light(d)
    }

    /// The radiance lookup at image point `uv` (scale applied).
    #[inline(always)]
    pub(crate) fn radiance_at_uv(&self, uv: [f32; 2]) -> [f32; 3] {
        self.lookup(uv)
    }
}

/// [`solid_angle`] for `crate::product`.
#[inline(always)]
pub(crate) fn solid_angle_density(planar_pdf: f32, inv_jacobian: f32) -> f32 {
    solid_angle(planar_pdf, inv_jacobian)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed forms of one efficiency node row against the four Gauss-Legendre
    /// nodes of each texel evaluated one by one, edges and zero pdfs included.
    #[test]
    fn node_row_moments_match_the_nodes() {
        let nodes = efficiency_nodes();
        let mut rng = crate::rng::SplitMix64::new(9);
        for w in [1usize, 2, 3, 4, 7, 12, 13] {
            // Runs of three black texels, the middle one (whose nodes all see black)
            // with pdf 0; and on the two-texel row a lit texel with pdf 0, which
            // makes the sum infinite.
            let blended: Vec<f32> = (0..w)
                .map(|i| {
                    if (3..6).contains(&(i % 6)) {
                        0.0
                    } else {
                        rng.next_f32() * 3.0
                    }
                })
                .collect();
            let inv_pdf: Vec<f64> = (0..w)
                .map(|i| {
                    if i % 6 == 4 || (i == 1 && w == 2) {
                        f64::INFINITY
                    } else {
                        1.0 / (0.1 + rng.next_f32() as f64)
                    }
                })
                .collect();
            for periodic in [true, false] {
                for lookup in [Lookup::Nearest, Lookup::Bilinear] {
                    let at = |i: isize| {
                        let i = if periodic {
                            i.rem_euclid(w as isize)
                        } else {
                            i.clamp(0, w as isize - 1)
                        };
                        blended[i as usize] as f64
                    };
                    let (mut want_y, mut want_y2p) = (0.0f64, 0.0f64);
                    for i in 0..w as isize {
                        for &t in &nodes {
                            let y = match lookup {
                                Lookup::Nearest => at(i),
                                Lookup::Bilinear if t < 0.5 => {
                                    at(i) + (0.5 - t) * (at(i - 1) - at(i))
                                }
                                Lookup::Bilinear => at(i) + (t - 0.5) * (at(i + 1) - at(i)),
                            };
                            want_y += y;
                            if y > 0.0 {
                                want_y2p += y * y * inv_pdf[i as usize];
                            }
                        }
                    }
                    let (y, y2p) = node_row_moments(&blended, &inv_pdf, lookup, periodic);
                    let close = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-12 * b.abs();
                    assert!(
                        close(y, want_y) && close(y2p, want_y2p),
                        "w={w} periodic={periodic} {lookup:?}: ({y}, {y2p}) vs ({want_y}, {want_y2p})"
                    );
                }
            }
        }
    }

    /// The importance rows, filter and RGB sums against a texel-by-texel reading of
    /// DESIGN.md §4 step 1, on small maps where every texel is next to an edge.
    #[test]
    fn importance_rows_match_their_definition() {
        let mut rng = crate::rng::SplitMix64::new(5);
        for (w, h) in [(1, 1), (1, 3), (2, 1), (2, 2), (3, 5), (7, 4), (13, 6)] {
            let texels: Vec<[f32; 3]> = (0..w * h)
                .map(|_| [rng.next_f32() * 4.0, rng.next_f32(), rng.next_f32() * 0.5])
                .collect();
            let image = EnvImage::new(w, h, texels).expect("a valid image");
            for mapping in Mapping::ALL {
                for lookup in [Lookup::Nearest, Lookup::Bilinear] {
                    let mut cache = LuminanceRows::new(w);
                    let mut out = vec![0.0f32; w];
                    for j in 0..h {
                        let sums = importance_row(&image, lookup, mapping, &mut cache, j, &mut out);
                        let factor = mapping.area_factor((j as f64 + 0.5) / h as f64);
                        let y = |i: isize, j: isize| {
                            let j = j.clamp(0, h as isize - 1) as usize;
                            let i = match mapping.wrap() {
                                WrapU::Periodic => i.rem_euclid(w as isize),
                                WrapU::Clamp => i.clamp(0, w as isize - 1),
                            } as usize;
                            luminance(image.texel(i, j)) as f64
                        };
                        for (i, &got) in out.iter().enumerate() {
                            let (i, jj) = (i as isize, j as isize);
                            let want = match lookup {
                                Lookup::Nearest => y(i, jj),
                                Lookup::Bilinear => {
                                    let weights = [1.0, 6.0, 1.0];
                                    let mut sum = 0.0;
                                    for (a, wa) in (-1..=1).zip(weights) {
                                        for (b, wb) in (-1..=1).zip(weights) {
                                            sum += wa * wb * y(i + a, jj + b);
                                        }
                                    }
                                    sum / 64.0
                                }
                            } * factor;
                            let err = (got as f64 - want).abs();
                            assert!(
                                err <= 1e-6 * want.abs().max(1e-30),
                                "{w}x{h} {mapping:?} {lookup:?} ({i}, {j}): {got} vs {want}"
                            );
                        }
                        for (c, &sum) in sums.iter().enumerate() {
                            let want: f64 = image.row(j).iter().map(|t| t[c] as f64).sum();
                            assert!((sum - want).abs() <= 1e-12 * want.abs(), "{sum} vs {want}");
                        }
                    }
                }
            }
        }
    }

    /// The batch kernels as built for the baseline target (two f64 lanes), which
    /// the public batch calls skip on a CPU with AVX2: bit for bit the single
    /// queries too (tests/threads.rs covers the path the CPU picks).
    #[test]
    fn portable_batch_kernels_equal_single_queries() {
        let image = crate::builtin::sky(96, 48);
        let mut dirs: Vec<Vec3> = (0..1_001u64)
            .map(|k| crate::math::uniform_sphere(crate::rng::xi_2d(5, k)))
            .collect();
        dirs.extend([
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, -1e-7, 0.0),
            Vec3::new(f32::NAN, 0.0, 1.0),
        ]);
        for (sampler, lookup, mapping) in [
            (
                Sampler::Inversion,
                Lookup::Bilinear,
                Mapping::Equirectangular,
            ),
            (Sampler::Alias, Lookup::Nearest, Mapping::Equirectangular),
            (Sampler::Hierarchical, Lookup::Bilinear, Mapping::EqualArea),
        ] {
            let options = LightOptions {
                sampler,
                lookup,
                mapping,
                rotation: Rotation::about_z_degrees(20.0),
                ..Default::default()
            };
            let light = EnvironmentLight::new(image.clone(), options).unwrap();
            let mut pdfs = vec![0.0; dirs.len()];
            light.pdf_chunk(&dirs, &mut pdfs);
            let mut radiance = vec![[0.0; 3]; dirs.len()];
            light.radiance_chunk(&dirs, &mut radiance);
            for (k, &d) in dirs.iter().enumerate() {
                assert_eq!(
                    pdfs[k].to_bits(),
                    light.pdf(d).to_bits(),
                    "{sampler:?} {d:?}"
                );
                assert_eq!(
                    radiance[k].map(f32::to_bits),
                    light.radiance(d).map(f32::to_bits),
                    "{sampler:?} {d:?}"
                );
            }
        }
    }

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
