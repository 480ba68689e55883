//! Building an [`EnvironmentLight`]: the option checks and the resampling of a
//! lat-long input to the light's mapping, the texel-grid importance of
//! docs/design.md §4 step 1 and its MIS compensation, the node values of the bilinear
//! density, the 2D sampler over them, and `∫ L dω`.

use super::{Density, EnvironmentLight, LightOptions, Mapping, OptionError, Planar, Sampler};
use crate::alias::AliasTable2D;
use crate::bilinear::BilinearDistribution2D;
use crate::color::luminance;
use crate::distribution::{for_each_row, positive_weight, Distribution2D};
use crate::error::{Error, Result};
use crate::hierarchical::Hierarchical2D;
use crate::image::{EnvImage, Lookup, WrapU};
use crate::mapping::equal_area;
use rayon::prelude::*;
use std::f64::consts::PI;

impl EnvironmentLight {
    /// Builds the light and its sampling distribution (rows in parallel).
    ///
    /// Time `O(w h)` (plus the resampling for an equal-area light from a lat-long
    /// map); memory: the image plus the sampler's data, 5 to 6 bytes per texel for
    /// the default inversion sampler.
    ///
    /// # Errors
    /// [`Error::LightOption`] when [`LightOptions::validate`] refuses the options
    /// (a negative or non-finite scale, the bilinear density with a sampler other
    /// than inversion, the node lookup with the equal-area mapping, an equal-area
    /// input for a lat-long light, ...); [`Error::InvalidOption`] when an
    /// equal-area input is not square, or `table_width` does not fit the image
    /// ([`table_reduction`]).
    pub fn new(image: EnvImage, options: LightOptions) -> Result<Self> {
        Self::with_progress(image, options, &|_| {})
    }

    /// [`Self::new`], reporting progress for a front end's progress bar: the build
    /// calls `rows_done(k)` each time it has finished `k` more rows of the light's
    /// image ([`Self::image`], so for an equal-area light from a lat-long map, rows
    /// of the resampled square). Calls come from the worker threads, in no
    /// particular order; their counts add up to the image's height.
    ///
    /// # Errors
    /// As [`Self::new`].
    pub fn with_progress(
        image: EnvImage,
        options: LightOptions,
        rows_done: &(dyn Fn(usize) + Sync),
    ) -> Result<Self> {
        // The rules about the options alone; those about the image follow.
        options.validate()?;
        let image = match (options.input_mapping, options.mapping) {
            (Mapping::Equirectangular, Mapping::Equirectangular) => image,
            (Mapping::Equirectangular, Mapping::EqualArea) => {
                // Never 0: `validate` refuses a given 0, and the default size of a
                // non-empty image is at least 1.
                let size = options
                    .equal_area_size
                    .unwrap_or_else(|| equal_area::default_size(image.width(), image.height()));
                equal_area::resample_equirect(&image, size, options.lookup)
            }
            (Mapping::EqualArea, Mapping::EqualArea) => {
                if image.width() != image.height() {
                    return Err(Error::InvalidOption(format!(
                        "an equal-area map must be square, this one is {}x{}",
                        image.width(),
                        image.height()
                    )));
                }
                image
            }
            // `validate` refused this above; the arm only completes the match.
            (Mapping::EqualArea, Mapping::Equirectangular) => {
                return Err(OptionError::EqualAreaInput.into())
            }
        };
        let reduction = table_reduction(image.width(), image.height(), &options)?;
        let (planar, integral_rgb, compensated) =
            build_sampler(&image, &options, reduction, rows_done);
        Ok(Self {
            world_to_light: options.rotation.inverse(),
            rotated: !options.rotation.is_identity(),
            image,
            options,
            planar,
            integral_rgb,
            compensated,
        })
    }
}

/// The factor by which `options.table_width` reduces the sampling table of a
/// light whose own image (after any resampling to its mapping) is `w × h` (1 for
/// no reduction), checked as [`EnvironmentLight::new`] checks it: the factor must
/// be a whole number that divides both sides, and only the piecewise-constant
/// density pools. Front ends call it to refuse a bad width before building.
///
/// # Errors
/// [`Error::LightOption`] for a width of 0 ([`LightOptions::validate`]'s rule);
/// [`Error::InvalidOption`] for one that does not fit, naming the widths that would.
pub fn table_reduction(w: usize, h: usize, options: &LightOptions) -> Result<usize> {
    options.validate_table_width()?;
    let Some(table) = options.table_width else {
        return Ok(1);
    };
    let bad = |why: String| {
        Err(Error::InvalidOption(format!(
            "sampling table width {table}: {why}"
        )))
    };
    if table > w {
        return bad(format!("wider than the light's image ({w} texels)"));
    }
    if !w.is_multiple_of(table) || !h.is_multiple_of(w / table) {
        let fits: Vec<String> = (1..=w.min(64))
            .filter(|f| w.is_multiple_of(*f) && h.is_multiple_of(*f))
            .map(|f| (w / f).to_string())
            .collect();
        return bad(format!(
            "the light's image is {w}x{h}, and the table must reduce both sides by the \
             same whole factor: widths that do are {}",
            fits.join(", ")
        ));
    }
    if table != w && options.density != Density::PiecewiseConstant {
        return bad(
            "a reduced table needs the piecewise-constant density (the default is \
             piecewise-bilinear: ask for piecewise-constant with a table width)"
                .into(),
        );
    }
    Ok(w / table)
}

