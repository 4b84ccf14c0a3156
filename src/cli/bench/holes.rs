//! `visage bench holes`: the thesis's hole filling measured. Trains the same
//! capture six ways with one seed — plain, the thesis's obscuring Gaussian,
//! back-face culling, both, and this project's opaque interior layer alone
//! and with culling — and reports leak, coverage, held-out PSNR, Gaussians
//! and training time side by side, with a picture grid like the thesis's
//! Table 6.2.

use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use super::stats::emit;
use super::train::{held_out_psnr, held_out_targets, train_to_end, BenchDataset};
use crate::cli::values::parse_size;
use crate::error::{Error, Result};
use crate::render::image::RgbImage;
use crate::render::Backend;
use crate::train::hole_metrics::{
    self, head_centre, repaint, turn, HoleSummary, FAR_SIDE, LEAK_COLOUR,
};
use crate::train::holes::HoleFilling;
use crate::train::holes::Obscurer;
use crate::train::model::{Render, Trainable};
use crate::train::posing::training_arc;
use crate::train::project::TrainCamera;
use crate::train::raster::Rasterizer;

/// Arguments of `visage bench holes`.
#[derive(Args, Debug, Clone)]
pub struct HolesBenchArgs {
    /// Dataset to train on (default: a fresh front-arc capture of the
    /// built-in `ada`, 16 cameras, 20 frames of `talk`, at --capture-size).
    #[arg(long, value_name = "DIR")]
    dataset: Option<PathBuf>,
    /// Size of the default capture.
    #[arg(long, value_parser = parse_size, default_value = "256x256", value_name = "WxH")]
    capture_size: (u32, u32),
    /// Iterations per variant.
    #[arg(long, default_value_t = 3000)]
    iterations: usize,
    /// The culling variants' threshold τ (share of training views).
    #[arg(long, default_value_t = DEFAULT_CULL, value_name = "TAU")]
    cull_backfaces: f64,
    /// Seed of every variant.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Rasteriser (auto, gpu, cpu).
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Picture grid: a row per variant, the head turning from the front to
    /// behind with hair, neck and ears repainted green.
    #[arg(long, value_name = "PNG", default_value = "holes.png")]
    grid: PathBuf,
    /// Variants to train, comma-separated (default: all six).
    #[arg(
        long,
        value_delimiter = ',',
        value_name = "LIST",
        default_value = "plain,obscuring,culling,both,interior,interior+culling"
    )]
    variants: Vec<String>,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// The default culling threshold τ.
pub const DEFAULT_CULL: f64 = 0.05;

/// Turns of the grid's columns, degrees from the most frontal training view.
const GRID_TURNS: [f64; 5] = [0.0, 45.0, 90.0, 135.0, 180.0];

/// Runs `visage bench holes`.
pub fn run(args: &HolesBenchArgs) -> Result<()> {
    if !(0.0..=1.0).contains(&args.cull_backfaces) {
        return Err(Error::input(format!(
            "--cull-backfaces takes a share of views from 0 to 1, not {}",
            args.cull_backfaces
        )));
    }
    let data = BenchDataset::open(args.dataset.as_deref(), args.capture_size, "holes")?;
    let dataset = &data.dataset;
    let head = crate::model::builtin::build_head();
    let (frames, targets) = held_out_targets(dataset, &head)?;
    let (posed, cameras) = training_arc(dataset, &head, hole_metrics::METRIC_SIDE)?;
    let tau = Some(args.cull_backfaces);
    let variant = |obscuring, interior, cull_below| HoleFilling {
        obscuring,
        interior,
        cull_below,
    };
    let variants = [
        ("plain", variant(false, false, None)),
        ("obscuring", variant(true, false, None)),
        ("culling", variant(false, false, tau)),
        ("both", variant(true, false, tau)),
        ("interior", variant(false, true, None)),
        ("interior+culling", variant(false, true, tau)),
    ];
    for name in &args.variants {
        if !variants.iter().any(|(n, _)| n == name) {
            return Err(Error::input(format!(
                "unknown variant '{}' (variants: {})",
                crate::text::printable(name),
                variants.map(|(n, _)| n).join(", ")
            )));
        }
    }
    let front = most_frontal(&cameras, &posed);
    let mut rows = Vec::new();
    let mut grid = Vec::new();
    let mut device = String::new();
    for (name, holes) in variants
        .into_iter()
        .filter(|(n, _)| args.variants.iter().any(|v| v == n))
    {
        let (trainer, train_s) = train_to_end(
            dataset,
            &head,
            args.iterations,
            args.seed,
            args.renderer,
            holes,
        )?;
        device = trainer.rasterizer();
        let model = Trainable::from_set(&trainer.gaussians());
        let metrics = hole_metrics::measure(&model, &head, &posed, &cameras);
        grid.push(turning_row(&model, &head, &posed, &front));
        if !args.json {
            eprintln!("visage: {name} done in {train_s:.0} s");
        }
        rows.push(VariantRow {
            variant: name,
            holes: metrics.summary(),
            psnr_db: held_out_psnr(&model, &frames, &targets),
            gaussians: trainer.model.len(),
            triangles_trained: trainer.triangles_kept().0,
            train_s,
        });
    }
    write_rows(&grid, &args.grid)?;
    let report = HolesReport {
        dataset: dataset.root.display().to_string(),
        iterations: args.iterations,
        cull_backfaces: args.cull_backfaces,
        device,
        grid: args.grid.display().to_string(),
        variants: rows,
    };
    emit(&report, args.json, print_table);
    Ok(())
}

