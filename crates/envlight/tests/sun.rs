//! Sun extraction (`envlight::sun`, issue 24): synthetic maps with a known uniform
//! disc (radius 0.27°–3°, 1k–4k wide, at the zenith, over the pole, near the
//! horizon, across the φ = 0 seam), maps without one, and the real maps in
//! `shared/envmaps` when they are there.
//!
//! What is measured against what (all printed; run with `--nocapture`):
//! - direction: the angle to the disc's true centre, within max(0.1°, one texel);
//! - solid angle: against `2π(1 − cos r)`, within 10% (a disc at least two texels
//!   across; a smaller one can only be bounded from above);
//! - irradiance at normal incidence: against what the map holds, the rasterised
//!   disc's `Σ coverage L (ω·c) ΔΩ`, within 3% per channel;
//! - residual + disc against the map: `E(n) = Σ L max(0, n·ω) ΔΩ` of the residual
//!   plus `E⊥ max(0, n·ĉ)` of the disc, at six normals at least 20° from grazing the
//!   sun, within 1% of the map's;
//! - the residual's brightest texel within `r + 4` texels of the sun, against the
//!   mean of the residual in the ring just outside: at most 3×.

mod common;

use std::f64::consts::PI;

use envlight::light::Mapping;
use envlight::{EnvImage, EnvironmentLight, LightOptions, Rotation, Sun, SunOptions, Vec3};
use rayon::prelude::*;

// ------------------------------------------------------------------ geometry

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalize(v: [f64; 3]) -> [f64; 3] {
    let l = dot(v, v).sqrt();
    v.map(|c| c / l)
}

fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = cross(a, b);
    dot(c, c).sqrt().atan2(dot(a, b))
}

fn v64(v: Vec3) -> [f64; 3] {
    [v.x as f64, v.y as f64, v.z as f64]
}

/// The unit direction at elevation `el` above the horizon and azimuth `az` from +x
/// towards +y (degrees).
fn dir_deg(el: f64, az: f64) -> [f64; 3] {
    let (el, az) = (el.to_radians(), az.to_radians());
    [el.cos() * az.cos(), el.cos() * az.sin(), el.sin()]
}

fn luminance(c: [f64; 3]) -> f64 {
    0.212671 * c[0] + 0.715160 * c[1] + 0.072169 * c[2]
}

/// Texel centre directions and solid angles of a lat-long `w × h` map.
struct LatLong {
    h: usize,
    /// `(sin θ, cos θ, ΔΩ)` per row.
    rows: Vec<(f64, f64, f64)>,
    /// `(cos φ, sin φ)` per column.
    cols: Vec<(f64, f64)>,
}

impl LatLong {
    fn new(w: usize, h: usize) -> Self {
        let dphi = 2.0 * PI / w as f64;
        let rows = (0..h)
            .map(|j| {
                let t = PI * (j as f64 + 0.5) / h as f64;
                let (a, b) = (PI * j as f64 / h as f64, PI * (j + 1) as f64 / h as f64);
                (t.sin(), t.cos(), dphi * (a.cos() - b.cos()))
            })
            .collect();
        let cols = (0..w)
            .map(|i| {
                let p = dphi * (i as f64 + 0.5);
                (p.cos(), p.sin())
            })
            .collect();
        Self { h, rows, cols }
    }

    fn dir(&self, x: usize, y: usize) -> [f64; 3] {
        let (st, ct, _) = self.rows[y];
        let (cp, sp) = self.cols[x];
        [st * cp, st * sp, ct]
    }

    fn pitch(&self) -> f64 {
        PI / self.h as f64
    }
}

/// Texel directions and solid angles of a light's image, whatever its mapping.
fn texel_geometry(light: &EnvironmentLight) -> Box<dyn Fn(usize) -> ([f64; 3], f64) + Sync> {
    let (w, h) = (light.image().width(), light.image().height());
    match light.mapping() {
        Mapping::Equirectangular => {
            let g = LatLong::new(w, h);
            Box::new(move |i| (g.dir(i % w, i / w), g.rows[i / w].2))
        }
        Mapping::EqualArea => Box::new(move |i| {
            let (x, y) = (i % w, i / w);
            let d = envlight::equal_area::square_to_sphere(
                (x as f32 + 0.5) / w as f32,
                (y as f32 + 0.5) / h as f32,
            );
            (normalize(v64(d)), 4.0 * PI / (w * h) as f64)
        }),
    }
}

