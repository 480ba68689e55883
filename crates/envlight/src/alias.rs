//! Vose's alias method over the cells of a piecewise-constant density on `[0, 1]²`:
//! O(1) sampling of the same density as [`Distribution2D`].
//!
//! The `n = nu nv` cells are first scaled to `q_i = n f_i / Σ f` (mean 1). The table
//! has one *slot* per cell; slot `i` keeps cell `i` with probability `T_i` and
//! otherwise yields its alias `a_i`. Vose's construction pairs each light cell
//! (`q < 1`) with a heavy one (`q ≥ 1`) that donates the missing `1 - q`, so every
//! slot carries exactly `1/n` of the mass and
//!
//! ```text
//! P(cell j) = (T_j + Σ_{i : a_i = j} (1 - T_i)) / n = f_j / Σ f.
//! ```
//!
//! A sample draws a slot uniformly, makes the keep-or-alias test, and places the
//! point uniformly inside the chosen cell, so `p(u, v) = f[cell] / I` with
//! `I = Σ f / (nu nv)`: the density of [`Distribution2D`], which matches it to
//! within its CDFs' 2⁻³² resolution.
//!
//! **Trade-off.** Sampling is O(1) (one table entry and one function value are read),
//! like inversion with its guide tables, but the map from `ξ` to the point is
//! scrambled: nearby `ξ` land in unrelated cells, so stratified or low-discrepancy
//! `ξ` lose their advantage, and there is no inverse.
//!
//! [`Distribution2D`]: crate::distribution::Distribution2D

use crate::distribution::{
    grid_2d_accessors, grid_rows, inverse_or_zero, place_in_cell_f64, sanitize, Sample2D,
};

/// `2⁴⁸`: the two 24-bit halves of `ξ` form a 48-bit fixed-point number.
const TWO_POW_48: f64 = (1u64 << 48) as f64;

/// One slot of the table: keep the slot's own cell when the 48-bit fraction is below
/// `threshold · 2⁴⁸`, otherwise take `alias`. Kept together so a sample reads one
/// cache line for the decision.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    threshold: f32,
    alias: u32,
}

/// O(1) sampling of the piecewise-constant density `p(u, v) = f[cell] / I` over an
/// `nu × nv` grid by Vose's alias method.
///
/// Guarantees: a cell with `f = 0` is never sampled (its threshold is 0 and no slot
/// aliases to it); `pdf(sample_continuous(ξ).uv)` equals the returned pdf; the pdf of
/// every cell is `f / I` to f32 rounding, the density [`Distribution2D::cell_pdf`]
/// gives to within its CDFs' resolution.
///
/// Cost: sampling O(1) (the slot and the chosen cell's value: two memory reads);
/// build O(n) time with `16 n` bytes of temporary memory. Memory: 12 bytes per cell
/// (the function, a 4-byte threshold and a 4-byte alias index).
///
/// It breaks stratification (nearby `ξ` do not map to nearby points) and has no
/// inverse; use [`Distribution2D`] or [`Hierarchical2D`] when either matters.
///
/// ```
/// use envlight::alias::AliasTable2D;
/// let table = AliasTable2D::new(&[1.0, 0.0, 3.0, 4.0], 2);
/// let s = table.sample_continuous([0.3, 0.8]);
/// assert!(s.pdf > 0.0 && s.cell != [1, 0]);
/// assert_eq!(table.pdf(s.uv), s.pdf);
/// ```
///
/// [`Distribution2D`]: crate::distribution::Distribution2D
/// [`Distribution2D::cell_pdf`]: crate::distribution::Distribution2D::cell_pdf
/// [`Hierarchical2D`]: crate::hierarchical::Hierarchical2D
#[derive(Debug, Clone, PartialEq)]
pub struct AliasTable2D {
    nu: usize,
    nv: usize,
    /// `f[v * nu + u]`, sanitised.
    func: Vec<f32>,
    slots: Vec<Slot>,
    /// `I = Σ f / (nu nv)`, summed like [`Distribution2D`](crate::distribution::Distribution2D).
    integral: f64,
    /// `1 / I`, or 0 for a zero function (so pdfs come out 0).
    inv_integral: f64,
    /// Bits of the leftover fraction given to the offset along u (the rest go to v).
    offset_bits: u32,
}

