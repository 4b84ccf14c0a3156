//! What every renderer shares, whichever draws: the settings a frame is drawn
//! with and the time each stage took.

use super::projection::MIN_TRANSMITTANCE;

/// Settings shared by the renderers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Background colour (0..1).
    pub background: [f32; 3],
    /// Highest SH degree evaluated (the scene's own degree caps it).
    pub sh_degree: u8,
    /// Multiplier on every Gaussian's scale (debug view); 1 for normal renders.
    pub scale_modifier: f32,
    /// A pixel stops once its transmittance would fall below this (3DGS: 1e-4).
    /// GPU renderer only; the reference always uses 1e-4.
    pub early_stop: f32,
    /// Bits of the depth key used for sorting (8-32, 32 = exact f32 order).
    /// GPU renderer only.
    pub sort_bits: u8,
}

impl Default for RenderSettings {
    fn default() -> Self {
        Self {
            background: [0.0, 0.0, 0.0],
            sh_degree: 3,
            scale_modifier: 1.0,
            early_stop: MIN_TRANSMITTANCE as f32,
            sort_bits: 32,
        }
    }
}

impl RenderSettings {
    /// The interactive preset, on the speed/error Pareto front measured by
    /// `visage bench render`: pixels stop at transmittance 1e-3 instead of 1e-4
    /// (~10% faster on the CPU renderer, 57 dB against the reference).
    pub fn interactive() -> Self {
        Self {
            early_stop: 1e-3,
            ..Self::default()
        }
    }
}

/// Wall-clock milliseconds of each stage of the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimings {
    /// Frame upload.
    pub upload: f64,
    /// bind + project kernels.
    pub project: f64,
    /// Depth sort and tile binning kernels.
    pub sort: f64,
    /// rasterize kernel.
    pub rasterize: f64,
    /// Image read-back and conversion.
    pub readback: f64,
}

impl StageTimings {
    /// Sum of the stages.
    pub fn total(&self) -> f64 {
        self.upload + self.project + self.sort + self.rasterize + self.readback
    }
}
