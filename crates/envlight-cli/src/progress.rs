//! Progress display: an `indicatif` bar on stderr when stderr is a terminal, and
//! nothing at all otherwise (so logs and pipes stay clean).
//!
//! Bars only become visible after a short delay, so quick work draws nothing even
//! on a terminal.

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Work shorter than this never shows a bar.
const SHOW_AFTER: Duration = Duration::from_millis(700);

/// True when progress should be drawn (stderr is an interactive terminal).
pub fn enabled() -> bool {
    std::io::stderr().is_terminal()
}

/// A progress handle; a no-op when progress is disabled. `Sync`: worker threads
/// may call [`Progress::inc`] through a shared reference.
pub struct Progress {
    bar: ProgressBar,
    started: std::time::Instant,
    visible: bool,
}

impl Progress {
    /// A bar for `len` units of work described by `message`.
    pub fn bar(len: u64, message: &str) -> Self {
        let style = ProgressStyle::with_template(
            "{msg:>12} [{bar:40.cyan/blue}] {human_pos}/{human_len} ({eta})",
        )
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
        Self::new(ProgressBar::hidden().with_style(style), Some(len), message)
    }

    /// A running count for work of unknown length (rows of a stream).
    pub fn counter(message: &str) -> Self {
        let style = ProgressStyle::with_template("{spinner} {msg} {human_pos} ({per_sec})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner());
        Self::new(ProgressBar::hidden().with_style(style), None, message)
    }

    /// A spinner for one step of unknown length (loading a map, building a light),
    /// drawn at once on a terminal.
    pub fn spinner(message: &str) -> Self {
        let style = ProgressStyle::with_template("{spinner} {msg} ({elapsed})")
            .unwrap_or_else(|_| ProgressStyle::default_spinner());
        let progress = Self::new(ProgressBar::hidden().with_style(style), None, message);
        if progress.visible {
            progress.bar.set_draw_target(ProgressDrawTarget::stderr());
            progress.bar.enable_steady_tick(Duration::from_millis(120));
        }
        progress
    }

    fn new(bar: ProgressBar, len: Option<u64>, message: &str) -> Self {
        if let Some(len) = len {
            bar.set_length(len);
        }
        bar.set_message(message.to_string());
        Self {
            bar,
            started: std::time::Instant::now(),
            visible: enabled(),
        }
    }

    /// Advances the bar by `delta` units.
    pub fn inc(&self, delta: u64) {
        if self.visible {
            if self.bar.is_hidden() && self.started.elapsed() >= SHOW_AFTER {
                self.bar.set_draw_target(ProgressDrawTarget::stderr());
            }
            self.bar.inc(delta);
        }
    }

    /// Replaces the bar's message (the step under way).
    pub fn set_message(&self, message: &str) {
        if self.visible {
            self.bar.set_message(message.to_string());
        }
    }

    /// Removes the bar from the terminal.
    pub fn finish(&self) {
        if self.visible {
            self.bar.finish_and_clear();
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        if self.visible && !self.bar.is_finished() {
            self.bar.finish_and_clear();
        }
    }
}
