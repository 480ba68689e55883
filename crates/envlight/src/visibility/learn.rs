//! Learning each entry's visibility: rays from the entry's points towards the
//! patches it can face, their transmittance from the renderer's callback, and
//! the estimates and distribution they give (module docs of
//! [`crate::visibility`]).

use super::entries::Groups;
use super::{Entry, VisibilityError, VisibilityOptions};
use crate::distribution::Distribution1D;
use crate::mapping::Mapping;
use crate::math::Vec3;
use crate::product::patches::Patches;
use crate::product::ProductSampler;
use crate::rng::{mix64, SplitMix64};
use rayon::prelude::*;

/// An entry whose probe (one ray in one patch of four) saw at least this share of the
/// light it faces is nearly open: its learned share `α (1 − V̄_e)` stays small,
/// the product sampler serves it, and it gets no more rays. In the open scenes
/// this cuts the build's rays fourfold.
const NEARLY_OPEN: f64 = 0.9;

/// The smallest learned share an entry samples with; below it the entry
/// samples the product sampler alone (in the open scenes most entries: their
/// `V̄_e` is above 0.95).
const MIN_LEARNED_SHARE: f32 = 0.05;

/// Entries whose rays are drawn at once (in parallel) before they are traced.
const ENTRIES_AT_ONCE: usize = 64;

/// Rays per call of the callback: large enough for a renderer to spread a
/// batch over its threads, small enough to keep the build's memory flat.
const BATCH: usize = 1 << 16;

/// The entries learned and the rays traced.
pub(crate) struct Learned {
    pub entries: Vec<Entry>,
    pub rays: u64,
}

/// An entry while its rays are traced.
struct Pending {
    /// Whether its probe found it nearly open ([`NEARLY_OPEN`]).
    open: bool,
    /// `Σ_k P_k C_e[k]` over the patches it can face, and how many those are.
    facing: f64,
    faceable: usize,
    normal: Vec3,
    cos_spread: f32,
    /// `C_e[k]`: 0 for a patch it cannot face (or without power).
    bound: Vec<f32>,
    /// `Σ t` and `m` per patch.
    sum: Vec<f32>,
    count: Vec<u32>,
}

/// Rays waiting for the callback, and whose they are.
struct Batch {
    origins: Vec<Vec3>,
    directions: Vec<Vec3>,
    owners: Vec<(u32, u32)>,
    transmittance: Vec<f32>,
}

