//! The path tracer: unidirectional paths with next-event estimation towards the
//! environment light, BSDF-sampled continuation and Russian roulette, with the light
//! estimated by one of the [`Strategy`] techniques at every vertex.

use crate::geometry::{Frame, Ray};
use crate::rgb::{add, is_black, max_component, mul, scale, Rgb};
use crate::scene::Scene;
use crate::strategy::{CompensatedLight, Strategy};
use crate::warp::{square_to_cosine_hemisphere, square_to_uniform_sphere, UNIFORM_SPHERE_PDF};
use envlight::light::Density;
use envlight::portal::{Portal, PortalLight, PortalOptions, PortalPoint};
use envlight::rng::{mix64, SplitMix64};
use envlight::visibility::{VisibilityOptions, VisibilityPoint, VisibilitySummary};
use envlight::{
    EnvironmentLight, Factor, ProductOptions, ProductSampler, ShadingPoint, Vec3, VisibilityCache,
};
use rayon::prelude::*;
use std::sync::Arc;

/// Product samples per diffuse vertex under [`Strategy::MisProduct`] (see
/// [`Integrator::li_with`]). Measured (BENCHMARKS.md, "Rendering at equal time"):
/// two (as many shadow rays as MIS's light and BSDF samples) win more on the
/// `diffuse` scene with direct light only (0.66× `mis`'s RMSE at equal time against
/// 0.75–0.77×) but lose on `balls` (1.02–1.44× against 0.85–1.06×), where light
/// through the metals, which sampling at a diffuse vertex does not touch, carries
/// the error and the second sample only costs time.
const DIFFUSE_PRODUCT_SAMPLES: u32 = 1;

/// Metals narrower than this (GGX α) take product samples under
/// [`Strategy::MisProduct`] when the light's density is piecewise-bilinear (the
/// default); rougher ones, and every metal under a piecewise-constant density,
/// the compensated light (see [`Integrator::li_with`]). Measured on `balls`
/// (BENCHMARKS.md, "Product samples at the near-mirror"): with the bilinear
/// density the near-mirror (α 0.02) gains at equal time in every seed and the
/// copper (α 0.25) measured the same either way; with the constant density the
/// near-mirror gains per sample but lost at equal time in two seeds of three.
pub const PRODUCT_METAL_BELOW_ROUGHNESS: f32 = 0.1;

/// Cells along each side of the portal light's rectified tables: small enough that
/// a portal's table (`12 n²` bytes) stays in cache along the paths, which sampling
/// at a vertex is bound by (the room's sky through its openings is smooth).
pub const PORTAL_RESOLUTION: usize = 128;

/// Bounces after which Russian roulette starts.
pub const ROULETTE_DEPTH: u32 = 3;

/// Seed of the bounces whose hits join the camera's in `mis-visibility`'s cache.
const BOUNCE_SEED: u64 = 0xb0_0ce5;

/// Estimates the radiance arriving along camera rays.
///
/// `Send + Sync`. [`Integrator::li_with`] allocates nothing; it keeps what changes
/// from vertex to vertex (the product sampler's [`ShadingPoint`]) in a [`Scratch`],
/// one per thread.
#[derive(Debug, Clone)]
pub struct Integrator<'a> {
    scene: &'a Scene,
    light: &'a EnvironmentLight,
    strategy: Strategy,
    max_depth: u32,
    compensated: Option<CompensatedLight>,
    product: Option<Arc<ProductSampler>>,
    /// The visibility cache of `mis-visibility`, once [`Self::learn_visibility`]
    /// has built it.
    visibility: Option<VisibilityCache>,
    /// The portal light over the scene's openings, for the portal strategies in a
    /// scene that has portals.
    portal: Option<PortalLight>,
    /// Metals narrower than this take product samples under `mis-product`
    /// ([`PRODUCT_METAL_BELOW_ROUGHNESS`], or 0 under a piecewise-constant density).
    product_metals_below: f32,
}

/// The working state of one thread's paths for [`Integrator::li_with`]: for the
/// product strategies, the one [`ShadingPoint`] that every vertex of every path
/// moves to its own factor ([`ShadingPoint::set_factor`] reuses its buffer). Made
/// by [`Integrator::scratch`]; holds nothing for the other strategies.
#[derive(Debug, Clone)]
pub struct Scratch<'s> {
    point: Option<ShadingPoint<'s>>,
}

