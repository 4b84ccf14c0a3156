//! The training rasteriser on wgpu: the forward and backward passes of
//! [`super::cpu`] as two kernels (`shaders/train_forward.wgsl`,
//! `shaders/train_backward.wgsl`) in f32. Binning stays on the host (the same
//! tile lists as the CPU pass); the backward writes one gradient slot per list
//! entry, summed by the workgroup in a fixed order, and the host adds a
//! splat's slots up tile by tile, so a run is deterministic without float
//! atomics.

use bytemuck::{Pod, Zeroable};

use super::splat::{bin, Backdrop, Rasterized, Splat, SplatGrad, TILE};
use crate::error::{Error, Result};
use crate::render::gpu::constants::SPLAT_GRAD_FLOATS;
use crate::render::gpu::device::{
    describe_adapter, guarded, map_and_read, open_device, Growable, OpenDevice, SOFTWARE_LOOP_LIMIT,
};
use crate::render::gpu::kernels::{TrainBackward, TrainForward};
use crate::render::projection::MIN_TRANSMITTANCE;

/// The kernels' uniform (`RasterParams` in shaders/common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct RasterParams {
    size: [u32; 4],
    tuning: [f32; 4],
}

/// The wgpu training rasteriser: a device, its two kernels and buffers that
/// grow with the scene.
pub struct GpuRaster {
    gpu: OpenDevice,
    forward: TrainForward,
    backward: TrainBackward,
    params: wgpu::Buffer,
    splats: Growable,
    ranges: Growable,
    list: Growable,
    backdrop: Growable,
    pixels: Growable,
    walked: Growable,
    grads: Growable,
    readback: Growable,
}

impl GpuRaster {
    /// Opens the best adapter (software ones only when `allow_software`):
    /// `Ok(None)` when there is only a software one and it is not allowed.
    pub fn open(allow_software: bool) -> Result<Option<Self>> {
        let Some(gpu) = pollster::block_on(open_device(allow_software))? else {
            return Ok(None);
        };
        let device = &gpu.device;
        let storage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST;
        let read_back = storage | wgpu::BufferUsages::COPY_SRC;
        Ok(Some(Self {
            forward: TrainForward::new(device),
            backward: TrainBackward::new(device),
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("raster params"),
                size: std::mem::size_of::<RasterParams>() as u64,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            splats: Growable::new(device, "training splats", storage),
            ranges: Growable::new(device, "tile ranges", storage),
            list: Growable::new(device, "tile list", storage),
            backdrop: Growable::new(device, "backdrop", storage),
            pixels: Growable::new(device, "pixels", read_back),
            walked: Growable::new(device, "walked", read_back),
            grads: Growable::new(device, "entry gradients", read_back),
            readback: Growable::new(
                device,
                "read-back",
                wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            ),
            gpu,
        }))
    }

    /// Name, driver and type of the adapter.
    pub fn description(&self) -> String {
        describe_adapter(&self.gpu.adapter)
    }

    /// True on a software adapter such as lavapipe.
    pub fn is_software(&self) -> bool {
        self.gpu.adapter.device_type == wgpu::DeviceType::Cpu
    }

    /// Writes `data` to a growable buffer (growing it first).
    fn upload<T: Pod>(&mut self, which: fn(&mut Self) -> &mut Growable, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let (device, queue) = (self.gpu.device.clone(), self.gpu.queue.clone());
        let buffer = which(self);
        buffer.ensure(&device, bytes.len() as u64);
        if !bytes.is_empty() {
            queue.write_buffer(&buffer.buffer, 0, bytes);
        }
    }

