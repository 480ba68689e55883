//! Helpers shared by the render tests (the chi-square test of BSDF sampling is
//! `envlight_verify::chi_square_warp`).

#![allow(dead_code)]

use envlight::{EnvironmentLight, Vec3};
use envlight_render::render::Rendered;
use envlight_render::{
    render, render_with_error, Image, NoProgress, RenderSettings, Scene, Strategy,
};

/// A small render of `width × height` pixels at `spp` samples, paths of at most
/// `max_depth` vertices, seed `seed`, with `mis` (the tests' usual settings).
pub fn small_render(
    width: usize,
    height: usize,
    spp: u32,
    max_depth: u32,
    seed: u64,
) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp,
        max_depth,
        seed,
        ..Default::default()
    }
}

/// A unit direction at polar angle `theta_deg` from +z, in the xz plane.
pub fn polar(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}

/// Mean and standard error of the mean, per channel.
pub fn mean_and_error(values: &[[f32; 3]]) -> ([f64; 3], [f64; 3]) {
    let n = values.len() as f64;
    let mut mean = [0.0; 3];
    let mut se = [0.0; 3];
    for c in 0..3 {
        let m = values.iter().map(|v| v[c] as f64).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|v| (v[c] as f64 - m).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        mean[c] = m;
        se[c] = (var / n).sqrt();
    }
    (mean, se)
}

/// The image's mean over its pixels, per channel, and the standard error of that
/// mean from the render's per-pixel standard errors (pixels independent).
pub fn image_mean_and_error(r: &Rendered) -> ([f64; 3], [f64; 3]) {
    let n = r.image.pixels().len() as f64;
    let mut mean = [0.0f64; 3];
    let mut var = [0.0f64; 3];
    for (p, e) in r.image.pixels().iter().zip(r.std_error.pixels()) {
        for c in 0..3 {
            mean[c] += p[c] as f64 / n;
            var[c] += (e[c] as f64 / n).powi(2);
        }
    }
    (mean, var.map(f64::sqrt))
}

/// Renders `scene` on one thread and on three: the images must be identical, every
/// channel finite and non-negative. The image.
pub fn render_on_any_thread_count(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
) -> Image {
    let run = |threads: usize| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| render(scene, light, settings, &NoProgress))
    };
    let one = run(1);
    assert_eq!(one, run(3), "{}", settings.strategy);
    assert!(one
        .pixels()
        .iter()
        .all(|p| p.iter().all(|c| c.is_finite() && *c >= 0.0)));
    one
}

/// Each channel of `mean` (standard error `se`) is within 5 standard errors plus
/// `relative` × `expected` of `expected`; `what` names the case in the message.
pub fn assert_agrees(what: &str, mean: [f64; 3], se: [f64; 3], expected: [f64; 3], relative: f64) {
    for c in 0..3 {
        let err = (mean[c] - expected[c]).abs();
        assert!(
            err <= 5.0 * se[c] + relative * expected[c],
            "{what} channel {c}: {} vs {} (se {})",
            mean[c],
            expected[c],
            se[c]
        );
    }
}

/// Renders `scene` with `settings` under each of `strategies` (`mis` among them):
/// every image's mean agrees with `mis`'s within 5 combined standard errors, per
/// channel. Each strategy with its image's mean and standard error.
pub fn strategies_agree_with_mis(
    scene: &Scene,
    light: &EnvironmentLight,
    strategies: &[Strategy],
    settings: &RenderSettings,
) -> Vec<(Strategy, [f64; 3], [f64; 3])> {
    let mut means = Vec::new();
    for &strategy in strategies {
        let settings = RenderSettings {
            strategy,
            ..*settings
        };
        let r = render_with_error(scene, light, &settings, &NoProgress);
        let (mean, se) = image_mean_and_error(&r);
        eprintln!("{strategy:<16} {mean:.5?} ± {se:.6?}");
        means.push((strategy, mean, se));
    }
    let mis = *means.iter().find(|m| m.0 == Strategy::Mis).unwrap();
    for (strategy, mean, se) in &means {
        for c in 0..3 {
            let tol = 5.0 * (se[c].powi(2) + mis.2[c].powi(2)).sqrt();
            assert!(
                (mean[c] - mis.1[c]).abs() <= tol,
                "{strategy} channel {c}: {} vs mis {} (tol {tol})",
                mean[c],
                mis.1[c]
            );
        }
    }
    means
}
