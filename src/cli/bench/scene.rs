//! `visage bench render --ply FILE` / `--synthetic-scale N`: a world-space 3DGS
//! scene instead of a composite — load time, peak memory, and per size the
//! frame time, stage times and PSNR against the f64 reference, per renderer.

use std::time::Instant;

use super::render_report::{
    Drawn, FrameFigures, KnobRow, LodColumns, RenderReport, RendererReport, SceneFacts,
    SizeOutcome, SizeRow,
};
use super::stats::{ms_since, open_and_upload, peak_rss_mb, summarize, time_frames, Rounds};
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

/// Times `rounds` frames of the uploaded scene; returns the frame times and
/// the median stage times of a second, profiled pass.
fn time_scene(
    renderer: &mut SplatRenderer,
    camera: &Camera,
    settings: &RenderSettings,
    rounds: Rounds,
) -> Result<(Vec<f64>, StageTimings)> {
    time_frames(renderer, rounds, true, |renderer, _| {
        renderer.render_world(camera, settings).map(drop)
    })
}

/// One row's level-of-detail columns: the cut's PSNR against the full
/// scene's reference, what it drew, and the frame time of a moving camera
/// (cut, gather, upload and render every frame). The renderer holds `full`
/// again afterwards, so the next size's exact row draws every Gaussian.
fn lod_columns(
    renderer: &mut SplatRenderer,
    full: &SplatScene,
    hierarchy: &mut LodScene,
    camera: &Camera,
    reference: &RgbImage,
    lod: LodPolicy,
    rounds: Rounds,
) -> Result<LodColumns> {
    let settings = RenderSettings::default();
    hierarchy.forget();
    let image = hierarchy.render(renderer, camera, lod, &settings)?;
    let summary = hierarchy.summary();
    let mut totals = Vec::new();
    for it in 0..rounds.warmup + rounds.timed {
        hierarchy.forget();
        let t = Instant::now();
        hierarchy.render(renderer, camera, lod, &settings)?;
        if it >= rounds.warmup {
            totals.push(ms_since(t));
        }
    }
    let (median, p90) = summarize(totals);
    renderer.set_world_scene(full)?;
    hierarchy.forget();
    Ok(LodColumns {
        lod_ms_median: median,
        lod_ms_p90: p90,
        lod_fps: 1e3 / median,
        lod_psnr_db: psnr_report(&image, reference).unwrap_or(0.0),
        lod_drawn: Drawn::Nodes(summary.drawn),
        lod_leaves: Some(summary.leaves),
        lod_levels: (!summary.on_gpu).then_some([summary.levels.0, summary.levels.1]),
        lod_cut_ms: summary.cut_ms,
        lod_cut_on_gpu: summary.on_gpu,
    })
}

/// A cut the device could not draw is a gap in its row, not the end of the
/// run (as an exact size it refuses is): the renderer gets the full scene
/// back for the next size.
fn cut_or_gap(
    columns: Result<LodColumns>,
    renderer: &mut SplatRenderer,
    full: &SplatScene,
    hierarchy: &mut LodScene,
) -> Result<Option<LodColumns>> {
    match columns {
        Ok(columns) => Ok(Some(columns)),
        Err(Error::Device(_)) => {
            hierarchy.forget();
            match renderer.set_world_scene(full) {
                Ok(()) | Err(Error::Device(_)) => Ok(None),
                Err(e) => Err(e),
            }
        }
        Err(e) => Err(e),
    }
}

/// The early-stop thresholds compared on scenes (the knob that trades
/// accuracy for speed on every renderer without resampling the image).
const EARLY_STOPS: [f32; 4] = [1e-4, 1e-3, 1e-2, 3e-2];

