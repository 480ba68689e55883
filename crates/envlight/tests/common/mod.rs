//! The statistical invariant harness of DESIGN.md §5, written once and run over any
//! sampler of directions on the sphere (Mitsuba 3's chi² harness is the model).
//!
//! A sampler is plugged in by implementing [`SphereSampler`]; each check is a plain
//! function returning a report that carries the measured numbers, prints as one
//! line (`cargo test -- --nocapture` shows the figures) and judges itself
//! (`verdict`). [`assert_invariants`] runs them all.
//!
//! Independence: everything the harness compares against is computed here, from
//! DESIGN.md §2 and the equal-area mapping's documented formulas, and not with the
//! library's own helpers. Its mappings between directions and `(u, v)` are its own
//! `f64` code: equirectangular ([`direction_at`], [`uv_of`]) and the equal-area
//! octahedral square ([`square_to_sphere`], [`sphere_to_square`], derived here by
//! folding the lower hemisphere onto the upper one). Its quadrature uses
//! Gauss-Legendre points in the sampler's own `(u, v)` with the exact measure
//! (`2π² sin θ du dv`, or `4π du dv` on the equal-area square), on a grid that
//! subdivides the sampler's cells (so the pdf's discontinuities fall on quadrature
//! cell edges) and only ever calls the sampler's public `pdf`/`radiance`; its
//! random numbers come from `rand_pcg`, not from `envlight::rng`.
//!
//! Determinism: every check draws `ξ` from PCG streams fixed by the seed and the
//! chunk index, and sums partial results in chunk order, so results do not depend
//! on the number of threads.

use envlight::color::luminance;
use envlight::{EnvironmentLight, Rotation, Vec3};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::{FRAC_PI_2, PI};
use std::fmt;

/// Significance level of every chi-square test: a correct sampler is rejected with
/// probability 1e-3 per case (but seeds are fixed, so a passing case stays passing).
pub const ALPHA: f64 = 1e-3;

/// Normalisation tolerance `|1 - ∫ p dω|` (DESIGN.md §5, issue 2).
pub const NORMALISATION_TOLERANCE: f64 = 1e-3;

/// Relative tolerance of `pdf(sample.ω)` against `sample.pdf`, away from the poles;
/// see [`pdf_tolerance`].
pub const PDF_CONSISTENCY_TOLERANCE: f64 = 1e-4;

/// Absolute error of `sin θ` computed in f32 from θ or v near the nadir, on each
/// side of the comparison: `π v` rounds to a multiple of `ulp(π) = 2.4e-7`, so
/// `sin(π v) = sin(π - π(1 - v))` is off by up to 1.2e-7 however `sin` is evaluated;
/// `sample` and `pdf` each round once.
pub const SIN_THETA_ABS_ERROR: f64 = 2.4e-7;

/// The allowed relative disagreement between `pdf(sample.ω)` and `sample.pdf` at a
/// direction with the given `sin θ`: [`PDF_CONSISTENCY_TOLERANCE`] plus the f32
/// precision of `1/sin θ`, [`SIN_THETA_ABS_ERROR`]` / sin θ` (which matters only
/// within ~0.5° of the nadir: it is 1e-4 at `sin θ = 2.4e-3`).
pub fn pdf_tolerance(sin_theta: f64) -> f64 {
    PDF_CONSISTENCY_TOLERANCE + SIN_THETA_ABS_ERROR / sin_theta
}

/// Absolute tolerance (per coordinate) of `invert(sample(ξ).ω)` against `ξ`. The
/// round trip ξ → (u, v) → ω → (u, v) → ξ loses about 1e-7 in (u, v); the inverse
/// multiplies that by the local density of the marginal or conditional CDF, which
/// is below 1e3 even for a single hot column of a 1024-wide map.
pub const INVERT_TOLERANCE: f64 = 1e-3;

/// Samples closer than this (in u or v units) to a cell edge of the sampler's grid
/// are exempt from the consistency checks, because the pdf jumps there and the f32
/// round trip of a direction moves (u, v) by about 1e-7 (the last bits of u near 1
/// are 6e-8 apart; atan2/acos of an f32 vector add a few more).
pub const EDGE_BAND: f64 = 5e-7;

/// The poles, "up to" which DESIGN.md §5 holds: directions with `sin θ` below this
/// (within 1e-4 rad, 0.006°, of a pole; 5e-9 of the sphere) are exempt from the
/// consistency and support checks and from the `∫Y²/p` quadrature. There the
/// solid-angle density diverges, a sample may legitimately be refused, and the f32
/// `sin θ` near the nadir is no better than 0.24%.
pub const POLE_BAND_SIN: f64 = 1e-4;

/// Number of standard errors allowed between a Monte Carlo mean and its
/// reference: a two-sided normal tail of 6.3e-5 per estimate.
pub const Z_TOLERANCE: f64 = 4.0;

/// Relative slack for the reference integrals' quadrature error. The reference is
/// Gauss-Legendre order 3 on sub-cells that split every texel at its centre, where a
/// bilinear (or nearest) reconstruction is a polynomial of degree ≤ 1 in u and the
/// measure `sin θ` is smooth, so the only sizeable error comes from the kink of a
/// cosine lobe (for real maps: order 2 against order 1, see [`unbiasedness`]). The
/// harness measures that error as `|Q3 - Q2|` (orders 3 and 2 on the same cells; an
/// overestimate of Q3's error; measured ≤ 1.5e-5 relative on every case, the
/// largest for a lobe on a real map) and fails when it exceeds this slack, so the
/// slack is checked, not assumed.
pub const QUADRATURE_SLACK: f64 = 1e-4;

/// One direction drawn by a sampler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereSample {
    /// World-space unit direction.
    pub direction: Vec3,
    /// Its solid-angle density, per steradian.
    pub pdf: f32,
    /// Radiance arriving from it, as the sampler reports it.
    pub radiance: [f32; 3],
}

/// The cell grid of a sampler, in the frame that `to_world` carries to world space:
/// the lines along which its pdf (and radiance) may be discontinuous, or kinked
/// (at the cells' centre lines, for bilinear reconstructions). The harness aligns
/// quadrature, chi-square bins, support probes and the consistency checks' edge
/// exemption with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Grid {
    /// `width × height` cells of the equirectangular map (DESIGN.md §2): `φ = 2π u`,
    /// `θ = π v` ([`direction_at`]); u wraps, and the poles are singular.
    Equirect {
        /// Cells along u (φ).
        width: usize,
        /// Cells along v (θ).
        height: usize,
        /// Grid frame to world.
        to_world: Rotation,
    },
    /// `size × size` cells of the equal-area octahedral square
    /// ([`square_to_sphere`]): `dω = 4π du dv` everywhere, no singular point; the
    /// square's boundary is folded onto itself.
    EqualArea {
        /// Cells along u and along v.
        size: usize,
        /// Grid frame to world.
        to_world: Rotation,
    },
}

impl Grid {
    /// Grid frame to world.
    pub fn to_world(self) -> Rotation {
        match self {
            Grid::Equirect { to_world, .. } | Grid::EqualArea { to_world, .. } => to_world,
        }
    }

    /// Cells along u and v.
    pub fn cells(self) -> [usize; 2] {
        match self {
            Grid::Equirect { width, height, .. } => [width, height],
            Grid::EqualArea { size, .. } => [size, size],
        }
    }

    /// The parameterisation the cells live in.
    pub fn param(self) -> Param {
        match self {
            Grid::Equirect { .. } => Param::Equirect,
            Grid::EqualArea { .. } => Param::EqualArea,
        }
    }
}

