//! `visage capture`: a multi-view dataset in GaussianAvatars' layout from a
//! built-in source (see `train::capture`).

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use super::render::parse_size;
use crate::error::Result;
use crate::pipeline::DatabaseSpec;
use crate::train::capture::{capture, CaptureOptions};

/// Arguments of `visage capture`.
#[derive(Args, Debug, Clone)]
pub struct CaptureArgs {
    /// Built-in source to capture.
    #[arg(long, default_value = "ada")]
    source: String,
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
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
}

/// Runs `visage capture`.
pub fn run(args: &CaptureArgs) -> Result<()> {
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
    let summary = capture(
        &db,
        &CaptureOptions {
            source: args.source.clone(),
            size: [args.size.0, args.size.1],
            cameras: args.cameras,
            frames: args.frames,
            motion: args.motion.clone(),
            ring: args.ring,
        },
        &args.output,
        &|done, all| {
            bar.set_length(all);
            bar.set_position(done);
        },
    )?;
    bar.finish_and_clear();
    eprintln!(
        "visage: captured {} images of {} over {} timesteps into {} in {:.1} s",
        summary.images,
        args.source,
        summary.timesteps,
        args.output.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(())
}
