//! `visage bench`: the thesis benchmark (6.4) of the composition engine, with the
//! error each measured path trades against.

use std::time::Instant;

use clap::{Args, Subcommand};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde_json::{json, Value};

use super::DbArgs;
use crate::compose::blend::Blender;
use crate::compose::engine::{Engine, PosedMesh};
use crate::compose::recipe::{
    AnimationMode, ColourCorrection, Deform, Membership, PostProcess, ResolvedRecipe, Smoothing,
};
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::scene::camera::Orbit;

/// Arguments of `visage bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Subcommand, Debug, Clone)]
enum BenchWhat {
    /// Animate / change shape / change assignment, per number of sources.
    Engine(EngineBenchArgs),
    /// Frame time per resolution and stage, and speed against error per knob.
    Render(super::bench_render::RenderBenchArgs),
    /// Encode time, bytes and end-to-end FPS per terminal graphics protocol.
    Terminal(super::bench_terminal::TerminalBenchArgs),
    /// Training speed, held-out PSNR against time, gradient error.
    Train(super::bench_train::TrainBenchArgs),
    /// Hole filling: leak, coverage and PSNR of plain, obscuring, culling, both.
    Holes(super::bench_holes::HolesBenchArgs),
    /// Composites against their ground truth: a fixed set of recipes over
    /// trained (cached) sources, every composite metric per recipe.
    Composites(super::bench_composites::CompositesBenchArgs),
    /// The mouth cavity: one capture trained on the built-in head with its
    /// pocket, with the pocket removed (FLAME-like) and with the generated
    /// cavity; open- and closed-mouth PSNR over views and the mouth's box.
    Mouth(super::bench_mouth::MouthBenchArgs),
}

#[derive(Args, Debug, Clone)]
struct EngineBenchArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Source counts to measure, comma-separated.
    #[arg(long, value_delimiter = ',', default_values_t = [2usize, 4, 6, 8, 10, 12, 14])]
    sources: Vec<usize>,
    /// Timed iterations per case (after the warm-up ones).
    #[arg(long, default_value_t = 100)]
    iterations: usize,
    /// Warm-up iterations per case.
    #[arg(long, default_value_t = 10)]
    warmup: usize,
    /// Print one JSON document instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `visage bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    match &args.what {
        BenchWhat::Engine(a) => engine_bench(a),
        BenchWhat::Render(a) => super::bench_render::run(a),
        BenchWhat::Terminal(a) => super::bench_terminal::run(a),
        BenchWhat::Train(a) => super::bench_train::run(a),
        BenchWhat::Holes(a) => super::bench_holes::run(a),
        BenchWhat::Composites(a) => super::bench_composites::run(a),
        BenchWhat::Mouth(a) => super::bench_mouth::run(a),
    }
}

/// Median and 90th percentile of timings in milliseconds.
/// The median of each stage over profiled frames (zeros when there are none).
pub fn median_stages(
    stages: &[crate::render::settings::StageTimings],
) -> crate::render::settings::StageTimings {
    use crate::render::settings::StageTimings;
    if stages.is_empty() {
        return StageTimings::default();
    }
    let median = |f: fn(&StageTimings) -> f64| summarize(stages.iter().map(f).collect()).0;
    StageTimings {
        upload: median(|s| s.upload),
        project: median(|s| s.project),
        sort: median(|s| s.sort),
        rasterize: median(|s| s.rasterize),
        readback: median(|s| s.readback),
    }
}

/// A renderer opened for a benchmark, or — when the graphics device is
/// missing and other renderers were asked for too — `None`, with the reason
/// added to `skipped` (a machine without a GPU still measures its CPU).
pub fn open_or_skip<T>(
    opened: crate::error::Result<T>,
    backend: crate::render::Backend,
    asked: usize,
    skipped: &mut Vec<serde_json::Value>,
) -> crate::error::Result<Option<T>> {
    match opened {
        Ok(t) => Ok(Some(t)),
        Err(e @ crate::error::Error::Device(_)) if asked > 1 => {
            eprintln!("visage: skipping the {} renderer: {e}", backend.name());
            skipped.push(serde_json::json!({ "renderer": backend, "reason": e.to_string() }));
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// Prints the renderers a benchmark skipped, and why.
pub fn print_skipped(doc: &serde_json::Value) {
    for s in doc["skipped"].as_array().into_iter().flatten() {
        println!(
            "\n{} renderer skipped: {}",
            s["renderer"].as_str().unwrap_or("?"),
            s["reason"].as_str().unwrap_or("")
        );
    }
}

/// Median and 90th percentile of frame times.
pub fn summarize(mut ms: Vec<f64>) -> (f64, f64) {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.9))
}

fn time<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let out = f();
    (out, t.elapsed().as_secs_f64() * 1e3)
}

