//! Every BSDF: energy conservation, reciprocity, and a sampling routine whose
//! density matches its samples (chi-square) and integrates to at most 1.

#![allow(clippy::needless_range_loop)] // per-channel arithmetic reads best indexed

mod common;

use common::{mean_and_error, polar};
use envlight::rng::SplitMix64;
use envlight::Vec3;
use envlight_render::bsdf::Bsdf;
use envlight_render::warp::square_to_uniform_sphere;
use envlight_verify::{chi_square_warp, WarpChiSquare};

const COPPER_ETA: [f32; 3] = [0.200, 0.924, 1.102];
const COPPER_K: [f32; 3] = [3.912, 2.452, 2.142];
const SILVER_ETA: [f32; 3] = [0.155, 0.117, 0.138];
const SILVER_K: [f32; 3] = [4.828, 3.122, 2.147];

/// The BSDFs under test: the `balls` scene's materials and the extremes (albedo 1,
/// very rough, very smooth).
fn bsdfs() -> Vec<(&'static str, Bsdf)> {
    vec![
        ("diffuse white", Bsdf::Diffuse { albedo: [1.0; 3] }),
        ("diffuse grey", Bsdf::Diffuse { albedo: [0.7; 3] }),
        (
            "copper a=0.25",
            Bsdf::Conductor {
                alpha: 0.25,
                eta: COPPER_ETA,
                k: COPPER_K,
            },
        ),
        (
            "silver a=0.02",
            Bsdf::Conductor {
                alpha: 0.02,
                eta: SILVER_ETA,
                k: SILVER_K,
            },
        ),
        (
            "silver a=0.8",
            Bsdf::Conductor {
                alpha: 0.8,
                eta: SILVER_ETA,
                k: SILVER_K,
            },
        ),
        (
            "plastic blue a=0.08",
            Bsdf::Plastic {
                albedo: [0.1, 0.25, 0.6],
                alpha: 0.08,
                eta: 1.5,
            },
        ),
        (
            "plastic white a=0.3",
            Bsdf::Plastic {
                albedo: [1.0; 3],
                alpha: 0.3,
                eta: 1.5,
            },
        ),
        (
            "plastic white a=0.9",
            Bsdf::Plastic {
                albedo: [1.0; 3],
                alpha: 0.9,
                eta: 1.5,
            },
        ),
    ]
}

/// Directional albedo `∫ f cos θi dωi` by Monte Carlo with the BSDF's own sampling,
/// at least 100 000 samples per direction: never above 1 (beyond 4 standard errors).
#[test]
fn directional_albedo_is_at_most_one() {
    let n = 100_000;
    for (name, bsdf) in bsdfs() {
        for theta in [0.0f32, 20.0, 40.0, 60.0, 75.0, 85.0, 89.0] {
            let wo = polar(theta);
            let mut rng = SplitMix64::new(17);
            let values: Vec<[f32; 3]> = (0..n)
                .map(|_| {
                    let uc = rng.next_f32();
                    let u = [rng.next_f32(), rng.next_f32()];
                    match bsdf.sample(wo, uc, u) {
                        Some(s) => s.f.map(|f| f * s.wi.z / s.pdf),
                        None => [0.0; 3],
                    }
                })
                .collect();
            let (mean, se) = mean_and_error(&values);
            for c in 0..3 {
                assert!(
                    mean[c] <= 1.0 + 4.0 * se[c] + 1e-4,
                    "{name} θo={theta}: albedo {mean:?} ± {se:?}"
                );
            }
            // The Lambertian albedo is exact.
            if let Bsdf::Diffuse { albedo } = bsdf {
                assert!(
                    (mean[0] - albedo[0] as f64).abs() < 1e-4,
                    "{name}: {mean:?}"
                );
            }
        }
    }
}

/// `f(ωo, ωi) = f(ωi, ωo)` for random pairs in the upper hemisphere.
#[test]
fn bsdfs_are_reciprocal() {
    let mut rng = SplitMix64::new(5);
    let mut upper = || loop {
        let w = square_to_uniform_sphere([rng.next_f32(), rng.next_f32()]);
        if w.z > 1e-3 {
            return w;
        }
    };
    for (name, bsdf) in bsdfs() {
        for _ in 0..20_000 {
            let (a, b) = (upper(), upper());
            let (f_ab, f_ba) = (bsdf.eval(a, b), bsdf.eval(b, a));
            for c in 0..3 {
                let tol = 1e-4 * f_ab[c].abs().max(f_ba[c].abs()) + 1e-7;
                assert!(
                    (f_ab[c] - f_ba[c]).abs() <= tol,
                    "{name}: f({a:?},{b:?}) = {f_ab:?} vs {f_ba:?}"
                );
            }
        }
    }
}

