//! The Rust side of `benches/peers/mitsuba_peer.py`, without Python: the same
//! synthetic maps (a sky gradient plus a 1° sun holding ~91% of the power), the
//! batch calls on one thread, 2²⁰ directions per query, best of several rounds, ns
//! per direction for each density (and the best of as many builds, in ms). For iterating on the batch kernels between peer
//! runs; the peer table itself comes from the Python script.
//!
//! `RAYON_NUM_THREADS=1 cargo run --release --example peer_queries -- [WIDTH ...]
//! [DENSITY ...] [sample|pdf|radiance ...]` (1024 2048 4096, both densities and
//! all three queries by default).

#[path = "common/sun_sky.rs"]
mod sun_sky;

use envlight::light::Density;
use envlight::{EnvironmentLight, LightOptions, LightSample, Vec3};
use std::time::Instant;
use sun_sky::synthetic;

const N: usize = 1 << 20;
const ROUNDS: usize = 7;

/// ns per direction of each of `runs`, over `ROUNDS` rounds that each time every
/// run once, in turn (so all see the same machine noise): the best of each and,
/// for each run, the median of its ratio to the first run in the same round.
fn timed_together(runs: &mut [&mut dyn FnMut()]) -> Vec<(f64, f64)> {
    let mut times = vec![Vec::new(); runs.len()];
    for _ in 0..ROUNDS {
        for (run, t) in runs.iter_mut().zip(&mut times) {
            let start = Instant::now();
            run();
            t.push(start.elapsed().as_secs_f64() * 1e9 / N as f64);
        }
    }
    let median = |mut x: Vec<f64>| {
        x.sort_by(f64::total_cmp);
        x[x.len() / 2]
    };
    times
        .iter()
        .map(|t| {
            let best = t.iter().copied().fold(f64::INFINITY, f64::min);
            let ratios = t.iter().zip(&times[0]).map(|(a, b)| a / b).collect();
            (best, median(ratios))
        })
        .collect()
}

/// [`timed_together`] of `runs` when `timed`; otherwise each run once, untimed
/// (its figures NaN).
fn timed_if(timed: bool, runs: &mut [&mut dyn FnMut()]) -> Vec<(f64, f64)> {
    if timed {
        return timed_together(runs);
    }
    for run in runs.iter_mut() {
        run();
    }
    vec![(f64::NAN, f64::NAN); runs.len()]
}

/// [`timed_if`] of one batch call per light: `call(k, light, out)` writes what
/// `lights[k]` gives into `outs[k]`.
fn time_batches<T>(
    timed: bool,
    lights: &[EnvironmentLight],
    outs: &mut [T],
    call: impl Fn(usize, &EnvironmentLight, &mut T),
) -> Vec<(f64, f64)> {
    let call = &call;
    let mut runs: Vec<Box<dyn FnMut() + '_>> = Vec::new();
    for (k, (light, out)) in lights.iter().zip(outs.iter_mut()).enumerate() {
        runs.push(Box::new(move || call(k, light, out)));
    }
    timed_if(
        timed,
        &mut runs.iter_mut().map(|r| &mut **r as _).collect::<Vec<_>>(),
    )
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut widths: Vec<usize> = args.iter().filter_map(|s| s.parse().ok()).collect();
    let queries = ["sample", "pdf", "radiance"];
    let only: Vec<&String> = args
        .iter()
        .filter(|s| s.parse::<usize>().is_err() && !queries.contains(&s.as_str()))
        .collect();
    // Queries named on the command line (all three by default) are timed; the
    // others run once, untimed, where a later query needs their output.
    let chosen: Vec<&str> = queries
        .into_iter()
        .filter(|q| args.iter().any(|a| a == q))
        .collect();
    let timed = |q: &str| chosen.is_empty() || chosen.contains(&q);
    if widths.is_empty() {
        widths = vec![1024, 2048, 4096];
    }
    println!("{N} directions per query, best of {ROUNDS} rounds; ns per direction");
    println!("(in brackets: the median over rounds of the time / piecewise-constant's)");
    println!("| density | map | build ms | sample | pdf | radiance |");
    println!("|---|---|---|---|---|---|");
    let mut rng = envlight::rng::SplitMix64::new(1);
    let xi: Vec<[f32; 2]> = (0..N).map(|_| [rng.next_f32(), rng.next_f32()]).collect();
    let densities: Vec<Density> = [Density::PiecewiseConstant, Density::PiecewiseBilinear]
        .into_iter()
        .filter(|d| only.is_empty() || only.iter().any(|o| *o == d.name()))
        .collect();
    for w in widths {
        let image = synthetic(w, w / 2);
        let mut builds = Vec::new();
        let lights: Vec<EnvironmentLight> = densities
            .iter()
            .map(|&density| {
                let options = LightOptions {
                    density,
                    ..Default::default()
                };
                // The best of ROUNDS builds (the image copied outside the timing).
                let mut best = f64::INFINITY;
                let mut light = None;
                for _ in 0..ROUNDS {
                    let copy = image.clone();
                    let start = Instant::now();
                    light = Some(EnvironmentLight::new(copy, options).expect("a light"));
                    best = best.min(start.elapsed().as_secs_f64() * 1e3);
                }
                builds.push(best);
                light.expect("ROUNDS > 0")
            })
            .collect();
        let mut samples: Vec<Vec<Option<LightSample>>> = vec![vec![None; N]; lights.len()];
        let sample = time_batches(timed("sample"), &lights, &mut samples, |_, light, out| {
            light.sample_batch(&xi, out)
        });
        // Each density's own samples are its pdf and radiance queries.
        let dirs: Vec<Vec<Vec3>> = samples
            .iter()
            .map(|s| {
                s.iter()
                    .map(|s| s.map_or(Vec3::new(0.0, 0.0, 1.0), |s| s.direction))
                    .collect()
            })
            .collect();
        let mut pdfs = vec![vec![0.0f32; N]; lights.len()];
        let pdf = time_batches(timed("pdf"), &lights, &mut pdfs, |k, light, out| {
            light.pdf_batch(&dirs[k], out)
        });
        let mut radiance = vec![vec![[0.0f32; 3]; N]; lights.len()];
        let rad = time_batches(
            timed("radiance"),
            &lights,
            &mut radiance,
            |k, light, out| light.radiance_batch(&dirs[k], out),
        );
        let cell = |(best, ratio): (f64, f64)| format!("{best:.1} [{ratio:.2}×]");
        for (k, density) in densities.iter().enumerate() {
            println!(
                "| {} | {w}×{} | {:.1} | {} | {} | {} |",
                density.name(),
                w / 2,
                builds[k],
                cell(sample[k]),
                cell(pdf[k]),
                cell(rad[k])
            );
        }
    }
}
