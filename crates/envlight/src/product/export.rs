//! The cosine product's tables as flat arrays, for ports of [`ShadingPoint`]'s
//! sampling and pdf to other languages (the Dr.Jit port in envlight's Python
//! package; layout in docs/gpu-tables.md, "Product tables").
//!
//! These are plain data, filled in one go by
//! [`ProductSampler::cosine_tables`](super::ProductSampler::cosine_tables) from
//! the fine level, the cosine's tables and the bright patches; nothing here reads
//! the rest of the module.
//!
//! [`ShadingPoint`]: super::ShadingPoint

/// A bright patch of a [`ProductTables`]: weighted at every shading point by the
/// cosine at its centre of light, floored by a share of the cosine's upper bound
/// over the patch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BrightPatch {
    /// Its patch index (`row · patches[0] + column`).
    pub patch: u32,
    /// Its share of the light's power.
    pub power: f64,
    /// Its centre of light, a unit light-frame direction.
    pub centre: [f64; 3],
    /// A cone holding its directions: axis, cosine and sine of the half-angle
    /// (`cos_half = −1`: the whole sphere).
    pub cone: ([f64; 3], f64, f64),
    /// For a lat-long light, the exact (θ, φ) box of its directions:
    /// `(cos 2πu₀, sin 2πu₀)`, `(cos 2πu₁, sin 2πu₁)`, whether it spans less than
    /// half a turn, `(sin πv₀, cos πv₀)`, `(sin πv₁, cos πv₁)`.
    pub latlong: Option<LatLongPatch>,
}

/// The (θ, φ) box of a [`BrightPatch`] of a lat-long light.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LatLongPatch {
    /// `(cos, sin)` of the box's first meridian, `2π u₀`.
    pub edge0: [f64; 2],
    /// `(cos, sin)` of its last meridian, `2π u₁`.
    pub edge1: [f64; 2],
    /// Whether `u₁ − u₀ < ½`.
    pub narrow: bool,
    /// `(sin, cos)` of its top colatitude, `π v₀`.
    pub top: [f64; 2],
    /// `(sin, cos)` of its bottom colatitude, `π v₁`.
    pub bottom: [f64; 2],
}

/// The tables of a [`ProductSampler`](super::ProductSampler)'s cosine factor
/// (`L · cos⁺`), flat; see [`ProductSampler::cosine_tables`](super::ProductSampler::cosine_tables).
#[derive(Debug, Clone, PartialEq)]
pub struct ProductTables {
    /// The light's density: its cells are the image's `w × h` texels (piecewise
    /// constant) or the `(w + 1) × (h + 1)` cells between its nodes (piecewise
    /// bilinear).
    pub density: crate::light::Density,
    /// The image's size `[w, h]`.
    pub image: [u32; 2],
    /// The cell grid: `[w, h]` or `[w + 1, h + 1]`.
    pub cells: [u32; 2],
    /// The piecewise-bilinear density's node values, row-major over
    /// `(h + 2) × (w + 2)` nodes (empty for the piecewise-constant density).
    pub node_values: Vec<f32>,
    /// Its node positions along u (`w + 2`); cell `i` spans `u_nodes[i]..u_nodes[i + 1]`.
    pub u_nodes: Vec<f64>,
    /// Its node positions along v (`h + 2`).
    pub v_nodes: Vec<f64>,
    /// Patches across and down, `[pw, ph]`.
    pub patches: [u32; 2],
    /// The patch column of each cell column (`w` entries).
    pub col_patch: Vec<u32>,
    /// The patch row of each cell row (`h` entries).
    pub row_patch: Vec<u32>,
    /// Each cell's width in its patch's fixed-point CDF, row-major (`w · h`).
    pub cell_widths: Vec<u32>,
    /// Each patch's alias table over its cells, patch after patch at
    /// `spans[k].first`: `(threshold, alias)` with the alias local to the patch.
    pub cell_slots: Vec<[u32; 2]>,
    /// Per patch: `[x0, y0, cols, rows, first]`: its first cell column and row, its
    /// size in cells and the index of its first slot in `cell_slots`.
    pub spans: Vec<[u32; 5]>,
    /// Cells per side of the octahedral grid of normals (`(n + 1)²` nodes).
    pub grid: u32,
    /// Each node's alias table over the patches, node after node (`nodes · patches`).
    pub table_slots: Vec<[u32; 2]>,
    /// Patch `k`'s width in node `m`'s table at `k · nodes + m`.
    pub table_widths: Vec<u32>,
    /// Per node: whether its table is empty (sees no light).
    pub node_empty: Vec<bool>,
    /// Per node: its table's total weight, in units of the patches' power.
    pub node_totals: Vec<f64>,
    /// The bright patches, brightest first (at most 16).
    pub bright: Vec<BrightPatch>,
    /// Per patch: its index in `bright`, or 255.
    pub bright_of_patch: Vec<u8>,
    /// The share of a patch's upper bound that floors its weight.
    pub bound_share: f64,
    /// What a lat-long box's bound adds for rounding.
    pub box_slack: f64,
    /// [`super::HORIZON_BAND`]: draws with `-s < n̂·ω < 0` are reflected in the
    /// tangent plane, `s` this or less (see [`super::ShadingPoint::horizon_band`]).
    pub horizon_band: f32,
    /// [`super::MIN_HORIZON_BAND`], the least `s`.
    pub min_horizon_band: f32,
}