impl AliasTable2D {
    /// Builds the table of `f`, given row-major with `nu` values per row, in O(n).
    /// Negative, NaN and infinite values count as 0. A function with no positive
    /// mass gives a table that samples uniformly with pdf 0 everywhere.
    ///
    /// # Panics
    /// When `nu == 0`, `f` is empty, `f.len()` is not a multiple of `nu`, or there
    /// are more than `u32::MAX` cells.
    pub fn new(f: &[f32], nu: usize) -> Self {
        let nv = grid_rows(f, nu);
        assert!(
            f.len() <= u32::MAX as usize,
            "too many cells for an alias table"
        );
        let n = f.len();
        let func: Vec<f32> = f.iter().map(|&x| sanitize(x)).collect();
        // The same summation order as Distribution2D, so the integrals agree to the bit.
        let integral = func
            .chunks(nu)
            .map(|row| row.iter().map(|&x| x as f64).sum::<f64>() / nu as f64)
            .sum::<f64>()
            / nv as f64;
        let total = integral * n as f64;
        let slots = if total > 0.0 && total.is_finite() {
            build_slots(&func, total)
        } else {
            (0..n as u32)
                .map(|i| Slot {
                    threshold: 1.0,
                    alias: i,
                })
                .collect()
        };
        // A 48-bit ξ spends about log2(n) bits on the slot; split what is left
        // evenly between the two in-cell offsets.
        let slot_bits = usize::BITS - (n - 1).leading_zeros();
        let offset_bits = ((48 - slot_bits) / 2).clamp(1, 24);
        Self {
            nu,
            nv,
            func,
            slots,
            integral,
            inv_integral: inverse_or_zero(integral),
            offset_bits,
        }
    }

    grid_2d_accessors!(
        integral: integral,
        cell_pdf: cell_pdf,
        /// Maps `ξ ∈ [0, 1)²` to a point with density [`Self::pdf`] in O(1).
        ///
        /// The two 24-bit halves `⌊2²⁴ ξ0⌋, ⌊2²⁴ ξ1⌋` form a 48-bit fraction `B`
        /// (ξ0 the high half). `B n` splits, exactly, into the slot (its integer part)
        /// and a 48-bit fraction that makes the keep-or-alias test; the fraction left
        /// over from that test, rescaled to `[0, 1)`, gives the offset along u (its top
        /// bits) and along v (the rest). Components outside `[0, 1)` or NaN are clamped.
        sample_continuous,
    );

    /// The (sanitised) function, row-major.
    #[inline]
    pub fn func(&self) -> &[f32] {
        &self.func
    }

