//! Rendering: cameras, projection conventions, the CPU reference splat renderer
//! (the accuracy oracle), and the CPU mesh preview.

pub mod camera;
pub mod image;
pub mod mesh_preview;
pub mod projection;
pub mod reference;
pub mod scene;
pub mod sh;
