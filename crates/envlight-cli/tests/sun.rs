//! `envlight sun` (issue 24): the JSON and text forms, the residual in each format
//! and its atomic write, the light options, the usage and input errors, the disc
//! on `importance`'s picture, and the real maps when they are there.

use std::f64::consts::PI;
use std::path::{Path, PathBuf};

use assert_cmd::Command;
use tempfile::TempDir;

mod common;
use common::{envlight, importance, stdout_of, write_pfm};

fn dir_deg(el: f64, az: f64) -> [f64; 3] {
    let (el, az) = (el.to_radians(), az.to_radians());
    [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
}

fn texel_dir(x: f64, y: f64, w: usize, h: usize) -> [f64; 3] {
    let (t, p) = (PI * y / h as f64, 2.0 * PI * x / w as f64);
    [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The sun's centre in [`disc_dir`]: 20° up, azimuth 60°.
const SUN_EL: f64 = 20.0;
const SUN_AZ: f64 = 60.0;

/// A 1024×512 map: a blue sky over dark ground and a 1° disc (4×4 supersampled
/// coverage) of radiance 3000 at [`SUN_EL`], [`SUN_AZ`].
fn disc_map(path: &Path) {
    let (w, h) = (1024, 512);
    let c = dir_deg(SUN_EL, SUN_AZ);
    let cos_r = 1f64.to_radians().cos();
    write_pfm(path, w, h, |x, y| {
        let d = texel_dir(x as f64 + 0.5, y as f64 + 0.5, w, h);
        let mut rgb = if d[2] > 0.0 {
            [0.3, 0.45, 0.8]
        } else {
            [0.1, 0.08, 0.06]
        };
        if dot(d, c) > 2f64.to_radians().cos() {
            let mut inside = 0;
            for sy in 0..4 {
                for sx in 0..4 {
                    let s = texel_dir(
                        x as f64 + (sx as f64 + 0.5) / 4.0,
                        y as f64 + (sy as f64 + 0.5) / 4.0,
                        w,
                        h,
                    );
                    inside += (dot(s, c) >= cos_r) as u32;
                }
            }
            let cov = inside as f32 / 16.0;
            rgb = [
                rgb[0] + 3000.0 * cov,
                rgb[1] + 2800.0 * cov,
                rgb[2] + 2500.0 * cov,
            ];
        }
        rgb
    });
}

fn disc_dir() -> (TempDir, PathBuf) {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("disc.pfm");
    disc_map(&path);
    (dir, path)
}

fn json_of(cmd: &mut Command) -> serde_json::Value {
    serde_json::from_str(&stdout_of(cmd)).unwrap()
}

fn vec3(v: &serde_json::Value) -> [f64; 3] {
    let a = v.as_array().unwrap();
    assert_eq!(a.len(), 3);
    [0, 1, 2].map(|k| a[k].as_f64().unwrap())
}

#[test]
fn json_has_exactly_the_documented_shape() {
    let (_dir, map) = disc_dir();
    let v = json_of(envlight().arg("sun").arg(&map).arg("--json"));
    let object = v.as_object().unwrap();
    assert_eq!(object.keys().collect::<Vec<_>>(), ["sun"]);
    let sun = v["sun"].as_object().unwrap();
    let mut keys: Vec<&str> = sun.keys().map(|k| k.as_str()).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "angular_radius_deg",
            "direction",
            "irradiance",
            "power_fraction",
            "radiance",
            "solid_angle_sr"
        ]
    );
    let d = vec3(&v["sun"]["direction"]);
    assert!((dot(d, d) - 1.0).abs() < 1e-6);
    let error = dot(d, dir_deg(SUN_EL, SUN_AZ)).min(1.0).acos().to_degrees();
    assert!(error < 0.1, "{error}");
    let r = v["sun"]["angular_radius_deg"].as_f64().unwrap();
    assert!((r - 1.0).abs() < 0.05, "{r}");
    let omega = v["sun"]["solid_angle_sr"].as_f64().unwrap();
    assert!((omega / (2.0 * PI * (1.0 - 1f64.to_radians().cos())) - 1.0).abs() < 0.1);
    // Radiance ≈ the disc's 3000, 2800, 2500; irradiance = radiance · π sin² r.
    let radiance = vec3(&v["sun"]["radiance"]);
    let irradiance = vec3(&v["sun"]["irradiance"]);
    let sin_r = r.to_radians().sin();
    for (k, expected) in [3000.0, 2800.0, 2500.0].into_iter().enumerate() {
        assert!((radiance[k] / expected - 1.0).abs() < 0.03, "{radiance:?}");
        assert!((irradiance[k] / (radiance[k] * PI * sin_r * sin_r) - 1.0).abs() < 1e-9);
    }
    let f = v["sun"]["power_fraction"].as_f64().unwrap();
    assert!(f > 0.1 && f < 1.0, "{f}");
}

#[test]
fn text_form_gives_elevation_and_azimuth() {
    let (_dir, map) = disc_dir();
    let out = envlight().arg("sun").arg(&map).output().unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("sun found"), "{text}");
    assert!(text.contains("elevation 20.0"), "{text}");
    assert!(text.contains("azimuth 60.0"), "{text}");
    for word in [
        "angular radius",
        "solid angle",
        "radiance",
        "irradiance",
        "power fraction",
    ] {
        assert!(text.contains(word), "{word}: {text}");
    }
}

