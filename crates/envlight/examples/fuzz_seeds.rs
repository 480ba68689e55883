//! Writes the seed corpora of the fuzz targets (`fuzz/fuzz_targets/`): small valid
//! inputs of every format and variant the decoders read, so a short fuzz run starts
//! deep inside the parsers instead of spending its seconds finding a magic number.
//!
//! `cargo run --release -p envlight --example fuzz_seeds -- fuzz/seeds`
//!
//! One folder per target under the given directory; each folder's files are
//! replaced. The output is byte-for-byte the same on every run (no clocks, no hash
//! maps, single-threaded OpenEXR writing); the GPU tables depend on the platform's
//! `sin`/`cos` through the light's solid-angle weights, like any table the light
//! builds. Every seed is checked before it is written: the image seeds load, the
//! GPU tables parse back to the same tables, and every compressed OpenEXR seed has
//! a chunk stored compressed (a chunk that does not shrink is stored raw, and its
//! decompressor would never run).
//!
//! What each target reads (see its source):
//! - `load_hdr`, `load_exr`, `load_pfm`: a file without the magic the target
//!   prepends (`#?RADIANCE\n`, `76 2f 31 01`, `P`);
//! - `load_ldr`: a selector byte (even: PNG, odd: JPEG), then the file without its
//!   signature;
//! - `load_any`: whole files of every format;
//! - `gpu_tables`: a GPU table file without its magic and version (12 bytes);
//! - `distribution`: a shape byte (the grid's width is `shape % count`), then
//!   little-endian `f32` values.

use std::error::Error;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use envlight::gpu::{GpuTableOptions, GpuTables, RadianceFormat};
use envlight::light::{Density, Mapping, Sampler};
use envlight::load::{load_from_memory, ImageFormat, LoadOptions};
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation};

type Seed = (String, Vec<u8>);

fn main() -> Result<(), Box<dyn Error>> {
    let out = std::env::args_os()
        .nth(1)
        .map(PathBuf::from)
        .ok_or("usage: fuzz_seeds OUT_DIR (the repository's fuzz/seeds)")?;

    let hdr = hdr_seeds();
    let exr = exr_seeds()?;
    let pfm = pfm_seeds();
    let png = png_seeds()?;
    let jpeg = jpeg_seeds()?;
    for (format, seeds) in [
        (ImageFormat::RadianceHdr, &hdr),
        (ImageFormat::OpenExr, &exr),
        (ImageFormat::Pfm, &pfm),
        (ImageFormat::Png, &png),
        (ImageFormat::Jpeg, &jpeg),
    ] {
        for (name, bytes) in seeds {
            check_loads(name, bytes, format)?;
        }
    }

    let mut targets: Vec<(&str, Vec<Seed>)> = vec![
        (
            "load_hdr",
            hdr.iter()
                .filter_map(|(name, bytes)| strip(name, bytes, b"#?RADIANCE\n"))
                .collect(),
        ),
        (
            "load_exr",
            exr.iter()
                .filter_map(|(name, bytes)| strip(name, bytes, &[0x76, 0x2f, 0x31, 0x01]))
                .collect(),
        ),
        (
            "load_pfm",
            pfm.iter()
                .filter_map(|(name, bytes)| strip(name, bytes, b"P"))
                .collect(),
        ),
        ("load_ldr", ldr_target(&png, &jpeg)),
        ("load_any", [hdr, exr, pfm, png, jpeg].concat()),
        ("gpu_tables", gpu_seeds()?),
        ("distribution", distribution_seeds()),
        ("visibility_cache", visibility_seeds()?),
    ];
    for (target, seeds) in &mut targets {
        seeds.sort();
        write_target(&out, target, seeds)?;
    }
    Ok(())
}

/// `bytes` without `prefix`, named `name` without its extension; `None` when the
/// file does not start with `prefix` (a variant only `load_any` can take).
fn strip(name: &str, bytes: &[u8], prefix: &[u8]) -> Option<Seed> {
    let stem = name.rsplit_once('.').map_or(name, |(stem, _)| stem);
    Some((stem.to_string(), bytes.strip_prefix(prefix)?.to_vec()))
}

/// `load_ldr`'s inputs: selector byte 0 and a PNG without its 8-byte signature, or
/// selector byte 1 and a JPEG without its 3-byte marker.
fn ldr_target(png: &[Seed], jpeg: &[Seed]) -> Vec<Seed> {
    let with_selector = |seeds: &[Seed], selector: u8, signature: usize| {
        seeds
            .iter()
            .map(|(name, bytes)| {
                let stem = name.rsplit_once('.').map_or(name.as_str(), |(s, _)| s);
                let mut data = vec![selector];
                data.extend_from_slice(&bytes[signature..]);
                (
                    format!("{stem}-{}", if selector == 0 { "png" } else { "jpeg" }),
                    data,
                )
            })
            .collect::<Vec<_>>()
    };
    [with_selector(png, 0, 8), with_selector(jpeg, 1, 3)].concat()
}

/// Replaces the files of `out/target` with `seeds` and prints a one-line summary.
fn write_target(out: &Path, target: &str, seeds: &[Seed]) -> Result<(), Box<dyn Error>> {
    let dir = out.join(target);
    if dir.exists() {
        for entry in std::fs::read_dir(&dir)? {
            let path = entry?.path();
            if !path.is_file() {
                return Err(
                    format!("{}: not a seed file; remove it by hand", path.display()).into(),
                );
            }
            std::fs::remove_file(&path)?;
        }
    } else {
        std::fs::create_dir_all(&dir)?;
    }
    for (name, bytes) in seeds {
        std::fs::write(dir.join(name), bytes)?;
    }
    let total: usize = seeds.iter().map(|(_, b)| b.len()).sum();
    let largest = seeds.iter().map(|(_, b)| b.len()).max().unwrap_or(0);
    println!(
        "{target:>12}: {:>3} seeds, {total:>6} bytes (largest {largest})",
        seeds.len()
    );
    Ok(())
}

