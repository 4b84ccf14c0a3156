//! Avatar data: triangle-bound Gaussians, the binding math that places them on a
//! posed mesh, source avatars and the database that holds them.

pub mod binding;
pub mod database;
pub mod gaussians;
