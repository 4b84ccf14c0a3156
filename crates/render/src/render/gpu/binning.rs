//! Depth sort and tile binning on the GPU: the same lists the CPU's
//! [`TileBins`](super::tiles::TileBins) builds, bit for bit, made by compute
//! kernels so a frame never leaves the device until its image does.
//!
//! 1. `sort_keys`: (depth bits, Gaussian index) for every Gaussian, culled ones last;
//!    or, where most are culled (a level-of-detail cut), `cull_flags` + prefix sum
//!    + `compact_keys`: the kept ones only, in room planned for them.
//! 2. A stable LSD radix sort on the top `sort_bits` of the depth, 8 bits a pass
//!    (`radix_histogram` → prefix sum → `radix_scatter`), so ties keep index order.
//! 3. `tiles_count` + prefix sum: where each Gaussian's tile entries start, in depth
//!    order, and how many entries there are in all.
//! 4. `tiles_emit` writes (tile, Gaussian) entries in depth order into the room
//!    planned for them; a stable radix sort by tile makes each tile's run front to
//!    back; `tiles_ranges` finds the runs.
//!
//! The room for the kept Gaussians and for the entries is planned from the last
//! frame's counts ([`Room`]; the counts come back with the image), so a frame goes to
//! the device in one piece with no wait in the middle. The dispatches after a count
//! cover its room, and their kernels read the true count from a GPU buffer
//! ([`GpuBinning::kept_total`], [`GpuBinning::entry_total`]), so unused room costs
//! only idle workgroups. A frame whose counts outgrow their room is told by
//! [`GpuBinning::settle`] and binned again with room for them; the first frame reads
//! its counts back before using them (4 bytes each).
//!
//! Every kernel is its own dispatch (no workgroup waits for another), so it runs
//! on any driver, lavapipe included.

use wgpu::util::DeviceExt;

use super::constants::{DIGITS, SORT_BLOCK as BLOCK};
use super::device::{element_grid, read_buffer, Growable, MAX_GROUPS};
use super::kernels::{
    CompactKeys, CullFlags, RadixHistogram, RadixScatter, ScanApply, ScanReduce, ScanSums,
    SortKeys, TilesCount, TilesEmit, TilesRanges,
};
use super::room::Room;
use crate::error::{Error, Result};

/// Bytes between uniform slots (the largest offset alignment wgpu allows devices to ask).
const SLOT: u64 = 256;
/// Uniform slots per frame.
const SLOTS: u64 = 32;

/// `SortParams` in shaders/common.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SortParams {
    count: u32,
    shift: u32,
    blocks: u32,
    /// `compact_keys`, `tiles_emit`: the room for what they write (what
    /// would go past it is dropped).
    limit: u32,
    tiles: [u32; 4],
}

impl SortParams {
    /// Parameters for `count` elements, everything else zero.
    fn new(count: u32) -> Self {
        Self {
            count,
            shift: 0,
            blocks: 0,
            limit: 0,
            tiles: [0; 4],
        }
    }
}

/// The sort and binning kernels.
struct Kernels {
    sort_keys: SortKeys,
    cull_flags: CullFlags,
    compact_keys: CompactKeys,
    histogram: RadixHistogram,
    scatter: RadixScatter,
    scan_reduce: ScanReduce,
    scan_sums: ScanSums,
    scan_apply: ScanApply,
    tiles_count: TilesCount,
    tiles_emit: TilesEmit,
    tiles_ranges: TilesRanges,
}

/// A pair of key/value buffers the radix passes ping-pong between.
struct KeyValues {
    keys: [Growable; 2],
    values: [Growable; 2],
}

impl KeyValues {
    fn new(device: &wgpu::Device, label: &'static str) -> Self {
        // COPY_SRC and COPY_DST so tests can fill them and compare with the CPU.
        let storage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let g = || Growable::new(device, label, storage);
        Self {
            keys: [g(), g()],
            values: [g(), g()],
        }
    }