/// Every image seed must decode as its format under the fuzz targets' limit.
fn check_loads(name: &str, bytes: &[u8], format: ImageFormat) -> Result<(), Box<dyn Error>> {
    let options = LoadOptions {
        max_texels: 1 << 20,
        replace_non_finite: false,
    };
    let loaded = load_from_memory(name, bytes, &options)?;
    if loaded.format != format {
        return Err(format!("{name}: loaded as {}, not {format}", loaded.format).into());
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// The pictures

/// A small map with what the loaders and tables should meet: flat rows (so the
/// run-length and dictionary coders have runs to find), a gradient, black texels
/// and one hot texel. Arithmetic only, so every platform computes the same bits.
fn texel(x: usize, y: usize, width: usize, height: usize) -> [f32; 3] {
    if (x, y) == (width / 3, height / 4) {
        [40.0, 30.0, 20.0]
    } else if y < height / 2 {
        // Sky: one colour per row.
        [0.25, 0.375 + 0.125 * y as f32, 0.75]
    } else if (x + 2 * y).is_multiple_of(7) {
        [0.0; 3]
    } else {
        let t = (x as f32 + 0.5) / width as f32;
        [0.125 + t, 0.25 * t, 0.0625]
    }
}

fn texels(width: usize, height: usize) -> Vec<[f32; 3]> {
    (0..height)
        .flat_map(|y| (0..width).map(move |x| texel(x, y, width, height)))
        .collect()
}

/// A smooth picture for the OpenEXR compressions: dyadic values in [0.5, 1), so
/// the samples use few distinct 16-bit codes (PIZ stores a bitmap of them) and
/// `f32` samples have zero low mantissa bits.
fn smooth_texel(x: usize, y: usize, width: usize, height: usize) -> [f32; 3] {
    [
        0.5 + x as f32 / (2 * width) as f32,
        0.5 + y as f32 / (2 * height) as f32,
        0.75,
    ]
}

/// sRGB-ish 8-bit values of [`texel`], clipped (the LDR seeds only need structure).
fn texel8(x: usize, y: usize, width: usize, height: usize) -> [u8; 3] {
    texel(x, y, width, height).map(|c| (c.min(1.0) * 255.0) as u8)
}

// ---------------------------------------------------------------------------
// Radiance HDR

/// RGBE of a texel: the shared exponent of the largest channel, 8-bit mantissas
/// (truncated). Powers of two built from bits keep the scaling exact (for channels
/// below 2^100, as in the seed pictures).
fn rgbe([r, g, b]: [f32; 3]) -> [u8; 4] {
    let m = r.max(g).max(b);
    if m.is_nan() || m < 1e-32 {
        return [0; 4];
    }
    // m = f · 2^e with f in [0.5, 1).
    let e = ((m.to_bits() >> 23) & 0xff) as i32 - 126;
    let scale = f32::from_bits(((127 + 8 - e) as u32) << 23); // 2^(8 - e)
    [
        (r * scale) as u8,
        (g * scale) as u8,
        (b * scale) as u8,
        (e + 128) as u8,
    ]
}

/// A scanline stored flat: 4 bytes per texel.
fn scanline_flat(pixels: &[[u8; 4]]) -> Vec<u8> {
    pixels.concat()
}

/// A scanline in new-style RLE: the marker `2 2 w>>8 w&255`, then each of the four
/// components as runs (`128 + n`, value) of 3 to 127 and literals (`n`, n values)
/// of up to 128.
fn scanline_rle(pixels: &[[u8; 4]]) -> Vec<u8> {
    let w = pixels.len();
    let mut out = vec![2, 2, (w >> 8) as u8, (w & 0xff) as u8];
    for c in 0..4 {
        let v: Vec<u8> = pixels.iter().map(|p| p[c]).collect();
        let run_at = |i: usize| i + 2 < w && v[i] == v[i + 1] && v[i] == v[i + 2];
        let mut i = 0;
        while i < w {
            if run_at(i) {
                let mut n = 3;
                while i + n < w && n < 127 && v[i + n] == v[i] {
                    n += 1;
                }
                out.extend_from_slice(&[128 + n as u8, v[i]]);
                i += n;
            } else {
                let start = i;
                while i < w && i - start < 128 && !run_at(i) {
                    i += 1;
                }
                out.push((i - start) as u8);
                out.extend_from_slice(&v[start..i]);
            }
        }
    }
    out
}

/// A scanline in old-style RLE: a repeat of the previous texel is `1 1 1 n`.
fn scanline_old_rle(pixels: &[[u8; 4]]) -> Vec<u8> {
    let mut out = pixels[0].to_vec();
    let mut i = 1;
    while i < pixels.len() {
        let mut n = 0;
        while i + n < pixels.len() && n < 255 && pixels[i + n] == pixels[i - 1] {
            n += 1;
        }
        if n > 0 {
            out.extend_from_slice(&[1, 1, 1, n as u8]);
            i += n;
        } else {
            out.extend_from_slice(&pixels[i]);
            i += 1;
        }
    }
    out
}

#[derive(Clone, Copy)]
enum Scanline {
    Flat,
    Rle,
    OldRle,
}

/// A Radiance file: `signature`, the header lines, a blank line, the resolution
/// line, then the scanlines (`n1` of `n2` texels each, as the resolution line
/// says), each coded as `coding(s)` says.
fn hdr_file(
    signature: &str,
    header: &[&str],
    resolution: &str,
    (n1, n2): (usize, usize),
    coding: impl Fn(usize) -> Scanline,
) -> Vec<u8> {
    let mut out = format!("{signature}\n").into_bytes();
    for line in header {
        out.extend_from_slice(line.as_bytes());
        out.push(b'\n');
    }
    out.push(b'\n');
    out.extend_from_slice(resolution.as_bytes());
    out.push(b'\n');
    for s in 0..n1 {
        let pixels: Vec<[u8; 4]> = (0..n2).map(|p| rgbe(texel(p, s, n2, n1))).collect();
        out.extend(match coding(s) {
            Scanline::Flat => scanline_flat(&pixels),
            Scanline::Rle => scanline_rle(&pixels),
            Scanline::OldRle => scanline_old_rle(&pixels),
        });
    }
    out
}

fn hdr_seeds() -> Vec<Seed> {
    const SIG: &str = "#?RADIANCE";
    const FORMAT: &str = "FORMAT=32-bit_rle_rgbe";
    let rle = |_| Scanline::Rle;
    let flat = |_| Scanline::Flat;
    // A seed with the signature and the usual format line.
    let std_seed = |name, resolution, size, coding: fn(usize) -> Scanline| {
        (name, hdr_file(SIG, &[FORMAT], resolution, size, coding))
    };
    vec![
        std_seed("flat-4x2.hdr", "-Y 2 +X 4", (2, 4), flat),
        std_seed("flat-16x8.hdr", "-Y 8 +X 16", (8, 16), flat),
        std_seed("rle-16x8.hdr", "-Y 8 +X 16", (8, 16), rle),
        (
            "old-rle-16x4.hdr",
            hdr_file(SIG, &[FORMAT], "-Y 4 +X 16", (4, 16), |_| Scanline::OldRle),
        ),
        (
            // Each scanline picks its own coding.
            "mixed-codings-16x6.hdr",
            hdr_file(SIG, &[FORMAT], "-Y 6 +X 16", (6, 16), |s| {
                [Scanline::Rle, Scanline::Flat, Scanline::OldRle][s % 3]
            }),
        ),
        (
            "no-format-line-8x4.hdr",
            hdr_file(SIG, &[], "-Y 4 +X 8", (4, 8), rle),
        ),
        std_seed("bottom-up-8x4.hdr", "+Y 4 +X 8", (4, 8), rle),
        std_seed("mirrored-8x4.hdr", "-Y 4 -X 8", (4, 8), rle),
        (
            // Scanlines are columns: 4 of 8 texels, an image 4 wide and 8 high.
            "columns-4x8.hdr",
            hdr_file(SIG, &[FORMAT], "+X 4 -Y 8", (4, 8), rle),
        ),
        (
            "header-notes-8x4.hdr",
            hdr_file(
                SIG,
                &[
                    "# written by envlight's fuzz_seeds",
                    "pcomb -s 2 sky.hdr",
                    "EXPOSURE=2.0",
                    "PRIMARIES=0.708 0.292 0.170 0.797 0.131 0.046 0.3127 0.3290",
                    FORMAT,
                ],
                "-Y 4 +X 8",
                (4, 8),
                rle,
            ),
        ),
        (
            "zero-primaries-crlf-4x2.hdr",
            hdr_file(
                SIG,
                &["FORMAT=32-bit_rle_rgbe\r", "PRIMARIES=0 0 0 0 0 0 0 0\r"],
                "-Y 2 +X 4",
                (2, 4),
                flat,
            ),
        ),
        // Only load_any sees other signatures (load_hdr prepends `#?RADIANCE\n`).
        (
            "rgbe-signature-8x2.hdr",
            hdr_file("#?RGBE", &[FORMAT], "-Y 2 +X 8", (2, 8), rle),
        ),
    ]
    .into_iter()
    .map(|(name, bytes)| (name.to_string(), bytes))
    .collect()
}

// ---------------------------------------------------------------------------
// OpenEXR

mod exr_seed {
    use exr::prelude::*;

    pub use exr::prelude::{Compression, Encoding, FlatSamples, LineOrder};

    pub fn scanlines(compression: Compression) -> Encoding {
        Encoding {
            compression,
            blocks: Blocks::ScanLines,
            line_order: LineOrder::Increasing,
        }
    }

    pub fn tiles(compression: Compression, tile: usize, line_order: LineOrder) -> Encoding {
        Encoding {
            compression,
            blocks: Blocks::Tiles(Vec2(tile, tile)),
            line_order,
        }
    }

    /// One plane of `f(x, y)` as f32 or f16 samples.
    pub fn plane(
        half: bool,
        (w, h): (usize, usize),
        f: impl Fn(usize, usize) -> f32,
    ) -> FlatSamples {
        let values = (0..h).flat_map(|y| (0..w).map(move |x| (x, y)));
        if half {
            FlatSamples::F16(values.map(|(x, y)| f16::from_f32(f(x, y))).collect())
        } else {
            FlatSamples::F32(values.map(|(x, y)| f(x, y)).collect())
        }
    }

    /// The channels `{prefix}R`, `{prefix}G`, `{prefix}B` of the seed picture.
    pub fn rgb(half: bool, size: (usize, usize), prefix: &str) -> Vec<(String, FlatSamples)> {
        rgb_of(half, size, prefix, super::texel)
    }

    /// The channels `{prefix}R`, `{prefix}G`, `{prefix}B` of `picture`.
    pub fn rgb_of(
        half: bool,
        size: (usize, usize),
        prefix: &str,
        picture: fn(usize, usize, usize, usize) -> [f32; 3],
    ) -> Vec<(String, FlatSamples)> {
        ["R", "G", "B"]
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let samples = plane(half, size, |x, y| picture(x, y, size.0, size.1)[c]);
                (format!("{prefix}{name}"), samples)
            })
            .collect()
    }

    pub fn layer(
        size: (usize, usize),
        name: Option<&str>,
        encoding: Encoding,
        channels: Vec<(String, FlatSamples)>,
    ) -> Layer<AnyChannels<FlatSamples>> {
        let attributes = name.map_or_else(LayerAttributes::default, LayerAttributes::named);
        let channels = channels
            .into_iter()
            .map(|(name, samples)| AnyChannel::new(name.as_str(), samples))
            .collect();
        Layer::new(size, attributes, encoding, AnyChannels::sort(channels))
    }

    /// The file holding `layers` (the first one's size is the display window).
    pub fn file(
        layers: Vec<Layer<AnyChannels<FlatSamples>>>,
        chromaticities: Option<[f32; 8]>,
    ) -> Result<Vec<u8>> {
        let display = (layers[0].size.0, layers[0].size.1);
        file_in(display, layers, chromaticities)
    }

    /// The file holding `layers` in a display window of `display` texels.
    pub fn file_in(
        display: (usize, usize),
        layers: Vec<Layer<AnyChannels<FlatSamples>>>,
        chromaticities: Option<[f32; 8]>,
    ) -> Result<Vec<u8>> {
        let mut attributes = ImageAttributes::new(IntegerBounds::from_dimensions(display));
        attributes.chromaticities = chromaticities.map(|c| attribute::Chromaticities {
            red: Vec2(c[0], c[1]),
            green: Vec2(c[2], c[3]),
            blue: Vec2(c[4], c[5]),
            white: Vec2(c[6], c[7]),
        });
        let image = Image::from_layers(attributes, SmallVec::from_vec(layers));
        let mut out = std::io::Cursor::new(Vec::new());
        // One thread: chunks in a fixed order, the same bytes every run.
        image.write().non_parallel().to_buffered(&mut out)?;
        Ok(out.into_inner())
    }

    /// A tiled, mip-mapped RGB file (levels rounded down to 1×1).
    pub fn mip_mapped(
        half: bool,
        size: (usize, usize),
        compression: Compression,
    ) -> Result<Vec<u8>> {
        use exr::math::RoundingMode;
        let rounding = RoundingMode::Down;
        let levels: Vec<(usize, usize)> = exr::meta::mip_map_levels(rounding, Vec2(size.0, size.1))
            .map(|(_, s)| (s.0, s.1))
            .collect();
        let channels = ["R", "G", "B"]
            .iter()
            .enumerate()
            .map(|(c, name)| {
                let level_data = levels
                    .iter()
                    .map(|&level| {
                        plane(half, level, |x, y| super::texel(x, y, level.0, level.1)[c])
                    })
                    .collect();
                AnyChannel::new(
                    *name,
                    Levels::Mip {
                        rounding_mode: rounding,
                        level_data,
                    },
                )
            })
            .collect();
        let layer = Layer::new(
            size,
            LayerAttributes::default(),
            tiles(compression, 4, LineOrder::Increasing),
            AnyChannels::sort(channels),
        );
        let image = Image::from_layer(layer);
        let mut out = std::io::Cursor::new(Vec::new());
        image.write().non_parallel().to_buffered(&mut out)?;
        Ok(out.into_inner())
    }
}

