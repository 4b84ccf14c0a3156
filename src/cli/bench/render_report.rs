//! The report of `visage bench render` on composites and scenes alike: per
//! renderer, a row per image size (frame time, stages, PSNR against the f64
//! reference, and on scenes the level-of-detail columns) and the knob table;
//! with its text printer.

use serde::Serialize;

use super::stats::{print_skipped, Skipped};
use crate::render::settings::StageTimings;
use crate::render::Backend;

/// The whole render bench.
#[derive(Serialize)]
pub struct RenderReport {
    /// Always "render".
    pub bench: &'static str,
    /// Gaussians drawn.
    pub gaussians: usize,
    /// Milliseconds to load the composite or scene.
    pub load_ms: f64,
    /// What only scenes have.
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub scene: Option<SceneFacts>,
    /// The process's peak memory at the end, MiB.
    pub peak_rss_mb: Option<f64>,
    /// One entry per renderer measured.
    pub renderers: Vec<RendererReport>,
    /// Renderers that could not be opened.
    pub skipped: Vec<Skipped>,
}

/// A scene's name, its level-of-detail hierarchy and its memory after loading.
#[derive(Serialize)]
pub struct SceneFacts {
    /// The file or "synthetic N".
    pub scene: String,
    /// The level-of-detail policy's label.
    pub lod: String,
    /// Milliseconds the hierarchy took to build (none when off).
    pub lod_build_ms: Option<f64>,
    /// Nodes of the hierarchy (none when off).
    pub lod_nodes: Option<usize>,
    /// Peak memory right after loading, MiB.
    pub load_peak_rss_mb: Option<f64>,
}

/// One renderer's figures.
#[derive(Serialize)]
pub struct RendererReport {
    /// The renderer asked for.
    pub renderer: Backend,
    /// The adapter or CPU it ran on.
    pub device: String,
    /// Milliseconds to open it.
    pub setup_ms: f64,
    /// Milliseconds to upload the Gaussians.
    pub gaussian_upload_ms: f64,
    /// One row per image size.
    pub rows: Vec<SizeRow>,
    /// The speed-against-error table.
    pub knobs: Vec<KnobRow>,
}

/// One image size.
#[derive(Serialize)]
pub struct SizeRow {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// The frame's figures, or why the device could not draw this size.
    #[serde(flatten)]
    pub outcome: SizeOutcome,
    /// The level-of-detail columns (scenes with a hierarchy).
    #[serde(flatten, skip_serializing_if = "Option::is_none")]
    pub lod: Option<LodColumns>,
}

/// A size drawn, or refused by the device.
#[derive(Serialize)]
#[serde(untagged)]
pub enum SizeOutcome {
    /// Drawn and timed.
    Drawn(FrameFigures),
    /// Not drawn.
    Refused {
        /// The device's error.
        error: String,
    },
}

/// Frame time and accuracy at one size.
#[derive(Clone, Copy, Serialize)]
pub struct FrameFigures {
    /// Median frame time.
    pub ms_median: f64,
    /// 90th percentile frame time.
    pub ms_p90: f64,
    /// Frames a second at the median.
    pub fps: f64,
    /// PSNR against the f64 reference.
    pub psnr_db: f64,
    /// Median stage times of the profiled pass.
    pub stages_ms: StageTimings,
    /// Milliseconds the reference took.
    pub reference_ms: f64,
}

