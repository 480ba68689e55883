//! Sun extraction: find the compact bright source of a map (a sun, a lamp),
//! measure it, and give back the map without it.
//!
//! Real-time renderers light a scene with a directional light plus an image for
//! the rest. This module finds the source, reports it as a uniform disc (unit
//! direction, angular radius, solid angle, radiance, irradiance at normal
//! incidence, share of the map's power), and in-paints its texels from the sky
//! around it, so that the **residual image plus the disc reproduce the map's
//! irradiance** `E(n) = ∫ L max(0, n·ω) dω` at any normal that does not graze the
//! source.
//!
//! # How the source is found
//! Every quantity is a sum over texels: texel `t` has radiance `L_t`, luminance
//! `Y_t`, the unit direction `ω_t` of its centre and its exact solid angle `ΔΩ_t`
//! (`(2π/w)(cos θ_j − cos θ_{j+1})` for a lat-long row, `4π/(w h)` for the
//! equal-area square). All geometry is done on directions, never on image
//! coordinates, so the φ = 0 seam, the poles and the folds of the equal-area square
//! need no special case.
//! 1. **Peak and core.** From the brightest texel, the *core* is the texels above
//!    half its luminance out to the first annulus (one texel pitch wide) around the
//!    centre that holds none; the centre moves to the core's luminance-weighted
//!    centroid, three times.
//! 2. **Extent.** Annuli around the centre, one texel pitch wide, are walked
//!    outwards from the core; the source ends where the mean luminance stops
//!    falling (the next annulus is within [`FLAT_PROFILE_DROP`] of the last, twice
//!    in a row), plus one annulus of margin. Anti-aliased and blurred edges are
//!    inside; a slowly decaying halo (glare, haze) is left to the sky.
//! 3. **In-painting.** A quadratic in the tangent plane at the centre is fitted per
//!    channel (least squares, weighted by solid angle) to the surrounding ring
//!    (as wide as half the source's radius, at least [`RING_MIN_TEXELS`] texels);
//!    ring texels brighter than [`RING_OUTLIER`] times its median luminance (other
//!    lamps, glints) are left out; the fill is clamped to the range the ring
//!    holds. Inside the source a texel brighter than the fill (the source), or
//!    darker than half of it (the black ringing lossy codecs leave round a clipped
//!    sun), becomes the fill; the others keep their value (sky texture): smooth,
//!    no disc.
//! 4. **Measurement.** The excess `e_t = L_t − residual_t` is the source. Its
//!    luminance-weighted moment `M = Σ e_Y ω ΔΩ` gives the direction `M/|M|` (a
//!    sub-texel weighted centroid); per channel, `E⊥ = Σ e ω·ĉ ΔΩ` is the irradiance
//!    at normal incidence. The equivalent disc has the source's peak excess radiance,
//!    so its solid angle is `Ω = Σ e_Y ΔΩ / max e_Y` (exact for a uniform disc
//!    with at least one texel fully inside it; for a source smaller than a texel
//!    it is an upper bound of about a texel, while direction and irradiance stay
//!    exact), its angular radius `r = acos(1 − Ω/2π)`, its radiance
//!    `E⊥ / (π sin² r)`.
//!
//! Because `max(0, n·ω)` is linear in `ω` wherever it is positive, the disc's
//! irradiance `E⊥ (n·ĉ)` equals the excess's `Σ e (n·ω) ΔΩ` exactly for every
//! normal that sees the whole source, and both are 0 for a normal that sees none
//! of it: residual + disc reproduce the map's irradiance (up to the colour varying
//! across the source). Only normals within the source's extent of grazing differ.
//!
//! # What counts as compact (the "no sun" answer)
//! A source is reported only when all of these hold ([`SunOptions`], defaults):
//! - its disc's angular radius is at most [`MAX_ANGULAR_RADIUS_DEG`] (5°, a solid
//!   angle of 0.0239 sr), and its half-maximum core fits within twice that;
//! - its **contrast**, the disc's mean luminance over the median luminance of the
//!   ring around it, is at least [`MIN_CONTRAST`] (20);
//! - it carries at least [`MIN_POWER_FRACTION`] (1%) of the map's `∫ Y dω`;
//! - the map's texels are smaller than that largest disc (a 1×1 or 16×8 map cannot
//!   hold a compact source).
//!
//! An overcast sky (a broad maximum: its core is too large, or its contrast too
//! low), a uniform map (no excess), an all-black map and a 1×1 map report none.
//! Only the brightest source is reported.

