//! Hand-written AVX-512 kernels for the two batch queries a renderer makes most:
//! `pdf_batch` of the piecewise-constant inversion sampler and `radiance_batch`
//! with the bilinear lookup, both on the lat-long map. They run the same IEEE
//! operations in the same order as the lane loops of `batch.rs` (no fused
//! multiply-add), so every value is bit for bit the single query's; what changes
//! is how the data moves. The compiler's version of those loops deinterleaves the
//! directions lane by lane, extracts each lane's cell index for a prefetch and
//! reads the tables with scalar loads; here 16 directions are three loads and six
//! permutes, and every table and texel read is a gather, whose cache misses the
//! CPU overlaps by itself. Values that sit side by side in memory (a cell's two
//! CDF entries, a patch row's two node values, a row's two texels) are read as
//! 64-bit pairs, eight lanes per gather: a gather costs about one load per
//! element, so a pair read once is half the loads of two 32-bit gathers.
//!
//! Each kernel returns `false` without touching `out` where it does not apply
//! (another sampler, density, mapping or lookup, or tables too large for 32-bit
//! gather indices); the caller then runs the generic kernel.

use super::{EnvironmentLight, LightSample, Mapping, Planar};
use crate::bilinear::{BilinearDistribution2D, CentredTables};
use crate::distribution::ONE_MINUS_EPSILON;
use crate::image::Lookup;
use crate::mapping::EQUIRECT_JACOBIAN;
use crate::math::{len_f32, prefetch_ptr, Vec3, ATAN_PI_Q, TAN_PI_8};
use std::arch::x86_64::*;

/// Directions per vector.
const LANES: usize = 16;

/// The bilinear density's tables (node values and factors) above which its
/// batch pdf asks for each block's corners a block ahead. Measured on a 2-core
/// Xeon with 2 MiB of L2 per core (`peer_queries`, the lights' own samples):
/// 2k map (17 MB) 7.6-9.2 -> 6.8-7.0 ns, 4k 13.1 -> 9.2-9.9 ns, but 1k (4.2 MB)
/// 5.2-5.7 -> 5.9-6.3 ns, where the sixteen lanes' 48 prefetches cost more
/// than the misses they hide.
pub(super) const PREFETCH_ABOVE: usize = 8 << 20;

/// How many blocks of directions ahead the input is asked for.
const INPUT_AHEAD: usize = 8;

/// [`EnvironmentLight::pdf_batch`] on one chunk, for the inversion sampler's
/// piecewise-constant density on the lat-long map; `false` (and nothing written)
/// for any other light.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
pub(super) fn pdf_chunk(light: &EnvironmentLight, dirs: &[Vec3], out: &mut [f32]) -> bool {
    let d = match &light.planar {
        Planar::Inversion(d) => d,
        Planar::Bilinear(d) => return bilinear_pdfs::<true>(light, d, dirs, out),
        _ => return false,
    };
    let t = d.cell_tables();
    if light.options.mapping != Mapping::Equirectangular
        || t.conditional_cdf.len() > i32::MAX as usize
    {
        return false;
    }
    let frame = Frame::of(light);
    let stride = _mm512_set1_epi32((t.nu + 1) as i32);
    let (nu, nv) = (_mm512_set1_ps(len_f32(t.nu)), _mm512_set1_ps(len_f32(t.nv)));
    let last = |n: usize| _mm512_set1_epi32((n - 1).min(i32::MAX as usize) as i32);
    let (last_u, last_v) = (last(t.nu), last(t.nv));
    let scale = _mm512_set1_pd(t.pdf_scale);
    let infinity = _mm512_set1_ps(f32::INFINITY);
    let (cdf, marginal) = (t.conditional_cdf.as_ptr(), t.marginal_cdf.as_ptr());
    for (dirs, out) in dirs.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let [x, y, z] = load_directions(dirs);
        let (u, v, csc) = frame.to_uv(x, y, z);
        let iu = floor_index(_mm512_mul_ps(u, nu), last_u);
        let iv = floor_index(_mm512_mul_ps(v, nv), last_v);
        let at = _mm512_add_epi32(_mm512_mullo_epi32(iv, stride), iu);
        // Each cell's two conditional CDF entries are neighbours, and so are its
        // row's two marginal ones: one 64-bit gather per pair and eight lanes,
        // whose halves' difference is the width (CDFs never decrease).
        // SAFETY: iu < nu and iv < nv (floor_index clamps), so `at + 1` is inside
        // the nv (nu + 1) conditional entries and `iv + 1` inside the nv + 1
        // marginal ones; every index fits an i32 (checked above).
        let widths = |at: __m256i, table: *const u32| {
            let pair = unsafe { _mm512_i32gather_epi64::<4>(at, table.cast()) };
            let low = _mm512_and_si512(pair, _mm512_set1_epi64(u32::MAX as i64));
            _mm512_cvtepi64_pd(_mm512_sub_epi64(_mm512_srli_epi64::<32>(pair), low))
        };
        // (wu wv) pdf_scale in f64, rounded to f32 once, eight lanes at a time.
        let planar_half = |at: __m256i, iv: __m256i| {
            _mm512_cvtpd_ps(_mm512_mul_pd(
                _mm512_mul_pd(widths(at, cdf), widths(iv, marginal)),
                scale,
            ))
        };
        let (lower, upper) = (
            |x: __m512i| _mm512_castsi512_si256(x),
            |x: __m512i| _mm512_extracti64x4_epi64::<1>(x),
        );
        let planar = _mm512_insertf32x8::<1>(
            _mm512_castps256_ps512(planar_half(lower(at), lower(iv))),
            planar_half(upper(at), upper(iv)),
        );
        store_solid_angle(out, planar, csc, infinity);
    }
    true
}

