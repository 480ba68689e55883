//! A piecewise-bilinear density on `[0, 1]²`, sampled by inversion.
//!
//! Non-negative values `f[k][i]` sit at the nodes `(U_i, V_k)` of a rectilinear grid
//! (`0 = U_0 < … < U_{m-1} = 1`, likewise V). Inside the patch
//! `[U_i, U_{i+1}] × [V_k, V_{k+1}]` the function is the bilinear interpolation of
//! its four corners, and the density is `p(u, v) = B(u, v) / I` with `I` the exact
//! integral of `B`. Placing the nodes at texel centres (with extra nodes on the
//! square's edges) makes `p` exactly proportional to a bilinear radiance lookup:
//! for a `w × h` image with u periodic and v clamped, `U = 0, (i + ½)/w, 1` with the
//! seam average `(f[j][w-1] + f[j][0]) / 2` at both `u = 0` and `u = 1`, and
//! `V = 0, (j + ½)/h, 1` with copies of the first and last texel rows at `v = 0` and
//! `v = 1`.
//!
//! Sampling inverts the marginal in v, then the conditional in u:
//!
//! ```text
//! R_k   = ∫ B(u, V_k) du = Σ_i (U_{i+1} - U_i)(f[k][i] + f[k][i+1]) / 2   (exact: linear in u)
//! m(v)  = ∫ B(u, v) du = (1 - t) R_k + t R_{k+1},   t = (v - V_k) / (V_{k+1} - V_k)
//! M_k   = (V_{k+1} - V_k)(R_k + R_{k+1}) / 2,   I = Σ_k M_k
//! ```
//!
//! `ξ1` picks the patch row `k` from the discrete distribution of `M_k`, then `t`
//! from the linear density `(1 - t) R_k + t R_{k+1}`. Given `t`, the conditional
//! `B(u, v) / m(v)` is piecewise linear in u with cumulative integral
//! `C(U_i) = (1 - t) C_k[i] + t C_{k+1}[i]`, where `C_k` is node row `k`'s cumulative
//! trapezoid integral; `ξ0` finds the segment by a binary search over that blend
//! (evaluated on the fly, so nothing per-`t` is stored) and then `u` inside it from
//! the linear density between the blended node values.
//!
//! A linear density `a (1 - x) + b x` on `[0, 1]` is sampled in closed form,
//! `x = ξ (a + b) / (a + √((1 - ξ) a² + ξ b²))`: the root of the quadratic CDF written
//! without cancellation, exact when `a = b` (x = ξ) and when `a = 0` (x = √ξ).

use crate::distribution::{sanitize, Sample2D, ONE_MINUS_EPSILON};
use crate::error::{Error, Result};

/// The largest `f64` below 1.
const ONE_MINUS_EPSILON_F64: f64 = 1.0 - f64::EPSILON / 2.0;

/// A piecewise-bilinear density on `[0, 1]²` over a rectilinear node grid, sampled
/// by inverting its marginal (v) and conditional (u) CDFs.
///
/// Guarantees: a point where the bilinear function is 0 is never returned (up to a
/// set of measure zero: a sample can land exactly on a zero node row when `ξ1`
/// equals a CDF breakpoint, and then reports pdf 0); `pdf(sample_continuous(ξ).uv)`
/// equals the returned pdf; `invert(sample_continuous(ξ).uv) ≈ ξ`.
///
/// Cost: sampling is a binary search over the patch rows and one over the nodes of
/// a row (each probe blends two stored rows), plus two square roots; `pdf` and
/// `invert` locate the patch through a guide table (O(1) for evenly spread nodes,
/// O(log n) at worst). Memory: 8 bytes per node (the value and its row's
/// normalised cumulative integral, both `f32`) plus 16 per node row and 12 per node
/// position.
///
/// ```
/// use envlight::bilinear::BilinearDistribution2D;
/// // B(u, v) = u on the unit square: p = 2u, so u = √ξ0 and v = ξ1.
/// let d = BilinearDistribution2D::new(&[0.0, 1.0, 0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]);
/// let s = d.sample_continuous([0.25, 0.3]);
/// assert!((s.uv[0] - 0.5).abs() < 1e-6 && (s.uv[1] - 0.3).abs() < 1e-6);
/// assert!((s.pdf - 1.0).abs() < 1e-6 && d.pdf(s.uv) == s.pdf);
/// ```
#[derive(Debug, Clone, PartialEq)]
pub struct BilinearDistribution2D {
    /// Node positions along u (`mu` of them) and v (`mv`).
    u_nodes: Vec<f64>,
    v_nodes: Vec<f64>,
    /// Lookup guides for the node positions ([`guide`]).
    u_guide: Vec<u32>,
    v_guide: Vec<u32>,
    /// `f[k * mu + i]`, sanitised.
    values: Vec<f32>,
    /// Node row `k`'s cumulative trapezoid integral divided by `R_k`, at
    /// `[k * mu .. (k + 1) * mu]`: 0 at the first node, exactly 1 at the last (a
    /// zero row holds the node positions instead; it is never weighted).
    cumulative: Vec<f32>,
    /// `R_k = ∫ B(u, V_k) du`.
    row_integral: Vec<f64>,
    /// The marginal CDF over patch rows: `mv` entries from 0 to exactly 1.
    row_cdf: Vec<f64>,
    /// `I = ∫∫ B du dv`.
    integral: f64,
}

impl BilinearDistribution2D {
    /// Builds the density of `values`, given row-major with `v_nodes.len()` rows of
    /// `u_nodes.len()` values, the value of row `k`, column `i` sitting at
    /// `(u_nodes[i], v_nodes[k])`. Negative, NaN and infinite values count as 0. A
    /// function with no positive mass samples uniformly with pdf 0 everywhere.
    ///
    /// # Panics
    /// When [`Self::try_new`] fails.
    pub fn new(values: &[f32], u_nodes: &[f64], v_nodes: &[f64]) -> Self {
        match Self::try_new(values, u_nodes, v_nodes) {
            Ok(d) => d,
            Err(e) => panic!("{e}"),
        }
    }

