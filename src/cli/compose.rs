//! `visage compose` (describe a composite) and `visage export` (write one frame).

use std::path::PathBuf;

use clap::{Args, ValueEnum};
use serde_json::json;

use super::DbArgs;
use crate::compose::recipe::{Fit, Recipe};
use crate::compose::{canonical_order, composite_hash, reordered, state_hash};
use crate::error::Result;
use crate::io::avatar::{neutral_offset, write_avatar, AvatarParams, FrameParams};
use crate::io::ply::write_splat_ply;
use crate::model::regions::{Group, Region};
use crate::pipeline::composer::{BuildTimings, Composer};
use crate::render::Backend;
use crate::text::printable;
use crate::train::fit_store::FitStore;
use crate::train::seam_fit::SeamFit;

/// Arguments of `visage compose`.
#[derive(Args, Debug, Clone)]
pub struct ComposeArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Recipe file (TOML).
    #[arg(long, value_name = "FILE")]
    recipe: PathBuf,
    /// Frame of the recipe's motion to pose (default: the recipe's frame).
    #[arg(long, value_name = "N")]
    frame: Option<usize>,
    #[command(flatten)]
    fit: FitArgs,
    /// Print one JSON document instead of text.
    #[arg(long)]
    json: bool,
}

/// The one-line error for a seam-fit option (`--seam-fit-size`,
/// `--seam-fit-renderer`) where no seam fit runs.
pub(super) fn without_fit(flag: &str) -> crate::error::Error {
    crate::error::Error::input(format!(
        "{flag} sets up a seam fit, and none runs: the recipe has no [post] fit = \"seams\" (give --seam-fit STEPS)"
    ))
}

/// The seam fit (method §7.12) of a command that composes a recipe.
#[derive(Args, Debug, Clone)]
pub struct FitArgs {
    /// Fit the composite's seams with this many steps before using it
    /// (colour and opacity of the Gaussians beside a change of source,
    /// fitted to what the sources draw there); 0: no fit. Default: as the
    /// recipe's `[post] fit` says (200 steps for "seams").
    #[arg(long, value_name = "STEPS")]
    seam_fit: Option<usize>,
    /// The width and height of the seam fit's views, in pixels (the fit
    /// needs the resolution the composite will be looked at) [default: 256].
    #[arg(long, value_name = "PX", value_parser = clap::value_parser!(u32).range(16..=4096))]
    seam_fit_size: Option<u32>,
    /// What draws the seam fit's views: cpu (the same bits on every
    /// machine), auto (a hardware GPU when there is one, else the CPU) or
    /// gpu (any adapter, f32) [default: cpu].
    #[arg(long, value_name = "RENDERER", value_parser = Backend::parse)]
    seam_fit_renderer: Option<Backend>,
    /// Fit even if the fit of this composite is stored, and store nothing
    /// (by default finished fits are kept in fits/ of visage's cache
    /// folder — $VISAGE_CACHE_DIR, else $XDG_CACHE_HOME/visage, else
    /// ~/.cache/visage — and read back).
    #[arg(long)]
    no_seam_fit_cache: bool,
}

impl FitArgs {
    /// No fit, whatever the recipe says (benchmarks of drawing speed).
    pub const OFF: FitArgs = FitArgs {
        seam_fit: Some(0),
        seam_fit_size: None,
        seam_fit_renderer: None,
        no_seam_fit_cache: false,
    };

    /// The recipe with `--seam-fit` applied to its `[post] fit`; a size for
    /// a fit that will not run is a mistake worth saying.
    fn apply(&self, recipe: &mut Recipe) -> Result<()> {
        match self.seam_fit {
            Some(0) => recipe.post.fit = Fit::Off,
            Some(_) => recipe.post.fit = Fit::Seams,
            None => {}
        }
        if recipe.post.fit == Fit::Off {
            if self.seam_fit_size.is_some() {
                return Err(without_fit("--seam-fit-size"));
            }
            if self.seam_fit_renderer.is_some() {
                return Err(without_fit("--seam-fit-renderer"));
            }
            if self.no_seam_fit_cache {
                return Err(without_fit("--no-seam-fit-cache"));
            }
        }
        Ok(())
    }

