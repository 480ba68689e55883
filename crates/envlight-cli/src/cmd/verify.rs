//! `envlight verify`: the invariants of DESIGN.md §5, checked on the user's map.
//!
//! Two passes: a quadrature over a lat-long grid of the sphere ([`Grid`]; k×k
//! points per cell, each weighted by the exact solid angle of its sub-cell)
//! integrates `pdf()` per chi-square bin and in total and `Y·cos⁺` for the
//! cosine-lobe reference; support is checked at the centres of the light's own
//! texels; then N samples (counter-based, so the same for any thread count) feed
//! the consistency, round-trip, chi-square and unbiasedness statistics.
//!
//! The grid is the sphere's, not the light's: its points and solid angles come from
//! the equirectangular formulas alone, so the checks do not take the light's
//! mapping (and its Jacobian) on trust. For an equirectangular light it coincides
//! with the light's texel grid, where the rule is exact for a piecewise-constant
//! density; for an equal-area light (texel edges are curves on the grid) cells where
//! the pdf or the luminance varies enough to matter are integrated again with more
//! points ([`refined_points`]).

mod gamma;

use std::f64::consts::PI;
use std::io::Write;

use anyhow::Context;
use envlight::color::luminance;
use envlight::light::Mapping;
use envlight::mapping::{direction_to_equirect, equirect_to_direction};
use envlight::{EnvironmentLight, Rotation, Vec3};
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
  normalisation    ∫p dω over the sphere by quadrature on a lat-long grid of the \
sphere (the map's texel grid for --mapping equirectangular, 2N×N cells for an N×N \
equal-area light; 4×4 points per cell, 2×2 above 1M cells, at least 2048×1024 in all; \
each weighted by its exact solid angle; for equal-area, cells where p or Y varies by \
more than 0.1 expected sample get up to 1024×1024 points): |1 - ∫p dω| < 1e-3.\n\
  pdf consistency  pdf(sample(ξ).ω) equals the sample's pdf to 1e-3 relative, except \
for samples within 1e-3 texel of a cell edge or 0.57° of a pole, where float rounding \
of the direction decides (counted, allowed).\n\
  invert           |invert(sample(ξ).ω) - ξ| < 1e-3, with the same edge allowance \
(skipped for --sampler alias, which has no inverse).\n\
  chi-square       samples binned into about N/20 cells, groups of grid cells, \
expected counts integrated from pdf(), cells expecting < 5 pooled: p-value ≥ 1e-3.\n\
  unbiased (Y)     the mean of Y/p is within 4 standard errors of ∫Y dω (exact).\n\
  unbiased (cos)   the mean of Y·max(0, z)/p is within 4 standard errors of its \
quadrature (a cosine lobe around +z).\n\
  support          every texel of the light's image (the resampled square for an \
equal-area light from a lat-long map) with luminance > 0 has pdf > 0 at its centre.\n\
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
        let grid = Grid::new(light);
        let bins = Bins::new(grid.w, grid.h, n);
        let quad = quadrature(light, &grid, &bins, n);
        let stats = sample_statistics(light, &grid, &bins, args.seed, n);
        rows = report(light, &grid, &bins, &quad, &stats, n);
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

/// The lat-long grid of the sphere that [`quadrature`] integrates over and the
/// chi-square cells are made of: `w × h` cells in `(u, v)` with the equirectangular
/// formulas (`θ = π v`, `φ = 2π u`), in the light's frame. So for an
/// equirectangular light the cells are its texels (where a piecewise-constant
/// density is constant, and the quadrature exact); for an equal-area light of side
/// N it is 2N × N. The frame follows `--rotate` (a turn about +z only shifts φ);
/// `pdf()` and `radiance()` are always asked about world directions.
struct Grid {
    w: usize,
    h: usize,
    /// Light-to-world rotation, `None` for the identity (as the library skips it).
    to_world: Option<Rotation>,
    to_grid: Option<Rotation>,
    /// Whether cells may straddle the light's texel edges, so that the fixed rule
    /// is not exact and varying cells are refined.
    refine: bool,
    /// `∫ Y dω` of the light, for the refinement criterion.
    luminance_integral: f64,
}

impl Grid {
    fn new(light: &EnvironmentLight) -> Self {
        let image = light.image();
        let (w, h, refine) = match light.mapping() {
            Mapping::Equirectangular => (image.width(), image.height(), false),
            Mapping::EqualArea => (2 * image.width(), image.width(), true),
        };
        let rotation = light.options().rotation;
        let identity = rotation.is_identity();
        Self {
            w,
            h,
            to_world: (!identity).then_some(rotation),
            to_grid: (!identity).then(|| rotation.inverse()),
            refine,
            luminance_integral: light.integral_luminance(),
        }
    }

    /// The world direction at grid point `(u, v)`.
    #[inline]
    fn direction(&self, u: f32, v: f32) -> Vec3 {
        let d = equirect_to_direction(u, v).0;
        match &self.to_world {
            Some(r) => r.apply(d),
            None => d,
        }
    }

    /// The grid point looking along the world direction `d`.
    #[inline]
    fn uv(&self, d: Vec3) -> [f32; 2] {
        direction_to_equirect(match &self.to_grid {
            Some(r) => r.apply(d),
            None => d,
        })
    }
}

/// Chi-square cells: blocks of `gx × gy` grid cells.
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

    /// The cell holding grid point `uv`.
    #[inline]
    fn index(&self, uv: [f32; 2]) -> usize {
        let i = ((uv[0] * self.w as f32).max(0.0) as usize).min(self.w - 1);
        let j = ((uv[1] * self.h as f32).max(0.0) as usize).min(self.h - 1);
        (j / self.gy) * self.nx + i / self.gx
    }
}

