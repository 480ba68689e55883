//! Product sampling at shading points: directions drawn in proportion to the
//! light's radiance times a factor of the surface (docs/design.md §6a).

use std::sync::Arc;

use envlight::{EnvironmentLight, Factor, ProductOptions, ProductSampler};
use rayon::prelude::*;

use crate::boundary::{deref, free, read, run, slice, slice_mut, value, Failure};
use crate::light::new_from_light;
use crate::sample::{as_vec3, draw_batch_at, finite_u, sample_into, vec3, CHUNK};
use crate::{envlight_light, envlight_sample, envlight_status};

/// A product sampler over a light: its tables for every surface normal, built once
/// (tens of milliseconds and a few bytes per texel; `envlight_product_memory_bytes`).
/// Opaque and immutable: a `const` pointer serves any number of threads. It keeps
/// the light alive; free it with `envlight_product_free`.
pub struct envlight_product {
    /// Shared with the visibility caches built over it, which keep it alive.
    pub(crate) product: Arc<ProductSampler>,
}

/// What multiplies the light's radiance at a shading point (world frame; vectors
/// need not be unit length).
///
/// - `roughness == 0`: the clamped cosine `max(0, n·ω)` of a diffuse surface;
///   `outgoing` is ignored.
/// - `0 < roughness <= 1`: the clamped cosine times a GGX lobe proxy of that
///   roughness about the mirror direction of `outgoing` (towards the viewer).
///
/// A zero or non-finite `normal` (or `outgoing`, when used), or a `roughness`
/// outside `[0, 1]`, samples nothing: `false` and pdf 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_factor {
    /// The surface normal `n`.
    pub normal: [f32; 3],
    /// The outgoing direction `ωo`, for a glossy factor.
    pub outgoing: [f32; 3],
    /// 0 for the cosine alone; the GGX roughness `α ∈ (0, 1]` for a glossy lobe.
    pub roughness: f32,
}

/// The library's factor.
#[inline(always)]
fn factor(f: &envlight_factor) -> Factor {
    if f.roughness == 0.0 {
        Factor::cosine(vec3(f.normal))
    } else {
        Factor::glossy(vec3(f.normal), vec3(f.outgoing), f.roughness)
    }
}

