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

    /// The points of row `j`, cell by cell: world direction, `dω` weight, and
    /// whether it is near a pole ([`Param::near_pole`]); `order²` per cell.
    fn row_points(&self, j: usize, phis: &[(f64, f64)]) -> Points {
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
    fn row<const K: usize>(
        &self,
        j: usize,
        phis: &[(f64, f64)],
        s: &dyn SphereSampler,
        needs: Needs,
        f: &(impl Fn(&Point) -> [f64; K] + Sync),
    ) -> Vec<[f64; K]> {
        let points = self.row_points(j, phis);
        let n = points.directions.len();
        let mut radiance = vec![[0.0f32; 3]; if needs.radiance { n } else { 0 }];
        let mut pdf = vec![0.0f32; if needs.pdf { n } else { 0 }];
        if needs.radiance {
            s.radiance_batch(&points.directions, &mut radiance);
        }
        if needs.pdf {
            s.pdf_batch(&points.directions, &mut pdf);
        }
        let per_cell = n / self.nu;
        let mut out = vec![[0.0; K]; self.nu];
        for (k, cell) in out.iter_mut().enumerate() {
            for q in k * per_cell..(k + 1) * per_cell {
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
        let phis = self.phi_table();
        (0..self.nv)
            .into_par_iter()
            .flat_map_iter(|j| self.row(j, &phis, s, needs, &f))
            .collect()
    }

    /// `Σ f(point)` over all points (summed per row, then rows in order).
    pub fn sum<const K: usize>(
        &self,
        s: &dyn SphereSampler,
        needs: Needs,
        f: impl Fn(&Point) -> [f64; K] + Sync,
    ) -> [f64; K] {
        let phis = self.phi_table();
        let add = |mut a: [f64; K], c: &[f64; K]| {
            for k in 0..K {
                a[k] += c[k];
            }
            a
        };
        let rows: Vec<[f64; K]> = (0..self.nv)
            .into_par_iter()
            .map(|j| self.row(j, &phis, s, needs, &f).iter().fold([0.0; K], add))
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
}

impl Points {
    fn with_capacity(n: usize) -> Self {
        Self {
            directions: Vec::with_capacity(n),
            weights: Vec::with_capacity(n),
            near_pole: Vec::with_capacity(n),
        }
    }
    fn push(&mut self, d: Vec3, w: f64, near_pole: bool) {
        self.directions.push(d);
        self.weights.push(w);
        self.near_pole.push(near_pole);
    }
}
