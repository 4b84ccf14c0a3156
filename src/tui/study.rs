//! A participant's study session in the terminal (thesis §6.2.3): each
//! avatar loops its closed-mouth animation at the study's frame rate on an
//! orbit locked to the study's radius and yaw/pitch limits; the participant
//! turns it with the arrow keys or the mouse and answers "Is this face
//! edited?" and, when yes, which parts. Every answer is journalled before the
//! next avatar shows, so a kill or a dropped SSH connection loses nothing
//! and the next start resumes. The category is never shown.

use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use crossterm::event::{Event, KeyCode, KeyEvent, KeyEventKind, KeyModifiers, MouseEventKind};
use ratatui::backend::CrosstermBackend;
use ratatui::layout::Rect;
use ratatui::style::{Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Paragraph, Wrap};
use ratatui::{Frame, Terminal};

use super::graphics::{
    detect, draw_halfblocks, place_image, reserve_cells, GraphicsChoice, ImageTarget, Protocol,
    TerminalGraphics, SYNC_BEGIN, SYNC_END,
};
use super::terminal::{
    enter_terminal, signal_name, spawn_input_reader, terminal_hung_up, write_to_terminal,
    Collector, StopSignal,
};
use super::view::MIN_SIZE;
use crate::compose::composition::StudyGroup;
use crate::compose::engine::Engine;
use crate::compose::recipe::Recipe;
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::pipeline::workbench::{DebugView, FrameRequest};
use crate::pipeline::{DatabaseSpec, Workbench};
use crate::render::image::RgbImage;
use crate::render::Backend;
use crate::study::design::{Display, StudyFolder};
use crate::study::fits::fit_store;
use crate::study::journal::{journal_path, Answer, Journal};
use crate::train::seam_fit::SeamFit;

/// Options of `visage study run`.
pub struct RunOptions {
    /// The study.
    pub study: StudyFolder,
    /// The participant's ID.
    pub participant: String,
    /// Graphics protocol choice.
    pub graphics: GraphicsChoice,
    /// Renderer.
    pub renderer: Backend,
    /// How the seam fit of the avatars whose post-processing asks for one
    /// runs (before each is shown); 0 iterations: none.
    pub seam_fit: SeamFit,
}

/// Degrees one arrow key turns the head.
const KEY_STEP_DEG: f32 = 5.0;
/// Degrees one cell of mouse drag turns the head.
const DRAG_DEG_PER_CELL: f32 = 1.5;

/// Longest wait for input before checking for signals and hang-ups.
const POLL: Duration = Duration::from_millis(50);

/// When the loop's next frame is due.
fn next_frame_time(since: Instant, fps: f64) -> Instant {
    let shown = (since.elapsed().as_secs_f64() * fps).floor();
    since + Duration::from_secs_f64((shown + 1.0) / fps)
}

/// Where the participant is in answering the current avatar.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    /// Looking; y or n answers.
    Looking,
    /// Said "edited"; choosing the parts.
    Choosing([bool; 4]),
}

/// One avatar on screen.
struct Showing {
    id: u32,
    position: usize,
    recipe: Recipe,
    workbench: usize,
    since: Instant,
    yaw: f32,
    pitch: f32,
    stage: Stage,
    hint: String,
    /// The previous avatar's answer is not final: `b` goes back to it.
    can_go_back: bool,
}

/// Runs the participant's session; returns a summary line for the shell.
pub fn run_participant(options: RunOptions) -> Result<String> {
    let RunOptions {
        study,
        participant,
        graphics,
        renderer,
        seam_fit,
    } = options;
    let mut journal = Journal::open(&study, &participant)?;
    let order = study.order(&participant);
    let total = order.len();
    let todo: Vec<u32> = order
        .iter()
        .copied()
        .filter(|id| !journal.answered(*id))
        .collect();
    let path = journal_path(&study, &participant);
    if todo.is_empty() {
        return Ok(format!(
            "participant {participant} has answered all {total} avatars ({})",
            path.display()
        ));
    }
    let mut workbenches: Vec<(DatabaseSpec, Workbench)> = Vec::new();
    for c in &study.study.categories {
        let spec = c.database.clone();
        if workbenches.iter().all(|(s, _)| *s != spec) {
            eprintln!("visage: opening the {} database…", spec.db);
            let (db, _) = spec.load()?;
            let mut workbench = Workbench::new(Engine::new(db)?, renderer)?;
            workbench.set_fit_options(seam_fit);
            // Fits made by `study build` (or for an earlier participant).
            workbench.set_fit_store(Some(fit_store(&study)));
            workbenches.push((spec.clone(), workbench));
        }
    }
    let graphics = detect(graphics);
    let kitty = graphics.protocol == Protocol::Kitty;
    let (_guard, stop) = enter_terminal(kitty)?;
    let mut session = Session {
        study: &study,
        graphics,
        workbenches,
        total,
        done: total - todo.len(),
    };
    let ended = session.run(&todo, &mut journal, &stop)?;
    let answered = journal
        .answers
        .iter()
        .map(|a| a.avatar)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    let progress = format!(
        "participant {participant} answered {answered} of {total}; run the same command to go on ({})",
        path.display()
    );
    match ended {
        Ended::Finished => Ok(format!(
            "thank you: participant {participant} answered all {total} avatars ({})",
            path.display()
        )),
        Ended::Quit => Ok(format!("stopped: {progress}")),
        Ended::Signal(signal) => Err(StopSignal::stopped(
            signal,
            format!("stopped by {}: {progress}", signal_name(signal)),
        )),
    }
}

