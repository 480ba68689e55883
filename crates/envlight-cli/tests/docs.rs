//! The guides' code blocks (README.md and docs/*.md) are part of the test command.
//!
//! `every_code_block_has_a_runner` lists every fenced block with what runs it and
//! fails on a block nothing runs: a new block must be Rust (a doctest of the crate
//! that includes its guide), Python (`python/tests/test_docs.py`), C, C++ or CMake
//! (`crates/envlight-c/tests/c_programs.rs`), shell (`shell_blocks_run`, here),
//! install instructions (`sh setup`: read, not run) or program output (`text`,
//! `json`, `csv`). `shell_blocks_run` runs every `sh` block with the built `envlight`
//! and checks that it exits 0.

#[path = "common/doc_blocks.rs"]
mod doc_blocks;

use doc_blocks::{all_blocks, blocks, guides, repo_root, Block};
use std::path::Path;
use std::process::Command;

/// Programs an `sh setup` block may name: installers and the project's scripts.
const SETUP_COMMANDS: &[&str] = &[
    "apt-get", "pip", "python3", "bash", "export", "cc", "c++", "cmake", "cargo",
];

/// The real maps a guide may name; they are linked into the folder its shell and
/// Python blocks run in.
const SHARED_MAPS: &[&str] = &[
    "sunrise.exr",
    "city.exr",
    "night.exr",
    "studio.exr",
    "courtyard.exr",
    "colorful_studio_2k.hdr",
];

fn read(path: &str) -> String {
    std::fs::read_to_string(repo_root().join(path)).unwrap_or_else(|e| panic!("{path}: {e}"))
}

/// What runs `block`, or why nothing does.
fn runner(block: &Block) -> Result<String, String> {
    let info = block.info.as_str();
    let language = info.split([',', ' ']).next().unwrap_or("");
    match language {
        "rust" => {
            if let Some(bad) = ["ignore", "no_run", "compile_fail"]
                .iter()
                .find(|a| info.contains(**a))
            {
                return Err(format!("a Rust block marked `{bad}` is not run"));
            }
            let (krate, needle) = match block.file.as_str() {
                "README.md" => ("envlight", "../repository-README.md".to_string()),
                "docs/gpu.md" => ("envlight-gpu", "../docs/gpu.md".to_string()),
                docs => ("envlight", format!("../{docs}")),
            };
            let lib = read(&format!("crates/{krate}/src/lib.rs"));
            if lib.contains(&format!("include_str!(\"{needle}\")")) {
                Ok(format!("doctest of {krate}"))
            } else {
                Err(format!(
                    "{} is not included as doctests: add `#[doc = include_str!(\"{needle}\")]` \
                     to crates/{krate}/src/lib.rs",
                    block.file
                ))
            }
        }
        "python" => {
            let runner = "python/tests/test_docs.py";
            if repo_root().join(runner).is_file() && read("scripts/test").contains("python/tests") {
                Ok(runner.to_string())
            } else {
                Err(format!(
                    "{runner} is missing or scripts/test does not run python/tests"
                ))
            }
        }
        "c" | "cpp" | "cmake" => {
            if read("crates/envlight-c/tests/c_programs.rs")
                .contains("fn docs_code_blocks_build_and_run")
            {
                Ok("crates/envlight-c/tests/c_programs.rs".to_string())
            } else {
                Err("c_programs.rs has no docs_code_blocks_build_and_run".to_string())
            }
        }
        "sh" if info == "sh" => Ok("shell_blocks_run (tests/docs.rs)".to_string()),
        "sh" if info == "sh setup" => {
            for line in commands(&block.code) {
                let program = line.split_whitespace().next().unwrap_or("");
                if !SETUP_COMMANDS.contains(&program) {
                    return Err(format!("`{program}` is not an install command ({line})"));
                }
                if let Some(script) = line.strip_prefix("bash ") {
                    let script = script.split_whitespace().next().unwrap_or("");
                    if !repo_root().join(script).is_file() {
                        return Err(format!("{script} does not exist"));
                    }
                }
            }
            Ok("install instructions (read, not run)".to_string())
        }
        "text" | "json" | "csv" => Ok("program output (not run)".to_string()),
        _ => Err(format!(
            "no runner for a ```{info} block: use rust, python, c, cpp, cmake, sh, \
             `sh setup`, text, json or csv"
        )),
    }
}

/// The command lines of a shell block: without comments, blank lines and
/// continuations joined.
fn commands(code: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut current = String::new();
    for line in code.lines() {
        let line = line.trim();
        if current.is_empty() && (line.is_empty() || line.starts_with('#')) {
            continue;
        }
        match line.strip_suffix('\\') {
            Some(head) => current.push_str(head),
            None => {
                current.push_str(line);
                out.push(std::mem::take(&mut current));
            }
        }
    }
    out
}

#[test]
fn every_code_block_has_a_runner() {
    let mut failures = Vec::new();
    let all = all_blocks();
    assert!(all.len() > 10, "found only {} blocks", all.len());
    for block in &all {
        match runner(block) {
            Ok(runner) => println!("{}:{} ```{} → {runner}", block.file, block.line, block.info),
            Err(why) => failures.push(format!("{}:{}: {why}", block.file, block.line)),
        }
    }
    assert!(
        failures.is_empty(),
        "blocks nothing runs:\n{}",
        failures.join("\n")
    );
}