    /// Uploads the splats, the tile lists and the uniform; returns the grid.
    fn upload_scene(&mut self, splats: &[Splat], lists: &[Vec<u32>], size: [u32; 2]) -> [u32; 2] {
        let grid = [size[0].div_ceil(TILE), size[1].div_ceil(TILE)];
        let packed: Vec<[f32; 4]> = splats
            .iter()
            .flat_map(|s| {
                [
                    [s.center[0], s.center[1], s.depth, s.radius],
                    [s.conic[0], s.conic[1], s.conic[2], s.opacity],
                    [s.rgb[0], s.rgb[1], s.rgb[2], 0.0],
                ]
                .map(|v| v.map(|c| c as f32))
            })
            .collect();
        let mut ranges = Vec::with_capacity(lists.len());
        let mut flat = Vec::with_capacity(lists.iter().map(Vec::len).sum());
        for list in lists {
            let start = flat.len() as u32;
            flat.extend_from_slice(list);
            ranges.push([start, flat.len() as u32]);
        }
        self.upload(|s| &mut s.splats, &packed);
        self.upload(|s| &mut s.ranges, &ranges);
        self.upload(|s| &mut s.list, &flat);
        let params = RasterParams {
            size: [size[0], size[1], grid[0], grid[1]],
            tuning: [MIN_TRANSMITTANCE as f32, 0.0, 0.0, 0.0],
        };
        self.gpu
            .queue
            .write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        grid
    }

    /// Runs one kernel over every tile.
    fn dispatch(&self, encoder: &mut wgpu::CommandEncoder, grid: [u32; 2], forward: bool) {
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        let uniform = self.params.as_entire_buffer_binding();
        let (device, groups) = (&self.gpu.device, (grid[0], grid[1]));
        let (splats, ranges, list) = (&self.splats.buffer, &self.ranges.buffer, &self.list.buffer);
        let (pixels, walked) = (&self.pixels.buffer, &self.walked.buffer);
        if forward {
            self.forward.dispatch(
                device,
                &mut pass,
                uniform,
                splats,
                ranges,
                list,
                &self.backdrop.buffer,
                pixels,
                walked,
                groups,
            );
        } else {
            self.backward.dispatch(
                device,
                &mut pass,
                uniform,
                splats,
                ranges,
                list,
                pixels,
                walked,
                &self.grads.buffer,
                groups,
            );
        }
    }

    /// Refuses lists a software adapter would walk short: the forward and
    /// backward each walk at most a tile's list in one invocation, and
    /// llvmpipe stops an invocation's loops after [`SOFTWARE_LOOP_LIMIT`]
    /// iterations, silently (measured: a 70,000-entry tile gave a wrong
    /// image and gradients 100 % off; 30,000 matched the CPU).
    fn check_software_walks(&self, lists: &[Vec<u32>]) -> Result<()> {
        let longest = lists.iter().map(Vec::len).max().unwrap_or(0);
        if self.gpu.adapter.device_type == wgpu::DeviceType::Cpu && longest > SOFTWARE_LOOP_LIMIT {
            return Err(Error::device(format!(
                "a tile lists {longest} splats, more than {} walks in one shader invocation ({SOFTWARE_LOOP_LIMIT} loop iterations); train with --renderer cpu",
                describe_adapter(&self.gpu.adapter)
            )));
        }
        Ok(())
    }

    /// Draws the splats over `backdrop` (the CPU pass's
    /// [`super::cpu::forward`], in f32).
    pub fn forward(
        &mut self,
        splats: &[Splat],
        size: [u32; 2],
        backdrop: &Backdrop,
    ) -> Result<Rasterized> {
        let device = self.gpu.device.clone();
        guarded(&device, "the training forward pass", || {
            self.forward_unguarded(splats, size, backdrop)
        })
    }

