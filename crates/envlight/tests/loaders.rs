//! Integration tests of the file decoders in `envlight::load`: round trips with
//! orientation for every format, colour-space conversion, bad input of every kind,
//! and the real maps in `shared/envmaps` (skipped when that folder is absent).

mod common;

use std::path::Path;
use std::time::{Duration, Instant};

use envlight::color::{luminance, srgb_to_linear};
use envlight::load::{
    encode_pfm, load, load_from_memory, write_pfm, ImageFormat, LoadOptions, LoadedImage,
    DEFAULT_MAX_TEXELS,
};
use envlight::{EnvImage, Error};

const W: usize = 5;
const H: usize = 3;
/// The distinctive texel of the small test images.
const HOT: (usize, usize) = (3, 1);
const HOT_RGB: [f32; 3] = [6.5, 0.25, 3.0];

/// Asymmetric 5×3 content (no two texels equal, channels differ) with `HOT_RGB` at
/// `HOT`. All values are exact in half precision and in RGBE with exponent 2^4.
fn pattern(x: usize, y: usize) -> [f32; 3] {
    if (x, y) == HOT {
        HOT_RGB
    } else {
        let v = (x + W * y + 1) as f32;
        [v / 16.0, (16.0 - v) / 16.0, 0.5]
    }
}

fn opts() -> LoadOptions {
    LoadOptions::default()
}

fn load_mem(name: &str, bytes: &[u8]) -> LoadedImage {
    match load_from_memory(name, bytes, &opts()) {
        Ok(loaded) => loaded,
        Err(e) => panic!("{name}: {e}"),
    }
}

fn assert_pattern(loaded: &LoadedImage, tolerance: f32) {
    let image = &loaded.image;
    assert_eq!((image.width(), image.height()), (W, H));
    for y in 0..H {
        for x in 0..W {
            let (got, want) = (image.texel(x, y), pattern(x, y));
            for c in 0..3 {
                assert!(
                    (got[c] - want[c]).abs() <= tolerance * want[c].abs().max(1e-3),
                    "texel ({x}, {y}) channel {c}: got {got:?}, want {want:?}"
                );
            }
        }
    }
}

fn expect_err(result: envlight::Result<LoadedImage>, what: &str) -> Error {
    match result {
        Ok(loaded) => panic!(
            "{what}: expected an error, got a {}x{} image",
            loaded.image.width(),
            loaded.image.height()
        ),
        Err(e) => e,
    }
}

/// A small deterministic generator for garbage bytes.
fn garbage(seed: u64, len: usize) -> Vec<u8> {
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    (0..len)
        .map(|_| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 24) as u8
        })
        .collect()
}

#[test]
fn format_names_and_default_options() {
    let all = [
        (ImageFormat::RadianceHdr, "hdr"),
        (ImageFormat::OpenExr, "exr"),
        (ImageFormat::Pfm, "pfm"),
        (ImageFormat::Png, "png"),
        (ImageFormat::Jpeg, "jpeg"),
    ];
    for (format, name) in all {
        assert_eq!(format.name(), name);
        assert_eq!(format.to_string(), name);
    }
    let defaults = LoadOptions::default();
    assert_eq!(defaults.max_texels, DEFAULT_MAX_TEXELS);
    assert_eq!(DEFAULT_MAX_TEXELS, 1 << 28);
    assert!(!defaults.replace_non_finite);
}

// ---------------------------------------------------------------------------
// PFM

/// A PFM file built by hand: `rows_top_down[y]` holds the texels of row y (from the
/// top); the file stores them bottom-up.
fn pfm_bytes(grey: bool, width: usize, scale: &str, rows_top_down: &[Vec<[f32; 3]>]) -> Vec<u8> {
    let little = scale.starts_with('-');
    let mut out = format!(
        "{}\n{} {}\n{}\n",
        if grey { "Pf" } else { "PF" },
        width,
        rows_top_down.len(),
        scale
    )
    .into_bytes();
    for row in rows_top_down.iter().rev() {
        assert_eq!(row.len(), width);
        for texel in row {
            let channels = if grey { &texel[..1] } else { &texel[..] };
            for v in channels {
                out.extend_from_slice(&if little {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                });
            }
        }
    }
    out
}

/// One of `loaded`'s notes mentions `what`.
fn assert_note(loaded: &LoadedImage, what: &str) {
    assert!(
        loaded.notes.iter().any(|n| n.contains(what)),
        "{what:?} in none of {:?}",
        loaded.notes
    );
}

fn pattern_rows() -> Vec<Vec<[f32; 3]>> {
    (0..H)
        .map(|y| (0..W).map(|x| pattern(x, y)).collect())
        .collect()
}

#[test]
fn pfm_colour_round_trip_both_byte_orders() {
    for scale in ["-1.0", "1.0"] {
        let loaded = load_mem("t.pfm", &pfm_bytes(false, W, scale, &pattern_rows()));
        assert_eq!(loaded.format, ImageFormat::Pfm);
        assert_pattern(&loaded, 0.0);
        assert_eq!(loaded.image.texel(HOT.0, HOT.1), HOT_RGB);
        assert!(loaded.notes.is_empty(), "{:?}", loaded.notes);
    }
}

#[test]
fn pfm_grey_round_trip_both_byte_orders() {
    let rows: Vec<Vec<[f32; 3]>> = (0..H)
        .map(|y| (0..W).map(|x| [pattern(x, y)[0]; 3]).collect())
        .collect();
    for scale in ["-1", "+1"] {
        let loaded = load_mem("g.pfm", &pfm_bytes(true, W, scale, &rows));
        for y in 0..H {
            for x in 0..W {
                assert_eq!(
                    loaded.image.texel(x, y),
                    [pattern(x, y)[0]; 3],
                    "({x}, {y})"
                );
            }
        }
    }
}

