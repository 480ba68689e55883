//! The C API of envlight: `libenvlight` and its header `envlight.h`.
//!
//! Every function here is `extern "C"` over the Rust library, with the same
//! numbers bit for bit: a sample, pdf or radiance through this API is the one
//! [`envlight::EnvironmentLight`] returns for the same `u` or direction. The
//! header is generated from this crate by cbindgen (`include/envlight.h`, checked
//! by `tests/header.rs`); `include/envlight.hpp` wraps it for C++17;
//! `docs/c-api.md` is the reference.
//!
//! The boundary's rules, kept by every entry point:
//! - pointers are checked: a NULL (or misaligned) pointer where data is needed is
//!   [`envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT`] naming the argument, or
//!   `false`/0 from a value-returning call, never a read through it;
//! - nothing unwinds into the host: a panic is caught and becomes
//!   [`envlight_status::ENVLIGHT_ERROR_INTERNAL`] (or `false`/0);
//! - every failure leaves a one-line message for [`envlight_last_error`] on the
//!   calling thread, in the CLI's words (the file, the texel, the argument);
//! - handles are immutable once built, so a `const` handle serves any number of
//!   threads at once.
//!
//! The calls, from Rust for the example (a C program makes the same ones through
//! `envlight.h`; `docs/c-api.md` has C and C++ examples):
//!
//! ```
//! use envlight_c::*;
//!
//! let rgb = [1.0f32, 1.0, 1.0, 2.0, 2.0, 2.0]; // a 2 x 1 map
//! let mut light = std::ptr::null_mut();
//! let status = envlight_light_from_rgb(rgb.as_ptr(), 2, 1, std::ptr::null(), &mut light);
//! assert_eq!(status, envlight_status::ENVLIGHT_OK);
//! let mut s = envlight_sample::default();
//! assert!(envlight_light_sample(light, [0.25f32, 0.75].as_ptr(), &mut s));
//! assert_eq!(envlight_light_pdf(light, s.direction.as_ptr()), s.pdf);
//! envlight_light_free(light);
//!
//! // A bad argument is a status and a message, never a crash.
//! let status = envlight_light_from_rgb(std::ptr::null(), 2, 1, std::ptr::null(), &mut light);
//! assert_eq!(status, envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT);
//! let mut message = [0u8; 256];
//! let n = envlight_last_error(message.as_mut_ptr().cast(), message.len());
//! assert!(n > 0);
//! ```
#![allow(non_camel_case_types)]
// Every extern function takes raw pointers from C and checks them before use; its
// safety contract is the C documentation (docs/c-api.md), not a Rust `unsafe fn`.
#![allow(clippy::not_unsafe_ptr_arg_deref)]
#![warn(missing_docs)]

use std::cell::RefCell;
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;

use envlight::light::{Density, Mapping, Sampler};
use envlight::load::{load, LoadOptions};
use envlight::{EnvImage, EnvironmentLight, LightOptions, LightSample, Lookup, Rotation, Vec3};
use rayon::prelude::*;

mod gpu;
mod portal;
mod product;
mod sun;

pub use gpu::*;
pub use portal::*;
pub use product::*;
pub use sun::*;

/// The major version of the library this header belongs to.
pub const ENVLIGHT_VERSION_MAJOR: u32 = 0;
/// The minor version of the library this header belongs to.
pub const ENVLIGHT_VERSION_MINOR: u32 = 1;
/// The patch version of the library this header belongs to.
pub const ENVLIGHT_VERSION_PATCH: u32 = 0;

