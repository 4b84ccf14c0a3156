//! The CPU reference splat renderer: f64 throughout, exact depth order per pixel.
//! Slow and simple on purpose: it is the oracle the GPU renderer is tested against.

use rayon::prelude::*;

use super::image::RgbImage;
use super::projection::{ProjectionCamera, Splat2D, MIN_TRANSMITTANCE};
use super::settings::RenderSettings;
use super::sh::eval_rgb;
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;

struct Projected {
    splat: Splat2D,
    rgb: [f64; 3],
    opacity: f64,
    index: usize,
}

/// Gaussian `i` projected in f64 with its opacity (clamped to [`crate::scene::splats::MAX_OPACITY`]), or `None`
/// when it cannot show (transparent, NaN, not finite, culled).
fn project(
    scene: &SplatScene,
    i: usize,
    cam: &ProjectionCamera,
    settings: &RenderSettings,
) -> Option<(Splat2D, f64)> {
    let opacity = scene.opacity[i] as f64;
    if opacity.is_nan() || opacity <= 0.0 || !scene.position[i].is_finite() {
        return None;
    }
    let opacity = opacity.min(crate::scene::splats::MAX_OPACITY as f64);
    let splat = cam.project(
        scene.position[i],
        scene.rotation[i],
        scene.scale[i] * settings.scale_modifier,
        opacity,
    )?;
    Some((splat, opacity))
}

/// Renders `scene` with the reference rasteriser and returns float RGB per pixel.
pub fn render_reference_f32(
    scene: &SplatScene,
    camera: &Camera,
    settings: &RenderSettings,
) -> Vec<f32> {
    let cam = ProjectionCamera::new(camera);
    let degree = settings.sh_degree.min(scene.sh_degree);
    let mut projected: Vec<Projected> = (0..scene.len())
        .into_par_iter()
        .filter_map(|i| {
            let (splat, opacity) = project(scene, i, &cam, settings)?;
            let dir = (scene.position[i].as_dvec3() - cam.eye).normalize_or_zero();
            let rgb = eval_rgb(scene.sh_of(i), degree, dir.to_array());
            Some(Projected {
                splat,
                rgb,
                opacity,
                index: i,
            })
        })
        .collect();
    projected.sort_by(|a, b| {
        a.splat
            .depth
            .total_cmp(&b.splat.depth)
            .then(a.index.cmp(&b.index))
    });
    let (w, h) = (camera.width, camera.height);
    // Bucket splats by pixel row span, so each row only scans splats touching it.
    let mut rows: Vec<Vec<u32>> = vec![Vec::new(); h as usize];
    for (k, p) in projected.iter().enumerate() {
        if let Some((_, y0, _, y1)) = p.splat.pixel_rect(w, h) {
            for row in &mut rows[y0 as usize..=y1 as usize] {
                row.push(k as u32);
            }
        }
    }
    let bg = settings.background.map(|c| c as f64);
    let mut out = vec![0.0f32; (w * h * 3) as usize];
    out.par_chunks_mut((w * 3) as usize)
        .zip(rows.par_iter())
        .enumerate()
        .for_each(|(y, (line, candidates))| {
            let py = y as f64 + 0.5;
            let mut colour = vec![[0.0f64; 3]; w as usize];
            let mut transmittance = vec![1.0f64; w as usize];
            let mut done = vec![false; w as usize];
            for &k in candidates {
                let p = &projected[k as usize];
                let Some((x0, _, x1, _)) = p.splat.pixel_rect(w, h) else {
                    continue;
                };
                for x in x0..=x1 {
                    let xi = x as usize;
                    if done[xi] {
                        continue;
                    }
                    let alpha = p.splat.alpha_at(p.opacity, x as f64 + 0.5, py);
                    if alpha == 0.0 {
                        continue;
                    }
                    let next = transmittance[xi] * (1.0 - alpha);
                    if next < MIN_TRANSMITTANCE {
                        done[xi] = true;
                        continue;
                    }
                    let weight = alpha * transmittance[xi];
                    for (c, rgb) in colour[xi].iter_mut().zip(p.rgb) {
                        *c += rgb * weight;
                    }
                    transmittance[xi] = next;
                }
            }
            for x in 0..w as usize {
                for ch in 0..3 {
                    line[x * 3 + ch] = (colour[x][ch] + transmittance[x] * bg[ch]) as f32;
                }
            }
        });
    out
}

/// Renders `scene` with the reference rasteriser to an 8-bit image.
pub fn render_reference(
    scene: &SplatScene,
    camera: &Camera,
    settings: &RenderSettings,
) -> RgbImage {
    let rgb = render_reference_f32(scene, camera, settings);
    RgbImage::from_f32(camera.width, camera.height, &rgb)
}

/// The depth of what the centre pixel shows: front to back over the
/// Gaussians covering it (the reference's blending), the depth at which the
/// accumulated opacity passes one half; `None` when it never does (the
/// centre shows mostly background).
pub fn centre_depth(scene: &SplatScene, camera: &Camera, settings: &RenderSettings) -> Option<f64> {
    let cam = ProjectionCamera::new(camera);
    let (px, py) = (camera.width as f64 / 2.0, camera.height as f64 / 2.0);
    let mut hits: Vec<(f64, f64)> = (0..scene.len())
        .into_par_iter()
        .filter_map(|i| {
            let (splat, opacity) = project(scene, i, &cam, settings)?;
            let alpha = splat.alpha_at(opacity, px, py);
            (alpha > 0.0).then_some((splat.depth, alpha))
        })
        .collect();
    hits.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut transmittance = 1.0;
    for (depth, alpha) in hits {
        transmittance *= 1.0 - alpha;
        if transmittance <= 0.5 {
            return Some(depth);
        }
    }
    None
}
