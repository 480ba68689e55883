//! The API called from Rust as C would call it: the same numbers as the library,
//! every error path a status and a message.

use super::*;
use crate::options::light_options;
use crate::sample::{to_c, vec3};
use envlight::light::{Density, Mapping, Sampler};
use envlight::{EnvImage, EnvironmentLight};
use std::ffi::{c_char, CStr};
use std::ptr::{null, null_mut};

// The visibility cache's tests, over the helpers here.
mod visibility;

/// A small sun-and-sky map.
fn sky() -> (Vec<f32>, u32, u32) {
    let image = envlight::builtin::sky(64, 32);
    let flat = image.texels().iter().flatten().copied().collect();
    (flat, 64, 32)
}

fn last_error() -> String {
    let n = envlight_last_error(null_mut(), 0);
    let mut buf = vec![0 as c_char; n + 1];
    assert_eq!(envlight_last_error(buf.as_mut_ptr(), buf.len()), n);
    // SAFETY: `buf` is zero-filled, and envlight_last_error wrote at most
    // `buf.len() - 1` bytes into it, so a NUL ends the string within `buf`.
    unsafe { CStr::from_ptr(buf.as_ptr()) }
        .to_string_lossy()
        .into_owned()
}

fn build(options: &envlight_light_options) -> *mut envlight_light {
    let (rgb, w, h) = sky();
    let mut light = null_mut();
    let status = envlight_light_from_rgb(rgb.as_ptr(), w, h, options, &mut light);
    assert_eq!(status, envlight_status::ENVLIGHT_OK, "{}", last_error());
    light
}

fn bits(s: &envlight_sample) -> Vec<u32> {
    s.direction
        .iter()
        .chain([s.pdf].iter())
        .chain(s.radiance.iter())
        .map(|x| x.to_bits())
        .collect()
}

/// Every sampler, density and mapping: single and batch calls through the C API
/// equal the library's own calls bit for bit.
#[test]
fn queries_equal_the_library_bit_for_bit() {
    let (rgb, w, h) = sky();
    let texels: Vec<[f32; 3]> = rgb.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let cases = [
        (0, 0, 0),
        (1, 0, 0),
        (2, 0, 0),
        (0, 1, 0),
        (0, 0, 1),
        (0, 1, 1),
    ];
    let n = 3000;
    let u: Vec<f32> = (0..n as u64)
        .flat_map(|k| envlight::rng::xi_2d(3, k))
        .collect();
    let dirs: Vec<f32> = (0..n as u64)
        .flat_map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(9, k)).to_array())
        .collect();
    for (sampler, density, mapping) in cases {
        let options = envlight_light_options {
            sampler,
            density,
            mapping,
            rotate_deg: 30.0,
            ..envlight_light_options_default()
        };
        let c = build(&options);
        let rust = EnvironmentLight::new(
            EnvImage::new(w as usize, h as usize, texels.clone()).unwrap(),
            light_options(&options, "test").unwrap(),
        )
        .unwrap();
        let mut batch = vec![envlight_sample::default(); n];
        let status = envlight_light_sample_batch(c, u.as_ptr(), n, batch.as_mut_ptr());
        assert_eq!(status, envlight_status::ENVLIGHT_OK);
        let mut pdf = vec![0.0f32; n];
        assert_eq!(
            envlight_light_pdf_batch(c, dirs.as_ptr(), n, pdf.as_mut_ptr()),
            envlight_status::ENVLIGHT_OK
        );
        let mut rgb_out = vec![0.0f32; 3 * n];
        assert_eq!(
            envlight_light_radiance_batch(c, dirs.as_ptr(), n, rgb_out.as_mut_ptr()),
            envlight_status::ENVLIGHT_OK
        );
        for k in 0..n {
            let xi = [u[2 * k], u[2 * k + 1]];
            let mut single = envlight_sample::default();
            let ok = envlight_light_sample(c, xi.as_ptr(), &mut single);
            let expected = to_c(rust.sample(xi));
            assert_eq!(ok, expected.pdf > 0.0);
            assert_eq!(bits(&single), bits(&expected), "sample {k}");
            assert_eq!(bits(&batch[k]), bits(&expected), "batch sample {k}");
            let d = [dirs[3 * k], dirs[3 * k + 1], dirs[3 * k + 2]];
            let p = rust.pdf(vec3(d));
            assert_eq!(envlight_light_pdf(c, d.as_ptr()).to_bits(), p.to_bits());
            assert_eq!(pdf[k].to_bits(), p.to_bits());
            let mut l = [0.0f32; 3];
            envlight_light_radiance(c, d.as_ptr(), l.as_mut_ptr());
            assert_eq!(l, rust.radiance(vec3(d)));
            assert_eq!(rgb_out[3 * k..3 * k + 3], l);
        }
        envlight_light_free(c);
    }
}

