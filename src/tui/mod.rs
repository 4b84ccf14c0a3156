//! The terminal editor, in The Elm Architecture: `state` (the editor state and
//! its update function) ← `command` (named commands, bound by `keymap`) →
//! `view` (cells) and `graphics` (image protocols); `workbench` turns state into
//! pictures, `session` records and `replay` re-runs commands on logical ticks,
//! `app` is the interactive runtime.

pub mod app;
pub mod command;
pub mod graphics;
pub mod keymap;
pub mod pacing;
pub mod replay;
pub mod session;
pub mod state;
pub mod view;
pub mod workbench;
