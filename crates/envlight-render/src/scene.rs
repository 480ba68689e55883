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
}

/// Names accepted by [`Scene::builtin`].
pub const SCENE_NAMES: [&str; 3] = ["balls", "diffuse", "furnace"];

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
    pub fn builtin(name: &str) -> Option<Scene> {
        match name {
            "balls" => Some(Self::balls()),
            "diffuse" => Some(Self::diffuse()),
            "furnace" => Some(Self::furnace()),
            _ => None,
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