/// The holes bench's report.
#[derive(Serialize)]
struct HolesReport {
    dataset: String,
    iterations: usize,
    cull_backfaces: f64,
    device: String,
    grid: String,
    variants: Vec<VariantRow>,
}

/// One variant's figures.
#[derive(Serialize)]
struct VariantRow {
    variant: &'static str,
    #[serde(flatten)]
    holes: HoleSummary,
    psnr_db: f64,
    gaussians: usize,
    triangles_trained: usize,
    train_s: f64,
}

fn print_table(report: &HolesReport) {
    println!(
        "{} iterations per variant on {}; τ = {}; grid in {}",
        report.iterations, report.dataset, report.cull_backfaces, report.grid
    );
    println!("  variant           leak ΔE  leak PSNR  coverage  beyond ±30°  PSNR dB  Gaussians  triangles  train s");
    for r in &report.variants {
        println!(
            "  {:<16} {:>8.2} {:>10.1} {:>9.3} {:>12.3} {:>8.2} {:>10} {:>10} {:>8.0}",
            r.variant,
            r.holes.leak_delta_e,
            r.holes.leak_psnr_db,
            r.holes.coverage,
            r.holes.coverage_beyond,
            r.psnr_db,
            r.gaussians,
            r.triangles_trained,
            r.train_s
        );
    }
}

/// The training camera looking most squarely at the head's front (the one
/// nearest the cameras' mean direction from the head).
fn most_frontal(cameras: &[TrainCamera], posed: &[glam::Vec3]) -> TrainCamera {
    let centre = head_centre(posed);
    let direction = |c: &TrainCamera| (glam::DVec3::from(c.eye) - centre).normalize_or_zero();
    let mean = cameras.iter().map(direction).sum::<glam::DVec3>();
    *cameras
        .iter()
        .max_by(|a, b| direction(a).dot(mean).total_cmp(&direction(b).dot(mean)))
        .expect("the training arc has cameras")
}

/// The avatar with its far side repainted, seen from `front` turned by each
/// of [`GRID_TURNS`].
fn turning_row(
    model: &Trainable,
    head: &crate::model::head::HeadModel,
    posed: &[glam::Vec3],
    front: &TrainCamera,
) -> Vec<RgbImage> {
    let far = |t: u32| FAR_SIDE.contains(&head.triangle_regions[t as usize].group());
    let painted = repaint(model, far, LEAK_COLOUR);
    let frames = crate::avatar::binding::triangle_frames(posed, &head.triangles);
    let pivot = head_centre(posed);
    GRID_TURNS
        .iter()
        .map(|&deg| {
            let camera = turn(front, pivot, deg);
            let render = Render::new(
                &painted,
                &frames,
                &camera,
                [1.0; 3],
                &Obscurer::None,
                &mut Rasterizer::Cpu,
            )
            .expect("the CPU rasteriser does not fail");
            let [w, h] = camera.size;
            RgbImage {
                width: w,
                height: h,
                pixels: render
                    .image()
                    .iter()
                    .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                    .collect(),
            }
        })
        .collect()
}

/// Writes rows of equally sized images as one PNG.
fn write_rows(rows: &[Vec<RgbImage>], path: &std::path::Path) -> Result<()> {
    let Some(first) = rows.first().and_then(|r| r.first()) else {
        return Ok(());
    };
    let (w, h) = (first.width, first.height);
    let columns = rows.iter().map(Vec::len).max().unwrap_or(0) as u32;
    let mut out = RgbImage::new(columns * w, rows.len() as u32 * h, [255, 255, 255]);
    for (r, row) in rows.iter().enumerate() {
        for (c, image) in row.iter().enumerate() {
            for y in 0..h {
                let from = (y * w * 3) as usize;
                let to = (((r as u32 * h + y) * out.width + c as u32 * w) * 3) as usize;
                out.pixels[to..to + (w * 3) as usize]
                    .copy_from_slice(&image.pixels[from..from + (w * 3) as usize]);
            }
        }
    }
    out.save_png(path)
}
