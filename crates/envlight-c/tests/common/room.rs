//! The room the visibility tests of this crate trace, in Rust and in C
//! (`tests/c/visibility.c` computes it with the same operations in the same order,
//! so their rows agree bit for bit): the box `[-1, 1]² × [0, 2]`, open only
//! through a window in its `+x` wall (`|y| < 0.4`, `0.6 < z < 1.4`).

/// 1 when the ray from `o` (inside the box) along `d` leaves through the window,
/// else 0.
pub fn room_transmittance(o: [f32; 3], d: [f32; 3]) -> f32 {
    let exit = |o: f32, d: f32, lo: f32, hi: f32| {
        if d > 0.0 {
            (hi - o) / d
        } else if d < 0.0 {
            (lo - o) / d
        } else {
            f32::INFINITY
        }
    };
    let t = [
        exit(o[0], d[0], -1.0, 1.0),
        exit(o[1], d[1], -1.0, 1.0),
        exit(o[2], d[2], 0.0, 2.0),
    ];
    let (y, z) = (o[1] + d[1] * t[0], o[2] + d[2] * t[0]);
    let window = d[0] > 0.0 && t[0] <= t[1] && t[0] <= t[2];
    (window && y.abs() < 0.4 && z > 0.6 && z < 1.4) as u8 as f32
}
