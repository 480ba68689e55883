//! Colour helpers: luminance and the sRGB transfer function.

/// Luminance weights of linear Rec.709 primaries (D65): `Y = 0.212671 R + 0.715160 G + 0.072169 B`.
pub const LUMINANCE_WEIGHTS: [f32; 3] = [0.212671, 0.715160, 0.072169];

/// Luminance `Y` of a linear Rec.709 RGB triple.
#[inline]
pub fn luminance(rgb: [f32; 3]) -> f32 {
    LUMINANCE_WEIGHTS[0] * rgb[0] + LUMINANCE_WEIGHTS[1] * rgb[1] + LUMINANCE_WEIGHTS[2] * rgb[2]
}

/// Decodes one sRGB-encoded channel value in `[0, 1]` to linear light.
#[inline]
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Encodes one linear channel value to sRGB in `[0, 1]` (clamping outside that range).
#[inline]
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}
