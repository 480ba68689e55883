//! The visibility cache (docs/design.md §10) through the invariant harness, at
//! fixed points of a synthetic room lit through one window, against the
//! unoccluded integrand `Y · cos⁺` (its pdf must cover all of it, whatever the
//! rays saw); the broken variants rejected; the callback's errors; and the
//! variance it saves against the product sampler alone, in that room, under
//! slatted roofs and in the open.
//!
//! Statistics as in `tests/product.rs` (`Config::SYNTHETIC`: chi-square at
//! α = 1e-3 with 1M samples, consistency over 200k samples, unbiasedness at 4
//! standard errors), fixed seeds.

use envlight::visibility::{VisibilityError, VisibilityOptions};
use envlight::{
    EnvironmentLight, Factor, LightOptions, ProductOptions, ProductSampler, Vec3, VisibilityCache,
};
use envlight_verify::{
    self as verify, AtVisibilityPoint, Config, SphereSampler, VisibilityVariant,
};
use std::sync::Arc;

/// The room: the box `[-1, 1]² × [0, 2]`, open only through a window in the
/// `+x` wall (`|y| < 0.4`, `0.6 < z < 1.4`); with `roof`, also through the
/// ceiling where `|x| < 0.5`.
#[derive(Clone, Copy)]
struct Room {
    roof: bool,
}

/// A scene as the cache's callback sees it.
trait Blocker {
    /// The transmittance of the ray from `o` along unit `d`: 1 if it reaches the
    /// sky, else 0.
    fn transmittance(&self, o: Vec3, d: Vec3) -> f32;

    fn trace(&self) -> impl FnMut(&[Vec3], &[Vec3], &mut [f32]) -> Result<(), String> + '_ {
        move |o, d, t| {
            for ((o, d), t) in o.iter().zip(d).zip(t.iter_mut()) {
                *t = self.transmittance(*o, *d);
            }
            Ok(())
        }
    }
}

impl Blocker for Room {
    /// 1 when the ray from `o` (inside the box) along `d` leaves through an
    /// opening, else 0.
    fn transmittance(&self, o: Vec3, d: Vec3) -> f32 {
        let exit = |o: f32, d: f32, lo: f32, hi: f32| {
            if d > 0.0 {
                (hi - o) / d
            } else if d < 0.0 {
                (lo - o) / d
            } else {
                f32::INFINITY
            }
        };
        let t = [
            exit(o.x, d.x, -1.0, 1.0),
            exit(o.y, d.y, -1.0, 1.0),
            exit(o.z, d.z, 0.0, 2.0),
        ];
        let (axis, &t) = t
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(b.1))
            .unwrap();
        let p = o + d * t;
        let open = match axis {
            0 => d.x > 0.0 && p.y.abs() < 0.4 && p.z > 0.6 && p.z < 1.4,
            2 => self.roof && d.z > 0.0 && p.x.abs() < 0.5,
            _ => false,
        };
        open as u8 as f32
    }
}

/// A slatted roof over the ground: slats along `y`, `width` wide every
/// `pitch`, at height 2 over `|x|, |y| < 3`, open on every side; below `z = 0`,
/// the ground.
struct Slats {
    width: f32,
    pitch: f32,
}

impl Blocker for Slats {
    fn transmittance(&self, o: Vec3, d: Vec3) -> f32 {
        if d.z <= 0.0 {
            return (d.z == 0.0 && o.z > 0.0) as u8 as f32;
        }
        let t = (2.0 - o.z) / d.z;
        let (x, y) = (o.x + d.x * t, o.y + d.y * t);
        let under = x.abs() < 3.0 && y.abs() < 3.0;
        let on_slat = (x / self.pitch).rem_euclid(1.0) < self.width / self.pitch;
        !(under && on_slat) as u8 as f32
    }
}

/// The open: the ground, and one box `[1, 2] × [-0.5, 0.5] × [0, 1]` on it.
struct Open;

impl Blocker for Open {
    fn transmittance(&self, o: Vec3, d: Vec3) -> f32 {
        if d.z <= 0.0 {
            return 0.0;
        }
        // The ray against the box's slabs.
        let (mut near, mut far) = (0.0f32, f32::INFINITY);
        for (o, d, lo, hi) in [
            (o.x, d.x, 1.0, 2.0),
            (o.y, d.y, -0.5, 0.5),
            (o.z, d.z, 0.0, 1.0),
        ] {
            if d == 0.0 {
                if o < lo || o > hi {
                    return 1.0;
                }
                continue;
            }
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            near = near.max(a.min(b));
            far = far.min(a.max(b));
        }
        (near > far) as u8 as f32
    }
}

