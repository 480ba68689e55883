use super::build::f32_to_f16_bits;
use super::parse::{u32_at, u64_at, words_at};
use super::*;
use crate::light::{Density, LightOptions, Sampler};
use crate::math::{uniform_sphere, Rotation, Vec3};
use crate::rng::xi_2d;
use crate::EnvImage;
use std::f64::consts::PI;

/// A small map with structure: a bright spot, a gradient, black texels.
fn map(w: usize, h: usize) -> EnvImage {
    EnvImage::from_fn(w, h, |x, y| {
        if (x, y) == (w / 3, h / 4) {
            [40.0, 30.0, 20.0]
        } else if (x + 2 * y) % 7 == 0 {
            [0.0; 3]
        } else {
            let t = (x as f32 + 0.5) / w as f32;
            [0.2 + t, 0.3 + 0.1 * y as f32, 0.6]
        }
    })
    .unwrap()
}

/// A rotation about +z by 37° after one about +x by 30°: every matrix entry
/// matters.
fn tilted() -> Rotation {
    let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
    let about_x = Rotation::from_rows([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]).unwrap();
    Rotation::about_z_degrees(37.0).then_after(about_x)
}

/// Every supported light: sampler × density, both mappings, every lookup (the
/// node lookup on the lat-long map only), a rotation, a scale, MIS compensation,
/// a reduced table, a black map.
fn lights() -> Vec<(String, EnvironmentLight)> {
    let mut out = Vec::new();
    let cases = [
        (Sampler::Inversion, Density::PiecewiseConstant),
        (Sampler::Alias, Density::PiecewiseConstant),
        (Sampler::Inversion, Density::PiecewiseBilinear),
    ];
    for (sampler, density) in cases {
        for mapping in Mapping::ALL {
            for lookup in [Lookup::Nearest, Lookup::Bilinear, Lookup::Node] {
                if lookup == Lookup::Node && mapping != Mapping::Equirectangular {
                    continue;
                }
                for (rotation, scale, compensate, table) in [
                    (Rotation::IDENTITY, 1.0, false, None),
                    (tilted(), 2.5, true, None),
                    (tilted(), 1.0, false, Some(8)),
                ] {
                    if table.is_some() && density != Density::PiecewiseConstant {
                        continue;
                    }
                    let options = LightOptions {
                        sampler,
                        density,
                        mapping,
                        lookup,
                        rotation,
                        scale,
                        mis_compensation: compensate,
                        table_width: table,
                        equal_area_size: Some(16),
                        ..Default::default()
                    };
                    let name = format!(
                        "{} {} {} {lookup:?} scale {scale} mis {compensate} table {table:?}",
                        sampler.name(),
                        density.name(),
                        mapping.name()
                    );
                    let light = EnvironmentLight::new(map(16, 8), options).unwrap();
                    out.push((name, light));
                }
            }
        }
    }
    for (sampler, density) in cases {
        let options = LightOptions {
            sampler,
            density,
            ..Default::default()
        };
        // Tables of 1 and 2 cells a side: guides of one entry, shift 32.
        for (w, h) in [(4, 2), (2, 1)] {
            for lookup in [Lookup::Bilinear, Lookup::Node] {
                out.push((
                    format!(
                        "tiny {w}x{h} {} {} {lookup:?}",
                        sampler.name(),
                        density.name()
                    ),
                    EnvironmentLight::new(map(w, h), LightOptions { lookup, ..options }).unwrap(),
                ));
            }
        }
        let black = EnvImage::from_fn(8, 4, |_, _| [0.0; 3]).unwrap();
        out.push((
            format!("black {}", sampler.name()),
            EnvironmentLight::new(black, options).unwrap(),
        ));
    }
    out
}

fn tables(light: &EnvironmentLight) -> GpuTables {
    light.gpu_tables(&GpuTableOptions::default()).unwrap()
}

#[test]
fn gpu_round_trip_of_every_supported_combination() {
    for (name, light) in lights() {
        for radiance in [RadianceFormat::F32, RadianceFormat::F16] {
            let t = light.gpu_tables(&GpuTableOptions { radiance }).unwrap();
            let bytes = t.to_bytes();
            let back = GpuTables::from_bytes(&bytes).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(back, t, "{name}");
            assert_eq!(back.to_bytes(), bytes, "{name}");
            assert_eq!(back.radiance_format(), radiance);
            let p = t.params();
            assert_eq!(p[param::VERSION], VERSION);
            assert_eq!(p[param::TABLES_WORDS] as usize, t.tables().len());
            assert_eq!(p[param::BLACK], u32::from(light.is_black()), "{name}");
            assert_eq!(
                [p[param::TABLE_WIDTH], p[param::TABLE_HEIGHT]],
                match light.options().density {
                    Density::PiecewiseConstant => light.table_size().map(|n| n as u32),
                    Density::PiecewiseBilinear => light.table_size().map(|n| n as u32 + 1),
                },
                "{name}"
            );
            assert_eq!(f32::from_bits(p[param::SCALE]), light.options().scale);
            assert!(p[param::RESERVED..].iter().all(|&w| w == 0));
        }
    }
}

