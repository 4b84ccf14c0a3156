//! The `visage` command line: argument parsing, dispatch and the exit-code
//! contract (0 ok, 1 a check failed, 2 bad input, always one line on stderr).

mod bench;
mod cache;
mod camera;
mod capture;
mod clean;
mod compose;
mod convert;
mod database;
mod db;
mod edit;
mod eval_composite;
mod farm;
mod info;
mod lod;
mod random;
mod render;
mod study;
mod train;
mod values;

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
    /// Remove floaters from a 3DGS scene: broken, transparent, huge and isolated Gaussians.
    Clean(clean::CleanArgs),
    /// Build (or find and check) the level-of-detail cache of scene files, ahead of viewing them.
    Lod(lod::LodArgs),
    /// Where visage's cache folder is and what it holds; --clear gives the disk back.
    Cache(cache::CacheArgs),
    /// Capture a multi-view dataset (GaussianAvatars layout) of a built-in source.
    Capture(capture::CaptureArgs),
    /// Train a GaussianAvatars avatar from a multi-view dataset.
    Train(train::TrainArgs),
    /// PSNR / SSIM of an avatar on a dataset's held-out views.
    Eval(train::EvalArgs),
    /// Check and index a database folder; follow a manifest's training across shards.
    Db(database::DbCommandArgs),
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
    let (args, moved) = hoist_subcommand(std::env::args_os().collect());
    let cli = match Cli::try_parse_from(&args) {
        Ok(cli) => cli,
        Err(e) => return usage_error(e, moved.as_deref()),
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
        Some(Command::Clean(args)) => clean::run(&args),
        Some(Command::Lod(args)) => lod::run(&args),
        Some(Command::Cache(args)) => cache::run(&args),
        Some(Command::Bench(args)) => bench::run(&args),
        Some(Command::Random(args)) => random::run(&args),
        Some(Command::Study(args)) => study::run(&args),
        Some(Command::Capture(args)) => capture::run(&args),
        Some(Command::Train(args)) => train::run_train(&args),
        Some(Command::Eval(args)) => train::run_eval(&args),
        Some(Command::Db(args)) => database::run(&args),
        Some(Command::Fixtures(args)) => run_fixtures(&args),
        Some(Command::Edit(args)) => edit::run_edit(&args),
        Some(Command::Replay(args)) => edit::run_replay(&args),
        Some(Command::View(args)) => edit::run_view(&args),
        None => edit::run_edit(&cli.edit),
    }
}

/// Options written before the subcommand they belong to (`visage --db DIR
/// info`) would be read as the editor's: the subcommand moves to the front
/// (`visage info --db DIR`), and the name of the subcommand moved is returned
/// for messages.
fn hoist_subcommand(
    mut args: Vec<std::ffi::OsString>,
) -> (Vec<std::ffi::OsString>, Option<String>) {
    use clap::CommandFactory;
    let starts_with_option = args
        .get(1)
        .is_some_and(|a| a.to_string_lossy().starts_with('-'));
    if !starts_with_option {
        return (args, None);
    }
    let names: Vec<String> = Cli::command()
        .get_subcommands()
        .map(|c| c.get_name().to_string())
        .collect();
    let found = args.iter().enumerate().skip(2).find(|(_, a)| {
        let a = a.to_string_lossy();
        names.iter().any(|n| *n == a) && !std::path::Path::new(a.as_ref()).exists()
    });
    let Some((at, _)) = found else {
        return (args, None);
    };
    let name = args.remove(at);
    let moved = name.to_string_lossy().into_owned();
    args.insert(1, name);
    (args, Some(moved))
}

/// Help and version go to stdout with exit 0; real usage errors become one line
/// on stderr with exit 2, naming what was wrong and the values allowed.
/// `moved`: the subcommand [`hoist_subcommand`] moved to the front.
fn usage_error(e: clap::Error, moved: Option<&str>) -> ExitCode {
    use clap::error::{ContextKind, ContextValue, ErrorKind};
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
    // The error's own lines up to the usage, joined: clap puts the missing
    // arguments and the possible values on lines of their own.
    let mut message: String = rendered
        .lines()
        .take_while(|l| !l.starts_with("Usage:"))
        .map(str::trim)
        .filter(|l| {
            !l.is_empty() && !l.starts_with("tip:") && !l.starts_with("For more information")
        })
        .collect::<Vec<_>>()
        .join(" ")
        .trim_start_matches("error: ")
        .to_string();
    if message.is_empty() {
        message = "invalid arguments".into();
    }
    // A typo's nearest command or option, as clap's own tip would say.
    for kind in [ContextKind::SuggestedSubcommand, ContextKind::SuggestedArg] {
        match e.get(kind) {
            Some(ContextValue::String(s)) => message.push_str(&format!(" (did you mean '{s}'?)")),
            Some(ContextValue::Strings(s)) if !s.is_empty() => {
                message.push_str(&format!(" (did you mean '{}'?)", s.join("' or '")))
            }
            _ => {}
        }
    }
    if let Some(ContextValue::Strings(valid)) = e.get(ContextKind::ValidValue) {
        if !message.contains("possible values") && !valid.is_empty() {
            message.push_str(&format!(" (one of: {})", valid.join(", ")));
        }
    }
    let hint = match (moved, e.kind()) {
        (Some(sub), ErrorKind::UnknownArgument) => format!(
            "; options before '{sub}' must be options of 'visage {sub}' (see visage {sub} --help)"
        ),
        _ => " (see visage --help)".into(),
    };
    eprintln!("visage: {}{hint}", crate::text::printable(&message));
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
    /// Cut the built-in head's mouth pocket away, leaving the lips' inner rim
    /// open as FLAME's is (the loader then adds its own mouth cavity).
    #[arg(long)]
    open_mouth: bool,
}

fn run_fixtures(args: &FixturesArgs) -> Result<()> {
    use crate::io::fixtures::{write_fixtures_with, FixtureMouth};
    let mouth = if args.open_mouth {
        FixtureMouth::Open
    } else {
        FixtureMouth::Pocket
    };
    let p = write_fixtures_with(
        &args.dir,
        args.sources,
        args.gaussians_per_avatar,
        args.seed,
        mouth,
    )?;
    println!(
        "visage --db {} --flame {} --masks {}",
        p.avatars.display(),
        p.model.display(),
        p.masks.display()
    );
    Ok(())
}
