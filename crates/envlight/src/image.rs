//! The environment image: linear RGB `f32` texels on a `width × height` grid, row 0 at
//! the top, with nearest and bilinear lookups (u wraps, v clamps).
//!
//! Decoding files lives in [`crate::load`]; this module only holds and reads texels.

use crate::error::{Error, Result, TexelPos};
use crate::math::{floor_f32, floor_index, floor_index_i32, len_f32, prefetch_ptr};

/// How radiance between texel centres is reconstructed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Lookup {
    /// The texel that contains `(u, v)`.
    Nearest,
    /// Bilinear interpolation between the four nearest texel centres
    /// (centres at `((i+.5)/w, (j+.5)/h)`), wrapping in u and clamping in v.
    #[default]
    Bilinear,
    /// Bilinear interpolation with the rows as nodes from pole to pole: row `j` at
    /// `v = j/(h-1)` (one row: constant in v), and texel centres `(i+.5)/w` along
    /// u, wrapped (clamped for a clamped u). Mitsuba 3's `envmap` reads a
    /// latitude-longitude map so: its duplicated seam column and half-texel shift
    /// are this u. The same radiance as [`Lookup::Bilinear`] along u, a different
    /// one along v.
    Node,
}

/// What happens to u outside `[0, 1)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum WrapU {
    /// u is periodic (an equirectangular map's seam).
    #[default]
    Periodic,
    /// u is clamped like v (an equal-area square's edges).
    Clamp,
}

/// A linear-RGB environment image. Every texel is finite and non-negative (the
/// constructors guarantee it), so no NaN can come out of a lookup.
#[derive(Debug, Clone, PartialEq)]
pub struct EnvImage {
    width: usize,
    height: usize,
    texels: Vec<[f32; 3]>,
}

/// What validation changed while an image was built from raw texels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Sanitized {
    /// Texels with at least one negative channel; those channels were set to 0.
    pub negative_texels: usize,
    /// The most negative channel value seen (0 when there was none).
    pub most_negative: f32,
    /// Texels with a NaN or infinite channel that were replaced by 0 (only when the
    /// caller asked for replacement; otherwise such a texel is an error).
    pub non_finite_texels: usize,
}

/// The longest side an image may have, 2²⁴ texels: every index and side is then
/// exact as an f32, and fits the 32-bit lanes of the batch lookups.
pub const MAX_SIDE: usize = 1 << 24;

impl EnvImage {
    /// Builds an image from texels in row-major order (row 0 at the top).
    ///
    /// # Errors
    /// [`Error::InvalidDimensions`] when a side is 0 or above [`MAX_SIDE`], or
    /// `texels.len() != width*height`;
    /// [`Error::NonFiniteTexel`] for the first NaN/infinite channel;
    /// [`Error::InvalidOption`] for a negative channel (use [`EnvImage::from_raw`] to
    /// clamp instead).
    pub fn new(width: usize, height: usize, texels: Vec<[f32; 3]>) -> Result<Self> {
        let (image, report) = Self::from_raw("<memory>", width, height, texels, false)?;
        if report.negative_texels > 0 {
            return Err(Error::InvalidOption(format!(
                "{} texels have negative channels (most negative {})",
                report.negative_texels, report.most_negative
            )));
        }
        Ok(image)
    }

    /// Builds an image by evaluating `f(x, y)` at every texel.
    ///
    /// # Errors
    /// As [`EnvImage::new`].
    pub fn from_fn(
        width: usize,
        height: usize,
        mut f: impl FnMut(usize, usize) -> [f32; 3],
    ) -> Result<Self> {
        let mut texels = Vec::with_capacity(width.saturating_mul(height));
        for y in 0..height {
            for x in 0..width {
                texels.push(f(x, y));
            }
        }
        Self::new(width, height, texels)
    }

