//! Renders a built-in scene under an environment map with every strategy and writes
//! the labelled comparison sheet, e.g.
//!
//! ```text
//! cargo run --release -p envlight-render --example compare -- \
//!     ../shared/envmaps/sunrise.exr balls 320 180 16 compare.png [EQUAL_TIME_S] [REFERENCE_SPP]
//! ```
//!
//! `ENVLIGHT_SEED=N` picks the seed, `ENVLIGHT_REFERENCE=FILE` reuses a reference
//! render, `ENVLIGHT_DUMP=DIR` saves the reference and every render, and
//! `ENVLIGHT_STRATEGIES=mis,mis-product` renders only those strategies (a smaller
//! sheet).
//!
//! The map is read as a linear `.exr`/`.pfm` (negative texels clamped); `builtin:sky`
//! selects the procedural sky.

use envlight::{EnvImage, EnvironmentLight, LightOptions};
use envlight_render::{
    compare, read_image, write_image, CompareSettings, RenderSettings, Scene, Strategy,
};
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, default: &str| args.get(i).cloned().unwrap_or_else(|| default.into());
    let map = arg(0, "builtin:sky");
    let scene = Scene::builtin(&arg(1, "balls")).ok_or("unknown scene")?;
    let width: usize = arg(2, "320").parse()?;
    let height: usize = arg(3, "180").parse()?;
    let spp: u32 = arg(4, "16").parse()?;
    let out = arg(5, "compare.png");
    let equal_time: Option<f64> = args
        .get(6)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse())
        .transpose()?;
    let reference_spp: u32 = arg(7, "1024").parse()?;

    let image = if map == "builtin:sky" {
        envlight::builtin::sky(1024, 512)
    } else {
        let img = read_image(Path::new(&map))?;
        let (image, report) = EnvImage::from_raw(
            &map,
            img.width(),
            img.height(),
            img.pixels().to_vec(),
            false,
        )?;
        eprintln!("{map}: {} negative texels clamped", report.negative_texels);
        image
    };
    let light = EnvironmentLight::new(image, LightOptions::default())?;
    let strategies = match std::env::var("ENVLIGHT_STRATEGIES") {
        Ok(list) => list
            .split(',')
            .map(str::parse)
            .collect::<Result<Vec<Strategy>, _>>()?,
        Err(_) => Strategy::ALL.to_vec(),
    };
    let settings = CompareSettings {
        render: RenderSettings {
            seed: std::env::var("ENVLIGHT_SEED")
                .ok()
                .and_then(|s| s.parse().ok())
                .unwrap_or(0),
            width,
            height,
            spp,
            ..Default::default()
        },
        strategies,
        equal_time,
        equal_time_of_mis: true,
        reference_spp,
    };
    let progress = |stage: &str, done: u64, total: u64| {
        if done == total {
            eprintln!("{stage}: done");
        }
    };
    // Optional: ENVLIGHT_REFERENCE=FILE reuses a reference render; ENVLIGHT_DUMP=DIR
    // writes the reference (EXR) and every render (PNG) there.
    let reference = match std::env::var("ENVLIGHT_REFERENCE") {
        Ok(path) => Some((read_image(Path::new(&path))?, path)),
        Err(_) => None,
    };
    let comparison = compare(&scene, &light, &settings, reference, &progress)?;
    print!("{}", comparison.table());
    let exposure = envlight_render::auto_exposure(&comparison.reference);
    if let Ok(dir) = std::env::var("ENVLIGHT_DUMP") {
        let dir = Path::new(&dir);
        write_image(&dir.join("reference.exr"), &comparison.reference, 0.0)?;
        write_image(&dir.join("reference.png"), &comparison.reference, exposure)?;
        for e in &comparison.entries {
            let tag = match e.budget {
                envlight_render::Budget::EqualSamples => "spp",
                envlight_render::Budget::EqualTime(_) => "time",
            };
            write_image(
                &dir.join(format!("{}-{tag}.png", e.strategy)),
                &e.image,
                exposure,
            )?;
        }
    }
    comparison.write_sheet_png(Path::new(&out), exposure)?;
    eprintln!("wrote {out}");
    Ok(())
}
