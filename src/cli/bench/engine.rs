//! `visage bench engine`: the thesis benchmark (6.4) of the composition
//! engine, with the error each measured path trades against.

use clap::Args;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::stats::{emit, summarize, timed};
use crate::cli::DbArgs;
use crate::compose::blend::Blender;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{
    Anchor, AnimationMode, ColourCorrection, Deform, Fit, Membership, PostProcess, ResolvedRecipe,
    Shading, SkinSource, Smoothing,
};
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::scene::camera::Orbit;

/// Arguments of `visage bench engine`.
#[derive(Args, Debug, Clone)]
pub struct EngineBenchArgs {
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

/// Runs `visage bench engine`.
pub fn run(args: &EngineBenchArgs) -> Result<()> {
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
    let (blender, factor_ms) = timed(|| Blender::new(&db.model));
    blender?;
    let (engine, setup_ms) = timed(|| Engine::new(db));
    let engine = engine?;
    let frames = engine
        .database()
        .motions
        .get(motion.unwrap_or(0))
        .map_or(1, |m| m.frames());
    let mut rows: Vec<EngineRow> = Vec::new();
    let mut rng = ChaCha8Rng::seed_from_u64(6_4);
    let iterations = args.warmup + args.iterations;
    let post_on = PostProcess {
        smoothing: Smoothing::Crossfade,
        colour: ColourCorrection::Skin,
        membership: Membership::Place,
        deform: Deform::Similarity,
        anchor: Anchor::Parent,
        shading: Shading::Kept,
        skin: SkinSource::Source,
        fit: Fit::Off,
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
                let ((), t) = timed(|| engine.pose(&composite, frame, &mut posed));
                residual = residual.max(posed.residual);
                if it >= args.warmup {
                    ms.push(t);
                }
            }
            let (median, p90) = summarize(ms);
            let error = if mode == AnimationMode::Fast {
                let (max, mean) =
                    fast_vs_exact(&engine, &composite, frames, &mut posed, &mut exact);
                EngineError::FastVsExact {
                    max_vertex_error_m: max,
                    mean_vertex_error_m: mean,
                }
            } else {
                EngineError::Residual {
                    max_residual: residual,
                }
            };
            rows.push(EngineRow {
                mode: Some(mode_name(mode)),
                frames: Some(iterations),
                ..EngineRow::new(Action::Animate, n, (median, p90), error)
            });
        }
        composite.recipe.mode = AnimationMode::Fast;

        // Shape: new random weights in every group, re-blend, pose the current frame.
        rows.push(EngineRow {
            post: Some("crossfade+skin"),
            ..time_shape_edits(
                &engine,
                &mut composite,
                &mut rng,
                &mut posed,
                (n, frames),
                args,
            )
        });

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
                let ((), t) = timed(|| {
                    engine.update(&mut composite, &next);
                });
                count = composite.gaussians.len();
                if it >= args.warmup {
                    ms.push(t);
                }
            }
            let (median, p90) = summarize(ms);
            rows.push(EngineRow {
                post: Some(label),
                ..EngineRow::new(
                    Action::Assign,
                    n,
                    (median, p90),
                    EngineError::Exact {
                        gaussians: count,
                        error: 0.0,
                    },
                )
            });
        }
        // Shape again under our post-processing, where the Gaussians that
        // follow the shape (relit, the base's skin, reshaped) are rebuilt,
        // drawing on its own generator so that every other row's random
        // draws, at every number of sources, stay as they were.
        let mut shape_rng = ChaCha8Rng::seed_from_u64(6_4 + n as u64);
        rows.push(EngineRow {
            post: Some("best"),
            ..time_shape_edits(
                &engine,
                &mut composite,
                &mut shape_rng,
                &mut posed,
                (n, frames),
                args,
            )
        });
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
        let ((_, r), t) = timed(|| engine.blend_neutral(&solve_recipe));
        residual = residual.max(r);
        if it >= args.warmup {
            ms.push(t);
        }
    }
    let (median, p90) = summarize(ms);
    rows.push(EngineRow::new(
        Action::Solve,
        total,
        (median, p90),
        EngineError::Residual {
            max_residual: residual,
        },
    ));
    rows.push(EngineRow::new(
        Action::Factor,
        total,
        (factor_ms, factor_ms),
        EngineError::Factor {
            vertices: engine.database().model.vertex_count(),
        },
    ));
    let report = EngineReport {
        bench: "engine",
        threads: rayon::current_num_threads(),
        database_ms: db_ms.as_secs_f64() * 1e3,
        engine_setup_ms: setup_ms,
        warmup: args.warmup,
        iterations: args.iterations,
        rows,
    };
    emit(&report, args.json, print_table);
    Ok(())
}

