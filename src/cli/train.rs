//! `visage train` (a GaussianAvatars avatar from a dataset) and `visage eval`
//! (its PSNR / SSIM on the dataset's held-out views, and a picture grid).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use crate::tui::terminal::{signal_name, StopSignal};
use serde_json::json;

use super::farm::ShardArgs;
use super::values::parse_size;
use crate::error::{Error, Result};
use crate::model::head::HeadModel;
use crate::render::image::RgbImage;
use crate::render::Backend;
use crate::train::dataset::{head_model, Dataset};
use crate::train::hole_metrics::{self, HoleMetrics};
use crate::train::holes::HoleFilling;
use crate::train::model::Trainable;
use crate::train::posing::{timestep_frames, training_arc};
use crate::train::target::{evaluate_view, load_target};
use crate::train::trainer::{TrainOptions, Trainer};

/// The FLAME files a dataset or avatar needs (none for the built-in head).
#[derive(Args, Debug, Clone, Default)]
pub struct HeadArgs {
    /// FLAME model pickle (not needed for datasets `visage capture` made).
    #[arg(long, value_name = "FILE")]
    flame: Option<PathBuf>,
    /// FLAME masks pickle (with --flame).
    #[arg(long, value_name = "FILE")]
    masks: Option<PathBuf>,
}

impl HeadArgs {
    /// The head model: the user's FLAME, or the built-in head when the dataset
    /// was captured from it (or nothing was given).
    fn load(&self, dataset: Option<&Dataset>) -> Result<HeadModel> {
        match (&self.flame, &self.masks) {
            (Some(f), Some(m)) => head_model(dataset, Some((f, m))),
            (None, None) => head_model(dataset, None),
            _ => Err(Error::input("--flame and --masks go together")),
        }
    }
}

/// Arguments of `visage train`.
#[derive(Args, Debug, Clone)]
pub struct TrainArgs {
    /// Dataset folder (transforms_{train,val,test}.json, images, FLAME parameters).
    #[arg(required_unless_present = "manifest")]
    dataset: Option<PathBuf>,
    #[command(flatten)]
    head: HeadArgs,
    /// Avatar folder to write (point_cloud.ply + flame_param.npz).
    #[arg(short, long, value_name = "DIR", required_unless_present = "manifest")]
    output: Option<PathBuf>,
    /// Train the subjects of a manifest (TOML) into its database folder
    /// instead: finished ones are skipped, interrupted ones resume (README
    /// "Building a database on a cluster").
    #[arg(long, value_name = "TOML", conflicts_with_all = [
        "dataset", "output", "flame", "masks", "iterations", "seed", "size", "white_background",
        "checkpoint_every", "resume", "renderer", "obscuring", "no_interior_layer", "cull_backfaces",
    ])]
    manifest: Option<PathBuf>,
    #[command(flatten)]
    shard: ShardArgs,
    /// Iterations (one training view each).
    #[arg(long, default_value_t = 3000)]
    iterations: usize,
    /// Seed (initial colours, view order, split sampling).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Train at this resolution (images are resized); default: as stored.
    #[arg(long, value_parser = parse_size, value_name = "WxH")]
    size: Option<(u32, u32)>,
    /// Composite masked images over white instead of black.
    #[arg(long)]
    white_background: bool,
    /// Write OUTPUT/checkpoint.npz every N iterations (0: only on Ctrl-C).
    #[arg(long, default_value_t = 500, value_name = "N")]
    checkpoint_every: usize,
    /// Continue a run from its checkpoint (its seed and iteration count).
    #[arg(long, value_name = "CHECKPOINT")]
    resume: Option<PathBuf>,
    /// Rasteriser: auto (a hardware GPU through wgpu when there is one, the
    /// CPU otherwise), gpu (wgpu on any adapter, lavapipe included) or cpu.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    #[command(flatten)]
    holes: HoleArgs,
}