/// What a call that can fail returns. Every failure also leaves a message for
/// `envlight_last_error` on the calling thread.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_status {
    /// Success.
    ENVLIGHT_OK = 0,
    /// A NULL or misaligned pointer, a size of 0 or one too large, an option out
    /// of range, or inputs that do not go together. The message names the argument.
    ENVLIGHT_ERROR_INVALID_ARGUMENT = 1,
    /// The file does not exist.
    ENVLIGHT_ERROR_NOT_FOUND = 2,
    /// The file exists but could not be read.
    ENVLIGHT_ERROR_IO = 3,
    /// The file is in no format envlight reads, or cannot be decoded (truncated,
    /// corrupt, an unsupported feature).
    ENVLIGHT_ERROR_FORMAT = 4,
    /// The image cannot be lit: a texel that is NaN, infinite or negative, or
    /// dimensions beyond the library's limits. The message names the texel.
    ENVLIGHT_ERROR_INVALID_IMAGE = 5,
    /// A combination of options a feature does not implement (the hierarchical
    /// sampler exported as GPU tables, a texel too large for 16-bit radiance).
    ENVLIGHT_ERROR_UNSUPPORTED = 6,
    /// A bug in envlight, caught at the boundary (a Rust panic). The message says
    /// where; please report it.
    ENVLIGHT_ERROR_INTERNAL = 7,
}

/// How directions are drawn from the density (`envlight_light_options.sampler`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_sampler {
    /// CDF inversion (the default): stratification kept, invertible.
    ENVLIGHT_SAMPLER_INVERSION = 0,
    /// Vose's alias table: O(1) per sample, no stratification, no inverse.
    ENVLIGHT_SAMPLER_ALIAS = 1,
    /// Hierarchical warping down a pyramid of sums.
    ENVLIGHT_SAMPLER_HIERARCHICAL = 2,
}

/// The shape of the sampling density (`envlight_light_options.density`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_density {
    /// Constant over each texel: the smallest and cheapest, and the only density
    /// of the alias and hierarchical samplers and of a reduced table
    /// (`table_width`).
    ENVLIGHT_DENSITY_PIECEWISE_CONSTANT = 0,
    /// Bilinear between texel centres (inversion sampler only; the default of
    /// `envlight_light_options_default`): follows the bilinear lookup.
    ENVLIGHT_DENSITY_PIECEWISE_BILINEAR = 1,
}

/// How image points map to directions (`envlight_light_options.mapping`,
/// `input_mapping`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_mapping {
    /// Latitude-longitude: `θ = π v` from +z, `φ = 2π u` from +x towards +y.
    ENVLIGHT_MAPPING_EQUIRECTANGULAR = 0,
    /// The equal-area octahedral square.
    ENVLIGHT_MAPPING_EQUAL_AREA = 1,
}

/// How radiance between texel centres is reconstructed
/// (`envlight_light_options.lookup`).
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_lookup {
    /// Bilinear between the four nearest texel centres (the default).
    ENVLIGHT_LOOKUP_BILINEAR = 0,
    /// The texel that contains the point.
    ENVLIGHT_LOOKUP_NEAREST = 1,
    /// Bilinear with the rows as nodes from pole to pole (row j at v = j/(h-1)),
    /// as Mitsuba 3's envmap reads a map (equirectangular; the piecewise-bilinear
    /// density puts its nodes on those rows).
    ENVLIGHT_LOOKUP_NODE = 2,
}

