//! Product sampling at a shading point (DESIGN.md §6a): directions drawn with
//! density `p(ω | n) ≈ L(ω) f(ω) / ∫ L f`, exactly normalised and with an exact
//! pdf, for a factor `f` that is the clamped cosine or the cosine times a glossy
//! lobe ([`Factor`]).
//!
//! **Levels** (after the two-level scheme of Conty Estevez and Lecocq 2018):
//! - *fine*: the light's own piecewise-constant importance over its texel grid,
//!   `f_t = Y(filtered) · J_j` (DESIGN.md §4 step 1, never MIS-compensated), whatever
//!   sampler, density or mapping the light uses. Its support covers the light's
//!   radiance: for bilinear lookups the importance is filtered with the `[1 6 1]`
//!   blur, which covers the bilinear reconstruction's support.
//! - *patches*: the texel grid cut into `Pw × Ph` rectangular blocks of texels
//!   (128 × 64 by default), block edges at texel edges.
//! - *pyramid*: patches grouped 2 × 2 level by level up to a single root. Every
//!   node (patch or group) holds the fraction `P` of the fine importance inside it
//!   and the regions bounding the directions of its *lit* texels: a cone, and on a
//!   lat-long light the exact (θ, φ) box of the texel rectangle.
//! - *cut*: nodes chosen once, from the root down, replacing any node with more
//!   than `1 / top_nodes` of the power by its children, so that bright regions are
//!   cut down to single patches and dim ones stay coarse.
//!
//! **Weights.** A node's weight at a shading point is `w = P · B`, where `B` is an
//! *upper bound* of `f` over the node's lit directions (never the value at its
//! centre: a patch straddling the horizon would get weight 0 while part of it is
//! lit, which is bias). For the cosine, `B = max(0, max n·ω)`; over a lat-long box
//! the maximum of `v·ω` is exact (the largest `cos(φ - φ_v)` over the φ range,
//! then the peak of `a sin θ + v_z cos θ` over the θ range), over a cone it is
//! `cos(max(0, α - h))`. The glossy lobe's bound is its value at the largest
//! `r·ω` (it falls with the angle to the mirror direction `r`).
//!
//! **Sampling.** [`ProductSampler::at`] weighs the cut's nodes; a sample picks one
//! by `w / Σw`, then descends the pyramid to a patch, choosing among each node's
//! children by their weights (if all of them are 0 by rounding, by their power),
//! then a texel inside the patch from the fine importance restricted to it (a row
//! from the patch's marginal, then a texel from that row's segment), then a point
//! uniformly inside the texel, mapped to a direction with the light's mapping and
//! rotation:
//!
//! ```text
//! p(ω | n) = (w_cut / Σw) · Π (w_child / Σ w_siblings) · (f_t / F_k) · w h / J(ω)
//! ```
//!
//! with `F_k = Σ_{t ∈ k} f_t` over patch `k`, `w h` the reciprocal of a texel's
//! area in `(u, v)`, and `J = dω / du dv` (`2π² sin θ` or `4π`). `f_t / F_k` is read
//! from the same fixed-point CDFs that sampling inverts (see
//! [`crate::distribution`]), and every choice's probability from the same
//! weights computed by the same function, so [`ShadingPoint::pdf`] is the exact
//! density of [`ShadingPoint::sample`]; it integrates to 1 over the sphere, and it
//! is positive wherever `L · f > 0` (up to the measure-zero poles of a lat-long
//! map, where it is 0 as for the light).

use crate::distribution::{
    cell_index, place_in_cell_f64, Distribution1D, CDF_ONE, ONE_MINUS_EPSILON,
};
use crate::light::{solid_angle_density, EnvironmentLight, LightSample, Mapping};
use crate::math::{is_positive_finite, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::sync::Arc;

/// Boundary samples per patch edge when bounding its cone.
const BOUNDARY_STEPS: usize = 64;

/// Midpoints per side of the grid that estimates a patch's mean direction.
const MEAN_GRID: usize = 16;

/// Radians added to every cone's half-angle for the rounding of the f32 mapping
/// (about 1e-6 rad) and of the rotation into the light frame (about 1e-7 rad).
const CONE_SLACK: f64 = 1e-4;

/// An upper bound of the arc length on the sphere per unit length in `(u, v)` of
/// the equal-area mapping, `2 √(8 + π²/2) ≈ 7.193`, rounded up.
///
/// In each quadrant of `(a, b) = (2u - 1, 2v - 1)` with `r = |a| + |b|` (or its
/// reflection in the lower hemisphere), `dθ = 2 dr / √(2 - r²)` with
/// `|dr| ≤ √2 |d(a, b)|`, and `sin θ dφ = √(2 - r²) (π/2) (a db - b da) / r` with
/// `|a db - b da| ≤ r |d(a, b)|`; so `|dω| ≤ √(8 + π²/2) |d(a, b)|` and
/// `|d(a, b)| = 2 |d(u, v)|`.
const EQUAL_AREA_LIPSCHITZ: f64 = 7.2;

/// How a [`ProductSampler`] is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ProductOptions {
    /// `[Pw, Ph]`: patches across and down the light's image, clamped into
    /// `[1, w] × [1, h]` for a `w × h` image. `None` for
    /// [`ProductOptions::default_patches`] of the light's mapping.
    ///
    /// More patches bound the factor more tightly (fewer samples where `f` is small)
    /// and cost more per sample (the pyramid above them is deeper).
    pub patches: Option<[usize; 2]>,
    /// About how many nodes of the patch pyramid [`ProductSampler::at`] weighs all
    /// at once (`O(n)` per shading point): the *cut*, nodes of at most
    /// `1 / top_nodes` of the light's power each (or single patches), so bright
    /// regions are cut finely and dim ones coarsely; below the cut each sample
    /// descends the pyramid (four bounds a level). `None` for
    /// [`ProductOptions::DEFAULT_TOP_NODES`].
    pub top_nodes: Option<usize>,
    /// How a patch's weight bounds the factor: always [`PatchBound::Cone`] except
    /// in tests that prove the verification harness rejects the alternative.
    #[doc(hidden)]
    pub bound: PatchBound,
}

/// How [`ProductSampler`] weights a patch.
#[doc(hidden)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PatchBound {
    /// `B_k`, the upper bound of the factor over the patch's cone: unbiased.
    #[default]
    Cone,
    /// The factor at the cone's axis only: **biased** (a patch straddling the
    /// horizon whose axis is below it gets weight 0 while part of it is lit).
    /// It exists so that tests can show that the invariant checks catch it.
    AxisOnly,
}

impl ProductOptions {
    /// The default of [`ProductOptions::top_nodes`].
    pub const DEFAULT_TOP_NODES: usize = 512;

    /// The patch grid used when [`ProductOptions::patches`] is `None`: 128 × 64 on
    /// a lat-long map (patches about 2.8° square at the equator), 64 × 64 on the
    /// equal-area square (4096 patches of equal solid angle). Chosen by measurement
    /// (`envlight-verify`'s `product_efficiency` example, BENCHMARKS.md): with the
    /// default cut of 512 nodes, 32 × 16 patches leave the worst efficiency on the
    /// shared maps at 0.50 of the light's own, 128 × 64 at 0.85, and 256 × 128 no
    /// better.
    pub fn default_patches(mapping: Mapping) -> [usize; 2] {
        match mapping {
            Mapping::Equirectangular => [128, 64],
            Mapping::EqualArea => [64, 64],
        }
    }
}

/// The factor `f(ω)` that multiplies the light's radiance in the sampling target
/// `L(ω) f(ω)` at a shading point. All vectors are in the world frame.
///
/// Inputs need not be unit length: every use normalises them first
/// ([`Factor::normalized`]). A factor whose normal (or outgoing direction) is zero
/// or not finite, or whose roughness is outside `(0, 1]`, is *invalid*: its value
/// is 0 everywhere and a shading point with it samples nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Factor {
    /// The clamped cosine of a diffuse surface with normal `n`:
    /// `f(ω) = max(0, n·ω)`.
    Cosine {
        /// The surface normal `n`.
        normal: Vec3,
    },
    /// The clamped cosine times a GGX reflection-lobe proxy:
    /// `f(ω) = max(0, n·ω) · D_α(γ(ω) / 2)`, with `r = 2 (n·ωo) n - ωo` the mirror
    /// direction of the outgoing direction `ωo`, `γ(ω)` the angle between `ω` and
    /// `r`, and `D_α(θ_h) = α² / (π (cos²θ_h (α² - 1) + 1)²)` the GGX normal
    /// distribution as a function of the half-angle.
    ///
    /// This is a *proxy* of the GGX BRDF lobe, used as a sampling target: its shape
    /// and width follow the lobe, but it is not the BRDF (no Fresnel, masking or
    /// `1/(4 cos θo)`, and `γ/2` equals the true half-angle, between `n` and the
    /// half-vector of `ω` and `ωo`, only in the plane of incidence). A renderer
    /// weights each sample by the true BSDF over this sampler's pdf. `D_α > 0`
    /// everywhere, so the pdf is positive wherever `L(ω) max(0, n·ω) > 0` and that
    /// estimate is unbiased for any BSDF over the upper hemisphere.
    Glossy {
        /// The surface normal `n`.
        normal: Vec3,
        /// The outgoing direction `ωo` (towards the viewer).
        outgoing: Vec3,
        /// The GGX roughness `α ∈ (0, 1]` (1 is a wide lobe, near 0 a mirror).
        roughness: f32,
    },
}

impl Factor {
    /// The clamped cosine about `normal`.
    pub fn cosine(normal: Vec3) -> Self {
        Factor::Cosine { normal }
    }

