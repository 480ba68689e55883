//! Self-checks of the harness's own equal-area mapping.

use crate::frame::Frame;
use crate::param::{sphere_to_square, square_to_sphere};
use crate::sampler::SphereSampler;
use envlight::light::Mapping;
use envlight::{EnvImage, LightOptions, Lookup};
use envlight::{EnvironmentLight, Rotation};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use std::f64::consts::PI;

fn close(d: [f64; 3], want: [f64; 3], tol: f64) -> bool {
    (0..3).all(|k| (d[k] - want[k]).abs() <= tol)
}

/// Points of `[0, 1]²` from a fixed PCG stream.
fn points(n: usize, seed: u64) -> Vec<[f64; 2]> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    (0..n)
        .map(|_| [rng.random::<f64>(), rng.random::<f64>()])
        .collect()
}

#[test]
fn harness_equal_area_orientation_folds_and_round_trip() {
    for ((u, v), want) in [
        ((0.5, 0.5), [0.0, 0.0, 1.0]),
        ((0.0, 0.0), [0.0, 0.0, -1.0]),
        ((1.0, 0.0), [0.0, 0.0, -1.0]),
        ((0.0, 1.0), [0.0, 0.0, -1.0]),
        ((1.0, 1.0), [0.0, 0.0, -1.0]),
        ((1.0, 0.5), [1.0, 0.0, 0.0]),
        ((0.0, 0.5), [-1.0, 0.0, 0.0]),
        ((0.5, 1.0), [0.0, 1.0, 0.0]),
        ((0.5, 0.0), [0.0, -1.0, 0.0]),
        ((0.75, 0.75), [0.5f64.sqrt(), 0.5f64.sqrt(), 0.0]),
    ] {
        let d = square_to_sphere(u, v);
        assert!(close(d, want, 1e-15), "({u}, {v}) → {d:?}, want {want:?}");
    }
    for [u, v] in points(100_000, 1) {
        let d = square_to_sphere(u, v);
        let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        assert!((len - 1.0).abs() < 1e-15, "({u}, {v}): |ω| = {len}");
        // Octants: x from u - ½, y from v - ½, z from the diamond.
        let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
        assert_eq!(d[0] > 0.0, a > 0.0);
        assert_eq!(d[1] > 0.0, b > 0.0);
        assert_eq!(d[2] > 0.0, a.abs() + b.abs() < 1.0);
        let [u2, v2] = sphere_to_square(d);
        assert!(
            (u2 - u).abs() < 1e-13 && (v2 - v).abs() < 1e-13,
            "({u}, {v}) → {d:?} → ({u2}, {v2})"
        );
        // The boundary folds about each edge's midpoint.
        for (p, q) in [
            ((u, 0.0), (1.0 - u, 0.0)),
            ((u, 1.0), (1.0 - u, 1.0)),
            ((0.0, v), (0.0, 1.0 - v)),
            ((1.0, v), (1.0, 1.0 - v)),
        ] {
            let (dp, dq) = (square_to_sphere(p.0, p.1), square_to_sphere(q.0, q.1));
            assert!(close(dp, dq, 1e-15), "{p:?} {dp:?} vs {q:?} {dq:?}");
        }
    }
}

#[test]
fn harness_equal_area_jacobian_is_four_pi() {
    // |∂ω/∂u × ∂ω/∂v| by central differences, away from the kinks of the map
    // (the axes a = 0, b = 0 and the equator |a| + |b| = 1).
    let h = 1e-6;
    let mut checked = 0;
    for [u, v] in points(20_000, 2) {
        let (a, b) = (2.0 * u - 1.0, 2.0 * v - 1.0);
        if a.abs().min(b.abs()).min((a.abs() + b.abs() - 1.0).abs()) < 1e-3
            || !(h..1.0 - h).contains(&u)
            || !(h..1.0 - h).contains(&v)
        {
            continue;
        }
        let diff = |p: [f64; 3], q: [f64; 3]| [0, 1, 2].map(|k| (p[k] - q[k]) / (2.0 * h));
        let du = diff(square_to_sphere(u + h, v), square_to_sphere(u - h, v));
        let dv = diff(square_to_sphere(u, v + h), square_to_sphere(u, v - h));
        let cross = [
            du[1] * dv[2] - du[2] * dv[1],
            du[2] * dv[0] - du[0] * dv[2],
            du[0] * dv[1] - du[1] * dv[0],
        ];
        let jacobian = (cross[0].powi(2) + cross[1].powi(2) + cross[2].powi(2)).sqrt();
        assert!(
            (jacobian / (4.0 * PI) - 1.0).abs() < 1e-6,
            "({u}, {v}): {jacobian}"
        );
        checked += 1;
    }
    assert!(checked > 19_000, "{checked}");
}

#[test]
fn harness_equal_area_square_is_the_lights() {
    // An equal-area input with a distinct value in every texel, looked up with
    // nearest lookups: the light's radiance in the harness's direction of each
    // texel's centre (and 10% in from each corner) is that texel, with and
    // without a rotation. So the harness's cells are the light's cells.
    let n = 23;
    let image = EnvImage::from_fn(n, n, |i, j| [(j * n + i) as f32 + 1.0, 0.0, 0.0]).unwrap();
    for degrees in [0.0f32, 37.0] {
        let light = EnvironmentLight::new(
            image.clone(),
            LightOptions {
                lookup: Lookup::Nearest,
                mapping: Mapping::EqualArea,
                input_mapping: Mapping::EqualArea,
                rotation: Rotation::about_z_degrees(degrees),
                ..Default::default()
            },
        )
        .unwrap();
        let frame = Frame::of(&light);
        assert_eq!(SphereSampler::grid(&light).map(|g| g.cells()), Some([n, n]));
        for j in 0..n {
            for i in 0..n {
                for (du, dv) in [(0.5, 0.5), (0.1, 0.1), (0.9, 0.1), (0.1, 0.9), (0.9, 0.9)] {
                    let (u, v) = ((i as f64 + du) / n as f64, (j as f64 + dv) / n as f64);
                    let got = light.radiance(frame.world_at(u, v))[0];
                    assert_eq!(
                        got,
                        image.texel(i, j)[0],
                        "texel ({i}, {j}) at ({u}, {v}), {degrees}°"
                    );
                }
            }
        }
    }
}
