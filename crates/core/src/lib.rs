//! The bottom of visage: terminal-safe text, the error type and its exit codes, the head model and its motions, triangle-bound Gaussians and databases, cameras and splat scenes, and every file format.

pub mod avatar;
pub mod error;
pub mod io;
pub mod model;
pub mod scene;
pub mod text;
