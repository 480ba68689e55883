//! Patch tables for a fixed grid of directions, precomputed once per light: for
//! each node of an octahedral grid over the sphere of normals (or of mirror
//! directions), a fixed-point CDF over the fine level's patches whose weights are
//! the patch's power times the factor's value over it, floored by a share of an
//! upper bound of the factor over the patch *and* over every direction of the
//! node's neighbourhood.
//!
//! A shading point whose direction `d` falls in grid cell `(i, j)` mixes the four
//! corner nodes' tables with bilinear weights in the grid; every direction of that
//! cell is in each corner's neighbourhood, so each table it mixes gives weight to
//! every patch the factor sees, and the mixture is positive wherever `L f > 0`.
//!
//! **The grid** is the plain octahedral map of the sphere onto `[0, 1]²` (not the
//! light's equal-area one): a direction is found in it with one L1 norm, one
//! division and a fold, no square root or arc tangent, which is most of what a new
//! shading point costs. Its cells are not equal in solid angle (about 7° a side at
//! the six axis directions, 17° at the octants' centres for 16 cells a side); the
//! neighbourhood cones follow each node's own cells.

use super::bounds::{Direction, PatchBound};
use super::factor::lobe_proxy;
use super::fine::Fine;
use super::pick::{self, Slot};
use super::tuning::{BOUNDARY_STEPS, BOUND_SHARE, CONE_SLACK, FLOOR_BUDGET};
use crate::distribution::CDF_ONE;
use crate::mapping::octahedral::{
    octahedral_to_sphere, sphere_to_octahedral, OCTAHEDRAL_LIPSCHITZ,
};
use crate::math::{dot3, norm3, Vec3};
use rayon::prelude::*;
use std::f64::consts::FRAC_PI_2;

/// The factor a set of tables is made for, about each node's direction `a`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) enum Lobe {
    /// `max(0, a·ω)`: `a` is the surface normal.
    Cosine,
    /// The GGX proxy `D_α` about `a`, the mirror direction, with `α² = alpha2`.
    Glossy { alpha2: f64 },
}

/// One table per node of an `n × n`-cell octahedral grid of directions
/// (`(n + 1)²` nodes, on the cells' corners), over a fine level's patches: a
/// fixed-point distribution, picked from by an exact alias table (module `pick`),
/// so that a patch is found with one slot read rather than a search whose
/// dependent loads miss the cache.
#[derive(Debug, Clone)]
pub(super) struct Tables {
    /// Cells per side of the grid.
    n: usize,
    /// Patches per table.
    patches: usize,
    /// Node `m = b (n + 1) + a`'s alias slots at `m P .. (m + 1) P`.
    slots: Vec<Slot>,
    /// Whether node `m`'s table is empty (no patch has weight for it).
    empty: Vec<bool>,
    /// Whether any is (when none is, a shading point need not look).
    any_empty: bool,
    /// Node `m`'s weights summed, `Σ_k P_k g_k` (see `fill_weights`): how much
    /// of the product the table stands for, next to the bright patches'.
    totals: Vec<f64>,
    /// The tables' widths transposed, patch-major: patch `k` of node `m` at
    /// `k (n + 1)² + m` (0 for an empty table). A pdf reads four neighbouring nodes
    /// of one patch, one or two cache lines here instead of four tables.
    widths: Vec<u32>,
}

/// The tables a shading point mixes: four nodes and their probabilities (which sum
/// to 1, or are all 0 when nothing can be sampled).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Mix {
    pub node: [u32; 4],
    pub probability: [f64; 4],
    /// The last of the four with a positive probability (0 when none has).
    pub last: u32,
}

impl Mix {
    /// True when no table is mixed: nothing is sampled.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        // The last table with weight has none only when none has.
        self.probability[self.last as usize] <= 0.0
    }
}

