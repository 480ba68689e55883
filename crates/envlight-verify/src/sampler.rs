//! What the harness checks: a sampler of directions and its cell grid.

use crate::param::Param;
use envlight::{EnvironmentLight, LightSample, Rotation, Vec3};

/// One direction drawn by a sampler.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SphereSample {
    /// World-space unit direction.
    pub direction: Vec3,
    /// Its solid-angle density, per steradian.
    pub pdf: f32,
    /// Radiance arriving from it, as the sampler reports it.
    pub radiance: [f32; 3],
}

/// The cell grid of a sampler, in the frame that `to_world` carries to world space:
/// the lines along which its pdf (and radiance) may be discontinuous, or kinked
/// (at the cells' centre lines, for bilinear reconstructions). The harness aligns
/// quadrature, chi-square bins, support probes and the consistency checks' edge
/// exemption with it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Grid {
    /// `width × height` cells of the equirectangular map (docs/design.md §2): `φ = 2π u`,
    /// `θ = π v` ([`direction_at`](crate::direction_at)); u wraps, and the poles are singular.
    Equirect {
        /// Cells along u (φ).
        width: usize,
        /// Cells along v (θ).
        height: usize,
        /// Whether the radiance has its kinks along v at the rows as nodes from
        /// pole to pole (`v = j/(height-1)`, [`envlight::Lookup::Node`]) rather
        /// than at the cells' centre lines.
        node_rows: bool,
        /// Whether the sampler's map from `ξ` also jumps on the cells' centre lines
        /// along u and along v (the piecewise-bilinear density's patches run
        /// between texel centres): samples within rounding of them are exempt
        /// from the consistency checks, as at cell edges.
        centre_edges: [bool; 2],
        /// Grid frame to world.
        to_world: Rotation,
    },
    /// `size × size` cells of the equal-area octahedral square
    /// ([`square_to_sphere`](crate::square_to_sphere)): `dω = 4π du dv` everywhere, no singular point; the
    /// square's boundary is folded onto itself.
    EqualArea {
        /// Cells along u and along v.
        size: usize,
        /// As [`Grid::Equirect`]'s `centre_edges`.
        centre_edges: [bool; 2],
        /// Grid frame to world.
        to_world: Rotation,
    },
}

impl Grid {
    /// Grid frame to world.
    pub fn to_world(self) -> Rotation {
        match self {
            Grid::Equirect { to_world, .. } | Grid::EqualArea { to_world, .. } => to_world,
        }
    }

    /// Cells along u and v.
    pub fn cells(self) -> [usize; 2] {
        match self {
            Grid::Equirect { width, height, .. } => [width, height],
            Grid::EqualArea { size, .. } => [size, size],
        }
    }

    /// Along u and v, whether the cells' centre lines are edges of the sampler's
    /// map from `ξ` too.
    pub fn centre_edges(self) -> [bool; 2] {
        match self {
            Grid::Equirect { centre_edges, .. } | Grid::EqualArea { centre_edges, .. } => {
                centre_edges
            }
        }
    }

    /// The parameterisation the cells live in.
    pub fn param(self) -> Param {
        match self {
            Grid::Equirect { .. } => Param::Equirect,
            Grid::EqualArea { .. } => Param::EqualArea,
        }
    }
}

/// A sampler of directions with a density, the thing docs/design.md §5 constrains.
/// Adding a sampler to a test table means implementing this (usually by
/// delegation) and adding one line to the table.
pub trait SphereSampler: Sync {
    /// What the sampler is, for the printed report.
    fn name(&self) -> String;
    /// Draws a direction for `ξ ∈ [0,1)²`, or `None` (no light, or a null set).
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample>;
    /// Solid-angle density of a world direction, per steradian.
    fn pdf(&self, direction: Vec3) -> f32;
    /// The `ξ` that `sample` maps to `direction`, when the sampler can invert.
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]>;
    /// Radiance arriving from a world direction.
    fn radiance(&self, direction: Vec3) -> [f32; 3];
    /// The sampler's own claim of `∫ Y(L) dω`.
    fn integral_luminance(&self) -> f64;
    /// The cell grid the pdf is piecewise constant (or bilinear) on, if any (see
    /// [`Grid`]).
    fn grid(&self) -> Option<Grid> {
        None
    }
    /// The sampler's own figure for `(∫Y)² / ∫(Y²/p)`, if it reports one.
    fn reported_efficiency(&self) -> Option<f64> {
        None
    }
    /// A fold `(a, s)` (a unit world axis and `0 < s ≤ 1`) of the pdf off the
    /// grid: draws with `-s < a·ω < 0` are reflected to `ω − 2(a·ω)a` (a product
    /// sampler's horizon band), so the pdf jumps along the circles `a·ω = -s, 0, s`
    /// and, within `0 ≤ a·ω < s`, along the mirror images of the grid's edges. The
    /// quadrature splits the cells there ([`crate::Quadrature`]).
    fn fold(&self) -> Option<(Vec3, f32)> {
        None
    }
    /// [`Self::sample`] of every `ξ`, written to `out` (as long as `xi`) in order.
    /// The checks draw their samples through this, one call per chunk of `ξ`
    /// ([`over_sample_chunks`](crate::over_sample_chunks)); a sampler with a
    /// faster batch query (a GPU dispatch, vector lanes) overrides it, and its
    /// results must equal the single calls', bit for bit.
    fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<SphereSample>]) {
        for (o, &x) in out.iter_mut().zip(xi) {
            *o = self.sample(x);
        }
    }
    /// [`Self::pdf`] of every direction; a sampler with a faster batch query
    /// overrides this (its results must equal the single calls').
    fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        for (o, &d) in out.iter_mut().zip(directions) {
            *o = self.pdf(d);
        }
    }
    /// [`Self::radiance`] of every direction (see [`Self::pdf_batch`]).
    fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        for (o, &d) in out.iter_mut().zip(directions) {
            *o = self.radiance(d);
        }
    }
}

