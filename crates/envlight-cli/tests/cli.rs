//! Integration tests: run the real `envlight` binary on the builtin sky, small
//! synthetic PFM maps written here, and (when present) the real maps in
//! `shared/envmaps`, through every subcommand and error path.

use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::Stdio;

use assert_cmd::Command;
use predicates::prelude::*;
use tempfile::TempDir;

mod common;
use common::{envlight, importance, parse_rows, stdout_of, write_pfm, HEADER};

/// A small map with structure: a warm hot spot, a blue sky gradient, dark ground.
fn test_map(x: usize, y: usize) -> [f32; 3] {
    if (x, y) == (5, 2) {
        [40.0, 30.0, 20.0]
    } else if y < 4 {
        [0.2 + 0.05 * x as f32, 0.3, 0.6 + 0.1 * y as f32]
    } else {
        [0.05, 0.04, 0.03 * (1 + x % 3) as f32]
    }
}

/// A temporary directory holding `map.pfm` (16×8, [`test_map`]).
fn pfm_dir() -> (TempDir, PathBuf) {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("map.pfm");
    write_pfm(&path, 16, 8, test_map);
    (dir, path)
}

/// `shared/envmaps` beside the workspace, when it is there.
fn envmaps() -> Option<PathBuf> {
    envlight_verify::maps::shared_envmaps()
}

/// The names of the entries of `dir` (to see that no temporary file was left).
fn file_names(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect()
}

/// An error run: exit 1, stderr one line starting `error:` containing `needle`,
/// and no panic.
fn assert_error(cmd: &mut Command, needle: &str) -> String {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("warning:"))
        .collect();
    assert_eq!(errors.len(), 1, "stderr: {stderr}");
    assert!(errors[0].starts_with("error: "), "stderr: {stderr}");
    assert!(
        errors[0].contains(needle),
        "expected {needle:?} in: {stderr}"
    );
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
    stderr
}

// ---------------------------------------------------------------- info

#[test]
fn info_readable_on_builtin_sky() {
    let text = stdout_of(envlight().arg("info"));
    assert!(text.contains("builtin:sky"), "{text}");
    assert!(text.contains("1024 x 512"), "{text}");
    assert!(text.contains("efficiency"), "{text}");
}

const REQUIRED_KEYS: [&str; 9] = [
    "width",
    "height",
    "format",
    "integral_rgb",
    "integral_luminance",
    "max_luminance",
    "brightest_direction",
    "efficiency",
    "build_ms",
];

fn info_json(args: &[&str]) -> serde_json::Value {
    let text = stdout_of(envlight().arg("info").arg("--json").args(args));
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    for key in REQUIRED_KEYS {
        assert!(v.get(key).is_some(), "missing {key} in {text}");
    }
    assert_eq!(v["integral_rgb"].as_array().unwrap().len(), 3);
    assert_eq!(v["brightest_direction"].as_array().unwrap().len(), 3);
    v
}

#[test]
fn info_json_on_builtin_sky() {
    let v = info_json(&["builtin:sky"]);
    assert_eq!(v["format"], "builtin");
    assert_eq!(v["width"], 1024);
    assert_eq!(v["height"], 512);
    assert_eq!(v["sampler"], "inversion");
    let e = v["efficiency"].as_f64().unwrap();
    assert!(e > 0.5 && e <= 1.0, "{e}");
    // The builtin sun is 35° above the horizon.
    let z = v["brightest_direction"][2].as_f64().unwrap();
    assert!((z - 35f64.to_radians().sin()).abs() < 0.02, "{z}");
}

/// Without `--density`, the light takes the piecewise-bilinear density with the
/// inversion sampler at full size, and the piecewise-constant one (the only one
/// they take) with the other samplers and `--table-size`; an explicit bilinear
/// density with them stays a usage error.
#[test]
fn the_default_density_follows_the_sampler() {
    let density = |args: &[&str]| info_json(args)["density"].as_str().unwrap().to_owned();
    assert_eq!(density(&[]), "piecewise-bilinear");
    assert_eq!(density(&["--sampler", "alias"]), "piecewise-constant");
    assert_eq!(
        density(&["--sampler", "hierarchical"]),
        "piecewise-constant"
    );
    assert_eq!(density(&["--table-size", "512"]), "piecewise-constant");
    assert_eq!(
        density(&["--density", "piecewise-constant"]),
        "piecewise-constant"
    );
    let out = envlight()
        .args([
            "info",
            "--sampler",
            "alias",
            "--density",
            "piecewise-bilinear",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--density piecewise-bilinear"));
}

/// `--table-size`: info reports the table and what it costs; a width that does
/// not divide the map, zero, and the bilinear density are usage errors (exit 2)
/// naming the option; sampling works with a reduced table.
#[test]
fn table_size_is_reported_and_checked() {
    let v = info_json(&["--table-size", "256"]);
    assert_eq!(
        (v["table_width"].as_u64(), v["table_height"].as_u64()),
        (Some(256), Some(128))
    );
    let (own, full) = (
        v["efficiency"].as_f64().unwrap(),
        v["full_table_efficiency"].as_f64().unwrap(),
    );
    assert!(0.0 < own && own < full && full <= 1.0, "{own} {full}");
    let plain = info_json(&["--density", "piecewise-constant"]);
    assert!(plain["full_table_efficiency"].is_null());
    assert_eq!(plain["table_width"].as_u64(), Some(1024));
    assert!((plain["efficiency"].as_f64().unwrap() - full).abs() < 1e-6);
    let text = stdout_of(envlight().args(["info", "--table-size", "512"]));
    assert!(
        text.contains("512 x 256 cells") && text.contains("with the full table"),
        "{text}"
    );
    for (args, needle) in [
        (
            &["--table-size", "300"][..],
            "widths that do are 1024, 512, 256",
        ),
        (&["--table-size", "0"][..], "--table-size"),
        (
            &["--table-size", "256", "--density", "piecewise-bilinear"][..],
            "--table-size",
        ),
    ] {
        let out = envlight().arg("info").args(args).output().unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(needle), "{args:?}: {stderr}");
    }
    envlight()
        .args([
            "sample",
            "-n",
            "5",
            "--table-size",
            "64",
            "--sampler",
            "alias",
        ])
        .assert()
        .success();
}

#[test]
fn info_json_on_pfm_and_rotation_moves_the_brightest_direction() {
    let (_dir, map) = pfm_dir();
    let m = map.to_str().unwrap();
    let v = info_json(&[m]);
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(16), Some(8))
    );
    assert_eq!(v["format"], "pfm");
    assert_eq!(
        v["max_luminance"].as_f64().unwrap() as f32,
        0.212671 * 40.0 + 0.715160 * 30.0 + 0.072169 * 20.0
    );
    let r = info_json(&[m, "--rotate", "90", "--scale", "2"]);
    let d = |v: &serde_json::Value| -> Vec<f64> {
        v["brightest_direction"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_f64().unwrap())
            .collect()
    };
    let (a, b) = (d(&v), d(&r));
    // +90° about z: (x, y, z) -> (-y, x, z).
    assert!(
        (b[0] + a[1]).abs() < 1e-5 && (b[1] - a[0]).abs() < 1e-5 && (b[2] - a[2]).abs() < 1e-6,
        "{a:?} {b:?}"
    );
    let (i1, i2) = (
        v["integral_luminance"].as_f64().unwrap(),
        r["integral_luminance"].as_f64().unwrap(),
    );
    assert!((i2 / i1 - 2.0).abs() < 1e-9);
    // The scale leaves the efficiency alone.
    assert!((v["efficiency"].as_f64().unwrap() - r["efficiency"].as_f64().unwrap()).abs() < 1e-9);
}

#[test]
fn info_json_on_every_real_map() {
    let Some(dir) = envmaps() else { return };
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
        if !["hdr", "exr"].contains(&ext) {
            continue;
        }
        let v = info_json(&[path.to_str().unwrap()]);
        assert_eq!(v["format"], ext, "{}", path.display());
        assert_eq!(
            v["width"].as_u64().unwrap(),
            2 * v["height"].as_u64().unwrap()
        );
        assert!(v["integral_luminance"].as_f64().unwrap() > 0.0);
        seen += 1;
    }
    assert!(seen >= 1);
}

