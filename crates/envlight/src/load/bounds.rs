//! Declared sizes checked against the bytes present, before anything is allocated.
//!
//! A file states sizes that a decoder turns into allocations: an OpenEXR file its
//! chunk count (the offset tables), each chunk's byte count, and, through its data
//! window, tile size and compression, how many bytes each chunk decompresses to; a
//! Radiance file the length of its scanlines. A malformed file of a few hundred
//! bytes can state gigabytes, and a failed allocation aborts the process: no caller
//! (C, Python, a renderer) could recover. So every such size is checked here first,
//! against what the input can possibly hold:
//! - a count or byte size that is read from the file must fit in the bytes that
//!   follow it;
//! - a size that is decoded from fewer bytes (decompression, run-length coding)
//!   must be reachable at the encoding's largest expansion ([`max_expansion`]).
//!
//! What this bounds, with the rest of the loader (which allocates an image as its
//! texels decode, and decompresses at most [`IN_FLIGHT_BYTES`] at once): a load's
//! peak allocation stays within a fixed 64 MiB, plus a few times the bytes of the
//! decoded texels, plus the largest expansion of one chunk's bytes.
//! `tests/memory_bound.rs` measures it with a counting allocator.

use exr::block::chunk::{Chunk, CompressedBlock};
use exr::compression::Compression;
use exr::meta::header::Header;
use exr::meta::BlockDescription;

/// Bytes of blocks decompressed at once by the OpenEXR loader (at least one
/// block): bounds the memory in flight whatever the thread count.
pub(super) const IN_FLIGHT_BYTES: usize = 16 << 20;

/// Bytes any encoding may produce beyond its expansion ratio (stream headers,
/// padding of a partial block): small blocks need no ratio to be believable.
const EXPANSION_SLACK: usize = 4096;

/// The most bytes one byte of a chunk compressed with `compression` can decode to,
/// rounded up. Each is the encoding's best case, so no valid chunk exceeds it:
/// - RLE: a two-byte run token repeats one byte at most 128 times (64);
/// - ZIP, ZIPS: deflate codes a 258-byte match in no fewer than 2 bits (1032);
/// - PXR24: deflate over 24-bit floats widened to 32 bits (1032 × 4/3);
/// - PIZ: its Huffman code repeats a 16-bit value at most 255 times with one code
///   of at least 1 bit and an 8-bit count (510 bytes from 9 bits: 454);
/// - B44, B44A: a flat 4×4 block of halves is 3 bytes for 32 (11);
/// - DWAA, DWAB: an 8×8 block of 128 bytes takes at least its DC value, deflated
///   (2/1032 bytes), and an end-of-block code, Huffman-coded with run lengths
///   (9/8 bytes per 255 blocks): about 20 000; 32 768 for margin;
/// - uncompressed and anything else: 1.
pub(super) fn max_expansion(compression: Compression) -> usize {
    match compression {
        Compression::RLE => 64,
        Compression::ZIP1 | Compression::ZIP16 => 1032,
        Compression::PXR24 => 1376,
        Compression::PIZ => 454,
        Compression::B44 | Compression::B44A => 11,
        Compression::DWAA(_) | Compression::DWAB(_) => 32768,
        _ => 1,
    }
}

fn le_u32(bytes: &[u8], at: usize) -> Option<u32> {
    let field = bytes.get(at..at.checked_add(4)?)?;
    Some(u32::from_le_bytes(field.try_into().ok()?))
}

fn le_u64(bytes: &[u8], at: usize) -> Option<u64> {
    let field = bytes.get(at..at.checked_add(8)?)?;
    Some(u64::from_le_bytes(field.try_into().ok()?))
}

/// The byte where an OpenEXR file's offset tables begin: after the magic number,
/// the version field and the headers. A header is a list of attributes (name and
/// type name, each ended by a zero byte, then a 4-byte size and that many bytes)
/// ended by a zero byte; a multi-part file ends its list of headers with one more.
/// `None` when the headers do not end inside the file, or their count differs
/// from `parts` (the exr crate's reading of the same bytes).
fn exr_tables_start(bytes: &[u8], multipart: bool, parts: usize) -> Option<usize> {
    let after_zero = |from: usize| -> Option<usize> {
        let rest = bytes.get(from..)?;
        Some(from + rest.iter().position(|&b| b == 0)? + 1)
    };
    let mut pos = 8;
    let mut found = 0;
    loop {
        if multipart && *bytes.get(pos)? == 0 {
            pos += 1;
            break;
        }
        while *bytes.get(pos)? != 0 {
            let type_start = after_zero(pos)?;
            let size_start = after_zero(type_start)?;
            let size = usize::try_from(le_u32(bytes, size_start)? as i32).ok()?;
            pos = size_start.checked_add(4)?.checked_add(size)?;
        }
        pos += 1;
        found += 1;
        if !multipart {
            break;
        }
    }
    (found == parts).then_some(pos)
}

