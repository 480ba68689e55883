//! Writes the peer benchmarks' synthetic map (a sky gradient plus a 1° sun
//! holding ~91% of the power) as a lat-long OpenEXR file of 32-bit floats, for
//! timing the CLI on maps larger than the shared ones (e.g. `envlight info` with
//! `--table-size` on a 16384×8192 map).
//!
//! `cargo run --release --example synthetic_exr -- WIDTH OUT.exr` (height WIDTH/2).

#[path = "common/sun_sky.rs"]
mod sun_sky;

use exr::prelude::{Encoding, Image, SpecificChannels, Vec2, WritableImage};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: synthetic_exr WIDTH OUT.exr";
    let width: usize = args.next().ok_or(usage)?.parse()?;
    let out = args.next().ok_or(usage)?;
    let map = sun_sky::synthetic(width, width / 2);
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let [r, g, b] = map.texel(p.x(), p.y());
        (r, g, b)
    });
    let image = Image::from_encoded_channels((width, width / 2), Encoding::FAST_LOSSLESS, channels);
    image.write().to_file(&out)?;
    println!("wrote {out}: {width}x{}", width / 2);
    Ok(())
}
