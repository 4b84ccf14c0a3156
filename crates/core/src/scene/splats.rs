//! World-space Gaussians ready to render: what the renderers consume.

use std::sync::Arc;

use glam::{Quat, Vec3};

use crate::avatar::binding::{local_to_world, normalize_quat, TriangleFrame};
use crate::avatar::gaussians::{sh_coefficients, sigmoid, GaussianSet};
use crate::scene::camera::{Orbit, UpAxis};

/// Share of the opacity-weighted means left out on each side of each axis
/// when framing a scene ([`SplatScene::robust_bounds`]).
pub const FRAMING_QUANTILE: f64 = 0.01;

/// The largest opacity a renderer honours. A scene file's Gaussians stay
/// at or below 1; a level-of-detail node that stands for overlapping
/// Gaussians may carry more (`render::lod`): its core saturates at the
/// renderers' α cap and its reach widens, as the union of the splats it
/// replaces does, where an opacity of 1 would leave a soft, see-through
/// edge between neighbouring nodes.
pub const MAX_OPACITY: f32 = 8.0;

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
    /// Opacity after the sigmoid: in [0, 1] for a scene's own Gaussians, up
    /// to [`MAX_OPACITY`] for level-of-detail nodes.
    pub opacity: Vec<f32>,
    /// SH degree 0..=3.
    pub sh_degree: u8,
    /// SH coefficients: three quarters of a degree-3 scene's bytes, so the
    /// CPU renderer shares them rather than copying (copy-on-write through
    /// `Arc::make_mut` should anything change them while they are shared).
    pub sh: Arc<Vec<f32>>,
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
        let all = Arc::make_mut(&mut self.sh);
        all.extend_from_slice(&sh[..take]);
        all.extend(std::iter::repeat_n(0.0, stride - take));
    }

    /// Sets the number of Gaussians to `len`, new ones all zero with the
    /// identity rotation: room for a reader to fill in place.
    pub fn resize_zeroed(&mut self, len: usize) {
        let stride = self.sh_stride();
        self.position.resize(len, Vec3::ZERO);
        self.rotation.resize(len, Quat::IDENTITY);
        self.scale.resize(len, Vec3::ZERO);
        self.opacity.resize(len, 0.0);
        Arc::make_mut(&mut self.sh).resize(len * stride, 0.0);
    }

    /// Axis-aligned bounds of the means (None when empty or all non-finite).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let mut it = self.position.iter().filter(|p| p.is_finite());
        let first = *it.next()?;
        Some(it.fold((first, first), |(lo, hi), p| (lo.min(*p), hi.max(*p))))
    }

    /// Bounds of the subject, ignoring floaters (the stray splats trained
    /// scenes carry far from everything else): per axis, the opacity-weighted
    /// [`FRAMING_QUANTILE`] and 1 − that quantile of the means give a core box;
    /// the result is the bounding box of the means within that core box grown
    /// by half its size on every side, so the subject's fringe stays in and a
    /// splat tens of units away does not. None when no mean is finite.
    pub fn robust_bounds(&self) -> Option<(Vec3, Vec3)> {
        let points: Vec<(Vec3, f32)> = self
            .position
            .iter()
            .zip(&self.opacity)
            .filter(|(p, _)| p.is_finite())
            .map(|(p, o)| (*p, if o.is_finite() { o.max(0.0) } else { 0.0 }))
            .collect();
        if points.is_empty() {
            return None;
        }
        let total: f64 = points.iter().map(|(_, w)| *w as f64).sum();
        // A scene of fully transparent splats still gets framed, by count.
        let weight = |w: f32| if total > 0.0 { w as f64 } else { 1.0 };
        let total = if total > 0.0 {
            total
        } else {
            points.len() as f64
        };
        let mut lo = Vec3::ZERO;
        let mut hi = Vec3::ZERO;
        for axis in 0..3 {
            let mut values: Vec<(f32, f64)> =
                points.iter().map(|(p, w)| (p[axis], weight(*w))).collect();
            values.sort_by(|a, b| a.0.total_cmp(&b.0));
            let at = |q: f64| {
                let mut seen = 0.0;
                for (v, w) in &values {
                    seen += w;
                    if seen >= q * total {
                        return *v;
                    }
                }
                values.last().map_or(0.0, |v| v.0)
            };
            lo[axis] = at(FRAMING_QUANTILE);
            hi[axis] = at(1.0 - FRAMING_QUANTILE);
        }
        let margin = 0.5 * (hi - lo);
        let (core_lo, core_hi) = (lo - margin, hi + margin);
        let inside = points
            .iter()
            .map(|(p, _)| *p)
            .filter(|p| p.cmpge(core_lo).all() && p.cmple(core_hi).all());
        let first = inside.clone().next()?;
        Some(inside.fold((first, first), |(a, b), p| (a.min(p), b.max(p))))
    }

    /// The camera a scene opens with: a field of view of `fov_deg` (40° when
    /// None) from the front of the orbit's frame, with `up` on screen, framing
    /// the subject without its floaters ([`SplatScene::robust_bounds`]). None
    /// for a scene without a finite mean.
    pub fn home_orbit(&self, fov_deg: Option<f32>, up: UpAxis) -> Option<Orbit> {
        let (lo, hi) = self.robust_bounds()?;
        let start = Orbit {
            fov_deg: fov_deg.unwrap_or(40.0),
            up,
            ..Orbit::STUDY
        };
        Some(start.framing(lo, hi))
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

#[cfg(test)]
mod tests {
    use super::*;

    fn cloud(n: usize) -> SplatScene {
        let mut s = SplatScene::with_degree(0);
        for i in 0..n {
            // A deterministic spread over the unit cube.
            let f = |k: u32| ((i as u32).wrapping_mul(k) % 1000) as f32 / 999.0 * 2.0 - 1.0;
            s.push(
                Vec3::new(f(7919), f(104_729), f(1_299_709)),
                Quat::IDENTITY,
                Vec3::splat(0.01),
                0.8,
                &[0.5; 3],
            );
        }
        s
    }

    #[test]
    fn robust_bounds_ignore_floaters_and_keep_the_subject() {
        let mut s = cloud(14_000);
        let (lo, hi) = s.robust_bounds().unwrap();
        assert!(
            lo.cmple(Vec3::splat(-0.99)).all() && hi.cmpge(Vec3::splat(0.99)).all(),
            "{lo} {hi}"
        );
        // Two splats 24 units away, as in a real trained scene.
        s.push(
            Vec3::new(24.0, 3.0, -2.0),
            Quat::IDENTITY,
            Vec3::ONE,
            0.9,
            &[0.0; 3],
        );
        s.push(
            Vec3::new(-20.0, 24.0, 1.0),
            Quat::IDENTITY,
            Vec3::ONE,
            0.9,
            &[0.0; 3],
        );
        assert!(s.bounds().unwrap().1.x >= 24.0);
        let (lo2, hi2) = s.robust_bounds().unwrap();
        assert_eq!((lo2, hi2), (lo, hi), "the floaters change nothing");
    }

    #[test]
    fn robust_bounds_of_hard_cases() {
        let mut s = SplatScene::with_degree(0);
        assert_eq!(s.robust_bounds(), None);
        s.push(Vec3::NAN, Quat::IDENTITY, Vec3::ONE, 0.5, &[0.0; 3]);
        assert_eq!(s.robust_bounds(), None, "only non-finite means");
        s.push(
            Vec3::new(1.0, 2.0, 3.0),
            Quat::IDENTITY,
            Vec3::ONE,
            0.0,
            &[0.0; 3],
        );
        assert_eq!(
            s.robust_bounds(),
            Some((Vec3::new(1.0, 2.0, 3.0), Vec3::new(1.0, 2.0, 3.0))),
            "one transparent splat is framed by count"
        );
        let mut huge = cloud(100);
        for p in &mut huge.position {
            *p = *p * 1e6 + Vec3::splat(1e7);
        }
        let (lo, hi) = huge.robust_bounds().unwrap();
        assert!(lo.is_finite() && hi.is_finite() && (hi - lo).min_element() > 1e6);
    }
}
