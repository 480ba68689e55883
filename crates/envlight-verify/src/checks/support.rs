//! 4. Support: `p(ω) > 0` wherever the integrand is.

use crate::frame::Frame;
use crate::integrand::Integrand;
use crate::report::{Row, Verdict};
use crate::sampler::SphereSampler;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::fmt;

/// `p(ω) > 0` wherever the integrand `Y(L(ω))·f(ω) > 0`, probed at every cell's
/// centre and 2% in from each of its corners.
#[derive(Debug, Clone, Default)]
pub struct Support {
    /// Probes evaluated.
    pub probes: usize,
    /// Probes skipped because they lie within [`POLE_BAND_SIN`](crate::POLE_BAND_SIN) of a pole.
    pub near_pole: usize,
    /// Probes where the integrand is positive (`L > 0` and a positive factor).
    pub lit: usize,
    /// Lit probes with `p == 0` (or a non-finite pdf).
    pub violations: usize,
    /// The first violation (cell and probe position in cell units).
    pub first: Option<String>,
}

impl Support {
    /// No violation allowed.
    pub fn verdict(&self) -> Result<(), String> {
        if self.violations == 0 {
            Ok(())
        } else {
            Err(format!(
                "{self}; first: {}",
                self.first.as_deref().unwrap_or("-")
            ))
        }
    }
}

impl Support {
    /// The table row.
    pub fn row(&self) -> Row {
        Row::new(
            "support",
            match &self.first {
                None => format!("{} lit probes, all with pdf > 0", self.lit),
                Some(first) => format!("{} lit probes with pdf 0, first {first}", self.violations),
            },
            "0 lit probes with pdf 0",
            0,
            Verdict::from_pass(self.violations == 0),
        )
    }
}

impl fmt::Display for Support {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "support: {} probes ({} skipped near a pole), {} lit, {} lit with pdf 0",
            self.probes, self.near_pole, self.lit, self.violations
        )
    }
}

/// Probes the support. Radiance reconstructed from a cell's 3×3 neighbourhood
/// (bilinear, wrapping in u and clamping in v on the lat-long map, clamping in both
/// on the equal-area square) reaches the probe 2% from a corner of the cell with
/// weight ≥ 0.48² from each of the four texels around that corner, so the five
/// probes see every neighbour that can light the cell. Probes are placed in the
/// grid's own `(u, v)` and mapped by the harness's mapping. On the lat-long map,
/// probes within [`POLE_BAND_SIN`](crate::POLE_BAND_SIN) of a pole are skipped: "up to the measure-zero
/// poles" (docs/design.md §5), widened to where an f32 direction no longer pins θ down;
/// the equal-area square has no such points.
pub fn support(s: &dyn SphereSampler, integrand: &Integrand) -> Support {
    let [w, h] = s.grid().map_or([512, 256], |g| g.cells());
    let frame = Frame::of(s);
    const INSET: f64 = 0.02;
    let probes = [
        [0.5, 0.5],
        [INSET, INSET],
        [1.0 - INSET, INSET],
        [INSET, 1.0 - INSET],
        [1.0 - INSET, 1.0 - INSET],
    ];
    // Probes share three u offsets and three v offsets per cell.
    let offsets = [INSET, 0.5, 1.0 - INSET];
    let us: Vec<f64> = (0..w)
        .flat_map(|i| offsets.map(|o| (i as f64 + o) / w as f64))
        .collect();
    let u_trig: Vec<(f64, f64)> = us.iter().map(|u| (2.0 * PI * u).sin_cos()).collect();
    let rows: Vec<Support> = (0..h)
        .into_par_iter()
        .map(|j| {
            let mut r = Support::default();
            // The row's probes off the poles, their radiance and pdf in batches.
            let mut at = Vec::with_capacity(w * probes.len());
            let mut directions = Vec::with_capacity(w * probes.len());
            let mut line = Vec::with_capacity(us.len());
            for (k, p) in probes.iter().enumerate() {
                let v = (j as f64 + p[1]) / h as f64;
                r.probes += w;
                if frame.param.near_pole([0.0, v]) {
                    r.near_pole += w;
                    continue;
                }
                line.clear();
                frame.world_row(&us, &u_trig, v, &mut line);
                let column = offsets.iter().position(|&o| o == p[0]).unwrap_or(1);
                for i in 0..w {
                    at.push((i, k));
                    directions.push(line[3 * i + column]);
                }
            }
            let mut radiance = vec![[0.0f32; 3]; directions.len()];
            let mut pdf = vec![0.0f32; directions.len()];
            s.radiance_batch(&directions, &mut radiance);
            s.pdf_batch(&directions, &mut pdf);
            for (q, &(i, k)) in at.iter().enumerate() {
                let (l, p, d) = (radiance[q], pdf[q], directions[q]);
                if !(l.iter().any(|&c| c > 0.0) && integrand.factor(d) > 0.0) {
                    continue;
                }
                r.lit += 1;
                if !(p > 0.0 && p.is_finite()) {
                    r.violations += 1;
                    r.first.get_or_insert_with(|| {
                        format!(
                            "cell ({i}, {j}) of {w}x{h} at ({:.2}, {:.2}): L={l:?}, pdf={p:e}",
                            probes[k][0], probes[k][1]
                        )
                    });
                }
            }
            r
        })
        .collect();
    rows.into_iter().fold(Support::default(), |mut a, r| {
        a.probes += r.probes;
        a.near_pole += r.near_pole;
        a.lit += r.lit;
        a.violations += r.violations;
        a.first = a.first.or(r.first);
        a
    })
}