    /// The slots as `(threshold, alias)`, slot `i` keeping cell `i` when the test's
    /// fraction is below `threshold · 2⁴⁸` (for [`crate::gpu`]'s export).
    pub(crate) fn slots(&self) -> impl ExactSizeIterator<Item = (f32, u32)> + '_ {
        self.slots.iter().map(|s| (s.threshold, s.alias))
    }

    /// `1 / I`, or 0 for a zero function.
    #[inline]
    pub(crate) fn inv_integral(&self) -> f64 {
        self.inv_integral
    }

    /// Bits of the leftover fraction that place the point along u.
    #[inline]
    pub(crate) fn offset_bits(&self) -> u32 {
        self.offset_bits
    }

    /// Bytes of sampling data held (function and table).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.func.as_slice()) + std::mem::size_of_val(self.slots.as_slice())
    }

    /// Density of cell `[iu, iv]`: `f[iv][iu] / I`, 0 for a zero function.
    #[inline(always)]
    pub fn cell_pdf(&self, iu: usize, iv: usize) -> f32 {
        self.index_pdf(iv * self.nu + iu)
    }

    /// Starts fetching the value [`Self::cell_pdf`] of cell `[iu, iv]` will read.
    /// A hint: any cell, even outside the grid, is harmless.
    #[inline(always)]
    pub(crate) fn prefetch_cell(&self, iu: usize, iv: usize) {
        let at = iv.wrapping_mul(self.nu).wrapping_add(iu);
        crate::math::prefetch_ptr(self.func.as_ptr().wrapping_add(at));
    }

    #[inline(always)]
    fn index_pdf(&self, index: usize) -> f32 {
        self.value_pdf(self.func[index])
    }

    /// `value / I` for a cell's (sanitised) function value, 0 for a zero function.
    #[inline(always)]
    fn value_pdf(&self, value: f32) -> f32 {
        (value as f64 * self.inv_integral) as f32
    }

    /// [`Self::sample_continuous`], telling `hint` the centre of the chosen cell as
    /// soon as the table has named it, before the point is placed (see
    /// [`Distribution2D::sample_continuous_hinted`]).
    ///
    /// [`Distribution2D::sample_continuous_hinted`]: crate::distribution::Distribution2D::sample_continuous_hinted
    #[inline(always)]
    pub fn sample_continuous_hinted(&self, xi: [f32; 2], hint: impl FnOnce([f32; 2])) -> Sample2D {
        let bits = (fixed_24(xi[0]) << 24) | fixed_24(xi[1]);
        let scaled = bits as u128 * self.slots.len() as u128;
        let slot_index = (scaled >> 48) as usize;
        let fraction = (scaled as u64 & ((1u64 << 48) - 1)) as f64;
        let slot = self.slots[slot_index];
        let keep = slot.threshold as f64 * TWO_POW_48;
        // Both sides are exact in f64 (a 48-bit integer; an f32 times 2⁴⁸), so the
        // test keeps exactly the threshold's share of the slot.
        // Selects rather than branches (the test goes either way at random), and
        // one division for both cases.
        let kept = fraction < keep;
        let index = if kept {
            slot_index
        } else {
            slot.alias as usize
        };
        let (above, span) = if kept {
            (fraction, keep)
        } else {
            (fraction - keep, TWO_POW_48 - keep)
        };
        let leftover = above / span;
        let split = (1u64 << self.offset_bits) as f64;
        let scaled_leftover = leftover * split;
        // Truncation is the floor here (the value is in [0, 2²⁴)); f64::floor is a
        // library call on the x86-64 baseline.
        let coarse = scaled_leftover as u32 as f64;
        let du = coarse / split;
        let dv = (scaled_leftover - coarse).min(crate::math::BELOW_ONE);
        // 32-bit division (the table has at most u32::MAX cells) is the cheaper one.
        let (iv, iu) = (
            (index as u32 / self.nu as u32) as usize,
            (index as u32 % self.nu as u32) as usize,
        );
        hint([
            (iu as f32 + 0.5) / self.nu as f32,
            (iv as f32 + 0.5) / self.nv as f32,
        ]);
        Sample2D {
            uv: [
                place_in_cell_f64(iu, du, self.nu),
                place_in_cell_f64(iv, dv, self.nv),
            ],
            pdf: self.index_pdf(index),
            cell: [iu, iv],
        }
    }
}

/// Vose's pairing, the one construction behind both alias tables (this module's,
/// and the product sampler's exact one in fixed point): `units[i]` is cell `i`'s
/// mass scaled so that a slot holds `capacity`. Cells short of `capacity` (in
/// index order, the last first) are each paired with a cell holding at least
/// `capacity`, which gives what they lack: `pair(short, its units, giver)` is
/// called once per short cell paired, and the giver keeps
/// `(giver + short) - capacity`, moving to the short cells when that falls below
/// `capacity`. Returns the cells left unpaired: `(full, short)`. In exact
/// arithmetic every full cell then holds exactly `capacity` and no short cell is
/// left; in floating point a few may be, within rounding of `capacity`.
pub(crate) fn vose_pairing<U>(
    units: &mut [U],
    capacity: U,
    mut pair: impl FnMut(u32, U, u32),
) -> (Vec<u32>, Vec<u32>)
where
    U: Copy + PartialOrd + std::ops::Add<Output = U> + std::ops::Sub<Output = U>,
{
    let (mut short, mut full): (Vec<u32>, Vec<u32>) =
        (0..units.len() as u32).partition(|&i| units[i as usize] < capacity);
    while let (Some(&s), Some(&g)) = (short.last(), full.last()) {
        short.pop();
        let (su, gu) = (s as usize, g as usize);
        pair(s, units[su], g);
        // The giver holds at least `capacity`, so what it keeps is never negative
        // (in floating point, `(a + b) - c` with `a ≥ c` and `b ≥ 0` rounds to
        // at least 0).
        let rest = (units[gu] + units[su]) - capacity;
        units[gu] = rest;
        if rest < capacity {
            full.pop();
            short.push(g);
        }
    }
    (full, short)
}