pub(crate) fn learn<E>(
    product: &ProductSampler,
    points: &[Vec3],
    normals: &[Vec3],
    groups: &Groups,
    options: &VisibilityOptions,
    mut trace: impl FnMut(&[Vec3], &[Vec3], &mut [f32]) -> Result<(), E>,
) -> Result<Learned, VisibilityError<E>> {
    let patches = product.patches_view();
    let count = patches.count();
    let mut pending: Vec<Pending> = groups
        .par_iter()
        .map(|group| {
            let (normal, cos_spread) = mean_normal(group, normals);
            let bound = cosine_bounds(&patches, normal, cos_spread);
            let facing = (0..count).map(|k| patches.power(k) * bound[k] as f64).sum();
            let faceable = bound.iter().filter(|&&b| b > 0.0).count();
            Pending {
                open: false,
                facing,
                faceable,
                normal,
                cos_spread,
                bound,
                sum: vec![0.0; count],
                count: vec![0; count],
            }
        })
        .collect();

    let mut batch = Batch {
        origins: Vec::with_capacity(BATCH),
        directions: Vec::with_capacity(BATCH),
        owners: Vec::with_capacity(BATCH),
        transmittance: vec![0.0; BATCH],
    };
    let grid = Neighbours::of(product);
    // One pass: for each entry, `rays_each` rays towards each patch its plan
    // names. The rays of a few entries at a time are drawn in parallel (each
    // entry from its own generator, so the rays do not depend on the threads),
    // then traced in batches in entry order.
    let mut pass = |pending: &mut [Pending],
                    seed: u64,
                    plan: &(dyn Fn(&Pending) -> Vec<(usize, usize)> + Sync)| {
        let mut rays = 0u64;
        for first in (0..groups.len()).step_by(ENTRIES_AT_ONCE) {
            let last = (first + ENTRIES_AT_ONCE).min(groups.len());
            let drawn: Vec<Vec<Ray>> = (first..last)
                .into_par_iter()
                .map(|e| {
                    let mut rng = SplitMix64::new(mix64(seed ^ mix64(e as u64)));
                    let group = &groups[e];
                    let mut out = Vec::new();
                    let shared: &[Pending] = pending;
                    for (k, rays_each) in plan(&shared[e]) {
                        for _ in 0..rays_each {
                            if let Some(ray) =
                                draw_ray(group, points, normals, &patches, k, &mut rng)
                            {
                                out.push(ray);
                            }
                        }
                    }
                    out
                })
                .collect();
            for (e, entry_rays) in (first..last).zip(drawn) {
                for ray in entry_rays {
                    batch.origins.push(ray.origin);
                    batch.directions.push(ray.direction);
                    batch.owners.push((e as u32, ray.patch));
                    if batch.origins.len() == BATCH {
                        rays += batch.flush(pending, &mut trace)?;
                    }
                }
            }
        }
        rays += batch.flush(pending, &mut trace)?;
        Ok::<u64, VisibilityError<E>>(rays)
    };
    // A probe: one ray towards every heavy patch each entry can face and one
    // other patch in each 2 × 2 block.
    let probe = |p: &Pending| p.probed(&patches, &grid).map(|(k, _)| (k, 1)).collect();
    let mut rays = pass(&mut pending, options.seed, &probe)?;
    // The rest of the first pass, and the second, only for the entries the
    // probe did not find nearly open: the others' learned share stays small.
    for p in &mut pending {
        p.open = p.probe_seen_share(&patches, &grid) >= NEARLY_OPEN;
    }
    let rest = |p: &Pending| {
        if p.open {
            return Vec::new();
        }
        let m = options.rays_per_patch;
        p.faceable()
            .map(|k| {
                let probed = p.probe_rate(&patches, &grid, k).is_some();
                (k, if probed { m - 1 } else { m })
            })
            .filter(|&(_, n)| n > 0)
            .collect()
    };
    rays += pass(&mut pending, mix64(options.seed ^ 1), &rest)?;
    // The second pass: more rays where the first saw an edge of what the entry
    // sees.
    if options.refine_rays > 0 {
        let edges = |p: &Pending| {
            if p.open {
                Vec::new()
            } else {
                p.edges(&grid)
                    .into_iter()
                    .map(|k| (k, options.refine_rays))
                    .collect()
            }
        };
        rays += pass(&mut pending, mix64(options.seed ^ 2), &edges)?;
    }

    let entries = pending
        .into_par_iter()
        .map(|p| finish(p, &patches, options))
        .collect();
    Ok(Learned { entries, rays })
}

/// A ray of a pass, and the patch it was drawn towards.
#[derive(Clone, Copy)]
struct Ray {
    origin: Vec3,
    direction: Vec3,
    patch: u32,
}

/// A ray from a random point of `group` towards a direction drawn from the
/// light within patch `k`; `None` for a ray into its own point's surface (it
/// says nothing about the sky) or a draw on a pole.
fn draw_ray(
    group: &[u32],
    points: &[Vec3],
    normals: &[Vec3],
    patches: &Patches<'_>,
    k: usize,
    rng: &mut SplitMix64,
) -> Option<Ray> {
    let i = group[(rng.next_u64() % group.len() as u64) as usize] as usize;
    let xi = [rng.next_f64(), rng.next_f64()];
    let (direction, _) = patches.sample(k, xi)?;
    (normals[i].dot(direction) > 0.0).then_some(Ray {
        origin: points[i],
        direction,
        patch: k as u32,
    })
}

/// The fine level's patch grid as neighbours see it: `[Pw, Ph]`, row-major,
/// and whether its columns wrap around (a lat-long map's seam).
struct Neighbours {
    size: [usize; 2],
    wraps: bool,
}

impl Neighbours {
    fn of(product: &ProductSampler) -> Self {
        Self {
            size: product.patches(),
            wraps: product.light().mapping() == Mapping::Equirectangular,
        }
    }

    /// Whether the probe traces patch `k` if it is not heavy: one patch in each
    /// 2 × 2 block.
    fn is_probed(&self, k: usize) -> bool {
        let w = self.size[0];
        (k % w).is_multiple_of(2) && (k / w).is_multiple_of(2)
    }

    /// The patches sharing a side with patch `k`.
    fn around(&self, k: usize) -> impl Iterator<Item = usize> {
        let [w, h] = self.size;
        let (x, y) = (k % w, k / w);
        let left = if x > 0 {
            Some(k - 1)
        } else {
            (self.wraps && w > 1).then(|| k + w - 1)
        };
        let right = if x + 1 < w {
            Some(k + 1)
        } else {
            (self.wraps && w > 1).then(|| k + 1 - w)
        };
        let up = (y > 0).then(|| k - w);
        let down = (y + 1 < h).then(|| k + w);
        [left, right, up, down].into_iter().flatten()
    }
}

