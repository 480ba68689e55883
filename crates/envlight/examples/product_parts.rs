//! Where a product shading point's time goes, on one thread, for one fixed normal
//! (as `envlight bench --normal` measures) and for random normals:
//! `cargo run --release -p envlight --example product_parts [-- MAP [X,Y,Z]]`.
//!
//! Rows (ns, the best of several rounds over 2¹⁹ queries; `PRODUCT_PARTS_ROUNDS`
//! sets the rounds, 1 under callgrind): the light's own sample and pdf; the
//! product's `at` alone, sample alone (point reused), pdf alone (at the sample's
//! direction), `at` + sample, sample + pdf, and a new point + sample + pdf, for a
//! fixed normal and for a random one per point. Parts timed alone overlap from one
//! query to the next; chained, they show what each adds to a shading point.

use envlight::load::{load, LoadOptions};
use envlight::{
    builtin, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

const QUERIES: usize = 1 << 19;
const ROUNDS: usize = 5;

/// Rounds per figure: `PRODUCT_PARTS_ROUNDS` (1 under callgrind, say), else 5.
fn rounds() -> usize {
    std::env::var("PRODUCT_PARTS_ROUNDS")
        .ok()
        .and_then(|r| r.parse().ok())
        .unwrap_or(ROUNDS)
}

fn best(mut f: impl FnMut() -> f32) -> f64 {
    (0..rounds())
        .map(|_| {
            let start = Instant::now();
            black_box(f());
            start.elapsed().as_secs_f64() * 1e9 / QUERIES as f64
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let image = match args.next() {
        Some(path) if path != "builtin:sky" => load(path.as_ref(), &LoadOptions::default())?.image,
        _ => builtin::sky(1024, 512),
    };
    let normal = match args.next() {
        Some(text) => {
            let v: Vec<f32> = text.split(',').map(str::parse).collect::<Result<_, _>>()?;
            Vec3::new(v[0], v[1], v[2])
        }
        None => Vec3::new(0.0, 0.0, 1.0),
    };
    let light = Arc::new(EnvironmentLight::new(image, LightOptions::default())?);
    let sampler = ProductSampler::new(light.clone(), ProductOptions::default());
    let xi: Vec<[f32; 2]> = (0..QUERIES as u64)
        .map(|k| envlight::rng::xi_2d(0xbe7c, k))
        .collect();
    let normals: Vec<Factor> = (0..QUERIES as u64)
        .map(|k| {
            Factor::cosine(envlight::math::uniform_sphere(envlight::rng::xi_2d(
                0x5eed, k,
            )))
        })
        .collect();
    // Every output goes into the sum, as in `envlight bench`, so none is skipped.
    let digest = |s: envlight::LightSample| {
        s.pdf + s.direction.x + s.direction.y + s.direction.z + s.radiance[1]
    };
    // One figure: the fastest pass of `query` over every ξ.
    let per_xi = |query: &dyn Fn([f32; 2]) -> f32| best(|| xi.iter().map(|&x| query(x)).sum());
    let light_sample = per_xi(&|x| light.sample(x).map_or(0.0, digest));
    let up = Vec3::new(0.0, 0.0, 1.0);
    let dirs: Vec<Vec3> = xi
        .iter()
        .map(|&x| light.sample(x).map_or(up, |s| s.direction))
        .collect();
    let light_pdf = best(|| dirs.iter().map(|&d| light.pdf(d)).sum());
    println!("light: sample {light_sample:.1} ns, pdf {light_pdf:.1} ns");

    let factor = Factor::cosine(normal);
    let at = per_xi(&|_| sampler.at(black_box(&factor)).samples_anything() as u32 as f32);
    let point = sampler.at(&factor);
    let sample = per_xi(&|x| point.sample(x).map_or(0.0, digest));
    let pdirs: Vec<Vec3> = xi
        .iter()
        .map(|&x| point.sample(x).map_or(up, |s| s.direction))
        .collect();
    let pdf = best(|| pdirs.iter().map(|&d| point.pdf(d)).sum());
    // A new shading point per query (`at_sample`, `whole`) or the same one.
    let whole = per_xi(&|x| {
        let p = sampler.at(black_box(&factor));
        p.sample(x).map_or(0.0, |s| p.pdf(s.direction) + digest(s))
    });
    let at_sample = per_xi(&|x| sampler.at(black_box(&factor)).sample(x).map_or(0.0, digest));
    let sample_pdf = per_xi(&|x| {
        point
            .sample(x)
            .map_or(0.0, |s| point.pdf(s.direction) + digest(s))
    });
    let light_sample_pdf = per_xi(&|x| {
        light
            .sample(x)
            .map_or(0.0, |s| light.pdf(s.direction) + digest(s))
    });
    println!(
        "at+sample {at_sample:.1}, sample+pdf {sample_pdf:.1}; light sample+pdf {light_sample_pdf:.1}"
    );
    println!(
        "product, normal ({}, {}, {}): at {at:.1}, sample {sample:.1}, pdf {pdf:.1}, \
         at+sample+pdf {whole:.1} ns ({:.2}x a light sample)",
        normal.x,
        normal.y,
        normal.z,
        whole / light_sample
    );
    let random = best(|| {
        xi.iter()
            .zip(&normals)
            .map(|(&x, f)| {
                let p = sampler.at(f);
                p.sample(x).map_or(0.0, |s| p.pdf(s.direction) + digest(s))
            })
            .sum()
    });
    println!(
        "product, random normals: at+sample+pdf {random:.1} ns ({:.2}x a light sample)",
        random / light_sample
    );
    Ok(())
}
