//! Saving and loading a [`VisibilityCache`]: what it learned, and the keys that
//! say what it was learned for.
//!
//! Layout (little-endian):
//!
//! ```text
//! magic "envlvis\0" | version u32 = 2 | light hash u64 | scene key: u32 length, UTF-8
//! radius f32 | normal_bins u32 | target_entries u64 | memory_budget u64 | rays_per_patch u32
//! refine_rays u32
//! learned_share f32 | prior f32 | seed u64 | patches u32 | rays u64 | entries u32
//! per entry: key u64 | normal 3 × f32 | cos_spread f32 | visibility patches × f32
//! ```
//!
//! Only the estimates are stored: each entry's distribution is rebuilt from them
//! by the same code as a build's, so a loaded cache samples exactly as the saved
//! one did. Every size is checked against the bytes present before anything is
//! allocated for it, and every value against its range.

use super::entries::Grid;
use super::learn::{cosine_bounds, entry};
use super::{VisibilityCache, VisibilityOptions};
use crate::error::{Error, Result};
use crate::light::EnvironmentLight;
use crate::math::Vec3;
use crate::product::ProductSampler;
use crate::rng::mix64;
use std::path::Path;
use std::sync::Arc;

const MAGIC: &[u8; 8] = b"envlvis\0";
/// The version of the file layout this library writes and reads.
pub const FILE_VERSION: u32 = 2;
const FORMAT: &str = "envlight visibility cache";
/// The longest scene key a file may hold.
pub const MAX_SCENE_KEY: usize = 1 << 16;

/// A 64-bit hash of what a cache's entries depend on: the light's image, its
/// options (rotation, density, mapping, ...) and the product sampler's patch
/// grid. Two lights with the same hash sample the same patches the same way.
pub fn light_hash(product: &ProductSampler) -> u64 {
    let light: &EnvironmentLight = product.light();
    let image = light.image();
    let mut h = mix64(0x656e_766c_6967_6874);
    let mut add = |word: u64| h = mix64(h ^ word);
    add(image.width() as u64);
    add(image.height() as u64);
    for t in image.texels() {
        add((t[0].to_bits() as u64) << 32 | t[1].to_bits() as u64);
        add(t[2].to_bits() as u64);
    }
    for b in format!("{:?}", light.options()).bytes() {
        add(b as u64);
    }
    let [pw, ph] = product.patches();
    add(pw as u64);
    add(ph as u64);
    h
}

