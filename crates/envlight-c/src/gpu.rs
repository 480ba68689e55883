//! The light's tables for a GPU: the flat buffers and file format of
//! `docs/gpu-tables.md`, which a shader (or any port of the sampling math) reads.

use envlight::gpu::{GpuTableOptions, GpuTables, RadianceFormat};

use crate::{deref, deref_mut, envlight_light, envlight_status, put, run, value, Failure};

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
    run(F, || {
        let out = unsafe { deref_mut(out, F, "out") }?;
        *out = std::ptr::null_mut();
        let light = unsafe { deref(light, F, "light") }?;
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
        let tables = light.light.gpu_tables(&GpuTableOptions { radiance })?;
        put(
            out,
            envlight_gpu_tables {
                tables,
                bytes: Default::default(),
            },
        );
        Ok(())
    })
}

/// Frees GPU tables (NULL: nothing).
#[no_mangle]
pub extern "C" fn envlight_gpu_tables_free(tables: *mut envlight_gpu_tables) {
    crate::free(tables);
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
        let words = unsafe { deref_mut(words, F, "words") }?;
        *words = 0;
        let t = &unsafe { deref(tables, F, "tables") }?.tables;
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
        let t = unsafe { deref(tables, F, "tables") }?;
        let bytes = t.bytes.get_or_init(|| t.tables.to_bytes());
        if !buf.is_null() && len >= bytes.len() {
            // SAFETY: the caller gives `len` writable bytes at `buf`.
            unsafe { std::ptr::copy_nonoverlapping(bytes.as_ptr(), buf, bytes.len()) };
        }
        Ok(bytes.len())
    })
}