/// The sampler for `options` over `image` (already in the light's mapping) with
/// its table reduced by `reduction` ([`table_reduction`]), `∫ L dω` of the
/// unscaled image, and whether MIS compensation took effect. `rows_done` hears of
/// every image row once its importance (or, for the bilinear density, its sums)
/// is done: the one pass over the texels.
fn build_sampler(
    image: &EnvImage,
    options: &LightOptions,
    reduction: usize,
    rows_done: &(dyn Fn(usize) + Sync),
) -> (Planar, [f64; 3], bool) {
    let (w, h) = (image.width(), image.height());
    let (tw, th) = (w / reduction, h / reduction);
    let mapping = options.mapping;
    // Image row `j`'s importance into `out`, and its RGB sums.
    let image_row = |cache: &mut LuminanceRows, j: usize, out: &mut [f32]| {
        let sums = importance_row(image, options.lookup, mapping, cache, j, out);
        rows_done(1);
        sums
    };
    // Table row `k` from image rows `k r .. (k + 1) r`, each cell the sum of its
    // r × r texels' importance (in f64); with the image rows' RGB sums.
    let init = || (LuminanceRows::new(w), vec![0.0f32; w], vec![0.0f64; tw]);
    let fill = |(cache, fine, pooled): &mut (LuminanceRows, Vec<f32>, Vec<f64>),
                k: usize,
                out: &mut [f32]| {
        if reduction == 1 {
            return vec![image_row(cache, k, out)];
        }
        pooled.fill(0.0);
        let sums = (k * reduction..(k + 1) * reduction)
            .map(|j| {
                let sums = image_row(cache, j, fine);
                add_blocks(pooled, fine, reduction);
                sums
            })
            .collect();
        for (o, &p) in out.iter_mut().zip(pooled.iter()) {
            *o = positive_weight(p);
        }
        sums
    };
    let integral =
        |row_sums: Vec<Vec<[f64; 3]>>| integral_rgb(&row_sums.concat(), w, options.lookup, mapping);
    match options.density {
        Density::PiecewiseConstant
            if options.sampler == Sampler::Inversion && !options.mis_compensation =>
        {
            // The default path: importance rows go straight into CDFs, never stored.
            let (distribution, row_sums) = Distribution2D::from_rows_with(tw, th, init, fill);
            (Planar::Inversion(distribution), integral(row_sums), false)
        }
        Density::PiecewiseConstant => {
            // Compensation needs the whole map's mean first, so the texel-grid
            // importance is stored, compensated texel by texel (a texel above the
            // mean keeps a positive weight), then pooled.
            let mut values = vec![0.0f32; w * h];
            let mut rows: Vec<&mut [f32]> = values.chunks_mut(w).collect();
            let init = || LuminanceRows::new(w);
            let fill = |cache: &mut LuminanceRows, j: usize, out: &mut [f32]| {
                vec![image_row(cache, j, out)]
            };
            let (_, row_sums) = for_each_row(w, init, fill, &mut rows, |row, out| {
                out.copy_from_slice(row);
                0.0
            });
            let subtracted = options
                .mis_compensation
                .then(|| compensate(&values, w, h, mapping))
                .flatten();
            let compensated = subtracted.is_some();
            let f = subtracted.unwrap_or(values);
            let f = if reduction > 1 {
                pool(&f, w, reduction)
            } else {
                f
            };
            let planar = match options.sampler {
                Sampler::Inversion => Planar::Inversion(Distribution2D::new(&f, tw)),
                Sampler::Alias => Planar::Alias(AliasTable2D::new(&f, tw)),
                Sampler::Hierarchical => Planar::Hierarchical(Hierarchical2D::new(&f, tw)),
            };
            (planar, integral(row_sums), compensated)
        }
        Density::PiecewiseBilinear => {
            let row_sums: Vec<[f64; 3]> = (0..h)
                .into_par_iter()
                .map(|j| rgb_sum(image.row(j)))
                .collect();
            let (mut values, u_nodes, v_nodes) = bilinear_nodes(image, mapping, options.lookup);
            let (mu, mv) = (u_nodes.len(), v_nodes.len());
            let mut compensated = false;
            if options.mis_compensation {
                // Nodes carry Y·J; subtract Ȳ·J node row by node row.
                let factors = node_row_factors(&v_nodes, mapping, node_rows(h, options.lookup));
                if let Some(c) = compensate_rows(&values, mu, mv, &factors) {
                    values = c;
                    compensated = true;
                }
            }
            (
                Planar::Bilinear(BilinearDistribution2D::new(&values, &u_nodes, &v_nodes)),
                integral(vec![row_sums]),
                compensated,
            )
        }
    }
}

