//! One thin typed wrapper per WGSL kernel in `shaders/`: the kernel's file, its
//! storage buffers by name and access in binding order (binding 0 is always the
//! uniform), declared once in the [`kernels!`] table, so a wrapper's dispatch
//! takes exactly the buffers its shader binds, in its order.

use std::sync::Mutex;

use super::device::{compute_pipeline, uniform_and_storage};

/// A compiled kernel, with the bind groups of its recent dispatches.
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    groups: Mutex<BindGroups>,
}

/// What one bind group binds: the uniform's buffer, offset and size, then
/// the storage buffers in binding order.
type Binds = (
    wgpu::Buffer,
    u64,
    Option<wgpu::BufferSize>,
    Vec<wgpu::Buffer>,
);

/// Bind groups a kernel made, each with the dispatch that last used it:
/// a frame binds what the last frame bound, and making some forty bind
/// groups anew every frame is CPU time the GPU waits for.
#[derive(Default)]
struct BindGroups {
    made: Vec<(Binds, wgpu::BindGroup, u64)>,
    dispatches: u64,
}

/// Dispatches of one kernel after which a bind group not used again is
/// dropped (with its hold on the buffers it binds): more than any kernel's
/// distinct bind groups in a frame (the scans: 9).
const KEEP_FOR_DISPATCHES: u64 = 32;

impl Kernel {
    fn compile(device: &wgpu::Device, name: &str, source: &str, read_only: &[bool]) -> Self {
        let pipeline = compute_pipeline(device, name, source, &uniform_and_storage(read_only));
        Self {
            layout: pipeline.get_bind_group_layout(0),
            pipeline,
            groups: Mutex::default(),
        }
    }

    /// Drops every kept bind group (and so its hold on the buffers).
    fn forget(&self) {
        let mut groups = self.groups.lock().unwrap_or_else(|e| e.into_inner());
        groups.made.clear();
    }

    /// The bind group of `binds`: a kept one, or a new one kept.
    fn bind_group(&self, device: &wgpu::Device, binds: Binds) -> wgpu::BindGroup {
        let mut groups = self.groups.lock().unwrap_or_else(|e| e.into_inner());
        groups.dispatches += 1;
        let now = groups.dispatches;
        groups
            .made
            .retain(|(_, _, used)| now - used < KEEP_FOR_DISPATCHES);
        if let Some(kept) = groups.made.iter_mut().find(|(b, _, _)| *b == binds) {
            kept.2 = now;
            return kept.1.clone();
        }
        let (uniform, offset, size, storage) = &binds;
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: uniform,
                offset: *offset,
                size: *size,
            }),
        }];
        entries.extend(
            storage
                .iter()
                .enumerate()
                .map(|(i, b)| wgpu::BindGroupEntry {
                    binding: i as u32 + 1,
                    resource: b.as_entire_binding(),
                }),
        );
        let group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &entries,
        });
        groups.made.push((binds, group.clone(), now));
        group
    }

    /// Binds the uniform and the storage buffers (binding order) and dispatches.
    fn dispatch(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        uniform: wgpu::BufferBinding<'_>,
        storage: &[&wgpu::Buffer],
        groups: (u32, u32),
    ) {
        let binds = (
            uniform.buffer.clone(),
            uniform.offset,
            uniform.size,
            storage.iter().map(|b| (*b).clone()).collect(),
        );
        let group = self.bind_group(device, binds);
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(groups.0.max(1), groups.1.max(1), 1);
    }
}

/// `read` or `write`: whether the shader only reads a storage buffer.
macro_rules! read_only {
    (read) => {
        true
    };
    (write) => {
        false
    };
}

