//! `envlight`: inspect, sample, evaluate, picture and verify HDR environment maps.
//!
//! This binary is a thin layer over the `envlight` library: argument parsing,
//! output formats, progress and exit codes. Each subcommand lives in its own module
//! under [`cmd`]; the pieces they share are [`light_args`] (the map and light
//! options), [`output`] (atomic `-o` files and buffered stdout) and [`progress`].
//!
//! Exit status: 0 on success (also when stdout is closed early, e.g. by `head`),
//! 1 for bad input or I/O failure, 2 for bad usage. Errors are one line on stderr
//! starting `error:`.

use std::io::Write;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The coordinate conventions, repeated at the end of every subcommand's `--help`.
macro_rules! conventions {
    () => {
        "Conventions: right-handed, z up. An equirectangular map's point (u, v), u left to \
right and v top to bottom in [0, 1], looks along the direction with polar angle \
θ = π v from +z and azimuth φ = 2π u from +x towards +y: \
ω = (sin θ cos φ, sin θ sin φ, cos θ). So the top row looks up (+z), u = 0 looks \
along +x and u = 0.25 along +y. An equal-area map (--input-mapping equal-area, or what \
--mapping equal-area resamples a lat-long map to) is PBRT-v4's octahedral square: its \
centre looks up (+z), its corners down, the midpoints of its right and bottom edges \
along +x and +y. --rotate DEG turns the map about +z (+x towards +y). \
Pdfs are solid-angle densities (per steradian); radiance is linear RGB as stored in \
the file, times --scale.

MAP is a file (.hdr, .exr, .pfm, or 8-bit .png/.jpg, which are decoded from sRGB) or \
builtin:sky (the default)."
    };
}
pub(crate) use conventions;

mod cmd;
mod csv;
mod device;
mod light_args;
mod output;
mod progress;
mod query;
mod shading;

/// Importance-sampled HDR environment lighting: inspect a map, draw directions with
/// their exact pdf, evaluate pdfs, picture the sampling density and verify it.
#[derive(Debug, Parser)]
#[command(name = "envlight", version, after_help = conventions!())]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The subcommands. Adding one means a variant here, a module under `cmd/` with an
/// `Args` type and a `run` function, and one arm in [`Command::run`].
#[derive(Debug, Subcommand)]
enum Command {
    /// Summarise a map: size, format, ∫L dω, brightest direction, efficiency.
    Info(cmd::info::Args),
    /// Draw N directions from the light; CSV `x,y,z,pdf,r,g,b`.
    Sample(cmd::sample::Args),
    /// Evaluate pdf and radiance for directions read from a CSV file.
    Eval(cmd::eval::Args),
    /// Write the light's flat GPU tables (docs/gpu-tables.md) to a binary file.
    Export(cmd::export::Args),
    /// Write a PNG of the tone-mapped map above a heat map of its sampling density.
    Importance(cmd::importance::Args),
    /// Run the sampler's invariant checks on a map and print a pass/fail table.
    Verify(cmd::verify::Args),
    /// Measure load, build and query speed on a map, against a memory floor.
    Bench(cmd::bench::Args),
    /// Render a preview scene lit by the map (path tracing; several sampling
    /// strategies, side by side with --compare).
    Render(cmd::render::RenderArgs),
    /// Write the GPU compute shader (sampling, pdf, radiance) in WGSL, GLSL, HLSL,
    /// MSL or SPIR-V.
    Shader(cmd::shader::Args),
    /// Find the map's sun (a compact bright source): direction, size, radiance,
    /// irradiance; optionally write the map without it (--residual).
    Sun(cmd::sun::Args),
    /// Summarise a saved visibility cache (render --save-visibility); draw what one
    /// of its entries sees of the map (--entry E --image FILE.png).
    Visibility(cmd::visibility::Args),
}

impl Command {
    fn run(&self) -> anyhow::Result<cmd::Outcome> {
        match self {
            Command::Info(args) => cmd::info::run(args),
            Command::Sample(args) => cmd::sample::run(args),
            Command::Eval(args) => cmd::eval::run(args),
            Command::Export(args) => cmd::export::run(args),
            Command::Importance(args) => cmd::importance::run(args),
            Command::Verify(args) => cmd::verify::run(args),
            Command::Bench(args) => cmd::bench::run(args),
            Command::Render(args) => cmd::render::run(args).map(|()| cmd::Outcome::Success),
            Command::Shader(args) => cmd::shader::run(args),
            Command::Sun(args) => cmd::sun::run(args),
            Command::Visibility(args) => cmd::visibility::run(args),
        }
    }
}

fn main() -> ExitCode {
    quiet_vulkan_device_select();
    // clap prints its own message and exits with 2 for bad usage, 0 for --help.
    let cli = Cli::parse();
    match cli.command.run() {
        Ok(cmd::Outcome::Success) => ExitCode::SUCCESS,
        Ok(cmd::Outcome::ChecksFailed) => ExitCode::from(1),
        Err(error) if output::is_broken_pipe(&error) => ExitCode::SUCCESS,
        Err(error) => {
            let message = one_line(&error);
            // If stderr itself is gone there is nobody left to tell.
            let _ = writeln!(std::io::stderr().lock(), "error: {message}");
            if error.is::<cmd::UsageError>() {
                ExitCode::from(2)
            } else {
                ExitCode::from(1)
            }
        }
    }
}

/// Mesa's Vulkan device-select layer (an implicit layer that picks a default GPU)
/// connects to a Wayland display to do so and, on a machine without one, prints
/// `error: XDG_RUNTIME_DIR is invalid or not set` to stderr, which reads like
/// ours. wgpu chooses the adapter itself (WGPU_ADAPTER_NAME), so the layer is
/// switched off there, unless the user set NODEVICE_SELECT. Done first thing in
/// `main`, while the process has one thread.
fn quiet_vulkan_device_select() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_none()
        && std::env::var_os("NODEVICE_SELECT").is_none()
    {
        // SAFETY: no other thread exists yet to read the environment concurrently.
        unsafe { std::env::set_var("NODEVICE_SELECT", "1") };
    }
}

/// The error and its causes as one line, `outer: cause: root`, leaving out a cause
/// whose text the message already carries (library errors often repeat their
/// source's text in their own).
fn one_line(error: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in error.chain() {
        let text = cause.to_string();
        if message.contains(&text) {
            continue;
        }
        if !message.is_empty() {
            message.push_str(": ");
        }
        message.push_str(&text);
    }
    message.replace(['\n', '\r'], " ")
}
