//! Thread guarantees: the light is `Send + Sync`, and the same ξ gives bit-identical
//! results whichever thread (or how many threads) evaluates it.

mod common;

use envlight::{builtin, EnvironmentLight, LightOptions, LightSample, Lookup, Rotation, Vec3};

fn assert_send_sync<T: Send + Sync>() {}

#[test]
fn light_and_its_parts_are_send_and_sync() {
    assert_send_sync::<EnvironmentLight>();
    assert_send_sync::<envlight::Distribution2D>();
    assert_send_sync::<envlight::EnvImage>();
    assert_send_sync::<envlight::Error>();
}

fn bits(s: &Option<LightSample>) -> Vec<u32> {
    match s {
        None => vec![],
        Some(s) => [s.direction.x, s.direction.y, s.direction.z, s.pdf]
            .iter()
            .chain(&s.radiance)
            .chain(&s.uv)
            .map(|v| v.to_bits())
            .collect(),
    }
}

#[test]
fn many_threads_give_bit_identical_results_to_one() {
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(33.0),
        lookup: Lookup::Bilinear,
        ..Default::default()
    };
    let light = EnvironmentLight::new(builtin::sky(256, 128), options).unwrap();
    let n = 50_000u64;
    let xi: Vec<[f32; 2]> = (0..n).map(|k| envlight::rng::xi_2d(11, k)).collect();
    let serial: Vec<Option<LightSample>> = xi.iter().map(|&x| light.sample(x)).collect();

    // Eight threads, each over an interleaved subset.
    let threads = 8usize;
    let parallel: Vec<Vec<(usize, Option<LightSample>)>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let (light, xi) = (&light, &xi);
                scope.spawn(move || {
                    (t..xi.len())
                        .step_by(threads)
                        .map(|k| (k, light.sample(xi[k])))
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for (k, s) in parallel.into_iter().flatten() {
        assert_eq!(
            bits(&s),
            bits(&serial[k]),
            "sample {k} differs between threads"
        );
    }

    // The batch API on a rayon pool of any size equals the serial loop.
    for pool_threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(pool_threads)
            .build()
            .unwrap();
        let mut out = vec![None; xi.len()];
        pool.install(|| light.sample_batch(&xi, &mut out));
        for (k, (a, b)) in out.iter().zip(&serial).enumerate() {
            assert_eq!(
                bits(a),
                bits(b),
                "batch sample {k} differs ({pool_threads} threads)"
            );
        }
        let dirs: Vec<Vec3> = serial.iter().flatten().map(|s| s.direction).collect();
        let mut pdfs = vec![0.0; dirs.len()];
        pool.install(|| light.pdf_batch(&dirs, &mut pdfs));
        for (d, p) in dirs.iter().zip(&pdfs) {
            assert_eq!(p.to_bits(), light.pdf(*d).to_bits());
        }
    }
}

/// The batch path samples in blocks and stages (see `sample_batch`): for every
/// sampler and density, and a length that is not a multiple of the block, it must
/// give exactly what one call at a time gives.
#[test]
fn batch_sampling_equals_single_samples_for_every_sampler() {
    let image = builtin::sky(200, 100);
    let xi: Vec<[f32; 2]> = (0..5_003u64).map(|k| envlight::rng::xi_2d(4, k)).collect();
    for (sampler, density) in common::SAMPLER_DENSITIES {
        let options = LightOptions {
            sampler,
            density,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image.clone(), options).unwrap();
        let mut out = vec![None; xi.len()];
        light.sample_batch(&xi, &mut out);
        for (k, (batched, &x)) in out.iter().zip(&xi).enumerate() {
            assert_eq!(
                bits(batched),
                bits(&light.sample(x)),
                "{sampler:?}/{density:?}: sample {k}"
            );
        }
    }
}

#[test]
fn building_is_independent_of_thread_count() {
    let image = builtin::sky(300, 150);
    let build = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| EnvironmentLight::new(image.clone(), LightOptions::default()).unwrap())
    };
    let (a, b) = (build(1), build(4));
    for k in 0..20_000 {
        let xi = envlight::rng::xi_2d(2, k);
        assert_eq!(bits(&a.sample(xi)), bits(&b.sample(xi)), "sample {k}");
    }
    assert_eq!(a.integral_rgb(), b.integral_rgb());
    assert_eq!(a.efficiency().to_bits(), b.efficiency().to_bits());
}

