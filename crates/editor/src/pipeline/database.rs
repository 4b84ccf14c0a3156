//! Which database to open, without the command line: the built-in synthetic
//! database (seed, size) or a folder of GaussianAvatars avatars (with the
//! user's FLAME files, from the arguments or the config file).

use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::avatar::database::Database;
use crate::avatar::synthetic::{builtin_database, SyntheticOptions, MAX_SOURCES};
use crate::error::{Error, Result};
use crate::model::builtin::build_head;

/// Most Gaussians per built-in avatar accepted (bounds memory: ~240 bytes each).
pub const MAX_GAUSSIANS_PER_AVATAR: usize = 2_000_000;

/// A database to open (also as a study names it in `study.toml`; fields left
/// out take the defaults).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DatabaseSpec {
    /// `builtin` or a folder of GaussianAvatars avatars.
    pub db: String,
    /// Seed of the built-in database.
    pub seed: u64,
    /// Gaussians per built-in avatar.
    pub gaussians_per_avatar: usize,
    /// Number of built-in sources.
    pub source_count: usize,
    /// FLAME model for a folder database.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flame: Option<PathBuf>,
    /// FLAME masks for a folder database.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub masks: Option<PathBuf>,
}

impl Default for DatabaseSpec {
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

impl DatabaseSpec {
    /// Opens the database and reports how long that took.
    pub fn load(&self) -> Result<(Database, Duration)> {
        if self.db != "builtin" {
            let start = Instant::now();
            let config = crate::io::folder::read_config()?;
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
            let db = crate::io::folder::load_folder(std::path::Path::new(&self.db), files)?;
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