    /// As [`Self::new`], with the shape checked.
    ///
    /// # Errors
    /// [`Error::InvalidOption`] when either node list has fewer than 2 entries, is
    /// not strictly increasing, does not start at exactly 0 and end at exactly 1, or
    /// holds a non-finite value; or when `values.len() != u_nodes.len() *
    /// v_nodes.len()`.
    pub fn try_new(values: &[f32], u_nodes: &[f64], v_nodes: &[f64]) -> Result<Self> {
        check_nodes("u", u_nodes)?;
        check_nodes("v", v_nodes)?;
        let (mu, mv) = (u_nodes.len(), v_nodes.len());
        if mu.checked_mul(mv) != Some(values.len()) {
            return Err(Error::InvalidOption(format!(
                "bilinear grid of {mu}x{mv} nodes needs {} values, got {}",
                mu.saturating_mul(mv),
                values.len()
            )));
        }
        let values: Vec<f32> = values.iter().map(|&x| sanitize(x)).collect();
        let mut cumulative = vec![0.0f32; mu * mv];
        let mut row_integral = vec![0.0f64; mv];
        let mut sums = vec![0.0f64; mu];
        for ((row, cdf), integral) in values
            .chunks(mu)
            .zip(cumulative.chunks_mut(mu))
            .zip(row_integral.iter_mut())
        {
            // Trapezoids are exact for a function linear between nodes.
            let mut running = 0.0f64;
            for i in 0..mu - 1 {
                let width = u_nodes[i + 1] - u_nodes[i];
                running += width * 0.5 * (row[i] as f64 + row[i + 1] as f64);
                sums[i + 1] = running;
            }
            *integral = running;
            if running > 0.0 {
                for (c, &s) in cdf.iter_mut().zip(&sums) {
                    *c = (s / running) as f32;
                }
            } else {
                for (c, &u) in cdf.iter_mut().zip(u_nodes) {
                    *c = u as f32;
                }
            }
            cdf[mu - 1] = 1.0;
        }
        let mut row_cdf = vec![0.0f64; mv];
        let mut running = 0.0f64;
        for k in 0..mv - 1 {
            let height = v_nodes[k + 1] - v_nodes[k];
            running += height * 0.5 * (row_integral[k] + row_integral[k + 1]);
            row_cdf[k + 1] = running;
        }
        let integral = running;
        if integral > 0.0 {
            for c in &mut row_cdf {
                *c /= integral;
            }
        } else {
            row_cdf.copy_from_slice(v_nodes);
        }
        row_cdf[mv - 1] = 1.0;
        Ok(Self {
            u_nodes: u_nodes.to_vec(),
            v_nodes: v_nodes.to_vec(),
            u_guide: guide(u_nodes),
            v_guide: guide(v_nodes),
            values,
            cumulative,
            row_integral,
            row_cdf,
            integral,
        })
    }

    /// Node positions along u.
    #[inline]
    pub fn u_nodes(&self) -> &[f64] {
        &self.u_nodes
    }

    /// Node positions along v.
    #[inline]
    pub fn v_nodes(&self) -> &[f64] {
        &self.v_nodes
    }

    /// The (sanitised) node values, row-major.
    #[inline]
    pub fn values(&self) -> &[f32] {
        &self.values
    }

    /// `I = ∫∫ B(u, v) du dv`, exact for the bilinear interpolant.
    #[inline]
    pub fn integral(&self) -> f64 {
        self.integral
    }