    /// Validates raw decoded texels: negative channels are clamped to 0 and counted;
    /// a NaN or infinite channel is an error naming `source_name` and the texel, or,
    /// with `replace_non_finite`, is replaced by 0 and counted.
    ///
    /// # Errors
    /// [`Error::InvalidDimensions`], [`Error::NonFiniteTexel`].
    pub fn from_raw(
        source_name: &str,
        width: usize,
        height: usize,
        mut texels: Vec<[f32; 3]>,
        replace_non_finite: bool,
    ) -> Result<(Self, Sanitized)> {
        if width == 0 || height == 0 || width.checked_mul(height) != Some(texels.len()) {
            return Err(Error::InvalidDimensions {
                source_name: source_name.to_string(),
                detail: format!("{width}x{height} with {} texels", texels.len()),
            });
        }
        if width.max(height) > MAX_SIDE {
            return Err(Error::InvalidDimensions {
                source_name: source_name.to_string(),
                detail: format!("{width}x{height}: a side above {MAX_SIDE} texels"),
            });
        }
        let mut report = Sanitized::default();
        for (index, texel) in texels.iter_mut().enumerate() {
            let mut negative = false;
            let mut non_finite = false;
            for (c, value) in texel.iter_mut().enumerate() {
                if !value.is_finite() {
                    if !replace_non_finite {
                        return Err(Error::NonFiniteTexel {
                            source_name: source_name.to_string(),
                            pos: TexelPos {
                                x: index % width,
                                y: index / width,
                            },
                            channel: ['R', 'G', 'B'][c],
                            value: *value,
                        });
                    }
                    non_finite = true;
                } else if *value < 0.0 {
                    negative = true;
                    report.most_negative = report.most_negative.min(*value);
                    *value = 0.0;
                }
            }
            if non_finite {
                *texel = [0.0; 3];
                report.non_finite_texels += 1;
            } else if negative {
                report.negative_texels += 1;
            }
        }
        Ok((
            Self {
                width,
                height,
                texels,
            },
            report,
        ))
    }

    /// Width in texels (along u, φ).
    #[inline]
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in texels (along v, θ).
    #[inline]
    pub fn height(&self) -> usize {
        self.height
    }

    /// All texels, row-major, row 0 at the top.
    #[inline]
    pub fn texels(&self) -> &[[f32; 3]] {
        &self.texels
    }

    /// One row of texels (`y` from the top).
    #[inline]
    pub fn row(&self, y: usize) -> &[[f32; 3]] {
        &self.texels[y * self.width..(y + 1) * self.width]
    }

    /// The texel at column `x`, row `y`. Panics when out of range (a programming error).
    #[inline]
    pub fn texel(&self, x: usize, y: usize) -> [f32; 3] {
        self.texels[y * self.width + x]
    }

    /// The brightest texel by luminance, the first in row order among equals:
    /// `(x, y, Y)`. Parallel; the result does not depend on the thread count.
    pub fn brightest_texel(&self) -> (usize, usize, f32) {
        use rayon::prelude::*;
        let (index, y) = self
            .texels
            .par_iter()
            .map(|&t| crate::color::luminance(t))
            .enumerate()
            .reduce(
                || (0, f32::NEG_INFINITY),
                |a, b| {
                    if b.1 > a.1 || (b.1 == a.1 && b.0 < a.0) {
                        b
                    } else {
                        a
                    }
                },
            );
        (index % self.width, index / self.width, y)
    }

    /// Radiance at `(u, v)` with the given reconstruction; u wraps, v clamps.
    #[inline]
    pub fn lookup(&self, u: f32, v: f32, mode: Lookup) -> [f32; 3] {
        self.lookup_wrapped(u, v, mode, WrapU::Periodic)
    }

    /// Radiance at `(u, v)` with the given reconstruction and treatment of u; v
    /// always clamps.
    #[inline(always)]
    pub fn lookup_wrapped(&self, u: f32, v: f32, mode: Lookup, wrap: WrapU) -> [f32; 3] {
        match mode {
            Lookup::Nearest => self.nearest(u, v, wrap),
            Lookup::Bilinear => self.bilinear(u, wrap, clamped_pair(v, self.height)),
            Lookup::Node => self.bilinear(u, wrap, node_pair(v, self.height)),
        }
    }

    /// The texel containing `(u, v)`; u wraps, v clamps.
    #[inline]
    pub fn lookup_nearest(&self, u: f32, v: f32) -> [f32; 3] {
        self.nearest(u, v, WrapU::Periodic)
    }

    /// Bilinear interpolation between texel centres; u wraps, v clamps (so the top
    /// and bottom half-rows are constant in v).
    #[inline]
    pub fn lookup_bilinear(&self, u: f32, v: f32) -> [f32; 3] {
        self.bilinear(u, WrapU::Periodic, clamped_pair(v, self.height))
    }

