//! Session files: plain text, a versioned header, then one command per line on
//! logical frame ticks (25 per second; never wall-clock time):
//!
//! ```text
//! visage-session 1
//! db builtin seed=1 gaussians-per-avatar=50000 sources=14
//! terminal 120x40
//! graphics halfblocks
//! render 160x120
//! post ours
//! ---
//! 0 select-group nose
//! 0 set-gaussians nose bram
//! 30 play
//! 80 expect state-hash 3f2a9c0d1e2b4a5c
//! 80 expect image nose.png psnr>=40
//! 80 snapshot nose-now.png
//! ```
//!
//! `expect` lines are checks for `visage replay --check`; paths are relative to
//! the session file (expected images) or to `--out` (snapshots). The recorder
//! writes and flushes one line per command, so a crash or a kill loses nothing.

use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::compose::recipe::PostPreset;
use crate::error::{Error, Result};
use crate::pipeline::{DatabaseSpec, SceneSpec, Subject};
use crate::scene::camera::UpAxis;

use super::command::Command;

/// A terminal graphics protocol (by name: the encoders live in the terminal front end).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Protocol {
    /// kitty graphics protocol.
    Kitty,
    /// DEC sixel.
    Sixel,
    /// iTerm2 inline images.
    Iterm2,
    /// Unicode half blocks in ordinary cells.
    Halfblocks,
}

impl Protocol {
    /// Name used in session headers and the info panel.
    pub fn name(self) -> &'static str {
        match self {
            Protocol::Kitty => "kitty",
            Protocol::Sixel => "sixel",
            Protocol::Iterm2 => "iterm2",
            Protocol::Halfblocks => "halfblocks",
        }
    }

    /// Parses a name as written by [`Protocol::name`].
    pub fn from_name(s: &str) -> Option<Protocol> {
        [
            Protocol::Kitty,
            Protocol::Sixel,
            Protocol::Iterm2,
            Protocol::Halfblocks,
        ]
        .into_iter()
        .find(|p| p.name() == s)
    }
}

/// Version written in the first line.
pub const SESSION_VERSION: u32 = 1;

/// The render size new sessions record (snapshots default to it, live and
/// in replay); sessions without a `render` line keep 160x120.
pub const NEW_SESSION_RENDER: (u32, u32) = (640, 480);

/// Logical ticks per second.
pub const TICKS_PER_SECOND: u64 = 25;

/// The header of a session file.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionHeader {
    /// Database: "builtin" or a folder.
    pub db: String,
    /// Built-in database seed.
    pub seed: u64,
    /// Built-in Gaussians per avatar.
    pub gaussians_per_avatar: usize,
    /// Built-in source count.
    pub sources: usize,
    /// FLAME model and masks of a folder database.
    pub flame: Option<(PathBuf, PathBuf)>,
    /// The scene file viewed instead of a database (`visage view FILE`).
    pub scene: Option<SceneSpec>,
    /// Terminal size (columns, rows) when recorded.
    pub terminal: (u16, u16),
    /// Graphics protocol when recorded.
    pub graphics: Protocol,
    /// Size of snapshots and image checks in replay.
    pub render: (u32, u32),
    /// The post-processing the session starts from: `off` where the header
    /// has no `post` line (sessions from before session 27, and those made
    /// through [`SessionHeader::new`]); the editor starts new sessions from
    /// `ours`.
    pub post: PostPreset,
}

impl SessionHeader {
    /// A header for a database. Folder and FLAME paths are made absolute so the
    /// session replays from any working directory.
    pub fn new(db: &DatabaseSpec, terminal: (u16, u16), graphics: Protocol) -> Self {
        let absolute = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
        let folder = if db.db == "builtin" {
            db.db.clone()
        } else {
            absolute(Path::new(&db.db)).display().to_string()
        };
        Self {
            db: folder,
            seed: db.seed,
            gaussians_per_avatar: db.gaussians_per_avatar,
            sources: db.source_count,
            flame: db
                .flame
                .as_deref()
                .map(absolute)
                .zip(db.masks.as_deref().map(absolute)),
            scene: None,
            terminal,
            graphics,
            render: NEW_SESSION_RENDER,
            post: PostPreset::Off,
        }
    }

