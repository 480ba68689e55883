//! The GPU light as a [`SphereSampler`], so the library's invariant harness
//! (`envlight-verify`) checks GPU-produced samples and pdfs.
//!
//! Every sample, pdf and radiance the harness sees comes from the device; only
//! what describes the light rather than measures it (its cell grid, and the
//! integral `∫ Y dω` it claims, which the parameter block carries) is read on the
//! host. The harness calls the batch methods for everything it draws in bulk; the
//! single calls are one dispatch each. `invert` is a CPU query: `None` here, as
//! for the alias sampler.

use crate::{GpuError, GpuLight};
use envlight::gpu::param;
use envlight::Vec3;
use envlight_verify::{Grid, SphereSample, SphereSampler};
use std::sync::Mutex;

/// A [`GpuLight`] seen by the harness. Device errors cannot travel through the
/// trait's signatures: the first one is kept ([`Self::error`]), and the query
/// that met it answers "no sample" and pdf 0, which the harness's checks reject.
#[derive(Debug)]
pub struct GpuSphereSampler<'a> {
    gpu: &'a GpuLight,
    grid: Grid,
    name: String,
    error: Mutex<Option<String>>,
}

impl<'a> GpuSphereSampler<'a> {
    /// The harness's view of `gpu`, whose pdf lives on `grid` (the CPU light's
    /// cell grid: [`SphereSampler::grid`] of the light the tables came from).
    pub fn new(gpu: &'a GpuLight, grid: Grid) -> Self {
        let r = gpu.device().report();
        Self {
            gpu,
            grid,
            name: format!("GPU light on {} ({})", r.name, r.backend),
            error: Mutex::new(None),
        }
    }

    /// The first device error met while the harness ran, if any.
    pub fn error(&self) -> Option<String> {
        self.error.lock().ok().and_then(|e| e.clone())
    }

    fn keep<T>(&self, r: Result<T, GpuError>) -> Option<T> {
        match r {
            Ok(v) => Some(v),
            Err(e) => {
                if let Ok(mut slot) = self.error.lock() {
                    slot.get_or_insert_with(|| e.to_string());
                }
                None
            }
        }
    }
}

fn arrays(directions: &[Vec3]) -> Vec<[f32; 3]> {
    directions.iter().map(|d| d.to_array()).collect()
}

impl SphereSampler for GpuSphereSampler<'_> {
    fn name(&self) -> String {
        self.name.clone()
    }

    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        let mut out = [None];
        self.sample_batch(&[xi], &mut out);
        out[0]
    }

    fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<SphereSample>]) {
        let Some(samples) = self.keep(self.gpu.sample(xi)) else {
            out.fill(None);
            return;
        };
        for (o, s) in out.iter_mut().zip(samples) {
            *o = s.is_valid().then(|| SphereSample {
                direction: Vec3::from(s.direction),
                pdf: s.pdf,
                radiance: s.radiance,
            });
        }
    }

    fn pdf(&self, direction: Vec3) -> f32 {
        let mut out = [0.0];
        self.pdf_batch(&[direction], &mut out);
        out[0]
    }

    fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        match self.keep(self.gpu.pdf(&arrays(directions))) {
            Some(p) => out.copy_from_slice(&p),
            None => out.fill(0.0),
        }
    }

    fn invert(&self, _direction: Vec3) -> Option<[f32; 2]> {
        None
    }

    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        let mut out = [[0.0; 3]];
        self.radiance_batch(&[direction], &mut out);
        out[0]
    }

    fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        match self.keep(self.gpu.radiance(&arrays(directions))) {
            Some(l) => out.copy_from_slice(&l),
            None => out.fill([0.0; 3]),
        }
    }

    fn integral_luminance(&self) -> f64 {
        f32::from_bits(self.gpu.params()[param::INTEGRAL_LUMINANCE]) as f64
    }

    fn grid(&self) -> Option<Grid> {
        Some(self.grid)
    }
}