/// What the quadrature pass found.
struct Quadrature {
    /// Points per grid cell along u and v.
    points: (usize, usize),
    /// Cells integrated again with more points, and the most points per axis.
    refined: usize,
    refined_max: usize,
    /// `∫ p dω` per chi-square cell.
    bin_mass: Vec<f64>,
    /// `∫ p dω` over the sphere.
    total: f64,
    /// `∫ Y max(0, z) dω` (scale applied).
    cosine_integral: f64,
    /// `∫ Y dω` by the same quadrature (a cross-check of the library's value).
    luminance_integral: f64,
    /// Texels of the light's image with luminance > 0 whose centre has pdf 0, and
    /// the first of them.
    unsupported: usize,
    first_unsupported: Option<(usize, usize)>,
}

/// Integrals of one grid cell.
#[derive(Debug, Clone, Copy, Default)]
struct CellSums {
    /// `∫ p dω`, `∫ Y dω`, `∫ Y cos⁺ dω` over the cell.
    mass: f64,
    luminance: f64,
    cosine: f64,
    /// The smallest and largest pdf and luminance at the points.
    p_range: (f64, f64),
    y_range: (f64, f64),
}

/// Integrates `pdf()`, `Y` and `Y cos⁺` over grid cell `(i, j)` with `kx × ky`
/// midpoints, each weighted by the exact solid angle of its sub-cell
/// `Δφ (cos θa − cos θb)`.
fn integrate_cell(
    light: &EnvironmentLight,
    grid: &Grid,
    (i, j): (usize, usize),
    (kx, ky): (usize, usize),
) -> CellSums {
    let (w, h) = (grid.w, grid.h);
    let dphi = 2.0 * PI / (kx * w) as f64;
    let mut c = CellSums {
        p_range: (f64::INFINITY, f64::NEG_INFINITY),
        y_range: (f64::INFINITY, f64::NEG_INFINITY),
        ..Default::default()
    };
    for t in 0..ky {
        let va = (j * ky + t) as f64 / (ky * h) as f64;
        let vb = (j * ky + t + 1) as f64 / (ky * h) as f64;
        let v = ((va + vb) * 0.5) as f32;
        let d_omega = dphi * ((PI * va).cos() - (PI * vb).cos());
        for s in 0..kx {
            let u = ((i * kx + s) as f32 + 0.5) / (kx * w) as f32;
            let d = grid.direction(u, v);
            let p = light.pdf(d) as f64;
            c.mass += p * d_omega;
            let y = luminance(light.radiance(d)) as f64;
            c.luminance += y * d_omega;
            c.cosine += y * (d.z as f64).max(0.0) * d_omega;
            c.p_range = (c.p_range.0.min(p), c.p_range.1.max(p));
            c.y_range = (c.y_range.0.min(y), c.y_range.1.max(y));
        }
    }
    c
}

/// Most quadrature points per axis in a refined cell.
const REFINE_MAX_POINTS: usize = 1024;
/// A cell is refined when the spread of the values around it, times its solid
/// angle, could move this many expected samples out of
/// [`REFINE_MIN_SAMPLES`] or more (see [`refined_points`]).
const REFINE_SAMPLES: f64 = 0.1;
/// The sample count the refinement aims at when fewer are drawn: the
/// normalisation and the cosine reference need the accuracy whatever N is.
const REFINE_MIN_SAMPLES: u64 = 200_000;

