//! Decoding environment maps from files: Radiance `.hdr`, OpenEXR `.exr`, PFM, and
//! (low dynamic range) PNG and JPEG.
//!
//! The format is recognised by the file's leading bytes, never by its extension.
//! Every decoder:
//! - reads the declared width and height first and refuses an image of more than
//!   [`LoadOptions::max_texels`] texels ([`Error::TooLarge`]) or with a zero side
//!   ([`Error::InvalidDimensions`]) before it allocates or decodes any texel;
//! - checks every other size the file declares (OpenEXR offset tables, chunk byte
//!   counts and decompressed block sizes; Radiance scanline lengths; PNG and JPEG
//!   image sizes) against the bytes present before allocating for it, and
//!   allocates the image as its data decodes (see the `bounds` module), so a small
//!   malformed file cannot ask for gigabytes;
//! - returns texels as linear Rec.709 RGB with row 0 at the top, whatever the
//!   file's own row order (PFM stores rows bottom-up; Radiance allows eight
//!   orientations) and primaries (an OpenEXR `chromaticities` attribute or a
//!   Radiance `PRIMARIES` line that is not Rec.709 is converted to Rec.709/D65);
//! - turns every failure into an [`Error`] naming the source, never a panic:
//!   decoder panics on malformed input are caught and reported as [`Error::Decode`];
//! - passes the texels through [`EnvImage::from_raw`], so NaN/infinite texels are an
//!   error (or replaced and counted) and negative channels are clamped and counted.

use std::collections::HashSet;
use std::fmt;
use std::io::{Cursor, Read, Write};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

mod bounds;

use bounds::{
    check_exr_chunk_table, check_exr_expansion, exr_block_bytes, hdr_scanline_believable,
    ldr_data_fits, IN_FLIGHT_BYTES,
};

use crate::color::srgb_to_linear;
use crate::error::{Error, Result};
use crate::image::{EnvImage, Sanitized};

/// The default for [`LoadOptions::max_texels`]: 2²⁸ texels (16384 × 16384), which
/// is 3 GiB of decoded `f32` RGB.
pub const DEFAULT_MAX_TEXELS: usize = 1 << 28;

/// A file format envlight decodes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ImageFormat {
    /// Radiance RGBE (`.hdr`, `.pic`), flat or run-length encoded.
    RadianceHdr,
    /// OpenEXR (`.exr`): half, float or uint channels, scanline or tiled, any
    /// compression the `exr` crate supports (including DWAA/DWAB).
    OpenExr,
    /// Portable float map (`.pfm`), colour (`PF`) or grey (`Pf`).
    Pfm,
    /// PNG, 8 or 16 bits per channel, taken as sRGB-encoded.
    Png,
    /// JPEG, taken as sRGB-encoded.
    Jpeg,
}

impl ImageFormat {
    /// The short lower-case name: `"hdr"`, `"exr"`, `"pfm"`, `"png"` or `"jpeg"`
    /// (also what [`fmt::Display`] prints).
    pub fn name(self) -> &'static str {
        match self {
            ImageFormat::RadianceHdr => "hdr",
            ImageFormat::OpenExr => "exr",
            ImageFormat::Pfm => "pfm",
            ImageFormat::Png => "png",
            ImageFormat::Jpeg => "jpeg",
        }
    }

    /// The name used in [`Error::Decode::format`].
    fn long_name(self) -> &'static str {
        match self {
            ImageFormat::RadianceHdr => "Radiance HDR",
            ImageFormat::OpenExr => "OpenEXR",
            ImageFormat::Pfm => "PFM",
            ImageFormat::Png => "PNG",
            ImageFormat::Jpeg => "JPEG",
        }
    }

    /// The format a file's leading bytes identify, if any.
    fn from_magic(bytes: &[u8]) -> Option<Self> {
        const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
        const PNG_MAGIC: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
        if bytes.starts_with(b"#?") {
            Some(ImageFormat::RadianceHdr)
        } else if bytes.starts_with(&EXR_MAGIC) {
            Some(ImageFormat::OpenExr)
        } else if (bytes.starts_with(b"PF") || bytes.starts_with(b"Pf"))
            && bytes.get(2).is_none_or(|b| b.is_ascii_whitespace())
        {
            Some(ImageFormat::Pfm)
        } else if bytes.starts_with(&PNG_MAGIC) {
            Some(ImageFormat::Png)
        } else if bytes.starts_with(&[0xff, 0xd8, 0xff]) {
            Some(ImageFormat::Jpeg)
        } else {
            None
        }
    }

    /// The format a file extension conventionally stands for.
    fn from_extension(extension: &str) -> Option<Self> {
        match extension.to_ascii_lowercase().as_str() {
            "hdr" | "pic" | "rgbe" => Some(ImageFormat::RadianceHdr),
            "exr" => Some(ImageFormat::OpenExr),
            "pfm" => Some(ImageFormat::Pfm),
            "png" => Some(ImageFormat::Png),
            "jpg" | "jpeg" => Some(ImageFormat::Jpeg),
            _ => None,
        }
    }
}

impl fmt::Display for ImageFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Limits and policies for [`load`] and [`load_from_memory`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LoadOptions {
    /// The largest `width × height` accepted; larger images are refused with
    /// [`Error::TooLarge`] before any texel is decoded. Default [`DEFAULT_MAX_TEXELS`].
    pub max_texels: usize,
    /// Replace NaN/infinite texels by black (and count them in
    /// [`Sanitized::non_finite_texels`]) instead of failing with
    /// [`Error::NonFiniteTexel`]. Default `false`.
    pub replace_non_finite: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            max_texels: DEFAULT_MAX_TEXELS,
            replace_non_finite: false,
        }
    }
}

/// A decoded environment map and what decoding it involved.
#[derive(Debug, Clone)]
pub struct LoadedImage {
    /// Linear Rec.709 RGB texels, row 0 at the top, all finite and non-negative.
    pub image: EnvImage,
    /// The format the data was decoded as (from its content, not its name).
    pub format: ImageFormat,
    /// What validation changed: negative channels clamped, non-finite texels
    /// replaced.
    pub sanitized: Sanitized,
    /// Human-readable facts worth telling the user, one sentence each: a colour
    /// space conversion, a layer chosen among several, an ignored scale or alpha
    /// channel, a low-dynamic-range source.
    pub notes: Vec<String>,
}