/// How a participant's session ended.
enum Ended {
    /// Every avatar answered.
    Finished,
    /// The participant stopped (q or ctrl-c); the answers are saved.
    Quit,
    /// A signal or a hang-up stopped it; the answers are saved.
    Signal(i32),
}

struct Session<'a> {
    study: &'a StudyFolder,
    graphics: TerminalGraphics,
    workbenches: Vec<(DatabaseSpec, Workbench)>,
    total: usize,
    done: usize,
}

impl Session<'_> {
    /// Shows the avatars in order. An answer is final once the next avatar
    /// is answered: until then `b` goes back to it, and answering it again
    /// replaces it (the journal keeps both lines; the last one counts).
    fn run(&mut self, todo: &[u32], journal: &mut Journal, stop: &StopSignal) -> Result<Ended> {
        let collector = Collector::default();
        let mut term = Terminal::new(CrosstermBackend::new(collector.clone()))
            .map_err(|e| Error::terminal(format!("cannot use this terminal: {e}")))?;
        let input = spawn_input_reader();
        let mut at = 0;
        while at < todo.len() {
            let mut showing = self.show(todo[at])?;
            showing.can_go_back = at > 0;
            match self.look(&mut showing, &input, &mut term, &collector, stop)? {
                Step::Answer(answer) => {
                    journal.record(answer)?;
                    self.done += 1;
                    at += 1;
                }
                Step::Back => {
                    self.done -= 1;
                    at -= 1;
                }
                Step::End(ended) => return Ok(ended),
            }
        }
        Ok(Ended::Finished)
    }

    /// Shows one avatar until the participant answers it, goes back, or the
    /// session ends.
    fn look(
        &mut self,
        showing: &mut Showing,
        input: &std::sync::mpsc::Receiver<Event>,
        term: &mut Terminal<CrosstermBackend<Collector>>,
        collector: &Collector,
        stop: &StopSignal,
    ) -> Result<Step> {
        let mut drag_from: Option<(f32, f32)> = None;
        // Draw at once, then once per frame of the loop or on input: no
        // faster than the display's frame rate, which matters over SSH.
        let mut dirty = true;
        let mut next_frame = Instant::now();
        loop {
            let signal = stop
                .received()
                .or_else(|| terminal_hung_up().then_some(libc::SIGHUP));
            if let Some(signal) = signal {
                return Ok(Step::End(Ended::Signal(signal)));
            }
            let mut wait = if dirty {
                Duration::ZERO
            } else {
                next_frame
                    .saturating_duration_since(Instant::now())
                    .min(POLL)
            };
            loop {
                let event = match input.recv_timeout(wait) {
                    Ok(event) => event,
                    Err(RecvTimeoutError::Timeout) => break,
                    Err(RecvTimeoutError::Disconnected) => {
                        return Ok(Step::End(Ended::Signal(libc::SIGHUP)))
                    }
                };
                wait = Duration::ZERO;
                dirty = true;
                match event {
                    Event::Key(k) if k.kind != KeyEventKind::Release => {
                        match on_key(showing, k, &self.study.study.display) {
                            KeyOutcome::Quit => return Ok(Step::End(Ended::Quit)),
                            KeyOutcome::Answer(a) => return Ok(Step::Answer(a)),
                            KeyOutcome::Back => return Ok(Step::Back),
                            KeyOutcome::Nothing => {}
                        }
                    }
                    Event::Mouse(m) => {
                        let at = (m.column as f32, m.row as f32);
                        match m.kind {
                            MouseEventKind::Down(_) => drag_from = Some(at),
                            MouseEventKind::Up(_) => drag_from = None,
                            MouseEventKind::Drag(_) => {
                                let from = drag_from.replace(at).unwrap_or(at);
                                turn(
                                    showing,
                                    &self.study.study.display,
                                    -DRAG_DEG_PER_CELL * (at.0 - from.0),
                                    DRAG_DEG_PER_CELL * 2.0 * (at.1 - from.1),
                                );
                            }
                            _ => {}
                        }
                    }
                    Event::Resize(..) => {
                        let _ = term.clear();
                    }
                    _ => {}
                }
            }
            if dirty || Instant::now() >= next_frame {
                self.present(term, collector, showing)?;
                dirty = false;
                next_frame = next_frame_time(showing.since, self.study.study.display.fps);
            }
        }
    }

    /// Puts an avatar on screen, facing the participant.
    fn show(&mut self, id: u32) -> Result<Showing> {
        let avatar = self
            .study
            .avatar(id)
            .ok_or_else(|| Error::input(format!("the study has no avatar {id}")))?;
        let recipe = self.study.recipe(avatar)?;
        let spec = self.study.category(avatar).database.clone();
        let workbench = self
            .workbenches
            .iter()
            .position(|(s, _)| *s == spec)
            .expect("every category's database was opened");
        // Every participant sees the finished avatar from its first frame:
        // a seam fit its post-processing asks for runs before it is shown.
        self.workbenches[workbench].1.settle(&recipe)?;
        Ok(Showing {
            id,
            position: self.done + 1,
            recipe,
            workbench,
            since: Instant::now(),
            yaw: 0.0,
            pitch: 0.0,
            stage: Stage::Looking,
            hint: String::new(),
            can_go_back: false,
        })
    }

    /// Renders the current frame of the loop and draws the screen.
    fn present(
        &mut self,
        term: &mut Terminal<CrosstermBackend<Collector>>,
        collector: &Collector,
        showing: &Showing,
    ) -> Result<()> {
        let size = term
            .size()
            .map_err(|e| Error::terminal(format!("cannot read the terminal size: {e}")))?;
        let area = Rect::new(0, 0, size.width, size.height);
        // The editor's minimum: below it the face would be too small to judge.
        if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
            let message = format!(
                "The study needs a terminal of at least {}x{} cells (this one is {}x{}): please make it larger.",
                MIN_SIZE.0, MIN_SIZE.1, area.width, area.height
            );
            term.draw(|f| f.render_widget(Paragraph::new(message).wrap(Wrap { trim: true }), area))
                .map_err(|e| Error::terminal(format!("cannot draw: {e}")))?;
            let mut out = SYNC_BEGIN.to_vec();
            out.extend(collector.take());
            out.extend_from_slice(SYNC_END);
            return write_to_terminal(&out);
        }
        let viewport = Rect::new(0, 1, area.width, area.height.saturating_sub(4));
        let target = ImageTarget::new(&self.graphics, (viewport.width, viewport.height));
        let image = if viewport.width >= 4 && viewport.height >= 2 {
            Some(self.render(showing, target.full)?)
        } else {
            None
        };
        let title = &self.study.study.title;
        let protocol = self.graphics.protocol;
        term.draw(|f| {
            draw(
                f,
                viewport,
                showing,
                title,
                self.total,
                protocol,
                image.as_ref(),
            )
        })
        .map_err(|e| Error::terminal(format!("cannot draw: {e}")))?;
        let mut out = SYNC_BEGIN.to_vec();
        out.extend(collector.take());
        if let Some(image) = &image {
            let encoded = target.encode(image).map_err(Error::terminal)?;
            place_image(&mut out, viewport, &encoded);
        }
        out.extend_from_slice(SYNC_END);
        write_to_terminal(&out)
    }

    /// The frame of the loop the clock has reached, seen from the orbit.
    fn render(&mut self, showing: &Showing, full: (u32, u32)) -> Result<RgbImage> {
        let display = &self.study.study.display;
        let mut recipe = showing.recipe.clone();
        let elapsed = showing.since.elapsed().as_secs_f64();
        recipe.animation.frame = (elapsed * display.fps) as usize;
        recipe.camera.yaw_deg = showing.yaw;
        recipe.camera.pitch_deg = showing.pitch;
        recipe.camera.radius = display.radius;
        let request = FrameRequest {
            recipe,
            debug: DebugView::default(),
            group: Group::Face,
            width: full.0.max(8),
            height: full.1.max(8),
            exact: true,
        };
        Ok(self.workbenches[showing.workbench]
            .1
            .render(&request)?
            .image)
    }
}