/// [`EnvironmentLight::sample_batch`] on one chunk for the bilinear density on
/// the lat-long map: the generic sampling, with the pdfs at the returned
/// directions from [`bilinear_pdfs`]; `false` for any other light.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
pub(super) fn sample_chunk(
    light: &EnvironmentLight,
    xi: &[[f32; 2]],
    out: &mut [Option<LightSample>],
) -> bool {
    let Planar::Bilinear(d) = &light.planar else {
        return false;
    };
    if bilinear_tables(light, d).is_none() {
        return false;
    }
    light.sample_bilinear_blocks(d, xi, out, |dirs: &[Vec3], out: &mut [f32]| {
        bilinear_pdfs::<false>(light, d, dirs, out);
    });
    true
}

/// The tables [`bilinear_pdfs`] reads for `d`, where it runs: the lat-long map,
/// the layouts the light builds (texel centres, or the node lookup's rows along
/// v), tables small enough for 32-bit gather indices.
fn bilinear_tables<'a>(
    light: &EnvironmentLight,
    d: &'a BilinearDistribution2D,
) -> Option<CentredTables<'a>> {
    d.centred_tables().filter(|t| {
        light.options.mapping == Mapping::Equirectangular && t.values.len() <= i32::MAX as usize
    })
}

/// The bilinear density's pdf at each direction (`pdf_in_centred_patches` over
/// the Jacobian: the patches and the distances to their sides in f64, eight
/// lanes at a time, the rest in f32 on 16); `false` (and nothing written) where
/// [`bilinear_tables`] does not hold.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
fn bilinear_pdfs<const PREFETCH: bool>(
    light: &EnvironmentLight,
    d: &BilinearDistribution2D,
    dirs: &[Vec3],
    out: &mut [f32],
) -> bool {
    let Some(t) = bilinear_tables(light, d) else {
        return false;
    };
    // With PREFETCH, on tables beyond the cache, each block's angles and
    // patches are computed, and their lines asked for, a block before its
    // corners are read.
    let tables = std::mem::size_of_val(t.values) + std::mem::size_of_val(t.factors);
    if PREFETCH && tables > PREFETCH_ABOVE {
        bilinear_pdf_blocks::<true>(light, &t, dirs, out);
    } else {
        bilinear_pdf_blocks::<false>(light, &t, dirs, out);
    }
    true
}