/// Each C code indexes the library's list (`ALL`) at its value.
fn assert_codes<T: PartialEq + std::fmt::Debug>(all: &[T], codes: &[(u32, T)]) {
    for (code, value) in codes {
        assert_eq!(&all[*code as usize], value, "code {code}");
    }
}

#[test]
fn enum_codes_follow_the_library_lists() {
    use envlight_density::*;
    use envlight_mapping::*;
    use envlight_sampler::*;
    assert_codes(
        &Sampler::ALL,
        &[
            (ENVLIGHT_SAMPLER_INVERSION as u32, Sampler::Inversion),
            (ENVLIGHT_SAMPLER_ALIAS as u32, Sampler::Alias),
            (ENVLIGHT_SAMPLER_HIERARCHICAL as u32, Sampler::Hierarchical),
        ],
    );
    assert_codes(
        &Density::ALL,
        &[
            (
                ENVLIGHT_DENSITY_PIECEWISE_BILINEAR as u32,
                Density::PiecewiseBilinear,
            ),
            (
                ENVLIGHT_DENSITY_PIECEWISE_CONSTANT as u32,
                Density::PiecewiseConstant,
            ),
        ],
    );
    assert_codes(
        &Mapping::ALL,
        &[
            (
                ENVLIGHT_MAPPING_EQUIRECTANGULAR as u32,
                Mapping::Equirectangular,
            ),
            (ENVLIGHT_MAPPING_EQUAL_AREA as u32, Mapping::EqualArea),
        ],
    );
    let version =
        format!("{ENVLIGHT_VERSION_MAJOR}.{ENVLIGHT_VERSION_MINOR}.{ENVLIGHT_VERSION_PATCH}");
    assert_eq!(version, env!("CARGO_PKG_VERSION"));
    // SAFETY: envlight_version returns a NUL-terminated string in static storage.
    let c = unsafe { CStr::from_ptr(envlight_version()) };
    assert_eq!(c.to_str().unwrap(), version);
}

