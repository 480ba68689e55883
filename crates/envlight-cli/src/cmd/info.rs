//! `envlight info`: a summary of a map and the light built from it.

use std::io::Write;
use std::time::Instant;

use anyhow::Context;
use envlight::equal_area::square_to_sphere;
use envlight::light::Mapping;
use envlight::mapping::equirect_to_direction;
use std::sync::Arc;

use envlight::{EnvImage, EnvironmentLight, Factor, LightOptions, Vec3};
use envlight_verify::{efficiency, AtShadingPoint, Integrand, Reference};
use serde_json::json;

use super::Outcome;
use crate::device::DeviceArgs;
use crate::light_args::LightArgs;
use crate::output::Output;
use crate::shading::{product_sampler, NormalArgs};

/// Arguments of `envlight info`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "With --json, one JSON object with the keys: map, width, height (of the map as read), \
format (\"builtin\", \"hdr\", \"exr\", \"pfm\", \"png\", \"jpeg\"), lookup, sampler, density, mapping \
(the light's), input_mapping (the map's), light_width, light_height (the light's own image: \
the map's size unless a lat-long map is resampled for --mapping equal-area), \
integral_rgb ([∫R dω, ∫G dω, ∫B dω] over the sphere), integral_luminance (∫Y dω), \
power_unit_radius ([R,G,B] power π r² ∫L dω for r = 1), max_luminance (of the map's \
brightest texel as read, times --scale), \
brightest_direction ([x,y,z], the centre of the map's brightest texel, as read), efficiency \
((∫Y dω)² / ∫(Y²/p) dω; 1 means pdf ∝ luminance), sampling_bytes, load_ms, build_ms, \
efficiency_ms, negative_texels, most_negative, non_finite_texels, black. With --normal \
also: normal (the unit normal), irradiance (∫Y max(0, n·ω) dω), product_efficiency and \
light_efficiency ((∫Y cos⁺)² / ∫(Y cos⁺)²/p dω with the product sampler's pdf and with \
the light's own, integrated with 16 or more Gauss-Legendre points per texel over the \
lookup's radiance: what a renderer's estimates see; their ratio of 1/e − 1 is the \
variance gain), product_density (the density drawn within the product sampler's \
patches: the light's own, piecewise-constant or piecewise-bilinear), product_tables and \
product_bytes (its tables and memory, the light's aside), product_ms. With --device \
gpu also: device (\"gpu\"), adapter, backend, device_type, driver, device_bytes (the light's \
buffers on the device), and gpu_sample_agreement and gpu_eval_agreement: the share of \
65536 rows (seed 0, and uniformly random directions) where the GPU's direction, pdf and \
radiance agree with the CPU's within 2e-4 rad and 2e-3 relative.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    #[command(flatten)]
    normal: NormalArgs,

    #[command(flatten)]
    device: DeviceArgs,

    /// Print one JSON object instead of the readable summary.
    #[arg(long)]
    json: bool,
}