    /// A header for a database or a scene (its path made absolute).
    pub fn for_subject(subject: &Subject, terminal: (u16, u16), graphics: Protocol) -> Self {
        match subject {
            Subject::Avatars(db) => Self::new(db, terminal, graphics),
            Subject::Scene(scene) => Self {
                scene: Some(scene.absolute()),
                ..Self::new(&DatabaseSpec::default(), terminal, graphics)
            },
        }
    }

    /// What this header names: its scene, else its database.
    pub fn subject(&self) -> Subject {
        match &self.scene {
            Some(scene) => Subject::Scene(scene.clone()),
            None => Subject::Avatars(self.database()),
        }
    }

    /// The database this header names.
    pub fn database(&self) -> DatabaseSpec {
        DatabaseSpec {
            db: self.db.clone(),
            seed: self.seed,
            gaussians_per_avatar: self.gaussians_per_avatar,
            source_count: self.sources,
            flame: self.flame.as_ref().map(|f| f.0.clone()),
            masks: self.flame.as_ref().map(|f| f.1.clone()),
        }
    }

    fn write(&self, out: &mut impl Write) -> std::io::Result<()> {
        writeln!(out, "visage-session {SESSION_VERSION}")?;
        if let Some(scene) = &self.scene {
            writeln!(
                out,
                "scene {} up={}",
                quote(&scene.path.display().to_string()),
                scene.up.unwrap_or_default().name()
            )?;
            return self.write_view(out);
        }
        write!(
            out,
            "db {} seed={} gaussians-per-avatar={} sources={}",
            quote(&self.db),
            self.seed,
            self.gaussians_per_avatar,
            self.sources
        )?;
        if let Some((model, masks)) = &self.flame {
            write!(
                out,
                " flame={} masks={}",
                quote(&model.display().to_string()),
                quote(&masks.display().to_string())
            )?;
        }
        writeln!(out)?;
        self.write_view(out)
    }

    /// The header lines after the subject.
    fn write_view(&self, out: &mut impl Write) -> std::io::Result<()> {
        writeln!(out, "terminal {}x{}", self.terminal.0, self.terminal.1)?;
        writeln!(out, "graphics {}", self.graphics.name())?;
        writeln!(out, "render {}x{}", self.render.0, self.render.1)?;
        // Left out when off: such headers read as before.
        if self.post != PostPreset::Off {
            writeln!(out, "post {}", self.post.name())?;
        }
        writeln!(out, "---")
    }
}

/// A check in a session file.
#[derive(Clone, Debug, PartialEq)]
pub enum Expectation {
    /// The composite's state hash equals this.
    StateHash(String),
    /// The view matches a stored PNG (relative to the session file) within a PSNR.
    Image {
        /// Stored image.
        path: PathBuf,
        /// Smallest PSNR accepted, in dB.
        min_psnr: f64,
    },
}

/// What a session line does.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    /// Run a command.
    Command(Command),
    /// Check something.
    Expect(Expectation),
}

/// One line of a session body.
#[derive(Clone, Debug, PartialEq)]
pub struct SessionLine {
    /// Logical tick at which it runs.
    pub tick: u64,
    /// What it does.
    pub action: Action,
    /// Line number in the file (for messages).
    pub line: usize,
}

/// A parsed session file.
#[derive(Clone, Debug, PartialEq)]
pub struct Session {
    /// Header.
    pub header: SessionHeader,
    /// Body lines, ticks non-decreasing.
    pub lines: Vec<SessionLine>,
}

fn size(text: &str, what: &str, line: usize, name: &str) -> Result<(u32, u32)> {
    let bad = || {
        Error::input(format!(
            "{name}:{line}: {what} must be WxH, not '{}'",
            crate::text::printable(text)
        ))
    };
    let (w, h) = text.split_once('x').ok_or_else(bad)?;
    let w: u32 = w.parse().map_err(|_| bad())?;
    let h: u32 = h.parse().map_err(|_| bad())?;
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}

