//! The map and light options shared by every subcommand that builds a light
//! (used with `#[command(flatten)]`), and building the light from them.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, Context};
use clap::ValueEnum;
use envlight::load::{LoadOptions, DEFAULT_MAX_TEXELS};
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation, Sanitized};

use crate::progress::Progress;

/// The prefix that names a procedural map instead of a file.
pub const BUILTIN_PREFIX: &str = "builtin:";

/// `MAP` and the options that say how the light is built from it.
#[derive(Debug, Clone, clap::Args)]
pub struct LightArgs {
    /// Environment map: a .hdr, .exr or .pfm file (8-bit .png/.jpg are accepted and
    /// decoded from sRGB), or builtin:sky.
    #[arg(value_name = "MAP", default_value = "builtin:sky")]
    pub map: PathBuf,

    /// Rotate the map about +z by DEG degrees (+x turns towards +y).
    #[arg(long, value_name = "DEG", default_value_t = 0.0, allow_hyphen_values = true,
          value_parser = parse_finite)]
    pub rotate: f32,

    /// Multiply every radiance value by S (the sampling density does not change).
    #[arg(long, value_name = "S", default_value_t = 1.0, value_parser = parse_scale)]
    pub scale: f32,

    /// Radiance reconstruction between texel centres.
    #[arg(long, value_enum, default_value_t = LookupArg::Bilinear)]
    pub lookup: LookupArg,

    /// How directions are drawn from the density.
    #[arg(long, value_name = "NAME", value_enum, default_value_t = SamplerArg::Inversion)]
    pub sampler: SamplerArg,

    /// The shape of the sampling density over the map.
    #[arg(long, value_name = "NAME", value_enum, default_value_t = DensityArg::PiecewiseConstant)]
    pub density: DensityArg,

    /// How image points map to directions.
    #[arg(long, value_name = "NAME", value_enum, default_value_t = MappingArg::Equirectangular)]
    pub mapping: MappingArg,

    /// Refuse maps with more texels than N (guards against absurd headers).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_TEXELS)]
    pub max_texels: usize,

    /// Replace NaN and infinite texels by 0 (with a warning that counts them)
    /// instead of refusing the map.
    #[arg(long)]
    pub sanitize: bool,
}

/// `--lookup`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum LookupArg {
    /// The texel containing the direction.
    Nearest,
    /// Bilinear interpolation (u wraps, v clamps); the importance is blurred by
    /// [1 6 1]/8 so every lit direction can be sampled.
    Bilinear,
}

/// `--sampler`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SamplerArg {
    /// CDF inversion: a row from the marginal, then a column from that row.
    Inversion,
}

/// `--density`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DensityArg {
    /// Constant over each texel (in image space), ∝ luminance · sin θ.
    PiecewiseConstant,
}

/// `--mapping`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum MappingArg {
    /// Latitude-longitude: θ = π v, φ = 2π u.
    Equirectangular,
}

/// The name clap shows for a value-enum choice (also what reports print).
pub fn choice_name<T: ValueEnum>(value: &T) -> String {
    value
        .to_possible_value()
        .map(|v| v.get_name().to_string())
        .unwrap_or_default()
}

fn parse_finite(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(v),
        Ok(_) => Err("must be a finite number".to_string()),
        Err(e) => Err(e.to_string()),
    }
}

fn parse_scale(s: &str) -> Result<f32, String> {
    let v = parse_finite(s)?;
    if v >= 0.0 {
        Ok(v)
    } else {
        Err("must be >= 0".to_string())
    }
}

/// A built light and what was learnt while building it.
pub struct Loaded {
    /// The light.
    pub light: EnvironmentLight,
    /// The map as the user named it (a path or `builtin:NAME`), for messages.
    pub name: String,
    /// `builtin`, or the decoded file format (`hdr`, `exr`, `pfm`, `png`, `jpeg`).
    pub format: String,
    /// Wall time to read and decode the map, in milliseconds.
    pub load_ms: f64,
    /// Wall time to build the light (sampling distribution, integrals), in ms.
    pub build_ms: f64,
    /// Negative and non-finite texels that were replaced.
    pub sanitized: Sanitized,
    /// True when the map has no light at all (every pdf is 0).
    pub black: bool,
}

