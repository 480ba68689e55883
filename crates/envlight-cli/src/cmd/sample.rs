//! `envlight sample`: N directions drawn from the light, as CSV.
//!
//! Row `k` uses the sample point `ξ = xi_2d(seed, k)`, a pure function of the seed
//! and the row, so the output is the same whatever the number of threads. Rows are
//! formatted in parallel, in chunks, and written in order.

use std::path::PathBuf;

use rayon::prelude::*;

use super::Outcome;
use crate::csv::{push_row, HEADER, MAX_ROW_BYTES};
use crate::light_args::warn;
use crate::output::{write_bytes, Output};
use crate::progress::Progress;
use crate::query::QueryArgs;

/// Rows formatted by one task.
const CHUNK_ROWS: u64 = 8192;

/// What rows are drawn from: the light or the product sampler, or the portal
/// light at `--at`.
enum Density<'a> {
    Shading(crate::shading::Density<'a>),
    Portal(Box<envlight::portal::PortalPoint<'a>>),
}

impl Density<'_> {
    fn sample(&self, xi: [f32; 2]) -> Option<envlight::LightSample> {
        match self {
            Density::Shading(d) => d.sample(xi),
            Density::Portal(p) => p.sample(xi),
        }
    }

    fn pdf(&self, direction: envlight::Vec3) -> f32 {
        match self {
            Density::Shading(d) => d.pdf(direction),
            Density::Portal(p) => p.pdf(direction),
        }
    }
}

/// Arguments of `envlight sample`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Output: CSV with the header line exactly `x,y,z,pdf,r,g,b`, then one row per sample: \
the world-space unit direction (x, y, z), its solid-angle pdf in sr⁻¹, and the radiance \
(r, g, b) arriving from it. pdf and radiance are evaluated at the direction as written, \
so `envlight eval` on these rows reproduces them exactly. Numbers are the shortest decimals that read back as the \
same 32-bit floats. Row k uses the k-th point of the seed's counter-based sequence, so \
the output depends only on MAP, the light options, N and the seed (not on the thread \
count). An all-black map has pdf 0 and radiance 0 on every row. With --normal the \
directions come from the product sampler for that surface normal and pdf is its density \
(rows where nothing lit faces the surface have pdf 0). With --portal (repeatable) and --at \
the directions go from the point --at through the portals only, and pdf is the portal light's \
density there (rows with no sample, when nothing lit is seen through a portal, have pdf 0).\n\n\
With --device gpu the rows come from the GPU (the same ξ, drawn on the device), in the \
same format: they agree with the CPU's to about 1e-4 rad in direction and 1e-3 in pdf and \
radiance (docs/gpu.md); a row whose direction rounds into a cell of zero density has \
pdf 0.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    query: QueryArgs,

    /// Number of directions to draw.
    #[arg(short = 'n', value_name = "N")]
    count: u64,

    /// Seed of the sample sequence.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,

    /// Write the CSV to FILE (atomically: all or nothing) instead of stdout.
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    output: Option<PathBuf>,
}

/// Runs `envlight sample`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    args.query.check()?;
    let query = args.query.open()?;
    let light = query.light();
    let loaded = &query.loaded;
    let density = match &query.portals {
        Some((pl, at)) => Density::Portal(Box::new(pl.at(*at))),
        None => Density::Shading(crate::shading::Density::new(
            light,
            query.product.as_ref(),
            args.query.normal(),
        )),
    };
    let mut out = Output::create(args.output.as_deref())?;
    write_bytes(&mut out, format!("{HEADER}\n").as_bytes())?;

    let progress = Progress::bar(args.count, "sampling");
    let failed = match &query.gpu {
        Some(gpu) => write_gpu_rows(gpu, args, &mut out, &progress)?,
        None => write_cpu_rows(light, &density, args, &mut out, &progress)?,
    };
    progress.finish();
    out.finish()?;
    if failed > 0 && !loaded.black && query.portals.is_some() {
        warn(&format!(
            "{}: {failed} of {} sample points gave no direction (nothing lit is seen \
             through the portals from --at, or the point fell outside a portal that is \
             not a parallelogram); written with pdf 0 and radiance 0",
            loaded.name, args.count
        ));
    } else if failed > 0 && !loaded.black && args.query.normal().is_some() {
        warn(&format!(
            "{}: {failed} of {} sample points gave no direction (a pole, or no light \
             above the surface); written with pdf 0 and radiance 0",
            loaded.name, args.count
        ));
    } else if failed > 0 && !loaded.black {
        warn(&format!(
            "{}: {failed} of {} sample points fell where the density is 0 (a pole); \
             written with pdf 0 and radiance 0",
            loaded.name, args.count
        ));
    }
    Ok(Outcome::Success)
}

