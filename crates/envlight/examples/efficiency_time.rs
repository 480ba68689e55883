//! Time of the efficiency quadrature (`EnvironmentLight::efficiency` and, with a
//! reduced table, `efficiency_with_full_table`) on the peer map at WIDTH ×
//! WIDTH/2 (8192 by default), best of 5.
//!
//! `cargo run --release --example efficiency_time -- [WIDTH]`

#[path = "common/sun_sky.rs"]
mod sun_sky;

use envlight::light::Density;
use envlight::{EnvironmentLight, LightOptions};
use std::time::Instant;

fn main() {
    let width: usize = std::env::args()
        .nth(1)
        .and_then(|s| s.parse().ok())
        .unwrap_or(8192);
    let image = sun_sky::synthetic(width, width / 2);
    for table_width in [None, Some(width / 4)] {
        let options = LightOptions {
            table_width,
            density: Density::PiecewiseConstant,
            ..Default::default()
        };
        let light = EnvironmentLight::new(image.clone(), options).expect("a light");
        let mut best = f64::INFINITY;
        let mut result = (0.0, None);
        for _ in 0..5 {
            let start = Instant::now();
            result = light.efficiency_with_full_table();
            best = best.min(start.elapsed().as_secs_f64() * 1e3);
        }
        println!("table {table_width:?}: {best:.1} ms, efficiency {result:?}");
    }
}