use crate::color::LUMINANCE_WEIGHTS;
use crate::image::EnvImage;
use crate::light::{EnvironmentLight, Mapping};
use crate::math::{cross3, dot3, Vec3};
use rayon::prelude::*;
use std::f64::consts::PI;

/// The largest angular radius of a reported source, in degrees (default of
/// [`SunOptions::max_angular_radius_deg`]).
pub const MAX_ANGULAR_RADIUS_DEG: f64 = 5.0;
/// The smallest contrast of a reported source: its disc's mean luminance over the
/// median luminance of the sky around it (default of [`SunOptions::min_contrast`]).
pub const MIN_CONTRAST: f64 = 20.0;
/// The smallest share of the map's `∫ Y dω` a reported source carries (default
/// of [`SunOptions::min_power_fraction`]).
pub const MIN_POWER_FRACTION: f64 = 0.01;
/// The source's radial profile has flattened when an annulus's mean luminance is
/// more than `1 − FLAT_PROFILE_DROP` of the previous one's.
pub const FLAT_PROFILE_DROP: f64 = 0.1;
/// The in-painting ring is at least this many texel pitches wide.
pub const RING_MIN_TEXELS: f64 = 4.0;
/// Ring texels brighter than this times the ring's median luminance are left out
/// of the in-painting fit.
pub const RING_OUTLIER: f64 = 20.0;

/// The thresholds that define a compact source (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunOptions {
    /// Largest angular radius of the source's disc, in degrees.
    pub max_angular_radius_deg: f64,
    /// Smallest ratio of the disc's mean luminance to the surrounding sky's median.
    pub min_contrast: f64,
    /// Smallest share of the map's `∫ Y dω` the source carries, in `[0, 1]`.
    pub min_power_fraction: f64,
}

impl Default for SunOptions {
    fn default() -> Self {
        Self {
            max_angular_radius_deg: MAX_ANGULAR_RADIUS_DEG,
            min_contrast: MIN_CONTRAST,
            min_power_fraction: MIN_POWER_FRACTION,
        }
    }
}

/// A compact bright source, as a uniform disc. Radiometric values are linear RGB
/// with the light's scale applied; the direction is in the world frame (the
/// light's rotation applied), z up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    /// Unit direction towards the disc's centre (world frame).
    pub direction: Vec3,
    /// Angular radius of the disc, in radians.
    pub angular_radius: f64,
    /// Solid angle of the disc, `2π (1 − cos r)`, in steradians.
    pub solid_angle: f64,
    /// The disc's uniform radiance (RGB).
    pub radiance: [f64; 3],
    /// Irradiance at normal incidence, `∫_disc L cos δ dω = L π sin² r` (RGB): what a
    /// surface facing the sun receives from it. It equals the disc's `∫ L dω`
    /// within `(1 − cos r)/2` (under 0.07% for r ≤ 3°).
    pub irradiance: [f64; 3],
    /// The source's share of the map's `∫ Y dω`, in `[0, 1]`.
    pub power_fraction: f64,
    /// The disc's mean luminance over the median luminance of the surrounding sky
    /// (+∞ on a black sky).
    pub contrast: f64,
}

impl Sun {
    /// Angular radius in degrees.
    pub fn angular_radius_deg(&self) -> f64 {
        self.angular_radius.to_degrees()
    }

    /// Elevation above the horizon (the xy plane), in degrees: `asin(z)`.
    pub fn elevation_deg(&self) -> f64 {
        (self.direction.z as f64)
            .clamp(-1.0, 1.0)
            .asin()
            .to_degrees()
    }