/// Runs the scene benchmark and returns its report; with `knob_size`, the
/// early-stop thresholds are compared at that size; with a `lod` other than
/// off, each row also measures the level-of-detail cut against the full
/// scene's reference.
pub fn bench_scene(
    source: SceneSource,
    sizes: &[(u32, u32)],
    renderers: &[Backend],
    rounds: Rounds,
    knob_size: Option<(u32, u32)>,
    lod: LodPolicy,
) -> Result<RenderReport> {
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
    let load_ms = ms_since(t);
    let load_peak = peak_rss_mb();
    let orbit = scene
        .home_orbit(None, UpAxis::default())
        .ok_or_else(|| Error::input(format!("{name} holds no Gaussians")))?;
    let mut references = Vec::new();
    for &(w, h) in sizes {
        let camera = orbit.camera(w, h);
        let t = Instant::now();
        let image = render_reference(&scene, &camera, &RenderSettings::default());
        references.push((camera, image, ms_since(t)));
    }
    let t = Instant::now();
    let mut hierarchy = (lod != LodPolicy::Off).then(|| LodScene::new(build(&scene)));
    let lod_build_ms = ms_since(t);
    let mut reports = Vec::new();
    let mut skipped = Vec::new();
    for &backend in renderers {
        let asked = renderers.len();
        let upload = |renderer: &mut SplatRenderer| renderer.set_world_scene(&scene);
        let open = SplatRenderer::open;
        let Some(opened) = open_and_upload(backend, asked, &mut skipped, open, upload)? else {
            continue;
        };
        let mut renderer = opened.renderer;
        let mut rows = Vec::new();
        for (camera, reference, reference_ms) in &references {
            let mut row = SizeRow {
                width: camera.width,
                height: camera.height,
                outcome: size_outcome(&mut renderer, camera, reference, *reference_ms, rounds)?,
                lod: None,
            };
            // A cut is measured even where the exact path could not draw
            // (a scene past the GPU's sort limit is what the cut is for).
            if let Some(hierarchy) = hierarchy.as_mut() {
                let pixels = (camera.width * camera.height) as usize;
                row.lod = match (lod.resolve(scene.len(), pixels), &row.outcome) {
                    (LodPolicy::Off, SizeOutcome::Drawn(frame)) => Some(LodColumns::exact(frame)),
                    (LodPolicy::Off, SizeOutcome::Refused { .. }) => None,
                    (policy, _) => {
                        let columns = lod_columns(
                            &mut renderer,
                            &scene,
                            hierarchy,
                            camera,
                            reference,
                            policy,
                            rounds,
                        );
                        cut_or_gap(columns, &mut renderer, &scene, hierarchy)?
                    }
                };
            }
            rows.push(row);
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
        reports.push(RendererReport {
            renderer: backend,
            device: renderer.description(),
            setup_ms: opened.setup_ms,
            gaussian_upload_ms: opened.upload_ms,
            rows,
            knobs,
        });
    }
    Ok(RenderReport {
        bench: "render",
        gaussians: scene.len(),
        load_ms,
        scene: Some(SceneFacts {
            scene: name,
            lod: lod.label(),
            lod_build_ms: hierarchy.is_some().then_some(lod_build_ms),
            lod_nodes: hierarchy.as_ref().map(LodScene::nodes),
            load_peak_rss_mb: load_peak,
        }),
        peak_rss_mb: peak_rss_mb(),
        renderers: reports,
        skipped,
    })
}

/// One size drawn exactly: PSNR against the reference and frame times. A
/// device that cannot draw a size is a row of the report, not the end of
/// the run (the other sizes and renderers still count).
fn size_outcome(
    renderer: &mut SplatRenderer,
    camera: &Camera,
    reference: &RgbImage,
    reference_ms: f64,
    rounds: Rounds,
) -> Result<SizeOutcome> {
    let image = match renderer.render_world(camera, &RenderSettings::default()) {
        Ok(image) => image,
        Err(e @ Error::Device(_)) => {
            return Ok(SizeOutcome::Refused {
                error: e.to_string(),
            })
        }
        Err(e) => return Err(e),
    };
    let psnr_db = psnr_report(&image, reference).unwrap_or(0.0);
    let (totals, stages_ms) = time_scene(renderer, camera, &RenderSettings::default(), rounds)?;
    let (ms_median, ms_p90) = summarize(totals);
    Ok(SizeOutcome::Drawn(FrameFigures {
        ms_median,
        ms_p90,
        fps: 1e3 / ms_median,
        psnr_db,
        stages_ms,
        reference_ms,
    }))
}

/// Frame time and PSNR against the exact reference for each early-stop
/// threshold at one camera (the rows' reference images are reused).
fn early_stop_knobs(
    renderer: &mut SplatRenderer,
    camera: &Camera,
    scene: &SplatScene,
    references: &[(Camera, RgbImage, f64)],
    rounds: Rounds,
) -> Result<Vec<KnobRow>> {
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
        let (ms_median, ms_p90) = summarize(totals);
        knobs.push(KnobRow {
            knob: "early_stop",
            value: format!("{early_stop:e}"),
            width: camera.width,
            height: camera.height,
            ms_median,
            ms_p90,
            psnr_db,
        });
    }
    Ok(knobs)
}