/// The `w`-wide grid `f` with each `r × r` block summed into one cell (in f64,
/// kept positive where any texel is: [`positive_weight`]).
fn pool(f: &[f32], w: usize, r: usize) -> Vec<f32> {
    let tw = w / r;
    f.par_chunks(w * r)
        .flat_map_iter(|rows| {
            let mut pooled = vec![0.0f64; tw];
            for row in rows.chunks_exact(w) {
                add_blocks(&mut pooled, row, r);
            }
            pooled.into_iter().map(positive_weight)
        })
        .collect()
}

/// Adds each run of `r` values of `row` (in f64) to its cell of `pooled`.
fn add_blocks(pooled: &mut [f64], row: &[f32], r: usize) {
    for (p, block) in pooled.iter_mut().zip(row.chunks_exact(r)) {
        *p += block.iter().map(|&x| x as f64).sum::<f64>();
    }
}

/// MIS compensation of a texel-grid importance `f = Y · J_j`: `max(0, f − Ȳ J_j)`
/// with `Ȳ = Σ f / Σ J` (the solid-angle mean of the filtered luminance), or `None`
/// when nothing is above the mean (keep `f`).
fn compensate(f: &[f32], w: usize, h: usize, mapping: Mapping) -> Option<Vec<f32>> {
    let factors: Vec<f64> = (0..h)
        .map(|j| mapping.area_factor((j as f64 + 0.5) / h as f64))
        .collect();
    compensate_rows(f, w, h, &factors)
}

/// [`compensate`] for any grid of `rows` rows of `cols` values whose row `k` was
/// multiplied by `factors[k]`.
fn compensate_rows(f: &[f32], cols: usize, rows: usize, factors: &[f64]) -> Option<Vec<f32>> {
    let total_f: f64 = f.iter().map(|&x| x as f64).sum();
    let total_j: f64 = factors.iter().sum::<f64>() * cols as f64;
    if !(total_f > 0.0 && total_j > 0.0) {
        return None;
    }
    let mean = total_f / total_j;
    let mut out = vec![0.0f32; f.len()];
    let mut any = false;
    for k in 0..rows {
        let threshold = mean * factors[k];
        for (o, &x) in out[k * cols..(k + 1) * cols]
            .iter_mut()
            .zip(&f[k * cols..(k + 1) * cols])
        {
            // Within rounding of the threshold counts as not above it, so a constant
            // map (f = Ȳ J up to f32 rounding) keeps its ordinary density.
            if x as f64 > threshold * (1.0 + 1e-5) {
                *o = (x as f64 - threshold) as f32;
                any = true;
            }
        }
    }
    any.then_some(out)
}

/// Node values and positions of the piecewise-bilinear density: `Y · J` at the
/// nodes of the lookup's reconstruction, plus edge nodes at u = 0, 1 and v = 0, 1
/// that reproduce its edge behaviour (the seam average for periodic u; a copy of
/// the edge texels for clamped u and for v). Returns `(values, u_nodes,
/// v_nodes)`, values row-major over `(h + 2) × (w + 2)` nodes.
///
/// Along u the nodes are the texel centres `0, (i + ½)/w, 1`. Along v they are
/// the texel centres `0, (j + ½)/h, 1` too, except for [`Lookup::Node`] on a map of
/// `h ≥ 2` rows, whose rows are nodes from pole to pole: `0, 0, j/(h - 1), 1, 1`,
/// the end rows copies of the poles' (zero-width cells, never sampled). `J` is
/// [`node_row_factors`]'s. (One row is constant in v with either lookup, so it
/// keeps the texel-centre layout.)
pub(crate) fn bilinear_nodes(
    image: &EnvImage,
    mapping: Mapping,
    lookup: Lookup,
) -> (Vec<f32>, Vec<f64>, Vec<f64>) {
    let (w, h) = (image.width(), image.height());
    let centres = |n: usize| -> Vec<f64> {
        let mut nodes = Vec::with_capacity(n + 2);
        nodes.push(0.0);
        nodes.extend((0..n).map(|i| (i as f64 + 0.5) / n as f64));
        nodes.push(1.0);
        nodes
    };
    let node_rows = node_rows(h, lookup);
    let v_nodes = if node_rows {
        let mut nodes = Vec::with_capacity(h + 2);
        nodes.push(0.0);
        nodes.extend((0..h).map(|j| j as f64 / (h - 1) as f64));
        nodes.push(1.0);
        nodes
    } else {
        centres(h)
    };
    let u_nodes = centres(w);
    let factors = node_row_factors(&v_nodes, mapping, node_rows);
    let mu = w + 2;
    let mut values = vec![0.0f32; mu * (h + 2)];
    values.par_chunks_mut(mu).enumerate().for_each(|(k, out)| {
        // Node row k sits at v_nodes[k]; its radiance is texel row k-1, clamped.
        let j = k.saturating_sub(1).min(h - 1);
        let factor = factors[k] as f32;
        let row = image.row(j);
        for (o, t) in out[1..=w].iter_mut().zip(row) {
            *o = luminance(*t) * factor;
        }
        let (first, last) = (out[1], out[w]);
        let (left, right) = match mapping.wrap() {
            WrapU::Periodic => {
                let seam = 0.5 * (first + last);
                (seam, seam)
            }
            WrapU::Clamp => (first, last),
        };
        out[0] = left;
        out[w + 1] = right;
    });
    (values, u_nodes, v_nodes)
}

