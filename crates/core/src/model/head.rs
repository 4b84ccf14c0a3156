//! The FLAME-like morphable head model and its forward pass: shape and expression
//! blendshapes, joint regression, optional pose correctives and linear blend skinning.
//!
//! The forward pass is split in two on purpose: [`HeadModel::neutral`] gives a
//! source's identity mesh (template + shape + static offset), and
//! [`HeadModel::pose`] animates any neutral mesh. The composition engine blends
//! neutral meshes once and then animates the result as a single head.

use glam::{DVec3, Mat3, Quat, Vec3};

use super::cavity::MouthCavity;
use super::regions::Region;

/// Number of skeleton joints (FLAME order: global, neck, jaw, left eye, right eye).
pub const JOINT_COUNT: usize = 5;

/// The skeleton joints, in FLAME order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Joint {
    Global = 0,
    Neck = 1,
    Jaw = 2,
    LeftEye = 3,
    RightEye = 4,
}

/// Parent of each joint in the kinematic tree (FLAME: neck hangs off global, jaw and
/// eyes off the neck).
pub const JOINT_PARENTS: [Option<usize>; JOINT_COUNT] = [None, Some(0), Some(1), Some(1), Some(1)];

/// Names of the joints, for files and the editor.
pub const JOINT_NAMES: [&str; JOINT_COUNT] = ["global", "neck", "jaw", "left_eye", "right_eye"];

/// Number of pose-corrective inputs: the 4 non-root joints' (R - I), 9 entries each.
pub const POSE_FEATURES: usize = (JOINT_COUNT - 1) * 9;

/// A linear blendshape basis: component `k` is a per-vertex displacement field.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Basis {
    vertex_count: usize,
    names: Vec<String>,
    /// Component-major displacements: component k occupies `[k*V, (k+1)*V)`.
    data: Vec<Vec3>,
}

impl Basis {
    /// An empty basis over `vertex_count` vertices.
    pub fn new(vertex_count: usize) -> Self {
        Self {
            vertex_count,
            names: Vec::new(),
            data: Vec::new(),
        }
    }

    /// Appends a named component; `field` must have one displacement per vertex.
    pub fn push(&mut self, name: impl Into<String>, field: Vec<Vec3>) {
        assert_eq!(field.len(), self.vertex_count, "basis field length");
        self.names.push(name.into());
        self.data.extend(field);
    }

    /// Number of components.
    pub fn len(&self) -> usize {
        self.names.len()
    }

    /// True when the basis has no component.
    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// Names of the components, in order.
    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Displacement field of component `k`.
    pub fn component(&self, k: usize) -> &[Vec3] {
        &self.data[k * self.vertex_count..(k + 1) * self.vertex_count]
    }

    /// This basis over `vertex_count` vertices: each component's field with
    /// the new vertices' displacements appended by `extend`.
    pub fn extended(&self, vertex_count: usize, extend: impl Fn(&mut Vec<Vec3>)) -> Basis {
        let mut out = Basis::new(vertex_count);
        for k in 0..self.len() {
            let mut field = self.component(k).to_vec();
            extend(&mut field);
            out.push(self.names[k].clone(), field);
        }
        out
    }

    /// Adds `Σ_k coeffs[k] · component(k)` to `out`. Coefficients past the basis
    /// length are ignored (a file may carry more than the model uses); zero
    /// coefficients cost nothing.
    pub fn accumulate(&self, coeffs: &[f32], out: &mut [Vec3]) {
        for (k, &c) in coeffs.iter().enumerate().take(self.len()) {
            if c == 0.0 {
                continue;
            }
            for (o, d) in out.iter_mut().zip(self.component(k)) {
                *o += c * *d;
            }
        }
    }
}

/// Joint rotations (axis-angle, radians) and a root translation for one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Pose {
    /// Axis-angle rotation per joint, in [`JOINT_NAMES`] order.
    pub joints: [Vec3; JOINT_COUNT],
    /// Translation added after skinning.
    pub translation: Vec3,
}

impl Pose {
    /// The rest pose: no rotation, no translation.
    pub const REST: Pose = Pose {
        joints: [Vec3::ZERO; JOINT_COUNT],
        translation: Vec3::ZERO,
    };
}

/// Sparse row of the joint regressor: (vertex, weight) pairs.
pub type RegressorRow = Vec<(u32, f32)>;

