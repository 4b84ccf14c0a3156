//! Rendering: cameras, projection conventions, the CPU reference splat renderer
//! (the accuracy oracle), and the CPU mesh preview.

pub mod cpu;
pub mod gpu;
pub mod image;
pub mod lod;
pub mod mesh_preview;
pub mod projection;
pub mod reference;
pub mod settings;
pub mod sh;
pub mod tiles;

use crate::avatar::binding::TriangleFrame;
use crate::avatar::gaussians::GaussianSet;
use crate::error::Result;

/// What both renderers check before a frame: something is uploaded, there
/// are frames to place it on; returns the uploaded data and the image size.
pub fn frame_inputs<'a, T>(
    uploaded: Option<&'a T>,
    frames: &[TriangleFrame],
    camera: &crate::scene::camera::Camera,
) -> Result<(&'a T, (u32, u32))> {
    let uploaded = uploaded
        .ok_or_else(|| crate::error::Error::input("no Gaussians uploaded to the renderer"))?;
    if frames.is_empty() {
        return Err(crate::error::Error::input(
            "no triangle frames to bind the Gaussians to",
        ));
    }
    Ok((uploaded, (camera.width.max(1), camera.height.max(1))))
}

/// Which renderer draws frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Backend {
    /// A hardware GPU through wgpu when there is one, otherwise the CPU renderer.
    #[default]
    Auto,
    /// wgpu on the best adapter, software (lavapipe) included.
    Gpu,
    /// The fast CPU renderer.
    Cpu,
}

impl Backend {
    /// Every backend with its name.
    pub const ALL: [(Backend, &'static str); 3] = [
        (Backend::Auto, "auto"),
        (Backend::Gpu, "gpu"),
        (Backend::Cpu, "cpu"),
    ];

    /// The backend's name (`auto`, `gpu`, `cpu`).
    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(b, _)| *b == self)
            .map_or("auto", |(_, n)| n)
    }

    /// Parses `auto`, `gpu` or `cpu`.
    pub fn parse(name: &str) -> std::result::Result<Backend, String> {
        Self::ALL
            .iter()
            .find(|(_, n)| *n == name)
            .map(|(b, _)| *b)
            .ok_or_else(|| {
                format!(
                    "renderer '{}' is not auto, gpu or cpu",
                    crate::text::printable(name)
                )
            })
    }
}

/// A splat renderer: the wgpu one or the CPU one, behind one interface.
pub enum SplatRenderer {
    /// wgpu compute.
    Gpu(Box<gpu::GpuRenderer>),
    /// Native CPU.
    Cpu(Box<cpu::CpuRenderer>),
}

impl SplatRenderer {
    /// Opens a renderer of the requested kind.
    pub fn open(backend: Backend) -> Result<Self> {
        Ok(match backend {
            Backend::Gpu => SplatRenderer::Gpu(Box::new(gpu::GpuRenderer::new()?)),
            Backend::Cpu => SplatRenderer::Cpu(Box::default()),
            Backend::Auto => match gpu::GpuRenderer::new_hardware() {
                Ok(Some(g)) => SplatRenderer::Gpu(Box::new(g)),
                _ => SplatRenderer::Cpu(Box::default()),
            },
        })
    }

    /// Uploads the Gaussians to render (when the selection changes).
    pub fn set_gaussians(&mut self, set: &GaussianSet) -> Result<()> {
        match self {
            SplatRenderer::Gpu(g) => g.set_gaussians(set),
            SplatRenderer::Cpu(c) => {
                c.set_gaussians(set);
                Ok(())
            }
        }
    }

    /// Uploads a world-space scene (render it with the identity frame).
    pub fn set_world_scene(&mut self, scene: &crate::scene::splats::SplatScene) -> Result<()> {
        match self {
            SplatRenderer::Gpu(g) => g.set_world_scene(scene),
            SplatRenderer::Cpu(c) => {
                c.set_world_scene(scene);
                Ok(())
            }
        }
    }

    /// Renders the uploaded Gaussians on `frames`.
    pub fn render(
        &mut self,
        frames: &[TriangleFrame],
        camera: &crate::scene::camera::Camera,
        settings: &settings::RenderSettings,
    ) -> Result<image::RgbImage> {
        match self {
            SplatRenderer::Gpu(g) => g.render(frames, camera, settings),
            SplatRenderer::Cpu(c) => c.render(frames, camera, settings),
        }
    }

    /// Renders a world-space scene uploaded with [`SplatRenderer::set_world_scene`].
    pub fn render_world(
        &mut self,
        camera: &crate::scene::camera::Camera,
        settings: &settings::RenderSettings,
    ) -> Result<image::RgbImage> {
        self.render(&[crate::scene::splats::IDENTITY_FRAME], camera, settings)
    }

    /// Makes the GPU renderer wait after each stage so its stage timings are
    /// exact (slower frames; the CPU renderer's stages are always exact).
    pub fn set_stage_profiling(&mut self, on: bool) {
        if let SplatRenderer::Gpu(g) = self {
            g.profile_stages = on;
        }
    }

    /// Stage timings of the last frame.
    pub fn timings(&self) -> settings::StageTimings {
        match self {
            SplatRenderer::Gpu(g) => g.timings,
            SplatRenderer::Cpu(c) => c.timings,
        }
    }

    /// Gaussians that survived culling in the last frame.
    pub fn visible(&self) -> Option<usize> {
        match self {
            SplatRenderer::Gpu(g) => Some(g.drawn().0 as usize),
            SplatRenderer::Cpu(c) => Some(c.visible()),
        }
    }

    /// What renders: adapter name or "CPU", and anything the device cannot
    /// draw of what was uploaded.
    pub fn description(&self) -> String {
        match self {
            SplatRenderer::Gpu(g) => match g.sh_notice() {
                Some(notice) => format!("wgpu on {} ({notice})", g.adapter_description()),
                None => format!("wgpu on {}", g.adapter_description()),
            },
            SplatRenderer::Cpu(_) => {
                let threads = rayon::current_num_threads();
                format!("CPU renderer ({threads} threads, {})", cpu::lanes_in_use())
            }
        }
    }
}
