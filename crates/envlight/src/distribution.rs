//! Piecewise-constant probability distributions on `[0, 1]` and `[0, 1]²`, sampled
//! by inverting their cumulative distribution functions.
//!
//! A 1D distribution is built from `n` non-negative values `f[0..n)`, each constant
//! over a cell of width `1/n`. Its CDF is stored in fixed point, as integers on
//! `0..=CDF_ONE`:
//!
//! ```text
//! c[0] = 0,   c[i] = round(CDF_ONE · Σ_{k<i} f[k] / Σ f),   c[n] = CDF_ONE
//! w[i] = c[i+1] - c[i]                      (the cell's width, in CDF units)
//! sample: x = (o + (ξ·CDF_ONE - c[o]) / w[o]) / n   for the o with c[o] <= ξ·CDF_ONE < c[o+1]
//! pdf(x) = n · w[⌊x n⌋] / CDF_ONE
//! ```
//!
//! The pdf is read from the stored CDF, not from `f`: it is the exact density of the
//! sampling procedure, so `pdf(sample(ξ).x) == sample(ξ).pdf` to the bit and the
//! pdf integrates to 1 exactly (the widths telescope). Prefix sums are accumulated
//! in `f64`; the rounding to 2⁻³² differs from `f / Σ f` by at most 2⁻³² per cell,
//! so the pdf of a cell holding a fraction `m` of its row's mass is within
//! `2⁻³² / m` of `f / ∫f` (10⁻⁶ relative for a uniform row of 4096 cells; an f32
//! CDF would be 256 times coarser near its end). A cell with `f > 0` always gets a
//! width of at least 1, so the support is exactly the cells with `f > 0`, however
//! wide the dynamic range: a 10⁻³⁰ texel next to a 10³⁰ sun is still sampled, with
//! a pdf that says how rarely.
//!
//! Each CDF carries a guide table (the cutpoint method of Chen and Asau, 1974): for
//! `K` equal slices of `[0, CDF_ONE)`, the first cell that a `ξ` in the slice can
//! land in. Sampling reads one guide entry and then steps forward over at most a few
//! cells, `n / K < 4` on average, in place of a binary search whose ~log₂ n
//! branches each mispredict half the time on random `ξ`.
//!
//! A function that is zero everywhere (or has no finite positive mass) gets a
//! uniform CDF and a pdf of 0 everywhere; callers read "pdf 0" as "no sample".
//!
//! The 2D distribution stores one conditional CDF and guide table per row in two
//! flat arrays (no per-row allocation), plus a marginal distribution over the rows'
//! integrals. Memory per cell: 4 bytes of CDF plus 1 to 2 bytes of guide table.

use crate::math::{
    advise_huge_pages, floor_index, floor_index_i32, len_f32, len_f64, prefetch_ptr, prefetch_read,
};

/// Lanes of the vector sampler ([`Distribution2D::staged_lanes`]): enough for
/// the widest vectors (16 f32 with AVX-512); a divisor of [`STAGED_BLOCK`].
pub(crate) const SAMPLE_LANES: usize = 16;

/// The most samples [`Distribution2D::sample_block`] takes at once.
pub const STAGED_BLOCK: usize = 32;

/// The fixed-point value of a CDF at 1: CDFs run over the integers `0..=CDF_ONE`.
pub const CDF_ONE: u32 = u32::MAX;

/// The largest `f32` below 1: continuous samples stay in `[0, 1)`.
pub const ONE_MINUS_EPSILON: f32 = 1.0 - f32::EPSILON / 2.0;

/// `ξ ∈ [0, 1)` on the CDF's fixed-point scale: the integer part (for the search,
/// at most `CDF_ONE - 1`) and the exact product (for the offset within the cell).
/// Values outside `[0, 1)`, and NaN, are clamped onto it.
#[inline(always)]
fn to_fixed(xi: f32) -> (u32, f64) {
    // `max` also maps NaN to 0.
    let t = (xi as f64 * CDF_ONE as f64)
        .max(0.0)
        .min((CDF_ONE - 1) as f64);
    // SAFETY: t is finite and in [0, 2³² - 2], where truncation to u32 is defined
    // (and is the floor).
    (unsafe { t.to_int_unchecked::<u32>() }, t)
}

/// log₂ of the number of guide entries for a CDF of `n` cells: the largest power of
/// two at most `n / 2` (at least 1), so a guide table costs at most 2 bytes per
/// cell and a slice spans fewer than 4 cells on average.
#[inline]
fn guide_bits(n: usize) -> u32 {
    (n / 2).max(1).ilog2()
}

/// A CDF with its guide table, borrowed from a distribution's storage.
#[derive(Clone, Copy)]
struct GuidedCdf<'a> {
    /// `n + 1` fixed-point values from 0 to [`CDF_ONE`].
    cdf: &'a [u32],
    /// `guide[k]`: the last cell `o` with `cdf[o] <= k << shift`.
    guide: &'a [u32],
    /// `32 - log₂(guide.len())`: the shift from a fixed-point `ξ` to its slice.
    shift: u32,
}

impl GuidedCdf<'_> {
    /// Number of cells.
    #[inline]
    fn len(&self) -> usize {
        self.cdf.len() - 1
    }

    /// Width of cell `o` in CDF units (0 for a cell with `f = 0`).
    #[inline(always)]
    fn width(&self, o: usize) -> u32 {
        self.cdf[o + 1] - self.cdf[o]
    }

    /// The guide table's answer for `x`: the first cell the search must consider.
    #[inline(always)]
    fn first_candidate(&self, x: u32) -> usize {
        *self.guide_entry(x) as usize
    }

    /// The guide entry of `x`'s slice.
    #[inline(always)]
    fn guide_entry(&self, x: u32) -> &u32 {
        &self.guide[(x as u64 >> self.shift) as usize]
    }

    /// Steps forward from the guide's candidate `o` to the cell `o` with
    /// `cdf[o] <= x < cdf[o + 1]` (for `x < CDF_ONE`; cells of zero width never
    /// satisfy this, so they are never returned), with that segment's ends
    /// `(cdf[o], cdf[o + 1])`.
    ///
    /// A plain loop: a branch-free variant taking the first two steps with selects
    /// (most searches end on the candidate or the cell after it) measured no faster
    /// with warm caches and cost 13 more instructions, so the predictor is left to
    /// guess the exit.
    #[inline(always)]
    fn segment(&self, mut o: usize, x: u32) -> (usize, u32, u32) {
        while self.cdf[o + 1] <= x {
            o += 1;
        }
        (o, self.cdf[o], self.cdf[o + 1])
    }

    /// The cell whose CDF segment holds `ξ`, `ξ` on the fixed-point scale (`t`),
    /// and the segment `(c[o], width)`. `hint` hears the guide table's first
    /// candidate cell before the CDF is read (see
    /// [`Distribution2D::sample_continuous_hinted`]).
    #[inline(always)]
    fn locate(&self, xi: f32, hint: impl FnOnce(usize)) -> (usize, f64, u32, u32) {
        let (x, t) = to_fixed(xi);
        let candidate = self.first_candidate(x);
        hint(candidate);
        let (o, lo, hi) = self.segment(candidate, x);
        (o, t, lo, hi - lo)
    }

    /// Continuous sample: the cell, the offset in `[0, 1)` within it, and its width.
    #[inline(always)]
    fn sample(&self, xi: f32) -> (usize, f64, u32) {
        let (o, t, lo, width) = self.locate(xi, |_| {});
        // t < cdf[o + 1] because ⌊t⌋ = x is, so the offset stays below 1.
        (o, (t - lo as f64) / width as f64, width)
    }

    /// Continuous sample as a point: the cell, the point `x ∈ [0, 1)` in it (placed
    /// with [`place_in_cell_f64`]'s guarantee), and the cell's width.
    ///
    /// `x = (o + (t - c[o]) / w) / n` is computed as `(o w + t - c[o]) / (w n)`, one
    /// division instead of two on the sample's critical path.
    #[inline(always)]
    fn sample_point(&self, xi: f32, hint: impl FnOnce(usize)) -> (usize, f32, u32) {
        let (x, t) = to_fixed(xi);
        let candidate = self.first_candidate(x);
        hint(candidate);
        self.point_from(candidate, x, t)
    }

    /// [`Self::sample_point`] from the guide's candidate cell for `ξ` on the
    /// fixed-point scale (`x = ⌊t⌋`).
    #[inline(always)]
    fn point_from(&self, candidate: usize, x: u32, t: f64) -> (usize, f32, u32) {
        let (o, lo, hi) = self.segment(candidate, x);
        let width = hi - lo;
        let n = self.len();
        let w = width as f64;
        let point = (len_f64(o) * w + (t - lo as f64)) / (w * len_f64(n));
        (o, nudge_into_cell(point as f32, o, n), width)
    }

    /// The `ξ` that [`Self::sample`] maps to the point `x ∈ [0, 1]`.
    #[inline]
    fn invert(&self, x: f32) -> f32 {
        let n = self.len();
        let o = cell_index(x, n);
        self.xi_at(o, x as f64 * n as f64 - o as f64)
    }

    /// The `ξ` that lands at offset `frac` (clamped to `[0, 1]`) within cell `o`'s
    /// CDF segment: `(c[o] + frac · width[o]) / CDF_ONE`.
    #[inline]
    fn xi_at(&self, o: usize, frac: f64) -> f32 {
        let t = self.cdf[o] as f64 + frac.clamp(0.0, 1.0) * self.width(o) as f64;
        ((t / CDF_ONE as f64) as f32).clamp(0.0, 1.0)
    }
}