#[test]
fn no_sun_is_an_answer_not_an_error() {
    let dir = TempDir::new().unwrap();
    let map = dir.path().join("grey.pfm");
    write_pfm(&map, 256, 128, |_, _| [0.5, 0.5, 0.5]);
    let v = json_of(envlight().arg("sun").arg(&map).arg("--json"));
    assert_eq!(v, serde_json::json!({ "sun": null }));
    let out = envlight().arg("sun").arg(&map).output().unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("no sun"));
    // Black and 1×1 maps too (the black one warns, and is still no error).
    let black = dir.path().join("black.pfm");
    write_pfm(&black, 64, 32, |_, _| [0.0; 3]);
    let tiny = dir.path().join("tiny.pfm");
    write_pfm(&tiny, 1, 1, |_, _| [7.0; 3]);
    for m in [&black, &tiny] {
        let v = json_of(envlight().arg("sun").arg(m).arg("--json"));
        assert_eq!(v["sun"], serde_json::Value::Null);
    }
}

#[test]
fn light_options_apply() {
    let (_dir, map) = disc_dir();
    let plain = json_of(envlight().arg("sun").arg(&map).arg("--json"));
    let turned = json_of(
        envlight()
            .args(["sun", "--json", "--rotate", "90", "--scale", "2"])
            .arg(&map),
    );
    let d = vec3(&turned["sun"]["direction"]);
    let error = dot(d, dir_deg(SUN_EL, SUN_AZ + 90.0))
        .min(1.0)
        .acos()
        .to_degrees();
    assert!(error < 0.1, "{error}");
    let (a, b) = (
        vec3(&plain["sun"]["irradiance"]),
        vec3(&turned["sun"]["irradiance"]),
    );
    for k in 0..3 {
        assert!((b[k] / a[k] - 2.0).abs() < 1e-9);
    }
    // An equal-area light finds the same sun on its resampled square.
    let ea = json_of(
        envlight()
            .args(["sun", "--json", "--mapping", "equal-area"])
            .arg(&map),
    );
    let d = vec3(&ea["sun"]["direction"]);
    let error = dot(d, dir_deg(SUN_EL, SUN_AZ)).min(1.0).acos().to_degrees();
    assert!(error < 0.2, "{error}");
}

fn load(path: &Path) -> envlight::EnvImage {
    envlight::load::load(path, &Default::default())
        .unwrap()
        .image
}

