//! Where one strategy beats another: the per-pixel ratio of their squared errors
//! against a reference, as a heat map, and the errors split by what the pixel sees
//! (sky, sunlit, facing away from the sun, in the sun's shadow), e.g.
//!
//! ```text
//! cargo run --release -p envlight-render --example error_ratio -- \
//!     ../shared/envmaps/sunrise.exr diffuse ref.exr ratio.png \
//!     mis-product-s0.exr,mis-product-s1.exr mis-s0.exr,mis-s1.exr [TIME_RATIO] [LABEL_A,LABEL_B]
//! ```
//!
//! `ENVLIGHT_ROTATE=DEG` rotates the map about +z as `--rotate` does (it only moves
//! the sun the pixels are classified by).
//!
//! `A` and `B` are comma-separated renders (`.exr`/`.pfm`, one per seed, same
//! samples per pixel) of two strategies; each pixel's squared error is averaged over
//! channels and seeds, then box-blurred (9 × 9 pixels) before the ratio is taken, as
//! a single pixel's ratio over a few seeds is mostly noise. `TIME_RATIO` (time per
//! sample of `A` over `B`, default 1) turns the equal-sample ratio into the
//! equal-time one: for unbiased estimators the squared error falls as 1/samples.
//!
//! "The sun" is the light's brightest texel; a pixel is classified by its centre's
//! camera ray: `sky` (no hit), `away` (the surface faces away from the sun),
//! `shadow` (faces it, but the shadow ray towards it is blocked) or `sunlit`.
//! Prints, per class, the pixel count, both mean squared errors, their ratio and
//! each class's share of `B`'s total squared error.

use envlight::{EnvImage, EnvironmentLight, LightOptions, Rotation, Vec3};
use envlight_render::font::Canvas;
use envlight_render::{auto_exposure, read_image, Image, Ray, Scene};
use std::path::Path;

/// Pixel classes, in print order.
const CLASSES: [&str; 4] = ["sky", "sunlit", "away", "shadow"];

/// Half-width of the box blur applied to the squared-error maps.
const BLUR: usize = 4;

/// Stops of the colour scale each way from a ratio of 1.
const STOPS: f64 = 3.0;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 6 {
        return Err(
            "usage: error_ratio MAP SCENE REFERENCE OUT.png A1,A2,.. B1,B2,.. \
                    [TIME_RATIO] [LABEL_A,LABEL_B]"
                .into(),
        );
    }
    let light = load_light(&args[0])?;
    let scene = Scene::builtin(&args[1]).ok_or("unknown scene")?;
    let reference = read_image(Path::new(&args[2]))?;
    let out = &args[3];
    let a = squared_errors(&args[4], &reference)?;
    let b = squared_errors(&args[5], &reference)?;
    let time_ratio: f64 = args.get(6).map_or(Ok(1.0), |s| s.parse())?;
    let labels: Vec<String> = args
        .get(7)
        .map_or("A,B", String::as_str)
        .split(',')
        .map(str::to_string)
        .collect();
    let (w, h) = (reference.width(), reference.height());
    let sun = light.brightest().1;
    let class = classify(&scene, sun, w, h);

    println!(
        "{} vs {} (time per sample ratio {time_ratio:.3}); sun at {:?}",
        labels[0],
        labels.get(1).map_or("B", |s| s.as_str()),
        sun.to_array()
    );
    println!(
        "{:<8} {:>7} {:>11} {:>11} {:>9} {:>10} {:>10}",
        "class", "pixels", "MSE A", "MSE B", "A/B spp", "A/B time", "share of B"
    );
    let total_b: f64 = b.iter().sum();
    let row = |name: &str, pick: &dyn Fn(usize) -> bool| {
        let (mut n, mut sa, mut sb) = (0usize, 0.0f64, 0.0f64);
        for i in 0..w * h {
            if pick(i) {
                n += 1;
                sa += a[i];
                sb += b[i];
            }
        }
        let ratio = sa / sb;
        println!(
            "{:<8} {:>7} {:>11.4e} {:>11.4e} {:>9.3} {:>10.3} {:>9.1}%",
            name,
            n,
            sa / n.max(1) as f64,
            sb / n.max(1) as f64,
            ratio,
            ratio * time_ratio,
            100.0 * sb / total_b
        );
    };
    for (k, name) in CLASSES.iter().enumerate() {
        row(name, &|i| class[i] == k);
    }
    row("all", &|_| true);

    // Panels: the reference, the ratio at equal samples and at equal time.
    let (ba, bb) = (blur(&a, w, h), blur(&b, w, h));
    let ratio: Vec<f64> = ba.iter().zip(&bb).map(|(x, y)| x / y).collect();
    let gap = 4;
    let band = 22;
    let legend = 40;
    let mut canvas = Canvas::new(3 * w + 4 * gap, h + band + legend + 2 * gap, [24; 3]);
    let white = [235u8; 3];
    canvas.blit(
        gap,
        gap,
        w,
        h,
        &reference.to_srgb8(auto_exposure(&reference)),
    );
    let samples = heat(&ratio, 1.0);
    let time = heat(&ratio, time_ratio);
    canvas.blit(2 * gap + w, gap, w, h, &samples);
    canvas.blit(3 * gap + 2 * w, gap, w, h, &time);
    let (la, lb) = (&labels[0], labels.get(1).map_or("B", |s| s.as_str()));
    canvas.text(gap + 2, gap + h + 4, "reference", 1, white);
    canvas.text(
        2 * gap + w + 2,
        gap + h + 4,
        &format!("MSE {la} / {lb}, equal samples"),
        1,
        white,
    );
    canvas.text(
        3 * gap + 2 * w + 2,
        gap + h + 4,
        &format!("equal time (x{time_ratio:.2} per sample)"),
        1,
        white,
    );
    // The colour scale, log2 of the ratio from -STOPS to +STOPS.
    let (lx, ly, lw) = (2 * gap + w, 2 * gap + h + band, 2 * w);
    let scale: Vec<u8> = (0..lw * 10)
        .flat_map(|i| {
            let t = (i % lw) as f64 / (lw - 1) as f64;
            color((2.0 * t - 1.0) * STOPS)
        })
        .collect();
    canvas.blit(lx, ly, lw, 10, &scale);
    for k in 0..=(2 * STOPS as usize) {
        let stops = k as f64 - STOPS;
        let x = lx + ((k as f64 / (2.0 * STOPS)) * (lw - 1) as f64) as usize;
        let text = if stops == 0.0 {
            "1".to_string()
        } else if stops > 0.0 {
            format!("{}", 2f64.powf(stops))
        } else {
            format!("1/{}", 2f64.powf(-stops))
        };
        canvas.text(
            x.saturating_sub(4).min(lx + lw - 24),
            ly + 13,
            &text,
            1,
            white,
        );
    }
    canvas.text(
        gap + 2,
        ly + 2,
        &format!("blue: {la} better"),
        1,
        [120, 160, 255],
    );
    canvas.text(
        gap + 2,
        ly + 13,
        &format!("red: {lb} better"),
        1,
        [255, 120, 110],
    );
    image::RgbImage::from_raw(canvas.width as u32, canvas.height as u32, canvas.rgb)
        .ok_or("canvas size")?
        .save(out)?;
    eprintln!("wrote {out}");
    Ok(())
}

