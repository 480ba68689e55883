//! Self-checks of the harness's batch path: the checks draw samples and look up
//! pdfs and radiance only through the batch calls, one per chunk, with the same
//! `ξ` and the same figures as the single calls.

use crate::checks::black::black;
use crate::checks::chi_square::chi_square;
use crate::checks::consistency::consistency;
use crate::checks::unbiasedness::{lobe_normals, unbiasedness, Reference};
use crate::integrand::Integrand;
use crate::product::AtShadingPoint;
use crate::sampler::{Grid, SphereSample, SphereSampler};
use crate::stats::{over_sample_chunks, over_samples, CHUNK};
use crate::suite::{run, Config};
use envlight::light::{Density, Mapping, Sampler};
use envlight::{
    EnvImage, EnvironmentLight, Factor, LightOptions, Lookup, ProductOptions, ProductSampler,
    Rotation, Vec3,
};
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::sync::{Arc, Mutex};

/// Calls counted by [`Counting`].
#[derive(Debug, Default)]
struct Calls {
    sample: AtomicUsize,
    pdf: AtomicUsize,
    radiance: AtomicUsize,
    sample_batch: AtomicUsize,
    pdf_batch: AtomicUsize,
    radiance_batch: AtomicUsize,
    /// Lengths of the `sample_batch` calls.
    sample_batch_lengths: Mutex<Vec<usize>>,
}

impl Calls {
    fn single(&self) -> [usize; 3] {
        [&self.sample, &self.pdf, &self.radiance].map(|c| c.load(Relaxed))
    }
}

/// A light that counts its single and batch calls, as a GPU sampler would pay
/// for them (one dispatch each).
struct Counting<'a> {
    light: &'a EnvironmentLight,
    calls: Calls,
}

impl<'a> Counting<'a> {
    fn new(light: &'a EnvironmentLight) -> Self {
        Self {
            light,
            calls: Calls::default(),
        }
    }
}

impl SphereSampler for Counting<'_> {
    fn name(&self) -> String {
        format!("counting {}", SphereSampler::name(self.light))
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        self.calls.sample.fetch_add(1, Relaxed);
        SphereSampler::sample(self.light, xi)
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        self.calls.pdf.fetch_add(1, Relaxed);
        SphereSampler::pdf(self.light, direction)
    }
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]> {
        SphereSampler::invert(self.light, direction)
    }
    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        self.calls.radiance.fetch_add(1, Relaxed);
        SphereSampler::radiance(self.light, direction)
    }
    fn integral_luminance(&self) -> f64 {
        self.light.integral_luminance()
    }
    fn grid(&self) -> Option<Grid> {
        SphereSampler::grid(self.light)
    }
    fn fold(&self) -> Option<(Vec3, f32)> {
        SphereSampler::fold(self.light)
    }
    fn reported_efficiency(&self) -> Option<f64> {
        SphereSampler::reported_efficiency(self.light)
    }
    fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<SphereSample>]) {
        self.calls.sample_batch.fetch_add(1, Relaxed);
        self.calls
            .sample_batch_lengths
            .lock()
            .unwrap()
            .push(xi.len());
        SphereSampler::sample_batch(self.light, xi, out)
    }
    fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        self.calls.pdf_batch.fetch_add(1, Relaxed);
        SphereSampler::pdf_batch(self.light, directions, out)
    }
    fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        self.calls.radiance_batch.fetch_add(1, Relaxed);
        SphereSampler::radiance_batch(self.light, directions, out)
    }
}

/// The light itself through the trait's default batch methods (single calls in a
/// loop), as a sampler without batch queries is checked.
struct Defaults<'a>(&'a EnvironmentLight);

