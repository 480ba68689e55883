//! `envlight visibility`: what a saved visibility cache holds, and a picture of
//! what one of its entries learned.
//!
//! The cache file (written by `envlight render --strategy mis-visibility
//! --save-visibility FILE`, or by the library's `VisibilityCache::save`) holds
//! two keys: the hash of the light it was learned under and a scene key. The
//! scene key is read from the file unless `--scene-key` asks for one; the light
//! is rebuilt from MAP and the light options, and must hash the same.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{bail, Context};
use envlight::color::luminance;
use envlight::light::Mapping;
use envlight::product::ProductTables;
use envlight::visibility::{light_hash, read_keys, SavedKeys};
use envlight::{EnvironmentLight, ProductOptions, ProductSampler, Vec3, VisibilityCache};
use envlight_render::font::{self, Canvas};
use image::ImageEncoder;
use rayon::prelude::*;
use serde_json::json;

use super::importance::{display_name, exposure_of, short_number, tone_map};
use super::{Outcome, UsageError};
use crate::light_args::LightArgs;
use crate::output::Output;

/// Arguments of `envlight visibility`.
#[derive(Debug, clap::Args)]
#[command(allow_missing_positional = true, after_help = concat!(
    "CACHE is a visibility cache file, as `envlight render --strategy mis-visibility \
--save-visibility CACHE` writes it (its scene key: the scene's name, e.g. room). The file \
holds the hash of the light it was learned under: MAP, the light options and the product \
sampler's patch grid must give the same light as the render's (a different hash is \
exit 1, naming both). The scene key is the file's own unless --scene-key asks for \
one (a different key is exit 1, naming both).\n\n\
The summary: entries, bytes (their tables and the lookup in memory), radius (the side of \
the cells that group points into entries, world units), mean visibility (per entry the \
share of the light it faces that it sees, averaged over entries), rays (traced to build it), the scene key and the map hash. \
With --json, one JSON object with the keys cache, file_bytes, map, map_hash, \
map_matches, scene_key, entries, bytes, radius, mean_visibility, rays, patches ([Pw, \
Ph]) and options; with --entry also entry (index, normal, cos_spread, patches_faced, \
seen: the share of the unoccluded irradiance Y·cos⁺ at its mean normal that its \
estimates let through), with --image also image.\n\n\
The picture (--entry E --image FILE.png): the map, tone mapped as `envlight importance` \
does, in the light's own image layout (lat-long: u across, v down; equal-area: the \
octahedral square), each patch of the product sampler's grid multiplied by the entry's \
visibility estimate V (black: every ray was blocked; unchanged: every ray escaped). \
Patches whose estimate is the untouched 1 and which lie wholly or mostly behind the \
entry's normals (never traced) are greyed and hatched. A title band above it names the \
entry, its normal and the share of its sky it sees.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    /// The visibility cache file.
    #[arg(value_name = "CACHE")]
    cache: PathBuf,

    /// The scene key to require (default: the one the file holds).
    #[arg(long, value_name = "KEY")]
    scene_key: Option<String>,

    /// Print one JSON object instead of the readable summary.
    #[arg(long)]
    json: bool,

    /// Also describe entry E (0 to entries - 1).
    #[arg(long, value_name = "E")]
    entry: Option<usize>,

    /// Draw entry E's visibility over the map to FILE.png (atomically); needs
    /// --entry.
    #[arg(long, value_name = "FILE.png", requires = "entry")]
    image: Option<PathBuf>,

    /// Width in pixels of the picture (its map panel has the light image's aspect).
    #[arg(long, value_name = "W", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(64..=8192))]
    width: u32,

    /// The product sampler's patch grid the render used (`render
    /// --product-patches`), e.g. `16x8`.
    #[arg(long, value_name = "PWxPH", value_parser = super::render::parse_patches, hide = true)]
    product_patches: Option<[usize; 2]>,
}

/// Colours of the picture's chrome.
const BACKGROUND: [u8; 3] = [22, 22, 24];
const INK: [u8; 3] = [225, 225, 225];
const HATCH: [u8; 3] = [150, 150, 150];

