//! Side-by-side comparison of strategies against a reference: errors, a table and a
//! labelled contact sheet.

use crate::font::Canvas;
use crate::image::{encode_png, write_atomically, Image};
use crate::render::{render_for_time, render_with_error, Progress, RenderSettings};
use crate::scene::Scene;
use crate::strategy::Strategy;
use crate::RenderError;
use envlight::EnvironmentLight;
use std::fmt::Write as _;
use std::path::Path;

/// The `ε` in the relative MSE `(x − r)² / (r² + ε)`, which keeps black reference
/// pixels from dominating.
pub const REL_MSE_EPSILON: f64 = 1e-2;

/// What to compare.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareSettings {
    /// Size, samples per pixel (for the equal-sample renders), depth and seed; the
    /// strategy field is ignored.
    pub render: RenderSettings,
    /// The strategies to render, in display order.
    pub strategies: Vec<Strategy>,
    /// Also render every strategy for this many seconds each.
    pub equal_time: Option<f64>,
    /// When [`Self::equal_time`] is `None`: also render every strategy for as long
    /// as `mis` (or, without it, the slowest strategy) took at equal samples, in
    /// the same run, so the comparison is at equal time as well.
    pub equal_time_of_mis: bool,
    /// Samples per pixel of the `mis` reference rendered when none is given.
    pub reference_spp: u32,
}

impl Default for CompareSettings {
    fn default() -> Self {
        Self {
            render: RenderSettings::default(),
            strategies: Strategy::ALL.to_vec(),
            equal_time: None,
            equal_time_of_mis: false,
            reference_spp: 1024,
        }
    }
}

/// How a render's budget was set.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Budget {
    /// A fixed number of samples per pixel.
    EqualSamples,
    /// A fixed wall-clock time, in seconds.
    EqualTime(f64),
}

/// One strategy's render and its errors against the reference.
#[derive(Debug, Clone, PartialEq)]
pub struct CompareEntry {
    /// The strategy.
    pub strategy: Strategy,
    /// Equal samples or equal time.
    pub budget: Budget,
    /// Samples per pixel taken.
    pub spp: u32,
    /// Seconds spent tracing.
    pub seconds: f64,
    /// Root-mean-square error over pixels and channels.
    pub rmse: f64,
    /// Mean of `(x − r)² / (r² + ε)` over pixels and channels ([`REL_MSE_EPSILON`]).
    pub rel_mse: f64,
    /// RMSE over the pixels of each of [`Comparison::regions`].
    pub region_rmse: Vec<f64>,
    /// The render.
    pub image: Image,
}

/// The result of [`compare`].
#[derive(Debug, Clone, PartialEq)]
pub struct Comparison {
    /// Scene name.
    pub scene: String,
    /// The reference image.
    pub reference: Image,
    /// Where the reference came from (`"mis 1024 spp"`, or a file name).
    pub reference_label: String,
    /// For a rendered reference, the RMSE its own noise adds to every error:
    /// `√(mean of the squared per-pixel standard errors)`.
    pub reference_noise_rmse: Option<f64>,
    /// One entry per strategy and budget.
    pub entries: Vec<CompareEntry>,
    /// Image regions by what the pixel centre's camera ray hits first: `"sky"` (the
    /// environment) and the scene's object names; only regions with pixels.
    pub regions: Vec<String>,
    /// Pixel count of each region.
    pub region_pixels: Vec<usize>,
}

/// For each pixel, what its centre's camera ray hits first: 0 for nothing (the
/// environment), `k + 1` for object `k`.
fn first_hit_ids(scene: &Scene, width: usize, height: usize) -> Vec<usize> {
    let mut ids = Vec::with_capacity(width * height);
    for y in 0..height {
        for x in 0..width {
            let ray = scene
                .camera
                .ray(x as f32 + 0.5, y as f32 + 0.5, width, height);
            ids.push(
                scene
                    .intersect(&ray, f32::INFINITY)
                    .map_or(0, |h| h.object + 1),
            );
        }
    }
    ids
}

/// RMSE over the pixels whose id is `id`.
fn rmse_where(image: &Image, reference: &Image, ids: &[usize], id: usize) -> f64 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for ((p, r), &i) in image.pixels().iter().zip(reference.pixels()).zip(ids) {
        if i == id {
            for c in 0..3 {
                sum += (p[c] as f64 - r[c] as f64).powi(2);
            }
            n += 3;
        }
    }
    (sum / n.max(1) as f64).sqrt()
}

