//! The interactive editor: opening the subject and its journal (recovering an
//! unsaved session when there is one), the event loop on 25 Hz logical
//! ticks, adaptive resolution while moving, and the front end's own state —
//! the status line, the `:` prompt, the help overlay, the quit confirmation,
//! source thumbnails and the orbit pivot after free flight. Drawing is in
//! `view`, the render thread in `worker`, terminal plumbing in `terminal`.

use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use crossterm::event::{Event, KeyEvent, KeyEventKind, MouseButton, MouseEvent, MouseEventKind};
use ratatui::backend::CrosstermBackend;
use ratatui::layout::Rect;
use ratatui::Terminal;

use super::graphics::{
    kitty_delete, place_image, ImageTarget, Protocol, TerminalGraphics, SYNC_BEGIN, SYNC_END,
};
use super::help::{draw_help, help_page, help_rows, HelpOutcome, HelpOverlay, HelpRow};
use super::keymap::Keymap;
use super::launch::{launch, EditOptions, Launched};
use super::prompt::{History, Prompt, PromptOutcome};
use super::terminal::{
    enter_terminal, signal_name, spawn_input_reader, terminal_hung_up, write_to_terminal,
    Collector, StopSignal,
};
use super::view::{draw, layout, source_slots, InfoPanel, Screen, ViewModel};
use super::worker::{FrameJob, RenderWorker, Reply, Task};
use crate::compose::recipe::Recipe;
use crate::editor::command::{nearest_names, Command, CommandSpec};
use crate::editor::journal::{state_dir, JournalledEditor};
use crate::editor::pacing::next_scale;
use crate::editor::state::Effect;
use crate::editor::Editor;
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::pipeline::workbench::{source_swatches, DebugView, FrameRequest};
use crate::render::image::RgbImage;
use crate::scene::camera::{CameraOverrides, Orbit};

/// Input within this long keeps the view "moving" (low resolution allowed).
const SETTLE: Duration = Duration::from_millis(300);

/// Terminal rows from which the source strip shows thumbnails.
const THUMBNAIL_MIN_ROWS: u16 = 30;

/// Runs the editor until the user quits or a signal arrives.
pub fn run_editor(options: EditOptions) -> Result<()> {
    let Launched {
        workbench,
        editor,
        recorder,
        auto_journal,
        status,
        unsaved,
        render_size,
        keymap,
        graphics,
    } = launch(&options)?;
    let swatches = workbench.engine().map(source_swatches).unwrap_or_default();
    let renderer_name = workbench.renderer_description();
    let history = History::load(state_dir().map(|d| d.join("history")));
    let help_rows = help_rows(&keymap, editor.catalog.scene.is_some());

    let kitty = graphics.protocol == Protocol::Kitty;
    let (_guard, stop) = enter_terminal(kitty)?;
    let mut app = App {
        journal: JournalledEditor::new(editor, recorder),
        auto_journal,
        user_journal: options.record.is_some(),
        swatches,
        keymap,
        graphics,
        renderer_name,
        worker: RenderWorker::spawn(workbench),
        picture: Picture::default(),
        status,
        prompt: None,
        help: None,
        help_rows,
        history,
        quit: false,
        unsaved,
        render_size,
        pivot: Pivot::default(),
        thumbnails: Thumbnails::default(),
        drag_from: None,
    };
    for command in options.initial {
        app.run(command, false);
    }
    let result = app.event_loop(&stop);
    if app.auto_journal {
        let closed = app.quit.then_some("quit");
        app.journal.finish(closed, true);
    }
    drop(app);
    result
}

/// The camera command for a drag of `delta` cells with a button (a cell is
/// about twice as tall as wide, so rows count double).
fn drag_command(button: MouseButton, delta: (f32, f32)) -> Option<Command> {
    let (dx, dy) = (delta.0, 2.0 * delta.1);
    if dx == 0.0 && dy == 0.0 {
        return None;
    }
    Some(match button {
        MouseButton::Left => Command::Orbit(-1.5 * dx, 1.5 * dy),
        MouseButton::Right => Command::Look(dx, -dy),
        MouseButton::Middle => Command::Fly(0.0, -0.01 * dx, 0.01 * dy),
    })
}