    #[inline(always)]
    fn nearest(&self, u: f32, v: f32, wrap: WrapU) -> [f32; 3] {
        let (w, h) = (self.width, self.height);
        let x = match wrap {
            WrapU::Periodic => floor_index(periodic(u) * len_f32(w), w),
            WrapU::Clamp => floor_index(u * len_f32(w), w),
        };
        self.texel(x, floor_index(v * len_f32(h), h))
    }

    /// Starts loading the texels a lookup at `(u, v)` will read (for a point in
    /// `[0, 1]²`), without waiting for them: a hint to the CPU that changes no
    /// result. The address arithmetic is unchecked: a prefetch never faults, and a
    /// point outside the square only wastes the hint.
    #[inline(always)]
    pub(crate) fn prefetch(&self, u: f32, v: f32) {
        let (w, h) = (self.width, self.height);
        let x = floor_index(u * len_f32(w), w);
        // The rows a bilinear lookup blends (the second may be one past the last,
        // harmlessly); a nearest lookup reads one of them.
        let y0 = floor_index(v * len_f32(h) - 0.5, h);
        let first = self.texels.as_ptr().wrapping_add(y0 * w + x);
        prefetch_ptr(first);
        prefetch_ptr(first.wrapping_add(w));
    }

    /// Texel centres sit at `(i + ½)/n`, so the lower neighbour of a coordinate is
    /// `⌊u n - ½⌋`, which is -1 left of the first centre. Each axis is shifted so
    /// that index is never negative before the floor (by a period for a periodic u,
    /// by one texel for a clamped axis), then mapped back. The rows and weight
    /// along v come from the caller (texel centres or nodes).
    #[inline(always)]
    fn bilinear(&self, u: f32, wrap: WrapU, rows: (usize, usize, f32)) -> [f32; 3] {
        let (w, h) = (self.width, self.height);
        let (x0, x1, fs) = match wrap {
            WrapU::Periodic => {
                let s = periodic(u) * len_f32(w) - 0.5 + len_f32(w);
                let i = floor_index(s, 2 * w);
                let x0 = if i >= w { i - w } else { i };
                let x1 = if x0 + 1 == w { 0 } else { x0 + 1 };
                (x0, x1, s - len_f32(i))
            }
            WrapU::Clamp => clamped_pair(u, w),
        };
        let (y0, y1, ft) = rows;
        debug_assert!(x0 < w && x1 < w && y0 < h && y1 < h);
        // SAFETY: `periodic` and `clamped_pair` clamp their indices into
        // `[0, w - 1]` and `[0, h - 1]`, and the texels are `w h` long (checked
        // when the image is made); unchecked reads drop six bounds checks from
        // every lookup.
        let (a, b, c, d) = unsafe {
            let texel = |x: usize, y: usize| *self.texels.get_unchecked(y * w + x);
            (texel(x0, y0), texel(x1, y0), texel(x0, y1), texel(x1, y1))
        };
        blend([a, b, c, d], fs, ft)
    }
}

/// Where a block of `N` lookups reads: for lane `i`, texels `x0[i], x1[i]` of
/// rows `y0[i], y1[i]`, blended with weights `1 - fs, fs` along u and
/// `1 - ft, ft` along v (a nearest lookup reads `(x0, y0)` alone). Computed for
/// all lanes at once by [`EnvImage::lookup_block`], in loops the compiler
/// vectorizes; bit for bit what the one-point lookups compute.
///
/// The one-point lookups keep their own code: routed through a block of one,
/// with selects for their branches and no early exit for an in-range `u`, a
/// single bilinear lookup measured 40% slower (and a light sample 15%).
#[derive(Clone, Copy)]
pub(crate) struct LookupBlock<const N: usize> {
    mode: Lookup,
    x0: [u32; N],
    x1: [u32; N],
    y0: [u32; N],
    y1: [u32; N],
    fs: [f32; N],
    ft: [f32; N],
}

