//! `Lookup::Node`, Mitsuba 3 envmap's reading of a lat-long map: exact values on
//! tiny images, the batch queries equal to the one-point ones, the bilinear
//! density's nodes on its rows, and the options it refuses. (Its sampling
//! invariants are in `invariants.rs`, the `*::node` cases.)

mod common;

use envlight::light::{Density, Mapping};
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation, Vec3, WrapU};

fn image_3x4() -> EnvImage {
    // Row j, column i: 10 j + i + 1 in every channel (distinct, positive).
    EnvImage::from_fn(3, 4, |i, j| [(10 * j + i + 1) as f32; 3]).unwrap()
}

#[test]
fn rows_are_nodes_from_pole_to_pole() {
    let img = image_3x4();
    let at = |u: f32, v: f32| img.lookup_wrapped(u, v, Lookup::Node, WrapU::Periodic)[0];
    // On a texel centre along u (u = (i + ½)/w), row j sits exactly at v = j/(h-1).
    let centre = |i: usize| (i as f32 + 0.5) / 3.0;
    for j in 0..4 {
        for i in 0..3 {
            let v = j as f32 / 3.0;
            let want = (10 * j + i + 1) as f32;
            assert!((at(centre(i), v) - want).abs() <= 1e-5 * want, "({i}, {j})");
        }
    }
    // Halfway between rows 1 and 2 (v = 1.5/3): their mean; the poles are rows 0 and 3.
    assert!((at(centre(1), 0.5) - 17.0).abs() < 1e-5);
    assert_eq!(at(centre(2), 0.0), 3.0);
    assert_eq!(at(centre(2), 1.0), 33.0);
    // Outside [0, 1] v clamps; NaN reads the top row.
    assert_eq!(at(centre(0), -0.3), 1.0);
    assert_eq!(at(centre(0), 1.7), 31.0);
    assert_eq!(at(centre(0), f32::NAN), 1.0);
    // Along u it is the bilinear lookup (the seam wraps: u = 0 is halfway between
    // the last and first columns).
    for v in [0.0f32, 0.2, 0.5, 0.9, 1.0] {
        for u in [0.0f32, 0.05, 0.3, 0.99] {
            let node = img.lookup_wrapped(u, v, Lookup::Node, WrapU::Periodic);
            // Rebuild the node row blend from two bilinear lookups at the rows'
            // own centres (bilinear is exact there along v).
            let t = v * 3.0;
            let k = (t.floor() as usize).min(2);
            let f = t - k as f32;
            let row = |k: usize| {
                img.lookup_wrapped(u, (k as f32 + 0.5) / 4.0, Lookup::Bilinear, WrapU::Periodic)[0]
            };
            let want = row(k) + f * (row(k + 1) - row(k));
            assert!(
                (node[0] - want).abs() <= 1e-4 * want,
                "u {u} v {v}: {} vs {want}",
                node[0]
            );
        }
    }
    // One row: constant in v.
    let one = EnvImage::from_fn(2, 1, |i, _| [(i + 1) as f32; 3]).unwrap();
    assert_eq!(
        one.lookup_wrapped(0.25, 0.9, Lookup::Node, WrapU::Periodic)[0],
        1.0
    );
}