impl Session {
    /// Reads a session file.
    pub fn load(path: &Path) -> Result<Session> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read session {}: {e}", path.display())))?;
        Session::parse(&text, &path.display().to_string())
    }

    /// Reads a journal, which a kill may have cut in the middle of its last
    /// line: that line (without its newline) is dropped. Returns the session
    /// and the length in bytes of its whole lines.
    pub fn load_journal(path: &Path) -> Result<(Session, u64)> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read session {}: {e}", path.display())))?;
        let whole = if text.ends_with('\n') {
            text.len()
        } else {
            text.rfind('\n').map_or(0, |i| i + 1)
        };
        let session = Session::parse(&text[..whole], &path.display().to_string())?;
        Ok((session, whole as u64))
    }

    /// Edits (and undos or redos) after the last `save-recipe`: what quitting
    /// now would lose.
    pub fn unsaved_edits(&self) -> usize {
        let mut count = 0;
        for line in &self.lines {
            if let Action::Command(c) = &line.action {
                match c {
                    Command::SaveRecipe(_) => count = 0,
                    Command::Undo | Command::Redo => count += 1,
                    c if c.is_edit() => count += 1,
                    _ => {}
                }
            }
        }
        count
    }

    /// Parses session text; `name` labels errors (`name:line: problem`).
    pub fn parse(text: &str, name: &str) -> Result<Session> {
        let err = |line: usize, msg: String| Error::input(format!("{name}:{line}: {msg}"));
        let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
        match lines.next() {
            Some((_, l)) if l == format!("visage-session {SESSION_VERSION}") => {}
            Some((n, l)) if l.starts_with("visage-session ") => {
                return Err(err(
                    n,
                    format!(
                    "session version '{}' is not supported (this build reads {SESSION_VERSION})",
                    crate::text::printable(&l[15..])
                ),
                ))
            }
            _ => {
                return Err(err(
                    1,
                    "not a visage session (first line must be 'visage-session 1')".into(),
                ))
            }
        }
        let mut header = SessionHeader {
            db: "builtin".into(),
            seed: 1,
            gaussians_per_avatar: 50_000,
            sources: crate::avatar::synthetic::MAX_SOURCES,
            flame: None,
            scene: None,
            terminal: (120, 40),
            graphics: Protocol::Halfblocks,
            render: (160, 120),
            post: PostPreset::Off,
        };
        let mut body = false;
        let mut out = Vec::new();
        let mut last_tick = 0u64;
        for (n, l) in lines {
            if l.is_empty() || l.starts_with('#') {
                continue;
            }
            if !body {
                let (key, rest) = l.split_once(' ').unwrap_or((l, ""));
                let unknown = |what: &str, choices: &str| {
                    err(
                        n,
                        format!("unknown {what} '{}'{choices}", crate::text::printable(rest)),
                    )
                };
                match key {
                    "---" => body = true,
                    "db" => {
                        let words = header_words(rest).map_err(|e| err(n, e))?;
                        let mut words = words.iter();
                        header.db = words
                            .next()
                            .ok_or_else(|| err(n, "db needs a name".into()))?
                            .to_string();
                        let (mut flame, mut masks) = (None, None);
                        for kv in words {
                            let (k, v) = kv.split_once('=').ok_or_else(|| {
                                err(
                                    n,
                                    format!("'{}' is not key=value", crate::text::printable(kv)),
                                )
                            })?;
                            let bad = || {
                                err(
                                    n,
                                    format!("bad value '{}' for {k}", crate::text::printable(v)),
                                )
                            };
                            match k {
                                "seed" => header.seed = v.parse().map_err(|_| bad())?,
                                "gaussians-per-avatar" => {
                                    header.gaussians_per_avatar = v.parse().map_err(|_| bad())?
                                }
                                "sources" => header.sources = v.parse().map_err(|_| bad())?,
                                "flame" => flame = Some(PathBuf::from(v)),
                                "masks" => masks = Some(PathBuf::from(v)),
                                _ => {
                                    return Err(err(
                                        n,
                                        format!(
                                            "unknown db option '{}'",
                                            crate::text::printable(k)
                                        ),
                                    ))
                                }
                            }
                        }
                        header.flame = match (flame, masks) {
                            (Some(f), Some(m)) => Some((f, m)),
                            (None, None) => None,
                            _ => {
                                return Err(err(
                                    n,
                                    "db options flame= and masks= go together".into(),
                                ))
                            }
                        };
                    }
                    "scene" => header.scene = Some(parse_scene(rest).map_err(|e| err(n, e))?),
                    "terminal" => {
                        let (w, h) = size(rest, "terminal", n, name)?;
                        header.terminal =
                            (w.min(u16::MAX as u32) as u16, h.min(u16::MAX as u32) as u16);
                    }
                    "graphics" => {
                        header.graphics = Protocol::from_name(rest.trim())
                            .ok_or_else(|| unknown("graphics protocol", ""))?
                    }
                    "render" => header.render = size(rest, "render", n, name)?,
                    "post" => {
                        header.post = PostPreset::from_name(rest.trim())
                            .ok_or_else(|| unknown("post-processing", " (off, thesis or ours)"))?
                    }
                    _ => {
                        return Err(err(
                            n,
                            format!("unknown header line '{}'", crate::text::printable(l)),
                        ))
                    }
                }
                continue;
            }
            let (tick, rest) = l
                .split_once(' ')
                .ok_or_else(|| err(n, "expected 'TICK COMMAND'".into()))?;
            let tick: u64 = tick.parse().map_err(|_| {
                err(
                    n,
                    format!("'{}' is not a tick number", crate::text::printable(tick)),
                )
            })?;
            if tick < last_tick {
                return Err(err(
                    n,
                    format!("tick {tick} goes back in time (previous line: {last_tick})"),
                ));
            }
            last_tick = tick;
            let action = if let Some(what) = rest.strip_prefix("expect ") {
                Action::Expect(parse_expectation(what).map_err(|e| err(n, e))?)
            } else {
                Action::Command(Command::parse(rest).map_err(|e| err(n, e))?)
            };
            out.push(SessionLine {
                tick,
                action,
                line: n,
            });
        }
        if !body {
            return Err(err(
                1,
                "the header never ends: add a '---' line before the commands".into(),
            ));
        }
        Ok(Session { header, lines: out })
    }
}