/// Whether the bilinear density of an `h`-row map read with `lookup` has the
/// node-row layout in v ([`bilinear_nodes`]).
pub(crate) fn node_rows(h: usize, lookup: Lookup) -> bool {
    lookup == Lookup::Node && h >= 2
}

/// The area factor `J` of each node row of the bilinear density at `v_nodes`:
/// `J(v)` at the node, except on the node-row layout's pole rows (`v = 0`, `1`,
/// and their copies), where `J = sin(π v)` is 0 while the lookup's radiance
/// there is not: a zero factor would leave the density 0 on the whole first
/// cell when the next row is black (and on the whole map for two rows). They
/// take instead the mean of `J` over the half cell next to the pole,
/// `(1 − cos(π Δ/2)) / (π Δ/2)` with `Δ = 1/(h − 1)` (`2/π` for two rows; about
/// `π Δ/4`, a quarter of the next row's, for many): the density stays > 0
/// wherever the radiance is, and close to `Y · J` near the pole.
pub(crate) fn node_row_factors(v_nodes: &[f64], mapping: Mapping, node_rows: bool) -> Vec<f64> {
    let n = v_nodes.len();
    v_nodes
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            let pole = k <= 1 || k + 2 >= n;
            if node_rows && pole {
                let half = 0.5 * PI * (v_nodes[2] - v_nodes[1]);
                (1.0 - half.cos()) / half
            } else {
                mapping.area_factor(v)
            }
        })
        .collect()
}

/// Row `j` of the texel-grid importance of docs/design.md §4 step 1, written to `out`;
/// returns the row's RGB sums (for `∫ L dω`).
///
/// Importance: `f[j][i] = Y(filtered) · J_j`; for bilinear lookups the filter is
/// the `[1 6 1]/8` blur in v (clamped) then u (wrapped or clamped with the
/// mapping), whose three input rows come from a rolling cache so each row's
/// luminance is computed once per block of rows.
pub(super) fn importance_row(
    image: &EnvImage,
    lookup: Lookup,
    mapping: Mapping,
    cache: &mut LuminanceRows,
    j: usize,
    out: &mut [f32],
) -> [f64; 3] {
    let (w, h) = (image.width(), image.height());
    let factor = mapping.area_factor((j as f64 + 0.5) / h as f64) as f32;
    match lookup {
        Lookup::Nearest => {
            let (luma, _) = cache.row(image, j);
            for (o, &y) in out.iter_mut().zip(luma) {
                *o = y * factor;
            }
        }
        Lookup::Bilinear | Lookup::Node => {
            // Vertical [1 6 1]/8 (clamped) into the cache's scratch row, then
            // horizontal into `out`: two passes without branches, which vectorize.
            // The node lookup has its own vertical weights (`node_row_weights`) and
            // the bilinear lookup's u.
            if lookup == Lookup::Node {
                cache.vertical_node_mean(image, j);
            } else {
                cache.vertical_blur(image, j);
            }
            let vertical = &cache.blurred;
            let (first, last) = (vertical[0], vertical[w - 1]);
            let (before_first, beyond_last) = match mapping.wrap() {
                WrapU::Periodic => (last, first),
                WrapU::Clamp => (first, last),
            };
            let blur =
                |prev: f32, centre: f32, next: f32| (prev + 6.0 * centre + next) * 0.125 * factor;
            if w == 1 {
                out[0] = blur(before_first, first, beyond_last);
            } else {
                for ((o, &centre), (&prev, &next)) in out[1..w - 1]
                    .iter_mut()
                    .zip(&vertical[1..w - 1])
                    .zip(vertical.iter().zip(&vertical[2..]))
                {
                    *o = blur(prev, centre, next);
                }
                out[0] = blur(before_first, first, vertical[1]);
                out[w - 1] = blur(vertical[w - 2], last, beyond_last);
            }
        }
    }
    cache.row(image, j).1
}

