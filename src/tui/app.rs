//! The interactive editor: terminal set-up and restore (quit, error, panic,
//! SIGINT, SIGTERM, SIGHUP), the event loop on 25 Hz logical ticks, the render
//! worker (only the latest frame in flight), adaptive resolution while moving,
//! the `:` prompt, and the session journal.

use std::io::Write;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use crossterm::event::{
    self, Event, KeyCode, KeyEventKind, MouseButton, MouseEvent, MouseEventKind,
};
use crossterm::{cursor, execute, terminal};
use ratatui::backend::CrosstermBackend;
use ratatui::Terminal;

use super::graphics::{
    detect, kitty_delete, place_image, GraphicsChoice, ImageTarget, Protocol, TerminalGraphics,
    SYNC_BEGIN, SYNC_END,
};
use super::keymap::Keymap;
use super::view::{draw, layout, InfoPanel, ViewModel};
use crate::editor::command::{complete, Command};
use crate::editor::pacing::next_scale;
use crate::editor::replay::replay_commands;
use crate::editor::session::{Recorder, Session, SessionHeader};
use crate::editor::state::Effect;
use crate::editor::{perform, Editor};
use crate::error::{Error, Result};
use crate::pipeline::workbench::{
    check_parent, source_swatches, FrameRequest, FrameResult, Workbench,
};
use crate::pipeline::Subject;
use crate::render::image::RgbImage;
use crate::render::Backend;

/// Options of `visage edit` and `visage view`.
#[derive(Clone, Debug)]
pub struct EditOptions {
    /// The database to compose from, or the scene to view.
    pub subject: Subject,
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

/// Input within this long keeps the view "moving" (low resolution allowed).
const SETTLE: Duration = Duration::from_millis(300);

/// A job for the render worker.
enum Job {
    Frame(FrameJob),
    /// A command's effect, with the recipe and the view it was asked in.
    Effect(Effect, crate::compose::recipe::Recipe, FrameRequest),
}

struct FrameJob {
    request: FrameRequest,
    version: u64,
    target: ImageTarget,
}

enum Reply {
    Frame {
        version: u64,
        result: Box<FrameResult>,
        encoded: Vec<u8>,
        encode_ms: f64,
        exact: bool,
    },
    Message(String),
}

/// The latest-frame slot shared with the worker plus a queue for effects.
#[derive(Default)]
struct Mailbox {
    frame: Option<FrameJob>,
    effects: Vec<Job>,
    stop: bool,
}

fn worker(mut bench: Workbench, mailbox: Arc<(Mutex<Mailbox>, Condvar)>, replies: Sender<Reply>) {
    loop {
        let job = {
            let (lock, cv) = &*mailbox;
            let mut m = lock.lock().unwrap_or_else(|e| e.into_inner());
            loop {
                if m.stop {
                    return;
                }
                if !m.effects.is_empty() {
                    break m.effects.remove(0);
                }
                if let Some(f) = m.frame.take() {
                    break Job::Frame(f);
                }
                m = cv.wait(m).unwrap_or_else(|e| e.into_inner());
            }
        };
        let reply = match job {
            Job::Frame(f) => match bench.render(&f.request) {
                Ok(result) => {
                    let t = Instant::now();
                    let encoded = f.target.encode(&result.image).unwrap_or_default();
                    Reply::Frame {
                        version: f.version,
                        encode_ms: t.elapsed().as_secs_f64() * 1e3,
                        exact: f.request.exact,
                        result: Box::new(result),
                        encoded,
                    }
                }
                Err(e) => Reply::Message(format!("render failed: {e}")),
            },
            Job::Effect(effect, recipe, view) => {
                match perform(&effect, &recipe, &view, &mut bench, &|p| PathBuf::from(p)) {
                    Ok(done) => Reply::Message(done.message),
                    Err(e) => Reply::Message(format!("{}: {e}", effect_name(&effect))),
                }
            }
        };
        if replies.send(reply).is_err() {
            return;
        }
    }
}

/// What failed, for the status line.
fn effect_name(effect: &Effect) -> &'static str {
    match effect {
        Effect::SaveRecipe(_) => "saving the recipe failed",
        Effect::ExportPly(_) => "export failed",
        Effect::Snapshot(_) => "snapshot failed",
    }
}

