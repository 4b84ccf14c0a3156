//! `visage bench render --ply FILE --memory-budget SIZE`: a scene drawn from
//! its level-of-detail cache within a memory budget, as `view` draws a
//! scene larger than memory: the cache found or built (time, size), the
//! first image's time from the start, then a camera orbiting a few degrees
//! a frame at each size (frame times while chunks arrive and are dropped),
//! and the process's peak memory. No PSNR: the reference would need the
//! whole scene in memory.

use std::path::Path;
use std::time::Instant;

use serde::Serialize;

use super::stats::{ms_since, open_or_skip, peak_rss_mb, summarize, Skipped};
use crate::error::{Error, Result};
use crate::pipeline::lod::{open_cached, CacheOrigin, LodScene};
use crate::render::lod::LodPolicy;
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::{Orbit, UpAxis};

/// Degrees the camera turns per frame while moving.
const DEGREES_PER_FRAME: f32 = 3.0;

/// Runs the paged benchmark and returns its report.
pub fn bench_paged(
    path: &Path,
    sizes: &[(u32, u32)],
    renderers: &[Backend],
    frames: usize,
    lod: LodPolicy,
    budget: usize,
) -> Result<PagedReport> {
    let start = Instant::now();
    let note = |line: &str| eprintln!("visage: {line}");
    let (tree, origin, cache) = open_cached(path, None, budget, &note, &|_, _| {})?;
    let open_ms = ms_since(start);
    let header = tree.header().clone();
    let (lo, hi) = header.source.bounds;
    let up = header.source.ground_up.unwrap_or(UpAxis::default());
    let home = Orbit {
        fov_deg: 40.0,
        up,
        ..Orbit::STUDY
    }
    .framing(lo, hi);
    let policy = if lod == LodPolicy::Off {
        return Err(Error::input(
            "--memory-budget draws from the level-of-detail cache: --lod off draws every Gaussian, which needs the whole scene in memory",
        ));
    } else {
        lod
    };
    let mut hierarchy = LodScene::paged(tree);
    let mut reports = Vec::new();
    let mut skipped = Vec::new();
    let mut first_image_ms = None;
    for &backend in renderers {
        let opened = SplatRenderer::open(backend);
        let Some(mut renderer) = open_or_skip(opened, backend, renderers.len(), &mut skipped)?
        else {
            continue;
        };
        let mut rows = Vec::new();
        for &(w, h) in sizes {
            let camera = home.camera(w, h);
            hierarchy.forget();
            hierarchy.render(&mut renderer, &camera, policy, &RenderSettings::default())?;
            first_image_ms.get_or_insert(ms_since(start));
            let first = hierarchy.summary();
            let (mut times, mut read) = (Vec::new(), first.chunks_read);
            for frame in 0..frames {
                let orbit = Orbit {
                    yaw_deg: home.yaw_deg + DEGREES_PER_FRAME * (frame + 1) as f32,
                    ..home
                };
                let camera = orbit.camera(w, h);
                let t = Instant::now();
                hierarchy.render(&mut renderer, &camera, policy, &RenderSettings::default())?;
                times.push(ms_since(t));
                read += hierarchy.summary().chunks_read;
            }
            let last = hierarchy.summary();
            let (median, p90) = summarize(times);
            rows.push(PagedRow {
                width: w,
                height: h,
                moving_ms_median: median,
                moving_ms_p90: p90,
                moving_fps: 1e3 / median,
                first_drawn: first.drawn,
                drawn: last.drawn,
                levels: [last.levels.0, last.levels.1],
                chunks_read: read,
                resident_mb: mib(last.resident_bytes as f64),
            });
        }
        reports.push(PagedRenderer {
            renderer: backend,
            device: renderer.description(),
            rows,
        });
    }
    let cache_built = match origin {
        CacheOrigin::Found => None,
        CacheOrigin::Built {
            why,
            seconds,
            bytes,
        } => Some(CacheBuilt {
            why,
            seconds,
            bytes,
        }),
    };
    Ok(PagedReport {
        bench: "render-paged",
        scene: path.display().to_string(),
        gaussians: header.source.gaussians,
        nodes: header.nodes,
        cache: cache.display().to_string(),
        cache_bytes: header.file_len(),
        cache_built,
        memory_budget_mb: mib(budget as f64),
        open_ms,
        first_image_ms,
        lod: policy.label(),
        frames,
        degrees_per_frame: DEGREES_PER_FRAME,
        peak_rss_mb: peak_rss_mb(),
        renderers: reports,
        skipped,
    })
}