/// How a light is built. Start from `envlight_light_options_default()` and change
/// fields; the enumerated fields hold the values of `envlight_sampler`,
/// `envlight_density`, `envlight_mapping` and `envlight_lookup`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct envlight_light_options {
    /// An `envlight_sampler`.
    pub sampler: u32,
    /// An `envlight_density`.
    pub density: u32,
    /// An `envlight_mapping`: the parameterization the light samples in. A
    /// lat-long input lit with `ENVLIGHT_MAPPING_EQUAL_AREA` is resampled.
    pub mapping: u32,
    /// An `envlight_mapping`: what the input image is (a 2:1 lat-long map, or an
    /// equal-area square as PBRT-v4 writes them).
    pub input_mapping: u32,
    /// An `envlight_lookup`.
    pub lookup: u32,
    /// Rotation of the map about +z, in degrees (finite).
    pub rotate_deg: f32,
    /// Light-to-world rotation as matrix rows, applied after `rotate_deg`; all
    /// zeros (the default) means none. Must be orthonormal with determinant 1.
    pub rotation: [[f32; 3]; 3],
    /// Multiplies every radiance value, not the density (finite, >= 0).
    pub scale: f32,
    /// Width of the sampling table in cells; 0 (the default) gives one cell per
    /// texel. Must divide the image's width, and the reduction its height.
    pub table_width: u32,
    /// Side of the square a lat-long input is resampled to for the equal-area
    /// mapping; 0 keeps about the input's texel count.
    pub equal_area_size: u32,
    /// Non-zero: MIS compensation (sample `max(0, Y - mean)`); the light alone then
    /// no longer covers the sphere; use it only inside MIS.
    pub mis_compensation: u32,
    /// Must be zero: room for options added later without changing this struct's size.
    pub reserved: [u32; 4],
}

/// A direction drawn from a light, with its solid-angle density (per steradian)
/// and the radiance arriving from it (linear RGB, scale applied). A call that
/// draws no direction leaves every field 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_sample {
    /// Unit direction towards the light, world frame, z up.
    pub direction: [f32; 3],
    /// Solid-angle density of `direction`, per steradian: > 0 and finite, or 0
    /// when no direction was drawn.
    pub pdf: f32,
    /// Radiance arriving from `direction`.
    pub radiance: [f32; 3],
}

/// An environment light: an HDR image at infinity and its sampling tables.
/// Opaque; immutable once built, so a `const` pointer serves any number of
/// threads at once. Free it with `envlight_light_free`.
pub struct envlight_light {
    pub(crate) light: Arc<EnvironmentLight>,
}

// ---------------------------------------------------------------------------
// Errors: the thread's last message, and the boundary's guards.
// ---------------------------------------------------------------------------

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
}

/// A failure on its way to the caller: the status and the message.
#[derive(Debug)]
pub(crate) struct Failure {
    status: envlight_status,
    message: String,
}

impl Failure {
    /// An invalid argument of the function `function`.
    pub(crate) fn argument(function: &str, message: impl std::fmt::Display) -> Self {
        Self {
            status: envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT,
            message: format!("{function}: {message}"),
        }
    }
}

impl From<envlight::Error> for Failure {
    fn from(e: envlight::Error) -> Self {
        use envlight::Error as E;
        use envlight_status::*;
        let status = match &e {
            E::Io { error, .. } if error.kind() == std::io::ErrorKind::NotFound => {
                ENVLIGHT_ERROR_NOT_FOUND
            }
            E::Io { .. } => ENVLIGHT_ERROR_IO,
            E::UnsupportedFormat { .. } | E::Decode { .. } => ENVLIGHT_ERROR_FORMAT,
            E::NonFiniteTexel { .. } | E::TooLarge { .. } | E::InvalidDimensions { .. } => {
                ENVLIGHT_ERROR_INVALID_IMAGE
            }
            E::InvalidOption(_) => ENVLIGHT_ERROR_INVALID_ARGUMENT,
            E::Unsupported(_) | E::HalfOverflow { .. } => ENVLIGHT_ERROR_UNSUPPORTED,
            _ => ENVLIGHT_ERROR_INTERNAL,
        };
        Self {
            status,
            message: e.to_string(),
        }
    }
}

/// Records `message` as this thread's last error.
pub(crate) fn set_last_error(message: String) {
    // One line, as the CLI prints it.
    let message = message.replace(['\n', '\r'], " ");
    LAST_ERROR.with(|e| *e.borrow_mut() = message);
}

/// The text of a caught panic's payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("a panic without a message")
}

