//! The visibility cache through the C API: a room lit through one window, traced
//! by an `extern "C"` callback; samples, pdfs and summaries equal the library's
//! bit for bit; saved and loaded back; every error a status and a message.

use super::*;

#[path = "../../tests/common/room.rs"]
mod room;
use room::room_transmittance;

/// What the room's callback saw: its calls and rays; `fail` makes it return that
/// status, `bad` makes it write that transmittance to ray 3 of each batch.
#[derive(Default)]
struct Tracer {
    calls: usize,
    rays: u64,
    fail: i32,
    bad: Option<f32>,
}

/// The room as an `envlight_visibility_trace`; `user` is a `Tracer`.
unsafe extern "C" fn room_trace(
    user: *mut std::ffi::c_void,
    origins: *const f32,
    directions: *const f32,
    count: usize,
    transmittance: *mut f32,
) -> i32 {
    // SAFETY: the build passes `count · 3` floats at `origins` and `directions`,
    // `count` writable floats at `transmittance`, and the tests' `user` is a
    // `Tracer` that nothing else touches during the build.
    let (tracer, o, d, t) = unsafe {
        (
            &mut *user.cast::<Tracer>(),
            std::slice::from_raw_parts(origins, 3 * count),
            std::slice::from_raw_parts(directions, 3 * count),
            std::slice::from_raw_parts_mut(transmittance, count),
        )
    };
    tracer.calls += 1;
    tracer.rays += count as u64;
    if tracer.fail != 0 {
        return tracer.fail;
    }
    for (k, t) in t.iter_mut().enumerate() {
        let three = |v: &[f32]| [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
        *t = room_transmittance(three(o), three(d));
    }
    if let Some(bad) = tracer.bad {
        t[3.min(count - 1)] = bad;
    }
    0
}

/// Points on the room's floor (normal up) and on its `-x` wall (normal `+x`),
/// flat.
fn room_points() -> (Vec<f32>, Vec<f32>) {
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for i in 0..20 {
        for j in 0..20 {
            let (a, b) = ((i as f32 + 0.5) / 10.0 - 1.0, (j as f32 + 0.5) / 10.0 - 1.0);
            points.extend([a, b, 0.0]);
            normals.extend([0.0, 0.0, 1.0]);
            points.extend([-1.0, a, b + 1.0]);
            normals.extend([1.0, 0.0, 0.0]);
        }
    }
    (points, normals)
}

/// The options the tests build with: the defaults with their own seed and fewer
/// rays.
fn room_options() -> envlight_visibility_options {
    envlight_visibility_options {
        seed: 7,
        rays_per_patch: 2,
        ..envlight_visibility_options_default()
    }
}

/// The room's cache through the C API over `product`, and what the callback saw.
fn build_room(
    product: *const envlight_product,
    options: &envlight_visibility_options,
) -> (*mut envlight_visibility_cache, Tracer) {
    let (points, normals) = room_points();
    let mut tracer = Tracer::default();
    let mut cache = null_mut();
    let status = envlight_visibility_cache_build(
        product,
        points.as_ptr(),
        normals.as_ptr(),
        points.len() / 3,
        options,
        Some(room_trace),
        (&mut tracer as *mut Tracer).cast(),
        &mut cache,
    );
    assert_eq!(status, envlight_status::ENVLIGHT_OK, "{}", last_error());
    assert!(!cache.is_null());
    (cache, tracer)
}

/// Shading points to query at: inside the room (floor, wall), outside every
/// entry, a long normal (`k % 12 == 5`), a zero normal (`k % 12 == 11`).
fn query_points(n: usize) -> (Vec<f32>, Vec<f32>) {
    let (mut points, mut normals) = (Vec::new(), Vec::new());
    for k in 0..n {
        let a = (k as f32 * 0.618_034).fract() * 1.8 - 0.9;
        let b = (k as f32 * 0.414_214).fract() * 1.8 - 0.9;
        let (p, n) = match k % 6 {
            0 | 1 => ([a, b, 0.0], [0.0, 0.0, 1.0]),
            2 | 3 => ([-1.0, a, b + 1.0], [1.0, 0.0, 0.0]),
            4 => ([5.0 + a, b, 3.0], [0.0, 0.0, 1.0]),
            _ if k % 12 == 5 => ([a, b, 0.0], [0.0, 0.0, 3.0]),
            _ => ([a, b, 0.0], [0.0, 0.0, 0.0]),
        };
        points.extend(p);
        normals.extend(n);
    }
    (points, normals)
}

fn summary_bits(s: &envlight_visibility_summary) -> [u64; 5] {
    [
        s.entries,
        s.bytes,
        s.radius.to_bits() as u64,
        s.mean_visibility.to_bits(),
        s.rays,
    ]
}

/// Samples and pdfs through the C cache, single and batch, equal the library's
/// own cache built from the same points, rays and options, bit for bit.
fn assert_cache_equals(
    c: *const envlight_visibility_cache,
    rust: &envlight::VisibilityCache,
    points: &[f32],
    normals: &[f32],
) {
    let n = points.len() / 3;
    let u: Vec<f32> = (0..n as u64)
        .flat_map(|k| envlight::rng::xi_2d(21, k))
        .collect();
    let dirs: Vec<f32> = (0..n as u64)
        .flat_map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(22, k)).to_array())
        .collect();
    let mut batch = vec![envlight_sample::default(); n];
    assert_eq!(
        envlight_visibility_cache_sample_batch(
            c,
            points.as_ptr(),
            normals.as_ptr(),
            u.as_ptr(),
            n,
            batch.as_mut_ptr()
        ),
        envlight_status::ENVLIGHT_OK,
        "{}",
        last_error()
    );
    let drawn: Vec<f32> = batch.iter().flat_map(|s| s.direction).collect();
    let (mut pdf_drawn, mut pdf_dirs) = (vec![0.0f32; n], vec![0.0f32; n]);
    for (dirs, pdf) in [(&drawn, &mut pdf_drawn), (&dirs, &mut pdf_dirs)] {
        assert_eq!(
            envlight_visibility_cache_pdf_batch(
                c,
                points.as_ptr(),
                normals.as_ptr(),
                dirs.as_ptr(),
                n,
                pdf.as_mut_ptr()
            ),
            envlight_status::ENVLIGHT_OK,
            "{}",
            last_error()
        );
    }
    let (mut drew, mut learned) = (0, 0);
    for k in 0..n {
        let three = |v: &[f32]| [v[3 * k], v[3 * k + 1], v[3 * k + 2]];
        let (p, nrm, d) = (three(points), three(normals), three(&dirs));
        let at = rust.at(vec3(p), &envlight::Factor::cosine(vec3(nrm)));
        learned += (at.learned_share() > 0.0) as usize;
        let xi = [u[2 * k], u[2 * k + 1]];
        let expected = to_c(at.sample(xi));
        let mut single = envlight_sample::default();
        let ok =
            envlight_visibility_cache_sample(c, p.as_ptr(), nrm.as_ptr(), xi.as_ptr(), &mut single);
        assert_eq!(ok, expected.pdf > 0.0, "row {k}");
        drew += ok as usize;
        assert_eq!(bits(&single), bits(&expected), "sample {k}");
        assert_eq!(bits(&batch[k]), bits(&expected), "batch sample {k}");
        // The pdf of the drawn direction is the sample's; none drawn, 0.
        let at_drawn =
            envlight_visibility_cache_pdf(c, p.as_ptr(), nrm.as_ptr(), single.direction.as_ptr());
        assert_eq!(
            at_drawn.to_bits(),
            single.pdf.to_bits(),
            "pdf of sample {k}"
        );
        assert_eq!(
            pdf_drawn[k].to_bits(),
            single.pdf.to_bits(),
            "batch pdf of sample {k}"
        );
        let expected = at.pdf(vec3(d));
        let single = envlight_visibility_cache_pdf(c, p.as_ptr(), nrm.as_ptr(), d.as_ptr());
        assert_eq!(single.to_bits(), expected.to_bits(), "pdf {k}");
        assert_eq!(pdf_dirs[k].to_bits(), expected.to_bits(), "batch pdf {k}");
    }
    // Most rows drew (not the zero normals'), many through a learned entry.
    assert!(
        drew > n / 2 && learned > n / 4,
        "{drew} drawn, {learned} learned of {n}"
    );
}

