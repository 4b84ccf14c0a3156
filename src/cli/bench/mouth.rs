//! `visage bench mouth`: what a mouth cavity is worth to an avatar trained on
//! FLAME-like geometry. One capture of the built-in `ada` (whose head has a
//! hand-made pocket behind the lips, so the truth shows the mouth's inside)
//! trains on three heads with one seed — `pocket`, the built-in head as it is;
//! `open`, its pocket's triangles removed so the lips end at an open rim as
//! FLAME's do; `cavity`, that rim given the generated cavity FLAME models now
//! get (docs/method.md §9.2) — and each is scored on the held-out views, over
//! whole views and over the mouth's box, separately for views whose jaw is
//! open at least 3° and the rest.

use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use super::stats::emit;
use super::train::{held_out_targets, train_to_end, BenchDataset};
use crate::cli::values::parse_size;
use crate::error::Result;
use crate::model::head::{HeadModel, Joint};
use crate::model::open_mouth::{open_rim, region_vertices, with_mouth_cavity};
use crate::model::regions::{Group, Region};
use crate::render::Backend;
use crate::train::composite_eval::OPEN_MOUTH_DEG;
use crate::train::holes::HoleFilling;
use crate::train::model::Trainable;
use crate::train::posing::{posed_vertices, timestep_params};
use crate::train::project::TrainCamera;
use crate::train::target::{evaluate_view, Target};