/// The methods a product-point sampler's [`SphereSampler`] impl ends with: no
/// inverse; radiance, integral and grid from its light (`self.light()`); the fold
/// from the factor's normal (`self.factor`) and the horizon band of the
/// [`envlight::ShadingPoint`] at `self.<field>`, whose draws there are reflected
/// above the horizon.
macro_rules! product_point_methods {
    (horizon_band_of: $field:ident) => {
        fn invert(&self, _: envlight::Vec3) -> Option<[f32; 2]> {
            None
        }
        fn radiance(&self, direction: envlight::Vec3) -> [f32; 3] {
            self.light().radiance(direction)
        }
        fn integral_luminance(&self) -> f64 {
            self.light().integral_luminance()
        }
        fn grid(&self) -> Option<$crate::sampler::Grid> {
            $crate::sampler::SphereSampler::grid(self.light())
        }
        fn fold(&self) -> Option<(envlight::Vec3, f32)> {
            let f = self.factor.normalized()?;
            Some((f.normal(), self.$field.horizon_band()))
        }
    };
}
pub(crate) use product_point_methods;

/// The harness's view of a light's sample (without its image point).
pub(crate) fn sphere_sample(s: LightSample) -> SphereSample {
    SphereSample {
        direction: s.direction,
        pdf: s.pdf,
        radiance: s.radiance,
    }
}

impl SphereSampler for EnvironmentLight {
    fn name(&self) -> String {
        let o = self.options();
        let rotated = if o.rotation.is_identity() {
            ""
        } else {
            ", rotated"
        };
        let mapping = match self.mapping() {
            envlight::light::Mapping::Equirectangular => "",
            envlight::light::Mapping::EqualArea => " equal-area",
        };
        format!(
            "EnvironmentLight {}x{}{mapping} {:?}{rotated}",
            self.image().width(),
            self.image().height(),
            o.lookup
        )
    }
    fn sample(&self, xi: [f32; 2]) -> Option<SphereSample> {
        EnvironmentLight::sample(self, xi).map(sphere_sample)
    }
    fn sample_batch(&self, xi: &[[f32; 2]], out: &mut [Option<SphereSample>]) {
        // The light's batch sampler is bit for bit its single samples (its own
        // tests and tests/threads.rs check that, for every sampler and density).
        let mut samples = vec![None; xi.len()];
        EnvironmentLight::sample_batch(self, xi, &mut samples);
        for (o, s) in out.iter_mut().zip(samples) {
            *o = s.map(sphere_sample);
        }
    }
    fn pdf(&self, direction: Vec3) -> f32 {
        EnvironmentLight::pdf(self, direction)
    }
    fn invert(&self, direction: Vec3) -> Option<[f32; 2]> {
        EnvironmentLight::invert(self, direction)
    }
    fn radiance(&self, direction: Vec3) -> [f32; 3] {
        EnvironmentLight::radiance(self, direction)
    }
    fn integral_luminance(&self) -> f64 {
        EnvironmentLight::integral_luminance(self)
    }
    fn grid(&self) -> Option<Grid> {
        // The pdf lives on the texels of the light's own image, in its own mapping
        // (for an equal-area light, the resampled square).
        let to_world = self.options().rotation;
        let (h, options) = (self.image().height(), self.options());
        let node_rows = options.lookup == envlight::Lookup::Node;
        // The piecewise-bilinear density's patches run between its nodes: the
        // texel centres along u, and along v the centres too, or the node
        // lookup's rows (then the grid's own rows, below).
        let bilinear = options.density == envlight::light::Density::PiecewiseBilinear;
        Some(match self.mapping() {
            // The node lookup's piecewise-bilinear density lives on the `h - 1`
            // intervals between its node rows `k/(h-1)` (where the radiance has
            // its kinks too), bilinear on each: a uniform grid of those rows.
            envlight::light::Mapping::Equirectangular if node_rows && h >= 2 && bilinear => {
                Grid::Equirect {
                    width: self.image().width(),
                    height: h - 1,
                    node_rows: false,
                    centre_edges: [true, false],
                    to_world,
                }
            }
            envlight::light::Mapping::Equirectangular => Grid::Equirect {
                width: self.image().width(),
                height: self.image().height(),
                node_rows,
                centre_edges: [bilinear, bilinear],
                to_world,
            },
            envlight::light::Mapping::EqualArea => Grid::EqualArea {
                size: self.image().width(),
                centre_edges: [bilinear, bilinear],
                to_world,
            },
        })
    }
    fn reported_efficiency(&self) -> Option<f64> {
        Some(self.efficiency())
    }
    fn pdf_batch(&self, directions: &[Vec3], out: &mut [f32]) {
        EnvironmentLight::pdf_batch(self, directions, out)
    }
    fn radiance_batch(&self, directions: &[Vec3], out: &mut [[f32; 3]]) {
        EnvironmentLight::radiance_batch(self, directions, out)
    }
}