/// Runs the body of a status-returning entry point: its failure or panic becomes
/// a status and the thread's last error.
pub(crate) fn run(function: &str, body: impl FnOnce() -> Result<(), Failure>) -> envlight_status {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(())) => envlight_status::ENVLIGHT_OK,
        Ok(Err(f)) => {
            set_last_error(f.message);
            f.status
        }
        Err(payload) => {
            set_last_error(format!(
                "{function}: internal error: {}",
                panic_message(payload.as_ref())
            ));
            envlight_status::ENVLIGHT_ERROR_INTERNAL
        }
    }
}

/// Runs the body of a value-returning entry point: a failure or panic gives
/// `fallback` and sets the thread's last error.
pub(crate) fn value<T>(
    function: &str,
    fallback: T,
    body: impl FnOnce() -> Result<T, Failure>,
) -> T {
    match catch_unwind(AssertUnwindSafe(body)) {
        Ok(Ok(v)) => v,
        Ok(Err(f)) => {
            set_last_error(f.message);
            fallback
        }
        Err(payload) => {
            set_last_error(format!(
                "{function}: internal error: {}",
                panic_message(payload.as_ref())
            ));
            fallback
        }
    }
}

/// `*p`, or an invalid-argument failure naming `name` when `p` is NULL or
/// misaligned.
///
/// # Safety
/// A non-NULL, aligned `p` must point to a valid `T` for `'a`.
pub(crate) unsafe fn deref<'a, T>(
    p: *const T,
    function: &str,
    name: &str,
) -> Result<&'a T, Failure> {
    if p.is_null() {
        return Err(Failure::argument(function, format_args!("{name} is NULL")));
    }
    if !p.is_aligned() {
        return Err(Failure::argument(
            function,
            format_args!("{name} is misaligned"),
        ));
    }
    Ok(unsafe { &*p })
}

/// `&mut *p`, checked as [`deref`].
///
/// # Safety
/// A non-NULL, aligned `p` must point to a valid, unaliased `T` for `'a`.
pub(crate) unsafe fn deref_mut<'a, T>(
    p: *mut T,
    function: &str,
    name: &str,
) -> Result<&'a mut T, Failure> {
    unsafe { deref(p, function, name) }?;
    Ok(unsafe { &mut *p })
}

/// The `K` floats at `p`, or a failure naming `name` (a NULL or misaligned `p`).
///
/// # Safety
/// A non-NULL, aligned `p` must point to `K` valid floats.
pub(crate) unsafe fn read<const K: usize>(
    p: *const f32,
    function: &str,
    name: &str,
) -> Result<[f32; K], Failure> {
    Ok(unsafe { slice::<f32, K>(p, 1, function, name) }?[0])
}

/// The `K` floats at `p`, to write, checked as [`read`].
///
/// # Safety
/// A non-NULL, aligned `p` must point to `K` writable, unaliased floats.
pub(crate) unsafe fn write_array<'a, const K: usize>(
    p: *mut f32,
    function: &str,
    name: &str,
) -> Result<&'a mut [f32; K], Failure> {
    Ok(&mut unsafe { slice_mut::<f32, K>(p, 1, function, name) }?[0])
}

/// The `n · k` values of `T` at `p`, viewed as `n` groups of `K` (`k == K`):
/// empty for `n == 0` whatever `p` is; a failure naming `name` for a NULL or
/// misaligned `p` or a length that overflows.
///
/// # Safety
/// For `n > 0`, a non-NULL, aligned `p` must point to `n · K` valid `T` for `'a`.
pub(crate) unsafe fn slice<'a, T, const K: usize>(
    p: *const T,
    n: usize,
    function: &str,
    name: &str,
) -> Result<&'a [[T; K]], Failure> {
    if n == 0 {
        return Ok(&[]);
    }
    check_array::<T, K>(p, n, function, name)?;
    // SAFETY: checked non-NULL and aligned; `[T; K]` has the layout of K
    // consecutive `T`; the caller promises `n · K` values.
    Ok(unsafe { std::slice::from_raw_parts(p.cast::<[T; K]>(), n) })
}