    /// Azimuth in degrees in `[0, 360)`, from +x towards +y: `atan2(y, x)` (the
    /// map's φ for an unrotated light).
    pub fn azimuth_deg(&self) -> f64 {
        let a = (self.direction.y as f64)
            .atan2(self.direction.x as f64)
            .to_degrees();
        if a < 0.0 {
            (a + 360.0) % 360.0
        } else {
            a
        }
    }
}

/// What [`EnvironmentLight::extract_sun`] finds: the source, if any, and the
/// residual image.
#[derive(Debug, Clone)]
pub struct SunExtraction {
    /// The compact source, or `None` when the map has none.
    pub sun: Option<Sun>,
    /// The light's image (same size and mapping, in the image's own units: the
    /// light's scale is *not* applied) with the source's texels in-painted from
    /// the sky around it; the image unchanged when there is no source. It replaces
    /// the map: light it with the same options.
    pub residual: EnvImage,
    /// How many texels were in-painted.
    pub inpainted_texels: usize,
}

impl EnvironmentLight {
    /// The map's compact bright source with the default thresholds, or `None`
    /// (see [`crate::sun`]).
    pub fn sun(&self) -> Option<Sun> {
        self.extract_sun(&SunOptions::default()).sun
    }

    /// Finds the map's compact bright source with the thresholds `options`, and the
    /// residual image without it (see [`crate::sun`]). Deterministic; never panics
    /// and never produces NaN, whatever the map (black, 1×1, uniform).
    pub fn extract_sun(&self, options: &SunOptions) -> SunExtraction {
        let image = self.image();
        let scale = self.options().scale as f64;
        let grid = Grid::new(image, self.mapping());
        let found = if scale > 0.0 {
            find(image, &grid, options)
        } else {
            None
        };
        let Some(found) = found else {
            return SunExtraction {
                sun: None,
                residual: image.clone(),
                inpainted_texels: 0,
            };
        };
        let mut texels = image.texels().to_vec();
        for &(index, value) in &found.replaced {
            texels[index] = value;
        }
        // The replacements are finite and non-negative (the fill is clamped into
        // the ring's range): validation cannot fail, and the original image stands
        // in if it ever did.
        let residual =
            EnvImage::new(image.width(), image.height(), texels).unwrap_or_else(|_| image.clone());
        let rows = self.options().rotation.rows();
        let c = found.direction;
        let world = [0, 1, 2].map(|i| {
            rows[i][0] as f64 * c[0] + rows[i][1] as f64 * c[1] + rows[i][2] as f64 * c[2]
        });
        let world = normalize(world).unwrap_or(c);
        let sun = Sun {
            direction: Vec3::new(world[0] as f32, world[1] as f32, world[2] as f32),
            angular_radius: found.angular_radius,
            solid_angle: found.solid_angle,
            radiance: found.radiance.map(|v| v * scale),
            irradiance: found.irradiance.map(|v| v * scale),
            power_fraction: found.power_fraction,
            contrast: found.contrast,
        };
        SunExtraction {
            sun: Some(sun),
            residual,
            inpainted_texels: found.replaced.len(),
        }
    }
}

/// A source found on the unscaled image, in the light frame.
struct Found {
    direction: [f64; 3],
    angular_radius: f64,
    solid_angle: f64,
    radiance: [f64; 3],
    irradiance: [f64; 3],
    power_fraction: f64,
    contrast: f64,
    /// `(texel index, residual value)` for every in-painted texel.
    replaced: Vec<(usize, [f32; 3])>,
}

/// A texel near the source.
#[derive(Clone, Copy)]
struct Near {
    index: usize,
    dir: [f64; 3],
    solid_angle: f64,
    y: f64,
    /// Angle from the current centre, radians.
    delta: f64,
}

/// Texel directions and solid angles of the light's image.
struct Grid {
    w: usize,
    h: usize,
    mapping: Mapping,
    /// Lat-long: `(sin θ, cos θ)` of each row's centre and its solid angle per texel.
    rows: Vec<(f64, f64, f64)>,
    /// Lat-long: `(cos φ, sin φ)` of each column's centre.
    columns: Vec<(f64, f64)>,
}

