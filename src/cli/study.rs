//! `visage study build | run | analyse`: the perceptual study of thesis
//! §6.2-6.3 from one tool.

use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};

use crate::compose::composition::Attributes;
use crate::compose::rules::Rules;
use crate::error::{Error, Result};
use crate::render::Backend;
use crate::study::analysis::{analyse, AnalysisOptions};
use crate::study::design::{build, category_counts, Databases, StudyFolder};
use crate::study::fits::{fit_avatars, fit_store};
use crate::study::journal::{read_all, tally};
use crate::study::plot::write_plots;
use crate::study::results::Results;
use crate::train::seam_fit::SeamFit;
use crate::tui::graphics::GraphicsChoice;
use crate::tui::study::{run_participant, RunOptions};

/// Arguments of `visage study`.
#[derive(Args, Debug)]
pub struct StudyArgs {
    #[command(subcommand)]
    command: StudyCommand,
}

#[derive(Subcommand, Debug)]
enum StudyCommand {
    /// Build a study folder from a spec (categories of recipes or unedited sources).
    Build(BuildArgs),
    /// Run a participant's session in the terminal (resumes where they left off).
    Run(RunArgs),
    /// Scores per avatar, category and region, with intervals, table and plots.
    Analyse(AnalyseArgs),
    /// Who has answered how much so far (safe while sessions run).
    Status(StatusArgs),
}

/// Arguments of `visage study status`.
#[derive(Args, Debug)]
struct StatusArgs {
    /// A study folder made by `visage study build`.
    study: PathBuf,
    /// Print JSON instead of lines.
    #[arg(long)]
    json: bool,
}

/// Arguments of `visage study build`.
#[derive(Args, Debug)]
struct BuildArgs {
    /// The study spec (TOML; see studies/builtin/spec.toml).
    spec: PathBuf,
    /// Folder to build the study in.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    #[command(flatten)]
    fit: StudyFitArgs,
}

/// The seam fit of a study's avatars: made by `study build` into the
/// study's fits/ folder, shown from there by `study run` under the same
/// options (under others the run fits again, and keeps those fits too).
#[derive(Args, Debug)]
struct StudyFitArgs {
    /// Steps of the seam fit of each avatar whose post-processing asks for
    /// one (`post = "ours"`, or a table with `fit = "seams"`): `study build` makes the fits into the study's
    /// fits/ folder, `study run` shows them from there under the same
    /// options (and fits under others); 0: none (`study build` then leaves
    /// each fit to the run, `study run` shows the avatar unfitted).
    #[arg(long, value_name = "STEPS", default_value_t = SeamFit::default().iterations)]
    seam_fit: usize,
    /// The width and height of the seam fit's views, in pixels.
    #[arg(long, value_name = "PX", default_value_t = SeamFit::default().size, value_parser = clap::value_parser!(u32).range(16..=4096))]
    seam_fit_size: u32,
    /// What draws the seam fit's views: cpu (the same bits on every
    /// machine), auto (a hardware GPU when there is one, else the CPU) or
    /// gpu (any adapter, f32).
    #[arg(long, value_name = "RENDERER", value_parser = Backend::parse, default_value = "cpu")]
    seam_fit_renderer: Backend,
}

impl StudyFitArgs {
    fn options(&self) -> SeamFit {
        SeamFit {
            iterations: self.seam_fit,
            size: self.seam_fit_size,
            renderer: self.seam_fit_renderer,
            ..SeamFit::default()
        }
    }
}

/// Arguments of `visage study run`.
#[derive(Args, Debug)]
struct RunArgs {
    /// A study folder made by `visage study build`.
    study: PathBuf,
    /// The participant's ID (letters, digits, '-' or '_'); their answers go
    /// to STUDY/answers/ID.jsonl.
    #[arg(long)]
    participant: String,
    /// Terminal graphics protocol.
    #[arg(long, value_enum, default_value_t = GraphicsChoice::Auto)]
    graphics: GraphicsChoice,
    /// Renderer: auto (hardware GPU, else CPU), gpu or cpu.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    #[command(flatten)]
    fit: StudyFitArgs,
}

