//! Training and capturing one subject of a manifest inside a database folder
//! ([`DbFolder`]): take the subject's lock, skip it when it is finished,
//! resume its checkpoint when there is one made with the same options, and
//! publish the avatar by rename.

use std::path::{Path, PathBuf};

use super::folder::{
    fingerprint_line, read_fingerprint, write_atomically, DbFolder, Progress, SubjectRecord,
    SUBJECT_RECORD,
};
use super::lock::{holder, host_name, this_process, SubjectLock};
use super::manifest::{CaptureSpec, Subject};
use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::model::head::HeadModel;
use crate::train::capture::{capture_sitter, CaptureOptions};
use crate::train::dataset::{head_model, Dataset};
use crate::train::posing::timestep_frames;
use crate::train::sitter::Sitter;
use crate::train::target::{evaluate_view, load_target};
use crate::train::trainer::{StepReport, TrainOptions, Trainer};

/// What became of one subject.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// Trained and published.
    Trained {
        /// The iteration a checkpoint brought, when the run resumed one.
        resumed_at: Option<usize>,
        /// Why a checkpoint there was not resumed, when one was dropped.
        restarted: Option<String>,
        /// Gaussians written.
        gaussians: usize,
        /// Mean PSNR on the validation views, in dB.
        val_psnr_db: Option<f64>,
    },
    /// Already finished with the manifest's options: skipped.
    Finished,
    /// Another process is training it: skipped.
    Busy(String),
    /// A signal stopped it; the checkpoint holds the run so far.
    Stopped {
        /// Iterations done.
        iteration: usize,
    },
    /// Training failed; the reason is in the work area's `failed` note.
    Failed(String),
}

/// What the caller hears and decides while a subject trains.
pub struct Hooks<'a> {
    /// Asked before each iteration: stop now (with a checkpoint)?
    pub stop: &'a dyn Fn() -> bool,
    /// Told after each iteration, with the iteration count.
    pub step: &'a dyn Fn(&StepReport, usize),
}

/// Head models by their FLAME files (`None`: the built-in head), loaded once
/// per process however many subjects share them.
#[derive(Default)]
pub struct Heads {
    loaded: Vec<(Option<(PathBuf, PathBuf)>, HeadModel)>,
}

impl Heads {
    /// The head model for these FLAME files; with no files, the built-in
    /// head, which a `dataset` given must have been captured from (asked
    /// every time: the dataset decides, not the cache).
    pub fn get(
        &mut self,
        dataset: Option<&Dataset>,
        files: Option<(PathBuf, PathBuf)>,
    ) -> Result<&HeadModel> {
        if let (None, Some(d)) = (&files, dataset) {
            d.check_builtin_head()?;
        }
        let at = match self.loaded.iter().position(|(k, _)| *k == files) {
            Some(at) => at,
            None => {
                let flame = files.as_ref().map(|(f, m)| (f.as_path(), m.as_path()));
                let head = head_model(None, flame)?;
                self.loaded.push((files, head));
                self.loaded.len() - 1
            }
        };
        Ok(&self.loaded[at].1)
    }
}

/// A subject's dataset and head model, checked before anything trains: a
/// missing or malformed dataset is the manifest's fault, said in one line.
pub fn open_subject(subject: &Subject, heads: &mut Heads) -> Result<(Dataset, HeadModel)> {
    let in_subject = |e: Error| match e {
        Error::Input(m) => Error::input(format!("subject '{}': {m}", subject.id)),
        other => other,
    };
    let dataset = Dataset::load(&subject.dataset).map_err(in_subject)?;
    let head = heads
        .get(Some(&dataset), subject.head_files.clone())
        .map_err(in_subject)?
        .clone();
    Ok((dataset, head))
}

