//! RGB float images: writing (`.exr`, `.pfm` linear; `.png` tone mapped), reading
//! (`.exr`, `.pfm`, for reference renders) and the display transform.

use crate::rgb::Rgb;
use crate::RenderError;
use std::io::Write;
use std::path::Path;

/// A linear RGB `f32` image, row-major, row 0 at the top.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    width: usize,
    height: usize,
    pixels: Vec<Rgb>,
}

impl Image {
    /// An image from its pixels.
    ///
    /// # Panics
    /// When `pixels.len() != width * height` (a programming error).
    pub fn new(width: usize, height: usize, pixels: Vec<Rgb>) -> Self {
        assert_eq!(
            pixels.len(),
            width * height,
            "pixel count must be width*height"
        );
        Self {
            width,
            height,
            pixels,
        }
    }

    /// An image filled with `value`.
    pub fn filled(width: usize, height: usize, value: Rgb) -> Self {
        Self::new(width, height, vec![value; width * height])
    }

    /// Width in pixels.
    pub fn width(&self) -> usize {
        self.width
    }

    /// Height in pixels.
    pub fn height(&self) -> usize {
        self.height
    }

    /// All pixels, row-major.
    pub fn pixels(&self) -> &[Rgb] {
        &self.pixels
    }

    /// The pixel at column `x`, row `y`.
    pub fn pixel(&self, x: usize, y: usize) -> Rgb {
        self.pixels[y * self.width + x]
    }

    /// Bytes of an 8-bit sRGB rendition: `2^exposure` times the radiance, an
    /// ACES-style filmic curve, then the sRGB transfer function. Row-major RGB.
    pub fn to_srgb8(&self, exposure: f32) -> Vec<u8> {
        let gain = exposure.exp2();
        self.pixels
            .iter()
            .flat_map(|p| p.map(|c| encode_display(c * gain)))
            .collect()
    }
}

/// An exposure (in stops) that maps the image's log-average luminance to middle
/// grey 0.18 (Reinhard et al. 2002's key value): `log2(0.18 / exp(mean ln(δ + Y)))`
/// with `δ = 10⁻⁴`, over finite pixels; 0 for an empty or black image. Clamped to
/// ±20 stops.
pub fn auto_exposure(image: &Image) -> f32 {
    let (mut sum, mut n) = (0.0f64, 0usize);
    for p in image.pixels() {
        let y = envlight::color::luminance(*p);
        if y.is_finite() && y >= 0.0 {
            sum += (1e-4 + y as f64).ln();
            n += 1;
        }
    }
    if n == 0 {
        return 0.0;
    }
    let log_average = (sum / n as f64).exp();
    if log_average <= 1.1e-4 {
        return 0.0;
    }
    ((0.18 / log_average).log2() as f32).clamp(-20.0, 20.0)
}

/// Krzysztof Narkowicz's fit of the ACES reference rendering transform,
/// `x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)`, applied to `0.6 x` (the fit
/// expects that pre-exposure), clamped to `[0, 1]`. NaN maps to 0.
#[inline]
pub fn aces_filmic(x: f32) -> f32 {
    let x = if x.is_nan() { 0.0 } else { 0.6 * x.max(0.0) };
    let y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
    if y.is_finite() {
        y.clamp(0.0, 1.0)
    } else {
        1.0
    }
}

#[inline]
fn encode_display(linear: f32) -> u8 {
    let v = envlight::color::linear_to_srgb(aces_filmic(linear));
    (v * 255.0 + 0.5) as u8
}

/// Output formats, chosen by file extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageFormat {
    /// OpenEXR, 32-bit float RGB (linear).
    Exr,
    /// Portable float map, colour (linear).
    Pfm,
    /// 8-bit PNG, tone mapped.
    Png,
}

impl ImageFormat {
    /// The format named by `path`'s extension (case-insensitive).
    ///
    /// # Errors
    /// [`RenderError::UnsupportedFormat`] for any other extension.
    pub fn from_path(path: &Path) -> Result<Self, RenderError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(|e| e.to_ascii_lowercase());
        match ext.as_deref() {
            Some("exr") => Ok(Self::Exr),
            Some("pfm") => Ok(Self::Pfm),
            Some("png") => Ok(Self::Png),
            _ => Err(RenderError::UnsupportedFormat {
                path: path.display().to_string(),
            }),
        }
    }
}