/// Vose's construction for a function with total `Σ f = total > 0`.
fn build_slots(func: &[f32], total: f64) -> Vec<Slot> {
    let n = func.len();
    let scale = n as f64 / total;
    let mut q: Vec<f64> = func.iter().map(|&x| x as f64 * scale).collect();
    // Slots are drawn uniformly at random: the table most in need of large pages.
    let mut slots = Vec::with_capacity(n);
    crate::math::advise_huge_pages(slots.spare_capacity_mut());
    slots.resize(
        n,
        Slot {
            threshold: 1.0,
            alias: 0,
        },
    );
    let (heavy, light) = vose_pairing(&mut q, 1.0, |l, ql, g| {
        slots[l as usize] = Slot {
            threshold: ql as f32,
            alias: g,
        };
    });
    // Any cell with mass: the alias of last resort for a zero cell left over when
    // rounding exhausts the heavy list first.
    let fallback = func.iter().position(|&x| x > 0.0).unwrap_or(0) as u32;
    for &g in &heavy {
        slots[g as usize] = Slot {
            threshold: 1.0,
            alias: g,
        };
    }
    // Only rounding leaves light cells here, each with q within n·ε of 1.
    for &l in &light {
        slots[l as usize] = if func[l as usize] > 0.0 {
            Slot {
                threshold: 1.0,
                alias: l,
            }
        } else {
            Slot {
                threshold: 0.0,
                alias: fallback,
            }
        };
    }
    slots
}

/// `⌊2²⁴ ξ⌋` clamped to `[0, 2²⁴)`; NaN gives 0.
#[inline(always)]
fn fixed_24(xi: f32) -> u64 {
    // Scaling by a power of two is exact; `as` saturates and maps NaN to 0.
    ((xi * (1u32 << 24) as f32) as u32).min((1 << 24) - 1) as u64
}

/// Test helpers shared by the sampler tests of this crate: random grids, a
/// chi-square goodness-of-fit test and a per-call timer.
#[cfg(test)]
pub(crate) mod test_support {
    use crate::rng::SplitMix64;
    use statrs::distribution::{ChiSquared, ContinuousCDF};

    /// Random values over four decades, a `zero_fraction` of them 0, never all 0.
    pub(crate) fn random_grid(rng: &mut SplitMix64, n: usize, zero_fraction: f64) -> Vec<f32> {
        let mut f: Vec<f32> = (0..n)
            .map(|_| {
                if rng.next_f64() < zero_fraction {
                    0.0
                } else {
                    10f32.powf(4.0 * rng.next_f32() - 2.0)
                }
            })
            .collect();
        if f.iter().all(|&x| x == 0.0) {
            f[n / 2] = 1.0;
        }
        f
    }

    /// Checks a sampler's cell pdfs against `f / I` to f32 rounding, and the
    /// inversion sampler's against the same to its CDFs' resolution (each edge is
    /// rounded by at most half a unit, so a cell of widths `wu`, `wv` is within
    /// `1/wu + 1/wv` relative); `pdf` at each cell centre must be the cell pdf, and
    /// the sampler's `integral` the inversion sampler's, to the bit.
    pub(crate) fn assert_pdf_is_f_over_integral(
        f: &[f32],
        nu: usize,
        integral: f64,
        cell_pdf: impl Fn(usize, usize) -> f32,
        pdf: impl Fn([f32; 2]) -> f32,
    ) {
        let nv = f.len() / nu;
        let inversion = crate::distribution::Distribution2D::new(f, nu);
        assert_eq!(integral, inversion.integral());
        for iv in 0..nv {
            for iu in 0..nu {
                let exact = (f[iv * nu + iu] as f64 / inversion.integral()) as f32;
                let mine = cell_pdf(iu, iv);
                assert!((mine - exact).abs() <= 1e-6 * exact, "{mine} vs {exact}");
                let (row, marginal) = (inversion.row_cdf(iv), inversion.marginal().cdf());
                let wu = (row[iu + 1] - row[iu]) as f32;
                let wv = (marginal[iv + 1] - marginal[iv]) as f32;
                let bound = (1.0 / wu + 1.0 / wv + 1e-6) * exact;
                let theirs = inversion.cell_pdf(iu, iv);
                assert!(
                    theirs == exact || (theirs - exact).abs() <= bound,
                    "{theirs} vs {exact}"
                );
                let uv = [(iu as f32 + 0.5) / nu as f32, (iv as f32 + 0.5) / nv as f32];
                assert_eq!(pdf(uv), mine);
            }
        }
    }

