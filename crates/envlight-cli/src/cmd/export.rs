//! `envlight export`: the light's flat GPU tables (`docs/gpu-tables.md`) as one
//! binary file.

use std::path::PathBuf;

use envlight::gpu::{GpuTableOptions, RadianceFormat};
use envlight::light::Sampler;

use super::{Outcome, UsageError};
use crate::light_args::{choices, LightArgs};
use crate::output::{write_bytes, Output};

/// Arguments of `envlight export`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Output: the GPU tables file of docs/gpu-tables.md (layout version 1): a header \
(magic ENVLGPU\\0, version, section count), a section table, then little-endian sections \
on 16-byte boundaries: the parameter block (rotation, sampler, density, mapping, lookup, \
sizes, scale), the sampler's tables exactly as the CPU samples them, and the radiance \
image (unscaled; --scale is a parameter). A shader binds three buffers: the parameter \
block, the tables (sections 2-8, contiguous) and the radiance. The inversion and alias \
samplers are exported, with either density, mapping and lookup; the hierarchical sampler \
is not ported to the GPU. --radiance f16 halves the image (RGBA half floats, rounded to \
nearest even) and is refused for a map brighter than 65504. The file is written \
atomically: on failure nothing is written and an existing FILE is left as it was.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    /// The file to write (binary; `-` for stdout).
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    output: PathBuf,

    /// How the radiance image is stored.
    #[arg(long, value_name = "FORMAT", default_value_t = RadianceFormat::F32,
          value_parser = choices(radiance_help))]
    radiance: RadianceFormat,
}

/// `--radiance`'s values, as `--help` explains them.
fn radiance_help(format: RadianceFormat) -> &'static str {
    match format {
        RadianceFormat::F32 => "RGB 32-bit floats, 12 bytes per texel: the map's values exactly",
        RadianceFormat::F16 => {
            "RGBA 16-bit floats (alpha 0), 8 bytes per texel; values above 65504 refused"
        }
    }
}

/// Runs `envlight export`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    // Refused before the map is read: it is the option, not the map, that is wrong.
    if args.light.sampler == Sampler::Hierarchical {
        return Err(UsageError(format!(
            "--sampler {} is not supported by export: the hierarchical sampler is not \
             ported to the GPU; use --sampler {} or {}",
            Sampler::Hierarchical,
            Sampler::Inversion,
            Sampler::Alias,
        ))
        .into());
    }
    let loaded = args.light.load()?;
    let options = GpuTableOptions {
        radiance: args.radiance,
    };
    let tables = loaded.light.gpu_tables(&options).map_err(|e| match e {
        envlight::Error::Unsupported(_) => anyhow::Error::new(UsageError(e.to_string())),
        e => anyhow::Error::new(e).context(format!("{}: cannot export", loaded.name)),
    })?;
    let mut out = Output::create(Some(&args.output))?;
    write_bytes(&mut out, &tables.to_bytes())?;
    out.finish()?;
    Ok(Outcome::Success)
}