/// The balance heuristic weight of a technique with density `a` against one with
/// density `b`.
#[inline]
pub fn balance_heuristic(a: f32, b: f32) -> f32 {
    if a + b > 0.0 {
        a / (a + b)
    } else {
        0.0
    }
}

/// The power heuristic (β = 2) weight of a technique with density `a` against one
/// with density `b`.
#[inline]
pub fn power_heuristic(a: f32, b: f32) -> f32 {
    let (a2, b2) = (a * a, b * b);
    if a2 + b2 > 0.0 {
        a2 / (a2 + b2)
    } else {
        0.0
    }
}

impl<'a> Integrator<'a> {
    /// An integrator for `scene` under `light`. `max_depth` is the largest number of
    /// surface interactions on a path (1 = direct lighting only; 0 renders only what
    /// camera rays see directly: the environment, black objects). Builds the
    /// compensated distribution (`mis-compensated`, and `mis-product` and `mis-visibility` for metals),
    /// the product sampler (over a copy of `light`,
    /// `O(w h)`), or the portal light over the scene's portals (a copy of `light`
    /// and `12 n²` bytes of tables per portal side seen, see [`envlight::portal`]), when
    /// `strategy` needs it: once per render. A scene's portals that are not valid
    /// quads are a bug in the scene: they panic here.
    pub fn new(
        scene: &'a Scene,
        light: &'a EnvironmentLight,
        strategy: Strategy,
        max_depth: u32,
    ) -> Self {
        Self::with_product_options(scene, light, strategy, max_depth, ProductOptions::default())
    }

    /// [`Self::new`] with the product sampler built with `product`.
    pub fn with_product_options(
        scene: &'a Scene,
        light: &'a EnvironmentLight,
        strategy: Strategy,
        max_depth: u32,
        product: ProductOptions,
    ) -> Self {
        let options = product;
        // `mis-product` samples metals from the compensated light too.
        let compensated = (strategy == Strategy::MisCompensated || strategy.mixes_product())
            .then(|| CompensatedLight::new(light));
        let product = strategy
            .uses_product()
            .then(|| Arc::new(ProductSampler::new(Arc::new(light.clone()), options)));
        let portal = (strategy.uses_portals() && !scene.portals.is_empty()).then(|| {
            let quads: Vec<Portal> = scene
                .portals
                .iter()
                .map(|&c| Portal::new(c).expect("the scene's portals are valid quads"))
                .collect();
            let options = PortalOptions {
                resolution: Some(PORTAL_RESOLUTION),
            };
            PortalLight::new(Arc::new(light.clone()), &quads, options)
                .expect("the scene has at most 8 portals")
        });
        let product_metals_below = match light.options().density {
            Density::PiecewiseBilinear => PRODUCT_METAL_BELOW_ROUGHNESS,
            Density::PiecewiseConstant => 0.0,
        };
        Self {
            scene,
            light,
            strategy,
            max_depth,
            compensated,
            product,
            visibility: None,
            portal,
            product_metals_below,
        }
    }

    /// The strategy in use.
    pub fn strategy(&self) -> Strategy {
        self.strategy
    }

    /// The visibility cache [`Self::learn_visibility`] built (`mis-visibility`),
    /// for saving it; `None` before, and for other strategies.
    pub fn visibility_cache(&self) -> Option<&VisibilityCache> {
        self.visibility.as_ref()
    }

