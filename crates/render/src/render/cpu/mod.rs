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
mod lanes;
mod prefetch;
mod prepared;
mod project;
mod raster;

use std::time::Instant;

use rayon::prelude::*;

use self::colour::batch_bases;
use self::prepared::Prepared;
use self::project::{Projector, Splat, LANES};
use self::raster::{blend_tile, Tile, TILE_PIXELS};
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

/// The lanes the CPU renderer projects and blends in on this processor:
/// "AVX2", or "SSE2" where an x86-64 processor lacks AVX2 or
/// `VISAGE_SIMD=baseline` asks for them ("NEON" on 64-bit Arm, "scalar"
/// elsewhere, as `wide` compiles there).
pub fn lanes_in_use() -> &'static str {
    #[cfg(target_arch = "x86_64")]
    if lanes::avx2_enabled() {
        return "AVX2";
    }
    if cfg!(target_arch = "x86_64") {
        "SSE2"
    } else if cfg!(target_arch = "aarch64") {
        "NEON"
    } else {
        "scalar"
    }
}

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
            project_chunk_fastest(Chunk {
                projector: &projector,
                prepared,
                frames,
                degree,
                first: chunk * PROJECT_CHUNK,
                cores,
                splats,
                keys,
            });
        });
}

/// One parallel task of the projection: the frame's camera, Gaussians,
/// triangle frames (`None` for a world-space scene) and SH degree, and the
/// chunk's Gaussians `first..` (their records) and where their splats and
/// keys go.
struct Chunk<'a> {
    projector: &'a Projector,
    prepared: &'a Prepared,
    frames: Option<&'a [TriangleFrame]>,
    degree: u8,
    first: usize,
    cores: &'a [prepared::Core],
    splats: &'a mut [Splat],
    keys: &'a mut [TileKey],
}

/// [`project_chunk`] in the fastest lanes this processor has: one AVX
/// register where it has AVX2, two SSE2 halves elsewhere (the same bits).
fn project_chunk_fastest(chunk: Chunk) {
    #[cfg(target_arch = "x86_64")]
    if lanes::avx2_enabled() {
        // SAFETY: the processor has AVX2 (just checked).
        unsafe { project_chunk_avx2(chunk) };
        return;
    }
    project_chunk::<wide::f32x8>(chunk);
}

/// [`project_chunk`] in AVX lanes, compiled for AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2")]
unsafe fn project_chunk_avx2(chunk: Chunk) {
    project_chunk::<lanes::Avx>(chunk);
}

/// Projects a chunk's Gaussians a batch of [`LANES`] at a time, colours the
/// live ones and writes their sort keys (zero for culled ones). Inlined into
/// each caller, so that the AVX2 one compiles all of it for AVX2.
#[inline(always)]
fn project_chunk<L: lanes::Lanes>(chunk: Chunk) {
    let Chunk {
        projector,
        prepared,
        frames,
        degree,
        ..
    } = chunk;
    let batches = chunk
        .splats
        .chunks_mut(LANES)
        .zip(chunk.keys.chunks_mut(LANES))
        .zip(chunk.cores.chunks(LANES));
    for (batch, ((splats, keys), cores)) in batches.enumerate() {
        let first = chunk.first + batch * LANES;
        let projected = projector.project_batch::<L>(cores, frames, splats);
        if projected.live == 0 {
            keys.fill([0; 4]);
            continue;
        }
        let bases = batch_bases::<L>(&projected.from_eye, degree);
        for (lane, (splat, key)) in splats.iter_mut().zip(keys.iter_mut()).enumerate() {
            if projected.live & (1 << lane) == 0 {
                *key = [0; 4];
                continue;
            }
            splat.rgb = rgb_from_basis_f32(prepared.sh_of(first + lane), &bases[lane], degree);
            let [x0, y0, x1, y1] = splat.rect.map(u32::from);
            *key = [
                projected.depth[lane].to_bits(),
                pack_tile(x0 / CPU_TILE, y0 / CPU_TILE),
                pack_tile(x1 / CPU_TILE, y1 / CPU_TILE),
                1,
            ];
        }
    }
}

/// [`blend_tile`] in the fastest lanes this processor has (as
/// [`project_chunk_fastest`]).
fn blend_tile_fastest(tile: &Tile) -> [[u8; 3]; TILE_PIXELS] {
    #[cfg(target_arch = "x86_64")]
    if lanes::avx2_enabled() {
        // SAFETY: the processor has AVX2 (just checked).
        return unsafe { blend_tile_avx2(tile) };
    }
    blend_tile::<wide::f32x8>(tile)
}