    fn reset(&mut self, device: &wgpu::Device) {
        for b in self.keys.iter_mut().chain(self.values.iter_mut()) {
            b.reset(device);
        }
    }

    fn ensure(&mut self, device: &wgpu::Device, count: u32) {
        let bytes = u64::from(count.max(1)) * 4;
        for b in self.keys.iter_mut().chain(self.values.iter_mut()) {
            b.ensure(device, bytes);
        }
    }
}

/// The GPU sort and binning stage with its reusable buffers.
pub(super) struct GpuBinning {
    kernels: Kernels,
    params: wgpu::Buffer,
    slots: Vec<SortParams>,
    depth: KeyValues,
    tiles: KeyValues,
    /// Per Gaussian in depth order: tile entries, then (scanned) where they start.
    entries: Growable,
    histogram: Growable,
    sums: Growable,
    total_readback: wgpu::Buffer,
    /// The last binned frame's entry total (4 bytes), copied into the
    /// frame's read-back for [`GpuBinning::settle`].
    pub entry_total: wgpu::Buffer,
    /// The last compacted frame's count of kept Gaussians (4 bytes), likewise.
    pub kept_total: wgpu::Buffer,
    /// `u32::MAX`: bound as the live count where the CPU knows the count.
    no_limit: wgpu::Buffer,
    /// Room for the tile entries.
    pub(super) entry_room: Room,
    /// Room for the Gaussians a compacted frame keeps.
    pub(super) kept_room: Room,
    /// Whether the last frame was compacted (so `kept_total` is its count).
    compacted: bool,
    /// Per tile: start and end of its run in the sorted entries.
    pub ranges: Growable,
    /// Which of `tiles.values` holds the sorted entries after [`GpuBinning::bin`].
    result: usize,
    /// Workgroups in one row of a per-element kernel's grid ([`MAX_GROUPS`];
    /// tests lower it to run the multi-row layout on small scenes).
    pub grid_columns: u32,
    /// The device's largest storage binding: the sort's buffers (grown to
    /// powers of two, bound whole) must fit it.
    pub max_binding: u64,
}

impl GpuBinning {
    /// Drops every buffer back to a small one (after a failure on the GPU).
    pub fn reset_buffers(&mut self, device: &wgpu::Device) {
        self.forget_bind_groups();
        self.forget_rooms();
        self.depth.reset(device);
        self.tiles.reset(device);
        for b in [
            &mut self.entries,
            &mut self.histogram,
            &mut self.sums,
            &mut self.ranges,
        ] {
            b.reset(device);
        }
    }

    /// Forgets the rooms planned from the last frame's counts (a new scene's
    /// say nothing of them).
    pub fn forget_rooms(&mut self) {
        self.entry_room.forget();
        self.kept_room.forget();
    }

    /// Drops the bind groups the kernels keep (so the buffers they bound
    /// can be freed).
    pub fn forget_bind_groups(&self) {
        let k = &self.kernels;
        k.sort_keys.forget();
        k.cull_flags.forget();
        k.compact_keys.forget();
        k.histogram.forget();
        k.scatter.forget();
        k.scan_reduce.forget();
        k.scan_sums.forget();
        k.scan_apply.forget();
        k.tiles_count.forget();
        k.tiles_emit.forget();
        k.tiles_ranges.forget();
    }

