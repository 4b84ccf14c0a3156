//! `visage render`: a still of a composite (or any standard 3DGS PLY) to PNG.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use super::compose::build;
use super::DbArgs;
use crate::compose::recipe::Recipe;
use crate::error::{Error, Result};
use crate::io::ply::read_splat_ply;
use crate::render::camera::Orbit;
use crate::render::reference::{render_reference, RenderSettings};
use crate::render::scene::SplatScene;

/// Arguments of `visage render`.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Recipe file (TOML); without one (and without --ply) the first source is shown.
    #[arg(long, value_name = "FILE", conflicts_with = "ply")]
    recipe: Option<PathBuf>,
    /// A standard 3DGS PLY (INRIA layout, SH degree 0-3) to render instead of a composite.
    #[arg(long, value_name = "FILE")]
    ply: Option<PathBuf>,
    /// Frame of the recipe's motion.
    #[arg(long, value_name = "N")]
    frame: Option<usize>,
    /// Camera yaw in degrees (overrides the recipe's camera).
    #[arg(long, allow_negative_numbers = true)]
    yaw: Option<f32>,
    /// Camera pitch in degrees (overrides the recipe's camera).
    #[arg(long, allow_negative_numbers = true)]
    pitch: Option<f32>,
    /// Image size as WxH.
    #[arg(long, default_value = "640x480", value_parser = parse_size)]
    size: (u32, u32),
    /// Render with the CPU reference renderer (f64, exact depth order).
    #[arg(long)]
    reference: bool,
    /// Output PNG.
    #[arg(short = 'o', long = "output", value_name = "OUT.png")]
    output: PathBuf,
}

/// Parses "WxH" with both sides in 1..=8192.
pub fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (w, h) = s
        .split_once(['x', 'X'])
        .ok_or_else(|| format!("size '{s}' is not WxH"))?;
    let parse = |v: &str| -> std::result::Result<u32, String> {
        v.trim()
            .parse::<u32>()
            .ok()
            .filter(|n| (1..=8192).contains(n))
            .ok_or_else(|| format!("size '{s}' needs sides between 1 and 8192"))
    };
    Ok((parse(w)?, parse(h)?))
}

/// Runs `visage render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let (scene, mut orbit) = if let Some(ply) = &args.ply {
        let scene = read_splat_ply(ply)?;
        let (lo, hi) = scene
            .bounds()
            .ok_or_else(|| Error::input(format!("{} holds no Gaussians", ply.display())))?;
        (
            scene,
            Orbit {
                fov_deg: 40.0,
                ..Orbit::STUDY
            }
            .framing(lo, hi),
        )
    } else {
        let path = match &args.recipe {
            Some(p) => p.clone(),
            None => {
                let tmp = std::env::temp_dir()
                    .join(format!("visage-default-{}.toml", std::process::id()));
                std::fs::write(&tmp, Recipe::unedited("ada").to_toml())
                    .map_err(|e| Error::input(e.to_string()))?;
                tmp
            }
        };
        let built = build(&args.db, &path, args.frame)?;
        let scene = built.engine.scene(&built.composite, &built.posed);
        (scene, built.composite.recipe.camera)
    };
    if let Some(yaw) = args.yaw {
        orbit.yaw_deg = yaw;
    }
    if let Some(pitch) = args.pitch {
        orbit.pitch_deg = pitch;
    }
    let camera = orbit.camera(args.size.0, args.size.1);
    let t = Instant::now();
    let image = render_still(&scene, &camera, args.reference)?;
    eprintln!(
        "visage: rendered {} Gaussians at {}x{} in {:.1} ms",
        scene.len(),
        args.size.0,
        args.size.1,
        t.elapsed().as_secs_f64() * 1e3
    );
    image.save_png(&args.output)?;
    Ok(())
}

fn render_still(
    scene: &SplatScene,
    camera: &crate::render::camera::Camera,
    _reference: bool,
) -> Result<crate::render::image::RgbImage> {
    Ok(render_reference(scene, camera, &RenderSettings::default()))
}
