//! Product sampling at a shading point (docs/design.md §6a): directions drawn with
//! density `p(ω | n) ≈ L(ω) f(ω) / ∫ L f`, exactly normalised and with an exact
//! pdf, for a factor `f` that is the clamped cosine or the cosine times a glossy
//! lobe ([`Factor`]), at a cost per shading point of a few light samples.
//!
//! **Levels.**
//! - *fine* (module `fine`): the light's own density over its cells, the same kind as
//!   the light draws (piecewise constant over texels, or piecewise bilinear
//!   between texel centres), cut into `Pw × Ph` rectangular *patches* of cells
//!   (64 × 32 by default); patch `k` holds the share `P_k` of the density, and an
//!   exact alias table over its cells (module `pick`).
//! - *tables* (module `tables`): precomputed once per light, one distribution over the
//!   patches, with its exact alias table, for each node of an octahedral grid of
//!   directions
//!   ([`ProductOptions::normal_grid`] cells a side). For the cosine, the nodes are
//!   normals and patch `k`'s weight in node `a`'s table is
//!   `P_k · max(cos⁺(a·c_k), s · B_k)`, `c_k` the patch's centre direction and `B_k`
//!   an *upper bound* of `cos⁺(n·ω)` over the patch's directions and over every
//!   normal `n` in the grid cells around `a` (exact over a lat-long light's (θ, φ)
//!   boxes, over cones otherwise), `s` a fixed share (`tuning::BOUND_SHARE`).
//!   Glossy factors use tables over mirror directions for a few roughnesses, the
//!   GGX proxy in place of the cosine; rough lobes use the cosine's tables.
//!
//! **Sampling.** [`ProductSampler::at`] maps the normal (or mirror direction) into
//! the grid: in its cell, the four corner nodes get the bilinear weights of its
//! place there. A sample picks one of the four tables by those weights (`ξ₀`),
//! a patch from that table's alias table (`ξ₁`), then a point of the patch from the
//! light's density restricted to it (a cell from the patch's alias table with what
//! is left of `ξ₀`, a point in the cell with the rest of both), mapped
//! to a direction with the light's mapping and rotation. Its density is the
//! mixture of the four tables:
//!
//! ```text
//! p(ω | n) = (Σ_m b_m p_m(k)) · q(u, v | k) / J(ω)
//! ```
//!
//! with `b_m` the bilinear weights, `p_m(k)` patch `k`'s probability in table `m`
//! (the width of its fixed-point CDF, which its alias table gives exactly),
//! `q(u, v | k)` the
//! light's density in `(u, v)` restricted to the patch and renormalised, and
//! `J = dω / du dv`.
//!
//! **The horizon.** Every factor holds `cos⁺(n·ω)`, yet the four tables follow
//! their own nodes' normals and a patch is filled by the light alone, so some
//! draws land just below the surface's horizon. A draw with `-s < n·ω < 0`
//! (`s =` [`HORIZON_BAND`], or less down to [`MIN_HORIZON_BAND`] so that the
//! lowest bright patch wholly above the horizon lies above the band too:
//! [`ShadingPoint::horizon_band`]) is returned as its mirror image in the tangent plane,
//! `Rω = ω − 2(n·ω) n`. The reflection keeps solid angle, so the density of what
//! is returned is
//!
//! ```text
//! p'(ω | n) = p(ω | n) + p(Rω | n)   for 0 ≤ n·ω < s,
//!             0                      for -s < n·ω < 0,
//!             p(ω | n)               otherwise,
//! ```
//!
//! [`ShadingPoint::pdf`] computes exactly that, so it is the density of
//! [`ShadingPoint::sample`]; it integrates to 1 (the mass moved is the mass
//! taken); and it is positive wherever `L · f > 0`, because `p' ≥ p` above the
//! horizon and every normal of a grid cell lies in each corner node's
//! neighbourhood, whose tables bound the factor over it (up to the measure-zero
//! poles of a lat-long map, where it is 0 as for the light). Since `p' ≥ p`
//! wherever `f > 0`, the variance of `L f / p'` is never above that of `L f / p`.

mod bounds;
mod bright;
mod export;
mod factor;
mod fine;
pub(crate) mod patches;
mod pick;
mod tables;
#[cfg(test)]
mod tests;
mod tuning;
mod variant;

pub use export::{BrightPatch, LatLongPatch, ProductTables};
pub use factor::Factor;
pub use tuning::{HORIZON_BAND, MIN_HORIZON_BAND};
#[cfg(feature = "variants")]
pub use variant::ProductVariant;

