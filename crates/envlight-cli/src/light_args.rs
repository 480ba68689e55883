//! The map and light options shared by every subcommand that builds a light
//! (used with `#[command(flatten)]`), and building the light from them.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{anyhow, Context};
use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
use envlight::light::{Density, Mapping, NamedOption, OptionError, Sampler};
use envlight::load::{LoadOptions, DEFAULT_MAX_TEXELS};
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation, Sanitized};

use crate::cmd::UsageError;
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
    #[arg(long, default_value_t = Lookup::Bilinear, value_parser = choices(lookup_help))]
    pub lookup: Lookup,

    /// How directions are drawn from the density (all give the same density).
    #[arg(long, value_name = "NAME", default_value_t = Sampler::Inversion,
          value_parser = choices(sampler_help))]
    pub sampler: Sampler,

    /// The shape of the sampling density over the map [default: piecewise-bilinear
    /// with --sampler inversion and no --table-size, else piecewise-constant].
    /// piecewise-bilinear follows the bilinear lookup (efficiency 1.000 on every
    /// shared map) for about 14 bytes per texel and a batch sample and pdf about
    /// 1.4-1.6x the constant one's; piecewise-constant is the smallest (6 bytes per
    /// texel) and cheapest, and the only one the alias and hierarchical samplers
    /// and --table-size take.
    #[arg(long, value_name = "NAME", value_parser = choices(density_help))]
    pub density: Option<Density>,

    /// The parameterization the light samples and looks up in [default: the same as
    /// --input-mapping]. A lat-long map lit with equal-area is resampled to an
    /// equal-area square (--equal-area-size); an equal-area map can only be lit
    /// with equal-area.
    #[arg(long, value_name = "NAME", value_parser = choices(mapping_help))]
    pub mapping: Option<Mapping>,

    /// What MAP is: a lat-long panorama, or an equal-area octahedral square (as
    /// PBRT-v4 writes them; must be square).
    #[arg(long, value_name = "NAME", default_value_t = Mapping::Equirectangular,
          value_parser = choices(mapping_help))]
    pub input_mapping: Mapping,

    /// Side N of the N×N equal-area square a lat-long map is resampled to for
    /// --mapping equal-area [default: about the map's texel count, √(w h) rounded
    /// to even].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u64).range(1..))]
    pub equal_area_size: Option<u64>,

    /// Build the sampling table W cells wide instead of one cell per texel: each
    /// cell sums the filtered importance of a block of texels (conservative: every
    /// lit texel keeps a positive density), radiance is still looked up at full
    /// resolution. W must reduce the light's width and height by the same whole
    /// factor. Piecewise-constant density only; `info` reports the efficiency it
    /// costs.
    #[arg(long, value_name = "W", value_parser = clap::value_parser!(u64).range(1..))]
    pub table_size: Option<u64>,

    /// Refuse maps with more texels than N (guards against absurd headers).
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_TEXELS)]
    pub max_texels: usize,

    /// Replace NaN and infinite texels by 0 (with a warning that counts them)
    /// instead of refusing the map.
    #[arg(long)]
    pub sanitize: bool,
}

/// The value parser of an option the library names ([`NamedOption`]): its names,
/// in the library's order, are the possible values, each shown with `help`'s
/// text in `--help`; the chosen name is parsed back with the library's parser.
pub fn choices<T>(help: fn(T) -> &'static str) -> impl TypedValueParser<Value = T>
where
    T: NamedOption + Send + Sync,
{
    PossibleValuesParser::new(
        T::VALUES
            .iter()
            .map(|&v| PossibleValue::new(v.option_name()).help(help(v))),
    )
    .try_map(|name| T::from_name(&name))
}

/// `--lookup`'s values, as `--help` explains them.
fn lookup_help(lookup: Lookup) -> &'static str {
    match lookup {
        Lookup::Nearest => "The texel containing the direction",
        Lookup::Bilinear => {
            "Bilinear interpolation (lat-long: u wraps, v clamps; equal-area: both clamp); \
             the importance is blurred by [1 6 1]/8 so every lit direction can be sampled"
        }
        Lookup::Node => {
            "Bilinear with the rows as nodes from pole to pole (row j at v = j/(h-1)), as \
             Mitsuba 3's envmap reads a map; lat-long maps (the piecewise-bilinear density \
             puts its nodes on those rows)"
        }
    }
}

