//! `envlight render --save-visibility` and `envlight visibility`: a tiny room
//! render saves its cache; the summary in text and JSON; an entry's picture;
//! the keys (scene and map) refused with both named; a damaged file; an entry
//! out of range; `--compare` saving the same cache as a single render.

use std::path::{Path, PathBuf};

use assert_cmd::Command;
use tempfile::TempDir;

mod common;
use common::{envlight, stdout_of, write_pfm};

/// Renders the room (24×12, 1 spp, mis-visibility) on builtin:sky and saves its
/// visibility cache as `room.envlvis` in a new folder.
fn room_cache() -> (TempDir, PathBuf) {
    let dir = TempDir::new().unwrap();
    let cache = dir.path().join("room.envlvis");
    let out = envlight()
        .args(["render", "--scene", "room", "--strategy", "mis-visibility"])
        .args(["--spp", "1", "--width", "24", "--height", "12"])
        .arg("-o")
        .arg(dir.path().join("room.png"))
        .arg("--save-visibility")
        .arg(&cache)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    assert!(
        stderr.contains("room.envlvis (visibility cache: ") && stderr.contains("\"room\""),
        "{stderr}"
    );
    assert!(cache.is_file() && dir.path().join("room.png").is_file());
    (dir, cache)
}

/// The names in `dir` (no temporary file may be left).
fn names(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

/// A failing run: exit `code`, one `error:` line containing every needle, no
/// panic.
fn assert_fails(cmd: &mut Command, code: i32, needles: &[&str]) -> String {
    let out = cmd.output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(code), "stderr: {stderr}");
    let errors: Vec<&str> = stderr
        .lines()
        .filter(|l| !l.starts_with("warning:"))
        .collect();
    assert!(!stderr.contains("panicked"), "stderr: {stderr}");
    if code == 1 {
        assert_eq!(errors.len(), 1, "stderr: {stderr}");
    }
    assert!(errors[0].starts_with("error: "), "stderr: {stderr}");
    for needle in needles {
        assert!(
            errors[0].contains(needle),
            "expected {needle:?} in: {stderr}"
        );
    }
    stderr
}

fn visibility_json(args: &[&str], cache: &Path) -> serde_json::Value {
    let text = stdout_of(
        envlight()
            .arg("visibility")
            .args(args)
            .arg(cache)
            .arg("--json"),
    );
    serde_json::from_str(&text).unwrap()
}

#[test]
fn a_saved_room_cache_is_summarised_in_text_and_json() {
    let (dir, cache) = room_cache();
    assert_eq!(names(dir.path()), ["room.envlvis", "room.png"]);

    let text = stdout_of(envlight().arg("visibility").arg(&cache));
    for needle in [
        "room.envlvis",
        "scene key    \"room\"",
        "map          builtin:sky",
        "matches",
        "entries",
        "radius",
        "mean vis",
        "rays",
    ] {
        assert!(text.contains(needle), "{needle:?} in:\n{text}");
    }

    let v = visibility_json(&[], &cache);
    for key in [
        "entries",
        "bytes",
        "radius",
        "mean_visibility",
        "rays",
        "scene_key",
        "map_hash",
        "map_matches",
        "patches",
        "options",
    ] {
        assert!(v.get(key).is_some(), "missing {key} in {v}");
    }
    let entries = v["entries"].as_u64().unwrap();
    assert!(entries > 0, "{v}");
    let mean = v["mean_visibility"].as_f64().unwrap();
    assert!(mean > 0.0 && mean <= 1.0, "{v}");
    assert!(v["rays"].as_u64().unwrap() > 0, "{v}");
    assert!(v["bytes"].as_u64().unwrap() > 0, "{v}");
    assert!(v["radius"].as_f64().unwrap() > 0.0, "{v}");
    assert_eq!(v["scene_key"], "room");
    assert_eq!(v["map_matches"], true);
    let hash = v["map_hash"].as_str().unwrap();
    assert!(
        hash.len() == 16 && hash.chars().all(|c| c.is_ascii_hexdigit()),
        "{hash}"
    );
    assert_eq!(v["patches"], serde_json::json!([64, 32]));
    // The stored key, asked for explicitly, is the same cache.
    let same = visibility_json(&["--scene-key", "room"], &cache);
    assert_eq!(same["entries"], v["entries"]);
}

