//! `envlight render`: the preview path tracer (crate `envlight-render`) lit by the map.
//!
//! One render with one strategy, written by extension (`.exr`/`.pfm` linear, `.png`
//! tone mapped); or, with `--compare`, every strategy against a reference, a table on
//! stdout and one labelled comparison PNG.
//!
//! Wiring (main.rs): a variant `Render(cmd::render::RenderArgs)` and the arm
//! `Command::Render(args) => cmd::render::run(args).map(|()| cmd::Outcome::Success)`;
//! Cargo.toml: `envlight-render = { path = "../envlight-render" }`.

use std::io::Write;
use std::path::PathBuf;
use std::sync::Mutex;

use anyhow::Context;
use clap::builder::TypedValueParser as _;
use envlight_render::{
    auto_exposure, compare, encode_image, read_image, render_with_visibility, CompareSettings,
    ImageFormat, RenderSettings, Scene, Strategy, SCENE_NAMES,
};

use super::UsageError;
use crate::light_args::LightArgs;
use crate::output::{write_bytes, Output};
use crate::progress::Progress;

/// Arguments of `envlight render`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Scenes: balls (diffuse, rough copper, near-mirror silver and blue plastic spheres on a \
checkered ground), diffuse (three white diffuse spheres of albedo 0.8 on a grey ground of \
albedo 0.5), furnace (one diffuse sphere of albedo 0.5: under a constant map of \
radiance 1 it renders 0.5 on the sphere and 1 around it), room (a closed room lit only \
through a window and a skylight, which are its portals).\n\n\
Strategies estimate the light at each path vertex: uniform (uniform sphere directions), \
bsdf (BSDF sampling only), light (environment importance sampling only), mis (both, \
power heuristic), mis-compensated (mis with the map's mean luminance subtracted from the \
light's sampling density, after Karlik et al. 2019; unbiased because BSDF sampling \
covers what it leaves out), product (the light sampled in proportion to radiance times \
the surface's cosine, or cosine times a GGX lobe for metals, at each shading point; each \
sample weighted by the true BSDF), mis-product (product and BSDF sampling, power \
heuristic), portal (the light sampled only through the scene's portals, in proportion to \
the radiance seen through them; the whole light in a scene without portals), mis-portal \
(portal and BSDF sampling, balance heuristic). Paths use next-event estimation with shadow rays and \
Russian roulette after 3 bounces. The image is the same for a given --seed whatever the \
number of threads.\n\n\
--compare renders every strategy at --spp, then again at equal time: each for as long as \
mis took at --spp in the same run (or for --equal-time SECONDS each), measures RMSE and \
relative MSE against --reference FILE (.exr/.pfm) or a mis render at --reference-spp, \
prints the table (RMSE/mis compares rows of the same budget) and writes a labelled PNG \
to -o. Equal time is the fair comparison: a strategy that costs more per sample takes \
fewer of them.\n\n",
    crate::conventions!()
))]
pub struct RenderArgs {
    #[command(flatten)]
    light: LightArgs,

