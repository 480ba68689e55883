//! Patch tables for a fixed grid of directions, precomputed once per light: for
//! each node of an equal-area octahedral grid over the sphere of normals (or of
//! mirror directions), a fixed-point CDF over the fine level's patches whose
//! weights are the patch's power times the factor's value over it, floored by a
//! share of an upper bound of the factor over the patch *and* over every direction
//! of the node's neighbourhood.
//!
//! A shading point whose direction `d` falls in grid cell `(i, j)` mixes the four
//! corner nodes' tables with bilinear weights in the grid; every direction of that
//! cell is in each corner's neighbourhood, so each table it mixes gives weight to
//! every patch the factor sees, and the mixture is positive wherever `L f > 0`.

use super::bounds::{dot, norm, Direction, BOUNDARY_STEPS, CONE_SLACK, EQUAL_AREA_LIPSCHITZ};
use super::factor::lobe_proxy;
use super::fine::Fine;
use super::PatchBound;
use crate::distribution::{Distribution1D, CDF_ONE};
use crate::equal_area::{square_to_sphere, unit_sphere_to_square_fast};
use crate::math::Vec3;
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

/// How much of a patch's bound its weight keeps at least: the weight is
/// `P · max(f(a, c), BOUND_SHARE · B)`, `c` the patch's centre of light and `B` the
/// bound over the patch and the node's neighbourhood. 1 would weight by the bound
/// alone, which spends samples on bright patches just past the surface's horizon
/// (a low sun: efficiency 0.31 for a surface facing down under sunrise.exr with a
/// share of 0.25); a small share follows the factor at the node and keeps just
/// enough weight elsewhere for the normals between nodes. Measured over the shared
/// maps, the five test normals and 24 random ones (BENCHMARKS.md): 0.01 and 0.03
/// give the same worst case over random normals, 0.01 the better one at the nodes.
pub(super) const BOUND_SHARE: f64 = 0.01;

/// One table per node of an `n × n`-cell equal-area octahedral grid of directions
/// (`(n + 1)²` nodes, on the cells' corners), over a fine level's patches: a
/// fixed-point CDF with a guide table ([`Distribution1D`]), so that a patch is
/// found in O(1) expected steps rather than by a binary search whose dependent
/// loads miss the cache.
#[derive(Debug, Clone)]
pub(super) struct Tables {
    /// Cells per side of the grid.
    n: usize,
    /// Node `b (n + 1) + a`'s table, `None` when it has no weight at all.
    table: Vec<Option<Distribution1D>>,
    /// Whether node `m`'s table is empty (a compact copy of `table[m].is_none()`,
    /// which every shading point reads four of).
    empty: Vec<bool>,
    /// The tables' CDF widths transposed, patch-major: patch `k` of node `m` at
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
}

impl Mix {
    /// True when no table is mixed: nothing is sampled.
    pub fn is_empty(&self) -> bool {
        self.probability == [0.0; 4]
    }
}

impl Tables {
    /// The tables of `lobe` over `fine`'s patches for an `n`-cell grid (`n ≥ 1`).
    pub fn new(fine: &Fine, n: usize, lobe: Lobe, bound: PatchBound) -> Self {
        let n = n.max(1);
        let patches = fine.power.len();
        let table = (0..(n + 1) * (n + 1))
            .into_par_iter()
            .map_init(
                || vec![0.0f32; patches],
                |weights, node| {
                    let (axis, spread) = neighbourhood(n, node % (n + 1), node / (n + 1));
                    fill_weights(fine, &axis, spread, lobe, bound, weights);
                    let any = weights.iter().any(|&w| w > 0.0);
                    any.then(|| Distribution1D::new(weights))
                },
            )
            .collect::<Vec<Option<Distribution1D>>>();
        let nodes = table.len();
        let mut widths = vec![0u32; patches * nodes];
        widths
            .par_chunks_mut(nodes)
            .enumerate()
            .for_each(|(k, row)| {
                for (w, t) in row.iter_mut().zip(&table) {
                    if let Some(d) = t {
                        *w = d.cdf()[k + 1] - d.cdf()[k];
                    }
                }
            });
        let empty = table.iter().map(Option::is_none).collect();
        Self {
            n,
            table,
            empty,
            widths,
        }
    }

