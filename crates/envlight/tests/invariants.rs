//! docs/design.md §5 over every sampler and map: one line per case in the tables below,
//! the checks themselves in the `envlight-verify` crate.
//!
//! Statistics (stated once for all cases, see `envlight_verify::Config`): chi-square at
//! significance α = 1e-3 with 1M samples (500k for real maps), consistency over 200k
//! samples, unbiasedness at 4 standard errors with 1M samples (500k for real maps).
//! All seeds are fixed, so every run gives the same figures; run with
//! `cargo test --release -p envlight --test invariants -- --nocapture` to see them.
//!
//! The `broken_*` tests wrap the light in deliberately wrong samplers and assert that
//! the harness rejects each of them: they prove the checks can fail.

use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation, Vec3};
use envlight_verify::maps::{black, constant, gradient, hot, huge_range, random};
use envlight_verify::{
    self as verify, Config, Grid, Integrand, SphereSample, SphereSampler, ALPHA,
};
use std::path::{Path, PathBuf};

// ---------------------------------------------------------------------------
// Lights over the synthetic maps of `envlight_verify::maps`.
// ---------------------------------------------------------------------------

/// A light over `image` with `lookup` and the piecewise-constant density (the
/// checks below that name no density are about it; the bilinear one, the
/// default, has its own cases in the table further down).
fn light(image: EnvImage, lookup: Lookup) -> EnvironmentLight {
    EnvironmentLight::new(
        image,
        LightOptions {
            lookup,
            density: Density::PiecewiseConstant,
            ..Default::default()
        },
    )
    .unwrap()
}

fn rotated(image: EnvImage, lookup: Lookup, degrees: f32) -> EnvironmentLight {
    EnvironmentLight::new(
        image,
        LightOptions {
            lookup,
            rotation: Rotation::about_z_degrees(degrees),
            density: Density::PiecewiseConstant,
            ..Default::default()
        },
    )
    .unwrap()
}

use Lookup::{Bilinear, Nearest, Node};

// ---------------------------------------------------------------------------
// Every sampler, density and mapping of the light (issue 5): the same checks,
// one line per combination in the table below.
// ---------------------------------------------------------------------------

/// A light with the given sampler, density and mapping (rotated when `degrees` ≠ 0).
fn combo(
    image: EnvImage,
    lookup: Lookup,
    sampler: Sampler,
    density: Density,
    mapping: Mapping,
    degrees: f32,
) -> EnvironmentLight {
    EnvironmentLight::new(
        image,
        LightOptions {
            lookup,
            sampler,
            density,
            mapping,
            rotation: Rotation::about_z_degrees(degrees),
            ..Default::default()
        },
    )
    .unwrap()
}

use envlight::light::{Density, Mapping, Sampler};
use Density::{PiecewiseBilinear, PiecewiseConstant};
use Mapping::{EqualArea, Equirectangular};
use Sampler::{Alias, Hierarchical, Inversion};

/// Every check of docs/design.md §5.
const FULL: Config = Config::SYNTHETIC;

/// Huge dynamic range: the 1e-30 texels have a pdf near 1e-60, below the smallest
/// f32, so `pdf()` is 0 where `L > 0` there. That is a limit of f32 densities, not a
/// sampling error (those texels carry 1e-60 of the light); support and the
/// efficiency figures (infinite `∫Y²/p`, so 0, for the same reason) are not
/// checked, everything else is.
const HUGE_RANGE: Config = Config {
    support: false,
    efficiency: false,
    ..Config::SYNTHETIC
};

/// One `#[test]` per line: `name: sampler, config;`.
macro_rules! invariant_cases {
    ($($name:ident: $sampler:expr, $cfg:expr;)*) => {$(
        #[test]
        fn $name() {
            let sampler = $sampler;
            verify::assert_invariants(stringify!($name), &sampler, &Integrand::luminance(), &$cfg);
        }
    )*};
}