// ---------------------------------------------------------------- sample

#[test]
fn sample_writes_the_exact_header_and_unit_directions() {
    let text = stdout_of(envlight().args(["sample", "-n", "1000"]));
    assert!(text.starts_with("x,y,z,pdf,r,g,b\n"));
    let rows = parse_rows(&text);
    assert_eq!(rows.len(), 1000);
    for r in rows {
        let len = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-6, "{r:?}");
        assert!(r[3] > 0.0 && r[3].is_finite(), "{r:?}");
        assert!(r[4..].iter().all(|c| *c >= 0.0 && c.is_finite()), "{r:?}");
    }
}

#[test]
fn sample_zero_rows_is_just_the_header() {
    let text = stdout_of(envlight().args(["sample", "-n", "0"]));
    assert_eq!(text, "x,y,z,pdf,r,g,b\n");
}

#[test]
fn sample_is_deterministic_and_independent_of_thread_count() {
    let (_dir, map) = pfm_dir();
    // More rows than one formatting chunk, so several tasks share the work.
    let args = [
        "sample",
        map.to_str().unwrap(),
        "-n",
        "30000",
        "--seed",
        "7",
    ];
    let run = |threads: Option<&str>| {
        let mut cmd = envlight();
        cmd.args(args);
        match threads {
            Some(t) => cmd.env("RAYON_NUM_THREADS", t),
            None => cmd.env_remove("RAYON_NUM_THREADS"),
        };
        cmd.output().unwrap().stdout
    };
    let a = run(None);
    assert!(a.len() > 30000 * 20);
    assert_eq!(a, run(None));
    assert_eq!(a, run(Some("1")));
    assert_eq!(a, run(Some("3")));
    let other =
        stdout_of(envlight().args(["sample", map.to_str().unwrap(), "-n", "100", "--seed", "8"]));
    assert_ne!(&a[..other.len()], other.as_bytes());
}

#[test]
fn sample_to_a_file_equals_stdout() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("s.csv");
    let to_stdout = stdout_of(envlight().args(["sample", "-n", "500", "--seed", "3"]));
    envlight()
        .args(["sample", "-n", "500", "--seed", "3", "-o"])
        .arg(&out)
        .assert()
        .success()
        .stdout("");
    assert_eq!(std::fs::read_to_string(&out).unwrap(), to_stdout);
    // Only the output itself is left in the directory (no temporary file).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn sample_follows_the_hot_spot() {
    let (_dir, map) = pfm_dir();
    let rows = parse_rows(&stdout_of(
        envlight().arg("sample").arg(&map).args(["-n", "4000"]),
    ));
    // Texel (5, 2) of 16×8: u in [5/16, 6/16), v in [2/8, 3/8).
    let hot = rows
        .iter()
        .filter(|r| {
            let theta = r[2].acos() / std::f64::consts::PI;
            let phi = r[1].atan2(r[0]).rem_euclid(2.0 * std::f64::consts::PI)
                / (2.0 * std::f64::consts::PI);
            (0.25..0.375).contains(&theta) && (5.0 / 16.0..6.0 / 16.0).contains(&phi)
        })
        .count();
    assert!(hot > 1000, "{hot} of 4000 samples near the hot texel");
}

#[test]
fn sample_sampler_names_are_checked() {
    for sampler in ["inversion", "alias", "hierarchical"] {
        envlight()
            .args(["sample", "-n", "3", "--sampler", sampler])
            .assert()
            .success();
    }
    envlight()
        .args(["sample", "-n", "3", "--sampler", "rejection"])
        .assert()
        .code(2)
        .stderr(
            predicate::str::contains("inversion")
                .and(predicate::str::contains("alias"))
                .and(predicate::str::contains("hierarchical")),
        );
    for (option, value) in [
        ("--density", "piecewise-cubic"),
        ("--mapping", "cube"),
        ("--input-mapping", "cube"),
        ("--equal-area-size", "0"),
    ] {
        envlight()
            .args(["sample", "-n", "3", option, value])
            .assert()
            .code(2);
    }
}

#[test]
fn sample_round_trips_through_eval() {
    let (dir, map) = pfm_dir();
    for (m, extra) in [
        (
            map.to_str().unwrap(),
            vec!["--rotate", "33.5", "--scale", "0.5"],
        ),
        (map.to_str().unwrap(), vec!["--lookup", "nearest"]),
        ("builtin:sky", vec![]),
    ] {
        let samples = dir.path().join("samples.csv");
        envlight()
            .args(["sample", m, "-n", "5000", "--seed", "11", "-o"])
            .arg(&samples)
            .args(&extra)
            .assert()
            .success();
        let evaluated = stdout_of(
            envlight()
                .args(["eval", m, "--dirs"])
                .arg(&samples)
                .args(&extra),
        );
        let a = parse_rows(&std::fs::read_to_string(&samples).unwrap());
        let b = parse_rows(&evaluated);
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(&b) {
            for k in 0..7 {
                let tol = 1e-5 * x[k].abs().max(1e-30);
                assert!((x[k] - y[k]).abs() <= tol, "{m} {extra:?}: {x:?} vs {y:?}");
            }
        }
        // In fact bit-identical: every value is a function of the written direction.
        assert_eq!(std::fs::read_to_string(&samples).unwrap(), evaluated);
    }
}

// ---------------------------------------------------------------- eval

#[test]
fn eval_reads_columns_in_any_order_and_normalises() {
    let input = "id, z ,note,y,X\n1, 2, up,0,0\n\n2,0,\"side\", 0 ,\"-3\"\n3,1e-30,x,1e-30,0\r\n";
    let out = stdout_of(envlight().args(["eval", "--dirs", "-"]).write_stdin(input));
    let rows = parse_rows(&out);
    assert_eq!(rows.len(), 3);
    assert_eq!(&rows[0][..3], &[0.0, 0.0, 1.0]);
    assert_eq!(&rows[1][..3], &[-1.0, 0.0, 0.0]);
    let s = std::f64::consts::FRAC_1_SQRT_2;
    assert!(
        (rows[2][1] - s).abs() < 1e-7 && (rows[2][2] - s).abs() < 1e-7,
        "{:?}",
        rows[2]
    );
    // +z: the zenith of the builtin sky is blue; exactly on the pole the density is
    // 0 (a set of measure zero where the equirectangular Jacobian vanishes).
    assert!(rows[0][6] > rows[0][4], "{:?}", rows[0]);
    assert_eq!(rows[0][3], 0.0);
    assert!(rows[1][3] > 0.0 && rows[2][3] > 0.0);
}

#[test]
fn eval_agrees_with_sample_on_a_file() {
    let (dir, map) = pfm_dir();
    let dirs = dir.path().join("dirs.csv");
    std::fs::write(&dirs, "x,y,z\n0.3,0.2,0.9\n-1,-1,-1\n").unwrap();
    let out = stdout_of(envlight().arg("eval").arg(&map).arg("--dirs").arg(&dirs));
    let rows = parse_rows(&out);
    assert_eq!(rows.len(), 2);
    assert!(rows.iter().all(|r| r[3] > 0.0 && r[4] > 0.0));
}

#[test]
fn eval_errors_name_the_line() {
    let dir = TempDir::new().unwrap();
    let dirs = dir.path().join("dirs.csv");
    for (input, needle) in [
        (
            "x,y,z\n1,0,0\n0,1,0\n0,0,0\n",
            "dirs.csv:4: direction (0, 0, 0) has zero length",
        ),
        ("x,y,z\n1,0,0\n0,1\n", "dirs.csv:3: missing field z"),
        (
            "x,y,z\n1,0,0\n1,abc,0\n",
            "dirs.csv:3: field y is not a number",
        ),
        ("x,y,z\n1,0,nan\n", "dirs.csv:2: field z is not finite"),
        ("x,y,z\ninf,0,0\n", "dirs.csv:2: field x is not finite"),
        ("x,y,z\n1,,0\n", "dirs.csv:2: field y is empty"),
        ("x,y,w\n1,0,0\n", "dirs.csv:1: header has no column named z"),
        (
            "x,y,z,x\n1,0,0,1\n",
            "dirs.csv:1: header names column x twice",
        ),
        ("", "dirs.csv: empty input"),
    ] {
        std::fs::write(&dirs, input).unwrap();
        assert_error(envlight().arg("eval").arg("--dirs").arg(&dirs), needle);
    }
    // From stdin the source is called <stdin>.
    assert_error(
        envlight()
            .args(["eval", "--dirs", "-"])
            .write_stdin("x,y,z\n0,0,0\n"),
        "<stdin>:2: direction (0, 0, 0) has zero length",
    );
}

