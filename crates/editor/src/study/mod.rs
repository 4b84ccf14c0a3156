//! The perceptual study of thesis §6.2–6.3, terminal-free: study folders
//! (categories, recipes, per-participant orders, display settings), the
//! journal of answers, tallied results and their analysis, and the plots.
//! `tui::study` runs a participant's session; `cli` exposes the commands.

pub mod analysis;
pub mod design;
pub mod fits;
pub mod journal;
pub mod plot;
pub mod results;
