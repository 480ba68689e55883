//! The light's tables as flat buffers for a GPU: the layout of
//! `docs/gpu-tables.md`, byte for byte.
//!
//! The CPU builds the tables; a GPU only reads them. [`EnvironmentLight::gpu_tables`]
//! lays a light out as three buffers:
//!
//! - the **parameter block** (section 1): 64 little-endian words holding the rotation,
//!   the sampler, density, mapping and lookup codes, the sizes, the scale, and the
//!   word offset of every sampling section in the tables buffer ([`param`]);
//! - the **tables buffer** (sections 2–8, whichever the sampler and density use,
//!   in id order, each zero-padded to 16 bytes): the fixed-point CDFs and guide
//!   tables of the inversion sampler, or the alias slots and cell values, and the
//!   node values of the piecewise-bilinear density;
//! - the **radiance buffer** (section 9): the light's image, unscaled, as RGB `f32`
//!   or RGBA `f16`.
//!
//! [`GpuTables::to_bytes`] writes them as one file (a 16-byte header, a section
//! table, then the sections on 16-byte boundaries); [`GpuTables::from_bytes`] reads
//! a file back and checks everything a shader relies on (bounds, alignment, the
//! sections the parameters call for and their lengths, CDFs that start at 0 and end
//! at `CDF_ONE`, guide and alias entries that index inside their tables), so a file
//! it accepts cannot send a shader out of bounds.
//!
//! The tables are the light's own, copied: sampling them as the document describes
//! picks the cells the CPU picks for the same `ξ`, and the densities they give are
//! the light's `pdf` (the tests evaluate both from the flat words alone).
//!
//! ```
//! use envlight::gpu::{param, GpuTableOptions, GpuTables};
//! use envlight::{builtin, EnvironmentLight, LightOptions};
//!
//! let light = EnvironmentLight::new(builtin::sky(64, 32), LightOptions::default()).unwrap();
//! let tables = light.gpu_tables(&GpuTableOptions::default()).unwrap();
//! assert_eq!(tables.params()[param::VERSION], 1);
//! assert_eq!(tables.tables().len(), tables.params()[param::TABLES_WORDS] as usize);
//! let bytes = tables.to_bytes();
//! assert_eq!(GpuTables::from_bytes(&bytes).unwrap(), tables);
//! ```

use crate::distribution::{Distribution2D, CDF_ONE};
use crate::error::{Error, Result, TexelPos};
use crate::image::Lookup;
use crate::light::{EnvironmentLight, Mapping, Planar};

/// The first 8 bytes of a file: `E N V L G P U \0`.
pub const MAGIC: [u8; 8] = *b"ENVLGPU\0";

/// The layout version this module writes and reads.
pub const VERSION: u32 = 1;

/// Words in the parameter block (section 1): 256 bytes.
pub const PARAMS_WORDS: usize = 64;

/// Every section starts on a multiple of this many bytes.
const ALIGN_BYTES: usize = 16;
/// [`ALIGN_BYTES`] in words.
const ALIGN_WORDS: usize = ALIGN_BYTES / 4;
/// Magic, version and section count.
const HEADER_BYTES: usize = 16;
/// One section-table entry.
const ENTRY_BYTES: usize = 32;
/// The format's name in decoding errors.
const FORMAT: &str = "envlight GPU tables";

/// Section ids (the `id` of a section-table entry).
pub mod section {
    /// The parameter block: 64 `u32` words.
    pub const PARAMS: u32 = 1;
    /// The marginal CDF over the table's rows: `table_height + 1` `u32`.
    pub const MARGINAL_CDF: u32 = 2;
    /// The marginal CDF's guide table (`u32`).
    pub const MARGINAL_GUIDE: u32 = 3;
    /// `table_height` rows of `table_width + 1` conditional CDF values (`u32`).
    pub const CONDITIONAL_CDF: u32 = 4;
    /// `table_height` rows of `1 << conditional_guide_bits` guide entries (`u32`).
    pub const CONDITIONAL_GUIDE: u32 = 5;
    /// The alias table: per slot, the threshold's `f32` bits and the alias cell.
    pub const ALIAS_SLOTS: u32 = 6;
    /// The alias table's cell values (`f32`, row-major).
    pub const ALIAS_FUNC: u32 = 7;
    /// The piecewise-bilinear density's node values (`f32`), `(h + 2) × (w + 2)`.
    pub const BILINEAR_VALUES: u32 = 8;
    /// The radiance image (`f32` RGB or `f16` RGBA).
    pub const RADIANCE: u32 = 9;

    /// The sampling sections, which make up the tables buffer, in id order.
    pub const SAMPLING: [u32; 7] = [
        MARGINAL_CDF,
        MARGINAL_GUIDE,
        CONDITIONAL_CDF,
        CONDITIONAL_GUIDE,
        ALIAS_SLOTS,
        ALIAS_FUNC,
        BILINEAR_VALUES,
    ];

    /// The name of section `id` (`"marginal_cdf"`, ...), `None` for an id this
    /// version does not know.
    pub fn name(id: u32) -> Option<&'static str> {
        Some(match id {
            PARAMS => "params",
            MARGINAL_CDF => "marginal_cdf",
            MARGINAL_GUIDE => "marginal_guide",
            CONDITIONAL_CDF => "conditional_cdf",
            CONDITIONAL_GUIDE => "conditional_guide",
            ALIAS_SLOTS => "alias_slots",
            ALIAS_FUNC => "alias_func",
            BILINEAR_VALUES => "bilinear_values",
            RADIANCE => "radiance",
            _ => return None,
        })
    }
}

