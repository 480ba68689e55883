//! `envlight verify`: the invariants of DESIGN.md §5, checked on the user's map.
//!
//! Two passes: a quadrature over the texel grid (k×k points per texel, each
//! weighted by the exact solid angle of its sub-cell) integrates `pdf()` per
//! chi-square bin and in total, `Y·cos⁺` for the cosine-lobe reference, and checks
//! support; then N samples (counter-based, so the same for any thread count) feed
//! the consistency, round-trip, chi-square and unbiasedness statistics.

mod gamma;

use std::f64::consts::PI;
use std::io::Write;

use anyhow::Context;
use envlight::color::luminance;
use envlight::EnvironmentLight;
use rayon::prelude::*;

use super::Outcome;
use crate::light_args::LightArgs;
use crate::output::Output;
use crate::progress::Progress;

/// Arguments of `envlight verify`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Checks (DESIGN.md §5), printed as a table `check | value | threshold | result`; the \
exit status is 1 when any check fails:\n\
  normalisation    ∫p dω over the sphere by quadrature (4×4 points per texel, 2×2 \
above 1M texels, at least 2048×1024 in all; each weighted by its exact solid angle): \
|1 - ∫p dω| < 1e-3.\n\
  pdf consistency  pdf(sample(ξ).ω) equals the sample's pdf to 1e-3 relative, except \
for samples within 1e-3 texel of a cell edge or 0.57° of a pole, where float rounding \
of the direction decides (counted, allowed).\n\
  invert           |invert(sample(ξ).ω) - ξ| < 1e-3, with the same edge allowance.\n\
  chi-square       samples binned into about N/20 cells aligned to groups of texels, \
expected counts integrated from pdf(), cells expecting < 5 pooled: p-value ≥ 1e-3.\n\
  unbiased (Y)     the mean of Y/p is within 4 standard errors of ∫Y dω (exact).\n\
  unbiased (cos)   the mean of Y·max(0, z)/p is within 4 standard errors of its \
quadrature (a cosine lobe around +z).\n\
  support          every texel with luminance > 0 has pdf > 0 at its centre.\n\
  efficiency       (∫Y dω)² / ∫(Y²/p) dω, reported only (1 means pdf ∝ luminance).\n\
An all-black map has nothing to check: the checks are skipped.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    /// Number of sample directions.
    #[arg(long, value_name = "N", default_value_t = 200_000,
          value_parser = clap::value_parser!(u64).range(100..))]
    samples: u64,

    /// Seed of the sample sequence (as in `envlight sample`).
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
}

/// Significance level of the chi-square test.
const CHI2_ALPHA: f64 = 1e-3;
/// Fewest expected samples for a chi-square cell of its own.
const CHI2_MIN_EXPECTED: f64 = 5.0;
/// Samples per chi-square cell aimed for.
const CHI2_SAMPLES_PER_CELL: u64 = 20;
/// Tolerances of the other checks.
const NORMALISATION_TOL: f64 = 1e-3;
const PDF_REL_TOL: f64 = 1e-3;
const INVERT_TOL: f64 = 1e-3;
const EDGE_TEXELS: f64 = 1e-3;
const SIGMAS: f64 = 4.0;
/// Samples handled per parallel task.
const TASK_SAMPLES: u64 = 8192;

/// Runs `envlight verify`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    let loaded = args.light.load()?;
    let light = &loaded.light;
    let n = args.samples;
    let mut rows: Vec<Row> = Vec::new();
    if loaded.black {
        for check in [
            "normalisation",
            "pdf consistency",
            "invert",
            "chi-square",
            "unbiased (Y)",
            "unbiased (cos)",
            "support",
            "efficiency",
        ] {
            rows.push(Row::new(check, "map is all black", "-", Verdict::Skip));
        }
    } else {
        let bins = Bins::new(light.image().width(), light.image().height(), n);
        let quad = quadrature(light, &bins);
        let stats = sample_statistics(light, &bins, args.seed, n);
        rows = report(light, &bins, &quad, &stats, n);
    }

    let failed = rows.iter().filter(|r| r.verdict == Verdict::Fail).count();
    let mut text = format_table(&rows);
    text.push_str(&if loaded.black {
        format!("{}: all black, nothing to verify\n", loaded.name)
    } else if failed == 0 {
        format!(
            "{}: all checks passed ({n} samples, seed {})\n",
            loaded.name, args.seed
        )
    } else {
        format!(
            "{}: {failed} check{} FAILED ({n} samples, seed {})\n",
            loaded.name,
            if failed == 1 { "" } else { "s" },
            args.seed
        )
    });
    let mut out = Output::create(None)?;
    out.write_all(text.as_bytes())
        .with_context(|| format!("{}: write failed", out.name()))?;
    out.finish()?;
    Ok(if failed == 0 {
        Outcome::Success
    } else {
        Outcome::ChecksFailed
    })
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Verdict {
    Pass,
    Fail,
    Info,
    Skip,
}