/// Root-mean-square difference over all pixels and channels.
///
/// # Panics
/// When the sizes differ.
pub fn rmse(image: &Image, reference: &Image) -> f64 {
    mean_over(image, reference, |d, _| d * d).sqrt()
}

/// Relative mean squared error, mean of `(x − r)² / (r² + ε)` ([`REL_MSE_EPSILON`]).
///
/// # Panics
/// When the sizes differ.
pub fn relative_mse(image: &Image, reference: &Image) -> f64 {
    mean_over(image, reference, |d, r| d * d / (r * r + REL_MSE_EPSILON))
}

fn mean_over(image: &Image, reference: &Image, term: impl Fn(f64, f64) -> f64) -> f64 {
    assert_eq!(
        (image.width(), image.height()),
        (reference.width(), reference.height()),
        "images must have the same size"
    );
    let mut sum = 0.0f64;
    for (p, r) in image.pixels().iter().zip(reference.pixels()) {
        for c in 0..3 {
            sum += term(p[c] as f64 - r[c] as f64, r[c] as f64);
        }
    }
    sum / (3 * image.pixels().len()).max(1) as f64
}

/// Renders every strategy at equal samples (and at equal time when asked) and
/// measures each against `reference`, or against a `mis` render at
/// `settings.reference_spp` with an independent seed when `reference` is `None`.
///
/// # Errors
/// [`RenderError::SizeMismatch`] when a given reference does not match the render
/// size.
pub fn compare(
    scene: &Scene,
    light: &EnvironmentLight,
    settings: &CompareSettings,
    reference: Option<(Image, String)>,
    progress: &dyn Progress,
) -> Result<Comparison, RenderError> {
    let base = settings.render;
    let (reference, reference_label, reference_noise_rmse) = match reference {
        Some((image, label)) => {
            if (image.width(), image.height()) != (base.width, base.height) {
                return Err(RenderError::SizeMismatch {
                    what: label,
                    expected: (base.width, base.height),
                    found: (image.width(), image.height()),
                });
            }
            (image, label, None)
        }
        None => {
            let ref_settings = RenderSettings {
                spp: settings.reference_spp.max(1),
                strategy: Strategy::Mis,
                seed: base.seed ^ 0x7265_6665_7265_6e63,
                ..base
            };
            let stage = |_: &str, done: u64, total: u64| progress.report("reference", done, total);
            let r = render_with_error(scene, light, &ref_settings, &stage);
            let noise = mean_over(&r.std_error, &r.std_error, |_, s| s * s).sqrt();
            (
                r.image,
                format!("mis {} spp", ref_settings.spp),
                Some(noise),
            )
        }
    };
    let ids = first_hit_ids(scene, base.width, base.height);
    let mut region_ids = Vec::new();
    let (mut regions, mut region_pixels) = (Vec::new(), Vec::new());
    for id in 0..=scene.objects.len() {
        let count = ids.iter().filter(|&&i| i == id).count();
        if count > 0 {
            region_ids.push(id);
            regions.push(if id == 0 {
                "sky".to_string()
            } else {
                scene.objects[id - 1].name.to_string()
            });
            region_pixels.push(count);
        }
    }
    let mut entries: Vec<CompareEntry> = Vec::new();
    for row in 0..2 {
        let budget = match (row, settings.equal_time) {
            (0, _) => Budget::EqualSamples,
            (_, Some(t)) => Budget::EqualTime(t),
            (_, None) if settings.equal_time_of_mis => {
                let mis = entries.iter().find(|e| e.strategy == Strategy::Mis);
                let slowest = entries.iter().map(|e| e.seconds).fold(0.0, f64::max);
                match mis.map_or(slowest, |e| e.seconds) {
                    t if t > 0.0 => Budget::EqualTime(t),
                    _ => break,
                }
            }
            (_, None) => break,
        };
        for &strategy in &settings.strategies {
            let s = RenderSettings { strategy, ..base };
            let r = match budget {
                Budget::EqualSamples => render_with_error(scene, light, &s, progress),
                Budget::EqualTime(t) => {
                    let capped = RenderSettings { spp: 1 << 20, ..s };
                    render_for_time(scene, light, &capped, t, progress)
                }
            };
            entries.push(CompareEntry {
                strategy,
                budget,
                spp: r.spp,
                seconds: r.seconds,
                rmse: rmse(&r.image, &reference),
                rel_mse: relative_mse(&r.image, &reference),
                region_rmse: region_ids
                    .iter()
                    .map(|&id| rmse_where(&r.image, &reference, &ids, id))
                    .collect(),
                image: r.image,
            });
        }
    }
    Ok(Comparison {
        scene: scene.name.clone(),
        reference,
        reference_label,
        reference_noise_rmse,
        entries,
        regions,
        region_pixels,
    })
}