#[test]
fn pfm_header_whitespace_scale_and_trailing_bytes() {
    // Any whitespace between the header fields; the scale's magnitude is not applied.
    let mut bytes = pfm_bytes(false, W, "-4.0", &pattern_rows());
    let raster = bytes.split_off(bytes.len() - W * H * 12);
    let mut spaced = b"PF \t\n 5\t3\r\n-4.0\n".to_vec();
    spaced.extend_from_slice(&raster);
    spaced.extend_from_slice(b"trailing");
    let loaded = load_mem("spaced.pfm", &spaced);
    assert_pattern(&loaded, 0.0);
    assert_note(&loaded, "scale");
    assert_note(&loaded, "8 bytes");
}

#[test]
fn pfm_encoder_round_trips_exactly() {
    let image = EnvImage::from_fn(W, H, pattern).unwrap();
    let bytes = encode_pfm(&image);
    assert!(bytes.starts_with(b"PF\n5 3\n-1.0\n"));
    // The first stored row is the bottom one.
    let first = f32::from_le_bytes(bytes[12..16].try_into().unwrap());
    assert_eq!(first, pattern(0, H - 1)[0]);
    assert_eq!(load_mem("enc.pfm", &bytes).image, image);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.pfm");
    write_pfm(&path, &image).unwrap();
    let loaded = load(&path, &opts()).unwrap();
    assert_eq!(loaded.image, image);
    assert_eq!(loaded.format, ImageFormat::Pfm);
    // No temporary file is left beside the output.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    let missing_dir = dir.path().join("no/such/dir/out.pfm");
    let err = write_pfm(&missing_dir, &image).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    assert!(err.to_string().contains("no/such/dir/out.pfm"), "{err}");
}

#[test]
fn pfm_non_finite_texels_are_named_in_top_down_coordinates() {
    for (bad, channel) in [(f32::NAN, 1), (f32::INFINITY, 2), (f32::NEG_INFINITY, 0)] {
        let mut rows = pattern_rows();
        rows[2][4][channel] = bad; // bottom row: stored first in the file
        let err = expect_err(
            load_from_memory("nan.pfm", &pfm_bytes(false, W, "-1", &rows), &opts()),
            "non-finite",
        );
        match &err {
            Error::NonFiniteTexel {
                source_name,
                pos,
                channel: c,
                ..
            } => {
                assert_eq!(source_name, "nan.pfm");
                assert_eq!((pos.x, pos.y), (4, 2));
                assert_eq!(*c, ['R', 'G', 'B'][channel]);
            }
            other => panic!("{other:?}"),
        }
        assert!(err.to_string().contains("(4, 2)"), "{err}");
    }
}

#[test]
fn pfm_non_finite_texels_can_be_replaced_and_counted() {
    let mut rows = pattern_rows();
    rows[0][0][0] = f32::NAN;
    rows[1][2] = [f32::INFINITY, 1.0, f32::NAN];
    let options = LoadOptions {
        replace_non_finite: true,
        ..LoadOptions::default()
    };
    let loaded = load_from_memory("nan.pfm", &pfm_bytes(false, W, "1", &rows), &options).unwrap();
    assert_eq!(loaded.sanitized.non_finite_texels, 2);
    assert_eq!(loaded.image.texel(0, 0), [0.0; 3]);
    assert_eq!(loaded.image.texel(2, 1), [0.0; 3]);
    assert_eq!(loaded.image.texel(HOT.0, HOT.1), HOT_RGB);
}

#[test]
fn pfm_negative_texels_are_clamped_and_counted() {
    let mut rows = pattern_rows();
    rows[0][1] = [-0.5, 1.0, -0.25];
    rows[2][3][2] = -2.0;
    let loaded = load_mem("neg.pfm", &pfm_bytes(false, W, "-1", &rows));
    assert_eq!(loaded.sanitized.negative_texels, 2);
    assert_eq!(loaded.sanitized.most_negative, -2.0);
    assert_eq!(loaded.image.texel(1, 0), [0.0, 1.0, 0.0]);
    assert_eq!(loaded.image.texel(3, 2)[2], 0.0);
}

#[test]
fn pfm_truncated_raster_says_how_many_bytes() {
    let bytes = pfm_bytes(false, W, "-1", &pattern_rows());
    let header_len = b"PF\n5 3\n-1\n".len();
    let cut = &bytes[..bytes.len() - 7];
    let err = expect_err(load_from_memory("cut.pfm", cut, &opts()), "truncated");
    match &err {
        Error::Decode { format, detail, .. } => {
            assert_eq!(*format, "PFM");
            assert!(detail.contains(&(W * H * 12).to_string()), "{detail}");
            assert!(
                detail.contains(&(cut.len() - header_len).to_string()),
                "{detail}"
            );
        }
        other => panic!("{other:?}"),
    }
    assert!(err.to_string().starts_with("cut.pfm: "), "{err}");
    for bad in [
        &b"PF\n5 3\n"[..],
        b"PF\n5",
        b"PF",
        b"Pf\n-5 3\n-1\n",
        b"PF\nfive 3\n-1\n",
        b"PF\n5 3\n0\n",
        b"PF\n5 3\nnan\n",
        b"PF\n5 3\n-1",
    ] {
        let err = expect_err(load_from_memory("bad.pfm", bad, &opts()), "bad header");
        assert!(matches!(err, Error::Decode { .. }), "{bad:?}: {err}");
    }
}

#[test]
fn huge_declared_sizes_are_refused_before_decoding() {
    let start = Instant::now();
    let cases: [(&str, &[u8]); 3] = [
        ("huge.pfm", b"PF\n1000000 1000000\n-1.0\n"),
        (
            "huge.hdr",
            b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1000000 +X 1000000\n",
        ),
        ("overflow.pfm", b"Pf\n18446744073709551615 3\n-1.0\n"),
    ];
    for (name, bytes) in cases {
        match load_from_memory(name, bytes, &opts()) {
            Err(Error::TooLarge {
                source_name, limit, ..
            }) => {
                assert_eq!(source_name, name);
                assert_eq!(limit, DEFAULT_MAX_TEXELS);
            }
            other => panic!("{name}: {:?}", other.map(|l| l.notes)),
        }
    }
    // The limit is the caller's: 15 texels pass, 14 do not.
    let bytes = pfm_bytes(false, W, "-1", &pattern_rows());
    let small = |max_texels| LoadOptions {
        max_texels,
        ..LoadOptions::default()
    };
    assert!(load_from_memory("p.pfm", &bytes, &small(15)).is_ok());
    assert!(matches!(
        load_from_memory("p.pfm", &bytes, &small(14)),
        Err(Error::TooLarge {
            width: 5,
            height: 3,
            limit: 14,
            ..
        })
    ));
    assert!(start.elapsed() < Duration::from_secs(1));
}

