//! Times `envlight::load::load` on one file: the median and the fastest of ROUNDS
//! loads (default 15), in milliseconds, after one load that is not counted.
//!
//! `cargo run --release --example load_time -- FILE [ROUNDS]`

use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: load_time FILE [ROUNDS]")?;
    let rounds: usize = args.next().map_or(Ok(15), |r| r.parse())?;
    let options = envlight::load::LoadOptions::default();
    let first = envlight::load::load(path.as_ref(), &options)?;
    let mut times: Vec<f64> = (0..rounds.max(1))
        .map(|_| {
            let start = Instant::now();
            let loaded = envlight::load::load(path.as_ref(), &options);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            drop(loaded);
            ms
        })
        .collect();
    times.sort_by(f64::total_cmp);
    println!(
        "{path}: {}x{}, median {:.2} ms, fastest {:.2} ms over {} loads",
        first.image.width(),
        first.image.height(),
        times[times.len() / 2],
        times[0],
        times.len()
    );
    Ok(())
}
