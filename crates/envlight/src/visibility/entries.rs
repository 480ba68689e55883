//! Grouping points into entries: a cubic cell of side `r` of world space times a
//! cell of an octahedral grid of normals, found again by a hash of the two.

use super::{VisibilityError, VisibilityOptions};
use crate::mapping::octahedral::sphere_to_octahedral;
use crate::math::Vec3;
use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Cell coordinates keep 18 bits each (±131 071 cells from the origin) in a key.
const COORD_BITS: u32 = 18;
const COORD_LIMIT: f32 = (1 << (COORD_BITS - 1)) as f32 - 1.0;

/// How many times the automatic radius is refined towards its target count.
const RADIUS_ROUNDS: usize = 8;

/// The lookup from a point and normal to an entry.
#[derive(Debug, Clone)]
pub(crate) struct Grid {
    radius: f32,
    inv_radius: f32,
    bins: usize,
    map: HashMap<u64, u32, BuildHasherDefault<KeyHasher>>,
    /// Each entry's key, by entry.
    keys: Vec<u64>,
}

/// The points of each entry, by index, in the order entries are numbered.
pub(crate) type Groups = Vec<Vec<u32>>;

impl Grid {
    /// The grid for `points` (with unit `normals`) under `options`, and the
    /// points of each entry. With no radius given, the radius is refined until
    /// about `target_entries` entries form; either way it grows until the
    /// entries fit the memory budget at `entry_bytes` each.
    pub fn group(
        points: &[Vec3],
        normals: &[Vec3],
        options: &VisibilityOptions,
        entry_bytes: usize,
    ) -> (Self, Groups) {
        let max_entries = (options.memory_budget / entry_bytes.max(1)).max(1);
        // The largest coordinate sets the smallest radius a key can hold.
        let extent = points
            .iter()
            .map(|p| p.x.abs().max(p.y.abs()).max(p.z.abs()))
            .fold(0.0f32, f32::max);
        let min_radius = (extent / COORD_LIMIT).max(f32::MIN_POSITIVE);
        let mut radius = match options.radius {
            Some(r) => r.max(min_radius),
            None => {
                let target = options.target_entries.min(max_entries).max(1);
                auto_radius(points, normals, options.normal_bins, target, min_radius)
            }
        };
        loop {
            let mut grid = Self::new(radius, options.normal_bins);
            let groups = grid.fill(points, normals);
            if groups.len() <= max_entries {
                return (grid, groups);
            }
            // Surfaces: entries fall about as the square of the radius.
            radius *= ((groups.len() as f32 / max_entries as f32).sqrt()).max(1.05);
        }
    }

    fn new(radius: f32, bins: usize) -> Self {
        Self {
            radius,
            inv_radius: 1.0 / radius,
            bins,
            map: HashMap::default(),
            keys: Vec::new(),
        }
    }

    /// The grid of a saved cache: entry `e` has key `keys[e]`.
    pub fn from_keys(radius: f32, bins: usize, keys: &[u64]) -> Result<Self, String> {
        if !(radius > 0.0 && radius.is_finite()) {
            return Err(format!("radius {radius}: must be positive and finite"));
        }
        let mut grid = Self::new(radius, bins);
        for (e, &key) in keys.iter().enumerate() {
            if (key & 0xff) as usize >= bins * bins {
                return Err(format!(
                    "entry {e}: normal bin {} of {}",
                    key & 0xff,
                    bins * bins
                ));
            }
            if grid.map.insert(key, e as u32).is_some() {
                return Err(format!("entry {e}: the key of an earlier entry"));
            }
        }
        grid.keys = keys.to_vec();
        Ok(grid)
    }

    /// Each entry's key, by entry.
    pub fn keys(&self) -> &[u64] {
        &self.keys
    }

    /// Numbers the keys of `points` in order of first appearance; returns the
    /// points of each.
    fn fill(&mut self, points: &[Vec3], normals: &[Vec3]) -> Groups {
        let mut groups: Groups = Vec::new();
        self.map.clear();
        self.keys.clear();
        for (i, (&p, &n)) in points.iter().zip(normals).enumerate() {
            let Some(key) = self.key(p, n) else { continue };
            let next = groups.len() as u32;
            let e = *self.map.entry(key).or_insert(next);
            if e == next {
                groups.push(Vec::new());
                self.keys.push(key);
            }
            groups[e as usize].push(i as u32);
        }
        groups
    }

