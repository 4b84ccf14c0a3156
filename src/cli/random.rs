//! `visage random`: random composites by the thesis's rules (§6.2.1), written
//! as recipes (and optionally rendered), the same for the same seed.

use std::path::PathBuf;

use clap::Args;

use super::values::{parse_group, parse_size};
use super::DbArgs;
use crate::compose::composition::{Attributes, StudyGroup};
use crate::compose::engine::Engine;
use crate::compose::random::{random_composites, RandomComposite, RandomOptions};
use crate::compose::rules::Rules;
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::pipeline::workbench::{check_parent, DebugView, FrameRequest};
use crate::pipeline::Workbench;
use crate::render::Backend;

/// Arguments of `visage random`. `--seed` seeds the draw, so the built-in
/// database's seed moves to `--db-seed`.
#[derive(Args, Debug, Clone)]
#[command(mut_arg("seed", |a| a.long("db-seed")))]
pub struct RandomArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Number of composites.
    #[arg(long, default_value_t = 10)]
    count: usize,
    /// Seed of the draw (the same seed gives the same composites).
    #[arg(long = "seed", id = "draw_seed", default_value_t = 1, value_name = "N")]
    draw_seed: u64,
    /// Sources to draw from (default: the whole database).
    #[arg(long, value_delimiter = ',', value_name = "NAME,…")]
    sources: Vec<String>,
    /// Groups that may be edited: eyes, nose, mouth, nhe (hair + neck + ears).
    #[arg(long, value_delimiter = ',', value_name = "GROUP,…", value_parser = parse_group)]
    groups: Vec<StudyGroup>,
    /// Constraints every composite meets (a rules file, see README).
    #[arg(long, value_name = "FILE")]
    constraints: Option<PathBuf>,
    /// Source labels on top of the database's own (`[name]` tables).
    #[arg(long, value_name = "FILE")]
    attributes: Option<PathBuf>,
    /// Folder to write `random-001.toml`, … into.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Also render each composite to a PNG beside its recipe.
    #[arg(long)]
    render: bool,
    /// Size of the renders.
    #[arg(long, default_value = "400x500", value_parser = parse_size)]
    size: (u32, u32),
    /// Renderer for `--render`.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
}

/// Runs `visage random`.
pub fn run(args: &RandomArgs) -> Result<()> {
    if args.count == 0 || args.count > 10_000 {
        return Err(Error::input("--count must be between 1 and 10000"));
    }
    let rules = match &args.constraints {
        Some(path) => Rules::load(path)?,
        None => Rules::default(),
    };
    check_parent(&args.out)?;
    let (db, _) = args.db.load()?;
    let mut attributes = Attributes::of_database(&db);
    if let Some(path) = &args.attributes {
        attributes = attributes.overlaid(Attributes::load(path)?);
    }
    let options = RandomOptions {
        count: args.count,
        seed: args.draw_seed,
        sources: args.sources.clone(),
        groups: args.groups.clone(),
        rules,
        attributes,
    };
    let composites = random_composites(&db, &options)?;
    std::fs::create_dir_all(&args.out).map_err(|e| Error::io("create", &args.out, e))?;
    let mut workbench = if args.render {
        Some(Workbench::new(Engine::new(db)?, args.renderer)?)
    } else {
        None
    };
    for (i, composite) in composites.iter().enumerate() {
        let path = args.out.join(format!("random-{:03}.toml", i + 1));
        std::fs::write(&path, composite.recipe.to_toml())
            .map_err(|e| Error::io("write", &path, e))?;
        if let Some(workbench) = &mut workbench {
            let request = FrameRequest {
                recipe: composite.recipe.clone(),
                debug: DebugView::default(),
                group: Group::Face,
                width: args.size.0,
                height: args.size.1,
                exact: true,
            };
            workbench.snapshot(&request, &path.with_extension("png"))?;
        }
        println!("{}  {}", path.display(), describe(composite));
    }
    Ok(())
}

/// One line: the sources, whose Gaussians each edited group shows, and the
/// blended shapes.
fn describe(c: &RandomComposite) -> String {
    let mut parts = vec![format!("base {}", c.recipe.base)];
    for (g, s) in &c.composition.groups {
        parts.push(format!("{}<-{s}", g.name()));
    }
    for (g, weights) in &c.blended {
        let w: Vec<String> = weights.iter().map(|(s, w)| format!("{s} {w:.3}")).collect();
        parts.push(format!("{} shape ({})", g.name(), w.join(", ")));
    }
    parts.join("  ")
}
