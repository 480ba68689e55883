//! A tiny 5×7 bitmap font for labelling images (comparison sheets here, the CLI's
//! importance pictures): A–Z (lower case is drawn as upper case), 0–9, space,
//! `. , : - + = _ / ( ) [ ] % ?`, `×`, `°`, `θ` and `φ`. [`glyph`] draws anything
//! else as `?`; [`try_glyph`] lets a caller choose its own stand-in.

/// Glyph width in font pixels.
pub const GLYPH_WIDTH: usize = 5;
/// Glyph height in font pixels.
pub const GLYPH_HEIGHT: usize = 7;
/// Horizontal advance per character (glyph plus one pixel of spacing).
pub const ADVANCE: usize = GLYPH_WIDTH + 1;

/// The `?` glyph, also drawn by [`glyph`] for characters the font lacks.
const QUESTION_MARK: [u8; GLYPH_HEIGHT] = [0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04];

/// Rows of the glyph for `c`, top first; bit 4 is the leftmost pixel. Characters
/// the font lacks are drawn as `?`.
pub fn glyph(c: char) -> [u8; GLYPH_HEIGHT] {
    try_glyph(c).unwrap_or(QUESTION_MARK)
}

/// Rows of the glyph for `c` as in [`glyph`], or `None` when the font has none.
pub fn try_glyph(c: char) -> Option<[u8; GLYPH_HEIGHT]> {
    Some(match c.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        ' ' => [0; 7],
        '.' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C],
        '-' => [0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00],
        '=' => [0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        ':' => [0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '/' => [0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00],
        '+' => [0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00],
        ',' => [0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08],
        '?' => QUESTION_MARK,
        '_' => [0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '×' => [0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x00],
        '°' => [0x0C, 0x12, 0x12, 0x0C, 0x00, 0x00, 0x00],
        'Θ' | 'θ' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x0E],
        'Φ' | 'φ' => [0x04, 0x0E, 0x15, 0x15, 0x15, 0x0E, 0x04],
        _ => return None,
    })
}

/// An 8-bit RGB canvas (row-major, 3 bytes per pixel).
#[derive(Debug, Clone, PartialEq)]
pub struct Canvas {
    /// Width in pixels.
    pub width: usize,
    /// Height in pixels.
    pub height: usize,
    /// `3 · width · height` bytes.
    pub rgb: Vec<u8>,
}

impl Canvas {
    /// A canvas filled with `color`.
    pub fn new(width: usize, height: usize, color: [u8; 3]) -> Self {
        Self {
            width,
            height,
            rgb: color.repeat(width * height),
        }
    }

    /// Copies `rgb` (a `w × h` RGB8 block) with its top-left corner at `(x0, y0)`,
    /// clipped to the canvas.
    pub fn blit(&mut self, x0: usize, y0: usize, w: usize, h: usize, rgb: &[u8]) {
        for y in 0..h.min(self.height.saturating_sub(y0)) {
            let n = w.min(self.width.saturating_sub(x0));
            let dst = 3 * ((y0 + y) * self.width + x0);
            self.rgb[dst..dst + 3 * n].copy_from_slice(&rgb[3 * y * w..3 * (y * w + n)]);
        }
    }

    /// Blends `color` over the rectangle with opacity `alpha ∈ [0, 1]` (clipped).
    pub fn shade(&mut self, x0: usize, y0: usize, w: usize, h: usize, color: [u8; 3], alpha: f32) {
        for y in y0..(y0 + h).min(self.height) {
            for x in x0..(x0 + w).min(self.width) {
                let i = 3 * (y * self.width + x);
                for (dst, &src) in self.rgb[i..i + 3].iter_mut().zip(&color) {
                    *dst = (*dst as f32 * (1.0 - alpha) + src as f32 * alpha).round() as u8;
                }
            }
        }
    }

