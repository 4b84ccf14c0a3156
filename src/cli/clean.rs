//! `visage clean IN OUT`: the floater filter (`scene::clean`) on a 3DGS scene
//! file, reporting what each rule removed and how much the scene's home view
//! (framed from the front at 320×240 on the input, CPU renderer) changed.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;
use serde_json::json;

use super::convert::{home_view, VIEW};
use crate::error::{Error, Result};
use crate::io::splat::{read_scene, write_scene};
use crate::render::image::psnr_report;
use crate::scene::camera::UpAxis;
use crate::scene::clean::{judge, keep, CleanOptions};

/// Arguments of `visage clean`.
#[derive(Args, Debug, Clone)]
pub struct CleanArgs {
    /// Input scene (.ply, .compressed.ply, .splat or .spz).
    input: PathBuf,
    /// Output scene (.ply, .compressed.ply, .splat or .spz, by extension).
    output: PathBuf,
    /// Remove Gaussians less opaque than this.
    #[arg(long, default_value_t = CleanOptions::default().min_opacity, value_name = "ALPHA")]
    min_opacity: f32,
    /// Remove Gaussians whose largest standard deviation exceeds this share
    /// of the subject's diagonal.
    #[arg(long, default_value_t = CleanOptions::default().huge, value_name = "SHARE")]
    huge: f32,
    /// Remove Gaussians with fewer than 4 others within this many times the
    /// scene's typical spacing (0: keep isolated ones).
    #[arg(long, default_value_t = CleanOptions::default().isolation, value_name = "FACTOR")]
    isolation: f32,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

impl CleanArgs {
    fn options(&self) -> Result<CleanOptions> {
        if !(0.0..=1.0).contains(&self.min_opacity) {
            return Err(Error::input(format!(
                "--min-opacity takes an opacity from 0 to 1, not {}",
                self.min_opacity
            )));
        }
        if !(self.huge.is_finite() && self.huge > 0.0) {
            return Err(Error::input(format!(
                "--huge takes a positive share of the scene's size, not {}",
                self.huge
            )));
        }
        if !(self.isolation.is_finite() && self.isolation >= 0.0) {
            return Err(Error::input(format!(
                "--isolation takes a factor of 0 or more, not {}",
                self.isolation
            )));
        }
        Ok(CleanOptions {
            min_opacity: self.min_opacity,
            huge: self.huge,
            isolation: self.isolation,
        })
    }
}

/// Runs `visage clean`.
pub fn run(args: &CleanArgs) -> Result<()> {
    let options = args.options()?;
    let input = read_scene(&args.input)?;
    let orbit = input
        .home_orbit(None, UpAxis::default())
        .ok_or_else(|| Error::input(format!("{} holds no Gaussians", args.input.display())))?;
    let start = Instant::now();
    let (verdicts, counts) = judge(&input, &options);
    let filter_ms = start.elapsed().as_secs_f64() * 1e3;
    let output = keep(&input, &verdicts);
    write_scene(&args.output, &output)?;
    let psnr = if output.is_empty() {
        0.0
    } else {
        psnr_report(&home_view(&output, &orbit)?, &home_view(&input, &orbit)?).unwrap_or(0.0)
    };
    let report = json!({
        "input": args.input.display().to_string(),
        "output": args.output.display().to_string(),
        "gaussians_in": input.len(),
        "removed": counts,
        "filter_ms": filter_ms,
        "view": format!("{}x{}", VIEW.0, VIEW.1),
        "psnr_db": psnr,
    });
    if args.json {
        println!("{report}");
        return Ok(());
    }
    println!(
        "kept {} of {} Gaussians in {:.0} ms: removed {} broken, {} transparent (opacity < {}), {} huge (> {} of the scene), {} isolated (fewer than 4 others within {:.3}); wrote {}",
        counts.kept,
        input.len(),
        filter_ms,
        counts.broken,
        counts.transparent,
        options.min_opacity,
        counts.huge,
        options.huge,
        counts.isolated,
        counts.radius,
        args.output.display()
    );
    println!(
        "the home view ({}x{}) after against before: PSNR {:.1} dB{}",
        VIEW.0,
        VIEW.1,
        psnr,
        if psnr >= 99.0 { " (unchanged)" } else { "" }
    );
    Ok(())
}
