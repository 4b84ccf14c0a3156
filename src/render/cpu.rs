//! The fast CPU splat renderer, for machines whose only Vulkan device is a
//! software one. Mesa's lavapipe runs the wgpu kernels correctly but pays ~7 ns
//! per tile-list entry per pixel (measured with `visage bench render`); this path
//! visits each entry once per tile and touches only the pixels its footprint
//! covers, so the same frame costs a fraction of that.
//!
//! Numerics are those of the reference (`projection.rs`: projection in f64),
//! with SH colour and blending in f32 and the same depth sort and tile binning as the GPU
//! path. What no frame changes is prepared once per upload (each Gaussian's
//! covariance in its triangle's frame, its opacity), so a frame only places
//! centres, turns covariances by the triangle frames and projects; the centre
//! comes first, so Gaussians behind the camera cost nothing more. The sort and
//! binning run in parallel (the same lists as a serial stable sort), tiles are
//! rasterised one task each, entries whose footprint is already saturated are
//! skipped, and a tile stops once every pixel in it is saturated.

use std::time::Instant;

use rayon::prelude::*;

use super::image::{quantize, RgbImage};
use super::projection::{ProjectionCamera, MAX_ALPHA, MIN_ALPHA};
use super::settings::RenderSettings;
use super::settings::StageTimings;
use super::sh::eval_rgb_f32;
use super::tiles::{pack_tile, TileBins, TileKey};
use crate::avatar::binding::TriangleFrame;
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

/// What a Gaussian's projection needs that no frame changes, prepared once
/// per upload: its covariance in its triangle's frame (R S Sᵀ Rᵀ of the local
/// rotation and scale, upper triangle) and its opacity after the sigmoid.
#[derive(Clone, Copy, Debug, Default)]
struct Prepared {
    cov_local: [f32; 6],
    opacity: f32,
}

impl Prepared {
    fn of(set: &GaussianSet, i: usize) -> Self {
        let r = glam::Mat3::from_quat(crate::avatar::binding::normalize_quat(set.rotation[i]));
        let m = r * glam::Mat3::from_diagonal(set.log_scale[i].exp());
        let c = m * m.transpose();
        Self {
            cov_local: [
                c.x_axis.x, c.y_axis.x, c.z_axis.x, c.y_axis.y, c.z_axis.y, c.z_axis.z,
            ],
            opacity: sigmoid(set.opacity_logit[i]).min(1.0),
        }
    }

    /// The world covariance on a triangle frame: (k R) Σ (k R)ᵀ.
    fn cov_world(&self, frame: &TriangleFrame, scale_modifier: f32) -> glam::DMat3 {
        let [xx, xy, xz, yy, yz, zz] = self.cov_local.map(f64::from);
        let local = glam::DMat3::from_cols_array(&[xx, xy, xz, xy, yy, yz, xz, yz, zz]);
        let k = f64::from(frame.scale) * f64::from(scale_modifier);
        let r = frame.rotation.as_dmat3() * k;
        r * local * r.transpose()
    }
}

/// The CPU renderer; same interface as the GPU one.
#[derive(Default)]
pub struct CpuRenderer {
    set: Option<GaussianSet>,
    prepared: Vec<Prepared>,
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

    /// Gaussians that survived culling in the last frame.
    pub fn visible(&self) -> usize {
        self.keys.par_iter().filter(|k| k[3] == 1).count()
    }