/// A sampler of directions with a density, the thing DESIGN.md §5 constrains.
/// Adding a sampler to the test table means implementing this (usually by
/// delegation) and adding one line to `tests/invariants.rs`.
pub trait SphereSampler: Sync {
    /// What the sampler is, for the printed report.
    fn name(&self) -> String;
    /// Draws a direction for `ξ ∈ [0,1)²`, or `None` (no light, or a null set).
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample>;
    /// Solid-angle density of a world direction, per steradian.
    fn pdf(&self, direction: Vec3) -> f32;
    /// The `ξ` that `sample` maps to `direction`, when the sampler can invert.
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]>;
    /// Radiance arriving from a world direction.
    fn radiance(&self, direction: Vec3) -> [f32; 3];
    /// The sampler's own claim of `∫ Y(L) dω`.
    fn integral_luminance(&self) -> f64;
    /// The cell grid the pdf is piecewise constant (or bilinear) on, if any (see
    /// [`Grid`]).
    fn grid(&self) -> Option<Grid> {
        None
    }
    /// The sampler's own figure for `(∫Y)² / ∫(Y²/p)`, if it reports one.
    fn reported_efficiency(&self) -> Option<f64> {
        None
    }
}

impl SphereSampler for EnvironmentLight {
    fn name(&self) -> String {
        let o = self.options();
        let rotated = if o.rotation.is_identity() {
            ""
        } else {
            ", rotated"
        };
        let mapping = match self.mapping() {
            envlight::light::Mapping::Equirectangular => "",
            envlight::light::Mapping::EqualArea => " equal-area",
        };
        format!(
            "EnvironmentLight {}x{}{mapping} {:?}{rotated}",
            self.image().width(),
            self.image().height(),
            o.lookup
        )
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        EnvironmentLight::sample(self, xi).map(|s| SphereSample {
            direction: s.direction,
            pdf: s.pdf,
            radiance: s.radiance,
        })
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        EnvironmentLight::pdf(self, direction)
    }
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]> {
        EnvironmentLight::invert(self, direction)
    }
    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        EnvironmentLight::radiance(self, direction)
    }
    fn integral_luminance(&self) -> f64 {
        EnvironmentLight::integral_luminance(self)
    }
    fn grid(&self) -> Option<Grid> {
        // The pdf lives on the texels of the light's own image, in its own mapping
        // (for an equal-area light, the resampled square).
        let to_world = self.options().rotation;
        Some(match self.mapping() {
            envlight::light::Mapping::Equirectangular => Grid::Equirect {
                width: self.image().width(),
                height: self.image().height(),
                to_world,
            },
            envlight::light::Mapping::EqualArea => Grid::EqualArea {
                size: self.image().width(),
                to_world,
            },
        })
    }
    fn reported_efficiency(&self) -> Option<f64> {
        Some(self.efficiency())
    }
}

// ---------------------------------------------------------------------------
// The harness's own mappings (DESIGN.md §2 and the equal-area square, in f64).
// ---------------------------------------------------------------------------

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
    /// at `uv`: [`pdf_tolerance`] for the lat-long map; just
    /// [`PDF_CONSISTENCY_TOLERANCE`] on the equal-area square, whose Jacobian is the
    /// constant 4π (no `1/sin θ` to round).
    pub fn pdf_tolerance(self, uv: [f64; 2]) -> f64 {
        match self {
            Param::Equirect => pdf_tolerance((PI * uv[1]).sin()),
            Param::EqualArea => PDF_CONSISTENCY_TOLERANCE,
        }
    }

    /// The row-major index of the cell holding `uv` in an `n[0] × n[1]` grid: u
    /// wraps on the lat-long map, everything else clamps.
    fn cell(self, uv: [f64; 2], n: [usize; 2]) -> usize {
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
    fn neighbours(self, [u, v]: [f64; 2], band: f64) -> Vec<[f64; 2]> {
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

    fn describe(self) -> &'static str {
        match self {
            Param::Equirect => "",
            Param::EqualArea => " equal-area",
        }
    }
}

fn to_f32(d: [f64; 3]) -> Vec3 {
    Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)
}

fn to_f64(d: Vec3) -> [f64; 3] {
    [d.x as f64, d.y as f64, d.z as f64]
}

/// The frame and parameterisation of a sampler's grid (identity and lat-long when
/// it has none).
#[derive(Debug, Clone, Copy)]
struct Frame {
    to_world: Rotation,
    to_local: Rotation,
    param: Param,
}

impl Frame {
    fn of(s: &dyn SphereSampler) -> Self {
        let grid = s.grid();
        let to_world = grid.map_or(Rotation::IDENTITY, |g| g.to_world());
        Self {
            to_world,
            to_local: to_world.inverse(),
            param: grid.map_or(Param::Equirect, |g| g.param()),
        }
    }
    /// The world direction at grid point `(u, v)`.
    fn world_at(&self, u: f64, v: f64) -> Vec3 {
        self.to_world.apply(to_f32(self.param.direction(u, v)))
    }
    fn local_uv(&self, world: Vec3) -> [f64; 2] {
        self.param.uv(to_f64(self.to_local.apply(world)))
    }
}

/// Where a direction sits relative to the grid's discontinuities.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Place {
    Interior,
    NearEdge,
    NearPole,
}

/// Where `d` is, judged by its `(u, v)` in the grid's own parameterisation: within
/// [`EDGE_BAND`] of a cell edge in u or v (on the equal-area square, the folded
/// boundary is a cell edge in both halves of the fold), or in the pole band.
fn place(grid: Option<Grid>, frame: &Frame, d: Vec3) -> Place {
    let [u, v] = frame.local_uv(d);
    if frame.param.near_pole([u, v]) {
        return Place::NearPole;
    }
    let Some(g) = grid else {
        return Place::Interior;
    };
    let to_edge = |x: f64, n: usize| {
        let s = x * n as f64;
        (s - s.round()).abs() / n as f64
    };
    let [w, h] = g.cells();
    if to_edge(u, w) < EDGE_BAND || to_edge(v, h) < EDGE_BAND {
        Place::NearEdge
    } else {
        Place::Interior
    }
}

// ---------------------------------------------------------------------------
// Quadrature.
// ---------------------------------------------------------------------------

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

    fn describe(&self) -> String {
        format!(
            "{}x{}{} cells x {}² GL pts",
            self.nu,
            self.nv,
            self.param.describe(),
            self.order
        )
    }
}

// ---------------------------------------------------------------------------
// Deterministic parallel sampling.
// ---------------------------------------------------------------------------

const CHUNK: usize = 1 << 15;

/// Runs `body(acc, ξ)` for `n` points `ξ` from PCG streams fixed by `seed`, in
/// parallel chunks with one accumulator each; accumulators come back in order.
pub fn over_samples<A: Send>(
    n: usize,
    seed: u64,
    init: impl Fn() -> A + Sync,
    body: impl Fn(&mut A, [f32; 2]) + Sync,
) -> Vec<A> {
    (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map(|c| {
            let stream = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15)
                ^ (c as u64).wrapping_mul(0xd1b5_4a32_d192_ed03);
            let mut rng = Pcg64Mcg::seed_from_u64(stream);
            let mut acc = init();
            for _ in 0..CHUNK.min(n - c * CHUNK) {
                let xi = [rng.random::<f32>(), rng.random::<f32>()];
                body(&mut acc, xi);
            }
            acc
        })
        .collect()
}

/// Mean and variance accumulated by Welford's method and merged by Chan's formula
/// (stable for the huge-dynamic-range maps).
#[derive(Debug, Clone, Copy, Default)]
pub struct Moments {
    /// Number of values.
    pub n: f64,
    /// Their mean.
    pub mean: f64,
    /// Sum of squared deviations from the mean.
    pub m2: f64,
}

impl Moments {
    /// Adds one value.
    pub fn push(&mut self, x: f64) {
        self.n += 1.0;
        let delta = x - self.mean;
        self.mean += delta / self.n;
        self.m2 += delta * (x - self.mean);
    }
    /// Combines two accumulators.
    pub fn merge(self, o: Self) -> Self {
        if o.n == 0.0 {
            return self;
        }
        if self.n == 0.0 {
            return o;
        }
        let n = self.n + o.n;
        let delta = o.mean - self.mean;
        Self {
            n,
            mean: self.mean + delta * o.n / n,
            m2: self.m2 + o.m2 + delta * delta * self.n * o.n / n,
        }
    }
    /// Standard error of the mean.
    pub fn std_err(&self) -> f64 {
        if self.n > 1.0 {
            (self.m2 / (self.n - 1.0) / self.n).sqrt()
        } else {
            0.0
        }
    }
    /// Mean of the squares.
    pub fn mean_square(&self) -> f64 {
        self.m2 / self.n + self.mean * self.mean
    }
}

