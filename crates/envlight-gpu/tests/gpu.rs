//! The GPU light against the CPU light, row by row, on a real device (Mesa's
//! lavapipe in CI), for every ported combination of sampler, density, mapping and
//! lookup; the library's invariant harness on GPU output; and the rejection of
//! deliberately broken shaders by both.
//!
//! Without an adapter the tests print one line naming the package to install and
//! pass, unless `ENVLIGHT_REQUIRE_GPU` is set (CI sets it): then they fail.

use std::path::Path;
use std::sync::OnceLock;

use envlight::gpu::GpuTableOptions;
use envlight::light::{Density, Mapping, Sampler};
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation};
use envlight_gpu::agreement::{compare, cpu_eval_rows, cpu_sample_rows, Agreement, Row, PORTED};
use envlight_gpu::{shader, GpuDevice, GpuLight, GpuSphereSampler};
use envlight_verify::{maps, Config, Integrand, SphereSampler};

/// Rows per agreement case.
const ROWS: usize = 20_000;
/// The seed of every agreement case.
const SEED: u64 = 0x6e41;

/// The shared device, or `None` (after printing why) where there is none.
fn device() -> Option<&'static GpuDevice> {
    static DEVICE: OnceLock<Option<GpuDevice>> = OnceLock::new();
    DEVICE
        .get_or_init(|| match GpuDevice::new() {
            Ok(d) => {
                let r = d.report();
                println!("GPU adapter: {} ({}, {})", r.name, r.backend, r.device_type);
                Some(d)
            }
            Err(e) => {
                assert!(
                    std::env::var_os("ENVLIGHT_REQUIRE_GPU").is_none(),
                    "ENVLIGHT_REQUIRE_GPU is set but there is no GPU: {e}"
                );
                println!("skipping GPU tests: {e}");
                None
            }
        })
        .as_ref()
}

/// A sun-and-sky map: a smooth sky and a 3×2-texel sun, asymmetric in u and v.
fn sun_sky(w: usize, h: usize) -> EnvImage {
    EnvImage::from_fn(w, h, |x, y| {
        let u = (x as f32 + 0.5) / w as f32;
        let v = (y as f32 + 0.5) / h as f32;
        let sky = [0.3 + 0.5 * (1.0 - v), 0.5 + 0.4 * u, 1.0 - 0.5 * v];
        if (x == w / 3 || x == w / 3 + 1 || x == w / 3 + 2) && (y == h / 4 || y == h / 4 + 1) {
            [5000.0, 4500.0, 4000.0]
        } else if v > 0.5 {
            [0.05 * sky[0], 0.05 * sky[1], 0.05 * sky[2]]
        } else {
            sky
        }
    })
    .unwrap()
}

fn options(sampler: Sampler, density: Density, mapping: Mapping, lookup: Lookup) -> LightOptions {
    LightOptions {
        sampler,
        density,
        mapping,
        lookup,
        ..Default::default()
    }
}

/// Every ported combination: (sampler, density) × mapping × lookup.
fn ported() -> Vec<(String, LightOptions)> {
    let mut out = Vec::new();
    for (sampler, density) in PORTED {
        for mapping in Mapping::ALL {
            for lookup in [Lookup::Nearest, Lookup::Bilinear] {
                let name = format!(
                    "{} {} {} {lookup:?}",
                    sampler.name(),
                    density.name(),
                    mapping.name()
                );
                out.push((name, options(sampler, density, mapping, lookup)));
            }
        }
    }
    // The node lookup: lat-long maps, either density (the bilinear one's nodes on
    // the rows, pole to pole).
    for (sampler, density) in PORTED {
        let name = format!("{} {} node", sampler.name(), density.name());
        out.push((
            name,
            options(sampler, density, Mapping::Equirectangular, Lookup::Node),
        ));
    }
    out
}

/// Samples `ROWS` rows for `SEED` on both devices (ξ drawn on each) and compares.
fn sample_agreement(gpu: &GpuLight, light: &EnvironmentLight) -> Agreement {
    let rows: Vec<Row> = gpu
        .sample_seeded(SEED, 0, ROWS)
        .unwrap()
        .iter()
        .map(|s| s.row())
        .collect();
    compare(&cpu_sample_rows(light, SEED, 0, ROWS), &rows)
}

