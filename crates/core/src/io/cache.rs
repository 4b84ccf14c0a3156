//! visage's cache folder: what it keeps because it can make it again but
//! would rather not — level-of-detail hierarchies of big scenes (`lod/`)
//! and finished seam fits (`fits/`) — and how much of the disk each takes,
//! so a user can see it and clear it (`visage cache`).

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The folder visage keeps what it can make again in (level-of-detail
/// caches in `lod/`, seam fits in `fits/`): `$VISAGE_CACHE_DIR`, else
/// `$XDG_CACHE_HOME/visage`, else `~/.cache/visage` (the temporary folder's
/// `visage` where there is no home).
pub fn cache_root() -> PathBuf {
    if let Some(dir) = std::env::var_os("VISAGE_CACHE_DIR").filter(|d| !d.is_empty()) {
        return PathBuf::from(dir);
    }
    std::env::var_os("XDG_CACHE_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(std::env::temp_dir)
        .join("visage")
}

/// One kind of file the cache folder keeps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CacheKind {
    /// Its folder under the cache folder.
    pub folder: &'static str,
    /// The extension of its files (without the dot).
    pub extension: &'static str,
    /// What the files are, for people.
    pub what: &'static str,
}

/// Every kind of file the cache folder keeps.
pub const CACHE_KINDS: [CacheKind; 2] = [
    CacheKind {
        folder: "lod",
        extension: "lod",
        what: "level-of-detail caches of scene files",
    },
    CacheKind {
        folder: "fits",
        extension: "fit",
        what: "finished seam fits",
    },
];

/// How much a kind of file takes: whole files, and the partial files and
/// build folders of writes under way or abandoned by a killed process.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheUsage {
    /// Finished files.
    pub files: usize,
    /// Their bytes.
    pub bytes: u64,
    /// Partial files and build folders.
    pub partial: usize,
    /// Their bytes.
    pub partial_bytes: u64,
}

impl CacheUsage {
    /// Counts one entry of `bytes`, partial or finished.
    fn add(&mut self, partial: bool, bytes: u64) {
        if partial {
            self.partial += 1;
            self.partial_bytes += bytes;
        } else {
            self.files += 1;
            self.bytes += bytes;
        }
    }
}

impl CacheKind {
    /// Its folder under `root`.
    pub fn dir(&self, root: &Path) -> PathBuf {
        root.join(self.folder)
    }

    /// Whether `name` is one of its finished files.
    fn finished(&self, name: &str) -> bool {
        name.strip_suffix(self.extension)
            .is_some_and(|stem| stem.ends_with('.') && stem.len() > 1)
    }

    /// Whether `name` is a partial file or build folder of one of its files.
    fn partial(&self, name: &str) -> bool {
        [".partial.", ".build."]
            .iter()
            .any(|tail| name.contains(&format!(".{}{tail}", self.extension)))
    }

    /// What its folder under `root` holds (nothing when there is none). Other
    /// files in the folder are not its, and are not counted.
    pub fn usage(&self, root: &Path) -> Result<CacheUsage> {
        let mut usage = CacheUsage::default();
        for (path, partial) in self.entries(root)? {
            usage.add(partial, size(&path));
        }
        Ok(usage)
    }

    /// Removes its finished files under `root`, and the partial files and
    /// build folders no running visage is writing (their names end in the
    /// writer's process id); returns what went. Nothing else in the folder is
    /// touched.
    pub fn clear(&self, root: &Path) -> Result<CacheUsage> {
        let mut removed = CacheUsage::default();
        for (path, partial) in self.entries(root)? {
            if partial && writer_alive(&path) {
                continue;
            }
            let bytes = size(&path);
            let gone = if path.is_dir() {
                std::fs::remove_dir_all(&path)
            } else {
                std::fs::remove_file(&path)
            };
            match gone {
                Ok(()) => {}
                // Removed meanwhile by another process: gone all the same.
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(Error::io("remove", &path, e)),
            }
            removed.add(partial, bytes);
        }
        Ok(removed)
    }

    /// Its entries under `root`, each with whether it is partial.
    fn entries(&self, root: &Path) -> Result<Vec<(PathBuf, bool)>> {
        let dir = self.dir(root);
        let entries = match std::fs::read_dir(&dir) {
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
            other => other.map_err(|e| Error::io("read", &dir, e))?,
        };
        let mut out = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| Error::io("read", &dir, e))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if self.partial(&name) {
                out.push((entry.path(), true));
            } else if self.finished(&name) && entry.path().is_file() {
                out.push((entry.path(), false));
            }
        }
        out.sort();
        Ok(out)
    }
}

/// Bytes of a file, or of everything in a folder.
fn size(path: &Path) -> u64 {
    if path.is_dir() {
        std::fs::read_dir(path).map_or(0, |d| d.flatten().map(|e| size(&e.path())).sum())
    } else {
        std::fs::metadata(path).map_or(0, |m| m.len())
    }
}

/// Whether the process whose id ends a partial file's name (`….partial.PID`,
/// `….build.PID`) still runs, so the file is a write under way rather than
/// one a killed process left (by `/proc`: elsewhere every writer reads as
/// gone).
pub fn writer_alive(path: &Path) -> bool {
    let name = path.file_name().unwrap_or_default().to_string_lossy();
    name.rsplit('.')
        .next()
        .and_then(|pid| pid.parse::<u32>().ok())
        .is_some_and(|pid| Path::new(&format!("/proc/{pid}")).exists())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn usage_and_clear_count_only_the_kinds_own_files_and_spare_live_writers() {
        let root = std::env::temp_dir().join(format!("visage-cache-kinds-{}", std::process::id()));
        std::fs::remove_dir_all(&root).ok();
        let fits = CACHE_KINDS[1].dir(&root);
        std::fs::create_dir_all(&fits).unwrap();
        std::fs::write(fits.join("0011.fit"), [0u8; 100]).unwrap();
        std::fs::write(fits.join("0022.fit"), [0u8; 50]).unwrap();
        // A writer that is gone, and one that runs: this test.
        std::fs::write(fits.join("0033.fit.partial.4000000000"), [0u8; 7]).unwrap();
        let live = fits.join(format!("0044.fit.partial.{}", std::process::id()));
        std::fs::write(&live, [0u8; 9]).unwrap();
        // Not ours: a user's file, a folder named like a fit, a bare ".fit".
        std::fs::write(fits.join("notes.txt"), b"keep").unwrap();
        std::fs::create_dir_all(fits.join("odd.fit")).unwrap();
        std::fs::write(fits.join(".fit"), b"keep").unwrap();
        let kind = CACHE_KINDS[1];
        let before = kind.usage(&root).unwrap();
        assert_eq!(
            before,
            CacheUsage {
                files: 2,
                bytes: 150,
                partial: 2,
                partial_bytes: 16
            }
        );
        // The other kind sees none of them, and a missing folder holds none.
        assert_eq!(CACHE_KINDS[0].usage(&root).unwrap(), CacheUsage::default());
        let removed = kind.clear(&root).unwrap();
        assert_eq!((removed.files, removed.bytes), (2, 150));
        assert_eq!((removed.partial, removed.partial_bytes), (1, 7));
        assert!(live.exists(), "a write under way is left alone");
        for kept in ["notes.txt", "odd.fit", ".fit"] {
            assert!(fits.join(kept).exists(), "{kept}");
        }
        std::fs::remove_dir_all(&root).ok();
    }
}
