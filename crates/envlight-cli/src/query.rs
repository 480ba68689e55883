//! The preamble of the commands that query the light (`sample`, `eval`, `verify`):
//! their shared options (the map, a surface normal, portals, the device) and what
//! those options build, checked and opened in one order for all three.

use std::sync::Arc;

use envlight::portal::PortalLight;
use envlight::product::ProductSampler;
use envlight::{EnvironmentLight, Vec3};

use crate::device::DeviceArgs;
use crate::light_args::{LightArgs, Loaded, PortalArgs};
use crate::shading::{product_sampler, NormalArgs};

/// The map, surface normal, portals and device options of a light query.
#[derive(clap::Args, Debug)]
pub struct QueryArgs {
    #[command(flatten)]
    pub light: LightArgs,

    #[command(flatten)]
    pub normal: NormalArgs,

    #[command(flatten)]
    pub portal: PortalArgs,

    #[command(flatten)]
    pub device: DeviceArgs,
}

/// What [`QueryArgs::open`] builds.
pub struct Query {
    /// The map and its light.
    pub loaded: Loaded,
    /// The product sampler at `--normal`, when given.
    pub product: Option<ProductSampler>,
    /// The portal light and `--at`, when `--portal` is given.
    pub portals: Option<(PortalLight, Vec3)>,
    /// The light's tables on the GPU for `--device gpu`.
    pub gpu: Option<envlight_gpu::GpuLight>,
}

impl Query {
    /// The light of the map.
    pub fn light(&self) -> &Arc<EnvironmentLight> {
        &self.loaded.light
    }
}

impl QueryArgs {
    /// `--normal`, when given.
    pub fn normal(&self) -> Option<Vec3> {
        self.normal.normal
    }

    /// Checks that the options go together (portals with a point, not with a
    /// normal or the GPU) before anything slow is read: a usage error otherwise.
    pub fn check(&self) -> anyhow::Result<()> {
        self.portal
            .requested(self.normal().is_some(), self.device.is_gpu())?;
        Ok(())
    }

    /// Loads the map, then builds the portal light, the product sampler and the
    /// GPU tables the options ask for.
    pub fn open(&self) -> anyhow::Result<Query> {
        let loaded = self.light.load()?;
        let light: &Arc<EnvironmentLight> = &loaded.light;
        let portals = self
            .portal
            .build(light, self.normal().is_some(), self.device.is_gpu())?;
        let product = product_sampler(light, self.normal());
        let gpu = self.device.open(light, self.normal())?;
        Ok(Query {
            loaded,
            product,
            portals,
            gpu,
        })
    }
}