/// Runs `envlight visibility`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    args.light.check()?;
    let name = args.cache.display().to_string();
    let bytes = std::fs::read(&args.cache).with_context(|| format!("{name}: cannot read"))?;
    let keys = read_keys(&bytes, &name)?;
    if let Some(e) = args.entry {
        if e >= keys.entries {
            return Err(UsageError(format!(
                "--entry {e}: {name} has {} entries{}",
                keys.entries,
                match keys.entries {
                    0 => String::new(),
                    n => format!(" (0 to {})", n - 1),
                }
            ))
            .into());
        }
    }
    let scene_key = match &args.scene_key {
        Some(asked) if *asked != keys.scene_key => bail!(
            "{name}: made for scene key {:?}, not {asked:?} (--scene-key)",
            keys.scene_key
        ),
        _ => keys.scene_key.clone(),
    };

    let loaded = args.light.load()?;
    let product = Arc::new(ProductSampler::new(
        Arc::clone(&loaded.light),
        ProductOptions {
            patches: args.product_patches,
            ..Default::default()
        },
    ));
    let hash = light_hash(&product);
    if hash != keys.light_hash {
        let [pw, ph] = product.patches();
        let grid = if keys.patches != pw * ph {
            format!(
                "; its estimates are over {} patches, not {pw} x {ph}: give the render's \
                 --product-patches",
                keys.patches
            )
        } else {
            String::new()
        };
        bail!(
            "{name}: made for map hash {:016x}, but {} with these light options has map hash \
             {hash:016x} (light it as the render did: same MAP, light options and patch \
             grid{grid})",
            keys.light_hash,
            loaded.name
        );
    }
    let cache = VisibilityCache::from_bytes(&bytes, &name, Arc::clone(&product), &scene_key)?;
    let summary = cache.summary();
    let [pw, ph] = product.patches();
    let grid = (args.entry.is_some()).then(|| PatchGrid::new(&product.cosine_tables()));
    let entry = args
        .entry
        .zip(grid.as_ref())
        .map(|(e, grid)| EntryView::new(&cache, e, grid, &loaded.light));

    if let (Some(path), Some(view), Some(grid)) = (&args.image, &entry, &grid) {
        let picture = draw(
            &loaded.light,
            &loaded.name,
            grid,
            view,
            &keys,
            args.width as usize,
        );
        write_png(path, &picture)?;
    }

    let options = cache.options();
    let text = if args.json {
        let mut value = json!({
            "cache": name,
            "file_bytes": bytes.len(),
            "map": loaded.name,
            "map_hash": format!("{hash:016x}"),
            "map_matches": true,
            "scene_key": scene_key,
            "entries": summary.entries,
            "bytes": summary.bytes,
            "radius": summary.radius,
            "mean_visibility": summary.mean_visibility,
            "rays": summary.rays,
            "patches": [pw, ph],
            "options": {
                "normal_bins": options.normal_bins,
                "target_entries": options.target_entries,
                "memory_budget": options.memory_budget,
                "rays_per_patch": options.rays_per_patch,
                "refine_rays": options.refine_rays,
                "learned_share": options.learned_share,
                "prior": options.prior,
                "seed": options.seed,
            },
        });
        if let (Some(v), Some(object)) = (&entry, value.as_object_mut()) {
            object.insert(
                "entry".into(),
                json!({
                    "index": v.index,
                    "normal": v.normal.to_array(),
                    "cos_spread": v.cos_spread,
                    "patches_faced": v.faced(),
                    "seen": v.seen,
                }),
            );
        }
        if let (Some(path), Some(object)) = (&args.image, value.as_object_mut()) {
            object.insert("image".into(), json!(path.display().to_string()));
        }
        let mut text = serde_json::to_string_pretty(&value).context("cannot format JSON")?;
        text.push('\n');
        text
    } else {
        let mut lines = vec![
            ("cache", format!("{name} ({} bytes)", bytes.len())),
            ("scene key", format!("{scene_key:?}")),
            ("map", loaded.name.clone()),
            (
                "map hash",
                format!("{hash:016x} (matches the cache's; patches {pw} x {ph})"),
            ),
            ("entries", summary.entries.to_string()),
            (
                "bytes",
                format!(
                    "{} ({:.2} MiB: the entries' tables and the lookup)",
                    summary.bytes,
                    summary.bytes as f64 / (1024.0 * 1024.0)
                ),
            ),
            (
                "radius",
                format!("{} (side of the cells, world units)", summary.radius),
            ),
            (
                "mean vis",
                format!(
                    "{:.4} (per entry the share of the light it faces that it sees, averaged)",
                    summary.mean_visibility
                ),
            ),
            ("rays", summary.rays.to_string()),
            (
                "options",
                format!(
                    "normal bins {}, rays per patch {} then {} per edge patch, learned share {}, \
                     prior {}",
                    options.normal_bins,
                    options.rays_per_patch,
                    options.refine_rays,
                    options.learned_share,
                    options.prior
                ),
            ),
        ];
        if let Some(v) = &entry {
            let n = v.normal;
            lines.push((
                "entry",
                format!(
                    "{}: normal ({:.4}, {:.4}, {:.4}), spread {:.1}°, faces {} of {} patches, \
                     sees {} of its unoccluded irradiance",
                    v.index,
                    n.x,
                    n.y,
                    n.z,
                    v.cos_spread.clamp(-1.0, 1.0).acos().to_degrees(),
                    v.faced(),
                    v.front.len(),
                    v.seen
                        .map_or_else(|| "n/a".to_string(), |s| format!("{:.1}%", 100.0 * s))
                ),
            ));
        }
        if let Some(path) = &args.image {
            lines.push(("image", path.display().to_string()));
        }
        let mut text = String::new();
        for (key, value) in lines {
            text.push_str(&format!("{key:<12} {value}\n"));
        }
        text
    };
    let mut out = Output::create(None)?;
    out.write_all(text.as_bytes())
        .with_context(|| format!("{}: write failed", out.name()))?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// Where the product sampler's patches lie in the light's image: patch `(c, r)`
