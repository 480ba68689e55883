//! Shared test harness: a chi-square goodness-of-fit test for direction samplers
//! (after Mitsuba 3's `ChiSquareTest`), and helpers.

#![allow(dead_code)]

use envlight::rng::{mix64, SplitMix64};
use envlight::Vec3;
use statrs::distribution::{ChiSquared, ContinuousCDF};
use std::f64::consts::PI;

/// Outcome of [`chi_square`].
#[derive(Debug, Clone, Copy)]
pub struct ChiSquare {
    /// Pearson's statistic over the pooled bins.
    pub statistic: f64,
    /// Degrees of freedom (bins used − 1).
    pub dof: usize,
    /// Probability of a statistic at least this large if the sampler is right.
    pub p_value: f64,
    /// `∫ pdf dω` over the binned region, by quadrature.
    pub integral: f64,
}

/// Gauss–Legendre nodes and weights on [0, 1], 3 points.
const GL_T: [f64; 3] = [0.112_701_665_379_258_3, 0.5, 0.887_298_334_620_741_7];
const GL_W: [f64; 3] = [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0];

/// Draws `n` directions with `sample(ξ)` (`ξ ∈ [0,1)³`, `None` = no direction) and
/// compares their histogram over a `(cos θ, φ)` grid of `n_z × n_phi` bins covering
/// `cos θ ∈ [z0, z1]` with the counts that `pdf` predicts: each bin's expected count
/// is `n ∫_bin pdf dω`, by Gauss–Legendre quadrature (3 nodes) on `sub × sub` sub-cells
/// (`dω = d(cos θ) dφ`). Samples that are `None` or fall outside the grid go to one
/// extra bin whose expected count is `n (1 − ∫ pdf)`. Bins expected to hold fewer
/// than 5 samples are pooled into one.
#[allow(clippy::too_many_arguments)]
pub fn chi_square(
    sample: impl Fn([f32; 3]) -> Option<Vec3>,
    pdf: impl Fn(Vec3) -> f32,
    (z0, z1): (f64, f64),
    n_z: usize,
    n_phi: usize,
    sub: usize,
    n: usize,
    seed: u64,
) -> ChiSquare {
    let bins = n_z * n_phi;
    let mut observed = vec![0.0f64; bins + 1];
    let mut rng = SplitMix64::new(mix64(seed));
    for _ in 0..n {
        let xi = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
        let bin = sample(xi).and_then(|w| {
            let z = w.z as f64;
            if !(z >= z0 && z <= z1) {
                return None;
            }
            let iz = (((z - z0) / (z1 - z0)) * n_z as f64) as usize;
            let mut phi = (w.y as f64).atan2(w.x as f64);
            if phi < 0.0 {
                phi += 2.0 * PI;
            }
            let ip = ((phi / (2.0 * PI)) * n_phi as f64) as usize;
            Some(iz.min(n_z - 1) * n_phi + ip.min(n_phi - 1))
        });
        observed[bin.unwrap_or(bins)] += 1.0;
    }

    let mut expected = vec![0.0f64; bins + 1];
    let dz = (z1 - z0) / n_z as f64;
    let dphi = 2.0 * PI / n_phi as f64;
    let (sz, sp) = (dz / sub as f64, dphi / sub as f64);
    let mut integral = 0.0;
    for iz in 0..n_z {
        for ip in 0..n_phi {
            let mut acc = 0.0;
            for a in 0..sub {
                for (ta, wa) in GL_T.iter().zip(GL_W) {
                    let z = z0 + iz as f64 * dz + (a as f64 + ta) * sz;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    for b in 0..sub {
                        for (tb, wb) in GL_T.iter().zip(GL_W) {
                            let phi = ip as f64 * dphi + (b as f64 + tb) * sp;
                            let w =
                                Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                            acc += wa * wb * pdf(w) as f64;
                        }
                    }
                }
            }
            let mass = acc * sz * sp;
            integral += mass;
            expected[iz * n_phi + ip] = mass * n as f64;
        }
    }
    expected[bins] = (1.0 - integral).max(0.0) * n as f64;

    // Pool small bins.
    let (mut stat, mut used) = (0.0, 0usize);
    let (mut pooled_o, mut pooled_e) = (0.0, 0.0);
    for (&o, &e) in observed.iter().zip(&expected) {
        if e < 5.0 {
            pooled_o += o;
            pooled_e += e;
        } else {
            stat += (o - e) * (o - e) / e;
            used += 1;
        }
    }
    if pooled_e > 0.0 {
        stat += (pooled_o - pooled_e) * (pooled_o - pooled_e) / pooled_e;
        used += 1;
    } else if pooled_o > 0.0 {
        // Samples where the pdf says there can be none.
        stat = f64::INFINITY;
    }
    let dof = used.saturating_sub(1).max(1);
    let p_value = ChiSquared::new(dof as f64).unwrap().sf(stat);
    ChiSquare {
        statistic: stat,
        dof,
        p_value,
        integral,
    }
}

/// A unit direction at polar angle `theta_deg` from +z, in the xz plane.
pub fn polar(theta_deg: f32) -> Vec3 {
    let t = theta_deg.to_radians();
    Vec3::new(t.sin(), 0.0, t.cos())
}

/// Mean and standard error of the mean, per channel.
pub fn mean_and_error(values: &[[f32; 3]]) -> ([f64; 3], [f64; 3]) {
    let n = values.len() as f64;
    let mut mean = [0.0; 3];
    let mut se = [0.0; 3];
    for c in 0..3 {
        let m = values.iter().map(|v| v[c] as f64).sum::<f64>() / n;
        let var = values
            .iter()
            .map(|v| (v[c] as f64 - m).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        mean[c] = m;
        se[c] = (var / n).sqrt();
    }
    (mean, se)
}
