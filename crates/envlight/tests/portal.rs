//! Portals (issue 25): the statistical checks of `envlight_verify::portal` from
//! several points of a room (near the window, at the centre, seeing both portals,
//! seeing none), with one and two portals, on synthetic and real maps; and the
//! broken variants the checks must reject (a portal corner off by a little, a pdf
//! that forgets the rectification's Jacobian).
//!
//! Significance: chi-square at α = 1e-3, means within 4 standard errors, as
//! everywhere in the harness; sample counts are `PortalConfig::SYNTHETIC` /
//! `REAL_MAP` (1M samples, 200k consistency samples, 200k probes).

use envlight::portal::{Portal, PortalLight, PortalOptions};
use envlight::{EnvironmentLight, LightOptions, Vec3};
use envlight_verify::{self as verify, AtPortalPoint, PortalConfig, PortalVariant};
use std::path::Path;
use std::sync::Arc;

fn v(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

/// The room of the render crate's `room` scene: `[0,4] × [0,3] × [0,2.5]`, a window
/// in the wall x = 4 and a skylight in the ceiling.
fn window() -> [Vec3; 4] {
    [
        v(4.0, 1.0, 0.8),
        v(4.0, 2.2, 0.8),
        v(4.0, 2.2, 1.9),
        v(4.0, 1.0, 1.9),
    ]
}
fn skylight() -> [Vec3; 4] {
    [
        v(1.2, 1.0, 2.5),
        v(2.4, 1.0, 2.5),
        v(2.4, 2.0, 2.5),
        v(1.2, 2.0, 2.5),
    ]
}

const NEAR_WINDOW: Vec3 = Vec3::new(3.7, 1.5, 1.2);
const CENTRE: Vec3 = Vec3::new(2.0, 1.5, 1.2);
/// On the line where the window's and the skylight's planes meet: it sees neither.
const SEES_NONE: Vec3 = Vec3::new(4.0, 0.5, 2.5);

fn light(image: envlight::EnvImage) -> Arc<EnvironmentLight> {
    Arc::new(EnvironmentLight::new(image, LightOptions::default()).unwrap())
}

fn portals(light: &Arc<EnvironmentLight>, corners: &[[Vec3; 4]]) -> PortalLight {
    let quads: Vec<Portal> = corners.iter().map(|&c| Portal::new(c).unwrap()).collect();
    PortalLight::new(light.clone(), &quads, PortalOptions::default()).unwrap()
}

fn check(case: &str, pl: &PortalLight, p: Vec3, cfg: &PortalConfig) -> verify::PortalReport {
    let s = AtPortalPoint::new(pl, p);
    assert!(s.power() > 0.0, "[{case}] nothing visible");
    verify::assert_portal_invariants(case, &s, cfg)
}

#[test]
fn one_and_two_portals_on_synthetic_maps() {
    // The random map's pdf jumps by up to 1e6 across table cells that do not line
    // up with the quadrature on the portals, so its quadrature is finer.
    let random = PortalConfig {
        cells: 576,
        ..PortalConfig::SYNTHETIC
    };
    let maps = [
        (
            "gradient",
            verify::maps::gradient(64, 32),
            PortalConfig::SYNTHETIC,
        ),
        ("random", verify::maps::random(48, 24, 11), random),
    ];
    for (name, image, cfg) in maps {
        let l = light(image);
        let one = portals(&l, &[window()]);
        let two = portals(&l, &[window(), skylight()]);
        check(
            &format!("{name}: 1 portal near the window"),
            &one,
            NEAR_WINDOW,
            &cfg,
        );
        check(
            &format!("{name}: 1 portal, room centre"),
            &one,
            CENTRE,
            &cfg,
        );
        let r = check(
            &format!("{name}: 2 portals, room centre (sees both)"),
            &two,
            CENTRE,
            &cfg,
        );
        assert!(r.reference[0] > 0.0);
        check(
            &format!("{name}: 2 portals near the window"),
            &two,
            NEAR_WINDOW,
            &cfg,
        );
        for (label, pl) in [("1 portal", &one), ("2 portals", &two)] {
            let s = AtPortalPoint::new(pl, SEES_NONE);
            assert_eq!(s.power(), 0.0);
            verify::assert_black(&format!("{name}: {label}, sees none"), &s, 20_000);
        }
    }
}

/// One portal straight behind another as seen from the point: directions through
/// both count both portals' densities.
#[test]
fn overlapping_portals_and_a_trapezoid() {
    let l = light(verify::maps::gradient(64, 32));
    let upper = [
        v(1.0, 1.0, 3.0),
        v(3.0, 1.0, 3.0),
        v(3.0, 2.0, 3.0),
        v(1.0, 2.0, 3.0),
    ];
    let pl = portals(&l, &[skylight(), upper]);
    check("overlapping portals", &pl, CENTRE, &PortalConfig::SYNTHETIC);
    // A trapezoid: samples outside it (in its bounding box) are refused, and ∫p
    // equals the acceptance rate.
    let trapezoid = [
        v(4.0, 1.0, 0.8),
        v(4.0, 2.2, 0.8),
        v(4.0, 1.9, 1.9),
        v(4.0, 1.3, 1.9),
    ];
    let pl = portals(&l, &[trapezoid]);
    let r = check("trapezoid window", &pl, CENTRE, &PortalConfig::SYNTHETIC);
    assert!(
        r.acceptance() < 0.95 && r.acceptance() > 0.5,
        "{}",
        r.acceptance()
    );
}

#[test]
fn real_maps() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/envmaps");
    let path = dir.join("sunrise.exr");
    if !path.is_file() {
        println!("skipping real maps: {} not found", path.display());
        return;
    }
    let loaded = envlight::load::load(&path, &envlight::load::LoadOptions::default()).unwrap();
    let l = light(loaded.image);
    let one = portals(&l, &[window()]);
    let two = portals(&l, &[window(), skylight()]);
    let cfg = PortalConfig::REAL_MAP;
    check("sunrise: 1 portal near the window", &one, NEAR_WINDOW, &cfg);
    check("sunrise: 2 portals, room centre", &two, CENTRE, &cfg);
    check(
        "sunrise: 2 portals near the window",
        &two,
        NEAR_WINDOW,
        &cfg,
    );
    verify::assert_black(
        "sunrise: sees none",
        &AtPortalPoint::new(&two, SEES_NONE),
        20_000,
    );
}

