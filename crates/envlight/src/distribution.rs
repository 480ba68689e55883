//! Piecewise-constant probability distributions on `[0, 1]` and `[0, 1]²`, sampled
//! by inverting their cumulative distribution functions.
//!
//! A 1D distribution is built from `n` non-negative values `f[0..n)`, each constant
//! over a cell of width `1/n`:
//!
//! ```text
//! cdf[0] = 0,   cdf[i] = cdf[i-1] + f[i-1]/n,   integral = cdf[n],   cdf /= integral
//! pdf(x) = f[⌊x n⌋] / integral
//! ```
//!
//! Prefix sums are accumulated in `f64` and the normalised CDF is stored in `f32`
//! with `cdf[n] == 1` exactly, so a row of 16 384 texels with a dynamic range of
//! 10¹⁰ keeps every non-zero cell reachable. A function that is zero everywhere (or
//! has no finite positive mass) gives a uniform CDF and a pdf of 0 everywhere; callers
//! must read "pdf 0" as "no sample".
//!
//! The 2D distribution stores one conditional CDF per row in a single flat array (no
//! per-row allocation) plus a marginal distribution over the rows' integrals.
//! Memory: 1D, 8 bytes per cell; 2D, 8 bytes per cell plus 8 per row.

/// The search that finds the CDF segment holding `xi`: the last index `o` with
/// `cdf[o] <= xi`, clamped to `[0, n-1]` where `n = cdf.len() - 1`.
///
/// Zero-width segments (cells with `f = 0`) are skipped because a later entry with
/// the same CDF value is preferred, so such cells are never returned for `xi < 1`.
///
/// A branchy bisection on purpose: light samples concentrate on a few bright rows
/// and cells, where its branches predict well and the CPU runs ahead of the loads;
/// the branchless `partition_point` waits for every load and measured 1.6× slower
/// per sample on a 4k sky.
#[inline]
fn find_segment(cdf: &[f32], xi: f32) -> usize {
    let n = cdf.len() - 1;
    // Invariant: cdf[lo] <= xi (or lo = 0), and the answer is below hi.
    let (mut lo, mut hi) = (0usize, n);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if cdf[mid] <= xi {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Continuous sample of one CDF: returns `(segment, offset in segment)`.
#[inline]
fn sample_segment(cdf: &[f32], xi: f32) -> (usize, f32) {
    let o = find_segment(cdf, xi);
    let (lo, hi) = (cdf[o], cdf[o + 1]);
    let width = hi - lo;
    let du = if width > 0.0 {
        ((xi - lo) / width).clamp(0.0, ONE_MINUS_EPSILON)
    } else {
        0.0
    };
    (o, du)
}

/// Inverse of [`sample_segment`] for a point `x ∈ [0, 1]` on a CDF with `n` cells.
#[inline]
fn invert_segment(cdf: &[f32], x: f32) -> f32 {
    let n = cdf.len() - 1;
    let o = cell_index(x, n);
    let frac = (x * n as f32 - o as f32).clamp(0.0, 1.0);
    (cdf[o] + frac * (cdf[o + 1] - cdf[o])).clamp(0.0, 1.0)
}

/// The cell of `x ∈ [0, 1]` on a grid of `n` cells, `⌊x n⌋` clamped to `[0, n-1]`.
/// Every lookup (pdf, invert) and every sample placement goes through this one
/// function, so they agree about which cell a point is in.
#[inline]
pub(crate) fn cell_index(x: f32, n: usize) -> usize {
    ((x * n as f32).max(0.0) as usize).min(n - 1)
}

/// The point `(cell + frac) / n`, nudged by an ulp or two where f32 rounding would
/// put it on a neighbouring cell (e.g. `frac` just below 1 rounds `cell + frac` up
/// to `cell + 1`). Without this, `pdf(sample.x)` could report the neighbour's
/// density, which can differ from the sampled cell's by any factor.
#[inline]
pub(crate) fn place_in_cell(cell: usize, frac: f32, n: usize) -> f32 {
    let x = ((cell as f32 + frac) / n as f32).min(ONE_MINUS_EPSILON);
    nudge_into_cell(x, cell, n, 8)
}

/// [`place_in_cell`] with the offset in `f64`: `(cell + frac) / n` is computed in
/// `f64` and rounded to `f32` once, then nudged the same way (up to 4 ulps). Used
/// by the samplers whose in-cell offsets carry more than 24 bits.
#[inline]
pub(crate) fn place_in_cell_f64(cell: usize, frac: f64, n: usize) -> f32 {
    let x = (((cell as f64) + frac) / n as f64) as f32;
    nudge_into_cell(x.min(ONE_MINUS_EPSILON), cell, n, 4)
}

/// Steps `x` by single ulps, at most `tries` times, until [`cell_index`] puts it
/// in `cell`.
#[inline]
fn nudge_into_cell(mut x: f32, cell: usize, n: usize, tries: usize) -> f32 {
    for _ in 0..tries {
        match cell_index(x, n).cmp(&cell) {
            std::cmp::Ordering::Greater => x = x.next_down(),
            std::cmp::Ordering::Less => x = x.next_up(),
            std::cmp::Ordering::Equal => break,
        }
    }
    x
}

/// The largest `f32` below 1: continuous samples stay in `[0, 1)`.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// Fills `cdf` (length `f.len() + 1`) with the normalised CDF of `f`, whose values
/// must already be sanitised, and returns the integral `Σ f / n` (0 when there is no
/// positive mass: then `cdf` is uniform).
///
/// Two passes over `f` (total, then running sums), both in f64, so no scratch
/// buffer is needed; the row is small enough to stay in cache between them.
fn build_cdf(f: &[f32], cdf: &mut [f32]) -> f64 {
    let n = f.len();
    debug_assert_eq!(cdf.len(), n + 1);
    let total: f64 = f.iter().map(|&v| v as f64).sum();
    if total > 0.0 && total.is_finite() {
        let inv = 1.0 / total;
        let mut running = 0.0f64;
        cdf[0] = 0.0;
        for (c, &v) in cdf[1..].iter_mut().zip(f) {
            running += v as f64;
            *c = (running * inv) as f32;
        }
    } else {
        for (i, c) in cdf.iter_mut().enumerate() {
            *c = (i as f64 / n as f64) as f32;
        }
    }
    cdf[n] = 1.0;
    total / n as f64
}

/// `1 / x` for a positive integral, 0 otherwise (a zero function has pdf 0).
pub(crate) fn inverse_or_zero(x: f64) -> f64 {
    if x > 0.0 && x.is_finite() {
        1.0 / x
    } else {
        0.0
    }
}

/// A value usable as a density: finite and positive, otherwise 0.
#[inline]
pub(crate) fn sanitize(value: f32) -> f32 {
    if value > 0.0 && value.is_finite() {
        value
    } else {
        0.0
    }
}

/// A piecewise-constant distribution on `[0, 1]` with `n` equal cells.
///
/// Guarantees: a cell with `f = 0` is never sampled; `pdf(sample_continuous(ξ).x)`
/// equals the returned pdf; `invert(sample_continuous(ξ).x) ≈ ξ`. Sampling costs one
/// binary search, `O(log n)`; memory is 8 bytes per cell.
///
/// ```
/// use envlight::distribution::Distribution1D;
/// let d = Distribution1D::new(&[1.0, 1.0, 2.0, 4.0, 8.0]);
/// let s = d.sample_continuous(0.75);
/// assert!((s.x - 0.9).abs() < 1e-6 && (s.pdf - 2.5).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    integral: f64,
    /// `1 / integral`, or 0 for a zero function.
    inv_integral: f64,
}

/// A continuous sample of a 1D distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample1D {
    /// The point in `[0, 1)`.
    pub x: f32,
    /// Its density `f[cell] / integral` (0 when the function is zero).
    pub pdf: f32,
    /// The cell that holds `x`.
    pub cell: usize,
}

