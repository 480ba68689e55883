//! `--device cpu|gpu`: where `info`, `sample`, `eval` and `verify` run the light's
//! queries. The GPU runs the WGSL module of `envlight-gpu` over the tables the CPU
//! light builds (docs/gpu-tables.md); the same seed gives the same `ξ` on both.

use envlight::{EnvironmentLight, Vec3};

use crate::cmd::UsageError;

/// The `--device` option.
#[derive(Debug, Clone, clap::Args)]
pub struct DeviceArgs {
    /// Where the light's queries run: cpu (the library), or gpu (its WGSL module
    /// through wgpu; WGPU_BACKEND and WGPU_ADAPTER_NAME choose the adapter). For
    /// the same seed both draw the same ξ, so their rows compare one to one.
    #[arg(long, value_enum, default_value_t = DeviceArg::Cpu)]
    pub device: DeviceArg,
}

/// `--device`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DeviceArg {
    /// The CPU cores, through the library.
    Cpu,
    /// A GPU adapter, through wgpu.
    Gpu,
}

impl DeviceArgs {
    /// True for `--device gpu`.
    pub fn is_gpu(&self) -> bool {
        self.device == DeviceArg::Gpu
    }

    /// The light's tables on the GPU for `--device gpu` (`None` for the CPU).
    /// Product sampling (`--normal`) is not ported: a usage error. No adapter is
    /// an error naming what to install; a combination the tables do not carry (the
    /// hierarchical sampler) a usage error saying so.
    pub fn open(
        &self,
        light: &EnvironmentLight,
        normal: Option<Vec3>,
    ) -> anyhow::Result<Option<envlight_gpu::GpuLight>> {
        if !self.is_gpu() {
            return Ok(None);
        }
        if normal.is_some() {
            return Err(UsageError(
                "--normal (product sampling) is not ported to the GPU; use --device cpu".into(),
            )
            .into());
        }
        // Refuse what is not ported before looking for an adapter.
        let tables = gpu_tables(light)?;
        let device = envlight_gpu::GpuDevice::new()?;
        Ok(Some(envlight_gpu::GpuLight::from_tables(
            &device,
            &tables,
            envlight_gpu::shader::WGSL,
        )?))
    }
}

/// The light's flat tables (f32 radiance) for the GPU; a combination they do not
/// carry (the hierarchical sampler) is a usage error saying so.
pub fn gpu_tables(light: &EnvironmentLight) -> anyhow::Result<envlight::gpu::GpuTables> {
    light.gpu_tables(&Default::default()).map_err(|e| match e {
        envlight::Error::Unsupported(why) => {
            anyhow::Error::from(UsageError(format!("--device gpu: {why}")))
        }
        other => anyhow::Error::from(other),
    })
}