    /// For `mis-visibility`: builds the visibility cache from the first hits of
    /// the camera's rays through the centres of every other pixel (across and
    /// down) of a `width × height` image
    /// and the hits of one cosine-distributed bounce from each,
    /// each ray's transmittance being the scene's own shadow-ray test, and
    /// returns what it holds. `None` (and nothing built) for other strategies.
    ///
    /// # Panics
    /// When `options` do not pass [`VisibilityOptions::validate`] (the scene's
    /// hits are finite and its tracer answers 0 or 1, so nothing else can fail).
    pub fn learn_visibility(
        &mut self,
        width: usize,
        height: usize,
        options: &VisibilityOptions,
    ) -> Option<VisibilitySummary> {
        let product = self
            .product
            .as_ref()
            .filter(|_| self.strategy.uses_visibility())?;
        let scene = self.scene;
        // Every other pixel across and down: entries hold hundreds of points
        // each even so, and the build's share of the render is what counts.
        let (across, down) = (width.div_ceil(2), height.div_ceil(2));
        let hits: Vec<(Vec3, Vec3)> = (0..across * down)
            .into_par_iter()
            .filter_map(|i| {
                let (x, y) = (
                    (2 * (i % across)) as f32 + 0.5,
                    (2 * (i / across)) as f32 + 0.5,
                );
                let ray = scene.camera.ray(x, y, width, height);
                let hit = scene.intersect(&ray, f32::INFINITY)?;
                // Oriented as the path tracer shades it: towards the viewer.
                let normal = if hit.normal.dot(ray.direction) > 0.0 {
                    -hit.normal
                } else {
                    hit.normal
                };
                Some((hit.point, normal))
            })
            .collect();
        // And where those points' light comes from: one cosine-distributed bounce
        // from each, so the surfaces the camera does not see but paths reach
        // (the walls behind it) have entries too.
        let bounces: Vec<(Vec3, Vec3)> = hits
            .par_iter()
            .enumerate()
            .filter_map(|(i, &(p, n))| {
                let mut rng = SplitMix64::new(mix64(BOUNCE_SEED ^ i as u64));
                let local = square_to_cosine_hemisphere([rng.next_f32(), rng.next_f32()]);
                let d = Frame::from_normal(n).to_world(local);
                let hit = scene.intersect(&Ray::spawn(p, n, d), f32::INFINITY)?;
                let normal = if hit.normal.dot(d) > 0.0 {
                    -hit.normal
                } else {
                    hit.normal
                };
                Some((hit.point, normal))
            })
            .collect();
        let (points, normals): (Vec<Vec3>, Vec<Vec3>) = hits.into_iter().chain(bounces).unzip();
        let trace = |origins: &[Vec3], directions: &[Vec3], out: &mut [f32]| {
            out.par_iter_mut()
                .zip(origins.par_iter().zip(directions.par_iter()))
                .for_each(|(t, (&o, &d))| {
                    // Pushed off along the ray: the cache traces only directions
                    // above the point's surface.
                    let blocked = scene.occluded(&Ray::spawn(o, d, d));
                    *t = if blocked { 0.0 } else { 1.0 };
                });
            Ok::<(), std::convert::Infallible>(())
        };
        let cache = match VisibilityCache::build(product.clone(), &points, &normals, options, trace)
        {
            Ok(cache) => cache,
            Err(e) => panic!("mis-visibility: {e}"),
        };
        let summary = cache.summary();
        self.visibility = Some(cache);
        Some(summary)
    }

