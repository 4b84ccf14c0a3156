//! Per-frame projection of prepared Gaussians to screen-space splats: the
//! steps of `render::projection` (the f64 reference), reordered so that what
//! is culled costs least, and in f32 where that is exact enough. The centre is
//! placed in view space in f64 (so scenes far from the origin keep their
//! precision), tested against the near and far planes and, with a bound on
//! its footprint from its largest scale, against the image; only what is left
//! gets its 2D covariance (as sums of squares of L·Lᵀ's factor, so f32 does
//! not cancel) and its colour. Everything after the f64 placement runs on
//! eight Gaussians at once in `wide`'s f32x8 lanes, which the SSE2 baseline
//! executes as two four-wide halves.

use glam::{DMat3, DVec3, Mat3, Vec3};

use wide::f32x8;

use super::fastmath::{ceil_lanes, floor_lanes};
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

/// What projecting a batch leaves beside the splats it wrote.
#[derive(Clone, Copy, Debug)]
pub(super) struct Projected {
    /// Lanes (bits) whose Gaussian can touch the image: their splats were
    /// written, colour still black.
    pub live: u32,
    /// Distance along the viewing axis.
    pub depth: [f32; LANES],
    /// World-space centre minus the eye (for the SH direction).
    pub from_eye: [Vec3; LANES],
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

/// Gaussians projected together: the covariance and footprint arithmetic
/// runs on this many lanes at once (`wide`'s f32x8: two SSE registers on
/// x86-64's baseline, one AVX register where the build enables it).
pub(super) const LANES: usize = 8;

/// Three lanes-wide coordinates.
#[derive(Clone, Copy)]
struct Lanes3 {
    x: f32x8,
    y: f32x8,
    z: f32x8,
}

impl Lanes3 {
    fn splat(v: Vec3) -> Self {
        Self {
            x: f32x8::splat(v.x),
            y: f32x8::splat(v.y),
            z: f32x8::splat(v.z),
        }
    }

    fn from_lanes(v: &[Vec3; LANES]) -> Self {
        Self {
            x: f32x8::new(v.map(|v| v.x)),
            y: f32x8::new(v.map(|v| v.y)),
            z: f32x8::new(v.map(|v| v.z)),
        }
    }

    fn dot(self, o: Self) -> f32x8 {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    fn scaled(self, k: f32x8) -> Self {
        Self {
            x: self.x * k,
            y: self.y * k,
            z: self.z * k,
        }
    }

    fn length_squared(self) -> f32x8 {
        self.dot(self)
    }

    fn cross(self, o: Self) -> Self {
        Self {
            x: self.y * o.z - self.z * o.y,
            y: self.z * o.x - self.x * o.z,
            z: self.x * o.y - self.y * o.x,
        }
    }
}

/// A batch's centres placed in view space (per lane, in f64), with what the
/// lane-wide arithmetic reads; lanes that are already culled hold harmless
/// numbers and a clear bit in `alive`.
struct Placed {
    alive: u32,
    depth: [f32; LANES],
    vx: [f32; LANES],
    vy: [f32; LANES],
    /// The frame's scale times the scale modifier.
    k: [f32; LANES],
    sigma_max: [f32; LANES],
    log_visible: [f32; LANES],
    /// Columns of each lane's covariance factor L.
    factor: [[Vec3; LANES]; 3],
    /// Columns of each lane's frame rotation (unused for world scenes).
    frame_rotation: [[Vec3; LANES]; 3],
    /// World-space centre minus the eye.
    from_eye: [Vec3; LANES],
}

impl Placed {
    fn empty() -> Self {
        Self {
            alive: 0,
            depth: [1.0; LANES],
            vx: [0.0; LANES],
            vy: [0.0; LANES],
            k: [0.0; LANES],
            sigma_max: [0.0; LANES],
            log_visible: [0.0; LANES],
            factor: [[Vec3::ZERO; LANES]; 3],
            frame_rotation: [[Vec3::ZERO; LANES]; 3],
            from_eye: [Vec3::ZERO; LANES],
        }
    }
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