    /// Draws `text` with its top-left corner at `(x0, y0)`, each font pixel a
    /// `scale × scale` square (clipped).
    pub fn text(&mut self, x0: usize, y0: usize, text: &str, scale: usize, color: [u8; 3]) {
        for (k, c) in text.chars().enumerate() {
            let rows = glyph(c);
            for (gy, bits) in rows.iter().enumerate() {
                for gx in 0..GLYPH_WIDTH {
                    if bits & (0x10 >> gx) == 0 {
                        continue;
                    }
                    let px = x0 + (k * ADVANCE + gx) * scale;
                    let py = y0 + gy * scale;
                    for dy in 0..scale {
                        for dx in 0..scale {
                            let (x, y) = (px + dx, py + dy);
                            if x < self.width && y < self.height {
                                let i = 3 * (y * self.width + x);
                                self.rgb[i..i + 3].copy_from_slice(&color);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Draws lines of text on a translucent dark box at `(x0, y0)`.
    pub fn label(&mut self, x0: usize, y0: usize, lines: &[String], scale: usize) {
        let pad = 2 * scale;
        let line_height = (GLYPH_HEIGHT + 3) * scale;
        let w = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0) * ADVANCE * scale;
        let h = lines.len() * line_height;
        self.shade(x0, y0, w + 2 * pad, h + 2 * pad - 2 * scale, [0, 0, 0], 0.6);
        for (i, line) in lines.iter().enumerate() {
            self.text(
                x0 + pad,
                y0 + pad + i * line_height,
                line,
                scale,
                [255, 255, 255],
            );
        }
    }
}

/// Width in pixels of `text` drawn at `scale`.
pub fn text_width(text: &str, scale: usize) -> usize {
    text.chars().count() * ADVANCE * scale
}

/// Width in pixels of `text` drawn at `scale` without the spacing after its last
/// character: from the first glyph's left edge to the last glyph's right edge
/// (0 for empty text).
pub fn text_extent(text: &str, scale: usize) -> usize {
    let n = text.chars().count();
    if n == 0 {
        0
    } else {
        (n * ADVANCE - 1) * scale
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_glyph_fits_in_five_columns() {
        let chars = "ABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789 .-=%:()/+,?";
        for c in chars.chars() {
            assert!(glyph(c).iter().all(|r| r & !0x1F == 0), "{c}");
        }
        // Distinct glyphs for distinct characters (no copy-paste slip).
        let all: Vec<_> = chars.chars().map(glyph).collect();
        for i in 0..all.len() {
            for j in 0..i {
                assert_ne!(
                    all[i],
                    all[j],
                    "{} vs {}",
                    chars.chars().nth(i).unwrap(),
                    chars.chars().nth(j).unwrap()
                );
            }
        }
        assert_eq!(glyph('a'), glyph('A'));
    }

    #[test]
    fn glyphs_are_five_bits_wide_and_distinct() {
        let chars = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ.,:-+=_/()[]%?×°θφ";
        let glyphs: Vec<[u8; GLYPH_HEIGHT]> = chars.chars().map(glyph).collect();
        for (c, g) in chars.chars().zip(&glyphs) {
            assert!(g.iter().all(|&r| r < 32), "{c}");
            assert!(g.iter().any(|&r| r != 0), "{c} is blank");
        }
        for i in 0..glyphs.len() {
            for j in i + 1..glyphs.len() {
                assert_ne!(
                    glyphs[i],
                    glyphs[j],
                    "{} and {}",
                    chars.chars().nth(i).unwrap(),
                    chars.chars().nth(j).unwrap()
                );
            }
        }
        assert_eq!(glyph('a'), glyph('A'));
        assert_eq!(text_extent("180°", 2), (4 * ADVANCE - 1) * 2);
    }

    #[test]
    fn text_lands_on_the_canvas() {
        let mut c = Canvas::new(40, 10, [0; 3]);
        c.text(1, 1, "I", 1, [255; 3]);
        // The I's stem is column 2 of the glyph.
        assert_eq!(
            &c.rgb[3 * (3 * 40 + 3)..3 * (3 * 40 + 3) + 3],
            &[255, 255, 255]
        );
        c.text(30, 5, "WIDE TEXT CLIPS", 2, [255; 3]);
    }
}