fn exr_seeds() -> Result<Vec<Seed>, Box<dyn Error>> {
    use exr_seed::{file, layer, plane, rgb, rgb_of, scanlines, tiles, Compression, LineOrder};

    const SIZE: (usize, usize) = (16, 8);
    let plain =
        |half: bool, encoding| file(vec![layer(SIZE, None, encoding, rgb(half, SIZE, ""))], None);
    let mut seeds: Vec<Seed> = Vec::new();

    // Every compression the exr crate writes, on a picture each of them shrinks
    // (checked below: a chunk that does not shrink is stored raw, and the
    // decompressor would never run).
    let compressions = [
        ("rle", Compression::RLE, [true, true]),
        ("zips", Compression::ZIP1, [true, true]),
        ("zip", Compression::ZIP16, [true, true]),
        ("piz", Compression::PIZ, [true, true]),
        ("pxr24", Compression::PXR24, [true, true]),
        // B44 and DWA compress f16 channels only.
        ("b44", Compression::B44, [false, true]),
        ("b44a", Compression::B44A, [false, true]),
        ("dwaa", Compression::DWAA(None), [false, true]),
        ("dwab", Compression::DWAB(None), [false, true]),
    ];
    for half in [false, true] {
        let ty = if half { "f16" } else { "f32" };
        for (name, compression, for_type) in compressions {
            if for_type[usize::from(half)] {
                let channels = rgb_of(half, SIZE, "", smooth_texel);
                let bytes = file(
                    vec![layer(SIZE, None, scanlines(compression), channels)],
                    None,
                )?;
                seeds.push((format!("scanline-{name}-{ty}-16x8.exr"), bytes));
            }
        }
        seeds.push((
            format!("scanline-none-{ty}-16x8.exr"),
            plain(half, scanlines(Compression::Uncompressed))?,
        ));
    }

    let tiny = (4, 2);
    seeds.extend([
        (
            "scanline-none-f32-4x2.exr".to_string(),
            file(
                vec![layer(
                    tiny,
                    None,
                    scanlines(Compression::Uncompressed),
                    rgb(false, tiny, ""),
                )],
                None,
            )?,
        ),
        (
            "tiled-4-zips-f16-16x8.exr".to_string(),
            plain(true, tiles(Compression::ZIP1, 4, LineOrder::Increasing))?,
        ),
        (
            // Partial tiles on the right and bottom edges, stored bottom-up.
            "tiled-6-rle-f32-decreasing-16x8.exr".to_string(),
            plain(false, tiles(Compression::RLE, 6, LineOrder::Decreasing))?,
        ),
        (
            "scanline-none-f32-decreasing-16x8.exr".to_string(),
            plain(
                false,
                exr_seed::Encoding {
                    line_order: LineOrder::Decreasing,
                    ..scanlines(Compression::Uncompressed)
                },
            )?,
        ),
        (
            "mipmap-tiled-4-zips-f16-16x8.exr".to_string(),
            exr_seed::mip_mapped(true, SIZE, Compression::ZIP1)?,
        ),
        (
            "mipmap-tiled-4-none-f32-8x4.exr".to_string(),
            exr_seed::mip_mapped(false, (8, 4), Compression::Uncompressed)?,
        ),
    ]);

    // Channel layouts the layer selection deals with.
    let small = (8, 4);
    let zip = scanlines(Compression::ZIP16);
    let luminance = |half| {
        vec![(
            "Y".to_string(),
            plane(half, small, |x, y| texel(x, y, 8, 4)[1]),
        )]
    };
    let alpha = plane(true, small, |x, _| if x < 4 { 1.0 } else { 0.5 });
    let uint = |c: u32| {
        exr_seed::FlatSamples::U32(
            (0..32u32)
                .map(|i| if i % 5 == 0 { 0 } else { i * 3 + c })
                .collect(),
        )
    };
    seeds.extend([
        (
            "grey-y-f16-8x4.exr".to_string(),
            file(vec![layer(small, None, zip, luminance(true))], None)?,
        ),
        (
            "grey-y-f32-8x4.exr".to_string(),
            file(
                vec![layer(
                    small,
                    None,
                    scanlines(Compression::Uncompressed),
                    luminance(false),
                )],
                None,
            )?,
        ),
        (
            "rgba-f16-8x4.exr".to_string(),
            file(
                vec![layer(
                    small,
                    None,
                    zip,
                    [rgb(true, small, ""), vec![("A".to_string(), alpha)]].concat(),
                )],
                None,
            )?,
        ),
        (
            "uint-rgb-8x4.exr".to_string(),
            file(
                vec![layer(
                    small,
                    None,
                    scanlines(Compression::RLE),
                    vec![
                        ("R".to_string(), uint(0)),
                        ("G".to_string(), uint(1)),
                        ("B".to_string(), uint(2)),
                    ],
                )],
                None,
            )?,
        ),
        (
            // A depth layer without colour, then "diffuse.*" and "specular.*".
            "layers-in-one-part-8x4.exr".to_string(),
            file(
                vec![layer(
                    small,
                    None,
                    zip,
                    [
                        vec![("Z".to_string(), plane(false, small, |x, y| (x + y) as f32))],
                        rgb(true, small, "diffuse."),
                        rgb(true, small, "specular."),
                    ]
                    .concat(),
                )],
                None,
            )?,
        ),
        (
            // Two parts; the first has no colour, so the second is loaded.
            "multipart-8x4.exr".to_string(),
            file(
                vec![
                    layer(
                        small,
                        Some("depth"),
                        zip,
                        vec![("Z".to_string(), plane(false, small, |x, _| x as f32))],
                    ),
                    layer(small, Some("beauty"), zip, rgb(true, small, "")),
                ],
                None,
            )?,
        ),
        (
            // ACEScg-like (AP1) primaries, converted to Rec.709.
            "chromaticities-ap1-8x4.exr".to_string(),
            file(
                vec![layer(small, None, zip, rgb(false, small, ""))],
                Some([0.713, 0.293, 0.165, 0.830, 0.128, 0.044, 0.32168, 0.33767]),
            )?,
        ),
    ]);

    // A data window inside a larger display window.
    let mut offset = layer(small, None, zip, rgb(true, small, ""));
    offset.attributes.layer_position = exr::prelude::Vec2(3, 2);
    seeds.push((
        "data-window-offset-8x4.exr".to_string(),
        exr_seed::file_in((16, 8), vec![offset], None)?,
    ));

    for (name, bytes) in &seeds {
        let (shrunk, chunks, compressed) =
            shrunk_chunks(bytes).map_err(|e| format!("{name}: {e}"))?;
        if compressed && shrunk == 0 {
            return Err(format!("{name}: none of its {chunks} chunks is stored compressed").into());
        }
    }
    Ok(seeds)
}