#[test]
fn bad_arguments_are_statuses_with_messages() {
    use envlight_status::*;
    let (rgb, w, h) = sky();
    let mut light = null_mut();
    // NULL out.
    assert_eq!(
        envlight_light_from_rgb(rgb.as_ptr(), w, h, null(), null_mut()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("out is NULL"), "{}", last_error());
    // NULL rgb.
    assert_eq!(
        envlight_light_from_rgb(null(), w, h, null(), &mut light),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("rgb is NULL"), "{}", last_error());
    assert!(light.is_null());
    // Zero size.
    assert_eq!(
        envlight_light_from_rgb(rgb.as_ptr(), 0, h, null(), &mut light),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("0x32"), "{}", last_error());
    // A NaN texel, named.
    let mut bad = rgb.clone();
    bad[3 * (5 * 64 + 7) + 1] = f32::NAN;
    assert_eq!(
        envlight_light_from_rgb(bad.as_ptr(), w, h, null(), &mut light),
        ENVLIGHT_ERROR_INVALID_IMAGE
    );
    assert!(
        last_error().contains("rgb: texel (7, 5)"),
        "{}",
        last_error()
    );
    // A negative texel, named.
    let mut bad = rgb.clone();
    bad[3 * (2 * 64 + 3)] = -1.0;
    assert_eq!(
        envlight_light_from_rgb(bad.as_ptr(), w, h, null(), &mut light),
        ENVLIGHT_ERROR_INVALID_IMAGE
    );
    assert!(last_error().contains("texel (3, 2)"), "{}", last_error());
    // Options out of range.
    for (options, field) in [
        (
            envlight_light_options {
                sampler: 9,
                ..envlight_light_options_default()
            },
            "options.sampler",
        ),
        (
            envlight_light_options {
                scale: f32::NAN,
                ..envlight_light_options_default()
            },
            "options.scale",
        ),
        (
            envlight_light_options {
                reserved: [0, 1, 0, 0],
                ..envlight_light_options_default()
            },
            "options.reserved",
        ),
        (
            envlight_light_options {
                rotation: [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                ..envlight_light_options_default()
            },
            "options.rotation",
        ),
        // The library's validation, under the C field names.
        (
            envlight_light_options {
                rotate_deg: f32::INFINITY,
                ..envlight_light_options_default()
            },
            "options.rotate_deg",
        ),
        (
            envlight_light_options {
                sampler: envlight_sampler::ENVLIGHT_SAMPLER_ALIAS as u32,
                ..envlight_light_options_default()
            },
            "options.density: the piecewise-bilinear density",
        ),
        (
            envlight_light_options {
                lookup: envlight_lookup::ENVLIGHT_LOOKUP_NODE as u32,
                mapping: envlight_mapping::ENVLIGHT_MAPPING_EQUAL_AREA as u32,
                ..envlight_light_options_default()
            },
            "options.lookup: the node lookup",
        ),
    ] {
        assert_eq!(
            envlight_light_from_rgb(rgb.as_ptr(), w, h, &options, &mut light),
            ENVLIGHT_ERROR_INVALID_ARGUMENT
        );
        assert!(last_error().contains(field), "{}", last_error());
    }
    // A missing file, a garbage file.
    let path = std::ffi::CString::new("/nonexistent/envlight/map.exr").unwrap();
    assert_eq!(
        envlight_light_load(path.as_ptr(), null(), &mut light),
        ENVLIGHT_ERROR_NOT_FOUND
    );
    assert!(last_error().contains("/nonexistent/envlight/map.exr"));
    let dir = tempfile::tempdir().unwrap();
    let garbage = dir.path().join("garbage.hdr");
    std::fs::write(&garbage, b"this is not an image at all").unwrap();
    let path = std::ffi::CString::new(garbage.to_str().unwrap()).unwrap();
    assert_eq!(
        envlight_light_load(path.as_ptr(), null(), &mut light),
        ENVLIGHT_ERROR_FORMAT
    );
    assert!(last_error().contains("garbage.hdr"), "{}", last_error());
    // Value-returning calls with NULL: false / 0, and a message.
    let mut s = envlight_sample::default();
    assert!(!envlight_light_sample(null(), [0.5, 0.5].as_ptr(), &mut s));
    assert!(last_error().contains("light is NULL"));
    assert_eq!(envlight_light_pdf(null(), [0.0, 0.0, 1.0].as_ptr()), 0.0);
    // Batch calls: NULL with n > 0 is an error, with n == 0 it is nothing to do.
    let good = build(&envlight_light_options_default());
    assert_eq!(
        envlight_light_pdf_batch(good, null(), 4, null_mut()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("directions is NULL"));
    assert_eq!(
        envlight_light_pdf_batch(good, null(), 0, null_mut()),
        ENVLIGHT_OK
    );
    assert_eq!(
        envlight_light_sample_batch(good, rgb.as_ptr(), usize::MAX / 4, null_mut()),
        ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    envlight_light_free(good);
    envlight_light_free(null_mut());
}

/// Inputs no renderer should give still give an answer, never a panic or a NaN.
#[test]
fn odd_inputs_give_no_nan() {
    let light = build(&envlight_light_options_default());
    let odd = [
        f32::NAN,
        f32::INFINITY,
        -f32::INFINITY,
        -1.0,
        1.0,
        2.0,
        0.0,
        -0.0,
        1e30,
        f32::MIN_POSITIVE,
    ];
    let mut u = Vec::new();
    for &a in &odd {
        for &b in &odd {
            u.extend([a, b]);
        }
    }
    let n = u.len() / 2;
    let mut batch = vec![envlight_sample::default(); n];
    assert_eq!(
        envlight_light_sample_batch(light, u.as_ptr(), n, batch.as_mut_ptr()),
        envlight_status::ENVLIGHT_OK,
        "{}",
        last_error()
    );
    for k in 0..n {
        let mut s = envlight_sample::default();
        envlight_light_sample(light, [u[2 * k], u[2 * k + 1]].as_ptr(), &mut s);
        assert_eq!(bits(&s), bits(&batch[k]));
        assert!(bits(&s).iter().all(|&b| f32::from_bits(b).is_finite()));
        let d = [u[2 * k], u[2 * k + 1], 0.5];
        let p = envlight_light_pdf(light, d.as_ptr());
        assert!(p.is_finite() && p >= 0.0, "pdf {p} at {d:?}");
        let mut l = [0.0; 3];
        envlight_light_radiance(light, d.as_ptr(), l.as_mut_ptr());
        assert!(l.iter().all(|c| c.is_finite()), "radiance {l:?} at {d:?}");
    }
    envlight_light_free(light);
}

#[test]
fn product_portal_sun_and_gpu_tables_equal_the_library() {
    let light = build(&envlight_light_options_default());
    // SAFETY: `build` returned a light from envlight_light_from_rgb (asserted OK,
    // so non-NULL), and it is read here before envlight_light_free below.
    let rust = unsafe { &*light }.light.clone();
    // Product.
    let mut product = null_mut();
    assert_eq!(
        envlight_product_new(light, &mut product),
        envlight_status::ENVLIGHT_OK
    );
    envlight_light_free(light);
    let rust_product =
        envlight::ProductSampler::new(rust.clone(), envlight::ProductOptions::default());
    let factors = [
        envlight_factor {
            normal: [0.0, 0.0, 1.0],
            ..Default::default()
        },
        envlight_factor {
            normal: [0.3, -0.2, 0.9],
            outgoing: [0.0, 0.6, 0.8],
            roughness: 0.2,
        },
    ];
    let n = 500;
    let u: Vec<f32> = (0..n as u64)
        .flat_map(|k| envlight::rng::xi_2d(5, k))
        .collect();
    let fs: Vec<envlight_factor> = (0..n).map(|k| factors[k % 2]).collect();
    let mut batch = vec![envlight_sample::default(); n];
    assert_eq!(
        envlight_product_sample_batch(product, fs.as_ptr(), u.as_ptr(), n, batch.as_mut_ptr()),
        envlight_status::ENVLIGHT_OK
    );
    let dirs: Vec<f32> = batch.iter().flat_map(|s| s.direction).collect();
    let mut pdf = vec![0.0; n];
    assert_eq!(
        envlight_product_pdf_batch(product, fs.as_ptr(), dirs.as_ptr(), n, pdf.as_mut_ptr()),
        envlight_status::ENVLIGHT_OK
    );
    for k in 0..n {
        let f = crate::product::tests_factor(&fs[k]);
        let xi = [u[2 * k], u[2 * k + 1]];
        let expected = to_c(rust_product.sample(&f, xi));
        let mut single = envlight_sample::default();
        envlight_product_sample(product, &fs[k], xi.as_ptr(), &mut single);
        assert_eq!(bits(&single), bits(&expected));
        assert_eq!(bits(&batch[k]), bits(&expected));
        let d = vec3(batch[k].direction);
        assert_eq!(pdf[k].to_bits(), rust_product.pdf(&f, d).to_bits());
        assert_eq!(
            envlight_product_pdf(product, &fs[k], batch[k].direction.as_ptr()),
            pdf[k]
        );
    }
    envlight_product_free(product);
    // Portal: one window above the origin.
    let corners: [f32; 12] = [
        -1.0, -1.0, 2.0, 1.0, -1.0, 2.0, 1.0, 1.0, 2.0, -1.0, 1.0, 2.0,
    ];
    let light = build(&envlight_light_options_default());
    let mut portal = null_mut();
    assert_eq!(
        envlight_portal_light_new(light, corners.as_ptr(), 1, 0, &mut portal),
        envlight_status::ENVLIGHT_OK,
        "{}",
        last_error()
    );
    let mut s = envlight_sample::default();
    assert!(envlight_portal_light_sample(
        portal,
        [0.0; 3].as_ptr(),
        [0.3, 0.6].as_ptr(),
        &mut s
    ));
    assert!(s.direction[2] > 0.0);
    assert_eq!(
        envlight_portal_light_pdf(portal, [0.0; 3].as_ptr(), s.direction.as_ptr()).to_bits(),
        s.pdf.to_bits()
    );
    envlight_portal_light_free(portal);
    let flat = [0.0f32; 12];
    assert_eq!(
        envlight_portal_light_new(light, flat.as_ptr(), 1, 0, &mut portal),
        envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert!(last_error().contains("portal 0"), "{}", last_error());
    // Sun.
    let mut extraction = null_mut();
    assert_eq!(
        envlight_light_extract_sun(light, &mut extraction),
        envlight_status::ENVLIGHT_OK
    );
    let mut sun = envlight_sun::default();
    let found = envlight_sun_extraction_sun(extraction, &mut sun);
    assert_eq!(found, rust.sun().is_some());
    let (mut w, mut h) = (0, 0);
    envlight_sun_extraction_residual_size(extraction, &mut w, &mut h);
    assert_eq!((w, h), (64, 32));
    let mut residual = vec![0.0f32; (w * h * 3) as usize];
    assert_eq!(
        envlight_sun_extraction_residual(extraction, residual.as_mut_ptr(), residual.len() - 1),
        envlight_status::ENVLIGHT_ERROR_INVALID_ARGUMENT
    );
    assert_eq!(
        envlight_sun_extraction_residual(extraction, residual.as_mut_ptr(), residual.len()),
        envlight_status::ENVLIGHT_OK
    );
    envlight_sun_extraction_free(extraction);
    // GPU tables: the file's bytes are the library's.
    let mut tables = null_mut();
    assert_eq!(
        envlight_light_gpu_tables(light, 0, &mut tables),
        envlight_status::ENVLIGHT_OK
    );
    let size = envlight_gpu_tables_to_bytes(tables, null_mut(), 0);
    let mut bytes = vec![0u8; size];
    assert_eq!(
        envlight_gpu_tables_to_bytes(tables, bytes.as_mut_ptr(), size),
        size
    );
    let expected = rust
        .gpu_tables(&envlight::gpu::GpuTableOptions::default())
        .unwrap()
        .to_bytes();
    assert_eq!(bytes, expected);
    let mut words = 0;
    let params = envlight_gpu_tables_buffer(tables, 0, &mut words);
    assert!(!params.is_null());
    assert_eq!(words, envlight::gpu::PARAMS_WORDS);
    envlight_gpu_tables_free(tables);
    envlight_light_free(light);
}
