//! Unit tests of the product sampler: its parts (regions, neighbourhoods, tiling)
//! and its promises (pdf of a sample, normalisation, support, radiance, batches).

use super::bounds::EQUAL_AREA_LIPSCHITZ;
use super::*;
use crate::color::luminance;
use crate::distribution::CDF_ONE;
use crate::image::{EnvImage, Lookup};
use crate::light::{Density, LightOptions, Sampler};
use crate::mapping::octahedral::{octahedral_to_sphere, OCTAHEDRAL_LIPSCHITZ};
use crate::math::Rotation;
use crate::math::{cross3, dot3, norm3};
use crate::rng::{xi_2d, SplitMix64};
use std::f64::consts::PI;

/// A named product sampler over one of the small test lights.
struct Case {
    name: &'static str,
    sampler: ProductSampler,
}

/// Random texels in `[0, 4)`, with about a quarter of them black.
fn random_image(w: usize, h: usize, seed: u64) -> EnvImage {
    let mut rng = SplitMix64::new(seed);
    EnvImage::from_fn(w, h, |_, _| {
        if rng.next_f32() < 0.25 {
            [0.0; 3]
        } else {
            [
                rng.next_f32() * 4.0,
                rng.next_f32() * 4.0,
                rng.next_f32() * 4.0,
            ]
        }
    })
    .unwrap()
}

/// A black image but for texels `(x, y, value)`.
fn hot_texels(w: usize, h: usize, hot: &[(usize, usize, f32)]) -> EnvImage {
    EnvImage::from_fn(w, h, |x, y| {
        hot.iter()
            .find(|t| t.0 == x && t.1 == y)
            .map_or([0.0; 3], |t| [t.2; 3])
    })
    .unwrap()
}

/// A rotation that moves the light's +z off the world's z axis: 30° about x,
/// then 37° about z.
fn tilted() -> Rotation {
    let (s, c) = 30f32.to_radians().sin_cos();
    let about_x = Rotation::from_rows([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]]).unwrap();
    Rotation::about_z_degrees(37.0).then_after(about_x)
}

fn case(
    name: &'static str,
    image: EnvImage,
    options: LightOptions,
    patches: Option<[usize; 2]>,
) -> Case {
    let light = EnvironmentLight::new(image, options).unwrap();
    Case {
        name,
        sampler: ProductSampler::new(
            Arc::new(light),
            ProductOptions {
                patches,
                ..Default::default()
            },
        ),
    }
}

