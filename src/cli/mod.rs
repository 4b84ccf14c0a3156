//! The `visage` command line: argument parsing, dispatch and the exit-code
//! contract (0 ok, 1 a check failed, 2 bad input, always one line on stderr).

mod bench;
mod bench_holes;
mod bench_render;
mod bench_scene;
mod bench_terminal;
mod bench_train;
mod camera;
mod capture;
mod compose;
mod convert;
mod db;
mod edit;
mod info;
mod random;
mod render;
mod study;
mod train;

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub use db::DbArgs;

use crate::error::Result;

/// Compose photo-realistic, animatable Gaussian head avatars in the terminal.
#[derive(Parser, Debug)]
#[command(name = "visage", version, about, long_about = None, args_conflicts_with_subcommands = true)]
pub struct Cli {
    #[command(subcommand)]
    command: Option<Command>,
    /// Without a command: open the editor.
    #[command(flatten)]
    edit: edit::EditArgs,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Open the editor (the default command).
    Edit(edit::EditArgs),
    /// View a 3DGS scene file (PLY, compressed PLY, .splat, SPZ) in the terminal.
    View(edit::ViewArgs),
    /// Replay a session file headless, with snapshots and checks.
    Replay(edit::ReplayArgs),
    /// Describe the database: model, regions, sources and motions.
    Info(info::InfoArgs),
    /// Build a composite from a recipe and describe it.
    Compose(compose::ComposeArgs),
    /// Write a composite to a file.
    Export(compose::ExportArgs),
    /// Render a still to PNG.
    Render(render::RenderArgs),
    /// Convert a 3DGS scene between PLY, compressed PLY, .splat and SPZ, reporting the error.
    Convert(convert::ConvertArgs),
    /// Capture a multi-view dataset (GaussianAvatars layout) of a built-in source.
    Capture(capture::CaptureArgs),
    /// Train a GaussianAvatars avatar from a multi-view dataset.
    Train(train::TrainArgs),
    /// PSNR / SSIM of an avatar on a dataset's held-out views.
    Eval(train::EvalArgs),
    /// Random composites by the thesis's rules, written as recipes.
    Random(random::RandomArgs),
    /// The perceptual study: build a study folder, run participants, analyse.
    Study(study::StudyArgs),
    /// Measure speed beside error.
    Bench(bench::BenchArgs),
    /// Write test fixtures in the real formats (FLAME-layout model and masks
    /// pickles, GaussianAvatars avatar folders) made from the built-in head.
    Fixtures(FixturesArgs),
}

/// Parses the process arguments, runs the command and maps errors to exit codes.
pub fn run() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    match dispatch(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("visage: {e}");
            ExitCode::from(e.exit_code())
        }
    }
}

fn dispatch(cli: Cli) -> Result<()> {
    match cli.command {
        Some(Command::Info(args)) => info::run(&args),
        Some(Command::Compose(args)) => compose::run_compose(&args),
        Some(Command::Export(args)) => compose::run_export(&args),
        Some(Command::Render(args)) => render::run(&args),
        Some(Command::Convert(args)) => convert::run(&args),
        Some(Command::Bench(args)) => bench::run(&args),
        Some(Command::Random(args)) => random::run(&args),
        Some(Command::Study(args)) => study::run(&args),
        Some(Command::Capture(args)) => capture::run(&args),
        Some(Command::Train(args)) => train::run_train(&args),
        Some(Command::Eval(args)) => train::run_eval(&args),
        Some(Command::Fixtures(args)) => run_fixtures(&args),
        Some(Command::Edit(args)) => edit::run_edit(&args),
        Some(Command::Replay(args)) => edit::run_replay(&args),
        Some(Command::View(args)) => edit::run_view(&args),
        None => edit::run_edit(&cli.edit),
    }
}

/// Help and version go to stdout with exit 0; real usage errors become one line
/// on stderr with exit 2.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(
        e.kind(),
        ErrorKind::DisplayHelp
            | ErrorKind::DisplayVersion
            | ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
    ) {
        let _ = e.print();
        return ExitCode::SUCCESS;
    }
    let rendered = e.render().to_string();
    let first = rendered
        .lines()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("invalid arguments")
        .trim_start_matches("error: ");
    eprintln!(
        "visage: {} (see visage --help)",
        crate::text::printable(first)
    );
    ExitCode::from(2)
}

/// Arguments of `visage fixtures`.
#[derive(clap::Args, Debug)]
struct FixturesArgs {
    /// Folder to write into.
    dir: std::path::PathBuf,
    /// Avatars to write.
    #[arg(long = "source-count", default_value_t = 3)]
    sources: usize,
    /// Gaussians per avatar.
    #[arg(long, default_value_t = 12_000)]
    gaussians_per_avatar: usize,
    /// Seed.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn run_fixtures(args: &FixturesArgs) -> Result<()> {
    let p = crate::io::fixtures::write_fixtures(
        &args.dir,
        args.sources,
        args.gaussians_per_avatar,
        args.seed,
    )?;
    println!(
        "visage --db {} --flame {} --masks {}",
        p.avatars.display(),
        p.model.display(),
        p.masks.display()
    );
    Ok(())
}