/// The checks reject a light whose portal is off by a little, and a pdf without
/// the rectification's Jacobian.
#[test]
fn broken_variants_are_rejected() {
    let l = light(verify::maps::gradient(64, 32));
    let cfg = PortalConfig {
        samples: 300_000,
        ..PortalConfig::SYNTHETIC
    };
    let truth = [window(), skylight()];
    for (label, shift) in [("outwards", 0.02f32), ("inwards", -0.02)] {
        // Corner 3 of the window moved 2 cm along +y and +z (out of / into the quad).
        let mut off = window();
        off[2] = v(off[2].x, off[2].y + shift, off[2].z + shift);
        let pl = portals(&l, &[off, skylight()]);
        let s = AtPortalPoint::with_geometry(&pl, NEAR_WINDOW, &truth);
        let r = verify::run_portal(&s, &cfg);
        let failures = r.failures();
        println!("corner off {label}: {failures:#?}");
        assert!(!failures.is_empty(), "a corner 2 cm {label} went unnoticed");
    }
    let pl = portals(&l, &truth);
    for p in [NEAR_WINDOW, CENTRE] {
        let s = AtPortalPoint::new(&pl, p).variant(PortalVariant::NoJacobian);
        let r = verify::run_portal(&s, &cfg);
        let failures = r.failures();
        println!("no Jacobian: {failures:#?}");
        assert!(
            failures.iter().any(|f| f.starts_with("normalisation")),
            "{failures:?}"
        );
    }
}
