//! visage: compose photo-realistic, animatable Gaussian head avatars from a
//! database of existing ones, in the terminal.
//!
//! Architecture (data flows one way): `model` (head model, synthetic database)
//! → `avatar` / `io` (data and formats) → `compose` (selection, blending,
//! post-processing) → `render` (splat renderers) → `tui` (the editor); `cli`
//! wires commands to them.

pub mod avatar;
pub mod cli;
pub mod compose;
pub mod editor;
pub mod error;
pub mod io;
pub mod model;
pub mod pipeline;
pub mod render;
pub mod scene;
pub mod text;
pub mod tui;
