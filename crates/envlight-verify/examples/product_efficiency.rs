//! The efficiency table of product sampling (issue 16): for every shared map,
//! several normals and both densities, the efficiency `(∫g)² / ∫g²/p` of the
//! irradiance integrand `g = Y·max(0, n·ω)` with the product sampler's pdf and
//! with the light's own, next to the light's own efficiency for `Y` alone.
//!
//! `cargo run --release -p envlight-verify --example product_efficiency [-- --patches PW,PH] [--grid N] [--random N] [--equal-area]`
//! (maps from `../shared/envmaps/`, plus `builtin:sky`).

use envlight::light::{Density, Mapping};
use envlight::{
    builtin, EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler,
};
use envlight_verify::{efficiency, maps, product_normals, AtShadingPoint, Integrand, Reference};
use std::sync::Arc;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let patches = match args.iter().position(|a| a == "--patches") {
        Some(k) => {
            let v: Vec<usize> = args
                .get(k + 1)
                .ok_or("--patches PW,PH")?
                .split(',')
                .map(str::parse)
                .collect::<Result<_, _>>()?;
            Some([v[0], v[1]])
        }
        None => None,
    };
    let normal_grid = match args.iter().position(|a| a == "--grid") {
        Some(k) => Some(args.get(k + 1).ok_or("--grid N")?.parse::<usize>()?),
        None => None,
    };
    let random = match args.iter().position(|a| a == "--random") {
        Some(k) => args.get(k + 1).ok_or("--random N")?.parse::<usize>()?,
        None => 0,
    };
    let mapping = if args.iter().any(|a| a == "--equal-area") {
        Mapping::EqualArea
    } else {
        Mapping::Equirectangular
    };
    let only: Option<Vec<String>> = std::env::var("MAPS")
        .ok()
        .map(|m| m.split(',').map(String::from).collect());
    let wanted: Vec<&str> = maps::SHARED
        .into_iter()
        .filter(|file| only.as_ref().is_none_or(|o| o.iter().any(|x| x == file)))
        .collect();
    let mut maps: Vec<(String, EnvImage)> = vec![("builtin:sky".into(), builtin::sky(1024, 512))];
    maps.extend(maps::shared(&wanted));
    println!(
        "| map | density | normal | own eff. (Y) | product eff. (Y·cos⁺) | light eff. (Y·cos⁺) | product / own | variance gain |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut worst = f64::INFINITY;
    for (name, image) in &maps {
        for density in [Density::PiecewiseConstant, Density::PiecewiseBilinear] {
            let light = Arc::new(EnvironmentLight::new(
                image.clone(),
                LightOptions {
                    density,
                    mapping,
                    ..Default::default()
                },
            )?);
            let own =
                efficiency(light.as_ref(), &Integrand::luminance(), Reference::Checked).efficiency;
            let sampler = ProductSampler::new(
                light.clone(),
                ProductOptions {
                    patches,
                    normal_grid,
                    ..Default::default()
                },
            );
            let normals = product_normals(&light, random);
            for (label, n) in normals {
                let at = AtShadingPoint::new(&sampler, Factor::cosine(n));
                let g = at.integrand();
                let product = efficiency(&at, &g, Reference::Checked).efficiency;
                let alone = efficiency(light.as_ref(), &g, Reference::Checked).efficiency;
                let ratio = product / own;
                worst = worst.min(ratio);
                let gain = (1.0 / alone - 1.0) / (1.0 / product - 1.0);
                println!(
                    "| {name} | {} | {label} | {own:.3} | {product:.3} | {alone:.3} | {ratio:.3} | {gain:.1}x |",
                    density.name()
                );
            }
        }
    }
    println!("\nsmallest product / own efficiency: {worst:.3} (target ≥ 0.85)");
    Ok(())
}