/// Trains one subject into the database folder, unless it is finished or
/// another process holds it.
pub fn train_subject(
    folder: &DbFolder,
    subject: &Subject,
    dataset: &Dataset,
    head: HeadModel,
    hooks: &Hooks,
) -> Result<Outcome> {
    let id = subject.id.as_str();
    folder.prepare(id)?;
    let Some(_lock) = SubjectLock::try_acquire(&folder.lock(id), &this_process())? else {
        let who = holder(&folder.lock(id))?.unwrap_or_else(|| "another process".into());
        return Ok(Outcome::Busy(who));
    };
    folder.recover(id)?;
    // Checked under the lock: a shard that finished it a moment ago has
    // published by now.
    if folder.finished(subject, Some(&head)) {
        return Ok(Outcome::Finished);
    }
    folder.clear_leftovers(id)?;
    if (hooks.stop)() {
        return Ok(Outcome::Stopped { iteration: 0 });
    }
    let (mut trainer, resumed_at, restarted) = match start(folder, subject, dataset, head) {
        Ok(started) => started,
        Err(e @ Error::Io(_)) => return Err(e),
        Err(e) => return fail(folder, id, &e.to_string()),
    };
    let total = trainer.iterations();
    let mut progress = Progress {
        iteration: trainer.iteration(),
        total,
        checkpointed: resumed_at.unwrap_or(0),
    };
    folder.write_progress(id, progress)?;
    let first = trainer.iteration();
    while trainer.iteration() < total {
        if (hooks.stop)() {
            if trainer.iteration() > first {
                save(folder, id, &mut trainer, &mut progress)?;
            }
            return Ok(Outcome::Stopped {
                iteration: trainer.iteration(),
            });
        }
        let report = match trainer.step() {
            Ok(r) => r,
            Err(e) => return fail(folder, id, &e.to_string()),
        };
        (hooks.step)(&report, total);
        if subject.checkpoint_every > 0 && report.iteration % subject.checkpoint_every == 0 {
            save(folder, id, &mut trainer, &mut progress)?;
        } else if report.iteration % 25 == 0 {
            progress.iteration = report.iteration;
            folder.write_progress(id, progress)?;
        }
    }
    // A rerun after a failure below resumes here rather than training again.
    if subject.checkpoint_every > 0 && total % subject.checkpoint_every != 0 {
        save(folder, id, &mut trainer, &mut progress)?;
    }
    let val_psnr_db = match validation_psnr(&trainer, dataset, subject) {
        Ok(p) => p,
        Err(e @ Error::Io(_)) => return Err(e),
        Err(e) => return fail(folder, id, &format!("validation: {e}")),
    };
    let record = SubjectRecord {
        id: id.to_string(),
        fingerprint: subject.options.fingerprint(),
        iterations: total,
        gaussians: trainer.model.len(),
        val_psnr_db,
    };
    let staged = folder.staging(id);
    if staged.exists() {
        std::fs::remove_dir_all(&staged).map_err(|e| Error::io("remove", &staged, e))?;
    }
    trainer.export(&staged)?;
    let text = serde_json::to_string_pretty(&record).expect("records serialise") + "\n";
    std::fs::write(staged.join(SUBJECT_RECORD), text)
        .map_err(|e| Error::io("write", &staged.join(SUBJECT_RECORD), e))?;
    folder.publish(id)?;
    folder.write_progress(
        id,
        Progress {
            iteration: total,
            total,
            checkpointed: 0,
        },
    )?;
    Ok(Outcome::Trained {
        resumed_at,
        restarted,
        gaussians: record.gaussians,
        val_psnr_db,
    })
}

/// A fresh trainer, or one resumed from a checkpoint made with the same
/// options; a checkpoint that cannot be resumed is dropped and said so.
fn start(
    folder: &DbFolder,
    subject: &Subject,
    dataset: &Dataset,
    head: HeadModel,
) -> Result<(Trainer, Option<usize>, Option<String>)> {
    let id = subject.id.as_str();
    let o = &subject.options;
    let options = TrainOptions {
        iterations: o.iterations,
        seed: o.seed,
        size: o.size,
        background: o.background(),
        renderer: o.backend(),
        holes: o.holes(),
    };
    let checkpoint = folder.checkpoint(id);
    let mut restarted = None;
    if checkpoint.exists() {
        let same = read_fingerprint(&folder.checkpoint_fingerprint(id))
            .is_some_and(|f| f == o.fingerprint());
        if same {
            match Trainer::resume(dataset, head.clone(), options.clone(), &checkpoint) {
                Ok(trainer) => {
                    let at = trainer.iteration();
                    return Ok((trainer, Some(at), None));
                }
                Err(e) => restarted = Some(format!("its checkpoint was unreadable ({e})")),
            }
        } else {
            restarted = Some("its checkpoint was made with other options".into());
        }
        std::fs::remove_file(&checkpoint).map_err(|e| Error::io("remove", &checkpoint, e))?;
    }
    write_atomically(
        &folder.checkpoint_fingerprint(id),
        fingerprint_line(o).as_bytes(),
    )?;
    Ok((Trainer::new(dataset, head, options)?, None, restarted))
}

/// Saves the checkpoint and the progress line.
fn save(folder: &DbFolder, id: &str, trainer: &mut Trainer, progress: &mut Progress) -> Result<()> {
    trainer.save_checkpoint(&folder.checkpoint(id))?;
    progress.iteration = trainer.iteration();
    progress.checkpointed = trainer.iteration();
    folder.write_progress(id, *progress)
}

/// Records why a subject failed.
fn fail(folder: &DbFolder, id: &str, why: &str) -> Result<Outcome> {
    write_atomically(&folder.failure(id), format!("{why}\n").as_bytes())?;
    Ok(Outcome::Failed(why.to_string()))
}