    /// The four tables to mix for the unit light-frame direction `d` (its grid cell
    /// found to float precision: a rounding that moves it into a neighbouring cell
    /// leaves it within every corner's neighbourhood, whose cone has a slack), with the
    /// bilinear weights of `d`'s place in its grid cell (those of empty tables
    /// given to the others).
    #[inline]
    pub fn mix(&self, d: Vec3) -> Mix {
        let n = self.n;
        let [s, t] = unit_sphere_to_square_fast(d);
        let (x, y) = (s as f64 * n as f64, t as f64 * n as f64);
        let (i, j) = ((x as usize).min(n - 1), (y as usize).min(n - 1));
        let (fx, fy) = (
            (x - i as f64).clamp(0.0, 1.0),
            (y - j as f64).clamp(0.0, 1.0),
        );
        let first = j * (n + 1) + i;
        let node = [first, first + 1, first + n + 1, first + n + 2];
        let mut probability = [
            (1.0 - fx) * (1.0 - fy),
            fx * (1.0 - fy),
            (1.0 - fx) * fy,
            fx * fy,
        ];
        for (p, &k) in probability.iter_mut().zip(&node) {
            if self.empty[k] {
                *p = 0.0;
            }
        }
        let total: f64 = probability.iter().sum();
        if total > 0.0 {
            for p in &mut probability {
                *p /= total;
            }
        } else {
            probability = [0.0; 4];
        }
        Mix {
            node: node.map(|k| k as u32),
            probability,
        }
    }

    /// The patch node `node`'s table (which has weight) gives `ξ`, and `ξ`
    /// rescaled within the patch's share.
    #[inline]
    pub fn sample(&self, node: u32, xi: f32) -> (usize, f32) {
        match &self.table[node as usize] {
            Some(d) => {
                let s = d.sample_discrete(xi);
                (s.index, s.remapped)
            }
            None => unreachable!("a mix never picks an empty table"),
        }
    }

    /// The probability of patch `k` in `mix`: `Σ_m P_m · p_m(k)`.
    #[inline]
    pub fn probability(&self, mix: &Mix, k: usize) -> f64 {
        let widths = &self.widths[k * self.table.len()..(k + 1) * self.table.len()];
        let mut sum = 0.0;
        for (&node, &p) in mix.node.iter().zip(&mix.probability) {
            sum += p * widths[node as usize] as f64;
        }
        sum * (1.0 / CDF_ONE as f64)
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        let tables: usize = self
            .table
            .iter()
            .flatten()
            .map(Distribution1D::memory_bytes)
            .sum();
        tables + std::mem::size_of::<Option<Distribution1D>>() * self.table.len()
    }

    /// Nodes (tables).
    pub fn len(&self) -> usize {
        self.table.len()
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
    let at = |u: f64, v: f64| {
        let d = square_to_sphere(u as f32, v as f32);
        [d.x as f64, d.y as f64, d.z as f64]
    };
    let cell = 1.0 / n as f64;
    let axis = at(a as f64 * cell, b as f64 * cell);
    let length = norm(axis);
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
            farthest = farthest.max(dot(axis, d).clamp(-1.0, 1.0).acos());
        }
    }
    let step = (u[1] - u[0]).max(v[1] - v[0]) / BOUNDARY_STEPS as f64;
    let half = farthest + 0.5 * EQUAL_AREA_LIPSCHITZ * step + CONE_SLACK;
    let spread = (half < FRAC_PI_2).then(|| half.sin_cos());
    (Direction::new(axis), spread)
}

/// One node's weights over the patches: `P_k · max(f(centre_k), BOUND_SHARE · B_k)`
/// with `B_k` the upper bound of the factor over patch `k` and over every direction
/// within the cone `spread` (`(sin, cos)` of its half-angle; `None` for the whole
/// sphere) about `axis` (just `f(centre_k)` for the broken [`PatchBound::AxisOnly`]),
/// as f32 relative to the largest, every positive weight kept positive.
fn fill_weights(
    fine: &Fine,
    axis: &Direction,
    spread: Option<(f64, f64)>,
    lobe: Lobe,
    bound: PatchBound,
    out: &mut [f32],
) {
    let mut weights = vec![0.0f64; out.len()];
    let patches = weights.iter_mut().zip(&fine.power).zip(&fine.regions);
    for (((w, &power), region), centre) in patches.zip(&fine.centres) {
        let Some(region) = region else { continue };
        if power <= 0.0 {
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
        let centre = dot(axis.v, *centre);
        let (value, upper) = match lobe {
            Lobe::Cosine => (centre.max(0.0), reach.max(0.0)),
            Lobe::Glossy { alpha2 } => (lobe_proxy(alpha2, centre), lobe_proxy(alpha2, reach)),
        };
        let g = match bound {
            PatchBound::Cone if upper > 0.0 => value.max(BOUND_SHARE * upper),
            PatchBound::Cone => 0.0,
            PatchBound::AxisOnly => value,
        };
        *w = power * g;
    }
    let max = weights.iter().fold(0.0f64, |a, &b| a.max(b));
    for (o, &w) in out.iter_mut().zip(&weights) {
        *o = if w > 0.0 {
            ((w / max) as f32).max(f32::from_bits(1))
        } else {
            0.0
        };
    }
}
