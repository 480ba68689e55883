//! Hierarchical sample warping through a pyramid of sums (Clarberg et al. 2005,
//! "Wavelet importance sampling"; Mitsuba 3's `Hierarchical2D`) for the
//! piecewise-constant density `p(u, v) = f[cell] / I` of
//! [`Distribution2D`](crate::distribution::Distribution2D).
//!
//! The grid is padded with zeros to `W × H`, each side separately rounded up to a
//! power of two (a 2:1 map stays 2:1), and summed into coarser levels: both sides
//! halve while both exceed 1, then the longer one alone, down to a single node.
//! Sampling walks from that node to a cell. At a node whose children form a 2×2
//! block,
//!
//! ```text
//! p_left = (a + c) / (a + b + c + d)         a b   (children, v down)
//! ξ0 < p_left ? (left,  ξ0 ← ξ0 / p_left)    c d
//!             : (right, ξ0 ← (ξ0 - p_left) / (1 - p_left))
//! ```
//!
//! then `ξ1` chooses top or bottom inside the chosen column the same way (a 2×1 or
//! 1×2 block uses one coordinate only). What is left of `(ξ0, ξ1)` places the point
//! inside the cell. Each step maps a rectangle of sample space affinely onto a
//! child, so the whole warp is piecewise affine and monotone in each coordinate: a
//! stratified or low-discrepancy set of `ξ` stays stratified among the cells, which
//! is what inversion with row CDFs also achieves but an alias table does not. The
//! warp is invertible step by step ([`Hierarchical2D::invert`]).

use crate::distribution::{
    cell_index, grid_2d_accessors, grid_rows, inverse_or_zero, place_in_cell_f64, sanitize,
    Sample2D, ONE_MINUS_EPSILON,
};
use crate::math::{unit_interval, BELOW_ONE};

/// One step of the walk: from a node of a coarser level to one of its children.
///
/// The children of every node of the coarser level are stored as one block of four
/// `f32` (`a b` over `c d`, v down), blocks in row-major order of their parents, so
/// a step reads one 16-byte block. A step that halves only u uses `a b` (and `c d`
/// are 0); one that halves only v uses `a c`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Step {
    /// Start of this step's blocks in [`Hierarchical2D::nodes`].
    offset: usize,
    /// Parent nodes per row (the coarser level's width, without padding).
    parent_width: usize,
    /// 1 when the step halves u (resp. v), else 0: child `x = (parent x << shift_u) + i`.
    shift_u: u32,
    shift_v: u32,
}

impl Step {
    /// Index in [`Hierarchical2D::nodes`] of the block holding the children of the
    /// parent of `(x, y)`, and the slot of `(x, y)` in it.
    #[inline]
    fn locate(&self, x: usize, y: usize) -> (usize, usize) {
        let (px, py) = (x >> self.shift_u, y >> self.shift_v);
        let slot = (x - (px << self.shift_u)) + 2 * (y - (py << self.shift_v));
        (self.offset + 4 * (py * self.parent_width + px), slot)
    }
}