#[test]
fn residual_in_every_format_is_the_map_without_its_sun() {
    let (dir, map) = disc_dir();
    let expected = {
        let light =
            envlight::EnvironmentLight::new(load(&map), envlight::LightOptions::default()).unwrap();
        light.extract_sun(&envlight::SunOptions::default()).residual
    };
    for ext in ["pfm", "exr", "hdr", "EXR"] {
        let out = dir.path().join(format!("residual.{ext}"));
        stdout_of(envlight().arg("sun").arg(&map).arg("--residual").arg(&out));
        let got = load(&out);
        assert_eq!((got.width(), got.height()), (1024, 512));
        // PFM and 32-bit EXR are exact; RGBE keeps 8 bits of mantissa under an
        // exponent shared with the brightest channel.
        let tolerance = if ext == "hdr" { 1.0 / 128.0 } else { 0.0 };
        for (a, b) in got.texels().iter().zip(expected.texels()) {
            let brightest = b[0].max(b[1]).max(b[2]);
            for k in 0..3 {
                assert!(
                    (a[k] - b[k]).abs() <= tolerance * brightest,
                    "{ext}: {a:?} vs {b:?}"
                );
            }
        }
        // The residual has no sun left.
        let v = json_of(envlight().arg("sun").arg(&out).arg("--json"));
        assert_eq!(v["sun"], serde_json::Value::Null, "{ext}");
    }
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(!names.iter().any(|n| n.ends_with(".partial")), "{names:?}");
}

/// `envlight sun MAP --residual FILE`, run.
fn sun_residual(map: &Path, residual: &Path) -> std::process::Output {
    envlight()
        .arg("sun")
        .arg(map)
        .arg("--residual")
        .arg(residual)
        .output()
        .unwrap()
}

#[test]
fn errors_are_one_line_and_leave_existing_files_alone() {
    let (dir, map) = disc_dir();
    let existing = dir.path().join("keep.exr");
    std::fs::write(&existing, b"precious").unwrap();
    // A bad extension is a usage error (exit 2), found before the map is read.
    let out = sun_residual(&map, &dir.path().join("residual.png"));
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.starts_with("error: ") && stderr.contains(".exr, .pfm or .hdr"),
        "{stderr}"
    );
    // A missing map: exit 1 naming it; the existing residual file is untouched.
    let missing = dir.path().join("missing.exr");
    let out = sun_residual(&missing, &existing);
    assert_eq!(out.status.code(), Some(1));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("missing.exr") && !stderr.contains("panicked"),
        "{stderr}"
    );
    assert_eq!(std::fs::read(&existing).unwrap(), b"precious");
    // A residual into a directory that does not exist: exit 1 naming it.
    let out = sun_residual(&map, &dir.path().join("nowhere/residual.pfm"));
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("residual.pfm"));
}

/// Pixels of the importance picture in the sun ring's colour.
fn cyan_pixels(png: &Path) -> usize {
    let img = image::open(png).unwrap().to_rgb8();
    img.pixels().filter(|p| p.0 == [0, 230, 255]).count()
}

#[test]
fn importance_marks_the_disc() {
    let (dir, map) = disc_dir();
    let with = dir.path().join("with.png");
    importance(&[map.to_str().unwrap(), "--width", "256"], &with);
    assert!(cyan_pixels(&with) > 20);
    let grey = dir.path().join("grey.pfm");
    write_pfm(&grey, 256, 128, |_, _| [0.5; 3]);
    let without = dir.path().join("without.png");
    importance(&[grey.to_str().unwrap(), "--width", "256"], &without);
    assert_eq!(cyan_pixels(&without), 0);
}

#[test]
fn real_maps_with_a_sun_report_it() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    let path = dir.join("sunrise.exr");
    if !path.is_file() {
        eprintln!(
            "skipped: {} not found (the real maps are optional)",
            path.display()
        );
        return;
    }
    let v = json_of(envlight().arg("sun").arg(&path).arg("--json"));
    let d = vec3(&v["sun"]["direction"]);
    // The brightest texel (614, 233) of the 1024×512 map, elevation 7.9°.
    let expected = texel_dir(614.5, 233.5, 1024, 512);
    let error = dot(d, expected).min(1.0).acos().to_degrees();
    assert!(error < 0.5, "{error}");
    assert!(v["sun"]["power_fraction"].as_f64().unwrap() > 0.4);
}
