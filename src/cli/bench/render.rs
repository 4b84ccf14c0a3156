//! `visage bench render`: frame time per resolution and per stage with PSNR
//! against the CPU reference, and a speed-against-error table over the renderer's
//! knobs (resolution scale, SH degree, sort precision, early-stop threshold).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use super::paged::{bench_paged, print_paged};
use super::render_report::{
    print_tables, FrameFigures, KnobRow, RenderReport, RendererReport, SizeOutcome, SizeRow,
};
use super::scene::{bench_scene, SceneSource, SCENE_SIZES};
use super::stats::{emit, ms_since, open_and_upload, peak_rss_mb, summarize, time_frames, Rounds};
use crate::cli::compose::{build, build_from, FitArgs};
use crate::cli::values::parse_size;
use crate::cli::DbArgs;
use crate::compose::recipe::{ColourCorrection, GroupEdit, Recipe, Smoothing};
use crate::error::{Error, Result};
use crate::pipeline::composer::{reference_image, Composer, Painter};
use crate::pipeline::lod::parse_memory_budget;
use crate::render::image::{psnr_report, RgbImage};
use crate::render::lod::LodPolicy;
use crate::render::settings::RenderSettings;
use crate::render::Backend;
use crate::scene::camera::Camera;

/// Arguments of `visage bench render`.
#[derive(Args, Debug, Clone)]
pub struct RenderBenchArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Recipe to render (default: a four-source composite with cross-fade and skin correction).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["ply", "synthetic_scale"])]
    recipe: Option<PathBuf>,
    /// A 3DGS scene (.ply, .compressed.ply, .splat or .spz) to measure instead of a composite.
    #[arg(long, value_name = "FILE", conflicts_with = "synthetic_scale")]
    ply: Option<PathBuf>,
    /// A deterministic synthetic scene of N Gaussians to measure instead of a composite.
    #[arg(long, value_name = "N")]
    synthetic_scale: Option<usize>,
    /// Image sizes, comma-separated WxH (default: 160x120,320x240,640x480,1280x720
    /// for composites; 120x80,200x120,320x240,640x480 for scenes).
    #[arg(long, value_delimiter = ',', value_parser = parse_size)]
    sizes: Vec<(u32, u32)>,
    /// Size at which the knobs are compared.
    #[arg(long, default_value = "320x240", value_parser = parse_size)]
    knob_size: (u32, u32),
    /// Timed frames per case (after the warm-up ones).
    #[arg(long, default_value_t = 30)]
    iterations: usize,
    /// Warm-up frames per case.
    #[arg(long, default_value_t = 5)]
    warmup: usize,
    /// Renderer(s) to measure, comma-separated: gpu (wgpu on any adapter,
    /// lavapipe included), cpu, auto.
    #[arg(long, value_parser = Backend::parse, value_delimiter = ',', default_value = "gpu,cpu")]
    renderers: Vec<Backend>,
    /// Skip the knob table.
    #[arg(long)]
    no_knobs: bool,
    /// Level of detail measured beside the exact path on scenes: off, auto
    /// (nodes of at most 1.5 px), or a budget of Gaussians (e.g. 300k).
    #[arg(long, default_value = "auto", value_parser = LodPolicy::parse)]
    lod: LodPolicy,
    /// Draw the scene (--ply) from its level-of-detail cache within this
    /// much memory (e.g. 1G), as `view` does a scene larger than memory:
    /// the cache is built first where it is missing, and the camera turns
    /// between frames.
    #[arg(long, value_name = "SIZE", value_parser = parse_memory_budget, requires = "ply")]
    memory_budget: Option<usize>,
    /// Frames per size with --memory-budget.
    #[arg(long, default_value_t = 60)]
    frames: usize,
    /// Print one JSON document instead of tables.
    #[arg(long)]
    json: bool,
}

/// The composite benchmarked when no recipe is given: the built-in benchmark
/// composite where the database has its sources, else the database's first
/// source animated by the first motion (its own, for a folder database).
pub fn bench_recipe_for(db: &crate::avatar::database::Database) -> Recipe {
    let builtin = default_bench_recipe();
    if builtin.resolve(db).is_ok() {
        return builtin;
    }
    let first = &db.sources[0].name;
    let mut recipe = Recipe::unedited(first);
    recipe.animation.motion = if db.motion_index(first).is_some() {
        first.clone()
    } else {
        db.motions.first().map_or("rest".into(), |m| m.name.clone())
    };
    recipe
}

