//! The light's tables for a GPU: the flat buffers and file format of
//! `docs/gpu-tables.md`, which a shader (or any port of the sampling math) reads.

use std::sync::Arc;

use envlight::gpu::{GpuTableOptions, GpuTables, RadianceFormat};
use envlight::EnvironmentLight;

use crate::boundary::{cleared, deref, free, value, write_whole, Failure};
use crate::light::new_from_light;
use crate::{envlight_light, envlight_status};

/// How `envlight_light_gpu_tables` stores the radiance image.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_radiance_format {
    /// RGB `f32`, 12 bytes per texel: exactly the light's texels.
    ENVLIGHT_RADIANCE_F32 = 0,
    /// RGBA `f16` (alpha 0), 8 bytes per texel.
    ENVLIGHT_RADIANCE_F16 = 1,
}

/// A light's GPU tables (layout version 1). Opaque and immutable; free it with
/// `envlight_gpu_tables_free`.
pub struct envlight_gpu_tables {
    tables: GpuTables,
    bytes: std::sync::OnceLock<Vec<u8>>,
}

/// Lays `light` out as GPU tables with the radiance stored as
/// `radiance_format` (an `envlight_radiance_format`). `ENVLIGHT_ERROR_UNSUPPORTED`
/// for the hierarchical sampler (not ported) and for f16 radiance of a map with a
/// texel above 65504 (named).
#[no_mangle]
pub extern "C" fn envlight_light_gpu_tables(
    light: *const envlight_light,
    radiance_format: u32,
    out: *mut *mut envlight_gpu_tables,
) -> envlight_status {
    const F: &str = "envlight_light_gpu_tables";
    let build = |light: &Arc<EnvironmentLight>| -> Result<_, Failure> {
        let radiance = match radiance_format {
            0 => RadianceFormat::F32,
            1 => RadianceFormat::F16,
            _ => {
                return Err(Failure::argument(
                    F,
                    format_args!(
                        "radiance_format is {radiance_format}, not 0 (ENVLIGHT_RADIANCE_F32) or 1 (ENVLIGHT_RADIANCE_F16)"
                    ),
                ))
            }
        };
        let tables = light.gpu_tables(&GpuTableOptions { radiance })?;
        Ok(envlight_gpu_tables {
            tables,
            bytes: Default::default(),
        })
    };
    // SAFETY: by the C contract `out` is NULL or points to a writable
    // `envlight_gpu_tables *`, and `light` is NULL or a light from
    // envlight_light_load/_from_rgb not yet freed (only read).
    unsafe { new_from_light(F, light, out, build) }
}

/// Frees GPU tables (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_gpu_tables_free(tables: *mut envlight_gpu_tables) {
    // SAFETY: by the C contract a non-NULL `tables` came from
    // envlight_light_gpu_tables (which makes an `envlight_gpu_tables`) and is freed
    // once, after the last use of the buffers it lent.
    unsafe { free(tables) };
}

/// Which of the three buffers `envlight_gpu_tables_buffer` returns.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum envlight_gpu_buffer {
    /// The parameter block: 64 words (section 1).
    ENVLIGHT_GPU_PARAMS = 0,
    /// The tables buffer a shader binds (sections 2-8, each padded to 16 bytes).
    ENVLIGHT_GPU_TABLES = 1,
    /// The radiance image (section 9).
    ENVLIGHT_GPU_RADIANCE = 2,
}

/// A pointer to one of the buffers (an `envlight_gpu_buffer`) as 32-bit
/// little-endian words, valid while `tables` lives, with its length in words
/// written to `*words`. NULL (and `*words` 0) for NULL arguments or an unknown
/// buffer.
#[no_mangle]
pub extern "C" fn envlight_gpu_tables_buffer(
    tables: *const envlight_gpu_tables,
    buffer: u32,
    words: *mut usize,
) -> *const u32 {
    const F: &str = "envlight_gpu_tables_buffer";
    value(F, std::ptr::null(), || {
        // SAFETY: by the C contract `words` is NULL or one writable `size_t`, and
        // `tables` NULL or a handle from envlight_light_gpu_tables not yet freed
        // (only read); the helpers reject NULL and misaligned pointers.
        let (words, tables) =
            unsafe { (cleared(words, 0, F, "words")?, deref(tables, F, "tables")?) };
        let t = &tables.tables;
        let data: &[u32] = match buffer {
            0 => t.params(),
            1 => t.tables(),
            2 => t.radiance(),
            _ => {
                return Err(Failure::argument(
                    F,
                    format_args!("buffer is {buffer}, not an envlight_gpu_buffer (0, 1 or 2)"),
                ))
            }
        };
        *words = data.len();
        Ok(data.as_ptr())
    })
}

/// The tables as the file `envlight export` writes (a header, a section table,
/// the sections on 16-byte boundaries), copied into `buf` when it holds `len >=`
/// the file's size; returns the file's size in bytes (0 for a NULL `tables`). Call
/// with `buf` NULL to learn the size. A `len` too small copies nothing.
#[no_mangle]
pub extern "C" fn envlight_gpu_tables_to_bytes(
    tables: *const envlight_gpu_tables,
    buf: *mut u8,
    len: usize,
) -> usize {
    const F: &str = "envlight_gpu_tables_to_bytes";
    value(F, 0, || {
        // SAFETY: by the C contract `tables` is NULL or a handle from
        // envlight_light_gpu_tables not yet freed; it is only read (its bytes are
        // built once, under `OnceLock`'s lock); `deref` rejects NULL and misaligned
        // pointers.
        let t = unsafe { deref(tables, F, "tables") }?;
        let bytes = t.bytes.get_or_init(|| t.tables.to_bytes());
        // SAFETY: by the C contract a non-NULL `buf` holds `len` writable bytes of
        // the caller's, which cannot overlap `bytes`, owned by the handle.
        unsafe { write_whole(bytes, buf, len) };
        Ok(bytes.len())
    })
}