/// `N` lanes of `ξ`, each on its way through a CDF of `n` cells within one
/// array (lane `j`'s CDF at `cdf[cdf_base[j]..][..n + 1]`): `ξ` on the fixed-point
/// scale (`⌊t⌋`, `t`), and once the guide is read, the range of CDF indices
/// `lo..=hi` that holds the lane's cell.
#[derive(Clone, Copy)]
pub(crate) struct SearchLanes<const N: usize> {
    fixed: [u32; N],
    t: [f64; N],
    cdf_base: [usize; N],
    lo: [usize; N],
    hi: [usize; N],
}

impl<const N: usize> SearchLanes<N> {
    /// `ξ` placed on the fixed-point scale, each lane's CDF starting at
    /// `cdf_base[j]`.
    #[inline(always)]
    fn new(xi: &[f32; N], cdf_base: [usize; N]) -> Self {
        let mut fixed = [0u32; N];
        let mut t = [0.0f64; N];
        for j in 0..N {
            (fixed[j], t[j]) = to_fixed(xi[j]);
        }
        Self {
            fixed,
            t,
            cdf_base,
            lo: [0; N],
            hi: [0; N],
        }
    }

    /// The index of each lane's guide entry in a table of guides, lane `j`'s
    /// starting at `guide_base[j]`, read with `shift` (as in [`GuidedCdf`]).
    #[inline(always)]
    fn guide_slots(&self, guide_base: &[usize; N], shift: u32) -> [usize; N] {
        let mut slot = [0usize; N];
        for j in 0..N {
            slot[j] = guide_base[j] + (self.fixed[j] as u64 >> shift) as usize;
        }
        slot
    }

    /// Reads each lane's guide entries at `slot` (from [`Self::guide_slots`])
    /// and the next, which bound its cell: the last cell `o` with
    /// `cdf[o] <= ⌊t⌋`, which the single sample's scan from the first entry
    /// reaches, lies between them (the last cell for the last slice).
    ///
    /// # Safety
    /// Each slot is in a guide of `1 << (32 - shift)` entries inside `guide`,
    /// each entry a cell below `n`; each lane's CDF lies inside the `cdf` that
    /// later calls read.
    #[inline(always)]
    unsafe fn bound(&mut self, guide: &[u32], slot: &[usize; N], shift: u32, n: usize) {
        let last_slice = (1usize << (32 - shift)) - 1;
        for (j, &slot) in slot.iter().enumerate() {
            let slice = (self.fixed[j] as u64 >> shift) as usize;
            let next = slot + (slice < last_slice) as usize;
            // SAFETY: both are entries of the lane's guide (the caller's promise).
            let (first, next) = unsafe { (*guide.get_unchecked(slot), *guide.get_unchecked(next)) };
            let next = if slice < last_slice {
                next
            } else {
                n as u32 - 1
            };
            self.lo[j] = self.cdf_base[j] + first as usize;
            self.hi[j] = self.cdf_base[j] + next as usize;
        }
    }

    /// Starts fetching the CDF entries where each lane's search begins.
    #[inline(always)]
    fn prefetch(&self, cdf: &[u32]) {
        for j in 0..N {
            prefetch_ptr(cdf.as_ptr().wrapping_add(self.lo[j]));
        }
    }

    /// The index in `cdf` of each lane's cell, as [`GuidedCdf::sample_point`]
    /// finds it: a binary search of every lane's range, all lanes a step at a
    /// time (a scan would take as many passes as the longest of the lanes'
    /// scans, which is long whenever one lane falls among many faint cells, as in
    /// a sun's row).
    ///
    /// # Safety
    /// As for [`Self::bound`], which must have been called.
    #[inline(always)]
    unsafe fn find(&self, cdf: &[u32]) -> [usize; N] {
        let (mut lo, mut hi) = (self.lo, self.hi);
        loop {
            let mut open = false;
            for j in 0..N {
                let mid = (lo[j] + hi[j]).div_ceil(2);
                // SAFETY: `mid` is a cell of the lane's CDF. A lane already found
                // reads its own cell, whose CDF entry is at most `⌊t⌋`.
                let below = unsafe { *cdf.get_unchecked(mid) } <= self.fixed[j];
                (lo[j], hi[j]) = if below {
                    (mid, hi[j])
                } else {
                    (lo[j], mid - 1)
                };
                open |= lo[j] < hi[j];
            }
            if !open {
                break;
            }
        }
        lo
    }

    /// The cells at `at` (from [`Self::find`]), the points in them and their
    /// widths, as [`GuidedCdf::sample_point`] gives them, bit for bit.
    ///
    /// # Safety
    /// `at` from [`Self::find`] on the same `cdf`.
    #[inline(always)]
    unsafe fn points(
        &self,
        cdf: &[u32],
        at: &[usize; N],
        n: usize,
    ) -> ([u32; N], [f32; N], [u32; N]) {
        let (mut cell, mut point, mut width) = ([0u32; N], [0.0f32; N], [0u32; N]);
        let n_f64 = len_f64(n);
        for j in 0..N {
            // SAFETY: a cell and the entry after it, both in the lane's CDF.
            let (a, b) = unsafe { (*cdf.get_unchecked(at[j]), *cdf.get_unchecked(at[j] + 1)) };
            let o = at[j] - self.cdf_base[j];
            let w = (b - a) as f64;
            // As `GuidedCdf::point_from`.
            let x = (len_f64(o) * w + (self.t[j] - a as f64)) / (w * n_f64);
            (cell[j], point[j], width[j]) = (o as u32, x as f32, b - a);
        }
        (cell, nudge_into_cell_lanes(&point, &cell, n), width)
    }

    /// The cells at `at` (from [`Self::find`]), the offsets of `ξ` in their CDF
    /// segments and their widths, as [`GuidedCdf::sample`] gives them, bit for
    /// bit.
    ///
    /// # Safety
    /// `at` from [`Self::find`] on the same `cdf`.
    #[inline(always)]
    unsafe fn offsets(&self, cdf: &[u32], at: &[usize; N]) -> ([u32; N], [f64; N], [u32; N]) {
        let (mut cell, mut offset, mut width) = ([0u32; N], [0.0f64; N], [0u32; N]);
        for j in 0..N {
            // SAFETY: a cell and the entry after it, both in the lane's CDF.
            let (a, b) = unsafe { (*cdf.get_unchecked(at[j]), *cdf.get_unchecked(at[j] + 1)) };
            let w = b - a;
            (cell[j], offset[j], width[j]) = (
                (at[j] - self.cdf_base[j]) as u32,
                (self.t[j] - a as f64) / w as f64,
                w,
            );
        }
        (cell, offset, width)
    }
}

/// [`nudge_into_cell`] of `N` points `x[j]` (each in `[0, 1)` but for rounding,
/// and within a few ulps of its cell) into their cells `cell[j]` on a grid of
/// `n < 2³¹` cells, with selects: the same values.
#[inline(always)]
fn nudge_into_cell_lanes<const N: usize>(x: &[f32; N], cell: &[u32; N], n: usize) -> [f32; N] {
    let last = (n - 1) as i32;
    let scale = len_f32(n);
    let mut out = [0.0f32; N];
    for j in 0..N {
        let mut y = x[j].min(ONE_MINUS_EPSILON);
        let c = cell[j] as i32;
        // Four tries, as `nudge_into_cell`, which stops at the first that finds
        // the cell: once found, a try changes nothing. The points are not
        // negative, so the neighbouring floats are a step of the bits.
        for _ in 0..4 {
            let found = floor_index_i32(y * scale, last);
            let bits = y.to_bits();
            let bits = if found > c {
                bits - 1
            } else if found < c {
                bits + 1
            } else {
                bits
            };
            y = f32::from_bits(bits);
        }
        out[j] = y;
    }
    out
}