/// [`bilinear_pdfs`] on the tables `t`, each block finished at once, or with
/// `AHEAD` one block later, its lines asked for in between.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
fn bilinear_pdf_blocks<const AHEAD: bool>(
    light: &EnvironmentLight,
    t: &CentredTables<'_>,
    dirs: &[Vec3],
    out: &mut [f32],
) {
    let frame = Frame::of(light);
    let mu = t.mu;
    let row = _mm256_set1_epi32(mu as i32);
    let patch_row = _mm256_set1_epi32(mu as i32 - 1);
    let one = _mm256_set1_epi32(1);
    // Patches are within [0, mu - 2] × [0, mv - 2] by construction; the clamps
    // keep the gathers inside the tables whatever happens.
    let mv = t.values.len() / mu;
    let (last_i, last_k) = (
        _mm256_set1_epi32(mu as i32 - 2),
        _mm256_set1_epi32(mv as i32 - 2),
    );
    let (cells_u, cells_v) = (_mm512_set1_pd(t.cells[0]), _mm512_set1_pd(t.cells[1]));
    let (zero, one_f, half) = (
        _mm512_setzero_pd(),
        _mm512_set1_pd(1.0),
        _mm512_set1_pd(0.5),
    );
    let node_rows = t.node_rows;
    let last_row = _mm256_set1_epi32(t.cells[1] as i32 - 1);
    let infinity = _mm512_set1_ps(f32::INFINITY);
    let scale = _mm512_set1_ps(t.scale);
    let (values, factors) = (t.values.as_ptr(), t.factors.as_ptr());
    let (even, odd) = (indices(&EVEN), indices(&ODD));
    // `unit_closed`: x in [0, 1] as f64 (0 for NaN). minpd gives 1 for a NaN.
    let unit_closed = |x: __m256| {
        let y = _mm512_min_pd(_mm512_cvtps_pd(x), one_f);
        _mm512_maskz_mov_pd(_mm256_cmp_ps_mask::<_CMP_GT_OQ>(x, _mm256_setzero_ps()), y)
    };
    // `[at − lo, hi − at]` clamped at 0, rounded to f32 (`centred_weights`,
    // `row_weights`).
    let distances = |at: __m512d, lo: __m512d, hi: __m512d| {
        [
            _mm512_cvtpd_ps(_mm512_max_pd(_mm512_sub_pd(at, lo), zero)),
            _mm512_cvtpd_ps(_mm512_max_pd(_mm512_sub_pd(hi, at), zero)),
        ]
    };
    // `centred_weights` of the point `at = x n` in patch `i` (as f64).
    let centred = |at: __m512d, n: __m512d, i: __m512d| {
        let lo = _mm512_max_pd(_mm512_sub_pd(i, half), zero);
        let hi = _mm512_min_pd(_mm512_add_pd(i, half), n);
        distances(at, lo, hi)
    };
    // `centred_patches` and the distances to the patches' sides at eight
    // points (`u`, `v` in f32): the patches' first node values, their factors'
    // indices and `[left, right, above, below]`.
    let patches = |u: __m256, v: __m256| {
        let (u, v) = (unit_closed(u), unit_closed(v));
        let (x, y) = (_mm512_mul_pd(u, cells_u), _mm512_mul_pd(v, cells_v));
        let i = _mm256_min_epu32(_mm512_cvttpd_epu32(_mm512_add_pd(x, half)), last_i);
        // Along v the texel centres' ⌊v h + ½⌋, or the node rows'
        // 1 + min(⌊v m⌋, m − 1).
        let k = if node_rows {
            let below = _mm512_cvttpd_epu32(y);
            _mm256_add_epi32(_mm256_min_epu32(below, last_row), one)
        } else {
            _mm512_cvttpd_epu32(_mm512_add_pd(y, half))
        };
        let k = _mm256_min_epu32(k, last_k);
        let [left, right] = centred(x, cells_u, _mm512_cvtepi32_pd(i));
        let fk = _mm512_cvtepi32_pd(k);
        let [above, below] = if node_rows {
            let lo = _mm512_min_pd(_mm512_max_pd(_mm512_sub_pd(fk, one_f), zero), cells_v);
            distances(y, lo, _mm512_min_pd(fk, cells_v))
        } else {
            centred(y, cells_v, fk)
        };
        let top = _mm256_add_epi32(_mm256_mullo_epi32(k, row), i);
        let patch = _mm256_add_epi32(_mm256_mullo_epi32(k, patch_row), i);
        (top, patch, [left, right, above, below])
    };
    // Both halves' 8 lanes as one vector of 16.
    let join = |lower: __m256, upper: __m256| {
        _mm512_insertf32x8::<1>(_mm512_castps256_ps512(lower), upper)
    };
    let join_i = |lower: __m256i, upper: __m256i| {
        _mm512_inserti32x8::<1>(_mm512_castsi256_si512(lower), upper)
    };
    // A row's two neighbouring node values at 16 patches (`first`: the left
    // node's index, eight lanes per half), each pair one 64-bit gather, split
    // into the left and right values.
    // SAFETY (the gathers): i <= mu - 2 and k <= mv - 2, so both nodes of each
    // patch's rows are inside the mu mv values and the patch inside the
    // (mu - 1)(mv - 1) factors; every index fits an i32 (`bilinear_tables`).
    let pairs = |first: [__m256i; 2]| unsafe {
        let [lower, upper] =
            first.map(|at| _mm512_castsi512_ps(_mm512_i32gather_epi64::<4>(at, values.cast())));
        [
            _mm512_permutex2var_ps(lower, even, upper),
            _mm512_permutex2var_ps(lower, odd, upper),
        ]
    };
    // A block's patches, distances and Jacobians.
    let prepare = |dirs: &[Vec3]| {
        let [x, y, z] = load_directions(dirs);
        let (u, v, csc) = frame.to_uv(x, y, z);
        let (top_l, patch_l, w_l) = patches(_mm512_castps512_ps256(u), _mm512_castps512_ps256(v));
        let (top_u, patch_u, w_u) = patches(upper_half(u), upper_half(v));
        let weights = [0, 1, 2, 3].map(|m| join(w_l[m], w_u[m]));
        ([top_l, top_u], [patch_l, patch_u], weights, csc)
    };
    // Starts fetching what `finish` reads for a block: both rows of corners and
    // the factor of each lane's patch.
    let prefetch = |top: &[__m256i; 2], patch: &[__m256i; 2]| {
        let (mut at, mut factor) = ([0i32; LANES], [0i32; LANES]);
        // SAFETY: 2 × 8 i32 are the 64 bytes of each array.
        unsafe {
            _mm512_storeu_si512(at.as_mut_ptr().cast(), join_i(top[0], top[1]));
            _mm512_storeu_si512(factor.as_mut_ptr().cast(), join_i(patch[0], patch[1]));
        }
        for (&at, &f) in at.iter().zip(&factor) {
            prefetch_ptr(values.wrapping_add(at as usize));
            prefetch_ptr(values.wrapping_add(at as usize + mu));
            prefetch_ptr(factors.wrapping_add(f as usize));
        }
    };
    let finish =
        |top: [__m256i; 2], patch: [__m256i; 2], weights: [__m512; 4], csc, out: &mut [f32]| {
            let [left, right, above, below] = weights;
            let [a, b] = pairs(top);
            let [c, dd] = pairs(top.map(|t| _mm256_add_epi32(t, row)));
            // SAFETY: as `pairs`.
            let factor =
                unsafe { _mm512_i32gather_ps::<4>(join_i(patch[0], patch[1]), factors.cast()) };
            // `pdf_from_weights`.
            let weighted = _mm512_add_ps(
                _mm512_mul_ps(
                    below,
                    _mm512_add_ps(_mm512_mul_ps(right, a), _mm512_mul_ps(left, b)),
                ),
                _mm512_mul_ps(
                    above,
                    _mm512_add_ps(_mm512_mul_ps(right, c), _mm512_mul_ps(left, dd)),
                ),
            );
            let planar = _mm512_mul_ps(factor, _mm512_mul_ps(weighted, scale));
            store_solid_angle(out, planar, csc, infinity);
        };
    if !AHEAD {
        for (dirs, out) in dirs.chunks(LANES).zip(out.chunks_mut(LANES)) {
            let (top, patch, weights, csc) = prepare(dirs);
            finish(top, patch, weights, csc, out);
        }
        return;
    }
    // Each block prepared and its lines asked for, then finished a block later.
    let mut ahead = None;
    let blocks = dirs.chunks(LANES).zip(out.chunks_mut(LANES));
    for block in blocks.map(Some).chain([None]) {
        let next = block.map(|(dirs, out)| (prepare(dirs), out));
        if let Some(((top, patch, _, _), _)) = &next {
            prefetch(top, patch);
        }
        let ready = std::mem::replace(&mut ahead, next);
        if let Some(((top, patch, weights, csc), out)) = ready {
            finish(top, patch, weights, csc, out);
        }
    }
}

