//! Property tests (proptest) for the piecewise-constant distributions of
//! docs/design.md §3: random non-negative functions with many exact zeros and
//! values spanning 1e-30..1e30, on 1 to 299 cells (1D) and up to 24×24 cells (2D).
//!
//! 1024 cases per property from a fixed seed, so CI runs are reproducible; set
//! `PROPTEST_RNG_SEED` (and `PROPTEST_CASES`) to explore further. Failures are
//! shrunk and saved in `distribution_props.proptest-regressions`, which is replayed
//! first.

use envlight::distribution::{Distribution1D, Distribution2D, CDF_ONE, ONE_MINUS_EPSILON};
use proptest::prelude::*;
use proptest::test_runner::RngSeed;

/// 1024 cases from a fixed seed unless the environment chooses a seed.
fn config() -> ProptestConfig {
    let mut config = ProptestConfig {
        cases: 1024,
        ..ProptestConfig::default()
    };
    if std::env::var_os("PROPTEST_RNG_SEED").is_none() {
        config.rng_seed = RngSeed::Fixed(0x5eed_d157);
    }
    if let Some(cases) = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|c| c.parse().ok())
    {
        config.cases = cases;
    }
    config
}

/// Tolerance of `invert(sample(ξ)) ≈ ξ`. The sample is `x = (o + du)/n` in f32 and
/// the inverse recomputes `x n`, whose rounding (≤ n ε, with `x`'s own ≤ ε/2)
/// moves the fraction inside the cell by ≤ 2ε n; the CDF rises across the cell by
/// `pdf / n`, so ξ moves by ≤ 2ε·pdf, plus a few ε from the CDF arithmetic itself.
/// Twice that: `8 ε (1 + pdf)`.
fn invert_tolerance(pdf: f32) -> f32 {
    8.0 * f32::EPSILON * (1.0 + pdf)
}

/// A function value: exactly 0 half the time, otherwise log-uniform over
/// 1e-30..1e30 or uniform in [0, 1).
fn value() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => Just(0.0f32),
        2 => (-30.0f64..30.0).prop_map(|e| 10f64.powf(e) as f32),
        2 => 0.0f32..1.0,
    ]
}

/// A function on 1..300 cells, sometimes all zero.
fn function() -> impl Strategy<Value = Vec<f32>> {
    prop_oneof![
        8 => prop::collection::vec(value(), 1..300),
        1 => (1usize..300).prop_map(|n| vec![0.0; n]),
    ]
}

/// A sample-space coordinate, sometimes one of the ends of `[0, 1)`.
fn xi() -> impl Strategy<Value = f32> {
    prop_oneof![1 => Just(0.0f32), 1 => Just(ONE_MINUS_EPSILON), 8 => 0.0f32..1.0]
}

/// Up to 15 sample-space points.
fn xis() -> impl Strategy<Value = Vec<f32>> {
    prop::collection::vec(xi(), 1..16)
}

/// A grid `(nu, values)` of up to 24×24 cells.
fn grid() -> impl Strategy<Value = (usize, Vec<f32>)> {
    (1usize..25, 1usize..25).prop_flat_map(|(nu, nv)| {
        prop_oneof![
            8 => prop::collection::vec(value(), nu * nv),
            1 => Just(vec![0.0; nu * nv]),
        ]
        .prop_map(move |f| (nu, f))
    })
}

/// `a ≈ b` for densities and probabilities stored in f32: 1e-6 relative, and the
/// spacing of subnormal f32s (a cell holding 1e-44 of the mass has a subnormal pdf).
fn close(a: f32, b: f64) -> bool {
    (a as f64 - b).abs() <= 1e-6 * b.abs() + 1.5e-45
}

fn total(f: &[f32]) -> f64 {
    f.iter().map(|&v| v as f64).sum()
}

/// How far, in CDF units (2⁻³² of the mass), a cell's stored width may be from its
/// exact share `f / Σ f`: one unit of rounding, plus the units that cells whose
/// share is below one unit borrow to keep a width of at least 1 (each such cell
/// shifts later edges by at most one unit, forward or backward).
fn width_slack(f: &[f32]) -> f64 {
    let mass = total(f);
    let tiny = f
        .iter()
        .filter(|&&v| v > 0.0 && (v as f64 / mass) * (CDF_ONE as f64) < 1.0)
        .count();
    2.0 + 2.0 * tiny as f64
}