    fn forward_unguarded(
        &mut self,
        splats: &[Splat],
        size: [u32; 2],
        backdrop: &Backdrop,
    ) -> Result<Rasterized> {
        let lists = bin(splats, size);
        self.check_software_walks(&lists)?;
        let grid = self.upload_scene(splats, &lists, size);
        let behind: Vec<[f32; 4]> = backdrop
            .colour
            .iter()
            .zip(&backdrop.stop)
            .map(|(c, &stop)| [c[0] as f32, c[1] as f32, c[2] as f32, stop as f32])
            .collect();
        self.upload(|s| &mut s.backdrop, &behind);
        let pixels = (size[0] * size[1]) as u64;
        let device = self.gpu.device.clone();
        self.pixels.ensure(&device, pixels * 16);
        self.walked.ensure(&device, pixels * 4);
        self.readback.ensure(&device, pixels * 20);
        let mut encoder = device.create_command_encoder(&Default::default());
        self.dispatch(&mut encoder, grid, true);
        let readback = &self.readback.buffer;
        encoder.copy_buffer_to_buffer(&self.pixels.buffer, 0, readback, 0, pixels * 16);
        encoder.copy_buffer_to_buffer(&self.walked.buffer, 0, readback, pixels * 16, pixels * 4);
        self.gpu.queue.submit([encoder.finish()]);
        let (mut image, mut final_t, mut walked) = (Vec::new(), Vec::new(), Vec::new());
        map_and_read(&device, &self.readback.buffer, pixels * 20, |bytes| {
            let (colour, counts) = bytes.split_at(pixels as usize * 16);
            let colour: &[[f32; 4]] = bytemuck::cast_slice(colour);
            image = colour
                .iter()
                .flat_map(|p| [p[0], p[1], p[2]].map(f64::from))
                .collect();
            final_t = colour.iter().map(|p| p[3] as f64).collect();
            walked = bytemuck::cast_slice::<u8, u32>(counts).to_vec();
        })?;
        Ok(Rasterized::from_parts(
            size,
            image,
            backdrop.clone(),
            lists,
            final_t,
            walked,
        ))
    }

    /// ∂loss/∂ every splat, given ∂loss/∂ the image (the CPU pass's
    /// [`super::cpu::backward`], in f32, summed on the host in f64).
    pub fn backward(
        &mut self,
        splats: &[Splat],
        raster: &Rasterized,
        d_image: &[f64],
    ) -> Result<Vec<SplatGrad>> {
        let device = self.gpu.device.clone();
        guarded(&device, "the training backward pass", || {
            self.backward_unguarded(splats, raster, d_image)
        })
    }

