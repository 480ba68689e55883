//! Rays, shapes, shading frames and the pinhole camera.

use envlight::Vec3;

/// A half-line `origin + t·direction`, `t > 0`; `direction` has unit length.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Vec3,
    /// Unit direction.
    pub direction: Vec3,
}

impl Ray {
    /// The point at parameter `t`.
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.origin + self.direction * t
    }

    /// A ray leaving the surface point `p` (with geometric normal `n`) along `direction`,
    /// its origin pushed off the surface to the side `direction` points to, so it
    /// cannot hit the surface it starts on through rounding.
    #[inline]
    pub fn spawn(p: Vec3, n: Vec3, direction: Vec3) -> Self {
        let scale = p.x.abs().max(p.y.abs()).max(p.z.abs()).max(1.0);
        let offset = 2e-4 * scale;
        let side = if direction.dot(n) >= 0.0 {
            offset
        } else {
            -offset
        };
        Self {
            origin: p + n * side,
            direction,
        }
    }
}

/// An orthonormal basis `(s, t, n)`: shading computations use the local frame in which
/// `n` is +z, so `cos θ = w.z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Frame {
    /// First tangent.
    pub s: Vec3,
    /// Second tangent, `n × s`.
    pub t: Vec3,
    /// The normal.
    pub n: Vec3,
}

impl Frame {
    /// A frame around the unit vector `n` (Duff et al. 2017, branchless and continuous
    /// except across `n.z = 0`'s sign flip).
    #[inline]
    pub fn from_normal(n: Vec3) -> Self {
        let sign = 1f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Self { s, t, n }
    }

    /// World vector → local coordinates.
    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    /// Local coordinates → world vector.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

/// A geometric primitive.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Shape {
    /// A sphere.
    Sphere {
        /// Centre.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
    },
    /// A horizontal disc (normal +z), seen from both sides.
    Disc {
        /// Centre; the disc lies in the plane `z = center.z`.
        center: Vec3,
        /// Radius (> 0).
        radius: f32,
    },
    /// A rectangle `corner + a·u + b·v`, `a, b ∈ [0, 1]` (`u ⟂ v`), seen from both
    /// sides; its normal is `u × v` normalised (the walls of the `room` scene).
    Rect {
        /// One corner.
        corner: Vec3,
        /// First edge from the corner.
        u: Vec3,
        /// Second edge from the corner (perpendicular to `u`).
        v: Vec3,
    },
}

/// Where a ray meets a shape: parameter and outward geometric normal.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShapeHit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Unit outward normal (for a disc, +z).
    pub normal: Vec3,
}

impl Shape {
    /// The nearest hit with `t ∈ (0, t_max)`, if any.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<ShapeHit> {
        match *self {
            Shape::Sphere { center, radius } => {
                // Numerically robust form (Haines et al., Ray Tracing Gems ch. 7): the
                // discriminant from the ray's closest approach, the near root from
                // c/q to avoid cancellation.
                let oc = ray.origin - center;
                let b = oc.dot(ray.direction);
                let closest = oc - ray.direction * b;
                let disc = radius * radius - closest.dot(closest);
                if disc < 0.0 {
                    return None;
                }
                let c = oc.dot(oc) - radius * radius;
                let q = -b - disc.sqrt().copysign(b);
                let (mut t0, mut t1) = (c / q, q);
                if t0 > t1 {
                    std::mem::swap(&mut t0, &mut t1);
                }
                let t = if t0 > 0.0 { t0 } else { t1 };
                if !(t > 0.0 && t < t_max) {
                    return None;
                }
                let normal = (ray.at(t) - center) * (1.0 / radius);
                Some(ShapeHit { t, normal })
            }
            Shape::Disc { center, radius } => {
                if ray.direction.z == 0.0 {
                    return None;
                }
                let t = (center.z - ray.origin.z) / ray.direction.z;
                if !(t > 0.0 && t < t_max) {
                    return None;
                }
                let p = ray.at(t);
                let (dx, dy) = (p.x - center.x, p.y - center.y);
                (dx * dx + dy * dy <= radius * radius).then_some(ShapeHit {
                    t,
                    normal: Vec3::new(0.0, 0.0, 1.0),
                })
            }
            Shape::Rect { corner, u, v } => {
                let n = u.cross(v);
                let dn = ray.direction.dot(n);
                if dn == 0.0 {
                    return None;
                }
                let t = (corner - ray.origin).dot(n) / dn;
                if !(t > 0.0 && t < t_max) {
                    return None;
                }
                let q = ray.at(t) - corner;
                let (a, b) = (q.dot(u) / u.dot(u), q.dot(v) / v.dot(v));
                ((0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b)).then(|| ShapeHit {
                    t,
                    normal: n * (1.0 / n.length()),
                })
            }
        }
    }
}

