//! The database options shared by every command that reads a database.

use std::time::{Duration, Instant};

use clap::Args;

use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::model::builtin::build_head;
use crate::avatar::synthetic::{builtin_database, SyntheticOptions, MAX_SOURCES};

/// Most Gaussians per built-in avatar accepted (bounds memory: ~240 bytes each).
const MAX_GAUSSIANS_PER_AVATAR: usize = 2_000_000;

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
        Self {
            db: "builtin".into(),
            seed: 1,
            gaussians_per_avatar: 50_000,
            source_count: MAX_SOURCES,
            flame: None,
            masks: None,
        }
    }
}

impl DbArgs {
    /// Opens the database and reports how long that took.
    pub fn load(&self) -> Result<(Database, Duration)> {
        if self.db != "builtin" {
            let start = Instant::now();
            let config = crate::io::folder::read_config().map_err(Error::Input)?;
            let flame = self.flame.clone().or(config.flame);
            let masks = self.masks.clone().or(config.masks);
            let files = match (&flame, &masks) {
                (Some(f), Some(m)) => Some((f.as_path(), m.as_path())),
                (None, None) => None,
                _ => {
                    return Err(Error::input(
                        "--flame and --masks go together (or set both in the config file)",
                    ))
                }
            };
            let db = crate::io::folder::load_folder(std::path::Path::new(&self.db), files)
                .map_err(Error::Input)?;
            return Ok((db, start.elapsed()));
        }
        if !(1..=MAX_GAUSSIANS_PER_AVATAR).contains(&self.gaussians_per_avatar) {
            return Err(Error::input(format!(
                "--gaussians-per-avatar must be between 1 and {MAX_GAUSSIANS_PER_AVATAR}, not {}",
                self.gaussians_per_avatar
            )));
        }
        let start = Instant::now();
        let options = SyntheticOptions {
            seed: self.seed,
            sources: self.source_count,
            gaussians_per_avatar: self.gaussians_per_avatar,
        };
        let db = builtin_database(build_head(), options).map_err(Error::Input)?;
        Ok((db, start.elapsed()))
    }
}
