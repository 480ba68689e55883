//! The environment light: an HDR image at infinity, importance sampled in
//! proportion to its luminance.
//!
//! Construction (docs/design.md §4), for the piecewise-constant density:
//! 1. importance `f[j][i] = Y(filtered radiance of texel (i, j)) · J_j`, where `J_j`
//!    is the mapping's area factor at the row centre (`sin θ_j` for the
//!    equirectangular map, 1 for the equal-area square). For bilinear lookups the
//!    filter is the exact texel-area average of the bilinear reconstruction, the
//!    separable `[1 6 1]/8` blur (u wraps or clamps with the mapping, v clamps), so
//!    every direction where `radiance()` can be non-zero has `pdf() > 0`. Nearest
//!    lookups need no filter.
//! 2. a 2D sampler over `f` ([`Sampler`]).
//!
//! The piecewise-bilinear density (the default) instead puts `Y · J` at the nodes of the
//! lookup's reconstruction (the texel centres; for [`Lookup::Node`], the rows from
//! pole to pole along v) and samples the bilinear interpolation of those values,
//! so `L / p` is nearly constant.
//!
//! Sampling maps the image point `(u, v)` to a direction and converts the density to
//! solid angle: `p(ω) = p(u, v) / (dω / du dv)`, with `dω / du dv = 2π² sin θ`
//! (equirectangular) or `4π` (equal-area).
//!
//! The light itself, its options and its single queries live here; the
//! submodules hold its construction (`build`), its batch queries (`batch`), the
//! efficiency quadrature (`efficiency`), and the options' names and validation
//! (`options`).

#[cfg(target_arch = "x86_64")]
mod avx512;
mod batch;
mod build;
pub(crate) use build::bilinear_nodes;
pub use build::table_reduction;
mod efficiency;
mod options;
pub(crate) use options::named_option;
pub use options::{NamedOption, OptionError, UnknownName};