/// A discrete sample of a 1D distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteSample {
    /// The chosen cell.
    pub index: usize,
    /// Its probability `f[index] / Σ f` (0 when the function is zero).
    pub probability: f32,
    /// `ξ` rescaled to `[0, 1)` within the chosen cell, free for reuse.
    pub remapped: f32,
}

impl Distribution1D {
    /// Builds the distribution of `f`. Negative, NaN and infinite values count as 0.
    ///
    /// # Panics
    /// When `f` is empty.
    pub fn new(f: &[f32]) -> Self {
        assert!(!f.is_empty(), "a distribution needs at least one cell");
        let func: Vec<f32> = f.iter().map(|&v| sanitize(v)).collect();
        let mut cdf = vec![0.0; f.len() + 1];
        let integral = build_cdf(&func, &mut cdf);
        Self {
            func,
            cdf,
            integral,
            inv_integral: inverse_or_zero(integral),
        }
    }

    /// Number of cells.
    #[inline]
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// Always false: a distribution has at least one cell.
    #[inline]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// `∫₀¹ f(x) dx = Σ f / n`.
    #[inline]
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// The (sanitised) function values.
    #[inline]
    pub fn func(&self) -> &[f32] {
        &self.func
    }

    /// The normalised CDF, `n + 1` entries from 0 to 1.
    #[inline]
    pub fn cdf(&self) -> &[f32] {
        &self.cdf
    }

