//! A [`PortalLight`] at one point, as a [`SphereSampler`], and the checks that only
//! make sense for it (docs/design.md §6d): every sample passes through a portal, the pdf
//! is 0 through none, and the normalisation, support, chi-square and
//! unbiasedness checks with their integrals taken **over the portals' own areas**
//! (so the portals' edges, where the pdf drops to 0, are edges of the quadrature
//! and not discontinuities inside its cells).
//!
//! Independence: the portals' geometry here is the harness's own (`f64`, the
//! bilinear patch through the four corners, normal from the diagonals), not the
//! library's oblique frame; the library is asked only `sample`, `pdf` and
//! `radiance`. The solid angle of a plane point `X` seen from `p` is
//! `dω = |n·(X − p)| / |X − p|³ dA`, with `dA = |∂X/∂a × ∂X/∂b| da db` on the patch.

use crate::checks::chi_square::pearson;
use crate::checks::consistency::{consistency, Consistency};
use crate::param::to_f64;
use crate::quadrature::gauss_legendre;
use crate::report::{sig, Row, Verdict};
use crate::sampler::{sphere_sample, SphereSample, SphereSampler};
use crate::stats::{fits, over_sample_chunks, Moments};
use crate::{ALPHA, NORMALISATION_TOLERANCE, PDF_CONSISTENCY_TOLERANCE, Z_TOLERANCE};
use envlight::color::luminance;
use envlight::portal::{PortalLight, PortalPoint};
use envlight::Vec3;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

type D3 = [f64; 3];

fn dot(a: D3, b: D3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn sub(a: D3, b: D3) -> D3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross(a: D3, b: D3) -> D3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn norm(a: D3) -> f64 {
    dot(a, a).sqrt()
}

/// A convex quad as the harness sees it: the bilinear patch
/// `X(a, b) = (1−a)(1−b) c₀ + a(1−b) c₁ + ab c₂ + (1−a)b c₃` over `[0, 1]²`.
#[derive(Debug, Clone, Copy)]
pub struct Quad {
    c: [D3; 4],
    n: D3,
    diagonal: f64,
}

impl Quad {
    /// The quad through four corners in order around it.
    pub fn new(corners: [Vec3; 4]) -> Self {
        let c = corners.map(to_f64);
        let nn = cross(sub(c[2], c[0]), sub(c[3], c[1]));
        let len = norm(nn);
        let n = [nn[0] / len, nn[1] / len, nn[2] / len];
        let diagonal = norm(sub(c[2], c[0])).max(norm(sub(c[3], c[1])));
        Quad { c, n, diagonal }
    }

    fn patch(&self, a: f64, b: f64) -> (D3, D3, D3) {
        let c = &self.c;
        let w = [(1.0 - a) * (1.0 - b), a * (1.0 - b), a * b, (1.0 - a) * b];
        let x = [0, 1, 2].map(|i| (0..4).map(|k| w[k] * c[k][i]).sum::<f64>());
        let da = [0, 1, 2].map(|i| (1.0 - b) * (c[1][i] - c[0][i]) + b * (c[2][i] - c[3][i]));
        let db = [0, 1, 2].map(|i| (1.0 - a) * (c[3][i] - c[0][i]) + a * (c[2][i] - c[1][i]));
        (x, da, db)
    }

    /// Where the ray from `p` along `w` meets the quad's plane (ahead of `p`), and
    /// the hit's margin: its smallest signed distance to the four edges over the
    /// diagonal (≥ 0 inside).
    fn hit(&self, p: D3, w: D3) -> Option<(D3, f64)> {
        let dn = dot(w, self.n);
        let t = dot(sub(self.c[0], p), self.n) / dn;
        if !(t > 0.0 && t.is_finite()) {
            return None;
        }
        let x = [p[0] + t * w[0], p[1] + t * w[1], p[2] + t * w[2]];
        let mut margin = f64::INFINITY;
        for k in 0..4 {
            let (a, b) = (self.c[k], self.c[(k + 1) % 4]);
            let e = sub(b, a);
            let d = dot(cross(e, sub(x, a)), self.n) / norm(e);
            margin = margin.min(d / self.diagonal);
        }
        Some((x, margin))
    }

    /// The patch parameters `(a, b)` of a plane point (Newton's method).
    fn invert(&self, x: D3) -> [f64; 2] {
        let (mut a, mut b) = (0.5, 0.5);
        for _ in 0..12 {
            let (xp, da, db) = self.patch(a, b);
            let r = sub(x, xp);
            let (m11, m12, m22) = (dot(da, da), dot(da, db), dot(db, db));
            let (r1, r2) = (dot(da, r), dot(db, r));
            let det = m11 * m22 - m12 * m12;
            a += (m22 * r1 - m12 * r2) / det;
            b += (m11 * r2 - m12 * r1) / det;
        }
        [a.clamp(0.0, 1.0 - 1e-12), b.clamp(0.0, 1.0 - 1e-12)]
    }
}

/// Samples whose hit is within this margin (relative to the portal's diagonal)
/// of a portal's edge are exempt from the pass-through and pdf-0 checks: the f32
/// direction moves a hit by about 1e-7 of the distance.
pub const PORTAL_EDGE_BAND: f64 = 1e-5;

/// Which density the adapter reports: the light's, or a deliberately broken one
/// (the harness's self-checks).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PortalVariant {
    /// [`PortalPoint::pdf`].
    Exact,
    /// [`PortalPoint::rectified_pdf`]: the pdf without the rectification's
    /// Jacobian, which must be rejected.
    NoJacobian,
}

