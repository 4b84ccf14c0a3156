//! Projection of 3D Gaussians to screen-space ellipses, following the reference
//! 3DGS rasteriser (EWA splatting): 2D covariance J·W·Σ·Wᵀ·Jᵀ dilated by 0.3 px²,
//! a square footprint of 3σ of the major axis (tighter where the opacity makes
//! α fall below 1/255 sooner: [`footprint_radius`]), near-plane culling. The GPU
//! kernels implement the same steps in f32 (`shaders/project.wgsl`); this is the
//! f64 version used by the reference renderer.
//!
//! A Gaussian contributes to a pixel iff the pixel centre lies inside its square
//! footprint, the exponent is ≤ 0 and α = min(0.99, o·exp(power)) ≥ 1/255. Pixel
//! (i, j) has its centre at (i + 0.5, j + 0.5).

use glam::{DMat3, DVec3, Quat, Vec3};

use crate::scene::camera::Camera;

/// Dilation added to the 2D covariance (pixels²).
pub const COVARIANCE_DILATION: f64 = 0.3;
/// Footprint radius in standard deviations of the major axis.
pub const RADIUS_SIGMAS: f64 = 3.0;
/// Largest alpha a single Gaussian may have.
pub const MAX_ALPHA: f64 = 0.99;
/// Alphas below this are skipped.
pub const MIN_ALPHA: f64 = 1.0 / 255.0;
/// A pixel stops accumulating once its transmittance would fall below this.
pub const MIN_TRANSMITTANCE: f64 = 1e-4;
/// The Jacobian is evaluated with x/z and y/z clamped to this multiple of the
/// half field of view (keeps off-screen Gaussians from exploding).
pub const FRUSTUM_GUARD: f64 = 1.3;

/// Footprint half-size in pixels for a splat whose 2D covariance has largest
/// eigenvalue `lambda` and whose opacity is `opacity`: 3σ of the major axis
/// rounded up (3DGS), or less where α = o·e^power falls below 1/255 sooner —
/// beyond σ·√(2 ln(255·o)) along any axis it does, and such pixels are skipped
/// anyway, so the image is the same and faint splats touch fewer pixels and
/// tiles. The small margin keeps rounding from dropping a pixel that counts.
pub fn footprint_radius(lambda: f64, opacity: f64) -> f64 {
    let three_sigma = (RADIUS_SIGMAS * lambda.sqrt()).ceil();
    let visible = (2.0 * lambda * (opacity / MIN_ALPHA).ln()).max(0.0).sqrt();
    three_sigma.min(visible * (1.0 + 1e-4) + 1e-3)
}

/// A Gaussian projected to the image.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat2D {
    /// Centre in pixels.
    pub center: [f64; 2],
    /// Inverse 2D covariance (a, b, c) for [[a, b], [b, c]].
    pub conic: [f64; 3],
    /// Footprint half-size in pixels.
    pub radius: f64,
    /// Distance along the viewing axis.
    pub depth: f64,
}

/// Camera data in f64 for projection.
#[derive(Clone, Copy, Debug)]
pub struct ProjectionCamera {
    rotation: DMat3,
    translation: DVec3,
    /// Camera position (world).
    pub eye: DVec3,
    fx: f64,
    fy: f64,
    cx: f64,
    cy: f64,
    tan_half_x: f64,
    tan_half_y: f64,
    near: f64,
    far: f64,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
}

impl ProjectionCamera {
    /// Prepares a camera.
    pub fn new(camera: &Camera) -> Self {
        let view = camera.view().as_dmat4();
        let (fx, fy) = camera.focal_px();
        let (w, h) = (camera.width as f64, camera.height as f64);
        Self {
            rotation: DMat3::from_mat4(view),
            translation: view.w_axis.truncate(),
            eye: camera.eye.as_dvec3(),
            fx: fx as f64,
            fy: fy as f64,
            cx: 0.5 * w,
            cy: 0.5 * h,
            tan_half_x: 0.5 * w / fx as f64,
            tan_half_y: 0.5 * h / fy as f64,
            near: camera.near as f64,
            far: camera.far as f64,
            width: camera.width,
            height: camera.height,
        }
    }

    /// Projects one Gaussian; `None` when culled (behind the near plane, beyond the
    /// far plane, degenerate, non-finite or entirely off-screen).
    pub fn project(
        &self,
        position: Vec3,
        rotation: Quat,
        scale: Vec3,
        opacity: f64,
    ) -> Option<Splat2D> {
        let p = self.rotation * position.as_dvec3() + self.translation;
        let depth = -p.z;
        if !(depth >= self.near && depth <= self.far) {
            return None;
        }
        let r = DMat3::from_quat(rotation.as_dquat().normalize());
        let s = scale.as_dvec3();
        if !s.is_finite() || !r.is_finite() {
            return None;
        }
        let m = r * DMat3::from_diagonal(s);
        self.project_view(p, m * m.transpose(), opacity)
    }

    /// Projects a Gaussian given by its centre and world covariance (for
    /// renderers that prepare covariances ahead of the frame).
    pub fn project_covariance(
        &self,
        position: Vec3,
        cov_world: DMat3,
        opacity: f64,
    ) -> Option<Splat2D> {
        let p = self.rotation * position.as_dvec3() + self.translation;
        let depth = -p.z;
        if !(depth >= self.near && depth <= self.far && cov_world.is_finite()) {
            return None;
        }
        self.project_view(p, cov_world, opacity)
    }