#[test]
fn zero_sides_are_invalid_dimensions() {
    let cases: [(&str, &[u8]); 3] = [
        ("z.pfm", b"PF\n0 3\n-1.0\n"),
        ("z.pfm", b"Pf\n5 0\n-1.0\n"),
        ("z.hdr", b"#?RADIANCE\n\n-Y 0 +X 5\n"),
    ];
    for (name, bytes) in cases {
        let err = expect_err(load_from_memory(name, bytes, &opts()), name);
        assert!(
            matches!(err, Error::InvalidDimensions { .. }),
            "{name}: {err}"
        );
    }
}

// ---------------------------------------------------------------------------
// Radiance HDR

fn hdr_encode(width: usize, height: usize, f: impl Fn(usize, usize) -> [f32; 3]) -> Vec<u8> {
    use image::codecs::hdr::HdrEncoder;
    let pixels: Vec<image::Rgb<f32>> = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| image::Rgb(f(x, y)))
        .collect();
    let mut out = Vec::new();
    HdrEncoder::new(&mut out)
        .encode(&pixels, width, height)
        .unwrap();
    out
}

/// The offset of the first scanline (after the resolution line).
fn hdr_data_start(bytes: &[u8]) -> usize {
    let blank = bytes.windows(2).position(|w| w == b"\n\n").unwrap() + 2;
    blank + bytes[blank..].iter().position(|&b| b == b'\n').unwrap() + 1
}

#[test]
fn hdr_round_trip_flat_and_rle() {
    // RGBE keeps 8 mantissa bits of the largest channel; the smaller channels of a
    // texel lose more (relative to themselves), so compare against the largest.
    for width in [5, 9, 40] {
        let f = |x: usize, y: usize| {
            if (x, y) == (width - 2, 1) {
                [300.0, 2.0, 0.75]
            } else {
                [x as f32 * 0.1 + 0.05, y as f32 + 0.5, 0.25]
            }
        };
        let bytes = hdr_encode(width, H, f);
        let data = &bytes[hdr_data_start(&bytes)..];
        let rle = data.starts_with(&[2, 2]);
        assert_eq!(
            rle,
            width >= 8,
            "width {width}: RLE marker {:?}",
            &data[..4]
        );
        let loaded = load_mem("t.hdr", &bytes);
        assert_eq!(loaded.format, ImageFormat::RadianceHdr);
        assert_eq!((loaded.image.width(), loaded.image.height()), (width, H));
        for y in 0..H {
            for x in 0..width {
                let (got, want) = (loaded.image.texel(x, y), f(x, y));
                let scale = want.iter().fold(0.0f32, |m, &v| m.max(v));
                for c in 0..3 {
                    assert!(
                        (got[c] - want[c]).abs() <= scale / 128.0,
                        "width {width} ({x}, {y}): {got:?} vs {want:?}"
                    );
                }
            }
        }
        let hot = loaded.image.texel(width - 2, 1);
        assert!((hot[0] - 300.0).abs() <= 2.0, "{hot:?}");
    }
}

/// Encodes a channel value that is a multiple of 1/16 below 16 exactly as RGBE
/// (exponent byte 132 = 2^4, mantissa = 16·value).
fn rgbe(texel: [f32; 3]) -> [u8; 4] {
    let m = texel.map(|v| {
        let m = v * 16.0;
        assert!(m.fract() == 0.0 && m < 256.0);
        m as u8
    });
    [m[0], m[1], m[2], 132]
}

#[test]
fn hdr_every_orientation_comes_out_top_down() {
    // (resolution line, texel (x, y) of scanline s at position p)
    type Place = fn(usize, usize) -> (usize, usize);
    let cases: [(&str, Place); 8] = [
        ("-Y 3 +X 5", |s, p| (p, s)),
        ("-Y 3 -X 5", |s, p| (W - 1 - p, s)),
        ("+Y 3 +X 5", |s, p| (p, H - 1 - s)),
        ("+Y 3 -X 5", |s, p| (W - 1 - p, H - 1 - s)),
        ("+X 5 -Y 3", |s, p| (s, p)),
        ("+X 5 +Y 3", |s, p| (s, H - 1 - p)),
        ("-X 5 -Y 3", |s, p| (W - 1 - s, p)),
        ("-X 5 +Y 3", |s, p| (W - 1 - s, H - 1 - p)),
    ];
    for (resolution, place) in cases {
        let (scanlines, length) = if resolution.as_bytes()[1] == b'Y' {
            (H, W)
        } else {
            (W, H)
        };
        for signature in ["#?RADIANCE", "#?RGBE"] {
            let mut bytes =
                format!("{signature}\n# comment\nFORMAT=32-bit_rle_rgbe\n\n{resolution}\n")
                    .into_bytes();
            for s in 0..scanlines {
                for p in 0..length {
                    let (x, y) = place(s, p);
                    bytes.extend_from_slice(&rgbe(pattern(x, y)));
                }
            }
            let loaded = load_mem("o.hdr", &bytes);
            assert_pattern(&loaded, 0.0);
            let standard = resolution == "-Y 3 +X 5";
            assert_eq!(
                loaded
                    .notes
                    .iter()
                    .any(|n| n.contains("orientation") || n.contains("resolution")),
                !standard,
                "{resolution}: {:?}",
                loaded.notes
            );
        }
    }
}

