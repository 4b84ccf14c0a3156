//! `visage bench`: speed beside error, one subcommand per part of the tool.
//! Each benchmark builds a typed report (`#[derive(Serialize)]`), printed as
//! one JSON document with `--json` or as tables by its own text printer;
//! what they share (statistics, the timing loop, skipped renderers) is in
//! [`stats`].

mod composites;
mod engine;
mod holes;
mod mouth;
mod paged;
mod render;
mod render_report;
mod scene;
mod stats;
mod terminal;
mod train;

use clap::{Args, Subcommand};

use crate::error::Result;

/// Arguments of `visage bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Subcommand, Debug, Clone)]
enum BenchWhat {
    /// Animate / change shape / change assignment, per number of sources.
    Engine(engine::EngineBenchArgs),
    /// Frame time per resolution and stage, and speed against error per knob.
    Render(render::RenderBenchArgs),
    /// Encode time, bytes and end-to-end FPS per terminal graphics protocol.
    Terminal(terminal::TerminalBenchArgs),
    /// Training speed, held-out PSNR against time, gradient error.
    Train(train::TrainBenchArgs),
    /// Hole filling: leak, coverage and PSNR of plain, obscuring, culling, both.
    Holes(holes::HolesBenchArgs),
    /// Composites against their ground truth: a fixed set of recipes over
    /// trained (cached) sources, every composite metric per recipe.
    Composites(composites::CompositesBenchArgs),
    /// The mouth cavity: one capture trained on the built-in head with its
    /// pocket, with the pocket removed (FLAME-like) and with the generated
    /// cavity; open- and closed-mouth PSNR over views and the mouth's box.
    Mouth(mouth::MouthBenchArgs),
}

/// Runs `visage bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    match &args.what {
        BenchWhat::Engine(a) => engine::run(a),
        BenchWhat::Render(a) => render::run(a),
        BenchWhat::Terminal(a) => terminal::run(a),
        BenchWhat::Train(a) => train::run(a),
        BenchWhat::Holes(a) => holes::run(a),
        BenchWhat::Composites(a) => composites::run(a),
        BenchWhat::Mouth(a) => mouth::run(a),
    }
}
