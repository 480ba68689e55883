//! Regions of directions and upper bounds of `v·ω` over them: cones, and the
//! exact (θ, φ) boxes of a lat-long light's texel rectangles; how a patch's
//! weight is floored by such a bound ([`PatchBound`]); and the f64 vector
//! helpers the module's geometry shares.

use super::tuning::{BOUNDARY_STEPS, BOUND_SHARE, BOX_SLACK, CONE_SLACK, MEAN_GRID};
use crate::light::{EnvironmentLight, Mapping};
use crate::math::{cross3, dot3, norm3};
use std::f64::consts::PI;

/// An upper bound of the arc length on the sphere per unit length in `(u, v)` of
/// the equal-area mapping, `2 √(8 + π²/2) ≈ 7.193`, rounded up.
///
/// In each quadrant of `(a, b) = (2u - 1, 2v - 1)` with `r = |a| + |b|` (or its
/// reflection in the lower hemisphere), `dθ = 2 dr / √(2 - r²)` with
/// `|dr| ≤ √2 |d(a, b)|`, and `sin θ dφ = √(2 - r²) (π/2) (a db - b da) / r` with
/// `|a db - b da| ≤ r |d(a, b)|`; so `|dω| ≤ √(8 + π²/2) |d(a, b)|` and
/// `|d(a, b)| = 2 |d(u, v)|`.
pub(super) const EQUAL_AREA_LIPSCHITZ: f64 = 7.2;

/// A cone of directions in the light frame: every direction within `half_angle`
/// of the unit `axis`, stored as the half-angle's cosine and sine.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Cone {
    pub axis: [f64; 3],
    pub cos_half: f64,
    pub sin_half: f64,
}

impl Cone {
    /// The whole sphere.
    pub const FULL: Cone = Cone {
        axis: [0.0, 0.0, 1.0],
        cos_half: -1.0,
        sin_half: 0.0,
    };

    /// `max_{ω in cone} v·ω = cos(max(0, α - h))` for a unit `v` at angle `α` from
    /// the axis: 1 when `α ≤ h`, else `cos α cos h + sin α sin h` (which may be
    /// negative). `sin α` is read off the cross product, exact near `α = 0`.
    #[inline]
    pub fn max_cos(&self, v: [f64; 3]) -> f64 {
        let cos = dot3(v, self.axis);
        if cos >= self.cos_half {
            return 1.0;
        }
        let sin = norm3(cross3(v, self.axis));
        cos * self.cos_half + sin * self.sin_half
    }
}

/// A patch of a lat-long light as the box `φ ∈ [φ0, φ1]`, `θ ∈ [θ0, θ1]` it is in
/// the light frame (`φ = 2π u`, `θ = π v`), for an exact bound of `v·ω` over it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct LatLongBox {
    /// `(cos φ0, sin φ0)` and `(cos φ1, sin φ1)`.
    pub edge0: [f64; 2],
    pub edge1: [f64; 2],
    /// `φ1 - φ0 < π`, where the test of which side of the edges a direction lies
    /// on decides whether its azimuth is inside.
    pub narrow: bool,
    /// `(sin θ0, cos θ0)` and `(sin θ1, cos θ1)`.
    pub top: (f64, f64),
    pub bottom: (f64, f64),
}

impl LatLongBox {
    pub fn new(u: [f64; 2], v: [f64; 2]) -> Self {
        let edge = |u: f64| {
            let (s, c) = (2.0 * PI * u).sin_cos();
            [c, s]
        };
        Self {
            edge0: edge(u[0]),
            edge1: edge(u[1]),
            narrow: u[1] - u[0] < 0.5,
            top: (PI * v[0]).sin_cos(),
            bottom: (PI * v[1]).sin_cos(),
        }
    }

