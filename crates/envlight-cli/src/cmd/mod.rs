//! One module per subcommand. Each has an `Args` type (clap derive) and a
//! `run(&Args) -> anyhow::Result<Outcome>`.
//! `render` returns `()` and is mapped to [`Outcome::Success`] in `main.rs`.

pub mod bench;
pub mod eval;
pub mod export;
pub mod importance;
pub mod info;
pub mod render;
pub mod sample;
pub mod shader;
pub mod sun;
pub mod verify;
pub mod visibility;

/// How a subcommand that did not hit an error ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// Everything worked: exit status 0.
    Success,
    /// The command ran but reports a failure in what it examined (e.g. `verify`
    /// found a failing check): exit status 1, with no `error:` line.
    ChecksFailed,
}

/// An error in how the command was called that clap could not catch (exit status 2).
#[derive(Debug)]
pub struct UsageError(pub String);

impl std::fmt::Display for UsageError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for UsageError {}