use crate::alias::AliasTable2D;
use crate::bilinear::BilinearDistribution2D;
use crate::distribution::{cell_index, Distribution2D, Sample2D};
use crate::hierarchical::Hierarchical2D;
use crate::image::{EnvImage, Lookup};
pub use crate::mapping::Mapping;
use crate::math::{is_positive_finite, Rotation, Vec3};
use build::{importance_row, LuminanceRows};
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
///
/// The default is [`Density::PiecewiseBilinear`]: it follows the bilinear
/// radiance lookup, so its efficiency (BENCHMARKS.md) is 1.000 on every shared
/// map, for a batch sample and pdf that cost 1.0–1.6× the piecewise-constant
/// density's. The alias and hierarchical samplers and a reduced table
/// ([`LightOptions::table_width`]) take the piecewise-constant density only;
/// [`Density::default_for`] picks the density for a sampler and table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Density {
    /// Constant over each texel (the seed's): `f[j][i]` as in the module docs.
    /// The smallest (6 bytes per texel against about 14) and cheapest to sample.
    PiecewiseConstant,
    /// Bilinear between the lookup's nodes (texel centres; along v for
    /// [`Lookup::Node`], its rows from pole to pole), proportional to the bilinear
    /// radiance reconstruction times the mapping's area factor at the nodes (at
    /// the node lookup's pole rows, where that factor is 0, its mean over the half
    /// row next to the pole, so the density covers the radiance). Sampled by
    /// inversion only. The default.
    #[default]
    PiecewiseBilinear,
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

    /// The density a light takes when none is asked for: piecewise-bilinear for
    /// the inversion sampler over a full-size table (`table_width` `None`), else
    /// piecewise-constant, the only density the other samplers and reduced tables
    /// take. The command line and the Python and C interfaces resolve an
    /// unspecified density with this.
    pub fn default_for(sampler: Sampler, table_width: Option<usize>) -> Density {
        if sampler == Sampler::Inversion && table_width.is_none() {
            Density::PiecewiseBilinear
        } else {
            Density::PiecewiseConstant
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
    /// The shape of the density (default: piecewise-bilinear; the alias and
    /// hierarchical samplers and `table_width` need piecewise-constant, see
    /// [`Density::default_for`]).
    pub density: Density,
    /// The parameterization the light samples and looks up in. A lat-long input
    /// with [`Mapping::EqualArea`] is resampled to an equal-area square.
    pub mapping: Mapping,
    /// What the image given to [`EnvironmentLight::new`] is: a lat-long map (2:1 by
    /// convention) or an equal-area square (as PBRT-v4 writes them).
    pub input_mapping: Mapping,
    /// Side of the equal-area square a lat-long input is resampled to; `None` keeps
    /// about the input's texel count ([`crate::equal_area::default_size`]).
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
    /// Width of the sampling table, in cells, when it should be coarser than the
    /// light's image (`None`: one cell per texel). It must divide the image's
    /// width, and the reduction factor `width / table_width` its height; each cell
    /// then pools a factor × factor block of texels by **summing** their filtered
    /// importance, so the table is conservative: every texel the radiance lookup
    /// can see lit keeps a positive density (its cell's, spread evenly over the
    /// cell). Radiance is still looked up at full resolution. Building from a
    /// 16k map costs about the same decoding and importance work, but CDFs and
    /// memory `factor²` times smaller; the price is efficiency, which
    /// [`EnvironmentLight::efficiency`] measures. Piecewise-constant density only.
    pub table_width: Option<usize>,
}

impl Default for LightOptions {
    fn default() -> Self {
        Self {
            scale: 1.0,
            rotation: Rotation::IDENTITY,
            lookup: Lookup::Bilinear,
            sampler: Sampler::Inversion,
            density: Density::PiecewiseBilinear,
            mapping: Mapping::Equirectangular,
            input_mapping: Mapping::Equirectangular,
            equal_area_size: None,
            mis_compensation: false,
            table_width: None,
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

/// How far inside its cell (in image coordinates) a sampled point must lie for
/// its direction to be sure to map back into the cell without the check: 30
/// times the f32 round trip's error (point → direction through `sin_cos_pi`,
/// back through `atan2_pi`: a few 10⁻⁸; `round_trip_stays_within_its_margin`
/// measures it). Points nearer an edge are mapped back and settled.
const ROUND_TRIP_MARGIN: f32 = 2e-6;

/// The 2D sampler over `[0, 1]²` behind a light.
#[derive(Debug, Clone)]
pub(crate) enum Planar {
    Inversion(Distribution2D),
    Alias(AliasTable2D),
    Hierarchical(Hierarchical2D),
    Bilinear(BilinearDistribution2D),
}

impl Planar {
    /// The planar density at `uv` (the light's queries inline each sampler's own).
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

    /// The sampling table's size in cells, `[width, height]`: the image's, unless
    /// [`LightOptions::table_width`] reduced it (the bilinear density's nodes sit
    /// at the texel centres, so its table is the image's too).
    pub fn table_size(&self) -> [usize; 2] {
        match &self.planar {
            Planar::Inversion(d) => [d.nu(), d.nv()],
            Planar::Alias(d) => [d.nu(), d.nv()],
            Planar::Hierarchical(d) => [d.nu(), d.nv()],
            Planar::Bilinear(_) => [self.image.width(), self.image.height()],
        }
    }

    /// Bytes of sampling data (excluding the image).
    pub fn sampling_bytes(&self) -> usize {
        self.planar.memory_bytes()
    }

    /// The 2D sampler behind the light (for [`crate::gpu`]'s export).
    pub(crate) fn planar(&self) -> &Planar {
        &self.planar
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
        scaled(l, self.options.scale)
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
            Planar::Bilinear(d) => self.finish_sample(d.sample_point(xi), true),
        }
    }

    /// The direction, pdf and radiance of the planar sample `s`, each what
    /// [`Self::pdf`] and [`Self::radiance`] give at the returned direction, bit for
    /// bit.
    ///
    /// A continuous density changes across the f32 rounding of the direction (by
    /// up to ~1e-3 relative next to a bright texel), so its pdf is evaluated at
    /// the returned direction. A piecewise-constant density is constant in the
    /// cell, but the f32 round trip point → direction → point (a few 10⁻⁸ of the
    /// image) can carry a point drawn next to the cell's edge into the neighbour,
    /// whose density may differ by any factor: the point is settled in its cell
    /// first ([`Self::settle`]), then the pdf is the cell's density over the
    /// Jacobian read off the direction, and the radiance is looked up where the
    /// direction points.
    #[inline(always)]
    fn finish_sample(&self, s: Sample2D, continuous_density: bool) -> Option<LightSample> {
        if s.pdf == 0.0 {
            return None;
        }
        if continuous_density {
            let (local, jacobian) = self.options.mapping.to_direction(s.uv);
            let direction = self.to_world(local);
            let pdf = self.pdf(direction);
            if !(jacobian > 0.0 && is_positive_finite(pdf)) {
                return None;
            }
            return Some(LightSample {
                direction,
                pdf,
                radiance: self.lookup(s.uv),
                uv: s.uv,
            });
        }
        let direction = self.uv_to_direction(s.uv);
        if self.clear_of_edges(&s) {
            return self.finish_clear(s, direction);
        }
        let (back, inv_jacobian) = self.options.mapping.to_uv(self.to_light(direction));
        self.finish_constant(s, direction, back, inv_jacobian)
    }

    /// Whether the point of `s` lies at least [`ROUND_TRIP_MARGIN`] inside its
    /// cell on every side, where its direction is sure to map back into the cell.
    #[inline(always)]
    fn clear_of_edges(&self, s: &Sample2D) -> bool {
        let [nu, nv] = self.table_size();
        clear_of_cell_edges(s.uv[0], s.cell[0] as u32, nu as f32)
            && clear_of_cell_edges(s.uv[1], s.cell[1] as u32, nv as f32)
    }

    /// The sample of a piecewise-constant density at a point clear of its cell's
    /// edges: the cell's density over the Jacobian read off the direction (what
    /// [`Self::pdf`] computes there, bit for bit, since the direction maps back
    /// into the cell), and the radiance at the drawn point.
    #[inline(always)]
    fn finish_clear(&self, s: Sample2D, direction: Vec3) -> Option<LightSample> {
        let inv_jacobian = self.options.mapping.inv_jacobian(self.to_light(direction));
        let pdf = solid_angle(s.pdf, inv_jacobian);
        is_positive_finite(pdf).then(|| LightSample {
            direction,
            pdf,
            radiance: self.lookup(s.uv),
            uv: s.uv,
        })
    }

    /// The sample of a piecewise-constant density drawn at `s`, given the direction
    /// of `s.uv` and that direction's image point `back` and reciprocal Jacobian
    /// (the batch computes those for a block at once).
    #[inline(always)]
    fn finish_constant(
        &self,
        s: Sample2D,
        direction: Vec3,
        back: [f32; 2],
        inv_jacobian: f32,
    ) -> Option<LightSample> {
        let (uv, direction, back, inv_jacobian, planar) = if self.cell_of(back) == s.cell {
            (s.uv, direction, back, inv_jacobian, s.pdf)
        } else {
            self.settle(s)
        };
        let pdf = solid_angle(planar, inv_jacobian);
        if !is_positive_finite(pdf) {
            return None;
        }
        Some(LightSample {
            direction,
            pdf,
            radiance: self.lookup(back),
            uv,
        })
    }

    /// The table cell holding the image point `uv`, as the densities find it.
    #[inline(always)]
    fn cell_of(&self, uv: [f32; 2]) -> [usize; 2] {
        let [nu, nv] = self.table_size();
        [cell_index(uv[0], nu), cell_index(uv[1], nv)]
    }

    /// Moves the point of `s`, whose direction maps back into a neighbouring cell,
    /// towards its cell's centre (by 0.1% of the way, then four times further each
    /// try, reaching the centre at the sixth) until its direction maps back into
    /// the cell: the density is constant there, and only a band of a few 10⁻⁸ of
    /// the image along the cell's edges is squeezed inward. Returns the point, its
    /// direction, that direction's image point and reciprocal Jacobian, and the
    /// planar density there (the cell's; should the direction still land
    /// elsewhere, as no case in the tests does, the density where it lands, so the
    /// pdf stays that of the returned direction).
    #[cold]
    #[inline(never)]
    fn settle(&self, s: Sample2D) -> ([f32; 2], Vec3, [f32; 2], f32, f32) {
        let [nu, nv] = self.table_size();
        let centre = [
            (s.cell[0] as f32 + 0.5) / nu as f32,
            (s.cell[1] as f32 + 0.5) / nv as f32,
        ];
        let (mut uv, mut step) = (s.uv, 1e-3f32);
        let mut tries = 0;
        loop {
            uv = [
                uv[0] + (centre[0] - uv[0]) * step,
                uv[1] + (centre[1] - uv[1]) * step,
            ];
            step = (4.0 * step).min(1.0);
            tries += 1;
            let direction = self.uv_to_direction(uv);
            let (back, inv_jacobian) = self.options.mapping.to_uv(self.to_light(direction));
            if self.cell_of(back) == s.cell {
                return (uv, direction, back, inv_jacobian, s.pdf);
            }
            if tries == 6 {
                return (uv, direction, back, inv_jacobian, self.planar.pdf(back));
            }
        }
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
}

/// Whether `x` lies at least [`ROUND_TRIP_MARGIN`] inside cell `cell` of an axis
/// of `n` cells (cells fit a u32: sides are at most `MAX_SIDE`).
#[inline(always)]
fn clear_of_cell_edges(x: f32, cell: u32, n: f32) -> bool {
    let (lo, hi) = (cell as f32 / n, (cell + 1) as f32 / n);
    x - lo >= ROUND_TRIP_MARGIN && hi - x >= ROUND_TRIP_MARGIN
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

// ---------------------------------------------------------------------------
// Crate-internal hooks for `crate::product`, kept together here on purpose: the
// product sampler builds its own fine level from this light's importance and maps
// image points to directions exactly as the light does.
// ---------------------------------------------------------------------------

impl EnvironmentLight {
    /// Rows `first_row..first_row + out.len() / w` of the texel-grid importance of
    /// docs/design.md §4 step 1 (`Y(filtered) · J_j`, never MIS-compensated), `w` values
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

/// A looked-up radiance `l` times the light's `scale`, kept finite: a bright
/// texel times a large scale would round past f32::MAX. Every path (single
/// calls, lanes, the AVX-512 kernel) scales through this or its operations.
#[inline(always)]
fn scaled(l: [f32; 3], scale: f32) -> [f32; 3] {
    l.map(|c| (c * scale).min(f32::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sample's pdf is what `pdf` gives at its direction, bit for bit (and its
    /// radiance `radiance`'s, up to the round trip), for every sampler, mapping, rotation and a
    /// reduced table: at random ξ, and at points placed a few ulps inside every
    /// cell's edges and corners, where the f32 round trip point → direction →
    /// point crosses into the neighbour unless the point is settled.
    #[test]
    fn constant_density_samples_are_exact_at_their_directions() {
        // Neighbouring cells differ by up to 50×, so a sample reporting its
        // neighbour's density would show.
        let image = EnvImage::from_fn(64, 32, |x, y| {
            let v = 0.02 + ((x * 7 + y * 13) % 5) as f32 * (1.0 + (x % 3) as f32 * 0.25);
            [v, 0.5 * v, 0.25 * v]
        })
        .unwrap();
        let mut settled_any = 0;
        for sampler in Sampler::ALL {
            for mapping in Mapping::ALL {
                for (rotate, table_width) in [(0.0, None), (37.0, None), (0.0, Some(32))] {
                    let options = LightOptions {
                        sampler,
                        mapping,
                        rotation: Rotation::about_z_degrees(rotate),
                        table_width,
                        density: Density::PiecewiseConstant,
                        ..Default::default()
                    };
                    let Ok(light) = EnvironmentLight::new(image.clone(), options) else {
                        continue;
                    };
                    let name = format!(
                        "{} {} {rotate} {table_width:?}",
                        sampler.name(),
                        mapping.name()
                    );
                    let check = |s: Option<LightSample>| {
                        let Some(s) = s else { return };
                        assert_eq!(
                            light.pdf(s.direction).to_bits(),
                            s.pdf.to_bits(),
                            "{name}: {s:?}"
                        );
                        // The radiance at the drawn point (at the returned direction's
                        // own point for settled ones): the same up to the round trip.
                        let l = light.radiance(s.direction);
                        for c in 0..3 {
                            assert!(
                                (l[c] - s.radiance[c]).abs() <= 2e-3 * l[c].max(1e-3),
                                "{name}: {s:?} vs {l:?}"
                            );
                        }
                    };
                    for k in 0..20_000 {
                        check(light.sample(crate::rng::xi_2d(3, k)));
                    }
                    // Points next to every cell's edges, as a sampler could place them.
                    let [nu, nv] = light.table_size();
                    for iv in 0..nv {
                        for iu in 0..nu {
                            let cell = [iu, iv];
                            let pdf = light.planar.pdf([
                                (iu as f32 + 0.5) / nu as f32,
                                (iv as f32 + 0.5) / nv as f32,
                            ]);
                            let lo = |i: usize, n: usize| (i as f32 / n as f32).next_up().next_up();
                            let hi = |i: usize, n: usize| {
                                ((i + 1) as f32 / n as f32).next_down().next_down()
                            };
                            for uv in [
                                [lo(iu, nu), lo(iv, nv)],
                                [hi(iu, nu), hi(iv, nv)],
                                [lo(iu, nu), hi(iv, nv)],
                                [hi(iu, nu), (iv as f32 + 0.5) / nv as f32],
                            ] {
                                let s = Sample2D { uv, pdf, cell };
                                if light.cell_of(uv) != cell {
                                    continue;
                                }
                                let direction = light.uv_to_direction(uv);
                                let (back, _) =
                                    light.options.mapping.to_uv(light.to_light(direction));
                                settled_any += (light.cell_of(back) != cell) as usize;
                                let sample = light.finish_sample(s, false);
                                check(sample);
                                if let Some(sample) = sample {
                                    assert_eq!(
                                        sample.pdf.to_bits(),
                                        solid_angle(
                                            pdf,
                                            light
                                                .options
                                                .mapping
                                                .to_uv(light.to_light(sample.direction))
                                                .1
                                        )
                                        .to_bits(),
                                        "{name}: the cell's own density"
                                    );
                                }
                            }
                        }
                    }
                }
            }
        }
        // The edges did need settling somewhere (else this test checks nothing).
        assert!(settled_any > 0);
        eprintln!("{settled_any} edge points settled into their cells");
    }

    /// The margin that lets a sample skip mapping its direction back is far above
    /// the f32 round trip's error: point → direction → point, over random points,
    /// points near the poles and the seam, both mappings, with a rotation.
    #[test]
    fn round_trip_stays_within_its_margin() {
        let image = crate::builtin::sky(64, 32);
        let mut worst = 0.0f32;
        for mapping in Mapping::ALL {
            for rotate in [0.0, 123.0] {
                let options = LightOptions {
                    mapping,
                    rotation: Rotation::about_z_degrees(rotate),
                    ..Default::default()
                };
                let light = EnvironmentLight::new(image.clone(), options).unwrap();
                let mut rng = crate::rng::SplitMix64::new(9);
                for k in 0..400_000 {
                    let (a, b) = (rng.next_f32(), rng.next_f32());
                    let uv = match k % 4 {
                        0 => [a, b],
                        1 => [a, b * 1e-3],
                        2 => [a, 1.0 - b * 1e-3],
                        _ => [a * 1e-4, b],
                    };
                    // The image's edges are cell edges: points within the margin of
                    // them (a pole's point, the equal-area square's fold) are always
                    // mapped back and settled.
                    let near_edge = |x: f32| x < ROUND_TRIP_MARGIN || 1.0 - x < ROUND_TRIP_MARGIN;
                    if near_edge(uv[0]) || near_edge(uv[1]) {
                        continue;
                    }
                    let d = light.uv_to_direction(uv);
                    let (back, _) = light.options.mapping.to_uv(light.to_light(d));
                    let mut du = (back[0] - uv[0]).abs();
                    if mapping == Mapping::Equirectangular {
                        du = du.min(1.0 - du); // the seam
                    }
                    worst = worst.max(du).max((back[1] - uv[1]).abs());
                }
            }
        }
        eprintln!("round trip: worst error {worst:e} of the image (margin {ROUND_TRIP_MARGIN:e})");
        assert!(worst * 10.0 <= ROUND_TRIP_MARGIN, "{worst:e}");
    }

    #[test]
    fn constant_map_integrates_to_4pi_and_has_uniform_pdf() {
        let image = EnvImage::from_fn(16, 8, |_, _| [2.0, 2.0, 2.0]).unwrap();
        let options = LightOptions {
            density: Density::PiecewiseConstant,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image, options).unwrap();
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
            density: Density::PiecewiseConstant,
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
}