/// Writes the CPU's rows; returns how many had no sample.
fn write_cpu_rows(
    light: &envlight::EnvironmentLight,
    density: &Density,
    args: &Args,
    out: &mut Output,
    progress: &Progress,
) -> anyhow::Result<u64> {
    let chunks = args.count.div_ceil(CHUNK_ROWS);
    // A few chunks per thread per batch keeps every thread busy while bounding
    // the memory held by formatted, unwritten rows.
    let batch = (rayon::current_num_threads() as u64 * 4).max(1);
    let mut failed = 0u64;
    let mut first = 0u64;
    while first < chunks {
        let last = (first + batch).min(chunks);
        let buffers: Vec<(Vec<u8>, u64)> = (first..last)
            .into_par_iter()
            .map(|chunk| {
                let start = chunk * CHUNK_ROWS;
                let end = (start + CHUNK_ROWS).min(args.count);
                let rows = format_rows(light, density, args.seed, start..end);
                progress.inc(end - start);
                rows
            })
            .collect();
        for (bytes, misses) in &buffers {
            write_bytes(out, bytes)?;
            failed += misses;
        }
        first = last;
    }
    Ok(failed)
}

/// Rows drawn by one GPU dispatch.
const GPU_ROWS: u64 = 1 << 20;

/// Writes the GPU's rows, the `ξ` drawn on the device from the same seed;
/// returns how many had no sample.
fn write_gpu_rows(
    gpu: &envlight_gpu::GpuLight,
    args: &Args,
    out: &mut Output,
    progress: &Progress,
) -> anyhow::Result<u64> {
    let mut failed = 0u64;
    let mut first = 0u64;
    while first < args.count {
        let n = (args.count - first).min(GPU_ROWS);
        let samples = gpu.sample_seeded(args.seed, first, n as usize)?;
        let buffers: Vec<Vec<u8>> = samples
            .par_chunks(CHUNK_ROWS as usize)
            .map(|chunk| {
                let mut buf = Vec::with_capacity(chunk.len() * MAX_ROW_BYTES);
                let mut fmt = ryu::Buffer::new();
                for s in chunk {
                    push_row(&mut buf, &mut fmt, s.direction, s.pdf, s.radiance);
                }
                buf
            })
            .collect();
        for bytes in &buffers {
            write_bytes(out, bytes)?;
        }
        failed += samples.iter().filter(|s| !s.is_valid()).count() as u64;
        progress.inc(n);
        first += n;
    }
    Ok(failed)
}

/// Formats rows `range`; returns the bytes and how many rows had no sample.
fn format_rows(
    light: &envlight::EnvironmentLight,
    density: &Density,
    seed: u64,
    range: std::ops::Range<u64>,
) -> (Vec<u8>, u64) {
    let mut buf = Vec::with_capacity((range.end - range.start) as usize * MAX_ROW_BYTES);
    let mut fmt = ryu::Buffer::new();
    let mut misses = 0;
    for k in range {
        let xi = envlight::rng::xi_2d(seed, k);
        match density.sample(xi) {
            Some(s) => {
                // Every value is evaluated at the direction as written (f32), exactly
                // as `eval` does, so feeding the rows back gives identical numbers.
                // The sampler's own uv differs from the written direction's by float
                // rounding, which shifts a bilinear lookup on a steep edge (a sun) by
                // up to ~1e-4 relative. Only if rounding lands in a zero cell (pdf()
                // says "no sample" for a real one) keep the sampler's values.
                let d = s.direction;
                let pdf = density.pdf(d);
                let (pdf, radiance) = if pdf > 0.0 {
                    (pdf, light.radiance(d))
                } else {
                    (s.pdf, s.radiance)
                };
                push_row(&mut buf, &mut fmt, d.to_array(), pdf, radiance)
            }
            None => {
                // No sample (black map, or ξ on a pole): still a row, so row k always
                // belongs to ξ_k: the direction of the image point ξ, pdf 0.
                misses += 1;
                let d = light.uv_to_direction(xi).to_array();
                push_row(&mut buf, &mut fmt, d, 0.0, [0.0; 3]);
            }
        }
    }
    (buf, misses)
}
