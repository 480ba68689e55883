//! The CSV rows of `sample` and `eval`: `x,y,z,pdf,r,g,b`.
//!
//! Numbers are the shortest decimal that reads back as the same `f32` (`ryu`), so a
//! direction written by `sample` and read by `eval` is bit-identical.

/// The header line both commands write (without the newline).
pub const HEADER: &str = "x,y,z,pdf,r,g,b";

/// How many bytes a row takes at most: 7 numbers of at most 16 bytes
/// (`-1.2345678e-38`), separators and the newline.
pub const MAX_ROW_BYTES: usize = 7 * 16 + 7;

/// Appends one row `x,y,z,pdf,r,g,b\n` to `out`.
#[inline]
pub fn push_row(
    out: &mut Vec<u8>,
    fmt: &mut ryu::Buffer,
    direction: [f32; 3],
    pdf: f32,
    rgb: [f32; 3],
) {
    let values = [
        direction[0],
        direction[1],
        direction[2],
        pdf,
        rgb[0],
        rgb[1],
        rgb[2],
    ];
    for (k, &value) in values.iter().enumerate() {
        if k > 0 {
            out.push(b',');
        }
        out.extend_from_slice(number(fmt, value).as_bytes());
    }
    out.push(b'\n');
}

/// Shortest round-trip text for `value`. Integers are written without a fractional
/// part (`0`, `1`), like most CSV writers; non-finite values (which the library
/// never produces) as `nan`/`inf`/`-inf`.
#[inline]
fn number(fmt: &mut ryu::Buffer, value: f32) -> &str {
    if value == 0.0 {
        // Also folds -0 into 0: a sign on zero means nothing to a reader.
        return "0";
    }
    let s = fmt.format(value);
    s.strip_suffix(".0").unwrap_or(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_round_trip_through_text() {
        let mut out = Vec::new();
        let mut fmt = ryu::Buffer::new();
        let d = [0.1f32, -0.9949874, 1.0e-7];
        push_row(&mut out, &mut fmt, d, 3.5, [0.0, -0.0, 32744.0]);
        let line = String::from_utf8(out).unwrap();
        assert_eq!(line, "0.1,-0.9949874,1e-7,3.5,0,0,32744\n");
        let back: Vec<f32> = line.trim().split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(&back[..3], &d);
        assert!(line.len() <= MAX_ROW_BYTES);
    }
}
