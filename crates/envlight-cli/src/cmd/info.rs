//! `envlight info`: a summary of a map and the light built from it.

use std::io::Write;
use std::time::Instant;

use anyhow::Context;
use serde_json::json;

use super::Outcome;
use crate::light_args::{choice_name, LightArgs};
use crate::output::Output;

/// Arguments of `envlight info`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "With --json, one JSON object with the keys: map, width, height, format \
(\"builtin\", \"hdr\", \"exr\", \"pfm\", \"png\", \"jpeg\"), lookup, sampler, density, mapping, \
integral_rgb ([∫R dω, ∫G dω, ∫B dω] over the sphere), integral_luminance (∫Y dω), \
power_unit_radius ([R,G,B] power π r² ∫L dω for r = 1), max_luminance, \
brightest_direction ([x,y,z], the brightest texel's centre), efficiency \
((∫Y dω)² / ∫(Y²/p) dω; 1 means pdf ∝ luminance), sampling_bytes, load_ms, build_ms, \
efficiency_ms, negative_texels, most_negative, non_finite_texels, black.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    /// Print one JSON object instead of the readable summary.
    #[arg(long)]
    json: bool,
}

/// Runs `envlight info`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    let loaded = args.light.load()?;
    let light = &loaded.light;
    let image = light.image();
    let integral_rgb = light.integral_rgb();
    let integral_luminance = light.integral_luminance();
    let power = light.power(1.0);
    let (max_luminance, brightest) = light.brightest();
    let started = Instant::now();
    let efficiency = light.efficiency();
    let efficiency_ms = started.elapsed().as_secs_f64() * 1e3;
    let brightest = brightest.to_array();

    let mut out = Output::create(None)?;
    let text = if args.json {
        let value = json!({
            "map": loaded.name,
            "width": image.width(),
            "height": image.height(),
            "format": loaded.format,
            "lookup": choice_name(&args.light.lookup),
            "sampler": choice_name(&args.light.sampler),
            "density": choice_name(&args.light.density),
            "mapping": choice_name(&args.light.mapping),
            "rotate_degrees": args.light.rotate,
            "scale": args.light.scale,
            "integral_rgb": integral_rgb,
            "integral_luminance": integral_luminance,
            "power_unit_radius": power,
            "max_luminance": max_luminance,
            "brightest_direction": brightest,
            "efficiency": efficiency,
            "sampling_bytes": light.sampling_bytes(),
            "load_ms": loaded.load_ms,
            "build_ms": loaded.build_ms,
            "efficiency_ms": efficiency_ms,
            "negative_texels": loaded.sanitized.negative_texels,
            "most_negative": loaded.sanitized.most_negative,
            "non_finite_texels": loaded.sanitized.non_finite_texels,
            "black": loaded.black,
        });
        let mut text = serde_json::to_string_pretty(&value).context("cannot format JSON")?;
        text.push('\n');
        text
    } else {
        let (theta, phi) = angles_degrees(brightest);
        let mib = |bytes: usize| bytes as f64 / (1024.0 * 1024.0);
        let texels = image.width() * image.height();
        let mut lines = vec![
            ("map", loaded.name.clone()),
            ("format", loaded.format.clone()),
            (
                "size",
                format!("{} x {} ({texels} texels)", image.width(), image.height()),
            ),
            (
                "light",
                format!(
                    "lookup {}, sampler {}, density {}, mapping {}, rotate {}°, scale {}",
                    choice_name(&args.light.lookup),
                    choice_name(&args.light.sampler),
                    choice_name(&args.light.density),
                    choice_name(&args.light.mapping),
                    args.light.rotate,
                    args.light.scale
                ),
            ),
            (
                "∫ L dω",
                format!(
                    "R {:.6}  G {:.6}  B {:.6}",
                    integral_rgb[0], integral_rgb[1], integral_rgb[2]
                ),
            ),
            ("∫ Y dω", format!("{integral_luminance:.6}")),
            (
                "mean Y",
                format!(
                    "{:.6} (solid-angle weighted, ∫Y dω / 4π)",
                    integral_luminance / (4.0 * std::f64::consts::PI)
                ),
            ),
            (
                "power (r=1)",
                format!("R {:.5}  G {:.5}  B {:.5}", power[0], power[1], power[2]),
            ),
            ("max Y", format!("{max_luminance}")),
            (
                "brightest",
                format!(
                    "({:.5}, {:.5}, {:.5})  θ {theta:.2}°  φ {phi:.2}°",
                    brightest[0], brightest[1], brightest[2]
                ),
            ),
            (
                "efficiency",
                format!("{efficiency:.5} ((∫Y dω)² / ∫Y²/p dω; 1 = pdf ∝ luminance)"),
            ),
            (
                "sampling",
                format!("{:.2} MiB", mib(light.sampling_bytes())),
            ),
            (
                "time",
                format!(
                    "load {:.1} ms, build {:.1} ms, efficiency {efficiency_ms:.1} ms",
                    loaded.load_ms, loaded.build_ms
                ),
            ),
        ];
        if loaded.sanitized.negative_texels > 0 {
            lines.push((
                "negative",
                format!(
                    "{} texels clamped to 0 (most negative {})",
                    loaded.sanitized.negative_texels, loaded.sanitized.most_negative
                ),
            ));
        }
        if loaded.sanitized.non_finite_texels > 0 {
            lines.push((
                "non-finite",
                format!(
                    "{} texels replaced by 0",
                    loaded.sanitized.non_finite_texels
                ),
            ));
        }
        if loaded.black {
            lines.push(("note", "all black: no light, every pdf is 0".to_string()));
        }
        let mut text = String::new();
        for (key, value) in lines {
            text.push_str(&format!("{key:<12} {value}\n"));
        }
        text
    };
    out.write_all(text.as_bytes())
        .with_context(|| format!("{}: write failed", out.name()))?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// Polar angle θ from +z and azimuth φ from +x towards +y, in degrees (φ in [0, 360)).
pub fn angles_degrees(d: [f32; 3]) -> (f64, f64) {
    let (x, y, z) = (d[0] as f64, d[1] as f64, d[2] as f64);
    let theta = z.clamp(-1.0, 1.0).acos().to_degrees();
    let mut phi = y.atan2(x).to_degrees();
    if phi < 0.0 {
        phi += 360.0;
    }
    (theta, phi)
}