#[test]
fn eval_streams_many_rows_in_order() {
    // More rows than one batch of the streaming reader.
    let n = 70_000;
    let mut input = String::from("x,y,z\n");
    for k in 0..n {
        let a = k as f64 * 0.001;
        input.push_str(&format!(
            "{},{},{}\n",
            a.cos(),
            a.sin(),
            (k % 7) as f64 * 0.1 - 0.3
        ));
    }
    let out = stdout_of(envlight().args(["eval", "--dirs", "-"]).write_stdin(input));
    let rows = parse_rows(&out);
    assert_eq!(rows.len(), n);
    for (k, r) in rows.iter().enumerate().step_by(997) {
        let a = k as f64 * 0.001;
        let z = (k % 7) as f64 * 0.1 - 0.3;
        let len = (1.0 + z * z).sqrt();
        assert!(
            (r[0] - a.cos() / len).abs() < 1e-6 && (r[2] - z / len).abs() < 1e-6,
            "row {k}: {r:?}"
        );
    }
}

// ---------------------------------------------------------------- importance

fn check_png(path: &Path, min_width: u32) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let img = image::load_from_memory(&bytes).unwrap();
    assert!(
        img.width() >= min_width && img.height() >= min_width / 2,
        "{}x{}",
        img.width(),
        img.height()
    );
}

#[test]
fn importance_writes_a_png_on_builtin_sky() {
    let dir = TempDir::new().unwrap();
    let png = dir.path().join("imp.png");
    importance(&["--samples", "300", "--width", "256"], &png);
    check_png(&png, 256);
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
}

#[test]
fn importance_upsamples_a_tiny_pfm_and_rotates() {
    let (dir, map) = pfm_dir();
    let png = dir.path().join("imp.png");
    let m = map.to_str().unwrap();
    importance(
        &[m, "--samples", "50", "--width", "128", "--rotate", "-45"],
        &png,
    );
    check_png(&png, 128);
}

#[test]
fn importance_needs_an_output_and_a_sane_width() {
    envlight().arg("importance").assert().code(2);
    envlight()
        .args(["importance", "-o", "x.png", "--width", "3"])
        .assert()
        .code(2);
}

// ---------------------------------------------------------------- verify

fn verify(args: &[&str]) -> (i32, String) {
    let out = envlight().arg("verify").args(args).output().unwrap();
    let stdout = String::from_utf8(out.stdout).unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    (out.status.code().unwrap(), stdout)
}

/// `envlight verify ARGS` passes (exit 0); its table.
fn verify_passes(args: &[&str]) -> String {
    let (code, table) = verify(args);
    assert_eq!(code, 0, "{args:?}\n{table}");
    table
}

#[test]
fn verify_passes_on_builtin_sky() {
    let table = verify_passes(&["--samples", "40000", "--seed", "1"]);
    let header: Vec<&str> = table
        .lines()
        .next()
        .unwrap()
        .split('|')
        .map(str::trim)
        .collect();
    assert_eq!(header, ["check", "value", "threshold", "result"]);
    // The rows, in order, are the library harness's (the names are a contract).
    let names: Vec<&str> = table
        .lines()
        .skip(2)
        .take(envlight_verify::CHECKS.len())
        .map(|l| l.split('|').next().unwrap().trim())
        .collect();
    assert_eq!(names, envlight_verify::CHECKS);
    for check in envlight_verify::CHECKS {
        let row = table
            .lines()
            .find(|l| l.starts_with(check))
            .unwrap_or_else(|| panic!("no {check} row in {table}"));
        let result = row.rsplit('|').next().unwrap().trim();
        assert!(
            result == "pass" || (check == "efficiency" && result == "info"),
            "{row}"
        );
    }
    assert!(table.contains("all checks passed"), "{table}");
}

#[test]
fn verify_passes_on_small_pfm_with_options() {
    verify_passes_on_pfm_with_each(
        &["--samples", "20000"],
        &[
            &[],
            &["--lookup", "nearest"],
            &["--rotate", "100", "--scale", "3"],
        ],
    );
}

/// `verify` passes on [`pfm_dir`]'s map with `args` and each of `option_sets` in
/// turn; the tables.
fn verify_passes_on_pfm_with_each(args: &[&str], option_sets: &[&[&str]]) -> Vec<String> {
    let (_dir, map) = pfm_dir();
    let m = map.to_str().unwrap();
    option_sets
        .iter()
        .map(|options| verify_passes(&[&[m][..], args, options].concat()))
        .collect()
}

#[test]
fn verify_passes_on_a_real_map() {
    let Some(dir) = envmaps() else { return };
    let map = dir.join("sunrise.exr");
    if !map.exists() {
        eprintln!("skipped: {} not found", map.display());
        return;
    }
    verify_passes(&[map.to_str().unwrap(), "--samples", "50000"]);
}

// ---------------------------------------------------------------- combinations

const SAMPLERS: [&str; 3] = ["inversion", "alias", "hierarchical"];
const DENSITIES: [&str; 2] = ["piecewise-constant", "piecewise-bilinear"];
const MAPPINGS: [&str; 2] = ["equirectangular", "equal-area"];

/// Whether the library supports the sampler with the density.
fn supported(sampler: &str, density: &str) -> bool {
    density != "piecewise-bilinear" || sampler == "inversion"
}

/// The options that choose the sampler, the density and the mapping.
fn light_options<'a>(sampler: &'a str, density: &'a str, mapping: &'a str) -> [&'a str; 6] {
    [
        "--sampler",
        sampler,
        "--density",
        density,
        "--mapping",
        mapping,
    ]
}

