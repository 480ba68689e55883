//! How closely the GPU reproduces the CPU, row by row: the measure behind the
//! tests, `envlight sample --device gpu`'s promise and docs/gpu.md's precision note.
//!
//! A row is a direction with its pdf and radiance, as `envlight sample` and
//! `envlight eval` write them. Two rows agree when both say "no sample" (pdf 0),
//! or when the directions are within [`ANGLE_TOLERANCE`] radians and the pdfs and
//! radiances within [`RELATIVE_TOLERANCE`] of the CPU's (radiance relative to the
//! row's largest channel).

use envlight::light::{Density, Sampler};
use envlight::{EnvironmentLight, Vec3};

/// The `(sampler, density)` pairs the shader ports, which the agreement tests
/// and the `gpu_agreement` example run through (with every mapping and lookup).
pub const PORTED: [(Sampler, Density); 3] = [
    (Sampler::Inversion, Density::PiecewiseConstant),
    (Sampler::Alias, Density::PiecewiseConstant),
    (Sampler::Inversion, Density::PiecewiseBilinear),
];

/// Largest angle between the CPU's and the GPU's direction of an agreeing row.
pub const ANGLE_TOLERANCE: f64 = 2e-4;

/// Largest relative difference of pdf and radiance in an agreeing row.
pub const RELATIVE_TOLERANCE: f64 = 2e-3;

/// The share of rows that must agree.
pub const REQUIRED_FRACTION: f64 = 0.999;

/// One output row: a direction, its solid-angle pdf (0: no sample) and radiance.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Row {
    /// World-space direction.
    pub direction: [f32; 3],
    /// Solid-angle pdf, per steradian.
    pub pdf: f32,
    /// Linear RGB radiance.
    pub radiance: [f32; 3],
}

/// The CPU's rows `first..first + count` for seed `seed`, exactly as
/// `envlight sample --seed` writes them: each value evaluated at the direction as
/// written; a missing sample as the direction of the image point `ξ` with pdf 0.
pub fn cpu_sample_rows(light: &EnvironmentLight, seed: u64, first: u64, count: usize) -> Vec<Row> {
    (first..first + count as u64)
        .map(|k| cpu_sample_row(light, envlight::rng::xi_2d(seed, k)))
        .collect()
}

/// The CPU's row for one `ξ` (see [`cpu_sample_rows`]).
pub fn cpu_sample_row(light: &EnvironmentLight, xi: [f32; 2]) -> Row {
    match light.sample(xi) {
        Some(s) => {
            let pdf = light.pdf(s.direction);
            let (pdf, radiance) = if pdf > 0.0 {
                (pdf, light.radiance(s.direction))
            } else {
                (s.pdf, s.radiance)
            };
            Row {
                direction: s.direction.to_array(),
                pdf,
                radiance,
            }
        }
        None => Row {
            direction: light.uv_to_direction(xi).to_array(),
            pdf: 0.0,
            radiance: [0.0; 3],
        },
    }
}

/// The CPU's pdf and radiance at each direction, as `envlight eval` writes them.
pub fn cpu_eval_rows(light: &EnvironmentLight, directions: &[[f32; 3]]) -> Vec<Row> {
    directions
        .iter()
        .map(|&d| Row {
            direction: d,
            pdf: light.pdf(Vec3::from(d)),
            radiance: light.radiance(Vec3::from(d)),
        })
        .collect()
}

/// How `gpu` agrees with `light` (the light its tables came from) on `rows` rows
/// of each query: `sample` for seed `seed` (the `ξ` drawn on each device) and
/// `eval` at as many uniformly random directions (from seed `seed + 1`). What
/// `envlight info --device gpu` and the `gpu_agreement` example report.
pub fn measure(
    gpu: &crate::GpuLight,
    light: &EnvironmentLight,
    seed: u64,
    rows: usize,
) -> Result<(Agreement, Agreement), crate::GpuError> {
    let samples: Vec<Row> = gpu
        .sample_seeded(seed, 0, rows)?
        .iter()
        .map(|s| s.row())
        .collect();
    let sample = compare(&cpu_sample_rows(light, seed, 0, rows), &samples);
    let directions: Vec<[f32; 3]> = (0..rows as u64)
        .map(|k| envlight::math::uniform_sphere(envlight::rng::xi_2d(seed + 1, k)).to_array())
        .collect();
    let evals: Vec<Row> = gpu
        .eval(&directions)?
        .iter()
        .zip(&directions)
        .map(|(e, &d)| e.row(d))
        .collect();
    let eval = compare(&cpu_eval_rows(light, &directions), &evals);
    Ok((sample, eval))
}

/// What a comparison of two row sets found.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Agreement {
    /// Rows compared.
    pub rows: usize,
    /// Rows that agree.
    pub agreeing: usize,
    /// Rows where only one side has a sample.
    pub one_sided: usize,
    /// Largest angle between directions (radians) over rows where both sample.
    pub max_angle: f64,
    /// Largest relative pdf difference over rows where both sample.
    pub max_pdf_relative: f64,
    /// Largest relative radiance difference over rows where both sample.
    pub max_radiance_relative: f64,
    /// The 99.9th percentile of the relative pdf difference (rows where both sample).
    pub p999_pdf_relative: f64,
}