impl EnvImage {
    /// The texels and weights of `N` lookups at `(u[i], v[i])` (see [`LookupBlock`]).
    #[inline(always)]
    pub(crate) fn lookup_block<const N: usize>(
        &self,
        u: &[f32; N],
        v: &[f32; N],
        mode: Lookup,
        wrap: WrapU,
    ) -> LookupBlock<N> {
        let (w, h) = (self.width, self.height);
        let (wf, hf) = (len_f32(w), len_f32(h));
        // Sides are at most MAX_SIDE = 2²⁴ (checked when the image is made), so
        // `2 w` and every index fit an i32.
        let (w32, h32) = (w as i32, h as i32);
        let mut b = LookupBlock {
            mode,
            x0: [0; N],
            x1: [0; N],
            y0: [0; N],
            y1: [0; N],
            fs: [0.0; N],
            ft: [0.0; N],
        };
        // Each mode and wrap its own loop (a branch-free body the compiler
        // vectorizes; a `match` inside one loop kept the loop scalar).
        if mode == Lookup::Nearest {
            for i in 0..N {
                let x = match wrap {
                    WrapU::Periodic => floor_index_i32(periodic_lanes(u[i]) * wf, w32 - 1),
                    WrapU::Clamp => floor_index_i32(u[i] * wf, w32 - 1),
                };
                let y = floor_index_i32(v[i] * hf, h32 - 1);
                (b.x0[i], b.x1[i], b.y0[i], b.y1[i]) = (x as u32, x as u32, y as u32, y as u32);
            }
            return b;
        }
        // Bilinear and node lookups: the same columns.
        match wrap {
            WrapU::Periodic => {
                for (i, &u) in u.iter().enumerate() {
                    // As in `bilinear`, with selects.
                    let s = periodic_lanes(u) * wf - 0.5 + wf;
                    let k = floor_index_i32(s, 2 * w32 - 1);
                    let x0 = if k >= w32 { k - w32 } else { k };
                    let x1 = if x0 + 1 == w32 { 0 } else { x0 + 1 };
                    (b.x0[i], b.x1[i], b.fs[i]) = (x0 as u32, x1 as u32, s - k as f32);
                }
            }
            WrapU::Clamp => {
                for (i, &u) in u.iter().enumerate() {
                    let (x0, x1, fs) = clamped_pair_i32(u, w32);
                    (b.x0[i], b.x1[i], b.fs[i]) = (x0 as u32, x1 as u32, fs);
                }
            }
        }
        if mode == Lookup::Node {
            for (i, &v) in v.iter().enumerate() {
                let (y0, y1, ft) = node_pair_i32(v, h32);
                (b.y0[i], b.y1[i], b.ft[i]) = (y0 as u32, y1 as u32, ft);
            }
        } else {
            for (i, &v) in v.iter().enumerate() {
                let (y0, y1, ft) = clamped_pair_i32(v, h32);
                (b.y0[i], b.y1[i], b.ft[i]) = (y0 as u32, y1 as u32, ft);
            }
        }
        b
    }

    /// Starts fetching the texels of every lookup in `b` (a hint).
    #[inline(always)]
    pub(crate) fn prefetch_block<const N: usize>(&self, b: &LookupBlock<N>) {
        let w = self.width;
        for i in 0..N {
            let first = self
                .texels
                .as_ptr()
                .wrapping_add(b.y0[i] as usize * w + b.x0[i] as usize);
            prefetch_ptr(first);
            if b.mode != Lookup::Nearest {
                let second = b.y1[i] as usize * w + b.x0[i] as usize;
                prefetch_ptr(self.texels.as_ptr().wrapping_add(second));
            }
        }
    }

    /// The radiance of lookup `i` of `b`: bit for bit [`Self::lookup_wrapped`] at
    /// its point.
    #[inline(always)]
    pub(crate) fn fetch<const N: usize>(&self, b: &LookupBlock<N>, i: usize) -> [f32; 3] {
        let w = self.width;
        let (x0, x1, y0, y1) = (
            b.x0[i] as usize,
            b.x1[i] as usize,
            b.y0[i] as usize,
            b.y1[i] as usize,
        );
        debug_assert!(x0 < w && x1 < w && y0 < self.height && y1 < self.height);
        // SAFETY: `lookup_block` clamps every index into `[0, w - 1]` and
        // `[0, h - 1]`, and the texels are `w h` long.
        let texel = |x: usize, y: usize| unsafe { *self.texels.get_unchecked(y * w + x) };
        match b.mode {
            Lookup::Nearest => texel(x0, y0),
            Lookup::Bilinear | Lookup::Node => {
                let (a, bb, c, d) = (texel(x0, y0), texel(x1, y0), texel(x0, y1), texel(x1, y1));
                blend([a, bb, c, d], b.fs[i], b.ft[i])
            }
        }
    }
}