/// A FLAME-like morphable head: fixed topology, blendshapes and a 5-joint skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct HeadModel {
    /// Rest-pose template vertices.
    pub template: Vec<Vec3>,
    /// Triangle list (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
    /// Region of each triangle.
    pub triangle_regions: Vec<Region>,
    /// Identity basis (β).
    pub shape_basis: Basis,
    /// Expression basis (ψ).
    pub expression_basis: Basis,
    /// One sparse row per joint: joint position = Σ weight · shaped vertex.
    pub joint_regressor: [RegressorRow; JOINT_COUNT],
    /// Linear blend skinning weights per vertex (each row sums to 1).
    pub skin_weights: Vec<[f32; JOINT_COUNT]>,
    /// Optional pose correctives: [`POSE_FEATURES`] components driven by (R - I).
    pub pose_correctives: Option<Basis>,
    /// The mouth cavity visage added behind the model's own vertices and
    /// triangles (FLAME has none), which files never see.
    pub mouth_cavity: Option<MouthCavity>,
}

impl HeadModel {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.template.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Vertices as files (offsets in `flame_param.npz`) have them: all but an
    /// added mouth cavity's.
    pub fn file_vertex_count(&self) -> usize {
        self.mouth_cavity
            .as_ref()
            .map_or(self.vertex_count(), |c| c.first_vertex)
    }

    /// Triangles as files (`binding_0` in `point_cloud.ply`) know them: all but
    /// an added mouth cavity's.
    pub fn file_triangle_count(&self) -> usize {
        self.mouth_cavity
            .as_ref()
            .map_or(self.triangle_count(), |c| c.first_triangle)
    }

    /// A source's identity mesh: template + shape blendshapes + static offset,
    /// summed in f64 and rounded once, so an offset written as `neutral - template`
    /// (in f64) reproduces `neutral` exactly.
    pub fn neutral(&self, shape: &[f32], static_offset: Option<&[DVec3]>) -> Vec<Vec3> {
        let mut v: Vec<DVec3> = self.template.iter().map(|p| p.as_dvec3()).collect();
        for (k, &c) in shape.iter().enumerate().take(self.shape_basis.len()) {
            if c != 0.0 {
                for (o, d) in v.iter_mut().zip(self.shape_basis.component(k)) {
                    *o += c as f64 * d.as_dvec3();
                }
            }
        }
        if let Some(offset) = static_offset {
            for (o, d) in v.iter_mut().zip(offset) {
                *o += *d;
            }
        }
        v.into_iter().map(|p| p.as_vec3()).collect()
    }

    /// Joint positions regressed from a shaped (unposed) mesh.
    pub fn joints(&self, shaped: &[Vec3]) -> [Vec3; JOINT_COUNT] {
        let mut joints = [Vec3::ZERO; JOINT_COUNT];
        for (j, row) in self.joint_regressor.iter().enumerate() {
            joints[j] = row
                .iter()
                .map(|&(v, w)| w * shaped[v as usize])
                .fold(Vec3::ZERO, |a, b| a + b);
        }
        joints
    }

    /// Animates a neutral mesh: adds the expression, regresses joints, applies pose
    /// correctives and skins. `out` is resized to the vertex count.
    pub fn pose(&self, neutral: &[Vec3], expression: &[f32], pose: &Pose, out: &mut Vec<Vec3>) {
        self.pose_offset(neutral, expression, pose, None, out);
    }

    /// [`HeadModel::pose`] with a frame's vertex offsets (a motion's
    /// `dynamic_offset`) added to the unposed mesh with the expression, so
    /// the joints are regressed from it and it is skinned with it, as VHAP's
    /// FLAME adds them (docs/method.md §9.4).
    pub fn pose_offset(
        &self,
        neutral: &[Vec3],
        expression: &[f32],
        pose: &Pose,
        offset: Option<&[Vec3]>,
        out: &mut Vec<Vec3>,
    ) {
        out.clear();
        out.extend_from_slice(neutral);
        self.expression_basis.accumulate(expression, out);
        for (v, d) in out.iter_mut().zip(offset.unwrap_or_default()) {
            *v += *d;
        }
        let joints = self.joints(out);
        let rotations = joint_rotations(pose);
        if let Some(correctives) = &self.pose_correctives {
            correctives.accumulate(&pose_features(&rotations), out);
        }
        let transforms = skinning_transforms(&rotations, &joints);
        for (v, w) in out.iter_mut().zip(&self.skin_weights) {
            *v = skin_vertex(*v, w, &transforms) + pose.translation;
        }
    }

    /// Full forward pass: neutral then pose.
    pub fn forward(
        &self,
        shape: &[f32],
        static_offset: Option<&[DVec3]>,
        expression: &[f32],
        pose: &Pose,
    ) -> Vec<Vec3> {
        let neutral = self.neutral(shape, static_offset);
        let mut out = Vec::with_capacity(neutral.len());
        self.pose(&neutral, expression, pose, &mut out);
        out
    }
}