/// A number in at most 8 characters: 4 significant digits, scientific when small
/// or large.
fn short(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if (1e-3..1e4).contains(&x.abs()) {
        let digits = (3 - x.abs().log10().floor() as i32).clamp(0, 6) as usize;
        format!("{x:.digits$}")
    } else {
        format!("{x:.2e}")
    }
}

fn budget_label(b: Budget) -> String {
    match b {
        Budget::EqualSamples => "equal spp".into(),
        Budget::EqualTime(t) => format!("{}s each", seconds(t)),
    }
}

/// Seconds as typed (`3`, `1.5`), at most 3 decimals.
fn seconds(t: f64) -> String {
    let s = format!("{t:.3}");
    s.trim_end_matches('0').trim_end_matches('.').to_string()
}

/// `text` cut to at most `max_chars` characters, the cut marked by `..` at the
/// end (a caption's start names what it is; its end is the least important).
fn clip(text: &str, max_chars: usize) -> String {
    if text.chars().count() <= max_chars {
        return text.to_string();
    }
    let keep = max_chars.saturating_sub(2);
    let head: String = text.chars().take(keep).collect();
    format!("{head}..")
}

impl Comparison {
    /// The `mis` entry with the same budget as `entry`, for ratios.
    fn mis_for(&self, budget: Budget) -> Option<&CompareEntry> {
        self.entries
            .iter()
            .find(|e| e.strategy == Strategy::Mis && e.budget == budget)
    }

