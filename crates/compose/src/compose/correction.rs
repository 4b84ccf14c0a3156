//! A colour correction as the engine applies it to a block of Gaussians: none,
//! one gain for the block, or a gain per Gaussian (docs/method.md §7.5–§7.7).

use std::sync::Arc;

use glam::Vec3;

/// Per-Gaussian colour gains shared between composites.
pub type SharedGains = Arc<Vec<Vec3>>;

/// A colour correction for a block of Gaussians of one source.
#[derive(Clone, Debug)]
pub enum Correction {
    /// Colours stay as trained.
    None,
    /// One gain for every Gaussian of the block (`colour = "thesis"`).
    Gain(Vec3),
    /// A gain per Gaussian of the source, by its index there.
    PerGaussian(SharedGains),
}

impl Correction {
    /// The gain of Gaussian `i` of the block's source.
    pub fn gain(&self, i: usize) -> Vec3 {
        match self {
            Correction::None => Vec3::ONE,
            Correction::Gain(g) => *g,
            Correction::PerGaussian(g) => g.get(i).copied().unwrap_or(Vec3::ONE),
        }
    }
}
