//! [`EnvironmentLight::efficiency`]: the sampling efficiency
//! `(∫ Y dω)² / ∫ (Y² / p) dω` by Gauss-Legendre quadrature over the image.

use super::build::{importance_row, LuminanceRows};
use super::{EnvironmentLight, Mapping, Planar};
use crate::image::{Lookup, WrapU};
use crate::mapping::equal_area::EQUAL_AREA_JACOBIAN;
use crate::mapping::EQUIRECT_JACOBIAN;
use crate::width::{at_width, VectorWidth};
use rayon::prelude::*;

impl EnvironmentLight {
    /// Sampling efficiency `(∫ Y dω)² / ∫ (Y² / p) dω`: 1 when the pdf is exactly
    /// proportional to luminance; the variance of the estimator `Y/p` of `∫ Y dω`
    /// is `(1/efficiency - 1) (∫ Y dω)²` per sample. 0 for a black map or when the
    /// pdf misses light (as MIS compensation does on purpose).
    ///
    /// Computed by quadrature (2×2 Gauss-Legendre points in each quarter of every
    /// texel, exact for bilinear radiance in u), in parallel. `O(16 w h)` lookups.
    pub fn efficiency(&self) -> f64 {
        let (ey, ey2p, _) = self.luminance_moments(false);
        efficiency_of(ey, ey2p)
    }

    /// [`Self::efficiency`], and for a light whose sampling table was reduced
    /// ([`LightOptions::table_width`](super::LightOptions::table_width)) the
    /// efficiency the full-resolution table would have had: what the reduction
    /// costs. Both come from one quadrature pass; the full table's density is read
    /// from the texel-grid importance (with the full table's normalisation), so no
    /// full table is built. The second figure is `None` for a table that was not
    /// reduced and for a compensated light.
    pub fn efficiency_with_full_table(&self) -> (f64, Option<f64>) {
        let reduced = self.table_size() != [self.image.width(), self.image.height()];
        let full = reduced && !self.compensated;
        let (ey, ey2p, ey2p_full) = self.luminance_moments(full);
        (
            efficiency_of(ey, ey2p),
            full.then(|| efficiency_of(ey, ey2p_full)),
        )
    }