/// The sample and pdf a BSDF reports agree with `eval` and `pdf`.
#[test]
fn sample_reports_eval_and_pdf() {
    for (name, bsdf) in bsdfs() {
        let mut rng = SplitMix64::new(9);
        for theta in [5.0f32, 45.0, 80.0] {
            let wo = polar(theta);
            for _ in 0..2000 {
                let uc = rng.next_f32();
                let u = [rng.next_f32(), rng.next_f32()];
                if let Some(s) = bsdf.sample(wo, uc, u) {
                    assert!(s.wi.z > 0.0 && s.pdf > 0.0, "{name}");
                    assert_eq!(s.f, bsdf.eval(wo, s.wi), "{name}");
                    assert_eq!(s.pdf, bsdf.pdf(wo, s.wi), "{name}");
                }
            }
        }
        // Below the surface: nothing.
        let below = Vec3::new(0.0, 0.6, -0.8);
        assert_eq!(bsdf.eval(polar(30.0), below), [0.0; 3]);
        assert_eq!(bsdf.pdf(polar(30.0), below), 0.0);
        assert!(bsdf.sample(below, 0.5, [0.5, 0.5]).is_none());
    }
}

/// Chi-square goodness of fit of every BSDF's sampling against its pdf, from three
/// outgoing directions: 200 000 samples, a 24 × 48 grid in (cos θ, φ) over the upper
/// hemisphere plus a "no sample" bin, expected counts by quadrature of `pdf`,
/// significance α = 1e-3 per test, fixed seed. Also `∫ pdf ≤ 1`.
/// The chi-square test of `bsdf`'s sampled directions at `wo` against the density
/// `pdf`: 24 × 48 bins over the upper hemisphere (`sub`² quadrature points each),
/// 200 000 samples from `seed`.
fn chi_square(
    bsdf: &Bsdf,
    wo: Vec3,
    pdf: impl Fn(Vec3) -> f32 + Sync,
    sub: usize,
    seed: u64,
) -> WarpChiSquare {
    chi_square_warp(
        |xi| bsdf.sample(wo, xi[0], [xi[1], xi[2]]).map(|s| s.wi),
        pdf,
        (0.0, 1.0),
        24,
        48,
        sub,
        200_000,
        seed,
    )
}

#[test]
fn sampling_matches_pdf_chi_square() {
    for (name, bsdf) in bsdfs() {
        // Narrow lobes need finer quadrature for the expected counts.
        let sub = match bsdf {
            Bsdf::Conductor { alpha, .. } | Bsdf::Plastic { alpha, .. } if alpha < 0.05 => 40,
            _ => 8,
        };
        for (k, theta) in [10.0f32, 45.0, 80.0].into_iter().enumerate() {
            let wo = polar(theta);
            let r = chi_square(&bsdf, wo, |wi| bsdf.pdf(wo, wi), sub, 1000 + k as u64);
            eprintln!("{name} θo={theta}: {r:?}");
            assert!(
                r.integral <= 1.0 + 1e-3,
                "{name} θo={theta}: ∫pdf = {}",
                r.integral
            );
            assert!(
                r.p_value > 1e-3,
                "{name} θo={theta}: chi² = {:.1} (dof {}), p = {:.2e}",
                r.statistic,
                r.dof,
                r.p_value
            );
        }
    }
}

/// The harness is sharp enough to reject a subtly wrong density: GGX sampled with
/// α = 0.25 but evaluated with α = 0.28 (and a Lambertian pdf off by a factor
/// 1.05 where `cos θ > 0.5`).
#[test]
fn chi_square_rejects_a_wrong_pdf() {
    let sampled = Bsdf::Conductor {
        alpha: 0.25,
        eta: COPPER_ETA,
        k: COPPER_K,
    };
    let claimed = Bsdf::Conductor {
        alpha: 0.28,
        eta: COPPER_ETA,
        k: COPPER_K,
    };
    let wo = polar(45.0);
    let r = chi_square(&sampled, wo, |wi| claimed.pdf(wo, wi), 8, 7);
    assert!(r.p_value < 1e-3, "wrong α accepted: p = {}", r.p_value);

    let diffuse = Bsdf::Diffuse { albedo: [1.0; 3] };
    let skewed = |wi: Vec3| diffuse.pdf(wo, wi) * if wi.z > 0.5 { 1.05 } else { 0.95 };
    let r = chi_square(&diffuse, wo, skewed, 4, 8);
    assert!(
        r.p_value < 1e-3,
        "skewed cosine pdf accepted: p = {}",
        r.p_value
    );
}
