//! Per-frame projection of prepared Gaussians to screen-space splats: the
//! steps of `render::projection` (the f64 reference), reordered so that what
//! is culled costs least, and in f32 where that is exact enough. The centre is
//! placed in view space in f64 (so scenes far from the origin keep their
//! precision), tested against the near and far planes and, with a bound on
//! its footprint from its largest scale, against the image; only what is left
//! gets its 2D covariance (as sums of squares of L·Lᵀ's factor, so f32 does
//! not cancel) and its colour. Everything after the f64 placement runs on
//! eight Gaussians at once in lanes ([`Lanes`]: two four-wide SSE2 halves on
//! the x86-64 baseline, one AVX register where the processor has AVX2).

use glam::{DMat3, DVec3, Mat3, Vec3};

use super::lanes::Lanes;
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
/// runs on this many lanes at once (see [`Lanes`]).
pub(super) const LANES: usize = 8;

/// Three lanes-wide coordinates.
#[derive(Clone, Copy)]
struct Lanes3<L> {
    x: L,
    y: L,
    z: L,
}

// No closures or array adaptors on lanes here or below: a closure is a
// function of its own, compiled without AVX when not inlined, and its every
// lane operation then a call (the projection took 62 ms instead of 17).
impl<L: Lanes> Lanes3<L> {
    #[inline(always)]
    fn splat(v: Vec3) -> Self {
        Self {
            x: L::splat(v.x),
            y: L::splat(v.y),
            z: L::splat(v.z),
        }
    }

    #[inline(always)]
    fn from_lanes(v: &[Vec3; LANES]) -> Self {
        Self {
            x: L::new(v.map(|v| v.x)),
            y: L::new(v.map(|v| v.y)),
            z: L::new(v.map(|v| v.z)),
        }
    }

    #[inline(always)]
    fn dot(self, o: Self) -> L {
        self.x * o.x + self.y * o.y + self.z * o.z
    }

    #[inline(always)]
    fn scaled(self, k: L) -> Self {
        Self {
            x: self.x * k,
            y: self.y * k,
            z: self.z * k,
        }
    }

    #[inline(always)]
    fn length_squared(self) -> L {
        self.dot(self)
    }

    #[inline(always)]
    fn cross(self, o: Self) -> Self {
        Self {
            x: self.y * o.z - self.z * o.y,
            y: self.z * o.x - self.x * o.z,
            z: self.x * o.y - self.y * o.x,
        }
    }

    /// `axis + along · t`, lane by lane.
    #[inline(always)]
    fn axis_plus(axis: Vec3, along: Self, t: L) -> Self {
        let a = Self::splat(axis);
        Self {
            x: a.x + along.x * t,
            y: a.y + along.y * t,
            z: a.z + along.z * t,
        }
    }

    /// The coordinates of `self` in the frame of the three `columns`.
    #[inline(always)]
    fn in_frame(self, columns: &[Self; 3]) -> Self {
        Self {
            x: columns[0].dot(self),
            y: columns[1].dot(self),
            z: columns[2].dot(self),
        }
    }