#[test]
fn the_visibility_cache_equals_the_librarys_bit_for_bit() {
    let light = build(&envlight_light_options_default());
    // SAFETY: `build` returned a light from envlight_light_from_rgb (asserted OK,
    // so non-NULL), read here before envlight_light_free below.
    let rust_light = unsafe { &*light }.light.clone();
    let mut product = null_mut();
    assert_eq!(
        envlight_product_new(light, &mut product),
        envlight_status::ENVLIGHT_OK
    );
    envlight_light_free(light);
    let options = room_options();
    let (cache, tracer) = build_room(product, &options);
    // The cache keeps the product sampler alive.
    envlight_product_free(product);

    let rust_product = std::sync::Arc::new(envlight::ProductSampler::new(
        rust_light,
        envlight::ProductOptions::default(),
    ));
    let (points, normals) = room_points();
    let mut rays = 0u64;
    let rust = envlight::VisibilityCache::build(
        rust_product,
        as_vec3_owned(&points).as_slice(),
        as_vec3_owned(&normals).as_slice(),
        &crate::visibility::visibility_options(&options, "test").unwrap(),
        |o: &[envlight::Vec3], d: &[envlight::Vec3], t: &mut [f32]| -> Result<(), ()> {
            rays += o.len() as u64;
            for ((o, d), t) in o.iter().zip(d).zip(t.iter_mut()) {
                *t = room_transmittance(o.to_array(), d.to_array());
            }
            Ok(())
        },
    )
    .unwrap();

    let mut summary = envlight_visibility_summary::default();
    assert_eq!(
        envlight_visibility_cache_summary(cache, &mut summary),
        envlight_status::ENVLIGHT_OK
    );
    let s = rust.summary();
    let expected = envlight_visibility_summary {
        entries: s.entries as u64,
        bytes: s.bytes as u64,
        radius: s.radius,
        mean_visibility: s.mean_visibility,
        rays: s.rays,
    };
    assert_eq!(summary_bits(&summary), summary_bits(&expected));
    assert_eq!((summary.rays, tracer.rays), (rays, rays));
    assert!(tracer.calls >= 1 && summary.entries > 10, "{summary:?}");
    assert!(summary.mean_visibility < 0.5, "{summary:?}");

    // More than one parallel chunk of the batch calls.
    let (points, normals) = query_points(2 * crate::sample::CHUNK + 100);
    assert_cache_equals(cache, &rust, &points, &normals);
    // The zero normal's rows draw nothing, and their pdf is 0.
    let zero_normal = 11 * 3;
    let mut s = envlight_sample::default();
    assert!(!envlight_visibility_cache_sample(
        cache,
        points[zero_normal..].as_ptr(),
        normals[zero_normal..].as_ptr(),
        [0.5f32, 0.5].as_ptr(),
        &mut s
    ));
    assert_eq!(s, envlight_sample::default());
    // A non-finite u draws nothing.
    assert!(!envlight_visibility_cache_sample(
        cache,
        points.as_ptr(),
        normals.as_ptr(),
        [f32::NAN, 0.5].as_ptr(),
        &mut s
    ));
    envlight_visibility_cache_free(cache);
}