/// Directions that probe the awkward places: random ones, the poles, the φ seam
/// (y = ±0 and tiny), texel-edge neighbourhoods, and non-unit lengths.
fn probe_directions(n: usize) -> Vec<[f32; 3]> {
    let mut rng = envlight::rng::SplitMix64::new(17);
    let mut out = vec![
        [0.0, 0.0, 1.0],
        [0.0, 0.0, -1.0],
        [1e-6, 0.0, 1.0],
        [0.0, -1e-6, -1.0],
        [1.0, 0.0, 0.0],
        [1.0, -0.0, 0.0],
        [1.0, 1e-7, 0.3],
        [1.0, -1e-7, -0.3],
        [-1.0, 0.0, 0.0],
        [-1.0, -1e-7, 0.5],
        [2.0, 3.0, 4.0],
    ];
    while out.len() < n {
        let d = envlight::math::uniform_sphere([rng.next_f32(), rng.next_f32()]);
        out.push(d.to_array());
    }
    out
}

fn eval_agreement(gpu: &GpuLight, light: &EnvironmentLight) -> Agreement {
    let dirs = probe_directions(ROWS);
    let rows: Vec<Row> = gpu
        .eval(&dirs)
        .unwrap()
        .iter()
        .zip(&dirs)
        .map(|(e, &d)| e.row(d))
        .collect();
    compare(&cpu_eval_rows(light, &dirs), &rows)
}

fn assert_agrees(case: &str, gpu: &GpuLight, light: &EnvironmentLight) {
    let s = sample_agreement(gpu, light);
    let e = eval_agreement(gpu, light);
    println!("[{case}] sample: {s}\n[{case}] eval:   {e}");
    assert!(s.passes(), "[{case}] sample rows disagree: {s}");
    assert!(e.passes(), "[{case}] eval rows disagree: {e}");
}

/// [`assert_agrees`] for the light of `image` under `o`, uploaded to `device`.
fn assert_light_agrees(case: &str, device: &GpuDevice, image: EnvImage, o: LightOptions) {
    let light = EnvironmentLight::new(image, o).unwrap();
    let gpu = GpuLight::new(device, &light).unwrap();
    assert_agrees(case, &gpu, &light);
}

#[test]
fn every_ported_combination_agrees_with_the_cpu() {
    let Some(device) = device() else { return };
    for (name, o) in ported() {
        for (map_name, image) in [
            ("sun-sky 96x48", sun_sky(96, 48)),
            ("random 40x20", maps::random(40, 20, 3)),
        ] {
            assert_light_agrees(&format!("{name}, {map_name}"), device, image, o);
        }
    }
}

