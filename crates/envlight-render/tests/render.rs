//! Whole-image properties: determinism, time-budgeted renders, agreement of all
//! strategies on a scene with occlusion and several bounces, and the comparison.

#![allow(clippy::needless_range_loop)] // per-channel arithmetic reads best indexed

mod common;

use envlight::{builtin, EnvImage, EnvironmentLight, LightOptions, Rotation};
use envlight_render::{
    compare, render, render_for_time, render_with_error, Budget, CompareSettings, NoProgress,
    RenderSettings, Scene, Strategy,
};

fn sky_light() -> EnvironmentLight {
    EnvironmentLight::new(builtin::sky(128, 64), LightOptions::default()).unwrap()
}

/// A soft map: gradient sky, ground, and a patch 20× the sky, so that even uniform
/// sampling has a trustworthy error estimate.
fn soft_light() -> EnvironmentLight {
    let image = EnvImage::from_fn(64, 32, |x, y| {
        let (u, v) = ((x as f32 + 0.5) / 64.0, (y as f32 + 0.5) / 32.0);
        if (0.55..0.62).contains(&u) && (0.3..0.4).contains(&v) {
            [20.0, 18.0, 14.0]
        } else if v < 0.5 {
            [0.5, 0.6, 0.9]
        } else {
            [0.2, 0.18, 0.15]
        }
    })
    .unwrap();
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(30.0),
        ..Default::default()
    };
    EnvironmentLight::new(image, options).unwrap()
}

#[test]
fn same_image_for_any_thread_count() {
    let light = sky_light();
    let scene = Scene::builtin("balls").unwrap();
    // The product strategies also check that a thread's scratch, reused across
    // pixels in a different order for each thread count, changes nothing.
    for strategy in [
        Strategy::Mis,
        Strategy::MisCompensated,
        Strategy::MisProduct,
    ] {
        let settings = RenderSettings {
            width: 40,
            height: 24,
            spp: 3,
            max_depth: 6,
            strategy,
            seed: 42,
            ..Default::default()
        };
        let one = common::render_on_any_thread_count(&scene, &light, &settings);
        // Another seed gives another image.
        let other = render(
            &scene,
            &light,
            &RenderSettings {
                seed: 43,
                ..settings
            },
            &NoProgress,
        );
        assert_ne!(one, other);
    }
}

#[test]
fn time_budget_render_equals_sample_count_render() {
    let light = sky_light();
    let scene = Scene::builtin("balls").unwrap();
    let settings = common::small_render(24, 16, 5, 4, 1);
    // A long budget stops at the cap of 5 samples; no budget at all still takes one.
    let timed = render_for_time(&scene, &light, &settings, 60.0, &NoProgress);
    assert_eq!(timed.spp, 5);
    let fixed = render_with_error(&scene, &light, &settings, &NoProgress);
    assert_eq!(timed.image, fixed.image);
    assert_eq!(timed.std_error, fixed.std_error);
    let minimal = render_for_time(&scene, &light, &settings, 0.0, &NoProgress);
    assert_eq!(minimal.spp, 1);
}

/// On `balls` (occlusion, up to 6 bounces, all four materials) the mean over the
/// image of every strategy agrees with `mis` within 5 combined standard errors.
#[test]
fn strategies_agree_on_balls() {
    let light = soft_light();
    let scene = Scene::builtin("balls").unwrap();
    let settings = common::small_render(48, 27, 96, 6, 5);
    common::strategies_agree_with_mis(&scene, &light, &Strategy::ALL, &settings);
}

#[test]
fn comparison_reports_every_strategy_and_draws_a_sheet() {
    let light = sky_light();
    let scene = Scene::builtin("balls").unwrap();
    let settings = CompareSettings {
        render: RenderSettings {
            width: 32,
            height: 18,
            spp: 2,
            ..Default::default()
        },
        equal_time: Some(0.05),
        equal_time_of_mis: false,
        reference_spp: 16,
        ..Default::default()
    };
    let c = compare(&scene, &light, &settings, None, &NoProgress).unwrap();
    assert_eq!(c.entries.len(), 2 * Strategy::ALL.len());
    assert!(c.entries.iter().all(|e| e.rmse.is_finite() && e.rmse > 0.0));
    assert!(c
        .entries
        .iter()
        .filter(|e| matches!(e.budget, Budget::EqualTime(_)))
        .all(|e| e.spp >= 1));
    let table = c.table();
    for s in Strategy::ALL {
        assert!(table.contains(s.name()), "{table}");
    }
    let sheet = c.sheet(0.0);
    assert_eq!(sheet.rgb.len(), 3 * sheet.width * sheet.height);
    assert!(sheet.width > (Strategy::ALL.len() + 1) * 32 && sheet.height > 2 * 18);
    // A reference of the wrong size is an error, not a panic.
    let wrong = envlight_render::Image::filled(8, 8, [0.0; 3]);
    assert!(compare(
        &scene,
        &light,
        &settings,
        Some((wrong, "ref.exr".into())),
        &NoProgress
    )
    .is_err());
}