/// Checks an OpenEXR file's chunk table against its length, before the exr crate
/// reads a chunk (it reserves each chunk's declared byte count before finding out
/// whether the file holds it): the offset tables of every part must fit after the
/// headers, and each chunk of `part`'s full-resolution level (the chunks the loader
/// reads) must begin inside the file, belong to `part`, and hold the bytes it
/// declares. The message names the chunk and what it declared.
pub(super) fn check_exr_chunk_table(
    bytes: &[u8],
    headers: &[Header],
    multipart: bool,
    part: usize,
) -> Result<(), String> {
    let len = bytes.len();
    let start = exr_tables_start(bytes, multipart, headers.len())
        .ok_or("the headers do not end inside the file (truncated or corrupt header)")?;
    let chunks: usize = headers.iter().map(|h| h.chunk_count).sum();
    let table_bytes = chunks.saturating_mul(8);
    if table_bytes > len - start.min(len) {
        return Err(format!(
            "the headers declare {chunks} chunks, whose offset tables take {table_bytes} bytes, \
             but the file holds {} bytes after its headers",
            len.saturating_sub(start)
        ));
    }
    let header = &headers[part];
    let table = start + 8 * headers[..part].iter().map(|h| h.chunk_count).sum::<usize>();
    let tiled = matches!(header.blocks, BlockDescription::Tiles(_));
    // Before the pixel data's byte count: the part number (multi-part files only),
    // then the tile's four coordinates or the scanline block's y.
    let leader = 4 * usize::from(multipart) + if tiled { 16 } else { 4 };
    for (k, tile) in header.blocks_increasing_y_order().enumerate() {
        if !tile.location.is_largest_resolution_level() {
            continue;
        }
        let offset = le_u64(bytes, table + 8 * k).unwrap_or(u64::MAX);
        let at = match usize::try_from(offset) {
            Ok(at) if at < len => at,
            _ => {
                return Err(format!(
                    "the offset table places chunk {k} at byte {offset}, past the end of the \
                     {len}-byte file"
                ))
            }
        };
        if multipart {
            let owner = le_u32(bytes, at).map_or(-1, |v| v as i32);
            if usize::try_from(owner).ok() != Some(part) {
                return Err(format!(
                    "chunk {k} of part {part} (at byte {at}) says it belongs to part {owner}"
                ));
            }
        }
        let declared = le_u32(bytes, at + leader)
            .map(|v| v as i32)
            .ok_or_else(|| format!("the file ends inside chunk {k}'s header (at byte {at})"))?;
        let follow = len - (at + leader + 4).min(len);
        if usize::try_from(declared).map_or(true, |size| size > follow) {
            return Err(format!(
                "chunk {k} (at byte {at}) declares {declared} bytes of pixel data, but only \
                 {follow} bytes follow its header"
            ));
        }
    }
    Ok(())
}

/// The bytes `chunk` decompresses to (its block's texels times the part's bytes
/// per texel), or `None` when its coordinates are invalid (the exr crate then
/// reports them).
pub(super) fn exr_block_bytes(chunk: &Chunk, header: &Header) -> Option<usize> {
    let tile = header
        .get_block_data_indices(&chunk.compressed_block)
        .ok()?;
    let bounds = header.get_absolute_block_pixel_coordinates(tile).ok()?;
    bounds
        .size
        .area()
        .checked_mul(header.channels.bytes_per_pixel)
}

/// Refuses a chunk whose compressed bytes cannot decode to its block, whatever
/// they hold (see [`max_expansion`]): the exr crate's decompressors allocate the
/// block's full size before decoding, so a few bytes declaring a block of
/// gigabytes would otherwise allocate them.
pub(super) fn check_exr_expansion(
    chunk: &Chunk,
    header: &Header,
    block_bytes: usize,
) -> Result<(), String> {
    let stored = match &chunk.compressed_block {
        CompressedBlock::ScanLine(b) => b.compressed_pixels_le.len(),
        CompressedBlock::Tile(b) => b.compressed_pixels_le.len(),
        _ => return Ok(()), // deep data is refused with its own message
    };
    let ratio = max_expansion(header.compression);
    let reachable = stored.saturating_mul(ratio).saturating_add(EXPANSION_SLACK);
    if stored == block_bytes || block_bytes <= reachable {
        return Ok(());
    }
    Err(format!(
        "a chunk of {stored} bytes ({:?}) declares a block of {block_bytes} bytes, more than \
         its compression can expand it to ({ratio}x)",
        header.compression
    ))
}

