//! 5. Unbiasedness of `E[g/p]` against quadrature, and 6. efficiency.

use crate::frame::Frame;
use crate::integrand::Integrand;
use crate::quadrature::{Needs, Point, Quadrature};
use crate::report::{sig, Row, Verdict};
use crate::sampler::SphereSampler;
use crate::stats::{fits, over_sample_chunks, Moments};
use crate::{QUADRATURE_SLACK, Z_TOLERANCE};
use envlight::color::luminance;
use envlight::Vec3;
use rayon::prelude::*;
use std::f64::consts::PI;
use std::fmt;

/// One Monte Carlo estimate of `∫ Y(L) f dω` against its quadrature.
#[derive(Debug, Clone)]
pub struct Estimate {
    /// What `f` is.
    pub label: String,
    /// Quadrature reference (order 3, or 2 for large grids).
    pub reference: f64,
    /// Its error estimate, `|Q3 - Q2|` (or `|Q2 - Q1|`), with [`Reference::Checked`].
    pub quadrature_error: Option<f64>,
    /// Monte Carlo mean of `Y f / p`.
    pub mean: f64,
    /// Its standard error.
    pub std_err: f64,
    /// `∫ Y dω` of the whole light (the f = 1 reference), for [`MASS_RESOLUTION`].
    pub total: f64,
}

/// Light below this fraction of `∫ Y dω` may be unreachable by any sampler whose
/// CDF is stored in f32 (steps under half an ulp of 1, 6e-8, round to zero width),
/// so an estimate may miss that much: `f32::EPSILON` of the total. Only the
/// huge-dynamic-range maps come near it (their 1e-30 texels hold 1e-58 of the light).
pub const MASS_RESOLUTION: f64 = f32::EPSILON as f64;

impl Estimate {
    /// Allowed `|mean - reference|`: [`Z_TOLERANCE`] standard errors plus
    /// [`QUADRATURE_SLACK`] relative plus [`MASS_RESOLUTION`] of the whole light.
    pub fn tolerance(&self) -> f64 {
        Z_TOLERANCE * self.std_err
            + QUADRATURE_SLACK * self.reference.abs()
            + MASS_RESOLUTION * self.total.abs()
    }
    /// The largest quadrature error estimate the reference may have:
    /// [`QUADRATURE_SLACK`] relative, or one standard error of the estimate,
    /// whichever is larger. Below one standard error an error in the reference
    /// moves the test by at most a quarter of its width; this matters for lobes
    /// that see only a sliver of the integrand (a reference 1e-5 of the total,
    /// with a cosine's kink through it). Plus [`MASS_RESOLUTION`] of the whole
    /// light, as in [`Self::tolerance`]: an integrand that is 0 but for rounding
    /// (a cosine lobe opposite the normal, whose product with the normal's cosine
    /// is positive only where f32 rounding puts a point on both sides) has a
    /// reference and an error estimate of that order.
    pub fn quadrature_allowance(&self) -> f64 {
        (QUADRATURE_SLACK * self.reference.abs()).max(self.std_err)
            + MASS_RESOLUTION * self.total.abs()
    }
    /// Deviation in standard errors (0 when both are exactly equal, e.g. a lobe
    /// facing only black).
    pub fn z(&self) -> f64 {
        if self.mean == self.reference {
            0.0
        } else {
            (self.mean - self.reference) / self.std_err
        }
    }
}

/// Unbiasedness of `Y(L) f / p` for f = 1 and cosine lobes, plus the efficiency figure.
#[derive(Debug, Clone)]
pub struct Unbiasedness {
    /// Samples drawn.
    pub samples: usize,
    /// One row per `f`.
    pub estimates: Vec<Estimate>,
    /// The sampler's own `∫ Y dω`, checked against the quadrature when the
    /// integrand is the luminance alone.
    pub claimed_integral: Option<f64>,
    /// Samples whose weight `Y/p` was not finite.
    pub bad_weights: usize,
    /// Quadrature rule.
    pub rule: String,
    /// `(∫Y)² / ∫(Y²/p)` by quadrature (0 when some lit point has pdf 0).
    pub efficiency_quadrature: f64,
    /// The same from the samples, `E[Y/p]² / E[(Y/p)²]`.
    pub efficiency_monte_carlo: f64,
    /// The sampler's own figure.
    pub efficiency_reported: Option<f64>,
}

