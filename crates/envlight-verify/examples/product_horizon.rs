//! The share of product samples below the surface's horizon (issue 35): for every
//! shared map (full size and box-filtered to 256 × 128), the built-in sky and a
//! synthetic low sun, at the axis normals, towards and away from the brightest
//! texel and at random normals, the fraction of `ShadingPoint::sample` draws with
//! `n·ω ≤ 0` (where `L·cos⁺` is 0), and the cosine's product efficiency.
//!
//! `cargo run --release -p envlight-verify --example product_horizon [-- --random N] [--samples N] [--grid N]`
//! (maps from `../shared/envmaps/`; `MAPS=a,b` keeps some).

use envlight::{
    builtin, EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
};
use envlight_verify::{efficiency, maps, product_normals, AtShadingPoint, Reference};
use std::sync::Arc;

/// A dim sky with a bright sun disc 3° above the horizon (0.5° radius).
fn low_sun(width: usize, height: usize) -> EnvImage {
    let sun = Vec3::new(0.6, 0.8, (3.0f32).to_radians().tan())
        .normalized()
        .unwrap();
    let mut texels = Vec::with_capacity(width * height);
    for j in 0..height {
        for i in 0..width {
            let theta = std::f32::consts::PI * (j as f32 + 0.5) / height as f32;
            let phi = 2.0 * std::f32::consts::PI * (i as f32 + 0.5) / width as f32;
            let d = Vec3::new(
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            );
            let sky = if d.z > 0.0 { 0.3 + 0.7 * d.z } else { 0.1 };
            let v = if d.dot(sun) > (0.5f32).to_radians().cos() {
                5.0e4
            } else {
                sky
            };
            texels.push([v, v, v]);
        }
    }
    EnvImage::new(width, height, texels).unwrap()
}

fn arg(args: &[String], name: &str) -> Option<usize> {
    let k = args.iter().position(|a| a == name)?;
    args.get(k + 1).and_then(|v| v.parse().ok())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let random = arg(&args, "--random").unwrap_or(24);
    let samples = arg(&args, "--samples").unwrap_or(1 << 17);
    let normal_grid = arg(&args, "--grid");
    let only: Option<Vec<String>> = std::env::var("MAPS")
        .ok()
        .map(|m| m.split(',').map(String::from).collect());
    let mut maps: Vec<(String, EnvImage)> = vec![
        ("builtin:sky".into(), builtin::sky(1024, 512)),
        ("builtin:sky 256".into(), builtin::sky(256, 128)),
        ("low sun".into(), low_sun(1024, 512)),
        ("low sun 256".into(), low_sun(256, 128)),
    ];
    for (file, image) in maps::shared(&maps::SHARED) {
        let small = maps::box_filter(&image, image.width() / 256);
        maps.push((file.clone(), image));
        maps.push((format!("{file} 256"), small));
    }
    maps.retain(|(name, _)| {
        only.as_ref()
            .is_none_or(|o| o.iter().any(|x| name.starts_with(x.as_str())))
    });
    println!(
        "| map | worst normal | below horizon (worst) | mean over normals | efficiency there |"
    );
    println!("|---|---|---|---|---|");
    let mut overall: f64 = 0.0;
    for (name, image) in &maps {
        let light = Arc::new(EnvironmentLight::new(
            image.clone(),
            LightOptions::default(),
        )?);
        let sampler = ProductSampler::new(
            light.clone(),
            ProductOptions {
                normal_grid,
                ..Default::default()
            },
        );
        let mut normals = product_normals(&light, random);
        for (label, n) in [
            ("+x", [1.0, 0.0, 0.0]),
            ("-x", [-1.0, 0.0, 0.0]),
            ("+y", [0.0, 1.0, 0.0]),
            ("-y", [0.0, -1.0, 0.0]),
        ] {
            normals.push((label.to_string(), Vec3::from(n)));
        }
        let mut worst = (0.0f64, String::new(), Vec3::new(0.0, 0.0, 1.0));
        let mut sum = 0.0;
        for (label, n) in &normals {
            let point = sampler.at(&Factor::cosine(*n));
            let (mut below, mut drawn) = (0usize, 0usize);
            for s in 0..samples {
                let xi = envlight::rng::xi_2d(5, s as u64);
                if let Some(sample) = point.sample(xi) {
                    drawn += 1;
                    below += (sample.direction.dot(*n) <= 0.0) as usize;
                }
            }
            let share = below as f64 / drawn.max(1) as f64;
            sum += share;
            if share >= worst.0 {
                worst = (share, label.clone(), *n);
            }
        }
        let at = AtShadingPoint::new(&sampler, Factor::cosine(worst.2));
        let eff = efficiency(&at, &at.integrand(), Reference::Midpoint).efficiency;
        overall = overall.max(worst.0);
        println!(
            "| {name} | {} | {:.2}% | {:.2}% | {eff:.3} |",
            worst.1,
            100.0 * worst.0,
            100.0 * sum / normals.len() as f64
        );
    }
    println!(
        "\nlargest below-horizon share: {:.2}% (target ≤ 2%)",
        100.0 * overall
    );
    Ok(())
}