/// Reads and decodes the environment map at `path`; see [`load_from_memory`] for
/// formats and guarantees. Errors name the path as given (`path.display()`).
///
/// When the content's format differs from what the extension suggests, the content
/// wins and a note says so.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::UnsupportedFormat`] (naming
/// the leading bytes and the extension) when the content is no supported format;
/// otherwise as [`load_from_memory`].
pub fn load(path: &Path, options: &LoadOptions) -> Result<LoadedImage> {
    let source_name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|error| Error::Io {
        source_name: source_name.clone(),
        error,
    })?;
    let extension = path.extension().map(|e| e.to_string_lossy().into_owned());
    match load_from_memory(&source_name, &bytes, options) {
        Ok(mut loaded) => {
            if let Some(ext) = &extension {
                if let Some(claimed) = ImageFormat::from_extension(ext) {
                    if claimed != loaded.format {
                        loaded.notes.push(format!(
                            "the content is {} although the extension is .{ext}",
                            loaded.format.long_name()
                        ));
                    }
                }
            }
            Ok(loaded)
        }
        Err(Error::UnsupportedFormat {
            source_name,
            detail,
        }) => {
            let about_extension = match &extension {
                None => "the file name has no extension".to_string(),
                Some(ext) => match ImageFormat::from_extension(ext) {
                    Some(format) => format!(
                        "the extension .{ext} suggests {}, but the content is not {}",
                        format.long_name(),
                        format.long_name()
                    ),
                    None => format!(
                        "the extension .{ext} is not a supported format \
                         (supported: .hdr, .exr, .pfm, .png, .jpg)"
                    ),
                },
            };
            Err(Error::UnsupportedFormat {
                source_name,
                detail: format!("{detail}; {about_extension}"),
            })
        }
        Err(other) => Err(other),
    }
}

/// Decodes an environment map held in memory; `source_name` is used in errors.
///
/// The format comes from the leading bytes: `#?` (Radiance, e.g. `#?RADIANCE` or
/// `#?RGBE`), the OpenEXR magic number `76 2f 31 01`, `PF`/`Pf` followed by
/// whitespace (PFM), and the PNG and JPEG signatures.
///
/// - Radiance: `FORMAT=32-bit_rle_rgbe` (or no `FORMAT` line), flat, old-style or
///   new-style RLE scanlines, all eight orientations of the resolution line.
///   `EXPOSURE` is not applied (values are used as stored; a note says so).
/// - OpenEXR: the first layer with `R`, `G`, `B` channels (found by name, in any
///   stored order, with or without a `layer.` prefix, across all parts), else the
///   first with `Y` alone (loaded as grey); half, float or uint samples; the
///   full-resolution level of mip/rip-mapped files; the data window.
/// - PFM: rows are stored bottom-up and flipped; the scale's sign gives the byte
///   order and its magnitude is not applied; bytes after the raster are ignored.
/// - PNG/JPEG: taken as sRGB-encoded and decoded to linear `[0, 1]`; alpha is
///   ignored.
///
/// # Errors
/// [`Error::UnsupportedFormat`] for unrecognised content; [`Error::TooLarge`] and
/// [`Error::InvalidDimensions`] from the declared size; [`Error::Decode`] for
/// malformed, truncated or unsupported data (with the decoder's explanation);
/// [`Error::NonFiniteTexel`] naming the first NaN/infinite texel (top-down
/// coordinates) unless [`LoadOptions::replace_non_finite`] is set.
pub fn load_from_memory(
    source_name: &str,
    bytes: &[u8],
    options: &LoadOptions,
) -> Result<LoadedImage> {
    let format = ImageFormat::from_magic(bytes).ok_or_else(|| Error::UnsupportedFormat {
        source_name: source_name.to_string(),
        detail: describe_unknown(bytes),
    })?;
    let ctx = Ctx {
        source_name,
        format,
        options,
    };
    // Last line of defence: a decoder that panics on malformed input becomes a
    // Decode error instead of taking the caller down.
    let decoded = catch_unwind(AssertUnwindSafe(|| match format {
        ImageFormat::RadianceHdr => decode_hdr(&ctx, bytes),
        ImageFormat::OpenExr => decode_exr(&ctx, bytes),
        ImageFormat::Pfm => decode_pfm(&ctx, bytes),
        ImageFormat::Png | ImageFormat::Jpeg => decode_ldr(&ctx, bytes),
    }))
    .unwrap_or_else(|payload| {
        Err(ctx.decode_error(format!(
            "the decoder failed on malformed data ({})",
            panic_message(payload.as_ref())
        )))
    })?;
    let (image, sanitized) = EnvImage::from_raw(
        source_name,
        decoded.width,
        decoded.height,
        decoded.texels,
        options.replace_non_finite,
    )?;
    Ok(LoadedImage {
        image,
        format,
        sanitized,
        notes: decoded.notes,
    })
}

/// Encodes `image` as a colour PFM: header `PF\n<w> <h>\n-1.0\n` (little-endian),
/// then `f32` RGB texels with the rows written bottom-to-top, as PFM requires.
/// [`load_from_memory`] reads the result back bit-exactly.
pub fn encode_pfm(image: &EnvImage) -> Vec<u8> {
    let (width, height) = (image.width(), image.height());
    let header = format!("PF\n{width} {height}\n-1.0\n");
    let mut out = Vec::with_capacity(header.len() + width * height * 12);
    out.extend_from_slice(header.as_bytes());
    for y in (0..height).rev() {
        for texel in image.row(y) {
            for value in texel {
                out.extend_from_slice(&value.to_le_bytes());
            }
        }
    }
    out
}

