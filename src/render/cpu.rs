//! The fast CPU splat renderer, for machines whose only Vulkan device is a
//! software one. Mesa's lavapipe runs the wgpu kernels correctly but pays ~7 ns
//! per tile-list entry per pixel (measured with `visage bench render`); this path
//! visits each entry once per tile and touches only the pixels its footprint
//! covers, so the same frame costs a fraction of that.
//!
//! Numerics are those of the reference (`projection.rs`: projection and SH in
//! f64), with blending in f32 and the same depth sort and tile binning as the GPU
//! path. Tiles are rasterised in parallel; a tile stops once every pixel in it
//! is saturated.

use std::time::Instant;

use rayon::prelude::*;

use super::image::{quantize, RgbImage};
use super::projection::{ProjectionCamera, MAX_ALPHA, MIN_ALPHA};
use super::settings::RenderSettings;
use super::settings::StageTimings;
use super::sh::eval_rgb;
use super::tiles::{pack_tile, TileBins, TileKey};
use crate::avatar::binding::{local_to_world, TriangleFrame};
use crate::avatar::gaussians::{sigmoid, GaussianSet};
use crate::error::{Error, Result};
use crate::scene::camera::Camera;

/// Tile edge of the CPU rasteriser.
pub const CPU_TILE: u32 = 16;

/// A projected Gaussian in the form the blending loop reads.
#[derive(Clone, Copy, Debug, Default)]
struct Splat {
    x: f32,
    y: f32,
    radius: f32,
    conic: [f32; 3],
    opacity: f32,
    /// Exponents below this give α < 1/255: skipped without evaluating exp.
    cutoff: f32,
    rgb: [f32; 3],
}

/// The CPU renderer; same interface as the GPU one.
#[derive(Default)]
pub struct CpuRenderer {
    set: Option<GaussianSet>,
    splats: Vec<Splat>,
    keys: Vec<TileKey>,
    bins: TileBins,
    /// Timings of the last frame (bind and project are one stage here).
    pub timings: StageTimings,
}

impl CpuRenderer {
    /// A renderer with nothing uploaded.
    pub fn new() -> Self {
        Self::default()
    }

    /// The sort keys of the last frame (depth bits, first and last tile; zero
    /// for culled Gaussians), for comparing with the GPU's `project` kernel.
    pub fn keys(&self) -> &[TileKey] {
        &self.keys
    }

    /// Keeps the Gaussians to render (call when the selection changes).
    pub fn set_gaussians(&mut self, set: &GaussianSet) {
        self.set = Some(set.clone());
    }