/// Every option combination on `map`: `info --json` reports it, `sample` is
/// deterministic across thread counts and round-trips through `eval`
/// bit-identically, and `verify` passes (the invert check skipped for alias only).
/// Unsupported combinations are usage errors naming both options.
fn every_combination(map: &str, input: &[&str], width: u64, height: u64, dir: &Path) {
    for mapping in MAPPINGS {
        if input.contains(&"equal-area") && mapping == "equirectangular" {
            continue;
        }
        for sampler in SAMPLERS {
            for density in DENSITIES {
                let mut options = light_options(sampler, density, mapping).to_vec();
                options.extend_from_slice(input);
                let what = format!("{map} {options:?}");
                if !supported(sampler, density) {
                    for cmd in ["info", "sample", "verify"] {
                        let count: &[&str] = if cmd == "sample" { &["-n", "10"] } else { &[] };
                        let out = envlight()
                            .args([cmd, map])
                            .args(count)
                            .args(&options)
                            .output()
                            .unwrap();
                        let stderr = String::from_utf8_lossy(&out.stderr);
                        assert_eq!(out.status.code(), Some(2), "{cmd} {what}: {stderr}");
                        assert!(out.stdout.is_empty(), "{cmd} {what}");
                        assert!(
                            stderr.starts_with("error: ")
                                && stderr.contains(&format!("--density {density}"))
                                && stderr.contains(&format!("--sampler {sampler}"))
                                && stderr.contains("not supported"),
                            "{cmd} {what}: {stderr}"
                        );
                    }
                    continue;
                }

                let mut args = vec![map];
                args.extend_from_slice(&options);
                let v = info_json(&args);
                assert_eq!(v["sampler"], sampler, "{what}");
                assert_eq!(v["density"], density, "{what}");
                assert_eq!(v["mapping"], mapping, "{what}");
                let input_mapping = if input.contains(&"equal-area") {
                    "equal-area"
                } else {
                    "equirectangular"
                };
                assert_eq!(v["input_mapping"], input_mapping, "{what}");
                assert_eq!(
                    (v["width"].as_u64(), v["height"].as_u64()),
                    (Some(width), Some(height)),
                    "{what}"
                );
                let (lw, lh) = (
                    v["light_width"].as_u64().unwrap(),
                    v["light_height"].as_u64().unwrap(),
                );
                if mapping == "equal-area" {
                    assert_eq!(lw, lh, "{what}");
                } else {
                    assert_eq!((lw, lh), (width, height), "{what}");
                }
                let e = v["efficiency"].as_f64().unwrap();
                assert!(e > 0.3 && e <= 1.0 + 1e-9, "{what}: efficiency {e}");

                let samples = dir.join("samples.csv");
                let run = |threads: &str| {
                    envlight()
                        .args(["sample", map, "-n", "3000", "--seed", "5", "-o"])
                        .arg(&samples)
                        .args(&options)
                        .env("RAYON_NUM_THREADS", threads)
                        .assert()
                        .success();
                    std::fs::read_to_string(&samples).unwrap()
                };
                let written = run("1");
                assert_eq!(written, run("3"), "{what}: depends on the thread count");
                let rows = parse_rows(&written);
                assert_eq!(rows.len(), 3000);
                assert!(rows.iter().all(|r| r[3] > 0.0), "{what}: a row with pdf 0");
                let evaluated = stdout_of(
                    envlight()
                        .args(["eval", map, "--dirs"])
                        .arg(&samples)
                        .args(&options),
                );
                assert_eq!(written, evaluated, "{what}: eval differs from sample");

                let mut args = vec![map, "--samples", "20000", "--seed", "3"];
                args.extend_from_slice(&options);
                let table = verify_passes(&args);
                let invert = table.lines().find(|l| l.starts_with("invert")).unwrap();
                let result = invert.rsplit('|').next().unwrap().trim();
                if sampler == "alias" {
                    assert_eq!(result, "skip", "{what}: {invert}");
                    assert!(invert.contains("n/a"), "{what}: {invert}");
                } else {
                    assert_eq!(result, "pass", "{what}: {invert}");
                }
            }
        }
    }
}

#[test]
fn every_combination_works_on_a_lat_long_map() {
    let dir = TempDir::new().unwrap();
    let map = dir.path().join("map.pfm");
    write_pfm(&map, 32, 16, |x, y| test_map(x / 2, y / 2));
    every_combination(map.to_str().unwrap(), &[], 32, 16, dir.path());
}

/// A small equal-area square: a bright patch in the upper hemisphere (the
/// square's centre is +z), a dimmer ring, dark corners (the lower hemisphere).
fn equal_area_map(x: usize, y: usize) -> [f32; 3] {
    let (a, b) = ((x as f32 + 0.5) / 8.0 - 1.0, (y as f32 + 0.5) / 8.0 - 1.0);
    if (x, y) == (10, 5) {
        [50.0, 40.0, 30.0]
    } else if a.abs() + b.abs() < 1.0 {
        [0.3 + 0.1 * a, 0.4, 0.8 + 0.2 * b]
    } else {
        [0.02, 0.03 + 0.01 * (x % 2) as f32, 0.02]
    }
}

#[test]
fn every_combination_works_on_an_equal_area_map() {
    let dir = TempDir::new().unwrap();
    let map = dir.path().join("square.pfm");
    write_pfm(&map, 16, 16, equal_area_map);
    every_combination(
        map.to_str().unwrap(),
        &["--input-mapping", "equal-area"],
        16,
        16,
        dir.path(),
    );
}

#[test]
fn an_equal_area_input_is_read_as_one() {
    let dir = TempDir::new().unwrap();
    let map = dir.path().join("square.pfm");
    write_pfm(&map, 16, 16, equal_area_map);
    let m = map.to_str().unwrap();
    // --mapping follows --input-mapping by default.
    let v = info_json(&[m, "--input-mapping", "equal-area"]);
    assert_eq!(v["mapping"], "equal-area");
    assert_eq!(v["input_mapping"], "equal-area");
    assert_eq!(
        (v["light_width"].as_u64(), v["light_height"].as_u64()),
        (Some(16), Some(16))
    );
    // The brightest texel's centre, through the equal-area mapping (PBRT-v4's).
    let d: Vec<f32> = v["brightest_direction"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap() as f32)
        .collect();
    let want = envlight::equal_area::square_to_sphere(10.5 / 16.0, 5.5 / 16.0);
    assert!(
        (d[0] - want.x).abs() < 1e-6
            && (d[1] - want.y).abs() < 1e-6
            && (d[2] - want.z).abs() < 1e-6,
        "{d:?} vs {want:?}"
    );
    // The samples crowd around that direction.
    let rows = parse_rows(&stdout_of(envlight().args([
        "sample",
        m,
        "--input-mapping",
        "equal-area",
        "-n",
        "4000",
    ])));
    let near = rows
        .iter()
        .filter(|r| (r[0] * want.x as f64 + r[1] * want.y as f64 + r[2] * want.z as f64) > 0.95)
        .count();
    // The hot texel holds about 40% of the power; the 18° cone 2.5% of the sphere.
    assert!(near > 1400, "{near} of 4000 samples near the hot texel");
    // Read as a lat-long map instead (the default), the same file is another light.
    let latlong = info_json(&[m]);
    assert_eq!(latlong["input_mapping"], "equirectangular");
    assert_ne!(latlong["brightest_direction"], v["brightest_direction"]);
}

#[test]
fn unsupported_combinations_are_usage_errors() {
    let dir = TempDir::new().unwrap();
    let square = dir.path().join("square.pfm");
    write_pfm(&square, 8, 8, |_, _| [1.0; 3]);
    let s = square.to_str().unwrap();
    let cases: [(&[&str], &[&str]); 3] = [
        (
            &["--sampler", "alias", "--density", "piecewise-bilinear"],
            &[
                "--density piecewise-bilinear",
                "--sampler alias",
                "inversion only",
            ],
        ),
        (
            &[
                "--sampler",
                "hierarchical",
                "--density",
                "piecewise-bilinear",
                "--mapping",
                "equal-area",
            ],
            &["--density piecewise-bilinear", "--sampler hierarchical"],
        ),
        (
            &[
                s,
                "--input-mapping",
                "equal-area",
                "--mapping",
                "equirectangular",
            ],
            &["--input-mapping equal-area", "--mapping equirectangular"],
        ),
    ];
    for (args, needles) in cases {
        let never = dir.path().join("never.png");
        for cmd in ["info", "verify", "importance", "bench", "render"] {
            let mut run = envlight();
            run.arg(cmd).args(args);
            if matches!(cmd, "importance" | "render") {
                run.arg("-o").arg(&never);
            }
            let out = run.output().unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert_eq!(out.status.code(), Some(2), "{cmd} {args:?}: {stderr}");
            assert!(out.stdout.is_empty(), "{cmd} {args:?}");
            let lines: Vec<&str> = stderr.lines().collect();
            assert_eq!(lines.len(), 1, "{cmd} {args:?}: {stderr}");
            assert!(lines[0].starts_with("error: "), "{stderr}");
            for needle in needles {
                assert!(
                    lines[0].contains(needle),
                    "{cmd} {args:?}: {needle:?} not in {stderr}"
                );
            }
        }
    }
    assert!(!dir.path().join("never.png").exists());
    // A lat-long file read as an equal-area square is bad input (exit 1), naming
    // the file and its size.
    let (_d, map) = pfm_dir();
    let stderr = assert_error(
        envlight().args([
            "info",
            map.to_str().unwrap(),
            "--input-mapping",
            "equal-area",
        ]),
        map.to_str().unwrap(),
    );
    assert!(
        stderr.contains("square") && stderr.contains("16x8"),
        "{stderr}"
    );
}