/// `points` (3 floats each) as vectors.
fn as_vec3_owned(v: &[f32]) -> Vec<envlight::Vec3> {
    v.chunks_exact(3)
        .map(|c| vec3([c[0], c[1], c[2]]))
        .collect()
}

#[test]
fn a_saved_visibility_cache_loads_back_the_same_for_its_light_and_key_only() {
    use envlight_status::*;
    let light = build(&envlight_light_options_default());
    let mut product = null_mut();
    assert_eq!(envlight_product_new(light, &mut product), ENVLIGHT_OK);
    let (cache, _) = build_room(product, &room_options());
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("room.envlvis");
    let path = std::ffi::CString::new(file.to_str().unwrap()).unwrap();
    let key = c"room v1";
    assert_eq!(
        envlight_visibility_cache_save(cache, path.as_ptr(), key.as_ptr()),
        ENVLIGHT_OK,
        "{}",
        last_error()
    );

    // The same light and key: the same cache, as the library reads it too.
    let mut loaded = null_mut();
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), product, key.as_ptr(), &mut loaded),
        ENVLIGHT_OK,
        "{}",
        last_error()
    );
    let (mut a, mut b) = (envlight_visibility_summary::default(), Default::default());
    envlight_visibility_cache_summary(cache, &mut a);
    envlight_visibility_cache_summary(loaded, &mut b);
    assert_eq!(summary_bits(&a), summary_bits(&b));
    let (points, normals) = query_points(300);
    // SAFETY: `cache` came from envlight_visibility_cache_build (asserted OK) and
    // is freed below, after this clone.
    let original = unsafe { &*cache }.cache.clone();
    assert_cache_equals(loaded, &original, &points, &normals);
    // SAFETY: `product` came from envlight_product_new (asserted OK) and is freed
    // below, after this clone of its sampler.
    let rust_product = unsafe { &*product }.product.clone();
    let rust = envlight::VisibilityCache::load(&file, rust_product, "room v1").unwrap();
    assert_cache_equals(loaded, &rust, &points, &normals);
    envlight_visibility_cache_free(loaded);

    // Another key, another light: a mismatch naming both.
    let mut out = std::ptr::dangling_mut();
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), product, c"room v2".as_ptr(), &mut out),
        ENVLIGHT_ERROR_MISMATCH
    );
    assert!(out.is_null());
    let message = last_error();
    assert!(
        message.contains("room.envlvis")
            && message.contains("\"room v1\"")
            && message.contains("\"room v2\""),
        "{message}"
    );
    let rotated = build(&envlight_light_options {
        rotate_deg: 30.0,
        ..envlight_light_options_default()
    });
    let mut other = null_mut();
    assert_eq!(envlight_product_new(rotated, &mut other), ENVLIGHT_OK);
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), other, key.as_ptr(), &mut out),
        ENVLIGHT_ERROR_MISMATCH
    );
    assert!(last_error().contains("made for light"), "{}", last_error());
    envlight_product_free(other);
    envlight_light_free(rotated);

    // Files that are not caches, or not there.
    let missing =
        std::ffi::CString::new(dir.path().join("none.envlvis").to_str().unwrap()).unwrap();
    assert_eq!(
        envlight_visibility_cache_load(missing.as_ptr(), product, key.as_ptr(), &mut out),
        ENVLIGHT_ERROR_NOT_FOUND
    );
    assert!(last_error().contains("none.envlvis"), "{}", last_error());
    let garbage = dir.path().join("garbage.envlvis");
    std::fs::write(&garbage, b"envlvis\0 but nothing after").unwrap();
    let garbage = std::ffi::CString::new(garbage.to_str().unwrap()).unwrap();
    assert_eq!(
        envlight_visibility_cache_load(garbage.as_ptr(), product, key.as_ptr(), &mut out),
        ENVLIGHT_ERROR_FORMAT
    );
    assert!(last_error().contains("garbage.envlvis"), "{}", last_error());
    let into_missing_folder =
        std::ffi::CString::new(dir.path().join("no/such/folder.envlvis").to_str().unwrap())
            .unwrap();
    assert_eq!(
        envlight_visibility_cache_save(cache, into_missing_folder.as_ptr(), key.as_ptr()),
        ENVLIGHT_ERROR_NOT_FOUND
    );
    assert!(last_error().contains("folder"), "{}", last_error());
    let long_key =
        std::ffi::CString::new("k".repeat(envlight::visibility::MAX_SCENE_KEY + 1)).unwrap();
    assert_eq!(
        envlight_visibility_cache_save(cache, path.as_ptr(), long_key.as_ptr()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    let not_utf8 = [0xffu8 as c_char, 0];
    assert_eq!(
        envlight_visibility_cache_save(cache, path.as_ptr(), not_utf8.as_ptr()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(
        last_error().contains("scene_key is not UTF-8"),
        "{}",
        last_error()
    );

    // NULL arguments.
    assert_eq!(
        envlight_visibility_cache_save(null(), path.as_ptr(), key.as_ptr()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("cache is NULL"));
    assert_eq!(
        envlight_visibility_cache_save(cache, null(), key.as_ptr()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("path is NULL"));
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), null(), key.as_ptr(), &mut out),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("product is NULL"));
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), product, null(), &mut out),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("scene_key is NULL"));
    assert_eq!(
        envlight_visibility_cache_load(path.as_ptr(), product, key.as_ptr(), null_mut()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("out is NULL"));
    envlight_visibility_cache_free(cache);
    envlight_product_free(product);
    envlight_light_free(light);
}

