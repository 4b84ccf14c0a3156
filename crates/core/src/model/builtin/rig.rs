//! Skeleton of the built-in head: skinning weights and the joint regressor.
//!
//! Joints are regressed from vertices (as in FLAME), so a different face shape
//! moves its joints too: the eyes from their eyeball vertices, the jaw from two
//! surface points under the ears, neck and global from rings around the neck.

use glam::Vec3;

use super::layout::*;
use super::mesh::{RawMesh, VertexPart};
use super::surface::Hole;
use crate::model::geometry::smoothstep;
use crate::model::head::{Joint, RegressorRow, JOINT_COUNT};

/// Linear blend skinning weights of every vertex (rows sum to 1).
pub fn skin_weights(mesh: &RawMesh, mouth: &Hole) -> Vec<[f32; JOINT_COUNT]> {
    mesh.positions
        .iter()
        .zip(&mesh.vertex_parts)
        .map(|(&p, part)| {
            let mut w = [0.0; JOINT_COUNT];
            match *part {
                VertexPart::Eyeball(Side::Left) => w[Joint::LeftEye as usize] = 1.0,
                VertexPart::Eyeball(Side::Right) => w[Joint::RightEye as usize] = 1.0,
                VertexPart::Teeth { upper: true } | VertexPart::EyeSocket { .. } => {
                    w[Joint::Neck as usize] = 1.0
                }
                VertexPart::Teeth { upper: false } => w[Joint::Jaw as usize] = 1.0,
                VertexPart::Pocket { alpha, .. } => {
                    let jaw = smoothstep(-0.25, 0.25, alpha.sin());
                    w[Joint::Jaw as usize] = jaw;
                    w[Joint::Neck as usize] = 1.0 - jaw;
                }
                VertexPart::Pole => w[Joint::Neck as usize] = 1.0,
                VertexPart::Surface { row, col } => {
                    let lower_neck = smoothstep(NECK_JOINT.y - 0.01, GLOBAL_JOINT.y + 0.005, p.y);
                    let jaw = surface_jaw_weight(p, row as usize, col as usize, mouth);
                    w[Joint::Global as usize] = lower_neck;
                    w[Joint::Jaw as usize] = (1.0 - lower_neck) * jaw;
                    w[Joint::Neck as usize] = (1.0 - lower_neck) * (1.0 - jaw);
                }
            }
            w
        })
        .collect()
}

/// How much a surface vertex follows the jaw: everything below the mouth line in
/// front of the ears, with the slit itself cutting cleanly between the lips.
fn surface_jaw_weight(p: Vec3, row: usize, col: usize, mouth: &Hole) -> f32 {
    let below_mouth = smoothstep(MOUTH_Y + 0.004, MOUTH_Y - 0.016, p.y);
    let beside_slit = smoothstep(MOUTH_OPENING.x + 0.007, MOUTH_OPENING.x - 0.001, p.x.abs())
        * smoothstep(MOUTH_Y + 0.02, MOUTH_Y + 0.006, p.y)
        * smoothstep(MOUTH_Y - 0.03, MOUTH_Y - 0.015, p.y)
        * smoothstep(0.03, 0.06, p.z);
    let in_span = (mouth.cols.0..=mouth.cols.1).contains(&col);
    let w = if in_span && row >= mouth.rows.1 {
        below_mouth.max(beside_slit)
    } else if in_span && row <= mouth.rows.0 {
        below_mouth * (1.0 - beside_slit)
    } else {
        below_mouth
    };
    w * smoothstep(-0.035, 0.02, p.z) * smoothstep(-0.135, -0.100, p.y)
}

/// The joint regressor rows of the built-in head.
pub fn joint_regressor(mesh: &RawMesh) -> [RegressorRow; JOINT_COUNT] {
    let ring = |y: f32| -> RegressorRow {
        // The grid row whose vertices lie closest to height `y`, averaged.
        let mut rows: Vec<(u16, f32, u32)> = Vec::new();
        for (i, part) in mesh.vertex_parts.iter().enumerate() {
            if let VertexPart::Surface { row, .. } = part {
                let dy = (mesh.positions[i].y - y).abs();
                match rows.iter_mut().find(|r| r.0 == *row) {
                    Some(r) => {
                        r.1 += dy;
                        r.2 += 1;
                    }
                    None => rows.push((*row, dy, 1)),
                }
            }
        }
        let best = rows
            .iter()
            .min_by(|a, b| (a.1 / a.2 as f32).total_cmp(&(b.1 / b.2 as f32)))
            .map(|r| r.0)
            .expect("surface rows");
        average(
            mesh,
            |_, part| matches!(part, VertexPart::Surface { row, .. } if *row == best),
        )
    };
    let nearest = |target: Vec3| -> u32 {
        (0..mesh.positions.len())
            .filter(|&i| matches!(mesh.vertex_parts[i], VertexPart::Surface { .. }))
            .min_by(|&a, &b| {
                (mesh.positions[a] - target)
                    .length_squared()
                    .total_cmp(&(mesh.positions[b] - target).length_squared())
            })
            .expect("surface vertices") as u32
    };
    let hinge = |side: Side| nearest(side.place(Vec3::new(0.068, JAW_HINGE.y, JAW_HINGE.z)));
    let jaw = vec![(hinge(Side::Left), 0.5), (hinge(Side::Right), 0.5)];
    let eye = |side: Side| average(mesh, move |_, part| *part == VertexPart::Eyeball(side));
    [
        ring(GLOBAL_JOINT.y),
        ring(NECK_JOINT.y),
        jaw,
        eye(Side::Left),
        eye(Side::Right),
    ]
}

fn average(mesh: &RawMesh, select: impl Fn(usize, &VertexPart) -> bool) -> RegressorRow {
    let chosen: Vec<u32> = mesh
        .vertex_parts
        .iter()
        .enumerate()
        .filter(|(i, p)| select(*i, p))
        .map(|(i, _)| i as u32)
        .collect();
    let w = 1.0 / chosen.len() as f32;
    chosen.into_iter().map(|i| (i, w)).collect()
}