use crate::distribution::CDF_ONE;
use crate::light::{solid_angle_density, Density, EnvironmentLight, LightSample, Mapping};
use crate::math::{is_positive_finite, Vec3, BELOW_ONE};
use bounds::{Direction, PatchBound};
use bright::{Bright, Target};
use factor::reflect;
use fine::Fine;
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};
use tables::{Lobe, Mix, Tables};
use tuning::{COSINE_FROM_ROUGHNESS, LOBE_GRID_SCALE, LOBE_ROUGHNESS, MAX_BRIGHT, TILT_GAIN};
use variant::Variant;

/// How a [`ProductSampler`] is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProductOptions {
    /// `[Pw, Ph]`: patches across and down the light's cell grid, clamped into it.
    /// `None` for [`ProductOptions::default_patches`] of the light's mapping.
    ///
    /// More patches follow the factor more closely within the light's density and
    /// cost memory in every table (12 bytes per patch per table).
    pub patches: Option<[usize; 2]>,
    /// Cells per side of the octahedral grid of normals of the cosine's
    /// tables (`(n + 1)²` tables). `None` for
    /// [`ProductOptions::DEFAULT_NORMAL_GRID`]. Finer grids bound the cosine over
    /// smaller neighbourhoods: fewer samples where it is small, more memory.
    pub normal_grid: Option<usize>,
    /// The scale of the glossy tables' grids of mirror directions: the tables of
    /// the two widest roughnesses have 1.5 times this many cells a side, those of
    /// the narrowest twice as many. `None` for
    /// [`ProductOptions::DEFAULT_LOBE_GRID`].
    pub lobe_grid: Option<usize>,
    /// An altered sampler, for the verification harness's self-tests and for
    /// measurements, not for rendering: only with the `variants` cargo feature.
    #[cfg(feature = "variants")]
    pub variant: ProductVariant,
}

impl ProductOptions {
    /// The default of [`ProductOptions::normal_grid`].
    pub const DEFAULT_NORMAL_GRID: usize = 16;
    /// The default of [`ProductOptions::lobe_grid`].
    pub const DEFAULT_LOBE_GRID: usize = 8;

    /// The patch grid used when [`ProductOptions::patches`] is `None`: 64 × 32 on
    /// a lat-long map (patches about 5.6° square at the equator), 48 × 48 on the
    /// equal-area square (2304 patches of equal solid angle). Chosen by measurement
    /// (`envlight-verify`'s `product_efficiency` example, BENCHMARKS.md): on the
    /// shared maps and the five test normals, 64 × 32 keeps the product's
    /// efficiency for `Y·cos⁺` at least 0.867 (bilinear density) and 0.947 of the
    /// light's own for `Y` (piecewise constant), within 0.02 of 128 × 64, with
    /// tables a quarter the size.
    pub fn default_patches(mapping: Mapping) -> [usize; 2] {
        match mapping {
            Mapping::Equirectangular => [64, 32],
            Mapping::EqualArea => [48, 48],
        }
    }
}

/// Half the spacing of f32 values just below 1.
const XI_HALF_QUANTUM: f64 = f32::EPSILON as f64 / 4.0;

/// The least probability of a shading point's component (the tables, or a bright
/// patch) with weight: one unit of a fixed-point CDF.
const MIN_SHARE: f64 = 1.0 / CDF_ONE as f64;

/// Samples directions at a shading point in proportion to (a close bound of) the
/// light's radiance times a [`Factor`], with the exact pdf (docs/design.md §6a; the
/// module docs give the scheme and the pdf's formula).
///
/// Guarantees: [`ShadingPoint::pdf`] is the density of [`ShadingPoint::sample`]
/// (`pdf(sample(ξ).direction) == sample(ξ).pdf` to float precision); it integrates
/// to 1; it is positive wherever the light's radiance and the factor are both
/// positive (except at the poles of a lat-long map); within a patch it follows the
/// light's own density, piecewise constant or piecewise bilinear
/// ([`Self::density`]); a black map or an invalid factor samples nothing (`None`,
/// pdf 0), nor does a factor no table mixed for it sees lit.
///
/// Cost: building is `O(w h)` for the fine level (rows in parallel) plus one
/// weight per patch per table (tables in parallel). A shading point
/// ([`Self::at`]) maps one direction into the octahedral grid (an L1 norm and a
/// division), `O(1)`; a sample is a pick among four tables, two alias-table picks
/// (a patch, a cell of it: no search), and the light's mapping and lookup; a pdf
/// reads one cell width and four table entries. Nothing allocates after the build.
///
/// Memory: the fine level's cell widths and alias slots (12 bytes per cell), and
/// 12 bytes per patch per table (an alias slot and a width): `(n + 1)²` tables for
/// the cosine and as many per glossy roughness at the lobe grid's `n`; see
/// [`Self::memory_bytes`].
///
/// ```
/// use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
/// use envlight::product::{Factor, ProductOptions, ProductSampler};
/// use std::sync::Arc;
///
/// let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
/// let sampler = ProductSampler::new(Arc::new(light), ProductOptions::default());
/// let point = sampler.at(&Factor::cosine(Vec3::new(0.0, 0.0, 1.0)));
/// let s = point.sample([0.3, 0.6]).expect("the sky lights an upward surface");
/// assert!((point.pdf(s.direction) - s.pdf).abs() <= 1e-4 * s.pdf);
/// // Well below the surface nothing is sampled, though the ground there is lit.
/// let below = Vec3::new(1.0, 0.0, -1.0).normalized().unwrap();
/// assert!(sampler.light().pdf(below) > 0.0 && point.pdf(below) == 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct ProductSampler {
    light: Arc<EnvironmentLight>,
    fine: Fine,
    /// The patches weighted at each shading point, not in the tables.
    bright: Bright,
    /// The cosine's tables.
    cosine: Tables,
    /// One set per [`LOBE_ROUGHNESS`], built when a glossy factor first needs it.
    lobes: [OnceLock<Tables>; LOBE_ROUGHNESS.len()],
    /// Cells per side of the lobes' grids.
    lobe_grid: usize,
    /// Which sampler this is: the plain one but for tests and measurements.
    variant: Variant,
}

