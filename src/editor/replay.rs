//! Headless replay of session files: the same state updates as the editor, on
//! logical ticks, with snapshots and expectation checks. Deterministic: the CPU
//! renderer draws the images and nothing depends on wall-clock time.

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::session::{Action, Expectation, Session};
use super::state::{Catalog, EditorState, Effect};
use crate::pipeline::workbench::{FrameRequest, Workbench};
use crate::compose::engine::Engine;
use crate::compose::recipe::Recipe;
use crate::error::{Error, Result};
use crate::render::image::{psnr_report, RgbImage};
use crate::render::Backend;

/// The state an editor starts in: the first source, unedited.
pub fn initial_state(catalog: &Catalog) -> EditorState {
    EditorState::new(Recipe::unedited(
        catalog.sources.first().map_or("", String::as_str),
    ))
}

/// The names a database offers the editor.
pub fn catalog_of(engine: &Engine) -> Catalog {
    let db = engine.database();
    Catalog {
        sources: db
            .sources
            .iter()
            .map(|s| crate::text::printable(&s.name))
            .collect(),
        motions: db
            .motions
            .iter()
            .map(|m| (m.name.clone(), m.frames()))
            .collect(),
    }
}

/// Applies a session's commands to a state without rendering (to resume editing).
/// Returns the last tick and the number of commands that failed.
pub fn replay_commands(
    session: &Session,
    catalog: &Catalog,
    state: &mut EditorState,
) -> (u64, usize) {
    let mut tick = 0;
    let mut failed = 0;
    for line in &session.lines {
        while tick < line.tick {
            state.tick(catalog);
            tick += 1;
        }
        if let Action::Command(c) = &line.action {
            if state.apply(catalog, c).is_err() {
                failed += 1;
            }
        }
    }
    state.quit = false;
    state.prompt = None;
    (tick, failed)
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
    let (db, _) = session.header.database().load()?;
    let engine = Engine::new(db)?;
    let catalog = catalog_of(&engine);
    let mut bench = Workbench::new(engine, Backend::Cpu)?;
    let mut state = initial_state(&catalog);
    if let Some(dir) = out {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::input(format!("cannot create {}: {e}", dir.display())))?;
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
    let request = |state: &EditorState| FrameRequest {
        recipe: state.recipe.clone(),
        debug: state.debug,
        group: state.selected_group(),
        width: w,
        height: h,
        exact: true,
    };
    let mut tick = 0u64;
    for line in &session.lines {
        while tick < line.tick {
            state.tick(&catalog);
            tick += 1;
        }
        match &line.action {
            Action::Command(c) => {
                report.commands += 1;
                match state.apply(&catalog, c) {
                    Ok(effects) => {
                        for effect in effects {
                            run_effect(
                                &mut bench,
                                &state,
                                &effect,
                                out,
                                &request(&state),
                                &mut report,
                            )
                            .map_err(|e| {
                                Error::input(format!("{}:{}: {e}", path.display(), line.line))
                            })?;
                        }
                    }
                    Err(e) => report
                        .failures
                        .push(format!("line {}: {c}: {e}", line.line)),
                }
            }
            Action::Expect(Expectation::StateHash(expected)) => {
                let actual = bench.state_hash(&request(&state).recipe)?;
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
                let stored = RgbImage::load_png(&base_dir.join(image))?;
                let frame = bench.render(&FrameRequest {
                    width: stored.width,
                    height: stored.height,
                    ..request(&state)
                })?;
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
    report.ticks = tick;
    report.state_hash = bench.state_hash(&request(&state).recipe)?;
    Ok(report)
}

fn run_effect(
    bench: &mut Workbench,
    state: &EditorState,
    effect: &Effect,
    out: Option<&Path>,
    request: &FrameRequest,
    report: &mut ReplayReport,
) -> Result<()> {
    let Some(dir) = out else {
        return Ok(());
    };
    let target = |p: &str| -> PathBuf { dir.join(Path::new(p).file_name().unwrap_or_default()) };
    match effect {
        Effect::SaveRecipe(p) => {
            let path = target(p);
            std::fs::write(&path, state.recipe.to_toml())
                .map_err(|e| Error::input(format!("cannot write {}: {e}", path.display())))?;
        }
        Effect::ExportPly(p) => {
            bench.export_ply(&state.recipe, &target(p))?;
        }
        Effect::Snapshot(p) => {
            let path = target(p);
            bench.snapshot(request, &path)?;
            report.snapshots.push(path.display().to_string());
        }
    }
    Ok(())
}
