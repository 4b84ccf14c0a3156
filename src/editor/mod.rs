//! The editor core, free of any terminal: named commands (`command`, declared
//! once), the state and its update function (`state`), session files
//! (`session`), headless replay (`replay`) and frame pacing (`pacing`). The
//! terminal front end (`crate::tui`) and replay drive the same [`Editor`].

pub mod command;
pub mod pacing;
pub mod replay;
pub mod session;
pub mod state;