fn mib(bytes: f64) -> f64 {
    bytes / (1 << 20) as f64
}

/// The paged benchmark's report.
#[derive(Serialize)]
pub struct PagedReport {
    bench: &'static str,
    scene: String,
    gaussians: u64,
    nodes: u64,
    cache: String,
    cache_bytes: u64,
    /// How the cache was built, when this run built it.
    cache_built: Option<CacheBuilt>,
    memory_budget_mb: f64,
    open_ms: f64,
    first_image_ms: Option<f64>,
    lod: String,
    frames: usize,
    degrees_per_frame: f32,
    peak_rss_mb: Option<f64>,
    renderers: Vec<PagedRenderer>,
    skipped: Vec<Skipped>,
}

/// A cache this run built: why, in how long, how big.
#[derive(Serialize)]
struct CacheBuilt {
    why: String,
    seconds: f64,
    bytes: u64,
}

/// One renderer's rows.
#[derive(Serialize)]
struct PagedRenderer {
    renderer: Backend,
    device: String,
    rows: Vec<PagedRow>,
}

/// One size: the moving camera's frame times and what the cut held.
#[derive(Serialize)]
struct PagedRow {
    width: u32,
    height: u32,
    moving_ms_median: f64,
    moving_ms_p90: f64,
    moving_fps: f64,
    first_drawn: usize,
    drawn: usize,
    levels: [u16; 2],
    chunks_read: usize,
    resident_mb: f64,
}

/// Prints the paged benchmark's tables.
pub fn print_paged(r: &PagedReport) {
    println!(
        "paged render bench: {} Gaussians ({}) in {} nodes, cache {} ({:.0} MB)",
        r.gaussians,
        r.scene,
        r.nodes,
        r.cache,
        r.cache_bytes as f64 / 1e6
    );
    if let Some(built) = &r.cache_built {
        println!("cache built in {:.1} s ({})", built.seconds, built.why);
    }
    println!(
        "memory budget {:.0} MiB; opened in {:.0} ms; first image {:.0} ms after the start; peak memory {:.0} MiB",
        r.memory_budget_mb,
        r.open_ms,
        r.first_image_ms.unwrap_or(0.0),
        r.peak_rss_mb.unwrap_or(0.0)
    );
    for renderer in &r.renderers {
        println!(
            "\n{} (camera turning {}° a frame, {} frames, level of detail {}):",
            renderer.device, r.degrees_per_frame, r.frames, r.lod
        );
        println!(
            "{:>10} {:>9} {:>9} {:>7} {:>9} {:>9} {:>7} {:>7} {:>9}",
            "size",
            "median ms",
            "p90 ms",
            "FPS",
            "1st drawn",
            "drawn",
            "levels",
            "chunks",
            "held MiB"
        );
        for row in &renderer.rows {
            println!(
                "{:>10} {:>9.2} {:>9.2} {:>7.1} {:>9} {:>9} {:>7} {:>7} {:>9.0}",
                format!("{}x{}", row.width, row.height),
                row.moving_ms_median,
                row.moving_ms_p90,
                row.moving_fps,
                row.first_drawn,
                row.drawn,
                format!("{}-{}", row.levels[0], row.levels[1]),
                row.chunks_read,
                row.resident_mb,
            );
        }
    }
}
