//! How the GPU's rows agree with the CPU's, for a map and the light options of
//! each ported combination: `cargo run --release -p envlight-gpu --example
//! gpu_agreement [MAP] [ROWS]` (default builtin sky, 65536 rows). With
//! `ENVLIGHT_SHOW_DISAGREEMENTS=N` it also prints the first N rows that disagree.

use envlight::light::Mapping;
use envlight::{EnvironmentLight, LightOptions, Lookup};
use envlight_gpu::agreement::{compare, cpu_sample_rows, measure, Row, PORTED};
use envlight_gpu::{GpuDevice, GpuLight};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let image = match args.next() {
        Some(path) if path != "builtin:sky" => {
            envlight::load::load(path.as_ref(), &Default::default())?.image
        }
        _ => envlight::builtin::sky(1024, 512),
    };
    let rows: usize = args.next().map_or(Ok(65536), |n| n.parse())?;
    let show: usize = std::env::var("ENVLIGHT_SHOW_DISAGREEMENTS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0);
    let device = GpuDevice::new()?;
    let r = device.report();
    println!("adapter: {} ({}, {})", r.name, r.backend, r.device_type);
    for (sampler, density) in PORTED {
        for mapping in Mapping::ALL {
            for lookup in [Lookup::Bilinear, Lookup::Nearest] {
                let options = LightOptions {
                    sampler,
                    density,
                    mapping,
                    lookup,
                    ..Default::default()
                };
                let light = EnvironmentLight::new(image.clone(), options)?;
                let gpu = GpuLight::new(&device, &light)?;
                let (s, e) = measure(&gpu, &light, 0, rows)?;
                println!(
                    "{} {} {} {lookup:?}\n  sample: {s}\n  eval:   {e}",
                    sampler.name(),
                    density.name(),
                    mapping.name()
                );
                let cpu_rows = cpu_sample_rows(&light, 0, 0, if show > 0 { rows } else { 0 });
                let gpu_rows: Vec<Row> = gpu
                    .sample_seeded(0, 0, cpu_rows.len())?
                    .iter()
                    .map(|s| s.row())
                    .collect();
                let mut shown = 0;
                for (k, (c, g)) in cpu_rows.iter().zip(&gpu_rows).enumerate() {
                    if shown >= show {
                        break;
                    }
                    if compare(&[*c], &[*g]).agreeing == 0 {
                        shown += 1;
                        let uv_c = light.direction_to_uv(envlight::Vec3::from(c.direction));
                        let uv_g = light.direction_to_uv(envlight::Vec3::from(g.direction));
                        println!(
                            "    row {k}: cpu {c:?} uv {uv_c:?}\n           gpu {g:?} uv {uv_g:?}"
                        );
                    }
                }
            }
        }
    }
    Ok(())
}