/// Word indices into the parameter block (section 1). `f32` words hold IEEE-754
/// binary32 bits; see `docs/gpu-tables.md` for each word's meaning.
pub mod param {
    /// Words 0–11: the light-to-world rotation's rows, `(x, y, z, 0)` each.
    pub const LIGHT_TO_WORLD: usize = 0;
    /// Words 12–23: the world-to-light rotation's rows (the transpose),
    /// `(x, y, z, 0)` each.
    pub const WORLD_TO_LIGHT: usize = 12;
    /// `u32`: the layout version, 1.
    pub const VERSION: usize = 24;
    /// `u32`: 0 = inversion, 1 = alias ([`super::value`]).
    pub const SAMPLER: usize = 25;
    /// `u32`: 0 = piecewise-constant, 1 = piecewise-bilinear.
    pub const DENSITY: usize = 26;
    /// `u32`: 0 = equirectangular, 1 = equal-area octahedral square.
    pub const MAPPING: usize = 27;
    /// `u32`: 0 = nearest, 1 = bilinear.
    pub const LOOKUP: usize = 28;
    /// `u32`: 0 = RGB `f32`, 1 = RGBA `f16`.
    pub const RADIANCE_FORMAT: usize = 29;
    /// `u32`: 1 when the rotation is not the identity.
    pub const ROTATED: usize = 30;
    /// `u32`: 1 when the light emits nothing (every pdf is 0).
    pub const BLACK: usize = 31;
    /// `u32`: radiance texels along u.
    pub const IMAGE_WIDTH: usize = 32;
    /// `u32`: radiance texels along v.
    pub const IMAGE_HEIGHT: usize = 33;
    /// `u32`: sampling-table cells along u (bilinear: patches, `image_width + 1`).
    pub const TABLE_WIDTH: usize = 34;
    /// `u32`: sampling-table cells along v (bilinear: `image_height + 1`).
    pub const TABLE_HEIGHT: usize = 35;
    /// `f32`: the radiance multiplier.
    pub const SCALE: usize = 36;
    /// `f32`: `∫ Y dω`, scale applied.
    pub const INTEGRAL_LUMINANCE: usize = 37;
    /// `u32`: word offset of the marginal CDF in the tables buffer.
    pub const MARGINAL_CDF: usize = 38;
    /// `u32`: word offset of the marginal guide table.
    pub const MARGINAL_GUIDE: usize = 39;
    /// `u32`: `32 − log₂(marginal guide length)`.
    pub const MARGINAL_GUIDE_SHIFT: usize = 40;
    /// `u32`: word offset of the conditional CDFs.
    pub const CONDITIONAL_CDF: usize = 41;
    /// `u32`: word offset of the conditional guide tables.
    pub const CONDITIONAL_GUIDE: usize = 42;
    /// `u32`: each row's guide has `1 << bits` entries.
    pub const CONDITIONAL_GUIDE_BITS: usize = 43;
    /// `u32`: word offset of the alias slots.
    pub const ALIAS_SLOTS: usize = 44;
    /// `u32`: word offset of the alias cell values.
    pub const ALIAS_FUNC: usize = 45;
    /// `u32`: bits of the alias test's leftover that place the point along u.
    pub const ALIAS_OFFSET_BITS: usize = 46;
    /// `f32`: `1 / I` of the alias table (0 for a black light).
    pub const ALIAS_INV_INTEGRAL: usize = 47;
    /// `u32`: word offset of the bilinear node values.
    pub const BILINEAR_VALUES: usize = 48;
    /// `u32`: length of the tables buffer in words.
    pub const TABLES_WORDS: usize = 49;
    /// Words 50–63: reserved, 0.
    pub const RESERVED: usize = 50;

    /// The word holding section `id`'s offset in the tables buffer, for the
    /// sampling sections (ids 2–8).
    pub fn offset_of(id: u32) -> Option<usize> {
        use super::section;
        Some(match id {
            section::MARGINAL_CDF => MARGINAL_CDF,
            section::MARGINAL_GUIDE => MARGINAL_GUIDE,
            section::CONDITIONAL_CDF => CONDITIONAL_CDF,
            section::CONDITIONAL_GUIDE => CONDITIONAL_GUIDE,
            section::ALIAS_SLOTS => ALIAS_SLOTS,
            section::ALIAS_FUNC => ALIAS_FUNC,
            section::BILINEAR_VALUES => BILINEAR_VALUES,
            _ => return None,
        })
    }
}

/// The codes the parameter block's enumerated words hold.
pub mod value {
    /// [`super::param::SAMPLER`]: CDF inversion.
    pub const SAMPLER_INVERSION: u32 = 0;
    /// [`super::param::SAMPLER`]: the alias table.
    pub const SAMPLER_ALIAS: u32 = 1;
    /// [`super::param::DENSITY`]: piecewise-constant.
    pub const DENSITY_PIECEWISE_CONSTANT: u32 = 0;
    /// [`super::param::DENSITY`]: piecewise-bilinear.
    pub const DENSITY_PIECEWISE_BILINEAR: u32 = 1;
    /// [`super::param::MAPPING`]: equirectangular.
    pub const MAPPING_EQUIRECTANGULAR: u32 = 0;
    /// [`super::param::MAPPING`]: the equal-area octahedral square.
    pub const MAPPING_EQUAL_AREA: u32 = 1;
    /// [`super::param::LOOKUP`]: nearest texel.
    pub const LOOKUP_NEAREST: u32 = 0;
    /// [`super::param::LOOKUP`]: bilinear between texel centres.
    pub const LOOKUP_BILINEAR: u32 = 1;
    /// [`super::param::RADIANCE_FORMAT`]: RGB `f32`, 3 words per texel.
    pub const RADIANCE_F32: u32 = 0;
    /// [`super::param::RADIANCE_FORMAT`]: RGBA `f16`, 2 words per texel.
    pub const RADIANCE_F16: u32 = 1;
}

/// How the radiance image is stored.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RadianceFormat {
    /// RGB `f32`, 12 bytes per texel: exactly the light's texels.
    #[default]
    F32,
    /// RGBA `f16` (alpha 0), 8 bytes per texel, rounded to nearest even. Refused
    /// for a map with a channel that would round to infinity (above 65504).
    F16,
}

/// Options of [`EnvironmentLight::gpu_tables`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GpuTableOptions {
    /// How the radiance image is stored.
    pub radiance: RadianceFormat,
}

/// The element type of a section (the section table's `element` field).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ElementType {
    /// Code 0: `u32`.
    U32,
    /// Code 1: `f32`.
    F32,
    /// Code 2: `f16`.
    F16,
}

impl ElementType {
    /// The code stored in the section table.
    pub fn code(self) -> u32 {
        match self {
            ElementType::U32 => 0,
            ElementType::F32 => 1,
            ElementType::F16 => 2,
        }
    }

    /// The type of a code, `None` for an unknown one.
    pub fn from_code(code: u32) -> Option<Self> {
        match code {
            0 => Some(ElementType::U32),
            1 => Some(ElementType::F32),
            2 => Some(ElementType::F16),
            _ => None,
        }
    }

    /// Bytes per element.
    pub fn bytes(self) -> u64 {
        match self {
            ElementType::U32 | ElementType::F32 => 4,
            ElementType::F16 => 2,
        }
    }

    /// `"u32"`, `"f32"` or `"f16"`.
    pub fn name(self) -> &'static str {
        match self {
            ElementType::U32 => "u32",
            ElementType::F32 => "f32",
            ElementType::F16 => "f16",
        }
    }
}

/// One entry of the section table, as [`GpuTables::to_bytes`] writes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SectionInfo {
    /// The section id ([`section`]).
    pub id: u32,
    /// Its name ([`section::name`]).
    pub name: &'static str,
    /// The type of its elements.
    pub element: ElementType,
    /// Number of elements of that type (`alias_slots`: 2 per slot; `radiance`:
    /// 3 `f32` or 4 `f16` per texel).
    pub count: u64,
    /// Byte offset from the start of the file (a multiple of 16).
    pub byte_offset: u64,
    /// Byte length, without the padding that follows.
    pub byte_len: u64,
}