    /// Bytes of sampling data held (values, cumulative integrals, per-row data and
    /// node positions).
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.values.as_slice())
            + std::mem::size_of_val(self.cumulative.as_slice())
            + std::mem::size_of_val(self.row_integral.as_slice())
            + std::mem::size_of_val(self.row_cdf.as_slice())
            + std::mem::size_of_val(self.u_nodes.as_slice())
            + std::mem::size_of_val(self.v_nodes.as_slice())
            + std::mem::size_of_val(self.u_guide.as_slice())
            + std::mem::size_of_val(self.v_guide.as_slice())
    }

    /// The patch column holding `u ∈ [0, 1]` ([`patch_of`], in O(1) for evenly
    /// spread nodes).
    #[inline]
    fn patch_u(&self, u: f64) -> usize {
        guided_patch(&self.u_nodes, &self.u_guide, u)
    }

    /// The patch row holding `v ∈ [0, 1]`.
    #[inline]
    fn patch_v(&self, v: f64) -> usize {
        guided_patch(&self.v_nodes, &self.v_guide, v)
    }

    #[inline]
    fn mu(&self) -> usize {
        self.u_nodes.len()
    }

    /// The blended cumulative integral `(1 - t) R_k ĉ_k[i] + t R_{k+1} ĉ_{k+1}[i]`
    /// with the weights `w = [(1 - t) R_k, t R_{k+1}]`.
    #[inline]
    fn blended_cumulative(&self, k: usize, w: [f64; 2], i: usize) -> f64 {
        let mu = self.mu();
        w[0] * self.cumulative[k * mu + i] as f64 + w[1] * self.cumulative[(k + 1) * mu + i] as f64
    }

    /// The node values of column `i` blended between node rows `k` and `k + 1`.
    #[inline]
    fn blended_value(&self, k: usize, t: f64, i: usize) -> f64 {
        let mu = self.mu();
        let (a, b) = (
            self.values[k * mu + i] as f64,
            self.values[(k + 1) * mu + i] as f64,
        );
        (1.0 - t) * a + t * b
    }

    /// `B(u, v) / I` in patch `[i, k]`, 0 for a zero function.
    #[inline]
    fn patch_pdf(&self, i: usize, k: usize, u: f64, v: f64) -> f32 {
        if self.integral <= 0.0 {
            return 0.0;
        }
        let tu = local(u, self.u_nodes[i], self.u_nodes[i + 1]);
        let tv = local(v, self.v_nodes[k], self.v_nodes[k + 1]);
        let top = lerp(
            tu,
            self.values[k * self.mu() + i] as f64,
            self.values[k * self.mu() + i + 1] as f64,
        );
        let bottom = lerp(
            tu,
            self.values[(k + 1) * self.mu() + i] as f64,
            self.values[(k + 1) * self.mu() + i + 1] as f64,
        );
        (lerp(tv, top, bottom) / self.integral) as f32
    }

    /// Density at `(u, v) ∈ [0, 1]²` (points outside are clamped onto the square):
    /// the bilinear interpolation of the patch's corners divided by `I`.
    #[inline]
    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        let (u, v) = (unit_closed(uv[0]), unit_closed(uv[1]));
        self.patch_pdf(self.patch_u(u), self.patch_v(v), u, v)
    }

    /// Maps `ξ ∈ [0, 1)²` to a point with density [`Self::pdf`]: `ξ1` picks the
    /// patch row and `v` in it, `ξ0` the segment of the conditional in u and `u` in
    /// it (see the module docs). The returned cell is the patch `[i, k]`, the one
    /// [`Self::pdf`] finds for the returned point. Components outside `[0, 1)` or
    /// NaN are clamped.
    #[inline]
    pub fn sample_continuous(&self, xi: [f32; 2]) -> Sample2D {
        let (xi0, xi1) = (unit_open(xi[0]), unit_open(xi[1]));
        if self.integral <= 0.0 {
            let uv = [
                (xi0 as f32).min(ONE_MINUS_EPSILON),
                (xi1 as f32).min(ONE_MINUS_EPSILON),
            ];
            let (u, v) = (uv[0] as f64, uv[1] as f64);
            return Sample2D {
                uv,
                pdf: 0.0,
                cell: [self.patch_u(u), self.patch_v(v)],
            };
        }
        // The patch row, then v inside it from the linear marginal.
        let k = last_at_most(self.row_cdf.len(), xi1, |j| self.row_cdf[j]);
        let (lo, hi) = (self.row_cdf[k], self.row_cdf[k + 1]);
        let xi1 = ((xi1 - lo) / (hi - lo)).clamp(0.0, ONE_MINUS_EPSILON_F64);
        let t = sample_linear(xi1, self.row_integral[k], self.row_integral[k + 1]);
        let v = lerp(t, self.v_nodes[k], self.v_nodes[k + 1]);

        // The segment of the conditional in u at this t, then u inside it.
        let w = [
            (1.0 - t) * self.row_integral[k],
            t * self.row_integral[k + 1],
        ];
        let total = w[0] + w[1];
        let i;
        let u;
        if total > 0.0 {
            let x = xi0 * total;
            i = last_at_most(self.mu(), x, |j| self.blended_cumulative(k, w, j));
            let (c0, c1) = (
                self.blended_cumulative(k, w, i),
                self.blended_cumulative(k, w, i + 1),
            );
            // c1 > c0 by the search, unless `total` is so small that ξ0·total rounds up.
            let within = if c1 > c0 {
                ((x - c0) / (c1 - c0)).clamp(0.0, ONE_MINUS_EPSILON_F64)
            } else {
                0.0
            };
            let s = sample_linear(
                within,
                self.blended_value(k, t, i),
                self.blended_value(k, t, i + 1),
            );
            u = lerp(s, self.u_nodes[i], self.u_nodes[i + 1]);
        } else {
            // Only on a zero node row hit exactly (t = 0 or 1): a point of pdf 0.
            u = xi0;
            i = self.patch_u(u);
        }
        // The pdf is evaluated at the rounded point in the patch `pdf()` finds for
        // it, so the two agree to the bit.
        let (u, i) = point_in_patch(&self.u_nodes, &self.u_guide, i, u);
        let (v, k) = point_in_patch(&self.v_nodes, &self.v_guide, k, v);
        Sample2D {
            uv: [u, v],
            pdf: self.patch_pdf(i, k, u as f64, v as f64),
            cell: [i, k],
        }
    }

    /// The sample-space point that [`Self::sample_continuous`] maps to `uv`.
    #[inline]
    pub fn invert(&self, uv: [f32; 2]) -> [f32; 2] {
        let (u, v) = (unit_closed(uv[0]), unit_closed(uv[1]));
        if self.integral <= 0.0 {
            return [u as f32, v as f32];
        }
        let k = self.patch_v(v);
        let t = local(v, self.v_nodes[k], self.v_nodes[k + 1]);
        let (r0, r1) = (self.row_integral[k], self.row_integral[k + 1]);
        let xi1 = lerp(cdf_linear(t, r0, r1), self.row_cdf[k], self.row_cdf[k + 1]);

        let i = self.patch_u(u);
        let w = [(1.0 - t) * r0, t * r1];
        let total = w[0] + w[1];
        let xi0 = if total > 0.0 {
            let s = local(u, self.u_nodes[i], self.u_nodes[i + 1]);
            let (c0, c1) = (
                self.blended_cumulative(k, w, i),
                self.blended_cumulative(k, w, i + 1),
            );
            let within = cdf_linear(
                s,
                self.blended_value(k, t, i),
                self.blended_value(k, t, i + 1),
            );
            (c0 + within * (c1 - c0)) / total
        } else {
            u
        };
        [(xi0 as f32).clamp(0.0, 1.0), (xi1 as f32).clamp(0.0, 1.0)]
    }
}

/// Checks one axis's node positions.
fn check_nodes(axis: &str, nodes: &[f64]) -> Result<()> {
    let bad = |why: &str| {
        Err(Error::InvalidOption(format!(
            "bilinear {axis} nodes: {why}"
        )))
    };
    if nodes.len() < 2 {
        return bad("need at least 2");
    }
    if nodes.iter().any(|x| !x.is_finite()) {
        return bad("not finite");
    }
    if nodes[0] != 0.0 || nodes[nodes.len() - 1] != 1.0 {
        return bad("must start at 0 and end at 1");
    }
    if nodes.windows(2).any(|w| w[0] >= w[1]) {
        return bad("not strictly increasing");
    }
    Ok(())
}