/// A [`PortalLight`] at the point `p`, with the portals' true corners (which the
/// checks use; normally the light's own, but a test may give the light slightly
/// wrong ones to prove the checks notice).
pub struct AtPortalPoint<'a> {
    light: &'a PortalLight,
    point: PortalPoint<'a>,
    p: D3,
    quads: Vec<Quad>,
    variant: PortalVariant,
}

impl<'a> AtPortalPoint<'a> {
    /// `light` at `p`, checked against its own portals.
    pub fn new(light: &'a PortalLight, p: Vec3) -> Self {
        let corners: Vec<[Vec3; 4]> = light.portals().iter().map(|q| q.corners()).collect();
        Self::with_geometry(light, p, &corners)
    }

    /// `light` at `p`, checked against the portals `corners`.
    pub fn with_geometry(light: &'a PortalLight, p: Vec3, corners: &[[Vec3; 4]]) -> Self {
        Self {
            light,
            point: light.at(p),
            p: to_f64(p),
            quads: corners.iter().map(|&c| Quad::new(c)).collect(),
            variant: PortalVariant::Exact,
        }
    }

    /// The same, reporting `variant`'s density.
    pub fn variant(mut self, variant: PortalVariant) -> Self {
        self.variant = variant;
        self
    }

    /// The luminance power seen through the portals (0: nothing to sample).
    pub fn power(&self) -> f64 {
        self.point.power()
    }

    /// The first portal the ray along `w` crosses, and the smallest edge margin
    /// (in absolute value) over all portals it meets the plane of.
    fn classify(&self, w: D3) -> (Option<(usize, D3)>, f64) {
        let mut first = None;
        let mut closest = f64::INFINITY;
        for (k, q) in self.quads.iter().enumerate() {
            if let Some((x, margin)) = q.hit(self.p, w) {
                closest = closest.min(margin.abs());
                if margin >= 0.0 && first.is_none() {
                    first = Some((k, x));
                }
            }
        }
        (first, closest)
    }

    /// Whether the ray along `direction` crosses one of the true portals.
    pub fn through(&self, direction: Vec3) -> bool {
        self.classify(to_f64(direction)).0.is_some()
    }

    fn density(&self, direction: Vec3) -> f32 {
        match self.variant {
            PortalVariant::Exact => self.point.pdf(direction),
            PortalVariant::NoJacobian => self.point.rectified_pdf(direction),
        }
    }

