//! The visibility cache: product sampling at shading points in proportion to the
//! sky each region of the scene actually sees, learned from rays the renderer
//! traces through a callback (docs/design.md §10).

use std::ffi::{c_char, c_void, CStr};
use std::sync::Arc;

use envlight::visibility::{VisibilityError, VisibilityOptions};
use envlight::{Factor, Vec3, VisibilityCache};
use rayon::prelude::*;

use crate::boundary::{
    c_str, deref, deref_mut, free, new_handle, read, run, slice, slice_mut, value, Failure,
};
use crate::light::path_of;
use crate::sample::{as_vec3, draw_batch_at, finite_u, sample_into, vec3, CHUNK};
use crate::{envlight_product, envlight_sample, envlight_status};

/// A visibility cache over a product sampler: for each entry (a cell of space
/// times a cell of normals) where the build's points fell, what share of each
/// patch of the light it sees, and the sampling distribution that follows.
/// Opaque and immutable once built: a `const` pointer serves any number of
/// threads. It keeps the product sampler (and its light) alive; free it with
/// `envlight_visibility_cache_free`.
pub struct envlight_visibility_cache {
    pub(crate) cache: VisibilityCache,
}

/// How a visibility cache is built. Start from
/// `envlight_visibility_options_default()` and change fields.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct envlight_visibility_options {
    /// Side of the cubic cells that group points into entries, in world units;
    /// 0 (the default) chooses it from the points, so that about
    /// `target_entries` entries form. Otherwise positive and finite.
    pub radius: f32,
    /// Cells per side of the octahedral grid of normals that splits a cell's
    /// points by orientation, 1 to 16 (4: groups about 50° across).
    pub normal_bins: u32,
    /// The number of entries the automatic radius aims at (at least 1).
    pub target_entries: usize,
    /// Bytes the entries' tables may take; the radius grows until they fit.
    pub memory_budget: usize,
    /// Rays per entry and lit patch it can face in the first pass, 1 to 4096.
    pub rays_per_patch: u32,
    /// Rays per entry and patch in the second pass, towards the patches on an
    /// edge of what the first pass saw, 0 to 4096 (0: no second pass).
    pub refine_rays: u32,
    /// The learned distribution's largest share of the mixture, in [0, 1); an
    /// entry's share shrinks with the share of its sky it sees.
    pub learned_share: f32,
    /// The prior count of unoccluded rays in each visibility estimate (positive
    /// and finite), so that no estimate is 0.
    pub prior: f32,
    /// Seed of the rays' directions and origins.
    pub seed: u64,
    /// Must be zero: room for options added later without changing this struct's size.
    pub reserved: [u32; 4],
}

/// What a visibility cache holds (`envlight_visibility_cache_summary`).
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_visibility_summary {
    /// Entries.
    pub entries: u64,
    /// Bytes of the entries' tables and of the lookup.
    pub bytes: u64,
    /// The cells' side, world units.
    pub radius: f32,
    /// The light-weighted visibility of each entry over the patches it can
    /// face, averaged over entries, in [0, 1].
    pub mean_visibility: f64,
    /// Rays traced to build it (those of the build that made it, for a loaded
    /// cache).
    pub rays: u64,
}

/// The renderer's tracer, called by `envlight_visibility_cache_build` with
/// batches of `count` rays: `origins` and `directions` hold `count · 3` floats
/// each (world frame, z up; unit directions; rays start exactly at the given
/// points, so offset them as your shadow rays need), and the callback writes the
/// transmittance in [0, 1] of each ray to `transmittance[0..count]` (1: the ray
/// escapes to the sky; 0: it is blocked). `user` is the pointer given to the
/// build. It returns `ENVLIGHT_OK` (0) on success; any other value stops the
/// build, which returns `ENVLIGHT_ERROR_CALLBACK` with a message giving the
/// value. The arrays are valid during the call only. It is called on the thread
/// that called the build, one batch at a time (never concurrently), and must not
/// unwind or `longjmp` out (catch C++ exceptions inside; `envlight.hpp` does).
pub type envlight_visibility_trace = Option<
    unsafe extern "C" fn(
        user: *mut c_void,
        origins: *const f32,
        directions: *const f32,
        count: usize,
        transmittance: *mut f32,
    ) -> i32,
