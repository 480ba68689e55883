//! Chi-square goodness of fit of a warp onto the sphere that has no cell grid of
//! its own, such as a BSDF's sampling routine: samples from three-dimensional `ξ`
//! binned over a `(cos θ, φ)` grid of a band of the sphere.

use crate::checks::chi_square::pearson;
use crate::quadrature::gauss_legendre;
use crate::stats::over_points;
use envlight::Vec3;
use std::f64::consts::PI;

/// What [`chi_square_warp`] measured.
#[derive(Debug, Clone, Copy)]
pub struct WarpChiSquare {
    /// Pearson's statistic over the pooled bins.
    pub statistic: f64,
    /// Degrees of freedom (bins used − 1).
    pub dof: usize,
    /// `P(χ²_dof ≥ statistic)`.
    pub p_value: f64,
    /// `∫ pdf dω` over the binned band, by quadrature.
    pub integral: f64,
}

/// Draws `n` directions with `sample(ξ)` (`ξ ∈ [0, 1)³`; `None` for no direction)
/// and tests their histogram over `n_z × n_phi` bins of `cos θ ∈ [z0, z1]` and
/// `φ ∈ [0, 2π)` against the counts `pdf` predicts: each bin expects `n ∫ pdf dω`,
/// by 3-point Gauss-Legendre quadrature on `sub × sub` sub-cells (`dω = d(cos θ)
/// dφ`, so a bin's measure is exact); samples that are `None` or outside the band
/// go to one more bin, which expects `n (1 − ∫ pdf)` over the band. Small bins are
/// pooled as in every chi-square test of the harness ([`pearson`]).
#[allow(clippy::too_many_arguments)]
pub fn chi_square_warp(
    sample: impl Fn([f32; 3]) -> Option<Vec3> + Sync,
    pdf: impl Fn(Vec3) -> f32 + Sync,
    (z0, z1): (f64, f64),
    n_z: usize,
    n_phi: usize,
    sub: usize,
    n: usize,
    seed: u64,
) -> WarpChiSquare {
    let bins = n_z * n_phi;
    let bin_of = |w: Vec3| -> Option<usize> {
        let z = w.z as f64;
        if !(z >= z0 && z <= z1) {
            return None;
        }
        let iz = (((z - z0) / (z1 - z0)) * n_z as f64) as usize;
        let phi = (w.y as f64).atan2(w.x as f64).rem_euclid(2.0 * PI);
        let ip = ((phi / (2.0 * PI)) * n_phi as f64) as usize;
        Some(iz.min(n_z - 1) * n_phi + ip.min(n_phi - 1))
    };
    let observed = over_points(
        n,
        seed,
        || vec![0.0f64; bins + 1],
        |hist, xi: [f32; 3]| hist[sample(xi).and_then(bin_of).unwrap_or(bins)] += 1.0,
    )
    .into_iter()
    .fold(vec![0.0f64; bins + 1], |mut a, h| {
        for (x, y) in a.iter_mut().zip(h) {
            *x += y;
        }
        a
    });

    let (t, w) = gauss_legendre(3);
    let dz = (z1 - z0) / n_z as f64;
    let dphi = 2.0 * PI / n_phi as f64;
    let (sz, sp) = (dz / sub as f64, dphi / sub as f64);
    let mut expected = vec![0.0f64; bins + 1];
    let mut integral = 0.0;
    for iz in 0..n_z {
        for ip in 0..n_phi {
            let mut acc = 0.0;
            for a in 0..sub {
                for (ta, wa) in t.iter().zip(w) {
                    let z = z0 + iz as f64 * dz + (a as f64 + ta) * sz;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    for b in 0..sub {
                        for (tb, wb) in t.iter().zip(w) {
                            let phi = ip as f64 * dphi + (b as f64 + tb) * sp;
                            let d =
                                Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                            acc += wa * wb * pdf(d) as f64;
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
    // Samples where the pdf says there can be none reject outright.
    let impossible = observed
        .iter()
        .zip(&expected)
        .any(|(&o, &e)| e == 0.0 && o > 0.0);
    let (statistic, _, dof, p_value) = pearson(&observed, &expected);
    WarpChiSquare {
        statistic: if impossible { f64::INFINITY } else { statistic },
        dof,
        p_value: if impossible { 0.0 } else { p_value },
        integral,
    }
}
