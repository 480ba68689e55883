//! Which quadrature of the efficiency `(∫g)² / ∫g²/p dω` is right (issue 35, item 6).
//!
//! With the default bilinear lookup, `Y` is bilinear between texel centres, so
//! `g²/p` is quadratic along each axis between the centre lines, and a midpoint
//! rule underestimates `∫g²/p` by `O(h²)` of its curvature (4 midpoints of `x²`
//! on `[0, 1]` give 0.328 instead of 1/3): it reads the efficiency high, most
//! around a sharp sun. [`Reference::Checked`] (Gauss-Legendre on cells split at
//! the centre lines, what `envlight info --normal` reports) has no such error. An
//! independent check with 4 × 4 midpoints per texel at 256 × 128 read 3–4.5% above
//! `info`; `examples/efficiency_convergence.rs` shows the whole table on the shared
//! maps, and this test the same law on the built-in sky.

use envlight::light::Density;
use envlight::{
    builtin, EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3,
};
use envlight_verify::{efficiency, midpoint_moments, AtShadingPoint, Reference};
use std::sync::Arc;

/// `(∫g)² / ∫g²/p` by [`midpoint_moments`] (written apart from the harness's
/// quadrature), with no lit point left at pdf 0.
fn midpoint_efficiency(at: &AtShadingPoint, size: [usize; 2], n: Vec3, m: usize) -> f64 {
    let moments = midpoint_moments(at, size, n, m, None);
    assert_eq!(moments.unsampled, 0, "lit points with pdf 0");
    moments.efficiency()
}

/// The built-in sky at 256 × 128 (its sun about one texel wide), the surface
/// facing the brightest texel, the product sampler's pdf. Measured (2026-12-03,
/// with the bright patches): Checked 0.70013; midpoint 2×2 0.79893, 4×4 0.72304,
/// 8×8 0.70576, 16×16 0.70154 per texel. The midpoint's excess shrinks 4.31×,
/// 4.07×, 3.99× per halving of the spacing, Richardson's extrapolation of 8×8 and
/// 16×16 lands on Checked (-3.5e-6), and the 4×4 rule's excess, 0.0229 (3.3%), is
/// what the `h²` law fitted on the finer levels predicts (0.0225). Replacing Checked by [`Reference::Midpoint`] (2×2 points per
/// texel) fails the test.
#[test]
fn midpoint_efficiency_converges_to_the_checked_rule() {
    let image = builtin::sky(256, 128);
    let size = [image.width(), image.height()];
    // The piecewise-constant density, whose product pdf is constant per texel
    // (the bilinear one's follows `Y` and leaves the midpoint rule no curvature
    // to miss).
    let options = LightOptions {
        density: Density::PiecewiseConstant,
        ..Default::default()
    };
    let light = Arc::new(EnvironmentLight::new(image, options).unwrap());
    let sampler = ProductSampler::new(light.clone(), ProductOptions::default());
    let n = light.brightest().1;
    let at = AtShadingPoint::new(&sampler, Factor::cosine(n));
    let checked = efficiency(&at, &at.integrand(), Reference::Checked).efficiency;
    let levels = [2, 4, 8, 16];
    let e = levels.map(|m| midpoint_efficiency(&at, size, n, m));
    let excess = e.map(|x| x - checked);
    println!("Checked {checked:.5}; midpoint {levels:?} per texel: {e:.5?}, excess {excess:.5?}");

    // The midpoint rule reads high at every level, by O(h²): the excess falls
    // 4× per halving of the spacing (3.5–4.5 allowed).
    for k in 0..levels.len() - 1 {
        assert!(excess[k + 1] > 0.0, "{levels:?}: excess {excess:?}");
        let ratio = excess[k] / excess[k + 1];
        assert!(
            (3.5..4.5).contains(&ratio),
            "{}→{} points: excess ratio {ratio:.3} (O(h²): 4); excess {excess:?}",
            levels[k],
            levels[k + 1]
        );
    }

    // Its limit (Richardson, from 8×8 and 16×16) is Checked's figure.
    let limit = (4.0 * e[3] - e[2]) / 3.0;
    println!(
        "Richardson limit {limit:.6} ({:+.1e} of Checked)",
        limit / checked - 1.0
    );
    assert!(
        (limit / checked - 1.0).abs() < 2e-4,
        "midpoint limit {limit:.5} against Checked {checked:.5}"
    );

    // The 4×4 rule of the independent check is off by what the h² law fitted on
    // 8×8 and 16×16 predicts (16× the 16×16 rule's excess, that is
    // 16/3 · (e8 − e16)), a few percent here: the size of issue 35's gap.
    let predicted = 16.0 / 3.0 * (e[2] - e[3]);
    println!("4×4 excess {:.5}, predicted {predicted:.5}", excess[1]);
    assert!(
        (excess[1] / predicted - 1.0).abs() < 0.05,
        "4×4 excess {:.5}, predicted {predicted:.5}",
        excess[1]
    );
    assert!(
        excess[1] / checked > 0.02,
        "4×4 excess {:.5} of {checked:.5}: smaller than issue 35's gap",
        excess[1]
    );
}
