//! The fenced code blocks of README.md and docs/*.md, for the tests that run them:
//! `crates/envlight-cli/tests/docs.rs` (the inventory and the `sh` blocks),
//! `crates/envlight-c/tests/c_programs.rs` (`c`, `cpp`, `cmake`); the Rust blocks
//! are doctests and `python/tests/test_docs.py` runs the Python ones (with its own
//! copy of this parser, a dozen lines).

use std::path::{Path, PathBuf};

/// One fenced block: where it starts, its info string and its text.
#[derive(Debug, Clone)]
pub struct Block {
    /// The guide, relative to the repository (`README.md`, `docs/cli.md`).
    pub file: String,
    /// The 1-based line of the opening fence.
    pub line: usize,
    /// The info string after the fence (`rust`, `sh setup`, ...), trimmed.
    pub info: String,
    /// The lines between the fences, each ending in a newline.
    pub code: String,
}

/// The repository's root (every crate lives in `crates/<name>`).
pub fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// README.md, then every `docs/*.md` in name order.
pub fn guides() -> Vec<String> {
    let mut docs: Vec<String> = std::fs::read_dir(repo_root().join("docs"))
        .expect("docs/")
        .map(|e| {
            e.expect("a docs/ entry")
                .file_name()
                .to_string_lossy()
                .into_owned()
        })
        .filter(|name| name.ends_with(".md"))
        .map(|name| format!("docs/{name}"))
        .collect();
    docs.sort();
    let mut all = vec!["README.md".to_string()];
    all.extend(docs);
    all
}

/// The fenced blocks of one guide. A fence is three or more backticks at the start
/// of a line (up to three spaces in); it closes at a line of at least as many
/// backticks and nothing else. An unclosed fence is an error.
pub fn blocks(file: &str) -> Vec<Block> {
    let text = std::fs::read_to_string(repo_root().join(file))
        .unwrap_or_else(|e| panic!("cannot read {file}: {e}"));
    let mut out = Vec::new();
    let mut open: Option<(usize, usize, String, String)> = None; // line, ticks, info, code
    for (index, line) in text.lines().enumerate() {
        let trimmed = line.trim_start_matches(' ');
        let indent = line.len() - trimmed.len();
        let ticks = trimmed.chars().take_while(|&c| c == '`').count();
        match &mut open {
            None if indent <= 3 && ticks >= 3 => {
                open = Some((
                    index + 1,
                    ticks,
                    trimmed[ticks..].trim().to_string(),
                    String::new(),
                ));
            }
            None => {}
            Some((start, n, info, code)) => {
                if indent <= 3 && ticks >= *n && trimmed[ticks..].trim().is_empty() {
                    out.push(Block {
                        file: file.to_string(),
                        line: *start,
                        info: std::mem::take(info),
                        code: std::mem::take(code),
                    });
                    open = None;
                } else {
                    code.push_str(line);
                    code.push('\n');
                }
            }
        }
    }
    if let Some((start, ..)) = open {
        panic!("{file}:{start}: a code fence that never closes");
    }
    out
}

/// Every block of every guide.
pub fn all_blocks() -> Vec<Block> {
    guides().iter().flat_map(|file| blocks(file)).collect()
}
