//! The composition method: recipes, region selection, Laplacian shape blending, border smoothing, colour correction, and the engine that composes, updates and poses composites.
//!
//! The layers below (`visage-core`) are re-exported, so every module of the
//! workspace names the others as `crate::model`, `crate::render`, … wherever
//! it lives; the crate graph itself keeps imports pointing down.

pub use visage_core::*;
pub mod compose;