#[test]
fn an_entry_is_drawn_over_the_map() {
    let (dir, cache) = room_cache();
    let png = dir.path().join("entry.png");
    let v = visibility_json(
        &[
            "--entry",
            "0",
            "--image",
            png.to_str().unwrap(),
            "--width",
            "200",
        ],
        &cache,
    );
    let entry = &v["entry"];
    assert_eq!(entry["index"], 0);
    let n: Vec<f64> = entry["normal"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    assert!(
        (n.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-3,
        "{v}"
    );
    let seen = entry["seen"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&seen), "{v}");
    let faced = entry["patches_faced"].as_u64().unwrap();
    assert!(faced > 0 && faced < 64 * 32, "{v}");

    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    let img = image::load_from_memory(&bytes).unwrap();
    // The 200 × 100 map panel (builtin:sky is 2:1) under a 24-pixel title band.
    assert_eq!((img.width(), img.height()), (200, 124));
    assert_eq!(
        names(dir.path()),
        ["entry.png", "room.envlvis", "room.png"],
        "no temporary file left"
    );
    // The text form names the entry and the picture.
    let text = stdout_of(
        envlight()
            .arg("visibility")
            .arg(&cache)
            .args(["--entry", "0", "--image"])
            .arg(&png)
            .args(["--width", "64"]),
    );
    assert!(text.contains("entry        0: normal ("), "{text}");
    assert!(text.contains("entry.png"), "{text}");
}

#[test]
fn a_cache_for_another_scene_key_or_map_is_refused_naming_both() {
    let (dir, cache) = room_cache();
    assert_fails(
        envlight()
            .arg("visibility")
            .arg(&cache)
            .args(["--scene-key", "hall"]),
        1,
        &["room.envlvis", "\"room\"", "\"hall\""],
    );
    let v = visibility_json(&[], &cache);
    let hash = v["map_hash"].as_str().unwrap().to_string();
    let map = dir.path().join("other.pfm");
    write_pfm(&map, 32, 16, |x, y| {
        [0.1 + x as f32 * 0.01, 0.2, 0.3 + y as f32 * 0.01]
    });
    let stderr = assert_fails(
        envlight().arg("visibility").arg(&map).arg(&cache),
        1,
        &["room.envlvis", &hash, "map hash"],
    );
    // The other hash too: two 16-digit hashes on the line.
    let hexes = stderr
        .split(|c: char| !c.is_ascii_hexdigit())
        .filter(|w| w.len() == 16)
        .count();
    assert_eq!(hexes, 2, "{stderr}");
    // The same map lit another way is another light.
    assert_fails(
        envlight()
            .arg("visibility")
            .arg(&cache)
            .args(["--rotate", "30"]),
        1,
        &["room.envlvis", &hash],
    );
}

#[test]
fn a_damaged_cache_is_an_error_naming_the_file() {
    let (dir, cache) = room_cache();
    let bytes = std::fs::read(&cache).unwrap();
    let truncated = dir.path().join("truncated.envlvis");
    std::fs::write(&truncated, &bytes[..bytes.len() - 7]).unwrap();
    assert_fails(
        envlight().arg("visibility").arg(&truncated),
        1,
        &["truncated.envlvis", "bytes follow"],
    );
    let header = dir.path().join("header.envlvis");
    std::fs::write(&header, &bytes[..30]).unwrap();
    assert_fails(
        envlight().arg("visibility").arg(&header),
        1,
        &["header.envlvis", "truncated"],
    );
    let garbage = dir.path().join("garbage.envlvis");
    std::fs::write(&garbage, b"not a cache at all, just some text\n").unwrap();
    assert_fails(
        envlight().arg("visibility").arg(&garbage),
        1,
        &["garbage.envlvis", "not a visibility cache"],
    );
    // A visibility estimate out of (0, 1] in the last entry.
    let mut bad = bytes.clone();
    let n = bad.len();
    bad[n - 4..].copy_from_slice(&2.0f32.to_le_bytes());
    let bad_value = dir.path().join("value.envlvis");
    std::fs::write(&bad_value, &bad).unwrap();
    assert_fails(
        envlight().arg("visibility").arg(&bad_value),
        1,
        &["value.envlvis", "visibility 2"],
    );
    assert_fails(
        envlight()
            .arg("visibility")
            .arg(dir.path().join("missing.envlvis")),
        1,
        &["missing.envlvis"],
    );
}

#[test]
fn an_entry_out_of_range_is_a_usage_error_naming_the_count() {
    let (dir, cache) = room_cache();
    let entries = visibility_json(&[], &cache)["entries"].as_u64().unwrap();
    let png = dir.path().join("entry.png");
    assert_fails(
        envlight()
            .arg("visibility")
            .arg(&cache)
            .args(["--entry", &entries.to_string(), "--image"])
            .arg(&png),
        2,
        &[&format!("has {entries} entries")],
    );
    assert!(!png.exists());
    // --image needs --entry; CACHE is required.
    envlight()
        .arg("visibility")
        .arg(&cache)
        .arg("--image")
        .arg(&png)
        .assert()
        .code(2);
    envlight().arg("visibility").assert().code(2);
}

#[test]
fn saving_needs_a_strategy_that_builds_a_cache() {
    let dir = TempDir::new().unwrap();
    let cache = dir.path().join("mis.envlvis");
    assert_fails(
        envlight()
            .args(["render", "--scene", "room", "--strategy", "mis"])
            .args(["--spp", "1", "--width", "8", "--height", "4", "-o"])
            .arg(dir.path().join("mis.png"))
            .arg("--save-visibility")
            .arg(&cache),
        2,
        &["--save-visibility", "mis-visibility"],
    );
    // A folder that is not there: found before the render, naming the file.
    assert_fails(
        envlight()
            .args(["render", "--scene", "room", "--strategy", "mis-visibility"])
            .args(["--spp", "1", "--width", "8", "--height", "4", "-o"])
            .arg(dir.path().join("x.png"))
            .arg("--save-visibility")
            .arg(dir.path().join("missing").join("x.envlvis")),
        1,
        &["x.envlvis"],
    );
    assert!(names(dir.path()).is_empty(), "{:?}", names(dir.path()));
}

/// `--compare` learns the cache again after its renders: the same bytes as a
/// single mis-visibility render of the same size saves.
#[test]
fn compare_saves_the_cache_a_single_render_saves() {
    let dir = TempDir::new().unwrap();
    let single = dir.path().join("single.envlvis");
    let compared = dir.path().join("compare.envlvis");
    let size = [
        "--spp", "1", "--width", "12", "--height", "6", "--scene", "room",
    ];
    stdout_of(
        envlight()
            .args(["render", "--strategy", "mis-visibility"])
            .args(size)
            .arg("-o")
            .arg(dir.path().join("single.png"))
            .arg("--save-visibility")
            .arg(&single),
    );
    let table = stdout_of(
        envlight()
            .args(["render", "--compare", "--reference-spp", "1"])
            .args(["--equal-time", "0.01"])
            .args(size)
            .arg("-o")
            .arg(dir.path().join("compare.png"))
            .arg("--save-visibility")
            .arg(&compared),
    );
    assert!(
        table.lines().last().unwrap().contains("compare.envlvis"),
        "{table}"
    );
    assert_eq!(
        std::fs::read(&single).unwrap(),
        std::fs::read(&compared).unwrap()
    );
}
