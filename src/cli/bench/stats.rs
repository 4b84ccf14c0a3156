//! What every benchmark shares: medians and percentiles, the one timing loop
//! over a renderer's frames (plain, then profiled per stage), the process's
//! peak memory, and renderers skipped on a machine without a device.

use std::time::Instant;

use serde::Serialize;

use crate::error::{Error, Result};
use crate::pipeline::composer::Painter;
use crate::render::settings::StageTimings;
use crate::render::{Backend, SplatRenderer};

/// Median and 90th percentile of a sample (frame times in milliseconds).
pub fn summarize(mut ms: Vec<f64>) -> (f64, f64) {
    ms.sort_by(f64::total_cmp);
    let at = |q: f64| ms[((ms.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.9))
}

/// The median of each stage over profiled frames (zeros when there are none).
pub fn median_stages(stages: &[StageTimings]) -> StageTimings {
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

/// Runs `f` and returns its result with the milliseconds it took.
pub fn timed<T>(f: impl FnOnce() -> T) -> (T, f64) {
    let t = Instant::now();
    let out = f();
    (out, t.elapsed().as_secs_f64() * 1e3)
}

/// Milliseconds since `t`.
pub fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The process's peak resident memory in MiB (Linux), when known.
pub fn peak_rss_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// Warm-up and timed frames of one case.
#[derive(Clone, Copy, Debug)]
pub struct Rounds {
    /// Frames drawn first and not counted.
    pub warmup: usize,
    /// Frames timed.
    pub timed: usize,
}

/// What the timing loop drives: a renderer whose stages can be profiled.
pub trait Profiled {
    /// Makes the renderer wait after each stage (on) so stages can be timed.
    fn set_stage_profiling(&mut self, on: bool);
    /// The last frame's stage times.
    fn stage_timings(&mut self) -> StageTimings;
}

impl Profiled for SplatRenderer {
    fn set_stage_profiling(&mut self, on: bool) {
        SplatRenderer::set_stage_profiling(self, on);
    }
    fn stage_timings(&mut self) -> StageTimings {
        self.timings()
    }
}

impl Profiled for Painter {
    fn set_stage_profiling(&mut self, on: bool) {
        self.renderer_mut().set_stage_profiling(on);
    }
    fn stage_timings(&mut self) -> StageTimings {
        self.renderer_mut().timings()
    }
}

/// Times `rounds` of `frame(renderer, index)`; returns the frame times as
/// the editor sees them and, with `stages_too`, the stage medians of a
/// second pass over the same frames with the renderer waiting after each
/// stage (which slows the frame, so the two passes are kept apart).
pub fn time_frames<R: Profiled>(
    renderer: &mut R,
    rounds: Rounds,
    stages_too: bool,
    mut frame: impl FnMut(&mut R, usize) -> Result<()>,
) -> Result<(Vec<f64>, StageTimings)> {
    let mut totals = Vec::new();
    let mut stages = Vec::new();
    for profiled in [false, true] {
        if profiled && !stages_too {
            break;
        }
        renderer.set_stage_profiling(profiled);
        for it in 0..rounds.warmup + rounds.timed {
            let t = Instant::now();
            frame(renderer, it)?;
            let ms = ms_since(t);
            if it < rounds.warmup {
                continue;
            }
            if profiled {
                stages.push(renderer.stage_timings());
            } else {
                totals.push(ms);
            }
        }
    }
    renderer.set_stage_profiling(false);
    Ok((totals, median_stages(&stages)))
}

/// A renderer a benchmark could not open, and why.
#[derive(Clone, Debug, Serialize)]
pub struct Skipped {
    /// The renderer asked for.
    pub renderer: Backend,
    /// The device error.
    pub reason: String,
}

/// A renderer opened for a benchmark, or — when the graphics device is
/// missing and other renderers were asked for too — `None`, with the reason
/// added to `skipped` (a machine without a GPU still measures its CPU).
pub fn open_or_skip<T>(
    opened: Result<T>,
    backend: Backend,
    asked: usize,
    skipped: &mut Vec<Skipped>,
) -> Result<Option<T>> {
    match opened {
        Ok(t) => Ok(Some(t)),
        Err(e @ Error::Device(_)) if asked > 1 => {
            eprintln!("visage: skipping the {} renderer: {e}", backend.name());
            skipped.push(Skipped {
                renderer: backend,
                reason: e.to_string(),
            });
            Ok(None)
        }
        Err(e) => Err(e),
    }
}

/// A renderer opened and given its Gaussians for a benchmark, with the
/// milliseconds each took.
pub struct Opened<T> {
    /// The renderer.
    pub renderer: T,
    /// Milliseconds to open it.
    pub setup_ms: f64,
    /// Milliseconds to upload the Gaussians.
    pub upload_ms: f64,
}

/// Opens `backend` with `open` and loads it with `upload`, timing both; a
/// missing device is skipped as [`open_or_skip`] says.
pub fn open_and_upload<T>(
    backend: Backend,
    asked: usize,
    skipped: &mut Vec<Skipped>,
    open: impl FnOnce(Backend) -> Result<T>,
    upload: impl FnOnce(&mut T) -> Result<()>,
) -> Result<Option<Opened<T>>> {
    let t = Instant::now();
    let Some(mut renderer) = open_or_skip(open(backend), backend, asked, skipped)? else {
        return Ok(None);
    };
    let setup_ms = ms_since(t);
    let t = Instant::now();
    upload(&mut renderer)?;
    Ok(Some(Opened {
        renderer,
        setup_ms,
        upload_ms: ms_since(t),
    }))
}

/// Prints the renderers a benchmark skipped, and why.
pub fn print_skipped(skipped: &[Skipped]) {
    for s in skipped {
        println!("\n{} renderer skipped: {}", s.renderer.name(), s.reason);
    }
}

/// Prints a report as one JSON document, or with its text printer.
pub fn emit<T: Serialize>(report: &T, json: bool, print: impl FnOnce(&T)) {
    if json {
        println!(
            "{}",
            serde_json::to_string(report).expect("reports serialise")
        );
    } else {
        print(report);
    }
}