    /// Pearson's statistic of `observed` counts against `expected` counts, pooling
    /// bins with an expected count below 5 (samples in a bin of expected count 0
    /// make the p-value 0). Returns `(statistic, degrees of freedom, p-value)`.
    pub(crate) fn chi_square(observed: &[u64], expected: &[f64]) -> (f64, usize, f64) {
        assert_eq!(observed.len(), expected.len());
        assert!(
            expected.iter().all(|e| e.is_finite() && *e >= 0.0),
            "bad expected counts"
        );
        let mut stat = 0.0;
        let mut bins = 0usize;
        let (mut pooled_obs, mut pooled_exp) = (0.0f64, 0.0f64);
        for (&o, &e) in observed.iter().zip(expected) {
            if e <= 0.0 {
                if o > 0 {
                    return (f64::INFINITY, 0, 0.0);
                }
            } else if e < 5.0 {
                pooled_obs += o as f64;
                pooled_exp += e;
            } else {
                stat += (o as f64 - e).powi(2) / e;
                bins += 1;
            }
        }
        if pooled_exp > 0.0 {
            stat += (pooled_obs - pooled_exp).powi(2) / pooled_exp;
            bins += 1;
        }
        let dof = bins.saturating_sub(1).max(1);
        let p = 1.0 - ChiSquared::new(dof as f64).unwrap().cdf(stat);
        (stat, dof, p)
    }

    /// The counts `n` samples of a density `∝ f` are expected to put in each cell.
    pub(crate) fn expected_counts(f: &[f32], n: u64) -> Vec<f64> {
        let total: f64 = f.iter().map(|&x| x as f64).sum();
        f.iter().map(|&x| x as f64 / total * n as f64).collect()
    }

    /// Asserts that `counts` of `n` samples fit the density `∝ f` (χ² at α = 1e-3).
    pub(crate) fn assert_counts_fit(counts: &[u64], f: &[f32], n: u64, what: &str) {
        let (stat, dof, p) = chi_square(counts, &expected_counts(f, n));
        assert!(p > 1e-3, "{what}: chi2 {stat} dof {dof} p {p}");
    }

    /// Asserts that the same test rejects `counts` of `n` samples of `∝ f` against
    /// a wrong density: `f` with its largest value 10 % higher.
    pub(crate) fn assert_rejects_hottest_raised(counts: &[u64], f: &[f32], n: u64) {
        let mut wrong = f.to_vec();
        let hot = (0..wrong.len())
            .max_by(|&a, &b| wrong[a].total_cmp(&wrong[b]))
            .unwrap();
        wrong[hot] *= 1.1;
        let (_, _, p) = chi_square(counts, &expected_counts(&wrong, n));
        assert!(
            p < 1e-3,
            "a 10 % error in the hottest cell went unnoticed (p = {p})"
        );
    }

    /// What a sampler of a function with no positive mass must do, given its
    /// integral and queries: integral 0, finite samples of pdf 0, pdf 0
    /// everywhere and finite inverses.
    pub(crate) fn assert_zero_function(
        integral: f64,
        sample: impl Fn([f32; 2]) -> crate::distribution::Sample2D,
        pdf: impl Fn([f32; 2]) -> f32,
        invert: impl Fn([f32; 2]) -> [f32; 2],
    ) {
        assert_eq!(integral, 0.0);
        let s = sample([0.3, 0.7]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.uv.iter().all(|x| x.is_finite()));
        assert_eq!(pdf([0.5, 0.5]), 0.0);
        assert!(invert([0.2, 0.4]).iter().all(|x| x.is_finite()));
    }

