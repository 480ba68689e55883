//! 2. Consistency of `sample()`, `pdf()` and `invert()`.

use crate::frame::{place, Frame, Place};
use crate::report::{Row, Verdict};
use crate::sampler::{Grid, SphereSample, SphereSampler};
use crate::stats::{finite_rgb, fits, over_sample_chunks};
use crate::{EDGE_BAND, INVERT_TOLERANCE};
use envlight::Vec3;
use std::fmt;

/// `pdf(sample(ξ).ω)` against `sample(ξ).pdf`, and `invert(sample(ξ).ω)` against `ξ`.
#[derive(Debug, Clone, Default)]
pub struct Consistency {
    /// `ξ` drawn.
    pub samples: usize,
    /// `sample` returned `None`.
    pub none: usize,
    /// Samples with a NaN/infinite/non-positive pdf, a non-unit or non-finite
    /// direction, or non-finite/negative radiance.
    pub malformed: usize,
    /// Exempt: within [`EDGE_BAND`] of a cell edge.
    pub near_edge: usize,
    /// Exempt: within [`POLE_BAND_SIN`](crate::POLE_BAND_SIN) of a pole.
    pub near_pole: usize,
    /// Samples checked.
    pub checked: usize,
    /// The relative pdf tolerance away from the poles (see [`crate::pdf_tolerance`]).
    pub tolerance: f64,
    /// Checked samples whose pdf disagreed by more than [`crate::pdf_tolerance`].
    pub pdf_failures: usize,
    /// Largest relative pdf disagreement among checked samples.
    pub max_pdf_error: f64,
    /// Checked samples whose inverse missed `ξ` by more than [`INVERT_TOLERANCE`].
    pub invert_failures: usize,
    /// Largest inversion error among checked samples.
    pub max_invert_error: f64,
    /// Checked samples for which `invert()` gave no answer (a sampler without an
    /// inverse, such as the alias table).
    pub no_inverse: usize,
    /// [`Consistency::max_exempt_fraction`] for the sampler's grid.
    pub max_exempt_fraction: f64,
    /// The worst offender, for the failure message: its badness (error over
    /// tolerance, the larger of the two checks; infinite when malformed) and a
    /// description.
    pub worst: Option<(f64, String)>,
}

impl Consistency {
    /// Exempt fraction allowed: edges and poles are measure-zero sets widened by
    /// float noise, so they hold a tiny fraction of the samples. Samples spread
    /// evenly within their cells put `2 EDGE_BAND (w + h)` of themselves in the edge
    /// bands of a `w × h` grid (1.6% for 16384 columns, 0.15% for 1024×512), twice
    /// as many along an axis whose centre lines are edges too; twice that plus 0.5%
    /// is allowed.
    pub fn max_exempt_fraction(grid: Option<Grid>) -> f64 {
        let expected = grid.map_or(0.0, |g| {
            let [w, h] = g.cells();
            let [cu, cv] = g.centre_edges().map(|c| if c { 2.0 } else { 1.0 });
            2.0 * EDGE_BAND * (cu * w as f64 + cv * h as f64)
        });
        2.0 * expected + 0.005
    }

    /// Passes when nothing is malformed, no checked sample fails and the exempt
    /// samples are a tiny fraction.
    pub fn verdict(&self) -> Result<(), String> {
        let exempt = (self.near_edge + self.near_pole) as f64 / self.samples.max(1) as f64;
        if self.malformed > 0
            || self.pdf_failures > 0
            || self.invert_failures > 0
            || exempt > self.max_exempt_fraction
        {
            Err(format!(
                "{self}; worst: {}",
                self.worst.as_ref().map_or("-", |w| w.1.as_str())
            ))
        } else {
            Ok(())
        }
    }