/// Stratification-preserving sampling of the piecewise-constant density
/// `p(u, v) = f[cell] / I`, `I = Σ f / (nu nv)`, by hierarchical warping.
///
/// Guarantees: a cell with `f = 0` is never sampled (the walk never enters a child
/// of zero sum below a non-zero node); `pdf(sample_continuous(ξ).uv)` equals the
/// returned pdf; the pdf of every cell is `f / I` to f32 rounding, the density
/// [`Distribution2D::cell_pdf`] gives to within its CDFs' resolution;
/// `invert(sample_continuous(ξ).uv) ≈ ξ`.
///
/// Cost: sampling and inversion walk `⌈log2 max(nu, nv)⌉` steps, reading one
/// 16-byte block per step; sampling also loads the next step's four candidate
/// blocks (two cache lines) before choosing, so the cache misses of consecutive
/// levels overlap. Memory: the function (4 bytes per cell, in 2×2 blocks)
/// plus the coarser levels in `f32`, stored only where they cover cells (the
/// power-of-two padding is implicit): about 4/3 bytes per cell when both sides
/// halve, 5.33 bytes per cell in all for a 2:1 map. Building is O(nu nv), with the
/// sums accumulated in `f64` and stored divided by the total, so no sum can
/// overflow `f32`.
///
/// ```
/// use envlight::hierarchical::Hierarchical2D;
/// let h = Hierarchical2D::new(&[1.0, 3.0, 0.0, 4.0], 2);
/// let s = h.sample_continuous([0.5, 0.5]);
/// assert_eq!((s.cell, s.pdf), ([1, 1], 2.0));
/// let xi = h.invert(s.uv);
/// assert!((xi[0] - 0.5).abs() < 1e-6 && (xi[1] - 0.5).abs() < 1e-6);
/// ```
///
/// [`Distribution2D::cell_pdf`]: crate::distribution::Distribution2D::cell_pdf
#[derive(Debug, Clone, PartialEq)]
pub struct Hierarchical2D {
    nu: usize,
    nv: usize,
    /// The walk from the root to the cells (the last step, whose blocks hold the
    /// sanitised function itself).
    steps: Vec<Step>,
    /// All blocks: node sums divided by `Σ f` for the coarser levels, raw function
    /// values for the cells.
    nodes: Vec<f32>,
    /// `I = Σ f / (nu nv)`, summed like [`Distribution2D`](crate::distribution::Distribution2D).
    integral: f64,
}

impl Hierarchical2D {
    /// Builds the pyramid of `f`, given row-major with `nu` values per row.
    /// Negative, NaN and infinite values count as 0. A function with no positive
    /// mass samples uniformly with pdf 0 everywhere.
    ///
    /// # Panics
    /// When `nu == 0`, `f` is empty, or `f.len()` is not a multiple of `nu`.
    pub fn new(f: &[f32], nu: usize) -> Self {
        let nv = grid_rows(f, nu);
        let cells: Vec<f32> = f.iter().map(|&x| sanitize(x)).collect();
        let row_sums: Vec<f64> = cells
            .chunks(nu)
            .map(|row| row.iter().map(|&x| x as f64).sum())
            .collect();
        // The same summation order as Distribution2D, so the integrals agree to the bit.
        let integral = row_sums.iter().map(|&s| s / nu as f64).sum::<f64>() / nv as f64;
        let total: f64 = row_sums.iter().sum();
        let normalise = inverse_or_zero(total);

        // Halvings of each side from the padded cells (W, H) up to the root: both
        // while both exceed 1, then the longer one alone. A 1×1 grid still gets
        // one (trivial) step so the cells have a block.
        let (mut w, mut h) = (nu.next_power_of_two(), nv.next_power_of_two());
        let mut shifts = Vec::new();
        while w > 1 || h > 1 {
            let (su, sv) = ((w > 1) as u32, (h > 1) as u32);
            shifts.push((su, sv));
            (w, h) = (w >> su, h >> sv);
        }
        if shifts.is_empty() {
            shifts.push((0, 0));
        }

        // Levels from the cells up, each only over the nodes that cover cells:
        // `(width, height, f64 sums row-major)`.
        let mut levels: Vec<(usize, usize, Vec<f64>)> =
            vec![(nu, nv, cells.iter().map(|&x| x as f64).collect())];
        for &(su, sv) in &shifts {
            let (fw, fh, finer) = levels.last().expect("starts non-empty");
            let (pw, ph) = (fw.div_ceil(1 << su), fh.div_ceil(1 << sv));
            let mut sums = vec![0.0f64; pw * ph];
            for (y, row) in finer.chunks(*fw).enumerate() {
                for (x, &s) in row.iter().enumerate() {
                    sums[(y >> sv) * pw + (x >> su)] += s;
                }
            }
            levels.push((pw, ph, sums));
        }

        // Blocks, coarse steps first; the cells (raw values) go last.
        let mut steps = Vec::with_capacity(shifts.len());
        let mut nodes = Vec::new();
        for k in (0..shifts.len()).rev() {
            let (su, sv) = shifts[k];
            let (cw, _, ref child) = levels[k];
            let (pw, ph, _) = levels[k + 1];
            let step = Step {
                offset: nodes.len(),
                parent_width: pw,
                shift_u: su,
                shift_v: sv,
            };
            nodes.resize(nodes.len() + 4 * pw * ph, 0.0f32);
            for (y, row) in child.chunks(cw).enumerate() {
                for (x, &s) in row.iter().enumerate() {
                    let (block, slot) = step.locate(x, y);
                    nodes[block + slot] = if k == 0 {
                        cells[y * nu + x]
                    } else {
                        (s * normalise) as f32
                    };
                }
            }
            steps.push(step);
        }
        Self {
            nu,
            nv,
            steps,
            nodes,
            integral,
        }
    }