/// The accessors every 2D grid sampler shares, with the same docs: `nu()`,
/// `nv()`, `integral()` (read from the named field path) and `pdf(uv)` (the named
/// cell-pdf method at the cell of `uv`); with `sample_continuous` (and its docs)
/// also the plain wrapper around the type's `sample_continuous_hinted`.
macro_rules! grid_2d_accessors {
    (integral: $($integral:ident).+, cell_pdf: $cell_pdf:ident $(,)?) => {
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
            self.$($integral).+
        }

        /// Density at `(u, v) ∈ [0, 1]²` (points outside are clamped onto the square).
        #[inline(always)]
        pub fn pdf(&self, uv: [f32; 2]) -> f32 {
            self.$cell_pdf(
                $crate::distribution::cell_index(uv[0], self.nu),
                $crate::distribution::cell_index(uv[1], self.nv),
            )
        }
    };
    (
        integral: $($integral:ident).+,
        cell_pdf: $cell_pdf:ident,
        $(#[$sample_doc:meta])*
        sample_continuous $(,)?
    ) => {
        $crate::distribution::grid_2d_accessors!(integral: $($integral).+, cell_pdf: $cell_pdf);

        $(#[$sample_doc])*
        #[inline(always)]
        pub fn sample_continuous(&self, xi: [f32; 2]) -> Sample2D {
            self.sample_continuous_hinted(xi, |_| {})
        }
    };
}
pub(crate) use grid_2d_accessors;

/// The number of rows of the row-major grid `f` with `nu` values per row.
///
/// # Panics
/// When `nu == 0`, `f` is empty, or `f.len()` is not a multiple of `nu`.
#[track_caller]
pub(crate) fn grid_rows(f: &[f32], nu: usize) -> usize {
    assert!(
        nu > 0 && !f.is_empty() && f.len().is_multiple_of(nu),
        "bad 2D grid shape"
    );
    f.len() / nu
}

/// The cell of `x ∈ [0, 1]` on a grid of `n` cells, `⌊x n⌋` clamped to `[0, n-1]`.
/// Every lookup (pdf, invert) and every sample placement goes through this one
/// function, so they agree about which cell a point is in.
#[inline(always)]
pub(crate) fn cell_index(x: f32, n: usize) -> usize {
    floor_index(x * len_f32(n), n)
}

/// [`cell_index`] of `N` coordinates at once, as a loop the compiler vectorizes;
/// bit for bit the same cells for any grid of fewer than 2³¹ cells.
#[inline(always)]
pub(crate) fn cell_indices<const N: usize>(x: &[f32; N], n: usize) -> [u32; N] {
    let last = (n - 1).min(i32::MAX as usize) as i32;
    let scale = len_f32(n);
    // A loop, not `array::map`, which the compiler may leave as a call.
    let mut out = [0u32; N];
    for (o, &x) in out.iter_mut().zip(x) {
        *o = floor_index_i32(x * scale, last) as u32;
    }
    out
}

/// The point `(cell + frac) / n` for an offset `frac ∈ [0, 1)`, computed in `f64`,
/// rounded to `f32` once, then nudged by an ulp or two where that rounding put it on
/// a neighbouring cell (`frac` just below 1 rounds up to the next cell's edge).
/// Without this, `pdf(sample.x)` could report the neighbour's density, which can
/// differ from the sampled cell's by any factor.
#[inline(always)]
pub(crate) fn place_in_cell_f64(cell: usize, frac: f64, n: usize) -> f32 {
    nudge_into_cell(((len_f64(cell) + frac) / len_f64(n)) as f32, cell, n)
}

/// Moves `x` (already within a few ulps of cell `cell`) into it, and below 1.
#[inline(always)]
pub(crate) fn nudge_into_cell(x: f32, cell: usize, n: usize) -> f32 {
    let mut x = x.min(ONE_MINUS_EPSILON);
    for _ in 0..4 {
        match cell_index(x, n).cmp(&cell) {
            std::cmp::Ordering::Greater => x = x.next_down(),
            std::cmp::Ordering::Less => x = x.next_up(),
            std::cmp::Ordering::Equal => break,
        }
    }
    x
}

/// Fills `cdf` (length `f.len() + 1`) with the fixed-point CDF of `f`, whose values
/// must be finite and non-negative, and `guide` (length `1 << guide_bits(n)`) with
/// its guide table. Returns `Σ f` (0 when there is no positive mass: then the CDF is
/// uniform).
///
/// Prefix sums in f64 are rounded to the nearest integer, then every cell with
/// `f > 0` is widened to at least 1: forward (a cell that rounded to nothing takes
/// one unit above its left edge) and, should that run past `CDF_ONE` at the end,
/// backward from `CDF_ONE`. Both passes only move edges by the few units that
/// rounding lost, and the CDF stays non-decreasing.
fn build_cdf<T: Copy + Into<f64>>(f: &[T], cdf: &mut [u32], guide: &mut [u32]) -> f64 {
    const TWO_TO_32: f64 = (1u64 << 32) as f64;
    let n = f.len();
    debug_assert_eq!(cdf.len(), n + 1);
    // Four partial sums, so that the adds do not wait on each other.
    let mut partial = [0.0f64; 4];
    let quads = f.chunks_exact(4);
    let rest: f64 = quads.remainder().iter().map(|&v| v.into()).sum();
    for quad in quads {
        for (p, &v) in partial.iter_mut().zip(quad) {
            *p += v.into();
        }
    }
    let total = (partial[0] + partial[1]) + (partial[2] + partial[3]) + rest;
    let one = CDF_ONE as u64;
    cdf[0] = 0;
    if total > 0.0 && total.is_finite() {
        let scale = CDF_ONE as f64 / total;
        let (mut running, mut prev, mut overran) = (0.0f64, 0u64, false);
        for (c, &v) in cdf[1..].iter_mut().zip(f) {
            let v: f64 = v.into();
            running += v;
            // Rounded half up by truncation, through i64 (f64::round is a library
            // call on the x86-64 baseline, and `as u64` a dozen instructions). Then
            // never below the previous edge, which a widened cell may have raised,
            // and a cell with mass at least one unit wide: branch-free, since
            // whether a cell rounds to nothing is data the predictor cannot learn.
            // Not `clamp`, which would pass a NaN through.
            #[allow(clippy::manual_clamp)]
            let rounded = (running * scale + 0.5).max(0.0).min(TWO_TO_32);
            // SAFETY: `max` and `min` return their non-NaN operand, so `rounded` is
            // a number in [0, 2³²], which an i64 holds; a plain `as` cast spends
            // six more instructions per texel on NaN and range checks.
            let rounded = unsafe { rounded.to_int_unchecked::<i64>() } as u64;
            let edge = rounded.max(prev + u64::from(v > 0.0));
            // An edge passes CDF_ONE when cells had to be widened near the end, or
            // (on rows of about 2²⁰ cells or more) when `running`, summed in another
            // order than `total`, ends a few ulps above it; the backward pass below
            // repairs both. The edge is capped where it is stored, not in `prev`,
            // which keeps the chain from one cell to the next at an add and a max;
            // past CDF_ONE every later edge is stored as CDF_ONE either way.
            overran |= edge > one;
            *c = edge.min(one) as u32;
            prev = edge;
        }
        // The last cell needs room below CDF_ONE too.
        overran |= f[n - 1].into() > 0.0 && cdf[n - 1] == CDF_ONE;
        cdf[n] = CDF_ONE;
        if overran {
            for o in (1..n).rev() {
                let limit = if f[o].into() > 0.0 {
                    cdf[o + 1].saturating_sub(1)
                } else {
                    cdf[o + 1]
                };
                cdf[o] = cdf[o].min(limit);
            }
        }
    } else {
        for (i, c) in cdf.iter_mut().enumerate() {
            *c = (i as f64 / n as f64 * CDF_ONE as f64).round() as u32;
        }
    }
    build_guide(cdf, guide);
    total
}

/// `guide[k]` = the last cell `o` (of `n = cdf.len() - 1`) with
/// `cdf[o] <= k · 2³² / guide.len()`.
fn build_guide(cdf: &[u32], guide: &mut [u32]) {
    let n = cdf.len() - 1;
    let shift = 32 - guide.len().ilog2();
    // Cell o belongs in every entry k with cdf[o] <= k · 2^shift, the first of
    // which is ⌈cdf[o] / 2^shift⌉. Writing o there for every cell, in increasing
    // order, leaves each entry with the last cell that starts exactly at it (or
    // 0); a running maximum then carries each cell on to the entries it covers.
    // No data-dependent branches, where a merge of the two arrays mispredicts
    // on about every other cell.
    guide.fill(0);
    let round_up = (1u64 << shift) - 1;
    let len = guide.len();
    for (o, &c) in (1..n as u32).zip(&cdf[1..n]) {
        let k = ((c as u64 + round_up) >> shift) as usize;
        if k < len {
            guide[k] = o;
        }
    }
    let mut last = 0;
    for g in guide.iter_mut() {
        last = last.max(*g);
        *g = last;
    }
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
    // `&` rather than `&&`: two compares and a select, which loops vectorize.
    if (value > 0.0) & (value < f32::INFINITY) {
        value
    } else {
        0.0
    }
}

/// `x ≥ 0` rounded to `f32` as a weight that keeps its support: a positive `x`
/// stays positive (at least the smallest subnormal) and finite (at most
/// `f32::MAX`); anything else is 0.
#[inline(always)]
pub(crate) fn positive_weight(x: f64) -> f32 {
    if x > 0.0 {
        (x as f32).clamp(f32::from_bits(1), f32::MAX)
    } else {
        0.0
    }
}

/// A piecewise-constant distribution on `[0, 1]` with `n` equal cells.
///
/// Guarantees: exactly the cells with `f > 0` are sampled; `pdf` is the exact density
/// of `sample_continuous` and `pdf(sample_continuous(ξ).x)` equals the returned pdf;
/// `invert(sample_continuous(ξ).x) ≈ ξ`. Sampling costs one guide-table lookup and a
/// short forward scan (`O(1)` expected); memory is 4 to 6 bytes per cell.
///
/// ```
/// use envlight::distribution::Distribution1D;
/// let d = Distribution1D::new(&[1.0, 1.0, 2.0, 4.0, 8.0]);
/// let s = d.sample_continuous(0.75);
/// assert!((s.x - 0.9).abs() < 1e-6 && (s.pdf - 2.5).abs() < 1e-6);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution1D {
    cdf: Vec<u32>,
    guide: Vec<u32>,
    integral: f64,
    /// `n / CDF_ONE`, or 0 for a zero function: pdf = width · this.
    pdf_scale: f64,
}

