//! The fine level of a [`ProductSampler`](super::ProductSampler): the light's own
//! density over its cells, cut into rectangular patches, with what it takes to draw
//! a point of a patch in proportion to that density and to read the density back.
//!
//! *Cells* are where the light's density is one piece:
//! - for the piecewise-constant density, the image's texels (`w × h`), weighted by
//!   the texel-grid importance `Y(filtered) · J_j` of DESIGN.md §4 step 1 (never
//!   MIS-compensated), constant over each;
//! - for the piecewise-bilinear density, the `(w + 1) × (h + 1)` cells between
//!   texel centres (half cells at the image's edges), over which the density is the
//!   bilinear interpolation of `Y · J` at their corners (as in
//!   [`crate::bilinear`]), weighted by its integral `M = Δu Δv Σ corners / 4`.
//!
//! A patch is a block of cells; within patch `k` a cell is drawn by two fixed-point
//! CDFs (a row from the patch's marginal, a cell from the row's segment) and a
//! point in the cell uniformly or, for the bilinear density, by inverting the
//! bilinear function's linear marginal and conditional. The density in `(u, v)`
//! given the patch is `q(u, v | k) = g(u, v) / F_k`, `g` the light's (unnormalised)
//! density and `F_k` its integral over the patch: up to the CDFs' 2⁻³² rounding,
//! which [`Fine::locate`] reports exactly as sampling uses it.

use super::bounds::Region;
use crate::bilinear::sample_linear;
use crate::distribution::{cell_index, place_in_cell_f64, Distribution1D, CDF_ONE};
use crate::light::{bilinear_nodes, Density, EnvironmentLight};
use rayon::prelude::*;

/// How the density is laid over a cell.
#[derive(Debug, Clone)]
enum Cells {
    /// Texels, the density constant over each.
    Texels,
    /// Cells between texel centres, the density bilinear over each: `values` at
    /// the `(w + 2) × (h + 2)` nodes `(u_nodes[i], v_nodes[j])`, row-major.
    Bilinear {
        values: Vec<f32>,
        u_nodes: Vec<f64>,
        v_nodes: Vec<f64>,
    },
}

/// The fine level: cells, patches, their CDFs and regions (see the module docs).
#[derive(Debug, Clone)]
pub(super) struct Fine {
    cells: Cells,
    /// The image's `[w, h]`.
    size: [usize; 2],
    /// Cells across and down: `[w, h]` or `[w + 1, h + 1]`.
    grid: [usize; 2],
    /// `[Pw, Ph]`.
    pub patches: [usize; 2],
    /// First cell column of each patch column, `Pw + 1` entries.
    pub(super) col_start: Vec<u32>,
    /// First cell row of each patch row, `Ph + 1` entries.
    pub(super) row_start: Vec<u32>,
    /// The patch column of each cell column.
    pub(super) col_patch: Vec<u32>,
    /// The patch row of each cell row.
    pub(super) row_patch: Vec<u32>,
    /// Fixed-point CDFs of the row segments: cell row `j`, patch column `c`
    /// (cells `x0..x1`) at `j (cw + Pw) + x0 + c`, `x1 - x0 + 1` entries.
    pub(super) segment_cdf: Vec<u32>,
    /// Fixed-point CDFs over each patch's rows: patch `(c, r)` (rows `y0..y1`) at
    /// `Pw (y0 + r) + c (y1 - y0 + 1)`, `y1 - y0 + 1` entries.
    pub(super) marginal_cdf: Vec<u32>,
    /// Patch `k = r Pw + c`: its share `P_k = F_k / Σ F` of the density.
    pub power: Vec<f64>,
    /// The regions of each patch's lit cells (`None` for a patch without power).
    pub regions: Vec<Option<Region>>,
    /// Each patch's centre of light: the unit mean of its cells' centre
    /// directions (light frame) weighted by their probability within the patch.
    pub centres: Vec<[f64; 3]>,
    /// For texels, `w h / CDF_ONE²`: a texel's density in `(u, v)` given its patch
    /// is its two CDF widths times this.
    texel_scale: f64,
}

