//! `visage train --manifest` and `visage capture --manifest`: one shard of a
//! manifest's subjects, as a Slurm array task, a Kubernetes Indexed Job pod
//! or a plain process runs it (see `train::farm`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;

use super::train::training_bar;
use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::pipeline::DatabaseSpec;
use crate::train::farm::folder::DbFolder;
use crate::train::farm::manifest::{Manifest, Subject};
use crate::train::farm::run::{
    capture_subject, open_subject, train_subject, Captured, Heads, Hooks, Outcome,
};
use crate::train::farm::shard::Shard;
use crate::tui::terminal::{signal_name, StopSignal};

/// Which share of a manifest this process takes.
#[derive(Args, Debug, Clone, Default)]
pub struct ShardArgs {
    /// With --manifest: take shard I of N (subjects I, I+N, I+2N, …).
    /// Default: the Slurm array task or Kubernetes completion index, else all.
    #[arg(long, value_parser = Shard::parse, value_name = "I/N", requires = "manifest")]
    shard: Option<Shard>,
    /// With --manifest: the number of shards, when the scheduler gives only
    /// the index (Kubernetes) or a task was resubmitted alone.
    #[arg(
        long,
        value_name = "N",
        requires = "manifest",
        conflicts_with = "shard"
    )]
    shards: Option<usize>,
}

impl ShardArgs {
    /// The shard: given, or from the scheduler's environment.
    fn shard(&self) -> Result<Shard> {
        match self.shard {
            Some(s) => Ok(s),
            None => Shard::from_env(&|k| std::env::var(k).ok(), self.shards),
        }
    }
}

/// This shard's subjects, in manifest order.
fn shard_subjects(manifest: &Manifest, shard: Shard) -> Vec<&Subject> {
    manifest
        .subjects
        .iter()
        .filter(|s| shard.takes(s.position))
        .collect()
}

/// Runs `visage train --manifest`: checks every dataset of the shard first
/// (bad input touches nothing), then trains each subject that is neither
/// finished nor held by another process.
pub fn train_manifest(path: &Path, args: &ShardArgs) -> Result<()> {
    let stop = StopSignal::install()?;
    let manifest = Manifest::load(path)?;
    let shard = args.shard()?;
    let mine = shard_subjects(&manifest, shard);
    // Every dataset is checked before anything is touched, then opened
    // again when its turn comes: a dataset is only its file lists, and the
    // FLAME models are cached, so holding nothing between costs little.
    let mut heads = Heads::default();
    for subject in &mine {
        open_subject(subject, &mut heads)?;
    }
    let folder = DbFolder::new(&manifest.output);
    std::fs::create_dir_all(&folder.root).map_err(|e| Error::io("create", &folder.root, e))?;
    eprintln!(
        "visage: shard {shard} of {}: {} of {} subjects into {}",
        path.display(),
        mine.len(),
        manifest.subjects.len(),
        folder.root.display()
    );
    let mut failed = Vec::new();
    for subject in mine {
        if let Some(signal) = stop.received() {
            return Err(StopSignal::stopped(
                signal,
                format!(
                    "stopped by {} before subject {}; run the same command again to continue",
                    signal_name(signal),
                    subject.id
                ),
            ));
        }
        let start = Instant::now();
        let (dataset, head) = open_subject(subject, &mut heads)?;
        let bar = training_bar(subject.options.iterations, &format!("{} ", subject.id));
        let hooks = Hooks {
            stop: &|| stop.received().is_some(),
            step: &|r, _| {
                bar.set_position(r.iteration as u64);
                if r.iteration % 10 == 0 {
                    bar.set_message(format!("PSNR {:.1} dB", r.psnr));
                }
            },
        };
        let outcome = train_subject(&folder, subject, &dataset, head, &hooks)?;
        bar.finish_and_clear();
        let id = &subject.id;
        match outcome {
            Outcome::Trained {
                resumed_at,
                restarted,
                gaussians,
                val_psnr_db,
            } => {
                if let Some(why) = restarted {
                    eprintln!("visage: {id}: started over: {why}");
                }
                eprintln!(
                    "visage: {id}: trained{} in {:.1} s: {gaussians} Gaussians{}",
                    resumed_at.map_or(String::new(), |i| format!(" (resumed at iteration {i})")),
                    start.elapsed().as_secs_f64(),
                    val_psnr_db.map_or(String::new(), |p| format!(", validation PSNR {p:.2} dB"))
                );
            }
            Outcome::Finished => eprintln!("visage: {id}: finished already, skipped"),
            Outcome::Busy(by) => eprintln!("visage: {id}: being trained by {by}, skipped"),
            Outcome::Failed(why) => {
                eprintln!("visage: {id}: failed: {why}");
                failed.push(id.clone());
            }
            Outcome::Stopped { iteration } => {
                let signal = stop.received().unwrap_or(libc::SIGTERM);
                return Err(StopSignal::stopped(
                    signal,
                    format!(
                        "stopped by {} at iteration {iteration} of subject {id}; its checkpoint is in {}; run the same command again to continue",
                        signal_name(signal),
                        folder.work(id).display()
                    ),
                ));
            }
        }
    }
    if !failed.is_empty() {
        return Err(Error::CheckFailed(format!(
            "{} subject(s) failed: {} (the reasons: visage db status {})",
            failed.len(),
            failed.join(", "),
            path.display()
        )));
    }
    Ok(())
}

/// Runs `visage capture --manifest`: makes the dataset of each of the
/// shard's subjects that names a built-in person and has none yet.
pub fn capture_manifest(path: &Path, args: &ShardArgs) -> Result<()> {
    let manifest = Manifest::load(path)?;
    let shard = args.shard()?;
    let mine: Vec<&Subject> = shard_subjects(&manifest, shard)
        .into_iter()
        .filter(|s| s.capture.is_some())
        .collect();
    if mine.is_empty() {
        eprintln!(
            "visage: shard {shard} of {}: no subjects to capture",
            path.display()
        );
        return Ok(());
    }
    let mut databases: BTreeMap<u64, Database> = BTreeMap::new();
    for subject in mine {
        let spec = subject.capture.as_ref().expect("filtered on capture");
        if let std::collections::btree_map::Entry::Vacant(slot) = databases.entry(spec.seed) {
            let spec = DatabaseSpec {
                seed: spec.seed,
                gaussians_per_avatar: 1,
                ..DatabaseSpec::default()
            };
            slot.insert(spec.load()?.0);
        }
        let start = Instant::now();
        let done = capture_subject(&databases[&spec.seed], subject, spec, &|_, _| {})?;
        let where_to: &PathBuf = &subject.dataset;
        match done {
            Captured::Written { images } => eprintln!(
                "visage: {}: captured {images} images of {} into {} in {:.1} s",
                subject.id,
                spec.source,
                where_to.display(),
                start.elapsed().as_secs_f64()
            ),
            Captured::Present => eprintln!(
                "visage: {}: {} holds a dataset already, skipped",
                subject.id,
                where_to.display()
            ),
        }
    }
    Ok(())
}