impl VisibilityCache {
    /// Writes the cache to `path` with the caller's `scene_key` (what says which
    /// scene it was learned in: a file name and a version, a hash of the
    /// geometry). The file is written whole or not at all.
    ///
    /// # Errors
    /// [`Error::Io`] naming the path; [`Error::InvalidOption`] for a key longer
    /// than [`MAX_SCENE_KEY`] bytes.
    pub fn save(&self, path: &Path, scene_key: &str) -> Result<()> {
        let bytes = self.to_bytes(scene_key)?;
        let io = |error| Error::Io {
            source_name: path.display().to_string(),
            error,
        };
        let tmp = path.with_extension("envlvis-partial");
        std::fs::write(&tmp, &bytes).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            io(e)
        })
    }

    /// The file's bytes.
    pub fn to_bytes(&self, scene_key: &str) -> Result<Vec<u8>> {
        if scene_key.len() > MAX_SCENE_KEY {
            return Err(Error::InvalidOption(format!(
                "scene key of {} bytes: at most {MAX_SCENE_KEY}",
                scene_key.len()
            )));
        }
        let o = &self.options;
        let patches = self.product.patches_view().count();
        let mut w = Vec::with_capacity(128 + self.entries.len() * (24 + 4 * patches));
        w.extend_from_slice(MAGIC);
        w.extend_from_slice(&FILE_VERSION.to_le_bytes());
        w.extend_from_slice(&light_hash(&self.product).to_le_bytes());
        w.extend_from_slice(&(scene_key.len() as u32).to_le_bytes());
        w.extend_from_slice(scene_key.as_bytes());
        w.extend_from_slice(&self.grid.radius().to_le_bytes());
        w.extend_from_slice(&(o.normal_bins as u32).to_le_bytes());
        w.extend_from_slice(&(o.target_entries as u64).to_le_bytes());
        w.extend_from_slice(&(o.memory_budget as u64).to_le_bytes());
        w.extend_from_slice(&(o.rays_per_patch as u32).to_le_bytes());
        w.extend_from_slice(&(o.refine_rays as u32).to_le_bytes());
        w.extend_from_slice(&o.learned_share.to_le_bytes());
        w.extend_from_slice(&o.prior.to_le_bytes());
        w.extend_from_slice(&o.seed.to_le_bytes());
        w.extend_from_slice(&(patches as u32).to_le_bytes());
        w.extend_from_slice(&self.rays.to_le_bytes());
        w.extend_from_slice(&(self.entries.len() as u32).to_le_bytes());
        for (key, entry) in self.grid.keys().iter().zip(&self.entries) {
            w.extend_from_slice(&key.to_le_bytes());
            for x in [
                entry.normal.x,
                entry.normal.y,
                entry.normal.z,
                entry.cos_spread,
            ] {
                w.extend_from_slice(&x.to_le_bytes());
            }
            for v in &entry.visibility {
                w.extend_from_slice(&v.to_le_bytes());
            }
        }
        Ok(w)
    }

    /// Reads a cache saved by [`Self::save`] for `product`'s light in the scene
    /// `scene_key`.
    ///
    /// # Errors
    /// [`Error::Io`] naming the path; [`Error::Decode`] for a file that is not a
    /// well-formed cache; [`Error::Mismatch`] naming both hashes or both keys
    /// when the file was made for another light or another scene.
    pub fn load(path: &Path, product: Arc<ProductSampler>, scene_key: &str) -> Result<Self> {
        let name = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|error| Error::Io {
            source_name: name.clone(),
            error,
        })?;
        Self::from_bytes(&bytes, &name, product, scene_key)
    }

    /// [`Self::load`] from the file's bytes; `source_name` names it in errors.
    pub fn from_bytes(
        bytes: &[u8],
        source_name: &str,
        product: Arc<ProductSampler>,
        scene_key: &str,
    ) -> Result<Self> {
        let mut r = Reader {
            bytes,
            at: 0,
            source_name,
        };
        let (saved, options) = read_header(&mut r)?;
        let hash = light_hash(&product);
        if saved.light_hash != hash || saved.scene_key != scene_key {
            return Err(Error::Mismatch {
                source_name: source_name.to_string(),
                detail: format!(
                    "made for light {:016x} in scene {:?}, \
                     asked for light {hash:016x} in scene {scene_key:?}",
                    saved.light_hash, saved.scene_key
                ),
            });
        }
        let (patches, rays, count, radius) =
            (saved.patches, saved.rays, saved.entries, saved.radius);
        let view = product.patches_view();
        if patches != view.count() {
            return Err(r.bad(format!(
                "{patches} patches, the light's sampler has {}",
                view.count()
            )));
        }
        let mut keys = Vec::with_capacity(count);
        let mut entries = Vec::with_capacity(count);
        for e in 0..count {
            let key = r.u64()?;
            let normal = Vec3::new(r.f32()?, r.f32()?, r.f32()?);
            let cos_spread = r.f32()?;
            let unit = (normal.length() - 1.0).abs() < 1e-3;
            if !unit || !(-1.0..=1.0).contains(&cos_spread) {
                return Err(r.bad(format!("entry {e}: normal or spread out of range")));
            }
            let visibility = (0..patches)
                .map(|_| r.f32())
                .collect::<Result<Vec<f32>>>()?;
            if let Some(k) = visibility.iter().position(|v| !(*v > 0.0 && *v <= 1.0)) {
                return Err(r.bad(format!(
                    "entry {e}, patch {k}: visibility {} outside (0, 1]",
                    visibility[k]
                )));
            }
            let bound = cosine_bounds(&view, normal, cos_spread);
            entries.push(entry(
                normal, cos_spread, &bound, visibility, &view, &options,
            ));
            keys.push(key);
        }
        let grid =
            Grid::from_keys(radius, options.normal_bins, &keys).map_err(|detail| r.bad(detail))?;
        Ok(Self {
            product,
            grid,
            entries,
            options,
            rays,
        })
    }
}

/// Reads the file's fields in order, every read checked against the bytes left.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    source_name: &'a str,
}