/// covers `u ∈ [u_edges[c], u_edges[c + 1])` and `v ∈ [v_edges[r], v_edges[r + 1])`
/// (its cells' extent: texels, or the cells between the bilinear density's
/// nodes).
struct PatchGrid {
    columns: usize,
    u_edges: Vec<f64>,
    v_edges: Vec<f64>,
}

impl PatchGrid {
    fn new(tables: &ProductTables) -> Self {
        let [columns, rows] = tables.patches.map(|n| n as usize);
        let [cw, ch] = tables.cells.map(|n| n as usize);
        let edge = |nodes: &[f64], cells: usize, i: usize| -> f64 {
            if nodes.is_empty() {
                i as f64 / cells as f64
            } else {
                nodes[i.min(nodes.len() - 1)]
            }
        };
        let u_edges = (0..columns)
            .map(|c| edge(&tables.u_nodes, cw, tables.spans[c][0] as usize))
            .chain([1.0])
            .collect();
        let v_edges = (0..rows)
            .map(|r| edge(&tables.v_nodes, ch, tables.spans[r * columns][1] as usize))
            .chain([1.0])
            .collect();
        Self {
            columns,
            u_edges,
            v_edges,
        }
    }

    fn count(&self) -> usize {
        self.columns * (self.v_edges.len() - 1)
    }

    /// The patch holding image point `uv`.
    fn patch(&self, uv: [f64; 2]) -> usize {
        let find = |edges: &[f64], x: f64| {
            let n = edges.len() - 1;
            edges[1..n].partition_point(|&e| e <= x)
        };
        find(&self.v_edges, uv[1]) * self.columns + find(&self.u_edges, uv[0])
    }

    /// Patch `k`'s `[u0, u1]` and `[v0, v1]`.
    fn bounds(&self, k: usize) -> ([f64; 2], [f64; 2]) {
        let (c, r) = (k % self.columns, k / self.columns);
        (
            [self.u_edges[c], self.u_edges[c + 1]],
            [self.v_edges[r], self.v_edges[r + 1]],
        )
    }
}

/// `dω / du dv` relative to its largest value: `sin θ` on a lat-long image, 1 on
/// the equal-area square.
fn area_factor(mapping: Mapping, v: f64) -> f64 {
    match mapping {
        Mapping::Equirectangular => (std::f64::consts::PI * v).sin(),
        Mapping::EqualArea => 1.0,
    }
}

/// One entry as the command shows it.
struct EntryView<'a> {
    index: usize,
    normal: Vec3,
    cos_spread: f32,
    /// `V̂` per patch.
    visibility: &'a [f32],
    /// The share of the patch's directions (on a grid over it) that lie within
    /// 90° plus the spread of the normal: 0 for a patch the entry cannot face
    /// (never traced: its `V̂` is 1).
    front: Vec<f32>,
    /// `Σ Y cos⁺ V̂ / Σ Y cos⁺` over the map at the mean normal: the share of the
    /// unoccluded irradiance the estimates let through (`None` when no light
    /// reaches the normal).
    seen: Option<f64>,
}