/// Times shape edits of `composite`, drawing on `n` sources (`args`'
/// warm-up and timed iterations): new random weights in every group,
/// re-blended and posed at the current one of `frames`.
fn time_shape_edits(
    engine: &Engine,
    composite: &mut Composite,
    rng: &mut ChaCha8Rng,
    posed: &mut PosedMesh,
    (n, frames): (usize, usize),
    args: &EngineBenchArgs,
) -> EngineRow {
    let total = engine.database().sources.len();
    let mut ms = Vec::new();
    let mut residual = 0.0f64;
    for it in 0..args.warmup + args.iterations {
        let mut next = composite.recipe.clone();
        for g in 0..Group::COUNT {
            next.shape[g] = stick_breaking(rng, n, total);
        }
        let ((), t) = timed(|| {
            engine.update(composite, &next);
            engine.pose(composite, it % frames, posed);
        });
        residual = residual.max(composite.residual);
        if it >= args.warmup {
            ms.push(t);
        }
    }
    EngineRow::new(
        Action::Shape,
        n,
        summarize(ms),
        EngineError::Residual {
            max_residual: residual,
        },
    )
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
    composite: &crate::compose::engine::Composite,
    frames: usize,
    fast: &mut PosedMesh,
    exact: &mut PosedMesh,
) -> (f64, f64) {
    let (mut max, mut sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for frame in 0..frames {
        let (e, p) = engine.frame_parameters(&composite.recipe, frame);
        let o = engine.frame_offset(&composite.recipe, frame);
        engine.pose_offset_with(composite, &e, &p, o, AnimationMode::Fast, fast);
        engine.pose_offset_with(composite, &e, &p, o, AnimationMode::Exact, exact);
        for (a, b) in fast.vertices.iter().zip(&exact.vertices) {
            let d = (*a - *b).length() as f64;
            max = max.max(d);
            sum += d;
            count += 1;
        }
    }
    (max, sum / count.max(1) as f64)
}

fn print_table(report: &EngineReport) {
    println!(
        "engine bench: {} timed iterations after {} warm-up, {} threads (database {:.0} ms, engine set-up {:.0} ms)",
        report.iterations, report.warmup, report.threads, report.database_ms, report.engine_setup_ms
    );
    println!(
        "{:<8} {:<15} {:>7} {:>10} {:>10}  error",
        "action", "mode/post", "sources", "median ms", "p90 ms"
    );
    for r in &report.rows {
        let error = match r.error {
            EngineError::FastVsExact {
                max_vertex_error_m,
                mean_vertex_error_m,
            } => format!(
                "fast vs exact: max {max_vertex_error_m:.2e} m, mean {mean_vertex_error_m:.2e} m"
            ),
            EngineError::Residual { max_residual } => format!("residual {max_residual:.1e}"),
            EngineError::Exact { gaussians, .. } => format!("exact ({gaussians} Gaussians)"),
            EngineError::Factor { .. } => String::new(),
        };
        println!(
            "{:<8} {:<15} {:>7} {:>10.3} {:>10.3}  {}",
            r.action.name(),
            r.mode.or(r.post).unwrap_or(""),
            r.sources,
            r.ms_median,
            r.ms_p90,
            error
        );
    }
}

/// The engine bench's report.
#[derive(Serialize)]
struct EngineReport {
    bench: &'static str,
    threads: usize,
    database_ms: f64,
    engine_setup_ms: f64,
    warmup: usize,
    iterations: usize,
    rows: Vec<EngineRow>,
}

/// What a row measures.
#[derive(Clone, Copy, Serialize)]
#[serde(rename_all = "snake_case")]
enum Action {
    /// Posing a frame.
    Animate,
    /// New shape weights, re-blended and posed.
    Shape,
    /// A new source for every group's Gaussians.
    Assign,
    /// One Laplacian solve.
    Solve,
    /// The Laplacian's factorisation.
    Factor,
}

impl Action {
    fn name(self) -> &'static str {
        match self {
            Action::Animate => "animate",
            Action::Shape => "shape",
            Action::Assign => "assign",
            Action::Solve => "solve",
            Action::Factor => "factor",
        }
    }
}

/// The error a measured path trades against.
#[derive(Clone, Copy, Serialize)]
#[serde(untagged)]
enum EngineError {
    /// Fast animation's vertex distance from exact animation, metres.
    FastVsExact {
        max_vertex_error_m: f64,
        mean_vertex_error_m: f64,
    },
    /// The largest solver residual.
    Residual { max_residual: f64 },
    /// An exact path: the composite's size.
    Exact { gaussians: usize, error: f64 },
    /// The factorisation: the model's size.
    Factor { vertices: usize },
}

/// One row: an action at a number of sources, its times and its error.
#[derive(Serialize)]
struct EngineRow {
    action: Action,
    #[serde(skip_serializing_if = "Option::is_none")]
    mode: Option<&'static str>,
    #[serde(skip_serializing_if = "Option::is_none")]
    post: Option<&'static str>,
    sources: usize,
    ms_median: f64,
    ms_p90: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    frames: Option<usize>,
    #[serde(flatten)]
    error: EngineError,
}

impl EngineRow {
    fn new(
        action: Action,
        sources: usize,
        (ms_median, ms_p90): (f64, f64),
        error: EngineError,
    ) -> Self {
        Self {
            action,
            mode: None,
            post: None,
            sources,
            ms_median,
            ms_p90,
            frames: None,
            error,
        }
    }
}