#[test]
fn equal_area_size_sets_the_resampled_square() {
    let v = info_json(&["--mapping", "equal-area", "--equal-area-size", "64"]);
    assert_eq!(
        (v["light_width"].as_u64(), v["light_height"].as_u64()),
        (Some(64), Some(64))
    );
    assert_eq!(
        (v["width"].as_u64(), v["height"].as_u64()),
        (Some(1024), Some(512))
    );
    // Without it, about the map's texel count.
    let v = info_json(&["--mapping", "equal-area"]);
    let side = v["light_width"].as_u64().unwrap();
    assert!(
        (side as f64 / (1024.0f64 * 512.0).sqrt() - 1.0).abs() < 0.01,
        "{side}"
    );
    // Squares beyond --max-texels are refused before any work.
    envlight()
        .args([
            "info",
            "--mapping",
            "equal-area",
            "--equal-area-size",
            "5000",
        ])
        .args(["--max-texels", "1000000"])
        .assert()
        .code(2)
        .stderr(predicate::str::contains("--equal-area-size 5000"));
    // Where nothing is resampled it has no effect, and says so.
    envlight()
        .args(["info", "--equal-area-size", "64"])
        .assert()
        .success()
        .stderr(predicate::str::contains(
            "warning: --equal-area-size 64 has no effect",
        ));
    let text =
        stdout_of(envlight().args(["info", "--mapping", "equal-area", "--equal-area-size", "64"]));
    assert!(
        text.contains("1024 x 512") && text.contains("64 x 64"),
        "{text}"
    );
}

#[test]
fn importance_and_bench_work_with_every_sampler_and_mapping() {
    let (dir, map) = pfm_dir();
    let m = map.to_str().unwrap();
    for mapping in MAPPINGS {
        let png = dir.path().join("imp.png");
        let args = [m, "--width", "128", "--samples", "30", "--mapping", mapping];
        importance(&args, &png);
        check_png(&png, 128);
        for sampler in SAMPLERS {
            for density in DENSITIES {
                if !supported(sampler, density) {
                    continue;
                }
                let out = stdout_of(
                    envlight()
                        .args(["bench", m, "--json", "--queries", "1024", "--repeat", "1"])
                        .args(light_options(sampler, density, mapping)),
                );
                let v: serde_json::Value = serde_json::from_str(&out).unwrap();
                for key in ["sample_ns", "pdf_ns", "build_ms", "bytes_per_texel"] {
                    let x = v[key].as_f64().unwrap_or(f64::NAN);
                    assert!(
                        x.is_finite() && x >= 0.0,
                        "{sampler} {density} {mapping}: {key} = {x}"
                    );
                }
            }
        }
    }
}

// ---------------------------------------------------------------- bad input

#[test]
fn missing_file_is_an_error_naming_it() {
    for cmd in ["info", "verify"] {
        assert_error(envlight().args([cmd, "no/such/map.exr"]), "no/such/map.exr");
    }
    assert_error(
        envlight().args(["sample", "no/such/map.hdr", "-n", "1"]),
        "no/such/map.hdr",
    );
    assert_error(
        envlight().args(["eval", "--dirs", "no/such/dirs.csv"]),
        "no/such/dirs.csv",
    );
    assert_error(envlight().args(["info", "builtin:nope"]), "builtin:nope");
}

#[test]
fn garbage_bytes_are_an_error_naming_the_file() {
    let dir = TempDir::new().unwrap();
    let mut junk = Vec::new();
    let mut state = 0x1234_5678u32;
    for _ in 0..4096 {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        junk.push((state >> 24) as u8);
    }
    for name in ["junk.hdr", "junk.exr", "junk.pfm", "empty.hdr"] {
        let path = dir.path().join(name);
        std::fs::write(
            &path,
            if name.starts_with("empty") {
                &[][..]
            } else {
                &junk[..]
            },
        )
        .unwrap();
        assert_error(envlight().arg("info").arg(&path), name);
    }
    // Right magic, broken body.
    let path = dir.path().join("cut.hdr");
    std::fs::write(
        &path,
        "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 10 +X 20\n\x02\x02",
    )
    .unwrap();
    assert_error(envlight().arg("info").arg(&path), "cut.hdr");
    let path = dir.path().join("cut.pfm");
    std::fs::write(&path, "PF\n4 4\n-1.0\n\0\0\0\0").unwrap();
    assert_error(envlight().arg("info").arg(&path), "cut.pfm");
}

/// A 612-byte OpenEXR file that once made the loader reserve 1.9 GB (a fuzzing
/// find) and, under an address-space limit, abort: now exit 1 naming the file,
/// under a 512 MiB limit.
#[test]
fn a_hostile_file_is_an_error_under_a_512_mib_address_space_limit() {
    let hostile = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions/load/exr-chunk-size-1.9GB.exr");
    let binary = assert_cmd::cargo::cargo_bin("envlight");
    assert_error(
        Command::new("sh")
            .args(["-c", "ulimit -v 524288 && exec \"$@\"", "sh"])
            .arg(&binary)
            .arg("info")
            .arg(&hostile),
        "exr-chunk-size-1.9GB.exr",
    );
}

#[test]
fn truncated_real_maps_are_errors_naming_the_file() {
    let Some(src) = envmaps() else { return };
    let dir = TempDir::new().unwrap();
    for name in ["sunrise.exr", "colorful_studio_2k.hdr"] {
        let Ok(bytes) = std::fs::read(src.join(name)) else {
            eprintln!("skipped: {name} not found");
            continue;
        };
        for fraction in [0.1, 0.5, 0.9] {
            let path = dir.path().join(format!("cut-{fraction}-{name}"));
            std::fs::write(&path, &bytes[..(bytes.len() as f64 * fraction) as usize]).unwrap();
            assert_error(
                envlight().arg("info").arg(&path),
                &format!("cut-{fraction}-{name}"),
            );
        }
    }
}

#[test]
fn non_finite_texels_are_errors_naming_the_texel() {
    let dir = TempDir::new().unwrap();
    for (name, bad) in [
        ("nan.pfm", f32::NAN),
        ("inf.pfm", f32::INFINITY),
        ("ninf.pfm", f32::NEG_INFINITY),
    ] {
        let path = dir.path().join(name);
        write_pfm(&path, 6, 3, |x, y| {
            if (x, y) == (4, 1) {
                [1.0, bad, 1.0]
            } else {
                [1.0; 3]
            }
        });
        let stderr = assert_error(envlight().arg("info").arg(&path), name);
        assert!(stderr.contains("(4, 1)"), "{stderr}");
        assert_error(envlight().args(["sample", "-n", "1"]).arg(&path), "(4, 1)");
        // --sanitize replaces it, with a warning that counts it.
        envlight()
            .args(["sample", "-n", "10", "--sanitize"])
            .arg(&path)
            .assert()
            .success()
            .stderr(
                predicate::str::contains("warning:")
                    .and(predicate::str::contains("replaced 1 texels")),
            );
    }
}