/// Reads `PATH [up=AXIS]` of a `scene` header line.
fn parse_scene(rest: &str) -> std::result::Result<SceneSpec, String> {
    let words = header_words(rest)?;
    let mut words = words.iter();
    let path = PathBuf::from(words.next().ok_or("scene needs a file")?);
    let mut up = UpAxis::default();
    for kv in words {
        let axis = kv
            .strip_prefix("up=")
            .ok_or_else(|| format!("unknown scene option '{}'", crate::text::printable(kv)))?;
        up = UpAxis::parse(axis).ok_or_else(|| {
            format!(
                "up axis '{}' is not one of +y, -y, +z, -z",
                crate::text::printable(axis)
            )
        })?;
    }
    Ok(SceneSpec {
        path,
        up: Some(up),
        memory_budget: None,
    })
}

fn parse_expectation(text: &str) -> std::result::Result<Expectation, String> {
    let mut words = text.split_whitespace();
    match words.next() {
        Some("state-hash") => {
            let h = words.next().ok_or("expect state-hash needs a hash")?;
            if words.next().is_some() {
                return Err("expect state-hash takes one hash".into());
            }
            Ok(Expectation::StateHash(h.to_string()))
        }
        Some("image") => {
            let path = PathBuf::from(words.next().ok_or("expect image needs a PNG path")?);
            let mut min_psnr = 40.0;
            for w in words {
                let v = w.strip_prefix("psnr>=").ok_or_else(|| {
                    format!("unknown option '{}' (psnr>=DB)", crate::text::printable(w))
                })?;
                min_psnr = v
                    .parse()
                    .map_err(|_| format!("'{}' is not a PSNR", crate::text::printable(v)))?;
            }
            Ok(Expectation::Image { path, min_psnr })
        }
        _ => Err("expect takes 'state-hash HASH' or 'image FILE [psnr>=DB]'".into()),
    }
}