/// A [`Distribution2D`]'s cell densities as tables (see
/// [`Distribution2D::cell_tables`]): cell `(iu, iv)` has the density
/// `(cdf[iv (nu + 1) + iu + 1] - cdf[iv (nu + 1) + iu]) ·
/// (marginal[iv + 1] - marginal[iv]) · pdf_scale`, the product taken in f64 and
/// rounded to f32 once.
pub(crate) struct CellTables<'a> {
    pub conditional_cdf: &'a [u32],
    pub marginal_cdf: &'a [u32],
    pub nu: usize,
    pub nv: usize,
    pub pdf_scale: f64,
}

/// A continuous sample of a 1D distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample1D {
    /// The point in `[0, 1)`.
    pub x: f32,
    /// Its density, `n` times the cell's probability (0 when the function is zero).
    pub pdf: f32,
    /// The cell that holds `x`.
    pub cell: usize,
}

/// A discrete sample of a 1D distribution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DiscreteSample {
    /// The chosen cell.
    pub index: usize,
    /// Its probability, `f[index] / Σ f` up to the CDF's 2⁻³² resolution (0 when the
    /// function is zero).
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
        let f: Vec<f32> = f.iter().map(|&v| sanitize(v)).collect();
        Self::from_sanitized(&f)
    }

    /// Builds from values already known to be finite and non-negative.
    fn from_sanitized<T: Copy + Into<f64>>(f: &[T]) -> Self {
        assert!(!f.is_empty(), "a distribution needs at least one cell");
        let n = f.len();
        let mut cdf = vec![0u32; n + 1];
        let mut guide = vec![0u32; 1 << guide_bits(n)];
        let total = build_cdf(f, &mut cdf, &mut guide);
        let integral = total / n as f64;
        let pdf_scale = if inverse_or_zero(integral) > 0.0 {
            n as f64 / CDF_ONE as f64
        } else {
            0.0
        };
        Self {
            cdf,
            guide,
            integral,
            pdf_scale,
        }
    }

    #[inline]
    fn view(&self) -> GuidedCdf<'_> {
        GuidedCdf {
            cdf: &self.cdf,
            guide: &self.guide,
            // The guide's length is a power of two: its log is one instruction,
            // where `guide_bits` takes six.
            shift: 32 - self.guide.len().trailing_zeros(),
        }
    }

    /// Number of cells.
    #[inline]
    pub fn len(&self) -> usize {
        self.cdf.len() - 1
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

    /// The fixed-point CDF, `n + 1` entries from 0 to [`CDF_ONE`].
    #[inline]
    pub fn cdf(&self) -> &[u32] {
        &self.cdf
    }

    /// Bytes of sampling data held (CDF and guide table).
    pub fn memory_bytes(&self) -> usize {
        4 * (self.cdf.len() + self.guide.len())
    }

    /// The guide table: `1 << guide_bits(n)` entries, entry `k` the last cell `o`
    /// with `cdf[o] <= k · 2³² / len` (for [`crate::gpu`]'s export).
    #[inline]
    pub(crate) fn guide(&self) -> &[u32] {
        &self.guide
    }

    /// Density at `x ∈ [0, 1]`: `n · width[⌊x n⌋] / CDF_ONE`, or 0 for a zero
    /// function.
    #[inline]
    pub fn pdf(&self, x: f32) -> f32 {
        self.cell_pdf(cell_index(x, self.len()))
    }

    #[inline]
    fn cell_pdf(&self, cell: usize) -> f32 {
        (self.view().width(cell) as f64 * self.pdf_scale) as f32
    }

    /// Maps `ξ ∈ [0, 1)` to `x` distributed with density `pdf`: finds the cell `o`
    /// whose CDF segment holds `ξ`, then places `x` linearly inside it.
    #[inline]
    pub fn sample_continuous(&self, xi: f32) -> Sample1D {
        let (cell, x, width) = self.view().sample_point(xi, |_| {});
        Sample1D {
            x,
            pdf: (width as f64 * self.pdf_scale) as f32,
            cell,
        }
    }

    /// Picks cell `i` with probability `width[i] / CDF_ONE ≈ f[i] / Σ f`.
    #[inline]
    pub fn sample_discrete(&self, xi: f32) -> DiscreteSample {
        let (index, frac, _) = self.view().sample(xi);
        DiscreteSample {
            index,
            probability: self.discrete_probability(index),
            remapped: (frac as f32).min(ONE_MINUS_EPSILON),
        }
    }

    /// Probability of picking cell `index` in [`Self::sample_discrete`].
    #[inline]
    pub fn discrete_probability(&self, index: usize) -> f32 {
        (self.cell_pdf(index) as f64 / self.len() as f64) as f32
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `x`:
    /// `ξ = (c[o] + (x n - o) width[o]) / CDF_ONE` with `o = ⌊x n⌋`.
    #[inline]
    pub fn invert(&self, x: f32) -> f32 {
        self.view().invert(x)
    }
}

/// A piecewise-constant distribution on `[0, 1]²` over an `nu × nv` grid, sampled
/// as a marginal over rows (v) and a conditional within the chosen row (u):
/// `p(u, v) = p(v) p(u | v)`, which equals `f[v][u] / I` with `I = Σ f / (nu nv)` up
/// to the CDFs' 2⁻³² resolution (see the module docs).
///
/// Memory: 4 bytes of CDF and 1 to 2 bytes of guide table per cell, plus about 6
/// per row. Sampling: two guide-table lookups with short scans, `O(1)` expected.
#[derive(Debug, Clone, PartialEq)]
pub struct Distribution2D {
    nu: usize,
    nv: usize,
    /// Row `v`'s conditional CDF at `[v * (nu + 1) .. (v + 1) * (nu + 1)]`.
    conditional_cdf: Vec<u32>,
    /// Row `v`'s guide table at `[v * guide_len .. (v + 1) * guide_len]`.
    conditional_guide: Vec<u32>,
    marginal: Distribution1D,
    /// `nu nv / CDF_ONE²`, or 0 for a zero function: pdf = width_u · width_v · this.
    pdf_scale: f64,
    /// `guide_bits(nu)`: each row's guide table has `1 << row_guide_bits` entries.
    row_guide_bits: u32,
    /// `1 / nu` in f32, for the sampling hint's cell centres (which need not be
    /// exact, and should not spend a division).
    inv_nu: f32,
}

/// `N` samples of a [`Distribution2D`] between the stages of
/// [`Distribution2D::rows_lanes`]: the marginal's search and each lane's row
/// (its index in the marginal's CDF), and the searches in the rows.
#[derive(Clone, Copy)]
pub(crate) struct RowLanes<const N: usize> {
    rows: SearchLanes<N>,
    row_at: [usize; N],
    cells: SearchLanes<N>,
    slot: [usize; N],
}

/// `N` cells picked by a [`Distribution2D`], lane by lane, as [`CellSample`]s:
/// `[iu, iv]`, the offsets of `ξ` in their CDF segments, their widths.
#[derive(Debug, Clone, Copy)]
pub(crate) struct CellLanes<const N: usize> {
    pub cell: [[u32; N]; 2],
    pub offset: [[f64; N]; 2],
    pub widths: [[u32; N]; 2],
}

/// `N` continuous samples of a [`Distribution2D`], lane by lane: the points
/// `(u, v)`, their densities and their cells `[iu, iv]`.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SampleLanes<const N: usize> {
    pub u: [f32; N],
    pub v: [f32; N],
    pub pdf: [f32; N],
    pub iu: [u32; N],
    pub iv: [u32; N],
}

