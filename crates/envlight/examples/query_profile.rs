//! Runs many `pdf`, `radiance` and `sample` queries on the built-in sky, for
//! profilers (`valgrind --tool=callgrind`, `perf`): `cargo run --release --example
//! query_profile -- [pdf|radiance|sample] [N] [WIDTH] [hot]` (the sky is WIDTH ×
//! WIDTH/2, 256 wide by default; `hot` cycles through 4096 queries, so the data they
//! touch stays in cache, instead of drawing every query afresh).

use envlight::{builtin, EnvironmentLight, LightOptions, Vec3};
use std::hint::black_box;

fn main() {
    let mut args = std::env::args().skip(1);
    let what = args.next().unwrap_or_else(|| "pdf".to_string());
    let n: u64 = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1_000_000);
    let width: usize = args
        .next()
        .and_then(|s| s.parse().ok())
        .unwrap_or(256)
        .max(2);
    let light = EnvironmentLight::new(builtin::sky(width, width / 2), LightOptions::default())
        .expect("the built-in sky builds");
    let hot = args.next().as_deref() == Some("hot");
    let started = std::time::Instant::now();
    let mut acc = 0.0f32;
    for k in 0..n {
        let [a, b] = envlight::rng::xi_2d(1, if hot { k % 4096 } else { k });
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
    let ns = started.elapsed().as_secs_f64() * 1e9 / n.max(1) as f64;
    println!(
        "{what} x {n}: {:.1} ns per call (sum {})",
        ns,
        black_box(acc)
    );
}