/// Points on the floor (normal up) and on the `-x` wall (normal `+x`): what a
/// camera in the room would hit.
fn room_points() -> (Vec<Vec3>, Vec<Vec3>) {
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..40 {
        for j in 0..40 {
            let (a, b) = ((i as f32 + 0.5) / 20.0 - 1.0, (j as f32 + 0.5) / 20.0 - 1.0);
            points.push(Vec3::new(a, b, 0.0));
            normals.push(Vec3::new(0.0, 0.0, 1.0));
            points.push(Vec3::new(-1.0, a, b + 1.0));
            normals.push(Vec3::new(1.0, 0.0, 0.0));
        }
    }
    (points, normals)
}

fn sky_product() -> Arc<ProductSampler> {
    let light = EnvironmentLight::new(envlight::builtin::sky(128, 64), LightOptions::default())
        .expect("the built-in sky builds");
    Arc::new(ProductSampler::new(
        Arc::new(light),
        ProductOptions::default(),
    ))
}

fn room_cache(room: Room, options: &VisibilityOptions) -> VisibilityCache {
    let (points, normals) = room_points();
    VisibilityCache::build(sky_product(), &points, &normals, options, room.trace())
        .expect("the room's cache builds")
}

const FLOOR: Vec3 = Vec3::new(0.1, -0.2, 0.0);
const UP: Vec3 = Vec3::new(0.0, 0.0, 1.0);
const WALL: Vec3 = Vec3::new(-1.0, 0.3, 1.1);
const EAST: Vec3 = Vec3::new(1.0, 0.0, 0.0);

/// The harness at a floor point (normal up) and a wall point (normal +x), both
/// with an entry that learned something.
fn assert_invariants_on_floor_and_wall(cache: &VisibilityCache) {
    for (case, position, normal) in [("floor", FLOOR, UP), ("wall", WALL, EAST)] {
        let factor = Factor::cosine(normal);
        let s = AtVisibilityPoint::new(cache, position, factor, VisibilityVariant::Exact);
        assert!(s.learned_share() > 0.0, "{case}: no learned share");
        verify::assert_invariants(case, &s, &s.integrand(), &Config::SYNTHETIC);
    }
}

#[test]
fn the_cache_in_a_room_passes_the_harness() {
    let cache = room_cache(Room { roof: false }, &VisibilityOptions::default());
    let summary = cache.summary();
    println!("{summary:?}");
    assert!(
        summary.entries > 0 && summary.mean_visibility < 0.5,
        "{summary:?}"
    );
    assert_invariants_on_floor_and_wall(&cache);
}

#[test]
fn a_cache_that_saw_everything_blocked_stays_unbiased() {
    // A tracer that reports every ray blocked: every estimate is the prior's
    // floor, and the product share keeps the whole sky sampled.
    let (points, normals) = room_points();
    let blocked = |_: &[Vec3], _: &[Vec3], t: &mut [f32]| -> Result<(), String> {
        t.fill(0.0);
        Ok(())
    };
    let cache = VisibilityCache::build(
        sky_product(),
        &points,
        &normals,
        &VisibilityOptions::default(),
        blocked,
    )
    .unwrap();
    let s = AtVisibilityPoint::new(&cache, FLOOR, Factor::cosine(UP), VisibilityVariant::Exact);
    verify::assert_invariants("all blocked", &s, &s.integrand(), &Config::SYNTHETIC);
}

#[test]
fn a_point_without_an_entry_samples_the_product() {
    let cache = room_cache(Room { roof: false }, &VisibilityOptions::default());
    let outside = Vec3::new(40.0, 40.0, 40.0);
    let factor = Factor::cosine(UP);
    assert_eq!(cache.entry_of(outside, UP), None);
    let point = cache.at(outside, &factor);
    let product = cache.product().at(&factor);
    for k in 0..1000 {
        let xi = envlight::rng::xi_2d(3, k);
        let (a, b) = (point.sample(xi), product.sample(xi));
        assert_eq!(
            a.map(|s| (s.direction, s.pdf)),
            b.map(|s| (s.direction, s.pdf))
        );
    }
}