    /// `(∫ Y dω, ∫ Y²/p dω)` by quadrature over the image (unscaled; efficiency is
    /// scale-free). Summed in row order, so independent of the thread count.
    ///
    /// Nodes: Gauss-Legendre, 2 points per quarter texel along each axis (each
    /// quarter lies inside one patch of the bilinear reconstruction), so 16 per
    /// texel. The luminance at the nodes is the lookup's reconstruction, computed
    /// row by row: for each node height, the two image rows' luminance is blended
    /// once, then read at the u nodes (luminance is linear in RGB). The pdf is read
    /// at every node for the bilinear density, and once per texel for the others,
    /// which are constant over each texel.
    ///
    /// With `full_table`, also `∫ Y²/p` for the density of the full-resolution
    /// table (`p ∝` the texel-grid importance), as the third value (else 0).
    fn luminance_moments(&self, full_table: bool) -> (f64, f64, f64) {
        let (w, h) = (self.image.width(), self.image.height());
        let nodes = efficiency_nodes();
        let (mapping, lookup) = (self.options.mapping, self.options.lookup);
        let periodic = mapping.wrap() == WrapU::Periodic;
        let jacobian_scale = match mapping {
            Mapping::Equirectangular => EQUIRECT_JACOBIAN as f64,
            Mapping::EqualArea => EQUAL_AREA_JACOBIAN as f64,
        };
        let constant_per_texel = !matches!(self.planar, Planar::Bilinear(_));
        // The full table's planar pdf is f · w h / Σ f; a reduced table's cells sum
        // their blocks, so Σ f is its integral times its cell count.
        let [tw, th] = self.table_size();
        let full_scale = (w * h) as f64 / (self.planar.integral() * (tw * th) as f64);
        // The u of every node along a row, for the bilinear density's pdfs.
        let node_us: Vec<f32> = if constant_per_texel {
            Vec::new()
        } else {
            (0..w)
                .flat_map(|i| nodes.map(|tu| ((i as f64 + tu) / w as f64) as f32))
                .collect()
        };
        // Rows go to each task in runs of neighbours, so a cache of the last three
        // rows' luminance computes each row's about once instead of three times.
        let init = || {
            (
                LuminanceRows::new(w),
                [vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]],
                vec![0.0f32; node_us.len()],
            )
        };
        (0..h)
            .into_par_iter()
            .map_init(init, |(cache, [above, here, below], node_pdfs), j| {
                let (mut ey, mut ey2p, mut ey2p_full) = (0.0f64, 0.0f64, 0.0f64);
                // The reciprocal of each texel's (constant) pdf, +∞ where it is 0:
                // one division per texel instead of one per node. A table reduced
                // by r pools r × r texels per cell: texel (i, j) is in cell
                // (i / r, j / r).
                let reciprocal = |p: f32| {
                    if p > 0.0 {
                        1.0 / p as f64
                    } else {
                        f64::INFINITY
                    }
                };
                let per_texel = |nu: usize, cell_pdf: &dyn Fn(usize, usize) -> f32| {
                    let r = w / nu;
                    (0..nu)
                        .flat_map(|i| std::iter::repeat_n(reciprocal(cell_pdf(i, j / r)), r))
                        .collect()
                };
                let inv_texel_pdf: Vec<f64> = match &self.planar {
                    Planar::Inversion(d) => per_texel(d.nu(), &|i, j| d.cell_pdf(i, j)),
                    Planar::Alias(d) => per_texel(d.nu(), &|i, j| d.cell_pdf(i, j)),
                    Planar::Hierarchical(d) => per_texel(d.nu(), &|i, j| d.cell_pdf(i, j)),
                    Planar::Bilinear(_) => Vec::new(),
                };
                let inv_full_pdf: Vec<f64> = if full_table {
                    let mut f = vec![0.0f32; w];
                    importance_row(&self.image, lookup, mapping, cache, j, &mut f);
                    f.iter()
                        .map(|&x| reciprocal((x as f64 * full_scale) as f32))
                        .collect()
                } else {
                    Vec::new()
                };
                // The neighbouring rows a node above or below the centre blends with
                // (clamped at the top and bottom).
                above.copy_from_slice(cache.row(&self.image, j.saturating_sub(1)).0);
                here.copy_from_slice(cache.row(&self.image, j).0);
                below.copy_from_slice(cache.row(&self.image, (j + 1).min(h - 1)).0);
                let (above, here, below) = (&*above, &*here, &*below);
                let mut blended = vec![0.0f32; w];
                // Node heights and weights (relative to the uniform ¼): the node
                // lookup is kinked inside the band, so its nodes split there.
                let heights: Vec<(f64, f64)> = if lookup == Lookup::Node {
                    node_lookup_heights(j, h)
                } else {
                    nodes.iter().map(|&tv| (tv, 1.0)).collect()
                };
                for &(tv, qw) in &heights {
                    let v = (j as f64 + tv) / h as f64;
                    let dw = jacobian_scale * mapping.area_factor(v);
                    match lookup {
                        Lookup::Nearest => blended.copy_from_slice(here),
                        Lookup::Node => {
                            // Rows as nodes at k/(h-1): the two around v are among
                            // j-1, j, j+1.
                            let (k0, k1, t) = node_rows(v, h);
                            let row = |k: usize| {
                                if k + 1 == j {
                                    above
                                } else if k == j {
                                    here
                                } else {
                                    below
                                }
                            };
                            let (r0, r1) = (row(k0), row(k1));
                            for ((b, &y0), &y1) in blended.iter_mut().zip(r0).zip(r1) {
                                *b = y0 + t * (y1 - y0);
                            }
                        }
                        Lookup::Bilinear => {
                            let (other, t) = if tv < 0.5 {
                                (above, (0.5 - tv) as f32)
                            } else {
                                (below, (tv - 0.5) as f32)
                            };
                            for ((b, &y0), &y1) in blended.iter_mut().zip(here).zip(other) {
                                *b = y0 + t * (y1 - y0);
                            }
                        }
                    }
                    if constant_per_texel {
                        // Without a full table to weigh, the texels' own pdfs twice
                        // (one multiply-add per texel, cheaper than a branch).
                        let second = if full_table {
                            &inv_full_pdf
                        } else {
                            &inv_texel_pdf
                        };
                        let [sum_y, sum_y2p, sum_y2p_full] =
                            node_row_moments(&blended, [&inv_texel_pdf, second], lookup, periodic);
                        ey += sum_y * dw * qw;
                        ey2p += sum_y2p * (dw * dw) * qw;
                        ey2p_full += sum_y2p_full * (dw * dw) * qw;
                        continue;
                    }
                    // The density at every u node of this height, in blocks.
                    if let Planar::Bilinear(d) = &self.planar {
                        d.pdf_at_height(&node_us, v as f32, node_pdfs);
                    }
                    for i in 0..w {
                        let left = if i > 0 {
                            blended[i - 1]
                        } else if periodic {
                            blended[w - 1]
                        } else {
                            blended[0]
                        };
                        let right = if i + 1 < w {
                            blended[i + 1]
                        } else if periodic {
                            blended[0]
                        } else {
                            blended[w - 1]
                        };
                        for (n, &tu) in nodes.iter().enumerate() {
                            let y = match lookup {
                                Lookup::Nearest => blended[i],
                                Lookup::Bilinear | Lookup::Node if tu < 0.5 => {
                                    let t = (0.5 - tu) as f32;
                                    blended[i] + t * (left - blended[i])
                                }
                                Lookup::Bilinear | Lookup::Node => {
                                    let t = (tu - 0.5) as f32;
                                    blended[i] + t * (right - blended[i])
                                }
                            } as f64;
                            ey += y * dw * qw;
                            if y > 0.0 {
                                let p_uv = node_pdfs[4 * i + n] as f64;
                                ey2p += if p_uv > 0.0 {
                                    y * y * dw * dw * qw / p_uv
                                } else {
                                    f64::INFINITY
                                };
                            }
                        }
                    }
                }
                let cell = 1.0 / (16.0 * w as f64 * h as f64);
                let full = if full_table { ey2p_full * cell } else { 0.0 };
                (ey * cell, ey2p * cell, full)
            })
            .collect::<Vec<_>>()
            .into_iter()
            .fold((0.0, 0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1, a.2 + b.2))
    }
}