/// `x ≤ limit`, false when either is NaN: checks written `!fits(error, tolerance)`
/// count a NaN error as a failure.
pub fn fits(x: f64, limit: f64) -> bool {
    x <= limit
}

fn luminance64(rgb: [f32; 3]) -> f64 {
    luminance(rgb) as f64
}

fn finite_rgb(rgb: [f32; 3]) -> bool {
    rgb.iter().all(|c| c.is_finite() && *c >= 0.0)
}

// ---------------------------------------------------------------------------
// 1. Normalisation.
// ---------------------------------------------------------------------------

/// `∫ p dω` by quadrature.
#[derive(Debug, Clone)]
pub struct Normalisation {
    /// The integral.
    pub integral: f64,
    /// Points where the pdf was NaN, infinite or negative.
    pub bad_values: usize,
    /// The rule used.
    pub rule: String,
}

impl Normalisation {
    /// Must be 1 (to [`NORMALISATION_TOLERANCE`]), or exactly 0 when `black`.
    pub fn verdict(&self, black: bool) -> Result<(), String> {
        if self.bad_values > 0 {
            return Err(format!(
                "{} non-finite or negative pdf values",
                self.bad_values
            ));
        }
        let ok = if black {
            self.integral == 0.0
        } else {
            (1.0 - self.integral).abs() <= NORMALISATION_TOLERANCE
        };
        if ok {
            Ok(())
        } else {
            Err(format!(
                "∫p dω = {:.6} (|1-∫p| = {:.2e})",
                self.integral,
                (1.0 - self.integral).abs()
            ))
        }
    }
}

impl fmt::Display for Normalisation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "normalisation: ∫p dω = {:.7} |1-∫p| = {:.1e} ({})",
            self.integral,
            (1.0 - self.integral).abs(),
            self.rule
        )
    }
}

/// Integrates the sampler's `pdf()` over the sphere: cells that subdivide the
/// sampler's cells (at least 256×128 overall, or as many on the equal-area square,
/// fewer than ~4M unless the grid itself is larger), 2×2 Gauss-Legendre points
/// each, weighted by the exact measure. For a density piecewise constant in
/// (u, v) this is exact up to the rule's error in `sin θ`, O(Δθ⁴), on the lat-long
/// map, and exact on the equal-area square (`dω = 4π du dv`); dropping or
/// misplacing the `1/sin θ` (or `1/4π`) of the solid-angle pdf shows up at O(1).
pub fn normalisation(s: &dyn SphereSampler) -> Normalisation {
    let q = Quadrature::for_sampler(s, 1, [256, 128], 4 << 20, 2);
    let [integral, bad] = q.sum(|d, w, _| {
        let p = s.pdf(d);
        if p.is_finite() && p >= 0.0 {
            [p as f64 * w, 0.0]
        } else {
            [0.0, 1.0]
        }
    });
    Normalisation {
        integral,
        bad_values: bad as usize,
        rule: q.describe(),
    }
}

// ---------------------------------------------------------------------------
// 2. Consistency of sample(), pdf() and invert().
// ---------------------------------------------------------------------------

/// `pdf(sample(ξ).ω)` against `sample(ξ).pdf`, and `invert(sample(ξ).ω)` against `ξ`.
#[derive(Debug, Clone, Default)]
pub struct Consistency {
    /// `ξ` drawn.
    pub samples: usize,
    /// `sample` returned `None`.
    pub none: usize,
    /// Samples with a NaN/infinite/non-positive pdf, a non-unit or non-finite
    /// direction, or non-finite/negative radiance.
    pub malformed: usize,
    /// Exempt: within [`EDGE_BAND`] of a cell edge.
    pub near_edge: usize,
    /// Exempt: within [`POLE_BAND_SIN`] of a pole.
    pub near_pole: usize,
    /// Samples checked.
    pub checked: usize,
    /// Checked samples whose pdf disagreed by more than [`pdf_tolerance`].
    pub pdf_failures: usize,
    /// Largest relative pdf disagreement among checked samples.
    pub max_pdf_error: f64,
    /// Checked samples whose inverse missed `ξ` by more than [`INVERT_TOLERANCE`].
    pub invert_failures: usize,
    /// Largest inversion error among checked samples.
    pub max_invert_error: f64,
    /// [`Consistency::max_exempt_fraction`] for the sampler's grid.
    pub max_exempt_fraction: f64,
    /// The worst offender, for the failure message: its badness (error over
    /// tolerance, the larger of the two checks; infinite when malformed) and a
    /// description.
    pub worst: Option<(f64, String)>,
}

impl Consistency {
    /// Exempt fraction allowed: edges and poles are measure-zero sets widened by
    /// float noise, so they hold a tiny fraction of the samples. Samples spread
    /// evenly within their cells put `2 EDGE_BAND (w + h)` of themselves in the edge
    /// bands of a `w × h` grid (1.6% for 16384 columns, 0.15% for 1024×512); twice
    /// that plus 0.5% is allowed.
    pub fn max_exempt_fraction(grid: Option<Grid>) -> f64 {
        let expected = grid.map_or(0.0, |g| {
            let [w, h] = g.cells();
            2.0 * EDGE_BAND * (w + h) as f64
        });
        2.0 * expected + 0.005
    }

    /// Passes when nothing is malformed, no checked sample fails and the exempt
    /// samples are a tiny fraction.
    pub fn verdict(&self) -> Result<(), String> {
        let exempt = (self.near_edge + self.near_pole) as f64 / self.samples.max(1) as f64;
        if self.malformed > 0
            || self.pdf_failures > 0
            || self.invert_failures > 0
            || exempt > self.max_exempt_fraction
        {
            Err(format!(
                "{self}; worst: {}",
                self.worst.as_ref().map_or("-", |w| w.1.as_str())
            ))
        } else {
            Ok(())
        }
    }

    fn merge(mut self, o: Self) -> Self {
        self.samples += o.samples;
        self.none += o.none;
        self.malformed += o.malformed;
        self.near_edge += o.near_edge;
        self.near_pole += o.near_pole;
        self.checked += o.checked;
        self.pdf_failures += o.pdf_failures;
        self.invert_failures += o.invert_failures;
        self.max_pdf_error = self.max_pdf_error.max(o.max_pdf_error);
        self.max_invert_error = self.max_invert_error.max(o.max_invert_error);
        self.worst = worse(self.worst, o.worst);
        self
    }
}

impl fmt::Display for Consistency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "consistency: {} samples ({} none, {} malformed), {} checked, exempt {} edge + {} pole ({:.2e} of ≤ {:.1e}); \
             pdf: {} fail, max rel err {:.1e}; invert: {} fail, max err {:.1e}",
            self.samples,
            self.none,
            self.malformed,
            self.checked,
            self.near_edge,
            self.near_pole,
            (self.near_edge + self.near_pole) as f64 / self.samples.max(1) as f64,
            self.max_exempt_fraction,
            self.pdf_failures,
            self.max_pdf_error,
            self.invert_failures,
            self.max_invert_error
        )
    }
}

fn worse(a: Option<(f64, String)>, b: Option<(f64, String)>) -> Option<(f64, String)> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.0 > a.0 { b } else { a }),
        (a, b) => a.or(b),
    }
}

