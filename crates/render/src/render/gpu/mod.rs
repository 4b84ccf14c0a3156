//! The offscreen splat renderer on wgpu compute (docs/method.md §8), running on any Vulkan,
//! Metal or DX12 device and on Mesa's lavapipe where there is no GPU.
//!
//! Stages per frame: upload the triangle frames (the Gaussians only when the
//! selection changes) → `bind` (local → world) → `project` (cull, 2D covariance,
//! SH colour, depth, touched tiles) → depth sort and tile binning on the GPU
//! ([`binning`]: radix sorts, prefix sums; 4 bytes read back) →
//! `rasterize` (per 16×16 tile, front to back, early termination) → read back RGBA8.

use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};
use rayon::prelude::*;
use wgpu::util::DeviceExt;

use super::image::RgbImage;
use super::settings::{RenderSettings, StageTimings};
use crate::avatar::binding::TriangleFrame;
use crate::avatar::gaussians::{logit, GaussianSet};
use crate::error::{Error, Result};
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;
use binning::GpuBinning;
use device::{
    describe_adapter, element_grid, guarded, map_and_read, open_device, wait, Growable, OpenDevice,
};
use kernels::{Bind, PackRgb, Project, TileRasterizer};

pub mod binning;
pub mod constants;
pub mod device;
pub mod kernels;

use constants::OPACITY_LITERAL;
pub use constants::TILE;

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct CameraUniform {
    view: [[f32; 4]; 4],
    position: [f32; 4],
    intrinsics: [f32; 4],
    limits: [f32; 4],
    size: [u32; 4],
    counts: [u32; 4],
    extra: [f32; 4],
    tuning: [f32; 4],
}

struct SceneBuffers {
    count: u32,
    sh_degree: u8,
    /// The degree the uploaded set carried (more than `sh_degree` when the
    /// device could not bind all of it).
    stored_sh_degree: u8,
    sh_stride: u32,
    /// Gaussians whose SH is in `sh`; the rest are in `sh_rest`.
    sh_split: u32,
    local: wgpu::Buffer,
    sh: wgpu::Buffer,
    sh_rest: wgpu::Buffer,
    world: wgpu::Buffer,
    projected: wgpu::Buffer,
    keys: wgpu::Buffer,
}

/// The bind kernel's code for an opacity (a logit up to 1, above 1 the
/// literal form of [`constants::OPACITY_LITERAL`]).
fn opacity_code(opacity: f32) -> f32 {
    if opacity > 1.0 {
        OPACITY_LITERAL - 1.0 + opacity
    } else {
        logit(opacity).min(OPACITY_LITERAL)
    }
}

/// The wgpu splat renderer. Create once; call [`GpuRenderer::set_gaussians`] when
/// the selection changes and [`GpuRenderer::render`] per frame.
pub struct GpuRenderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    adapter: wgpu::AdapterInfo,
    limits: wgpu::Limits,
    bind: Bind,
    project: Project,
    rasterize: TileRasterizer,
    pack_rgb: PackRgb,
    camera: wgpu::Buffer,
    scene: Option<SceneBuffers>,
    frames: Growable,
    binning: GpuBinning,
    image: Growable,
    packed: Growable,
    image_readback: Growable,
    /// Pixels of the last frame whose walk a driver cut short (read back
    /// after the image).
    cut_short: wgpu::Buffer,
    /// The frames `scene.world` was last bound on: a world scene's never
    /// change, so after its first frame only the camera's work is redone.
    bound_frames: Option<Vec<TriangleFrame>>,
    /// Times the bind kernel ran (for tests).
    bind_dispatches: u64,
    /// Timings of the last frame.
    pub timings: StageTimings,
    /// Wait for the device after every stage so `timings` attribute GPU time to
    /// the right stage (costs a round trip per stage; off for normal frames).
    pub profile_stages: bool,
    /// The largest SH binding, when smaller than the device's (tests make
    /// a small scene need both SH bindings this way).
    sh_binding_limit: Option<u64>,
}

impl GpuRenderer {
    /// Opens the first suitable adapter (a real GPU when present, lavapipe
    /// otherwise) and compiles the kernels.
    pub fn new() -> Result<Self> {
        pollster::block_on(Self::open(true))?
            .ok_or_else(|| Error::device("no graphics adapter found"))
    }

    /// Opens a hardware adapter only: `Ok(None)` when the best adapter is a
    /// software one (no shaders are compiled then).
    pub fn new_hardware() -> Result<Option<Self>> {
        pollster::block_on(Self::open(false))
    }

