//! Moment matching: the one Gaussian that stands for a group of Gaussians in
//! a coarser level. Each member weighs by the mass it shows, opacity times
//! the mean area it presents to a random view; the merged mean and
//! covariance are the weighted first and second moments of the members
//! (their own covariances plus their spread about the merged mean), the
//! colour is the weighted mean of the SH coefficients, and the opacity is
//! set so that the merged Gaussian shows the members' total mass. That
//! opacity may exceed 1 (up to [`MAX_OPACITY`]): a patch of surface merged
//! into one Gaussian is opaque over most of its footprint, and a Gaussian
//! capped at 1 is see-through everywhere but near its centre, so the surface
//! turned translucent between neighbouring nodes (capped, cuts of 300k
//! synthetic Gaussians at 200×120 lost 2.5-4 dB against the full scene).

use glam::{DMat3, DVec3, Quat, Vec3};

use crate::avatar::binding::quat_from_matrix;
use crate::model::eigen::symmetric_eigen;
use crate::scene::splats::{SplatScene, MAX_OPACITY};

/// One Gaussian as a level of the hierarchy keeps it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Member<'a> {
    /// Centre.
    pub position: Vec3,
    /// Unit rotation.
    pub rotation: Quat,
    /// Standard deviations along the rotated axes.
    pub scale: Vec3,
    /// Opacity in [0, 1].
    pub opacity: f32,
    /// SH coefficients, coefficient-major.
    pub sh: &'a [f32],
}

impl<'a> Member<'a> {
    /// Gaussian `i` of `scene`.
    pub fn of(scene: &'a SplatScene, i: usize) -> Member<'a> {
        Member {
            position: scene.position[i],
            rotation: scene.rotation[i],
            scale: scene.scale[i],
            opacity: scene.opacity[i],
            sh: scene.sh_of(i),
        }
    }
}

/// The merged Gaussian (its SH is written into the caller's buffer).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Merged {
    /// Centre: the members' weighted mean.
    pub position: Vec3,
    /// Rotation of the merged covariance's eigenvectors.
    pub rotation: Quat,
    /// Square roots of the merged covariance's eigenvalues.
    pub scale: Vec3,
    /// Opacity that keeps the members' mass, in [0, [`MAX_OPACITY`]].
    pub opacity: f32,
}

/// The mean area a Gaussian of standard deviations `s` presents to a
/// random view direction, up to a constant (s₁s₂ + s₂s₃ + s₃s₁, the
/// ellipsoid's surface-area proxy): flat splats count by their face, and
/// a needle by its length and width.
pub fn mean_area(s: Vec3) -> f64 {
    let s = s.as_dvec3().abs();
    s.x * s.y + s.y * s.z + s.z * s.x
}

fn covariance(rotation: Quat, scale: Vec3) -> DMat3 {
    let r = DMat3::from_quat(rotation.as_dquat().normalize());
    let s = scale.as_dvec3();
    r * DMat3::from_diagonal(s * s) * r.transpose()
}

/// Merges `members` (at least one) into one Gaussian; `sh_out` receives
/// the weighted mean of their SH (all members hold `sh_out.len()` floats).
/// Members that show no mass (zero opacity or zero size) still count when
/// every member is such, by count, so the merged Gaussian sits where they
/// are.
pub fn merge(members: &[Member], sh_out: &mut [f32]) -> Merged {
    let masses: Vec<f64> = members
        .iter()
        .map(|m| m.opacity.max(0.0) as f64 * mean_area(m.scale))
        .collect();
    let total_mass: f64 = masses.iter().sum();
    let weights: Vec<f64> = if total_mass > 0.0 && total_mass.is_finite() {
        masses.iter().map(|w| w / total_mass).collect()
    } else {
        vec![1.0 / members.len() as f64; members.len()]
    };
    let mean = members
        .iter()
        .zip(&weights)
        .fold(DVec3::ZERO, |acc, (m, w)| acc + m.position.as_dvec3() * *w);
    let mut second = DMat3::ZERO;
    for (m, &w) in members.iter().zip(&weights) {
        let d = m.position.as_dvec3() - mean;
        let spread = DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        second += (covariance(m.rotation, m.scale) + spread) * w;
    }
    sh_out.fill(0.0);
    for (m, &w) in members.iter().zip(&weights) {
        for (out, c) in sh_out.iter_mut().zip(m.sh) {
            *out += (*c as f64 * w) as f32;
        }
    }
    let (rotation, scale) = factor(second);
    let area = mean_area(scale);
    let opacity = if area > 0.0 && total_mass.is_finite() {
        (total_mass / area).min(MAX_OPACITY as f64)
    } else {
        // Points: the members' opacities composited.
        1.0 - members
            .iter()
            .map(|m| 1.0 - m.opacity.clamp(0.0, 1.0) as f64)
            .product::<f64>()
    };
    Merged {
        position: mean.as_vec3(),
        rotation,
        scale,
        opacity: opacity as f32,
    }
}