    /// Built-in scene.
    #[arg(long, value_name = "NAME", default_value = "balls",
          value_parser = clap::builder::PossibleValuesParser::new(SCENE_NAMES))]
    scene: String,

    /// Samples per pixel.
    #[arg(long, value_name = "N", default_value_t = 64,
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    spp: u32,

    /// How the light is estimated at each vertex.
    #[arg(long, value_name = "S", default_value = "mis-visibility",
          value_parser = clap::builder::PossibleValuesParser::new(Strategy::ALL.map(Strategy::name))
              .map(|s| s.parse::<Strategy>().unwrap_or_default()))]
    strategy: Strategy,

    /// Image width in pixels.
    #[arg(long, value_name = "W", default_value_t = 640,
          value_parser = clap::value_parser!(u32).range(1..=16384))]
    width: u32,

    /// Image height in pixels.
    #[arg(long, value_name = "H", default_value_t = 360,
          value_parser = clap::value_parser!(u32).range(1..=16384))]
    height: u32,

    /// Largest number of surface interactions on a path.
    #[arg(long, value_name = "D", default_value_t = 8,
          value_parser = clap::value_parser!(u32).range(0..=1000))]
    max_depth: u32,

    /// Seed of the random streams.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,

    /// Output file: .exr or .pfm (linear float) or .png (tone mapped). With --compare,
    /// the comparison PNG.
    #[arg(
        short = 'o',
        long = "output",
        value_name = "FILE",
        default_value = "render.png"
    )]
    output: PathBuf,

    /// Exposure in stops applied before tone mapping (PNG only). Default: automatic,
    /// the image's (with --compare, the reference's) log-average luminance made
    /// middle grey.
    #[arg(long, value_name = "STOPS", allow_hyphen_values = true)]
    exposure: Option<f32>,

    /// Render every strategy and compare them against a reference.
    #[arg(long)]
    compare: bool,

    /// With --compare, render each strategy for SECONDS of wall time in the equal-time
    /// row (default: as long as mis took at --spp).
    #[arg(long, value_name = "SECONDS", requires = "compare")]
    equal_time: Option<f64>,

    /// The product strategies' patch grid, e.g. `16x8` (for measurements; default:
    /// the library's).
    #[arg(long, value_name = "PWxPH", value_parser = parse_patches, hide = true)]
    product_patches: Option<[usize; 2]>,

    /// The product strategies weight every patch at each shading point, without
    /// tables (an on-the-fly product, for measurements against the tables).
    #[arg(long, hide = true)]
    product_on_the_fly: bool,

    /// mis-visibility: the learned distribution's share of the mixture, in [0, 1)
    /// (for measurements; default: the library's).
    #[arg(long, value_name = "A", hide = true)]
    visibility_share: Option<f32>,

    /// mis-visibility: rays per entry and patch (for measurements).
    #[arg(long, value_name = "N", hide = true)]
    visibility_rays: Option<usize>,

    /// mis-visibility: rays per entry and edge patch in the second pass (for
    /// measurements).
    #[arg(long, value_name = "N", hide = true)]
    visibility_refine: Option<usize>,

    /// mis-visibility: the number of entries the cache aims at (for measurements).
    #[arg(long, value_name = "N", hide = true)]
    visibility_entries: Option<usize>,

    /// mis-visibility: the prior count of unoccluded rays per estimate (for
    /// measurements).
    #[arg(long, value_name = "A", hide = true)]
    visibility_prior: Option<f32>,

    /// mis-visibility: save the visibility cache the render built to FILE (its
    /// scene key: the scene's name), for `envlight visibility` to inspect. Needs
    /// --strategy mis-visibility or --compare.
    #[arg(long, value_name = "FILE", hide = true)]
    save_visibility: Option<PathBuf>,

    /// With --compare, the reference image (.exr or .pfm of the same size) instead of
    /// rendering one.
    #[arg(long, value_name = "FILE", requires = "compare")]
    reference: Option<PathBuf>,

    /// With --compare and no --reference, samples per pixel of the mis reference.
    #[arg(long, value_name = "N", default_value_t = 1024,
          value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    reference_spp: u32,
}

/// Adapts the renderer's `(stage, done, total)` reports to the CLI's progress bars:
/// one bar per stage, replaced when the stage changes.
struct Bars {
    current: Mutex<Option<(String, Progress, u64)>>,
}

impl envlight_render::Progress for Bars {
    fn report(&self, stage: &str, done: u64, total: u64) {
        let Ok(mut current) = self.current.lock() else {
            return;
        };
        if current.as_ref().map(|c| c.0.as_str()) != Some(stage) {
            if let Some((_, bar, _)) = current.take() {
                bar.finish();
            }
            *current = Some((stage.to_string(), Progress::bar(total, stage), 0));
        }
        if let Some((_, bar, last)) = current.as_mut() {
            if done > *last {
                bar.inc(done - *last);
                *last = done;
            }
        }
    }
}