/// The picture on screen and what it cost.
struct Picture {
    /// Bumped on every change that affects the picture.
    version: u64,
    requested: u64,
    shown_version: u64,
    last_input: Instant,
    scale: f64,
    image: Option<RgbImage>,
    encoded: Vec<u8>,
    /// The cells `encoded` covers.
    encoded_cells: (u16, u16),
    dirty: bool,
    info: InfoPanel,
    frames_shown: u32,
    fps_clock: Instant,
    last_exact: bool,
    /// The version an edit was made at, when, and what it said.
    edit_time: Option<(u64, Instant, Option<String>)>,
}

impl Default for Picture {
    fn default() -> Self {
        Self {
            version: 1,
            requested: 0,
            shown_version: 0,
            last_input: Instant::now(),
            scale: 1.0,
            image: None,
            encoded: Vec::new(),
            encoded_cells: (0, 0),
            dirty: true,
            info: InfoPanel::default(),
            frames_shown: 0,
            fps_clock: Instant::now(),
            last_exact: false,
            edit_time: None,
        }
    }
}

/// Orbiting after free flight turns about what is at the centre of the
/// view, not the old target: once the view settles after `fly` or `look`, the
/// worker measures the depth under the centre; the next orbit first moves
/// the target there (a journalled `set-camera`, so replays agree).
#[derive(Default)]
struct Pivot {
    /// `fly` or `look` moved the camera since the target was last set.
    free: bool,
    /// The worker is measuring.
    asked: bool,
    /// The depth under the centre, for the camera it was measured at.
    found: Option<(Orbit, f32)>,
}

/// Source thumbnails for graphics terminals.
#[derive(Default)]
struct Thumbnails {
    asked: bool,
    /// Encoded per source, in source order.
    encoded: Vec<Vec<u8>>,
    /// The cells each thumbnail takes.
    cells: (u16, u16),
    /// To be placed again (new, moved, or drawn over).
    dirty: bool,
}

struct App {
    journal: JournalledEditor,
    /// The journal is one of the state folder's (closed on quit).
    auto_journal: bool,
    /// The user named the journal (`--record`): quitting loses nothing.
    user_journal: bool,
    swatches: Vec<[u8; 3]>,
    keymap: Keymap,
    graphics: TerminalGraphics,
    renderer_name: String,
    worker: RenderWorker,
    picture: Picture,
    status: String,
    prompt: Option<Prompt>,
    help: Option<HelpOverlay>,
    help_rows: Vec<HelpRow>,
    history: History,
    /// The user asked to quit (rather than a signal or hang-up).
    quit: bool,
    /// Edits since the recipe was last saved.
    unsaved: usize,
    /// The session's render size: snapshots take it unless they name one.
    render_size: (u32, u32),
    pivot: Pivot,
    thumbnails: Thumbnails,
    /// Where the mouse was at the last drag event.
    drag_from: Option<(f32, f32)>,
}

impl App {
    fn editor(&self) -> &Editor {
        &self.journal.editor
    }

