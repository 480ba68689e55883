//! Tiny helpers for linear RGB triples.

/// A linear RGB triple.
pub type Rgb = [f32; 3];

#[inline]
pub(crate) fn mul(a: Rgb, b: Rgb) -> Rgb {
    [a[0] * b[0], a[1] * b[1], a[2] * b[2]]
}

#[inline]
pub(crate) fn scale(a: Rgb, s: f32) -> Rgb {
    [a[0] * s, a[1] * s, a[2] * s]
}

#[inline]
pub(crate) fn add(a: Rgb, b: Rgb) -> Rgb {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

#[inline]
pub(crate) fn max_component(a: Rgb) -> f32 {
    a[0].max(a[1]).max(a[2])
}

#[inline]
pub(crate) fn is_black(a: Rgb) -> bool {
    a == [0.0; 3]
}
