//! Opening a live session, before the terminal is taken over (so bad input
//! fails with one line): the keymap, the subject — the one the command line
//! names, else that of the journal being continued or the session resumed —
//! the offer to recover an unsaved session, the journal to record into, and
//! the commands replayed from it.

use std::path::PathBuf;

use super::graphics::{detect, GraphicsChoice, TerminalGraphics};
use super::keymap::Keymap;
use super::terminal::ask_yes_no;
use crate::compose::recipe::PostPreset;
use crate::editor::command::Command;
use crate::editor::journal::{choose_subject, open_journal, JournalFolder, KEEP_JOURNALS};
use crate::editor::replay::replay_commands;
use crate::editor::session::{Recorder, Session, SessionHeader};
use crate::editor::Editor;
use crate::error::Result;
use crate::pipeline::workbench::{check_parent, Workbench};
use crate::pipeline::{SceneSpec, Subject};
use crate::render::Backend;

/// Options of `visage edit` and `visage view`.
#[derive(Clone, Debug)]
pub struct EditOptions {
    /// The database or scene the command line named (`None`: the journal's
    /// or resumed session's own, else the built-in database).
    pub subject: Option<Subject>,
    /// Session to resume.
    pub session: Option<PathBuf>,
    /// Journal to record to.
    pub record: Option<PathBuf>,
    /// Extra keymap layer.
    pub keymap: Option<PathBuf>,
    /// Graphics protocol choice.
    pub graphics: GraphicsChoice,
    /// Renderer.
    pub renderer: Backend,
    /// Commands run (and journalled) before the first key, e.g. the camera
    /// the command line asked for.
    pub initial: Vec<Command>,
}

/// What a live session starts with.
pub struct Launched {
    /// The subject, opened.
    pub workbench: Workbench,
    /// The editor, with the journal or resumed session replayed into it.
    pub editor: Editor,
    /// The journal it records into.
    pub recorder: Option<Recorder>,
    /// The journal is one of the state folder's.
    pub auto_journal: bool,
    /// What the status line says first.
    pub status: String,
    /// Edits the replayed journal holds after its last saved recipe.
    pub unsaved: usize,
    /// The session's render size (snapshots).
    pub render_size: (u32, u32),
    /// The keys for the subject (the editor's or the viewer's).
    pub keymap: Keymap,
    /// The terminal's graphics.
    pub graphics: TerminalGraphics,
}

