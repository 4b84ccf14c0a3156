//! What the front ends drive: the recipe-to-image pipeline (`pipeline`), the editor core with its commands, journals and sessions (`editor`), and the perceptual study (`study`).
//!
//! The layers below (`visage-compose`, `visage-render`, `visage-train`) are re-exported, so every module of the
//! workspace names the others as `crate::model`, `crate::render`, … wherever
//! it lives; the crate graph itself keeps imports pointing down.

pub use visage_compose::*;
pub use visage_render::*;
pub use visage_train::train;
pub mod editor;
pub mod pipeline;
pub mod study;
