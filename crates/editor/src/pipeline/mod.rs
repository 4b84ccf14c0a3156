//! The terminal-free path from a database and a recipe to a posed composite
//! and an image: opening a database from a clap-free [`DatabaseSpec`], one-shot
//! builds for the command line, and the [`Workbench`] that keeps a composite up
//! to date for the editor (rebuilding only what a recipe change touches), or
//! a scene file to view ([`Subject`]).

pub mod composer;
pub mod database;
pub mod lod;
pub mod subject;
pub mod workbench;

pub use composer::{Composer, Painter};
pub use database::DatabaseSpec;
pub use subject::{SceneSpec, Subject};
pub use workbench::Workbench;
