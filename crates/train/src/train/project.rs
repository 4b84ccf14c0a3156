//! The differentiable half of a splat's way to the screen: a triangle-bound
//! Gaussian's parameters → its world centre and covariance (through the
//! triangle's frame) → the projected centre, conic and view-dependent colour,
//! with the same numerics as the renderers (`render::projection`: the 0.3 px²
//! dilation, the 1.3× frustum guard on the Jacobian, 3σ square footprints,
//! near/far culling, the opacity-aware footprint; SH colour `max(0, 0.5 + Σ basis·coef)`). The geometry
//! runs in [`Dual`] numbers, so every output carries its derivatives with
//! respect to the ten geometry parameters.

use glam::{DMat3, DVec3, Mat4};

use super::dual::{dot, mat_vec, DVec, Dual};
use crate::avatar::binding::TriangleFrame;
use crate::render::projection::{footprint_radius, COVARIANCE_DILATION, FRUSTUM_GUARD};
use crate::scene::camera::Camera;

/// Geometry parameters per Gaussian: local position (3), log-scale (3) and
/// the raw quaternion w, x, y, z (4).
pub const GEOMETRY: usize = 10;

/// A dual number over the geometry parameters.
pub type G = Dual<GEOMETRY>;

crate::render::sh::sh_basis!(
    /// The SH basis in dual numbers (for the colour's dependence on position).
    basis_dual,
    G,
    G::constant
);

/// A pinhole camera as datasets give it: camera-to-world in the OpenGL /
/// NeRF convention (x right, y up, looking down −z) and intrinsics in pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainCamera {
    /// World → camera rotation, row-major.
    pub rotation: [[f64; 3]; 3],
    /// World → camera translation.
    pub translation: [f64; 3],
    /// Camera centre in world space.
    pub eye: [f64; 3],
    /// Focal lengths in pixels.
    pub focal: [f64; 2],
    /// Principal point in pixels.
    pub principal: [f64; 2],
    /// Image size in pixels.
    pub size: [u32; 2],
    /// Near and far clipping distances.
    pub clip: [f64; 2],
}

impl TrainCamera {
    /// From a camera-to-world matrix (columns: right, up, back, position) and
    /// intrinsics.
    pub fn from_c2w(
        c2w: [[f64; 4]; 4],
        focal: [f64; 2],
        principal: [f64; 2],
        size: [u32; 2],
    ) -> Self {
        // c2w is given row-major here: c2w[r][c].
        let r = DMat3::from_cols(
            DVec3::new(c2w[0][0], c2w[1][0], c2w[2][0]),
            DVec3::new(c2w[0][1], c2w[1][1], c2w[2][1]),
            DVec3::new(c2w[0][2], c2w[1][2], c2w[2][2]),
        );
        let eye = DVec3::new(c2w[0][3], c2w[1][3], c2w[2][3]);
        let rt = r.transpose();
        let t = -(rt * eye);
        Self {
            rotation: rows(rt),
            translation: t.to_array(),
            eye: eye.to_array(),
            focal,
            principal,
            size,
            clip: [0.01, 100.0],
        }
    }

    /// The camera the renderers use for `camera` (centred principal point).
    pub fn from_camera(camera: &Camera) -> Self {
        let view: Mat4 = camera.view();
        let view = view.as_dmat4();
        let (fx, fy) = camera.focal_px();
        Self {
            rotation: rows(DMat3::from_mat4(view)),
            translation: view.w_axis.truncate().to_array(),
            eye: camera.eye.as_dvec3().to_array(),
            focal: [fx as f64, fy as f64],
            principal: [0.5 * camera.width as f64, 0.5 * camera.height as f64],
            size: [camera.width, camera.height],
            clip: [camera.near as f64, camera.far as f64],
        }
    }