/// Draws `n` samples and checks each against `pdf()` and `invert()`.
pub fn consistency(s: &dyn SphereSampler, n: usize, seed: u64) -> Consistency {
    let grid = s.grid();
    let frame = Frame::of(s);
    let mut c = over_samples(n, seed, Consistency::default, |c, xi| {
        c.samples += 1;
        let Some(smp) = s.sample(xi) else {
            c.none += 1;
            return;
        };
        let len = smp.direction.length();
        if !(smp.pdf.is_finite()
            && smp.pdf > 0.0
            && (len - 1.0).abs() < 1e-5
            && finite_rgb(smp.radiance))
        {
            c.malformed += 1;
            let w = Some((f64::INFINITY, format!("malformed sample for ξ={xi:?}: {smp:?}")));
            c.worst = worse(c.worst.take(), w);
            return;
        }
        match place(grid, &frame, smp.direction) {
            Place::NearEdge => {
                c.near_edge += 1;
                return;
            }
            Place::NearPole => {
                c.near_pole += 1;
                return;
            }
            Place::Interior => {}
        }
        c.checked += 1;
        let p = s.pdf(smp.direction) as f64;
        let rel = (p - smp.pdf as f64).abs() / smp.pdf as f64;
        let rel = if rel.is_nan() { f64::INFINITY } else { rel };
        let tolerance = frame.param.pdf_tolerance(frame.local_uv(smp.direction));
        if !fits(rel, tolerance) {
            c.pdf_failures += 1;
        }
        let back = s.invert(smp.direction);
        let inv_err = back.map_or(0.0, |b| {
            let e = (b[0] as f64 - xi[0] as f64)
                .abs()
                .max((b[1] as f64 - xi[1] as f64).abs());
            if e.is_nan() {
                f64::INFINITY
            } else {
                e
            }
        });
        if !fits(inv_err, INVERT_TOLERANCE) {
            c.invert_failures += 1;
        }
        let badness = (rel / tolerance).max(inv_err / INVERT_TOLERANCE);
        let worst_so_far = match &c.worst {
            Some(w) => w.0,
            None => -1.0,
        };
        if badness > worst_so_far {
            c.worst = Some((
                badness,
                format!(
                    "ξ={xi:?} → ω={:?} (local uv {:?}): sample pdf {:e}, pdf() {p:e}, invert {back:?}",
                    smp.direction,
                    frame.local_uv(smp.direction),
                    smp.pdf,
                ),
            ));
        }
        c.max_pdf_error = c.max_pdf_error.max(rel);
        c.max_invert_error = c.max_invert_error.max(inv_err);
    })
    .into_iter()
    .fold(Consistency::default(), Consistency::merge);
    c.max_exempt_fraction = Consistency::max_exempt_fraction(grid);
    c
}

// ---------------------------------------------------------------------------
// 3. Chi-square goodness of fit.
// ---------------------------------------------------------------------------

/// Pearson's chi-square test of the samples' histogram against `N ∫_bin p dω`.
#[derive(Debug, Clone)]
pub struct ChiSquare {
    /// Samples drawn (including `None`s, which land in no bin).
    pub samples: usize,
    /// `sample` returned `None`.
    pub none: usize,
    /// Bins before pooling (`bins_u × bins_v`).
    pub bins: [usize; 2],
    /// Bins (or pools) that entered the statistic.
    pub used_bins: usize,
    /// Degrees of freedom (`used_bins - 1`).
    pub dof: usize,
    /// The statistic `Σ (O - E)² / E`.
    pub statistic: f64,
    /// `P(χ²_dof ≥ statistic)`.
    pub p_value: f64,
    /// Samples in bins where the pdf is 0 at every quadrature point.
    pub outside_support: usize,
    /// The bin with the largest `|O - E| / √E`, for diagnosis.
    pub worst_bin: String,
    /// Sum of expected counts over `N` (the quadrature's `∫p`).
    pub expected_mass: f64,
    /// Samples within [`EDGE_BAND`] of a cell where the pdf is 0, credited to the
    /// neighbouring cell where it is not.
    pub nudged: usize,
}

impl ChiSquare {
    /// Rejects at [`ALPHA`], or when any sample fell where the pdf is 0.
    pub fn verdict(&self) -> Result<(), String> {
        if self.outside_support > 0 || !fits(ALPHA, self.p_value) {
            Err(format!("rejected at α={ALPHA}: {self}"))
        } else {
            Ok(())
        }
    }
}

impl fmt::Display for ChiSquare {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "chi2: N={} ({} none, {} nudged off an edge), ∫p {:.6}, {}x{} bins → {} used, dof {}, χ²={:.1}, p={:.3e}, outside support {}, worst bin {}",
            self.samples,
            self.none,
            self.nudged,
            self.expected_mass,
            self.bins[0],
            self.bins[1],
            self.used_bins,
            self.dof,
            self.statistic,
            self.p_value,
            self.outside_support,
            self.worst_bin
        )
    }
}

/// Minimum expected count of a bin entering the statistic; smaller bins are pooled.
pub const MIN_EXPECTED: f64 = 5.0;

/// Most quadrature cells [`chi_square`] spends on splitting whole-cell bins at the
/// cells' centre lines (4M: every grid up to 1024×1024 cells; a 2048×1024 real
/// map keeps one quadrature cell per grid cell, exact for its piecewise-constant
/// density).
pub const CHI2_QUADRATURE_CELLS: usize = 4 << 20;

/// Draws `n` samples into at most `max_bins` bins and tests them against the
/// pdf. Bins are unions of whole cells of the sampler's grid, each cell split 2×2
/// when the budget allows (so a wrong placement inside a cell is seen too); the
/// expected count of each bin is `n` times the order-2 Gauss-Legendre integral of
/// `pdf()` over it, on quadrature cells that split every grid cell at its centre
/// lines (up to [`CHI2_QUADRATURE_CELLS`]). In the grid's own `(u, v)`, `p dω` is
/// the planar density times a constant (`sin θ / sin θ` on the lat-long map, `4π`
/// on the equal-area square), so the rule is exact for a density piecewise
/// constant on the grid, and also for one bilinear between cell centres (which has
/// its kinks on the centre lines). Bins with expected count below [`MIN_EXPECTED`]
/// are pooled in increasing order of expected count (Mitsuba's rule).
pub fn chi_square(s: &dyn SphereSampler, n: usize, seed: u64, max_bins: usize) -> ChiSquare {
    let frame = Frame::of(s);
    let (fine_u, fine_v, split) = match s.grid() {
        Some(g) => {
            let [w, h] = g.cells();
            let sub = if 4 * w * h <= max_bins { 2 } else { 1 };
            let split = if sub == 1 && 4 * w * h <= CHI2_QUADRATURE_CELLS {
                2
            } else {
                1
            };
            (w * sub, h * sub, split)
        }
        None => (64, 32, 1),
    };
    let fine_total = fine_u * fine_v;
    let (bins_u, bins_v) = if fine_total <= max_bins {
        (fine_u, fine_v)
    } else {
        let g = ((fine_total as f64 / max_bins as f64).sqrt()).ceil() as usize;
        (fine_u.div_ceil(g).max(1), fine_v.div_ceil(g).max(1))
    };
    let bin_of_fine = |iu: usize, iv: usize| (iv * bins_v / fine_v) * bins_u + iu * bins_u / fine_u;

    // Expected counts: per fine cell, the sum over its `split × split` quadrature
    // cells.
    let q = Quadrature {
        to_world: frame.to_world,
        param: frame.param,
        nu: fine_u * split,
        nv: fine_v * split,
        order: 2,
    };
    let quadrature_cells = q.cells(|d, w, _| {
        let p = s.pdf(d);
        [if p.is_finite() && p > 0.0 {
            p as f64 * w
        } else {
            0.0
        }]
    });
    let mut cells = vec![[0.0f64]; fine_u * fine_v];
    for (k, c) in quadrature_cells.iter().enumerate() {
        let (iu, iv) = (k % q.nu / split, k / q.nu / split);
        cells[iv * fine_u + iu][0] += c[0];
    }
    let mut expected = vec![0.0f64; bins_u * bins_v];
    for (k, c) in cells.iter().enumerate() {
        expected[bin_of_fine(k % fine_u, k / fine_u)] += c[0] * n as f64;
    }

    // Observed counts.
    let fine_of = |uv: [f64; 2]| frame.param.cell(uv, [fine_u, fine_v]);
    let (observed, none, nudged) = over_samples(
        n,
        seed,
        || (vec![0u32; bins_u * bins_v], 0usize, 0usize),
        |(hist, none, nudged), xi| match s.sample(xi) {
            Some(smp) => {
                let uv = frame.local_uv(smp.direction);
                let mut cell = fine_of(uv);
                if cells[cell][0] == 0.0 {
                    // Within float noise of the edge of a cell where the pdf is 0 (or
                    // of a fold of the equal-area square), a sample is ambiguous:
                    // credit it to the lit neighbour, if any.
                    for other_uv in frame.param.neighbours(uv, EDGE_BAND) {
                        let other = fine_of(other_uv);
                        if cells[other][0] > 0.0 {
                            cell = other;
                            *nudged += 1;
                            break;
                        }
                    }
                }
                hist[bin_of_fine(cell % fine_u, cell / fine_u)] += 1;
            }
            None => *none += 1,
        },
    )
    .into_iter()
    .fold(
        (vec![0u64; bins_u * bins_v], 0usize, 0usize),
        |(mut h, n0, m0), (c, n1, m1)| {
            for (a, b) in h.iter_mut().zip(c) {
                *a += b as u64;
            }
            (h, n0 + n1, m0 + m1)
        },
    );

    let expected_mass = expected.iter().sum::<f64>() / n as f64;
    let outside_support: u64 = observed
        .iter()
        .zip(&expected)
        .filter(|(_, &e)| e == 0.0)
        .map(|(&o, _)| o)
        .sum();

    // Worst bin, for diagnosis.
    let mut worst = (0.0f64, 0usize);
    for (k, (&o, &e)) in observed.iter().zip(&expected).enumerate() {
        let z = if e > 0.0 {
            (o as f64 - e).abs() / e.sqrt()
        } else if o > 0 {
            f64::INFINITY
        } else {
            0.0
        };
        if z > worst.0 {
            worst = (z, k);
        }
    }
    let worst_bin = {
        let k = worst.1;
        format!(
            "({}, {}) of {}x{}: O={} E={:.1} z={:.1}",
            k % bins_u,
            k / bins_u,
            bins_u,
            bins_v,
            observed[k],
            expected[k],
            worst.0
        )
    };

    // Pool small bins in increasing order of expectation.
    let mut order: Vec<usize> = (0..expected.len()).filter(|&k| expected[k] > 0.0).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]).then(a.cmp(&b)));
    let mut statistic = 0.0;
    let mut used_bins = 0usize;
    let (mut pool_o, mut pool_e) = (0.0f64, 0.0f64);
    for &k in &order {
        pool_o += observed[k] as f64;
        pool_e += expected[k];
        if pool_e >= MIN_EXPECTED {
            statistic += (pool_o - pool_e).powi(2) / pool_e;
            used_bins += 1;
            pool_o = 0.0;
            pool_e = 0.0;
        }
    }
    if pool_e > 0.0 {
        // A remainder smaller than MIN_EXPECTED only happens when every bin is tiny;
        // keep it as one bin rather than dropping its samples.
        statistic += (pool_o - pool_e).powi(2) / pool_e;
        used_bins += 1;
    }
    let dof = used_bins.saturating_sub(1).max(1);
    let p_value = if outside_support > 0 {
        0.0
    } else {
        ChiSquared::new(dof as f64)
            .map(|c| c.sf(statistic))
            .unwrap_or(f64::NAN)
    };
    ChiSquare {
        samples: n,
        none,
        bins: [bins_u, bins_v],
        used_bins,
        dof,
        statistic,
        p_value,
        outside_support: outside_support as usize,
        worst_bin,
        expected_mass,
        nudged,
    }
}

