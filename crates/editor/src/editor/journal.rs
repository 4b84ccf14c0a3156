//! Journals: every live editor session is recorded, so nothing typed is lost.
//! Without `--record`, the journal goes to the user's state folder
//! (`$XDG_STATE_HOME/visage/journals`, else `~/.local/state/visage/journals`);
//! a journal the user did not close (a kill, a crash, a dropped SSH
//! connection) is offered back on the next start. A journal always replays to
//! what the editor showed: recording into an existing journal continues it,
//! and a new journal begins with the commands of the session it resumed.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use super::command::Command;
use super::session::{is_closed, Recorder, Session, SessionHeader};
use super::state::Applied;
use super::Editor;
use crate::error::{Error, Result};
use crate::pipeline::Subject;

/// Journals kept in the state folder; older ones are deleted at start-up.
pub const KEEP_JOURNALS: usize = 50;

/// The user's state folder for visage: `$XDG_STATE_HOME/visage`, else
/// `~/.local/state/visage` (the XDG base directory specification).
pub fn state_dir() -> Option<PathBuf> {
    let from = |var: &str| {
        std::env::var_os(var)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    from("XDG_STATE_HOME")
        .filter(|p| p.is_absolute())
        .or_else(|| from("HOME").map(|h| h.join(".local/state")))
        .map(|p| p.join("visage"))
}

/// An editor whose every successful, journalled command is written to its
/// journal before the next one runs: what the live editor drives.
pub struct JournalledEditor {
    /// The editor.
    pub editor: Editor,
    recorder: Option<Recorder>,
}

impl JournalledEditor {
    /// An editor recording into `recorder`.
    pub fn new(editor: Editor, recorder: Option<Recorder>) -> Self {
        Self { editor, recorder }
    }

    /// Runs a command and journals it when it succeeded. Should the journal
    /// fail (a full disk), recording stops, so the file stays a journal of
    /// what the editor showed up to that point, and the message says so.
    pub fn run(&mut self, command: &Command) -> std::result::Result<Applied, String> {
        let mut applied = self.editor.step(command)?;
        if command.journalled() {
            if let Some(recorder) = &mut self.recorder {
                if let Err(e) = recorder.record(self.editor.tick(), command) {
                    let path = recorder.path().display().to_string();
                    self.recorder = None;
                    applied.message = Some(format!(
                        "cannot journal to {path}: {e}; recording stopped (save the recipe to keep your work)"
                    ));
                }
            }
        }
        Ok(applied)
    }

    /// The journal being written, if any.
    pub fn journal(&self) -> Option<&Path> {
        self.recorder.as_ref().map(Recorder::path)
    }

    /// Ends the journal. A journal that recorded nothing is deleted when
    /// `tidy` (an automatic one); otherwise, when the user quit (`closed`
    /// names why), it is marked closed so it is not offered for recovery —
    /// after a kill or a hang-up it is left open, to be offered.
    pub fn finish(&mut self, closed: Option<&str>, tidy: bool) {
        let Some(recorder) = self.recorder.take() else {
            return;
        };
        let path = recorder.path().to_path_buf();
        let empty = Session::load(&path).is_ok_and(|s| s.lines.is_empty());
        if tidy && empty {
            drop(recorder);
            let _ = std::fs::remove_file(&path);
        } else if let Some(reason) = closed {
            let _ = recorder.close(reason);
        }
    }
}

/// Opens the journal `record` for a live session: an existing journal is
/// continued (and returned, to be replayed first); otherwise a new one is
/// started with `header`, holding the commands of `resume` (the session
/// replayed first), so that it replays to what the screen will show.
/// Resuming one session while recording into another existing one is refused.
pub fn open_journal(
    record: &Path,
    resume: Option<&Path>,
    header: &SessionHeader,
) -> Result<(Recorder, Option<Session>)> {
    check_record_and_resume(record, resume)?;
    if std::fs::metadata(record).is_ok_and(|m| m.len() > 0) {
        let (recorder, session) = Recorder::append(record)?;
        return Ok((recorder, Some(session)));
    }
    // The session resumed may itself be a journal a kill cut short.
    let base = resume
        .map(|p| Session::load_journal(p).map(|(s, _)| s))
        .transpose()?;
    let header = match &base {
        Some(b) => SessionHeader {
            terminal: header.terminal,
            graphics: header.graphics,
            ..b.header.clone()
        },
        None => header.clone(),
    };
    let seed = base.as_ref().map_or(&[][..], |b| &b.lines[..]);
    let recorder = Recorder::create(record, &header, seed)?;
    Ok((recorder, base))
}

/// Refuses to resume one session while recording into another that exists:
/// the journal would no longer replay to what the screen shows.
pub fn check_record_and_resume(record: &Path, resume: Option<&Path>) -> Result<()> {
    let exists = std::fs::metadata(record).is_ok_and(|m| m.len() > 0);
    match resume.filter(|r| exists && !same_file(r, record)) {
        Some(other) => Err(Error::input(format!(
            "{} already holds a session, and --session {} is another: record into a new file, or continue {0} with --record {0} alone",
            record.display(),
            other.display()
        ))),
        None => Ok(()),
    }
}

/// The subject a live session opens: the journal's or resumed session's own,
/// unless the command line named one explicitly — then the two must agree.
pub fn choose_subject(explicit: Option<&Subject>, recorded: Option<&Session>) -> Result<Subject> {
    let Some(session) = recorded else {
        return Ok(explicit.cloned().unwrap_or_default());
    };
    let theirs = session.header.subject();
    if let Some(ours) = explicit {
        let ours_absolute =
            SessionHeader::for_subject(ours, (0, 0), session.header.graphics).subject();
        if !ours_absolute.agrees_with(&theirs) {
            return Err(Error::input(format!(
                "the session records {}, not {}: leave out the database or scene to continue it, or record into a new file",
                theirs.describe(),
                ours.describe()
            )));
        }
    }
    Ok(theirs)
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    }
}

