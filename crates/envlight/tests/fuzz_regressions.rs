//! Inputs the fuzzers once crashed on, replayed through the same checks the fuzz
//! targets run (their bodies are shared with `include!`). Add a file under
//! `fuzz/regressions/<target>/` for every crash fixed.

use std::path::PathBuf;

include!("../../../fuzz/fuzz_targets/common.rs");
include!("../../../fuzz/fuzz_targets/distribution_check.rs");

fn inputs(target: &str) -> Vec<(PathBuf, Vec<u8>)> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.unwrap().path())
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|p| {
            let bytes = std::fs::read(&p).unwrap();
            (p, bytes)
        })
        .collect()
}

#[test]
fn distribution_regressions() {
    let cases = inputs("distribution");
    assert!(
        !cases.is_empty(),
        "the fixed crash inputs are part of the repository"
    );
    for (path, bytes) in cases {
        println!("replaying {}", path.display());
        check_distribution(&bytes);
    }
}

#[test]
fn load_regressions() {
    // Replayed under every prefix the loader targets use.
    for (path, bytes) in inputs("load") {
        println!("replaying {}", path.display());
        for prefix in prefix::ALL {
            check_load(prefix, &bytes);
        }
    }
}