/// Samples `x ∈ [0, 1)` from the density ∝ `a (1 - x) + b x` (`a, b ≥ 0`):
/// `x = ξ (a + b) / (a + √((1 - ξ) a² + ξ b²))`, the stable root of
/// `(b - a) x² / 2 + a x = ξ (a + b) / 2`. Uniform when `a = b` (including 0).
#[inline]
fn sample_linear(xi: f64, a: f64, b: f64) -> f64 {
    if a == b {
        return xi;
    }
    let denominator = a + ((1.0 - xi) * a * a + xi * b * b).sqrt();
    if denominator > 0.0 {
        (xi * (a + b) / denominator).clamp(0.0, ONE_MINUS_EPSILON_F64)
    } else {
        // a = 0 and ξ b² = 0: the density's zero end.
        0.0
    }
}

/// The CDF of the density ∝ `a (1 - x) + b x` on `[0, 1]`, the inverse of
/// [`sample_linear`]: `x (a (2 - x) + b x) / (a + b)`.
#[inline]
fn cdf_linear(x: f64, a: f64, b: f64) -> f64 {
    if a == b {
        return x;
    }
    (x * (a * (2.0 - x) + b * x) / (a + b)).clamp(0.0, 1.0)
}

/// The last index `j ∈ [0, n - 2]` with `value(j) <= x`, for a non-decreasing
/// `value` with `value(0) <= x < value(n - 1)`: the segment `[j, j + 1]` holding
/// `x`, never one of zero width.
#[inline]
fn last_at_most(n: usize, x: f64, value: impl Fn(usize) -> f64) -> usize {
    let (mut lo, mut hi) = (0usize, n - 1);
    while hi - lo > 1 {
        let mid = (lo + hi) / 2;
        if value(mid) <= x {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// The patch of `nodes` holding `x ∈ [0, 1]`: the last `i ≤ n - 2` with
/// `nodes[i] <= x`.
#[inline]
fn patch_of(nodes: &[f64], x: f64) -> usize {
    nodes[1..nodes.len() - 1].partition_point(|&n| n <= x)
}

/// A guide to [`patch_of`]: with `G = nodes.len() - 1` equal cells over `[0, 1]`,
/// entry `g` is the patch holding `g / G` (`G + 1` entries). A query then only
/// searches the nodes between the entries around it: O(1) for evenly spread
/// nodes (such as texel centres), O(log n) at worst.
fn guide(nodes: &[f64]) -> Vec<u32> {
    let cells = nodes.len() - 1;
    (0..=cells)
        .map(|g| patch_of(nodes, g as f64 / cells as f64) as u32)
        .collect()
}

/// [`patch_of`] through a [`guide`].
#[inline]
fn guided_patch(nodes: &[f64], guide: &[u32], x: f64) -> usize {
    let cells = guide.len() - 1;
    let g = ((x * cells as f64) as usize).min(cells);
    // One guide cell of margin either side absorbs the rounding of x·G.
    let lo = guide[g.saturating_sub(1)] as usize;
    let hi = guide[(g + 2).min(cells)] as usize;
    lo + nodes[lo + 1..=hi].partition_point(|&n| n <= x)
}

/// `x` rounded to `f32` below 1 and kept where [`patch_of`] finds patch `i`
/// (rounding can carry a point on a patch edge into the neighbour), with the patch
/// [`patch_of`] finds for it: `i`, unless the patch is narrower than an `f32` step.
#[inline]
fn point_in_patch(nodes: &[f64], guide: &[u32], i: usize, x: f64) -> (f32, usize) {
    let last = nodes.len() - 2;
    let mut y = (x as f32).min(ONE_MINUS_EPSILON);
    for _ in 0..4 {
        let yd = y as f64;
        if i < last && yd >= nodes[i + 1] && y > 0.0 {
            y = f32::from_bits(y.to_bits() - 1);
        } else if yd < nodes[i] {
            y = f32::from_bits(y.to_bits() + 1);
        } else {
            return (y, i);
        }
    }
    (y, guided_patch(nodes, guide, y as f64))
}

/// `(x - a) / (b - a)` clamped to `[0, 1]`.
#[inline]
fn local(x: f64, a: f64, b: f64) -> f64 {
    ((x - a) / (b - a)).clamp(0.0, 1.0)
}

#[inline]
fn lerp(t: f64, a: f64, b: f64) -> f64 {
    (1.0 - t) * a + t * b
}

/// `x` in `[0, 1]` as an `f64`; NaN gives 0.
#[inline]
fn unit_closed(x: f32) -> f64 {
    if x > 0.0 {
        (x as f64).min(1.0)
    } else {
        0.0
    }
}

/// `ξ` in `[0, 1)` as an `f64`; NaN gives 0.
#[inline]
fn unit_open(x: f32) -> f64 {
    if x > 0.0 {
        (x as f64).min(ONE_MINUS_EPSILON_F64)
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::alias::test_support;
    use crate::image::EnvImage;
    use crate::rng::{xi_2d, SplitMix64};

    /// Significance level of every chi-square test here.
    const ALPHA: f64 = 1e-3;

    fn close(a: f32, b: f32, tol: f32) -> bool {
        (a - b).abs() <= tol * (1.0 + b.abs())
    }

    /// Random increasing nodes from 0 to 1.
    fn random_nodes(rng: &mut SplitMix64, n: usize) -> Vec<f64> {
        let mut x: Vec<f64> = (0..n).map(|_| 0.2 + rng.next_f64()).collect();
        let mut sum = 0.0;
        for v in x.iter_mut() {
            sum += *v;
            *v = sum;
        }
        let mut nodes = vec![0.0];
        nodes.extend(
            x[..n - 2]
                .iter()
                .map(|v| v / x[n - 2] * (1.0 - 1.0 / n as f64)),
        );
        nodes.push(1.0);
        nodes
    }

    /// A random density: node values over three decades with zero patches, a zero
    /// node row and a zero node column in the middle.
    fn random_density(rng: &mut SplitMix64, mu: usize, mv: usize) -> BilinearDistribution2D {
        let mut values: Vec<f32> = (0..mu * mv)
            .map(|_| {
                if rng.next_f64() < 0.25 {
                    0.0
                } else {
                    10f32.powf(3.0 * rng.next_f32() - 1.5)
                }
            })
            .collect();
        for i in 0..mu {
            values[(mv / 2) * mu + i] = 0.0;
        }
        for k in 0..mv {
            values[k * mu + mu / 3] = 0.0;
        }
        if values.iter().all(|&x| x == 0.0) {
            values[mu - 1] = 1.0;
        }
        let (u, v) = (random_nodes(rng, mu), random_nodes(rng, mv));
        BilinearDistribution2D::new(&values, &u, &v)
    }

    /// `∫∫ p` over `[u0, u1] × [v0, v1]` inside one patch: a bilinear function's mean
    /// over a rectangle is its value at the centre.
    fn rect_probability(d: &BilinearDistribution2D, u0: f64, u1: f64, v0: f64, v1: f64) -> f64 {
        let (i, k) = (
            patch_of(&d.u_nodes, 0.5 * (u0 + u1)),
            patch_of(&d.v_nodes, 0.5 * (v0 + v1)),
        );
        let (u, v) = (0.5 * (u0 + u1), 0.5 * (v0 + v1));
        let tu = local(u, d.u_nodes[i], d.u_nodes[i + 1]);
        let tv = local(v, d.v_nodes[k], d.v_nodes[k + 1]);
        let mu = d.mu();
        let at = |kk: usize, ii: usize| d.values[kk * mu + ii] as f64;
        let b = lerp(
            tv,
            lerp(tu, at(k, i), at(k, i + 1)),
            lerp(tu, at(k + 1, i), at(k + 1, i + 1)),
        );
        b / d.integral * (u1 - u0) * (v1 - v0)
    }

    /// Bins: every patch split 2×2. Returns the bin rectangles.
    fn bins(d: &BilinearDistribution2D) -> Vec<[f64; 4]> {
        let halves = |n: &[f64]| -> Vec<f64> {
            let mut out = vec![];
            for w in n.windows(2) {
                out.push(w[0]);
                out.push(0.5 * (w[0] + w[1]));
            }
            out.push(1.0);
            out
        };
        let (us, vs) = (halves(&d.u_nodes), halves(&d.v_nodes));
        let mut out = vec![];
        for vw in vs.windows(2) {
            for uw in us.windows(2) {
                out.push([uw[0], uw[1], vw[0], vw[1]]);
            }
        }
        out
    }

    fn chi_square(
        d: &BilinearDistribution2D,
        expected_of: impl Fn([f64; 4]) -> f64,
        n: u64,
        seed: u64,
    ) -> f64 {
        let rects = bins(d);
        let nbu = 2 * (d.mu() - 1);
        let mut counts = vec![0u64; rects.len()];
        for k in 0..n {
            let s = d.sample_continuous(xi_2d(seed, k));
            let (u, v) = (s.uv[0] as f64, s.uv[1] as f64);
            let (i, kk) = (s.cell[0], s.cell[1]);
            let bu = 2 * i + (u >= 0.5 * (d.u_nodes[i] + d.u_nodes[i + 1])) as usize;
            let bv = 2 * kk + (v >= 0.5 * (d.v_nodes[kk] + d.v_nodes[kk + 1])) as usize;
            counts[bv * nbu + bu] += 1;
        }
        let expected: Vec<f64> = rects.iter().map(|&r| expected_of(r) * n as f64).collect();
        test_support::chi_square(&counts, &expected).2
    }

    #[test]
    fn hand_computed_linear_in_u() {
        // B(u, v) = u: I = 1/2, p = 2u, u = √ξ0, v = ξ1.
        let d = BilinearDistribution2D::new(&[0.0, 1.0, 0.0, 1.0], &[0.0, 1.0], &[0.0, 1.0]);
        assert_eq!(d.integral(), 0.5);
        for &(a, b) in &[(0.25f32, 0.3f32), (0.64, 0.9), (0.01, 0.0)] {
            let s = d.sample_continuous([a, b]);
            assert!(
                close(s.uv[0], a.sqrt(), 1e-6) && close(s.uv[1], b, 1e-6),
                "{s:?}"
            );
            assert!(close(s.pdf, 2.0 * a.sqrt(), 1e-6), "{s:?}");
            let back = d.invert(s.uv);
            assert!(
                close(back[0], a, 1e-6) && close(back[1], b, 1e-6),
                "{back:?}"
            );
        }
        assert_eq!(d.pdf([0.0, 0.5]), 0.0);
        assert_eq!(d.pdf([1.0, 0.5]), 2.0);
    }

    #[test]
    fn hand_computed_linear_in_v() {
        // Node rows 1 and 3: B = 1 + 2v, I = 2, CDF (v + v²)/2; ξ1 = .5 gives
        // v² + v - 1 = 0, v = (√5 - 1)/2, pdf (1 + 2v)/2 = √5/2.
        let d = BilinearDistribution2D::new(&[1.0, 1.0, 3.0, 3.0], &[0.0, 1.0], &[0.0, 1.0]);
        let s = d.sample_continuous([0.7, 0.5]);
        let golden = (5f32.sqrt() - 1.0) / 2.0;
        assert!(
            close(s.uv[1], golden, 1e-6) && close(s.uv[0], 0.7, 1e-6),
            "{s:?}"
        );
        assert!(close(s.pdf, 5f32.sqrt() / 2.0, 1e-6), "{s:?}");
        // Uneven nodes, constant values: the identity map.
        let d = BilinearDistribution2D::new(&[2.0; 9], &[0.0, 0.1, 1.0], &[0.0, 0.7, 1.0]);
        let s = d.sample_continuous([0.37, 0.81]);
        assert!(
            close(s.uv[0], 0.37, 1e-6) && close(s.uv[1], 0.81, 1e-6) && close(s.pdf, 1.0, 1e-6),
            "{s:?}"
        );
        assert_eq!(s.cell, [1, 1]);
    }

    #[test]
    fn guided_lookup_matches_binary_search() {
        let mut rng = SplitMix64::new(40);
        for n in [2, 3, 5, 17, 100] {
            let mut nodes = random_nodes(&mut rng, n);
            if n > 4 {
                // A cluster of close nodes.
                for (j, node) in nodes.iter_mut().enumerate().take(n / 2).skip(1) {
                    *node = j as f64 * 1e-9;
                }
            }
            let g = guide(&nodes);
            let mut probes: Vec<f64> = nodes.clone();
            probes.extend((0..2000).map(|_| rng.next_f64()));
            probes.extend(nodes.iter().map(|&x| (x - 1e-17).max(0.0)));
            probes.extend([0.0, 1.0, 1.0 - 1e-16]);
            for x in probes {
                assert_eq!(
                    guided_patch(&nodes, &g, x),
                    patch_of(&nodes, x),
                    "n {n} x {x}"
                );
            }
        }
    }

    #[test]
    fn linear_sampling_is_stable_and_inverts() {
        for &(a, b) in &[
            (1.0, 1.0),
            (0.0, 1.0),
            (1.0, 0.0),
            (1e-30, 1.0),
            (1.0, 1e-30),
            (3.0, 5.0),
            (0.0, 0.0),
        ] {
            for k in 0..=100 {
                let xi = (k as f64 / 100.0).min(ONE_MINUS_EPSILON_F64);
                let x = sample_linear(xi, a, b);
                assert!((0.0..1.0).contains(&x), "{a} {b} {xi} → {x}");
                assert!(
                    (cdf_linear(x, a, b) - xi).abs() < 1e-12,
                    "{a} {b} {xi} → {x}"
                );
            }
        }
    }

    #[test]
    fn normalised_by_quadrature() {
        // ∫∫ p = 1 by 2×2 Gauss-Legendre per patch (exact for bilinear).
        let mut rng = SplitMix64::new(3);
        for &(mu, mv) in &[(2, 2), (5, 4), (17, 9)] {
            let d = random_density(&mut rng, mu, mv);
            let g = 0.5 / 3f64.sqrt();
            let mut total = 0.0;
            for k in 0..mv - 1 {
                for i in 0..mu - 1 {
                    let (du, dv) = (
                        d.u_nodes[i + 1] - d.u_nodes[i],
                        d.v_nodes[k + 1] - d.v_nodes[k],
                    );
                    for &a in &[0.5 - g, 0.5 + g] {
                        for &b in &[0.5 - g, 0.5 + g] {
                            let u = d.u_nodes[i] + a * du;
                            let v = d.v_nodes[k] + b * dv;
                            total += d.patch_pdf(i, k, u, v) as f64 * du * dv / 4.0;
                        }
                    }
                }
            }
            assert!((total - 1.0).abs() < 1e-6, "{mu}x{mv}: {total}");
        }
        // A density off by 1 % fails the same check.
        let d = random_density(&mut rng, 5, 5);
        let total: f64 = bins(&d)
            .iter()
            .map(|r| rect_probability(&d, r[0], r[1], r[2], r[3]) * 1.01)
            .sum();
        assert!((total - 1.0).abs() > 1e-6);
    }

    #[test]
    fn sample_pdf_and_invert_agree() {
        let mut rng = SplitMix64::new(4);
        for &(mu, mv) in &[(2, 2), (5, 4), (17, 9), (3, 40)] {
            let d = random_density(&mut rng, mu, mv);
            for k in 0..5000 {
                let xi = xi_2d(5, k);
                let s = d.sample_continuous(xi);
                assert_eq!(d.pdf(s.uv), s.pdf, "{mu}x{mv} {xi:?} {s:?}");
                assert_eq!(
                    [
                        patch_of(&d.u_nodes, s.uv[0] as f64),
                        patch_of(&d.v_nodes, s.uv[1] as f64)
                    ],
                    s.cell
                );
                assert!(s.pdf > 0.0, "{mu}x{mv} {xi:?} {s:?}");
                let back = d.invert(s.uv);
                // ξ moves by p_marginal·Δv: allow for the f32 rounding of uv.
                let err = (back[0] - xi[0]).abs().max((back[1] - xi[1]).abs());
                assert!(err < 1e-4, "{mu}x{mv}: {xi:?} → {s:?} → {back:?}");
            }
        }
    }

    #[test]
    fn chi_square_against_integrated_pdf() {
        // α = 1e-3, N = 400 000 per density, seed 20 + index; bins are patch quarters.
        let mut rng = SplitMix64::new(6);
        for (j, &(mu, mv)) in [(2, 2), (6, 5), (13, 7)].iter().enumerate() {
            let d = random_density(&mut rng, mu, mv);
            let p = chi_square(
                &d,
                |r| rect_probability(&d, r[0], r[1], r[2], r[3]),
                400_000,
                20 + j as u64,
            );
            assert!(p > ALPHA, "{mu}x{mv}: p = {p}");
        }
    }

    #[test]
    fn chi_square_rejects_the_piecewise_constant_approximation() {
        // Same samples, expected counts from a density constant on each patch (the
        // same patch masses): the in-patch slope must be detected (α = 1e-3,
        // N = 400 000, seed 30).
        let mut rng = SplitMix64::new(7);
        let d = random_density(&mut rng, 6, 5);
        let flat = |r: [f64; 4]| {
            let (i, k) = (
                patch_of(&d.u_nodes, 0.5 * (r[0] + r[1])),
                patch_of(&d.v_nodes, 0.5 * (r[2] + r[3])),
            );
            let patch = rect_probability(
                &d,
                d.u_nodes[i],
                d.u_nodes[i + 1],
                d.v_nodes[k],
                d.v_nodes[k + 1],
            );
            patch / 4.0
        };
        let p = chi_square(&d, flat, 400_000, 30);
        assert!(p < ALPHA, "p = {p}");
    }

    #[test]
    fn zero_regions_are_never_sampled() {
        // Only the patch [1, 1] of a 4×4-node grid is non-zero, and only at one
        // corner: every sample must land inside it with pdf > 0.
        let mut values = vec![0.0f32; 16];
        values[2 * 4 + 2] = 5.0;
        let nodes = [0.0, 0.3, 0.6, 1.0];
        let d = BilinearDistribution2D::new(&values, &nodes, &nodes);
        for k in 0..20_000 {
            let s = d.sample_continuous(xi_2d(9, k));
            assert!(s.pdf > 0.0, "{s:?}");
            // The corner (2, 2) touches patches [1..2] × [1..2].
            assert!(
                (1..=2).contains(&s.cell[0]) && (1..=2).contains(&s.cell[1]),
                "{s:?}"
            );
        }
        for &a in &[0.0, 1e-30, 0.5, ONE_MINUS_EPSILON, 1.0, -1.0, f32::NAN] {
            for &b in &[1e-30, 0.5, ONE_MINUS_EPSILON, 1.0, f32::NAN, f32::INFINITY] {
                let s = d.sample_continuous([a, b]);
                assert!(s.uv.iter().all(|x| (0.0..1.0).contains(x)), "{s:?}");
                assert!(d.invert(s.uv).iter().all(|x| (0.0..=1.0).contains(x)));
            }
        }
    }

    #[test]
    fn all_zero_and_invalid_inputs() {
        let d = BilinearDistribution2D::new(
            &[0.0, f32::NAN, -1.0, f32::INFINITY],
            &[0.0, 1.0],
            &[0.0, 1.0],
        );
        assert_eq!(d.integral(), 0.0);
        let s = d.sample_continuous([0.3, 0.7]);
        assert_eq!(s.pdf, 0.0);
        assert!(s.uv.iter().all(|x| x.is_finite()));
        assert_eq!(d.pdf([0.5, 0.5]), 0.0);
        assert!(d.invert([0.2, 0.4]).iter().all(|x| x.is_finite()));
        let ok = [0.0, 1.0];
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 8], &[0.0, 0.5, 0.5, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 8], &[0.0, 0.7, 0.5, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.1, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &[0.0, 0.9], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 6], &[0.0, f64::NAN, 1.0], &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 5], &ok, &ok).is_err());
        assert!(BilinearDistribution2D::try_new(&[1.0; 4], &ok, &ok).is_ok());
        // Huge values neither overflow nor lose the density.
        let d = BilinearDistribution2D::new(&[f32::MAX; 4], &ok, &ok);
        let s = d.sample_continuous([0.4, 0.6]);
        assert!(close(s.pdf, 1.0, 1e-6), "{s:?}");
    }

    #[test]
    #[should_panic(expected = "strictly increasing")]
    fn new_panics_on_bad_nodes() {
        BilinearDistribution2D::new(&[1.0; 8], &[0.0, 0.5, 0.5, 1.0], &[0.0, 1.0]);
    }

    /// Node values at texel centres plus the square's edges (seam averages in u,
    /// clamped rows in v): the layout that makes `p` proportional to a bilinear
    /// lookup of the image.
    fn texel_centre_layout(image: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let mut u = vec![0.0];
        u.extend((0..w).map(|i| (i as f64 + 0.5) / w as f64));
        u.push(1.0);
        let mut v = vec![0.0];
        v.extend((0..h).map(|j| (j as f64 + 0.5) / h as f64));
        v.push(1.0);
        let mut values = Vec::with_capacity((w + 2) * (h + 2));
        for k in 0..h + 2 {
            let j = k.saturating_sub(1).min(h - 1);
            let row = &image[j * w..(j + 1) * w];
            let seam = 0.5 * (row[0] + row[w - 1]);
            values.push(seam);
            values.extend_from_slice(row);
            values.push(seam);
        }
        (values, u, v)
    }

    #[test]
    fn proportional_to_a_bilinear_image_lookup() {
        let (w, h) = (7, 5);
        let mut rng = SplitMix64::new(12);
        let texels: Vec<f32> = (0..w * h).map(|_| rng.next_f32() * 4.0).collect();
        let image = EnvImage::from_fn(w, h, |x, y| [texels[y * w + x]; 3]).unwrap();
        let (values, u, v) = texel_centre_layout(&texels, w, h);
        let d = BilinearDistribution2D::new(&values, &u, &v);
        for k in 0..2000 {
            let [a, b] = xi_2d(13, k);
            let want = image.lookup_bilinear(a, b)[0] as f64 / d.integral();
            let got = d.pdf([a, b]) as f64;
            assert!(
                (got - want).abs() < 1e-5 * want.max(1.0),
                "({a}, {b}): {got} vs {want}"
            );
        }
    }

    /// The light's layout for a lat-long map ([`texel_centre_layout`] with every
    /// node row weighted by `sin(π V_k)`, so the edge rows at `v = 0, 1` are 0).
    fn latlong_layout(image: &[f32], w: usize, h: usize) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
        let (mut values, u, v) = texel_centre_layout(image, w, h);
        for (row, &vk) in values.chunks_mut(w + 2).zip(&v) {
            let factor = if vk == 0.0 || vk == 1.0 {
                0.0
            } else {
                (std::f64::consts::PI * vk).sin() as f32
            };
            for x in row {
                *x *= factor;
            }
        }
        (values, u, v)
    }

    #[test]
    fn chi_square_fits_a_sun_next_to_a_dim_sky() {
        // The built-in sky in miniature: a 16×8 lat-long map of values 0.5 to 1.5
        // with one texel at 5e4 (the sun, ~99.8% of the mass), bilinear nodes at
        // texel centres, zero edge rows. α = 1e-3, N = 1 000 000, seed 41.
        let (w, h) = (16, 8);
        let mut texels: Vec<f32> = (0..w * h)
            .map(|k| 1.0 + 0.5 * ((k * 7 % 11) as f32 / 5.0 - 1.0))
            .collect();
        texels[2 * w + 5] = 5e4;
        let (values, u, v) = latlong_layout(&texels, w, h);
        let d = BilinearDistribution2D::new(&values, &u, &v);
        let n = 1_000_000u64;
        let samples: Vec<[f32; 2]> = (0..n)
            .map(|k| d.sample_continuous(xi_2d(41, k)).uv)
            .collect();

        // 1. Bins 4×4 per patch (each inside one patch, where the bilinear density
        //    is a polynomial and `rect_probability` is exact): the fit holds, in
        //    the sun's patches too.
        let s = 4;
        let cuts = |nodes: &[f64]| -> Vec<f64> {
            let mut out = vec![0.0];
            for pair in nodes.windows(2) {
                out.extend((1..=s).map(|j| pair[0] + (pair[1] - pair[0]) * j as f64 / s as f64));
            }
            *out.last_mut().unwrap() = 1.0;
            out
        };
        let (bu, bv) = (cuts(&d.u_nodes), cuts(&d.v_nodes));
        let mut counts = vec![0u64; (bu.len() - 1) * (bv.len() - 1)];
        for uv in &samples {
            let (i, k) = (patch_of(&bu, uv[0] as f64), patch_of(&bv, uv[1] as f64));
            counts[k * (bu.len() - 1) + i] += 1;
        }
        let mut expected = vec![];
        for vw in bv.windows(2) {
            for uw in bu.windows(2) {
                expected.push(rect_probability(&d, uw[0], uw[1], vw[0], vw[1]) * n as f64);
            }
        }
        let (stat, dof, p) = test_support::chi_square(&counts, &expected);
        assert!(p > ALPHA, "patch bins: χ² = {stat} (dof {dof}), p = {p}");

        // 2. Bins = texel cells, which straddle the density's kinks at the texel
        //    centres. Integrated exactly (as four quarter-cells) the fit holds.
        //    Integrated by a 2×2 Gauss-Legendre rule over the whole cell (what the
        //    invariant harness does when its bin budget forbids splitting cells),
        //    the sun's cell gets (1 - 1/(2√3))² / (3/4)² = 0.8995 of its mass, the
        //    rest going to its neighbours while ∫p stays ≈ 1, and the fit is
        //    rejected: bins that straddle node kinks must be integrated piecewise.
        let mut texel_counts = vec![0u64; w * h];
        for uv in &samples {
            let i = ((uv[0] as f64 * w as f64) as usize).min(w - 1);
            let j = ((uv[1] as f64 * h as f64) as usize).min(h - 1);
            texel_counts[j * w + i] += 1;
        }
        let g = [0.5 - 0.5 / 3f64.sqrt(), 0.5 + 0.5 / 3f64.sqrt()];
        let (mut exact, mut gauss) = (vec![], vec![]);
        for j in 0..h {
            for i in 0..w {
                let (u0, v0, du, dv) = (
                    i as f64 / w as f64,
                    j as f64 / h as f64,
                    1.0 / w as f64,
                    1.0 / h as f64,
                );
                let (um, vm) = (u0 + 0.5 * du, v0 + 0.5 * dv);
                let quarters = rect_probability(&d, u0, um, v0, vm)
                    + rect_probability(&d, um, u0 + du, v0, vm)
                    + rect_probability(&d, u0, um, vm, v0 + dv)
                    + rect_probability(&d, um, u0 + du, vm, v0 + dv);
                exact.push(quarters * n as f64);
                let mut q = 0.0;
                for a in g {
                    for b in g {
                        let uv = [(u0 + a * du) as f32, (v0 + b * dv) as f32];
                        q += d.pdf(uv) as f64 * du * dv / 4.0;
                    }
                }
                gauss.push(q * n as f64);
            }
        }
        let total = |e: &[f64]| e.iter().sum::<f64>() / n as f64;
        assert!((total(&exact) - 1.0).abs() < 1e-9, "{}", total(&exact));
        assert!((total(&gauss) - 1.0).abs() < 1e-4, "{}", total(&gauss));
        let (stat, dof, p) = test_support::chi_square(&texel_counts, &exact);
        assert!(
            p > ALPHA,
            "texel bins, exact: χ² = {stat} (dof {dof}), p = {p}"
        );
        let (stat, dof, p) = test_support::chi_square(&texel_counts, &gauss);
        assert!(
            p < ALPHA,
            "texel bins, GL2: χ² = {stat} (dof {dof}), p = {p}"
        );
        let sun = 2 * w + 5;
        let ratio = gauss[sun] / exact[sun];
        assert!(
            (ratio - 0.8995).abs() < 1e-3,
            "sun cell GL2 / exact = {ratio}"
        );
    }

    #[test]
    fn is_send_and_sync() {
        fn check<T: Send + Sync>() {}
        check::<BilinearDistribution2D>();
    }

    /// Per-sample cost against the piecewise-constant inversion sampler, with nodes
    /// at the texel centres of a 4096×2048 random image (4098×2050 nodes) and of a
    /// 64×32 one. Run: `cargo test --release -p envlight --lib
    /// bilinear::tests::timing -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn timing_against_inversion() {
        for (w, h) in [(4096, 2048), (64, 32)] {
            let mut rng = SplitMix64::new(1);
            let texels: Vec<f32> = (0..w * h)
                .map(|_| 10f32.powf(4.0 * rng.next_f32() - 2.0))
                .collect();
            let (values, u, v) = texel_centre_layout(&texels, w, h);
            let start = std::time::Instant::now();
            let d = BilinearDistribution2D::new(&values, &u, &v);
            let build = start.elapsed();
            let inversion = crate::distribution::Distribution2D::new(&texels, w);
            let xi: Vec<[f32; 2]> = (0..2_000_000).map(|k| xi_2d(2, k)).collect();
            let time = |name: &str, run: &dyn Fn([f32; 2]) -> f32| {
                test_support::time_per_call(&format!("{w}x{h} {name}"), &xi, run)
            };
            time("inversion sample", &|x| {
                inversion.sample_continuous(x).uv[0]
            });
            time("bilinear sample", &|x| d.sample_continuous(x).uv[0]);
            time("bilinear pdf", &|x| d.pdf(x));
            time("bilinear invert", &|x| d.invert(x)[0]);
            println!(
                "{w}x{h} build {build:?}; bytes/texel: bilinear {:.2}, inversion {:.2}",
                d.memory_bytes() as f64 / (w * h) as f64,
                inversion.memory_bytes() as f64 / (w * h) as f64
            );
        }
    }
}
