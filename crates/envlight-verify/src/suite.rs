//! Every check at once: [`run`] measures, [`Report`] judges and prints,
//! [`assert_invariants`] and [`assert_black`] are the tests' one-liners.

use crate::checks::black::black;
use crate::checks::chi_square::{chi_square, ChiSquare};
use crate::checks::consistency::{consistency, Consistency};
use crate::checks::normalisation::{normalisation, Normalisation};
use crate::checks::support::{support, Support};
use crate::checks::unbiasedness::{lobe_normals, unbiasedness, Reference, Unbiasedness};
use crate::integrand::Integrand;
use crate::report::Row;
use crate::sampler::SphereSampler;
use crate::PDF_CONSISTENCY_TOLERANCE;
use envlight::Vec3;
use std::time::Instant;

/// The rows of [`Report::rows`], in order, for the integrand `Y` (the front ends
/// print them as skipped when a map is all black).
pub const CHECKS: [&str; 8] = [
    "normalisation",
    "pdf consistency",
    "invert",
    "chi-square",
    "unbiased (Y)",
    "unbiased (cos)",
    "support",
    "efficiency",
];

/// Which cosine lobes [`unbiasedness`] tests on top of the integrand.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Lobes {
    /// [`lobe_normals`]: towards the brightest cell, up, and obliquely down.
    Standard,
    /// One lobe around world +z.
    Zenith,
}

/// Sample counts, tolerances and options for [`run`].
#[derive(Debug, Clone, Copy)]
pub struct Config {
    /// Samples for the chi-square test.
    pub chi2_samples: usize,
    /// Largest number of chi-square bins.
    pub max_bins: usize,
    /// Samples for the consistency checks.
    pub consistency_samples: usize,
    /// Relative tolerance of `pdf(sample.ω)` against `sample.pdf` away from the
    /// poles (see [`crate::pdf_tolerance`]).
    pub pdf_tolerance: f64,
    /// Samples for the unbiasedness/efficiency estimates.
    pub mc_samples: usize,
    /// The lobes the unbiasedness check adds to the integrand.
    pub lobes: Lobes,
    /// How the unbiasedness check integrates its references.
    pub reference: Reference,
    /// Whether to run the support check.
    pub support: bool,
    /// Whether to run the unbiasedness check.
    pub unbiasedness: bool,
    /// Whether the efficiency figures (quadrature, Monte Carlo, reported) must agree.
    pub efficiency: bool,
    /// Base seed; each check derives its own.
    pub seed: u64,
}

impl Config {
    /// For small synthetic maps: 1M chi-square samples in at most 40k bins, 200k
    /// consistency samples, 1M Monte Carlo samples.
    pub const SYNTHETIC: Config = Config {
        chi2_samples: 1_000_000,
        max_bins: 40_000,
        consistency_samples: 200_000,
        pdf_tolerance: PDF_CONSISTENCY_TOLERANCE,
        mc_samples: 1_000_000,
        lobes: Lobes::Standard,
        reference: Reference::Checked,
        support: true,
        unbiasedness: true,
        efficiency: true,
        seed: 0x5eed,
    };
    /// For real 1k–2k maps: 500k chi-square samples in at most 8192 bins (groups of
    /// texels), 200k consistency samples, 500k Monte Carlo samples.
    pub const REAL_MAP: Config = Config {
        chi2_samples: 500_000,
        max_bins: 8192,
        consistency_samples: 200_000,
        mc_samples: 500_000,
        ..Config::SYNTHETIC
    };

    /// `n` samples for every check in at most `n / 20` chi-square bins (about 20
    /// samples per bin), as `envlight verify --samples N --seed S` asks.
    pub fn with_samples(n: usize, seed: u64) -> Config {
        Config {
            chi2_samples: n,
            max_bins: (n / 20).max(1),
            consistency_samples: n,
            mc_samples: n,
            seed,
            ..Config::SYNTHETIC
        }
    }
}

/// Every figure measured for one case, with the seconds each check took.
#[derive(Debug, Clone)]
pub struct Report {
    /// 1. normalisation.
    pub normalisation: Normalisation,
    /// 2. consistency.
    pub consistency: Consistency,
    /// 3. chi-square.
    pub chi_square: ChiSquare,
    /// 4. support (when run).
    pub support: Option<Support>,
    /// 5–6. unbiasedness and efficiency (when run).
    pub unbiasedness: Option<Unbiasedness>,
    /// Seconds spent on checks 1 to 5.
    pub seconds: [f64; 5],
    /// Whether the efficiency figures were judged.
    efficiency_judged: bool,
}

