//! The library's version, as the header states it and as the library reports it.

use std::ffi::c_char;

/// The major version of the library this header belongs to.
pub const ENVLIGHT_VERSION_MAJOR: u32 = 0;
/// The minor version of the library this header belongs to.
pub const ENVLIGHT_VERSION_MINOR: u32 = 1;
/// The patch version of the library this header belongs to.
pub const ENVLIGHT_VERSION_PATCH: u32 = 0;

/// The library's version, `"MAJOR.MINOR.PATCH"` (static storage; never NULL).
#[no_mangle]
pub extern "C" fn envlight_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}