impl Grid {
    fn new(image: &EnvImage, mapping: Mapping) -> Self {
        let (w, h) = (image.width(), image.height());
        let (rows, columns) = match mapping {
            Mapping::Equirectangular => {
                let dphi = 2.0 * PI / w as f64;
                let rows = (0..h)
                    .map(|j| {
                        let t = PI * (j as f64 + 0.5) / h as f64;
                        let (a, b) = (PI * j as f64 / h as f64, PI * (j + 1) as f64 / h as f64);
                        (t.sin(), t.cos(), dphi * (a.cos() - b.cos()))
                    })
                    .collect();
                let columns = (0..w)
                    .map(|i| {
                        let p = dphi * (i as f64 + 0.5);
                        (p.cos(), p.sin())
                    })
                    .collect();
                (rows, columns)
            }
            Mapping::EqualArea => (Vec::new(), Vec::new()),
        };
        Self {
            w,
            h,
            mapping,
            rows,
            columns,
        }
    }

    /// The angular size of a texel's side, radians (the larger of the θ pitch and
    /// the φ pitch at the equator of a lat-long map, equal for a 2:1 map; the side
    /// of a square of the texel's solid angle for the equal-area map).
    fn pitch(&self) -> f64 {
        match self.mapping {
            Mapping::Equirectangular => (PI / self.h as f64).max(2.0 * PI / self.w as f64),
            Mapping::EqualArea => (4.0 * PI / (self.w * self.h) as f64).sqrt(),
        }
    }

    #[inline]
    fn solid_angle(&self, y: usize) -> f64 {
        match self.mapping {
            Mapping::Equirectangular => self.rows[y].2,
            Mapping::EqualArea => 4.0 * PI / (self.w * self.h) as f64,
        }
    }

    #[inline]
    fn direction(&self, x: usize, y: usize) -> [f64; 3] {
        match self.mapping {
            Mapping::Equirectangular => {
                let (st, ct, _) = self.rows[y];
                let (cp, sp) = self.columns[x];
                [st * cp, st * sp, ct]
            }
            Mapping::EqualArea => {
                let u = (x as f32 + 0.5) / self.w as f32;
                let v = (y as f32 + 0.5) / self.h as f32;
                let d = crate::mapping::equal_area::square_to_sphere(u, v);
                normalize([d.x as f64, d.y as f64, d.z as f64]).unwrap_or([0.0, 0.0, 1.0])
            }
        }
    }

    /// `∫ Y dω` of the image (texel sums).
    fn luminance_integral(&self, image: &EnvImage) -> f64 {
        (0..self.h)
            .into_par_iter()
            .map(|y| {
                let row: f64 = image.row(y).iter().map(|&t| lum(t)).sum();
                row * self.solid_angle(y)
            })
            .sum()
    }