/// [`blend_tile`] in AVX lanes, compiled for AVX2.
///
/// # Safety
/// The processor must have AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2")]
unsafe fn blend_tile_avx2(tile: &Tile) -> [[u8; 3]; TILE_PIXELS] {
    blend_tile::<lanes::Avx>(tile)
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
            let pixels = blend_tile_fastest(&Tile {
                origin: tile_origin(tile),
                size: (width, height),
                list: bins.tile(tile as usize),
                splats,
                background: settings.background,
                early_stop: settings.early_stop,
            });
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

#[cfg(test)]
mod tests {
    use glam::{Mat3, Quat, Vec3};
    use rand::{Rng, SeedableRng};

    use super::*;

    /// Every field of a splat, as bits.
    fn splat_bits(s: &Splat) -> Vec<u32> {
        let floats = [
            s.x, s.y, s.conic[0], s.conic[1], s.conic[2], s.inv_a, s.opacity, s.cutoff,
        ];
        let floats = floats.into_iter().chain(s.rgb).map(f32::to_bits);
        floats.chain(s.rect.map(u32::from)).collect()
    }

    /// The splats and keys of every Gaussian of `prepared`, projected in
    /// AVX lanes (`avx`) or `wide`'s SSE2 ones.
    fn project_everything(
        prepared: &Prepared,
        frames: Option<&[TriangleFrame]>,
        camera: &Camera,
        avx: bool,
    ) -> (Vec<Vec<u32>>, Vec<TileKey>) {
        let projector = Projector::new(camera, 1.0);
        let n = prepared.len();
        let (mut splats, mut keys) = (vec![Splat::default(); n], vec![[0; 4]; n]);
        let chunk = Chunk {
            projector: &projector,
            prepared,
            frames,
            degree: 3,
            first: 0,
            cores: &prepared.core,
            splats: &mut splats,
            keys: &mut keys,
        };
        if avx {
            #[cfg(target_arch = "x86_64")]
            // SAFETY: only asked for where the processor has AVX2.
            unsafe {
                project_chunk_avx2(chunk)
            };
        } else {
            project_chunk::<wide::f32x8>(chunk);
        }
        (splats.iter().map(splat_bits).collect(), keys)
    }

    /// The projection in AVX lanes gives the splats, colours and keys of
    /// the SSE2 lanes bit for bit, on hard Gaussians (behind the camera and
    /// at it, needles, huge and zero scales, zero quaternions, zero opacity,
    /// NaN and infinite positions and coefficients), in world space and on a
    /// triangle's frame. Without AVX2 there is nothing to compare.
    #[test]
    fn the_projection_gives_the_same_bits_in_avx_and_sse2_lanes() {
        #[cfg(target_arch = "x86_64")]
        let avx2 = std::is_x86_feature_detected!("avx2");
        #[cfg(not(target_arch = "x86_64"))]
        let avx2 = false;
        if !avx2 {
            eprintln!("no AVX2 on this processor: only the SSE2 lanes exist here");
            return;
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let camera = project::test_camera();
        let mut scene = SplatScene::with_degree(3);
        for i in 0..6_000 {
            let mut position = Vec3::new(
                rng.random_range(-6.0..6.0),
                rng.random_range(-6.0..6.0),
                rng.random_range(-6.0..6.0),
            );
            let mut scale = Vec3::new(
                10f32.powf(rng.random_range(-6.0..1.0)),
                10f32.powf(rng.random_range(-6.0..1.0)),
                10f32.powf(rng.random_range(-6.0..1.0)),
            );
            let mut rotation = Quat::from_xyzw(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let mut opacity = rng.random_range(0.0..1.0);
            let mut sh: Vec<f32> = (0..48).map(|_| rng.random_range(-1.0..1.0)).collect();
            match i % 40 {
                0 => position = Vec3::new(f32::NAN, 0.0, 0.0),
                1 => position = Vec3::splat(f32::INFINITY),
                2 => scale = Vec3::ZERO,
                3 => scale = Vec3::splat(1e4),
                4 => rotation = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
                5 => opacity = 0.0,
                6 => sh[7] = f32::NAN,
                7 => sh[30] = f32::INFINITY,
                8 => position = camera.eye,
                9 => scale = Vec3::new(1.0, 1e-7, 1e-7),
                _ => {}
            }
            scene.push(position, rotation, scale, opacity, &sh);
        }
        let prepared = Prepared::of_scene(&scene);
        let quat = Quat::from_axis_angle(Vec3::new(0.3, 1.0, -0.2).normalize(), 0.8);
        let frame = [TriangleFrame {
            center: Vec3::new(0.1, -0.2, 0.3),
            rotation: Mat3::from_quat(quat),
            quat,
            scale: 0.7,
        }];
        for frames in [None, Some(&frame[..])] {
            let (sse, sse_keys) = project_everything(&prepared, frames, &camera, false);
            let (avx, avx_keys) = project_everything(&prepared, frames, &camera, true);
            let live = sse_keys.iter().filter(|k| k[3] == 1).count();
            assert!(
                live > 500,
                "only {live} Gaussians in view: the test proves little"
            );
            for (i, (key, other)) in sse_keys.iter().zip(&avx_keys).enumerate() {
                assert_eq!(key, other, "Gaussian {i}'s key");
                if key[3] == 1 {
                    assert_eq!(sse[i], avx[i], "Gaussian {i}'s splat");
                }
            }
        }
    }
}
