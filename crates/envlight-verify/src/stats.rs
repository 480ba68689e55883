//! Deterministic parallel sampling and the small statistics the checks share.

use crate::sampler::{SphereSample, SphereSampler};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use rayon::prelude::*;

/// Points per chunk of [`over_points`] and [`over_sample_chunks`] (one PCG stream,
/// one accumulator, one batch call each).
pub(crate) const CHUNK: usize = 1 << 15;

/// Runs `body(acc, ξ)` for `n` points `ξ` from PCG streams fixed by `seed`, in
/// parallel chunks with one accumulator each; accumulators come back in order.
pub fn over_samples<A: Send>(
    n: usize,
    seed: u64,
    init: impl Fn() -> A + Sync,
    body: impl Fn(&mut A, [f32; 2]) + Sync,
) -> Vec<A> {
    over_points(n, seed, init, body)
}

/// [`over_samples`] for points of any dimension `D` (the first two coordinates of
/// each point are those `over_samples` gives for the same seed).
pub fn over_points<A: Send, const D: usize>(
    n: usize,
    seed: u64,
    init: impl Fn() -> A + Sync,
    body: impl Fn(&mut A, [f32; D]) + Sync,
) -> Vec<A> {
    (0..chunks(n))
        .into_par_iter()
        .map(|c| {
            let mut rng = chunk_rng(seed, c);
            let mut acc = init();
            for _ in 0..chunk_len(n, c) {
                let xi = [(); D].map(|_| rng.random::<f32>());
                body(&mut acc, xi);
            }
            acc
        })
        .collect()
}

/// [`over_samples`] with the samples drawn in batches: for each chunk of the
/// same `ξ` (the same chunks and PCG streams), one [`SphereSampler::sample_batch`]
/// call, then `body(acc, ξ, samples)` with the chunk's `ξ` and `s.sample_batch`'s
/// results for them, in order. A check that works through each chunk's samples in
/// order sums exactly what it would sum in `over_samples` calling `s.sample(ξ)`
/// point by point; chunks run in parallel, one accumulator each, and come back in
/// order.
pub fn over_sample_chunks<A: Send, S: SphereSampler + ?Sized>(
    s: &S,
    n: usize,
    seed: u64,
    init: impl Fn() -> A + Sync,
    body: impl Fn(&mut A, &[[f32; 2]], &[Option<SphereSample>]) + Sync,
) -> Vec<A> {
    (0..chunks(n))
        .into_par_iter()
        .map(|c| {
            let mut rng = chunk_rng(seed, c);
            let xi: Vec<[f32; 2]> = (0..chunk_len(n, c))
                .map(|_| [(); 2].map(|_| rng.random::<f32>()))
                .collect();
            let mut samples = vec![None; xi.len()];
            s.sample_batch(&xi, &mut samples);
            let mut acc = init();
            body(&mut acc, &xi, &samples);
            acc
        })
        .collect()
}

/// Number of chunks of `n` points.
fn chunks(n: usize) -> usize {
    n.div_ceil(CHUNK)
}

/// Number of points in chunk `c` of `n`.
fn chunk_len(n: usize, c: usize) -> usize {
    CHUNK.min(n - c * CHUNK)
}

/// The PCG stream of chunk `c` for `seed`.
fn chunk_rng(seed: u64, c: usize) -> Pcg64Mcg {
    let stream =
        seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (c as u64).wrapping_mul(0xd1b5_4a32_d192_ed03);
    Pcg64Mcg::seed_from_u64(stream)
}

/// Mean and variance accumulated by Welford's method and merged by Chan's formula
/// (stable for the huge-dynamic-range maps).
#[derive(Debug, Clone, Copy, Default)]
pub struct Moments {
    /// Number of values.
    pub n: f64,
    /// Their mean.
    pub mean: f64,
    /// Sum of squared deviations from the mean.
    pub m2: f64,
}

impl Moments {
    /// Adds one value.
    pub fn push(&mut self, x: f64) {
        self.n += 1.0;
        let delta = x - self.mean;
        self.mean += delta / self.n;
        self.m2 += delta * (x - self.mean);
    }
    /// Combines two accumulators.
    pub fn merge(self, o: Self) -> Self {
        if o.n == 0.0 {
            return self;
        }
        if self.n == 0.0 {
            return o;
        }
        let n = self.n + o.n;
        let delta = o.mean - self.mean;
        Self {
            n,
            mean: self.mean + delta * o.n / n,
            m2: self.m2 + o.m2 + delta * delta * self.n * o.n / n,
        }
    }
    /// Standard error of the mean.
    pub fn std_err(&self) -> f64 {
        if self.n > 1.0 {
            (self.m2 / (self.n - 1.0) / self.n).sqrt()
        } else {
            0.0
        }
    }
    /// Mean of the squares.
    pub fn mean_square(&self) -> f64 {
        self.m2 / self.n + self.mean * self.mean
    }
}

/// `x ≤ limit`, false when either is NaN: checks written `!fits(error, tolerance)`
/// count a NaN error as a failure.
pub fn fits(x: f64, limit: f64) -> bool {
    x <= limit
}

pub(crate) fn finite_rgb(rgb: [f32; 3]) -> bool {
    rgb.iter().all(|c| c.is_finite() && *c >= 0.0)
}