/// A pinhole camera. Image `y` grows downwards; pixel `(x, y)` covers
/// `[x, x+1) × [y, y+1)` in continuous raster coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub position: Vec3,
    /// Point the camera looks at.
    pub look_at: Vec3,
    /// Vertical field of view, degrees.
    pub vfov_degrees: f32,
}

impl Camera {
    /// The primary ray through raster point `(x, y)` of a `width × height` image.
    pub fn ray(&self, x: f32, y: f32, width: usize, height: usize) -> Ray {
        let forward = (self.look_at - self.position)
            .normalized()
            .unwrap_or(Vec3::new(0.0, 1.0, 0.0));
        // z is up; a camera looking straight up or down falls back to +y as "up".
        let right = forward
            .cross(Vec3::new(0.0, 0.0, 1.0))
            .normalized()
            .unwrap_or(Vec3::new(1.0, 0.0, 0.0));
        let up = right.cross(forward);
        let tan_half = (0.5 * self.vfov_degrees).to_radians().tan();
        let aspect = width as f32 / height as f32;
        let sx = (2.0 * x / width as f32 - 1.0) * tan_half * aspect;
        let sy = (1.0 - 2.0 * y / height as f32) * tan_half;
        let direction = (forward + right * sx + up * sy)
            .normalized()
            .unwrap_or(forward);
        Ray {
            origin: self.position,
            direction,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_is_orthonormal() {
        for n in [
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(0.6, 0.0, 0.8),
            Vec3::new(-0.36, 0.48, -0.8),
        ] {
            let f = Frame::from_normal(n);
            for (a, b) in [(f.s, f.t), (f.s, f.n), (f.t, f.n)] {
                assert!(a.dot(b).abs() < 1e-6);
            }
            for v in [f.s, f.t, f.n] {
                assert!((v.length() - 1.0).abs() < 1e-6);
            }
            let w = Vec3::new(0.3, -0.2, 0.5);
            let back = f.to_world(f.to_local(w));
            assert!((back - w).length() < 1e-6);
        }
    }

    #[test]
    fn sphere_hits_from_outside_and_inside() {
        let s = Shape::Sphere {
            center: Vec3::new(0.0, 0.0, 0.0),
            radius: 1.0,
        };
        let ray = Ray {
            origin: Vec3::new(0.0, -5.0, 0.0),
            direction: Vec3::new(0.0, 1.0, 0.0),
        };
        let hit = s.intersect(&ray, f32::INFINITY).unwrap();
        assert!((hit.t - 4.0).abs() < 1e-5 && (hit.normal.y + 1.0).abs() < 1e-5);
        let inside = Ray {
            origin: Vec3::new(0.0, 0.0, 0.0),
            direction: Vec3::new(0.0, 1.0, 0.0),
        };
        assert!((s.intersect(&inside, f32::INFINITY).unwrap().t - 1.0).abs() < 1e-6);
        assert!(s.intersect(&ray, 3.0).is_none());
    }

    #[test]
    fn disc_respects_its_radius() {
        let d = Shape::Disc {
            center: Vec3::new(0.0, 0.0, 0.0),
            radius: 2.0,
        };
        let down = Vec3::new(0.0, 0.0, -1.0);
        let hit = |x: f32| {
            d.intersect(
                &Ray {
                    origin: Vec3::new(x, 0.0, 1.0),
                    direction: down,
                },
                f32::INFINITY,
            )
        };
        assert!(hit(1.9).is_some() && hit(2.1).is_none());
    }

    #[test]
    fn rect_respects_its_edges_from_both_sides() {
        // The square [1, 3] × [0, 2] in the plane x = 4 (a wall of the room).
        let r = Shape::Rect {
            corner: Vec3::new(4.0, 1.0, 0.0),
            u: Vec3::new(0.0, 2.0, 0.0),
            v: Vec3::new(0.0, 0.0, 2.0),
        };
        let hit = |origin: Vec3, y: f32| {
            let target = Vec3::new(4.0, y, 1.0);
            let direction = (target - origin).normalized().unwrap();
            r.intersect(&Ray { origin, direction }, f32::INFINITY)
        };
        for origin in [Vec3::new(0.0, 2.0, 1.0), Vec3::new(6.0, 2.0, 1.0)] {
            let h = hit(origin, 1.1).expect("inside");
            let distance = (Vec3::new(4.0, 1.1, 1.0) - origin).length();
            assert!((h.t - distance).abs() < 1e-5, "{} vs {distance}", h.t);
            assert!((h.normal.x.abs() - 1.0).abs() < 1e-6);
            assert!(hit(origin, 0.9).is_none() && hit(origin, 3.1).is_none());
        }
    }
}
