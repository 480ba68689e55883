//! envlight-render: a small, correct, multi-threaded path tracer lit by an
//! importance-sampled environment map — the preview renderer of `envlight render`
//! and the end-to-end test of the light.
//!
//! - [`Scene::builtin`] gives the built-in scenes (`balls`, `diffuse`, `furnace`).
//! - [`render()`] traces an image with one [`Strategy`] for the light: uniform
//!   directions, BSDF sampling, the light's importance sampling, their MIS
//!   combination, MIS with the compensated light distribution
//!   ([`CompensatedLight`]), or product sampling of the light times the BSDF's
//!   factor at each shading point ([`envlight::ProductSampler`]), alone or with
//!   MIS.
//! - [`write_image`] saves `.exr`/`.pfm` (linear) or `.png` (tone mapped).
//! - [`compare()`] renders every strategy at equal samples (and time) and measures
//!   them against a reference; [`Comparison::write_sheet_png`] draws the labelled
//!   contact sheet.
//!
//! The library knows nothing of terminals: progress arrives through a
//! [`Progress`] callback. Renders are deterministic per seed, whatever the number of
//! threads: each sample's random stream is a function of (seed, pixel, sample index).
//!
//! ```
//! use envlight::{EnvImage, EnvironmentLight, LightOptions};
//! use envlight_render::{render, NoProgress, RenderSettings, Scene, Strategy};
//!
//! let white = EnvImage::from_fn(8, 4, |_, _| [1.0; 3]).unwrap();
//! let light = EnvironmentLight::new(white, LightOptions::default()).unwrap();
//! let scene = Scene::builtin("furnace").unwrap();
//! let settings = RenderSettings { width: 16, height: 16, spp: 4, strategy: Strategy::Bsdf, ..Default::default() };
//! let image = render(&scene, &light, &settings, &NoProgress);
//! // Cosine-weighted sampling of a white furnace has no variance: every sphere pixel is 0.5.
//! let centre = image.pixel(8, 8);
//! assert!((centre[0] - 0.5).abs() < 1e-4, "{centre:?}");
//! ```
#![warn(missing_docs)]

pub mod bsdf;
pub mod compare;
pub mod font;
pub mod geometry;
pub mod image;
pub mod integrator;
pub mod render;
mod rgb;
pub mod scene;
pub mod strategy;
pub mod warp;

pub use bsdf::{Bsdf, BsdfSample};
pub use compare::{compare, relative_mse, rmse, Budget, CompareEntry, CompareSettings, Comparison};
pub use geometry::{Camera, Frame, Ray, Shape};
pub use image::{auto_exposure, encode_image, read_image, write_image, Image, ImageFormat};
pub use integrator::{Integrator, Scratch};
pub use render::{
    learn_visibility, render, render_for_time, render_with_error, render_with_visibility,
    NoProgress, Progress, RenderSettings, Rendered,
};
pub use rgb::Rgb;
pub use scene::{Material, Object, Scene, SCENE_NAMES};
pub use strategy::{CompensatedLight, Strategy, UnknownStrategy};

/// Everything that can go wrong outside the tracing itself (which cannot fail).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// Reading or writing a file failed.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: String,
        /// The underlying error.
        #[source]
        error: std::io::Error,
    },
    /// The extension names no supported image format.
    #[error("{path}: unsupported image format (use .exr, .pfm or .png; references: .exr or .pfm)")]
    UnsupportedFormat {
        /// The file.
        path: String,
    },
    /// An encoder failed.
    #[error("cannot encode {format}: {detail}")]
    Encode {
        /// The format.
        format: &'static str,
        /// The encoder's message.
        detail: String,
    },
    /// A file could not be decoded.
    #[error("{path}: cannot decode {format} data: {detail}")]
    Decode {
        /// The file.
        path: String,
        /// The format.
        format: &'static str,
        /// What went wrong.
        detail: String,
    },
    /// An image has the wrong size.
    #[error("{what}: expected a {}x{} image, found {}x{}", expected.0, expected.1, found.0, found.1)]
    SizeMismatch {
        /// The image (a file name).
        what: String,
        /// Expected width and height.
        expected: (usize, usize),
        /// Actual width and height.
        found: (usize, usize),
    },
}