    /// The clamped cosine about `normal` times the GGX lobe proxy of roughness
    /// `roughness` about the mirror direction of `outgoing`.
    pub fn glossy(normal: Vec3, outgoing: Vec3, roughness: f32) -> Self {
        Factor::Glossy {
            normal,
            outgoing,
            roughness,
        }
    }

    /// The surface normal, as given.
    pub fn normal(&self) -> Vec3 {
        match *self {
            Factor::Cosine { normal } | Factor::Glossy { normal, .. } => normal,
        }
    }

    /// The same factor with unit vectors, or `None` when it is invalid (a zero or
    /// non-finite vector, or a roughness outside `(0, 1]`, NaN included).
    pub fn normalized(&self) -> Option<Factor> {
        match *self {
            Factor::Cosine { normal } => Some(Factor::Cosine {
                normal: normal.normalized()?,
            }),
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                if !(roughness > 0.0 && roughness <= 1.0) {
                    return None;
                }
                Some(Factor::Glossy {
                    normal: normal.normalized()?,
                    outgoing: outgoing.normalized()?,
                    roughness,
                })
            }
        }
    }

    /// `f(ω)` for the unit world direction `direction` (0 for an invalid factor).
    pub fn value(&self, direction: Vec3) -> f32 {
        match self.normalized() {
            Some(factor) => factor.unit_value(direction),
            None => 0.0,
        }
    }

    /// [`Self::value`] of a factor already normalised.
    fn unit_value(&self, direction: Vec3) -> f32 {
        match *self {
            Factor::Cosine { normal } => normal.dot(direction).max(0.0),
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => {
                let cos = normal.dot(direction);
                if !(cos > 0.0 && cos.is_finite()) {
                    return 0.0;
                }
                let r = reflect(outgoing, normal);
                let alpha2 = roughness as f64 * roughness as f64;
                (cos as f64 * lobe_proxy(alpha2, r.dot(direction) as f64)) as f32
            }
        }
    }
}

/// The mirror direction of the unit vector `outgoing` about the unit `normal`,
/// `2 (n·ωo) n - ωo`, renormalised against rounding (it is a unit vector).
fn reflect(outgoing: Vec3, normal: Vec3) -> Vec3 {
    let r = normal * (2.0 * normal.dot(outgoing)) - outgoing;
    r.normalized().unwrap_or(normal)
}

/// The GGX lobe proxy `D_α(γ/2)` from `cos γ`, with `α² = alpha2`:
/// `cos²(γ/2) = (1 + cos γ) / 2`, so no trigonometry. Non-increasing in `γ`.
#[inline]
fn lobe_proxy(alpha2: f64, cos_gamma: f64) -> f64 {
    let cos2_half = 0.5 * (1.0 + cos_gamma.clamp(-1.0, 1.0));
    let d = cos2_half * (alpha2 - 1.0) + 1.0;
    alpha2 / (PI * d * d)
}

/// A cone of directions in the light frame: every direction within `half_angle`
/// of the unit `axis`, stored as the half-angle's cosine and sine.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Cone {
    axis: [f64; 3],
    cos_half: f64,
    sin_half: f64,
}

impl Cone {
    /// The whole sphere.
    const FULL: Cone = Cone {
        axis: [0.0, 0.0, 1.0],
        cos_half: -1.0,
        sin_half: 0.0,
    };

    /// `max_{ω in cone} v·ω = cos(max(0, α - h))` for a unit `v` at angle `α` from
    /// the axis: 1 when `α ≤ h`, else `cos α cos h + sin α sin h` (which may be
    /// negative). `sin α` is read off the cross product, exact near `α = 0`.
    #[inline]
    fn max_cos(&self, v: [f64; 3]) -> f64 {
        let cos = dot(v, self.axis);
        if cos >= self.cos_half {
            return 1.0;
        }
        let sin = norm(cross(v, self.axis));
        cos * self.cos_half + sin * self.sin_half
    }
}

/// A patch of a lat-long light as the box `φ ∈ [φ0, φ1]`, `θ ∈ [θ0, θ1]` it is in
/// the light frame (`φ = 2π u`, `θ = π v`), for an exact bound of `v·ω` over it.
#[derive(Debug, Clone, Copy, PartialEq)]
struct LatLongBox {
    /// `(cos φ0, sin φ0)` and `(cos φ1, sin φ1)`.
    edge0: [f64; 2],
    edge1: [f64; 2],
    /// `φ1 - φ0 < π`, where the test of which side of the edges a direction lies
    /// on decides whether its azimuth is inside.
    narrow: bool,
    /// `(sin θ0, cos θ0)` and `(sin θ1, cos θ1)`.
    top: (f64, f64),
    bottom: (f64, f64),
}