/// A sampling section's place in the tables buffer.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Placed {
    id: u32,
    /// Offset in words from the start of the tables buffer (a multiple of 4).
    word_offset: usize,
    /// Length in words, without padding.
    words: usize,
}

/// A light's flat GPU tables: the parameter block, the tables buffer and the
/// radiance buffer of `docs/gpu-tables.md` (see the module docs).
///
/// Memory: the light's sampling data (4 bytes per CDF value, guide entry, alias
/// word or node value) plus the radiance image (12 or 8 bytes per texel); building
/// copies them once, `O(w h)`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpuTables {
    params: [u32; PARAMS_WORDS],
    /// Sections 2–8 present, in id order, each padded to 16 bytes.
    tables: Vec<u32>,
    /// Where each of them sits in `tables`, in id order.
    layout: Vec<Placed>,
    /// Section 9's words, unpadded.
    radiance: Vec<u32>,
}

impl GpuTables {
    /// The parameter block (section 1).
    pub fn params(&self) -> &[u32; PARAMS_WORDS] {
        &self.params
    }

    /// The tables buffer: the sampling sections present (ids 2–8), concatenated
    /// in id order, each zero-padded to a multiple of 16 bytes, exactly the file's
    /// bytes from the first of them to the end of the last. Its length in words is
    /// `params()[param::TABLES_WORDS]`.
    pub fn tables(&self) -> &[u32] {
        &self.tables
    }

    /// The radiance buffer (section 9) as words: `f32` bits, 3 per texel, or two
    /// `f16` per word (low half first), 2 per texel (R, G then B, 0). Unpadded.
    pub fn radiance(&self) -> &[u32] {
        &self.radiance
    }

    /// The radiance format the tables hold.
    pub fn radiance_format(&self) -> RadianceFormat {
        if self.params[param::RADIANCE_FORMAT] == value::RADIANCE_F16 {
            RadianceFormat::F16
        } else {
            RadianceFormat::F32
        }
    }

    /// The section table [`Self::to_bytes`] writes: params, the sampling sections
    /// in id order, radiance.
    pub fn sections(&self) -> Vec<SectionInfo> {
        let count = 2 + self.layout.len();
        let params_at = (HEADER_BYTES + ENTRY_BYTES * count) as u64;
        let tables_at = params_at + 4 * PARAMS_WORDS as u64;
        let mut out = Vec::with_capacity(count);
        out.push(SectionInfo {
            id: section::PARAMS,
            name: "params",
            element: ElementType::U32,
            count: PARAMS_WORDS as u64,
            byte_offset: params_at,
            byte_len: 4 * PARAMS_WORDS as u64,
        });
        for p in &self.layout {
            out.push(SectionInfo {
                id: p.id,
                name: section::name(p.id).unwrap_or("unknown"),
                element: sampling_element(p.id),
                count: p.words as u64,
                byte_offset: tables_at + 4 * p.word_offset as u64,
                byte_len: 4 * p.words as u64,
            });
        }
        let (element, per_word) = match self.radiance_format() {
            RadianceFormat::F32 => (ElementType::F32, 1),
            RadianceFormat::F16 => (ElementType::F16, 2),
        };
        out.push(SectionInfo {
            id: section::RADIANCE,
            name: "radiance",
            element,
            count: per_word * self.radiance.len() as u64,
            byte_offset: tables_at + 4 * self.tables.len() as u64,
            byte_len: 4 * self.radiance.len() as u64,
        });
        out
    }

    /// Section `id`'s words, unpadded (`None` for a section these tables do not
    /// have).
    pub fn section_words(&self, id: u32) -> Option<&[u32]> {
        match id {
            section::PARAMS => Some(&self.params[..]),
            section::RADIANCE => Some(&self.radiance),
            _ => self
                .layout
                .iter()
                .find(|p| p.id == id)
                .map(|p| &self.tables[p.word_offset..p.word_offset + p.words]),
        }
    }

    /// The whole file: header, section table, then every section on a 16-byte
    /// boundary, each followed by zero padding to the next one.
    pub fn to_bytes(&self) -> Vec<u8> {
        let sections = self.sections();
        let end = sections
            .last()
            .map_or(0, |s| padded_bytes((s.byte_offset + s.byte_len) as usize));
        let mut out = Vec::with_capacity(end);
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&VERSION.to_le_bytes());
        out.extend_from_slice(&(sections.len() as u32).to_le_bytes());
        for s in &sections {
            out.extend_from_slice(&s.id.to_le_bytes());
            out.extend_from_slice(&s.element.code().to_le_bytes());
            out.extend_from_slice(&s.byte_offset.to_le_bytes());
            out.extend_from_slice(&s.byte_len.to_le_bytes());
            out.extend_from_slice(&s.count.to_le_bytes());
        }
        // The table's 32-byte entries keep the params on a 16-byte boundary, and
        // the tables buffer is padded already.
        for words in [&self.params[..], &self.tables, &self.radiance] {
            for w in words {
                out.extend_from_slice(&w.to_le_bytes());
            }
            out.resize(padded_bytes(out.len()), 0);
        }
        debug_assert_eq!(out.len(), end);
        out
    }

    /// Parses and checks a file written by [`Self::to_bytes`] (or by anyone
    /// following `docs/gpu-tables.md`). Sections with ids this version does not
    /// know are skipped (they must still lie inside the file, in table order).
    ///
    /// # Errors
    /// [`Error::Decode`] naming what is wrong: a short file, a bad magic number or
    /// version, a section that is misaligned, out of bounds, out of order,
    /// duplicated or of the wrong element type; a missing section the parameters
    /// call for, or one they do not; a length that does not match the sizes in the
    /// parameters; an offset in the parameters that does not match the file; a
    /// parameter code out of range; a CDF that does not run from 0 to `CDF_ONE`
    /// without decreasing, or a guide or alias entry outside its table.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self> {
        parse(bytes).map_err(|detail| Error::Decode {
            source_name: "<memory>".to_string(),
            format: FORMAT,
            detail,
        })
    }
}

/// The element type of a sampling section.
fn sampling_element(id: u32) -> ElementType {
    match id {
        section::ALIAS_FUNC | section::BILINEAR_VALUES => ElementType::F32,
        _ => ElementType::U32,
    }
}

/// `n` rounded up to a multiple of 16.
fn padded_bytes(n: usize) -> usize {
    n.div_ceil(ALIGN_BYTES) * ALIGN_BYTES
}