    /// Projects up to [`LANES`] Gaussians, each on its triangle's frame
    /// (`frames` is `None` for world-space scenes, which skips the frames'
    /// arithmetic), into `splats` (one per Gaussian, written in place: a
    /// batch's eight returned by value cost a copy of each); a lane is not
    /// live when its Gaussian cannot touch the image (the reference's
    /// culls: behind the near plane, beyond the far one, degenerate, not
    /// finite, or off-screen), and its splat is left as it was.
    pub fn project_batch(
        &self,
        cores: &[Core],
        frames: Option<&[TriangleFrame]>,
        splats: &mut [Splat],
    ) -> Projected {
        let placed = self.place(cores, frames);
        let mut out = Projected {
            live: 0,
            depth: placed.depth,
            from_eye: placed.from_eye,
        };
        if placed.alive == 0 {
            return out;
        }
        let depth = f32x8::new(placed.depth);
        let vx = f32x8::new(placed.vx);
        let vy = f32x8::new(placed.vy);
        let k = f32x8::new(placed.k);
        let center_x = f32x8::splat(self.cx) + f32x8::splat(self.fx) * vx;
        let center_y = f32x8::splat(self.cy) - f32x8::splat(self.fy) * vy;
        // A bound on the footprint before any covariance work: 3σ of the
        // largest scale, dilated (√(s² + 2d) ≤ s + √(2d)), rounded up.
        let sigma_px =
            f32x8::splat(self.spread_bound) * k.abs() * f32x8::new(placed.sigma_max) / depth;
        let bound = f32x8::splat(RADIUS_SIGMAS as f32)
            * (sigma_px + f32x8::splat(DILATION_SIGMA_BOUND))
            + f32x8::ONE;
        let near_image = placed.alive & self.on_screen(center_x, center_y, bound);
        if near_image == 0 {
            return out;
        }
        let (conic, lambda, valid, variance) =
            self.covariance_2d(&placed, frames.is_some(), depth, vx, vy);
        let three_sigma = ceil_lanes(f32x8::splat(RADIUS_SIGMAS as f32) * lambda.sqrt());
        let visible = (f32x8::splat(2.0) * lambda * f32x8::new(placed.log_visible)).sqrt();
        let radius = three_sigma.min(visible * f32x8::splat(1.0 + 1e-4) + f32x8::splat(1e-3));
        let finite = radius.is_finite();
        let radius = finite.bitselect(radius, f32x8::ZERO);
        let live =
            near_image & valid & finite.to_bitmask() & self.on_screen(center_x, center_y, radius);
        // The ellipse where α reaches 1/255, |d|² ≤ 2·ln(255·o) in the
        // covariance's metric, reaches ±√(2·ln(255·o)·Σ_xx) across and
        // ±√(2·ln(255·o)·Σ_yy) down (widened a little for rounding): the
        // square's pixels outside that box are never blended, so the splat
        // is listed in the box's tiles only and blends the box's pixels
        // (the GPU's `project` kernel lists the same tiles).
        let reach = f32x8::splat(2.0) * f32x8::new(placed.log_visible);
        let extent = |v: f32x8| {
            radius.min((reach * v).sqrt() * f32x8::splat(1.0 + 1e-3) + f32x8::splat(1e-2))
        };
        let tight = self.pixel_rects(center_x, center_y, variance.map(extent));
        let (x, y) = (center_x.to_array(), center_y.to_array());
        let inv_a = (f32x8::ONE / conic[0]).to_array();
        let conic = conic.map(f32x8::to_array);
        let empty = |edges: &[[f32; LANES]; 4], lane: usize| {
            edges[0][lane] > edges[2][lane] || edges[1][lane] > edges[3][lane]
        };
        for (lane, (g, splat)) in cores.iter().zip(splats).enumerate() {
            // The box lies inside the square, so it is empty wherever the
            // square is.
            if live & (1 << lane) == 0 || empty(&tight, lane) {
                continue;
            }
            out.live |= 1 << lane;
            *splat = Splat {
                x: x[lane],
                y: y[lane],
                conic: [conic[0][lane], conic[1][lane], conic[2][lane]],
                inv_a: inv_a[lane],
                opacity: g.opacity,
                cutoff: -g.log_visible - 1e-6,
                rgb: [0.0; 3],
                rect: tight.map(|e| e[lane] as u16),
            };
        }
        out
    }

    /// Places each lane's centre in view space in f64 (so scenes far from
    /// the origin keep their precision) and culls against the near and far
    /// planes; gathers what the lane-wide arithmetic reads.
    fn place(&self, cores: &[Core], frames: Option<&[TriangleFrame]>) -> Placed {
        let mut p = Placed::empty();
        for (lane, g) in cores.iter().enumerate().take(LANES) {
            if g.opacity <= 0.0 {
                continue;
            }
            let frame = frames.map(|f| &f[(g.binding as usize).min(f.len() - 1)]);
            let world = match frame {
                Some(f) => f.scale * (f.rotation * g.position) + f.center,
                None => g.position,
            };
            let view = self.rotation64 * world.as_dvec3() + self.translation64;
            let depth64 = -view.z;
            if !(depth64 >= f64::from(self.near) && depth64 <= f64::from(self.far)) {
                continue;
            }
            let inv_depth = 1.0 / depth64;
            p.alive |= 1 << lane;
            p.depth[lane] = depth64 as f32;
            p.vx[lane] = (view.x * inv_depth) as f32;
            p.vy[lane] = (view.y * inv_depth) as f32;
            p.k[lane] = frame.map_or(1.0, |f| f.scale) * self.scale_modifier;
            p.sigma_max[lane] = g.sigma_max;
            p.log_visible[lane] = g.log_visible;
            for (column, axis) in p.factor.iter_mut().zip(g.factor) {
                column[lane] = axis;
            }
            if let Some(f) = frame {
                let axes = [f.rotation.x_axis, f.rotation.y_axis, f.rotation.z_axis];
                for (column, axis) in p.frame_rotation.iter_mut().zip(axes) {
                    column[lane] = axis;
                }
            }
            p.from_eye[lane] = (world.as_dvec3() - self.eye64).as_vec3();
        }
        p
    }