impl LatLongBox {
    fn new(u: [f64; 2], v: [f64; 2]) -> Self {
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

/// One level of the patch pyramid.
#[derive(Debug, Clone)]
struct Level {
    /// Nodes across and down.
    size: [usize; 2],
    /// Node `(i, j)` at `j size[0] + i`: its power and bounding regions.
    nodes: Vec<Patch>,
}

/// Added to [`LatLongBox::max_dot`] for the rounding of f32 directions and of the
/// rotation into the light frame (about 1e-7 each).
const BOX_SLACK: f64 = 1e-5;

/// A patch's share of the fine importance and the regions bounding its directions.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Patch {
    /// `P_k = F_k / Σ F`.
    power: f64,
    cone: Cone,
    /// On a lat-long light, the patch's exact extent in angles.
    latlong: Option<LatLongBox>,
}

impl Patch {
    /// An upper bound of `v·ω` over the patch, for a unit `v` with `ρ = |v_xy|`:
    /// the lat-long box's exact maximum (plus rounding slack) where there is one,
    /// which is never above the cone's, else the cone's.
    #[inline]
    fn max_dot(&self, v: &Direction) -> f64 {
        match &self.latlong {
            Some(b) => b.max_dot(v.v, v.rho) + BOX_SLACK,
            None => self.cone.max_cos(v.v),
        }
    }
}

/// A unit vector in the light frame and the length of its xy part.
#[derive(Debug, Clone, Copy)]
struct Direction {
    v: [f64; 3],
    rho: f64,
}

impl Direction {
    fn new(v: [f64; 3]) -> Self {
        Self {
            v,
            rho: (v[0] * v[0] + v[1] * v[1]).sqrt(),
        }
    }
}

/// A factor prepared for patch bounds: its vectors in the light frame.
#[derive(Debug, Clone, Copy)]
struct Target {
    normal: Direction,
    /// The mirror direction and `α²` of a glossy factor.
    lobe: Option<(Direction, f64)>,
}

impl Target {
    /// `B_k`: an upper bound of the factor over every direction of `patch`. The
    /// product of the bounds of its non-negative parts: the cosine's, `max(0, max
    /// n·ω)`, and the lobe's, `D_α` at the largest `r·ω` (`D_α` falls as the
    /// angle `γ` to the mirror direction `r` grows), each maximum over the patch's
    /// cone (`cos(max(0, α - h))` for a vector at angle `α` from its axis) or,
    /// tighter, over its exact lat-long box.
    #[inline(always)]
    fn bound(&self, patch: &Patch) -> f64 {
        let cosine = patch.max_dot(&self.normal).max(0.0);
        match &self.lobe {
            Some((reflected, alpha2)) if cosine > 0.0 => {
                cosine * lobe_proxy(*alpha2, patch.max_dot(reflected).min(1.0))
            }
            _ => cosine,
        }
    }
}

/// Samples directions at a shading point in proportion to (a close bound of) the
/// light's radiance times a [`Factor`], with the exact pdf (DESIGN.md §6a; the
/// module docs give the scheme and the pdf's formula).
///
/// Guarantees: [`ShadingPoint::pdf`] is the density of [`ShadingPoint::sample`]
/// (`pdf(sample(ξ).direction) == sample(ξ).pdf` to float precision); it integrates
/// to 1; it is positive wherever the light's radiance and the factor are both
/// positive (except at the poles of a lat-long map); a black map, an invalid factor,
/// or a factor that is 0 over all the light samples nothing (`None`, pdf 0).
///
/// Cost: building is `O(w h)` (rows in parallel) plus two bounding regions per
/// pyramid node; each shading point ([`Self::at`]) one bound per cut node (about
/// 3 µs for the default cut of 512 on one core); each sample and each pdf four
/// bounds per pyramid level below the cut, and binary searches for the row and
/// texel, without allocation (BENCHMARKS.md has the measured trade-offs).
///
/// Memory: a fixed-point CDF entry per texel plus one per row segment and per patch
/// row, `4 h (w + Pw) + 4 Pw (h + Ph)` bytes (about `4 + 8 Pw / w` bytes per
/// texel), `4 (w + h)` bytes of index tables, and the pyramid's nodes
/// (`Pw Ph · 4/3` of them, about 1.5 MB at 128 × 64 patches); see
/// [`Self::memory_bytes`].
///
/// ```
/// use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
/// use envlight::product::{Factor, ProductOptions, ProductSampler};
/// use std::sync::Arc;
///
/// let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
/// let sampler = ProductSampler::new(Arc::new(light), ProductOptions::default());
/// let point = sampler.at(&Factor::cosine(Vec3::new(0.0, 0.0, 1.0)));
/// let s = point.sample([0.3, 0.6]).expect("the sky lights an upward surface");
/// assert!((point.pdf(s.direction) - s.pdf).abs() <= 1e-4 * s.pdf);
/// // Well below the surface nothing is sampled, though the ground there is lit.
/// let below = Vec3::new(1.0, 0.0, -1.0).normalized().unwrap();
/// assert!(sampler.light().pdf(below) > 0.0 && point.pdf(below) == 0.0);
/// ```
#[derive(Debug, Clone)]
pub struct ProductSampler {
    light: Arc<EnvironmentLight>,
    /// The light image's `[w, h]`.
    size: [usize; 2],
    /// `[Pw, Ph]`.
    patches: [usize; 2],
    /// First texel column of each patch column, `Pw + 1` entries (`c w / Pw`).
    col_start: Vec<u32>,
    /// First texel row of each patch row, `Ph + 1` entries (`r h / Ph`).
    row_start: Vec<u32>,
    /// The patch column of each texel column (`w` entries).
    col_patch: Vec<u32>,
    /// The patch row of each texel row (`h` entries).
    row_patch: Vec<u32>,
    /// Fixed-point CDFs of the row segments: row `j`, patch column `c` (texels
    /// `x0..x1`) at `j (w + Pw) + x0 + c`, `x1 - x0 + 1` entries.
    segment_cdf: Vec<u32>,
    /// Fixed-point CDFs over each patch's rows (of its row segments' sums): patch
    /// `(c, r)` (rows `y0..y1`) at `Pw (y0 + r) + c (y1 - y0 + 1)`, `y1 - y0 + 1`
    /// entries.
    marginal_cdf: Vec<u32>,
    /// Patch `k = r Pw + c`: the leaves of the pyramid.
    patch: Vec<Patch>,
    /// The levels above the patches, root (1 × 1) first: node `(i, j)` of a level
    /// holds the patches of columns `[i 2^d, (i + 1) 2^d)` and rows
    /// `[j 2^d, (j + 1) 2^d)` (clipped), `d` levels above them; its children are
    /// the nodes `(2i + a, 2j + b)`, `a, b ∈ {0, 1}`, of the level below.
    pyramid: Vec<Level>,
    /// The cut: the nodes whose weights a shading point computes all at once, as
    /// `(level, i, j)` (level an index into the pyramid, or its length for the
    /// patches), every lit patch under exactly one of them.
    cut: Vec<(usize, usize, usize)>,
    /// The cut's nodes, in its order, side by side (what every shading point reads).
    cut_nodes: Vec<Patch>,
    /// For each patch, the index of the cut node above it (`u32::MAX` for a
    /// patch without power).
    patch_cut: Vec<u32>,
    /// `w h / CDF_ONE²`: a texel's density in `(u, v)` given its patch is its two
    /// CDF widths times this.
    planar_scale: f64,
    /// How patches are weighted.
    bound: PatchBound,
}

impl ProductSampler {
    /// Builds the two levels for `light` (rows in parallel). A black map gives a
    /// sampler that samples nothing.
    pub fn new(light: Arc<EnvironmentLight>, options: ProductOptions) -> Self {
        let (w, h) = (light.image().width(), light.image().height());
        let [pw, ph] = options
            .patches
            .unwrap_or_else(|| ProductOptions::default_patches(light.mapping()));
        let (pw, ph) = (pw.clamp(1, w), ph.clamp(1, h));
        // Texel counts fit in u32: an image side is at most 2²⁴ (image::MAX_SIDE).
        let starts = |n: usize, parts: usize| -> Vec<u32> {
            (0..=parts).map(|p| (p * n / parts) as u32).collect()
        };
        let (col_start, row_start) = (starts(w, pw), starts(h, ph));
        let owners = |start: &[u32], n: usize| -> Vec<u32> {
            let mut owner = vec![0u32; n];
            for (p, edges) in start.windows(2).enumerate() {
                owner[edges[0] as usize..edges[1] as usize].fill(p as u32);
            }
            owner
        };
        let (col_patch, row_patch) = (owners(&col_start, w), owners(&row_start, h));

        // The fine level, one band of patch rows per task: each band's CDFs are
        // contiguous runs of both arrays.
        let mut segment_cdf = vec![0u32; h * (w + pw)];
        let mut marginal_cdf = vec![0u32; pw * (h + ph)];
        let mut bands = Vec::with_capacity(ph);
        let (mut segments, mut marginals) = (&mut segment_cdf[..], &mut marginal_cdf[..]);
        for r in 0..ph {
            let (y0, y1) = (row_start[r] as usize, row_start[r + 1] as usize);
            let (band_segments, rest) =
                std::mem::take(&mut segments).split_at_mut((y1 - y0) * (w + pw));
            segments = rest;
            let (band_marginals, rest) =
                std::mem::take(&mut marginals).split_at_mut(pw * (y1 - y0 + 1));
            marginals = rest;
            bands.push((y0..y1, band_segments, band_marginals));
        }
        let band_sums: Vec<Vec<f64>> = bands
            .into_par_iter()
            .map(|(rows, segments, marginals)| {
                build_band(&light, &col_start, rows, segments, marginals)
            })
            .collect();
        let sums: Vec<f64> = band_sums.concat();
        let total: f64 = sums.iter().sum();
        let inv_total = if total > 0.0 && total.is_finite() {
            1.0 / total
        } else {
            0.0
        };

        // Each patch's lit texels, as the smallest texel rectangle `[x0, x1) ×
        // [y0, y1)` holding them: a row is lit when its marginal width is not 0,
        // and a texel of a lit row when its segment width is not 0.
        let width = |cdf: &[u32], o: usize| cdf[o + 1] - cdf[o];
        let lit: Vec<Option<[usize; 4]>> = (0..pw * ph)
            .into_par_iter()
            .map(|k| {
                let (c, r) = (k % pw, k / pw);
                let (x0, x1) = (col_start[c] as usize, col_start[c + 1] as usize);
                let (y0, y1) = (row_start[r] as usize, row_start[r + 1] as usize);
                let at = pw * (y0 + r) + c * (y1 - y0 + 1);
                let marginal = &marginal_cdf[at..at + y1 - y0 + 1];
                let mut rect: Option<[usize; 4]> = None;
                for j in y0..y1 {
                    if width(marginal, j - y0) == 0 {
                        continue;
                    }
                    let at = j * (w + pw) + x0 + c;
                    let segment = &segment_cdf[at..at + x1 - x0 + 1];
                    let first = (0..x1 - x0).find(|&o| width(segment, o) > 0);
                    let last = (0..x1 - x0).rev().find(|&o| width(segment, o) > 0);
                    if let (Some(f), Some(l)) = (first, last) {
                        rect = Some(union(rect, [x0 + f, x0 + l + 1, j, j + 1]));
                    }
                }
                rect
            })
            .collect();
        let latlong = light.mapping() == Mapping::Equirectangular;
        // A node of power P over the lit rectangle `rect`: its bounding cone and,
        // on a lat-long light, its exact box.
        let node = |power: f64, rect: Option<[usize; 4]>| match rect {
            Some([x0, x1, y0, y1]) if power > 0.0 => {
                let u = [x0 as f64 / w as f64, x1 as f64 / w as f64];
                let v = [y0 as f64 / h as f64, y1 as f64 / h as f64];
                Patch {
                    power,
                    cone: bounding_cone(&light, u, v),
                    latlong: latlong.then(|| LatLongBox::new(u, v)),
                }
            }
            _ => Patch {
                power: 0.0,
                cone: Cone::FULL,
                latlong: None,
            },
        };
        let patch: Vec<Patch> = sums
            .par_iter()
            .zip(lit.par_iter())
            .map(|(&sum, &rect)| node(sum * inv_total, rect))
            .collect();

        // The levels above: a node's power is the sum of its patches', its lit
        // rectangle the smallest holding theirs.
        let mut pyramid = Vec::new();
        let mut span = 1usize;
        while span < pw.max(ph) {
            span *= 2;
            let size = [pw.div_ceil(span), ph.div_ceil(span)];
            let nodes = (0..size[0] * size[1])
                .into_par_iter()
                .map(|k| {
                    let (i, j) = (k % size[0], k / size[0]);
                    let (c0, c1) = (i * span, ((i + 1) * span).min(pw));
                    let (r0, r1) = (j * span, ((j + 1) * span).min(ph));
                    let mut power = 0.0;
                    let mut rect = None;
                    for r in r0..r1 {
                        for c in c0..c1 {
                            power += patch[r * pw + c].power;
                            if let Some(l) = lit[r * pw + c] {
                                rect = Some(union(rect, l));
                            }
                        }
                    }
                    node(power, rect)
                })
                .collect();
            pyramid.push(Level { size, nodes });
        }
        if pyramid.is_empty() {
            // A single patch: the root above it is the same region.
            pyramid.push(Level {
                size: [1, 1],
                nodes: vec![patch[0]],
            });
        }
        pyramid.reverse();
        // The cut: from the root down, a node holding more than 1/top_nodes of the
        // power is replaced by its children, until the patches.
        let top_nodes = options
            .top_nodes
            .unwrap_or(ProductOptions::DEFAULT_TOP_NODES)
            .max(1);
        let depth = pyramid.len();
        let level_of = |level: usize| -> (&[Patch], [usize; 2]) {
            match pyramid.get(level) {
                Some(l) => (&l.nodes, l.size),
                None => (&patch, [pw, ph]),
            }
        };
        let mut cut = Vec::new();
        let mut stack = vec![(0usize, 0usize, 0usize)];
        while let Some((level, i, j)) = stack.pop() {
            let (nodes, size) = level_of(level);
            let power = nodes[j * size[0] + i].power;
            if power.is_nan() || power <= 0.0 {
                continue;
            }
            if level == depth || power <= 1.0 / top_nodes as f64 {
                cut.push((level, i, j));
                continue;
            }
            let below = level_of(level + 1).1;
            for (a, b) in [(1, 1), (0, 1), (1, 0), (0, 0)] {
                if 2 * i + a < below[0] && 2 * j + b < below[1] {
                    stack.push((level + 1, 2 * i + a, 2 * j + b));
                }
            }
        }
        let mut patch_cut = vec![u32::MAX; patch.len()];
        for (index, &(level, i, j)) in cut.iter().enumerate() {
            let shift = depth - level;
            for r in (j << shift)..((j + 1) << shift).min(ph) {
                for c in (i << shift)..((i + 1) << shift).min(pw) {
                    patch_cut[r * pw + c] = index as u32;
                }
            }
        }
        let cut_nodes = cut
            .iter()
            .map(|&(level, i, j)| {
                let (nodes, size) = level_of(level);
                nodes[j * size[0] + i]
            })
            .collect();
        Self {
            pyramid,
            cut,
            cut_nodes,
            patch_cut,
            planar_scale: (w as f64 / CDF_ONE as f64) * (h as f64 / CDF_ONE as f64),
            bound: options.bound,
            light,
            size: [w, h],
            patches: [pw, ph],
            col_start,
            row_start,
            col_patch,
            row_patch,
            segment_cdf,
            marginal_cdf,
            patch,
        }
    }

