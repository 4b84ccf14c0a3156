//! `visage cache`: where visage's cache folder is, what each kind of file in
//! it takes (level-of-detail caches, seam fits), and `--clear` to give the
//! disk back. Everything in it is made again when needed.

use clap::{Args, ValueEnum};
use indicatif::HumanBytes;
use serde_json::json;

use crate::error::Result;
use crate::io::cache::{cache_root, CacheKind, CacheUsage, CACHE_KINDS};

/// What `--clear` removes.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum Clear {
    /// Level-of-detail caches (`lod/`).
    Lod,
    /// Seam fits (`fits/`).
    Fits,
    /// Both.
    All,
}

impl Clear {
    fn covers(self, kind: &CacheKind) -> bool {
        match self {
            Clear::Lod => kind.folder == "lod",
            Clear::Fits => kind.folder == "fits",
            Clear::All => true,
        }
    }
}

/// Arguments of `visage cache`.
#[derive(Args, Debug, Clone)]
pub struct CacheArgs {
    /// Remove these files (writes under way in a running visage are left
    /// alone); they are made again when next needed.
    #[arg(long, value_enum, value_name = "WHAT")]
    clear: Option<Clear>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Runs `visage cache`.
pub fn run(args: &CacheArgs) -> Result<()> {
    let root = cache_root();
    let mut kinds = Vec::new();
    for kind in &CACHE_KINDS {
        let removed = match args.clear {
            Some(clear) if clear.covers(kind) => Some(kind.clear(&root)?),
            _ => None,
        };
        kinds.push((kind, kind.usage(&root)?, removed));
    }
    if args.json {
        let entry = |u: &CacheUsage| {
            json!({
                "files": u.files,
                "bytes": u.bytes,
                "partial": u.partial,
                "partial_bytes": u.partial_bytes,
            })
        };
        let mut doc = json!({ "folder": root.display().to_string() });
        for (kind, usage, removed) in &kinds {
            doc[kind.folder] = json!({
                "what": kind.what,
                "usage": entry(usage),
                "removed": removed.as_ref().map(entry),
            });
        }
        println!("{doc}");
        return Ok(());
    }
    println!("visage's cache folder: {}", root.display());
    for (kind, usage, removed) in &kinds {
        let mut line = format!(
            "  {:<6} {:>5} file{} {:>11}  {}",
            format!("{}/", kind.folder),
            usage.files,
            if usage.files == 1 { " " } else { "s" },
            HumanBytes(usage.bytes).to_string(),
            kind.what
        );
        if usage.partial > 0 {
            line += &format!(
                " (and {} being written or left by a killed run, {})",
                usage.partial,
                HumanBytes(usage.partial_bytes)
            );
        }
        println!("{line}");
        if let Some(r) = removed {
            println!(
                "         removed {} file{} ({})",
                r.files + r.partial,
                if r.files + r.partial == 1 { "" } else { "s" },
                HumanBytes(r.bytes + r.partial_bytes)
            );
        }
    }
    Ok(())
}
