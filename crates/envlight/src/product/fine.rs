//! The fine level of a [`ProductSampler`](super::ProductSampler): the light's own
//! density over its cells, cut into rectangular patches, with what it takes to draw
//! a point of a patch in proportion to that density and to read the density back.
//!
//! *Cells* are where the light's density is one piece:
//! - for the piecewise-constant density, the image's texels (`w × h`), weighted by
//!   the texel-grid importance `Y(filtered) · J_j` of docs/design.md §4 step 1 (never
//!   MIS-compensated), constant over each;
//! - for the piecewise-bilinear density, the `(w + 1) × (h + 1)` cells between
//!   its nodes: texel centres (half cells at the image's edges) or, along v for the
//!   node lookup, the rows from pole to pole (whose first and last cells have zero
//!   width and are never drawn); over a cell the density is the bilinear
//!   interpolation of `Y · J` at its corners (as in [`crate::bilinear`]), weighted
//!   by its integral `M = Δu Δv Σ corners / 4`.
//!
//! A patch is a block of cells, stored patch by patch. Within patch `k` a cell is
//! drawn from the patch's own fixed-point distribution over its cells by an exact
//! alias table (module `pick`: one slot read, no search), and a point in the cell
//! uniformly or, for the bilinear density, by inverting the bilinear function's
//! linear marginal and conditional. The density in `(u, v)` given the patch is
//! `q(u, v | k) = g(u, v) / F_k`, `g` the light's (unnormalised) density and `F_k`
//! its integral over the patch: up to the CDF's 2⁻³² rounding, which
//! [`Fine::locate`] reports exactly as sampling uses it (the cell's width).

use super::bounds::Region;
use super::pick::{self, Slot};
use crate::bilinear::{corners, sample_linear};
use crate::distribution::{cell_index, nudge_into_cell, CDF_ONE};
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

/// Where patch `k` lies in the cell grid and in [`Fine`]'s per-cell arrays.
#[derive(Debug, Clone, Copy)]
struct Span {
    /// First cell column and row.
    x0: u32,
    y0: u32,
    /// Cells across and down.
    cols: u32,
    rows: u32,
    /// Index of the patch's first slot in [`Fine::slots`]: the patch's cells
    /// follow, row by row.
    first: u32,
    /// `1 / cols`.
    inv_cols: f64,
}

/// The fine level: cells, patches, their alias tables and regions (see the module
/// docs).
#[derive(Debug, Clone)]
pub(super) struct Fine {
    cells: Cells,
    /// The image's `[w, h]`.
    pub(super) size: [usize; 2],
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
    /// Each cell's width in its patch's fixed-point distribution over its cells
    /// (`q(cell | k) = width / CDF_ONE`; 0 for an unlit cell), in image order
    /// (cell `(i, j)` at `j cw + i`), so that a pdf finds it without its patch.
    pub(super) widths: Vec<u32>,
    /// The alias table of each patch's widths ([`pick`]), patch by patch (see
    /// [`Span::first`]), each patch's cells row by row, aliases local to it.
    pub(super) slots: Vec<Slot>,
    /// `[1 / w, 1 / h]`: a cell's place in `[0, 1]` by a product, not a division.
    inv_size: [f64; 2],
    /// Patch `k`'s cells and where they are stored.
    spans: Vec<Span>,
    /// Patch `k = r Pw + c`: its share `P_k = F_k / Σ F` of the density.
    pub power: Vec<f64>,
    /// The regions of each patch's lit cells (`None` for a patch without power).
    pub regions: Vec<Option<Region>>,
    /// Each patch's centre of light: the unit mean of its cells' centre
    /// directions (light frame) weighted by their probability within the patch.
    pub centres: Vec<[f64; 3]>,
    /// For texels, `w h / CDF_ONE`: a texel's density in `(u, v)` given its patch
    /// is its width times this.
    texel_scale: f64,
}

