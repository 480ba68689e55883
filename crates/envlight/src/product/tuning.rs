//! The constants that tune the product sampler, each with what it was chosen
//! by: how finely the bounds are computed, how much of a bound a weight keeps,
//! which patches are bright, which glossy roughnesses get tables, and the
//! horizon's band. The defaults of [`ProductOptions`](super::ProductOptions) stay
//! with the options they are the defaults of.
//!
//! Nothing here depends on the rest of the module: every file of it reads these
//! from here.

// ---- Bounds of a patch's directions (module `bounds`, and the tables'
// ---- neighbourhood cones).

/// Boundary samples per patch edge when bounding its cone.
pub(super) const BOUNDARY_STEPS: usize = 64;

/// Midpoints per side of the grid that estimates a patch's mean direction.
pub(super) const MEAN_GRID: usize = 16;

/// Radians added to every cone's half-angle for the rounding of the f32 mapping
/// (about 1e-6 rad) and of the rotation into the light frame (about 1e-7 rad).
pub(super) const CONE_SLACK: f64 = 1e-4;

/// Added to a lat-long box's exact maximum of `v·ω` for the rounding of f32
/// directions and of the rotation into the light frame (about 1e-7 each).
pub(super) const BOX_SLACK: f64 = 1e-5;

// ---- The floor of a patch's weight (`bounds::PatchBound::weight`).

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

/// At most this share of what the factor gives a node's table at its own direction
/// is added by the floors: more would spend samples below the horizon of a
/// surface facing the node's direction (up to 6% measured for a surface facing
/// down under night.exr with the full share).
pub(super) const FLOOR_BUDGET: f64 = 0.01;

// ---- The bright patches (module `bright`).

/// At most this many patches are bright: the cost of a new shading point grows
/// with them (one bound and one dot product each).
pub(super) const MAX_BRIGHT: usize = 16;

/// A patch is bright when it holds at least this share of the light's density.
pub(super) const BRIGHT_SHARE: f64 = 0.01;

/// ... and lies within a cone of at most this half-angle (radians, 10°): the
/// factor at a patch's centre of light stands for it only when the patch is
/// small (the default patches are about 4° across from centre to corner). On
/// coarse patch grids the tables, which mix four nodes' views, serve better.
pub(super) const BRIGHT_MAX_HALF_ANGLE: f64 = 0.1745;

// ---- The glossy tables.

/// The GGX roughnesses with tables of their own: a glossy factor uses the nearest
/// (in log scale), or the cosine's tables from [`COSINE_FROM_ROUGHNESS`] up.
pub(super) const LOBE_ROUGHNESS: [f32; 3] = [0.08, 0.16, 0.32];

/// The lobe grid of each of [`LOBE_ROUGHNESS`], in halves of
/// [`ProductOptions::lobe_grid`](super::ProductOptions::lobe_grid): narrower
/// lobes need finer grids, as a shading point mixes tables about its four
/// neighbouring nodes (16, 12 and 12 cells a side by default; nodes about 13°,
/// 17° and 17° apart). The widest lobe lost 0.03–0.05 of its efficiency on a
/// constant map at 8 cells (nodes 25° apart).
pub(super) const LOBE_GRID_SCALE: [usize; 3] = [4, 3, 3];

/// Glossy factors this rough or rougher sample from the cosine's tables: their
/// lobe is wide enough that the cosine is the better part of the product.
pub(super) const COSINE_FROM_ROUGHNESS: f32 = 0.45;

/// How far [`tilted_mirror`](super::tilted_mirror) may turn a glossy factor's
/// lookup, per unit of roughness, in units of `tan(θo / 2)`.
pub(super) const TILT_GAIN: f32 = 1.75;

// ---- The horizon's band.

/// The depth of the band below a surface's horizon whose samples are reflected
/// above it, as the cosine `n·ω` (sin 20°), at most: a draw with `-s < n·ω < 0`
/// is returned as its mirror image `ω - 2(n·ω)n` (see
/// [`ShadingPoint::pdf`](super::ShadingPoint::pdf);
/// [`ShadingPoint::horizon_band`](super::ShadingPoint::horizon_band) gives a
/// point's `s`). The tables mix four neighbouring normals' products and a patch
/// is sampled by the light alone, so some draws land just below the horizon,
/// where `L·f` is 0: up to 4.6% of them for some normals, measured over the
/// shared maps and 64 random normals, of which at most 0.28% lie deeper than 20°
/// (0.47% deeper than 15°, 0.71% than 10°; BENCHMARKS.md). A deeper band costs
/// more second lookups (a direction within it above the horizon needs the
/// mixture at its mirror image too: about `s²` of a cosine-distributed set).
pub const HORIZON_BAND: f32 = 0.342_020_14;

/// The least band a shading point keeps (sin 5°). A point narrows its band below
/// [`HORIZON_BAND`] to the lowest bright patch (a sun) that lies wholly above its
/// horizon within it, down to this: that patch's draws then need no second
/// lookup (a low sun over a ground plane: most of its product samples).
pub const MIN_HORIZON_BAND: f32 = 0.087_155_74;
