//! The light: built from a file or from texels, queried one direction at a time or
//! in parallel batches, described, and freed.

use std::ffi::{c_char, CStr};
use std::sync::Arc;

use envlight::light::{Density, Mapping, Sampler};
use envlight::load::{load, LoadOptions};
use envlight::{EnvImage, EnvironmentLight, LightSample, Lookup, Vec3};

use crate::boundary::{
    c_str, cleared_array, deref, deref_mut, free, new_handle, read, run, slice, slice_mut, value,
    Failure,
};
use crate::envlight_status;
use crate::options::{envlight_light_options, options_or_default};
use crate::sample::{as_vec3, draw_batch, envlight_sample, finite_u, sample_into, vec3};

/// An environment light: an HDR image at infinity and its sampling tables.
/// Opaque; immutable once built, so a `const` pointer serves any number of
/// threads at once. Free it with `envlight_light_free`.
pub struct envlight_light {
    pub(crate) light: Arc<EnvironmentLight>,
}

/// Reads the map at `path` (`.hdr`, `.exr`, `.pfm`, 8-bit `.png`/`.jpg`; the content
/// decides, not the name) and builds a light with `options` (NULL: the defaults).
/// On success `*out` holds a new light to free with `envlight_light_free`; on
/// failure `*out` is set to NULL (when `out` is not NULL) and the status says why:
/// `ENVLIGHT_ERROR_NOT_FOUND`, `_IO`, `_FORMAT`, `_INVALID_IMAGE` (a NaN or
/// infinite texel, named) or `_INVALID_ARGUMENT`.
#[no_mangle]
pub extern "C" fn envlight_light_load(
    path: *const c_char,
    options: *const envlight_light_options,
    out: *mut *mut envlight_light,
) -> envlight_status {
    const F: &str = "envlight_light_load";
    let build = || {
        // SAFETY: by this function's C contract (docs/c-api.md, "Handles, ownership,
        // lifetime"), `path` is NULL or a NUL-terminated string and `options` NULL
        // or an `envlight_light_options`, both live and unchanged for the call; the
        // helpers reject NULL (and misaligned) pointers before reading.
        let (path, options) = unsafe { (c_str(path, F, "path")?, options_or_default(options, F)?) };
        let image = load(&path_of(path), &LoadOptions::default())?.image;
        envlight_light::new(image, options)
    };
    // SAFETY: by the C contract `out` is NULL or points to an `envlight_light *` the
    // call may write, which no other argument overlaps.
    unsafe { new_handle(F, out, build) }
}

impl envlight_light {
    /// The light of `image` with `options`.
    fn new(image: EnvImage, options: envlight::LightOptions) -> Result<Self, Failure> {
        let light = EnvironmentLight::new(image, options)?;
        Ok(Self {
            light: Arc::new(light),
        })
    }
}

/// Runs the body of an entry point that makes a handle from a light: `*out` is set
/// to NULL before anything else can fail, `light` is checked, and `*out` then holds
/// the new handle of what `build` makes of the light (as [`new_handle`]).
///
/// # Safety
/// `out` as for [`new_handle`]; a non-NULL, aligned `light` must be a light from
/// `envlight_light_load` or `envlight_light_from_rgb`, not yet freed, that the
/// call only reads.
pub(crate) unsafe fn new_from_light<T>(
    function: &str,
    light: *const envlight_light,
    out: *mut *mut T,
    build: impl FnOnce(&Arc<EnvironmentLight>) -> Result<T, Failure>,
) -> envlight_status {
    let build = || {
        // SAFETY: forwarded: the caller makes `deref`'s promise for `light`.
        let light = unsafe { deref(light, function, "light") }?;
        build(&light.light)
    };
    // SAFETY: forwarded: the caller makes `new_handle`'s promise for `out`.
    unsafe { new_handle(function, out, build) }
}