/// `∫ L dω` from each row's RGB sums.
///
/// Along u, linear interpolation between texel centres (wrapped, or clamped with
/// constant half-texels at the ends) integrates to the row mean, so
/// `∫ L dω = Σ_j W_j · mean_i L[j][i]` with `W_j` the solid angle of row j's
/// reconstruction weight ([`row_solid_angles`]); exact for either lookup.
fn integral_rgb(row_sums: &[[f64; 3]], w: usize, lookup: Lookup, mapping: Mapping) -> [f64; 3] {
    let h = row_sums.len();
    let weights = match mapping {
        Mapping::Equirectangular => row_solid_angles(h, lookup),
        // Constant Jacobian: every row covers the same solid angle, 4π/h, and the
        // clamped interpolation in v integrates to the mean like the one in u.
        Mapping::EqualArea => vec![4.0 * PI / h as f64; h],
    };
    let mut integral = [0.0f64; 3];
    for (sums, weight) in row_sums.iter().zip(&weights) {
        for k in 0..3 {
            integral[k] += sums[k] / w as f64 * weight;
        }
    }
    integral
}

/// Per-channel sums of a row of texels, in f64. The row is read as a flat run of
/// floats with twelve partial sums (four texels' worth, so that partial `k` holds
/// channel `k mod 3`): the adds are independent, and the loop vectorizes.
fn rgb_sum(row: &[[f32; 3]]) -> [f64; 3] {
    let flat = row.as_flattened();
    let mut partial = [0.0f64; 12];
    let chunks = flat.chunks_exact(12);
    let rest = chunks.remainder();
    for chunk in chunks {
        for (p, &x) in partial.iter_mut().zip(chunk) {
            *p += x as f64;
        }
    }
    for (p, &x) in partial.iter_mut().zip(rest) {
        *p += x as f64;
    }
    std::array::from_fn(|c| (partial[c] + partial[c + 3]) + (partial[c + 6] + partial[c + 9]))
}

/// The luminance of the last three image rows a build task asked for, with each
/// row's RGB sums (f64), so the `[1 6 1]` filter computes every row's luminance once
/// per block of rows instead of three times.
pub(super) struct LuminanceRows {
    slots: [(usize, Vec<f32>, [f64; 3]); 3],
    /// The vertically filtered luminance of the row being built.
    blurred: Vec<f32>,
}

impl LuminanceRows {
    pub(super) fn new(w: usize) -> Self {
        Self {
            slots: std::array::from_fn(|_| (usize::MAX, vec![0.0; w], [0.0; 3])),
            blurred: vec![0.0; w],
        }
    }

    /// Fills `blurred` with the `[1 6 1]/8` filter in v of row `j`'s luminance (the
    /// rows above and below clamped to the image).
    fn vertical_blur(&mut self, image: &EnvImage, j: usize) {
        let h = image.height();
        // Each distinct row into the cache first; then all three are borrowed.
        for row in [j.saturating_sub(1), j, (j + 1).min(h - 1)] {
            self.row(image, row);
        }
        let slot = |j: usize| &self.slots.iter().find(|s| s.0 == j).expect("cached").1;
        let (above, centre, below) = (slot(j.saturating_sub(1)), slot(j), slot((j + 1).min(h - 1)));
        for (((b, &a), &c), &d) in self.blurred.iter_mut().zip(above).zip(centre).zip(below) {
            *b = (a + d + 6.0 * c) * 0.125;
        }
    }

    /// Row `j`'s luminance averaged over its band of v as [`Lookup::Node`]
    /// reconstructs it (weights from [`node_row_weights`]), into `blurred`.
    fn vertical_node_mean(&mut self, image: &EnvImage, j: usize) {
        let h = image.height();
        for row in [j.saturating_sub(1), j, (j + 1).min(h - 1)] {
            self.row(image, row);
        }
        let [wa, wc, wb] = node_row_weights(j, h);
        let slot = |j: usize| &self.slots.iter().find(|s| s.0 == j).expect("cached").1;
        let (above, centre, below) = (slot(j.saturating_sub(1)), slot(j), slot((j + 1).min(h - 1)));
        for (((b, &a), &c), &d) in self.blurred.iter_mut().zip(above).zip(centre).zip(below) {
            *b = wa * a + wc * c + wb * d;
        }
    }

    /// Luminance and RGB sums of row `j`, computed unless cached.
    pub(super) fn row(&mut self, image: &EnvImage, j: usize) -> (&[f32], [f64; 3]) {
        let slot = match self.slots.iter().position(|s| s.0 == j) {
            Some(slot) => slot,
            None => {
                // Rows are requested in increasing order: the lowest row is stale.
                let slot = (0..3)
                    .min_by_key(|&k| self.slots[k].0.wrapping_add(1))
                    .unwrap_or(0);
                let (id, luma, sums) = &mut self.slots[slot];
                *id = j;
                let row = image.row(j);
                for (y, rgb) in luma.iter_mut().zip(row) {
                    *y = luminance(*rgb);
                }
                *sums = rgb_sum(row);
                slot
            }
        };
        let (_, luma, sums) = &self.slots[slot];
        (luma, *sums)
    }
}

