//! The fine level's patches as other samplers in the crate read them: the
//! visibility cache (module `visibility`, above this one) weights each patch by
//! what a region of the scene sees through it, and draws within a patch from the
//! light's own density, as the product sampler does.

use super::bounds::Direction;
use super::ProductSampler;
use crate::math::Vec3;

/// A read-only view of a [`ProductSampler`]'s patches (module docs of
/// [`crate::product`]: patch `k` holds the share `P_k` of the light's density,
/// and draws within it follow that density restricted to the patch).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Patches<'a> {
    sampler: &'a ProductSampler,
}

impl ProductSampler {
    /// The patches of the fine level.
    pub(crate) fn patches_view(&self) -> Patches<'_> {
        Patches { sampler: self }
    }
}

impl Patches<'_> {
    /// `Pw · Ph`.
    #[inline]
    pub fn count(&self) -> usize {
        self.sampler.fine.power.len()
    }

    /// `P_k`, patch `k`'s share of the light's density (0 for an unlit patch).
    #[inline]
    pub fn power(&self, k: usize) -> f64 {
        self.sampler.fine.power[k]
    }

    /// An upper bound of `v·ω` over the lit directions of patch `k`, for a unit
    /// world direction `v`; `None` for a patch without power.
    pub fn max_dot(&self, k: usize, v: Vec3) -> Option<f64> {
        let local = self.sampler.light.world_to_local(v);
        let direction = Direction::new([local.x as f64, local.y as f64, local.z as f64]);
        self.sampler.fine.regions[k]
            .as_ref()
            .map(|r| r.max_dot(&direction))
    }

    /// A world direction of patch `k` (which has power) drawn from the light's
    /// density restricted to the patch, for `ξ ∈ [0, 1)²`, with its image point.
    /// `None` on a pole of a lat-long map (measure zero).
    #[inline]
    pub fn sample(&self, k: usize, xi: [f64; 2]) -> Option<(Vec3, [f32; 2])> {
        let light = &self.sampler.light;
        let (uv, _) = self.sampler.fine.sample(k, xi, |uv| {
            light.image().prefetch(uv[0], uv[1]);
        });
        let (local, jacobian) = light.uv_to_local(uv);
        (jacobian > 0.0).then(|| (light.local_to_world(local), uv))
    }

    /// The patch of world direction `direction`, the light's density in `(u, v)`
    /// there restricted to that patch, `q(u, v | k)`, and `1 / J(ω)` (for
    /// [`crate::light::solid_angle_density`]). `None` where the light's density
    /// is 0.
    #[inline]
    pub fn locate(&self, direction: Vec3) -> Option<(usize, f64, f32)> {
        let light = &self.sampler.light;
        let (uv, inv_jacobian) = light.local_to_uv(light.world_to_local(direction));
        let (k, planar) = self.sampler.fine.locate(uv)?;
        Some((k, planar, inv_jacobian))
    }
}
