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

mod build;
mod parse;
#[cfg(test)]
mod tests;

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
        // Ids 1 to 9, in order.
        const NAMES: [&str; 9] = [
            "params",
            "marginal_cdf",
            "marginal_guide",
            "conditional_cdf",
            "conditional_guide",
            "alias_slots",
            "alias_func",
            "bilinear_values",
            "radiance",
        ];
        NAMES.get((id as usize).wrapping_sub(1)).copied()
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
    /// `u32`: 0 = nearest, 1 = bilinear, 2 = node rows (Mitsuba's envmap).
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
    /// `u32`: where the piecewise-bilinear density's nodes sit along v: 0 = texel
    /// centres `0, (j + ½)/h, 1`, 1 = node rows `0, 0, j/(h − 1), 1, 1` (the node
    /// lookup's, `h ≥ 2`); 0 for the piecewise-constant density.
    pub const BILINEAR_V_NODES: usize = 50;
    /// Words 51–63: reserved, 0.
    pub const RESERVED: usize = 51;

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
    /// [`super::param::LOOKUP`]: bilinear with rows as nodes from pole to pole
    /// (Mitsuba's envmap; [`crate::Lookup::Node`]).
    pub const LOOKUP_NODE: u32 = 2;
    /// [`super::param::BILINEAR_V_NODES`]: texel centres.
    pub const V_NODES_TEXEL_CENTRES: u32 = 0;
    /// [`super::param::BILINEAR_V_NODES`]: the node lookup's rows, pole to pole.
    pub const V_NODES_NODE_ROWS: u32 = 1;
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

impl RadianceFormat {
    /// Every format, in declaration order, for option parsers and tests.
    pub const ALL: [RadianceFormat; 2] = [RadianceFormat::F32, RadianceFormat::F16];
    /// The name used on the command line and in Python: `"f32"` or `"f16"`.
    pub fn name(self) -> &'static str {
        match self {
            RadianceFormat::F32 => "f32",
            RadianceFormat::F16 => "f16",
        }
    }
}

crate::light::named_option!(RadianceFormat, "radiance");

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
        parse::parse(bytes).map_err(|detail| Error::Decode {
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
