//! A piecewise-bilinear density on `[0, 1]²`, sampled by inversion.
//!
//! Non-negative values `f[k][i]` sit at the nodes `(U_i, V_k)` of a rectilinear grid
//! (`0 = U_0 < … < U_{m-1} = 1`, likewise V). Inside the patch
//! `[U_i, U_{i+1}] × [V_k, V_{k+1}]` the function is the bilinear interpolation of
//! its four corners, and the density is `p(u, v) = B(u, v) / I` with `I` the exact
//! integral of `B`. Placing the nodes at texel centres (with extra nodes on the
//! square's edges) makes `p` exactly proportional to a bilinear radiance lookup:
//! for a `w × h` image with u periodic and v clamped, `U = 0, (i + ½)/w, 1` with the
//! seam average `(f[j][w-1] + f[j][0]) / 2` at both `u = 0` and `u = 1`, and
//! `V = 0, (j + ½)/h, 1` with copies of the first and last texel rows at `v = 0` and
//! `v = 1`. Nodes may repeat (a patch of zero width, which has no mass and is
//! never sampled nor found by a lookup inside `[0, 1]`): Mitsuba's lat-long
//! reading, whose rows are nodes from pole to pole, is
//! `V = 0, 0, j/(h - 1), 1, 1` in the same `h + 2` rows.
//!
//! Sampling picks a patch, then a point in it. The patches' masses
//! `M_ik = (U_{i+1} - U_i)(V_{k+1} - V_k)(f_00 + f_10 + f_01 + f_11) / 4` (exact for
//! the bilinear interpolant of the corners `f_ab`) go into a piecewise-constant
//! [`Distribution2D`] over the patch grid, whose fixed-point CDFs and guide tables
//! pick patch `[i, k]` with probability `P_ik ≈ M_ik / I` in O(1) and leave the two
//! offsets of `ξ` within the patch's CDF segments, `(s, r) ∈ [0, 1)²`, free. Inside
//! the patch, in local coordinates `(x, y) ∈ [0, 1]²`, the bilinear function's
//! marginal in `y` is linear with ends `f_00 + f_10` and `f_01 + f_11`: `r` gives
//! `y`; at that `y` the conditional in `x` is linear with ends `lerp(y, f_00, f_01)`
//! and `lerp(y, f_10, f_11)`: `s` gives `x`. The density of the whole procedure is
//!
//! ```text
//! p(u, v) = P_ik · B(u, v) / M_ik
//! ```
//!
//! which is `B / I` up to the CDFs' 2⁻³² rounding of `P_ik` (the rounding
//! [`Distribution2D`] documents): that is the pdf reported, so it is the exact
//! density of the sampler and integrates to 1 exactly. Patch choice and placement
//! are each a few operations, with no search over a row: about the cost of the
//! piecewise-constant sampler plus two square roots. (The map is continuous
//! within each patch; across a patch edge it jumps, as every patch- or cell-based
//! sampler does.)
//!
use crate::distribution::{
    positive_weight, probability_of_widths, sanitize, CellSample, Distribution2D, Sample2D,
    ONE_MINUS_EPSILON, STAGED_BLOCK,
};
use crate::error::{Error, Result};
use crate::math::{prefetch_ptr, unit_interval, BELOW_ONE};
use crate::width::{at_width, VectorWidth};

/// A piecewise-bilinear density on `[0, 1]²` over a rectilinear node grid, sampled
/// by picking a patch and then a point in it (see the module docs).
///
/// Guarantees: a point where the bilinear function is 0 is never returned (up to a
/// set of measure zero: a sample can land exactly on a zero edge of its patch,
/// and then reports pdf 0); `pdf(sample_continuous(ξ).uv)` equals the returned
/// pdf; `invert(sample_continuous(ξ).uv) ≈ ξ`.
///
/// Cost: sampling is two guide-table lookups with short scans plus two square
/// roots, O(1) expected; `pdf` and `invert` locate the patch through a guide table
/// on the node positions (O(1) for evenly spread nodes, O(log n) at worst) and read
/// its four corners and its factor (`P_ik / M_ik` with the constants folded in,
/// so the density is a weighted sum and one product in `f32`). Memory: 4 bytes
/// per node for the values, the patch distribution's 5-6 bytes per patch and 4
/// more for the factors, and 12 per node position.
///
/// ```
/// use envlight::bilinear::BilinearDistribution2D;
/// // B(u, v) = u on the unit square: p = 2u, so u = √ξ0 and v = ξ1.
/// let d = BilinearDistribution2D::new(&[0.0, 1.0, 0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]);
/// let s = d.sample_continuous([0.25, 0.3]);
/// assert!((s.uv[0] - 0.5).abs() < 1e-6 && (s.uv[1] - 0.3).abs() < 1e-6);
/// assert!((s.pdf - 1.0).abs() < 1e-6 && d.pdf(s.uv) == s.pdf);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct BilinearDistribution2D {
    /// The node positions along u (`mu` of them) and v (`mv`).
    u: Axis,
    v: Axis,
    /// `f[k * mu + i]`, sanitised.
    values: Vec<f32>,
    /// The patches' masses `M_ik` as a piecewise-constant distribution over the
    /// `(mu - 1) × (mv - 1)` patch grid: it picks the patch.
    patches: Distribution2D,
    /// `I = ∫∫ B du dv = Σ M_ik`.
    integral: f64,
    /// Per patch (row-major over the patch grid), the factor `F_ik` that turns the
    /// corners weighted by the point's normalised distances to the sides into
    /// the density ([`pdf_from_weights`]): `4 P_ik / (c_u c_v Δu² Δv² Σf)` over
    /// [`Self::scale`], in `f32`; 0 for a patch of no mass or never picked.
    factors: Vec<f32>,
    /// A power of two that brings the weighted corners near 1 when the integral
    /// is outside `[2⁻⁶⁴, 2⁶⁴]` (so that the factors stay inside `f32`'s range),
    /// else 1.
    scale: f32,
}

/// A [`BilinearDistribution2D`] on a layout the light builds as tables (see
/// [`BilinearDistribution2D::centred_tables`]): the node values (`mu` per row),
/// the patches' factors (`mu − 1` per row) and the scale of
/// [`pdf_from_weights`], and the counts that locate a patch with one product
/// (along u the texel count `w`, patch `⌊u w + ½⌋`; along v the texel count `h`,
/// patch `⌊v h + ½⌋`, or with `node_rows` the row intervals `m = h − 1`, patch
/// `1 + min(⌊v m⌋, m − 1)`), which are also the units of the distances to the
/// patch's sides ([`centred_weights`], [`row_weights`]).
pub(crate) struct CentredTables<'a> {
    /// Nodes per row.
    pub mu: usize,
    pub values: &'a [f32],
    pub factors: &'a [f32],
    pub scale: f32,
    pub cells: [f64; 2],
    pub node_rows: bool,
}

impl BilinearDistribution2D {
    /// Builds the density of `values`, given row-major with `v_nodes.len()` rows of
    /// `u_nodes.len()` values, the value of row `k`, column `i` sitting at
    /// `(u_nodes[i], v_nodes[k])`. Negative, NaN and infinite values count as 0. A
    /// function with no positive mass samples uniformly with pdf 0 everywhere.
    ///
    /// # Panics
    /// When [`Self::try_new`] fails.
    pub fn new(values: &[f32], u_nodes: &[f64], v_nodes: &[f64]) -> Self {
        match Self::try_new(values, u_nodes, v_nodes) {
            Ok(d) => d,
            Err(e) => panic!("{e}"),
        }
    }

    /// As [`Self::new`], with the shape checked.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] when either node list has fewer than 2 entries, is
    /// not strictly increasing, does not start at exactly 0 and end at exactly 1, or
    /// holds a non-finite value; or when `values.len() != u_nodes.len() *
    /// v_nodes.len()`. Repeated nodes are allowed: the patch between them has no
    /// width, so no mass.
    pub fn try_new(values: &[f32], u_nodes: &[f64], v_nodes: &[f64]) -> Result<Self> {
        check_nodes("u", u_nodes)?;
        check_nodes("v", v_nodes)?;
        let (mu, mv) = (u_nodes.len(), v_nodes.len());
        if mu.checked_mul(mv) != Some(values.len()) {
            return Err(Error::InvalidOption(format!(
                "bilinear grid of {mu}x{mv} nodes needs {} values, got {}",
                mu.saturating_mul(mv),
                values.len()
            )));
        }
        let values: Vec<f32> = values.iter().map(|&x| sanitize(x)).collect();
        // Masses relative to the mean patch area, so that they stay well inside
        // f32's range for any node spacing; a positive mass never rounds to 0.
        let patch_count = ((mu - 1) * (mv - 1)) as f64;
        let width = VectorWidth::detect();
        let (patches, row_sums) = Distribution2D::from_rows_with(
            mu - 1,
            mv - 1,
            || (),
            |_, k, row| {
                let args = MassRow {
                    top: &values[k * mu..(k + 1) * mu],
                    bottom: &values[(k + 1) * mu..(k + 2) * mu],
                    u_nodes,
                    height: v_nodes[k + 1] - v_nodes[k],
                    patch_count,
                };
                mass_row_at(width, &args, row)
            },
        );
        let integral: f64 = row_sums.iter().sum();
        let (u, v) = (Axis::new(u_nodes), Axis::new(v_nodes));
        let scale = factor_scale(integral);
        let factors = patch_factors(
            &values,
            [u_nodes, v_nodes],
            &patches,
            u.count() * v.count() * scale as f64,
        );
        Ok(Self {
            u,
            v,
            values,
            patches,
            integral,
            factors,
            scale,
        })
    }

    /// Node positions along u.
    #[inline]
    pub fn u_nodes(&self) -> &[f64] {
        &self.u.nodes
    }

    /// Node positions along v.
    #[inline]
    pub fn v_nodes(&self) -> &[f64] {
        &self.v.nodes
    }

    /// The (sanitised) node values, row-major.
    #[inline]
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// `I = ∫∫ B(u, v) du dv`, exact for the bilinear interpolant.
    #[inline]
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// The piecewise-constant distribution over the patches' masses that picks
    /// the patch (for [`crate::gpu`]'s export).
    #[inline]
    pub(crate) fn patches(&self) -> &Distribution2D {
        &self.patches
    }

    /// `([w, h], node_rows)` when the nodes are one of the layouts the light
    /// builds: along u the texel centres of `w` texels, along v the texel centres
    /// of `h` texels (`node_rows` false) or the node rows `0, 0, j/(h - 1), 1, 1`
    /// of `h ≥ 2` rows (true); else `None`.
    pub(crate) fn image_cells(&self) -> Option<([usize; 2], bool)> {
        let w = self.u.cells as usize;
        if w == 0 {
            None
        } else if self.v.cells > 0.0 {
            Some(([w, self.v.cells as usize], false))
        } else if self.v.rows > 0.0 {
            Some(([w, self.v.rows as usize + 1], true))
        } else {
            None
        }
    }

