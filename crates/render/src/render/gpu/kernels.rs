//! One thin typed wrapper per WGSL kernel in `shaders/`: the kernel's file, its
//! storage buffers by name and access in binding order (binding 0 is always the
//! uniform), declared once in the [`kernels!`] table, so a wrapper's dispatch
//! takes exactly the buffers its shader binds, in its order.

use super::device::{compute_pipeline, uniform_and_storage};

/// A compiled kernel.
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
}

impl Kernel {
    fn compile(device: &wgpu::Device, name: &str, source: &str, read_only: &[bool]) -> Self {
        Self {
            pipeline: compute_pipeline(device, name, source, &uniform_and_storage(read_only)),
        }
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
        let mut entries = vec![wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(uniform),
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
            layout: &self.pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
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
    /// Culls and projects world Gaussians, evaluates SH, writes sort keys.
    Project = "project" { world: read, sh: read, sh_rest: read, projected: write, keys: write }
    /// Pairs each Gaussian's depth bits with its index (culled ones last).
    SortKeys = "sort_keys" { keys: read, depth: write, index: write }
    /// Counts each block's keys per digit of one radix pass.
    RadixHistogram = "radix_histogram" { keys: read, counts: write }
    /// Moves keys and values to their sorted slots for one radix pass (stable).
    RadixScatter = "radix_scatter" { keys: read, values: read, offsets: read, keys_out: write, values_out: write }
    /// Prefix sum, step 1: each block's sum.
    ScanReduce = "scan_reduce" { data: read, sums: write }
    /// Prefix sum, step 2: the block sums become offsets (and the total).
    ScanSums = "scan_sums" { sums: write }
    /// Prefix sum, step 3: each element becomes its exclusive prefix.
    ScanApply = "scan_apply" { data: write, sums: read }
    /// Counts each Gaussian's tiles.
    TilesCount = "tiles_count" { keys: read, order: read, counts: write }
    /// Writes (tile, Gaussian) entries in depth order.
    TilesEmit = "tiles_emit" { keys: read, order: read, starts: read, tiles: write, gaussians: write }
    /// Marks where each tile's run of entries starts and ends.
    TilesRanges = "tiles_ranges" { tiles: read, ranges: write }
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
}

#[cfg(test)]
mod tests {
    use super::BINDINGS;

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
