//! The efficiency table of product sampling (issue 16): for every shared map,
//! several normals and both densities, the efficiency `(∫g)² / ∫g²/p` of the
//! irradiance integrand `g = Y·max(0, n·ω)` with the product sampler's pdf and
//! with the light's own, next to the light's own efficiency for `Y` alone.
//!
//! `cargo run --release -p envlight-verify --example product_efficiency [-- --patches PW,PH] [--grid N] [--random N] [--equal-area] [--glossy A,B,..]`
//! (maps from `../shared/envmaps/`, plus `builtin:sky`).
//!
//! With `--glossy`, the table is for the glossy integrand `Y·cos⁺·D` instead (the
//! GGX lobe proxy of each roughness `α`, docs/design.md §6a), seen from the direction
//! that puts the brightest texel at the lobe's centre (its mirror image about the
//! normal) where that direction is above the surface, else from 45° off the
//! normal: the product's efficiency and the light's own for the same integrand.

use envlight::light::{Density, Mapping};
use envlight::{
    builtin, EnvImage, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
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
    let glossy: Vec<f32> = match args.iter().position(|a| a == "--glossy") {
        Some(k) => args
            .get(k + 1)
            .ok_or("--glossy A,B,..")?
            .split(',')
            .map(str::parse)
            .collect::<Result<_, _>>()?,
        None => Vec::new(),
    };
    let options = Options {
        patches,
        normal_grid,
        mapping,
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
    if !glossy.is_empty() {
        return glossy_table(&maps, &glossy, &options, random);
    }
    println!(
        "| map | density | normal | own eff. (Y) | product eff. (Y·cos⁺) | light eff. (Y·cos⁺) | product / own | variance gain |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut worst = f64::INFINITY;
    for (name, image) in &maps {
        for density in [Density::PiecewiseConstant, Density::PiecewiseBilinear] {
            let (light, sampler) = light_and_sampler(image, density, &options)?;
            let own =
                efficiency(light.as_ref(), &Integrand::luminance(), Reference::Checked).efficiency;
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

/// The `--glossy` table: for each map, density, normal and roughness, the
/// efficiency for `Y·cos⁺·D` of the product sampler and of the light's own.
fn glossy_table(
    maps: &[(String, EnvImage)],
    roughness: &[f32],
    options: &Options,
    random: usize,
) -> Result<(), Box<dyn std::error::Error>> {
    println!("| map | density | normal | α | product eff. (Y·cos⁺·D) | light eff. | gain |");
    println!("|---|---|---|---|---|---|---|");
    let mut worst = vec![f64::INFINITY; roughness.len()];
    for (name, image) in maps {
        for density in [Density::PiecewiseConstant, Density::PiecewiseBilinear] {
            let (light, sampler) = light_and_sampler(image, density, options)?;
            let sun = light.brightest().1;
            for (label, n) in product_normals(&light, random) {
                let outgoing = highlight_view(n, sun);
                for (r, &alpha) in roughness.iter().enumerate() {
                    let at = AtShadingPoint::new(&sampler, Factor::glossy(n, outgoing, alpha));
                    if !at.samples_anything() {
                        continue;
                    }
                    let g = at.integrand();
                    let product = efficiency(&at, &g, Reference::Checked).efficiency;
                    let alone = efficiency(light.as_ref(), &g, Reference::Checked).efficiency;
                    worst[r] = worst[r].min(product);
                    println!(
                        "| {name} | {} | {label} | {alpha} | {product:.3} | {alone:.3} | {:.1}x |",
                        density.name(),
                        product / alone
                    );
                }
            }
        }
    }
    for (alpha, worst) in roughness.iter().zip(worst) {
        println!("α = {alpha}: smallest product efficiency {worst:.3}");
    }
    Ok(())
}

/// The viewing direction whose mirror direction about `n` is `sun` when the sun is
/// above the surface (the highlight), else one 45° off `n`.
fn highlight_view(n: Vec3, sun: Vec3) -> Vec3 {
    let c = n.dot(sun);
    if c > 0.05 {
        // reflect(sun) = 2 (n·s) n - s.
        let r = Vec3::new(
            2.0 * c * n.x - sun.x,
            2.0 * c * n.y - sun.y,
            2.0 * c * n.z - sun.z,
        );
        return r.normalized().unwrap_or(n);
    }
    let side = if n.z.abs() < 0.9 {
        Vec3::new(0.0, 0.0, 1.0)
    } else {
        Vec3::new(1.0, 0.0, 0.0)
    };
    let t = side.cross(n).normalized().unwrap_or(side);
    Vec3::new(n.x + t.x, n.y + t.y, n.z + t.z)
        .normalized()
        .unwrap_or(n)
}

/// The light and product options the tables are made with.
struct Options {
    patches: Option<[usize; 2]>,
    normal_grid: Option<usize>,
    mapping: Mapping,
}

/// The light of `image` with `density` and its product sampler, as `options` say.
fn light_and_sampler(
    image: &EnvImage,
    density: Density,
    options: &Options,
) -> Result<(Arc<EnvironmentLight>, ProductSampler), Box<dyn std::error::Error>> {
    let light = Arc::new(EnvironmentLight::new(
        image.clone(),
        LightOptions {
            density,
            mapping: options.mapping,
            ..Default::default()
        },
    )?);
    let sampler = ProductSampler::new(
        light.clone(),
        ProductOptions {
            patches: options.patches,
            normal_grid: options.normal_grid,
            ..Default::default()
        },
    );
    Ok((light, sampler))
}