/// A `Write` that collects ratatui's output so a frame goes out in one write.
#[derive(Clone, Default)]
pub struct Collector(Arc<Mutex<Vec<u8>>>);

impl Collector {
    /// Takes the bytes collected so far.
    pub fn take(&self) -> Vec<u8> {
        std::mem::take(&mut *self.0.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Write for Collector {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// Restores the terminal when dropped (normal exit, error, unwinding panic).
pub(super) struct TerminalGuard {
    pub(super) kitty: bool,
}

pub(super) fn restore_terminal(kitty: bool) {
    let mut out = std::io::stdout();
    if kitty {
        let _ = out.write_all(&kitty_delete());
    }
    let _ = out.write_all(SYNC_END);
    let _ = execute!(
        out,
        event::DisableMouseCapture,
        terminal::LeaveAlternateScreen,
        cursor::Show
    );
    let _ = terminal::disable_raw_mode();
    let _ = out.flush();
}

impl Drop for TerminalGuard {
    fn drop(&mut self) {
        restore_terminal(self.kitty);
    }
}

/// Takes over the terminal (raw mode, alternate screen, mouse, no cursor)
/// until the guard drops, restoring it on panics too; the flag turns true
/// when SIGINT, SIGTERM or SIGHUP arrives.
pub(super) fn enter_terminal(kitty: bool) -> Result<(TerminalGuard, Arc<AtomicBool>)> {
    let stop = Arc::new(AtomicBool::new(false));
    for signal in [
        signal_hook::consts::SIGINT,
        signal_hook::consts::SIGTERM,
        signal_hook::consts::SIGHUP,
    ] {
        signal_hook::flag::register(signal, Arc::clone(&stop))
            .map_err(|e| Error::terminal(format!("cannot install signal handler: {e}")))?;
    }
    let default_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        restore_terminal(kitty);
        default_hook(info);
    }));
    terminal::enable_raw_mode()
        .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
    let guard = TerminalGuard { kitty };
    execute!(
        std::io::stdout(),
        terminal::EnterAlternateScreen,
        event::EnableMouseCapture,
        cursor::Hide
    )
    .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
    Ok((guard, stop))
}

/// Runs the editor until the user quits or a signal arrives.
pub fn run_editor(options: EditOptions) -> Result<()> {
    // Everything that can fail on bad input fails before the terminal changes.
    let keymap = Keymap::load(options.keymap.as_deref())?;
    if let Some(r) = &options.record {
        check_parent(r)?;
    }
    let resume = options.session.as_deref().map(Session::load).transpose()?;
    let subject = match &resume {
        Some(s) => s.header.subject(),
        None => options.subject.clone(),
    };
    let keymap = match subject {
        Subject::Avatars(_) => keymap,
        Subject::Scene(_) => Keymap::load_viewer(options.keymap.as_deref())?,
    };
    eprintln!("visage: opening {}…", subject.describe());
    let bench = open_with_progress(&subject, options.renderer)?;
    let swatches = bench.engine().map(source_swatches).unwrap_or_default();
    let mut editor = Editor::for_bench(&bench);
    if let Some(session) = &resume {
        let failed = replay_commands(session, &mut editor);
        editor.state.status = format!(
            "resumed {} commands at tick {} ({failed} failed)",
            session.lines.len(),
            editor.tick()
        );
    }
    let renderer_name = bench.renderer_description();
    let graphics = detect(options.graphics);
    let size = terminal::size().unwrap_or((120, 40));
    let mut recorder = match &options.record {
        Some(path) => Some(Recorder::open(
            path,
            &SessionHeader::for_subject(&subject, size, graphics.protocol),
        )?),
        None => None,
    };

    let kitty = graphics.protocol == Protocol::Kitty;
    let (_guard, stop) = enter_terminal(kitty)?;

    let mailbox = Arc::new((Mutex::new(Mailbox::default()), Condvar::new()));
    let (reply_tx, replies) = channel();
    let handle = {
        let mailbox = Arc::clone(&mailbox);
        std::thread::spawn(move || worker(bench, mailbox, reply_tx))
    };
    let mut app = App {
        editor,
        swatches,
        keymap,
        graphics,
        renderer_name,
        recorder,
        mailbox,
        replies,
        version: 1,
        requested: 0,
        shown_version: 0,
        last_input: Instant::now(),
        scale: 1.0,
        image: None,
        encoded: Vec::new(),
        image_dirty: true,
        info: InfoPanel::default(),
        frames_shown: 0,
        fps_clock: Instant::now(),
        last_exact: false,
        edit_time: None,
        drag_from: None,
    };
    for command in options.initial {
        app.run(command);
    }
    let result = app.event_loop(&stop);
    {
        let (lock, cv) = &*app.mailbox;
        lock.lock().unwrap_or_else(|e| e.into_inner()).stop = true;
        cv.notify_all();
    }
    let _ = handle.join();
    recorder = app.recorder.take();
    drop(recorder);
    result
}

/// Opens the subject, with a progress bar on standard error while a scene
/// file loads (big scenes take a while to read from a slow disk).
fn open_with_progress(subject: &Subject, renderer: Backend) -> Result<Workbench> {
    let bar = indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} reading {bytes}/{total_bytes} [{bar:30}] {bytes_per_sec}, {eta} left",
        )
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    let progress = |done: u64, all: u64| {
        bar.set_length(all);
        bar.set_position(done);
    };
    let bench = subject.open(renderer, &progress);
    bar.finish_and_clear();
    bench
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