impl LightArgs {
    /// The library's light options for these arguments.
    pub fn light_options(&self) -> LightOptions {
        LightOptions {
            scale: self.scale,
            rotation: if self.rotate == 0.0 {
                Rotation::IDENTITY
            } else {
                Rotation::about_z_degrees(self.rotate)
            },
            lookup: match self.lookup {
                LookupArg::Nearest => Lookup::Nearest,
                LookupArg::Bilinear => Lookup::Bilinear,
            },
        }
    }

    /// The builtin map's name when `MAP` is `builtin:NAME`.
    fn builtin_name(&self) -> Option<&str> {
        self.map.to_str()?.strip_prefix(BUILTIN_PREFIX)
    }

    /// Loads the map, builds the light and prints warnings (negative texels clamped,
    /// non-finite texels replaced, loader notes, an all-black map) to stderr.
    ///
    /// # Errors
    /// An unknown builtin name, or the loader's error (which names the file and,
    /// where it applies, the texel).
    pub fn load(&self) -> anyhow::Result<Loaded> {
        let name = self.map.display().to_string();
        let spinner = Progress::spinner(&format!("loading {name}"));
        let started = Instant::now();
        let (image, format, sanitized, notes) = match self.builtin_name() {
            Some(builtin) => {
                let image = envlight::builtin::by_name(builtin).ok_or_else(|| {
                    let known: Vec<String> = envlight::builtin::NAMES
                        .iter()
                        .map(|n| format!("{BUILTIN_PREFIX}{n}"))
                        .collect();
                    anyhow!("{name}: no such builtin map (known: {})", known.join(", "))
                })?;
                (
                    image,
                    "builtin".to_string(),
                    Sanitized::default(),
                    Vec::new(),
                )
            }
            None => load_file(&self.map, self.max_texels, self.sanitize)?,
        };
        let load_ms = started.elapsed().as_secs_f64() * 1e3;
        spinner.finish();
        drop(spinner);

        for note in &notes {
            warn(&format!("{name}: {note}"));
        }
        let (w, h) = (image.width(), image.height());
        if w != 2 * h {
            warn(&format!(
                "{name}: the map is {w}x{h}, not 2:1; it is read as equirectangular all the \
                 same (φ across the width, θ down the height)"
            ));
        }
        if sanitized.negative_texels > 0 {
            warn(&format!(
                "{name}: clamped {} texels with negative values to 0 (most negative {})",
                sanitized.negative_texels, sanitized.most_negative
            ));
        }
        if sanitized.non_finite_texels > 0 {
            warn(&format!(
                "{name}: replaced {} texels holding NaN or infinity by 0 (--sanitize)",
                sanitized.non_finite_texels
            ));
        }

        let spinner = Progress::spinner(&format!("building light from {name}"));
        let started = Instant::now();
        let light = EnvironmentLight::new(image, self.light_options())
            .with_context(|| format!("{name}: cannot build the light"))?;
        let build_ms = started.elapsed().as_secs_f64() * 1e3;
        spinner.finish();

        let integral = light.distribution().integral();
        let black = integral.is_nan() || integral <= 0.0;
        if black {
            warn(&format!(
                "{name}: the map is all black: it emits no light, so every pdf is 0 and \
                 no direction can be sampled"
            ));
        }
        Ok(Loaded {
            light,
            name,
            format,
            load_ms,
            build_ms,
            sanitized,
            black,
        })
    }
}

/// Decodes a map file with the library's loader.
fn load_file(
    path: &Path,
    max_texels: usize,
    replace_non_finite: bool,
) -> anyhow::Result<(EnvImage, String, Sanitized, Vec<String>)> {
    let options = LoadOptions {
        max_texels,
        replace_non_finite,
    };
    let loaded = envlight::load::load(path, &options)?;
    Ok((
        loaded.image,
        loaded.format.to_string(),
        loaded.sanitized,
        loaded.notes,
    ))
}

/// Prints `warning: MESSAGE` on stderr (one line).
pub fn warn(message: &str) {
    use std::io::Write;
    let message = message.replace(['\n', '\r'], " ");
    let _ = writeln!(std::io::stderr().lock(), "warning: {message}");
}
