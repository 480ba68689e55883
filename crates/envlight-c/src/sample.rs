//! What the light, product and portal samplers share at the boundary: the C
//! sample, C's float triples as the library's vectors, and the parallel driver of
//! the batch calls.

use envlight::{LightSample, Vec3};
use rayon::prelude::*;

use crate::boundary::{cleared, value, Failure};

/// A direction drawn from a light, with its solid-angle density (per steradian)
/// and the radiance arriving from it (linear RGB, scale applied). A call that
/// draws no direction leaves every field 0.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct envlight_sample {
    /// Unit direction towards the light, world frame, z up.
    pub direction: [f32; 3],
    /// Solid-angle density of `direction`, per steradian: > 0 and finite, or 0
    /// when no direction was drawn.
    pub pdf: f32,
    /// Radiance arriving from `direction`.
    pub radiance: [f32; 3],
}

/// `[f32; 3]` as a [`Vec3`].
#[inline(always)]
pub(crate) fn vec3(v: [f32; 3]) -> Vec3 {
    Vec3::new(v[0], v[1], v[2])
}

// `as_vec3` relies on this: `Vec3` is `repr(C)` over three `f32` (x, y, z), with the
// size and alignment of `[f32; 3]`.
const _: () = assert!(
    std::mem::size_of::<Vec3>() == std::mem::size_of::<[f32; 3]>()
        && std::mem::align_of::<Vec3>() == std::mem::align_of::<[f32; 3]>()
);

/// Directions given as `n` triples, viewed as [`Vec3`] without copying.
#[inline(always)]
pub(crate) fn as_vec3(v: &[[f32; 3]]) -> &[Vec3] {
    // SAFETY: `Vec3` is `repr(C)` over three `f32`, like `[f32; 3]` (same size and
    // alignment, asserted above), and any three floats are a valid `Vec3`; the view
    // has `v`'s length and borrows `v`, so it is in bounds and shared like `v`.
    unsafe { std::slice::from_raw_parts(v.as_ptr().cast::<Vec3>(), v.len()) }
}

/// The C form of a sample; a missing one is all zeros.
#[inline(always)]
pub(crate) fn to_c(s: Option<LightSample>) -> envlight_sample {
    match s {
        Some(s) => envlight_sample {
            direction: s.direction.to_array(),
            pdf: s.pdf,
            radiance: s.radiance,
        },
        None => envlight_sample::default(),
    }
}

/// Runs the body of an entry point that draws one sample: `*out` is zeroed before
/// anything else can fail, then holds the C form of what `draw` draws; returns
/// whether a direction was drawn (false also for a failure or a panic).
///
/// # Safety
/// A non-NULL, aligned `out` must point to a writable `envlight_sample` that
/// nothing else accesses during the call.
pub(crate) unsafe fn sample_into(
    function: &str,
    out: *mut envlight_sample,
    draw: impl FnOnce() -> Result<Option<LightSample>, Failure>,
) -> bool {
    value(function, false, || {
        // SAFETY: forwarded: the caller makes `cleared`'s promise for `out`.
        let out = unsafe { cleared(out, envlight_sample::default(), function, "out") }?;
        *out = to_c(draw()?);
        Ok(out.pdf > 0.0)
    })
}

/// Whether a point `u` can be sampled: both coordinates finite.
#[inline(always)]
pub(crate) fn finite_u(u: [f32; 2]) -> bool {
    u[0].is_finite() && u[1].is_finite()
}

/// No direction for the samples drawn at non-finite points (the single calls
/// draw none there either).
#[inline(always)]
fn drop_non_finite(samples: &mut [Option<LightSample>], u: &[[f32; 2]]) {
    for (s, &u) in samples.iter_mut().zip(u) {
        if !finite_u(u) {
            *s = None;
        }
    }
}

/// Samples per parallel task when the library's samples are converted to C's.
pub(crate) const CHUNK: usize = 1 << 12;

/// Fills `out` from `draw` (the library's batch form: an index range and its
/// output slice), a chunk at a time in parallel, converting to C's layout.
pub(crate) fn draw_batch(
    out: &mut [envlight_sample],
    draw: impl Fn(std::ops::Range<usize>, &mut [Option<LightSample>]) + Sync,
) {
    out.par_chunks_mut(CHUNK)
        .enumerate()
        .for_each_init(Vec::new, |samples, (c, out)| {
            let start = c * CHUNK;
            samples.clear();
            samples.resize(out.len(), None);
            draw(start..start + out.len(), samples);
            for (o, s) in out.iter_mut().zip(samples.iter()) {
                *o = to_c(*s);
            }
        });
}

/// [`draw_batch`] for the calls that draw each sample at its own point `u[i]`:
/// `draw` gets the index range and its points, and draws nothing where a point is
/// not finite.
pub(crate) fn draw_batch_at(
    out: &mut [envlight_sample],
    u: &[[f32; 2]],
    draw: impl Fn(std::ops::Range<usize>, &[[f32; 2]], &mut [Option<LightSample>]) + Sync,
) {
    draw_batch(out, |range, samples| {
        let u = &u[range.clone()];
        draw(range, u, samples);
        drop_non_finite(samples, u);
    });
}
