//! `envlight importance`: a PNG showing the map and the density it is sampled with.
//!
//! Layout, top to bottom: the tone-mapped map, then a heat map of the solid-angle
//! pdf on a log scale (viridis, with a colour bar; pdf 0 is black), both in world
//! space (so `--rotate` shows), both with θ ticks down the left side and φ ticks
//! along the bottom. Sample directions, when asked for, are dots on both panels.

use std::f64::consts::PI;
use std::path::PathBuf;

use anyhow::Context;
use envlight::color::{linear_to_srgb, luminance};
use envlight::light::Mapping;
use envlight::mapping::{direction_to_equirect, equirect_to_direction};
use envlight::EnvironmentLight;
use envlight_render::font;
use image::ImageEncoder;
use rayon::prelude::*;

use super::Outcome;
use crate::light_args::LightArgs;
use crate::output::Output;
use crate::shading::{product_sampler, Density, NormalArgs};

/// Arguments of `envlight importance`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "The picture: on top the map, tone mapped (exposure from its median luminance, a \
filmic curve, sRGB); below it the solid-angle sampling density p(ω) in sr⁻¹ on a log \
scale (viridis; black where p = 0) with its colour bar. Both panels are the \
equirectangular world view: θ (0° = +z, up) runs down the side, φ (0° = +x, 90° = +y) \
along the bottom, whatever --mapping the light uses. With --samples N the first N \
directions `envlight sample` would draw (same --seed) are drawn as magenta dots on both \
panels. With --normal the lower panel is the product sampler's density for a surface \
with that normal (radiance × max(0, n·ω), docs/design.md §6a), and the dots its samples. \
Each pixel is the solid-angle weighted mean of radiance and pdf over points in \
it, enough to see every texel of maps wider than --width. When the map has a sun (a \
compact bright source, as `envlight sun` reports it), its disc is outlined in cyan on \
both panels (drawn at least 10 pixels across) and the top title gives its elevation, \
azimuth and angular radius.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    #[command(flatten)]
    normal: NormalArgs,

    /// The PNG file to write (atomically).
    #[arg(short = 'o', long = "output", value_name = "FILE.png")]
    output: PathBuf,

    /// Draw the first N sample directions as dots.
    #[arg(long, value_name = "N", default_value_t = 0)]
    samples: u64,

    /// Seed of the sample sequence (as in `envlight sample`).
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,

    /// Width in pixels of each panel (the map is resampled to W × W/2).
    #[arg(long, value_name = "W", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(64..=8192))]
    width: u32,
}

/// Colours of the chrome.
const BACKGROUND: [u8; 3] = [22, 22, 24];
const INK: [u8; 3] = [225, 225, 225];
const DIM: [u8; 3] = [150, 150, 150];
const DOT: [u8; 3] = [255, 0, 255];
const ZERO_PDF: [u8; 3] = [0, 0, 0];
const SUN_RING: [u8; 3] = [0, 230, 255];

