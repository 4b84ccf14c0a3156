//! visage: compose photo-realistic, animatable Gaussian head avatars from a
//! database of existing ones, in the terminal.
//!
//! Architecture (docs/architecture.md; data flows one way, imports only point
//! down): `text`, `error` → `model`, `avatar`, `scene`, `io` (data and formats)
//! → `compose` (the method) → `render` → `pipeline` (recipe → image) →
//! `editor` (commands, state, sessions, replay) → the front ends `tui` and
//! `cli`. `tests/architecture.rs` checks the order.

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
pub mod study;
pub mod text;
pub mod train;
pub mod tui;