    /// The timing tests' grids as `(nu, nv, f)`: random values (none 0) on
    /// 4096×2048 cells (out of cache) and 64×32 (in cache).
    pub(crate) fn timing_grids() -> impl Iterator<Item = (usize, usize, Vec<f32>)> {
        [(4096, 2048), (64, 32)].into_iter().map(|(nu, nv)| {
            let mut rng = SplitMix64::new(1);
            (nu, nv, random_grid(&mut rng, nu * nv, 0.0))
        })
    }

    /// For the timing tests against the inversion sampler: times `inversion`'s
    /// sampling over 2 000 000 counter-based ξ (`xi_2d`, no coherence) and returns
    /// `time(name, run)`, which times `run` over the same ξ, labelled `{grid} {name}`.
    pub(crate) fn timer_against_inversion(
        grid: String,
        inversion: &crate::distribution::Distribution2D,
    ) -> impl Fn(&str, &dyn Fn([f32; 2]) -> f32) {
        let xi: Vec<[f32; 2]> = (0..2_000_000).map(|k| crate::rng::xi_2d(2, k)).collect();
        let time = move |name: &str, run: &dyn Fn([f32; 2]) -> f32| {
            time_per_call(&format!("{grid} {name}"), &xi, run)
        };
        time("inversion sample", &|x| {
            inversion.sample_continuous(x).uv[0]
        });
        time
    }

    /// Nanoseconds this thread has spent on a CPU (Linux `schedstat`), so timings
    /// on a loaded machine are not inflated by time spent descheduled; `None`
    /// where unavailable.
    fn on_cpu_ns() -> Option<u64> {
        let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
        text.split_whitespace().next()?.parse().ok()
    }