/// Reads terminal events on their own thread. crossterm's `poll` can spin
/// without returning once the terminal hangs up; on this thread that costs
/// nothing, since the editor loop notices the hang-up and the process exits.
pub(super) fn spawn_input_reader() -> Receiver<Event> {
    let (tx, rx) = channel();
    std::thread::spawn(move || loop {
        match event::poll(Duration::from_millis(50)) {
            Ok(true) => match event::read() {
                Ok(e) => {
                    if tx.send(e).is_err() {
                        return;
                    }
                }
                Err(_) => return,
            },
            Ok(false) => {}
            Err(_) => return,
        }
    });
    rx
}

/// True when standard input's terminal has hung up or is gone.
pub(super) fn terminal_hung_up() -> bool {
    let mut fd = libc::pollfd {
        fd: libc::STDIN_FILENO,
        events: 0,
        revents: 0,
    };
    // SAFETY: one valid pollfd, zero timeout; poll only writes `revents`.
    let n = unsafe { libc::poll(&mut fd, 1, 0) };
    n > 0 && fd.revents & (libc::POLLHUP | libc::POLLERR | libc::POLLNVAL) != 0
}

struct App {
    editor: Editor,
    swatches: Vec<[u8; 3]>,
    keymap: Keymap,
    graphics: TerminalGraphics,
    renderer_name: String,
    recorder: Option<Recorder>,
    mailbox: Arc<(Mutex<Mailbox>, Condvar)>,
    replies: Receiver<Reply>,
    /// Bumped on every change that affects the picture.
    version: u64,
    requested: u64,
    shown_version: u64,
    last_input: Instant,
    scale: f64,
    image: Option<RgbImage>,
    encoded: Vec<u8>,
    image_dirty: bool,
    info: InfoPanel,
    frames_shown: u32,
    fps_clock: Instant,
    last_exact: bool,
    edit_time: Option<(u64, Instant)>,
    /// Where the mouse was at the last drag event.
    drag_from: Option<(f32, f32)>,
}

