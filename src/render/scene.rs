//! World-space Gaussians ready to render: what the renderers consume.

use glam::{Quat, Vec3};

use crate::avatar::binding::{local_to_world, normalize_quat, TriangleFrame};
use crate::avatar::gaussians::{logit, sh_coefficients, sigmoid, GaussianSet};

/// World-space Gaussians in structure-of-arrays form. `sh` holds
/// `3 · (sh_degree+1)²` floats per Gaussian, coefficient-major (`[coef][channel]`).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplatScene {
    /// Means.
    pub position: Vec<Vec3>,
    /// Unit rotations.
    pub rotation: Vec<Quat>,
    /// Standard deviations along the rotated axes.
    pub scale: Vec<Vec3>,
    /// Opacity in [0, 1] (after the sigmoid).
    pub opacity: Vec<f32>,
    /// SH degree 0..=3.
    pub sh_degree: u8,
    /// SH coefficients.
    pub sh: Vec<f32>,
}

impl SplatScene {
    /// An empty scene of the given SH degree.
    pub fn with_degree(sh_degree: u8) -> Self {
        Self {
            sh_degree,
            ..Self::default()
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.position.len()
    }

    /// True when there are no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.position.is_empty()
    }

    /// Floats of SH per Gaussian.
    pub fn sh_stride(&self) -> usize {
        3 * sh_coefficients(self.sh_degree)
    }

    /// SH coefficients of Gaussian `i`.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let s = self.sh_stride();
        &self.sh[i * s..(i + 1) * s]
    }

    /// Appends one Gaussian; `sh` may hold more coefficients than the scene's degree
    /// (extra are dropped) or fewer (missing are zero).
    pub fn push(&mut self, position: Vec3, rotation: Quat, scale: Vec3, opacity: f32, sh: &[f32]) {
        self.position.push(position);
        self.rotation.push(normalize_quat(rotation));
        self.scale.push(scale);
        self.opacity.push(opacity);
        let stride = self.sh_stride();
        let take = stride.min(sh.len());
        self.sh.extend_from_slice(&sh[..take]);
        self.sh.extend(std::iter::repeat_n(0.0, stride - take));
    }

    /// Axis-aligned bounds of the means (None when empty or all non-finite).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.position.iter().filter(|p| p.is_finite());
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p))))
    }

    /// The scene as Gaussians bound to one identity frame ([`IDENTITY_FRAME`]), so a
    /// world-space scene goes through the same renderer path as a composite.
    pub fn as_bound_to_identity(&self) -> GaussianSet {
        let mut set = GaussianSet::with_degree(self.sh_degree);
        set.reserve(self.len());
        for i in 0..self.len() {
            set.push(
                0,
                self.position[i],
                self.rotation[i],
                self.scale[i].max(Vec3::splat(1e-30)).ln(),
                logit(self.opacity[i]),
                self.sh_of(i),
            );
        }
        set
    }

    /// Appends the Gaussians `indices` of a bound set, placed on `frames`.
    pub fn append_bound(&mut self, set: &GaussianSet, frames: &[TriangleFrame], indices: &[u32]) {
        for &i in indices {
            let i = i as usize;
            let frame = &frames[set.binding[i] as usize];
            let g = local_to_world(frame, set.position[i], set.rotation[i], set.log_scale[i]);
            self.push(
                g.position,
                g.rotation,
                g.scale,
                sigmoid(set.opacity_logit[i]),
                set.sh_of(i),
            );
        }
    }
}

/// The frame that leaves triangle-local values as they are (world = local).
pub const IDENTITY_FRAME: TriangleFrame = TriangleFrame {
    center: Vec3::ZERO,
    rotation: glam::Mat3::IDENTITY,
    quat: Quat::IDENTITY,
    scale: 1.0,
};