    grid_2d_accessors!(integral: integral, cell_pdf: cell_pdf);

    /// The (sanitised) function value of cell `[iu, iv]`.
    #[inline]
    pub fn value(&self, iu: usize, iv: usize) -> f32 {
        let cells = self.steps[self.steps.len() - 1];
        let (block, slot) = cells.locate(iu, iv);
        self.nodes[block + slot]
    }

    /// Bytes of sampling data held (function and pyramid).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice()) + std::mem::size_of_val(self.steps.as_slice())
    }

    /// Density of cell `[iu, iv]`: `f[iv][iu] / I`, 0 for a zero function.
    #[inline(always)]
    pub fn cell_pdf(&self, iu: usize, iv: usize) -> f32 {
        if self.integral > 0.0 {
            (self.value(iu, iv) as f64 / self.integral) as f32
        } else {
            0.0
        }
    }

    /// The block `[a, b, c, d]` starting at `index`; zeros past the end (a
    /// speculative load of a child that does not exist).
    #[inline(always)]
    fn raw_block(&self, index: usize) -> [f32; 4] {
        match self.nodes.get(index..index + 4) {
            Some(&[a, b, c, d]) => [a, b, c, d],
            _ => [0.0; 4],
        }
    }

    /// The block `[a, b, c, d]` starting at `index` in `f64`; zeros past the end,
    /// which a walk over a non-zero function never reaches.
    #[inline(always)]
    fn block(&self, index: usize) -> [f64; 4] {
        match self.nodes.get(index..index + 4) {
            Some(&[a, b, c, d]) => [a as f64, b as f64, c as f64, d as f64],
            _ => [0.0; 4],
        }
    }

    /// Maps `ξ ∈ [0, 1)²` to a point with density [`Self::pdf`] by walking the
    /// pyramid from the root (see the module docs). Components outside `[0, 1)` or
    /// NaN are clamped.
    #[inline(always)]
    pub fn sample_continuous(&self, xi: [f32; 2]) -> Sample2D {
        let (mut xi0, mut xi1) = (unit_interval(xi[0]), unit_interval(xi[1]));
        if self.integral <= 0.0 {
            return self.uniform_sample(xi0, xi1);
        }
        let (mut x, mut y) = (0usize, 0usize);
        let mut block = self.raw_block(self.steps[0].offset);
        for (s, step) in self.steps.iter().enumerate() {
            // Load the blocks of all four children for the next step before choosing
            // among them: their addresses are known now, so the (cache-missing)
            // loads of two levels overlap instead of forming one serial chain.
            let (cx, cy) = (x << step.shift_u, y << step.shift_v);
            let candidates = match self.steps.get(s + 1) {
                Some(next) => {
                    let at = |i: usize, j: usize| {
                        self.raw_block(next.offset + 4 * ((cy + j) * next.parent_width + cx + i))
                    };
                    [at(0, 0), at(1, 0), at(0, 1), at(1, 1)]
                }
                None => [[0.0; 4]; 4],
            };
            let [a, b, c, d] = block.map(|v| v as f64);
            let right = split(a + c, b + d, &mut xi0);
            let (top, bottom) = if right { (b, d) } else { (a, c) };
            let down = split(top, bottom, &mut xi1);
            x = cx + right as usize;
            y = cy + down as usize;
            block = candidates[right as usize + 2 * down as usize];
        }
        // Already in range for a non-zero function; keeps a degenerate walk in bounds.
        let (x, y) = (x.min(self.nu - 1), y.min(self.nv - 1));
        Sample2D {
            uv: [
                place_in_cell_f64(x, xi0, self.nu),
                place_in_cell_f64(y, xi1, self.nv),
            ],
            pdf: self.cell_pdf(x, y),
            cell: [x, y],
        }
    }

    /// The zero function's sample: the point `ξ` itself, pdf 0.
    fn uniform_sample(&self, xi0: f64, xi1: f64) -> Sample2D {
        let uv = [
            (xi0 as f32).min(ONE_MINUS_EPSILON),
            (xi1 as f32).min(ONE_MINUS_EPSILON),
        ];
        Sample2D {
            uv,
            pdf: 0.0,
            cell: [cell_index(uv[0], self.nu), cell_index(uv[1], self.nv)],
        }
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `uv`: the
    /// walk run backwards from the cell to the root, each step the affine inverse of
    /// the corresponding rescaling. Points in cells of zero density map to where
    /// their (empty) rectangle of sample space would be.
    #[inline]
    pub fn invert(&self, uv: [f32; 2]) -> [f32; 2] {
        if self.integral <= 0.0 {
            return [unit_interval(uv[0]) as f32, unit_interval(uv[1]) as f32];
        }
        let (mut x, mut y) = (cell_index(uv[0], self.nu), cell_index(uv[1], self.nv));
        let mut xi0 = (unit_interval(uv[0]) * self.nu as f64 - x as f64).clamp(0.0, 1.0);
        let mut xi1 = (unit_interval(uv[1]) * self.nv as f64 - y as f64).clamp(0.0, 1.0);
        for step in self.steps.iter().rev() {
            let (block, slot) = step.locate(x, y);
            let [a, b, c, d] = self.block(block);
            let (right, down) = (slot & 1 == 1, slot >= 2);
            unsplit(a + c, b + d, right, &mut xi0);
            let (top, bottom) = if right { (b, d) } else { (a, c) };
            unsplit(top, bottom, down, &mut xi1);
            (x, y) = (x >> step.shift_u, y >> step.shift_v);
        }
        [(xi0 as f32).min(1.0), (xi1 as f32).min(1.0)]
    }
}