    /// Each lane's columns of `columns`, lane-wide.
    #[inline(always)]
    fn columns(columns: &[[Vec3; LANES]; 3]) -> [Self; 3] {
        [
            Self::from_lanes(&columns[0]),
            Self::from_lanes(&columns[1]),
            Self::from_lanes(&columns[2]),
        ]
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
    #[inline(always)]
    pub fn project_batch<L: Lanes>(
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
        let depth = L::new(placed.depth);
        let vx = L::new(placed.vx);
        let vy = L::new(placed.vy);
        let k = L::new(placed.k);
        let center_x = L::splat(self.cx) + L::splat(self.fx) * vx;
        let center_y = L::splat(self.cy) - L::splat(self.fy) * vy;
        // A bound on the footprint before any covariance work: 3σ of the
        // largest scale, dilated (√(s² + 2d) ≤ s + √(2d)), rounded up.
        let sigma_px = L::splat(self.spread_bound) * k.abs() * L::new(placed.sigma_max) / depth;
        let bound = L::splat(RADIUS_SIGMAS as f32) * (sigma_px + L::splat(DILATION_SIGMA_BOUND))
            + L::splat(1.0);
        let near_image = placed.alive & self.on_screen(center_x, center_y, bound);
        if near_image == 0 {
            return out;
        }
        let (conic, lambda, valid, variance) =
            self.covariance_2d(&placed, frames.is_some(), depth, vx, vy);
        let three_sigma = L::ceil(L::splat(RADIUS_SIGMAS as f32) * lambda.sqrt());
        let visible = (L::splat(2.0) * lambda * L::new(placed.log_visible)).sqrt();
        let radius = three_sigma.min(visible * L::splat(1.0 + 1e-4) + L::splat(1e-3));
        let finite = radius.is_finite();
        let radius = finite.bitselect(radius, L::splat(0.0));
        let live =
            near_image & valid & finite.to_bitmask() & self.on_screen(center_x, center_y, radius);
        // The ellipse where α reaches 1/255, |d|² ≤ 2·ln(255·o) in the
        // covariance's metric, reaches ±√(2·ln(255·o)·Σ_xx) across and
        // ±√(2·ln(255·o)·Σ_yy) down (widened a little for rounding): the
        // square's pixels outside that box are never blended, so the splat
        // is listed in the box's tiles only and blends the box's pixels
        // (the GPU's `project` kernel lists the same tiles).
        let reach = L::splat(2.0) * L::new(placed.log_visible);
        let (widen, pad) = (L::splat(1.0 + 1e-3), L::splat(1e-2));
        let [variance_x, variance_y] = variance;
        let extent = [
            radius.min((reach * variance_x).sqrt() * widen + pad),
            radius.min((reach * variance_y).sqrt() * widen + pad),
        ];
        let tight = self.pixel_rects(center_x, center_y, extent);
        let (x, y) = (center_x.to_array(), center_y.to_array());
        let inv_a = (L::splat(1.0) / conic[0]).to_array();
        let conic = [
            conic[0].to_array(),
            conic[1].to_array(),
            conic[2].to_array(),
        ];
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
    #[inline(always)]
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
    #[inline(always)]
    fn on_screen<L: Lanes>(&self, center_x: L, center_y: L, radius: L) -> u32 {
        let (w, h) = (L::splat(self.width), L::splat(self.height));
        ((center_x + radius).simd_ge(L::splat(0.0))
            & (center_x - radius).simd_le(w)
            & (center_y + radius).simd_ge(L::splat(0.0))
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
    #[inline(always)]
    fn covariance_2d<L: Lanes>(
        &self,
        placed: &Placed,
        on_frames: bool,
        depth: L,
        vx: L,
        vy: L,
    ) -> ([L; 3], L, u32, [L; 2]) {
        let tx = vx.max(L::splat(-self.lim_x)).min(L::splat(self.lim_x));
        let ty = vy.max(L::splat(-self.lim_y)).min(L::splat(self.lim_y));
        let w = self.rotation.transpose();
        let wz = Lanes3::<L>::splat(w.z_axis);
        // Rows of J·W: J's rows are (fx/z, 0, fx·tx/z) and (0, −fy/z, −fy·ty/z).
        let j0 = Lanes3::axis_plus(w.x_axis, wz, tx).scaled(L::splat(self.fx) / depth);
        let j1 = Lanes3::axis_plus(w.y_axis, wz, ty).scaled(L::splat(-self.fy) / depth);
        let k = L::new(placed.k);
        let factor = Lanes3::columns(&placed.factor);
        // Into the Gaussian's own axes: (J·W·k·R_f·L)ᵀ rows.
        let (v0, v1) = if on_frames {
            let frame_rotation = Lanes3::columns(&placed.frame_rotation);
            (
                j0.in_frame(&frame_rotation).scaled(k).in_frame(&factor),
                j1.in_frame(&frame_rotation).scaled(k).in_frame(&factor),
            )
        } else {
            (
                j0.scaled(k).in_frame(&factor),
                j1.scaled(k).in_frame(&factor),
            )
        };
        let d = L::splat(COVARIANCE_DILATION as f32);
        let (s0, s1) = (v0.length_squared(), v1.length_squared());
        let (a, b, c) = (s0 + d, v0.dot(v1), s1 + d);
        let det = v0.cross(v1).length_squared() + d * (s0 + s1) + d * d;
        let valid = (det.is_finite() & det.simd_gt(L::splat(0.0))).to_bitmask();
        let half = L::splat(0.5);
        let mid = half * (a + c);
        let half_gap = half * (a - c);
        let lambda = mid + (half_gap * half_gap + b * b).max(L::splat(0.1)).sqrt();
        let inv_det = L::splat(1.0) / det;
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
    #[inline(always)]
    fn pixel_rects<L: Lanes>(
        &self,
        center_x: L,
        center_y: L,
        [radius_x, radius_y]: [L; 2],
    ) -> [[f32; LANES]; 4] {
        [
            first_pixel(center_x, radius_x).to_array(),
            first_pixel(center_y, radius_y).to_array(),
            last_pixel(center_x, radius_x, self.width).to_array(),
            last_pixel(center_y, radius_y, self.height).to_array(),
        ]
    }
}

/// The first pixel (of a row or column) whose centre lies within `radius`
/// of `centre`, at least 0 (see [`Projector::pixel_rects`]).
#[inline(always)]
fn first_pixel<L: Lanes>(centre: L, radius: L) -> L {
    L::ceil((centre - radius - L::splat(0.5)).max(L::splat(-1.0))).max(L::splat(0.0))
}

/// The last pixel whose centre lies within `radius` of `centre`, at most
/// `size − 1` (see [`Projector::pixel_rects`]).
#[inline(always)]
fn last_pixel<L: Lanes>(centre: L, radius: L, size: f32) -> L {
    L::floor((centre + radius - L::splat(0.5)).min(L::splat(size))).min(L::splat(size - 1.0))
}

/// The camera the projection's tests look through: 4 units from the
/// origin, 160×120.
#[cfg(test)]
pub(super) fn test_camera() -> Camera {
    crate::scene::camera::Orbit {
        radius: 4.0,
        target: [0.0; 3],
        ..crate::scene::camera::Orbit::STUDY
    }
    .camera(160, 120)
}

#[cfg(test)]
mod tests {
    use glam::Quat;
    use rand::{Rng, SeedableRng};

    use super::*;
    use crate::render::cpu::prepared::Prepared;
    use crate::render::projection::ProjectionCamera;
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
        let camera = test_camera();
        let projector = Projector::new(&camera, 1.0);
        let reference = ProjectionCamera::new(&camera);
        let footprints: Vec<Option<Splat>> = prepared
            .core
            .chunks(LANES)
            .flat_map(|cores| {
                let mut splats = [Splat::default(); LANES];
                let live = projector
                    .project_batch::<wide::f32x8>(cores, None, &mut splats)
                    .live;
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