#[test]
fn broken_pdf_without_the_plain_share_is_rejected() {
    let cache = room_cache(Room { roof: false }, &VisibilityOptions::default());
    let s = AtVisibilityPoint::new(
        &cache,
        FLOOR,
        Factor::cosine(UP),
        VisibilityVariant::WithoutPlainShare,
    );
    let norm = verify::normalisation(&s);
    println!("[{}]\n  {norm}", s.name());
    assert!(norm.verdict(false).is_err(), "{norm}");
}

#[test]
fn broken_pdf_at_another_entry_is_rejected() {
    // The pdf of a wall entry, the samples of a floor one (same normal given,
    // so only the position's entry differs).
    let cache = room_cache(Room { roof: true }, &VisibilityOptions::default());
    let elsewhere = Vec3::new(0.9, 0.9, 0.0);
    assert_ne!(cache.entry_of(FLOOR, UP), cache.entry_of(elsewhere, UP));
    let s = AtVisibilityPoint::new(
        &cache,
        FLOOR,
        Factor::cosine(UP),
        VisibilityVariant::EntryOf(elsewhere),
    );
    let chi = verify::chi_square(&s, 1_000_000, 11, 4096);
    println!("[{}]\n  {chi}", s.name());
    assert!(chi.verdict().is_err(), "{chi}");
}

#[test]
fn the_callbacks_errors_and_bad_points_are_reported() {
    let product = sky_product();
    let (points, normals) = room_points();
    let options = VisibilityOptions::default();
    let failing = |_: &[Vec3], _: &[Vec3], _: &mut [f32]| Err("out of rays".to_string());
    match VisibilityCache::build(product.clone(), &points, &normals, &options, failing) {
        Err(VisibilityError::Trace(e)) => assert_eq!(e, "out of rays"),
        other => panic!("{other:?}"),
    }
    for bad in [f32::NAN, -0.5, 1.5] {
        let wrong = |_: &[Vec3], _: &[Vec3], t: &mut [f32]| -> Result<(), String> {
            t.fill(0.5);
            t[7] = bad;
            Ok(())
        };
        let e = VisibilityCache::build(product.clone(), &points, &normals, &options, wrong)
            .unwrap_err();
        assert!(
            matches!(e, VisibilityError::Transmittance { ray: 7, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("ray 7"), "{e}");
    }
    let refused = |points: &[Vec3], normals: &[Vec3]| {
        let trace = Room { roof: false }.trace();
        VisibilityCache::build(product.clone(), points, normals, &options, trace)
            .unwrap_err()
            .to_string()
    };
    let mut bad_points = points.clone();
    bad_points[5].y = f32::INFINITY;
    let e = refused(&bad_points, &normals);
    assert!(e.starts_with("point 5:"), "{e}");
    let mut bad_normals = normals.clone();
    bad_normals[9] = Vec3::new(0.0, 0.0, 0.0);
    let e = refused(&points, &bad_normals);
    assert!(e.starts_with("point 9:"), "{e}");
}

/// The variance of `L_Y · cos⁺ · V / p` over `n` samples at `(position, normal)`,
/// `V` the room's own visibility: the irradiance a renderer estimates there.
fn irradiance_variance(
    room: &impl Blocker,
    n: u64,
    sample: impl Fn([f32; 2]) -> Option<envlight::LightSample>,
    position: Vec3,
    normal: Vec3,
) -> (f64, f64) {
    let (mut sum, mut sum2) = (0.0, 0.0);
    for k in 0..n {
        let value = sample(envlight::rng::xi_2d(17, k)).map_or(0.0, |s| {
            let y = envlight::color::luminance(s.radiance) as f64;
            let cos = normal.dot(s.direction).max(0.0) as f64;
            y * cos * room.transmittance(position, s.direction) as f64 / s.pdf as f64
        });
        sum += value;
        sum2 += value * value;
    }
    let mean = sum / n as f64;
    (mean, sum2 / n as f64 - mean * mean)
}

/// Ground points, normal up, on a `40 × 40` grid over `[-r, r]²`, but for those
/// `inside`.
fn ground_points(r: f32, inside: impl Fn(Vec3) -> bool) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut points = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            let (a, b) = ((i as f32 + 0.5) / 20.0 - 1.0, (j as f32 + 0.5) / 20.0 - 1.0);
            let p = Vec3::new(a * r, b * r, 0.0);
            if !inside(p) {
                points.push(p);
            }
        }
    }
    let normals = vec![UP; points.len()];
    (points, normals)
}