    /// Every texel whose centre is within `alpha` radians of the unit direction `c`.
    fn gather(&self, image: &EnvImage, c: [f64; 3], alpha: f64) -> Vec<Near> {
        let cos_alpha = alpha.min(PI).cos();
        let near = |x: usize, y: usize| -> Option<Near> {
            let dir = self.direction(x, y);
            let cos = dot3(dir, c);
            (cos >= cos_alpha).then(|| {
                let index = y * self.w + x;
                Near {
                    index,
                    dir,
                    solid_angle: self.solid_angle(y),
                    y: lum(image.texels()[index]),
                    delta: angle_between(dir, c),
                }
            })
        };
        match self.mapping {
            Mapping::Equirectangular => {
                let (h, w) = (self.h as f64, self.w as f64);
                let theta = (c[0].hypot(c[1])).atan2(c[2]);
                let phi = c[1].atan2(c[0]);
                let pad = self.pitch();
                let y0 = (((theta - alpha - pad) / PI * h).floor().max(0.0)) as usize;
                let y1 = ((((theta + alpha + pad) / PI * h).ceil()) as usize).min(self.h);
                // A cap that holds no pole spans |Δφ| ≤ asin(sin α / sin θ).
                let all_columns =
                    theta - alpha <= 0.0 || theta + alpha >= PI || alpha.sin() >= theta.sin();
                let columns: Vec<usize> = if all_columns {
                    (0..self.w).collect()
                } else {
                    let dphi = (alpha.sin() / theta.sin()).asin();
                    let first = ((phi - dphi) / (2.0 * PI) * w).floor() as i64 - 1;
                    let last = ((phi + dphi) / (2.0 * PI) * w).ceil() as i64 + 1;
                    if last - first + 1 >= self.w as i64 {
                        (0..self.w).collect()
                    } else {
                        (first..=last)
                            .map(|i| i.rem_euclid(self.w as i64) as usize)
                            .collect()
                    }
                };
                (y0..y1)
                    .into_par_iter()
                    .flat_map_iter(|y| columns.iter().filter_map(move |&x| near(x, y)))
                    .collect()
            }
            Mapping::EqualArea => (0..self.h)
                .into_par_iter()
                .flat_map_iter(|y| (0..self.w).filter_map(move |x| near(x, y)))
                .collect(),
        }
    }
}

/// Finds the source on the unscaled image, in the light frame (module docs).
fn find(image: &EnvImage, grid: &Grid, options: &SunOptions) -> Option<Found> {
    let max_radius = options.max_angular_radius_deg.to_radians();
    let pitch = grid.pitch();
    // A NaN or non-positive largest radius admits no sun.
    if max_radius.is_nan() || max_radius <= 0.0 || pitch >= max_radius {
        return None;
    }
    let total = grid.luminance_integral(image);
    if !(total > 0.0 && total.is_finite()) {
        return None;
    }
    let (px, py, peak) = image.brightest_texel();
    let peak = peak as f64;
    if peak.is_nan() || peak <= 0.0 {
        return None;
    }

    // 1. The core: above half the peak, contiguous in annuli from the centre.
    let core_limit = 2.0 * max_radius;
    let mut centre = grid.direction(px, py);
    let mut near = grid.gather(image, centre, core_limit + 2.0 * pitch);
    let mut core_radius = 0.0;
    for _ in 0..3 {
        set_deltas(&mut near, centre);
        core_radius = core_extent(&near, 0.5 * peak, pitch);
        if core_radius > core_limit {
            return None;
        }
        let mut moment = [0.0; 3];
        for t in near
            .iter()
            .filter(|t| t.delta < core_radius && t.y >= 0.5 * peak)
        {
            add_scaled(&mut moment, t.dir, t.y * t.solid_angle);
        }
        centre = normalize(moment)?;
    }

    // 2. The extent: out to where the radial profile flattens.
    let extent_limit = (2.0 * core_radius + 6.0 * pitch)
        .min(3.0 * max_radius)
        .max(core_radius + 2.0 * pitch);
    let ring_width = |extent: f64| (RING_MIN_TEXELS * pitch).max(0.5 * extent);
    let reach = extent_limit + ring_width(extent_limit) + 2.0 * pitch;
    let mut near = grid.gather(image, centre, reach);
    set_deltas(&mut near, centre);
    let extent = profile_extent(&near, core_radius, extent_limit, pitch);

    // 3. The fill, fitted to the ring around the source.
    let outer = extent + ring_width(extent);
    let ring: Vec<&Near> = near
        .iter()
        .filter(|t| t.delta >= extent && t.delta < outer)
        .collect();
    let ring_median = median(ring.iter().map(|t| t.y).collect());
    let fill = Fill::fit(image, &ring, ring_median, centre, outer);

    // 4. The excess and its moments.
    let mut replaced = Vec::new();
    let mut moment_y = [0.0; 3];
    let mut moment_rgb = [[0.0; 3]; 3];
    let mut energy_y = 0.0;
    let mut peak_excess: f64 = 0.0;
    for t in near.iter().filter(|t| t.delta < extent) {
        let original = image.texels()[t.index];
        let f = fill.at(t.dir);
        let (y_original, y_fill) = (lum(original), lum_f64(f));
        // Brighter than the sky around it: the source. Far darker: the source's
        // own reconstruction artefacts (the black ringing that lossy codecs leave
        // round a clipped sun), which would otherwise stay as a dotted disc. Both
        // become the fill; sky-like texels keep their texture.
        let replace = y_original > y_fill || y_original < 0.5 * y_fill;
        let kept: [f32; 3] = if replace {
            f.map(|v| v as f32)
        } else {
            original
        };
        let excess: [f64; 3] = [0, 1, 2].map(|c| (original[c] - kept[c]) as f64);
        let e_y = lum_f64(excess);
        for c in 0..3 {
            add_scaled(&mut moment_rgb[c], t.dir, excess[c] * t.solid_angle);
        }
        add_scaled(&mut moment_y, t.dir, e_y * t.solid_angle);
        energy_y += e_y * t.solid_angle;
        peak_excess = peak_excess.max(e_y);
        if kept != original {
            replaced.push((t.index, kept));
        }
    }
    let direction = normalize(moment_y)?;
    if !(energy_y > 0.0 && peak_excess > 0.0) {
        return None;
    }
    let solid_angle = (energy_y / peak_excess).min(2.0 * PI);
    let angular_radius = (1.0 - solid_angle / (2.0 * PI)).clamp(-1.0, 1.0).acos();
    let irradiance = moment_rgb.map(|m| dot3(m, direction).max(0.0));
    let sin_r = angular_radius.sin();
    let disc_factor = PI * sin_r * sin_r;
    let radiance = irradiance.map(|e| e / disc_factor);
    let contrast = if ring_median > 0.0 {
        lum_f64(radiance) / ring_median
    } else {
        f64::INFINITY
    };
    let power_fraction = (energy_y / total).min(1.0);
    let accepted = angular_radius <= max_radius
        && contrast >= options.min_contrast
        && power_fraction >= options.min_power_fraction
        && irradiance.iter().chain(&radiance).all(|v| v.is_finite());
    accepted.then_some(Found {
        direction,
        angular_radius,
        solid_angle,
        radiance,
        irradiance,
        power_fraction,
        contrast,
        replaced,
    })
}