impl<'a> EntryView<'a> {
    fn new(
        cache: &'a VisibilityCache,
        e: usize,
        grid: &PatchGrid,
        light: &EnvironmentLight,
    ) -> Self {
        let (normal, cos_spread) = cache.entry_normal(e);
        let visibility = cache.visibility(e);
        // A direction faces some normal of the entry when n·ω > cos(90° + β) = -sin β.
        let sin_spread = (1.0 - cos_spread.clamp(-1.0, 1.0).powi(2)).max(0.0).sqrt();
        let threshold = -sin_spread - 0.02;
        const STEPS: usize = 6;
        let front = (0..grid.count())
            .into_par_iter()
            .map(|k| {
                let (u, v) = grid.bounds(k);
                let mut inside = 0;
                for i in 0..=STEPS {
                    for j in 0..=STEPS {
                        let s = u[0] + (u[1] - u[0]) * i as f64 / STEPS as f64;
                        let t = v[0] + (v[1] - v[0]) * j as f64 / STEPS as f64;
                        let d = light.uv_to_direction([s as f32, t as f32]);
                        inside += (d.dot(normal) > threshold) as usize;
                    }
                }
                inside as f32 / ((STEPS + 1) * (STEPS + 1)) as f32
            })
            .collect();
        // The irradiance at the mean normal, on a grid of about the image's
        // resolution (at most 1024 across).
        let image = light.image();
        let gw = image.width().clamp(64, 1024);
        let gh = (gw * image.height() / image.width()).max(16);
        let mapping = light.mapping();
        let (seen, total) = (0..gh)
            .into_par_iter()
            .map(|y| {
                let v = (y as f64 + 0.5) / gh as f64;
                let jacobian = area_factor(mapping, v);
                let (mut seen, mut total) = (0.0f64, 0.0f64);
                for x in 0..gw {
                    let u = (x as f64 + 0.5) / gw as f64;
                    let d = light.uv_to_direction([u as f32, v as f32]);
                    let cos = d.dot(normal) as f64;
                    if cos <= 0.0 {
                        continue;
                    }
                    let w = luminance(light.radiance(d)) as f64 * cos * jacobian;
                    total += w;
                    seen += w * visibility[grid.patch([u, v])] as f64;
                }
                (seen, total)
            })
            .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
        Self {
            index: e,
            normal,
            cos_spread,
            visibility,
            front,
            seen: (total > 0.0).then(|| seen / total),
        }
    }

    /// Patches some direction of which the entry faces.
    fn faced(&self) -> usize {
        self.front.iter().filter(|&&f| f > 0.0).count()
    }

    /// Whether patch `k` is drawn as not faced: its estimate is the untouched 1
    /// and it lies wholly (never traced) or mostly (its few rays most likely
    /// all fell behind the surface, none traced) behind the entry's normals. A
    /// patch in front at 1 is one whose rays all escaped.
    fn hatched(&self, k: usize) -> bool {
        self.visibility[k] == 1.0 && self.front[k] < 0.5
    }
}

/// Text scale of the picture's title band at width `width`.
fn text_scale(width: usize) -> usize {
    if width >= 1024 {
        2
    } else {
        1
    }
}

/// Height of the title band: two lines of text.
fn band_height(scale: usize) -> usize {
    (2 * (font::GLYPH_HEIGHT + 3) + 4) * scale
}