// ---------------------------------------------------------------------------
// 4. Support.
// ---------------------------------------------------------------------------

/// `p(ω) > 0` wherever `L(ω) > 0`, probed at every cell's centre and 2% in from each
/// of its corners.
#[derive(Debug, Clone, Default)]
pub struct Support {
    /// Probes evaluated.
    pub probes: usize,
    /// Probes skipped because they lie within [`POLE_BAND_SIN`] of a pole.
    pub near_pole: usize,
    /// Probes with `L > 0`.
    pub lit: usize,
    /// Lit probes with `p == 0` (or a non-finite pdf).
    pub violations: usize,
    /// The first violation (cell and probe position in cell units).
    pub first: Option<String>,
}

impl Support {
    /// No violation allowed.
    pub fn verdict(&self) -> Result<(), String> {
        if self.violations == 0 {
            Ok(())
        } else {
            Err(format!(
                "{self}; first: {}",
                self.first.as_deref().unwrap_or("-")
            ))
        }
    }
}

impl fmt::Display for Support {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "support: {} probes ({} skipped near a pole), {} lit, {} lit with pdf 0",
            self.probes, self.near_pole, self.lit, self.violations
        )
    }
}

/// Probes the support. Radiance reconstructed from a cell's 3×3 neighbourhood
/// (bilinear, wrapping in u and clamping in v on the lat-long map, clamping in both
/// on the equal-area square) reaches the probe 2% from a corner of the cell with
/// weight ≥ 0.48² from each of the four texels around that corner, so the five
/// probes see every neighbour that can light the cell. Probes are placed in the
/// grid's own `(u, v)` and mapped by the harness's mapping. On the lat-long map,
/// probes within [`POLE_BAND_SIN`] of a pole are skipped: "up to the measure-zero
/// poles" (DESIGN.md §5), widened to where an f32 direction no longer pins θ down;
/// the equal-area square has no such points.
pub fn support(s: &dyn SphereSampler) -> Support {
    let [w, h] = s.grid().map_or([512, 256], |g| g.cells());
    let frame = Frame::of(s);
    const INSET: f64 = 0.02;
    let probes = [
        [0.5, 0.5],
        [INSET, INSET],
        [1.0 - INSET, INSET],
        [INSET, 1.0 - INSET],
        [1.0 - INSET, 1.0 - INSET],
    ];
    let rows: Vec<Support> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut r = Support::default();
            for i in 0..w {
                for p in &probes {
                    let (u, v) = ((i as f64 + p[0]) / w as f64, (j as f64 + p[1]) / h as f64);
                    let d = frame.world_at(u, v);
                    r.probes += 1;
                    if frame.param.near_pole([u, v]) {
                        r.near_pole += 1;
                        continue;
                    }
                    let l = s.radiance(d);
                    if l.iter().any(|&c| c > 0.0) {
                        r.lit += 1;
                        let pdf = s.pdf(d);
                        if !(pdf > 0.0 && pdf.is_finite()) {
                            r.violations += 1;
                            if r.first.is_none() {
                                r.first = Some(format!(
                                    "cell ({i}, {j}) of {w}x{h} at ({:.2}, {:.2}): L={l:?}, pdf={pdf:e}",
                                    p[0], p[1]
                                ));
                            }
                        }
                    }
                }
            }
            r
        })
        .collect();
    rows.into_iter().fold(Support::default(), |mut a, r| {
        a.probes += r.probes;
        a.near_pole += r.near_pole;
        a.lit += r.lit;
        a.violations += r.violations;
        a.first = a.first.or(r.first);
        a
    })
}

// ---------------------------------------------------------------------------
// 5. Unbiasedness and 6. efficiency.
// ---------------------------------------------------------------------------

/// One Monte Carlo estimate of `∫ Y(L) f dω` against its quadrature.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// What `f` is.
    pub label: String,
    /// Quadrature reference (order 3, or 2 for large grids).
    pub reference: f64,
    /// Its error estimate, `|Q3 - Q2|` (or `|Q2 - Q1|`).
    pub quadrature_error: f64,
    /// Monte Carlo mean of `Y f / p`.
    pub mean: f64,
    /// Its standard error.
    pub std_err: f64,
    /// `∫ Y dω` of the whole light (the f = 1 reference), for [`MASS_RESOLUTION`].
    pub total: f64,
}

/// Light below this fraction of `∫ Y dω` may be unreachable by any sampler whose
/// CDF is stored in f32 (steps under half an ulp of 1, 6e-8, round to zero width),
/// so an estimate may miss that much: `f32::EPSILON` of the total. Only the
/// huge-dynamic-range maps come near it (their 1e-30 texels hold 1e-58 of the light).
pub const MASS_RESOLUTION: f64 = f32::EPSILON as f64;

impl Estimate {
    /// Allowed `|mean - reference|`: [`Z_TOLERANCE`] standard errors plus
    /// [`QUADRATURE_SLACK`] relative plus [`MASS_RESOLUTION`] of the whole light.
    pub fn tolerance(&self) -> f64 {
        Z_TOLERANCE * self.std_err
            + QUADRATURE_SLACK * self.reference.abs()
            + MASS_RESOLUTION * self.total.abs()
    }
    /// Deviation in standard errors (0 when both are exactly equal, e.g. a lobe
    /// facing only black).
    pub fn z(&self) -> f64 {
        if self.mean == self.reference {
            0.0
        } else {
            (self.mean - self.reference) / self.std_err
        }
    }
}