#[test]
fn gpu_hierarchical_sampler_is_refused() {
    let options = LightOptions {
        sampler: Sampler::Hierarchical,
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    let light = EnvironmentLight::new(map(16, 8), options).unwrap();
    let e = light.gpu_tables(&GpuTableOptions::default()).unwrap_err();
    assert!(matches!(e, Error::Unsupported(_)), "{e:?}");
    assert!(
        e.to_string().contains(
            "the hierarchical sampler is not ported to the GPU; use --sampler inversion or alias"
        ),
        "{e}"
    );
}

#[test]
fn gpu_header_and_section_table_bytes() {
    let light = EnvironmentLight::new(
        map(16, 8),
        LightOptions {
            density: Density::PiecewiseBilinear,
            rotation: tilted(),
            ..Default::default()
        },
    )
    .unwrap();
    let t = tables(&light);
    let bytes = t.to_bytes();
    assert_eq!(
        &bytes[..8],
        &[0x45, 0x4E, 0x56, 0x4C, 0x47, 0x50, 0x55, 0x00]
    );
    assert_eq!(u32_at(&bytes, 8), 1);
    let sections = t.sections();
    let ids: Vec<u32> = sections.iter().map(|s| s.id).collect();
    assert_eq!(ids, [1, 2, 3, 4, 5, 8, 9]);
    assert_eq!(u32_at(&bytes, 12) as usize, sections.len());
    assert_eq!(bytes.len() % 16, 0);
    for (k, s) in sections.iter().enumerate() {
        let at = 16 + 32 * k;
        assert_eq!(u32_at(&bytes, at), s.id);
        assert_eq!(u32_at(&bytes, at + 4), s.element.code());
        assert_eq!(u64_at(&bytes, at + 8), s.byte_offset);
        assert_eq!(u64_at(&bytes, at + 16), s.byte_len);
        assert_eq!(u64_at(&bytes, at + 24), s.count);
        assert_eq!(s.byte_offset % 16, 0, "{}", s.name);
        assert_eq!(Some(s.name), section::name(s.id));
        // The section's bytes are its words, and the padding after it is zero.
        let start = s.byte_offset as usize;
        let end = start + s.byte_len as usize;
        let words = words_at(&bytes, start, s.byte_len as usize / 4);
        assert_eq!(Some(&words[..]), t.section_words(s.id), "{}", s.name);
        assert!(bytes[end..padded_bytes(end)].iter().all(|&b| b == 0));
        if let Some(next) = sections.get(k + 1) {
            assert_eq!(next.byte_offset as usize, padded_bytes(end));
        }
    }
    assert_eq!(sections[0].byte_offset as usize, 16 + 32 * sections.len());
    // The tables buffer is the file from the first sampling section to the end
    // of the last one, padding included.
    let first = sections[1].byte_offset as usize;
    let last = &sections[sections.len() - 2];
    let end = padded_bytes((last.byte_offset + last.byte_len) as usize);
    assert_eq!(words_at(&bytes, first, (end - first) / 4), t.tables());
    // The offsets in the parameter block point at each section in it.
    for s in &sections[1..sections.len() - 1] {
        let at = t.params()[param::offset_of(s.id).unwrap()] as usize;
        assert_eq!(first + 4 * at, s.byte_offset as usize);
    }
    // The rotation's rows, w = 0, and its transpose.
    let p = t.params();
    let m = tilted().rows();
    for i in 0..3 {
        for j in 0..3 {
            assert_eq!(f32::from_bits(p[4 * i + j]), m[i][j]);
            assert_eq!(f32::from_bits(p[12 + 4 * i + j]), m[j][i]);
        }
        assert_eq!(p[4 * i + 3], 0);
        assert_eq!(p[12 + 4 * i + 3], 0);
    }
    assert_eq!(p[param::ROTATED], 1);
    // The radiance is the image's texels.
    let texels: Vec<u32> = light
        .image()
        .texels()
        .iter()
        .flat_map(|texel| texel.map(f32::to_bits))
        .collect();
    assert_eq!(t.radiance(), &texels[..]);
}

#[test]
fn gpu_f16_conversion_rounds_to_nearest_even() {
    let cases: [(f32, u16); 18] = [
        (0.0, 0x0000),
        (-0.0, 0x8000),
        (1.0, 0x3c00),
        (-2.0, 0xc000),
        (0.5, 0x3800),
        (65504.0, 0x7bff),
        // Halfway between 65504 and 65536 (which would be 2¹⁶): ties to even
        // rounds up to the next exponent, +∞.
        (65520.0, 0x7c00),
        (65519.99, 0x7bff),
        (1e6, 0x7c00),
        (-1e6, 0xfc00),
        (f32::INFINITY, 0x7c00),
        // The smallest normal and the largest and smallest subnormals.
        (6.103_515_6e-5, 0x0400),
        (6.097_555e-5, 0x03ff),
        (5.960_464_5e-8, 0x0001),
        // Half the smallest subnormal ties to even (0); just above, up to it.
        (2.980_232_2e-8, 0x0000),
        (2.980_233e-8, 0x0001),
        (1e-10, 0x0000),
        // 1 + 2⁻¹¹ is halfway between 1 and 1 + 2⁻¹⁰: to even, 1.
        (1.000_488_3, 0x3c00),
    ];
    for (x, want) in cases {
        assert_eq!(f32_to_f16_bits(x), want, "{x:e}");
    }
    // 1 + 3·2⁻¹¹ is halfway between 1 + 2⁻¹⁰ (odd) and 1 + 2⁻⁹: up, to even.
    assert_eq!(f32_to_f16_bits(1.0 + 3.0 / 2048.0), 0x3c02);
    // Just above and below a halfway point.
    assert_eq!(
        f32_to_f16_bits(f32::from_bits((1.0f32 + 1.0 / 2048.0).to_bits() + 1)),
        0x3c01
    );
    assert_eq!(
        f32_to_f16_bits(f32::from_bits((1.0f32 + 3.0 / 2048.0).to_bits() - 1)),
        0x3c01
    );
    // A subnormal tie to odd rounds up: 1.5 · 2⁻²⁴ → 2 · 2⁻²⁴.
    assert_eq!(f32_to_f16_bits(1.5 * 5.960_464_5e-8), 0x0002);
    // A rounding carry from the subnormals into the smallest normal.
    assert_eq!(f32_to_f16_bits(6.102_5e-5), 0x0400);
    assert_eq!(f32_to_f16_bits(f32::NAN) & 0x7c00, 0x7c00);
    assert_ne!(f32_to_f16_bits(f32::NAN) & 0x3ff, 0);
    // Exhaustively against the value every f16 stands for: each f16 is its own
    // conversion, and the midpoints between neighbours go to the even one.
    let value = |h: u16| -> f64 {
        let e = ((h >> 10) & 0x1f) as i32;
        let m = (h & 0x3ff) as f64;
        if e == 0 {
            m * 2f64.powi(-24)
        } else {
            (1.0 + m / 1024.0) * 2f64.powi(e - 15)
        }
    };
    for h in 0u16..0x7c00 {
        assert_eq!(f32_to_f16_bits(value(h) as f32), h);
        assert_eq!(f32_to_f16_bits(-value(h) as f32), h | 0x8000);
        if h < 0x7bff {
            let mid = (value(h) + value(h + 1)) / 2.0;
            let even = if h % 2 == 0 { h } else { h + 1 };
            assert_eq!(
                f32_to_f16_bits(mid as f32),
                even,
                "between {h:#x} and the next"
            );
        }
    }
}

#[test]
fn gpu_f16_radiance_packs_rgba_and_refuses_overflow() {
    let image = EnvImage::from_fn(4, 2, |x, y| [x as f32 + 0.5, y as f32, 65504.0]).unwrap();
    let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
    let options = GpuTableOptions {
        radiance: RadianceFormat::F16,
    };
    let t = light.gpu_tables(&options).unwrap();
    assert_eq!(t.params()[param::RADIANCE_FORMAT], 1);
    assert_eq!(t.radiance().len(), 2 * 8);
    let radiance = t.sections().into_iter().last().unwrap();
    assert_eq!((radiance.element, radiance.count), (ElementType::F16, 32));
    // Texel (1, 1): R = 1.5, G = 1, B = 65504, A = 0.
    let k = 4 + 1;
    assert_eq!(t.radiance()[2 * k], 0x3e00 | (0x3c00 << 16));
    assert_eq!(t.radiance()[2 * k + 1], 0x7bff);

    let image = EnvImage::from_fn(4, 2, |x, y| {
        if (x, y) == (3, 1) {
            [1.0, 7e4, 1.0]
        } else {
            [1.0; 3]
        }
    })
    .unwrap();
    let light = EnvironmentLight::new(image, LightOptions::default()).unwrap();
    let e = light.gpu_tables(&options).unwrap_err();
    match &e {
        Error::HalfOverflow { pos, channel, .. } => {
            assert_eq!((*pos, *channel), (TexelPos { x: 3, y: 1 }, 'G'))
        }
        _ => panic!("{e:?}"),
    }
    assert!(
        e.to_string().contains("(3, 1)") && e.to_string().contains("f32"),
        "{e}"
    );
    // f32 keeps it.
    assert!(light.gpu_tables(&GpuTableOptions::default()).is_ok());
}

/// `bytes` with the `u32` at `at` replaced by `value`.
fn patched(bytes: &[u8], at: usize, value: u32) -> Vec<u8> {
    let mut b = bytes.to_vec();
    b[at..at + 4].copy_from_slice(&value.to_le_bytes());
    b
}

/// The decoding error of `bytes`, which must contain `needle`.
fn rejected(bytes: &[u8], needle: &str) {
    match GpuTables::from_bytes(bytes) {
        Ok(_) => panic!("accepted, expected an error containing {needle:?}"),
        Err(e) => {
            let text = e.to_string();
            assert!(matches!(e, Error::Decode { .. }), "{e:?}");
            assert!(text.contains(needle), "{needle:?} not in: {text}");
        }
    }
}

#[test]
fn gpu_corrupt_files_are_rejected_with_clear_errors() {
    // The piecewise-constant layout, whose sections the offsets below name.
    let options = LightOptions {
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    let light = EnvironmentLight::new(map(16, 8), options).unwrap();
    let t = tables(&light);
    let good = t.to_bytes();
    let sections = t.sections();
    let entry = |id: u32| 16 + 32 * sections.iter().position(|s| s.id == id).unwrap();

    rejected(&good[..10], "truncated: 10 bytes");
    rejected(&good[..20], "section table");
    rejected(&good[..good.len() - 4], "radiance");
    rejected(&good[..good.len() - 4], "past the end of the file");
    let cdf_offset_at = entry(section::CONDITIONAL_CDF) + 8;
    let offset = u64_at(&good, cdf_offset_at) as u32;
    let params_at = sections[0].byte_offset as usize;
    let param_at = |word: usize| params_at + 4 * word;
    let cdf_at = sections[1].byte_offset as usize;
    let guide_at = sections[4].byte_offset as usize;
    // One u32 of the file replaced: (where, by what, what the error says).
    for (at, value, needle) in [
        (0, u32::from_le_bytes(*b"ENVX"), "bad magic"),
        (8, 2, "layout version 2"),
        // A section out of bounds, misaligned, or overlapping the one before.
        (cdf_offset_at, 1 << 30, "conditional_cdf"),
        (cdf_offset_at, 1 << 30, "past the end"),
        (cdf_offset_at, offset + 4, "not a multiple of 16"),
        (cdf_offset_at, offset - 16, "inside"),
        // A missing required section (its id made unknown: skipped).
        (
            entry(section::MARGINAL_GUIDE),
            77,
            "no marginal_guide section",
        ),
        (entry(section::RADIANCE), 77, "no radiance section"),
        (entry(section::PARAMS), 77, "no params section"),
        // Inconsistent sizes and codes. One more row moves the sections after
        // the conditional CDFs.
        (
            param_at(param::TABLE_HEIGHT),
            9,
            "parameter conditional_guide (word 42) is 152",
        ),
        (param_at(param::IMAGE_WIDTH), 17, "17x8"),
        (param_at(param::SAMPLER), 1, "alias_offset_bits"),
        (param_at(param::SAMPLER), 7, "sampler (word 25) is 7"),
        (param_at(param::VERSION), 2, "version 2"),
        (param_at(param::TABLES_WORDS), 4, "tables_words"),
        (param_at(param::CONDITIONAL_CDF), 8, "conditional_cdf"),
        (
            entry(section::RADIANCE) + 4,
            2,
            "section radiance has 384 f16",
        ),
        (entry(section::MARGINAL_CDF) + 24, 3, "3 u32 elements in 36"),
        // Contents a shader would walk off the end of.
        (cdf_at + 4 * 8, 5, "marginal_cdf row 0"),
        (guide_at, 16, "names cell 16 of 16"),
    ] {
        rejected(&patched(&good, at, value), needle);
    }
    // Half the guide entries (and a tables buffer that short): the section in
    // the file is longer than the sizes say.
    let shorter = patched(&good, param_at(param::CONDITIONAL_GUIDE_BITS), 2);
    let words = t.params()[param::TABLES_WORDS] - 32;
    let shorter = patched(&shorter, param_at(param::TABLES_WORDS), words);
    rejected(
        &shorter,
        "conditional_guide holds 64 elements, but the parameters' sizes call for 32",
    );

    let alias = EnvironmentLight::new(
        map(16, 8),
        LightOptions {
            sampler: Sampler::Alias,
            density: Density::PiecewiseConstant,
            ..Default::default()
        },
    )
    .unwrap();
    let t = tables(&alias);
    let good_alias = t.to_bytes();
    let slots = t.sections()[1].byte_offset as usize;
    rejected(&patched(&good_alias, slots + 4, 128), "alias below 128");
    rejected(&patched(&good_alias, slots, 2f32.to_bits()), "threshold 2");
    let params_at = t.sections()[0].byte_offset as usize;
    rejected(
        &patched(&good_alias, params_at + 4 * param::ALIAS_OFFSET_BITS, 0),
        "alias_offset_bits",
    );

    // A bilinear file read as piecewise-constant: its node values are a section
    // the parameters do not use.
    let bilinear = EnvironmentLight::new(
        map(16, 8),
        LightOptions {
            density: Density::PiecewiseBilinear,
            ..Default::default()
        },
    )
    .unwrap();
    let t = tables(&bilinear);
    let params_at = t.sections()[0].byte_offset as usize;
    let b = patched(&t.to_bytes(), params_at + 4 * param::DENSITY, 0);
    let values = t.params()[param::BILINEAR_VALUES];
    let b = patched(&b, params_at + 4 * param::TABLES_WORDS, values);
    let b = patched(&b, params_at + 4 * param::BILINEAR_VALUES, 0);
    rejected(&b, "section bilinear_values is present, but the parameters (sampler inversion, density piecewise-constant) do not use it");

    // No prefix short of the last section's end parses, and no single corrupt
    // byte panics.
    let end = sections
        .last()
        .map(|s| (s.byte_offset + s.byte_len) as usize)
        .unwrap();
    for n in 0..end {
        assert!(
            GpuTables::from_bytes(&good[..n]).is_err(),
            "prefix of {n} bytes"
        );
    }
    let mut rng = crate::rng::SplitMix64::new(5);
    for _ in 0..3000 {
        let mut b = good.clone();
        let k = (rng.next_u64() % b.len().min(600) as u64) as usize;
        b[k] ^= 1 << (rng.next_u64() % 8);
        let _ = GpuTables::from_bytes(&b);
    }
    // A section of an unknown id is skipped.
    let extra = extra_section(&t);
    assert_eq!(GpuTables::from_bytes(&extra).unwrap(), t);
}

/// `t`'s file with one more section of unknown id 42 (16 bytes) at the end:
/// its header and section table with one more entry counted and every offset
/// 32 bytes on, the new entry, its sections, then the new one's.
fn extra_section(t: &GpuTables) -> Vec<u8> {
    let old = t.to_bytes();
    let n = t.sections().len();
    let old_data = 16 + 32 * n;
    let mut b = patched(&old[..old_data], 12, n as u32 + 1);
    for k in 0..n {
        let at = 16 + 32 * k + 8;
        let moved = u64_at(&b, at) + 32;
        b[at..at + 8].copy_from_slice(&moved.to_le_bytes());
    }
    let extra_at = (old.len() + 32) as u64;
    for w in [42u32, 0] {
        b.extend_from_slice(&w.to_le_bytes());
    }
    for w in [extra_at, 16, 4] {
        b.extend_from_slice(&w.to_le_bytes());
    }
    b.extend_from_slice(&old[old_data..]);
    b.extend_from_slice(&[0xab; 16]);
    b
}

// -----------------------------------------------------------------------
// A reference reader: the solid-angle pdf and the sampled cell, computed
// from the parameter block and the tables buffer alone, as the document's
// math says, for comparison with the light's own.
// -----------------------------------------------------------------------

/// The flat buffers a shader binds.
struct Flat<'a> {
    p: &'a [u32; PARAMS_WORDS],
    t: &'a [u32],
}

/// `2⁴⁸`.
const TWO_48: f64 = (1u64 << 48) as f64;

impl Flat<'_> {
    fn u(&self, word: usize) -> usize {
        self.p[word] as usize
    }

    fn f(&self, word: usize) -> f32 {
        f32::from_bits(self.p[word])
    }

    /// Word `k` of the section whose offset is in parameter word `at`.
    fn word(&self, at: usize, k: usize) -> u32 {
        self.t[self.u(at) + k]
    }

    fn table(&self) -> (usize, usize) {
        (self.u(param::TABLE_WIDTH), self.u(param::TABLE_HEIGHT))
    }

    /// The world direction `d` in the light frame: `world_to_light` rows.
    fn to_light(&self, d: Vec3) -> Vec3 {
        let row = |i: usize| {
            let at = param::WORLD_TO_LIGHT + 4 * i;
            Vec3::new(self.f(at), self.f(at + 1), self.f(at + 2))
        };
        Vec3::new(row(0).dot(d), row(1).dot(d), row(2).dot(d))
    }

    /// The image point of a light-frame direction and `dω / du dv` there, or
    /// `None` within 1e-3 rad of a lat-long pole.
    fn to_uv(&self, d: Vec3) -> Option<([f32; 2], f64)> {
        if self.u(param::MAPPING) == 0 {
            let (uv, csc) = crate::mapping::direction_to_equirect_and_csc(d);
            let theta = PI * uv[1] as f64;
            (theta > 1e-3 && theta < PI - 1e-3).then_some((uv, 2.0 * PI * PI / csc as f64))
        } else {
            Some((crate::mapping::equal_area::sphere_to_square(d), 4.0 * PI))
        }
    }

    /// CDF entry `k` of the section at parameter word `at`.
    fn cdf(&self, at: usize, k: usize) -> f64 {
        self.word(at, k) as f64
    }

    /// The planar density of the piecewise-constant inversion tables at cell
    /// `(iu, iv)`, or of the patch distribution's cell for the bilinear
    /// density: `w_u w_v / CDF_ONE²` times `tw th`.
    fn cell_probability(&self, iu: usize, iv: usize) -> f64 {
        let (tw, _) = self.table();
        let wv = self.cdf(param::MARGINAL_CDF, iv + 1) - self.cdf(param::MARGINAL_CDF, iv);
        let row = iv * (tw + 1) + iu;
        let wu = self.cdf(param::CONDITIONAL_CDF, row + 1) - self.cdf(param::CONDITIONAL_CDF, row);
        wu * wv / (CDF_ONE as f64 * CDF_ONE as f64)
    }

    /// The node position `k` along an axis of `n` texels: 0, `(j + ½)/n`, 1.
    fn node(k: usize, n: usize) -> f64 {
        if k == 0 {
            0.0
        } else if k > n {
            1.0
        } else {
            (k as f64 - 0.5) / n as f64
        }
    }

    /// Whether the bilinear density's v nodes are the node rows
    /// `0, 0, j/(h − 1), 1, 1` (else the texel centres).
    fn node_rows(&self) -> bool {
        self.u(param::BILINEAR_V_NODES) == 1
    }

    /// The node position `k` along v of `h` rows, either layout.
    fn v_node(&self, k: usize, h: usize) -> f64 {
        if !self.node_rows() {
            Self::node(k, h)
        } else if k == 0 {
            0.0
        } else if k > h {
            1.0
        } else {
            (k - 1) as f64 / (h - 1) as f64
        }
    }

    /// The planar density at `uv`, or `None` within 1e-5 of a cell (patch) edge.
    fn planar_pdf(&self, [u, v]: [f32; 2]) -> Option<f64> {
        let (u, v) = (u as f64, v as f64);
        let (tw, th) = self.table();
        // `⌊x n + offset⌋`, clamped, unless x is within 1e-5 of an edge.
        let cell = |x: f64, n: usize, offset: f64, last: usize| -> Option<usize> {
            let s = x * n as f64 + offset;
            ((s - s.round()).abs() >= 1e-5 * n as f64).then_some((s as usize).min(last))
        };
        if self.u(param::SAMPLER) == 1 {
            let (iu, iv) = (cell(u, tw, 0.0, tw - 1)?, cell(v, th, 0.0, th - 1)?);
            let f = f32::from_bits(self.word(param::ALIAS_FUNC, iv * tw + iu)) as f64;
            return Some(f * self.f(param::ALIAS_INV_INTEGRAL) as f64);
        }
        if self.u(param::DENSITY) == 0 {
            let (iu, iv) = (cell(u, tw, 0.0, tw - 1)?, cell(v, th, 0.0, th - 1)?);
            return Some((tw * th) as f64 * self.cell_probability(iu, iv));
        }
        let (w, h) = (self.u(param::IMAGE_WIDTH), self.u(param::IMAGE_HEIGHT));
        // Node rows: patch 1 + ⌊v (h − 1)⌋ (the zero-width ends never).
        let k = if self.node_rows() {
            cell(v, h - 1, 1.0, h - 1)?
        } else {
            cell(v, h, 0.5, h)?
        };
        let i = cell(u, w, 0.5, w)?;
        let [f00, f10, f01, f11] = self.corners(i, k);
        let (u0, u1) = (Self::node(i, w), Self::node(i + 1, w));
        let (v0, v1) = (self.v_node(k, h), self.v_node(k + 1, h));
        let (x, y) = ((u - u0) / (u1 - u0), (v - v0) / (v1 - v0));
        let b = (1.0 - y) * ((1.0 - x) * f00 + x * f10) + y * ((1.0 - x) * f01 + x * f11);
        let mass = (u1 - u0) * (v1 - v0) * (f00 + f10 + f01 + f11) / 4.0;
        Some(if mass > 0.0 {
            self.cell_probability(i, k) * b / mass
        } else {
            0.0
        })
    }

    /// The corners `[f00, f10, f01, f11]` of bilinear patch `(i, k)`.
    fn corners(&self, i: usize, k: usize) -> [f64; 4] {
        let mu = self.u(param::IMAGE_WIDTH) + 2;
        let at = |r: usize, c: usize| {
            f32::from_bits(self.word(param::BILINEAR_VALUES, r * mu + c)) as f64
        };
        [at(k, i), at(k, i + 1), at(k + 1, i), at(k + 1, i + 1)]
    }

    /// The solid-angle pdf of world direction `d`, or `None` where the
    /// comparison is skipped (next to a pole or a cell edge).
    fn pdf(&self, d: Vec3) -> Option<f64> {
        if self.u(param::BLACK) == 1 {
            return Some(0.0);
        }
        let (uv, jacobian) = self.to_uv(self.to_light(d))?;
        Some(self.planar_pdf(uv)? / jacobian)
    }

    /// The cell of a fixed-point CDF that `ξ` lands in, by the guide and the
    /// forward scan, and the offset of `ξ` in its segment.
    fn invert_cdf(&self, cdf_at: usize, guide_at: usize, shift: u32, xi: f32) -> (usize, f64) {
        let t = (xi as f64 * CDF_ONE as f64).clamp(0.0, (CDF_ONE - 1) as f64);
        let x = t as u32;
        let mut o = self.t[guide_at + (x as u64 >> shift) as usize] as usize;
        while self.t[cdf_at + o + 1] <= x {
            o += 1;
        }
        let (lo, hi) = (self.t[cdf_at + o] as f64, self.t[cdf_at + o + 1] as f64);
        (o, (t - lo) / (hi - lo))
    }

    /// The cell `[iu, iv]` the inversion tables pick for `ξ`, and the offsets.
    fn sample_cell(&self, xi: [f32; 2]) -> ([usize; 2], [f64; 2]) {
        let (tw, _) = self.table();
        let shift = self.p[param::MARGINAL_GUIDE_SHIFT];
        let (iv, fv) = self.invert_cdf(
            self.u(param::MARGINAL_CDF),
            self.u(param::MARGINAL_GUIDE),
            shift,
            xi[1],
        );
        let bits = self.p[param::CONDITIONAL_GUIDE_BITS];
        let (iu, fu) = self.invert_cdf(
            self.u(param::CONDITIONAL_CDF) + iv * (tw + 1),
            self.u(param::CONDITIONAL_GUIDE) + (iv << bits),
            32 - bits,
            xi[0],
        );
        ([iu, iv], [fu, fv])
    }

    /// The image point the flat tables sample for `ξ`.
    fn sample_uv(&self, xi: [f32; 2]) -> ([usize; 2], [f64; 2]) {
        let (tw, th) = self.table();
        if self.u(param::SAMPLER) == 1 {
            return self.sample_alias(xi);
        }
        let ([iu, iv], [s, r]) = self.sample_cell(xi);
        if self.u(param::DENSITY) == 0 {
            let uv = [(iu as f64 + s) / tw as f64, (iv as f64 + r) / th as f64];
            return ([iu, iv], uv);
        }
        let (w, h) = (self.u(param::IMAGE_WIDTH), self.u(param::IMAGE_HEIGHT));
        let [a, b, c, d] = self.corners(iu, iv);
        let linear = |xi: f64, a: f64, b: f64| {
            if a == b {
                xi
            } else {
                xi * (a + b) / (a + ((1.0 - xi) * a * a + xi * b * b).sqrt())
            }
        };
        let lerp = |t: f64, a: f64, b: f64| (1.0 - t) * a + t * b;
        let y = linear(r, a + b, c + d);
        let x = linear(s, lerp(y, a, c), lerp(y, b, d));
        let (u0, u1) = (Self::node(iu, w), Self::node(iu + 1, w));
        let (v0, v1) = (self.v_node(iv, h), self.v_node(iv + 1, h));
        ([iu, iv], [lerp(x, u0, u1), lerp(y, v0, v1)])
    }

    /// The alias table's cell and point for `ξ`.
    fn sample_alias(&self, xi: [f32; 2]) -> ([usize; 2], [f64; 2]) {
        let (tw, th) = self.table();
        let n = (tw * th) as u128;
        let fixed = |x: f32| ((x as f64 * (1u64 << 24) as f64) as u64).min((1 << 24) - 1);
        let bits = (fixed(xi[0]) << 24) | fixed(xi[1]);
        let scaled = bits as u128 * n;
        let slot = (scaled >> 48) as usize;
        let fraction = (scaled & ((1u128 << 48) - 1)) as f64;
        let threshold = f32::from_bits(self.word(param::ALIAS_SLOTS, 2 * slot)) as f64;
        let keep = threshold * TWO_48;
        let (cell, leftover) = if fraction < keep {
            (slot, fraction / keep)
        } else {
            let alias = self.word(param::ALIAS_SLOTS, 2 * slot + 1) as usize;
            (alias, (fraction - keep) / (TWO_48 - keep))
        };
        let split = (1u64 << self.p[param::ALIAS_OFFSET_BITS]) as f64;
        let scaled = leftover * split;
        let (du, dv) = (scaled.floor() / split, scaled - scaled.floor());
        let (iu, iv) = (cell % tw, cell / tw);
        (
            [iu, iv],
            [(iu as f64 + du) / tw as f64, (iv as f64 + dv) / th as f64],
        )
    }
}