impl ProductSampler {
    /// Builds the fine level and the tables for `light` (in parallel). A black map
    /// gives a sampler that samples nothing.
    pub fn new(light: Arc<EnvironmentLight>, options: ProductOptions) -> Self {
        let patches = options
            .patches
            .unwrap_or_else(|| ProductOptions::default_patches(light.mapping()));
        let fine = Fine::new(&light, patches);
        let normal_grid = options
            .normal_grid
            .unwrap_or(ProductOptions::DEFAULT_NORMAL_GRID);
        let lobe_grid = options
            .lobe_grid
            .unwrap_or(ProductOptions::DEFAULT_LOBE_GRID);
        let variant = Variant::new(&options);
        let bright = Bright::new(&fine, variant.on_the_fly());
        let cosine = Tables::new(
            &fine,
            normal_grid,
            Lobe::Cosine,
            variant.bound(),
            &bright.mask(),
        );
        Self {
            light,
            fine,
            bright,
            cosine,
            lobes: Default::default(),
            lobe_grid,
            variant,
        }
    }

    /// Set `set` of tables: 0 for the cosine's, `1 + i` for roughness
    /// `LOBE_ROUGHNESS[i]`'s (built on first use).
    #[inline]
    fn tables(&self, set: usize) -> &Tables {
        match set.checked_sub(1) {
            None => &self.cosine,
            Some(i) => self.lobes[i].get_or_init(|| {
                let alpha = LOBE_ROUGHNESS[i] as f64;
                let lobe = Lobe::Glossy {
                    alpha2: alpha * alpha,
                };
                let grid = self.lobe_grid * LOBE_GRID_SCALE[i] / 2;
                Tables::new(
                    &self.fine,
                    grid.max(1),
                    lobe,
                    self.bound(),
                    &self.bright.mask(),
                )
            }),
        }
    }

    /// Whether it is the on-the-fly product, a sampler for measurements (the
    /// `variants` feature's `ProductVariant::OnTheFly`): always false without
    /// that feature. envlight-render asks, so that a render measuring it takes
    /// product samples at every vertex rather than leaving rough metals to the
    /// light.
    #[doc(hidden)]
    pub fn is_on_the_fly(&self) -> bool {
        self.variant.on_the_fly()
    }

    /// How its patches' weights are floored.
    #[inline(always)]
    fn bound(&self) -> PatchBound {
        self.variant.bound()
    }

    /// The light sampled.
    pub fn light(&self) -> &EnvironmentLight {
        &self.light
    }

    /// The patch grid `[Pw, Ph]` in use (after clamping to the cell grid).
    pub fn patches(&self) -> [usize; 2] {
        self.fine.patches
    }

    /// The density drawn within a patch: the light's own kind.
    pub fn density(&self) -> Density {
        self.light.options().density
    }

    /// Tables held: the cosine's, and those of the glossy roughnesses built so
    /// far (each is built when a glossy factor first needs it).
    pub fn table_count(&self) -> usize {
        self.built().map(Tables::len).sum()
    }

    /// The sets of tables built so far.
    fn built(&self) -> impl Iterator<Item = &Tables> {
        std::iter::once(&self.cosine).chain(self.lobes.iter().filter_map(OnceLock::get))
    }