>;

/// The default options: the automatic radius aiming at 512 entries, 4 × 4 bins
/// of normals, a 64 MiB budget, 4 rays per entry and patch, a learned share of
/// 0.9, a prior of 0.1 rays and the library's seed.
#[no_mangle]
pub extern "C" fn envlight_visibility_options_default() -> envlight_visibility_options {
    let d = VisibilityOptions::default();
    envlight_visibility_options {
        radius: d.radius.unwrap_or(0.0),
        normal_bins: d.normal_bins as u32,
        target_entries: d.target_entries,
        memory_budget: d.memory_budget,
        rays_per_patch: d.rays_per_patch as u32,
        refine_rays: d.refine_rays as u32,
        learned_share: d.learned_share,
        prior: d.prior,
        seed: d.seed,
        reserved: [0; 4],
    }
}

/// The library's options from C's, or an invalid-argument failure naming the
/// field (the rules are `VisibilityOptions::validate`'s).
pub(crate) fn visibility_options(
    o: &envlight_visibility_options,
    function: &str,
) -> Result<VisibilityOptions, Failure> {
    if o.reserved != [0; 4] {
        return Err(Failure::argument(
            function,
            "options.reserved must be zero (start from envlight_visibility_options_default())",
        ));
    }
    let options = VisibilityOptions {
        radius: (o.radius != 0.0).then_some(o.radius),
        normal_bins: o.normal_bins as usize,
        target_entries: o.target_entries,
        memory_budget: o.memory_budget,
        rays_per_patch: o.rays_per_patch as usize,
        refine_rays: o.refine_rays as usize,
        learned_share: o.learned_share,
        prior: o.prior,
        seed: o.seed,
    };
    // The library's message starts with the field's name, which C shares.
    options
        .validate()
        .map_err(|e| Failure::argument(function, format_args!("options.{e}")))?;
    Ok(options)
}

/// The options at `options` (the defaults for NULL).
///
/// # Safety
/// A non-NULL `options` must point to a valid `envlight_visibility_options`.
unsafe fn options_or_default(
    options: *const envlight_visibility_options,
    function: &str,
) -> Result<VisibilityOptions, Failure> {
    if options.is_null() {
        return visibility_options(&envlight_visibility_options_default(), function);
    }
    // SAFETY: forwarded: the caller promises a valid `envlight_visibility_options`
    // at a non-NULL `options`; `deref` rejects a misaligned one.
    visibility_options(unsafe { deref(options, function, "options") }?, function)
}

/// A status other than `ENVLIGHT_OK` returned by the caller's callback.
#[derive(Debug)]
struct CallbackStatus(i32);

impl std::fmt::Display for CallbackStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "it returned status {} (not ENVLIGHT_OK)", self.0)
    }
}

/// The failure of a build: the callback's own failure as
/// `ENVLIGHT_ERROR_CALLBACK`, anything else (a transmittance outside [0, 1], a
/// bad point or normal, an option) as an invalid argument, in the library's words.
fn build_failure(function: &str, e: VisibilityError<CallbackStatus>) -> Failure {
    match e {
        VisibilityError::Trace(_) => Failure::new(
            envlight_status::ENVLIGHT_ERROR_CALLBACK,
            format!("{function}: {e}"),
        ),
        _ => Failure::argument(function, e),
    }
}

/// `*key` as UTF-8, or a failure naming `scene_key`.
fn utf8_key<'a>(key: &'a CStr, function: &str) -> Result<&'a str, Failure> {
    key.to_str()
        .map_err(|_| Failure::argument(function, "scene_key is not UTF-8"))
}