    fn merge(mut self, o: Self) -> Self {
        self.samples += o.samples;
        self.none += o.none;
        self.malformed += o.malformed;
        self.near_edge += o.near_edge;
        self.near_pole += o.near_pole;
        self.checked += o.checked;
        self.pdf_failures += o.pdf_failures;
        self.invert_failures += o.invert_failures;
        self.no_inverse += o.no_inverse;
        self.max_pdf_error = self.max_pdf_error.max(o.max_pdf_error);
        self.max_invert_error = self.max_invert_error.max(o.max_invert_error);
        self.worst = worse(self.worst, o.worst);
        self
    }
}

impl Consistency {
    fn exempt(&self) -> String {
        format!(
            "{} exempt at cell edges/poles (≤ {:.1e} allowed)",
            self.near_edge + self.near_pole,
            self.max_exempt_fraction
        )
    }

    /// The `pdf consistency` table row.
    pub fn pdf_row(&self) -> Row {
        let exempt_ok = (self.near_edge + self.near_pole) as f64
            <= self.max_exempt_fraction * self.samples.max(1) as f64;
        Row::new(
            "pdf consistency",
            format!(
                "max rel err {:.3e}; {} mismatches, {} malformed, {}",
                self.max_pdf_error,
                self.pdf_failures,
                self.malformed,
                self.exempt()
            ),
            format!("rel err ≤ {:.0e} off edges", self.tolerance),
            self.samples,
            Verdict::from_pass(self.malformed == 0 && self.pdf_failures == 0 && exempt_ok),
        )
    }

    /// The `invert` table row (skipped when the sampler has no inverse).
    pub fn invert_row(&self, sampler: &str) -> Row {
        if self.checked > 0 && self.no_inverse == self.checked {
            return Row::new(
                "invert",
                format!("n/a: the {sampler} sampler has no inverse"),
                "-",
                self.samples,
                Verdict::Skip,
            );
        }
        Row::new(
            "invert",
            format!(
                "max |Δξ| {:.3e}; {} off, {}",
                self.max_invert_error,
                self.invert_failures,
                self.exempt()
            ),
            format!("|Δξ| < {INVERT_TOLERANCE:.0e} off edges"),
            self.samples,
            Verdict::from_pass(self.invert_failures == 0),
        )
    }
}

impl fmt::Display for Consistency {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "consistency: {} samples ({} none, {} malformed), {} checked, exempt {} edge + {} pole ({:.2e} of ≤ {:.1e}); \
             pdf: {} fail, max rel err {:.1e}; invert: {} fail, max err {:.1e}",
            self.samples,
            self.none,
            self.malformed,
            self.checked,
            self.near_edge,
            self.near_pole,
            (self.near_edge + self.near_pole) as f64 / self.samples.max(1) as f64,
            self.max_exempt_fraction,
            self.pdf_failures,
            self.max_pdf_error,
            self.invert_failures,
            self.max_invert_error
        )
    }
}

fn worse(a: Option<(f64, String)>, b: Option<(f64, String)>) -> Option<(f64, String)> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.0 > a.0 { b } else { a }),
        (a, b) => a.or(b),
    }
}