#[test]
fn gpu_reference_pdf_from_flat_tables_equals_the_lights() {
    let mut compared = 0usize;
    for (name, light) in lights() {
        let t = tables(&light);
        let flat = Flat {
            p: t.params(),
            t: t.tables(),
        };
        let mut lit = 0;
        for k in 0..4000 {
            let d = uniform_sphere(xi_2d(17, k));
            let Some(want) = flat.pdf(d) else {
                continue;
            };
            let got = light.pdf(d) as f64;
            assert!(
                (got - want).abs() <= 1e-4 * want.abs().max(1e-30),
                "{name}: direction {d:?}: light {got}, flat tables {want}"
            );
            compared += 1;
            lit += usize::from(want > 0.0);
        }
        assert!(light.is_black() || lit > 100, "{name}: only {lit} lit");
    }
    assert!(compared > 100_000, "{compared}");
}

#[test]
fn gpu_reference_sampling_from_flat_tables_picks_the_lights_cells() {
    for (name, light) in lights() {
        if light.is_black() {
            continue;
        }
        let t = tables(&light);
        let flat = Flat {
            p: t.params(),
            t: t.tables(),
        };
        let (tw, th) = flat.table();
        let bilinear = flat.u(param::DENSITY) == 1;
        let mut checked = 0;
        for k in 0..4000 {
            let xi = xi_2d(23, k);
            let Some(s) = light.sample(xi) else {
                continue;
            };
            let (cell, uv) = flat.sample_uv(xi);
            let light_cell = if bilinear {
                let (w, h) = (flat.u(param::IMAGE_WIDTH), flat.u(param::IMAGE_HEIGHT));
                let v = s.uv[1] as f64;
                [
                    ((s.uv[0] as f64 * w as f64 + 0.5) as usize).min(w),
                    if flat.node_rows() {
                        1 + ((v * (h - 1) as f64) as usize).min(h - 2)
                    } else {
                        ((v * h as f64 + 0.5) as usize).min(h)
                    },
                ]
            } else {
                // As the light finds cells: the product in f32.
                [
                    ((s.uv[0] * tw as f32) as usize).min(tw - 1),
                    ((s.uv[1] * th as f32) as usize).min(th - 1),
                ]
            };
            assert_eq!(cell, light_cell, "{name}: ξ {xi:?}");
            for c in 0..2 {
                assert!(
                    (uv[c] - s.uv[c] as f64).abs() < 1e-5,
                    "{name}: ξ {xi:?}: flat {uv:?}, light {:?}",
                    s.uv
                );
            }
            checked += 1;
        }
        assert!(checked > 3500, "{name}: {checked}");
    }
}

