//! `envlight shader`: the GPU compute shader (`envlight-gpu`'s WGSL module) in
//! WGSL, GLSL, HLSL, MSL or SPIR-V, for use outside envlight.

use std::io::IsTerminal;
use std::path::PathBuf;

use clap::builder::PossibleValuesParser;
use envlight_gpu::shader::{translate, Lang, ShaderError, DEFAULT_ENTRY_POINT, ENTRY_POINTS};

use super::{Outcome, UsageError};
use crate::output::{write_bytes, Output};

/// Arguments of `envlight shader`.
#[derive(Debug, clap::Args)]
#[command(
    after_help = "The shader is the compute shader `sample --device gpu` runs \
(or, with --entry, the one for pdfs, radiance or both), with the library functions inside: \
light_sample, light_pdf, light_radiance and light_eval over the light's flat tables \
(docs/gpu-tables.md, which `envlight export` writes), with the CPU's algorithms, so the \
same ξ give the same directions up to f32 rounding. Workgroups of 64 invocations, one row \
each; the row is global_invocation_id.x + global_invocation_id.y · num_workgroups.x · 64.

Bindings, all in group 0 (descriptor set 0):
  0  params   uniform              the parameter block (section 1 of docs/gpu-tables.md, 64 words)
  1  tables   storage, read        the tables buffer (the sampling sections, contiguous)
  2  radiance storage, read        the radiance image (section 9)
  3  batch    uniform              8 words: count, mode (1 = ξ from the seed, 0 = from inputs), seed lo/hi, first row lo/hi, 2 reserved
  4  inputs   storage, read        sample_main: ξ, 2 floats a row; the others: directions, 4 floats a row (x, y, z, unused)
  5  outputs  storage, read_write  sample_main: 8 floats a row (x, y, z, pdf, r, g, b, 1 if sampled); pdf_main: 1; \
radiance_main: 4 (r, g, b, 0); eval_main: 4 (pdf, r, g, b)

Languages (translated by naga): wgsl is envlight.wgsl as it is (every entry point); glsl \
is GLSL 4.50 core (layout binding = N; the entry point is main); hlsl is shader model 5.1 \
(registers bN/tN/uN in space0, and num_workgroups from the constant buffer \
_NagaConstants at b0, space1); msl is Metal 2.0 ([[buffer(N)]], with the storage buffers' \
byte sizes in [[buffer(6)]]); spirv is a SPIR-V 1.3 binary for Vulkan 1.1 (set 0, \
binding N). Out-of-range indices are clamped. SPIR-V is binary: it is written to a file \
or a pipe, never to a terminal. -o writes atomically: all or nothing."
)]
pub struct Args {
    /// The shading language to write.
    #[arg(long, value_name = "LANG", value_parser = PossibleValuesParser::new(Lang::NAMES))]
    lang: String,

    /// The compute entry point to write (every one is in the wgsl).
    #[arg(
        long,
        value_name = "NAME",
        default_value = DEFAULT_ENTRY_POINT,
        value_parser = PossibleValuesParser::new(ENTRY_POINTS)
    )]
    entry: String,

    /// Write the shader to FILE (atomically: all or nothing) instead of stdout.
    #[arg(short = 'o', long = "output", value_name = "FILE")]
    output: Option<PathBuf>,
}

/// Runs `envlight shader`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    let lang: Lang = args.lang.parse().map_err(usage)?;
    let to_stdout = args.output.as_deref().is_none_or(|p| p.as_os_str() == "-");
    if lang.is_binary() && to_stdout && std::io::stdout().is_terminal() {
        return Err(UsageError(format!(
            "--lang {lang} is binary and stdout is a terminal: use -o FILE, or pipe it"
        ))
        .into());
    }
    let code = translate(lang, &args.entry).map_err(|e| match e {
        ShaderError::UnknownLang(_) | ShaderError::UnknownEntryPoint { .. } => usage(e),
        e => anyhow::Error::new(e),
    })?;
    let mut out = Output::create(args.output.as_deref())?;
    write_bytes(&mut out, &code)?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// A name clap let through but the shader module does not know (clap's lists and
/// the module's are the same constants, so only a mismatch between them).
fn usage(e: ShaderError) -> anyhow::Error {
    UsageError(e.to_string()).into()
}
