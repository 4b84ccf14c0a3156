//! Per-frame projection of prepared Gaussians to screen-space splats: the
//! steps of `render::projection` (the f64 reference), reordered so that what
//! is culled costs least, and in f32 where that is exact enough. The centre is
//! placed in view space in f64 (so scenes far from the origin keep their
//! precision), tested against the near and far planes and, with a bound on
//! its footprint from its largest scale, against the image; only what is left
//! gets its 2D covariance (as sums of squares of L·Lᵀ's factor, so f32 does
//! not cancel) and its colour.

use glam::{DMat3, DVec3, Mat3, Vec3};

use super::fastmath::{ceil, floor};
use super::prepared::Core;
use crate::avatar::binding::TriangleFrame;
use crate::render::projection::{COVARIANCE_DILATION, FRUSTUM_GUARD, RADIUS_SIGMAS};
use crate::scene::camera::Camera;

/// √(2 · 0.3): the dilation's share of a bound on the footprint's σ.
const DILATION_SIGMA_BOUND: f32 = 0.774_596_7;

/// A projected Gaussian in the form the blending loop reads.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Splat {
    /// Centre in pixels.
    pub x: f32,
    /// Centre in pixels.
    pub y: f32,
    /// Inverse 2D covariance (a, b, c) of [[a, b], [b, c]].
    pub conic: [f32; 3],
    /// 1 / a, for solving each row's span without a division.
    pub inv_a: f32,
    /// Opacity.
    pub opacity: f32,
    /// Exponents below this give α < 1/255.
    pub cutoff: f32,
    /// Colour.
    pub rgb: [f32; 3],
    /// Inclusive pixel rectangle of the square footprint, clamped to the
    /// image: x0, y0, x1, y1.
    pub rect: [u16; 4],
}

/// A splat before its colour: where it lands, how deep, and its footprint.
#[derive(Clone, Copy, Debug)]
pub(super) struct Footprint {
    /// The splat, colour still black.
    pub splat: Splat,
    /// Distance along the viewing axis.
    pub depth: f32,
    /// World-space centre minus the eye (for the SH direction).
    pub from_eye: Vec3,
}

/// The camera as the per-frame projection uses it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Projector {
    rotation64: DMat3,
    translation64: DVec3,
    eye64: DVec3,
    rotation: Mat3,
    fx: f32,
    fy: f32,
    cx: f32,
    cy: f32,
    lim_x: f32,
    lim_y: f32,
    near: f32,
    far: f32,
    width: f32,
    height: f32,
    /// √(2 + lim_x² + lim_y²) · max(fx, fy): times a scale over the depth,
    /// a bound on √(trace) of the undilated 2D covariance, in pixels.
    spread_bound: f32,
    /// Multiplier on every scale.
    scale_modifier: f32,
}

impl Projector {
    /// The camera of a frame.
    pub fn new(camera: &Camera, scale_modifier: f32) -> Self {
        let view = camera.view();
        let (fx, fy) = camera.focal_px();
        let (w, h) = (camera.width as f32, camera.height as f32);
        let lim_x = (FRUSTUM_GUARD * 0.5 * w as f64 / fx as f64) as f32;
        let lim_y = (FRUSTUM_GUARD * 0.5 * h as f64 / fy as f64) as f32;
        Self {
            rotation64: DMat3::from_mat4(view.as_dmat4()),
            translation64: view.w_axis.truncate().as_dvec3(),
            eye64: camera.eye.as_dvec3(),
            rotation: Mat3::from_mat4(view),
            fx,
            fy,
            cx: 0.5 * w,
            cy: 0.5 * h,
            lim_x,
            lim_y,
            near: camera.near,
            far: camera.far,
            width: w,
            height: h,
            spread_bound: (2.0 + lim_x * lim_x + lim_y * lim_y).sqrt() * fx.max(fy),
            scale_modifier,
        }
    }