impl Bars {
    fn new() -> Self {
        Self {
            current: Mutex::new(None),
        }
    }

    fn finish(&self) {
        if let Ok(mut current) = self.current.lock() {
            if let Some((_, bar, _)) = current.take() {
                bar.finish();
            }
        }
    }
}

/// Runs `envlight render`.
pub fn run(args: &RenderArgs) -> anyhow::Result<()> {
    // Check what can be checked before any work.
    let format =
        ImageFormat::from_path(&args.output).map_err(|e| UsageError(format!("-o {}", e)))?;
    if args.compare && format != ImageFormat::Png {
        return Err(UsageError(format!(
            "{}: --compare writes a PNG; use a .png output",
            args.output.display()
        ))
        .into());
    }
    if let Some(t) = args.equal_time {
        if !(t > 0.0 && t.is_finite()) {
            return Err(UsageError(format!(
                "--equal-time must be a positive number of seconds, got {t}"
            ))
            .into());
        }
    }
    if args.exposure.is_some_and(|e| !e.is_finite()) {
        return Err(UsageError("--exposure must be finite".into()).into());
    }
    let (width, height) = (args.width as usize, args.height as usize);
    if width * height > 1 << 26 {
        return Err(UsageError(format!(
            "{width}x{height} is too large (at most 2^26 pixels)"
        ))
        .into());
    }
    if let Some(path) = &args.save_visibility {
        if !args.compare && !args.strategy.uses_visibility() {
            return Err(UsageError(format!(
                "--save-visibility {}: only --strategy {} (or --compare) builds a \
                 visibility cache, not --strategy {}",
                path.display(),
                Strategy::MisVisibility,
                args.strategy
            ))
            .into());
        }
        // Found now rather than when the finished render cannot be saved.
        if path.is_dir() {
            anyhow::bail!(
                "{}: cannot save the visibility cache: it is a directory",
                path.display()
            );
        }
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            if !dir.is_dir() {
                anyhow::bail!(
                    "{}: cannot save the visibility cache: no folder {}",
                    path.display(),
                    dir.display()
                );
            }
        }
    }
    let scene = Scene::builtin(&args.scene)
        .ok_or_else(|| UsageError(format!("unknown scene '{}'", args.scene)))?;
    let reference = match &args.reference {
        Some(path) => {
            let image = read_image(path)
                .with_context(|| format!("{}: cannot read the reference", path.display()))?;
            // The file's name labels the reference (its folder is noise on a
            // sheet, and a temporary path is meaningless there).
            let name = path.file_name().map_or_else(
                || path.display().to_string(),
                |n| n.to_string_lossy().into_owned(),
            );
            Some((image, name))
        }
        None => None,
    };

    let loaded = args.light.load()?;
    let settings = RenderSettings {
        width,
        height,
        spp: args.spp,
        max_depth: args.max_depth,
        strategy: args.strategy,
        seed: args.seed,
        product: envlight::ProductOptions {
            patches: args.product_patches,
            variant: if args.product_on_the_fly {
                envlight::product::ProductVariant::OnTheFly
            } else {
                envlight::product::ProductVariant::Tables
            },
            ..Default::default()
        },
        visibility: {
            let d = envlight::VisibilityOptions::default();
            envlight::VisibilityOptions {
                learned_share: args.visibility_share.unwrap_or(d.learned_share),
                rays_per_patch: args.visibility_rays.unwrap_or(d.rays_per_patch),
                refine_rays: args.visibility_refine.unwrap_or(d.refine_rays),
                target_entries: args.visibility_entries.unwrap_or(d.target_entries),
                prior: args.visibility_prior.unwrap_or(d.prior),
                ..d
            }
        },
    };
    settings
        .visibility
        .validate()
        .map_err(|e| UsageError(format!("--visibility-*: {e}")))?;
    let bars = Bars::new();

    if args.compare {
        let compare_settings = CompareSettings {
            render: settings,
            strategies: Strategy::ALL.to_vec(),
            equal_time: args.equal_time,
            equal_time_of_mis: true,
            reference_spp: args.reference_spp,
        };
        let comparison = compare(&scene, &loaded.light, &compare_settings, reference, &bars)?;
        bars.finish();
        // The comparison's renders keep nothing: the cache is learned again, the
        // same as theirs (a function of the scene, light, size and options).
        let saved = match &args.save_visibility {
            Some(path) => {
                let settings = RenderSettings {
                    strategy: Strategy::MisVisibility,
                    ..settings
                };
                let cache = envlight_render::learn_visibility(&scene, &loaded.light, &settings);
                Some(save_visibility(cache.as_ref(), path, &args.scene)?)
            }
            None => None,
        };
        let exposure = args
            .exposure
            .unwrap_or_else(|| auto_exposure(&comparison.reference));
        let png = comparison.sheet_png(exposure)?;
        let mut out = Output::create(Some(&args.output))?;
        write_bytes(&mut out, &png)?;
        out.finish()?;
        let mut stdout = Output::create(None)?;
        write!(stdout, "{}", comparison.table()).context("<stdout>: write failed")?;
        writeln!(stdout, "wrote {}", args.output.display()).context("<stdout>: write failed")?;
        if let Some(line) = saved {
            writeln!(stdout, "{line}").context("<stdout>: write failed")?;
        }
        stdout.finish()?;
    } else {
        let (rendered, cache) = render_with_visibility(&scene, &loaded.light, &settings, &bars);
        bars.finish();
        let saved = match &args.save_visibility {
            Some(path) => Some(save_visibility(cache.as_ref(), path, &args.scene)?),
            None => None,
        };
        let exposure = args
            .exposure
            .unwrap_or_else(|| auto_exposure(&rendered.image));
        let bytes = encode_image(&rendered.image, format, exposure)?;
        let mut out = Output::create(Some(&args.output))?;
        write_bytes(&mut out, &bytes)?;
        out.finish()?;
        let _ = writeln!(
            std::io::stderr().lock(),
            "wrote {} ({}x{}, {} spp, {}, {:.2} s)",
            args.output.display(),
            width,
            height,
            rendered.spp,
            args.strategy,
            rendered.seconds
        );
        if let Some(line) = saved {
            let _ = writeln!(std::io::stderr().lock(), "{line}");
        }
    }
    Ok(())
}

