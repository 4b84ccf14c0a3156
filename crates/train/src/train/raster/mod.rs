//! The training rasteriser, forward and backward: [`cpu`] in f64 on rayon
//! (the reference, and the default without a hardware GPU) and [`gpu`], the
//! same passes as wgpu kernels in f32; [`Rasterizer`] picks one per run.

pub mod cpu;
pub mod gpu;
mod splat;

pub use cpu::{backward, forward};
pub use splat::{Backdrop, Rasterized, Splat, SplatGrad};

use crate::error::{Error, Result};
use crate::render::Backend;
use gpu::GpuRaster;

/// Which rasteriser a training run uses: the f64 CPU passes above, or their
/// f32 wgpu kernels.
pub enum Rasterizer {
    /// [`forward`] and [`backward`] on rayon, f64.
    Cpu,
    /// [`GpuRaster`]: wgpu compute, f32.
    Gpu(Box<GpuRaster>),
}

impl Rasterizer {
    /// Opens the rasteriser a renderer choice names: `gpu` any wgpu adapter
    /// (lavapipe included), `cpu` the CPU, `auto` a hardware GPU when there is
    /// one and the CPU otherwise.
    pub fn open(backend: Backend) -> Result<Self> {
        Ok(match backend {
            Backend::Cpu => Rasterizer::Cpu,
            Backend::Gpu => Rasterizer::Gpu(Box::new(
                GpuRaster::open(true)?.ok_or_else(|| Error::device("no graphics adapter found"))?,
            )),
            Backend::Auto => match GpuRaster::open(false) {
                Ok(Some(gpu)) => Rasterizer::Gpu(Box::new(gpu)),
                _ => Rasterizer::Cpu,
            },
        })
    }

    /// What runs the passes, for reports.
    pub fn description(&self) -> String {
        match self {
            Rasterizer::Cpu => "cpu (f64, rayon)".to_string(),
            Rasterizer::Gpu(gpu) => format!("wgpu (f32) on {}", gpu.description()),
        }
    }

    /// Draws the splats over `backdrop`.
    pub fn forward(
        &mut self,
        splats: &[Splat],
        size: [u32; 2],
        backdrop: &Backdrop,
    ) -> Result<Rasterized> {
        match self {
            Rasterizer::Cpu => Ok(forward(splats, size, backdrop)),
            Rasterizer::Gpu(gpu) => gpu.forward(splats, size, backdrop),
        }
    }

    /// ∂loss/∂ every splat, given ∂loss/∂ the image.
    pub fn backward(
        &mut self,
        splats: &[Splat],
        raster: &Rasterized,
        d_image: &[f64],
    ) -> Result<Vec<SplatGrad>> {
        match self {
            Rasterizer::Cpu => Ok(backward(splats, raster, d_image)),
            Rasterizer::Gpu(gpu) => gpu.backward(splats, raster, d_image),
        }
    }
}
