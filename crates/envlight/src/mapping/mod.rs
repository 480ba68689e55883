//! How image points `(u, v) ∈ [0, 1]²` map to directions, and back: the
//! [`Mapping`] a light's image is stored in, and the maps themselves.
//!
//! - `equirect`: latitude-longitude, [`equirect_to_direction`] and
//!   [`direction_to_equirect`], re-exported here (their public path);
//! - [`equal_area`]: the equal-area octahedral square, and the resampling of a
//!   lat-long image to it;
//! - `octahedral`: the plain octahedral map (crate-private), cheaper than the
//!   equal-area one and not equal in area, which indexes the product sampler's
//!   grids of normals.
//!
//! The module sits below the light and the product sampler: it reads images and
//! math, nothing above them.

pub mod equal_area;
mod equirect;
pub(crate) mod octahedral;

pub use equirect::{
    direction_to_equirect, direction_to_equirect_and_csc, equirect_to_direction, EQUIRECT_JACOBIAN,
};
pub(crate) use equirect::{directions_to_equirect_and_csc, radius_and_csc};

use crate::image::WrapU;
use crate::math::Vec3;
use equal_area::EQUAL_AREA_JACOBIAN;
use std::f64::consts::PI;

/// How image points map to directions.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Mapping {
    /// Latitude-longitude: `θ = π v`, `φ = 2π u` ([`equirect_to_direction`]).
    #[default]
    Equirectangular,
    /// The equal-area octahedral square ([`equal_area`]): constant Jacobian
    /// `4π`, no pole singularity.
    EqualArea,
}

impl Mapping {
    /// Every mapping, for option parsers and tests.
    pub const ALL: [Mapping; 2] = [Mapping::Equirectangular, Mapping::EqualArea];
    /// The name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Mapping::Equirectangular => "equirectangular",
            Mapping::EqualArea => "equal-area",
        }
    }

    /// How u behaves at the image's left and right edges.
    pub(crate) fn wrap(self) -> WrapU {
        match self {
            Mapping::Equirectangular => WrapU::Periodic,
            Mapping::EqualArea => WrapU::Clamp,
        }
    }

    /// The unit direction at `uv` and `dω / du dv` there.
    #[inline(always)]
    pub(crate) fn to_direction(self, uv: [f32; 2]) -> (Vec3, f32) {
        match self {
            Mapping::Equirectangular => {
                let (d, sin_theta) = equirect_to_direction(uv[0], uv[1]);
                (d, EQUIRECT_JACOBIAN * sin_theta)
            }
            Mapping::EqualArea => (
                equal_area::square_to_sphere(uv[0], uv[1]),
                EQUAL_AREA_JACOBIAN,
            ),
        }
    }

    /// The image point looking along `d`, and `du dv / dω` there (the reciprocal
    /// of the Jacobian; +∞ at the poles of the lat-long map).
    #[inline(always)]
    pub(crate) fn to_uv(self, d: Vec3) -> ([f32; 2], f32) {
        match self {
            Mapping::Equirectangular => {
                let (uv, csc_theta) = direction_to_equirect_and_csc(d);
                (uv, csc_theta * (1.0 / EQUIRECT_JACOBIAN))
            }
            Mapping::EqualArea => (equal_area::sphere_to_square(d), 1.0 / EQUAL_AREA_JACOBIAN),
        }
    }

    /// `du dv / dω` at the light-frame direction `d`, bit for bit the second value
    /// of [`Self::to_uv`], without the angles.
    #[inline(always)]
    pub(crate) fn inv_jacobian(self, d: Vec3) -> f32 {
        match self {
            Mapping::Equirectangular => radius_and_csc(d).1 * (1.0 / EQUIRECT_JACOBIAN),
            Mapping::EqualArea => 1.0 / EQUAL_AREA_JACOBIAN,
        }
    }

    /// The mapping's area factor `J` at image height `v`, relative to its maximum
    /// (`sin θ` for lat-long, 1 for equal-area): what importance is multiplied by.
    pub(crate) fn area_factor(self, v: f64) -> f64 {
        match self {
            Mapping::Equirectangular => (PI * v).sin(),
            Mapping::EqualArea => 1.0,
        }
    }
}