    /// True when the light's density is zero everywhere: nothing is ever sampled.
    pub fn is_black(&self) -> bool {
        !self.fine.power.iter().any(|&p| p > 0.0)
    }

    /// Bytes of sampling data held (the fine level and the tables; not the light).
    pub fn memory_bytes(&self) -> usize {
        self.fine.memory_bytes()
            + self.bright.memory_bytes()
            + self.built().map(Tables::memory_bytes).sum::<usize>()
    }

    /// The tables of the cosine factor (`L · cos⁺`) as flat arrays, for a port of
    /// [`ShadingPoint::sample`] and [`ShadingPoint::pdf`] with
    /// [`Factor::Cosine`] (layout: docs/gpu-tables.md, "Product tables").
    pub fn cosine_tables(&self) -> ProductTables {
        let (fine, bright) = (&self.fine, &self.bright);
        let (grid, table_slots, table_widths, node_empty, node_totals) = self.cosine.parts();
        let nodes = fine.nodes();
        let [w, h] = fine.size;
        assert!(bright.len() <= MAX_BRIGHT, "the default bright patches");
        ProductTables {
            density: match nodes {
                None => Density::PiecewiseConstant,
                Some(_) => Density::PiecewiseBilinear,
            },
            image: [w as u32, h as u32],
            cells: [fine.col_patch.len() as u32, fine.row_patch.len() as u32],
            node_values: nodes.map_or_else(Vec::new, |(values, _, _)| values.to_vec()),
            u_nodes: nodes.map_or_else(Vec::new, |(_, u, _)| u.to_vec()),
            v_nodes: nodes.map_or_else(Vec::new, |(_, _, v)| v.to_vec()),
            patches: fine.patches.map(|p| p as u32),
            col_patch: fine.col_patch.clone(),
            row_patch: fine.row_patch.clone(),
            cell_widths: fine.widths.clone(),
            cell_slots: pick::words(&fine.slots),
            spans: fine.span_words(),
            grid: grid as u32,
            table_slots: pick::words(table_slots),
            table_widths: table_widths.to_vec(),
            node_empty: node_empty.to_vec(),
            node_totals: node_totals.to_vec(),
            bright: bright.items().iter().map(export_bright).collect(),
            bright_of_patch: (0..fine.power.len())
                .map(|k| bright.index(k).map_or(u8::MAX, |b| b as u8))
                .collect(),
            bound_share: tuning::BOUND_SHARE,
            box_slack: tuning::BOX_SLACK,
            horizon_band: HORIZON_BAND,
            min_horizon_band: MIN_HORIZON_BAND,
        }
    }

    /// The sampling state at a shading point with factor `factor`: which tables it
    /// mixes and how. `O(1)`, no allocation; [`ShadingPoint::set_factor`] moves it.
    pub fn at(&self, factor: &Factor) -> ShadingPoint<'_> {
        let mut point = self.empty_point();
        point.move_to(factor);
        point
    }

    /// A shading point with no (a zero) factor, which samples nothing.
    fn empty_point(&self) -> ShadingPoint<'_> {
        ShadingPoint {
            sampler: self,
            given: None,
            factor: None,
            set: 0,
            mix: Mix::default(),
            tables_share: 0.0,
            bright: if self.bright.len() <= MAX_BRIGHT {
                Weights::Inline([0.0; MAX_BRIGHT])
            } else {
                Weights::Heap(vec![0.0; self.bright.len()])
            },
            anything: false,
            normal: Vec3::new(0.0, 0.0, 1.0),
            band: HORIZON_BAND,
        }
    }

    /// [`ShadingPoint::sample`] at a shading point used once.
    pub fn sample(&self, factor: &Factor, xi: [f32; 2]) -> Option<LightSample> {
        self.at(factor).sample(xi)
    }

    /// [`ShadingPoint::pdf`] at a shading point used once (see [`Self::sample`]).
    pub fn pdf(&self, factor: &Factor, direction: Vec3) -> f32 {
        self.at(factor).pdf(direction)
    }

    /// One sample per shading point: `out[i] = self.sample(&factors[i], xi[i])`, in
    /// parallel. Each result depends only on its own inputs, so the output is the
    /// same for any thread count.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn sample_batch(
        &self,
        factors: &[Factor],
        xi: &[[f32; 2]],
        out: &mut [Option<LightSample>],
    ) {
        self.per_point(factors, xi, out, |point, &xi| point.sample(xi));
    }

    /// `out[i] = self.pdf(&factors[i], directions[i])`, in parallel, as
    /// [`Self::sample_batch`].
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn pdf_batch(&self, factors: &[Factor], directions: &[Vec3], out: &mut [f32]) {
        self.per_point(factors, directions, out, |point, &d| point.pdf(d));
    }

    /// `out[i] = query(shading point of factors[i], &input[i])` in parallel, each
    /// thread reusing one [`ShadingPoint`].
    fn per_point<I: Sync, O: Send>(
        &self,
        factors: &[Factor],
        input: &[I],
        out: &mut [O],
        query: impl Fn(&ShadingPoint, &I) -> O + Sync,
    ) {
        assert!(
            factors.len() == input.len() && input.len() == out.len(),
            "batch input and output lengths differ"
        );
        out.par_iter_mut()
            .zip(factors.par_iter().zip(input.par_iter()))
            .with_min_len(64)
            .for_each_init(
                || self.empty_point(),
                |point, (o, (factor, x))| {
                    point.set_factor(factor);
                    *o = query(point, x);
                },
            );
    }

    /// The set of tables for a normalised factor and the light-frame direction
    /// (not always of unit length: the grid's map needs none) that indexes them:
    /// the normal for the cosine and rough lobes, the mirror direction for the
    /// others. The normal is taken as `given` (the factor before normalising), so
    /// that finding it in the grid need not wait for the normalisation.
    fn tables_for(&self, factor: &Factor, given: &Factor) -> (usize, Vec3) {
        match *factor {
            Factor::Cosine { .. } => (0, self.light.world_to_local(given.normal())),
            Factor::Glossy { roughness, .. } if roughness >= COSINE_FROM_ROUGHNESS => {
                (0, self.light.world_to_local(given.normal()))
            }
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                // The nearest roughness in log scale: below the geometric mean of
                // two neighbours, the lower.
                let set = 1 + LOBE_ROUGHNESS
                    .windows(2)
                    .take_while(|pair| roughness * roughness >= pair[0] * pair[1])
                    .count();
                let mirror = reflect(outgoing, normal);
                let lookup = if self.variant.glossy_without_tilt() {
                    mirror
                } else {
                    tilted_mirror(mirror, normal, roughness)
                };
                (set, self.light.world_to_local(lookup))
            }
        }
    }
}