/// Runs checks 1–6 on a sampler that is not black, against `integrand`: `step`
/// hears the name of each check as it starts (for a progress display).
pub fn run(
    s: &dyn SphereSampler,
    integrand: &Integrand,
    cfg: &Config,
    step: &dyn Fn(&str),
) -> Report {
    let mut seconds = [0.0; 5];
    let timed = |k: usize, name: &str| {
        step(name);
        let start = Instant::now();
        move |seconds: &mut [f64; 5]| seconds[k] = start.elapsed().as_secs_f64()
    };
    let done = timed(0, "normalisation");
    let normalisation = normalisation(s);
    done(&mut seconds);
    let done = timed(1, "consistency");
    let consistency = consistency(s, cfg.consistency_samples, cfg.seed ^ 1, cfg.pdf_tolerance);
    done(&mut seconds);
    let done = timed(2, "chi-square");
    let chi_square = chi_square(s, cfg.chi2_samples, cfg.seed ^ 2, cfg.max_bins);
    done(&mut seconds);
    let done = timed(3, "support");
    let support = cfg.support.then(|| support(s, integrand));
    done(&mut seconds);
    let done = timed(4, "unbiasedness");
    let unbiasedness = cfg.unbiasedness.then(|| {
        let lobes = match cfg.lobes {
            Lobes::Standard => lobe_normals(s),
            Lobes::Zenith => vec![Vec3::new(0.0, 0.0, 1.0)],
        };
        unbiasedness(
            s,
            integrand,
            &lobes,
            cfg.mc_samples,
            cfg.seed ^ 3,
            cfg.reference,
        )
    });
    done(&mut seconds);
    Report {
        normalisation,
        consistency,
        chi_square,
        support,
        unbiasedness,
        seconds,
        efficiency_judged: cfg.efficiency,
    }
}

impl Report {
    /// One `(line, verdict)` per check: its figures and whether it passed.
    pub fn checks(&self) -> Vec<(String, Result<(), String>)> {
        let mut out = vec![
            (
                self.normalisation.to_string(),
                self.normalisation.verdict(false),
            ),
            (self.consistency.to_string(), self.consistency.verdict()),
            (self.chi_square.to_string(), self.chi_square.verdict()),
        ];
        if let Some(s) = &self.support {
            out.push((s.to_string(), s.verdict()));
        }
        if let Some(u) = &self.unbiasedness {
            out.push((u.to_string(), u.verdict(self.efficiency_judged)));
        }
        out
    }

    /// The failed checks' messages (empty when everything passed).
    pub fn failures(&self) -> Vec<String> {
        self.checks()
            .into_iter()
            .filter_map(|(_, v)| v.err())
            .collect()
    }

    /// The table of `envlight verify` ([`CHECKS`]): normalisation, pdf
    /// consistency, invert, chi-square, the unbiasedness of the integrand (named
    /// by its label) and of the integrand times the first lobe (`cos`), support
    /// and efficiency. `sampler` names the sampler for the invert row.
    pub fn rows(&self, sampler: &str) -> Vec<Row> {
        let mut rows = vec![
            self.normalisation.row(false),
            self.consistency.pdf_row(),
            self.consistency.invert_row(sampler),
            self.chi_square.row(),
        ];
        if let Some(u) = &self.unbiasedness {
            let label = u.estimates.first().map_or("", |e| e.label.as_str());
            let names = [label, "cos"];
            rows.extend(
                u.estimates
                    .iter()
                    .zip(names)
                    .map(|(e, name)| e.row(name, u.samples)),
            );
        }
        if let Some(s) = &self.support {
            rows.push(s.row());
        }
        if let Some(u) = &self.unbiasedness {
            rows.push(u.efficiency_row());
        }
        rows
    }
}

/// Runs checks 1–6 on a sampler that is not black, prints one line per check and
/// panics listing every failed check: the integration tests' one-liner.
pub fn assert_invariants(
    case: &str,
    s: &dyn SphereSampler,
    integrand: &Integrand,
    cfg: &Config,
) -> Report {
    let report = run(s, integrand, cfg, &|_| {});
    let total: f64 = report.seconds.iter().sum();
    let mut lines = vec![format!("[{case}] {} ({total:.2}s)", s.name())];
    for ((line, verdict), seconds) in report.checks().into_iter().zip(report.seconds) {
        let mark = if verdict.is_ok() { "ok  " } else { "FAIL" };
        lines.push(format!("  {mark} [{seconds:.2}s] {line}"));
    }
    print_and_assert(case, &s.name(), &lines, &report.failures());
    report
}

/// Prints `lines` (a case's header and one line per check) and panics listing
/// `failures` when there are any: the tail of every `assert_*` one-liner.
pub(crate) fn print_and_assert(case: &str, name: &str, lines: &[String], failures: &[String]) {
    println!("{}", lines.join("\n"));
    assert!(
        failures.is_empty(),
        "[{case}] {name} failed:\n  {}",
        failures.join("\n  ")
    );
}

/// Checks an all-black sampler: no sample, pdf 0 everywhere, ∫p = 0, no NaN;
/// panics with the figures otherwise.
pub fn assert_black(case: &str, s: &dyn SphereSampler, n: usize) {
    let b = black(s, n, 0xb1ac);
    let norm = normalisation(s);
    println!("[{case}] {}\n  {b}\n  {norm}", s.name());
    if let Err(e) = b.verdict(s) {
        panic!("[{case}] black: {e}");
    }
    if let Err(e) = norm.verdict(true) {
        panic!("[{case}] normalisation: {e}");
    }
}
