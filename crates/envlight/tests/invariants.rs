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

mod common;

use envlight::{EnvImage, EnvironmentLight, LightOptions, Lookup, Rotation, Vec3};
use envlight_verify::maps::{black, constant, gradient, hot, huge_range, random};
use envlight_verify::{
    self as verify, Config, Grid, Integrand, SphereSample, SphereSampler, ALPHA,
};

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
    let options = LightOptions {
        rotation: Rotation::about_z_degrees(degrees),
        ..options(lookup, sampler, density, mapping)
    };
    EnvironmentLight::new(image, options).unwrap()
}

/// The options of that lookup, sampler, density and mapping, the rest default.
fn options(lookup: Lookup, sampler: Sampler, density: Density, mapping: Mapping) -> LightOptions {
    LightOptions {
        lookup,
        sampler,
        density,
        mapping,
        ..Default::default()
    }
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

/// The lookup a test is named after.
macro_rules! lookup {
    (nearest) => {
        Nearest
    };
    (bilinear) => {
        Bilinear
    };
    (node) => {
        Node
    };
}

/// One module per line, `name: |lookup| light, config, [lookups];`, and in it one
/// `#[test]` per lookup listed: `constant::nearest`, `constant::bilinear`, ...
macro_rules! invariant_cases {
    ($($name:ident: $light:expr, $cfg:expr, [$($lookup:ident),+];)*) => {$(
        mod $name {
            use super::*;
            $(
                #[test]
                fn $lookup() {
                    let sampler = ($light)(lookup!($lookup));
                    let case = concat!(stringify!($name), "::", stringify!($lookup));
                    verify::assert_invariants(case, &sampler, &Integrand::luminance(), &$cfg);
                }
            )+
        }
    )*};
}

invariant_cases! {
    constant:             |l| light(constant(64, 32), l), FULL, [nearest, bilinear, node];
    gradient:             |l| light(gradient(64, 32), l), FULL, [nearest, bilinear, node];
    hot_middle:           |l| light(hot(64, 32, 27, 13), l), FULL, [nearest, bilinear, node];
    hot_top_row:          |l| light(hot(64, 32, 20, 0), l), FULL, [nearest, bilinear, node];
    hot_bottom_row:       |l| light(hot(64, 32, 41, 31), l), FULL, [nearest, bilinear, node];
    hot_seam_first_col:   |l| light(hot(64, 32, 0, 10), l), FULL, [nearest, bilinear];
    hot_seam_last_col:    |l| light(hot(64, 32, 63, 20), l), FULL, [nearest, bilinear, node];
    random_91x37:         |l| light(random(91, 37, 91), l), FULL, [nearest, bilinear, node];
    one_texel:            |l| light(constant(1, 1), l), FULL, [nearest, bilinear, node];
    wide_16384x1:         |l| light(gradient(16384, 1), l), FULL, [nearest, bilinear, node];
    tall_1x4096:          |l| light(gradient(1, 4096), l), FULL, [nearest, bilinear, node];
    huge_range:           |l| light(huge_range(32, 16), l), HUGE_RANGE, [nearest, bilinear, node];
    rotated_random:       |l| rotated(random(48, 24, 7), l, 37.0), FULL, [nearest, bilinear, node];
    rotated_hot_seam:     |l| rotated(hot(64, 32, 63, 9), l, 37.0), FULL, [bilinear];
    builtin_sky:          |l| light(envlight::builtin::sky(256, 128), l), FULL, [bilinear, node];
    // The node lookup (Mitsuba envmap's rows as nodes from pole to pole) and the
    // importance that follows it: every check, the edge rows and the seam included
    // (with the maps above, and these).
    hot_second_row:       |l| light(hot(64, 32, 5, 1), l), FULL, [node];
    two_rows:             |l| light(random(16, 2, 4), l), FULL, [node];
    // The piecewise-bilinear density (with the node lookup, nodes on its rows, pole
    // to pole): two rows (both poles), odd sides, hot pole rows, rotated.
    bilinear_density_random:          |l| combo(random(91, 37, 91), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [nearest, bilinear, node];
    bilinear_density_two_rows:        |l| combo(random(16, 2, 4), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [node];
    bilinear_density_three_rows:      |l| combo(random(5, 3, 8), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [node];
    bilinear_density_hot_top_row:     |l| combo(hot(64, 32, 20, 0), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [bilinear, node];
    bilinear_density_hot_bottom:      |l| combo(hot(63, 33, 41, 32), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [node];
    bilinear_density_hot_second:      |l| combo(hot(64, 32, 5, 1), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [node];
    bilinear_density_hot_seam:        |l| combo(hot(64, 32, 63, 20), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [bilinear];
    bilinear_density_rotated_hot_seam: |l| combo(hot(64, 32, 63, 20), l, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL, [node];
    bilinear_density_one_row:         |l| combo(gradient(64, 1), l, Inversion, PiecewiseBilinear, Equirectangular, 0.0), FULL, [node];
    bilinear_density_rotated_sky:     |l| combo(envlight::builtin::sky(256, 128), l, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL, [bilinear, node];
    bilinear_density_rotated_random:  |l| combo(random(48, 24, 7), l, Inversion, PiecewiseBilinear, Equirectangular, 37.0), FULL, [node];
    // The same importance through other samplers of the grid.
    alias_random:                     |l| combo(random(91, 37, 91), l, Alias, PiecewiseConstant, Equirectangular, 0.0), FULL, [bilinear];
    alias_hot_top_row:                |l| combo(hot(64, 32, 20, 0), l, Alias, PiecewiseConstant, Equirectangular, 0.0), FULL, [nearest, node];
    alias_rotated_sky:                |l| combo(envlight::builtin::sky(256, 128), l, Alias, PiecewiseConstant, Equirectangular, 37.0), FULL, [bilinear];
    hierarchical_random:              |l| combo(random(91, 37, 91), l, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL, [bilinear];
    hierarchical_hot_seam:            |l| combo(hot(64, 32, 63, 20), l, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL, [nearest, node];
    hierarchical_rotated_sky:         |l| combo(envlight::builtin::sky(256, 128), l, Hierarchical, PiecewiseConstant, Equirectangular, 37.0), FULL, [bilinear];
    hierarchical_wide_16384x1:        |l| combo(gradient(16384, 1), l, Hierarchical, PiecewiseConstant, Equirectangular, 0.0), FULL, [bilinear];
    equal_area_random:                |l| combo(random(91, 37, 91), l, Inversion, PiecewiseConstant, EqualArea, 0.0), FULL, [bilinear];
    equal_area_rotated_sky:           |l| combo(envlight::builtin::sky(256, 128), l, Inversion, PiecewiseConstant, EqualArea, 37.0), FULL, [nearest];
    equal_area_alias_sky:             |l| combo(envlight::builtin::sky(256, 128), l, Alias, PiecewiseConstant, EqualArea, 0.0), FULL, [bilinear];
    equal_area_hierarchical_hot:      |l| combo(hot(64, 32, 20, 3), l, Hierarchical, PiecewiseConstant, EqualArea, 0.0), FULL, [bilinear];
    equal_area_bilinear_sky:          |l| combo(envlight::builtin::sky(256, 128), l, Inversion, PiecewiseBilinear, EqualArea, 0.0), FULL, [bilinear];
    // Sampling tables coarser than the map (`table_width`): the same checks, with
    // the support check proving the pooling conservative.
    table_half_hot_middle:            |l| table(hot(64, 32, 27, 13), l, Inversion, 32), FULL, [bilinear];
    table_quarter_hot_top_row:        |l| table(hot(64, 32, 21, 0), l, Inversion, 16), FULL, [nearest, node];
    table_quarter_random:             |l| table(random(96, 48, 5), l, Inversion, 24), FULL, [bilinear];
    table_alias_hot_seam:             |l| table(hot(64, 32, 63, 20), l, Alias, 16), FULL, [bilinear];
    table_hierarchical_sky:           |l| table(envlight::builtin::sky(256, 128), l, Hierarchical, 64), FULL, [bilinear];
    table_one_cell:                   |l| table(random(48, 24, 3), l, Inversion, 2), FULL, [bilinear];
}

/// A light whose sampling table is `table_width` cells wide.
fn table(
    image: EnvImage,
    lookup: Lookup,
    sampler: Sampler,
    table_width: usize,
) -> EnvironmentLight {
    let options = LightOptions {
        table_width: Some(table_width),
        ..options(
            lookup,
            sampler,
            Density::PiecewiseConstant,
            Mapping::default(),
        )
    };
    EnvironmentLight::new(image, options).unwrap()
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

/// The full harness on one real map (bilinear lookups, the default), with the
/// statistics of `Config::REAL_MAP`. Skips with a printed reason when the folder is
/// absent.
fn real_map(file: &str) {
    let Some(dir) = common::envmaps() else { return };
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

/// Delegates everything to a light (`inner`); the broken samplers override one
/// thing. `delegate!(radiance)`: only the radiance, its integral and the grid.
macro_rules! delegate {
    () => {
        fn invert(&self, d: Vec3) -> Option<[f32; 2]> {
            self.inner.invert(d)
        }
        delegate!(radiance);
    };
    (radiance) => {
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

/// Scales the density by `factor(ω)`, consistently in `sample()` and `pdf()` (they
/// agree with each other, not with the samples).
struct ScaledDensity {
    inner: EnvironmentLight,
    name: &'static str,
    factor: fn(Vec3) -> f32,
}

impl SphereSampler for ScaledDensity {
    fn name(&self) -> String {
        format!("broken: {}", self.name)
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi).map(|s| SphereSample {
            pdf: s.pdf * (self.factor)(s.direction),
            ..s
        })
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf(d) * (self.factor)(d)
    }
    delegate!();
}

fn sin_theta(d: Vec3) -> f32 {
    d.x.hypot(d.y)
}

/// Samples right, but `pdf()` answers for `elsewhere(light, ω)` instead of `ω`.
struct PdfElsewhere {
    inner: EnvironmentLight,
    name: &'static str,
    elsewhere: fn(&EnvironmentLight, Vec3) -> Vec3,
}

impl SphereSampler for PdfElsewhere {
    fn name(&self) -> String {
        format!("broken: {}", self.name)
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(&self.inner, xi)
    }
    fn pdf(&self, d: Vec3) -> f32 {
        self.inner.pdf((self.elsewhere)(&self.inner, d))
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
    delegate!(radiance);
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
    let s = ScaledDensity {
        inner: light(random(91, 37, 91), Bilinear),
        name: "pdf × 1.05",
        factor: |_| 1.05,
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
    let s = ScaledDensity {
        inner: light(gradient(64, 32), Nearest),
        name: "no sin θ Jacobian",
        factor: sin_theta,
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
    let s = PdfElsewhere {
        inner: light(random(91, 37, 91), Nearest),
        name: "pdf() half a texel off in φ",
        elsewhere: |light, d| {
            let degrees = 180.0 / light.image().width() as f32;
            Rotation::about_z_degrees(-degrees).apply(d)
        },
    };
    assert_pdf_elsewhere_rejected(&s, 26);
}

/// Rejects `s` by its pdf() alone: normalisation cannot see a pdf that answers
/// for the wrong direction (it still integrates to 1), but it no longer matches
/// the samples: consistency (200k samples, `seed`) fails on more than half of
/// them and chi-square (1M samples, `seed + 1`, α = 1e-3) rejects.
fn assert_pdf_elsewhere_rejected(s: &PdfElsewhere, seed: u64) {
    let n = verify::normalisation(s);
    let c = verify::consistency(s, 200_000, seed, verify::PDF_CONSISTENCY_TOLERANCE);
    let chi = verify::chi_square(s, 1_000_000, seed + 1, 40_000);
    println!("[{}]\n  {n}\n  {c}\n  {chi}", s.name());
    assert!(n.verdict(false).is_ok(), "{n}");
    assert!(
        c.verdict().is_err() && c.pdf_failures > c.checked / 2,
        "{c}"
    );
    assert!(chi.p_value < ALPHA && chi.verdict().is_err(), "{chi}");
}

#[test]
fn broken_equal_area_samplers_are_rejected() {
    // Transposed pdf(): a mirror image of the density still integrates to 1, but
    // consistency (200k samples) fails on most samples (measured 195465 of 199974)
    // and chi-square (1M samples, α = 1e-3) rejects (p ≈ 0; 91851 samples where the
    // transposed pdf is 0).
    // (`pdf()` reads the square at `(v, u)`, rows and columns swapped, computed
    // with the harness's own mapping.)
    let s = PdfElsewhere {
        name: "equal-area pdf() at the transposed square point",
        elsewhere: |_, d| {
            let [u, v] = verify::sphere_to_square([d.x as f64, d.y as f64, d.z as f64]);
            let t = verify::square_to_sphere(v, u);
            Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32)
        },
        inner: combo(
            random(91, 37, 91),
            Nearest,
            Inversion,
            PiecewiseConstant,
            EqualArea,
            0.0,
        ),
    };
    assert_pdf_elsewhere_rejected(&s, 28);

    // The lat-long Jacobian: ∫p = 0.795, chi-square (1M samples, α = 1e-3) p ≈ 0,
    // and the f = 1 estimate (1M samples) 470 standard errors high.
    // (The density converted with the lat-long Jacobian `2π² sin θ` instead of the
    // square's `4π`.)
    let s = ScaledDensity {
        name: "equal-area density with the lat-long Jacobian",
        factor: |d| 4.0 / (2.0 * std::f32::consts::PI * sin_theta(d)),
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