/// Lanes `start, start + 2, …` of two vectors of 16 (lanes `0..16` the first's,
/// `16..32` the second's): their even (`start` 0) or odd (1) floats.
const fn every_other(start: i32) -> [i32; 16] {
    let mut e = [0; 16];
    let mut i = 0;
    while i < 16 {
        e[i] = 2 * i as i32 + start;
        i += 1;
    }
    e
}
const EVEN: [i32; 16] = every_other(0);
const ODD: [i32; 16] = every_other(1);

/// Lanes 8 to 15.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn upper_half(x: __m512) -> __m256 {
    _mm512_extractf32x8_ps::<1>(x)
}

/// `solid_angle` of the planar pdfs over the Jacobians `csc / EQUIRECT_JACOBIAN`
/// (0 where either is not finite), stored to the first `out.len()` lanes.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn store_solid_angle(out: &mut [f32], planar: __m512, csc: __m512, infinity: __m512) {
    let inv_jacobian = _mm512_mul_ps(csc, _mm512_set1_ps(1.0 / EQUIRECT_JACOBIAN));
    let pdf = _mm512_mul_ps(planar, inv_jacobian);
    let finite = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(inv_jacobian, infinity)
        & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(pdf, infinity);
    let pdf = _mm512_maskz_mov_ps(finite, pdf);
    // SAFETY: the mask covers the chunk's `out.len()` entries only.
    unsafe { _mm512_mask_storeu_ps(out.as_mut_ptr(), lane_mask(out.len()), pdf) };
}

