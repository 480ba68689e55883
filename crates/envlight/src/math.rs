//! Small geometric types: a 3-vector and a rotation.

use std::ops::{Add, Mul, Neg, Sub};

/// A 3-vector of `f32` (a direction or a point). The frame is right-handed, z up.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Vec3 {
    /// x component.
    pub x: f32,
    /// y component.
    pub y: f32,
    /// z component (up).
    pub z: f32,
}

impl Vec3 {
    /// Builds a vector from its components.
    #[inline]
    pub const fn new(x: f32, y: f32, z: f32) -> Self {
        Self { x, y, z }
    }
    /// Dot product.
    #[inline]
    pub fn dot(self, o: Self) -> f32 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Cross product.
    #[inline]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Euclidean length.
    #[inline]
    pub fn length(self) -> f32 {
        self.dot(self).sqrt()
    }
    /// The vector scaled to unit length. A zero or non-finite vector gives `None`.
    #[inline]
    pub fn normalized(self) -> Option<Self> {
        let len = self.length();
        if len > 0.0 && len.is_finite() {
            Some(self * (1.0 / len))
        } else {
            None
        }
    }
    /// Components as an array `[x, y, z]`.
    #[inline]
    pub fn to_array(self) -> [f32; 3] {
        [self.x, self.y, self.z]
    }
}

impl From<[f32; 3]> for Vec3 {
    #[inline]
    fn from(a: [f32; 3]) -> Self {
        Self::new(a[0], a[1], a[2])
    }
}

impl Add for Vec3 {
    type Output = Self;
    #[inline]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}

impl Sub for Vec3 {
    type Output = Self;
    #[inline]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}

impl Mul<f32> for Vec3 {
    type Output = Self;
    #[inline]
    fn mul(self, s: f32) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
}

impl Neg for Vec3 {
    type Output = Self;
    #[inline]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

/// A rotation, stored as an orthonormal 3×3 matrix (rows). Applying it is a
/// matrix-vector product; its inverse is the transpose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rotation {
    m: [[f32; 3]; 3],
}

impl Default for Rotation {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Rotation {
    /// No rotation.
    pub const IDENTITY: Self = Self {
        m: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    };

    /// A rotation by `degrees` about +z, counter-clockwise seen from above
    /// (+x turns towards +y).
    pub fn about_z_degrees(degrees: f32) -> Self {
        let (s, c) = (degrees as f64).to_radians().sin_cos();
        let (s, c) = (s as f32, c as f32);
        Self {
            m: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        }
    }

    /// A rotation from its matrix rows. Returns `None` unless the matrix is
    /// orthonormal with determinant +1 (to 1e-4).
    pub fn from_rows(m: [[f32; 3]; 3]) -> Option<Self> {
        let r = Self { m };
        let rows = [Vec3::from(m[0]), Vec3::from(m[1]), Vec3::from(m[2])];
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                let error = (rows[i].dot(rows[j]) - want).abs();
                // Written so that a NaN entry is rejected too.
                if error.is_nan() || error >= 1e-4 {
                    return None;
                }
            }
        }
        let det = rows[0].dot(rows[1].cross(rows[2]));
        ((det - 1.0).abs() < 1e-4).then_some(r)
    }

    /// The composition `self ∘ other` (apply `other` first).
    pub fn then_after(self, other: Self) -> Self {
        let mut m = [[0.0f32; 3]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = (0..3).map(|k| self.m[i][k] * other.m[k][j]).sum();
            }
        }
        Self { m }
    }

    /// The inverse rotation (the transpose).
    pub fn inverse(self) -> Self {
        let m = self.m;
        Self {
            m: [
                [m[0][0], m[1][0], m[2][0]],
                [m[0][1], m[1][1], m[2][1]],
                [m[0][2], m[1][2], m[2][2]],
            ],
        }
    }

    /// Applies the rotation to a vector.
    #[inline]
    pub fn apply(&self, v: Vec3) -> Vec3 {
        let m = &self.m;
        Vec3::new(
            m[0][0] * v.x + m[0][1] * v.y + m[0][2] * v.z,
            m[1][0] * v.x + m[1][1] * v.y + m[1][2] * v.z,
            m[2][0] * v.x + m[2][1] * v.y + m[2][2] * v.z,
        )
    }

    /// True when this is exactly the identity (lets hot paths skip the product).
    #[inline]
    pub fn is_identity(&self) -> bool {
        *self == Self::IDENTITY
    }
}