/// What a key did.
enum KeyOutcome {
    Nothing,
    Quit,
    Answer(Answer),
    /// Back to the previous avatar, whose answer is not final yet.
    Back,
}

/// How showing one avatar ended.
enum Step {
    Answer(Answer),
    Back,
    End(Ended),
}

fn turn(showing: &mut Showing, display: &Display, yaw: f32, pitch: f32) {
    (showing.yaw, showing.pitch) = display.clamp(showing.yaw + yaw, showing.pitch + pitch);
}

fn on_key(showing: &mut Showing, key: KeyEvent, display: &Display) -> KeyOutcome {
    let ctrl_c = key.code == KeyCode::Char('c') && key.modifiers.contains(KeyModifiers::CONTROL);
    if ctrl_c || key.code == KeyCode::Char('q') {
        return KeyOutcome::Quit;
    }
    match key.code {
        KeyCode::Left | KeyCode::Char('h') => turn(showing, display, -KEY_STEP_DEG, 0.0),
        KeyCode::Right | KeyCode::Char('l') => turn(showing, display, KEY_STEP_DEG, 0.0),
        KeyCode::Up | KeyCode::Char('k') => turn(showing, display, 0.0, KEY_STEP_DEG),
        KeyCode::Down | KeyCode::Char('j') => turn(showing, display, 0.0, -KEY_STEP_DEG),
        _ => {}
    }
    let answer = |showing: &Showing, regions: Vec<StudyGroup>| {
        KeyOutcome::Answer(Answer {
            avatar: showing.id,
            edited: !regions.is_empty(),
            regions,
            seconds: showing.since.elapsed().as_secs_f64(),
            yaw_deg: showing.yaw,
            pitch_deg: showing.pitch,
        })
    };
    match (showing.stage, key.code) {
        (Stage::Looking, KeyCode::Char('b') | KeyCode::Backspace) if showing.can_go_back => {
            KeyOutcome::Back
        }
        (Stage::Looking, KeyCode::Char('n' | 'N')) => answer(showing, Vec::new()),
        (Stage::Looking, KeyCode::Char('y' | 'Y')) => {
            showing.stage = Stage::Choosing([false; 4]);
            showing.hint.clear();
            KeyOutcome::Nothing
        }
        (Stage::Choosing(mut picked), KeyCode::Char(c @ '1'..='4')) => {
            let i = c as usize - '1' as usize;
            picked[i] = !picked[i];
            showing.stage = Stage::Choosing(picked);
            KeyOutcome::Nothing
        }
        (Stage::Choosing(_), KeyCode::Esc) => {
            showing.stage = Stage::Looking;
            KeyOutcome::Nothing
        }
        (Stage::Choosing(picked), KeyCode::Enter) => {
            let regions: Vec<StudyGroup> = StudyGroup::EDITABLE
                .into_iter()
                .zip(picked)
                .filter_map(|(g, on)| on.then_some(g))
                .collect();
            if regions.is_empty() {
                showing.hint = "choose at least one part (or Esc to go back)".into();
                KeyOutcome::Nothing
            } else {
                answer(showing, regions)
            }
        }
        _ => KeyOutcome::Nothing,
    }
}