/// [`EnvironmentLight::radiance_batch`] on one chunk, for the bilinear lookup of
/// a lat-long map (periodic in u); `false` (and nothing written) for any other
/// lookup or mapping.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
pub(super) fn radiance_chunk(
    light: &EnvironmentLight,
    dirs: &[Vec3],
    out: &mut [[f32; 3]],
) -> bool {
    let image = &light.image;
    let (w, h) = (image.width(), image.height());
    let node = light.options.lookup == Lookup::Node;
    if light.options.mapping != Mapping::Equirectangular
        || !(light.options.lookup == Lookup::Bilinear || node)
        || w.saturating_mul(h).saturating_mul(3) > i32::MAX as usize
    {
        return false;
    }
    let frame = Frame::of(light);
    let (w32, h32) = (w as i32, h as i32);
    let (wf, hf) = (_mm512_set1_ps(len_f32(w)), _mm512_set1_ps(len_f32(h)));
    let (wi, hi) = (_mm512_set1_epi32(w32), _mm512_set1_epi32(h32));
    let (zero_i, one_i) = (_mm512_setzero_si512(), _mm512_set1_epi32(1));
    let (zero, one, half) = (
        _mm512_setzero_ps(),
        _mm512_set1_ps(1.0),
        _mm512_set1_ps(0.5),
    );
    let last_column = _mm512_set1_epi32(2 * w32 - 1);
    // The node lookup's rows: h − 1 intervals, a first row of at most h − 2.
    let rows = _mm512_set1_ps(len_f32(h.saturating_sub(1)));
    let last_row = _mm512_set1_epi32((h32 - 2).max(0));
    let scale = _mm512_set1_ps(light.options.scale);
    let largest = _mm512_set1_ps(f32::MAX);
    let texels = image.texels().as_ptr().cast::<f32>();
    for (dirs, out) in dirs.chunks(LANES).zip(out.chunks_mut(LANES)) {
        let [x, y, z] = load_directions(dirs);
        let (u, v, _) = frame.to_uv(x, y, z);
        // Columns, as `EnvImage::lookup_block` (periodic u): s = u w - ½ + w.
        let s = _mm512_add_ps(_mm512_sub_ps(_mm512_mul_ps(periodic(u), wf), half), wf);
        let k = floor_index(s, last_column);
        let wrapped = _mm512_cmpge_epi32_mask(k, wi);
        let x0 = _mm512_mask_sub_epi32(k, wrapped, k, wi);
        let x1 = _mm512_add_epi32(x0, one_i);
        let x1 = _mm512_mask_mov_epi32(x1, _mm512_cmpeq_epi32_mask(x1, wi), zero_i);
        let fs = _mm512_sub_ps(s, _mm512_cvtepi32_ps(k));
        let (y0, y1, ft) = if !node {
            // Rows, clamped: t = v h + ½.
            let t = _mm512_add_ps(_mm512_mul_ps(v, hf), half);
            let i = floor_index(t, hi);
            let y0 = _mm512_max_epi32(_mm512_sub_epi32(i, one_i), zero_i);
            let y1 = _mm512_min_epi32(i, _mm512_sub_epi32(hi, one_i));
            (y0, y1, _mm512_sub_ps(t, _mm512_cvtepi32_ps(i)))
        } else if h >= 2 {
            // `node_pair`: the rows as nodes, s = clamp(v, 0, 1) (h − 1), rows
            // ⌊s⌋ ≤ h − 2 and the next.
            let inside = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(v, zero);
            let s = _mm512_mul_ps(_mm512_maskz_mov_ps(inside, _mm512_min_ps(v, one)), rows);
            let i = floor_index(s, last_row);
            (
                i,
                _mm512_add_epi32(i, one_i),
                _mm512_sub_ps(s, _mm512_cvtepi32_ps(i)),
            )
        } else {
            (zero_i, zero_i, zero)
        };
        // `blend`'s weights (a NaN weight becomes 0).
        let (fs, ft) = (_mm512_max_ps(fs, zero), _mm512_max_ps(ft, zero));
        let (gs, gt) = (_mm512_sub_ps(one, fs), _mm512_sub_ps(one, ft));
        let weights = [
            _mm512_mul_ps(gs, gt),
            _mm512_mul_ps(fs, gt),
            _mm512_mul_ps(gs, ft),
            _mm512_mul_ps(fs, ft),
        ];
        let texel = |x: __m512i, y: __m512i| {
            let at = _mm512_add_epi32(_mm512_mullo_epi32(y, wi), x);
            _mm512_add_epi32(_mm512_add_epi32(at, at), at)
        };
        // The four corners' channels, `[corner][channel]`, corners in `blend`'s
        // order. Where every lane's right column follows its left one (all but
        // the lanes on the seam, x0 = w − 1), a row's two texels are six
        // consecutive floats: three 64-bit gathers per eight lanes, split into
        // channels by permutes (96 loads per 16 lanes); otherwise one 32-bit
        // gather per corner and channel (192).
        let consecutive = _mm512_cmpeq_epi32_mask(x1, _mm512_add_epi32(x0, one_i)) == !0;
        let corners: [[__m512; 3]; 4] = if consecutive {
            let [a, b] = row_pairs(texel(x0, y0), texels);
            let [c, d] = row_pairs(texel(x0, y1), texels);
            [a, b, c, d]
        } else {
            let at = [texel(x0, y0), texel(x1, y0), texel(x0, y1), texel(x1, y1)];
            let mut corners = [[zero; 3]; 4];
            for (corner, &at) in corners.iter_mut().zip(&at) {
                for (c, channel) in corner.iter_mut().enumerate() {
                    // SAFETY: x0, x1 < w and y0, y1 < h, so every corner's
                    // channel is inside the w h texels, and 3 w h fits an i32
                    // (checked above).
                    *channel = unsafe {
                        _mm512_i32gather_ps::<4>(
                            _mm512_add_epi32(at, _mm512_set1_epi32(c as i32)),
                            texels.cast(),
                        )
                    };
                }
            }
            corners
        };
        // A plain loop: written with `std::array::from_fn` and a closure, the
        // closure was compiled out of line (three calls a block, with spills),
        // and the kernel measured 25% slower.
        let mut rgb = [zero; 3];
        for (c, rgb) in rgb.iter_mut().enumerate() {
            let [a, b, cc, d] = [corners[0][c], corners[1][c], corners[2][c], corners[3][c]];
            let near = _mm512_add_ps(_mm512_mul_ps(weights[0], a), _mm512_mul_ps(weights[1], b));
            let far = _mm512_add_ps(_mm512_mul_ps(weights[2], cc), _mm512_mul_ps(weights[3], d));
            // `blend`'s and `scaled`'s clamps to f32::MAX.
            let blended = _mm512_min_ps(_mm512_add_ps(near, far), largest);
            *rgb = _mm512_min_ps(_mm512_mul_ps(blended, scale), largest);
        }
        store_triples(out, rgb);
    }
    true
}

