//! `visage convert IN OUT`: a 3DGS scene from one format to another (INRIA
//! PLY, SuperSplat's compressed PLY, `.splat`, Niantic's SPZ), with the error a lossy conversion introduces measured as
//! the PSNR of a fixed view (the scene framed from the front at 320×240, CPU
//! renderer) against the same view of the input.

use std::path::PathBuf;

use clap::Args;
use serde_json::json;

use crate::error::{Error, Result};
use crate::io::splat::{read_scene, write_scene};
use crate::render::image::{psnr_report, RgbImage};
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::{Orbit, UpAxis};
use crate::scene::splats::SplatScene;

/// Arguments of `visage convert`.
#[derive(Args, Debug, Clone)]
pub struct ConvertArgs {
    /// Input scene (.ply, .compressed.ply, .splat or .spz).
    input: PathBuf,
    /// Output scene (.ply, .compressed.ply, .splat or .spz, by extension).
    output: PathBuf,
    /// Print one JSON document.
    #[arg(long)]
    json: bool,
}

/// Size of the view the conversion error is measured on.
pub(super) const VIEW: (u32, u32) = (320, 240);

/// `scene` seen from `orbit` at [`VIEW`] on the CPU renderer: the fixed view
/// that `convert` and `clean` compare before and after.
pub(super) fn home_view(scene: &SplatScene, orbit: &Orbit) -> Result<RgbImage> {
    let mut renderer = SplatRenderer::open(Backend::Cpu)?;
    renderer.set_world_scene(scene)?;
    renderer.render_world(&orbit.camera(VIEW.0, VIEW.1), &RenderSettings::default())
}

/// Runs `visage convert`.
pub fn run(args: &ConvertArgs) -> Result<()> {
    let input = read_scene(&args.input)?;
    let orbit = input
        .home_orbit(None, UpAxis::default())
        .ok_or_else(|| Error::input(format!("{} holds no Gaussians", args.input.display())))?;
    write_scene(&args.output, &input)?;
    let output = read_scene(&args.output)?;
    let psnr =
        psnr_report(&home_view(&output, &orbit)?, &home_view(&input, &orbit)?).unwrap_or(0.0);
    let size = |p: &PathBuf| std::fs::metadata(p).map_or(0, |m| m.len());
    let report = json!({
        "input": args.input.display().to_string(),
        "output": args.output.display().to_string(),
        "gaussians": output.len(),
        "sh_degree_in": input.sh_degree,
        "sh_degree_out": output.sh_degree,
        "bytes_in": size(&args.input),
        "bytes_out": size(&args.output),
        "view": format!("{}x{}", VIEW.0, VIEW.1),
        "psnr_db": psnr,
    });
    if args.json {
        println!("{report}");
    } else {
        println!(
            "wrote {} Gaussians (SH degree {} → {}) to {}: {} → {} bytes; a {}x{} view differs by PSNR {:.1} dB{}",
            output.len(),
            input.sh_degree,
            output.sh_degree,
            args.output.display(),
            size(&args.input),
            size(&args.output),
            VIEW.0,
            VIEW.1,
            psnr,
            if psnr >= 99.0 { " (lossless)" } else { "" }
        );
    }
    Ok(())
}