/// Journals commands into a session file, one synced line each, holding an
/// exclusive lock on the file while it records (a second editor recording the
/// same file is refused rather than interleaved).
pub struct Recorder {
    file: File,
    path: PathBuf,
}

impl Recorder {
    /// Starts a new journal at `path` with `header`, seeded with the commands
    /// of `seed` (a session replayed before recording began, so that the
    /// journal replays to what the screen shows). Refuses a file that already
    /// holds a session: continuing one is [`Recorder::append`].
    pub fn create(path: &Path, header: &SessionHeader, seed: &[SessionLine]) -> Result<Recorder> {
        if std::fs::metadata(path).is_ok_and(|m| m.len() > 0) {
            return Err(Error::input(format!(
                "{} already holds a session: continue it with --record {0} alone, or record into a new file",
                path.display()
            )));
        }
        let file = OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| Error::input(format!("cannot record to {}: {e}", path.display())))?;
        let mut recorder = Recorder::locked(file, path)?;
        let mut text = Vec::new();
        header
            .write(&mut text)
            .expect("writing into memory cannot fail");
        for line in seed {
            if let Action::Command(c) = &line.action {
                if c.journalled() {
                    writeln!(text, "{} {c}", line.tick).expect("writing into memory cannot fail");
                }
            }
        }
        recorder
            .file
            .write_all(&text)
            .and_then(|_| recorder.file.sync_data())
            .map_err(|e| Error::input(format!("cannot record to {}: {e}", path.display())))?;
        Ok(recorder)
    }

    /// Continues the journal at `path`: reads it (a last line cut short by a
    /// kill is dropped from the file) and returns it with a recorder that
    /// appends after it.
    pub fn append(path: &Path) -> Result<(Recorder, Session)> {
        let file = OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .map_err(|e| Error::input(format!("cannot record to {}: {e}", path.display())))?;
        let mut recorder = Recorder::locked(file, path)?;
        let (session, whole) = Session::load_journal(path)?;
        let io =
            |e: std::io::Error| Error::input(format!("cannot record to {}: {e}", path.display()));
        recorder.file.set_len(whole).map_err(io)?;
        std::io::Seek::seek(&mut recorder.file, std::io::SeekFrom::End(0)).map_err(io)?;
        Ok((recorder, session))
    }

    fn locked(file: File, path: &Path) -> Result<Recorder> {
        use std::os::fd::AsRawFd;
        // SAFETY: flock on a file descriptor this function owns through `file`.
        let locked = unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0;
        if !locked {
            return Err(Error::input(format!(
                "{} is being recorded by another visage: record into another file",
                path.display()
            )));
        }
        Ok(Recorder {
            file,
            path: path.to_path_buf(),
        })
    }

    /// The journal's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Journals a command run at `tick` and syncs it to disk.
    pub fn record(&mut self, tick: u64, command: &Command) -> std::io::Result<()> {
        writeln!(self.file, "{tick} {command}")?;
        self.file.flush()?;
        self.file.sync_data()
    }

    /// Marks the journal as ended by the user (`# closed REASON`): the next
    /// start does not offer to recover it.
    pub fn close(mut self, reason: &str) -> std::io::Result<()> {
        writeln!(self.file, "{CLOSED_MARK} {reason}")?;
        self.file.sync_data()
    }
}

/// The comment that ends a journal the user closed.
pub const CLOSED_MARK: &str = "# closed";

/// Whether a journal's last line says the user closed it.
pub fn is_closed(text: &str) -> bool {
    text.lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .is_some_and(|l| l.trim_start().starts_with(CLOSED_MARK))
}