/// The channels of two neighbouring texels of one row at 16 lanes, `[left,
/// right]`, each `[r, g, b]`; `at` is each lane's left texel's first float.
/// Six floats from `at` are three pairs, each pair one 64-bit gather per eight
/// lanes, split into channels by permutes: `(r0, g0)`, `(b0, r1)`, `(g1, b1)`.
///
/// The caller guarantees that for every lane both texels are inside `texels`
/// (six floats from `at`) and that `at + 6` fits an i32.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn row_pairs(at: __m512i, texels: *const f32) -> [[__m512; 3]; 2] {
    let (even, odd) = (indices(&EVEN), indices(&ODD));
    let halves = [
        _mm512_castsi512_si256(at),
        _mm512_extracti32x8_epi32::<1>(at),
    ];
    let pair = |offset: i32| {
        let [lower, upper] = halves.map(|at| {
            // SAFETY: the caller's (both texels inside `texels`).
            unsafe {
                _mm512_castsi512_ps(_mm512_i32gather_epi64::<4>(
                    _mm256_add_epi32(at, _mm256_set1_epi32(offset)),
                    texels.cast(),
                ))
            }
        });
        [
            _mm512_permutex2var_ps(lower, even, upper),
            _mm512_permutex2var_ps(lower, odd, upper),
        ]
    };
    let ([r0, g0], [b0, r1], [g1, b1]) = (pair(0), pair(2), pair(4));
    [[r0, g0, b0], [r1, g1, b1]]
}

/// The rotation into the light's frame, if any, and the lat-long map's angles.
struct Frame {
    rows: Option<[[__m512; 3]; 3]>,
}

impl Frame {
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
    fn of(light: &EnvironmentLight) -> Self {
        let rows = light.rotated.then(|| {
            light
                .world_to_light
                .rows()
                .map(|row| row.map(|m| _mm512_set1_ps(m)))
        });
        Self { rows }
    }