    /// Renders the Gaussians placed on `frames` (one per triangle).
    pub fn render(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let set = self
            .set
            .as_ref()
            .ok_or_else(|| Error::input("no Gaussians uploaded to the renderer"))?;
        if frames.is_empty() {
            return Err(Error::input("no triangle frames to bind the Gaussians to"));
        }
        let (width, height) = (camera.width.max(1), camera.height.max(1));
        let tiles = (width.div_ceil(CPU_TILE), height.div_ceil(CPU_TILE));
        let mut timings = StageTimings::default();

        let t = Instant::now();
        let cam = ProjectionCamera::new(camera);
        let degree = settings.sh_degree.min(set.sh_degree);
        let n = set.len();
        self.splats.resize(n, Splat::default());
        self.keys.resize(n, [0; 4]);
        let last_frame = frames.len() - 1;
        self.splats
            .par_iter_mut()
            .zip(self.keys.par_iter_mut())
            .enumerate()
            .with_min_len(1024)
            .for_each(|(i, (splat, key))| {
                *key = [0; 4];
                let frame = &frames[(set.binding[i] as usize).min(last_frame)];
                let g = local_to_world(frame, set.position[i], set.rotation[i], set.log_scale[i]);
                let opacity = sigmoid(set.opacity_logit[i]).min(1.0);
                if opacity.is_nan() || opacity <= 0.0 || !g.position.is_finite() {
                    return;
                }
                let Some(s) =
                    cam.project(g.position, g.rotation, g.scale * settings.scale_modifier)
                else {
                    return;
                };
                let Some((x0, y0, x1, y1)) = s.pixel_rect(width, height) else {
                    return;
                };
                let dir = (g.position.as_dvec3() - cam.eye).normalize_or_zero();
                let rgb = eval_rgb(set.sh_of(i), degree, dir.to_array());
                *splat = Splat {
                    x: s.center[0] as f32,
                    y: s.center[1] as f32,
                    radius: s.radius as f32,
                    conic: s.conic.map(|c| c as f32),
                    opacity,
                    cutoff: ((MIN_ALPHA / opacity as f64).ln() - 1e-6) as f32,
                    rgb: rgb.map(|c| c as f32),
                };
                *key = [
                    (s.depth as f32).to_bits(),
                    pack_tile(x0 / CPU_TILE, y0 / CPU_TILE),
                    pack_tile(x1 / CPU_TILE, y1 / CPU_TILE),
                    1,
                ];
            });
        timings.project = ms(t);

        let t = Instant::now();
        self.bins.bin(&self.keys, tiles, settings.sort_bits);
        timings.sort = ms(t);

        let t = Instant::now();
        let mut rgba = vec![0u8; (width * height * 3) as usize];
        let row_bytes = (width * 3) as usize;
        let band = row_bytes * CPU_TILE as usize;
        let (splats, bins) = (&self.splats, &self.bins);
        let background = settings.background;
        let early_stop = settings.early_stop;
        rgba.par_chunks_mut(band)
            .enumerate()
            .for_each(|(ty, rows)| {
                for tx in 0..tiles.0 {
                    let tile = (ty as u32 * tiles.0 + tx) as usize;
                    blend_tile(
                        rows,
                        row_bytes,
                        (tx * CPU_TILE, ty as u32 * CPU_TILE),
                        (width, height),
                        bins.tile(tile),
                        splats,
                        background,
                        early_stop,
                    );
                }
            });
        timings.rasterize = ms(t);
        self.timings = timings;
        Ok(RgbImage {
            width,
            height,
            pixels: rgba,
        })
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Blends one tile front to back into `rows` (the image rows of its tile band).
#[allow(clippy::too_many_arguments)]
fn blend_tile(
    rows: &mut [u8],
    row_bytes: usize,
    origin: (u32, u32),
    size: (u32, u32),
    list: &[u32],
    splats: &[Splat],
    background: [f32; 3],
    early_stop: f32,
) {
    const N: usize = (CPU_TILE * CPU_TILE) as usize;
    let w = (size.0 - origin.0).min(CPU_TILE);
    let h = (size.1 - origin.1).min(CPU_TILE);
    let mut colour = [[0.0f32; 3]; N];
    let mut transmittance = [1.0f32; N];
    let mut done = [false; N];
    let mut remaining = w * h;
    let (ox, oy) = (origin.0 as f32, origin.1 as f32);
    for &i in list {
        let s = &splats[i as usize];
        // Pixels of this tile whose centres lie in the square footprint.
        let x0 = ((s.x - s.radius - 0.5 - ox).ceil().max(0.0)) as u32;
        let x1 = (s.x + s.radius - 0.5 - ox).floor().min((w - 1) as f32);
        let y0 = ((s.y - s.radius - 0.5 - oy).ceil().max(0.0)) as u32;
        let y1 = (s.y + s.radius - 0.5 - oy).floor().min((h - 1) as f32);
        if x1 < x0 as f32 || y1 < y0 as f32 {
            continue;
        }
        let [a, b, c] = s.conic;
        for ly in y0..=y1 as u32 {
            let dy = oy + ly as f32 + 0.5 - s.y;
            for lx in x0..=x1 as u32 {
                let p = (ly * CPU_TILE + lx) as usize;
                if done[p] {
                    continue;
                }
                let dx = ox + lx as f32 + 0.5 - s.x;
                let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
                if power > 0.0 || power < s.cutoff {
                    continue;
                }
                let alpha = (s.opacity * power.exp()).min(MAX_ALPHA as f32);
                if alpha < MIN_ALPHA as f32 {
                    continue;
                }
                let t = transmittance[p];
                let next = t * (1.0 - alpha);
                if next < early_stop {
                    done[p] = true;
                    remaining -= 1;
                    continue;
                }
                let weight = alpha * t;
                for (out, rgb) in colour[p].iter_mut().zip(s.rgb) {
                    *out += rgb * weight;
                }
                transmittance[p] = next;
            }
        }
        if remaining == 0 {
            break;
        }
    }
    for ly in 0..h {
        for lx in 0..w {
            let p = (ly * CPU_TILE + lx) as usize;
            let k = ly as usize * row_bytes + (origin.0 + lx) as usize * 3;
            for ch in 0..3 {
                rows[k + ch] = quantize(colour[p][ch] + transmittance[p] * background[ch]);
            }
        }
    }
}
