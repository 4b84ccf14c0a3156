//! `visage lod FILE...`: builds (or finds and checks) the level-of-detail
//! cache of each scene file ahead of viewing it — on a bigger machine, or as
//! a cluster job — and says where it is, how big, and how it was come by.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use crate::error::Result;
use crate::pipeline::lod::{default_memory_budget, open_cached, parse_memory_budget, CacheOrigin};

/// Arguments of `visage lod`.
#[derive(Args, Debug, Clone)]
pub struct LodArgs {
    /// Scene files (.ply, .compressed.ply, .splat or .spz).
    #[arg(required = true)]
    files: Vec<PathBuf>,
    /// Folder for the caches (default: lod/ of visage's cache folder,
    /// $VISAGE_CACHE_DIR, else $XDG_CACHE_HOME/visage, else ~/.cache/visage).
    #[arg(long, value_name = "DIR")]
    cache_dir: Option<PathBuf>,
    /// Memory the build may take, and the check of a cache found reads
    /// within (e.g. 512M, 2G; default: a quarter of the machine's memory,
    /// at most 1.5G).
    #[arg(long, value_name = "SIZE", value_parser = parse_memory_budget)]
    memory_budget: Option<usize>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// The progress bar of one cache build's stages.
fn stage_bar() -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template("{spinner} [{bar:30}] {percent:>3}%, {eta} left")
            .expect("the template is valid")
            .progress_chars("=> "),
    )
}

/// Runs `visage lod`.
pub fn run(args: &LodArgs) -> Result<()> {
    let budget = args.memory_budget.unwrap_or_else(default_memory_budget);
    let mut reports = Vec::new();
    for file in &args.files {
        // A bar for each stage of a build (hidden when stderr is no
        // terminal), the stages' notes printed above it.
        let bar = stage_bar();
        let note = |line: &str| {
            let line = format!("visage: {line}");
            if bar.is_hidden() {
                eprintln!("{line}");
            } else {
                bar.set_position(0);
                bar.println(line);
            }
        };
        let progress = |done: u64, all: u64| {
            bar.set_length(all);
            bar.set_position(done);
        };
        let opened = open_cached(file, args.cache_dir.as_deref(), budget, &note, &progress);
        bar.finish_and_clear();
        let (tree, origin, cache) = opened?;
        let header = tree.header();
        let (status, why, seconds) = match origin {
            CacheOrigin::Found => ("found", String::new(), 0.0),
            CacheOrigin::Built { why, seconds, .. } => ("built", why, seconds),
        };
        reports.push(json!({
            "scene": file.display().to_string(),
            "cache": cache.display().to_string(),
            "status": status,
            "why": why,
            "build_seconds": seconds,
            "bytes": header.file_len(),
            "gaussians": header.source.gaussians,
            "nodes": header.nodes,
            "dropped": header.dropped,
        }));
    }
    if args.json {
        let doc = json!({ "caches": reports });
        println!("{}", serde_json::to_string_pretty(&doc).unwrap_or_default());
        return Ok(());
    }
    for r in &reports {
        let built = match r["status"].as_str() {
            Some("built") => format!(
                "built in {:.1} s ({})",
                r["build_seconds"].as_f64().unwrap_or(0.0),
                r["why"].as_str().unwrap_or("")
            ),
            _ => "found, still matching the file".to_string(),
        };
        println!(
            "{}: {} Gaussians in {} nodes ({} left out as undrawable); {} ({:.0} MB), {built}",
            r["scene"].as_str().unwrap_or(""),
            r["gaussians"],
            r["nodes"],
            r["dropped"],
            r["cache"].as_str().unwrap_or(""),
            r["bytes"].as_f64().unwrap_or(0.0) / 1e6,
        );
    }
    Ok(())
}
