//! `envlight shader`: every language and entry point, checked by the reference
//! validators where the machine has them (glslangValidator from Debian's
//! `glslang-tools`, spirv-val from `spirv-tools`). Without a validator the check is
//! skipped with one line, unless `ENVLIGHT_REQUIRE_GPU` is set (CI sets it): then
//! it fails, naming the package to install.

use std::path::{Path, PathBuf};

use envlight_gpu::shader::{ENTRY_POINTS, WGSL};
use predicates::prelude::*;
use tempfile::TempDir;

mod common;
use common::envlight;

/// `envlight shader ARGS` succeeds; its stdout.
fn shader(args: &[&str]) -> Vec<u8> {
    let out = envlight().arg("shader").args(args).output().unwrap();
    assert!(
        out.status.success(),
        "shader {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out.stdout
}

/// `program` on the PATH.
fn which(program: &str) -> Option<PathBuf> {
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|dir| dir.join(program))
            .find(|path| path.is_file())
    })
}

/// `program` on the PATH; if it is missing, `None` after one `skipping:` line, or
/// a failure naming `package` when `ENVLIGHT_REQUIRE_GPU` is set.
fn validator(program: &str, package: &str) -> Option<PathBuf> {
    let found = which(program);
    if found.is_none() {
        assert!(
            std::env::var_os("ENVLIGHT_REQUIRE_GPU").is_none(),
            "{program} not found, and ENVLIGHT_REQUIRE_GPU is set: install it with \
             `apt-get install {package}`"
        );
        eprintln!("skipping: {program} not found (apt-get install {package})");
    }
    found
}

/// Runs `program args… file` and fails with its output unless it succeeds.
fn validate(program: &Path, args: &[&str], file: &Path) {
    let out = std::process::Command::new(program)
        .args(args)
        .arg(file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{} {args:?} {} failed:\n{}{}",
        program.display(),
        file.display(),
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Writes every entry point in `lang` to `ENTRY.ext` and has the validator
/// `program` (from the Debian package `package`) pass each, called with `args`.
fn every_entry_point_passes(
    lang: &str,
    ext: &str,
    (program, package): (&str, &str),
    args: &[&str],
) {
    let Some(validator) = validator(program, package) else {
        return;
    };
    let dir = TempDir::new().unwrap();
    for entry in ENTRY_POINTS {
        let path = dir.path().join(format!("{entry}.{ext}"));
        let file = path.to_str().unwrap();
        shader(&["--lang", lang, "--entry", entry, "-o", file]);
        validate(&validator, args, &path);
    }
}

#[test]
fn glsl_passes_glslang_for_every_entry_point() {
    every_entry_point_passes(
        "glsl",
        "comp",
        ("glslangValidator", "glslang-tools"),
        &["-S", "comp"],
    );
}

#[test]
fn spirv_passes_spirv_val_for_every_entry_point() {
    // naga writes SPIR-V 1.3, the version Vulkan 1.1 consumes.
    every_entry_point_passes(
        "spirv",
        "spv",
        ("spirv-val", "spirv-tools"),
        &["--target-env", "vulkan1.1"],
    );
}

#[test]
fn hlsl_and_msl_are_text_naming_the_entry_point() {
    for lang in ["hlsl", "msl"] {
        for entry in ENTRY_POINTS {
            let text = String::from_utf8(shader(&["--lang", lang, "--entry", entry])).unwrap();
            assert!(text.contains(entry), "{lang} {entry}");
            assert!(
                text.contains("light_"),
                "{lang} {entry}: no library function"
            );
        }
    }
}

#[test]
fn wgsl_is_the_source_for_every_entry_point() {
    for entry in ENTRY_POINTS {
        assert_eq!(
            shader(&["--lang", "wgsl", "--entry", entry]),
            WGSL.as_bytes()
        );
    }
}

#[test]
fn the_default_entry_point_is_sample_main() {
    let glsl = shader(&["--lang", "glsl"]);
    assert_eq!(glsl, shader(&["--lang", "glsl", "--entry", "sample_main"]));
    assert_ne!(glsl, shader(&["--lang", "glsl", "--entry", "pdf_main"]));
}

#[test]
fn a_file_holds_what_stdout_gets_and_spirv_pipes() {
    let dir = TempDir::new().unwrap();
    for lang in ["glsl", "spirv"] {
        let path = dir.path().join(format!("shader.{lang}"));
        shader(&["--lang", lang, "-o", path.to_str().unwrap()]);
        // stdout here is a pipe, so SPIR-V is allowed on it.
        assert_eq!(std::fs::read(&path).unwrap(), shader(&["--lang", lang]));
    }
    let spirv = shader(&["--lang", "spirv"]);
    assert_eq!(spirv.len() % 4, 0);
    assert_eq!(spirv[..4], 0x0723_0203u32.to_le_bytes(), "SPIR-V magic");
}

#[test]
fn spirv_is_refused_on_a_terminal() {
    // `script` (util-linux) gives the command a pseudo-terminal for stdout; it is
    // not a GPU tool, so its absence never fails the test.
    let Some(script) = which("script") else {
        eprintln!("skipping: script not found (apt-get install bsdutils)");
        return;
    };
    let command = format!("{} shader --lang spirv", env!("CARGO_BIN_EXE_envlight"));
    let out = std::process::Command::new(script)
        .args(["-qec", &command, "/dev/null"])
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(2), "{text}");
    assert!(text.contains("use -o FILE"), "{text}");
    assert!(
        !text.contains("\u{3}\u{2}\u{23}\u{7}"),
        "SPIR-V reached the terminal"
    );
}

#[test]
fn bad_names_are_usage_errors() {
    for args in [
        &["--lang", "cuda"][..],
        &["--lang", "glsl", "--entry", "main"],
        &[],
    ] {
        envlight()
            .arg("shader")
            .args(args)
            .assert()
            .code(2)
            .stdout("");
    }
}

#[test]
fn help_explains_the_bindings() {
    envlight()
        .args(["shader", "--help"])
        .assert()
        .success()
        .stdout(predicate::str::contains("docs/gpu-tables.md"))
        .stdout(predicate::str::contains("read_write"))
        .stdout(predicate::str::contains("group 0"));
}