    /// Density at `x ∈ [0, 1]`: `f[⌊x n⌋] / integral`, or 0 for a zero function.
    #[inline]
    pub fn pdf(&self, x: f32) -> f32 {
        self.cell_pdf(cell_index(x, self.func.len()))
    }

    #[inline]
    fn cell_pdf(&self, cell: usize) -> f32 {
        (self.func[cell] as f64 * self.inv_integral) as f32
    }

    /// Maps `ξ ∈ [0, 1)` to `x` distributed with density `pdf`: finds the CDF segment
    /// `o` holding `ξ`, then places `x` linearly inside it,
    /// `x = (o + (ξ - cdf[o]) / (cdf[o+1] - cdf[o])) / n`.
    #[inline]
    pub fn sample_continuous(&self, xi: f32) -> Sample1D {
        let (cell, du) = sample_segment(&self.cdf, xi);
        Sample1D {
            x: place_in_cell(cell, du, self.func.len()),
            pdf: self.cell_pdf(cell),
            cell,
        }
    }

    /// Picks cell `i` with probability `f[i] / Σ f`.
    #[inline]
    pub fn sample_discrete(&self, xi: f32) -> DiscreteSample {
        let (index, remapped) = sample_segment(&self.cdf, xi);
        let n = self.func.len() as f64;
        let probability = (self.func[index] as f64 * self.inv_integral / n) as f32;
        DiscreteSample {
            index,
            probability,
            remapped,
        }
    }

    /// Probability of picking cell `index` in [`Self::sample_discrete`].
    #[inline]
    pub fn discrete_probability(&self, index: usize) -> f32 {
        self.cell_pdf(index) / self.func.len() as f32
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `x`:
    /// `ξ = cdf[o] + (x n - o)(cdf[o+1] - cdf[o])` with `o = ⌊x n⌋`.
    #[inline]
    pub fn invert(&self, x: f32) -> f32 {
        invert_segment(&self.cdf, x)
    }
}

/// A piecewise-constant distribution on `[0, 1]²` over an `nu × nv` grid, sampled
/// as a marginal over rows (v) and a conditional within the chosen row (u):
/// `p(u, v) = p(v) p(u | v) = f[v][u] / I`, `I = Σ f / (nu nv)`.
///
/// Memory: 8 bytes per cell (the function and one CDF entry) plus 8 per row.
/// Sampling: two binary searches, `O(log nu + log nv)`.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution2D {
    nu: usize,
    nv: usize,
    /// `f[v * nu + u]`, sanitised.
    func: Vec<f32>,
    /// Row `v`'s normalised conditional CDF at `[v * (nu + 1) .. (v + 1) * (nu + 1)]`.
    conditional_cdf: Vec<f32>,
    /// Each row's integral `Σ_u f[v][u] / nu`.
    row_integral: Vec<f64>,
    marginal: Distribution1D,
    /// `1 / I`, or 0 for a zero function (so pdfs come out 0, never NaN).
    inv_integral: f64,
}

/// A continuous sample of a 2D distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample2D {
    /// The point `[u, v]` in `[0, 1)²`.
    pub uv: [f32; 2],
    /// Its density with respect to area in `[0, 1]²` (0 for a zero function).
    pub pdf: f32,
    /// The cell `[iu, iv]` holding the point.
    pub cell: [usize; 2],
}

impl Distribution2D {
    /// Builds the distribution of `f`, given row-major with `nu` values per row.
    /// Rows are built in parallel. Negative, NaN and infinite values count as 0.
    ///
    /// # Panics
    /// When `nu == 0`, `f` is empty, or `f.len()` is not a multiple of `nu`.
    pub fn new(f: &[f32], nu: usize) -> Self {
        assert!(
            nu > 0 && !f.is_empty() && f.len() % nu == 0,
            "bad 2D grid shape"
        );
        Self::from_rows(nu, f.len() / nu, |v, row| {
            for (dst, &src) in row.iter_mut().zip(&f[v * nu..(v + 1) * nu]) {
                *dst = sanitize(src);
            }
        })
    }