#[test]
fn batch_queries_equal_the_single_ones() {
    let img = EnvImage::from_fn(37, 19, |i, j| {
        let x = ((i * 7 + j * 13) % 11) as f32;
        [x, 0.5 * x + 0.1, if (i + j) % 5 == 0 { 0.0 } else { 1.0 }]
    })
    .unwrap();
    for (sampler, density) in common::SAMPLER_DENSITIES {
        let options = LightOptions {
            lookup: Lookup::Node,
            sampler,
            density,
            rotation: Rotation::about_z_degrees(25.0),
            ..Default::default()
        };
        let light = EnvironmentLight::new(img.clone(), options).unwrap();
        let xi: Vec<[f32; 2]> = (0..2001u64).map(|k| envlight::rng::xi_2d(3, k)).collect();
        let mut samples = vec![None; xi.len()];
        light.sample_batch(&xi, &mut samples);
        let mut dirs = Vec::new();
        for (x, s) in xi.iter().zip(&samples) {
            let one = light.sample(*x);
            assert_eq!(
                one.map(|s| (s.direction, s.pdf, s.radiance)),
                s.map(|s| (s.direction, s.pdf, s.radiance))
            );
            if let Some(s) = s {
                dirs.push(s.direction);
            }
        }
        dirs.extend([
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(0.0, 0.0, -1.0),
            Vec3::new(1.0, -1e-7, 0.0),
        ]);
        let mut pdfs = vec![0.0; dirs.len()];
        let mut radiance = vec![[0.0; 3]; dirs.len()];
        light.pdf_batch(&dirs, &mut pdfs);
        light.radiance_batch(&dirs, &mut radiance);
        for ((d, p), r) in dirs.iter().zip(&pdfs).zip(&radiance) {
            assert_eq!(light.pdf(*d), *p, "{sampler:?} {density:?} {d:?}");
            assert_eq!(light.radiance(*d), *r, "{sampler:?} {density:?} {d:?}");
        }
    }
}

#[test]
fn the_node_lookup_refuses_what_it_does_not_cover() {
    let img = image_3x4();
    for density in [Density::PiecewiseConstant, Density::PiecewiseBilinear] {
        let options = LightOptions {
            lookup: Lookup::Node,
            mapping: Mapping::EqualArea,
            density,
            ..Default::default()
        };
        let err = EnvironmentLight::new(img.clone(), options)
            .unwrap_err()
            .to_string();
        assert!(err.contains("equal-area"), "{err}");
    }
}

/// The piecewise-bilinear density of the node lookup puts `Y · J` on the rows,
/// pole to pole (`v = j/(h − 1)`), with the poles' `J` the mean of `sin π v` over
/// the half cell next to them: exact values of the density, relative to each
/// other, on a 3×4 map at texel centres along u.
#[test]
fn the_bilinear_density_of_the_node_lookup_has_its_nodes_on_the_rows() {
    let img = image_3x4();
    let light = EnvironmentLight::new(
        img,
        LightOptions {
            lookup: Lookup::Node,
            density: Density::PiecewiseBilinear,
            ..Default::default()
        },
    )
    .unwrap();
    let pi = std::f64::consts::PI;
    let half = pi / 6.0; // π Δ/2 with Δ = 1/3
    let pole = (1.0 - half.cos()) / half;
    // Planar density ∝ Y J: the solid-angle pdf times the Jacobian 2π² sin θ.
    let planar = |i: usize, v: f64| {
        let u = (i as f64 + 0.5) / 3.0;
        let (d, _) = envlight::mapping::equirect_to_direction(u as f32, v as f32);
        light.pdf(d) as f64 * 2.0 * pi * pi * (pi * v).sin()
    };
    let value = |row: usize, col: usize| (10 * row + col + 1) as f64;
    let factor = |row: usize| match row {
        0 | 3 => pole,
        _ => (pi * row as f64 / 3.0).sin(),
    };
    let reference = planar(1, 0.5) / (0.5 * (value(1, 1) * factor(1) + value(2, 1) * factor(2)));
    for (row, v) in [(1usize, 1.0 / 3.0), (2, 2.0 / 3.0)] {
        for col in 0..3 {
            let want = value(row, col) * factor(row) * reference;
            let got = planar(col, v);
            assert!(
                (got - want).abs() <= 1e-4 * want,
                "row {row} col {col}: {got} vs {want}"
            );
        }
    }
    // Next to the poles (the pdf is finite there, its Jacobian 0 at them): the
    // interpolation between the pole row and the next.
    for (row, next, v, t) in [(0usize, 1usize, 0.05, 0.15), (3, 2, 0.95, 0.15)] {
        for col in 0..3 {
            let want = ((1.0 - t) * value(row, col) * factor(row)
                + t * value(next, col) * factor(next))
                * reference;
            let got = planar(col, v);
            assert!(
                (got - want).abs() <= 1e-4 * want,
                "v {v} col {col}: {got} vs {want}"
            );
        }
    }
}