/// The batch pdf and radiance compute a block of directions at a time, in vector
/// instructions (four f64 lanes where the CPU has AVX2, two otherwise): for every
/// sampler, density, lookup, mapping and rotation, on random and degenerate
/// directions (poles, the seam, zero, NaN, infinite and non-unit vectors), and a
/// length that is not a multiple of the block, they must give exactly what one
/// call at a time gives.
#[test]
fn batch_pdf_and_radiance_equal_single_queries() {
    use envlight::light::Mapping;
    let image = builtin::sky(200, 100);
    let mut dirs: Vec<Vec3> = (0..5_003u64)
        .map(|k| {
            envlight::math::uniform_sphere(envlight::rng::xi_2d(8, k)) * (1.0 + (k % 3) as f32)
        })
        .collect();
    let tiny = 1e-7f32;
    dirs.extend([
        Vec3::new(0.0, 0.0, 1.0),
        Vec3::new(0.0, 0.0, -1.0),
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(1.0, -tiny, 0.0),
        Vec3::new(1.0, -0.0, 0.0),
        Vec3::new(-1.0, 0.0, 0.0),
        Vec3::new(-1.0, -0.0, 0.0),
        Vec3::new(tiny, 0.0, 1.0),
        Vec3::new(f32::NAN, 0.0, 1.0),
        Vec3::new(f32::INFINITY, 1.0, 0.0),
        Vec3::new(3.0e-39, 1.0e-39, -2.0e-39),
    ]);
    // Tilted off +z, so that every coordinate mixes.
    let (c, s) = (0.8f32, 0.6f32);
    let tilt = Rotation::from_rows([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]).unwrap();
    let rotations = [
        Rotation::IDENTITY,
        tilt.then_after(Rotation::about_z_degrees(71.0)),
    ];
    for (sampler, density) in common::SAMPLER_DENSITIES {
        for mapping in [Mapping::Equirectangular, Mapping::EqualArea] {
            for lookup in [Lookup::Bilinear, Lookup::Nearest] {
                for rotation in rotations {
                    let options = LightOptions {
                        sampler,
                        density,
                        mapping,
                        lookup,
                        rotation,
                        scale: 1.5,
                        ..Default::default()
                    };
                    let light = EnvironmentLight::new(image.clone(), options).unwrap();
                    let mut pdfs = vec![0.0; dirs.len()];
                    light.pdf_batch(&dirs, &mut pdfs);
                    let mut radiance = vec![[0.0; 3]; dirs.len()];
                    light.radiance_batch(&dirs, &mut radiance);
                    for (k, &d) in dirs.iter().enumerate() {
                        let what = format!("{sampler:?}/{density:?}/{mapping:?}/{lookup:?}: {d:?}");
                        assert_eq!(pdfs[k].to_bits(), light.pdf(d).to_bits(), "pdf, {what}");
                        assert_eq!(
                            radiance[k].map(f32::to_bits),
                            light.radiance(d).map(f32::to_bits),
                            "radiance, {what}"
                        );
                    }
                }
            }
        }
    }
}

/// Runs `work` on a thread and fails if it has not finished within a minute
/// (a deadlock fails the test instead of hanging the suite).
fn within_a_minute(what: &str, work: impl FnOnce() + Send + 'static) {
    let (done, finished) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        work();
        let _ = done.send(());
    });
    if finished
        .recv_timeout(std::time::Duration::from_secs(60))
        .is_err()
    {
        panic!("{what}: not finished after 60 s (a deadlock?)");
    }
}

/// Portal side tables and glossy product tables are built the first time a query
/// needs them, inside a `OnceLock`. The first queries often come from a caller's
/// rayon loop; building them must not deadlock there (a parallel build inside the
/// lock let the waiting worker steal a job asking for the same table).
#[test]
fn lazily_built_tables_can_be_first_asked_for_inside_a_rayon_loop() {
    use envlight::portal::{Portal, PortalLight, PortalOptions};
    use envlight::product::{Factor, ProductOptions, ProductSampler};
    use rayon::prelude::*;
    use std::sync::Arc;

    within_a_minute("portal and glossy tables from rayon workers", || {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .build()
            .unwrap();
        let light =
            Arc::new(EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap());
        let v = Vec3::new;
        let window = Portal::new([
            v(-1.0, 1.0, 0.5),
            v(1.0, 1.0, 0.5),
            v(1.0, 1.0, 1.5),
            v(-1.0, 1.0, 1.5),
        ])
        .unwrap();
        for round in 0..20 {
            let portals = PortalLight::new(
                light.clone(),
                std::slice::from_ref(&window),
                PortalOptions::default(),
            )
            .unwrap();
            let seen: f64 = pool.install(|| {
                (0..64)
                    .into_par_iter()
                    .map(|k| {
                        let p = v(0.02 * k as f32 - 0.6, 0.0, 1.0);
                        portals
                            .at(p)
                            .sample([0.3, 0.7])
                            .map_or(0.0, |s| s.pdf as f64)
                    })
                    .sum()
            });
            assert!(seen > 0.0, "round {round}: no portal sample");
            let product = ProductSampler::new(light.clone(), ProductOptions::default());
            let glossy: f64 = pool.install(|| {
                (0..64)
                    .into_par_iter()
                    .map(|k| {
                        let n = v(0.0, (k as f32 * 0.1).sin(), 1.0).normalized().unwrap();
                        let factor = Factor::glossy(n, n, 0.05 + 0.005 * k as f32);
                        product
                            .at(&factor)
                            .sample([0.4, 0.6])
                            .map_or(0.0, |s| s.pdf as f64)
                    })
                    .sum()
            });
            assert!(glossy > 0.0, "round {round}: no glossy product sample");
        }
    });
}