/// Encodes `image` in `format` (`exposure` in stops applies to PNG only).
///
/// # Errors
/// [`RenderError::Encode`] when the encoder fails.
pub fn encode_image(
    image: &Image,
    format: ImageFormat,
    exposure: f32,
) -> Result<Vec<u8>, RenderError> {
    match format {
        ImageFormat::Pfm => Ok(encode_pfm(image)),
        ImageFormat::Png => encode_png(
            &image.to_srgb8(exposure),
            image.width as u32,
            image.height as u32,
        ),
        ImageFormat::Exr => {
            use exr::prelude::{Image as ExrImage, SpecificChannels, Vec2, WritableImage};
            let channels = SpecificChannels::rgb(|Vec2(x, y): Vec2<usize>| {
                let p = image.pixel(x, y);
                (p[0], p[1], p[2])
            });
            let exr = ExrImage::from_channels((image.width, image.height), channels);
            let mut out = std::io::Cursor::new(Vec::new());
            exr.write()
                .to_buffered(&mut out)
                .map_err(|e| RenderError::Encode {
                    format: "OpenEXR",
                    detail: e.to_string(),
                })?;
            Ok(out.into_inner())
        }
    }
}

/// Encodes 8-bit RGB bytes as PNG.
pub(crate) fn encode_png(rgb: &[u8], width: u32, height: u32) -> Result<Vec<u8>, RenderError> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(rgb, width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| RenderError::Encode {
            format: "PNG",
            detail: e.to_string(),
        })?;
    Ok(out)
}