#[test]
fn hdr_header_quirks() {
    let body = |header: &str| {
        let mut bytes = format!("#?RADIANCE\n{header}\n-Y 3 +X 5\n").into_bytes();
        for y in 0..H {
            for x in 0..W {
                bytes.extend_from_slice(&rgbe(pattern(x, y)));
            }
        }
        bytes
    };
    // Photoshop's all-zero PRIMARIES and GAMMA lines are ignored; EXPOSURE is noted.
    let loaded = load_mem(
        "ps.hdr",
        &body("# Made with Adobe Photoshop\nGAMMA=1\nPRIMARIES=0 0 0 0 0 0 0 0\nEXPOSURE=2.0\n"),
    );
    assert_pattern(&loaded, 0.0);
    assert_eq!(loaded.notes.len(), 1, "{:?}", loaded.notes);
    assert!(loaded.notes[0].contains("EXPOSURE"));
    // Rec.709 PRIMARIES: nothing to do.
    let loaded = load_mem(
        "709.hdr",
        &body("PRIMARIES=0.640 0.330 0.300 0.600 0.150 0.060 0.3127 0.3290\n"),
    );
    assert_pattern(&loaded, 0.0);
    assert!(loaded.notes.is_empty(), "{:?}", loaded.notes);
    // XYZE is refused rather than read as RGB.
    let err = expect_err(
        load_from_memory("xyz.hdr", &body("FORMAT=32-bit_rle_xyze\n"), &opts()),
        "xyze",
    );
    assert!(err.to_string().contains("xyze"), "{err}");
    // Bad resolution lines.
    for line in [
        "-Y 3",
        "-Y 3 +Y 5",
        "-Z 3 +X 5",
        "-Y three +X 5",
        "-Y 3 +X 5 7",
    ] {
        let bytes = format!("#?RADIANCE\n\n{line}\n").into_bytes();
        let err = expect_err(load_from_memory("r.hdr", &bytes, &opts()), line);
        assert!(
            matches!(
                err,
                Error::Decode {
                    format: "Radiance HDR",
                    ..
                }
            ),
            "{line}: {err}"
        );
    }
}

#[test]
fn hdr_truncated_data_names_the_scanline() {
    let bytes = hdr_encode(16, 8, |x, y| [x as f32, y as f32, 1.0]);
    let cut = &bytes[..bytes.len() - 10];
    let err = expect_err(load_from_memory("cut.hdr", cut, &opts()), "truncated");
    let message = err.to_string();
    assert!(message.contains("scanline 7 of 8"), "{message}");
    assert!(message.contains("truncated"), "{message}");
}

// ---------------------------------------------------------------------------
// OpenEXR

mod exr_files {
    use exr::prelude::*;
    use std::io::Cursor;

    pub fn to_bytes(image: &Image<Layers<AnyChannels<FlatSamples>>>) -> Vec<u8> {
        let mut out = Cursor::new(Vec::new());
        image.write().to_buffered(&mut out).unwrap();
        out.into_inner()
    }

    pub fn samples(half: bool, values: Vec<f32>) -> FlatSamples {
        if half {
            FlatSamples::F16(values.into_iter().map(f16::from_f32).collect())
        } else {
            FlatSamples::F32(values)
        }
    }

    pub fn layer(
        size: (usize, usize),
        name: Option<&str>,
        encoding: Encoding,
        channels: Vec<(&str, FlatSamples)>,
    ) -> Layer<AnyChannels<FlatSamples>> {
        let attributes = match name {
            Some(name) => LayerAttributes::named(name),
            None => LayerAttributes::default(),
        };
        let channels = channels
            .into_iter()
            .map(|(name, samples)| AnyChannel::new(name, samples))
            .collect();
        Layer::new(size, attributes, encoding, AnyChannels::sort(channels))
    }

    pub fn image(
        layers: Vec<Layer<AnyChannels<FlatSamples>>>,
        chromaticities: Option<[f32; 8]>,
    ) -> Image<Layers<AnyChannels<FlatSamples>>> {
        let size = layers[0].size;
        let mut attributes = ImageAttributes::new(IntegerBounds::from_dimensions(size));
        attributes.chromaticities = chromaticities.map(|c| attribute::Chromaticities {
            red: Vec2(c[0], c[1]),
            green: Vec2(c[2], c[3]),
            blue: Vec2(c[4], c[5]),
            white: Vec2(c[6], c[7]),
        });
        Image::from_layers(attributes, SmallVec::from_vec(layers))
    }

    pub fn tiled(tile: usize) -> Encoding {
        Encoding {
            compression: Compression::ZIP1,
            blocks: Blocks::Tiles(Vec2(tile, tile)),
            line_order: LineOrder::Increasing,
        }
    }

    pub use exr::prelude::Encoding;
}

