//! `visage db`: check a database folder, index it for the editor, and follow
//! a manifest's progress across shards (docs/scale-out.md).

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use serde::Serialize;

use crate::error::{Error, Result};
use crate::io::folder::{scan_avatar_folders, DbIndex, IndexedAvatar, INDEX_FORMAT};
use crate::train::farm::folder::{check_avatar, AvatarCheck, Progress};
use crate::train::farm::manifest::Manifest;
use crate::train::farm::run::Heads;
use crate::train::farm::status::{manifest_status, State};

/// Arguments of `visage db`.
#[derive(Args, Debug, Clone)]
pub struct DbCommandArgs {
    #[command(subcommand)]
    command: DbCommand,
}

#[derive(Subcommand, Debug, Clone)]
enum DbCommand {
    /// Load every avatar of a database folder and report what is wrong;
    /// with --manifest, also the subjects missing or failed.
    Check(CheckArgs),
    /// Check a database folder and write its index.json, which the editor
    /// and `study build` read instead of scanning the folder.
    Index(CheckArgs),
    /// Progress of a manifest across shards: done, running, failed,
    /// interrupted, not started (safe while jobs run).
    Status(StatusArgs),
}

/// Arguments of `visage db check` and `visage db index`.
#[derive(Args, Debug, Clone)]
struct CheckArgs {
    /// Database folder (default: the --manifest's output folder).
    #[arg(required_unless_present = "manifest")]
    dir: Option<PathBuf>,
    /// The manifest the folder was built from.
    #[arg(long, value_name = "TOML")]
    manifest: Option<PathBuf>,
    /// FLAME model the avatars were trained on (default: the config file's,
    /// else the built-in head).
    #[arg(long, value_name = "FILE", requires = "masks")]
    flame: Option<PathBuf>,
    /// FLAME masks (with --flame).
    #[arg(long, value_name = "FILE", requires = "flame")]
    masks: Option<PathBuf>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Arguments of `visage db status`.
#[derive(Args, Debug, Clone)]
struct StatusArgs {
    /// The manifest.
    manifest: PathBuf,
    /// Group by shard, for N shards.
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Runs `visage db`.
pub fn run(args: &DbCommandArgs) -> Result<()> {
    match &args.command {
        DbCommand::Check(a) => check(a, false),
        DbCommand::Index(a) => check(a, true),
        DbCommand::Status(a) => status(a),
    }
}

/// One row of `db check`.
#[derive(Serialize)]
struct Row {
    name: String,
    #[serde(flatten)]
    found: Found,
}

#[derive(Serialize)]
#[serde(tag = "status", rename_all = "snake_case")]
enum Found {
    Ok(AvatarCheck),
    Bad { reason: String },
    Missing,
    Outdated,
    Failed { reason: String },
    Running { by: String },
}

/// The FLAME files the folder's avatars are checked on: the arguments', else
/// the config file's, else none (the built-in head).
fn default_head_files(args: &CheckArgs) -> Result<Option<(PathBuf, PathBuf)>> {
    let config = crate::io::folder::read_config()?;
    match (
        args.flame.clone().or(config.flame),
        args.masks.clone().or(config.masks),
    ) {
        (Some(f), Some(m)) => Ok(Some((f, m))),
        (None, None) => Ok(None),
        _ => Err(Error::input(
            "--flame and --masks go together (or set both in the config file)",
        )),
    }
}

fn check(args: &CheckArgs, write_index: bool) -> Result<()> {
    let manifest = args.manifest.as_deref().map(Manifest::load).transpose()?;
    let dir = match (&args.dir, &manifest) {
        (Some(d), _) => d.clone(),
        (None, Some(m)) => m.output.clone(),
        (None, None) => unreachable!("clap requires a folder or a manifest"),
    };
    if !dir.is_dir() {
        return Err(Error::input(format!(
            "database folder {} does not exist",
            dir.display()
        )));
    }
    let default_files = default_head_files(args)?;
    // A manifest's subject is checked on its own FLAME files.
    let mut heads = Heads::default();
    let mut rows = Vec::new();
    for (name, path) in scan_avatar_folders(&dir)? {
        let files = manifest
            .as_ref()
            .and_then(|m| m.subject(&name))
            .and_then(|s| s.head_files.clone())
            .or_else(|| default_files.clone());
        let head = heads.get(None, files)?;
        let found = match check_avatar(&path, head) {
            Ok(c) => Found::Ok(c),
            Err(reason) => Found::Bad { reason },
        };
        rows.push(Row { name, found });
    }
    if let Some(m) = &manifest {
        manifest_rows(m, &dir, &mut rows)?;
    }
    if rows.is_empty() {
        return Err(Error::CheckFailed(format!(
            "{} holds no avatar folders (point_cloud.ply and flame_param.npz)",
            dir.display()
        )));
    }
    let problems = rows
        .iter()
        .filter(|r| !matches!(r.found, Found::Ok(_)))
        .count();
    let good = rows.len() - problems;
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "folder": dir.display().to_string(), "avatars": rows })
        );
    } else {
        print_rows(&rows);
    }
    if write_index {
        write_index_of(&dir, &rows)?;
    }
    if problems > 0 {
        return Err(Error::CheckFailed(format!(
            "{problems} problem(s) in {} ({good} avatar(s) fine){}",
            dir.display(),
            if write_index {
                "; the index lists the fine ones"
            } else {
                ""
            }
        )));
    }
    if !args.json {
        eprintln!(
            "visage: {good} avatar(s) in {} load{}",
            dir.display(),
            if write_index {
                "; wrote index.json"
            } else {
                ""
            }
        );
    }
    Ok(())
}

