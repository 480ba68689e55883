//! How much a visibility cache cuts the variance of direct irradiance at the
//! first hits of a built-in scene, against the product sampler (and the scene's
//! portals, where it has them), at equal samples, e.g.
//!
//! ```text
//! cargo run --release -p envlight-render --example visibility_gain -- \
//!     ../shared/envmaps/sunrise.exr room [POINTS] [SAMPLES]
//! ```
//!
//! The cache is built as `envlight render --strategy mis-visibility` builds it
//! at 320 × 180 (the camera's first hits through the pixel centres, the scene's
//! shadow rays as the callback), with the library's default options unless
//! `ENVLIGHT_VIS=key=value,...` overrides them (`share`, `rays`, `refine`, `prior`,
//! `entries`, `bins`), and `ENVLIGHT_PATCHES=WxH` sets the product sampler's
//! patch grid. `POINTS` first hits (default 200) are drawn at random
//! pixels; at each, `SAMPLES` (default 2000) one-sample estimates
//! `L cos⁺ V / p` of the irradiance are taken with each sampler. Prints the
//! variance summed over the diffuse points, each weighted by its albedo's
//! luminance squared, relative to the product sampler's (what the image's squared
//! error from direct light follows), the median of the per-point ratios, and each
//! sampler's time per sample.

use envlight::portal::{Portal, PortalLight, PortalOptions};
use envlight::rng::SplitMix64;
use envlight::visibility::VisibilityOptions;
use envlight::{
    EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
    VisibilityCache,
};
use envlight_render::{read_image, Bsdf, Ray, Scene};
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 2 {
        return Err("usage: visibility_gain MAP SCENE [POINTS] [SAMPLES]".into());
    }
    let image = if args[0] == "builtin:sky" {
        envlight::builtin::sky(1024, 512)
    } else {
        let img = read_image(Path::new(&args[0]))?;
        EnvImage::from_raw(
            &args[0],
            img.width(),
            img.height(),
            img.pixels().to_vec(),
            false,
        )?
        .0
    };
    let light = Arc::new(EnvironmentLight::new(image, LightOptions::default())?);
    let scene = Scene::builtin(&args[1]).ok_or("unknown scene")?;
    let points: usize = args.get(2).map_or(Ok(200), |s| s.parse())?;
    let samples: usize = args.get(3).map_or(Ok(2000), |s| s.parse())?;
    let options = options_from_env()?;

    let patches = std::env::var("ENVLIGHT_PATCHES").ok().map(|v| {
        let (a, b) = v.split_once('x').expect("ENVLIGHT_PATCHES=WxH");
        [a.parse().expect("a width"), b.parse().expect("a height")]
    });
    let product_options = ProductOptions {
        patches,
        ..ProductOptions::default()
    };
    let product = Arc::new(ProductSampler::new(light.clone(), product_options));
    let (w, h) = (320usize, 180usize);
    let hits: Vec<(Vec3, Vec3)> = (0..w * h)
        .filter_map(|i| first_hit(&scene, (i % w) as f32 + 0.5, (i / w) as f32 + 0.5, w, h))
        .collect();
    let (ps, ns): (Vec<Vec3>, Vec<Vec3>) = hits.iter().copied().unzip();
    let start = Instant::now();
    let cache = VisibilityCache::build(product.clone(), &ps, &ns, &options, |o, d, t| {
        for ((t, &o), &d) in t.iter_mut().zip(o).zip(d) {
            *t = if scene.occluded(&Ray::spawn(o, d, d)) {
                0.0
            } else {
                1.0
            };
        }
        Ok::<(), std::convert::Infallible>(())
    })?;
    let build = start.elapsed().as_secs_f64();
    let summary = cache.summary();
    println!(
        "{} points, {} entries, radius {:.3}, {} rays, {:.2} MB, built in {build:.2} s",
        ps.len(),
        summary.entries,
        summary.radius,
        summary.rays,
        summary.bytes as f64 / 1e6
    );
    let portal = (!scene.portals.is_empty()).then(|| {
        let quads: Vec<Portal> = scene
            .portals
            .iter()
            .map(|&c| Portal::new(c).unwrap())
            .collect();
        PortalLight::new(light.clone(), &quads, PortalOptions::default()).unwrap()
    });

    let mut rng = SplitMix64::new(7);
    let names = ["product", "cache", "portal"];
    let mut total = [0.0f64; 3];
    let mut time = [0.0f64; 3];
    let mut ratios = Vec::new();
    let mut shares = Vec::new();
    for _ in 0..points {
        let (x, y) = (rng.next_f32() * w as f32, rng.next_f32() * h as f32);
        let Some((p, n, weight)) = first_hit_weighted(&scene, x, y, w, h) else {
            continue;
        };
        if weight == 0.0 {
            continue;
        }
        let factor = Factor::cosine(n);
        let at = cache.at(p, &factor);
        shares.push(at.learned_share());
        let point = product.at(&factor);
        let portal_point = portal.as_ref().map(|pl| pl.at(p));
        let mut var = [f64::NAN; 3];
        for s in 0..3 {
            let start = Instant::now();
            let (mut sum, mut sq) = (0.0f64, 0.0f64);
            for _ in 0..samples {
                let xi = [rng.next_f32(), rng.next_f32()];
                let drawn = match s {
                    0 => point.sample(xi),
                    1 => at.sample(xi),
                    _ => match &portal_point {
                        Some(pp) => pp.sample(xi),
                        None => break,
                    },
                };
                let f = drawn.map_or(0.0, |d| {
                    let c = n.dot(d.direction);
                    if c <= 0.0 || scene.occluded(&Ray::spawn(p, n, d.direction)) {
                        0.0
                    } else {
                        let y = 0.2126 * d.radiance[0]
                            + 0.7152 * d.radiance[1]
                            + 0.0722 * d.radiance[2];
                        (y * c / d.pdf) as f64
                    }
                });
                sum += f;
                sq += f * f;
            }
            time[s] += start.elapsed().as_secs_f64();
            let m = samples as f64;
            var[s] = (sq / m - (sum / m).powi(2)).max(0.0);
        }
        for s in 0..3 {
            total[s] += weight * var[s];
        }
        if var[0] > 0.0 {
            ratios.push(var[1] / var[0]);
        }
        if std::env::var("ENVLIGHT_VIS_POINTS").is_ok() {
            println!(
                "point {:?} normal {:?} share {:.3} variance product {:.4} cache {:.4} portal {:.4}",
                p.to_array(),
                n.to_array(),
                at.learned_share(),
                var[0],
                var[1],
                var[2]
            );
        }
    }
    ratios.sort_by(f64::total_cmp);
    shares.sort_by(f32::total_cmp);
    let n_samples = (points * samples) as f64;
    for s in 0..3 {
        if s == 2 && portal.is_none() {
            continue;
        }
        println!(
            "{:<8} variance {:.4} x product's, {:.0} ns per sample",
            names[s],
            total[s] / total[0],
            time[s] / n_samples * 1e9
        );
    }
    println!(
        "cache/product per point: median {:.3}, quartiles {:.3} {:.3}; learned share median {:.3}",
        ratios[ratios.len() / 2],
        ratios[ratios.len() / 4],
        ratios[3 * ratios.len() / 4],
        shares[shares.len() / 2]
    );
    Ok(())
}

