//! The peer benchmarks' synthetic map (`benches/peers/mitsuba_peer.py` draws the
//! same): a sky gradient plus a 1° sun holding about 91% of the power.

use envlight::EnvImage;
use std::f64::consts::PI;

/// The peer script's map: `cos θ` sky (at least 0.05) tinted (0.4, 0.6, 1.0), and
/// a sun of 1° radius at θ = 60°, φ = 130° ten times as bright in total.
pub fn synthetic(w: usize, h: usize) -> EnvImage {
    let dir = |x: usize, y: usize| {
        let theta = PI * (y as f64 + 0.5) / h as f64;
        let phi = 2.0 * PI * (x as f64 + 0.5) / w as f64;
        (
            theta,
            [
                theta.sin() * phi.cos(),
                theta.sin() * phi.sin(),
                theta.cos(),
            ],
        )
    };
    let (t0, p0) = (60f64.to_radians(), 130f64.to_radians());
    let sun = [t0.sin() * p0.cos(), t0.sin() * p0.sin(), t0.cos()];
    let cos_radius = 1f64.to_radians().cos();
    let inside = |x, y| {
        let (_, d) = dir(x, y);
        d[0] * sun[0] + d[1] * sun[1] + d[2] * sun[2] > cos_radius
    };
    let sky = |theta: f64| theta.cos().max(0.05);
    let (mut sky_power, mut sun_area) = (0.0, 0.0);
    let texel = (2.0 * PI / w as f64) * (PI / h as f64);
    for y in 0..h {
        for x in 0..w {
            let (theta, _) = dir(x, y);
            let dw = texel * theta.sin();
            sky_power += sky(theta) * (0.4 + 0.6 + 1.0) / 3.0 * dw;
            if inside(x, y) {
                sun_area += dw;
            }
        }
    }
    let sun_value = (10.0 * sky_power / sun_area) as f32;
    EnvImage::from_fn(w, h, |x, y| {
        if inside(x, y) {
            [sun_value; 3]
        } else {
            let s = sky(dir(x, y).0) as f32;
            [0.4 * s, 0.6 * s, s]
        }
    })
    .expect("a valid map")
}