/// Builds a visibility cache over `product` from `count` shading points:
/// `points` and `normals` hold `count · 3` floats each (world frame; normals
/// need not be unit length, but must be finite and non-zero, and the points
/// finite), typically the first hits of the renderer's camera rays. The build
/// asks `trace(user, ...)` for the transmittance of batches of rays (see
/// `envlight_visibility_trace`); `options` NULL means the defaults. `*out` holds
/// the cache on success (NULL on failure).
///
/// Statuses: `ENVLIGHT_ERROR_CALLBACK` when `trace` returns anything but
/// `ENVLIGHT_OK`; `ENVLIGHT_ERROR_INVALID_ARGUMENT` for a NULL argument, an
/// option out of range (`options.FIELD ...`), a point or normal that is not
/// finite or a zero normal (`point i: ...`), or a transmittance the callback
/// wrote that is NaN or outside [0, 1] (naming the ray and the value).
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_build(
    product: *const envlight_product,
    points: *const f32,
    normals: *const f32,
    count: usize,
    options: *const envlight_visibility_options,
    trace: envlight_visibility_trace,
    user: *mut c_void,
    out: *mut *mut envlight_visibility_cache,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_build";
    let build = || {
        // SAFETY: by the C contract `product` is NULL or a product sampler from
        // envlight_product_new not yet freed (only read), `points` and `normals`
        // NULL or `count · 3` floats each and `options` NULL or one
        // `envlight_visibility_options`, all only read during the call; the
        // helpers reject NULL (where data is needed), misaligned and overflowing
        // pointers.
        let (p, points, normals, options) = unsafe {
            (
                deref(product, F, "product")?,
                slice::<f32, 3>(points, count, F, "points")?,
                slice::<f32, 3>(normals, count, F, "normals")?,
                options_or_default(options, F)?,
            )
        };
        let Some(trace) = trace else {
            return Err(Failure::argument(F, "trace is NULL"));
        };
        let call = |origins: &[Vec3], directions: &[Vec3], t: &mut [f32]| {
            let n = origins.len();
            assert!(
                directions.len() == n && t.len() == n,
                "a batch of {n} origins, {} directions and {} transmittances",
                directions.len(),
                t.len()
            );
            // SAFETY: by the C contract `trace` is a function of the
            // `envlight_visibility_trace` type that reads `3n` floats at each of
            // its two inputs and writes `n` floats at its output, and returns
            // without unwinding; `Vec3` is three `f32` (sample.rs asserts its
            // layout), so the input slices hold `3n` floats, and `t` holds `n`
            // writable ones that nothing else accesses during the call. `user` is
            // the caller's own pointer, passed through unread.
            let status = unsafe {
                trace(
                    user,
                    origins.as_ptr().cast::<f32>(),
                    directions.as_ptr().cast::<f32>(),
                    n,
                    t.as_mut_ptr(),
                )
            };
            match status {
                0 => Ok(()),
                status => Err(CallbackStatus(status)),
            }
        };
        let cache = VisibilityCache::build(
            Arc::clone(&p.product),
            as_vec3(points),
            as_vec3(normals),
            &options,
            call,
        )
        .map_err(|e| build_failure(F, e))?;
        Ok(envlight_visibility_cache { cache })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_visibility_cache *` that no other argument overlaps.
    unsafe { new_handle(F, out, build) }
}

/// Frees a visibility cache (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_free(cache: *mut envlight_visibility_cache) {
    // SAFETY: by the C contract a non-NULL `cache` came from
    // envlight_visibility_cache_build or _load (which make an
    // `envlight_visibility_cache`) and is freed once.
    unsafe { free(cache) };
}

/// The library's sampling state at shading point `(point, normal)`: the entry of
/// the two, and the product sampler's cosine factor about `normal`.
#[inline(always)]
fn at(
    cache: &VisibilityCache,
    point: Vec3,
    normal: Vec3,
) -> envlight::visibility::VisibilityPoint<'_> {
    cache.at(point, &Factor::cosine(normal))
}

/// Draws a direction at the shading point `point` with normal `normal` (world
/// frame; any length) for `u` in [0, 1)², from the cache's mixture of its
/// learned distribution and the product sampler's cosine-weighted one (the
/// product sampler alone where the build put no entry). Returns false and zeroes
/// `*out` when nothing lit can be drawn there, `u` is not finite, or an argument
/// is NULL.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_sample(
    cache: *const envlight_visibility_cache,
    point: *const f32,
    normal: *const f32,
    u: *const f32,
    out: *mut envlight_sample,
) -> bool {
    const F: &str = "envlight_visibility_cache_sample";
    let draw = || {
        // SAFETY: by the C contract `cache` is NULL or a visibility cache not yet
        // freed (only read), `point` and `normal` NULL or 3 floats each and `u`
        // NULL or 2; the helpers reject NULL and misaligned pointers.
        let (c, p, n, u) = unsafe {
            (
                deref(cache, F, "cache")?,
                read::<3>(point, F, "point")?,
                read::<3>(normal, F, "normal")?,
                read::<2>(u, F, "u")?,
            )
        };
        Ok(if finite_u(u) {
            at(&c.cache, vec3(p), vec3(n)).sample(u)
        } else {
            None
        })
    };
    // SAFETY: by the C contract `out` is NULL or one writable sample, overlapping
    // no input.
    unsafe { sample_into(F, out, draw) }
}

/// The density (per steradian) with which `envlight_visibility_cache_sample`
/// draws the unit world direction `direction` at `(point, normal)`; 0 for NULL
/// arguments.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_pdf(
    cache: *const envlight_visibility_cache,
    point: *const f32,
    normal: *const f32,
    direction: *const f32,
) -> f32 {
    const F: &str = "envlight_visibility_cache_pdf";
    value(F, 0.0, || {
        // SAFETY: by the C contract `cache` is NULL or a visibility cache not yet
        // freed (only read), and `point`, `normal` and `direction` NULL or 3
        // floats each; the helpers reject NULL and misaligned pointers.
        let (c, p, n, d) = unsafe {
            (
                deref(cache, F, "cache")?,
                read::<3>(point, F, "point")?,
                read::<3>(normal, F, "normal")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        Ok(at(&c.cache, vec3(p), vec3(n)).pdf(vec3(d)))
    })
}

/// `envlight_visibility_cache_sample` for each of `n` shading points:
/// `points[3i..3i+3]`, `normals[3i..3i+3]` and `u[2i], u[2i+1]` give `out[i]`, in
/// parallel; independent of the thread count.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_sample_batch(
    cache: *const envlight_visibility_cache,
    points: *const f32,
    normals: *const f32,
    u: *const f32,
    n: usize,
    out: *mut envlight_sample,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_sample_batch";
    run(F, || {
        // SAFETY: by the C contract `cache` is NULL or a visibility cache not yet
        // freed (only read), and for n > 0 `points` and `normals` hold 3n floats
        // each, `u` 2n floats and `out` n writable samples apart from them; the
        // helpers take nothing for n = 0 and otherwise reject NULL, misaligned and
        // overflowing arrays.
        let (c, points, normals, u, out) = unsafe {
            (
                deref(cache, F, "cache")?,
                slice::<f32, 3>(points, n, F, "points")?,
                slice::<f32, 3>(normals, n, F, "normals")?,
                slice::<f32, 2>(u, n, F, "u")?,
                slice_mut::<envlight_sample, 1>(out, n, F, "out")?,
            )
        };
        let cache = &c.cache;
        let (points, normals) = (as_vec3(points), as_vec3(normals));
        draw_batch_at(out.as_flattened_mut(), u, |range, u, samples| {
            let at_points = points[range.clone()].iter().zip(&normals[range]);
            for ((s, &u), (&p, &n)) in samples.iter_mut().zip(u).zip(at_points) {
                *s = if finite_u(u) {
                    at(cache, p, n).sample(u)
                } else {
                    None
                };
            }
        });
        Ok(())
    })
}

/// `envlight_visibility_cache_pdf` for each of `n` shading points: `points[3i..]`,
/// `normals[3i..]` and the direction `directions[3i..3i+3]` give `pdf[i]`, in
/// parallel (0 for the all-zero direction of a sample that drew none).
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_pdf_batch(
    cache: *const envlight_visibility_cache,
    points: *const f32,
    normals: *const f32,
    directions: *const f32,
    n: usize,
    pdf: *mut f32,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_pdf_batch";
    run(F, || {
        // SAFETY: by the C contract `cache` is NULL or a visibility cache not yet
        // freed (only read), and for n > 0 `points`, `normals` and `directions`
        // hold 3n floats each and `pdf` n writable floats apart from them; the
        // helpers take nothing for n = 0 and otherwise reject NULL, misaligned and
        // overflowing arrays.
        let (c, points, normals, dirs, out) = unsafe {
            (
                deref(cache, F, "cache")?,
                slice::<f32, 3>(points, n, F, "points")?,
                slice::<f32, 3>(normals, n, F, "normals")?,
                slice::<f32, 3>(directions, n, F, "directions")?,
                slice_mut::<f32, 1>(pdf, n, F, "pdf")?,
            )
        };
        let cache = &c.cache;
        out.as_flattened_mut()
            .par_chunks_mut(CHUNK)
            .zip(as_vec3(points).par_chunks(CHUNK))
            .zip(as_vec3(normals).par_chunks(CHUNK))
            .zip(as_vec3(dirs).par_chunks(CHUNK))
            .for_each(|(((out, points), normals), dirs)| {
                for (((o, &p), &n), &d) in out.iter_mut().zip(points).zip(normals).zip(dirs) {
                    *o = at(cache, p, n).pdf(d);
                }
            });
        Ok(())
    })
}

/// Writes the cache to the file `path` with `scene_key` (UTF-8, at most 65536
/// bytes: what says which scene it was learned in, such as a file name and a
/// version or a hash of the geometry). The file is written whole or not at all.
/// `ENVLIGHT_ERROR_IO` (or `_NOT_FOUND` for a missing folder) names the path.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_save(
    cache: *const envlight_visibility_cache,
    path: *const c_char,
    scene_key: *const c_char,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_save";
    run(F, || {
        // SAFETY: by the C contract `cache` is NULL or a visibility cache not yet
        // freed (only read), and `path` and `scene_key` NULL or NUL-terminated
        // strings, unchanged during the call; the helpers reject NULL (and
        // misaligned) pointers.
        let (c, path, key) = unsafe {
            (
                deref(cache, F, "cache")?,
                c_str(path, F, "path")?,
                c_str(scene_key, F, "scene_key")?,
            )
        };
        c.cache.save(&path_of(path), utf8_key(key, F)?)?;
        Ok(())
    })
}

/// Reads a cache saved by `envlight_visibility_cache_save` for `product`'s light
/// in the scene `scene_key`. `*out` holds it on success (NULL on failure).
/// `ENVLIGHT_ERROR_MISMATCH` when the file was made for another light (image,
/// options or patch grid) or another scene key, with a message naming both;
/// `ENVLIGHT_ERROR_NOT_FOUND`, `_IO` or `_FORMAT` (a file that is not a
/// well-formed cache) naming the path.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_load(
    path: *const c_char,
    product: *const envlight_product,
    scene_key: *const c_char,
    out: *mut *mut envlight_visibility_cache,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_load";
    let build = || {
        // SAFETY: by the C contract `path` and `scene_key` are NULL or
        // NUL-terminated strings, unchanged during the call, and `product` NULL or
        // a product sampler not yet freed (only read); the helpers reject NULL
        // (and misaligned) pointers.
        let (path, p, key) = unsafe {
            (
                c_str(path, F, "path")?,
                deref(product, F, "product")?,
                c_str(scene_key, F, "scene_key")?,
            )
        };
        let product = Arc::clone(&p.product);
        let cache = VisibilityCache::load(&path_of(path), product, utf8_key(key, F)?)?;
        Ok(envlight_visibility_cache { cache })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_visibility_cache *` that no other argument overlaps.
    unsafe { new_handle(F, out, build) }
}

/// Fills `*summary` with what the cache holds: entries, bytes, radius, mean
/// visibility and rays.
#[no_mangle]
pub extern "C" fn envlight_visibility_cache_summary(
    cache: *const envlight_visibility_cache,
    summary: *mut envlight_visibility_summary,
) -> envlight_status {
    const F: &str = "envlight_visibility_cache_summary";
    run(F, || {
        // SAFETY: by the C contract `summary` is NULL or one writable
        // `envlight_visibility_summary` and `cache` NULL or a visibility cache
        // not yet freed (only read); `deref_mut` and `deref` reject NULL and
        // misaligned pointers.
        let (summary, c) =
            unsafe { (deref_mut(summary, F, "summary")?, deref(cache, F, "cache")?) };
        let s = c.cache.summary();
        *summary = envlight_visibility_summary {
            entries: s.entries as u64,
            bytes: s.bytes as u64,
            radius: s.radius,
            mean_visibility: s.mean_visibility,
            rays: s.rays,
        };
        Ok(())
    })
}