/// [`slice`], mutable.
///
/// # Safety
/// As [`slice`], and the memory must not be aliased for `'a`.
pub(crate) unsafe fn slice_mut<'a, T, const K: usize>(
    p: *mut T,
    n: usize,
    function: &str,
    name: &str,
) -> Result<&'a mut [[T; K]], Failure> {
    if n == 0 {
        return Ok(&mut []);
    }
    check_array::<T, K>(p, n, function, name)?;
    // SAFETY: as in `slice`.
    Ok(unsafe { std::slice::from_raw_parts_mut(p.cast::<[T; K]>(), n) })
}

/// The checks of [`slice`] for a non-empty array.
fn check_array<T, const K: usize>(
    p: *const T,
    n: usize,
    function: &str,
    name: &str,
) -> Result<(), Failure> {
    if p.is_null() {
        return Err(Failure::argument(
            function,
            format_args!("{name} is NULL (n = {n})"),
        ));
    }
    if !p.is_aligned() {
        return Err(Failure::argument(
            function,
            format_args!("{name} is misaligned"),
        ));
    }
    let fits = n
        .checked_mul(K * std::mem::size_of::<T>())
        .is_some_and(|bytes| bytes <= isize::MAX as usize);
    if !fits {
        return Err(Failure::argument(
            function,
            format_args!("n = {n} is too large"),
        ));
    }
    Ok(())
}

/// `[f32; 3]` as a [`Vec3`].
#[inline(always)]
pub(crate) fn vec3(v: [f32; 3]) -> Vec3 {
    Vec3::new(v[0], v[1], v[2])
}

/// Directions given as `n` triples, viewed as [`Vec3`] without copying.
#[inline(always)]
pub(crate) fn as_vec3(v: &[[f32; 3]]) -> &[Vec3] {
    // SAFETY: `Vec3` is `repr(C)` over three `f32`, like `[f32; 3]`.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<Vec3>(), v.len()) }
}

/// The C form of a sample; a missing one is all zeros.
#[inline(always)]
pub(crate) fn to_c(s: Option<LightSample>) -> envlight_sample {
    match s {
        Some(s) => envlight_sample {
            direction: s.direction.to_array(),
            pdf: s.pdf,
            radiance: s.radiance,
        },
        None => envlight_sample::default(),
    }
}

/// Whether a point `u` can be sampled: both coordinates finite.
#[inline(always)]
pub(crate) fn finite_u(u: [f32; 2]) -> bool {
    u[0].is_finite() && u[1].is_finite()
}

/// No direction for the samples drawn at non-finite points (the single calls
/// draw none there either).
#[inline(always)]
pub(crate) fn drop_non_finite(samples: &mut [Option<LightSample>], u: &[[f32; 2]]) {
    for (s, &u) in samples.iter_mut().zip(u) {
        if !finite_u(u) {
            *s = None;
        }
    }
}

/// Samples per parallel task when the library's samples are converted to C's.
const CHUNK: usize = 1 << 12;

/// Fills `out` from `draw` (the library's batch form: an index range and its
/// output slice), a chunk at a time in parallel, converting to C's layout.
pub(crate) fn draw_batch(
    out: &mut [envlight_sample],
    draw: impl Fn(std::ops::Range<usize>, &mut [Option<LightSample>]) + Sync,
) {
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each_init(Vec::new, |samples, (c, out)| {
            let start = c * CHUNK;
            samples.clear();
            samples.resize(out.len(), None);
            draw(start..start + out.len(), samples);
            for (o, s) in out.iter_mut().zip(samples.iter()) {
                *o = to_c(*s);
            }
        });
}

// ---------------------------------------------------------------------------
// Version and errors.
// ---------------------------------------------------------------------------