    async fn open(allow_software: bool) -> Result<Option<Self>> {
        let Some(OpenDevice {
            device,
            queue,
            adapter,
            limits,
        }) = open_device(allow_software).await?
        else {
            return Ok(None);
        };
        let (bind, project) = (Bind::new(&device), Project::new(&device));
        let software = adapter.device_type == wgpu::DeviceType::Cpu;
        let rasterize = TileRasterizer::for_adapter(&device, software);
        let pack_rgb = PackRgb::new(&device);
        let binning = GpuBinning::new(&device);
        let camera = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("camera"),
            size: std::mem::size_of::<CameraUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let frames = Growable::new(&device, "frames", storage);
        // COPY_SRC: the kernel tests read the RGBA image back.
        let image = Growable::new(
            &device,
            "image",
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let packed = Growable::new(
            &device,
            "packed image",
            wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let image_readback = Growable::new(
            &device,
            "image read-back",
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let cut_short = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("walks cut short"),
            size: 4,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Ok(Some(Self {
            adapter,
            limits,
            device,
            queue,
            bind,
            project,
            rasterize,
            pack_rgb,
            camera,
            scene: None,
            frames,
            binning,
            image,
            packed,
            image_readback,
            cut_short,
            bound_frames: None,
            bind_dispatches: 0,
            sh_binding_limit: None,
            timings: StageTimings::default(),
            profile_stages: false,
        }))
    }

    /// Why the uploaded Gaussians are drawn with fewer SH bands than they
    /// carry, when they are: the device binds less than their coefficients.
    pub fn sh_notice(&self) -> Option<String> {
        let scene = self.scene.as_ref()?;
        (scene.sh_degree < scene.stored_sh_degree).then(|| {
            format!(
                "SH degree {} of {}: {} Gaussians' coefficients exceed this device's largest storage binding ({} MiB)",
                scene.sh_degree,
                scene.stored_sh_degree,
                scene.count,
                self.limits.max_storage_buffer_binding_size >> 20
            )
        })
    }

    /// Name, driver and type of the adapter in use.
    pub fn adapter_description(&self) -> String {
        describe_adapter(&self.adapter)
    }

    /// The device and queue, for tests of single stages.
    #[cfg(test)]
    pub(super) fn device_and_queue(&self) -> (&wgpu::Device, &wgpu::Queue) {
        (&self.device, &self.queue)
    }

    /// True when rendering on a CPU (software) adapter such as lavapipe.
    pub fn is_software(&self) -> bool {
        self.adapter.device_type == wgpu::DeviceType::Cpu
    }

    /// Uploads triangle-bound Gaussians (call when the selection changes). SH above
    /// what fits the device's largest storage binding is truncated.
    pub fn set_gaussians(&mut self, set: &GaussianSet) -> Result<()> {
        let local = local_records(set.len(), |i| {
            (
                set.position[i],
                set.binding[i],
                set.rotation[i],
                set.log_scale[i],
                set.opacity_logit[i].min(OPACITY_LITERAL),
            )
        });
        self.upload(&local, &set.sh, set.sh_degree)
    }

    /// Uploads a world-space scene (drawn on the identity frame) straight
    /// from its arrays: the records are made in parallel and its SH is
    /// uploaded from the scene itself, not from a converted copy.
    pub fn set_world_scene(&mut self, scene: &SplatScene) -> Result<()> {
        let local = local_records(scene.len(), |i| {
            (
                scene.position[i],
                0,
                scene.rotation[i],
                scene.scale[i].max(Vec3::splat(1e-30)).ln(),
                opacity_code(scene.opacity[i]),
            )
        });
        self.upload(&local, &scene.sh, scene.sh_degree)
    }

    /// Makes the scene's buffers from its records (12 floats a Gaussian)
    /// and its SH of degree `stored_degree`.
    fn upload(&mut self, local: &[f32], all_sh: &[f32], stored_degree: u8) -> Result<()> {
        let device = self.device.clone();
        guarded(&device, "uploading the Gaussians", || {
            self.upload_unguarded(local, all_sh, stored_degree)
        })
    }

    fn upload_unguarded(&mut self, local: &[f32], all_sh: &[f32], stored_degree: u8) -> Result<()> {
        let n = local.len() / 12;
        let max_binding = self.limits.max_storage_buffer_binding_size;
        let sh_binding = self
            .sh_binding_limit
            .unwrap_or(max_binding)
            .min(max_binding);
        let degree = sh_degree_that_fits(n, stored_degree, sh_binding);
        if (n as u64) * 48 > max_binding {
            return Err(Error::device(format!(
                "{n} Gaussians do not fit this device's largest storage buffer ({max_binding} bytes); try --lod auto or --renderer cpu"
            )));
        }
        let stride = 3 * (degree as usize + 1).pow(2);
        let sh = sh_up_to_degree(all_sh, stored_degree, degree);
        let split = gaussians_per_binding(sh_binding, degree).min(n as u64) as usize;
        let (sh_first, sh_rest) = sh.split_at(split * stride);
        let storage = wgpu::BufferUsages::STORAGE;
        let init = |label, contents: &[u8], usage| {
            self.device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(label),
                    contents: if contents.is_empty() {
                        &[0u8; 16]
                    } else {
                        contents
                    },
                    usage,
                })
        };
        let empty = |label, size: u64, usage| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        self.bound_frames = None;
        self.scene = Some(SceneBuffers {
            count: n as u32,
            sh_degree: degree,
            stored_sh_degree: stored_degree,
            sh_stride: stride as u32,
            sh_split: split as u32,
            local: init("local gaussians", bytemuck::cast_slice(local), storage),
            sh: init("sh", bytemuck::cast_slice(sh_first), storage),
            sh_rest: init("sh, the rest", bytemuck::cast_slice(sh_rest), storage),
            // COPY_SRC: the kernel tests read it back.
            world: empty(
                "world gaussians",
                n as u64 * 48,
                storage | wgpu::BufferUsages::COPY_SRC,
            ),
            projected: empty("projected", n as u64 * 48, storage),
            keys: empty(
                "keys",
                n as u64 * 16,
                storage | wgpu::BufferUsages::COPY_SRC,
            ),
        });
        Ok(())
    }

    /// Writes the triangle frames for the bind kernel into `buffer`.
    fn upload_frames(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        buffer: &mut Growable,
        frames: &[TriangleFrame],
    ) {
        let mut frame_data = Vec::with_capacity(frames.len() * 20);
        for f in frames {
            let r = f.rotation;
            frame_data.extend_from_slice(&[r.x_axis.x, r.x_axis.y, r.x_axis.z, f.scale]);
            frame_data.extend_from_slice(&[r.y_axis.x, r.y_axis.y, r.y_axis.z, 0.0]);
            frame_data.extend_from_slice(&[r.z_axis.x, r.z_axis.y, r.z_axis.z, 0.0]);
            frame_data.extend_from_slice(&[f.center.x, f.center.y, f.center.z, 0.0]);
            frame_data.extend_from_slice(&[f.quat.w, f.quat.x, f.quat.y, f.quat.z]);
        }
        buffer.ensure(device, frame_data.len() as u64 * 4);
        queue.write_buffer(&buffer.buffer, 0, bytemuck::cast_slice(&frame_data));
    }

    /// Renders the uploaded Gaussians placed on `frames` (one per triangle).
    pub fn render(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let device = self.device.clone();
        guarded(&device, "drawing a frame", || {
            self.render_unguarded(frames, camera, settings)
        })
    }

    fn render_unguarded(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let (scene, (width, height)) = super::frame_inputs(self.scene.as_ref(), frames, camera)?;
        let tiles = (width.div_ceil(TILE), height.div_ceil(TILE));
        let mut timings = StageTimings::default();

        // Upload: camera and frames.
        let t = Instant::now();
        let uniform = camera_uniform(camera, settings, scene, frames.len() as u32, tiles);
        self.queue
            .write_buffer(&self.camera, 0, bytemuck::bytes_of(&uniform));
        let rebind = self.bound_frames.as_deref() != Some(frames);
        if rebind {
            Self::upload_frames(&self.device, &self.queue, &mut self.frames, frames);
        }
        timings.upload = ms(t);

        // bind + project, then read the keys back.
        let t = Instant::now();
        let n = scene.count;
        let groups = element_grid(n, self.binning.grid_columns);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let camera = self.camera.as_entire_buffer_binding();
            if rebind {
                self.bind.dispatch(
                    &self.device,
                    &mut pass,
                    camera.clone(),
                    &scene.local,
                    &self.frames.buffer,
                    &scene.world,
                    groups,
                );
            }
            self.project.dispatch(
                &self.device,
                &mut pass,
                camera,
                &scene.world,
                &scene.sh,
                &scene.sh_rest,
                &scene.projected,
                &scene.keys,
                groups,
            );
        }
        self.queue.submit([encoder.finish()]);
        if rebind {
            self.bound_frames = Some(frames.to_vec());
            self.bind_dispatches += 1;
        }
        if self.profile_stages {
            wait(&self.device)?;
        }
        timings.project = ms(t);

        // Depth sort and tile binning on the GPU.
        let t = Instant::now();
        self.binning.bin(
            &self.device,
            &self.queue,
            &scene.keys,
            n,
            tiles,
            settings.sort_bits,
        )?;
        if self.profile_stages {
            wait(&self.device)?;
        }
        timings.sort = ms(t);

        // Rasterise.
        let t = Instant::now();
        let image_bytes = width as u64 * height as u64 * 4;
        let rgb_bytes = width as u64 * height as u64 * 3;
        let packed_bytes = rgb_bytes.next_multiple_of(4);
        self.image.ensure(&self.device, image_bytes);
        self.packed.ensure(&self.device, packed_bytes);
        // The image, then the count of walks cut short.
        self.image_readback.ensure(&self.device, packed_bytes + 4);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&self.cut_short, 0, None);
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let camera = self.camera.as_entire_buffer_binding();
            self.rasterize.dispatch(
                &self.device,
                &mut pass,
                camera.clone(),
                &scene.projected,
                &self.binning.ranges.buffer,
                self.binning.list(),
                &self.image.buffer,
                &self.cut_short,
                tiles,
            );
            self.pack_rgb.dispatch(
                &self.device,
                &mut pass,
                camera,
                &self.image.buffer,
                &self.packed.buffer,
                element_grid((packed_bytes / 4) as u32, self.binning.grid_columns),
            );
        }
        encoder.copy_buffer_to_buffer(
            &self.packed.buffer,
            0,
            &self.image_readback.buffer,
            0,
            packed_bytes,
        );
        encoder.copy_buffer_to_buffer(
            &self.cut_short,
            0,
            &self.image_readback.buffer,
            packed_bytes,
            4,
        );
        self.queue.submit([encoder.finish()]);
        wait(&self.device)?;
        timings.rasterize = ms(t);

        // Read back: the packed RGB bytes are the image.
        let t = Instant::now();
        let mut pixels = vec![0u8; rgb_bytes as usize];
        let mut cut_short = 0;
        map_and_read(
            &self.device,
            &self.image_readback.buffer,
            packed_bytes + 4,
            |bytes| {
                pixels.copy_from_slice(&bytes[..rgb_bytes as usize]);
                let tail = &bytes[packed_bytes as usize..];
                cut_short = u32::from_le_bytes([tail[0], tail[1], tail[2], tail[3]]);
            },
        )?;
        timings.readback = ms(t);
        if cut_short > 0 {
            // llvmpipe ends an invocation's loops after 65,535 iterations in
            // all; such pixels would silently show too much background.
            return Err(Error::device(format!(
                "{} stopped {cut_short} pixels' walks along their tile lists short (a dense scene: a tile lists more Gaussians than the driver lets one shader loop visit); render it with the CPU renderer (--renderer cpu)",
                describe_adapter(&self.adapter)
            )));
        }
        self.timings = timings;
        Ok(RgbImage {
            width,
            height,
            pixels,
        })
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn camera_uniform(
    camera: &Camera,
    settings: &RenderSettings,
    scene: &SceneBuffers,
    triangles: u32,
    tiles: (u32, u32),
) -> CameraUniform {
    let view = camera.view();
    let (fx, fy) = camera.focal_px();
    let (w, h) = (camera.width as f32, camera.height as f32);
    let guard = super::projection::FRUSTUM_GUARD as f32;
    CameraUniform {
        view: view.to_cols_array_2d(),
        position: camera.eye.extend(0.0).to_array(),
        intrinsics: [fx, fy, 0.5 * w, 0.5 * h],
        limits: [
            guard * 0.5 * w / fx,
            guard * 0.5 * h / fy,
            camera.near,
            camera.far,
        ],
        size: [camera.width, camera.height, tiles.0, tiles.1],
        counts: [
            scene.count,
            settings.sh_degree.min(scene.sh_degree) as u32,
            scene.sh_stride,
            triangles,
        ],
        extra: [
            settings.scale_modifier,
            settings.background[0],
            settings.background[1],
            settings.background[2],
        ],
        tuning: [
            settings.early_stop.clamp(0.0, 1.0),
            f32::from_bits(scene.sh_split),
            0.0,
            0.0,
        ],
    }
}

