//! `envlight verify`: the invariants of docs/design.md §5, checked on the user's map by
//! the library's harness (`envlight-verify`); this file only parses arguments,
//! shows progress and prints the harness's table.

use std::io::Write;

use anyhow::Context;
use envlight::Factor;
use envlight_verify::{
    format_table, run_portal, AtPortalPoint, AtShadingPoint, Config, Integrand, Lobes,
    PortalConfig, Reference, Row, SphereSampler, Verdict,
};

use super::Outcome;
use crate::output::Output;
use crate::progress::Progress;
use crate::query::QueryArgs;

/// Arguments of `envlight verify`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Checks (docs/design.md §5), printed as a table `check | value | threshold | result`; the \
exit status is 1 when any check fails. Quadrature and bins follow the light's own cell grid \
(its texels, or the equal-area square's), in the harness's own mapping code, each point \
weighted by the exact measure (2π² sin θ du dv, or 4π du dv):\n\
  normalisation    ∫p dω over the sphere, 2×2 Gauss-Legendre points per cell (cells split \
until at least 256×128): |1 - ∫p dω| < 1e-3.\n\
  pdf consistency  pdf(sample(ξ).ω) equals the sample's pdf to 1e-3 relative, except for \
samples within 5e-7 of a cell edge or 1e-4 rad of a pole, where float rounding of the \
direction decides (exempt, and allowed only as a tiny fraction).\n\
  invert           |invert(sample(ξ).ω) - ξ| < 1e-3 with the same exemption (skipped for \
--sampler alias, which has no inverse).\n\
  chi-square       samples binned into about N/20 bins (groups of cells), expected counts \
integrated from pdf(), bins expecting < 5 pooled: p-value ≥ 1e-3.\n\
  unbiased (Y)     the mean of Y/p is within 4 standard errors (plus 1e-4 relative for the \
quadrature) of ∫Y dω by the midpoint rule on every cell split in four (exact for bilinear \
radiance).\n\
  unbiased (cos)   the same for Y·max(0, z)/p (a cosine lobe around +z).\n\
  support          p > 0 wherever L > 0, probed at every cell's centre and 2% in from its \
corners.\n\
  efficiency       (∫Y dω)² / ∫(Y²/p) dω, reported only (1 means pdf ∝ luminance).\n\
With --normal the checks run on the product sampler for that surface normal, against \
its integrand Y·max(0, n·ω) instead of Y (the `unbiased` rows name it), and `invert` is \
skipped (it has no inverse).\n\n\
With --device gpu every sample, pdf and radiance the checks see is computed on the GPU \
(the light's cell grid and its claimed ∫Y dω come from the tables); `invert` is \
skipped (a CPU query).\n\n\
With --portal (repeatable) and --at the checks run on the portal light at that point, \
with every integral taken over the portals' own areas (a 192×192 patch grid per portal, \
3×3 Gauss-Legendre points per cell, checked against 2×2): through a portal (no sample \
misses every portal, up to 1e-5 of an edge), pdf 0 elsewhere (N uniform probe \
directions through no portal), normalisation (|1 - ∫p dω| < 1e-3 plus the quadrature's \
|Q3 - Q2|; for a quad that is not a parallelogram ∫p must equal the fraction of samples \
accepted), pdf consistency, chi-square on 16×16 bins per portal, unbiased (Y) against \
∫ Y dω over the portals, support at the quadrature points, efficiency.\n\n\
An all-black map has nothing to check, nor a normal that no light faces, nor a point that \
sees nothing lit through its portals: the checks are skipped.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    query: QueryArgs,

    /// Number of sample directions (for each sampling check).
    #[arg(long, value_name = "N", default_value_t = 200_000,
          value_parser = clap::value_parser!(u64).range(100..))]
    samples: u64,

    /// Seed of the sample sequence.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
}

/// Relative tolerance of `pdf(sample.ω)` against the sample's pdf: looser than
/// the test suite's 1e-4, because user maps may be far wider than the tests'.
const PDF_TOLERANCE: f64 = 1e-3;

/// Runs `envlight verify`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    args.query.check()?;
    let query = args.query.open()?;
    let light = query.light();
    let loaded = &query.loaded;
    let n = args.samples as usize;
    let at_portals = query
        .portals
        .as_ref()
        .map(|(pl, at)| AtPortalPoint::new(pl, *at));
    let unseen = at_portals.as_ref().is_some_and(|a| a.power() <= 0.0);
    let on_gpu = query
        .gpu
        .as_ref()
        .zip(SphereSampler::grid(light.as_ref()))
        .map(|(g, grid)| envlight_gpu::GpuSphereSampler::new(g, grid));
    let at = query
        .product
        .as_ref()
        .zip(args.query.normal())
        .map(|(p, normal)| AtShadingPoint::new(p, Factor::cosine(normal)));
    let unlit = at.as_ref().is_some_and(|a| !a.samples_anything());
    let skipped = |why: &str| -> Vec<Row> {
        envlight_verify::CHECKS
            .into_iter()
            .map(|check| Row::new(check, why, "-", 0, Verdict::Skip))
            .collect()
    };
    let rows: Vec<Row> = if loaded.black {
        skipped("map is all black")
    } else if unseen {
        skipped("nothing lit is seen through the portals from --at")
    } else if let Some(a) = &at_portals {
        let config = PortalConfig {
            samples: n,
            consistency_samples: n,
            probes: n,
            seed: args.seed,
            ..PortalConfig::SYNTHETIC
        };
        let progress = Progress::spinner("verifying through the portals");
        let report = run_portal(a, &config);
        progress.finish();
        report.rows()
    } else if unlit {
        skipped("no light faces the surface")
    } else {
        let config = Config {
            pdf_tolerance: PDF_TOLERANCE,
            lobes: Lobes::Zenith,
            reference: Reference::Midpoint,
            ..Config::with_samples(n, args.seed)
        };
        let (sampler, integrand, name): (&dyn SphereSampler, Integrand, &str) = match (&at, &on_gpu)
        {
            (Some(a), _) => (a, a.integrand(), "product"),
            (None, Some(g)) => (g, Integrand::luminance(), "gpu"),
            (None, None) => (
                light.as_ref(),
                Integrand::luminance(),
                light.options().sampler.name(),
            ),
        };
        let progress = Progress::bar(5, "verifying");
        let report = envlight_verify::run(sampler, &integrand, &config, &|step| {
            progress.set_message(step);
            progress.inc(1);
        });
        progress.finish();
        if let Some(e) = on_gpu.as_ref().and_then(|g| g.error()) {
            anyhow::bail!("{}: the GPU failed while verifying: {e}", loaded.name);
        }
        report.rows(name)
    };

    let failed = rows.iter().filter(|r| r.verdict == Verdict::Fail).count();
    let mut text = format_table(&rows);
    text.push_str(&if loaded.black {
        format!("{}: all black, nothing to verify\n", loaded.name)
    } else if unseen {
        format!(
            "{}: nothing lit is seen through the portals from --at, nothing to verify\n",
            loaded.name
        )
    } else if unlit {
        format!(
            "{}: no light faces the surface, nothing to verify\n",
            loaded.name
        )
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