impl Fine {
    /// The fine level of `light` with `patches` (clamped to the cell grid).
    pub fn new(light: &EnvironmentLight, patches: [usize; 2]) -> Self {
        let (w, h) = (light.image().width(), light.image().height());
        let cells = match light.options().density {
            Density::PiecewiseConstant => Cells::Texels,
            Density::PiecewiseBilinear => {
                let (values, u_nodes, v_nodes) = bilinear_nodes(light.image(), light.mapping());
                Cells::Bilinear {
                    values,
                    u_nodes,
                    v_nodes,
                }
            }
        };
        let grid = match cells {
            Cells::Texels => [w, h],
            Cells::Bilinear { .. } => [w + 1, h + 1],
        };
        let [cw, ch] = grid;
        let (pw, ph) = (patches[0].clamp(1, cw), patches[1].clamp(1, ch));
        // Cell counts fit in u32: an image side is at most 2²⁴ (image::MAX_SIDE).
        let starts = |n: usize, parts: usize| -> Vec<u32> {
            (0..=parts).map(|p| (p * n / parts) as u32).collect()
        };
        let (col_start, row_start) = (starts(cw, pw), starts(ch, ph));
        let owners = |start: &[u32], n: usize| -> Vec<u32> {
            let mut owner = vec![0u32; n];
            for (p, edges) in start.windows(2).enumerate() {
                owner[edges[0] as usize..edges[1] as usize].fill(p as u32);
            }
            owner
        };
        let (col_patch, row_patch) = (owners(&col_start, cw), owners(&row_start, ch));

        // One band of patch rows per task: each band's CDFs are contiguous runs of
        // both arrays.
        let mut segment_cdf = vec![0u32; ch * (cw + pw)];
        let mut marginal_cdf = vec![0u32; pw * (ch + ph)];
        let mut bands = Vec::with_capacity(ph);
        let (mut segments, mut marginals) = (&mut segment_cdf[..], &mut marginal_cdf[..]);
        for r in 0..ph {
            let (y0, y1) = (row_start[r] as usize, row_start[r + 1] as usize);
            let (band_segments, rest) =
                std::mem::take(&mut segments).split_at_mut((y1 - y0) * (cw + pw));
            segments = rest;
            let (band_marginals, rest) =
                std::mem::take(&mut marginals).split_at_mut(pw * (y1 - y0 + 1));
            marginals = rest;
            bands.push((y0..y1, band_segments, band_marginals));
        }
        let fill_rows = |first: usize, out: &mut [f32]| match &cells {
            Cells::Texels => light.importance_rows(first, out),
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => {
                for (jj, row) in out.chunks_exact_mut(cw).enumerate() {
                    let j = first + jj;
                    let (above, below) = (&values[j * (w + 2)..], &values[(j + 1) * (w + 2)..]);
                    let dv = v_nodes[j + 1] - v_nodes[j];
                    for (i, m) in row.iter_mut().enumerate() {
                        let corners = above[i] as f64
                            + above[i + 1] as f64
                            + below[i] as f64
                            + below[i + 1] as f64;
                        let mass = 0.25 * corners * dv * (u_nodes[i + 1] - u_nodes[i]);
                        *m = crate::distribution::positive_weight(mass);
                    }
                }
            }
        };
        let band_sums: Vec<Vec<f64>> = bands
            .into_par_iter()
            .map(|(rows, segments, marginals)| {
                build_band(cw, &col_start, rows, segments, marginals, &fill_rows)
            })
            .collect();
        let sums: Vec<f64> = band_sums.concat();
        let total: f64 = sums.iter().sum();
        let inv_total = if total > 0.0 && total.is_finite() {
            1.0 / total
        } else {
            0.0
        };
        let mut fine = Self {
            cells,
            size: [w, h],
            grid,
            patches: [pw, ph],
            col_start,
            row_start,
            col_patch,
            row_patch,
            segment_cdf,
            marginal_cdf,
            power: sums.iter().map(|&s| s * inv_total).collect(),
            regions: Vec::new(),
            centres: Vec::new(),
            texel_scale: (w as f64 / CDF_ONE as f64) * (h as f64 / CDF_ONE as f64),
        };
        let (regions, centres) = (0..pw * ph)
            .into_par_iter()
            .map(|k| {
                let Some([x0, x1, y0, y1]) = fine.lit_cells(k) else {
                    return (None, [0.0, 0.0, 1.0]);
                };
                if fine.power[k] <= 0.0 {
                    return (None, [0.0, 0.0, 1.0]);
                }
                let u = [fine.edge(0, x0), fine.edge(0, x1)];
                let v = [fine.edge(1, y0), fine.edge(1, y1)];
                (
                    Some(Region::new(light, u, v)),
                    fine.centre_of_light(light, k),
                )
            })
            .unzip();
        fine.regions = regions;
        fine.centres = centres;
        fine
    }