/// Writes `image` to `path` as a colour PFM (see [`encode_pfm`]).
///
/// The data goes to a temporary file beside `path` that is renamed over it only
/// when complete, so a failure never leaves a partial file nor destroys an
/// existing one.
///
/// # Errors
/// [`Error::Io`] naming `path` when the file cannot be written.
pub fn write_pfm(path: &Path, image: &EnvImage) -> Result<()> {
    let io_error = |error| Error::Io {
        source_name: path.display().to_string(),
        error,
    };
    let bytes = encode_pfm(image);
    let Some(file_name) = path.file_name() else {
        return std::fs::write(path, &bytes).map_err(io_error);
    };
    let mut temp_name = std::ffi::OsString::from(".");
    temp_name.push(file_name);
    temp_name.push(format!(".{}.tmp", std::process::id()));
    let temp = path.with_file_name(temp_name);
    let written = std::fs::File::create(&temp)
        .and_then(|mut file| {
            file.write_all(&bytes)?;
            file.sync_all()
        })
        .and_then(|()| std::fs::rename(&temp, path));
    if let Err(error) = written {
        let _ = std::fs::remove_file(&temp);
        return Err(io_error(error));
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Shared plumbing

/// What a format decoder hands back before validation.
struct Decoded {
    width: usize,
    height: usize,
    texels: Vec<[f32; 3]>,
    notes: Vec<String>,
}

/// The input being decoded.
struct Ctx<'a> {
    source_name: &'a str,
    format: ImageFormat,
    options: &'a LoadOptions,
}

impl Ctx<'_> {
    fn decode_error(&self, detail: impl Into<String>) -> Error {
        Error::Decode {
            source_name: self.source_name.to_string(),
            format: self.format.long_name(),
            detail: detail.into(),
        }
    }

    /// Checks a declared size against the limits; returns the texel count.
    fn check_dimensions(&self, width: usize, height: usize) -> Result<usize> {
        if width == 0 || height == 0 {
            return Err(Error::InvalidDimensions {
                source_name: self.source_name.to_string(),
                detail: format!("the header declares {width}x{height} texels"),
            });
        }
        match width.checked_mul(height) {
            Some(n) if n <= self.options.max_texels => Ok(n),
            _ => Err(Error::TooLarge {
                source_name: self.source_name.to_string(),
                width,
                height,
                limit: self.options.max_texels,
            }),
        }
    }
}

/// "unrecognised content: ..." with the leading bytes in hex and as text.
fn describe_unknown(bytes: &[u8]) -> String {
    if bytes.is_empty() {
        return "the input is empty (0 bytes)".to_string();
    }
    let head = &bytes[..bytes.len().min(8)];
    let hex: Vec<String> = head.iter().map(|b| format!("{b:02x}")).collect();
    let text: String = head
        .iter()
        .map(|&b| {
            if b.is_ascii_graphic() || b == b' ' {
                b as char
            } else {
                '.'
            }
        })
        .collect();
    format!(
        "unrecognised content starting with bytes {} (\"{text}\"); expected Radiance HDR, \
         OpenEXR, PFM, PNG or JPEG",
        hex.join(" ")
    )
}

fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "panic".to_string()
    }
}

/// At most `max` characters of `s`, with "..." when cut.
fn clip(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_string()
    } else {
        s.chars().take(max).chain("...".chars()).collect()
    }
}

// ---------------------------------------------------------------------------
// Colour spaces

/// CIE xy chromaticities of three primaries and a white point.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Chromaticities {
    red: [f64; 2],
    green: [f64; 2],
    blue: [f64; 2],
    white: [f64; 2],
}

type Mat3 = [[f64; 3]; 3];

/// ITU-R BT.709 primaries with the D65 white point (also sRGB's).
const REC709: Chromaticities = Chromaticities {
    red: [0.64, 0.33],
    green: [0.30, 0.60],
    blue: [0.15, 0.06],
    white: [0.3127, 0.3290],
};

/// Bradford cone response matrix (XYZ → sharpened LMS).
const BRADFORD: Mat3 = [
    [0.8951, 0.2664, -0.1614],
    [-0.7502, 1.7135, 0.0367],
    [0.0389, -0.0685, 1.0296],
];

impl Chromaticities {
    fn values(&self) -> [f64; 8] {
        [
            self.red[0],
            self.red[1],
            self.green[0],
            self.green[1],
            self.blue[0],
            self.blue[1],
            self.white[0],
            self.white[1],
        ]
    }

    fn from_values(v: [f64; 8]) -> Self {
        Self {
            red: [v[0], v[1]],
            green: [v[2], v[3]],
            blue: [v[4], v[5]],
            white: [v[6], v[7]],
        }
    }

    /// Within `1e-3` of Rec.709/D65 in every coordinate.
    fn is_rec709(&self) -> bool {
        self.values()
            .iter()
            .zip(REC709.values())
            .all(|(a, b)| (a - b).abs() <= 1e-3)
    }

    fn describe(&self) -> String {
        let [rx, ry, gx, gy, bx, by, wx, wy] = self.values();
        format!("R({rx:.3},{ry:.3}) G({gx:.3},{gy:.3}) B({bx:.3},{by:.3}) white ({wx:.4},{wy:.4})")
    }

    /// The matrix taking RGB in these primaries to CIE XYZ, scaled so that RGB
    /// (1,1,1) maps to the white point with Y = 1. `None` when degenerate.
    fn rgb_to_xyz(&self) -> Option<Mat3> {
        let xyz = |[x, y]: [f64; 2]| -> Option<[f64; 3]> {
            (y > 0.0 && x.is_finite() && y.is_finite()).then(|| [x / y, 1.0, (1.0 - x - y) / y])
        };
        let (r, g, b, w) = (
            xyz(self.red)?,
            xyz(self.green)?,
            xyz(self.blue)?,
            xyz(self.white)?,
        );
        let primaries = [[r[0], g[0], b[0]], [r[1], g[1], b[1]], [r[2], g[2], b[2]]];
        // Scale each primary so that their sum is the white point.
        let s = mul_vec(&invert(&primaries)?, w);
        let m = [
            [r[0] * s[0], g[0] * s[1], b[0] * s[2]],
            [r[1] * s[0], g[1] * s[1], b[1] * s[2]],
            [r[2] * s[0], g[2] * s[1], b[2] * s[2]],
        ];
        m.iter().flatten().all(|v| v.is_finite()).then_some(m)
    }

    /// RGB in these primaries → XYZ → Bradford adaptation of this white to D65 →
    /// linear Rec.709 RGB. `None` when the chromaticities are degenerate.
    fn conversion_to_rec709(&self) -> Option<Mat3> {
        let to_xyz = self.rgb_to_xyz()?;
        let from_xyz_709 = invert(&REC709.rgb_to_xyz()?)?;
        let source_white = mul_vec(&to_xyz, [1.0; 3]);
        let target_white = mul_vec(&REC709.rgb_to_xyz()?, [1.0; 3]);
        let (ls, ld) = (
            mul_vec(&BRADFORD, source_white),
            mul_vec(&BRADFORD, target_white),
        );
        if ls.iter().any(|&v| v.abs() < 1e-12) {
            return None;
        }
        let gain = [
            [ld[0] / ls[0], 0.0, 0.0],
            [0.0, ld[1] / ls[1], 0.0],
            [0.0, 0.0, ld[2] / ls[2]],
        ];
        let adapt = mul(&invert(&BRADFORD)?, &mul(&gain, &BRADFORD));
        let m = mul(&from_xyz_709, &mul(&adapt, &to_xyz));
        m.iter().flatten().all(|v| v.is_finite()).then_some(m)
    }
}

