//! Shapes and poses of a composite: its neutral mesh blended from the
//! sources' by the recipe's shape weights (method §6), and each frame posed
//! in either animation mode (§6.6) with its triangle frames, and the
//! world-space Gaussians they carry.

use glam::{DVec3, Vec3};

use super::{Composite, Engine, PosedMesh};
use crate::avatar::binding::triangle_frames_into;
use crate::compose::recipe::{AnimationMode, ResolvedRecipe};
use crate::model::head::{Joint, Pose};
use crate::model::regions::Region;
use crate::scene::splats::SplatScene;

impl Engine {
    /// Blends the sources' neutral meshes with the recipe's shape weights. When
    /// every group takes its whole shape from one source, that source's mesh is
    /// the exact answer (moved so the pinned vertex sits where the base has it).
    pub fn blend_neutral(&self, recipe: &ResolvedRecipe) -> (Vec<Vec3>, f64) {
        let single = |row: &Vec<f64>| row.iter().position(|&w| w == 1.0);
        let first = single(&recipe.shape[0]);
        if let Some(f) = first.filter(|_| recipe.shape.iter().all(|row| single(row) == first)) {
            let p = self.blender.pinned_vertex() as usize;
            let shift = self.neutrals[recipe.base][p] - self.neutrals[f][p];
            let mesh = if f == recipe.base {
                self.neutrals[f].clone()
            } else {
                self.neutrals[f].iter().map(|v| *v + shift).collect()
            };
            return (mesh, 0.0);
        }
        let mut rhs = vec![DVec3::ZERO; self.blender.vertex_count()];
        for r in Region::ALL {
            for (f, &w) in recipe.shape[r.group().index()].iter().enumerate() {
                if w > 0.0 {
                    for &(v, d) in &self.region_rhs[f][r.index()] {
                        rhs[v as usize] += w * d;
                    }
                }
            }
        }
        let pin = self.neutrals[recipe.base][self.blender.pinned_vertex() as usize].as_dvec3();
        let solution = self.blender.solve(&rhs, pin);
        (
            solution.vertices.iter().map(|v| v.as_vec3()).collect(),
            solution.residual,
        )
    }

    /// Expression and pose of the recipe's frame (rest when it has no motion).
    /// Includes the recipe's manual pose and expression offsets.
    pub fn frame_parameters(&self, recipe: &ResolvedRecipe, frame: usize) -> (Vec<f32>, Pose) {
        let (mut expression, mut pose) = match recipe.motion {
            Some(m) => {
                let (e, p) = self.db.motions[m].frame(frame);
                (e.to_vec(), *p)
            }
            None => (Vec::new(), Pose::REST),
        };
        let o = &recipe.offsets;
        if !o.is_zero() {
            let add = |v: &mut glam::Vec3, d: [f32; 3]| *v += glam::Vec3::from(d);
            add(&mut pose.joints[Joint::Jaw as usize], o.jaw);
            add(&mut pose.joints[Joint::Neck as usize], o.neck);
            add(&mut pose.joints[Joint::LeftEye as usize], o.eyes);
            add(&mut pose.joints[Joint::RightEye as usize], o.eyes);
            let n = self.db.model.expression_basis.len();
            if expression.len() < n.min(o.expression.len()) {
                expression.resize(n.min(o.expression.len()), 0.0);
            }
            for (e, d) in expression.iter_mut().zip(o.expression) {
                *e += d;
            }
        }
        (expression, pose)
    }

    /// The vertex offsets of the recipe's frame (its motion's
    /// `dynamic_offset`), when the motion has them.
    pub fn frame_offset(&self, recipe: &ResolvedRecipe, frame: usize) -> Option<&[Vec3]> {
        recipe
            .motion
            .and_then(|m| self.db.motions[m].frame_offset(frame))
    }

    /// Poses the composite at `frame` of its motion, in the recipe's animation mode.
    pub fn pose(&self, composite: &Composite, frame: usize, out: &mut PosedMesh) {
        let (expression, pose) = self.frame_parameters(&composite.recipe, frame);
        let offset = self.frame_offset(&composite.recipe, frame);
        let mode = composite.recipe.mode;
        self.pose_offset_with(composite, &expression, &pose, offset, mode, out);
    }

    /// Poses the composite with explicit parameters and mode.
    pub fn pose_with(
        &self,
        composite: &Composite,
        expression: &[f32],
        pose: &Pose,
        mode: AnimationMode,
        out: &mut PosedMesh,
    ) {
        self.pose_offset_with(composite, expression, pose, None, mode, out);
    }

    /// [`Engine::pose_with`] with a frame's vertex offsets (a motion's
    /// `dynamic_offset`), added to each unposed mesh with the expression.
    pub fn pose_offset_with(
        &self,
        composite: &Composite,
        expression: &[f32],
        pose: &Pose,
        offset: Option<&[Vec3]>,
        mode: AnimationMode,
        out: &mut PosedMesh,
    ) {
        let model = &self.db.model;
        match mode {
            AnimationMode::Fast => {
                let neutral = &composite.neutral;
                model.pose_offset(neutral, expression, pose, offset, &mut out.vertices);
                out.residual = composite.residual;
            }
            AnimationMode::Exact => {
                let recipe = &composite.recipe;
                let sources = recipe.shape_sources();
                let posed: Vec<(usize, Vec<Vec3>)> = sources
                    .iter()
                    .map(|&f| {
                        let mut v = Vec::new();
                        model.pose_offset(&self.neutrals[f], expression, pose, offset, &mut v);
                        (f, v)
                    })
                    .collect();
                let mut meshes: Vec<Option<&[Vec3]>> = vec![None; self.db.sources.len()];
                for (f, v) in &posed {
                    meshes[*f] = Some(v);
                }
                let weights: Vec<&[f64]> = Region::ALL
                    .iter()
                    .map(|r| recipe.shape[r.group().index()].as_slice())
                    .collect();
                let rhs = self.blender.rhs_from_meshes(&weights, &meshes);
                let base = meshes[recipe.base].expect("base is always posed");
                let pin = base[self.blender.pinned_vertex() as usize].as_dvec3();
                let solution = self.blender.solve(&rhs, pin);
                out.vertices.clear();
                out.vertices
                    .extend(solution.vertices.iter().map(|v| v.as_vec3()));
                out.residual = solution.residual;
            }
        }
        triangle_frames_into(&out.vertices, &model.triangles, &mut out.frames);
    }

    /// World-space Gaussians of a posed composite (CPU binding; the GPU renderer
    /// does the same on the device).
    pub fn scene(&self, composite: &Composite, posed: &PosedMesh) -> SplatScene {
        let mut scene = SplatScene::with_degree(composite.gaussians.sh_degree);
        let all: Vec<u32> = (0..composite.gaussians.len() as u32).collect();
        scene.append_bound(&composite.gaussians, &posed.frames, &all);
        scene
    }
}
