//! `visage bench composites`: how far composites are from their ground
//! truth. A fixed set of recipes (`recipes/bench/`: random composites by the
//! thesis's rules and hard cases chosen on purpose), sources captured and
//! trained once and cached, each recipe's ground truth captured and the
//! composite evaluated (`eval --composite`); one row per recipe and the mean,
//! as a table or one JSON document.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use serde::Serialize;

use super::stats::emit;
use crate::avatar::database::Database;
use crate::cli::values::parse_size;
use crate::compose::recipe::{ColourCorrection, Fit, PostProcess, Recipe, Smoothing};
use crate::error::{Error, Result};
use crate::pipeline::DatabaseSpec;
use crate::render::Backend;
use crate::train::capture::{capture, capture_sitter, CaptureOptions};
use crate::train::composite_eval::{evaluate_composite, CompositeReport, EvalOptions};
use crate::train::dataset::Dataset;
use crate::train::seam_fit::SeamFit;
use crate::train::sitter::{Seams, Sitter, Tone};
use crate::train::trainer::{TrainOptions, Trainer};

/// Arguments of `visage bench composites`.
#[derive(Args, Debug, Clone)]
pub struct CompositesBenchArgs {
    /// Folder of recipes to measure (one composite per `.toml`).
    #[arg(long, default_value = "recipes/bench", value_name = "DIR")]
    recipes: PathBuf,
    /// Image size of the captures (training and ground truth).
    #[arg(long, value_parser = parse_size, default_value = "128x128", value_name = "WxH")]
    size: (u32, u32),
    /// Cameras of the rig.
    #[arg(long, default_value_t = 8)]
    cameras: usize,
    /// Timesteps of the motion captured.
    #[arg(long, default_value_t = 4)]
    frames: usize,
    /// Training iterations per source.
    #[arg(long, default_value_t = 1500)]
    iterations: usize,
    /// Where trained sources are kept between runs (one folder per capture
    /// and training setting).
    #[arg(long, default_value = "target/composite-sources", value_name = "DIR")]
    cache: PathBuf,
    /// Rasteriser the sources train with.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Border band width in pixels.
    #[arg(long, default_value_t = 3)]
    border_px: u32,
    /// Whose post-processing the composites get: as each recipe says, the
    /// thesis's (membership by parent triangle, thesis smoothing and colour),
    /// or ours (the best measured: by place, colour seams, semantic colour).
    #[arg(long, value_enum, default_value = "recipe")]
    pipeline: Pipeline,
    /// Steps of the seam fit (method §7.12) run for the composites whose
    /// post-processing asks for it (`[post] fit = "seams"`, as `--pipeline
    /// ours` does; `thesis` never fits); 0: none.
    #[arg(long, value_name = "STEPS", default_value_t = SeamFit::default().iterations)]
    seam_fit: usize,
    /// What draws the seam fit's views: cpu (the same bits on every
    /// machine), auto (a hardware GPU when there is one, else the CPU) or
    /// gpu (any adapter, f32).
    #[arg(long, value_name = "RENDERER", value_parser = Backend::parse, default_value = "cpu")]
    seam_fit_renderer: Backend,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Whose post-processing the bench's composites get.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize)]
#[serde(rename_all = "snake_case")]
enum Pipeline {
    /// As each recipe says.
    Recipe,
    /// The thesis's: [`PostProcess::THESIS`].
    Thesis,
    /// Ours: [`PostProcess::BEST`].
    Ours,
}

/// One trained source.
#[derive(Clone, Debug, Serialize)]
struct SourceRow {
    name: String,
    /// Seconds its training took (0 when it came from the cache).
    train_s: f64,
    cached: bool,
}

/// One recipe's figures.
#[derive(Clone, Debug, Serialize)]
struct RecipeRow {
    recipe: String,
    tone: Tone,
    seams: Seams,
    report: CompositeReport,
    /// Seconds the ground truth took to capture.
    truth_s: f64,
}

/// The means over the recipes.
#[derive(Clone, Debug, Default, Serialize)]
struct Means {
    psnr_db: f64,
    ceiling_psnr_db: f64,
    border_psnr_db: f64,
    interior_psnr_db: f64,
    leak_percent: f64,
    holes_percent: f64,
    open_mouth_psnr_db: f64,
    closed_mouth_psnr_db: f64,
    skin_delta_e: f64,
    non_skin_delta_e: f64,
    ceiling_skin_delta_e: f64,
    ceiling_non_skin_delta_e: f64,
    ceiling_border_psnr_db: f64,
    ceiling_interior_psnr_db: f64,
    /// Interior minus band, averaged over the recipes that have a band: the
    /// figure the band's target reads (the band and interior means above
    /// are over different recipes when one has no band).
    border_gap_db: f64,
    /// The same of the sources on their own truth.
    ceiling_border_gap_db: f64,
    held_out_psnr_db: f64,
    ceiling_held_out_psnr_db: f64,
}

/// The whole bench.
#[derive(Clone, Debug, Serialize)]
struct CompositesBench {
    bench: &'static str,
    size: [u32; 2],
    cameras: usize,
    frames: usize,
    iterations: usize,
    pipeline: Pipeline,
    /// Steps of the seam fit run on each composite (0: none).
    seam_fit: usize,
    sources: Vec<SourceRow>,
    recipes: Vec<RecipeRow>,
    mean: Means,
}

/// The ground truth a recipe is measured against: colour-corrected
/// composites against the base's skin tone, smoothed ones against smooth seams.
fn target_of(recipe: &Recipe) -> (Tone, Seams) {
    let tone = if recipe.post.colour == ColourCorrection::Off {
        Tone::Source
    } else {
        Tone::Base
    };
    let seams = if recipe.post.smoothing == Smoothing::Off {
        Seams::Hard
    } else {
        Seams::Smooth
    };
    (tone, seams)
}

fn capture_options(args: &CompositesBenchArgs, source: &str) -> CaptureOptions {
    CaptureOptions {
        source: source.to_string(),
        size: [args.size.0, args.size.1],
        cameras: args.cameras,
        frames: args.frames,
        motion: "talk".into(),
        ring: false,
    }
}

fn scratch(tag: &str) -> PathBuf {
    std::env::temp_dir().join(format!(
        "visage-bench-composites-{}-{tag}",
        std::process::id()
    ))
}

/// Trains `name` into the cache unless a finished one is there; a source
/// appears by rename, so a kill leaves nothing half written.
fn trained_source(
    args: &CompositesBenchArgs,
    builtin: &Database,
    name: &str,
    dir: &Path,
) -> Result<SourceRow> {
    let done = dir.join(name);
    if done.join("point_cloud.ply").is_file() && done.join("flame_param.npz").is_file() {
        return Ok(SourceRow {
            name: name.to_string(),
            train_s: 0.0,
            cached: true,
        });
    }
    let start = Instant::now();
    let data = scratch(name);
    std::fs::remove_dir_all(&data).ok();
    capture(builtin, &capture_options(args, name), &data, &|_, _| {})?;
    let dataset = Dataset::load(&data)?;
    let mut trainer = Trainer::new(
        &dataset,
        crate::model::builtin::build_head(),
        TrainOptions::recommended(args.iterations, 1, args.renderer),
    )?;
    eprintln!("visage: training {name} ({} iterations)…", args.iterations);
    while trainer.iteration() < trainer.iterations() {
        trainer.step()?;
    }
    let partial = dir.join(format!("{name}.partial"));
    std::fs::remove_dir_all(&partial).ok();
    trainer.export(&partial)?;
    std::fs::rename(&partial, &done).map_err(|e| Error::io("move into place", &partial, e))?;
    std::fs::remove_dir_all(&data).ok();
    Ok(SourceRow {
        name: name.to_string(),
        train_s: start.elapsed().as_secs_f64(),
        cached: false,
    })
}

/// Runs `visage bench composites`.
pub fn run(args: &CompositesBenchArgs) -> Result<()> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(&args.recipes)
        .map_err(|e| Error::input(format!("cannot read {}: {e}", args.recipes.display())))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    if paths.is_empty() {
        return Err(Error::input(format!(
            "{} holds no recipes",
            args.recipes.display()
        )));
    }
    let recipes: Vec<(String, Recipe)> = paths
        .iter()
        .map(|p| {
            let name = p
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            let mut recipe = Recipe::load(p)?;
            match args.pipeline {
                Pipeline::Recipe => {}
                Pipeline::Thesis => recipe.post = PostProcess::THESIS,
                Pipeline::Ours => recipe.post = PostProcess::BEST,
            }
            Ok((name, recipe))
        })
        .collect::<Result<_>>()?;
    let (builtin, _) = DatabaseSpec {
        gaussians_per_avatar: 1,
        ..DatabaseSpec::default()
    }
    .load()?;
    let mut names: Vec<String> = recipes.iter().flat_map(|(_, r)| r.source_names()).collect();
    names.sort();
    names.dedup();
    let cache = args.cache.join(format!(
        "{}x{}-c{}-f{}-i{}-interior",
        args.size.0, args.size.1, args.cameras, args.frames, args.iterations
    ));
    std::fs::create_dir_all(&cache).map_err(|e| Error::io("create", &cache, e))?;
    let sources = names
        .iter()
        .map(|n| trained_source(args, &builtin, n, &cache))
        .collect::<Result<Vec<_>>>()?;
    // The cache holds every source trained at this setting; the evaluation
    // reads it as a folder database.
    let (trained, _) = DatabaseSpec {
        db: cache.display().to_string(),
        ..DatabaseSpec::default()
    }
    .load()?;
    let fit = SeamFit {
        iterations: args.seam_fit,
        renderer: args.seam_fit_renderer,
        ..SeamFit::default()
    };
    let mut fitted_any = false;
    let mut rows = Vec::new();
    for (name, recipe) in &recipes {
        let options = EvalOptions {
            border_px: args.border_px,
            picture_views: 0,
            arrays: None,
            fit: (recipe.post.fit == Fit::Seams && args.seam_fit > 0).then_some(fit),
        };
        fitted_any |= options.fit.is_some();
        let (tone, seams) = target_of(recipe);
        let start = Instant::now();
        let truth = scratch(&format!("truth-{name}"));
        std::fs::remove_dir_all(&truth).ok();
        let sitter = Sitter::composite(&builtin, recipe, tone, seams)?;
        capture_sitter(
            &builtin,
            &capture_options(args, &recipe.base),
            &sitter,
            &truth,
            &|_, _| {},
        )?;
        let truth_s = start.elapsed().as_secs_f64();
        eprintln!("visage: evaluating {name}…");
        let (report, _) = evaluate_composite(&trained, recipe, &Dataset::load(&truth)?, &options)?;
        std::fs::remove_dir_all(&truth).ok();
        rows.push(RecipeRow {
            recipe: name.clone(),
            tone,
            seams,
            report,
            truth_s,
        });
    }
    // Means over the recipes that have the figure (a single-source composite
    // has no border band); none where no recipe has it, rather than a 0.
    let mean_of = |f: &dyn Fn(&CompositeReport) -> f64| {
        let values: Vec<f64> = rows
            .iter()
            .map(|r| f(&r.report))
            .filter(|v| v.is_finite())
            .collect();
        if values.is_empty() {
            return f64::NAN;
        }
        values.iter().sum::<f64>() / values.len() as f64
    };
    let report = CompositesBench {
        bench: "composites",
        size: [args.size.0, args.size.1],
        cameras: args.cameras,
        frames: args.frames,
        iterations: args.iterations,
        pipeline: args.pipeline,
        seam_fit: if fitted_any { args.seam_fit } else { 0 },
        mean: Means {
            psnr_db: mean_of(&|r| r.quality.psnr_db),
            ceiling_psnr_db: mean_of(&|r| r.ceiling.psnr_db),
            border_psnr_db: mean_of(&|r| r.border.psnr_db),
            interior_psnr_db: mean_of(&|r| r.interior.psnr_db),
            leak_percent: mean_of(&|r| 100.0 * r.leak.mean),
            holes_percent: mean_of(&|r| 100.0 * r.holes),
            open_mouth_psnr_db: mean_of(&|r| r.open_mouth.psnr_db),
            closed_mouth_psnr_db: mean_of(&|r| r.closed_mouth.psnr_db),
            skin_delta_e: mean_of(&|r| r.skin.delta_e),
            non_skin_delta_e: mean_of(&|r| r.non_skin.delta_e),
            ceiling_skin_delta_e: mean_of(&|r| r.ceiling_skin.delta_e),
            ceiling_non_skin_delta_e: mean_of(&|r| r.ceiling_non_skin.delta_e),
            ceiling_border_psnr_db: mean_of(&|r| r.ceiling_border.psnr_db),
            ceiling_interior_psnr_db: mean_of(&|r| r.ceiling_interior.psnr_db),
            border_gap_db: mean_of(&|r| r.interior.psnr_db - r.border.psnr_db),
            ceiling_border_gap_db: mean_of(&|r| {
                r.ceiling_interior.psnr_db - r.ceiling_border.psnr_db
            }),
            held_out_psnr_db: mean_of(&|r| r.held_out.psnr_db),
            ceiling_held_out_psnr_db: mean_of(&|r| r.ceiling_held_out.psnr_db),
        },
        sources,
        recipes: rows,
    };
    emit(&report, args.json, print_table);
    Ok(())
}