/// Random convex weights over the first `n` sources (stick breaking).
fn stick_breaking(rng: &mut ChaCha8Rng, n: usize, total: usize) -> Vec<f64> {
    let mut w = vec![0.0; total];
    let mut left = 1.0;
    let order: Vec<usize> = {
        let mut o: Vec<usize> = (0..n).collect();
        for i in (1..n).rev() {
            o.swap(i, rng.random_range(0..=i));
        }
        o
    };
    for (k, &f) in order.iter().enumerate() {
        let take = if k + 1 == n {
            left
        } else {
            left * rng.random::<f64>()
        };
        w[f] = take;
        left -= take;
    }
    w
}

fn recipe(
    n_total: usize,
    post: PostProcess,
    mode: AnimationMode,
    motion: Option<usize>,
) -> ResolvedRecipe {
    ResolvedRecipe {
        base: 0,
        gaussians: [0; Group::COUNT],
        shape: std::array::from_fn(|_| {
            let mut r = vec![0.0; n_total];
            r[0] = 1.0;
            r
        }),
        post,
        motion,
        frame: 0,
        mode,
        offsets: Default::default(),
        camera: Orbit::STUDY,
    }
}

fn engine_bench(args: &EngineBenchArgs) -> Result<()> {
    if args.iterations == 0 {
        return Err(Error::input("--iterations must be at least 1"));
    }
    let max_sources = args.sources.iter().copied().max().unwrap_or(2);
    if args.sources.iter().any(|&n| n < 1) || max_sources > args.db.source_count {
        return Err(Error::input(format!(
            "--sources must lie between 1 and the database's {} sources",
            args.db.source_count
        )));
    }
    let (db, db_ms) = args.db.load()?;
    let total = db.sources.len();
    let motion = db
        .motion_index("talk")
        .or(Some(0).filter(|_| !db.motions.is_empty()));
    let (blender, factor_ms) = time(|| Blender::new(&db.model));
    blender?;
    let (engine, setup_ms) = time(|| Engine::new(db));
    let engine = engine?;
    let frames = engine
        .database()
        .motions
        .get(motion.unwrap_or(0))
        .map_or(1, |m| m.frames());
    let mut rows: Vec<Value> = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(6_4);
    let iterations = args.warmup + args.iterations;
    let post_on = PostProcess {
        smoothing: Smoothing::Crossfade,
        colour: ColourCorrection::Skin,
        membership: Membership::Place,
        deform: Deform::Similarity,
    };
    for &n in &args.sources {
        // A composite drawing on all n sources: random shape weights and assignment.
        let mut base_recipe = recipe(total, post_on, AnimationMode::Fast, motion);
        for g in 0..Group::COUNT {
            base_recipe.shape[g] = stick_breaking(&mut rng, n, total);
            base_recipe.gaussians[g] = rng.random_range(0..n);
        }
        let mut composite = engine.compose(&base_recipe);
        let mut posed = PosedMesh::default();
        let mut exact = PosedMesh::default();

        // Animate, both modes, plus the vertex error of fast against exact.
        for mode in [AnimationMode::Fast, AnimationMode::Exact] {
            composite.recipe.mode = mode;
            let mut ms = Vec::new();
            let mut residual = 0.0f64;
            for it in 0..iterations {
                let frame = it % frames;
                let ((), t) = time(|| engine.pose(&composite, frame, &mut posed));
                residual = residual.max(posed.residual);
                if it >= args.warmup {
                    ms.push(t);
                }
            }
            let (median, p90) = summarize(ms);
            let mut row = json!({"action": "animate", "mode": mode_name(mode), "sources": n, "ms_median": median, "ms_p90": p90, "frames": iterations});
            if mode == AnimationMode::Fast {
                let (max_err, mean_err) =
                    fast_vs_exact(&engine, &mut composite, frames, &mut posed, &mut exact);
                row["max_vertex_error_m"] = json!(max_err);
                row["mean_vertex_error_m"] = json!(mean_err);
            } else {
                row["max_residual"] = json!(residual);
            }
            rows.push(row);
        }
        composite.recipe.mode = AnimationMode::Fast;

        // Shape: new random weights in every group, re-blend, pose the current frame.
        let mut ms = Vec::new();
        let mut residual = 0.0f64;
        for it in 0..iterations {
            let mut next = composite.recipe.clone();
            for g in 0..Group::COUNT {
                next.shape[g] = stick_breaking(&mut rng, n, total);
            }
            let ((), t) = time(|| {
                engine.update(&mut composite, &next);
                engine.pose(&composite, it % frames, &mut posed);
            });
            residual = residual.max(composite.residual);
            if it >= args.warmup {
                ms.push(t);
            }
        }
        let (median, p90) = summarize(ms);
        rows.push(json!({"action": "shape", "sources": n, "ms_median": median, "ms_p90": p90, "max_residual": residual}));

        // Assignment: a new random source for the Gaussians of every group.
        let posts = [
            (PostProcess::default(), "off"),
            (post_on, "crossfade+skin"),
            (PostProcess::BEST, "best"),
        ];
        for (post, label) in posts {
            let mut ms = Vec::new();
            let mut count = 0;
            composite = engine.compose(&ResolvedRecipe {
                post,
                ..composite.recipe.clone()
            });
            for it in 0..iterations {
                let mut next = composite.recipe.clone();
                for g in 0..Group::COUNT {
                    next.gaussians[g] = rng.random_range(0..n);
                }
                let ((), t) = time(|| {
                    engine.update(&mut composite, &next);
                });
                count = composite.gaussians.len();
                if it >= args.warmup {
                    ms.push(t);
                }
            }
            let (median, p90) = summarize(ms);
            rows.push(json!({
                "action": "assign", "sources": n, "ms_median": median, "ms_p90": p90,
                "post": label,
                "gaussians": count, "error": 0.0,
            }));
        }
    }
    // The factorisation and a bare solve, with its residual: every group blends
    // all sources equally (a one-hot recipe would take the exact-source short cut).
    let mut solve_recipe = engine
        .compose(&recipe(
            total,
            PostProcess::default(),
            AnimationMode::Fast,
            motion,
        ))
        .recipe;
    for row in solve_recipe.shape.iter_mut() {
        row.iter_mut().for_each(|w| *w = 1.0 / total as f64);
    }
    let mut ms = Vec::new();
    let mut residual = 0.0f64;
    for it in 0..iterations {
        let ((_, r), t) = time(|| engine.blend_neutral(&solve_recipe));
        residual = residual.max(r);
        if it >= args.warmup {
            ms.push(t);
        }
    }
    let (median, p90) = summarize(ms);
    rows.push(json!({"action": "solve", "sources": total, "ms_median": median, "ms_p90": p90, "max_residual": residual}));
    rows.push(json!({"action": "factor", "sources": total, "ms_median": factor_ms, "ms_p90": factor_ms, "vertices": engine.database().model.vertex_count()}));
    let doc = json!({
        "bench": "engine",
        "threads": rayon::current_num_threads(),
        "database_ms": db_ms.as_secs_f64() * 1e3,
        "engine_setup_ms": setup_ms,
        "warmup": args.warmup,
        "iterations": args.iterations,
        "rows": rows,
    });
    if args.json {
        println!("{doc}");
    } else {
        print_table(&doc);
    }
    Ok(())
}