impl Pending {
    /// The lit patches the entry can face.
    fn faceable(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.bound.len()).filter(|&k| self.bound[k] > 0.0)
    }

    /// Whether patch `k` carries at least the mean weight `P_k C_e[k]` of the
    /// patches the entry can face: the probe traces every such patch (a sun
    /// must not fall between the probe's patches).
    fn is_heavy(&self, patches: &Patches<'_>, k: usize) -> bool {
        patches.power(k) * self.bound[k] as f64 * self.faceable as f64 >= self.facing
    }

    /// Whether the probe traces patch `k` (which the entry can face), with
    /// the inverse of its inclusion rate: every heavy patch (1), and one other
    /// in each 2 × 2 block of the grid (4).
    fn probe_rate(&self, patches: &Patches<'_>, grid: &Neighbours, k: usize) -> Option<f64> {
        if self.is_heavy(patches, k) {
            Some(1.0)
        } else {
            grid.is_probed(k).then_some(4.0)
        }
    }

    /// The probe's patches, each with its inverse inclusion rate.
    fn probed<'a>(
        &'a self,
        patches: &'a Patches<'_>,
        grid: &'a Neighbours,
    ) -> impl Iterator<Item = (usize, f64)> + 'a {
        self.faceable()
            .filter_map(move |k| self.probe_rate(patches, grid, k).map(|rate| (k, rate)))
    }

    /// The share of the light the entry faces that its probe saw, each
    /// patch's `P_k C_e[k]` weighted by its inverse inclusion rate (so the
    /// sampled patches stand for those skipped); 1 if it traced nothing.
    fn probe_seen_share(&self, patches: &Patches<'_>, grid: &Neighbours) -> f64 {
        let (mut seen, mut facing) = (0.0f64, 0.0f64);
        for (k, rate) in self.probed(patches, grid) {
            if self.count[k] > 0 {
                let w = rate * patches.power(k) * self.bound[k] as f64;
                facing += w;
                seen += w * (self.sum[k] / self.count[k] as f32) as f64;
            }
        }
        if facing > 0.0 {
            seen / facing
        } else {
            1.0
        }
    }

    /// Whether the first pass's rays to patch `k` all escaped (`Some(true)`),
    /// were all blocked (`Some(false)`), or neither, or none was traced (`None`).
    fn outcome(&self, k: usize) -> Option<bool> {
        let (s, m) = (self.sum[k], self.count[k]);
        if m == 0 || self.bound[k] <= 0.0 {
            None
        } else if s == 0.0 {
            Some(false)
        } else if s == m as f32 {
            Some(true)
        } else {
            None
        }
    }

    /// The traced patches on an edge of what the entry sees: a patch whose
    /// rays disagreed, or whose rays agreed but not with those of a traced
    /// neighbour. Inside a wall, or inside open sky, no patch is refined.
    fn edges(&self, grid: &Neighbours) -> Vec<usize> {
        (0..self.sum.len())
            .filter(|&k| self.count[k] > 0 && self.bound[k] > 0.0)
            .filter(|&k| match self.outcome(k) {
                None => true,
                Some(mine) => grid.around(k).any(|j| {
                    self.count[j] > 0 && self.bound[j] > 0.0 && self.outcome(j) != Some(mine)
                }),
            })
            .collect()
    }
}

impl Batch {
    /// Traces the rays waiting and adds their transmittance to their entries.
    fn flush<E>(
        &mut self,
        pending: &mut [Pending],
        trace: &mut impl FnMut(&[Vec3], &[Vec3], &mut [f32]) -> Result<(), E>,
    ) -> Result<u64, VisibilityError<E>> {
        let n = self.origins.len();
        if n == 0 {
            return Ok(0);
        }
        let out = &mut self.transmittance[..n];
        out.fill(f32::NAN);
        trace(&self.origins, &self.directions, out).map_err(VisibilityError::Trace)?;
        for (ray, (&t, &(e, k))) in out.iter().zip(&self.owners).enumerate() {
            if !(0.0..=1.0).contains(&t) {
                return Err(VisibilityError::Transmittance {
                    ray,
                    batch: n,
                    value: t,
                });
            }
            let p = &mut pending[e as usize];
            p.sum[k as usize] += t;
            p.count[k as usize] += 1;
        }
        self.origins.clear();
        self.directions.clear();
        self.owners.clear();
        Ok(n as u64)
    }
}

