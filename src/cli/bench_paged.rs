//! `visage bench render --ply FILE --memory-budget SIZE`: a scene drawn from
//! its level-of-detail cache within a memory budget, as `view` draws a
//! scene larger than memory: the cache found or built (time, size), the
//! first image's time from the start, then a camera orbiting a few degrees
//! a frame at each size (frame times while chunks arrive and are dropped),
//! and the process's peak memory. No PSNR: the reference would need the
//! whole scene in memory.

use std::path::Path;
use std::time::Instant;

use serde_json::{json, Value};

use super::bench::{open_or_skip, summarize};
use super::bench_scene::peak_rss_mb;
use crate::error::{Error, Result};
use crate::pipeline::lod::{open_cached, CacheOrigin, LodScene};
use crate::render::lod::LodPolicy;
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::{Orbit, UpAxis};

/// Degrees the camera turns per frame while moving.
const DEGREES_PER_FRAME: f32 = 3.0;

/// Runs the paged benchmark and returns its JSON document.
pub fn bench_paged(
    path: &Path,
    sizes: &[(u32, u32)],
    renderers: &[Backend],
    frames: usize,
    lod: LodPolicy,
    budget: usize,
) -> Result<Value> {
    let start = Instant::now();
    let note = |line: &str| eprintln!("visage: {line}");
    let (tree, origin, cache) = open_cached(path, None, budget, &note, &|_, _| {})?;
    let open_ms = start.elapsed().as_secs_f64() * 1e3;
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
    let mut docs = Vec::new();
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
            first_image_ms.get_or_insert(start.elapsed().as_secs_f64() * 1e3);
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
                times.push(t.elapsed().as_secs_f64() * 1e3);
                read += hierarchy.summary().chunks_read;
            }
            let last = hierarchy.summary();
            let (median, p90) = summarize(times);
            rows.push(json!({
                "width": w, "height": h, "moving_ms_median": median, "moving_ms_p90": p90,
                "moving_fps": 1e3 / median, "first_drawn": first.drawn, "drawn": last.drawn,
                "levels": [last.levels.0, last.levels.1], "chunks_read": read,
                "resident_mb": last.resident_bytes as f64 / (1 << 20) as f64,
            }));
        }
        docs.push(json!({ "renderer": backend, "device": renderer.description(), "rows": rows }));
    }
    let built = match origin {
        CacheOrigin::Found => Value::Null,
        CacheOrigin::Built {
            why,
            seconds,
            bytes,
        } => json!({ "why": why, "seconds": seconds, "bytes": bytes }),
    };
    Ok(json!({
        "bench": "render-paged",
        "scene": path.display().to_string(),
        "gaussians": header.source.gaussians,
        "nodes": header.nodes,
        "cache": cache.display().to_string(),
        "cache_bytes": header.file_len(),
        "cache_built": built,
        "memory_budget_mb": budget as f64 / (1 << 20) as f64,
        "open_ms": open_ms,
        "first_image_ms": first_image_ms,
        "lod": policy.label(),
        "frames": frames,
        "degrees_per_frame": DEGREES_PER_FRAME,
        "peak_rss_mb": peak_rss_mb(),
        "renderers": docs,
        "skipped": skipped,
    }))
}

/// Prints the paged benchmark's tables.
pub fn print_paged(doc: &Value) {
    println!(
        "paged render bench: {} Gaussians ({}) in {} nodes, cache {} ({:.0} MB)",
        doc["gaussians"],
        doc["scene"].as_str().unwrap_or(""),
        doc["nodes"],
        doc["cache"].as_str().unwrap_or(""),
        doc["cache_bytes"].as_f64().unwrap_or(0.0) / 1e6
    );
    if let Some(seconds) = doc["cache_built"]["seconds"].as_f64() {
        println!(
            "cache built in {seconds:.1} s ({})",
            doc["cache_built"]["why"].as_str().unwrap_or("")
        );
    }
    println!(
        "memory budget {:.0} MiB; opened in {:.0} ms; first image {:.0} ms after the start; peak memory {:.0} MiB",
        doc["memory_budget_mb"].as_f64().unwrap_or(0.0),
        doc["open_ms"].as_f64().unwrap_or(0.0),
        doc["first_image_ms"].as_f64().unwrap_or(0.0),
        doc["peak_rss_mb"].as_f64().unwrap_or(0.0)
    );
    for r in doc["renderers"].as_array().into_iter().flatten() {
        println!(
            "\n{} (camera turning {}° a frame, {} frames, level of detail {}):",
            r["device"].as_str().unwrap_or(""),
            doc["degrees_per_frame"],
            doc["frames"],
            doc["lod"].as_str().unwrap_or("")
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
        for row in r["rows"].as_array().into_iter().flatten() {
            println!(
                "{:>10} {:>9.2} {:>9.2} {:>7.1} {:>9} {:>9} {:>7} {:>7} {:>9.0}",
                format!("{}x{}", row["width"], row["height"]),
                row["moving_ms_median"].as_f64().unwrap_or(0.0),
                row["moving_ms_p90"].as_f64().unwrap_or(0.0),
                row["moving_fps"].as_f64().unwrap_or(0.0),
                row["first_drawn"],
                row["drawn"],
                format!("{}-{}", row["levels"][0], row["levels"][1]),
                row["chunks_read"],
                row["resident_mb"].as_f64().unwrap_or(0.0),
            );
        }
    }
}
