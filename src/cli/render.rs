//! `visage render`: a still of a composite (or any standard 3DGS PLY) to PNG.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use super::camera::CameraArgs;
use super::compose::{build, build_from, FitArgs};
use super::values::{parse_range, parse_size};
use super::DbArgs;
use crate::compose::recipe::Recipe;
use crate::error::{Error, Result};
use crate::pipeline::composer::{reference_image, Composer, Painter};
use crate::pipeline::lod::LodScene;
use crate::render::lod::LodPolicy;
use crate::render::reference::render_reference;
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::splats::SplatScene;

/// Arguments of `visage render`.
#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    #[command(flatten)]
    db: DbArgs,
    /// Recipe file (TOML); without one (and without --ply) the first source is shown.
    #[arg(long, value_name = "FILE", conflicts_with = "ply")]
    recipe: Option<PathBuf>,
    #[command(flatten)]
    fit: FitArgs,
    /// A 3DGS scene to render instead of a composite: an INRIA PLY (SH degree
    /// 0-3) or an antimatter15 .splat.
    #[arg(long, value_name = "FILE")]
    ply: Option<PathBuf>,
    /// Frame of the recipe's motion.
    #[arg(long, value_name = "N")]
    frame: Option<usize>,
    /// Camera settings (each replaces that part of the recipe's camera or of
    /// the framing of a --ply scene).
    #[command(flatten)]
    camera: CameraArgs,
    /// Image size as WxH.
    #[arg(long, default_value = "640x480", value_parser = parse_size)]
    size: (u32, u32),
    /// Render with the CPU reference renderer (f64, exact depth order).
    #[arg(long)]
    reference: bool,
    /// Level of detail for a scene (--ply): off (every Gaussian, the
    /// default), auto (nodes of at most 1.5 px where the scene holds more
    /// than 4 Gaussians a pixel), or a budget of Gaussians (e.g. 300k).
    #[arg(long, default_value = "off", value_parser = LodPolicy::parse, conflicts_with = "reference")]
    lod: LodPolicy,
    /// Renderer: auto (a hardware GPU if present, else the CPU renderer), gpu
    /// (wgpu on any adapter, lavapipe included) or cpu.
    #[arg(long, value_parser = Backend::parse, default_value = "auto")]
    renderer: Backend,
    /// Render a frame sequence START..END (END excluded) of the recipe's motion;
    /// the output path must contain `{frame}` (replaced by the zero-padded index).
    #[arg(long, value_name = "START..END", value_parser = parse_range, conflicts_with = "frame")]
    frames: Option<(usize, usize)>,
    /// Output PNG.
    #[arg(short = 'o', long = "output", value_name = "OUT.png")]
    output: PathBuf,
}

/// Renders frames `start..end` of a composite's motion to numbered PNGs.
fn render_sequence(
    args: &RenderArgs,
    subject: &mut Subject,
    camera: &crate::scene::camera::Camera,
    settings: &RenderSettings,
    start: usize,
    end: usize,
) -> Result<()> {
    let Subject::Composite(composer) = subject else {
        return Err(Error::input(
            "--frames renders a recipe's motion; a PLY has one frame",
        ));
    };
    let pattern = args.output.to_string_lossy().into_owned();
    if !pattern.contains("{frame}") {
        return Err(Error::input(
            "with --frames the output path must contain {frame}, e.g. -o shots/frame-{frame}.png",
        ));
    }
    composer.check_frames(start..end)?;
    let first = PathBuf::from(pattern.replace("{frame}", &format!("{start:04}")));
    if let Some(dir) = first.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
    }
    let mut painter = (!args.reference)
        .then(|| Painter::open(args.renderer))
        .transpose()?;
    let t = Instant::now();
    for k in start..end {
        composer.pose(k);
        let image = match &mut painter {
            Some(p) => p.render(composer, camera, settings)?,
            None => reference_image(composer, camera, settings),
        };
        image.save_png(std::path::Path::new(
            &pattern.replace("{frame}", &format!("{k:04}")),
        ))?;
    }
    eprintln!(
        "visage: rendered frames {start}..{end} in {:.1} s",
        t.elapsed().as_secs_f64()
    );
    Ok(())
}