    /// `max v·ω` over the box, exactly, given `ρ = |v_xy|`. As
    /// `v·ω = sin θ ρ cos(φ - φ_v) + v_z cos θ`; as `sin θ ≥ 0`, the largest value
    /// over φ is `a = ρ` when `φ_v` is inside `[φ0, φ1]`, else the larger of the
    /// edges'; then `a sin θ + v_z cos θ = R cos(θ - θ*)` with `R = √(a² + v_z²)`
    /// peaks at `θ* = atan2(a, v_z)` when that is inside `[θ0, θ1]` (the two side
    /// tests below), else at the nearer end, one of the two ends.
    #[inline(always)]
    fn max_dot(&self, v: [f64; 3], rho: f64) -> f64 {
        // Every candidate is computed and the right one selected, without
        // branches: the normals of a renderer's shading points are not
        // predictable.
        let side0 = self.edge0[0] * v[1] - self.edge0[1] * v[0];
        let side1 = v[0] * self.edge1[1] - v[1] * self.edge1[0];
        let edges = (v[0] * self.edge0[0] + v[1] * self.edge0[1])
            .max(v[0] * self.edge1[0] + v[1] * self.edge1[1]);
        let inside_phi = !self.narrow | ((side0 >= 0.0) & (side1 >= 0.0));
        let a = if inside_phi { rho } else { edges };
        let b = v[2];
        let ((s0, c0), (s1, c1)) = (self.top, self.bottom);
        let inside_theta = (a * c0 - b * s0 >= 0.0) & (b * s1 - a * c1 >= 0.0);
        let peak = (a * a + b * b).sqrt();
        let ends = (a * s0 + b * c0).max(a * s1 + b * c1);
        if inside_theta {
            peak
        } else {
            ends
        }
    }
}

/// The directions of a patch's lit cells, bounded: a cone, and on a lat-long
/// light the exact (θ, φ) box of the cells' rectangle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Region {
    pub cone: Cone,
    /// On a lat-long light, the rectangle's exact extent in angles.
    pub latlong: Option<LatLongBox>,
}

impl Region {
    /// The region of the image rectangle `u[0]..u[1] × v[0]..v[1]` of `light`.
    pub fn new(light: &EnvironmentLight, u: [f64; 2], v: [f64; 2]) -> Self {
        Self {
            cone: bounding_cone(light, u, v),
            latlong: (light.mapping() == Mapping::Equirectangular).then(|| LatLongBox::new(u, v)),
        }
    }

    /// An upper bound of `v·ω` over the region, for a unit `v`: the lat-long
    /// box's exact maximum (plus rounding slack) where there is one, which is
    /// never above the cone's, else the cone's.
    #[inline]
    pub fn max_dot(&self, v: &Direction) -> f64 {
        match &self.latlong {
            Some(b) => b.max_dot(v.v, v.rho) + BOX_SLACK,
            None => self.cone.max_cos(v.v),
        }
    }
}

/// A unit vector in the light frame and the length of its xy part.
#[derive(Debug, Clone, Copy)]
pub(super) struct Direction {
    pub v: [f64; 3],
    pub rho: f64,
}

impl Direction {
    pub fn new(v: [f64; 3]) -> Self {
        Self {
            v,
            rho: (v[0] * v[0] + v[1] * v[1]).sqrt(),
        }
    }
}

/// How [`ProductSampler`](super::ProductSampler) weights a patch. Crate-private:
/// the sampler always floors by the bound, unless built as the broken
/// `ProductVariant::AxisOnlyBound` (the `variants` feature).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum PatchBound {
    /// Floored by a share of the upper bound of the factor over the patch and the
    /// node's neighbourhood: unbiased.
    Cone,
    /// The factor at the patch's centre for the node's own direction only:
    /// **biased** (a patch beyond the node's horizon gets weight 0 while a
    /// neighbouring normal sees it lit). It exists so that tests can show that the
    /// invariant checks catch it.
    #[cfg(feature = "variants")]
    AxisOnly,
}

impl PatchBound {
    /// The floor rule of a patch's weight, for the tables' patches and the bright
    /// ones alike: from the factor's `value` at the patch's centre of light and
    /// its `upper` bound over the patch (and, for a table, the node's
    /// neighbourhood), both `≥ 0`, `max(value, scale · BOUND_SHARE · upper)`
    /// where the bound is positive and 0 where it is not (the patch is wholly
    /// past the horizon); the broken `AxisOnly` keeps `value`.
    /// `scale ≤ 1` shrinks the share (a table's floor budget; 1 for a bright
    /// patch).
    #[inline(always)]
    pub(super) fn weight(self, value: f64, upper: f64, scale: f64) -> f64 {
        match self {
            PatchBound::Cone if upper > 0.0 => value.max(scale * BOUND_SHARE * upper),
            PatchBound::Cone => 0.0,
            #[cfg(feature = "variants")]
            PatchBound::AxisOnly => value,
        }
    }