    /// The light sampled.
    pub fn light(&self) -> &EnvironmentLight {
        &self.light
    }

    /// The patch grid `[Pw, Ph]` in use (after clamping to the image).
    pub fn patches(&self) -> [usize; 2] {
        self.patches
    }

    /// Nodes in the cut (what [`Self::at`] weighs; see [`ProductOptions::top_nodes`]).
    pub fn cut_len(&self) -> usize {
        self.cut.len()
    }

    /// True when the light's importance is zero everywhere: nothing is ever sampled.
    pub fn is_black(&self) -> bool {
        !self.patch.iter().any(|p| p.power > 0.0)
    }

    /// Bytes of sampling data held (CDFs, index tables and patches; not the light).
    pub fn memory_bytes(&self) -> usize {
        4 * (self.segment_cdf.len()
            + self.marginal_cdf.len()
            + self.col_start.len()
            + self.row_start.len()
            + self.col_patch.len()
            + self.row_patch.len()
            + self.patch_cut.len())
            + std::mem::size_of::<Patch>()
                * (self.patch.len()
                    + self.cut_nodes.len()
                    + self.pyramid.iter().map(|l| l.nodes.len()).sum::<usize>())
            + std::mem::size_of::<(usize, usize, usize)>() * self.cut.len()
    }

    /// The sampling state at a shading point with factor `factor`: the factor's
    /// vectors in the light frame and the running sums of the weights of the
    /// pyramid's cut (about [`ProductOptions::top_nodes`] nodes). Cost
    /// one bound per top node and one allocation; [`ShadingPoint::set_factor`]
    /// moves an existing state to another point without allocating.
    pub fn at(&self, factor: &Factor) -> ShadingPoint<'_> {
        let mut point = self.empty_point();
        point.set_factor(factor);
        point
    }

    /// A shading point with no (a zero) factor, which samples nothing.
    fn empty_point(&self) -> ShadingPoint<'_> {
        ShadingPoint {
            sampler: self,
            factor: None,
            target: None,
            running: vec![0.0; self.cut.len() + 1],
        }
    }

    /// [`ShadingPoint::sample`] at a shading point used once.
    pub fn sample(&self, factor: &Factor, xi: [f32; 2]) -> Option<LightSample> {
        self.at(factor).sample(xi)
    }

    /// [`ShadingPoint::pdf`] at a shading point used once (see [`Self::sample`]).
    pub fn pdf(&self, factor: &Factor, direction: Vec3) -> f32 {
        self.at(factor).pdf(direction)
    }

    /// One sample per shading point: `out[i] = self.sample(&factors[i], xi[i])`, in
    /// parallel, each thread reusing one [`ShadingPoint`] (runs of equal factors
    /// set it up once). Each result depends only on its own inputs, so the output
    /// is the same for any thread count.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn sample_batch(
        &self,
        factors: &[Factor],
        xi: &[[f32; 2]],
        out: &mut [Option<LightSample>],
    ) {
        self.per_point(factors, xi, out, |point, &xi| point.sample(xi));
    }

    /// `out[i] = self.pdf(&factors[i], directions[i])`, in parallel, as
    /// [`Self::sample_batch`].
    ///
    /// # Panics
    /// When the slices differ in length.
    pub fn pdf_batch(&self, factors: &[Factor], directions: &[Vec3], out: &mut [f32]) {
        self.per_point(factors, directions, out, |point, &d| point.pdf(d));
    }

    /// `out[i] = query(shading point of factors[i], &input[i])` in parallel, each
    /// thread reusing one [`ShadingPoint`] (runs of equal factors set it up once).
    fn per_point<I: Sync, O: Send>(
        &self,
        factors: &[Factor],
        input: &[I],
        out: &mut [O],
        query: impl Fn(&ShadingPoint, &I) -> O + Sync,
    ) {
        assert!(
            factors.len() == input.len() && input.len() == out.len(),
            "batch input and output lengths differ"
        );
        out.par_iter_mut()
            .zip(factors.par_iter().zip(input.par_iter()))
            .with_min_len(64)
            .for_each_init(
                || self.empty_point(),
                |point, (o, (factor, x))| {
                    point.set_factor(factor);
                    *o = query(point, x);
                },
            );
    }

    /// The nodes of pyramid level `level` (the patches below the last level) and
    /// how many across.
    #[inline]
    fn level(&self, level: usize) -> (&[Patch], usize) {
        match self.pyramid.get(level) {
            Some(l) => (&l.nodes, l.size[0]),
            None => (&self.patch, self.patches[0]),
        }
    }

    /// Node `(i, j)` of pyramid level `level` (the patches below the last level).
    #[inline]
    fn node(&self, level: usize, i: usize, j: usize) -> &Patch {
        let (nodes, across) = self.level(level);
        &nodes[j * across + i]
    }

    /// `w = P · B` for a node: its power times the factor's bound over it (the
    /// bound at the cone's axis alone for [`PatchBound::AxisOnly`]).
    #[inline]
    fn weight(&self, target: &Target, node: &Patch) -> f64 {
        if node.power.is_nan() || node.power <= 0.0 {
            return 0.0;
        }
        let bound = if self.bound == PatchBound::AxisOnly {
            target.bound(&Patch {
                cone: Cone {
                    cos_half: 1.0,
                    sin_half: 0.0,
                    ..node.cone
                },
                latlong: None,
                ..*node
            })
        } else {
            target.bound(node)
        };
        node.power * bound
    }

    /// The weights of the (up to 2 × 2) children of node `(i, j)` of level
    /// `level`, `[row][column]` (0 where a child is missing), and the index of the
    /// first child. When every child's weight is 0 though the node's own was not (rounding, or a cone looser than its children's),
    /// the children are weighted by their power alone, so that every node with
    /// weight leads somewhere: sampling and [`ShadingPoint::pdf`] both use this
    /// one function, so they agree, and the pdf integrates to 1.
    #[inline]
    fn child_weights(
        &self,
        target: &Target,
        level: usize,
        i: usize,
        j: usize,
    ) -> ([[f64; 2]; 2], [usize; 2]) {
        let below = match self.pyramid.get(level + 1) {
            Some(l) => l.size,
            None => self.patches,
        };
        let first = [2 * i, 2 * j];
        let mut w = [[0.0f64; 2]; 2];
        let mut any = false;
        for (b, row) in w.iter_mut().enumerate() {
            for (a, x) in row.iter_mut().enumerate() {
                let (ci, cj) = (first[0] + a, first[1] + b);
                if ci < below[0] && cj < below[1] {
                    *x = self.weight(target, self.node(level + 1, ci, cj));
                    any |= *x > 0.0;
                }
            }
        }
        if !any {
            for (b, row) in w.iter_mut().enumerate() {
                for (a, x) in row.iter_mut().enumerate() {
                    let (ci, cj) = (first[0] + a, first[1] + b);
                    if ci < below[0] && cj < below[1] {
                        *x = self.node(level + 1, ci, cj).power.max(0.0);
                    }
                }
            }
        }
        (w, first)
    }

    /// A normalised factor's vectors in the light frame.
    fn target(&self, factor: &Factor) -> Target {
        let local = |v: Vec3| {
            let d = self.light.world_to_local(v);
            Direction::new([d.x as f64, d.y as f64, d.z as f64])
        };
        match *factor {
            Factor::Cosine { normal } => Target {
                normal: local(normal),
                lobe: None,
            },
            Factor::Glossy {
                normal,
                outgoing,
                roughness,
            } => Target {
                normal: local(normal),
                lobe: Some((
                    local(reflect(outgoing, normal)),
                    roughness as f64 * roughness as f64,
                )),
            },
        }
    }

    /// Patch `k`'s texel columns `x0..x1` and rows `y0..y1`.
    #[inline]
    fn patch_texels(&self, k: usize) -> ([usize; 2], [usize; 2]) {
        let pw = self.patches[0];
        let (c, r) = (k % pw, k / pw);
        (
            [self.col_start[c] as usize, self.col_start[c + 1] as usize],
            [self.row_start[r] as usize, self.row_start[r + 1] as usize],
        )
    }

    /// Patch `k`'s CDF over its rows.
    #[inline]
    fn marginal(&self, k: usize) -> &[u32] {
        let pw = self.patches[0];
        let (c, r) = (k % pw, k / pw);
        let (y0, y1) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
        let at = pw * (y0 + r) + c * (y1 - y0 + 1);
        &self.marginal_cdf[at..at + y1 - y0 + 1]
    }

    /// Row `j`'s CDF over the texels of patch column `c`.
    #[inline]
    fn segment(&self, j: usize, c: usize) -> &[u32] {
        let (x0, x1) = (self.col_start[c] as usize, self.col_start[c + 1] as usize);
        let at = j * (self.size[0] + self.patches[0]) + x0 + c;
        &self.segment_cdf[at..at + x1 - x0 + 1]
    }

    /// The density in `(u, v)` of a texel whose patch has probability
    /// `patch_probability` and whose row and texel CDF widths (within the patch,
    /// within the row segment) are `wv` and `wu`. Sampling and [`ShadingPoint::pdf`]
    /// both go through here, so they agree to the bit.
    #[inline(always)]
    fn planar_density(&self, patch_probability: f64, wv: u32, wu: u32) -> f32 {
        (patch_probability * (wv as f64 * wu as f64) * self.planar_scale) as f32
    }
}

