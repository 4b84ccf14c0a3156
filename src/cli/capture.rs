//! `visage capture`: a multi-view dataset in GaussianAvatars' layout from a
//! built-in source (see `train::capture`).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use super::values::parse_size;
use crate::error::Result;
use crate::pipeline::DatabaseSpec;
use crate::train::capture::{capture_sitter, CaptureOptions};
use crate::train::sitter::{Seams, Sitter, Tone};

/// Arguments of `visage capture`.
#[derive(Args, Debug, Clone)]
pub struct CaptureArgs {
    /// Built-in source to capture.
    #[arg(long, default_value = "ada", conflicts_with = "recipe")]
    source: String,
    /// Capture the ground truth of a composite instead: the ideal avatar of
    /// the person this recipe describes over the built-in people.
    #[arg(long, value_name = "RECIPE")]
    recipe: Option<PathBuf>,
    /// The composite's appearance: each region as its source has it
    /// (`source`), or the base's skin tone and detail with each source's own
    /// lips, eyes, brows, hair and beard (`base`).
    #[arg(long, value_parser = Tone::parse, requires = "recipe", value_name = "source|base")]
    tone: Option<Tone>,
    /// How sources meet at a group border: `hard`, or `smooth` (cross-blended
    /// over about 1 cm of template surface).
    #[arg(long, value_parser = Seams::parse, requires = "recipe", value_name = "hard|smooth")]
    seams: Option<Seams>,
    /// Image size.
    #[arg(long, value_parser = parse_size, default_value = "256x256", value_name = "WxH")]
    size: (u32, u32),
    /// Training cameras (a frontal arc of ±60° yaw in two rows, as NeRSemble's).
    #[arg(long, default_value_t = 16)]
    cameras: usize,
    /// Timesteps, sampled evenly from the motion; the last fifth are the test
    /// split (novel expressions).
    #[arg(long, default_value_t = 20)]
    frames: usize,
    /// Built-in motion to capture.
    #[arg(long, default_value = "talk")]
    motion: String,
    /// A full ring of cameras instead of the frontal arc.
    #[arg(long)]
    ring: bool,
    /// Seed of the built-in database (the source's shape and textures).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Folder to write the dataset into.
    #[arg(short, long, value_name = "DIR", required_unless_present = "manifest")]
    output: Option<PathBuf>,
    /// Capture the datasets of a manifest's subjects that name a built-in
    /// person (`[subject.capture]`) instead, skipping those already there.
    #[arg(long, value_name = "TOML", conflicts_with_all = [
        "output", "recipe", "source", "size", "cameras", "frames", "motion", "ring", "seed",
    ])]
    manifest: Option<PathBuf>,
    #[command(flatten)]
    shard: super::farm::ShardArgs,
}

/// Runs `visage capture`.
pub fn run(args: &CaptureArgs) -> Result<()> {
    if let Some(manifest) = &args.manifest {
        return super::farm::capture_manifest(manifest, &args.shard);
    }
    let Some(output) = &args.output else {
        return Err(crate::error::Error::input("give -o DIR, or --manifest"));
    };
    let start = Instant::now();
    let spec = DatabaseSpec {
        seed: args.seed,
        gaussians_per_avatar: 1,
        ..DatabaseSpec::default()
    };
    let (db, _) = spec.load()?;
    let bar = indicatif::ProgressBar::new(0).with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} capturing {pos}/{len} images [{bar:30}] {eta} left",
        )
        .expect("the template is valid")
        .progress_chars("=> "),
    );
    if args.recipe.is_none() && (args.tone.is_some() || args.seams.is_some()) {
        return Err(crate::error::Error::input(
            "--tone and --seams describe a composite's ground truth: they go with --recipe",
        ));
    }
    let sitter = match &args.recipe {
        Some(path) => {
            let recipe = crate::compose::recipe::Recipe::load(path)?;
            let (tone, seams) = (
                args.tone.unwrap_or_default(),
                args.seams.unwrap_or_default(),
            );
            Sitter::composite(&db, &recipe, tone, seams)
                .map_err(|e| crate::error::Error::input(format!("{}: {e}", path.display())))?
        }
        None => {
            let index = db
                .sources
                .iter()
                .position(|s| s.name == args.source)
                .ok_or_else(|| {
                    crate::error::Error::input(format!(
                        "unknown source '{}' (sources: {})",
                        crate::text::printable(&args.source),
                        db.sources
                            .iter()
                            .map(|s| s.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })?;
            Sitter::source(&db, index)
        }
    };
    let summary = capture_sitter(
        &db,
        &CaptureOptions {
            source: args.source.clone(),
            size: [args.size.0, args.size.1],
            cameras: args.cameras,
            frames: args.frames,
            motion: args.motion.clone(),
            ring: args.ring,
        },
        &sitter,
        output,
        &|done, all| {
            bar.set_length(all);
            bar.set_position(done);
        },
    )?;
    bar.finish_and_clear();
    eprintln!(
        "visage: captured {} images of {} over {} timesteps into {} in {:.1} s",
        summary.images,
        match &args.recipe {
            Some(r) => format!("the composite of {}", r.display()),
            None => args.source.clone(),
        },
        summary.timesteps,
        output.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