/// The entry of `p`, its estimates `V̂ = (Σ t + a) / (m + a)`.
fn finish(p: Pending, patches: &Patches<'_>, options: &VisibilityOptions) -> Entry {
    let a = options.prior;
    let visibility = p
        .sum
        .iter()
        .zip(&p.count)
        .map(|(&s, &m)| (s + a) / (m as f32 + a))
        .collect();
    entry(
        p.normal,
        p.cos_spread,
        &p.bound,
        visibility,
        patches,
        options,
    )
}

/// The entry with normal `normal`, spread `cos_spread`, cosine bounds `bound`
/// and estimates `visibility`: `W = V̂ P_k C_e[k]`, and the learned share where
/// any weight is positive. The one place an entry's distribution is made, for a
/// build and for a cache read back from a file alike.
pub(crate) fn entry(
    normal: Vec3,
    cos_spread: f32,
    bound: &[f32],
    visibility: Vec<f32>,
    patches: &Patches<'_>,
    options: &VisibilityOptions,
) -> Entry {
    let (mut seen, mut facing) = (0.0f64, 0.0f64);
    let weights: Vec<f32> = (0..visibility.len())
        .map(|k| {
            let unoccluded = patches.power(k) * bound[k] as f64;
            facing += unoccluded;
            seen += visibility[k] as f64 * unoccluded;
            (visibility[k] as f64 * unoccluded) as f32
        })
        .collect();
    let distribution = Distribution1D::new(&weights);
    // `V̄`, the share of the light the entry faces that it sees: where it sees
    // all of it the product sampler (whose tables follow each normal closely)
    // is the better sampler; the less it sees, the more the learned one wins.
    let seen_share = if facing > 0.0 { seen / facing } else { 1.0 };
    let share = if distribution.integral() > 0.0 && facing > 0.0 {
        (options.learned_share as f64 * (1.0 - seen_share)).clamp(0.0, 1.0) as f32
    } else {
        0.0
    };
    // Below `MIN_LEARNED_SHARE` the learned part would move the density by
    // less than that share anywhere: not worth its pdf at every sample.
    let share = if share < MIN_LEARNED_SHARE {
        0.0
    } else {
        share
    };
    Entry {
        normal,
        cos_spread,
        share,
        seen: seen_share as f32,
        visibility,
        patches: distribution,
    }
}

/// `C_e[k]` for every patch: an upper bound of the cosine between a normal
/// within the spread of `normal` and a direction of the patch (0 for a patch
/// without power or wholly behind every such normal).
pub(crate) fn cosine_bounds(patches: &Patches<'_>, normal: Vec3, cos_spread: f32) -> Vec<f32> {
    (0..patches.count())
        .map(|k| {
            if patches.power(k) > 0.0 {
                patches
                    .max_dot(k, normal)
                    .map_or(0.0, |m| cosine_bound(m, cos_spread as f64) as f32)
            } else {
                0.0
            }
        })
        .collect()
}

/// The unit mean of the group's normals and the cosine of the widest angle
/// between it and one of them.
fn mean_normal(group: &[u32], normals: &[Vec3]) -> (Vec3, f32) {
    let sum = group
        .iter()
        .fold(Vec3::new(0.0, 0.0, 0.0), |s, &i| s + normals[i as usize]);
    let mean = sum.normalized().unwrap_or(normals[group[0] as usize]);
    let spread = group
        .iter()
        .map(|&i| normals[i as usize].dot(mean))
        .fold(1.0f32, f32::min);
    (mean, spread.clamp(-1.0, 1.0))
}

/// An upper bound of `n·ω` over normals `n` within angle `β` of the mean and
/// directions `ω` at least angle `γ` from it, given `cos γ ≥ m` (the patch's
/// bound) and `cos β`: `cos(max(0, γ - β))`, 0 when that is not positive.
fn cosine_bound(m: f64, cos_spread: f64) -> f64 {
    if m >= cos_spread {
        return 1.0;
    }
    let (m, c) = (m.clamp(-1.0, 1.0), cos_spread);
    let (sin_gamma, sin_beta) = ((1.0 - m * m).max(0.0).sqrt(), (1.0 - c * c).max(0.0).sqrt());
    (m * c + sin_gamma * sin_beta).max(0.0)
}