/// The sampling state at one shading point: the factor, in the light frame too,
/// and the weight of the pyramid's top. Made by [`ProductSampler::at`]; `O(1)`.
#[derive(Debug, Clone)]
pub struct ShadingPoint<'a> {
    sampler: &'a ProductSampler,
    /// The normalised factor, `None` when the factor given was invalid.
    factor: Option<Factor>,
    /// Its vectors in the light frame.
    target: Option<Target>,
    /// Over the nodes of the sampler's cut: `running[0] = 0`,
    /// `running[k + 1] = running[k] + w_k`, except that a node with `w_k > 0` too
    /// small to change the sum adds one ulp instead, so every node with weight
    /// keeps a non-empty interval. `running[K] = Σw`.
    running: Vec<f64>,
}

impl ShadingPoint<'_> {
    /// Moves this state to a shading point with factor `factor` (`O(1)`; nothing
    /// when the normalised factor is unchanged).
    pub fn set_factor(&mut self, factor: &Factor) {
        let factor = factor.normalized();
        // Bit for bit, so that skipping the work never changes a result (as
        // `-0.0 == 0.0` could).
        if bits(&factor) == bits(&self.factor) {
            return;
        }
        self.factor = factor;
        self.target = factor.map(|f| self.sampler.target(&f));
        let Some(target) = &self.target else {
            self.running.fill(0.0);
            return;
        };
        let sampler = self.sampler;
        let mut sum = 0.0f64;
        for (node, running) in sampler.cut_nodes.iter().zip(&mut self.running[1..]) {
            let weight = sampler.weight(target, node);
            let next = sum + weight;
            sum = if weight > 0.0 && next == sum {
                sum.next_up()
            } else {
                next
            };
            *running = sum;
        }
    }

    /// The normalised factor of this shading point, `None` when the one given was
    /// invalid.
    pub fn factor(&self) -> Option<&Factor> {
        self.factor.as_ref()
    }

    /// `Σ P_k B_k` over the nodes of the cut: an upper bound of the factor's
    /// mean `E[f(ω)]` over directions drawn from the light's piecewise-constant
    /// importance alone. 0 when nothing can be sampled: a black map, an invalid
    /// factor, or a factor that is 0 over the whole light.
    pub fn weight_sum(&self) -> f64 {
        self.running[self.running.len() - 1]
    }

    /// Draws a world direction for `ξ ∈ [0, 1)²` with density [`Self::pdf`]. `ξ₁`
    /// picks a node of the cut by the running sums of its weights; below
    /// it, each node's children are chosen by their weights `P B`, the row of
    /// children with `ξ₁` and the child within it with `ξ₀` (each rescaled to the
    /// choice's share after use, as a hierarchical warp); in the patch
    /// reached, `ξ₁` picks the row and `ξ₀` the texel and the point within it from
    /// the light's importance. The radiance is the light's lookup at the sample's
    /// image point, `uv`.
    ///
    /// `None` when nothing can be sampled ([`Self::weight_sum`] is 0), or when the
    /// point falls exactly on a pole of a lat-long map (measure zero).
    pub fn sample(&self, xi: [f32; 2]) -> Option<LightSample> {
        let sampler = self.sampler;
        let target = self.target.as_ref()?;
        let total = self.weight_sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        // `max` also maps a NaN ξ to 0.
        #[allow(clippy::manual_clamp)]
        let clamp = |x: f32| x.max(0.0).min(ONE_MINUS_EPSILON) as f64;
        let (mut x, mut y) = (clamp(xi[0]), clamp(xi[1]));
        // The cut node k with running[k] <= t < running[k + 1] (such an interval is
        // never empty).
        let t = y * total;
        let last = self.running.len() - 2;
        let k = self.running[1..=last].partition_point(|&s| s <= t);
        let (lo, hi) = (self.running[k], self.running[k + 1]);
        y = ((t - lo) / (hi - lo)).clamp(0.0, ONE_MINUS_EPSILON as f64);
        let mut probability = (hi - lo) / total;
        let (top, mut i, mut j) = sampler.cut[k];
        for level in top..sampler.pyramid.len() {
            let (w, first) = sampler.child_weights(target, level, i, j);
            let rows = [w[0][0] + w[0][1], w[1][0] + w[1][1]];
            let total = rows[0] + rows[1];
            if total.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
                return None;
            }
            let b;
            (b, y) = choose(y, rows);
            let a;
            (a, x) = choose(x, w[b]);
            probability *= w[b][a] / total;
            (i, j) = (first[0] + a, first[1] + b);
        }
        let k = j * sampler.patches[0] + i;

        let ([x0, _], [y0, _]) = sampler.patch_texels(k);
        let (row, frac_v, wv) = sample_cdf(sampler.marginal(k), y as f32);
        let r = y0 + row;
        let (column, frac_u, wu) = sample_cdf(sampler.segment(r, i), x as f32);
        let t = x0 + column;
        let [w, h] = sampler.size;
        let uv = [
            place_in_cell_f64(t, frac_u, w),
            place_in_cell_f64(r, frac_v, h),
        ];

        let planar = sampler.planar_density(probability, wv, wu);
        let light = &sampler.light;
        let (local, jacobian) = light.uv_to_local(uv);
        let pdf = planar / jacobian;
        if !(jacobian > 0.0 && is_positive_finite(pdf)) {
            return None;
        }
        Some(LightSample {
            direction: light.local_to_world(local),
            pdf,
            radiance: light.radiance_at_uv(uv),
            uv,
        })
    }

    /// The solid-angle density (per steradian) with which [`Self::sample`] produces
    /// the world unit direction `direction`: the product of the choices from the
    /// cut down to the patch `k` of the direction's texel `t`, times
    /// `(f_t / F_k) · w h / J(ω)`. 0 where the light's importance or a bound on the
    /// way is 0, at the poles of a lat-long map, and when nothing can be sampled.
    #[inline]
    pub fn pdf(&self, direction: Vec3) -> f32 {
        let sampler = self.sampler;
        let Some(target) = self.target.as_ref() else {
            return 0.0;
        };
        let total = self.weight_sum();
        if !(total > 0.0 && total.is_finite()) {
            return 0.0;
        }
        let light = &sampler.light;
        let (uv, inv_jacobian) = light.local_to_uv(light.world_to_local(direction));
        let [w, h] = sampler.size;
        let (t, r) = (cell_index(uv[0], w), cell_index(uv[1], h));
        let (c, p) = (sampler.col_patch[t] as usize, sampler.row_patch[r] as usize);
        let depth = sampler.pyramid.len();
        let k = sampler.patch_cut[p * sampler.patches[0] + c];
        if k == u32::MAX {
            return 0.0;
        }
        let k = k as usize;
        let top = sampler.cut[k].0;
        let mut probability = (self.running[k + 1] - self.running[k]) / total;
        for level in top..depth {
            // The ancestors of patch (c, p) one and two levels down.
            let shift = depth - level;
            let (i, j) = (c >> shift, p >> shift);
            let (w, first) = sampler.child_weights(target, level, i, j);
            let rows = [w[0][0] + w[0][1], w[1][0] + w[1][1]];
            let total = rows[0] + rows[1];
            let (a, b) = ((c >> (shift - 1)) - first[0], (p >> (shift - 1)) - first[1]);
            if !(total > 0.0 && w[b][a] > 0.0) {
                return 0.0;
            }
            probability *= w[b][a] / total;
        }
        let k = p * sampler.patches[0] + c;
        let ([x0, _], [y0, _]) = sampler.patch_texels(k);
        let width = |cdf: &[u32], o: usize| cdf[o + 1] - cdf[o];
        let wv = width(sampler.marginal(k), r - y0);
        let wu = width(sampler.segment(r, c), t - x0);
        let planar = sampler.planar_density(probability, wv, wu);
        solid_angle_density(planar, inv_jacobian)
    }
}

/// Picks entry 0 or 1 of `weights` with probability proportional to it for
/// `x ∈ [0, 1)` (never an entry of weight 0 when the other has weight), and
/// returns `x` rescaled to `[0, 1)` within the pick's share.
#[inline]
fn choose(x: f64, weights: [f64; 2]) -> (usize, f64) {
    let total = weights[0] + weights[1];
    let t = x * total;
    let (pick, rescaled) = if weights[1] == 0.0 || (t < weights[0] && weights[0] > 0.0) {
        (0, t / weights[0])
    } else {
        (1, (t - weights[0]) / weights[1])
    };
    (pick, rescaled.clamp(0.0, ONE_MINUS_EPSILON as f64))
}

