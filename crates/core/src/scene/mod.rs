//! What is looked at and from where, as data: world-space Gaussian scenes
//! (what every renderer draws) and cameras (part of every recipe). Below the
//! method and the renderers, beside the head model and the formats.

pub mod camera;
pub mod clean;
pub mod splats;
pub mod synthetic;
pub mod upright;
