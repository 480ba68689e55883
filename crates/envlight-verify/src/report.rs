//! One line of a verification table: what was measured, against what, and the
//! verdict. Every check's report gives one (`row()`), so that `envlight verify`
//! and other front ends print the library's findings without judging anything.

/// The outcome of one check.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Within its threshold.
    Pass,
    /// Outside its threshold.
    Fail,
    /// A figure reported, not judged.
    Info,
    /// Not run (nothing to check, or the sampler lacks the capability).
    Skip,
}

impl Verdict {
    /// `Pass` when `pass`, else `Fail`.
    pub fn from_pass(pass: bool) -> Self {
        if pass {
            Self::Pass
        } else {
            Self::Fail
        }
    }

    /// `pass`, `FAIL`, `info` or `skip`.
    pub fn label(self) -> &'static str {
        match self {
            Self::Pass => "pass",
            Self::Fail => "FAIL",
            Self::Info => "info",
            Self::Skip => "skip",
        }
    }
}

/// One check's result as a table row.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The check's name.
    pub check: String,
    /// The measured value(s), as text.
    pub value: String,
    /// The threshold it is judged against, as text.
    pub threshold: String,
    /// Samples the check drew (0 for quadrature-only checks).
    pub samples: usize,
    /// The verdict.
    pub verdict: Verdict,
}

impl Row {
    /// A row.
    pub fn new(
        check: impl Into<String>,
        value: impl Into<String>,
        threshold: impl Into<String>,
        samples: usize,
        verdict: Verdict,
    ) -> Self {
        Self {
            check: check.into(),
            value: value.into(),
            threshold: threshold.into(),
            samples,
            verdict,
        }
    }
}

/// `check | value | threshold | result`, columns padded to their widest entry,
/// with a rule under the header.
pub fn format_table(rows: &[Row]) -> String {
    let header = ["check", "value", "threshold", "result"];
    let cells: Vec<[&str; 4]> = rows
        .iter()
        .map(|r| {
            [
                r.check.as_str(),
                r.value.as_str(),
                r.threshold.as_str(),
                r.verdict.label(),
            ]
        })
        .collect();
    let mut widths = header.map(|h| h.chars().count());
    for row in &cells {
        for (w, cell) in widths.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: [&str; 4]| {
        let padded: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(k, cell)| {
                let pad = if k < 3 {
                    widths[k] - cell.chars().count()
                } else {
                    0
                };
                format!("{cell}{}", " ".repeat(pad))
            })
            .collect();
        padded.join(" | ") + "\n"
    };
    let rule: Vec<String> = widths.iter().map(|&w| "-".repeat(w)).collect();
    let mut text = line(header) + &rule.join("-+-") + "\n";
    for row in cells {
        text.push_str(&line(row));
    }
    text
}

/// `x` with `digits` significant digits: fixed notation for moderate magnitudes,
/// scientific otherwise.
pub(crate) fn sig(x: f64, digits: usize) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let magnitude = x.abs().log10().floor() as i64;
    if (-3..6).contains(&magnitude) {
        let decimals = (digits as i64 - 1 - magnitude).max(0) as usize;
        format!("{x:.decimals$}")
    } else {
        format!("{x:.prec$e}", prec = digits - 1)
    }
}
