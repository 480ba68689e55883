//! Degenerate input: what a sampler of an all-black light must do.

use crate::quadrature::{Needs, Quadrature};
use crate::sampler::SphereSampler;
use crate::stats::{finite_rgb, over_sample_chunks};
use std::fmt;

/// What a sampler of an all-black light does.
#[derive(Debug, Clone, Default)]
pub struct Black {
    /// `ξ` drawn.
    pub samples: usize,
    /// Samples that came back `Some` (must be 0).
    pub some: usize,
    /// Quadrature points with a pdf other than exactly 0 (NaN included).
    pub nonzero_pdf: usize,
    /// Quadrature points with non-finite radiance.
    pub bad_radiance: usize,
    /// Quadrature points.
    pub points: usize,
}

impl Black {
    /// Nothing sampled, pdf 0 everywhere, no NaN, zero integral and efficiency.
    pub fn verdict(&self, s: &dyn SphereSampler) -> Result<(), String> {
        let eff = s.reported_efficiency().unwrap_or(0.0);
        if self.some == 0
            && self.nonzero_pdf == 0
            && self.bad_radiance == 0
            && s.integral_luminance() == 0.0
            && eff == 0.0
        {
            Ok(())
        } else {
            Err(format!(
                "{self}; ∫Y = {}, efficiency = {eff}",
                s.integral_luminance()
            ))
        }
    }
}

impl fmt::Display for Black {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "black: {} samples → {} Some; {} pdf points → {} non-zero, {} bad radiance",
            self.samples, self.some, self.points, self.nonzero_pdf, self.bad_radiance
        )
    }
}

/// Samples and probes an all-black sampler.
pub fn black(s: &dyn SphereSampler, n: usize, seed: u64) -> Black {
    let some = over_sample_chunks(
        s,
        n,
        seed,
        || 0usize,
        |c, _, samples| *c += samples.iter().filter(|smp| smp.is_some()).count(),
    )
    .iter()
    .sum();
    let q = Quadrature::for_sampler(s, 1, [64, 32], 1 << 20, 2);
    let [nonzero, bad, points] = q.sum(s, Needs::BOTH, |pt| {
        [
            (pt.pdf != 0.0) as u8 as f64,
            (!finite_rgb(pt.radiance)) as u8 as f64,
            1.0,
        ]
    });
    Black {
        samples: n,
        some,
        nonzero_pdf: nonzero as usize,
        bad_radiance: bad as usize,
        points: points as usize,
    }
}