#[test]
fn negative_texels_are_clamped_with_a_warning() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("neg.pfm");
    write_pfm(&path, 8, 4, |x, y| match (x, y) {
        (1, 1) => [-0.5, 1.0, 1.0],
        (2, 2) => [1.0, -0.25, -2.0],
        (7, 3) => [-1e-4, 0.0, 0.0],
        _ => [1.0; 3],
    });
    let out = envlight()
        .args(["info", "--json"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("warning:"), "{stderr}");
    assert!(
        stderr.contains("3 texels") && stderr.contains("-2"),
        "{stderr}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["negative_texels"], 3);
    verify_passes(&[path.to_str().unwrap(), "--samples", "5000"]);
}

#[test]
fn bad_usage_exits_with_2() {
    for args in [
        &[][..],
        &["frobnicate"][..],
        &["sample"][..],
        &["sample", "-n", "many"][..],
        &["sample", "-n", "5", "--scale", "-1"][..],
        &["sample", "-n", "5", "--rotate", "nan"][..],
        &["sample", "-n", "5", "--lookup", "cubic"][..],
        &["eval"][..],
        &["info", "--bogus"][..],
        &["verify", "--samples", "10"][..],
    ] {
        let out = envlight().args(args).output().unwrap();
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(out.stdout.is_empty());
    }
}

#[test]
fn help_explains_the_conventions() {
    for cmd in [
        "info",
        "sample",
        "eval",
        "importance",
        "verify",
        "visibility",
    ] {
        let text = stdout_of(envlight().args([cmd, "--help"]));
        assert!(text.contains("z up"), "{cmd}: {text}");
        assert!(
            text.contains("φ = 2π u") && text.contains("θ = π v"),
            "{cmd}: {text}"
        );
    }
    let text = stdout_of(envlight().args(["sample", "--help"]));
    assert!(text.contains(HEADER));
}

// ---------------------------------------------------------------- degenerate maps

#[test]
fn all_black_map_gives_pdf_zero_rows_and_a_warning() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("black.pfm");
    write_pfm(&path, 8, 4, |_, _| [0.0; 3]);
    let out = envlight()
        .args(["sample", "-n", "200"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
    assert!(
        stderr.starts_with("warning:") && stderr.contains("black"),
        "{stderr}"
    );
    let rows = parse_rows(&String::from_utf8(out.stdout).unwrap());
    assert_eq!(rows.len(), 200);
    for r in &rows {
        assert_eq!(&r[3..], &[0.0; 4], "{r:?}");
        let len = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-6, "{r:?}");
    }
    // Every other command copes too.
    let v = info_json(&[path.to_str().unwrap()]);
    assert_eq!(v["efficiency"], 0.0);
    assert_eq!(v["black"], true);
    let evaluated = stdout_of(
        envlight()
            .arg("eval")
            .arg(&path)
            .args(["--dirs", "-"])
            .write_stdin("x,y,z\n0,0,1\n"),
    );
    assert_eq!(parse_rows(&evaluated)[0][3..], [0.0; 4]);
    let table = verify_passes(&[path.to_str().unwrap()]);
    assert!(table.contains("skip"));
    // Whatever the sampler, density and mapping.
    for options in [
        &["--sampler", "alias"][..],
        &["--sampler", "hierarchical", "--mapping", "equal-area"][..],
        &["--density", "piecewise-bilinear", "--mapping", "equal-area"][..],
    ] {
        let p = path.to_str().unwrap();
        let rows = parse_rows(&stdout_of(
            envlight().args(["sample", p, "-n", "50"]).args(options),
        ));
        assert!(rows.iter().all(|r| r[3..] == [0.0; 4]), "{options:?}");
        let v = info_json(&[&[p][..], options].concat());
        assert_eq!(v["black"], true, "{options:?}");
        verify_passes(&[&[p][..], options].concat());
    }
    let png = dir.path().join("black.png");
    importance(&[path.to_str().unwrap(), "--samples", "10"], &png);
    check_png(&png, 64);
}

#[test]
fn one_texel_and_one_hot_texel_maps_work() {
    let dir = TempDir::new().unwrap();
    let one = dir.path().join("one.pfm");
    write_pfm(&one, 1, 1, |_, _| [2.0, 1.0, 0.5]);
    let hot = dir.path().join("hot.pfm");
    write_pfm(&hot, 32, 16, |x, y| {
        if (x, y) == (31, 0) {
            [1e4; 3]
        } else {
            [0.0; 3]
        }
    });
    for map in [&one, &hot] {
        let m = map.to_str().unwrap();
        for options in [
            &[][..],
            &["--mapping", "equal-area"][..],
            &["--density", "piecewise-bilinear"][..],
            &["--sampler", "hierarchical", "--mapping", "equal-area"][..],
            &["--sampler", "alias"][..],
        ] {
            let mut args = vec![m];
            args.extend_from_slice(options);
            info_json(&args);
            let rows = parse_rows(&stdout_of(
                envlight().args(["sample", "-n", "2000"]).args(&args),
            ));
            assert!(rows.iter().all(|r| r.iter().all(|v| v.is_finite())));
            verify_passes(&[&args[..], &["--samples", "5000"]].concat());
            let png = dir.path().join("x.png");
            importance(
                &[&["--width", "64", "--samples", "20"][..], &args].concat(),
                &png,
            );
        }
    }
}

// ---------------------------------------------------------------- output

#[test]
fn a_failing_command_leaves_an_existing_output_untouched() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("out.csv");
    std::fs::write(&out, "precious\n").unwrap();
    let dirs = dir.path().join("dirs.csv");
    // The bad row comes after enough good rows that output has been written.
    let mut input = String::from("x,y,z\n");
    for _ in 0..100_000 {
        input.push_str("0.1,0.2,0.3\n");
    }
    input.push_str("0,0,0\n");
    std::fs::write(&dirs, input).unwrap();
    assert_error(
        envlight()
            .args(["eval", "--dirs"])
            .arg(&dirs)
            .arg("-o")
            .arg(&out),
        "dirs.csv:100002:",
    );
    assert_error(
        envlight()
            .args(["sample", "missing.exr", "-n", "5", "-o"])
            .arg(&out),
        "missing.exr",
    );
    assert_error(
        envlight()
            .args(["importance", "missing.exr", "-o"])
            .arg(&out),
        "missing.exr",
    );
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "precious\n");
    // No temporary files left behind.
    let names = file_names(dir.path());
    assert_eq!(names.len(), 2, "{names:?}");
    // And a new output that fails is never created.
    let fresh = dir.path().join("fresh.csv");
    assert_error(
        envlight()
            .args(["eval", "--dirs"])
            .arg(&dirs)
            .arg("-o")
            .arg(&fresh),
        "dirs.csv",
    );
    assert!(!fresh.exists());
}

#[test]
fn output_into_a_missing_directory_is_an_error_naming_it() {
    assert_error(
        envlight().args(["sample", "-n", "1", "-o", "no/such/dir/s.csv"]),
        "no/such/dir/s.csv",
    );
}