/// `n` words rounded up to a multiple of 16 bytes.
fn padded_words(n: usize) -> usize {
    n.div_ceil(ALIGN_WORDS) * ALIGN_WORDS
}

// ---------------------------------------------------------------------------
// Building from a light
// ---------------------------------------------------------------------------

impl EnvironmentLight {
    /// The light's tables in the flat layout of `docs/gpu-tables.md`
    /// ([`crate::gpu`]): the parameter block, the sampler's tables (copied, bit for
    /// bit the CPU's), and the radiance image in `options.radiance`'s format
    /// (unscaled: the scale is a parameter).
    ///
    /// # Errors
    /// [`Error::Unsupported`] for the hierarchical sampler (not ported to the GPU),
    /// or tables of more than 2³² words; [`Error::HalfOverflow`] for
    /// [`RadianceFormat::F16`] when a channel would round to infinity, naming the
    /// first such texel.
    pub fn gpu_tables(&self, options: &GpuTableOptions) -> Result<GpuTables> {
        let mut p = [0u32; PARAMS_WORDS];
        let rotation = self.options().rotation;
        for (at, rows) in [
            (param::LIGHT_TO_WORLD, rotation.rows()),
            (param::WORLD_TO_LIGHT, rotation.inverse().rows()),
        ] {
            for (i, row) in rows.iter().enumerate() {
                for (j, x) in row.iter().enumerate() {
                    p[at + 4 * i + j] = x.to_bits();
                }
            }
        }
        let image = self.image();
        let (w, h) = (image.width(), image.height());
        p[param::VERSION] = VERSION;
        p[param::MAPPING] = match self.mapping() {
            Mapping::Equirectangular => value::MAPPING_EQUIRECTANGULAR,
            Mapping::EqualArea => value::MAPPING_EQUAL_AREA,
        };
        p[param::LOOKUP] = match self.options().lookup {
            Lookup::Nearest => value::LOOKUP_NEAREST,
            Lookup::Bilinear => value::LOOKUP_BILINEAR,
        };
        p[param::RADIANCE_FORMAT] = match options.radiance {
            RadianceFormat::F32 => value::RADIANCE_F32,
            RadianceFormat::F16 => value::RADIANCE_F16,
        };
        p[param::ROTATED] = u32::from(!rotation.is_identity());
        p[param::BLACK] = u32::from(self.is_black());
        p[param::IMAGE_WIDTH] = to_u32(w, "image width")?;
        p[param::IMAGE_HEIGHT] = to_u32(h, "image height")?;
        p[param::SCALE] = self.options().scale.to_bits();
        p[param::INTEGRAL_LUMINANCE] = (self.integral_luminance() as f32).to_bits();

        let mut tables = Tables::default();
        match self.planar() {
            Planar::Inversion(d) => {
                p[param::SAMPLER] = value::SAMPLER_INVERSION;
                p[param::DENSITY] = value::DENSITY_PIECEWISE_CONSTANT;
                tables.push_inversion(d, &mut p)?;
            }
            Planar::Bilinear(d) => {
                if d.texel_centre_cells() != Some([w, h]) || d.values().len() != (w + 2) * (h + 2) {
                    return Err(Error::Unsupported(
                        "the GPU tables hold a piecewise-bilinear density only on the \
                         texel-centre node grid"
                            .into(),
                    ));
                }
                p[param::SAMPLER] = value::SAMPLER_INVERSION;
                p[param::DENSITY] = value::DENSITY_PIECEWISE_BILINEAR;
                tables.push_inversion(d.patches(), &mut p)?;
                let values = d.values().iter().map(|x| x.to_bits());
                tables.push(section::BILINEAR_VALUES, values, &mut p)?;
            }
            Planar::Alias(a) => {
                p[param::SAMPLER] = value::SAMPLER_ALIAS;
                p[param::DENSITY] = value::DENSITY_PIECEWISE_CONSTANT;
                p[param::TABLE_WIDTH] = to_u32(a.nu(), "table width")?;
                p[param::TABLE_HEIGHT] = to_u32(a.nv(), "table height")?;
                p[param::ALIAS_OFFSET_BITS] = a.offset_bits();
                p[param::ALIAS_INV_INTEGRAL] = (a.inv_integral() as f32).to_bits();
                let slots = a.slots().flat_map(|(t, alias)| [t.to_bits(), alias]);
                tables.push(section::ALIAS_SLOTS, slots, &mut p)?;
                let func = a.func().iter().map(|x| x.to_bits());
                tables.push(section::ALIAS_FUNC, func, &mut p)?;
            }
            Planar::Hierarchical(_) => {
                return Err(Error::Unsupported(
                    "the hierarchical sampler is not ported to the GPU; use --sampler \
                     inversion or alias"
                        .into(),
                ))
            }
        }
        p[param::TABLES_WORDS] = to_u32(tables.words.len(), "the tables buffer's length")?;
        let radiance = radiance_words(self, options.radiance)?;
        Ok(GpuTables {
            params: p,
            tables: tables.words,
            layout: tables.layout,
            radiance,
        })
    }
}

/// `n` as a `u32` parameter, or [`Error::Unsupported`] naming `what`.
fn to_u32(n: usize, what: &str) -> Result<u32> {
    u32::try_from(n).map_err(|_| {
        Error::Unsupported(format!(
            "{what} is {n}, more than the GPU tables' 32-bit words hold"
        ))
    })
}

/// The tables buffer under construction.
#[derive(Default)]
struct Tables {
    words: Vec<u32>,
    layout: Vec<Placed>,
}

impl Tables {
    /// Appends section `id` (sections must come in id order), pads it to 16
    /// bytes, and records its word offset in the parameter block.
    fn push(
        &mut self,
        id: u32,
        words: impl Iterator<Item = u32>,
        p: &mut [u32; PARAMS_WORDS],
    ) -> Result<()> {
        debug_assert!(self.layout.last().is_none_or(|l| l.id < id));
        let word_offset = self.words.len();
        self.words.extend(words);
        let len = self.words.len() - word_offset;
        self.words.resize(padded_words(self.words.len()), 0);
        if let Some(at) = param::offset_of(id) {
            p[at] = to_u32(word_offset, "a section's offset in the tables buffer")?;
        }
        self.layout.push(Placed {
            id,
            word_offset,
            words: len,
        });
        Ok(())
    }