/// The bind kernel's input, 12 floats a Gaussian: position and binding
/// (its bits), rotation (w, x, y, z), log scale and opacity logit; made in
/// parallel from what `gaussian(i)` gives.
fn local_records(
    count: usize,
    gaussian: impl Fn(usize) -> (Vec3, u32, Quat, Vec3, f32) + Sync,
) -> Vec<f32> {
    let mut local = vec![0.0f32; count * 12];
    local
        .par_chunks_mut(12)
        .enumerate()
        .for_each(|(i, record)| {
            let (p, binding, q, s, opacity_logit) = gaussian(i);
            record.copy_from_slice(&[
                p.x,
                p.y,
                p.z,
                f32::from_bits(binding),
                q.w,
                q.x,
                q.y,
                q.z,
                s.x,
                s.y,
                s.z,
                opacity_logit,
            ]);
        });
    local
}

/// Each Gaussian's SH coefficients up to `degree` (of the `stored` degree
/// they carry): the slice itself when nothing is dropped.
fn sh_up_to_degree(sh: &[f32], stored: u8, degree: u8) -> std::borrow::Cow<'_, [f32]> {
    if degree >= stored {
        return sh.into();
    }
    let stride = |d: u8| 3 * (usize::from(d) + 1).pow(2);
    sh.chunks_exact(stride(stored))
        .flat_map(|g| g[..stride(degree)].iter().copied())
        .collect::<Vec<f32>>()
        .into()
}

