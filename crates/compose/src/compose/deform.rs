//! Gaussians on a reshaped triangle (docs/method.md §6.7). A Gaussian is
//! stored in its parent triangle's frame (rotation R, size k, method §3.2),
//! so on the composite's blended triangle it follows R and k alone: a
//! similarity. When the blend stretches or shears a triangle, or changes its
//! size unevenly, the Gaussians on it keep their old proportions, and their
//! extent along the normal — which no in-plane measure of a triangle gives —
//! follows the triangle's mean size (thesis §7.3).
//!
//! `affine` maps each Gaussian by the triangle's deformation gradient F
//! instead: F takes the source's two edges to the composite's and the
//! source's unit normal to the composite's times λ = √(area ratio), the
//! geometric mean of the in-plane stretch (so a uniformly scaled triangle
//! gives exactly the similarity). In the triangle's local frame the map is
//! L = (k_f / k_c)·R_cᵀ·F·R_f, the identity for a similarity; positions go
//! to L·p, covariances to L·Σ·Lᵀ, re-factored into a rotation and scales.
//!
//! `anchor = "nearest"` (method §6.8) changes which triangle's reshaping a
//! Gaussian follows: the triangle of its source's surface nearest its
//! centre, where training moved it off its parent. It stays bound to its
//! parent: the moved Gaussian is written back in the parent's frame.

use glam::{DMat3, DVec3, Quat, Vec3};

use crate::avatar::binding::{
    local_to_world, normalize_quat, quat_from_matrix, triangle_frame, world_to_local, TriangleFrame,
};
use crate::model::eigen::symmetric_eigen;

/// Local maps within this of the identity (largest entry of L − I) are left
/// alone: a triangle whose shape the blend kept keeps its Gaussians bit for bit.
pub const IDENTITY_TOLERANCE: f64 = 1e-5;

/// Log-scale floor for a Gaussian the map flattens completely.
const MIN_LOG_SCALE: f32 = -30.0;

/// The local map of a triangle reshaped from `source` to `target` (corners in
/// the same order), or `None` where it is (nearly) a similarity or either
/// triangle is degenerate — then the Gaussians follow the frame as before.
pub fn local_map(source: [Vec3; 3], target: [Vec3; 3]) -> Option<DMat3> {
    let edges = |t: [Vec3; 3]| {
        let [a, b, c] = t.map(|v| v.as_dvec3());
        (b - a, c - a)
    };
    let (e1f, e2f) = edges(source);
    let (e1c, e2c) = edges(target);
    let (nf, nc) = (e1f.cross(e2f), e1c.cross(e2c));
    let (area_f, area_c) = (nf.length(), nc.length());
    // Relative to the edges' size, so tiny and huge triangles are judged alike.
    let degenerate = |area: f64, e1: DVec3, e2: DVec3| {
        !(area.is_finite() && area > 1e-9 * e1.length_squared().max(e2.length_squared()))
    };
    if degenerate(area_f, e1f, e2f) || degenerate(area_c, e1c, e2c) {
        return None;
    }
    let lambda = (area_c / area_f).sqrt();
    let from = DMat3::from_cols(e1f, e2f, nf / area_f);
    let to = DMat3::from_cols(e1c, e2c, nc / area_c * lambda);
    let f = to * from.inverse();
    let frame = |t: [Vec3; 3]| triangle_frame(t[0], t[1], t[2]);
    let (ff, fc) = (frame(source), frame(target));
    if !(ff.scale > 0.0 && fc.scale > 0.0) {
        return None;
    }
    let rf = ff.rotation.as_dmat3();
    let rc = fc.rotation.as_dmat3();
    let l = rc.transpose() * f * rf * (ff.scale as f64 / fc.scale as f64);
    let off_identity = (l - DMat3::IDENTITY)
        .to_cols_array()
        .iter()
        .fold(0.0f64, |m, x| m.max(x.abs()));
    (l.is_finite() && off_identity > IDENTITY_TOLERANCE).then_some(l)
}

