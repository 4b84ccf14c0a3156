//! One trainer per subject, across processes and machines: a POSIX record
//! lock (`fcntl`) on the subject's lock file. The system drops it when the
//! process ends however it ends (kill -9 included), so no stale lock outlives
//! a job, and it works on NFS, where cluster home folders live. `db status`
//! asks whether a lock is held without taking it (`F_GETLK`), so looking
//! never makes a starting shard think the subject is taken.
//!
//! POSIX locks belong to the process and fall when it closes any handle on
//! the file: nothing else in a process opens a lock file.

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

/// The whole-file write lock request.
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
        let r = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_SETLK, &request) };
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

/// Who holds the lock at `path`, if anyone does (another process: a
/// process's own locks never conflict with it). Takes nothing.
pub fn holder(path: &Path) -> Result<Option<String>> {
    let file = match File::open(path) {
        Ok(f) => f,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(Error::io("open", path, e)),
    };
    let mut probe = whole_file(libc::F_WRLCK as libc::c_short);
    // SAFETY: a valid descriptor and a pointer to a live flock. F_GETLK on
    // a read-only handle is allowed for any lock type.
    let r = unsafe { libc::fcntl(file.as_raw_fd(), libc::F_GETLK, &mut probe) };
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
        format!("process {}", probe.l_pid)
    } else {
        crate::text::printable(line)
    }))
}

/// Who is training here, for the lock file: host, process and, under a
/// scheduler, the job.
pub fn this_process() -> String {
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_else(|_| "?".into());
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