/// The highest SH degree, up to `stored`, whose coefficients for `count`
/// Gaussians fit one storage binding of `max_binding` bytes.
fn sh_degree_that_fits(count: usize, stored: u8, max_binding: u64) -> u8 {
    (0..=stored)
        .rev()
        .find(|&d| count as u64 <= SH_BINDINGS * gaussians_per_binding(max_binding, d))
        .unwrap_or(0)
}

/// Bindings the SH is split over (the project kernel's `sh` and `sh_rest`).
const SH_BINDINGS: u64 = 2;

/// Gaussians whose SH of `degree` one binding of `max_binding` bytes holds.
fn gaussians_per_binding(max_binding: u64, degree: u8) -> u64 {
    max_binding / (12 * (u64::from(degree) + 1).pow(2))
}

#[cfg(test)]
mod tests {
    /// lavapipe binds 128 MiB and the SH has two bindings: a million
    /// degree-3 Gaussians (192 MB of SH) keep degree 3, 1.5 million drop to
    /// degree 2, 2.7 million to degree 1; a big binding keeps all.
    /// Dropping bands keeps each Gaussian's lowest coefficients in order;
    /// keeping them all copies nothing.
    #[test]
    fn sh_up_to_a_degree_keeps_each_gaussians_low_bands() {
        let sh: Vec<f32> = (0..2 * 48).map(|k| k as f32).collect();
        let kept = super::sh_up_to_degree(&sh, 3, 1);
        let expected: Vec<f32> = (0..12).chain(48..60).map(|k| k as f32).collect();
        assert_eq!(&kept[..], &expected[..]);
        assert!(matches!(
            super::sh_up_to_degree(&sh, 3, 3),
            std::borrow::Cow::Borrowed(_)
        ));
    }

