//! A visibility cache: sampling of `L · cos⁺` in proportion to what each region
//! of a scene actually sees of the sky (docs/design.md §10).
//!
//! envlight never traces rays. The renderer hands over points with normals (its
//! camera rays' first hits, say) and a batch visibility callback; the cache
//! groups the points into *entries* (a cubic cell of side `r` times a cell of an
//! octahedral grid of normals), and for each entry and each patch of the
//! [`ProductSampler`]'s fine level that the entry's normals can face, it asks the
//! callback for the transmittance of a few rays from the entry's points towards
//! directions drawn from the light within the patch (after a probe of the heavy
//! patches and one in four of the others: an entry that sees nearly all the
//! light it faces stops there); then, in a second pass, for
//! many more rays towards the patches on an *edge* of what the first pass saw (a
//! patch whose rays disagreed, or agreed otherwise than a neighbour's): a window's
//! rim, a roof's eave, the horizon of a wall. Inside a wall or open sky no ray
//! is spent twice. From those it estimates the patch's visibility `V̂_e[k] = (Σ t + a) / (m + a)`, `m` the rays that left
//! their point's upper hemisphere and `a` a small prior count of unoccluded rays,
//! so `V̂ ∈ (0, 1]`: never 0.
//!
//! **The density.** At a shading point `(x, n)` the entry is a pure function of
//! `(x, n)` ([`VisibilityCache::entry_of`]), the same in sampling and in the pdf.
//! With `P_k` the patch's share of the light, `C_e[k]` an upper bound of the
//! cosine over the patch and the entry's normals, and `q(ω | k)` the light's
//! density restricted to patch `k` (per steradian), the learned density is
//!
//! ```text
//! q_e(ω) = π_e(k(ω)) · q(ω | k(ω)),   π_e(k) = W_e[k] / Σ_j W_e[j],   W_e[k] = V̂_e[k] P_k C_e[k]
//! ```
//!
//! (a patch from the entry's distribution, then a direction from the light
//! within it), and the cache samples the exact mixture
//!
//! ```text
//! p(ω | x, n) = α_e q_e(ω) + (1 − α_e) p_prod(ω | n)
//! ```
//!
//! with the product sampler's own density `p_prod` (docs/design.md §6a) and
//! `α_e = α (1 − V̄_e)`, `V̄_e = Σ V̂_e[k] P_k C_e[k] / Σ P_k C_e[k]` the share of
//! the light the entry faces that it sees (`α` is
//! [`VisibilityOptions::learned_share`]): where nothing is in the way the product
//! sampler, whose tables follow each normal, serves alone. Since
//! `p_prod > 0` wherever `L · cos⁺ > 0`, so is `p`: a window the rays missed still
//! gets samples, at least the share `1 − α_e` of the product's. A point with no
//! entry (or an entry that faces no lit patch, `α_e = 0`) samples `p_prod` alone.
//!
//! **Memory.** Each entry holds a distribution over the patches (its weights, a
//! fixed-point CDF and a guide table) and the visibility estimates:
//! [`VisibilityCache::entry_bytes`] each. The automatic radius grows until the
//! entries fit [`VisibilityOptions::memory_budget`].

mod entries;
mod file;
mod learn;

pub use file::{light_hash, read_keys, SavedKeys, FILE_VERSION, MAX_SCENE_KEY};

use crate::distribution::Distribution1D;
use crate::light::{solid_angle_density, LightSample};
use crate::math::{unit_interval, Vec3};
use crate::product::{Factor, ProductSampler, ShadingPoint};
use entries::Grid;
use std::sync::Arc;

/// How a [`VisibilityCache`] is built.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisibilityOptions {
    /// Side of the cubic cells that group points into entries, in world units.
    /// `None`: chosen from the points, so that about
    /// [`Self::target_entries`] entries form.
    pub radius: Option<f32>,
    /// Cells per side of the octahedral grid of normals that splits a cell's
    /// points by orientation (`n²` groups; 4 gives groups about 50° across).
    pub normal_bins: usize,
    /// The number of entries the automatic radius aims at.
    pub target_entries: usize,
    /// Bytes the entries' tables may take; the radius grows until they fit.
    pub memory_budget: usize,
    /// Rays per entry and lit patch it can face, in the first pass.
    pub rays_per_patch: usize,
    /// Rays per entry and patch in the second pass, towards the patches on an
    /// edge of what the first pass saw (a patch whose rays disagreed, or whose
    /// rays disagreed with a neighbour's); 0 for no second pass.
    pub refine_rays: usize,
    /// `α`: the learned distribution's largest share of the mixture, in
    /// `[0, 1)`. An entry's share is `α (1 − V̄_e)`, `V̄_e` the share of the
    /// light it faces that it sees (module docs): the product sampler alone
    /// where nothing is in the way, mostly the learned distribution where most
    /// of the sky is hidden.
    pub learned_share: f32,
    /// `a`: the prior count of unoccluded rays in each visibility estimate
    /// (`> 0`, so no estimate is 0).
    pub prior: f32,
    /// Seed of the rays' directions and origins.
    pub seed: u64,
}