impl<'a> Reader<'a> {
    fn bad(&self, detail: String) -> Error {
        Error::Decode {
            source_name: self.source_name.to_string(),
            format: FORMAT,
            detail,
        }
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.at
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.left() {
            return Err(self.bad(format!(
                "truncated at byte {}: {n} more bytes expected, {} left",
                self.at,
                self.left()
            )));
        }
        let out = &self.bytes[self.at..self.at + n];
        self.at += n;
        Ok(out)
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N]> {
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn u32(&mut self) -> Result<u32> {
        self.array().map(u32::from_le_bytes)
    }

    fn u64(&mut self) -> Result<u64> {
        self.array().map(u64::from_le_bytes)
    }

    fn f32(&mut self) -> Result<f32> {
        self.array().map(f32::from_le_bytes)
    }
}

/// What a saved cache's header says it was made for, read without the light:
/// see [`read_keys`].
#[derive(Debug, Clone, PartialEq)]
pub struct SavedKeys {
    /// The [`light_hash`] of the light it was learned under.
    pub light_hash: u64,
    /// The scene key it was saved with.
    pub scene_key: String,
    /// The cells' side, world units.
    pub radius: f32,
    /// Patches of the product sampler's fine level (`Pw · Ph`).
    pub patches: usize,
    /// Entries held.
    pub entries: usize,
    /// Rays traced to build it.
    pub rays: u64,
}

/// Reads the keys of a cache saved by [`VisibilityCache::save`] from the file's
/// bytes, without the light: for a front end to say what a file was made for
/// before it builds (or to find that it cannot build) the light that
/// [`VisibilityCache::load`] needs. The header is checked as the loader checks
/// it, and the entries' size against the bytes that follow; the entries
/// themselves are not read. `source_name` names the file in errors.
///
/// # Errors
/// [`Error::Decode`] for a file that is not a well-formed cache header, or
/// whose length does not match its entries.
pub fn read_keys(bytes: &[u8], source_name: &str) -> Result<SavedKeys> {
    let mut r = Reader {
        bytes,
        at: 0,
        source_name,
    };
    read_header(&mut r).map(|(keys, _)| keys)
}

/// The header up to the first entry, checked (magic, version, key length,
/// options in range, the entries' bytes against what follows), with the
/// options it records; `r` is left at the first entry.
fn read_header(r: &mut Reader<'_>) -> Result<(SavedKeys, VisibilityOptions)> {
    if r.take(8)? != MAGIC {
        return Err(r.bad("not a visibility cache (no envlvis magic)".into()));
    }
    let version = r.u32()?;
    if version != FILE_VERSION {
        return Err(r.bad(format!(
            "version {version}, this library reads {FILE_VERSION}"
        )));
    }
    let light_hash = r.u64()?;
    let key_len = r.u32()? as usize;
    if key_len > MAX_SCENE_KEY {
        return Err(r.bad(format!(
            "scene key of {key_len} bytes (at most {MAX_SCENE_KEY})"
        )));
    }
    let scene_key = std::str::from_utf8(r.take(key_len)?)
        .map_err(|_| r.bad("the scene key is not UTF-8".into()))?
        .to_string();
    let radius = r.f32()?;
    let options = VisibilityOptions {
        radius: Some(radius),
        normal_bins: r.u32()? as usize,
        target_entries: r.u64()? as usize,
        memory_budget: r.u64()? as usize,
        rays_per_patch: r.u32()? as usize,
        refine_rays: r.u32()? as usize,
        learned_share: r.f32()?,
        prior: r.f32()?,
        seed: r.u64()?,
    };
    super::check_options::<std::convert::Infallible>(&options).map_err(|e| r.bad(e.to_string()))?;
    let patches = r.u32()? as usize;
    let rays = r.u64()?;
    let entries = r.u32()? as usize;
    let per_entry = 24 + 4 * patches;
    if entries.checked_mul(per_entry) != Some(r.left()) {
        return Err(r.bad(format!(
            "{entries} entries of {per_entry} bytes declared, {} bytes follow",
            r.left()
        )));
    }
    let keys = SavedKeys {
        light_hash,
        scene_key,
        radius,
        patches,
        entries,
        rays,
    };
    Ok((keys, options))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{builtin, LightOptions, ProductOptions};

    /// A cache of a few points on a floor under an open sky, built and saved.
    fn saved() -> (VisibilityCache, Vec<u8>) {
        let light = EnvironmentLight::new(builtin::sky(32, 16), LightOptions::default()).unwrap();
        let options = ProductOptions {
            patches: Some([8, 4]),
            ..Default::default()
        };
        let product = Arc::new(ProductSampler::new(Arc::new(light), options));
        let points: Vec<Vec3> = (0..16)
            .map(|i| Vec3::new((i % 4) as f32, (i / 4) as f32, 0.0))
            .collect();
        let normals = vec![Vec3::new(0.0, 0.0, 1.0); points.len()];
        let cache = VisibilityCache::build(
            product,
            &points,
            &normals,
            &VisibilityOptions::default(),
            |_: &[Vec3], _: &[Vec3], t: &mut [f32]| {
                t.fill(0.5);
                Ok::<(), std::convert::Infallible>(())
            },
        )
        .unwrap();
        let bytes = cache.to_bytes("floor v1").unwrap();
        (cache, bytes)
    }

    #[test]
    fn visibility_keys_are_read_without_the_light() {
        let (cache, bytes) = saved();
        let keys = read_keys(&bytes, "floor.envlvis").unwrap();
        let summary = cache.summary();
        assert_eq!(keys.light_hash, light_hash(cache.product()));
        assert_eq!(keys.scene_key, "floor v1");
        assert_eq!(keys.radius, summary.radius);
        assert_eq!(keys.entries, summary.entries);
        assert_eq!(keys.rays, summary.rays);
        assert_eq!(keys.patches, 32);
        assert!(keys.entries > 0 && keys.rays > 0);
    }

    #[test]
    fn visibility_keys_of_a_damaged_file_are_errors_naming_it() {
        let (_, bytes) = saved();
        let mut wrong_magic = bytes.clone();
        wrong_magic[0] = b'E';
        let mut wrong_version = bytes.clone();
        wrong_version[8] = 9;
        for (damaged, needle) in [
            (&bytes[..5], "truncated"),
            (&bytes[..40], "truncated"),
            (&bytes[..bytes.len() - 1], "bytes follow"),
            (&wrong_magic[..], "magic"),
            (&wrong_version[..], "version 9"),
        ] {
            let e = read_keys(damaged, "floor.envlvis").unwrap_err();
            let text = e.to_string();
            assert!(matches!(e, Error::Decode { .. }), "{text}");
            assert!(text.contains("floor.envlvis"), "{text}");
            assert!(text.contains(needle), "{needle}: {text}");
        }
    }
}
