//! Synthetic maps that exercise the checks: smooth, constant, one hot texel,
//! random with black holes, extreme dynamic range, black. Each is a pure function
//! of its arguments, so every test and front end that uses them sees the same map.

use envlight::EnvImage;

/// `[0.8, 1.0, 1.2]` everywhere.
pub fn constant(w: usize, h: usize) -> EnvImage {
    from_fn(w, h, |_, _| [0.8, 1.0, 1.2])
}

/// Smooth in u (periodic) and v, never zero, with the three channels differing.
pub fn gradient(w: usize, h: usize) -> EnvImage {
    from_fn(w, h, |x, y| {
        let u = (x as f32 + 0.5) / w as f32;
        let v = (y as f32 + 0.5) / h as f32;
        let phase = (2.0 * std::f32::consts::PI * u).cos();
        [1.0 + 0.9 * phase, 0.2 + 3.0 * v * v, 0.5 + u]
    })
}

/// Black except texel `(hx, hy)`, which is `[40, 30, 20]`.
pub fn hot(w: usize, h: usize, hx: usize, hy: usize) -> EnvImage {
    from_fn(w, h, |x, y| {
        if (x, y) == (hx, hy) {
            [40.0, 30.0, 20.0]
        } else {
            [0.0; 3]
        }
    })
}

/// Log-uniform values over 1e-3..1e3 per channel, a third of the texels exactly
/// black, from a fixed seed.
pub fn random(w: usize, h: usize, seed: u64) -> EnvImage {
    let mut rng = envlight::rng::SplitMix64::new(seed);
    from_fn(w, h, |_, _| {
        if rng.next_f32() < 1.0 / 3.0 {
            [0.0; 3]
        } else {
            [(); 3].map(|_| 10f32.powf(6.0 * rng.next_f32() - 3.0))
        }
    })
}

/// One texel at 1e30 (at `(w/3, h/2)`), all others 1e-30.
pub fn huge_range(w: usize, h: usize) -> EnvImage {
    from_fn(w, h, |x, y| {
        if (x, y) == (w / 3, h / 2) {
            [1e30; 3]
        } else {
            [1e-30; 3]
        }
    })
}

/// All black.
pub fn black(w: usize, h: usize) -> EnvImage {
    from_fn(w, h, |_, _| [0.0; 3])
}

/// # Panics
/// For a size [`EnvImage::from_fn`] refuses (zero or above its limit).
fn from_fn(w: usize, h: usize, f: impl FnMut(usize, usize) -> [f32; 3]) -> EnvImage {
    match EnvImage::from_fn(w, h, f) {
        Ok(image) => image,
        Err(e) => panic!("synthetic map {w}x{h}: {e}"),
    }
}

/// The real maps in the repository's `shared/envmaps` (with their licences there).
pub const SHARED: [&str; 6] = [
    "sunrise.exr",
    "city.exr",
    "studio.exr",
    "courtyard.exr",
    "night.exr",
    "colorful_studio_2k.hdr",
];

/// The maps `files` of `shared/envmaps` that can be read, by file name; one
/// printed line for each that cannot (the directory is beside the repository,
/// and absent on some machines).
pub fn shared(files: &[&str]) -> Vec<(String, EnvImage)> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    let options = envlight::load::LoadOptions::default();
    files
        .iter()
        .filter_map(
            |file| match envlight::load::load(&dir.join(file), &options) {
                Ok(l) => Some((file.to_string(), l.image)),
                Err(e) => {
                    println!("skipping {file}: {e}");
                    None
                }
            },
        )
        .collect()
}

/// The `f × f` box-filter average of `image` (`f` divides both sides).
pub fn box_filter(image: &EnvImage, f: usize) -> EnvImage {
    let (w, h) = (image.width() / f, image.height() / f);
    from_fn(w, h, |x, y| {
        let mut sum = [0.0f64; 3];
        for sy in 0..f {
            for texel in &image.row(y * f + sy)[x * f..(x + 1) * f] {
                for (s, &t) in sum.iter_mut().zip(texel) {
                    *s += t as f64;
                }
            }
        }
        sum.map(|s| (s / (f * f) as f64) as f32)
    })
}

/// The folder of real maps, `shared/envmaps` beside the repository's workspace,
/// when it is there; `None`, saying so on stdout, when it is not (the real maps
/// are optional: tests over them skip).
pub fn shared_envmaps() -> Option<std::path::PathBuf> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    if dir.is_dir() {
        Some(dir)
    } else {
        println!(
            "skipped: {} not found (the real maps are optional)",
            dir.display()
        );
        None
    }
}
