//! `visage bench render`: frame time per resolution and per stage with PSNR
//! against the CPU reference, and a speed-against-error table over the renderer's
//! knobs (resolution scale, SH degree, sort precision, early-stop threshold).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use serde_json::{json, Value};

use super::bench::{median_stages, open_or_skip, print_skipped, summarize};
use super::bench_paged::{bench_paged, print_paged};
use super::bench_scene::{bench_scene, peak_rss_mb, SceneSource, SCENE_SIZES};
use super::compose::{build, build_from};
use super::render::parse_size;
use super::DbArgs;
use crate::compose::recipe::{ColourCorrection, GroupEdit, Recipe, Smoothing};
use crate::error::{Error, Result};
use crate::pipeline::composer::{reference_image, Composer, Painter};
use crate::pipeline::lod::parse_memory_budget;
use crate::render::image::{psnr_report, RgbImage};
use crate::render::lod::LodPolicy;
use crate::render::settings::RenderSettings;
use crate::render::settings::StageTimings;
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

/// Times `frames` animated renders; returns the per-frame totals and, with
/// `stages`, the stage medians of a second, profiled pass.
fn time_frames(
    painter: &mut Painter,
    composer: &mut Composer,
    camera: &Camera,
    case: &Case,
    (warmup, iterations): (usize, usize),
    stages_too: bool,
) -> Result<(Vec<f64>, StageTimings)> {
    let mut totals = Vec::new();
    let mut stages: Vec<StageTimings> = Vec::new();
    let scaled = scaled_camera(camera, case.scale);
    // Frame times as the editor sees them; then the same frames again with the
    // GPU waiting after each stage, for the stage breakdown.
    for profiled in [false, true] {
        if profiled && !stages_too {
            break;
        }
        painter.renderer_mut().set_stage_profiling(profiled);
        for it in 0..warmup + iterations {
            composer.pose(it);
            let t = Instant::now();
            let image = painter.render(composer, &scaled, &case.settings)?;
            if case.scale != 1.0 {
                let _ = image.resized(camera.width, camera.height);
            }
            let total = t.elapsed().as_secs_f64() * 1e3;
            if it < warmup {
                continue;
            }
            if profiled {
                stages.push(painter.renderer_mut().timings());
            } else {
                totals.push(total);
            }
        }
    }
    painter.renderer_mut().set_stage_profiling(false);
    Ok((totals, median_stages(&stages)))
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
    let source = match (&args.ply, args.synthetic_scale) {
        (Some(path), _) => Some(SceneSource::File(path)),
        (None, Some(0)) => return Err(Error::input("--synthetic-scale must be at least 1")),
        (None, Some(n)) => Some(SceneSource::Synthetic(n)),
        (None, None) => None,
    };
    if let Some(source) = source {
        let sizes = if args.sizes.is_empty() {
            SCENE_SIZES.to_vec()
        } else {
            args.sizes.clone()
        };
        if let (Some(budget), Some(path)) = (args.memory_budget, &args.ply) {
            let doc = bench_paged(
                path,
                &sizes,
                &args.renderers,
                args.frames.max(1),
                args.lod,
                budget,
            )?;
            if args.json {
                println!("{}", serde_json::to_string_pretty(&doc).unwrap_or_default());
            } else {
                print_paged(&doc);
            }
            return Ok(());
        }
        let doc = bench_scene(
            source,
            &sizes,
            &args.renderers,
            (args.warmup, args.iterations),
            (!args.no_knobs).then_some(args.knob_size),
            args.lod,
        )?;
        return print(&doc, args.json);
    }
    let sizes = if args.sizes.is_empty() {
        vec![(160, 120), (320, 240), (640, 480), (1280, 720)]
    } else {
        args.sizes.clone()
    };
    let t = Instant::now();
    let (mut composer, _) = match &args.recipe {
        Some(path) => build(&args.db, path, Some(0))?,
        None => build_from(&args.db, Some(0), bench_recipe_for)?,
    };
    let orbit = composer.composite().recipe.camera;
    let exact = Case {
        settings: RenderSettings::default(),
        scale: 1.0,
    };
    let mut references = Vec::new();
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    for &(w, h) in &sizes {
        let camera = orbit.camera(w, h);
        let t = Instant::now();
        let image = reference_image(&composer, &camera, &RenderSettings::default());
        references.push((camera, image, t.elapsed().as_secs_f64() * 1e3));
    }
    let mut renderers = Vec::new();
    let mut skipped = Vec::new();
    for &backend in &args.renderers {
        let t = Instant::now();
        let opened = Painter::open(backend);
        let Some(mut painter) = open_or_skip(opened, backend, args.renderers.len(), &mut skipped)?
        else {
            continue;
        };
        let setup_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        painter.upload(&composer)?;
        let upload_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut rows = Vec::new();
        for (camera, reference, reference_ms) in &references {
            let psnr_db = accuracy(&mut painter, &mut composer, camera, &exact, reference)?;
            let (totals, stages) = time_frames(
                &mut painter,
                &mut composer,
                camera,
                &exact,
                (args.warmup, args.iterations),
                true,
            )?;
            let (median, p90) = summarize(totals);
            rows.push(json!({
                "width": camera.width, "height": camera.height, "ms_median": median, "ms_p90": p90, "fps": 1e3 / median,
                "psnr_db": psnr_db, "stages_ms": stages, "reference_ms": reference_ms,
            }));
        }
        let mut knobs = Vec::new();
        if !args.no_knobs {
            let (w, h) = args.knob_size;
            let camera = orbit.camera(w, h);
            composer.pose(0);
            let reference = reference_image(&composer, &camera, &RenderSettings::default());
            for (knob, value, case) in knob_cases() {
                let psnr_db = accuracy(&mut painter, &mut composer, &camera, &case, &reference)?;
                let (totals, _) = time_frames(
                    &mut painter,
                    &mut composer,
                    &camera,
                    &case,
                    (args.warmup, args.iterations),
                    false,
                )?;
                let (median, p90) = summarize(totals);
                knobs.push(json!({
                    "knob": knob, "value": value, "width": w, "height": h,
                    "ms_median": median, "ms_p90": p90, "psnr_db": psnr_db,
                }));
            }
        }
        renderers.push(json!({
            "renderer": backend,
            "device": painter.description(),
            "setup_ms": setup_ms,
            "gaussian_upload_ms": upload_ms,
            "rows": rows,
            "knobs": knobs,
        }));
    }
    let doc = json!({
        "bench": "render",
        "gaussians": composer.composite().gaussians.len(),
        "load_ms": load_ms,
        "peak_rss_mb": peak_rss_mb(),
        "renderers": renderers,
        "skipped": skipped,
    });
    print(&doc, args.json)
}