/// The smallest and largest pdf and luminance at a cell's points.
type Ranges = [f32; 4];

/// Points per axis for grid cell `(i, j)` when its fixed-rule integral is not to
/// be trusted, or `None` when it is. `ranges` holds every cell's [`Ranges`], row-major.
///
/// A midpoint rule over a cell that a texel edge crosses misplaces up to the
/// jump of the integrand times a sub-cell's solid angle per straddling sub-cell.
/// The jump is bounded by the spread of the values at the points of the cell and
/// its eight neighbours (a bright texel can reach into a cell between its points;
/// it is then seen from a neighbour). In units of expected samples
/// (`N × probability`, and for luminance `N × fraction of ∫Y dω`, the scale of
/// the unbiasedness test's standard error), the cell's risk is
/// `r = N Ω_cell max(Δp, ΔY / ∫Y)` with `N` at least [`REFINE_MIN_SAMPLES`].
/// Above [`REFINE_SAMPLES`] the cell gets `K = √(r / REFINE_SAMPLES)` points per
/// axis (so each straddling sub-cell errs by at most that many samples), capped at
/// [`REFINE_MAX_POINTS`]. The work, `Σ K²`, is at most about `Σ r / 0.1`: a small
/// multiple of `10 N` points.
fn refined_points(
    grid: &Grid,
    ranges: &[Ranges],
    (i, j): (usize, usize),
    k: usize,
    n: u64,
) -> Option<usize> {
    let (w, h) = (grid.w, grid.h);
    let mut lo = [f32::INFINITY; 2];
    let mut hi = [f32::NEG_INFINITY; 2];
    for jj in j.saturating_sub(1)..=(j + 1).min(h - 1) {
        for di in [w - 1, 0, 1] {
            let r = ranges[jj * w + (i + di) % w];
            lo = [lo[0].min(r[0]), lo[1].min(r[2])];
            hi = [hi[0].max(r[1]), hi[1].max(r[3])];
        }
    }
    let cell = 2.0 * PI / w as f64
        * ((PI * j as f64 / h as f64).cos() - (PI * (j + 1) as f64 / h as f64).cos());
    let dp = (hi[0] - lo[0]) as f64;
    let dy = if grid.luminance_integral > 0.0 {
        (hi[1] - lo[1]) as f64 / grid.luminance_integral
    } else {
        0.0
    };
    let r = n.max(REFINE_MIN_SAMPLES) as f64 * cell * dp.max(dy);
    // NaN (a NaN pdf or luminance) is not trusted either.
    if r <= REFINE_SAMPLES {
        return None;
    }
    let points = (r / REFINE_SAMPLES).sqrt().ceil() as usize;
    let points = points.clamp(2 * k, REFINE_MAX_POINTS);
    Some(points + points % 2)
}

/// Per-row sums of the quadrature.
struct RowSums {
    bin_mass: Vec<f64>,
    total: f64,
    cosine: f64,
    luminance: f64,
    refined: usize,
    refined_max: usize,
}

impl RowSums {
    fn new(bins: usize) -> Self {
        Self {
            bin_mass: vec![0.0; bins],
            total: 0.0,
            cosine: 0.0,
            luminance: 0.0,
            refined: 0,
            refined_max: 0,
        }
    }

    /// Adds `sign ×` a cell's integrals (bin column `b`).
    fn add(&mut self, b: usize, c: &CellSums, sign: f64) {
        self.bin_mass[b] += sign * c.mass;
        self.total += sign * c.mass;
        self.luminance += sign * c.luminance;
        self.cosine += sign * c.cosine;
    }
}