/// The weights of rows `j - 1`, `j`, `j + 1` in the mean of the [`Lookup::Node`]
/// reconstruction over texel row `j`'s band `v ∈ [j/h, (j+1)/h)`, for an image of
/// `h` rows. In node units (`t = v (h-1)`) the band is `[j - α, j + β)` with
/// `α = j/h`, `β = 1 - (j+1)/h`, both below 1: it reaches back into the interval of
/// nodes `j-1, j` by α and forward into that of `j, j+1` by β, where the
/// reconstruction is linear, so the mean is exactly
/// `(α²/2 · r[j-1] + (α + β - α²/2 - β²/2) · r[j] + β²/2 · r[j+1]) / (α + β)`.
/// A row weight is 0 exactly when that row's nodes do not reach the band (the
/// first and last rows' outer neighbours), so the importance built from these
/// weights is positive wherever the lookup is. One row: `[0, 1, 0]`.
pub(crate) fn node_row_weights(j: usize, h: usize) -> [f32; 3] {
    if h < 2 {
        return [0.0, 1.0, 0.0];
    }
    let hf = h as f64;
    let alpha = j as f64 / hf;
    let beta = 1.0 - (j + 1) as f64 / hf;
    let length = alpha + beta;
    let above = 0.5 * alpha * alpha / length;
    let below = 0.5 * beta * beta / length;
    [above as f32, (1.0 - above - below) as f32, below as f32]
}

/// The 4-point Gauss-Legendre rule on `[0, 1]`: its points and weights (exact for
/// polynomials of degree 7).
pub(super) const GL4_POINTS: [f64; 4] = [
    0.069_431_844_202_973_71,
    0.330_009_478_207_571_9,
    0.669_990_521_792_428_1,
    0.930_568_155_797_026_3,
];
/// The weights of [`GL4_POINTS`].
pub(super) const GL4_WEIGHTS: [f64; 4] = [
    0.173_927_422_568_726_9,
    0.326_072_577_431_273_1,
    0.326_072_577_431_273_1,
    0.173_927_422_568_726_9,
];

/// Solid angle `W_j` attributed to each row by `lookup` (they sum to 4π).
fn row_solid_angles(h: usize, lookup: Lookup) -> Vec<f64> {
    let hf = h as f64;
    match lookup {
        Lookup::Nearest => (0..h)
            .map(|j| 2.0 * PI * ((PI * j as f64 / hf).cos() - (PI * (j + 1) as f64 / hf).cos()))
            .collect(),
        Lookup::Node => node_row_solid_angles(h),
        Lookup::Bilinear => {
            use GL4_POINTS as GL_T;
            use GL4_WEIGHTS as GL_W;
            let mut weights = vec![0.0f64; h];
            for j in 0..h {
                let centre = (j as f64 + 0.5) / hf;
                // Upper half: between the top edge of texel j and its centre, the
                // neighbour is row j-1; lower half: row j+1 (clamped at the ends).
                for (lo, neighbour) in [
                    (j as f64 / hf, j.saturating_sub(1)),
                    (centre, (j + 1).min(h - 1)),
                ] {
                    let len = 0.5 / hf;
                    for (t, gw) in GL_T.iter().zip(GL_W) {
                        let v = lo + t * len;
                        let dw = 2.0 * PI * PI * (PI * v).sin() * gw * len;
                        let far = ((v - centre).abs() * hf).min(1.0);
                        weights[j] += (1.0 - far) * dw;
                        weights[neighbour] += far * dw;
                    }
                }
            }
            weights
        }
    }
}