/// Rotation and standard deviations of a covariance (eigenvalues rounded
/// below zero count as zero; a reflection is turned into a rotation by
/// flipping the last axis, which leaves the covariance as it is).
fn factor(covariance: DMat3) -> (Quat, Vec3) {
    let c = covariance.to_cols_array_2d();
    // Symmetrise: the sum above is symmetric up to rounding.
    let m = [
        [
            c[0][0],
            0.5 * (c[0][1] + c[1][0]),
            0.5 * (c[0][2] + c[2][0]),
        ],
        [
            0.5 * (c[0][1] + c[1][0]),
            c[1][1],
            0.5 * (c[1][2] + c[2][1]),
        ],
        [
            0.5 * (c[0][2] + c[2][0]),
            0.5 * (c[1][2] + c[2][1]),
            c[2][2],
        ],
    ];
    if !m.iter().flatten().all(|v| v.is_finite()) {
        return (Quat::IDENTITY, Vec3::ZERO);
    }
    let (values, mut vectors) = symmetric_eigen(m);
    if vectors.determinant() < 0.0 {
        vectors.z_axis = -vectors.z_axis;
    }
    let scale = Vec3::new(
        values[0].max(0.0).sqrt() as f32,
        values[1].max(0.0).sqrt() as f32,
        values[2].max(0.0).sqrt() as f32,
    );
    (quat_from_matrix(vectors.as_mat3()), scale)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn member(position: Vec3, rotation: Quat, scale: Vec3, opacity: f32) -> Member<'static> {
        Member {
            position,
            rotation,
            scale,
            opacity,
            sh: &[0.5, 0.25, 0.0],
        }
    }

    fn covariance_of(m: &Merged) -> DMat3 {
        covariance(m.rotation, m.scale)
    }

    fn close(a: DMat3, b: DMat3, tol: f64) -> bool {
        (a - b).to_cols_array().iter().all(|d| d.abs() <= tol)
    }

    #[test]
    fn one_member_merges_into_itself() {
        let q = Quat::from_rotation_y(0.7) * Quat::from_rotation_x(0.3);
        let m = member(Vec3::new(1.0, 2.0, 3.0), q, Vec3::new(0.3, 0.2, 0.1), 0.6);
        let mut sh = [0.0; 3];
        let merged = merge(&[m], &mut sh);
        assert!((merged.position - m.position).length() < 1e-6);
        assert!((merged.opacity - 0.6).abs() < 1e-5);
        assert!(close(covariance_of(&merged), covariance(q, m.scale), 1e-6));
        assert_eq!(sh, [0.5, 0.25, 0.0]);
    }

    #[test]
    fn two_points_merge_into_their_spread() {
        let a = member(
            Vec3::new(-1.0, 0.0, 0.0),
            Quat::IDENTITY,
            Vec3::splat(0.1),
            0.5,
        );
        let b = member(
            Vec3::new(1.0, 0.0, 0.0),
            Quat::IDENTITY,
            Vec3::splat(0.1),
            0.5,
        );
        let merged = merge(&[a, b], &mut [0.0; 3]);
        assert!(merged.position.length() < 1e-6);
        // Variance along x: own 0.01 plus spread 1.
        let expected = DMat3::from_diagonal(DVec3::new(1.01, 0.01, 0.01));
        assert!(close(covariance_of(&merged), expected, 1e-5));
        // Mass is kept: α·area equals the members' total.
        let kept = merged.opacity as f64 * mean_area(merged.scale);
        let members = 2.0 * 0.5 * mean_area(Vec3::splat(0.1));
        assert!((kept - members).abs() < 1e-6 * members, "{kept} {members}");
    }

    #[test]
    fn opposite_orientations_are_the_same_covariance() {
        // q and −q are one rotation: a merge must not average them to zero.
        let q = Quat::from_rotation_z(0.9);
        let s = Vec3::new(0.5, 0.05, 0.01);
        let a = member(Vec3::ZERO, q, s, 0.8);
        let b = member(Vec3::ZERO, -q, s, 0.8);
        let merged = merge(&[a, b], &mut [0.0; 3]);
        assert!(close(covariance_of(&merged), covariance(q, s), 1e-6));
        // Two overlapping members keep their mass: twice the opacity.
        assert!((merged.opacity - 1.6).abs() < 1e-5);
    }

    #[test]
    fn flat_and_needle_members_stay_flat() {
        // Two flat splats side by side in the xy-plane: the merge is flat too.
        let flat = Vec3::new(0.2, 0.2, 0.0);
        let a = member(Vec3::new(-0.1, 0.0, 0.0), Quat::IDENTITY, flat, 0.9);
        let b = member(Vec3::new(0.1, 0.0, 0.0), Quat::IDENTITY, flat, 0.9);
        let merged = merge(&[a, b], &mut [0.0; 3]);
        assert!(merged.scale.min_element() < 1e-6, "{}", merged.scale);
        assert!(merged.scale.is_finite() && merged.opacity > 0.0);
        // Crossed needles make a flat cross.
        let needle = Vec3::new(1.0, 0.0, 0.0);
        let x = member(Vec3::ZERO, Quat::IDENTITY, needle, 0.5);
        let y = member(
            Vec3::ZERO,
            Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
            needle,
            0.5,
        );
        let merged = merge(&[x, y], &mut [0.0; 3]);
        let c = covariance_of(&merged);
        assert!((c.x_axis.x - 0.5).abs() < 1e-4 && (c.y_axis.y - 0.5).abs() < 1e-4);
        assert!(c.z_axis.z.abs() < 1e-9);
    }

    #[test]
    fn zero_opacity_and_points_stay_finite() {
        let a = member(Vec3::X, Quat::IDENTITY, Vec3::splat(0.1), 0.0);
        let b = member(-Vec3::X, Quat::IDENTITY, Vec3::splat(0.1), 0.0);
        let merged = merge(&[a, b], &mut [0.0; 3]);
        assert!(merged.position.length() < 1e-6, "by count");
        assert_eq!(merged.opacity, 0.0);
        // Zero-size points at one place composite their opacities.
        let p = member(Vec3::ONE, Quat::IDENTITY, Vec3::ZERO, 0.5);
        let merged = merge(&[p, p], &mut [0.0; 3]);
        assert!((merged.opacity - 0.75).abs() < 1e-6);
        assert_eq!(merged.scale, Vec3::ZERO);
    }

    #[test]
    fn huge_scales_and_opacity_capped() {
        let a = member(Vec3::ZERO, Quat::IDENTITY, Vec3::splat(1e6), 1.0);
        let b = member(
            Vec3::new(1e6, 0.0, 0.0),
            Quat::IDENTITY,
            Vec3::splat(1e6),
            1.0,
        );
        let merged = merge(&[a, b], &mut [0.0; 3]);
        assert!(merged.position.is_finite() && merged.scale.is_finite());
        assert!(merged.opacity <= MAX_OPACITY && merged.opacity > 0.5);
        // Many overlapping opaque members: the renderers' ceiling, not more.
        let many = vec![member(Vec3::ZERO, Quat::IDENTITY, Vec3::splat(0.1), 0.9); 10];
        assert_eq!(merge(&many, &mut [0.0; 3]).opacity, MAX_OPACITY);
    }
}
