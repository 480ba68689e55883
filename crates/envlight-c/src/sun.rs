//! Sun extraction: the map's brightest compact source as a uniform disc, and the
//! map without it (docs/design.md §6d).

use std::sync::Arc;

use envlight::{EnvironmentLight, SunExtraction, SunOptions};

use crate::boundary::{cleared, deref, deref_mut, free, run, slice_mut, value, Failure};
use crate::light::new_from_light;
use crate::{envlight_light, envlight_status};

/// What `envlight_light_extract_sun` found. Opaque and immutable; free it with
/// `envlight_sun_extraction_free`.
pub struct envlight_sun_extraction {
    extraction: SunExtraction,
}

/// A compact bright source as a uniform disc. Radiometric values are linear RGB
/// with the light's scale applied; the direction is in the world frame (the
/// light's rotation applied), z up.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_sun {
    /// Unit direction towards the disc's centre.
    pub direction: [f32; 3],
    /// Angular radius of the disc, in degrees.
    pub angular_radius_deg: f64,
    /// Solid angle of the disc, `2π (1 − cos r)`, in steradians.
    pub solid_angle_sr: f64,
    /// The disc's uniform radiance.
    pub radiance: [f64; 3],
    /// Irradiance at normal incidence, `L π sin² r`.
    pub irradiance: [f64; 3],
    /// The source's share of the map's `∫ Y dω`, in [0, 1].
    pub power_fraction: f64,
    /// Elevation above the horizon (the xy plane), in degrees.
    pub elevation_deg: f64,
    /// Azimuth in [0, 360) degrees, from +x towards +y.
    pub azimuth_deg: f64,
    /// The disc's mean luminance over the surrounding sky's median (+∞ on a black sky).
    pub contrast: f64,
}

/// Looks for the light's sun (radius <= 5°, contrast >= 20, >= 1% of the power) and
/// in-paints it out of a copy of the image. `*out` holds the result on success
/// (NULL on failure); whether a sun was found is `envlight_sun_extraction_sun`'s
/// answer.
#[no_mangle]
pub extern "C" fn envlight_light_extract_sun(
    light: *const envlight_light,
    out: *mut *mut envlight_sun_extraction,
) -> envlight_status {
    let build = |light: &Arc<EnvironmentLight>| -> Result<_, Failure> {
        let extraction = light.extract_sun(&SunOptions::default());
        Ok(envlight_sun_extraction { extraction })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_sun_extraction *`, and `light` is NULL or a light from
    // envlight_light_load/_from_rgb not yet freed (only read).
    unsafe { new_from_light("envlight_light_extract_sun", light, out, build) }
}

/// Frees a sun extraction (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_sun_extraction_free(extraction: *mut envlight_sun_extraction) {
    // SAFETY: by the C contract a non-NULL `extraction` came from
    // envlight_light_extract_sun (which makes an `envlight_sun_extraction`) and is
    // freed once.
    unsafe { free(extraction) };
}

/// Writes the sun to `*sun` and returns true; false (and `*sun` zeroed) when the
/// map has none or an argument is NULL.
#[no_mangle]
pub extern "C" fn envlight_sun_extraction_sun(
    extraction: *const envlight_sun_extraction,
    sun: *mut envlight_sun,
) -> bool {
    const F: &str = "envlight_sun_extraction_sun";
    value(F, false, || {
        // SAFETY: by the C contract `sun` is NULL or one writable `envlight_sun`,
        // and `extraction` NULL or a handle from envlight_light_extract_sun not yet
        // freed (only read); the helpers reject NULL and misaligned pointers.
        let (out, e) = unsafe {
            (
                cleared(sun, envlight_sun::default(), F, "sun")?,
                deref(extraction, F, "extraction")?,
            )
        };
        let Some(s) = e.extraction.sun else {
            return Ok(false);
        };
        *out = envlight_sun {
            direction: s.direction.to_array(),
            angular_radius_deg: s.angular_radius_deg(),
            solid_angle_sr: s.solid_angle,
            radiance: s.radiance,
            irradiance: s.irradiance,
            power_fraction: s.power_fraction,
            elevation_deg: s.elevation_deg(),
            azimuth_deg: s.azimuth_deg(),
            contrast: s.contrast,
        };
        Ok(true)
    })
}

/// The residual image's size (the light's image's), written to `*width` and
/// `*height`, and the number of texels in-painted as the return value (0 also for
/// NULL arguments).
#[no_mangle]
pub extern "C" fn envlight_sun_extraction_residual_size(
    extraction: *const envlight_sun_extraction,
    width: *mut u32,
    height: *mut u32,
) -> u64 {
    const F: &str = "envlight_sun_extraction_residual_size";
    value(F, 0, || {
        // SAFETY: by the C contract `extraction` is NULL or a handle from
        // envlight_light_extract_sun not yet freed (only read), and `width` and
        // `height` are NULL or one writable `uint32_t` each, distinct; the helpers
        // reject NULL and misaligned pointers. `width` is written before `height` is
        // checked, as the API always has.
        let (e, width) = unsafe {
            (
                deref(extraction, F, "extraction")?,
                deref_mut(width, F, "width")?,
            )
        };
        let r = &e.extraction.residual;
        *width = r.width() as u32;
        // SAFETY: as for `width` above: NULL or one writable `uint32_t` of its own.
        *unsafe { deref_mut(height, F, "height") }? = r.height() as u32;
        Ok(e.extraction.inpainted_texels as u64)
    })
}

/// Copies the residual image (the map without its sun, in the image's own units:
/// the scale not applied; the image itself when there is no sun) into `rgb`, which
/// holds `len` floats: at least `width · height · 3`, rows from the top. With the
/// disc it reproduces the map's irradiance at any normal that does not graze the
/// sun; build a light from it with `envlight_light_from_rgb` and the same options.
#[no_mangle]
pub extern "C" fn envlight_sun_extraction_residual(
    extraction: *const envlight_sun_extraction,
    rgb: *mut f32,
    len: usize,
) -> envlight_status {
    const F: &str = "envlight_sun_extraction_residual";
    run(F, || {
        // SAFETY: by the C contract `extraction` is NULL or a handle from
        // envlight_light_extract_sun not yet freed, only read here; `deref` rejects
        // NULL and misaligned pointers.
        let e = unsafe { deref(extraction, F, "extraction") }?;
        let texels = e.extraction.residual.texels();
        if len < 3 * texels.len() {
            return Err(Failure::argument(
                F,
                format_args!(
                    "len is {len}, but the residual has {} floats ({}x{}x3)",
                    3 * texels.len(),
                    e.extraction.residual.width(),
                    e.extraction.residual.height()
                ),
            ));
        }
        // SAFETY: by the C contract `rgb` is NULL or holds `len` writable floats of
        // the caller's, and `len >= 3 · texels.len()` was checked just above, so the
        // `texels.len()` triples are within them; `slice_mut` rejects NULL,
        // misaligned and overflowing arrays.
        let out = unsafe { slice_mut::<f32, 3>(rgb, texels.len(), F, "rgb") }?;
        out.copy_from_slice(texels);
        Ok(())
    })
}