    /// `direction_to_equirect_and_csc` of 16 world directions (rotated into the
    /// light's frame first, as `Rotation::apply` does): `u`, `v` and `1 / sin θ`.
    #[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
    #[inline]
    fn to_uv(&self, x: __m512, y: __m512, z: __m512) -> (__m512, __m512, __m512) {
        let (x, y, z) = match &self.rows {
            None => (x, y, z),
            Some(m) => {
                let row = |r: &[__m512; 3]| {
                    _mm512_add_ps(
                        _mm512_add_ps(_mm512_mul_ps(r[0], x), _mm512_mul_ps(r[1], y)),
                        _mm512_mul_ps(r[2], z),
                    )
                };
                (row(&m[0]), row(&m[1]), row(&m[2]))
            }
        };
        let r2 = _mm512_add_ps(_mm512_mul_ps(x, x), _mm512_mul_ps(y, y));
        let r = _mm512_sqrt_ps(r2);
        let csc = _mm512_div_ps(_mm512_sqrt_ps(_mm512_add_ps(r2, _mm512_mul_ps(z, z))), r);
        let v = atan2_pi(r, z);
        // `u_of_half_turns`: φ/π in [-1, 1] to u in [0, 1).
        let turns = atan2_pi(y, x);
        let u = _mm512_mul_ps(_mm512_set1_ps(0.5), turns);
        let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(turns, _mm512_setzero_ps());
        let u = _mm512_mask_add_ps(u, negative, u, _mm512_set1_ps(1.0));
        // minps gives its second operand for a NaN, as f32::min does.
        let u = _mm512_min_ps(u, _mm512_set1_ps(ONE_MINUS_EPSILON));
        (u, v, csc)
    }
}

/// `math::atan2_pi` on 16 lanes: its operations, in its order.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn atan2_pi(y: __m512, x: __m512) -> __m512 {
    let zero = _mm512_setzero_ps();
    let (ax, ay) = (_mm512_abs_ps(x), _mm512_abs_ps(y));
    let swapped = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(ay, ax);
    let num = _mm512_mask_blend_ps(swapped, ay, ax);
    let den = _mm512_mask_blend_ps(swapped, ax, ay);
    let big = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(num, _mm512_mul_ps(_mm512_set1_ps(TAN_PI_8), den));
    let top = _mm512_mask_sub_ps(num, big, num, den);
    let bottom = _mm512_mask_add_ps(den, big, num, den);
    // maxps gives its second operand for a NaN: the scalar `if MIN_POSITIVE > bottom`.
    let bottom = _mm512_max_ps(_mm512_set1_ps(f32::MIN_POSITIVE), bottom);
    let t = _mm512_div_ps(top, bottom);
    let s = _mm512_mul_ps(t, t);
    let s2 = _mm512_mul_ps(s, s);
    let q = &ATAN_PI_Q;
    let pair = |k: usize| {
        _mm512_add_ps(
            _mm512_set1_ps(q[k]),
            _mm512_mul_ps(_mm512_set1_ps(q[k + 1]), s),
        )
    };
    let poly = _mm512_add_ps(
        pair(0),
        _mm512_mul_ps(s2, _mm512_add_ps(pair(2), _mm512_mul_ps(s2, pair(4)))),
    );
    let offset = _mm512_maskz_mov_ps(big, _mm512_set1_ps(0.25));
    let a = _mm512_add_ps(offset, _mm512_mul_ps(t, poly));
    let a = _mm512_mask_sub_ps(a, swapped, _mm512_set1_ps(0.5), a);
    let a = _mm512_mask_sub_ps(
        a,
        _mm512_cmp_ps_mask::<_CMP_LT_OQ>(x, zero),
        _mm512_set1_ps(1.0),
        a,
    );
    let flip = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(y, zero);
    _mm512_mask_xor_ps(a, flip, a, _mm512_set1_ps(-0.0))
}

/// `math::floor_index_i32` on 16 lanes: ⌊x⌋ clamped to `[0, last]`, NaN to 0.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn floor_index(x: __m512, last: __m512i) -> __m512i {
    // maxps(x, 0) gives 0 for a NaN x, as f32::max does.
    let y = _mm512_max_ps(x, _mm512_setzero_ps());
    let y = _mm512_min_ps(y, _mm512_set1_ps(2_147_483_520.0));
    _mm512_min_epi32(_mm512_cvttps_epi32(y), last)
}

/// `image::periodic_lanes` on 16 lanes: u reduced into `[0, 1)` (NaN to 0).
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn periodic(u: __m512) -> __m512 {
    let (zero, one) = (_mm512_setzero_ps(), _mm512_set1_ps(1.0));
    let r = _mm512_sub_ps(u, floor(u));
    let r = _mm512_maskz_mov_ps(_mm512_cmp_ps_mask::<_CMP_LT_OQ>(r, one), r);
    let inside =
        _mm512_cmp_ps_mask::<_CMP_GE_OQ>(u, zero) & _mm512_cmp_ps_mask::<_CMP_LT_OQ>(u, one);
    _mm512_mask_blend_ps(inside, r, u)
}