impl Tables {
    /// The tables of `lobe` over `fine`'s patches for an `n`-cell grid (`n ≥ 1`).
    /// Patches marked in `skip` get no weight in any table.
    pub fn new(fine: &Fine, n: usize, lobe: Lobe, bound: PatchBound, skip: &[bool]) -> Self {
        let n = n.max(1);
        let patches = fine.power.len();
        let nodes = (n + 1) * (n + 1);
        let mut slots: Vec<Slot> = pick::large_table(nodes * patches);
        let mut by_node = vec![0u32; nodes * patches];
        let fill =
            |weights: &mut Vec<f32>,
             (node, (slots, widths)): (usize, (&mut [Slot], &mut [u32]))| {
                let (axis, spread) = neighbourhood(n, node % (n + 1), node / (n + 1));
                let total = fill_weights(fine, &axis, spread, lobe, bound, skip, weights);
                // An empty table: widths 0, and slots that pick nothing.
                let empty = pick::fixed_point_widths(weights, widths) == 0.0;
                pick::build(widths, slots);
                (empty, if empty { 0.0 } else { total })
            };
        // Lobe tables are built on first use (`crate::parallel::lazy_build_in_parallel`).
        let parallel = crate::parallel::lazy_build_in_parallel();
        let (empty, totals): (Vec<bool>, Vec<f64>) = if parallel {
            slots
                .par_chunks_mut(patches)
                .zip(by_node.par_chunks_mut(patches))
                .enumerate()
                .map_init(|| vec![0.0f32; patches], fill)
                .unzip()
        } else {
            let mut weights = vec![0.0f32; patches];
            slots
                .chunks_mut(patches)
                .zip(by_node.chunks_mut(patches))
                .enumerate()
                .map(|item| fill(&mut weights, item))
                .unzip()
        };
        let transpose = |(k, row): (usize, &mut [u32])| {
            for (m, w) in row.iter_mut().enumerate() {
                *w = by_node[m * patches + k];
            }
        };
        let mut widths: Vec<u32> = pick::large_table(patches * nodes);
        if parallel {
            widths.par_chunks_mut(nodes).enumerate().for_each(transpose);
        } else {
            widths.chunks_mut(nodes).enumerate().for_each(transpose);
        }
        Self {
            n,
            patches,
            slots,
            any_empty: empty.contains(&true),
            empty,
            totals,
            widths,
        }
    }

    /// The four tables to mix for the light-frame direction `d` (non-zero; its grid
    /// cell found to float precision: a rounding that moves it into a neighbouring
    /// cell leaves it within every corner's neighbourhood, whose cone has a slack),
    /// with the bilinear weights of `d`'s place in its grid cell (those of empty
    /// tables given to the others).
    #[inline]
    pub fn mix(&self, d: Vec3) -> Mix {
        let n = self.n;
        let [s, t] = sphere_to_octahedral(d);
        let (x, y) = (s * n as f32, t * n as f32);
        let top = (n - 1) as f32;
        // SAFETY: `max` and `min` return their non-NaN operand, so the values are
        // in [0, n - 1], where truncation to u32 is defined (and is the floor).
        let (i, j) = unsafe {
            (
                x.max(0.0).min(top).to_int_unchecked::<u32>(),
                y.max(0.0).min(top).to_int_unchecked::<u32>(),
            )
        };
        let (fx, fy) = (
            (x - i as f32).clamp(0.0, 1.0) as f64,
            (y - j as f32).clamp(0.0, 1.0) as f64,
        );
        let first = j as usize * (n + 1) + i as usize;
        let node = [first, first + 1, first + n + 1, first + n + 2];
        let mut probability = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        if self.any_empty {
            let empty = node.map(|k| self.empty[k]);
            for (p, &e) in probability.iter_mut().zip(&empty) {
                if e {
                    *p = 0.0;
                }
            }
            let total: f64 = probability.iter().sum();
            probability = if total > 0.0 {
                probability.map(|p| p / total)
            } else {
                [0.0; 4]
            };
        }
        let last = [1, 2, 3]
            .map(|m| if probability[m] > 0.0 { m as u32 } else { 0 })
            .into_iter()
            .fold(0, u32::max);
        Mix {
            node: node.map(|k| k as u32),
            probability,
            last,
        }
    }

