//! The readers' memory bound, measured: a counting global allocator records the
//! peak of live heap bytes while each input is read, and every input must stay
//! within [`bound`]: a fixed 64 MiB plus four times the bytes of the texels it
//! decoded (an image that fails to decode has decoded none). The inputs are every
//! regression input and every committed seed of the loader and GPU table fuzz
//! targets, the shared maps when present, and hostile files built here, each
//! declaring a large image (within the default texel limit) or a large chunk that
//! its bytes cannot hold. Readers run with the default options, as users call them.
//!
//! This file holds one test: the allocator counts the whole process, so nothing
//! else may run beside it.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use envlight::load::{load_from_memory, LoadOptions};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(bytes: usize) {
    let live = LIVE.fetch_add(bytes, Ordering::SeqCst) + bytes;
    PEAK.fetch_max(live, Ordering::SeqCst);
}

// SAFETY: every call is forwarded to the system allocator with its own arguments;
// the counters only observe sizes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: the caller's contract for `alloc` is passed on unchanged.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as for `alloc`.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated by `System` with `layout` (this allocator
        // forwards every allocation).
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::SeqCst);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: as for `dealloc`; `new_size` is the caller's.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::SeqCst);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

const FIXED: usize = 64 << 20;

/// The most a read may allocate beyond what was live before it.
fn bound(decoded_texels: usize) -> usize {
    FIXED + 4 * 12 * decoded_texels
}

/// Runs `read` and returns the peak of live heap bytes above those live before.
fn peak_of<T>(read: impl FnOnce() -> T) -> (T, usize) {
    let base = LIVE.load(Ordering::SeqCst);
    PEAK.store(base, Ordering::SeqCst);
    let out = read();
    (out, PEAK.load(Ordering::SeqCst) - base)
}

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|entry| entry.unwrap().path())
        .filter(|p| p.is_file() && p.extension().is_none_or(|e| e != "md"))
        .collect();
    files.sort();
    files
}

fn joined(prefix: &[u8], data: &[u8]) -> Vec<u8> {
    [prefix, data].concat()
}

const EXR_MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
const PNG_MAGIC: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a];

/// The loader inputs of the fuzz folders, as their targets complete them.
fn fuzz_inputs(fuzz: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    for path in files(&fuzz.join("regressions/load")) {
        let bytes = std::fs::read(&path).unwrap();
        // The regression replay's prefixes (tests/fuzz_regressions.rs).
        let prefixes: [&[u8]; 5] = [b"", b"#?RADIANCE\n", &EXR_MAGIC, b"P", &PNG_MAGIC];
        for prefix in prefixes {
            out.push((path.display().to_string(), joined(prefix, &bytes)));
        }
    }
    for (target, prefix) in [
        ("load_any", &b""[..]),
        ("load_exr", &EXR_MAGIC[..]),
        ("load_hdr", b"#?RADIANCE\n"),
        ("load_pfm", b"P"),
    ] {
        for path in files(&fuzz.join("seeds").join(target)) {
            let bytes = std::fs::read(&path).unwrap();
            out.push((path.display().to_string(), joined(prefix, &bytes)));
        }
    }
    for path in files(&fuzz.join("seeds/load_ldr")) {
        let bytes = std::fs::read(&path).unwrap();
        let Some((&first, rest)) = bytes.split_first() else {
            continue;
        };
        let prefix: &[u8] = if first & 1 == 0 {
            &PNG_MAGIC
        } else {
            &[0xff, 0xd8, 0xff]
        };
        out.push((path.display().to_string(), joined(prefix, rest)));
    }
    out
}

// ---------------------------------------------------------------------------
// Hostile files

fn attribute(out: &mut Vec<u8>, name: &str, kind: &str, value: &[u8]) {
    out.extend_from_slice(name.as_bytes());
    out.push(0);
    out.extend_from_slice(kind.as_bytes());
    out.push(0);
    out.extend_from_slice(&(value.len() as i32).to_le_bytes());
    out.extend_from_slice(value);
}

