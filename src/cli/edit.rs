//! `visage` / `visage edit` (the editor) and `visage replay` (headless sessions).

use std::path::PathBuf;

use clap::Args;

use super::camera::CameraArgs;
use super::DbArgs;
use crate::editor::command::Command;
use crate::editor::replay::replay;
use crate::error::{Error, Result};
use crate::pipeline::lod::parse_memory_budget;
use crate::pipeline::{SceneSpec, Subject};
use crate::render::lod::LodPolicy;
use crate::render::Backend;
use crate::tui::app::run_editor;
use crate::tui::graphics::GraphicsChoice;
use crate::tui::launch::EditOptions;

/// What the editor and the viewer share: sessions, keys, graphics, renderer
/// and the starting camera.
#[derive(Args, Debug, Clone, Default)]
pub struct TerminalArgs {
    /// Resume a recorded session (replays it, then continues).
    #[arg(long, value_name = "FILE")]
    session: Option<PathBuf>,
    /// Journal every command to this session file as it runs.
    #[arg(long, value_name = "FILE")]
    record: Option<PathBuf>,
    /// A keymap layer applied over the default and the user's config.
    #[arg(long, value_name = "FILE")]
    keymap: Option<PathBuf>,
    /// Terminal graphics protocol.
    #[arg(long, value_enum, default_value_t = GraphicsChoice::Auto)]
    graphics: GraphicsChoice,
    /// Renderer: auto (hardware GPU, else CPU), gpu (wgpu on any adapter) or cpu.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Starting camera (run as a `set-camera` command, so sessions record it).
    #[command(flatten)]
    camera: CameraArgs,
}

/// Arguments of the editor.
#[derive(Args, Debug, Clone, Default)]
pub struct EditArgs {
    #[command(flatten)]
    db: DbArgs,
    /// A 3DGS scene file (.ply, .compressed.ply, .splat, .spz) to view instead of
    /// composing avatars: the same as `visage view FILE`.
    #[arg(value_name = "SCENE")]
    scene: Option<PathBuf>,
    #[command(flatten)]
    terminal: TerminalArgs,
}

/// Arguments of `visage view`.
#[derive(Args, Debug, Clone)]
pub struct ViewArgs {
    /// A 3DGS scene: INRIA PLY (any SH degree, ASCII or binary), SuperSplat's
    /// compressed PLY, a .splat file or Niantic's SPZ (versions 2-4).
    file: PathBuf,
    /// Level of detail: auto (a hierarchy's nodes of at most 1.5 px where
    /// the scene holds more than 4 Gaussians a pixel), off (every Gaussian)
    /// or a budget of Gaussians drawn (e.g. 300k). The `lod` command
    /// changes it while viewing.
    #[arg(long, default_value = "auto", value_parser = LodPolicy::parse)]
    lod: LodPolicy,
    /// Draw the scene from its level-of-detail cache within this much
    /// memory (e.g. 1G; built first where missing). Files of 1 GiB or more
    /// always are, within a quarter of the machine's memory (at most 1.5G)
    /// unless this says otherwise.
    #[arg(long, value_name = "SIZE", value_parser = parse_memory_budget)]
    memory_budget: Option<usize>,
    #[command(flatten)]
    terminal: TerminalArgs,
}

/// Runs the editor (or, given a scene file, the viewer).
pub fn run_edit(args: &EditArgs) -> Result<()> {
    let subject = match &args.scene {
        Some(file) => Some(scene_subject(file, &args.terminal, None)?),
        // The built-in database by default: a journal being continued keeps its own.
        None if args.db.spec() == crate::pipeline::DatabaseSpec::default() => None,
        None => Some(Subject::Avatars(args.db.spec())),
    };
    run_terminal(subject, &args.terminal, Vec::new())
}

/// Runs `visage view FILE`.
pub fn run_view(args: &ViewArgs) -> Result<()> {
    // The default needs no command: a scene view starts with auto.
    let lod = (args.lod != LodPolicy::Auto).then_some(Command::Lod(args.lod));
    run_terminal(
        Some(scene_subject(
            &args.file,
            &args.terminal,
            args.memory_budget,
        )?),
        &args.terminal,
        lod.into_iter().collect(),
    )
}