/// A bright patch as exported ([`ProductTables::bright`]).
fn export_bright(item: &bright::Item) -> BrightPatch {
    let region = &item.region;
    BrightPatch {
        patch: item.patch,
        power: item.power,
        centre: item.centre,
        cone: (region.cone.axis, region.cone.cos_half, region.cone.sin_half),
        latlong: region.latlong.map(|b| LatLongPatch {
            edge0: b.edge0,
            edge1: b.edge1,
            narrow: b.narrow,
            top: [b.top.0, b.top.1],
            bottom: [b.bottom.0, b.bottom.1],
        }),
    }
}

/// The direction a glossy factor's lobe tables are looked up at: the mirror
/// direction `r` turned towards the normal `n` by the angle `ψ` with
/// `tan ψ = min(2 α² tan θo, TILT_GAIN · α · tan(θo / 2))`, `θo` the angle
/// between them.
///
/// The lobe tables weight a patch by the lobe `D_α(r·ω)` alone; the factor is
/// `cos⁺(n·ω) · D_α(r·ω)`, whose mass lies towards the normal from `r`, the more so
/// the wider the lobe and the lower `r` (a lobe at grazing angles is cut by the
/// horizon and weighted up towards the normal). Turning the lookup carries that
/// first-order effect of the cosine into the choice of tables. For small angles
/// the peak of the factor in the plane of `r` and `n` lies at `ψ ≈ α² tan θo` from
/// `r` (where the lobe's log-slope `-ψ / (α² + ψ² / 4)` meets the cosine's
/// `tan(θo − ψ)`), and the factor's mass lies further: twice that was best for
/// narrow lobes, the second bound for wide lobes at grazing angles, on a constant
/// map over α 0.05–0.4 and `θo` 0–85° (BENCHMARKS.md, "Glossy tables and the
/// cosine under the lobe"). `ψ < θo / 2`, since `TILT_GAIN · α < 1` below
/// `COSINE_FROM_ROUGHNESS`. A deterministic function of the factor, so the pdf
/// stays exact.
///
/// With `t = n − (n·r) r` (length `sin θo`), the lookup is `r + μ t` normalised,
/// `tan ψ = μ sin θo`: `μ = 2 α² / cos θo` or `TILT_GAIN · α / (1 + cos θo)`
/// (`tan(θo / 2) = sin θo / (1 + cos θo)`), whichever is less. No trigonometry.
fn tilted_mirror(mirror: Vec3, normal: Vec3, roughness: f32) -> Vec3 {
    let cos_o = normal.dot(mirror).clamp(0.0, 1.0);
    let (narrow, wide) = (2.0 * roughness * roughness, TILT_GAIN * roughness);
    // min(narrow / cos_o, wide / (1 + cos_o)), without dividing by a zero cos_o.
    let mu = if narrow * (1.0 + cos_o) < wide * cos_o {
        narrow / cos_o
    } else {
        wide / (1.0 + cos_o)
    };
    let side = normal - mirror * cos_o;
    (mirror + side * mu).normalized().unwrap_or(mirror)
}

