//! The bright patches: the few patches that hold the most light (a sun, a lamp),
//! weighted at every shading point by the factor itself, at that point's own
//! normal (and mirror direction), rather than through the grid's tables.
//!
//! A table mixes what its node sees. A shading point between nodes mixes four of
//! them, so a bright patch that one node sees just above its horizon gets that
//! node's share of samples even when the point's own surface cannot see it: a low
//! sun put up to 19% of a surface's product samples below its horizon (issue 35).
//! Weighted per point, a bright patch gets `P_k · max(f(c_k), s · B_k)`, with `f`
//! the factor at the patch's centre of light and `B_k` the factor's exact upper
//! bound over the patch for this normal (`s = BOUND_SHARE`): nothing when the
//! patch is wholly below the horizon, something whenever any of it is above, and
//! the factor's own value, cosine and lobe together, otherwise. The tables give
//! these patches no weight; a shading point mixes the tables' component, weighted
//! by the sum of the mixed tables' weights, with the bright patches' weights.

use super::bounds::{Direction, PatchBound, Region};
use super::factor::lobe_proxy;
use super::fine::Fine;
use super::tuning::{BRIGHT_MAX_HALF_ANGLE, BRIGHT_SHARE, MAX_BRIGHT};
use crate::math::dot3;

/// One bright patch, with what its weight needs, stored together.
#[derive(Debug, Clone, Copy)]
pub(super) struct Item {
    /// Its patch index.
    pub patch: u32,
    /// Its share of the light's power.
    pub power: f64,
    /// Its directions, bounded.
    pub region: Region,
    /// Its centre of light, a unit light-frame direction.
    pub centre: [f64; 3],
}

/// The bright patches of a fine level (see the module docs).
#[derive(Debug, Clone)]
pub(super) struct Bright {
    /// Brightest first.
    items: Vec<Item>,
    /// Each patch's place in `items`, or [`Bright::NONE`].
    of_patch: Vec<u16>,
}

/// The factor a shading point weights the bright patches by, in the light frame.
#[derive(Debug, Clone, Copy)]
pub(super) enum Target {
    /// `max(0, n·ω)`.
    Cosine { normal: Direction },
    /// `max(0, n·ω) · D_α(r·ω)` (the lobe proxy of `factor`), `r` the mirror
    /// direction.
    Glossy {
        normal: Direction,
        mirror: Direction,
        alpha2: f64,
    },
}

impl Bright {
    const NONE: u16 = u16::MAX;

    /// The patches of `fine` holding at least [`BRIGHT_SHARE`] of its light
    /// within [`BRIGHT_MAX_HALF_ANGLE`], at most [`MAX_BRIGHT`], brightest first
    /// (ties by index). With `every`, every lit patch instead (the on-the-fly
    /// product, `ProductVariant::OnTheFly` of the `variants` feature).
    pub fn new(fine: &Fine, every: bool) -> Self {
        let mut order: Vec<usize> = (0..fine.power.len())
            .filter(|&k| {
                let lit = fine.power[k] > 0.0 && fine.regions[k].is_some();
                let bright = fine.power[k] >= BRIGHT_SHARE
                    && fine.regions[k]
                        .is_some_and(|r| r.cone.cos_half >= BRIGHT_MAX_HALF_ANGLE.cos());
                if every {
                    lit
                } else {
                    bright
                }
            })
            .collect();
        order.sort_by(|&a, &b| fine.power[b].total_cmp(&fine.power[a]).then(a.cmp(&b)));
        if !every {
            order.truncate(MAX_BRIGHT);
        }
        assert!(order.len() < Self::NONE as usize, "at most 65535 patches");
        let mut of_patch = vec![Self::NONE; fine.power.len()];
        let items = order
            .iter()
            .enumerate()
            .map(|(b, &k)| {
                of_patch[k] = b as u16;
                Item {
                    patch: k as u32,
                    power: fine.power[k],
                    region: fine.regions[k].expect("a bright patch is lit"),
                    centre: fine.centres[k],
                }
            })
            .collect();
        Self { items, of_patch }
    }

    /// Which patches are bright, patch by patch.
    pub fn mask(&self) -> Vec<bool> {
        self.of_patch.iter().map(|&b| b != Self::NONE).collect()
    }

    /// Bright patches.
    pub fn len(&self) -> usize {
        self.items.len()
    }

    /// The patch of bright patch `b`.
    #[inline]
    pub fn patch(&self, b: usize) -> usize {
        self.items[b].patch as usize
    }

    /// Patch `k`'s place among the bright patches, if it is one.
    #[inline(always)]
    pub fn index(&self, k: usize) -> Option<usize> {
        let b = self.of_patch[k];
        (b != Self::NONE).then_some(b as usize)
    }

    /// Each bright patch's weight for `target` into `out` (the first
    /// [`Self::len`] entries; the others are left as they are), and their sum.
    #[inline]
    pub fn weights(&self, target: &Target, bound: PatchBound, out: &mut [f64]) -> f64 {
        let mut total = 0.0;
        for (o, item) in out.iter_mut().zip(&self.items) {
            let (value, upper) = match target {
                // The bound (at most 1 and its slack) matters only when the
                // cosine at the centre is below its share of it.
                Target::Cosine { normal } => {
                    let value = dot3(normal.v, item.centre);
                    if bound.keeps_cosine(value) {
                        *o = item.power * value;
                        total += *o;
                        continue;
                    }
                    (value.max(0.0), item.region.max_dot(normal).max(0.0))
                }
                Target::Glossy {
                    normal,
                    mirror,
                    alpha2,
                } => {
                    let cos = dot3(normal.v, item.centre).max(0.0);
                    let cos_upper = item.region.max_dot(normal).max(0.0);
                    (
                        cos * lobe_proxy(*alpha2, dot3(mirror.v, item.centre)),
                        cos_upper * lobe_proxy(*alpha2, item.region.max_dot(mirror)),
                    )
                }
            };
            *o = item.power * bound.weight(value, upper, 1.0);
            total += *o;
        }
        total
    }

    /// The least lower bound of `n·ω` over the bright patches with weight that
    /// lie wholly above the horizon of the unit `normal` (bound above 0), when
    /// below `ceiling`; else `ceiling`. `weights` as [`Self::weights`] wrote them.
    pub fn lowest_above(&self, normal: &Direction, weights: &[f64], ceiling: f64) -> f64 {
        let opposite = Direction::new(normal.v.map(|x| -x));
        let mut lowest = ceiling;
        for (item, &w) in self.items.iter().zip(weights) {
            if w > 0.0 {
                let lower = -item.region.max_dot(&opposite);
                if lower > 0.0 && lower < lowest {
                    lowest = lower;
                }
            }
        }
        lowest
    }

    /// The bright patches, brightest first.
    pub fn items(&self) -> &[Item] {
        &self.items
    }

    /// Bytes held.
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of::<Item>() * self.items.len() + 2 * self.of_patch.len()
    }
}
