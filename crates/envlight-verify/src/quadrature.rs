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
            };
        };
        match g {
            Grid::Equirect {
                width,
                height,
                to_world,
            } => {
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
                }
            }
            Grid::EqualArea { size, to_world } => {
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

    /// Calls `f(world direction, dω weight, near pole)` at every point of row `j`
    /// and sums the results per cell; "near pole" is [`Param::near_pole`].
    fn row<const K: usize>(
        &self,
        j: usize,
        phis: &[(f64, f64)],
        f: &(impl Fn(Vec3, f64, bool) -> [f64; K] + Sync),
    ) -> Vec<[f64; K]> {
        match self.param {
            Param::Equirect => self.row_equirect(j, phis, f),
            Param::EqualArea => self.row_equal_area(j, f),
        }
    }

    fn row_equirect<const K: usize>(
        &self,
        j: usize,
        phis: &[(f64, f64)],
        f: &(impl Fn(Vec3, f64, bool) -> [f64; K] + Sync),
    ) -> Vec<[f64; K]> {
        let (t, w) = gauss_legendre(self.order);
        let (du, dv) = (1.0 / self.nu as f64, 1.0 / self.nv as f64);
        let rotate = !self.to_world.is_identity();
        let mut out = vec![[0.0; K]; self.nu];
        for (&tv, &wv) in t.iter().zip(w) {
            let v = (j as f64 + tv) * dv;
            let (st, ct) = (PI * v).sin_cos();
            let near_pole = st < POLE_BAND_SIN;
            let weight_v = wv * st * PI * dv * 2.0 * PI * du;
            for (cell, cell_phis) in out.iter_mut().zip(phis.chunks_exact(t.len())) {
                for (&(sp, cp), &wu) in cell_phis.iter().zip(w) {
                    let local = Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32);
                    let d = if rotate {
                        self.to_world.apply(local)
                    } else {
                        local
                    };
                    let r = f(d, weight_v * wu, near_pole);
                    for k in 0..K {
                        cell[k] += r[k];
                    }
                }
            }
        }
        out
    }

    fn row_equal_area<const K: usize>(
        &self,
        j: usize,
        f: &(impl Fn(Vec3, f64, bool) -> [f64; K] + Sync),
    ) -> Vec<[f64; K]> {
        let (t, w) = gauss_legendre(self.order);
        let (du, dv) = (1.0 / self.nu as f64, 1.0 / self.nv as f64);
        let area = 4.0 * PI * du * dv;
        let rotate = !self.to_world.is_identity();
        let mut out = vec![[0.0; K]; self.nu];
        for (&tv, &wv) in t.iter().zip(w) {
            let v = (j as f64 + tv) * dv;
            for (i, cell) in out.iter_mut().enumerate() {
                for (&tu, &wu) in t.iter().zip(w) {
                    let local = to_f32(square_to_sphere((i as f64 + tu) * du, v));
                    let d = if rotate {
                        self.to_world.apply(local)
                    } else {
                        local
                    };
                    let r = f(d, area * wu * wv, false);
                    for k in 0..K {
                        cell[k] += r[k];
                    }
                }
            }
        }
        out
    }

    /// Per-cell sums of `f(ω, dω, near pole)`, row-major (`nv` rows of `nu`).
    pub fn cells<const K: usize>(
        &self,
        f: impl Fn(Vec3, f64, bool) -> [f64; K] + Sync,
    ) -> Vec<[f64; K]> {
        let phis = self.phi_table();
        (0..self.nv)
            .into_par_iter()
            .flat_map_iter(|j| self.row(j, &phis, &f))
            .collect()
    }

    /// `Σ f(ω, dω, near pole)` over all points (summed per row, then rows in order).
    pub fn sum<const K: usize>(&self, f: impl Fn(Vec3, f64, bool) -> [f64; K] + Sync) -> [f64; K] {
        let phis = self.phi_table();
        let rows: Vec<[f64; K]> = (0..self.nv)
            .into_par_iter()
            .map(|j| {
                self.row(j, &phis, &f).iter().fold([0.0; K], |mut a, c| {
                    for k in 0..K {
                        a[k] += c[k];
                    }
                    a
                })
            })
            .collect();
        rows.iter().fold([0.0; K], |mut a, r| {
            for k in 0..K {
                a[k] += r[k];
            }
            a
        })
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