/// Arguments of `visage bench mouth`.
#[derive(Args, Debug, Clone)]
pub struct MouthBenchArgs {
    /// Dataset of the built-in head to train on (default: a fresh front-arc
    /// capture of `ada`, 16 cameras, 20 frames of `talk`, at --capture-size).
    #[arg(long, value_name = "DIR")]
    dataset: Option<PathBuf>,
    /// Size of the default capture.
    #[arg(long, value_parser = parse_size, default_value = "128x128", value_name = "WxH")]
    capture_size: (u32, u32),
    /// Iterations per head.
    #[arg(long, default_value_t = 1500)]
    iterations: usize,
    /// Seed of every head's training.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Rasteriser (auto, gpu, cpu).
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Pixels the mouth's box reaches beyond the projected mouth triangles.
const BOX_MARGIN_PX: f64 = 2.0;

/// One held-out view: whether its mouth is open and the pixel box of its mouth.
struct ViewMouth {
    open: bool,
    /// x0, y0, x1, y1 (inclusive), clamped to the image.
    bounds: [usize; 4],
}

/// Squared error sums over whole views and mouth boxes, open and closed.
#[derive(Default, Clone, Copy)]
struct Errors {
    /// [closed, open] × (sum of squared errors, values).
    whole: [(f64, usize); 2],
    mouth: [(f64, usize); 2],
}

fn psnr((sum, n): (f64, usize)) -> f64 {
    if n == 0 {
        return f64::NAN;
    }
    let mse = sum / n as f64;
    10.0 * (1.0 / mse.max(1e-12)).log10()
}

/// The box of the mouth group's triangle centres (the truth's head, posed at
/// the view's timestep) seen by the view's camera.
fn mouth_box(head: &HeadModel, posed: &[glam::Vec3], camera: &TrainCamera) -> [usize; 4] {
    let mut lo = [f64::MAX; 2];
    let mut hi = [f64::MIN; 2];
    for (t, r) in head.triangles.iter().zip(&head.triangle_regions) {
        if r.group() != Group::Mouth {
            continue;
        }
        let c = t.iter().map(|&v| posed[v as usize]).sum::<glam::Vec3>() / 3.0;
        let p = std::array::from_fn::<f64, 3, _>(|r| {
            (0..3)
                .map(|k| camera.rotation[r][k] * c[k] as f64)
                .sum::<f64>()
                + camera.translation[r]
        });
        let depth = -p[2];
        if depth <= 0.0 {
            continue;
        }
        let x = p[0] * camera.focal[0] / depth + camera.principal[0];
        let y = -(p[1] * camera.focal[1] / depth) + camera.principal[1];
        lo = [lo[0].min(x), lo[1].min(y)];
        hi = [hi[0].max(x), hi[1].max(y)];
    }
    let [w, h] = camera.size;
    let clamp = |v: f64, n: u32| v.clamp(0.0, (n - 1) as f64) as usize;
    [
        clamp(lo[0] - BOX_MARGIN_PX, w),
        clamp(lo[1] - BOX_MARGIN_PX, h),
        clamp(hi[0] + BOX_MARGIN_PX, w),
        clamp(hi[1] + BOX_MARGIN_PX, h),
    ]
}

/// Per held-out target: its jaw and mouth box on the truth's head.
fn view_mouths(
    dataset: &crate::train::dataset::Dataset,
    head: &HeadModel,
    targets: &[Target],
) -> Result<Vec<ViewMouth>> {
    targets
        .iter()
        .map(|t| {
            let params = timestep_params(dataset, head, t.view.timestep)?;
            let (_, pose) = params.motion.frame(0);
            let jaw = (pose.joints[Joint::Jaw as usize].length() as f64).to_degrees();
            let posed = posed_vertices(&params, head);
            Ok(ViewMouth {
                open: jaw >= OPEN_MOUTH_DEG,
                bounds: mouth_box(head, &posed, &t.camera),
            })
        })
        .collect()
}

/// Scores a trained model on the held-out targets.
fn score(
    model: &Trainable,
    head: &HeadModel,
    dataset: &crate::train::dataset::Dataset,
    targets: &[Target],
    mouths: &[ViewMouth],
) -> Result<Errors> {
    let (frames, _) = held_out_targets(dataset, head)?;
    let mut errors = Errors::default();
    for (t, m) in targets.iter().zip(mouths) {
        let (image, _, _) = evaluate_view(model, &frames[&t.view.timestep], t, [0.0; 3]);
        let w = t.camera.size[0] as usize;
        let k = usize::from(m.open);
        for (p, (a, b)) in image.chunks(3).zip(t.pixels.chunks(3)).enumerate() {
            let sq: f64 = (0..3).map(|c| (a[c] - b[c] as f64).powi(2)).sum();
            errors.whole[k].0 += sq;
            errors.whole[k].1 += 3;
            let (x, y) = (p % w, p / w);
            let [x0, y0, x1, y1] = m.bounds;
            if (x0..=x1).contains(&x) && (y0..=y1).contains(&y) {
                errors.mouth[k].0 += sq;
                errors.mouth[k].1 += 3;
            }
        }
    }
    Ok(errors)
}

/// Runs `visage bench mouth`.
pub fn run(args: &MouthBenchArgs) -> Result<()> {
    let bench = BenchDataset::open(args.dataset.as_deref(), args.capture_size, "mouth")?;
    let dataset = &bench.dataset;
    let pocket = crate::model::builtin::build_head();
    let open = open_rim(&pocket);
    let lips = region_vertices(&open, Region::Lips);
    let cavity = with_mouth_cavity(open.clone(), |v| lips[v as usize]);
    let (_, targets) = held_out_targets(dataset, &pocket)?;
    let mouths = view_mouths(dataset, &pocket, &targets)?;
    let open_views = mouths.iter().filter(|m| m.open).count();
    let mut rows = Vec::new();
    for (name, head) in [("pocket", &pocket), ("open", &open), ("cavity", &cavity)] {
        let (trainer, train_s) = train_to_end(
            dataset,
            head,
            args.iterations,
            args.seed,
            args.renderer,
            HoleFilling::RECOMMENDED,
        )?;
        let model = Trainable::from_set(&trainer.gaussians());
        let e = score(&model, head, dataset, &targets, &mouths)?;
        if !args.json {
            eprintln!("visage: {name} trained in {train_s:.0} s");
        }
        rows.push(MouthRow {
            head: name,
            triangles: head.triangle_count(),
            gaussians: trainer.model.len(),
            open_psnr_db: psnr(e.whole[1]),
            closed_psnr_db: psnr(e.whole[0]),
            open_mouth_psnr_db: psnr(e.mouth[1]),
            closed_mouth_psnr_db: psnr(e.mouth[0]),
            train_s,
        });
    }
    let report = MouthReport {
        dataset: dataset.root.display().to_string(),
        iterations: args.iterations,
        held_out_views: targets.len(),
        open_views,
        heads: rows,
    };
    emit(&report, args.json, print_table);
    Ok(())
}

/// The mouth bench's report.
#[derive(Serialize)]
struct MouthReport {
    dataset: String,
    iterations: usize,
    held_out_views: usize,
    open_views: usize,
    heads: Vec<MouthRow>,
}

/// One head's figures (PSNR in dB; NaN, written null, where no view counts).
#[derive(Serialize)]
struct MouthRow {
    head: &'static str,
    triangles: usize,
    gaussians: usize,
    open_psnr_db: f64,
    closed_psnr_db: f64,
    open_mouth_psnr_db: f64,
    closed_mouth_psnr_db: f64,
    train_s: f64,
}

fn print_table(report: &MouthReport) {
    println!(
        "{} iterations per head; {} held-out views, {} with the jaw open ≥ {OPEN_MOUTH_DEG}°; PSNR dB over whole views and the mouth's box",
        report.iterations, report.held_out_views, report.open_views
    );
    println!(
        "  {:<8} {:>9} {:>10} {:>10} {:>12} {:>11} {:>13} {:>8}",
        "head",
        "triangles",
        "Gaussians",
        "open view",
        "closed view",
        "open mouth",
        "closed mouth",
        "train s"
    );
    for r in &report.heads {
        println!(
            "  {:<8} {:>9} {:>10} {:>10.2} {:>12.2} {:>11.2} {:>13.2} {:>8.0}",
            r.head,
            r.triangles,
            r.gaussians,
            r.open_psnr_db,
            r.closed_psnr_db,
            r.open_mouth_psnr_db,
            r.closed_mouth_psnr_db,
            r.train_s
        );
    }
}
