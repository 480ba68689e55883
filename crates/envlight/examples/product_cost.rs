//! Per-shading-point cost of product sampling against one light-only sample, on
//! one thread: `cargo run --release -p envlight --example product_cost [-- MAP]`.
//!
//! Rows (ns per shading point, the best of several rounds over 65 536 points with
//! random normals and ξ):
//! - `light sample`: one `EnvironmentLight::sample` (the yardstick);
//! - `light sample + pdf`: that plus one `pdf` (what a renderer's MIS pays);
//! - `product at + sample + pdf`: a new shading point (`ShadingPoint::set_factor`),
//!   one product sample and one product pdf;
//! - `product sample + pdf, point reused`: the same shading point for 16 samples;
//! - `product sample_batch + pdf_batch`: the batch calls, one factor per point;
//! - per GGX roughness, with the default options: the glossy tables' build (on
//!   first use) and a new glossy shading point (random normal and outgoing
//!   direction above it), one sample and one pdf.
//!
//! `GLOSSY_ONLY=1` skips the grid rows (to profile the glossy points alone);
//! `CONSTANT=1` builds the light with the piecewise-constant density instead of
//! the default piecewise-bilinear one.

use envlight::light::Density;
use envlight::load::{load, LoadOptions};
use envlight::{
    builtin, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, ShadingPoint,
    Vec3,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

const POINTS: usize = 1 << 16;
const ROUNDS: usize = 7;

fn best(mut f: impl FnMut() -> f64) -> f64 {
    (0..ROUNDS).map(|_| f()).fold(f64::INFINITY, f64::min)
}

/// ns per shading point, the best of `ROUNDS`: at each ξ of `xi`, `point` set to
/// `factor(k)` (the k-th ξ's), one sample and its pdf.
fn sample_pdf<'f>(
    point: &mut ShadingPoint,
    xi: &[[f32; 2]],
    factor: impl Fn(usize) -> &'f Factor,
) -> f64 {
    best(|| {
        let start = Instant::now();
        for (k, x) in xi.iter().enumerate() {
            point.set_factor(factor(k));
            if let Some(s) = point.sample(*x) {
                black_box(point.pdf(s.direction));
            }
        }
        start.elapsed().as_secs_f64() * 1e9 / xi.len() as f64
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let image = match std::env::args().nth(1) {
        Some(path) => load(path.as_ref(), &LoadOptions::default())?.image,
        None => builtin::sky(1024, 512),
    };
    let density = if std::env::var_os("CONSTANT").is_some() {
        Density::PiecewiseConstant
    } else {
        Density::PiecewiseBilinear
    };
    let options = LightOptions {
        density,
        ..Default::default()
    };
    let light = Arc::new(EnvironmentLight::new(image, options)?);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut rng = envlight::rng::SplitMix64::new(7);
    let normals: Vec<Vec3> = (0..POINTS)
        .map(|_| envlight::math::uniform_sphere([rng.next_f32(), rng.next_f32()]))
        .collect();
    let xi: Vec<[f32; 2]> = (0..POINTS)
        .map(|_| [rng.next_f32(), rng.next_f32()])
        .collect();
    let factors: Vec<Factor> = normals.iter().map(|&n| Factor::cosine(n)).collect();
    let per_point = |start: Instant| start.elapsed().as_secs_f64() * 1e9 / POINTS as f64;

    let light_sample = best(|| {
        let start = Instant::now();
        for x in &xi {
            black_box(light.sample(*x));
        }
        per_point(start)
    });
    let light_sample_pdf = best(|| {
        let start = Instant::now();
        for x in &xi {
            if let Some(s) = light.sample(*x) {
                black_box(light.pdf(s.direction));
            }
        }
        per_point(start)
    });
    println!("light sample: {light_sample:.1} ns; light sample + pdf: {light_sample_pdf:.1} ns");

    let grids = if std::env::var_os("GLOSSY_ONLY").is_some() {
        vec![]
    } else {
        vec![
            (8, [128, 64]),
            (16, [64, 32]),
            (16, [128, 64]),
            (32, [64, 32]),
            (32, [128, 64]),
        ]
    };
    for (grid, patches) in grids {
        let options = ProductOptions {
            normal_grid: Some(grid),
            patches: Some(patches),
            ..Default::default()
        };
        let started = Instant::now();
        let sampler = ProductSampler::new(light.clone(), options);
        let build_ms = started.elapsed().as_secs_f64() * 1e3;
        let mut point = sampler.at(&factors[0]);
        let fresh = sample_pdf(&mut point, &xi, |k| &factors[k]);
        let reused = sample_pdf(&mut point, &xi, |k| &factors[k / 16]);
        let mut out = vec![None; POINTS];
        let mut pdfs = vec![0.0f32; POINTS];
        let batch = best(|| {
            pool.install(|| {
                let start = Instant::now();
                sampler.sample_batch(&factors, &xi, &mut out);
                let dirs: Vec<Vec3> = out
                    .iter()
                    .map(|s| s.map_or(Vec3::new(0.0, 0.0, 1.0), |s| s.direction))
                    .collect();
                sampler.pdf_batch(&factors, &dirs, &mut pdfs);
                per_point(start)
            })
        });
        println!(
            "normal grid {grid:>2}, {}x{} patches ({} tables, {:.1} MB, built in {build_ms:.0} ms): \
             product at + sample + pdf {fresh:.0} ns ({:.1}x light sample), \
             point reused for 16 samples {reused:.0} ns ({:.1}x), batch {batch:.0} ns ({:.1}x)",
            patches[0],
            patches[1],
            sampler.table_count(),
            sampler.memory_bytes() as f64 / 1e6,
            fresh / light_sample,
            reused / light_sample,
            batch / light_sample
        );
    }
    let sampler = ProductSampler::new(light.clone(), ProductOptions::default());
    let mut point = sampler.at(&factors[0]);
    for alpha in [0.02f32, 0.08, 0.16, 0.25, 0.32] {
        let glossy: Vec<Factor> = normals
            .iter()
            .zip(xi.iter())
            .map(|(&n, x)| {
                let o = envlight::math::uniform_sphere([x[1], x[0]]);
                let o = if o.dot(n) < 0.0 { o * -1.0 } else { o };
                Factor::glossy(n, o, alpha)
            })
            .collect();
        let started = Instant::now();
        point.set_factor(&glossy[0]);
        let build_ms = started.elapsed().as_secs_f64() * 1e3;
        let fresh = sample_pdf(&mut point, &xi, |k| &glossy[k]);
        println!(
            "glossy alpha {alpha}: tables built on first use in {build_ms:.0} ms; \
             product at + sample + pdf {fresh:.0} ns ({:.1}x light sample)",
            fresh / light_sample
        );
    }
    Ok(())
}