fn first_hit(scene: &Scene, x: f32, y: f32, w: usize, h: usize) -> Option<(Vec3, Vec3)> {
    first_hit_weighted(scene, x, y, w, h).map(|(p, n, _)| (p, n))
}

/// The first hit, its normal towards the camera, and the squared luminance of
/// its diffuse albedo (0 for other surfaces): the weight of its irradiance's
/// variance in the pixel's.
fn first_hit_weighted(
    scene: &Scene,
    x: f32,
    y: f32,
    w: usize,
    h: usize,
) -> Option<(Vec3, Vec3, f64)> {
    let ray = scene.camera.ray(x, y, w, h);
    let hit = scene.intersect(&ray, f32::INFINITY)?;
    let n = if hit.normal.dot(ray.direction) > 0.0 {
        -hit.normal
    } else {
        hit.normal
    };
    let weight = match scene.objects[hit.object].material.bsdf_at(hit.point) {
        Bsdf::Diffuse { albedo } => {
            let y = 0.2126 * albedo[0] + 0.7152 * albedo[1] + 0.0722 * albedo[2];
            (y * y) as f64
        }
        _ => 0.0,
    };
    Some((hit.point, n, weight))
}

fn options_from_env() -> Result<VisibilityOptions, Box<dyn std::error::Error>> {
    let mut o = VisibilityOptions::default();
    if let Ok(spec) = std::env::var("ENVLIGHT_VIS") {
        for kv in spec.split(',').filter(|s| !s.is_empty()) {
            let (k, v) = kv.split_once('=').ok_or("ENVLIGHT_VIS: key=value")?;
            match k {
                "share" => o.learned_share = v.parse()?,
                "rays" => o.rays_per_patch = v.parse()?,
                "refine" => o.refine_rays = v.parse()?,
                "prior" => o.prior = v.parse()?,
                "entries" => o.target_entries = v.parse()?,
                "bins" => o.normal_bins = v.parse()?,
                _ => return Err(format!("ENVLIGHT_VIS: unknown key {k}").into()),
            }
        }
    }
    Ok(o)
}