    /// Quadrature points over the portals' areas (`cells × cells` patch cells of
    /// Gauss-Legendre order `order` each): direction, solid-angle weight, portal and
    /// patch cell. A point whose direction also crosses an earlier portal is left
    /// out (it is that portal's).
    fn points(&self, cells: usize, order: usize) -> Vec<QPoint> {
        let (x, w) = gauss_legendre(order);
        let h = 1.0 / cells as f64;
        let mut out = Vec::new();
        for (k, q) in self.quads.iter().enumerate() {
            let pts: Vec<QPoint> = (0..cells)
                .into_par_iter()
                .flat_map_iter(|jb| {
                    let mut row = Vec::new();
                    for ia in 0..cells {
                        for (xb, wb) in x.iter().zip(w) {
                            for (xa, wa) in x.iter().zip(w) {
                                let a = (ia as f64 + xa) * h;
                                let b = (jb as f64 + xb) * h;
                                let (xp, da, db) = q.patch(a, b);
                                let r = sub(xp, self.p);
                                let dist = norm(r);
                                let area = norm(cross(da, db)) * h * h * wa * wb;
                                let weight = area * dot(r, q.n).abs() / (dist * dist * dist);
                                let dir = [r[0] / dist, r[1] / dist, r[2] / dist];
                                let earlier = self.quads[..k]
                                    .iter()
                                    .any(|e| e.hit(self.p, dir).is_some_and(|(_, m)| m >= 0.0));
                                if earlier || weight.is_nan() || weight <= 0.0 {
                                    continue;
                                }
                                row.push(QPoint {
                                    direction: Vec3::new(
                                        dir[0] as f32,
                                        dir[1] as f32,
                                        dir[2] as f32,
                                    ),
                                    weight,
                                    cell: [k, ia, jb],
                                });
                            }
                        }
                    }
                    row
                })
                .collect();
            out.extend(pts);
        }
        out
    }
}

#[derive(Debug, Clone, Copy)]
struct QPoint {
    direction: Vec3,
    weight: f64,
    cell: [usize; 3],
}

impl SphereSampler for AtPortalPoint<'_> {
    fn name(&self) -> String {
        let variant = match self.variant {
            PortalVariant::Exact => "",
            PortalVariant::NoJacobian => " [broken: no Jacobian]",
        };
        format!(
            "portals ({}, n={}) at ({:.3},{:.3},{:.3}) over {}{variant}",
            self.quads.len(),
            self.light.resolution(),
            self.p[0],
            self.p[1],
            self.p[2],
            SphereSampler::name(self.light.light())
        )
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        let s = self.point.sample(xi).map(sphere_sample)?;
        Some(SphereSample {
            pdf: self.density(s.direction),
            ..s
        })
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        self.density(direction)
    }
    fn invert(&self, _: Vec3) -> Option<[f32; 2]> {
        None
    }
    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        self.light.radiance(direction)
    }
    fn integral_luminance(&self) -> f64 {
        self.point.power()
    }
}

/// Sample counts and resolutions for [`run_portal`].
#[derive(Debug, Clone, Copy)]
pub struct PortalConfig {
    /// Samples for the chi-square, pass-through and unbiasedness checks.
    pub samples: usize,
    /// Samples for the pdf consistency check.
    pub consistency_samples: usize,
    /// Uniform random directions probed for pdf 0 through no portal.
    pub probes: usize,
    /// Quadrature cells along each side of a portal's patch.
    pub cells: usize,
    /// Chi-square bins along each side of a portal's patch (divides `cells`).
    pub bins: usize,
    /// Base seed.
    pub seed: u64,
}

impl PortalConfig {
    /// Synthetic maps: 1M samples, 200k consistency samples, 200k probes, 192²
    /// cells and 16² bins per portal.
    pub const SYNTHETIC: PortalConfig = PortalConfig {
        samples: 1_000_000,
        consistency_samples: 200_000,
        probes: 200_000,
        cells: 192,
        bins: 16,
        seed: 0x9047,
    };
    /// Real maps (a sun a few texels wide): 384² cells per portal.
    pub const REAL_MAP: PortalConfig = PortalConfig {
        cells: 384,
        ..PortalConfig::SYNTHETIC
    };
}

