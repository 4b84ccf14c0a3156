//! Gaussians bound to triangles, GaussianAvatars convention (docs/method.md §3).
//!
//! For triangle (v0, v1, v2): c = centroid; a0 = n(v1−v0); a1 = n(a0 × (v2−v0));
//! a2 = −n(a1 × a0); R = [a0 a1 a2]; k = (|v1−v0| + |a2·(v2−v0)|)/2 with
//! n(x) = x / sqrt(max(x·x, 1e-20)). World values: μ = k·R·μ_local + c,
//! scale = exp(s_local)·k, q = q(R) ⊗ normalize(q_local). Degenerate triangles
//! give finite (if meaningless) frames, never NaN.

use glam::{Mat3, Quat, Vec3};

/// Orientation, centre and size of one triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TriangleFrame {
    /// Centroid.
    pub center: Vec3,
    /// Columns a0 (along the first edge), a1 (normal), a2 (in-plane, ⟂ a0).
    pub rotation: Mat3,
    /// The rotation as a unit quaternion (identity where R is degenerate).
    pub quat: Quat,
    /// Size k.
    pub scale: f32,
}

impl TriangleFrame {
    /// The world position of a point at `local` in this frame (units of the
    /// triangle's size): k·R·local + c.
    pub fn to_world(&self, local: Vec3) -> Vec3 {
        self.scale * (self.rotation * local) + self.center
    }
}

/// The GaussianAvatars safe normalisation.
pub fn safe_normalize(x: Vec3) -> Vec3 {
    x / x.length_squared().max(1e-20).sqrt()
}

/// The frame of triangle (v0, v1, v2).
pub fn triangle_frame(v0: Vec3, v1: Vec3, v2: Vec3) -> TriangleFrame {
    let e1 = v1 - v0;
    let e2 = v2 - v0;
    let a0 = safe_normalize(e1);
    let a1 = safe_normalize(a0.cross(e2));
    let a2 = -safe_normalize(a1.cross(a0));
    let rotation = Mat3::from_cols(a0, a1, a2);
    let scale = 0.5 * (e1.length() + a2.dot(e2).abs());
    let scale = if scale.is_finite() { scale } else { 0.0 };
    TriangleFrame {
        center: (v0 + v1 + v2) / 3.0,
        rotation,
        quat: quat_from_matrix(rotation),
        scale,
    }
}

/// Frames of all triangles of a mesh.
pub fn triangle_frames(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Vec<TriangleFrame> {
    triangles
        .iter()
        .map(|t| {
            triangle_frame(
                vertices[t[0] as usize],
                vertices[t[1] as usize],
                vertices[t[2] as usize],
            )
        })
        .collect()
}

/// Frames of all triangles, written into `out` (no allocation when it has room).
pub fn triangle_frames_into(
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    out: &mut Vec<TriangleFrame>,
) {
    out.clear();
    out.extend(triangles.iter().map(|t| {
        triangle_frame(
            vertices[t[0] as usize],
            vertices[t[1] as usize],
            vertices[t[2] as usize],
        )
    }));
}

/// Quaternion of a rotation matrix (Shepperd's method, largest-pivot branch).
/// Matrices that are not rotations (degenerate triangles) still give a finite
/// unit quaternion; all-zero input gives the identity.
pub fn quat_from_matrix(m: Mat3) -> Quat {
    let (c0, c1, c2) = (m.x_axis, m.y_axis, m.z_axis);
    let (m00, m11, m22) = (c0.x, c1.y, c2.z);
    let trace = m00 + m11 + m22;
    let q = if trace >= m00.max(m11).max(m22) {
        let s = (1.0 + trace).max(0.0).sqrt() * 2.0;
        Quat::from_xyzw(
            (c1.z - c2.y) / s,
            (c2.x - c0.z) / s,
            (c0.y - c1.x) / s,
            0.25 * s,
        )
    } else if m00 >= m11 && m00 >= m22 {
        let s = (1.0 + m00 - m11 - m22).max(0.0).sqrt() * 2.0;
        Quat::from_xyzw(
            0.25 * s,
            (c1.x + c0.y) / s,
            (c2.x + c0.z) / s,
            (c1.z - c2.y) / s,
        )
    } else if m11 >= m22 {
        let s = (1.0 + m11 - m00 - m22).max(0.0).sqrt() * 2.0;
        Quat::from_xyzw(
            (c1.x + c0.y) / s,
            0.25 * s,
            (c2.y + c1.z) / s,
            (c2.x - c0.z) / s,
        )
    } else {
        let s = (1.0 + m22 - m00 - m11).max(0.0).sqrt() * 2.0;
        Quat::from_xyzw(
            (c2.x + c0.z) / s,
            (c2.y + c1.z) / s,
            0.25 * s,
            (c0.y - c1.x) / s,
        )
    };
    normalize_quat(q)
}

/// Unit quaternion, or the identity for zero, tiny or non-finite input.
pub fn normalize_quat(q: Quat) -> Quat {
    let len2 = q.length_squared();
    if len2.is_finite() && len2 > 1e-30 {
        q / len2.sqrt()
    } else {
        Quat::IDENTITY
    }
}

/// A Gaussian in world space.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldGaussian {
    /// Mean.
    pub position: Vec3,
    /// Unit rotation.
    pub rotation: Quat,
    /// Standard deviations along the rotated axes.
    pub scale: Vec3,
}

