//! The checks of docs/design.md §5 and §6a, one module each.

pub mod black;
pub mod chi_square;
pub mod consistency;
pub mod normalisation;
pub mod support;
pub mod unbiasedness;
pub mod warp;