/// The library's version, `"MAJOR.MINOR.PATCH"` (static storage; never NULL).
#[no_mangle]
pub extern "C" fn envlight_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// Copies this thread's last error message into `buf` (at most `len - 1` bytes and
/// a terminating NUL; nothing when `buf` is NULL or `len` is 0) and returns the
/// message's length in bytes, without the NUL, like `snprintf`: a buffer of the
/// returned length + 1 holds it whole. The message is set by every failing call on
/// this thread and kept until the next failure; "" before any.
#[no_mangle]
pub extern "C" fn envlight_last_error(buf: *mut c_char, len: usize) -> usize {
    catch_unwind(|| {
        LAST_ERROR.with(|e| {
            let message = e.borrow();
            let bytes = message.as_bytes();
            if !buf.is_null() && len > 0 {
                let n = bytes.len().min(len - 1);
                // SAFETY: the caller gives `len` writable bytes at `buf`.
                unsafe {
                    std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf.cast::<u8>(), n);
                    *buf.add(n) = 0;
                }
            }
            bytes.len()
        })
    })
    .unwrap_or(0)
}

/// A short static name for a status (`"ENVLIGHT_OK"`, ...; `"unknown status"` for
/// a value that is none).
#[no_mangle]
pub extern "C" fn envlight_status_name(status: u32) -> *const c_char {
    let name: &'static str = match status {
        0 => "ENVLIGHT_OK\0",
        1 => "ENVLIGHT_ERROR_INVALID_ARGUMENT\0",
        2 => "ENVLIGHT_ERROR_NOT_FOUND\0",
        3 => "ENVLIGHT_ERROR_IO\0",
        4 => "ENVLIGHT_ERROR_FORMAT\0",
        5 => "ENVLIGHT_ERROR_INVALID_IMAGE\0",
        6 => "ENVLIGHT_ERROR_UNSUPPORTED\0",
        7 => "ENVLIGHT_ERROR_INTERNAL\0",
        _ => "unknown status\0",
    };
    name.as_ptr().cast()
}

// ---------------------------------------------------------------------------
// Building a light.
// ---------------------------------------------------------------------------

/// The default options: inversion sampler, piecewise-bilinear density,
/// equirectangular mapping and input, bilinear lookup, no rotation, scale 1, one
/// table cell per texel. With the alias or hierarchical sampler or a
/// `table_width`, set the density to `ENVLIGHT_DENSITY_PIECEWISE_CONSTANT` too.
#[no_mangle]
pub extern "C" fn envlight_light_options_default() -> envlight_light_options {
    envlight_light_options {
        sampler: envlight_sampler::ENVLIGHT_SAMPLER_INVERSION as u32,
        density: envlight_density::ENVLIGHT_DENSITY_PIECEWISE_BILINEAR as u32,
        mapping: envlight_mapping::ENVLIGHT_MAPPING_EQUIRECTANGULAR as u32,
        input_mapping: envlight_mapping::ENVLIGHT_MAPPING_EQUIRECTANGULAR as u32,
        lookup: envlight_lookup::ENVLIGHT_LOOKUP_BILINEAR as u32,
        rotate_deg: 0.0,
        rotation: [[0.0; 3]; 3],
        scale: 1.0,
        table_width: 0,
        equal_area_size: 0,
        mis_compensation: 0,
        reserved: [0; 4],
    }
}