/// Declares the kernels: a wrapper type per WGSL file with a typed dispatch.
macro_rules! kernels {
    ($(
        $(#[doc = $doc:expr])*
        $kernel:ident = $file:literal { $( $buffer:ident : $access:ident ),* $(,)? }
    )*) => {
        /// Every kernel's file and its storage buffers' access (true: read only),
        /// in binding order (checked against the WGSL by a test).
        pub const BINDINGS: &[(&str, &[bool])] = &[
            $( (concat!($file, ".wgsl"), &[$(read_only!($access)),*]), )*
        ];

        $(
            $(#[doc = $doc])*
            pub struct $kernel(Kernel);

            impl $kernel {
                /// The WGSL source file in `shaders/`.
                pub const FILE: &'static str = concat!($file, ".wgsl");

                /// Compiles the kernel.
                pub fn new(device: &wgpu::Device) -> Self {
                    Self(Kernel::compile(
                        device,
                        $file,
                        include_str!(concat!("../../../shaders/", $file, ".wgsl")),
                        &[$(read_only!($access)),*],
                    ))
                }

                /// Drops the bind groups it keeps (call when the buffers it
                /// bound are replaced, so they are freed).
                pub fn forget(&self) {
                    self.0.forget();
                }

                /// Dispatches `groups` workgroups with its uniform and buffers.
                #[allow(clippy::too_many_arguments)]
                pub fn dispatch(
                    &self,
                    device: &wgpu::Device,
                    pass: &mut wgpu::ComputePass<'_>,
                    uniform: wgpu::BufferBinding<'_>,
                    $( $buffer: &wgpu::Buffer, )*
                    groups: (u32, u32),
                ) {
                    self.0.dispatch(device, pass, uniform, &[$($buffer),*], groups);
                }
            }
        )*
    };
}

kernels! {
    /// Places triangle-local Gaussians in world space from the triangle frames.
    Bind = "bind" { local: read, frames: read, world: write }
    /// Culls and projects world Gaussians (or a hierarchy's nodes in the
    /// cut of a level-of-detail threshold), evaluates SH, writes sort keys
    /// and counts what it drew.
    Project = "project" { world: read, sh: read, sh_rest: read, lod: read, projected: write, keys: write, drawn: write }
    /// Pairs each Gaussian's depth bits with its index (culled ones last).
    SortKeys = "sort_keys" { keys: read, depth: write, index: write }
    /// Marks the Gaussians `project` kept (1) and culled (0).
    CullFlags = "cull_flags" { keys: read, flags: write }
    /// `sort_keys` without the culled Gaussians, placed by the scanned flags.
    CompactKeys = "compact_keys" { keys: read, offsets: read, depth: write, index: write }
    /// Counts each block's keys per digit of one radix pass.
    RadixHistogram = "radix_histogram" { keys: read, counts: write, live: read }
    /// Moves keys and values to their sorted slots for one radix pass (stable).
    RadixScatter = "radix_scatter" { keys: read, values: read, offsets: read, keys_out: write, values_out: write, live: read }
    /// Prefix sum, step 1: each block's sum.
    ScanReduce = "scan_reduce" { data: read, sums: write }
    /// Prefix sum, step 2: the block sums become offsets (and the total).
    ScanSums = "scan_sums" { sums: write }
    /// Prefix sum, step 3: each element becomes its exclusive prefix.
    ScanApply = "scan_apply" { data: write, sums: read }
    /// Counts each Gaussian's tiles.
    TilesCount = "tiles_count" { keys: read, order: read, counts: write, live: read }
    /// Writes (tile, Gaussian) entries in depth order.
    TilesEmit = "tiles_emit" { keys: read, order: read, starts: read, tiles: write, gaussians: write, live: read }
    /// Marks where each tile's run of entries starts and ends.
    TilesRanges = "tiles_ranges" { tiles: read, ranges: write, live: read }
    /// Blends each 16×16 tile front to back.
    Rasterize = "rasterize" { projected: read, ranges: read, list: read, image: write, cut_short: write }
    /// `rasterize` for hardware GPUs: each tile's Gaussians read in batches
    /// into workgroup memory (the same image, bit for bit).
    RasterizeBatched = "rasterize_batched" { projected: read, ranges: read, list: read, image: write, cut_short: write }
    /// Packs the RGBA image to RGB bytes for the read-back.
    PackRgb = "pack_rgb" { image: read, packed: write }
    /// The training rasteriser's forward: colour, final transmittance and
    /// entries walked per pixel.
    TrainForward = "train_forward" { splats: read, ranges: read, list: read, backdrop: read, pixels: write, walked: write }
    /// The training rasteriser's backward: ∂loss/∂ screen quantities per list entry.
    TrainBackward = "train_backward" { splats: read, ranges: read, list: read, pixels: read, walked: read, grads: write }
}

/// The tile rasteriser suited to the adapter: [`RasterizeBatched`] on
/// hardware GPUs, whose loads overlap in a batch (an H200 drew a million
/// Gaussians at 1920×1080 in 8.0 ms a frame with per-entry reads, 3.8 ms
/// batched), and [`Rasterize`] on software ones such as lavapipe, where a
/// workgroup barrier costs more than the loads it overlaps. Both bind the
/// same buffers in the same order.
pub struct TileRasterizer(Kernel);

impl TileRasterizer {
    /// Compiles the kernel for an adapter that is (or is not) software.
    pub fn for_adapter(device: &wgpu::Device, software: bool) -> Self {
        if software {
            Self(Rasterize::new(device).0)
        } else {
            Self(RasterizeBatched::new(device).0)
        }
    }

    /// Dispatches one workgroup per tile of `tiles`.
    #[allow(clippy::too_many_arguments)]
    pub fn dispatch(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        uniform: wgpu::BufferBinding<'_>,
        projected: &wgpu::Buffer,
        ranges: &wgpu::Buffer,
        list: &wgpu::Buffer,
        image: &wgpu::Buffer,
        cut_short: &wgpu::Buffer,
        tiles: (u32, u32),
    ) {
        let buffers = [projected, ranges, list, image, cut_short];
        self.0.dispatch(device, pass, uniform, &buffers, tiles);
    }

    /// Drops the bind groups it keeps.
    pub fn forget(&self) {
        self.0.forget();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A dispatch binding what an earlier one bound reuses its bind group;
    /// other buffers or another uniform slot get their own; one unused for
    /// KEEP_FOR_DISPATCHES dispatches is dropped, and `forget` drops all.
    #[test]
    fn bind_groups_are_kept_while_their_buffers_are_bound() {
        let gpu = pollster::block_on(crate::render::gpu::device::open_device(true))
            .unwrap()
            .unwrap();
        let device = &gpu.device;
        let buffer = |usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: 512,
                usage,
                mapped_at_creation: false,
            })
        };
        let uniform = buffer(wgpu::BufferUsages::UNIFORM);
        let (a, b, c) = (
            buffer(wgpu::BufferUsages::STORAGE),
            buffer(wgpu::BufferUsages::STORAGE),
            buffer(wgpu::BufferUsages::STORAGE),
        );
        let kernel = PackRgb::new(device);
        let made = || kernel.0.groups.lock().unwrap().made.len();
        let dispatch = |from: &wgpu::Buffer, to: &wgpu::Buffer, offset: u64| {
            let mut encoder = device.create_command_encoder(&Default::default());
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let binding = wgpu::BufferBinding {
                buffer: &uniform,
                offset,
                size: wgpu::BufferSize::new(128),
            };
            kernel.dispatch(device, &mut pass, binding, from, to, (1, 1));
        };
        dispatch(&a, &b, 0);
        dispatch(&a, &b, 0);
        assert_eq!(made(), 1);
        dispatch(&a, &c, 0);
        dispatch(&a, &b, 256);
        assert_eq!(made(), 3);
        for _ in 0..KEEP_FOR_DISPATCHES {
            dispatch(&a, &b, 0);
        }
        assert_eq!(made(), 1, "unused bind groups are dropped");
        kernel.forget();
        assert_eq!(made(), 0);
    }

    /// The table's buffers are the shaders' storage bindings, in order, with
    /// the same access; every shader but common.wgsl has a wrapper.
    #[test]
    fn wrappers_match_the_shaders() {
        for (file, access) in BINDINGS {
            let text = std::fs::read_to_string(format!("shaders/{file}")).unwrap();
            let found: Vec<bool> = text
                .lines()
                .filter_map(|l| l.split_once("var<storage, ").map(|(_, rest)| rest))
                .map(|rest| rest.starts_with("read>"))
                .collect();
            assert_eq!(&found, access, "{file}");
            for (k, _) in access.iter().enumerate() {
                assert!(text.contains(&format!("@binding({})", k + 1)), "{file}");
            }
        }
        let mut shaders: Vec<String> = std::fs::read_dir("shaders")
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n != "common.wgsl")
            .collect();
        shaders.sort();
        let mut wrapped: Vec<String> = BINDINGS.iter().map(|(f, _)| f.to_string()).collect();
        wrapped.sort();
        assert_eq!(shaders, wrapped);
    }
}