/// A header value as written: bare, or in double quotes (with `\"` and `\\`)
/// when it is empty or holds whitespace, quotes or backslashes.
fn quote(value: &str) -> String {
    if !value.is_empty()
        && !value
            .chars()
            .any(|c| c.is_whitespace() || c == '"' || c == '\\')
    {
        return value.to_string();
    }
    let mut out = String::from("\"");
    for c in value.chars() {
        if c == '"' || c == '\\' {
            out.push('\\');
        }
        out.push(c);
    }
    out.push('"');
    out
}

/// Splits a header line into words; double quotes (anywhere in a word) protect
/// whitespace, and a backslash inside them escapes the next character.
fn header_words(line: &str) -> std::result::Result<Vec<String>, String> {
    let mut words = Vec::new();
    let mut word: Option<String> = None;
    let mut quoted = false;
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' => {
                quoted = !quoted;
                word.get_or_insert_with(String::new);
            }
            '\\' if quoted => {
                let next = chars.next().ok_or("a backslash ends the line")?;
                word.get_or_insert_with(String::new).push(next);
            }
            c if c.is_whitespace() && !quoted => words.extend(word.take()),
            c => word.get_or_insert_with(String::new).push(c),
        }
    }
    if quoted {
        return Err("a quoted value is not closed".into());
    }
    words.extend(word);
    Ok(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recorded_sessions_parse_back() {
        let path = std::env::temp_dir().join(format!("visage-session-{}.vsg", std::process::id()));
        std::fs::remove_file(&path).ok();
        let header = SessionHeader::new(&DatabaseSpec::default(), (100, 30), Protocol::Kitty);
        let mut r = Recorder::create(&path, &header, &[]).unwrap();
        r.record(0, &Command::parse("set-gaussians nose bram").unwrap())
            .unwrap();
        r.record(7, &Command::Play).unwrap();
        // A second recorder on the same file is refused while the first holds it.
        let e = Recorder::append(&path).err().unwrap().to_string();
        assert!(e.contains("being recorded by another visage"), "{e}");
        drop(r);
        // Creating over a session is refused; appending keeps the header and adds lines.
        let e = Recorder::create(&path, &header, &[])
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("already holds a session"), "{e}");
        let (mut r, before) = Recorder::append(&path).unwrap();
        assert_eq!(before.lines.len(), 2);
        r.record(9, &Command::Pause).unwrap();
        r.close("quit").unwrap();
        let s = Session::load(&path).unwrap();
        assert!(is_closed(&std::fs::read_to_string(&path).unwrap()));
        assert_eq!(s.header, header);
        assert_eq!(s.lines.len(), 3);
        assert_eq!(s.lines[1].tick, 7);
        assert_eq!(s.lines[2].action, Action::Command(Command::Pause));
        // A line cut short by a kill is dropped, and appending starts after
        // the last whole line.
        let mut f = OpenOptions::new().append(true).open(&path).unwrap();
        f.write_all(b"12 set-gaussians ey").unwrap();
        drop(f);
        let (mut r, cut) = Recorder::append(&path).unwrap();
        assert_eq!(cut.lines.len(), 3);
        r.record(14, &Command::Play).unwrap();
        drop(r);
        let s = Session::load(&path).unwrap();
        assert_eq!(s.lines.len(), 4);
        assert_eq!(s.lines[3].action, Action::Command(Command::Play));
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn folder_databases_with_flame_files_and_odd_paths_parse_back() {
        let db = DatabaseSpec {
            db: "/data/my avatars".into(),
            flame: Some("/models/flame \"2023\".pkl".into()),
            masks: Some("relative/FLAME_masks.pkl".into()),
            ..DatabaseSpec::default()
        };
        let header = SessionHeader::new(&db, (80, 24), Protocol::Sixel);
        let mut text = Vec::new();
        header.write(&mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("db \"/data/my avatars\" "), "{text}");
        let back = Session::parse(&text, "s.vsg").unwrap().header;
        assert_eq!(back, header);
        let (model, masks) = back.flame.unwrap();
        assert_eq!(model, Path::new("/models/flame \"2023\".pkl"));
        assert!(masks.is_absolute() && masks.ends_with("relative/FLAME_masks.pkl"));
        let e = Session::parse("visage-session 1\ndb /d flame=/f.pkl\n---\n", "s.vsg")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains(":2: db options flame= and masks= go together"),
            "{e}"
        );
        let e = Session::parse("visage-session 1\ndb \"/d\n---\n", "s.vsg")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not closed"), "{e}");
    }

    /// A scene view's header names the file (absolute, quoted when it has
    /// spaces) and its up axis, and reads back as the same subject.
    #[test]
    fn scene_headers_parse_back() {
        let subject = Subject::Scene(SceneSpec {
            path: "my scans/garden.ply".into(),
            up: Some(UpAxis::NegY),
            memory_budget: None,
        });
        let header = SessionHeader::for_subject(&subject, (90, 30), Protocol::Kitty);
        let mut text = Vec::new();
        header.write(&mut text).unwrap();
        let text = String::from_utf8(text).unwrap();
        assert!(text.contains("garden.ply\" up=-y\n"), "{text}");
        assert!(!text.contains("\ndb "), "{text}");
        let back = Session::parse(&text, "s.vsg").unwrap().header;
        assert_eq!(back, header);
        let Subject::Scene(scene) = back.subject() else {
            panic!("a scene header opens a scene");
        };
        assert!(scene.path.is_absolute() && scene.path.ends_with("my scans/garden.ply"));
        assert_eq!(scene.up, Some(UpAxis::NegY));
    }

    /// The post-processing a session starts from reads back; a header
    /// without a `post` line (every session before session 27) starts from
    /// none (an unknown name is among the malformed sessions below).
    #[test]
    fn the_post_processing_a_session_starts_from_parses_back() {
        let mut header = SessionHeader::new(&DatabaseSpec::default(), (80, 24), Protocol::Sixel);
        assert_eq!(header.post, PostPreset::Off);
        for post in PostPreset::ALL {
            header.post = post;
            let mut text = Vec::new();
            header.write(&mut text).unwrap();
            let text = String::from_utf8(text).unwrap();
            assert_eq!(text.contains("\npost "), post != PostPreset::Off, "{text}");
            assert_eq!(Session::parse(&text, "s.vsg").unwrap().header, header);
        }
        let old = Session::parse("visage-session 1\nrender 64x48\n---\n", "s.vsg").unwrap();
        assert_eq!(old.header.post, PostPreset::Off);
    }

    #[test]
    fn malformed_sessions_name_the_line() {
        let cases = [
            ("hello\n", ":1:"),
            ("visage-session 2\n---\n", "version"),
            ("visage-session 1\nterminal big\n---\n", ":2:"),
            (
                "visage-session 1\npost warm\n---\n",
                ":2: unknown post-processing 'warm' (off, thesis or ours)",
            ),
            (
                "visage-session 1\n---\n3 play\n1 pause\n",
                ":4: tick 1 goes back",
            ),
            ("visage-session 1\n---\n0 soar\n", ":3: unknown command"),
            ("visage-session 1\nscene\n---\n", ":2: scene needs a file"),
            (
                "visage-session 1\nscene a.ply up=x\n---\n",
                ":2: up axis 'x' is not",
            ),
            (
                "visage-session 1\nscene a.ply fov=3\n---\n",
                ":2: unknown scene option",
            ),
            ("visage-session 1\n---\nsoon play\n", ":3:"),
            (
                "visage-session 1\n---\n0 expect image a.png psnr>=x\n",
                ":3:",
            ),
            ("visage-session 1\ndb builtin\n", "never ends"),
        ];
        for (text, needle) in cases {
            let e = Session::parse(text, "s.vsg").unwrap_err().to_string();
            assert!(e.contains(needle), "{text:?}: {e}");
            assert!(!e.contains('\n'));
        }
    }
}