impl Verdict {
    fn from_pass(pass: bool) -> Self {
        if pass {
            Self::Pass
        } else {
            Self::Fail
        }
    }

    fn label(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Fail => "FAIL",
            Self::Info => "info",
            Self::Skip => "skip",
        }
    }
}

struct Row {
    check: String,
    value: String,
    threshold: String,
    verdict: Verdict,
}

impl Row {
    fn new(check: &str, value: impl Into<String>, threshold: &str, verdict: Verdict) -> Self {
        Self {
            check: check.to_string(),
            value: value.into(),
            threshold: threshold.to_string(),
            verdict,
        }
    }
}

/// `check | value | threshold | result`, columns padded to their widest entry.
fn format_table(rows: &[Row]) -> String {
    let header = ["check", "value", "threshold", "result"];
    let cells: Vec<[&str; 4]> = rows
        .iter()
        .map(|r| {
            [
                r.check.as_str(),
                r.value.as_str(),
                r.threshold.as_str(),
                r.verdict.label(),
            ]
        })
        .collect();
    let mut widths = header.map(|h| h.chars().count());
    for row in &cells {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: [&str; 4]| {
        let mut s = String::new();
        for (k, cell) in cells.iter().enumerate() {
            if k > 0 {
                s.push_str(" | ");
            }
            s.push_str(cell);
            if k < 3 {
                s.push_str(&" ".repeat(widths[k] - cell.chars().count()));
            }
        }
        s.push('\n');
        s
    };
    let mut text = line(header);
    let rule: Vec<String> = widths.iter().map(|&w| "-".repeat(w)).collect();
    text.push_str(&rule.join("-+-"));
    text.push('\n');
    for row in cells {
        text.push_str(&line(row));
    }
    text
}

/// Chi-square cells: blocks of `gx × gy` texels.
struct Bins {
    w: usize,
    h: usize,
    gx: usize,
    gy: usize,
    nx: usize,
    ny: usize,
}

impl Bins {
    fn new(w: usize, h: usize, samples: u64) -> Self {
        let target = (samples / CHI2_SAMPLES_PER_CELL).max(1) as f64;
        let texels_per_bin = (w as f64 * h as f64 / target).max(1.0);
        let g = texels_per_bin.sqrt().round().max(1.0) as usize;
        let (gx, gy) = (g.min(w), g.min(h));
        Self {
            w,
            h,
            gx,
            gy,
            nx: w.div_ceil(gx),
            ny: h.div_ceil(gy),
        }
    }

    fn len(&self) -> usize {
        self.nx * self.ny
    }

    /// The cell holding image point `uv`.
    #[inline]
    fn index(&self, uv: [f32; 2]) -> usize {
        let i = ((uv[0] * self.w as f32).max(0.0) as usize).min(self.w - 1);
        let j = ((uv[1] * self.h as f32).max(0.0) as usize).min(self.h - 1);
        (j / self.gy) * self.nx + i / self.gx
    }
}

/// What the quadrature pass found.
struct Quadrature {
    /// Points per texel along u and v.
    points: (usize, usize),
    /// `∫ p dω` per chi-square cell.
    bin_mass: Vec<f64>,
    /// `∫ p dω` over the sphere.
    total: f64,
    /// `∫ Y max(0, z) dω` (scale applied).
    cosine_integral: f64,
    /// `∫ Y dω` by the same quadrature (a cross-check of the library's value).
    luminance_integral: f64,
    /// Texels with luminance > 0 whose centre has pdf 0, and the first of them.
    unsupported: usize,
    first_unsupported: Option<(usize, usize)>,
}

/// Integrates over the texel grid in image (light) space; `pdf()` and `radiance()`
/// are called with the world directions, as a renderer would.
fn quadrature(light: &EnvironmentLight, bins: &Bins) -> Quadrature {
    let (w, h) = (bins.w, bins.h);
    let (kx, ky) = quadrature_points(w, h);
    let progress = Progress::bar(h as u64, "integrating");
    let image = light.image();
    struct RowResult {
        bin_mass: Vec<f64>,
        total: f64,
        cosine: f64,
        luminance: f64,
        unsupported: usize,
        first_unsupported: Option<(usize, usize)>,
    }
    let per_row: Vec<RowResult> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut r = RowResult {
                bin_mass: vec![0.0; bins.nx],
                total: 0.0,
                cosine: 0.0,
                luminance: 0.0,
                unsupported: 0,
                first_unsupported: None,
            };
            let dphi = 2.0 * PI / (kx * w) as f64;
            for t in 0..ky {
                let va = (j * ky + t) as f64 / (ky * h) as f64;
                let vb = (j * ky + t + 1) as f64 / (ky * h) as f64;
                let v = ((va + vb) * 0.5) as f32;
                // Exact solid angle of the sub-cell: Δφ (cos θa - cos θb).
                let d_omega = dphi * ((PI * va).cos() - (PI * vb).cos());
                for i in 0..w {
                    let mut mass = 0.0f64;
                    for s in 0..kx {
                        let u = ((i * kx + s) as f32 + 0.5) / (kx * w) as f32;
                        let d = light.uv_to_direction([u, v]);
                        let p = light.pdf(d) as f64;
                        mass += p * d_omega;
                        let y = luminance(light.radiance(d)) as f64;
                        r.luminance += y * d_omega;
                        r.cosine += y * (d.z as f64).max(0.0) * d_omega;
                    }
                    r.bin_mass[i / bins.gx] += mass;
                    r.total += mass;
                }
            }
            for i in 0..w {
                if luminance(image.texel(i, j)) > 0.0 {
                    let centre = [(i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32];
                    let p = light.pdf(light.uv_to_direction(centre));
                    if p.is_nan() || p <= 0.0 {
                        r.unsupported += 1;
                        r.first_unsupported.get_or_insert((i, j));
                    }
                }
            }
            progress.inc(1);
            r
        })
        .collect();
    progress.finish();
    let mut q = Quadrature {
        points: (kx, ky),
        bin_mass: vec![0.0; bins.len()],
        total: 0.0,
        cosine_integral: 0.0,
        luminance_integral: 0.0,
        unsupported: 0,
        first_unsupported: None,
    };
    for (j, r) in per_row.into_iter().enumerate() {
        let row = j / bins.gy;
        for (b, m) in r.bin_mass.iter().enumerate() {
            q.bin_mass[row * bins.nx + b] += m;
        }
        q.total += r.total;
        q.cosine_integral += r.cosine;
        q.luminance_integral += r.luminance;
        q.unsupported += r.unsupported;
        if q.first_unsupported.is_none() {
            q.first_unsupported = r.first_unsupported;
        }
    }
    q
}

