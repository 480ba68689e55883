//! Laying a light out as GPU tables: the sampling sections, the parameter block and
//! the radiance (f32, or f16 rounded to nearest even).

use super::*;

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
            Lookup::Node => value::LOOKUP_NODE,
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
                let Some(([cw, ch], node_rows)) = d.image_cells() else {
                    return Err(Error::Unsupported(
                        "the GPU tables hold a piecewise-bilinear density only on the \
                         light's node grids"
                            .into(),
                    ));
                };
                if [cw, ch] != [w, h] || d.values().len() != (w + 2) * (h + 2) {
                    return Err(Error::Unsupported(
                        "the GPU tables hold a piecewise-bilinear density only on the \
                         light's node grids"
                            .into(),
                    ));
                }
                p[param::SAMPLER] = value::SAMPLER_INVERSION;
                p[param::BILINEAR_V_NODES] = if node_rows {
                    value::V_NODES_NODE_ROWS
                } else {
                    value::V_NODES_TEXEL_CENTRES
                };
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
pub(super) fn f32_to_f16_bits(x: f32) -> u16 {
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
