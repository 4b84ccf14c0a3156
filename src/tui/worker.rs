//! The render worker: a thread that owns the workbench and draws frames,
//! performs command effects (files) and answers questions about the view,
//! while the interface thread stays responsive. Only the latest frame request
//! is kept (an older one is dropped unseen); effects and questions queue in
//! order.

use std::path::PathBuf;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use super::graphics::ImageTarget;
use crate::compose::recipe::Recipe;
use crate::editor::perform;
use crate::editor::state::Effect;
use crate::pipeline::composer::FitProgress;
use crate::pipeline::workbench::{FrameRequest, FrameResult, Workbench};
use crate::render::image::RgbImage;
use crate::scene::camera::Orbit;

/// A frame to draw, tagged with the interface's version of the picture.
pub struct FrameJob {
    /// What to draw.
    pub request: FrameRequest,
    /// The interface's picture version it answers.
    pub version: u64,
    /// How to encode it for the terminal.
    pub target: ImageTarget,
}

/// Work besides frames, done in the order asked.
pub enum Task {
    /// A command's effect, with the recipe and the view it was asked in.
    Effect(Effect, Box<(Recipe, FrameRequest)>),
    /// The depth under the centre of the view (to orbit about what is there).
    Pivot(FrameRequest),
    /// Small pictures of each source's face, encoded for the terminal.
    Thumbnails(Vec<(FrameRequest, ImageTarget)>),
}

/// What the worker sends back.
pub enum Reply {
    /// A drawn frame.
    Frame {
        /// The picture version it answers.
        version: u64,
        /// The frame and its figures.
        result: Box<FrameResult>,
        /// The frame encoded for the terminal.
        encoded: Vec<u8>,
        /// The cells the encoded frame covers (a frame for another layout
        /// must not be placed: it would overflow and scroll the terminal).
        cells: (u16, u16),
        /// Encoding time (ms).
        encode_ms: f64,
        /// Drawn at full accuracy.
        exact: bool,
    },
    /// An effect was performed (or failed): a message, and whether it wrote
    /// the recipe.
    Done {
        /// For the status line.
        message: String,
        /// The recipe was saved.
        saved_recipe: bool,
    },
    /// The depth under the view's centre for a camera (`None`: nothing there).
    Pivot(Orbit, Option<f32>),
    /// Source thumbnails, encoded, in the order asked.
    Thumbnails(Vec<(RgbImage, Vec<u8>)>),
    /// A frame or question failed.
    Failed(String),
    /// The seam fit went on in the background: how far it is, or `None`
    /// once it is done (the composite shows it from the next frame), and
    /// whether it was read from the fit store rather than made.
    Fit(Option<FitProgress>, bool),
}

#[derive(Default)]
struct Mailbox {
    frame: Option<FrameJob>,
    tasks: Vec<Task>,
    stop: bool,
}

/// The worker thread and its mailbox.
pub struct RenderWorker {
    mailbox: Arc<(Mutex<Mailbox>, Condvar)>,
    replies: Receiver<Reply>,
    handle: Option<JoinHandle<()>>,
}

impl RenderWorker {
    /// Starts the worker on a workbench.
    pub fn spawn(workbench: Workbench) -> Self {
        let mailbox = Arc::new((Mutex::new(Mailbox::default()), Condvar::new()));
        let (tx, replies) = channel();
        let handle = {
            let mailbox = Arc::clone(&mailbox);
            std::thread::spawn(move || work(workbench, &mailbox, &tx))
        };
        Self {
            mailbox,
            replies,
            handle: Some(handle),
        }
    }

    fn with_mailbox(&self, f: impl FnOnce(&mut Mailbox)) {
        let (lock, cv) = &*self.mailbox;
        f(&mut lock.lock().unwrap_or_else(|e| e.into_inner()));
        cv.notify_one();
    }

    /// Asks for a frame, replacing any frame not yet started.
    pub fn draw(&self, job: FrameJob) {
        self.with_mailbox(|m| m.frame = Some(job));
    }

    /// Queues a task.
    pub fn ask(&self, task: Task) {
        self.with_mailbox(|m| m.tasks.push(task));
    }

    /// The next reply, if one is waiting.
    pub fn try_reply(&self) -> Option<Reply> {
        self.replies.try_recv().ok()
    }
}

impl Drop for RenderWorker {
    fn drop(&mut self) {
        self.with_mailbox(|m| m.stop = true);
        if let Some(handle) = self.handle.take() {
            let _ = handle.join();
        }
    }
}