/// Every figure [`run_portal`] measures.
#[derive(Debug, Clone)]
pub struct PortalReport {
    /// Samples drawn for the chi-square/unbiasedness checks.
    pub samples: usize,
    /// Of those, `None`.
    pub none: usize,
    /// Samples that pass through no true portal (outside the edge band).
    pub escaped: usize,
    /// Samples within [`PORTAL_EDGE_BAND`] of an edge (exempt).
    pub near_edge: usize,
    /// Probes through no portal (outside the edge band).
    pub probes_outside: usize,
    /// Of those, probes with a pdf ≠ 0.
    pub probes_nonzero: usize,
    /// `∫ p dω` over the portals (order 3) and the same with order 2.
    pub integral: [f64; 2],
    /// Whether every portal is a parallelogram (then `∫ p dω` must be 1; otherwise
    /// it must equal the acceptance rate).
    pub parallelograms: bool,
    /// Quadrature points with `Y > 0` and pdf 0, away from the edges.
    pub support_failures: usize,
    /// Quadrature points where the pdf was NaN, infinite or negative.
    pub bad_values: usize,
    /// Chi-square `(statistic, dof, p)`.
    pub chi2: (f64, usize, f64),
    /// `E[Y/p]` (with `None` as 0) and its standard error.
    pub estimate: (f64, f64),
    /// `∫ Y dω` over the portals, order 3 and order 2.
    pub reference: [f64; 2],
    /// `(∫ Y)² / ∫ Y²/p` over the portals.
    pub efficiency: f64,
    /// The generic pdf consistency check.
    pub consistency: Consistency,
}