/// The bilinear blend of the texels `[(x0, y0), (x1, y0), (x0, y1), (x1, y1)]`
/// with weights `fs` along u and `ft` along v. The four weights are ready before
/// the texels arrive, so a lookup ends with one multiplication and two additions
/// after its loads (nested lerps would chain six operations there). Non-negative
/// weights of non-negative texels: the result needs no clamp.
#[inline(always)]
fn blend([a, b, c, d]: [[f32; 3]; 4], fs: f32, ft: f32) -> [f32; 3] {
    // A NaN point (from a NaN or infinite direction) gives NaN weights; `max`
    // turns them into 0, so a lookup never returns NaN. Weights of a finite point
    // are in [0, 1) already and pass unchanged.
    let (fs, ft) = (fs.max(0.0), ft.max(0.0));
    let (gs, gt) = (1.0 - fs, 1.0 - ft);
    let weights = [gs * gt, fs * gt, gs * ft, fs * ft];
    let mut out = [0.0f32; 3];
    for k in 0..3 {
        // Kept finite: weights that round to a sum just above 1 would carry
        // texels within an ulp or two of f32::MAX past it.
        out[k] = ((weights[0] * a[k] + weights[1] * b[k])
            + (weights[2] * c[k] + weights[3] * d[k]))
            .min(f32::MAX);
    }
    out
}

/// [`periodic`] with selects and [`floor_f32`] (no branch, no library call), the
/// same value.
#[inline(always)]
fn periodic_lanes(u: f32) -> f32 {
    let r = u - floor_f32(u);
    let r = if r < 1.0 { r } else { 0.0 };
    if (0.0..1.0).contains(&u) {
        u
    } else {
        r
    }
}

/// [`clamped_pair`] in `i32` (see [`floor_index_i32`]), the same values.
#[inline(always)]
fn clamped_pair_i32(t: f32, n: i32) -> (i32, i32, f32) {
    let s = t * n as f32 + 0.5;
    let i = floor_index_i32(s, n);
    ((i - 1).max(0), i.min(n - 1), s - i as f32)
}

/// `u` reduced into `[0, 1)` (for u outside it: the lookups' u is periodic).
#[inline]
fn periodic(u: f32) -> f32 {
    if (0.0..1.0).contains(&u) {
        u
    } else {
        let r = u - u.floor();
        // u - ⌊u⌋ rounds up to 1 for tiny negative u.
        if r < 1.0 {
            r
        } else {
            0.0
        }
    }
}

/// The two texels around coordinate `t ∈ [0, 1]` on a clamped axis of `n` texels,
/// and the interpolation weight of the second: `⌊t n - ½⌋` and the next, clamped
/// into `[0, n - 1]` (constant half-texels at the ends).
#[inline]
fn clamped_pair(t: f32, n: usize) -> (usize, usize, f32) {
    let s = t * len_f32(n) + 0.5;
    let i = floor_index(s, n + 1);
    (i.saturating_sub(1), i.min(n - 1), s - len_f32(i))
}

/// The two rows around `t` when the `n` rows are nodes from `t = 0` to `t = 1`
/// (row `j` at `j/(n-1)`), and the second's weight; `t` is clamped into `[0, 1]`
/// (NaN to 0). One row: `(0, 0, 0)`.
#[inline(always)]
fn node_pair(t: f32, n: usize) -> (usize, usize, f32) {
    if n < 2 {
        return (0, 0, 0.0);
    }
    let t = if t > 0.0 { t.min(1.0) } else { 0.0 };
    let s = t * len_f32(n - 1);
    let i = floor_index(s, n - 1);
    (i, i + 1, s - len_f32(i))
}

