//! The trainer's hyperparameters and their schedule.

/// Hyperparameters: GaussianAvatars' (`arguments/__init__.py`), with its
/// iteration counts scaled to `iterations`.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Position learning rate at the start and the end (× scene extent).
    pub position_lr: [f64; 2],
    /// SH DC learning rate (the rest use a twentieth).
    pub feature_lr: f64,
    /// Opacity learning rate.
    pub opacity_lr: f64,
    /// Log-scale learning rate.
    pub scaling_lr: f64,
    /// Rotation learning rate.
    pub rotation_lr: f64,
    /// SH degree up every this many iterations.
    pub sh_interval: usize,
    /// Densify every this many iterations …
    pub densify_interval: usize,
    /// … from this iteration …
    pub densify_from: usize,
    /// … until this one.
    pub densify_until: usize,
    /// Opacity reset every this many iterations.
    pub opacity_reset_interval: usize,
    /// Clone or split above this view-space gradient (NDC units).
    pub densify_grad_threshold: f64,
    /// Clone below / split above this share of the scene extent (world scale).
    pub percent_dense: f64,
    /// Weight of the local-position regulariser and its threshold.
    pub xyz: [f64; 2],
    /// Weight of the local-scale regulariser and its threshold.
    pub scale: [f64; 2],
}

impl Schedule {
    /// GaussianAvatars' schedule compressed to `iterations`.
    pub fn for_iterations(iterations: usize) -> Self {
        let at = |fraction: f64| ((iterations as f64 * fraction).round() as usize).max(1);
        Schedule {
            position_lr: [0.005, 0.00005],
            feature_lr: 0.0025,
            opacity_lr: 0.05,
            scaling_lr: 0.017,
            rotation_lr: 0.001,
            // GaussianAvatars raises it every 1000 of 600k; a short run would
            // never reach degree 3 at that rate, so every 8 %.
            sh_interval: at(0.08),
            densify_interval: at(0.04),
            densify_from: at(0.1),
            densify_until: at(0.8),
            opacity_reset_interval: at(0.3),
            densify_grad_threshold: 0.0002,
            percent_dense: 0.01,
            xyz: [0.01, 1.0],
            scale: [1.0, 0.6],
        }
    }

    /// The position learning rate at `step` (log-linear from start to end).
    pub fn position_lr_at(&self, step: usize, iterations: usize, extent: f64) -> f64 {
        let t = (step as f64 / iterations.max(1) as f64).clamp(0.0, 1.0);
        let [a, b] = self.position_lr.map(|x| (x * extent).ln());
        ((1.0 - t) * a + t * b).exp()
    }
}