    #[test]
    fn sh_bands_are_dropped_only_when_the_binding_is_too_small() {
        let lavapipe = 128 << 20;
        assert_eq!(super::sh_degree_that_fits(600_000, 3, lavapipe), 3);
        assert_eq!(super::sh_degree_that_fits(1_000_000, 3, lavapipe), 3);
        assert_eq!(super::sh_degree_that_fits(1_500_000, 3, lavapipe), 2);
        assert_eq!(super::sh_degree_that_fits(2_700_000, 3, lavapipe), 1);
        assert_eq!(super::sh_degree_that_fits(20_000_000, 3, lavapipe), 0);
        assert_eq!(
            super::sh_degree_that_fits(5_000_000, 3, u64::from(u32::MAX)),
            3
        );
        assert_eq!(super::sh_degree_that_fits(1_000_000, 1, lavapipe), 1);
    }

    use glam::{Quat, Vec3};
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::avatar::binding::{local_to_world, triangle_frames};
    use crate::avatar::gaussians::sigmoid;
    use crate::scene::camera::Orbit;

    /// Kernel level: `bind` places every Gaussian (f32 on the GPU) as the CPU
    /// binding does, degenerate triangles and unnormalised rotations included.
    /// The bind kernel runs only when the frames change: a camera move (or
    /// a world scene's every frame after the first) reuses the bound
    /// Gaussians, and each image equals a fresh renderer's.
    /// A scene whose SH outgrows one binding is drawn from two, with every
    /// band: the same image as from one binding; past two bindings, bands
    /// are dropped and the renderer says so.
    #[test]
    fn sh_split_over_two_bindings_draws_the_same_image() {
        let scene = crate::scene::synthetic::synthetic_scene(1_000, 2);
        let camera = scene
            .home_orbit(None, crate::scene::camera::UpAxis::default())
            .unwrap()
            .camera(64, 48);
        let settings = RenderSettings::default();
        let draw = |limit: Option<u64>| {
            let mut r = GpuRenderer::new().unwrap();
            r.sh_binding_limit = limit;
            r.set_world_scene(&scene).unwrap();
            let image = r.render(&[crate::scene::splats::IDENTITY_FRAME], &camera, &settings);
            (
                image.unwrap(),
                r.sh_notice(),
                r.scene.as_ref().unwrap().sh_split,
            )
        };
        let (whole, notice, split) = draw(None);
        assert_eq!((notice, split), (None, 1_000));
        // 192 bytes of SH a Gaussian: 600 fit one binding of 115,200 bytes.
        let (halves, notice, split) = draw(Some(115_200));
        assert_eq!((notice, split), (None, 600));
        assert!(halves == whole);
        let (_, notice, _) = draw(Some(60_000));
        assert!(notice.unwrap().contains("SH degree 2 of 3"));
    }

