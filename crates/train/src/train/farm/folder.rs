//! A database folder being built: finished avatars at `DIR/<id>/`, and per
//! subject a work area `DIR/.work/<id>/` with the lock, the checkpoint, the
//! progress line and the failure note. An avatar is trained into the work
//! area and appears at `DIR/<id>/` by one rename, so a reader (the editor,
//! `db index`, another shard) sees a whole avatar or none.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::manifest::{Subject, SubjectOptions};
use crate::error::{Error, Result};
use crate::io::avatar::read_avatar;
use crate::model::head::HeadModel;
use crate::train::trainer::TRAINING_METADATA;

/// The record beside a finished avatar of a manifest: how it was trained
/// (the fingerprint says whether it is the manifest's subject as written
/// now) and what it scored on the dataset's held-out views.
pub const SUBJECT_RECORD: &str = "subject.json";

/// The work areas' folder inside a database folder.
pub const WORK: &str = ".work";

/// What `subject.json` holds.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SubjectRecord {
    /// The subject id.
    pub id: String,
    /// [`SubjectOptions::fingerprint`] of the options it was trained with.
    pub fingerprint: String,
    /// Iterations trained.
    pub iterations: usize,
    /// Gaussians written.
    pub gaussians: usize,
    /// Mean PSNR on the dataset's validation views (novel cameras), in dB.
    pub val_psnr_db: Option<f64>,
}

/// How far a subject's run is, as its progress line says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Progress {
    /// Iterations done.
    pub iteration: usize,
    /// Iterations asked for.
    pub total: usize,
    /// The iteration of the newest checkpoint (0: none): what a run that
    /// dies now resumes from.
    pub checkpointed: usize,
}

/// A database folder and its work areas.
#[derive(Clone, Debug)]
pub struct DbFolder {
    /// The database folder.
    pub root: PathBuf,
}

impl DbFolder {
    /// The folder of `root`.
    pub fn new(root: &Path) -> DbFolder {
        DbFolder {
            root: root.to_path_buf(),
        }
    }

    /// Where a finished avatar lives.
    pub fn avatar(&self, id: &str) -> PathBuf {
        self.root.join(id)
    }

    /// The subject's work area.
    pub fn work(&self, id: &str) -> PathBuf {
        self.root.join(WORK).join(id)
    }

    /// The lock file.
    pub fn lock(&self, id: &str) -> PathBuf {
        self.work(id).join("lock")
    }

    /// The checkpoint of an unfinished run.
    pub fn checkpoint(&self, id: &str) -> PathBuf {
        self.work(id).join("checkpoint.npz")
    }

    /// The fingerprint of the options the checkpoint was made with.
    pub fn checkpoint_fingerprint(&self, id: &str) -> PathBuf {
        self.work(id).join("checkpoint.options")
    }

    /// `iteration total checkpointed`, rewritten as training goes.
    pub fn progress(&self, id: &str) -> PathBuf {
        self.work(id).join("progress")
    }

    /// Why the last run failed, when it did.
    pub fn failure(&self, id: &str) -> PathBuf {
        self.work(id).join("failed")
    }

    /// Where this process writes the avatar before renaming it into place.
    pub fn staging(&self, id: &str) -> PathBuf {
        self.work(id)
            .join(format!("avatar.partial-{}", std::process::id()))
    }

    /// Where an outdated avatar waits while its replacement moves in, where
    /// the two cannot be swapped in one step.
    fn replaced(&self, id: &str) -> PathBuf {
        self.work(id).join("replaced")
    }

    /// Creates the subject's work area.
    pub fn prepare(&self, id: &str) -> Result<()> {
        let work = self.work(id);
        std::fs::create_dir_all(&work).map_err(|e| Error::io("create", &work, e))
    }