/// A continuous sample of a 2D distribution.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sample2D {
    /// The point `[u, v]` in `[0, 1)²`.
    pub uv: [f32; 2],
    /// Its density with respect to area in `[0, 1]²` (0 for a zero function).
    pub pdf: f32,
    /// The cell `[iu, iv]` holding the point.
    pub cell: [usize; 2],
}

/// The probability of a cell of a [`Distribution2D`] of CDF widths `[wu, wv]`:
/// `wu wv / CDF_ONE²`.
#[inline(always)]
pub(crate) fn probability_of_widths([wu, wv]: [u32; 2]) -> f64 {
    (wu as f64 * (1.0 / CDF_ONE as f64)) * (wv as f64 * (1.0 / CDF_ONE as f64))
}

/// A cell picked by a [`Distribution2D`], before a point is placed in it.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct CellSample {
    /// `[iu, iv]`.
    pub cell: [usize; 2],
    /// Where `ξ` fell within the cell's CDF segments, `[0, 1)` each.
    pub offset: [f64; 2],
    /// The cell's widths in CDF units, `[width_u, width_v]`.
    pub widths: [u32; 2],
}

impl Distribution2D {
    /// Builds the distribution of `f`, given row-major with `nu` values per row.
    /// Rows are built in parallel. Negative, NaN and infinite values count as 0.
    ///
    /// # Panics
    /// When `nu == 0`, `f` is empty, or `f.len()` is not a multiple of `nu`.
    pub fn new(f: &[f32], nu: usize) -> Self {
        Self::from_rows(nu, grid_rows(f, nu), |v, row| {
            row.copy_from_slice(&f[v * nu..(v + 1) * nu]);
        })
    }