fn set_deltas(near: &mut [Near], centre: [f64; 3]) {
    for t in near.iter_mut() {
        t.delta = angle_between(t.dir, centre);
    }
}

/// Walks annuli one pitch wide from the centre while each holds a texel at or
/// above `threshold` (an annulus holding no texel at all neither extends nor ends
/// the run); returns the outer radius of the last such annulus.
fn core_extent(near: &[Near], threshold: f64, pitch: f64) -> f64 {
    let bins = near
        .iter()
        .map(|t| (t.delta / pitch) as usize)
        .max()
        .map_or(0, |b| b + 1);
    // Per annulus: 0 = empty, 1 = only dim texels, 2 = some bright texel.
    let mut state = vec![0u8; bins];
    for t in near {
        let k = (t.delta / pitch) as usize;
        state[k] = state[k].max(if t.y >= threshold { 2 } else { 1 });
    }
    let mut extent = 0;
    for (k, &s) in state.iter().enumerate() {
        match s {
            2 => extent = k + 1,
            1 => break,
            _ => {}
        }
    }
    extent as f64 * pitch
}

/// The source's radius: from the core outwards, the first annulus whose mean
/// luminance is followed by two that no longer fall by [`FLAT_PROFILE_DROP`], plus
/// that annulus as a margin; between `core + 2 pitch` and `limit`.
fn profile_extent(near: &[Near], core: f64, limit: f64, pitch: f64) -> f64 {
    let bins = ((limit / pitch).ceil() as usize) + 3;
    let mut sum = vec![(0.0f64, 0.0f64); bins];
    for t in near {
        let k = (t.delta / pitch) as usize;
        if k < bins {
            sum[k].0 += t.y * t.solid_angle;
            sum[k].1 += t.solid_angle;
        }
    }
    // Empty annuli (none near the centre of a fine map) are skipped.
    let means: Vec<(usize, f64)> = sum
        .iter()
        .enumerate()
        .filter(|(_, s)| s.1 > 0.0)
        .map(|(k, s)| (k, s.0 / s.1))
        .collect();
    let first = (core / pitch).floor() as usize;
    let flat = |a: f64, b: f64| b >= (1.0 - FLAT_PROFILE_DROP) * a;
    let mut extent = limit;
    for i in 0..means.len().saturating_sub(2) {
        let (k, m) = means[i];
        if k < first {
            continue;
        }
        if flat(m, means[i + 1].1) && flat(means[i + 1].1, means[i + 2].1) {
            extent = (k + 1) as f64 * pitch;
            break;
        }
    }
    extent.max(core + 2.0 * pitch).min(limit)
}