/// Maps a Gaussian's local position, rotation and log-scales by `map`
/// (a [`local_map`]): p ↦ L·p, Σ ↦ L·Σ·Lᵀ. The result's scales are in
/// descending order along the rotation's axes.
pub fn apply_local_map(
    map: &DMat3,
    position: &mut Vec3,
    rotation: &mut Quat,
    log_scale: &mut Vec3,
) {
    let q = normalize_quat(*rotation).as_dquat();
    let axes = DMat3::from_quat(q);
    let scale = log_scale.as_dvec3().exp();
    // Σ' = M·Mᵀ with M = L·R·S, factored in the old axes, where Rᵀ·Σ'·R is
    // nearly diagonal for a nearly rigid map: a flat Gaussian's graded
    // covariance, which the solver hands to Jacobi rotations, then keeps its
    // small variances to their own digits.
    let m = axes.transpose() * *map * axes * DMat3::from_diagonal(scale);
    let sigma = m * m.transpose();
    let (values, vectors) = symmetric_eigen(sigma.to_cols_array_2d());
    let mut basis = axes * vectors;
    if basis.determinant() < 0.0 {
        basis.z_axis = -basis.z_axis;
    }
    let new_position = *map * position.as_dvec3();
    let new_rotation = quat_from_matrix(basis.as_mat3());
    let new_scale = Vec3::new(
        log_sqrt(values[0]),
        log_sqrt(values[1]),
        log_sqrt(values[2]),
    );
    if new_position.is_finite() && new_rotation.is_finite() && new_scale.is_finite() {
        *position = new_position.as_vec3();
        *rotation = new_rotation;
        *log_scale = new_scale;
    }
}

/// A Gaussian in the frame of the triangle it follows (its anchor) on its
/// source's neutral mesh: what `anchor = "nearest"` moves with that triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AnchorLocal {
    /// The triangle it follows.
    pub anchor: u32,
    /// Position, rotation and log-scales in the anchor's frame.
    pub position: Vec3,
    pub rotation: Quat,
    pub log_scale: Vec3,
}

/// Whether a triangle frame has a size to divide by.
fn sized(frame: &TriangleFrame) -> bool {
    frame.scale.is_finite() && frame.scale > 0.0
}

/// A Gaussian stored in its `parent` triangle's frame re-expressed in its
/// `anchor` triangle's (both on the source's neutral mesh); `None` where
/// either has no size or the result is not finite.
pub fn to_anchor(
    parent: &TriangleFrame,
    anchor: (u32, &TriangleFrame),
    position: Vec3,
    rotation: Quat,
    log_scale: Vec3,
) -> Option<AnchorLocal> {
    if !(sized(parent) && sized(anchor.1)) {
        return None;
    }
    let world = local_to_world(parent, position, rotation, log_scale);
    let (position, rotation, log_scale) = world_to_local(anchor.1, &world);
    (position.is_finite() && rotation.is_finite() && log_scale.is_finite()).then_some(AnchorLocal {
        anchor: anchor.0,
        position,
        rotation,
        log_scale,
    })
}

/// The composite's values, in its `parent` triangle's frame, of a Gaussian
/// that follows its anchor triangle (`anchor`, the composite's frame of
/// it): the anchor's similarity, and its local `map` first when one is given
/// (`deform = "affine"`). `None` where either triangle has no size or the
/// result is not finite: the Gaussian then follows its parent as stored.
pub fn from_anchor(
    local: &AnchorLocal,
    anchor: &TriangleFrame,
    parent: &TriangleFrame,
    map: Option<&DMat3>,
) -> Option<(Vec3, Quat, Vec3)> {
    if !(sized(parent) && sized(anchor)) {
        return None;
    }
    let (mut p, mut q, mut s) = (local.position, local.rotation, local.log_scale);
    if let Some(map) = map {
        apply_local_map(map, &mut p, &mut q, &mut s);
    }
    let world = local_to_world(anchor, p, q, s);
    let (p, q, s) = world_to_local(parent, &world);
    (p.is_finite() && q.is_finite() && s.is_finite()).then_some((p, q, s))
}

