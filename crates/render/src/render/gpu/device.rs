//! Device plumbing every kernel wrapper shares: growable buffers, bind-group
//! layouts, compiling a kernel with the generated constants header, waiting for
//! the device and reading buffers back.

use bytemuck::Pod;

use super::constants::{wgsl_header, GROUP};
use crate::error::{Error, Result};

/// An opened wgpu device with what its users need to know about it.
pub struct OpenDevice {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// The adapter behind it.
    pub adapter: wgpu::AdapterInfo,
    /// The limits it was opened with.
    pub limits: wgpu::Limits,
}

/// Loop iterations llvmpipe (lavapipe) allows one shader invocation, shared
/// by all its loops (Mesa's `LP_MAX_TGSI_LOOP_ITERATIONS`); past it the loops
/// end silently. Hardware adapters have no such limit.
pub const SOFTWARE_LOOP_LIMIT: usize = 65_535;

/// Opens the best adapter (high performance) with the limits every kernel in
/// `shaders/` needs: `Ok(None)` when `allow_software` is false and the best
/// adapter is a software one.
pub async fn open_device(allow_software: bool) -> Result<Option<OpenDevice>> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            force_fallback_adapter: false,
            compatible_surface: None,
            apply_limit_buckets: false,
        })
        .await
        .map_err(|e| {
            Error::device(format!(
                "no graphics adapter found ({e}); install Mesa's software Vulkan driver with \
                 'apt-get install mesa-vulkan-drivers libvulkan1', or use --reference for the CPU renderer"
            ))
        })?;
    if !allow_software && adapter.get_info().device_type == wgpu::DeviceType::Cpu {
        return Ok(None);
    }
    let adapter_limits = adapter.limits();
    let mut limits = wgpu::Limits::downlevel_defaults();
    limits.max_storage_buffer_binding_size = adapter_limits.max_storage_buffer_binding_size;
    limits.max_buffer_size = adapter_limits.max_buffer_size;
    // `project` binds seven storage buffers; eight is WebGPU's default,
    // which every Vulkan, Metal and DX12 device wgpu runs on offers.
    limits.max_storage_buffers_per_shader_stage = 8;
    limits.max_compute_invocations_per_workgroup = 256;
    limits.max_compute_workgroup_size_x = 256;
    limits.max_compute_workgroup_size_y = 16;
    let (device, queue) = adapter
        .request_device(&wgpu::DeviceDescriptor {
            label: Some("visage"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::default(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        })
        .await
        .map_err(|e| Error::device(format!("cannot open the graphics device: {e}")))?;
    Ok(Some(OpenDevice {
        device,
        queue,
        adapter: adapter.get_info(),
        limits,
    }))
}

/// Name, driver and type of an adapter, for reports.
pub fn describe_adapter(adapter: &wgpu::AdapterInfo) -> String {
    format!(
        "{} ({:?}, {}{})",
        adapter.name,
        adapter.device_type,
        adapter.driver,
        if adapter.driver_info.is_empty() {
            String::new()
        } else {
            format!(" {}", adapter.driver_info)
        }
    )
}

/// Runs `work` with the device's validation and out-of-memory errors
/// captured, so that a failure on the GPU (a buffer the device cannot
/// allocate, a limit this code did not foresee) is a one-line
/// [`Error::Device`] (exit 3) naming `what`, rather than wgpu's default
/// handler's panic.
pub fn guarded<T>(
    device: &wgpu::Device,
    what: &str,
    work: impl FnOnce() -> Result<T>,
) -> Result<T> {
    let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let result = work();
    // Scopes pop innermost first.
    let invalid = pollster::block_on(validation.pop());
    let exhausted = pollster::block_on(memory.pop());
    match exhausted.or(invalid) {
        Some(error) => Err(Error::device(format!(
            "{what} failed on the GPU: {}",
            one_line(&error.to_string())
        ))),
        None => result,
    }
}

/// wgpu's multi-line error report as one line: its kind, then each cause.
fn one_line(report: &str) -> String {
    report
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty() && *l != "Caused by:")
        .collect::<Vec<_>>()
        .join(": ")
}

/// Most workgroups in one dispatch dimension (wgpu's downlevel limit, and
/// what NVIDIA's Vulkan driver allows in y and z).
pub const MAX_GROUPS: u32 = 65_535;

/// The workgroup grid of a per-element kernel over `count` elements
/// ([`GROUP`] each): one row while it fits in `columns` (at most
/// [`MAX_GROUPS`]), else rows of `columns` workgroups (the kernels'
/// `element_index` flattens them), so 20 million Gaussians (78,125
/// workgroups) dispatch like 20 thousand.
pub fn element_grid(count: u32, columns: u32) -> (u32, u32) {
    let groups = count.div_ceil(GROUP).max(1);
    let columns = groups.min(columns.clamp(1, MAX_GROUPS));
    (columns, groups.div_ceil(columns))
}