    /// Per-element kernels past [`device::MAX_GROUPS`] workgroups (20M
    /// Gaussians once failed wgpu's validation) run as rows of a 2D grid;
    /// a grid of 3 columns on a small scene exercises the same layout,
    /// rows cut short included, and draws the one-row image bit for bit.
    #[test]
    fn kernels_laid_out_in_rows_draw_the_same_image() {
        assert_eq!(element_grid(20_000_000, device::MAX_GROUPS), (65_535, 2));
        assert_eq!(element_grid(0, device::MAX_GROUPS), (1, 1));
        assert_eq!(element_grid(20_000, 3), (3, 27));
        let scene = crate::scene::synthetic::synthetic_scene(20_000, 3);
        let camera = scene
            .home_orbit(None, crate::scene::camera::UpAxis::default())
            .unwrap()
            .camera(96, 64);
        let draw = |columns: u32| {
            let mut r = GpuRenderer::new().unwrap();
            r.binning.grid_columns = columns;
            r.set_world_scene(&scene).unwrap();
            r.render(
                &[crate::scene::splats::IDENTITY_FRAME],
                &camera,
                &RenderSettings::default(),
            )
            .unwrap()
        };
        let one_row = draw(device::MAX_GROUPS);
        let rows = draw(3);
        assert!(rows == one_row);
        let reference =
            crate::render::reference::render_reference(&scene, &camera, &RenderSettings::default());
        assert!(crate::render::image::psnr_report(&rows, &reference).unwrap() > 50.0);
    }

    /// The hardware GPUs' batched rasteriser draws the plain one's image bit
    /// for bit: a dense scene whose pixels saturate mid-batch, tiles cut by
    /// the image's edge (70×50 is not a multiple of 16), tiles with no
    /// Gaussians, lists longer than one batch. lavapipe runs both.
    #[test]
    fn batched_rasteriser_draws_the_plain_image() {
        let scene = crate::scene::synthetic::synthetic_scene(30_000, 4);
        let orbit = scene
            .home_orbit(None, crate::scene::camera::UpAxis::default())
            .unwrap();
        let settings = RenderSettings::default();
        for (w, h) in [(70, 50), (160, 120)] {
            let camera = orbit.camera(w, h);
            let draw = |software: bool| {
                let mut r = GpuRenderer::new().unwrap();
                r.rasterize = TileRasterizer::for_adapter(&r.device, software);
                r.set_world_scene(&scene).unwrap();
                r.render(&[crate::scene::splats::IDENTITY_FRAME], &camera, &settings)
                    .unwrap()
            };
            let (plain, batched) = (draw(true), draw(false));
            assert!(batched == plain, "{w}x{h}");
        }
    }