/// Chooses between two children of masses `first` and `second` with `ξ`, rescaling
/// `ξ` to `[0, 1)` within the chosen one; returns whether `second` was chosen.
///
/// A zero child is never chosen while its sibling has mass: with `t = ξ (first +
/// second)`, `first == 0` fails `t < first`, and `second == 0` makes `t = ξ first`,
/// which rounds below `first` for every `ξ < 1`. Both children zero (possible only
/// for the zero function) chooses `first`.
#[inline]
fn split(first: f64, second: f64, xi: &mut f64) -> bool {
    let t = *xi * (first + second);
    let chose_second = t >= first && second > 0.0;
    // Selects rather than branches: the choice is a coin flip for random ξ.
    let (numerator, denominator) = if chose_second {
        (t - first, second)
    } else {
        (t, first)
    };
    let rescaled = numerator / denominator;
    *xi = if denominator > 0.0 {
        rescaled.min(BELOW_ONE)
    } else {
        *xi
    };
    chose_second
}

/// The inverse of [`split`]: maps `ξ` within the chosen child back to the parent.
#[inline]
fn unsplit(first: f64, second: f64, chose_second: bool, xi: &mut f64) {
    let sum = first + second;
    if sum > 0.0 {
        *xi = if chose_second {
            (first + *xi * second) / sum
        } else {
            *xi * first / sum
        };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alias::{test_support, AliasTable2D};
    use crate::distribution::Distribution2D;
    use crate::rng::{xi_2d, SplitMix64};

    /// Significance level of every chi-square test here.
    const ALPHA: f64 = 1e-3;

    const SHAPES: [(usize, usize); 9] = [
        (1, 1),
        (2, 1),
        (1, 2),
        (7, 3),
        (3, 7),
        (64, 32),
        (5, 17),
        (300, 1),
        (1, 33),
    ];

    #[test]
    fn hand_computed_two_by_two() {
        // f = [1 3; 0 4]: left column 1, right 7, so ξ0 = .5 goes right with
        // ξ0 ← (.5 - 1/8)/(7/8) = 3/7; in the right column top 3, bottom 4, so
        // ξ1 = .5 goes down with ξ1 ← (.5 - 3/7)/(4/7) = 1/8.
        let h = Hierarchical2D::new(&[1.0, 3.0, 0.0, 4.0], 2);
        assert_eq!(h.integral(), 2.0);
        let s = h.sample_continuous([0.5, 0.5]);
        assert_eq!((s.cell, s.pdf), ([1, 1], 2.0));
        assert!((s.uv[0] - (1.0 + 3.0 / 7.0) / 2.0).abs() < 1e-6, "{s:?}");
        assert!((s.uv[1] - (1.0 + 1.0 / 8.0) / 2.0).abs() < 1e-6, "{s:?}");
        // ξ0 < 1/8 is the left column, whose bottom cell is empty: always the top.
        let s = h.sample_continuous([0.0625, 0.99]);
        assert_eq!((s.cell, s.pdf), ([0, 0], 0.5));
        assert!(
            (s.uv[0] - 0.25).abs() < 1e-6 && (s.uv[1] - 0.495).abs() < 1e-6,
            "{s:?}"
        );
    }

    #[test]
    fn padding_is_per_axis() {
        // 5×3 pads to 8×4 (not 8×8): steps from the root halve u, then both twice;
        // levels are stored only over the nodes that cover cells (3×2, 2×1 parents).
        let h = Hierarchical2D::new(&[1.0; 15], 5);
        let shape: Vec<_> = h
            .steps
            .iter()
            .map(|s| (s.shift_u, s.shift_v, s.parent_width))
            .collect();
        assert_eq!(shape, [(1, 0, 1), (1, 1, 2), (1, 1, 3)]);
        assert_eq!(h.nodes.len(), 4 + 4 * 2 + 4 * 3 * 2);
        // 4096×2048: one u-only step from the root, then eleven 2×2 steps.
        let h = Hierarchical2D::new(&vec![1.0; 4096 * 2048], 4096);
        assert_eq!(h.steps.len(), 12);
        assert_eq!((h.steps[0].shift_u, h.steps[0].shift_v), (1, 0));
        let per_cell = h.memory_bytes() as f64 / (4096.0 * 2048.0);
        assert!(per_cell < 5.34, "{per_cell}");
        // A 1×1 grid has one trivial step.
        let h = Hierarchical2D::new(&[2.0], 1);
        assert_eq!(h.steps.len(), 1);
        assert_eq!(h.value(0, 0), 2.0);
    }

    #[test]
    fn pdf_matches_inversion_sampler_cell_by_cell() {
        let mut rng = SplitMix64::new(21);
        for &(nu, nv) in &SHAPES {
            let f = test_support::random_grid(&mut rng, nu * nv, 0.3);
            let h = Hierarchical2D::new(&f, nu);
            test_support::assert_pdf_is_f_over_integral(
                &f,
                nu,
                h.integral(),
                |iu, iv| h.cell_pdf(iu, iv),
                |uv| h.pdf(uv),
            );
        }
    }

    /// Counts per cell, checking pdf consistency and the cell of each sample.
    fn cell_counts(h: &Hierarchical2D, xis: impl Iterator<Item = [f32; 2]>) -> Vec<u64> {
        let mut counts = vec![0u64; h.nu * h.nv];
        for xi in xis {
            let s = h.sample_continuous(xi);
            assert_eq!(h.pdf(s.uv), s.pdf);
            assert_eq!(
                [cell_index(s.uv[0], h.nu), cell_index(s.uv[1], h.nv)],
                s.cell
            );
            counts[s.cell[1] * h.nu + s.cell[0]] += 1;
        }
        counts
    }

    #[test]
    fn chi_square_fit_on_random_grids() {
        // α = 1e-3, N = 300 000 per shape, ξ = xi_2d(40 + shape index, k).
        let mut rng = SplitMix64::new(17);
        for (i, &(nu, nv)) in SHAPES.iter().enumerate() {
            let f = test_support::random_grid(&mut rng, nu * nv, 0.2);
            let h = Hierarchical2D::new(&f, nu);
            let n = 300_000;
            let counts = cell_counts(&h, (0..n).map(|k| xi_2d(40 + i as u64, k)));
            test_support::assert_counts_fit(&counts, &f, n, &format!("{nu}x{nv}"));
        }
    }

    #[test]
    fn chi_square_rejects_a_wrong_pdf() {
        // Samples of f tested against f with one cell 10 % heavier (α = 1e-3,
        // N = 300 000, seed 9): the harness must reject.
        let mut rng = SplitMix64::new(2);
        let f = test_support::random_grid(&mut rng, 96, 0.0);
        let h = Hierarchical2D::new(&f, 12);
        let n = 300_000;
        let counts = cell_counts(&h, (0..n).map(|k| xi_2d(9, k)));
        test_support::assert_rejects_hottest_raised(&counts, &f, n);
    }

    #[test]
    fn in_cell_offsets_are_uniform() {
        // Within one cell of a 3×2 grid, the point must be uniform: a 4×4 histogram
        // of the in-cell position of samples that fall in the heaviest cell.
        let h = Hierarchical2D::new(&[1.0, 2.0, 3.0, 0.5, 6.0, 1.0], 3);
        let mut counts = vec![0u64; 16];
        let mut n = 0;
        for k in 0..200_000 {
            let s = h.sample_continuous(xi_2d(3, k));
            if s.cell == [1, 1] {
                let du = s.uv[0] * 3.0 - 1.0;
                let dv = s.uv[1] * 2.0 - 1.0;
                counts[(dv * 4.0) as usize * 4 + (du * 4.0) as usize] += 1;
                n += 1;
            }
        }
        let (_, _, p) = test_support::chi_square(&counts, &[n as f64 / 16.0; 16]);
        assert!(p > ALPHA, "p = {p}");
    }

    #[test]
    fn invert_undoes_sample() {
        let mut rng = SplitMix64::new(8);
        for &(nu, nv) in &SHAPES {
            let f = test_support::random_grid(&mut rng, nu * nv, 0.3);
            let h = Hierarchical2D::new(&f, nu);
            for k in 0..2000 {
                let xi = xi_2d(6, k);
                let s = h.sample_continuous(xi);
                let back = h.invert(s.uv);
                let err = (back[0] - xi[0]).abs().max((back[1] - xi[1]).abs());
                assert!(err < 2e-5, "{nu}x{nv}: ξ {xi:?} → {s:?} → {back:?}");
            }
        }
        // A mismatched inverse (another function's pyramid) is caught by the same
        // check: the worst error is far above the tolerance.
        let f = test_support::random_grid(&mut rng, 64, 0.0);
        let (h, other) = (
            Hierarchical2D::new(&f, 8),
            Hierarchical2D::new(&[1.0; 64], 8),
        );
        let worst = (0..2000)
            .map(|k| {
                let xi = xi_2d(6, k);
                let back = other.invert(h.sample_continuous(xi).uv);
                (back[0] - xi[0]).abs().max((back[1] - xi[1]).abs())
            })
            .fold(0.0f32, f32::max);
        assert!(worst > 1e-2, "{worst}");
    }

    #[test]
    fn warp_is_monotone_in_each_coordinate() {
        // Two ξ0 with the same ξ1 share their path until the first level where their
        // columns differ, so u is non-decreasing in ξ0; likewise v in ξ1. (This is
        // what keeps stratified points stratified.)
        let mut rng = SplitMix64::new(30);
        let f = test_support::random_grid(&mut rng, 16 * 12, 0.3);
        let h = Hierarchical2D::new(&f, 16);
        for j in 0..25 {
            let fixed = (j as f32 + 0.5) / 25.0;
            let (mut last_u, mut last_v) = (0.0f32, 0.0f32);
            for i in 0..2000 {
                let moving = (i as f32 + 0.5) / 2000.0;
                let u = h.sample_continuous([moving, fixed]).uv[0];
                let v = h.sample_continuous([fixed, moving]).uv[1];
                assert!(u >= last_u && v >= last_v, "row {j}, step {i}");
                (last_u, last_v) = (u, v);
            }
        }
    }

    #[test]
    fn zero_children_are_never_entered() {
        let mut f = vec![0.0f32; 13 * 6];
        f[0] = 1e-20;
        f[13 * 5 + 12] = 1e20;
        f[40] = 3.0;
        let h = Hierarchical2D::new(&f, 13);
        for k in 0..50_000 {
            let s = h.sample_continuous(xi_2d(5, k));
            assert!(s.pdf > 0.0, "{s:?}");
        }
        for &a in &[
            0.0,
            1e-30,
            0.5,
            ONE_MINUS_EPSILON,
            1.0,
            -2.0,
            f32::NAN,
            f32::INFINITY,
        ] {
            for &b in &[0.0, 0.5, ONE_MINUS_EPSILON, 1.0, f32::NAN] {
                let s = h.sample_continuous([a, b]);
                assert!(
                    s.pdf > 0.0 && s.uv.iter().all(|x| (0.0..1.0).contains(x)),
                    "{s:?}"
                );
                let back = h.invert(s.uv);
                assert!(back.iter().all(|x| (0.0..=1.0).contains(x)));
            }
        }
    }

    #[test]
    fn degenerate_inputs() {
        let h = Hierarchical2D::new(&[0.0, f32::NAN, -1.0, f32::NEG_INFINITY, 0.0, 0.0], 3);
        test_support::assert_zero_function(
            h.integral(),
            |xi| h.sample_continuous(xi),
            |uv| h.pdf(uv),
            |uv| h.invert(uv),
        );
        let h = Hierarchical2D::new(&[5.0], 1);
        let s = h.sample_continuous([0.25, 0.75]);
        assert_eq!((s.cell, s.pdf, s.uv), ([0, 0], 1.0, [0.25, 0.75]));
        assert_eq!(h.invert([0.25, 0.75]), [0.25, 0.75]);
        let h = Hierarchical2D::new(&[f32::MAX, f32::MAX, 0.0, f32::MAX, f32::MAX, 1.0], 2);
        let s = h.sample_continuous([0.9, 0.9]);
        assert!(s.pdf > 0.0 && s.pdf.is_finite(), "{s:?}");
    }

    /// RMSE over `seeds` of the estimate of `∫ g` from `n × n` jittered points
    /// (one uniform point per stratum, seeded by `seed`), with points drawn by
    /// `sample`; or from independent uniform points when `jitter` is false.
    fn rmse(
        sample: &dyn Fn([f32; 2]) -> Sample2D,
        g: &dyn Fn(f64, f64) -> f64,
        exact: f64,
        n: usize,
        seeds: u64,
        jitter: bool,
    ) -> f64 {
        let mut sum_sq = 0.0;
        for seed in 0..seeds {
            let mut rng = SplitMix64::new(1000 + seed);
            let mut estimate = 0.0;
            for j in 0..n {
                for i in 0..n {
                    let (a, b) = (rng.next_f64(), rng.next_f64());
                    let xi = if jitter {
                        [
                            ((i as f64 + a) / n as f64) as f32,
                            ((j as f64 + b) / n as f64) as f32,
                        ]
                    } else {
                        [a as f32, b as f32]
                    };
                    let s = sample(xi);
                    estimate += g(s.uv[0] as f64, s.uv[1] as f64) / s.pdf as f64;
                }
            }
            estimate /= (n * n) as f64;
            sum_sq += (estimate - exact).powi(2);
        }
        (sum_sq / seeds as f64).sqrt()
    }

    #[test]
    fn stratification_survives_the_warp() {
        // A smooth positive density on 64×32 cells and a smooth integrand with
        // ∫∫ e^u (1 + v²) du dv = (e - 1)·4/3. 16×16 jittered ξ, 50 seeds.
        let (nu, nv) = (64, 32);
        let f: Vec<f32> = (0..nu * nv)
            .map(|k| {
                let (u, v) = (
                    ((k % nu) as f64 + 0.5) / nu as f64,
                    ((k / nu) as f64 + 0.5) / nv as f64,
                );
                (1.5 + (2.0 * std::f64::consts::PI * u).sin() * (std::f64::consts::PI * v).sin())
                    as f32
            })
            .collect();
        let g = |u: f64, v: f64| u.exp() * (1.0 + v * v);
        let exact = (std::f64::consts::E - 1.0) * 4.0 / 3.0;
        let h = Hierarchical2D::new(&f, nu);
        let a = AliasTable2D::new(&f, nu);
        let d = Distribution2D::new(&f, nu);
        let (n, seeds) = (16, 50);
        let hier = rmse(&|x| h.sample_continuous(x), &g, exact, n, seeds, true);
        let alias = rmse(&|x| a.sample_continuous(x), &g, exact, n, seeds, true);
        let inversion = rmse(&|x| d.sample_continuous(x), &g, exact, n, seeds, true);
        println!("RMSE, 256 jittered ξ: hierarchical {hier:.2e}, inversion {inversion:.2e}, alias {alias:.2e}");
        assert!(hier < 0.5 * alias, "hierarchical {hier} vs alias {alias}");
        // The check measures stratification: with independent ξ the hierarchical
        // warp has nothing to preserve and does not beat the alias table clearly.
        let hier_iid = rmse(&|x| h.sample_continuous(x), &g, exact, n, seeds, false);
        let alias_iid = rmse(&|x| a.sample_continuous(x), &g, exact, n, seeds, false);
        println!("RMSE, 256 independent ξ: hierarchical {hier_iid:.2e}, alias {alias_iid:.2e}");
        assert!(hier_iid > 0.5 * alias_iid, "{hier_iid} vs {alias_iid}");
    }

    /// Per-sample cost against the inversion sampler on random grids of 4096×2048
    /// (out of cache) and 64×32 (in cache), with ξ from `xi_2d` (no coherence).
    /// Run: `cargo test --release -p envlight --lib hierarchical::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_against_inversion() {
        for (nu, nv, f) in test_support::timing_grids() {
            let start = std::time::Instant::now();
            let h = Hierarchical2D::new(&f, nu);
            let build = start.elapsed();
            let inversion = Distribution2D::new(&f, nu);
            let time = test_support::timer_against_inversion(format!("{nu}x{nv}"), &inversion);
            time("hierarchical sample", &|x| h.sample_continuous(x).uv[0]);
            time("inversion invert", &|x| inversion.invert(x)[0]);
            time("hierarchical invert", &|x| h.invert(x)[0]);
            time("inversion pdf", &|x| inversion.pdf(x));
            time("hierarchical pdf", &|x| h.pdf(x));
            println!(
                "{nu}x{nv} build {build:?}; bytes/cell: hierarchical {:.2}, inversion {:.2}",
                h.memory_bytes() as f64 / (nu * nv) as f64,
                inversion.memory_bytes() as f64 / (nu * nv) as f64
            );
        }
    }
}
