//! Which way is up in a scene file that does not say: COLMAP and INRIA
//! captures are usually y-down, Blender-style scenes z-up, heads y-up. A
//! capture's cameras decide it when their file is at hand (INRIA's
//! `cameras.json`: each camera's image "up" is minus its y axis); without
//! them, the ground does, conservatively: when a good share of the flat
//! Gaussians lie flat along one axis (floors, table tops, ground), and most
//! of that flat mass lies on one side of the scene's middle, that side is
//! down. Anything less clear keeps +y; `flip-up` corrects a wrong guess.

use glam::Vec3;

use super::camera::UpAxis;
use super::splats::SplatScene;

/// How the up axis was chosen, for the viewer's panel.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum UpReason {
    /// The user said so (`--up`, or a session header).
    Given,
    /// The capture's cameras.
    Cameras,
    /// The ground's orientation and side.
    Ground,
    /// Nothing was clear: the default.
    Default,
}

impl UpReason {
    /// A few words for the panel.
    pub fn describe(self) -> &'static str {
        match self {
            UpReason::Given => "as given",
            UpReason::Cameras => "from the capture's cameras",
            UpReason::Ground => "guessed from the ground",
            UpReason::Default => "default",
        }
    }
}

/// The axis (+y, -y, +z, -z) nearest a direction that cameras call up, when
/// one is clearly nearest.
pub fn nearest_up(direction: Vec3) -> Option<UpAxis> {
    let d = direction.try_normalize()?;
    let (axis, best) = [
        (UpAxis::PosY, d.y),
        (UpAxis::NegY, -d.y),
        (UpAxis::PosZ, d.z),
        (UpAxis::NegZ, -d.z),
    ]
    .into_iter()
    .max_by(|a, b| a.1.total_cmp(&b.1))?;
    (best > 0.5).then_some(axis)
}

/// Share of the flat mass that must lie flat along the axis.
const FLAT_SHARE: f64 = 0.25;
/// Share of that mass that must lie on one side of the middle.
const ONE_SIDE: f64 = 0.7;
/// A Gaussian is flat when its smallest scale is below this share of its middle one.
const FLATNESS: f32 = 0.3;
/// cos 20°: a flat Gaussian lies along an axis when its normal is this close to it.
const ALONG: f32 = 0.94;

/// Guesses up from the ground (see the module documentation); `None` when
/// the scene does not show one clearly.
pub fn ground_up(scene: &SplatScene) -> Option<UpAxis> {
    let (lo, hi) = scene.robust_bounds()?;
    let inside = |p: Vec3| p.cmpge(lo).all() && p.cmple(hi).all();
    let mut flat_mass = 0.0f64;
    // Per axis (y, z): flat mass along it, and its mass below and above the middle.
    let mut along = [[0.0f64; 3]; 2];
    let middle = (lo + hi) * 0.5;
    for i in 0..scene.len() {
        let (p, s, o) = (scene.position[i], scene.scale[i], scene.opacity[i]);
        if !inside(p) || !s.is_finite() || !o.is_finite() || o <= 0.0 {
            continue;
        }
        let mut axes = [(s.x, Vec3::X), (s.y, Vec3::Y), (s.z, Vec3::Z)];
        axes.sort_by(|a, b| a.0.total_cmp(&b.0));
        if axes[0].0 >= FLATNESS * axes[1].0 {
            continue;
        }
        let weight = (o * axes[1].0 * axes[2].0) as f64;
        flat_mass += weight;
        let normal = scene.rotation[i] * axes[0].1;
        for (k, axis) in [1usize, 2].into_iter().enumerate() {
            if normal[axis].abs() >= ALONG {
                along[k][0] += weight;
                let side = if p[axis] < middle[axis] { 1 } else { 2 };
                along[k][side] += weight;
            }
        }
    }
    if flat_mass <= 0.0 {
        return None;
    }
    let k = if along[0][0] >= along[1][0] { 0 } else { 1 };
    let [mass, below, above] = along[k];
    let other = along[1 - k][0];
    if mass < FLAT_SHARE * flat_mass || mass < 2.0 * other {
        return None;
    }
    let (positive, negative) = if k == 0 {
        (UpAxis::PosY, UpAxis::NegY)
    } else {
        (UpAxis::PosZ, UpAxis::NegZ)
    };
    if below >= ONE_SIDE * mass {
        Some(positive) // the ground is at the low end: up is +axis
    } else if above >= ONE_SIDE * mass {
        Some(negative)
    } else {
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Quat;

    /// A capture: a floor of flat Gaussians, boxes standing on it and a
    /// sparse tree canopy above, with "up" along `up`.
    fn capture(up: Vec3) -> SplatScene {
        let to_world = Quat::from_rotation_arc(Vec3::Y, up);
        let mut scene = SplatScene::with_degree(0);
        let sh = [0.1f32; 3];
        let mut push = |p: Vec3, flat_normal: Vec3, size: f32| {
            let r = to_world * Quat::from_rotation_arc(Vec3::Z, flat_normal);
            scene.push(
                to_world * p,
                r,
                Vec3::new(size, size, size * 0.05),
                0.9,
                &sh,
            );
        };
        for i in 0..60 {
            for j in 0..60 {
                let p = Vec3::new(i as f32 * 0.1 - 3.0, 0.0, j as f32 * 0.1 - 3.0);
                push(p, Vec3::Y, 0.06);
            }
        }
        for k in 0..2000 {
            let t = k as f32 * 0.618;
            let p = Vec3::new(
                (t * 7.0).sin() * 0.5,
                (k % 40) as f32 * 0.02,
                (t * 3.0).cos() * 0.5,
            );
            push(p, Vec3::new(t.cos(), 0.0, t.sin()), 0.03);
        }
        for k in 0..400 {
            let t = k as f32 * 1.7;
            let p = Vec3::new(t.sin() * 2.0, 2.0 + (k % 7) as f32 * 0.1, t.cos() * 2.0);
            push(p, Vec3::new(t.cos(), 0.3, t.sin()).normalize(), 0.05);
        }
        scene
    }

    #[test]
    fn the_ground_shows_which_way_is_up() {
        assert_eq!(ground_up(&capture(Vec3::Y)), Some(UpAxis::PosY));
        assert_eq!(ground_up(&capture(-Vec3::Y)), Some(UpAxis::NegY));
        assert_eq!(ground_up(&capture(Vec3::Z)), Some(UpAxis::PosZ));
        assert_eq!(ground_up(&capture(-Vec3::Z)), Some(UpAxis::NegZ));
    }

    #[test]
    fn unclear_scenes_keep_the_default() {
        // Randomly oriented splats (the synthetic scene) and a head-like
        // shell: no ground to read.
        assert_eq!(
            ground_up(&crate::scene::synthetic::synthetic_scene(20_000, 3)),
            None
        );
        assert_eq!(ground_up(&SplatScene::with_degree(0)), None);
        assert_eq!(nearest_up(Vec3::new(0.1, -0.9, 0.2)), Some(UpAxis::NegY));
        assert_eq!(
            nearest_up(Vec3::new(0.9, 0.1, 0.1)),
            None,
            "x is not offered"
        );
        assert_eq!(nearest_up(Vec3::ZERO), None);
    }
}
