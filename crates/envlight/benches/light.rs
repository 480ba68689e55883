//! Benchmarks for building and querying the environment light, each next to the
//! plain seed implementation in `baseline/` measured in the same run, so figures can
//! be read as ratios on a noisy machine.
//!
//! Run: `cargo bench -p envlight --bench light` (all), or filter, e.g.
//! `cargo bench -p envlight --bench light -- sample`.

mod baseline;
#[path = "../examples/common/queries.rs"]
mod queries;

use baseline::BaselineLight;
use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion, Throughput};
use envlight::light::{Density, Sampler};
use envlight::{builtin, EnvImage, EnvironmentLight, LightOptions, Lookup};
use queries::{fold, sample_all};
use std::hint::black_box;
use std::sync::OnceLock;

/// Maps used by the benches: the built-in sky at 1k, 4k and 8k width (generated
/// once; the 8k map is 400 MB of texels).
fn sky(width: usize) -> &'static EnvImage {
    static MAPS: [OnceLock<EnvImage>; 3] = [OnceLock::new(), OnceLock::new(), OnceLock::new()];
    let slot = match width {
        1024 => &MAPS[0],
        4096 => &MAPS[1],
        _ => &MAPS[2],
    };
    slot.get_or_init(|| builtin::sky(width, width / 2))
}

