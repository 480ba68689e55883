//! `envlight bench`: how fast the light builds and answers queries on a map, with
//! a memory floor measured in the same run so build time reads as a ratio.

use std::hint::black_box;
use std::io::Write;
use std::time::Instant;

use anyhow::Context;
use envlight::{EnvironmentLight, Factor, ProductOptions, ProductSampler, Vec3};
use serde_json::json;
use std::sync::Arc;

use super::Outcome;
use crate::device::DeviceArgs;
use crate::light_args::LightArgs;
use crate::output::Output;
use crate::shading::NormalArgs;

/// Arguments of `envlight bench`.
#[derive(Debug, clap::Args)]
#[command(after_help = concat!(
    "Measures, on this machine and map: load_ms (read and decode), build_ms (best of \
--repeat builds on all threads), build_ms_1thread (best build on one thread), floor_ms \
(the memory floor: one parallel pass that reads every texel and writes one f32 per \
texel), sample_ns / pdf_ns / radiance_ns (mean per call on one thread, random ξ or \
uniformly random directions, in the fastest of --repeat passes over --queries calls), \
batch_samples_per_s (the batch API on all threads, fastest pass) and \
bytes_per_texel (sampling data per texel of the light's image, the image itself aside). \
The readable table also gives the batch pdf and radiance per direction on one thread, \
and the process's first build (of the light the queries use), which also pays \
for memory the process had never touched. \
Builds start from the map as read, with the light options given (for --mapping \
equal-area from a lat-long map, the resampling is part of build_ms).\n\n\
With --json, one object with exactly the keys width, height (of the map as read), threads, load_ms, \
build_ms, build_ms_1thread, floor_ms, sample_ns, pdf_ns, radiance_ns, \
batch_samples_per_s, bytes_per_texel (all numbers).\n\n\
With --normal X,Y,Z, also the product sampler at a surface with that normal (light × \
max(0, n·ω), docs/design.md §6a), on one thread: product_point_ns (a new shading point, one \
sample and one pdf: what a renderer pays per shading point), product_sample_ns and \
product_pdf_ns (a point reused; pdfs of the same random directions as pdf_ns), \
product_build_ms (building the product sampler on all threads, fastest of --repeat, \
next to build_ms), product_bytes (its tables, the light's aside) and \
product_point_ratio (product_point_ns over one light sample, the two timed in \
alternating rounds, each pass after one that warms the caches, fastest of --repeat \
each: the ratio that holds on a busy machine, where the separate figures may come \
from quieter and busier moments); the JSON object \
gets these keys too.\n\n\
With --device gpu the queries run on the GPU instead, --queries at a time (the library's \
WGSL module through wgpu), and the figures are per pass, fastest of --repeat: for \
sample (ξ uploaded), sample_seeded (ξ drawn on the device), pdf and radiance, the \
upload, kernel and read-back times in ms and the rate of the kernel alone and of the \
whole round trip. With --json: device, adapter, backend, device_type, driver, width, \
height, queries, tables_ms (building the flat tables on the CPU), setup_ms (uploading \
them and compiling the pipelines), device_bytes, and per query an object with upload_ms, \
kernel_ms, readback_ms, kernel_per_s, round_trip_per_s. A software device (lavapipe) \
measures nothing about GPUs.\n\n",
    crate::conventions!()
))]
pub struct Args {
    #[command(flatten)]
    light: LightArgs,

    #[command(flatten)]
    device: DeviceArgs,

    #[command(flatten)]
    normal: NormalArgs,

    /// Print one JSON object instead of the readable table.
    #[arg(long)]
    json: bool,

    /// Queries per timed loop (per-call figures average over this many calls).
    #[arg(long, value_name = "N", default_value_t = 1 << 20,
          value_parser = clap::value_parser!(u64).range(1024..=1 << 28))]
    queries: u64,

    /// Builds, floor passes and query passes to time; the fastest of each is reported.
    #[arg(long, value_name = "K", default_value_t = 3,
          value_parser = clap::value_parser!(u32).range(1..=100))]
    repeat: u32,
}