/// The bright patches' weights at a shading point: on the stack for the default
/// sampler's few, on the heap for the on-the-fly product's every patch.
#[derive(Debug, Clone)]
enum Weights {
    Inline([f64; MAX_BRIGHT]),
    Heap(Vec<f64>),
}

impl AsRef<[f64]> for Weights {
    fn as_ref(&self) -> &[f64] {
        match self {
            Weights::Inline(a) => a,
            Weights::Heap(v) => v,
        }
    }
}

impl AsMut<[f64]> for Weights {
    fn as_mut(&mut self) -> &mut [f64] {
        match self {
            Weights::Inline(a) => a,
            Weights::Heap(v) => v,
        }
    }
}

/// The sampling state at one shading point: the factor and the tables it mixes.
/// Made by [`ProductSampler::at`]; `O(1)`.
#[derive(Debug, Clone)]
pub struct ShadingPoint<'a> {
    sampler: &'a ProductSampler,
    /// The normalised factor, `None` when the factor given was invalid.
    factor: Option<Factor>,
    /// The factor last given, as given (`None` before the first).
    given: Option<Factor>,
    /// Index of the set of tables in use.
    set: usize,
    /// Its tables mixed here.
    mix: Mix,
    /// The probability that a sample comes from the tables (the rest from the
    /// bright patches).
    tables_share: f64,
    /// Each bright patch's probability.
    bright: Weights,
    /// Whether anything can be sampled.
    anything: bool,
    /// The factor's unit normal (world frame), for the horizon's band.
    normal: Vec3,
    /// The horizon's band here (`s`, see [`HORIZON_BAND`]).
    band: f32,
}

