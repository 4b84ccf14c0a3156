//! What the CPU renderer keeps of the uploaded Gaussians: everything no frame
//! changes, computed once per upload and laid out for one streaming pass per
//! frame. The per-Gaussian numbers the projection reads for every Gaussian
//! fill one 64-byte record; the colour, read only for Gaussians that survive
//! culling, lives apart.

use std::sync::Arc;

use glam::{Mat3, Quat, Vec3};
use rayon::prelude::*;

use crate::avatar::binding::normalize_quat;
use crate::avatar::gaussians::{sh_coefficients, sigmoid, GaussianSet};
use crate::render::projection::MIN_ALPHA;
use crate::scene::splats::{SplatScene, MAX_OPACITY};

/// One Gaussian as the projection reads it, in its triangle's frame.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Core {
    /// Centre in the triangle's frame.
    pub position: Vec3,
    /// Triangle the Gaussian rides on.
    pub binding: u32,
    /// R·S (rotation times the diagonal scale), columns: the covariance is
    /// L·Lᵀ, and keeping the factor lets the projection form the 2D
    /// covariance as sums of squares, free of cancellation in f32.
    pub factor: [Vec3; 3],
    /// Opacity after the sigmoid, in (1/255, 1]; 0 marks a Gaussian that can
    /// never reach α = 1/255 (or is not a number), culled before any work.
    pub opacity: f32,
    /// ln(opacity · 255): α = o·e^power falls below 1/255 where power < −this.
    pub log_visible: f32,
    /// The largest standard deviation (scale), for culling off-screen
    /// Gaussians before their covariance is projected.
    pub sigma_max: f32,
}

impl Core {
    fn new(position: Vec3, binding: u32, rotation: Quat, scale: Vec3, opacity: f32) -> Self {
        let m = Mat3::from_quat(normalize_quat(rotation)) * Mat3::from_diagonal(scale);
        let opacity = opacity.min(MAX_OPACITY);
        let usable = opacity >= MIN_ALPHA as f32 && m.is_finite() && position.is_finite();
        let opacity = if usable { opacity } else { 0.0 };
        Self {
            position,
            binding,
            factor: [m.x_axis, m.y_axis, m.z_axis],
            opacity,
            log_visible: (opacity * 255.0).ln().max(0.0),
            sigma_max: scale.abs().max_element(),
        }
    }
}

/// The uploaded Gaussians, prepared.
#[derive(Clone, Debug, Default)]
pub(super) struct Prepared {
    /// One record per Gaussian.
    pub core: Vec<Core>,
    /// SH coefficients, coefficient-major `[coef][rgb]`, `sh_stride` per
    /// Gaussian; a world scene's own, shared rather than copied.
    pub sh: Arc<Vec<f32>>,
    /// Floats of SH per Gaussian.
    pub sh_stride: usize,
    /// The SH degree stored.
    pub sh_degree: u8,
}

impl Prepared {
    /// Prepares triangle-bound Gaussians (the editor's composites).
    pub fn of_set(set: &GaussianSet) -> Self {
        Self::build(set.len(), Arc::new(set.sh.clone()), set.sh_degree, |i| {
            Core::new(
                set.position[i],
                set.binding[i],
                set.rotation[i],
                set.log_scale[i].exp(),
                sigmoid(set.opacity_logit[i]),
            )
        })
    }

    /// Prepares a world-space scene (rendered on the identity frame) straight
    /// from its scales and opacities, without a round trip through logs.
    pub fn of_scene(scene: &SplatScene) -> Self {
        Self::build(scene.len(), Arc::clone(&scene.sh), scene.sh_degree, |i| {
            Core::new(
                scene.position[i],
                0,
                scene.rotation[i],
                scene.scale[i],
                scene.opacity[i],
            )
        })
    }

    /// `count` records made by `core` in parallel, beside the SH.
    fn build(
        count: usize,
        sh: Arc<Vec<f32>>,
        sh_degree: u8,
        core: impl Fn(usize) -> Core + Sync + Send,
    ) -> Self {
        Self {
            core: (0..count)
                .into_par_iter()
                .with_min_len(4096)
                .map(core)
                .collect(),
            sh,
            sh_stride: 3 * sh_coefficients(sh_degree),
            sh_degree,
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.core.len()
    }

    /// SH coefficients of Gaussian `i`.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        &self.sh[i * self.sh_stride..(i + 1) * self.sh_stride]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A million-Gaussian scene's SH is three quarters of its bytes: the
    /// upload must share it, and a later edit of the scene must not reach
    /// what was uploaded.
    #[test]
    fn a_world_scene_shares_its_sh_and_edits_copy_on_write() {
        let mut scene = SplatScene::with_degree(1);
        let sh: Vec<f32> = (0..12).map(|k| k as f32 * 0.1).collect();
        scene.push(Vec3::ZERO, Quat::IDENTITY, Vec3::splat(0.1), 0.5, &sh);
        let prepared = Prepared::of_scene(&scene);
        assert!(Arc::ptr_eq(&prepared.sh, &scene.sh));
        assert_eq!(prepared.sh_of(0), &sh[..]);

        scene.push(Vec3::ONE, Quat::IDENTITY, Vec3::splat(0.1), 0.5, &sh);
        assert_eq!(scene.sh.len(), 24);
        assert_eq!(prepared.sh.len(), 12);
        assert_eq!(prepared.sh_of(0), &sh[..]);
    }
}