/// A rigid transform `x ↦ rotation·x + translation` for skinning.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidTransform {
    /// Linear part.
    pub rotation: Mat3,
    /// Translation part.
    pub translation: Vec3,
}

impl RigidTransform {
    fn apply(&self, x: Vec3) -> Vec3 {
        self.rotation * x + self.translation
    }
}

/// Rotation matrices of the joints from axis-angle (Rodrigues; zero → identity).
pub fn joint_rotations(pose: &Pose) -> [Mat3; JOINT_COUNT] {
    pose.joints.map(|aa| {
        if aa.is_finite() {
            Mat3::from_quat(Quat::from_scaled_axis(aa))
        } else {
            Mat3::IDENTITY
        }
    })
}

/// The pose-corrective feature vector: (R_j - I) of the non-root joints, row-major.
pub fn pose_features(rotations: &[Mat3; JOINT_COUNT]) -> [f32; POSE_FEATURES] {
    let mut f = [0.0; POSE_FEATURES];
    for (j, r) in rotations.iter().skip(1).enumerate() {
        let m = *r - Mat3::IDENTITY;
        for row in 0..3 {
            for col in 0..3 {
                f[j * 9 + row * 3 + col] = m.col(col)[row];
            }
        }
    }
    f
}

/// Per-joint skinning transforms that map rest-pose points to posed points,
/// composed along the kinematic tree (SMPL/FLAME convention).
pub fn skinning_transforms(
    rotations: &[Mat3; JOINT_COUNT],
    joints: &[Vec3; JOINT_COUNT],
) -> [RigidTransform; JOINT_COUNT] {
    // World transform of each joint frame (rest joint at origin of its local frame).
    let mut world = [RigidTransform {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
    }; JOINT_COUNT];
    for j in 0..JOINT_COUNT {
        let local_offset = match JOINT_PARENTS[j] {
            Some(p) => joints[j] - joints[p],
            None => joints[j],
        };
        let local = RigidTransform {
            rotation: rotations[j],
            translation: local_offset,
        };
        world[j] = match JOINT_PARENTS[j] {
            Some(p) => RigidTransform {
                rotation: world[p].rotation * local.rotation,
                translation: world[p].apply(local.translation),
            },
            None => local,
        };
    }
    // Remove the rest joint position so the transform applies to rest-pose points.
    for (t, joint) in world.iter_mut().zip(joints) {
        t.translation -= t.rotation * *joint;
    }
    world
}

fn skin_vertex(v: Vec3, weights: &[f32; JOINT_COUNT], transforms: &[RigidTransform]) -> Vec3 {
    let mut rotation = Mat3::ZERO;
    let mut translation = Vec3::ZERO;
    for (w, t) in weights.iter().zip(transforms) {
        if *w != 0.0 {
            rotation += t.rotation * *w;
            translation += t.translation * *w;
        }
    }
    rotation * v + translation
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skinning_with_rest_pose_is_identity() {
        let rotations = joint_rotations(&Pose::REST);
        let joints = [Vec3::new(0.1, 0.2, 0.3); JOINT_COUNT];
        for t in skinning_transforms(&rotations, &joints) {
            assert!(t.rotation.abs_diff_eq(Mat3::IDENTITY, 0.0));
            assert!(t.translation.abs_diff_eq(Vec3::ZERO, 1e-7));
        }
    }

    #[test]
    fn child_rotates_about_its_own_joint() {
        let mut pose = Pose::REST;
        pose.joints[Joint::Jaw as usize] = Vec3::new(0.0, 0.0, std::f32::consts::FRAC_PI_2);
        let mut joints = [Vec3::ZERO; JOINT_COUNT];
        joints[Joint::Jaw as usize] = Vec3::new(1.0, 0.0, 0.0);
        let t = skinning_transforms(&joint_rotations(&pose), &joints)[Joint::Jaw as usize];
        // The jaw joint itself stays put; a point one unit along +x from it swings to +y.
        assert!(t
            .apply(Vec3::new(1.0, 0.0, 0.0))
            .abs_diff_eq(Vec3::new(1.0, 0.0, 0.0), 1e-6));
        assert!(t
            .apply(Vec3::new(2.0, 0.0, 0.0))
            .abs_diff_eq(Vec3::new(1.0, 1.0, 0.0), 1e-6));
    }

    #[test]
    fn pose_features_vanish_at_rest() {
        let f = pose_features(&joint_rotations(&Pose::REST));
        assert!(f.iter().all(|x| *x == 0.0));
    }

    #[test]
    fn non_finite_axis_angle_is_ignored() {
        let mut pose = Pose::REST;
        pose.joints[1] = Vec3::new(f32::NAN, 0.0, 0.0);
        assert_eq!(joint_rotations(&pose)[1], Mat3::IDENTITY);
    }
}