/// `math::floor_f32` on 16 lanes.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn floor(x: __m512) -> __m512 {
    const BIG: f32 = 8_388_608.0;
    // maxps(x, -BIG) gives -BIG for a NaN x, as f32::max does.
    let c = _mm512_min_ps(_mm512_max_ps(x, _mm512_set1_ps(-BIG)), _mm512_set1_ps(BIG));
    let t = _mm512_cvtepi32_ps(_mm512_cvttps_epi32(c));
    let above = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(t, c);
    let floor = _mm512_mask_sub_ps(t, above, t, _mm512_set1_ps(1.0));
    let small = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(_mm512_abs_ps(c), _mm512_set1_ps(BIG));
    _mm512_mask_blend_ps(small, x, floor)
}

/// The first `n` of 16 lanes (all for `n >= 16`).
#[inline]
fn lane_mask(n: usize) -> __mmask16 {
    if n >= LANES {
        !0
    } else {
        (1u16 << n) - 1
    }
}

/// For each of the three vectors of 16 interleaved triples, which of its 16
/// floats come from coordinate `k` (`first` picks from the first two vectors,
/// `second` keeps those and picks the rest from the third).
const fn deinterleave(k: usize) -> ([i32; 16], [i32; 16]) {
    let (mut first, mut second) = ([0; 16], [0; 16]);
    let mut i = 0;
    while i < 16 {
        let p = 3 * i + k;
        if p < 32 {
            first[i] = p as i32;
            second[i] = i as i32;
        } else {
            second[i] = (16 + p - 32) as i32;
        }
        i += 1;
    }
    (first, second)
}

/// For output vector `m` of 16 interleaved triples, which lane of the first two
/// coordinates (`first`) and then of the third (`second`) each float is.
const fn interleave(m: usize) -> ([i32; 16], [i32; 16]) {
    let (mut first, mut second) = ([0; 16], [0; 16]);
    let mut q = 0;
    while q < 16 {
        let p = 16 * m + q;
        let (i, channel) = (p / 3, p % 3);
        first[q] = match channel {
            0 => i as i32,
            1 => 16 + i as i32,
            _ => 0,
        };
        second[q] = if channel == 2 {
            16 + i as i32
        } else {
            q as i32
        };
        q += 1;
    }
    (first, second)
}

const DEINTERLEAVE: [([i32; 16], [i32; 16]); 3] =
    [deinterleave(0), deinterleave(1), deinterleave(2)];
const INTERLEAVE: [([i32; 16], [i32; 16]); 3] = [interleave(0), interleave(1), interleave(2)];

/// Loads an index vector.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn indices(i: &[i32; 16]) -> __m512i {
    // SAFETY: 16 i32 are 64 readable bytes.
    unsafe { _mm512_loadu_si512(i.as_ptr().cast()) }
}

/// The x, y and z of up to 16 directions in lanes (missing ones are zero).
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn load_directions(dirs: &[Vec3]) -> [__m512; 3] {
    let floats = 3 * dirs.len().min(LANES);
    let base = dirs.as_ptr().cast::<f32>();
    let part = |m: usize| {
        let mask = lane_mask(floats.saturating_sub(16 * m));
        // SAFETY: the mask covers only the 3 len floats of `dirs` (`Vec3` is
        // `repr(C)` over three f32); masked-off lanes are not read.
        unsafe { _mm512_maskz_loadu_ps(mask, base.wrapping_add(16 * m)) }
    };
    let (a, b, c) = (part(0), part(1), part(2));
    if INPUT_AHEAD > 0 {
        for line in 0..3 {
            prefetch_ptr(base.wrapping_add(3 * LANES * INPUT_AHEAD + 16 * line));
        }
    }
    DEINTERLEAVE.map(|(first, second)| {
        _mm512_permutex2var_ps(
            _mm512_permutex2var_ps(a, indices(&first), b),
            indices(&second),
            c,
        )
    })
}

/// Stores up to 16 triples from their coordinates in lanes.
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw")]
#[inline]
fn store_triples(out: &mut [[f32; 3]], [r, g, b]: [__m512; 3]) {
    let floats = 3 * out.len().min(LANES);
    let base = out.as_mut_ptr().cast::<f32>();
    for (m, (first, second)) in INTERLEAVE.iter().enumerate() {
        let v = _mm512_permutex2var_ps(
            _mm512_permutex2var_ps(r, indices(first), g),
            indices(second),
            b,
        );
        let mask = lane_mask(floats.saturating_sub(16 * m));
        // SAFETY: the mask covers only the 3 len floats of `out`.
        unsafe { _mm512_mask_storeu_ps(base.wrapping_add(16 * m), mask, v) };
    }
}