/// Runs `envlight importance`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    let loaded = args.light.load()?;
    let light = &loaded.light;
    let pw = args.width as usize;
    let ph = (pw / 2).max(1);
    let product = product_sampler(light, args.normal.normal);
    let density = Density::new(light, product.as_ref(), args.normal.normal);

    let panels = Panels::new(light, &density, pw, ph);
    let exposure = panels.exposure();
    let (lo, hi) = panels.log_pdf_range();
    let dots: Vec<(usize, usize)> = (0..args.samples)
        .into_par_iter()
        .filter_map(|k| {
            let s = density.sample(envlight::rng::xi_2d(args.seed, k))?;
            let [u, v] = direction_to_equirect(s.direction);
            let x = ((u as f64 * pw as f64) as usize).min(pw - 1);
            let y = ((v as f64 * ph as f64) as usize).min(ph - 1);
            Some((x, y))
        })
        .collect();

    let scale = if pw >= 512 { 2 } else { 1 };
    let layout = Layout::new(pw, ph, scale);
    let mut canvas = Canvas::new(layout.width, layout.height, BACKGROUND);

    // Panel 1: the map.
    let mut map_title = format!(
        "RADIANCE  {}  EXPOSURE ×{}  FILMIC",
        display_name(&loaded.name),
        short_number(exposure as f64)
    );
    let sun = light.sun();
    if let Some(sun) = &sun {
        // The longest description of the sun that fits on the canvas.
        let (el, az) = (sun.elevation_deg(), sun.azimuth_deg());
        let room = layout.width - layout.left;
        let suffix = [
            format!(
                "  SUN EL {el:.1}° AZ {az:.1}° R {:.2}°",
                sun.angular_radius_deg()
            ),
            format!("  SUN {el:.1}°/{az:.1}°"),
            String::new(),
        ]
        .into_iter()
        .find(|s| font::text_extent(&format!("{map_title}{s}"), scale) <= room)
        .unwrap_or_default();
        map_title.push_str(&suffix);
    }
    let sun_ring = sun.map(|s| disc_outline(&s, pw, ph));
    canvas.panel(&layout, layout.top1, &map_title, &panels.rgb, |&rgb| {
        tone_map(rgb, exposure)
    });

    // Panel 2: the density.
    let mut density_title = match args.normal.normal {
        Some(n) => format!("PRODUCT PDF, N=({:.2},{:.2},{:.2}), LOG", n.x, n.y, n.z),
        None => "SAMPLING PDF PER SR, LOG SCALE".to_string(),
    };
    if loaded.black {
        density_title.push_str("  (ALL BLACK: PDF 0)");
    }
    if args.samples > 0 {
        density_title.push_str(&format!("  {} SAMPLES", args.samples));
    }
    canvas.panel(&layout, layout.top2, &density_title, &panels.pdf, |&p| {
        heat_colour(p, lo, hi)
    });

    for &top in &[layout.top1, layout.top2] {
        for &(x, y) in &dots {
            canvas.dot(layout.left + x, top + y, scale, DOT);
        }
        for &(x, y) in sun_ring.iter().flatten() {
            canvas.dot(layout.left + x, top + y, scale / 2, SUN_RING);
        }
        canvas.axes(&layout, top);
    }
    canvas.colour_bar(&layout, lo, hi);

    let mut out = Output::create(Some(&args.output))?;
    let name = out.name();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            &canvas.pixels,
            canvas.width as u32,
            canvas.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .with_context(|| format!("{name}: cannot write PNG"))?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// Pixels of the outline of the sun's disc on a `pw × ph` world lat-long panel: the
/// circle at its angular radius around its direction (at least 5 pixels of radius,
/// so a real sun shows), in the panel's equirectangular view.
fn disc_outline(sun: &envlight::Sun, pw: usize, ph: usize) -> Vec<(usize, usize)> {
    let c = sun.direction;
    let radius = sun.angular_radius.max(5.0 * PI / ph as f64);
    let helper = if c.z.abs() < 0.9 {
        envlight::Vec3::new(0.0, 0.0, 1.0)
    } else {
        envlight::Vec3::new(1.0, 0.0, 0.0)
    };
    let Some(a) = helper.cross(c).normalized() else {
        return Vec::new();
    };
    let b = c.cross(a);
    let (s, co) = (radius.sin() as f32, radius.cos() as f32);
    let steps = 4 * (pw + ph);
    (0..steps)
        .filter_map(|k| {
            let t = 2.0 * std::f32::consts::PI * k as f32 / steps as f32;
            let d = c * co + (a * t.cos() + b * t.sin()) * s;
            let [u, v] = direction_to_equirect(d.normalized()?);
            let x = ((u as f64 * pw as f64) as usize).min(pw - 1);
            let y = ((v as f64 * ph as f64) as usize).min(ph - 1);
            Some((x, y))
        })
        .collect()
}

/// The last path component of a map name, for the title.
pub(crate) fn display_name(name: &str) -> String {
    let base = std::path::Path::new(name)
        .file_name()
        .map_or_else(|| name.to_string(), |n| n.to_string_lossy().into_owned());
    base.chars().take(40).collect()
}