    /// Lanes (as a bitmask) whose square of half-side `radius` around the
    /// centre overlaps the image.
    fn on_screen(&self, center_x: f32x8, center_y: f32x8, radius: f32x8) -> u32 {
        let (w, h) = (f32x8::splat(self.width), f32x8::splat(self.height));
        ((center_x + radius).simd_ge(f32x8::ZERO)
            & (center_x - radius).simd_le(w)
            & (center_y + radius).simd_ge(f32x8::ZERO)
            & (center_y - radius).simd_le(h))
        .to_bitmask()
    }

    /// The conic, the larger eigenvalue of the dilated
    /// 2D covariance J·W·(k R_f L)(k R_f L)ᵀ·Wᵀ·Jᵀ + 0.3 I, the lanes
    /// (bitmask) where it is finite and positive definite, and its diagonal
    /// (a, c) for the box the ellipse reaches. With v₀, v₁ the
    /// rows of J·W·k R_f L: a = |v₀|² + d, c = |v₁|² + d, b = v₀·v₁ and
    /// det = |v₀ × v₁|² + d(|v₀|² + |v₁|²) + d² (Lagrange's identity), so
    /// nothing cancels.
    fn covariance_2d(
        &self,
        placed: &Placed,
        on_frames: bool,
        depth: f32x8,
        vx: f32x8,
        vy: f32x8,
    ) -> ([f32x8; 3], f32x8, u32, [f32x8; 2]) {
        let tx = vx
            .max(f32x8::splat(-self.lim_x))
            .min(f32x8::splat(self.lim_x));
        let ty = vy
            .max(f32x8::splat(-self.lim_y))
            .min(f32x8::splat(self.lim_y));
        let w = self.rotation.transpose();
        let wz = Lanes3::splat(w.z_axis);
        let axis_plus = |axis: Vec3, t: f32x8| {
            let a = Lanes3::splat(axis);
            Lanes3 {
                x: a.x + wz.x * t,
                y: a.y + wz.y * t,
                z: a.z + wz.z * t,
            }
        };
        // Rows of J·W: J's rows are (fx/z, 0, fx·tx/z) and (0, −fy/z, −fy·ty/z).
        let j0 = axis_plus(w.x_axis, tx).scaled(f32x8::splat(self.fx) / depth);
        let j1 = axis_plus(w.y_axis, ty).scaled(f32x8::splat(-self.fy) / depth);
        let k = f32x8::new(placed.k);
        let frame_rotation = placed.frame_rotation.each_ref().map(Lanes3::from_lanes);
        let factor = placed.factor.each_ref().map(Lanes3::from_lanes);
        // Into the Gaussian's own axes: (J·W·k·R_f·L)ᵀ rows.
        let to_local = |j: Lanes3| {
            let r = if on_frames {
                Lanes3 {
                    x: frame_rotation[0].dot(j),
                    y: frame_rotation[1].dot(j),
                    z: frame_rotation[2].dot(j),
                }
                .scaled(k)
            } else {
                j.scaled(k)
            };
            Lanes3 {
                x: factor[0].dot(r),
                y: factor[1].dot(r),
                z: factor[2].dot(r),
            }
        };
        let (v0, v1) = (to_local(j0), to_local(j1));
        let d = f32x8::splat(COVARIANCE_DILATION as f32);
        let (s0, s1) = (v0.length_squared(), v1.length_squared());
        let (a, b, c) = (s0 + d, v0.dot(v1), s1 + d);
        let det = v0.cross(v1).length_squared() + d * (s0 + s1) + d * d;
        let valid = (det.is_finite() & det.simd_gt(f32x8::ZERO)).to_bitmask();
        let half = f32x8::splat(0.5);
        let mid = half * (a + c);
        let half_gap = half * (a - c);
        let lambda = mid + (half_gap * half_gap + b * b).max(f32x8::splat(0.1)).sqrt();
        let inv_det = f32x8::ONE / det;
        (
            [c * inv_det, -b * inv_det, a * inv_det],
            lambda,
            valid,
            [a, c],
        )
    }