/// What a still shows: a world-space PLY scene, or a posed composite.
enum Subject {
    Ply(SplatScene),
    Composite(Box<Composer>),
}

/// Runs `visage render`.
pub fn run(args: &RenderArgs) -> Result<()> {
    let overrides = args.camera.overrides()?;
    // Checked before anything is rendered: the file must be a PNG.
    if !args
        .output
        .to_string_lossy()
        .to_ascii_lowercase()
        .ends_with(".png")
    {
        return Err(Error::input(format!(
            "render writes PNG images: name the output .png, not '{}'",
            args.output.display()
        )));
    }
    let (mut subject, orbit) = if let Some(ply) = &args.ply {
        let scene = crate::io::splat::read_scene(ply)?;
        let orbit = scene
            .home_orbit(overrides.fov_deg, overrides.up.unwrap_or_default())
            .ok_or_else(|| Error::input(format!("{} holds no Gaussians", ply.display())))?;
        (Subject::Ply(scene), orbit)
    } else {
        // Without a recipe: the database's first source as it is, in the rest pose.
        let (composer, _) = match &args.recipe {
            Some(path) => build(&args.db, path, args.frame, &args.fit)?,
            None => build_from(&args.db, args.frame, |database| {
                Recipe::unedited(&database.sources[0].name)
            })?,
        };
        let orbit = composer.composite().recipe.camera;
        (Subject::Composite(Box::new(composer)), orbit)
    };
    let orbit = overrides.apply(orbit);
    let camera = orbit.camera(args.size.0, args.size.1);
    let settings = RenderSettings::default();
    if let Some((start, end)) = args.frames {
        return render_sequence(args, &mut subject, &camera, &settings, start, end);
    }
    let t = Instant::now();
    let (image, count, device) = match (&subject, args.reference) {
        (Subject::Ply(scene), true) => (
            render_reference(scene, &camera, &settings),
            scene.len(),
            "CPU reference".to_string(),
        ),
        (Subject::Composite(c), true) => (
            reference_image(c, &camera, &settings),
            c.composite().gaussians.len(),
            "CPU reference".to_string(),
        ),
        (Subject::Ply(scene), false) => {
            let mut r = SplatRenderer::open(args.renderer)?;
            let pixels = (camera.width * camera.height) as usize;
            match args.lod.resolve(scene.len(), pixels) {
                LodPolicy::Off => {
                    r.set_world_scene(scene)?;
                    (
                        r.render_world(&camera, &settings)?,
                        scene.len(),
                        r.description(),
                    )
                }
                policy => {
                    let mut hierarchy = LodScene::new(crate::render::lod::build(scene));
                    let image = hierarchy.render(&mut r, &camera, policy, &settings)?;
                    let cut = hierarchy.summary();
                    let device = match cut.on_gpu {
                        true => format!(
                            "{} (level of detail, cut on the GPU: {} of {} Gaussians on screen)",
                            r.description(),
                            cut.drawn,
                            scene.len(),
                        ),
                        false => format!(
                            "{} (level of detail: {} of {} Gaussians, levels {}-{})",
                            r.description(),
                            cut.drawn,
                            scene.len(),
                            cut.levels.0,
                            cut.levels.1
                        ),
                    };
                    (image, cut.drawn, device)
                }
            }
        }
        (Subject::Composite(c), false) => {
            let mut painter = Painter::open(args.renderer)?;
            let image = painter.render(c, &camera, &settings)?;
            (image, c.composite().gaussians.len(), painter.description())
        }
    };
    eprintln!(
        "visage: rendered {count} Gaussians at {}x{} in {:.1} ms on {device}",
        args.size.0,
        args.size.1,
        t.elapsed().as_secs_f64() * 1e3
    );
    image.save_png(&args.output)?;
    Ok(())
}