    fn options(&self) -> SeamFit {
        SeamFit {
            iterations: self.seam_fit.unwrap_or(SeamFit::default().iterations),
            size: self.seam_fit_size.unwrap_or(SeamFit::default().size),
            renderer: self
                .seam_fit_renderer
                .unwrap_or(SeamFit::default().renderer),
            ..SeamFit::default()
        }
    }
}

/// Export formats.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// World-space standard 3DGS PLY of one frame (INRIA layout).
    Ply,
    /// A GaussianAvatars avatar folder (point_cloud.ply + flame_param.npz): the
    /// composite's Gaussians, the blended neutral as static_offset, the motion.
    GaussianAvatars,
}

/// Arguments of `visage export`.
#[derive(Args, Debug, Clone)]
pub struct ExportArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Recipe file (TOML).
    #[arg(long, value_name = "FILE")]
    recipe: PathBuf,
    /// Output format.
    #[arg(long, value_enum)]
    format: ExportFormat,
    /// Frame of the recipe's motion (default: the recipe's frame).
    #[arg(long, value_name = "N")]
    frame: Option<usize>,
    /// Output path.
    #[arg(short = 'o', long = "output", value_name = "PATH")]
    output: PathBuf,
    #[command(flatten)]
    fit: FitArgs,
}

/// Loads the database and a recipe file, builds the composite, poses
/// `frame` and runs the seam fit the recipe (or `fit`) asks for, with a
/// progress bar.
pub fn build(
    db_args: &DbArgs,
    recipe_path: &std::path::Path,
    frame: Option<usize>,
    fit: &FitArgs,
) -> Result<(Composer, BuildTimings)> {
    let mut recipe = Recipe::load(recipe_path)?;
    fit.apply(&mut recipe)?;
    let (mut composer, timings) =
        Composer::build(&db_args.spec(), |_| recipe, frame, Some(recipe_path))?;
    composer.set_fit_options(fit.options());
    if !fit.no_seam_fit_cache {
        composer.set_fit_store(Some(FitStore::user()));
    }
    finish_fit(&mut composer)?;
    Ok((composer, timings))
}

/// Runs the composer's pending seam fit with a progress bar on stderr and
/// says what it did.
fn finish_fit(composer: &mut Composer) -> Result<()> {
    if composer.fit_progress().is_none() {
        return Ok(());
    }
    let bar = super::train::training_bar(0, "seam fit ");
    let report = composer.finish_fit(&mut |p| {
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
    })?;
    bar.finish_and_clear();
    if let Some(report) = report.filter(|r| r.fitted > 0) {
        let what = match composer.fit_store() {
            Some(store) if composer.fit_was_stored() => format!(
                "read the stored seam fit of {} Gaussians over {} views from {}",
                report.fitted,
                report.views,
                store.dir().display()
            ),
            _ => format!(
                "fitted {} Gaussians (at seams, and where the shape moved the light) over {} views",
                report.fitted, report.views
            ),
        };
        eprintln!(
            "visage: {what}: error against the fit's targets {:.2e} → {:.2e}",
            report.mse_before, report.mse_after
        );
    }
    // The fit is done and shows; a cache that cannot keep it costs only
    // the next run's time.
    if let Some(e) = composer.take_store_error() {
        eprintln!("visage: warning: the seam fit was not kept: {e}");
    }
    Ok(())
}

/// Loads the database, builds the composite of the recipe `choose` picks for
/// it (defaults that depend on the database's sources) and poses `frame`.
pub fn build_from(
    db_args: &DbArgs,
    frame: Option<usize>,
    choose: impl FnOnce(&crate::avatar::database::Database) -> Recipe,
) -> Result<(Composer, BuildTimings)> {
    Composer::build(&db_args.spec(), choose, frame, None)
}