    /// The tables of the layouts the light builds ([`Self::image_cells`]) for
    /// kernels that gather them themselves (the AVX-512 batch queries); `None` for
    /// other node layouts.
    pub(crate) fn centred_tables(&self) -> Option<CentredTables<'_>> {
        self.image_cells().map(|(_, node_rows)| CentredTables {
            mu: self.u.nodes.len(),
            values: &self.values,
            factors: &self.factors,
            scale: self.scale,
            cells: [self.u.cells, self.v.locating_count()],
            node_rows,
        })
    }

    /// Bytes of sampling data held (values, the patch distribution and the node
    /// positions with their guides).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.values.as_slice())
            + std::mem::size_of_val(self.factors.as_slice())
            + self.patches.memory_bytes()
            + self.u.memory_bytes()
            + self.v.memory_bytes()
    }

    /// The sides `[u0, u1, v0, v1]` of patch `[i, k]`.
    #[inline(always)]
    fn sides(&self, i: usize, k: usize) -> [f64; 4] {
        let ([u0, u1], [v0, v1]) = (self.u.side(i), self.v.side(k));
        [u0, u1, v0, v1]
    }

    /// The corners of patch `[i, k]`: `[f_00, f_10, f_01, f_11]` (first index u).
    #[inline(always)]
    fn corners(&self, i: usize, k: usize) -> [f64; 4] {
        corners(&self.values, self.u.nodes.len(), i, k)
    }

    /// The density at `(u, v)` in patch `[i, k]`: `P_ik · B(u, v) / M_ik`, 0 for a
    /// patch of no mass ([`pdf_from_weights`]).
    ///
    /// # Panics
    /// When the patch is outside the grid.
    #[inline(always)]
    fn patch_pdf(&self, i: usize, k: usize, u: f64, v: f64) -> f32 {
        pdf_from_weights(
            corners32(&self.values, self.u.nodes.len(), i, k),
            [self.u.weights(i, u), self.v.weights(k, v)],
            self.factors[self.patch_index(i, k)],
            self.scale,
        )
    }

    /// Where patch `[i, k]`'s factor is: row-major over the `mu − 1` patches of
    /// a row.
    #[inline(always)]
    fn patch_index(&self, i: usize, k: usize) -> usize {
        k.wrapping_mul(self.u.nodes.len() - 1).wrapping_add(i)
    }

    /// The patch `[i, k]` holding `uv` (clamped onto the square), and the point as
    /// [`Self::pdf`] reads it: the first half of [`Self::pdf`], for callers that
    /// fetch the patch's data ahead ([`Self::prefetch_patch`]) before the second
    /// ([`Self::pdf_in_patch`]).
    #[inline(always)]
    pub(crate) fn locate(&self, uv: [f32; 2]) -> ([usize; 2], [f64; 2]) {
        let (u, v) = (unit_closed(uv[0]), unit_closed(uv[1]));
        ([self.u.patch(u), self.v.patch(v)], [u, v])
    }

    /// Starts fetching what [`Self::pdf_in_patch`] of patch `[i, k]` reads: its
    /// two rows of corners and its CDF entries. A hint; harmless for any patch.
    #[inline(always)]
    pub(crate) fn prefetch_patch(&self, [i, k]: [usize; 2]) {
        let mu = self.u.nodes.len();
        let top = k.wrapping_mul(mu).wrapping_add(i);
        prefetch_ptr(self.values.as_ptr().wrapping_add(top));
        prefetch_ptr(self.values.as_ptr().wrapping_add(top.wrapping_add(mu)));
        prefetch_ptr(self.factors.as_ptr().wrapping_add(self.patch_index(i, k)));
    }

    /// [`Self::pdf_in_patch`] for a block of patches and points: the patches'
    /// data gathered lane by lane, then the densities in vector lanes. Bit for bit
    /// the single calls.
    #[inline(always)]
    pub(crate) fn pdf_in_patches<const N: usize>(
        &self,
        patches: &[[usize; 2]; N],
        points: &[[f64; 2]; N],
        out: &mut [f32; N],
    ) {
        let mu = self.u.nodes.len();
        let mut corners = [[0.0f32; 4]; N];
        let mut weights = [[[0.0f32; 2]; 2]; N];
        let mut factors = [0.0f32; N];
        for (j, (&[i, k], &[u, v])) in patches.iter().zip(points).enumerate() {
            corners[j] = corners32(&self.values, mu, i, k);
            weights[j] = [self.u.weights(i, u), self.v.weights(k, v)];
            factors[j] = self.factors[self.patch_index(i, k)];
        }
        for j in 0..N {
            out[j] = pdf_from_weights(corners[j], weights[j], factors[j], self.scale);
        }
    }

    /// The patches of `N` points `(u[j], v[j])` on a layout the light builds
    /// (`cells` and `node_rows` as in [`CentredTables`]), as loops the compiler
    /// vectorizes: the patches [`Self::locate`] finds, bit for bit.
    #[inline(always)]
    pub(crate) fn centred_patches<const N: usize>(
        cells: [f64; 2],
        node_rows: bool,
        u: &[f32; N],
        v: &[f32; N],
    ) -> ([u32; N], [u32; N]) {
        let (mut i, mut k) = ([0u32; N], [0u32; N]);
        for j in 0..N {
            // As `locate_patch`: x ∈ [0, 1], so the floor is in [0, n].
            i[j] = (unit_closed(u[j]) * cells[0] + 0.5) as u32;
        }
        if node_rows {
            let last = cells[1] as u32 - 1;
            for j in 0..N {
                k[j] = 1 + ((unit_closed(v[j]) * cells[1]) as u32).min(last);
            }
        } else {
            for j in 0..N {
                k[j] = (unit_closed(v[j]) * cells[1] + 0.5) as u32;
            }
        }
        (i, k)
    }

    /// [`Self::pdf`] at `N` points `(u[j], v[j])` in the patches `[i[j], k[j]]`
    /// that [`Self::centred_patches`] found for them, on a layout the light builds
    /// (`cells` and `node_rows` as in [`CentredTables`]), as loops the compiler
    /// turns into vector gathers and vector arithmetic: the same operations as
    /// the single call, so bit for bit its values.
    ///
    /// # Panics
    /// When a patch is outside the grid, or the nodes are not such a layout.
    #[inline(always)]
    pub(crate) fn pdf_in_centred_patches<const N: usize>(
        &self,
        [i, k]: [&[u32; N]; 2],
        u: &[f32; N],
        v: &[f32; N],
    ) -> [f32; N] {
        let (mu, mv) = (self.u.nodes.len(), self.v.nodes.len());
        assert!(
            i.iter().all(|&i| (i as usize) + 1 < mu) && k.iter().all(|&k| (k as usize) + 1 < mv),
            "patch outside the grid"
        );
        let (cells, rows) = (self.u.cells, self.v.locating_count());
        let node_rows = self.v.rows > 0.0;
        assert!(cells > 0.0 && rows > 0.0, "not a layout the light builds");
        let mut weights = [[[0.0f32; 2]; 2]; N];
        for j in 0..N {
            let (x, y) = (unit_closed(u[j]), unit_closed(v[j]));
            let wv = if node_rows {
                row_weights(y, rows, k[j] as f64)
            } else {
                centred_weights(y, rows, k[j] as f64)
            };
            weights[j] = [centred_weights(x, cells, i[j] as f64), wv];
        }
        let (values, factors) = (&self.values, &self.factors);
        let mut out = [0.0f32; N];
        for j in 0..N {
            let (i, k) = (i[j] as usize, k[j] as usize);
            let (top, bottom) = (k * mu + i, (k + 1) * mu + i);
            // SAFETY: i + 1 < mu and k + 1 < mv (checked above), so every index is
            // below mu mv = values.len(), and the patch's below (mu - 1)(mv - 1).
            let (corners, factor) = unsafe {
                (
                    [
                        *values.get_unchecked(top),
                        *values.get_unchecked(top + 1),
                        *values.get_unchecked(bottom),
                        *values.get_unchecked(bottom + 1),
                    ],
                    *factors.get_unchecked(self.patch_index(i, k)),
                )
            };
            out[j] = pdf_from_weights(corners, weights[j], factor, self.scale);
        }
        out
    }

    /// [`Self::pdf`] at the points `(us[k], v)` of one height, into `out` (as long
    /// as `us`), located and evaluated in blocks ([`Self::pdf_in_patches`]): bit
    /// for bit the single calls.
    ///
    /// # Panics
    /// When the slices differ in length.
    pub(crate) fn pdf_at_height(&self, us: &[f32], v: f32, out: &mut [f32]) {
        assert_eq!(us.len(), out.len(), "one pdf per point");
        const BLOCK: usize = 16;
        let mut patches = [[0usize; 2]; BLOCK];
        let mut points = [[0.0f64; 2]; BLOCK];
        let mut pdfs = [0.0f32; BLOCK];
        for (us, out) in us.chunks(BLOCK).zip(out.chunks_mut(BLOCK)) {
            for (k, &u) in us.iter().enumerate() {
                (patches[k], points[k]) = self.locate([u, v]);
            }
            // A short last block repeats its first point in the lanes past its end.
            for k in us.len()..BLOCK {
                (patches[k], points[k]) = (patches[0], points[0]);
            }
            self.pdf_in_patches(&patches, &points, &mut pdfs);
            out.copy_from_slice(&pdfs[..out.len()]);
        }
    }

    /// [`Self::pdf`] from what [`Self::locate`] returned.
    #[inline(always)]
    pub(crate) fn pdf_in_patch(&self, [i, k]: [usize; 2], [u, v]: [f64; 2]) -> f32 {
        self.patch_pdf(i, k, u, v)
    }

    /// Density at `(u, v) ∈ [0, 1]²` (points outside are clamped onto the square):
    /// the bilinear interpolation of the patch's corners over the patch's mass,
    /// times the probability of picking the patch.
    #[inline]
    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        let (patch, point) = self.locate(uv);
        self.pdf_in_patch(patch, point)
    }

    /// Maps `ξ ∈ [0, 1)²` to a point with density [`Self::pdf`]: the patch from
    /// the patch distribution, then the point in it from the offsets (see the
    /// module docs). The returned cell is the patch `[i, k]`, the one [`Self::pdf`]
    /// finds for the returned point. Components outside `[0, 1)` or NaN are
    /// clamped.
    #[inline]
    pub fn sample_continuous(&self, xi: [f32; 2]) -> Sample2D {
        if self.integral <= 0.0 {
            return self.sample_black(xi);
        }
        self.place(self.patches.sample_cell(xi))
    }

    /// [`Self::sample_continuous`] for a block of `ξ` (at most
    /// [`STAGED_BLOCK`]), the patches picked
    /// with overlapping memory accesses; the same results as one at a time.
    /// `hint` hears each patch's first corner before any point is placed, so a
    /// caller can start fetching what it will read there (such as the texels of
    /// a radiance lookup).
    ///
    /// # Panics
    /// When the slices differ in length or are longer than [`STAGED_BLOCK`].
    #[inline(always)]
    pub fn sample_block(&self, xi: &[[f32; 2]], out: &mut [Sample2D], hint: impl Fn([f32; 2])) {
        self.sample_block_with::<true>(xi, out, hint);
    }

    /// [`Self::sample_continuous`] without the density: the same point and patch,
    /// with pdf 1 (0 for a function with no mass), for callers that evaluate the
    /// density elsewhere (the light, at the returned direction).
    #[inline]
    pub(crate) fn sample_point(&self, xi: [f32; 2]) -> Sample2D {
        if self.integral <= 0.0 {
            return self.sample_black(xi);
        }
        let (uv, cell) = self.place_point(self.patches.sample_cell(xi));
        Sample2D { uv, pdf: 1.0, cell }
    }

    /// [`Self::sample_block`] of [`Self::sample_point`]s.
    ///
    /// # Panics
    /// As [`Self::sample_block`].
    #[inline(always)]
    pub(crate) fn sample_point_block(
        &self,
        xi: &[[f32; 2]],
        out: &mut [Sample2D],
        hint: impl Fn([f32; 2]),
    ) {
        self.sample_block_with::<false>(xi, out, hint);
    }

    /// [`Self::sample_block`], with the densities where `PDF` (else pdf 1, as
    /// [`Self::sample_point`]).
    #[inline(always)]
    fn sample_block_with<const PDF: bool>(
        &self,
        xi: &[[f32; 2]],
        out: &mut [Sample2D],
        hint: impl Fn([f32; 2]),
    ) {
        assert_eq!(xi.len(), out.len(), "one sample per xi");
        if self.integral <= 0.0 {
            for (o, &x) in out.iter_mut().zip(xi) {
                *o = self.sample_black(x);
            }
            return;
        }
        let mut cells = [CellSample::default(); STAGED_BLOCK];
        let cells = &mut cells[..xi.len().min(STAGED_BLOCK)];
        self.patches.sample_cell_lanes_block(xi, cells);
        // Every patch's corners, and whatever the caller reads near it, start
        // loading before the first point is placed.
        for c in cells.iter() {
            self.prefetch_patch(c.cell);
            let [i, k] = c.cell;
            hint([self.u.nodes[i] as f32, self.v.nodes[k] as f32]);
        }
        // The corners and sides, then both coordinates in the patch for all
        // lanes at once (in vector lanes: two square roots and two divisions
        // each), then the points rounded to f32 in lanes, then the few that
        // rounding carried out of their patch one at a time.
        let mut corners = [[0.0f64; STAGED_BLOCK]; 4];
        let mut sides = [[0.0f64; STAGED_BLOCK]; 4];
        let mut offsets = [[0.0f64; STAGED_BLOCK]; 2];
        for (j, c) in cells.iter().enumerate() {
            let [i, k] = c.cell;
            let (q, e) = (self.corners(i, k), self.sides(i, k));
            for m in 0..4 {
                corners[m][j] = q[m];
                sides[m][j] = e[m];
            }
            (offsets[0][j], offsets[1][j]) = (c.offset[0], c.offset[1]);
        }
        let [a, b, cc, d] = &corners;
        let [u0, u1, v0, v1] = &sides;
        let mut local = [[0.0f64; STAGED_BLOCK]; 2];
        let mut point = [[0.0f32; STAGED_BLOCK]; 2];
        for j in 0..STAGED_BLOCK {
            let y = sample_linear(offsets[1][j], a[j] + b[j], cc[j] + d[j]);
            let x = sample_linear(offsets[0][j], lerp(y, a[j], cc[j]), lerp(y, b[j], d[j]));
            (local[0][j], local[1][j]) = (x, y);
            point[0][j] = round_below_one(lerp(x, u0[j], u1[j]));
            point[1][j] = round_below_one(lerp(y, v0[j], v1[j]));
        }
        let (last_u, last_v) = (self.u.nodes.len() - 2, self.v.nodes.len() - 2);
        for (j, (o, c)) in out.iter_mut().zip(cells.iter()).enumerate() {
            let [i, k] = c.cell;
            // Most points stay in their patch when rounded; the others are
            // settled one at a time by `point_in_patch`.
            let settled = kept_in_patch(point[0][j], u0[j], u1[j], i == last_u)
                && kept_in_patch(point[1][j], v0[j], v1[j], k == last_v);
            let (uv, cell) = if settled {
                ([point[0][j], point[1][j]], c.cell)
            } else {
                self.point_at(c.cell, [local[0][j], local[1][j]])
            };
            let pdf = if PDF {
                self.patch_pdf(cell[0], cell[1], uv[0] as f64, uv[1] as f64)
            } else {
                1.0
            };
            *o = Sample2D { uv, pdf, cell };
        }
    }

    /// The uniform point with pdf 0 that a function with no mass gives for `ξ`.
    fn sample_black(&self, xi: [f32; 2]) -> Sample2D {
        let uv = [
            (unit_interval(xi[0]) as f32).min(ONE_MINUS_EPSILON),
            (unit_interval(xi[1]) as f32).min(ONE_MINUS_EPSILON),
        ];
        Sample2D {
            uv,
            pdf: 0.0,
            cell: [self.u.patch(uv[0] as f64), self.v.patch(uv[1] as f64)],
        }
    }

    /// The point of patch `c.cell` that the offsets `c.offset` give: `y` from the
    /// linear marginal, then `x` from the linear conditional at `y`.
    #[inline(always)]
    fn place(&self, c: CellSample) -> Sample2D {
        let (uv, cell) = self.place_point(c);
        // The pdf is evaluated at the rounded point in the patch `pdf()` finds for
        // it, so the two agree to the bit.
        let pdf = self.patch_pdf(cell[0], cell[1], uv[0] as f64, uv[1] as f64);
        Sample2D { uv, pdf, cell }
    }

    /// [`Self::place`] without the density: the point and its patch.
    #[inline(always)]
    fn place_point(&self, c: CellSample) -> ([f32; 2], [usize; 2]) {
        let [a, b, cc, d] = self.corners(c.cell[0], c.cell[1]);
        let y = sample_linear(c.offset[1], a + b, cc + d);
        let x = sample_linear(c.offset[0], lerp(y, a, cc), lerp(y, b, d));
        self.point_at(c.cell, [x, y])
    }

    /// The point at local coordinates `[x, y]` of patch `[i, k]`, rounded to f32,
    /// and the patch [`Self::pdf`] finds for it.
    #[inline(always)]
    fn point_at(&self, [i, k]: [usize; 2], [x, y]: [f64; 2]) -> ([f32; 2], [usize; 2]) {
        let [u0, u1, v0, v1] = self.sides(i, k);
        let (u, iu) = self.u.point_in_patch(i, lerp(x, u0, u1));
        let (v, iv) = self.v.point_in_patch(k, lerp(y, v0, v1));
        ([u, v], [iu, iv])
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `uv`.
    #[inline]
    pub fn invert(&self, uv: [f32; 2]) -> [f32; 2] {
        let (u, v) = (unit_closed(uv[0]), unit_closed(uv[1]));
        if self.integral <= 0.0 {
            return [u as f32, v as f32];
        }
        let (i, k) = (self.u.patch(u), self.v.patch(v));
        let [a, b, c, d] = self.corners(i, k);
        let [u0, u1, v0, v1] = self.sides(i, k);
        let (x, y) = (local(u, u0, u1), local(v, v0, v1));
        let r = cdf_linear(y, a + b, c + d);
        let s = cdf_linear(x, lerp(y, a, c), lerp(y, b, d));
        self.patches.invert_cell([i, k], [s, r])
    }
}

