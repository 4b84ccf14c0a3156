//! The fast CPU splat renderer, for machines whose only Vulkan device is a
//! software one. Mesa's lavapipe runs the wgpu kernels correctly but pays ~7 ns
//! per tile-list entry per pixel (measured with `visage bench render`); this path
//! visits each entry once per tile and touches only the pixels its footprint
//! covers, so the same frame costs a fraction of that.
//!
//! A frame's cost follows what is visible. What no frame changes is prepared
//! once per upload (`prepared.rs`: each Gaussian's covariance factor in its
//! triangle's frame, its opacity and reach, in one 64-byte record); a frame
//! places centres, culls what cannot touch the image before any covariance
//! work, and projects the rest in f32 (`project.rs`); colour is evaluated only
//! for survivors. The depth sort is a parallel radix sort and the binning is
//! parallel (the same lists as a serial stable sort), tiles are rasterised one
//! task each (`raster.rs`), entries whose footprint is already saturated are
//! skipped, and a tile stops once every pixel in it is saturated.

mod colour;
mod fastmath;
mod prefetch;
mod prepared;
mod project;
mod raster;

use std::time::Instant;

use rayon::prelude::*;

use self::colour::batch_bases;
use self::prepared::Prepared;
use self::project::{Projector, Splat, LANES};
use self::raster::{blend_tile, TILE_PIXELS};
use super::image::RgbImage;
use super::settings::{RenderSettings, StageTimings};
use super::sh::rgb_from_basis_f32;
use super::tiles::{pack_tile, TileBins, TileKey};
use crate::avatar::binding::TriangleFrame;
use crate::avatar::gaussians::GaussianSet;
use crate::error::{Error, Result};
use crate::scene::camera::Camera;
use crate::scene::splats::{SplatScene, IDENTITY_FRAME};

pub use self::raster::CPU_TILE;

/// The largest image side the CPU renderer draws (footprints are kept in
/// 16-bit pixel coordinates).
pub const MAX_SIDE: u32 = 1 << 16;

/// The CPU renderer; same interface as the GPU one.
#[derive(Default)]
pub struct CpuRenderer {
    prepared: Option<Prepared>,
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
        self.prepared = Some(Prepared::of_set(set));
    }

    /// Keeps a world-space scene to render on the identity frame, straight
    /// from its scales and opacities (no round trip through logs).
    pub fn set_world_scene(&mut self, scene: &SplatScene) {
        self.prepared = Some(Prepared::of_scene(scene));
    }

    /// Renders the Gaussians placed on `frames` (one per triangle).
    pub fn render(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let (prepared, (width, height)) =
            super::frame_inputs(self.prepared.as_ref(), frames, camera)?;
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(Error::input(format!(
                "a {width}x{height} image is larger than the CPU renderer's {MAX_SIDE} pixels a side"
            )));
        }
        let tiles = (width.div_ceil(CPU_TILE), height.div_ceil(CPU_TILE));
        let mut timings = StageTimings::default();

        let t = Instant::now();
        project_all(
            prepared,
            frames,
            camera,
            settings,
            &mut self.splats,
            &mut self.keys,
        );
        timings.project = ms(t);

        let t = Instant::now();
        self.bins.bin(&self.keys, tiles, settings.sort_bits);
        timings.sort = ms(t);

        let t = Instant::now();
        let image = rasterize(&self.splats, &self.bins, (width, height), settings);
        timings.rasterize = ms(t);
        self.timings = timings;
        Ok(image)
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Gaussians per parallel task of the projection (a multiple of [`LANES`]).
const PROJECT_CHUNK: usize = 4096;

