//! A deterministic 3DGS scene of any size, so scale can be measured without
//! downloads: a subject (an ellipsoid shell of splats with view-dependent
//! colour) on a floor in front of a backdrop, with a few floaters far away as
//! trained scenes have — the same bytes for the same count and seed.

use glam::{Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::splats::SplatScene;

/// One Gaussian of the synthetic scene (SH degree 3, 16 coefficients ×
/// RGB, coefficient-major).
#[derive(Clone, Debug, PartialEq)]
pub struct SyntheticSplat {
    /// Centre.
    pub position: Vec3,
    /// Rotation (not normalised; the scene normalises it).
    pub rotation: Quat,
    /// Standard deviations.
    pub scale: Vec3,
    /// Opacity in [0, 1].
    pub opacity: f32,
    /// SH coefficients.
    pub sh: [f32; 48],
}

/// A scene of `count` Gaussians (SH degree 3), deterministic from `seed`.
pub fn synthetic_scene(count: usize, seed: u64) -> SplatScene {
    let mut scene = SplatScene::with_degree(3);
    for g in synthetic_splats(count, seed) {
        scene.push(g.position, g.rotation, g.scale, g.opacity, &g.sh);
    }
    scene
}

/// The Gaussians of [`synthetic_scene`], one at a time, so that a file of
/// any size can be written without holding the scene.
pub fn synthetic_splats(count: usize, seed: u64) -> impl Iterator<Item = SyntheticSplat> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    // Splat size follows the density: more splats, smaller ones.
    let size = 2.5 / (count.max(1) as f32).sqrt();
    (0..count).map(move |i| synthetic_splat(&mut rng, i, size))
}

/// Gaussian `i`, drawn from the scene's one random stream.
fn synthetic_splat(rng: &mut ChaCha8Rng, i: usize, size: f32) -> SyntheticSplat {
    let mut sh = [0.0f32; 48];
    let part = rng.random_range(0.0f32..1.0);
    let (position, base, spread) = if i % 1000 == 999 {
        // Floaters: one in a thousand, 20-40 units out.
        let dir = Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-0.2..1.0),
            rng.random_range(-1.0..1.0),
        )
        .normalize_or(Vec3::X);
        (dir * rng.random_range(20.0..40.0), [0.8, 0.8, 0.9], 3.0)
    } else if part < 0.5 {
        let u = rng.random_range(0.0f32..std::f32::consts::TAU);
        let v = rng.random_range(-1.0f32..1.0);
        let r = (1.0 - v * v).sqrt();
        let p = Vec3::new(r * u.cos() * 0.6, v * 0.9 + 0.9, r * u.sin() * 0.5);
        (p, [0.75 + 0.2 * v, 0.5 + 0.2 * u.sin(), 0.4], 1.0)
    } else if part < 0.8 {
        let p = Vec3::new(
            rng.random_range(-3.0..3.0),
            0.0,
            rng.random_range(-3.0..3.0),
        );
        let checker = ((p.x.floor() + p.z.floor()) as i32).rem_euclid(2) as f32;
        (p, [0.3 + 0.3 * checker, 0.35, 0.3], 2.0)
    } else {
        let p = Vec3::new(
            rng.random_range(-3.0..3.0),
            rng.random_range(0.0..3.0),
            -2.5,
        );
        (p, [0.2, 0.3 + 0.1 * p.y, 0.5], 2.0)
    };
    for (c, b) in base.iter().enumerate() {
        sh[c] = (b + rng.random_range(-0.05..0.05) - 0.5) / 0.282_094_8;
    }
    for s in sh.iter_mut().skip(3) {
        *s = rng.random_range(-0.05..0.05);
    }
    let rotation = Quat::from_xyzw(
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
        rng.random_range(-1.0..1.0),
    );
    let scale = Vec3::new(
        rng.random_range(0.5..1.5),
        rng.random_range(0.5..1.5),
        rng.random_range(0.2..0.6),
    ) * size
        * spread;
    let opacity = rng.random_range(0.3..1.0);
    SyntheticSplat {
        position,
        rotation,
        scale,
        opacity,
        sh,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn synthetic_scenes_are_deterministic_and_framed_without_floaters() {
        let a = synthetic_scene(20_000, 1);
        assert_eq!(a, synthetic_scene(20_000, 1));
        assert_ne!(a, synthetic_scene(20_000, 2));
        assert_eq!(a.len(), 20_000);
        let (lo, hi) = a.robust_bounds().unwrap();
        assert!(
            hi.max_element() < 10.0 && lo.min_element() > -10.0,
            "{lo} {hi}"
        );
        assert!(a.bounds().unwrap().1.max_element() > 15.0, "floaters exist");
    }
}