/// ln √v, floored for a zero (or rounding-negative) variance.
fn log_sqrt(v: f64) -> f32 {
    if v > 0.0 {
        ((0.5 * v.ln()) as f32).max(MIN_LOG_SCALE)
    } else {
        MIN_LOG_SCALE
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::binding::local_to_world;

    const TRIANGLE: [Vec3; 3] = [
        Vec3::new(0.0, 0.0, 0.0),
        Vec3::new(0.01, 0.0, 0.0),
        Vec3::new(0.002, 0.008, 0.001),
    ];

    /// World covariance of a local Gaussian on a triangle.
    fn world_covariance(t: [Vec3; 3], rotation: Quat, log_scale: Vec3) -> DMat3 {
        let frame = triangle_frame(t[0], t[1], t[2]);
        let g = local_to_world(&frame, Vec3::ZERO, rotation, log_scale);
        let r = DMat3::from_quat(g.rotation.as_dquat());
        let s = DMat3::from_diagonal(g.scale.as_dvec3());
        r * s * s * r.transpose()
    }

    #[test]
    fn a_similarity_changes_nothing() {
        let turn = Quat::from_rotation_y(0.7);
        let moved = TRIANGLE.map(|v| turn * (v * 1.7) + Vec3::new(0.1, -0.2, 0.3));
        assert!(local_map(TRIANGLE, moved).is_none());
        assert!(local_map(TRIANGLE, TRIANGLE).is_none());
    }

    #[test]
    fn an_affine_map_moves_covariances_and_positions_by_the_deformation_gradient() {
        // Stretch 2× along x and shear: F known in world space.
        let f = DMat3::from_cols(
            DVec3::new(2.0, 0.0, 0.0),
            DVec3::new(0.3, 1.0, 0.0),
            DVec3::new(0.0, 0.0, 1.0),
        );
        let source = TRIANGLE;
        let target = source.map(|v| (f * v.as_dvec3()).as_vec3());
        let map = local_map(source, target).expect("not a similarity");
        let rotation = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.8, 1.1);
        let log_scale = Vec3::new(-1.0, -2.0, -3.5);
        let (mut p, mut q, mut s) = (Vec3::new(0.2, 0.05, -0.1), rotation, log_scale);
        apply_local_map(&map, &mut p, &mut q, &mut s);
        // In-plane the world covariance is F·Σ·Fᵀ; along the normal, λ.
        let before = world_covariance(source, rotation, log_scale);
        let after = world_covariance(target, q, s);
        let n = (source[1] - source[0])
            .cross(source[2] - source[0])
            .normalize()
            .as_dvec3();
        let lambda = ((target[1] - target[0])
            .cross(target[2] - target[0])
            .length()
            / (source[1] - source[0])
                .cross(source[2] - source[0])
                .length())
        .sqrt() as f64;
        let nc = (target[1] - target[0])
            .cross(target[2] - target[0])
            .normalize()
            .as_dvec3();
        // F with the normal sent to λ·n_c, on the basis of edges and normal.
        let full = DMat3::from_cols(
            f * (source[1] - source[0]).as_dvec3(),
            f * (source[2] - source[0]).as_dvec3(),
            nc * lambda,
        ) * DMat3::from_cols(
            (source[1] - source[0]).as_dvec3(),
            (source[2] - source[0]).as_dvec3(),
            n,
        )
        .inverse();
        let expected = full * before * full.transpose();
        let error = (after - expected)
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        let size = expected
            .to_cols_array()
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(error < 1e-5 * size, "{error} vs {size}");
        // The centre: local positions are in units of the triangle's size.
        let fs = triangle_frame(source[0], source[1], source[2]);
        let fc = triangle_frame(target[0], target[1], target[2]);
        let world_before = fs.scale * (fs.rotation * Vec3::new(0.2, 0.05, -0.1)) + fs.center;
        let world_after = fc.scale * (fc.rotation * p) + fc.center;
        let expected = (full * (world_before - fs.center).as_dvec3()).as_vec3() + fc.center;
        assert!(
            world_after.abs_diff_eq(expected, 1e-7),
            "{world_after} {expected}"
        );
    }

    /// A parent triangle and a neighbour the Gaussian sits over.
    const NEIGHBOUR: [Vec3; 3] = [
        Vec3::new(0.01, 0.0, 0.0),
        Vec3::new(0.02, 0.001, 0.002),
        Vec3::new(0.012, 0.009, 0.0),
    ];

    fn frame_of(t: [Vec3; 3]) -> TriangleFrame {
        triangle_frame(t[0], t[1], t[2])
    }

    #[test]
    fn an_anchored_gaussian_moves_with_its_anchor_and_is_stored_on_its_parent() {
        let (parent, anchor) = (frame_of(TRIANGLE), frame_of(NEIGHBOUR));
        let (p, q, s) = (
            Vec3::new(1.2, 0.3, -0.4),
            Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.8, 1.1),
            Vec3::new(-1.0, -2.0, -3.5),
        );
        let local = to_anchor(&parent, (5, &anchor), p, q, s).expect("sized triangles");
        assert_eq!(local.anchor, 5);
        // Nothing moved: back where it was (to rounding).
        let (p2, q2, s2) = from_anchor(&local, &anchor, &parent, None).unwrap();
        assert!(
            p2.abs_diff_eq(p, 1e-5) && s2.abs_diff_eq(s, 1e-5),
            "{p2} {s2}"
        );
        assert!(q2.dot(q).abs() > 1.0 - 1e-6);
        // The anchor turned, grew and moved; the parent stayed: the
        // Gaussian's world values follow the anchor's similarity.
        let turn = Quat::from_rotation_z(0.4);
        let moved = NEIGHBOUR.map(|v| turn * (v * 1.5) + Vec3::new(0.0, 0.002, 0.001));
        let moved_anchor = frame_of(moved);
        let (p3, q3, s3) = from_anchor(&local, &moved_anchor, &parent, None).unwrap();
        let before = local_to_world(&parent, p, q, s);
        let after = local_to_world(&parent, p3, q3, s3);
        let expected = turn * (before.position * 1.5) + Vec3::new(0.0, 0.002, 0.001);
        assert!(
            after.position.abs_diff_eq(expected, 1e-7),
            "{} {expected}",
            after.position
        );
        assert!(after.scale.abs_diff_eq(before.scale * 1.5, 1e-7));
        assert!((after.rotation.dot(turn * before.rotation)).abs() > 1.0 - 1e-6);
        // With the anchor's affine map: a flat anchor stretched 2× along x
        // stretches the Gaussian's offset along x, and along its normal by
        // √(area ratio) (method §6.7).
        let flat = NEIGHBOUR.map(|v| Vec3::new(v.x, v.y, 0.0));
        let local = to_anchor(&parent, (5, &frame_of(flat)), p, q, s).unwrap();
        let stretched = flat.map(|v| Vec3::new(v.x * 2.0, v.y, v.z));
        let map = local_map(flat, stretched).expect("a stretch");
        let (p4, q4, s4) = from_anchor(&local, &frame_of(stretched), &parent, Some(&map)).unwrap();
        let after = local_to_world(&parent, p4, q4, s4).position;
        assert!((after.x - 2.0 * before.position.x).abs() < 1e-6, "{after}");
        assert!((after.y - before.position.y).abs() < 1e-6, "{after}");
        assert!(
            (after.z - 2f32.sqrt() * before.position.z).abs() < 1e-6,
            "{after}"
        );
    }

    #[test]
    fn anchoring_to_degenerate_triangles_or_extreme_gaussians_is_refused_or_finite() {
        let (parent, anchor) = (frame_of(TRIANGLE), frame_of(NEIGHBOUR));
        let flat = frame_of([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
        let point = frame_of([Vec3::ONE; 3]);
        let nan = frame_of([Vec3::ZERO, Vec3::X, Vec3::NAN]);
        let (p, q, s) = (Vec3::new(0.1, 0.2, 0.3), Quat::IDENTITY, Vec3::splat(-2.0));
        for bad in [point, nan] {
            assert!(to_anchor(&bad, (1, &anchor), p, q, s).is_none());
            assert!(to_anchor(&parent, (1, &bad), p, q, s).is_none());
        }
        let local = to_anchor(&parent, (1, &anchor), p, q, s).unwrap();
        for bad in [point, nan] {
            assert!(from_anchor(&local, &bad, &parent, None).is_none());
            assert!(from_anchor(&local, &anchor, &bad, None).is_none());
        }
        // A collinear triangle still has a size: finite, if meaningless.
        if let Some((p, q, s)) = from_anchor(&local, &flat, &parent, None) {
            assert!(p.is_finite() && q.is_finite() && s.is_finite());
        }
        // Huge coordinates, a zero quaternion, zero and huge scales.
        let huge = |t: [Vec3; 3]| frame_of(t.map(|v| v * 1e6));
        let zero_q = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
        for (q, s) in [
            (zero_q, Vec3::splat(-2.0)),
            (Quat::IDENTITY, Vec3::splat(-80.0)),
            (Quat::IDENTITY, Vec3::new(20.0, 0.0, -20.0)),
        ] {
            let big = to_anchor(&huge(TRIANGLE), (1, &huge(NEIGHBOUR)), p, q, s);
            if let Some(local) = big {
                if let Some((p, q, s)) =
                    from_anchor(&local, &huge(NEIGHBOUR), &huge(TRIANGLE), None)
                {
                    assert!(
                        p.is_finite() && q.is_finite() && s.is_finite(),
                        "{p} {q} {s}"
                    );
                }
            }
        }
    }

    #[test]
    fn degenerate_triangles_and_extreme_gaussians_leave_no_nan() {
        let flat = [Vec3::ZERO, Vec3::X, Vec3::X * 2.0];
        let point = [Vec3::ONE; 3];
        let nan = [Vec3::ZERO, Vec3::X, Vec3::NAN];
        for (a, b) in [
            (TRIANGLE, flat),
            (flat, TRIANGLE),
            (point, TRIANGLE),
            (TRIANGLE, nan),
        ] {
            assert!(local_map(a, b).is_none());
        }
        // A sliver that is still a triangle: a finite map.
        let sliver = [Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-3, 0.0)];
        let map = local_map(TRIANGLE, sliver).expect("a real reshape");
        assert!(map.is_finite());
        // Huge coordinates: the same map as at a human scale.
        let huge = |t: [Vec3; 3]| t.map(|v| v * 1e6);
        let big = local_map(huge(TRIANGLE), huge(sliver)).expect("the same reshape");
        assert!(big.abs_diff_eq(map, 1e-4), "{big} vs {map}");
        // Zero and huge scales, a zero quaternion.
        for (q, s) in [
            (Quat::from_xyzw(0.0, 0.0, 0.0, 0.0), Vec3::splat(-2.0)),
            (Quat::IDENTITY, Vec3::new(-80.0, -80.0, -80.0)),
            (Quat::IDENTITY, Vec3::new(20.0, 0.0, -20.0)),
        ] {
            let (mut p, mut q, mut s) = (Vec3::ONE, q, s);
            apply_local_map(&map, &mut p, &mut q, &mut s);
            assert!(
                p.is_finite() && q.is_finite() && s.is_finite(),
                "{p} {q} {s}"
            );
        }
    }
}
