//! What crossing the C boundary costs: the C API's batch and single calls against
//! the Rust library's own, on the same light and inputs, timed in alternating
//! rounds on one thread (BENCHMARKS.md, "The C boundary").
//!
//! The C functions are called through their C ABI from this separate crate (no
//! LTO), as a C program calls them: every pointer check, conversion and
//! `catch_unwind` of the boundary is in the timed path.
//!
//! ```text
//! RAYON_NUM_THREADS=1 cargo run --release -p envlight-c --example boundary_cost -- [MAP] [--queries N] [--rounds R]
//! ```

use std::hint::black_box;
use std::time::Instant;

use envlight::{EnvironmentLight, LightOptions, Vec3};
use envlight_c::*;

/// A query's name, its Rust call and its C call.
type Row<'a> = (&'static str, Box<dyn FnMut() + 'a>, Box<dyn FnMut() + 'a>);

fn main() {
    let mut args = std::env::args().skip(1);
    let (mut map, mut queries, mut rounds) = (None, 1usize << 20, 7usize);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--queries" => {
                queries = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("--queries N")
            }
            "--rounds" => {
                rounds = args
                    .next()
                    .and_then(|v| v.parse().ok())
                    .expect("--rounds R")
            }
            _ => map = Some(a),
        }
    }
    let image = match &map {
        Some(path) => {
            envlight::load::load(path.as_ref(), &Default::default())
                .expect("a readable map")
                .image
        }
        None => envlight::builtin::sky(2048, 1024),
    };
    let (w, h) = (image.width() as u32, image.height() as u32);
    let rgb: Vec<f32> = image.texels().iter().flatten().copied().collect();
    let rust = EnvironmentLight::new(image, LightOptions::default()).expect("a light");
    let mut c = std::ptr::null_mut();
    assert_eq!(
        envlight_light_from_rgb(rgb.as_ptr(), w, h, std::ptr::null(), &mut c),
        envlight_status::ENVLIGHT_OK
    );
    let c = c as *const envlight_light;
    println!(
        "map {} ({w}x{h}), {queries} queries, {rounds} alternating rounds, {} rayon threads",
        map.as_deref().unwrap_or("builtin:sky 2048x1024"),
        rayon::current_num_threads()
    );

    let u: Vec<[f32; 2]> = (0..queries as u64)
        .map(|k| envlight::rng::xi_2d(1, k))
        .collect();
    let dirs: Vec<Vec3> = (0..queries as u64)
        .map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(2, k)))
        .collect();
    let u_flat: &[f32] = u.as_flattened();
    let d_flat: Vec<f32> = dirs.iter().flat_map(|d| d.to_array()).collect();

    let mut rust_samples = vec![None; queries];
    let mut c_samples = vec![envlight_sample::default(); queries];
    let (mut pdf, mut c_pdf) = (vec![0.0f32; queries], vec![0.0f32; queries]);
    let (mut rgb_out, mut c_rgb) = (vec![[0.0f32; 3]; queries], vec![0.0f32; 3 * queries]);
    let n = queries;

    let rows: Vec<Row<'_>> = vec![
        (
            "sample_batch",
            Box::new(|| rust.sample_batch(&u, &mut rust_samples)),
            Box::new(|| {
                envlight_light_sample_batch(c, u_flat.as_ptr(), n, c_samples.as_mut_ptr());
            }),
        ),
        (
            "pdf_batch",
            Box::new(|| rust.pdf_batch(&dirs, &mut pdf)),
            Box::new(|| {
                envlight_light_pdf_batch(c, d_flat.as_ptr(), n, c_pdf.as_mut_ptr());
            }),
        ),
        (
            "radiance_batch",
            Box::new(|| rust.radiance_batch(&dirs, &mut rgb_out)),
            Box::new(|| {
                envlight_light_radiance_batch(c, d_flat.as_ptr(), n, c_rgb.as_mut_ptr());
            }),
        ),
        (
            "sample (single)",
            Box::new(|| {
                for &x in &u {
                    black_box(rust.sample(black_box(x)));
                }
            }),
            Box::new(|| {
                let mut s = envlight_sample::default();
                for x in &u {
                    black_box(envlight_light_sample(c, black_box(x).as_ptr(), &mut s));
                    black_box(&s);
                }
            }),
        ),
        (
            "pdf (single)",
            Box::new(|| {
                for &d in &dirs {
                    black_box(rust.pdf(black_box(d)));
                }
            }),
            Box::new(|| {
                for d in d_flat.chunks_exact(3) {
                    black_box(envlight_light_pdf(c, black_box(d).as_ptr()));
                }
            }),
        ),
        (
            "radiance (single)",
            Box::new(|| {
                for &d in &dirs {
                    black_box(rust.radiance(black_box(d)));
                }
            }),
            Box::new(|| {
                let mut l = [0.0f32; 3];
                for d in d_flat.chunks_exact(3) {
                    envlight_light_radiance(c, black_box(d).as_ptr(), l.as_mut_ptr());
                    black_box(&l);
                }
            }),
        ),
    ];
    println!(
        "{:<18} {:>10} {:>10} {:>8}",
        "query", "rust ns", "C ns", "C/rust"
    );
    for (name, mut rust_call, mut c_call) in rows {
        // One warming pass each, then alternating timed passes; the best of each.
        rust_call();
        c_call();
        let (mut best_rust, mut best_c) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..rounds {
            let t = Instant::now();
            rust_call();
            best_rust = best_rust.min(t.elapsed().as_secs_f64());
            let t = Instant::now();
            c_call();
            best_c = best_c.min(t.elapsed().as_secs_f64());
        }
        let per = |s: f64| s * 1e9 / n as f64;
        println!(
            "{name:<18} {:>10.2} {:>10.2} {:>8.3}",
            per(best_rust),
            per(best_c),
            best_c / best_rust
        );
    }
    envlight_light_free(c as *mut envlight_light);
}
