//! The offscreen splat renderer on wgpu compute (docs/method.md §8), running on any Vulkan,
//! Metal or DX12 device and on Mesa's lavapipe where there is no GPU.
//!
//! Stages per frame: upload the triangle frames (the Gaussians only when the
//! selection changes) → `bind` (local → world) → `project` (cull, 2D covariance,
//! SH colour, depth, touched tiles) → depth sort and tile binning on the GPU
//! ([`binning`]: radix sorts, prefix sums; counts read back with the image size the
//! next frame's, [`room`]) →
//! `rasterize` (per 16×16 tile, front to back, early termination) → read back RGBA8.

use std::time::Instant;

use bytemuck::{Pod, Zeroable};
use glam::{Quat, Vec3};
use rayon::prelude::*;

use super::image::RgbImage;
use super::settings::{RenderSettings, StageTimings};
use crate::avatar::binding::TriangleFrame;
use crate::avatar::gaussians::{logit, GaussianSet};
use crate::error::{Error, Result};
use crate::render::lod::LodTree;
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
pub mod lod;
mod room;

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
    /// Gaussians the last frame drew, and of them the scene's own (read
    /// back after the walks cut short).
    drawn_counts: wgpu::Buffer,
    /// The uploaded scene's hierarchy records ([`lod::node_records`]) and
    /// the caller's name for the hierarchy, when the scene is one.
    lod: Option<(wgpu::Buffer, u64)>,
    /// Bound in place of hierarchy records when there are none.
    no_lod: wgpu::Buffer,
    /// What the last frame drew: Gaussians, and of them the scene's own.
    drawn: (u32, u32),
    /// The frames `scene.world` was last bound on: a world scene's never
    /// change, so after its first frame only the camera's work is redone.
    bound_frames: Option<Vec<TriangleFrame>>,
    /// Times the bind kernel ran (for tests).
    bind_dispatches: u64,
    /// Frames drawn a second time because their tile entries or kept
    /// Gaussians outgrew the room planned for them (for tests).
    redrawn_frames: u64,
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
        let mut binning = GpuBinning::new(&device);
        binning.max_binding = limits.max_storage_buffer_binding_size;
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
        let small = |label, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 16,
                usage,
                mapped_at_creation: false,
            })
        };
        let drawn_counts = small(
            "Gaussians drawn",
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        );
        let no_lod = small("no hierarchy", wgpu::BufferUsages::STORAGE);
        Ok(Some(Self {
            drawn_counts,
            no_lod,
            lod: None,
            drawn: (0, 0),
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
            redrawn_frames: 0,
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

    /// Uploads every node of a level-of-detail hierarchy, each with its
    /// record for the cut, to draw with [`GpuRenderer::render_lod`]; `name`
    /// is the caller's for this hierarchy ([`GpuRenderer::lod_name`]).
    pub fn set_lod_tree(&mut self, tree: &LodTree, name: u64) -> Result<()> {
        let records = lod::node_records(tree)?;
        self.set_world_scene(&tree.nodes)?;
        let device = self.device.clone();
        let uploaded = guarded(&device, "uploading the hierarchy", || {
            let buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hierarchy"),
                size: (records.len() as u64 * 16).max(16),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            self.queue
                .write_buffer(&buffer, 0, bytemuck::cast_slice(&records));
            Ok(buffer)
        });
        match uploaded {
            Ok(buffer) => {
                self.lod = Some((buffer, name));
                Ok(())
            }
            Err(e) => {
                self.scene = None;
                Err(e)
            }
        }
    }

    /// The name given to the uploaded hierarchy, while it is what the
    /// renderer holds.
    pub fn lod_name(&self) -> Option<u64> {
        self.lod.as_ref().map(|l| l.1)
    }

    /// Draws the uploaded hierarchy's cut for `camera`: the nodes of at
    /// most `pixels` on screen standing for their subtrees, chosen on the
    /// GPU (the same cut as [`crate::render::lod::cut_at`] without a budget).
    pub fn render_lod(
        &mut self,
        camera: &Camera,
        settings: &RenderSettings,
        pixels: f32,
    ) -> Result<RgbImage> {
        if self.lod.is_none() {
            return Err(Error::input("no hierarchy uploaded to the renderer"));
        }
        let frames = [crate::scene::splats::IDENTITY_FRAME];
        self.render_guarded(&frames, camera, settings, pixels.max(f32::MIN_POSITIVE))
    }

    /// What the last frame drew: Gaussians (nodes of a hierarchy), and of
    /// them the scene's own.
    pub fn drawn(&self) -> (u32, u32) {
        self.drawn
    }

    /// Makes the scene's buffers from its records (12 floats a Gaussian)
    /// and its SH of degree `stored_degree`.
    fn upload(&mut self, local: &[f32], all_sh: &[f32], stored_degree: u8) -> Result<()> {
        self.lod = None;
        self.forget_bind_groups();
        // The last scene's counts would plan room for another scene's frame.
        self.binning.forget_rooms();
        let device = self.device.clone();
        let uploaded = guarded(&device, "uploading the Gaussians", || {
            self.upload_unguarded(local, all_sh, stored_degree)
        });
        if uploaded.is_err() {
            // Half-made buffers are no scene to draw.
            self.scene = None;
            self.bound_frames = None;
        }
        uploaded
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
        // Made empty and written through the queue (not `create_buffer_init`,
        // which maps the new buffer and panics when the device could not
        // allocate it): a failure reaches the error scope of `upload`.
        let init = |label, contents: &[u8], usage| {
            let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (contents.len() as u64).max(16),
                usage: usage | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            if !contents.is_empty() {
                self.queue.write_buffer(&buffer, 0, contents);
            }
            buffer
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

    /// Renders the uploaded Gaussians placed on `frames` (one per triangle);
    /// an uploaded hierarchy is drawn whole (every node).
    pub fn render(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        self.render_guarded(frames, camera, settings, 0.0)
    }

    /// Renders a frame, with the cut of `lod_pixels` when it is positive.
    fn render_guarded(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
        lod_pixels: f32,
    ) -> Result<RgbImage> {
        let device = self.device.clone();
        let drawn = guarded(&device, "drawing a frame", || {
            // A frame whose tile entries or kept Gaussians outgrew the room
            // the last frame's counts planned is drawn again with room for them.
            match self.render_unguarded(frames, camera, settings, lod_pixels)? {
                Some(image) => Ok(image),
                None => {
                    self.redrawn_frames += 1;
                    self.render_unguarded(frames, camera, settings, lod_pixels)?
                        .ok_or_else(|| {
                            Error::device("a frame outgrew the room planned for it twice")
                        })
                }
            }
        });
        if matches!(drawn, Err(Error::Device(_))) {
            self.reset_after_failure();
        }
        drawn
    }

    /// After a failure on the GPU: buffers that failed to grow are invalid
    /// handles reporting the size asked for, so every per-frame buffer goes
    /// back to a small one, and the Gaussians are bound again next frame.
    fn reset_after_failure(&mut self) {
        self.forget_bind_groups();
        for b in [
            &mut self.frames,
            &mut self.image,
            &mut self.packed,
            &mut self.image_readback,
        ] {
            b.reset(&self.device);
        }
        self.binning.reset_buffers(&self.device);
        self.bound_frames = None;
    }

    /// Drops every bind group the kernels keep, so the buffers they bound
    /// (an old scene's) are freed with their owners.
    fn forget_bind_groups(&self) {
        self.bind.forget();
        self.project.forget();
        self.rasterize.forget();
        self.pack_rgb.forget();
        self.binning.forget_bind_groups();
    }

    fn render_unguarded(
        &mut self,
        frames: &[TriangleFrame],
        camera: &Camera,
        settings: &RenderSettings,
        lod_pixels: f32,
    ) -> Result<Option<RgbImage>> {
        let (scene, (width, height)) = super::frame_inputs(self.scene.as_ref(), frames, camera)?;
        let tiles = (width.div_ceil(TILE), height.div_ceil(TILE));
        let mut timings = StageTimings::default();
        let (lod_records, lod_pixels) = match &self.lod {
            Some((records, _)) if lod_pixels > 0.0 => (records, lod_pixels),
            _ => (&self.no_lod, 0.0),
        };

        // Upload: camera and frames.
        let t = Instant::now();
        let mut uniform = camera_uniform(camera, settings, scene, frames.len() as u32, tiles);
        uniform.tuning[2] = lod_pixels;
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
        encoder.clear_buffer(&self.drawn_counts, 0, None);
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
                lod_records,
                &scene.projected,
                &scene.keys,
                &self.drawn_counts,
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
            // A cut keeps a small share of the hierarchy's nodes.
            lod_pixels > 0.0,
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
        // The image, the count of walks cut short, the counts drawn, the
        // tile entries, the Gaussians a cut kept.
        let tail_bytes = 20;
        self.image_readback
            .ensure(&self.device, packed_bytes + tail_bytes);
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
        encoder.copy_buffer_to_buffer(
            &self.drawn_counts,
            0,
            &self.image_readback.buffer,
            packed_bytes + 4,
            8,
        );
        encoder.copy_buffer_to_buffer(
            &self.binning.entry_total,
            0,
            &self.image_readback.buffer,
            packed_bytes + 12,
            4,
        );
        encoder.copy_buffer_to_buffer(
            &self.binning.kept_total,
            0,
            &self.image_readback.buffer,
            packed_bytes + 16,
            4,
        );
        self.queue.submit([encoder.finish()]);
        // Unprofiled, the map below is the one wait for the frame's end (a
        // wait here first cost a second round trip to the device).
        if self.profile_stages {
            wait(&self.device)?;
        }

        // Read back: the packed RGB bytes are the image.
        let mut pixels = vec![0u8; rgb_bytes as usize];
        let mut tail = [0u32; 5];
        let mut copy_ms = 0.0;
        map_and_read(
            &self.device,
            &self.image_readback.buffer,
            packed_bytes + tail_bytes,
            |bytes| {
                let copy = Instant::now();
                // On several threads: 6 MB at 1920×1080 (0.64 → 0.60 ms of
                // an H200's read-back).
                const PIECE: usize = 1 << 18;
                pixels
                    .par_chunks_mut(PIECE)
                    .zip(bytes[..rgb_bytes as usize].par_chunks(PIECE))
                    .for_each(|(to, from)| to.copy_from_slice(from));
                let counts = &bytes[packed_bytes as usize..(packed_bytes + tail_bytes) as usize];
                tail = bytemuck::pod_read_unaligned(counts);
                copy_ms = ms(copy);
            },
        )?;
        let [cut_short, drawn, leaves, entries, kept] = tail;
        if !self.binning.settle(entries, kept) {
            return Ok(None);
        }
        self.drawn = (drawn, leaves);
        // Unprofiled, the raster's own end is not seen apart from the map's.
        let until_read = ms(t);
        timings.rasterize = until_read - copy_ms;
        timings.readback = copy_ms;
        if cut_short > 0 {
            // llvmpipe ends an invocation's loops after 65,535 iterations in
            // all; such pixels would silently show too much background.
            return Err(Error::device(format!(
                "{} stopped {cut_short} pixels' walks along their tile lists short (a dense scene: a tile lists more Gaussians than the driver lets one shader loop visit); render it with the CPU renderer (--renderer cpu)",
                describe_adapter(&self.adapter)
            )));
        }
        self.timings = timings;
        Ok(Some(RgbImage {
            width,
            height,
            pixels,
        }))
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
mod tests;