impl Default for VisibilityOptions {
    fn default() -> Self {
        Self {
            radius: None,
            normal_bins: 4,
            target_entries: 512,
            memory_budget: 64 << 20,
            rays_per_patch: 4,
            refine_rays: 16,
            learned_share: 0.9,
            prior: 0.02,
            seed: 0x5eed_5c7e,
        }
    }
}

/// Why a [`VisibilityCache`] could not be built.
#[derive(Debug, thiserror::Error)]
pub enum VisibilityError<E> {
    /// The renderer's callback failed; its error, unchanged.
    #[error("the visibility callback failed: {0}")]
    Trace(E),
    /// The callback returned a transmittance that is NaN or outside `[0, 1]`.
    #[error("the visibility callback returned transmittance {value} for ray {ray} of a batch of {batch}: it must be in [0, 1]")]
    Transmittance {
        /// The ray's index in its batch.
        ray: usize,
        /// Rays in that batch.
        batch: usize,
        /// What was returned.
        value: f32,
    },
    /// A point or normal is not finite, or a normal has zero length.
    #[error("point {index}: {what}")]
    Point {
        /// The point's index.
        index: usize,
        /// What is wrong with it.
        what: String,
    },
    /// An option is out of its range.
    #[error("invalid visibility option: {0}")]
    Option(String),
}

/// One entry: the points of one cell and one bin of normals.
#[derive(Debug, Clone)]
pub(crate) struct Entry {
    /// The mean of its points' normals, unit.
    pub normal: Vec3,
    /// `cos β`, `β` the widest angle between that mean and a point's normal.
    pub cos_spread: f32,
    /// `α_e`: the learned distribution's share (0 when it faces no lit patch).
    pub share: f32,
    /// `V̄_e`: the share of the light it faces that it sees (1 when it faces
    /// no lit patch).
    pub seen: f32,
    /// `V̂_e[k]` per patch (1 for a patch it cannot face, never traced).
    pub visibility: Vec<f32>,
    /// `π_e`: the distribution over patches, from `W_e`.
    pub patches: Distribution1D,
}

/// Sampling of `L · cos⁺` at shading points in proportion to the sky each
/// region of the scene sees (module docs), with an exact pdf, never 0 where
/// `L · cos⁺ > 0`.
///
/// Immutable once built: queries take `&self` from any number of threads.
#[derive(Debug, Clone)]
pub struct VisibilityCache {
    product: Arc<ProductSampler>,
    grid: Grid,
    entries: Vec<Entry>,
    options: VisibilityOptions,
    /// Rays the build asked the callback for.
    rays: u64,
}

/// What a [`VisibilityCache`] holds, for reports.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VisibilitySummary {
    /// Entries.
    pub entries: usize,
    /// Bytes of the entries' tables and the lookup.
    pub bytes: usize,
    /// The cells' side, world units.
    pub radius: f32,
    /// The mean over entries of `V̄_e`, the share of the light an entry faces
    /// that it sees (`Σ_k V̂_e[k] P_k C_e[k] / Σ_k P_k C_e[k]`, module docs); 0
    /// without entries.
    pub mean_visibility: f64,
    /// Rays traced to build it.
    pub rays: u64,
}

impl VisibilityCache {
    /// Builds a cache over `points` with unit-or-not `normals` (same length,
    /// world space), asking `trace(origins, directions, transmittance)` for the
    /// transmittance in `[0, 1]` of batches of rays (1: the ray escapes to the
    /// sky). Rays start exactly at the given points: the callback offsets them as
    /// its own shadow rays need.
    ///
    /// # Errors
    /// [`VisibilityError`]: the callback's own error, a transmittance outside
    /// `[0, 1]`, a non-finite point, a zero normal, or an invalid option.
    pub fn build<E>(
        product: Arc<ProductSampler>,
        points: &[Vec3],
        normals: &[Vec3],
        options: &VisibilityOptions,
        trace: impl FnMut(&[Vec3], &[Vec3], &mut [f32]) -> Result<(), E>,
    ) -> Result<Self, VisibilityError<E>> {
        check_options(options)?;
        if points.len() != normals.len() {
            return Err(VisibilityError::Option(format!(
                "{} points but {} normals",
                points.len(),
                normals.len()
            )));
        }
        let unit_normals = entries::checked_points(points, normals)?;
        let patch_count = product.patches_view().count();
        let entry_bytes = Self::entry_bytes_for(patch_count);
        let (grid, groups) = Grid::group(points, &unit_normals, options, entry_bytes);
        let learned = learn::learn(&product, points, &unit_normals, &groups, options, trace)?;
        Ok(Self {
            product,
            grid,
            entries: learned.entries,
            options: *options,
            rays: learned.rays,
        })
    }