impl Fine {
    /// The fine level of `light` with `patches` (clamped to the cell grid).
    pub fn new(light: &EnvironmentLight, patches: [usize; 2]) -> Self {
        let (w, h) = (light.image().width(), light.image().height());
        let cells = match light.options().density {
            Density::PiecewiseConstant => Cells::Texels,
            Density::PiecewiseBilinear => {
                let (values, u_nodes, v_nodes) =
                    bilinear_nodes(light.image(), light.mapping(), light.options().lookup);
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

        // Cells are stored patch by patch, the patches of a patch row one after
        // the other: patch (c, r) starts at y0 cw + x0 (y1 - y0), and patch row r
        // fills cells y0 cw .. y1 cw, one band of both arrays per task.
        let spans: Vec<Span> = (0..pw * ph)
            .map(|k| {
                let (c, r) = (k % pw, k / pw);
                let (x0, x1) = (col_start[c], col_start[c + 1]);
                let (y0, y1) = (row_start[r], row_start[r + 1]);
                let first = u32::try_from(y0 as u64 * cw as u64 + x0 as u64 * (y1 - y0) as u64)
                    .expect("cell grids of up to 2³² cells");
                Span {
                    x0,
                    y0,
                    cols: x1 - x0,
                    rows: y1 - y0,
                    first,
                    inv_cols: 1.0 / (x1 - x0) as f64,
                }
            })
            .collect();
        // Sampling reads a slot and a width of a cell drawn anywhere in the map.
        let mut widths: Vec<u32> = pick::large_table(cw * ch);
        let mut slots: Vec<Slot> = pick::large_table(cw * ch);
        let mut bands = Vec::with_capacity(ph);
        let (mut band_widths, mut band_slots) = (&mut widths[..], &mut slots[..]);
        for r in 0..ph {
            let rows = (row_start[r + 1] - row_start[r]) as usize;
            let (this, rest) = std::mem::take(&mut band_widths).split_at_mut(rows * cw);
            band_widths = rest;
            let (these, others) = std::mem::take(&mut band_slots).split_at_mut(rows * cw);
            band_slots = others;
            bands.push((r, this, these));
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
            .map(|(r, widths, slots)| {
                let band = &spans[r * pw..(r + 1) * pw];
                build_band(cw, band, widths, slots, &fill_rows)
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
            spans,
            cells,
            size: [w, h],
            patches: [pw, ph],
            col_start,
            row_start,
            col_patch,
            row_patch,
            widths,
            slots,
            inv_size: [1.0 / w as f64, 1.0 / h as f64],
            power: sums.iter().map(|&s| s * inv_total).collect(),
            regions: Vec::new(),
            centres: Vec::new(),
            texel_scale: (w as f64 * h as f64) / CDF_ONE as f64,
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

    /// The bilinear density's node values and positions `(values, u_nodes,
    /// v_nodes)` (see [`Cells::Bilinear`]), `None` for texels.
    pub(super) fn nodes(&self) -> Option<(&[f32], &[f64], &[f64])> {
        match &self.cells {
            Cells::Texels => None,
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => Some((values, u_nodes, v_nodes)),
        }
    }

    /// Per patch `[x0, y0, cols, rows, first]` (see `ProductTables::spans`).
    pub(super) fn span_words(&self) -> Vec<[u32; 5]> {
        self.spans
            .iter()
            .map(|s| [s.x0, s.y0, s.cols, s.rows, s.first])
            .collect()
    }

    /// The smallest cell rectangle `[x0, x1, y0, y1]` (ends exclusive) holding
    /// patch `k`'s lit cells, those of non-zero width: `None` if there is none.
    fn lit_cells(&self, k: usize) -> Option<[usize; 4]> {
        let mut rect: Option<[usize; 4]> = None;
        for (i, j, _) in self.lit(k) {
            rect = Some(match rect {
                Some([x0, x1, y0, y1]) => [x0.min(i), x1.max(i + 1), y0.min(j), y1.max(j + 1)],
                None => [i, i + 1, j, j + 1],
            });
        }
        rect
    }

    /// Patch `k`'s cells of non-zero width: `(column, row, width)`.
    fn lit(&self, k: usize) -> impl Iterator<Item = (usize, usize, u32)> + '_ {
        let s = self.spans[k];
        let (x0, y0) = (s.x0 as usize, s.y0 as usize);
        let (cols, rows) = (s.cols as usize, s.rows as usize);
        let cw = self.col_patch.len();
        (y0..y0 + rows)
            .flat_map(move |j| (x0..x0 + cols).map(move |i| (i, j, self.widths[j * cw + i])))
            .filter(|&(_, _, w)| w > 0)
    }

    /// Patch `k`'s centre of light (see [`Fine::centres`]); +z if it has none.
    fn centre_of_light(&self, light: &EnvironmentLight, k: usize) -> [f64; 3] {
        let mut sum = [0.0f64; 3];
        for (i, j, width) in self.lit(k) {
            let u = 0.5 * (self.edge(0, i) + self.edge(0, i + 1));
            let v = 0.5 * (self.edge(1, j) + self.edge(1, j + 1));
            let (d, _) = light.uv_to_local([u as f32, v as f32]);
            for (s, x) in sum.iter_mut().zip([d.x, d.y, d.z]) {
                *s += width as f64 * x as f64;
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
    #[cfg(test)]
    pub(super) fn patch_cells(&self, k: usize) -> ([usize; 2], [usize; 2]) {
        let s = &self.spans[k];
        let (x0, y0) = (s.x0 as usize, s.y0 as usize);
        ([x0, x0 + s.cols as usize], [y0, y0 + s.rows as usize])
    }

    /// Patch `k`'s alias slots, its cells row by row.
    #[inline]
    pub(super) fn slots(&self, k: usize) -> &[Slot] {
        let s = &self.spans[k];
        let (first, n) = (s.first as usize, (s.cols * s.rows) as usize);
        &self.slots[first..first + n]
    }

    /// The cell holding image coordinate `x ∈ [0, 1]` along `axis`.
    #[inline]
    fn cell_of(&self, axis: usize, x: f32) -> usize {
        match self.cells {
            Cells::Texels => cell_index(x, self.size[axis]),
            // Nodes at 0, j/(n - 1), 1 along v (the node lookup's rows, whose
            // first node repeats 0): cell k ≥ 1 is [(k - 1)/(n - 1), k/(n - 1)),
            // the end cells of zero width are never the one found.
            Cells::Bilinear { ref v_nodes, .. } if axis == 1 && v_nodes[1] == 0.0 => {
                let rows = self.size[1] - 1;
                1 + ((x as f64 * rows as f64).max(0.0) as usize).min(rows - 1)
            }
            // Nodes at 0, (i + ½)/n, 1: cell i is [(i - ½)/n, (i + ½)/n).
            Cells::Bilinear { .. } => {
                let n = self.size[axis];
                ((x as f64 * n as f64 + 0.5).max(0.0) as usize).min(n)
            }
        }
    }

    /// A point of patch `k` (which has power) for `ξ ∈ [0, 1)²`: the cell with
    /// `ξ₀` from the patch's alias table, the point in the cell with what is left
    /// of `ξ₀` across and `ξ₁` down. Returns the image point (inside the cell that
    /// [`Self::locate`] finds for it) and, for texels, `q(u, v | k)` there as
    /// [`Self::locate`] computes it (for the bilinear density, which varies across
    /// a point's rounding, `None`).
    ///
    /// `hint` hears the chosen cell's centre in `(u, v)` as soon as it is known,
    /// before the point is placed: a caller can start loading the radiance there.
    #[inline]
    pub fn sample(
        &self,
        k: usize,
        xi: [f64; 2],
        hint: impl FnOnce([f32; 2]),
    ) -> ([f32; 2], Option<f64>) {
        let s = &self.spans[k];
        let (cell, frac_u) = pick::pick(self.slots(k), xi[0]);
        // The row by a product with 1/cols: the exact row plus a fraction in
        // [½/cols, 1 - ½/cols], off by far less than ½/cols in f64.
        let row = ((cell as f64 + 0.5) * s.inv_cols) as u32;
        let column = cell as u32 - row * s.cols;
        let (i, j) = ((s.x0 + column) as usize, (s.y0 + row) as usize);
        let frac_v = xi[1];
        match &self.cells {
            Cells::Texels => {
                let [w, h] = self.size;
                let [su, sv] = self.inv_size;
                hint([
                    ((i as f64 + 0.5) * su) as f32,
                    ((j as f64 + 0.5) * sv) as f32,
                ]);
                let width = self.widths[j * w + i];
                let uv = [
                    nudge_into_cell(((i as f64 + frac_u) * su) as f32, i, w),
                    nudge_into_cell(((j as f64 + frac_v) * sv) as f32, j, h),
                ];
                (uv, Some(width as f64 * self.texel_scale))
            }
            Cells::Bilinear {
                values,
                u_nodes,
                v_nodes,
            } => {
                let [su, sv] = self.inv_size;
                hint([(i as f64 * su) as f32, (j as f64 * sv) as f32]);
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
    /// patch, `q(u, v | k)`; `None` where the cell has no weight (nor the patch).
    #[inline]
    pub fn locate(&self, uv: [f32; 2]) -> Option<(usize, f64)> {
        let (i, j) = (self.cell_of(0, uv[0]), self.cell_of(1, uv[1]));
        let (c, r) = (self.col_patch[i] as usize, self.row_patch[j] as usize);
        let k = r * self.patches[0] + c;
        let width = self.widths[j * self.col_patch.len() + i];
        if width == 0 {
            return None;
        }
        let density = match &self.cells {
            Cells::Texels => width as f64 * self.texel_scale,
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
                if mean > 0.0 {
                    width as f64 / CDF_ONE as f64 * value / (mean * du * dv)
                } else {
                    0.0
                }
            }
        };
        Some((k, density))
    }

    /// Bytes held: the widths and alias slots, index tables, powers and regions (and the bilinear
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
        4 * (self.widths.len()
            + self.col_start.len()
            + self.row_start.len()
            + self.col_patch.len()
            + self.row_patch.len())
            + std::mem::size_of::<Slot>() * self.slots.len()
            + std::mem::size_of::<Span>() * self.spans.len()
            + 8 * self.power.len()
            + std::mem::size_of::<Option<Region>>() * self.regions.len()
            + 24 * self.centres.len()
            + nodes
    }
}

/// Builds one band of patches (one patch row, the cells of `band`'s patches, the
/// band's rows' importance from `fill_rows(first_row, out)`, `cw` values a row):
/// each patch's fixed-point distribution over its cells into `widths` (the band's
/// rows, in image order) and its alias table into `slots` (patch by patch, from
/// the band's first). Returns each patch's importance sum `F_k`, in order.
fn build_band(
    cw: usize,
    band: &[Span],
    widths: &mut [u32],
    slots: &mut [Slot],
    fill_rows: &(impl Fn(usize, &mut [f32]) + Sync),
) -> Vec<f64> {
    let (y0, rows) = (band[0].y0 as usize, band[0].rows as usize);
    let start = band[0].first as usize;
    let mut importance = vec![0.0f32; rows * cw];
    fill_rows(y0, &mut importance);
    let (mut cells, mut local) = (Vec::new(), Vec::new());
    band.iter()
        .map(|s| {
            let (x0, cols) = (s.x0 as usize, s.cols as usize);
            cells.clear();
            for row in importance.chunks_exact(cw) {
                cells.extend_from_slice(&row[x0..x0 + cols]);
            }
            local.resize(cells.len(), 0);
            let sum = pick::fixed_point_widths(&cells, &mut local);
            let at = s.first as usize - start;
            // No light: widths 0, and slots that pick nothing.
            pick::build(&local, &mut slots[at..at + cells.len()]);
            for (jj, row) in local.chunks_exact(cols).enumerate() {
                widths[jj * cw + x0..jj * cw + x0 + cols].copy_from_slice(row);
            }
            sum
        })
        .collect()
}
