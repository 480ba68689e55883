//! envlight: image-based environment lighting with exact importance sampling.
#![warn(missing_docs)]

pub mod color;
pub mod error;
pub mod image;
pub mod load;
pub mod math;

pub use error::{Error, Result, TexelPos};
pub use image::{EnvImage, Lookup, Sanitized};
pub use math::{Rotation, Vec3};