/// A number with about three significant digits, without exponent for moderate values.
pub(crate) fn short_number(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i32;
    if (-3..=4).contains(&magnitude) {
        let decimals = (2 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.2e}").to_uppercase()
    }
}

/// The map and its density resampled to the panel size, in world space.
struct Panels {
    /// Linear radiance per pixel (scale applied), row-major.
    rgb: Vec<[f32; 3]>,
    /// Solid-angle pdf per pixel: the probability in the pixel over its solid angle.
    pdf: Vec<f32>,
}

impl Panels {
    /// Each pixel of the `pw × ph` world lat-long panel is the solid-angle
    /// weighted mean of `radiance()` and `pdf()` at `sx × sy` midpoints of its
    /// sub-cells (each weighted by its exact solid angle `Δφ (cos θa − cos θb)`),
    /// with enough points to see every texel of the light's image: the image's
    /// resolution as a lat-long grid (2N × N for an N × N equal-area light) over
    /// the panel's. Asking the light about world directions shows whatever mapping
    /// and density it uses, and `--rotate` exactly.
    fn new(light: &EnvironmentLight, density: &Density, pw: usize, ph: usize) -> Self {
        let image = light.image();
        let (gw, gh) = match light.mapping() {
            Mapping::Equirectangular => (image.width(), image.height()),
            Mapping::EqualArea => (2 * image.width(), image.width()),
        };
        let (sx, sy) = (gw.div_ceil(pw).max(1), gh.div_ceil(ph).max(1));
        let pixels: Vec<([f32; 3], f32)> = (0..ph)
            .into_par_iter()
            .flat_map_iter(|y| {
                let rows: Vec<(f32, f64)> = (0..sy)
                    .map(|t| {
                        let va = (y * sy + t) as f64 / (sy * ph) as f64;
                        let vb = (y * sy + t + 1) as f64 / (sy * ph) as f64;
                        let band = (PI * va).cos() - (PI * vb).cos();
                        (((va + vb) * 0.5) as f32, band)
                    })
                    .collect();
                (0..pw).map(move |x| {
                    let mut rgb = [0.0f64; 3];
                    let mut pdf = 0.0f64;
                    let mut total = 0.0f64;
                    for &(v, band) in &rows {
                        for s in 0..sx {
                            let u = ((x * sx + s) as f32 + 0.5) / (sx * pw) as f32;
                            let d = equirect_to_direction(u, v).0;
                            let l = light.radiance(d);
                            for (a, c) in rgb.iter_mut().zip(l) {
                                *a += c as f64 * band;
                            }
                            pdf += density.pdf(d) as f64 * band;
                            total += band;
                        }
                    }
                    if total > 0.0 {
                        (rgb.map(|c| (c / total) as f32), (pdf / total) as f32)
                    } else {
                        ([0.0; 3], 0.0)
                    }
                })
            })
            .collect();
        let (rgb, pdf) = pixels.into_iter().unzip();
        Self { rgb, pdf }
    }

    /// [`exposure_of`] the panel.
    fn exposure(&self) -> f32 {
        exposure_of(&self.rgb)
    }

    /// `(log10 min, log10 max)` of the colour scale: the largest pdf down to the
    /// smallest positive one, at most 6 decades, at least 1.
    fn log_pdf_range(&self) -> (f32, f32) {
        let positive = self
            .pdf
            .iter()
            .copied()
            .filter(|&p| p > 0.0 && p.is_finite());
        let (min, max) = positive.fold((f32::INFINITY, 0.0f32), |(a, b), p| (a.min(p), b.max(p)));
        if max <= 0.0 {
            return (-1.0, 0.0);
        }
        let hi = max.log10();
        let lo = min.log10().max(hi - 6.0).min(hi - 1.0);
        (lo, hi)
    }
}