/// `--sampler`'s values, as `--help` explains them.
fn sampler_help(sampler: Sampler) -> &'static str {
    match sampler {
        Sampler::Inversion => {
            "CDF inversion: a row from the marginal, then a column from that row. Keeps \
             stratification; invertible"
        }
        Sampler::Alias => {
            "Vose's alias table: O(1) per sample, but breaks stratification and has no inverse"
        }
        Sampler::Hierarchical => {
            "Hierarchical warping down a pyramid of sums: keeps stratification; invertible"
        }
    }
}

/// `--density`'s values, as `--help` explains them.
fn density_help(density: Density) -> &'static str {
    match density {
        Density::PiecewiseConstant => {
            "Constant over each texel (in image space), ∝ filtered luminance × the mapping's \
             area factor"
        }
        Density::PiecewiseBilinear => {
            "Bilinear between texel centres, ∝ the bilinear radiance reconstruction's \
             luminance × the area factor (sampled by inversion only)"
        }
    }
}

/// `--mapping`'s and `--input-mapping`'s values, as `--help` explains them.
fn mapping_help(mapping: Mapping) -> &'static str {
    match mapping {
        Mapping::Equirectangular => "Latitude-longitude: θ = π v, φ = 2π u",
        Mapping::EqualArea => {
            "The equal-area octahedral square (PBRT-v4's): constant Jacobian 4π, no pole \
             singularity"
        }
    }
}

/// The command-line option that sets the [`LightOptions`] field `field`.
fn flag(field: &str) -> String {
    match field {
        "rotation" => "--rotate".into(),
        "table_width" => "--table-size".into(),
        _ => format!("--{}", field.replace('_', "-")),
    }
}