/// The in-painting surface: per channel `a + b x + c y + d x² + e xy + f y²` in
/// the tangent plane at the centre (coordinates divided by the ring's outer
/// radius), clamped to the ring's range.
struct Fill {
    axes: [[f64; 3]; 2],
    scale: f64,
    coefficients: [[f64; 6]; 3],
    max: [f64; 3],
}

impl Fill {
    fn fit(image: &EnvImage, ring: &[&Near], median: f64, centre: [f64; 3], outer: f64) -> Self {
        let axes = tangent_axes(centre);
        let scale = outer.sin().max(1e-9);
        let used: Vec<&&Near> = ring
            .iter()
            .filter(|t| median <= 0.0 || t.y <= RING_OUTLIER * median)
            .collect();
        let mut max = [0.0f64; 3];
        let mut mean = [0.0f64; 3];
        let mut weight = 0.0;
        let mut normal = [[0.0f64; 6]; 6];
        let mut rhs = [[0.0f64; 6]; 3];
        for t in &used {
            let l = image.texels()[t.index];
            let basis = basis(axes, scale, t.dir);
            for c in 0..3 {
                max[c] = max[c].max(l[c] as f64);
                mean[c] += l[c] as f64 * t.solid_angle;
                for (r, b) in rhs[c].iter_mut().zip(basis) {
                    *r += t.solid_angle * b * l[c] as f64;
                }
            }
            weight += t.solid_angle;
            for i in 0..6 {
                for j in 0..6 {
                    normal[i][j] += t.solid_angle * basis[i] * basis[j];
                }
            }
        }
        let mean = mean.map(|m| if weight > 0.0 { m / weight } else { 0.0 });
        let constant = |m: f64| [m, 0.0, 0.0, 0.0, 0.0, 0.0];
        let coefficients = if used.len() >= 24 {
            [0, 1, 2].map(|c| solve6(normal, rhs[c]).unwrap_or(constant(mean[c])))
        } else {
            mean.map(constant)
        };
        Self {
            axes,
            scale,
            coefficients,
            max,
        }
    }

    fn at(&self, dir: [f64; 3]) -> [f64; 3] {
        let b = basis(self.axes, self.scale, dir);
        [0, 1, 2].map(|c| {
            let v: f64 = self.coefficients[c].iter().zip(b).map(|(k, b)| k * b).sum();
            if v.is_finite() {
                v.clamp(0.0, self.max[c])
            } else {
                0.0
            }
        })
    }
}

fn basis(axes: [[f64; 3]; 2], scale: f64, dir: [f64; 3]) -> [f64; 6] {
    let x = dot3(dir, axes[0]) / scale;
    let y = dot3(dir, axes[1]) / scale;
    [1.0, x, y, x * x, x * y, y * y]
}

