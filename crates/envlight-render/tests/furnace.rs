//! White furnace: a diffuse sphere of albedo 0.5 under a constant map of radiance 1
//! renders 0.5 on every sphere pixel and 1 on every background pixel, for every
//! strategy, within the estimator's own standard error.

#![allow(clippy::needless_range_loop)] // per-channel arithmetic reads best indexed

use envlight::{EnvImage, EnvironmentLight, LightOptions, Vec3};
use envlight_render::scene::FURNACE_ALBEDO;
use envlight_render::{render_with_error, NoProgress, RenderSettings, Scene, Strategy};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Coverage {
    Sphere,
    Background,
    Edge,
}

/// Classifies each pixel of the furnace image by where its whole footprint lies:
/// the angle between the pixel's centre ray and the sphere's centre, against the
/// silhouette cone, with the pixel's angular radius as margin.
fn coverage(scene: &Scene, width: usize, height: usize) -> Vec<Coverage> {
    let cam = scene.camera;
    let to_centre = (Vec3::new(0.0, 0.0, 0.0) - cam.position)
        .normalized()
        .unwrap();
    let distance = cam.position.length();
    let cone = (1.0 / distance).asin();
    let angle = |a: Vec3, b: Vec3| a.dot(b).clamp(-1.0, 1.0).acos();
    let mut out = Vec::new();
    for y in 0..height {
        for x in 0..width {
            let (fx, fy) = (x as f32, y as f32);
            let centre = cam.ray(fx + 0.5, fy + 0.5, width, height).direction;
            let margin = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]
                .iter()
                .map(|&(dx, dy)| angle(centre, cam.ray(fx + dx, fy + dy, width, height).direction))
                .fold(0.0f32, f32::max)
                * 1.01;
            let a = angle(centre, to_centre);
            out.push(if a + margin < cone {
                Coverage::Sphere
            } else if a - margin > cone {
                Coverage::Background
            } else {
                Coverage::Edge
            });
        }
    }
    out
}

#[test]
fn white_furnace_every_strategy() {
    let white = EnvImage::from_fn(32, 16, |_, _| [1.0; 3]).unwrap();
    let light = EnvironmentLight::new(white, LightOptions::default()).unwrap();
    let scene = Scene::builtin("furnace").unwrap();
    let (w, h) = (32, 32);
    let cover = coverage(&scene, w, h);
    let n_sphere = cover.iter().filter(|&&c| c == Coverage::Sphere).count();
    let n_background = cover.iter().filter(|&&c| c == Coverage::Background).count();
    assert!(
        n_sphere > 200 && n_background > 200,
        "{n_sphere} {n_background}"
    );

    // Every strategy, the product ones included.
    assert!([Strategy::Product, Strategy::MisProduct]
        .iter()
        .all(|s| Strategy::ALL.contains(s)));
    for strategy in Strategy::ALL {
        let settings = RenderSettings {
            width: w,
            height: h,
            spp: 64,
            max_depth: 5,
            strategy,
            seed: 11,
            ..Default::default()
        };
        let r = render_with_error(&scene, &light, &settings, &NoProgress);
        let expected = FURNACE_ALBEDO as f64;
        let (mut sum, mut var_sum) = ([0.0f64; 3], [0.0f64; 3]);
        for (i, c) in cover.iter().enumerate() {
            let (v, se) = (r.image.pixels()[i], r.std_error.pixels()[i]);
            for ch in 0..3 {
                match c {
                    Coverage::Background => assert_eq!(v[ch], 1.0, "{strategy}: pixel {i}"),
                    Coverage::Sphere => {
                        // Per pixel: within 5 standard errors (a few ulps for the
                        // zero-variance cosine-sampling estimator).
                        let err = (v[ch] as f64 - expected).abs();
                        assert!(
                            err <= 5.0 * se[ch] as f64 + 1e-5,
                            "{strategy}: pixel {i} = {v:?} ± {se:?}"
                        );
                        sum[ch] += v[ch] as f64;
                        var_sum[ch] += (se[ch] as f64).powi(2);
                    }
                    Coverage::Edge => {}
                }
            }
        }
        // All sphere pixels together, per channel (the channels of a white furnace
        // are correlated, pixels are not): within 4 standard errors of 0.5.
        let count = n_sphere as f64;
        for ch in 0..3 {
            let mean = sum[ch] / count;
            let se = var_sum[ch].sqrt() / count;
            eprintln!("{strategy}: channel {ch} sphere mean {mean:.6} ± {se:.2e}");
            assert!(
                (mean - expected).abs() <= 4.0 * se + 1e-6,
                "{strategy}: sphere mean {mean} ± {se}"
            );
        }
        let se = var_sum[0].sqrt() / count;
        if strategy != Strategy::Bsdf {
            assert!(se > 0.0, "{strategy}: no variance at all is suspicious");
        }
    }
}
