//! The library's error type.
//!
//! Every error that comes from input names its source (a file path, or the name a
//! caller gave to in-memory bytes) and, where it applies, the texel. The messages
//! are written to be shown to a user as they are, after `error: `.

use std::fmt;

/// Where a texel sits in an image: `x` from the left, `y` from the top, both from 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TexelPos {
    /// Column, 0 at the left edge.
    pub x: usize,
    /// Row, 0 at the top edge.
    pub y: usize,
}

impl fmt::Display for TexelPos {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "({}, {})", self.x, self.y)
    }
}

/// Everything that can go wrong in envlight.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The file could not be opened or read.
    #[error("{source_name}: {error}")]
    Io {
        /// The path or name of the input.
        source_name: String,
        /// The underlying I/O error.
        #[source]
        error: std::io::Error,
    },
    /// The file's format is not one envlight reads.
    #[error("{source_name}: unsupported format ({detail})")]
    UnsupportedFormat {
        /// The path or name of the input.
        source_name: String,
        /// What was seen (an extension, a magic number).
        detail: String,
    },
    /// The file claims to be of a supported format but cannot be decoded
    /// (truncated, corrupt, or using a feature that is not supported).
    #[error("{source_name}: cannot decode {format} data: {detail}")]
    Decode {
        /// The path or name of the input.
        source_name: String,
        /// The format that was being decoded ("Radiance HDR", "OpenEXR", "PFM", ...).
        format: &'static str,
        /// What went wrong, as precisely as the decoder says.
        detail: String,
    },
    /// A texel holds NaN or an infinity.
    #[error("{source_name}: texel {pos} has a non-finite value ({value}) in channel {channel}")]
    NonFiniteTexel {
        /// The path or name of the input.
        source_name: String,
        /// The first bad texel in reading order (rows from the top).
        pos: TexelPos,
        /// The channel, `R`, `G` or `B`.
        channel: char,
        /// The offending value.
        value: f32,
    },
    /// The image declares more texels than the caller allows (or than fit in memory).
    #[error("{source_name}: image of {width}x{height} texels is too large (limit {limit} texels)")]
    TooLarge {
        /// The path or name of the input.
        source_name: String,
        /// Declared width.
        width: usize,
        /// Declared height.
        height: usize,
        /// The limit in force.
        limit: usize,
    },
    /// Width or height is zero, or the texel buffer does not match them.
    #[error("{source_name}: invalid image dimensions: {detail}")]
    InvalidDimensions {
        /// The path or name of the input.
        source_name: String,
        /// What is wrong.
        detail: String,
    },
    /// An option given to a builder is out of range (a NaN scale, say).
    #[error("invalid option: {0}")]
    InvalidOption(String),
    /// Light options that no light can be built with, whatever the image
    /// ([`crate::light::LightOptions::validate`], whose
    /// [`crate::light::OptionError`] this carries as the field at fault and its
    /// message).
    #[error("invalid option: {message}")]
    LightOption {
        /// The [`crate::light::LightOptions`] field at fault.
        field: &'static str,
        /// The rule it breaks.
        message: String,
    },
    /// A combination of options that a feature does not implement (the hierarchical
    /// sampler exported for a GPU, say).
    #[error("not supported: {0}")]
    Unsupported(String),
    /// A saved file was made for another input than the one given (a visibility
    /// cache for another light or scene).
    #[error("{source_name}: {detail}")]
    Mismatch {
        /// The path or name of the file.
        source_name: String,
        /// What it was made for, and what it was asked for.
        detail: String,
    },
    /// A texel channel too large for a 16-bit float: it would round to infinity.
    #[error(
        "texel {pos} has {channel} = {value}, beyond the largest 16-bit float (65504); \
         export the radiance as f32"
    )]
    HalfOverflow {
        /// The first such texel in reading order (rows from the top).
        pos: TexelPos,
        /// The channel, `R`, `G` or `B`.
        channel: char,
        /// The offending value.
        value: f32,
    },
}

/// Shorthand for results in this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
