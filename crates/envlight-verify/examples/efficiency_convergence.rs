//! Which quadrature of the product sampler's efficiency is right (issue 35, item 6).
//!
//! For the irradiance integrand `g = Y·max(0, n·ω)` and the product sampler's pdf
//! `p`, the efficiency `(∫g)² / ∫g²/p dω` by
//! - (a) [`Reference::Checked`], what `envlight info --normal` reports;
//! - (b) an independent midpoint rule with `m × m` points per texel in `(u, v)`,
//!   `m = 2, 4, 8, …`, `dω = 2π² sin θ du dv`, radiance and pdf queried through
//!   the sampler's public API, and Richardson's extrapolation of the two finest
//!   levels assuming an `O(h²)` error: `(4·E(2m) − E(m)) / 3`;
//! - (c) the same midpoint rule with the radiance replaced by the value of the
//!   texel that contains the point (a nearest lookup: a different integrand, over
//!   the same pdf).
//!
//! Maps: `sunrise.exr` and `night.exr` from `../shared/envmaps/` (a line says so
//! when one is missing), box-filtered down to 256×128 and at full size, and the
//! built-in sky at both sizes; normals towards the brightest texel, up and down.
//! The midpoint levels stop before a level would take more than 2²⁷ points.
//!
//! `cargo run --release -p envlight-verify --example efficiency_convergence [-- --small-only]`

use envlight::color::luminance;
use envlight::load::{load, LoadOptions};
use envlight::{
    builtin, EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
};
use envlight_verify::{efficiency, AtShadingPoint, Reference, SphereSampler};
use rayon::prelude::*;
use std::f64::consts::PI;
use std::path::Path;
use std::sync::Arc;

/// Midpoint levels: points per texel and axis.
const LEVELS: [usize; 5] = [2, 4, 8, 16, 32];
/// No level with more points than this.
const MAX_POINTS: usize = 1 << 27;

/// The `f × f` box-filter average of `image` (`f` divides both sides).
fn box_downsample(image: &EnvImage, f: usize) -> EnvImage {
    let (w, h) = (image.width() / f, image.height() / f);
    let mut texels = vec![[0.0f32; 3]; w * h];
    for (k, t) in texels.iter_mut().enumerate() {
        let (x, y) = (k % w, k / w);
        let mut sum = [0.0f64; 3];
        for sy in 0..f {
            let row = image.row(y * f + sy);
            for texel in &row[x * f..(x + 1) * f] {
                for c in 0..3 {
                    sum[c] += texel[c] as f64;
                }
            }
        }
        *t = sum.map(|s| (s / (f * f) as f64) as f32);
    }
    EnvImage::new(w, h, texels).expect("an average of finite, non-negative texels")
}

/// `[∫g dω, ∫g²/p dω]` by the midpoint rule with `m × m` points per texel of
/// the `w × h` lat-long grid, and the number of points with `g > 0` and `p = 0`.
/// `nearest`: `Y` of the texel containing the point instead of the light's lookup.
fn midpoint(at: &AtShadingPoint, image: &EnvImage, n: Vec3, m: usize, nearest: bool) -> [f64; 3] {
    let (w, h) = (image.width(), image.height());
    let (nu, nv) = (w * m, h * m);
    let (du, dv) = (1.0 / nu as f64, 1.0 / nv as f64);
    let rows: Vec<[f64; 3]> = (0..nv)
        .into_par_iter()
        .map(|r| {
            let v = (r as f64 + 0.5) * dv;
            let (st, ct) = (PI * v).sin_cos();
            let dw = 2.0 * PI * PI * st * du * dv;
            let directions: Vec<Vec3> = (0..nu)
                .map(|c| {
                    let (sp, cp) = (2.0 * PI * (c as f64 + 0.5) * du).sin_cos();
                    Vec3::new((st * cp) as f32, (st * sp) as f32, ct as f32)
                })
                .collect();
            let mut pdf = vec![0.0f32; nu];
            at.pdf_batch(&directions, &mut pdf);
            let mut radiance = vec![[0.0f32; 3]; nu];
            if nearest {
                let texels = image.row(r / m);
                for (c, l) in radiance.iter_mut().enumerate() {
                    *l = texels[c / m];
                }
            } else {
                at.radiance_batch(&directions, &mut radiance);
            }
            let mut acc = [0.0f64; 3];
            for ((d, l), p) in directions.iter().zip(&radiance).zip(&pdf) {
                let g = luminance(*l) as f64 * n.dot(*d).max(0.0) as f64;
                if g > 0.0 {
                    acc[0] += g * dw;
                    if *p > 0.0 {
                        acc[1] += g * g / *p as f64 * dw;
                    } else {
                        acc[2] += 1.0;
                    }
                }
            }
            acc
        })
        .collect();
    rows.iter()
        .fold([0.0; 3], |a, r| [a[0] + r[0], a[1] + r[1], a[2] + r[2]])
}