/// Unbiasedness of `Y(L) f / p` for f = 1 and cosine lobes, plus the efficiency figure.
#[derive(Debug, Clone)]
pub struct Unbiasedness {
    /// Samples drawn.
    pub samples: usize,
    /// One row per `f`.
    pub estimates: Vec<Estimate>,
    /// The sampler's own `∫ Y dω`.
    pub claimed_integral: f64,
    /// Samples whose weight `Y/p` was not finite.
    pub bad_weights: usize,
    /// Quadrature rule.
    pub rule: String,
    /// `(∫Y)² / ∫(Y²/p)` by quadrature (0 when some lit point has pdf 0).
    pub efficiency_quadrature: f64,
    /// The same from the samples, `E[Y/p]² / E[(Y/p)²]`.
    pub efficiency_monte_carlo: f64,
    /// The sampler's own figure.
    pub efficiency_reported: Option<f64>,
}

impl Unbiasedness {
    /// Relative agreement required between the reported and the quadrature
    /// efficiency ("loose": the figure is for reports, and a sampler may compute it
    /// with a coarser rule; `EnvironmentLight::efficiency` uses 2 points per half
    /// texel, which is 0.3% off for one-row maps, where ∫ sin θ over a whole
    /// hemisphere gets two points).
    pub const EFFICIENCY_QUADRATURE_TOLERANCE: f64 = 1e-2;
    /// Relative agreement required between the Monte Carlo and the quadrature
    /// efficiency ("loose": `E[(Y/p)²]` converges slowly when the tails are heavy).
    pub const EFFICIENCY_MC_TOLERANCE: f64 = 0.05;

    /// Every estimate within tolerance, the quadrature error within the slack, the
    /// claimed integral equal to the quadrature, and (when `check_efficiency`) the
    /// efficiency figures in agreement.
    pub fn verdict(&self, check_efficiency: bool) -> Result<(), String> {
        let mut errors = Vec::new();
        if self.bad_weights > 0 {
            errors.push(format!("{} non-finite weights", self.bad_weights));
        }
        for e in &self.estimates {
            if !fits((e.mean - e.reference).abs(), e.tolerance()) {
                errors.push(format!(
                    "{}: mean {:.6e} vs reference {:.6e} ({:+.1} SE, tolerance {:.2e})",
                    e.label,
                    e.mean,
                    e.reference,
                    e.z(),
                    e.tolerance()
                ));
            }
            if !fits(e.quadrature_error, QUADRATURE_SLACK * e.reference.abs()) {
                errors.push(format!(
                    "{}: quadrature error estimate {:.2e} exceeds the slack {:.2e}",
                    e.label,
                    e.quadrature_error,
                    QUADRATURE_SLACK * e.reference.abs()
                ));
            }
        }
        let reference = self.estimates[0].reference;
        if !fits(
            (self.claimed_integral - reference).abs(),
            QUADRATURE_SLACK * reference.abs(),
        ) {
            errors.push(format!(
                "claimed ∫Y dω = {:.7e} vs quadrature {:.7e}",
                self.claimed_integral, reference
            ));
        }
        if let (true, Some(r)) = (check_efficiency, self.efficiency_reported) {
            let q = self.efficiency_quadrature;
            if !fits((r - q).abs(), Self::EFFICIENCY_QUADRATURE_TOLERANCE * q) {
                errors.push(format!("reported efficiency {r:.6} vs quadrature {q:.6}"));
            }
        }
        let (m, q) = (self.efficiency_monte_carlo, self.efficiency_quadrature);
        if check_efficiency && !fits((m - q).abs(), Self::EFFICIENCY_MC_TOLERANCE * q) {
            errors.push(format!(
                "Monte Carlo efficiency {m:.4} vs quadrature {q:.4}"
            ));
        }
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors.join("; "))
        }
    }
}

impl fmt::Display for Unbiasedness {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unbiasedness: N={} ({}):", self.samples, self.rule)?;
        for e in &self.estimates {
            write!(
                f,
                "\n    {:<28} ref {:.6e} (quad err {:.1e}) MC {:.6e} ± {:.1e} ({:+.2} SE)",
                e.label,
                e.reference,
                e.quadrature_error,
                e.mean,
                e.std_err,
                e.z()
            )?;
        }
        write!(
            f,
            "\n    claimed ∫Y dω {:.6e}; efficiency: quadrature {:.5}, Monte Carlo {:.5}, reported {}",
            self.claimed_integral,
            self.efficiency_quadrature,
            self.efficiency_monte_carlo,
            self.efficiency_reported.map_or("-".to_string(), |e| format!("{e:.5}"))
        )
    }
}

/// The number of integrands: f = 1 and three cosine lobes.
const LOBES: usize = 3;

/// The lobe normals: towards the brightest probe (the texel centre with the largest
/// luminance), straight up, and an oblique one below the horizon.
fn lobe_normals(s: &dyn SphereSampler) -> [Vec3; LOBES] {
    let [w, h] = s.grid().map_or([512, 256], |g| g.cells());
    let frame = Frame::of(s);
    let best = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut best = (f32::NEG_INFINITY, Vec3::new(0.0, 0.0, 1.0));
            for i in 0..w {
                let d = frame.world_at((i as f64 + 0.5) / w as f64, (j as f64 + 0.5) / h as f64);
                let y = luminance(s.radiance(d));
                if y > best.0 {
                    best = (y, d);
                }
            }
            best
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold((f32::NEG_INFINITY, Vec3::new(0.0, 0.0, 1.0)), |a, b| {
            if b.0 > a.0 {
                b
            } else {
                a
            }
        });
    let k = 1.0 / 3f32.sqrt();
    [best.1, Vec3::new(0.0, 0.0, 1.0), Vec3::new(k, -k, -k)]
}