impl Agreement {
    /// The share of rows that agree (1 for no rows).
    pub fn fraction(&self) -> f64 {
        if self.rows == 0 {
            1.0
        } else {
            self.agreeing as f64 / self.rows as f64
        }
    }

    /// True when at least [`REQUIRED_FRACTION`] of the rows agree.
    pub fn passes(&self) -> bool {
        self.fraction() >= REQUIRED_FRACTION
    }
}

impl std::fmt::Display for Agreement {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} of {} rows agree ({:.4}%), {} one-sided; max angle {:.2e} rad, max pdf diff \
             {:.2e} (99.9th pct {:.2e}), max radiance diff {:.2e}",
            self.agreeing,
            self.rows,
            100.0 * self.fraction(),
            self.one_sided,
            self.max_angle,
            self.max_pdf_relative,
            self.p999_pdf_relative,
            self.max_radiance_relative
        )
    }
}

/// Compares the GPU's rows with the CPU's, row by row.
///
/// # Panics
/// When the two have different lengths.
pub fn compare(cpu: &[Row], gpu: &[Row]) -> Agreement {
    assert_eq!(cpu.len(), gpu.len(), "row counts differ");
    let mut a = Agreement {
        rows: cpu.len(),
        ..Default::default()
    };
    let mut pdf_diffs = Vec::with_capacity(cpu.len());
    for (c, g) in cpu.iter().zip(gpu) {
        let (c_has, g_has) = (c.pdf > 0.0, g.pdf > 0.0);
        if !c_has && !g_has {
            a.agreeing += 1;
            continue;
        }
        if c_has != g_has {
            a.one_sided += 1;
            continue;
        }
        let angle = angle_between(c.direction, g.direction);
        let pdf = relative(c.pdf as f64, g.pdf as f64, c.pdf as f64);
        let scale = c
            .radiance
            .iter()
            .fold(0.0f64, |m, &x| m.max(x.abs() as f64));
        let radiance = (0..3)
            .map(|k| relative(c.radiance[k] as f64, g.radiance[k] as f64, scale))
            .fold(0.0, f64::max);
        a.max_angle = a.max_angle.max(angle);
        a.max_pdf_relative = a.max_pdf_relative.max(pdf);
        a.max_radiance_relative = a.max_radiance_relative.max(radiance);
        pdf_diffs.push(pdf);
        if angle <= ANGLE_TOLERANCE && pdf <= RELATIVE_TOLERANCE && radiance <= RELATIVE_TOLERANCE {
            a.agreeing += 1;
        }
    }
    if !pdf_diffs.is_empty() {
        pdf_diffs.sort_by(f64::total_cmp);
        let at = ((pdf_diffs.len() as f64 * 0.999) as usize).min(pdf_diffs.len() - 1);
        a.p999_pdf_relative = pdf_diffs[at];
    }
    a
}

/// `|a − b| / scale`, 0 when both are equal, infinite for NaN.
fn relative(a: f64, b: f64, scale: f64) -> f64 {
    if a == b {
        return 0.0;
    }
    let r = (a - b).abs() / scale;
    if r.is_nan() {
        f64::INFINITY
    } else {
        r
    }
}

/// The angle between two directions (normalised here), in radians.
fn angle_between(a: [f32; 3], b: [f32; 3]) -> f64 {
    let unit = |v: [f32; 3]| {
        let v = v.map(|x| x as f64);
        let n = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        v.map(|x| x / n)
    };
    let (a, b) = (unit(a), unit(b));
    let d = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let chord = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let angle = 2.0 * (chord / 2.0).min(1.0).asin();
    if angle.is_nan() {
        f64::INFINITY
    } else {
        angle
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(d: [f32; 3], pdf: f32, l: f32) -> Row {
        Row {
            direction: d,
            pdf,
            radiance: [l, l / 2.0, 0.0],
        }
    }

    #[test]
    fn rows_agree_within_the_tolerances_and_not_beyond() {
        let c = row([0.0, 0.0, 1.0], 1.0, 2.0);
        let close = row([1e-4, 0.0, 1.0], 1.0015, 2.003);
        let far = row([3e-4, 0.0, 1.0], 1.0, 2.0);
        let pdf_off = row([0.0, 0.0, 1.0], 1.01, 2.0);
        let radiance_off = row([0.0, 0.0, 1.0], 1.0, 2.01);
        let none = row([0.0, 1.0, 0.0], 0.0, 0.0);
        let a = compare(
            &[c, c, c, c, none, c],
            &[close, far, pdf_off, radiance_off, none, none],
        );
        assert_eq!((a.rows, a.agreeing, a.one_sided), (6, 2, 1), "{a}");
        assert!((a.max_pdf_relative - 0.01).abs() < 1e-6, "{a}");
        assert!(!a.passes());
        assert!(compare(&[c; 1000], &[close; 1000]).passes());
    }
}
