//! The head model: regions, the morphable model and its forward pass, the
//! built-in procedural head and its motions.

pub mod builtin;
pub mod cavity;
pub mod eigen;
pub mod geometry;
pub mod head;
pub mod motion;
pub mod nearest;
pub mod open_mouth;
pub mod regions;
pub mod topology;