    fn backward_unguarded(
        &mut self,
        splats: &[Splat],
        raster: &Rasterized,
        d_image: &[f64],
    ) -> Result<Vec<SplatGrad>> {
        let size = raster.size;
        let grid = self.upload_scene(splats, &raster.lists, size);
        let pixels: Vec<[f32; 4]> = raster
            .final_t
            .iter()
            .zip(&raster.backdrop.colour)
            .enumerate()
            .flat_map(|(p, (&t, behind))| {
                let d = &d_image[p * 3..p * 3 + 3];
                [
                    [d[0] as f32, d[1] as f32, d[2] as f32, t as f32],
                    [behind[0] as f32, behind[1] as f32, behind[2] as f32, 0.0],
                ]
            })
            .collect();
        self.upload(|s| &mut s.pixels, &pixels);
        self.upload(|s| &mut s.walked, &raster.walked);
        let entries: usize = raster.lists.iter().map(Vec::len).sum();
        let bytes = (entries * SPLAT_GRAD_FLOATS as usize * 4) as u64;
        let device = self.gpu.device.clone();
        self.grads.ensure(&device, bytes);
        self.readback.ensure(&device, bytes);
        let mut encoder = device.create_command_encoder(&Default::default());
        self.dispatch(&mut encoder, grid, false);
        if bytes > 0 {
            encoder.copy_buffer_to_buffer(&self.grads.buffer, 0, &self.readback.buffer, 0, bytes);
        }
        self.gpu.queue.submit([encoder.finish()]);
        let mut grads = vec![SplatGrad::default(); splats.len()];
        if bytes == 0 {
            return Ok(grads);
        }
        map_and_read(&device, &self.readback.buffer, bytes, |data| {
            let slots: &[f32] = bytemuck::cast_slice(data);
            let mut slots = slots.chunks_exact(SPLAT_GRAD_FLOATS as usize);
            for &i in raster.lists.iter().flatten() {
                let g = slots.next().expect("one slot per entry");
                grads[i as usize].add(&SplatGrad {
                    center: [g[0], g[1]].map(f64::from),
                    conic: [g[2], g[3], g[4]].map(f64::from),
                    opacity: g[5] as f64,
                    rgb: [g[6], g[7], g[8]].map(f64::from),
                });
            }
        })?;
        Ok(grads)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::raster::cpu::{backward, forward};
    use rand::{Rng, SeedableRng};

    /// Splats over several tiles and partial edge tiles: elongated and round,
    /// opacities up to 1 (α clamped at 0.99), a nearly opaque stack that stops
    /// pixels early, and splats hanging off the image.
    fn scene(size: [u32; 2]) -> Vec<Splat> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut splats: Vec<Splat> = (0..300)
            .map(|i| {
                let (sx, sy) = (rng.random_range(0.8..6.0), rng.random_range(0.8..6.0));
                let rho: f64 = rng.random_range(-0.8..0.8);
                let det = sx * sx * sy * sy * (1.0 - rho * rho);
                let radius = 3.0 * sx.max(sy);
                Splat {
                    center: [
                        rng.random_range(-4.0..size[0] as f64 + 4.0),
                        rng.random_range(-4.0..size[1] as f64 + 4.0),
                    ],
                    conic: [sy * sy / det, -rho * sx * sy / det, sx * sx / det],
                    opacity: if i % 7 == 0 {
                        1.0
                    } else {
                        rng.random_range(0.05..0.95)
                    },
                    rgb: [rng.random(), rng.random(), rng.random()],
                    radius,
                    depth: rng.random_range(1.0..5.0),
                }
            })
            .collect();
        for k in 0..6 {
            splats.push(Splat {
                center: [20.0, 15.0],
                conic: [0.02, 0.0, 0.02],
                // Not 0.99: two of those leave exactly the stopping
                // transmittance, a tie f32 and f64 break differently.
                opacity: 0.985,
                rgb: [0.9, 0.1 * k as f64, 0.3],
                radius: 20.0,
                depth: 0.5 + 0.01 * k as f64,
            });
        }
        splats
    }

    fn gpu() -> GpuRaster {
        GpuRaster::open(true)
            .expect("a wgpu adapter (lavapipe in CI)")
            .expect("software adapters allowed")
    }

    /// The largest difference over the largest value, per gradient part.
    fn relative_difference(ours: &[SplatGrad], theirs: &[SplatGrad]) -> f64 {
        let parts = |g: &SplatGrad| -> Vec<f64> {
            g.center
                .iter()
                .chain(&g.conic)
                .chain([&g.opacity])
                .chain(&g.rgb)
                .copied()
                .collect()
        };
        let mut worst: f64 = 0.0;
        for part in 0..9 {
            let largest = ours.iter().fold(0.0f64, |m, g| m.max(parts(g)[part].abs()));
            let difference = ours.iter().zip(theirs).fold(0.0f64, |m, (a, b)| {
                m.max((parts(a)[part] - parts(b)[part]).abs())
            });
            worst = worst.max(difference / largest);
        }
        worst
    }

    /// The wgpu forward draws the CPU pass's image, transmittance and walk
    /// (up to f32 rounding: a threshold may flip at a rare pixel).
    #[test]
    fn forward_matches_the_cpu_pass() {
        let size = [53, 37];
        let splats = scene(size);
        let mut gpu = gpu();
        for background in [Backdrop::uniform(size, [0.1, 0.2, 0.3]), layered(size)] {
            forward_agrees(&splats, size, &background, &mut gpu);
        }
    }

    /// A layer at depth 2.5 over the left half, coloured per pixel.
    fn layered(size: [u32; 2]) -> Backdrop {
        let mut b = crate::train::raster::splat::test_layered_backdrop(size);
        for stop in b.stop.iter_mut().filter(|s| s.is_finite()) {
            *stop = 2.5;
        }
        b
    }