    /// Removes what runs that died left in the work area: staged avatars
    /// and the note of a failure (the subject's lock held).
    pub fn clear_leftovers(&self, id: &str) -> Result<()> {
        let work = self.work(id);
        let entries = std::fs::read_dir(&work).map_err(|e| Error::io("list", &work, e))?;
        for entry in entries.filter_map(|e| e.ok()) {
            if entry
                .file_name()
                .to_string_lossy()
                .starts_with("avatar.partial")
            {
                let path = entry.path();
                std::fs::remove_dir_all(&path).map_err(|e| Error::io("remove", &path, e))?;
            }
        }
        let _ = std::fs::remove_file(self.failure(id));
        Ok(())
    }

    /// Puts back an avatar a crashed publish left moved aside (the subject's
    /// lock held): it is outdated, and will be replaced by a whole one.
    pub fn recover(&self, id: &str) -> Result<()> {
        let (aside, target) = (self.replaced(id), self.avatar(id));
        if aside.exists() && !target.exists() {
            std::fs::rename(&aside, &target).map_err(|e| Error::io("restore", &target, e))?;
        }
        Ok(())
    }

    /// The record of a finished avatar, if it has a readable one.
    pub fn record(&self, id: &str) -> Option<SubjectRecord> {
        let text = std::fs::read_to_string(self.avatar(id).join(SUBJECT_RECORD)).ok()?;
        serde_json::from_str(&text).ok()
    }

    /// Whether `subject` is finished as the manifest now asks: its record
    /// matches the options, and (with `head`) its avatar loads with as many
    /// Gaussians as recorded. Without `head` it trusts the record (for
    /// `db status`, which must stay cheap while jobs run).
    pub fn finished(&self, subject: &Subject, head: Option<&HeadModel>) -> bool {
        self.current_record(subject).is_some_and(|record| {
            head.is_none_or(|h| {
                check_avatar(&self.avatar(&subject.id), h)
                    .is_ok_and(|c| c.gaussians == record.gaussians)
            })
        })
    }

    /// The record of `subject`'s avatar when it was trained as the manifest
    /// asks now (same options fingerprint and iterations).
    pub fn current_record(&self, subject: &Subject) -> Option<SubjectRecord> {
        self.record(&subject.id).filter(|r| {
            r.fingerprint == subject.options.fingerprint()
                && r.iterations == subject.options.iterations
        })
    }

    /// The progress line of a subject's current or last run.
    pub fn read_progress(&self, id: &str) -> Option<Progress> {
        let text = std::fs::read_to_string(self.progress(id)).ok()?;
        let mut words = text.split_whitespace().map(|w| w.parse().ok());
        Some(Progress {
            iteration: words.next()??,
            total: words.next()??,
            checkpointed: words.next()??,
        })
    }

    /// Rewrites the progress line (by rename: a reader never sees half).
    pub fn write_progress(&self, id: &str, p: Progress) -> Result<()> {
        let line = format!("{} {} {}\n", p.iteration, p.total, p.checkpointed);
        write_atomically(&self.progress(id), line.as_bytes())
    }

    /// Moves the staged avatar into place: one rename when the subject has
    /// no avatar yet, one atomic swap (`renameat2(RENAME_EXCHANGE)`) when an
    /// outdated one is there. Where the file system cannot swap (NFS), the
    /// old one is moved aside first; [`DbFolder::recover`] undoes a crash
    /// between the two renames.
    pub fn publish(&self, id: &str) -> Result<()> {
        let staged = self.staging(id);
        let target = self.avatar(id);
        if !target.exists() {
            std::fs::rename(&staged, &target).map_err(|e| Error::io("rename into", &target, e))?;
        } else if exchange(&staged, &target) {
            // The outdated avatar is where the staged one was.
            std::fs::remove_dir_all(&staged).map_err(|e| Error::io("remove", &staged, e))?;
        } else {
            let aside = self.replaced(id);
            let _ = std::fs::remove_dir_all(&aside);
            std::fs::rename(&target, &aside).map_err(|e| Error::io("move aside", &target, e))?;
            std::fs::rename(&staged, &target).map_err(|e| Error::io("rename into", &target, e))?;
            std::fs::remove_dir_all(&aside).map_err(|e| Error::io("remove", &aside, e))?;
        }
        // The run is over: its checkpoint and notes go (the lock file stays,
        // as another process may be waiting on it).
        for path in [
            self.checkpoint(id),
            self.checkpoint_fingerprint(id),
            self.failure(id),
        ] {
            let _ = std::fs::remove_file(path);
        }
        Ok(())
    }
}