/// Transforms a triangle-local Gaussian to world space.
pub fn local_to_world(
    frame: &TriangleFrame,
    local_position: Vec3,
    local_rotation: Quat,
    log_scale: Vec3,
) -> WorldGaussian {
    WorldGaussian {
        position: frame.to_world(local_position),
        rotation: normalize_quat(frame.quat * normalize_quat(local_rotation)),
        scale: log_scale.exp() * frame.scale,
    }
}

/// The triangle-local parameters that give a world-space Gaussian on a frame:
/// the inverse of [`local_to_world`] for non-degenerate frames.
pub fn world_to_local(frame: &TriangleFrame, world: &WorldGaussian) -> (Vec3, Quat, Vec3) {
    let k = frame.scale.max(1e-12);
    let position = frame.rotation.transpose() * (world.position - frame.center) / k;
    let rotation = normalize_quat(frame.quat.conjugate() * world.rotation);
    let log_scale = (world.scale / k).max(Vec3::splat(1e-12)).ln();
    (position, rotation, log_scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn finite(g: &WorldGaussian) -> bool {
        g.position.is_finite() && g.rotation.is_finite() && g.scale.is_finite()
    }

    #[test]
    fn right_triangle_by_hand() {
        // v0 at origin, v1 = 2x, v2 = 2y: a0 = x, a1 = x × 2y / 2 = z, a2 = -(z × x) = -y.
        let f = triangle_frame(
            Vec3::ZERO,
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(0.0, 2.0, 0.0),
        );
        assert!(f.rotation.x_axis.abs_diff_eq(Vec3::X, 1e-6));
        assert!(f.rotation.y_axis.abs_diff_eq(Vec3::Z, 1e-6));
        assert!(f.rotation.z_axis.abs_diff_eq(Vec3::NEG_Y, 1e-6));
        // k = (|v1 - v0| + |a2·(v2 - v0)|)/2 = (2 + 2)/2.
        assert!((f.scale - 2.0).abs() < 1e-6);
        assert!(f
            .center
            .abs_diff_eq(Vec3::new(2.0 / 3.0, 2.0 / 3.0, 0.0), 1e-6));
        // A local offset of 1 along a1 (the normal) lands k = 2 above the centroid.
        let g = local_to_world(&f, Vec3::Y, Quat::IDENTITY, Vec3::ZERO);
        assert!(g.position.abs_diff_eq(f.center + 2.0 * Vec3::Z, 1e-6));
        assert!(g.scale.abs_diff_eq(Vec3::splat(2.0), 1e-6));
        // q(R) rotates x to x, y to z, z to -y.
        assert!((g.rotation * Vec3::Y).abs_diff_eq(Vec3::Z, 1e-6));
    }

    #[test]
    fn quaternion_matches_matrix_for_random_rotations() {
        for i in 0..500 {
            let axis = Vec3::new((i as f32 * 0.7).sin(), (i as f32 * 1.3).cos(), 0.4).normalize();
            let angle = i as f32 * 0.0137 * std::f32::consts::TAU;
            let m = Mat3::from_axis_angle(axis, angle);
            let q = quat_from_matrix(m);
            assert!(Mat3::from_quat(q).abs_diff_eq(m, 1e-5), "angle {angle}");
        }
    }

    #[test]
    fn degenerate_triangles_stay_finite() {
        let p = Vec3::new(0.3, -0.2, 0.1);
        let cases = [
            [p, p, p],                                        // a point
            [Vec3::ZERO, Vec3::X, 2.0 * Vec3::X],             // collinear
            [Vec3::ZERO, Vec3::ZERO, Vec3::Y],                // repeated vertex
            [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-9, 0.0)], // sliver
            [
                Vec3::splat(1e6),
                Vec3::splat(1e6) + Vec3::X,
                Vec3::splat(1e6) + Vec3::Y,
            ], // far away
            [
                Vec3::ZERO,
                Vec3::new(1e-20, 0.0, 0.0),
                Vec3::new(0.0, 1e-20, 0.0),
            ], // tiny
        ];
        for tri in cases {
            let f = triangle_frame(tri[0], tri[1], tri[2]);
            assert!(
                f.center.is_finite() && f.scale.is_finite() && f.quat.is_finite(),
                "{tri:?}"
            );
            let g = local_to_world(
                &f,
                Vec3::new(0.1, 0.2, 0.3),
                Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
                Vec3::splat(-3.0),
            );
            assert!(finite(&g), "{tri:?} -> {g:?}");
        }
    }

    #[test]
    fn huge_triangle_keeps_relative_accuracy() {
        let s = 1e4;
        let f = triangle_frame(Vec3::ZERO, Vec3::new(s, 0.0, 0.0), Vec3::new(0.0, s, 0.0));
        assert!((f.scale / s - 1.0).abs() < 1e-6);
        let g = local_to_world(&f, Vec3::X * 0.5, Quat::IDENTITY, Vec3::ZERO);
        assert!(((g.position.x - f.center.x) / s - 0.5).abs() < 1e-6);
    }

    #[test]
    fn zero_quaternion_and_huge_scales_are_finite() {
        let f = triangle_frame(Vec3::ZERO, Vec3::X, Vec3::Y);
        let g = local_to_world(
            &f,
            Vec3::ZERO,
            Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            Vec3::new(30.0, -30.0, 0.0),
        );
        assert!(g.rotation.is_finite() && g.position.is_finite());
        assert!(g.scale.y >= 0.0 && g.scale.x > 1e12);
    }

    #[test]
    fn world_to_local_inverts_local_to_world() {
        let f = triangle_frame(
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::new(0.13, 0.01, 0.0),
            Vec3::new(0.11, 0.03, 0.01),
        );
        let q = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.2, 1.1);
        let g = local_to_world(
            &f,
            Vec3::new(0.2, -0.1, 0.4),
            q,
            Vec3::new(-1.0, -2.0, -0.5),
        );
        let (p, r, s) = world_to_local(&f, &g);
        let back = local_to_world(&f, p, r, s);
        assert!(back.position.abs_diff_eq(g.position, 1e-6));
        assert!(back.scale.abs_diff_eq(g.scale, 1e-6));
        assert!(back.rotation.dot(g.rotation).abs() > 1.0 - 1e-5);
    }
}