fn mul(a: &Mat3, b: &Mat3) -> Mat3 {
    let mut out = [[0.0; 3]; 3];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, value) in row.iter_mut().enumerate() {
            *value = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    out
}

fn mul_vec(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

fn invert(m: &Mat3) -> Option<Mat3> {
    let cofactor =
        |r0: usize, r1: usize, c0: usize, c1: usize| m[r0][c0] * m[r1][c1] - m[r0][c1] * m[r1][c0];
    let c = [
        [
            cofactor(1, 2, 1, 2),
            -cofactor(1, 2, 0, 2),
            cofactor(1, 2, 0, 1),
        ],
        [
            -cofactor(0, 2, 1, 2),
            cofactor(0, 2, 0, 2),
            -cofactor(0, 2, 0, 1),
        ],
        [
            cofactor(0, 1, 1, 2),
            -cofactor(0, 1, 0, 2),
            cofactor(0, 1, 0, 1),
        ],
    ];
    let det = m[0][0] * c[0][0] + m[0][1] * c[0][1] + m[0][2] * c[0][2];
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    // The inverse is the transposed cofactor matrix over the determinant.
    Some([0, 1, 2].map(|i| [0, 1, 2].map(|j| c[j][i] / det)))
}

/// Converts texels from `file` primaries to Rec.709/D65 when they differ; returns
/// the note to record (or `None` when nothing was done). Degenerate chromaticities
/// are ignored with a note.
fn convert_primaries(texels: &mut [[f32; 3]], file: &Chromaticities, what: &str) -> Option<String> {
    if file.is_rec709() {
        return None;
    }
    let Some(m) = file.conversion_to_rec709() else {
        return Some(format!(
            "ignored the {what} {} (degenerate primaries); texels taken as Rec.709",
            file.describe()
        ));
    };
    for texel in texels.iter_mut() {
        let v = texel.map(f64::from);
        let finite = texel.iter().all(|c| c.is_finite());
        for (i, out) in texel.iter_mut().enumerate() {
            let x = m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2];
            // Keep finite input finite; NaN/Inf stays non-finite for validation.
            *out = if finite {
                x.clamp(-f64::from(f32::MAX), f64::from(f32::MAX)) as f32
            } else {
                x as f32
            };
        }
    }
    Some(format!(
        "converted from file primaries {} to Rec.709/D65 (Bradford white adaptation)",
        file.describe()
    ))
}

// ---------------------------------------------------------------------------
// Radiance HDR

/// One axis of a Radiance resolution line: `-Y`, `+Y`, `-X` or `+X`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Axis {
    is_y: bool,
    positive: bool,
}

impl Axis {
    fn parse(token: &str) -> Option<Self> {
        let (sign, axis) = token.split_at_checked(1)?;
        let positive = match sign {
            "+" => true,
            "-" => false,
            _ => None?,
        };
        let is_y = match axis {
            "Y" => true,
            "X" => false,
            _ => None?,
        };
        Some(Self { is_y, positive })
    }
}

/// The line starting at `start` (without its `\n`) and where the next one starts;
/// `None` when there is no `\n`.
fn take_line(bytes: &[u8], start: usize) -> Option<(&[u8], usize)> {
    let rest = bytes.get(start..)?;
    let end = rest.iter().position(|&b| b == b'\n')?;
    Some((&rest[..end], start + end + 1))
}

fn decode_hdr(ctx: &Ctx<'_>, bytes: &[u8]) -> Result<Decoded> {
    use image::codecs::hdr::HdrDecoder;
    use image::ImageDecoder;

    let mut notes = Vec::new();
    let (_, mut pos) = take_line(bytes, 0)
        .ok_or_else(|| ctx.decode_error("the file ends inside the signature line"))?;
    let mut primaries_line = None;
    loop {
        let (line, next) = take_line(bytes, pos).ok_or_else(|| {
            ctx.decode_error("the header is not ended by an empty line (truncated file?)")
        })?;
        pos = next;
        let line = line.strip_suffix(b"\r").unwrap_or(line);
        if line.is_empty() {
            break;
        }
        if line[0] == b'#' {
            continue;
        }
        let line = String::from_utf8_lossy(line);
        let Some((key, value)) = line.split_once('=') else {
            continue; // old Radiance files keep command lines in the header
        };
        let value = value.trim();
        match key.trim() {
            "FORMAT" if value != "32-bit_rle_rgbe" => {
                return Err(ctx.decode_error(format!(
                    "FORMAT={} is not supported (only 32-bit_rle_rgbe)",
                    clip(value, 40)
                )));
            }
            "EXPOSURE" => notes.push(format!(
                "the header declares EXPOSURE={}; texel values are used as stored",
                clip(value, 40)
            )),
            "PRIMARIES" => primaries_line = Some(value.to_string()),
            _ => {}
        }
    }

    // Resolution line: "±A n1 ±B n2"; n1 scanlines of n2 texels each.
    let (line, data_start) = take_line(bytes, pos).unwrap_or((&bytes[pos..], bytes.len()));
    let line = String::from_utf8_lossy(line);
    let bad_resolution = || {
        ctx.decode_error(format!(
            "resolution line \"{}\" is not of the form \"-Y <height> +X <width>\"",
            clip(line.trim_end(), 60)
        ))
    };
    let tokens: Vec<&str> = line.split_ascii_whitespace().collect();
    let [t1, n1, t2, n2] = tokens[..] else {
        return Err(bad_resolution());
    };
    let (a1, a2) = match (Axis::parse(t1), Axis::parse(t2)) {
        (Some(a1), Some(a2)) if a1.is_y != a2.is_y => (a1, a2),
        _ => return Err(bad_resolution()),
    };
    let n1: usize = n1.parse().map_err(|_| bad_resolution())?;
    let n2: usize = n2.parse().map_err(|_| bad_resolution())?;
    let (width, height) = if a1.is_y { (n2, n1) } else { (n1, n2) };
    let n = ctx.check_dimensions(width, height)?;
    let scanline_len = u32::try_from(n2)
        .map_err(|_| ctx.decode_error(format!("scanlines of {n2} texels are not supported")))?;

    // Decode one scanline at a time: memory grows with the data actually present
    // (a truncated file claiming a huge size fails early), and an error can say
    // which scanline broke. Capacity starts at one texel per byte of input; only
    // heavily run-length-encoded data grows it (a few doublings at most for
    // new-style RLE, ~16 texels per byte).
    let data_bytes = &bytes[data_start.min(bytes.len())..];
    if !hdr_scanline_believable(n2, data_bytes.len()) {
        return Err(ctx.decode_error(format!(
            "scanlines of {n2} texels need more than the {} bytes of data the file holds",
            data_bytes.len()
        )));
    }
    let header = format!("#?RADIANCE\n\n-Y 1 +X {scanline_len}\n").into_bytes();
    let mut data = Cursor::new(data_bytes);
    let mut line_bytes = vec![0u8; n2 * 12];
    let mut scan = Vec::with_capacity(n.min(bytes.len()));
    for s in 0..n1 {
        let scanline_error = |e: image::ImageError| {
            let eof = matches!(&e, image::ImageError::IoError(io)
                if io.kind() == std::io::ErrorKind::UnexpectedEof);
            let what = if eof {
                "the data ends early (truncated file?)".to_string()
            } else {
                e.to_string()
            };
            ctx.decode_error(format!("scanline {s} of {n1}: {what}"))
        };
        let reader = Cursor::new(&header[..]).chain(&mut data);
        let decoder = HdrDecoder::new(reader).map_err(scanline_error)?;
        decoder
            .read_image(&mut line_bytes)
            .map_err(scanline_error)?;
        scan.extend(
            line_bytes.chunks_exact(12).map(|c| {
                [0, 4, 8].map(|o| f32::from_ne_bytes([c[o], c[o + 1], c[o + 2], c[o + 3]]))
            }),
        );
    }

    let mut texels = if !a1.is_y || a1.positive || !a2.positive {
        notes.push(format!(
            "resolution line \"{t1} {n1} {t2} {n2}\" (not the standard -Y +X): \
             texels reordered to rows from the top, left to right"
        ));
        // +X runs left to right and -Y top to bottom; the other signs run backwards.
        let along = |axis: Axis, i: usize, len: usize| {
            if axis.positive != axis.is_y {
                i
            } else {
                len - 1 - i
            }
        };
        let mut out = vec![[0.0f32; 3]; n];
        for (index, texel) in scan.into_iter().enumerate() {
            let (s, p) = (index / n2, index % n2);
            let (x, y) = if a1.is_y {
                (along(a2, p, n2), along(a1, s, n1))
            } else {
                (along(a1, s, n1), along(a2, p, n2))
            };
            out[y * width + x] = texel;
        }
        out
    } else {
        scan
    };

    if let Some(value) = primaries_line {
        let numbers: Option<Vec<f64>> = value
            .split_ascii_whitespace()
            .map(|t| t.parse().ok().filter(|v: &f64| v.is_finite()))
            .collect();
        match numbers.and_then(|v| <[f64; 8]>::try_from(v).ok()) {
            Some(v) if v.iter().all(|&x| x == 0.0) => {} // Photoshop writes all zeros
            Some(v) => notes.extend(convert_primaries(
                &mut texels,
                &Chromaticities::from_values(v),
                "PRIMARIES line",
            )),
            None => notes.push(format!(
                "ignored the malformed header line PRIMARIES={}; texels taken as Rec.709",
                clip(&value, 60)
            )),
        }
    }
    Ok(Decoded {
        width,
        height,
        texels,
        notes,
    })
}