    /// The patch node `node`'s table (which has weight) picks for `x ∈ [0, 1)`, and
    /// `x` rescaled to `[0, 1)` within what gave the patch.
    #[inline]
    pub fn sample(&self, node: u32, x: f64) -> (usize, f64) {
        let first = node as usize * self.patches;
        pick::pick(&self.slots[first..first + self.patches], x)
    }

    /// The probability of patch `k` in `mix`: `Σ_m P_m · p_m(k)`.
    #[inline(always)]
    pub fn probability(&self, mix: &Mix, k: usize) -> f64 {
        // The four nodes are `first`, `first + 1`, `first + n + 1` and
        // `first + n + 2`: one slice, one bounds check.
        let first = k * self.empty.len() + mix.node[0] as usize;
        let w = &self.widths[first..first + self.n + 3];
        let [a, b, c, d] = mix.probability;
        let sum = (a * w[0] as f64 + b * w[1] as f64)
            + (c * w[self.n + 1] as f64 + d * w[self.n + 2] as f64);
        sum * (1.0 / CDF_ONE as f64)
    }

    /// The mixed tables' weight sums `Σ_m P_m W_m`: what the tables stand for at
    /// the shading point, in the units of the factor times the patches' shares.
    #[inline]
    pub fn total(&self, mix: &Mix) -> f64 {
        mix.node
            .iter()
            .zip(&mix.probability)
            .map(|(&m, &p)| p * self.totals[m as usize])
            .sum()
    }

    /// Starts loading what [`Self::probability`] of patch `k` in `mix` reads.
    #[inline(always)]
    pub fn prefetch(&self, mix: &Mix, k: usize) {
        let first = k * self.empty.len() + mix.node[0] as usize;
        crate::math::prefetch_ptr(self.widths.as_ptr().wrapping_add(first));
        crate::math::prefetch_ptr(self.widths.as_ptr().wrapping_add(first + self.n + 2));
    }

    /// Patch `k`'s width in node `node`'s table.
    #[cfg(test)]
    pub fn width(&self, node: u32, k: usize) -> u32 {
        self.widths[k * self.empty.len() + node as usize]
    }

    /// `(n, slots, widths, empty, totals)`, for the export.
    pub fn parts(&self) -> (usize, &[Slot], &[u32], &[bool], &[f64]) {
        (self.n, &self.slots, &self.widths, &self.empty, &self.totals)
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Slot>() * self.slots.len()
            + 4 * self.widths.len()
            + 9 * self.empty.len()
    }

    /// Nodes (tables).
    pub fn len(&self) -> usize {
        self.empty.len()
    }
}

/// Node `(a, b)` of an `n`-cell grid: its unit direction, and the sine and cosine
/// of the half-angle of a cone about it holding every direction of the (up to
/// 2 × 2) grid cells around it. The half-angle is the largest angle from the axis
/// over [`BOUNDARY_STEPS`] points per edge of those cells' square, plus half the
/// longest arc between neighbouring points and [`CONE_SLACK`]: the angle from the
/// axis peaks on the boundary of a region that avoids the antipode (see
/// `bounds::bounding_cone`). Half-angles of `π/2` and more give the whole sphere.
pub(super) fn neighbourhood(n: usize, a: usize, b: usize) -> (Direction, Option<(f64, f64)>) {
    let at = octahedral_to_sphere;
    let cell = 1.0 / n as f64;
    let axis = at(a as f64 * cell, b as f64 * cell);
    let length = norm3(axis);
    let axis = axis.map(|x| x / length);
    let lo = |x: usize| (x as f64 - 1.0).max(0.0) * cell;
    let hi = |x: usize| ((x + 1) as f64 * cell).min(1.0);
    let (u, v) = ([lo(a), hi(a)], [lo(b), hi(b)]);
    let mut farthest = 0.0f64;
    for s in 0..=BOUNDARY_STEPS {
        let t = s as f64 / BOUNDARY_STEPS as f64;
        let (pu, pv) = (u[0] + t * (u[1] - u[0]), v[0] + t * (v[1] - v[0]));
        for (x, y) in [(pu, v[0]), (pu, v[1]), (u[0], pv), (u[1], pv)] {
            let d = at(x, y);
            farthest = farthest.max(dot3(axis, d).clamp(-1.0, 1.0).acos());
        }
    }
    let step = (u[1] - u[0]).max(v[1] - v[0]) / BOUNDARY_STEPS as f64;
    let half = farthest + 0.5 * OCTAHEDRAL_LIPSCHITZ * step + CONE_SLACK;
    let spread = (half < FRAC_PI_2).then(|| half.sin_cos());
    (Direction::new(axis), spread)
}

