//! An alias table in exact integers over a fixed-point distribution: O(1) picks
//! with no search, whose probabilities are exactly the distribution's CDF widths.
//!
//! For `n` cells of widths `w_i` (`Σ w = C`, the CDF's [`CDF_ONE`]) each slot holds
//! `C` units: slot `s` keeps its own cell for the first `T_s` of them and gives the
//! rest, `C - T_s`, to its alias `a_s`. Vose's pairing is done on the integers
//! `n w_i`, so it is exact: every cell receives
//!
//! ```text
//! T_i + Σ_{s : a_s = i} (C - T_s) = n w_i   units of the n C,
//! ```
//!
//! and a pick (a slot uniformly, then keep when a uniform fraction is below
//! `T_s / C`) returns cell `i` with probability `w_i / C`, the width the pdf reads.
//! A cell of width 0 has `T = 0` and is nobody's alias, so it is never returned.

use crate::alias::vose_pairing;
use crate::distribution::{Distribution1D, CDF_ONE};
use crate::math::BELOW_ONE;

/// One slot: keep the slot's own cell below `threshold` (of [`CDF_ONE`] units),
/// else take `alias`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(super) struct Slot {
    pub threshold: u32,
    pub alias: u32,
}

/// `slots` as the exported `[threshold, alias]` pairs.
pub(super) fn words(slots: &[Slot]) -> Vec<[u32; 2]> {
    slots.iter().map(|s| [s.threshold, s.alias]).collect()
}

/// A table of `n` default (all-zero) values whose memory the kernel is asked to
/// back with 2 MiB pages before it is written: the product sampler reads its
/// big tables at random places, which with 4 KiB pages would miss the TLB.
pub(super) fn large_table<T: Clone + Default>(n: usize) -> Vec<T> {
    let mut table = Vec::with_capacity(n);
    crate::math::advise_huge_pages(table.spare_capacity_mut());
    table.resize(n, T::default());
    table
}

/// The fixed-point distribution of the weights `f` as its cells' widths, written
/// to `widths` (as long as `f`): they sum to [`CDF_ONE`], every positive weight
/// keeping at least one unit, or are all 0 when `f` has no positive, finite sum.
/// Returns that sum (0 in the second case).
pub(super) fn fixed_point_widths(f: &[f32], widths: &mut [u32]) -> f64 {
    let d = Distribution1D::new(f);
    let sum = d.integral() * f.len() as f64;
    let lit = sum > 0.0 && sum.is_finite();
    for (w, c) in widths.iter_mut().zip(d.cdf().windows(2)) {
        *w = if lit { c[1] - c[0] } else { 0 };
    }
    if lit {
        sum
    } else {
        0.0
    }
}

/// The units each cell receives over all `slots` (`n w_i` for an exact table of
/// widths `w`).
#[cfg(test)]
pub(super) fn received(slots: &[Slot]) -> Vec<u128> {
    let mut got = vec![0u128; slots.len()];
    for (s, slot) in slots.iter().enumerate() {
        got[s] += slot.threshold as u128;
        got[slot.alias as usize] += (CDF_ONE - slot.threshold) as u128;
    }
    got
}

/// Fills `slots` (as long as `widths`) with the exact alias table of the
/// fixed-point widths `widths`, which sum to [`CDF_ONE`] or are all 0 (then every
/// slot keeps its own cell with threshold 0: nothing can be picked, and nothing is,
/// as no table gives such a patch weight).
///
/// # Panics
/// When the lengths differ, or the widths sum to neither 0 nor [`CDF_ONE`].
pub(super) fn build(widths: &[u32], slots: &mut [Slot]) {
    assert_eq!(widths.len(), slots.len(), "one slot per cell");
    let total: u64 = widths.iter().map(|&w| w as u64).sum();
    for (s, slot) in slots.iter_mut().enumerate() {
        *slot = Slot {
            threshold: 0,
            alias: s as u32,
        };
    }
    if total == 0 {
        return;
    }
    assert_eq!(total, CDF_ONE as u64, "widths of a fixed-point CDF");
    let n = widths.len() as u128;
    let capacity = CDF_ONE as u128;
    let mut units: Vec<u128> = widths.iter().map(|&w| n * w as u128).collect();
    let (full, short) = vose_pairing(&mut units, capacity, |s, su, l| {
        slots[s as usize] = Slot {
            threshold: su as u32,
            alias: l,
        };
    });
    // In exact arithmetic what is left holds exactly `capacity` units a slot, so
    // no short cell is left and every full one keeps its own cell.
    debug_assert!(short.is_empty());
    for &l in &full {
        debug_assert_eq!(units[l as usize], capacity);
        slots[l as usize].threshold = CDF_ONE;
    }
}

