//! `--device gpu` end to end: the binary's GPU rows against its CPU rows (the same
//! seed, the same ξ), the harness on GPU output, `info` and `bench` reports, and
//! the errors (no adapter, combinations not ported).
//!
//! Without an adapter the GPU runs are skipped with one printed line naming the
//! package, unless `ENVLIGHT_REQUIRE_GPU` is set (CI sets it): then they fail.

use std::path::{Path, PathBuf};

use envlight_gpu::agreement::{compare, Agreement, Row};
use tempfile::TempDir;

mod common;
use common::{envlight, stdout_of};

/// True when the binary finds a GPU adapter; otherwise prints why (or fails, when
/// `ENVLIGHT_REQUIRE_GPU` is set).
fn has_gpu() -> bool {
    let out = envlight()
        .args(["info", "--device", "gpu", "--json"])
        .output()
        .unwrap();
    if out.status.success() {
        return true;
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        std::env::var_os("ENVLIGHT_REQUIRE_GPU").is_none(),
        "ENVLIGHT_REQUIRE_GPU is set but `info --device gpu` failed: {stderr}"
    );
    assert!(stderr.contains("no GPU adapter"), "{stderr}");
    println!("skipping GPU runs: no GPU adapter (apt-get install mesa-vulkan-drivers)");
    false
}

fn run(args: &[&str]) -> String {
    stdout_of(envlight().args(args))
}

fn rows(csv: &str) -> Vec<Row> {
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some("x,y,z,pdf,r,g,b"));
    lines
        .map(|l| {
            let v: Vec<f32> = l.split(',').map(|f| f.parse().unwrap()).collect();
            assert_eq!(v.len(), 7, "{l}");
            Row {
                direction: [v[0], v[1], v[2]],
                pdf: v[3],
                radiance: [v[4], v[5], v[6]],
            }
        })
        .collect()
}

/// `sample` on both devices, then `eval` on both of the CPU's rows plus the poles
/// and the seam; both comparisons must pass.
fn assert_devices_agree(map: &str, options: &[&str], dir: &Path) -> (Agreement, Agreement) {
    let sample = |device: &str| {
        let mut args = vec![
            "sample", map, "-n", "20000", "--seed", "9", "--device", device,
        ];
        args.extend_from_slice(options);
        run(&args)
    };
    let cpu = sample("cpu");
    let gpu = sample("gpu");
    let s = compare(&rows(&cpu), &rows(&gpu));
    let mut dirs = cpu.clone();
    for extra in [
        "0,0,1",
        "0,0,-1",
        "1e-7,0,1",
        "1,0,0",
        "1,-0,0",
        "1,1e-7,0.2",
        "1,-1e-7,-0.2",
        "-1,0,0.5",
        "3,4,5",
    ] {
        dirs.push_str(extra);
        dirs.push('\n');
    }
    let path = dir.join("dirs.csv");
    std::fs::write(&path, dirs).unwrap();
    let eval = |device: &str| {
        let mut args = vec![
            "eval",
            map,
            "--dirs",
            path.to_str().unwrap(),
            "--device",
            device,
        ];
        args.extend_from_slice(options);
        run(&args)
    };
    let e = compare(&rows(&eval("cpu")), &rows(&eval("gpu")));
    println!("[{map} {options:?}] sample: {s}\n[{map} {options:?}] eval:   {e}");
    assert!(s.passes(), "[{map} {options:?}] sample rows: {s}");
    assert!(e.passes(), "[{map} {options:?}] eval rows: {e}");
    (s, e)
}

#[test]
fn sample_and_eval_rows_agree_with_the_cpu() {
    if !has_gpu() {
        return;
    }
    let dir = TempDir::new().unwrap();
    for options in [
        &[][..],
        &["--sampler", "alias"],
        &["--density", "piecewise-bilinear"],
        &["--mapping", "equal-area", "--lookup", "nearest"],
        &["--rotate", "33", "--scale", "2"],
    ] {
        assert_devices_agree("builtin:sky", options, dir.path());
    }
}