/// [`node_pair`] for `n < 2³¹` rows as `i32`s, with selects (for vector lanes):
/// the same rows and weight.
#[inline(always)]
fn node_pair_i32(t: f32, n: i32) -> (i32, i32, f32) {
    let t = if t > 0.0 { t.min(1.0) } else { 0.0 };
    let s = t * (n - 1) as f32;
    let i = floor_index_i32(s, (n - 2).max(0));
    let (i, j, f) = (i, i + 1, s - i as f32);
    if n < 2 {
        (0, 0, 0.0)
    } else {
        (i, j, f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sides_above_the_limit_are_refused() {
        // Zeroed memory the kernel maps lazily: the check comes before any texel is read.
        let texels = vec![[0.0f32; 3]; MAX_SIDE + 1];
        let err = EnvImage::new(MAX_SIDE + 1, 1, texels).unwrap_err();
        assert!(matches!(err, Error::InvalidDimensions { .. }), "{err}");
        assert!(EnvImage::new(1, MAX_SIDE, vec![[0.0f32; 3]; MAX_SIDE]).is_ok());
    }

    fn ramp() -> EnvImage {
        EnvImage::from_fn(4, 2, |x, y| [x as f32, y as f32, 1.0]).unwrap()
    }

    #[test]
    fn nearest_wraps_u_and_clamps_v() {
        let img = ramp();
        assert_eq!(img.lookup_nearest(0.1, 0.1), [0.0, 0.0, 1.0]);
        assert_eq!(img.lookup_nearest(0.99, 0.99), [3.0, 1.0, 1.0]);
        assert_eq!(img.lookup_nearest(1.1, 1.5), [0.0, 1.0, 1.0]);
        assert_eq!(img.lookup_nearest(-0.1, -0.5), [3.0, 0.0, 1.0]);
    }

    #[test]
    fn bilinear_hits_texel_centres_and_wraps_the_seam() {
        let img = ramp();
        assert_eq!(img.lookup_bilinear(2.5 / 4.0, 0.25), [2.0, 0.0, 1.0]);
        // Halfway between the last column (x = 3) and the first (x = 0) across the seam.
        let seam = img.lookup_bilinear(0.0, 0.25);
        assert!((seam[0] - 1.5).abs() < 1e-6, "{seam:?}");
        // Top half-row is constant in v (clamp).
        assert_eq!(img.lookup_bilinear(0.625, 0.0), [2.0, 0.0, 1.0]);
        assert!((img.lookup_bilinear(0.625, 0.5)[1] - 0.5).abs() < 1e-6);
    }

    #[test]
    fn clamped_u_holds_the_edge_columns() {
        let img = ramp();
        let mode = Lookup::Bilinear;
        assert_eq!(img.lookup_wrapped(0.0, 0.25, mode, WrapU::Clamp)[0], 0.0);
        assert_eq!(img.lookup_wrapped(0.999, 0.25, mode, WrapU::Clamp)[0], 3.0);
        assert_eq!(
            img.lookup_wrapped(1.2, 0.25, Lookup::Nearest, WrapU::Clamp)[0],
            3.0
        );
        assert!((img.lookup_wrapped(0.5, 0.25, mode, WrapU::Clamp)[0] - 1.5).abs() < 1e-6);
    }

    #[test]
    fn brightest_texel_is_the_first_maximum_in_row_order() {
        let img = EnvImage::from_fn(5, 3, |x, y| {
            if (x, y) == (3, 1) || (x, y) == (1, 2) {
                [2.0; 3]
            } else {
                [1.0; 3]
            }
        })
        .unwrap();
        let (x, y, lum) = img.brightest_texel();
        assert_eq!((x, y), (3, 1));
        assert!((lum - 2.0).abs() < 1e-5);
    }

    #[test]
    fn raw_texels_are_validated() {
        let bad = vec![[0.0, 1.0, 2.0], [0.0, f32::NAN, 0.0]];
        match EnvImage::from_raw("f.pfm", 2, 1, bad.clone(), false) {
            Err(Error::NonFiniteTexel { pos, channel, .. }) => {
                assert_eq!((pos.x, pos.y, channel), (1, 0, 'G'))
            }
            other => panic!("{other:?}"),
        }
        let (img, report) = EnvImage::from_raw("f.pfm", 2, 1, bad, true).unwrap();
        assert_eq!(report.non_finite_texels, 1);
        assert_eq!(img.texel(1, 0), [0.0; 3]);
        let (img, report) =
            EnvImage::from_raw("f", 1, 2, vec![[-0.5, 1.0, -0.25], [1.0; 3]], false).unwrap();
        assert_eq!((report.negative_texels, report.most_negative), (1, -0.5));
        assert_eq!(img.texel(0, 0), [0.0, 1.0, 0.0]);
        assert!(EnvImage::new(2, 2, vec![[0.0; 3]; 3]).is_err());
        assert!(EnvImage::new(0, 2, vec![]).is_err());
    }
}