/// Checks `E[Y(L) f / p] = ∫ Y f dω` for f = 1 and three cosine lobes with `n`
/// samples, against Gauss-Legendre quadrature, and measures the efficiency
/// `(∫Y)² / ∫(Y²/p)` both ways.
///
/// The rule splits every cell of the sampler's grid at its centre lines, where a
/// bilinear reconstruction has its kinks (at least 256×128 cells overall, at most
/// ~1M unless the grid needs more), so `Y` is bilinear and `Y²` quadratic in each
/// quadrature cell. It uses order 3, checked against order 2; above 256k cells in
/// the sampler's grid (real maps), orders 2 and 1 keep the cost down (order 2 is
/// still exact for `Y²` along u; the midpoint rule's error, printed, bounds it).
/// On the equal-area square the measure is the constant `4π du dv`, and only the
/// cosine lobes are not polynomial in `(u, v)` (the map is kinked along the axes
/// and the equator's diamond); `|Q3 - Q2|` measures that too (≤ 6.2e-6 relative
/// in the equal-area cases).
pub fn unbiasedness(s: &dyn SphereSampler, n: usize, seed: u64) -> Unbiasedness {
    let normals = lobe_normals(s);
    const K: usize = 2 + LOBES;
    let integrand = |d: Vec3, w: f64, near_pole: bool, with_efficiency: bool| -> [f64; K] {
        let y = luminance64(s.radiance(d));
        let mut r = [0.0; K];
        r[0] = y * w;
        for (k, n) in normals.iter().enumerate() {
            r[1 + k] = y * n.dot(d).max(0.0) as f64 * w;
        }
        // ∫ Y²/p leaves out the lat-long map's pole caps (sin θ < POLE_BAND_SIN,
        // 5e-9 of the sphere), where the density diverges and an f32 pdf may
        // legitimately be 0; Y/p is bounded around them, so the caps change the
        // efficiency by about their share of ∫Y. (The equal-area square has none.)
        if with_efficiency && y > 0.0 && !near_pole {
            let p = s.pdf(d) as f64;
            r[K - 1] = if p > 0.0 {
                y * y / p * w
            } else {
                f64::INFINITY
            };
        }
        r
    };
    let large = s.grid().is_some_and(|g| {
        let [w, h] = g.cells();
        w * h > 256 << 10
    });
    let order = if large { 2 } else { 3 };
    let q3 = Quadrature::for_sampler(s, 2, [256, 128], 1 << 20, order);
    let q2 = Quadrature {
        order: order - 1,
        ..q3
    };
    let r3 = q3.sum(|d, w, pole| integrand(d, w, pole, true));
    let r2 = q2.sum(|d, w, pole| integrand(d, w, pole, false));

    let merged = over_samples(
        n,
        seed,
        || ([Moments::default(); 1 + LOBES], 0usize),
        |(m, bad), xi| {
            let mut values = [0.0f64; 1 + LOBES];
            if let Some(smp) = s.sample(xi) {
                let w = luminance64(smp.radiance) / smp.pdf as f64;
                if !w.is_finite() {
                    *bad += 1;
                }
                values[0] = w;
                for (k, nrm) in normals.iter().enumerate() {
                    values[1 + k] = w * nrm.dot(smp.direction).max(0.0) as f64;
                }
            }
            for (acc, v) in m.iter_mut().zip(values) {
                acc.push(v);
            }
        },
    )
    .into_iter()
    .fold(
        ([Moments::default(); 1 + LOBES], 0usize),
        |(mut a, b0), (m, b1)| {
            for (x, y) in a.iter_mut().zip(m) {
                *x = x.merge(y);
            }
            (a, b0 + b1)
        },
    );
    let (moments, bad_weights) = merged;

    let fmt_n = |n: Vec3| format!("({:.2},{:.2},{:.2})", n.x, n.y, n.z);
    let mut labels = vec!["f = 1".to_string()];
    labels.push(format!("cos lobe brightest {}", fmt_n(normals[0])));
    labels.push(format!("cos lobe {}", fmt_n(normals[1])));
    labels.push(format!("cos lobe {}", fmt_n(normals[2])));
    let estimates = (0..1 + LOBES)
        .map(|k| Estimate {
            label: labels[k].clone(),
            reference: r3[k],
            quadrature_error: (r3[k] - r2[k]).abs(),
            mean: moments[k].mean,
            std_err: moments[k].std_err(),
            total: r3[0],
        })
        .collect();
    let efficiency_quadrature = if r3[0] > 0.0 && r3[K - 1].is_finite() && r3[K - 1] > 0.0 {
        r3[0] * r3[0] / r3[K - 1]
    } else {
        0.0
    };
    let m0 = moments[0];
    let efficiency_monte_carlo = if m0.mean > 0.0 {
        m0.mean * m0.mean / m0.mean_square()
    } else {
        0.0
    };
    Unbiasedness {
        samples: n,
        estimates,
        claimed_integral: s.integral_luminance(),
        bad_weights,
        rule: q3.describe(),
        efficiency_quadrature,
        efficiency_monte_carlo,
        efficiency_reported: s.reported_efficiency(),
    }
}

// ---------------------------------------------------------------------------
// Black maps.
// ---------------------------------------------------------------------------

/// What a sampler of an all-black light does.
#[derive(Debug, Clone, Default)]
pub struct Black {
    /// `ξ` drawn.
    pub samples: usize,
    /// Samples that came back `Some` (must be 0).
    pub some: usize,
    /// Quadrature points with a pdf other than exactly 0 (NaN included).
    pub nonzero_pdf: usize,
    /// Quadrature points with non-finite radiance.
    pub bad_radiance: usize,
    /// Quadrature points.
    pub points: usize,
}

impl Black {
    /// Nothing sampled, pdf 0 everywhere, no NaN, zero integral and efficiency.
    pub fn verdict(&self, s: &dyn SphereSampler) -> Result<(), String> {
        let eff = s.reported_efficiency().unwrap_or(0.0);
        if self.some == 0
            && self.nonzero_pdf == 0
            && self.bad_radiance == 0
            && s.integral_luminance() == 0.0
            && eff == 0.0
        {
            Ok(())
        } else {
            Err(format!(
                "{self}; ∫Y = {}, efficiency = {eff}",
                s.integral_luminance()
            ))
        }
    }
}

impl fmt::Display for Black {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "black: {} samples → {} Some; {} pdf points → {} non-zero, {} bad radiance",
            self.samples, self.some, self.points, self.nonzero_pdf, self.bad_radiance
        )
    }
}

/// Samples and probes an all-black sampler.
pub fn black(s: &dyn SphereSampler, n: usize, seed: u64) -> Black {
    let some = over_samples(
        n,
        seed,
        || 0usize,
        |c, xi| *c += s.sample(xi).is_some() as usize,
    )
    .iter()
    .sum();
    let q = Quadrature::for_sampler(s, 1, [64, 32], 1 << 20, 2);
    let [nonzero, bad, points] = q.sum(|d, _, _| {
        let p = s.pdf(d);
        let l = s.radiance(d);
        [(p != 0.0) as u8 as f64, (!finite_rgb(l)) as u8 as f64, 1.0]
    });
    Black {
        samples: n,
        some,
        nonzero_pdf: nonzero as usize,
        bad_radiance: bad as usize,
        points: points as usize,
    }
}

// ---------------------------------------------------------------------------
// Everything at once.
// ---------------------------------------------------------------------------

/// Sample counts and options for [`assert_invariants`].
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// Samples for the chi-square test.
    pub chi2_samples: usize,
    /// Largest number of chi-square bins.
    pub max_bins: usize,
    /// Samples for the consistency checks.
    pub consistency_samples: usize,
    /// Samples for the unbiasedness/efficiency estimates.
    pub mc_samples: usize,
    /// Whether to run the support check.
    pub support: bool,
    /// Whether to run the unbiasedness check.
    pub unbiasedness: bool,
    /// Whether the efficiency figures (quadrature, Monte Carlo, reported) must agree.
    pub efficiency: bool,
    /// Base seed; each check derives its own.
    pub seed: u64,
}

impl Config {
    /// For small synthetic maps: 1M chi-square samples in at most 40k bins, 200k
    /// consistency samples, 1M Monte Carlo samples.
    pub const SYNTHETIC: Config = Config {
        chi2_samples: 1_000_000,
        max_bins: 40_000,
        consistency_samples: 200_000,
        mc_samples: 1_000_000,
        support: true,
        unbiasedness: true,
        efficiency: true,
        seed: 0x5eed,
    };
    /// For real 1k–2k maps: 500k chi-square samples in at most 8192 bins (groups of
    /// texels), 200k consistency samples, 500k Monte Carlo samples.
    pub const REAL_MAP: Config = Config {
        chi2_samples: 500_000,
        max_bins: 8192,
        consistency_samples: 200_000,
        mc_samples: 500_000,
        support: true,
        unbiasedness: true,
        efficiency: true,
        seed: 0x5eed,
    };
}

/// Every figure measured for one case.
#[derive(Debug, Clone)]
pub struct Report {
    /// 1. normalisation.
    pub normalisation: Normalisation,
    /// 2. consistency.
    pub consistency: Consistency,
    /// 3. chi-square.
    pub chi_square: ChiSquare,
    /// 4. support (when run).
    pub support: Option<Support>,
    /// 5–6. unbiasedness and efficiency (when run).
    pub unbiasedness: Option<Unbiasedness>,
}

