//! Runs many `pdf`, `radiance` and `sample` queries on the built-in sky, for
//! profilers (`valgrind --tool=callgrind`, `perf stat`): `cargo run --release
//! --example query_profile -- [pdf|radiance|sample|build|pdf-batch|radiance-batch] [N] [WIDTH] [hot]` (the sky is
//! WIDTH × WIDTH/2, 256 wide by default; `hot` cycles through 4096 queries, so the
//! data they touch stays in cache, instead of drawing every query afresh). The
//! queries are generated before the clock starts, and every output of a sample is
//! folded into the printed sum so that none of it can be skipped. `build` times N
//! builds of the sky (N small) and prints the best.

#[allow(dead_code)] // query_ratios and the benches use more of it than this does
#[path = "common/queries.rs"]
mod queries;

use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
use std::hint::black_box;

fn main() {
    let mut args = std::env::args().skip(1);
    let what = args.next().unwrap_or_else(|| "pdf".to_string());
    let n: usize = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let width: usize = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(256)
        .max(2);
    let sky = builtin::sky(width, width / 2);
    if what == "build" {
        // N builds of the sky, each from its own copy made outside the clock.
        let mut ms = f64::INFINITY;
        for _ in 0..n {
            let copy = sky.clone();
            let started = std::time::Instant::now();
            black_box(one_build(copy));
            ms = ms.min(started.elapsed().as_secs_f64() * 1e3);
        }
        println!("build x {n}: best {ms:.2} ms");
        return;
    }
    let light =
        EnvironmentLight::new(sky, LightOptions::default()).expect("the built-in sky builds");
    let hot = args.next().as_deref() == Some("hot");
    let distinct = if hot { n.min(4096) } else { n };
    let xi = queries::xi(1, distinct);
    let directions = queries::directions(&xi);
    if let Some(batch) = what.strip_suffix("-batch") {
        // `pdf-batch` / `radiance-batch`: the batch calls over the queries, N in all.
        let started = std::time::Instant::now();
        let (mut pdfs, mut radiance) = (vec![0.0f32; distinct], vec![[0.0f32; 3]; distinct]);
        for _ in 0..n / distinct {
            match batch {
                "radiance" => light.radiance_batch(&directions, &mut radiance),
                _ => light.pdf_batch(&directions, &mut pdfs),
            }
            black_box((&pdfs, &radiance));
        }
        let ns = started.elapsed().as_secs_f64() * 1e9 / n.max(1) as f64;
        println!("{what} x {n}: {ns:.1} ns per direction");
        return;
    }
    let started = std::time::Instant::now();
    let mut acc = 0.0f32;
    for k in 0..n {
        let k = k % distinct;
        acc += match what.as_str() {
            "sample" => one_sample(&light, xi[k]),
            "radiance" => one_radiance(&light, directions[k]),
            _ => one_pdf(&light, directions[k]),
        };
    }
    let ns = started.elapsed().as_secs_f64() * 1e9 / n.max(1) as f64;
    println!(
        "{what} x {n}: {:.1} ns per call (sum {})",
        ns,
        black_box(acc)
    );
}

// One query each, kept out of line so that a profiler can attribute (and callgrind
// can collect, with `--toggle-collect=query_profile::one_*`) exactly its cost.

#[inline(never)]
fn one_build(image: envlight::EnvImage) -> EnvironmentLight {
    EnvironmentLight::new(image, LightOptions::default()).expect("the built-in sky builds")
}

#[inline(never)]
fn one_sample(light: &EnvironmentLight, xi: [f32; 2]) -> f32 {
    light.sample(xi).map_or(0.0, queries::fold_sample)
}

#[inline(never)]
fn one_radiance(light: &EnvironmentLight, direction: Vec3) -> f32 {
    light.radiance(direction)[1]
}

#[inline(never)]
fn one_pdf(light: &EnvironmentLight, direction: Vec3) -> f32 {
    light.pdf(direction)
}
