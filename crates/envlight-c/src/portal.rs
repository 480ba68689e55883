//! Portals: the light seen only through windows (planar convex quads), sampled
//! from a point in proportion to the radiance that comes through them
//! (docs/design.md §6d).

use std::sync::Arc;

use crate::boundary::{deref, free, read, run, slice, slice_mut, value, Failure};
use crate::light::new_from_light;
use crate::sample::{as_vec3, draw_batch_at, finite_u, sample_into, vec3};
use crate::{envlight_light, envlight_sample, envlight_status};
use envlight::portal::{Portal, PortalLight, PortalOptions};
use envlight::EnvironmentLight;

/// A light seen through portals. Opaque; a `const` pointer serves any number of
/// threads (each portal's tables are built, once, the first time a point on its
/// side asks). It keeps the light alive; free it with `envlight_portal_light_free`.
pub struct envlight_portal_light {
    light: PortalLight,
}

/// Builds a portal light over `light` from `count` portals at `corners`
/// (`count · 12` floats: each portal's four corners `x, y, z`, in order around a
/// planar convex quad, either winding; world frame). `resolution` is the cells
/// along each side of a portal's table (0: the light image's height clamped to
/// [32, 1024]). At most 8 portals. A bad quad is `ENVLIGHT_ERROR_INVALID_ARGUMENT`
/// with a message naming the portal (from 0) and what is wrong.
#[no_mangle]
pub extern "C" fn envlight_portal_light_new(
    light: *const envlight_light,
    corners: *const f32,
    count: usize,
    resolution: u32,
    out: *mut *mut envlight_portal_light,
) -> envlight_status {
    const F: &str = "envlight_portal_light_new";
    let build = |light: &Arc<EnvironmentLight>| -> Result<_, Failure> {
        if count == 0 {
            return Err(Failure::argument(F, "count must be at least 1"));
        }
        // SAFETY: by the C contract `corners` is NULL or holds `count · 12` floats,
        // only read during the call; `slice` rejects a NULL or misaligned pointer
        // and a size past `isize::MAX` bytes.
        let quads = unsafe { slice::<f32, 12>(corners, count, F, "corners") }?;
        let portals = quads
            .iter()
            .enumerate()
            .map(|(k, c)| {
                let p = |i: usize| vec3([c[3 * i], c[3 * i + 1], c[3 * i + 2]]);
                Portal::new([p(0), p(1), p(2), p(3)])
                    .map_err(|e| Failure::argument(F, format_args!("portal {k}: {e}")))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let options = PortalOptions {
            resolution: (resolution != 0).then_some(resolution as usize),
        };
        let light = PortalLight::new(Arc::clone(light), &portals, options)
            .map_err(|e| Failure::argument(F, e))?;
        Ok(envlight_portal_light { light })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_portal_light *`, and `light` is NULL or a light from
    // envlight_light_load/_from_rgb not yet freed (only read).
    unsafe { new_from_light(F, light, out, build) }
}

/// Frees a portal light (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_portal_light_free(light: *mut envlight_portal_light) {
    // SAFETY: by the C contract a non-NULL `light` came from
    // envlight_portal_light_new (which makes an `envlight_portal_light`) and is
    // freed once.
    unsafe { free(light) };
}

/// Draws a direction from the point `point` through the portals, for `u` in
/// [0, 1)², in proportion to the radiance seen through them. False (and `*out`
/// zeroed) when nothing lit is seen through a portal from `point`, `u` or `point`
/// is not finite, or an argument is NULL.
#[no_mangle]
pub extern "C" fn envlight_portal_light_sample(
    light: *const envlight_portal_light,
    point: *const f32,
    u: *const f32,
    out: *mut envlight_sample,
) -> bool {
    const F: &str = "envlight_portal_light_sample";
    let draw = || {
        // SAFETY: by the C contract `light` is NULL or a portal light not yet freed
        // (only read; its lazily built tables are behind a lock), `point` NULL or 3
        // floats and `u` NULL or 2; the helpers reject NULL and misaligned pointers.
        let (light, p, u) = unsafe {
            (
                deref(light, F, "light")?,
                read::<3>(point, F, "point")?,
                read::<2>(u, F, "u")?,
            )
        };
        Ok(if finite_u(u) {
            light.light.sample(vec3(p), u)
        } else {
            None
        })
    };
    // SAFETY: by the C contract `out` is NULL or one writable sample, overlapping
    // neither input.
    unsafe { sample_into(F, out, draw) }
}

/// The density (per steradian) with which `envlight_portal_light_sample` draws
/// `direction` from `point`: 0 for a direction through no portal and for NULL
/// arguments.
#[no_mangle]
pub extern "C" fn envlight_portal_light_pdf(
    light: *const envlight_portal_light,
    point: *const f32,
    direction: *const f32,
) -> f32 {
    const F: &str = "envlight_portal_light_pdf";
    value(F, 0.0, || {
        // SAFETY: by the C contract `light` is NULL or a portal light not yet
        // freed (only read), and `point` and `direction` are NULL or 3 floats each;
        // the helpers reject NULL and misaligned pointers.
        let (light, p, d) = unsafe {
            (
                deref(light, F, "light")?,
                read::<3>(point, F, "point")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        Ok(light.light.pdf(vec3(p), vec3(d)))
    })
}

/// `envlight_portal_light_sample` for `n` points (`points[3i..3i+3]` with
/// `u[2i], u[2i+1]`), written to `out[i]`, in parallel.
#[no_mangle]
pub extern "C" fn envlight_portal_light_sample_batch(
    light: *const envlight_portal_light,
    points: *const f32,
    u: *const f32,
    n: usize,
    out: *mut envlight_sample,
) -> envlight_status {
    const F: &str = "envlight_portal_light_sample_batch";
    run(F, || {
        // SAFETY: by the C contract `light` is NULL or a portal light not yet
        // freed (only read), and for n > 0 `points` holds 3n floats, `u` 2n floats
        // and `out` n writable samples apart from both; the helpers take nothing for
        // n = 0 and otherwise reject NULL, misaligned and overflowing arrays.
        let (light, points, u, out) = unsafe {
            (
                deref(light, F, "light")?,
                slice::<f32, 3>(points, n, F, "points")?,
                slice::<f32, 2>(u, n, F, "u")?,
                slice_mut::<envlight_sample, 1>(out, n, F, "out")?,
            )
        };
        let light = &light.light;
        let points = as_vec3(points);
        draw_batch_at(out.as_flattened_mut(), u, |range, u, samples| {
            light.sample_batch(&points[range], u, samples);
        });
        Ok(())
    })
}

/// `envlight_portal_light_pdf` for `n` points and directions, written to `pdf[i]`,
/// in parallel.
#[no_mangle]
pub extern "C" fn envlight_portal_light_pdf_batch(
    light: *const envlight_portal_light,
    points: *const f32,
    directions: *const f32,
    n: usize,
    pdf: *mut f32,
) -> envlight_status {
    const F: &str = "envlight_portal_light_pdf_batch";
    run(F, || {
        // SAFETY: by the C contract `light` is NULL or a portal light not yet
        // freed (only read), and for n > 0 `points` and `directions` hold 3n floats
        // each and `pdf` n writable floats apart from both; the helpers take
        // nothing for n = 0 and otherwise reject NULL, misaligned and overflowing
        // arrays.
        let (light, points, dirs, out) = unsafe {
            (
                deref(light, F, "light")?,
                slice::<f32, 3>(points, n, F, "points")?,
                slice::<f32, 3>(directions, n, F, "directions")?,
                slice_mut::<f32, 1>(pdf, n, F, "pdf")?,
            )
        };
        light
            .light
            .pdf_batch(as_vec3(points), as_vec3(dirs), out.as_flattened_mut());
        Ok(())
    })
}
