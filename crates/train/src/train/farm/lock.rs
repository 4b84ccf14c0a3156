//! One trainer per subject, across processes and machines: a record lock
//! (`fcntl`) on the subject's lock file. The system drops it when the process
//! ends however it ends (kill -9 included), so no stale lock outlives a job,
//! and record locks are what NFS implements (cluster file systems need their
//! locking on: docs/scale-out.md). `db status` asks whether a lock is held
//! without taking it (`F_GETLK`), so looking never makes a starting shard
//! think the subject is taken.
//!
//! On Linux the locks are open-file-description locks (`F_OFD_SETLK`): they
//! belong to the open file, not the process, so no other handle on the same
//! file anywhere in the process can release them by being closed, as it
//! would a classic POSIX lock.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::os::fd::AsRawFd;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// A held subject lock; dropping it releases the lock.
#[derive(Debug)]
pub struct SubjectLock {
    file: File,
    path: PathBuf,
}

/// Lock commands: open-file-description locks where there are some.
#[cfg(target_os = "linux")]
const SET_LOCK: libc::c_int = libc::F_OFD_SETLK;
#[cfg(target_os = "linux")]
const GET_LOCK: libc::c_int = libc::F_OFD_GETLK;
#[cfg(not(target_os = "linux"))]
const SET_LOCK: libc::c_int = libc::F_SETLK;
#[cfg(not(target_os = "linux"))]
const GET_LOCK: libc::c_int = libc::F_GETLK;

/// The whole-file write lock request (`l_pid` 0, as OFD locks require).
fn whole_file(kind: libc::c_short) -> libc::flock {
    // SAFETY: flock is plain data; all-zero is a valid value.
    let mut lock: libc::flock = unsafe { std::mem::zeroed() };
    lock.l_type = kind;
    lock.l_whence = libc::SEEK_SET as libc::c_short;
    lock.l_start = 0;
    lock.l_len = 0; // to the end of the file, however long
    lock
}

fn open(path: &Path) -> Result<File> {
    OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| Error::io("open", path, e))
}

impl SubjectLock {
    /// Takes the lock, or `None` when another process holds it. `holder`
    /// (host, process, job) is written into the file for `db status`.
    pub fn try_acquire(path: &Path, holder: &str) -> Result<Option<SubjectLock>> {
        let file = open(path)?;
        let request = whole_file(libc::F_WRLCK as libc::c_short);
        // SAFETY: a valid descriptor and a pointer to a live flock.
        let r = unsafe { libc::fcntl(file.as_raw_fd(), SET_LOCK, &request) };
        if r == -1 {
            let e = std::io::Error::last_os_error();
            return match e.raw_os_error() {
                Some(libc::EAGAIN) | Some(libc::EACCES) => Ok(None),
                _ => Err(Error::io("lock", path, e)),
            };
        }
        let mut lock = SubjectLock {
            file,
            path: path.to_path_buf(),
        };
        lock.describe(holder)?;
        Ok(Some(lock))
    }

    /// Rewrites the holder line.
    pub fn describe(&mut self, holder: &str) -> Result<()> {
        let io = |e| Error::io("write", &self.path, e);
        self.file.set_len(0).map_err(io)?;
        use std::io::Seek;
        self.file.rewind().map_err(io)?;
        self.file
            .write_all(format!("{holder}\n").as_bytes())
            .map_err(io)
    }
}

/// Who holds the lock at `path`, if anyone does (another open file: the
/// caller's own locks never conflict with it). Takes nothing.
pub fn holder(path: &Path) -> Result<Option<String>> {
    let file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io("open", path, e)),
    };
    let mut probe = whole_file(libc::F_WRLCK as libc::c_short);
    // SAFETY: a valid descriptor and a pointer to a live flock. F_GETLK on
    // a read-only handle is allowed for any lock type.
    let r = unsafe { libc::fcntl(file.as_raw_fd(), GET_LOCK, &mut probe) };
    if r == -1 {
        return Err(Error::io(
            "query the lock on",
            path,
            std::io::Error::last_os_error(),
        ));
    }
    if probe.l_type == libc::F_UNLCK as libc::c_short {
        return Ok(None);
    }
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let line = text.lines().next().unwrap_or("").trim();
    Ok(Some(if line.is_empty() {
        "another process".to_string()
    } else {
        crate::text::printable(line)
    }))
}

/// This machine's name ("?" where the system does not say).
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "?".into())
}

/// Who is training here, for the lock file: host, process and, under a
/// scheduler, the job.
pub fn this_process() -> String {
    let host = host_name();
    let var = |k: &str| std::env::var(k).ok().filter(|v| !v.is_empty());
    let mut s = format!("host {host} pid {}", std::process::id());
    if let (Some(job), Some(task)) = (var("SLURM_ARRAY_JOB_ID"), var("SLURM_ARRAY_TASK_ID")) {
        s += &format!(" slurm job {job}_{task}");
    } else if let Some(job) = var("SLURM_JOB_ID") {
        s += &format!(" slurm job {job}");
    } else if let (Some(pod), Some(_)) = (var("HOSTNAME"), var("JOB_COMPLETION_INDEX")) {
        s += &format!(" pod {pod}");
    }
    s
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    #[test]
    fn a_held_lock_is_seen_and_refused_and_dropping_it_frees_it() {
        let path = std::env::temp_dir().join(format!("visage-lock-{}", std::process::id()));
        let _ = std::fs::remove_file(&path);
        assert_eq!(holder(&path).unwrap(), None, "no file, no holder");
        let lock = SubjectLock::try_acquire(&path, "host test pid 1")
            .unwrap()
            .unwrap();
        // Open-file-description locks conflict within one process too.
        assert_eq!(holder(&path).unwrap().as_deref(), Some("host test pid 1"));
        assert!(SubjectLock::try_acquire(&path, "second").unwrap().is_none());
        // Opening and closing the file elsewhere does not drop the lock.
        drop(std::fs::File::open(&path).unwrap());
        assert!(holder(&path).unwrap().is_some());
        drop(lock);
        assert_eq!(holder(&path).unwrap(), None);
        assert!(SubjectLock::try_acquire(&path, "third").unwrap().is_some());
        let _ = std::fs::remove_file(&path);
    }
}