/// Exposure that puts the median pixel luminance of `rgb` at mid grey (0.18);
/// falls back on the mean for maps that are mostly black, and on 1 for black maps.
pub(crate) fn exposure_of(rgb: &[[f32; 3]]) -> f32 {
    let mut y: Vec<f32> = rgb.iter().map(|&c| luminance(c)).collect();
    let mean = y.iter().map(|&v| v as f64).sum::<f64>() / y.len().max(1) as f64;
    let middle = y.len() / 2;
    let median = if y.is_empty() {
        0.0
    } else {
        *y.select_nth_unstable_by(middle, f32::total_cmp).1
    };
    let key = if median > 0.0 { median as f64 } else { mean };
    if key > 0.0 && key.is_finite() {
        (0.18 / key) as f32
    } else {
        1.0
    }
}

/// Exposure, the ACES filmic fit (Narkowicz 2015), then sRGB encoding.
pub(crate) fn tone_map(rgb: [f32; 3], exposure: f32) -> [u8; 3] {
    rgb.map(|c| {
        let x = (c * exposure).max(0.0);
        let mapped = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
        let encoded = linear_to_srgb(if mapped.is_finite() { mapped } else { 1.0 });
        (encoded * 255.0 + 0.5) as u8
    })
}

/// Viridis (matplotlib), sampled at nine evenly spaced stops.
const VIRIDIS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [71, 45, 123],
    [59, 82, 139],
    [44, 114, 142],
    [33, 145, 140],
    [40, 174, 128],
    [94, 201, 98],
    [173, 220, 48],
    [253, 231, 37],
];

/// The colormap at `t ∈ [0, 1]` (linear between stops).
fn viridis(t: f32) -> [u8; 3] {
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    };
    let x = t * (VIRIDIS.len() - 1) as f32;
    let i = (x as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f32;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    [0, 1, 2].map(|k| (a[k] as f32 + f * (b[k] as f32 - a[k] as f32) + 0.5) as u8)
}

/// The heat-map colour of pdf `p` on the log scale `[lo, hi]`.
fn heat_colour(p: f32, lo: f32, hi: f32) -> [u8; 3] {
    if p.is_nan() || p <= 0.0 {
        return ZERO_PDF;
    }
    viridis((p.log10() - lo) / (hi - lo))
}

/// Where everything goes on the canvas, in pixels.
struct Layout {
    width: usize,
    height: usize,
    scale: usize,
    /// Left edge of both panels.
    left: usize,
    /// Top edges of the two panels.
    top1: usize,
    top2: usize,
    panel_w: usize,
    panel_h: usize,
}

impl Layout {
    fn new(panel_w: usize, panel_h: usize, scale: usize) -> Self {
        let line = (font::GLYPH_HEIGHT + 3) * scale;
        let tick = 4 * scale;
        // θ axis: "θ" then labels like "180°" then the tick.
        let left = font::text_extent("θ 180°", scale) + tick + 6 * scale;
        let top1 = 2 * line;
        // Below a panel: tick, φ labels, the axis name, then the next title.
        let below = tick + 2 * line + line / 2;
        let top2 = top1 + panel_h + below + line;
        let right =
            8 * scale + 10 * scale + 4 * scale + font::text_extent("1E-10", scale) + 8 * scale;
        Self {
            width: left + panel_w + right,
            height: top2 + panel_h + below,
            scale,
            left,
            top1,
            top2,
            panel_w,
            panel_h,
        }
    }

    fn title_gap(&self) -> usize {
        (font::GLYPH_HEIGHT + 4) * self.scale
    }
}

/// Drawn for characters the font lacks: a hollow box.
const MISSING_GLYPH: [u8; font::GLYPH_HEIGHT] = [0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F];

/// An RGB8 image being drawn.
struct Canvas {
    width: usize,
    height: usize,
    pixels: Vec<u8>,
}

impl Canvas {
    fn new(width: usize, height: usize, background: [u8; 3]) -> Self {
        let mut pixels = Vec::with_capacity(width * height * 3);
        for _ in 0..width * height {
            pixels.extend_from_slice(&background);
        }
        Self {
            width,
            height,
            pixels,
        }
    }