    /// Compiles the kernels.
    pub fn new(device: &wgpu::Device) -> Self {
        let kernels = Kernels {
            sort_keys: SortKeys::new(device),
            cull_flags: CullFlags::new(device),
            compact_keys: CompactKeys::new(device),
            histogram: RadixHistogram::new(device),
            scatter: RadixScatter::new(device),
            scan_reduce: ScanReduce::new(device),
            scan_sums: ScanSums::new(device),
            scan_apply: ScanApply::new(device),
            tiles_count: TilesCount::new(device),
            tiles_emit: TilesEmit::new(device),
            tiles_ranges: TilesRanges::new(device),
        };
        let storage = wgpu::BufferUsages::STORAGE;
        Self {
            kernels,
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("sort params"),
                size: SLOT * SLOTS,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            slots: Vec::new(),
            grid_columns: MAX_GROUPS,
            max_binding: u64::MAX,
            depth: KeyValues::new(device, "depth sort"),
            tiles: KeyValues::new(device, "tile entries"),
            entries: Growable::new(device, "tile entry counts", storage),
            histogram: Growable::new(device, "radix histogram", storage),
            sums: Growable::new(device, "scan sums", storage | wgpu::BufferUsages::COPY_SRC),
            total_readback: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("entry total read-back"),
                size: 4,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            entry_total: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("entry total"),
                size: 4,
                usage: storage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            kept_total: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kept total"),
                size: 4,
                usage: storage | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
            no_limit: device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("no limit"),
                contents: bytemuck::bytes_of(&u32::MAX),
                usage: storage,
            }),
            entry_room: Room::default(),
            kept_room: Room::default(),
            compacted: false,
            ranges: Growable::new(
                device,
                "tile ranges",
                storage | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
            ),
            result: 0,
        }
    }

    /// The tile-sorted Gaussian indices (valid after [`GpuBinning::bin`]).
    pub fn list(&self) -> &wgpu::Buffer {
        &self.tiles.values[self.result].buffer
    }

    fn slot(&mut self, params: SortParams) -> u64 {
        self.slots.push(params);
        assert!(self.slots.len() as u64 <= SLOTS, "too many sort dispatches");
        self.slots.len() as u64 - 1
    }

    /// Sorts the `count` Gaussians whose keys `project` wrote by depth (top
    /// `sort_bits` bits) and bins them into the tiles of a `tiles` grid;
    /// with `compact`, the culled ones are left out before the sort (worth
    /// its extra pass where most are culled). The lists are complete only if
    /// [`GpuBinning::settle`] says so once the frame's counts are read back.
    /// A count with no room planned (the first frame, after a failure or a
    /// new scene, after the kept Gaussians outgrew theirs) is read back
    /// before it is used.
    #[allow(clippy::too_many_arguments)]
    pub fn bin(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        keys: &wgpu::Buffer,
        count: u32,
        tiles: (u32, u32),
        sort_bits: u8,
        compact: bool,
    ) -> Result<()> {
        let tile_count = tiles.0 * tiles.1;
        self.ranges.ensure(device, u64::from(tile_count.max(1)) * 8);
        self.slots.clear();
        check_groups(count, "Gaussians", self.max_binding)?;
        // Per Gaussian: flags, then (scanned) where each kept one goes.
        self.entries.ensure(device, u64::from(count.max(1)) * 4);
        let mut encoder = device.create_command_encoder(&Default::default());
        self.compacted = compact;
        // With `compact`: the room for the kept ones, their true count in
        // `kept_total` on the GPU.
        let kept = match compact {
            true => self.count_kept(device, queue, &mut encoder, keys, count)?,
            false => count,
        };
        let live_kept = match compact {
            true => self.kept_total.clone(),
            false => self.no_limit.clone(),
        };
        let live_kept = &live_kept;
        let compacting = self.slot(SortParams {
            limit: kept,
            ..SortParams::new(count)
        });
        let tile_grid = [tiles.0, tiles.1, 0, 0];
        let per_gaussian = self.slot(SortParams {
            tiles: tile_grid,
            ..SortParams::new(kept)
        });

        // Phase 1: depth keys, depth sort, tile entry counts and their starts.
        self.depth.ensure(device, kept);
        let depth_passes = u32::from(sort_bits.clamp(8, 32)).div_ceil(8);
        let first_byte = 4 - depth_passes;
        let depth_sort = self.radix_plan(kept, first_byte..4);
        let entry_scan = self.scan_plan(kept);
        self.ensure_scratch(device, &depth_sort, &entry_scan);
        self.write_slots(queue);
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            let k = &self.kernels;
            let d = &self.depth;
            let groups = element_grid(kept, self.grid_columns);
            if compact {
                k.compact_keys.dispatch(
                    device,
                    &mut pass,
                    self.uniform(compacting),
                    keys,
                    &self.entries.buffer,
                    &d.keys[0].buffer,
                    &d.values[0].buffer,
                    element_grid(count, self.grid_columns),
                );
            } else {
                k.sort_keys.dispatch(
                    device,
                    &mut pass,
                    self.uniform(per_gaussian),
                    keys,
                    &d.keys[0].buffer,
                    &d.values[0].buffer,
                    groups,
                );
            }
            let order = self.encode_radix(device, &mut pass, &depth_sort, &self.depth, live_kept);
            let order = &self.depth.values[order].buffer;
            k.tiles_count.dispatch(
                device,
                &mut pass,
                self.uniform(per_gaussian),
                keys,
                order,
                &self.entries.buffer,
                live_kept,
                groups,
            );
            self.encode_scan(device, &mut pass, &entry_scan, &self.entries.buffer);
        }
        encoder.copy_buffer_to_buffer(
            &self.sums.buffer,
            u64::from(entry_scan.sums) * 4,
            &self.entry_total,
            0,
            4,
        );
        let room = match self.entry_room.planned() {
            Some(room) => room,
            None => self.read_now(device, queue, &mut encoder, &self.entry_total)?,
        };
        self.entry_room.given = room;
        let count = kept;

        // Phase 2: entries in depth order, stable sort by tile, tile runs.
        encoder.clear_buffer(&self.ranges.buffer, 0, None);
        if room > 0 {
            check_groups(room, "tile entries", self.max_binding)?;
            self.tiles.ensure(device, room);
            let order = depth_sort.result;
            let tile_bytes = (32 - (tile_count.max(2) - 1).leading_zeros()).div_ceil(8);
            let tile_sort = self.radix_plan(room, 0..tile_bytes);
            let per_entry = self.slot(SortParams {
                tiles: tile_grid,
                ..SortParams::new(room)
            });
            let per_emitter = self.slot(SortParams {
                tiles: tile_grid,
                limit: room,
                ..SortParams::new(kept)
            });
            self.ensure_scratch(device, &tile_sort, &tile_sort.scan);
            self.write_slots(queue);
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                let k = &self.kernels;
                let t = &self.tiles;
                k.tiles_emit.dispatch(
                    device,
                    &mut pass,
                    self.uniform(per_emitter),
                    keys,
                    &self.depth.values[order].buffer,
                    &self.entries.buffer,
                    &t.keys[0].buffer,
                    &t.values[0].buffer,
                    live_kept,
                    element_grid(count, self.grid_columns),
                );
                let sorted = self.encode_radix(
                    device,
                    &mut pass,
                    &tile_sort,
                    &self.tiles,
                    &self.entry_total,
                );
                k.tiles_ranges.dispatch(
                    device,
                    &mut pass,
                    self.uniform(per_entry),
                    &t.keys[sorted].buffer,
                    &self.ranges.buffer,
                    &self.entry_total,
                    element_grid(room, self.grid_columns),
                );
            }
            self.result = tile_sort.result;
        }
        queue.submit([encoder.finish()]);
        Ok(())
    }

    /// Takes the counts the last [`GpuBinning::bin`] made, read back from
    /// [`GpuBinning::entry_total`] and [`GpuBinning::kept_total`] after the
    /// frame, and plans the next frame's room from them; false when they did
    /// not fit the room that frame gave them, so its lists lack some and it
    /// must be binned again.
    pub fn settle(&mut self, entries: u32, kept: u32) -> bool {
        let largest = largest_sort(self.max_binding);
        if self.compacted && !self.kept_room.settle(kept, largest) {
            // The entries of too few Gaussians say nothing of the next
            // frame's: read them back then, and give the ones after half
            // more room, as after the entries' own outgrowing.
            self.entry_room.outgrown();
            return false;
        }
        self.entry_room.settle(entries, largest)
    }

    /// Submits `encoder` with a copy of `count` (one u32 on the GPU), waits
    /// for it and returns the count; `encoder` is a new one after.
    fn read_now(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        count: &wgpu::Buffer,
    ) -> Result<u32> {
        encoder.copy_buffer_to_buffer(count, 0, &self.total_readback, 0, 4);
        let done = std::mem::replace(encoder, device.create_command_encoder(&Default::default()));
        queue.submit([done.finish()]);
        Ok(read_buffer::<u32>(device, &self.total_readback, 4)?[0])
    }

    /// Encodes the flags of the Gaussians `project` kept and their scan in
    /// `entries` (each kept one's place among them), copies their count to
    /// `kept_total`, and returns the room for them: planned from the last
    /// frame's count, or this frame's read back now.
    fn count_kept(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        keys: &wgpu::Buffer,
        count: u32,
    ) -> Result<u32> {
        let every = self.slot(SortParams::new(count));
        let scan = self.scan_plan(count);
        self.sums.ensure(device, (u64::from(scan.sums) + 1) * 4);
        self.write_slots(queue);
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            self.kernels.cull_flags.dispatch(
                device,
                &mut pass,
                self.uniform(every),
                keys,
                &self.entries.buffer,
                element_grid(count, self.grid_columns),
            );
            self.encode_scan(device, &mut pass, &scan, &self.entries.buffer);
        }
        encoder.copy_buffer_to_buffer(
            &self.sums.buffer,
            u64::from(scan.sums) * 4,
            &self.kept_total,
            0,
            4,
        );
        let room = match self.kept_room.planned() {
            Some(room) => room.min(count),
            None => self.read_now(device, queue, encoder, &self.kept_total)?,
        };
        self.kept_room.given = room;
        Ok(room)
    }

    /// Plans a radix sort of `count` elements over the bytes `bytes` (low to high).
    fn radix_plan(&mut self, count: u32, bytes: std::ops::Range<u32>) -> RadixPlan {
        let blocks = count.div_ceil(BLOCK).max(1);
        let passes: Vec<u64> = bytes
            .clone()
            .map(|b| {
                self.slot(SortParams {
                    shift: b * 8,
                    blocks,
                    ..SortParams::new(count)
                })
            })
            .collect();
        let scan = self.scan_plan(DIGITS * blocks);
        RadixPlan {
            blocks,
            result: passes.len() % 2,
            passes,
            scan,
        }
    }

    /// Plans an exclusive prefix sum over `count` elements.
    fn scan_plan(&mut self, count: u32) -> ScanPlan {
        let sums = count.div_ceil(BLOCK).max(1);
        let per_element = self.slot(SortParams {
            blocks: sums,
            ..SortParams::new(count)
        });
        let per_sum = self.slot(SortParams::new(sums));
        ScanPlan {
            per_element,
            per_sum,
            sums,
        }
    }

    /// Makes room for a radix sort's histogram and for the block sums of its
    /// scan and of `other`.
    fn ensure_scratch(&mut self, device: &wgpu::Device, sort: &RadixPlan, other: &ScanPlan) {
        self.histogram
            .ensure(device, u64::from(DIGITS) * u64::from(sort.blocks) * 4);
        let sums = sort.scan.sums.max(other.sums);
        self.sums.ensure(device, (u64::from(sums) + 1) * 4);
    }

    fn write_slots(&self, queue: &wgpu::Queue) {
        let mut bytes = vec![0u8; (SLOT as usize) * self.slots.len()];
        for (k, s) in self.slots.iter().enumerate() {
            let at = k * SLOT as usize;
            bytes[at..at + std::mem::size_of::<SortParams>()]
                .copy_from_slice(bytemuck::bytes_of(s));
        }
        queue.write_buffer(&self.params, 0, &bytes);
    }

    /// Encodes a radix sort of `kv` (input in buffers 0), of as many of the
    /// planned elements as `live` (one `u32` on the GPU) says; returns the
    /// buffer index holding the result.
    fn encode_radix(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        plan: &RadixPlan,
        kv: &KeyValues,
        live: &wgpu::Buffer,
    ) -> usize {
        let k = &self.kernels;
        let mut from = 0;
        for &slot in &plan.passes {
            k.histogram.dispatch(
                device,
                pass,
                self.uniform(slot),
                &kv.keys[from].buffer,
                &self.histogram.buffer,
                live,
                (plan.blocks, 1),
            );
            self.encode_scan(device, pass, &plan.scan, &self.histogram.buffer);
            k.scatter.dispatch(
                device,
                pass,
                self.uniform(slot),
                &kv.keys[from].buffer,
                &kv.values[from].buffer,
                &self.histogram.buffer,
                &kv.keys[1 - from].buffer,
                &kv.values[1 - from].buffer,
                live,
                (plan.blocks, 1),
            );
            from = 1 - from;
        }
        from
    }

    /// Encodes an in-place exclusive prefix sum of `data`.
    fn encode_scan(
        &self,
        device: &wgpu::Device,
        pass: &mut wgpu::ComputePass<'_>,
        plan: &ScanPlan,
        data: &wgpu::Buffer,
    ) {
        let k = &self.kernels;
        let sums = &self.sums.buffer;
        let (per_element, per_sum) = (self.uniform(plan.per_element), self.uniform(plan.per_sum));
        k.scan_reduce.dispatch(
            device,
            pass,
            per_element.clone(),
            data,
            sums,
            (plan.sums, 1),
        );
        k.scan_sums.dispatch(device, pass, per_sum, sums, (1, 1));
        k.scan_apply
            .dispatch(device, pass, per_element, data, sums, (plan.sums, 1));
    }

    /// The parameter slot `slot` as a uniform binding.
    fn uniform(&self, slot: u64) -> wgpu::BufferBinding<'_> {
        wgpu::BufferBinding {
            buffer: &self.params,
            offset: slot * SLOT,
            size: wgpu::BufferSize::new(std::mem::size_of::<SortParams>() as u64),
        }
    }
}