    #[test]
    fn binding_is_redone_only_when_the_frames_change() {
        let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
        let triangles = [[0, 1, 2], [0, 2, 3]];
        let still = triangle_frames(&positions, &triangles);
        let moved = triangle_frames(&positions.map(|p| p * 1.2 + Vec3::X * 0.1), &triangles);
        let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
        for i in 0..200u32 {
            let t = i as f32 * 0.05;
            set.push(
                i % 2,
                Vec3::new(t.sin(), t.cos(), 0.1) * 0.3,
                Quat::IDENTITY,
                Vec3::splat(-3.0),
                1.0,
                &[0.5, 0.2, 0.1],
            );
        }
        let settings = RenderSettings::default();
        let fresh = |frames: &[TriangleFrame], camera: &Camera| {
            let mut r = GpuRenderer::new().unwrap();
            r.set_gaussians(&set).unwrap();
            r.render(frames, camera, &settings).unwrap()
        };
        let near = Orbit {
            radius: 2.0,
            target: [0.3, 0.3, 0.0],
            ..Orbit::STUDY
        }
        .camera(48, 40);
        let far = Orbit {
            radius: 3.0,
            ..Orbit::STUDY
        }
        .camera(48, 40);
        let mut renderer = GpuRenderer::new().unwrap();
        renderer.set_gaussians(&set).unwrap();
        let steps: [(&[TriangleFrame], &Camera, u64); 4] = [
            (&still, &near, 1),
            (&still, &far, 1),
            (&moved, &far, 2),
            (&still, &far, 3),
        ];
        for (k, (frames, camera, binds)) in steps.into_iter().enumerate() {
            let image = renderer.render(frames, camera, &settings).unwrap();
            assert_eq!(renderer.bind_dispatches, binds, "step {k}");
            assert_eq!(image, fresh(frames, camera), "step {k}");
        }
        renderer.set_gaussians(&set).unwrap();
        renderer.render(&still, &far, &settings).unwrap();
        assert_eq!(renderer.bind_dispatches, 4, "a new upload is bound again");
    }