/// The cache's irradiance variance over the product sampler's at equal samples,
/// summed over `at` (each point's own variance: what an image's squared error
/// adds up), with both means checked against each other at every point.
fn variance_ratio(
    name: &str,
    scene: &impl Blocker,
    points: &[Vec3],
    normals: &[Vec3],
    at: &[(Vec3, Vec3)],
) -> f64 {
    let cache = VisibilityCache::build(
        sky_product(),
        points,
        normals,
        &VisibilityOptions::default(),
        scene.trace(),
    )
    .expect("the cache builds");
    let n = 200_000;
    let (mut cache_sum, mut product_sum) = (0.0, 0.0);
    for &(position, normal) in at {
        let factor = Factor::cosine(normal);
        let (point, product) = (cache.at(position, &factor), cache.product().at(&factor));
        let (m_c, v_c) = irradiance_variance(scene, n, |xi| point.sample(xi), position, normal);
        let (m_p, v_p) = irradiance_variance(scene, n, |xi| product.sample(xi), position, normal);
        println!(
            "{name} at {:?}: share {:.3}, irradiance cache {m_c:.5} product {m_p:.5}, variance ratio {:.3}",
            position.to_array(),
            point.learned_share(),
            v_c / v_p
        );
        // Unbiased: both estimate the same irradiance (4 standard errors).
        let se = ((v_c + v_p) / n as f64).sqrt();
        assert!((m_c - m_p).abs() < 4.0 * se, "{name}: {m_c} vs {m_p}");
        cache_sum += v_c;
        product_sum += v_p;
    }
    cache_sum / product_sum
}

#[test]
fn the_variance_it_saves_in_a_room_under_slats_and_in_the_open() {
    // The targets at equal samples: a room lit through one window
    // ≤ 0.2× the product sampler's variance, a slatted roof ≤ 0.8×, the open
    // ≤ 1.15× (no harm).
    let (points, normals) = room_points();
    let room = variance_ratio(
        "room",
        &Room { roof: false },
        &points,
        &normals,
        &[(FLOOR, UP), (Vec3::new(-0.6, 0.5, 0.0), UP), (WALL, EAST)],
    );
    // Under the slats: the ground from which the built-in sky's sun (towards
    // (0.41, 0.71, 0.57)) is seen through the roof, on a 3 × 3 grid.
    let (points, normals) = ground_points(2.5, |_| false);
    let at: Vec<(Vec3, Vec3)> = (0..9)
        .map(|i| {
            let (x, y) = (-2.0 + 1.3 * (i % 3) as f32, -2.0 + 1.1 * (i / 3) as f32);
            (Vec3::new(x, y, 0.0), UP)
        })
        .collect();
    let beams = Slats {
        width: 0.5,
        pitch: 1.0,
    };
    let slats = variance_ratio("slats", &beams, &points, &normals, &at);
    let fine = Slats {
        width: 0.12,
        pitch: 0.3,
    };
    let fine = variance_ratio("fine slats", &fine, &points, &normals, &at);
    let (points, normals) = ground_points(3.0, |p| (1.0..=2.0).contains(&p.x) && p.y.abs() <= 0.5);
    let spots = [
        Vec3::new(0.8, 0.1, 0.0),
        Vec3::new(2.3, -0.6, 0.0),
        Vec3::new(-1.5, 1.5, 0.0),
    ];
    let at: Vec<(Vec3, Vec3)> = spots.iter().map(|&p| (p, UP)).collect();
    let open = variance_ratio("open", &Open, &points, &normals, &at);
    println!(
        "variance over the product's: room {room:.3}, slats {slats:.3}, fine slats {fine:.3}, open {open:.3}"
    );
    assert!(room <= 0.2, "room: {room}");
    assert!(slats <= 0.8, "slats: {slats}");
    assert!(fine <= 1.15, "fine slats: {fine}");
    assert!(open <= 1.15, "open: {open}");
}

#[test]
fn a_saved_cache_loads_and_samples_the_same() {
    let cache = room_cache(Room { roof: true }, &VisibilityOptions::default());
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("room.envlvis");
    cache.save(&path, "room v1").unwrap();
    let loaded =
        VisibilityCache::load(&path, Arc::new(cache.product().clone()), "room v1").unwrap();
    assert_eq!(loaded.summary(), cache.summary());
    let factor = Factor::cosine(UP);
    for position in [FLOOR, Vec3::new(-0.7, 0.6, 0.0)] {
        let (a, b) = (cache.at(position, &factor), loaded.at(position, &factor));
        for k in 0..2000 {
            let xi = envlight::rng::xi_2d(5, k);
            let (sa, sb) = (a.sample(xi).unwrap(), b.sample(xi).unwrap());
            assert_eq!(
                (sa.direction, sa.pdf.to_bits()),
                (sb.direction, sb.pdf.to_bits())
            );
        }
    }
    assert_eq!(
        std::fs::read(&path).unwrap(),
        loaded.to_bytes("room v1").unwrap(),
        "save, load and save again: the same bytes"
    );
}

