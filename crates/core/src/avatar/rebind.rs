//! Moving Gaussians from one triangle to another without moving them: how
//! exports hand Gaussians bound to triangles a file cannot name (an added mouth
//! cavity's) to the nearest triangle it can.

use glam::Vec3;

use super::binding::{local_to_world, triangle_frames, world_to_local};
use super::gaussians::GaussianSet;
use crate::model::nearest::TriangleGrid;

/// A copy of `set` in which every Gaussian bound to triangle `keep` or later is
/// bound to the triangle among the first `keep` nearest its centre on the mesh
/// `vertices`, with its local position, rotation and scale recomputed so that
/// it sits exactly where it sat on that mesh. Gaussians already bound below
/// `keep` are copied unchanged.
pub fn rebind_past(
    set: &GaussianSet,
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    keep: usize,
) -> GaussianSet {
    let mut out = set.clone();
    if !set.binding.iter().any(|&b| b as usize >= keep) {
        return out;
    }
    let frames = triangle_frames(vertices, triangles);
    let grid = TriangleGrid::new(vertices, &triangles[..keep]);
    for i in 0..set.len() {
        let from = set.binding[i] as usize;
        if from < keep {
            continue;
        }
        let world = local_to_world(
            &frames[from],
            set.position[i],
            set.rotation[i],
            set.log_scale[i],
        );
        // A mesh without finite triangles below `keep` leaves no choice.
        let to = grid.nearest(world.position).map_or(0, |(t, _)| t);
        let (position, rotation, log_scale) = world_to_local(&frames[to as usize], &world);
        out.binding[i] = to;
        out.position[i] = position;
        out.rotation[i] = rotation;
        out.log_scale[i] = log_scale;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    #[test]
    fn rebound_gaussians_keep_their_place_and_shape() {
        // Two triangles a file knows, one it does not (index 2, behind them).
        let vertices = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.2, 0.2, -0.3),
            Vec3::new(0.9, 0.3, -0.3),
            Vec3::new(0.3, 0.8, -0.4),
        ];
        let triangles = [[0, 1, 2], [1, 3, 2], [4, 5, 6]];
        let mut set = GaussianSet::with_degree(0);
        let rot = Quat::from_rotation_y(0.4);
        set.push(
            2,
            Vec3::new(0.1, 0.05, 0.02),
            rot,
            Vec3::new(-3.0, -4.0, -5.0),
            0.5,
            &[0.1, 0.2, 0.3],
        );
        set.push(
            1,
            Vec3::new(0.0, 0.0, 0.1),
            Quat::IDENTITY,
            Vec3::splat(-2.0),
            0.0,
            &[0.0; 3],
        );
        let out = rebind_past(&set, &vertices, &triangles, 2);
        assert!(out.binding.iter().all(|&b| b < 2));
        assert_eq!(out.binding[1], 1);
        assert_eq!(
            out.position[1], set.position[1],
            "kept Gaussians are untouched"
        );
        let frames = triangle_frames(&vertices, &triangles);
        let before = local_to_world(
            &frames[2],
            set.position[0],
            set.rotation[0],
            set.log_scale[0],
        );
        let b = out.binding[0] as usize;
        let after = local_to_world(
            &frames[b],
            out.position[0],
            out.rotation[0],
            out.log_scale[0],
        );
        assert!((before.position - after.position).length() < 1e-5);
        assert!((before.scale - after.scale).length() < 1e-6);
        assert!(before.rotation.dot(after.rotation).abs() > 1.0 - 1e-5);
        assert_eq!(out.sh_of(0), set.sh_of(0));
        assert_eq!(out.opacity_logit[0], 0.5);
    }
}
