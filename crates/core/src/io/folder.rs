//! Databases from folders of GaussianAvatars avatars, on the user's FLAME model
//! (`--flame`, `--masks`, or the config file) or, without one, on the built-in
//! head (folders exported from built-in composites).

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::avatar::read_avatar;
use super::flame::load_flame;
use crate::avatar::database::Database;
use crate::model::builtin::build_head;
use crate::model::head::HeadModel;

/// `$XDG_CONFIG_HOME/visage/config.toml` (or `~/.config/visage/config.toml`).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// Default FLAME model for `--db DIR`.
    pub flame: Option<PathBuf>,
    /// Default FLAME masks for `--db DIR`.
    pub masks: Option<PathBuf>,
}

/// Path of the config file.
pub fn config_path() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config")))?;
    Some(base.join("visage").join("config.toml"))
}

/// Reads the config file if there is one.
pub fn read_config() -> super::Result<Config> {
    let Some(path) = config_path().filter(|p| p.exists()) else {
        return Ok(Config::default());
    };
    let text =
        std::fs::read_to_string(&path).map_err(|e| super::FileError::access("read", &path, e))?;
    toml::from_str(&text).map_err(|e| format!("{}: {}", path.display(), e.message().trim()).into())
}

/// The index `visage db index` writes into a database folder: the avatars
/// that passed `db check`, which the editor and `study build` then load
/// (and nothing else in the folder: half-trained work, failed subjects).
pub const INDEX_FILE: &str = "index.json";

/// What `index.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct DbIndex {
    /// `visage-db-index 1`.
    pub format: String,
    /// The avatars, in name order.
    pub avatars: Vec<IndexedAvatar>,
}

/// One avatar of an index.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct IndexedAvatar {
    /// Its name (the folder's).
    pub name: String,
    /// Gaussians when indexed.
    pub gaussians: usize,
    /// Iterations trained, when recorded.
    pub iterations: Option<usize>,
    /// Held-out PSNR in dB, when recorded.
    pub psnr_db: Option<f64>,
}

/// The index format this version writes and reads.
pub const INDEX_FORMAT: &str = "visage-db-index 1";

impl DbIndex {
    /// Reads `dir/index.json`, if there is one.
    pub fn read(dir: &Path) -> super::Result<Option<DbIndex>> {
        let path = dir.join(INDEX_FILE);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(super::FileError::access("read", &path, e)),
        };
        let index: DbIndex = serde_json::from_str(&text)
            .map_err(|e| format!("{} is not a visage index: {e}", path.display()))?;
        if index.format != INDEX_FORMAT {
            return Err(format!(
                "{} is a '{}', not a '{INDEX_FORMAT}': index the folder again with this visage",
                path.display(),
                crate::text::printable(&index.format)
            )
            .into());
        }
        Ok(Some(index))
    }

    /// Writes `dir/index.json` by rename, so a loader never reads half.
    pub fn write(&self, dir: &Path) -> super::Result<()> {
        let path = dir.join(INDEX_FILE);
        let partial = dir.join(format!("{INDEX_FILE}.partial-{}", std::process::id()));
        let text = serde_json::to_string_pretty(self).expect("indexes serialise") + "\n";
        std::fs::write(&partial, text)
            .map_err(|e| super::FileError::access("write", &partial, e))?;
        std::fs::rename(&partial, &path).map_err(|e| super::FileError::access("write", &path, e))
    }
}

/// Whether `dir` holds a GaussianAvatars avatar.
pub fn is_avatar_folder(dir: &Path) -> bool {
    dir.join("point_cloud.ply").is_file() && dir.join("flame_param.npz").is_file()
}

/// The folder name as a display name.
fn name_of(p: &Path) -> String {
    crate::text::printable(
        &p.file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "avatar".into()),
    )
}

/// Every avatar folder directly in `dir` (sorted by name), ignoring hidden
/// folders (a database's `.work` areas) and any index.
pub fn scan_avatar_folders(dir: &Path) -> super::Result<Vec<(String, PathBuf)>> {
    let mut out: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| super::FileError::access("list", dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| !name_of(p).starts_with('.') && is_avatar_folder(p))
        .map(|p| (name_of(&p), p))
        .collect();
    out.sort();
    Ok(out)
}