/// Integrates over [`Grid`]: `pdf()` per chi-square bin and in total, `Y` and
/// `Y cos⁺`; then checks support at the centres of the light's own texels.
/// `pdf()` and `radiance()` are called with world directions, as a renderer would.
///
/// Pass 1 applies the fixed rule ([`quadrature_points`]) to every cell; where the
/// grid may straddle the light's texels, pass 2 integrates the cells that
/// [`refined_points`] picks again, replacing their pass-1 values.
fn quadrature(light: &EnvironmentLight, grid: &Grid, bins: &Bins, n: u64) -> Quadrature {
    let (w, h) = (grid.w, grid.h);
    let (kx, ky) = quadrature_points(w, h);
    let progress = Progress::bar(h as u64, "integrating");
    let pass1: Vec<(RowSums, Vec<Ranges>)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut r = RowSums::new(bins.nx);
            let mut ranges = Vec::with_capacity(if grid.refine { w } else { 0 });
            for i in 0..w {
                let c = integrate_cell(light, grid, (i, j), (kx, ky));
                r.add(i / bins.gx, &c, 1.0);
                if grid.refine {
                    ranges.push([
                        c.p_range.0 as f32,
                        c.p_range.1 as f32,
                        c.y_range.0 as f32,
                        c.y_range.1 as f32,
                    ]);
                }
            }
            progress.inc(1);
            (r, ranges)
        })
        .collect();
    progress.finish();
    let (mut per_row, ranges): (Vec<RowSums>, Vec<Vec<Ranges>>) = pass1.into_iter().unzip();
    if grid.refine {
        let ranges: Vec<Ranges> = ranges.into_iter().flatten().collect();
        let progress = Progress::bar(h as u64, "refining");
        per_row.par_iter_mut().enumerate().for_each(|(j, r)| {
            for i in 0..w {
                let Some(k) = refined_points(grid, &ranges, (i, j), kx.min(ky), n) else {
                    continue;
                };
                let coarse = integrate_cell(light, grid, (i, j), (kx, ky));
                let fine = integrate_cell(light, grid, (i, j), (k, k));
                r.add(i / bins.gx, &coarse, -1.0);
                r.add(i / bins.gx, &fine, 1.0);
                r.refined += 1;
                r.refined_max = r.refined_max.max(k);
            }
            progress.inc(1);
        });
        progress.finish();
    }
    let mut q = Quadrature {
        points: (kx, ky),
        refined: 0,
        refined_max: 0,
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
        q.refined += r.refined;
        q.refined_max = q.refined_max.max(r.refined_max);
    }
    (q.unsupported, q.first_unsupported) = support(light);
    q
}

/// Texels of the light's own image with luminance > 0 whose centre has pdf 0, and
/// the first of them (row order).
fn support(light: &EnvironmentLight) -> (usize, Option<(usize, usize)>) {
    let image = light.image();
    let (w, h) = (image.width(), image.height());
    let per_row: Vec<(usize, Option<(usize, usize)>)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut count = 0;
            let mut first = None;
            for i in 0..w {
                if luminance(image.texel(i, j)) > 0.0 {
                    let centre = [(i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32];
                    let p = light.pdf(light.uv_to_direction(centre));
                    if p.is_nan() || p <= 0.0 {
                        count += 1;
                        first.get_or_insert((i, j));
                    }
                }
            }
            (count, first)
        })
        .collect();
    let count = per_row.iter().map(|r| r.0).sum();
    (count, per_row.iter().find_map(|r| r.1))
}

/// Quadrature points per grid cell along u and v: 4×4 (2×2 above 1M cells), and
/// more on small grids so that the sphere is covered by at least 2048 × 1024 points (the
/// midpoint rule's error in a band of height Δθ is about Δθ²/24 relative). Always
/// even, so that on an equirectangular light's texel grid sub-cell boundaries fall
/// on texel centres, where bilinear radiance and the bilinear density have their
/// kinks: the rule is then exact for them along u.
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
    /// Samples for which `invert()` gave no answer (the alias sampler).
    invert_none: u64,
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
            invert_none: 0,
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
        self.invert_none += o.invert_none;
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

