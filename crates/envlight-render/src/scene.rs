//! Scenes: a camera and a few objects, each a shape with a material. The built-in
//! scenes need no files.

use crate::bsdf::Bsdf;
use crate::geometry::{Camera, Ray, Shape};
use crate::rgb::Rgb;
use envlight::Vec3;

/// What a surface is made of; turned into a [`Bsdf`] at each hit point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Material {
    /// A fixed BSDF everywhere on the surface.
    Uniform(Bsdf),
    /// A Lambertian checkerboard in x and y (for ground planes), squares of side
    /// `size`.
    Checker {
        /// Albedo of the even squares.
        even: Rgb,
        /// Albedo of the odd squares.
        odd: Rgb,
        /// Side of one square.
        size: f32,
    },
}

impl Material {
    /// The BSDF at world point `p`.
    #[inline]
    pub fn bsdf_at(&self, p: Vec3) -> Bsdf {
        match *self {
            Material::Uniform(bsdf) => bsdf,
            Material::Checker { even, odd, size } => {
                let parity = ((p.x / size).floor() as i64 + (p.y / size).floor() as i64) & 1;
                Bsdf::Diffuse {
                    albedo: if parity == 0 { even } else { odd },
                }
            }
        }
    }
}

/// A shape with a material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Object {
    /// A short name for reports (`"diffuse"`, `"ground"`).
    pub name: &'static str,
    /// Geometry.
    pub shape: Shape,
    /// Surface.
    pub material: Material,
}

/// The nearest surface a ray meets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Ray parameter.
    pub t: f32,
    /// World position.
    pub point: Vec3,
    /// Unit outward geometric normal (also the shading normal).
    pub normal: Vec3,
    /// Index of the object in [`Scene::objects`].
    pub object: usize,
}

/// A camera and a list of objects lit by an environment light only.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// The scene's name.
    pub name: String,
    /// The viewpoint.
    pub camera: Camera,
    /// Everything that can be hit (intersection is brute force: scenes are tiny).
    pub objects: Vec<Object>,
    /// The openings the environment is seen through, as quads (four corners in
    /// order), for the portal strategies; empty for an open scene.
    pub portals: Vec<[Vec3; 4]>,
}

/// Names accepted by [`Scene::builtin`].
pub const SCENE_NAMES: [&str; 5] = ["balls", "diffuse", "furnace", "pergola", "room"];

/// Albedo of the spheres in the `diffuse` scene.
pub const DIFFUSE_SPHERE_ALBEDO: f32 = 0.8;

/// Albedo of the ground in the `diffuse` scene.
pub const DIFFUSE_GROUND_ALBEDO: f32 = 0.5;

/// Albedo of the sphere in the `furnace` scene.
pub const FURNACE_ALBEDO: f32 = 0.5;

impl Scene {
    /// A built-in scene by name (see [`SCENE_NAMES`]), or `None`.
    ///
    /// - `balls`: four unit spheres in a row on a large checkered diffuse disc,
    ///   seen from slightly above: diffuse (ρ = 0.7), rough copper (GGX α = 0.25),
    ///   near-mirror silver (α = 0.02), and a blue plastic (ρ = (0.1, 0.25, 0.6)
    ///   under a GGX coating with η = 1.5, α = 0.08).
    /// - `diffuse`: only Lambertian surfaces, the target of product sampling with
    ///   the clamped cosine: three white spheres (ρ = [`DIFFUSE_SPHERE_ALBEDO`]) of
    ///   radii 1, 0.6 and 1.3 on a large grey disc (ρ = [`DIFFUSE_GROUND_ALBEDO`]),
    ///   the camera of `balls`.
    /// - `furnace`: one unit diffuse sphere of albedo [`FURNACE_ALBEDO`], nothing
    ///   else. Under a constant map of radiance 1 every sphere pixel is 0.5 and every
    ///   background pixel 1.
    /// - `room`: a closed room `[0, 4] × [0, 3] × [0, 2.5]` lit only through two
    ///   openings, which are its [`Scene::portals`]: a window in the wall x = 4
    ///   (y ∈ [0.9, 2.1], z ∈ [0.8, 1.9], facing +x, away from the `sunrise` map's
    ///   low sun: the room is lit by the sky alone, the case where sampling the
    ///   whole map wastes its samples on the sun behind the walls) and a skylight
    ///   in the ceiling (x ∈ [1.6, 2.8], y ∈ [1, 2]) at the foot of a shaft 0.5
    ///   high with black walls, whose top (z = 3) is the portal (the shaft keeps the
    ///   low sun out).
    ///   Diffuse walls (ρ = 0.7), a checkered floor, a white diffuse sphere, a rough copper
    ///   sphere and a blue plastic sphere; the camera stands in a corner.
    /// - `pergola`: a lattice roof over a 5 × 5 patch of ground, open on three
    ///   sides with a wall on the fourth: two crossed layers of thin slats (0.12
    ///   wide, 0.3 apart) at heights 2.4 and 2.45, so the sky and the sun reach the
    ///   ground under it through some 280 small square gaps — light that no set of
    ///   portals can describe. A white diffuse sphere and a blue plastic one stand
    ///   under it on a large grey ground; the camera looks in from outside.
    pub fn builtin(name: &str) -> Option<Scene> {
        match name {
            "balls" => Some(Self::balls()),
            "diffuse" => Some(Self::diffuse()),
            "furnace" => Some(Self::furnace()),
            "pergola" => Some(Self::pergola()),
            "room" => Some(Self::room()),
            _ => None,
        }
    }