/// What a level-of-detail cut drew: a count, or the scene as it is.
#[derive(Clone, Copy, Serialize)]
#[serde(untagged)]
pub enum Drawn {
    /// Nodes drawn.
    Nodes(usize),
    /// Every Gaussian: the policy drew the scene exactly ("exact").
    Exact(&'static str),
}

/// A row's level-of-detail columns: a moving camera's frame (cut, gather,
/// upload and render every frame), the cut's PSNR against the full scene's
/// reference, and what it drew.
#[derive(Clone, Copy, Serialize)]
pub struct LodColumns {
    /// Median frame time.
    pub lod_ms_median: f64,
    /// 90th percentile frame time.
    pub lod_ms_p90: f64,
    /// Frames a second at the median.
    pub lod_fps: f64,
    /// PSNR of the cut against the full scene's reference.
    pub lod_psnr_db: f64,
    /// Nodes drawn.
    pub lod_drawn: Drawn,
    /// Of them, leaves (original Gaussians).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lod_leaves: Option<usize>,
    /// The coarsest and finest level drawn (none when drawn exactly).
    pub lod_levels: Option<[u16; 2]>,
    /// Milliseconds the cut took on the CPU.
    pub lod_cut_ms: f64,
    /// The GPU chose the cut within its frame (then `lod_drawn` counts
    /// what reached the screen, and no levels are known).
    pub lod_cut_on_gpu: bool,
}

impl LodColumns {
    /// The columns of a row the policy draws exactly: the exact path's own figures.
    pub fn exact(frame: &FrameFigures) -> Self {
        Self {
            lod_ms_median: frame.ms_median,
            lod_ms_p90: frame.ms_p90,
            lod_fps: frame.fps,
            lod_psnr_db: frame.psnr_db,
            lod_drawn: Drawn::Exact("exact"),
            lod_leaves: None,
            lod_levels: None,
            lod_cut_ms: 0.0,
            lod_cut_on_gpu: false,
        }
    }
}

/// One knob setting at one size.
#[derive(Serialize)]
pub struct KnobRow {
    /// The knob's name.
    pub knob: &'static str,
    /// Its value.
    pub value: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Median frame time.
    pub ms_median: f64,
    /// 90th percentile frame time.
    pub ms_p90: f64,
    /// PSNR against the exact reference.
    pub psnr_db: f64,
}

/// Prints the render bench's tables.
pub fn print_tables(report: &RenderReport) {
    let scene = report.scene.as_ref();
    println!(
        "render bench: {} Gaussians{}; loaded in {:.0} ms{}, peak memory {}",
        report.gaussians,
        scene.map(|s| format!(" ({})", s.scene)).unwrap_or_default(),
        report.load_ms,
        scene
            .and_then(|s| s.load_peak_rss_mb)
            .map(|m| format!(" (peak {m:.0} MiB after loading)"))
            .unwrap_or_default(),
        report
            .peak_rss_mb
            .map_or("unknown".to_string(), |m| format!("{m:.0} MiB"))
    );
    if let Some(s) = scene {
        if let (Some(ms), Some(nodes)) = (s.lod_build_ms, s.lod_nodes) {
            println!(
                "level of detail ({}): {nodes} nodes built in {ms:.0} ms",
                s.lod
            );
        }
    }
    for r in &report.renderers {
        print_renderer(r);
        print_lod_rows(&r.rows);
    }
    print_skipped(&report.skipped);
}

fn size_label(width: u32, height: u32) -> String {
    format!("{width}x{height}")
}

fn print_renderer(r: &RendererReport) {
    println!(
        "\n{}: set-up {:.0} ms, Gaussian upload {:.1} ms",
        r.device, r.setup_ms, r.gaussian_upload_ms
    );
    println!(
        "{:>10} {:>9} {:>9} {:>7} {:>9}  stages (upload/project/sort/raster/readback ms)",
        "size", "median ms", "p90 ms", "FPS", "PSNR dB"
    );
    for row in &r.rows {
        let size = size_label(row.width, row.height);
        let f = match &row.outcome {
            SizeOutcome::Refused { error } => {
                println!("{size:>10} not drawn: {error}");
                continue;
            }
            SizeOutcome::Drawn(f) => f,
        };
        let s = &f.stages_ms;
        println!(
            "{size:>10} {:>9.2} {:>9.2} {:>7.1} {:>9.1}  {:.2}/{:.2}/{:.2}/{:.2}/{:.2}",
            f.ms_median,
            f.ms_p90,
            f.fps,
            f.psnr_db,
            s.upload,
            s.project,
            s.sort,
            s.rasterize,
            s.readback,
        );
    }
    let Some(first) = r.knobs.first() else {
        return;
    };
    println!("speed against error at {}x{}:", first.width, first.height);
    println!(
        "{:<17} {:>7} {:>9} {:>9}",
        "knob", "value", "median ms", "PSNR dB"
    );
    for k in &r.knobs {
        println!(
            "{:<17} {:>7} {:>9.2} {:>9.1}",
            k.knob, k.value, k.ms_median, k.psnr_db
        );
    }
}

/// The rows' level-of-detail columns, when measured.
fn print_lod_rows(rows: &[SizeRow]) {
    let rows: Vec<(&SizeRow, &LodColumns)> = rows
        .iter()
        .filter_map(|r| r.lod.as_ref().map(|l| (r, l)))
        .collect();
    if rows.is_empty() {
        return;
    }
    println!(
        "with level of detail:\n{:>10} {:>9} {:>7} {:>9} {:>9} {:>7} {:>7}",
        "size", "median ms", "FPS", "PSNR dB", "drawn", "levels", "cut ms"
    );
    for (r, l) in rows {
        println!(
            "{:>10} {:>9.2} {:>7.1} {:>9.1} {:>9} {:>7} {:>7.2}",
            size_label(r.width, r.height),
            l.lod_ms_median,
            l.lod_fps,
            l.lod_psnr_db,
            match l.lod_drawn {
                Drawn::Nodes(n) => n.to_string(),
                Drawn::Exact(label) => label.to_string(),
            },
            match (l.lod_levels, l.lod_cut_on_gpu) {
                (_, true) => "on GPU".into(),
                (Some([a, b]), _) => format!("{a}-{b}"),
                (None, _) => "all".to_string(),
            },
            l.lod_cut_ms,
        );
    }
}