#[test]
fn real_maps_agree() {
    if !has_gpu() {
        return;
    }
    let maps = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    if !maps.is_dir() {
        println!("skipping real maps: {} not found", maps.display());
        return;
    }
    let dir = TempDir::new().unwrap();
    for file in ["sunrise.exr", "courtyard.exr", "studio.exr", "night.exr"] {
        let path: PathBuf = maps.join(file);
        assert_devices_agree(path.to_str().unwrap(), &[], dir.path());
    }
}

#[test]
fn verify_runs_the_harness_on_gpu_output() {
    if !has_gpu() {
        return;
    }
    let out = run(&[
        "verify",
        "builtin:sky",
        "--device",
        "gpu",
        "--samples",
        "100000",
    ]);
    assert!(out.contains("all checks passed"), "{out}");
    assert!(out.contains("the gpu sampler has no inverse"), "{out}");
}

#[test]
fn info_names_the_adapter_and_measures_agreement() {
    if !has_gpu() {
        return;
    }
    let out = run(&["info", "--device", "gpu", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["device"], "gpu");
    for key in ["adapter", "backend", "device_type", "driver"] {
        assert!(
            v[key].as_str().is_some_and(|s| !s.is_empty()),
            "{key}: {out}"
        );
    }
    for key in ["gpu_sample_agreement", "gpu_eval_agreement"] {
        assert!(v[key].as_f64().unwrap() >= 0.999, "{key}: {out}");
    }
    assert!(v["device_bytes"].as_u64().unwrap() > 0);
}

#[test]
fn bench_reports_upload_kernel_and_read_back() {
    if !has_gpu() {
        return;
    }
    let out = run(&[
        "bench",
        "--device",
        "gpu",
        "--json",
        "--queries",
        "65536",
        "--repeat",
        "1",
    ]);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["device"], "gpu");
    for query in ["sample", "sample_seeded", "pdf", "radiance"] {
        for key in [
            "upload_ms",
            "kernel_ms",
            "readback_ms",
            "kernel_per_s",
            "round_trip_per_s",
        ] {
            let x = v[query][key].as_f64();
            assert!(x.is_some_and(|x| x >= 0.0), "{query}.{key}: {out}");
        }
        assert!(v[query]["kernel_per_s"].as_f64().unwrap() > 0.0);
    }
}

/// One `error:` line containing `needle`, the given exit status, no panic.
fn assert_fails(args: &[&str], envs: &[(&str, &str)], code: i32, needle: &str) {
    let mut cmd = envlight();
    cmd.args(args);
    for (k, v) in envs {
        cmd.env(k, v);
    }
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}: {stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(
        lines[0].starts_with("error: ") && lines[0].contains(needle),
        "{stderr}"
    );
    assert!(
        out.stdout.is_empty(),
        "{args:?} wrote to stdout before failing"
    );
}

#[test]
fn no_adapter_is_one_error_line_naming_the_package() {
    // A backend this machine cannot have, and a Vulkan loader pointed at no driver.
    for envs in [
        &[("WGPU_BACKEND", "metal")][..],
        &[
            ("WGPU_BACKEND", "vulkan"),
            ("VK_ICD_FILENAMES", "/nonexistent.json"),
        ],
        &[("WGPU_ADAPTER_NAME", "no such adapter 7f3a")],
    ] {
        for args in [
            &["sample", "-n", "3", "--device", "gpu"][..],
            &["info", "--device", "gpu"],
            &["verify", "--device", "gpu"],
        ] {
            assert_fails(args, envs, 1, "no GPU adapter");
            assert_fails(args, envs, 1, "mesa-vulkan-drivers");
        }
    }
}

#[test]
fn combinations_not_ported_are_usage_errors() {
    assert_fails(
        &[
            "sample",
            "-n",
            "3",
            "--device",
            "gpu",
            "--sampler",
            "hierarchical",
        ],
        &[],
        2,
        "not ported to the GPU",
    );
    assert_fails(
        &["sample", "-n", "3", "--device", "gpu", "--normal", "0,0,1"],
        &[],
        2,
        "not ported to the GPU",
    );
}

#[test]
fn an_existing_output_survives_a_gpu_failure() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("keep.csv");
    std::fs::write(&path, "precious").unwrap();
    let out = envlight()
        .args(["sample", "-n", "3", "--device", "gpu", "-o"])
        .arg(&path)
        .env("WGPU_BACKEND", "metal")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "precious");
}