impl App {
    fn event_loop(&mut self, stop: &AtomicBool) -> Result<()> {
        let collector = Collector::default();
        let mut term = Terminal::new(CrosstermBackend::new(collector.clone()))
            .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
        let tick_len = Duration::from_millis(1000 / crate::editor::session::TICKS_PER_SECOND);
        let mut next_tick = Instant::now() + tick_len;
        let mut viewport = None;
        let input = spawn_input_reader();
        while !self.editor.state.quit {
            // A closed terminal (SSH dropped, emulator killed) ends the editor even
            // if SIGHUP never arrives; the journal already holds every command.
            if stop.load(Ordering::Relaxed) || terminal_hung_up() {
                break;
            }
            let timeout = next_tick
                .saturating_duration_since(Instant::now())
                .min(Duration::from_millis(10));
            match input.recv_timeout(timeout) {
                Ok(Event::Key(k)) if k.kind != KeyEventKind::Release => self.on_key(k),
                Ok(Event::Mouse(m)) => self.on_mouse(m),
                Ok(Event::Resize(..)) => {
                    self.version += 1;
                    self.image_dirty = true;
                    let _ = term.clear();
                }
                Ok(_) | Err(RecvTimeoutError::Timeout) => {}
                Err(RecvTimeoutError::Disconnected) => break,
            }
            while Instant::now() >= next_tick {
                next_tick += tick_len;
                let next = self.editor.tick() + 1;
                self.editor.advance_to(next);
                if self.editor.state.playing {
                    self.version += 1;
                }
            }
            self.receive();
            let area = term
                .size()
                .map(|s| ratatui::layout::Rect::new(0, 0, s.width, s.height))
                .unwrap_or_default();
            let new_viewport = layout(area).map(|a| a.viewport);
            if new_viewport != viewport {
                viewport = new_viewport;
                self.version += 1;
                self.image_dirty = true;
            }
            if let Some(v) = viewport {
                self.request_frame(v);
            }
            self.present(&mut term, &collector, viewport)?;
        }
        Ok(())
    }

    fn moving(&self) -> bool {
        self.editor.state.playing || self.last_input.elapsed() < SETTLE
    }