    /// Bytes one entry takes with `patches` patches: its weights, CDF, guide and
    /// visibility (4 bytes each per patch, the guide at most as long).
    pub(crate) fn entry_bytes_for(patches: usize) -> usize {
        16 * patches + std::mem::size_of::<Entry>()
    }

    /// Bytes one entry takes.
    pub fn entry_bytes(&self) -> usize {
        Self::entry_bytes_for(self.product.patches_view().count())
    }

    /// The product sampler it mixes with.
    pub fn product(&self) -> &ProductSampler {
        &self.product
    }

    /// The options it was built with.
    pub fn options(&self) -> &VisibilityOptions {
        &self.options
    }

    /// The entry serving shading point `(position, normal)`: a pure function of
    /// the two (the cell of `position`, the bin of `normal`), `None` where no
    /// point of the build fell (or for a non-finite input).
    #[inline]
    pub fn entry_of(&self, position: Vec3, normal: Vec3) -> Option<usize> {
        self.grid.find(position, normal).map(|e| e as usize)
    }

    /// Entries, bytes, radius and mean visibility.
    pub fn summary(&self) -> VisibilitySummary {
        let mean = if self.entries.is_empty() {
            0.0
        } else {
            self.entries.iter().map(|e| e.seen as f64).sum::<f64>() / self.entries.len() as f64
        };
        VisibilitySummary {
            entries: self.entries.len(),
            bytes: self
                .entries
                .iter()
                .map(|e| {
                    std::mem::size_of::<Entry>()
                        + e.patches.memory_bytes()
                        + std::mem::size_of_val(e.visibility.as_slice())
                })
                .sum::<usize>()
                + self.grid.memory_bytes(),
            radius: self.grid.radius(),
            mean_visibility: mean,
            rays: self.rays,
        }
    }

    /// Entry `e`'s mean normal (unit, world space) and the cosine of the widest
    /// angle between it and the normal of one of its points.
    pub fn entry_normal(&self, e: usize) -> (Vec3, f32) {
        (self.entries[e].normal, self.entries[e].cos_spread)
    }

    /// Entry `e`'s visibility estimates, one per patch of the product sampler
    /// (row-major over its `[Pw, Ph]` grid).
    pub fn visibility(&self, e: usize) -> &[f32] {
        &self.entries[e].visibility
    }

    /// The sampling state at shading point `position` with factor `factor` (its
    /// normal picks the entry). `O(1)`: one hash lookup and the product's
    /// [`ProductSampler::at`].
    pub fn at(&self, position: Vec3, factor: &Factor) -> VisibilityPoint<'_> {
        VisibilityPoint {
            cache: self,
            entry: self.learned_entry(position, factor),
            point: Held::Owned(Box::new(self.product.at(factor))),
        }
    }

    /// [`Self::at`] with the caller's own shading point of this cache's
    /// product sampler, `point`, already set to `factor`
    /// ([`ShadingPoint::set_factor`]): no allocation, for a renderer that keeps
    /// one shading point per thread.
    ///
    /// # Panics
    /// In debug builds, when `point` belongs to another product sampler.
    pub fn at_point<'a>(
        &'a self,
        position: Vec3,
        factor: &Factor,
        point: &'a ShadingPoint<'a>,
    ) -> VisibilityPoint<'a> {
        debug_assert!(
            std::ptr::eq(point.sampler(), &*self.product),
            "the shading point belongs to another product sampler"
        );
        VisibilityPoint {
            cache: self,
            entry: self.learned_entry(position, factor),
            point: Held::Shared(point),
        }
    }

    /// The entry of `(position, factor's normal)` if it samples with a
    /// learned share.
    #[inline]
    fn learned_entry(&self, position: Vec3, factor: &Factor) -> Option<&Entry> {
        self.entry_of(position, factor.normal())
            .map(|e| &self.entries[e])
            .filter(|e| e.share > 0.0)
    }
}