    #[inline]
    fn set(&mut self, x: usize, y: usize, c: [u8; 3]) {
        if x < self.width && y < self.height {
            let i = 3 * (y * self.width + x);
            self.pixels[i..i + 3].copy_from_slice(&c);
        }
    }

    fn fill(&mut self, x: usize, y: usize, w: usize, h: usize, c: [u8; 3]) {
        for yy in y..y + h {
            for xx in x..x + w {
                self.set(xx, yy, c);
            }
        }
    }

    fn blit(&mut self, x: usize, y: usize, w: usize, h: usize, src: &[[u8; 3]]) {
        for yy in 0..h {
            for xx in 0..w {
                self.set(x + xx, y + yy, src[yy * w + xx]);
            }
        }
    }

    /// A panel of the layout at `top`: its title above it, then `values` (row-major,
    /// the layout's panel size), each drawn in the colour `colour` gives it.
    fn panel<T: Sync>(
        &mut self,
        layout: &Layout,
        top: usize,
        title: &str,
        values: &[T],
        colour: impl Fn(&T) -> [u8; 3] + Sync + Send,
    ) {
        let scale = layout.scale;
        self.text(layout.left, top - layout.title_gap(), title, scale, INK);
        let pixels: Vec<[u8; 3]> = values.par_iter().map(colour).collect();
        self.blit(layout.left, top, layout.panel_w, layout.panel_h, &pixels);
    }

    fn text(&mut self, x: usize, y: usize, text: &str, scale: usize, c: [u8; 3]) {
        for (n, ch) in text.chars().enumerate() {
            let gx = x + n * font::ADVANCE * scale;
            let rows = font::try_glyph(ch).unwrap_or(MISSING_GLYPH);
            for (row, bits) in rows.iter().enumerate() {
                for col in 0..font::GLYPH_WIDTH {
                    if bits & (1 << (font::GLYPH_WIDTH - 1 - col)) != 0 {
                        self.fill(gx + col * scale, y + row * scale, scale, scale, c);
                    }
                }
            }
        }
    }

    /// A sample dot: a small square.
    fn dot(&mut self, x: usize, y: usize, scale: usize, c: [u8; 3]) {
        let r = scale.div_ceil(2);
        for yy in y.saturating_sub(r)..=y + r {
            for xx in x.saturating_sub(r)..=x + r {
                self.set(xx, yy, c);
            }
        }
    }

    /// Frame, θ ticks down the left (every 30°) and φ ticks along the bottom.
    fn axes(&mut self, layout: &Layout, top: usize) {
        let s = layout.scale;
        let (left, w, h) = (layout.left, layout.panel_w, layout.panel_h);
        let tick = 4 * s;
        // Frame just outside the panel.
        self.fill(left - 1, top - 1, w + 2, 1, DIM);
        self.fill(left - 1, top + h, w + 2, 1, DIM);
        self.fill(left - 1, top - 1, 1, h + 2, DIM);
        self.fill(left + w, top - 1, 1, h + 2, DIM);
        let glyph_h = font::GLYPH_HEIGHT * s;
        for theta in (0..=180).step_by(30) {
            let y = top + ((theta as f64 / 180.0) * (h - 1) as f64).round() as usize;
            self.fill(left - 1 - tick, y, tick, s, DIM);
            let label = format!("{theta}°");
            let lw = font::text_extent(&label, s);
            let ty = (y + s / 2)
                .saturating_sub(glyph_h / 2)
                .clamp(top.saturating_sub(glyph_h / 2), top + h - glyph_h / 2);
            self.text(left - 1 - tick - 2 * s - lw, ty, &label, s, INK);
        }
        // The axis name, halfway down, left of the labels.
        self.text(s, top + h / 2 + 8 * s, "θ", s, INK);
        // φ: the widest spacing that still leaves room between labels.
        let label_w = font::text_extent("360°", s) as f64;
        let step = [45, 90, 180]
            .into_iter()
            .find(|&d| d as f64 / 360.0 * w as f64 >= 1.5 * label_w)
            .unwrap_or(180);
        for phi in (0..=360).step_by(step) {
            let x = left + ((phi as f64 / 360.0) * (w - 1) as f64).round() as usize;
            self.fill(x, top + h + 1, s, tick, DIM);
            let label = format!("{phi}°");
            let lw = font::text_extent(&label, s);
            let lx = x
                .saturating_sub(lw / 2)
                .clamp(left.saturating_sub(lw / 2), left + w - lw / 2);
            self.text(lx, top + h + 1 + tick + 2 * s, &label, s, INK);
        }
        let name_y = top + h + 1 + tick + 2 * s + (font::GLYPH_HEIGHT + 3) * s;
        self.text(
            left + w / 2 - font::text_extent("φ", s) / 2,
            name_y,
            "φ",
            s,
            INK,
        );
    }

