//! Rendering whole images in parallel, at a fixed sample count or for a time budget.

use crate::geometry::Ray;
use crate::image::Image;
use crate::integrator::Integrator;
use crate::scene::Scene;
use crate::strategy::Strategy;
use envlight::rng::{mix64, SplitMix64};
use envlight::{EnvironmentLight, VisibilityCache};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

/// What to render.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels (≥ 1).
    pub width: usize,
    /// Image height in pixels (≥ 1).
    pub height: usize,
    /// Samples per pixel (≥ 1). For a time-budgeted render, the most it may take.
    pub spp: u32,
    /// Largest number of surface interactions on a path.
    pub max_depth: u32,
    /// How the light is estimated.
    pub strategy: Strategy,
    /// Seed of the random streams.
    pub seed: u64,
    /// How the product strategies' sampler is built (the library's defaults unless
    /// a measurement asks otherwise).
    pub product: envlight::ProductOptions,
    /// How `mis-visibility` builds its cache (the library's defaults unless a
    /// measurement asks otherwise); rendering with options that do not pass
    /// [`envlight::VisibilityOptions::validate`] panics.
    pub visibility: envlight::VisibilityOptions,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            width: 640,
            height: 360,
            spp: 64,
            max_depth: 8,
            strategy: Strategy::MisVisibility,
            seed: 0,
            product: envlight::ProductOptions::default(),
            visibility: envlight::VisibilityOptions::default(),
        }
    }
}

/// Receives progress from a render running on many threads.
///
/// `report(stage, done, total)`: `stage` names what is running (e.g. `"mis"`), `done`
/// and `total` count its work units (rows, or milliseconds for a time budget).
/// Calls come from worker threads and may arrive slightly out of order.
pub trait Progress: Sync {
    /// Reports that `done` of `total` units of `stage` are finished.
    fn report(&self, stage: &str, done: u64, total: u64);
}

impl<F: Fn(&str, u64, u64) + Sync> Progress for F {
    fn report(&self, stage: &str, done: u64, total: u64) {
        self(stage, done, total)
    }
}

/// A [`Progress`] that ignores everything.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn report(&self, _: &str, _: u64, _: u64) {}
}

/// A finished render with its per-pixel error estimate.
#[derive(Debug, Clone, PartialEq)]
pub struct Rendered {
    /// The mean of the samples of each pixel.
    pub image: Image,
    /// Per pixel and channel, the standard error of that mean, `√(s² / n)` with
    /// `s²` the unbiased sample variance (0 when `n < 2`).
    pub std_error: Image,
    /// Samples per pixel taken.
    pub spp: u32,
    /// Wall-clock time spent tracing, in seconds.
    pub seconds: f64,
}

/// Running sums of one pixel: Σx and Σx² per channel (f64, so the variance survives
/// a few thousand samples of a firefly-prone estimator).
#[derive(Debug, Clone, Copy, Default)]
struct PixelSums {
    sum: [f64; 3],
    sum_sq: [f64; 3],
}

/// The random stream of sample `sample` of pixel `pixel`: a pure function of
/// `(seed, pixel, sample)`, so images do not depend on thread count or on how the
/// samples are split into passes.
#[inline]
fn sample_rng(seed: u64, pixel: u64, sample: u64) -> SplitMix64 {
    let key = mix64(mix64(seed ^ 0x5851_f42d_4c95_7f2d).wrapping_add(pixel));
    SplitMix64::new(mix64(key ^ sample.wrapping_mul(0x9e37_79b9_7f4a_7c15)))
}

/// Renders `scene` under `light` at `settings.spp` samples per pixel.
///
/// Rows are traced in parallel (rayon's global pool). The result is bitwise the same
/// for a given seed whatever the number of threads.
pub fn render(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Image {
    render_with_error(scene, light, settings, progress).image
}

/// The integrator `settings` asks for, with what it learns before rendering
/// (the visibility cache of `mis-visibility`, from this image's camera hits).
/// The renders time it with the render: it is part of the strategy's cost.
fn integrator_for<'a>(
    scene: &'a Scene,
    light: &'a EnvironmentLight,
    settings: &RenderSettings,
) -> Integrator<'a> {
    let mut integrator = Integrator::with_product_options(
        scene,
        light,
        settings.strategy,
        settings.max_depth,
        settings.product,
    );
    integrator.learn_visibility(settings.width, settings.height, &settings.visibility);
    integrator
}

/// The visibility cache a render with `settings` learns before it traces
/// (`mis-visibility`'s, from the camera's first hits; `None` for the other
/// strategies), built alone: the same cache as the render's, the build being a
/// function of the scene, the light, the image size and the options.
pub fn learn_visibility(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
) -> Option<VisibilityCache> {
    integrator_for(scene, light, settings)
        .visibility_cache()
        .cloned()
}