impl Unbiasedness {
    /// Relative agreement required between the reported and the quadrature
    /// efficiency ("loose": the figure is for reports, and a sampler may compute it
    /// with a coarser rule; `EnvironmentLight::efficiency` uses 2 points per half
    /// texel, which is 0.3% off for one-row maps, where ∫ sin θ over a whole
    /// hemisphere gets two points).
    pub const EFFICIENCY_QUADRATURE_TOLERANCE: f64 = 1e-2;
    /// Relative agreement required between the Monte Carlo and the quadrature
    /// efficiency ("loose": `E[(Y/p)²]` converges slowly when the tails are heavy).
    pub const EFFICIENCY_MC_TOLERANCE: f64 = 0.05;

    /// Every estimate within tolerance, the quadrature error within the slack, the
    /// claimed integral equal to the quadrature, and (when `check_efficiency`) the
    /// efficiency figures in agreement.
    pub fn verdict(&self, check_efficiency: bool) -> Result<(), String> {
        let mut errors = Vec::new();
        if self.bad_weights > 0 {
            errors.push(format!("{} non-finite weights", self.bad_weights));
        }
        for e in &self.estimates {
            if !fits((e.mean - e.reference).abs(), e.tolerance()) {
                errors.push(format!(
                    "{}: mean {:.6e} vs reference {:.6e} ({:+.1} SE, tolerance {:.2e})",
                    e.label,
                    e.mean,
                    e.reference,
                    e.z(),
                    e.tolerance()
                ));
            }
            if let Some(error) = e.quadrature_error {
                if !fits(error, e.quadrature_allowance()) {
                    errors.push(format!(
                        "{}: quadrature error estimate {error:.2e} exceeds {:.2e}",
                        e.label,
                        e.quadrature_allowance()
                    ));
                }
            }
        }
        let reference = self.estimates[0].reference;
        if let Some(claimed) = self.claimed_integral {
            if !fits(
                (claimed - reference).abs(),
                QUADRATURE_SLACK * reference.abs(),
            ) {
                errors.push(format!(
                    "claimed ∫Y dω = {claimed:.7e} vs quadrature {reference:.7e}"
                ));
            }
        }
        if let (true, Some(r)) = (check_efficiency, self.efficiency_reported) {
            let q = self.efficiency_quadrature;
            if !fits((r - q).abs(), Self::EFFICIENCY_QUADRATURE_TOLERANCE * q) {
                errors.push(format!("reported efficiency {r:.6} vs quadrature {q:.6}"));
            }
        }
        let (m, q) = (self.efficiency_monte_carlo, self.efficiency_quadrature);
        if check_efficiency && !fits((m - q).abs(), Self::EFFICIENCY_MC_TOLERANCE * q) {
            errors.push(format!(
                "Monte Carlo efficiency {m:.4} vs quadrature {q:.4}"
            ));
        }
        if errors.is_empty() {
            Ok(())
        } else {
            Err(errors.join("; "))
        }
    }
}

impl fmt::Display for Unbiasedness {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "unbiasedness: N={} ({}):", self.samples, self.rule)?;
        for e in &self.estimates {
            write!(
                f,
                "\n    {:<28} ref {:.6e} (quad err {}) MC {:.6e} ± {:.1e} ({:+.2} SE)",
                e.label,
                e.reference,
                e.quadrature_error
                    .map_or("-".into(), |q| format!("{q:.1e}")),
                e.mean,
                e.std_err,
                e.z()
            )?;
        }
        write!(
            f,
            "\n    claimed ∫Y dω {}; efficiency: quadrature {:.5}, Monte Carlo {:.5}, reported {}",
            self.claimed_integral
                .map_or("-".to_string(), |c| format!("{c:.6e}")),
            self.efficiency_quadrature,
            self.efficiency_monte_carlo,
            self.efficiency_reported
                .map_or("-".to_string(), |e| format!("{e:.5}"))
        )
    }
}

impl Estimate {
    /// The table row `unbiased (<name>)`.
    pub fn row(&self, name: &str, samples: usize) -> Row {
        let sigmas = if self.std_err > 0.0 {
            (self.mean - self.reference).abs() / self.std_err
        } else {
            0.0
        };
        Row::new(
            format!("unbiased ({name})"),
            format!(
                "{} ± {} vs {} ({sigmas:.2}σ)",
                sig(self.mean, 6),
                sig(self.std_err, 2),
                sig(self.reference, 6)
            ),
            format!("within {Z_TOLERANCE}σ"),
            samples,
            Verdict::from_pass(fits((self.mean - self.reference).abs(), self.tolerance())),
        )
    }
}

