//! The statistical invariant harness of docs/design.md §5, written once and run over any
//! sampler of directions on the sphere (Mitsuba 3's chi² harness is the model).
//!
//! A sampler is plugged in by implementing [`SphereSampler`]; what it is meant to
//! follow is an [`Integrand`] (the luminance `Y(ω)` for a light alone, `Y(ω)·f(ω)`
//! for a sampler conditioned on a shading point, docs/design.md §6a). Each check is a
//! plain function returning a typed report that carries the measured numbers,
//! prints as one line, judges itself (`verdict`) and gives one table [`Row`]
//! (measured value, threshold, sample count, pass/fail). [`run`] runs them all.
//! The integration tests, `envlight verify` and `envlight info --normal` all call
//! these functions; no check exists anywhere else.
//!
//! It is a crate of its own rather than a module of `envlight` because it needs
//! `statrs` (the chi-square tail) and `rand`/`rand_pcg`, which a renderer that
//! links the light should not have to build.
//!
//! Independence: everything the harness compares against is computed here, from
//! docs/design.md §2 and the equal-area mapping's documented formulas, and not with the
//! library's own helpers. Its mappings between directions and `(u, v)` are its own
//! `f64` code: equirectangular ([`direction_at`], [`uv_of`]) and the equal-area
//! octahedral square ([`square_to_sphere`], [`sphere_to_square`], derived here by
//! folding the lower hemisphere onto the upper one). Its quadrature uses
//! Gauss-Legendre points in the sampler's own `(u, v)` with the exact measure
//! (`2π² sin θ du dv`, or `4π du dv` on the equal-area square), on a grid that
//! subdivides the sampler's cells (so the pdf's discontinuities fall on quadrature
//! cell edges) and only ever calls the sampler's public `pdf`/`radiance`; its
//! random numbers come from `rand_pcg`, not from `envlight::rng`.
//!
//! Determinism: every check draws `ξ` from PCG streams fixed by the seed and the
//! chunk index, and sums partial results in chunk order, so results do not depend
//! on the number of threads.
//!
//! Batches: the checks ask a sampler for samples, pdfs and radiance only through
//! its batch methods ([`SphereSampler::sample_batch`], `pdf_batch`,
//! `radiance_batch`), one call per chunk of samples ([`over_sample_chunks`]), per
//! row of quadrature points or per set of probes, so a sampler whose single calls
//! are expensive (a GPU dispatch each) costs a few dispatches per check; only
//! `invert` is asked point by point. The batch results must equal the single
//! calls', so the figures are those of the single calls.
//!
//! ```
//! use envlight::{builtin, EnvironmentLight, LightOptions};
//! use envlight_verify::{format_table, run, Config, Integrand};
//!
//! // The built-in sky's light against its own luminance, with a small sample
//! // budget (`envlight verify --samples 20000` asks the same).
//! let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
//! let report = run(&light, &Integrand::luminance(), &Config::with_samples(20_000, 1), &|_| {});
//! assert!(report.failures().is_empty(), "{:?}", report.failures());
//! println!("{}", format_table(&report.rows("inversion")));
//! ```

#![warn(missing_docs)]

#[cfg(test)]
mod batch_self_checks;
mod checks;
mod frame;
mod integrand;
pub mod maps;
mod param;
mod portal;
mod product;
mod quadrature;
mod report;
mod sampler;
#[cfg(test)]
mod self_checks;
mod stats;
mod suite;
mod visibility;

pub use checks::black::{black, Black};
pub use checks::chi_square::{
    chi_square, pearson, ChiSquare, CHI2_QUADRATURE_CELLS, MAX_UNRESOLVED, MIN_EXPECTED,
};
pub use checks::consistency::{consistency, Consistency};
pub use checks::normalisation::{normalisation, Normalisation};
pub use checks::support::{support, Support};
pub use checks::unbiasedness::{
    efficiency, lobe_normals, midpoint_moments, unbiasedness, Efficiency, Estimate,
    MidpointMoments, Reference, Unbiasedness, MASS_RESOLUTION, MAX_LOBES,
};
pub use checks::warp::{chi_square_warp, WarpChiSquare};
pub use integrand::Integrand;
pub use param::{direction_at, sphere_to_square, square_to_sphere, uv_of, Param};
pub use portal::{
    assert_portal_invariants, run_portal, AtPortalPoint, PortalConfig, PortalReport, PortalVariant,
    Quad, PORTAL_EDGE_BAND,
};
pub use product::{product_normals, AtShadingPoint};
pub use quadrature::{gauss_legendre, Needs, Point, Quadrature, FOLD_SPLIT, SPLIT, SPLIT_ANGLE};
pub use report::{format_table, Row, Verdict};
pub use sampler::{Grid, SphereSample, SphereSampler};
pub use stats::{fits, over_points, over_sample_chunks, over_samples, Moments};
pub use suite::{assert_black, assert_invariants, run, Config, Lobes, Report, CHECKS};
pub use visibility::{AtVisibilityPoint, VisibilityVariant};