/// Runs `envlight info`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    let input = args.light.read()?;
    let options = args.light.light_options();
    let (max_luminance, brightest) = brightest_texel(&input.image, &options);
    let loaded = args.light.build(input)?;
    let light = &loaded.light;
    // What the light was built with (the library's names).
    let used = light.options();
    let (sampler, density) = (used.sampler.name(), used.density.name());
    let (mapping, input_mapping) = (used.mapping.name(), used.input_mapping.name());
    let image = light.image();
    let (width, height) = (loaded.input_width, loaded.input_height);
    let integral_rgb = light.integral_rgb();
    let integral_luminance = light.integral_luminance();
    let power = light.power(1.0);
    let started = Instant::now();
    let (efficiency, full_table_efficiency) = light.efficiency_with_full_table();
    let [table_width, table_height] = light.table_size();
    let efficiency_ms = started.elapsed().as_secs_f64() * 1e3;
    let brightest = brightest.to_array();
    let shading = args.normal.normal.map(|n| Shading::measure(light, n));
    let gpu = args
        .device
        .open(light, args.normal.normal)?
        .map(|g| GpuInfo::measure(&g, light))
        .transpose()?;

    let mut out = Output::create(None)?;
    let text = if args.json {
        let mut value = json!({
            "map": loaded.name,
            "width": width,
            "height": height,
            "format": loaded.format,
            "lookup": args.light.lookup.name(),
            "sampler": sampler,
            "density": density,
            "mapping": mapping,
            "input_mapping": input_mapping,
            "light_width": image.width(),
            "light_height": image.height(),
            "rotate_degrees": args.light.rotate,
            "scale": args.light.scale,
            "integral_rgb": integral_rgb,
            "integral_luminance": integral_luminance,
            "power_unit_radius": power,
            "max_luminance": max_luminance,
            "brightest_direction": brightest,
            "efficiency": efficiency,
            "table_width": table_width,
            "table_height": table_height,
            "full_table_efficiency": full_table_efficiency,
            "sampling_bytes": light.sampling_bytes(),
            "load_ms": loaded.load_ms,
            "build_ms": loaded.build_ms,
            "efficiency_ms": efficiency_ms,
            "negative_texels": loaded.sanitized.negative_texels,
            "most_negative": loaded.sanitized.most_negative,
            "non_finite_texels": loaded.sanitized.non_finite_texels,
            "black": loaded.black,
        });
        if let (Some(s), Some(object)) = (&shading, value.as_object_mut()) {
            object.insert("normal".into(), json!(s.normal.to_array()));
            object.insert("irradiance".into(), json!(s.irradiance));
            object.insert("product_efficiency".into(), json!(s.product_efficiency));
            object.insert("light_efficiency".into(), json!(s.light_efficiency));
            object.insert("product_density".into(), json!(s.density.name()));
            object.insert("product_tables".into(), json!(s.tables));
            object.insert("product_bytes".into(), json!(s.bytes));
            object.insert("product_ms".into(), json!(s.ms));
        }
        if let (Some(g), Some(object)) = (&gpu, value.as_object_mut()) {
            object.insert("device".into(), json!("gpu"));
            object.insert("adapter".into(), json!(g.adapter.name));
            object.insert("backend".into(), json!(g.adapter.backend));
            object.insert("device_type".into(), json!(g.adapter.device_type));
            object.insert("driver".into(), json!(g.adapter.driver));
            object.insert("device_bytes".into(), json!(g.device_bytes));
            object.insert("gpu_sample_agreement".into(), json!(g.sample.fraction()));
            object.insert("gpu_eval_agreement".into(), json!(g.eval.fraction()));
        }
        let mut text = serde_json::to_string_pretty(&value).context("cannot format JSON")?;
        text.push('\n');
        text
    } else {
        let (theta, phi) = angles_degrees(brightest);
        let mib = |bytes: usize| bytes as f64 / (1024.0 * 1024.0);
        let mut lines = vec![
            ("map", loaded.name.clone()),
            ("format", loaded.format.clone()),
            (
                "size",
                format!(
                    "{width} x {height} ({} texels, {input_mapping})",
                    width * height
                ),
            ),
            (
                "light",
                format!(
                    "lookup {}, sampler {sampler}, density {density}, mapping {mapping}, \
                     rotate {}°, scale {}",
                    args.light.lookup.name(),
                    args.light.rotate,
                    args.light.scale
                ),
            ),
        ];
        if used.mapping != used.input_mapping {
            lines.push((
                "light size",
                format!(
                    "{} x {} ({} texels, resampled to {mapping})",
                    image.width(),
                    image.height(),
                    image.width() * image.height()
                ),
            ));
        }
        lines.extend([
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
                format!(
                    "{:.2} MiB, table {table_width} x {table_height} cells",
                    mib(light.sampling_bytes())
                ),
            ),
        ]);
        if let Some(full) = full_table_efficiency {
            lines.push((
                "reduction",
                format!(
                    "{}x: efficiency {efficiency:.5} against {full:.5} with the full table \
                     (variance per sample x{:.3})",
                    image.width() / table_width,
                    variance_ratio(efficiency, full)
                ),
            ));
        }
        lines.extend([(
            "time",
            format!(
                "load {:.1} ms, build {:.1} ms, efficiency {efficiency_ms:.1} ms",
                loaded.load_ms, loaded.build_ms
            ),
        )]);
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
        if let Some(g) = &gpu {
            let a = &g.adapter;
            lines.push((
                "device",
                format!(
                    "gpu: {} ({}, {}; {}), {:.2} MiB of buffers",
                    a.name,
                    a.backend,
                    a.device_type,
                    a.driver,
                    g.device_bytes as f64 / (1024.0 * 1024.0)
                ),
            ));
            lines.push(("gpu sample", format!("{}", g.sample)));
            lines.push(("gpu eval", format!("{}", g.eval)));
        }
        if let Some(s) = &shading {
            let n = s.normal;
            lines.push(("normal", format!("({:.5}, {:.5}, {:.5})", n.x, n.y, n.z)));
            lines.push((
                "irradiance",
                format!("{} (∫Y max(0, n·ω) dω)", s.irradiance),
            ));
            lines.push((
                "product",
                format!(
                    "efficiency {:.5} with the product sampler, {:.5} with the light alone \
                     ((∫Y cos⁺)² / ∫(Y cos⁺)²/p dω), {:.1} ms; draws {} within \
                     patches, {} tables, {:.1} MB",
                    s.product_efficiency,
                    s.light_efficiency,
                    s.ms,
                    s.density.name(),
                    s.tables,
                    s.bytes as f64 / (1024.0 * 1024.0)
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

/// The brightest texel of the map as read (in its input mapping, before any
/// resampling; the first in row order among equals): its luminance times the scale,
/// and the world direction of its centre.
fn brightest_texel(image: &EnvImage, options: &LightOptions) -> (f32, Vec3) {
    let (w, h) = (image.width(), image.height());
    let (x, row, y) = image.brightest_texel();
    let (u, v) = ((x as f32 + 0.5) / w as f32, (row as f32 + 0.5) / h as f32);
    let local = match options.input_mapping {
        Mapping::Equirectangular => equirect_to_direction(u, v).0,
        Mapping::EqualArea => square_to_sphere(u, v),
    };
    let world = if options.rotation.is_identity() {
        local
    } else {
        options.rotation.apply(local)
    };
    (y * options.scale, world)
}

/// The figures of `--normal`: the irradiance integrand `Y·max(0, n·ω)` integrated,
/// and the efficiency for it of the product sampler's pdf and of the light's own.
struct Shading {
    normal: Vec3,
    irradiance: f64,
    product_efficiency: f64,
    light_efficiency: f64,
    /// What the product sampler draws within a patch.
    density: envlight::light::Density,
    tables: usize,
    bytes: usize,
    /// Time to build the product sampler and integrate, in milliseconds.
    ms: f64,
}

impl Shading {
    fn measure(light: &Arc<EnvironmentLight>, normal: Vec3) -> Self {
        let started = Instant::now();
        let product = product_sampler(light, Some(normal));
        let at = product
            .as_ref()
            .map(|p| AtShadingPoint::new(p, Factor::cosine(normal)));
        let integrand = Integrand::clamped_cosine(normal);
        // The checked rule (Gauss-Legendre, 16 or 36 points per texel over the
        // lookup's radiance), which a midpoint rule approaches as it is refined:
        // a midpoint rule misses part of the quadratic term of (Y cos)²/p between
        // texel centres and reads the efficiency high next to a sun (4 × 4 points
        // a texel: 1-5% high; BENCHMARKS.md).
        let light_only = efficiency(light.as_ref(), &integrand, Reference::Checked);
        let product_efficiency = at.as_ref().map_or(0.0, |a| {
            efficiency(a, &integrand, Reference::Checked).efficiency
        });
        Self {
            normal,
            irradiance: light_only.integral,
            product_efficiency,
            light_efficiency: light_only.efficiency,
            density: product
                .as_ref()
                .map_or(light.options().density, |p| p.density()),
            tables: product.as_ref().map_or(0, |p| p.table_count()),
            bytes: product.as_ref().map_or(0, |p| p.memory_bytes()),
            ms: started.elapsed().as_secs_f64() * 1e3,
        }
    }
}

/// How many times the variance per sample of `Y/p` grows from efficiency `full`
/// to `reduced`: `(1/reduced − 1) / (1/full − 1)`; 1 when both are exact.
fn variance_ratio(reduced: f64, full: f64) -> f64 {
    let (a, b) = (1.0 / reduced - 1.0, 1.0 / full - 1.0);
    if b > 0.0 {
        a / b
    } else if a > 0.0 {
        f64::INFINITY
    } else {
        1.0
    }
}

/// What `info --device gpu` reports: the adapter, and how the GPU's rows agree
/// with the CPU's.
struct GpuInfo {
    adapter: envlight_gpu::AdapterReport,
    device_bytes: u64,
    sample: envlight_gpu::agreement::Agreement,
    eval: envlight_gpu::agreement::Agreement,
}

impl GpuInfo {
    /// Rows compared per query.
    const ROWS: usize = 65536;

    fn measure(gpu: &envlight_gpu::GpuLight, light: &EnvironmentLight) -> anyhow::Result<Self> {
        let (sample, eval) = envlight_gpu::agreement::measure(gpu, light, 0, Self::ROWS)?;
        Ok(Self {
            adapter: gpu.device().report(),
            device_bytes: gpu.device_bytes(),
            sample,
            eval,
        })
    }
}