    /// The smallest cell rectangle `[x0, x1, y0, y1]` (ends exclusive) holding
    /// patch `k`'s lit cells, those of non-zero CDF width: `None` if there is none.
    fn lit_cells(&self, k: usize) -> Option<[usize; 4]> {
        let ([x0, x1], [y0, y1]) = self.patch_cells(k);
        let c = k % self.patches[0];
        let width = |cdf: &[u32], o: usize| cdf[o + 1] - cdf[o];
        let marginal = self.marginal(k);
        let mut rect: Option<[usize; 4]> = None;
        for j in y0..y1 {
            if width(marginal, j - y0) == 0 {
                continue;
            }
            let segment = self.segment(j, c);
            let first = (0..x1 - x0).find(|&o| width(segment, o) > 0);
            let last = (0..x1 - x0).rev().find(|&o| width(segment, o) > 0);
            if let (Some(f), Some(l)) = (first, last) {
                let b = [x0 + f, x0 + l + 1, j, j + 1];
                rect = Some(match rect {
                    Some(a) => [
                        a[0].min(b[0]),
                        a[1].max(b[1]),
                        a[2].min(b[2]),
                        a[3].max(b[3]),
                    ],
                    None => b,
                });
            }
        }
        rect
    }

    /// Patch `k`'s centre of light (see [`Fine::centres`]); +z if it has none.
    fn centre_of_light(&self, light: &EnvironmentLight, k: usize) -> [f64; 3] {
        let ([x0, x1], [y0, y1]) = self.patch_cells(k);
        let c = k % self.patches[0];
        let width = |cdf: &[u32], o: usize| (cdf[o + 1] - cdf[o]) as f64;
        let marginal = self.marginal(k);
        let mut sum = [0.0f64; 3];
        for j in y0..y1 {
            let wv = width(marginal, j - y0);
            if wv == 0.0 {
                continue;
            }
            let v = 0.5 * (self.edge(1, j) + self.edge(1, j + 1));
            let segment = self.segment(j, c);
            for i in x0..x1 {
                let wu = width(segment, i - x0);
                if wu > 0.0 {
                    let u = 0.5 * (self.edge(0, i) + self.edge(0, i + 1));
                    let (d, _) = light.uv_to_local([u as f32, v as f32]);
                    for (s, x) in sum.iter_mut().zip([d.x, d.y, d.z]) {
                        *s += wv * wu * x as f64;
                    }
                }
            }
        }
        let length = (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt();
        if length > 0.0 && length.is_finite() {
            sum.map(|x| x / length)
        } else {
            [0.0, 0.0, 1.0]
        }
    }

    /// Edge `i` of the cell grid along `axis` (0 for u, 1 for v), in `[0, 1]`.
    fn edge(&self, axis: usize, i: usize) -> f64 {
        match &self.cells {
            Cells::Texels => i as f64 / self.size[axis] as f64,
            Cells::Bilinear {
                u_nodes, v_nodes, ..
            } => [u_nodes, v_nodes][axis][i],
        }
    }

    /// Patch `k`'s image rectangle `[u0, u1, v0, v1]`.
    #[cfg(test)]
    pub(super) fn patch_rect(&self, k: usize) -> [f64; 4] {
        let ([x0, x1], [y0, y1]) = self.patch_cells(k);
        [
            self.edge(0, x0),
            self.edge(0, x1),
            self.edge(1, y0),
            self.edge(1, y1),
        ]
    }

    /// Patch `k`'s cell columns `x0..x1` and rows `y0..y1`.
    #[inline]
    fn patch_cells(&self, k: usize) -> ([usize; 2], [usize; 2]) {
        let pw = self.patches[0];
        let (c, r) = (k % pw, k / pw);
        (
            [self.col_start[c] as usize, self.col_start[c + 1] as usize],
            [self.row_start[r] as usize, self.row_start[r + 1] as usize],
        )
    }

    /// Patch `k`'s CDF over its rows.
    #[inline]
    pub(super) fn marginal(&self, k: usize) -> &[u32] {
        let pw = self.patches[0];
        let (c, r) = (k % pw, k / pw);
        let (y0, y1) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
        let at = pw * (y0 + r) + c * (y1 - y0 + 1);
        &self.marginal_cdf[at..at + y1 - y0 + 1]
    }

    /// Cell row `j`'s CDF over the cells of patch column `c`.
    #[inline]
    pub(super) fn segment(&self, j: usize, c: usize) -> &[u32] {
        let (x0, x1) = (self.col_start[c] as usize, self.col_start[c + 1] as usize);
        let at = j * (self.grid[0] + self.patches[0]) + x0 + c;
        &self.segment_cdf[at..at + x1 - x0 + 1]
    }

    /// The cell holding image coordinate `x ∈ [0, 1]` along `axis`.
    #[inline]
    fn cell_of(&self, axis: usize, x: f32) -> usize {
        match self.cells {
            Cells::Texels => cell_index(x, self.size[axis]),
            // Nodes at 0, (i + ½)/n, 1: cell i is [(i - ½)/n, (i + ½)/n).
            Cells::Bilinear { .. } => {
                let n = self.size[axis];
                ((x as f64 * n as f64 + 0.5).max(0.0) as usize).min(n)
            }
        }
    }

    /// A point of patch `k` (which has power) for `ξ ∈ [0, 1)²`: the row with
    /// `ξ₁`, the cell with `ξ₀`, and the point in the cell with what is left of
    /// each. Returns the image point (inside the cell that [`Self::locate`] finds
    /// for it) and, for texels, `q(u, v | k)` there as [`Self::locate`] computes it
    /// (for the bilinear density, which varies across a point's rounding, `None`).
    pub fn sample(&self, k: usize, xi: [f64; 2]) -> ([f32; 2], Option<f64>) {
        let ([x0, _], [y0, _]) = self.patch_cells(k);
        let c = k % self.patches[0];
        let (row, frac_v, wv) = sample_cdf(self.marginal(k), xi[1]);
        let j = y0 + row;
        let (column, frac_u, wu) = sample_cdf(self.segment(j, c), xi[0]);
        let i = x0 + column;
        match &self.cells {
            Cells::Texels => {
                let [w, h] = self.size;
                let uv = [
                    place_in_cell_f64(i, frac_u, w),
                    place_in_cell_f64(j, frac_v, h),
                ];
                (uv, Some(wv as f64 * wu as f64 * self.texel_scale))
            }
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => {
                let [a, b, c, d] = corners(values, self.size[0] + 2, i, j);
                let y = sample_linear(frac_v, a + b, c + d);
                let x = sample_linear(frac_u, a + (c - a) * y, b + (d - b) * y);
                let uv = [
                    self.place(0, i, u_nodes[i] + x * (u_nodes[i + 1] - u_nodes[i])),
                    self.place(1, j, v_nodes[j] + y * (v_nodes[j + 1] - v_nodes[j])),
                ];
                (uv, None)
            }
        }
    }

    /// `x` rounded to f32 and nudged, if rounding moved it, back into cell `cell`
    /// along `axis` (and below 1).
    fn place(&self, axis: usize, cell: usize, x: f64) -> f32 {
        let mut p = (x as f32).clamp(0.0, crate::distribution::ONE_MINUS_EPSILON);
        for _ in 0..4 {
            let at = self.cell_of(axis, p);
            if at == cell {
                break;
            }
            p = if at < cell {
                p.next_up()
            } else {
                p.next_down()
            };
        }
        p
    }

    /// The patch of image point `uv` and the density in `(u, v)` there given that
    /// patch, `q(u, v | k)`; `None` where the patch has no power.
    #[inline]
    pub fn locate(&self, uv: [f32; 2]) -> Option<(usize, f64)> {
        let (i, j) = (self.cell_of(0, uv[0]), self.cell_of(1, uv[1]));
        let (c, r) = (self.col_patch[i] as usize, self.row_patch[j] as usize);
        let k = r * self.patches[0] + c;
        if self.power[k] <= 0.0 {
            return None;
        }
        let ([x0, _], [y0, _]) = self.patch_cells(k);
        let width = |cdf: &[u32], o: usize| (cdf[o + 1] - cdf[o]) as f64;
        let (wv, wu) = (
            width(self.marginal(k), j - y0),
            width(self.segment(j, c), i - x0),
        );
        let density = match &self.cells {
            Cells::Texels => wv * wu * self.texel_scale,
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => {
                // The cell's probability times the bilinear function over its
                // integral there.
                let [a, b, cc, d] = corners(values, self.size[0] + 2, i, j);
                let (du, dv) = (u_nodes[i + 1] - u_nodes[i], v_nodes[j + 1] - v_nodes[j]);
                let x = ((uv[0] as f64 - u_nodes[i]) / du).clamp(0.0, 1.0);
                let y = ((uv[1] as f64 - v_nodes[j]) / dv).clamp(0.0, 1.0);
                let value = (1.0 - y) * (a + (b - a) * x) + y * (cc + (d - cc) * x);
                let mean = 0.25 * (a + b + cc + d);
                let scale = 1.0 / (CDF_ONE as f64 * CDF_ONE as f64);
                if mean > 0.0 {
                    wv * wu * scale * value / (mean * du * dv)
                } else {
                    0.0
                }
            }
        };
        Some((k, density))
    }

    /// Bytes held: the CDFs, index tables, powers and regions (and the bilinear
    /// density's node values).
    pub fn memory_bytes(&self) -> usize {
        let nodes = match &self.cells {
            Cells::Texels => 0,
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => 4 * values.len() + 8 * (u_nodes.len() + v_nodes.len()),
        };
        4 * (self.segment_cdf.len()
            + self.marginal_cdf.len()
            + self.col_start.len()
            + self.row_start.len()
            + self.col_patch.len()
            + self.row_patch.len())
            + 8 * self.power.len()
            + std::mem::size_of::<Option<Region>>() * self.regions.len()
            + 24 * self.centres.len()
            + nodes
    }
}

/// The four corner values `[top-left, top-right, bottom-left, bottom-right]` of
/// bilinear cell `(i, j)` from node values `mu` wide.
#[inline]
fn corners(values: &[f32], mu: usize, i: usize, j: usize) -> [f64; 4] {
    let (top, bottom) = (&values[j * mu + i..], &values[(j + 1) * mu + i..]);
    [
        top[0] as f64,
        top[1] as f64,
        bottom[0] as f64,
        bottom[1] as f64,
    ]
}

/// Continuous sample of a fixed-point CDF (`n + 1` entries from 0 to [`CDF_ONE`]):
/// the cell `o` with `c[o] ≤ ξ·CDF_ONE < c[o + 1]` (never a cell of zero width),
/// the offset of `ξ` within it in `[0, 1)`, and its width.
#[inline]
fn sample_cdf(cdf: &[u32], xi: f64) -> (usize, f64, u32) {
    let n = cdf.len() - 1;
    // `max` also maps NaN to 0.
    let t = (xi * CDF_ONE as f64).max(0.0).min((CDF_ONE - 1) as f64);
    let x = t as u32;
    let o = cdf[1..n].partition_point(|&c| c <= x);
    let (lo, hi) = (cdf[o], cdf[o + 1]);
    let frac = (t - lo as f64) / (hi - lo) as f64;
    (o, frac.clamp(0.0, 1.0 - f64::EPSILON / 2.0), hi - lo)
}

/// Builds the CDFs of one band of patch rows (cell rows `rows`), each row's
/// importance from `fill_rows(first_row, out)` (`cw` values a row): each row's
/// segment CDFs into `segments` and each patch's CDF over its rows into
/// `marginals` (laid out as in [`Fine`]). Returns each patch's importance sum
/// `F_k`, patch columns in order.
fn build_band(
    cw: usize,
    col_start: &[u32],
    rows: std::ops::Range<usize>,
    segments: &mut [u32],
    marginals: &mut [u32],
    fill_rows: &(impl Fn(usize, &mut [f32]) + Sync),
) -> Vec<f64> {
    let pw = col_start.len() - 1;
    let n = rows.len();
    let mut importance = vec![0.0f32; n * cw];
    fill_rows(rows.start, &mut importance);
    // row_sums[c n + jj]: the sum of row jj's segment in patch column c.
    let mut row_sums = vec![0.0f64; pw * n];
    for (jj, (row, out)) in importance
        .chunks_exact(cw)
        .zip(segments.chunks_exact_mut(cw + pw))
        .enumerate()
    {
        for c in 0..pw {
            let (x0, x1) = (col_start[c] as usize, col_start[c + 1] as usize);
            let segment = Distribution1D::new(&row[x0..x1]);
            out[x0 + c..=x1 + c].copy_from_slice(segment.cdf());
            row_sums[c * n + jj] = segment.integral() * (x1 - x0) as f64;
        }
    }
    let mut weights = vec![0.0f32; n];
    (0..pw)
        .map(|c| {
            let sums = &row_sums[c * n..(c + 1) * n];
            // Relative to the largest, so that f32 neither overflows nor (but for
            // the odd subnormal, kept positive) underflows: a row with importance
            // must keep a CDF width of at least one unit.
            let max = sums.iter().fold(0.0f64, |a, &b| a.max(b));
            for (weight, &sum) in weights.iter_mut().zip(sums) {
                *weight = if sum > 0.0 {
                    ((sum / max) as f32).max(f32::from_bits(1))
                } else {
                    0.0
                };
            }
            let marginal = Distribution1D::new(&weights);
            marginals[c * (n + 1)..(c + 1) * (n + 1)].copy_from_slice(marginal.cdf());
            sums.iter().sum()
        })
        .collect()
}
