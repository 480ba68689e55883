//! The seed's algorithm written plainly, as the yardstick every benchmark is
//! reported against: per-row `Vec<f32>` CDFs accumulated in f32, a binary search per
//! dimension, importance from the texel's luminance × sin θ, no parallelism and no
//! layout tricks. It is deliberately not optimised; do not "fix" it.

use envlight::color::luminance;
use envlight::{EnvImage, Vec3};
use std::f32::consts::PI;

pub struct Baseline1D {
    func: Vec<f32>,
    cdf: Vec<f32>,
    func_int: f32,
}

impl Baseline1D {
    pub fn new(f: &[f32]) -> Self {
        let n = f.len();
        let mut cdf = vec![0.0f32; n + 1];
        for i in 1..=n {
            cdf[i] = cdf[i - 1] + f[i - 1] / n as f32;
        }
        let func_int = cdf[n];
        if func_int == 0.0 {
            for (i, c) in cdf.iter_mut().enumerate().skip(1) {
                *c = i as f32 / n as f32;
            }
        } else {
            for c in cdf.iter_mut().skip(1) {
                *c /= func_int;
            }
        }
        Self {
            func: f.to_vec(),
            cdf,
            func_int,
        }
    }

    fn find_interval(&self, u: f32) -> usize {
        // Largest index with cdf[i] <= u, by bisection over [0, n-1].
        let (mut first, mut len) = (0usize, self.cdf.len());
        while len > 0 {
            let half = len >> 1;
            let middle = first + half;
            if self.cdf[middle] <= u {
                first = middle + 1;
                len -= half + 1;
            } else {
                len = half;
            }
        }
        first.saturating_sub(1).min(self.cdf.len() - 2)
    }

    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let offset = self.find_interval(u);
        let mut du = u - self.cdf[offset];
        let width = self.cdf[offset + 1] - self.cdf[offset];
        if width > 0.0 {
            du /= width;
        }
        let pdf = if self.func_int > 0.0 {
            self.func[offset] / self.func_int
        } else {
            0.0
        };
        ((offset as f32 + du) / self.func.len() as f32, pdf, offset)
    }
}

pub struct Baseline2D {
    conditional: Vec<Baseline1D>,
    marginal: Baseline1D,
}

impl Baseline2D {
    pub fn new(f: &[f32], nu: usize, nv: usize) -> Self {
        let conditional: Vec<Baseline1D> = (0..nv)
            .map(|v| Baseline1D::new(&f[v * nu..(v + 1) * nu]))
            .collect();
        let marginal_func: Vec<f32> = conditional.iter().map(|d| d.func_int).collect();
        let marginal = Baseline1D::new(&marginal_func);
        Self {
            conditional,
            marginal,
        }
    }

    pub fn sample_continuous(&self, xi: [f32; 2]) -> ([f32; 2], f32) {
        let (v, pdf1, iv) = self.marginal.sample_continuous(xi[1]);
        let (u, pdf0, _) = self.conditional[iv].sample_continuous(xi[0]);
        ([u, v], pdf0 * pdf1)
    }

    pub fn pdf(&self, uv: [f32; 2]) -> f32 {
        let nu = self.conditional[0].func.len();
        let nv = self.marginal.func.len();
        let iu = ((uv[0] * nu as f32) as usize).min(nu - 1);
        let iv = ((uv[1] * nv as f32) as usize).min(nv - 1);
        self.conditional[iv].func[iu] / self.marginal.func_int
    }
}

/// Bilinear lookup between texel centres, u periodic and v clamped, written the
/// plain way (floor, wrap each index, four bounds-checked texel reads). The baseline
/// has its own rather than the library's, so that optimising the library's lookup
/// cannot speed up the yardstick it is measured against.
fn lookup_bilinear(image: &EnvImage, u: f32, v: f32) -> [f32; 3] {
    let (w, h) = (image.width() as i64, image.height() as i64);
    let (s, t) = (u * w as f32 - 0.5, v * h as f32 - 0.5);
    let (s0, t0) = (s.floor(), t.floor());
    let (ds, dt) = (s - s0, t - t0);
    let texel = |i: i64, j: i64| image.texel(i.rem_euclid(w) as usize, j.clamp(0, h - 1) as usize);
    let (i, j) = (s0 as i64, t0 as i64);
    let (a, b, c, d) = (
        texel(i, j),
        texel(i + 1, j),
        texel(i, j + 1),
        texel(i + 1, j + 1),
    );
    let mut out = [0.0f32; 3];
    for k in 0..3 {
        out[k] =
            (1.0 - dt) * ((1.0 - ds) * a[k] + ds * b[k]) + dt * ((1.0 - ds) * c[k] + ds * d[k]);
    }
    out
}

pub struct BaselineLight {
    image: EnvImage,
    dist: Baseline2D,
    importance: Vec<f32>,
}

impl BaselineLight {
    pub fn new(image: EnvImage) -> Self {
        let (w, h) = (image.width(), image.height());
        let mut img = vec![0.0f32; w * h];
        for v in 0..h {
            let vp = (v as f32 + 0.5) / h as f32;
            let sin_theta = (PI * vp).sin();
            for u in 0..w {
                let up = (u as f32 + 0.5) / w as f32;
                img[v * w + u] = luminance(lookup_bilinear(&image, up, vp)) * sin_theta;
            }
        }
        let dist = Baseline2D::new(&img, w, h);
        Self {
            image,
            dist,
            importance: img,
        }
    }

    /// The planar distribution alone (no direction, no radiance).
    pub fn distribution(&self) -> &Baseline2D {
        &self.dist
    }

    /// The importance the distribution was built from, row-major.
    pub fn importance(&self) -> &[f32] {
        &self.importance
    }

    pub fn sample(&self, xi: [f32; 2]) -> Option<(Vec3, f32, [f32; 3])> {
        let (uv, map_pdf) = self.dist.sample_continuous(xi);
        if map_pdf == 0.0 {
            return None;
        }
        let (theta, phi) = (uv[1] * PI, uv[0] * 2.0 * PI);
        let (sin_theta, cos_theta) = theta.sin_cos();
        let (sin_phi, cos_phi) = phi.sin_cos();
        if sin_theta == 0.0 {
            return None;
        }
        let dir = Vec3::new(sin_theta * cos_phi, sin_theta * sin_phi, cos_theta);
        let pdf = map_pdf / (2.0 * PI * PI * sin_theta);
        Some((dir, pdf, lookup_bilinear(&self.image, uv[0], uv[1])))
    }

    pub fn pdf(&self, d: Vec3) -> f32 {
        let theta = d.z.clamp(-1.0, 1.0).acos();
        let mut phi = d.y.atan2(d.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        let sin_theta = theta.sin();
        if sin_theta == 0.0 {
            return 0.0;
        }
        self.dist.pdf([phi / (2.0 * PI), theta / PI]) / (2.0 * PI * PI * sin_theta)
    }

    pub fn radiance(&self, d: Vec3) -> [f32; 3] {
        let theta = d.z.clamp(-1.0, 1.0).acos();
        let mut phi = d.y.atan2(d.x);
        if phi < 0.0 {
            phi += 2.0 * PI;
        }
        lookup_bilinear(&self.image, phi / (2.0 * PI), theta / PI)
    }
}