/// The pattern's channels as separate planes, in B, G, R order.
fn bgr_planes(f: impl Fn(usize, usize) -> [f32; 3], w: usize, h: usize) -> [Vec<f32>; 3] {
    let plane = |c: usize| {
        (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .map(|(x, y)| f(x, y)[c])
            .collect::<Vec<f32>>()
    };
    [plane(2), plane(1), plane(0)]
}

fn bgr_layer(
    name: Option<&str>,
    half: bool,
    encoding: exr_files::Encoding,
    prefix: &str,
) -> exr::prelude::Layer<exr::prelude::AnyChannels<exr::prelude::FlatSamples>> {
    let [b, g, r] = bgr_planes(pattern, W, H);
    let names = [
        format!("{prefix}B"),
        format!("{prefix}G"),
        format!("{prefix}R"),
    ];
    exr_files::layer(
        (W, H),
        name,
        encoding,
        vec![
            (names[0].as_str(), exr_files::samples(half, b)),
            (names[1].as_str(), exr_files::samples(half, g)),
            (names[2].as_str(), exr_files::samples(half, r)),
        ],
    )
}

#[test]
fn exr_round_trip_float_half_scanline_and_tiled() {
    use exr_files::Encoding;
    let encodings = [
        ("uncompressed", Encoding::UNCOMPRESSED),
        ("zip", Encoding::SMALL_LOSSLESS),
        ("rle", Encoding::FAST_LOSSLESS),
        ("tiled 2x2", exr_files::tiled(2)),
    ];
    for half in [false, true] {
        for (what, encoding) in encodings {
            let bytes = exr_files::to_bytes(&exr_files::image(
                vec![bgr_layer(None, half, encoding, "")],
                None,
            ));
            let loaded = load_mem("t.exr", &bytes);
            assert_eq!(loaded.format, ImageFormat::OpenExr, "{what}");
            assert_pattern(&loaded, 0.0);
            assert_eq!(
                loaded.image.texel(HOT.0, HOT.1),
                HOT_RGB,
                "{what} half={half}"
            );
            assert!(loaded.notes.is_empty(), "{what}: {:?}", loaded.notes);
        }
    }
}

/// Images above the loader's 16 MiB first allocation grow from the top as blocks
/// decode, and blocks that arrive further down are held until half the image has
/// decoded: every line order and block shape must come out texel for texel.
#[test]
fn large_exr_images_load_in_any_block_order() {
    use exr::prelude::{Blocks, Compression, Encoding, LineOrder, Vec2};
    let (w, h) = (1600, 1000); // 1.6M texels, 19 MB decoded
    let texel = |x: usize, y: usize| [(x % 251) as f32, (y % 241) as f32, ((x * y) % 239) as f32];
    let [b, g, r] = bgr_planes(texel, w, h);
    for (what, blocks, line_order) in [
        (
            "scanlines top-down",
            Blocks::ScanLines,
            LineOrder::Increasing,
        ),
        (
            "scanlines bottom-up",
            Blocks::ScanLines,
            LineOrder::Decreasing,
        ),
        (
            "tiles top-down",
            Blocks::Tiles(Vec2(96, 64)),
            LineOrder::Increasing,
        ),
        (
            "tiles bottom-up",
            Blocks::Tiles(Vec2(96, 64)),
            LineOrder::Decreasing,
        ),
    ] {
        let encoding = Encoding {
            compression: Compression::ZIP16,
            blocks,
            line_order,
        };
        let layer = exr_files::layer(
            (w, h),
            None,
            encoding,
            vec![
                ("B", exr_files::samples(false, b.clone())),
                ("G", exr_files::samples(false, g.clone())),
                ("R", exr_files::samples(false, r.clone())),
            ],
        );
        let bytes = exr_files::to_bytes(&exr_files::image(vec![layer], None));
        let loaded = load_mem(what, &bytes);
        assert_eq!(
            (loaded.image.width(), loaded.image.height()),
            (w, h),
            "{what}"
        );
        for y in 0..h {
            for x in 0..w {
                assert_eq!(
                    loaded.image.texel(x, y),
                    texel(x, y),
                    "{what}: texel ({x}, {y})"
                );
            }
        }
    }
}

#[test]
fn exr_uint_channels_load_as_numbers() {
    let plane = |c: u32| -> Vec<u32> { (0..(W * H) as u32).map(|i| i * 3 + c).collect() };
    let bytes = exr_files::to_bytes(&exr_files::image(
        vec![exr_files::layer(
            (W, H),
            None,
            exr_files::Encoding::FAST_LOSSLESS,
            vec![
                ("R", exr::prelude::FlatSamples::U32(plane(0))),
                ("G", exr::prelude::FlatSamples::U32(plane(1))),
                ("B", exr::prelude::FlatSamples::U32(plane(2))),
            ],
        )],
        None,
    ));
    let loaded = load_mem("u.exr", &bytes);
    let i = (HOT.1 * W + HOT.0) as f32;
    assert_eq!(
        loaded.image.texel(HOT.0, HOT.1),
        [i * 3.0, i * 3.0 + 1.0, i * 3.0 + 2.0]
    );
}

#[test]
fn exr_luminance_only_is_grey() {
    let y: Vec<f32> = (0..W * H).map(|i| i as f32 * 0.5).collect();
    for half in [false, true] {
        let bytes = exr_files::to_bytes(&exr_files::image(
            vec![exr_files::layer(
                (W, H),
                None,
                exr_files::Encoding::SMALL_LOSSLESS,
                vec![("Y", exr_files::samples(half, y.clone()))],
            )],
            None,
        ));
        let loaded = load_mem("y.exr", &bytes);
        for yy in 0..H {
            for x in 0..W {
                let v = (yy * W + x) as f32 * 0.5;
                assert_eq!(loaded.image.texel(x, yy), [v; 3], "({x}, {yy})");
            }
        }
        assert_note(&loaded, "grey");
    }
}

#[test]
fn exr_picks_the_first_layer_with_rgb() {
    use exr_files::Encoding;
    // Multi-part: a depth-only part first, then the beauty pass.
    let depth = exr_files::layer(
        (W, H),
        Some("depth"),
        Encoding::FAST_LOSSLESS,
        vec![("Z", exr_files::samples(false, vec![7.0; W * H]))],
    );
    let beauty = bgr_layer(Some("beauty"), true, Encoding::FAST_LOSSLESS, "");
    let bytes = exr_files::to_bytes(&exr_files::image(vec![depth, beauty], None));
    let loaded = load_mem("parts.exr", &bytes);
    assert_pattern(&loaded, 0.0);
    assert_note(&loaded, "beauty");

    // Single part with channel-name layers: "Z" and "diffuse.{B,G,R}".
    let [b, g, r] = bgr_planes(pattern, W, H);
    let named = exr_files::layer(
        (W, H),
        None,
        Encoding::FAST_LOSSLESS,
        vec![
            ("Z", exr_files::samples(false, vec![7.0; W * H])),
            ("diffuse.B", exr_files::samples(false, b)),
            ("diffuse.G", exr_files::samples(false, g)),
            ("diffuse.R", exr_files::samples(false, r)),
        ],
    );
    let bytes = exr_files::to_bytes(&exr_files::image(vec![named], None));
    let loaded = load_mem("named.exr", &bytes);
    assert_pattern(&loaded, 0.0);
    assert_note(&loaded, "diffuse");

    // Nothing usable: a clear error listing the channels.
    let only_z = exr_files::layer(
        (W, H),
        None,
        Encoding::FAST_LOSSLESS,
        vec![("Z", exr_files::samples(false, vec![7.0; W * H]))],
    );
    let bytes = exr_files::to_bytes(&exr_files::image(vec![only_z], None));
    let err = expect_err(load_from_memory("z.exr", &bytes, &opts()), "Z only");
    assert!(err.to_string().contains("Z"), "{err}");
    assert!(
        matches!(
            err,
            Error::Decode {
                format: "OpenEXR",
                ..
            }
        ),
        "{err}"
    );
}

/// Writes a one-row EXR with the given texels and chromaticities, loads it back.
fn exr_with_chromaticities(texels: &[[f32; 3]], chromaticities: [f32; 8]) -> LoadedImage {
    let n = texels.len();
    let [b, g, r] = bgr_planes(|x, _| texels[x], n, 1);
    let layer = exr_files::layer(
        (n, 1),
        None,
        exr_files::Encoding::FAST_LOSSLESS,
        vec![
            ("B", exr_files::samples(false, b)),
            ("G", exr_files::samples(false, g)),
            ("R", exr_files::samples(false, r)),
        ],
    );
    let bytes = exr_files::to_bytes(&exr_files::image(vec![layer], Some(chromaticities)));
    load_mem("chroma.exr", &bytes)
}

fn assert_close(got: [f32; 3], want: [f64; 3], tolerance: f64, what: &str) {
    for c in 0..3 {
        assert!(
            (f64::from(got[c]) - want[c]).abs() <= tolerance * want[c].abs().max(1.0),
            "{what}: got {got:?}, want {want:?}"
        );
    }
}

fn apply(m: [[f64; 3]; 3], v: [f32; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| (0..3).map(|k| m[i][k] * f64::from(v[k])).sum())
}

#[test]
fn exr_chromaticities_are_converted_to_rec709() {
    // city.exr's primaries, D50 white: file white stays neutral after adaptation.
    let city = [0.648, 0.331, 0.321, 0.598, 0.156, 0.066, 0.3457, 0.3585];
    let loaded = exr_with_chromaticities(&[[1.0; 3], [2.5; 3], [0.5, 0.25, 0.125]], city);
    for (x, v) in [(0, 1.0), (1, 2.5)] {
        assert_close(loaded.image.texel(x, 0), [v; 3], 1e-5, "neutral");
    }
    assert_ne!(loaded.image.texel(2, 0), [0.5, 0.25, 0.125]);
    let note = loaded.notes.join("; ");
    assert!(note.contains("R(0.648,0.331)"), "{note}");
    assert!(note.contains("white (0.3457,0.3585)"), "{note}");
    assert!(note.contains("Rec.709"), "{note}");

    // Display P3 (D65): no adaptation; reference matrix P3 → linear sRGB.
    let p3 = [0.680, 0.320, 0.265, 0.690, 0.150, 0.060, 0.3127, 0.3290];
    let p3_to_srgb = [
        [1.224_940_1, -0.224_940_4, 0.0],
        [-0.042_056_9, 1.042_057_1, 0.0],
        [-0.019_637_6, -0.078_636_1, 1.098_273_5],
    ];
    let input = [0.2, 1.0, 0.5];
    let loaded = exr_with_chromaticities(&[input, [1.0, 0.0, 0.0]], p3);
    assert_close(
        loaded.image.texel(0, 0),
        apply(p3_to_srgb, input),
        1e-3,
        "P3",
    );
    // Pure P3 red is outside Rec.709: its negative G and B are clamped and counted.
    assert_close(loaded.image.texel(1, 0), [1.2249, 0.0, 0.0], 1e-3, "P3 red");
    assert_eq!(loaded.sanitized.negative_texels, 1);

    // ProPhoto (D50 white): Bradford-adapted reference from Lindbloom's matrices
    // (ProPhoto→XYZ D50, Bradford D50→D65, XYZ→sRGB).
    let prophoto = [
        0.7347, 0.2653, 0.1596, 0.8404, 0.0366, 0.0001, 0.3457, 0.3585,
    ];
    let prophoto_to_srgb = [
        [2.034_075_8, -0.727_334_1, -0.306_741_8],
        [-0.228_813_1, 1.231_730_1, -0.002_916_9],
        [-0.008_569_8, -0.153_286_6, 1.161_856_4],
    ];
    let input = [1.0, 1.0, 0.2];
    let loaded = exr_with_chromaticities(&[input], prophoto);
    assert_close(
        loaded.image.texel(0, 0),
        apply(prophoto_to_srgb, input),
        2e-3,
        "ProPhoto",
    );

    // Rec.709 chromaticities: values untouched, no note.
    let rec709 = [0.64, 0.33, 0.30, 0.60, 0.15, 0.06, 0.3127, 0.3290];
    let loaded = exr_with_chromaticities(&[[0.5, 0.25, 0.125]], rec709);
    assert_eq!(loaded.image.texel(0, 0), [0.5, 0.25, 0.125]);
    assert!(loaded.notes.is_empty(), "{:?}", loaded.notes);
}

#[test]
fn exr_huge_data_window_is_refused_before_decoding() {
    // Uncompressed: one scanline per chunk, so the chunk count is the height.
    let mut bytes = exr_files::to_bytes(&exr_files::image(
        vec![bgr_layer(None, true, exr_files::Encoding::UNCOMPRESSED, "")],
        None,
    ));
    let find = |bytes: &[u8], key: &[u8]| {
        bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len() + 4
    };
    let at = find(&bytes, b"dataWindow\0box2i\0");
    bytes[at + 8..at + 12].copy_from_slice(&999_999i32.to_le_bytes()); // xMax
    bytes[at + 12..at + 16].copy_from_slice(&999_999i32.to_le_bytes()); // yMax
    if bytes.windows(11).any(|w| w == b"chunkCount\0") {
        let at = find(&bytes, b"chunkCount\0int\0");
        bytes[at..at + 4].copy_from_slice(&1_000_000i32.to_le_bytes());
    }
    let start = Instant::now();
    let err = expect_err(load_from_memory("huge.exr", &bytes, &opts()), "huge exr");
    assert!(
        matches!(
            err,
            Error::TooLarge {
                width: 1_000_000,
                height: 1_000_000,
                ..
            }
        ),
        "{err}"
    );
    assert!(start.elapsed() < Duration::from_secs(1));
}

#[test]
fn corrupted_small_files_give_errors_not_panics() {
    let exr = exr_files::to_bytes(&exr_files::image(
        vec![bgr_layer(
            None,
            true,
            exr_files::Encoding::SMALL_LOSSLESS,
            "",
        )],
        None,
    ));
    let hdr = hdr_encode(16, 4, |x, y| [x as f32, y as f32, 0.5]);
    let pfm = pfm_bytes(false, W, "-1", &pattern_rows());
    let png = png_bytes(image::ExtendedColorType::Rgb8, &[7u8; W * H * 3]);
    let options = LoadOptions {
        max_texels: 1 << 16,
        ..LoadOptions::default()
    };
    for (name, original) in [
        ("c.exr", &exr),
        ("c.hdr", &hdr),
        ("c.pfm", &pfm),
        ("c.png", &png),
    ] {
        for seed in 0..150u64 {
            let mut bytes = original.clone();
            let noise = garbage(seed, 8);
            for k in 0..1 + (seed as usize % 4) {
                let at = usize::from(noise[2 * k]) * 256 + usize::from(noise[2 * k + 1]);
                let at = at % bytes.len();
                bytes[at] ^= noise[7] | 1;
            }
            // Ok or Err are both fine; a panic or abort is not.
            let _ = load_from_memory(name, &bytes, &options);
        }
    }
}

// ---------------------------------------------------------------------------
// PNG and JPEG

fn png_bytes(color: image::ExtendedColorType, data: &[u8]) -> Vec<u8> {
    use image::ImageEncoder;
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(data, W as u32, H as u32, color)
        .unwrap();
    out
}

#[test]
fn png_8_and_16_bit_are_srgb_decoded() {
    let texel8 = |x: usize, y: usize| -> [u8; 3] {
        if (x, y) == HOT {
            [255, 128, 0]
        } else {
            [(x * 40) as u8, (y * 100) as u8, 10]
        }
    };
    let data: Vec<u8> = (0..H)
        .flat_map(|y| (0..W).map(move |x| (x, y)))
        .flat_map(|(x, y)| texel8(x, y))
        .collect();
    let loaded = load_mem("t.png", &png_bytes(image::ExtendedColorType::Rgb8, &data));
    assert_eq!(loaded.format, ImageFormat::Png);
    assert_eq!(
        loaded.image.texel(HOT.0, HOT.1),
        [1.0, srgb_to_linear(128.0 / 255.0), 0.0]
    );
    for y in 0..H {
        for x in 0..W {
            let want = texel8(x, y).map(|v| srgb_to_linear(f32::from(v) / 255.0));
            assert_eq!(loaded.image.texel(x, y), want, "({x}, {y})");
        }
    }
    assert_note(&loaded, "low-dynamic-range");

    // 16-bit, big-endian samples as PNG stores them... the encoder takes native u16.
    let data16: Vec<u16> = (0..W * H)
        .flat_map(|i| {
            if i == HOT.1 * W + HOT.0 {
                [65535, 32768, 0]
            } else {
                [i as u16 * 1000, 5, 60000]
            }
        })
        .collect();
    let raw: Vec<u8> = data16.iter().flat_map(|v| v.to_ne_bytes()).collect();
    let loaded = load_mem("t16.png", &png_bytes(image::ExtendedColorType::Rgb16, &raw));
    let hot = loaded.image.texel(HOT.0, HOT.1);
    assert_eq!(hot[0], 1.0);
    assert!(
        (hot[1] - srgb_to_linear(32768.0 / 65535.0)).abs() < 1e-6,
        "{hot:?}"
    );
    assert_eq!(hot[2], 0.0);

    // RGBA: alpha ignored (and said so); grey: replicated.
    let rgba: Vec<u8> = (0..W * H).flat_map(|_| [255, 0, 128, 7]).collect();
    let loaded = load_mem("a.png", &png_bytes(image::ExtendedColorType::Rgba8, &rgba));
    assert_eq!(
        loaded.image.texel(0, 0),
        [1.0, 0.0, srgb_to_linear(128.0 / 255.0)]
    );
    assert_note(&loaded, "alpha");
    let grey: Vec<u8> = (0..W * H).map(|i| i as u8 * 10).collect();
    let loaded = load_mem("l.png", &png_bytes(image::ExtendedColorType::L8, &grey));
    assert_eq!(loaded.image.texel(4, 2), [srgb_to_linear(140.0 / 255.0); 3]);
}

#[test]
fn jpeg_decodes_with_orientation() {
    use image::ImageEncoder;
    // 16x8: left 8x8 block bright, right block dark, so orientation is visible
    // despite the lossy codec.
    let (w, h) = (16u32, 8u32);
    let data: Vec<u8> = (0..h)
        .flat_map(|_| (0..w).map(|x| if x < 8 { 230u8 } else { 20u8 }))
        .flat_map(|v| [v, v, v])
        .collect();
    let mut bytes = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, 95)
        .write_image(&data, w, h, image::ExtendedColorType::Rgb8)
        .unwrap();
    let loaded = load_mem("t.jpg", &bytes);
    assert_eq!(loaded.format, ImageFormat::Jpeg);
    assert_eq!((loaded.image.width(), loaded.image.height()), (16, 8));
    let bright = loaded.image.texel(3, 4)[1];
    let dark = loaded.image.texel(12, 4)[1];
    assert!(
        (bright - srgb_to_linear(230.0 / 255.0)).abs() < 0.03,
        "{bright}"
    );
    assert!((dark - srgb_to_linear(20.0 / 255.0)).abs() < 0.01, "{dark}");
}