// ---------------------------------------------------------------------------
// OpenEXR

/// Where one EXR channel's samples go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Slot {
    Channel(usize),
    Grey,
}

/// The part and channels chosen from an EXR file.
struct ExrSelection {
    part: usize,
    /// Per channel of the part's channel list, where its samples go.
    slots: Vec<Option<Slot>>,
    notes: Vec<String>,
}

/// Picks the first layer (over parts, and over `prefix.` channel groups within a
/// part, the unprefixed group first) with R, G and B; else the first with Y.
fn select_exr_layer(
    headers: &[exr::meta::header::Header],
) -> std::result::Result<ExrSelection, String> {
    struct Group {
        part: usize,
        label: String,
        /// (base name, channel index)
        channels: Vec<(String, usize)>,
    }
    let mut groups: Vec<Group> = Vec::new();
    let mut all_names = Vec::new();
    let mut deep_parts = 0;
    for (part, header) in headers.iter().enumerate() {
        if header.deep {
            deep_parts += 1;
            continue;
        }
        let part_name = header
            .own_attributes
            .layer_name
            .as_ref()
            .map(|t| t.to_string());
        let first_group = groups.len();
        for (index, channel) in header.channels.list.iter().enumerate() {
            let full = channel.name.to_string();
            all_names.push(full.clone());
            let (prefix, base) = match full.rsplit_once('.') {
                Some((prefix, base)) => (prefix.to_string(), base.to_string()),
                None => (String::new(), full.clone()),
            };
            let label = match (&part_name, prefix.is_empty()) {
                (Some(p), true) => format!("\"{p}\""),
                (Some(p), false) => format!("\"{p}.{prefix}\""),
                (None, true) => "the default layer".to_string(),
                (None, false) => format!("\"{prefix}\""),
            };
            match groups[first_group..].iter_mut().find(|g| g.label == label) {
                Some(group) => group.channels.push((base, index)),
                None => {
                    let group = Group {
                        part,
                        label,
                        channels: vec![(base, index)],
                    };
                    // The unprefixed group of a part comes first.
                    if prefix.is_empty() {
                        groups.insert(first_group, group);
                    } else {
                        groups.push(group);
                    }
                }
            }
        }
    }
    let find = |group: &Group, name: &str| {
        group
            .channels
            .iter()
            .find(|(base, _)| base == name)
            .map(|&(_, i)| i)
    };
    let rgb = groups
        .iter()
        .find(|g| ["R", "G", "B"].iter().all(|c| find(g, c).is_some()));
    let grey = || groups.iter().find(|g| find(g, "Y").is_some());
    let (group, is_grey) = match (rgb, grey()) {
        (Some(g), _) => (g, false),
        (None, Some(g)) => (g, true),
        (None, None) => {
            if deep_parts > 0 && groups.is_empty() {
                return Err("deep (multi-sample) images are not supported".to_string());
            }
            let mut names = all_names.clone();
            names.truncate(16);
            return Err(format!(
                "no layer has R, G, B or Y channels (channels: {})",
                if names.is_empty() {
                    "none".to_string()
                } else {
                    names.join(", ")
                }
            ));
        }
    };
    let header = &headers[group.part];
    let mut slots = vec![None; header.channels.list.len()];
    let mut notes = Vec::new();
    if is_grey {
        if find(group, "RY").is_some() || find(group, "BY").is_some() {
            return Err(
                "luminance/chroma images (Y, RY, BY channels) are not supported".to_string(),
            );
        }
        if let Some(i) = find(group, "Y") {
            slots[i] = Some(Slot::Grey);
        }
        notes.push("luminance-only (Y) image: loaded as grey (R = G = B = Y)".to_string());
    } else {
        for (c, name) in ["R", "G", "B"].iter().enumerate() {
            if let Some(i) = find(group, name) {
                slots[i] = Some(Slot::Channel(c));
            }
        }
    }
    for (i, slot) in slots.iter().enumerate() {
        let channel = &header.channels.list[i];
        if slot.is_some() && channel.sampling != exr::math::Vec2(1, 1) {
            return Err(format!(
                "channel {} is subsampled ({}x{}), which is not supported",
                channel.name, channel.sampling.0, channel.sampling.1
            ));
        }
    }
    if groups.len() > 1 {
        let labels: Vec<&str> = groups.iter().map(|g| g.label.as_str()).take(8).collect();
        notes.push(format!(
            "the file has {} layers ({}{}); loaded {}",
            groups.len(),
            labels.join(", "),
            if groups.len() > 8 { ", ..." } else { "" },
            group.label
        ));
    }
    if find(group, "A").is_some() {
        notes.push("the alpha channel is ignored".to_string());
    }
    Ok(ExrSelection {
        part: group.part,
        slots,
        notes,
    })
}

