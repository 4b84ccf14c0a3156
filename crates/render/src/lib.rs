//! The renderers: the CPU renderer, the wgpu renderer with its WGSL kernels (`shaders/`), the f64 reference, images, and the level-of-detail hierarchy of large scenes.
//!
//! The layers below (`visage-core`) are re-exported, so every module of the
//! workspace names the others as `crate::model`, `crate::render`, … wherever
//! it lives; the crate graph itself keeps imports pointing down.

pub use visage_core::*;
pub mod render;