// ---------------------------------------------------------------------------
// Unreadable and unrecognised input

#[test]
fn missing_file_is_an_io_error_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("does-not-exist.exr");
    let err = load(&path, &opts()).unwrap_err();
    assert!(matches!(err, Error::Io { .. }), "{err}");
    assert!(
        err.to_string().contains(&path.display().to_string()),
        "{err}"
    );
}

#[test]
fn garbage_bytes_are_errors_whatever_the_name() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["x.hdr", "x.exr", "x.pfm", "x.png", "x.jpg", "x.txt", "x"] {
        for (seed, len) in [(1, 0), (2, 1), (3, 7), (4, 100), (5, 4096)] {
            let bytes = garbage(seed, len);
            let err = expect_err(load_from_memory(name, &bytes, &opts()), name);
            assert!(err.to_string().starts_with(&format!("{name}: ")), "{err}");
            let path = dir.path().join(name);
            std::fs::write(&path, &bytes).unwrap();
            let err = expect_err(load(&path, &opts()), name);
            match &err {
                Error::UnsupportedFormat { detail, .. } => {
                    let ext = Path::new(name).extension();
                    match ext {
                        Some(ext) => assert!(
                            detail.contains(&format!(".{}", ext.to_string_lossy())),
                            "{detail}"
                        ),
                        None => assert!(detail.contains("no extension"), "{detail}"),
                    }
                }
                other => panic!("{name}: {other}"),
            }
        }
        // Garbage behind each format's magic number: a decode error, not a panic.
        let magics: [&[u8]; 6] = [
            b"#?RADIANCE\n",
            b"#?RGBE\n\n-Y 4 +X 4\n",
            &[0x76, 0x2f, 0x31, 0x01],
            b"PF\n",
            &[0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a],
            &[0xff, 0xd8, 0xff],
        ];
        for magic in magics {
            for seed in 0..20 {
                let mut bytes = magic.to_vec();
                bytes.extend(garbage(seed, 50 * seed as usize));
                match load_from_memory(name, &bytes, &opts()) {
                    Err(err) => {
                        assert!(err.to_string().starts_with(&format!("{name}: ")), "{err}")
                    }
                    // Any 64 bytes are a valid flat 4x4 RGBE raster.
                    Ok(loaded) => assert!(
                        magic.ends_with(b"-Y 4 +X 4\n") && bytes.len() >= magic.len() + 64,
                        "{name}: garbage loaded as {:?}",
                        loaded.format
                    ),
                }
            }
        }
    }
    let err = expect_err(load_from_memory("empty.hdr", &[], &opts()), "empty");
    assert!(err.to_string().contains("empty"), "{err}");
}