fn exr_detail(error: exr::error::Error) -> String {
    match error {
        exr::error::Error::Invalid(message) if message == "reference to missing bytes" => {
            "the data ends early (truncated file?)".to_string()
        }
        other => other.to_string(),
    }
}

/// Bounds the sizes a DWAA/DWAB chunk's leader declares before the exr crate
/// (1.74) decodes it: its decoder takes them as allocation sizes unchecked, and a
/// malformed chunk of a few bytes (a fuzzing find, kept in
/// `fuzz/regressions/load/`) asks for terabytes, which aborts the process; no
/// caller could catch that. The leader is eleven little-endian u64 counters
/// (version; unknown uncompressed and compressed sizes; AC, DC, RLE compressed
/// sizes; RLE uncompressed and raw sizes; AC and DC value counts; AC coder). No
/// section of a valid chunk decodes to more than the block's bytes, nor holds more
/// values than the block has samples (each at least 2 bytes), so anything larger
/// is refused as corrupt. A chunk stored raw (its size the block's) or empty has no
/// leader.
fn check_dwa_chunk(chunk: &exr::block::chunk::Chunk, block_bytes: usize) -> Result<(), String> {
    use exr::block::chunk::CompressedBlock;
    let data = match &chunk.compressed_block {
        CompressedBlock::ScanLine(b) => &b.compressed_pixels_le,
        CompressedBlock::Tile(b) => &b.compressed_pixels_le,
        // Deep data is refused later, with its own message.
        _ => return Ok(()),
    };
    if data.is_empty() || data.len() == block_bytes || data.len() < 88 {
        return Ok(());
    }
    let counter = |k: usize| {
        let bytes: [u8; 8] = data[8 * k..8 * k + 8].try_into().unwrap_or([0xff; 8]);
        u64::from_le_bytes(bytes)
    };
    let limit = block_bytes as u64;
    // Sizes of decoded sections (unknown, RLE uncompressed and raw) and value
    // counts (AC, DC: 2 bytes each).
    for (k, name, max) in [
        (1, "unknown section size", limit),
        (6, "RLE section size", limit),
        (7, "RLE raw size", limit),
        (8, "AC value count", limit / 2 + 64),
        (9, "DC value count", limit / 2 + 64),
    ] {
        let value = counter(k);
        if value > max {
            return Err(format!(
                "corrupt DWA chunk: its {name} is {value}, more than its block of {block_bytes} bytes can hold"
            ));
        }
    }
    Ok(())
}

/// An OpenEXR image's texels as its blocks decode, allocated as the decoded data
/// grows: an image of up to [`CANVAS_AT_ONCE`] texels at once; a larger one from
/// the top, row by row, as far as twice the texels decoded so far. A block further
/// down (a file stored bottom-up, or in random order) is held on its own until
/// half of the image has decoded. So a file that declares a large image but holds
/// little data never has the image allocated.
struct Canvas {
    width: usize,
    texels: usize,
    /// The image's top rows, zero where no block has decoded yet.
    rows: Vec<[f32; 3]>,
    held: Vec<Region>,
    decoded: usize,
}

/// One block's rectangle, with its own texels when it lies below the rows.
struct Region {
    x0: usize,
    y0: usize,
    width: usize,
    height: usize,
    own: Option<Vec<[f32; 3]>>,
}

/// Texels (12 bytes each, 16 MiB) of an image allocated before any block decodes.
const CANVAS_AT_ONCE: usize = (16 << 20) / 12;

impl Canvas {
    fn new(width: usize, height: usize) -> Self {
        let texels = width * height;
        Self {
            width,
            texels,
            rows: if texels <= CANVAS_AT_ONCE {
                vec![[0.0; 3]; texels]
            } else {
                Vec::new()
            },
            held: Vec::new(),
            decoded: 0,
        }
    }

    /// Extends the rows to `end` texels if that is at most twice the texels
    /// decoded (or [`CANVAS_AT_ONCE`]); the capacity at least doubles each time,
    /// never past the image.
    fn grow(&mut self, end: usize) -> bool {
        if end <= self.rows.len() {
            return true;
        }
        if end > CANVAS_AT_ONCE.max(2 * self.decoded) {
            return false;
        }
        if end > self.rows.capacity() {
            let capacity = end.max(2 * self.rows.capacity()).min(self.texels);
            self.rows.reserve_exact(capacity - self.rows.len());
        }
        self.rows.resize(end, [0.0; 3]);
        true
    }

    /// Starts the block of `width` × `height` texels at (`x0`, `y0`), which lies
    /// inside the image.
    fn begin(&mut self, x0: usize, y0: usize, width: usize, height: usize) -> Region {
        self.decoded += width * height;
        let in_rows = self.grow((y0 + height) * self.width);
        Region {
            x0,
            y0,
            width,
            height,
            own: (!in_rows).then(|| vec![[0.0; 3]; width * height]),
        }
    }