/// The hole-filling options of `visage train` (docs/method.md §11.6). By
/// default an opaque interior layer sits behind the head's visible surface
/// (`visage bench holes`: two thirds less leak at the same held-out PSNR).
#[derive(Args, Debug, Clone)]
pub struct HoleArgs {
    /// Use the thesis's obscuring Gaussian (one opaque Gaussian in the
    /// head's bounding box) instead of the interior layer.
    #[arg(long)]
    obscuring: bool,
    /// Train with neither the interior layer nor the obscuring Gaussian.
    #[arg(long, conflicts_with = "obscuring")]
    no_interior_layer: bool,
    /// Cull triangles facing fewer than this share of the training views
    /// (camera × timestep) before training (thesis §4.2.1; off by default).
    #[arg(long, value_name = "TAU")]
    cull_backfaces: Option<f64>,
}

impl HoleArgs {
    /// The hole filling asked for.
    pub fn filling(&self) -> Result<HoleFilling> {
        if let Some(tau) = self.cull_backfaces {
            if !(0.0..=1.0).contains(&tau) {
                return Err(Error::input(format!(
                    "--cull-backfaces takes a share of views from 0 to 1, not {tau}"
                )));
            }
        }
        Ok(HoleFilling {
            obscuring: self.obscuring,
            interior: !self.obscuring && !self.no_interior_layer,
            cull_below: self.cull_backfaces,
        })
    }
}

/// Runs `visage train`.
pub fn run_train(args: &TrainArgs) -> Result<()> {
    if let Some(manifest) = &args.manifest {
        return super::farm::train_manifest(manifest, &args.shard);
    }
    let (Some(dataset), Some(output)) = (&args.dataset, &args.output) else {
        return Err(Error::input("give a dataset and -o DIR, or --manifest"));
    };
    // Ctrl-C, SIGTERM or a hang-up stops at the end of an iteration with a
    // checkpoint, then exits 128 + the signal as shells expect (installed
    // first, so a signal while loading is no crash either).
    let stop = StopSignal::install()?;
    let dataset = Dataset::load(dataset)?;
    let head = args.head.load(Some(&dataset))?;
    // Fail on an unwritable output before training, not after.
    std::fs::create_dir_all(output).map_err(|e| Error::io("create", output, e))?;
    let background = if args.white_background {
        [1.0; 3]
    } else {
        [0.0; 3]
    };
    let start = Instant::now();
    let options = TrainOptions {
        iterations: args.iterations,
        seed: args.seed,
        size: args.size.map(|(w, h)| [w, h]),
        background,
        renderer: args.renderer,
        holes: args.holes.filling()?,
    };
    let mut trainer = match &args.resume {
        Some(path) => Trainer::resume(&dataset, head, options, path)?,
        None => Trainer::new(&dataset, head, options)?,
    };
    let iterations = trainer.iterations();
    let checkpoint = output.join("checkpoint.npz");
    let first = trainer.iteration();
    let bar = training_bar(iterations, "");
    bar.set_position(first as u64);
    // The rate and the time left count only this run's iterations, not the
    // ones a resumed checkpoint brought.
    bar.reset_eta();
    let mut smoothed: Option<(f64, f64)> = None;
    while trainer.iteration() < iterations {
        if let Some(signal) = stop.received() {
            bar.finish_and_clear();
            trainer.save_checkpoint(&checkpoint)?;
            trainer.export(output)?;
            return Err(StopSignal::stopped(
                signal,
                format!(
                    "stopped by {} at iteration {} of {iterations}; the avatar so far is in {}; continue with --resume {}",
                    signal_name(signal),
                    trainer.iteration(),
                    output.display(),
                    checkpoint.display()
                ),
            ));
        }
        let r = trainer.step()?;
        if args.checkpoint_every > 0 && r.iteration % args.checkpoint_every == 0 {
            trainer.save_checkpoint(&checkpoint)?;
        }
        let (loss, psnr) = smoothed.map_or((r.loss, r.psnr), |(l, p)| {
            (0.6 * l + 0.4 * r.loss, 0.6 * p + 0.4 * r.psnr)
        });
        smoothed = Some((loss, psnr));
        if r.iteration % 10 == 0 || r.iteration == iterations {
            bar.set_message(format!(
                "loss {loss:.4} PSNR {psnr:.1} dB {} Gaussians",
                r.gaussians
            ));
        }
        bar.set_position(r.iteration as u64);
    }
    bar.finish_and_clear();
    trainer.export(output)?;
    eprintln!(
        "visage: trained {} Gaussians in {:.1} s ({:.1} it/s, training PSNR {:.2} dB); wrote {}",
        trainer.model.len(),
        start.elapsed().as_secs_f64(),
        (iterations - first) as f64 / start.elapsed().as_secs_f64(),
        smoothed.map_or(0.0, |s| s.1),
        output.display()
    );
    Ok(())
}