/// Everything before the terminal is taken over, where bad input fails: the
/// keymap, the journal to continue (or the unsaved one to offer), the
/// subject opened, the journal opened and replayed.
pub fn launch(options: &EditOptions) -> Result<Launched> {
    // Everything that can fail on bad input fails before the terminal changes.
    let keymap = Keymap::load(options.keymap.as_deref())?;
    if let Some(r) = &options.record {
        check_parent(r)?;
    }
    let recorded = recorded_session(options)?;
    let mut subject = choose_subject(options.subject.as_ref(), recorded.as_ref())?;
    let journals = JournalFolder::in_state_dir();
    let recovered = match (&options.record, &options.session, &journals) {
        (None, None, Ok(folder)) => offer_recovery(folder, &subject),
        _ => None,
    };
    if let Some(r) = &recovered {
        subject = r.1.clone();
    }
    let keymap = match subject {
        Subject::Avatars(_) => keymap,
        Subject::Scene(_) => Keymap::load_viewer(options.keymap.as_deref())?,
    };
    eprintln!("visage: opening {}…", subject.describe());
    let workbench = open_with_progress(&subject, options.renderer)?;
    let subject = resolved_subject(subject, &workbench);
    let graphics = detect(options.graphics);
    let size = crossterm::terminal::size().unwrap_or((120, 40));
    let mut header = SessionHeader::for_subject(&subject, size, graphics.protocol);
    if let Subject::Avatars(_) = subject {
        // A new session starts from what measured best (README, ground
        // truth); one continued or resumed starts from what it recorded.
        header.post = PostPreset::Ours;
    }

    let mut status = String::new();
    let (recorder, replayed, auto) = match (&options.record, &recovered, &journals) {
        (Some(record), _, _) => {
            let (r, s) = open_journal(record, options.session.as_deref(), &header)?;
            (Some(r), s, false)
        }
        (None, Some((path, _)), _) => {
            let (r, s) = open_journal(path, None, &header)?;
            (Some(r), s, true)
        }
        (None, None, Ok(folder)) => {
            folder.prune(KEEP_JOURNALS);
            match open_journal(
                &folder.new_journal_path(),
                options.session.as_deref(),
                &header,
            ) {
                Ok((r, s)) => (Some(r), s, true),
                Err(e) => {
                    status = format!("not journalling this session: {e}");
                    (
                        None,
                        options.session.as_deref().map(Session::load).transpose()?,
                        false,
                    )
                }
            }
        }
        (None, None, Err(e)) => {
            status = format!("not journalling this session: {e}");
            (
                None,
                options.session.as_deref().map(Session::load).transpose()?,
                false,
            )
        }
    };
    let mut editor = Editor::for_workbench(&workbench);
    editor.start_from(replayed.as_ref().map_or(header.post, |s| s.header.post));
    let mut unsaved = 0;
    let mut render_size = header.render;
    if let Some(session) = &replayed {
        let failed = replay_commands(session, &mut editor);
        unsaved = session.unsaved_edits();
        render_size = session.header.render;
        status = format!(
            "resumed {} commands at tick {}{}",
            session.lines.len(),
            editor.tick(),
            if failed > 0 {
                format!(" ({failed} failed)")
            } else {
                String::new()
            }
        );
    }
    Ok(Launched {
        workbench,
        editor,
        recorder,
        auto_journal: auto,
        status,
        unsaved,
        render_size,
        keymap,
        graphics,
    })
}

/// The session a live session starts from, read to learn its subject: the
/// journal being continued, else the session being resumed.
fn recorded_session(options: &EditOptions) -> Result<Option<Session>> {
    if let Some(record) = options.record.as_deref() {
        if std::fs::metadata(record).is_ok_and(|m| m.len() > 0) {
            return Ok(Some(Session::load_journal(record)?.0));
        }
    }
    options.session.as_deref().map(Session::load).transpose()
}

/// Offers the newest journal of `subject` that was not closed and holds
/// unsaved edits; returns its path and subject when the user takes it. A
/// declined journal is closed, so it is not offered again.
fn offer_recovery(folder: &JournalFolder, subject: &Subject) -> Option<(PathBuf, Subject)> {
    let newest = folder.unfinished(subject).into_iter().next()?;
    if ask_yes_no(&format!("visage: {}: resume it?", newest.describe())) {
        let subject = newest.session.header.subject();
        return Some((newest.path, subject));
    }
    if let Ok((recorder, _)) = crate::editor::session::Recorder::append(&newest.path) {
        let _ = recorder.close("declined");
    }
    None
}

/// The subject as opened: a scene's up axis as detected, so the journal
/// replays with the same camera.
fn resolved_subject(subject: Subject, workbench: &Workbench) -> Subject {
    match (subject, workbench.scene()) {
        (Subject::Scene(spec), Some(viewed)) => Subject::Scene(SceneSpec {
            up: Some(viewed.home.up),
            ..spec
        }),
        (subject, _) => subject,
    }
}

/// Opens the subject, with a progress bar on standard error while a scene
/// file loads (big scenes take a while to read from a slow disk) and for
/// each stage of a cache build; the bar fills the terminal's width, so it
/// never wraps at 80 columns.
fn open_with_progress(subject: &Subject, renderer: Backend) -> Result<Workbench> {
    let bar = indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} [{wide_bar}] {bytes}/{total_bytes}, {eta} left",
        )
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    let progress = |done: u64, all: u64| {
        bar.set_length(all);
        bar.set_position(done);
    };
    let workbench = subject.open(renderer, &progress);
    bar.finish_and_clear();
    workbench
}