#[test]
fn a_cache_for_another_scene_or_light_is_refused() {
    let cache = room_cache(Room { roof: false }, &VisibilityOptions::default());
    let bytes = cache.to_bytes("room v1").unwrap();
    let product = Arc::new(cache.product().clone());
    let e = VisibilityCache::from_bytes(&bytes, "room.envlvis", product, "room v2").unwrap_err();
    let message = e.to_string();
    assert!(matches!(e, envlight::Error::Mismatch { .. }), "{message}");
    assert!(
        message.contains("\"room v1\"") && message.contains("\"room v2\""),
        "{message}"
    );
    let rotated = EnvironmentLight::new(
        envlight::builtin::sky(128, 64),
        LightOptions {
            rotation: envlight::Rotation::about_z_degrees(10.0),
            ..Default::default()
        },
    )
    .unwrap();
    let other = Arc::new(ProductSampler::new(
        Arc::new(rotated),
        ProductOptions::default(),
    ));
    let e = VisibilityCache::from_bytes(&bytes, "room.envlvis", other, "room v1").unwrap_err();
    assert!(matches!(e, envlight::Error::Mismatch { .. }), "{e}");
}

#[test]
fn a_damaged_cache_file_is_an_error_never_a_panic() {
    // Every truncation, and single-byte changes all over the file: a decode
    // error (or, for a change that leaves a valid cache, a cache), never a panic.
    let (points, normals) = room_points();
    let product = Arc::new(ProductSampler::new(
        Arc::new(
            EnvironmentLight::new(envlight::builtin::sky(32, 16), LightOptions::default()).unwrap(),
        ),
        ProductOptions {
            patches: Some([8, 4]),
            ..Default::default()
        },
    ));
    let options = VisibilityOptions {
        target_entries: 8,
        ..Default::default()
    };
    let cache = VisibilityCache::build(
        product.clone(),
        &points[..200],
        &normals[..200],
        &options,
        Room { roof: true }.trace(),
    )
    .unwrap();
    let bytes = cache.to_bytes("k").unwrap();
    for n in 0..bytes.len() {
        let e = VisibilityCache::from_bytes(&bytes[..n], "cut", product.clone(), "k").unwrap_err();
        assert!(
            matches!(e, envlight::Error::Decode { .. }),
            "cut at {n}: {e}"
        );
    }
    let mut rng = envlight::rng::SplitMix64::new(9);
    for _ in 0..5000 {
        let mut damaged = bytes.clone();
        let at = (rng.next_u64() % damaged.len() as u64) as usize;
        damaged[at] = rng.next_u64() as u8;
        match VisibilityCache::from_bytes(&damaged, "damaged", product.clone(), "k") {
            Ok(c) => {
                let point = c.at(FLOOR, &Factor::cosine(UP));
                if let Some(s) = point.sample([0.3, 0.7]) {
                    assert!(s.pdf > 0.0 && s.pdf.is_finite());
                }
            }
            Err(e) => assert!(
                matches!(
                    e,
                    envlight::Error::Decode { .. } | envlight::Error::Mismatch { .. }
                ),
                "{e}"
            ),
        }
    }
}

#[test]
fn a_rotated_small_map_in_the_room_passes_the_harness() {
    // About one patch per cell of a 64 × 32 map turned 30° about z: the cache's
    // patches, bounds and directions all go through the light's rotation.
    // A random 64 × 32 map (envlight-verify's synthetic maps): light from every
    // direction, so both points' entries have some to learn.
    let image = envlight_verify::maps::random(64, 32, 7);
    let options = LightOptions {
        rotation: envlight::Rotation::about_z_degrees(30.0),
        ..Default::default()
    };
    let light = EnvironmentLight::new(image, options).unwrap();
    let product = Arc::new(ProductSampler::new(
        Arc::new(light),
        ProductOptions::default(),
    ));
    let (points, normals) = room_points();
    let cache = VisibilityCache::build(
        product,
        &points,
        &normals,
        &VisibilityOptions::default(),
        Room { roof: true }.trace(),
    )
    .unwrap();
    assert_invariants_on_floor_and_wall(&cache);
}
