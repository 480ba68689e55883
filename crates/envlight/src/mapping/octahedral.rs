//! The plain octahedral map of the sphere onto `[0, 1]²`: a direction over its L1
//! norm, projected on the plane, the lower half folded over the diagonals. Not
//! equal in area (unlike [`super::equal_area`]), but a direction is placed with
//! one L1 norm, one division and a fold, no square root or arc tangent: the
//! product sampler finds a shading point's normal in its grids of tables with it
//! (`product::tables`).

use crate::math::Vec3;

/// An upper bound of the arc length on the sphere per unit length in `[0, 1]²` of
/// the octahedral map, 6. With `(a, b) = (2u - 1, 2v - 1)`, the map normalises
/// `p = (a, b, 1 - |a| - |b|)` in the upper half (and the folded
/// `((1 - |b|) sgn a, (1 - |a|) sgn b, 1 - |a| - |b|)` in the lower), whose
/// components move by `|da|`, `|db|` and at most `|da| + |db|`, so
/// `|dp| ≤ √3 |d(a, b)|`; `|p|₁ = 1` gives `|p| ≥ 1/√3`, and normalising moves a
/// direction by at most `|dp| / |p|`: `|dω| ≤ 3 |d(a, b)| = 6 |d(u, v)|`.
pub(crate) const OCTAHEDRAL_LIPSCHITZ: f64 = 6.0;

/// The grid point `[u, v] ∈ [0, 1]²` of the non-zero direction `d` in the
/// octahedral map: `d / |d|₁` projected on the plane, the lower half folded
/// over the diagonals. On a fold either equivalent point is returned.
#[inline]
pub(crate) fn sphere_to_octahedral(d: Vec3) -> [f32; 2] {
    let inv_l1 = 1.0 / (d.x.abs() + d.y.abs() + d.z.abs());
    let (a, b) = (d.x * inv_l1, d.y * inv_l1);
    let (a, b) = if d.z < 0.0 {
        ((1.0 - b.abs()).copysign(a), (1.0 - a.abs()).copysign(b))
    } else {
        (a, b)
    };
    [
        (0.5 * a + 0.5).clamp(0.0, 1.0),
        (0.5 * b + 0.5).clamp(0.0, 1.0),
    ]
}

/// The unit direction of grid point `[u, v] ∈ [0, 1]²` of the octahedral map (the
/// inverse of [`sphere_to_octahedral`]), in f64.
pub(crate) fn octahedral_to_sphere(u: f64, v: f64) -> [f64; 3] {
    let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
    let z = 1.0 - a.abs() - b.abs();
    let (x, y) = if z < 0.0 {
        ((1.0 - b.abs()).copysign(a), (1.0 - a.abs()).copysign(b))
    } else {
        (a, b)
    };
    let length = (x * x + y * y + z * z).sqrt();
    [x / length, y / length, z / length]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::{cross3, dot3, norm3};

    /// The map's forward and inverse agree: grid point → direction → grid point
    /// → direction comes back to the same direction (the grid point itself may
    /// be the other one on a fold), for directions of any length.
    #[test]
    fn round_trip() {
        for k in 0..100_000u64 {
            let [u, v] = crate::rng::xi_2d(23, k);
            let d = octahedral_to_sphere(u as f64, v as f64);
            let d = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
            let [s, t] = sphere_to_octahedral(d * 3.5);
            let back = octahedral_to_sphere(s as f64, t as f64);
            let d = [d.x as f64, d.y as f64, d.z as f64];
            let angle = norm3(cross3(back, d)).atan2(dot3(back, d));
            assert!(angle < 1e-5, "({u}, {v}) -> ({s}, {t})");
        }
    }
}
