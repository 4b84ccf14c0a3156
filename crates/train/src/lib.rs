//! Making source avatars: the differentiable renderer, captures, the GaussianAvatars-style trainer with hole filling, and composites measured against their ground truth.
//!
//! The layers below (`visage-compose`, `visage-render`) are re-exported, so every module of the
//! workspace names the others as `crate::model`, `crate::render`, … wherever
//! it lives; the crate graph itself keeps imports pointing down.

pub use visage_compose::*;
pub use visage_render::*;
pub mod train;