/// The library's options from C's, or an invalid-argument failure naming the field.
fn light_options(o: &envlight_light_options, function: &str) -> Result<LightOptions, Failure> {
    fn pick<T: Copy>(
        function: &str,
        field: &str,
        code: u32,
        all: &[T],
        name: impl Fn(T) -> &'static str,
    ) -> Result<T, Failure> {
        all.get(code as usize).copied().ok_or_else(|| {
            let names: Vec<String> = all
                .iter()
                .enumerate()
                .map(|(k, &t)| format!("{k} {}", name(t)))
                .collect();
            Failure::argument(
                function,
                format_args!("options.{field} is {code}, not one of {}", names.join(", ")),
            )
        })
    }
    // The orders of the C enums.
    let sampler = pick(function, "sampler", o.sampler, &Sampler::ALL, Sampler::name)?;
    let density = pick(function, "density", o.density, &Density::ALL, Density::name)?;
    let mapping = pick(function, "mapping", o.mapping, &Mapping::ALL, Mapping::name)?;
    let input_mapping = pick(
        function,
        "input_mapping",
        o.input_mapping,
        &Mapping::ALL,
        Mapping::name,
    )?;
    let lookup = pick(
        function,
        "lookup",
        o.lookup,
        &[Lookup::Bilinear, Lookup::Nearest, Lookup::Node],
        |l| match l {
            Lookup::Bilinear => "bilinear",
            Lookup::Nearest => "nearest",
            Lookup::Node => "node",
        },
    )?;
    if !o.rotate_deg.is_finite() {
        return Err(Failure::argument(
            function,
            format_args!("options.rotate_deg must be finite, not {}", o.rotate_deg),
        ));
    }
    let mut rotation = Rotation::about_z_degrees(o.rotate_deg);
    if o.rotation != [[0.0; 3]; 3] {
        let matrix = Rotation::from_rows(o.rotation).ok_or_else(|| {
            Failure::argument(
                function,
                format_args!(
                    "options.rotation {:?} is not a rotation (orthonormal rows, determinant 1)",
                    o.rotation
                ),
            )
        })?;
        rotation = rotation.then_after(matrix);
    }
    if !(o.scale.is_finite() && o.scale >= 0.0) {
        return Err(Failure::argument(
            function,
            format_args!("options.scale must be finite and >= 0, not {}", o.scale),
        ));
    }
    if o.mis_compensation > 1 {
        return Err(Failure::argument(
            function,
            format_args!(
                "options.mis_compensation must be 0 or 1, not {}",
                o.mis_compensation
            ),
        ));
    }
    if o.reserved != [0; 4] {
        return Err(Failure::argument(
            function,
            "options.reserved must be zero (start from envlight_light_options_default())",
        ));
    }
    let nonzero = |v: u32| (v != 0).then_some(v as usize);
    Ok(LightOptions {
        scale: o.scale,
        rotation,
        lookup,
        sampler,
        density,
        mapping,
        input_mapping,
        equal_area_size: nonzero(o.equal_area_size),
        mis_compensation: o.mis_compensation == 1,
        table_width: nonzero(o.table_width),
    })
}

/// The options at `options` (the defaults for NULL).
///
/// # Safety
/// A non-NULL `options` must point to a valid `envlight_light_options`.
unsafe fn options_or_default(
    options: *const envlight_light_options,
    function: &str,
) -> Result<LightOptions, Failure> {
    if options.is_null() {
        return light_options(&envlight_light_options_default(), function);
    }
    light_options(unsafe { deref(options, function, "options") }?, function)
}

/// Stores a new handle at `out`.
pub(crate) fn put<T>(out: &mut *mut T, value: T) {
    *out = Box::into_raw(Box::new(value));
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
    run(F, || {
        let out = unsafe { deref_mut(out, F, "out") }?;
        *out = std::ptr::null_mut();
        if path.is_null() {
            return Err(Failure::argument(F, "path is NULL"));
        }
        let path = unsafe { CStr::from_ptr(path) };
        let path = path_of(path);
        let options = unsafe { options_or_default(options, F) }?;
        let image = load(&path, &LoadOptions::default())?.image;
        let light = EnvironmentLight::new(image, options)?;
        put(
            out,
            envlight_light {
                light: Arc::new(light),
            },
        );
        Ok(())
    })
}

