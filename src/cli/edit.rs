//! `visage` / `visage edit` (the editor) and `visage replay` (headless sessions).

use std::path::PathBuf;

use clap::Args;

use super::camera::CameraArgs;
use super::DbArgs;
use crate::editor::command::Command;
use crate::editor::replay::replay;
use crate::error::{Error, Result};
use crate::render::Backend;
use crate::tui::app::{run_editor, EditOptions};
use crate::tui::graphics::GraphicsChoice;

/// Arguments of the editor.
#[derive(Args, Debug, Clone, Default)]
pub struct EditArgs {
    #[command(flatten)]
    db: DbArgs,
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

/// Runs the editor.
pub fn run_edit(args: &EditArgs) -> Result<()> {
    use std::io::IsTerminal;
    let overrides = args.camera.overrides()?;
    if !std::io::stdout().is_terminal() || !std::io::stdin().is_terminal() {
        return Err(Error::input(
            "the editor needs a terminal; for scripts use 'visage replay SESSION' or 'visage render'",
        ));
    }
    run_editor(EditOptions {
        db: args.db.spec(),
        session: args.session.clone(),
        record: args.record.clone(),
        keymap: args.keymap.clone(),
        graphics: args.graphics,
        renderer: args.renderer,
        initial: if overrides.is_empty() {
            Vec::new()
        } else {
            vec![Command::SetCamera(overrides)]
        },
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