/// shaders/common.wgsl: the structs and helpers every kernel includes.
const COMMON: &str = include_str!("../../../shaders/common.wgsl");

/// A growable GPU buffer.
pub struct Growable {
    /// The buffer (replaced when it grows).
    pub buffer: wgpu::Buffer,
    usage: wgpu::BufferUsages,
    label: &'static str,
}

impl Growable {
    /// A small buffer that grows on demand.
    pub fn new(device: &wgpu::Device, label: &'static str, usage: wgpu::BufferUsages) -> Self {
        Self {
            buffer: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: 256,
                usage,
                mapped_at_creation: false,
            }),
            usage,
            label,
        }
    }

    /// Goes back to a small buffer: after a failure on the GPU the buffer
    /// may be an invalid handle that still reports the size asked for, and
    /// [`Growable::ensure`] would keep it.
    pub fn reset(&mut self, device: &wgpu::Device) {
        *self = Self::new(device, self.label, self.usage);
    }

    /// Makes room for `bytes`; returns true when the buffer was replaced.
    pub fn ensure(&mut self, device: &wgpu::Device, bytes: u64) -> bool {
        if self.buffer.size() >= bytes {
            return false;
        }
        let size = bytes.next_power_of_two().max(256);
        self.buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(self.label),
            size,
            usage: self.usage,
            mapped_at_creation: false,
        });
        true
    }
}

fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

fn uniform_entry() -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding: 0,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Layout entries: a uniform at binding 0, then storage buffers (read-only or not).
pub fn uniform_and_storage(read_only: &[bool]) -> Vec<wgpu::BindGroupLayoutEntry> {
    let mut entries = vec![uniform_entry()];
    entries.extend(
        read_only
            .iter()
            .enumerate()
            .map(|(i, &r)| storage_entry(i as u32 + 1, r)),
    );
    entries
}

/// Compiles a kernel: the constants header generated from Rust
/// ([`super::constants`]), shaders/common.wgsl, then the kernel's own source
/// (entry point `main`).
pub fn compute_pipeline(
    device: &wgpu::Device,
    name: &str,
    source: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(format!("{}\n{COMMON}\n{source}", wgsl_header()).into()),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(name),
        entries,
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(name),
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(name),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// Waits until the device has finished the work submitted so far.
pub fn wait(device: &wgpu::Device) -> Result<()> {
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map(|_| ())
        .map_err(|e| Error::device(format!("the graphics device failed: {e}")))
}

/// Maps a read-back buffer, copies `bytes` out as `T`, and unmaps it.
pub fn read_buffer<T: Pod>(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    bytes: u64,
) -> Result<Vec<T>> {
    let mut out = Vec::new();
    map_and_read(device, buffer, bytes, |b| {
        out = bytemuck::cast_slice::<u8, T>(b).to_vec()
    })?;
    Ok(out)
}

/// Maps the first `bytes` of a read-back buffer, hands them to `read`, and unmaps it.
pub fn map_and_read(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    bytes: u64,
    read: impl FnOnce(&[u8]),
) -> Result<()> {
    let slice = buffer.slice(..bytes);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| Error::device(format!("the graphics device failed: {e}")))?;
    rx.recv()
        .map_err(|_| Error::device("the graphics device dropped a read-back"))?
        .map_err(|e| Error::device(format!("cannot read back from the graphics device: {e}")))?;
    {
        let view = slice.get_mapped_range().map_err(|e| {
            Error::device(format!("cannot read back from the graphics device: {e}"))
        })?;
        read(&view);
    }
    buffer.unmap();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A GPU failure inside a guard is a one-line device error naming the
    /// work (before, wgpu's default handler panicked: 20M Gaussians once
    /// ended `bench render` with a backtrace), and the device goes on
    /// working after it.
    #[test]
    fn a_gpu_failure_is_a_one_line_device_error() {
        let gpu = pollster::block_on(open_device(true)).unwrap().unwrap();
        let device = &gpu.device;
        let failed = guarded(device, "making a buffer", || {
            // MAP_READ may only go with COPY_DST: a validation error.
            let _invalid = device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: 16,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            Ok(())
        });
        let Err(Error::Device(message)) = failed else {
            panic!("{failed:?}");
        };
        assert!(message.starts_with("making a buffer failed on the GPU: "));
        assert!(!message.contains('\n'), "{message}");
        let fine = guarded(device, "making a buffer", || {
            let _buffer = device.create_buffer(&wgpu::BufferDescriptor {
                label: None,
                size: 16,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            });
            Ok(7)
        });
        assert_eq!(fine.unwrap(), 7);
    }
}