    /// Builds the distribution from a function that fills row `v` (`nu` values) into
    /// a scratch buffer; rows are filled and turned into CDFs in parallel, in one pass
    /// over memory, and the function values themselves are never stored. Values that
    /// are not finite and positive count as 0.
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
        assert!(nu > 0 && nv > 0, "bad 2D grid shape");
        let mut conditional_cdf = vec![0u32; (nu + 1) * nv];
        advise_huge_pages(&conditional_cdf);
        let guide_len = 1usize << guide_bits(nu);
        let mut conditional_guide = vec![0u32; guide_len * nv];
        advise_huge_pages(&conditional_guide);
        let mut rows: Vec<(&mut [u32], &mut [u32])> = conditional_cdf
            .chunks_mut(nu + 1)
            .zip(conditional_guide.chunks_mut(guide_len))
            .collect();
        let (row_sums, results) = for_each_row(nu, init, fill_row, &mut rows, |row, out| {
            build_cdf(row, out.0, out.1)
        });
        drop(rows);
        let row_integrals: Vec<f64> = row_sums.iter().map(|&s| s / nu as f64).collect();
        let marginal = Distribution1D::from_sanitized(&row_integrals);
        let pdf_scale = if marginal.pdf_scale > 0.0 {
            (nu as f64 / CDF_ONE as f64) * (nv as f64 / CDF_ONE as f64)
        } else {
            0.0
        };
        (
            Self {
                nu,
                nv,
                conditional_cdf,
                conditional_guide,
                marginal,
                pdf_scale,
                row_guide_bits: guide_bits(nu),
                inv_nu: 1.0 / nu as f32,
            },
            results,
        )
    }

    grid_2d_accessors!(
        integral: marginal.integral,
        cell_pdf: cell_pdf_in_grid,
        /// Maps `ξ = [ξ0, ξ1] ∈ [0, 1)²` to a point with density [`Self::pdf`]: `ξ1`
        /// picks the row from the marginal, `ξ0` the position within that row.
        sample_continuous,
    );

    /// The marginal distribution over rows (built from the rows' integrals).
    #[inline]
    pub fn marginal(&self) -> &Distribution1D {
        &self.marginal
    }

    /// Row `v`'s conditional distribution's fixed-point CDF, `nu + 1` entries.
    #[inline]
    pub fn row_cdf(&self, v: usize) -> &[u32] {
        &self.conditional_cdf[v * (self.nu + 1)..(v + 1) * (self.nu + 1)]
    }

    /// Bytes of sampling data held (CDFs and guide tables).
    pub fn memory_bytes(&self) -> usize {
        4 * (self.conditional_cdf.len() + self.conditional_guide.len())
            + self.marginal.memory_bytes()
    }

    /// Every row's conditional CDF, row `v` at `[v (nu + 1) .. (v + 1) (nu + 1)]`
    /// (for [`crate::gpu`]'s export).
    #[inline]
    pub(crate) fn conditional_cdfs(&self) -> &[u32] {
        &self.conditional_cdf
    }

    /// Every row's guide table, row `v` at `[v << bits .. (v + 1) << bits]` with
    /// `bits` = [`Self::row_guide_bits`] (for [`crate::gpu`]'s export).
    #[inline]
    pub(crate) fn conditional_guides(&self) -> &[u32] {
        &self.conditional_guide
    }

    /// log₂ of the entries of each row's guide table.
    #[inline]
    pub(crate) fn row_guide_bits(&self) -> u32 {
        self.row_guide_bits
    }

    #[inline(always)]
    fn row(&self, v: usize) -> GuidedCdf<'_> {
        let bits = self.row_guide_bits;
        let len = 1usize << bits;
        GuidedCdf {
            cdf: self.row_cdf(v),
            guide: &self.conditional_guide[v * len..(v + 1) * len],
            shift: 32 - bits,
        }
    }

    /// Density of cell `[iu, iv]`: `nu nv · width_v(iv) · width_u(iu | iv) /
    /// CDF_ONE²`, 0 for a zero function.
    ///
    /// # Panics
    /// When the cell is outside the grid.
    #[inline(always)]
    pub fn cell_pdf(&self, iu: usize, iv: usize) -> f32 {
        assert!(iu < self.nu && iv < self.nv, "cell outside the grid");
        self.cell_pdf_in_grid(iu, iv)
    }

    /// Starts fetching what [`Self::cell_pdf`] of cell `[iu, iv]` will read (the
    /// row's CDF entries; the marginal is small and stays cached). A hint: any
    /// cell, even outside the grid, is harmless.
    #[inline(always)]
    pub(crate) fn prefetch_cell(&self, iu: usize, iv: usize) {
        let at = iv.wrapping_mul(self.nu + 1).wrapping_add(iu);
        prefetch_ptr(self.conditional_cdf.as_ptr().wrapping_add(at));
    }

    /// The tables a cell's density is read from, for kernels that gather them
    /// themselves (the AVX-512 batch queries): each row's conditional CDF, the
    /// marginal CDF, the grid's size and the scale of [`Self::cell_pdfs_in_grid`].
    pub(crate) fn cell_tables(&self) -> CellTables<'_> {
        CellTables {
            conditional_cdf: &self.conditional_cdf,
            marginal_cdf: &self.marginal.cdf,
            nu: self.nu,
            nv: self.nv,
            pdf_scale: self.pdf_scale,
        }
    }

    /// [`Self::cell_pdf`] of a cell known to be in the grid (`iu < nu`, `iv < nv`,
    /// as [`cell_index`] guarantees), without bounds checks: the hot lookups pay
    /// for four of them otherwise, which the compiler cannot prove redundant.
    #[inline(always)]
    pub(crate) fn cell_pdf_in_grid(&self, iu: usize, iv: usize) -> f32 {
        let [wu, wv] = self.cell_widths_in_grid(iu, iv);
        self.pdf_of_widths(wu, wv)
    }

    /// Row `iv`'s conditional CDF (`nu + 1` entries) and its width in the
    /// marginal CDF: each cell's probability is `(cdf[iu + 1] − cdf[iu]) ·
    /// width` in CDF units ([`probability_of_widths`]).
    ///
    /// # Panics
    /// When `iv >= nv`.
    pub(crate) fn row_widths(&self, iv: usize) -> (&[u32], u32) {
        let stride = self.nu + 1;
        let marginal = &self.marginal.cdf;
        (
            &self.conditional_cdf[iv * stride..(iv + 1) * stride],
            marginal[iv + 1] - marginal[iv],
        )
    }

    /// The CDF widths `[width_u, width_v]` of a cell in the grid, read without
    /// bounds checks (see [`Self::cell_pdf_in_grid`]).
    #[inline(always)]
    fn cell_widths_in_grid(&self, iu: usize, iv: usize) -> [u32; 2] {
        debug_assert!(iu < self.nu && iv < self.nv);
        let marginal = &self.marginal.cdf;
        // The row's CDF entries directly: building the row's view would also
        // slice (and bounds-check) its guide table, which a lookup never reads.
        let at = iv * (self.nu + 1) + iu;
        let cdf = &self.conditional_cdf;
        // SAFETY: the marginal CDF has nv + 1 entries and the conditional CDFs
        // nv (nu + 1), so for iu < nu and iv < nv all four indices are in range.
        let (wu, wv) = unsafe {
            (
                cdf.get_unchecked(at + 1) - cdf.get_unchecked(at),
                marginal.get_unchecked(iv + 1) - marginal.get_unchecked(iv),
            )
        };
        [wu, wv]
    }

    /// [`Self::cell_pdf_in_grid`] of `N` cells at once (`iu[i] < nu`, `iv[i] < nv`,
    /// as [`cell_indices`] gives them), as loops the compiler turns into vector
    /// gathers and vector f64 arithmetic: the same operations, bit for bit.
    #[inline(always)]
    pub(crate) fn cell_pdfs_in_grid<const N: usize>(
        &self,
        iu: &[u32; N],
        iv: &[u32; N],
    ) -> [f32; N] {
        let (cdf, marginal) = (&self.conditional_cdf, &self.marginal.cdf);
        let stride = self.nu + 1;
        let mut out = [0.0f32; N];
        for i in 0..N {
            let (u, v) = (iu[i] as usize, iv[i] as usize);
            debug_assert!(u < self.nu && v < self.nv);
            let at = v * stride + u;
            // SAFETY: as in `cell_widths_in_grid`, for u < nu and v < nv.
            let (wu, wv) = unsafe {
                (
                    cdf.get_unchecked(at + 1) - cdf.get_unchecked(at),
                    marginal.get_unchecked(v + 1) - marginal.get_unchecked(v),
                )
            };
            out[i] = self.pdf_of_widths(wu, wv);
        }
        out
    }

    #[inline(always)]
    fn pdf_of_widths(&self, wu: u32, wv: u32) -> f32 {
        (wu as f64 * wv as f64 * self.pdf_scale) as f32
    }

    /// [`Self::sample_continuous`], telling `hint` an early estimate of the point
    /// (the centre of the first cell the row's guide table names, usually the
    /// sampled cell or its neighbour) before the row's CDF is read. A caller can
    /// start fetching what it will read at the point, such as the texels of a
    /// radiance lookup, while the search finishes: on a large map that overlaps two
    /// cache misses that would otherwise follow each other.
    #[inline(always)]
    pub fn sample_continuous_hinted(&self, xi: [f32; 2], hint: impl FnOnce([f32; 2])) -> Sample2D {
        let (iv, v, wv) = self.marginal.view().sample_point(xi[1], |_| {});
        let (iu, u, wu) = self
            .row(iv)
            .sample_point(xi[0], |guess| hint([self.cell_centre_u(guess), v]));
        Sample2D {
            uv: [u, v],
            pdf: self.pdf_of_widths(wu, wv),
            cell: [iu, iv],
        }
    }

    /// [`Self::sample_continuous_hinted`] for a block of `ξ` (at most
    /// [`STAGED_BLOCK`]) in three passes over the block: the marginal and the
    /// address of each row's guide entry, then the guide entries and the address
    /// of each CDF segment, then the scans and placements. Each pass only asks for
    /// the memory the next one reads, so the block's cache misses overlap instead
    /// of following each other; the results are the same as one sample at a time.
    ///
    /// # Panics
    /// When the slices differ in length or are longer than [`STAGED_BLOCK`].
    #[inline(always)]
    pub fn sample_block(&self, xi: &[[f32; 2]], out: &mut [Sample2D], hint: impl Fn([f32; 2])) {
        self.staged_block(
            xi,
            out,
            |marginal, x| {
                let (iv, v, wv) = marginal.sample_point(x, |_| {});
                (iv, (v, wv))
            },
            |c, &(v, _)| hint([self.cell_centre_u(c), v]),
            |row, c, fixed, t, iv, &(v, wv)| {
                let (iu, u, wu) = row.point_from(c, fixed, t);
                Sample2D {
                    uv: [u, v],
                    pdf: self.pdf_of_widths(wu, wv),
                    cell: [iu, iv],
                }
            },
        );
    }

    /// The cell that [`Self::sample_continuous`] picks for `ξ`, with the offsets of
    /// `ξ` within the cell's CDF segments (each in `[0, 1)`, free for placing a
    /// point in the cell by some other rule) and the cell's fixed-point widths.
    #[inline(always)]
    pub(crate) fn sample_cell(&self, xi: [f32; 2]) -> CellSample {
        let (iv, fv, wv) = self.marginal.view().sample(xi[1]);
        let (iu, fu, wu) = self.row(iv).sample(xi[0]);
        CellSample {
            cell: [iu, iv],
            offset: [fu, fv],
            widths: [wu, wv],
        }
    }

    /// The `ξ` that [`Self::sample_cell`] maps to cell `cell` with `offset`: the
    /// inverse of the choice, whatever rule placed the point in the cell.
    #[inline]
    pub(crate) fn invert_cell(&self, cell: [usize; 2], offset: [f64; 2]) -> [f32; 2] {
        [
            self.row(cell[1]).xi_at(cell[0], offset[0]),
            self.marginal.view().xi_at(cell[1], offset[1]),
        ]
    }

    /// Samples a block of `ξ` (at most [`STAGED_BLOCK`]) in three passes over the
    /// block: the marginal (`marginal`, whose data is small and stays cached) and
    /// the address of each row's guide entry, then the guide entries (each
    /// candidate cell told to `hint`) and the address of each CDF segment, then the
    /// scans and results (`finish`). Each pass only asks for the memory the next
    /// one reads, so on a map larger than the caches a block's cache misses
    /// overlap instead of following each other sample by sample.
    ///
    /// # Panics
    /// When the slices differ in length or are longer than [`STAGED_BLOCK`].
    #[inline(always)]
    fn staged_block<M: Copy + Default, R>(
        &self,
        xi: &[[f32; 2]],
        out: &mut [R],
        marginal: impl Fn(GuidedCdf<'_>, f32) -> (usize, M),
        hint: impl Fn(usize, &M),
        finish: impl Fn(GuidedCdf<'_>, usize, u32, f64, usize, &M) -> R,
    ) {
        assert!(
            xi.len() == out.len() && xi.len() <= STAGED_BLOCK,
            "bad block"
        );
        /// A sample between passes: its row, what `marginal` said of it, and `ξ0`
        /// on the fixed-point scale (`⌊t⌋`, `t`).
        #[derive(Clone, Copy, Default)]
        struct InRow<M> {
            iv: usize,
            row: M,
            fixed: u32,
            t: f64,
        }
        let mut rows = [InRow::<M>::default(); STAGED_BLOCK];
        for (row, &x) in rows.iter_mut().zip(xi) {
            let (iv, m) = marginal(self.marginal.view(), x[1]);
            let (fixed, t) = to_fixed(x[0]);
            prefetch_read(self.row(iv).guide_entry(fixed));
            *row = InRow {
                iv,
                row: m,
                fixed,
                t,
            };
        }
        let mut candidates = [0usize; STAGED_BLOCK];
        for (c, row) in candidates.iter_mut().zip(&rows[..xi.len()]) {
            let cdf = self.row(row.iv);
            *c = cdf.first_candidate(row.fixed);
            prefetch_read(&cdf.cdf[*c + 1]);
            hint(*c, &row.row);
        }
        for ((o, row), &c) in out.iter_mut().zip(&rows).zip(&candidates) {
            *o = finish(self.row(row.iv), c, row.fixed, row.t, row.iv, &row.row);
        }
    }

    /// The first stage of [`Self::sample_continuous`] for `N` lanes of `ξ` in
    /// vector lanes: the rows, from the marginal (small, so in cache), and where
    /// in each row's guide its `ξ0` falls. [`Self::prefetch_guides`],
    /// [`Self::bound_lanes`], [`Self::prefetch_cdfs`] and [`Self::finish_lanes`]
    /// go on from there; a caller runs each stage over several blocks before the
    /// next, so that each block's memory is on its way while the others work.
    #[inline(always)]
    pub(crate) fn rows_lanes<const N: usize>(&self, xi0: &[f32; N], xi1: &[f32; N]) -> RowLanes<N> {
        let marginal = self.marginal.view();
        let mut rows = SearchLanes::new(xi1, [0; N]);
        let slot = rows.guide_slots(&[0; N], marginal.shift);
        // SAFETY: one CDF and guide, the marginal's own, of nv cells.
        let at = unsafe {
            rows.bound(marginal.guide, &slot, marginal.shift, self.nv);
            rows.find(marginal.cdf)
        };
        let (stride, guide_len) = (self.nu + 1, 1usize << self.row_guide_bits);
        let (mut cdf_base, mut guide_base) = ([0usize; N], [0usize; N]);
        for j in 0..N {
            cdf_base[j] = at[j] * stride;
            guide_base[j] = at[j] * guide_len;
        }
        let cells = SearchLanes::new(xi0, cdf_base);
        let slot = cells.guide_slots(&guide_base, 32 - self.row_guide_bits);
        RowLanes {
            rows,
            row_at: at,
            cells,
            slot,
        }
    }

    /// The stages of the lanes sampler ([`Self::rows_lanes`]) over a block of
    /// `ξ` (at most [`STAGED_BLOCK`]), [`SAMPLE_LANES`] at a time, each stage run
    /// over the whole block before the next so that the block's cache misses
    /// overlap; `finish` takes each lane block's last stage and writes its
    /// results (as many as the lanes hold real `ξ`).
    ///
    /// # Panics
    /// When the slices differ in length or are longer than [`STAGED_BLOCK`].
    #[inline(always)]
    pub(crate) fn staged_lanes<R>(
        &self,
        xi: &[[f32; 2]],
        out: &mut [R],
        finish: impl Fn(&RowLanes<SAMPLE_LANES>, &mut [R]),
    ) {
        const BLOCKS: usize = STAGED_BLOCK / SAMPLE_LANES;
        assert!(
            xi.len() == out.len() && xi.len() <= STAGED_BLOCK,
            "bad block"
        );
        let mut rows = [None; BLOCKS];
        for (r, xi) in rows.iter_mut().zip(xi.chunks(SAMPLE_LANES)) {
            let (mut xi0, mut xi1) = ([0.0f32; SAMPLE_LANES], [0.0f32; SAMPLE_LANES]);
            for (j, x) in xi.iter().enumerate() {
                (xi0[j], xi1[j]) = (x[0], x[1]);
            }
            let lanes = self.rows_lanes(&xi0, &xi1);
            self.prefetch_guides(&lanes);
            *r = Some(lanes);
        }
        for r in rows.iter_mut().flatten() {
            self.bound_lanes(r);
            self.prefetch_cdfs(r);
        }
        for (r, out) in rows.iter().flatten().zip(out.chunks_mut(SAMPLE_LANES)) {
            finish(r, out);
        }
    }

    /// [`Self::sample_cell_block`] in vector lanes ([`Self::staged_lanes`]),
    /// bit for bit.
    #[inline(always)]
    pub(crate) fn sample_cell_lanes_block(&self, xi: &[[f32; 2]], out: &mut [CellSample]) {
        self.staged_lanes(
            xi,
            out,
            #[inline(always)]
            |rows, out| {
                let c = self.finish_cells_lanes(rows);
                for (j, o) in out.iter_mut().enumerate() {
                    *o = CellSample {
                        cell: [c.cell[0][j] as usize, c.cell[1][j] as usize],
                        offset: [c.offset[0][j], c.offset[1][j]],
                        widths: [c.widths[0][j], c.widths[1][j]],
                    };
                }
            },
        );
    }

    /// Starts fetching the row guide entries that [`Self::bound_lanes`] reads.
    #[inline(always)]
    pub(crate) fn prefetch_guides<const N: usize>(&self, rows: &RowLanes<N>) {
        for &slot in &rows.slot {
            prefetch_ptr(self.conditional_guide.as_ptr().wrapping_add(slot));
        }
    }

    /// Reads the row guides of `rows`, bounding each lane's cell.
    #[inline(always)]
    pub(crate) fn bound_lanes<const N: usize>(&self, rows: &mut RowLanes<N>) {
        // SAFETY: the slots are in the guides of rows below nv, as `Self::row`
        // slices them, whose entries are cells below nu.
        unsafe {
            rows.cells.bound(
                &self.conditional_guide,
                &rows.slot,
                32 - self.row_guide_bits,
                self.nu,
            )
        };
    }

    /// Starts fetching the CDF entries where [`Self::finish_lanes`] searches.
    #[inline(always)]
    pub(crate) fn prefetch_cdfs<const N: usize>(&self, rows: &RowLanes<N>) {
        rows.cells.prefetch(&self.conditional_cdf);
    }

    /// The last stage: the cells in the rows, the points, the densities.
    #[inline(always)]
    pub(crate) fn finish_lanes<const N: usize>(&self, r: &RowLanes<N>) -> SampleLanes<N> {
        // SAFETY: the marginal's search found `row_at` in its CDF; `bound_lanes`
        // bounded the cells in the CDFs of those rows.
        let ((iv, v, wv), (iu, u, wu)) = unsafe {
            (r.rows.points(&self.marginal.cdf, &r.row_at, self.nv), {
                let at = r.cells.find(&self.conditional_cdf);
                r.cells.points(&self.conditional_cdf, &at, self.nu)
            })
        };
        let mut pdf = [0.0f32; N];
        for j in 0..N {
            pdf[j] = self.pdf_of_widths(wu[j], wv[j]);
        }
        SampleLanes { u, v, pdf, iu, iv }
    }

    /// The last stage of [`Self::sample_cell`] in vector lanes: the cells and the
    /// offsets of `ξ` in their CDF segments, bit for bit.
    #[inline(always)]
    pub(crate) fn finish_cells_lanes<const N: usize>(&self, r: &RowLanes<N>) -> CellLanes<N> {
        // SAFETY: as in `finish_lanes`.
        let ((iv, fv, wv), (iu, fu, wu)) = unsafe {
            (r.rows.offsets(&self.marginal.cdf, &r.row_at), {
                let at = r.cells.find(&self.conditional_cdf);
                r.cells.offsets(&self.conditional_cdf, &at)
            })
        };
        CellLanes {
            cell: [iu, iv],
            offset: [fu, fv],
            widths: [wu, wv],
        }
    }

    /// The centre of column `iu`, `(iu + ½) / nu`, to within an ulp or two (for
    /// hints only).
    #[inline(always)]
    fn cell_centre_u(&self, iu: usize) -> f32 {
        (len_f32(iu) + 0.5) * self.inv_nu
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `uv`.
    #[inline]
    pub fn invert(&self, uv: [f32; 2]) -> [f32; 2] {
        let xi1 = self.marginal.view().invert(uv[1]);
        let xi0 = self.row(cell_index(uv[1], self.nv)).invert(uv[0]);
        [xi0, xi1]
    }
}

/// Fills `nv` rows of `nu` values in parallel and hands each, sanitised, to
/// `consume` with that row's item of `outputs` (one per row). Returns what `consume`
/// gave for each row and `fill_row`'s results, in row order.
///
/// Rows go out in contiguous blocks, in increasing order within a block: enough
/// blocks to balance the load, each big enough that per-block work (state set-up,
/// scheduling) costs little next to its rows. A block fills one scratch row, which
/// stays in cache while it is consumed.
pub(crate) fn for_each_row<S, T, O>(
    nu: usize,
    init: impl Fn() -> S + Sync,
    fill_row: impl Fn(&mut S, usize, &mut [f32]) -> T + Sync,
    outputs: &mut [O],
    consume: impl Fn(&[f32], &mut O) -> f64 + Sync,
) -> (Vec<f64>, Vec<T>)
where
    T: Send + Default + Clone,
    O: Send,
{
    use rayon::prelude::*;
    let nv = outputs.len();
    assert!(nu > 0 && nv > 0, "bad 2D grid shape");
    let blocks = (rayon::current_num_threads() * 8).max(1);
    let rows_per_task = nv.div_ceil(blocks).max((4096 / nu).max(1));
    let mut consumed = vec![0.0f64; nv];
    let mut results = vec![T::default(); nv];
    outputs
        .par_chunks_mut(rows_per_task)
        .zip(consumed.par_chunks_mut(rows_per_task))
        .zip(results.par_chunks_mut(rows_per_task))
        .enumerate()
        .for_each(|(task, ((outs, sums), res))| {
            let mut state = init();
            let mut scratch = vec![0.0f32; nu];
            for (k, ((out, sum), result)) in outs.iter_mut().zip(sums).zip(res).enumerate() {
                *result = fill_row(&mut state, task * rows_per_task + k, &mut scratch);
                for value in scratch.iter_mut() {
                    *value = sanitize(*value);
                }
                *sum = consume(&scratch, out);
            }
        });
    (consumed, results)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes sampler's stages (`rows_lanes` … `finish_lanes` and
    /// `finish_cells_lanes`), run over blocks
    /// of 16 as the batch queries run them: bit for bit the single samples, on
    /// grids with a sun (long binary searches among faint cells), zero rows,
    /// zero columns, trailing zero cells, a single column and a single row, and
    /// a black grid, for ordinary `ξ`, the ends of [0, 1), and values outside it.
    #[test]
    fn lanes_sampling_equals_single_samples() {
        let mut rng = crate::rng::SplitMix64::new(34);
        let sun = |nu: usize, nv: usize| -> Vec<f32> {
            let mut f: Vec<f32> = (0..nu * nv).map(|k| 0.01 + (k % 7) as f32 * 1e-3).collect();
            f[(nv / 3) * nu + nu / 2] = 1e6;
            f[(nv / 3) * nu + nu / 2 + 1] = 3e5;
            f
        };
        let mut zeros = sun(64, 32);
        for k in 0..64 {
            zeros[5 * 64 + k] = 0.0;
            zeros[k * 32 % (64 * 32)] = 0.0;
        }
        for k in 60..64 {
            for r in 0..32 {
                zeros[r * 64 + k] = 0.0;
            }
        }
        let grids: Vec<(Vec<f32>, usize)> = vec![
            (sun(256, 128), 256),
            (sun(3, 1000), 3),
            (zeros, 64),
            ((0..40).map(|k| (k * k) as f32).collect(), 1),
            ((0..40).map(|k| (k % 3) as f32).collect(), 40),
            (vec![0.0; 12 * 6], 12),
        ];
        let mut xi: Vec<[f32; 2]> = (0..4000)
            .map(|_| [rng.next_f32(), rng.next_f32()])
            .collect();
        for e in [0.0, ONE_MINUS_EPSILON, 1.0, -0.5, 2.0, f32::NAN, 1e-30, 0.5] {
            xi.push([e, rng.next_f32()]);
            xi.push([rng.next_f32(), e]);
            xi.push([e, e]);
        }
        for (f, nu) in grids {
            let d = Distribution2D::new(&f, nu);
            for block in xi.chunks(16) {
                let (mut xi0, mut xi1) = ([0.0f32; 16], [0.0f32; 16]);
                for (j, x) in block.iter().enumerate() {
                    (xi0[j], xi1[j]) = (x[0], x[1]);
                }
                let mut rows = d.rows_lanes(&xi0, &xi1);
                d.prefetch_guides(&rows);
                d.bound_lanes(&mut rows);
                d.prefetch_cdfs(&rows);
                let s = d.finish_lanes(&rows);
                let c = d.finish_cells_lanes(&rows);
                for (j, &x) in block.iter().enumerate() {
                    let single = d.sample_continuous(x);
                    let lane = Sample2D {
                        uv: [s.u[j], s.v[j]],
                        pdf: s.pdf[j],
                        cell: [s.iu[j] as usize, s.iv[j] as usize],
                    };
                    assert_eq!(
                        (lane.uv.map(f32::to_bits), lane.pdf.to_bits(), lane.cell),
                        (
                            single.uv.map(f32::to_bits),
                            single.pdf.to_bits(),
                            single.cell
                        ),
                        "grid {nu} wide, ξ {x:?}"
                    );
                    let single = d.sample_cell(x);
                    let lane = CellSample {
                        cell: [c.cell[0][j] as usize, c.cell[1][j] as usize],
                        offset: [c.offset[0][j], c.offset[1][j]],
                        widths: [c.widths[0][j], c.widths[1][j]],
                    };
                    assert_eq!(
                        (lane.cell, lane.offset.map(f64::to_bits), lane.widths),
                        (single.cell, single.offset.map(f64::to_bits), single.widths),
                        "grid {nu} wide, ξ {x:?}"
                    );
                }
            }
        }
    }

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
        // The edge at cdf = 1/2 sits half a unit above ξ = 0.5 on the 2³² - 1 scale,
        // so ξ = 0.5 ends cell 3; just above it starts cell 4.
        let s = d.sample_continuous(0.5);
        assert!(
            close(s.x, 0.8) && close(s.pdf, 1.25) && s.cell == 3,
            "{s:?}"
        );
        let s = d.sample_continuous(0.500001);
        assert!(close(s.x, 0.8) && close(s.pdf, 2.5) && s.cell == 4, "{s:?}");
        let s = d.sample_continuous(0.75);
        assert!(close(s.x, 0.9) && close(s.pdf, 2.5), "{s:?}");
        let s = d.sample_continuous(ONE_MINUS_EPSILON);
        assert!(close(s.x, 1.0) && s.x < 1.0, "{s:?}");
        // ξ = 1 is outside the contract but must still land in range.
        assert!(d.sample_continuous(1.0).x < 1.0);
    }

    #[test]
    fn guide_table_search_equals_a_plain_scan() {
        // Rows with zero runs, a spike and smooth parts; ξ at and around every edge.
        let mut rng = crate::rng::SplitMix64::new(11);
        for n in [1usize, 2, 3, 5, 8, 31, 64, 100, 257] {
            let f: Vec<f32> = (0..n)
                .map(|i| match rng.next_u64() % 4 {
                    0 => 0.0,
                    1 => 1e6 * (i + 1) as f32,
                    _ => rng.next_f32(),
                })
                .collect();
            let d = Distribution1D::new(&f);
            assert!(d.cdf().windows(2).all(|c| c[0] <= c[1]), "{:?}", d.cdf());
            let view = d.view();
            // Every guide entry is exactly the last cell starting at or before its
            // slice (a smaller one would only slow the search, which the probes
            // below cannot see).
            for (k, &g) in view.guide.iter().enumerate() {
                let start = (k as u64) << view.shift;
                let expected = (0..n).rev().find(|&o| d.cdf()[o] as u64 <= start);
                assert_eq!(Some(g as usize), expected, "n={n} entry {k}");
            }
            let mut probes: Vec<u32> = (0..2000).map(|_| rng.next_u64() as u32).collect();
            for &c in d.cdf() {
                probes.extend([c.saturating_sub(1), c, c.saturating_add(1)]);
            }
            for x in probes.into_iter().map(|x| x.min(CDF_ONE - 1)) {
                let expected = (0..n).rev().find(|&o| d.cdf()[o] <= x).unwrap();
                let (o, lo, hi) = view.segment(view.first_candidate(x), x);
                assert_eq!(o, expected, "n={n} x={x}");
                assert_eq!((lo, hi), (d.cdf()[o], d.cdf()[o + 1]));
                assert!(view.width(expected) > 0);
            }
        }
    }

    #[test]
    fn every_positive_cell_keeps_a_nonzero_width() {
        // 1e-30 next to 1e30: far below 2⁻³² of the mass, still sampled, with a pdf
        // that is the CDF's smallest step rather than 0. Also at the very end of the
        // row, where the forward pass has no room and the backward pass makes it.
        for f in [
            vec![1e-30f32, 1e30, 1e-30, 0.0, 1e-30],
            vec![1e30, 1e-30, 1e-30, 1e-30],
            vec![0.0, 1e-30, 1e30],
        ] {
            let d = Distribution1D::new(&f);
            for (i, &v) in f.iter().enumerate() {
                let width = d.view().width(i);
                assert_eq!(width > 0, v > 0.0, "{f:?} cell {i} width {width}");
            }
            let total: u64 = (0..f.len()).map(|i| d.view().width(i) as u64).sum();
            assert_eq!(total, CDF_ONE as u64);
        }
        // A row with more positive cells than rounding can place.
        let mut f = vec![1e-30f32; 1000];
        f[500] = 1e30;
        let d = Distribution1D::new(&f);
        assert!((0..1000).all(|i| d.view().width(i) > 0));
        assert!(d.pdf(0.5) > 999.0 * 0.99);
    }

    #[test]
    fn pdf_integrates_to_one_exactly_in_cdf_units() {
        let f: Vec<f32> = (0..37).map(|i| ((i * 7919) % 13) as f32).collect();
        let d = Distribution2D::new(&f, 1);
        let sum: f64 = (0..37).map(|v| d.cell_pdf(0, v) as f64).sum::<f64>() / 37.0;
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
        let d = Distribution2D::new(&f[..36], 6);
        let sum: f64 = (0..6)
            .flat_map(|v| (0..6).map(move |u| (u, v)))
            .map(|(u, v)| d.cell_pdf(u, v) as f64)
            .sum::<f64>()
            / 36.0;
        assert!((sum - 1.0).abs() < 1e-6, "{sum}");
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
        let quarter = CDF_ONE / 4 + 1; // round(0.25 · (2³² - 1))
        assert_eq!(
            d.cdf(),
            &[0, quarter, CDF_ONE / 2 + 1, 3 * quarter - 1, CDF_ONE]
        );
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
        assert!(cdf[n - 1] < CDF_ONE && cdf[n] == CDF_ONE);
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
        let (lo, hi) = (d.cdf()[3] as f64, d.cdf()[4] as f64);
        for k in 0..=4096 {
            let xi = ((lo + (hi - lo) * k as f64 / 4096.0) / CDF_ONE as f64) as f32;
            let s = d.sample_continuous(xi.min(ONE_MINUS_EPSILON));
            assert_eq!(d.pdf(s.x), s.pdf, "ξ={xi} x={} cell {}", s.x, s.cell);
        }
        for cell in 0..n {
            for frac in [0.0, 1e-9, 0.5, ONE_MINUS_EPSILON, 1.0] {
                let x = place_in_cell_f64(cell, frac as f64, n);
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
        [if k.is_multiple_of(2) { near_one } else { a[0] }, a[1]]
    }

    #[test]
    fn two_dimensional_zero_function_has_zero_pdf() {
        let d = Distribution2D::new(&[0.0; 8], 4);
        let s = d.sample_continuous([0.3, 0.7]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.uv[0].is_finite() && s.uv[1].is_finite());
    }
}