    /// Sections 2–5: the marginal and conditional CDFs of `d` and their guide
    /// tables, with the table size and guide shifts in the parameter block.
    fn push_inversion(&mut self, d: &Distribution2D, p: &mut [u32; PARAMS_WORDS]) -> Result<()> {
        p[param::TABLE_WIDTH] = to_u32(d.nu(), "table width")?;
        p[param::TABLE_HEIGHT] = to_u32(d.nv(), "table height")?;
        let marginal = d.marginal();
        // Guide lengths are powers of two: log₂ is the trailing zero count.
        p[param::MARGINAL_GUIDE_SHIFT] = 32 - marginal.guide().len().trailing_zeros();
        p[param::CONDITIONAL_GUIDE_BITS] = d.row_guide_bits();
        self.push(section::MARGINAL_CDF, marginal.cdf().iter().copied(), p)?;
        self.push(section::MARGINAL_GUIDE, marginal.guide().iter().copied(), p)?;
        self.push(
            section::CONDITIONAL_CDF,
            d.conditional_cdfs().iter().copied(),
            p,
        )?;
        self.push(
            section::CONDITIONAL_GUIDE,
            d.conditional_guides().iter().copied(),
            p,
        )
    }
}

/// The radiance section's words for `format` (the light's image, unscaled).
fn radiance_words(light: &EnvironmentLight, format: RadianceFormat) -> Result<Vec<u32>> {
    let image = light.image();
    match format {
        RadianceFormat::F32 => Ok(image
            .texels()
            .iter()
            .flat_map(|t| t.map(f32::to_bits))
            .collect()),
        RadianceFormat::F16 => {
            let w = image.width();
            let mut out = Vec::with_capacity(2 * image.texels().len());
            for (k, t) in image.texels().iter().enumerate() {
                let mut half = [0u16; 3];
                for (c, (&x, name)) in t.iter().zip(['R', 'G', 'B']).enumerate() {
                    half[c] = f32_to_f16_bits(x);
                    if half[c] & 0x7fff >= F16_INFINITY {
                        return Err(Error::HalfOverflow {
                            pos: TexelPos { x: k % w, y: k / w },
                            channel: name,
                            value: x,
                        });
                    }
                }
                out.push(u32::from(half[0]) | (u32::from(half[1]) << 16));
                out.push(u32::from(half[2]));
            }
            Ok(out)
        }
    }
}

/// The bits of `f16` +∞ (exponent all ones, mantissa 0).
const F16_INFINITY: u16 = 0x7c00;

/// `x` as IEEE-754 binary16 bits, rounded to nearest, ties to even: values from
/// 65520 up become ±∞, values below 2⁻²⁵ in magnitude ±0, those in between and
/// below 2⁻¹⁴ subnormals; NaN stays NaN (quiet).
fn f32_to_f16_bits(x: f32) -> u16 {
    let bits = x.to_bits();
    let sign = ((bits >> 16) & 0x8000) as u16;
    let exponent = ((bits >> 23) & 0xff) as i32;
    let mantissa = bits & 0x7f_ffff;
    if exponent == 0xff {
        let nan = if mantissa != 0 { 0x200 } else { 0 };
        return sign | F16_INFINITY | nan;
    }
    // The exponent rebiased to f16's (bias 15 instead of 127).
    let e = exponent - 127 + 15;
    if e >= 0x1f {
        return sign | F16_INFINITY;
    }
    // With the implicit leading 1: x = m · 2^(exponent − 150), and as an f16
    // (normal or not) the mantissa field counts units of 2^(e − 25) for e ≥ 1, of
    // 2⁻²⁴ below. So drop `shift` low bits of m and round what they held.
    let (base, m, shift) = if e >= 1 {
        ((e as u32) << 10, mantissa, 13)
    } else if e >= -10 {
        (0, mantissa | 0x80_0000, (14 - e) as u32)
    } else {
        // Below half the smallest subnormal (or an f32 subnormal): ±0.
        return sign;
    };
    let kept = m >> shift;
    let rest = m & ((1 << shift) - 1);
    let half = 1 << (shift - 1);
    let round_up = rest > half || (rest == half && kept & 1 == 1);
    // A carry out of the mantissa steps the exponent, and out of the largest
    // finite value to +∞: both are the right answer.
    sign | (base + kept + u32::from(round_up)) as u16
}

// ---------------------------------------------------------------------------
// Reading a file
// ---------------------------------------------------------------------------

/// A known section's entry in the section table.
#[derive(Debug, Clone, Copy)]
struct Entry {
    element: ElementType,
    byte_offset: usize,
    byte_len: usize,
    count: u64,
}

/// The little-endian `u32` at byte `at` (the caller checked the bounds).
fn u32_at(bytes: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(b)
}

/// The little-endian `u64` at byte `at` (the caller checked the bounds).
fn u64_at(bytes: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(b)
}

/// `n` words from byte `at` (the caller checked the bounds).
fn words_at(bytes: &[u8], at: usize, n: usize) -> Vec<u32> {
    bytes[at..at + 4 * n]
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
}

/// [`GpuTables::from_bytes`], with the detail of the error.
fn parse(bytes: &[u8]) -> std::result::Result<GpuTables, String> {
    let len = bytes.len();
    if len < HEADER_BYTES {
        return Err(format!(
            "truncated: {len} bytes, shorter than the {HEADER_BYTES}-byte header"
        ));
    }
    if bytes[..8] != MAGIC {
        return Err(format!(
            "bad magic number {:02x?}: not an envlight GPU tables file (expected \"ENVLGPU\\0\")",
            &bytes[..8]
        ));
    }
    let version = u32_at(bytes, 8);
    if version != VERSION {
        return Err(format!(
            "layout version {version}, but this reader knows version {VERSION} only"
        ));
    }
    let entries = find_sections(bytes)?;
    let params_entry = entries[section::PARAMS as usize].ok_or("no params section (id 1)")?;
    if params_entry.element != ElementType::U32 || params_entry.count != PARAMS_WORDS as u64 {
        return Err(format!(
            "the params section holds {} {} elements, not {PARAMS_WORDS} u32",
            params_entry.count,
            params_entry.element.name()
        ));
    }
    let mut params = [0u32; PARAMS_WORDS];
    params.copy_from_slice(&words_at(bytes, params_entry.byte_offset, PARAMS_WORDS));
    let expected = expected_sampling(&params)?;

    // The sampling sections: exactly those the parameters call for, contiguous in
    // id order from the first, where the parameters say they are.
    let first = expected
        .first()
        .ok_or("the parameters call for no sampling section")?;
    let first_entry = entries[first.id as usize].ok_or_else(|| missing(first.id, &params))?;
    let tables_at = first_entry.byte_offset;
    for id in section::SAMPLING {
        let name = section::name(id).unwrap_or("?");
        let entry = entries[id as usize];
        let Some(place) = expected.iter().find(|p| p.id == id) else {
            if entry.is_some() {
                return Err(format!(
                    "section {name} is present, but the parameters ({}) do not use it",
                    describe(&params)
                ));
            }
            continue;
        };
        let entry = entry.ok_or_else(|| missing(id, &params))?;
        if entry.count != place.words as u64 {
            return Err(format!(
                "section {name} holds {} elements, but the parameters' sizes call for {}",
                entry.count, place.words
            ));
        }
        let want = tables_at as u64 + 4 * place.word_offset as u64;
        if entry.byte_offset as u64 != want {
            return Err(format!(
                "section {name} starts at byte {}, but the tables buffer (from byte \
                 {tables_at}) puts it at {want}: the sampling sections must follow each \
                 other in id order, each padded to 16 bytes",
                entry.byte_offset
            ));
        }
    }
    let tables_words = params[param::TABLES_WORDS] as usize;
    let tables_end = tables_at as u64 + 4 * tables_words as u64;
    if tables_end > len as u64 {
        return Err(format!(
            "truncated: the tables buffer runs from byte {tables_at} to {tables_end}, past \
             the end of the file ({len} bytes)"
        ));
    }
    let tables = words_at(bytes, tables_at, tables_words);

    let radiance = entries[section::RADIANCE as usize].ok_or("no radiance section (id 9)")?;
    let (want_element, per_texel) = match params[param::RADIANCE_FORMAT] {
        value::RADIANCE_F32 => (ElementType::F32, 3),
        _ => (ElementType::F16, 4),
    };
    let texels = params[param::IMAGE_WIDTH] as u64 * params[param::IMAGE_HEIGHT] as u64;
    let want_count = texels.saturating_mul(per_texel);
    if radiance.element != want_element || radiance.count != want_count {
        return Err(format!(
            "the radiance section holds {} {} elements, but a {}x{} image in the format \
             the parameters name needs {} {}",
            radiance.count,
            radiance.element.name(),
            params[param::IMAGE_WIDTH],
            params[param::IMAGE_HEIGHT],
            want_count,
            want_element.name()
        ));
    }
    if radiance.byte_offset < tables_at + 4 * tables_words {
        return Err("the radiance section overlaps the tables buffer".into());
    }
    let radiance = words_at(bytes, radiance.byte_offset, radiance.byte_len / 4);
    let out = GpuTables {
        params,
        tables,
        layout: expected,
        radiance,
    };
    check_contents(&out)?;
    Ok(out)
}