/// The node heights within texel row `j` (as fractions of the row) and their
/// weights relative to the uniform rule's ¼ each, for [`Lookup::Node`]: four
/// Gauss-Legendre points on either side of the node `v = j/(h-1)` that lies in the
/// row (exact for polynomials of degree 7 on each piece of the reconstruction:
/// near the poles `Y² sin² θ` is of degree 4 in v). One row: the uniform rule.
fn node_lookup_heights(j: usize, h: usize) -> Vec<(f64, f64)> {
    if h < 2 {
        return efficiency_nodes().iter().map(|&tv| (tv, 1.0)).collect();
    }
    use super::build::{GL4_POINTS as GL_X, GL4_WEIGHTS as GL_W};
    // The node's place in the row, in [0, 1].
    let a = (j as f64 / (h - 1) as f64 * h as f64 - j as f64).clamp(0.0, 1.0);
    let mut out = Vec::with_capacity(8);
    for (start, length) in [(0.0, a), (a, 1.0 - a)] {
        if length > 0.0 {
            for (x, w) in GL_X.iter().zip(GL_W) {
                out.push((start + length * x, 4.0 * length * w));
            }
        }
    }
    out
}

/// The rows [`Lookup::Node`] blends at height `v` of an image of `h` rows (rows as
/// nodes at `k/(h-1)`) and the second's weight.
fn node_rows(v: f64, h: usize) -> (usize, usize, f32) {
    if h < 2 {
        return (0, 0, 0.0);
    }
    let s = v.clamp(0.0, 1.0) * (h - 1) as f64;
    let k = (s.floor() as usize).min(h - 2);
    (k, k + 1, (s - k as f64) as f32)
}

/// `(∫ Y)² / ∫ Y²/p`, or 0 when either is not positive and finite.
fn efficiency_of(ey: f64, ey2p: f64) -> f64 {
    if ey > 0.0 && ey2p.is_finite() && ey2p > 0.0 {
        ey * ey / ey2p
    } else {
        0.0
    }
}

/// The efficiency quadrature's node positions within a texel, along each axis:
/// two Gauss-Legendre points in each half.
fn efficiency_nodes() -> [f64; 4] {
    let g = 0.5 / 3f64.sqrt();
    [
        0.25 - 0.5 * g,
        0.25 + 0.5 * g,
        0.75 - 0.5 * g,
        0.75 + 0.5 * g,
    ]
}