    /// Builds the distribution from a function that fills row `v` (`nu` values) in
    /// place; rows are filled and summed in parallel, in one pass over memory.
    /// Values that are not finite and positive are stored as 0.
    ///
    /// # Panics
    /// When `nu == 0` or `nv == 0`.
    pub fn from_rows(nu: usize, nv: usize, fill_row: impl Fn(usize, &mut [f32]) + Sync) -> Self {
        Self::from_rows_with(nu, nv, || (), |_, v, row| fill_row(v, row)).0
    }

    /// [`Self::from_rows`] with per-task state and a per-row result. Rows are handed
    /// out in contiguous blocks, in increasing order within a block, each block with
    /// its own state from `init` (so a fill can cache work shared by neighbouring
    /// rows). `fill_row` must give each row the same values whatever the blocks are;
    /// then the distribution, and the results (returned in row order), do not depend
    /// on the number of threads.
    ///
    /// # Panics
    /// When `nu == 0` or `nv == 0`.
    pub fn from_rows_with<S, T: Send + Default + Clone>(
        nu: usize,
        nv: usize,
        init: impl Fn() -> S + Sync,
        fill_row: impl Fn(&mut S, usize, &mut [f32]) -> T + Sync,
    ) -> (Self, Vec<T>) {
        use rayon::prelude::*;
        assert!(nu > 0 && nv > 0, "bad 2D grid shape");
        let mut func = vec![0.0f32; nu * nv];
        let mut conditional_cdf = vec![0.0f32; (nu + 1) * nv];
        let mut row_integral = vec![0.0f64; nv];
        let mut results = vec![T::default(); nv];
        // Enough blocks to balance the load, each big enough that per-block work
        // (state set-up, scheduling) costs little next to its rows.
        let blocks = (rayon::current_num_threads() * 8).max(1);
        let rows_per_task = nv.div_ceil(blocks).max((4096 / nu).max(1));
        func.par_chunks_mut(nu * rows_per_task)
            .zip(conditional_cdf.par_chunks_mut((nu + 1) * rows_per_task))
            .zip(row_integral.par_chunks_mut(rows_per_task))
            .zip(results.par_chunks_mut(rows_per_task))
            .enumerate()
            .for_each(|(task, (((funcs, cdfs), integrals), outs))| {
                let mut state = init();
                for (k, (((row, cdf), integral), out)) in funcs
                    .chunks_mut(nu)
                    .zip(cdfs.chunks_mut(nu + 1))
                    .zip(integrals.iter_mut())
                    .zip(outs.iter_mut())
                    .enumerate()
                {
                    *out = fill_row(&mut state, task * rows_per_task + k, row);
                    for value in row.iter_mut() {
                        *value = sanitize(*value);
                    }
                    *integral = build_cdf(row, cdf);
                }
            });
        let marginal_func: Vec<f32> = row_integral.iter().map(|&i| i as f32).collect();
        let mut marginal = Distribution1D::new(&marginal_func);
        // The marginal's integral is the 2D integral; keep it in full precision
        // (the f32 row integrals only shape the marginal CDF).
        marginal.integral = row_integral.iter().sum::<f64>() / nv as f64;
        marginal.inv_integral = inverse_or_zero(marginal.integral);
        (
            Self {
                nu,
                nv,
                func,
                conditional_cdf,
                row_integral,
                inv_integral: marginal.inv_integral,
                marginal,
            },
            results,
        )
    }

    /// Grid width (cells along u).
    #[inline]
    pub fn nu(&self) -> usize {
        self.nu
    }

    /// Grid height (cells along v).
    #[inline]
    pub fn nv(&self) -> usize {
        self.nv
    }

    /// `I = ∫∫ f du dv = Σ f / (nu nv)`.
    #[inline]
    pub fn integral(&self) -> f64 {
        self.marginal.integral
    }

    /// The (sanitised) function, row-major.
    #[inline]
    pub fn func(&self) -> &[f32] {
        &self.func
    }

    /// The marginal distribution over rows.
    #[inline]
    pub fn marginal(&self) -> &Distribution1D {
        &self.marginal
    }

    /// Integral of row `v`, `Σ_u f[v][u] / nu`.
    #[inline]
    pub fn row_integral(&self, v: usize) -> f64 {
        self.row_integral[v]
    }

    /// Bytes of sampling data held (function, CDFs and row integrals).
    pub fn memory_bytes(&self) -> usize {
        4 * (self.func.len() + self.conditional_cdf.len() + self.marginal.func.len())
            + 4 * self.marginal.cdf.len()
            + 8 * self.row_integral.len()
    }