/// The product's shading point of a [`VisibilityPoint`]: its own, or the
/// caller's.
#[derive(Debug, Clone)]
enum Held<'a> {
    Owned(Box<ShadingPoint<'a>>),
    Shared(&'a ShadingPoint<'a>),
}

impl<'a> Held<'a> {
    #[inline]
    fn get(&self) -> &ShadingPoint<'a> {
        match self {
            Held::Owned(p) => p,
            Held::Shared(p) => p,
        }
    }
}

/// The sampling state of a [`VisibilityCache`] at one shading point.
#[derive(Debug, Clone)]
pub struct VisibilityPoint<'a> {
    cache: &'a VisibilityCache,
    entry: Option<&'a Entry>,
    point: Held<'a>,
}

impl VisibilityPoint<'_> {
    /// `α_e` here: the learned distribution's share (0 without an entry).
    pub fn learned_share(&self) -> f32 {
        self.entry.map_or(0.0, |e| e.share)
    }

    /// A direction from the mixture `p(ω | x, n)` (module docs) for
    /// `ξ ∈ [0, 1)²`, with its pdf (per steradian, [`Self::pdf`] at the
    /// returned direction) and radiance. `None` when nothing can be sampled here,
    /// or the draw has density 0 (a null set).
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        let Some(entry) = self.entry else {
            return self.point.get().sample(xi);
        };
        let share = entry.share;
        let x = xi[0].max(0.0);
        let drawn = if x < share {
            let light = self.cache.product.light();
            let pick = entry.patches.sample_discrete(x / share);
            let (direction, uv) = self
                .cache
                .product
                .patches_view()
                .sample(pick.index, [pick.remapped as f64, unit_interval(xi[1])])?;
            LightSample {
                direction,
                pdf: 0.0,
                radiance: light.radiance_at_uv(uv),
                uv,
            }
        } else {
            let rest = ((x - share) / (1.0 - share)).min(crate::distribution::ONE_MINUS_EPSILON);
            self.point.get().sample([rest, xi[1]])?
        };
        let pdf = self.pdf(drawn.direction);
        (pdf > 0.0 && pdf.is_finite()).then_some(LightSample { pdf, ..drawn })
    }

    /// The density of [`Self::sample`] at world unit direction `direction`, per
    /// steradian: `α_e q_e(ω) + (1 − α_e) p_prod(ω | n)`.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        let product = self.point.get().pdf(direction);
        let Some(entry) = self.entry else {
            return product;
        };
        let learned = match self.cache.product.patches_view().locate(direction) {
            Some((k, planar, inv_jacobian)) => {
                let pick = entry.patches.discrete_probability(k) as f64;
                solid_angle_density((pick * planar) as f32, inv_jacobian)
            }
            None => 0.0,
        };
        entry.share * learned + (1.0 - entry.share) * product
    }
}

pub(crate) fn check_options<E>(o: &VisibilityOptions) -> Result<(), VisibilityError<E>> {
    o.validate().map_err(VisibilityError::Option)
}

impl VisibilityOptions {
    /// Checks every option against its range: what [`VisibilityCache::build`]
    /// refuses, for a front end to refuse before it traces anything.
    ///
    /// # Errors
    /// A message naming the option and its range.
    pub fn validate(&self) -> Result<(), String> {
        let o = self;
        if let Some(r) = o.radius {
            if !(r > 0.0 && r.is_finite()) {
                return Err(format!("radius {r}: must be positive and finite"));
            }
        }
        if !(1..=16).contains(&o.normal_bins) {
            return Err(format!("normal_bins {}: must be 1 to 16", o.normal_bins));
        }
        if o.target_entries == 0 {
            return Err("target_entries 0: must be at least 1".into());
        }
        if o.rays_per_patch == 0 || o.rays_per_patch > 4096 {
            return Err(format!(
                "rays_per_patch {}: must be 1 to 4096",
                o.rays_per_patch
            ));
        }
        if o.refine_rays > 4096 {
            return Err(format!("refine_rays {}: must be 0 to 4096", o.refine_rays));
        }
        if !(o.learned_share >= 0.0 && o.learned_share < 1.0) {
            return Err(format!(
                "learned_share {}: must be in [0, 1)",
                o.learned_share
            ));
        }
        if !(o.prior > 0.0 && o.prior.is_finite()) {
            return Err(format!("prior {}: must be positive and finite", o.prior));
        }
        Ok(())
    }
}