impl SphereSampler for Defaults<'_> {
    fn name(&self) -> String {
        "defaults".into()
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        SphereSampler::sample(self.0, xi)
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        SphereSampler::pdf(self.0, direction)
    }
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]> {
        SphereSampler::invert(self.0, direction)
    }
    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        SphereSampler::radiance(self.0, direction)
    }
    fn integral_luminance(&self) -> f64 {
        self.0.integral_luminance()
    }
    fn grid(&self) -> Option<Grid> {
        SphereSampler::grid(self.0)
    }
    fn fold(&self) -> Option<(Vec3, f32)> {
        SphereSampler::fold(self.0)
    }
}

/// Lights of every sampler and density, in both mappings, rotated and not.
fn lights() -> Vec<EnvironmentLight> {
    let image = envlight::builtin::sky(96, 48);
    [
        (
            Sampler::Inversion,
            Density::PiecewiseConstant,
            Lookup::Bilinear,
            Mapping::Equirectangular,
            0.0,
        ),
        (
            Sampler::Alias,
            Density::PiecewiseConstant,
            Lookup::Nearest,
            Mapping::Equirectangular,
            20.0,
        ),
        (
            Sampler::Hierarchical,
            Density::PiecewiseConstant,
            Lookup::Bilinear,
            Mapping::EqualArea,
            0.0,
        ),
        (
            Sampler::Inversion,
            Density::PiecewiseBilinear,
            Lookup::Bilinear,
            Mapping::Equirectangular,
            33.0,
        ),
    ]
    .into_iter()
    .map(|(sampler, density, lookup, mapping, degrees)| {
        let options = LightOptions {
            sampler,
            density,
            lookup,
            mapping,
            rotation: Rotation::about_z_degrees(degrees),
            ..Default::default()
        };
        EnvironmentLight::new(image.clone(), options).unwrap()
    })
    .collect()
}

/// Every sample as bits, for exact comparison (`-0.0 == 0.0` would hide a change).
fn bits(s: &Option<SphereSample>) -> Option<([u32; 3], u32, [u32; 3])> {
    s.map(|s| {
        (
            [s.direction.x, s.direction.y, s.direction.z].map(f32::to_bits),
            s.pdf.to_bits(),
            s.radiance.map(f32::to_bits),
        )
    })
}

#[test]
fn sample_chunks_see_the_same_xi_as_single_samples() {
    // Two whole chunks and a partial one.
    let n = 2 * CHUNK + 1234;
    let light = &lights()[0];
    let single = over_samples(n, 77, Vec::new, |v, xi| v.push(xi));
    let chunked = over_sample_chunks(light, n, 77, Vec::new, |v, xi, samples| {
        assert_eq!(xi.len(), samples.len());
        v.extend_from_slice(xi);
    });
    assert_eq!(single.len(), 3);
    assert_eq!(chunked.len(), 3);
    for (a, b) in single.iter().zip(&chunked) {
        let bits = |v: &Vec<[f32; 2]>| v.iter().map(|x| x.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(a), bits(b));
    }
}

#[test]
fn batch_samples_equal_single_samples() {
    let xi: Vec<[f32; 2]> = over_samples(5_003, 5, Vec::new, |v, xi| v.push(xi)).concat();
    let check = |s: &dyn SphereSampler| {
        let mut batch = vec![None; xi.len()];
        s.sample_batch(&xi, &mut batch);
        let mut some = 0;
        for (&x, b) in xi.iter().zip(&batch) {
            assert_eq!(bits(b), bits(&s.sample(x)), "{} at ξ={x:?}", s.name());
            some += b.is_some() as usize;
        }
        assert!(some > 4_900, "{}: {some} samples", s.name());
        let directions: Vec<Vec3> = batch.iter().flatten().map(|s| s.direction).collect();
        let mut pdfs = vec![0.0; directions.len()];
        s.pdf_batch(&directions, &mut pdfs);
        for (&d, p) in directions.iter().zip(&pdfs) {
            assert_eq!(p.to_bits(), s.pdf(d).to_bits(), "{} at {d:?}", s.name());
        }
    };
    for light in lights() {
        check(&light);
        check(&Defaults(&light));
    }
    let light = Arc::new(lights().swap_remove(0));
    let product = ProductSampler::new(light, ProductOptions::default());
    for normal in [Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.6, -0.64, -0.48)] {
        check(&AtShadingPoint::new(&product, Factor::Cosine { normal }));
    }
}