/// Caps the sizes a guide asks for, so its commands take seconds; every option
/// keeps its meaning.
const WRAPPER: &str = r#"#!/usr/bin/env bash
set -euo pipefail
limit_for() {
    case "$1" in
        -n | --samples | --queries) echo 2000 ;;
        --spp) echo 4 ;;
        --width) echo 128 ;;
        --height) echo 72 ;;
        --repeat) echo 2 ;;
        --equal-time) echo 0.5 ;;
        *) echo "" ;;
    esac
}
cap() { awk -v a="$1" -v b="$2" 'BEGIN { if (a + 0 > b + 0) print b; else print a }'; }
args=()
while [ $# -gt 0 ]; do
    arg=$1
    shift
    case "$arg" in
        --*=*)
            key=${arg%%=*} value=${arg#*=} limit=$(limit_for "${arg%%=*}")
            if [ -n "$limit" ]; then value=$(cap "$value" "$limit"); fi
            args+=("$key=$value")
            ;;
        *)
            limit=$(limit_for "$arg")
            if [ -n "$limit" ] && [ $# -gt 0 ]; then
                args+=("$arg" "$(cap "$1" "$limit")")
                shift
            else
                args+=("$arg")
            fi
            ;;
    esac
done
exec "$ENVLIGHT_REAL" "${args[@]}"
"#;

/// `cargo run --release -- ARGS` as the guides write the main job; `bash
/// scripts/test`, the test command, is what is running this test.
const PRELUDE: &str = r#"bash() {
    if [ "$*" = scripts/test ]; then
        echo "(bash scripts/test is the command running this test)"
    else
        command bash "$@"
    fi
}
cargo() {
    if [ "${1-}" = run ] && [ "${2-}" = --release ] && [ "${3-}" = -- ]; then
        shift 3
        envlight "$@"
    else
        echo "the docs test runs only 'cargo run --release -- ...', not: cargo $*" >&2
        return 1
    fi
}
"#;

#[test]
fn shell_blocks_run() {
    let shared = repo_root().join("../shared/envmaps");
    let real = Path::new(env!("CARGO_BIN_EXE_envlight"));
    let mut ran = 0;
    // Blocks that ask for `--device gpu` need an adapter: without one they are
    // skipped with a line saying so, as the GPU tests are, unless
    // ENVLIGHT_REQUIRE_GPU asks for a failure (CI, on lavapipe).
    let no_gpu = Command::new(real)
        .args(["info", "--device", "gpu"])
        .output()
        .ok()
        .filter(|o| !o.status.success())
        .map(|o| String::from_utf8_lossy(&o.stderr).trim().to_string());
    if let Some(why) = &no_gpu {
        assert!(
            std::env::var_os("ENVLIGHT_REQUIRE_GPU").is_none(),
            "ENVLIGHT_REQUIRE_GPU is set but `envlight info --device gpu` fails: {why}"
        );
    }
    for file in guides() {
        let shells: Vec<Block> = blocks(&file)
            .into_iter()
            .filter(|b| b.info == "sh")
            .collect();
        if shells.is_empty() {
            continue;
        }
        if let Some(map) = SHARED_MAPS
            .iter()
            .find(|m| shells.iter().any(|b| b.code.contains(**m)) && !shared.join(m).is_file())
        {
            println!("skipping {file}'s shell blocks: {map} is not in ../shared/envmaps");
            continue;
        }
        let work = tempfile::tempdir().expect("a temporary folder");
        let bin = work.path().join(".bin");
        std::fs::create_dir(&bin).unwrap();
        let wrapper = bin.join("envlight");
        std::fs::write(&wrapper, WRAPPER).unwrap();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&wrapper, std::fs::Permissions::from_mode(0o755)).unwrap();
        }
        #[cfg(unix)]
        for map in SHARED_MAPS {
            if shared.join(map).is_file() {
                std::os::unix::fs::symlink(shared.join(map), work.path().join(map)).unwrap();
            }
        }
        let path = format!(
            "{}:{}",
            bin.display(),
            std::env::var("PATH").unwrap_or_default()
        );
        for block in &shells {
            if let (Some(why), true) = (&no_gpu, block.code.contains("--device gpu")) {
                println!("{}:{}: skipped ({why})", block.file, block.line);
                continue;
            }
            let output = Command::new("bash")
                .args(["-eo", "pipefail", "-c"])
                .arg(format!("{PRELUDE}{}", block.code))
                .current_dir(work.path())
                .env("PATH", &path)
                .env("ENVLIGHT_REAL", real)
                .output()
                .expect("bash");
            assert!(
                output.status.success(),
                "{}:{}: the block failed ({}):\n{}\nstdout:\n{}\nstderr:\n{}",
                block.file,
                block.line,
                output.status,
                block.code,
                String::from_utf8_lossy(&output.stdout),
                String::from_utf8_lossy(&output.stderr)
            );
            println!("{}:{}: ran", block.file, block.line);
            ran += 1;
        }
    }
    println!("{ran} shell blocks ran");
}
