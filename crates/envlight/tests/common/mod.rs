//! What several test files share (each uses a part of it).

#![allow(dead_code)]

use envlight::light::{Density, Sampler};
use std::path::PathBuf;

/// Every sampler with every density it takes (the piecewise-bilinear density is
/// sampled by inversion only).
pub const SAMPLER_DENSITIES: [(Sampler, Density); 4] = [
    (Sampler::Inversion, Density::PiecewiseConstant),
    (Sampler::Alias, Density::PiecewiseConstant),
    (Sampler::Hierarchical, Density::PiecewiseConstant),
    (Sampler::Inversion, Density::PiecewiseBilinear),
];

/// `shared/envmaps` beside the workspace, when it is there (the real maps are
/// optional: the tests over them skip, saying so, when it is not).
pub fn envmaps() -> Option<PathBuf> {
    envlight_verify::maps::shared_envmaps()
}