/// The progress bar of a training run (`prefix`: the subject, if any).
pub(super) fn training_bar(iterations: usize, prefix: &str) -> indicatif::ProgressBar {
    indicatif::ProgressBar::new(iterations as u64)
        .with_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} {prefix}[{bar:25}] {pos}/{len} {per_sec} {msg} ({eta} left)",
            )
            .expect("the template is valid")
            .progress_chars("=> "),
        )
        .with_prefix(prefix.to_string())
}

/// Arguments of `visage eval`.
#[derive(Args, Debug, Clone)]
pub struct EvalArgs {
    /// Avatar folder (point_cloud.ply + flame_param.npz); with --composite,
    /// the recipe of the composite.
    #[arg(value_name = "AVATAR|RECIPE")]
    avatar: PathBuf,
    /// Dataset folder (with --composite: the composite's ground truth from
    /// `visage capture --recipe`).
    dataset: PathBuf,
    /// Evaluate a composite built in-process from the trained sources of
    /// --db against its ground truth: per split, view and group, border band
    /// against interior, leak, the ceiling and the decomposition.
    #[arg(long, requires = "db")]
    pub(super) composite: bool,
    /// With --composite: the folder of trained sources (GaussianAvatars
    /// avatars named like the built-in people).
    #[arg(long, value_name = "DIR", requires = "composite")]
    pub(super) db: Option<PathBuf>,
    /// With --composite: pixels within this many of a change of source are
    /// the border band.
    #[arg(long, default_value_t = 3, requires = "composite")]
    pub(super) border_px: u32,
    /// With --composite: ground truth, composite and an error map side by
    /// side for a few views, as PNG.
    #[arg(long, value_name = "PNG", requires = "composite")]
    pub(super) picture: Option<PathBuf>,
    /// With --composite: write each view's composite, ground truth,
    /// labels (head, band, region, source) and every used source's own
    /// render and truth into this folder, one numpy .npz a view.
    #[arg(long, value_name = "DIR", requires = "composite")]
    pub(super) arrays: Option<PathBuf>,
    /// With --composite: fit the composite's seams with this many steps
    /// (method §7.12) and measure the fitted composite as a fifth step of
    /// the decomposition; 0: no fit. Default: as the recipe's `[post] fit`
    /// says (200 steps for "seams", what `bench composites --pipeline ours`
    /// runs).
    #[arg(long, value_name = "STEPS", requires = "composite")]
    pub(super) seam_fit: Option<usize>,
    /// With --composite: the width and height of the seam fit's views, in
    /// pixels (the fit needs the resolution the composite is looked at)
    /// [default: 256].
    #[arg(long, value_name = "PX", value_parser = clap::value_parser!(u32).range(16..=4096), requires = "composite")]
    pub(super) seam_fit_size: Option<u32>,
    /// With --composite: what draws the seam fit's views: cpu, auto (a
    /// hardware GPU when there is one, else the CPU) or gpu [default: cpu].
    #[arg(long, value_name = "RENDERER", value_parser = Backend::parse, requires = "composite")]
    pub(super) seam_fit_renderer: Option<Backend>,
    #[command(flatten)]
    head: HeadArgs,
    /// Side-by-side grid (render | ground truth) of the first views, as PNG.
    #[arg(long, value_name = "PNG")]
    grid: Option<PathBuf>,
    /// Composite masked images over white instead of black.
    #[arg(long)]
    white_background: bool,
    /// Also measure hole filling: leak of the far side through the face and
    /// coverage of the face regions (docs/method.md §11.6).
    #[arg(long)]
    holes: bool,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

impl EvalArgs {
    /// The recipe (with --composite).
    pub(super) fn recipe(&self) -> &std::path::Path {
        &self.avatar
    }

