//! File formats: pickles, npy/npz, PLY (INRIA and SuperSplat's compressed),
//! `.splat`, SPZ, OBJ, FLAME models and masks,
//! GaussianAvatars avatar folders, folder databases and the fixtures generator.

pub mod avatar;
pub mod cache;
pub mod compressed_ply;
pub mod fixtures;
pub mod flame;
pub mod folder;
pub mod inria;
pub mod npy;
pub mod obj;
pub mod pickle;
pub mod pickle_write;
pub mod ply;
pub mod ply_stream;
pub mod splat;
pub mod spz;

use std::path::{Path, PathBuf};

pub use cache::cache_root;

/// Why a file could not be read or written.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FileError {
    /// The file system refused: a missing file or folder, permissions, a full disk.
    #[error("cannot {action} {}: {reason}", path.display())]
    Access {
        /// What was tried ("read", "write", "create").
        action: &'static str,
        /// The path.
        path: PathBuf,
        /// What the system said.
        reason: String,
    },
    /// The content is not what the format allows; the message names the
    /// problem (and the file, when there is one).
    #[error("{0}")]
    Malformed(String),
}

impl FileError {
    /// A file-system failure on `path`.
    pub fn access(
        action: &'static str,
        path: impl AsRef<Path>,
        error: impl std::fmt::Display,
    ) -> Self {
        FileError::Access {
            action,
            path: path.as_ref().to_path_buf(),
            reason: error.to_string(),
        }
    }

    /// The error with the file named in front of a content problem.
    pub fn in_file(self, path: &Path) -> Self {
        match self {
            FileError::Malformed(m) => FileError::Malformed(format!("{}: {m}", path.display())),
            access => access,
        }
    }
}

impl From<String> for FileError {
    fn from(message: String) -> Self {
        FileError::Malformed(message)
    }
}

impl From<&str> for FileError {
    fn from(message: &str) -> Self {
        FileError::Malformed(message.to_string())
    }
}

/// A file that cannot be read or is malformed is bad input (exit 2); a file
/// or folder that cannot be written is an I/O failure (exit 4).
impl From<FileError> for crate::error::Error {
    fn from(e: FileError) -> Self {
        match &e {
            FileError::Access { action, .. } if *action != "read" => {
                crate::error::Error::Io(e.to_string())
            }
            _ => crate::error::Error::Input(e.to_string()),
        }
    }
}

/// Result of reading or writing a file format.
pub type Result<T> = std::result::Result<T, FileError>;

/// Hears how far a long read has got: (bytes done, bytes in all). Called from
/// the reading thread; a progress bar is the usual listener.
pub type Progress<'a> = &'a (dyn Fn(u64, u64) + Sync);

/// Reads a whole file.
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    std::fs::read(path).map_err(|e| FileError::access("read", path, e))
}

/// Writes a whole file.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).map_err(|e| FileError::access("write", path, e))
}

/// A file of the repository's `tests/data/` (the fixtures made by other
/// tools), for unit tests whatever crate folder they run in.
#[cfg(test)]
pub fn test_data(relative: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/data")
        .join(relative)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A file the system refuses and a file with bad content are told apart,
    /// and both name the file.
    #[test]
    fn file_errors_say_what_failed() {
        let missing = Path::new("/no/such/model.pkl");
        let e = pickle::read(missing).unwrap_err();
        assert!(
            matches!(e, FileError::Access { action: "read", .. }),
            "{e:?}"
        );
        assert!(
            e.to_string()
                .starts_with("cannot read /no/such/model.pkl: "),
            "{e}"
        );
        let dir = std::env::temp_dir().join(format!("visage-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let bad = dir.join("bad.npz");
        std::fs::write(&bad, b"not a zip").unwrap();
        let e = npy::read_npz(&bad).unwrap_err();
        assert!(matches!(e, FileError::Malformed(_)), "{e:?}");
        assert!(
            e.to_string().starts_with(&format!("{}: ", bad.display())),
            "{e}"
        );
        let as_cli: crate::error::Error = e.into();
        assert_eq!(as_cli.exit_code(), 2);
        std::fs::remove_dir_all(&dir).ok();
    }
}