/// The library's refusal of `options` ([`LightOptions::validate`]) as the command
/// line says it: the flags with their values. A flag's own parser refuses a bad
/// scale, rotation, table or square size before this, so those only get the
/// library's words after the flag.
fn usage_message(e: &OptionError, options: &LightOptions) -> String {
    match e {
        OptionError::BilinearDensitySampler(sampler) => format!(
            "--density {} with --sampler {sampler} is not supported: the piecewise-bilinear \
             density is sampled by inversion only (use --sampler {})",
            options.density,
            Sampler::Inversion,
        ),
        OptionError::EqualAreaInput => format!(
            "--input-mapping {} with --mapping {} is not supported: an equal-area map \
             can only be lit with --mapping {}",
            options.input_mapping,
            options.mapping,
            Mapping::EqualArea,
        ),
        OptionError::NodeLookupMapping => format!(
            "--lookup {} with --mapping {} is not supported: the node lookup reads lat-long \
             maps only (use --lookup {} or --mapping {})",
            options.lookup,
            options.mapping,
            Lookup::Bilinear,
            Mapping::Equirectangular,
        ),
        e => format!("{}: {e}", flag(e.field())),
    }
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

/// A decoded map, before the light is built from it.
pub struct Input {
    /// The map's texels, in the input mapping.
    pub image: EnvImage,
    /// The map as the user named it (a path or `builtin:NAME`), for messages.
    pub name: String,
    /// `builtin`, or the decoded file format (`hdr`, `exr`, `pfm`, `png`, `jpeg`).
    pub format: String,
    /// Wall time to read and decode the map, in milliseconds.
    pub load_ms: f64,
    /// Negative and non-finite texels that were replaced.
    pub sanitized: Sanitized,
}

/// A built light and what was learnt while building it.
pub struct Loaded {
    /// The light.
    pub light: Arc<EnvironmentLight>,
    /// The map as the user named it (a path or `builtin:NAME`), for messages.
    pub name: String,
    /// `builtin`, or the decoded file format (`hdr`, `exr`, `pfm`, `png`, `jpeg`).
    pub format: String,
    /// Size of the map as read (the light's own image differs for an equal-area
    /// light built from a lat-long map).
    pub input_width: usize,
    pub input_height: usize,
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
    /// The mapping the light uses: `--mapping`, or by default the input's.
    pub fn mapping(&self) -> Mapping {
        self.mapping.unwrap_or(self.input_mapping)
    }

    /// `--density`, or when not given the library's default for the sampler and
    /// table ([`Density::default_for`]).
    pub fn density(&self) -> Density {
        self.density.unwrap_or_else(|| {
            let table = self
                .table_size
                .map(|n| usize::try_from(n).unwrap_or(usize::MAX));
            Density::default_for(self.sampler, table)
        })
    }

    /// The library's light options for these arguments (MIS compensation off: it
    /// is a rendering strategy, not a light option of the CLI).
    pub fn light_options(&self) -> LightOptions {
        LightOptions {
            scale: self.scale,
            rotation: if self.rotate == 0.0 {
                Rotation::IDENTITY
            } else {
                Rotation::about_z_degrees(self.rotate)
            },
            lookup: self.lookup,
            sampler: self.sampler,
            density: self.density(),
            mapping: self.mapping(),
            input_mapping: self.input_mapping,
            equal_area_size: self
                .equal_area_size
                .map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
            table_width: self
                .table_size
                .map(|n| usize::try_from(n).unwrap_or(usize::MAX)),
            ..Default::default()
        }
    }

    /// Refuses option combinations the library does not support, before any work,
    /// as a usage error (exit status 2) naming the options; warns about options
    /// that have no effect.
    ///
    /// # Errors
    /// [`UsageError`] for options [`LightOptions::validate`] refuses (the
    /// piecewise-bilinear density with a sampler other than inversion, the node
    /// lookup with the equal-area mapping, an equal-area input lit with the
    /// equirectangular mapping), and an `--equal-area-size` whose square exceeds
    /// `--max-texels`. A `--table-size` that does not fit the map is refused once
    /// the map is read ([`Self::build`]).
    pub fn check(&self) -> Result<(), UsageError> {
        let options = self.light_options();
        options
            .validate()
            .map_err(|e| UsageError(usage_message(&e, &options)))?;
        let mapping = options.mapping;
        if let Some(n) = self.equal_area_size {
            let resampled =
                self.input_mapping == Mapping::Equirectangular && mapping == Mapping::EqualArea;
            if !resampled {
                warn(&format!(
                    "--equal-area-size {n} has no effect: only a lat-long map lit with \
                     --mapping equal-area is resampled (here --input-mapping {}, --mapping {})",
                    self.input_mapping, mapping
                ));
            } else if n.checked_mul(n).is_none_or(|t| t > self.max_texels as u64) {
                return Err(UsageError(format!(
                    "--equal-area-size {n} gives more than --max-texels {} texels",
                    self.max_texels
                )));
            }
        }
        Ok(())
    }

    /// The builtin map's name when `MAP` is `builtin:NAME`.
    fn builtin_name(&self) -> Option<&str> {
        self.map.to_str()?.strip_prefix(BUILTIN_PREFIX)
    }

    /// [`Self::read`] then [`Self::build`].
    ///
    /// # Errors
    /// As [`Self::read`] and [`Self::build`].
    pub fn load(&self) -> anyhow::Result<Loaded> {
        let input = self.read()?;
        self.build(input)
    }

    /// Checks the options ([`Self::check`]), then loads the map and prints
    /// warnings about it (negative texels clamped, non-finite texels replaced,
    /// loader notes, an odd shape) to stderr.
    ///
    /// # Errors
    /// A usage error from [`Self::check`], an unknown builtin name, or the loader's
    /// error (which names the file and, where it applies, the texel).
    pub fn read(&self) -> anyhow::Result<Input> {
        self.check()?;
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
        match self.input_mapping {
            Mapping::Equirectangular if w != 2 * h => warn(&format!(
                "{name}: the map is {w}x{h}, not 2:1; it is read as equirectangular all the \
                 same (φ across the width, θ down the height)"
            )),
            // A non-square equal-area map is refused by the light (below).
            _ => {}
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
        Ok(Input {
            image,
            name,
            format,
            load_ms,
            sanitized,
        })
    }

    /// Builds the light from a map read by [`Self::read`]; warns when it is all
    /// black.
    ///
    /// # Errors
    /// The library's refusal of the options for this map (an equal-area map that
    /// is not square), naming the map: exit status 1 (bad input).
    pub fn build(&self, input: Input) -> anyhow::Result<Loaded> {
        let Input {
            image,
            name,
            format,
            load_ms,
            sanitized,
        } = input;
        let (input_width, input_height) = (image.width(), image.height());
        let options = self.light_options();
        // The build reports rows of the light's image: the resampled square for an
        // equal-area light from a lat-long map.
        let (columns, rows) = match (options.input_mapping, options.mapping) {
            (Mapping::Equirectangular, Mapping::EqualArea) => {
                let side = options.equal_area_size.unwrap_or_else(|| {
                    envlight::equal_area::default_size(input_width, input_height)
                });
                (side, side)
            }
            _ => (input_width, input_height),
        };
        // A table width that does not fit this map is the option's fault: a usage
        // error, found before the build.
        envlight::light::table_reduction(columns, rows, &options)
            .map_err(|e| UsageError(format!("--table-size: {name}: {e}")))?;
        let bar = Progress::bar(rows as u64, "building");
        let started = Instant::now();
        let light = EnvironmentLight::with_progress(image, options, &|k| bar.inc(k as u64))
            .with_context(|| format!("{name}: cannot build the light"))?;
        let build_ms = started.elapsed().as_secs_f64() * 1e3;
        bar.finish();

        let black = light.is_black();
        if black {
            warn(&format!(
                "{name}: the map is all black: it emits no light, so every pdf is 0 and \
                 no direction can be sampled"
            ));
        }
        Ok(Loaded {
            light: Arc::new(light),
            name,
            format,
            input_width,
            input_height,
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

/// `--portal QUAD` (repeatable) and `--at X,Y,Z`: sample the map only through
/// windows, from one point (docs/design.md §6d).
#[derive(Debug, Clone, clap::Args)]
pub struct PortalArgs {
    /// A portal (a window the map is seen through): the four corners of a planar
    /// convex quad in order around it (either winding), "x,y,z;x,y,z;x,y,z;x,y,z" in
    /// world space. Repeatable (up to 8). Needs --at. Directions then come only
    /// through the portals, and pdf is the portal light's density at --at (0 for a
    /// direction through no portal).
    #[arg(long, value_name = "X,Y,Z;X,Y,Z;X,Y,Z;X,Y,Z", value_parser = parse_portal,
          allow_hyphen_values = true)]
    pub portal: Vec<envlight::portal::Portal>,

    /// The point the portals are seen from (needs --portal).
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_point, allow_hyphen_values = true)]
    pub at: Option<envlight::Vec3>,
}

impl PortalArgs {
    /// The portals and the point, when asked for; a usage error when only one of
    /// `--portal` and `--at` is given, or `--portal` with `--normal` (`normal`) or
    /// `--device gpu` (`gpu`). Called before the map is read, so these fail fast.
    pub fn requested(
        &self,
        normal: bool,
        gpu: bool,
    ) -> anyhow::Result<Option<(&[envlight::portal::Portal], envlight::Vec3)>> {
        if gpu && !self.portal.is_empty() {
            return Err(UsageError(
                "--portal (portal sampling) is not ported to the GPU; use --device cpu".into(),
            )
            .into());
        }
        match (self.portal.is_empty(), self.at) {
            (true, None) => Ok(None),
            (false, None) => Err(UsageError(
                "--portal needs --at X,Y,Z: portals are sampled from one point, the one the \
                 windows are seen from"
                    .into(),
            )
            .into()),
            (true, Some(_)) => Err(UsageError(
                "--at needs at least one --portal: it names the point the portals are seen from"
                    .into(),
            )
            .into()),
            (false, Some(_)) if normal => Err(UsageError(
                "--portal and --normal cannot be combined: choose portal sampling or product \
                 sampling"
                    .into(),
            )
            .into()),
            (false, Some(at)) => {
                if self.portal.len() > envlight::portal::MAX_PORTALS {
                    return Err(UsageError(format!(
                        "at most {} --portal options, got {}",
                        envlight::portal::MAX_PORTALS,
                        self.portal.len()
                    ))
                    .into());
                }
                Ok(Some((&self.portal, at)))
            }
        }
    }

    /// The portal light over `light` and the point, when asked for (see
    /// [`Self::requested`]).
    pub fn build(
        &self,
        light: &Arc<EnvironmentLight>,
        normal: bool,
        gpu: bool,
    ) -> anyhow::Result<Option<(envlight::portal::PortalLight, envlight::Vec3)>> {
        let Some((portals, at)) = self.requested(normal, gpu)? else {
            return Ok(None);
        };
        let pl = envlight::portal::PortalLight::new(
            Arc::clone(light),
            portals,
            envlight::portal::PortalOptions::default(),
        )
        .map_err(|e| UsageError(format!("--portal: {e}")))?;
        Ok(Some((pl, at)))
    }
}

/// Three finite comma-separated numbers (`--at`, `--portal` corners, `--normal`).
pub(crate) fn parse_xyz(text: &str) -> Result<envlight::Vec3, String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let [x, y, z] = parts[..] else {
        return Err(format!(
            "expected three comma-separated numbers X,Y,Z, got {} part(s) in '{text}'",
            parts.len()
        ));
    };
    let number = |s: &str| -> Result<f32, String> {
        match s.parse::<f32>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => Err(format!("'{s}' is not finite")),
            Err(_) => Err(format!("'{s}' is not a number")),
        }
    };
    Ok(envlight::Vec3::new(number(x)?, number(y)?, number(z)?))
}