/// The cell `slots` picks for `x ∈ [0, 1)`: slot `⌊x n⌋`, kept or aliased by the
/// fraction of `x` past it, and that fraction rescaled to `[0, 1)` within the part
/// of the slot that gave the cell, free for reuse.
#[inline(always)]
pub(super) fn pick(slots: &[Slot], x: f64) -> (usize, f64) {
    let n = slots.len();
    let t = x * n as f64;
    // `t` is in [0, n) for x in [0, 1); `min` keeps a rounding at the top inside.
    let s = (t as usize).min(n - 1);
    let slot = slots[s];
    let units = (t - s as f64) * CDF_ONE as f64;
    let threshold = slot.threshold as f64;
    let keep = units < threshold;
    let (index, offset, width) = if keep {
        (s, units, threshold)
    } else {
        (
            slot.alias as usize,
            units - threshold,
            CDF_ONE as f64 - threshold,
        )
    };
    // `max` also maps the 0/0 of a full slot's measure-zero top to 0.
    #[allow(clippy::manual_clamp)]
    let remapped = (offset / width).max(0.0).min(BELOW_ONE);
    (index, remapped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    #[test]
    fn every_cell_receives_exactly_its_width() {
        let mut rng = SplitMix64::new(5);
        for n in [1usize, 2, 3, 7, 64, 257, 4096] {
            for zeros in [0.0, 0.5, 0.95] {
                let f: Vec<f32> = (0..n)
                    .map(|_| {
                        if rng.next_f32() < zeros {
                            0.0
                        } else {
                            rng.next_f32().powi(8) * 1e6
                        }
                    })
                    .collect();
                let mut widths = vec![0u32; n];
                if fixed_point_widths(&f, &mut widths) == 0.0 {
                    assert!(f.iter().all(|&v| v == 0.0) && widths.iter().all(|&w| w == 0));
                    continue;
                }
                let mut slots = vec![Slot::default(); n];
                build(&widths, &mut slots);
                let got = received(&slots);
                for (i, (&g, &w)) in got.iter().zip(&widths).enumerate() {
                    assert_eq!(g, n as u128 * w as u128, "n {n}, cell {i}");
                }
                // Picks land on cells with width only, in proportion to it.
                let mut count = vec![0u64; n];
                let picks = 200_000u64;
                for k in 0..picks {
                    let x = (k as f64 + 0.5) / picks as f64;
                    let (i, r) = pick(&slots, x);
                    assert!(widths[i] > 0, "n {n}: cell {i} of width 0 picked");
                    assert!((0.0..1.0).contains(&r), "{r}");
                    count[i] += 1;
                }
                // Stratified x: each slot a cell draws from is off by at most one
                // pick (plus the slot's own when it is split).
                let mut sources = vec![1.0f64; n];
                for slot in &slots {
                    sources[slot.alias as usize] += 1.0;
                }
                for (i, (&c, &w)) in count.iter().zip(&widths).enumerate() {
                    let expected = picks as f64 * w as f64 / CDF_ONE as f64;
                    assert!(
                        (c as f64 - expected).abs() <= sources[i] + 1.0,
                        "n {n}, cell {i}: {c} picks, {expected} expected"
                    );
                }
            }
        }
    }

    #[test]
    fn zero_widths_pick_nothing_with_weight() {
        let mut slots = vec![Slot::default(); 4];
        build(&[0; 4], &mut slots);
        assert!(slots.iter().all(|s| s.threshold == 0));
    }
}