    fn forward_agrees(
        splats: &[Splat],
        size: [u32; 2],
        background: &Backdrop,
        gpu: &mut GpuRaster,
    ) {
        let cpu = forward(splats, size, background);
        let wgpu = gpu.forward(splats, size, background).unwrap();
        assert!(cpu.saturated_pixels() > 0, "the stack saturates pixels");
        let worst = cpu
            .image
            .iter()
            .zip(&wgpu.image)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        let off = cpu
            .image
            .iter()
            .zip(&wgpu.image)
            .filter(|(a, b)| (*a - *b).abs() > 1e-4)
            .count();
        assert!(worst < 5e-3, "largest colour difference {worst}");
        assert!(
            off * 100 < cpu.image.len(),
            "{off} channels differ by > 1e-4"
        );
        let same_walk = cpu
            .walked
            .iter()
            .zip(&wgpu.walked)
            .filter(|(a, b)| a == b)
            .count();
        assert!(same_walk * 100 >= cpu.walked.len() * 99, "{same_walk}");
    }

    /// On the same forward result (over a layer hiding part of the scene),
    /// the wgpu backward's per-splat gradients are the CPU pass's to f32
    /// rounding, and two runs agree bit for bit.
    #[test]
    fn backward_matches_the_cpu_pass_and_repeats_exactly() {
        let size = [53, 37];
        let splats = scene(size);
        let raster = forward(&splats, size, &layered(size));
        let d_image: Vec<f64> = (0..raster.image.len())
            .map(|i| ((i * 37) % 17) as f64 / 17.0 - 0.4)
            .collect();
        let ours = backward(&splats, &raster, &d_image);
        let mut gpu = gpu();
        let theirs = gpu.backward(&splats, &raster, &d_image).unwrap();
        let difference = relative_difference(&ours, &theirs);
        assert!(difference < 1e-4, "relative difference {difference}");
        let again = gpu.backward(&splats, &raster, &d_image).unwrap();
        assert_eq!(theirs, again);
    }

    /// Through the projection and the binding, every parameter's gradient
    /// from the wgpu rasteriser matches the CPU's on the gradient-check scene
    /// (near plane, tiny and huge scales, a zero quaternion, saturation).
    #[test]
    fn parameter_gradients_agree_with_the_cpu() {
        let difference =
            crate::train::model::gradient_check::agreement_with_cpu(crate::render::Backend::Gpu)
                .unwrap();
        assert!(difference < 1e-4, "{difference}");
    }

    /// A tile of 70,000 splats, each over a few of its pixels, so a pixel
    /// walks the whole list: beyond llvmpipe's loop limit. A hardware GPU
    /// must match the CPU pass; a software one must refuse, never answer
    /// wrong (it did: the image off by 4·10⁻³ and every gradient 100 % off).
    #[test]
    fn a_tile_longer_than_a_software_loop_limit_is_refused_or_right() {
        let size = [16, 16];
        let splats: Vec<Splat> = (0..70_000)
            .map(|i| Splat {
                center: [(i % 16) as f64 + 0.5, ((i / 16) % 16) as f64 + 0.5],
                conic: [4.0, 0.0, 4.0],
                opacity: 0.01 + (i % 3) as f64 * 0.001,
                rgb: [0.5, (i % 7) as f64 / 7.0, 0.2],
                radius: 1.0,
                depth: 1.0 + i as f64 * 1e-4,
            })
            .collect();
        let backdrop = layered(size);
        let mut gpu = gpu();
        match gpu.forward(&splats, size, &backdrop) {
            Ok(ours) => {
                let cpu = forward(&splats, size, &backdrop);
                let worst = cpu
                    .image
                    .iter()
                    .zip(&ours.image)
                    .map(|(a, b)| (a - b).abs())
                    .fold(0.0, f64::max);
                assert!(
                    worst < 1e-5,
                    "a hardware GPU must walk the whole list: {worst}"
                );
            }
            Err(e) => {
                assert_eq!(gpu.gpu.adapter.device_type, wgpu::DeviceType::Cpu, "{e}");
                assert!(e.to_string().contains("--renderer cpu"), "{e}");
            }
        }
    }
}