struct ScanPlan {
    per_element: u64,
    per_sum: u64,
    sums: u32,
}

struct RadixPlan {
    blocks: u32,
    passes: Vec<u64>,
    scan: ScanPlan,
    /// Buffer index of the result (passes alternate 0 → 1 → 0 …).
    result: usize,
}

/// The radix and scan kernels give each workgroup one block of [`BLOCK`]
/// elements along one dispatch dimension, so one sort holds at most
/// [`MAX_GROUPS`] blocks (67 million elements); and its key and value
/// buffers (4 bytes an element, grown to a power of two, bound whole) must
/// fit the device's largest storage binding (33.5 million on lavapipe).
fn check_groups(count: u32, what: &str, max_binding: u64) -> Result<()> {
    if count > largest_sort(max_binding) {
        return Err(Error::device(format!(
            "{count} {what} are more than the GPU renderer sorts in one frame on this device; try --lod auto or --renderer cpu"
        )));
    }
    Ok(())
}

/// The most elements one sort takes (see [`check_groups`]).
fn largest_sort(max_binding: u64) -> u32 {
    let binding = match max_binding {
        0 => 0,
        b => 1u64 << b.ilog2(),
    };
    let elements = (binding / 4).min(u64::from(MAX_GROUPS) * u64::from(BLOCK));
    elements.min(u64::from(u32::MAX)) as u32
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use wgpu::util::DeviceExt;

    use super::*;
    use crate::render::gpu::GpuRenderer;
    use crate::render::tiles::{entry_gaussian, pack_tile, TileBins, TileKey};

    fn read_back(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        buffer: &wgpu::Buffer,
        words: usize,
    ) -> Vec<u32> {
        let bytes = (words.max(1) * 4) as u64;
        let staging = device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, bytes);
        queue.submit([encoder.finish()]);
        read_buffer(device, &staging, bytes).unwrap()
    }

    /// Random keys: depths with many exact ties, some culled, rectangles that
    /// may run past the grid (the binning clamps them).
    fn keys(n: usize, tiles: (u32, u32), seed: u64) -> Vec<TileKey> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                if rng.random_bool(0.1) {
                    return [0; 4];
                }
                let depth = 0.5 + (rng.random_range(0..400) as f32) * 0.037;
                let x0 = rng.random_range(0..tiles.0);
                let y0 = rng.random_range(0..tiles.1);
                let x1 = x0 + rng.random_range(0..4);
                let y1 = y0 + rng.random_range(0..3);
                [depth.to_bits(), pack_tile(x0, y0), pack_tile(x1, y1), 1]
            })
            .collect()
    }

    /// Kernel level: scan_reduce, scan_sums and scan_apply give the CPU's
    /// exclusive prefix sum and total, across block boundaries.
    #[test]
    fn scan_kernels_match_the_cpu_prefix_sum() {
        let renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let (device, queue) = renderer.device_and_queue();
        let mut b = GpuBinning::new(device);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        for n in [1u32, 255, 1024, 1025, 4_097, 70_001] {
            let data: Vec<u32> = (0..n).map(|_| rng.random_range(0..9)).collect();
            b.slots.clear();
            let plan = b.scan_plan(n);
            b.sums.ensure(device, (u64::from(plan.sums) + 1) * 4);
            b.write_slots(queue);
            let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(&data),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                b.encode_scan(device, &mut pass, &plan, &buffer);
            }
            queue.submit([encoder.finish()]);
            let gpu = read_back(device, queue, &buffer, n as usize);
            let sums = read_back(device, queue, &b.sums.buffer, plan.sums as usize + 1);
            let mut running = 0;
            let cpu: Vec<u32> = data
                .iter()
                .map(|&x| {
                    let before = running;
                    running += x;
                    before
                })
                .collect();
            assert_eq!(gpu, cpu, "{n} elements");
            assert_eq!(sums[plan.sums as usize], running, "{n} elements: total");
        }
    }

    /// Kernel level: radix_histogram + radix_scatter, one 8-bit pass, order
    /// keys and values like the CPU's stable sort by that digit.
    #[test]
    fn radix_kernels_match_a_stable_cpu_sort_by_one_digit() {
        let renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let (device, queue) = renderer.device_and_queue();
        let mut b = GpuBinning::new(device);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
        for n in [1u32, 300, 1024, 3_001, 40_000] {
            // Few distinct digits, so ties are everywhere.
            let keys: Vec<u32> = (0..n).map(|_| rng.random::<u32>() & 0x0000_0f0f).collect();
            let values: Vec<u32> = (0..n).collect();
            b.slots.clear();
            let plan = b.radix_plan(n, 1..2);
            b.depth.ensure(device, n);
            b.ensure_scratch(device, &plan, &plan.scan);
            b.write_slots(queue);
            queue.write_buffer(&b.depth.keys[0].buffer, 0, bytemuck::cast_slice(&keys));
            queue.write_buffer(&b.depth.values[0].buffer, 0, bytemuck::cast_slice(&values));
            let mut encoder = device.create_command_encoder(&Default::default());
            let result = {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                b.encode_radix(device, &mut pass, &plan, &b.depth, &b.no_limit)
            };
            queue.submit([encoder.finish()]);
            let gpu_keys = read_back(device, queue, &b.depth.keys[result].buffer, n as usize);
            let gpu_values = read_back(device, queue, &b.depth.values[result].buffer, n as usize);
            let mut order: Vec<u32> = (0..n).collect();
            order.sort_by_key(|&i| (keys[i as usize] >> 8) & 255); // stable
            assert_eq!(gpu_values, order, "{n} keys");
            let sorted: Vec<u32> = order.iter().map(|&i| keys[i as usize]).collect();
            assert_eq!(gpu_keys, sorted, "{n} keys");
        }
    }

    /// The lists match the CPU's whether the room planned for a frame's
    /// entries (and, compacted, its kept Gaussians) is exact (the first
    /// frame), larger than they need, or too small (detected, then binned
    /// again).
    #[test]
    fn gpu_binning_builds_the_same_lists_as_the_cpu() {
        let renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
        let (device, queue) = renderer.device_and_queue();
        let mut binning = GpuBinning::new(device);
        // Sizes across block boundaries; grids needing one and two tile passes;
        // full, 16-bit and 8-bit depth keys; nothing visible; nothing at all.
        let cases: [(usize, (u32, u32), u8); 7] = [
            (5_000, (40, 30), 32),
            (1_024, (3, 2), 32),
            (3_333, (80, 45), 16),
            (2_500, (17, 9), 8),
            (70_001, (80, 45), 32),
            (1, (4, 4), 32),
            (0, (4, 4), 32),
        ];
        // Whether some room was larger than needed, and which rooms were
        // outgrown: the entries', the kept Gaussians'.
        let (mut unused_room, mut outgrown, mut kept_outgrown) = (false, false, false);
        for (k, &(n, tiles, bits)) in cases.iter().enumerate() {
            let mut keys = keys(n, tiles, k as u64);
            if n == 1 {
                keys[0] = [0; 4];
            }
            let buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::cast_slice(if keys.is_empty() { &[[0u32; 4]] } else { &keys }),
                usage: wgpu::BufferUsages::STORAGE,
            });
            let mut cpu = TileBins::default();
            cpu.bin(&keys, tiles, bits);
            let visible = keys.iter().filter(|k| k[3] != 0).count();
            for compact in [false, true] {
                // As a frame does: bin in the rooms the last counts planned,
                // and again when the counts outgrew them.
                let mut attempts = 0;
                loop {
                    binning
                        .bin(device, queue, &buffer, n as u32, tiles, bits, compact)
                        .unwrap();
                    attempts += 1;
                    let total = read_back(device, queue, &binning.entry_total, 1)[0];
                    let kept = read_back(device, queue, &binning.kept_total, 1)[0];
                    unused_room |= binning.entry_room.given > total;
                    kept_outgrown |= compact && kept > binning.kept_room.given;
                    if binning.settle(total, kept) {
                        assert_eq!(total as usize, cpu.list.len(), "case {k}: entry total");
                        if compact {
                            assert_eq!(kept as usize, visible, "case {k}: kept");
                        }
                        break;
                    }
                    outgrown = true;
                    assert!(
                        attempts < 3,
                        "case {k}: the rooms are too small three times"
                    );
                }
                let tile_count = (tiles.0 * tiles.1) as usize;
                let ranges = read_back(device, queue, &binning.ranges.buffer, 2 * tile_count);
                let list = read_back(
                    device,
                    queue,
                    binning.list(),
                    binning.entry_room.given as usize,
                );
                for t in 0..tile_count {
                    let (a, b) = (ranges[2 * t] as usize, ranges[2 * t + 1] as usize);
                    let gpu_tile = if a < b { &list[a..b] } else { &[][..] };
                    let cpu_tile: Vec<u32> =
                        cpu.tile(t).iter().map(|&e| entry_gaussian(e)).collect();
                    assert_eq!(
                        gpu_tile,
                        &cpu_tile[..],
                        "case {k} (compact {compact}): tile {t} differs"
                    );
                }
            }
        }
        // Every way a planned room goes was taken: too much, too little
        // for the entries, too little for the kept Gaussians.
        assert!(unused_room && outgrown && kept_outgrown);
    }
}