    /// Projects one Gaussian on its frame (`None`: the identity, for
    /// world-space scenes, which skips the frame's arithmetic); `None` when
    /// it cannot touch the image (the reference's culls: behind the near
    /// plane, beyond the far one, degenerate, not finite, or off-screen).
    pub fn project(&self, g: &Core, frame: Option<&TriangleFrame>) -> Option<Footprint> {
        if g.opacity <= 0.0 {
            return None;
        }
        let world = match frame {
            Some(f) => f.scale * (f.rotation * g.position) + f.center,
            None => g.position,
        };
        let view = self.rotation64 * world.as_dvec3() + self.translation64;
        let depth64 = -view.z;
        if !(depth64 >= f64::from(self.near) && depth64 <= f64::from(self.far)) {
            return None;
        }
        let depth = depth64 as f32;
        let inv_depth = 1.0 / depth64;
        let (vx, vy) = ((view.x * inv_depth) as f32, (view.y * inv_depth) as f32);
        let center = [self.cx + self.fx * vx, self.cy - self.fy * vy];
        let k = frame.map_or(1.0, |f| f.scale) * self.scale_modifier;
        // A bound on the footprint before any covariance work: 3σ of the
        // largest scale, dilated (√(s² + 2d) ≤ s + √(2d)), rounded up.
        let sigma_px = self.spread_bound * k.abs() * g.sigma_max / depth;
        let bound = RADIUS_SIGMAS as f32 * (sigma_px + DILATION_SIGMA_BOUND) + 1.0;
        if !self.on_screen(center, bound) {
            return None;
        }
        let (conic, lambda) = self.covariance_2d(g, frame, k, depth, vx, vy)?;
        let three_sigma = ceil(RADIUS_SIGMAS as f32 * lambda.sqrt());
        let visible = (2.0 * lambda * g.log_visible).sqrt();
        let radius = three_sigma.min(visible * (1.0 + 1e-4) + 1e-3);
        if !radius.is_finite() || !self.on_screen(center, radius) {
            return None;
        }
        let rect = pixel_rect(center, radius, self.width, self.height)?;
        Some(Footprint {
            splat: Splat {
                x: center[0],
                y: center[1],
                conic,
                inv_a: 1.0 / conic[0],
                opacity: g.opacity,
                cutoff: -g.log_visible - 1e-6,
                rgb: [0.0; 3],
                rect,
            },
            depth,
            from_eye: (world.as_dvec3() - self.eye64).as_vec3(),
        })
    }

    fn on_screen(&self, center: [f32; 2], radius: f32) -> bool {
        center[0] + radius >= 0.0
            && center[0] - radius <= self.width
            && center[1] + radius >= 0.0
            && center[1] - radius <= self.height
    }

    /// The conic and the larger eigenvalue of the dilated
    /// 2D covariance J·W·(k R_f L)(k R_f L)ᵀ·Wᵀ·Jᵀ + 0.3 I. With v₀, v₁ the
    /// rows of J·W·k R_f L: a = |v₀|² + d, c = |v₁|² + d, b = v₀·v₁ and
    /// det = |v₀ × v₁|² + d(|v₀|² + |v₁|²) + d² (Lagrange's identity), so
    /// nothing cancels.
    fn covariance_2d(
        &self,
        g: &Core,
        frame: Option<&TriangleFrame>,
        k: f32,
        depth: f32,
        vx: f32,
        vy: f32,
    ) -> Option<([f32; 3], f32)> {
        let tx = vx.clamp(-self.lim_x, self.lim_x);
        let ty = vy.clamp(-self.lim_y, self.lim_y);
        let w = self.rotation.transpose();
        // Rows of J·W: J's rows are (fx/z, 0, fx·tx/z) and (0, −fy/z, −fy·ty/z).
        let j0 = (w.x_axis + w.z_axis * tx) * (self.fx / depth);
        let j1 = (w.y_axis + w.z_axis * ty) * (-self.fy / depth);
        // Into the Gaussian's own axes: (J·W·k·R_f·L)ᵀ rows.
        let to_local = |j: Vec3| {
            let r = match frame {
                Some(f) => f.rotation.transpose() * j * k,
                None => j * k,
            };
            Vec3::new(g.factor[0].dot(r), g.factor[1].dot(r), g.factor[2].dot(r))
        };
        let (v0, v1) = (to_local(j0), to_local(j1));
        let d = COVARIANCE_DILATION as f32;
        let (s0, s1) = (v0.length_squared(), v1.length_squared());
        let (a, b, c) = (s0 + d, v0.dot(v1), s1 + d);
        let det = v0.cross(v1).length_squared() + d * (s0 + s1) + d * d;
        if !det.is_finite() || det <= 0.0 {
            return None;
        }
        let mid = 0.5 * (a + c);
        let half_gap = 0.5 * (a - c);
        let lambda = mid + (half_gap * half_gap + b * b).max(0.1).sqrt();
        Some(([c / det, -b / det, a / det], lambda))
    }
}

/// Inclusive pixel range whose centres lie in the square footprint, clamped
/// to the image (pixel i's centre is i + 0.5; images are at most 65,536
/// pixels a side); `None` when empty.
fn pixel_rect(center: [f32; 2], radius: f32, w: f32, h: f32) -> Option<[u16; 4]> {
    let x0 = ceil(center[0] - radius - 0.5).max(0.0);
    let x1 = floor(center[0] + radius - 0.5).min(w - 1.0);
    let y0 = ceil(center[1] - radius - 0.5).max(0.0);
    let y1 = floor(center[1] + radius - 0.5).min(h - 1.0);
    (x0 <= x1 && y0 <= y1).then_some([x0 as u16, y0 as u16, x1 as u16, y1 as u16])
}
