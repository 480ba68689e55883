//! Product Gauss-Legendre quadrature over the sphere, aligned with a sampler's grid.

use crate::param::{square_to_sphere, to_f32, Param};
use crate::sampler::{Grid, SphereSampler};
use crate::POLE_BAND_SIN;
use envlight::{Rotation, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// Gauss-Legendre nodes and weights on `[0, 1]`, orders 1 to 4.
pub fn gauss_legendre(order: usize) -> (&'static [f64], &'static [f64]) {
    match order {
        1 => (&[0.5], &[1.0]),
        2 => (
            &[0.211_324_865_405_187_1, 0.788_675_134_594_812_9],
            &[0.5, 0.5],
        ),
        3 => (
            &[0.112_701_665_379_258_3, 0.5, 0.887_298_334_620_741_7],
            &[5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0],
        ),
        4 => (
            &[
                0.069_431_844_202_973_7,
                0.330_009_478_207_571_9,
                0.669_990_521_792_428_1,
                0.930_568_155_797_026_3,
            ],
            &[
                0.173_927_422_568_726_9,
                0.326_072_577_431_273_1,
                0.326_072_577_431_273_1,
                0.173_927_422_568_726_9,
            ],
        ),
        _ => panic!("Gauss-Legendre order {order} not tabulated"),
    }
}

/// A product Gauss-Legendre rule over the sphere: `nu × nv` cells of the
/// parameterisation `param` in the frame `to_world`, `order²` points per cell,
/// weighted by the exact measure: `sin θ Δθ Δφ` on the lat-long map (so the weights
/// of a cell sum to its solid angle up to the rule's error in `sin θ`), `4π Δu Δv`
/// on the equal-area square (exactly the cell's solid angle).
#[derive(Debug, Clone, Copy)]
pub struct Quadrature {
    /// Grid frame to world.
    pub to_world: Rotation,
    /// The parameterisation the cells live in.
    pub param: Param,
    /// Cells along u.
    pub nu: usize,
    /// Cells along v.
    pub nv: usize,
    /// Gauss-Legendre points per cell and axis.
    pub order: usize,
    /// 0: the `nv` rows of cells are uniform in v. `h ≥ 2` (lat-long only): they
    /// split the `2h - 2` intervals between the texel edges `j/h` and the nodes
    /// `k/(h-1)` of an `h`-row map read with [`envlight::Lookup::Node`]
    /// (interleaved: `0 < 1/h < 1/(h-1) < 2/h < …`), `nv / (2h - 2)` cells each, so
    /// that neither the density's steps nor the radiance's kinks fall inside a cell.
    pub node_rows: usize,
    /// How many times each way a cell within a fold's band is split (see
    /// [`SphereSampler::fold`]): 1 but for the chi-square's expected counts
    /// ([`FOLD_SPLIT`]), which need the mirror images of the grid's edges there;
    /// elsewhere their error is far below the checks' tolerances, and the cells
    /// the fold's circles cross are split in every rule.
    pub fold_split: usize,
}

impl Quadrature {
    /// A rule whose cells subdivide each of the sampler's cells `su × sv` times:
    /// `s = step · ⌈·⌉` large enough for `min_cells` cells along each axis (at least
    /// `step`), then lowered in steps of `step` (never below `step`) while the rule
    /// has more than `max_total` cells. `step = 2` keeps every cell split at its
    /// centre lines, where a bilinear reconstruction has its kinks. On the
    /// equal-area square the subdivision is the same along both axes, and large
    /// enough for `√(min_cells[0] · min_cells[1])` cells along each (as many cells
    /// as the lat-long rule asks for). A sampler without a grid gets a `min_cells`
    /// lat-long grid in world space.
    pub fn for_sampler(
        s: &dyn SphereSampler,
        step: usize,
        min_cells: [usize; 2],
        max_total: usize,
        order: usize,
    ) -> Self {
        let Some(g) = s.grid() else {
            return Self {
                to_world: Rotation::IDENTITY,
                param: Param::Equirect,
                nu: min_cells[0],
                nv: min_cells[1],
                order,
                node_rows: 0,
                fold_split: 1,
            };
        };
        match g {
            Grid::Equirect {
                width,
                height,
                node_rows,
                to_world,
                ..
            } => {
                // Texel edges and node rows interleave: 2h - 2 intervals along v.
                let (node_rows, height) = if node_rows && height >= 2 {
                    (height, 2 * height - 2)
                } else {
                    (0, height)
                };
                let mut su = min_cells[0].div_ceil(width).div_ceil(step).max(1) * step;
                let mut sv = min_cells[1].div_ceil(height).div_ceil(step).max(1) * step;
                while width * su * height * sv > max_total && (su > step || sv > step) {
                    if su >= sv && su > step {
                        su -= step;
                    } else {
                        sv -= step;
                    }
                }
                Self {
                    to_world,
                    param: Param::Equirect,
                    nu: width * su,
                    nv: height * sv,
                    order,
                    node_rows,
                    fold_split: 1,
                }
            }
            Grid::EqualArea { size, to_world, .. } => {
                let min_side = ((min_cells[0] * min_cells[1]) as f64).sqrt().ceil() as usize;
                let mut sub = min_side.div_ceil(size).div_ceil(step).max(1) * step;
                while (size * sub).pow(2) > max_total && sub > step {
                    sub -= step;
                }
                Self {
                    to_world,
                    param: Param::EqualArea,
                    nu: size * sub,
                    nv: size * sub,
                    order,
                    node_rows: 0,
                    fold_split: 1,
                }
            }
        }
    }

    /// `(sin φ, cos φ)` at every u point of the lat-long map, `order` per cell
    /// (empty for the equal-area square, which needs no table).
    fn phi_table(&self) -> Vec<(f64, f64)> {
        if self.param != Param::Equirect {
            return Vec::new();
        }
        let (t, _) = gauss_legendre(self.order);
        (0..self.nu)
            .flat_map(|i| {
                t.iter()
                    .map(move |&tu| (2.0 * PI * (i as f64 + tu) / self.nu as f64).sin_cos())
            })
            .collect()
    }

    /// The world direction of the grid point `(x, y)` in cell units.
    fn direction_at(&self, x: f64, y: f64) -> Vec3 {
        let (u, v) = (x / self.nu as f64, y / self.nv as f64);
        let local = match self.param {
            Param::Equirect => {
                let j = (y.floor() as usize).min(self.nv - 1);
                let (start, dv) = self.v_cell(j, 1.0 / self.nv as f64);
                let (st, ct) = (PI * (start + (y - j as f64) * dv)).sin_cos();
                let (sp, cp) = (2.0 * PI * u).sin_cos();
                Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32)
            }
            Param::EqualArea => to_f32(square_to_sphere(u, v)),
        };
        self.to_world.apply(local)
    }

    /// How many times each way the cell with these `corners` is split for the sampler's `fold`
    /// (see [`SphereSampler::fold`]): when one of its circles `a·ω = -s, 0, s` may
    /// cross the cell, enough for parts at most [`SPLIT_ANGLE`] across (at least
    /// [`SPLIT`], at most 256); else [`Self::fold_split`] within the band `0 ≤ a·ω < s`,
    /// where the pdf jumps along the mirror images of the grid's edges; else 1. A
    /// circle may cross the cell when `a·ω` at its corners and centre (their
    /// normalised mean) brackets it, widened by the largest distance from the
    /// centre to a corner (which bounds how far the circle can bulge between the
    /// corners).
    fn split(&self, corners: [Vec3; 4], (axis, band): (Vec3, f32)) -> usize {
        let sum = corners.iter().fold(Vec3::new(0.0, 0.0, 0.0), |a, &d| a + d);
        let centre = sum.normalized().unwrap_or(corners[0]);
        let reach = corners
            .iter()
            .map(|&d| (d - centre).length())
            .fold(0.0f32, f32::max);
        let dots = corners.map(|d| axis.dot(d));
        let lo = dots.iter().fold(axis.dot(centre), |m, &d| m.min(d)) - reach;
        let hi = dots.iter().fold(axis.dot(centre), |m, &d| m.max(d)) + reach;
        if [-band, 0.0, band].iter().any(|&c| lo <= c && c <= hi) {
            ((2.0 * reach as f64 / SPLIT_ANGLE).ceil() as usize).clamp(SPLIT, 256)
        } else if lo >= 0.0 && hi < band {
            self.fold_split
        } else {
            1
        }
    }

    /// The points of cell `(i, j)` split `m × m` times, `order²` per part.
    fn push_split_cell(&self, p: &mut Points, i: usize, j: usize, m: usize) {
        let (t, w) = gauss_legendre(self.order);
        let (du, dv) = (1.0 / self.nu as f64, 1.0 / self.nv as f64);
        let part = 1.0 / m as f64;
        for b in 0..m {
            for (&tv, &wv) in t.iter().zip(w) {
                let y = (b as f64 + tv) * part;
                for a in 0..m {
                    for (&tu, &wu) in t.iter().zip(w) {
                        let x = (a as f64 + tu) * part;
                        let d = self.direction_at(i as f64 + x, j as f64 + y);
                        let (weight, near_pole) = match self.param {
                            Param::Equirect => {
                                let (start, dv) = self.v_cell(j, dv);
                                let st = (PI * (start + y * dv)).sin();
                                let weight = wv * st * PI * dv * 2.0 * PI * du * wu;
                                (weight * part * part, st < POLE_BAND_SIN)
                            }
                            Param::EqualArea => (4.0 * PI * du * dv * wu * wv * part * part, false),
                        };
                        p.push(d, weight, near_pole);
                    }
                }
            }
        }
    }

    /// The points of row `j`, cell by cell: world direction, `dω` weight, and
    /// whether it is near a pole ([`Param::near_pole`]); `order²` per cell, or
    /// `(m · order)²` where the sampler's `fold` asks for more (`m` from `split`).
    fn row_points(&self, j: usize, phis: &[(f64, f64)], fold: Option<(Vec3, f32)>) -> Points {
        let plain = self.plain_row_points(j, phis);
        let Some(fold) = fold else {
            return plain;
        };
        // The cells' corners along the row's two edges.
        let edge = |y: f64| -> Vec<Vec3> {
            (0..=self.nu)
                .map(|i| self.direction_at(i as f64, y))
                .collect()
        };
        let (top, bottom) = (edge(j as f64), edge(j as f64 + 1.0));
        let mut p = Points::with_capacity(plain.directions.len());
        for i in 0..self.nu {
            let m = self.split([top[i], top[i + 1], bottom[i], bottom[i + 1]], fold);
            if m == 1 {
                for q in plain.ends[i]..plain.ends[i + 1] {
                    p.push(plain.directions[q], plain.weights[q], plain.near_pole[q]);
                }
            } else {
                self.push_split_cell(&mut p, i, j, m);
            }
            p.end_cell();
        }
        p
    }

    /// [`Self::row_points`] without a fold.
    fn plain_row_points(&self, j: usize, phis: &[(f64, f64)]) -> Points {
        let (t, w) = gauss_legendre(self.order);
        let (du, dv) = (1.0 / self.nu as f64, 1.0 / self.nv as f64);
        let rotate = !self.to_world.is_identity();
        let world = |local: Vec3| {
            if rotate {
                self.to_world.apply(local)
            } else {
                local
            }
        };
        let per_cell = t.len() * t.len();
        let mut p = Points::with_capacity(self.nu * per_cell);
        match self.param {
            Param::Equirect => {
                let (start, dv) = self.v_cell(j, dv);
                let heights: Vec<(f64, f64, f64)> = t
                    .iter()
                    .zip(w)
                    .map(|(&tv, &wv)| {
                        let (st, ct) = (PI * (start + tv * dv)).sin_cos();
                        (st, ct, wv * st * PI * dv * 2.0 * PI * du)
                    })
                    .collect();
                for cell_phis in phis.chunks_exact(t.len()) {
                    for &(st, ct, weight_v) in &heights {
                        for (&(sp, cp), &wu) in cell_phis.iter().zip(w) {
                            let local = Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32);
                            p.push(world(local), weight_v * wu, st < POLE_BAND_SIN);
                        }
                    }
                    p.end_cell();
                }
            }
            Param::EqualArea => {
                let area = 4.0 * PI * du * dv;
                for i in 0..self.nu {
                    for (&tv, &wv) in t.iter().zip(w) {
                        let v = (j as f64 + tv) * dv;
                        for (&tu, &wu) in t.iter().zip(w) {
                            let local = to_f32(square_to_sphere((i as f64 + tu) * du, v));
                            p.push(world(local), area * wu * wv, false);
                        }
                    }
                    p.end_cell();
                }
            }
        }
        p
    }

    /// Where row `j` of cells starts along v and its height (`dv` for uniform rows;
    /// see [`Self::node_rows`]).
    fn v_cell(&self, j: usize, dv: f64) -> (f64, f64) {
        let h = self.node_rows;
        if h < 2 {
            return (j as f64 * dv, dv);
        }
        let split = (self.nv / (2 * h - 2)).max(1);
        let edge = |n: usize| {
            if n.is_multiple_of(2) {
                (n / 2) as f64 / (h - 1) as f64
            } else {
                n.div_ceil(2) as f64 / h as f64
            }
        };
        let (base, sub) = (j / split, j % split);
        let (lo, hi) = (edge(base), edge(base + 1));
        let height = (hi - lo) / split as f64;
        (lo + sub as f64 * height, height)
    }

    /// Per-cell sums of `f(point)` over row `j`, the sampler's values at the
    /// points looked up in batches (only those `needs` asks for).
    #[allow(clippy::too_many_arguments)]
    fn row<const K: usize>(
        &self,
        j: usize,
        phis: &[(f64, f64)],
        fold: Option<(Vec3, f32)>,
        s: &dyn SphereSampler,
        needs: Needs,
        f: &(impl Fn(&Point) -> [f64; K] + Sync),
    ) -> Vec<[f64; K]> {
        let points = self.row_points(j, phis, fold);
        let n = points.directions.len();
        let mut radiance = vec![[0.0f32; 3]; if needs.radiance { n } else { 0 }];
        let mut pdf = vec![0.0f32; if needs.pdf { n } else { 0 }];
        if needs.radiance {
            s.radiance_batch(&points.directions, &mut radiance);
        }
        if needs.pdf {
            s.pdf_batch(&points.directions, &mut pdf);
        }
        let mut out = vec![[0.0; K]; self.nu];
        for (k, cell) in out.iter_mut().enumerate() {
            for q in points.ends[k]..points.ends[k + 1] {
                let r = f(&Point {
                    direction: points.directions[q],
                    weight: points.weights[q],
                    near_pole: points.near_pole[q],
                    radiance: radiance.get(q).copied().unwrap_or_default(),
                    pdf: pdf.get(q).copied().unwrap_or_default(),
                });
                for k in 0..K {
                    cell[k] += r[k];
                }
            }
        }
        out
    }

    /// Per-cell sums of `f(point)`, row-major (`nv` rows of `nu`).
    pub fn cells<const K: usize>(
        &self,
        s: &dyn SphereSampler,
        needs: Needs,
        f: impl Fn(&Point) -> [f64; K] + Sync,
    ) -> Vec<[f64; K]> {
        let (phis, fold) = (self.phi_table(), s.fold());
        (0..self.nv)
            .into_par_iter()
            .flat_map_iter(|j| self.row(j, &phis, fold, s, needs, &f))
            .collect()
    }

    /// `Σ f(point)` over all points (summed per row, then rows in order).
    pub fn sum<const K: usize>(
        &self,
        s: &dyn SphereSampler,
        needs: Needs,
        f: impl Fn(&Point) -> [f64; K] + Sync,
    ) -> [f64; K] {
        let (phis, fold) = (self.phi_table(), s.fold());
        let add = |mut a: [f64; K], c: &[f64; K]| {
            for k in 0..K {
                a[k] += c[k];
            }
            a
        };
        let rows: Vec<[f64; K]> = (0..self.nv)
            .into_par_iter()
            .map(|j| {
                self.row(j, &phis, fold, s, needs, &f)
                    .iter()
                    .fold([0.0; K], add)
            })
            .collect();
        rows.iter().fold([0.0; K], add)
    }

    pub(crate) fn describe(&self) -> String {
        format!(
            "{}x{}{} cells x {}² GL pts",
            self.nu,
            self.nv,
            self.param.describe(),
            self.order
        )
    }
}