/// `(∫g)² / ∫g²/p`.
fn efficiency_of([integral, second, _]: [f64; 3]) -> f64 {
    integral * integral / second
}

/// One row per normal: Checked, the midpoint levels, Richardson's extrapolation,
/// and the nearest-lookup midpoint levels' extrapolation.
fn measure(name: &str, image: &EnvImage) {
    let (w, h) = (image.width(), image.height());
    let light = Arc::new(
        EnvironmentLight::new(image.clone(), LightOptions::default())
            .expect("a finite, non-negative map"),
    );
    let sampler = ProductSampler::new(light.clone(), ProductOptions::default());
    let levels: Vec<usize> = LEVELS
        .iter()
        .copied()
        .filter(|m| w * h * m * m <= MAX_POINTS)
        .collect();
    let normals = [
        ("brightest", light.brightest().1),
        ("up", Vec3::new(0.0, 0.0, 1.0)),
        ("down", Vec3::new(0.0, 0.0, -1.0)),
    ];
    for (label, n) in normals {
        let at = AtShadingPoint::new(&sampler, Factor::cosine(n));
        let checked = efficiency(&at, &at.integrand(), Reference::Checked).efficiency;
        let mut cells = Vec::new();
        let (mut bilinear, mut nearest) = (Vec::new(), Vec::new());
        let mut unsampled = 0.0;
        for m in LEVELS {
            if !levels.contains(&m) {
                cells.push("—".to_string());
                continue;
            }
            let b = midpoint(&at, image, n, m, false);
            let e = efficiency_of(b);
            unsampled += b[2];
            bilinear.push(e);
            nearest.push(efficiency_of(midpoint(&at, image, n, m, true)));
            cells.push(format!("{e:.4}"));
        }
        let richardson = |e: &[f64]| {
            let k = e.len();
            (4.0 * e[k - 1] - e[k - 2]) / 3.0
        };
        let r = richardson(&bilinear);
        // Error ratio of successive levels: 4 for an O(h²) error.
        let k = bilinear.len();
        let ratio = if k >= 3 {
            format!(
                "{:.2}",
                (bilinear[k - 3] - bilinear[k - 2]) / (bilinear[k - 2] - bilinear[k - 1])
            )
        } else {
            "—".to_string()
        };
        let n4 = nearest[levels.iter().position(|&m| m == 4).unwrap_or(0)];
        println!(
            "| {name} | {w}×{h} | {label} | {checked:.4} | {} | {r:.4} | {:+.1e} | {ratio} | {n4:.4} | {:.4} | {unsampled} |",
            cells.join(" | "),
            r / checked - 1.0,
            richardson(&nearest),
        );
    }
}

fn main() {
    let small_only = std::env::args().any(|a| a == "--small-only");
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    let mut maps: Vec<(String, EnvImage)> = Vec::new();
    for file in ["sunrise.exr", "night.exr"] {
        match load(&dir.join(file), &LoadOptions::default()) {
            Ok(l) => maps.push((file.into(), l.image)),
            Err(e) => println!("skipping {file}: {e}"),
        }
    }
    maps.push(("builtin:sky".into(), builtin::sky(1024, 512)));
    println!(
        "| map | size | normal | Checked | mid 2×2 | 4×4 | 8×8 | 16×16 | 32×32 | Richardson | Richardson / Checked − 1 | error ratio | nearest 4×4 | nearest Richardson | lit points with p = 0 |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, image) in &maps {
        let f = image.width() / 256;
        assert!(
            f * 256 == image.width() && f * 128 == image.height(),
            "{name}: {}×{} is not an integer multiple of 256×128",
            image.width(),
            image.height()
        );
        measure(name, &box_downsample(image, f));
        if !small_only {
            measure(name, image);
        }
    }
}