#[test]
fn visibility_cache_errors_are_statuses_with_messages() {
    use envlight_status::*;
    let light = build(&envlight_light_options_default());
    let mut product = null_mut();
    assert_eq!(envlight_product_new(light, &mut product), ENVLIGHT_OK);
    let (points, normals) = room_points();
    let n = points.len() / 3;
    let build_with = |tracer: &mut Tracer,
                      points: &[f32],
                      normals: &[f32],
                      options: *const envlight_visibility_options,
                      out: &mut *mut envlight_visibility_cache| {
        *out = std::ptr::dangling_mut();
        envlight_visibility_cache_build(
            product,
            points.as_ptr(),
            normals.as_ptr(),
            points.len() / 3,
            options,
            Some(room_trace),
            (tracer as *mut Tracer).cast(),
            out,
        )
    };
    let mut out = null_mut();

    // The callback's failure, with its status; it is not called again.
    let mut tracer = Tracer {
        fail: 5,
        ..Default::default()
    };
    assert_eq!(
        build_with(&mut tracer, &points, &normals, null(), &mut out),
        ENVLIGHT_ERROR_CALLBACK
    );
    assert!(out.is_null());
    assert_eq!(tracer.calls, 1);
    let message = last_error();
    assert!(
        message.starts_with("envlight_visibility_cache_build: the visibility callback failed")
            && message.contains("status 5"),
        "{message}"
    );
    // A transmittance that is NaN or outside [0, 1], named with its ray.
    for bad in [f32::NAN, 1.5, -0.25] {
        let mut tracer = Tracer {
            bad: Some(bad),
            ..Default::default()
        };
        assert_eq!(
            build_with(&mut tracer, &points, &normals, null(), &mut out),
            ENVLIGHT_ERROR_INVALID_ARGUMENT
        );
        assert!(out.is_null());
        let message = last_error();
        assert!(
            message.contains(&format!("transmittance {bad} for ray 3")),
            "{message}"
        );
    }
    // Points and normals the library refuses, named.
    let mut bad_points = points.clone();
    bad_points[3 * 7 + 1] = f32::INFINITY;
    assert_eq!(
        build_with(
            &mut Tracer::default(),
            &bad_points,
            &normals,
            null(),
            &mut out
        ),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("point 7"), "{}", last_error());
    let mut zero_normal = normals.clone();
    zero_normal[3 * 9..3 * 10].fill(0.0);
    assert_eq!(
        build_with(
            &mut Tracer::default(),
            &points,
            &zero_normal,
            null(),
            &mut out
        ),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("point 9"), "{}", last_error());
    // Options out of range, by their C names.
    let d = envlight_visibility_options_default();
    for (options, field) in [
        (
            envlight_visibility_options { radius: -1.0, ..d },
            "options.radius -1",
        ),
        (
            envlight_visibility_options {
                radius: f32::NAN,
                ..d
            },
            "options.radius NaN",
        ),
        (
            envlight_visibility_options {
                normal_bins: 0,
                ..d
            },
            "options.normal_bins 0",
        ),
        (
            envlight_visibility_options {
                target_entries: 0,
                ..d
            },
            "options.target_entries 0",
        ),
        (
            envlight_visibility_options {
                rays_per_patch: 5000,
                ..d
            },
            "options.rays_per_patch 5000",
        ),
        (
            envlight_visibility_options {
                learned_share: 1.0,
                ..d
            },
            "options.learned_share 1",
        ),
        (
            envlight_visibility_options { prior: 0.0, ..d },
            "options.prior 0",
        ),
        (
            envlight_visibility_options {
                reserved: [0, 0, 1, 0],
                ..d
            },
            "options.reserved",
        ),
    ] {
        let mut tracer = Tracer::default();
        assert_eq!(
            build_with(&mut tracer, &points, &normals, &options, &mut out),
            ENVLIGHT_ERROR_INVALID_ARGUMENT
        );
        assert!(out.is_null());
        assert!(last_error().contains(field), "{field}: {}", last_error());
        assert_eq!(tracer.calls, 0, "{field}: the options are checked first");
    }
    // NULL arguments.
    let mut tracer = Tracer::default();
    let user: *mut std::ffi::c_void = (&mut tracer as *mut Tracer).cast();
    // Each call's status and message, read at once.
    let call = |product, points, normals, trace, out| {
        let status =
            envlight_visibility_cache_build(product, points, normals, n, null(), trace, user, out);
        (status, last_error())
    };
    let (p, nn, tr) = (points.as_ptr(), normals.as_ptr(), Some(room_trace as _));
    for ((status, message), needle) in [
        (call(null(), p, nn, tr, &mut out), "product is NULL"),
        (call(product, null(), nn, tr, &mut out), "points is NULL"),
        (call(product, p, null(), tr, &mut out), "normals is NULL"),
        (call(product, p, nn, None, &mut out), "trace is NULL"),
        (call(product, p, nn, tr, null_mut()), "out is NULL"),
    ] {
        assert_eq!(status, ENVLIGHT_ERROR_INVALID_ARGUMENT, "{needle}");
        assert!(message.contains(needle), "{needle}: {message}");
    }
    assert_eq!(tracer.calls, 0);

    // No points: a cache with no entry, which samples as the product sampler.
    let mut empty = null_mut();
    assert_eq!(
        envlight_visibility_cache_build(
            product,
            null(),
            null(),
            0,
            null(),
            Some(room_trace),
            user,
            &mut empty
        ),
        ENVLIGHT_OK,
        "{}",
        last_error()
    );
    let mut summary = envlight_visibility_summary::default();
    assert_eq!(
        envlight_visibility_cache_summary(empty, &mut summary),
        ENVLIGHT_OK
    );
    assert_eq!((summary.entries, summary.rays), (0, 0));
    let (up, origin, xi) = ([0.0f32, 0.0, 1.0], [0.0f32; 3], [0.3f32, 0.7]);
    let (mut s, mut t) = (envlight_sample::default(), envlight_sample::default());
    assert!(envlight_visibility_cache_sample(
        empty,
        origin.as_ptr(),
        up.as_ptr(),
        xi.as_ptr(),
        &mut s
    ));
    let f = envlight_factor {
        normal: up,
        ..Default::default()
    };
    assert!(envlight_product_sample(product, &f, xi.as_ptr(), &mut t));
    assert_eq!(bits(&s), bits(&t));

    // Queries with NULL arguments: false / 0 / a status, and a message.
    let mut s = envlight_sample::default();
    assert!(!envlight_visibility_cache_sample(
        null(),
        origin.as_ptr(),
        up.as_ptr(),
        xi.as_ptr(),
        &mut s
    ));
    assert!(last_error().contains("cache is NULL"));
    assert!(!envlight_visibility_cache_sample(
        empty,
        origin.as_ptr(),
        null(),
        xi.as_ptr(),
        &mut s
    ));
    assert!(last_error().contains("normal is NULL"));
    assert!(!envlight_visibility_cache_sample(
        empty,
        origin.as_ptr(),
        up.as_ptr(),
        xi.as_ptr(),
        null_mut()
    ));
    assert!(last_error().contains("out is NULL"));
    assert_eq!(
        envlight_visibility_cache_pdf(empty, null(), up.as_ptr(), up.as_ptr()),
        0.0
    );
    assert!(last_error().contains("point is NULL"));
    assert_eq!(
        envlight_visibility_cache_pdf_batch(
            empty,
            origin.as_ptr(),
            null(),
            up.as_ptr(),
            1,
            null_mut()
        ),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("normals is NULL"));
    assert_eq!(
        envlight_visibility_cache_sample_batch(empty, null(), null(), null(), 0, null_mut()),
        ENVLIGHT_OK
    );
    assert_eq!(
        envlight_visibility_cache_sample_batch(
            empty,
            origin.as_ptr(),
            up.as_ptr(),
            xi.as_ptr(),
            usize::MAX / 4,
            null_mut()
        ),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert_eq!(
        envlight_visibility_cache_summary(empty, null_mut()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("summary is NULL"));
    assert_eq!(
        envlight_visibility_cache_summary(null(), &mut summary),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("cache is NULL"));
    envlight_visibility_cache_free(empty);
    envlight_visibility_cache_free(null_mut());
    envlight_product_free(product);
    envlight_light_free(light);
    // SAFETY: envlight_status_name returns a NUL-terminated static string.
    let name = unsafe { CStr::from_ptr(envlight_status_name(ENVLIGHT_ERROR_MISMATCH as u32)) };
    assert_eq!(name.to_str().unwrap(), "ENVLIGHT_ERROR_MISMATCH");
    // SAFETY: as above.
    let name = unsafe { CStr::from_ptr(envlight_status_name(ENVLIGHT_ERROR_CALLBACK as u32)) };
    assert_eq!(name.to_str().unwrap(), "ENVLIGHT_ERROR_CALLBACK");
}