fn print_table(b: &CompositesBench) {
    println!(
        "composites against their ground truth: {}x{}, {} cameras, {} timesteps, sources trained {} iterations, {:?} post-processing{}",
        b.size[0],
        b.size[1],
        b.cameras,
        b.frames,
        b.iterations,
        b.pipeline,
        if b.seam_fit > 0 {
            let on_gpu = b.recipes.iter().any(|r| r.report.seam_fit.is_some_and(|f| f.on_gpu));
            format!(
                ", seams fitted in {} steps on the {}",
                b.seam_fit,
                if on_gpu { "GPU" } else { "CPU" }
            )
        } else {
            String::new()
        }
    );
    for s in &b.sources {
        if !s.cached {
            println!("  trained {} in {:.0} s", s.name, s.train_s);
        }
    }
    println!(
        "{:<22} {:>7} {:>8} {:>7} {:>9} {:>6} {:>8} {:>8} {:>7} {:>7} {:>7}",
        "recipe",
        "PSNR",
        "ceiling",
        "border",
        "interior",
        "leak%",
        "ΔE skin",
        "ΔE other",
        "truth s",
        "eval s",
        "fit s"
    );
    let row = |name: &str, figures: [f64; 7], times: String| {
        let widths = [7, 8, 7, 9, 6, 8, 8];
        let cells: Vec<String> = figures
            .iter()
            .zip(widths)
            .map(|(x, w)| {
                if x.is_finite() {
                    format!("{x:>w$.2}")
                } else {
                    format!("{:>w$}", "-")
                }
            })
            .collect();
        println!("{name:<22} {} {times}", cells.join(" "));
    };
    for r in &b.recipes {
        let p = &r.report;
        row(
            &r.recipe,
            [
                p.quality.psnr_db,
                p.ceiling.psnr_db,
                p.border.psnr_db,
                p.interior.psnr_db,
                100.0 * p.leak.mean,
                p.skin.delta_e,
                p.non_skin.delta_e,
            ],
            format!(
                "{:>7.1} {:>7.1} {:>7}",
                r.truth_s,
                p.eval_ms / 1e3,
                p.seam_fit
                    .map_or("-".to_string(), |f| format!("{:.1}", f.ms / 1e3))
            ),
        );
    }
    let m = &b.mean;
    row(
        "mean",
        [
            m.psnr_db,
            m.ceiling_psnr_db,
            m.border_psnr_db,
            m.interior_psnr_db,
            m.leak_percent,
            m.skin_delta_e,
            m.non_skin_delta_e,
        ],
        String::new(),
    );
    // A mean no recipe has (no open mouth, no band) reads "-".
    let figure = |x: f64| {
        if x.is_finite() {
            format!("{x:.2}")
        } else {
            "-".to_string()
        }
    };
    println!(
        "border band {} dB under the interior, the sources on their own truth {} dB (means over the recipes with a band)",
        figure(m.border_gap_db),
        figure(m.ceiling_border_gap_db)
    );
    println!(
        "open-mouth views {} dB, closed-mouth views {} dB (means; {} % of head pixels are holes)",
        figure(m.open_mouth_psnr_db),
        figure(m.closed_mouth_psnr_db),
        figure(m.holes_percent)
    );
    println!(
        "the sources on their own truth (the ceiling): ΔE skin {}, ΔE other {}; band {} dB, interior {} dB",
        figure(m.ceiling_skin_delta_e),
        figure(m.ceiling_non_skin_delta_e),
        figure(m.ceiling_border_psnr_db),
        figure(m.ceiling_interior_psnr_db)
    );
    println!(
        "held-out views (val, test; no source trained on them): composite {} dB, ceiling {} dB",
        figure(m.held_out_psnr_db),
        figure(m.ceiling_held_out_psnr_db)
    );
}