enum Job {
    Frame(FrameJob),
    Task(Task),
    /// A unit of the composite's seam fit, done while nothing else waits.
    FitStep,
}

fn work(mut workbench: Workbench, mailbox: &(Mutex<Mailbox>, Condvar), replies: &Sender<Reply>) {
    loop {
        let job = {
            let (lock, cv) = mailbox;
            let mut m = lock.lock().unwrap_or_else(|e| e.into_inner());
            loop {
                if m.stop {
                    return;
                }
                if !m.tasks.is_empty() {
                    break Job::Task(m.tasks.remove(0));
                }
                if let Some(f) = m.frame.take() {
                    break Job::Frame(f);
                }
                if workbench.fit_progress().is_some() {
                    break Job::FitStep;
                }
                m = cv.wait(m).unwrap_or_else(|e| e.into_inner());
            }
        };
        let reply = match job {
            Job::Frame(f) => draw(&mut workbench, f),
            Job::Task(task) => {
                let fitting = workbench.fit_progress().is_some();
                let reply = run_task(&mut workbench, task);
                // A still or an export finishes the fit first: say so before
                // the task's own reply, which the status line shows last.
                if fitting
                    && workbench.fit_progress().is_none()
                    && replies
                        .send(Reply::Fit(None, workbench.fit_was_stored()))
                        .is_err()
                {
                    return;
                }
                reply
            }
            Job::FitStep => {
                let reply = fit_step(&mut workbench);
                // The fit shows either way; a cache that cannot keep it is
                // said after it, on the status line.
                match workbench.take_store_error() {
                    Some(e) => {
                        if replies.send(reply).is_err() {
                            return;
                        }
                        Reply::Failed(format!("the seam fit was not kept in the cache: {e}"))
                    }
                    None => reply,
                }
            }
        };
        if replies.send(reply).is_err() {
            return;
        }
    }
}

fn draw(workbench: &mut Workbench, job: FrameJob) -> Reply {
    match workbench.render(&job.request) {
        Ok(result) => {
            let t = Instant::now();
            let encoded = job.target.encode(&result.image).unwrap_or_default();
            Reply::Frame {
                version: job.version,
                encode_ms: t.elapsed().as_secs_f64() * 1e3,
                exact: job.request.exact,
                result: Box::new(result),
                encoded,
                cells: job.target.cells,
            }
        }
        Err(e) => Reply::Failed(format!("render failed: {e}")),
    }
}

/// One unit of the seam fit; a unit takes a fraction of a second, so a
/// frame asked for meanwhile waits at most that long.
fn fit_step(workbench: &mut Workbench) -> Reply {
    match workbench.fit_step() {
        Ok(_) => Reply::Fit(workbench.fit_progress(), workbench.fit_was_stored()),
        Err(e) => Reply::Failed(format!(
            "seam fit failed (the composite shows unfitted): {e}"
        )),
    }
}

fn run_task(workbench: &mut Workbench, task: Task) -> Reply {
    match task {
        Task::Effect(effect, asked) => {
            let (recipe, view) = *asked;
            match perform(&effect, &recipe, &view, workbench, &|p| PathBuf::from(p)) {
                Ok(done) => Reply::Done {
                    message: done.message,
                    saved_recipe: matches!(effect, Effect::SaveRecipe(_)),
                },
                Err(e) => Reply::Done {
                    message: format!("{}: {e}", failure(&effect)),
                    saved_recipe: false,
                },
            }
        }
        Task::Pivot(view) => match workbench.centre_depth(&view) {
            Ok(depth) => Reply::Pivot(view.recipe.camera, depth),
            Err(e) => Reply::Failed(format!("cannot find the depth at the centre: {e}")),
        },
        Task::Thumbnails(requests) => {
            let mut out = Vec::new();
            for (request, target) in requests {
                match workbench.render(&request) {
                    Ok(frame) => {
                        let encoded = target.encode(&frame.image).unwrap_or_default();
                        out.push((frame.image, encoded));
                    }
                    Err(e) => return Reply::Failed(format!("thumbnails: {e}")),
                }
            }
            Reply::Thumbnails(out)
        }
    }
}

/// What failed, for the status line.
fn failure(effect: &Effect) -> &'static str {
    match effect {
        Effect::SaveRecipe(_) => "saving the recipe failed",
        Effect::ExportPly(_) => "export failed",
        Effect::Snapshot(..) => "snapshot failed",
    }
}
