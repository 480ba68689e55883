//! The boundary's guards, which every entry point goes through: failures as a
//! status and the calling thread's last message, panics caught before they reach
//! C, pointers from C checked before a reference is formed, results written into
//! the caller's buffers, and handles boxed and freed.
//!
//! The `unsafe` of the crate that is not an entry point's own lives here: an entry
//! point states its C contract (docs/c-api.md) once where it calls these helpers,
//! and the helpers turn that contract and their checks into references.

use std::cell::RefCell;
use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

use crate::envlight_status;

// ---------------------------------------------------------------------------
// Failures and the thread's last error.
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
    /// A failure with `status` and the whole `message`.
    pub(crate) fn new(status: envlight_status, message: String) -> Self {
        Self { status, message }
    }

    /// An invalid argument of the function `function`.
    pub(crate) fn argument(function: &str, message: impl std::fmt::Display) -> Self {
        Self {
            status: envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT,
            message: format!("{function}: {message}"),
        }
    }
}

/// The status of each of the library's errors.
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
            E::InvalidOption(_) | E::LightOption { .. } => ENVLIGHT_ERROR_INVALID_ARGUMENT,
            E::Unsupported(_) | E::HalfOverflow { .. } => ENVLIGHT_ERROR_UNSUPPORTED,
            E::Mismatch { .. } => ENVLIGHT_ERROR_MISMATCH,
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

/// `f` of this thread's last error ("" before any).
pub(crate) fn with_last_error<R>(f: impl FnOnce(&str) -> R) -> R {
    LAST_ERROR.with(|e| f(&e.borrow()))
}

/// The text of a caught panic's payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    payload
        .downcast_ref::<&str>()
        .copied()
        .or_else(|| payload.downcast_ref::<String>().map(String::as_str))
        .unwrap_or("a panic without a message")
}

// ---------------------------------------------------------------------------
// Running an entry point's body.
// ---------------------------------------------------------------------------

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

// ---------------------------------------------------------------------------
// Pointers from C, checked.
// ---------------------------------------------------------------------------

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
    check_pointer(p, function, name)?;
    // SAFETY: `check_pointer` found `p` non-NULL and aligned, and the caller
    // promises that such a `p` points to a valid `T` for `'a`.
    Ok(unsafe { &*p })
}

/// The checks of [`deref()`]: an invalid-argument failure naming `name` when `p`
/// is NULL or misaligned.
fn check_pointer<T>(p: *const T, function: &str, name: &str) -> Result<(), Failure> {
    if p.is_null() {
        return Err(Failure::argument(function, format_args!("{name} is NULL")));
    }
    if !p.is_aligned() {
        return Err(Failure::argument(
            function,
            format_args!("{name} is misaligned"),
        ));
    }
    Ok(())
}

/// `&mut *p`, checked as [`deref()`].
///
/// # Safety
/// A non-NULL, aligned `p` must point to a valid, unaliased `T` for `'a`.
pub(crate) unsafe fn deref_mut<'a, T>(
    p: *mut T,
    function: &str,
    name: &str,
) -> Result<&'a mut T, Failure> {
    // SAFETY: the caller's promise for `p` (a valid `T` when non-NULL and aligned)
    // is `deref`'s; the shared reference it forms is dropped at once.
    unsafe { deref(p, function, name) }?;
    // SAFETY: `deref` returned Ok, so `p` is non-NULL and aligned; the caller
    // promises such a `p` points to a valid `T` that nothing else accesses for `'a`.
    Ok(unsafe { &mut *p })
}

/// The out-parameter `*p`, set to `empty` before anything else can fail (so a
/// failing call leaves it NULL or zeroed), checked as [`deref()`].
///
/// # Safety
/// As [`deref_mut`].
pub(crate) unsafe fn cleared<'a, T: Copy>(
    p: *mut T,
    empty: T,
    function: &str,
    name: &str,
) -> Result<&'a mut T, Failure> {
    // SAFETY: forwarded: the caller makes `deref_mut`'s promise for `p`.
    let out = unsafe { deref_mut(p, function, name) }?;
    *out = empty;
    Ok(out)
}

/// The NUL-terminated string at `p`, or a failure naming `name` when `p` is NULL.
///
/// # Safety
/// A non-NULL `p` must point to a NUL-terminated string that lives, unchanged,
/// for `'a`.
pub(crate) unsafe fn c_str<'a>(
    p: *const c_char,
    function: &str,
    name: &str,
) -> Result<&'a CStr, Failure> {
    // A `c_char` is never misaligned: only NULL fails.
    check_pointer(p, function, name)?;
    // SAFETY: `check_pointer` found `p` non-NULL, and the caller promises a
    // NUL-terminated string there for `'a`.
    Ok(unsafe { CStr::from_ptr(p) })
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
    // SAFETY: forwarded: the caller's `K` floats at a non-NULL, aligned `p` are
    // the one group of `K` that `slice` needs for `n = 1`.
    Ok(unsafe { slice::<f32, K>(p, 1, function, name) }?[0])
}