/// The section table's known entries, indexed by id, after checking that every
/// entry (known or not) is aligned, in bounds and after the previous one, and
/// that known ones have their element type, a byte length that matches their
/// count, and no duplicate.
fn find_sections(bytes: &[u8]) -> std::result::Result<[Option<Entry>; 10], String> {
    let len = bytes.len() as u64;
    let count = u32_at(bytes, 12) as u64;
    let table_end = HEADER_BYTES as u64 + ENTRY_BYTES as u64 * count;
    if table_end > len {
        return Err(format!(
            "truncated: the section table of {count} entries needs {table_end} bytes, the \
             file has {len}"
        ));
    }
    let mut entries: [Option<Entry>; 10] = [None; 10];
    let mut previous_end = table_end;
    for k in 0..count as usize {
        let at = HEADER_BYTES + ENTRY_BYTES * k;
        let id = u32_at(bytes, at);
        let code = u32_at(bytes, at + 4);
        let byte_offset = u64_at(bytes, at + 8);
        let byte_len = u64_at(bytes, at + 16);
        let elements = u64_at(bytes, at + 24);
        let name = section::name(id);
        let what = match name {
            Some(name) => format!("section {name}"),
            None => format!("section {k} (unknown id {id})"),
        };
        if !byte_offset.is_multiple_of(ALIGN_BYTES as u64) {
            return Err(format!(
                "{what} starts at byte {byte_offset}, not a multiple of 16"
            ));
        }
        if byte_offset < previous_end {
            return Err(format!(
                "{what} starts at byte {byte_offset}, inside the header, the section table \
                 or the section before it (which end at byte {previous_end})"
            ));
        }
        let end = byte_offset.checked_add(byte_len).filter(|&e| e <= len);
        let Some(end) = end else {
            return Err(format!(
                "{what} (byte {byte_offset}, {byte_len} bytes) runs past the end of the \
                 file ({len} bytes): truncated or corrupt"
            ));
        };
        previous_end = end;
        let Some(name) = name else {
            continue;
        };
        let element = ElementType::from_code(code)
            .ok_or_else(|| format!("{what} has unknown element type {code}"))?;
        let allowed = match id {
            section::RADIANCE => element != ElementType::U32,
            _ => element == known_element(id),
        };
        if !allowed {
            return Err(format!("{what} has element type {}", element.name()));
        }
        if elements.checked_mul(element.bytes()) != Some(byte_len) || !byte_len.is_multiple_of(4) {
            return Err(format!(
                "{what} has {elements} {} elements in {byte_len} bytes",
                element.name()
            ));
        }
        let slot = &mut entries[id as usize];
        if slot.is_some() {
            return Err(format!("section {name} appears twice"));
        }
        // In bounds of the file, so they fit in usize.
        *slot = Some(Entry {
            element,
            byte_offset: byte_offset as usize,
            byte_len: byte_len as usize,
            count: elements,
        });
    }
    Ok(entries)
}

/// The element type of a known section other than the radiance.
fn known_element(id: u32) -> ElementType {
    match id {
        section::PARAMS => ElementType::U32,
        _ => sampling_element(id),
    }
}

/// The error for a sampling section the parameters call for and the file lacks.
fn missing(id: u32, params: &[u32; PARAMS_WORDS]) -> String {
    format!(
        "no {} section (id {id}), which the parameters ({}) call for",
        section::name(id).unwrap_or("?"),
        describe(params)
    )
}

/// `sampler S, density D` as the parameters name them.
fn describe(p: &[u32; PARAMS_WORDS]) -> String {
    let sampler = match p[param::SAMPLER] {
        value::SAMPLER_INVERSION => "inversion",
        _ => "alias",
    };
    let density = match p[param::DENSITY] {
        value::DENSITY_PIECEWISE_CONSTANT => "piecewise-constant",
        _ => "piecewise-bilinear",
    };
    format!("sampler {sampler}, density {density}")
}