/// The density in a patch with corners `[f_00, f_10, f_01, f_11]` at a point
/// whose distances to the patch's sides, in units of `1/c` along each axis, are
/// `[[left, right], [above, below]]`: the corners weighted by the opposite
/// distances are `c_u c_v Δu Δv B`, and the patch's `factor` (`F_ik` of
/// [`BilinearDistribution2D`], over `scale`) turns them into
/// `P_ik B / M_ik = 4 P_ik Δu Δv B / (Δu² Δv² Σf)`. All in `f32`, in one order,
/// with selects only, so that a loop over lanes vectorizes and every path (single
/// calls, lanes, hand-written kernels) gives the same bits.
#[inline(always)]
fn pdf_from_weights(
    [a, b, c, d]: [f32; 4],
    [[left, right], [above, below]]: [[f32; 2]; 2],
    factor: f32,
    scale: f32,
) -> f32 {
    let weighted = below * (right * a + left * b) + above * (right * c + left * d);
    factor * (weighted * scale)
}

/// The factors `F_ik = 4 P_ik / (c Δu² Δv² Σf)` of [`BilinearDistribution2D`]
/// (`c`: the two axes' counts times the scale), row by row in loops the compiler
/// vectorizes; 0 for a patch of no mass or probability. A factor beyond `f32`
/// (a patch whose probability the CDF's `2⁻⁶⁴` quantum raised far above its
/// mass, at a dynamic range of the values beyond `f32`'s) is kept finite.
fn patch_factors(
    values: &[f32],
    [u_nodes, v_nodes]: [&[f64]; 2],
    patches: &Distribution2D,
    c: f64,
) -> Vec<f32> {
    use rayon::prelude::*;
    let (mu, mv) = (u_nodes.len(), v_nodes.len());
    let widths: Vec<f64> = u_nodes.windows(2).map(|w| w[1] - w[0]).collect();
    let mut factors = vec![0.0f32; (mu - 1) * (mv - 1)];
    let width = VectorWidth::detect();
    // Rows in parallel, each an independent loop; a task takes enough rows to
    // be worth its scheduling.
    let rows_per_task = (16384 / mu).max(1);
    factors
        .par_chunks_mut((mu - 1) * rows_per_task)
        .enumerate()
        .for_each(|(task, rows)| {
            for (r, row) in rows.chunks_mut(mu - 1).enumerate() {
                let k = task * rows_per_task + r;
                let (cdf, marginal) = patches.row_widths(k);
                let height = v_nodes[k + 1] - v_nodes[k];
                let args = FactorRow {
                    top: &values[k * mu..(k + 1) * mu],
                    bottom: &values[(k + 1) * mu..(k + 2) * mu],
                    cdf,
                    marginal,
                    widths: &widths,
                    row_scale: c * height * height,
                };
                factor_row_at(width, &args, row);
            }
        });
    factors
}