/// The `K` floats at `p`, an out-parameter set to zeros before anything else can
/// fail, checked as [`read`].
///
/// # Safety
/// A non-NULL, aligned `p` must point to `K` writable, unaliased floats.
pub(crate) unsafe fn cleared_array<'a, const K: usize>(
    p: *mut f32,
    function: &str,
    name: &str,
) -> Result<&'a mut [f32; K], Failure> {
    // SAFETY: forwarded: the caller's `K` writable, unaliased floats at a
    // non-NULL, aligned `p` are what `slice_mut` needs for `n = 1`.
    let out = &mut unsafe { slice_mut::<f32, K>(p, 1, function, name) }?[0];
    *out = [0.0; K];
    Ok(out)
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
    // SAFETY: `check_array` found `p` non-NULL and aligned (for `T`, hence for
    // `[T; K]`, which has the layout of K consecutive `T`) and the `n · K` values
    // within `isize::MAX` bytes; the caller promises that many valid `T` at `p`.
    Ok(unsafe { std::slice::from_raw_parts(p.cast::<[T; K]>(), n) })
}

/// [`slice()`], mutable.
///
/// # Safety
/// As [`slice()`], and the memory must not be aliased for `'a`.
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
    // SAFETY: as in `slice` (non-NULL, aligned, size in bounds, `n · K` valid `T`
    // promised), and the caller promises nothing else accesses them for `'a`.
    Ok(unsafe { std::slice::from_raw_parts_mut(p.cast::<[T; K]>(), n) })
}

/// The checks of [`slice()`] for a non-empty array.
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

// ---------------------------------------------------------------------------
// Writing into the caller's buffers.
// ---------------------------------------------------------------------------

/// Copies `bytes` into the caller's buffer of `len` bytes at `buf` as `snprintf`
/// does: at most `len - 1` bytes and a terminating NUL; nothing when `buf` is NULL
/// or `len` is 0.
///
/// # Safety
/// A non-NULL `buf` must be valid for writes of `len` bytes, none of them in
/// `bytes`.
pub(crate) unsafe fn write_c_string(bytes: &[u8], buf: *mut c_char, len: usize) {
    if !buf.is_null() && len > 0 {
        let n = bytes.len().min(len - 1);
        // SAFETY: `buf` is non-NULL and `n + 1 <= len`, so the `n` bytes copied
        // and the NUL after them are within the `len` writable bytes the caller
        // promises, apart from `bytes`; `u8` and `c_char` need no alignment.
        unsafe {
            std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf.cast::<u8>(), n);
            *buf.add(n) = 0;
        }
    }
}

/// Copies `bytes` into the caller's buffer of `len` bytes at `buf` when they fit
/// whole; nothing when `buf` is NULL or `len` is too small.
///
/// # Safety
/// A non-NULL `buf` must be valid for writes of `len` bytes, none of them in
/// `bytes`.
pub(crate) unsafe fn write_whole(bytes: &[u8], buf: *mut u8, len: usize) {
    if !buf.is_null() && len >= bytes.len() {
        // SAFETY: `buf` is non-NULL and `bytes.len() <= len`, so the copy stays
        // within the `len` writable bytes the caller promises, apart from `bytes`.
        unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf, bytes.len()) };
    }
}

// ---------------------------------------------------------------------------
// Handles.
// ---------------------------------------------------------------------------

/// Runs the body of an entry point that makes a handle: `*out` is set to NULL
/// before anything else can fail, then holds the new handle of what `build`
/// makes (to free with [`free`]).
///
/// # Safety
/// As [`cleared`] for `out`: a non-NULL, aligned `out` must point to a writable
/// `*mut T` that nothing else accesses during the call.
pub(crate) unsafe fn new_handle<T>(
    function: &str,
    out: *mut *mut T,
    build: impl FnOnce() -> Result<T, Failure>,
) -> envlight_status {
    run(function, || {
        // SAFETY: forwarded: the caller makes `cleared`'s promise for `out`.
        let out = unsafe { cleared(out, std::ptr::null_mut(), function, "out") }?;
        *out = Box::into_raw(Box::new(build()?));
        Ok(())
    })
}

/// Frees a handle made by [`new_handle`] (NULL: nothing), never unwinding into C.
///
/// # Safety
/// A non-NULL `handle` must come from [`new_handle`] with the same `T`, and not
/// have been freed; nothing may use it afterwards.
pub(crate) unsafe fn free<T>(handle: *mut T) {
    if !handle.is_null() {
        // SAFETY: the caller promises a non-NULL handle came from `new_handle`'s
        // `Box::into_raw` of a `Box<T>` and is freed this once, so the box is
        // rebuilt and dropped exactly once.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(handle) })));
    }
}
