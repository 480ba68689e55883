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
// Each `unsafe` block says why it is sound: the C contract it relies on and the
// checks made before it; in an `unsafe fn`, each unsafe operation is such a block.
#![deny(unsafe_op_in_unsafe_fn, clippy::undocumented_unsafe_blocks)]

// The helpers every entry point goes through, and what the samplers share.
mod boundary;
mod sample;

// The entry points, by object. cbindgen writes the header's functions in the order
// it meets them (these modules in turn, each file from the top), so this order is
// the header's; the comment above each module keeps rustfmt from sorting them.
//
// `envlight_version` and the version constants.
mod version;
// `envlight_status`, `envlight_status_name`, `envlight_last_error`.
mod status;
// `envlight_light_options` and its enumerations.
mod options;
// `envlight_light`: building, queries, info, freeing.
mod light;
// `envlight_gpu_tables`.
mod gpu;
// `envlight_portal_light`.
mod portal;
// `envlight_product`.
mod product;
// `envlight_visibility_cache`, its options, callback and summary.
mod visibility;
// `envlight_sun_extraction`.
mod sun;

pub use gpu::*;
pub use light::*;
pub use options::*;
pub use portal::*;
pub use product::*;
pub use sample::envlight_sample;
pub use status::*;
pub use sun::*;
pub use version::*;
pub use visibility::*;

#[cfg(test)]
mod tests;
