//! Real spherical-harmonics colour evaluation, degrees 0-3, in the 3D Gaussian
//! Splatting convention: the functions live in the core layer
//! (`visage_core::avatar::sh`), where the composition's colour statistics use
//! them too; the renderers and the trainer reach them here.

pub use crate::avatar::sh::*;
pub use visage_core::sh_basis;