/// One node's weights over the patches: `P_k · max(f(centre_k), t · BOUND_SHARE · B_k)`
/// (the floor rule, [`PatchBound::weight`]) with `B_k` the upper bound of the factor over patch `k` and over every direction
/// within the cone `spread` (`(sin, cos)` of its half-angle; `None` for the whole
/// sphere) about `axis` (just `f(centre_k)` for the broken `PatchBound::AxisOnly`),
/// as f32 relative to the largest, every positive weight kept positive. Patches
/// marked in `skip` (the bright ones, weighted at each shading point instead) get
/// none. `t ≤ 1` keeps what the floors add within [`FLOOR_BUDGET`] of the weight
/// the factor gives at the node. Returns the weights' sum `Σ P_k g_k`.
fn fill_weights(
    fine: &Fine,
    axis: &Direction,
    spread: Option<(f64, f64)>,
    lobe: Lobe,
    bound: PatchBound,
    skip: &[bool],
    out: &mut [f32],
) -> f64 {
    // (P·value, P·upper) per patch.
    let mut parts = vec![(0.0f64, 0.0f64); out.len()];
    let patches = parts.iter_mut().zip(&fine.power).zip(&fine.regions);
    for ((((part, &power), region), centre), &skip) in patches.zip(&fine.centres).zip(skip) {
        let Some(region) = region else { continue };
        if power <= 0.0 || skip {
            continue;
        }
        // cos of the smallest angle γ between the axis and the patch, then of
        // max(0, γ - β) for the cone's half-angle β.
        let m = region.max_dot(axis).clamp(-1.0, 1.0);
        let reach = match spread {
            None => 1.0,
            Some((sin_b, cos_b)) if m < cos_b => m * cos_b + (1.0 - m * m).sqrt() * sin_b,
            Some(_) => 1.0,
        };
        let centre = dot3(axis.v, *centre);
        let (value, upper) = match lobe {
            Lobe::Cosine => (centre.max(0.0), reach.max(0.0)),
            Lobe::Glossy { alpha2 } => (lobe_proxy(alpha2, centre), lobe_proxy(alpha2, reach)),
        };
        *part = (power * value, power * upper);
    }
    // What the floors add, at full share: `Σ max(0, s B - f)`.
    let valued: f64 = parts.iter().map(|p| p.0).sum();
    let added: f64 = parts
        .iter()
        .map(|&(value, upper)| (BOUND_SHARE * upper - value).max(0.0))
        .sum();
    // For t ≤ 1, max(0, t s B - f) ≤ t max(0, s B - f) (as f ≥ 0): scaling the
    // share by t scales what the floors add by at most t. A node that sees
    // nothing keeps the full share (its table is floors only).
    let t = if valued > 0.0 && added > FLOOR_BUDGET * valued {
        FLOOR_BUDGET * valued / added
    } else {
        1.0
    };
    let weights: Vec<f64> = parts
        .iter()
        .map(|&(value, upper)| bound.weight(value, upper, t))
        .collect();
    let total: f64 = weights.iter().sum();
    let max = weights.iter().fold(0.0f64, |m, &w| m.max(w));
    for (o, &w) in out.iter_mut().zip(&weights) {
        *o = if w > 0.0 {
            ((w / max) as f32).max(f32::from_bits(1))
        } else {
            0.0
        };
    }
    total
}
