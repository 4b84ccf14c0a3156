//! Avatar data: triangle-bound Gaussians, the binding math that places them on a
//! posed mesh, source avatars, the database that holds them and the built-in
//! synthetic database.

pub mod binding;
pub mod database;
pub mod gaussians;
pub mod rebind;
pub mod sh;
pub mod synthetic;