/// Runs `visage compose`.
pub fn run_compose(args: &ComposeArgs) -> Result<()> {
    let (composer, timings) = build(&args.db, &args.recipe, args.frame, &args.fit)?;
    let report = report(&composer, &timings, args.frame);
    if args.json {
        println!("{report}");
    } else {
        print_text(&report);
    }
    Ok(())
}

/// Runs `visage export`.
pub fn run_export(args: &ExportArgs) -> Result<()> {
    let (composer, _) = build(&args.db, &args.recipe, args.frame, &args.fit)?;
    match args.format {
        ExportFormat::Ply => {
            let scene = composer.scene();
            write_splat_ply(&args.output, &scene)?;
            eprintln!(
                "visage: wrote {} Gaussians (SH degree {}) to {}",
                scene.len(),
                scene.sh_degree,
                args.output.display()
            );
        }
        ExportFormat::GaussianAvatars => {
            let engine = composer.engine();
            let c = composer.composite();
            let count = c
                .recipe
                .motion
                .map_or(1, |m| engine.database().motions[m].frames());
            let frames: Vec<FrameParams> = (0..count)
                .map(|k| {
                    let (expression, pose) = engine.frame_parameters(&c.recipe, k);
                    let offset = engine.frame_offset(&c.recipe, k);
                    FrameParams {
                        expression,
                        pose,
                        offset: offset.unwrap_or_default().to_vec(),
                    }
                })
                .collect();
            let model = &engine.database().model;
            let offset = neutral_offset(&model.template, &c.neutral);
            let params = AvatarParams {
                shape: &[],
                static_offset: &offset,
                frames: &frames,
            };
            let gaussians = reordered(&c.gaussians, &canonical_order(model, &c.gaussians));
            write_avatar(&args.output, &gaussians, &params, model)?;
            eprintln!(
                "visage: wrote a GaussianAvatars avatar ({} Gaussians, {count} frames) to {}",
                c.gaussians.len(),
                args.output.display()
            );
        }
    }
    Ok(())
}

fn round(x: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (x * p).round() / p
}

fn report(composer: &Composer, timings: &BuildTimings, frame: Option<usize>) -> serde_json::Value {
    let db = composer.engine().database();
    let c = composer.composite();
    let posed = composer.posed();
    let r = &c.recipe;
    let name = |f: usize| printable(&db.sources[f].name);
    let groups: Vec<_> = Group::ALL
        .iter()
        .map(|g| {
            let weights: serde_json::Map<String, serde_json::Value> = r.shape[g.index()]
                .iter()
                .enumerate()
                .filter(|(_, w)| **w > 0.0)
                .map(|(f, w)| (name(f), json!(w)))
                .collect();
            json!({"group": g.name(), "gaussians": name(r.gaussians[g.index()]), "shape": weights})
        })
        .collect();
    let regions: Vec<_> = Region::ALL
        .iter()
        .map(|reg| {
            let block = c.blocks.iter().find(|b| b.region == *reg && b.extra_from.is_none());
            let gain = c.colour_gains[reg.index()];
            json!({
                "region": reg.name(),
                "group": reg.group().name(),
                "source": block.map(|b| name(b.source)),
                "gaussians": block.map_or(0, |b| b.end - b.start),
                "colour_gain": [round(gain.x as f64, 4), round(gain.y as f64, 4), round(gain.z as f64, 4)],
            })
        })
        .collect();
    let extras: Vec<_> = c
        .blocks
        .iter()
        .filter_map(|b| {
            b.extra_from.map(|from| {
                json!({"from": from.name(), "into": b.region.name(), "source": name(b.source), "gaussians": b.end - b.start})
            })
        })
        .collect();
    let extra_total: usize = c
        .blocks
        .iter()
        .filter(|b| b.extra_from.is_some())
        .map(|b| b.end - b.start)
        .sum();
    let nan = posed.vertices.iter().any(|v| !v.is_finite());
    json!({
        "state_hash": state_hash(db, r),
        "composite_hash": composite_hash(composer.engine(), c, frame.unwrap_or(r.frame)),
        "database": printable(&db.fingerprint),
        "base": name(r.base),
        "groups": groups,
        "regions": regions,
        "smoothing": format!("{:?}", r.post.smoothing).to_lowercase(),
        "colour": format!("{:?}", r.post.colour).to_lowercase(),
        "membership": format!("{:?}", r.post.membership).to_lowercase(),
        "deform": format!("{:?}", r.post.deform).to_lowercase(),
        "anchor": format!("{:?}", r.post.anchor).to_lowercase(),
        "shading": format!("{:?}", r.post.shading).to_lowercase(),
        "skin": format!("{:?}", r.post.skin).to_lowercase(),
        "fit": format!("{:?}", r.post.fit).to_lowercase(),
        "seam_fit": composer.fit_report().map(|f| json!({
            "fitted": f.fitted,
            "views": f.views,
            "mse_before": f.mse_before,
            "mse_after": f.mse_after,
            "renderer": if f.on_gpu { "gpu" } else { "cpu" },
            "stored": composer.fit_was_stored(),
        })),
        "gaussians": c.gaussians.len(),
        "extra_gaussians": extra_total,
        "extras": extras,
        "solve_residual": c.residual,
        "frame": {
            "motion": r.motion.map(|m| printable(&db.motions[m].name)).unwrap_or_else(|| "rest".into()),
            "index": frame.unwrap_or(r.frame),
            "mode": format!("{:?}", r.mode).to_lowercase(),
            "residual": posed.residual,
            "vertices": posed.vertices.len(),
            "finite": !nan,
        },
        "timings_ms": {
            "database": round(timings.database, 3),
            "engine_setup": round(timings.setup, 3),
            "compose": round(timings.compose, 3),
            "pose": round(timings.pose, 3),
        },
    })
}