/// How many chunks of an OpenEXR file are smaller than their decompressed pixels,
/// out of how many, and whether any part declares a compression.
fn shrunk_chunks(bytes: &[u8]) -> exr::error::Result<(usize, usize, bool)> {
    use exr::block::chunk::CompressedBlock;
    use exr::block::reader::ChunksReader;
    use exr::block::UncompressedBlock;
    use exr::prelude::Compression;

    let mut chunks = exr::block::read(Cursor::new(bytes), false)?.all_chunks(false)?;
    let meta = chunks.meta_data().clone();
    let compressed = meta
        .headers
        .iter()
        .any(|h| h.compression != Compression::Uncompressed);
    let (mut shrunk, mut total) = (0, 0);
    for chunk in chunks.by_ref() {
        let chunk = chunk?;
        let stored = match &chunk.compressed_block {
            CompressedBlock::ScanLine(b) => b.compressed_pixels_le.len(),
            CompressedBlock::Tile(b) => b.compressed_pixels_le.len(),
            _ => 0,
        };
        let raw = UncompressedBlock::decompress_chunk(chunk, &meta, false)?
            .data
            .len();
        total += 1;
        if stored < raw {
            shrunk += 1;
        }
    }
    Ok((shrunk, total, compressed))
}

// ---------------------------------------------------------------------------
// PFM