#[test]
fn rotation_scale_compensation_and_reduced_tables_agree() {
    let Some(device) = device() else { return };
    let base = LightOptions {
        rotation: Rotation::about_z_degrees(37.0),
        scale: 2.5,
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    let cases = [
        ("rotated, scaled", base),
        (
            "alias, rotated",
            LightOptions {
                sampler: Sampler::Alias,
                ..base
            },
        ),
        (
            "MIS-compensated",
            LightOptions {
                mis_compensation: true,
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
        ),
        (
            "table 24 wide",
            LightOptions {
                table_width: Some(24),
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
        ),
        (
            "alias, table 24 wide",
            LightOptions {
                sampler: Sampler::Alias,
                table_width: Some(24),
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
        ),
        (
            "bilinear density, rotated",
            LightOptions {
                density: Density::PiecewiseBilinear,
                ..base
            },
        ),
    ];
    for (name, o) in cases {
        assert_light_agrees(name, device, sun_sky(96, 48), o);
    }
}

#[test]
fn degenerate_maps_agree() {
    let Some(device) = device() else { return };
    for (name, o) in ported() {
        // One texel: the whole sphere is one cell.
        assert_light_agrees(&format!("{name}, 1x1"), device, maps::constant(1, 1), o);
        // One hot texel on a pole row.
        let hot = maps::hot(32, 16, 5, 0);
        assert_light_agrees(&format!("{name}, hot texel on the top row"), device, hot, o);
        // All black: no sample, pdf 0 everywhere.
        let light = EnvironmentLight::new(maps::black(16, 8), o).unwrap();
        let gpu = GpuLight::new(device, &light).unwrap();
        let samples = gpu.sample_seeded(SEED, 0, 4096).unwrap();
        assert!(
            samples.iter().all(|s| !s.is_valid() && s.pdf == 0.0),
            "[{name}] black map sampled"
        );
        assert!(samples
            .iter()
            .all(|s| s.direction.iter().all(|c| c.is_finite())));
        let pdfs = gpu.pdf(&probe_directions(4096)).unwrap();
        assert!(
            pdfs.iter().all(|&p| p == 0.0),
            "[{name}] black map has a pdf"
        );
        assert_agrees(&format!("{name}, black"), &gpu, &light);
    }
}

#[test]
fn f16_radiance_agrees_within_its_precision() {
    let Some(device) = device() else { return };
    let light = EnvironmentLight::new(sun_sky(96, 48), LightOptions::default()).unwrap();
    let options = GpuTableOptions {
        radiance: envlight::gpu::RadianceFormat::F16,
    };
    let tables = light.gpu_tables(&options).unwrap();
    let gpu = GpuLight::from_tables(device, &tables, shader::WGSL).unwrap();
    let dirs = probe_directions(ROWS);
    let evals = gpu.eval(&dirs).unwrap();
    let cpu = cpu_eval_rows(&light, &dirs);
    let mut worst = 0.0f64;
    for (e, c) in evals.iter().zip(&cpu) {
        assert_eq!(e.pdf > 0.0, c.pdf > 0.0);
        let scale = c.radiance.iter().fold(0.0f32, |m, &x| m.max(x)) as f64;
        for k in 0..3 {
            worst = worst.max((e.radiance[k] as f64 - c.radiance[k] as f64).abs() / scale);
        }
    }
    println!("f16 radiance: worst relative difference {worst:.2e}");
    // f16 keeps 11 significant bits: 2⁻¹¹ relative per texel.
    assert!(worst < 1e-3, "{worst}");
}

/// The real maps in `shared/envmaps`, when present, with the default light and
/// the bilinear density.
#[test]
fn real_maps_agree() {
    let Some(device) = device() else { return };
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    if !dir.is_dir() {
        println!("skipping real maps: {} not found", dir.display());
        return;
    }
    for file in ["sunrise.exr", "city.exr", "colorful_studio_2k.hdr"] {
        let path = dir.join(file);
        let image = envlight::load::load(&path, &Default::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
            .image;
        for (name, o) in [
            ("default", LightOptions::default()),
            (
                "alias",
                LightOptions {
                    sampler: Sampler::Alias,
                    density: Density::PiecewiseConstant,
                    ..Default::default()
                },
            ),
            (
                "bilinear density",
                LightOptions {
                    density: Density::PiecewiseBilinear,
                    ..Default::default()
                },
            ),
        ] {
            assert_light_agrees(&format!("{file}, {name}"), device, image.clone(), o);
        }
    }
}

/// The harness's checks (normalisation, pdf consistency, χ², E[L/p], support,
/// efficiency) on samples and pdfs computed by the GPU.
#[test]
fn the_harness_passes_on_gpu_output() {
    let Some(device) = device() else { return };
    let config = Config {
        chi2_samples: 400_000,
        max_bins: 8_000,
        consistency_samples: 100_000,
        mc_samples: 400_000,
        ..Config::SYNTHETIC
    };
    let only = std::env::var("ENVLIGHT_HARNESS_CASE").ok();
    for (name, o) in [
        ("inversion", LightOptions::default()),
        (
            "alias, equal-area",
            LightOptions {
                sampler: Sampler::Alias,
                mapping: Mapping::EqualArea,
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
        ),
        (
            "bilinear density, rotated",
            LightOptions {
                density: Density::PiecewiseBilinear,
                rotation: Rotation::about_z_degrees(-70.0),
                ..Default::default()
            },
        ),
    ] {
        if only.as_deref().is_some_and(|c| c != name) {
            continue;
        }
        let light = EnvironmentLight::new(sun_sky(64, 32), o).unwrap();
        let gpu = GpuLight::new(device, &light).unwrap();
        let sampler = GpuSphereSampler::new(&gpu, SphereSampler::grid(&light).unwrap());
        envlight_verify::assert_invariants(name, &sampler, &Integrand::luminance(), &config);
        assert_eq!(sampler.error(), None);
    }
}

/// The WGSL module with one piece of text replaced (which must be there).
fn broken(what: &str, with: &str) -> String {
    assert!(
        shader::WGSL.contains(what),
        "the shader no longer contains {what:?}"
    );
    shader::WGSL.replacen(what, with, 1)
}

/// A pdf 1% too large, and a flipped axis, are caught by the row comparison and
/// by the harness.
#[test]
fn broken_shaders_are_rejected() {
    let Some(device) = device() else { return };
    let options = LightOptions {
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    let light = EnvironmentLight::new(sun_sky(64, 32), options).unwrap();
    let tables = light.gpu_tables(&GpuTableOptions::default()).unwrap();
    // Every pdf of the piecewise-constant density (the light's) 1% too large.
    let scaled = broken(
        "    return pdf_constant(uv);",
        "    return pdf_constant(uv) * 1.01;",
    );
    let flipped = broken(
        "return vec3<f32>(sin_theta * phi.y, sin_theta * phi.x, theta.y);",
        "return vec3<f32>(sin_theta * phi.y, -sin_theta * phi.x, theta.y);",
    );
    let config = Config {
        chi2_samples: 200_000,
        max_bins: 4_000,
        consistency_samples: 50_000,
        mc_samples: 200_000,
        ..Config::SYNTHETIC
    };
    for (name, wgsl) in [("pdf × 1.01", scaled), ("y flipped", flipped)] {
        let gpu = GpuLight::from_tables(device, &tables, &wgsl).unwrap();
        let s = sample_agreement(&gpu, &light);
        println!("[{name}] sample: {s}");
        assert!(
            !s.passes(),
            "[{name}] the row comparison accepted a broken shader: {s}"
        );
        let sampler = GpuSphereSampler::new(&gpu, SphereSampler::grid(&light).unwrap());
        let report = envlight_verify::run(&sampler, &Integrand::luminance(), &config, &|_| {});
        let failures = report.failures();
        println!("[{name}] harness failures: {failures:?}");
        assert!(
            !failures.is_empty(),
            "[{name}] the harness accepted a broken shader"
        );
    }
}

/// Orientation, independently of the CPU light: on a map whose texel (i, j) holds
/// `[i, j, 1]`, the GPU's radiance at each texel's centre direction (from the
/// harness's own mappings, docs/design.md §2 and the equal-area square) is that texel,
/// rotation included; and the GPU draws its samples where the map is bright.
#[test]
fn directions_point_where_the_conventions_say() {
    let Some(device) = device() else { return };
    let (w, h) = (24usize, 12usize);
    let coded = EnvImage::from_fn(w, h, |x, y| [x as f32, y as f32, 1.0]).unwrap();
    for (mapping, rotate) in [
        (Mapping::Equirectangular, 0.0f32),
        (Mapping::Equirectangular, 90.0),
        (Mapping::EqualArea, 0.0),
    ] {
        let (image, size) = match mapping {
            Mapping::Equirectangular => (coded.clone(), [w, h]),
            Mapping::EqualArea => (
                EnvImage::from_fn(16, 16, |x, y| [x as f32, y as f32, 1.0]).unwrap(),
                [16, 16],
            ),
        };
        let o = LightOptions {
            mapping,
            input_mapping: mapping,
            lookup: Lookup::Nearest,
            rotation: Rotation::about_z_degrees(rotate),
            ..Default::default()
        };
        let light = EnvironmentLight::new(image, o).unwrap();
        let gpu = GpuLight::new(device, &light).unwrap();
        let turn = rotate.to_radians() as f64;
        let mut dirs = Vec::new();
        let mut expected = Vec::new();
        for j in 0..size[1] {
            for i in 0..size[0] {
                let (u, v) = (
                    (i as f64 + 0.5) / size[0] as f64,
                    (j as f64 + 0.5) / size[1] as f64,
                );
                let d = match mapping {
                    Mapping::Equirectangular => envlight_verify::direction_at(u, v),
                    Mapping::EqualArea => envlight_verify::square_to_sphere(u, v),
                };
                // The light-to-world rotation about +z.
                let (s, c) = turn.sin_cos();
                let d = [c * d[0] - s * d[1], s * d[0] + c * d[1], d[2]];
                dirs.push(d.map(|x| x as f32));
                expected.push([i as f32, j as f32, 1.0]);
            }
        }
        let got = gpu.radiance(&dirs).unwrap();
        assert_eq!(got, expected, "{mapping:?}, rotated {rotate}°");
    }
    // Conventions by name: the top row looks up, u = 0 along +x, u = ¼ along +y.
    let light = EnvironmentLight::new(
        coded,
        LightOptions {
            lookup: Lookup::Nearest,
            ..Default::default()
        },
    )
    .unwrap();
    let gpu = GpuLight::new(device, &light).unwrap();
    let l = gpu
        .radiance(&[[0.0, 0.0, 1.0], [1.0, 0.01, 0.0], [-0.01, 1.0, 0.0]])
        .unwrap();
    assert_eq!(l[0][1], 0.0, "+z is the top row");
    assert_eq!(
        l[1],
        [0.0, (h / 2) as f32, 1.0],
        "+x is u = 0 on the equator"
    );
    assert_eq!(l[2][0], (w / 4) as f32, "+y is u = 1/4");
    // Samples go where the light is: a hot texel's direction.
    let light = EnvironmentLight::new(maps::hot(w, h, 7, 3), LightOptions::default()).unwrap();
    let gpu = GpuLight::new(device, &light).unwrap();
    let (_, hot) = light.brightest();
    let near = gpu
        .sample_seeded(1, 0, 4096)
        .unwrap()
        .iter()
        .filter(|s| s.is_valid() && envlight::Vec3::from(s.direction).dot(hot) > 0.9)
        .count();
    assert!(near > 4000, "{near} of 4096 samples near the hot texel");
}
