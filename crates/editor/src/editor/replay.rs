//! Headless replay of session files: the same state updates as the editor, on
//! logical ticks, with snapshots and expectation checks. Deterministic: the CPU
//! renderer draws the images and nothing depends on wall-clock time.

use std::path::Path;

use serde::Serialize;

use super::session::{Action, Expectation, Session};
use super::state::Effect;
use super::{inside, perform, Editor};
use crate::error::{Error, Result};
use crate::render::image::{psnr_report, RgbImage};
use crate::render::Backend;

/// Applies a session's commands to an editor without rendering (to resume
/// editing). Returns the number of commands that failed.
pub fn replay_commands(session: &Session, editor: &mut Editor) -> usize {
    let mut failed = 0;
    for line in &session.lines {
        editor.advance_to(line.tick);
        if let Action::Command(c) = &line.action {
            if editor.step(c).is_err() {
                failed += 1;
            }
        }
    }
    failed
}

/// One checked expectation.
#[derive(Clone, Debug, Serialize)]
pub struct CheckResult {
    /// Session line.
    pub line: usize,
    /// Tick.
    pub tick: u64,
    /// "state-hash" or "image".
    pub kind: &'static str,
    /// What was expected.
    pub expected: String,
    /// What was found.
    pub actual: String,
    /// Whether it held.
    pub ok: bool,
}

/// The outcome of a replay.
#[derive(Clone, Debug, Serialize)]
pub struct ReplayReport {
    /// Session file.
    pub session: String,
    /// Last tick reached.
    pub ticks: u64,
    /// Commands run.
    pub commands: usize,
    /// Commands that failed (with their line and reason).
    pub failures: Vec<String>,
    /// Checks.
    pub checks: Vec<CheckResult>,
    /// Snapshot files written.
    pub snapshots: Vec<String>,
    /// State hash at the end.
    pub state_hash: String,
}

impl ReplayReport {
    /// True when every command ran and every check held.
    pub fn passed(&self) -> bool {
        self.failures.is_empty() && self.checks.iter().all(|c| c.ok)
    }
}

/// Replays a session file. `out` receives snapshots and exports (skipped without it).
pub fn replay(path: &Path, out: Option<&Path>) -> Result<ReplayReport> {
    let session = Session::load(path)?;
    let mut workbench = session.header.subject().open(Backend::Cpu, &|_, _| {})?;
    let mut editor = Editor::for_workbench(&workbench);
    editor.start_from(session.header.post);
    if let Some(dir) = out {
        std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
    }
    let base_dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let (w, h) = session.header.render;
    let mut report = ReplayReport {
        session: path.display().to_string(),
        ticks: 0,
        commands: 0,
        failures: Vec::new(),
        checks: Vec::new(),
        snapshots: Vec::new(),
        state_hash: String::new(),
    };
    for line in &session.lines {
        editor.advance_to(line.tick);
        let tick = editor.tick();
        match &line.action {
            Action::Command(c) => {
                report.commands += 1;
                match editor.step(c) {
                    Ok(applied) => {
                        let Some(dir) = out else { continue };
                        for effect in applied.effects {
                            let view = editor.frame_request(w, h, true);
                            let done = perform(
                                &effect,
                                &editor.state.recipe,
                                &view,
                                &mut workbench,
                                &inside(dir),
                            )
                            .map_err(|e| {
                                Error::input(format!("{}:{}: {e}", path.display(), line.line))
                            })?;
                            if matches!(effect, Effect::Snapshot(..)) {
                                report.snapshots.push(done.path.display().to_string());
                            }
                        }
                    }
                    Err(e) => report
                        .failures
                        .push(format!("line {}: {c}: {e}", line.line)),
                }
            }
            Action::Expect(Expectation::StateHash(expected)) => {
                let actual = workbench.state_hash(&editor.state.recipe)?;
                report.checks.push(CheckResult {
                    line: line.line,
                    tick,
                    kind: "state-hash",
                    expected: expected.clone(),
                    ok: &actual == expected,
                    actual,
                });
            }
            Action::Expect(Expectation::Image {
                path: image,
                min_psnr,
            }) => {
                let stored = RgbImage::load_png(&base_dir.join(image)).map_err(Error::input)?;
                // The finished composite, seam fit included: what a still shows.
                workbench.settle(&editor.state.recipe)?;
                let frame =
                    workbench.render(&editor.frame_request(stored.width, stored.height, true))?;
                let p = psnr_report(&frame.image, &stored).unwrap_or(0.0);
                report.checks.push(CheckResult {
                    line: line.line,
                    tick,
                    kind: "image",
                    expected: format!("{} psnr>={min_psnr}", image.display()),
                    actual: format!("psnr {p:.2}"),
                    ok: p >= *min_psnr,
                });
            }
        }
    }
    report.ticks = editor.tick();
    report.state_hash = workbench.state_hash(&editor.state.recipe)?;
    Ok(report)
}
