//! 3. Chi-square goodness of fit of the samples to `pdf()`.

use crate::frame::Frame;
use crate::quadrature::{Needs, Quadrature, FOLD_SPLIT};
use crate::report::{Row, Verdict};
use crate::sampler::SphereSampler;
use crate::stats::{fits, over_sample_chunks};
use crate::{ALPHA, EDGE_BAND};
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::fmt;

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
    /// Samples in a cell where the pdf is 0 at every quadrature point but positive
    /// at the sample itself: a sliver of support the quadrature missed, next to a
    /// jump of the pdf off the grid ([`SphereSampler::fold`]). Left out of the
    /// statistic; more than [`MAX_UNRESOLVED`] of the samples fails the check.
    pub unresolved: usize,
}

/// The largest share of samples [`ChiSquare::unresolved`] may hold.
pub const MAX_UNRESOLVED: f64 = 1e-4;

impl ChiSquare {
    /// Rejects at [`ALPHA`], or when any sample fell where the pdf is 0.
    pub fn verdict(&self) -> Result<(), String> {
        if self.outside_support > 0
            || self.unresolved as f64 > MAX_UNRESOLVED * self.samples as f64
            || !fits(ALPHA, self.p_value)
        {
            Err(format!("rejected at α={ALPHA}: {self}"))
        } else {
            Ok(())
        }
    }
}

impl ChiSquare {
    /// The table row.
    pub fn row(&self) -> Row {
        let value = if self.outside_support > 0 {
            format!("{} samples in bins where ∫p dω = 0", self.outside_support)
        } else if self.unresolved as f64 > MAX_UNRESOLVED * self.samples as f64 {
            format!(
                "{} samples in support the quadrature missed",
                self.unresolved
            )
        } else {
            format!(
                "p = {:.4} (χ² = {:.1}, {} dof; {}×{} bins)",
                self.p_value, self.statistic, self.dof, self.bins[0], self.bins[1]
            )
        };
        Row::new(
            "chi-square",
            value,
            format!("p ≥ {ALPHA:.0e}"),
            self.samples,
            Verdict::from_pass(self.verdict().is_ok()),
        )
    }
}

impl fmt::Display for ChiSquare {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "chi2: N={} ({} none, {} nudged off an edge), ∫p {:.6}, {}x{} bins → {} used, dof {}, χ²={:.1}, p={:.3e}, outside support {}, unresolved {}, worst bin {}",
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
            self.unresolved,
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
        node_rows: 0,
        fold_split: FOLD_SPLIT,
    };
    let quadrature_cells = q.cells(s, Needs::PDF, |pt| {
        [if pt.pdf.is_finite() && pt.pdf > 0.0 {
            pt.pdf as f64 * pt.weight
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
    let (observed, none, nudged, unresolved) = over_sample_chunks(
        s,
        n,
        seed,
        || (vec![0u32; bins_u * bins_v], 0usize, 0usize, 0usize),
        |(hist, none, nudged, unresolved), _, samples| {
            for smp in samples {
                let Some(smp) = smp else {
                    *none += 1;
                    continue;
                };
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
                    if cells[cell][0] == 0.0 && s.pdf(smp.direction) > 0.0 {
                        *unresolved += 1;
                        continue;
                    }
                }
                hist[bin_of_fine(cell % fine_u, cell / fine_u)] += 1;
            }
        },
    )
    .into_iter()
    .fold(
        (vec![0u64; bins_u * bins_v], 0usize, 0usize, 0usize),
        |(mut h, n0, m0, r0), (c, n1, m1, r1)| {
            for (a, b) in h.iter_mut().zip(c) {
                *a += b as u64;
            }
            (h, n0 + n1, m0 + m1, r0 + r1)
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

    let observed: Vec<f64> = observed.iter().map(|&o| o as f64).collect();
    let (statistic, used_bins, dof, p_value) = pearson(&observed, &expected);
    let p_value = if outside_support > 0 { 0.0 } else { p_value };
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
        unresolved,
    }
}

/// Pearson's statistic of `observed` against `expected` counts, bins with
/// expectation 0 left out, bins expecting fewer than [`MIN_EXPECTED`] pooled in
/// increasing order of expectation (Mitsuba's rule): `(statistic, bins used,
/// degrees of freedom, P(χ²_dof ≥ statistic))`. Every chi-square test of the
/// harness ends here.
pub fn pearson(observed: &[f64], expected: &[f64]) -> (f64, usize, usize, f64) {
    let mut order: Vec<usize> = (0..expected.len()).filter(|&k| expected[k] > 0.0).collect();
    order.sort_by(|&a, &b| expected[a].total_cmp(&expected[b]).then(a.cmp(&b)));
    let mut statistic = 0.0;
    let mut used_bins = 0usize;
    let (mut pool_o, mut pool_e) = (0.0f64, 0.0f64);
    for &k in &order {
        pool_o += observed[k];
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
    let p_value = ChiSquared::new(dof as f64)
        .map(|c| c.sf(statistic))
        .unwrap_or(f64::NAN);
    (statistic, used_bins, dof, p_value)
}