/// A C path as a filesystem path (any bytes on Unix).
pub(crate) fn path_of(path: &CStr) -> std::path::PathBuf {
    #[cfg(unix)]
    {
        use std::os::unix::ffi::OsStrExt;
        std::path::PathBuf::from(std::ffi::OsStr::from_bytes(path.to_bytes()))
    }
    #[cfg(not(unix))]
    {
        std::path::PathBuf::from(path.to_string_lossy().into_owned())
    }
}

/// Builds a light from `height` rows of `width` linear RGB texels at `rgb`
/// (`height · width · 3` floats, row 0 at the top (θ = 0), column 0 at φ = 0), with
/// `options` (NULL: the defaults). The texels are copied. Every channel must be
/// finite and >= 0 (`ENVLIGHT_ERROR_INVALID_IMAGE` names the first that is not);
/// a zero or too large size is `ENVLIGHT_ERROR_INVALID_ARGUMENT`. `*out` as for
/// `envlight_light_load`.
#[no_mangle]
pub extern "C" fn envlight_light_from_rgb(
    rgb: *const f32,
    width: u32,
    height: u32,
    options: *const envlight_light_options,
    out: *mut *mut envlight_light,
) -> envlight_status {
    const F: &str = "envlight_light_from_rgb";
    let build = || light_from_rgb(rgb, width, height, options, F);
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_light *` that no other argument overlaps.
    unsafe { new_handle(F, out, build) }
}

/// The body of [`envlight_light_from_rgb`].
fn light_from_rgb(
    rgb: *const f32,
    width: u32,
    height: u32,
    options: *const envlight_light_options,
    function: &str,
) -> Result<envlight_light, Failure> {
    if width == 0 || height == 0 {
        return Err(Failure::argument(
            function,
            format_args!("width and height must be positive, not {width}x{height}"),
        ));
    }
    let (w, h) = (width as usize, height as usize);
    let n = w.checked_mul(h).ok_or_else(|| {
        Failure::argument(function, format_args!("{width}x{height} is too large"))
    })?;
    if n > envlight::load::DEFAULT_MAX_TEXELS {
        return Err(Failure::argument(
            function,
            format_args!(
                "{width}x{height} texels is too large (limit {} texels)",
                envlight::load::DEFAULT_MAX_TEXELS
            ),
        ));
    }
    // SAFETY: by envlight_light_from_rgb's C contract `rgb` is NULL or holds
    // `height · width · 3` floats (`n` texels of 3; `n > 0` here) and `options` is
    // NULL or an `envlight_light_options`, both only read during the call; `slice`
    // rejects a NULL or misaligned `rgb` and a size past `isize::MAX` bytes.
    let (texels, options) = unsafe {
        (
            slice::<f32, 3>(rgb, n, function, "rgb")?,
            options_or_default(options, function)?,
        )
    };
    if let Some(k) = texels.iter().flatten().position(|&c| c < 0.0) {
        let (texel, channel) = (k / 3, ['R', 'G', 'B'][k % 3]);
        return Err(Failure::new(
            envlight_status::ENVLIGHT_ERROR_INVALID_IMAGE,
            format!(
                "rgb: texel ({}, {}) has a negative value ({}) in channel {channel}",
                texel % w,
                texel / w,
                texels[texel][k % 3]
            ),
        ));
    }
    let (image, _) = EnvImage::from_raw("rgb", w, h, texels.to_vec(), false)?;
    envlight_light::new(image, options)
}

/// Frees a light (NULL: nothing). Handles built from it (product samplers,
/// portal lights, sun extractions, GPU tables) keep what they need and stay
/// valid.
#[no_mangle]
pub extern "C" fn envlight_light_free(light: *mut envlight_light) {
    // SAFETY: by the C contract a non-NULL `light` came from envlight_light_load or
    // envlight_light_from_rgb (both make an `envlight_light`) and is freed once.
    unsafe { free(light) };
}

/// Draws a direction for `u` in [0, 1)², with density proportional to the map's
/// luminance (times the mapping's area factor). Writes `*out` and returns true;
/// returns false and zeroes `*out` when there is no direction (a black map, a
/// point on a pole of a lat-long map, a non-finite `u`) or an argument is NULL.
#[no_mangle]
pub extern "C" fn envlight_light_sample(
    light: *const envlight_light,
    u: *const f32,
    out: *mut envlight_sample,
) -> bool {
    const F: &str = "envlight_light_sample";
    let draw = || {
        // SAFETY: by the C contract `light` is NULL or a light from
        // envlight_light_load/_from_rgb not yet freed (only read, so other threads
        // may share it), and `u` NULL or 2 floats; the helpers reject NULL and
        // misaligned pointers.
        let (light, u) = unsafe { (deref(light, F, "light")?, read::<2>(u, F, "u")?) };
        Ok(sample_checked(&light.light, u))
    };
    // SAFETY: by the C contract `out` is NULL or one writable sample, overlapping
    // neither input.
    unsafe { sample_into(F, out, draw) }
}

/// The light's sample at `u`, none for a non-finite `u`.
#[inline(always)]
fn sample_checked(light: &EnvironmentLight, u: [f32; 2]) -> Option<LightSample> {
    if finite_u(u) {
        light.sample(u)
    } else {
        None
    }
}

/// The solid-angle density (per steradian) with which `envlight_light_sample`
/// draws the unit world direction `direction`: 0 where the light is black, at a
/// pole of a lat-long map, for a non-finite or zero direction, and for NULL
/// arguments.
#[no_mangle]
pub extern "C" fn envlight_light_pdf(light: *const envlight_light, direction: *const f32) -> f32 {
    const F: &str = "envlight_light_pdf";
    value(F, 0.0, || {
        // SAFETY: by the C contract `light` is NULL or a live light (only read) and
        // `direction` NULL or 3 floats; `deref` and `read` reject NULL and
        // misaligned pointers.
        let (light, d) = unsafe {
            (
                deref(light, F, "light")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        Ok(light.light.pdf(vec3(d)))
    })
}

/// The radiance arriving from the unit world direction `direction` (linear RGB,
/// scale applied), written to `rgb`; zeros for NULL `light` or `direction`.
#[no_mangle]
pub extern "C" fn envlight_light_radiance(
    light: *const envlight_light,
    direction: *const f32,
    rgb: *mut f32,
) {
    const F: &str = "envlight_light_radiance";
    value(F, (), || {
        // SAFETY: by the C contract `rgb` is NULL or 3 writable floats apart from
        // `direction`, which is NULL or 3 floats, and `light` is NULL or a live
        // light (only read); the helpers reject NULL and misaligned pointers.
        let (rgb, light, d) = unsafe {
            (
                cleared_array::<3>(rgb, F, "rgb")?,
                deref(light, F, "light")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        *rgb = light.light.radiance(vec3(d));
        Ok(())
    })
}

/// `envlight_light_sample` for each of the `n` points `u[2i], u[2i+1]`, written to
/// `out[i]` (a zeroed sample where there is no direction), in parallel on the
/// library's thread pool. The results do not depend on the thread count.
/// `u` and `out` may be NULL when `n` is 0.
#[no_mangle]
pub extern "C" fn envlight_light_sample_batch(
    light: *const envlight_light,
    u: *const f32,
    n: usize,
    out: *mut envlight_sample,
) -> envlight_status {
    const F: &str = "envlight_light_sample_batch";
    run(F, || {
        // SAFETY: by the C contract `light` is NULL or a live light (only read),
        // and for n > 0 `u` holds 2n floats and `out` n writable samples, the two
        // apart; `slice` and `slice_mut` take nothing for n = 0 and otherwise
        // reject NULL, misaligned and overflowing arrays.
        let (light, u, out) = unsafe {
            (
                deref(light, F, "light")?,
                slice::<f32, 2>(u, n, F, "u")?,
                slice_mut::<envlight_sample, 1>(out, n, F, "out")?,
            )
        };
        let out = out.as_flattened_mut();
        let light = &light.light;
        if u.iter().all(|&u| finite_u(u)) {
            draw_batch(out, |range, samples| light.sample_batch(&u[range], samples));
        } else {
            draw_batch(out, |range, samples| {
                for (s, &u) in samples.iter_mut().zip(&u[range]) {
                    *s = sample_checked(light, u);
                }
            });
        }
        Ok(())
    })
}

/// `envlight_light_pdf` of each of the `n` directions at `directions` (`3n`
/// floats), written to `pdf[i]`, in parallel.
#[no_mangle]
pub extern "C" fn envlight_light_pdf_batch(
    light: *const envlight_light,
    directions: *const f32,
    n: usize,
    pdf: *mut f32,
) -> envlight_status {
    let query = |light: &EnvironmentLight, dirs: &[Vec3], pdf: &mut [[f32; 1]]| {
        light.pdf_batch(dirs, pdf.as_flattened_mut());
    };
    // SAFETY: by the C contract `light` is NULL or a live light (only read), and
    // for n > 0 `directions` holds 3n floats and `pdf` n writable floats, the two
    // apart.
    unsafe {
        by_direction(
            "envlight_light_pdf_batch",
            light,
            directions,
            n,
            pdf,
            "pdf",
            query,
        )
    }
}

/// `envlight_light_radiance` of each of the `n` directions at `directions`,
/// written to `rgb[3i..3i+3]`, in parallel.
#[no_mangle]
pub extern "C" fn envlight_light_radiance_batch(
    light: *const envlight_light,
    directions: *const f32,
    n: usize,
    rgb: *mut f32,
) -> envlight_status {
    let query = |light: &EnvironmentLight, dirs: &[Vec3], rgb: &mut [[f32; 3]]| {
        light.radiance_batch(dirs, rgb);
    };
    // SAFETY: by the C contract `light` is NULL or a live light (only read), and
    // for n > 0 `directions` holds 3n floats and `rgb` 3n writable floats, the two
    // apart.
    unsafe {
        by_direction(
            "envlight_light_radiance_batch",
            light,
            directions,
            n,
            rgb,
            "rgb",
            query,
        )
    }
}

/// Runs the body of a batch query by direction: `light`, the `n` directions at
/// `directions` (3n floats) and the output, `n` groups of `K` floats at `out`
/// (named `out_name`), are checked in that order, then `query` fills them in.
///
/// # Safety
/// A non-NULL, aligned `light` must be a live light, only read; for `n > 0`, a
/// non-NULL, aligned `directions` must hold `3n` floats and `out` `Kn` writable
/// floats apart from them.
unsafe fn by_direction<const K: usize>(
    function: &str,
    light: *const envlight_light,
    directions: *const f32,
    n: usize,
    out: *mut f32,
    out_name: &str,
    query: impl FnOnce(&EnvironmentLight, &[Vec3], &mut [[f32; K]]),
) -> envlight_status {
    run(function, || {
        // SAFETY: forwarded: the caller makes the helpers' promises for `light`,
        // `directions` and `out`; they take nothing for n = 0 and otherwise reject
        // NULL, misaligned and overflowing arrays.
        let (light, dirs, out) = unsafe {
            (
                deref(light, function, "light")?,
                slice::<f32, 3>(directions, n, function, "directions")?,
                slice_mut::<f32, K>(out, n, function, out_name)?,
            )
        };
        query(&light.light, as_vec3(dirs), out);
        Ok(())
    })
}

/// The point `u` that `envlight_light_sample` maps to the unit world direction
/// `direction` (the inverse of sampling, up to float rounding), written to `u`;
/// false (and `u` zeroed) for the alias sampler, which has no inverse, and for NULL
/// arguments.
#[no_mangle]
pub extern "C" fn envlight_light_invert(
    light: *const envlight_light,
    direction: *const f32,
    u: *mut f32,
) -> bool {
    const F: &str = "envlight_light_invert";
    value(F, false, || {
        // SAFETY: by the C contract `u` is NULL or 2 writable floats apart from
        // `direction`, which is NULL or 3 floats, and `light` is NULL or a live
        // light (only read); the helpers reject NULL and misaligned pointers.
        let (u, light, d) = unsafe {
            (
                cleared_array::<2>(u, F, "u")?,
                deref(light, F, "light")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        match light.light.invert(vec3(d)) {
            Some(x) => {
                *u = x;
                Ok(true)
            }
            None => Ok(false),
        }
    })
}

/// What a light is: sizes, integrals, the brightest direction, memory.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_light_info {
    /// Width of the light's image in texels (after resampling to the equal-area
    /// square, when asked).
    pub width: u32,
    /// Height of the light's image in texels.
    pub height: u32,
    /// Width of the sampling table in cells.
    pub table_width: u32,
    /// Height of the sampling table in cells.
    pub table_height: u32,
    /// The options' `envlight_sampler`, `envlight_density`, `envlight_mapping` and
    /// `envlight_lookup`, in that order.
    pub sampler: u32,
    /// See `sampler`.
    pub density: u32,
    /// See `sampler`.
    pub mapping: u32,
    /// See `sampler`.
    pub lookup: u32,
    /// `∫ R dω, ∫ G dω, ∫ B dω` over the sphere (scale applied).
    pub integral_rgb: [f64; 3],
    /// `∫ Y dω` over the sphere (scale applied).
    pub integral_luminance: f64,
    /// The brightest texel's luminance (scale applied).
    pub max_luminance: f32,
    /// The world direction of the brightest texel's centre.
    pub brightest_direction: [f32; 3],
    /// Bytes of sampling tables (the image not counted).
    pub sampling_bytes: u64,
    /// Non-zero when the map is black: no direction can be drawn.
    pub black: u32,
}

/// Fills `*info` with what `light` is (cheap: nothing is integrated here; see
/// `envlight_light_efficiency`).
#[no_mangle]
pub extern "C" fn envlight_light_get_info(
    light: *const envlight_light,
    info: *mut envlight_light_info,
) -> envlight_status {
    const F: &str = "envlight_light_get_info";
    run(F, || {
        // SAFETY: by the C contract `info` is NULL or one writable
        // `envlight_light_info` and `light` NULL or a live light (only read);
        // `deref_mut` and `deref` reject NULL and misaligned pointers.
        let (info, light) = unsafe { (deref_mut(info, F, "info")?, deref(light, F, "light")?) };
        let light = &light.light;
        let options = light.options();
        let code =
            |all: &[&str], name: &str| all.iter().position(|&n| n == name).unwrap_or(0) as u32;
        let [tw, th] = light.table_size();
        let (max_luminance, brightest) = light.brightest();
        *info = envlight_light_info {
            width: light.image().width() as u32,
            height: light.image().height() as u32,
            table_width: tw as u32,
            table_height: th as u32,
            sampler: code(&Sampler::ALL.map(Sampler::name), options.sampler.name()),
            density: code(&Density::ALL.map(Density::name), options.density.name()),
            mapping: code(&Mapping::ALL.map(Mapping::name), options.mapping.name()),
            lookup: match options.lookup {
                Lookup::Bilinear => 0,
                Lookup::Nearest => 1,
                Lookup::Node => 2,
            },
            integral_rgb: light.integral_rgb(),
            integral_luminance: light.integral_luminance(),
            max_luminance,
            brightest_direction: brightest.to_array(),
            sampling_bytes: light.sampling_bytes() as u64,
            black: light.is_black() as u32,
        };
        Ok(())
    })
}

/// The light's sampling efficiency `(∫ Y dω)² / ∫ (Y² / p) dω`, integrated by
/// quadrature over the map (1 when the pdf is proportional to luminance; about
/// as costly as building the light). 0 for a black map or a NULL `light`.
#[no_mangle]
pub extern "C" fn envlight_light_efficiency(light: *const envlight_light) -> f64 {
    const F: &str = "envlight_light_efficiency";
    value(F, 0.0, || {
        // SAFETY: by the C contract `light` is NULL or a light from
        // envlight_light_load/_from_rgb not yet freed, only read here; `deref`
        // rejects NULL and misaligned pointers.
        let light = &unsafe { deref(light, F, "light") }?.light;
        Ok(if light.is_black() {
            0.0
        } else {
            light.efficiency()
        })
    })
}