impl Unbiasedness {
    /// The `efficiency` table row (reported, not judged).
    pub fn efficiency_row(&self) -> Row {
        Row::new(
            "efficiency",
            format!(
                "{:.5} (from samples {:.5})",
                self.efficiency_reported
                    .unwrap_or(self.efficiency_quadrature),
                self.efficiency_monte_carlo
            ),
            "report only",
            self.samples,
            Verdict::Info,
        )
    }
}

/// Most test lobes [`unbiasedness`] takes.
pub const MAX_LOBES: usize = 4;

/// Values per quadrature point: `g`, `g·cos⁺` per lobe, `g²/p`.
const K: usize = 2 + MAX_LOBES;

/// Test lobes for [`unbiasedness`]: normals towards the brightest probe (the cell
/// centre with the largest luminance), straight up, and an oblique one below the
/// horizon.
pub fn lobe_normals(s: &dyn SphereSampler) -> Vec<Vec3> {
    let [w, h] = s.grid().map_or([512, 256], |g| g.cells());
    let frame = Frame::of(s);
    let up = Vec3::new(0.0, 0.0, 1.0);
    let best = (0..h)
        .into_par_iter()
        .map(|j| {
            // One batch query per row of cell centres.
            let v = (j as f64 + 0.5) / h as f64;
            let directions: Vec<Vec3> = (0..w)
                .map(|i| frame.world_at((i as f64 + 0.5) / w as f64, v))
                .collect();
            let mut radiance = vec![[0.0f32; 3]; w];
            s.radiance_batch(&directions, &mut radiance);
            let mut best = (f32::NEG_INFINITY, up);
            for (&d, &l) in directions.iter().zip(&radiance) {
                let y = luminance(l);
                if y > best.0 {
                    best = (y, d);
                }
            }
            best
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold(
            (f32::NEG_INFINITY, up),
            |a, b| if b.0 > a.0 { b } else { a },
        );
    let k = 1.0 / 3f32.sqrt();
    vec![best.1, up, Vec3::new(k, -k, -k)]
}

/// How [`unbiasedness`] and [`efficiency`] integrate their references.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference {
    /// Gauss-Legendre order 3 (order 2 on grids above 256k cells) on cells that
    /// split every grid cell at its centre lines, with the error estimated by the
    /// next lower order on the same cells and required below [`QUADRATURE_SLACK`]
    /// relative: what the test suite uses.
    Checked,
    /// The midpoint rule on the same cells (4 points per grid cell), without an
    /// error estimate: exact for a bilinear reconstruction, O(h²) in the measure
    /// and at a cosine's kink, for quick checks (`envlight verify`); the quadrature
    /// of `Y²/p` in the efficiency errs by O(h²) of the luminance's variation.
    Midpoint,
}

/// The reference rule of [`unbiasedness`] and [`efficiency`] ([`Reference`]): cells that split every
/// cell of the sampler's grid at its centre lines, where a bilinear reconstruction
/// has its kinks (at least 256×128 cells overall, at most ~1M unless the grid needs
/// more), so `Y` is bilinear and `Y²` quadratic in each quadrature cell. Order 3
/// (checked against order 2); above 256k cells in the sampler's grid (real maps),
/// order 2 (checked against 1) keeps the cost down: it is still exact for `Y²`
/// along u, and the midpoint rule's error, printed, bounds it. On the equal-area
/// square the measure is the constant `4π du dv`, and only cosine factors are not
/// polynomial in `(u, v)` (the map is kinked along the axes and the equator's
/// diamond); `|Q3 - Q2|` measures that too (≤ 6.2e-6 relative in the equal-area
/// cases).
fn reference_rule(s: &dyn SphereSampler, reference: Reference) -> Quadrature {
    let large = s.grid().is_some_and(|g| {
        let [w, h] = g.cells();
        w * h > 256 << 10
    });
    let order = match reference {
        Reference::Midpoint => 1,
        Reference::Checked if large => 2,
        Reference::Checked => 3,
    };
    Quadrature::for_sampler(s, 2, [256, 128], 1 << 20, order)
}

/// The `g²/p` term of the efficiency at a quadrature point (+∞ where `g > 0`
/// and `p = 0`). It leaves out the lat-long map's pole caps (sin θ < POLE_BAND_SIN,
/// 5e-9 of the sphere), where the density diverges and an f32 pdf may legitimately
/// be 0; `g/p` is bounded around them, so the caps change the efficiency by about
/// their share of `∫g`. (The equal-area square has none.)
fn second_moment(pt: &Point, g: f64) -> f64 {
    if g <= 0.0 || pt.near_pole {
        return 0.0;
    }
    let p = pt.pdf as f64;
    if p > 0.0 {
        g * g / p * pt.weight
    } else {
        f64::INFINITY
    }
}

/// `(∫g)² / ∫g²/p`, 0 when some point with `g > 0` has `p = 0` (or nothing is lit).
fn efficiency_of(integral: f64, second: f64) -> f64 {
    if integral > 0.0 && second.is_finite() && second > 0.0 {
        integral * integral / second
    } else {
        0.0
    }
}

/// The efficiency of a sampler's pdf for an integrand, by quadrature.
#[derive(Debug, Clone)]
pub struct Efficiency {
    /// `∫ g dω`.
    pub integral: f64,
    /// `(∫ g)² / ∫ g²/p dω`: 1 when `p ∝ g`; the variance of one-sample estimates
    /// of `∫ g` is `(1/efficiency − 1) (∫ g)²`.
    pub efficiency: f64,
    /// The rule used.
    pub rule: String,
}

/// [`Efficiency`] of `s`'s pdf for `integrand` (which need not be what `s` follows:
/// a light-only pdf can be measured on a shading point's integrand), on the rule
/// of [`unbiasedness`].
pub fn efficiency(
    s: &dyn SphereSampler,
    integrand: &Integrand,
    reference: Reference,
) -> Efficiency {
    let q = reference_rule(s, reference);
    let [integral, second] = q.sum(s, Needs::BOTH, |pt| {
        let g = integrand.value(pt.radiance, pt.direction);
        [g * pt.weight, second_moment(pt, g)]
    });
    Efficiency {
        integral,
        efficiency: efficiency_of(integral, second),
        rule: q.describe(),
    }
}

/// `∫g dω` and `∫g²/p dω` for `g = Y·max(0, n·ω)` and `s`'s pdf by the plain
/// midpoint rule, `m × m` points per texel of a `w × h` lat-long grid
/// (`dω = 2π² sin θ du dv`), with `s`'s radiance or, given `texels` (a `w × h`
/// image), the value of the texel holding each point (a nearest lookup). Written
/// apart from [`Quadrature`] on purpose: it is what an outside check would do,
/// and it converges to [`Reference::Checked`] as `m` grows, at `O(h²)`
/// (`tests/efficiency_quadrature.rs`).
pub fn midpoint_moments(
    s: &dyn SphereSampler,
    [w, h]: [usize; 2],
    n: Vec3,
    m: usize,
    texels: Option<&envlight::EnvImage>,
) -> MidpointMoments {
    let (nu, nv) = (w * m, h * m);
    let (du, dv) = (1.0 / nu as f64, 1.0 / nv as f64);
    let rows: Vec<MidpointMoments> = (0..nv)
        .into_par_iter()
        .map(|r| {
            let (st, ct) = (PI * (r as f64 + 0.5) * dv).sin_cos();
            let dw = 2.0 * PI * PI * st * du * dv;
            let directions: Vec<Vec3> = (0..nu)
                .map(|c| {
                    let (sp, cp) = (2.0 * PI * (c as f64 + 0.5) * du).sin_cos();
                    Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32)
                })
                .collect();
            let mut pdf = vec![0.0f32; nu];
            s.pdf_batch(&directions, &mut pdf);
            let mut radiance = vec![[0.0f32; 3]; nu];
            match texels {
                Some(image) => {
                    let row = image.row(r / m);
                    for (c, l) in radiance.iter_mut().enumerate() {
                        *l = row[c / m];
                    }
                }
                None => s.radiance_batch(&directions, &mut radiance),
            }
            let mut acc = MidpointMoments::default();
            for ((d, l), &p) in directions.iter().zip(&radiance).zip(&pdf) {
                let g = luminance(*l) as f64 * n.dot(*d).max(0.0) as f64;
                if g > 0.0 {
                    acc.integral += g * dw;
                    if p > 0.0 {
                        acc.second += g * g / p as f64 * dw;
                    } else {
                        acc.unsampled += 1;
                    }
                }
            }
            acc
        })
        .collect();
    rows.iter()
        .fold(MidpointMoments::default(), |a, r| MidpointMoments {
            integral: a.integral + r.integral,
            second: a.second + r.second,
            unsampled: a.unsampled + r.unsampled,
        })
}