    /// The density panel's colour bar with decade labels, and a swatch for pdf 0.
    fn colour_bar(&mut self, layout: &Layout, lo: f32, hi: f32) {
        let s = layout.scale;
        let x = layout.left + layout.panel_w + 8 * s;
        let bar_w = 10 * s;
        let top = layout.top2;
        let swatch = 8 * s;
        let h = layout.panel_h.saturating_sub(swatch + 4 * s).max(2);
        for yy in 0..h {
            let t = 1.0 - yy as f32 / (h - 1) as f32;
            self.fill(x, top + yy, bar_w, 1, viridis(t));
        }
        self.fill(x, top + h + 4 * s, bar_w, swatch, ZERO_PDF);
        self.fill(x - 1, top + h + 4 * s - 1, bar_w + 2, 1, DIM);
        self.fill(x - 1, top + h + 4 * s + swatch, bar_w + 2, 1, DIM);
        let label_x = x + bar_w + 4 * s;
        let glyph_h = font::GLYPH_HEIGHT * s;
        self.text(
            label_x,
            top + h + 4 * s + swatch / 2 - glyph_h / 2,
            "0",
            s,
            INK,
        );
        // Decades, thinned so labels never overlap.
        let per_decade = h as f32 / (hi - lo);
        let every = ((2.0 * glyph_h as f32 / per_decade).ceil() as i32).max(1);
        let first = lo.ceil() as i32;
        let last = hi.floor() as i32;
        for k in first..=last {
            if (last - k) % every != 0 {
                continue;
            }
            let y = top + ((hi - k as f32) * per_decade).round() as usize;
            // The tick is a notch across the bar: outside it would read as a minus.
            self.fill(x, y.min(top + h - 1), bar_w, 1, BACKGROUND);
            let ty = y
                .saturating_sub(glyph_h / 2)
                .clamp(top.saturating_sub(glyph_h / 2), top + h);
            self.text(label_x, ty, &decade_label(k), s, INK);
        }
    }
}

/// `10^k` as a short label: plain decimals for -2..=3, `1E{k}` otherwise.
fn decade_label(k: i32) -> String {
    match k {
        -2 => "0.01".into(),
        -1 => "0.1".into(),
        0 => "1".into(),
        1 => "10".into(),
        2 => "100".into(),
        3 => "1000".into(),
        _ => format!("1E{k}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_cover_the_scale() {
        assert_eq!(viridis(0.0), VIRIDIS[0]);
        assert_eq!(viridis(1.0), VIRIDIS[8]);
        assert_eq!(viridis(f32::NAN), VIRIDIS[0]);
        assert_eq!(heat_colour(0.0, -1.0, 1.0), ZERO_PDF);
        assert_eq!(tone_map([0.0; 3], 1.0), [0, 0, 0]);
        assert_eq!(tone_map([1e30; 3], 1.0)[0], 255);
        assert_eq!(short_number(1.6234), "1.62");
        assert_eq!(short_number(123.4), "123");
    }
}
