//! `visage bench terminal`: per protocol and terminal size, encode time and bytes
//! per frame, end-to-end frames per second (render + encode) while animating with
//! the editor's adaptive resolution (with the PSNR that costs), and edit latency.

use std::time::Instant;

use clap::Args;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use ratatui::backend::CrosstermBackend;
use ratatui::layout::Rect;
use ratatui::{Terminal, TerminalOptions, Viewport};
use serde::Serialize;

use super::render::bench_recipe_for;
use super::stats::{emit, summarize};
use crate::cli::values::parse_size;
use crate::cli::DbArgs;
use crate::compose::engine::Engine;
use crate::editor::pacing::next_scale;
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::pipeline::workbench::DebugView;
use crate::pipeline::workbench::{FrameRequest, Workbench};
use crate::render::image::{psnr_report, RgbImage};
use crate::render::Backend;
use crate::tui::graphics::{
    draw_halfblocks, encode_iterm2, encode_kitty, encode_sixel, KittyTransport, Protocol,
};
use crate::tui::terminal::Collector;
use crate::tui::view::{layout, Screen};

/// Arguments of `visage bench terminal`.
#[derive(Args, Debug, Clone)]
pub struct TerminalBenchArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Terminal sizes in cells, comma-separated COLSxROWS.
    #[arg(long, value_delimiter = ',', default_values = ["80x24", "120x40", "200x60"], value_parser = parse_size)]
    terminals: Vec<(u32, u32)>,
    /// Cell size in pixels for the image protocols.
    #[arg(long, default_value = "8x16", value_parser = parse_size)]
    cell_px: (u32, u32),
    /// Animated frames per end-to-end run.
    #[arg(long, default_value_t = 60)]
    frames: usize,
    /// Renderer.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

const PROTOCOLS: [Protocol; 4] = [
    Protocol::Halfblocks,
    Protocol::Kitty,
    Protocol::Sixel,
    Protocol::Iterm2,
];

/// Encodes a frame the way the editor does; returns the bytes written to the terminal.
fn encode_frame(
    protocol: Protocol,
    image: &RgbImage,
    cells: (u16, u16),
    full: (u32, u32),
    halfblocks: &mut (Terminal<CrosstermBackend<Collector>>, Collector),
) -> Result<Vec<u8>> {
    Ok(match protocol {
        Protocol::Halfblocks => {
            halfblocks.1.take();
            halfblocks
                .0
                .draw(|f| {
                    let area = f.area();
                    draw_halfblocks(f.buffer_mut(), area, image)
                })
                .map_err(|e| Error::terminal(e.to_string()))?;
            halfblocks.1.take()
        }
        Protocol::Kitty => encode_kitty(image, cells, KittyTransport::Zlib)
            .map_err(|e| Error::terminal(e.to_string()))?,
        Protocol::Iterm2 => encode_iterm2(image, cells).map_err(Error::terminal)?,
        Protocol::Sixel => {
            if (image.width, image.height) != full {
                encode_sixel(&image.resized(full.0, full.1)).map_err(Error::terminal)?
            } else {
                encode_sixel(image).map_err(Error::terminal)?
            }
        }
    })
}