/// One row of patches' inputs to their masses: the top and bottom node values,
/// the u nodes, the row's height and the number of patches.
struct MassRow<'a> {
    top: &'a [f32],
    bottom: &'a [f32],
    u_nodes: &'a [f64],
    height: f64,
    patch_count: f64,
}

/// [`mass_row`] compiled for the vectors `width` names (the same IEEE
/// operations at every width, so the same weights and sum).
fn mass_row_at(width: VectorWidth, args: &MassRow<'_>, out: &mut [f32]) -> f64 {
    at_width!(width, fn(args: &MassRow<'_>, out: &mut [f32]) -> f64 {
        mass_row(args, out)
    })
}

/// A row of patches' masses `Δu Δv (a + b + c + d) / 4` (exact, in f64): each
/// written to `out` relative to the mean patch area, so that it stays well
/// inside f32's range for any node spacing (a positive mass never rounds to 0),
/// and their sum returned, summed in four interleaved partial sums (a loop the
/// compiler vectorizes; one running sum would be a chain of dependent adds).
#[inline(always)]
fn mass_row(a: &MassRow<'_>, out: &mut [f32]) -> f64 {
    let n = out.len();
    let (top, bottom, u) = (&a.top[..n + 1], &a.bottom[..n + 1], &a.u_nodes[..n + 1]);
    let mass = |i: usize| (u[i + 1] - u[i]) * a.height * 0.25 * corner_sum(top, bottom, i);
    let mut partial = [0.0f64; 4];
    let mut quads = out.chunks_exact_mut(4);
    for (q, quad) in (&mut quads).enumerate() {
        for (l, (o, p)) in quad.iter_mut().zip(&mut partial).enumerate() {
            let exact = mass(4 * q + l);
            *p += exact;
            *o = positive_weight(exact * a.patch_count);
        }
    }
    let rest = quads.into_remainder();
    let mut rest_sum = 0.0f64;
    for (l, o) in rest.iter_mut().enumerate() {
        let exact = mass(n - n % 4 + l);
        rest_sum += exact;
        *o = positive_weight(exact * a.patch_count);
    }
    (partial[0] + partial[1]) + (partial[2] + partial[3]) + rest_sum
}

/// One row of [`patch_factors`]' inputs: the patches' top and bottom node
/// values, the row's conditional CDF and marginal width, the patch widths and
/// `c Δv²`.
struct FactorRow<'a> {
    top: &'a [f32],
    bottom: &'a [f32],
    cdf: &'a [u32],
    marginal: u32,
    widths: &'a [f64],
    row_scale: f64,
}

/// [`factor_row`] compiled for the vectors `width` names (the same IEEE
/// operations at every width, so the same factors; AVX-512 divides eight f64 at
/// a time where the baseline's SSE2 divides two).
fn factor_row_at(width: VectorWidth, args: &FactorRow<'_>, out: &mut [f32]) {
    at_width!(width, fn(args: &FactorRow<'_>, out: &mut [f32]) {
        factor_row(args, out)
    })
}

/// The sum of patch `i`'s four node values in f64, in [`corners`]' order, from
/// its row's top and bottom nodes.
#[inline(always)]
fn corner_sum(top: &[f32], bottom: &[f32], i: usize) -> f64 {
    top[i] as f64 + top[i + 1] as f64 + bottom[i] as f64 + bottom[i + 1] as f64
}

/// The factors of one row of patches (see [`patch_factors`]).
#[inline(always)]
fn factor_row(a: &FactorRow<'_>, out: &mut [f32]) {
    let n = out.len();
    let (top, bottom, cdf, widths) = (
        &a.top[..n + 1],
        &a.bottom[..n + 1],
        &a.cdf[..n + 1],
        &a.widths[..n],
    );
    for (i, f) in out.iter_mut().enumerate() {
        let sum = corner_sum(top, bottom, i);
        let probability = probability_of_widths([cdf[i + 1] - cdf[i], a.marginal]);
        let denominator = a.row_scale * widths[i] * widths[i] * sum;
        let factor = (4.0 * probability / denominator).min(f32::MAX as f64) as f32;
        *f = if denominator > 0.0 && probability > 0.0 {
            factor
        } else {
            0.0
        };
    }
}

/// The power of two [`pdf_from_weights`] scales the weighted corners by: 1 for an
/// integral in `[2⁻⁶⁴, 2⁶⁴]`, else about its reciprocal (so that the factors,
/// about `1 / (I · scale)`, stay near 1).
fn factor_scale(integral: f64) -> f32 {
    if integral > 0.0 && !(2f64.powi(-64)..=2f64.powi(64)).contains(&integral) {
        let e = (-integral.log2().round()).clamp(-126.0, 126.0) as i32;
        2f32.powi(e)
    } else {
        1.0
    }
}

/// `[x n − lo, hi − x n]` for `x ∈ [0, 1]` in patch `i` of the texel-centre layout
/// over `n` texels, whose sides in texel units are `lo = max(i − ½, 0)` and
/// `hi = min(i + ½, n)`: exact in `f64` (for `n < 2²⁸` the product of an `f32`
/// and `n` is), so rounded once, to `f32`. Negative distances (a point outside
/// the patch) count as 0.
#[inline(always)]
fn centred_weights(x: f64, n: f64, i: f64) -> [f32; 2] {
    let at = x * n;
    let (lo, hi) = ((i - 0.5).max(0.0), (i + 0.5).min(n));
    [(at - lo).max(0.0) as f32, (hi - at).max(0.0) as f32]
}

/// [`centred_weights`] for the node-row layout over `m` row intervals, whose
/// patch `i` (from 1 to `m`; 0 and `m + 1` have no width) runs from `i − 1` to
/// `i` in row units.
#[inline(always)]
fn row_weights(x: f64, m: f64, i: f64) -> [f32; 2] {
    let at = x * m;
    let (lo, hi) = ((i - 1.0).max(0.0).min(m), i.min(m));
    [(at - lo).max(0.0) as f32, (hi - at).max(0.0) as f32]
}

/// Checks one axis's node positions: from exactly 0 to exactly 1, never
/// decreasing (a repeated node is a patch of zero width).
fn check_nodes(axis: &str, nodes: &[f64]) -> Result<()> {
    let bad = |why: &str| {
        Err(Error::InvalidOption(format!(
            "bilinear {axis} nodes: {why}"
        )))
    };
    if nodes.len() < 2 {
        return bad("need at least 2");
    }
    if nodes.iter().any(|x| !x.is_finite()) {
        return bad("not finite");
    }
    if nodes[0] != 0.0 || nodes[nodes.len() - 1] != 1.0 {
        return bad("must start at 0 and end at 1");
    }
    if nodes.windows(2).any(|w| w[0] > w[1]) {
        return bad("decreasing");
    }
    Ok(())
}

/// Samples `x ∈ [0, 1)` from the density ∝ `a (1 - x) + b x` (`a, b ≥ 0`):
/// `x = ξ (a + b) / (a + √((1 - ξ) a² + ξ b²))`, the stable root of
/// `(b - a) x² / 2 + a x = ξ (a + b) / 2`. Uniform when `a = b` (including 0).
///
/// Written with selects and no early return, so that a loop over lanes
/// vectorizes ([`BilinearDistribution2D::sample_block`]).
#[inline(always)]
pub(crate) fn sample_linear(xi: f64, a: f64, b: f64) -> f64 {
    let denominator = a + ((1.0 - xi) * a * a + xi * b * b).sqrt();
    let x = (xi * (a + b) / denominator).clamp(0.0, BELOW_ONE);
    // A zero denominator is a = 0 and ξ b² = 0: the density's zero end.
    let x = if denominator > 0.0 { x } else { 0.0 };
    if a == b {
        xi
    } else {
        x
    }
}

/// The CDF of the density ∝ `a (1 - x) + b x` on `[0, 1]`, the inverse of
/// [`sample_linear`]: `x (a (2 - x) + b x) / (a + b)`.
#[inline]
fn cdf_linear(x: f64, a: f64, b: f64) -> f64 {
    if a == b {
        return x;
    }
    (x * (a * (2.0 - x) + b * x) / (a + b)).clamp(0.0, 1.0)
}

/// The patch of `nodes` holding `x ∈ [0, 1]`: the last `i ≤ n - 2` with
/// `nodes[i] <= x` and `nodes[i] < 1`, which has positive width (with repeated
/// nodes, `nodes[i] <= x` alone would give a zero-width patch `[1, 1]` at
/// `x = 1`).
#[inline]
fn patch_of(nodes: &[f64], x: f64) -> usize {
    nodes[1..nodes.len() - 1].partition_point(|&n| below(n, x))
}

/// Whether node `n` is at or below `x` and below 1: the predicate that
/// [`patch_of`] counts the interior nodes by (true for a prefix of them).
#[inline(always)]
fn below(n: f64, x: f64) -> bool {
    n <= x && n < 1.0
}

/// A guide to [`patch_of`]: with `G = nodes.len() - 1` equal cells over `[0, 1]`,
/// entry `g` is the patch holding `g / G` (`G + 1` entries). A query then only
/// searches the nodes between the entries around it: O(1) for evenly spread
/// nodes (such as texel centres), O(log n) at worst.
fn guide(nodes: &[f64]) -> Vec<u32> {
    let cells = nodes.len() - 1;
    (0..=cells)
        .map(|g| patch_of(nodes, g as f64 / cells as f64) as u32)
        .collect()
}

/// [`patch_of`] through a [`guide`].
#[inline]
fn guided_patch(nodes: &[f64], guide: &[u32], x: f64) -> usize {
    let cells = guide.len() - 1;
    let g = ((x * cells as f64) as usize).min(cells);
    // One guide cell of margin either side absorbs the rounding of x·G.
    let lo = guide[g.saturating_sub(1)] as usize;
    let hi = guide[(g + 2).min(cells)] as usize;
    lo + nodes[lo + 1..=hi].partition_point(|&n| below(n, x))
}

/// The corners `[f_00, f_10, f_01, f_11]` (top-left, top-right, bottom-left,
/// bottom-right) of patch `[i, k]` of the node values `values`, `mu` per row:
/// also the product sampler's bilinear cells ([`crate::product`]).
///
/// # Panics
/// When the patch is outside the grid.
#[inline(always)]
pub(crate) fn corners(values: &[f32], mu: usize, i: usize, k: usize) -> [f64; 4] {
    assert!(
        i + 1 < mu && (k + 2) * mu <= values.len(),
        "patch outside the grid"
    );
    let (top, bottom) = (k * mu + i, (k + 1) * mu + i);
    // SAFETY: bottom + 1 = (k + 1) mu + i + 1 < (k + 2) mu <= values.len().
    unsafe {
        [
            *values.get_unchecked(top) as f64,
            *values.get_unchecked(top + 1) as f64,
            *values.get_unchecked(bottom) as f64,
            *values.get_unchecked(bottom + 1) as f64,
        ]
    }
}