/// The folder of automatic journals.
#[derive(Clone, Debug)]
pub struct JournalFolder {
    dir: PathBuf,
}

/// A journal that was never closed and holds unsaved edits.
#[derive(Clone, Debug)]
pub struct Unfinished {
    /// The file.
    pub path: PathBuf,
    /// Its commands.
    pub session: Session,
    /// When it was last written.
    pub modified: SystemTime,
    /// Edits after its last `save-recipe`.
    pub unsaved: usize,
}

impl Unfinished {
    /// A line for the recovery question.
    pub fn describe(&self) -> String {
        format!(
            "an unsaved session from {} ({} edit{} in {} commands, {})",
            utc_time(self.modified, " ", ":"),
            self.unsaved,
            if self.unsaved == 1 { "" } else { "s" },
            self.session.lines.len(),
            self.path.display()
        )
    }
}

impl JournalFolder {
    /// The journals folder under the user's state folder, created if needed.
    pub fn in_state_dir() -> Result<JournalFolder> {
        let dir = state_dir().ok_or_else(|| {
            Error::input(
                "no state folder: set HOME or XDG_STATE_HOME (or journal with --record FILE)",
            )
        })?;
        JournalFolder::at(dir.join("journals"))
    }

    /// The journals folder at `dir`, created if needed.
    pub fn at(dir: PathBuf) -> Result<JournalFolder> {
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("create", &dir, e))?;
        Ok(JournalFolder { dir })
    }

    /// The folder.
    pub fn path(&self) -> &Path {
        &self.dir
    }

    /// A fresh journal's path: the time and the process, so that editors
    /// started in the same second do not collide.
    pub fn new_journal_path(&self) -> PathBuf {
        let stamp = utc_time(SystemTime::now(), "-", "");
        let pid = std::process::id();
        (0..)
            .map(|n| {
                let suffix = if n == 0 {
                    String::new()
                } else {
                    format!("-{n}")
                };
                self.dir.join(format!("{stamp}-{pid}{suffix}.vsg"))
            })
            .find(|p| !p.exists())
            .expect("some name is free")
    }

    /// Journals of `subject` that were not closed, hold unsaved edits and no
    /// running editor records: newest first.
    pub fn unfinished(&self, subject: &Subject) -> Vec<Unfinished> {
        let mut found: Vec<Unfinished> = self
            .journals()
            .into_iter()
            .filter_map(|(path, modified)| {
                let text = std::fs::read_to_string(&path).ok()?;
                if is_closed(&text) || in_use(&path) {
                    return None;
                }
                let (session, _) = Session::load_journal(&path).ok()?;
                let unsaved = session.unsaved_edits();
                (unsaved > 0 && subject.agrees_with(&session.header.subject())).then_some(
                    Unfinished {
                        path,
                        session,
                        modified,
                        unsaved,
                    },
                )
            })
            .collect();
        found.sort_by_key(|u| std::cmp::Reverse(u.modified));
        found
    }

    /// Deletes the oldest journals beyond `keep` (never one in use); returns
    /// how many went.
    pub fn prune(&self, keep: usize) -> usize {
        let mut all = self.journals();
        all.sort_by_key(|j| std::cmp::Reverse(j.1));
        all.into_iter()
            .skip(keep)
            .filter(|(path, _)| !in_use(path) && std::fs::remove_file(path).is_ok())
            .count()
    }

    fn journals(&self) -> Vec<(PathBuf, SystemTime)> {
        let Ok(entries) = std::fs::read_dir(&self.dir) else {
            return Vec::new();
        };
        entries
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "vsg"))
            .filter_map(|e| Some((e.path(), e.metadata().ok()?.modified().ok()?)))
            .collect()
    }
}

/// Whether a running editor holds the journal's lock.
fn in_use(path: &Path) -> bool {
    use std::os::fd::AsRawFd;
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    // SAFETY: flock on a descriptor owned by `file`; the lock (if taken) is
    // released when `file` closes at the end of this function.
    unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) != 0 }
}