invariant_cases! {
    constant_nearest:              light(constant(64, 32), Nearest), FULL;
    constant_bilinear:             light(constant(64, 32), Bilinear), FULL;
    gradient_nearest:              light(gradient(64, 32), Nearest), FULL;
    gradient_bilinear:             light(gradient(64, 32), Bilinear), FULL;
    hot_middle_nearest:            light(hot(64, 32, 27, 13), Nearest), FULL;
    hot_middle_bilinear:           light(hot(64, 32, 27, 13), Bilinear), FULL;
    hot_top_row_nearest:           light(hot(64, 32, 20, 0), Nearest), FULL;
    hot_top_row_bilinear:          light(hot(64, 32, 20, 0), Bilinear), FULL;
    hot_bottom_row_nearest:        light(hot(64, 32, 41, 31), Nearest), FULL;
    hot_bottom_row_bilinear:       light(hot(64, 32, 41, 31), Bilinear), FULL;
    hot_seam_first_col_nearest:    light(hot(64, 32, 0, 10), Nearest), FULL;
    hot_seam_first_col_bilinear:   light(hot(64, 32, 0, 10), Bilinear), FULL;
    hot_seam_last_col_nearest:     light(hot(64, 32, 63, 20), Nearest), FULL;
    hot_seam_last_col_bilinear:    light(hot(64, 32, 63, 20), Bilinear), FULL;
    random_91x37_nearest:          light(random(91, 37, 91), Nearest), FULL;
    random_91x37_bilinear:         light(random(91, 37, 91), Bilinear), FULL;
    one_texel_nearest:             light(constant(1, 1), Nearest), FULL;
    one_texel_bilinear:            light(constant(1, 1), Bilinear), FULL;
    wide_16384x1_nearest:          light(gradient(16384, 1), Nearest), FULL;
    wide_16384x1_bilinear:         light(gradient(16384, 1), Bilinear), FULL;
    tall_1x4096_nearest:           light(gradient(1, 4096), Nearest), FULL;
    tall_1x4096_bilinear:          light(gradient(1, 4096), Bilinear), FULL;
    huge_range_nearest:            light(huge_range(32, 16), Nearest), HUGE_RANGE;
    huge_range_bilinear:           light(huge_range(32, 16), Bilinear), HUGE_RANGE;
    rotated_random_nearest:        rotated(random(48, 24, 7), Nearest, 37.0), FULL;
    rotated_random_bilinear:       rotated(random(48, 24, 7), Bilinear, 37.0), FULL;
    rotated_hot_seam_bilinear:     rotated(hot(64, 32, 63, 9), Bilinear, 37.0), FULL;
    builtin_sky_bilinear:          light(envlight::builtin::sky(256, 128), Bilinear), FULL;
    // The node lookup (Mitsuba envmap's rows as nodes from pole to pole) and the
    // importance that follows it: every check, the edge rows and the seam included.
    constant_node:                 light(constant(64, 32), Node), FULL;
    gradient_node:                 light(gradient(64, 32), Node), FULL;
    hot_middle_node:               light(hot(64, 32, 27, 13), Node), FULL;
    hot_top_row_node:              light(hot(64, 32, 20, 0), Node), FULL;
    hot_bottom_row_node:           light(hot(64, 32, 41, 31), Node), FULL;
    hot_second_row_node:           light(hot(64, 32, 5, 1), Node), FULL;
    hot_seam_last_col_node:        light(hot(64, 32, 63, 20), Node), FULL;
    random_91x37_node:             light(random(91, 37, 91), Node), FULL;
    two_rows_node:                 light(random(16, 2, 4), Node), FULL;
    one_texel_node:                light(constant(1, 1), Node), FULL;
    wide_16384x1_node:             light(gradient(16384, 1), Node), FULL;
    tall_1x4096_node:              light(gradient(1, 4096), Node), FULL;
    huge_range_node:               light(huge_range(32, 16), Node), HUGE_RANGE;
    rotated_random_node:           rotated(random(48, 24, 7), Node, 37.0), FULL;
    builtin_sky_node:              light(envlight::builtin::sky(256, 128), Node), FULL;
    alias_hot_top_row_node:        combo(hot(64, 32, 20, 0), Node, Alias, PiecewiseConstant, Equirectangular, 0.0), FULL;
    hierarchical_hot_seam_node:    combo(hot(64, 32, 63, 20), Node, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL;
    table_quarter_hot_top_row_node: table(hot(64, 32, 21, 0), Node, Inversion, 16), FULL;
    // The node lookup with the piecewise-bilinear density (nodes on its rows, pole
    // to pole): two rows (both poles), odd sides, hot pole rows, rotated.
    bilinear_density_random_node:       combo(random(91, 37, 91), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_two_rows_node:     combo(random(16, 2, 4), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_three_rows_node:   combo(random(5, 3, 8), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_top_row_node:  combo(hot(64, 32, 20, 0), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_bottom_node:   combo(hot(63, 33, 41, 32), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_second_node:   combo(hot(64, 32, 5, 1), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_seam_node:     combo(hot(64, 32, 63, 20), Node, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL;
    bilinear_density_one_row_node:      combo(gradient(64, 1), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_rotated_sky_node:  combo(envlight::builtin::sky(256, 128), Node, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL;
    bilinear_density_rotated_random_node: combo(random(48, 24, 7), Node, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL;
    // The same importance through other samplers of the grid (one line each).
    alias_random_bilinear:         combo(random(91, 37, 91), Bilinear, Alias, PiecewiseConstant, Equirectangular, 0.0), FULL;
    alias_hot_top_row_nearest:     combo(hot(64, 32, 20, 0), Nearest, Alias, PiecewiseConstant, Equirectangular, 0.0), FULL;
    alias_rotated_sky:             combo(envlight::builtin::sky(256, 128), Bilinear, Alias, PiecewiseConstant, Equirectangular, 37.0), FULL;
    hierarchical_random_bilinear:  combo(random(91, 37, 91), Bilinear, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL;
    hierarchical_hot_seam_nearest: combo(hot(64, 32, 63, 20), Nearest, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL;
    hierarchical_rotated_sky:      combo(envlight::builtin::sky(256, 128), Bilinear, Hierarchical, PiecewiseConstant, Equirectangular, 37.0), FULL;
    bilinear_density_random:       combo(random(91, 37, 91), Bilinear, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_seam:     combo(hot(64, 32, 63, 20), Bilinear, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_hot_top_row:  combo(hot(64, 32, 20, 0), Bilinear, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    bilinear_density_rotated_sky:  combo(envlight::builtin::sky(256, 128), Bilinear, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL;
    bilinear_density_nearest:      combo(random(91, 37, 91), Nearest, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL;
    equal_area_random:             combo(random(91, 37, 91), Bilinear, Inversion, PiecewiseConstant, EqualArea, 0.0), FULL;
    equal_area_sky_nearest:        combo(envlight::builtin::sky(256, 128), Nearest, Inversion, PiecewiseConstant, EqualArea, 37.0), FULL;
    equal_area_alias_sky:          combo(envlight::builtin::sky(256, 128), Bilinear, Alias, PiecewiseConstant, EqualArea, 0.0), FULL;
    equal_area_hierarchical_hot:   combo(hot(64, 32, 20, 3), Bilinear, Hierarchical, PiecewiseConstant, EqualArea, 0.0), FULL;
    equal_area_bilinear_sky:       combo(envlight::builtin::sky(256, 128), Bilinear, Inversion, PiecewiseBilinear, EqualArea, 0.0), FULL;
    hierarchical_wide_16384x1:     combo(gradient(16384, 1), Bilinear, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL;
    // Sampling tables coarser than the map (`table_width`): the same checks, with
    // the support check proving the pooling conservative.
    table_half_hot_middle:         table(hot(64, 32, 27, 13), Bilinear, Inversion, 32), FULL;
    table_quarter_hot_top_row:     table(hot(64, 32, 21, 0), Nearest, Inversion, 16), FULL;
    table_quarter_random:          table(random(96, 48, 5), Bilinear, Inversion, 24), FULL;
    table_alias_hot_seam:          table(hot(64, 32, 63, 20), Bilinear, Alias, 16), FULL;
    table_hierarchical_sky:        table(envlight::builtin::sky(256, 128), Bilinear, Hierarchical, 64), FULL;
    table_one_cell:                table(random(48, 24, 3), Bilinear, Inversion, 2), FULL;
}

/// A light whose sampling table is `table_width` cells wide.
fn table(
    image: EnvImage,
    lookup: Lookup,
    sampler: Sampler,
    table_width: usize,
) -> EnvironmentLight {
    EnvironmentLight::new(
        image,
        LightOptions {
            lookup,
            sampler,
            table_width: Some(table_width),
            density: Density::PiecewiseConstant,
            ..Default::default()
        },
    )
    .unwrap()
}

/// One `#[test]` per all-black map: no sample, pdf 0, ∫p = 0, no NaN (200k ξ).
macro_rules! black_cases {
    ($($name:ident: $sampler:expr;)*) => {$(
        #[test]
        fn $name() {
            verify::assert_black(stringify!($name), &$sampler, 200_000);
        }
    )*};
}

black_cases! {
    black_nearest:        light(black(16, 8), Nearest);
    black_bilinear:       light(black(16, 8), Bilinear);
    black_node:           light(black(16, 8), Node);
    black_bilinear_density_node: combo(black(16, 8), Node, Inversion, PiecewiseBilinear, Equirectangular, 0.0);
    black_one_texel:      light(black(1, 1), Bilinear);
    black_wide:           light(black(4096, 1), Bilinear);
}

// ---------------------------------------------------------------------------
// Real maps.
// ---------------------------------------------------------------------------

fn envmaps_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps")
}

/// The full harness on one real map (bilinear lookups, the default), with the
/// statistics of `Config::REAL_MAP`. Skips with a printed reason when the folder is
/// absent.
fn real_map(file: &str) {
    let dir = envmaps_dir();
    if !dir.is_dir() {
        println!("skipping real maps: {} not found", dir.display());
        return;
    }
    let path = dir.join(file);
    let start = std::time::Instant::now();
    let loaded = envlight::load::load(&path, &envlight::load::LoadOptions::default())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let load_s = start.elapsed().as_secs_f64();
    let start = std::time::Instant::now();
    let l = EnvironmentLight::new(loaded.image, LightOptions::default()).unwrap();
    let build_s = start.elapsed().as_secs_f64();
    let report = verify::assert_invariants(file, &l, &Integrand::luminance(), &Config::REAL_MAP);
    println!(
        "[{file}] efficiency {:.4} (reported {:.4}); load {load_s:.2}s, build {build_s:.3}s",
        report
            .unbiasedness
            .as_ref()
            .map_or(f64::NAN, |u| u.efficiency_quadrature),
        l.efficiency()
    );
}

macro_rules! real_maps {
    ($($name:ident: $file:expr;)*) => {$(
        #[test]
        fn $name() {
            real_map($file);
        }
    )*};
}

real_maps! {
    real_sunrise: "sunrise.exr";
    real_city: "city.exr";
    real_studio: "studio.exr";
    real_courtyard: "courtyard.exr";
    real_night: "night.exr";
    real_colorful_studio_2k: "colorful_studio_2k.hdr";
}

// ---------------------------------------------------------------------------
// Orientation: independent of any loader, the direction of a texel is the one
// docs/design.md §2 gives.
// ---------------------------------------------------------------------------

/// θ = π(y+½)/h, φ = 2π(x+½)/w, ω = (sinθ cosφ, sinθ sinφ, cosθ), computed here.
fn convention_direction(x: usize, y: usize, w: usize, h: usize) -> [f64; 3] {
    let theta = std::f64::consts::PI * (y as f64 + 0.5) / h as f64;
    let phi = 2.0 * std::f64::consts::PI * (x as f64 + 0.5) / w as f64;
    [
        theta.sin() * phi.cos(),
        theta.sin() * phi.sin(),
        theta.cos(),
    ]
}

#[test]
fn orientation_hot_texel_samples_come_from_its_direction() {
    let (w, h) = (64, 32);
    // 10k samples per texel; with nearest lookups every one must land in the texel.
    for &(x, y) in &[
        (27, 13),
        (0, 0),
        (63, 31),
        (16, 16),
        (48, 5),
        (0, 20),
        (63, 3),
    ] {
        for degrees in [0.0f32, 37.0] {
            let l = rotated(hot(w, h, x, y), Nearest, degrees);
            let rot = Rotation::about_z_degrees(degrees);
            let centre = rot.apply(Vec3::new(
                convention_direction(x, y, w, h)[0] as f32,
                convention_direction(x, y, w, h)[1] as f32,
                convention_direction(x, y, w, h)[2] as f32,
            ));
            assert_eq!(
                l.radiance(centre),
                [40.0, 30.0, 20.0],
                "({x},{y}) {degrees}°"
            );
            assert!(l.pdf(centre) > 0.0);
            assert_eq!(l.radiance(-centre), [0.0; 3]);
            assert_eq!(l.pdf(-centre), 0.0);
            let back = rot.inverse();
            let mut sum = [0.0f64; 3];
            let n = 10_000;
            for k in 0..n {
                let xi = envlight::rng::xi_2d(11, k);
                let s = l.sample(xi).expect("a hot texel always samples");
                let d = back.apply(s.direction);
                let [u, v] = verify::uv_of([d.x as f64, d.y as f64, d.z as f64]);
                // Inside the texel's (φ, θ) box, up to float noise.
                let su = u * w as f64 - x as f64;
                let su = su - (su / w as f64).round() * w as f64; // wrap across the seam
                let sv = v * h as f64 - y as f64;
                assert!(
                    (-1e-4..=1.0001).contains(&su) && (-1e-4..=1.0001).contains(&sv),
                    "texel ({x},{y}) rotated {degrees}°: ξ={xi:?} gave u·w={}, v·h={}",
                    u * w as f64,
                    v * h as f64
                );
                for (a, c) in sum.iter_mut().zip(s.direction.to_array()) {
                    *a += c as f64;
                }
            }
            // The mean direction points at the texel centre (to a fifth of a texel).
            let len = (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt();
            let mean = [sum[0] / len, sum[1] / len, sum[2] / len];
            let c = [centre.x as f64, centre.y as f64, centre.z as f64];
            let angle = (mean[0] * c[0] + mean[1] * c[1] + mean[2] * c[2])
                .clamp(-1.0, 1.0)
                .acos();
            let texel = std::f64::consts::PI / h as f64;
            // Pole texels are wedges: their mean sits off the θ-centre by up to 1/6 texel.
            assert!(
                angle < 0.2 * texel,
                "texel ({x},{y}) rotated {degrees}°: mean is {angle} rad off"
            );
        }
    }
}

// ---------------------------------------------------------------------------
// Broken samplers: the harness must reject each.
// ---------------------------------------------------------------------------

/// Delegates everything to a light; the broken samplers override one thing.
macro_rules! delegate {
    () => {
        fn invert(&self, d: Vec3) -> Option<[f32; 2]> {
            self.inner.invert(d)
        }
        fn radiance(&self, d: Vec3) -> [f32; 3] {
            self.inner.radiance(d)
        }
        fn integral_luminance(&self) -> f64 {
            self.inner.integral_luminance()
        }
        fn grid(&self) -> Option<Grid> {
            SphereSampler::grid(&self.inner)
        }
    };
}

/// Reports every pdf 5% too high (sample and `pdf()` agree with each other).
struct ScaledPdf {
    inner: EnvironmentLight,
    factor: f32,
}

impl SphereSampler for ScaledPdf {
    fn name(&self) -> String {
        format!("broken: pdf × {}", self.factor)
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi).map(|s| SphereSample {
            pdf: s.pdf * self.factor,
            ..s
        })
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf(d) * self.factor
    }
    delegate!();
}

/// Forgets the `1/sin θ` of the solid-angle density (consistently in sample and pdf).
struct NoSinJacobian {
    inner: EnvironmentLight,
}

fn sin_theta(d: Vec3) -> f32 {
    d.x.hypot(d.y)
}

impl SphereSampler for NoSinJacobian {
    fn name(&self) -> String {
        "broken: no sin θ Jacobian".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi).map(|s| SphereSample {
            pdf: s.pdf * sin_theta(s.direction),
            ..s
        })
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf(d) * sin_theta(d)
    }
    delegate!();
}

/// Picks rows from a distorted marginal CDF, `ξ1 ↦ ξ1 + δ sin(2πξ1)/2π`: the row
/// densities are off by a factor `1/(1 + δ cos 2πξ1)`, within ±δ; pdf() is the
/// light's. Only the distribution of the samples is wrong.
struct DistortedRows {
    inner: EnvironmentLight,
    delta: f32,
}

impl SphereSampler for DistortedRows {
    fn name(&self) -> String {
        format!("broken: row CDF distorted by ±{}", self.delta)
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        let tau = 2.0 * std::f32::consts::PI;
        let x1 = (xi[1] + self.delta * (tau * xi[1]).sin() / tau).clamp(0.0, 1.0 - f32::EPSILON);
        SphereSampler::sample(&self.inner, [xi[0], x1])
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf(d)
    }
    delegate!();
}

/// Importance without the [1 6 1] filter (built for nearest lookups) while the
/// radiance is bilinear: black texels next to a bright one are lit but never sampled.
struct UnfilteredImportance {
    importance: EnvironmentLight,
    inner: EnvironmentLight,
}

impl SphereSampler for UnfilteredImportance {
    fn name(&self) -> String {
        "broken: unfiltered importance, bilinear radiance".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        self.importance.sample(xi).map(|s| SphereSample {
            direction: s.direction,
            pdf: s.pdf,
            radiance: self.inner.radiance(s.direction),
        })
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.importance.pdf(d)
    }
    fn invert(&self, d: Vec3) -> Option<[f32; 2]> {
        self.importance.invert(d)
    }
    fn radiance(&self, d: Vec3) -> [f32; 3] {
        self.inner.radiance(d)
    }
    fn integral_luminance(&self) -> f64 {
        self.inner.integral_luminance()
    }
    fn grid(&self) -> Option<Grid> {
        SphereSampler::grid(&self.inner)
    }
}

/// `pdf()` looks half a texel to the east of the asked direction.
struct PdfHalfTexelOff {
    inner: EnvironmentLight,
}

impl SphereSampler for PdfHalfTexelOff {
    fn name(&self) -> String {
        "broken: pdf() half a texel off in φ".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi)
    }
    fn pdf(&self, d: Vec3) -> f32 {
        let degrees = 180.0 / self.inner.image().width() as f32;
        self.inner.pdf(Rotation::about_z_degrees(-degrees).apply(d))
    }
    delegate!();
}

/// The unbiasedness check of the luminance (and its lobes) with 1M samples, the
/// one the broken samplers below must fail.
fn luminance_unbiasedness(s: &dyn SphereSampler, seed: u64) -> verify::Unbiasedness {
    verify::unbiasedness(
        s,
        &Integrand::luminance(),
        &verify::lobe_normals(s),
        1_000_000,
        seed,
        verify::Reference::Checked,
    )
}

#[test]
fn broken_scaled_pdf_is_rejected() {
    // pdf × 1.05: ∫p = 1.05; chi-square (1M samples, α = 1e-3) measured p ≈ 2e-26;
    // f = 1 estimate (1M samples) 76 standard errors low.
    let s = ScaledPdf {
        inner: light(random(91, 37, 91), Bilinear),
        factor: 1.05,
    };
    let n = verify::normalisation(&s);
    let c = verify::chi_square(&s, 1_000_000, 21, 40_000);
    let u = luminance_unbiasedness(&s, 22);
    println!("[{}]\n  {n}\n  {c}\n  {u}", s.name());
    assert!(
        n.verdict(false).is_err() && (n.integral - 1.05).abs() < 1e-3,
        "{n}"
    );
    assert!(c.p_value < ALPHA && c.verdict().is_err(), "{c}");
    assert!(u.verdict(true).is_err(), "{u}");
}

#[test]
fn broken_missing_sin_theta_is_rejected() {
    // ∫p = E[sin θ] ≈ 0.76 instead of 1; chi-square (1M samples, α = 1e-3) p ≈ 0.
    let s = NoSinJacobian {
        inner: light(gradient(64, 32), Nearest),
    };
    let n = verify::normalisation(&s);
    let c = verify::chi_square(&s, 1_000_000, 23, 40_000);
    println!("[{}]\n  {n}\n  {c}", s.name());
    assert!(n.verdict(false).is_err(), "{n}");
    assert!(c.p_value < ALPHA && c.verdict().is_err(), "{c}");
}

#[test]
fn broken_row_cdf_is_rejected() {
    // ±5% errors in the row densities. The pdf is the light's own, so normalisation
    // passes: only the chi-square test (1M samples, α = 1e-3) can see this; measured
    // p ≈ 6e-15 and 2e-26.
    for base in [
        light(gradient(64, 32), Bilinear),
        light(random(91, 37, 91), Nearest),
    ] {
        let s = DistortedRows {
            inner: base,
            delta: 0.05,
        };
        let n = verify::normalisation(&s);
        let c = verify::chi_square(&s, 1_000_000, 24, 40_000);
        println!(
            "[{} on {}]\n  {n}\n  {c}",
            s.name(),
            SphereSampler::name(&s.inner)
        );
        assert!(n.verdict(false).is_ok(), "{n}");
        assert!(c.p_value < ALPHA && c.verdict().is_err(), "{c}");
    }
}

#[test]
fn broken_unfiltered_importance_is_rejected() {
    // A hot texel's bilinear tail in its 8 black neighbours is never sampled:
    // support fails at 13 probes, and the f = 1 estimate (1M samples, 4 SE) misses
    // 44% of the light (about 2800 standard errors).
    let image = hot(64, 32, 27, 13);
    let s = UnfilteredImportance {
        importance: light(image.clone(), Nearest),
        inner: light(image, Bilinear),
    };
    let sup = verify::support(&s, &Integrand::luminance());
    let u = luminance_unbiasedness(&s, 25);
    println!("[{}]\n  {sup}\n  {u}", s.name());
    assert!(sup.verdict().is_err() && sup.violations > 0, "{sup}");
    let f1 = &u.estimates[0];
    assert!((f1.mean - f1.reference).abs() > f1.tolerance(), "{u}");
    assert!(u.verdict(true).is_err());
}

#[test]
fn broken_pdf_lookup_is_rejected() {
    // pdf() evaluated half a texel east: consistency (200k samples) fails on about
    // half of them; chi-square (1M samples, α = 1e-3) p ≈ 0.
    let s = PdfHalfTexelOff {
        inner: light(random(91, 37, 91), Nearest),
    };
    let n = verify::normalisation(&s);
    let c = verify::consistency(&s, 200_000, 26, verify::PDF_CONSISTENCY_TOLERANCE);
    let chi = verify::chi_square(&s, 1_000_000, 27, 40_000);
    println!("[{}]\n  {n}\n  {c}\n  {chi}", s.name());
    // A shifted pdf still integrates to 1: normalisation cannot see it ...
    assert!(n.verdict(false).is_ok(), "{n}");
    // ... but it no longer matches the samples.
    assert!(
        c.verdict().is_err() && c.pdf_failures > c.checked / 2,
        "{c}"
    );
    assert!(chi.p_value < ALPHA, "{chi}");
}

/// An equal-area light whose `pdf()` reads the square at the transposed point
/// `(v, u)` (rows and columns swapped), computed with the harness's own mapping;
/// `sample()` is right.
struct TransposedSquarePdf {
    inner: EnvironmentLight,
}

impl SphereSampler for TransposedSquarePdf {
    fn name(&self) -> String {
        "broken: equal-area pdf() at the transposed square point".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi)
    }
    fn pdf(&self, d: Vec3) -> f32 {
        let [u, v] = verify::sphere_to_square([d.x as f64, d.y as f64, d.z as f64]);
        let t = verify::square_to_sphere(v, u);
        self.inner
            .pdf(Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32))
    }
    delegate!();
}

/// An equal-area light that converts its density with the lat-long Jacobian
/// `2π² sin θ` instead of the square's `4π` (consistently in sample and pdf).
struct LatLongJacobian {
    inner: EnvironmentLight,
}

impl LatLongJacobian {
    fn factor(d: Vec3) -> f32 {
        4.0 / (2.0 * std::f32::consts::PI * sin_theta(d))
    }
}

impl SphereSampler for LatLongJacobian {
    fn name(&self) -> String {
        "broken: equal-area density with the lat-long Jacobian".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi).map(|s| SphereSample {
            pdf: s.pdf * Self::factor(s.direction),
            ..s
        })
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf(d) * Self::factor(d)
    }
    delegate!();
}

#[test]
fn broken_equal_area_samplers_are_rejected() {
    // Transposed pdf(): a mirror image of the density still integrates to 1, but
    // consistency (200k samples) fails on most samples (measured 195465 of 199974)
    // and chi-square (1M samples, α = 1e-3) rejects (p ≈ 0; 91851 samples where the
    // transposed pdf is 0).
    let s = TransposedSquarePdf {
        inner: combo(
            random(91, 37, 91),
            Nearest,
            Inversion,
            PiecewiseConstant,
            EqualArea,
            0.0,
        ),
    };
    let n = verify::normalisation(&s);
    let c = verify::consistency(&s, 200_000, 28, verify::PDF_CONSISTENCY_TOLERANCE);
    let chi = verify::chi_square(&s, 1_000_000, 29, 40_000);
    println!("[{}]\n  {n}\n  {c}\n  {chi}", s.name());
    assert!(n.verdict(false).is_ok(), "{n}");
    assert!(
        c.verdict().is_err() && c.pdf_failures > c.checked / 2,
        "{c}"
    );
    assert!(chi.p_value < ALPHA && chi.verdict().is_err(), "{chi}");

    // The lat-long Jacobian: ∫p = 0.795, chi-square (1M samples, α = 1e-3) p ≈ 0,
    // and the f = 1 estimate (1M samples) 470 standard errors high.
    let s = LatLongJacobian {
        inner: combo(
            envlight::builtin::sky(256, 128),
            Bilinear,
            Inversion,
            PiecewiseConstant,
            EqualArea,
            0.0,
        ),
    };
    let n = verify::normalisation(&s);
    let chi = verify::chi_square(&s, 1_000_000, 30, 40_000);
    let u = luminance_unbiasedness(&s, 31);
    println!("[{}]\n  {n}\n  {chi}\n  {u}", s.name());
    assert!(n.verdict(false).is_err(), "{n}");
    assert!(chi.p_value < ALPHA && chi.verdict().is_err(), "{chi}");
    let f1 = &u.estimates[0];
    assert!((f1.mean - f1.reference).abs() > f1.tolerance(), "{u}");

    // ±5% errors in the densities of the square's rows, pdf() the light's own:
    // only the chi-square test over the square's cells can see it (1M samples,
    // α = 1e-3; measured p ≈ 7e-14).
    let s = DistortedRows {
        inner: combo(
            random(91, 37, 91),
            Bilinear,
            Inversion,
            PiecewiseConstant,
            EqualArea,
            0.0,
        ),
        delta: 0.05,
    };
    let n = verify::normalisation(&s);
    let chi = verify::chi_square(&s, 1_000_000, 32, 40_000);
    println!("[{} on the equal-area square]\n  {n}\n  {chi}", s.name());
    assert!(n.verdict(false).is_ok(), "{n}");
    assert!(chi.p_value < ALPHA && chi.verdict().is_err(), "{chi}");
}