/// Checks the parameter block's codes and sizes, and returns the sampling
/// sections they call for with their places in the tables buffer (in id order,
/// each padded to 16 bytes); the parameters' offsets and `tables_words` must be
/// exactly those.
fn expected_sampling(p: &[u32; PARAMS_WORDS]) -> std::result::Result<Vec<Placed>, String> {
    if p[param::VERSION] != VERSION {
        return Err(format!(
            "the parameter block says layout version {}, the header {VERSION}",
            p[param::VERSION]
        ));
    }
    for (word, name) in [
        (param::SAMPLER, "sampler"),
        (param::DENSITY, "density"),
        (param::MAPPING, "mapping"),
        (param::LOOKUP, "lookup"),
        (param::RADIANCE_FORMAT, "radiance_format"),
        (param::ROTATED, "rotated"),
        (param::BLACK, "black"),
    ] {
        if p[word] > 1 {
            return Err(format!(
                "parameter {name} (word {word}) is {}, not 0 or 1",
                p[word]
            ));
        }
    }
    let bilinear = p[param::DENSITY] == value::DENSITY_PIECEWISE_BILINEAR;
    let alias = p[param::SAMPLER] == value::SAMPLER_ALIAS;
    if bilinear && alias {
        return Err(
            "the parameters name the alias sampler with the piecewise-bilinear \
                    density, which is sampled by inversion only"
                .into(),
        );
    }
    let size = |word: usize, name: &str| -> std::result::Result<u64, String> {
        match p[word] {
            0 => Err(format!("parameter {name} (word {word}) is 0")),
            n => Ok(n as u64),
        }
    };
    let (iw, ih) = (
        size(param::IMAGE_WIDTH, "image_width")?,
        size(param::IMAGE_HEIGHT, "image_height")?,
    );
    let (tw, th) = (
        size(param::TABLE_WIDTH, "table_width")?,
        size(param::TABLE_HEIGHT, "table_height")?,
    );
    if bilinear && (tw != iw + 1 || th != ih + 1) {
        return Err(format!(
            "the piecewise-bilinear density's table is {tw}x{th} patches, not the \
             {}x{} of a {iw}x{ih} image",
            iw + 1,
            ih + 1
        ));
    }
    // Sizes come from the file: saturating products (which then match no
    // section) rather than overflow.
    let mul = |a: u64, b: u64| a.saturating_mul(b);
    let mut wanted: Vec<(u32, u64)> = Vec::new();
    if alias {
        let bits = p[param::ALIAS_OFFSET_BITS];
        if !(1..=24).contains(&bits) {
            return Err(format!(
                "parameter alias_offset_bits (word {}) is {bits}, not in 1..=24",
                param::ALIAS_OFFSET_BITS
            ));
        }
        wanted.push((section::ALIAS_SLOTS, mul(2, mul(tw, th))));
        wanted.push((section::ALIAS_FUNC, mul(tw, th)));
    } else {
        let shift = p[param::MARGINAL_GUIDE_SHIFT];
        if !(1..=32).contains(&shift) {
            return Err(format!(
                "parameter marginal_guide_shift (word {}) is {shift}, not in 1..=32",
                param::MARGINAL_GUIDE_SHIFT
            ));
        }
        let bits = p[param::CONDITIONAL_GUIDE_BITS];
        if bits > 31 {
            return Err(format!(
                "parameter conditional_guide_bits (word {}) is {bits}, not in 0..=31",
                param::CONDITIONAL_GUIDE_BITS
            ));
        }
        wanted.push((section::MARGINAL_CDF, th + 1));
        wanted.push((section::MARGINAL_GUIDE, 1u64 << (32 - shift)));
        wanted.push((section::CONDITIONAL_CDF, mul(th, tw + 1)));
        wanted.push((section::CONDITIONAL_GUIDE, mul(th, 1 << bits)));
        if bilinear {
            wanted.push((section::BILINEAR_VALUES, mul(ih + 2, iw + 2)));
        }
    }
    let mut placed = Vec::with_capacity(wanted.len());
    let mut offset = 0u64;
    for (id, words) in wanted {
        // Offsets and lengths are 32-bit words: anything larger cannot be what the
        // parameters say.
        let (Ok(word_offset), Ok(n)) = (usize::try_from(offset), usize::try_from(words)) else {
            return Err("the sections the parameters call for do not fit in memory".into());
        };
        if offset > u32::MAX as u64 {
            return Err("the sampling sections would need more than 2³² words".into());
        }
        placed.push(Placed {
            id,
            word_offset,
            words: n,
        });
        offset = offset.saturating_add(mul(words.div_ceil(ALIGN_WORDS as u64), ALIGN_WORDS as u64));
    }
    for id in section::SAMPLING {
        let word = param::offset_of(id).unwrap_or(param::RESERVED);
        let want = placed
            .iter()
            .find(|q| q.id == id)
            .map_or(0, |q| q.word_offset);
        if p[word] as usize != want {
            return Err(format!(
                "parameter {} (word {word}) is {}, but the sections the parameters call for \
                 put it at word {want} of the tables buffer",
                section::name(id).unwrap_or("?"),
                p[word]
            ));
        }
    }
    if p[param::TABLES_WORDS] as u64 != offset {
        return Err(format!(
            "parameter tables_words (word {}) is {}, but the sections the parameters call \
             for take {offset} words",
            param::TABLES_WORDS,
            p[param::TABLES_WORDS]
        ));
    }
    Ok(placed)
}

/// The checks a shader's memory safety rests on: every CDF runs from 0 to
/// `CDF_ONE` without decreasing (so the forward scan from a guide entry stops
/// inside the row), every guide entry names a cell of its CDF, every alias names
/// a cell and every threshold is in `[0, 1]`.
fn check_contents(t: &GpuTables) -> std::result::Result<(), String> {
    let p = &t.params;
    let (tw, th) = (
        p[param::TABLE_WIDTH] as usize,
        p[param::TABLE_HEIGHT] as usize,
    );
    let words = |id: u32| t.section_words(id).unwrap_or(&[]);
    if p[param::SAMPLER] == value::SAMPLER_ALIAS {
        let n = (tw * th) as u64;
        for (k, slot) in words(section::ALIAS_SLOTS).chunks_exact(2).enumerate() {
            let threshold = f32::from_bits(slot[0]);
            if !(0.0..=1.0).contains(&threshold) || slot[1] as u64 >= n {
                return Err(format!(
                    "alias slot {k} has threshold {threshold} and alias {}: the threshold \
                     must be in [0, 1] and the alias below {n}",
                    slot[1]
                ));
            }
        }
        return Ok(());
    }
    check_cdfs(
        "marginal_cdf",
        words(section::MARGINAL_CDF),
        th,
        words(section::MARGINAL_GUIDE),
    )?;
    check_cdfs(
        "conditional_cdf",
        words(section::CONDITIONAL_CDF),
        tw,
        words(section::CONDITIONAL_GUIDE),
    )
}