/// A PFM file: `header` (ending in the single whitespace byte before the
/// raster), then the rows bottom-up, each value little- or big-endian.
fn pfm_file(
    header: &str,
    grey: bool,
    (w, h): (usize, usize),
    little_endian: bool,
    f: impl Fn(usize, usize) -> [f32; 3],
) -> Vec<u8> {
    let mut out = header.as_bytes().to_vec();
    for y in (0..h).rev() {
        for x in 0..w {
            let t = f(x, y);
            let values = if grey { &t[1..2] } else { &t[..] };
            for v in values {
                out.extend_from_slice(&if little_endian {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                });
            }
        }
    }
    out
}

fn pfm_seeds() -> Vec<Seed> {
    let picture = |w, h| move |x, y| texel(x, y, w, h);
    let mut seeds = vec![
        (
            "colour-le-4x2.pfm",
            pfm_file("PF\n4 2\n-1.0\n", false, (4, 2), true, picture(4, 2)),
        ),
        (
            "colour-be-4x2.pfm",
            pfm_file("PF\n4 2\n1.0\n", false, (4, 2), false, picture(4, 2)),
        ),
        (
            "colour-le-16x8.pfm",
            pfm_file("PF\n16 8\n-1.0\n", false, (16, 8), true, picture(16, 8)),
        ),
        (
            "grey-le-8x4.pfm",
            pfm_file("Pf\n8 4\n-1.0\n", true, (8, 4), true, picture(8, 4)),
        ),
        (
            "grey-be-3x5.pfm",
            pfm_file("Pf\n3 5\n1\n", true, (3, 5), false, picture(3, 5)),
        ),
        (
            // Spaces for newlines, a scale that is not applied (a note), negative
            // values (clamped), and bytes after the raster (ignored).
            "quirks-le-4x2.pfm",
            {
                let mut bytes = pfm_file("PF 4 2 -2.5 ", false, (4, 2), true, |x, y| {
                    if x == 1 {
                        [-1.0, 0.5, -0.0]
                    } else {
                        texel(x, y, 4, 2)
                    }
                });
                bytes.extend_from_slice(b"trailing");
                bytes
            },
        ),
    ]
    .into_iter()
    .map(|(name, bytes)| (name.to_string(), bytes))
    .collect::<Vec<_>>();
    // And the library's own writer.
    let image = EnvImage::new(8, 4, texels(8, 4)).expect("the seed picture is valid");
    seeds.push((
        "encode-pfm-8x4.pfm".to_string(),
        envlight::load::encode_pfm(&image),
    ));
    seeds
}