/// [`corners`] as stored, in `f32`.
///
/// # Panics
/// When the patch is outside the grid.
#[inline(always)]
fn corners32(values: &[f32], mu: usize, i: usize, k: usize) -> [f32; 4] {
    let (top, bottom) = (k * mu + i, (k + 1) * mu + i);
    [
        values[top],
        values[top + 1],
        values[bottom],
        values[bottom + 1],
    ]
}

/// One axis of the node grid: the node positions, their lookup [`guide`], and
/// whether they are the texel-centre layout.
#[derive(Debug, Clone, PartialEq)]
struct Axis {
    nodes: Vec<f64>,
    guide: Vec<u32>,
    /// `n` when the nodes are the texel-centre layout `0, (j + ½)/n, 1`
    /// ([`centred_cells`]), whose patches are found with one multiplication;
    /// else 0.
    cells: f64,
    /// `m` when the nodes are the node-row layout `0, 0, k/m for k ≤ m, 1, 1`
    /// ([`node_rows`]), likewise found with one multiplication; else 0.
    rows: f64,
}

impl Axis {
    /// The axis of `nodes` (already checked).
    fn new(nodes: &[f64]) -> Self {
        Self {
            nodes: nodes.to_vec(),
            guide: guide(nodes),
            cells: centred_cells(nodes),
            rows: node_rows(nodes),
        }
    }

    /// How many of the units a point's distances to its patch's sides are
    /// measured in span the axis ([`Self::weights`]): `n` for the texel-centre
    /// layout, `m` for the node rows, else the number of patches.
    fn count(&self) -> f64 {
        if self.cells > 0.0 {
            self.cells
        } else if self.rows > 0.0 {
            self.rows
        } else {
            (self.nodes.len() - 1) as f64
        }
    }

    /// The distances `[x − start, end − x]` of `x ∈ [0, 1]` to the sides of patch
    /// `i`, in units of `1 / count` and in `f32` (0 where negative): exactly
    /// rounded for the light's layouts ([`centred_weights`], [`row_weights`]).
    #[inline(always)]
    fn weights(&self, i: usize, x: f64) -> [f32; 2] {
        if self.cells > 0.0 {
            centred_weights(x, self.cells, i as f64)
        } else if self.rows > 0.0 {
            row_weights(x, self.rows, i as f64)
        } else {
            let [a, b] = self.side(i);
            let c = self.count();
            [((x - a) * c).max(0.0) as f32, ((b - x) * c).max(0.0) as f32]
        }
    }

    /// The count that locates a patch with one product: `n` for the texel-centre
    /// layout, `m` for the node rows (0 otherwise).
    fn locating_count(&self) -> f64 {
        if self.cells > 0.0 {
            self.cells
        } else {
            self.rows
        }
    }

    /// Bytes held.
    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.guide.as_slice())
    }

    /// The patch holding `x ∈ [0, 1]` ([`locate_patch`]).
    #[inline(always)]
    fn patch(&self, x: f64) -> usize {
        locate_patch(&self.nodes, &self.guide, [self.cells, self.rows], x)
    }

    /// The ends of patch `i`.
    #[inline(always)]
    fn side(&self, i: usize) -> [f64; 2] {
        [self.nodes[i], self.nodes[i + 1]]
    }

    /// `x` rounded to `f32` below 1 and kept where [`patch_of`] finds patch `i`
    /// (rounding can carry a point on a patch edge into the neighbour), with the
    /// patch [`patch_of`] finds for it: `i`, unless the patch is narrower than an
    /// `f32` step.
    #[inline]
    fn point_in_patch(&self, i: usize, x: f64) -> (f32, usize) {
        let nodes = &self.nodes;
        let last = nodes.len() - 2;
        let mut y = round_below_one(x);
        for _ in 0..4 {
            if kept_in_patch(y, nodes[i], nodes[i + 1], i == last) {
                return (y, i);
            }
            // Not kept: at or past the end (step down), or before the start.
            y = if (y as f64) < nodes[i] {
                f32::from_bits(y.to_bits() + 1)
            } else {
                f32::from_bits(y.to_bits() - 1)
            };
        }
        (y, self.patch(y as f64))
    }
}

/// `n` when `nodes` are `0, (j + ½)/n for j < n, 1` exactly as written here (the
/// texel-centre layout), else 0.
fn centred_cells(nodes: &[f64]) -> f64 {
    let n = nodes.len().saturating_sub(2);
    let centred = n >= 1
        && nodes[0] == 0.0
        && nodes[n + 1] == 1.0
        && (0..n).all(|j| nodes[j + 1] == (j as f64 + 0.5) / n as f64);
    if centred {
        n as f64
    } else {
        0.0
    }
}

/// `m` when `nodes` are `0, 0, k/m for k ≤ m, 1, 1` exactly as written here (the
/// node-row layout of an image of `m + 1 ≥ 2` rows), else 0.
fn node_rows(nodes: &[f64]) -> f64 {
    let m = nodes.len().saturating_sub(3);
    let rows = m >= 1
        && nodes[0] == 0.0
        && nodes[m + 2] == 1.0
        && (0..=m).all(|k| nodes[k + 1] == k as f64 / m as f64);
    if rows {
        m as f64
    } else {
        0.0
    }
}

/// [`patch_of`] for `x` that is an `f32` in `[0, 1]`, with `[cells, rows]` of the
/// [`Axis`]: `⌊x n + ½⌋` for the texel-centre layout over `cells = n > 0` texels,
/// `1 + min(⌊x m⌋, m - 1)` for the node-row layout over `rows = m > 0` intervals,
/// else through the guide. For `n, m < 2²⁸` they agree exactly: `x n + ½` and
/// `x m` are exact in `f64`, and an `f32` that is not a node `(2j + 1) / 2n` (or
/// `k / m`) is at least `2⁻²⁴ / 2n` (relative) from it, far more than the node's
/// rounding to `f64`, which so cannot flip a comparison.
#[inline(always)]
fn locate_patch(nodes: &[f64], guide: &[u32], [cells, rows]: [f64; 2], x: f64) -> usize {
    if cells > 0.0 {
        // x ∈ [0, 1], so the floor is in [0, n] (n at x = 1, the last patch).
        (x * cells + 0.5) as usize
    } else if rows > 0.0 {
        // Patch 0 and m + 1 are the zero-width ones at the ends.
        1 + ((x * rows) as usize).min(rows as usize - 1)
    } else {
        guided_patch(nodes, guide, x)
    }
}

/// `x` rounded to `f32` and kept below 1: where [`Axis::point_in_patch`] starts.
#[inline(always)]
fn round_below_one(x: f64) -> f32 {
    (x as f32).min(ONE_MINUS_EPSILON)
}

/// Whether [`Axis::point_in_patch`] keeps `y` in the patch `[start, end]`
/// (`last`: the axis's last patch, which keeps its end): the test of each of its
/// passes, which a block of samples makes first in lanes.
#[inline(always)]
fn kept_in_patch(y: f32, start: f64, end: f64, last: bool) -> bool {
    let yd = y as f64;
    !(!last && yd >= end && y > 0.0) && yd >= start
}

/// `(x - a) / (b - a)` clamped to `[0, 1]`.
#[inline]
fn local(x: f64, a: f64, b: f64) -> f64 {
    ((x - a) / (b - a)).clamp(0.0, 1.0)
}

#[inline]
fn lerp(t: f64, a: f64, b: f64) -> f64 {
    (1.0 - t) * a + t * b
}