/// Projects every Gaussian into `splats` and writes its sort key (zero for
/// culled ones) into `keys`.
fn project_all(
    prepared: &Prepared,
    frames: &[TriangleFrame],
    camera: &Camera,
    settings: &RenderSettings,
    splats: &mut Vec<Splat>,
    keys: &mut Vec<TileKey>,
) {
    let projector = Projector::new(camera, settings.scale_modifier);
    let degree = settings.sh_degree.min(prepared.sh_degree);
    let n = prepared.len();
    splats.resize(n, Splat::default());
    keys.resize(n, [0; 4]);
    let world_space = frames.len() == 1 && frames[0] == IDENTITY_FRAME;
    let frames = (!world_space).then_some(frames);
    splats
        .par_chunks_mut(PROJECT_CHUNK)
        .zip(keys.par_chunks_mut(PROJECT_CHUNK))
        .zip(prepared.core.par_chunks(PROJECT_CHUNK))
        .enumerate()
        .for_each(|(chunk, ((splats, keys), cores))| {
            let batches = splats
                .chunks_mut(LANES)
                .zip(keys.chunks_mut(LANES))
                .zip(cores.chunks(LANES));
            for (batch, ((splats, keys), cores)) in batches.enumerate() {
                let first = chunk * PROJECT_CHUNK + batch * LANES;
                let projected = projector.project_batch(cores, frames, splats);
                if projected.live == 0 {
                    keys.fill([0; 4]);
                    continue;
                }
                let bases = batch_bases(&projected.from_eye, degree);
                for (lane, (splat, key)) in splats.iter_mut().zip(keys.iter_mut()).enumerate() {
                    if projected.live & (1 << lane) == 0 {
                        *key = [0; 4];
                        continue;
                    }
                    splat.rgb =
                        rgb_from_basis_f32(prepared.sh_of(first + lane), &bases[lane], degree);
                    let [x0, y0, x1, y1] = splat.rect.map(u32::from);
                    *key = [
                        projected.depth[lane].to_bits(),
                        pack_tile(x0 / CPU_TILE, y0 / CPU_TILE),
                        pack_tile(x1 / CPU_TILE, y1 / CPU_TILE),
                        1,
                    ];
                }
            }
        });
}

/// Blends every tile (one task each: tiles cost very different amounts, each
/// into its own small buffer) and assembles the image; a tile blends
/// `splats` in the order of its list in `bins`.
fn rasterize(
    splats: &[Splat],
    bins: &TileBins,
    (width, height): (u32, u32),
    settings: &RenderSettings,
) -> RgbImage {
    let tiles = (width.div_ceil(CPU_TILE), height.div_ceil(CPU_TILE));
    let tile_origin = |tile: u32| ((tile % tiles.0) * CPU_TILE, (tile / tiles.0) * CPU_TILE);
    // Longest lists first, one task each: a tile's cost follows its list,
    // and a long tile started last would leave the other cores idle.
    let mut order: Vec<u32> = (0..tiles.0 * tiles.1).collect();
    order.sort_by_key(|&tile| std::cmp::Reverse(bins.tile(tile as usize).len()));
    let tile_pixels: Vec<(u32, [[u8; 3]; TILE_PIXELS])> = order
        .into_par_iter()
        .with_max_len(1)
        .map(|tile| {
            let pixels = blend_tile(
                tile_origin(tile),
                (width, height),
                bins.tile(tile as usize),
                splats,
                settings.background,
                settings.early_stop,
            );
            (tile, pixels)
        })
        .collect();
    let mut rgb = vec![0u8; (width * height * 3) as usize];
    let row_bytes = (width * 3) as usize;
    for (tile, pixels) in &tile_pixels {
        let (x0, y0) = tile_origin(*tile);
        let w = (width - x0).min(CPU_TILE) as usize;
        for ly in 0..(height - y0).min(CPU_TILE) as usize {
            let at = (y0 as usize + ly) * row_bytes + x0 as usize * 3;
            for (lx, px) in pixels[ly * CPU_TILE as usize..][..w].iter().enumerate() {
                rgb[at + 3 * lx..at + 3 * lx + 3].copy_from_slice(px);
            }
        }
    }
    RgbImage {
        width,
        height,
        pixels: rgb,
    }
}
