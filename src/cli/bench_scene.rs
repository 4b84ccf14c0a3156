//! `visage bench render --ply FILE` / `--synthetic-scale N`: a world-space 3DGS
//! scene instead of a composite — load time, peak memory, and per size the
//! frame time, stage times and PSNR against the f64 reference, per renderer.

use std::time::Instant;

use serde_json::{json, Value};

use super::bench::{median_stages, open_or_skip, summarize};
use crate::error::{Error, Result};
use crate::pipeline::lod::LodScene;
use crate::render::image::{psnr_report, RgbImage};
use crate::render::lod::{build, LodPolicy};
use crate::render::reference::render_reference;
use crate::render::settings::{RenderSettings, StageTimings};
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::{Camera, UpAxis};
use crate::scene::splats::SplatScene;

/// Sizes measured on scenes unless `--sizes` is given.
pub const SCENE_SIZES: [(u32, u32); 4] = [(120, 80), (200, 120), (320, 240), (640, 480)];

/// Where the scene comes from.
pub enum SceneSource<'a> {
    /// A file (.ply, .compressed.ply, .splat or .spz).
    File(&'a std::path::Path),
    /// [`crate::scene::synthetic::synthetic_scene`] of this many Gaussians.
    Synthetic(usize),
}

/// The process's peak resident memory in MiB (Linux), when known.
pub fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Times `warmup + iterations` frames of the uploaded scene; returns the frame
/// times and the median stage times of a second, profiled pass.
fn time_scene(
    renderer: &mut SplatRenderer,
    camera: &Camera,
    settings: &RenderSettings,
    (warmup, iterations): (usize, usize),
) -> Result<(Vec<f64>, StageTimings)> {
    let (mut totals, mut stages) = (Vec::new(), Vec::new());
    for profiled in [false, true] {
        renderer.set_stage_profiling(profiled);
        for it in 0..warmup + iterations {
            let t = Instant::now();
            renderer.render_world(camera, settings)?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            if it < warmup {
                continue;
            }
            if profiled {
                stages.push(renderer.timings());
            } else {
                totals.push(ms);
            }
        }
    }
    renderer.set_stage_profiling(false);
    Ok((totals, median_stages(&stages)))
}

