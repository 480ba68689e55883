//! Compares every sampler × density × mapping on environment maps: the table in
//! BENCHMARKS.md. For each combination it reports the efficiency `(∫Y)²/∫(Y²/p)`, the RMSE
//! of irradiance estimates with stratified (jittered) ξ at 16, 64 and 256 samples,
//! ns per `sample` on one thread, build time and bytes of sampling data per texel.
//!
//! `cargo run --release -p envlight --example compare_samplers -- [MAP ...]`
//! (no arguments: the real maps in ../shared/envmaps, or the built-in sky).
//!
//! RMSE: relative to the irradiance `E(n) = ∫ Y(ω) max(0, n·ω) dω` computed by
//! quadrature over the lat-long input (4×4 points per texel, exact solid angles),
//! for n = +z, the direction of the brightest texel, and a horizontal normal
//! pointing away from it; averaged in quadrature over the normals and 64 seeds.

use envlight::color::luminance;
use envlight::light::{Density, Mapping, Sampler};
use envlight::load::{load, LoadOptions};
use envlight::rng::SplitMix64;
use envlight::{builtin, EnvImage, EnvironmentLight, LightOptions, Lookup, Vec3};
use std::hint::black_box;
use std::path::PathBuf;
use std::time::Instant;

const COUNTS: [usize; 3] = [16, 64, 256];
const SEEDS: u64 = 64;

fn main() {
    let mut maps: Vec<(String, EnvImage)> = Vec::new();
    let args: Vec<String> = std::env::args().skip(1).collect();
    let paths: Vec<PathBuf> = if args.is_empty() {
        let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
        let mut p: Vec<PathBuf> = std::fs::read_dir(&dir)
            .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
            .unwrap_or_default();
        p.retain(|p| matches!(p.extension().and_then(|e| e.to_str()), Some("exr" | "hdr")));
        p.sort();
        p
    } else {
        args.iter().map(PathBuf::from).collect()
    };
    for path in paths {
        match load(&path, &LoadOptions::default()) {
            Ok(loaded) => maps.push((
                path.file_name()
                    .unwrap_or_default()
                    .to_string_lossy()
                    .into_owned(),
                loaded.image,
            )),
            Err(e) => eprintln!("skipping {}: {e}", path.display()),
        }
    }
    if maps.is_empty() {
        maps.push(("builtin:sky".into(), builtin::sky(1024, 512)));
    }

    println!("| map | sampler | density | mapping | efficiency | RMSE 16 | RMSE 64 | RMSE 256 | ns/sample | build ms | bytes/texel |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, image) in &maps {
        let reference = Reference::new(image);
        for mapping in Mapping::ALL {
            for density in Density::ALL {
                for sampler in Sampler::ALL {
                    let options = LightOptions {
                        sampler,
                        density,
                        mapping,
                        ..Default::default()
                    };
                    let started = Instant::now();
                    let Ok(light) = EnvironmentLight::new(image.clone(), options) else {
                        continue; // an unsupported combination
                    };
                    let build_ms = started.elapsed().as_secs_f64() * 1e3;
                    let rmse = COUNTS.map(|n| reference.rmse(&light, n));
                    println!(
                        "| {name} | {} | {} | {} | {:.4} | {:.4} | {:.4} | {:.4} | {:.0} | {:.0} | {:.2} |",
                        sampler.name(),
                        density.name(),
                        mapping.name(),
                        light.efficiency(),
                        rmse[0],
                        rmse[1],
                        rmse[2],
                        ns_per_sample(&light),
                        build_ms,
                        light.sampling_bytes() as f64
                            / (light.image().width() * light.image().height()) as f64,
                    );
                }
            }
        }
    }
}

/// Irradiance references by quadrature over the lat-long input.
struct Reference {
    normals: Vec<Vec3>,
    irradiance: Vec<f64>,
}

impl Reference {
    fn new(image: &EnvImage) -> Self {
        let (w, h) = (image.width(), image.height());
        let (mut best, mut best_y) = (0, -1.0f32);
        for (k, t) in image.texels().iter().enumerate() {
            if luminance(*t) > best_y {
                best_y = luminance(*t);
                best = k;
            }
        }
        let sun = envlight::mapping::equirect_to_direction(
            ((best % w) as f32 + 0.5) / w as f32,
            ((best / w) as f32 + 0.5) / h as f32,
        )
        .0;
        let away = Vec3::new(-sun.x, -sun.y, 0.0)
            .normalized()
            .unwrap_or(Vec3::new(1.0, 0.0, 0.0));
        let normals = vec![Vec3::new(0.0, 0.0, 1.0), sun, away];
        let k = 4usize;
        let irradiance = normals
            .iter()
            .map(|n| {
                let mut e = 0.0f64;
                for j in 0..h * k {
                    let (va, vb) = (j as f64 / (h * k) as f64, (j + 1) as f64 / (h * k) as f64);
                    let d_omega = 2.0 * std::f64::consts::PI / (w * k) as f64
                        * ((std::f64::consts::PI * va).cos() - (std::f64::consts::PI * vb).cos());
                    let v = ((va + vb) / 2.0) as f32;
                    for i in 0..w * k {
                        let u = (i as f32 + 0.5) / (w * k) as f32;
                        let d = envlight::mapping::equirect_to_direction(u, v).0;
                        let c = d.dot(*n).max(0.0) as f64;
                        if c > 0.0 {
                            e += luminance(image.lookup(u, v, Lookup::Bilinear)) as f64
                                * c
                                * d_omega;
                        }
                    }
                }
                e
            })
            .collect();
        Self {
            normals,
            irradiance,
        }
    }

    /// Relative RMSE of `n`-sample estimates with jittered ξ on a √n × √n grid.
    fn rmse(&self, light: &EnvironmentLight, n: usize) -> f64 {
        let side = (n as f64).sqrt().round() as usize;
        let mut sum_sq = 0.0;
        let mut count = 0usize;
        for (normal, &reference) in self.normals.iter().zip(&self.irradiance) {
            for seed in 0..SEEDS {
                let mut rng = SplitMix64::new(envlight::rng::mix64(seed * 7919 + n as u64));
                let mut estimate = 0.0f64;
                for a in 0..side {
                    for b in 0..side {
                        let xi = [
                            ((a as f64 + rng.next_f64()) / side as f64) as f32,
                            ((b as f64 + rng.next_f64()) / side as f64) as f32,
                        ];
                        if let Some(s) =
                            light.sample([xi[0].min(0.99999994), xi[1].min(0.99999994)])
                        {
                            let c = s.direction.dot(*normal).max(0.0) as f64;
                            estimate += luminance(s.radiance) as f64 * c / s.pdf as f64;
                        }
                    }
                }
                estimate /= (side * side) as f64;
                sum_sq += ((estimate - reference) / reference).powi(2);
                count += 1;
            }
        }
        (sum_sq / count as f64).sqrt()
    }
}

/// Mean ns per `sample` on this thread over 2^20 pseudo-random ξ.
fn ns_per_sample(light: &EnvironmentLight) -> f64 {
    let n = 1u64 << 20;
    let xi: Vec<[f32; 2]> = (0..n).map(|k| envlight::rng::xi_2d(42, k)).collect();
    let started = Instant::now();
    let mut acc = 0.0f32;
    for &x in &xi {
        acc += light.sample(black_box(x)).map_or(0.0, |s| s.pdf);
    }
    black_box(acc);
    started.elapsed().as_secs_f64() * 1e9 / n as f64
}