/// Builds the product sampler of `light` (default options: the light's own density
/// within patches, tables over an octahedral grid of normals). `*out` holds it on
/// success (NULL on failure).
#[no_mangle]
pub extern "C" fn envlight_product_new(
    light: *const envlight_light,
    out: *mut *mut envlight_product,
) -> envlight_status {
    let build = |light: &Arc<EnvironmentLight>| -> Result<_, Failure> {
        let product = ProductSampler::new(Arc::clone(light), ProductOptions::default());
        Ok(envlight_product {
            product: Arc::new(product),
        })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_product *`, and `light` is NULL or a light from
    // envlight_light_load/_from_rgb not yet freed (only read).
    unsafe { new_from_light("envlight_product_new", light, out, build) }
}

/// Frees a product sampler (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_product_free(product: *mut envlight_product) {
    // SAFETY: by the C contract a non-NULL `product` came from envlight_product_new
    // (which makes an `envlight_product`) and is freed once.
    unsafe { free(product) };
}

/// Bytes of the product sampler's tables.
#[no_mangle]
pub extern "C" fn envlight_product_memory_bytes(product: *const envlight_product) -> u64 {
    const F: &str = "envlight_product_memory_bytes";
    value(F, 0, || {
        // SAFETY: by the C contract `product` is NULL or a product sampler from
        // envlight_product_new not yet freed, only read here; `deref` rejects NULL
        // and misaligned pointers.
        let p = unsafe { deref(product, F, "product") }?;
        Ok(p.product.memory_bytes() as u64)
    })
}

/// Draws a direction for `u` in [0, 1)² with density proportional to radiance ×
/// `factor` (up to the tables' resolution; the pdf is exact). Returns false and
/// zeroes `*out` when nothing lit is seen by the factor, the factor is invalid,
/// `u` is not finite, or an argument is NULL.
#[no_mangle]
pub extern "C" fn envlight_product_sample(
    product: *const envlight_product,
    factor: *const envlight_factor,
    u: *const f32,
    out: *mut envlight_sample,
) -> bool {
    const F: &str = "envlight_product_sample";
    let draw = || {
        // SAFETY: by the C contract `product` is NULL or a product sampler not yet
        // freed (only read), `factor` NULL or one `envlight_factor` and `u` NULL or
        // 2 floats; the helpers reject NULL and misaligned pointers.
        let (p, f, u) = unsafe {
            (
                deref(product, F, "product")?,
                deref(factor, F, "factor")?,
                read::<2>(u, F, "u")?,
            )
        };
        Ok(if finite_u(u) {
            p.product.sample(&self::factor(f), u)
        } else {
            None
        })
    };
    // SAFETY: by the C contract `out` is NULL or one writable sample, overlapping
    // no input.
    unsafe { sample_into(F, out, draw) }
}

/// The density (per steradian) with which `envlight_product_sample` draws the unit
/// world direction `direction` at `factor`; 0 for NULL arguments.
#[no_mangle]
pub extern "C" fn envlight_product_pdf(
    product: *const envlight_product,
    factor: *const envlight_factor,
    direction: *const f32,
) -> f32 {
    const F: &str = "envlight_product_pdf";
    value(F, 0.0, || {
        // SAFETY: by the C contract `product` is NULL or a product sampler not yet
        // freed (only read), `factor` NULL or one `envlight_factor` and `direction`
        // NULL or 3 floats; the helpers reject NULL and misaligned pointers.
        let (p, f, d) = unsafe {
            (
                deref(product, F, "product")?,
                deref(factor, F, "factor")?,
                read::<3>(direction, F, "direction")?,
            )
        };
        Ok(p.product.pdf(&self::factor(f), vec3(d)))
    })
}

/// `envlight_product_sample` for each of `n` shading points: `factors[i]` and
/// `u[2i], u[2i+1]` give `out[i]`, in parallel; independent of the thread count.
#[no_mangle]
pub extern "C" fn envlight_product_sample_batch(
    product: *const envlight_product,
    factors: *const envlight_factor,
    u: *const f32,
    n: usize,
    out: *mut envlight_sample,
) -> envlight_status {
    const F: &str = "envlight_product_sample_batch";
    run(F, || {
        // SAFETY: by the C contract `product` is NULL or a product sampler not yet
        // freed (only read), and for n > 0 `factors` holds n factors, `u` 2n floats
        // and `out` n writable samples apart from both; the helpers take nothing for
        // n = 0 and otherwise reject NULL, misaligned and overflowing arrays.
        let (p, factors, u, out) = unsafe {
            (
                deref(product, F, "product")?,
                slice::<envlight_factor, 1>(factors, n, F, "factors")?,
                slice::<f32, 2>(u, n, F, "u")?,
                slice_mut::<envlight_sample, 1>(out, n, F, "out")?,
            )
        };
        let p = &p.product;
        let factors = factors.as_flattened();
        draw_batch_at(out.as_flattened_mut(), u, |range, u, samples| {
            let f: Vec<Factor> = factors[range].iter().map(factor).collect();
            p.sample_batch(&f, u, samples);
        });
        Ok(())
    })
}

/// `envlight_product_pdf` for each of `n` shading points: `factors[i]` and the
/// direction `directions[3i..3i+3]` give `pdf[i]`, in parallel.
#[no_mangle]
pub extern "C" fn envlight_product_pdf_batch(
    product: *const envlight_product,
    factors: *const envlight_factor,
    directions: *const f32,
    n: usize,
    pdf: *mut f32,
) -> envlight_status {
    const F: &str = "envlight_product_pdf_batch";
    run(F, || {
        // SAFETY: by the C contract `product` is NULL or a product sampler not yet
        // freed (only read), and for n > 0 `factors` holds n factors, `directions`
        // 3n floats and `pdf` n writable floats apart from both; the helpers take
        // nothing for n = 0 and otherwise reject NULL, misaligned and overflowing
        // arrays.
        let (p, factors, dirs, out) = unsafe {
            (
                deref(product, F, "product")?,
                slice::<envlight_factor, 1>(factors, n, F, "factors")?,
                slice::<f32, 3>(directions, n, F, "directions")?,
                slice_mut::<f32, 1>(pdf, n, F, "pdf")?,
            )
        };
        let p = &p.product;
        let factors = factors.as_flattened();
        out.as_flattened_mut()
            .par_chunks_mut(CHUNK)
            .zip(factors.par_chunks(CHUNK))
            .zip(as_vec3(dirs).par_chunks(CHUNK))
            .for_each(|((out, factors), dirs)| {
                let f: Vec<Factor> = factors.iter().map(factor).collect();
                p.pdf_batch(&f, dirs, out);
            });
        Ok(())
    })
}

/// The library's factor of a C factor, for the crate's tests.
#[cfg(test)]
pub(crate) fn tests_factor(f: &envlight_factor) -> Factor {
    factor(f)
}
