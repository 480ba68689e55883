//! envlight: image-based environment lighting with exact importance sampling.
//!
//! An environment light surrounds the scene at infinity; its radiance comes from an
//! equirectangular HDR panorama. envlight builds a sampling distribution whose
//! density follows the map's luminance, draws directions with their exact
//! solid-angle pdf, and evaluates the pdf and radiance of any direction (for
//! multiple importance sampling).
//!
//! Conventions (see docs/design.md §2): right-handed, z up; image point `(u, v)` with u
//! left→right and v top→bottom maps to `θ = π v` (from +z), `φ = 2π u` (from +x
//! towards +y). Luminance `Y = 0.212671 R + 0.715160 G + 0.072169 B`.
//!
//! ```
//! use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
//!
//! let light = EnvironmentLight::new(builtin::sky(256, 128), LightOptions::default()).unwrap();
//! // Estimate the irradiance on an upward-facing surface, E = ∫ L cosθ dω.
//! let n = 4096;
//! let mut e = 0.0;
//! for k in 0..n {
//!     let xi = envlight::rng::xi_2d(7, k);
//!     if let Some(s) = light.sample(xi) {
//!         let cos = s.direction.dot(Vec3::new(0.0, 0.0, 1.0)).max(0.0);
//!         e += envlight::color::luminance(s.radiance) * cos / s.pdf;
//!     }
//! }
//! let e = e / n as f32;
//! assert!(e > 0.0 && e.is_finite());
//! ```
//!
//! # Optional features
//!
//! Off by default; each adds conversions of [`Vec3`] (and [`Rotation`]) to and from
//! another math crate's types, copying the components as they are:
//!
//! - `mint`: `Vec3` ⇄ `mint::Vector3<f32>`; `Rotation` → `mint::RowMatrix3<f32>`
//!   (the rows of [`Rotation::rows`]), and back through `TryFrom`, which rejects a
//!   matrix that is not a rotation as [`Rotation::from_rows`] does.
//! - `glam`: `Vec3` ⇄ `glam::Vec3`.
//!
//! One more, `variants`, is for the project's own tests and measurements, not for
//! rendering: it adds `product::ProductVariant`, altered product samplers (the
//! deliberately broken ones the verification harness must reject, and the
//! on-the-fly product measured against the tables).
#![warn(missing_docs)]

pub mod alias;
pub mod bilinear;
pub mod builtin;
pub mod color;
pub mod distribution;
pub mod error;
pub mod gpu;
pub mod hierarchical;
pub mod image;
#[cfg(any(feature = "mint", feature = "glam"))]
mod interop;
pub mod light;
pub mod load;
pub mod mapping;
pub mod math;
mod parallel;
pub mod portal;
pub mod product;
pub mod rng;
pub mod sun;
pub mod visibility;
mod width;

// The equal-area map keeps the public path it had before the mappings were
// gathered in `mapping`.
pub use mapping::equal_area;

pub use distribution::{Distribution1D, Distribution2D};
pub use error::{Error, Result, TexelPos};
pub use image::{EnvImage, Lookup, Sanitized, WrapU};
pub use light::{EnvironmentLight, LightOptions, LightSample};
pub use math::{Rotation, Vec3};
pub use product::{Factor, ProductOptions, ProductSampler, ShadingPoint};
pub use sun::{Sun, SunExtraction, SunOptions};
pub use visibility::{VisibilityCache, VisibilityOptions, VisibilitySummary};

/// The README's Rust example, compiled and run as a doctest so the README stays true.
/// `repository-README.md` is a link to the repository's README.md, which the
/// package holds as a copy: the doctests run from the package too.
#[doc = include_str!("../repository-README.md")]
#[cfg(doctest)]
pub struct ReadmeDoctests;

/// The crate's own README (its page on crates.io), compiled and run as a doctest.
#[doc = include_str!("../README.md")]
#[cfg(doctest)]
pub struct CrateReadmeDoctests;

/// The guides in the repository's `docs/` (`docs` here is a link to it, which the
/// package holds as a copy): every Rust block in them is a doctest of this crate,
/// except `docs/gpu.md`'s, which are `envlight-gpu`'s. The docs test
/// (`crates/envlight-cli/tests/docs.rs`) fails when a guide with Rust blocks is
/// missing from this list.
#[cfg(doctest)]
pub mod guides {
    #[doc = include_str!("../docs/light.md")]
    pub struct Light;
    #[doc = include_str!("../docs/product-sampling.md")]
    pub struct ProductSampling;
    #[doc = include_str!("../docs/portals.md")]
    pub struct Portals;
    #[doc = include_str!("../docs/sun.md")]
    pub struct Sun;
    #[doc = include_str!("../docs/visibility.md")]
    pub struct Visibility;
    #[doc = include_str!("../docs/gpu-tables.md")]
    pub struct GpuTables;
    #[doc = include_str!("../docs/c-api.md")]
    pub struct CApi;
    #[doc = include_str!("../docs/python.md")]
    pub struct Python;
    #[doc = include_str!("../docs/mitsuba.md")]
    pub struct Mitsuba;
    #[doc = include_str!("../docs/cli.md")]
    pub struct Cli;
    #[doc = include_str!("../docs/conventions.md")]
    pub struct Conventions;
    #[doc = include_str!("../docs/verification.md")]
    pub struct Verification;
    #[doc = include_str!("../docs/performance.md")]
    pub struct Performance;
}