/// The bits of an optional factor, for exact comparison.
fn bits(factor: &Option<Factor>) -> Option<(u8, [u32; 7])> {
    let v = |v: Vec3| v.to_array().map(f32::to_bits);
    factor.map(|f| match f {
        Factor::Cosine { normal } => {
            let [x, y, z] = v(normal);
            (0, [x, y, z, 0, 0, 0, 0])
        }
        Factor::Glossy {
            normal,
            outgoing,
            roughness,
        } => {
            let ([x, y, z], [a, b, c]) = (v(normal), v(outgoing));
            (1, [x, y, z, a, b, c, roughness.to_bits()])
        }
    })
}

/// Continuous sample of a fixed-point CDF (`n + 1` entries from 0 to [`CDF_ONE`]):
/// the cell `o` with `c[o] ≤ ξ·CDF_ONE < c[o + 1]` (never a cell of zero width), the
/// offset of `ξ` within it in `[0, 1)`, and its width.
#[inline]
fn sample_cdf(cdf: &[u32], xi: f32) -> (usize, f64, u32) {
    let n = cdf.len() - 1;
    // `max` also maps NaN to 0.
    let t = (xi as f64 * CDF_ONE as f64)
        .max(0.0)
        .min((CDF_ONE - 1) as f64);
    let x = t as u32;
    let o = cdf[1..n].partition_point(|&c| c <= x);
    let (lo, hi) = (cdf[o], cdf[o + 1]);
    (o, (t - lo as f64) / (hi - lo) as f64, hi - lo)
}

/// Builds the fine level of one band of patch rows (texel rows `rows`): each row's
/// segment CDFs into `segments` and each patch's CDF over its rows into
/// `marginals` (laid out as in [`ProductSampler`]). Returns each patch's importance
/// sum `F_k`, patch columns in order.
fn build_band(
    light: &EnvironmentLight,
    col_start: &[u32],
    rows: std::ops::Range<usize>,
    segments: &mut [u32],
    marginals: &mut [u32],
) -> Vec<f64> {
    let w = light.image().width();
    let pw = col_start.len() - 1;
    let n = rows.len();
    let mut importance = vec![0.0f32; n * w];
    light.importance_rows(rows.start, &mut importance);
    // row_sums[c n + jj]: the sum of row jj's segment in patch column c.
    let mut row_sums = vec![0.0f64; pw * n];
    for (jj, (row, out)) in importance
        .chunks_exact(w)
        .zip(segments.chunks_exact_mut(w + pw))
        .enumerate()
    {
        for c in 0..pw {
            let (x0, x1) = (col_start[c] as usize, col_start[c + 1] as usize);
            let segment = Distribution1D::new(&row[x0..x1]);
            out[x0 + c..=x1 + c].copy_from_slice(segment.cdf());
            row_sums[c * n + jj] = segment.integral() * (x1 - x0) as f64;
        }
    }
    let mut weights = vec![0.0f32; n];
    (0..pw)
        .map(|c| {
            let sums = &row_sums[c * n..(c + 1) * n];
            // Relative to the largest, so that f32 neither overflows nor (but for
            // the odd subnormal, kept positive) underflows: a row with importance
            // must keep a CDF width of at least one unit.
            let max = sums.iter().fold(0.0f64, |a, &b| a.max(b));
            for (weight, &sum) in weights.iter_mut().zip(sums) {
                *weight = if sum > 0.0 {
                    ((sum / max) as f32).max(f32::from_bits(1))
                } else {
                    0.0
                };
            }
            let marginal = Distribution1D::new(&weights);
            marginals[c * (n + 1)..(c + 1) * (n + 1)].copy_from_slice(marginal.cdf());
            sums.iter().sum()
        })
        .collect()
}