/// Quadrature points per texel along u and v: 4×4 (2×2 above 1M texels), and more
/// on small maps so that the sphere is covered by at least 2048 × 1024 points (the
/// midpoint rule's error in a band of height Δθ is about Δθ²/24 relative). Always
/// even, so that sub-cell boundaries fall on texel centres, where bilinear
/// radiance has its kinks: the rule is then exact for it along u.
fn quadrature_points(w: usize, h: usize) -> (usize, usize) {
    let base = if w.saturating_mul(h) <= 1 << 20 { 4 } else { 2 };
    let even = |k: usize| k + k % 2;
    (
        even(base.max(2048usize.div_ceil(w))),
        even(base.max(1024usize.div_ceil(h))),
    )
}

/// Statistics gathered over the samples.
#[derive(Clone)]
struct SampleStats {
    none: u64,
    pdf_max_rel: f64,
    pdf_bad: u64,
    pdf_edge: u64,
    invert_max: f64,
    invert_bad: u64,
    invert_edge: u64,
    /// Σ Y/p and Σ (Y/p)².
    sum_y: f64,
    sum_y2: f64,
    /// Σ Y cos⁺/p and its square.
    sum_c: f64,
    sum_c2: f64,
    counts: Vec<u64>,
}

impl SampleStats {
    fn new(bins: usize) -> Self {
        Self {
            none: 0,
            pdf_max_rel: 0.0,
            pdf_bad: 0,
            pdf_edge: 0,
            invert_max: 0.0,
            invert_bad: 0,
            invert_edge: 0,
            sum_y: 0.0,
            sum_y2: 0.0,
            sum_c: 0.0,
            sum_c2: 0.0,
            counts: vec![0; bins],
        }
    }