    #[test]
    fn bind_kernel_matches_the_cpu_binding() {
        let mut renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut v = || {
            Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let mut positions: Vec<Vec3> = (0..30).map(|_| v()).collect();
        positions.push(positions[0]); // a repeated vertex: a degenerate triangle
        let mut triangles: Vec<[u32; 3]> = (0..10).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
        triangles.push([0, 30, 1]);
        let frames = triangle_frames(&positions, &triangles);
        let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
        for i in 0..700u32 {
            let mut r = || rng.random_range(-1.0f32..1.0);
            let q = Quat::from_xyzw(r(), r(), r(), r() + 1.5); // unnormalised
            set.push(
                i % triangles.len() as u32,
                Vec3::new(r(), r(), r()),
                q,
                Vec3::new(r(), r(), r()) * 3.0,
                r() * 4.0,
                &[0.5, 0.5, 0.5],
            );
        }
        renderer.set_gaussians(&set).unwrap();
        renderer
            .render(
                &frames,
                &Orbit::STUDY.camera(32, 24),
                &RenderSettings::default(),
            )
            .unwrap();
        let scene = renderer.scene.as_ref().unwrap();
        let bytes = set.len() as u64 * 48;
        let staging = renderer.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = renderer.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&scene.world, 0, &staging, 0, bytes);
        renderer.queue.submit([encoder.finish()]);
        let world: Vec<f32> = device::read_buffer(&renderer.device, &staging, bytes).unwrap();
        for i in 0..set.len() {
            let w = &world[12 * i..12 * i + 12];
            let frame = &frames[set.binding[i] as usize];
            let cpu = local_to_world(frame, set.position[i], set.rotation[i], set.log_scale[i]);
            let close = |a: f32, b: f32, what: &str| {
                assert!(
                    (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                    "Gaussian {i} {what}: GPU {a}, CPU {b}"
                );
            };
            for c in 0..3 {
                close(w[c], cpu.position[c], "position");
                close(w[8 + c], cpu.scale[c], "scale");
            }
            close(w[3], sigmoid(set.opacity_logit[i]), "opacity");
            let gpu_q = Quat::from_xyzw(w[5], w[6], w[7], w[4]);
            assert!(
                gpu_q.dot(cpu.rotation).abs() > 1.0 - 1e-5,
                "Gaussian {i} rotation"
            );
        }
    }

    /// Kernel level: `project` (f32) culls the same Gaussians as the CPU
    /// renderer's f64 projection and writes the same depth and tile rectangle,
    /// but for rounding at the edges: Gaussians behind, at and just in front of
    /// the camera, tiny and huge scales included.
    #[test]
    fn project_kernel_matches_the_cpu_projection() {
        let mut gpu = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let mut cpu = crate::render::cpu::CpuRenderer::new();
        let frames = triangle_frames(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let mut set = crate::avatar::gaussians::GaussianSet::with_degree(1);
        for k in 0..4_000 {
            let mut r = || rng.random_range(-1.0f32..1.0);
            // Spread along the view axis through and behind the camera (at z = 3).
            let position = Vec3::new(r() * 1.5, r() * 1.5, r() * 4.0);
            let log_scale = match k % 10 {
                0 => Vec3::splat(-12.0), // tiny
                1 => Vec3::splat(1.0),   // huge
                _ => Vec3::new(r(), r(), r()) * 2.0 - Vec3::splat(3.0),
            };
            let sh: Vec<f32> = (0..12).map(|_| r() * 0.5).collect();
            set.push(
                0,
                position,
                Quat::from_xyzw(r(), r(), r(), 1.0),
                log_scale,
                r() * 3.0,
                &sh,
            );
        }
        let camera = Orbit {
            radius: 3.0,
            fov_deg: 50.0,
            target: [0.0, 0.0, 0.0],
            ..Orbit::STUDY
        }
        .camera(160, 120);
        let settings = RenderSettings::default();
        gpu.set_gaussians(&set).unwrap();
        gpu.render(&frames, &camera, &settings).unwrap();
        cpu.set_gaussians(&set);
        cpu.render(&frames, &camera, &settings).unwrap();
        let scene = gpu.scene.as_ref().unwrap();
        let bytes = set.len() as u64 * 16;
        let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&scene.keys, 0, &staging, 0, bytes);
        gpu.queue.submit([encoder.finish()]);
        let keys: Vec<[u32; 4]> = device::read_buffer(&gpu.device, &staging, bytes).unwrap();
        let (mut visible, mut differ) = (0, 0);
        for (i, (g, c)) in keys.iter().zip(cpu.keys()).enumerate() {
            if g[3] != c[3] || g[1..3] != c[1..3] {
                differ += 1;
                continue;
            }
            if c[3] == 1 {
                visible += 1;
                let (a, b) = (f32::from_bits(g[0]), f32::from_bits(c[0]));
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs(),
                    "Gaussian {i}: depth {a} vs {b}"
                );
            }
        }
        assert!(visible > 500, "only {visible} visible");
        assert!(
            differ * 200 <= keys.len(),
            "{differ} of {} keys differ",
            keys.len()
        );
    }

    /// Kernel level: `pack_rgb` keeps the RGB bytes of every RGBA pixel, in
    /// order, across image sizes that do not fill whole words or workgroups.
    #[test]
    fn pack_rgb_kernel_matches_the_cpu_packing() {
        let mut renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
        set.push(
            0,
            Vec3::ZERO,
            Quat::IDENTITY,
            Vec3::splat(-2.0),
            3.0,
            &[1.0, -0.5, 0.2],
        );
        renderer.set_gaussians(&set).unwrap();
        let frames = triangle_frames(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
        for (w, h) in [(1, 1), (7, 5), (33, 17), (160, 120)] {
            let camera = Orbit {
                radius: 3.0,
                fov_deg: 60.0,
                target: [0.3, 0.3, 0.0],
                ..Orbit::STUDY
            }
            .camera(w, h);
            let image = renderer
                .render(&frames, &camera, &RenderSettings::default())
                .unwrap();
            // The RGBA image the rasteriser wrote, packed on the CPU.
            let words = (w * h) as u64;
            let staging = renderer.device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: words * 4,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = renderer.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&renderer.image.buffer, 0, &staging, 0, words * 4);
            renderer.queue.submit([encoder.finish()]);
            let rgba: Vec<u32> =
                device::read_buffer(&renderer.device, &staging, words * 4).unwrap();
            let cpu: Vec<u8> = rgba
                .iter()
                .flat_map(|p| p.to_le_bytes()[..3].to_vec())
                .collect();
            assert_eq!(image.pixels, cpu, "{w}x{h}");
            assert!(cpu.iter().any(|&c| c > 0), "{w}x{h}: something drawn");
        }
    }
}