/// Runs `envlight bench`.
pub fn run(args: &Args) -> anyhow::Result<Outcome> {
    // Builds are timed from the map as read, with the options as given: for an
    // equal-area light from a lat-long map that includes the resampling.
    let input = args.light.read()?;
    let input_image = input.image.clone();
    let image = &input_image;
    let loaded = args.light.build(input)?;
    let light = &loaded.light;
    if args.device.is_gpu() {
        return run_gpu(args, light, image.width(), image.height());
    }
    let options = *light.options();
    let texels = image.width() * image.height();
    let light_image = light.image();
    let light_texels = light_image.width() * light_image.height();
    let threads = rayon::current_num_threads();

    // The fastest of `--repeat` runs of `work` on what `setup` prepares for it,
    // each timed from its start until its result exists: neither the setup nor
    // freeing the result is timed.
    fn best_ms<S, T>(
        repeat: u32,
        mut setup: impl FnMut() -> S,
        mut work: impl FnMut(S) -> T,
    ) -> f64 {
        (0..repeat)
            .map(|_| {
                let input = setup();
                let started = Instant::now();
                let result = black_box(work(input));
                let ms = started.elapsed().as_secs_f64() * 1e3;
                drop(result);
                ms
            })
            .fold(f64::INFINITY, f64::min)
    }
    let floor_ms = best_ms(args.repeat, || (), |()| memory_floor(image.texels()));
    // Each build gets its own copy of the map, made before its clock starts.
    let best_build_ms = || {
        best_ms(
            args.repeat,
            || image.clone(),
            |copy| EnvironmentLight::new(copy, options),
        )
    };
    let build_ms = best_build_ms();
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .context("cannot start a one-thread pool")?;
    let build_ms_1thread = one_thread.install(best_build_ms);

    let n = args.queries;
    let xi: Vec<[f32; 2]> = (0..n).map(|k| envlight::rng::xi_2d(0xbe7c, k)).collect();
    let dirs: Vec<Vec3> = xi
        .iter()
        .map(|&x| envlight::math::uniform_sphere(x))
        .collect();

    // Per-query figures are the fastest of `--repeat` passes over the same queries
    // into the same output buffers, like the builds: a pass that the machine
    // interrupts, or that first touches freshly allocated output pages (a page
    // fault per 4 KiB), does not count.
    let best_ns = |mut pass: Box<dyn FnMut() + '_>| {
        let ms = best_ms(args.repeat, || (), |()| pass());
        ms * 1e6 / n as f64
    };
    // Every output of a single query goes into a sum, so none of them can be skipped.
    let (sample_ns, pdf_ns, radiance_ns) = one_thread.install(|| {
        (
            best_ns(Box::new(|| {
                black_box(
                    xi.iter()
                        .map(|&x| light.sample(x).map_or(0.0, digest))
                        .sum::<f32>(),
                );
            })),
            best_ns(Box::new(|| {
                black_box(dirs.iter().map(|&d| light.pdf(d)).sum::<f32>());
            })),
            best_ns(Box::new(|| {
                black_box(dirs.iter().map(|&d| light.radiance(d)[1]).sum::<f32>());
            })),
        )
    });
    // The batch queries on one thread: per-direction cost of the block kernels,
    // comparable with the single calls above.
    let mut pdfs = vec![0.0f32; dirs.len()];
    let mut radiance = vec![[0.0f32; 3]; dirs.len()];
    let (pdf_batch_ns, radiance_batch_ns) = one_thread.install(|| {
        (
            best_ns(Box::new(|| {
                light.pdf_batch(&dirs, &mut pdfs);
                black_box(&pdfs);
            })),
            best_ns(Box::new(|| {
                light.radiance_batch(&dirs, &mut radiance);
                black_box(&radiance);
            })),
        )
    });
    let mut out_samples = vec![None; xi.len()];
    let batch_samples_per_s = 1e9
        / best_ns(Box::new(|| {
            light.sample_batch(&xi, &mut out_samples);
            black_box(&out_samples);
        }));
    let bytes_per_texel = light.sampling_bytes() as f64 / light_texels as f64;
    let product = args
        .normal
        .normal
        .map(|normal| measure_product(light, normal, &xi, &dirs, args.repeat, &one_thread));

    let mut out = Output::create(None)?;
    let text = if args.json {
        let value = json!({
            "width": image.width(),
            "height": image.height(),
            "threads": threads,
            "load_ms": loaded.load_ms,
            "build_ms": build_ms,
            "build_ms_1thread": build_ms_1thread,
            "floor_ms": floor_ms,
            "sample_ns": sample_ns,
            "pdf_ns": pdf_ns,
            "radiance_ns": radiance_ns,
            "batch_samples_per_s": batch_samples_per_s,
            "bytes_per_texel": bytes_per_texel,
        });
        let mut value = value;
        if let (Some(p), Some(object)) = (&product, value.as_object_mut()) {
            object.insert("product_point_ns".into(), json!(p.point_ns));
            object.insert("product_sample_ns".into(), json!(p.sample_ns));
            object.insert("product_pdf_ns".into(), json!(p.pdf_ns));
            object.insert("product_build_ms".into(), json!(p.build_ms));
            object.insert("product_bytes".into(), json!(p.bytes));
            object.insert("product_point_ratio".into(), json!(p.point_ratio));
        }
        format!("{value}\n")
    } else {
        let ratio = |a: f64, b: f64| if b > 0.0 { a / b } else { f64::NAN };
        let light_size = if options.mapping == options.input_mapping {
            String::new()
        } else {
            format!(
                "light size        {} x {} ({:.1} Mtexels, {})\n",
                light_image.width(),
                light_image.height(),
                light_texels as f64 / 1e6,
                options.mapping.name()
            )
        };
        format!(
            "map               {}\n\
             size              {} x {} ({:.1} Mtexels), {threads} threads\n\
             {light_size}\
             light             sampler {}, density {}, mapping {}\n\
             load              {:>10.1} ms\n\
             build             {build_ms:>10.1} ms   ({:.2}x the memory floor)\n\
             build, 1 thread   {build_ms_1thread:>10.1} ms   ({:.2}x the floor)\n\
             build, first      {:>10.1} ms   (the process's first, on fresh memory)\n\
             memory floor      {floor_ms:>10.1} ms   (read every texel, write one f32)\n\
             sample            {sample_ns:>10.1} ns   (1 thread)\n\
             pdf               {pdf_ns:>10.1} ns   (1 thread)\n\
             radiance          {radiance_ns:>10.1} ns   (1 thread)\n\
             pdf, batch        {pdf_batch_ns:>10.1} ns   (per direction, 1 thread)\n\
             radiance, batch   {radiance_batch_ns:>10.1} ns   (per direction, 1 thread)\n\
             batch sample      {:>10.2} M/s  (all threads)\n\
             sampling data     {bytes_per_texel:>10.2} bytes per texel\n{}",
            loaded.name,
            image.width(),
            image.height(),
            texels as f64 / 1e6,
            options.sampler.name(),
            options.density.name(),
            options.mapping.name(),
            loaded.load_ms,
            ratio(build_ms, floor_ms),
            ratio(build_ms_1thread, floor_ms),
            loaded.build_ms,
            batch_samples_per_s / 1e6,
            product
                .as_ref()
                .map_or(String::new(), |p| p.table(sample_ns, pdf_ns, build_ms)),
        )
    };
    out.write_all(text.as_bytes())?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// The product sampler's figures of `--normal`.