    /// Runs `run` over `inputs` and prints the mean time per call, on-CPU where
    /// the OS reports it (wall clock otherwise).
    pub(crate) fn time_per_call<T: Copy>(label: &str, inputs: &[T], run: &dyn Fn(T) -> f32) {
        let (wall, cpu) = (std::time::Instant::now(), on_cpu_ns());
        let mut checksum = 0.0f32;
        for &x in inputs {
            checksum += run(x);
        }
        let wall = wall.elapsed().as_nanos() as f64 / inputs.len() as f64;
        match (cpu, on_cpu_ns()) {
            (Some(a), Some(b)) => {
                let cpu = (b - a) as f64 / inputs.len() as f64;
                println!("{label}: {cpu:.1} ns on-CPU ({wall:.1} wall; checksum {checksum})")
            }
            _ => println!("{label}: {wall:.1} ns wall (checksum {checksum})"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::distribution::{cell_index, Distribution2D, ONE_MINUS_EPSILON};
    use crate::rng::{xi_2d, SplitMix64};

    /// Significance level of every chi-square test here.
    const ALPHA: f64 = 1e-3;

    /// Counts of samples per cell over `n` counter-based `ξ` of `seed`, checking each
    /// sample's pdf against the lookup and that it lies in its reported cell.
    fn cell_counts(t: &AliasTable2D, n: u64, seed: u64) -> Vec<u64> {
        let mut counts = vec![0u64; t.nu * t.nv];
        for k in 0..n {
            let s = t.sample_continuous(xi_2d(seed, k));
            assert_eq!(t.pdf(s.uv), s.pdf);
            assert_eq!(
                [cell_index(s.uv[0], t.nu), cell_index(s.uv[1], t.nv)],
                s.cell
            );
            assert!(s.uv[0] < 1.0 && s.uv[1] < 1.0);
            counts[s.cell[1] * t.nu + s.cell[0]] += 1;
        }
        counts
    }

    #[test]
    fn hand_computed_two_cells() {
        // f = {1, 3}: q = {.5, 1.5}; slot 0 keeps cell 0 below .5, else cell 1.
        let t = AliasTable2D::new(&[1.0, 3.0], 2);
        assert_eq!(
            t.slots[0],
            Slot {
                threshold: 0.5,
                alias: 1
            }
        );
        assert_eq!(
            t.slots[1],
            Slot {
                threshold: 1.0,
                alias: 1
            }
        );
        assert_eq!(t.integral(), 2.0);
        // ξ0 = .1: slot 0 (B n < 2⁴⁸), fraction .2 < .5 keeps cell 0, leftover .4.
        let s = t.sample_continuous([0.1, 0.0]);
        assert_eq!((s.cell, s.pdf), ([0, 0], 0.5));
        assert!((s.uv[0] - 0.2).abs() < 1e-6, "{s:?}");
        // ξ0 = .25: fraction exactly .5 goes to the alias, leftover 0.
        let s = t.sample_continuous([0.25, 0.0]);
        assert_eq!((s.cell, s.pdf, s.uv), ([1, 0], 1.5, [0.5, 0.0]));
        let s = t.sample_continuous([0.75, 0.0]);
        assert_eq!((s.cell, s.pdf), ([1, 0], 1.5));
    }

    #[test]
    fn uniform_function_is_an_identity_table() {
        let t = AliasTable2D::new(&[2.0; 12], 4);
        assert!(t
            .slots
            .iter()
            .enumerate()
            .all(|(i, s)| s.threshold == 1.0 && s.alias as usize == i));
        let s = t.sample_continuous([0.6, 0.0]);
        assert_eq!(s.cell, [3, 1]);
        assert_eq!(s.pdf, 1.0);
    }

    #[test]
    fn pdf_matches_inversion_sampler_cell_by_cell() {
        let mut rng = SplitMix64::new(11);
        for &(nu, nv) in &[(1, 1), (7, 3), (64, 32), (5, 17), (300, 1)] {
            let f = test_support::random_grid(&mut rng, nu * nv, 0.3);
            let alias = AliasTable2D::new(&f, nu);
            test_support::assert_pdf_is_f_over_integral(
                &f,
                nu,
                alias.integral(),
                |iu, iv| alias.cell_pdf(iu, iv),
                |uv| alias.pdf(uv),
            );
        }
    }

    #[test]
    fn table_reproduces_cell_probabilities_exactly() {
        // Σ over slots of the mass each gives to a cell must equal f/Σf.
        let mut rng = SplitMix64::new(5);
        let f = test_support::random_grid(&mut rng, 999, 0.25);
        let t = AliasTable2D::new(&f, 37);
        let n = f.len() as f64;
        let mut mass = vec![0.0f64; f.len()];
        for (i, s) in t.slots.iter().enumerate() {
            mass[i] += s.threshold as f64 / n;
            mass[s.alias as usize] += (1.0 - s.threshold as f64) / n;
        }
        let total: f64 = t.func.iter().map(|&x| x as f64).sum();
        for (i, &m) in mass.iter().enumerate() {
            let want = t.func[i] as f64 / total;
            assert!(
                (m - want).abs() <= 1e-6 * want + 1e-12,
                "cell {i}: {m} vs {want}"
            );
            if t.func[i] == 0.0 {
                assert_eq!(m, 0.0, "zero cell {i} reachable");
            }
        }
    }

    #[test]
    fn chi_square_fit_on_random_grids() {
        // α = 1e-3, N = 400 000 samples per grid, ξ from xi_2d(seed 3..6).
        let mut rng = SplitMix64::new(99);
        for (seed, &(nu, nv)) in [(16usize, 8usize), (13, 9), (50, 1), (1, 40)]
            .iter()
            .enumerate()
        {
            let f = test_support::random_grid(&mut rng, nu * nv, 0.2);
            let t = AliasTable2D::new(&f, nu);
            let n = 400_000;
            let counts = cell_counts(&t, n, 3 + seed as u64);
            test_support::assert_counts_fit(&counts, &t.func, n, &format!("{nu}x{nv}"));
        }
    }

    #[test]
    fn chi_square_rejects_a_wrong_pdf() {
        // The same harness must reject a table whose claimed density differs from the
        // sampled one: sample a table built from f but test against f with one
        // cell's weight raised by 10 % (α = 1e-3, N = 400 000, seed 8).
        let mut rng = SplitMix64::new(1);
        let f = test_support::random_grid(&mut rng, 128, 0.0);
        let t = AliasTable2D::new(&f, 16);
        let n = 400_000;
        let counts = cell_counts(&t, n, 8);
        test_support::assert_rejects_hottest_raised(&counts, &t.func, n);
    }

    #[test]
    fn zero_cells_are_never_sampled() {
        let mut f = vec![0.0f32; 64];
        f[5] = 1.0;
        f[40] = 1e-6;
        f[63] = 2.0;
        let t = AliasTable2D::new(&f, 8);
        let mut seen = [false; 64];
        for k in 0..100_000 {
            let s = t.sample_continuous(xi_2d(4, k));
            assert!(s.pdf > 0.0, "{s:?}");
            seen[s.cell[1] * 8 + s.cell[0]] = true;
        }
        assert!(seen[5] && seen[63]);
        // Sweep the edges of ξ space too, including values outside it.
        for &a in &[0.0, 1e-30, 0.5, ONE_MINUS_EPSILON, 1.0, 2.0, -1.0, f32::NAN] {
            for &b in &[0.0, 0.5, ONE_MINUS_EPSILON, 1.0, f32::NAN, f32::INFINITY] {
                let s = t.sample_continuous([a, b]);
                assert!(
                    s.pdf > 0.0 && s.uv.iter().all(|x| (0.0..1.0).contains(x)),
                    "{s:?}"
                );
            }
        }
    }

    #[test]
    fn degenerate_inputs() {
        let t = AliasTable2D::new(&[0.0, f32::NAN, -1.0, f32::INFINITY], 2);
        assert_eq!(t.integral(), 0.0);
        let s = t.sample_continuous([0.3, 0.7]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.uv.iter().all(|x| x.is_finite()));
        assert_eq!(t.pdf([0.5, 0.5]), 0.0);
        let t = AliasTable2D::new(&[5.0], 1);
        let s = t.sample_continuous([0.25, 0.75]);
        assert_eq!((s.cell, s.pdf), ([0, 0], 1.0));
        assert_eq!(t.pdf([f32::NAN, 7.0]), 1.0);
        // Huge values must not overflow the normalisation.
        let t = AliasTable2D::new(&[f32::MAX, f32::MAX, 0.0, f32::MAX], 2);
        let s = t.sample_continuous([0.9, 0.9]);
        assert!(s.pdf > 0.0 && s.pdf.is_finite(), "{s:?}");
    }

    #[test]
    fn offsets_fill_the_cell() {
        // One cell: the point must cover [0,1)² evenly (a 4×4 histogram).
        let t = AliasTable2D::new(&[1.0], 1);
        let mut counts = vec![0u64; 16];
        let n = 160_000;
        for k in 0..n {
            let s = t.sample_continuous(xi_2d(12, k));
            let (a, b) = ((s.uv[0] * 4.0) as usize, (s.uv[1] * 4.0) as usize);
            counts[b * 4 + a] += 1;
        }
        let (_, _, p) = test_support::chi_square(&counts, &[n as f64 / 16.0; 16]);
        assert!(p > ALPHA, "p = {p}");
    }

    #[test]
    fn samplers_are_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<AliasTable2D>();
        check::<crate::hierarchical::Hierarchical2D>();
        check::<crate::bilinear::BilinearDistribution2D>();
    }

    /// Per-sample cost against the inversion sampler on random grids of 4096×2048
    /// (out of cache) and 64×32 (in cache), with ξ from `xi_2d` (no coherence).
    /// Run: `cargo test --release -p envlight --lib alias::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_against_inversion() {
        for (nu, nv, f) in test_support::timing_grids() {
            let start = std::time::Instant::now();
            let alias = AliasTable2D::new(&f, nu);
            let build_alias = start.elapsed();
            let start = std::time::Instant::now();
            let inversion = Distribution2D::new(&f, nu);
            let build_inversion = start.elapsed();
            let time = test_support::timer_against_inversion(format!("{nu}x{nv}"), &inversion);
            time("alias sample", &|x| alias.sample_continuous(x).uv[0]);
            time("alias pdf", &|x| alias.pdf(x));
            println!(
                "{nu}x{nv} build: alias {build_alias:?}, inversion {build_inversion:?}; \
                 bytes/cell: alias {:.2}, inversion {:.2}",
                alias.memory_bytes() as f64 / (nu * nv) as f64,
                inversion.memory_bytes() as f64 / (nu * nv) as f64
            );
        }
    }
}