/// As [`render`], also returning the per-pixel standard error.
pub fn render_with_error(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> Rendered {
    let start = Instant::now();
    let integrator = integrator_for(scene, light, settings);
    trace_all(scene, &integrator, settings, progress, start)
}

/// As [`render_with_error`], also returning the visibility cache the render
/// built and used (`mis-visibility`; `None` for the other strategies), for
/// saving it ([`VisibilityCache::save`]).
pub fn render_with_visibility(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
    progress: &dyn Progress,
) -> (Rendered, Option<VisibilityCache>) {
    let start = Instant::now();
    let integrator = integrator_for(scene, light, settings);
    let rendered = trace_all(scene, &integrator, settings, progress, start);
    (rendered, integrator.visibility_cache().cloned())
}

/// Traces `settings.spp` samples of every pixel with `integrator`, the time
/// counted from `start`.
fn trace_all(
    scene: &Scene,
    integrator: &Integrator,
    settings: &RenderSettings,
    progress: &dyn Progress,
    start: Instant,
) -> Rendered {
    let mut sums = vec![PixelSums::default(); settings.width * settings.height];
    let rows = settings.height as u64;
    let done = AtomicU64::new(0);
    trace_pass(
        scene,
        integrator,
        settings,
        0,
        settings.spp,
        &mut sums,
        &|| {
            let d = done.fetch_add(1, Ordering::Relaxed) + 1;
            progress.report(settings.strategy.name(), d, rows);
        },
    );
    finish(settings, &sums, settings.spp, start.elapsed())
}

/// Renders for about `seconds` of wall-clock time: passes of one sample per pixel
/// until the budget is spent (at least one pass, at most `settings.spp`). Pass `k`
/// uses sample index `k`, so the result equals [`render_with_error`] at the sample
/// count reached.
pub fn render_for_time(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &RenderSettings,
    seconds: f64,
    progress: &dyn Progress,
) -> Rendered {
    let start = Instant::now();
    let integrator = integrator_for(scene, light, settings);
    let mut sums = vec![PixelSums::default(); settings.width * settings.height];
    let budget = Duration::from_secs_f64(seconds.max(0.0));
    let budget_ms = budget.as_millis() as u64;
    let mut spp = 0;
    while spp < settings.spp.max(1) {
        trace_pass(
            scene,
            &integrator,
            settings,
            spp,
            spp + 1,
            &mut sums,
            &|| (),
        );
        spp += 1;
        let elapsed = start.elapsed();
        progress.report(
            settings.strategy.name(),
            (elapsed.as_millis() as u64).min(budget_ms),
            budget_ms,
        );
        if elapsed >= budget {
            break;
        }
    }
    finish(settings, &sums, spp, start.elapsed())
}

/// Adds samples `[first, end)` of every pixel to `sums`, rows in parallel.
fn trace_pass(
    scene: &Scene,
    integrator: &Integrator,
    settings: &RenderSettings,
    first: u32,
    end: u32,
    sums: &mut [PixelSums],
    row_done: &(dyn Fn() + Sync),
) {
    let width = settings.width;
    if width == 0 {
        return;
    }
    // One scratch per rayon work item (about one per thread), not per sample.
    sums.par_chunks_mut(width).enumerate().for_each_init(
        || integrator.scratch(),
        |scratch, (y, row)| {
            for (x, acc) in row.iter_mut().enumerate() {
                let pixel = (y * width + x) as u64;
                for s in first..end {
                    let mut rng = sample_rng(settings.seed, pixel, s as u64);
                    // Box filter: a uniform point in the pixel.
                    let (jx, jy) = (rng.next_f32(), rng.next_f32());
                    let ray: Ray =
                        scene
                            .camera
                            .ray(x as f32 + jx, y as f32 + jy, width, settings.height);
                    let l = integrator.li_with(&ray, &mut rng, scratch);
                    for (c, &v) in l.iter().enumerate() {
                        let v = v as f64;
                        acc.sum[c] += v;
                        acc.sum_sq[c] += v * v;
                    }
                }
            }
            row_done();
        },
    );
}

fn finish(settings: &RenderSettings, sums: &[PixelSums], spp: u32, elapsed: Duration) -> Rendered {
    let n = spp.max(1) as f64;
    let mut image = Vec::with_capacity(sums.len());
    let mut error = Vec::with_capacity(sums.len());
    for p in sums {
        let mean = p.sum.map(|s| s / n);
        image.push(mean.map(|m| m as f32));
        error.push(if spp >= 2 {
            [0, 1, 2].map(|c| {
                let var = ((p.sum_sq[c] - n * mean[c] * mean[c]) / (n - 1.0)).max(0.0);
                (var / n).sqrt() as f32
            })
        } else {
            [0.0; 3]
        });
    }
    Rendered {
        image: Image::new(settings.width, settings.height, image),
        std_error: Image::new(settings.width, settings.height, error),
        spp,
        seconds: elapsed.as_secs_f64(),
    }
}