/// Runs checks 1–6 on a sampler that is not black, prints one line per check and
/// panics listing every failed check.
pub fn assert_invariants(case: &str, s: &dyn SphereSampler, cfg: &Config) -> Report {
    fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
        let start = std::time::Instant::now();
        let r = f();
        (r, start.elapsed().as_secs_f64())
    }
    let (normalisation, t1) = timed(|| normalisation(s));
    let (consistency, t2) = timed(|| consistency(s, cfg.consistency_samples, cfg.seed ^ 1));
    let (chi_square, t3) = timed(|| chi_square(s, cfg.chi2_samples, cfg.seed ^ 2, cfg.max_bins));
    let (support, t4) = timed(|| cfg.support.then(|| support(s)));
    let (unbiasedness, t5) = timed(|| {
        cfg.unbiasedness
            .then(|| unbiasedness(s, cfg.mc_samples, cfg.seed ^ 3))
    });
    let report = Report {
        normalisation,
        consistency,
        chi_square,
        support,
        unbiasedness,
    };
    let mut lines = vec![format!(
        "[{case}] {} ({:.2}s)",
        s.name(),
        t1 + t2 + t3 + t4 + t5
    )];
    let mut failures = Vec::new();
    let mut add = |line: String, seconds: f64, verdict: Result<(), String>, what: &str| {
        let mark = if verdict.is_ok() { "ok  " } else { "FAIL" };
        lines.push(format!("  {mark} [{seconds:.2}s] {line}"));
        if let Err(e) = verdict {
            failures.push(format!("{what}: {e}"));
        }
    };
    let r = &report;
    add(
        r.normalisation.to_string(),
        t1,
        r.normalisation.verdict(false),
        "normalisation",
    );
    add(
        r.consistency.to_string(),
        t2,
        r.consistency.verdict(),
        "consistency",
    );
    add(
        r.chi_square.to_string(),
        t3,
        r.chi_square.verdict(),
        "chi-square",
    );
    if let Some(sup) = &r.support {
        add(sup.to_string(), t4, sup.verdict(), "support");
    }
    if let Some(u) = &r.unbiasedness {
        add(
            u.to_string(),
            t5,
            u.verdict(cfg.efficiency),
            "unbiasedness/efficiency",
        );
    }
    println!("{}", lines.join("\n"));
    assert!(
        failures.is_empty(),
        "[{case}] {} failed:\n  {}",
        s.name(),
        failures.join("\n  ")
    );
    report
}

/// Checks an all-black sampler: no sample, pdf 0 everywhere, ∫p = 0, no NaN.
pub fn assert_black(case: &str, s: &dyn SphereSampler, n: usize) {
    let b = black(s, n, 0xb1ac);
    let norm = normalisation(s);
    println!("[{case}] {}\n  {b}\n  {norm}", s.name());
    if let Err(e) = b.verdict(s) {
        panic!("[{case}] black: {e}");
    }
    if let Err(e) = norm.verdict(true) {
        panic!("[{case}] normalisation: {e}");
    }
}

// ---------------------------------------------------------------------------
// Self-checks of the harness's own equal-area mapping.
// ---------------------------------------------------------------------------

#[cfg(test)]
mod self_checks {
    use super::*;
    use envlight::light::Mapping;
    use envlight::{EnvImage, LightOptions, Lookup};

    fn close(d: [f64; 3], want: [f64; 3], tol: f64) -> bool {
        (0..3).all(|k| (d[k] - want[k]).abs() <= tol)
    }

    /// Points of `[0, 1]²` from a fixed PCG stream.
    fn points(n: usize, seed: u64) -> Vec<[f64; 2]> {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        (0..n)
            .map(|_| [rng.random::<f64>(), rng.random::<f64>()])
            .collect()
    }

    #[test]
    fn harness_equal_area_orientation_folds_and_round_trip() {
        for ((u, v), want) in [
            ((0.5, 0.5), [0.0, 0.0, 1.0]),
            ((0.0, 0.0), [0.0, 0.0, -1.0]),
            ((1.0, 0.0), [0.0, 0.0, -1.0]),
            ((0.0, 1.0), [0.0, 0.0, -1.0]),
            ((1.0, 1.0), [0.0, 0.0, -1.0]),
            ((1.0, 0.5), [1.0, 0.0, 0.0]),
            ((0.0, 0.5), [-1.0, 0.0, 0.0]),
            ((0.5, 1.0), [0.0, 1.0, 0.0]),
            ((0.5, 0.0), [0.0, -1.0, 0.0]),
            ((0.75, 0.75), [0.5f64.sqrt(), 0.5f64.sqrt(), 0.0]),
        ] {
            let d = square_to_sphere(u, v);
            assert!(close(d, want, 1e-15), "({u}, {v}) → {d:?}, want {want:?}");
        }
        for [u, v] in points(100_000, 1) {
            let d = square_to_sphere(u, v);
            let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            assert!((len - 1.0).abs() < 1e-15, "({u}, {v}): |ω| = {len}");
            // Octants: x from u - ½, y from v - ½, z from the diamond.
            let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
            assert_eq!(d[0] > 0.0, a > 0.0);
            assert_eq!(d[1] > 0.0, b > 0.0);
            assert_eq!(d[2] > 0.0, a.abs() + b.abs() < 1.0);
            let [u2, v2] = sphere_to_square(d);
            assert!(
                (u2 - u).abs() < 1e-13 && (v2 - v).abs() < 1e-13,
                "({u}, {v}) → {d:?} → ({u2}, {v2})"
            );
            // The boundary folds about each edge's midpoint.
            for (p, q) in [
                ((u, 0.0), (1.0 - u, 0.0)),
                ((u, 1.0), (1.0 - u, 1.0)),
                ((0.0, v), (0.0, 1.0 - v)),
                ((1.0, v), (1.0, 1.0 - v)),
            ] {
                let (dp, dq) = (square_to_sphere(p.0, p.1), square_to_sphere(q.0, q.1));
                assert!(close(dp, dq, 1e-15), "{p:?} {dp:?} vs {q:?} {dq:?}");
            }
        }
    }

    #[test]
    fn harness_equal_area_jacobian_is_four_pi() {
        // |∂ω/∂u × ∂ω/∂v| by central differences, away from the kinks of the map
        // (the axes a = 0, b = 0 and the equator |a| + |b| = 1).
        let h = 1e-6;
        let mut checked = 0;
        for [u, v] in points(20_000, 2) {
            let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
            if a.abs().min(b.abs()).min((a.abs() + b.abs() - 1.0).abs()) < 1e-3
                || !(h..1.0 - h).contains(&u)
                || !(h..1.0 - h).contains(&v)
            {
                continue;
            }
            let diff = |p: [f64; 3], q: [f64; 3]| [0, 1, 2].map(|k| (p[k] - q[k]) / (2.0 * h));
            let du = diff(square_to_sphere(u + h, v), square_to_sphere(u - h, v));
            let dv = diff(square_to_sphere(u, v + h), square_to_sphere(u, v - h));
            let cross = [
                du[1] * dv[2] - du[2] * dv[1],
                du[2] * dv[0] - du[0] * dv[2],
                du[0] * dv[1] - du[1] * dv[0],
            ];
            let jacobian = (cross[0].powi(2) + cross[1].powi(2) + cross[2].powi(2)).sqrt();
            assert!(
                (jacobian / (4.0 * PI) - 1.0).abs() < 1e-6,
                "({u}, {v}): {jacobian}"
            );
            checked += 1;
        }
        assert!(checked > 19_000, "{checked}");
    }

    #[test]
    fn harness_equal_area_square_is_the_lights() {
        // An equal-area input with a distinct value in every texel, looked up with
        // nearest lookups: the light's radiance in the harness's direction of each
        // texel's centre (and 10% in from each corner) is that texel, with and
        // without a rotation. So the harness's cells are the light's cells.
        let n = 23;
        let image = EnvImage::from_fn(n, n, |i, j| [(j * n + i) as f32 + 1.0, 0.0, 0.0]).unwrap();
        for degrees in [0.0f32, 37.0] {
            let light = EnvironmentLight::new(
                image.clone(),
                LightOptions {
                    lookup: Lookup::Nearest,
                    mapping: Mapping::EqualArea,
                    input_mapping: Mapping::EqualArea,
                    rotation: Rotation::about_z_degrees(degrees),
                    ..Default::default()
                },
            )
            .unwrap();
            let frame = Frame::of(&light);
            assert_eq!(SphereSampler::grid(&light).map(|g| g.cells()), Some([n, n]));
            for j in 0..n {
                for i in 0..n {
                    for (du, dv) in [(0.5, 0.5), (0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)] {
                        let (u, v) = ((i as f64 + du) / n as f64, (j as f64 + dv) / n as f64);
                        let got = light.radiance(frame.world_at(u, v))[0];
                        assert_eq!(
                            got,
                            image.texel(i, j)[0],
                            "texel ({i}, {j}) at ({u}, {v}), {degrees}°"
                        );
                    }
                }
            }
        }
    }
}