/// Runs every portal check on `s` (which must see light: [`AtPortalPoint::power`] > 0).
pub fn run_portal(s: &AtPortalPoint, cfg: &PortalConfig) -> PortalReport {
    assert!(cfg.cells.is_multiple_of(cfg.bins), "bins must divide cells");
    let nq = s.quads.len();
    let nb = cfg.bins;
    let per = cfg.cells / nb;
    // Quadrature over the portals.
    let mut integral = [0.0; 2];
    let mut reference = [0.0; 2];
    let mut expected = vec![0.0; nq * nb * nb];
    let (mut support_failures, mut bad_values) = (0, 0);
    let mut y2p = 0.0;
    for (slot, order) in [3usize, 2].into_iter().enumerate() {
        let pts = s.points(cfg.cells, order);
        let dirs: Vec<Vec3> = pts.iter().map(|q| q.direction).collect();
        let mut pdf = vec![0.0f32; dirs.len()];
        let mut rad = vec![[0.0f32; 3]; dirs.len()];
        s.pdf_batch(&dirs, &mut pdf);
        s.radiance_batch(&dirs, &mut rad);
        for ((q, &p), l) in pts.iter().zip(&pdf).zip(&rad) {
            if !(p.is_finite() && p >= 0.0) {
                bad_values += usize::from(slot == 0);
                continue;
            }
            let y = luminance(*l) as f64;
            integral[slot] += p as f64 * q.weight;
            reference[slot] += y * q.weight;
            if slot == 0 {
                let [k, ia, jb] = q.cell;
                expected[(k * nb + jb / per) * nb + ia / per] += p as f64 * q.weight;
                if y > 0.0 {
                    if p > 0.0 {
                        y2p += y * y / p as f64 * q.weight;
                    } else if s.classify(to_f64(q.direction)).1 > PORTAL_EDGE_BAND {
                        support_failures += 1;
                    }
                }
            }
        }
    }
    // Samples: pass-through, histogram and E[Y/p].
    type Acc = (usize, usize, usize, Vec<f64>, Moments);
    let accs = over_sample_chunks(
        s,
        cfg.samples,
        cfg.seed,
        || -> Acc { (0, 0, 0, vec![0.0; nq * nb * nb], Moments::default()) },
        |acc, _, samples| {
            for smp in samples {
                let Some(smp) = smp else {
                    acc.0 += 1;
                    acc.4.push(0.0);
                    continue;
                };
                let y = luminance(smp.radiance) as f64;
                acc.4.push(if smp.pdf > 0.0 {
                    y / smp.pdf as f64
                } else {
                    f64::INFINITY
                });
                let (first, margin) = s.classify(to_f64(smp.direction));
                if margin <= PORTAL_EDGE_BAND {
                    acc.2 += 1;
                }
                match first {
                    Some((k, x)) => {
                        let [a, b] = s.quads[k].invert(x);
                        let (ia, jb) = ((a * nb as f64) as usize, (b * nb as f64) as usize);
                        acc.3[(k * nb + jb.min(nb - 1)) * nb + ia.min(nb - 1)] += 1.0;
                    }
                    None if margin > PORTAL_EDGE_BAND => acc.1 += 1,
                    None => {}
                }
            }
        },
    );
    let (mut none, mut escaped, mut near_edge) = (0, 0, 0);
    let mut observed = vec![0.0; nq * nb * nb];
    let mut moments = Moments::default();
    for (a, b, c, hist, m) in accs {
        none += a;
        escaped += b;
        near_edge += c;
        for (o, h) in observed.iter_mut().zip(hist) {
            *o += h;
        }
        moments = moments.merge(m);
    }
    let n = cfg.samples as f64;
    let expected: Vec<f64> = expected.iter().map(|e| e * n).collect();
    let (statistic, _, dof, p_value) = pearson(&observed, &expected);
    // Probes: uniform directions through no portal must have pdf 0.
    let (probes_outside, probes_nonzero) = (0..16)
        .into_par_iter()
        .map(|c| {
            let mut rng = Pcg64Mcg::seed_from_u64(cfg.seed ^ 0x9e37_79b9 ^ (c as u64) << 32);
            let (mut outside, mut nonzero) = (0, 0);
            for _ in 0..cfg.probes / 16 {
                let z: f64 = rng.random::<f64>() * 2.0 - 1.0;
                let phi: f64 = rng.random::<f64>() * std::f64::consts::TAU;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let d = Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32);
                let (first, margin) = s.classify(to_f64(d));
                if first.is_none() && margin > PORTAL_EDGE_BAND {
                    outside += 1;
                    if s.pdf(d) != 0.0 {
                        nonzero += 1;
                    }
                }
            }
            (outside, nonzero)
        })
        .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let consistency = consistency(
        s,
        cfg.consistency_samples,
        cfg.seed ^ 1,
        PDF_CONSISTENCY_TOLERANCE,
    );
    let efficiency = if y2p > 0.0 {
        reference[0] * reference[0] / y2p
    } else {
        0.0
    };
    PortalReport {
        samples: cfg.samples,
        none,
        escaped,
        near_edge,
        probes_outside,
        probes_nonzero,
        integral,
        parallelograms: s.light.portals().iter().all(|q| q.is_parallelogram()),
        support_failures,
        bad_values,
        chi2: (statistic, dof, p_value),
        estimate: (moments.mean, moments.std_err()),
        reference,
        efficiency,
        consistency,
    }
}

impl PortalReport {
    /// The fraction of samples accepted (not `None`).
    pub fn acceptance(&self) -> f64 {
        1.0 - self.none as f64 / self.samples as f64
    }