struct ProductFigures {
    normal: Vec3,
    point_ns: f64,
    /// `point_ns` over a light sample, timed in alternating passes.
    point_ratio: f64,
    sample_ns: f64,
    pdf_ns: f64,
    build_ms: f64,
    bytes: usize,
}

impl ProductFigures {
    /// The readable table's lines, with ratios to the light's own figures.
    fn table(&self, sample_ns: f64, pdf_ns: f64, build_ms: f64) -> String {
        let n = self.normal;
        format!(
            "product at normal ({:.3}, {:.3}, {:.3}), 1 thread:\n\
             \x20 point+sample+pdf {:>10.1} ns   ({:.2}x a light sample; {:.2}x in alternating passes)\n\
             \x20 sample           {:>10.1} ns   ({:.2}x)\n\
             \x20 pdf              {:>10.1} ns   ({:.2}x a light pdf)\n\
             \x20 build            {:>10.1} ms   ({:.2}x the light's), {:.1} MB\n",
            n.x,
            n.y,
            n.z,
            self.point_ns,
            self.point_ns / sample_ns,
            self.point_ratio,
            self.sample_ns,
            self.sample_ns / sample_ns,
            self.pdf_ns,
            self.pdf_ns / pdf_ns,
            self.build_ms,
            self.build_ms / build_ms,
            self.bytes as f64 / 1e6,
        )
    }
}

/// Every output of a sample in one number, so that a timed loop summing them can
/// skip none of the work.
fn digest(s: envlight::LightSample) -> f32 {
    s.pdf + s.direction.x + s.direction.y + s.direction.z + s.radiance[1]
}

