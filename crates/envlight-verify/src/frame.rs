//! A sampler's grid frame: the rotation and parameterisation its cells live in,
//! and where a direction sits relative to the cells' edges.

use crate::param::{to_f32, to_f64, Param};
use crate::sampler::{Grid, SphereSampler};
use crate::EDGE_BAND;
use envlight::{Rotation, Vec3};
use std::f64::consts::PI;

/// The frame and parameterisation of a sampler's grid (identity and lat-long when
/// it has none).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Frame {
    pub(crate) to_world: Rotation,
    to_local: Rotation,
    pub(crate) param: Param,
}

impl Frame {
    pub(crate) fn of(s: &dyn SphereSampler) -> Self {
        let grid = s.grid();
        let to_world = grid.map_or(Rotation::IDENTITY, |g| g.to_world());
        Self {
            to_world,
            to_local: to_world.inverse(),
            param: grid.map_or(Param::Equirect, |g| g.param()),
        }
    }
    /// The world direction at grid point `(u, v)`.
    pub(crate) fn world_at(&self, u: f64, v: f64) -> Vec3 {
        self.to_world.apply(to_f32(self.param.direction(u, v)))
    }
    /// The world directions at `(u, v)` for every `u` in `us`, given `u_trig`, the
    /// `(sin 2πu, cos 2πu)` of each (used on the lat-long map only; computed once
    /// for many rows, it saves the trigonometry of every point).
    pub(crate) fn world_row(&self, us: &[f64], u_trig: &[(f64, f64)], v: f64, out: &mut Vec<Vec3>) {
        match self.param {
            Param::Equirect => {
                let (st, ct) = (PI * v).sin_cos();
                out.extend(
                    u_trig
                        .iter()
                        .map(|&(sp, cp)| self.to_world.apply(to_f32([st * cp, st * sp, ct]))),
                );
            }
            Param::EqualArea => out.extend(us.iter().map(|&u| self.world_at(u, v))),
        }
    }
    pub(crate) fn local_uv(&self, world: Vec3) -> [f64; 2] {
        self.param.uv(to_f64(self.to_local.apply(world)))
    }
}

/// Where a direction sits relative to the grid's discontinuities.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Place {
    Interior,
    NearEdge,
    NearPole,
}

/// Where `d` is, judged by its `(u, v)` in the grid's own parameterisation: within
/// [`EDGE_BAND`] of a cell edge in u or v (on the equal-area square, the folded
/// boundary is a cell edge in both halves of the fold) or of a centre line the
/// grid marks as an edge ([`Grid::centre_edges`]), or in the pole band.
pub(crate) fn place(grid: Option<Grid>, frame: &Frame, d: Vec3) -> Place {
    let [u, v] = frame.local_uv(d);
    if frame.param.near_pole([u, v]) {
        return Place::NearPole;
    }
    let Some(g) = grid else {
        return Place::Interior;
    };
    // Distance to the nearest cell edge, and to the nearest centre line when
    // those are edges of the sampler's map too.
    let to_edge = |x: f64, n: usize, centres: bool| {
        let s = x * n as f64;
        let edge = (s - s.round()).abs();
        let centre = if centres {
            (s - 0.5 - (s - 0.5).round()).abs()
        } else {
            f64::INFINITY
        };
        edge.min(centre) / n as f64
    };
    let [w, h] = g.cells();
    let [cu, cv] = g.centre_edges();
    if to_edge(u, w, cu) < EDGE_BAND || to_edge(v, h, cv) < EDGE_BAND {
        Place::NearEdge
    } else {
        Place::Interior
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use envlight::light::{Density, Mapping};
    use envlight::{builtin, EnvironmentLight, LightOptions};

    /// The piecewise-bilinear density's patches run between texel centres, so a
    /// sample on a centre line is at an edge of its map from `ξ` (its inverse may
    /// land in the next patch), as a texel edge is for the constant density.
    #[test]
    fn centre_lines_are_edges_for_the_bilinear_density_only() {
        for mapping in [Mapping::Equirectangular, Mapping::EqualArea] {
            let light = |density| {
                let options = LightOptions {
                    density,
                    mapping,
                    ..Default::default()
                };
                EnvironmentLight::new(builtin::sky(64, 32), options).unwrap()
            };
            let (constant, bilinear) = (
                light(Density::PiecewiseConstant),
                light(Density::PiecewiseBilinear),
            );
            let [w, h] = constant.grid().unwrap().cells();
            let frame = Frame::of(&constant);
            // On a centre line along v, in the middle of a cell along u; then the
            // middle of a cell along both, a quarter off either line.
            let on_centre = frame.world_at(10.5 / w as f64 + 0.25 / w as f64, 11.5 / h as f64);
            let inside = frame.world_at(10.25 / w as f64, 11.25 / h as f64);
            let c = (constant.grid(), bilinear.grid());
            assert_eq!(
                place(c.0, &frame, on_centre),
                Place::Interior,
                "{mapping:?}"
            );
            assert_eq!(
                place(c.1, &frame, on_centre),
                Place::NearEdge,
                "{mapping:?}"
            );
            assert_eq!(place(c.1, &frame, inside), Place::Interior, "{mapping:?}");
        }
    }
}