    /// The `count` texels from (`x`, `y`) of `region`, `None` when they leave it.
    fn row<'a>(
        &'a mut self,
        region: &'a mut Region,
        x: usize,
        y: usize,
        count: usize,
    ) -> Option<&'a mut [[f32; 3]]> {
        let (dx, dy) = (x.checked_sub(region.x0)?, y.checked_sub(region.y0)?);
        if dy >= region.height || dx.checked_add(count)? > region.width {
            return None;
        }
        let (texels, start) = match &mut region.own {
            Some(own) => (own, dy * region.width + dx),
            None => (&mut self.rows, y * self.width + x),
        };
        texels.get_mut(start..start + count)
    }

    /// Ends `region`: a held block waits until half of the image has decoded,
    /// then all held blocks go into the rows.
    fn end(&mut self, region: Region) {
        if region.own.is_some() {
            self.held.push(region);
        }
        if !self.held.is_empty() && 2 * self.decoded >= self.texels && self.grow(self.texels) {
            for region in std::mem::take(&mut self.held) {
                let own = region.own.unwrap_or_default();
                for (dy, line) in own.chunks_exact(region.width).enumerate() {
                    let start = (region.y0 + dy) * self.width + region.x0;
                    self.rows[start..start + region.width].copy_from_slice(line);
                }
            }
        }
    }

    /// The image, `None` unless every row is there.
    fn finish(self) -> Option<Vec<[f32; 3]>> {
        (self.rows.len() == self.texels && self.held.is_empty()).then_some(self.rows)
    }
}

fn decode_exr(ctx: &Ctx<'_>, bytes: &[u8]) -> Result<Decoded> {
    use exr::block::reader::ChunksReader;
    use exr::block::UncompressedBlock;
    use exr::meta::attribute::SampleType;
    use exr::prelude::f16;
    use rayon::prelude::*;

    let exr_error = |e: exr::error::Error| ctx.decode_error(exr_detail(e));
    // Reads the headers only; the offset tables and pixels come after the checks.
    let reader = exr::block::read(Cursor::new(bytes), false).map_err(exr_error)?;
    let selection = select_exr_layer(reader.headers()).map_err(|d| ctx.decode_error(d))?;
    let part = selection.part;
    let header = reader.headers()[part].clone();
    let dwa = matches!(
        header.compression,
        exr::compression::Compression::DWAA(_) | exr::compression::Compression::DWAB(_)
    );
    let (width, height) = (header.layer_size.0, header.layer_size.1);
    let n = ctx.check_dimensions(width, height)?;
    let mut notes = selection.notes;
    let data_window = header.data_window();
    let display_window = header.shared_attributes.display_window;
    if data_window != display_window {
        notes.push(format!(
            "the data window ({}x{} at ({}, {})) differs from the display window \
             ({}x{} at ({}, {})); loaded the data window",
            data_window.size.0,
            data_window.size.1,
            data_window.position.0,
            data_window.position.1,
            display_window.size.0,
            display_window.size.1,
            display_window.position.0,
            display_window.position.1
        ));
    }

    check_exr_chunk_table(
        bytes,
        reader.headers(),
        reader.meta_data().requirements.is_multilayer(),
        part,
    )
    .map_err(|d| ctx.decode_error(d))?;
    let mut chunks = reader
        .filter_chunks(false, |_, tile, block| {
            block.layer == part && tile.is_largest_resolution_level()
        })
        .map_err(exr_error)?;
    let mut canvas = Canvas::new(width, height);
    let mut blocks_seen = HashSet::new();
    let mut covered = 0usize;
    let batch_size = 2 * rayon::current_num_threads().max(1);
    loop {
        // A batch of chunks, each checked before it is decompressed, with at most
        // IN_FLIGHT_BYTES of decompressed blocks (and at least one block).
        let mut batch = Vec::with_capacity(batch_size);
        let mut batch_bytes = 0usize;
        while batch.len() < batch_size && batch_bytes < IN_FLIGHT_BYTES {
            let Some(chunk) = chunks.next() else {
                break;
            };
            let chunk = chunk.map_err(exr_error)?;
            if chunk.layer_index != part {
                continue;
            }
            if let Some(block_bytes) = exr_block_bytes(&chunk, &header) {
                check_exr_expansion(&chunk, &header, block_bytes)
                    .map_err(|d| ctx.decode_error(d))?;
                batch_bytes = batch_bytes.saturating_add(block_bytes);
            }
            if dwa {
                check_dwa_chunk(&chunk, header.max_block_byte_size())
                    .map_err(|d| ctx.decode_error(d))?;
            }
            batch.push(chunk);
        }
        if batch.is_empty() {
            break;
        }
        // Decompress in parallel; a panic in a worker is re-raised here, on the
        // caller's thread, where `load_from_memory` catches it.
        let meta = chunks.meta_data();
        let blocks: Vec<exr::error::Result<UncompressedBlock>> = batch
            .into_par_iter()
            .map(|chunk| UncompressedBlock::decompress_chunk(chunk, meta, false))
            .collect();
        for block in blocks {
            let block = block.map_err(exr_error)?;
            let index = block.index;
            if index.layer != part || index.level != exr::math::Vec2(0, 0) {
                continue;
            }
            let (x0, y0) = (index.pixel_position.0, index.pixel_position.1);
            let (bw, bh) = (index.pixel_size.0, index.pixel_size.1);
            if x0.checked_add(bw).is_none_or(|e| e > width)
                || y0.checked_add(bh).is_none_or(|e| e > height)
            {
                return Err(ctx.decode_error(format!(
                    "a block of {bw}x{bh} texels at ({x0}, {y0}) lies outside the \
                     {width}x{height} data window"
                )));
            }
            if !blocks_seen.insert((x0, y0)) {
                return Err(ctx.decode_error(format!("the block at ({x0}, {y0}) is stored twice")));
            }
            covered += bw * bh;
            let mut region = canvas.begin(x0, y0, bw, bh);
            for line in block.lines(&header.channels) {
                let Some(slot) = selection.slots[line.location.channel] else {
                    continue;
                };
                let (x, y) = (line.location.position.0, line.location.position.1);
                let count = line.location.sample_count;
                let Some(row) = canvas.row(&mut region, x, y, count) else {
                    return Err(ctx.decode_error("a scanline lies outside its block"));
                };
                let put = |texel: &mut [f32; 3], value: f32| match slot {
                    Slot::Channel(c) => texel[c] = value,
                    Slot::Grey => *texel = [value; 3],
                };
                let sample_type = header.channels.list[line.location.channel].sample_type;
                match sample_type {
                    SampleType::F16 => {
                        for (texel, value) in row.iter_mut().zip(line.read_samples::<f16>()) {
                            put(texel, value.map_err(exr_error)?.to_f32());
                        }
                    }
                    SampleType::F32 => {
                        for (texel, value) in row.iter_mut().zip(line.read_samples::<f32>()) {
                            put(texel, value.map_err(exr_error)?);
                        }
                    }
                    SampleType::U32 => {
                        for (texel, value) in row.iter_mut().zip(line.read_samples::<u32>()) {
                            put(texel, value.map_err(exr_error)? as f32);
                        }
                    }
                }
            }
            canvas.end(region);
        }
    }
    let mut texels = match canvas.finish() {
        Some(texels) if covered == n => texels,
        _ => {
            return Err(ctx.decode_error(format!(
                "the file's blocks cover {covered} of the {n} texels of the data window \
                 (missing or corrupt chunks)"
            )))
        }
    };

    if let Some(c) = header.shared_attributes.chromaticities {
        let file = Chromaticities {
            red: [f64::from(c.red.0), f64::from(c.red.1)],
            green: [f64::from(c.green.0), f64::from(c.green.1)],
            blue: [f64::from(c.blue.0), f64::from(c.blue.1)],
            white: [f64::from(c.white.0), f64::from(c.white.1)],
        };
        notes.extend(convert_primaries(
            &mut texels,
            &file,
            "chromaticities attribute",
        ));
    }
    Ok(Decoded {
        width,
        height,
        texels,
        notes,
    })
}

