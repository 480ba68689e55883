//! What a call that can fail returns, a status's name, and the calling thread's
//! last error message (kept by the `boundary` module).

use std::ffi::c_char;
use std::panic::catch_unwind;

use crate::boundary::{with_last_error, write_c_string};

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
    /// A callback of the caller's (the visibility cache's `envlight_visibility_trace`)
    /// returned a status other than `ENVLIGHT_OK`. The message gives that status.
    ENVLIGHT_ERROR_CALLBACK = 8,
    /// A saved file was made for other inputs than the ones given (a visibility
    /// cache for another light or scene key). The message names both.
    ENVLIGHT_ERROR_MISMATCH = 9,
}

/// Copies this thread's last error message into `buf` (at most `len - 1` bytes and
/// a terminating NUL; nothing when `buf` is NULL or `len` is 0) and returns the
/// message's length in bytes, without the NUL, like `snprintf`: a buffer of the
/// returned length + 1 holds it whole. The message is set by every failing call on
/// this thread and kept until the next failure; "" before any.
#[no_mangle]
pub extern "C" fn envlight_last_error(buf: *mut c_char, len: usize) -> usize {
    catch_unwind(|| {
        with_last_error(|message| {
            let bytes = message.as_bytes();
            // SAFETY: by this function's C contract a non-NULL `buf` holds `len`
            // writable bytes; they cannot overlap the message, which the library
            // owns in thread-local storage.
            unsafe { write_c_string(bytes, buf, len) };
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
        8 => "ENVLIGHT_ERROR_CALLBACK\0",
        9 => "ENVLIGHT_ERROR_MISMATCH\0",
        _ => "unknown status\0",
    };
    name.as_ptr().cast()
}
