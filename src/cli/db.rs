//! The database options shared by every command that reads a database.

use std::time::Duration;

use clap::Args;

use crate::avatar::database::Database;
use crate::avatar::synthetic::MAX_SOURCES;
use crate::error::Result;
use crate::pipeline::DatabaseSpec;

/// Which database to open and, for the built-in one, how to generate it.
#[derive(Args, Debug, Clone)]
pub struct DbArgs {
    /// Database: `builtin` (synthetic avatars) or a folder of GaussianAvatars avatars.
    #[arg(long, default_value = "builtin", value_name = "builtin|DIR")]
    pub db: String,
    /// Seed of the built-in database (shapes, textures, Gaussian placement).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Gaussians per built-in avatar.
    #[arg(long, default_value_t = 50_000, value_name = "N")]
    pub gaussians_per_avatar: usize,
    /// Number of built-in source avatars (1-14).
    #[arg(long = "source-count", default_value_t = MAX_SOURCES, value_name = "N")]
    pub source_count: usize,
    /// FLAME model for `--db DIR` (flame2023.pkl or generic_model.pkl).
    #[arg(long, value_name = "FILE")]
    pub flame: Option<std::path::PathBuf>,
    /// FLAME masks for `--db DIR` (FLAME_masks.pkl).
    #[arg(long, value_name = "FILE")]
    pub masks: Option<std::path::PathBuf>,
}

impl Default for DbArgs {
    fn default() -> Self {
        DbArgs::from(&DatabaseSpec::default())
    }
}

impl From<&DatabaseSpec> for DbArgs {
    fn from(spec: &DatabaseSpec) -> Self {
        Self {
            db: spec.db.clone(),
            seed: spec.seed,
            gaussians_per_avatar: spec.gaussians_per_avatar,
            source_count: spec.source_count,
            flame: spec.flame.clone(),
            masks: spec.masks.clone(),
        }
    }
}

impl DbArgs {
    /// The database these arguments name.
    pub fn spec(&self) -> DatabaseSpec {
        DatabaseSpec {
            db: self.db.clone(),
            seed: self.seed,
            gaussians_per_avatar: self.gaussians_per_avatar,
            source_count: self.source_count,
            flame: self.flame.clone(),
            masks: self.masks.clone(),
        }
    }

    /// Opens the database and reports how long that took.
    pub fn load(&self) -> Result<(Database, Duration)> {
        self.spec().load()
    }
}