// ---------------------------------------------------------------------------
// PNG and JPEG

fn png_seeds() -> Result<Vec<Seed>, Box<dyn Error>> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::{ExtendedColorType, ImageEncoder};

    let encode = |(w, h): (usize, usize),
                  color: ExtendedColorType,
                  filter: FilterType,
                  data: Vec<u8>|
     -> Result<Vec<u8>, Box<dyn Error>> {
        let mut out = Vec::new();
        PngEncoder::new_with_quality(&mut out, CompressionType::Best, filter)
            .write_image(&data, w as u32, h as u32, color)?;
        Ok(out)
    };
    let rgb8 = |w, h| -> Vec<u8> {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .flat_map(|(x, y)| texel8(x, y, w, h))
            .collect()
    };
    let grey8 = |w, h| -> Vec<u8> { rgb8(w, h).chunks(3).map(|c| c[1]).collect() };
    let with_alpha = |data: Vec<u8>, channels: usize| -> Vec<u8> {
        data.chunks(channels)
            .enumerate()
            .flat_map(|(i, c)| {
                c.iter()
                    .copied()
                    .chain([(i * 37) as u8])
                    .collect::<Vec<_>>()
            })
            .collect()
    };
    // 16-bit samples in native order, as the encoder takes them.
    let rgb16 = |w, h| -> Vec<u8> {
        rgb8(w, h)
            .iter()
            .flat_map(|&v| (u16::from(v) * 256 + 3).to_ne_bytes())
            .collect()
    };
    Ok(vec![
        (
            "rgb8-adaptive-16x8.png".to_string(),
            encode(
                (16, 8),
                ExtendedColorType::Rgb8,
                FilterType::Adaptive,
                rgb8(16, 8),
            )?,
        ),
        (
            "rgb8-sub-4x2.png".to_string(),
            encode((4, 2), ExtendedColorType::Rgb8, FilterType::Sub, rgb8(4, 2))?,
        ),
        (
            "rgba8-up-8x4.png".to_string(),
            encode(
                (8, 4),
                ExtendedColorType::Rgba8,
                FilterType::Up,
                with_alpha(rgb8(8, 4), 3),
            )?,
        ),
        (
            "grey8-avg-8x4.png".to_string(),
            encode((8, 4), ExtendedColorType::L8, FilterType::Avg, grey8(8, 4))?,
        ),
        (
            "greya8-paeth-8x4.png".to_string(),
            encode(
                (8, 4),
                ExtendedColorType::La8,
                FilterType::Paeth,
                with_alpha(grey8(8, 4), 1),
            )?,
        ),
        (
            "rgb16-paeth-8x4.png".to_string(),
            encode(
                (8, 4),
                ExtendedColorType::Rgb16,
                FilterType::Paeth,
                rgb16(8, 4),
            )?,
        ),
        (
            "grey16-none-4x4.png".to_string(),
            encode(
                (4, 4),
                ExtendedColorType::L16,
                FilterType::NoFilter,
                (0..16u16).flat_map(|i| (i * 4000).to_ne_bytes()).collect(),
            )?,
        ),
        ("palette4-trns-8x4.png".to_string(), png_palette()),
        ("grey1-5x3.png".to_string(), png_grey1()),
        ("rgb8-interlaced-8x8.png".to_string(), png_interlaced()),
    ])
}

/// CRC-32 (IEEE, reflected) as PNG chunks use.
fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 == 1 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

/// A zlib stream of `data` in stored (uncompressed) deflate blocks.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let blocks: Vec<&[u8]> = data.chunks(0xffff).collect();
    for (i, block) in blocks.iter().enumerate() {
        out.push(u8::from(i + 1 == blocks.len()));
        let len = block.len() as u16;
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&(!len).to_le_bytes());
        out.extend_from_slice(block);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &byte in data {
        a = (a + u32::from(byte)) % 65521;
        b = (b + a) % 65521;
    }
    out.extend_from_slice(&((b << 16) | a).to_be_bytes());
    out
}

/// A PNG put together chunk by chunk, for the colour types and the interlacing the
/// `image` encoder does not write. `rows` are the filtered scanlines (filter byte
/// first), concatenated.
fn png_chunks(ihdr: [u8; 13], extra: &[(&[u8; 4], Vec<u8>)], rows: &[u8]) -> Vec<u8> {
    let mut out = vec![0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];
    let mut chunk = |kind: &[u8; 4], data: &[u8]| {
        out.extend_from_slice(&(data.len() as u32).to_be_bytes());
        let mut body = kind.to_vec();
        body.extend_from_slice(data);
        out.extend_from_slice(&body);
        out.extend_from_slice(&crc32(&body).to_be_bytes());
    };
    chunk(b"IHDR", &ihdr);
    for (kind, data) in extra {
        chunk(kind, data);
    }
    chunk(b"IDAT", &zlib_stored(rows));
    chunk(b"IEND", &[]);
    out
}