fn scene_subject(
    file: &std::path::Path,
    args: &TerminalArgs,
    memory_budget: Option<usize>,
) -> Result<Subject> {
    if !file.is_file() {
        return Err(Error::input(format!(
            "{} is not a file (visage view takes a .ply, .compressed.ply, .splat or .spz scene)",
            file.display()
        )));
    }
    Ok(Subject::Scene(SceneSpec {
        path: file.to_path_buf(),
        up: args.camera.overrides()?.up,
        memory_budget,
    }))
}

/// Opens the editor on `subject` with `initial` commands applied after the
/// camera overrides.
fn run_terminal(
    subject: Option<Subject>,
    args: &TerminalArgs,
    initial: Vec<Command>,
) -> Result<()> {
    use std::io::IsTerminal;
    let mut overrides = args.camera.overrides()?;
    if matches!(subject, Some(Subject::Scene(_))) {
        overrides.up = None; // the scene's framed camera has it already
    }
    // Files the user named are checked before the terminal is, so the real
    // problem is the one reported.
    for (flag, file) in [("--session", &args.session), ("--keymap", &args.keymap)] {
        if let Some(f) = file.as_deref().filter(|f| !f.is_file()) {
            return Err(Error::input(format!(
                "{flag} {}: no such file",
                f.display()
            )));
        }
    }
    if let Some(Subject::Avatars(db)) = &subject {
        if db.db != "builtin" && !std::path::Path::new(&db.db).is_dir() {
            return Err(Error::input(format!(
                "database folder {} does not exist",
                db.db
            )));
        }
    }
    crate::tui::keymap::Keymap::load(args.keymap.as_deref())?;
    if let Some(record) = &args.record {
        crate::editor::journal::check_record_and_resume(record, args.session.as_deref())?;
    }
    if !std::io::stdout().is_terminal() || !std::io::stdin().is_terminal() {
        return Err(Error::input(
            "the editor needs a terminal; for scripts use 'visage replay SESSION' or 'visage render'",
        ));
    }
    run_editor(EditOptions {
        subject,
        session: args.session.clone(),
        record: args.record.clone(),
        keymap: args.keymap.clone(),
        graphics: args.graphics,
        renderer: args.renderer,
        initial: (!overrides.is_empty())
            .then_some(Command::SetCamera(overrides))
            .into_iter()
            .chain(initial)
            .collect(),
    })
}

/// Arguments of `visage replay`.
#[derive(Args, Debug, Clone)]
pub struct ReplayArgs {
    /// Session file.
    file: PathBuf,
    /// Folder for snapshots and exports the session asks for.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Exit with code 1 when a command fails or an expectation does not hold.
    #[arg(long)]
    check: bool,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Runs `visage replay`.
pub fn run_replay(args: &ReplayArgs) -> Result<()> {
    let report = replay(&args.file, args.out.as_deref())?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string(&report).expect("report serialises")
        );
    } else {
        println!(
            "replayed {} commands over {} ticks; state hash {}",
            report.commands, report.ticks, report.state_hash
        );
        for f in &report.failures {
            println!("  failed: {}", crate::text::printable(f));
        }
        for c in &report.checks {
            println!(
                "  {} line {} (tick {}): {} expected {}, got {}",
                if c.ok { "ok  " } else { "FAIL" },
                c.line,
                c.tick,
                c.kind,
                c.expected,
                c.actual
            );
        }
        for s in &report.snapshots {
            println!("  wrote {s}");
        }
    }
    if args.check && !report.passed() {
        let failed = report.checks.iter().filter(|c| !c.ok).count();
        return Err(Error::CheckFailed(format!(
            "{}: {failed} expectation(s) did not hold, {} command(s) failed",
            args.file.display(),
            report.failures.len()
        )));
    }
    Ok(())
}