    /// The rest of the projection, from the view-space centre `p` (in front
    /// of the camera, checked) and the world covariance.
    fn project_view(&self, p: DVec3, cov_world: DMat3, opacity: f64) -> Option<Splat2D> {
        let depth = -p.z;
        let cov_view = self.rotation * cov_world * self.rotation.transpose();
        let lim_x = FRUSTUM_GUARD * self.tan_half_x;
        let lim_y = FRUSTUM_GUARD * self.tan_half_y;
        let tx = (p.x / depth).clamp(-lim_x, lim_x);
        let ty = (p.y / depth).clamp(-lim_y, lim_y);
        // Rows of the Jacobian of (u, v) with respect to view-space (x, y, z).
        let j0 = DVec3::new(self.fx / depth, 0.0, self.fx * tx / depth);
        let j1 = DVec3::new(0.0, -self.fy / depth, -self.fy * ty / depth);
        let a = j0.dot(cov_view * j0) + COVARIANCE_DILATION;
        let b = j0.dot(cov_view * j1);
        let c = j1.dot(cov_view * j1) + COVARIANCE_DILATION;
        let det = a * c - b * b;
        if det.is_nan() || det <= 0.0 || !det.is_finite() {
            return None;
        }
        let mid = 0.5 * (a + c);
        let lambda = mid + (mid * mid - det).max(0.1).sqrt();
        let radius = footprint_radius(lambda, opacity);
        let center = [
            self.cx + self.fx * p.x / depth,
            self.cy - self.fy * p.y / depth,
        ];
        let (w, h) = (self.width as f64, self.height as f64);
        if !radius.is_finite()
            || center[0] + radius < 0.0
            || center[0] - radius > w
            || center[1] + radius < 0.0
            || center[1] - radius > h
        {
            return None;
        }
        Some(Splat2D {
            center,
            conic: [c / det, -b / det, a / det],
            radius,
            depth,
        })
    }
}

impl Splat2D {
    /// Alpha of this splat at a pixel centre, or 0 when it does not contribute.
    pub fn alpha_at(&self, opacity: f64, px: f64, py: f64) -> f64 {
        let dx = px - self.center[0];
        let dy = py - self.center[1];
        if dx.abs() > self.radius || dy.abs() > self.radius {
            return 0.0;
        }
        let [a, b, c] = self.conic;
        let power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy;
        if power > 0.0 {
            return 0.0;
        }
        let alpha = (opacity * power.exp()).min(MAX_ALPHA);
        if alpha < MIN_ALPHA {
            0.0
        } else {
            alpha
        }
    }

    /// Inclusive pixel range covered by the footprint, clamped to the image.
    pub fn pixel_rect(&self, width: u32, height: u32) -> Option<(u32, u32, u32, u32)> {
        // Pixel i's centre is i + 0.5; include i when |i + 0.5 - cx| <= radius.
        let x0 = (self.center[0] - self.radius - 0.5).ceil().max(0.0);
        let x1 = (self.center[0] + self.radius - 0.5)
            .floor()
            .min(width as f64 - 1.0);
        let y0 = (self.center[1] - self.radius - 0.5).ceil().max(0.0);
        let y1 = (self.center[1] + self.radius - 0.5)
            .floor()
            .min(height as f64 - 1.0);
        (x0 <= x1 && y0 <= y1).then_some((x0 as u32, y0 as u32, x1 as u32, y1 as u32))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Of the pixels the 3σ footprint covers, the tighter one drops only those
    /// whose α is below 1/255 — ones the blend skips anyway — and it is never
    /// wider than 3σ: sub-pixel splats,
    /// elongated ones, faint and opaque ones, opacities under 1/255.
    #[test]
    fn the_footprint_keeps_every_pixel_that_counts() {
        let mut state = 12345u64;
        let mut uniform = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut checked = 0;
        for _ in 0..20_000 {
            // A 2D covariance: rotation, two variances (dilated as projected).
            let angle = uniform() * std::f64::consts::PI;
            let (s1, s2) = (0.3 + uniform() * 20.0, 0.3 + uniform().powi(3) * 2.0);
            let (c, s) = (angle.cos(), angle.sin());
            let (a, b, cc) = (
                c * c * s1 + s * s * s2,
                c * s * (s1 - s2),
                s * s * s1 + c * c * s2,
            );
            let det = a * cc - b * b;
            let mid = 0.5 * (a + cc);
            let lambda = mid + (mid * mid - det).max(0.1).sqrt();
            let opacity = uniform().powi(2);
            let radius = footprint_radius(lambda, opacity);
            let three_sigma = (RADIUS_SIGMAS * lambda.sqrt()).ceil();
            assert!(radius <= three_sigma);
            let conic = [cc / det, -b / det, a / det];
            for _ in 0..20 {
                let (dx, dy) = (
                    (uniform() - 0.5) * 6.0 * radius.max(1.0),
                    (uniform() - 0.5) * 6.0 * radius.max(1.0),
                );
                let inside = |r: f64| dx.abs() <= r && dy.abs() <= r;
                // Only what 3σ kept and the tighter footprint drops.
                if inside(radius) || !inside(three_sigma) {
                    continue;
                }
                let power = -0.5 * (conic[0] * dx * dx + conic[2] * dy * dy) - conic[1] * dx * dy;
                assert!(
                    opacity * power.exp() < MIN_ALPHA,
                    "a pixel at ({dx}, {dy}) outside radius {radius} counts"
                );
                checked += 1;
            }
        }
        assert!(checked > 10_000, "{checked} pixels between the footprints");
    }
}