    fn merge(mut self, o: Self) -> Self {
        self.none += o.none;
        self.pdf_max_rel = self.pdf_max_rel.max(o.pdf_max_rel);
        self.pdf_bad += o.pdf_bad;
        self.pdf_edge += o.pdf_edge;
        self.invert_max = self.invert_max.max(o.invert_max);
        self.invert_bad += o.invert_bad;
        self.invert_edge += o.invert_edge;
        self.sum_y += o.sum_y;
        self.sum_y2 += o.sum_y2;
        self.sum_c += o.sum_c;
        self.sum_c2 += o.sum_c2;
        for (a, b) in self.counts.iter_mut().zip(&o.counts) {
            *a += b;
        }
        self
    }
}

/// True when `x` (in cells) is within [`EDGE_TEXELS`] of a cell boundary.
#[inline]
fn near_edge(x: f64) -> bool {
    (x - x.round()).abs() < EDGE_TEXELS
}

/// True within about 0.57° of a pole (sin θ < 0.01). There an `f32` direction pins
/// `z = cos θ` to 6e-8 and so `sin θ`, which the pdf divides by, only to about
/// 6e-8 / sin²θ relative: more than the tolerance. (A set of relative measure 5e-5.)
#[inline]
fn near_pole(v: f32) -> bool {
    (PI * v as f64).sin() < 0.01
}

fn sample_statistics(light: &EnvironmentLight, bins: &Bins, seed: u64, n: u64) -> SampleStats {
    let progress = Progress::bar(n, "sampling");
    let tasks = n.div_ceil(TASK_SAMPLES);
    // Partial results are merged in task order, so sums do not depend on scheduling.
    let partials: Vec<SampleStats> = (0..tasks)
        .into_par_iter()
        .map(|task| {
            let mut st = SampleStats::new(bins.len());
            let start = task * TASK_SAMPLES;
            let end = (start + TASK_SAMPLES).min(n);
            for index in start..end {
                let xi = envlight::rng::xi_2d(seed, index);
                let Some(s) = light.sample(xi) else {
                    st.none += 1;
                    continue;
                };
                let edge = near_edge(s.uv[0] as f64 * bins.w as f64)
                    || near_edge(s.uv[1] as f64 * bins.h as f64)
                    || near_pole(s.uv[1]);
                // Consistency of pdf().
                let p = light.pdf(s.direction) as f64;
                let rel = (p - s.pdf as f64).abs() / s.pdf as f64;
                if rel > PDF_REL_TOL {
                    if edge {
                        st.pdf_edge += 1;
                    } else {
                        st.pdf_bad += 1;
                    }
                }
                if !edge {
                    st.pdf_max_rel = st.pdf_max_rel.max(rel);
                }
                // Round trip through invert().
                let back = light.invert(s.direction);
                let err = ((back[0] - xi[0]).abs().max((back[1] - xi[1]).abs())) as f64;
                if err >= INVERT_TOL {
                    if edge {
                        st.invert_edge += 1;
                    } else {
                        st.invert_bad += 1;
                    }
                }
                if !edge {
                    st.invert_max = st.invert_max.max(err);
                }
                // Fit: the cell of the direction actually returned.
                st.counts[bins.index(light.direction_to_uv(s.direction))] += 1;
                // Unbiasedness.
                let y = luminance(s.radiance) as f64 / s.pdf as f64;
                st.sum_y += y;
                st.sum_y2 += y * y;
                let c = y * (s.direction.z as f64).max(0.0);
                st.sum_c += c;
                st.sum_c2 += c * c;
            }
            progress.inc(end - start);
            st
        })
        .collect();
    progress.finish();
    partials
        .into_iter()
        .fold(SampleStats::new(bins.len()), SampleStats::merge)
}

/// Mean, and standard error of the mean, from Σx and Σx² over n samples.
fn mean_and_error(sum: f64, sum2: f64, n: u64) -> (f64, f64) {
    let n = n as f64;
    let mean = sum / n;
    let variance = (sum2 / n - mean * mean).max(0.0) * n / (n - 1.0).max(1.0);
    (mean, (variance / n).sqrt())
}

/// Compact scientific notation for table values.
fn sci(x: f64) -> String {
    format!("{x:.3e}")
}

/// `x` with `digits` significant digits: fixed notation for moderate magnitudes,
/// scientific otherwise.
fn sig(x: f64, digits: usize) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i64;
    if (-3..6).contains(&magnitude) {
        let decimals = (digits as i64 - 1 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.prec$e}", prec = digits - 1)
    }
}