fn mode_name(mode: AnimationMode) -> &'static str {
    match mode {
        AnimationMode::Fast => "fast",
        AnimationMode::Exact => "exact",
    }
}

/// Max and mean vertex distance (metres) between fast and exact animation over
/// every frame of the motion.
fn fast_vs_exact(
    engine: &Engine,
    composite: &mut crate::compose::engine::Composite,
    frames: usize,
    fast: &mut PosedMesh,
    exact: &mut PosedMesh,
) -> (f64, f64) {
    let (mut max, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for frame in 0..frames {
        let (e, p) = engine.frame_parameters(&composite.recipe, frame);
        engine.pose_with(composite, &e, &p, AnimationMode::Fast, fast);
        engine.pose_with(composite, &e, &p, AnimationMode::Exact, exact);
        for (a, b) in fast.vertices.iter().zip(&exact.vertices) {
            let d = (*a - *b).length() as f64;
            max = max.max(d);
            sum += d;
            count += 1;
        }
    }
    (max, sum / count.max(1) as f64)
}

fn print_table(doc: &Value) {
    println!(
        "engine bench: {} timed iterations after {} warm-up, {} threads (database {:.0} ms, engine set-up {:.0} ms)",
        doc["iterations"], doc["warmup"], doc["threads"],
        doc["database_ms"].as_f64().unwrap_or(0.0),
        doc["engine_setup_ms"].as_f64().unwrap_or(0.0)
    );
    println!(
        "{:<8} {:<15} {:>7} {:>10} {:>10}  error",
        "action", "mode/post", "sources", "median ms", "p90 ms"
    );
    for r in doc["rows"].as_array().into_iter().flatten() {
        let variant = r["mode"].as_str().or(r["post"].as_str()).unwrap_or("");
        let error = if let Some(e) = r["max_vertex_error_m"].as_f64() {
            format!(
                "fast vs exact: max {:.2e} m, mean {:.2e} m",
                e,
                r["mean_vertex_error_m"].as_f64().unwrap_or(0.0)
            )
        } else if let Some(e) = r["max_residual"].as_f64() {
            format!("residual {e:.1e}")
        } else if let Some(g) = r["gaussians"].as_u64() {
            format!("exact ({g} Gaussians)")
        } else {
            String::new()
        };
        println!(
            "{:<8} {:<15} {:>7} {:>10.3} {:>10.3}  {}",
            r["action"].as_str().unwrap_or(""),
            variant,
            r["sources"],
            r["ms_median"].as_f64().unwrap_or(0.0),
            r["ms_p90"].as_f64().unwrap_or(0.0),
            error
        );
    }
}