    /// Camera-to-world (row-major), the inverse of the view transform.
    pub fn c2w(&self) -> [[f64; 4]; 4] {
        let r = self.rotation;
        let e = self.eye;
        // Columns of c2w's rotation are the rows of the view rotation.
        [
            [r[0][0], r[1][0], r[2][0], e[0]],
            [r[0][1], r[1][1], r[2][1], e[1]],
            [r[0][2], r[1][2], r[2][2], e[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }
}

/// A matrix's rows.
fn rows(m: DMat3) -> [[f64; 3]; 3] {
    let t = m.transpose();
    [
        t.x_axis.to_array(),
        t.y_axis.to_array(),
        t.z_axis.to_array(),
    ]
}

/// One Gaussian's trainable parameters (f64).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// Position in the triangle's frame.
    pub position: [f64; 3],
    /// Log of the per-axis scale (units of the triangle size).
    pub log_scale: [f64; 3],
    /// Quaternion w, x, y, z (normalised when used).
    pub rotation: [f64; 4],
}

/// A projected Gaussian with the derivatives of its screen quantities.
#[derive(Clone, Debug)]
pub struct Projected {
    /// Centre in pixels.
    pub center: [G; 2],
    /// Inverse 2D covariance (a, b, c).
    pub conic: [G; 3],
    /// Colour before the clamp at 0 (derivatives through the view direction).
    pub rgb: [G; 3],
    /// The SH basis at the view direction (∂colour/∂coefficient).
    pub basis: [f64; 16],
    /// Footprint half-size in pixels.
    pub radius: f64,
    /// Distance along the viewing axis.
    pub depth: f64,
}

impl Projected {
    /// The colour as drawn: clamped at 0.
    pub fn drawn_rgb(&self) -> [f64; 3] {
        self.rgb.map(|c| c.v.max(0.0))
    }
}

/// Projects one Gaussian bound to `frame`; `None` when culled as the renderers
/// cull (behind the near plane, past the far one, degenerate, off-screen).
pub fn project(
    geometry: &Geometry,
    sh: &[f64],
    degree: u8,
    opacity: f64,
    frame: &TriangleFrame,
    camera: &TrainCamera,
) -> Option<Projected> {
    let var = |v: f64, k: usize| G::variable(v, k);
    let local: DVec<GEOMETRY> = std::array::from_fn(|i| var(geometry.position[i], i));
    let log_scale: DVec<GEOMETRY> = std::array::from_fn(|i| var(geometry.log_scale[i], 3 + i));
    let q: [G; 4] = std::array::from_fn(|i| var(geometry.rotation[i], 6 + i));

    let frame_rotation = rows(frame.rotation.as_dmat3());
    let k = frame.scale as f64;
    let rotated = mat_vec(&frame_rotation, &local);
    let world: DVec<GEOMETRY> = std::array::from_fn(|i| rotated[i] * k + frame.center[i] as f64);
    let view_point = {
        let p = mat_vec(&camera.rotation, &world);
        [
            p[0] + camera.translation[0],
            p[1] + camera.translation[1],
            p[2] + camera.translation[2],
        ]
    };
    let depth = -view_point[2];
    if !(depth.v >= camera.clip[0] && depth.v <= camera.clip[1]) {
        return None;
    }

    // Σ_view = k² A (R_q S² R_qᵀ) Aᵀ with A = R_view R_frame.
    let rq = quaternion_matrix(q);
    let scale: DVec<GEOMETRY> = log_scale.map(|s| s.exp());
    let a = mat_mul(&camera.rotation, &frame_rotation);
    // M = A R_q diag(s): columns of R_q scaled, then rotated by A.
    let m: [[G; 3]; 3] = std::array::from_fn(|r| {
        std::array::from_fn(|c| {
            (rq[0][c] * a[r][0] + rq[1][c] * a[r][1] + rq[2][c] * a[r][2]) * scale[c] * k
        })
    });
    let cov = |i: usize, j: usize| dot(&m[i], &m[j]);
    let cov_view = [
        [cov(0, 0), cov(0, 1), cov(0, 2)],
        [cov(1, 0), cov(1, 1), cov(1, 2)],
        [cov(2, 0), cov(2, 1), cov(2, 2)],
    ];

    let [fx, fy] = camera.focal;
    let [w, h] = camera.size.map(f64::from);
    let lim_x = FRUSTUM_GUARD * 0.5 * w / fx;
    let lim_y = FRUSTUM_GUARD * 0.5 * h / fy;
    let tx = (view_point[0] / depth).clamp(-lim_x, lim_x);
    let ty = (view_point[1] / depth).clamp(-lim_y, lim_y);
    let zero = G::constant(0.0);
    let j0 = [G::constant(fx) / depth, zero, tx * fx / depth];
    let j1 = [zero, G::constant(-fy) / depth, -(ty * fy) / depth];
    let quadratic = |u: &DVec<GEOMETRY>, v: &DVec<GEOMETRY>| {
        let cv: DVec<GEOMETRY> = std::array::from_fn(|r| dot(&cov_view[r], v));
        dot(u, &cv)
    };
    let ca = quadratic(&j0, &j0) + COVARIANCE_DILATION;
    let cb = quadratic(&j0, &j1);
    let cc = quadratic(&j1, &j1) + COVARIANCE_DILATION;
    let det = ca * cc - cb * cb;
    if !(det.v.is_finite() && det.v > 0.0) {
        return None;
    }
    let mid = 0.5 * (ca.v + cc.v);
    let lambda = mid + (mid * mid - det.v).max(0.1).sqrt();
    let radius = footprint_radius(lambda, opacity);
    let center = [
        view_point[0] * fx / depth + camera.principal[0],
        -(view_point[1] * fy / depth) + camera.principal[1],
    ];
    if !radius.is_finite()
        || center[0].v + radius < 0.0
        || center[0].v - radius > w
        || center[1].v + radius < 0.0
        || center[1].v - radius > h
    {
        return None;
    }

    let offset: DVec<GEOMETRY> = std::array::from_fn(|i| world[i] - camera.eye[i]);
    let length = dot(&offset, &offset).sqrt();
    let dir = if length.v > 0.0 {
        offset.map(|o| o / length)
    } else {
        [zero; 3]
    };
    let basis = basis_dual(degree, dir);
    let coefficients = (degree as usize + 1).pow(2).min(sh.len() / 3);
    let rgb: [G; 3] = std::array::from_fn(|ch| {
        let mut c = G::constant(0.5);
        for (j, b) in basis.iter().enumerate().take(coefficients) {
            c = c + *b * sh[j * 3 + ch];
        }
        c
    });
    Some(Projected {
        center,
        conic: [cc / det, -cb / det, ca / det],
        rgb,
        basis: basis.map(|b| b.v),
        radius,
        depth: depth.v,
    })
}

/// The rotation matrix (row-major) of a quaternion w, x, y, z, normalised
/// first; a (near-)zero quaternion is the identity, as the renderers treat it.
fn quaternion_matrix(q: [G; 4]) -> [[G; 3]; 3] {
    let norm2 = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    let one = G::constant(1.0);
    let zero = G::constant(0.0);
    if !(norm2.v.is_finite() && norm2.v > 1e-30) {
        return [[one, zero, zero], [zero, one, zero], [zero, zero, one]];
    }
    let n = norm2.sqrt();
    let [w, x, y, z] = q.map(|c| c / n);
    let two = 2.0;
    [
        [
            one - (y * y + z * z) * two,
            (x * y - w * z) * two,
            (x * z + w * y) * two,
        ],
        [
            (x * y + w * z) * two,
            one - (x * x + z * z) * two,
            (y * z - w * x) * two,
        ],
        [
            (x * z - w * y) * two,
            (y * z + w * x) * two,
            one - (x * x + y * y) * two,
        ],
    ]
}

fn mat_mul(a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..3).map(|k| a[r][k] * b[k][c]).sum()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::projection::ProjectionCamera;
    use crate::scene::camera::Orbit;
    use glam::{Mat3, Quat, Vec3};

    /// The dual projection's values are the renderers' (f64 reference)
    /// projection of the same Gaussian, on a tilted, scaled triangle frame.
    #[test]
    fn values_match_the_reference_projection() {
        let camera = Orbit {
            yaw_deg: 20.0,
            pitch_deg: -10.0,
            radius: 1.5,
            fov_deg: 30.0,
            target: [0.0, 0.0, 0.0],
            ..Orbit::STUDY
        }
        .camera(120, 90);
        let rotation = Mat3::from_quat(Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.2));
        let frame = TriangleFrame {
            center: Vec3::new(0.05, -0.02, 0.1),
            rotation,
            quat: Quat::from_mat3(&rotation),
            scale: 0.07,
        };
        let g = Geometry {
            position: [0.3, -0.2, 0.5],
            log_scale: [-0.5, 0.2, -1.5],
            rotation: [0.9, 0.1, -0.3, 0.2],
        };
        let sh: Vec<f64> = (0..48)
            .map(|i| ((i * 7) % 11) as f64 * 0.03 - 0.15)
            .collect();
        let p = project(&g, &sh, 3, 0.7, &frame, &TrainCamera::from_camera(&camera)).unwrap();
        let local_q = Quat::from_xyzw(0.1, -0.3, 0.2, 0.9).normalize();
        let world = frame.scale * (frame.rotation * Vec3::new(0.3, -0.2, 0.5)) + frame.center;
        let reference = ProjectionCamera::new(&camera)
            .project(
                world,
                frame.quat * local_q,
                Vec3::new(-0.5f32, 0.2, -1.5).exp() * frame.scale,
                0.7,
            )
            .unwrap();
        for i in 0..2 {
            assert!((p.center[i].v - reference.center[i]).abs() < 1e-4);
        }
        for i in 0..3 {
            let scale = reference.conic[i].abs().max(1e-3);
            assert!(
                (p.conic[i].v - reference.conic[i]).abs() < 1e-4 * scale,
                "{i}"
            );
        }
        assert_eq!(p.radius, reference.radius);
        let dir = (world.as_dvec3() - camera.eye.as_dvec3()).normalize();
        let sh32: Vec<f32> = sh.iter().map(|&x| x as f32).collect();
        let rgb = crate::render::sh::eval_rgb(&sh32, 3, dir.to_array());
        for (drawn, expected) in p.drawn_rgb().iter().zip(rgb) {
            assert!((drawn - expected).abs() < 1e-5);
        }
    }
}