/// The fewest bytes a Radiance scanline of `width` texels takes: 4 per texel flat;
/// new-style run-length coding (for widths of 8 to 32767) takes a 4-byte marker and
/// at least 2 bytes per 127 values of each of the four components. Old-style runs
/// can code a line in a few bytes whatever its width, so a line whose buffers would
/// pass [`WIDE_SCANLINE_BYTES`] must hold at least one byte per 16 texels.
pub(super) fn hdr_scanline_believable(width: usize, bytes_left: usize) -> bool {
    width.saturating_mul(16) <= WIDE_SCANLINE_BYTES || width / 16 <= bytes_left
}

/// Buffer bytes of one Radiance scanline (decoded `f32` RGB and the decoder's own
/// RGBE line) above which [`hdr_scanline_believable`] asks for data.
const WIDE_SCANLINE_BYTES: usize = 16 << 20;

/// Checks that a PNG or JPEG of `width` × `height` texels can be coded in `len`
/// bytes, before the decoder allocates the image (`png` selects the format;
/// `bits_per_pixel` is the PNG's own, before any palette or bit-depth expansion):
/// - PNG: its deflate stream carries every row (a filter byte and the row's
///   packed samples), and deflate expands a byte at most 1032 times;
/// - JPEG: every 8×8 block of the full-resolution component takes at least one bit
///   (its DC code; Huffman codes are never shorter).
pub(super) fn ldr_data_fits(
    png: bool,
    width: usize,
    height: usize,
    bits_per_pixel: usize,
    len: usize,
) -> Result<(), String> {
    let reachable = len.saturating_add(EXPANSION_SLACK);
    let (needed, unit, capacity) = if png {
        let row = 1 + width.saturating_mul(bits_per_pixel).div_ceil(8);
        (
            row.saturating_mul(height),
            "bytes of rows",
            reachable.saturating_mul(1032),
        )
    } else {
        let blocks = width.div_ceil(8).saturating_mul(height.div_ceil(8));
        (blocks, "8x8 blocks", reachable.saturating_mul(8))
    };
    if needed <= capacity {
        return Ok(());
    }
    Err(format!(
        "a {width}x{height} image needs {needed} {unit}, more than its {len} bytes can code \
         (at most {capacity})"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tables_start_after_single_and_multi_part_headers() {
        // magic, version, then attribute "a" of type "t" with 2 bytes, end of header.
        let mut single = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
        single.extend_from_slice(b"a\0t\0\x02\0\0\0xy\0");
        assert_eq!(exr_tables_start(&single, false, 1), Some(single.len()));
        assert_eq!(
            exr_tables_start(&single[..single.len() - 1], false, 1),
            None
        );
        assert_eq!(exr_tables_start(&single, false, 2), None);
        let mut multi = single.clone();
        multi.extend_from_slice(b"b\0t\0\x00\0\0\0\0\0");
        assert_eq!(exr_tables_start(&multi, true, 2), Some(multi.len()));
        assert_eq!(exr_tables_start(&multi, true, 1), None);
    }

    #[test]
    fn a_negative_attribute_size_ends_the_walk() {
        let mut bytes = vec![0x76, 0x2f, 0x31, 0x01, 2, 0, 0, 0];
        bytes.extend_from_slice(b"a\0t\0\xff\xff\xff\xff\0");
        assert_eq!(exr_tables_start(&bytes, false, 1), None);
    }

    #[test]
    fn wide_scanlines_need_data() {
        assert!(hdr_scanline_believable(16384, 0));
        assert!(!hdr_scanline_believable(1 << 28, 1000));
        assert!(hdr_scanline_believable(1 << 28, 1 << 24));
    }

    #[test]
    fn ldr_sizes_need_data() {
        assert!(ldr_data_fits(true, 16384, 8192, 24, 400_000).is_ok());
        assert!(ldr_data_fits(true, 16384, 16384, 24, 600).is_err());
        assert!(ldr_data_fits(false, 16384, 8192, 24, 300_000).is_ok());
        assert!(ldr_data_fits(false, 65535, 65535, 24, 600).is_err());
    }
}
