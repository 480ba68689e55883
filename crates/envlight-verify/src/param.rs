//! The harness's own mappings (docs/design.md §2 and the equal-area square, in f64),
//! independent of the library's.

use crate::{pdf_tolerance, POLE_BAND_SIN};
use envlight::Vec3;
use std::f64::consts::{FRAC_PI_2, PI};

/// `ω(u, v) = (sin θ cos φ, sin θ sin φ, cos θ)` with `θ = π v`, `φ = 2π u`.
pub fn direction_at(u: f64, v: f64) -> [f64; 3] {
    let (st, ct) = (PI * v).sin_cos();
    let (sp, cp) = (2.0 * PI * u).sin_cos();
    [st * cp, st * sp, ct]
}

/// `(u, v)` of a (not necessarily unit) direction: `θ = atan2(√(x²+y²), z)` (accurate
/// near the poles, unlike `acos z`), `φ = atan2(y, x)` wrapped to `[0, 2π)`.
pub fn uv_of(d: [f64; 3]) -> [f64; 2] {
    let theta = d[0].hypot(d[1]).atan2(d[2]);
    let mut phi = d[1].atan2(d[0]);
    if phi < 0.0 {
        phi += 2.0 * PI;
    }
    [phi / (2.0 * PI), theta / PI]
}

/// The equal-area octahedral square (Clarberg 2008, PBRT-v4's convention, z up),
/// derived here independently of the library: with `a = 2u - 1`, `b = 2v - 1`, a
/// point outside the diamond `|a| + |b| ≤ 1` is first folded onto it by
/// `(|a|, |b|) → (1 - |b|, 1 - |a|)` (the lower hemisphere is the upper one
/// reflected in the diamond's edge, the equator). Then, with `r = |a| + |b|` and
/// `φ = (π/2) |b| / r` within the quadrant,
///
/// ```text
/// ω = (± r√(2 - r²) cos φ,  ± r√(2 - r²) sin φ,  ±(1 - r²))
/// ```
///
/// with the signs of `a`, of `b`, and + inside the diamond (`r√(2 - r²)` is the
/// `sin θ` of `cos θ = 1 - r²`). Equal area: the triangle `r ≤ r₀` (area `r₀²/2` in
/// `(a, b)`) goes onto the quarter cap `1 - z ≤ r₀²` (solid angle `π r₀²/2`), and
/// along each level line of `r`, φ is linear in `|b|`; so `dω = π da db = 4π du dv`.
///
/// Orientation: `(½, ½)` is +z, the corners −z, `(1, ½)` +x, `(0, ½)` −x, `(½, 1)`
/// +y, `(½, 0)` −y. The boundary folds: `(u, 0) ~ (1 - u, 0)`, `(0, v) ~ (0, 1 - v)`
/// (likewise at 1).
pub fn square_to_sphere(u: f64, v: f64) -> [f64; 3] {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    let lower = a.abs() + b.abs() > 1.0;
    let (fa, fb) = if lower {
        (1.0 - b.abs(), 1.0 - a.abs())
    } else {
        (a.abs(), b.abs())
    };
    let r = fa + fb;
    let phi = if r > 0.0 { FRAC_PI_2 * fb / r } else { 0.0 };
    let (sp, cp) = phi.sin_cos();
    let sin_theta = r * (2.0 - r * r).max(0.0).sqrt();
    let cos_theta = 1.0 - r * r;
    [
        (sin_theta * cp).copysign(a),
        (sin_theta * sp).copysign(b),
        if lower { -cos_theta } else { cos_theta },
    ]
}

/// The square point of a (not necessarily unit) direction, the inverse of
/// [`square_to_sphere`]: `r = √(1 - |z|)`, computed as `ρ / √(1 + |z|)` with
/// `ρ = √(x² + y²)` (no cancellation near the poles), `|b| = r φ/(π/2)` with
/// `φ = atan2(|y|, |x|)`, `|a| = r - |b|`, unfolded below the equator, signs from x
/// and y. On the folded boundary one of the two equivalent points is returned.
pub fn sphere_to_square(d: [f64; 3]) -> [f64; 2] {
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let [x, y, z] = d.map(|c| c / len);
    let rho = x.hypot(y);
    let r = (rho / (1.0 + z.abs()).sqrt()).min(1.0);
    let t = if rho > 0.0 {
        y.abs().atan2(x.abs()) / FRAC_PI_2
    } else {
        0.0
    };
    let (fa, fb) = (r * (1.0 - t), r * t);
    let (fa, fb) = if z < 0.0 {
        (1.0 - fb, 1.0 - fa)
    } else {
        (fa, fb)
    };
    [
        (0.5 * (1.0 + fa.copysign(x))).clamp(0.0, 1.0),
        (0.5 * (1.0 + fb.copysign(y))).clamp(0.0, 1.0),
    ]
}

