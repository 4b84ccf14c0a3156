//! `visage convert IN OUT`: a 3DGS scene from one format to another (INRIA
//! PLY, SuperSplat's compressed PLY, `.splat`, Niantic's SPZ), with the error a lossy conversion introduces measured as
//! the PSNR of a fixed view (the scene framed from the front at 320×240, CPU
//! renderer) against the same view of the input.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;
use serde_json::json;

use crate::avatar::binding::normalize_quat;
use crate::avatar::gaussians::logit;
use crate::error::{Error, Result};
use crate::io::ply::{write_inria_ply_stream, InriaRecord};
use crate::io::splat::{read_scene, write_scene, SceneFormat};
use crate::render::image::{psnr_report, RgbImage};
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::{Orbit, UpAxis};
use crate::scene::splats::SplatScene;
use crate::scene::synthetic::{synthetic_scene, synthetic_splats, SyntheticSplat};

/// Arguments of `visage convert`.
#[derive(Args, Debug, Clone)]
pub struct ConvertArgs {
    /// IN OUT: the input scene and the output scene (.ply, .compressed.ply,
    /// .splat or .spz, by extension); with --synthetic-scale, OUT alone.
    #[arg(value_name = "IN OUT", num_args = 1..=2, required = true)]
    paths: Vec<PathBuf>,
    /// Write the built-in synthetic scene of N Gaussians (SH degree 3, one in
    /// a thousand a floater) instead of converting; to a .ply it is streamed,
    /// so its size is bounded by the disk, not by memory.
    #[arg(long, value_name = "N")]
    synthetic_scale: Option<usize>,
    /// Seed of the synthetic scene (`bench scene --synthetic` uses 1).
    #[arg(long, default_value_t = 1, requires = "synthetic_scale")]
    seed: u64,
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
    let (input_path, output_path) = match (args.synthetic_scale, args.paths.as_slice()) {
        (Some(n), [out]) => return write_synthetic(n, args.seed, out, args.json),
        (Some(_), _) => {
            return Err(Error::input(
                "--synthetic-scale N writes a scene: give only the output file",
            ))
        }
        (None, [input, output]) => (input, output),
        (None, _) => {
            return Err(Error::input(
                "convert takes IN and OUT (or --synthetic-scale N and OUT)",
            ))
        }
    };
    let input = read_scene(input_path)?;
    let orbit = input
        .home_orbit(None, UpAxis::default())
        .ok_or_else(|| Error::input(format!("{} holds no Gaussians", input_path.display())))?;
    write_scene(output_path, &input)?;
    let output = read_scene(output_path)?;
    let psnr =
        psnr_report(&home_view(&output, &orbit)?, &home_view(&input, &orbit)?).unwrap_or(0.0);
    let size = |p: &PathBuf| std::fs::metadata(p).map_or(0, |m| m.len());
    let report = json!({
        "input": input_path.display().to_string(),
        "output": output_path.display().to_string(),
        "gaussians": output.len(),
        "sh_degree_in": input.sh_degree,
        "sh_degree_out": output.sh_degree,
        "bytes_in": size(input_path),
        "bytes_out": size(output_path),
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
            output_path.display(),
            size(input_path),
            size(output_path),
            VIEW.0,
            VIEW.1,
            psnr,
            if psnr >= 99.0 { " (lossless)" } else { "" }
        );
    }
    Ok(())
}

/// One synthetic Gaussian as a PLY row, exactly as `write_splat_ply` writes
/// the same Gaussian of a `SplatScene` (normalised rotation, logit opacity,
/// log scale).
fn synthetic_record(g: &SyntheticSplat) -> InriaRecord<'_> {
    InriaRecord {
        position: g.position,
        sh: &g.sh,
        opacity_logit: logit(g.opacity),
        log_scale: g.scale.max(glam::Vec3::splat(1e-30)).ln(),
        rotation: normalize_quat(g.rotation),
        extra: None,
    }
}

/// `convert --synthetic-scale N OUT`: the synthetic scene written to OUT,
/// streamed when OUT is a PLY.
fn write_synthetic(count: usize, seed: u64, output: &Path, json: bool) -> Result<()> {
    let start = Instant::now();
    let streamed = SceneFormat::of(output)? == SceneFormat::Ply;
    if streamed {
        write_inria_ply_stream(
            output,
            "synthetic scene written by visage",
            count,
            3,
            synthetic_splats(count, seed),
            synthetic_record,
        )?;
    } else {
        write_scene(output, &synthetic_scene(count, seed))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(output).map_or(0, |m| m.len());
    if json {
        println!(
            "{}",
            json!({"output": output.display().to_string(), "gaussians": count, "seed": seed,
                   "bytes": bytes, "seconds": seconds, "streamed": streamed})
        );
    } else {
        println!(
            "wrote the synthetic scene of {count} Gaussians (seed {seed}) to {}: {bytes} bytes in {seconds:.1} s{}",
            output.display(),
            if streamed { ", streamed" } else { "" }
        );
    }
    Ok(())
}