/// `x` in `[0, 1]` as an `f64`; NaN gives 0.
#[inline(always)]
fn unit_closed(x: f32) -> f64 {
    // Computed on both sides of the select, so that vector lanes need no branch.
    let y = (x as f64).min(1.0);
    if x > 0.0 {
        y
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alias::test_support;
    use crate::image::EnvImage;
    use crate::rng::{xi_2d, SplitMix64};

    /// Significance level of every chi-square test here.
    const ALPHA: f64 = 1e-3;

    /// The patch factors and masses are the same bits at every vector width this
    /// CPU has (the tables must not depend on the machine that built them): a row
    /// with a sun, zero nodes, a zero-width patch and values spanning f32's range.
    #[test]
    fn patch_tables_are_the_same_at_every_vector_width() {
        let mut rng = SplitMix64::new(11);
        let n = 203;
        let top: Vec<f32> = (0..=n)
            .map(|i| match i % 17 {
                0 => 0.0,
                1 => 3e30,
                2 => 1e-30,
                _ => rng.next_f32() * 5.0,
            })
            .collect();
        let bottom: Vec<f32> = (0..=n).map(|_| rng.next_f32()).collect();
        let mut cdf = vec![0u32; n + 1];
        for i in 1..=n {
            cdf[i] = cdf[i - 1] + (rng.next_f32() * 1e6) as u32 * u32::from(i % 13 != 0);
        }
        let mut widths: Vec<f64> = (0..n).map(|_| 0.5 + rng.next_f32() as f64).collect();
        widths[7] = 0.0;
        let args = FactorRow {
            top: &top,
            bottom: &bottom,
            cdf: &cdf,
            marginal: 123_456_789,
            widths: &widths,
            row_scale: 0.37,
        };
        let run = |width| {
            let mut out = vec![0.0f32; n];
            factor_row_at(width, &args, &mut out);
            out.iter().map(|f| f.to_bits()).collect::<Vec<_>>()
        };
        let baseline = run(VectorWidth::Baseline);
        assert!(baseline.iter().any(|&b| b != 0) && baseline.contains(&0));
        // The patches' masses and their row sum, over the same nodes (a row
        // length that leaves a remainder after the fours).
        let u_nodes: Vec<f64> = std::iter::once(0.0)
            .chain(widths.iter().scan(0.0, |x, w| {
                *x += w;
                Some(*x)
            }))
            .collect();
        let masses = MassRow {
            top: &top,
            bottom: &bottom,
            u_nodes: &u_nodes,
            height: 0.013,
            patch_count: 5e4,
        };
        let run_masses = |width| {
            let mut out = vec![0.0f32; n];
            let sum = mass_row_at(width, &masses, &mut out);
            (
                sum.to_bits(),
                out.iter().map(|f| f.to_bits()).collect::<Vec<_>>(),
            )
        };
        let baseline_masses = run_masses(VectorWidth::Baseline);
        assert!(f64::from_bits(baseline_masses.0) > 0.0 && baseline_masses.1.contains(&0));
        for width in [VectorWidth::Avx2, VectorWidth::Avx512] {
            if width <= VectorWidth::detect() {
                assert_eq!(run(width), baseline, "{width:?}");
                assert_eq!(run_masses(width), baseline_masses, "{width:?}");
            }
        }
    }

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// Random increasing nodes from 0 to 1.
    fn random_nodes(rng: &mut SplitMix64, n: usize) -> Vec<f64> {
        let mut x: Vec<f64> = (0..n).map(|_| 0.2 + rng.next_f64()).collect();
        let mut sum = 0.0;
        for v in x.iter_mut() {
            sum += *v;
            *v = sum;
        }
        let mut nodes = vec![0.0];
        nodes.extend(
            x[..n - 2]
                .iter()
                .map(|v| v / x[n - 2] * (1.0 - 1.0 / n as f64)),
        );
        nodes.push(1.0);
        nodes
    }

    /// A random density: node values over three decades with zero patches, a zero
    /// node row and a zero node column in the middle.
    fn random_density(rng: &mut SplitMix64, mu: usize, mv: usize) -> BilinearDistribution2D {
        let mut values: Vec<f32> = (0..mu * mv)
            .map(|_| {
                if rng.next_f64() < 0.25 {
                    0.0
                } else {
                    10f32.powf(3.0 * rng.next_f32() - 1.5)
                }
            })
            .collect();
        for i in 0..mu {
            values[(mv / 2) * mu + i] = 0.0;
        }
        for k in 0..mv {
            values[k * mu + mu / 3] = 0.0;
        }
        if values.iter().all(|&x| x == 0.0) {
            values[mu - 1] = 1.0;
        }
        let (u, v) = (random_nodes(rng, mu), random_nodes(rng, mv));
        BilinearDistribution2D::new(&values, &u, &v)
    }

    /// `∫∫ p` over `[u0, u1] × [v0, v1]` inside one patch: a bilinear function's mean
    /// over a rectangle is its value at the centre.
    fn rect_probability(d: &BilinearDistribution2D, u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
        let (i, k) = (
            patch_of(&d.u.nodes, 0.5 * (u0 + u1)),
            patch_of(&d.v.nodes, 0.5 * (v0 + v1)),
        );
        let (u, v) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
        let tu = local(u, d.u.nodes[i], d.u.nodes[i + 1]);
        let tv = local(v, d.v.nodes[k], d.v.nodes[k + 1]);
        let mu = d.u.nodes.len();
        let at = |kk: usize, ii: usize| d.values[kk * mu + ii] as f64;
        let b = lerp(
            tv,
            lerp(tu, at(k, i), at(k, i + 1)),
            lerp(tu, at(k + 1, i), at(k + 1, i + 1)),
        );
        b / d.integral * (u1 - u0) * (v1 - v0)
    }

    /// Bins: every patch split 2×2. Returns the bin rectangles.
    fn bins(d: &BilinearDistribution2D) -> Vec<[f64; 4]> {
        let halves = |n: &[f64]| -> Vec<f64> {
            let mut out = vec![];
            for w in n.windows(2) {
                out.push(w[0]);
                out.push(0.5 * (w[0] + w[1]));
            }
            out.push(1.0);
            out
        };
        let (us, vs) = (halves(&d.u.nodes), halves(&d.v.nodes));
        let mut out = vec![];
        for vw in vs.windows(2) {
            for uw in us.windows(2) {
                out.push([uw[0], uw[1], vw[0], vw[1]]);
            }
        }
        out
    }

    fn chi_square(
        d: &BilinearDistribution2D,
        expected_of: impl Fn([f64; 4]) -> f64,
        n: u64,
        seed: u64,
    ) -> f64 {
        let rects = bins(d);
        let nbu = 2 * (d.u.nodes.len() - 1);
        let mut counts = vec![0u64; rects.len()];
        for k in 0..n {
            let s = d.sample_continuous(xi_2d(seed, k));
            let (u, v) = (s.uv[0] as f64, s.uv[1] as f64);
            let (i, kk) = (s.cell[0], s.cell[1]);
            let bu = 2 * i + (u >= 0.5 * (d.u.nodes[i] + d.u.nodes[i + 1])) as usize;
            let bv = 2 * kk + (v >= 0.5 * (d.v.nodes[kk] + d.v.nodes[kk + 1])) as usize;
            counts[bv * nbu + bu] += 1;
        }
        let expected: Vec<f64> = rects.iter().map(|&r| expected_of(r) * n as f64).collect();
        test_support::chi_square(&counts, &expected).2
    }

    #[test]
    fn hand_computed_linear_in_u() {
        // B(u, v) = u: I = 1/2, p = 2u, u = √ξ0, v = ξ1.
        let d = BilinearDistribution2D::new(&[0.0, 1.0, 0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]);
        assert_eq!(d.integral(), 0.5);
        for &(a, b) in &[(0.25f32, 0.3f32), (0.64, 0.9), (0.01, 0.0)] {
            let s = d.sample_continuous([a, b]);
            assert!(
                close(s.uv[0], a.sqrt(), 1e-6) && close(s.uv[1], b, 1e-6),
                "{s:?}"
            );
            assert!(close(s.pdf, 2.0 * a.sqrt(), 1e-6), "{s:?}");
            let back = d.invert(s.uv);
            assert!(
                close(back[0], a, 1e-6) && close(back[1], b, 1e-6),
                "{back:?}"
            );
        }
        assert_eq!(d.pdf([0.0, 0.5]), 0.0);
        assert_eq!(d.pdf([1.0, 0.5]), 2.0);
    }

    #[test]
    fn hand_computed_linear_in_v() {
        // Node rows 1 and 3: B = 1 + 2v, I = 2, CDF (v + v²)/2; ξ1 = .5 gives
        // v² + v - 1 = 0, v = (√5 - 1)/2, pdf (1 + 2v)/2 = √5/2.
        let d = BilinearDistribution2D::new(&[1.0, 1.0, 3.0, 3.0], &[0.0, 1.0], &[0.0, 1.0]);
        let s = d.sample_continuous([0.7, 0.5]);
        let golden = (5f32.sqrt() - 1.0) / 2.0;
        assert!(
            close(s.uv[1], golden, 1e-6) && close(s.uv[0], 0.7, 1e-6),
            "{s:?}"
        );
        assert!(close(s.pdf, 5f32.sqrt() / 2.0, 1e-6), "{s:?}");
        // Uneven nodes, constant values: the identity map.
        let d = BilinearDistribution2D::new(&[2.0; 9], &[0.0, 0.1, 1.0], &[0.0, 0.7, 1.0]);
        let s = d.sample_continuous([0.37, 0.81]);
        assert!(
            close(s.uv[0], 0.37, 1e-6) && close(s.uv[1], 0.81, 1e-6) && close(s.pdf, 1.0, 1e-6),
            "{s:?}"
        );
        assert_eq!(s.cell, [1, 1]);
    }

    #[test]
    fn guided_lookup_matches_binary_search() {
        let mut rng = SplitMix64::new(40);
        for n in [2, 3, 5, 17, 100] {
            let mut nodes = random_nodes(&mut rng, n);
            if n > 4 {
                // A cluster of close nodes.
                for (j, node) in nodes.iter_mut().enumerate().take(n / 2).skip(1) {
                    *node = j as f64 * 1e-9;
                }
            }
            let g = guide(&nodes);
            let mut probes: Vec<f64> = nodes.clone();
            probes.extend((0..2000).map(|_| rng.next_f64()));
            probes.extend(nodes.iter().map(|&x| (x - 1e-17).max(0.0)));
            probes.extend([0.0, 1.0, 1.0 - 1e-16]);
            for x in probes {
                assert_eq!(
                    guided_patch(&nodes, &g, x),
                    patch_of(&nodes, x),
                    "n {n} x {x}"
                );
            }
        }
    }

    /// The texel-centre and node-row shortcuts find the patch the node
    /// comparisons find, for every f32 near each node (the nodes themselves, the
    /// f32 steps either side) and for random f32, on sides that are and are not
    /// powers of two; the node rows never give a zero-width end patch.
    #[test]
    fn centred_lookup_matches_the_node_comparisons() {
        let mut rng = SplitMix64::new(41);
        let centred = |n: usize| {
            let mut nodes = vec![0.0];
            nodes.extend((0..n).map(|j| (j as f64 + 0.5) / n as f64));
            nodes.push(1.0);
            nodes
        };
        let rows = |n: usize| {
            let mut nodes = vec![0.0];
            nodes.extend((0..n).map(|j| j as f64 / (n - 1) as f64));
            nodes.push(1.0);
            nodes
        };
        let layouts = [1usize, 2, 3, 7, 96, 1000, 1024, 4097, 16384]
            .into_iter()
            .map(|n| (n, centred(n), [n as f64, 0.0]))
            .chain(
                [2usize, 3, 7, 96, 1000, 1025, 4097, 16385]
                    .into_iter()
                    .map(|n| (n, rows(n), [0.0, (n - 1) as f64])),
            );
        for (n, nodes, shortcut) in layouts {
            assert_eq!([centred_cells(&nodes), node_rows(&nodes)], shortcut);
            let cells = shortcut;
            let g = guide(&nodes);
            let mut probes: Vec<f32> = vec![0.0, 1.0, ONE_MINUS_EPSILON];
            for &x in &nodes {
                let x = x as f32;
                probes.extend([
                    x,
                    x.next_up(),
                    x.next_down().max(0.0),
                    x.next_up().next_up(),
                ]);
            }
            probes.extend((0..20_000).map(|_| rng.next_f32()));
            for x in probes {
                let x = (x as f64).clamp(0.0, 1.0);
                let patch = locate_patch(&nodes, &g, cells, x);
                assert_eq!(patch, patch_of(&nodes, x), "n {n} x {x}");
                assert_eq!(patch, locate_patch(&nodes, &g, [0.0; 2], x), "n {n} x {x}");
                assert!(nodes[patch] < nodes[patch + 1], "n {n} x {x}");
            }
        }
        let uneven = [0.0, 0.3, 1.0];
        assert_eq!(centred_cells(&uneven), 0.0);
        assert_eq!(centred_cells(&[0.0, 1.0]), 0.0);
        assert_eq!(node_rows(&uneven), 0.0);
        assert_eq!(node_rows(&[0.0, 0.0, 1.0, 1.0]), 1.0);
    }

    #[test]
    fn linear_sampling_is_stable_and_inverts() {
        for &(a, b) in &[
            (1.0, 1.0),
            (0.0, 1.0),
            (1.0, 0.0),
            (1e-30, 1.0),
            (1.0, 1e-30),
            (3.0, 5.0),
            (0.0, 0.0),
        ] {
            for k in 0..=100 {
                let xi = (k as f64 / 100.0).min(BELOW_ONE);
                let x = sample_linear(xi, a, b);
                assert!((0.0..1.0).contains(&x), "{a} {b} {xi} → {x}");
                assert!(
                    (cdf_linear(x, a, b) - xi).abs() < 1e-12,
                    "{a} {b} {xi} → {x}"
                );
            }
        }
    }

    #[test]
    fn normalised_by_quadrature() {
        // ∫∫ p = 1 by 2×2 Gauss-Legendre per patch (exact for bilinear).
        let mut rng = SplitMix64::new(3);
        for &(mu, mv) in &[(2, 2), (5, 4), (17, 9)] {
            let d = random_density(&mut rng, mu, mv);
            let g = 0.5 / 3f64.sqrt();
            let mut total = 0.0;
            for k in 0..mv - 1 {
                for i in 0..mu - 1 {
                    let (du, dv) = (
                        d.u.nodes[i + 1] - d.u.nodes[i],
                        d.v.nodes[k + 1] - d.v.nodes[k],
                    );
                    for &a in &[0.5 - g, 0.5 + g] {
                        for &b in &[0.5 - g, 0.5 + g] {
                            let u = d.u.nodes[i] + a * du;
                            let v = d.v.nodes[k] + b * dv;
                            total += d.patch_pdf(i, k, u, v) as f64 * du * dv / 4.0;
                        }
                    }
                }
            }
            assert!((total - 1.0).abs() < 1e-6, "{mu}x{mv}: {total}");
        }
        // A density off by 1 % fails the same check.
        let d = random_density(&mut rng, 5, 5);
        let total: f64 = bins(&d)
            .iter()
            .map(|r| rect_probability(&d, r[0], r[1], r[2], r[3]) * 1.01)
            .sum();
        assert!((total - 1.0).abs() > 1e-6);
    }

    #[test]
    fn blocks_and_points_equal_single_samples() {
        // Random nodes (with repeats), the texel-centre layout and the node
        // rows; ξ on a grid fine enough that some points round onto a patch
        // edge and are settled one at a time.
        let mut rng = SplitMix64::new(9);
        let image: Vec<f32> = (0..7 * 5).map(|_| rng.next_f32() + 0.05).collect();
        let (values, u, v) = texel_centre_layout(&image, 7, 5);
        let mut densities = vec![
            random_density(&mut rng, 5, 4),
            random_density(&mut rng, 17, 9),
            BilinearDistribution2D::new(&values, &u, &v),
        ];
        let rows = [0.0, 0.0, 0.25, 0.5, 0.75, 1.0, 1.0];
        densities.push(BilinearDistribution2D::new(&values, &u, &rows));
        assert_eq!(densities[2].image_cells(), Some(([7, 5], false)));
        assert_eq!(densities[3].image_cells(), Some(([7, 5], true)));
        let near = |x: f32| {
            [
                x,
                f32::from_bits(x.to_bits().saturating_sub(1)),
                x.next_up(),
            ]
        };
        for d in &densities {
            // ξ that lands on the nodes (the inverse of each node), and beside.
            let mut xi: Vec<[f32; 2]> = Vec::new();
            for &u in &d.u.nodes {
                for &v in &d.v.nodes {
                    let [a, b] = d.invert([u as f32, v as f32]);
                    for a in near(a) {
                        xi.extend(near(b).map(|b| [a, b]));
                    }
                }
            }
            xi.extend((0..4096).map(|k| [(k % 64) as f32 / 64.0, (k / 64) as f32 / 64.0]));
            xi.extend((0..4096).map(|k| xi_2d(3, k)));
            for xi in xi.chunks(STAGED_BLOCK) {
                let mut block = vec![Sample2D::default(); xi.len()];
                let mut points = block.clone();
                d.sample_block(xi, &mut block, |_| {});
                d.sample_point_block(xi, &mut points, |_| {});
                for ((x, b), p) in xi.iter().zip(&block).zip(&points) {
                    let one = d.sample_continuous(*x);
                    assert_eq!(*b, one, "{x:?}");
                    assert_eq!(*p, d.sample_point(*x), "{x:?}");
                    assert_eq!((p.uv, p.cell, p.pdf), (one.uv, one.cell, 1.0), "{x:?}");
                }
            }
        }
    }

    #[test]
    fn pdf_does_not_depend_on_the_values_scale() {
        // Integrals far outside [2⁻⁶⁴, 2⁶⁴] take a scale so that the factors stay
        // in f32: the same density, to f32 rounding, and still exact for samples.
        let mut rng = SplitMix64::new(12);
        let values: Vec<f32> = (0..9 * 6)
            .map(|n| {
                if n % 7 == 3 {
                    0.0
                } else {
                    0.5 + 1.5 * rng.next_f32()
                }
            })
            .collect();
        let (u, v) = (random_nodes(&mut rng, 9), random_nodes(&mut rng, 6));
        let base = BilinearDistribution2D::new(&values, &u, &v);
        // 1e-39: subnormal values, an integral whose reciprocal is beyond f32.
        for k in [1e-39f32, 1e-20, 1e20, 1e30] {
            let scaled: Vec<f32> = values.iter().map(|v| v * k).collect();
            let d = BilinearDistribution2D::new(&scaled, &base.u.nodes, &base.v.nodes);
            assert_ne!(d.integral(), base.integral());
            for j in 0..2000 {
                let xi = xi_2d(2, j);
                let s = d.sample_continuous(xi);
                assert_eq!(d.pdf(s.uv), s.pdf);
                let t = base.pdf(s.uv);
                assert!(
                    s.pdf > 0.0 && close(s.pdf, t, 1e-5),
                    "{k} {xi:?}: {s:?} {t}"
                );
            }
        }
    }

    #[test]
    fn sample_pdf_and_invert_agree() {
        let mut rng = SplitMix64::new(4);
        for &(mu, mv) in &[(2, 2), (5, 4), (17, 9), (3, 40)] {
            let d = random_density(&mut rng, mu, mv);
            for k in 0..5000 {
                let xi = xi_2d(5, k);
                let s = d.sample_continuous(xi);
                assert_eq!(d.pdf(s.uv), s.pdf, "{mu}x{mv} {xi:?} {s:?}");
                assert_eq!(
                    [
                        patch_of(&d.u.nodes, s.uv[0] as f64),
                        patch_of(&d.v.nodes, s.uv[1] as f64)
                    ],
                    s.cell
                );
                assert!(s.pdf > 0.0, "{mu}x{mv} {xi:?} {s:?}");
                let back = d.invert(s.uv);
                // ξ moves by p_marginal·Δv: allow for the f32 rounding of uv.
                let err = (back[0] - xi[0]).abs().max((back[1] - xi[1]).abs());
                assert!(err < 1e-4, "{mu}x{mv}: {xi:?} → {s:?} → {back:?}");
            }
        }
    }

    #[test]
    fn chi_square_against_integrated_pdf() {
        // α = 1e-3, N = 400 000 per density, seed 20 + index; bins are patch quarters.
        let mut rng = SplitMix64::new(6);
        for (j, &(mu, mv)) in [(2, 2), (6, 5), (13, 7)].iter().enumerate() {
            let d = random_density(&mut rng, mu, mv);
            let p = chi_square(
                &d,
                |r| rect_probability(&d, r[0], r[1], r[2], r[3]),
                400_000,
                20 + j as u64,
            );
            assert!(p > ALPHA, "{mu}x{mv}: p = {p}");
        }
    }

    #[test]
    fn chi_square_rejects_the_piecewise_constant_approximation() {
        // Same samples, expected counts from a density constant on each patch (the
        // same patch masses): the in-patch slope must be detected (α = 1e-3,
        // N = 400 000, seed 30).
        let mut rng = SplitMix64::new(7);
        let d = random_density(&mut rng, 6, 5);
        let flat = |r: [f64; 4]| {
            let (i, k) = (
                patch_of(&d.u.nodes, 0.5 * (r[0] + r[1])),
                patch_of(&d.v.nodes, 0.5 * (r[2] + r[3])),
            );
            let patch = rect_probability(
                &d,
                d.u.nodes[i],
                d.u.nodes[i + 1],
                d.v.nodes[k],
                d.v.nodes[k + 1],
            );
            patch / 4.0
        };
        let p = chi_square(&d, flat, 400_000, 30);
        assert!(p < ALPHA, "p = {p}");
    }

    #[test]
    fn zero_regions_are_never_sampled() {
        // Only the patch [1, 1] of a 4×4-node grid is non-zero, and only at one
        // corner: every sample must land inside it with pdf > 0.
        let mut values = vec![0.0f32; 16];
        values[2 * 4 + 2] = 5.0;
        let nodes = [0.0, 0.3, 0.6, 1.0];
        let d = BilinearDistribution2D::new(&values, &nodes, &nodes);
        for k in 0..20_000 {
            let s = d.sample_continuous(xi_2d(9, k));
            assert!(s.pdf > 0.0, "{s:?}");
            // The corner (2, 2) touches patches [1..2] × [1..2].
            assert!(
                (1..=2).contains(&s.cell[0]) && (1..=2).contains(&s.cell[1]),
                "{s:?}"
            );
        }
        for &a in &[0.0, 1e-30, 0.5, ONE_MINUS_EPSILON, 1.0, -1.0, f32::NAN] {
            for &b in &[1e-30, 0.5, ONE_MINUS_EPSILON, 1.0, f32::NAN, f32::INFINITY] {
                let s = d.sample_continuous([a, b]);
                assert!(s.uv.iter().all(|x| (0.0..1.0).contains(x)), "{s:?}");
                assert!(d.invert(s.uv).iter().all(|x| (0.0..=1.0).contains(x)));
            }
        }
    }

    /// Repeated end nodes (the node-row layout) make zero-width patches: they
    /// hold no mass, no sample lands in them, and no point of `[0, 1]` is looked
    /// up in them, not even the ends, so the density there is the neighbours'.
    #[test]
    fn zero_width_patches_are_never_sampled_nor_found() {
        let (u, v) = ([0.0, 0.5, 1.0], [0.0, 0.0, 0.5, 1.0, 1.0]);
        // B = 1 + v' in the real patches (rows 1..=3 at v = 0, ½, 1: 1, 1.5, 2),
        // end rows copies; ∫B = 1.5, so p(u, v) = (1 + v) / 1.5.
        let values = [
            1.0f32, 1.0, 1.0, 1.0, 1.0, 1.0, 1.5, 1.5, 1.5, 2.0, 2.0, 2.0, 2.0, 2.0, 2.0,
        ];
        let d = BilinearDistribution2D::new(&values, &u, &v);
        assert!((d.integral() - 1.5).abs() < 1e-12);
        for (y, want) in [(0.0f32, 1.0), (0.25, 1.25), (1.0, 2.0)] {
            let pdf = d.pdf([0.3, y]);
            assert!(close(pdf, (want / 1.5) as f32, 1e-6), "v {y}: {pdf}");
        }
        assert_eq!(d.locate([0.3, 0.0]).0[1], 1);
        assert_eq!(d.locate([0.3, 1.0]).0[1], 2);
        for k in 0..20_000 {
            let s = d.sample_continuous(xi_2d(13, k));
            assert!((1..=2).contains(&s.cell[1]) && s.pdf > 0.0, "{s:?}");
            assert_eq!(d.pdf(s.uv), s.pdf);
        }
        for &b in &[0.0f32, 1e-30, ONE_MINUS_EPSILON, 1.0] {
            let s = d.sample_continuous([0.5, b]);
            assert!((1..=2).contains(&s.cell[1]) && s.pdf > 0.0, "{s:?}");
            assert!(d.invert(s.uv).iter().all(|x| (0.0..=1.0).contains(x)));
        }
    }

    #[test]
    fn all_zero_and_invalid_inputs() {
        let d = BilinearDistribution2D::new(
            &[0.0, f32::NAN, -1.0, f32::INFINITY],
            &[0.0, 1.0],
            &[0.0, 1.0],
        );
        test_support::assert_zero_function(
            d.integral(),
            |xi| d.sample_continuous(xi),
            |uv| d.pdf(uv),
            |uv| d.invert(uv),
        );
        let ok = [0.0, 1.0];
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.0], &ok).is_err());
        // Repeated nodes are a zero-width patch, allowed; decreasing ones are not.
        assert!(BilinearDistribution2D::try_new(&[1.0; 8], &[0.0, 0.5, 0.5, 1.0], &ok).is_ok());
        assert!(BilinearDistribution2D::try_new(&[1.0; 8], &[0.0, 0.7, 0.5, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.1, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.0, 0.9], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 6], &[0.0, f64::NAN, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 5], &ok, &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &ok, &ok).is_ok());
        // Huge values neither overflow nor lose the density.
        let d = BilinearDistribution2D::new(&[f32::MAX; 4], &ok, &ok);
        let s = d.sample_continuous([0.4, 0.6]);
        assert!(close(s.pdf, 1.0, 1e-6), "{s:?}");
    }

    #[test]
    #[should_panic(expected = "decreasing")]
    fn new_panics_on_bad_nodes() {
        BilinearDistribution2D::new(&[1.0; 8], &[0.0, 0.7, 0.5, 1.0], &[0.0, 1.0]);
    }

    /// Node values at texel centres plus the square's edges (seam averages in u,
    /// clamped rows in v): the layout that makes `p` proportional to a bilinear
    /// lookup of the image.
    fn texel_centre_layout(image: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let mut u = vec![0.0];
        u.extend((0..w).map(|i| (i as f64 + 0.5) / w as f64));
        u.push(1.0);
        let mut v = vec![0.0];
        v.extend((0..h).map(|j| (j as f64 + 0.5) / h as f64));
        v.push(1.0);
        let mut values = Vec::with_capacity((w + 2) * (h + 2));
        for k in 0..h + 2 {
            let j = k.saturating_sub(1).min(h - 1);
            let row = &image[j * w..(j + 1) * w];
            let seam = 0.5 * (row[0] + row[w - 1]);
            values.push(seam);
            values.extend_from_slice(row);
            values.push(seam);
        }
        (values, u, v)
    }

    #[test]
    fn proportional_to_a_bilinear_image_lookup() {
        let (w, h) = (7, 5);
        let mut rng = SplitMix64::new(12);
        let texels: Vec<f32> = (0..w * h).map(|_| rng.next_f32() * 4.0).collect();
        let image = EnvImage::from_fn(w, h, |x, y| [texels[y * w + x]; 3]).unwrap();
        let (values, u, v) = texel_centre_layout(&texels, w, h);
        let d = BilinearDistribution2D::new(&values, &u, &v);
        for k in 0..2000 {
            let [a, b] = xi_2d(13, k);
            let want = image.lookup_bilinear(a, b)[0] as f64 / d.integral();
            let got = d.pdf([a, b]) as f64;
            assert!(
                (got - want).abs() < 1e-5 * want.max(1.0),
                "({a}, {b}): {got} vs {want}"
            );
        }
    }

    /// The light's layout for a lat-long map ([`texel_centre_layout`] with every
    /// node row weighted by `sin(π V_k)`, so the edge rows at `v = 0, 1` are 0).
    fn latlong_layout(image: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let (mut values, u, v) = texel_centre_layout(image, w, h);
        for (row, &vk) in values.chunks_mut(w + 2).zip(&v) {
            let factor = if vk == 0.0 || vk == 1.0 {
                0.0
            } else {
                (std::f64::consts::PI * vk).sin() as f32
            };
            for x in row {
                *x *= factor;
            }
        }
        (values, u, v)
    }

    #[test]
    fn chi_square_fits_a_sun_next_to_a_dim_sky() {
        // The built-in sky in miniature: a 16×8 lat-long map of values 0.5 to 1.5
        // with one texel at 5e4 (the sun, ~99.8% of the mass), bilinear nodes at
        // texel centres, zero edge rows. α = 1e-3, N = 1 000 000, seed 41.
        let (w, h) = (16, 8);
        let mut texels: Vec<f32> = (0..w * h)
            .map(|k| 1.0 + 0.5 * ((k * 7 % 11) as f32 / 5.0 - 1.0))
            .collect();
        texels[2 * w + 5] = 5e4;
        let (values, u, v) = latlong_layout(&texels, w, h);
        let d = BilinearDistribution2D::new(&values, &u, &v);
        let n = 1_000_000u64;
        let samples: Vec<[f32; 2]> = (0..n)
            .map(|k| d.sample_continuous(xi_2d(41, k)).uv)
            .collect();

        // 1. Bins 4×4 per patch (each inside one patch, where the bilinear density
        //    is a polynomial and `rect_probability` is exact): the fit holds, in
        //    the sun's patches too.
        let s = 4;
        let cuts = |nodes: &[f64]| -> Vec<f64> {
            let mut out = vec![0.0];
            for pair in nodes.windows(2) {
                out.extend((1..=s).map(|j| pair[0] + (pair[1] - pair[0]) * j as f64 / s as f64));
            }
            *out.last_mut().unwrap() = 1.0;
            out
        };
        let (bu, bv) = (cuts(&d.u.nodes), cuts(&d.v.nodes));
        let mut counts = vec![0u64; (bu.len() - 1) * (bv.len() - 1)];
        for uv in &samples {
            let (i, k) = (patch_of(&bu, uv[0] as f64), patch_of(&bv, uv[1] as f64));
            counts[k * (bu.len() - 1) + i] += 1;
        }
        let mut expected = vec![];
        for vw in bv.windows(2) {
            for uw in bu.windows(2) {
                expected.push(rect_probability(&d, uw[0], uw[1], vw[0], vw[1]) * n as f64);
            }
        }
        let (stat, dof, p) = test_support::chi_square(&counts, &expected);
        assert!(p > ALPHA, "patch bins: χ² = {stat} (dof {dof}), p = {p}");

        // 2. Bins = texel cells, which straddle the density's kinks at the texel
        //    centres. Integrated exactly (as four quarter-cells) the fit holds.
        //    Integrated by a 2×2 Gauss-Legendre rule over the whole cell (what the
        //    invariant harness does when its bin budget forbids splitting cells),
        //    the sun's cell gets (1 - 1/(2√3))² / (3/4)² = 0.8995 of its mass, the
        //    rest going to its neighbours while ∫p stays ≈ 1, and the fit is
        //    rejected: bins that straddle node kinks must be integrated piecewise.
        let mut texel_counts = vec![0u64; w * h];
        for uv in &samples {
            let i = ((uv[0] as f64 * w as f64) as usize).min(w - 1);
            let j = ((uv[1] as f64 * h as f64) as usize).min(h - 1);
            texel_counts[j * w + i] += 1;
        }
        let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
        let (mut exact, mut gauss) = (vec![], vec![]);
        for j in 0..h {
            for i in 0..w {
                let (u0, v0, du, dv) = (
                    i as f64 / w as f64,
                    j as f64 / h as f64,
                    1.0 / w as f64,
                    1.0 / h as f64,
                );
                let (um, vm) = (u0 + 0.5 * du, v0 + 0.5 * dv);
                let quarters = rect_probability(&d, u0, um, v0, vm)
                    + rect_probability(&d, um, u0 + du, v0, vm)
                    + rect_probability(&d, u0, um, vm, v0 + dv)
                    + rect_probability(&d, um, u0 + du, vm, v0 + dv);
                exact.push(quarters * n as f64);
                let mut q = 0.0;
                for a in g {
                    for b in g {
                        let uv = [(u0 + a * du) as f32, (v0 + b * dv) as f32];
                        q += d.pdf(uv) as f64 * du * dv / 4.0;
                    }
                }
                gauss.push(q * n as f64);
            }
        }
        let total = |e: &[f64]| e.iter().sum::<f64>() / n as f64;
        assert!((total(&exact) - 1.0).abs() < 1e-9, "{}", total(&exact));
        assert!((total(&gauss) - 1.0).abs() < 1e-4, "{}", total(&gauss));
        let (stat, dof, p) = test_support::chi_square(&texel_counts, &exact);
        assert!(
            p > ALPHA,
            "texel bins, exact: χ² = {stat} (dof {dof}), p = {p}"
        );
        let (stat, dof, p) = test_support::chi_square(&texel_counts, &gauss);
        assert!(
            p < ALPHA,
            "texel bins, GL2: χ² = {stat} (dof {dof}), p = {p}"
        );
        let sun = 2 * w + 5;
        let ratio = gauss[sun] / exact[sun];
        assert!(
            (ratio - 0.8995).abs() < 1e-3,
            "sun cell GL2 / exact = {ratio}"
        );
    }

    /// Per-sample cost against the piecewise-constant inversion sampler, with nodes
    /// at the texel centres of a 4096×2048 random image (4098×2050 nodes) and of a
    /// 64×32 one. Run: `cargo test --release -p envlight --lib
    /// bilinear::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_against_inversion() {
        for (w, h) in [(4096, 2048), (64, 32)] {
            let mut rng = SplitMix64::new(1);
            let texels: Vec<f32> = (0..w * h)
                .map(|_| 10f32.powf(4.0 * rng.next_f32() - 2.0))
                .collect();
            let (values, u, v) = texel_centre_layout(&texels, w, h);
            let start = std::time::Instant::now();
            let d = BilinearDistribution2D::new(&values, &u, &v);
            let build = start.elapsed();
            let inversion = crate::distribution::Distribution2D::new(&texels, w);
            let time = test_support::timer_against_inversion(format!("{w}x{h}"), &inversion);
            time("bilinear sample", &|x| d.sample_continuous(x).uv[0]);
            time("bilinear pdf", &|x| d.pdf(x));
            time("bilinear invert", &|x| d.invert(x)[0]);
            println!(
                "{w}x{h} build {build:?}; bytes/texel: bilinear {:.2}, inversion {:.2}",
                d.memory_bytes() as f64 / (w * h) as f64,
                inversion.memory_bytes() as f64 / (w * h) as f64
            );
        }
    }
}