/// Colour PFM: header `PF\n{w} {h}\n-1.0\n` (little-endian), rows bottom to top.
fn encode_pfm(image: &Image) -> Vec<u8> {
    let mut out = format!("PF\n{} {}\n-1.0\n", image.width, image.height).into_bytes();
    out.reserve(image.pixels.len() * 12);
    for y in (0..image.height).rev() {
        for p in &image.pixels[y * image.width..(y + 1) * image.width] {
            for c in p {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
    }
    out
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a
/// rename, so a failure never leaves a partial file nor destroys an existing one.
pub(crate) fn write_atomically(path: &Path, bytes: &[u8]) -> Result<(), RenderError> {
    let io = |error| RenderError::Io {
        path: path.display().to_string(),
        error,
    };
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dir.join(format!(".{name}.tmp-{}", std::process::id()));
    let result = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result.map_err(io)
}

/// Writes `image` to `path`, the format chosen by the extension: `.exr` and `.pfm`
/// keep the linear float values; `.png` applies `exposure` (stops), the ACES-style
/// curve [`aces_filmic`] and sRGB encoding. The file appears complete or not at all.
///
/// # Errors
/// [`RenderError::UnsupportedFormat`], [`RenderError::Encode`], [`RenderError::Io`].
pub fn write_image(path: &Path, image: &Image, exposure: f32) -> Result<(), RenderError> {
    let format = ImageFormat::from_path(path)?;
    let bytes = encode_image(image, format, exposure)?;
    write_atomically(path, &bytes)
}

/// Reads a linear image (a reference render) from `.exr` (first RGB(A) layer) or
/// `.pfm` (colour or greyscale, either byte order).
///
/// # Errors
/// [`RenderError::UnsupportedFormat`], [`RenderError::Io`], [`RenderError::Decode`].
pub fn read_image(path: &Path) -> Result<Image, RenderError> {
    let name = path.display().to_string();
    match ImageFormat::from_path(path)? {
        ImageFormat::Exr => {
            use exr::prelude::read_first_rgba_layer_from_file;
            let decoded = read_first_rgba_layer_from_file(
                path,
                |resolution, _| Image::filled(resolution.width(), resolution.height(), [0.0; 3]),
                |img: &mut Image, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
                    let w = img.width;
                    img.pixels[pos.y() * w + pos.x()] = [r, g, b];
                },
            )
            .map_err(|e| match e {
                exr::error::Error::Io(error) => RenderError::Io {
                    path: name.clone(),
                    error,
                },
                other => RenderError::Decode {
                    path: name.clone(),
                    format: "OpenEXR",
                    detail: other.to_string(),
                },
            })?;
            Ok(decoded.layer_data.channel_data.pixels)
        }
        ImageFormat::Pfm => {
            let bytes = std::fs::read(path).map_err(|error| RenderError::Io {
                path: name.clone(),
                error,
            })?;
            decode_pfm(&bytes).map_err(|detail| RenderError::Decode {
                path: name,
                format: "PFM",
                detail,
            })
        }
        ImageFormat::Png => Err(RenderError::UnsupportedFormat { path: name }),
    }
}

/// Decodes PFM bytes (`PF` colour or `Pf` greyscale).
fn decode_pfm(bytes: &[u8]) -> Result<Image, String> {
    // Three whitespace-separated header tokens after the magic, then one whitespace byte.
    let mut pos = 0;
    let mut token = || -> Result<String, String> {
        while pos < bytes.len() && bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        let start = pos;
        while pos < bytes.len() && !bytes[pos].is_ascii_whitespace() {
            pos += 1;
        }
        if start == pos {
            return Err("truncated header".into());
        }
        Ok(String::from_utf8_lossy(&bytes[start..pos]).into_owned())
    };
    let magic = token()?;
    let channels = match magic.as_str() {
        "PF" => 3,
        "Pf" => 1,
        other => return Err(format!("bad magic '{other}'")),
    };
    let width: usize = token()?.parse().map_err(|_| "bad width".to_string())?;
    let height: usize = token()?.parse().map_err(|_| "bad height".to_string())?;
    let scale: f32 = token()?.parse().map_err(|_| "bad scale".to_string())?;
    let data = &bytes[(pos + 1).min(bytes.len())..];
    let count = width
        .checked_mul(height)
        .and_then(|n| n.checked_mul(channels))
        .ok_or("image too large")?;
    if width == 0 || height == 0 || data.len() < count * 4 {
        return Err(format!(
            "{width}x{height}x{channels} needs {} data bytes, found {}",
            count.saturating_mul(4),
            data.len()
        ));
    }
    let little = scale < 0.0;
    let value = |k: usize| {
        let b = [
            data[4 * k],
            data[4 * k + 1],
            data[4 * k + 2],
            data[4 * k + 3],
        ];
        if little {
            f32::from_le_bytes(b)
        } else {
            f32::from_be_bytes(b)
        }
    };
    let mut pixels = vec![[0.0f32; 3]; width * height];
    for y in 0..height {
        let src_row = height - 1 - y;
        for x in 0..width {
            let k = (src_row * width + x) * channels;
            pixels[y * width + x] = if channels == 3 {
                [value(k), value(k + 1), value(k + 2)]
            } else {
                [value(k); 3]
            };
        }
    }
    Ok(Image::new(width, height, pixels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pfm_round_trips() {
        let img = Image::new(3, 2, (0..6).map(|i| [i as f32, 0.5, -1.0]).collect());
        let back = decode_pfm(&encode_pfm(&img)).unwrap();
        assert_eq!(back, img);
        assert!(decode_pfm(b"PF\n3 2\n-1.0\n\0\0").is_err());
    }

    #[test]
    fn auto_exposure_maps_the_log_average_to_middle_grey() {
        let img = Image::filled(4, 4, [0.72; 3]);
        assert!(
            (auto_exposure(&img) + 2.0).abs() < 1e-3,
            "{}",
            auto_exposure(&img)
        );
        assert_eq!(auto_exposure(&Image::filled(2, 2, [0.0; 3])), 0.0);
    }

    #[test]
    fn tone_curve_is_monotone_and_bounded() {
        let mut prev = 0.0;
        for i in 0..1000 {
            let y = aces_filmic(i as f32 * 0.05);
            assert!(y >= prev && (0.0..=1.0).contains(&y));
            prev = y;
        }
        assert_eq!(aces_filmic(f32::NAN), 0.0);
        assert_eq!(aces_filmic(f32::INFINITY), 1.0);
    }

    #[test]
    fn files_round_trip_through_disk() {
        let dir = std::env::temp_dir().join(format!("envlight-render-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let img = Image::new(4, 3, (0..12).map(|i| [i as f32 * 0.25, 1.0, 2.0]).collect());
        for ext in ["exr", "pfm"] {
            let p = dir.join(format!("t.{ext}"));
            write_image(&p, &img, 0.0).unwrap();
            assert_eq!(read_image(&p).unwrap(), img, "{ext}");
        }
        let p = dir.join("t.png");
        write_image(&p, &img, 0.0).unwrap();
        assert!(std::fs::metadata(&p).unwrap().len() > 0);
        assert!(write_image(&dir.join("t.bmp"), &img, 0.0).is_err());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