    /// Runs until the user quits (`Ok`) or a signal or a hang-up ends the
    /// session (an interruption: exit 128 + the signal; the journal is left
    /// open, to be offered for recovery).
    fn event_loop(&mut self, stop: &StopSignal) -> Result<()> {
        let collector = Collector::default();
        let mut term = Terminal::new(CrosstermBackend::new(collector.clone()))
            .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
        let tick_len = Duration::from_millis(1000 / crate::editor::session::TICKS_PER_SECOND);
        let mut next_tick = Instant::now() + tick_len;
        let mut viewport = None;
        let input = spawn_input_reader();
        while !self.quit {
            // A closed terminal (SSH dropped, emulator killed) ends the editor even
            // if SIGHUP never arrives; the journal already holds every command.
            let signal = stop
                .received()
                .or_else(|| terminal_hung_up().then_some(libc::SIGHUP));
            if let Some(signal) = signal {
                return Err(self.interrupted(signal));
            }
            let timeout = next_tick
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(10));
            let area = term
                .size()
                .map(|s| Rect::new(0, 0, s.width, s.height))
                .unwrap_or_default();
            match input.recv_timeout(timeout) {
                Ok(Event::Key(k)) if k.kind != KeyEventKind::Release => self.on_key(k, area),
                Ok(Event::Mouse(m)) if self.help.is_none() => self.on_mouse(m),
                Ok(Event::Resize(..)) => {
                    self.picture.version += 1;
                    self.picture.dirty = true;
                    self.thumbnails.dirty = true;
                    let _ = term.clear();
                }
                Ok(_) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => return Err(self.interrupted(libc::SIGHUP)),
            }
            while Instant::now() >= next_tick {
                next_tick += tick_len;
                let next = self.editor().tick() + 1;
                self.journal.editor.advance_to(next);
                if self.editor().state.playing {
                    self.picture.version += 1;
                }
            }
            self.receive();
            let new_viewport = layout(area, self.screen()).map(|a| a.viewport);
            if new_viewport != viewport {
                // The layout moved (a resize, thumbnails arriving): redraw
                // every cell, since cells left to images are never diffed.
                if viewport.is_some() {
                    let _ = term.clear();
                }
                viewport = new_viewport;
                self.picture.version += 1;
                self.picture.dirty = true;
                self.thumbnails.dirty = true;
            }
            if let Some(v) = viewport {
                self.request_frame(v);
            }
            self.present(&mut term, &collector, area)?;
        }
        Ok(())
    }

    /// The error a signal ends the session with, saying where the work is.
    fn interrupted(&self, signal: i32) -> Error {
        let kept = match self.journal.journal() {
            Some(path) if self.auto_journal => format!(
                "; the journal keeps the session and the next start offers it back ({})",
                path.display()
            ),
            Some(path) => format!("; the journal keeps the session ({})", path.display()),
            None => String::new(),
        };
        StopSignal::stopped(signal, format!("stopped by {}{kept}", signal_name(signal)))
    }

    /// What the layout needs to know beyond the terminal's size.
    fn screen(&self) -> Screen {
        Screen {
            thumbnails: self.thumbnails_shown(),
        }
    }

    /// Thumbnails replace swatches on graphics terminals tall enough.
    fn thumbnails_shown(&self) -> Option<(u16, u16)> {
        let rows = crossterm::terminal::size().map_or(0, |s| s.1);
        (self.graphics.protocol != Protocol::Halfblocks
            && self.editor().catalog.scene.is_none()
            && rows >= THUMBNAIL_MIN_ROWS)
            .then_some(self.thumbnails.cells)
            .filter(|_| !self.thumbnails.encoded.is_empty())
    }

    fn moving(&self) -> bool {
        self.editor().state.playing || self.picture.last_input.elapsed() < SETTLE
    }

    fn on_key(&mut self, key: KeyEvent, area: Rect) {
        self.picture.last_input = Instant::now();
        if let Some(help) = &mut self.help {
            if help.on_key(&key, help_page(area)) == HelpOutcome::Close {
                self.help = None;
                self.redraw_images();
            }
            return;
        }
        if let Some(prompt) = &mut self.prompt {
            match prompt.on_key(&key, &self.journal.editor.catalog, &self.history) {
                PromptOutcome::Editing => {}
                PromptOutcome::Cancelled => self.prompt = None,
                PromptOutcome::Submitted(line) => {
                    self.prompt = None;
                    self.history.push(&line);
                    if line.trim().is_empty() {
                        return;
                    }
                    let armed = self.status_quit_armed();
                    match Command::parse(&line) {
                        Ok(c) => self.run(c, armed),
                        Err(e) => self.status = e,
                    }
                }
            }
            return;
        }
        if let Some(c) = self.keymap.lookup(&key).cloned() {
            let armed = self.status_quit_armed();
            if armed && c != Command::Quit {
                self.status.clear();
            }
            self.run(c, armed);
        }
    }

    /// Whether the status line is asking to confirm quitting (a second quit
    /// confirms it; any other key withdraws the question).
    fn status_quit_armed(&self) -> bool {
        self.status.starts_with(QUIT_QUESTION)
    }

    /// Mouse drags move the camera (left orbits, right looks, middle pans) and
    /// the wheel zooms, each as the command a key would run, so sessions
    /// journal them.
    fn on_mouse(&mut self, event: MouseEvent) {
        let at = (event.column as f32, event.row as f32);
        let command = match event.kind {
            MouseEventKind::Down(_) => {
                self.drag_from = Some(at);
                None
            }
            MouseEventKind::Up(_) => {
                self.drag_from = None;
                None
            }
            MouseEventKind::Drag(button) => {
                let from = self.drag_from.replace(at).unwrap_or(at);
                drag_command(button, (at.0 - from.0, at.1 - from.1))
            }
            MouseEventKind::ScrollUp => Some(Command::Zoom(0.9)),
            MouseEventKind::ScrollDown => Some(Command::Zoom(1.0 / 0.9)),
            _ => None,
        };
        if let Some(c) = command {
            self.picture.last_input = Instant::now();
            self.run(c, false);
        }
    }

    /// Runs a command: the front end's own (quit, help, the prompt) here,
    /// the rest through the journalled editor. `quit_armed`: the user was
    /// just asked to confirm quitting.
    fn run(&mut self, command: Command, quit_armed: bool) {
        match &command {
            Command::Quit => return self.ask_quit(quit_armed),
            Command::ForceQuit => {
                self.quit = true;
                return;
            }
            Command::Help(topic) => return self.help(topic.as_deref()),
            Command::Prompt => {
                self.prompt = Some(Prompt::new());
                return;
            }
            Command::Orbit(..) if self.pivot.free => self.repivot(),
            Command::Fly(..) | Command::Look(..) => {
                self.pivot = Pivot {
                    free: true,
                    ..Pivot::default()
                };
            }
            _ => {}
        }
        let undoing = matches!(command, Command::Undo | Command::Redo);
        let before = (command.is_edit() || undoing).then(|| self.editor().state.recipe.clone());
        match self.journal.run(&command) {
            Ok(applied) => {
                if before.is_some_and(|b| b != self.editor().state.recipe) {
                    self.unsaved += 1;
                }
                self.picture.version += 1;
                if command.is_edit() || undoing {
                    self.picture.edit_time =
                        Some((self.picture.version, Instant::now(), applied.message));
                } else if let Some(m) = applied.message {
                    self.status = m;
                }
                if matches!(
                    command,
                    Command::NextSource | Command::PrevSource | Command::SelectSource(_)
                ) {
                    self.thumbnails.dirty = true;
                }
                for effect in applied.effects {
                    self.effect(effect);
                }
            }
            Err(e) => self.status = e,
        }
    }

    /// Quits, unless edits would be lost without being asked: then asks.
    fn ask_quit(&mut self, armed: bool) {
        if armed || self.unsaved == 0 || self.user_journal {
            self.quit = true;
            return;
        }
        let key = |line: &str, fallback: &str| {
            self.keymap.key_for(line).unwrap_or_else(|| fallback.into())
        };
        self.status = format!(
            "{QUIT_QUESTION} {} unsaved edit{}: {} again quits (the journal keeps them), :quit! quits at once, {} saves the recipe",
            self.unsaved,
            if self.unsaved == 1 { "" } else { "s" },
            key("quit", ":quit"),
            key("save-recipe recipe.toml", ":save-recipe PATH"),
        );
    }

    /// `help`: the overlay; `help COMMAND`: its usage and keys on the status line.
    fn help(&mut self, topic: Option<&str>) {
        let Some(name) = topic else {
            self.help = Some(HelpOverlay::default());
            return;
        };
        self.status = match CommandSpec::find(name) {
            Some(spec) => {
                let keys: Vec<String> = self
                    .keymap
                    .bindings()
                    .filter(|(_, line)| line.split_whitespace().next() == Some(spec.name))
                    .map(|(k, line)| format!("{k} ({line})"))
                    .collect();
                format!(
                    "{}: {}; keys: {}",
                    spec.usage(),
                    spec.summary,
                    if keys.is_empty() {
                        "none, type it at :".into()
                    } else {
                        keys.join(", ")
                    }
                )
            }
            None => {
                let near = nearest_names(name);
                format!(
                    "help: no command '{}'{}",
                    crate::text::printable(name),
                    if near.is_empty() {
                        String::new()
                    } else {
                        format!(" (did you mean {}?)", near.join(" or "))
                    }
                )
            }
        };
    }

    /// Before an orbit after free flight: moves the target to the surface
    /// under the centre of the view, keeping the eye where it is.
    fn repivot(&mut self) {
        let camera = self.editor().state.recipe.camera;
        let Some((at, depth)) = self.pivot.found else {
            return;
        };
        if at != camera || depth <= 0.0 || !depth.is_finite() {
            return;
        }
        let eye = camera.eye();
        let forward = (glam::Vec3::from(camera.target) - eye).normalize_or_zero();
        let target = eye + forward * depth;
        let settings = CameraOverrides {
            target: Some(target.into()),
            radius: Some(depth),
            ..CameraOverrides::default()
        };
        self.pivot = Pivot::default();
        self.run(Command::SetCamera(settings), false);
    }

    /// Hands an effect to the render thread with the recipe and the view of
    /// now, at the session's render size.
    fn effect(&mut self, effect: Effect) {
        let (w, h) = self.render_size;
        let view = self.editor().frame_request(w, h, true);
        let recipe = self.editor().state.recipe.clone();
        self.worker
            .ask(Task::Effect(effect, Box::new((recipe, view))));
    }

    /// The kitty image under an overlay was removed, and sixel or iTerm2
    /// images were drawn over: draw them again.
    fn redraw_images(&mut self) {
        self.picture.version += 1;
        self.picture.dirty = true;
        self.thumbnails.dirty = true;
    }

    /// Asks for a new frame when the picture is out of date, or for a full-quality
    /// one once the view has settled (then also for the depth at the centre
    /// after free flight).
    fn request_frame(&mut self, viewport: Rect) {
        let p = &self.picture;
        let moving = self.moving();
        let refine = !moving && !p.last_exact && p.requested == p.shown_version;
        if p.requested == p.version && !refine {
            return;
        }
        let target = ImageTarget::new(&self.graphics, (viewport.width, viewport.height));
        let full = target.full;
        let scale = if moving { p.scale } else { 1.0 };
        let (w, h) = (
            ((full.0 as f64 * scale).round() as u32).max(8),
            ((full.1 as f64 * scale).round() as u32).max(8),
        );
        let request = self.editor().frame_request(w, h, !moving);
        if !moving && self.pivot.free && !self.pivot.asked && self.pivot.found.is_none() {
            self.pivot.asked = true;
            self.worker.ask(Task::Pivot(request.clone()));
        }
        self.worker.draw(FrameJob {
            request,
            version: self.picture.version,
            target,
        });
        self.picture.requested = self.picture.version;
        if refine {
            self.picture.last_exact = true;
        }
    }

    fn receive(&mut self) {
        while let Some(reply) = self.worker.try_reply() {
            match reply {
                Reply::Done {
                    message,
                    saved_recipe,
                } => {
                    if saved_recipe {
                        self.unsaved = 0;
                    }
                    self.status = message;
                }
                Reply::Failed(message) => self.status = message,
                Reply::Fit(progress, stored) => {
                    // A fit read from the cache is done at its first step,
                    // before any progress was shown.
                    if progress.is_none() && (self.picture.info.fit.is_some() || stored) {
                        // Done: draw the fitted composite.
                        self.picture.version += 1;
                        self.status = if stored {
                            "seam fit done (read from the cache)"
                        } else {
                            "seam fit done"
                        }
                        .into();
                    }
                    self.picture.info.fit = progress;
                }
                Reply::Pivot(at, depth) => {
                    self.pivot.asked = false;
                    if at == self.editor().state.recipe.camera {
                        self.pivot.found = depth.map(|d| (at, d));
                    }
                }
                Reply::Thumbnails(thumbs) => {
                    self.thumbnails.encoded = thumbs.into_iter().map(|(_, e)| e).collect();
                    self.thumbnails.dirty = true;
                    self.picture.version += 1;
                }
                Reply::Frame {
                    version,
                    result,
                    encoded,
                    cells,
                    encode_ms,
                    exact,
                } => {
                    self.show_frame(version, *result, encoded, encode_ms, exact);
                    self.picture.encoded_cells = cells;
                }
            }
        }
        let p = &mut self.picture;
        let elapsed = p.fps_clock.elapsed().as_secs_f64();
        if elapsed >= 1.0 {
            p.info.fps = p.frames_shown as f64 / elapsed;
            p.frames_shown = 0;
            p.fps_clock = Instant::now();
        }
    }

    fn show_frame(
        &mut self,
        version: u64,
        result: crate::pipeline::workbench::FrameResult,
        encoded: Vec<u8>,
        encode_ms: f64,
        exact: bool,
    ) {
        let p = &mut self.picture;
        p.last_exact = exact;
        p.shown_version = version;
        // A paged scene read chunks for this frame: draw again, finer.
        if result.lod.is_some_and(|cut| cut.chunks_read > 0) {
            p.version += 1;
        }
        let t = &result.timings;
        let spent = t.compose + t.pose + t.render + encode_ms;
        if !exact {
            p.scale = next_scale(p.scale, spent);
        }
        if let Some((v, at, message)) = &p.edit_time {
            if version >= *v {
                let ms = at.elapsed().as_secs_f64() * 1e3;
                self.status = match message {
                    Some(m) => format!("{m} (shown in {ms:.0} ms)"),
                    None => format!("edit shown in {ms:.0} ms"),
                };
                p.edit_time = None;
            }
        }
        let last_compose = if t.recomposed {
            t.compose
        } else {
            p.info.last_compose
        };
        p.info = InfoPanel {
            gaussians: result.gaussians,
            visible: result.visible,
            lod: result.lod,
            stages: result.stages,
            extras: result.extras,
            timings: result.timings,
            last_compose,
            encode_ms,
            fps: p.info.fps,
            image_size: (result.image.width, result.image.height),
            renderer: self.renderer_name.clone(),
            fit: p.info.fit,
        };
        p.image = Some(result.image);
        p.encoded = encoded;
        p.dirty = true;
        p.frames_shown += 1;
        if !self.thumbnails.asked {
            self.ask_thumbnails();
        }
    }

    /// Renders each source's face once, small, for the source strip.
    fn ask_thumbnails(&mut self) {
        self.thumbnails.asked = true;
        if self.graphics.protocol == Protocol::Halfblocks || self.editor().catalog.scene.is_some() {
            return;
        }
        let (cw, ch) = self.graphics.cell_px;
        let rows = 2u16;
        let cols = ((rows as u32 * ch as u32) / (cw.max(1) as u32)).clamp(2, 8) as u16;
        self.thumbnails.cells = (cols, rows);
        let catalog = &self.editor().catalog;
        let requests = catalog
            .sources
            .iter()
            .enumerate()
            .map(|(i, name)| {
                let target = ImageTarget::thumbnail(&self.graphics, (cols, rows), i);
                let mut recipe = Recipe::unedited(name);
                recipe.camera = Orbit {
                    fov_deg: Orbit::STUDY.fov_deg * 0.8,
                    ..Orbit::STUDY
                };
                let request = FrameRequest {
                    recipe,
                    debug: DebugView::default(),
                    group: Group::Face,
                    width: target.full.0.max(8),
                    height: target.full.1.max(8),
                    exact: true,
                };
                (request, target)
            })
            .collect();
        self.worker.ask(Task::Thumbnails(requests));
    }

    /// Draws the cells and, for image protocols, the frame and thumbnails —
    /// one write in synchronized output.
    fn present(
        &mut self,
        term: &mut Terminal<CrosstermBackend<Collector>>,
        collector: &Collector,
        area: Rect,
    ) -> Result<()> {
        let screen = self.screen();
        let vm = ViewModel {
            state: &self.journal.editor.state,
            catalog: &self.journal.editor.catalog,
            swatches: &self.swatches,
            keymap: &self.keymap,
            info: &self.picture.info,
            protocol: self.graphics.protocol,
            image: self.picture.image.as_ref(),
            status: &self.status,
            prompt: self.prompt.as_ref(),
            screen,
            overlay: self.help.is_some(),
            journal: self.journal.journal(),
        };
        let help = &mut self.help;
        let rows = &self.help_rows;
        term.draw(|f| {
            draw(f, &vm);
            if let Some(h) = help {
                draw_help(f, f.area(), h, rows);
            }
        })
        .map_err(|e| Error::terminal(format!("cannot draw: {e}")))?;
        let mut out = SYNC_BEGIN.to_vec();
        out.extend(collector.take());
        let images = self.graphics.protocol != Protocol::Halfblocks;
        if let (true, Some(areas)) = (images, layout(area, screen)) {
            if self.help.is_some() {
                if self.picture.dirty && self.graphics.protocol == Protocol::Kitty {
                    out.extend_from_slice(&kitty_delete());
                }
            } else {
                let fits =
                    self.picture.encoded_cells == (areas.viewport.width, areas.viewport.height);
                if self.picture.dirty && fits {
                    place_image(&mut out, areas.viewport, &self.picture.encoded);
                }
                if self.thumbnails.dirty {
                    if let Some(cells) = screen.thumbnails {
                        let s = &self.journal.editor;
                        for (i, slot) in source_slots(
                            areas.sources,
                            &s.catalog.sources,
                            s.state.source,
                            Some(cells),
                        ) {
                            if let Some(encoded) = self.thumbnails.encoded.get(i) {
                                place_image(&mut out, slot, encoded);
                            }
                        }
                    }
                    self.thumbnails.dirty = false;
                }
            }
        }
        self.picture.dirty = false;
        if out.len() == SYNC_BEGIN.len() {
            return Ok(()); // nothing changed on screen
        }
        out.extend_from_slice(SYNC_END);
        write_to_terminal(&out)
    }
}

/// How the quit question begins (so the next key knows it was asked).
const QUIT_QUESTION: &str = "quit?";

#[cfg(test)]
mod tests {
    use super::*;

    /// Drags move the camera the way the hand moves: dragging right turns the
    /// subject to the right (the camera orbits left), dragging down shows it
    /// from above; a right drag turns the view with the hand; a middle drag
    /// grabs the scene.
    #[test]
    fn drags_become_camera_commands() {
        assert_eq!(
            drag_command(MouseButton::Left, (2.0, 1.0)),
            Some(Command::Orbit(-3.0, 3.0))
        );
        assert_eq!(
            drag_command(MouseButton::Right, (3.0, -1.0)),
            Some(Command::Look(3.0, 2.0))
        );
        assert_eq!(
            drag_command(MouseButton::Middle, (100.0, 0.0)),
            Some(Command::Fly(0.0, -1.0, 0.0))
        );
        assert_eq!(drag_command(MouseButton::Left, (0.0, 0.0)), None);
    }
}
