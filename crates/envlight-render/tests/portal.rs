//! The portal strategies in the `room` scene (issue 25): direct light under a
//! constant map against the closed form of `∫ cos dω` over the openings (the
//! room's furnace), agreement of every strategy on the room, and determinism.

#![allow(clippy::needless_range_loop)] // per-channel arithmetic reads best indexed

mod common;

use envlight::rng::{mix64, SplitMix64};
use envlight::{builtin, EnvImage, EnvironmentLight, LightOptions, Vec3};
use envlight_render::{Integrator, Ray, RenderSettings, Scene, Strategy};
use std::f64::consts::PI;

/// `∫ max(0, n·ω) dω` over the polygon `corners` seen from `p` (Lambert's formula:
/// half the sum over its edges of the edge's angle times the cosine of the normal
/// with the edge's plane through `p`).
fn polygon_cosine_integral(p: Vec3, n: Vec3, corners: &[Vec3; 4]) -> f64 {
    let d = |c: Vec3| {
        let v = c - p;
        let l = (v.dot(v) as f64).sqrt();
        [v.x as f64 / l, v.y as f64 / l, v.z as f64 / l]
    };
    let n = [n.x as f64, n.y as f64, n.z as f64];
    let mut sum = 0.0;
    for k in 0..4 {
        let (a, b) = (d(corners[k]), d(corners[(k + 1) % 4]));
        let c = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        let len = (c[0] * c[0] + c[1] * c[1] + c[2] * c[2]).sqrt();
        let angle = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .clamp(-1.0, 1.0)
            .acos();
        sum += angle * (c[0] * n[0] + c[1] * n[1] + c[2] * n[2]) / len;
    }
    0.5 * sum.abs()
}

/// The room's furnace: under a constant map of radiance 1, the direct light at a
/// floor point under the skylight (spheres removed, so only the openings' edges
/// bound what it sees) is `ρ/π ∫ cos dω` over the window and the skylight's top.
/// Every strategy that samples the light must find it; the portal strategies with
/// a tiny error (their pdf is ∝ the solid angle of the openings).
#[test]
fn direct_light_through_the_openings_matches_the_closed_form() {
    let mut scene = Scene::builtin("room").unwrap();
    scene
        .objects
        .retain(|o| !matches!(o.name, "diffuse" | "copper" | "plastic"));
    let light = EnvironmentLight::new(
        EnvImage::from_fn(16, 8, |_, _| [1.0; 3]).unwrap(),
        LightOptions::default(),
    )
    .unwrap();
    let p = Vec3::new(2.2, 1.5, 0.0);
    let up = Vec3::new(0.0, 0.0, 1.0);
    let e = polygon_cosine_integral(p, up, &Scene::ROOM_WINDOW)
        + polygon_cosine_integral(p, up, &Scene::ROOM_SKYLIGHT);
    // The floor's checker square at (2.2, 1.5) is an odd one.
    let albedo = [0.3, 0.27, 0.25];
    let expected = albedo.map(|a| a / PI * e);
    let ray = Ray {
        origin: Vec3::new(2.2, 1.5, 1.0),
        direction: Vec3::new(0.0, 0.0, -1.0),
    };
    for (strategy, samples) in [
        (Strategy::Portal, 4000),
        (Strategy::MisPortal, 4000),
        (Strategy::Mis, 40000),
        (Strategy::Light, 40000),
    ] {
        let integrator = Integrator::new(&scene, &light, strategy, 1);
        let values: Vec<[f32; 3]> = (0..samples as u64)
            .map(|s| integrator.li(&ray, &mut SplitMix64::new(mix64(s))))
            .collect();
        let (mean, se) = common::mean_and_error(&values);
        eprintln!("{strategy:<12} {mean:.6?} ± {se:.6?} (closed form {expected:.6?})");
        common::assert_agrees(&strategy.to_string(), mean, se, expected, 1e-3);
        if strategy == Strategy::Portal {
            // Sampling ∝ solid angle of the openings: only the cosine varies.
            assert!(se[0] < 0.01 * expected[0], "{se:?}");
        }
    }
}

/// Every strategy agrees with `mis` on the room (occlusion, several bounces, all
/// materials) within 5 combined standard errors of the image mean.
#[test]
fn strategies_agree_on_the_room() {
    let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
    let scene = Scene::builtin("room").unwrap();
    let settings = common::small_render(32, 18, 48, 4, 8);
    let strategies = [
        Strategy::Mis,
        Strategy::Light,
        Strategy::Bsdf,
        Strategy::Portal,
        Strategy::MisPortal,
    ];
    let means = common::strategies_agree_with_mis(&scene, &light, &strategies, &settings);
    let mis = means[0];
    // Sampling through the openings beats sampling the whole sky per sample.
    let portal = means.iter().find(|m| m.0 == Strategy::MisPortal).unwrap();
    assert!(portal.2[1] < mis.2[1], "{:?} vs {:?}", portal.2, mis.2);
}

#[test]
fn portal_renders_are_the_same_for_any_thread_count() {
    let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
    let scene = Scene::builtin("room").unwrap();
    for strategy in [Strategy::Portal, Strategy::MisPortal] {
        let settings = RenderSettings {
            width: 24,
            height: 16,
            spp: 2,
            max_depth: 4,
            strategy,
            seed: 3,
            ..Default::default()
        };
        common::render_on_any_thread_count(&scene, &light, &settings);
    }
}
