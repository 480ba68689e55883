//! Per-query cost of `sample`, `pdf` and `radiance` against the plain baseline of
//! the benches, interleaved: each round times the baseline and then envlight on the
//! same 4096 queries (warm caches), and the figures are the minimum and the median
//! over the rounds. Interleaving puts both under the same machine noise, and the
//! minimum is what the code costs when nothing else interferes, so the ratios hold
//! on a busy machine where criterion's separate runs drift by ±20%.
//!
//! The batch rows time `pdf_batch` / `radiance_batch` on one thread against the
//! baseline's one-at-a-time queries. The chained rows time queries that cannot
//! overlap (each waits for the one before): the latency of one query, which
//! bounds what a loop of single calls can reach (see BENCHMARKS.md).
//!
//! `cargo run --release --example query_ratios -- [WIDTH] [ROUNDS]` (the built-in
//! sky, WIDTH × WIDTH/2, 4096 by default; 300 rounds).

#[allow(dead_code)] // the benches use more of the baseline than this does
#[path = "../benches/baseline/mod.rs"]
mod baseline;
#[path = "common/queries.rs"]
mod queries;

use baseline::BaselineLight;
use envlight::{builtin, EnvironmentLight, LightOptions, Lookup, Vec3};
use std::hint::black_box;
use std::time::Instant;

const QUERIES: usize = 4096;

/// One timed pass over the queries, returning a checksum.
type Run<'a> = Box<dyn Fn() -> f32 + Sync + 'a>;

fn samples<'a>(light: &'a EnvironmentLight, xi: &'a [[f32; 2]]) -> Run<'a> {
    Box::new(move || queries::sample_all(light, xi))
}

fn radiance<'a>(light: &'a EnvironmentLight, dirs: &'a [Vec3]) -> Run<'a> {
    Box::new(move || dirs.iter().map(|&d| light.radiance(black_box(d))[1]).sum())
}

fn main() {
    let mut args = std::env::args().skip(1);
    let width: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(4096);
    let rounds: usize = args.next().and_then(|s| s.parse().ok()).unwrap_or(300);
    let sky = builtin::sky(width, width / 2);
    let base = BaselineLight::new(sky.clone());
    let light = |lookup| {
        let options = LightOptions {
            lookup,
            ..Default::default()
        };
        EnvironmentLight::new(sky.clone(), options).expect("the built-in sky builds")
    };
    let (bilinear, nearest) = (light(Lookup::Bilinear), light(Lookup::Nearest));
    let xi = queries::xi(99, QUERIES);
    let dirs = queries::directions(&xi);

    println!(
        "{width}x{} sky, {rounds} rounds of {QUERIES} warm queries; ns per query",
        width / 2
    );
    println!(
        "{:<28} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "query", "min", "median", "base min", "base med", "ratio"
    );
    let base_samples = || -> Run {
        Box::new(|| {
            xi.iter()
                .map(|&x| {
                    base.sample(black_box(x))
                        .map_or(0.0, |(d, p, l)| queries::fold(d, p, l))
                })
                .sum()
        })
    };
    let base_pdf = || -> Run { Box::new(|| dirs.iter().map(|&d| base.pdf(black_box(d))).sum()) };
    let base_radiance =
        || -> Run { Box::new(|| dirs.iter().map(|&d| base.radiance(black_box(d))[1]).sum()) };
    let cases: Vec<(&str, Run, Run)> = vec![
        ("sample (bilinear)", base_samples(), samples(&bilinear, &xi)),
        ("sample (nearest)", base_samples(), samples(&nearest, &xi)),
        (
            "pdf",
            base_pdf(),
            Box::new(|| dirs.iter().map(|&d| bilinear.pdf(black_box(d))).sum()),
        ),
        (
            "radiance (bilinear)",
            base_radiance(),
            radiance(&bilinear, &dirs),
        ),
        (
            "radiance (nearest)",
            base_radiance(),
            radiance(&nearest, &dirs),
        ),
        (
            "pdf, chained (latency)",
            chained(|d| base.pdf(d), &dirs),
            chained(|d| bilinear.pdf(d), &dirs),
        ),
        (
            "radiance, chained (latency)",
            chained(|d| base.radiance(d)[1], &dirs),
            chained(|d| bilinear.radiance(d)[1], &dirs),
        ),
        (
            "pdf, batch",
            base_pdf(),
            Box::new(|| {
                let mut out = vec![0.0f32; dirs.len()];
                bilinear.pdf_batch(black_box(&dirs), &mut out);
                out.iter().sum()
            }),
        ),
        (
            "radiance, batch (bilinear)",
            base_radiance(),
            radiance_batch(&bilinear, &dirs),
        ),
        (
            "radiance, batch (nearest)",
            base_radiance(),
            radiance_batch(&nearest, &dirs),
        ),
    ];
    // Everything on one worker thread, where the batch calls run their one chunk
    // in place (from outside the pool they would pay a hand-over each).
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    one_thread.install(|| report(&cases, rounds));
}

/// Queries made one after another, each direction nudged by the previous result
/// (`x + r·0`, which the compiler cannot drop: `r` could be infinite), so that no
/// two overlap: the time of one query's whole dependent chain, plus a
/// multiplication and an addition.
fn chained<'a>(query: impl Fn(Vec3) -> f32 + Sync + 'a, dirs: &'a [Vec3]) -> Run<'a> {
    Box::new(move || {
        let mut r = 0.0f32;
        for &d in dirs {
            r = query(Vec3::new(d.x + r * 0.0, d.y, d.z));
        }
        r
    })
}

fn radiance_batch<'a>(light: &'a EnvironmentLight, dirs: &'a [Vec3]) -> Run<'a> {
    Box::new(move || {
        let mut out = vec![[0.0f32; 3]; dirs.len()];
        light.radiance_batch(black_box(dirs), &mut out);
        out.iter().map(|l| l[1]).sum()
    })
}

/// Times every case, interleaved with its baseline, and prints the table.
fn report(cases: &[(&str, Run, Run)], rounds: usize) {
    for (name, run_base, run_ours) in cases {
        let time = |run: &Run| {
            let started = Instant::now();
            black_box(run());
            started.elapsed().as_secs_f64() * 1e9 / QUERIES as f64
        };
        let (mut ours, mut theirs) = (Vec::new(), Vec::new());
        for _ in 0..rounds {
            theirs.push(time(run_base));
            ours.push(time(run_ours));
        }
        let stats = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            (v[0], v[v.len() / 2])
        };
        let ((min, med), (bmin, bmed)) = (stats(&mut ours), stats(&mut theirs));
        println!(
            "{name:<28} {min:>8.1} {med:>8.1} {bmin:>8.1} {bmed:>8.1} {:>7.2}x",
            bmed / med
        );
    }
}