/// Every mapping, both lookups, rotations, odd sizes, patch grids that do not
/// divide the image or exceed it, a single hot texel (also on a pole row), a
/// 1×1 map, and an extreme dynamic range.
fn cases() -> Vec<Case> {
    let nearest = LightOptions {
        lookup: Lookup::Nearest,
        ..Default::default()
    };
    let equal_area = LightOptions {
        mapping: Mapping::EqualArea,
        equal_area_size: Some(8),
        ..Default::default()
    };
    vec![
        case(
            "8x4 random",
            random_image(8, 4, 1),
            LightOptions::default(),
            None,
        ),
        case(
            "16x8 nearest, 5x3 patches",
            random_image(16, 8, 2),
            nearest,
            Some([5, 3]),
        ),
        case(
            "16x8 hot texel, 4x2 patches",
            hot_texels(16, 8, &[(5, 2, 50.0)]),
            LightOptions::default(),
            Some([4, 2]),
        ),
        case(
            "16x8 hot pole texel, nearest",
            hot_texels(16, 8, &[(3, 0, 9.0)]),
            nearest,
            None,
        ),
        case(
            "16x8 extreme range, nearest",
            hot_texels(16, 8, &[(2, 3, 1e30), (11, 6, 1e-30)]),
            nearest,
            Some([4, 4]),
        ),
        case(
            "1x1",
            EnvImage::new(1, 1, vec![[1.0, 2.0, 3.0]]).unwrap(),
            LightOptions::default(),
            None,
        ),
        case(
            "2x1 halves",
            random_image(2, 1, 3),
            LightOptions::default(),
            None,
        ),
        case(
            "13x7 tilted, hierarchical, 4x3 patches",
            random_image(13, 7, 4),
            LightOptions {
                rotation: tilted(),
                sampler: Sampler::Hierarchical,
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
            Some([4, 3]),
        ),
        case(
            "16x8 about z 37°, bilinear density, 100x100 patches",
            random_image(16, 8, 5),
            LightOptions {
                rotation: Rotation::about_z_degrees(37.0),
                density: Density::PiecewiseBilinear,
                ..Default::default()
            },
            Some([100, 100]),
        ),
        case(
            "equal-area 8 from 16x8, 3x3 patches",
            random_image(16, 8, 6),
            equal_area,
            Some([3, 3]),
        ),
        case(
            "equal-area 6x6 input, hot texel, tilted",
            hot_texels(6, 6, &[(1, 4, 20.0)]),
            LightOptions {
                mapping: Mapping::EqualArea,
                input_mapping: Mapping::EqualArea,
                rotation: tilted(),
                ..Default::default()
            },
            None,
        ),
        case(
            "sky 64x32",
            crate::builtin::sky(64, 32),
            LightOptions::default(),
            None,
        ),
        case(
            "sky 64x32, one patch",
            crate::builtin::sky(64, 32),
            LightOptions::default(),
            Some([1, 1]),
        ),
    ]
}

/// Cosine and glossy factors about several normals, with outgoing directions
/// above and below the surface.
fn factors() -> Vec<Factor> {
    let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let mut out = vec![
        Factor::cosine(v(0.0, 0.0, 1.0)),
        Factor::cosine(v(0.0, 0.0, -1.0)),
        Factor::cosine(v(1.0, 0.2, -0.3)),
        Factor::cosine(v(0.3, -1.0, 0.001)),
        Factor::glossy(v(0.0, 0.0, 1.0), v(1.0, 0.0, 1.0), 0.05),
        Factor::glossy(v(-0.2, 0.5, 0.8), v(0.1, 0.9, 0.3), 0.3),
        Factor::glossy(v(0.6, 0.0, -0.8), v(0.0, 1.0, 0.0), 1.0),
        Factor::glossy(v(0.0, 0.0, 1.0), v(0.5, 0.5, -0.1), 0.15),
    ];
    for k in 0..4 {
        let n = crate::math::uniform_sphere(xi_2d(17, k));
        let wo = crate::math::uniform_sphere(xi_2d(18, k));
        out.push(Factor::cosine(n));
        out.push(Factor::glossy(n, wo, 0.1 + 0.2 * k as f32));
    }
    out
}

/// `u`-by-`v` image points spanning patch `k` edge to edge, plus random ones.
fn patch_points(sampler: &ProductSampler, k: usize, grid: usize) -> Vec<[f32; 2]> {
    let [u0, u1, v0, v1] = sampler.fine.patch_rect(k);
    let u = |t: f64| (u0 + t * (u1 - u0)) as f32;
    let v = |t: f64| (v0 + t * (v1 - v0)) as f32;
    let mut points = Vec::new();
    for a in 0..=grid {
        for b in 0..=grid {
            points.push([u(a as f64 / grid as f64), v(b as f64 / grid as f64)]);
        }
    }
    for s in 0..64 {
        let [a, b] = xi_2d(k as u64, s);
        points.push([u(a as f64), v(b as f64)]);
    }
    points
}

fn angle(a: [f64; 3], d: Vec3) -> f64 {
    let d = [d.x as f64, d.y as f64, d.z as f64];
    norm3(cross3(a, d)).atan2(dot3(a, d))
}

#[test]
fn cones_contain_their_patches() {
    for case in cases() {
        let sampler = &case.sampler;
        let mut widest = 0.0f64;
        for (k, region) in sampler.fine.regions.iter().enumerate() {
            let Some(patch) = region else { continue };
            let half = patch.cone.sin_half.atan2(patch.cone.cos_half);
            widest = widest.max(half);
            // Only the lit cells are bounded (nothing is sampled in the others).
            for uv in patch_points(sampler, k, 40) {
                let (d, _) = sampler.light.uv_to_local(uv);
                if sampler.fine.locate(uv).is_none_or(|(_, q)| q <= 0.0) {
                    continue;
                }
                let a = angle(patch.cone.axis, d);
                assert!(
                    a <= half,
                    "{}: patch {k} at {uv:?}: {a} > {half}",
                    case.name
                );
            }
        }
        // The cones are tight enough to matter where patches are small.
        if case.name.starts_with("sky 64x32") && sampler.patches() == [32, 16] {
            assert!(widest < 0.2, "{}: {widest}", case.name);
        }
    }
}

/// Every direction of a grid cell lies within the neighbourhood cone of each of
/// the cell's four corner nodes, and the cones are not much wider than the cells.
#[test]
fn neighbourhoods_hold_their_cells() {
    for n in [1usize, 2, 5, 16] {
        let mut widest = 0.0f64;
        for node in 0..(n + 1) * (n + 1) {
            let (a, b) = (node % (n + 1), node / (n + 1));
            let (axis, spread) = tables::neighbourhood(n, a, b);
            let Some((sin, cos)) = spread else {
                assert!(n < 4, "grid {n}: node {node} bounds the whole sphere");
                continue;
            };
            let half = sin.atan2(cos);
            widest = widest.max(half);
            let cell = 1.0 / n as f64;
            for k in 0..4_000u64 {
                let [s, t] = xi_2d(node as u64, k);
                // A point in the 2 × 2 cells about the node (clipped to the square).
                let u = ((a as f64 - 1.0 + 2.0 * s as f64) * cell).clamp(0.0, 1.0);
                let v = ((b as f64 - 1.0 + 2.0 * t as f64) * cell).clamp(0.0, 1.0);
                let d = octahedral_to_sphere(u, v);
                let d = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
                let angle = angle(axis.v, d);
                assert!(
                    angle <= half,
                    "grid {n} node {node} at ({u}, {v}): {angle} > {half}"
                );
            }
        }
        // The cells are equal in area, not in shape: those along the octahedron's
        // edges are the longest.
        if n == 16 {
            assert!(widest < 0.55, "grid 16: widest neighbourhood {widest}");
        }
    }
}

/// Each table a shading point mixes gives weight to every patch holding a lit
/// point its factor sees: the support of the mixture, patch by patch.
#[test]
fn mixed_tables_weight_every_patch_the_factor_sees() {
    for case in cases() {
        let sampler = &case.sampler;
        // Lit points, by the patch they fall in (points on a patch's edge may
        // belong to its neighbour).
        let mut lit = vec![Vec::new(); sampler.fine.power.len()];
        for k in 0..lit.len() {
            for uv in patch_points(sampler, k, 6) {
                if let Some((at, q)) = sampler.fine.locate(uv) {
                    if q > 0.0 {
                        lit[at].push(uv);
                    }
                }
            }
        }
        for factor in factors() {
            let point = sampler.at(&factor);
            let tables = sampler.tables(point.set);
            for (k, points) in lit.iter().enumerate() {
                let seen = points
                    .iter()
                    .any(|&uv| factor.value(sampler.light.uv_to_direction(uv)) > 0.0);
                if !seen {
                    continue;
                }
                // A bright patch is weighted at the point itself, not in the tables.
                if let Some(b) = sampler.bright.index(k) {
                    assert!(
                        point.bright.as_ref()[b] > 0.0,
                        "{}: {factor:?}: bright patch {k} has no weight",
                        case.name
                    );
                    continue;
                }
                assert!(point.tables_share > 0.0, "{}: {factor:?}", case.name);
                for (&node, &p) in point.mix.node.iter().zip(&point.mix.probability) {
                    if p > 0.0 {
                        assert!(
                            tables.width(node, k) > 0,
                            "{}: {factor:?}: node {node} gives lit patch {k} no weight",
                            case.name
                        );
                    }
                }
            }
        }
    }
}

/// With the piecewise-bilinear density, the product pdf follows the light's own
/// within each patch: their ratio is the same at every point of a patch.
#[test]
fn bilinear_density_is_followed_within_patches() {
    let c = case(
        "bilinear",
        random_image(32, 16, 11),
        LightOptions {
            density: Density::PiecewiseBilinear,
            ..Default::default()
        },
        Some([4, 4]),
    );
    let sampler = &c.sampler;
    assert_eq!(sampler.density(), Density::PiecewiseBilinear);
    let light = sampler.light();
    let normal = Vec3::new(0.2, -0.3, 0.9);
    let point = sampler.at(&Factor::cosine(normal));
    let normal = normal.normalized().unwrap();
    let mut checked = 0;
    for k in 0..sampler.fine.power.len() {
        let mut ratio: Option<f64> = None;
        for uv in patch_points(sampler, k, 9) {
            // Keep away from the patch's edges, where rounding may pick the
            // neighbour.
            let [u0, u1, v0, v1] = sampler.fine.patch_rect(k);
            let inner = |x: f32, a: f64, b: f64| {
                let t = (x as f64 - a) / (b - a);
                (0.01..0.99).contains(&t)
            };
            if !(inner(uv[0], u0, u1) && inner(uv[1], v0, v1)) {
                continue;
            }
            let d = light.uv_to_direction(uv);
            // Within the horizon's band the pdf holds the mirror image's too.
            if normal.dot(d).abs() < point.horizon_band() {
                continue;
            }
            let (p, q) = (point.pdf(d) as f64, light.pdf(d) as f64);
            if p <= 0.0 || q <= 1e-6 {
                continue;
            }
            match ratio {
                None => ratio = Some(p / q),
                Some(r) => {
                    assert!(
                        (p / q - r).abs() <= 2e-3 * r,
                        "patch {k} at {uv:?}: ratio {} vs {r}",
                        p / q
                    );
                    checked += 1;
                }
            }
        }
    }
    assert!(checked > 500, "{checked}");
}

#[test]
fn pdf_of_sample_matches_sample_pdf() {
    for case in cases() {
        check_pdf_of_samples(&case);
    }
}

fn check_pdf_of_samples(case: &Case) {
    {
        for (index, factor) in factors().iter().enumerate() {
            let point = case.sampler.at(factor);
            let mut drawn = 0;
            for k in 0..2_000 {
                let Some(s) = point.sample(xi_2d(index as u64, k)) else {
                    continue;
                };
                drawn += 1;
                assert!(is_positive_finite(s.pdf), "{}: {s:?}", case.name);
                assert!((s.direction.length() - 1.0).abs() < 1e-5);
                // Within 1e-3 rad of a lat-long pole, the f32 round trip of a
                // (rotated) direction leaves sin θ, and so the pdf, uncertain
                // beyond 1e-4 (the harness exempts 1e-4 rad).
                let lat_long = case.sampler.light.mapping() == Mapping::Equirectangular;
                if lat_long && (std::f64::consts::PI * s.uv[1] as f64).sin() < 1e-3 {
                    continue;
                }
                let p = point.pdf(s.direction);
                assert!(
                    (p - s.pdf).abs() <= 1e-4 * s.pdf,
                    "{}: {factor:?}: pdf {p} vs sample {s:?}",
                    case.name
                );
            }
            assert_eq!(drawn > 0, point.samples_anything(), "{}", case.name);
        }
    }
}

/// `∫ p dω` by the midpoint rule on a lat-long grid of the world sphere, with
/// 8 × 8 points in each cell where the pdf jumps: where it differs by more than 25%
/// between the cell's corners (a texel's or a patch's edge, or their mirror images
/// across the horizon) or the cell crosses an edge of the horizon's band. Only a
/// smoke test: an edge that slips between the corners goes unseen.
#[test]
fn pdf_integrates_to_one() {
    for case in cases() {
        check_integral(&case);
    }
}

fn check_integral(case: &Case) {
    let (nu, nv) = (1024usize, 512usize);
    let direction = |i: f64, j: f64| {
        let (u, v) = (i / nu as f64, j / nv as f64);
        crate::mapping::equirect_to_direction(u as f32, v as f32).0
    };
    for factor in factors().iter().step_by(3) {
        let point = case.sampler.at(factor);
        let normal = factor
            .normal()
            .normalized()
            .unwrap_or(Vec3::new(0.0, 0.0, 1.0));
        // The pdf at a grid point, and the side of the band's three edges it is on.
        let at = |i: f64, j: f64| {
            let d = direction(i, j);
            let c = normal.dot(d);
            let band = point.horizon_band();
            let side = (c < -band) as u8 + (c < 0.0) as u8 + (c < band) as u8;
            (point.pdf(d) as f64, side)
        };
        let corners: Vec<(f64, u8)> = (0..=nv)
            .flat_map(|j| (0..=nu).map(move |i| (i, j)))
            .map(|(i, j)| at(i as f64, j as f64))
            .collect();
        let mut integral = 0.0f64;
        for j in 0..nv {
            for i in 0..nu {
                let c = [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)]
                    .map(|(a, b)| corners[b * (nu + 1) + a]);
                let lo = c.iter().map(|x| x.0).fold(f64::INFINITY, f64::min);
                let hi = c.iter().map(|x| x.0).fold(0.0, f64::max);
                let even = c.iter().all(|x| x.1 == c[0].1) && hi <= 1.25 * lo;
                let m = if even { 1 } else { 8 };
                for b in 0..m {
                    let y = j as f64 + (b as f64 + 0.5) / m as f64;
                    let area =
                        2.0 * PI * PI * (PI * y / nv as f64).sin() / (nu * nv * m * m) as f64;
                    for a in 0..m {
                        let x = i as f64 + (a as f64 + 0.5) / m as f64;
                        integral += point.pdf(direction(x, y)) as f64 * area;
                    }
                }
            }
        }
        let want = if point.samples_anything() { 1.0 } else { 0.0 };
        assert!(
            (integral - want).abs() < 2e-3,
            "{}: {factor:?}: {integral}",
            case.name
        );
    }
}