/// One row's level-of-detail columns: the cut's PSNR against the full
/// scene's reference, what it drew, and the frame time of a moving camera
/// (cut, gather, upload and render every frame).
fn lod_row(
    renderer: &mut SplatRenderer,
    hierarchy: &mut LodScene,
    camera: &Camera,
    reference: &RgbImage,
    lod: LodPolicy,
    (warmup, iterations): (usize, usize),
) -> Result<serde_json::Map<String, Value>> {
    let settings = RenderSettings::default();
    hierarchy.forget();
    let image = hierarchy.render(renderer, camera, lod, &settings)?;
    let summary = hierarchy.summary();
    let mut totals = Vec::new();
    for it in 0..warmup + iterations {
        hierarchy.forget();
        let t = Instant::now();
        hierarchy.render(renderer, camera, lod, &settings)?;
        if it >= warmup {
            totals.push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    let (median, p90) = summarize(totals);
    let row = json!({
        "lod_ms_median": median, "lod_ms_p90": p90, "lod_fps": 1e3 / median,
        "lod_psnr_db": psnr_report(&image, reference).unwrap_or(0.0),
        "lod_drawn": summary.drawn, "lod_leaves": summary.leaves,
        "lod_levels": [summary.levels.0, summary.levels.1], "lod_cut_ms": summary.cut_ms,
    });
    Ok(row.as_object().cloned().unwrap_or_default())
}

/// The level-of-detail columns of a row where the policy draws the scene
/// as it is: the exact path's own figures.
fn exact_as_lod_row(row: &Value) -> serde_json::Map<String, Value> {
    let row = json!({
        "lod_ms_median": row["ms_median"], "lod_ms_p90": row["ms_p90"], "lod_fps": row["fps"],
        "lod_psnr_db": row["psnr_db"], "lod_drawn": "exact", "lod_levels": Value::Null,
        "lod_cut_ms": 0.0,
    });
    row.as_object().cloned().unwrap_or_default()
}

/// The early-stop thresholds compared on scenes (the knob that trades
/// accuracy for speed on every renderer without resampling the image).
const EARLY_STOPS: [f32; 4] = [1e-4, 1e-3, 1e-2, 3e-2];

/// Runs the scene benchmark and returns its JSON document; with `knob_size`,
/// the early-stop thresholds are compared at that size; with a `lod` other
/// than off, each row also measures the level-of-detail cut against the
/// full scene's reference.
pub fn bench_scene(
    source: SceneSource,
    sizes: &[(u32, u32)],
    renderers: &[Backend],
    rounds: (usize, usize),
    knob_size: Option<(u32, u32)>,
    lod: LodPolicy,
) -> Result<Value> {
    let t = Instant::now();
    let (scene, name): (SplatScene, String) = match source {
        SceneSource::File(path) => (
            crate::io::splat::read_scene(path)?,
            path.display().to_string(),
        ),
        SceneSource::Synthetic(n) => (
            crate::scene::synthetic::synthetic_scene(n, 1),
            format!("synthetic {n}"),
        ),
    };
    let load_ms = t.elapsed().as_secs_f64() * 1e3;
    let load_peak = peak_rss_mb();
    let orbit = scene
        .home_orbit(None, UpAxis::default())
        .ok_or_else(|| Error::input(format!("{name} holds no Gaussians")))?;
    let mut references = Vec::new();
    for &(w, h) in sizes {
        let camera = orbit.camera(w, h);
        let t = Instant::now();
        let image = render_reference(&scene, &camera, &RenderSettings::default());
        references.push((camera, image, t.elapsed().as_secs_f64() * 1e3));
    }
    let t = Instant::now();
    let mut hierarchy = (lod != LodPolicy::Off).then(|| LodScene::new(build(&scene)));
    let lod_build_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut docs = Vec::new();
    let mut skipped = Vec::new();
    for &backend in renderers {
        let t = Instant::now();
        let opened = SplatRenderer::open(backend);
        let Some(mut renderer) = open_or_skip(opened, backend, renderers.len(), &mut skipped)?
        else {
            continue;
        };
        let setup_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        renderer.set_world_scene(&scene)?;
        let upload_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut rows = Vec::new();
        for (camera, reference, reference_ms) in &references {
            // A device that cannot draw a size is a row of the report, not
            // the end of the run (the other sizes and renderers still count).
            let image = match renderer.render_world(camera, &RenderSettings::default()) {
                Ok(image) => image,
                Err(e @ Error::Device(_)) => {
                    rows.push(json!({
                        "width": camera.width, "height": camera.height, "error": e.to_string(),
                    }));
                    continue;
                }
                Err(e) => return Err(e),
            };
            let psnr_db = psnr_report(&image, reference).unwrap_or(0.0);
            let (totals, stages) =
                time_scene(&mut renderer, camera, &RenderSettings::default(), rounds)?;
            let (median, p90) = summarize(totals);
            rows.push(json!({
                "width": camera.width, "height": camera.height, "ms_median": median, "ms_p90": p90,
                "fps": 1e3 / median, "psnr_db": psnr_db, "stages_ms": stages, "reference_ms": reference_ms,
            }));
        }
        let knobs = match knob_size {
            Some(size) => match early_stop_knobs(
                &mut renderer,
                &orbit.camera(size.0, size.1),
                &scene,
                &references,
                rounds,
            ) {
                Ok(knobs) => knobs,
                Err(Error::Device(_)) => Vec::new(),
                Err(e) => return Err(e),
            },
            None => Vec::new(),
        };
        if let Some(hierarchy) = hierarchy.as_mut() {
            for (row, (camera, reference, _)) in rows.iter_mut().zip(&references) {
                if row.get("error").is_some() {
                    continue;
                }
                let pixels = (camera.width * camera.height) as usize;
                let measured = match lod.resolve(scene.len(), pixels) {
                    LodPolicy::Off => exact_as_lod_row(row),
                    policy => lod_row(&mut renderer, hierarchy, camera, reference, policy, rounds)?,
                };
                row.as_object_mut().unwrap().extend(measured);
            }
        }
        docs.push(json!({
            "renderer": backend,
            "device": renderer.description(),
            "setup_ms": setup_ms,
            "gaussian_upload_ms": upload_ms,
            "rows": rows,
            "knobs": knobs,
        }));
    }
    Ok(json!({
        "bench": "render",
        "scene": name,
        "gaussians": scene.len(),
        "load_ms": load_ms,
        "lod": lod.label(),
        "lod_build_ms": hierarchy.is_some().then_some(lod_build_ms),
        "lod_nodes": hierarchy.as_ref().map(LodScene::nodes),
        "load_peak_rss_mb": load_peak,
        "peak_rss_mb": peak_rss_mb(),
        "renderers": docs,
        "skipped": skipped,
    }))
}

/// Frame time and PSNR against the exact reference for each early-stop
/// threshold at one camera (the rows' reference images are reused).
fn early_stop_knobs(
    renderer: &mut SplatRenderer,
    camera: &Camera,
    scene: &SplatScene,
    references: &[(Camera, RgbImage, f64)],
    rounds: (usize, usize),
) -> Result<Vec<Value>> {
    // The size's reference when a row already drew it.
    let size = (camera.width, camera.height);
    let reference = match references
        .iter()
        .find(|(c, _, _)| (c.width, c.height) == size)
    {
        Some((_, image, _)) => image.clone(),
        None => render_reference(scene, camera, &RenderSettings::default()),
    };
    let mut knobs = Vec::new();
    for early_stop in EARLY_STOPS {
        let settings = RenderSettings {
            early_stop,
            ..RenderSettings::default()
        };
        let image = renderer.render_world(camera, &settings)?;
        let psnr_db = psnr_report(&image, &reference).unwrap_or(0.0);
        let (totals, _) = time_scene(renderer, camera, &settings, rounds)?;
        let (median, p90) = summarize(totals);
        knobs.push(json!({
            "knob": "early_stop", "value": format!("{early_stop:e}"),
            "width": camera.width, "height": camera.height,
            "ms_median": median, "ms_p90": p90, "psnr_db": psnr_db,
        }));
    }
    Ok(knobs)
}