#[test]
fn content_decides_the_format_not_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("really-a-pfm.exr");
    std::fs::write(&path, pfm_bytes(false, W, "-1", &pattern_rows())).unwrap();
    let loaded = load(&path, &opts()).unwrap();
    assert_eq!(loaded.format, ImageFormat::Pfm);
    assert_pattern(&loaded, 0.0);
    assert_note(&loaded, ".exr");
}

// ---------------------------------------------------------------------------
// Real maps

/// The real maps: file, size, texels with any negative channel (`None`: only
/// "> 0" is known), brightest texel.
type RealMap = (&'static str, (usize, usize), Option<usize>, (usize, usize));

const REAL_MAPS: [RealMap; 6] = [
    ("sunrise.exr", (1024, 512), Some(570), (614, 233)),
    // Colour-converted from D50 primaries before clamping, so the count differs.
    ("city.exr", (1024, 512), None, (614, 120)),
    ("studio.exr", (1024, 512), Some(3), (709, 234)),
    ("colorful_studio_2k.hdr", (2048, 1024), Some(0), (1182, 161)),
    ("courtyard.exr", (1024, 512), Some(1188), (956, 214)),
    ("night.exr", (1024, 512), Some(596), (289, 237)),
];

#[test]
fn real_maps_load_with_the_documented_statistics() {
    let Some(dir) = common::envmaps() else { return };
    for &(file, size, negative, brightest) in &REAL_MAPS {
        let path = dir.join(file);
        let loaded = load(&path, &opts()).unwrap_or_else(|e| panic!("{e}"));
        let image = &loaded.image;
        assert_eq!((image.width(), image.height()), size, "{file}");
        let expected_format = if file.ends_with(".hdr") {
            ImageFormat::RadianceHdr
        } else {
            ImageFormat::OpenExr
        };
        assert_eq!(loaded.format, expected_format);
        match negative {
            Some(n) => assert_eq!(loaded.sanitized.negative_texels, n, "{file}"),
            None => assert!(loaded.sanitized.negative_texels > 0, "{file}"),
        }
        assert_eq!(loaded.sanitized.non_finite_texels, 0);
        let (mut best, mut best_y) = ((0, 0), f32::MIN);
        for y in 0..image.height() {
            for (x, &texel) in image.row(y).iter().enumerate() {
                let l = luminance(texel);
                if l > best_y {
                    (best, best_y) = ((x, y), l);
                }
            }
        }
        assert_eq!(best, brightest, "{file} (Y = {best_y})");
        let converted = loaded.notes.iter().any(|n| n.contains("converted"));
        assert_eq!(converted, file == "city.exr", "{file}: {:?}", loaded.notes);
    }
}

#[test]
fn truncated_real_maps_are_errors_not_panics() {
    let Some(dir) = common::envmaps() else { return };
    for &(file, ..) in &REAL_MAPS {
        let name = format!("truncated-{file}");
        let bytes = std::fs::read(dir.join(file)).unwrap();
        for len in [10, 100, 1000, bytes.len() / 2, bytes.len() - 1] {
            let err = expect_err(
                load_from_memory(&name, &bytes[..len], &opts()),
                &format!("{name} at {len} bytes"),
            );
            assert!(
                matches!(err, Error::Decode { .. }),
                "{name} at {len} bytes: {err}"
            );
            assert!(err.to_string().starts_with(&name), "{err}");
        }
    }
}

/// A DWA chunk whose leader declares sections larger than its block is an error
/// naming the file, not an abort: the exr crate's DWA decoder allocates what the
/// leader says (a fuzzing find, kept in fuzz/regressions/load/).
#[test]
fn corrupt_dwa_chunk_is_an_error_not_an_abort() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../fuzz/regressions/load/exr-dwa-ac-count.exr");
    let bytes = std::fs::read(&path).unwrap();
    let e = expect_err(load_from_memory("dwa.exr", &bytes, &opts()), "DWA");
    let message = e.to_string();
    assert!(matches!(e, Error::Decode { .. }), "{message}");
    assert!(
        message.starts_with("dwa.exr: ")
            && message.contains("corrupt DWA chunk: its AC value count"),
        "{message}"
    );
}