/// Two unit vectors that make a right-handed orthonormal frame with `n`.
fn tangent_axes(n: [f64; 3]) -> [[f64; 3]; 2] {
    let helper = if n[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let a = normalize(cross3(helper, n)).unwrap_or([1.0, 0.0, 0.0]);
    let b = cross3(n, a);
    [a, b]
}

/// Solves the 6×6 system by Gaussian elimination with partial pivoting; `None`
/// when it is (numerically) singular.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale.is_nan() || scale <= 0.0 {
        return None;
    }
    for col in 0..6 {
        let pivot = (col..6).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        let pivot_row = a[col];
        for row in col + 1..6 {
            let f = a[row][col] / pivot_row[col];
            for (v, p) in a[row][col..].iter_mut().zip(&pivot_row[col..]) {
                *v -= f * p;
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for row in (0..6).rev() {
        let s: f64 = (row + 1..6).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn median(mut values: Vec<f64>) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    let mid = values.len() / 2;
    *values.select_nth_unstable_by(mid, f64::total_cmp).1
}

#[inline]
fn lum(t: [f32; 3]) -> f64 {
    lum_f64(t.map(|c| c as f64))
}

#[inline]
fn lum_f64(t: [f64; 3]) -> f64 {
    let w = LUMINANCE_WEIGHTS;
    w[0] as f64 * t[0] + w[1] as f64 * t[1] + w[2] as f64 * t[2]
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let len = dot3(v, v).sqrt();
    (len > 0.0 && len.is_finite()).then(|| v.map(|c| c / len))
}

fn add_scaled(acc: &mut [f64; 3], v: [f64; 3], s: f64) {
    for k in 0..3 {
        acc[k] += v[k] * s;
    }
}

/// The angle between two unit vectors, accurate for small angles.
#[inline]
fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
    let c = cross3(a, b);
    dot3(c, c).sqrt().atan2(dot3(a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::LightOptions;

    fn light(w: usize, h: usize, f: impl FnMut(usize, usize) -> [f32; 3]) -> EnvironmentLight {
        EnvironmentLight::new(EnvImage::from_fn(w, h, f).unwrap(), LightOptions::default()).unwrap()
    }

    #[test]
    fn degenerate_maps_have_no_sun() {
        assert!(light(1, 1, |_, _| [5.0; 3]).sun().is_none());
        assert!(light(64, 32, |_, _| [0.0; 3]).sun().is_none());
        assert!(light(64, 32, |_, _| [1.0; 3]).sun().is_none());
        assert!(light(512, 256, |_, _| [2.0, 1.0, 0.5]).sun().is_none());
    }

    #[test]
    fn a_hot_block_is_found_and_removed() {
        // A 4×4 block of texels on the equator of a 512×256 map, 1e4 × the sky.
        let l = light(512, 256, |x, y| {
            if (200..204).contains(&x) && (126..130).contains(&y) {
                [1e4; 3]
            } else {
                [1.0; 3]
            }
        });
        let ex = l.extract_sun(&SunOptions::default());
        let sun = ex.sun.expect("a sun");
        let phi = 2.0 * PI * 202.0 / 512.0;
        let expected = [phi.cos(), phi.sin(), 0.0];
        let d = sun.direction;
        let err = angle_between([d.x as f64, d.y as f64, d.z as f64], expected);
        assert!(err < 1e-3, "{err}");
        assert!(ex.inpainted_texels >= 16);
        let (_, _, y) = ex.residual.brightest_texel();
        assert!(y <= 1.0 + 1e-5, "{y}");
        // Solid angle of the block: 16 texels of about (π/256)² each.
        let block = 16.0 * (PI / 256.0) * (2.0 * PI / 512.0);
        assert!(
            (sun.solid_angle / block - 1.0).abs() < 0.01,
            "{}",
            sun.solid_angle
        );
    }

    #[test]
    fn linear_solver_solves() {
        let mut a = [[0.0; 6]; 6];
        for (i, row) in a.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                *v = if i == j {
                    4.0
                } else {
                    1.0 / (1 + i + j) as f64
                };
            }
        }
        let x = [1.0, -2.0, 3.0, 0.5, 0.0, 7.0];
        let b = a.map(|row| row.iter().zip(x).map(|(a, x)| a * x).sum());
        let got = solve6(a, b).unwrap();
        for k in 0..6 {
            assert!((got[k] - x[k]).abs() < 1e-12);
        }
        assert!(solve6([[0.0; 6]; 6], [1.0; 6]).is_none());
    }
}