#[test]
fn pdf_is_positive_where_light_times_factor_is() {
    for case in cases() {
        let sampler = &case.sampler;
        let light = sampler.light();
        let [w, h] = [light.image().width(), light.image().height()];
        for factor in factors() {
            let point = sampler.at(&factor);
            for j in 0..h {
                for i in 0..w {
                    for (a, b) in [(0.5, 0.5), (0.1, 0.2), (0.9, 0.15), (0.3, 0.95)] {
                        let uv = [(i as f32 + a) / w as f32, (j as f32 + b) / h as f32];
                        let d = light.uv_to_direction(uv);
                        let target = luminance(light.radiance(d)) * factor.value(d);
                        assert!(
                            target <= 0.0 || point.pdf(d) > 0.0,
                            "{}: {factor:?} at texel ({i}, {j}) {uv:?}: L f = {target}, pdf 0",
                            case.name
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn sample_radiance_is_the_lights() {
    for case in cases() {
        let light = case.sampler.light();
        // The direction's round trip to the image moves the point by float
        // rounding, which changes a bilinear lookup by that much of its slope.
        let brightest = light.brightest().0;
        for (index, factor) in factors().iter().enumerate().step_by(2) {
            let point = case.sampler.at(factor);
            for k in 0..500 {
                let Some(s) = point.sample(xi_2d(100 + index as u64, k)) else {
                    continue;
                };
                // Within 3e-3 rad of a lat-long pole the direction's f32 round
                // trip moves the image point by up to 1e-5 (the azimuth of a
                // direction 0.0016 rad from the pole is known to about 1e-4 rad):
                // a bilinear lookup there changed by 1.2e-4 relative.
                let lat_long = light.mapping() == Mapping::Equirectangular;
                if lat_long && (PI * s.uv[1] as f64).sin() < 3e-3 {
                    continue;
                }
                let want = light.radiance(s.direction);
                for (got, want) in s.radiance.iter().zip(want) {
                    assert!(
                        (got - want).abs() <= 1e-4 * want + 1e-5 * brightest,
                        "{}: {s:?} vs {want}",
                        case.name
                    );
                }
                let [u, v] = light.direction_to_uv(s.direction);
                let du = (u - s.uv[0]).abs();
                assert!(
                    du.min(1.0 - du) < 1e-5 && (v - s.uv[1]).abs() < 1e-5,
                    "{}: {s:?} at {u}, {v}",
                    case.name
                );
            }
        }
    }
}

#[test]
fn nothing_to_sample_gives_none_and_pdf_zero() {
    let check_empty = |sampler: &ProductSampler, factor: &Factor, what: &str| {
        let point = sampler.at(factor);
        assert!(!point.samples_anything(), "{what}");
        for k in 0..200 {
            assert!(point.sample(xi_2d(3, k)).is_none(), "{what}");
            let d = crate::math::uniform_sphere(xi_2d(4, k));
            assert_eq!(point.pdf(d), 0.0, "{what}");
            assert_eq!(sampler.pdf(factor, d), 0.0, "{what}");
        }
    };
    let up = Factor::cosine(Vec3::new(0.0, 0.0, 1.0));
    let down = Factor::cosine(Vec3::new(0.0, 0.0, -1.0));
    let black = case(
        "black",
        EnvImage::from_fn(4, 2, |_, _| [0.0; 3]).unwrap(),
        LightOptions::default(),
        None,
    );
    assert!(black.sampler.is_black());
    check_empty(&black.sampler, &up, "black map");
    // Only the top row of eight (θ < 22.5°) is lit; the filter (and the
    // resampling to the equal-area square) spread it down to about θ < 45°, and
    // the patches holding any of it lie well above a surface facing down.
    let sky_only =
        EnvImage::from_fn(16, 8, |_, y| if y < 1 { [1.0; 3] } else { [0.0; 3] }).unwrap();
    for mapping in Mapping::ALL {
        let options = LightOptions {
            mapping,
            equal_area_size: Some(32),
            ..Default::default()
        };
        let c = case("sky only", sky_only.clone(), options, None);
        let glossy = Factor::glossy(down.normal(), Vec3::new(0.3, 0.0, -1.0), 0.2);
        if mapping == Mapping::Equirectangular {
            check_empty(&c.sampler, &down, "light above, surface facing down");
            check_empty(&c.sampler, &glossy, "glossy");
        } else {
            // On the equal-area square, bounded by cones alone, a patch holding a
            // faint resampling tail may reach below the horizon: a sliver of
            // weight, whose samples carry a factor of 0 (wasted, not wrong).
            for factor in [down, glossy] {
                let point = c.sampler.at(&factor);
                for k in 0..200 {
                    if let Some(s) = point.sample(xi_2d(3, k)) {
                        assert_eq!(factor.value(s.direction), 0.0, "{s:?}");
                    }
                }
            }
        }
        assert!(c.sampler.at(&up).samples_anything());
        // Invalid factors.
        let z = Vec3::new(0.0, 0.0, 1.0);
        for bad in [
            Factor::cosine(Vec3::default()),
            Factor::cosine(Vec3::new(f32::NAN, 0.0, 1.0)),
            Factor::cosine(Vec3::new(f32::INFINITY, 0.0, 1.0)),
            Factor::glossy(z, Vec3::default(), 0.5),
            Factor::glossy(z, z, 0.0),
            Factor::glossy(z, z, 1.5),
            Factor::glossy(z, z, f32::NAN),
        ] {
            assert!(bad.normalized().is_none() && bad.value(z) == 0.0, "{bad:?}");
            check_empty(&c.sampler, &bad, "invalid factor");
        }
    }
}

#[test]
fn batches_equal_single_queries() {
    let c = case(
        "sky",
        crate::builtin::sky(64, 32),
        LightOptions::default(),
        None,
    );
    let sampler = &c.sampler;
    let all = factors();
    // Runs of equal factors (which reuse a point's setup) and changes.
    let batch: Vec<Factor> = (0..3_000)
        .map(|k| all[(k / 7 + k % 3) % all.len()])
        .collect();
    let xi: Vec<[f32; 2]> = (0..batch.len() as u64).map(|k| xi_2d(9, k)).collect();
    let mut samples = vec![None; batch.len()];
    sampler.sample_batch(&batch, &xi, &mut samples);
    let dirs: Vec<Vec3> = (0..batch.len() as u64)
        .map(|k| crate::math::uniform_sphere(xi_2d(10, k)))
        .collect();
    let mut pdfs = vec![0.0; batch.len()];
    sampler.pdf_batch(&batch, &dirs, &mut pdfs);
    for k in 0..batch.len() {
        assert_eq!(samples[k], sampler.sample(&batch[k], xi[k]));
        assert_eq!(pdfs[k].to_bits(), sampler.pdf(&batch[k], dirs[k]).to_bits());
    }
}

#[test]
fn patches_tile_the_image_and_the_arrays() {
    for (w, h, asked, want) in [
        (13, 7, Some([4, 3]), [4, 3]),
        (8, 4, Some([100, 100]), [8, 4]),
        (8, 4, Some([0, 0]), [1, 1]),
        (1, 1, None, [1, 1]),
        (64, 32, None, [64, 32]),
        (256, 128, None, [64, 32]),
        (50, 9, Some([7, 9]), [7, 9]),
    ] {
        let c = case(
            "tiling",
            random_image(w, h, 7),
            // Texel cells: the widths of a patch's cells sum to CDF_ONE.
            LightOptions {
                density: Density::PiecewiseConstant,
                ..Default::default()
            },
            asked,
        );
        let sampler = &c.sampler;
        let s = &sampler.fine;
        assert_eq!(sampler.patches(), want);
        let [pw, ph] = want;
        // Every texel belongs to the patch whose block holds it.
        for i in 0..w {
            let p = s.col_patch[i] as usize;
            assert!(s.col_start[p] as usize <= i && i < s.col_start[p + 1] as usize);
        }
        for j in 0..h {
            let p = s.row_patch[j] as usize;
            assert!(s.row_start[p] as usize <= j && j < s.row_start[p + 1] as usize);
        }
        // The patches' cells tile the per-cell arrays in patch order, each patch
        // holding exactly its block of cells; a lit patch's widths sum to
        // CDF_ONE and its alias table gives each cell exactly its width.
        let mut used = 0;
        for k in 0..pw * ph {
            let slots = s.slots(k);
            let at = slots.as_ptr() as usize - s.slots.as_ptr() as usize;
            assert_eq!(at, std::mem::size_of_val(&slots[0]) * used);
            let ([x0, x1], [y0, y1]) = s.patch_cells(k);
            assert_eq!(slots.len(), (x1 - x0) * (y1 - y0));
            used += slots.len();
            let widths: Vec<u32> = (y0..y1)
                .flat_map(|j| (x0..x1).map(move |i| (i, j)))
                .map(|(i, j)| s.widths[j * w + i])
                .collect();
            let total: u64 = widths.iter().map(|&w| w as u64).sum();
            assert_eq!(total, if s.power[k] > 0.0 { CDF_ONE as u64 } else { 0 });
            if total > 0 {
                for (&r, &w) in super::pick::received(slots).iter().zip(&widths) {
                    assert_eq!(r, widths.len() as u128 * w as u128);
                }
            }
        }
        assert_eq!(used, s.widths.len());
        assert_eq!(used, w * h);
        let powers: f64 = s.power.iter().sum();
        assert!((powers - 1.0).abs() < 1e-12, "{powers}");
        assert!(sampler.memory_bytes() >= 4 * w * h);
    }
}

/// The largest ratio of arc length to step length of `map` over short random steps
/// in every direction of `[0, 1]²`.
fn worst_stretch(map: impl Fn(f64, f64) -> [f64; 3]) -> f64 {
    let mut worst = 0.0f64;
    for k in 0..200_000u64 {
        let [u, v] = xi_2d(21, k);
        let [a, b] = xi_2d(22, k);
        let step = 1e-3 * (0.1 + a as f64);
        let (s, c) = (2.0 * PI * b as f64).sin_cos();
        let (u, v) = (u as f64, v as f64);
        let (u2, v2) = (u + step * c, v + step * s);
        if !(0.0..=1.0).contains(&u2) || !(0.0..=1.0).contains(&v2) {
            continue;
        }
        let (p, q) = (map(u, v), map(u2, v2));
        let q = Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32);
        let length = ((u2 - u).powi(2) + (v2 - v).powi(2)).sqrt();
        worst = worst.max(angle(p, q) / length);
    }
    worst
}

/// The arc-length bound used for equal-area cones, against the mapping.
#[test]
fn equal_area_lipschitz_bound_holds() {
    let worst = worst_stretch(|u, v| {
        let d = crate::mapping::equal_area::square_to_sphere(u as f32, v as f32);
        [d.x as f64, d.y as f64, d.z as f64]
    });
    assert!(worst <= EQUAL_AREA_LIPSCHITZ, "{worst}");
    assert!(worst > 0.5 * EQUAL_AREA_LIPSCHITZ, "a loose bound: {worst}");
}

/// The arc-length bound of the octahedral grid of normals (the neighbourhoods'
/// cones), against the map (whose round trip `mapping::octahedral` tests).
#[test]
fn octahedral_lipschitz_bound_holds() {
    let worst = worst_stretch(octahedral_to_sphere);
    assert!(worst <= OCTAHEDRAL_LIPSCHITZ, "{worst}");
    assert!(worst > 0.5 * OCTAHEDRAL_LIPSCHITZ, "a loose bound: {worst}");
}

/// Sampling efficiency `(∫ Y f dω)² / ∫ (Y f)² / p dω` (1 when `p ∝ Y f`) by
/// quadrature, for the product pdf and for the light's own: on a constant map,
/// where the light alone ignores the factor, and on the sky, whose sun carries
/// most of any integral.
#[test]
fn product_beats_the_light_alone() {
    let constant = EnvImage::from_fn(64, 32, |_, _| [1.0; 3]).unwrap();
    let sky = crate::builtin::sky(128, 64);
    let tilted = Vec3::new(0.3, 0.2, 0.9);
    let up = Vec3::new(0.0, 0.0, 1.0);
    for (name, image, factor, at_least) in [
        ("constant", &constant, Factor::cosine(tilted), 0.9),
        // A glossy factor's tables follow the lobe; the cosine, which falls
        // from 0.86 to 0.22 across this lobe (its mirror direction is 54° from
        // the normal), only through the lookup turned towards the normal: 0.75
        // measured (0.64 with the lookup at the mirror direction and the widest
        // lobe's grid at 8 cells a side).
        (
            "constant",
            &constant,
            Factor::glossy(tilted, Vec3::new(-0.5, 0.1, 0.7), 0.3),
            0.7,
        ),
        ("sky", &sky, Factor::cosine(up), 0.5),
        ("sky", &sky, Factor::cosine(Vec3::new(1.0, 0.0, 0.2)), 0.5),
        (
            "sky",
            &sky,
            Factor::glossy(up, Vec3::new(-0.5, -0.8, 0.6), 0.2),
            0.5,
        ),
    ] {
        let c = case(name, image.clone(), LightOptions::default(), None);
        let light = c.sampler.light();
        let point = c.sampler.at(&factor);
        let (nu, nv) = (512usize, 256usize);
        let (mut target, mut product, mut alone) = (0.0f64, 0.0f64, 0.0f64);
        for j in 0..nv {
            for i in 0..nu {
                let (u, v) = ((i as f32 + 0.5) / nu as f32, (j as f32 + 0.5) / nv as f32);
                let (d, sin_theta) = crate::mapping::equirect_to_direction(u, v);
                let dw = 2.0 * PI * PI * sin_theta as f64 / (nu * nv) as f64;
                let y = (luminance(light.radiance(d)) * factor.value(d)) as f64;
                if y > 0.0 {
                    target += y * dw;
                    product += y * y / point.pdf(d) as f64 * dw;
                    alone += y * y / light.pdf(d) as f64 * dw;
                }
            }
        }
        let (product, alone) = (target * target / product, target * target / alone);
        assert!(
            product > alone && product > at_least,
            "{name}, {factor:?}: {product} vs {alone}"
        );
    }
}

/// The exported cosine tables are the sampler's own: every lit patch's cell widths
/// and every non-empty node's patch widths sum to `CDF_ONE`, each alias table gives
/// every entry exactly its width, spans tile the cell grid, and the bright patches
/// are where `bright_of_patch` says.
#[test]
fn exported_cosine_tables_are_consistent() {
    for c in cases() {
        let t = c.sampler.cosine_tables();
        let [cw, ch] = t.cells.map(|x| x as usize);
        let nodes = (t.grid as usize + 1).pow(2);
        let patches = t.spans.len();
        assert_eq!(
            patches,
            (t.patches[0] * t.patches[1]) as usize,
            "{}",
            c.name
        );
        assert_eq!(t.cell_widths.len(), cw * ch, "{}", c.name);
        assert_eq!(t.cell_slots.len(), cw * ch, "{}", c.name);
        assert_eq!(t.table_widths.len(), patches * nodes, "{}", c.name);
        assert_eq!(t.table_slots.len(), patches * nodes, "{}", c.name);
        let received = |slots: &[[u32; 2]]| {
            let mut got = vec![0u128; slots.len()];
            for (s, &[threshold, alias]) in slots.iter().enumerate() {
                got[s] += threshold as u128;
                got[alias as usize] += (CDF_ONE - threshold) as u128;
            }
            got
        };
        let mut covered = vec![0u8; cw * ch];
        for [x0, y0, cols, rows, first] in t.spans.iter().map(|s| s.map(|x| x as usize)) {
            let mut widths = Vec::new();
            for j in y0..y0 + rows {
                for i in x0..x0 + cols {
                    widths.push(t.cell_widths[j * cw + i] as u64);
                    covered[j * cw + i] += 1;
                }
            }
            let sum: u64 = widths.iter().sum();
            assert!(sum == 0 || sum == CDF_ONE as u64, "{}", c.name);
            if sum > 0 {
                let got = received(&t.cell_slots[first..first + cols * rows]);
                for (g, w) in got.iter().zip(&widths) {
                    assert_eq!(*g, (cols * rows) as u128 * *w as u128, "{}", c.name);
                }
            }
        }
        assert!(covered.iter().all(|&n| n == 1), "{}", c.name);
        for m in 0..nodes {
            let widths: Vec<u64> = (0..patches)
                .map(|k| t.table_widths[k * nodes + m] as u64)
                .collect();
            let sum: u64 = widths.iter().sum();
            assert_eq!(sum == 0, t.node_empty[m], "{}", c.name);
            if sum > 0 {
                assert_eq!(sum, CDF_ONE as u64, "{}", c.name);
                let got = received(&t.table_slots[m * patches..(m + 1) * patches]);
                for (g, w) in got.iter().zip(&widths) {
                    assert_eq!(*g, patches as u128 * *w as u128, "{}", c.name);
                }
            }
        }
        for (b, bright) in t.bright.iter().enumerate() {
            assert_eq!(
                t.bright_of_patch[bright.patch as usize] as usize, b,
                "{}",
                c.name
            );
        }
        let marked = t.bright_of_patch.iter().filter(|&&b| b != 255).count();
        assert_eq!(marked, t.bright.len(), "{}", c.name);
        let bilinear = c.sampler.density() == Density::PiecewiseBilinear;
        assert_eq!(t.density, c.sampler.density(), "{}", c.name);
        assert_eq!(!t.node_values.is_empty(), bilinear, "{}", c.name);
    }
}

/// The on-the-fly product (every patch weighted at the shading point, for
/// measurements against the tables) is a density too: it integrates to 1 and its
/// pdf is its samples'.
#[test]
fn on_the_fly_product_is_a_density() {
    // Sizes that divide check_integral's grid: the midpoint rule is then exact.
    for (w, h, patches) in [(64, 32, [16, 8]), (64, 32, [64, 32])] {
        let light =
            EnvironmentLight::new(crate::builtin::sky(w, h), LightOptions::default()).unwrap();
        let case = Case {
            name: "on the fly",
            sampler: ProductSampler::new(
                Arc::new(light),
                ProductOptions {
                    patches: Some(patches),
                    variant: ProductVariant::OnTheFly,
                    ..Default::default()
                },
            ),
        };
        assert!(case.sampler.bright.len() > MAX_BRIGHT);
        check_pdf_of_samples(&case);
        check_integral(&case);
    }
}

/// The horizon's band: no sample lands in it below the horizon (its draws are
/// reflected above), and of the rest few lie below the horizon, for random
/// normals under the built-in sky, whose hazy horizon puts up to 2.1% of the
/// draws there without the reflection.
#[test]
fn samples_stay_above_the_horizon() {
    let light = EnvironmentLight::new(crate::builtin::sky(256, 128), LightOptions::default());
    let sampler = ProductSampler::new(Arc::new(light.unwrap()), ProductOptions::default());
    let mut worst = 0.0f64;
    for i in 0..32 {
        let normal = crate::math::uniform_sphere(xi_2d(77, i));
        let point = sampler.at(&Factor::cosine(normal));
        let (mut below, mut drawn) = (0usize, 0usize);
        for s in 0..20_000 {
            let Some(sample) = point.sample(xi_2d(5, s)) else {
                continue;
            };
            let c = normal.dot(sample.direction);
            assert!(
                !(c < 0.0 && c > -point.horizon_band()),
                "normal {normal:?}: a sample at n·ω = {c}"
            );
            let pdf = point.pdf(sample.direction);
            assert!(
                (pdf - sample.pdf).abs() <= 1e-5 * sample.pdf,
                "{pdf} {sample:?}"
            );
            drawn += 1;
            below += (c <= 0.0) as usize;
        }
        worst = worst.max(below as f64 / drawn as f64);
    }
    assert!(worst < 0.005, "{worst}");
}
