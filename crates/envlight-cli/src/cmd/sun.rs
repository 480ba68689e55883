//! `envlight sun`: the map's compact bright source (sun) as a uniform disc, and
//! optionally the residual map with the source in-painted (`envlight::sun`).

use std::io::Cursor;
use std::path::{Path, PathBuf};

use anyhow::Context;
use envlight::{EnvImage, Sun, SunOptions};
use serde_json::json;

use super::{Outcome, UsageError};
use crate::light_args::LightArgs;
use crate::output::{write_bytes, Output};

/// Arguments of `envlight sun`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Finds the brightest compact source of the map and reports it as a uniform disc: \
unit direction (world frame, z up, --rotate applied; also as elevation above the xy \
plane and azimuth from +x towards +y), angular radius, solid angle, radiance (RGB, \
--scale applied), irradiance at normal incidence E⊥ = L π sin² r (RGB: what a surface \
facing the sun receives from it, the intensity of an engine's directional light) and \
its share of the map's ∫Y dω. A source is compact when its disc's radius is at most 5°, \
its mean luminance at least 20 times the median of the sky around it, and it carries \
at least 1% of the map's power; otherwise there is no sun (an answer, not an error: \
exit status 0).\n\n\
With --json: {\"sun\": {\"direction\": [x, y, z], \"angular_radius_deg\": r, \
\"solid_angle_sr\": Ω, \"radiance\": [r, g, b], \"irradiance\": [r, g, b], \
\"power_fraction\": f}} or {\"sun\": null}.\n\n\
--residual OUT writes the map without the source: same size and mapping as the light's \
image, the source's texels in-painted smoothly from the ring around it, in the map's \
own units (--scale and --rotate not applied: light it with the same options as the \
map). The residual plus the disc reproduce the map's irradiance at any normal that \
does not graze the source. The format follows the extension (.exr: 32-bit float, \
.pfm, .hdr: RGBE); the file is written atomically.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,

    /// Write the residual map (the sky without the source) to OUT: .exr, .pfm or .hdr.
    #[arg(long, value_name = "OUT")]
    residual: Option<PathBuf>,
}

/// The residual's file formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Format {
    Exr,
    Pfm,
    Hdr,
}

impl Format {
    fn of(path: &Path) -> Result<Self, UsageError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("exr") => Ok(Self::Exr),
            Some("pfm") => Ok(Self::Pfm),
            Some("hdr") => Ok(Self::Hdr),
            _ => Err(UsageError(format!(
                "--residual {}: the extension must be .exr, .pfm or .hdr",
                path.display()
            ))),
        }
    }
}

/// Runs `envlight sun`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    // The option, not the map, is wrong: refused before any work.
    let format = args.residual.as_deref().map(Format::of).transpose()?;
    let loaded = args.light.load()?;
    let extraction = loaded.light.extract_sun(&SunOptions::default());
    if let (Some(path), Some(format)) = (&args.residual, format) {
        let bytes = encode(&extraction.residual, format)
            .with_context(|| format!("{}: cannot encode the residual", path.display()))?;
        let mut out = Output::create(Some(path))?;
        write_bytes(&mut out, &bytes)?;
        out.finish()?;
    }
    let text = match (args.json, &extraction.sun) {
        (true, sun) => {
            let value = json!({ "sun": sun.as_ref().map(sun_json) });
            let mut text = serde_json::to_string_pretty(&value).context("cannot format JSON")?;
            text.push('\n');
            text
        }
        (false, Some(sun)) => sun_text(&loaded.name, sun, extraction.inpainted_texels, args),
        (false, None) => format!(
            "{}: no sun (no source of radius ≤ {}° with contrast ≥ {} and ≥ {}% of the power)\n",
            loaded.name,
            envlight::sun::MAX_ANGULAR_RADIUS_DEG,
            envlight::sun::MIN_CONTRAST,
            100.0 * envlight::sun::MIN_POWER_FRACTION
        ),
    };
    let mut out = Output::create(None)?;
    write_bytes(&mut out, text.as_bytes())?;
    out.finish()?;
    Ok(Outcome::Success)
}

fn sun_json(sun: &Sun) -> serde_json::Value {
    json!({
        "direction": sun.direction.to_array(),
        "angular_radius_deg": sun.angular_radius_deg(),
        "solid_angle_sr": sun.solid_angle,
        "radiance": sun.radiance,
        "irradiance": sun.irradiance,
        "power_fraction": sun.power_fraction,
    })
}

fn sun_text(name: &str, sun: &Sun, inpainted: usize, args: &Args) -> String {
    let d = sun.direction;
    let rgb = |v: [f64; 3]| format!("{:.6e} {:.6e} {:.6e}", v[0], v[1], v[2]);
    let mut lines = vec![
        format!("{name}: sun found"),
        format!(
            "direction        {:.6} {:.6} {:.6} (elevation {:.3}°, azimuth {:.3}°)",
            d.x,
            d.y,
            d.z,
            sun.elevation_deg(),
            sun.azimuth_deg()
        ),
        format!(
            "angular radius   {:.4}° (solid angle {:.4e} sr)",
            sun.angular_radius_deg(),
            sun.solid_angle
        ),
        format!("radiance         {} (RGB, per sr)", rgb(sun.radiance)),
        format!(
            "irradiance       {} (RGB, at normal incidence)",
            rgb(sun.irradiance)
        ),
        format!(
            "power fraction   {:.4} ({:.2}% of the map's ∫Y dω)",
            sun.power_fraction,
            100.0 * sun.power_fraction
        ),
        format!(
            "contrast         {:.4e} (disc over the sky around it)",
            sun.contrast
        ),
    ];
    if let Some(path) = &args.residual {
        lines.push(format!(
            "residual         {} ({inpainted} texels in-painted)",
            path.display()
        ));
    }
    let mut text = lines.join("\n");
    text.push('\n');
    text
}

/// The residual image as the bytes of a `format` file.
fn encode(image: &EnvImage, format: Format) -> anyhow::Result<Vec<u8>> {
    let (w, h) = (image.width(), image.height());
    match format {
        Format::Pfm => Ok(envlight::load::encode_pfm(image)),
        Format::Exr => {
            use exr::prelude::*;
            let channels = SpecificChannels::rgb(|Vec2(x, y)| {
                let t = image.texel(x, y);
                (t[0], t[1], t[2])
            });
            let mut bytes = Cursor::new(Vec::new());
            Image::from_channels((w, h), channels)
                .write()
                .to_buffered(&mut bytes)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok(bytes.into_inner())
        }
        Format::Hdr => {
            let pixels: Vec<image::Rgb<f32>> =
                image.texels().iter().map(|&t| image::Rgb(t)).collect();
            let mut bytes = Vec::new();
            image::codecs::hdr::HdrEncoder::new(&mut bytes)
                .encode(&pixels, w, h)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
            Ok(bytes)
        }
    }
}