/// A UTC time as `YYYY-MM-DD{sep}HH{colon}MM{colon}SS` (the civil calendar
/// from days since 1970, after Howard Hinnant's `civil_from_days`).
pub fn utc_time(t: SystemTime, sep: &str, colon: &str) -> String {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let (days, rem) = (secs.div_euclid(86_400), secs.rem_euclid(86_400));
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}{sep}{:02}{colon}{:02}{colon}{:02}",
        rem / 3600,
        rem % 3600 / 60,
        rem % 60
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::editor::session::Protocol;
    use crate::pipeline::DatabaseSpec;
    use std::time::{Duration, UNIX_EPOCH};

    fn temp(name: &str) -> PathBuf {
        let dir =
            std::env::temp_dir().join(format!("visage-journal-{}-{name}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn utc_times_follow_the_calendar() {
        let at = |s: u64| utc_time(UNIX_EPOCH + Duration::from_secs(s), " ", ":");
        assert_eq!(at(0), "1970-01-01 00:00:00");
        assert_eq!(at(951_782_400), "2000-02-29 00:00:00");
        assert_eq!(at(1_795_000_000), "2026-11-18 11:06:40");
    }

    /// Only journals of the same subject that were not closed and hold
    /// unsaved edits are offered, newest first; pruning keeps the newest.
    #[test]
    fn unfinished_journals_are_found_and_old_ones_pruned() {
        let folder = JournalFolder::at(temp("unfinished")).unwrap();
        let subject = Subject::Avatars(DatabaseSpec::default());
        let header = SessionHeader::for_subject(&subject, (80, 24), Protocol::Halfblocks);
        let write = |lines: &[&str], close: bool| {
            let path = folder.new_journal_path();
            let mut r = Recorder::create(&path, &header, &[]).unwrap();
            for (tick, l) in lines.iter().enumerate() {
                r.record(tick as u64, &Command::parse(l).unwrap()).unwrap();
            }
            if close {
                r.close("quit").unwrap();
            }
            std::thread::sleep(Duration::from_millis(20));
            path
        };
        let saved = write(&["assign", "save-recipe r.toml", "orbit 5 0"], false);
        let closed = write(&["assign"], true);
        let older = write(&["assign"], false);
        let newer = write(&["set-base bram", "undo"], false);
        let found = folder.unfinished(&subject);
        let paths: Vec<&PathBuf> = found.iter().map(|u| &u.path).collect();
        assert_eq!(paths, [&newer, &older], "not {saved:?} nor {closed:?}");
        assert_eq!(found[0].unsaved, 2);
        assert!(
            found[0].describe().contains("2 edits in 2 commands"),
            "{}",
            found[0].describe()
        );
        let other = Subject::Avatars(DatabaseSpec {
            seed: 9,
            ..DatabaseSpec::default()
        });
        assert!(folder.unfinished(&other).is_empty());
        // A journal being recorded is never offered nor pruned.
        let live_path = folder.new_journal_path();
        let mut live = Recorder::create(&live_path, &header, &[]).unwrap();
        live.record(0, &Command::Assign).unwrap();
        assert_eq!(folder.unfinished(&subject).len(), 2);
        assert_eq!(folder.prune(1), 4);
        assert!(live_path.exists() && !newer.exists());
        std::fs::remove_dir_all(folder.path()).ok();
    }

    #[test]
    fn recording_into_an_existing_journal_continues_it() {
        let dir = temp("open");
        let subject = Subject::Avatars(DatabaseSpec::default());
        let header = SessionHeader::for_subject(&subject, (80, 24), Protocol::Halfblocks);
        let (journal, other) = (dir.join("j.vsg"), dir.join("other.vsg"));
        let (mut r, none) = open_journal(&journal, None, &header).unwrap();
        assert!(none.is_none());
        r.record(3, &Command::parse("set-base bram").unwrap())
            .unwrap();
        drop(r);
        let (mut r, resumed) = open_journal(&journal, None, &header).unwrap();
        assert_eq!(resumed.unwrap().lines.len(), 1);
        r.record(4, &Command::Assign).unwrap();
        drop(r);
        // Resuming it into a new file copies its commands first.
        let (r, base) = open_journal(&other, Some(&journal), &header).unwrap();
        drop(r);
        assert_eq!(base.unwrap().lines.len(), 2);
        assert_eq!(Session::load(&other).unwrap().lines.len(), 2);
        // Resuming one session into another existing one is refused.
        let e = open_journal(&other, Some(&journal), &header)
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("already holds a session"), "{e}");
        // The journal's own subject wins unless another was named.
        let recorded = Session::load(&journal).unwrap();
        assert_eq!(choose_subject(None, Some(&recorded)).unwrap(), subject);
        let named = Subject::Avatars(DatabaseSpec {
            seed: 4,
            ..DatabaseSpec::default()
        });
        let e = choose_subject(Some(&named), Some(&recorded))
            .unwrap_err()
            .to_string();
        assert!(e.contains("the session records"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
