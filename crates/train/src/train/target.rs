//! Training targets: a view's image (and mask) read, composited over the
//! background and box-filtered to the training size with its camera scaled
//! to match; and a model scored against one (PSNR and SSIM).

use super::dataset::View;
use super::holes::Obscurer;
use super::loss::{photometric_loss, psnr};
use super::model::{Render, Trainable};
use super::project::TrainCamera;
use super::raster::Rasterizer;
use crate::avatar::binding::TriangleFrame;
use crate::error::{Error, Result};

/// A view's image at the size it is used at, composited over the background.
pub struct Target {
    /// The view.
    pub view: View,
    /// Its camera, scaled to the image's size.
    pub camera: TrainCamera,
    /// RGB, row-major.
    pub pixels: Vec<f32>,
}

/// Reads an image (and its mask) as a target at `size` (default: as stored).
pub fn load_target(view: &View, size: Option<[u32; 2]>, background: [f64; 3]) -> Result<Target> {
    let image = crate::render::image::RgbImage::load_png(&view.image).map_err(Error::input)?;
    if [image.width, image.height] != view.camera.size {
        return Err(Error::input(format!(
            "{} is {}x{}, its frame says {}x{}",
            view.image.display(),
            image.width,
            image.height,
            view.camera.size[0],
            view.camera.size[1]
        )));
    }
    let mask = match &view.mask {
        Some(path) => Some(
            image::open(path)
                .map_err(|e| Error::input(format!("cannot read mask {}: {e}", path.display())))?
                .to_luma8(),
        ),
        None => None,
    };
    let [w, h] = size.unwrap_or(view.camera.size);
    let (sx, sy) = (
        image.width as f64 / w as f64,
        image.height as f64 / h as f64,
    );
    // Box-filter down (or sample up) to the training size.
    let mut pixels = vec![0.0f32; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let (x0, x1) = (
                (x as f64 * sx) as u32,
                (((x + 1) as f64 * sx).ceil() as u32)
                    .min(image.width)
                    .max((x as f64 * sx) as u32 + 1),
            );
            let (y0, y1) = (
                (y as f64 * sy) as u32,
                (((y + 1) as f64 * sy).ceil() as u32)
                    .min(image.height)
                    .max((y as f64 * sy) as u32 + 1),
            );
            let mut sum = [0.0f64; 3];
            let mut n = 0.0;
            for yy in y0..y1 {
                for xx in x0..x1 {
                    let p = (yy * image.width + xx) as usize;
                    let coverage = mask.as_ref().map_or(1.0, |m| m.as_raw()[p] as f64 / 255.0);
                    for ch in 0..3 {
                        // Images are premultiplied by their mask (black behind).
                        sum[ch] += image.pixels[p * 3 + ch] as f64 / 255.0
                            + (1.0 - coverage) * background[ch];
                    }
                    n += 1.0;
                }
            }
            for ch in 0..3 {
                pixels[((y * w + x) * 3) as usize + ch] = (sum[ch] / n) as f32;
            }
        }
    }
    let mut camera = view.camera;
    camera.size = [w, h];
    camera.focal = [camera.focal[0] / sx, camera.focal[1] / sy];
    camera.principal = [camera.principal[0] / sx, camera.principal[1] / sy];
    Ok(Target {
        view: view.clone(),
        camera,
        pixels,
    })
}

/// Renders `model` for a target and returns the image with its PSNR and
/// SSIM against the target.
pub fn evaluate_view(
    model: &Trainable,
    frames: &[TriangleFrame],
    target: &Target,
    background: [f64; 3],
) -> (Vec<f64>, f64, f64) {
    let render = Render::new(
        model,
        frames,
        &target.camera,
        background,
        &Obscurer::None,
        &mut Rasterizer::Cpu,
    )
    .expect("the CPU rasteriser does not fail");
    let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
    let [w, h] = target.camera.size;
    let (loss, _) = photometric_loss(render.image(), &goal, w as usize, h as usize, false);
    let quality = psnr(render.image(), &goal);
    (render.image().to_vec(), quality, loss.ssim)
}
