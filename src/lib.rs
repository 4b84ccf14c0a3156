//! visage: compose photo-realistic, animatable Gaussian head avatars in the
//! terminal. This crate holds the front ends — the interactive terminal
//! runtime (`tui`) and the command line (`cli`) — over the workspace's layers
//! (`crates/`), which it re-exports so `visage::model`, `visage::render`, …
//! name every layer from one place.

pub use visage_editor::*;

pub mod cli;
pub mod tui;