#[test]
fn consistency_and_chi_square_sample_only_in_batches() {
    // Three whole chunks and a partial one.
    let n = 3 * CHUNK + 5_000;
    for light in lights() {
        let counting = Counting::new(&light);
        let case = SphereSampler::name(&light);

        let direct = consistency(&light, n, 11, 1e-4);
        let batched = consistency(&counting, n, 11, 1e-4);
        assert_eq!(format!("{batched:?}"), format!("{direct:?}"), "{case}");
        assert_eq!(direct.samples, n);
        assert!(direct.checked > n / 2, "{case}: {direct}");
        assert_eq!(counting.calls.single(), [0, 0, 0], "{case}: single calls");
        assert_eq!(counting.calls.sample_batch.load(Relaxed), 4, "{case}");
        assert_eq!(counting.calls.pdf_batch.load(Relaxed), 4, "{case}");
        let mut lengths = counting.calls.sample_batch_lengths.lock().unwrap().clone();
        lengths.sort_unstable();
        assert_eq!(lengths, [5_000, CHUNK, CHUNK, CHUNK], "{case}");

        let counting = Counting::new(&light);
        let direct = chi_square(&light, n, 12, 4_000);
        let batched = chi_square(&counting, n, 12, 4_000);
        assert_eq!(format!("{batched:?}"), format!("{direct:?}"), "{case}");
        assert!(direct.verdict().is_ok(), "{case}: {direct}");
        assert_eq!(counting.calls.single(), [0, 0, 0], "{case}: single calls");
        assert_eq!(counting.calls.sample_batch.load(Relaxed), 4, "{case}");
    }
}

#[test]
fn every_check_uses_only_batch_calls() {
    let cfg = Config {
        chi2_samples: 70_000,
        max_bins: 4_000,
        consistency_samples: 70_000,
        mc_samples: 70_000,
        ..Config::SYNTHETIC
    };
    for light in lights() {
        let case = SphereSampler::name(&light);
        let counting = Counting::new(&light);
        let integrand = Integrand::luminance();
        let mut direct = run(&light, &integrand, &cfg, &|_| {});
        let mut batched = run(&counting, &integrand, &cfg, &|_| {});
        (direct.seconds, batched.seconds) = ([0.0; 5], [0.0; 5]);
        assert_eq!(format!("{batched:?}"), format!("{direct:?}"), "{case}");
        assert_eq!(
            format!("{:?}", lobe_normals(&counting)),
            format!("{:?}", lobe_normals(&light)),
            "{case}"
        );
        let lobes = [Vec3::new(0.0, 0.0, 1.0)];
        let u = |s: &dyn SphereSampler| {
            let r = unbiasedness(s, &integrand, &lobes, 40_000, 3, Reference::Midpoint);
            format!("{r:?}")
        };
        assert_eq!(u(&counting), u(&light), "{case}");
        assert_eq!(counting.calls.single(), [0, 0, 0], "{case}: single calls");
    }
    let black_map = EnvImage::from_fn(32, 16, |_, _| [0.0; 3]).unwrap();
    let light = EnvironmentLight::new(black_map, LightOptions::default()).unwrap();
    let counting = Counting::new(&light);
    let b = black(&counting, 2 * CHUNK + 1, 4);
    assert!(b.verdict(&counting).is_ok(), "{b}");
    assert_eq!(
        format!("{b:?}"),
        format!("{:?}", black(&light, 2 * CHUNK + 1, 4))
    );
    assert_eq!(counting.calls.single(), [0, 0, 0], "black: single calls");
    assert_eq!(counting.calls.sample_batch.load(Relaxed), 3);
}