impl ShadingPoint<'_> {
    /// Moves this state to a shading point with factor `factor` (`O(1)`; nothing
    /// when the factor is the one given last).
    pub fn set_factor(&mut self, factor: &Factor) {
        // The factor as given, bit for bit: the grid cell is found from the normal
        // as given (see `tables_for`), so only an identical one may skip the work
        // without changing a result (and `-0.0 == 0.0` could).
        if Factor::bits(&Some(*factor)) != Factor::bits(&self.given) {
            self.move_to(factor);
        }
    }

    /// [`Self::set_factor`] without the check for an unchanged factor.
    fn move_to(&mut self, factor: &Factor) {
        self.given = Some(*factor);
        let (given, factor) = (factor, factor.normalized());
        self.factor = factor;
        self.anything = false;
        let Some(f) = &factor else {
            self.mix = Mix::default();
            return;
        };
        self.normal = f.normal();
        let sampler = self.sampler;
        let light = &sampler.light;
        let (set, direction) = sampler.tables_for(f, given);
        self.set = set;
        self.mix = sampler.tables(set).mix(direction);
        let local = |d: Vec3| Direction::new([d.x as f64, d.y as f64, d.z as f64]);
        let normal_light = light.world_to_local(f.normal());
        let normal = local(normal_light);
        // The tables' weights are in units of the factor they follow; a lobe's
        // leave out the cosine, which is about `n·r` over a narrow lobe (kept
        // above α, where a grazing lobe's lit half still sees the surface).
        let (target, scale) = match *f {
            Factor::Glossy {
                outgoing,
                roughness,
                normal: n,
            } if set != 0 => {
                let mirror = local(light.world_to_local(reflect(outgoing, n)));
                let alpha = roughness as f64;
                let target = Target::Glossy {
                    normal,
                    mirror,
                    alpha2: alpha * alpha,
                };
                (target, crate::math::dot3(normal.v, mirror.v).max(alpha))
            }
            _ => (Target::Cosine { normal }, 1.0),
        };
        // A lobe's tables cover every lit patch; the cosine's say whether the
        // surface sees any of them.
        if set != 0 && !self.mix.is_empty() && sampler.cosine.mix(normal_light).is_empty() {
            self.mix = Mix::default();
        }
        let tables = if self.mix.is_empty() {
            0.0
        } else {
            sampler.tables(set).total(&self.mix) * scale
        };
        let bright = sampler
            .bright
            .weights(&target, sampler.bound(), self.bright.as_mut());
        let lowest = sampler.bright.lowest_above(
            &normal,
            &self.bright.as_ref()[..sampler.bright.len()],
            HORIZON_BAND as f64,
        );
        self.band = (lowest as f32).clamp(MIN_HORIZON_BAND, HORIZON_BAND);
        let total = tables + bright;
        if !(total > 0.0 && total.is_finite()) {
            self.mix = Mix::default();
            self.tables_share = 0.0;
            return;
        }
        self.anything = true;
        if bright <= 0.0 {
            // Exactly 1: no ξ may reach for a bright patch.
            self.tables_share = 1.0;
            return;
        }
        // Every share with weight kept at least MIN_SHARE (one unit of a table's
        // fixed-point CDF), so that the f32 pdf stays positive wherever a
        // component has weight, however far apart the components' totals are.
        let floor = |x: f64| if x > 0.0 { x.max(MIN_SHARE) } else { 0.0 };
        let inv_total = 1.0 / total;
        let brights = &mut self.bright.as_mut()[..sampler.bright.len()];
        let mut sum = floor(tables * inv_total);
        for b in brights.iter_mut() {
            *b = floor(*b * inv_total);
            sum += *b;
        }
        let inv_sum = 1.0 / sum;
        self.tables_share = floor(tables * inv_total) * inv_sum;
        for b in brights {
            *b *= inv_sum;
        }
    }

    /// The patch the mixed tables give for `x, y ∈ [0, 1)` (`x` picks one of the
    /// four tables by its weight, `y` a patch from it), and what is left of both.
    #[inline]
    fn sample_tables(&self, x: f64, y: f64) -> (usize, [f64; 2]) {
        // The table: the first whose running sum passes x, found without branches
        // (the weights of a renderer's shading points are not predictable). A
        // table of probability 0 ends where the one before it does, so it is never
        // the first passed; the last with weight is taken if rounding leaves x past
        // them all.
        let p = &self.mix.probability;
        let ends = [p[0], p[0] + p[1], p[0] + p[1] + p[2]];
        let passed = ends.iter().map(|&e| (x >= e) as usize).sum::<usize>();
        let m = passed.min(self.mix.last as usize);
        let below = if m == 0 { 0.0 } else { ends[m - 1] };
        let x = ((x - below) / p[m]).clamp(0.0, BELOW_ONE);
        let tables = self.sampler.tables(self.set);
        let (k, y) = tables.sample(self.mix.node[m], y);
        tables.prefetch(&self.mix, k);
        (k, [x, y])
    }

    /// The probability of patch `k` at this point: a bright patch's own, or the
    /// tables' share times the mixture's.
    #[inline]
    fn patch_probability(&self, k: usize) -> f64 {
        match self.sampler.bright.index(k) {
            Some(b) => self.bright.as_ref()[b],
            None => self.tables_share * self.sampler.tables(self.set).probability(&self.mix, k),
        }
    }

    /// The horizon's band at this point, `s` of the module docs: draws with
    /// `-s < n·ω < 0` are reflected above the horizon. [`HORIZON_BAND`], or less
    /// (not below [`MIN_HORIZON_BAND`]) to keep the lowest bright patch wholly
    /// above the horizon out of it.
    pub fn horizon_band(&self) -> f32 {
        self.band
    }

    /// The normalised factor of this shading point, `None` when the one given was
    /// invalid.
    pub fn factor(&self) -> Option<&Factor> {
        self.factor.as_ref()
    }

    /// The sampler this point belongs to.
    pub fn sampler(&self) -> &ProductSampler {
        self.sampler
    }

    /// True when this point samples something: the factor is valid and some table
    /// it mixes has weight. False means that no patch the factor can see (with
    /// the tables' bounds) is lit: then the pdf is 0 everywhere and so is `L f`.
    pub fn samples_anything(&self) -> bool {
        self.anything
    }

    /// Draws a world direction for `ξ ∈ [0, 1)²` with density [`Self::pdf`]: `ξ₀`
    /// picks one of the four tables by its weight, `ξ₁` a patch from it; in the
    /// patch, what is left of `ξ₁` picks the row and of `ξ₀` the cell, and the
    /// point within it, from the light's density. The radiance is the light's
    /// lookup at the sample's image point, `uv`.
    ///
    /// `None` when nothing can be sampled ([`Self::samples_anything`] is false), or
    /// when the point falls exactly on a pole of a lat-long map (measure zero).
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        if !self.anything {
            return None;
        }
        let sampler = self.sampler;
        // ξ moved to the middle of its f32 quantum (2⁻²⁴ below 1), so that what is
        // left of it after a pick among a power of two of slots is never exactly
        // 0: that would put points on cell edges, where the f32 round trip of the
        // direction may find the neighbouring cell. `max` also maps a NaN ξ to 0.
        #[allow(clippy::manual_clamp)]
        let clamp = |x: f32| (x.max(0.0) as f64 + XI_HALF_QUANTUM).min(BELOW_ONE);
        let x = clamp(xi[0]);
        let (k, [x, y]) = if x < self.tables_share {
            self.sample_tables((x / self.tables_share).min(BELOW_ONE), clamp(xi[1]))
        } else {
            // The bright patch: the first whose running sum (after the tables')
            // passes x, or the last with weight if rounding leaves x past them all.
            let bright = &sampler.bright;
            let (mut b, mut start, mut end) = (0, self.tables_share, self.tables_share);
            let weights = self.bright.as_ref();
            for (c, &p) in weights[..bright.len()].iter().enumerate() {
                if p > 0.0 {
                    (b, start, end) = (c, end, end + p);
                    if x < end {
                        break;
                    }
                }
            }
            let x = ((x - start) / weights[b]).clamp(0.0, BELOW_ONE);
            (bright.patch(b), [x, clamp(xi[1])])
        };
        let light = &sampler.light;
        let (uv, density) = sampler.fine.sample(k, [x, y], |uv| {
            light.image().prefetch(uv[0], uv[1]);
        });

        let (local, jacobian) = light.uv_to_local(uv);
        let direction = light.local_to_world(local);
        // A piecewise-constant density is exact at `uv`, whose cell (and so patch)
        // is the one sampled. A bilinear density changes across the f32 rounding
        // of the direction (by up to ~1e-3 relative next to a bright texel): its
        // pdf is evaluated where the caller will, at the returned direction, as
        // the light does.
        let drawn = |direction| match density {
            Some(q) if jacobian > 0.0 => (self.patch_probability(k) * q) as f32 / jacobian,
            _ => self.drawn_pdf(direction),
        };
        let cosine = self.normal.dot(direction);
        let band = self.band;
        let (direction, uv, pdf) = if cosine >= band || cosine <= -band {
            (direction, uv, drawn(direction))
        } else if cosine >= 0.0 {
            // Within the horizon's band above it: the density holds the mirror
            // image's too.
            let mirror = direction - self.normal * (2.0 * cosine);
            (direction, uv, drawn(direction) + self.mirror_pdf(mirror))
        } else {
            // Within the band below the horizon: reflected above it, with the
            // mirror image's image point and radiance, and the pdf evaluated at
            // the returned direction, as the caller will.
            let mirror = direction - self.normal * (2.0 * cosine);
            let uv = light.local_to_uv(light.world_to_local(mirror)).0;
            (mirror, uv, self.pdf(mirror))
        };
        if !is_positive_finite(pdf) {
            return None;
        }
        Some(LightSample {
            direction,
            pdf,
            radiance: light.radiance_at_uv(uv),
            uv,
        })
    }

    /// The solid-angle density (per steradian) with which [`Self::sample`] produces
    /// the world unit direction `direction`: the mixture probability of its patch
    /// times the light's density restricted to the patch, over `J(ω)`, plus the
    /// same at its mirror image in the tangent plane within the horizon's band
    /// above the horizon ([`Self::horizon_band`]; the module docs give the
    /// formula). 0 just below the horizon (`-s < n·ω < 0`, whose draws are
    /// reflected), where the light's density or every mixed table's weight is 0,
    /// at the poles of a lat-long map, and when nothing can be sampled.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        if !self.anything {
            return 0.0;
        }
        let cosine = self.normal.dot(direction);
        if cosine >= self.band || cosine <= -self.band {
            return self.drawn_pdf(direction);
        }
        if cosine < 0.0 {
            return 0.0;
        }
        let mirror = direction - self.normal * (2.0 * cosine);
        self.drawn_pdf(direction) + self.mirror_pdf(mirror)
    }

    /// [`Self::drawn_pdf`] at the mirror image of a direction within the band
    /// above the horizon (0 for the broken `ProductVariant::FoldWithoutMirror`).
    #[inline]
    fn mirror_pdf(&self, mirror: Vec3) -> f32 {
        if self.sampler.variant.fold_without_mirror() {
            0.0
        } else {
            self.drawn_pdf(mirror)
        }
    }

    /// The density of the draws before the horizon's reflection, `p(ω | n)`.
    #[inline]
    fn drawn_pdf(&self, direction: Vec3) -> f32 {
        let light = &self.sampler.light;
        let (uv, inv_jacobian) = light.local_to_uv(light.world_to_local(direction));
        let planar = match self.sampler.fine.locate(uv) {
            Some((k, density)) => (self.patch_probability(k) * density) as f32,
            None => 0.0,
        };
        solid_angle_density(planar, inv_jacobian)
    }
}