/// The manifest's view of the folder: subjects missing, running or failed
/// are added, avatars trained with options it no longer asks for marked.
fn manifest_rows(manifest: &Manifest, dir: &Path, rows: &mut Vec<Row>) -> Result<()> {
    let here = Manifest {
        output: dir.to_path_buf(),
        ..manifest.clone()
    };
    for status in manifest_status(&here, None)? {
        let found = match status.state {
            State::Done { .. } => continue,
            State::Running { by, .. } => Found::Running { by },
            State::Failed { reason } => Found::Failed { reason },
            State::Outdated => Found::Outdated,
            State::Interrupted { .. } | State::NotStarted => Found::Missing,
        };
        match rows.iter_mut().find(|r| r.name == status.id) {
            // A folder that does not load stays reported as bad.
            Some(row) if matches!(row.found, Found::Bad { .. }) => {}
            // Present but not the manifest's finished subject.
            Some(row) if matches!(found, Found::Missing) => row.found = Found::Outdated,
            Some(row) => row.found = found,
            None => rows.push(Row {
                name: status.id,
                found,
            }),
        }
    }
    Ok(())
}

fn print_rows(rows: &[Row]) {
    println!(
        "{:<24} {:>10} {:>10} {:>9}  status",
        "avatar", "gaussians", "iterations", "PSNR dB"
    );
    for r in rows {
        match &r.found {
            Found::Ok(c) => println!(
                "{:<24} {:>10} {:>10} {:>9}  ok",
                r.name,
                c.gaussians,
                c.iterations.map_or("-".into(), |i| i.to_string()),
                c.psnr_db.map_or("-".into(), |p| format!("{p:.2}")),
            ),
            Found::Bad { reason } => println!("{:<24} {:>32}  bad: {reason}", r.name, ""),
            Found::Missing => println!("{:<24} {:>32}  missing", r.name, ""),
            Found::Outdated => println!(
                "{:<24} {:>32}  outdated: trained with options the manifest no longer asks for",
                r.name, ""
            ),
            Found::Failed { reason } => println!("{:<24} {:>32}  failed: {reason}", r.name, ""),
            Found::Running { by } => println!("{:<24} {:>32}  running ({by})", r.name, ""),
        }
    }
}

/// Writes the index of the avatars that loaded; an empty one is refused.
fn write_index_of(dir: &Path, rows: &[Row]) -> Result<()> {
    let avatars: Vec<IndexedAvatar> = rows
        .iter()
        .filter_map(|r| match &r.found {
            Found::Ok(c) => Some(IndexedAvatar {
                name: r.name.clone(),
                gaussians: c.gaussians,
                iterations: c.iterations,
                psnr_db: c.psnr_db,
            }),
            _ => None,
        })
        .collect();
    if avatars.is_empty() {
        return Err(Error::CheckFailed(format!(
            "no avatar in {} loads: no index written",
            dir.display()
        )));
    }
    DbIndex {
        format: INDEX_FORMAT.into(),
        avatars,
    }
    .write(dir)?;
    Ok(())
}

fn status(args: &StatusArgs) -> Result<()> {
    let manifest = Manifest::load(&args.manifest)?;
    if args.shards == Some(0) {
        return Err(Error::input("--shards must be at least 1"));
    }
    let statuses = manifest_status(&manifest, args.shards)?;
    if args.json {
        println!(
            "{}",
            serde_json::json!({ "folder": manifest.output.display().to_string(), "subjects": statuses })
        );
        return Ok(());
    }
    for s in &statuses {
        let shard = s.shard.map_or(String::new(), |i| format!("shard {i:<3} "));
        let detail = match &s.state {
            State::Done {
                gaussians,
                val_psnr_db,
            } => format!(
                "{gaussians} Gaussians{}",
                val_psnr_db.map_or(String::new(), |p| format!(", validation PSNR {p:.2} dB"))
            ),
            State::Running { by, progress } => format!("{}by {by}", progress_text(*progress)),
            State::Failed { reason } => reason.clone(),
            State::Interrupted { progress } => progress.map_or(String::new(), |p| {
                format!("resumes from iteration {} of {}", p.checkpointed, p.total)
            }),
            State::Outdated => "trained with other options; will train again".into(),
            State::NotStarted => String::new(),
        };
        println!("{shard}{:<24} {:<12} {detail}", s.id, s.state.name());
    }
    let count = |name: &str| statuses.iter().filter(|s| s.state.name() == name).count();
    println!(
        "{} subjects: {} done, {} running, {} failed, {} interrupted, {} outdated, {} not started",
        statuses.len(),
        count("done"),
        count("running"),
        count("failed"),
        count("interrupted"),
        count("outdated"),
        count("not started")
    );
    Ok(())
}

fn progress_text(progress: Option<Progress>) -> String {
    progress.map_or(String::new(), |p| {
        let share = 100.0 * p.iteration as f64 / p.total.max(1) as f64;
        format!("{}/{} ({share:.0} %) ", p.iteration, p.total)
    })
}