/// A parameterisation of the sphere by `(u, v) ∈ [0, 1]²`, in the harness's own
/// `f64` code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Param {
    /// Latitude-longitude: [`direction_at`], [`uv_of`]; `dω = 2π² sin θ du dv`.
    Equirect,
    /// The equal-area octahedral square: [`square_to_sphere`],
    /// [`sphere_to_square`]; `dω = 4π du dv`.
    EqualArea,
}

impl Param {
    /// The unit direction at `(u, v)`.
    pub fn direction(self, u: f64, v: f64) -> [f64; 3] {
        match self {
            Param::Equirect => direction_at(u, v),
            Param::EqualArea => square_to_sphere(u, v),
        }
    }

    /// The `(u, v)` of a direction.
    pub fn uv(self, d: [f64; 3]) -> [f64; 2] {
        match self {
            Param::Equirect => uv_of(d),
            Param::EqualArea => sphere_to_square(d),
        }
    }

    /// Whether `uv` lies within [`POLE_BAND_SIN`] of a point where this
    /// parameterisation's solid-angle density diverges: the poles of the lat-long
    /// map; nowhere on the equal-area square.
    pub fn near_pole(self, uv: [f64; 2]) -> bool {
        match self {
            Param::Equirect => (PI * uv[1]).sin() < POLE_BAND_SIN,
            Param::EqualArea => false,
        }
    }

    /// The allowed relative disagreement between `pdf(sample.ω)` and `sample.pdf`
    /// at `uv`, given the tolerance `base` away from the poles: [`pdf_tolerance`]
    /// for the lat-long map; just `base` on the equal-area square, whose Jacobian
    /// is the constant 4π (no `1/sin θ` to round).
    pub fn pdf_tolerance(self, base: f64, uv: [f64; 2]) -> f64 {
        match self {
            Param::Equirect => pdf_tolerance(base, (PI * uv[1]).sin()),
            Param::EqualArea => base,
        }
    }

    /// The row-major index of the cell holding `uv` in an `n[0] × n[1]` grid: u
    /// wraps on the lat-long map, everything else clamps.
    pub(crate) fn cell(self, uv: [f64; 2], n: [usize; 2]) -> usize {
        let u = match self {
            Param::Equirect => uv[0].rem_euclid(1.0),
            Param::EqualArea => uv[0].clamp(0.0, 1.0),
        };
        let iu = ((u * n[0] as f64) as usize).min(n[0] - 1);
        let iv = ((uv[1].max(0.0) * n[1] as f64) as usize).min(n[1] - 1);
        iv * n[0] + iu
    }

    /// The points within `band` of `uv` across a cell edge (or a fold of the
    /// square's boundary, where the same direction has a second `(u, v)`), for
    /// crediting a sample on an edge to a neighbouring cell.
    pub(crate) fn neighbours(self, [u, v]: [f64; 2], band: f64) -> Vec<[f64; 2]> {
        let mut out = vec![[u + band, v], [u - band, v], [u, v + band], [u, v - band]];
        if self == Param::EqualArea {
            if u < band || u > 1.0 - band {
                out.push([u, 1.0 - v]);
            }
            if v < band || v > 1.0 - band {
                out.push([1.0 - u, v]);
            }
        }
        out
    }

    pub(crate) fn describe(self) -> &'static str {
        match self {
            Param::Equirect => "",
            Param::EqualArea => " equal-area",
        }
    }
}

pub(crate) fn to_f32(d: [f64; 3]) -> Vec3 {
    Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)
}

pub(crate) fn to_f64(d: Vec3) -> [f64; 3] {
    [d.x as f64, d.y as f64, d.z as f64]
}