    /// The key of a point and a unit normal; `None` for a non-finite one.
    #[inline]
    fn key(&self, p: Vec3, n: Vec3) -> Option<u64> {
        let cell = |x: f32| {
            let c = (x * self.inv_radius).floor();
            (c.abs() <= COORD_LIMIT).then_some(c as i64)
        };
        let (x, y, z) = (cell(p.x)?, cell(p.y)?, cell(p.z)?);
        let n = n.normalized()?;
        let [s, t] = sphere_to_octahedral(n);
        let b = self.bins as f32;
        let bin = ((s * b) as usize).min(self.bins - 1) * self.bins
            + ((t * b) as usize).min(self.bins - 1);
        let mask = (1u64 << COORD_BITS) - 1;
        Some(
            ((x as u64 & mask) << (2 * COORD_BITS + 8))
                | ((y as u64 & mask) << (COORD_BITS + 8))
                | ((z as u64 & mask) << 8)
                | bin as u64,
        )
    }

    /// The entry of `(p, n)`, if a point of the build shares its key.
    #[inline]
    pub fn find(&self, p: Vec3, n: Vec3) -> Option<u32> {
        self.map.get(&self.key(p, n)?).copied()
    }

    /// The cells' side.
    pub fn radius(&self) -> f32 {
        self.radius
    }

    /// Bytes of the lookup (its table's slots).
    pub fn memory_bytes(&self) -> usize {
        self.map.capacity() * (std::mem::size_of::<(u64, u32)>() + 1) + 8 * self.keys.len()
    }
}

/// A radius giving about `target` entries: entries over surfaces fall as the
/// square of the radius, so each round scales it by `√(count / target)`.
fn auto_radius(
    points: &[Vec3],
    normals: &[Vec3],
    bins: usize,
    target: usize,
    min_radius: f32,
) -> f32 {
    let (lo, hi) = points.iter().fold(
        (
            Vec3::new(f32::MAX, f32::MAX, f32::MAX),
            Vec3::new(f32::MIN, f32::MIN, f32::MIN),
        ),
        |(lo, hi), p| {
            (
                Vec3::new(lo.x.min(p.x), lo.y.min(p.y), lo.z.min(p.z)),
                Vec3::new(hi.x.max(p.x), hi.y.max(p.y), hi.z.max(p.z)),
            )
        },
    );
    let diagonal = if points.is_empty() {
        1.0
    } else {
        (hi - lo).length()
    };
    let mut radius = (diagonal / (target as f32).sqrt()).max(min_radius);
    if !(radius > 0.0 && radius.is_finite()) {
        radius = 1.0f32.max(min_radius);
    }
    for _ in 0..RADIUS_ROUNDS {
        let count = Grid::new(radius, bins).fill(points, normals).len();
        let ratio = count as f32 / target as f32;
        if (0.7..=1.3).contains(&ratio) || count == 0 {
            break;
        }
        radius = (radius * ratio.sqrt()).max(min_radius);
    }
    radius
}

/// The unit normals of `normals`, after checking every point and normal.
pub(crate) fn checked_points<E>(
    points: &[Vec3],
    normals: &[Vec3],
) -> Result<Vec<Vec3>, VisibilityError<E>> {
    points
        .iter()
        .zip(normals)
        .enumerate()
        .map(|(index, (p, n))| {
            let finite = |v: &Vec3| v.x.is_finite() && v.y.is_finite() && v.z.is_finite();
            if !finite(p) {
                return Err(VisibilityError::Point {
                    index,
                    what: format!("position ({}, {}, {}) is not finite", p.x, p.y, p.z),
                });
            }
            n.normalized()
                .filter(finite)
                .ok_or_else(|| VisibilityError::Point {
                    index,
                    what: format!("normal ({}, {}, {}) has no direction", n.x, n.y, n.z),
                })
        })
        .collect()
}

/// A hasher for the packed keys: one multiply and a fold, as the keys are
/// already spread over their bits.
#[derive(Debug, Default, Clone, Copy)]
pub(crate) struct KeyHasher(u64);

impl Hasher for KeyHasher {
    fn finish(&self) -> u64 {
        self.0
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }

    #[inline]
    fn write_u64(&mut self, x: u64) {
        let h = (self.0 ^ x).wrapping_mul(0x9e37_79b9_7f4a_7c15);
        self.0 = h ^ (h >> 29);
    }
}