    /// Whether [`Self::weight`] is `value` itself for every `upper` at most
    /// `1.001`, the most a cosine's bound reaches with its slack: then the bound
    /// need not be computed.
    #[inline(always)]
    pub(super) fn keeps_cosine(self, value: f64) -> bool {
        value >= BOUND_SHARE * 1.001 && self == PatchBound::Cone
    }
}

/// A cone (in the light frame) holding every direction of the image rectangle
/// `u[0]..u[1] × v[0]..v[1]`.
///
/// Axis: the solid-angle-weighted mean direction (midpoint rule). Half-angle: the
/// largest angle from the axis over [`BOUNDARY_STEPS`] samples per edge, plus half
/// the longest arc the boundary can run between neighbouring samples (so every
/// boundary point is within it), plus [`CONE_SLACK`]. That bounds the whole patch
/// when the patch lies inside the open hemisphere about the axis: the angle from the
/// axis has no maximum inside a region that avoids the antipode, so it peaks on the
/// boundary, and the boundary of the patch's image is the image of the rectangle's
/// boundary. The patch lies in that hemisphere when the bound is below `π/2` and the
/// patch covers less than `2π` sr: its boundary then avoids the closed opposite
/// hemisphere, which, being connected, is either wholly outside the patch or wholly
/// inside it, and only a patch of at least `2π` sr can hold it. Otherwise the cone
/// is the whole sphere.
pub(super) fn bounding_cone(light: &EnvironmentLight, u: [f64; 2], v: [f64; 2]) -> Cone {
    let direction = |u: f64, v: f64| {
        let (d, jacobian) = light.uv_to_local([u as f32, v as f32]);
        ([d.x as f64, d.y as f64, d.z as f64], jacobian as f64)
    };
    let (du, dv) = (u[1] - u[0], v[1] - v[0]);
    let mut mean = [0.0f64; 3];
    for a in 0..MEAN_GRID {
        for b in 0..MEAN_GRID {
            let t = |i: usize| (i as f64 + 0.5) / MEAN_GRID as f64;
            let (d, jacobian) = direction(u[0] + t(a) * du, v[0] + t(b) * dv);
            for (m, x) in mean.iter_mut().zip(d) {
                *m += x * jacobian;
            }
        }
    }
    let length = norm3(mean);
    if !(length > 1e-9 && length.is_finite()) {
        return Cone::FULL;
    }
    let axis = mean.map(|m| m / length);

    let mut farthest = 0.0f64;
    for s in 0..=BOUNDARY_STEPS {
        let t = s as f64 / BOUNDARY_STEPS as f64;
        for (pu, pv) in [
            (u[0] + t * du, v[0]),
            (u[0] + t * du, v[1]),
            (u[0], v[0] + t * dv),
            (u[1], v[0] + t * dv),
        ] {
            let (d, _) = direction(pu, pv);
            farthest = farthest.max(norm3(cross3(axis, d)).atan2(dot3(axis, d)));
        }
    }
    let (step_u, step_v) = (du / BOUNDARY_STEPS as f64, dv / BOUNDARY_STEPS as f64);
    let (longest_arc, solid_angle) = match light.mapping() {
        // A parallel runs 2π sin θ du ≤ 2π du, a meridian π dv.
        Mapping::Equirectangular => (
            (2.0 * PI * step_u).max(PI * step_v),
            2.0 * PI * du * ((PI * v[0]).cos() - (PI * v[1]).cos()),
        ),
        Mapping::EqualArea => (
            EQUAL_AREA_LIPSCHITZ * step_u.max(step_v),
            4.0 * PI * du * dv,
        ),
    };
    let half_angle = farthest + 0.5 * longest_arc + CONE_SLACK;
    if half_angle < 0.5 * PI && solid_angle < 2.0 * PI * (1.0 - 1e-6) {
        Cone {
            axis,
            cos_half: half_angle.cos(),
            sin_half: half_angle.sin(),
        }
    } else {
        Cone::FULL
    }
}