/// What [`consistency`] makes of one sample before its `pdf()` is known.
#[derive(Clone, Copy)]
enum Class<'a> {
    /// `sample` returned `None`.
    None,
    Malformed(&'a SphereSample),
    NearEdge,
    NearPole,
    /// Checked against `pdf()` and `invert()`.
    Interior(&'a SphereSample),
}

impl<'a> Class<'a> {
    fn of(smp: &'a Option<SphereSample>, grid: Option<Grid>, frame: &Frame) -> Self {
        let Some(smp) = smp else {
            return Class::None;
        };
        let len = smp.direction.length();
        if !(smp.pdf.is_finite()
            && smp.pdf > 0.0
            && (len - 1.0).abs() < 1e-5
            && finite_rgb(smp.radiance))
        {
            return Class::Malformed(smp);
        }
        match place(grid, frame, smp.direction) {
            Place::NearEdge => Class::NearEdge,
            Place::NearPole => Class::NearPole,
            Place::Interior => Class::Interior(smp),
        }
    }
}

/// Draws `n` samples and checks each against `pdf()` (to the relative `tolerance`
/// away from the poles, normally [`crate::PDF_CONSISTENCY_TOLERANCE`]) and `invert()`.
/// Per chunk of samples it makes one [`SphereSampler::sample_batch`] and one
/// [`SphereSampler::pdf_batch`] call (over the directions that are checked);
/// `invert()` is asked sample by sample.
pub fn consistency(s: &dyn SphereSampler, n: usize, seed: u64, tolerance: f64) -> Consistency {
    let grid = s.grid();
    let frame = Frame::of(s);
    let mut c = over_sample_chunks(s, n, seed, Consistency::default, |c, xi, samples| {
        // Classify the chunk's samples, look up the pdfs of those to be checked in
        // one batch, then go through the samples in order.
        let classes: Vec<Class> = samples
            .iter()
            .map(|smp| Class::of(smp, grid, &frame))
            .collect();
        let directions: Vec<Vec3> = classes
            .iter()
            .filter_map(|class| match class {
                Class::Interior(smp) => Some(smp.direction),
                _ => None,
            })
            .collect();
        let mut pdfs = vec![0.0f32; directions.len()];
        if !directions.is_empty() {
            s.pdf_batch(&directions, &mut pdfs);
        }
        let mut pdfs = pdfs.into_iter();
        for (&xi, class) in xi.iter().zip(classes) {
            c.samples += 1;
            match class {
                Class::None => c.none += 1,
                Class::Malformed(smp) => {
                    c.malformed += 1;
                    let w = Some((
                        f64::INFINITY,
                        format!("malformed sample for ξ={xi:?}: {smp:?}"),
                    ));
                    c.worst = worse(c.worst.take(), w);
                }
                Class::NearEdge => c.near_edge += 1,
                Class::NearPole => c.near_pole += 1,
                Class::Interior(smp) => {
                    let p = pdfs.next().expect("one pdf per checked sample");
                    c.check(s, &frame, tolerance, xi, smp, p);
                }
            }
        }
    })
    .into_iter()
    .fold(Consistency::default(), Consistency::merge);
    c.max_exempt_fraction = Consistency::max_exempt_fraction(grid);
    c.tolerance = tolerance;
    c
}

impl Consistency {
    /// Checks one sample `smp`, drawn for `xi`, off the edges and poles, against
    /// `p`, its `pdf()`, and against `invert()`.
    fn check(
        &mut self,
        s: &dyn SphereSampler,
        frame: &Frame,
        tolerance: f64,
        xi: [f32; 2],
        smp: &SphereSample,
        p: f32,
    ) {
        let c = self;
        c.checked += 1;
        let p = p as f64;
        let rel = (p - smp.pdf as f64).abs() / smp.pdf as f64;
        let rel = if rel.is_nan() { f64::INFINITY } else { rel };
        let tolerance = frame
            .param
            .pdf_tolerance(tolerance, frame.local_uv(smp.direction));
        if !fits(rel, tolerance) {
            c.pdf_failures += 1;
        }
        let back = s.invert(smp.direction);
        c.no_inverse += back.is_none() as usize;
        let inv_err = back.map_or(0.0, |b| {
            let e = (b[0] as f64 - xi[0] as f64)
                .abs()
                .max((b[1] as f64 - xi[1] as f64).abs());
            if e.is_nan() {
                f64::INFINITY
            } else {
                e
            }
        });
        if !fits(inv_err, INVERT_TOLERANCE) {
            c.invert_failures += 1;
        }
        let badness = (rel / tolerance).max(inv_err / INVERT_TOLERANCE);
        let worst_so_far = match &c.worst {
            Some(w) => w.0,
            None => -1.0,
        };
        if badness > worst_so_far {
            c.worst = Some((
                badness,
                format!(
                    "ξ={xi:?} → ω={:?} (local uv {:?}): sample pdf {:e}, pdf() {p:e}, invert {back:?}",
                    smp.direction,
                    frame.local_uv(smp.direction),
                    smp.pdf,
                ),
            ));
        }
        c.max_pdf_error = c.max_pdf_error.max(rel);
        c.max_invert_error = c.max_invert_error.max(inv_err);
    }
}