    /// The window of the `room` scene (a portal), corners in order.
    pub const ROOM_WINDOW: [Vec3; 4] = [
        Vec3::new(4.0, 0.9, 0.8),
        Vec3::new(4.0, 2.1, 0.8),
        Vec3::new(4.0, 2.1, 1.9),
        Vec3::new(4.0, 0.9, 1.9),
    ];

    /// The skylight of the `room` scene (a portal), corners in order.
    pub const ROOM_SKYLIGHT: [Vec3; 4] = [
        Vec3::new(1.6, 1.0, 3.0),
        Vec3::new(2.8, 1.0, 3.0),
        Vec3::new(2.8, 2.0, 3.0),
        Vec3::new(1.6, 2.0, 3.0),
    ];

    fn room() -> Scene {
        const SIZE: [f32; 3] = [4.0, 3.0, 2.5];
        // Walls overlap at the room's edges (no cracks for rays to leak through) and
        // reach 1e-4 into the openings, so every escaping ray passes through a
        // portal (an opening larger than its portal would leak unsampled light).
        const SEAL: f32 = 1e-3;
        const LIP: f32 = 1e-4;
        let wall = Material::Uniform(Bsdf::Diffuse {
            albedo: [0.7, 0.7, 0.7],
        });
        // An axis-aligned rectangle in the plane `axis = value`, spanning `a` and `b`
        // along the two other axes (in x, y, z order).
        let rect = |name: &'static str, axis: usize, value: f32, a: [f32; 2], b: [f32; 2]| {
            let (i, j) = match axis {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            let mut corner = [0.0f32; 3];
            corner[axis] = value;
            corner[i] = a[0];
            corner[j] = b[0];
            let mut u = [0.0f32; 3];
            u[i] = a[1] - a[0];
            let mut v = [0.0f32; 3];
            v[j] = b[1] - b[0];
            Object {
                name,
                shape: Shape::Rect {
                    corner: Vec3::from(corner),
                    u: Vec3::from(u),
                    v: Vec3::from(v),
                },
                material: wall,
            }
        };
        let full = |axis: usize| {
            let (i, j) = match axis {
                0 => (1, 2),
                1 => (0, 2),
                _ => (0, 1),
            };
            ([-SEAL, SIZE[i] + SEAL], [-SEAL, SIZE[j] + SEAL])
        };
        // A wall with a rectangular opening `ha × hb`: four pieces around it.
        let holed = |name: &'static str, axis: usize, value: f32, ha: [f32; 2], hb: [f32; 2]| {
            let (a, b) = full(axis);
            vec![
                rect(name, axis, value, a, [b[0], hb[0] + LIP]),
                rect(name, axis, value, a, [hb[1] - LIP, b[1]]),
                rect(name, axis, value, [a[0], ha[0] + LIP], hb),
                rect(name, axis, value, [ha[1] - LIP, a[1]], hb),
            ]
        };
        let mut objects = Vec::new();
        let w = Self::ROOM_WINDOW;
        objects.extend(holed(
            "window wall",
            0,
            SIZE[0],
            [w[0].y, w[2].y],
            [w[0].z, w[2].z],
        ));
        let k = Self::ROOM_SKYLIGHT;
        objects.extend(holed(
            "ceiling",
            2,
            SIZE[2],
            [k[0].x, k[2].x],
            [k[0].y, k[2].y],
        ));
        // The skylight's shaft, from the ceiling's hole up to the portal at its top:
        // rays leave through the portal only, and the low sun cannot get in.
        let shaft = [SIZE[2] - SEAL, k[0].z];
        // Its walls are black: the low sun reaches a strip of them, which would
        // otherwise light the room by a bright, tiny indirect source.
        let (ys, xs) = (
            [k[0].y - SEAL, k[2].y + SEAL],
            [k[0].x - SEAL, k[2].x + SEAL],
        );
        let black = Material::Uniform(Bsdf::Diffuse { albedo: [0.0; 3] });
        for (axis, value, span) in [
            (0, k[0].x, ys),
            (0, k[2].x, ys),
            (1, k[0].y, xs),
            (1, k[2].y, xs),
        ] {
            let mut side = rect("shaft", axis, value, span, shaft);
            side.material = black;
            objects.push(side);
        }
        let (a, b) = full(0);
        objects.push(rect("back wall", 0, 0.0, a, b));
        let (a, b) = full(1);
        objects.push(rect("wall", 1, 0.0, a, b));
        objects.push(rect("wall", 1, SIZE[1], a, b));
        let (a, b) = full(2);
        let mut floor = rect("floor", 2, 0.0, a, b);
        floor.material = Material::Checker {
            even: [0.6, 0.55, 0.5],
            odd: [0.3, 0.27, 0.25],
            size: 0.5,
        };
        objects.push(floor);
        let sphere = |name: &'static str, c: [f32; 3], radius: f32, bsdf: Bsdf| Object {
            name,
            shape: Shape::Sphere {
                center: Vec3::from(c),
                radius,
            },
            material: Material::Uniform(bsdf),
        };
        objects.push(sphere(
            "diffuse",
            [1.6, 1.9, 0.5],
            0.5,
            Bsdf::Diffuse {
                albedo: [0.8, 0.8, 0.8],
            },
        ));
        objects.push(sphere(
            "copper",
            [2.7, 1.0, 0.35],
            0.35,
            Bsdf::Conductor {
                alpha: 0.25,
                eta: [0.200, 0.924, 1.102],
                k: [3.912, 2.452, 2.142],
            },
        ));
        objects.push(sphere(
            "plastic",
            [1.0, 0.9, 0.3],
            0.3,
            Bsdf::Plastic {
                albedo: [0.1, 0.25, 0.6],
                alpha: 0.08,
                eta: 1.5,
            },
        ));
        Scene {
            name: "room".into(),
            camera: Camera {
                position: Vec3::new(0.25, 0.3, 1.5),
                look_at: Vec3::new(3.0, 1.8, 1.0),
                vfov_degrees: 70.0,
            },
            objects,
            portals: vec![Self::ROOM_WINDOW, Self::ROOM_SKYLIGHT],
        }
    }

    /// The camera of the scenes on the ground plane (`balls`, `diffuse`).
    fn ground_camera() -> Camera {
        Camera {
            position: Vec3::new(0.0, -9.5, 2.6),
            look_at: Vec3::new(0.0, 0.0, 0.8),
            vfov_degrees: 32.0,
        }
    }

    fn balls() -> Scene {
        let sphere = |name: &'static str, x: f32, bsdf: Bsdf| Object {
            name,
            shape: Shape::Sphere {
                center: Vec3::new(x, 0.0, 1.0),
                radius: 1.0,
            },
            material: Material::Uniform(bsdf),
        };
        let objects = vec![
            sphere(
                "diffuse",
                -3.3,
                Bsdf::Diffuse {
                    albedo: [0.7, 0.7, 0.7],
                },
            ),
            sphere(
                "copper",
                -1.1,
                Bsdf::Conductor {
                    alpha: 0.25,
                    eta: [0.200, 0.924, 1.102],
                    k: [3.912, 2.452, 2.142],
                },
            ),
            sphere(
                "mirror",
                1.1,
                Bsdf::Conductor {
                    alpha: 0.02,
                    eta: [0.155, 0.117, 0.138],
                    k: [4.828, 3.122, 2.147],
                },
            ),
            sphere(
                "plastic",
                3.3,
                Bsdf::Plastic {
                    albedo: [0.1, 0.25, 0.6],
                    alpha: 0.08,
                    eta: 1.5,
                },
            ),
            Object {
                name: "ground",
                shape: Shape::Disc {
                    center: Vec3::new(0.0, 0.0, 0.0),
                    radius: 30.0,
                },
                material: Material::Checker {
                    even: [0.55, 0.55, 0.55],
                    odd: [0.35, 0.35, 0.35],
                    size: 1.0,
                },
            },
        ];
        Scene {
            name: "balls".into(),
            camera: Self::ground_camera(),
            objects,
            portals: Vec::new(),
        }
    }

    fn diffuse() -> Scene {
        let white = Material::Uniform(Bsdf::Diffuse {
            albedo: [DIFFUSE_SPHERE_ALBEDO; 3],
        });
        let sphere = |name: &'static str, x: f32, y: f32, radius: f32| Object {
            name,
            shape: Shape::Sphere {
                center: Vec3::new(x, y, radius),
                radius,
            },
            material: white,
        };
        let objects = vec![
            sphere("left", -2.6, 0.4, 1.0),
            sphere("small", -0.2, -1.4, 0.6),
            sphere("right", 2.3, 0.9, 1.3),
            Object {
                name: "ground",
                shape: Shape::Disc {
                    center: Vec3::new(0.0, 0.0, 0.0),
                    radius: 30.0,
                },
                material: Material::Uniform(Bsdf::Diffuse {
                    albedo: [DIFFUSE_GROUND_ALBEDO; 3],
                }),
            },
        ];
        Scene {
            name: "diffuse".into(),
            camera: Self::ground_camera(),
            objects,
            portals: Vec::new(),
        }
    }

    fn pergola() -> Scene {
        const HALF: f32 = 2.5;
        const SLAT: f32 = 0.12;
        const PITCH: f32 = 0.3;
        let wood = Material::Uniform(Bsdf::Diffuse {
            albedo: [0.45, 0.35, 0.25],
        });
        let rect =
            |name: &'static str, corner: [f32; 3], u: [f32; 3], v: [f32; 3], material| Object {
                name,
                shape: Shape::Rect {
                    corner: Vec3::from(corner),
                    u: Vec3::from(u),
                    v: Vec3::from(v),
                },
                material,
            };
        let mut objects = Vec::new();
        let slats = (2.0 * HALF / PITCH) as usize;
        for k in 0..=slats {
            let at = -HALF + k as f32 * PITCH - SLAT / 2.0;
            // Lower layer along y, upper layer along x: a lattice of square gaps.
            let along_y = [at, -HALF, 2.4];
            objects.push(rect(
                "roof",
                along_y,
                [SLAT, 0.0, 0.0],
                [0.0, 2.0 * HALF, 0.0],
                wood,
            ));
            let along_x = [-HALF, at, 2.45];
            objects.push(rect(
                "roof",
                along_x,
                [2.0 * HALF, 0.0, 0.0],
                [0.0, SLAT, 0.0],
                wood,
            ));
        }
        objects.push(rect(
            "wall",
            [-HALF, HALF, 0.0],
            [2.0 * HALF, 0.0, 0.0],
            [0.0, 0.0, 2.45],
            Material::Uniform(Bsdf::Diffuse {
                albedo: [0.7, 0.7, 0.7],
            }),
        ));
        objects.push(Object {
            name: "diffuse",
            shape: Shape::Sphere {
                center: Vec3::new(0.4, 0.6, 0.6),
                radius: 0.6,
            },
            material: Material::Uniform(Bsdf::Diffuse {
                albedo: [0.8, 0.8, 0.8],
            }),
        });
        objects.push(Object {
            name: "plastic",
            shape: Shape::Sphere {
                center: Vec3::new(-1.1, -0.4, 0.4),
                radius: 0.4,
            },
            material: Material::Uniform(Bsdf::Plastic {
                albedo: [0.1, 0.25, 0.6],
                alpha: 0.08,
                eta: 1.5,
            }),
        });
        objects.push(Object {
            name: "ground",
            shape: Shape::Disc {
                center: Vec3::new(0.0, 0.0, 0.0),
                radius: 30.0,
            },
            material: Material::Uniform(Bsdf::Diffuse {
                albedo: [0.5, 0.5, 0.5],
            }),
        });
        Scene {
            name: "pergola".into(),
            camera: Camera {
                position: Vec3::new(1.2, -4.6, 1.2),
                look_at: Vec3::new(-0.2, 0.6, 0.6),
                vfov_degrees: 60.0,
            },
            objects,
            portals: Vec::new(),
        }
    }

    fn furnace() -> Scene {
        Scene {
            name: "furnace".into(),
            camera: Camera {
                position: Vec3::new(0.0, -4.0, 0.0),
                look_at: Vec3::new(0.0, 0.0, 0.0),
                vfov_degrees: 40.0,
            },
            objects: vec![Object {
                name: "sphere",
                shape: Shape::Sphere {
                    center: Vec3::new(0.0, 0.0, 0.0),
                    radius: 1.0,
                },
                material: Material::Uniform(Bsdf::Diffuse {
                    albedo: [FURNACE_ALBEDO; 3],
                }),
            }],
            portals: Vec::new(),
        }
    }

    /// The nearest hit along `ray` with `t ∈ (0, t_max)`.
    #[inline]
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best: Option<Hit> = None;
        let mut t_max = t_max;
        for (index, object) in self.objects.iter().enumerate() {
            if let Some(h) = object.shape.intersect(ray, t_max) {
                t_max = h.t;
                best = Some(Hit {
                    t: h.t,
                    point: ray.at(h.t),
                    normal: h.normal,
                    object: index,
                });
            }
        }
        best
    }

    /// Whether anything blocks `ray` (a shadow ray towards the light at infinity).
    #[inline]
    pub fn occluded(&self, ray: &Ray) -> bool {
        self.objects
            .iter()
            .any(|o| o.shape.intersect(ray, f32::INFINITY).is_some())
    }
}
