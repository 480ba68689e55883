//! The cost per point of the portal light (docs/portals.md): nanoseconds per
//! `at(p)` (the per-point windows), per `sample` and per `pdf` at a point, and the
//! build time and memory, for one and two portals over a map.
//!
//! `cargo run --release -p envlight --example portal_cost [MAP]` (default: the
//! shared sunrise.exr when present, else the builtin sky).

use envlight::portal::{Portal, PortalLight, PortalOptions};
use envlight::{EnvironmentLight, LightOptions, Vec3};
use std::hint::black_box;
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let path = std::env::args()
        .nth(1)
        .map(std::path::PathBuf::from)
        .or_else(|| {
            let p = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../../shared/envmaps/sunrise.exr");
            p.is_file().then_some(p)
        });
    let image = match &path {
        Some(p) => {
            envlight::load::load(p, &Default::default())
                .expect("readable map")
                .image
        }
        None => envlight::builtin::sky(1024, 512),
    };
    let name = path.map_or("builtin:sky 1024x512".to_string(), |p| {
        p.display().to_string()
    });
    let light = Arc::new(EnvironmentLight::new(image, LightOptions::default()).unwrap());
    let v = Vec3::new;
    let window = [
        v(4.0, 1.0, 0.8),
        v(4.0, 2.2, 0.8),
        v(4.0, 2.2, 1.9),
        v(4.0, 1.0, 1.9),
    ];
    let skylight = [
        v(1.2, 1.0, 2.5),
        v(2.4, 1.0, 2.5),
        v(2.4, 2.0, 2.5),
        v(1.2, 2.0, 2.5),
    ];
    println!("map: {name}");
    // The default resolution (the map's height), and the preview renderer's 128.
    for (corners, resolution) in [
        (vec![window], None),
        (vec![window, skylight], None),
        (vec![window, skylight], Some(128)),
    ] {
        let quads: Vec<Portal> = corners.iter().map(|&c| Portal::new(c).unwrap()).collect();
        let start = Instant::now();
        let pl = PortalLight::new(light.clone(), &quads, PortalOptions { resolution }).unwrap();
        // Tables are built for the side a point is on, the first time one asks.
        black_box(pl.at(v(2.0, 1.5, 1.2)));
        let build = start.elapsed().as_secs_f64();
        let n = 1_000_000u64;
        let points: Vec<Vec3> = (0..1024)
            .map(|k| {
                let [a, b] = envlight::rng::xi_2d(11, k);
                v(0.2 + 3.6 * a, 0.2 + 2.6 * b, 1.0)
            })
            .collect();
        let time = |f: &dyn Fn(u64) -> f32| {
            let start = Instant::now();
            let mut acc = 0.0f32;
            for k in 0..n {
                acc += f(k);
            }
            black_box(acc);
            start.elapsed().as_secs_f64() * 1e9 / n as f64
        };
        let at = time(&|k| pl.at(points[(k & 1023) as usize]).power() as f32);
        let sample = time(&|k| {
            let p = pl.at(points[(k & 1023) as usize]);
            p.sample(envlight::rng::xi_2d(3, k)).map_or(0.0, |s| s.pdf)
        }) - at;
        let dirs: Vec<Vec3> = (0..1024)
            .map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(5, k)))
            .collect();
        let at_point = pl.at(v(2.0, 1.5, 1.2));
        let pdf = time(&|k| at_point.pdf(dirs[(k & 1023) as usize]));
        // Directions through the portals (the pdf's full path: intersection, table).
        let through: Vec<Vec3> = (0..1024)
            .filter_map(|k| {
                at_point
                    .sample(envlight::rng::xi_2d(9, k))
                    .map(|s| s.direction)
            })
            .collect();
        let pdf_through = time(&|k| at_point.pdf(through[(k as usize) % through.len()]));
        let light_pdf = time(&|k| light.pdf(dirs[(k & 1023) as usize]));
        println!(
            "{} portal(s), n = {}: build {:.0} ms, {:.1} MiB; per point at(p) {at:.0} ns, \
             sample {sample:.0} ns (incl. its pdf), pdf {pdf:.0} ns for uniform directions, \
             {pdf_through:.0} ns through a portal (the light's own pdf {light_pdf:.0} ns)",
            quads.len(),
            pl.resolution(),
            build * 1e3,
            pl.memory_bytes() as f64 / (1 << 20) as f64
        );
    }
}