fn ints(values: &[i32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// A single-part OpenEXR file of half RGB, `width` × `height`: its header (`tile` makes it tiled),
/// an offset table of `chunk_count` entries all pointing at one chunk, and that
/// chunk: `leader` (block coordinates), a declared byte count and `payload`.
fn exr_file(
    (width, height): (i32, i32),
    compression: u8,
    tile: Option<u32>,
    chunk_count: usize,
    leader: &[i32],
    declared: i32,
    payload: &[u8],
) -> Vec<u8> {
    let version: u32 = 2 | if tile.is_some() { 0x200 } else { 0 };
    let mut out = EXR_MAGIC.to_vec();
    out.extend_from_slice(&version.to_le_bytes());
    let mut channels = Vec::new();
    for name in ["B", "G", "R"] {
        channels.extend_from_slice(name.as_bytes());
        channels.push(0);
        channels.extend_from_slice(&ints(&[1, 0, 1, 1])); // half, pLinear+reserved, sampling
    }
    channels.push(0);
    attribute(&mut out, "channels", "chlist", &channels);
    attribute(&mut out, "compression", "compression", &[compression]);
    let window = ints(&[0, 0, width - 1, height - 1]);
    attribute(&mut out, "dataWindow", "box2i", &window);
    attribute(&mut out, "displayWindow", "box2i", &window);
    attribute(&mut out, "lineOrder", "lineOrder", &[0]);
    attribute(&mut out, "pixelAspectRatio", "float", &1f32.to_le_bytes());
    attribute(&mut out, "screenWindowCenter", "v2f", &[0; 8]);
    attribute(&mut out, "screenWindowWidth", "float", &1f32.to_le_bytes());
    if let Some(size) = tile {
        let mut desc = Vec::new();
        desc.extend_from_slice(&size.to_le_bytes());
        desc.extend_from_slice(&size.to_le_bytes());
        desc.push(0);
        attribute(&mut out, "tiles", "tiledesc", &desc);
    }
    out.push(0);
    let chunk_at = (out.len() + 8 * chunk_count) as u64;
    for _ in 0..chunk_count {
        out.extend_from_slice(&chunk_at.to_le_bytes());
    }
    out.extend_from_slice(&ints(leader));
    out.extend_from_slice(&declared.to_le_bytes());
    out.extend_from_slice(payload);
    out
}

fn crc32(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = (crc >> 1) ^ (0xedb8_8320 & (crc & 1).wrapping_neg());
        }
    }
    !crc
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// An 8-bit RGB PNG declaring `side` × `side` texels with a tiny stored block.
fn png_file(side: u32) -> Vec<u8> {
    let mut out = PNG_MAGIC.to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&side.to_be_bytes());
    ihdr.extend_from_slice(&side.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    png_chunk(&mut out, b"IHDR", &ihdr);
    // zlib header, one final stored block of 4 zero bytes, Adler-32 of those.
    png_chunk(
        &mut out,
        b"IDAT",
        &[0x78, 0x01, 1, 4, 0, 0xfb, 0xff, 0, 0, 0, 0, 0, 0x04, 0, 1],
    );
    png_chunk(&mut out, b"IEND", &[]);
    out
}

/// A baseline greyscale JPEG declaring `side` × `side` texels whose one-bit codes
/// (DC difference 0, end of block) cover 800 blocks.
fn jpeg_file(side: u16) -> Vec<u8> {
    let mut out = vec![0xff, 0xd8];
    out.extend_from_slice(&[0xff, 0xdb, 0, 67, 0]);
    out.extend_from_slice(&[1; 64]);
    out.extend_from_slice(&[0xff, 0xc0, 0, 11, 8]);
    out.extend_from_slice(&side.to_be_bytes());
    out.extend_from_slice(&side.to_be_bytes());
    out.extend_from_slice(&[1, 1, 0x11, 0]);
    for class in [0x00, 0x10] {
        out.extend_from_slice(&[0xff, 0xc4, 0, 20, class, 1]);
        out.extend_from_slice(&[0; 15]);
        out.push(0);
    }
    out.extend_from_slice(&[0xff, 0xda, 0, 8, 1, 1, 0, 0, 63, 0]);
    out.extend_from_slice(&[0; 200]);
    out.extend_from_slice(&[0xff, 0xd9]);
    out
}

fn hostile() -> Vec<(String, Vec<u8>)> {
    let zip = 3;
    let garbage: Vec<u8> = (0..100u32).map(|i| (i * 37 % 251) as u8).collect();
    vec![
        (
            "EXR, a 2^27-texel ZIP scanline from 100 bytes".into(),
            exr_file((1 << 27, 1), zip, None, 1, &[0], 100, &garbage),
        ),
        (
            "EXR, 16384x16384 uncompressed, every chunk one 10-byte block".into(),
            exr_file((16384, 16384), 0, None, 16384, &[0], 10, &garbage[..10]),
        ),
        (
            "EXR, an offset table of 2^28 chunks in a few hundred bytes".into(),
            exr_file((1, 1 << 28), 0, None, 4, &[0], 6, &garbage[..6]),
        ),
        (
            "EXR, one 8192x8192 ZIP tile from 60 bytes".into(),
            exr_file(
                (8192, 8192),
                zip,
                Some(8192),
                1,
                &[0, 0, 0, 0],
                60,
                &garbage[..60],
            ),
        ),
        (
            "EXR, a chunk declaring 2^31 - 1 bytes".into(),
            exr_file((64, 64), zip, None, 4, &[0], i32::MAX, &garbage),
        ),
        (
            "HDR, 200M-texel scanline from 64 bytes".into(),
            [
                &b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 200000000\n"[..],
                &[7; 64],
            ]
            .concat(),
        ),
        (
            "HDR, 2^28 one-texel scanlines from 64 bytes".into(),
            [&b"#?RADIANCE\n\n-Y 268435456 +X 1\n"[..], &[7; 64]].concat(),
        ),
        (
            "PFM, 16384x16384 from 16 bytes".into(),
            [&b"PF\n16384 16384\n-1.0\n"[..], &[0; 16]].concat(),
        ),
        (
            "PNG, 16384x16384 from 4 bytes of rows".into(),
            png_file(16384),
        ),
        (
            "JPEG, 16000x16000 from 200 bytes of scan".into(),
            jpeg_file(16000),
        ),
    ]
}

#[test]
fn every_reader_stays_within_its_memory_bound() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut inputs = fuzz_inputs(&root.join("fuzz"));
    assert!(
        inputs
            .iter()
            .any(|(name, _)| name.contains("exr-chunk-size-1.9GB")),
        "the 1.9 GB fuzz find is a regression input"
    );
    inputs.extend(hostile());
    let shared = root.join("../shared/envmaps");
    if shared.is_dir() {
        for path in files(&shared) {
            if matches!(
                path.extension().and_then(|e| e.to_str()),
                Some("exr" | "hdr" | "pfm")
            ) {
                inputs.push((path.display().to_string(), std::fs::read(&path).unwrap()));
            }
        }
    } else {
        println!("skipping the shared maps: {} is absent", shared.display());
    }

    let options = LoadOptions::default();
    let mut over = Vec::new();
    let mut worst = (0.0f64, String::new());
    for (name, bytes) in &inputs {
        let (result, peak) = peak_of(|| load_from_memory(name, bytes, &options));
        let texels = result.as_ref().map_or(0, |l| l.image.texels().len());
        let limit = bound(texels);
        let share = peak as f64 / limit as f64;
        if !name.contains('/') {
            // A hostile file: say what the loader made of it.
            println!(
                "{name}: peak {peak} bytes; {}",
                result
                    .as_ref()
                    .map_or_else(|e| e.to_string(), |_| "loaded".into())
            );
        }
        if share > worst.0 {
            worst = (share, name.clone());
        }
        if peak > limit {
            over.push(format!(
                "{name}: {peak} bytes at peak, bound {limit} ({texels} texels decoded; {})",
                match &result {
                    Ok(_) => "loaded".to_string(),
                    Err(e) => e.to_string(),
                }
            ));
        }
    }

    let gpu = files(&root.join("fuzz/seeds/gpu_tables"));
    assert!(!gpu.is_empty(), "the GPU table seeds are in the repository");
    for path in gpu {
        // The target gives the magic and version; the seeds hold the rest.
        let bytes = joined(b"ENVLGPU\0\x01\0\0\0", &std::fs::read(&path).unwrap());
        let (_, peak) = peak_of(|| envlight::gpu::GpuTables::from_bytes(&bytes));
        // A parsed file's tables are copies of its bytes.
        let limit = FIXED + 4 * bytes.len();
        if peak > limit {
            over.push(format!(
                "{}: {peak} bytes at peak, bound {limit}",
                path.display()
            ));
        }
    }

    println!(
        "{} loader inputs; the highest peak is {:.4} of its bound ({})",
        inputs.len(),
        worst.0,
        worst.1
    );
    assert!(
        over.is_empty(),
        "over the memory bound:\n{}",
        over.join("\n")
    );
}