fn ihdr(w: u32, h: u32, bit_depth: u8, color_type: u8, interlace: u8) -> [u8; 13] {
    let mut out = [0u8; 13];
    out[..4].copy_from_slice(&w.to_be_bytes());
    out[4..8].copy_from_slice(&h.to_be_bytes());
    out[8..].copy_from_slice(&[bit_depth, color_type, 0, 0, interlace]);
    out
}

/// 4-bit palette of 6 colours, one of them partly transparent (tRNS).
fn png_palette() -> Vec<u8> {
    let palette: Vec<u8> = [
        [0, 0, 0],
        [255, 255, 255],
        [64, 96, 192],
        [255, 200, 120],
        [20, 60, 20],
        [250, 250, 40],
    ]
    .concat();
    let (w, h) = (8usize, 4usize);
    let mut rows = Vec::new();
    for y in 0..h {
        rows.push(0); // filter: none
        for x in (0..w).step_by(2) {
            let index = |x: usize| ((x + y) % 6) as u8;
            rows.push((index(x) << 4) | index(x + 1));
        }
    }
    png_chunks(
        ihdr(w as u32, h as u32, 4, 3, 0),
        &[(b"PLTE", palette), (b"tRNS", vec![255, 255, 128])],
        &rows,
    )
}

/// 1-bit grey, a width that does not fill the last byte.
fn png_grey1() -> Vec<u8> {
    let rows = [0, 0b1010_1000, 0, 0b0101_0000, 0, 0b1111_1000];
    png_chunks(
        ihdr(5, 3, 1, 0, 0),
        &[(b"gAMA", 45455u32.to_be_bytes().to_vec())],
        &rows,
    )
}

/// 8-bit RGB, Adam7-interlaced: the seven passes of an 8×8 image, unfiltered.
fn png_interlaced() -> Vec<u8> {
    // (x0, y0, dx, dy) of each pass.
    const PASSES: [(usize, usize, usize, usize); 7] = [
        (0, 0, 8, 8),
        (4, 0, 8, 8),
        (0, 4, 4, 8),
        (2, 0, 4, 4),
        (0, 2, 2, 4),
        (1, 0, 2, 2),
        (0, 1, 1, 2),
    ];
    let mut rows = Vec::new();
    for (x0, y0, dx, dy) in PASSES {
        for y in (y0..8).step_by(dy) {
            rows.push(0);
            for x in (x0..8).step_by(dx) {
                rows.extend_from_slice(&texel8(x, y, 8, 8));
            }
        }
    }
    png_chunks(ihdr(8, 8, 8, 2, 1), &[], &rows)
}