/// Swaps two folders in one step where the system can (Linux's
/// `renameat2(RENAME_EXCHANGE)`); false where it cannot.
fn exchange(a: &Path, b: &Path) -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::ffi::OsStrExt;
        let (Ok(a), Ok(b)) = (
            std::ffi::CString::new(a.as_os_str().as_bytes()),
            std::ffi::CString::new(b.as_os_str().as_bytes()),
        ) else {
            return false;
        };
        // SAFETY: two NUL-terminated paths, relative to the working folder.
        let r = unsafe {
            libc::renameat2(
                libc::AT_FDCWD,
                a.as_ptr(),
                libc::AT_FDCWD,
                b.as_ptr(),
                libc::RENAME_EXCHANGE,
            )
        };
        r == 0
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (a, b);
        false
    }
}

/// What `db check` finds in one avatar folder.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct AvatarCheck {
    /// Gaussians in the point cloud.
    pub gaussians: usize,
    /// Iterations, from `training.json`, when it is there.
    pub iterations: Option<usize>,
    /// Held-out PSNR in dB, from `subject.json` (or a `psnr` in
    /// `training.json`), when recorded.
    pub psnr_db: Option<f64>,
}

/// Loads an avatar folder the way the editor does and reads what its
/// records say; the error says what is wrong.
pub fn check_avatar(dir: &Path, head: &HeadModel) -> std::result::Result<AvatarCheck, String> {
    let name = dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let source = read_avatar(dir, &name, head).map_err(|e| e.to_string())?;
    let gaussians = source.gaussians.len();
    let json = |file: &str| -> std::result::Result<Option<serde_json::Value>, String> {
        match std::fs::read_to_string(dir.join(file)) {
            Ok(text) => serde_json::from_str(&text)
                .map(Some)
                .map_err(|e| format!("{file} is not JSON: {e}")),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(format!("cannot read {file}: {e}")),
        }
    };
    let training = json(TRAINING_METADATA)?;
    let record = json(SUBJECT_RECORD)?;
    let number = |doc: &Option<serde_json::Value>, key: &str| {
        doc.as_ref()
            .and_then(|d| d.get(key))
            .and_then(|v| v.as_f64())
    };
    if let Some(n) = number(&training, "gaussians") {
        if n as usize != gaussians {
            return Err(format!(
                "{TRAINING_METADATA} says {n} Gaussians, point_cloud.ply holds {gaussians}"
            ));
        }
    }
    Ok(AvatarCheck {
        gaussians,
        iterations: number(&training, "iterations").map(|n| n as usize),
        psnr_db: number(&record, "val_psnr_db").or(number(&training, "psnr")),
    })
}

/// Writes a file under a temporary name and renames it into place.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    let partial = path.with_extension(format!("partial-{}", std::process::id()));
    std::fs::write(&partial, bytes).map_err(|e| Error::io("write", &partial, e))?;
    std::fs::rename(&partial, path).map_err(|e| Error::io("write", path, e))
}

/// A fingerprint read back from a file, if it is one.
pub fn read_fingerprint(path: &Path) -> Option<String> {
    std::fs::read_to_string(path)
        .ok()
        .map(|t| t.trim().to_string())
}

/// The options a checkpoint must have been made with to be resumed.
pub fn fingerprint_line(options: &SubjectOptions) -> String {
    options.fingerprint() + "\n"
}