/// A C path as a filesystem path (any bytes on Unix).
fn path_of(path: &CStr) -> std::path::PathBuf {
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
    run(F, || {
        let out = unsafe { deref_mut(out, F, "out") }?;
        *out = std::ptr::null_mut();
        let light = light_from_rgb(rgb, width, height, options, F)?;
        put(out, light);
        Ok(())
    })
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
    let texels: &[[f32; 3]] = unsafe { slice(rgb, n, function, "rgb") }?;
    let options = unsafe { options_or_default(options, function) }?;
    if let Some(k) = texels.iter().flatten().position(|&c| c < 0.0) {
        let (texel, channel) = (k / 3, ['R', 'G', 'B'][k % 3]);
        return Err(Failure {
            status: envlight_status::ENVLIGHT_ERROR_INVALID_IMAGE,
            message: format!(
                "rgb: texel ({}, {}) has a negative value ({}) in channel {channel}",
                texel % w,
                texel / w,
                texels[texel][k % 3]
            ),
        });
    }
    let (image, _) = EnvImage::from_raw("rgb", w, h, texels.to_vec(), false)?;
    let light = EnvironmentLight::new(image, options)?;
    Ok(envlight_light {
        light: Arc::new(light),
    })
}

/// Frees a light (NULL: nothing). Handles built from it (product samplers,
/// portal lights, sun extractions, GPU tables) keep what they need and stay
/// valid.
#[no_mangle]
pub extern "C" fn envlight_light_free(light: *mut envlight_light) {
    free(light);
}

/// Frees a handle made by [`put`] (NULL: nothing), never unwinding into C.
pub(crate) fn free<T>(handle: *mut T) {
    if !handle.is_null() {
        // SAFETY: a non-NULL handle came from `put`'s `Box::into_raw`, and the C
        // contract frees it once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(handle) })));
    }
}

// ---------------------------------------------------------------------------
// The light's queries.
// ---------------------------------------------------------------------------

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
    value(F, false, || {
        let out = unsafe { deref_mut(out, F, "out") }?;
        *out = envlight_sample::default();
        let light = unsafe { deref(light, F, "light") }?;
        let u = unsafe { read(u, F, "u") }?;
        *out = to_c(sample_checked(&light.light, u));
        Ok(out.pdf > 0.0)
    })
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
        let light = unsafe { deref(light, F, "light") }?;
        let d = unsafe { read(direction, F, "direction") }?;
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
        let rgb = unsafe { write_array::<3>(rgb, F, "rgb") }?;
        *rgb = [0.0; 3];
        let light = unsafe { deref(light, F, "light") }?;
        let d = unsafe { read(direction, F, "direction") }?;
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
        let light = unsafe { deref(light, F, "light") }?;
        let u: &[[f32; 2]] = unsafe { slice(u, n, F, "u") }?;
        let out: &mut [[envlight_sample; 1]] = unsafe { slice_mut(out, n, F, "out") }?;
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
    const F: &str = "envlight_light_pdf_batch";
    run(F, || {
        let light = unsafe { deref(light, F, "light") }?;
        let dirs: &[[f32; 3]] = unsafe { slice(directions, n, F, "directions") }?;
        let out: &mut [[f32; 1]] = unsafe { slice_mut(pdf, n, F, "pdf") }?;
        light.light.pdf_batch(as_vec3(dirs), out.as_flattened_mut());
        Ok(())
    })
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
    const F: &str = "envlight_light_radiance_batch";
    run(F, || {
        let light = unsafe { deref(light, F, "light") }?;
        let dirs: &[[f32; 3]] = unsafe { slice(directions, n, F, "directions") }?;
        let out: &mut [[f32; 3]] = unsafe { slice_mut(rgb, n, F, "rgb") }?;
        light.light.radiance_batch(as_vec3(dirs), out);
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
        let u = unsafe { write_array::<2>(u, F, "u") }?;
        *u = [0.0; 2];
        let light = unsafe { deref(light, F, "light") }?;
        let d = unsafe { read(direction, F, "direction") }?;
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
        let info = unsafe { deref_mut(info, F, "info") }?;
        let light = &unsafe { deref(light, F, "light") }?.light;
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
        let light = &unsafe { deref(light, F, "light") }?.light;
        Ok(if light.is_black() {
            0.0
        } else {
            light.efficiency()
        })
    })
}

#[cfg(test)]
mod tests;