/// Significance level of every chi-square test: a correct sampler is rejected with
/// probability 1e-3 per case (but seeds are fixed, so a passing case stays passing).
pub const ALPHA: f64 = 1e-3;

/// Normalisation tolerance `|1 - ∫ p dω|` (docs/design.md §5, issue 2).
pub const NORMALISATION_TOLERANCE: f64 = 1e-3;

/// Relative tolerance of `pdf(sample.ω)` against `sample.pdf`, away from the poles,
/// unless [`Config::pdf_tolerance`] says otherwise; see [`pdf_tolerance`].
pub const PDF_CONSISTENCY_TOLERANCE: f64 = 1e-4;

/// Absolute error of `sin θ` computed in f32 from θ or v near the nadir, on each
/// side of the comparison: `π v` rounds to a multiple of `ulp(π) = 2.4e-7`, so
/// `sin(π v) = sin(π - π(1 - v))` is off by up to 1.2e-7 however `sin` is evaluated;
/// `sample` and `pdf` each round once.
pub const SIN_THETA_ABS_ERROR: f64 = 2.4e-7;

/// The allowed relative disagreement between `pdf(sample.ω)` and `sample.pdf` at a
/// direction with the given `sin θ`: `base` (normally [`PDF_CONSISTENCY_TOLERANCE`])
/// plus the f32 precision of `1/sin θ`, [`SIN_THETA_ABS_ERROR`]` / sin θ` (which
/// matters only within ~0.5° of the nadir: it is 1e-4 at `sin θ = 2.4e-3`).
pub fn pdf_tolerance(base: f64, sin_theta: f64) -> f64 {
    base + SIN_THETA_ABS_ERROR / sin_theta
}

/// Absolute tolerance (per coordinate) of `invert(sample(ξ).ω)` against `ξ`. The
/// round trip ξ → (u, v) → ω → (u, v) → ξ loses about 1e-7 in (u, v); the inverse
/// multiplies that by the local density of the marginal or conditional CDF, which
/// is below 1e3 even for a single hot column of a 1024-wide map.
pub const INVERT_TOLERANCE: f64 = 1e-3;

/// Samples closer than this (in u or v units) to a cell edge of the sampler's grid
/// are exempt from the consistency checks, because the pdf jumps there and the f32
/// round trip of a direction moves (u, v) by about 1e-7 (the last bits of u near 1
/// are 6e-8 apart; atan2/acos of an f32 vector add a few more).
pub const EDGE_BAND: f64 = 5e-7;

/// The poles, "up to" which docs/design.md §5 holds: directions with `sin θ` below this
/// (within 1e-4 rad, 0.006°, of a pole; 5e-9 of the sphere) are exempt from the
/// consistency and support checks and from the `∫Y²/p` quadrature. There the
/// solid-angle density diverges, a sample may legitimately be refused, and the f32
/// `sin θ` near the nadir is no better than 0.24%.
pub const POLE_BAND_SIN: f64 = 1e-4;

/// Number of standard errors allowed between a Monte Carlo mean and its
/// reference: a two-sided normal tail of 6.3e-5 per estimate.
pub const Z_TOLERANCE: f64 = 4.0;

/// Relative slack for the reference integrals' quadrature error. The reference is
/// Gauss-Legendre order 3 on sub-cells that split every texel at its centre, where a
/// bilinear (or nearest) reconstruction is a polynomial of degree ≤ 1 in u and the
/// measure `sin θ` is smooth, so the only sizeable error comes from the kink of a
/// cosine lobe (for real maps: order 2 against order 1, see [`unbiasedness`]). The
/// harness measures that error as `|Q3 - Q2|` (orders 3 and 2 on the same cells; an
/// overestimate of Q3's error; measured ≤ 1.5e-5 relative on every case, the
/// largest for a lobe on a real map) and fails when it exceeds this slack (or one
/// standard error, see [`Estimate::quadrature_allowance`]), so the slack is
/// checked, not assumed.
pub const QUADRATURE_SLACK: f64 = 1e-4;
