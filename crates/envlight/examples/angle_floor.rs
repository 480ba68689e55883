//! The floor under a batch `pdf` or `radiance` query: the same calls on a 1×1 map,
//! whose lookups are one cached texel, so what remains is the direction-to-image
//! angles (atan2, acos in f64) and the batch machinery. ns per direction, one
//! thread, best of 15 runs of 2²⁰ random directions.
//!
//! `RAYON_NUM_THREADS=1 cargo run --release --example angle_floor`

use envlight::light::Density;
use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Vec3};
use std::time::Instant;

fn main() {
    let n = 1 << 20;
    let mut rng = envlight::rng::SplitMix64::new(3);
    let dirs: Vec<Vec3> = (0..n)
        .map(|_| envlight::math::uniform_sphere([rng.next_f32(), rng.next_f32()]))
        .collect();
    for (density, lookup) in [
        (Density::PiecewiseConstant, Lookup::Nearest),
        (Density::PiecewiseConstant, Lookup::Bilinear),
        (Density::PiecewiseBilinear, Lookup::Bilinear),
    ] {
        let image = EnvImage::from_fn(1, 1, |_, _| [1.0; 3]).expect("a map");
        let options = LightOptions {
            density,
            lookup,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image, options).expect("a light");
        let best = |f: &mut dyn FnMut()| {
            (0..15)
                .map(|_| {
                    let t = Instant::now();
                    f();
                    t.elapsed().as_secs_f64() * 1e9 / n as f64
                })
                .fold(f64::INFINITY, f64::min)
        };
        let mut pdfs = vec![0.0f32; n];
        let mut radiance = vec![[0.0f32; 3]; n];
        let pdf = best(&mut || light.pdf_batch(&dirs, &mut pdfs));
        let rad = best(&mut || light.radiance_batch(&dirs, &mut radiance));
        println!(
            "1x1 map, {} density, {lookup:?} lookup: pdf_batch {pdf:.2} ns, radiance_batch {rad:.2} ns",
            density.name()
        );
    }
}