/// [`row_solid_angles`] for [`Lookup::Node`]: row `k` is the node at
/// `v = k/(h-1)`, its weight the hat function over the two node intervals beside
/// it; each interval integrated by 8-point Gauss-Legendre (of the smooth
/// `2π² sin πv` times a linear weight).
fn node_row_solid_angles(h: usize) -> Vec<f64> {
    if h < 2 {
        return vec![4.0 * PI];
    }
    const GL_T: [f64; 8] = [
        0.019_855_071_751_231_856,
        0.101_666_761_293_186_63,
        0.237_233_795_041_835_5,
        0.408_282_678_752_175_1,
        0.591_717_321_247_825,
        0.762_766_204_958_164_5,
        0.898_333_238_706_813_4,
        0.980_144_928_248_768_1,
    ];
    const GL_W: [f64; 8] = [
        0.050_614_268_145_188_13,
        0.111_190_517_226_687_24,
        0.156_853_322_938_943_64,
        0.181_341_891_689_181,
        0.181_341_891_689_181,
        0.156_853_322_938_943_64,
        0.111_190_517_226_687_24,
        0.050_614_268_145_188_13,
    ];
    let len = 1.0 / (h - 1) as f64;
    let mut weights = vec![0.0f64; h];
    for k in 0..h - 1 {
        for (t, gw) in GL_T.iter().zip(GL_W) {
            let v = (k as f64 + t) * len;
            let dw = 2.0 * PI * PI * (PI * v).sin() * gw * len;
            weights[k] += (1.0 - t) * dw;
            weights[k + 1] += t * dw;
        }
    }
    weights
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The importance rows, filter and RGB sums against a texel-by-texel reading of
    /// docs/design.md §4 step 1, on small maps where every texel is next to an edge.
    #[test]
    fn importance_rows_match_their_definition() {
        let mut rng = crate::rng::SplitMix64::new(5);
        for (w, h) in [(1, 1), (1, 3), (2, 1), (2, 2), (3, 5), (7, 4), (13, 6)] {
            let texels: Vec<[f32; 3]> = (0..w * h)
                .map(|_| [rng.next_f32() * 4.0, rng.next_f32(), rng.next_f32() * 0.5])
                .collect();
            let image = EnvImage::new(w, h, texels).expect("a valid image");
            for mapping in Mapping::ALL {
                for lookup in [Lookup::Nearest, Lookup::Bilinear, Lookup::Node] {
                    let mut cache = LuminanceRows::new(w);
                    let mut out = vec![0.0f32; w];
                    for j in 0..h {
                        let sums = importance_row(&image, lookup, mapping, &mut cache, j, &mut out);
                        let factor = mapping.area_factor((j as f64 + 0.5) / h as f64);
                        let y = |i: isize, j: isize| {
                            let j = j.clamp(0, h as isize - 1) as usize;
                            let i = match mapping.wrap() {
                                WrapU::Periodic => i.rem_euclid(w as isize),
                                WrapU::Clamp => i.clamp(0, w as isize - 1),
                            } as usize;
                            luminance(image.texel(i, j)) as f64
                        };
                        for (i, &got) in out.iter().enumerate() {
                            let (i, jj) = (i as isize, j as isize);
                            let want = match lookup {
                                Lookup::Nearest => y(i, jj),
                                Lookup::Bilinear => {
                                    let weights = [1.0, 6.0, 1.0];
                                    let mut sum = 0.0;
                                    for (a, wa) in (-1..=1).zip(weights) {
                                        for (b, wb) in (-1..=1).zip(weights) {
                                            sum += wa * wb * y(i + a, jj + b);
                                        }
                                    }
                                    sum / 64.0
                                }
                                Lookup::Node => {
                                    // The band's mean of the node reconstruction in
                                    // v, from its definition (α, β as documented).
                                    let (hf, jf) = (h as f64, j as f64);
                                    let vertical = if h < 2 {
                                        [0.0, 1.0, 0.0]
                                    } else {
                                        let (a, b) = (jf / hf, 1.0 - (jf + 1.0) / hf);
                                        let (above, below) = (a * a / 2.0, b * b / 2.0);
                                        let centre = a + b - above - below;
                                        [above / (a + b), centre / (a + b), below / (a + b)]
                                    };
                                    let weights = [1.0, 6.0, 1.0];
                                    let mut sum = 0.0;
                                    for (a, wa) in (-1..=1).zip(weights) {
                                        for (b, wb) in (-1..=1).zip(vertical) {
                                            sum += wa * wb * y(i + a, jj + b);
                                        }
                                    }
                                    sum / 8.0
                                }
                            } * factor;
                            let err = (got as f64 - want).abs();
                            assert!(
                                err <= 1e-6 * want.abs().max(1e-30),
                                "{w}x{h} {mapping:?} {lookup:?} ({i}, {j}): {got} vs {want}"
                            );
                        }
                        for (c, &sum) in sums.iter().enumerate() {
                            let want: f64 = image.row(j).iter().map(|t| t[c] as f64).sum();
                            assert!((sum - want).abs() <= 1e-12 * want.abs(), "{sum} vs {want}");
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn row_solid_angles_sum_to_the_sphere() {
        for lookup in [Lookup::Nearest, Lookup::Bilinear, Lookup::Node] {
            for h in [1, 2, 3, 17, 512] {
                let total: f64 = row_solid_angles(h, lookup).iter().sum();
                assert!(
                    (total / (4.0 * PI) - 1.0).abs() < 1e-7,
                    "{lookup:?} h={h}: {total}"
                );
            }
        }
    }

    #[test]
    fn bad_scale_is_rejected() {
        let image = EnvImage::from_fn(1, 1, |_, _| [1.0; 3]).unwrap();
        for scale in [f32::NAN, -1.0, f32::INFINITY] {
            let options = LightOptions {
                scale,
                ..Default::default()
            };
            assert!(EnvironmentLight::new(image.clone(), options).is_err());
        }
    }

    /// The reduction's cost measured in one pass equals the efficiency of a
    /// light built with the full table; a full table reports no cost.
    #[test]
    fn full_table_efficiency_matches_the_full_light() {
        let image = crate::builtin::sky(96, 48);
        let constant = LightOptions {
            density: Density::PiecewiseConstant,
            ..Default::default()
        };
        let full = EnvironmentLight::new(image.clone(), constant).unwrap();
        assert_eq!(full.efficiency_with_full_table(), (full.efficiency(), None));
        for (table_width, sampler) in [(48, Sampler::Inversion), (24, Sampler::Alias)] {
            let options = LightOptions {
                table_width: Some(table_width),
                sampler,
                density: Density::PiecewiseConstant,
                ..Default::default()
            };
            let reduced = EnvironmentLight::new(image.clone(), options).unwrap();
            assert_eq!(reduced.table_size(), [table_width, table_width / 2]);
            let (own, at_full) = reduced.efficiency_with_full_table();
            assert_eq!(own, reduced.efficiency());
            let at_full = at_full.expect("a reduced table reports the full one's");
            assert!(
                (at_full / full.efficiency() - 1.0).abs() < 1e-6,
                "{at_full} vs {}",
                full.efficiency()
            );
            assert!(own < at_full, "{own} vs {at_full}");
        }
    }

    /// A reduced table's cells carry their blocks' summed importance, for every
    /// sampler and with compensation; the integral is the full map's; a table as
    /// wide as the map is the ordinary one.
    #[test]
    fn reduced_tables_pool_by_block_sums() {
        let mut rng = crate::rng::SplitMix64::new(9);
        let (w, h) = (24, 12);
        let texels: Vec<[f32; 3]> = (0..w * h)
            .map(|k| {
                let y = if k % 37 == 5 { 50.0 } else { rng.next_f32() };
                [y, y, y]
            })
            .collect();
        let image = EnvImage::new(w, h, texels).unwrap();
        let constant = LightOptions {
            density: Density::PiecewiseConstant,
            ..Default::default()
        };
        let full = EnvironmentLight::new(image.clone(), constant).unwrap();
        let mut importance = vec![0.0f32; w * h];
        full.importance_rows(0, &mut importance);
        for r in [1, 2, 3, 4, 6, 12] {
            for sampler in [Sampler::Inversion, Sampler::Alias, Sampler::Hierarchical] {
                let options = LightOptions {
                    sampler,
                    table_width: Some(w / r),
                    density: Density::PiecewiseConstant,
                    ..Default::default()
                };
                let light = EnvironmentLight::new(image.clone(), options).unwrap();
                assert_eq!(light.integral_rgb(), full.integral_rgb());
                let (tw, th) = (w / r, h / r);
                let total: f64 = importance.iter().map(|&x| x as f64).sum();
                for k in 0..th {
                    for i in 0..tw {
                        let block: f64 = (k * r..(k + 1) * r)
                            .flat_map(|j| (i * r..(i + 1) * r).map(move |x| (x, j)))
                            .map(|(x, j)| importance[j * w + x] as f64)
                            .sum();
                        let want = block / total * (tw * th) as f64;
                        let uv = [(i as f32 + 0.5) / tw as f32, (k as f32 + 0.5) / th as f32];
                        let got = light.planar.pdf(uv) as f64;
                        assert!(
                            (got - want).abs() <= 1e-5 * want,
                            "r {r} {sampler:?} cell ({i}, {k}): {got} vs {want}"
                        );
                    }
                }
                if r == 1 {
                    assert_eq!(light.planar.pdf([0.3, 0.4]), full.planar.pdf([0.3, 0.4]));
                }
            }
        }
        // Compensation first, texel by texel, then pooling: a block holding a texel
        // above the mean keeps a positive density, the others get none.
        let options = LightOptions {
            table_width: Some(w / 4),
            mis_compensation: true,
            sampler: Sampler::Alias,
            density: Density::PiecewiseConstant,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image.clone(), options).unwrap();
        assert!(light.is_compensated());
        for (k, _) in (0..w * h).filter(|k| k % 37 == 5).map(|k| (k, ())) {
            let (x, y) = (k % w, k / w);
            let uv = [(x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32];
            assert!(light.planar.pdf(uv) > 0.0, "hot texel ({x}, {y})");
        }
    }

    #[test]
    fn bad_table_widths_are_rejected_with_the_widths_that_fit() {
        let image = EnvImage::from_fn(24, 12, |_, _| [1.0; 3]).unwrap();
        let build = |table_width, density| {
            let options = LightOptions {
                table_width: Some(table_width),
                density,
                ..Default::default()
            };
            EnvironmentLight::new(image.clone(), options).map(|_| ())
        };
        let message = |r: Result<()>| r.unwrap_err().to_string();
        assert!(message(build(0, Density::PiecewiseConstant)).contains("at least 1"));
        assert!(message(build(48, Density::PiecewiseConstant)).contains("wider"));
        let m = message(build(5, Density::PiecewiseConstant));
        assert!(
            m.contains("24x12") && m.contains("24, 12, 8, 6, 4, 2"),
            "{m}"
        );
        // 16 divides neither side by the same factor.
        assert!(build(16, Density::PiecewiseConstant).is_err());
        assert!(message(build(12, Density::PiecewiseBilinear)).contains("piecewise-constant"));
        assert!(build(24, Density::PiecewiseBilinear).is_ok());
        assert!(build(12, Density::PiecewiseConstant).is_ok());
    }
}