    /// The inclusive pixel range whose centres lie in the box of
    /// half-sides `radius` (across, down) around the centre, clamped to the
    /// image (pixel i's centre is i + 0.5), as x0, y0, x1, y1 of each lane,
    /// empty where x0 > x1 or y0 > y1. The arguments are clamped before rounding
    /// (⌈max(v, −1)⌉ = max(⌈v⌉, −1), and so on), so footprints far larger
    /// than the image round exactly.
    #[inline]
    fn pixel_rects(
        &self,
        center_x: f32x8,
        center_y: f32x8,
        [radius_x, radius_y]: [f32x8; 2],
    ) -> [[f32; LANES]; 4] {
        let half = f32x8::splat(0.5);
        let low = |c: f32x8, radius: f32x8| {
            ceil_lanes((c - radius - half).max(f32x8::splat(-1.0))).max(f32x8::ZERO)
        };
        let high = |c: f32x8, radius: f32x8, size: f32| {
            let last = f32x8::splat(size - 1.0);
            floor_lanes((c + radius - half).min(f32x8::splat(size))).min(last)
        };
        [
            low(center_x, radius_x).to_array(),
            low(center_y, radius_y).to_array(),
            high(center_x, radius_x, self.width).to_array(),
            high(center_y, radius_y, self.height).to_array(),
        ]
    }
}

#[cfg(test)]
mod tests {
    use glam::Quat;
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::render::cpu::prepared::Prepared;
    use crate::render::projection::ProjectionCamera;
    use crate::scene::camera::Orbit;
    use crate::scene::splats::SplatScene;

    /// The box a splat is listed and blended in (the square's part the
    /// ellipse can reach) holds every pixel the f64 reference gives an
    /// α ≥ 1/255, for needles, discs and round Gaussians at every
    /// orientation; and it is smaller than the reference's square for the
    /// thin ones, or it would prove nothing.
    #[test]
    fn the_blend_box_keeps_every_pixel_the_ellipse_reaches() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut scene = SplatScene::with_degree(0);
        for _ in 0..4_000 {
            let position = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            );
            let axis = Vec3::new(rng.random(), rng.random(), rng.random()) - 0.5;
            let rotation =
                Quat::from_axis_angle(axis.normalize_or(Vec3::X), rng.random_range(0.0..6.3));
            let thin = [1.0, 1e-1, 1e-3][rng.random_range(0..3)];
            let scale = Vec3::new(0.05, 0.05 * thin, 0.05 * rng.random_range(thin..=1.0));
            scene.push(
                position,
                rotation,
                scale,
                rng.random_range(0.01..1.0),
                &[0.0; 3],
            );
        }
        let prepared = Prepared::of_scene(&scene);
        let camera = Orbit {
            radius: 4.0,
            target: [0.0; 3],
            ..Orbit::STUDY
        }
        .camera(160, 120);
        let projector = Projector::new(&camera, 1.0);
        let reference = ProjectionCamera::new(&camera);
        let footprints: Vec<Option<Splat>> = prepared
            .core
            .chunks(LANES)
            .flat_map(|cores| {
                let mut splats = [Splat::default(); LANES];
                let live = projector.project_batch(cores, None, &mut splats).live;
                (0..LANES).map(move |lane| (live & (1 << lane) != 0).then_some(splats[lane]))
            })
            .collect();
        let (mut checked, mut smaller) = (0, 0);
        for (i, footprint) in footprints.iter().enumerate() {
            let (o, scale) = (f64::from(scene.opacity[i]), scene.scale[i]);
            let Some(want) = reference.project(scene.position[i], scene.rotation[i], scale, o)
            else {
                continue;
            };
            let Some((x0, y0, x1, y1)) = want.pixel_rect(camera.width, camera.height) else {
                continue;
            };
            let mut reached = 0;
            for py in y0..=y1 {
                for px in x0..=x1 {
                    if want.alpha_at(o, px as f64 + 0.5, py as f64 + 0.5) == 0.0 {
                        continue;
                    }
                    reached += 1;
                    let rect = footprint.map(|f| f.rect.map(u32::from));
                    assert!(
                        rect.is_some_and(|[bx0, by0, bx1, by1]| {
                            (bx0..=bx1).contains(&px) && (by0..=by1).contains(&py)
                        }),
                        "Gaussian {i}: pixel ({px}, {py}) outside {rect:?} (square {:?})",
                        (x0, y0, x1, y1)
                    );
                }
            }
            checked += reached;
            if let Some(f) = footprint {
                let [bx0, by0, bx1, by1] = f.rect.map(u32::from);
                smaller +=
                    usize::from((bx1 - bx0 + 1) * (by1 - by0 + 1) < (x1 - x0 + 1) * (y1 - y0 + 1));
            }
        }
        assert!(checked > 20_000, "only {checked} pixels reached");
        let drawn = footprints.iter().flatten().count();
        assert!(
            smaller * 10 > drawn,
            "the box is smaller than the square for only {smaller} of {drawn}"
        );
    }
}