fn light(width: usize, lookup: Lookup, sampler: Sampler) -> EnvironmentLight {
    let options = LightOptions {
        lookup,
        sampler,
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    EnvironmentLight::new(sky(width).clone(), options).unwrap()
}

/// [`sample_all`] for the baseline.
fn baseline_sample_all(base: &BaselineLight, xi: &[[f32; 2]]) -> f32 {
    xi.iter()
        .map(|&x| {
            base.sample(black_box(x))
                .map_or(0.0, |(d, p, l)| fold(d, p, l))
        })
        .sum()
}

const QUERIES: usize = 4096;
const COLD_QUERIES: usize = 1 << 20;

fn bench_build(c: &mut Criterion) {
    let mut group = c.benchmark_group("build");
    group.sample_size(10);
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    for width in [1024usize, 4096, 8192] {
        let image = sky(width);
        group.throughput(Throughput::Elements((width * width / 2) as u64));
        group.bench_with_input(BenchmarkId::new("baseline", width), image, |b, img| {
            b.iter_batched(|| img.clone(), BaselineLight::new, BatchSize::PerIteration)
        });
        // The baseline's density (piecewise-constant), and the default one.
        for (name, density) in [
            ("envlight", Density::PiecewiseConstant),
            ("envlight-bilinear", Density::PiecewiseBilinear),
        ] {
            let options = LightOptions {
                density,
                ..Default::default()
            };
            group.bench_with_input(BenchmarkId::new(name, width), image, |b, img| {
                b.iter_batched(
                    || img.clone(),
                    |img| EnvironmentLight::new(img, options).unwrap(),
                    BatchSize::PerIteration,
                )
            });
            group.bench_with_input(
                BenchmarkId::new(format!("{name}-1thread"), width),
                image,
                |b, img| {
                    b.iter_batched(
                        || img.clone(),
                        |img| one_thread.install(|| EnvironmentLight::new(img, options).unwrap()),
                        BatchSize::PerIteration,
                    )
                },
            );
        }
    }
    group.finish();
}

fn bench_queries(c: &mut Criterion) {
    let xi = queries::xi(99, QUERIES);
    let dirs = queries::directions(&xi);
    let width = 4096;
    let base = BaselineLight::new(sky(width).clone());
    let lights = [
        (
            "envlight-bilinear",
            light(width, Lookup::Bilinear, Sampler::Inversion),
        ),
        (
            "envlight-nearest",
            light(width, Lookup::Nearest, Sampler::Inversion),
        ),
    ];
    let alias = light(width, Lookup::Bilinear, Sampler::Alias);

    let mut group = c.benchmark_group("sample");
    group.throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("baseline", |b| b.iter(|| baseline_sample_all(&base, &xi)));
    for (name, l) in &lights {
        group.bench_function(*name, |b| b.iter(|| sample_all(l, &xi)));
    }
    group.bench_function("envlight-alias-bilinear", |b| {
        b.iter(|| sample_all(&alias, &xi))
    });
    let mut out = vec![None; QUERIES * 64];
    let many = queries::xi(5, out.len());
    group.throughput(Throughput::Elements(out.len() as u64));
    group.bench_function("envlight-batch-all-threads", |b| {
        b.iter(|| lights[0].1.sample_batch(black_box(&many), &mut out))
    });
    let one_thread = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    group.bench_function("envlight-batch-1thread", |b| {
        b.iter(|| one_thread.install(|| lights[0].1.sample_batch(black_box(&many), &mut out)))
    });
    group.finish();

    // Cold caches: a million fresh ξ per pass, so each query touches parts of the
    // map's data (48 MB of CDFs and 100 MB of texels for the baseline) that no
    // recent query brought in, as in a renderer whose samples wander the map.
    let cold = queries::xi(77, COLD_QUERIES);
    let mut group = c.benchmark_group("sample-cold");
    group.sample_size(10);
    group.throughput(Throughput::Elements(COLD_QUERIES as u64));
    group.bench_function("baseline", |b| b.iter(|| baseline_sample_all(&base, &cold)));
    group.bench_function("envlight-bilinear", |b| {
        b.iter(|| sample_all(&lights[0].1, &cold))
    });
    group.finish();

    // The planar sampler alone, on the same importance: the CDF search and placement
    // without the mapping to a direction or the radiance lookup.
    let planar = envlight::Distribution2D::new(base.importance(), width);
    let mut group = c.benchmark_group("sample2d");
    group.throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("baseline", |b| {
        b.iter(|| {
            xi.iter()
                .map(|&x| base.distribution().sample_continuous(black_box(x)).1)
                .sum::<f32>()
        })
    });
    group.bench_function("envlight", |b| {
        b.iter(|| {
            xi.iter()
                .map(|&x| planar.sample_continuous(black_box(x)).pdf)
                .sum::<f32>()
        })
    });
    let alias_planar = envlight::alias::AliasTable2D::new(base.importance(), width);
    group.bench_function("envlight-alias", |b| {
        b.iter(|| {
            xi.iter()
                .map(|&x| alias_planar.sample_continuous(black_box(x)).pdf)
                .sum::<f32>()
        })
    });
    group.finish();

    let mut group = c.benchmark_group("pdf");
    group.throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("baseline", |b| {
        b.iter(|| dirs.iter().map(|&d| base.pdf(black_box(d))).sum::<f32>())
    });
    for (name, l) in &lights {
        group.bench_function(*name, |b| {
            b.iter(|| dirs.iter().map(|&d| l.pdf(black_box(d))).sum::<f32>())
        });
    }
    // The batch call on one thread (run from inside the pool, so its one chunk
    // runs in place), per direction.
    let mut pdfs = vec![0.0f32; dirs.len()];
    group.bench_function("envlight-batch-1thread", |b| {
        one_thread.install(|| b.iter(|| lights[0].1.pdf_batch(black_box(&dirs), &mut pdfs)))
    });
    group.finish();

    let mut group = c.benchmark_group("radiance");
    group.throughput(Throughput::Elements(QUERIES as u64));
    group.bench_function("baseline", |b| {
        b.iter(|| {
            dirs.iter()
                .map(|&d| base.radiance(black_box(d))[1])
                .sum::<f32>()
        })
    });
    for (name, l) in &lights {
        group.bench_function(*name, |b| {
            b.iter(|| {
                dirs.iter()
                    .map(|&d| l.radiance(black_box(d))[1])
                    .sum::<f32>()
            })
        });
    }
    let mut radiance = vec![[0.0f32; 3]; dirs.len()];
    for (name, l) in &lights {
        group.bench_function(format!("{name}-batch-1thread"), |b| {
            one_thread.install(|| b.iter(|| l.radiance_batch(black_box(&dirs), &mut radiance)))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_build, bench_queries);
criterion_main!(benches);