fn print_text(r: &serde_json::Value) {
    println!(
        "composite {} (base {}), state hash {}",
        r["gaussians"],
        r["base"].as_str().unwrap_or(""),
        r["state_hash"].as_str().unwrap_or("")
    );
    for g in r["groups"].as_array().into_iter().flatten() {
        let shape: Vec<String> = g["shape"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(k, v)| format!("{k} {:.3}", v.as_f64().unwrap_or(0.0)))
            .collect();
        println!(
            "  {:<6} Gaussians {:<8} shape {}",
            g["group"].as_str().unwrap_or(""),
            g["gaussians"].as_str().unwrap_or(""),
            shape.join(", ")
        );
    }
    println!("regions:");
    for reg in r["regions"].as_array().into_iter().flatten() {
        let gain = &reg["colour_gain"];
        println!(
            "  {:<17} {:<8} {:>6} Gaussians  colour gain {:.3} {:.3} {:.3}",
            reg["region"].as_str().unwrap_or(""),
            reg["source"].as_str().unwrap_or("-"),
            reg["gaussians"],
            gain[0].as_f64().unwrap_or(1.0),
            gain[1].as_f64().unwrap_or(1.0),
            gain[2].as_f64().unwrap_or(1.0)
        );
    }
    println!(
        "smoothing {} adds {} Gaussians; colour {}; regions by {}; deform {}; anchor {}; shading {}; skin {}; fit {}; blend residual {:.2e}",
        r["smoothing"].as_str().unwrap_or(""),
        r["extra_gaussians"],
        r["colour"].as_str().unwrap_or(""),
        r["membership"].as_str().unwrap_or(""),
        r["deform"].as_str().unwrap_or(""),
        r["anchor"].as_str().unwrap_or(""),
        r["shading"].as_str().unwrap_or(""),
        r["skin"].as_str().unwrap_or(""),
        r["fit"].as_str().unwrap_or(""),
        r["solve_residual"].as_f64().unwrap_or(0.0)
    );
    let t = &r["timings_ms"];
    println!(
        "timings: database {:.1} ms, engine set-up {:.1} ms, compose {:.2} ms, pose {:.2} ms",
        t["database"].as_f64().unwrap_or(0.0),
        t["engine_setup"].as_f64().unwrap_or(0.0),
        t["compose"].as_f64().unwrap_or(0.0),
        t["pose"].as_f64().unwrap_or(0.0)
    );
}