/// The map as a light with the default options (negative texels clamped), or the
/// procedural sky for `builtin:sky`.
fn load_light(map: &str) -> Result<EnvironmentLight, Box<dyn std::error::Error>> {
    let image = if map == "builtin:sky" {
        envlight::builtin::sky(1024, 512)
    } else {
        let img = read_image(Path::new(map))?;
        EnvImage::from_raw(map, img.width(), img.height(), img.pixels().to_vec(), false)?.0
    };
    let degrees: f32 = std::env::var("ENVLIGHT_ROTATE").map_or(Ok(0.0), |s| s.parse())?;
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(degrees),
        ..Default::default()
    };
    Ok(EnvironmentLight::new(image, options)?)
}

/// Per pixel, the squared error against `reference` averaged over channels and over
/// the comma-separated renders of `list`.
fn squared_errors(list: &str, reference: &Image) -> Result<Vec<f64>, Box<dyn std::error::Error>> {
    let paths: Vec<&str> = list.split(',').collect();
    let mut sum = vec![0.0f64; reference.pixels().len()];
    for path in &paths {
        let image = read_image(Path::new(path))?;
        if (image.width(), image.height()) != (reference.width(), reference.height()) {
            return Err(format!("{path}: not the reference's size").into());
        }
        for ((s, p), r) in sum.iter_mut().zip(image.pixels()).zip(reference.pixels()) {
            for c in 0..3 {
                *s += (p[c] as f64 - r[c] as f64).powi(2);
            }
        }
    }
    let n = 3.0 * paths.len() as f64;
    Ok(sum.into_iter().map(|s| s / n).collect())
}

/// The class (index into [`CLASSES`]) of every pixel, from its centre's camera ray.
fn classify(scene: &Scene, sun: Vec3, w: usize, h: usize) -> Vec<usize> {
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let ray = scene.camera.ray(x as f32 + 0.5, y as f32 + 0.5, w, h);
            out.push(match scene.intersect(&ray, f32::INFINITY) {
                None => 0,
                Some(hit) => {
                    // The side facing the viewer, as the integrator shades it.
                    let n = if hit.normal.dot(ray.direction) > 0.0 {
                        -hit.normal
                    } else {
                        hit.normal
                    };
                    if n.dot(sun) <= 0.0 {
                        2
                    } else if scene.occluded(&Ray::spawn(hit.point, n, sun)) {
                        3
                    } else {
                        1
                    }
                }
            });
        }
    }
    out
}

/// A `(2 BLUR + 1)²` box blur, clamped at the edges.
fn blur(values: &[f64], w: usize, h: usize) -> Vec<f64> {
    let mut out = vec![0.0; w * h];
    for y in 0..h {
        for x in 0..w {
            let (mut s, mut n) = (0.0, 0.0);
            for yy in y.saturating_sub(BLUR)..(y + BLUR + 1).min(h) {
                for xx in x.saturating_sub(BLUR)..(x + BLUR + 1).min(w) {
                    s += values[yy * w + xx];
                    n += 1.0;
                }
            }
            out[y * w + x] = s / n;
        }
    }
    out
}

/// The heat map of `ratio × factor`, log2 scale (see [`color`]); black where the
/// ratio is undefined (both errors 0).
fn heat(ratio: &[f64], factor: f64) -> Vec<u8> {
    ratio
        .iter()
        .flat_map(|&r| {
            let r = r * factor;
            if r.is_finite() && r > 0.0 {
                color(r.log2())
            } else {
                [0, 0, 0]
            }
        })
        .collect()
}

/// A diverging colour for `stops = log2(ratio)`: white at 0, blue below (the first
/// strategy better), red above, saturated at ±[`STOPS`].
fn color(stops: f64) -> [u8; 3] {
    let t = (stops / STOPS).clamp(-1.0, 1.0);
    let fade = |c: f64| (255.0 * (1.0 - t.abs() * (1.0 - c))) as u8;
    if t < 0.0 {
        [fade(0.15), fade(0.35), fade(0.95)]
    } else {
        [fade(0.9), fade(0.15), fade(0.1)]
    }
}