fn report(
    light: &EnvironmentLight,
    bins: &Bins,
    quad: &Quadrature,
    st: &SampleStats,
    n: u64,
) -> Vec<Row> {
    let mut rows = Vec::new();

    let err = (1.0 - quad.total).abs();
    rows.push(Row::new(
        "normalisation",
        format!(
            "∫p dω = {:.7} ({}×{} points/texel)",
            quad.total, quad.points.0, quad.points.1
        ),
        "|1 - ∫p dω| < 1e-3",
        Verdict::from_pass(err < NORMALISATION_TOL),
    ));

    rows.push(Row::new(
        "pdf consistency",
        format!(
            "max rel err {}; {} mismatches, {} at cell edges/poles",
            sci(st.pdf_max_rel),
            st.pdf_bad,
            st.pdf_edge
        ),
        "rel err ≤ 1e-3 off edges",
        Verdict::from_pass(st.pdf_bad == 0),
    ));

    rows.push(Row::new(
        "invert",
        format!(
            "max |Δξ| {}; {} off, {} at cell edges/poles",
            sci(st.invert_max),
            st.invert_bad,
            st.invert_edge
        ),
        "|Δξ| < 1e-3 off edges",
        Verdict::from_pass(st.invert_bad == 0),
    ));

    rows.push(chi_square_row(bins, quad, st, n));

    let (mean, se) = mean_and_error(st.sum_y, st.sum_y2, n);
    let reference = light.integral_luminance();
    rows.push(unbiased_row("unbiased (Y)", mean, se, reference));
    let (mean, se) = mean_and_error(st.sum_c, st.sum_c2, n);
    rows.push(unbiased_row(
        "unbiased (cos)",
        mean,
        se,
        quad.cosine_integral,
    ));

    rows.push(Row::new(
        "support",
        match quad.first_unsupported {
            None => "every lit texel has pdf > 0".to_string(),
            Some((i, j)) => format!(
                "{} lit texels with pdf 0, first ({i}, {j})",
                quad.unsupported
            ),
        },
        "0 lit texels with pdf 0",
        Verdict::from_pass(quad.unsupported == 0),
    ));

    let efficiency = light.efficiency();
    let (mean, _) = mean_and_error(st.sum_y, st.sum_y2, n);
    let second = st.sum_y2 / n as f64;
    let mc = if second > 0.0 {
        mean * mean / second
    } else {
        0.0
    };
    rows.push(Row::new(
        "efficiency",
        format!("{efficiency:.5} (from samples {mc:.5})"),
        "report only",
        Verdict::Info,
    ));
    rows
}

fn unbiased_row(check: &str, mean: f64, se: f64, reference: f64) -> Row {
    let deviation = (mean - reference).abs();
    // A sliver of relative slack for float rounding in the reference itself.
    let tolerance = SIGMAS * se + 1e-5 * reference.abs();
    let sigmas = if se > 0.0 { deviation / se } else { 0.0 };
    Row::new(
        check,
        format!(
            "{} ± {} vs {} ({:.2}σ)",
            sig(mean, 6),
            sig(se, 2),
            sig(reference, 6),
            sigmas
        ),
        "within 4σ",
        Verdict::from_pass(deviation <= tolerance),
    )
}

fn chi_square_row(bins: &Bins, quad: &Quadrature, st: &SampleStats, n: u64) -> Row {
    let mut chi2 = 0.0f64;
    let mut cells = 0u64;
    let (mut pooled_expected, mut pooled_observed) = (0.0f64, 0u64);
    for (&mass, &observed) in quad.bin_mass.iter().zip(&st.counts) {
        let expected = mass * n as f64;
        if expected < CHI2_MIN_EXPECTED {
            pooled_expected += expected;
            pooled_observed += observed;
        } else {
            let d = observed as f64 - expected;
            chi2 += d * d / expected;
            cells += 1;
        }
    }
    let threshold = "p ≥ 1e-3";
    if pooled_expected > 0.0 {
        let d = pooled_observed as f64 - pooled_expected;
        chi2 += d * d / pooled_expected;
        cells += 1;
    } else if pooled_observed > 0 {
        return Row::new(
            "chi-square",
            format!("{pooled_observed} samples in cells where ∫p dω = 0"),
            threshold,
            Verdict::Fail,
        );
    }
    let grid = format!(
        "{}×{} cells of {}×{} texels",
        bins.nx, bins.ny, bins.gx, bins.gy
    );
    if cells < 2 {
        return Row::new(
            "chi-square",
            format!("all mass in one cell ({grid}), nothing to test"),
            threshold,
            Verdict::Pass,
        );
    }
    let dof = (cells - 1) as f64;
    let p = gamma::chi_square_p_value(chi2, dof);
    Row::new(
        "chi-square",
        format!("p = {p:.4} (χ² = {chi2:.1}, {dof} dof; {grid})"),
        threshold,
        Verdict::from_pass(p >= CHI2_ALPHA),
    )
}