fn draw(
    f: &mut Frame,
    viewport: Rect,
    showing: &Showing,
    title: &str,
    total: usize,
    protocol: Protocol,
    image: Option<&RgbImage>,
) {
    let area = f.area();
    let bold = Style::default().add_modifier(Modifier::BOLD);
    let heading = format!("{title}  -  avatar {} of {total}", showing.position);
    f.render_widget(
        Paragraph::new(Line::styled(heading, bold)),
        Rect::new(0, 0, area.width, 1),
    );
    if let Some(image) = image {
        if protocol == Protocol::Halfblocks {
            draw_halfblocks(f.buffer_mut(), viewport, image);
        } else {
            reserve_cells(f.buffer_mut(), viewport);
        }
    }
    let (question, keys) = match showing.stage {
        Stage::Looking => (
            "Is this face edited?   y = yes   n = no".to_string(),
            format!(
                "arrows or mouse drag: turn the head{}   q: stop (answers are saved)",
                if showing.can_go_back {
                    "   b: back to the last avatar"
                } else {
                    ""
                }
            ),
        ),
        Stage::Choosing(picked) => {
            let boxes: Vec<String> = StudyGroup::EDITABLE
                .iter()
                .zip(picked)
                .enumerate()
                .map(|(i, (g, on))| {
                    format!("{} [{}] {}", i + 1, if on { 'x' } else { ' ' }, g.label())
                })
                .collect();
            (
                format!("Which parts look edited?   {}", boxes.join("   ")),
                if showing.hint.is_empty() {
                    "1-4: toggle   Enter: confirm   Esc: back".to_string()
                } else {
                    showing.hint.clone()
                },
            )
        }
    };
    let bottom = area.height.saturating_sub(2);
    f.render_widget(
        Paragraph::new(Line::styled(question, bold)),
        Rect::new(0, bottom, area.width, 1),
    );
    f.render_widget(
        Paragraph::new(Line::raw(keys)),
        Rect::new(0, bottom + 1, area.width, 1),
    );
}