/// The reference reader is not a copy of the light: a broken table (one
/// conditional CDF edge moved) or a flipped rotation is caught by it.
#[test]
fn gpu_reference_reader_catches_broken_tables() {
    let light = EnvironmentLight::new(
        map(16, 8),
        LightOptions {
            rotation: tilted(),
            ..Default::default()
        },
    )
    .unwrap();
    let t = tables(&light);
    let mismatches = |p: &[u32; PARAMS_WORDS], tables: &[u32]| {
        let flat = Flat { p, t: tables };
        (0..2000)
            .filter_map(|k| {
                let d = uniform_sphere(xi_2d(29, k));
                let want = flat.pdf(d)?;
                let got = light.pdf(d) as f64;
                Some((got - want).abs() > 1e-4 * want.abs().max(1e-30))
            })
            .filter(|&bad| bad)
            .count()
    };
    assert_eq!(mismatches(t.params(), t.tables()), 0);
    let mut broken = t.tables().to_vec();
    let row = t.params()[param::CONDITIONAL_CDF] as usize + 3 * 17;
    broken[row + 5] = broken[row + 5] / 2 + broken[row + 4] / 2;
    assert!(mismatches(t.params(), &broken) > 0);
    let mut flipped = *t.params();
    for w in &mut flipped[param::WORLD_TO_LIGHT..param::WORLD_TO_LIGHT + 3] {
        *w = (-f32::from_bits(*w)).to_bits();
    }
    assert!(mismatches(&flipped, t.tables()) > 100);
}

/// The radiance formats' names parse back, print as themselves, and an unknown
/// one is refused with both names (as the light's option enums).
#[test]
fn radiance_format_names_round_trip() {
    use crate::light::NamedOption;
    for f in RadianceFormat::ALL {
        assert_eq!(f.name().parse::<RadianceFormat>().unwrap(), f);
        assert_eq!(f.to_string(), f.name());
    }
    let e = "f64".parse::<RadianceFormat>().unwrap_err();
    assert_eq!(e.accepted, RadianceFormat::names());
    assert!(e.to_string().contains("f32, f16"), "{e}");
}
