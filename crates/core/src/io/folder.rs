//! Databases from folders of GaussianAvatars avatars, on the user's FLAME model
//! (`--flame`, `--masks`, or the config file) or, without one, on the built-in
//! head (folders exported from built-in composites).

use std::path::{Path, PathBuf};

use serde::Deserialize;

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

/// Avatar folders in `dir` (sorted by name), or `dir` itself when it is one.
pub fn avatar_folders(dir: &Path) -> super::Result<Vec<(String, PathBuf)>> {
    if !dir.is_dir() {
        return Err(format!("database folder {} does not exist", dir.display()).into());
    }
    let is_avatar =
        |p: &Path| p.join("point_cloud.ply").is_file() && p.join("flame_param.npz").is_file();
    let name_of = |p: &Path| {
        crate::text::printable(
            &p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_else(|| "avatar".into()),
        )
    };
    if is_avatar(dir) {
        return Ok(vec![(name_of(dir), dir.to_path_buf())]);
    }
    let mut out: Vec<(String, PathBuf)> = std::fs::read_dir(dir)
        .map_err(|e| super::FileError::access("list", dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| is_avatar(p))
        .map(|p| (name_of(&p), p))
        .collect();
    out.sort();
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