/// Nanoseconds per query of one pass of `pass` over `queries` queries.
fn ns_per_query(pass: &dyn Fn() -> f32, queries: usize) -> f64 {
    let started = Instant::now();
    black_box(pass());
    started.elapsed().as_secs_f64() * 1e9 / queries as f64
}

/// Times the product sampler at `normal` (see `--help`): queries on `one_thread`,
/// the fastest of `repeat` passes; builds on all threads.
fn measure_product(
    light: &EnvironmentLight,
    normal: Vec3,
    xi: &[[f32; 2]],
    dirs: &[Vec3],
    repeat: u32,
    one_thread: &rayon::ThreadPool,
) -> ProductFigures {
    let shared = Arc::new(light.clone());
    let mut build_ms = f64::INFINITY;
    let mut sampler = None;
    for _ in 0..repeat {
        let started = Instant::now();
        let built = ProductSampler::new(Arc::clone(&shared), ProductOptions::default());
        build_ms = build_ms.min(started.elapsed().as_secs_f64() * 1e3);
        sampler = Some(black_box(built));
    }
    let sampler = sampler.expect("repeat is at least 1");
    let factor = Factor::cosine(normal);
    let best_ns = |pass: &dyn Fn() -> f32| {
        (0..repeat)
            .map(|_| ns_per_query(pass, xi.len()))
            .fold(f64::INFINITY, f64::min)
    };
    let (point_ns, point_ratio, sample_ns, pdf_ns) = one_thread.install(|| {
        // A new shading point per query: `at` maps the normal into the table
        // grid from scratch every time (nothing is cached between points).
        let point_pass = || -> f32 {
            xi.iter()
                .map(|&x| {
                    let point = sampler.at(black_box(&factor));
                    point
                        .sample(x)
                        .map_or(0.0, |s| point.pdf(s.direction) + digest(s))
                })
                .sum()
        };
        let light_pass = || -> f32 {
            xi.iter()
                .map(|&x| light.sample(x).map_or(0.0, digest))
                .sum()
        };
        let point_ns = best_ns(&point_pass);
        // The two in alternating rounds, so that both see the same machine; in each,
        // a pass that warms the caches for its kind of query, then the timed one.
        let (mut point_best, mut light_best) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..repeat {
            black_box(point_pass());
            point_best = point_best.min(ns_per_query(&point_pass, xi.len()));
            black_box(light_pass());
            light_best = light_best.min(ns_per_query(&light_pass, xi.len()));
        }
        let point_ratio = point_best / light_best;
        let point = sampler.at(&factor);
        let sample_ns = best_ns(&|| {
            xi.iter()
                .map(|&x| point.sample(x).map_or(0.0, digest))
                .sum()
        });
        let pdf_ns = best_ns(&|| dirs.iter().map(|&d| point.pdf(d)).sum());
        (point_ns, point_ratio, sample_ns, pdf_ns)
    });
    ProductFigures {
        normal,
        point_ns,
        point_ratio,
        sample_ns,
        pdf_ns,
        build_ms,
        bytes: sampler.memory_bytes(),
    }
}

/// One query's fastest pass on the GPU.
#[derive(Debug, Clone, Copy)]
struct GpuPass {
    timings: envlight_gpu::Timings,
    rows: usize,
}

impl GpuPass {
    fn fastest(
        repeat: u32,
        mut pass: impl FnMut() -> anyhow::Result<envlight_gpu::Timings>,
        rows: usize,
    ) -> anyhow::Result<Self> {
        let mut best: Option<envlight_gpu::Timings> = None;
        for _ in 0..repeat {
            let t = pass()?;
            let total = |t: &envlight_gpu::Timings| t.upload + t.kernel + t.readback;
            if best.as_ref().is_none_or(|b| total(&t) < total(b)) {
                best = Some(t);
            }
        }
        Ok(Self {
            timings: best.unwrap_or_default(),
            rows,
        })
    }

    fn per_s(&self, seconds: f64) -> f64 {
        if seconds > 0.0 {
            self.rows as f64 / seconds
        } else {
            f64::NAN
        }
    }

    fn kernel_per_s(&self) -> f64 {
        self.per_s(self.timings.kernel)
    }

    fn round_trip_per_s(&self) -> f64 {
        let t = self.timings;
        self.per_s(t.upload + t.kernel + t.readback)
    }

