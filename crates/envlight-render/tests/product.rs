//! The product strategies (`product`, `mis-product`) against `mis`: the same
//! expected image on the all-diffuse scene under a sky with a small bright sun,
//! over the whole image and over each object, within standard errors.

#![allow(clippy::needless_range_loop)] // per-channel arithmetic reads best indexed

use envlight::{builtin, EnvironmentLight, LightOptions, Rotation};
use envlight_render::{render_with_error, NoProgress, RenderSettings, Scene, Strategy};

/// Mean and standard error per channel over the pixels `pick` selects, from a
/// render's per-pixel means and standard errors (pixels are independent).
fn region_mean(r: &envlight_render::Rendered, pick: &[bool]) -> ([f64; 3], [f64; 3]) {
    let n = pick.iter().filter(|&&p| p).count() as f64;
    let (mut mean, mut var) = ([0.0f64; 3], [0.0f64; 3]);
    for ((p, e), _) in r
        .image
        .pixels()
        .iter()
        .zip(r.std_error.pixels())
        .zip(pick)
        .filter(|(_, &k)| k)
    {
        for c in 0..3 {
            mean[c] += p[c] as f64 / n;
            var[c] += (e[c] as f64 / n).powi(2);
        }
    }
    (mean, var.map(f64::sqrt))
}

/// On `diffuse` (occlusion, interreflection up to 5 bounces) under the built-in
/// sky, turned so the sun lights the spheres from the side: the image mean and the
/// mean over every object of `product` and `mis-product` agree with `mis` within 5
/// combined standard errors per channel (each comparison at about 6e-7 two-sided
/// if the errors are normal; 2 strategies × 5 regions × 3 channels).
#[test]
fn product_strategies_agree_with_mis_on_diffuse() {
    let sky = builtin::sky(128, 64);
    agree_with_mis(
        "diffuse",
        sky,
        &[(Strategy::Product, 22), (Strategy::MisProduct, 23)],
    );
}

/// The same on `balls`, whose near-mirror sphere takes product samples under
/// `mis-product` (its rough copper the compensated light) and whose plastic
/// combines product and BSDF samples, under the sky with its sun's texels
/// clamped: the unclamped sun's highlight on the near-mirror leaves `mis` a
/// standard error of a quarter of that region's mean at this budget.
#[test]
fn mis_product_agrees_with_mis_on_balls() {
    let sky = builtin::sky(128, 64);
    let clamped = sky
        .texels()
        .iter()
        .map(|t| t.map(|c| c.min(CLAMP)))
        .collect();
    let sky = envlight::EnvImage::new(sky.width(), sky.height(), clamped).unwrap();
    agree_with_mis("balls", sky, &[(Strategy::MisProduct, 24)]);
}

/// The radiance the balls' sky is clamped to.
const CLAMP: f32 = 20.0;

/// The image mean and each object's mean of every `(strategy, seed)` of
/// `strategies` against `mis`'s on the built-in scene `name`, within 5 combined
/// standard errors per channel.
fn agree_with_mis(name: &str, sky: envlight::EnvImage, strategies: &[(Strategy, u64)]) {
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(70.0),
        ..Default::default()
    };
    let light = EnvironmentLight::new(sky, options).unwrap();
    let scene = Scene::builtin(name).unwrap();
    let (w, h) = (40, 24);
    // Regions by what the pixel centre's camera ray hits first (sky excluded: camera
    // rays that escape are the same for every strategy).
    let ids: Vec<Option<usize>> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let ray = scene.camera.ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            scene.intersect(&ray, f32::INFINITY).map(|hit| hit.object)
        })
        .collect();
    let mut regions: Vec<(String, Vec<bool>)> = vec![("image".into(), vec![true; w * h])];
    for (k, object) in scene.objects.iter().enumerate() {
        let pick: Vec<bool> = ids.iter().map(|&id| id == Some(k)).collect();
        assert!(pick.iter().filter(|&&p| p).count() >= 10, "{}", object.name);
        regions.push((object.name.to_string(), pick));
    }

    // Independent seeds: the combined standard error assumes independent renders
    // (the same seed would trace the same paths and hide differences).
    let run = |strategy: Strategy, seed: u64| {
        let settings = RenderSettings {
            width: w,
            height: h,
            spp: 512,
            max_depth: 5,
            strategy,
            seed,
            ..Default::default()
        };
        render_with_error(&scene, &light, &settings, &NoProgress)
    };
    let mis = run(Strategy::Mis, 21);
    for &(strategy, seed) in strategies {
        let r = run(strategy, seed);
        for (name, pick) in &regions {
            let (a, sa) = region_mean(&r, pick);
            let (b, sb) = region_mean(&mis, pick);
            for c in 0..3 {
                let se = (sa[c].powi(2) + sb[c].powi(2)).sqrt();
                eprintln!(
                    "{strategy} {name} channel {c}: {:.5} vs mis {:.5} ({:+.2} se)",
                    a[c],
                    b[c],
                    (a[c] - b[c]) / se
                );
                assert!(
                    (a[c] - b[c]).abs() <= 5.0 * se,
                    "{strategy} {name} channel {c}: {} vs mis {} (se {se})",
                    a[c],
                    b[c]
                );
            }
        }
    }
}
