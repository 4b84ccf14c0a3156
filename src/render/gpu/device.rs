//! Device plumbing every kernel wrapper shares: growable buffers, bind-group
//! layouts, compiling a kernel with the generated constants header, waiting for
//! the device and reading buffers back.

use bytemuck::Pod;

use super::constants::wgsl_header;
use crate::error::{Error, Result};

/// Most workgroups in one dispatch dimension (wgpu's downlevel limit).
pub const MAX_GROUPS: u32 = 65_535;

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