/// The built-in database's benchmark composite (ada with jomo's eyes, bram's
/// nose and ines's mouth, shapes blended, crossfade + skin correction).
pub fn default_bench_recipe() -> Recipe {
    let mut r = Recipe::unedited("ada");
    let edit = |src: &str, with: &[(&str, f64)]| GroupEdit {
        gaussians: src.into(),
        shape: with.iter().map(|(k, v)| (k.to_string(), *v)).collect(),
    };
    r.groups
        .insert("eyes".into(), edit("jomo", &[("jomo", 0.5), ("ada", 0.5)]));
    r.groups
        .insert("nose".into(), edit("bram", &[("bram", 0.7), ("ada", 0.3)]));
    r.groups
        .insert("mouth".into(), edit("ines", &[("ines", 0.6), ("ada", 0.4)]));
    r.post.smoothing = Smoothing::Crossfade;
    r.post.colour = ColourCorrection::Skin;
    r.animation.motion = "talk".into();
    r
}

struct Case {
    settings: RenderSettings,
    scale: f32,
}

/// Times animated renders of `case` at `camera` (frame `i` of the motion
/// for round `i`), as the editor sees them; with `stages_too`, the stage
/// medians of a second, profiled pass.
fn time_case(
    painter: &mut Painter,
    composer: &mut Composer,
    camera: &Camera,
    case: &Case,
    rounds: Rounds,
    stages_too: bool,
) -> Result<(Vec<f64>, crate::render::settings::StageTimings)> {
    let scaled = scaled_camera(camera, case.scale);
    time_frames(painter, rounds, stages_too, |painter, it| {
        composer.pose(it);
        let image = painter.render(composer, &scaled, &case.settings)?;
        if case.scale != 1.0 {
            let _ = image.resized(camera.width, camera.height);
        }
        Ok(())
    })
}

fn scaled_camera(camera: &Camera, scale: f32) -> Camera {
    Camera {
        width: ((camera.width as f32 * scale).round() as u32).max(1),
        height: ((camera.height as f32 * scale).round() as u32).max(1),
        ..*camera
    }
}

/// PSNR of frame 0 (rendered with `case`) against the reference at full size.
fn accuracy(
    painter: &mut Painter,
    composer: &mut Composer,
    camera: &Camera,
    case: &Case,
    reference: &RgbImage,
) -> Result<f64> {
    composer.pose(0);
    let image = painter.render(composer, &scaled_camera(camera, case.scale), &case.settings)?;
    let image = if case.scale != 1.0 {
        image.resized(camera.width, camera.height)
    } else {
        image
    };
    Ok(psnr_report(&image, reference).unwrap_or(0.0))
}

/// Runs `visage bench render`.
pub fn run(args: &RenderBenchArgs) -> Result<()> {
    if args.iterations == 0 {
        return Err(Error::input("--iterations must be at least 1"));
    }
    let rounds = Rounds {
        warmup: args.warmup,
        timed: args.iterations,
    };
    let source = match (&args.ply, args.synthetic_scale) {
        (Some(path), _) => Some(SceneSource::File(path)),
        (None, Some(0)) => return Err(Error::input("--synthetic-scale must be at least 1")),
        (None, Some(n)) => Some(SceneSource::Synthetic(n)),
        (None, None) => None,
    };
    let Some(source) = source else {
        let report = bench_composite(args, rounds)?;
        emit(&report, args.json, print_tables);
        return Ok(());
    };
    let sizes = if args.sizes.is_empty() {
        SCENE_SIZES.to_vec()
    } else {
        args.sizes.clone()
    };
    if let (Some(budget), Some(path)) = (args.memory_budget, &args.ply) {
        let frames = args.frames.max(1);
        let report = bench_paged(path, &sizes, &args.renderers, frames, args.lod, budget)?;
        emit(&report, args.json, print_paged);
        return Ok(());
    }
    let report = bench_scene(
        source,
        &sizes,
        &args.renderers,
        rounds,
        (!args.no_knobs).then_some(args.knob_size),
        args.lod,
    )?;
    emit(&report, args.json, print_tables);
    Ok(())
}