/// `--at X,Y,Z`.
pub fn parse_point(text: &str) -> Result<envlight::Vec3, String> {
    parse_xyz(text)
}

/// `--portal "x,y,z;x,y,z;x,y,z;x,y,z"`: four corners of a planar convex quad.
pub fn parse_portal(text: &str) -> Result<envlight::portal::Portal, String> {
    let corners: Vec<&str> = text.split(';').map(str::trim).collect();
    let [a, b, c, d] = corners[..] else {
        return Err(format!(
            "expected four corners separated by ';' (x,y,z;x,y,z;x,y,z;x,y,z), got {}",
            corners.len()
        ));
    };
    let mut points = [envlight::Vec3::default(); 4];
    for (k, (p, t)) in points.iter_mut().zip([a, b, c, d]).enumerate() {
        *p = parse_xyz(t).map_err(|e| format!("corner {}: {e}", k + 1))?;
    }
    envlight::portal::Portal::new(points).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The command-line choices are exactly the library's values, under the
    /// library's names and in its order (which reports print), each explained.
    #[test]
    fn choices_are_the_library_values_and_names() {
        fn names<T: NamedOption + Send + Sync>(help: fn(T) -> &'static str) {
            let parser = choices(help);
            let shown: Vec<String> = parser
                .possible_values()
                .expect("choices lists its values")
                .map(|v| {
                    assert!(v.get_help().is_some_and(|h| !h.to_string().is_empty()));
                    v.get_name().to_owned()
                })
                .collect();
            assert_eq!(shown, T::names());
        }
        names(sampler_help);
        names(density_help);
        names(mapping_help);
        names(lookup_help);
    }

    /// Each combination the library refuses is said with the flags and values.
    #[test]
    fn refusals_name_the_flags() {
        let options = LightOptions {
            lookup: Lookup::Node,
            mapping: Mapping::EqualArea,
            ..Default::default()
        };
        let m = usage_message(&options.validate().unwrap_err(), &options);
        assert!(
            m.starts_with("--lookup node with --mapping equal-area is not supported"),
            "{m}"
        );
        let options = LightOptions {
            sampler: Sampler::Alias,
            ..Default::default()
        };
        let m = usage_message(&options.validate().unwrap_err(), &options);
        assert_eq!(
            m,
            "--density piecewise-bilinear with --sampler alias is not supported: the \
             piecewise-bilinear density is sampled by inversion only (use --sampler inversion)"
        );
        assert_eq!(flag("table_width"), "--table-size");
        assert_eq!(flag("equal_area_size"), "--equal-area-size");
    }

    #[test]
    fn portals_parse_and_explain_what_is_wrong() {
        let p = parse_portal("0,0,2; 1,0,2; 1,1,2; 0,1,2").unwrap();
        assert!(p.is_parallelogram());
        assert!(parse_portal("0,0,2;1,0,2;1,1,2;0,1,2.5")
            .unwrap_err()
            .contains("not planar"));
        assert!(parse_portal("0,0,0;1,0,0;2,0,0;3,0,0")
            .unwrap_err()
            .contains("degenerate"));
        assert!(parse_portal("0,0,0;1,0,0;1,1,0")
            .unwrap_err()
            .contains("four corners"));
        assert!(parse_portal("0,0,0;1,0,0;1,x,0;0,1,0")
            .unwrap_err()
            .contains("corner 3"));
        assert!(parse_point("1,2").is_err());
        assert_eq!(
            parse_point("1,-2,3").unwrap(),
            envlight::Vec3::new(1.0, -2.0, 3.0)
        );
    }
}