    fn on_key(&mut self, key: crossterm::event::KeyEvent) {
        self.last_input = Instant::now();
        if let Some(text) = self.editor.state.prompt.as_mut() {
            match key.code {
                KeyCode::Esc => self.editor.state.prompt = None,
                KeyCode::Backspace => {
                    text.pop();
                }
                KeyCode::Tab => {
                    let matches = complete(text.trim());
                    if matches.len() == 1 {
                        *text = format!("{} ", matches[0]);
                    } else if !matches.is_empty() {
                        self.editor.state.status = matches.join(" ");
                    }
                }
                KeyCode::Enter => {
                    let line = text.clone();
                    self.editor.state.prompt = None;
                    match Command::parse(&line) {
                        Ok(c) => self.run(c),
                        Err(e) => self.editor.state.status = e,
                    }
                }
                KeyCode::Char(c) if !c.is_control() => text.push(c),
                _ => {}
            }
            return;
        }
        if self.editor.state.help && key.code == KeyCode::Esc {
            self.editor.state.help = false;
            // The image under the overlay was removed: draw a fresh one.
            self.version += 1;
            return;
        }
        if let Some(c) = self.keymap.lookup(&key).cloned() {
            self.run(c);
        }
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
            self.last_input = Instant::now();
            self.run(c);
        }
    }

    fn run(&mut self, command: Command) {
        match self.editor.step(&command) {
            Ok(effects) => {
                if command.journalled() {
                    if let Some(r) = &mut self.recorder {
                        if let Err(e) = r.record(self.editor.tick(), &command) {
                            self.editor.state.status = format!("cannot journal the session: {e}");
                        }
                    }
                }
                self.version += 1;
                if command.is_edit() {
                    self.edit_time = Some((self.version, Instant::now()));
                }
                for effect in effects {
                    self.effect(effect);
                }
            }
            Err(e) => self.editor.state.status = e,
        }
    }

    /// Hands an effect to the render thread with the recipe and view of now.
    fn effect(&mut self, effect: Effect) {
        let (w, h) = self.info.image_size;
        let view = self.editor.frame_request(w.max(64), h.max(48), true);
        let job = Job::Effect(effect, self.editor.state.recipe.clone(), view);
        let (lock, cv) = &*self.mailbox;
        lock.lock()
            .unwrap_or_else(|e| e.into_inner())
            .effects
            .push(job);
        cv.notify_one();
    }

    /// Asks for a new frame when the picture is out of date, or for a full-quality
    /// one once the view has settled.
    fn request_frame(&mut self, viewport: ratatui::layout::Rect) {
        let moving = self.moving();
        let refine = !moving && !self.last_exact && self.requested == self.shown_version;
        if self.requested == self.version && !refine {
            return;
        }
        let target = ImageTarget::new(&self.graphics, (viewport.width, viewport.height));
        let full = target.full;
        let scale = if moving { self.scale } else { 1.0 };
        let (w, h) = (
            ((full.0 as f64 * scale).round() as u32).max(8),
            ((full.1 as f64 * scale).round() as u32).max(8),
        );
        let job = FrameJob {
            request: self.editor.frame_request(w, h, !moving),
            version: self.version,
            target,
        };
        let (lock, cv) = &*self.mailbox;
        lock.lock().unwrap_or_else(|e| e.into_inner()).frame = Some(job);
        cv.notify_one();
        self.requested = self.version;
        if refine {
            self.last_exact = true;
        }
    }

    fn receive(&mut self) {
        while let Ok(reply) = self.replies.try_recv() {
            match reply {
                Reply::Message(m) => self.editor.state.status = m,
                Reply::Frame {
                    version,
                    result,
                    encoded,
                    encode_ms,
                    exact,
                } => {
                    self.last_exact = exact;
                    self.shown_version = version;
                    let t = &result.timings;
                    let spent = t.compose + t.pose + t.render + encode_ms;
                    if !exact {
                        self.scale = next_scale(self.scale, spent);
                    }
                    if let Some((v, at)) = self.edit_time {
                        if version >= v {
                            self.editor.state.status =
                                format!("edit shown in {:.0} ms", at.elapsed().as_secs_f64() * 1e3);
                            self.edit_time = None;
                        }
                    }
                    self.info = InfoPanel {
                        gaussians: result.gaussians,
                        visible: result.visible,
                        stages: result.stages,
                        extras: result.extras,
                        timings: result.timings,
                        encode_ms,
                        fps: self.info.fps,
                        image_size: (result.image.width, result.image.height),
                        renderer: self.renderer_name.clone(),
                    };
                    self.image = Some(result.image);
                    self.encoded = encoded;
                    self.image_dirty = true;
                    self.frames_shown += 1;
                }
            }
        }
        let elapsed = self.fps_clock.elapsed().as_secs_f64();
        if elapsed >= 1.0 {
            self.info.fps = self.frames_shown as f64 / elapsed;
            self.frames_shown = 0;
            self.fps_clock = Instant::now();
        }
    }

    /// Draws the cells and, for image protocols, the frame — one write in
    /// synchronized output.
    fn present(
        &mut self,
        term: &mut Terminal<CrosstermBackend<Collector>>,
        collector: &Collector,
        viewport: Option<ratatui::layout::Rect>,
    ) -> Result<()> {
        let vm = ViewModel {
            state: &self.editor.state,
            catalog: &self.editor.catalog,
            swatches: &self.swatches,
            keymap: &self.keymap,
            info: &self.info,
            protocol: self.graphics.protocol,
            image: self.image.as_ref(),
        };
        term.draw(|f| draw(f, &vm))
            .map_err(|e| Error::terminal(format!("cannot draw: {e}")))?;
        let mut out = SYNC_BEGIN.to_vec();
        out.extend(collector.take());
        if self.image_dirty && self.graphics.protocol != Protocol::Halfblocks {
            if let Some(v) = viewport {
                if self.editor.state.help {
                    if self.graphics.protocol == Protocol::Kitty {
                        out.extend_from_slice(&kitty_delete());
                    }
                } else {
                    place_image(&mut out, v, &self.encoded);
                }
            }
        }
        self.image_dirty = false;
        if out.len() == SYNC_BEGIN.len() {
            return Ok(()); // nothing changed on screen
        }
        out.extend_from_slice(SYNC_END);
        write_to_terminal(&out)
    }
}

/// Writes a frame's bytes to the terminal in one write.
pub(super) fn write_to_terminal(bytes: &[u8]) -> Result<()> {
    let mut stdout = std::io::stdout().lock();
    stdout
        .write_all(bytes)
        .and_then(|_| stdout.flush())
        .map_err(|e| Error::terminal(format!("cannot write to the terminal: {e}")))
}

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