    /// Keeps the Gaussians to render (call when the selection changes).
    pub fn set_gaussians(&mut self, set: &GaussianSet) {
        self.prepared = (0..set.len())
            .into_par_iter()
            .map(|i| Prepared::of(set, i))
            .collect();
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
        let prepared = &self.prepared;
        self.splats
            .par_iter_mut()
            .zip(self.keys.par_iter_mut())
            .enumerate()
            .with_min_len(1024)
            .for_each(|(i, (splat, key))| {
                *key = [0; 4];
                let frame = &frames[(set.binding[i] as usize).min(last_frame)];
                let opacity = prepared[i].opacity;
                // Centre first: what is behind the camera costs nothing more.
                let position = frame.scale * (frame.rotation * set.position[i]) + frame.center;
                if opacity.is_nan() || opacity <= 0.0 || !position.is_finite() {
                    return;
                }
                let cov = prepared[i].cov_world(frame, settings.scale_modifier);
                let Some(s) = cam.project_covariance(position, cov, opacity as f64) else {
                    return;
                };
                let Some((x0, y0, x1, y1)) = s.pixel_rect(width, height) else {
                    return;
                };
                let dir = (position - cam.eye.as_vec3()).normalize_or_zero();
                let rgb = eval_rgb_f32(set.sh_of(i), degree, dir.to_array());
                *splat = Splat {
                    x: s.center[0] as f32,
                    y: s.center[1] as f32,
                    radius: s.radius as f32,
                    conic: s.conic.map(|c| c as f32),
                    opacity,
                    cutoff: ((MIN_ALPHA / opacity as f64).ln() - 1e-6) as f32,
                    rgb,
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
        let (splats, bins) = (&self.splats, &self.bins);
        let background = settings.background;
        let early_stop = settings.early_stop;
        // One task per tile (tiles cost very different amounts), each into its
        // own small buffer; the image is assembled after.
        let tile_pixels: Vec<[[u8; 3]; TILE_PIXELS]> = (0..tiles.0 * tiles.1)
            .into_par_iter()
            .map(|tile| {
                let origin = ((tile % tiles.0) * CPU_TILE, (tile / tiles.0) * CPU_TILE);
                blend_tile(
                    origin,
                    (width, height),
                    bins.tile(tile as usize),
                    splats,
                    background,
                    early_stop,
                )
            })
            .collect();
        let row_bytes = (width * 3) as usize;
        for (tile, pixels) in tile_pixels.iter().enumerate() {
            let (x0, y0) = (
                (tile as u32 % tiles.0) * CPU_TILE,
                (tile as u32 / tiles.0) * CPU_TILE,
            );
            let w = (width - x0).min(CPU_TILE) as usize;
            for ly in 0..(height - y0).min(CPU_TILE) as usize {
                let at = (y0 as usize + ly) * row_bytes + x0 as usize * 3;
                for (lx, px) in pixels[ly * CPU_TILE as usize..][..w].iter().enumerate() {
                    rgba[at + 3 * lx..at + 3 * lx + 3].copy_from_slice(px);
                }
            }
        }
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

/// Pixels of one tile.
const TILE_PIXELS: usize = (CPU_TILE * CPU_TILE) as usize;

/// Blends one tile front to back; returns its pixels, row-major (CPU_TILE wide).
fn blend_tile(
    origin: (u32, u32),
    size: (u32, u32),
    list: &[u32],
    splats: &[Splat],
    background: [f32; 3],
    early_stop: f32,
) -> [[u8; 3]; TILE_PIXELS] {
    const N: usize = (CPU_TILE * CPU_TILE) as usize;
    let w = (size.0 - origin.0).min(CPU_TILE);
    let h = (size.1 - origin.1).min(CPU_TILE);
    let mut colour = [[0.0f32; 3]; N];
    let mut transmittance = [1.0f32; N];
    // Saturated pixels, one bit a pixel, a word a row: an entry whose whole
    // footprint is saturated is skipped without touching its pixels.
    let mut done = [0u16; CPU_TILE as usize];
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
        let row_mask = (((1u32 << (x1 as u32 - x0 + 1)) - 1) << x0) as u16;
        if (y0..=y1 as u32).all(|ly| done[ly as usize] & row_mask == row_mask) {
            continue;
        }
        let [a, b, c] = s.conic;
        for ly in y0..=y1 as u32 {
            let dy = oy + ly as f32 + 0.5 - s.y;
            for lx in x0..=x1 as u32 {
                let p = (ly * CPU_TILE + lx) as usize;
                if done[ly as usize] & (1 << lx) != 0 {
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
                    done[ly as usize] |= 1 << lx;
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
    let mut out = [[0u8; 3]; TILE_PIXELS];
    for ly in 0..h {
        for lx in 0..w {
            let p = (ly * CPU_TILE + lx) as usize;
            out[p] = std::array::from_fn(|ch| {
                quantize(colour[p][ch] + transmittance[p] * background[ch])
            });
        }
    }
    out
}