    /// The dataset.
    pub(super) fn dataset(&self) -> &std::path::Path {
        &self.dataset
    }

    /// Print JSON.
    pub(super) fn json(&self) -> bool {
        self.json
    }
}

/// Runs `visage eval`.
pub fn run_eval(args: &EvalArgs) -> Result<()> {
    if args.composite {
        return super::eval_composite::run(args);
    }
    let dataset = Dataset::load(&args.dataset)?;
    let head = args.head.load(Some(&dataset))?;
    let avatar = crate::io::avatar::read_avatar(&args.avatar, "avatar", &head)?;
    let model = Trainable::from_set(&avatar.gaussians);
    let background = if args.white_background {
        [1.0; 3]
    } else {
        [0.0; 3]
    };
    let mut rows = Vec::new();
    let mut grid: Vec<RgbImage> = Vec::new();
    let mut grid_rows: Vec<String> = Vec::new();
    for (split, views) in [("val", &dataset.val), ("test", &dataset.test)] {
        if views.is_empty() {
            continue;
        }
        let frames = timestep_frames(&dataset, &head, views)?;
        let (mut psnr_sum, mut ssim_sum) = (0.0, 0.0);
        for (k, view) in views.iter().enumerate() {
            let target = load_target(view, None, background)?;
            let (image, psnr, ssim) =
                evaluate_view(&model, &frames[&view.timestep], &target, background);
            psnr_sum += psnr;
            ssim_sum += ssim;
            if k < 4 {
                let [w, h] = view.camera.size;
                let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
                grid.push(to_image(&image, w, h));
                grid.push(to_image(&goal, w, h));
                grid_rows.push(format!("{split} {k}: {psnr:.1} dB"));
            }
        }
        let n = views.len() as f64;
        rows.push(json!({
            "split": split,
            "views": views.len(),
            "psnr_db": psnr_sum / n,
            "ssim": ssim_sum / n,
        }));
    }
    if let Some(path) = &args.grid {
        if !grid.is_empty() {
            crate::study::plot::labelled_grid(&grid, &["render", "truth"], &grid_rows)?
                .save_png(path)?;
        }
    }
    let holes = if args.holes {
        let (posed, cameras) = training_arc(&dataset, &head, hole_metrics::METRIC_SIDE)?;
        Some(hole_metrics::measure(&model, &head, &posed, &cameras))
    } else {
        None
    };
    if args.json {
        println!(
            "{}",
            json!({
                "avatar": args.avatar.display().to_string(),
                "splits": rows,
                "holes": holes.as_ref().map(HoleMetrics::summary),
            })
        );
    } else {
        for r in &rows {
            println!(
                "{:<5} {:>4} views  PSNR {:6.2} dB  SSIM {:.4}",
                r["split"].as_str().unwrap_or(""),
                r["views"],
                r["psnr_db"].as_f64().unwrap_or(0.0),
                r["ssim"].as_f64().unwrap_or(0.0)
            );
        }
        if let Some(h) = &holes {
            print_holes(h);
        }
    }
    Ok(())
}

/// Prints hole metrics as two lines.
pub fn print_holes(h: &HoleMetrics) {
    println!(
        "leak  ΔE {:.2} (PSNR {:.1} dB) over the face with hair, neck and ears repainted",
        h.leak_delta_e, h.leak_psnr_db
    );
    let list = |c: &[(crate::model::regions::Group, f64)]| {
        c.iter()
            .map(|(g, v)| format!("{} {:.3}", g.name(), v))
            .collect::<Vec<_>>()
            .join(", ")
    };
    println!("coverage (training views)  {}", list(&h.coverage));
    println!(
        "coverage (turned ±{:.0}°)    {}",
        hole_metrics::BEYOND_DEG,
        list(&h.coverage_beyond)
    );
}

fn to_image(values: &[f64], w: u32, h: u32) -> RgbImage {
    RgbImage {
        width: w,
        height: h,
        pixels: values
            .iter()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
    }
}