/// The picture: the title band, then the map in the light's image layout,
/// `width` wide, each patch multiplied by the entry's `V̂`, patches it cannot
/// face greyed and hatched.
fn draw(
    light: &EnvironmentLight,
    map_name: &str,
    grid: &PatchGrid,
    entry: &EntryView,
    keys: &SavedKeys,
    width: usize,
) -> Canvas {
    let image = light.image();
    let (pw, ph) = (
        width,
        ((width * image.height()) as f64 / image.width() as f64)
            .round()
            .max(1.0) as usize,
    );
    // Sub-samples per pixel: enough to see every texel of an image wider than
    // the panel (at most 4 × 4).
    let sx = image.width().div_ceil(pw).clamp(1, 4);
    let sy = image.height().div_ceil(ph).clamp(1, 4);
    let pixels: Vec<([f32; 3], usize)> = (0..ph)
        .into_par_iter()
        .flat_map_iter(|y| {
            (0..pw).map(move |x| {
                let mut rgb = [0.0f32; 3];
                for j in 0..sy {
                    for i in 0..sx {
                        let u = (x as f32 + (i as f32 + 0.5) / sx as f32) / pw as f32;
                        let v = (y as f32 + (j as f32 + 0.5) / sy as f32) / ph as f32;
                        let l = light.radiance(light.uv_to_direction([u, v]));
                        for (a, c) in rgb.iter_mut().zip(l) {
                            *a += c / (sx * sy) as f32;
                        }
                    }
                }
                let centre = [(x as f64 + 0.5) / pw as f64, (y as f64 + 0.5) / ph as f64];
                (rgb, grid.patch(centre))
            })
        })
        .collect();
    let radiance: Vec<[f32; 3]> = pixels.iter().map(|p| p.0).collect();
    let exposure = exposure_of(&radiance);
    let mut rgb = Vec::with_capacity(3 * pw * ph);
    for (n, &(l, k)) in pixels.iter().enumerate() {
        let (x, y) = (n % pw, n / pw);
        let shown = tone_map(l, exposure);
        let colour = if entry.hatched(k) {
            if (x + y) % 8 < 2 {
                HATCH
            } else {
                // Grey, dimmed: the map's brightness without its colour.
                let g = (shown.iter().map(|&c| c as u32).sum::<u32>() / 3) as f32;
                [(0.35 * g + 30.0) as u8; 3]
            }
        } else {
            let vis = entry.visibility[k].clamp(0.0, 1.0);
            shown.map(|c| (c as f32 * vis + 0.5) as u8)
        };
        rgb.extend_from_slice(&colour);
    }

    let scale = text_scale(width);
    let band = band_height(scale);
    let mut canvas = Canvas::new(pw, band + ph, BACKGROUND);
    canvas.blit(0, band, pw, ph, &rgb);
    let n = entry.normal;
    let seen = entry
        .seen
        .map_or_else(|| "NO LIGHT".to_string(), |s| format!("{:.0}%", 100.0 * s));
    let line1 = fit(
        [
            format!(
                "ENTRY {} OF {}  N=({:.2},{:.2},{:.2})  SEES {seen} OF ITS SKY",
                entry.index, keys.entries, n.x, n.y, n.z
            ),
            format!("ENTRY {}/{}  SEES {seen}", entry.index, keys.entries),
            format!("{}/{}", entry.index, keys.entries),
        ],
        width,
        scale,
    );
    let line2 = fit(
        [
            format!(
                "{}  ×V PER PATCH ({}X{})  HATCHED: FACES AWAY  EXPOSURE ×{}",
                display_name(map_name),
                grid.columns,
                grid.v_edges.len() - 1,
                short_number(exposure as f64)
            ),
            "×V PER PATCH  HATCHED: FACES AWAY".to_string(),
            "×V".to_string(),
        ],
        width,
        scale,
    );
    let line = (font::GLYPH_HEIGHT + 3) * scale;
    canvas.text(2 * scale, 2 * scale, &line1, scale, INK);
    canvas.text(2 * scale, 2 * scale + line, &line2, scale, INK);
    canvas
}

/// The first of `variants` (longest first) that fits in `width` pixels at
/// `scale` with the band's margins, or the last.
fn fit<const N: usize>(variants: [String; N], width: usize, scale: usize) -> String {
    let room = width.saturating_sub(4 * scale);
    let mut variants = Vec::from(variants);
    let last = variants.pop().unwrap_or_default();
    variants
        .into_iter()
        .find(|v| font::text_extent(v, scale) <= room)
        .unwrap_or(last)
}

/// Writes `canvas` to `path` as a PNG, atomically.
fn write_png(path: &Path, canvas: &Canvas) -> anyhow::Result<()> {
    let mut out = Output::create(Some(path))?;
    let name = out.name();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            &canvas.rgb,
            canvas.width as u32,
            canvas.height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .with_context(|| format!("{name}: cannot write PNG"))?;
    out.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patches_are_found_by_their_edges() {
        let grid = PatchGrid {
            columns: 4,
            u_edges: vec![0.0, 0.25, 0.5, 0.75, 1.0],
            v_edges: vec![0.0, 0.5, 1.0],
        };
        assert_eq!(grid.count(), 8);
        assert_eq!(grid.patch([0.0, 0.0]), 0);
        assert_eq!(grid.patch([0.3, 0.2]), 1);
        assert_eq!(grid.patch([0.999, 0.7]), 7);
        assert_eq!(grid.patch([1.0, 1.0]), 7);
        assert_eq!(grid.bounds(5), ([0.25, 0.5], [0.5, 1.0]));
    }
}