    /// A plain-text table: strategy, budget, spp, seconds, RMSE, relative MSE and
    /// RMSE relative to `mis` at the same budget.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "scene {}, reference: {}",
            self.scene, self.reference_label
        );
        let _ = writeln!(
            out,
            "{:<16} {:<12} {:>7} {:>8} {:>11} {:>11} {:>9}",
            "strategy", "budget", "spp", "time s", "RMSE", "rel MSE", "RMSE/mis"
        );
        for e in &self.entries {
            let ratio = self
                .mis_for(e.budget)
                .filter(|m| m.rmse > 0.0)
                .map(|m| format!("{:.3}", e.rmse / m.rmse))
                .unwrap_or_else(|| "-".into());
            let _ = writeln!(
                out,
                "{:<16} {:<12} {:>7} {:>8.2} {:>11.4e} {:>11.4e} {:>9}",
                e.strategy.name(),
                budget_label(e.budget),
                e.spp,
                e.seconds,
                e.rmse,
                e.rel_mse,
                ratio
            );
        }
        let _ = writeln!(
            out,
            "\nRMSE by region (what the pixel centre sees first; pixel counts in brackets):"
        );
        let _ = write!(out, "{:<16} {:<12}", "strategy", "budget");
        for (name, count) in self.regions.iter().zip(&self.region_pixels) {
            let _ = write!(out, " {:>16}", format!("{name} [{count}]"));
        }
        let _ = writeln!(out);
        for e in &self.entries {
            let _ = write!(
                out,
                "{:<16} {:<12}",
                e.strategy.name(),
                budget_label(e.budget)
            );
            for r in &e.region_rmse {
                let _ = write!(out, " {:>16.4e}", r);
            }
            let _ = writeln!(out);
        }
        if let Some(noise) = self.reference_noise_rmse {
            let _ = writeln!(
                out,
                "(the reference's own noise contributes about {noise:.3e} RMSE to every row)"
            );
        }
        out
    }

    /// The contact sheet: the reference and then one tile per strategy, a row per
    /// budget, each tile with a caption band below it naming the strategy, its
    /// samples and time, RMSE, relative MSE and RMSE relative to `mis`, one a line
    /// (a line too long for its tile is cut at the end, marked `..`).
    pub fn sheet(&self, exposure: f32) -> Canvas {
        let (w, h) = (self.reference.width(), self.reference.height());
        let scale = if w >= 300 { 2 } else { 1 };
        let line = (crate::font::GLYPH_HEIGHT + 3) * scale;
        let band = 5 * line + 4 * scale;
        let gap = 4;
        let budgets: Vec<Budget> = {
            let mut b: Vec<Budget> = Vec::new();
            for e in &self.entries {
                if !b.contains(&e.budget) {
                    b.push(e.budget);
                }
            }
            b
        };
        let columns = 1 + budgets
            .iter()
            .map(|&b| self.entries.iter().filter(|e| e.budget == b).count())
            .max()
            .unwrap_or(0);
        let rows = budgets.len().max(1);
        let sheet_w = columns * w + (columns + 1) * gap;
        let sheet_h = rows * (h + band) + (rows + 1) * gap;
        let mut canvas = Canvas::new(sheet_w, sheet_h, [24, 24, 24]);
        let tile_origin =
            |col: usize, row: usize| (gap + col * (w + gap), gap + row * (h + band + gap));
        let caption = |canvas: &mut Canvas, col: usize, row: usize, lines: &[String]| {
            let (x, y) = tile_origin(col, row);
            let max_chars = (w.saturating_sub(2 * scale)) / (crate::font::ADVANCE * scale);
            for (i, l) in lines.iter().enumerate() {
                let l = &clip(l, max_chars);
                canvas.text(
                    x + 2 * scale,
                    y + h + 3 * scale + i * line,
                    l,
                    scale,
                    [235, 235, 235],
                );
            }
        };
        let (x, y) = tile_origin(0, 0);
        canvas.blit(x, y, w, h, &self.reference.to_srgb8(exposure));
        caption(
            &mut canvas,
            0,
            0,
            &["reference".into(), self.reference_label.clone()],
        );
        for (row, &budget) in budgets.iter().enumerate() {
            if row > 0 {
                // The reference column is empty below the first row: name the budget
                // in the middle of that space.
                let (x, y) = tile_origin(0, row);
                let text = match budget {
                    Budget::EqualSamples => "equal samples".to_string(),
                    Budget::EqualTime(t) => format!("equal time {}s", seconds(t)),
                };
                let tx = x + w.saturating_sub(crate::font::text_width(&text, scale)) / 2;
                canvas.text(tx, y + h / 2, &text, scale, [235, 235, 235]);
            }
            let mis = self.mis_for(budget).map(|m| m.rmse);
            for (k, e) in self
                .entries
                .iter()
                .filter(|e| e.budget == budget)
                .enumerate()
            {
                let (x, y) = tile_origin(k + 1, row);
                canvas.blit(x, y, w, h, &e.image.to_srgb8(exposure));
                // One figure a line, so that none is cut on a narrow tile.
                let mut lines = vec![
                    e.strategy.name().to_string(),
                    format!("{} spp {}s", e.spp, short(e.seconds)),
                    format!("rmse {}", short(e.rmse)),
                    format!("rel mse {}", short(e.rel_mse)),
                ];
                if let Some(m) = mis.filter(|&m| m > 0.0) {
                    lines.push(format!("rmse/mis {}", short(e.rmse / m)));
                }
                caption(&mut canvas, k + 1, row, &lines);
            }
        }
        canvas
    }

    /// Writes [`Comparison::sheet`] as a PNG (atomically).
    ///
    /// # Errors
    /// [`RenderError::Encode`], [`RenderError::Io`].
    pub fn write_sheet_png(&self, path: &Path, exposure: f32) -> Result<(), RenderError> {
        write_atomically(path, &self.sheet_png(exposure)?)
    }

    /// [`Comparison::sheet`] encoded as PNG bytes.
    ///
    /// # Errors
    /// [`RenderError::Encode`].
    pub fn sheet_png(&self, exposure: f32) -> Result<Vec<u8>, RenderError> {
        let canvas = self.sheet(exposure);
        encode_png(&canvas.rgb, canvas.width as u32, canvas.height as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_are_computed_per_channel() {
        let r = Image::filled(2, 1, [1.0, 1.0, 1.0]);
        let x = Image::new(2, 1, vec![[1.0, 1.0, 1.0], [1.0, 1.0, 4.0]]);
        assert!((rmse(&x, &r) - (9.0f64 / 6.0).sqrt()).abs() < 1e-12);
        assert!((relative_mse(&x, &r) - 9.0 / (1.0 + REL_MSE_EPSILON) / 6.0).abs() < 1e-12);
    }

    #[test]
    fn short_numbers_fit() {
        assert_eq!(short(0.012346), "0.01235");
        assert_eq!(short(12.3456), "12.35");
        assert_eq!(short(2.5e-5), "2.50e-5");
        assert!(short(123456.0).len() <= 8);
        assert_eq!(seconds(3.0), "3");
        assert_eq!(seconds(1.5), "1.5");
        assert_eq!(clip("rel mse 0.08870", 8), "rel ms..");
        assert_eq!(clip("short", 8), "short");
    }
}