/// How many times each way [`Quadrature`] splits a cell that a circle of a fold
/// of the pdf crosses ([`SphereSampler::fold`]), at least.
pub const SPLIT: usize = 8;

/// The largest size (radians) of the parts of a split cell, up to 256 a side.
pub const SPLIT_ANGLE: f64 = 0.004;

/// How many times each way [`Quadrature`] splits a cell within a fold's band.
pub const FOLD_SPLIT: usize = 4;

/// Which of the sampler's values [`Quadrature::sum`] and [`Quadrature::cells`]
/// look up at the points (the others read as 0).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Needs {
    /// `radiance(ω)`.
    pub radiance: bool,
    /// `pdf(ω)`.
    pub pdf: bool,
}

impl Needs {
    /// The pdf alone.
    pub const PDF: Needs = Needs {
        radiance: false,
        pdf: true,
    };
    /// Radiance and pdf.
    pub const BOTH: Needs = Needs {
        radiance: true,
        pdf: true,
    };
}

/// One quadrature point with the sampler's values there.
#[derive(Debug, Clone, Copy)]
pub struct Point {
    /// World direction.
    pub direction: Vec3,
    /// `dω` weight.
    pub weight: f64,
    /// Within the pole band of the lat-long map.
    pub near_pole: bool,
    /// `radiance(ω)` (when asked for).
    pub radiance: [f32; 3],
    /// `pdf(ω)` (when asked for).
    pub pdf: f32,
}

/// A row's points, as arrays (the directions go to the batch queries whole).
struct Points {
    directions: Vec<Vec3>,
    weights: Vec<f64>,
    near_pole: Vec<bool>,
    /// Cell `k`'s points are `ends[k]..ends[k + 1]`.
    ends: Vec<usize>,
}

impl Points {
    fn with_capacity(n: usize) -> Self {
        Self {
            directions: Vec::with_capacity(n),
            weights: Vec::with_capacity(n),
            near_pole: Vec::with_capacity(n),
            ends: vec![0],
        }
    }
    /// Closes the current cell.
    fn end_cell(&mut self) {
        self.ends.push(self.directions.len());
    }
    fn push(&mut self, d: Vec3, w: f64, near_pole: bool) {
        self.directions.push(d);
        self.weights.push(w);
        self.near_pole.push(near_pole);
    }
}
