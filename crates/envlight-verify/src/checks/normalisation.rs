//! 1. Normalisation: `∫ p dω = 1`.

use crate::quadrature::{Needs, Quadrature};
use crate::report::{Row, Verdict};
use crate::sampler::SphereSampler;
use crate::NORMALISATION_TOLERANCE;
use std::fmt;

/// `∫ p dω` by quadrature.
#[derive(Debug, Clone)]
pub struct Normalisation {
    /// The integral.
    pub integral: f64,
    /// Points where the pdf was NaN, infinite or negative.
    pub bad_values: usize,
    /// The rule used.
    pub rule: String,
}

impl Normalisation {
    /// Must be 1 (to [`NORMALISATION_TOLERANCE`]), or exactly 0 when `black`.
    pub fn verdict(&self, black: bool) -> Result<(), String> {
        if self.bad_values > 0 {
            return Err(format!(
                "{} non-finite or negative pdf values",
                self.bad_values
            ));
        }
        let ok = if black {
            self.integral == 0.0
        } else {
            (1.0 - self.integral).abs() <= NORMALISATION_TOLERANCE
        };
        if ok {
            Ok(())
        } else {
            Err(format!(
                "∫p dω = {:.6} (|1-∫p| = {:.2e})",
                self.integral,
                (1.0 - self.integral).abs()
            ))
        }
    }
}

impl Normalisation {
    /// The table row (`black`: see [`Self::verdict`]).
    pub fn row(&self, black: bool) -> Row {
        Row::new(
            "normalisation",
            format!("∫p dω = {:.7} ({})", self.integral, self.rule),
            format!("|1 - ∫p dω| < {NORMALISATION_TOLERANCE:.0e}"),
            0,
            Verdict::from_pass(self.verdict(black).is_ok()),
        )
    }
}

impl fmt::Display for Normalisation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "normalisation: ∫p dω = {:.7} |1-∫p| = {:.1e} ({})",
            self.integral,
            (1.0 - self.integral).abs(),
            self.rule
        )
    }
}

/// Integrates the sampler's `pdf()` over the sphere: cells that subdivide the
/// sampler's cells (at least 256×128 overall, or as many on the equal-area square,
/// fewer than ~4M unless the grid itself is larger), 2×2 Gauss-Legendre points
/// each, weighted by the exact measure. For a density piecewise constant in
/// (u, v) this is exact up to the rule's error in `sin θ`, O(Δθ⁴), on the lat-long
/// map, and exact on the equal-area square (`dω = 4π du dv`); dropping or
/// misplacing the `1/sin θ` (or `1/4π`) of the solid-angle pdf shows up at O(1).
///
/// A sampler with a fold ([`SphereSampler::fold`]) gets its cells split at their
/// centre lines as well, where a bilinear density has its kinks: the rule's error
/// on such a density cancels over the sphere as a whole only, and the cells the
/// fold's circles cross are integrated apart (finely), which would leave their
/// neighbours' share of it (0.7% on a sky with its sun near the band's edge).
pub fn normalisation(s: &dyn SphereSampler) -> Normalisation {
    let step = if s.fold().is_some() { 2 } else { 1 };
    let q = Quadrature::for_sampler(s, step, [256, 128], 4 << 20, 2);
    let [integral, bad] = q.sum(s, Needs::PDF, |pt| {
        let p = pt.pdf;
        if p.is_finite() && p >= 0.0 {
            [p as f64 * pt.weight, 0.0]
        } else {
            [0.0, 1.0]
        }
    });
    Normalisation {
        integral,
        bad_values: bad as usize,
        rule: q.describe(),
    }
}
