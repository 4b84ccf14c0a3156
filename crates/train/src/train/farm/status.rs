//! Where every subject of a manifest stands, read from the database folder
//! alone (records, progress lines, locks asked about but never taken), so
//! `visage db status` is safe to run while jobs train.

use serde::Serialize;

use super::folder::{DbFolder, Progress};
use super::lock::holder;
use super::manifest::{Manifest, Subject};
use crate::error::Result;

/// One subject's state.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum State {
    /// Published with the manifest's options.
    Done {
        /// Gaussians.
        gaussians: usize,
        /// Held-out PSNR, dB.
        val_psnr_db: Option<f64>,
    },
    /// A process holds its lock.
    Running {
        /// Host, process and job of the holder.
        by: String,
        /// Iterations done and asked for, as last written.
        progress: Option<Progress>,
    },
    /// Its last run failed.
    Failed {
        /// Why.
        reason: String,
    },
    /// Stopped partway (signal, preemption, kill): a checkpoint waits.
    Interrupted {
        /// Iterations done and asked for, as last written.
        progress: Option<Progress>,
    },
    /// Published, but with options the manifest no longer asks for.
    Outdated,
    /// Nothing yet.
    NotStarted,
}

impl State {
    /// The state's one-word name.
    pub fn name(&self) -> &'static str {
        match self {
            State::Done { .. } => "done",
            State::Running { .. } => "running",
            State::Failed { .. } => "failed",
            State::Interrupted { .. } => "interrupted",
            State::Outdated => "outdated",
            State::NotStarted => "not started",
        }
    }
}

/// One line of `db status`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SubjectStatus {
    /// Subject id.
    pub id: String,
    /// Its shard, when the shard count was given.
    pub shard: Option<usize>,
    /// Its state.
    #[serde(flatten)]
    pub state: State,
}

/// The state of every subject, in manifest order.
pub fn manifest_status(manifest: &Manifest, shards: Option<usize>) -> Result<Vec<SubjectStatus>> {
    let folder = DbFolder::new(&manifest.output);
    manifest
        .subjects
        .iter()
        .map(|s| {
            Ok(SubjectStatus {
                id: s.id.clone(),
                shard: shards.map(|n| s.position % n.max(1)),
                state: subject_state(&folder, s)?,
            })
        })
        .collect()
}

fn subject_state(folder: &DbFolder, subject: &Subject) -> Result<State> {
    let id = subject.id.as_str();
    let progress = folder.read_progress(id);
    if let Some(by) = holder(&folder.lock(id))? {
        return Ok(State::Running { by, progress });
    }
    if let Some(record) = folder.current_record(subject) {
        return Ok(State::Done {
            gaussians: record.gaussians,
            val_psnr_db: record.val_psnr_db,
        });
    }
    if let Ok(reason) = std::fs::read_to_string(folder.failure(id)) {
        return Ok(State::Failed {
            reason: crate::text::printable(reason.trim()),
        });
    }
    if folder.checkpoint(id).exists() {
        return Ok(State::Interrupted { progress });
    }
    if folder.avatar(id).exists() {
        return Ok(State::Outdated);
    }
    Ok(State::NotStarted)
}