/// Runs `visage bench terminal`.
pub fn run(args: &TerminalBenchArgs) -> Result<()> {
    if args.frames < 2 {
        return Err(Error::input("--frames must be at least 2"));
    }
    let (db, _) = args.db.load()?;
    let engine = Engine::new(db)?;
    let recipe = bench_recipe_for(engine.database());
    let sources: Vec<String> = engine
        .database()
        .sources
        .iter()
        .map(|s| s.name.clone())
        .collect();
    let mut workbench = Workbench::new(engine, args.renderer)?;
    let device = workbench.renderer_description();
    let mut rows = Vec::new();
    let mut latency = Vec::new();
    for &(cols, lines) in &args.terminals {
        let Some(areas) = layout(
            Rect::new(0, 0, cols as u16, lines as u16),
            Screen::default(),
        ) else {
            return Err(Error::input(format!(
                "{cols}x{lines} is smaller than the editor's minimum layout"
            )));
        };
        let v = areas.viewport;
        let cells = (v.width, v.height);
        let options = TerminalOptions {
            viewport: Viewport::Fixed(Rect::new(0, 0, v.width, v.height)),
        };
        let collector = Collector::default();
        let terminal = Terminal::with_options(CrosstermBackend::new(collector.clone()), options)
            .map_err(|e| Error::terminal(e.to_string()))?;
        let mut halfblocks = (terminal, collector);
        for protocol in PROTOCOLS {
            let full = match protocol {
                Protocol::Halfblocks => (v.width as u32, 2 * v.height as u32),
                _ => (
                    v.width as u32 * args.cell_px.0,
                    v.height as u32 * args.cell_px.1,
                ),
            };
            let request = |frame: usize, w: u32, h: u32, exact: bool| {
                let mut r = recipe.clone();
                r.animation.frame = frame;
                FrameRequest {
                    recipe: r,
                    debug: DebugView::default(),
                    group: Group::Nose,
                    width: w,
                    height: h,
                    exact,
                }
            };
            // Encoding alone, on two alternating frames (so half-block diffs rewrite the view).
            let frames = [
                workbench.render(&request(10, full.0, full.1, false))?.image,
                workbench.render(&request(40, full.0, full.1, false))?.image,
            ];
            let (mut enc, mut bytes) = (Vec::new(), Vec::new());
            for k in 0..10 {
                let t = Instant::now();
                let out = encode_frame(protocol, &frames[k % 2], cells, full, &mut halfblocks)?;
                enc.push(t.elapsed().as_secs_f64() * 1e3);
                bytes.push(out.len());
            }
            let (enc_median, _) = summarize(enc);
            // End to end while animating, with the editor's resolution control.
            let mut scale = 1.0f64;
            let (mut totals, mut scales) = (Vec::new(), Vec::new());
            let mut last = None;
            for k in 0..args.frames {
                let (w, h) = (
                    ((full.0 as f64 * scale) as u32).max(8),
                    ((full.1 as f64 * scale) as u32).max(8),
                );
                let t = Instant::now();
                let frame = workbench.render(&request(k, w, h, false))?;
                encode_frame(protocol, &frame.image, cells, full, &mut halfblocks)?;
                let spent = t.elapsed().as_secs_f64() * 1e3;
                totals.push(spent);
                scales.push(scale);
                scale = next_scale(scale, spent);
                last = Some((k, frame.image));
            }
            let (k, image) = last.expect("frames ≥ 2");
            let exact = workbench.render(&request(k, full.0, full.1, true))?.image;
            let shown = if (image.width, image.height) != full {
                image.resized(full.0, full.1)
            } else {
                image
            };
            let psnr_db = psnr_report(&shown, &exact).unwrap_or(0.0);
            let steady = &totals[totals.len() / 2..];
            let (median, p90) = summarize(steady.to_vec());
            let mean_scale = scales[scales.len() / 2..].iter().sum::<f64>()
                / (scales.len() - scales.len() / 2) as f64;
            rows.push(ProtocolRow {
                terminal: format!("{cols}x{lines}"),
                protocol: protocol.name(),
                viewport_cells: [v.width, v.height],
                full_pixels: [full.0, full.1],
                encode_ms_median: enc_median,
                bytes_per_frame: bytes.iter().sum::<usize>() / bytes.len(),
                e2e_ms_median: median,
                e2e_ms_p90: p90,
                fps: 1e3 / median,
                mean_scale,
                psnr_db,
            });
            // Edit latency at 120x40: a random assignment change until the encoded frame.
            if (cols, lines) == (120, 40)
                && matches!(protocol, Protocol::Halfblocks | Protocol::Kitty)
            {
                let mut rng = ChaCha8Rng::seed_from_u64(50);
                let mut ms = Vec::new();
                for _ in 0..20 {
                    let mut r = recipe.clone();
                    let g = Group::ALL[rng.random_range(0..Group::COUNT)];
                    let s = &sources[rng.random_range(0..sources.len())];
                    let mut edit = r.groups.get(g.name()).cloned().unwrap_or(
                        crate::compose::recipe::GroupEdit {
                            gaussians: s.clone(),
                            shape: [(r.base.clone(), 1.0)].into(),
                        },
                    );
                    edit.gaussians = s.clone();
                    r.groups.insert(g.name().into(), edit);
                    let (w, h) = (
                        ((full.0 as f64 * scale) as u32).max(8),
                        ((full.1 as f64 * scale) as u32).max(8),
                    );
                    let req = FrameRequest {
                        recipe: r,
                        debug: DebugView::default(),
                        group: g,
                        width: w,
                        height: h,
                        exact: false,
                    };
                    let t = Instant::now();
                    let frame = workbench.render(&req)?;
                    encode_frame(protocol, &frame.image, cells, full, &mut halfblocks)?;
                    ms.push(t.elapsed().as_secs_f64() * 1e3);
                }
                let (median, p90) = summarize(ms);
                latency.push(EditLatency {
                    terminal: "120x40",
                    protocol: protocol.name(),
                    edit_ms_median: median,
                    edit_ms_p90: p90,
                });
            }
        }
    }
    let report = TerminalReport {
        bench: "terminal",
        device,
        cell_px: [args.cell_px.0, args.cell_px.1],
        rows,
        edit_latency: latency,
    };
    emit(&report, args.json, print_table);
    Ok(())
}

/// The terminal bench's report.
#[derive(Serialize)]
struct TerminalReport {
    bench: &'static str,
    device: String,
    cell_px: [u32; 2],
    rows: Vec<ProtocolRow>,
    edit_latency: Vec<EditLatency>,
}

/// One protocol at one terminal size.
#[derive(Serialize)]
struct ProtocolRow {
    terminal: String,
    protocol: &'static str,
    viewport_cells: [u16; 2],
    full_pixels: [u32; 2],
    encode_ms_median: f64,
    bytes_per_frame: usize,
    e2e_ms_median: f64,
    e2e_ms_p90: f64,
    fps: f64,
    mean_scale: f64,
    psnr_db: f64,
}

/// Edit latency: an assignment change until the encoded frame.
#[derive(Serialize)]
struct EditLatency {
    terminal: &'static str,
    protocol: &'static str,
    edit_ms_median: f64,
    edit_ms_p90: f64,
}

fn print_table(report: &TerminalReport) {
    println!(
        "terminal bench on {} (cells of {}x{} px for image protocols)",
        report.device, report.cell_px[0], report.cell_px[1]
    );
    println!(
        "{:>8} {:<10} {:>10} {:>9} {:>10} {:>7} {:>6} {:>6}",
        "terminal", "protocol", "pixels", "enc ms", "bytes", "FPS", "scale", "PSNR"
    );
    for r in &report.rows {
        println!(
            "{:>8} {:<10} {:>10} {:>9.2} {:>10} {:>7.1} {:>6.2} {:>6.1}",
            r.terminal,
            r.protocol,
            format!("{}x{}", r.full_pixels[0], r.full_pixels[1]),
            r.encode_ms_median,
            r.bytes_per_frame,
            r.fps,
            r.mean_scale,
            r.psnr_db
        );
    }
    for l in &report.edit_latency {
        println!(
            "edit latency at {} with {}: median {:.1} ms, p90 {:.1} ms",
            l.terminal, l.protocol, l.edit_ms_median, l.edit_ms_p90
        );
    }
}
