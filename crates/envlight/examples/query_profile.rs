//! Runs many `pdf`, `radiance` and `sample` queries on the built-in sky, for
//! profilers (`valgrind --tool=callgrind`, `perf`): `cargo run --release --example
//! query_profile -- [pdf|radiance|sample] [N]`.

use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
use std::hint::black_box;

fn main() {
    let mut args = std::env::args().skip(1);
    let what = args.next().unwrap_or_else(|| "pdf".to_string());
    let n: u64 = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let light = EnvironmentLight::new(builtin::sky(256, 128), LightOptions::default())
        .expect("the built-in sky builds");
    let mut acc = 0.0f32;
    for k in 0..n {
        let [a, b] = envlight::rng::xi_2d(1, k);
        match what.as_str() {
            "sample" => acc += light.sample([a, b]).map_or(0.0, |s| s.pdf),
            _ => {
                let z = 1.0 - 2.0 * a;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * std::f32::consts::PI * b;
                let d = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                acc += if what == "radiance" {
                    light.radiance(black_box(d))[1]
                } else {
                    light.pdf(black_box(d))
                };
            }
        }
    }
    println!("{what} x {n}: {}", black_box(acc));
}
