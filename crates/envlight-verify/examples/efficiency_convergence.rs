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

use envlight::{
    builtin, EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
};
use envlight_verify::{efficiency, maps, midpoint_moments, AtShadingPoint, Reference};
use std::sync::Arc;

/// Midpoint levels: points per texel and axis.
const LEVELS: [usize; 5] = [2, 4, 8, 16, 32];
/// No level with more points than this.
const MAX_POINTS: usize = 1 << 27;

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
        let mut unsampled = 0;
        for m in LEVELS {
            if !levels.contains(&m) {
                cells.push("—".to_string());
                continue;
            }
            let b = midpoint_moments(&at, [w, h], n, m, None);
            let e = b.efficiency();
            unsampled += b.unsampled;
            bilinear.push(e);
            nearest.push(midpoint_moments(&at, [w, h], n, m, Some(image)).efficiency());
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
    let mut maps = maps::shared(&["sunrise.exr", "night.exr"]);
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
        measure(name, &maps::box_filter(image, f));
        if !small_only {
            measure(name, image);
        }
    }
}