/// Checks rows of `n + 1` CDF values (`cdf.len() / (n + 1)` of them) and their
/// guide tables (`guide.len()` split evenly among the rows).
fn check_cdfs(name: &str, cdf: &[u32], n: usize, guide: &[u32]) -> std::result::Result<(), String> {
    let rows = cdf.len() / (n + 1);
    for (r, row) in cdf.chunks_exact(n + 1).enumerate() {
        let ends = (row.first(), row.last());
        if ends != (Some(&0), Some(&CDF_ONE)) || row.windows(2).any(|w| w[0] > w[1]) {
            return Err(format!(
                "{name} row {r} does not rise from 0 to {CDF_ONE} without decreasing"
            ));
        }
    }
    if let Some(k) = guide.iter().position(|&g| g as usize >= n) {
        let per_row = guide.len() / rows.max(1);
        return Err(format!(
            "the guide of {name} row {} names cell {} of {n}",
            k / per_row.max(1),
            guide[k]
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
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

    /// Every supported light: sampler × density, both mappings, both lookups, a
    /// rotation, a scale, MIS compensation, a reduced table, a black map.
    fn lights() -> Vec<(String, EnvironmentLight)> {
        let mut out = Vec::new();
        let cases = [
            (Sampler::Inversion, Density::PiecewiseConstant),
            (Sampler::Alias, Density::PiecewiseConstant),
            (Sampler::Inversion, Density::PiecewiseBilinear),
        ];
        for (sampler, density) in cases {
            for mapping in Mapping::ALL {
                for lookup in [Lookup::Nearest, Lookup::Bilinear] {
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
                out.push((
                    format!("tiny {w}x{h} {} {}", sampler.name(), density.name()),
                    EnvironmentLight::new(map(w, h), options).unwrap(),
                ));
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
        let light = EnvironmentLight::new(map(16, 8), LightOptions::default()).unwrap();
        let t = tables(&light);
        let good = t.to_bytes();
        let sections = t.sections();
        let entry = |id: u32| 16 + 32 * sections.iter().position(|s| s.id == id).unwrap();

        rejected(
            &patched(&good, 0, u32::from_le_bytes(*b"ENVX")),
            "bad magic",
        );
        rejected(&patched(&good, 8, 2), "layout version 2");
        rejected(&good[..10], "truncated: 10 bytes");
        rejected(&good[..20], "section table");
        rejected(&good[..good.len() - 4], "radiance");
        rejected(&good[..good.len() - 4], "past the end of the file");
        // A section out of bounds, misaligned, or overlapping the one before.
        let at = entry(section::CONDITIONAL_CDF);
        rejected(&patched(&good, at + 8, 1 << 30), "conditional_cdf");
        rejected(&patched(&good, at + 8, 1 << 30), "past the end");
        let offset = u64_at(&good, at + 8) as u32;
        rejected(&patched(&good, at + 8, offset + 4), "not a multiple of 16");
        rejected(&patched(&good, at + 8, offset - 16), "inside");
        // A missing required section (its id made unknown: skipped).
        rejected(
            &patched(&good, entry(section::MARGINAL_GUIDE), 77),
            "no marginal_guide section",
        );
        rejected(
            &patched(&good, entry(section::RADIANCE), 77),
            "no radiance section",
        );
        rejected(
            &patched(&good, entry(section::PARAMS), 77),
            "no params section",
        );
        // Inconsistent sizes and codes.
        let params_at = sections[0].byte_offset as usize;
        // One more row moves the sections after the conditional CDFs.
        rejected(
            &patched(&good, params_at + 4 * param::TABLE_HEIGHT, 9),
            "parameter conditional_guide (word 42) is 152",
        );
        // Half the guide entries (and a tables buffer that short): the section in
        // the file is longer than the sizes say.
        let shorter = patched(&good, params_at + 4 * param::CONDITIONAL_GUIDE_BITS, 2);
        let words = t.params()[param::TABLES_WORDS] - 32;
        let shorter = patched(&shorter, params_at + 4 * param::TABLES_WORDS, words);
        rejected(
            &shorter,
            "conditional_guide holds 64 elements, but the parameters' sizes call for 32",
        );
        rejected(
            &patched(&good, params_at + 4 * param::IMAGE_WIDTH, 17),
            "17x8",
        );
        rejected(
            &patched(&good, params_at + 4 * param::SAMPLER, 1),
            "alias_offset_bits",
        );
        rejected(
            &patched(&good, params_at + 4 * param::SAMPLER, 7),
            "sampler (word 25) is 7",
        );
        rejected(
            &patched(&good, params_at + 4 * param::VERSION, 2),
            "version 2",
        );
        rejected(
            &patched(&good, params_at + 4 * param::TABLES_WORDS, 4),
            "tables_words",
        );
        rejected(
            &patched(&good, params_at + 4 * param::CONDITIONAL_CDF, 8),
            "conditional_cdf",
        );
        rejected(
            &patched(&good, entry(section::RADIANCE) + 4, 2),
            "section radiance has 384 f16",
        );
        rejected(
            &patched(&good, entry(section::MARGINAL_CDF) + 24, 3),
            "3 u32 elements in 36",
        );
        // Contents a shader would walk off the end of.
        let cdf_at = sections[1].byte_offset as usize;
        rejected(&patched(&good, cdf_at + 4 * 8, 5), "marginal_cdf row 0");
        let guide_at = t.sections()[4].byte_offset as usize;
        rejected(&patched(&good, guide_at, 16), "names cell 16 of 16");

        let alias = EnvironmentLight::new(
            map(16, 8),
            LightOptions {
                sampler: Sampler::Alias,
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

    /// `t`'s file with one more section of unknown id 42 (16 bytes) at the end.
    fn extra_section(t: &GpuTables) -> Vec<u8> {
        let mut sections = t.sections();
        for s in sections.iter_mut() {
            s.byte_offset += 32;
        }
        let old = t.to_bytes();
        let old_data = 16 + 32 * sections.len();
        let mut b = Vec::new();
        b.extend_from_slice(&MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&(sections.len() as u32 + 1).to_le_bytes());
        for s in &sections {
            b.extend_from_slice(&s.id.to_le_bytes());
            b.extend_from_slice(&s.element.code().to_le_bytes());
            b.extend_from_slice(&s.byte_offset.to_le_bytes());
            b.extend_from_slice(&s.byte_len.to_le_bytes());
            b.extend_from_slice(&s.count.to_le_bytes());
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
                Some((crate::equal_area::sphere_to_square(d), 4.0 * PI))
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
            let wu =
                self.cdf(param::CONDITIONAL_CDF, row + 1) - self.cdf(param::CONDITIONAL_CDF, row);
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
            let (i, k) = (cell(u, w, 0.5, w)?, cell(v, h, 0.5, h)?);
            let [f00, f10, f01, f11] = self.corners(i, k);
            let (u0, u1) = (Self::node(i, w), Self::node(i + 1, w));
            let (v0, v1) = (Self::node(k, h), Self::node(k + 1, h));
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
            let (v0, v1) = (Self::node(iv, h), Self::node(iv + 1, h));
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
                    [
                        ((s.uv[0] as f64 * w as f64 + 0.5) as usize).min(w),
                        ((s.uv[1] as f64 * h as f64 + 0.5) as usize).min(h),
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
}
