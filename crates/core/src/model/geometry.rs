//! Small geometric helpers shared by the procedural head: smooth falloffs and
//! anisotropic Gaussian bumps evaluated in head space (metres, y up, +z forward,
//! +x towards the subject's left).

use glam::Vec3;

/// Hermite smoothstep from `edge0` to `edge1` (either order), clamped to [0, 1].
pub fn smoothstep(edge0: f32, edge1: f32, x: f32) -> f32 {
    let t = ((x - edge0) / (edge1 - edge0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Linear interpolation.
pub fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + (b - a) * t
}

/// An anisotropic Gaussian displacement: `displacement · exp(-½ Σ ((p-c)/σ)²)`.
/// With `mirror`, the bump exists on both sides of the x = 0 plane, `center.x`
/// and `displacement.x` being mirrored for points with x < 0.
#[derive(Clone, Copy, Debug)]
pub struct Bump {
    /// Centre (for mirrored bumps: the +x side).
    pub center: Vec3,
    /// Per-axis standard deviation in metres.
    pub sigma: Vec3,
    /// Displacement at the centre.
    pub displacement: Vec3,
    /// Whether the bump is bilateral.
    pub mirror: bool,
}

impl Bump {
    /// A single bump.
    pub const fn new(center: Vec3, sigma: Vec3, displacement: Vec3) -> Self {
        Self {
            center,
            sigma,
            displacement,
            mirror: false,
        }
    }

    /// A bilateral bump (mirrored across x = 0).
    pub const fn mirrored(center: Vec3, sigma: Vec3, displacement: Vec3) -> Self {
        Self {
            center,
            sigma,
            displacement,
            mirror: true,
        }
    }

    /// The Gaussian weight at `p` (1 at the centre).
    pub fn weight(&self, p: Vec3) -> f32 {
        let q = if self.mirror {
            Vec3::new(p.x.abs(), p.y, p.z)
        } else {
            p
        };
        let d = (q - self.center) / self.sigma;
        (-0.5 * d.length_squared()).exp()
    }

    /// The displacement at `p`.
    pub fn at(&self, p: Vec3) -> Vec3 {
        let mut d = self.displacement * self.weight(p);
        if self.mirror && p.x < 0.0 {
            d.x = -d.x;
        }
        d
    }
}

/// Deterministic value noise in 3D (trilinear over a hashed lattice), in [0, 1).
pub fn value_noise(p: Vec3, seed: u32) -> f32 {
    let cell = p.floor();
    let f = p - cell;
    let s = f * f * (Vec3::splat(3.0) - 2.0 * f);
    let (x, y, z) = (cell.x as i32, cell.y as i32, cell.z as i32);
    let h = |dx: i32, dy: i32, dz: i32| lattice_hash(x + dx, y + dy, z + dz, seed);
    let lx0 = lerp(h(0, 0, 0), h(1, 0, 0), s.x);
    let lx1 = lerp(h(0, 1, 0), h(1, 1, 0), s.x);
    let lx2 = lerp(h(0, 0, 1), h(1, 0, 1), s.x);
    let lx3 = lerp(h(0, 1, 1), h(1, 1, 1), s.x);
    lerp(lerp(lx0, lx1, s.y), lerp(lx2, lx3, s.y), s.z)
}

/// Fractal (3-octave) value noise in [0, 1).
pub fn fractal_noise(p: Vec3, seed: u32) -> f32 {
    0.57 * value_noise(p, seed)
        + 0.29 * value_noise(p * 2.03, seed ^ 0x9e37)
        + 0.14 * value_noise(p * 4.11, seed ^ 0x7f4a)
}

fn lattice_hash(x: i32, y: i32, z: i32, seed: u32) -> f32 {
    let mut h = (x as u32).wrapping_mul(0x8da6_b343)
        ^ (y as u32).wrapping_mul(0xd816_3841)
        ^ (z as u32).wrapping_mul(0xcb1a_b31f)
        ^ seed.wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 15;
    h = h.wrapping_mul(0x2c1b_3c6d);
    h ^= h >> 12;
    h = h.wrapping_mul(0x297a_2d39);
    h ^= h >> 15;
    (h >> 8) as f32 / (1u32 << 24) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothstep_clamps_and_reverses() {
        assert_eq!(smoothstep(0.0, 1.0, -1.0), 0.0);
        assert_eq!(smoothstep(0.0, 1.0, 2.0), 1.0);
        assert_eq!(smoothstep(1.0, 0.0, 0.0), 1.0);
        assert!((smoothstep(0.0, 1.0, 0.5) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn mirrored_bump_is_symmetric() {
        let b = Bump::mirrored(
            Vec3::new(0.03, 0.0, 0.0),
            Vec3::splat(0.01),
            Vec3::new(0.01, 0.0, 0.0),
        );
        let l = b.at(Vec3::new(0.031, 0.001, 0.0));
        let r = b.at(Vec3::new(-0.031, 0.001, 0.0));
        assert!((l.x + r.x).abs() < 1e-9 && l.x > 0.0);
    }

    #[test]
    fn noise_is_deterministic_and_bounded() {
        for i in 0..200 {
            let p = Vec3::new(i as f32 * 0.37, -(i as f32) * 0.11, 0.5);
            let a = fractal_noise(p, 7);
            assert_eq!(a, fractal_noise(p, 7));
            assert!((0.0..1.0).contains(&a));
        }
    }
}