/// `E(n) = Σ L max(0, n·ω) ΔΩ` per channel of `image` (in the light's frame),
/// for every normal at once.
fn irradiance(
    image: &EnvImage,
    geometry: &(dyn Fn(usize) -> ([f64; 3], f64) + Sync),
    normals: &[[f64; 3]],
) -> Vec<[f64; 3]> {
    let zero = || vec![[0.0f64; 3]; normals.len()];
    image
        .texels()
        .par_iter()
        .enumerate()
        .fold(zero, |mut acc, (i, t)| {
            let (d, dw) = geometry(i);
            for (a, n) in acc.iter_mut().zip(normals) {
                let c = dot(*n, d);
                if c > 0.0 {
                    for k in 0..3 {
                        a[k] += t[k] as f64 * c * dw;
                    }
                }
            }
            acc
        })
        .reduce(zero, |mut a, b| {
            for (x, y) in a.iter_mut().zip(b) {
                for k in 0..3 {
                    x[k] += y[k];
                }
            }
            a
        })
}

/// Six normals at 0°, 45°, 70°, 115°, 150° and 180° from `c` (light frame): lit
/// and unlit, none within 20° of grazing the sun.
fn normals_around(c: [f64; 3]) -> Vec<[f64; 3]> {
    let helper = if c[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let a = normalize(cross(helper, c));
    let b = cross(c, a);
    [
        (0.0, a),
        (45.0, a),
        (70.0, b),
        (115.0, a),
        (150.0, b),
        (180.0, a),
    ]
    .iter()
    .map(|&(deg, t): &(f64, [f64; 3])| {
        let (s, co) = deg.to_radians().sin_cos();
        normalize([0, 1, 2].map(|k| co * c[k] + s * t[k]))
    })
    .collect()
}

/// The worst relative difference, over six normals and three channels, between the
/// map's irradiance and the residual's plus the disc's. Works in the light frame.
fn residual_plus_disc_error(light: &EnvironmentLight, sun: &Sun, residual: &EnvImage) -> f64 {
    let rotation = light.options().rotation.inverse();
    let scale = light.options().scale as f64;
    let c = normalize(v64(rotation.apply(sun.direction)));
    let normals = normals_around(c);
    let geometry = texel_geometry(light);
    let map = irradiance(light.image(), &*geometry, &normals);
    let res = irradiance(residual, &*geometry, &normals);
    let mut worst: f64 = 0.0;
    for (k, n) in normals.iter().enumerate() {
        let lit = dot(*n, c).max(0.0);
        for ch in 0..3 {
            let total = res[k][ch] + sun.irradiance[ch] / scale * lit;
            worst = worst.max((total / map[k][ch] - 1.0).abs());
        }
    }
    worst
}

// ------------------------------------------------------------------ synthetic maps

/// A smooth outdoor sky (light frame): dark ground, a soft horizon (±6°), a blue
/// sky brightening towards the horizon, a gentle azimuthal variation.
fn sky(d: [f64; 3]) -> [f64; 3] {
    let t = ((d[2] + 0.1) / 0.2).clamp(0.0, 1.0);
    let t = t * t * (3.0 - 2.0 * t);
    let ground = [0.12, 0.10, 0.08];
    let glow = 1.0 + 0.6 * (1.0 - d[2].abs()) + 0.15 * d[0];
    let blue = [0.35 * glow, 0.5 * glow, 0.9 * glow];
    [0, 1, 2].map(|k| ground[k] + t * (blue[k] - ground[k]))
}

/// A uniform disc over [`sky`], rasterised with each texel's exact (supersampled,
/// solid-angle weighted) coverage.
struct DiscMap {
    image: EnvImage,
    centre: [f64; 3],
    radius: f64,
    /// What the map holds: `Σ coverage L (ω·c) ΔΩ` per channel.
    held_irradiance: [f64; 3],
    /// `Σ coverage ΔΩ` (the rasterised disc's solid angle).
    held_solid_angle: f64,
    pitch: f64,
}

/// The sun's colour; its `∫ L dω` is [`SUN_POWER`] in luminance.
const SUN_RGB: [f64; 3] = [1.0, 0.93, 0.8];
/// The disc's `∫ Y dω` (the sky's is about 6.7): a share of about 18%.
const SUN_POWER: f64 = 1.5;

fn disc_map(w: usize, centre: [f64; 3], radius_deg: f64) -> DiscMap {
    disc_map_over(w, centre, radius_deg, SUN_POWER, 0.0)
}

/// [`disc_map`] with the disc's `∫ Y dω` and a texel noise of relative amplitude
/// `noise_amplitude` on the sky (which the in-painting cannot reproduce).
fn disc_map_over(
    w: usize,
    centre: [f64; 3],
    radius_deg: f64,
    power: f64,
    noise_amplitude: f64,
) -> DiscMap {
    let h = w / 2;
    let g = LatLong::new(w, h);
    let radius = radius_deg.to_radians();
    let omega = 2.0 * PI * (1.0 - radius.cos());
    let sun = SUN_RGB.map(|c| c * power / (luminance(SUN_RGB) * omega));
    let centre = normalize(centre);
    let pitch = g.pitch();
    let theta_c = centre[0].hypot(centre[1]).atan2(centre[2]);
    let reach = radius + 1.5 * pitch;
    let y0 = (((theta_c - reach) / PI * h as f64).floor().max(0.0)) as usize;
    let y1 = ((((theta_c + reach) / PI * h as f64).ceil()) as usize).min(h);
    // Sub-samples per texel side: enough for a disc a few sub-samples across.
    let k_side = if radius < 2.0 * pitch { 48 } else { 16 };
    let cos_r = radius.cos();
    // Coverage of the texels whose centre is within the radius plus a texel.
    let covered: Vec<(usize, f64)> = (y0..y1)
        .into_par_iter()
        .flat_map_iter(|y| {
            let g = &g;
            (0..w).filter_map(move |x| {
                if angle(g.dir(x, y), centre) > reach {
                    return None;
                }
                let (mut inside, mut total) = (0.0, 0.0);
                let k = k_side as f64;
                for sy in 0..k_side {
                    let th = PI * (y as f64 + (sy as f64 + 0.5) / k) / h as f64;
                    let (st, ct) = th.sin_cos();
                    for sx in 0..k_side {
                        let ph = 2.0 * PI * (x as f64 + (sx as f64 + 0.5) / k) / w as f64;
                        let d = [st * ph.cos(), st * ph.sin(), ct];
                        total += st;
                        if dot(d, centre) >= cos_r {
                            inside += st;
                        }
                    }
                }
                (inside > 0.0).then(|| (y * w + x, inside / total))
            })
        })
        .collect();
    let mut texels: Vec<[f32; 3]> = (0..h)
        .into_par_iter()
        .flat_map_iter(|y| {
            let g = &g;
            (0..w).map(move |x| {
                let d = g.dir(x, y);
                let n = 1.0 + noise_amplitude * (2.0 * noise(d) - 1.0);
                sky(d).map(|c| (c * n) as f32)
            })
        })
        .collect();
    let mut held_irradiance = [0.0; 3];
    let mut held_solid_angle = 0.0;
    for &(i, cov) in &covered {
        let (x, y) = (i % w, i / w);
        let dw = g.rows[y].2;
        let cos = dot(g.dir(x, y), centre);
        for k in 0..3 {
            texels[i][k] += (cov * sun[k]) as f32;
            held_irradiance[k] += cov * sun[k] * cos * dw;
        }
        held_solid_angle += cov * dw;
    }
    DiscMap {
        image: EnvImage::new(w, h, texels).unwrap(),
        centre,
        radius,
        held_irradiance,
        held_solid_angle,
        pitch,
    }
}

fn lat_long_light(image: EnvImage) -> EnvironmentLight {
    EnvironmentLight::new(image, LightOptions::default()).unwrap()
}

/// Brightest residual texel within `r + 4` texels of the sun over the mean
/// residual luminance in the ring from there out to `2r + 10` texels.
fn residual_peak_ratio(residual: &EnvImage, centre: [f64; 3], radius: f64, pitch: f64) -> f64 {
    let (w, h) = (residual.width(), residual.height());
    let g = LatLong::new(w, h);
    let inner = radius + 4.0 * pitch;
    let outer = 2.0 * radius + 10.0 * pitch;
    let (mut peak, mut sum, mut weight) = (0.0f64, 0.0, 0.0);
    for y in 0..h {
        for x in 0..w {
            let a = angle(g.dir(x, y), centre);
            if a >= outer {
                continue;
            }
            let t = residual.texel(x, y);
            let lum = luminance(t.map(|c| c as f64));
            if a < inner {
                peak = peak.max(lum);
            } else {
                sum += lum * g.rows[y].2;
                weight += g.rows[y].2;
            }
        }
    }
    peak / (sum / weight)
}

struct Case {
    name: &'static str,
    width: usize,
    radius_deg: f64,
    centre: [f64; 3],
    /// At least two texels across: the solid angle is measured, not bounded.
    resolved: bool,
    /// The disc's `∫ Y dω` and the sky's relative texel noise.
    power: f64,
    noise: f64,
}

fn check_disc(case: &Case) {
    let map = disc_map_over(
        case.width,
        case.centre,
        case.radius_deg,
        case.power,
        case.noise,
    );
    let omega = 2.0 * PI * (1.0 - map.radius.cos());
    assert!(
        // Sub-sampling quantises the coverage of rows cut by a disc at the zenith.
        (map.held_solid_angle / omega - 1.0).abs() < 0.015,
        "{}: rasterised {} vs {omega}",
        case.name,
        map.held_solid_angle
    );
    let light = lat_long_light(map.image.clone());
    let ex = light.extract_sun(&SunOptions::default());
    let sun = ex
        .sun
        .unwrap_or_else(|| panic!("{}: no sun found", case.name));

    let direction_error = angle(v64(sun.direction), map.centre);
    let direction_limit = (0.1f64.to_radians()).max(map.pitch);
    let omega_error = sun.solid_angle / omega - 1.0;
    let irradiance_error = (0..3)
        .map(|k| (sun.irradiance[k] / map.held_irradiance[k] - 1.0).abs())
        .fold(0.0, f64::max);
    let residual_error = residual_plus_disc_error(&light, &sun, &ex.residual);
    let peak_ratio = residual_peak_ratio(&ex.residual, map.centre, map.radius, map.pitch);
    println!(
        "{:<28} {}x{} r={:.2}°: direction off {:.4}° (limit {:.3}°), solid angle {:+.2}%, \
         irradiance {:.3}%, residual+disc {:.4}%, residual peak {:.2}x sky, \
         radius {:.3}°, power {:.3}, contrast {:.0}",
        case.name,
        case.width,
        case.width / 2,
        case.radius_deg,
        direction_error.to_degrees(),
        direction_limit.to_degrees(),
        100.0 * omega_error,
        100.0 * irradiance_error,
        100.0 * residual_error,
        peak_ratio,
        sun.angular_radius_deg(),
        sun.power_fraction,
        sun.contrast,
    );
    assert!(
        direction_error <= direction_limit,
        "{}: direction",
        case.name
    );
    // Sub-texel: the weighted centroid, not the brightest texel's centre.
    assert!(
        direction_error <= 0.1 * map.pitch,
        "{}: sub-texel",
        case.name
    );
    if case.resolved {
        assert!(omega_error.abs() <= 0.10, "{}: solid angle", case.name);
    } else {
        // Below the resolution the disc is an upper bound of about a texel.
        assert!(omega_error > -0.10, "{}: solid angle", case.name);
    }
    assert!(irradiance_error <= 0.03, "{}: irradiance", case.name);
    assert!(residual_error <= 0.01, "{}: residual + disc", case.name);
    assert!(peak_ratio <= 3.0, "{}: residual peak", case.name);
    // The radiance is the irradiance spread over the disc.
    let r = sun.angular_radius;
    for k in 0..3 {
        let e = sun.radiance[k] * PI * r.sin() * r.sin();
        assert!((e / sun.irradiance[k] - 1.0).abs() < 1e-9);
    }
    assert!((sun.solid_angle / (2.0 * PI * (1.0 - r.cos())) - 1.0).abs() < 1e-9);
}

#[test]
fn small_suns_on_wide_maps() {
    check_disc(&Case {
        name: "0.27° at 35° elevation",
        width: 4096,
        radius_deg: 0.27,
        centre: dir_deg(35.0, 123.0),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "0.27° near the horizon",
        width: 2048,
        radius_deg: 0.27,
        centre: dir_deg(2.0, 250.0),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "0.27° unresolved on 1k",
        width: 1024,
        radius_deg: 0.27,
        centre: dir_deg(20.3, 77.7),
        resolved: false,
        power: SUN_POWER,
        noise: 0.0,
    });
}

#[test]
fn large_suns_at_the_zenith_the_pole_and_the_seam() {
    check_disc(&Case {
        name: "3° at the zenith",
        width: 1024,
        radius_deg: 3.0,
        centre: [0.0, 0.0, 1.0],
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "2° over the pole",
        width: 2048,
        radius_deg: 2.0,
        centre: dir_deg(88.7, 300.0),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "1° across the seam",
        width: 2048,
        radius_deg: 1.0,
        centre: dir_deg(20.0, 0.1),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "1.5° on the seam, horizon",
        width: 1024,
        radius_deg: 1.5,
        centre: dir_deg(3.0, 359.6),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
    check_disc(&Case {
        name: "3° at 60° elevation on 4k",
        width: 4096,
        radius_deg: 3.0,
        centre: dir_deg(60.0, 10.0),
        resolved: true,
        power: SUN_POWER,
        noise: 0.0,
    });
}

#[test]
fn dim_suns_over_a_noisy_sky() {
    // 20% texel noise on the sky, and a sun with about 2% of the power (the
    // threshold is 1%): the in-painting now misses the noise under the disc.
    check_disc(&Case {
        name: "dim 0.5°, noisy sky",
        width: 2048,
        radius_deg: 0.5,
        centre: dir_deg(15.0, 280.0),
        resolved: true,
        power: 0.1,
        noise: 0.2,
    });
    check_disc(&Case {
        name: "dim 2.5°, noisy sky, seam",
        width: 1024,
        radius_deg: 2.5,
        centre: dir_deg(40.0, 1.0),
        resolved: true,
        power: 0.1,
        noise: 0.2,
    });
}

#[test]
fn rotation_and_scale_apply_to_the_sun_not_to_the_residual() {
    let map = disc_map(1024, dir_deg(30.0, 40.0), 1.0);
    let plain = lat_long_light(map.image.clone()).extract_sun(&SunOptions::default());
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(90.0),
        scale: 2.0,
        ..Default::default()
    };
    let light = EnvironmentLight::new(map.image.clone(), options).unwrap();
    let turned = light.extract_sun(&SunOptions::default());
    let (a, b) = (plain.sun.unwrap(), turned.sun.unwrap());
    let expected = dir_deg(30.0, 130.0);
    assert!(angle(v64(b.direction), expected) < 0.1f64.to_radians());
    for k in 0..3 {
        assert!((b.irradiance[k] / a.irradiance[k] - 2.0).abs() < 1e-9);
        assert!((b.radiance[k] / a.radiance[k] - 2.0).abs() < 1e-9);
    }
    assert_eq!(a.power_fraction, b.power_fraction);
    assert_eq!(plain.residual, turned.residual);
    assert!(residual_plus_disc_error(&light, &b, &turned.residual) < 0.01);
}

#[test]
fn equal_area_light_finds_the_same_sun() {
    let map = disc_map(1024, dir_deg(25.0, 200.0), 1.5);
    let options = LightOptions {
        mapping: Mapping::EqualArea,
        ..Default::default()
    };
    let light = EnvironmentLight::new(map.image.clone(), options).unwrap();
    let ex = light.extract_sun(&SunOptions::default());
    let sun = ex.sun.expect("a sun on the equal-area square");
    let direction_error = angle(v64(sun.direction), map.centre).to_degrees();
    let irradiance_error = (sun.irradiance[1] / map.held_irradiance[1] - 1.0).abs();
    let residual_error = residual_plus_disc_error(&light, &sun, &ex.residual);
    println!(
        "equal-area {}²: direction off {direction_error:.4}°, irradiance {:.3}%, \
         residual+disc {:.4}%, radius {:.3}° (true 1.5°)",
        light.image().width(),
        100.0 * irradiance_error,
        100.0 * residual_error,
        sun.angular_radius_deg()
    );
    // The resampling to the square blurs the disc by about a texel.
    assert!(direction_error < 0.2);
    assert!(irradiance_error < 0.03);
    assert!(residual_error < 0.01);
    assert_eq!(ex.residual.width(), light.image().width());
}

// ------------------------------------------------------------------ no sun

fn no_sun(name: &str, w: usize, h: usize, f: impl Fn([f64; 3]) -> [f64; 3] + Sync) {
    let g = LatLong::new(w, h);
    let image = EnvImage::from_fn(w, h, |x, y| f(g.dir(x, y)).map(|c| c as f32)).unwrap();
    let ex = lat_long_light(image.clone()).extract_sun(&SunOptions::default());
    println!(
        "{name:<40} {w}x{h}: {:?}",
        ex.sun.map(|s| s.angular_radius_deg())
    );
    assert!(ex.sun.is_none(), "{name}: {:?}", ex.sun);
    assert_eq!(ex.residual, image, "{name}: the residual is the map");
    assert_eq!(ex.inpainted_texels, 0);
}

/// A deterministic hash of a direction in [0, 1).
fn noise(d: [f64; 3]) -> f64 {
    let s = (d[0] * 12.9898 + d[1] * 78.233 + d[2] * 37.719).sin() * 43758.5453;
    s - s.floor()
}

#[test]
fn maps_without_a_compact_source_report_none() {
    no_sun("black", 256, 128, |_| [0.0; 3]);
    no_sun("uniform", 1024, 512, |_| [0.7, 0.8, 0.9]);
    no_sun("1x1", 1, 1, |_| [3.0; 3]);
    no_sun("2x1", 2, 1, |_| [3.0; 3]);
    no_sun("clear sky, no sun", 1024, 512, sky);
    no_sun("overcast (bright zenith)", 1024, 512, |d| {
        let b = 1.0 + 3.0 * d[2].max(0.0).powi(2);
        [b, b, b * 1.1]
    });
    no_sun("overcast with 30% texel noise", 1024, 512, |d| {
        let b = (1.0 + d[2].max(0.0)) * (0.85 + 0.3 * noise(d));
        [b, b, b]
    });
    no_sun("soft glow, 8° wide, 5x the sky", 1024, 512, |d| {
        let a = angle(d, dir_deg(40.0, 100.0));
        let b = 1.0 + 4.0 * (-(a * a) / (2.0 * 8f64.to_radians().powi(2))).exp();
        [b, b, b]
    });
    no_sun("window 20°x15°, 50x the sky", 1024, 512, |d| {
        let (el, az) = (d[2].asin().to_degrees(), d[1].atan2(d[0]).to_degrees());
        let inside = (10.0..25.0).contains(&el) && (30.0..50.0).contains(&az);
        let b = if inside { 50.0 } else { 1.0 };
        [b, b, b]
    });
    no_sun("faint star (0.1% of the power)", 1024, 512, |d| {
        let b = if angle(d, dir_deg(50.0, 10.0)) < 0.5f64.to_radians() {
            50.0
        } else {
            0.5
        };
        [b, b, b]
    });
    // A map with a single column: each texel is a whole ring of latitude.
    no_sun("1x512 with a hot texel", 1, 512, |d| {
        if d[2].abs() < 0.01 {
            [1e4; 3]
        } else {
            [1.0; 3]
        }
    });
    // A tiny map cannot hold a compact source: its texels are larger than 5°.
    no_sun("32x16 with a hot texel", 32, 16, |d| {
        if angle(d, dir_deg(30.0, 30.0)) < 0.2 {
            [1e4; 3]
        } else {
            [1.0; 3]
        }
    });
}

#[test]
fn a_black_sky_with_a_sun_has_infinite_contrast() {
    let g = LatLong::new(512, 256);
    let c = dir_deg(45.0, 45.0);
    let image = EnvImage::from_fn(512, 256, |x, y| {
        if angle(g.dir(x, y), c) < 2f64.to_radians() {
            [100.0; 3]
        } else {
            [0.0; 3]
        }
    })
    .unwrap();
    let light = lat_long_light(image);
    let ex = light.extract_sun(&SunOptions::default());
    let sun = ex.sun.expect("a sun on black");
    assert_eq!(sun.contrast, f64::INFINITY);
    assert!((sun.power_fraction - 1.0).abs() < 1e-9);
    assert!(ex.residual.texels().iter().all(|t| *t == [0.0; 3]));
    assert!(residual_plus_disc_error(&light, &sun, &ex.residual) < 0.01);
}

// ------------------------------------------------------------------ real maps

#[test]
fn real_maps_residual_plus_disc_reproduces_the_irradiance() {
    let Some(dir) = common::envmaps() else { return };
    for name in envlight_verify::maps::SHARED {
        let path = dir.join(name);
        if !path.is_file() {
            println!("skipped: {} not found", path.display());
            continue;
        }
        let image = envlight::load::load(&path, &Default::default())
            .unwrap()
            .image;
        let light = lat_long_light(image);
        let ex = light.extract_sun(&SunOptions::default());
        match &ex.sun {
            None => println!("{name:<24} no sun"),
            Some(sun) => {
                let error = residual_plus_disc_error(&light, sun, &ex.residual);
                println!(
                    "{name:<24} elevation {:6.2}° azimuth {:6.2}° radius {:.3}° Ω {:.3e} sr \
                     E⊥ {:.3e} power {:.3} contrast {:.0}, {} texels in-painted: \
                     residual+disc {:.4}%",
                    sun.elevation_deg(),
                    sun.azimuth_deg(),
                    sun.angular_radius_deg(),
                    sun.solid_angle,
                    luminance(sun.irradiance),
                    sun.power_fraction,
                    sun.contrast,
                    ex.inpainted_texels,
                    100.0 * error
                );
                assert!(error <= 0.01, "{name}: residual + disc off by {error}");
                assert!(sun
                    .irradiance
                    .iter()
                    .chain(&sun.radiance)
                    .all(|v| v.is_finite()));
            }
        }
        // The two outdoor maps with a visible sun, at the brightest texel's elevation
        // (shared/envmaps/README.md); the soft courtyard has none.
        match name {
            "sunrise.exr" => {
                let s = ex.sun.expect("sunrise has a sun");
                assert!((s.elevation_deg() - 7.9).abs() < 0.5 && s.power_fraction > 0.4);
            }
            "city.exr" => {
                let s = ex.sun.expect("city has a sun");
                assert!((s.elevation_deg() - 47.6).abs() < 0.5);
            }
            "courtyard.exr" => assert!(ex.sun.is_none()),
            _ => {}
        }
    }
}

#[test]
fn the_builtin_sky_gives_back_its_own_sun() {
    // builtin::sky draws a 1° disc of known radiance at a known direction, with
    // 4×4 supersampled edges, over a glow.
    let light = lat_long_light(envlight::builtin::sky(1024, 512));
    let sun = light.sun().expect("the built-in sky has a sun");
    let truth = envlight::builtin::sun_direction();
    let error = angle(v64(sun.direction), v64(truth)).to_degrees();
    let radius = envlight::builtin::SUN_ANGULAR_RADIUS as f64;
    let radiance = envlight::builtin::SUN_RADIANCE;
    println!(
        "builtin:sky 1024x512: direction off {error:.4}°, radius {:.4}° (true {:.4}°), \
         radiance {:?} (true {radiance:?})",
        sun.angular_radius_deg(),
        radius.to_degrees(),
        sun.radiance
    );
    assert!(error < 0.01);
    assert!((sun.angular_radius / radius - 1.0).abs() < 0.01);
    for (got, truth) in sun.radiance.iter().zip(radiance) {
        assert!((got / truth as f64 - 1.0).abs() < 0.01);
    }
}