/// The binary started with `args`, its stdin and stdout piped, its stderr to `stderr`.
fn spawn_piped(args: &[&str], stderr: Stdio) -> std::process::Child {
    std::process::Command::new(assert_cmd::cargo::cargo_bin("envlight"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .unwrap()
}

#[test]
fn a_closed_pipe_ends_quietly() {
    for args in [
        &["sample", "-n", "1000000"][..],
        &["eval", "--dirs", "-"][..],
    ] {
        let mut child = spawn_piped(args, Stdio::piped());
        let stdin = child.stdin.take().unwrap();
        let feeder = std::thread::spawn(move || {
            use std::io::Write;
            let mut stdin = stdin;
            let _ = stdin.write_all(b"x,y,z\n");
            for _ in 0..200_000 {
                if stdin.write_all(b"0.1,0.2,0.3\n").is_err() {
                    break;
                }
            }
        });
        let mut reader = BufReader::new(child.stdout.take().unwrap());
        let mut line = String::new();
        reader.read_line(&mut line).unwrap();
        assert_eq!(line, "x,y,z,pdf,r,g,b\n");
        drop(reader);
        let mut stderr = String::new();
        child
            .stderr
            .take()
            .unwrap()
            .read_to_string(&mut stderr)
            .unwrap();
        let status = child.wait().unwrap();
        let _ = feeder.join();
        assert_eq!(status.code(), Some(0), "{args:?}: {stderr}");
        assert!(
            !stderr.contains("panicked") && !stderr.contains("error"),
            "{stderr}"
        );
    }
}

#[test]
fn eval_streams_from_an_open_stdin() {
    // 70 000 rows (more than one read batch) go in and stdin stays open: results
    // must come out before the input ends, so eval never holds all of its input.
    let mut child = spawn_piped(&["eval", "--dirs", "-"], Stdio::null());
    let stdin = child.stdin.take().unwrap();
    let (close_tx, close_rx) = std::sync::mpsc::channel::<()>();
    let feeder = std::thread::spawn(move || {
        use std::io::Write;
        let mut stdin = std::io::BufWriter::new(stdin);
        stdin.write_all(b"x,y,z\n").unwrap();
        for k in 0..70_000 {
            writeln!(stdin, "{},0.5,0.25", k as f32 * 1e-5).unwrap();
        }
        stdin.flush().unwrap();
        // Keep the pipe open until the test has seen output.
        let _ = close_rx.recv_timeout(std::time::Duration::from_secs(60));
    });
    let stdout = child.stdout.take().unwrap();
    let (line_tx, line_rx) = std::sync::mpsc::channel();
    let reader = std::thread::spawn(move || {
        let mut reader = BufReader::new(stdout);
        let mut first = [String::new(), String::new()];
        for line in &mut first {
            reader.read_line(line).unwrap();
        }
        line_tx.send(first).unwrap();
        // Drain the rest so the child is never blocked on a full pipe.
        std::io::copy(&mut reader, &mut std::io::sink()).unwrap();
    });
    let first = line_rx
        .recv_timeout(std::time::Duration::from_secs(30))
        .expect("no output while stdin was still open: eval does not stream");
    assert_eq!(first[0], "x,y,z,pdf,r,g,b\n");
    assert!(first[1].starts_with("0,"), "{}", first[1]);
    close_tx.send(()).unwrap();
    feeder.join().unwrap();
    reader.join().unwrap();
    assert_eq!(child.wait().unwrap().code(), Some(0));
}

// ---------------------------------------------------------------- --normal

/// `--normal` on every command: `sample` draws from the product sampler and
/// `eval` reproduces its rows bit for bit; `info --json` adds the shading keys
/// with the product sampler at least as efficient as the light alone on a
/// surface facing away from the sun; `verify` passes for every sampler, density
/// and mapping; `importance` writes its picture.
#[test]
fn normal_option_on_every_command() {
    let dir = TempDir::new().unwrap();
    let samples = dir.path().join("samples.csv");
    let normal = ["--normal", "-0.3, 0.2, -0.9"];
    envlight()
        .args(["sample", "-n", "2000", "--seed", "4", "-o"])
        .arg(&samples)
        .args(normal)
        .assert()
        .success();
    let written = std::fs::read_to_string(&samples).unwrap();
    let rows = parse_rows(&written);
    assert_eq!(rows.len(), 2000);
    let n = [-0.3f64, 0.2, -0.9];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let facing = rows
        .iter()
        .filter(|r| (r[0] * n[0] + r[1] * n[1] + r[2] * n[2]) / len > 0.0)
        .count();
    // The product sampler puts nearly every sample above the surface: only
    // patches straddling the horizon reach below it (measured 1962 of 2000 above
    // within 0.05 of it); the light alone puts most of them on the sun, behind.
    assert!(facing > 1900, "{facing} of 2000 above the surface");
    assert!(rows.iter().all(|r| r[3] > 0.0));
    let evaluated = stdout_of(
        envlight()
            .args(["eval", "--dirs"])
            .arg(&samples)
            .args(normal),
    );
    assert_eq!(
        written, evaluated,
        "eval --normal differs from sample --normal"
    );
    let light_only = parse_rows(&stdout_of(
        envlight().args(["eval", "--dirs"]).arg(&samples),
    ));
    assert!(rows.iter().zip(&light_only).any(|(a, b)| a[3] != b[3]));

    let v = info_json(&normal);
    let unit = v["normal"].as_array().unwrap();
    assert!(
        (unit[2].as_f64().unwrap() - (-0.9 / len)).abs() < 1e-6,
        "{v}"
    );
    let irradiance = v["irradiance"].as_f64().unwrap();
    let (p, l) = (
        v["product_efficiency"].as_f64().unwrap(),
        v["light_efficiency"].as_f64().unwrap(),
    );
    assert!(irradiance > 0.0 && p > 0.5 && p > l, "{v}");

    let tables = verify_passes_on_pfm_with_each(
        &["--samples", "20000", "--normal", "0.2,-0.5,0.8"],
        &[
            &[],
            &["--sampler", "alias"],
            &["--sampler", "hierarchical", "--mapping", "equal-area"],
            &["--density", "piecewise-bilinear"],
            &["--lookup", "nearest", "--rotate", "30"],
        ],
    );
    for table in tables {
        assert!(table.contains("unbiased (Y·cos⁺"), "{table}");
    }
    let png = dir.path().join("product.png");
    importance(
        &[&["--width", "64", "--samples", "20"][..], &normal].concat(),
        &png,
    );
    check_png(&png, 64);

    // bench --normal adds the product's figures, each a positive number.
    let out = stdout_of(
        envlight()
            .args(["bench", "--json", "--queries", "1024", "--repeat", "2"])
            .args(normal),
    );
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in [
        "product_point_ns",
        "product_sample_ns",
        "product_pdf_ns",
        "product_build_ms",
        "product_bytes",
        "product_point_ratio",
    ] {
        let x = v[key].as_f64().unwrap_or(f64::NAN);
        assert!(x.is_finite() && x > 0.0, "{key} = {x} in {v}");
    }
}

#[test]
fn bad_normals_are_usage_errors() {
    for value in ["0,0,0", "1,2", "a,b,c", "nan,0,1", "1,2,3,4", "inf,0,0"] {
        for cmd in ["sample", "eval", "info", "verify", "importance"] {
            let out = envlight().args([cmd, "--normal", value]).output().unwrap();
            assert_eq!(out.status.code(), Some(2), "{cmd} --normal {value}");
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(
                stderr.starts_with("error:") && stderr.contains("--normal"),
                "{cmd} --normal {value}: {stderr}"
            );
        }
    }
}

/// A surface that faces no light: `sample` writes pdf 0 rows, `verify` skips.
#[test]
fn a_normal_facing_no_light() {
    let dir = TempDir::new().unwrap();
    let map = dir.path().join("upper.pfm");
    write_pfm(&map, 32, 16, |_, y| if y < 4 { [1.0; 3] } else { [0.0; 3] });
    let m = map.to_str().unwrap();
    let rows = parse_rows(&stdout_of(
        envlight().args(["sample", m, "-n", "50", "--normal", "0,0,-1"]),
    ));
    assert!(rows.iter().all(|r| r[3..] == [0.0; 4]));
    let table = verify_passes(&[m, "--normal", "0,0,-1"]);
    assert!(table.contains("no light faces the surface"), "{table}");
}

// ---------------------------------------------------------------- export

/// Runs `envlight export ARGS -o FILE` and returns the file's bytes, checked to
/// read back as GPU tables.
fn export(args: &[&str], file: &Path) -> (Vec<u8>, envlight::gpu::GpuTables) {
    let out = envlight()
        .arg("export")
        .args(args)
        .arg("-o")
        .arg(file)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "export {args:?}: {stderr}");
    assert!(out.stdout.is_empty(), "export {args:?} wrote to stdout");
    let bytes = std::fs::read(file).unwrap();
    let tables = envlight::gpu::GpuTables::from_bytes(&bytes)
        .unwrap_or_else(|e| panic!("export {args:?}: {e}"));
    (bytes, tables)
}

#[test]
fn export_writes_gpu_tables_of_builtin_sky() {
    use envlight::gpu::{param, RadianceFormat, MAGIC, VERSION};
    let dir = TempDir::new().unwrap();
    let file = dir.path().join("sky.envgpu");
    let (bytes, tables) = export(&[], &file);
    assert_eq!(&bytes[..8], &MAGIC);
    assert_eq!(&bytes[..8], b"ENVLGPU\0");
    assert_eq!(
        u32::from_le_bytes(bytes[8..12].try_into().unwrap()),
        VERSION
    );
    assert_eq!(tables.to_bytes(), bytes);
    assert_eq!(tables.radiance_format(), RadianceFormat::F32);
    let p = tables.params();
    assert_eq!(p[param::VERSION], 1);
    // The default light: inversion, piecewise-bilinear.
    assert_eq!((p[param::SAMPLER], p[param::DENSITY]), (0, 1));
    // The same tables as the library builds for the same light.
    let light = envlight::EnvironmentLight::new(
        envlight::builtin::by_name("sky").unwrap(),
        envlight::LightOptions::default(),
    )
    .unwrap();
    let want = light.gpu_tables(&Default::default()).unwrap();
    assert_eq!(tables, want);
    // Light options reach the parameters; a second export replaces the file.
    let (_, tables) = export(
        &[
            "--sampler",
            "alias",
            "--mapping",
            "equal-area",
            "--rotate",
            "30",
            "--scale",
            "2",
            "--lookup",
            "nearest",
        ],
        &file,
    );
    let p = tables.params();
    assert_eq!(
        (p[param::SAMPLER], p[param::MAPPING], p[param::LOOKUP]),
        (1, 1, 0)
    );
    assert_eq!(
        (p[param::ROTATED], f32::from_bits(p[param::SCALE])),
        (1, 2.0)
    );
    let (_, tables) = export(&["--density", "piecewise-bilinear"], &file);
    assert_eq!(tables.params()[param::DENSITY], 1);
}

#[test]
fn export_f16_radiance_on_builtin_sky_and_a_file() {
    use envlight::gpu::{param, RadianceFormat};
    let dir = TempDir::new().unwrap();
    let f32_file = dir.path().join("f32.envgpu");
    let f16_file = dir.path().join("f16.envgpu");
    let (f32_bytes, full) = export(&["--radiance", "f32"], &f32_file);
    let (f16_bytes, half) = export(&["--radiance", "f16"], &f16_file);
    assert_eq!(half.radiance_format(), RadianceFormat::F16);
    assert_eq!(half.params()[param::RADIANCE_FORMAT], 1);
    assert_eq!(half.tables(), full.tables());
    // 8 bytes per texel instead of 12.
    assert_eq!(2 * full.radiance().len(), 3 * half.radiance().len());
    assert!(f16_bytes.len() < f32_bytes.len());
    // A small map: its texels round to the f16 the file holds (R, G in the first
    // word, B and 0 in the second).
    let (_d, map) = pfm_dir();
    let (_, half) = export(&[map.to_str().unwrap(), "--radiance", "f16"], &f16_file);
    assert_eq!(half.radiance().len(), 2 * 16 * 8);
    // Texel (5, 2) is [40, 30, 20]: exact in f16.
    let k = 2 * 16 + 5;
    assert_eq!(half.radiance()[2 * k], 0x5100 | (0x4f80 << 16));
    assert_eq!(half.radiance()[2 * k + 1], 0x4d00);
}

#[test]
fn export_of_the_hierarchical_sampler_is_a_usage_error() {
    let dir = TempDir::new().unwrap();
    let file = dir.path().join("never.envgpu");
    let out = envlight()
        .args(["export", "--sampler", "hierarchical", "-o"])
        .arg(&file)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    let lines: Vec<&str> = stderr.lines().collect();
    assert_eq!(lines.len(), 1, "{stderr}");
    assert!(lines[0].starts_with("error: "), "{stderr}");
    assert!(lines[0].contains("not ported to the GPU"), "{stderr}");
    assert!(
        lines[0].contains("--sampler inversion or alias"),
        "{stderr}"
    );
    assert!(!file.exists());
    // -o is required: a usage error from clap.
    let out = envlight().arg("export").output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--output"));
}

#[test]
fn export_failures_leave_an_existing_file_untouched() {
    let dir = TempDir::new().unwrap();
    let out = dir.path().join("out.envgpu");
    std::fs::write(&out, "precious\n").unwrap();
    assert_error(
        envlight().args(["export", "missing.exr", "-o"]).arg(&out),
        "missing.exr",
    );
    // A texel beyond f16's range: refused for f16, naming the map and the texel.
    let bright = dir.path().join("bright.pfm");
    write_pfm(&bright, 8, 4, |x, y| {
        if (x, y) == (6, 1) {
            [1.0, 1e5, 1.0]
        } else {
            [1.0; 3]
        }
    });
    let stderr = assert_error(
        envlight()
            .arg("export")
            .arg(&bright)
            .args(["--radiance", "f16", "-o"])
            .arg(&out),
        "bright.pfm",
    );
    assert!(
        stderr.contains("(6, 1)") && stderr.contains("65504") && stderr.contains("f32"),
        "{stderr}"
    );
    let code = envlight()
        .args(["export", "--sampler", "hierarchical", "-o"])
        .arg(&out)
        .output()
        .unwrap()
        .status
        .code();
    assert_eq!(code, Some(2));
    assert_eq!(std::fs::read_to_string(&out).unwrap(), "precious\n");
    let names = file_names(dir.path());
    assert_eq!(names.len(), 2, "{names:?}");
    // The same map in f32 is fine, and replaces the file.
    let (bytes, _) = export(&[bright.to_str().unwrap()], &out);
    assert_eq!(std::fs::read(&out).unwrap(), bytes);
}

/// `info --normal`'s efficiencies against an independent quadrature of what a
/// renderer's estimates see: 4 × 4 midpoints per texel of the lat-long map, the
/// lookup's radiance times the clamped cosine over the sampler's actual pdf, for
/// the product sampler and the light alone, both densities (within 3%).
#[test]
fn info_efficiencies_match_a_fine_quadrature() {
    use envlight::light::Density;
    use envlight::{EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3};
    use std::sync::Arc;
    let normal = Vec3::new(0.0, 0.0, 1.0);
    for density in Density::ALL {
        let v = info_json(&[
            "builtin:sky",
            "--normal",
            "0,0,1",
            "--density",
            density.name(),
        ]);
        assert_eq!(v["product_density"], density.name(), "{v}");
        let image = envlight::builtin::sky(1024, 512);
        let (w, h) = (image.width(), image.height());
        let options = LightOptions {
            density,
            ..Default::default()
        };
        let light = Arc::new(EnvironmentLight::new(image, options).unwrap());
        let sampler = ProductSampler::new(light.clone(), ProductOptions::default());
        let point = sampler.at(&Factor::cosine(normal));
        let (mut g1, mut product, mut alone) = (0.0f64, 0.0f64, 0.0f64);
        for j in 0..h {
            for b in 0..4 {
                let v = (j as f64 + (b as f64 + 0.5) / 4.0) / h as f64;
                let dw = 2.0 * std::f64::consts::PI.powi(2) * (std::f64::consts::PI * v).sin()
                    / (16 * w * h) as f64;
                for i in 0..w {
                    for a in 0..4 {
                        let u = (i as f64 + (a as f64 + 0.5) / 4.0) / w as f64;
                        let d = light.uv_to_direction([u as f32, v as f32]);
                        let y = envlight::color::luminance(light.radiance(d)) as f64;
                        let f = y * normal.dot(d).max(0.0) as f64;
                        if f > 0.0 {
                            g1 += f * dw;
                            product += f * f / point.pdf(d) as f64 * dw;
                            alone += f * f / light.pdf(d) as f64 * dw;
                        }
                    }
                }
            }
        }
        let (product, alone) = (g1 * g1 / product, g1 * g1 / alone);
        let reported = (
            v["product_efficiency"].as_f64().unwrap(),
            v["light_efficiency"].as_f64().unwrap(),
        );
        println!(
            "{}: product {} reported, {product} by 4x4 quadrature; light {} reported, {alone}",
            density.name(),
            reported.0,
            reported.1
        );
        assert!((reported.0 / product - 1.0).abs() < 0.03, "{v}");
        assert!((reported.1 / alone - 1.0).abs() < 0.03, "{v}");
    }
}

/// A visibility cache option out of range is a usage error before anything is
/// traced or rendered, not a panic inside the render.
#[test]
fn render_refuses_visibility_options_out_of_range() {
    for (flag, value, needle) in [
        ("--visibility-share", "1.5", "learned_share 1.5"),
        ("--visibility-rays", "0", "rays_per_patch 0"),
        ("--visibility-prior", "-1", "prior -1"),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let out = envlight()
            .args(["render", "--scene", "balls", "--strategy", "mis-visibility"])
            .args(["--spp", "1", "--width", "8", "--height", "4"])
            .arg(format!("{flag}={value}"))
            .arg("-o")
            .arg(dir.path().join("out.png"))
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{flag}: {stderr}");
        assert!(stderr.contains(needle), "{flag}: {stderr}");
        assert!(!dir.path().join("out.png").exists());
    }
}
