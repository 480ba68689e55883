//! Seconds per check of the harness on one map, with the settings of
//! `envlight verify` (200k samples) or the test suite's real-map settings:
//! `cargo run --release -p envlight-verify --example check_times -- MAP [--tests]`.

use envlight::load::{load, LoadOptions};
use envlight::{EnvironmentLight, LightOptions};
use envlight_verify::{run, Config, Integrand, Lobes, Reference};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args.next().ok_or("usage: check_times MAP [--tests]")?;
    let tests = args.next().as_deref() == Some("--tests");
    let image = load(path.as_ref(), &LoadOptions::default())?.image;
    let light = EnvironmentLight::new(image, LightOptions::default())?;
    let cfg = if tests {
        Config::REAL_MAP
    } else {
        Config {
            lobes: Lobes::Zenith,
            reference: Reference::Midpoint,
            ..Config::with_samples(200_000, 0)
        }
    };
    let report = run(&light, &Integrand::luminance(), &cfg, &|_| {});
    for (name, s) in [
        "normalisation",
        "consistency",
        "chi-square",
        "support",
        "unbiasedness",
    ]
    .iter()
    .zip(report.seconds)
    {
        println!("{name:>14} {s:.3} s");
    }
    println!(
        "{:>14} {:.3} s",
        "total",
        report.seconds.iter().sum::<f64>()
    );
    Ok(())
}