fn print(doc: &Value, json: bool) -> Result<()> {
    if json {
        println!("{doc}");
    } else {
        print_tables(doc);
    }
    Ok(())
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

fn print_tables(doc: &Value) {
    println!(
        "render bench: {} Gaussians{}; loaded in {:.0} ms{}, peak memory {}",
        doc["gaussians"],
        doc["scene"]
            .as_str()
            .map(|s| format!(" ({s})"))
            .unwrap_or_default(),
        doc["load_ms"].as_f64().unwrap_or(0.0),
        doc["load_peak_rss_mb"]
            .as_f64()
            .map(|m| format!(" (peak {m:.0} MiB after loading)"))
            .unwrap_or_default(),
        doc["peak_rss_mb"]
            .as_f64()
            .map_or("unknown".to_string(), |m| format!("{m:.0} MiB"))
    );
    if let Some(ms) = doc["lod_build_ms"].as_f64() {
        println!(
            "level of detail ({}): {} nodes built in {ms:.0} ms",
            doc["lod"].as_str().unwrap_or(""),
            doc["lod_nodes"]
        );
    }
    for r in doc["renderers"].as_array().into_iter().flatten() {
        print_renderer(r);
        print_lod_rows(r);
    }
    print_skipped(doc);
}

/// The rows' level-of-detail columns, when measured: a moving camera's
/// frame (cut, gather, upload, render), the cut's PSNR against the full
/// scene's reference, and what it drew.
fn print_lod_rows(doc: &Value) {
    let rows: Vec<&Value> = doc["rows"]
        .as_array()
        .into_iter()
        .flatten()
        .filter(|r| r.get("lod_ms_median").is_some())
        .collect();
    if rows.is_empty() {
        return;
    }
    println!(
        "with level of detail:\n{:>10} {:>9} {:>7} {:>9} {:>9} {:>7} {:>7}",
        "size", "median ms", "FPS", "PSNR dB", "drawn", "levels", "cut ms"
    );
    for r in rows {
        println!(
            "{:>10} {:>9.2} {:>7.1} {:>9.1} {:>9} {:>7} {:>7.2}",
            format!("{}x{}", r["width"], r["height"]),
            r["lod_ms_median"].as_f64().unwrap_or(0.0),
            r["lod_fps"].as_f64().unwrap_or(0.0),
            r["lod_psnr_db"].as_f64().unwrap_or(0.0),
            match &r["lod_drawn"] {
                Value::String(s) => s.clone(),
                n => n.to_string(),
            },
            match &r["lod_levels"] {
                Value::Array(l) => format!("{}-{}", l[0], l[1]),
                _ => "all".into(),
            },
            r["lod_cut_ms"].as_f64().unwrap_or(0.0),
        );
    }
}

fn print_renderer(doc: &Value) {
    println!(
        "\n{}: set-up {:.0} ms, Gaussian upload {:.1} ms",
        doc["device"].as_str().unwrap_or(""),
        doc["setup_ms"].as_f64().unwrap_or(0.0),
        doc["gaussian_upload_ms"].as_f64().unwrap_or(0.0)
    );
    println!(
        "{:>10} {:>9} {:>9} {:>7} {:>9}  stages (upload/project/sort/raster/readback ms)",
        "size", "median ms", "p90 ms", "FPS", "PSNR dB"
    );
    for r in doc["rows"].as_array().into_iter().flatten() {
        if let Some(error) = r["error"].as_str() {
            println!(
                "{:>10} not drawn: {error}",
                format!("{}x{}", r["width"], r["height"])
            );
            continue;
        }
        let s = &r["stages_ms"];
        let f = |k: &str| s[k].as_f64().unwrap_or(0.0);
        println!(
            "{:>10} {:>9.2} {:>9.2} {:>7.1} {:>9.1}  {:.2}/{:.2}/{:.2}/{:.2}/{:.2}",
            format!("{}x{}", r["width"], r["height"]),
            r["ms_median"].as_f64().unwrap_or(0.0),
            r["ms_p90"].as_f64().unwrap_or(0.0),
            r["fps"].as_f64().unwrap_or(0.0),
            r["psnr_db"].as_f64().unwrap_or(0.0),
            f("upload"),
            f("project"),
            f("sort"),
            f("rasterize"),
            f("readback"),
        );
    }
    if let Some(knobs) = doc["knobs"].as_array().filter(|k| !k.is_empty()) {
        println!(
            "speed against error at {}x{}:",
            knobs[0]["width"], knobs[0]["height"]
        );
        println!(
            "{:<17} {:>7} {:>9} {:>9}",
            "knob", "value", "median ms", "PSNR dB"
        );
        for k in knobs {
            println!(
                "{:<17} {:>7} {:>9.2} {:>9.1}",
                k["knob"].as_str().unwrap_or(""),
                k["value"].as_str().unwrap_or(""),
                k["ms_median"].as_f64().unwrap_or(0.0),
                k["psnr_db"].as_f64().unwrap_or(0.0)
            );
        }
    }
}