/// Avatar folders in `dir`: those its index lists when it has one, else
/// every avatar folder in it (sorted by name), or `dir` itself when it is one.
pub fn avatar_folders(dir: &Path) -> super::Result<Vec<(String, PathBuf)>> {
    if !dir.is_dir() {
        return Err(format!("database folder {} does not exist", dir.display()).into());
    }
    if is_avatar_folder(dir) {
        return Ok(vec![(name_of(dir), dir.to_path_buf())]);
    }
    let out = match DbIndex::read(dir)? {
        Some(index) => index
            .avatars
            .iter()
            .map(|a| {
                let path = dir.join(&a.name);
                if a.name.contains(['/', '\\']) || a.name.starts_with('.') || !is_avatar_folder(&path) {
                    return Err(format!(
                        "{} lists '{}', which is not an avatar folder there: run visage db index {} again",
                        dir.join(INDEX_FILE).display(),
                        crate::text::printable(&a.name),
                        dir.display()
                    )
                    .into());
                }
                Ok((crate::text::printable(&a.name), path))
            })
            .collect::<super::Result<Vec<_>>>()?,
        None => scan_avatar_folders(dir)?,
    };
    if out.is_empty() {
        return Err(format!(
            "{} holds no GaussianAvatars avatars (folders with point_cloud.ply and flame_param.npz)",
            dir.display()
        ).into());
    }
    Ok(out)
}

/// Avatars made on FLAME (5,023 vertices, 5,143 with GaussianAvatars'
/// teeth) cannot load on the built-in head: say so, and what to pass, before
/// an array's shape would.
fn check_built_in_head(name: &str, dir: &Path, vertices: usize) -> super::Result<()> {
    let Ok(arrays) = super::npy::read_npz(&dir.join("flame_param.npz")) else {
        return Ok(()); // reading the avatar reports it
    };
    let theirs = ["static_offset", "dynamic_offset"]
        .iter()
        .filter_map(|k| arrays.get(*k))
        .find_map(|a| (a.shape.len() == 3).then(|| a.shape[1]));
    match theirs {
        Some(v) if v != vertices => Err(super::FileError::Malformed(format!(
            "avatar {name} was made on a head of {v} vertices (FLAME{}), not the built-in head's {vertices}: \
             pass the FLAME model and masks it was trained with, --flame generic_model.pkl --masks FLAME_masks.pkl \
             (or set flame and masks in ~/.config/visage/config.toml)",
            if v == 5023 || v == 5143 { "" } else { "?" }
        ))),
        _ => Ok(()),
    }
}

/// Loads a folder database. `flame` is (model, masks); `None` uses the built-in head.
pub fn load_folder(dir: &Path, flame: Option<(&Path, &Path)>) -> super::Result<Database> {
    let folders = avatar_folders(dir)?;
    let mut digest = blake3::Hasher::new();
    let model: HeadModel = match flame {
        Some((m, k)) => {
            for p in [m, k] {
                digest.update(&super::read_file(p)?);
            }
            load_flame(m, k)?
        }
        None => build_head(),
    };
    if flame.is_none() {
        if let Some((name, path)) = folders.first() {
            check_built_in_head(name, path, model.vertex_count())?;
        }
    }
    let mut sources = Vec::new();
    for (name, path) in &folders {
        for f in ["point_cloud.ply", "flame_param.npz"] {
            let p = path.join(f);
            digest.update(&std::fs::read(&p).map_err(|e| super::FileError::access("read", &p, e))?);
        }
        sources.push(read_avatar(path, name, &model)?);
    }
    let motions = sources.iter().map(|s| s.motion.clone()).collect();
    Ok(Database {
        label: dir.display().to_string(),
        fingerprint: format!("folder {} {}", dir.display(), digest.finalize().to_hex()),
        model,
        sources,
        motions,
    })
}
