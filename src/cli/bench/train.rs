//! `visage bench train`: training speed beside quality — iterations per
//! second and held-out PSNR against wall time (a short curve), peak memory,
//! and the gradient error against central differences.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use serde::Serialize;

use super::stats::{emit, peak_rss_mb, summarize};
use crate::avatar::binding::TriangleFrame;
use crate::cli::values::parse_size;
use crate::error::Result;
use crate::pipeline::DatabaseSpec;
use crate::render::Backend;
use crate::train::capture::{capture, CaptureOptions};
use crate::train::dataset::Dataset;
use crate::train::loss::photometric_loss;
use crate::train::model::gradient_check;
use crate::train::posing::timestep_frames;
use crate::train::target::{evaluate_view, load_target, Target};
use crate::train::trainer::{StageSeconds, TrainOptions, Trainer};
use std::collections::BTreeMap;

/// Arguments of `visage bench train`.
#[derive(Args, Debug, Clone)]
pub struct TrainBenchArgs {
    /// Dataset to train on (default: a fresh capture of the built-in `ada`,
    /// 16 cameras, 20 frames of `talk`, at --capture-size).
    #[arg(long, value_name = "DIR")]
    dataset: Option<PathBuf>,
    /// Size of the default capture.
    #[arg(long, value_parser = parse_size, default_value = "128x128", value_name = "WxH")]
    capture_size: (u32, u32),
    /// Iterations.
    #[arg(long, default_value_t = 600)]
    iterations: usize,
    /// Evaluate the held-out views every this many iterations.
    #[arg(long, default_value_t = 100)]
    eval_every: usize,
    /// Rasteriser(s) to train with, comma-separated: auto (a hardware GPU
    /// through wgpu when there is one, the CPU otherwise), gpu (wgpu on any
    /// adapter, lavapipe included), cpu.
    #[arg(long, value_parser = Backend::parse, value_delimiter = ',', default_value = "auto")]
    renderers: Vec<Backend>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// The dataset a training bench runs on: the user's, or a fresh capture of
/// the built-in `ada` (16 cameras, 20 frames of `talk`) removed afterwards.
pub struct BenchDataset {
    /// The dataset.
    pub dataset: Dataset,
    scratch: Option<PathBuf>,
}

impl BenchDataset {
    /// Loads `dataset`, or captures the default one at `size`.
    pub fn open(dataset: Option<&std::path::Path>, size: (u32, u32), tag: &str) -> Result<Self> {
        let Some(root) = dataset else {
            let scratch =
                std::env::temp_dir().join(format!("visage-bench-{tag}-{}", std::process::id()));
            let (db, _) = DatabaseSpec {
                gaussians_per_avatar: 1,
                ..DatabaseSpec::default()
            }
            .load()?;
            let options = CaptureOptions {
                source: "ada".into(),
                size: [size.0, size.1],
                cameras: 16,
                frames: 20,
                motion: "talk".into(),
                ring: false,
            };
            capture(&db, &options, &scratch, &|_, _| {})?;
            return Ok(Self {
                dataset: Dataset::load(&scratch)?,
                scratch: Some(scratch),
            });
        };
        Ok(Self {
            dataset: Dataset::load(root)?,
            scratch: None,
        })
    }
}

impl Drop for BenchDataset {
    fn drop(&mut self) {
        if let Some(dir) = &self.scratch {
            std::fs::remove_dir_all(dir).ok();
        }
    }
}

/// Triangle frames per timestep.
pub type TimestepFrames = BTreeMap<usize, Vec<TriangleFrame>>;

/// The held-out (val and test) views read once: each timestep's triangle
/// frames and the targets.
pub fn held_out_targets(
    dataset: &Dataset,
    head: &crate::model::head::HeadModel,
) -> Result<(TimestepFrames, Vec<Target>)> {
    let held_out: Vec<_> = dataset.val.iter().chain(&dataset.test).cloned().collect();
    let frames = timestep_frames(dataset, head, &held_out)?;
    let targets = held_out
        .iter()
        .map(|v| load_target(v, None, [0.0; 3]))
        .collect::<Result<Vec<_>>>()?;
    Ok((frames, targets))
}

/// Trains `head` on `dataset` for `iterations` with one seed and returns the
/// trainer at the end and the seconds it took (the hole and mouth benches
/// train several variants this way).
pub fn train_to_end(
    dataset: &Dataset,
    head: &crate::model::head::HeadModel,
    iterations: usize,
    seed: u64,
    renderer: Backend,
    holes: crate::train::holes::HoleFilling,
) -> Result<(Trainer, f64)> {
    let mut trainer = Trainer::new(
        dataset,
        head.clone(),
        TrainOptions {
            iterations,
            seed,
            size: None,
            background: [0.0; 3],
            renderer,
            holes,
        },
    )?;
    let start = Instant::now();
    while trainer.iteration() < iterations {
        trainer.step()?;
    }
    Ok((trainer, start.elapsed().as_secs_f64()))
}

/// Mean held-out PSNR of a model.
pub fn held_out_psnr(
    model: &crate::train::model::Trainable,
    frames: &BTreeMap<usize, Vec<TriangleFrame>>,
    targets: &[Target],
) -> f64 {
    let sum: f64 = targets
        .iter()
        .map(|t| evaluate_view(model, &frames[&t.view.timestep], t, [0.0; 3]).1)
        .sum();
    sum / targets.len().max(1) as f64
}

/// Trains with one renderer, evaluating the held-out views along the way.
fn run_one(
    args: &TrainBenchArgs,
    dataset: &Dataset,
    frames: &BTreeMap<usize, Vec<TriangleFrame>>,
    targets: &[Target],
    renderer: Backend,
) -> Result<RendererRun> {
    let mut trainer = Trainer::new(
        dataset,
        crate::model::builtin::build_head(),
        TrainOptions::recommended(args.iterations, 1, renderer),
    )?;
    let agreement = gradient_check::agreement_with_cpu(renderer)?;
    let mut curve = Vec::new();
    let mut training_s = 0.0;
    while trainer.iteration() < args.iterations {
        let t = Instant::now();
        for _ in 0..args.eval_every.max(1) {
            if trainer.iteration() >= args.iterations {
                break;
            }
            trainer.step()?;
        }
        training_s += t.elapsed().as_secs_f64();
        curve.push(CurvePoint {
            iteration: trainer.iteration(),
            train_s: training_s,
            held_out_psnr_db: held_out_psnr(&trainer.model, frames, targets),
            gaussians: trainer.model.len(),
        });
    }
    Ok(RendererRun {
        renderer,
        device: trainer.rasterizer(),
        iterations_per_s: args.iterations as f64 / training_s,
        stage_ms: StageMs::per_iteration(&trainer.stage_seconds, trainer.iteration()),
        gradient_difference_from_cpu: agreement,
        curve,
    })
}

/// The train bench's report.
#[derive(Serialize)]
struct TrainReport {
    #[serde(skip)]
    dataset: String,
    threads: usize,
    gradient_max_relative_error: f64,
    gradient_parameters_checked: usize,
    peak_rss_mb: Option<f64>,
    /// The photometric loss and its gradient (f64, on the CPU) at the
    /// dataset's image size: median milliseconds of five evaluations. Every
    /// iteration pays it whatever rasterises.
    loss_ms: Option<f64>,
    loss_size: Option<[u32; 2]>,
    renderers: Vec<RendererRun>,
}

/// One rasteriser's training run.
#[derive(Serialize)]
struct RendererRun {
    renderer: Backend,
    device: String,
    iterations_per_s: f64,
    /// Milliseconds an iteration spends in each part of the step.
    stage_ms: StageMs,
    gradient_difference_from_cpu: f64,
    curve: Vec<CurvePoint>,
}

/// Mean milliseconds an iteration spends in each part of a training step.
#[derive(Serialize)]
struct StageMs {
    forward: f64,
    loss: f64,
    backward: f64,
    update: f64,
}

impl StageMs {
    fn per_iteration(total: &StageSeconds, iterations: usize) -> Self {
        let ms = |s: f64| s * 1e3 / iterations.max(1) as f64;
        Self {
            forward: ms(total.forward),
            loss: ms(total.loss),
            backward: ms(total.backward),
            update: ms(total.update),
        }
    }
}

/// The held-out PSNR after so many iterations.
#[derive(Serialize)]
struct CurvePoint {
    iteration: usize,
    train_s: f64,
    held_out_psnr_db: f64,
    gaussians: usize,
}

fn print_report(report: &TrainReport) {
    println!(
        "training on {} ({} threads); gradient error {:.1e} (max relative against central differences, {} parameters); peak memory {:.0} MiB",
        report.dataset,
        report.threads,
        report.gradient_max_relative_error,
        report.gradient_parameters_checked,
        report.peak_rss_mb.unwrap_or(0.0)
    );
    if let (Some(ms), Some([w, h])) = (report.loss_ms, report.loss_size) {
        println!("loss and its gradient at {w}×{h}: {ms:.1} ms an iteration");
    }
    for run in &report.renderers {
        println!(
            "{}: {:.2} iterations/s; gradients within {:.1e} of the CPU's (largest difference over the largest gradient)",
            run.device, run.iterations_per_s, run.gradient_difference_from_cpu,
        );
        let st = &run.stage_ms;
        println!(
            "  an iteration: forward {:.1} ms, loss {:.1} ms, backward {:.1} ms, update {:.1} ms",
            st.forward, st.loss, st.backward, st.update
        );
        println!("  iteration  train s  held-out PSNR dB  Gaussians");
        for row in &run.curve {
            println!(
                "  {:>9}  {:>7.1}  {:>16.2}  {:>9}",
                row.iteration, row.train_s, row.held_out_psnr_db, row.gaussians
            );
        }
    }
}

/// Median time of the loss and its gradient of a grey image against
/// `target`, at the target's size.
fn time_loss(target: &Target) -> (f64, [u32; 2]) {
    let [w, h] = target.camera.size;
    let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
    let grey = vec![0.5; goal.len()];
    let times = (0..5)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(photometric_loss(&grey, &goal, w as usize, h as usize, true));
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    (summarize(times).0, [w, h])
}

/// Runs `visage bench train`.
pub fn run(args: &TrainBenchArgs) -> Result<()> {
    let (gradient_error, checked) = gradient_check::worst_relative_error();
    let data = BenchDataset::open(args.dataset.as_deref(), args.capture_size, "train")?;
    let dataset = &data.dataset;
    let head = crate::model::builtin::build_head();
    let (frames, targets) = held_out_targets(dataset, &head)?;
    let (loss_ms, loss_size) = targets.first().map(time_loss).unzip();
    let mut runs = Vec::new();
    for &renderer in &args.renderers {
        runs.push(run_one(args, dataset, &frames, &targets, renderer)?);
    }
    let report = TrainReport {
        dataset: dataset.root.display().to_string(),
        threads: rayon::current_num_threads(),
        gradient_max_relative_error: gradient_error,
        gradient_parameters_checked: checked,
        peak_rss_mb: peak_rss_mb(),
        loss_ms,
        loss_size,
        renderers: runs,
    };
    emit(&report, args.json, print_report);
    Ok(())
}