/// The scene key a render saves its visibility cache with: the built-in scene's
/// name (`room`). Nothing else of a render changes the geometry the cache learned
/// (the image size only picks the points it learned at; the light is the file's
/// other key).
pub fn scene_key(scene: &str) -> String {
    scene.to_string()
}

/// Saves `cache` (the one a mis-visibility render built) to `path` under the key
/// of `scene`, and says so in a line for the user.
fn save_visibility(
    cache: Option<&envlight::VisibilityCache>,
    path: &std::path::Path,
    scene: &str,
) -> anyhow::Result<String> {
    let cache = cache
        .with_context(|| format!("{}: no visibility cache was built to save", path.display()))?;
    let key = scene_key(scene);
    cache
        .save(path, &key)
        .context("cannot save the visibility cache")?;
    let summary = cache.summary();
    Ok(format!(
        "wrote {} (visibility cache: {} entries, scene key {key:?})",
        path.display(),
        summary.entries
    ))
}

/// `PWxPH` as two positive counts.
pub(crate) fn parse_patches(text: &str) -> Result<[usize; 2], String> {
    let parse = |t: &str| t.trim().parse::<usize>().ok().filter(|&n| n > 0);
    match text.split_once(['x', 'X']) {
        Some((a, b)) => match (parse(a), parse(b)) {
            (Some(a), Some(b)) => Ok([a, b]),
            _ => Err(format!("expected PWxPH with positive counts, got {text:?}")),
        },
        None => Err(format!("expected PWxPH, got {text:?}")),
    }
}