    /// The rows of `envlight verify --portal`: each with its verdict.
    pub fn rows(&self) -> Vec<Row> {
        let n = self.samples;
        let mut rows = Vec::new();
        rows.push(Row::new(
            "through a portal",
            format!(
                "{} of {} samples missed every portal ({} near an edge)",
                self.escaped,
                n - self.none,
                self.near_edge
            ),
            "0 missed",
            n,
            Verdict::from_pass(self.escaped == 0 && self.near_edge * 100 <= n),
        ));
        rows.push(Row::new(
            "pdf 0 elsewhere",
            format!(
                "{} of {} probes through no portal had pdf > 0",
                self.probes_nonzero, self.probes_outside
            ),
            "0",
            self.probes_outside,
            Verdict::from_pass(self.probes_nonzero == 0),
        ));
        let target = if self.parallelograms {
            1.0
        } else {
            self.acceptance()
        };
        let slack = if self.parallelograms {
            0.0
        } else {
            4.0 * (self.acceptance() * (1.0 - self.acceptance()) / n as f64).sqrt()
        };
        let err = (self.integral[0] - target).abs();
        // The pdf is piecewise constant on the light's rectified cells, whose edges
        // cross the quadrature's cells; |Q3 - Q2| measures what that costs (it is
        // 1e-4 on smooth maps, a few 1e-3 on the random map's 1e6 jumps).
        let quad = (self.integral[0] - self.integral[1]).abs();
        let tol = NORMALISATION_TOLERANCE + slack + quad;
        rows.push(Row::new(
            "normalisation",
            format!(
                "∫p dω over the portals = {:.6} (order 2: {:.6}){}",
                self.integral[0],
                self.integral[1],
                if self.parallelograms {
                    String::new()
                } else {
                    format!(", acceptance {:.6}", self.acceptance())
                }
            ),
            format!(
                "|{} - ∫p| < {} (1e-3 + |Q3-Q2|)",
                if self.parallelograms {
                    "1"
                } else {
                    "acceptance"
                },
                sig(tol, 2)
            ),
            0,
            Verdict::from_pass(self.bad_values == 0 && fits(err, tol)),
        ));
        rows.push(Row::new(
            "pdf consistency",
            format!(
                "{} of {} disagree (max rel err {:.1e}), {} malformed",
                self.consistency.pdf_failures,
                self.consistency.checked,
                self.consistency.max_pdf_error,
                self.consistency.malformed
            ),
            format!("rel err < {:.0e}", self.consistency.tolerance),
            self.consistency.samples,
            Verdict::from_pass(
                self.consistency.pdf_failures == 0 && self.consistency.malformed == 0,
            ),
        ));
        let (stat, dof, p) = self.chi2;
        rows.push(Row::new(
            "chi-square",
            format!("p = {p:.4} (χ² = {stat:.1}, {dof} dof; bins on the portals)"),
            format!("p ≥ {ALPHA:.0e}"),
            n,
            Verdict::from_pass(fits(ALPHA, p)),
        ));
        let (mean, se) = self.estimate;
        let quad = (self.reference[0] - self.reference[1]).abs();
        let z = (mean - self.reference[0]).abs() / (se + quad);
        rows.push(Row::new(
            "unbiased (Y)",
            format!(
                "E[Y/p] = {} ± {} vs ∫_portals Y dω = {} (|Q3-Q2| {}), z = {z:.2}",
                sig(mean, 6),
                sig(se, 2),
                sig(self.reference[0], 6),
                sig(quad, 2)
            ),
            format!("z ≤ {Z_TOLERANCE}"),
            n,
            Verdict::from_pass(fits(z, Z_TOLERANCE)),
        ));
        rows.push(Row::new(
            "support",
            format!(
                "{} quadrature points with Y > 0 and pdf 0",
                self.support_failures
            ),
            "0",
            0,
            Verdict::from_pass(self.support_failures == 0),
        ));
        rows.push(Row::new(
            "efficiency",
            format!("(∫Y)²/∫Y²/p = {:.4}", self.efficiency),
            "",
            0,
            Verdict::Info,
        ));
        rows
    }

    /// The failed rows, one line each.
    pub fn failures(&self) -> Vec<String> {
        self.rows()
            .into_iter()
            .filter(|r| r.verdict == Verdict::Fail)
            .map(|r| format!("{}: {}", r.check, r.value))
            .collect()
    }
}

/// Runs [`run_portal`], prints the rows and panics listing every failed check.
pub fn assert_portal_invariants(case: &str, s: &AtPortalPoint, cfg: &PortalConfig) -> PortalReport {
    let report = run_portal(s, cfg);
    let mut lines = vec![format!("[{case}] {}", s.name())];
    for r in report.rows() {
        lines.push(format!(
            "  {:4} {}: {}",
            r.verdict.label(),
            r.check,
            r.value
        ));
    }
    crate::suite::print_and_assert(case, &s.name(), &lines, &report.failures());
    report
}