/// A cell's share of the mass as stored: its CDF width over `CDF_ONE`.
fn stored_share(cdf: &[u32], i: usize) -> f64 {
    (cdf[i + 1] - cdf[i]) as f64 / CDF_ONE as f64
}

/// `|stored − exact| ≤ slack units` (with f32's 1e-6 and subnormal spacing), for a
/// density of `n` cells times a share.
fn share_close(stored: f32, exact_share: f64, n: f64, slack: f64) -> bool {
    let exact = exact_share * n;
    (stored as f64 - exact).abs() <= n * slack / CDF_ONE as f64 + 1e-6 * exact + 1.5e-45
}

/// The cell of `x ∈ [0, 1)` among `n`.
fn cell_of(x: f32, n: usize) -> usize {
    ((x * n as f32) as usize).min(n - 1)
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn cdf_is_a_distribution_function(f in function()) {
        let d = Distribution1D::new(&f);
        let n = f.len();
        let cdf = d.cdf();
        prop_assert_eq!(cdf.len(), n + 1);
        prop_assert_eq!(cdf[0], 0);
        prop_assert_eq!(cdf[n], CDF_ONE);
        for w in cdf.windows(2) {
            prop_assert!(w[0] <= w[1], "not monotone: {:?}", w);
        }
        // integral = Σ f / n, summed in f64.
        let expected = total(&f) / n as f64;
        prop_assert!((d.integral() - expected).abs() <= 1e-12 * expected, "{} vs {expected}", d.integral());
        if expected > 0.0 {
            // Each cell's CDF step is its share of the mass, to the CDF's resolution,
            // and is positive exactly where f is.
            let slack = width_slack(&f);
            for (i, w) in cdf.windows(2).enumerate() {
                let share = f[i] as f64 / total(&f);
                let stored = (w[1] - w[0]) as f64;
                prop_assert!((stored - share * CDF_ONE as f64).abs() <= slack, "cell {i}: {stored} vs {share}");
                prop_assert_eq!(stored > 0.0, f[i] > 0.0, "cell {}: width {} for f = {}", i, stored, f[i]);
            }
        }
    }

    #[test]
    fn continuous_samples_are_consistent(f in function(), xis in xis()) {
        let d = Distribution1D::new(&f);
        let n = f.len();
        let lit = total(&f) > 0.0;
        for xi in xis {
            let s = d.sample_continuous(xi);
            prop_assert!(s.x.is_finite() && (0.0..1.0).contains(&s.x), "ξ={xi}: {s:?}");
            prop_assert!(s.pdf.is_finite() && s.pdf >= 0.0);
            prop_assert_eq!(s.cell, cell_of(s.x, n), "ξ={}: cell {} but x={} (n={})", xi, s.cell, s.x, n);
            // pdf(sample.x) is the sample's pdf, exactly.
            prop_assert_eq!(d.pdf(s.x), s.pdf, "ξ={}: {:?}", xi, s);
            if lit {
                // Never in a zero cell; pdf = n · width / CDF_ONE exactly, which is
                // f / integral to the CDF's resolution.
                prop_assert!(f[s.cell] > 0.0, "ξ={xi} landed in zero cell {}: {s:?}", s.cell);
                let stored = stored_share(d.cdf(), s.cell) * n as f64;
                prop_assert!(close(s.pdf, stored), "{s:?} vs {stored}");
                let share = f[s.cell] as f64 / total(&f);
                prop_assert!(share_close(s.pdf, share, n as f64, width_slack(&f)), "{s:?} vs share {share}");
                let back = d.invert(s.x);
                prop_assert!((back - xi).abs() <= invert_tolerance(s.pdf), "ξ={xi} → x={} → {back} (pdf {})", s.x, s.pdf);
            } else {
                prop_assert_eq!(s.pdf, 0.0);
            }
        }
    }

    #[test]
    fn discrete_samples_match_their_probabilities(f in function(), xis in xis()) {
        let d = Distribution1D::new(&f);
        let mass = total(&f);
        let sum: f64 = (0..f.len()).map(|i| d.discrete_probability(i) as f64).sum();
        if mass > 0.0 {
            prop_assert!((sum - 1.0).abs() <= 1e-5, "Σ p = {sum}");
        } else {
            prop_assert_eq!(sum, 0.0);
        }
        for xi in xis {
            let s = d.sample_discrete(xi);
            prop_assert!(s.index < f.len());
            prop_assert!((0.0..1.0).contains(&s.remapped), "{s:?}");
            prop_assert_eq!(s.index, d.sample_continuous(xi).cell);
            if mass > 0.0 {
                prop_assert!(f[s.index] > 0.0);
                let expected = f[s.index] as f64 / mass;
                prop_assert!(share_close(s.probability, expected, 1.0, width_slack(&f)), "{s:?} vs {expected}");
            } else {
                prop_assert_eq!(s.probability, 0.0);
            }
        }
    }

    /// M = 4096 stratified ξ: an interval of length L holds L·M ± 1 of them, so each
    /// cell's count is its probability times M to within one.
    #[test]
    fn stratified_counts_follow_the_probabilities(f in function()) {
        let d = Distribution1D::new(&f);
        let mass = total(&f);
        prop_assume!(mass > 0.0);
        const M: usize = 4096;
        let mut counts = vec![0usize; f.len()];
        for k in 0..M {
            counts[d.sample_discrete((k as f32 + 0.5) / M as f32).index] += 1;
        }
        for (i, &c) in counts.iter().enumerate() {
            let p = f[i] as f64 / mass;
            prop_assert!((c as f64 - p * M as f64).abs() <= 1.0 + 1e-3, "cell {i}: {c} of {M} for p = {p}");
        }
    }

    #[test]
    fn zero_functions_have_zero_pdf(n in 1usize..300, xis in xis()) {
        let d = Distribution1D::new(&vec![0.0; n]);
        prop_assert_eq!(d.integral(), 0.0);
        for xi in xis {
            let s = d.sample_continuous(xi);
            prop_assert!(s.x.is_finite() && (0.0..1.0).contains(&s.x));
            prop_assert_eq!(s.pdf, 0.0);
            prop_assert_eq!(d.pdf(xi), 0.0);
            prop_assert_eq!(d.sample_discrete(xi).probability, 0.0);
            prop_assert!(d.invert(xi).is_finite());
        }
    }

    #[test]
    fn two_dimensional_samples_are_consistent((nu, f) in grid(), xis in prop::collection::vec((xi(), xi()), 1..16)) {
        let d = Distribution2D::new(&f, nu);
        let nv = f.len() / nu;
        let mass = total(&f);
        let expected = mass / (nu * nv) as f64;
        prop_assert!((d.integral() - expected).abs() <= 1e-9 * expected, "{} vs {expected}", d.integral());
        let pdf_sum: f64 = (0..nv).flat_map(|v| (0..nu).map(move |u| (u, v))).map(|(u, v)| d.cell_pdf(u, v) as f64).sum();
        if mass > 0.0 {
            // The widths telescope: only f32 rounding of each cell's pdf remains.
            prop_assert!((pdf_sum / (nu * nv) as f64 - 1.0).abs() <= 1e-6, "mean cell pdf {}", pdf_sum / (nu * nv) as f64);
        } else {
            prop_assert_eq!(pdf_sum, 0.0);
        }
        for (x0, x1) in xis {
            let s = d.sample_continuous([x0, x1]);
            prop_assert!(s.uv.iter().all(|c| c.is_finite() && (0.0..1.0).contains(c)), "{s:?}");
            prop_assert_eq!(s.cell, [cell_of(s.uv[0], nu), cell_of(s.uv[1], nv)], "{:?}", s);
            prop_assert_eq!(d.pdf(s.uv), s.pdf, "{:?}", s);
            if mass > 0.0 {
                let [iu, iv] = s.cell;
                prop_assert!(f[iv * nu + iu] > 0.0, "landed in a zero cell: {s:?}");
                prop_assert_eq!(s.pdf, d.cell_pdf(iu, iv));
                // The row's share of the mass times the cell's share of the row, each
                // to its CDF's resolution (the product may underflow f32: the grid
                // spans up to 1e60, so a row can be chosen whose cell's density is
                // below 1e-45).
                let row = &f[iv * nu..(iv + 1) * nu];
                let row_sums: Vec<f32> = f.chunks(nu).map(|r| total(r) as f32).collect();
                let (share_v, share_u) = (total(row) / mass, f[iv * nu + iu] as f64 / total(row));
                let (slack_v, slack_u) = (width_slack(&row_sums), width_slack(row));
                let exact = share_v * share_u * (nu * nv) as f64;
                let one = CDF_ONE as f64;
                let err = (nu * nv) as f64
                    * ((slack_u * share_v + slack_v * share_u) / one + slack_u * slack_v / (one * one));
                prop_assert!((s.pdf as f64 - exact).abs() <= err + 1e-6 * exact + 1.5e-45, "{s:?} vs {exact} ± {err}");
                let back = d.invert(s.uv);
                // Marginal density of the row, conditional density within it.
                let p_v = d.marginal().pdf(s.uv[1]);
                let p_u = (stored_share(d.row_cdf(iv), iu) * nu as f64) as f32;
                prop_assert!((back[1] - x1).abs() <= invert_tolerance(p_v), "ξ1 {x1} → {} ({s:?})", back[1]);
                prop_assert!((back[0] - x0).abs() <= invert_tolerance(p_u), "ξ0 {x0} → {} ({s:?})", back[0]);
            } else {
                prop_assert_eq!(s.pdf, 0.0);
            }
        }
    }

    /// A 64×64 stratified grid of ξ: row r (marginal probability P) gets P·M ± 1 of
    /// the ξ1 values and cell c within it (conditional p) gets p·M ± 1 of the ξ0
    /// values, so the count is within (P + p) M + 1 of P p M².
    #[test]
    fn two_dimensional_stratified_counts((nu, f) in grid()) {
        let d = Distribution2D::new(&f, nu);
        let nv = f.len() / nu;
        let mass = total(&f);
        prop_assume!(mass > 0.0);
        const M: usize = 64;
        let mut counts = vec![0usize; nu * nv];
        for k1 in 0..M {
            for k0 in 0..M {
                let xi = [(k0 as f32 + 0.5) / M as f32, (k1 as f32 + 0.5) / M as f32];
                let [iu, iv] = d.sample_continuous(xi).cell;
                counts[iv * nu + iu] += 1;
            }
        }
        for iv in 0..nv {
            let row: f64 = total(&f[iv * nu..(iv + 1) * nu]);
            let p_row = row / mass;
            for iu in 0..nu {
                let p_cell = if row > 0.0 { f[iv * nu + iu] as f64 / row } else { 0.0 };
                let expected = p_row * p_cell * (M * M) as f64;
                let slack = (p_row + p_cell) * M as f64 + 1.0 + 1e-3;
                let c = counts[iv * nu + iu] as f64;
                prop_assert!((c - expected).abs() <= slack, "cell ({iu},{iv}): {c} vs {expected} ± {slack}");
            }
        }
    }
}