/// Arguments of `visage study analyse`.
#[derive(Args, Debug)]
struct AnalyseArgs {
    /// A study folder, or a results file (such as studies/thesis/results.toml).
    study: PathBuf,
    /// Exclusion rules (see studies/thesis/exclusions.toml).
    #[arg(long, value_name = "RULES")]
    exclude: Option<PathBuf>,
    /// Source labels for the rules, on top of the study's own.
    #[arg(long, value_name = "FILE")]
    attributes: Option<PathBuf>,
    /// Print JSON instead of the table.
    #[arg(long)]
    json: bool,
    /// Write authenticity.png and regions.png into this folder.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Write the tallied per-avatar results (the format a results file has).
    #[arg(long, value_name = "FILE")]
    results: Option<PathBuf>,
    /// Bootstrap resamples per interval.
    #[arg(long, default_value_t = 10_000)]
    resamples: usize,
    /// Seed of the bootstrap.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Runs `visage study …`.
pub fn run(args: &StudyArgs) -> Result<()> {
    match &args.command {
        StudyCommand::Build(a) => run_build(a),
        StudyCommand::Run(a) => run_session(a),
        StudyCommand::Analyse(a) => run_analyse(a),
        StudyCommand::Status(a) => run_status(a),
    }
}

fn run_status(args: &StatusArgs) -> Result<()> {
    let study = StudyFolder::open(&args.study)?;
    let total = study.study.avatars.len();
    let journals = read_all(&study)?;
    let rows: Vec<serde_json::Value> = journals
        .iter()
        .map(|(who, answers)| {
            let mut answered: Vec<u32> = answers.iter().map(|a| a.avatar).collect();
            answered.sort_unstable();
            answered.dedup();
            let seconds = answers.iter().map(|a| a.seconds).fold(0.0, |a, b| a + b);
            serde_json::json!({
                "participant": who,
                "answered": answered.len(),
                "avatars": total,
                "done": answered.len() == total,
                "seconds": seconds,
            })
        })
        .collect();
    if args.json {
        let all = serde_json::json!({ "avatars": total, "participants": rows });
        println!(
            "{}",
            serde_json::to_string_pretty(&all).expect("JSON values serialise")
        );
        return Ok(());
    }
    println!(
        "{}: {total} avatars, {} participants ({} done)",
        args.study.display(),
        rows.len(),
        rows.iter().filter(|r| r["done"] == true).count()
    );
    for r in &rows {
        println!(
            "  {:<20} {:>4} / {total}{}  {:.0} s looking",
            r["participant"].as_str().unwrap_or_default(),
            r["answered"],
            if r["done"] == true { "  done" } else { "" },
            r["seconds"].as_f64().unwrap_or_default()
        );
    }
    Ok(())
}

fn run_build(args: &BuildArgs) -> Result<()> {
    let study = build(&args.spec, &args.out, &mut Databases::default())?;
    if args.fit.seam_fit > 0 {
        let options = args.fit.options();
        let folder = StudyFolder::open(&args.out)?;
        let bar = indicatif::ProgressBar::new(0).with_style(
            indicatif::ProgressStyle::with_template(
                "{spinner} seam fits [{bar:25}] {pos}/{len} avatars done, {msg} ({eta} left)",
            )
            .expect("the template is valid")
            .progress_chars("=> "),
        );
        let summary = fit_avatars(&folder, &options, &mut |k, count, p| {
            bar.set_length(count as u64);
            bar.set_position(k as u64);
            bar.set_message(format!(
                "avatar {} at {}%",
                k + 1,
                100 * p.done / p.total.max(1)
            ));
        })?;
        bar.finish_and_clear();
        let plural = |n: usize| if n == 1 { "" } else { "s" };
        if summary.fitted + summary.stored > 0 {
            let earlier = match summary.stored {
                0 => String::new(),
                n => format!(" ({n} of them there from an earlier build)"),
            };
            let n = summary.fitted + summary.stored;
            eprintln!(
                "visage: fitted the seams of {n} avatar{}{earlier} into {}",
                plural(n),
                fit_store(&folder).dir().display()
            );
        }
        if summary.removed > 0 {
            eprintln!(
                "visage: removed {} fit{} of no avatar of this build from {}",
                summary.removed,
                plural(summary.removed),
                fit_store(&folder).dir().display()
            );
        }
    }
    let counts: Vec<String> = category_counts(&study)
        .into_iter()
        .map(|(c, n)| format!("{c} {n}"))
        .collect();
    println!(
        "built {} with {} avatars ({}); run it with: visage study run {} --participant ID",
        args.out.display(),
        study.avatars.len(),
        counts.join(", "),
        args.out.display()
    );
    Ok(())
}

fn run_session(args: &RunArgs) -> Result<()> {
    use std::io::IsTerminal;
    let study = StudyFolder::open(&args.study)?;
    if !std::io::stdout().is_terminal() || !std::io::stdin().is_terminal() {
        return Err(Error::input("visage study run needs a terminal"));
    }
    let summary = run_participant(RunOptions {
        study,
        participant: args.participant.clone(),
        graphics: args.graphics,
        renderer: args.renderer,
        seam_fit: args.fit.options(),
    })?;
    println!("{summary}");
    Ok(())
}

/// The results to analyse and the labels that come with them.
fn load_results(path: &Path) -> Result<(Results, Attributes)> {
    if path.is_dir() {
        let study = StudyFolder::open(path)?;
        let results = tally(&study)?;
        Ok((results, study.study.attributes))
    } else {
        Ok((Results::load(path)?, Attributes::default()))
    }
}

fn run_analyse(args: &AnalyseArgs) -> Result<()> {
    if args.resamples == 0 || args.resamples > 1_000_000 {
        return Err(Error::input("--resamples must be between 1 and 1000000"));
    }
    let (results, mut attributes) = load_results(&args.study)?;
    if let Some(path) = &args.attributes {
        attributes = attributes.overlaid(Attributes::load(path)?);
    }
    let options = AnalysisOptions {
        exclude: args.exclude.as_deref().map(Rules::load).transpose()?,
        attributes,
        resamples: args.resamples,
        seed: args.seed,
    };
    let analysis = analyse(&results, &options)?;
    if let Some(path) = &args.results {
        std::fs::write(path, results.to_toml()).map_err(|e| Error::io("write", path, e))?;
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&analysis).expect("analyses serialise")
        );
    } else {
        print!("{}", analysis.table());
    }
    if let Some(dir) = &args.plots {
        for path in write_plots(&analysis, dir)? {
            eprintln!("wrote {}", path.display());
        }
    }
    Ok(())
}