    #[inline]
    fn row_cdf(&self, v: usize) -> &[f32] {
        &self.conditional_cdf[v * (self.nu + 1)..(v + 1) * (self.nu + 1)]
    }

    /// Density of cell `[iu, iv]`: `f[iv][iu] / I`, 0 for a zero function.
    #[inline]
    pub fn cell_pdf(&self, iu: usize, iv: usize) -> f32 {
        (self.func[iv * self.nu + iu] as f64 * self.inv_integral) as f32
    }

    /// Density at `(u, v) ∈ [0, 1]²` (points outside are clamped onto the square).
    #[inline]
    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        self.cell_pdf(cell_index(uv[0], self.nu), cell_index(uv[1], self.nv))
    }

    /// Maps `ξ = [ξ0, ξ1] ∈ [0, 1)²` to a point with density [`Self::pdf`]: `ξ1`
    /// picks the row from the marginal, `ξ0` the position within that row.
    #[inline]
    pub fn sample_continuous(&self, xi: [f32; 2]) -> Sample2D {
        let (iv, dv) = sample_segment(&self.marginal.cdf, xi[1]);
        let (iu, du) = sample_segment(self.row_cdf(iv), xi[0]);
        Sample2D {
            uv: [
                place_in_cell(iu, du, self.nu),
                place_in_cell(iv, dv, self.nv),
            ],
            pdf: self.cell_pdf(iu, iv),
            cell: [iu, iv],
        }
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `uv`.
    #[inline]
    pub fn invert(&self, uv: [f32; 2]) -> [f32; 2] {
        let xi1 = invert_segment(&self.marginal.cdf, uv[1]);
        let xi0 = invert_segment(self.row_cdf(cell_index(uv[1], self.nv)), uv[0]);
        [xi0, xi1]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: f32, b: f32) -> bool {
        (a - b).abs() <= 1e-6 * (1.0 + b.abs())
    }

    #[test]
    fn continuous_sampling_matches_hand_computed_cdf() {
        // f = {1,1,2,4,8}: integral 16/5, cdf = {0, 1/16, 2/16, 4/16, 8/16, 1}.
        let d = Distribution1D::new(&[1.0, 1.0, 2.0, 4.0, 8.0]);
        assert!((d.integral() - 3.2).abs() < 1e-12);
        let s = d.sample_continuous(0.0);
        assert!(close(s.x, 0.0) && close(s.pdf, 5.0 / 16.0), "{s:?}");
        let s = d.sample_continuous(0.5);
        assert!(close(s.x, 0.8) && close(s.pdf, 2.5), "{s:?}");
        let s = d.sample_continuous(0.75);
        assert!(close(s.x, 0.9) && close(s.pdf, 2.5), "{s:?}");
        let s = d.sample_continuous(ONE_MINUS_EPSILON);
        assert!(close(s.x, 1.0) && s.x < 1.0, "{s:?}");
        // ξ = 1 is outside the contract but must still land in range.
        assert!(d.sample_continuous(1.0).x < 1.0);
    }

    #[test]
    fn invert_matches_hand_computed_cdf() {
        // f = {0, .25, .5, .25}: cdf = {0, 0, .25, .75, 1}.
        let d = Distribution1D::new(&[0.0, 0.25, 0.5, 0.25]);
        assert!(close(d.invert(0.5), 0.25));
        assert!(close(d.invert(0.625), 0.5));
        assert!(close(d.invert(0.75), 0.75));
        assert_eq!(d.invert(0.0), 0.0);
        assert_eq!(d.invert(1.0), 1.0);
    }

    #[test]
    fn zero_cells_are_never_sampled() {
        let d = Distribution1D::new(&[0.0, 0.0, 3.0, 0.0, 1.0, 0.0]);
        for k in 0..=1000 {
            let xi = (k as f32 / 1000.0).min(ONE_MINUS_EPSILON);
            let s = d.sample_continuous(xi);
            assert!(s.cell == 2 || s.cell == 4, "ξ={xi} gave {s:?}");
            assert!(s.pdf > 0.0);
            assert_eq!(d.sample_discrete(xi).index, s.cell);
        }
    }

    #[test]
    fn zero_function_is_uniform_with_zero_pdf() {
        let d = Distribution1D::new(&[0.0, f32::NAN, -1.0, 0.0]);
        assert_eq!(d.integral(), 0.0);
        assert_eq!(d.cdf(), &[0.0, 0.25, 0.5, 0.75, 1.0]);
        let s = d.sample_continuous(0.6);
        assert_eq!((s.pdf, s.cell), (0.0, 2));
        assert!(close(s.x, 0.6));
        assert_eq!(d.sample_discrete(0.6).probability, 0.0);
        assert_eq!(d.pdf(0.3), 0.0);
    }

    #[test]
    fn discrete_sampling_reports_probability_and_remaps() {
        let d = Distribution1D::new(&[1.0, 3.0]);
        let s = d.sample_discrete(0.5);
        assert_eq!(s.index, 1);
        assert!(close(s.probability, 0.75));
        assert!(close(s.remapped, 1.0 / 3.0));
        assert!(close(d.discrete_probability(0), 0.25));
    }

    #[test]
    fn f64_accumulation_keeps_the_last_cell_of_a_long_row() {
        // 2^24 + 1 cells of 1: summed in f32, the running total stops at 2^24 and
        // the last cell would get zero width.
        let n = (1 << 24) + 1;
        let d = Distribution1D::new(&vec![1.0; n]);
        let cdf = d.cdf();
        assert!(cdf[n - 1] < 1.0 && cdf[n] == 1.0);
        assert!(close(d.integral() as f32, 1.0));
    }

    #[test]
    fn two_dimensional_sampling_and_pdf_agree() {
        // 3×2 grid: rows {1,0,1} and {0,4,0}; I = 6/6 = 1.
        let d = Distribution2D::new(&[1.0, 0.0, 1.0, 0.0, 4.0, 0.0], 3);
        assert!((d.integral() - 1.0).abs() < 1e-12);
        // Row 1 carries 4/6 of the mass: ξ1 ≥ 1/3 picks it.
        let s = d.sample_continuous([0.5, 0.5]);
        assert_eq!(s.cell, [1, 1]);
        assert!(close(s.pdf, 4.0) && close(d.pdf(s.uv), 4.0));
        // Row 1 spans ξ1 ∈ [1/3, 1): ξ1 = .5 is a quarter of the way down it.
        assert!(close(s.uv[0], 0.5) && close(s.uv[1], 0.625), "{s:?}");
        let s = d.sample_continuous([0.75, 0.1]);
        assert_eq!(s.cell, [2, 0]);
        let back = d.invert(s.uv);
        assert!(close(back[0], 0.75) && close(back[1], 0.1), "{back:?}");
        assert_eq!(d.pdf([0.5, 0.25]), 0.0);
    }

    #[test]
    fn samples_stay_in_their_cell_despite_rounding() {
        // A cell next to one a hundred orders of magnitude dimmer: ξ at the very top
        // of the bright cell's CDF segment gives du just below 1, and (cell + du) / n
        // rounds onto the boundary with the dim cell (found by the fuzzer).
        let n = 7;
        let f = [1e-20, 1e-20, 1e-20, 5.0, 1e-30, 1e-20, 1e-20];
        let d = Distribution1D::new(&f);
        for k in 0..=4096 {
            let lo = d.cdf()[3];
            let hi = d.cdf()[4];
            let xi = (lo + (hi - lo) * k as f32 / 4096.0).min(hi.next_down());
            let s = d.sample_continuous(xi);
            assert_eq!(d.pdf(s.x), s.pdf, "ξ={xi} x={} cell {}", s.x, s.cell);
        }
        for cell in 0..n {
            for frac in [0.0, 1e-9, 0.5, ONE_MINUS_EPSILON, 1.0] {
                let x = place_in_cell(cell, frac, n);
                assert_eq!(cell_index(x, n), cell, "cell {cell} frac {frac}");
            }
        }
        let d2 = Distribution2D::new(&[1e-23, 2.35, 2.35, 1e-23, 1e-23, 2.35], 3);
        for k in 0..=1000u64 {
            let xi = envlight_xi(k);
            let s = d2.sample_continuous(xi);
            assert_eq!(d2.pdf(s.uv), s.pdf, "{s:?}");
        }
    }

    fn envlight_xi(k: u64) -> [f32; 2] {
        let near_one = ONE_MINUS_EPSILON - (k % 7) as f32 * f32::EPSILON;
        let a = crate::rng::xi_2d(3, k);
        [if k % 2 == 0 { near_one } else { a[0] }, a[1]]
    }

    #[test]
    fn two_dimensional_zero_function_has_zero_pdf() {
        let d = Distribution2D::new(&[0.0; 8], 4);
        let s = d.sample_continuous([0.3, 0.7]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.uv[0].is_finite() && s.uv[1].is_finite());
    }
}