/// One row of quadrature nodes (at one height) of [`EnvironmentLight::efficiency`]
/// for a density that is constant over each texel: `[Σ_i Σ_nodes y, Σ_i Σ_nodes
/// y² / p_i, Σ_i Σ_nodes y² / q_i]` over the texels' four u nodes, from the row's
/// reconstructed luminance `blended` at the texel centres and each texel's `1 / p`
/// and `1 / q` (two densities at once; +∞ where a density is 0).
///
/// Within a texel, y is constant (nearest) or linear on each half (bilinear), and the
/// four Gauss-Legendre nodes, exact for cubics on each half, sum to closed forms:
/// `Σ y = 4 mean(y)` and `Σ y² = 4 mean(y²)` ([`texel_moments`]). The texels
/// between the edges go through [`interior_moments`], in vector lanes.
fn node_row_moments(
    blended: &[f32],
    [inv_p, inv_q]: [&[f64]; 2],
    lookup: Lookup,
    periodic: bool,
) -> [f64; 3] {
    let w = blended.len();
    // Along u the node lookup is the bilinear one.
    let bilinear = lookup != Lookup::Nearest;
    let texel = |left: f32, centre: f32, right: f32, inv_p: f64, inv_q: f64| {
        texel_moments(left, centre, right, inv_p, inv_q, bilinear)
    };
    let (first, last) = (blended[0], blended[w - 1]);
    let (before_first, beyond_last) = if periodic {
        (last, first)
    } else {
        (first, last)
    };
    if w == 1 {
        return texel(before_first, first, beyond_last, inv_p[0], inv_q[0]);
    }
    let interior = interior_moments(blended, inv_p, inv_q, lookup);
    let edges = [
        texel(before_first, first, blended[1], inv_p[0], inv_q[0]),
        texel(
            blended[w - 2],
            last,
            beyond_last,
            inv_p[w - 1],
            inv_q[w - 1],
        ),
    ];
    std::array::from_fn(|m| interior[m] + (edges[0][m] + edges[1][m]))
}

/// Partial sums per lane in [`interior_moments`]: a vector's worth of f64 at the
/// widest (AVX-512), two at AVX2.
const LANES: usize = 8;

/// [`node_row_moments`] over the texels between the row's ends (`1..w-1`, for
/// `w ≥ 2`), in [`LANES`] running sums added up in a fixed order at the end, so
/// the loop runs in vector lanes and the result does not depend on their width;
/// compiled for the widest vectors the CPU has.
fn interior_moments(blended: &[f32], inv_p: &[f64], inv_q: &[f64], lookup: Lookup) -> [f64; 3] {
    let bilinear = lookup != Lookup::Nearest;
    at_width!(VectorWidth::detect(), fn(blended: &[f32], inv_p: &[f64], inv_q: &[f64], bilinear: bool) -> [f64; 3] {
        interior_lanes(blended, inv_p, inv_q, bilinear)
    })
}

/// The body of [`interior_moments`].
#[inline(always)]
fn interior_lanes(blended: &[f32], inv_p: &[f64], inv_q: &[f64], bilinear: bool) -> [f64; 3] {
    let n = blended.len().saturating_sub(2);
    let mut sums = [[0.0f64; LANES]; 3];
    let whole = n / LANES * LANES;
    for base in (0..whole).step_by(LANES) {
        // Fixed-size views, so the lane loop has no bounds checks to keep it scalar.
        let y: &[f32; LANES + 2] = blended[base..base + LANES + 2]
            .try_into()
            .expect("in range");
        let p: &[f64; LANES] = inv_p[base + 1..base + 1 + LANES]
            .try_into()
            .expect("in range");
        let q: &[f64; LANES] = inv_q[base + 1..base + 1 + LANES]
            .try_into()
            .expect("in range");
        for k in 0..LANES {
            let [sum_y, y2p, y2q] = texel_moments(y[k], y[k + 1], y[k + 2], p[k], q[k], bilinear);
            sums[0][k] += sum_y;
            sums[1][k] += y2p;
            sums[2][k] += y2q;
        }
    }
    for i in whole..n {
        let k = i - whole;
        let [sum_y, y2p, y2q] = texel_moments(
            blended[i],
            blended[i + 1],
            blended[i + 2],
            inv_p[i + 1],
            inv_q[i + 1],
            bilinear,
        );
        sums[0][k] += sum_y;
        sums[1][k] += y2p;
        sums[2][k] += y2q;
    }
    std::array::from_fn(|m| {
        let s = &sums[m];
        ((s[0] + s[1]) + (s[2] + s[3])) + ((s[4] + s[5]) + (s[6] + s[7]))
    })
}