/// What [`midpoint_moments`] sums.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct MidpointMoments {
    /// `∫ g dω`.
    pub integral: f64,
    /// `∫ g²/p dω` over the points where `p > 0`.
    pub second: f64,
    /// Points with `g > 0` and `p = 0`.
    pub unsampled: usize,
}

impl MidpointMoments {
    /// `(∫g)² / ∫g²/p`.
    pub fn efficiency(&self) -> f64 {
        self.integral * self.integral / self.second
    }
}

/// Checks `E[g / p] = ∫ g dω` for the integrand `g` and for `g` times the cosine
/// lobe of each normal in `lobes` (at most [`MAX_LOBES`]; see [`lobe_normals`]),
/// with `n` samples, against quadrature by the `reference` rule, and measures the efficiency `(∫g)² / ∫(g²/p)` both ways.
///
/// # Panics
/// With more than [`MAX_LOBES`] lobes.
pub fn unbiasedness(
    s: &dyn SphereSampler,
    integrand: &Integrand,
    lobes: &[Vec3],
    n: usize,
    seed: u64,
    reference: Reference,
) -> Unbiasedness {
    assert!(lobes.len() <= MAX_LOBES, "at most {MAX_LOBES} lobes");
    let m = 1 + lobes.len();
    let values = |g: f64, d: Vec3| -> [f64; K] {
        let mut r = [0.0; K];
        r[0] = g;
        for (k, l) in lobes.iter().enumerate() {
            r[1 + k] = g * l.dot(d).max(0.0) as f64;
        }
        r
    };
    let q3 = reference_rule(s, reference);
    let quadrature = |q: &Quadrature, with_efficiency: bool| {
        let needs = Needs {
            radiance: true,
            pdf: with_efficiency,
        };
        q.sum(s, needs, |pt| {
            let g = integrand.value(pt.radiance, pt.direction);
            let mut r = values(g, pt.direction).map(|x| x * pt.weight);
            if with_efficiency {
                r[K - 1] = second_moment(pt, g);
            }
            r
        })
    };
    let r3 = quadrature(&q3, true);
    let r2 = (reference == Reference::Checked).then(|| {
        let q2 = Quadrature {
            order: q3.order - 1,
            ..q3
        };
        quadrature(&q2, false)
    });

    let (moments, bad_weights) = over_sample_chunks(
        s,
        n,
        seed,
        || ([Moments::default(); K], 0usize),
        |(acc, bad), _, samples| {
            for smp in samples {
                let mut v = [0.0f64; K];
                if let Some(smp) = smp {
                    let w = integrand.value(smp.radiance, smp.direction) / smp.pdf as f64;
                    if !w.is_finite() {
                        *bad += 1;
                    }
                    v = values(w, smp.direction);
                }
                for (a, x) in acc.iter_mut().zip(&v[..m]) {
                    a.push(*x);
                }
            }
        },
    )
    .into_iter()
    .fold(([Moments::default(); K], 0usize), |(mut a, b0), (c, b1)| {
        for (x, y) in a.iter_mut().zip(c) {
            *x = x.merge(y);
        }
        (a, b0 + b1)
    });

    let fmt_n = |n: &Vec3| format!("({:.2},{:.2},{:.2})", n.x, n.y, n.z);
    let labels = std::iter::once(integrand.label().to_string()).chain(
        lobes
            .iter()
            .map(|l| format!("{} × cos lobe {}", integrand.label(), fmt_n(l))),
    );
    let estimates = labels
        .enumerate()
        .map(|(k, label)| Estimate {
            label,
            reference: r3[k],
            quadrature_error: r2.map(|r2| (r3[k] - r2[k]).abs()),
            mean: moments[k].mean,
            std_err: moments[k].std_err(),
            total: r3[0],
        })
        .collect();
    let m0 = moments[0];
    let efficiency_monte_carlo = if m0.mean > 0.0 {
        m0.mean * m0.mean / m0.mean_square()
    } else {
        0.0
    };
    let luminance_only = integrand.is_luminance();
    Unbiasedness {
        samples: n,
        estimates,
        claimed_integral: luminance_only.then(|| s.integral_luminance()),
        bad_weights,
        rule: q3.describe(),
        efficiency_quadrature: efficiency_of(r3[0], r3[K - 1]),
        efficiency_monte_carlo,
        efficiency_reported: if luminance_only {
            s.reported_efficiency()
        } else {
            None
        },
    }
}