    /// Working state for [`Self::li_with`], one per thread: for the product
    /// strategies one [`ShadingPoint`] (an allocation of one double per node of the
    /// sampler's cut, made here and never again).
    pub fn scratch(&self) -> Scratch<'_> {
        Scratch {
            // An invalid (zero) factor: no bounds are computed until a vertex sets one.
            point: self
                .product
                .as_ref()
                .map(|p| p.at(&Factor::cosine(Vec3::default()))),
        }
    }

    /// Density of the light-sampling technique at world direction `d` (0 for
    /// strategies without one); `point` is the current vertex's shading point for
    /// the product strategies (`None` where `mis-product` samples the compensated
    /// light instead, at metals).
    #[inline]
    fn light_technique_pdf(
        &self,
        d: Vec3,
        point: Option<&ShadingPoint>,
        portal: Option<&PortalPoint>,
        seen: Option<&VisibilityPoint>,
    ) -> f32 {
        if let Some(v) = seen {
            return v.pdf(d);
        }
        match (&self.compensated, self.strategy) {
            (Some(c), Strategy::MisProduct | Strategy::MisVisibility) => match point {
                Some(p) => p.pdf(d),
                None => c.pdf(d),
            },
            (Some(c), _) => c.pdf(d),
            (None, Strategy::Mis | Strategy::Light) => self.light.pdf(d),
            (None, Strategy::Portal | Strategy::MisPortal) => match portal {
                Some(p) => p.pdf(d),
                None => self.light.pdf(d),
            },
            (None, Strategy::Uniform) => UNIFORM_SPHERE_PDF,
            (None, Strategy::Product | Strategy::MisProduct | Strategy::MisVisibility) => {
                match point {
                    Some(p) => p.pdf(d),
                    None => self.light.pdf(d),
                }
            }
            (None, _) => 0.0,
        }
    }

    /// One light-sampled direction: `(direction, pdf, radiance)`; `point` as in
    /// [`Self::light_technique_pdf`].
    #[inline]
    fn sample_light_technique(
        &self,
        xi: [f32; 2],
        point: Option<&ShadingPoint>,
        portal: Option<&PortalPoint>,
        seen: Option<&VisibilityPoint>,
    ) -> Option<(Vec3, f32, Rgb)> {
        if let Some(v) = seen {
            return v.sample(xi).map(|s| (s.direction, s.pdf, s.radiance));
        }
        match self.strategy {
            Strategy::Bsdf => None,
            Strategy::Uniform => {
                let d = square_to_uniform_sphere(xi);
                Some((d, UNIFORM_SPHERE_PDF, self.light.radiance(d)))
            }
            Strategy::Light | Strategy::Mis => self
                .light
                .sample(xi)
                .map(|s| (s.direction, s.pdf, s.radiance)),
            Strategy::MisCompensated => self
                .compensated
                .as_ref()
                .and_then(|c| c.sample(xi))
                .map(|s| (s.direction, s.pdf, s.radiance)),
            Strategy::Product | Strategy::MisProduct | Strategy::MisVisibility => {
                match (point, &self.compensated) {
                    (Some(p), _) => p.sample(xi),
                    (None, Some(c)) => c.sample(xi),
                    (None, None) => self.light.sample(xi),
                }
                .map(|s| (s.direction, s.pdf, s.radiance))
            }
            Strategy::Portal | Strategy::MisPortal => match portal {
                Some(p) => p.sample(xi),
                None => self.light.sample(xi),
            }
            .map(|s| (s.direction, s.pdf, s.radiance)),
        }
    }

    /// One sample of the radiance arriving at the camera along `ray` (linear RGB).
    ///
    /// Consumes random numbers from `rng` only; the result is a pure function of
    /// the ray and the generator's state. Makes a fresh [`Scratch`] (an allocation
    /// for the product strategies): loops should call [`Self::li_with`].
    pub fn li(&self, ray: &Ray, rng: &mut SplitMix64) -> Rgb {
        self.li_with(ray, rng, &mut self.scratch())
    }

    /// [`Self::li`] with this thread's working state, `scratch`, which must come
    /// from [`Self::scratch`] of this integrator (another's would sample another
    /// light). Allocates nothing. The result does not depend on what `scratch` was
    /// used for before: every vertex sets its own factor.
    pub fn li_with(&self, ray: &Ray, rng: &mut SplitMix64, scratch: &mut Scratch) -> Rgb {
        debug_assert_eq!(
            scratch.point.is_some(),
            self.product.is_some(),
            "a scratch from another integrator"
        );
        let mis = self.strategy.is_mis();
        let heuristic = if self.strategy == Strategy::MisPortal {
            balance_heuristic
        } else {
            power_heuristic
        };
        let Some(mut hit) = self.scene.intersect(ray, f32::INFINITY) else {
            return self.light.radiance(ray.direction);
        };
        let mut ray = *ray;
        let mut radiance = [0.0f32; 3];
        let mut throughput = [1.0f32; 3];
        let mut depth = 1u32;
        while depth <= self.max_depth {
            let bsdf = self.scene.objects[hit.object].material.bsdf_at(hit.point);
            // Both-sided shading: the normal faces the viewer.
            let normal = if hit.normal.dot(ray.direction) > 0.0 {
                -hit.normal
            } else {
                hit.normal
            };
            let frame = Frame::from_normal(normal);
            let wo = frame.to_local(-ray.direction);
            if wo.z <= 0.0 {
                break;
            }
            // The product sampler's target at this vertex; the escaped BSDF ray below
            // is weighted with the pdf of this same shading point.
            // `mis-product` takes product samples at a near-mirror metal (α below
            // `product_metals_below`) and samples other metals from the
            // MIS-compensated light, both with BSDF sampling (power heuristic). At
            // the near-mirror the sun's highlight is most of a render's error; the
            // product (light × lobe, the light's own bilinear density within each
            // patch, which matches the bilinear radiance exactly) cut `balls`' RMSE
            // to 0.56–0.68× `mis` at equal time against 0.63–1.00× with the
            // compensated light. At the rough copper the two measured the same,
            // and the compensated light costs a light sample
            // (PRODUCT_METAL_BELOW_ROUGHNESS).
            let on_the_fly = self.product.as_ref().is_some_and(|p| p.is_on_the_fly());
            let light_here = self.strategy.mixes_product()
                && !on_the_fly
                && bsdf
                    .conductor_roughness()
                    .is_some_and(|a| a >= self.product_metals_below);
            let factor = bsdf.product_factor(normal, -ray.direction);
            // `mis-visibility`: the cache's mixture where `mis-product` would take
            // product samples, but at near-mirror metals (whose lobe, not the
            // sky's visibility, decides where light comes from). It mixes with
            // this thread's product shading point.
            let uses_cache =
                self.visibility.is_some() && !light_here && bsdf.conductor_roughness().is_none();
            let product_here = !light_here && !uses_cache;
            if let (Some(point), true) = (scratch.point.as_mut(), !light_here) {
                point.set_factor(&factor);
            }
            let seen_point = match (&self.visibility, scratch.point.as_ref()) {
                (Some(cache), Some(point)) if uses_cache => {
                    Some(cache.at_point(hit.point, &factor, point))
                }
                _ => None,
            };
            let seen = seen_point.as_ref();
            let point = scratch.point.as_ref().filter(|_| product_here);
            // The portals as seen from this vertex (their windows and powers; on the
            // stack, no allocation).
            let portal_point = self.portal.as_ref().map(|pl| pl.at(hit.point));
            let portal = portal_point.as_ref();

            // At a diffuse vertex, `mis-product`'s light technique samples the
            // whole integrand but visibility (the product of the light and the
            // BSDF's cosine), which BSDF sampling cannot improve on: next-event
            // estimation there takes `DIFFUSE_PRODUCT_SAMPLES` product samples and
            // a BSDF-sampled ray that escapes counts 0 (so at the last vertex none
            // is traced); other vertices combine the two techniques.
            let product_only = self.strategy.mixes_product() && bsdf.is_diffuse();
            let (vertex_mis, light_samples) = if product_only {
                (false, DIFFUSE_PRODUCT_SAMPLES)
            } else {
                (mis, 1)
            };

            // Next-event estimation: a direction from the light technique, weighted
            // against the BSDF technique when combining. The estimate is the true
            // `f cos θi L / p`, whatever target the light technique sampled.
            for _ in 0..light_samples {
                let xi_light = [rng.next_f32(), rng.next_f32()];
                let Some((wi_world, light_pdf, le)) =
                    self.sample_light_technique(xi_light, point, portal, seen)
                else {
                    continue;
                };
                let wi = frame.to_local(wi_world);
                if wi.z > 0.0 && !is_black(le) {
                    let f = bsdf.eval(wo, wi);
                    if !is_black(f)
                        && !self
                            .scene
                            .occluded(&Ray::spawn(hit.point, normal, wi_world))
                    {
                        let weight = if vertex_mis {
                            heuristic(light_pdf, bsdf.pdf(wo, wi))
                        } else {
                            1.0
                        };
                        let c = scale(
                            mul(f, le),
                            wi.z * weight / (light_pdf * light_samples as f32),
                        );
                        radiance = add(radiance, mul(throughput, c));
                    }
                }
            }

            // Continue the path by sampling the BSDF. At the last vertex this ray
            // only matters when it may escape to the light with a non-zero weight.
            let counts_escape = self.strategy.counts_escaped_bsdf_rays() && !product_only;
            if depth == self.max_depth && !counts_escape {
                break;
            }
            let uc = rng.next_f32();
            let u = [rng.next_f32(), rng.next_f32()];
            let Some(bs) = bsdf.sample(wo, uc, u) else {
                break;
            };
            throughput = mul(throughput, scale(bs.f, bs.wi.z / bs.pdf));
            if is_black(throughput) {
                break;
            }
            if depth >= ROULETTE_DEPTH {
                let survive = max_component(throughput).min(0.95);
                if rng.next_f32() >= survive {
                    break;
                }
                throughput = scale(throughput, 1.0 / survive);
            }
            let wi_world = frame.to_world(bs.wi);
            ray = Ray::spawn(hit.point, normal, wi_world);
            match self.scene.intersect(&ray, f32::INFINITY) {
                None => {
                    if counts_escape {
                        let weight = if vertex_mis {
                            heuristic(
                                bs.pdf,
                                self.light_technique_pdf(wi_world, point, portal, seen),
                            )
                        } else {
                            1.0
                        };
                        let le = self.light.radiance(wi_world);
                        radiance = add(radiance, scale(mul(throughput, le), weight));
                    }
                    break;
                }
                Some(next) => {
                    hit = next;
                    depth += 1;
                }
            }
        }
        radiance
    }
}