// Deterministic regressions (found by the properties above).

/// `sample_continuous` must keep `x` inside the cell it reports: with
/// `x = (o + du) / n` computed in f32, `o + du` rounds up to `o + 1` when `du` is
/// within half an ulp of `o` below 1, and `x` lands on the next cell (here a zero
/// cell), where `pdf(x)` is 0.
#[test]
fn continuous_sample_stays_in_its_cell_1d() {
    for (f, xi) in [
        (vec![0.0, 1.0, 0.0], ONE_MINUS_EPSILON),
        // ulp(3000) = 2.4e-4 in f32, so any du > 1 - 1.2e-4 rounds up.
        (
            {
                let mut f = vec![0.0; 4096];
                f[3000] = 1.0;
                f
            },
            0.9999,
        ),
    ] {
        let d = Distribution1D::new(&f);
        let s = d.sample_continuous(xi);
        let n = f.len();
        assert!(
            cell_of(s.x, n) == s.cell && d.pdf(s.x) == s.pdf,
            "n={n}, ξ={xi}: {s:?} but x is in cell {} where pdf(x) = {}",
            cell_of(s.x, n),
            d.pdf(s.x)
        );
    }
}

/// The same for both axes of the 2D distribution.
#[test]
fn continuous_sample_stays_in_its_cell_2d() {
    for (nu, f, xi) in [
        (3, vec![0.0, 1.0, 0.0], [ONE_MINUS_EPSILON, 0.5]),
        (1, vec![0.0, 1.0, 0.0], [0.5, ONE_MINUS_EPSILON]),
    ] {
        let d = Distribution2D::new(&f, nu);
        let s = d.sample_continuous(xi);
        let nv = f.len() / nu;
        let cell = [cell_of(s.uv[0], nu), cell_of(s.uv[1], nv)];
        assert!(
            cell == s.cell && d.pdf(s.uv) == s.pdf,
            "{nu}x{nv}, ξ={xi:?}: {s:?} but uv is in cell {cell:?} where pdf(uv) = {}",
            d.pdf(s.uv)
        );
    }
}