    fn json(&self) -> serde_json::Value {
        let t = self.timings;
        json!({
            "upload_ms": t.upload * 1e3,
            "kernel_ms": t.kernel * 1e3,
            "readback_ms": t.readback * 1e3,
            "kernel_per_s": self.kernel_per_s(),
            "round_trip_per_s": self.round_trip_per_s(),
        })
    }

    fn line(&self, name: &str) -> String {
        let t = self.timings;
        format!(
            "{name:<17} upload {:>8.2} ms  kernel {:>8.2} ms  read-back {:>8.2} ms  \
             {:>8.2} M/s kernel, {:>8.2} M/s round trip\n",
            t.upload * 1e3,
            t.kernel * 1e3,
            t.readback * 1e3,
            self.kernel_per_s() / 1e6,
            self.round_trip_per_s() / 1e6
        )
    }
}

/// `bench --device gpu`: the GPU's passes over `--queries` rows.
fn run_gpu(
    args: &Args,
    light: &EnvironmentLight,
    width: usize,
    height: usize,
) -> anyhow::Result<Outcome> {
    let started = Instant::now();
    let tables = crate::device::gpu_tables(light)?;
    let tables_ms = started.elapsed().as_secs_f64() * 1e3;
    let device = envlight_gpu::GpuDevice::new()?;
    let started = Instant::now();
    let gpu = envlight_gpu::GpuLight::from_tables(&device, &tables, envlight_gpu::shader::WGSL)?;
    let setup_ms = started.elapsed().as_secs_f64() * 1e3;
    let n = args.queries as usize;
    let xi: Vec<[f32; 2]> = (0..n as u64)
        .map(|k| envlight::rng::xi_2d(0xbe7c, k))
        .collect();
    let dirs: Vec<[f32; 3]> = xi
        .iter()
        .map(|&x| envlight::math::uniform_sphere(x).to_array())
        .collect();
    let r = args.repeat;
    let sample = GpuPass::fastest(r, || Ok(gpu.sample_timed(&xi)?.1), n)?;
    let seeded = GpuPass::fastest(r, || Ok(gpu.sample_seeded_timed(0xbe7c, 0, n)?.1), n)?;
    let pdf = GpuPass::fastest(r, || Ok(gpu.pdf_timed(&dirs)?.1), n)?;
    let radiance = GpuPass::fastest(r, || Ok(gpu.radiance_timed(&dirs)?.1), n)?;
    let adapter = device.report();
    let mut out = Output::create(None)?;
    let text = if args.json {
        let value = json!({
            "device": "gpu",
            "adapter": adapter.name,
            "backend": adapter.backend,
            "device_type": adapter.device_type,
            "driver": adapter.driver,
            "width": width,
            "height": height,
            "queries": n,
            "tables_ms": tables_ms,
            "setup_ms": setup_ms,
            "device_bytes": gpu.device_bytes(),
            "sample": sample.json(),
            "sample_seeded": seeded.json(),
            "pdf": pdf.json(),
            "radiance": radiance.json(),
        });
        format!("{value}\n")
    } else {
        let software = if adapter.device_type == "cpu" {
            " (a software device: these figures say nothing about GPUs)"
        } else {
            ""
        };
        format!(
            "map               {width} x {height}\n\
             adapter           {} ({}, {}){software}\n\
             tables            {tables_ms:>10.1} ms   (flat tables built on the CPU)\n\
             setup             {setup_ms:>10.1} ms   (upload and pipeline compilation)\n\
             device memory     {:>10.1} MiB\n\
             passes of {n} rows, fastest of {r}:\n{}{}{}{}",
            adapter.name,
            adapter.backend,
            adapter.device_type,
            gpu.device_bytes() as f64 / (1 << 20) as f64,
            sample.line("sample"),
            seeded.line("sample, seeded"),
            pdf.line("pdf"),
            radiance.line("radiance"),
        )
    };
    out.write_all(text.as_bytes())?;
    out.finish()?;
    Ok(Outcome::Success)
}

/// The memory floor of a build: read every texel once and write one `f32` per texel
/// (its luminance), in parallel.
fn memory_floor(texels: &[[f32; 3]]) -> Vec<f32> {
    use rayon::prelude::*;
    let mut out = vec![0.0f32; texels.len()];
    out.par_chunks_mut(1 << 16)
        .zip(texels.par_chunks(1 << 16))
        .for_each(|(o, t)| {
            for (dst, &rgb) in o.iter_mut().zip(t) {
                *dst = envlight::color::luminance(rgb);
            }
        });
    out
}