fn jpeg_seeds() -> Result<Vec<Seed>, Box<dyn Error>> {
    use image::codecs::jpeg::JpegEncoder;
    use image::{ExtendedColorType, ImageEncoder};

    let encode =
        |(w, h): (usize, usize), quality: u8, grey: bool| -> Result<Vec<u8>, Box<dyn Error>> {
            let rgb: Vec<u8> = (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .flat_map(|(x, y)| texel8(x, y, w, h))
                .collect();
            let (data, color) = if grey {
                (rgb.chunks(3).map(|c| c[1]).collect(), ExtendedColorType::L8)
            } else {
                (rgb, ExtendedColorType::Rgb8)
            };
            let mut out = Vec::new();
            JpegEncoder::new_with_quality(&mut out, quality)
                .write_image(&data, w as u32, h as u32, color)?;
            Ok(out)
        };
    Ok(vec![
        ("rgb-q90-16x8.jpg".to_string(), encode((16, 8), 90, false)?),
        // Partial blocks on both edges.
        ("rgb-q50-13x7.jpg".to_string(), encode((13, 7), 50, false)?),
        ("grey-q75-16x8.jpg".to_string(), encode((16, 8), 75, true)?),
        ("grey-q100-3x2.jpg".to_string(), encode((3, 2), 100, true)?),
    ])
}

// ---------------------------------------------------------------------------
// GPU tables

fn gpu_seeds() -> Result<Vec<Seed>, Box<dyn Error>> {
    let map = |w, h| EnvImage::new(w, h, texels(w, h));
    let black = |w, h| EnvImage::new(w, h, vec![[0.0; 3]; w * h]);
    let tilted = Rotation::about_z_degrees(37.0).then_after(
        Rotation::from_rows([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
            .ok_or("a quarter turn about x is a rotation")?,
    );
    let methods = [
        (
            "inversion-constant",
            Sampler::Inversion,
            Density::PiecewiseConstant,
        ),
        ("alias-constant", Sampler::Alias, Density::PiecewiseConstant),
        (
            "inversion-bilinear",
            Sampler::Inversion,
            Density::PiecewiseBilinear,
        ),
    ];
    let mut lights: Vec<(String, EnvironmentLight, RadianceFormat)> = Vec::new();
    for (method, sampler, density) in methods {
        let base = LightOptions {
            sampler,
            density,
            ..Default::default()
        };
        // Both mappings and radiance formats; nearest lookup with f16, bilinear with f32.
        for (mapping, mapping_name) in [
            (Mapping::Equirectangular, "equirect"),
            (Mapping::EqualArea, "equal-area"),
        ] {
            for (radiance, lookup, format_name) in [
                (RadianceFormat::F32, Lookup::Bilinear, "f32"),
                (RadianceFormat::F16, Lookup::Nearest, "f16-nearest"),
            ] {
                let options = LightOptions {
                    mapping,
                    lookup,
                    equal_area_size: Some(8),
                    ..base
                };
                lights.push((
                    format!("{method}-{mapping_name}-{format_name}-8x4"),
                    EnvironmentLight::new(map(8, 4)?, options)?,
                    radiance,
                ));
            }
        }
        lights.push((
            format!("{method}-black-8x4"),
            EnvironmentLight::new(black(8, 4)?, base)?,
            RadianceFormat::F32,
        ));
        // Tables of 1 and 2 cells a side: guides of one entry.
        lights.push((
            format!("{method}-tiny-2x1"),
            EnvironmentLight::new(map(2, 1)?, base)?,
            RadianceFormat::F16,
        ));
        lights.push((
            format!("{method}-rotated-scaled-mis-16x8"),
            EnvironmentLight::new(
                map(16, 8)?,
                LightOptions {
                    rotation: tilted,
                    scale: 2.5,
                    mis_compensation: true,
                    ..base
                },
            )?,
            RadianceFormat::F32,
        ));
        if density == Density::PiecewiseConstant {
            lights.push((
                format!("{method}-table-width-4-16x8"),
                EnvironmentLight::new(
                    map(16, 8)?,
                    LightOptions {
                        table_width: Some(4),
                        ..base
                    },
                )?,
                RadianceFormat::F16,
            ));
        }
    }
    let mut seeds = Vec::new();
    for (name, light, radiance) in lights {
        let tables = light.gpu_tables(&GpuTableOptions { radiance })?;
        let bytes = tables.to_bytes();
        if GpuTables::from_bytes(&bytes)? != tables {
            return Err(format!("{name}: the tables do not survive a round trip").into());
        }
        // gpu_tables prepends the magic and the version.
        let header = b"ENVLGPU\0\x01\0\0\0";
        let data = bytes
            .strip_prefix(&header[..])
            .ok_or_else(|| format!("{name}: the file does not start with {header:?}"))?;
        seeds.push((name, data.to_vec()));
    }
    Ok(seeds)
}

// ---------------------------------------------------------------------------
// Distributions

/// `shape` then the values as little-endian f32: a grid `shape % values.len()`
/// wide (at least 1); odd shapes give the light a nearest lookup, even ones bilinear.
fn grid(shape: u8, values: &[f32]) -> Vec<u8> {
    let mut out = vec![shape];
    for v in values {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

fn distribution_seeds() -> Vec<Seed> {
    let luminance = |w, h| -> Vec<f32> {
        texels(w, h)
            .iter()
            .map(|[r, g, b]| 0.2126 * r + 0.7152 * g + 0.0722 * b)
            .collect()
    };
    let mut sparse = vec![0.0f32; 32];
    sparse[13] = 1.0;
    sparse[30] = 0.25;
    let mut zero_rows = luminance(8, 4);
    zero_rows[8..16].fill(0.0);
    let special = [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        -0.0,
        f32::MIN_POSITIVE / 8.0, // subnormal
        f32::MAX,
        1.0,
        1e-30,
        1e30,
        0.5,
        2.0,
    ];
    vec![
        ("picture-8x4-bilinear", grid(8, &luminance(8, 4))),
        ("picture-16x8-bilinear", grid(16, &luminance(16, 8))),
        ("picture-7x3-nearest", grid(7, &luminance(7, 3))),
        ("single-value", grid(0, &[3.0])),
        (
            "column-1x6-nearest",
            grid(1, &[1.0, 2.0, 0.0, 4.0, 0.5, 0.25]),
        ),
        ("sparse-9x3-nearest", grid(9, &sparse)), // 32 values: the last 5 are dropped
        ("zero-row-8x4", grid(8, &zero_rows)),
        ("black-4x2", grid(4, &[0.0; 8])),
        ("special-values-4x3-bilinear", grid(4, &special)),
        ("special-values-3x4-nearest", grid(3, &special)),
        ("overflowing-sum-2x2", grid(2, &[f32::MAX; 4])),
        ("constant-6x3-shape-96", grid(96, &[0.75; 18])), // 96 % 18 = 6 wide
    ]
    .into_iter()
    .map(|(name, bytes)| (name.to_string(), bytes))
    .collect()
}

/// Visibility cache files for the light and patch grid of the
/// `visibility_cache` target (the built-in sky 32 × 16, 8 × 4 patches), learned
/// over points on a floor and a wall with a tracer that sees the sky above a
/// slanted line, under a few option sets; without the 24 bytes of magic,
/// version, light hash and empty scene key the target puts back.
fn visibility_seeds() -> Result<Vec<Seed>, Box<dyn Error>> {
    use envlight::visibility::{VisibilityCache, VisibilityOptions};
    use envlight::{ProductOptions, ProductSampler, Vec3};
    use std::sync::Arc;
    let light = EnvironmentLight::new(envlight::builtin::sky(32, 16), LightOptions::default())?;
    let product = Arc::new(ProductSampler::new(
        Arc::new(light),
        ProductOptions {
            patches: Some([8, 4]),
            ..Default::default()
        },
    ));
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..12 {
        for j in 0..12 {
            let (a, b) = (i as f32 / 6.0 - 1.0, j as f32 / 6.0 - 1.0);
            points.push(Vec3::new(a, b, 0.0));
            normals.push(Vec3::new(0.0, 0.0, 1.0));
            points.push(Vec3::new(-1.0, a, b + 1.0));
            normals.push(Vec3::new(1.0, 0.0, 0.0));
        }
    }
    let sky_above_a_line = |_: &[Vec3], d: &[Vec3], t: &mut [f32]| -> Result<(), String> {
        for (d, t) in d.iter().zip(t.iter_mut()) {
            *t = (d.z > 0.3 + 0.2 * d.x) as u8 as f32;
        }
        Ok(())
    };
    let mut seeds = Vec::new();
    for (name, target_entries, normal_bins, rays_per_patch) in
        [("few", 2, 1, 1), ("some", 6, 2, 2), ("many", 24, 4, 3)]
    {
        let options = VisibilityOptions {
            target_entries,
            normal_bins,
            rays_per_patch,
            ..Default::default()
        };
        let cache = VisibilityCache::build(
            product.clone(),
            &points,
            &normals,
            &options,
            sky_above_a_line,
        )
        .map_err(|e| e.to_string())?;
        let bytes = cache.to_bytes("")?;
        seeds.push((name.to_string(), bytes[24..].to_vec()));
    }
    Ok(seeds)
}