/// The render bench on a composite: the recipe's (or the built-in
/// benchmark composite's) frames per size and renderer, and the knobs.
fn bench_composite(args: &RenderBenchArgs, rounds: Rounds) -> Result<RenderReport> {
    let sizes = if args.sizes.is_empty() {
        vec![(160, 120), (320, 240), (640, 480), (1280, 720)]
    } else {
        args.sizes.clone()
    };
    let t = Instant::now();
    let (mut composer, _) = match &args.recipe {
        // Drawing speed does not depend on fitted colours: no seam fit.
        Some(path) => build(&args.db, path, Some(0), &FitArgs::OFF)?,
        None => build_from(&args.db, Some(0), bench_recipe_for)?,
    };
    let orbit = composer.composite().recipe.camera;
    let exact = Case {
        settings: RenderSettings::default(),
        scale: 1.0,
    };
    let mut references = Vec::new();
    let load_ms = ms_since(t);
    for &(w, h) in &sizes {
        let camera = orbit.camera(w, h);
        let t = Instant::now();
        let image = reference_image(&composer, &camera, &RenderSettings::default());
        references.push((camera, image, ms_since(t)));
    }
    let mut renderers = Vec::new();
    let mut skipped = Vec::new();
    for &backend in &args.renderers {
        let asked = args.renderers.len();
        let upload = |painter: &mut Painter| painter.upload(&composer);
        let Some(opened) = open_and_upload(backend, asked, &mut skipped, Painter::open, upload)?
        else {
            continue;
        };
        let mut painter = opened.renderer;
        let mut rows = Vec::new();
        for (camera, reference, reference_ms) in &references {
            let psnr_db = accuracy(&mut painter, &mut composer, camera, &exact, reference)?;
            let (totals, stages_ms) =
                time_case(&mut painter, &mut composer, camera, &exact, rounds, true)?;
            let (ms_median, ms_p90) = summarize(totals);
            rows.push(SizeRow {
                width: camera.width,
                height: camera.height,
                outcome: SizeOutcome::Drawn(FrameFigures {
                    ms_median,
                    ms_p90,
                    fps: 1e3 / ms_median,
                    psnr_db,
                    stages_ms,
                    reference_ms: *reference_ms,
                }),
                lod: None,
            });
        }
        let mut knobs = Vec::new();
        if !args.no_knobs {
            let (width, height) = args.knob_size;
            let camera = orbit.camera(width, height);
            composer.pose(0);
            let reference = reference_image(&composer, &camera, &RenderSettings::default());
            for (knob, value, case) in knob_cases() {
                let psnr_db = accuracy(&mut painter, &mut composer, &camera, &case, &reference)?;
                let (totals, _) =
                    time_case(&mut painter, &mut composer, &camera, &case, rounds, false)?;
                let (ms_median, ms_p90) = summarize(totals);
                knobs.push(KnobRow {
                    knob,
                    value,
                    width,
                    height,
                    ms_median,
                    ms_p90,
                    psnr_db,
                });
            }
        }
        renderers.push(RendererReport {
            renderer: backend,
            device: painter.description(),
            setup_ms: opened.setup_ms,
            gaussian_upload_ms: opened.upload_ms,
            rows,
            knobs,
        });
    }
    Ok(RenderReport {
        bench: "render",
        gaussians: composer.composite().gaussians.len(),
        load_ms,
        scene: None,
        peak_rss_mb: peak_rss_mb(),
        renderers,
        skipped,
    })
}

/// The knob settings compared at one size: (knob, value, case).
fn knob_cases() -> Vec<(&'static str, String, Case)> {
    let base = RenderSettings::default();
    let mut cases: Vec<(&str, String, Case)> = vec![(
        "default",
        "exact".into(),
        Case {
            settings: base,
            scale: 1.0,
        },
    )];
    for scale in [0.75f32, 0.5, 0.25] {
        cases.push((
            "resolution_scale",
            format!("{scale}"),
            Case {
                settings: base,
                scale,
            },
        ));
    }
    for degree in [0u8, 1, 2] {
        cases.push((
            "sh_degree",
            format!("{degree}"),
            Case {
                settings: RenderSettings {
                    sh_degree: degree,
                    ..base
                },
                scale: 1.0,
            },
        ));
    }
    for bits in [16u8, 8] {
        cases.push((
            "sort_bits",
            format!("{bits}"),
            Case {
                settings: RenderSettings {
                    sort_bits: bits,
                    ..base
                },
                scale: 1.0,
            },
        ));
    }
    for stop in [1e-3f32, 1e-2, 5e-2] {
        cases.push((
            "early_stop",
            format!("{stop}"),
            Case {
                settings: RenderSettings {
                    early_stop: stop,
                    ..base
                },
                scale: 1.0,
            },
        ));
    }
    cases
}