fn sample_statistics(
    light: &EnvironmentLight,
    grid: &Grid,
    bins: &Bins,
    seed: u64,
    n: u64,
) -> SampleStats {
    let progress = Progress::bar(n, "sampling");
    let (lw, lh) = (light.image().width() as f64, light.image().height() as f64);
    // Only the lat-long mapping divides by sin θ; equal-area has no poles.
    let poles = light.mapping() == Mapping::Equirectangular;
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
                // Texel edges of the light's own image (s.uv is in its mapping).
                let edge = near_edge(s.uv[0] as f64 * lw)
                    || near_edge(s.uv[1] as f64 * lh)
                    || (poles && near_pole(s.uv[1]));
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
                // Round trip through invert(), where the sampler has one.
                match light.invert(s.direction) {
                    Some(back) => {
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
                    }
                    None => st.invert_none += 1,
                }
                // Fit: the grid cell of the direction actually returned.
                st.counts[bins.index(grid.uv(s.direction))] += 1;
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
    grid: &Grid,
    bins: &Bins,
    quad: &Quadrature,
    st: &SampleStats,
    n: u64,
) -> Vec<Row> {
    let mut rows = Vec::new();

    let err = (1.0 - quad.total).abs();
    let points = if grid.refine {
        let mut text = format!(
            "{}×{} points/cell of {}×{}",
            quad.points.0, quad.points.1, grid.w, grid.h
        );
        if quad.refined > 0 {
            text.push_str(&format!(
                ", {} cells up to {m}×{m}",
                quad.refined,
                m = quad.refined_max
            ));
        }
        text
    } else {
        format!("{}×{} points/texel", quad.points.0, quad.points.1)
    };
    rows.push(Row::new(
        "normalisation",
        format!("∫p dω = {:.7} ({points})", quad.total),
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

    let sampled = n - st.none;
    rows.push(if sampled > 0 && st.invert_none == sampled {
        Row::new(
            "invert",
            format!(
                "n/a: the {} sampler has no inverse",
                light.options().sampler.name()
            ),
            "-",
            Verdict::Skip,
        )
    } else {
        Row::new(
            "invert",
            format!(
                "max |Δξ| {}; {} off, {} at cell edges/poles{}",
                sci(st.invert_max),
                st.invert_bad,
                st.invert_edge,
                if st.invert_none > 0 {
                    format!(", {} without an inverse", st.invert_none)
                } else {
                    String::new()
                }
            ),
            "|Δξ| < 1e-3 off edges",
            Verdict::from_pass(st.invert_bad == 0 && st.invert_none == 0),
        )
    });

    rows.push(chi_square_row(grid, bins, quad, st, n));

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

fn chi_square_row(grid: &Grid, bins: &Bins, quad: &Quadrature, st: &SampleStats, n: u64) -> Row {
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
    let layout = format!(
        "{}×{} cells of {}×{} {}",
        bins.nx,
        bins.ny,
        bins.gx,
        bins.gy,
        if grid.refine { "grid cells" } else { "texels" }
    );
    if cells < 2 {
        return Row::new(
            "chi-square",
            format!("all mass in one cell ({layout}), nothing to test"),
            threshold,
            Verdict::Pass,
        );
    }
    let dof = (cells - 1) as f64;
    let p = gamma::chi_square_p_value(chi2, dof);
    Row::new(
        "chi-square",
        format!("p = {p:.4} (χ² = {chi2:.1}, {dof} dof; {layout})"),
        threshold,
        Verdict::from_pass(p >= CHI2_ALPHA),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use envlight::{EnvImage, LightOptions, Lookup};

    /// An equal-area light whose texel edges cross the lat-long grid, with a hot
    /// spot far brighter than the rest: the refined quadrature still integrates
    /// the pdf to 1 and the luminance to the light's exact integral, where the
    /// fixed rule alone is off by more than 1e-3 (the normalisation tolerance).
    #[test]
    fn refined_quadrature_is_accurate_on_an_equal_area_light() {
        let image = EnvImage::from_fn(512, 256, |x, y| {
            if (x, y) == (321, 90) {
                [3e4, 2e4, 1e4]
            } else {
                [
                    0.2 + 0.01 * (x % 5) as f32,
                    0.3,
                    0.4 + 0.02 * (y % 3) as f32,
                ]
            }
        })
        .unwrap();
        for lookup in [Lookup::Nearest, Lookup::Bilinear] {
            let options = LightOptions {
                mapping: Mapping::EqualArea,
                equal_area_size: Some(300),
                lookup,
                ..Default::default()
            };
            let light = EnvironmentLight::new(image.clone(), options).unwrap();
            let grid = Grid::new(&light);
            assert_eq!((grid.w, grid.h, grid.refine), (600, 300, true));
            assert_eq!(quadrature_points(grid.w, grid.h), (4, 4));
            let bins = Bins::new(grid.w, grid.h, 20_000);
            let q = quadrature(&light, &grid, &bins, 20_000);
            assert!(q.refined > 0);
            assert!(
                (q.total - 1.0).abs() < 2e-5,
                "{lookup:?}: ∫p dω = {}",
                q.total
            );
            let exact = light.integral_luminance();
            let rel = (q.luminance_integral / exact - 1.0).abs();
            assert!(
                rel < 1e-4,
                "{lookup:?}: ∫Y dω {} vs {exact}",
                q.luminance_integral
            );
            let mass: f64 = q.bin_mass.iter().sum();
            assert!((mass - q.total).abs() < 1e-12);
            // Without the second pass.
            let coarse = Grid {
                refine: false,
                ..Grid::new(&light)
            };
            let c = quadrature(&light, &coarse, &bins, 20_000);
            assert!(
                (c.total - 1.0).abs() > 1e-3,
                "{lookup:?}: coarse {}",
                c.total
            );
        }
    }
}