/// One texel's `[Σ y, Σ y²/p, Σ y²/q]` over its four u nodes (see
/// [`node_row_moments`]), from the blended luminance at its centre and its
/// neighbours' and the reciprocals of its two densities; no branches.
#[inline(always)]
fn texel_moments(
    left: f32,
    centre: f32,
    right: f32,
    inv_p: f64,
    inv_q: f64,
    bilinear: bool,
) -> [f64; 3] {
    let c = centre as f64;
    let (sum_y, sum_y2) = if bilinear {
        let (l, r) = (0.5 * (left as f64 + c), 0.5 * (c + right as f64));
        // The mean of the square of a line from a to b is (a² + ab + b²) / 3.
        let square = |a: f64, b: f64| a * a + a * b + b * b;
        (l + 2.0 * c + r, (2.0 / 3.0) * (square(l, c) + square(c, r)))
    } else {
        (4.0 * c, 4.0 * c * c)
    };
    // A texel with no light adds nothing, even where a pdf is 0.
    let lit = sum_y2 > 0.0;
    [
        sum_y,
        if lit { sum_y2 * inv_p } else { 0.0 },
        if lit { sum_y2 * inv_q } else { 0.0 },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed forms of one efficiency node row against the four Gauss-Legendre
    /// nodes of each texel evaluated one by one, edges and zero pdfs included.
    #[test]
    fn node_row_moments_match_the_nodes() {
        let nodes = efficiency_nodes();
        let mut rng = crate::rng::SplitMix64::new(9);
        for w in [1usize, 2, 3, 4, 7, 12, 13] {
            // Runs of three black texels, the middle one (whose nodes all see black)
            // with pdf 0; and on the two-texel row a lit texel with pdf 0, which
            // makes the sum infinite.
            let blended: Vec<f32> = (0..w)
                .map(|i| {
                    if (3..6).contains(&(i % 6)) {
                        0.0
                    } else {
                        rng.next_f32() * 3.0
                    }
                })
                .collect();
            let inv_pdf: Vec<f64> = (0..w)
                .map(|i| {
                    if i % 6 == 4 || (i == 1 && w == 2) {
                        f64::INFINITY
                    } else {
                        1.0 / (0.1 + rng.next_f32() as f64)
                    }
                })
                .collect();
            for periodic in [true, false] {
                for lookup in [Lookup::Nearest, Lookup::Bilinear] {
                    let at = |i: isize| {
                        let i = if periodic {
                            i.rem_euclid(w as isize)
                        } else {
                            i.clamp(0, w as isize - 1)
                        };
                        blended[i as usize] as f64
                    };
                    let (mut want_y, mut want_y2p) = (0.0f64, 0.0f64);
                    for i in 0..w as isize {
                        for &t in &nodes {
                            let y = match lookup {
                                Lookup::Nearest => at(i),
                                Lookup::Bilinear | Lookup::Node if t < 0.5 => {
                                    at(i) + (0.5 - t) * (at(i - 1) - at(i))
                                }
                                Lookup::Bilinear | Lookup::Node => {
                                    at(i) + (t - 0.5) * (at(i + 1) - at(i))
                                }
                            };
                            want_y += y;
                            if y > 0.0 {
                                want_y2p += y * y * inv_pdf[i as usize];
                            }
                        }
                    }
                    let halved: Vec<f64> = inv_pdf.iter().map(|x| 0.5 * x).collect();
                    let [y, y2p, y2q] =
                        node_row_moments(&blended, [&inv_pdf, &halved], lookup, periodic);
                    assert!(y2q == 0.5 * y2p || (y2q - 0.5 * y2p).abs() <= 1e-12 * y2p);
                    let close = |a: f64, b: f64| a == b || (a - b).abs() <= 1e-12 * b.abs();
                    assert!(
                        close(y, want_y) && close(y2p, want_y2p),
                        "w={w} periodic={periodic} {lookup:?}: ({y}, {y2p}) vs ({want_y}, {want_y2p})"
                    );
                }
            }
        }
    }
}