/// Mean PSNR over the dataset's validation views at the training size.
fn validation_psnr(trainer: &Trainer, dataset: &Dataset, subject: &Subject) -> Result<Option<f64>> {
    if dataset.val.is_empty() {
        return Ok(None);
    }
    let frames = timestep_frames(dataset, trainer.head(), &dataset.val)?;
    let background = subject.options.background();
    let mut sum = 0.0;
    for view in &dataset.val {
        let target = load_target(view, subject.options.size, background)?;
        sum += evaluate_view(&trainer.model, &frames[&view.timestep], &target, background).1;
    }
    Ok(Some(sum / dataset.val.len() as f64))
}

/// What became of one subject's capture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Captured {
    /// The dataset was written.
    Written {
        /// Images.
        images: usize,
    },
    /// A dataset is there already (from an earlier run or another shard).
    Present,
}

/// Makes a subject's dataset from a built-in person of `db` unless a
/// readable one is there: written beside its place and renamed in, so a
/// trainer never reads half a capture.
pub fn capture_subject(
    db: &Database,
    subject: &Subject,
    spec: &CaptureSpec,
    progress: &dyn Fn(u64, u64),
) -> Result<Captured> {
    let target = &subject.dataset;
    if target.exists() {
        // Never overwrite a folder we did not make: a readable dataset is
        // kept, anything else is the manifest's mistake.
        return match Dataset::load(target) {
            Ok(_) => Ok(Captured::Present),
            Err(e) => Err(Error::input(format!(
                "subject '{}': {} is there but is no dataset ({e}); move it or change the manifest",
                subject.id,
                target.display()
            ))),
        };
    }
    let index = db
        .sources
        .iter()
        .position(|s| s.name == spec.source)
        .ok_or_else(|| {
            Error::input(format!(
                "subject '{}': unknown built-in person '{}'",
                subject.id,
                crate::text::printable(&spec.source)
            ))
        })?;
    let (w, h) = crate::text::parse_image_size(&spec.size).map_err(Error::input)?;
    let host = this_host();
    remove_dead_partials(target, &host);
    let partial = sibling(target, &format!("partial-{host}-{}", std::process::id()));
    if partial.exists() {
        std::fs::remove_dir_all(&partial).map_err(|e| Error::io("remove", &partial, e))?;
    }
    let options = CaptureOptions {
        source: spec.source.clone(),
        size: [w, h],
        cameras: spec.cameras,
        frames: spec.frames,
        motion: spec.motion.clone(),
        ring: spec.ring,
    };
    let summary = capture_sitter(db, &options, &Sitter::source(db, index), &partial, progress)?;
    if let Some(parent) = target.parent() {
        std::fs::create_dir_all(parent).map_err(|e| Error::io("create", parent, e))?;
    }
    match std::fs::rename(&partial, target) {
        Ok(()) => Ok(Captured::Written {
            images: summary.images,
        }),
        // Another shard captured it meanwhile (the captures are identical).
        Err(_) if Dataset::load(target).is_ok() => {
            let _ = std::fs::remove_dir_all(&partial);
            Ok(Captured::Present)
        }
        Err(e) => Err(Error::io("rename into", target, e)),
    }
}

/// This machine's name as it goes into the names of half-written captures
/// (no `-`, which separates it from the process id there).
fn this_host() -> String {
    host_name().replace(['/', '-', '?'], "_")
}

/// Removes half-written captures of `target` that processes of this host
/// which are gone left behind (killed mid-capture). Other hosts' are kept:
/// whether their writer lives cannot be told from here.
fn remove_dead_partials(target: &Path, host: &str) {
    let (Some(parent), Some(name)) = (target.parent(), target.file_name()) else {
        return;
    };
    let prefix = format!("{}.partial-{host}-", name.to_string_lossy());
    let Ok(entries) = std::fs::read_dir(if parent.as_os_str().is_empty() {
        Path::new(".")
    } else {
        parent
    }) else {
        return;
    };
    for entry in entries.filter_map(|e| e.ok()) {
        let file = entry.file_name().to_string_lossy().into_owned();
        let Some(pid) = file
            .strip_prefix(&prefix)
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        let alive = Path::new(&format!("/proc/{pid}")).exists();
        if !alive && pid != std::process::id() {
            let _ = std::fs::remove_dir_all(entry.path());
        }
    }
}

/// `dir.suffix` beside `dir`.
fn sibling(dir: &Path, suffix: &str) -> PathBuf {
    let mut name = dir.file_name().unwrap_or_default().to_os_string();
    name.push(format!(".{suffix}"));
    dir.with_file_name(name)
}