// ---------------------------------------------------------------------------
// PFM

fn decode_pfm(ctx: &Ctx<'_>, bytes: &[u8]) -> Result<Decoded> {
    let grey = bytes[1] == b'f';
    let channels = if grey { 1 } else { 3 };
    let mut pos = 2;
    let mut token = |what: &str| -> Result<String> {
        while bytes.get(pos).is_some_and(|b| b.is_ascii_whitespace()) {
            pos += 1;
        }
        let start = pos;
        while bytes.get(pos).is_some_and(|b| !b.is_ascii_whitespace()) {
            pos += 1;
            if pos - start > 40 {
                return Err(ctx.decode_error(format!("the {what} in the header is too long")));
            }
        }
        if start == pos {
            return Err(ctx.decode_error(format!("the header ends before the {what}")));
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let parse_side = |text: String, what: &str| -> Result<usize> {
        text.parse().map_err(|_| {
            ctx.decode_error(format!(
                "the {what} \"{text}\" is not a non-negative integer"
            ))
        })
    };
    let width = parse_side(token("width")?, "width")?;
    let height = parse_side(token("height")?, "height")?;
    let scale_text = token("scale")?;
    let scale: f32 = scale_text
        .parse()
        .ok()
        .filter(|s: &f32| s.is_finite() && *s != 0.0)
        .ok_or_else(|| {
            ctx.decode_error(format!(
                "the scale \"{scale_text}\" is not a non-zero finite number \
                 (its sign gives the byte order)"
            ))
        })?;
    let n = ctx.check_dimensions(width, height)?;
    // Exactly one whitespace byte separates the scale from the raster.
    let data = bytes.get(pos + 1..).unwrap_or(&[]);
    let expected = n
        .checked_mul(channels * 4)
        .ok_or_else(|| ctx.decode_error("the raster size overflows"))?;
    if data.len() < expected {
        return Err(ctx.decode_error(format!(
            "truncated raster: {width}x{height} {} texels need {expected} bytes after the \
             header, but only {} are present",
            if grey { "grey" } else { "colour" },
            data.len()
        )));
    }
    let little_endian = scale < 0.0;
    let value = |offset: usize| {
        let b = [
            data[offset],
            data[offset + 1],
            data[offset + 2],
            data[offset + 3],
        ];
        if little_endian {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut texels = Vec::with_capacity(n);
    for y in 0..height {
        // Rows are stored bottom-to-top.
        let row_start = (height - 1 - y) * width * channels * 4;
        for x in 0..width {
            let offset = row_start + x * channels * 4;
            texels.push(if grey {
                [value(offset); 3]
            } else {
                [value(offset), value(offset + 4), value(offset + 8)]
            });
        }
    }
    let mut notes = Vec::new();
    if scale.abs() != 1.0 {
        notes.push(format!(
            "the PFM scale {scale} is not applied: texel values are used as stored"
        ));
    }
    if data.len() > expected {
        notes.push(format!(
            "{} bytes after the raster were ignored",
            data.len() - expected
        ));
    }
    Ok(Decoded {
        width,
        height,
        texels,
        notes,
    })
}

// ---------------------------------------------------------------------------
// PNG and JPEG

fn decode_ldr(ctx: &Ctx<'_>, bytes: &[u8]) -> Result<Decoded> {
    use image::codecs::{jpeg::JpegDecoder, png::PngDecoder};

    let image = match ctx.format {
        ImageFormat::Png => decode_with(ctx, bytes.len(), PngDecoder::new(Cursor::new(bytes)))?,
        _ => decode_with(ctx, bytes.len(), JpegDecoder::new(Cursor::new(bytes)))?,
    };
    let mut notes = Vec::new();
    let color = image.color();
    if color.has_alpha() {
        notes.push("the alpha channel is ignored".to_string());
    }
    notes.push(format!(
        "{} is a low-dynamic-range format: {}-bit sRGB values were decoded to linear [0, 1], \
         so bright light sources are clipped",
        ctx.format.long_name(),
        color.bits_per_pixel() / u16::from(color.channel_count())
    ));
    let (width, height) = (image.width() as usize, image.height() as usize);
    let rgb = image.to_rgb32f();
    drop(image);
    let texels = rgb
        .into_raw()
        .chunks_exact(3)
        .map(|c| {
            [
                srgb_to_linear(c[0]),
                srgb_to_linear(c[1]),
                srgb_to_linear(c[2]),
            ]
        })
        .collect();
    Ok(Decoded {
        width,
        height,
        texels,
        notes,
    })
}

/// Checks the declared size, against the limit and against the `len` bytes of
/// input, then decodes all pixels.
fn decode_with<D: image::ImageDecoder>(
    ctx: &Ctx<'_>,
    len: usize,
    decoder: image::ImageResult<D>,
) -> Result<image::DynamicImage> {
    let decoder = decoder.map_err(|e| ctx.decode_error(e.to_string()))?;
    let (width, height) = decoder.dimensions();
    ctx.check_dimensions(width as usize, height as usize)?;
    let bits = usize::from(decoder.original_color_type().bits_per_pixel());
    ldr_data_fits(
        ctx.format == ImageFormat::Png,
        width as usize,
        height as usize,
        bits,
        len,
    )
    .map_err(|d| ctx.decode_error(d))?;
    image::DynamicImage::from_decoder(decoder).map_err(|e| ctx.decode_error(e.to_string()))
}