/// The smallest texel rectangle `[x0, x1, y0, y1]` holding `a` (if any) and `b`.
fn union(a: Option<[usize; 4]>, b: [usize; 4]) -> [usize; 4] {
    match a {
        Some(a) => [
            a[0].min(b[0]),
            a[1].max(b[1]),
            a[2].min(b[2]),
            a[3].max(b[3]),
        ],
        None => b,
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
fn bounding_cone(light: &EnvironmentLight, u: [f64; 2], v: [f64; 2]) -> Cone {
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
    let length = norm(mean);
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
            farthest = farthest.max(norm(cross(axis, d)).atan2(dot(axis, d)));
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

#[inline]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::color::luminance;
    use crate::image::{EnvImage, Lookup};
    use crate::light::{Density, LightOptions, Sampler};
    use crate::math::Rotation;
    use crate::rng::{xi_2d, SplitMix64};

    /// A named product sampler over one of the small test lights.
    struct Case {
        name: &'static str,
        sampler: ProductSampler,
    }

    /// Random texels in `[0, 4)`, with about a quarter of them black.
    fn random_image(w: usize, h: usize, seed: u64) -> EnvImage {
        let mut rng = SplitMix64::new(seed);
        EnvImage::from_fn(w, h, |_, _| {
            if rng.next_f32() < 0.25 {
                [0.0; 3]
            } else {
                [
                    rng.next_f32() * 4.0,
                    rng.next_f32() * 4.0,
                    rng.next_f32() * 4.0,
                ]
            }
        })
        .unwrap()
    }

    /// A black image but for texels `(x, y, value)`.
    fn hot_texels(w: usize, h: usize, hot: &[(usize, usize, f32)]) -> EnvImage {
        EnvImage::from_fn(w, h, |x, y| {
            hot.iter()
                .find(|t| t.0 == x && t.1 == y)
                .map_or([0.0; 3], |t| [t.2; 3])
        })
        .unwrap()
    }

    /// A rotation that moves the light's +z off the world's z axis: 30° about x,
    /// then 37° about z.
    fn tilted() -> Rotation {
        let (s, c) = 30f32.to_radians().sin_cos();
        let about_x = Rotation::from_rows([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]).unwrap();
        Rotation::about_z_degrees(37.0).then_after(about_x)
    }

    fn case(
        name: &'static str,
        image: EnvImage,
        options: LightOptions,
        patches: Option<[usize; 2]>,
    ) -> Case {
        let light = EnvironmentLight::new(image, options).unwrap();
        Case {
            name,
            sampler: ProductSampler::new(
                Arc::new(light),
                ProductOptions {
                    patches,
                    ..Default::default()
                },
            ),
        }
    }

    /// Every mapping, both lookups, rotations, odd sizes, patch grids that do not
    /// divide the image or exceed it, a single hot texel (also on a pole row), a
    /// 1×1 map, and an extreme dynamic range.
    fn cases() -> Vec<Case> {
        let nearest = LightOptions {
            lookup: Lookup::Nearest,
            ..Default::default()
        };
        let equal_area = LightOptions {
            mapping: Mapping::EqualArea,
            equal_area_size: Some(8),
            ..Default::default()
        };
        vec![
            case(
                "8x4 random",
                random_image(8, 4, 1),
                LightOptions::default(),
                None,
            ),
            case(
                "16x8 nearest, 5x3 patches",
                random_image(16, 8, 2),
                nearest,
                Some([5, 3]),
            ),
            case(
                "16x8 hot texel, 4x2 patches",
                hot_texels(16, 8, &[(5, 2, 50.0)]),
                LightOptions::default(),
                Some([4, 2]),
            ),
            case(
                "16x8 hot pole texel, nearest",
                hot_texels(16, 8, &[(3, 0, 9.0)]),
                nearest,
                None,
            ),
            case(
                "16x8 extreme range, nearest",
                hot_texels(16, 8, &[(2, 3, 1e30), (11, 6, 1e-30)]),
                nearest,
                Some([4, 4]),
            ),
            case(
                "1x1",
                EnvImage::new(1, 1, vec![[1.0, 2.0, 3.0]]).unwrap(),
                LightOptions::default(),
                None,
            ),
            case(
                "2x1 halves",
                random_image(2, 1, 3),
                LightOptions::default(),
                None,
            ),
            case(
                "13x7 tilted, hierarchical, 4x3 patches",
                random_image(13, 7, 4),
                LightOptions {
                    rotation: tilted(),
                    sampler: Sampler::Hierarchical,
                    ..Default::default()
                },
                Some([4, 3]),
            ),
            case(
                "16x8 about z 37°, bilinear density, 100x100 patches",
                random_image(16, 8, 5),
                LightOptions {
                    rotation: Rotation::about_z_degrees(37.0),
                    density: Density::PiecewiseBilinear,
                    ..Default::default()
                },
                Some([100, 100]),
            ),
            case(
                "equal-area 8 from 16x8, 3x3 patches",
                random_image(16, 8, 6),
                equal_area,
                Some([3, 3]),
            ),
            case(
                "equal-area 6x6 input, hot texel, tilted",
                hot_texels(6, 6, &[(1, 4, 20.0)]),
                LightOptions {
                    mapping: Mapping::EqualArea,
                    input_mapping: Mapping::EqualArea,
                    rotation: tilted(),
                    ..Default::default()
                },
                None,
            ),
            case(
                "sky 64x32",
                crate::builtin::sky(64, 32),
                LightOptions::default(),
                None,
            ),
            case(
                "sky 64x32, one patch",
                crate::builtin::sky(64, 32),
                LightOptions::default(),
                Some([1, 1]),
            ),
        ]
    }

    /// Cosine and glossy factors about several normals, with outgoing directions
    /// above and below the surface.
    fn factors() -> Vec<Factor> {
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let mut out = vec![
            Factor::cosine(v(0.0, 0.0, 1.0)),
            Factor::cosine(v(0.0, 0.0, -1.0)),
            Factor::cosine(v(1.0, 0.2, -0.3)),
            Factor::cosine(v(0.3, -1.0, 0.001)),
            Factor::glossy(v(0.0, 0.0, 1.0), v(1.0, 0.0, 1.0), 0.05),
            Factor::glossy(v(-0.2, 0.5, 0.8), v(0.1, 0.9, 0.3), 0.3),
            Factor::glossy(v(0.6, 0.0, -0.8), v(0.0, 1.0, 0.0), 1.0),
            Factor::glossy(v(0.0, 0.0, 1.0), v(0.5, 0.5, -0.1), 0.15),
        ];
        for k in 0..4 {
            let n = crate::math::uniform_sphere(xi_2d(17, k));
            let wo = crate::math::uniform_sphere(xi_2d(18, k));
            out.push(Factor::cosine(n));
            out.push(Factor::glossy(n, wo, 0.1 + 0.2 * k as f32));
        }
        out
    }

    /// `u`-by-`v` image points spanning patch `k` edge to edge, plus random ones.
    fn patch_points(sampler: &ProductSampler, k: usize, grid: usize) -> Vec<[f32; 2]> {
        let ([x0, x1], [y0, y1]) = sampler.patch_texels(k);
        let [w, h] = sampler.size;
        let u = |t: f64| ((x0 as f64 + t * (x1 - x0) as f64) / w as f64) as f32;
        let v = |t: f64| ((y0 as f64 + t * (y1 - y0) as f64) / h as f64) as f32;
        let mut points = Vec::new();
        for a in 0..=grid {
            for b in 0..=grid {
                points.push([u(a as f64 / grid as f64), v(b as f64 / grid as f64)]);
            }
        }
        for s in 0..64 {
            let [a, b] = xi_2d(k as u64, s);
            points.push([u(a as f64), v(b as f64)]);
        }
        points
    }

    fn angle(a: [f64; 3], d: Vec3) -> f64 {
        let d = [d.x as f64, d.y as f64, d.z as f64];
        norm(cross(a, d)).atan2(dot(a, d))
    }

    #[test]
    fn cones_contain_their_patches() {
        for case in cases() {
            let sampler = &case.sampler;
            let mut widest = 0.0f64;
            for (k, patch) in sampler.patch.iter().enumerate() {
                let half = patch.cone.sin_half.atan2(patch.cone.cos_half);
                widest = widest.max(half);
                // Only the lit texels are bounded (nothing is sampled in the others).
                for uv in patch_points(sampler, k, 40) {
                    let (d, _) = sampler.light.uv_to_local(uv);
                    if sampler.light.radiance_at_uv(uv) == [0.0; 3] {
                        continue;
                    }
                    let a = angle(patch.cone.axis, d);
                    assert!(
                        a <= half,
                        "{}: patch {k} at {uv:?}: {a} > {half}",
                        case.name
                    );
                }
            }
            // The cones are tight enough to matter where patches are small.
            if case.name.starts_with("sky 64x32") && sampler.patches() == [32, 16] {
                assert!(widest < 0.2, "{}: {widest}", case.name);
            }
        }
    }

    /// Every patch's bound, and every pyramid node's, is at least the factor at
    /// every lit point under it (so every node over light the factor sees has
    /// weight).
    #[test]
    fn bounds_dominate_the_factor() {
        for case in cases() {
            let sampler = &case.sampler;
            let [pw, _] = sampler.patches();
            let depth = sampler.pyramid.len();
            // The lit points of each patch.
            let lit: Vec<Vec<[f32; 2]>> = (0..sampler.patch.len())
                .map(|k| {
                    patch_points(sampler, k, 12)
                        .into_iter()
                        .filter(|&uv| sampler.light.radiance_at_uv(uv) != [0.0; 3])
                        .collect()
                })
                .collect();
            for factor in factors() {
                let target = sampler.target(&factor.normalized().unwrap());
                for level in 0..=depth {
                    let (nodes, across) = sampler.level(level);
                    let shift = depth - level;
                    for (n, node) in nodes.iter().enumerate() {
                        let bound = target.bound(node);
                        let (i, j) = (n % across, n / across);
                        for (k, points) in lit.iter().enumerate() {
                            if (k % pw) >> shift != i || (k / pw) >> shift != j {
                                continue;
                            }
                            for &uv in points {
                                let d = sampler.light.uv_to_direction(uv);
                                let value = factor.value(d) as f64;
                                assert!(
                                    value <= bound * (1.0 + 1e-4) + 1e-6,
                                    "{}: {factor:?}, level {level} node {n} (patch {k}) at {uv:?}: {value} > bound {bound}",
                                    case.name
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn pdf_of_sample_matches_sample_pdf() {
        for case in cases() {
            for (index, factor) in factors().iter().enumerate() {
                let point = case.sampler.at(factor);
                let mut drawn = 0;
                for k in 0..2_000 {
                    let Some(s) = point.sample(xi_2d(index as u64, k)) else {
                        continue;
                    };
                    drawn += 1;
                    assert!(is_positive_finite(s.pdf), "{}: {s:?}", case.name);
                    assert!((s.direction.length() - 1.0).abs() < 1e-5);
                    // Within 1e-4 rad of a lat-long pole, the f32 round trip of a
                    // (rotated) direction leaves sin θ, and so the pdf, uncertain
                    // beyond 1e-4 (the harness exempts the same band).
                    let lat_long = case.sampler.light.mapping() == Mapping::Equirectangular;
                    if lat_long && (std::f64::consts::PI * s.uv[1] as f64).sin() < 1e-4 {
                        continue;
                    }
                    let p = point.pdf(s.direction);
                    assert!(
                        (p - s.pdf).abs() <= 1e-4 * s.pdf,
                        "{}: {factor:?}: pdf {p} vs sample {s:?}",
                        case.name
                    );
                }
                assert_eq!(drawn > 0, point.weight_sum() > 0.0, "{}", case.name);
            }
        }
    }

    /// `∫ p dω` by the midpoint rule on a lat-long grid of the world sphere, only as
    /// a smoke test: the pdf is discontinuous at texel edges, which the grid does not
    /// follow once the light is rotated or equal-area.
    #[test]
    fn pdf_integrates_to_one() {
        let (nu, nv) = (1024usize, 512usize);
        for case in cases() {
            for factor in factors().iter().step_by(3) {
                let point = case.sampler.at(factor);
                let mut integral = 0.0f64;
                for j in 0..nv {
                    let (u_row, v) = (0.0, (j as f64 + 0.5) / nv as f64);
                    let sin_theta = (PI * v).sin();
                    let cell = 2.0 * PI * PI * sin_theta / (nu * nv) as f64;
                    for i in 0..nu {
                        let u = u_row + (i as f64 + 0.5) / nu as f64;
                        let (d, _) = crate::mapping::equirect_to_direction(u as f32, v as f32);
                        integral += point.pdf(d) as f64 * cell;
                    }
                }
                let want = if point.weight_sum() > 0.0 { 1.0 } else { 0.0 };
                assert!(
                    (integral - want).abs() < 2e-3,
                    "{}: {factor:?}: {integral}",
                    case.name
                );
            }
        }
    }

    #[test]
    fn pdf_is_positive_where_light_times_factor_is() {
        for case in cases() {
            let sampler = &case.sampler;
            let light = sampler.light();
            let [w, h] = sampler.size;
            for factor in factors() {
                let point = sampler.at(&factor);
                for j in 0..h {
                    for i in 0..w {
                        for (a, b) in [(0.5, 0.5), (0.1, 0.2), (0.9, 0.15), (0.3, 0.95)] {
                            let uv = [(i as f32 + a) / w as f32, (j as f32 + b) / h as f32];
                            let d = light.uv_to_direction(uv);
                            let target = luminance(light.radiance(d)) * factor.value(d);
                            assert!(
                                target <= 0.0 || point.pdf(d) > 0.0,
                                "{}: {factor:?} at texel ({i}, {j}) {uv:?}: L f = {target}, pdf 0",
                                case.name
                            );
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn sample_radiance_is_the_lights() {
        for case in cases() {
            let light = case.sampler.light();
            // The direction's round trip to the image moves the point by float
            // rounding, which changes a bilinear lookup by that much of its slope.
            let brightest = light.brightest().0;
            for (index, factor) in factors().iter().enumerate().step_by(2) {
                let point = case.sampler.at(factor);
                for k in 0..500 {
                    let Some(s) = point.sample(xi_2d(100 + index as u64, k)) else {
                        continue;
                    };
                    let want = light.radiance(s.direction);
                    for (got, want) in s.radiance.iter().zip(want) {
                        assert!(
                            (got - want).abs() <= 1e-4 * want + 1e-5 * brightest,
                            "{}: {s:?} vs {want}",
                            case.name
                        );
                    }
                    let [u, v] = light.direction_to_uv(s.direction);
                    let du = (u - s.uv[0]).abs();
                    assert!(
                        du.min(1.0 - du) < 1e-5 && (v - s.uv[1]).abs() < 1e-5,
                        "{}: {s:?} at {u}, {v}",
                        case.name
                    );
                }
            }
        }
    }

    #[test]
    fn nothing_to_sample_gives_none_and_pdf_zero() {
        let check_empty = |sampler: &ProductSampler, factor: &Factor, what: &str| {
            let point = sampler.at(factor);
            assert_eq!(point.weight_sum(), 0.0, "{what}");
            for k in 0..200 {
                assert!(point.sample(xi_2d(3, k)).is_none(), "{what}");
                let d = crate::math::uniform_sphere(xi_2d(4, k));
                assert_eq!(point.pdf(d), 0.0, "{what}");
                assert_eq!(sampler.pdf(factor, d), 0.0, "{what}");
            }
        };
        let up = Factor::cosine(Vec3::new(0.0, 0.0, 1.0));
        let down = Factor::cosine(Vec3::new(0.0, 0.0, -1.0));
        let black = case(
            "black",
            EnvImage::from_fn(4, 2, |_, _| [0.0; 3]).unwrap(),
            LightOptions::default(),
            None,
        );
        assert!(black.sampler.is_black());
        check_empty(&black.sampler, &up, "black map");
        // Only the top row of eight (θ < 22.5°) is lit; the filter (and the
        // resampling to the equal-area square) spread it down to about θ < 45°, and
        // the patches holding any of it lie well above a surface facing down.
        let sky_only =
            EnvImage::from_fn(16, 8, |_, y| if y < 1 { [1.0; 3] } else { [0.0; 3] }).unwrap();
        for mapping in Mapping::ALL {
            let options = LightOptions {
                mapping,
                equal_area_size: Some(32),
                ..Default::default()
            };
            let c = case("sky only", sky_only.clone(), options, None);
            let glossy = Factor::glossy(down.normal(), Vec3::new(0.3, 0.0, -1.0), 0.2);
            if mapping == Mapping::Equirectangular {
                check_empty(&c.sampler, &down, "light above, surface facing down");
                check_empty(&c.sampler, &glossy, "glossy");
            } else {
                // On the equal-area square, bounded by cones alone, a coarse node of
                // the cut holding a faint resampling tail (1.5e-6 of the power) may
                // reach below the horizon: a sliver of weight, whose samples carry
                // a factor of 0 (wasted, not wrong).
                for factor in [down, glossy] {
                    let point = c.sampler.at(&factor);
                    assert!(point.weight_sum() < 1e-6, "{}", point.weight_sum());
                    for k in 0..200 {
                        if let Some(s) = point.sample(xi_2d(3, k)) {
                            assert_eq!(factor.value(s.direction), 0.0, "{s:?}");
                        }
                    }
                }
            }
            assert!(c.sampler.at(&up).weight_sum() > 0.0);
            // Invalid factors.
            let z = Vec3::new(0.0, 0.0, 1.0);
            for bad in [
                Factor::cosine(Vec3::default()),
                Factor::cosine(Vec3::new(f32::NAN, 0.0, 1.0)),
                Factor::cosine(Vec3::new(f32::INFINITY, 0.0, 1.0)),
                Factor::glossy(z, Vec3::default(), 0.5),
                Factor::glossy(z, z, 0.0),
                Factor::glossy(z, z, 1.5),
                Factor::glossy(z, z, f32::NAN),
            ] {
                assert!(bad.normalized().is_none() && bad.value(z) == 0.0, "{bad:?}");
                check_empty(&c.sampler, &bad, "invalid factor");
            }
        }
    }

    #[test]
    fn batches_equal_single_queries() {
        let c = case(
            "sky",
            crate::builtin::sky(64, 32),
            LightOptions::default(),
            None,
        );
        let sampler = &c.sampler;
        let all = factors();
        // Runs of equal factors (which reuse a point's setup) and changes.
        let batch: Vec<Factor> = (0..3_000)
            .map(|k| all[(k / 7 + k % 3) % all.len()])
            .collect();
        let xi: Vec<[f32; 2]> = (0..batch.len() as u64).map(|k| xi_2d(9, k)).collect();
        let mut samples = vec![None; batch.len()];
        sampler.sample_batch(&batch, &xi, &mut samples);
        let dirs: Vec<Vec3> = (0..batch.len() as u64)
            .map(|k| crate::math::uniform_sphere(xi_2d(10, k)))
            .collect();
        let mut pdfs = vec![0.0; batch.len()];
        sampler.pdf_batch(&batch, &dirs, &mut pdfs);
        for k in 0..batch.len() {
            assert_eq!(samples[k], sampler.sample(&batch[k], xi[k]));
            assert_eq!(pdfs[k].to_bits(), sampler.pdf(&batch[k], dirs[k]).to_bits());
        }
    }

    #[test]
    fn patches_tile_the_image_and_the_arrays() {
        for (w, h, asked, want) in [
            (13, 7, Some([4, 3]), [4, 3]),
            (8, 4, Some([100, 100]), [8, 4]),
            (8, 4, Some([0, 0]), [1, 1]),
            (1, 1, None, [1, 1]),
            (64, 32, None, [64, 32]),
            (256, 128, None, [128, 64]),
            (50, 9, Some([7, 9]), [7, 9]),
        ] {
            let c = case(
                "tiling",
                random_image(w, h, 7),
                LightOptions::default(),
                asked,
            );
            let s = &c.sampler;
            assert_eq!(s.patches(), want);
            let [pw, ph] = want;
            // Every texel belongs to the patch whose block holds it.
            for i in 0..w {
                let p = s.col_patch[i] as usize;
                assert!(s.col_start[p] as usize <= i && i < s.col_start[p + 1] as usize);
            }
            for j in 0..h {
                let p = s.row_patch[j] as usize;
                assert!(s.row_start[p] as usize <= j && j < s.row_start[p + 1] as usize);
            }
            // The CDF slices tile their arrays, each running from 0 to CDF_ONE.
            let mut marginal_used = 0;
            for k in 0..pw * ph {
                let m = s.marginal(k);
                let at = m.as_ptr() as usize - s.marginal_cdf.as_ptr() as usize;
                assert_eq!(at, 4 * marginal_used);
                marginal_used += m.len();
                assert!(m[0] == 0 && m[m.len() - 1] == CDF_ONE);
            }
            // (Patches are row-major, so the slices come in order.)
            assert_eq!(marginal_used, s.marginal_cdf.len());
            let mut segment_used = 0;
            for j in 0..h {
                for c in 0..pw {
                    let seg = s.segment(j, c);
                    let at = seg.as_ptr() as usize - s.segment_cdf.as_ptr() as usize;
                    assert_eq!(at, 4 * segment_used);
                    segment_used += seg.len();
                    assert!(seg[0] == 0 && seg[seg.len() - 1] == CDF_ONE);
                }
            }
            assert_eq!(segment_used, s.segment_cdf.len());
            let powers: f64 = s.patch.iter().map(|p| p.power).sum();
            assert!((powers - 1.0).abs() < 1e-12, "{powers}");
            assert!(s.memory_bytes() >= 4 * w * h);
        }
    }

    /// The arc-length bound used for equal-area cones, against the mapping on
    /// short random steps in every direction.
    #[test]
    fn equal_area_lipschitz_bound_holds() {
        let mut worst = 0.0f64;
        for k in 0..200_000u64 {
            let [u, v] = xi_2d(21, k);
            let [a, b] = xi_2d(22, k);
            let step = 1e-3 * (0.1 + a as f64);
            let (s, c) = (2.0 * PI * b as f64).sin_cos();
            let (u2, v2) = (u as f64 + step * c, v as f64 + step * s);
            if !(0.0..=1.0).contains(&u2) || !(0.0..=1.0).contains(&v2) {
                continue;
            }
            let p = crate::equal_area::square_to_sphere(u, v);
            let q = crate::equal_area::square_to_sphere(u2 as f32, v2 as f32);
            let length = ((u2 - u as f64).powi(2) + (v2 - v as f64).powi(2)).sqrt();
            worst = worst.max(angle([p.x as f64, p.y as f64, p.z as f64], q) / length);
        }
        assert!(worst <= EQUAL_AREA_LIPSCHITZ, "{worst}");
        assert!(worst > 0.5 * EQUAL_AREA_LIPSCHITZ, "a loose bound: {worst}");
    }

    /// Sampling efficiency `(∫ Y f dω)² / ∫ (Y f)² / p dω` (1 when `p ∝ Y f`) by
    /// quadrature, for the product pdf and for the light's own: on a constant map,
    /// where the light alone ignores the factor, and on the sky, whose sun carries
    /// most of any integral.
    #[test]
    fn product_beats_the_light_alone() {
        let constant = EnvImage::from_fn(64, 32, |_, _| [1.0; 3]).unwrap();
        let sky = crate::builtin::sky(128, 64);
        let tilted = Vec3::new(0.3, 0.2, 0.9);
        let up = Vec3::new(0.0, 0.0, 1.0);
        for (name, image, factor, at_least) in [
            ("constant", &constant, Factor::cosine(tilted), 0.9),
            (
                "constant",
                &constant,
                Factor::glossy(tilted, Vec3::new(-0.5, 0.1, 0.7), 0.3),
                0.8,
            ),
            ("sky", &sky, Factor::cosine(up), 0.5),
            ("sky", &sky, Factor::cosine(Vec3::new(1.0, 0.0, 0.2)), 0.5),
            (
                "sky",
                &sky,
                Factor::glossy(up, Vec3::new(-0.5, -0.8, 0.6), 0.2),
                0.5,
            ),
        ] {
            let c = case(name, image.clone(), LightOptions::default(), None);
            let light = c.sampler.light();
            let point = c.sampler.at(&factor);
            let (nu, nv) = (512usize, 256usize);
            let (mut target, mut product, mut alone) = (0.0f64, 0.0f64, 0.0f64);
            for j in 0..nv {
                for i in 0..nu {
                    let (u, v) = ((i as f32 + 0.5) / nu as f32, (j as f32 + 0.5) / nv as f32);
                    let (d, sin_theta) = crate::mapping::equirect_to_direction(u, v);
                    let dw = 2.0 * PI * PI * sin_theta as f64 / (nu * nv) as f64;
                    let y = (luminance(light.radiance(d)) * factor.value(d)) as f64;
                    if y > 0.0 {
                        target += y * dw;
                        product += y * y / point.pdf(d) as f64 * dw;
                        alone += y * y / light.pdf(d) as f64 * dw;
                    }
                }
            }
            let (product, alone) = (target * target / product, target * target / alone);
            assert!(
                product > alone && product > at_least,
                "{name}, {factor:?}: {product} vs {alone}"
            );
        }
    }
}
