//! Small geometric helpers shared by the procedural head: smooth falloffs and
//! anisotropic Gaussian bumps evaluated in head space (metres, y up, +z forward,
//! +x towards the subject's left).

use glam::{DMat3, DVec3, Vec3};

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

/// Eigenvalues (descending) and orthonormal eigenvectors (as columns, in
/// the same order) of a symmetric 3×3 matrix, by cyclic Jacobi rotations:
/// exact to rounding for repeated eigenvalues and flat (rank-deficient)
/// inputs alike; near-diagonal inputs take one or two sweeps. Only the
/// upper triangle is read and kept: each rotation updates the two
/// diagonal entries it turns and the one off-diagonal pair left (the
/// rotated pair becomes zero), which halves the work of a full update —
/// `deform = "affine"` runs one per Gaussian reshaped (docs/method.md §6.7),
/// LOD merging one per merged pair. Session 50's rewrite moved results at
/// rounding level only (the 256² composite bench read the same to 4
/// decimals).
pub fn symmetric_eigen(m: [[f64; 3]; 3]) -> ([f64; 3], DMat3) {
    let mut diagonal = [m[0][0], m[1][1], m[2][2]];
    // The off-diagonal entries (0,1), (0,2), (1,2).
    let mut off = [m[0][1], m[0][2], m[1][2]];
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // Each plane (p, q) with the entries in `off` of (p, q), and of (p, r)
    // and (q, r) for the third axis r.
    const PLANES: [(usize, usize, usize, usize, usize); 3] =
        [(0, 1, 0, 1, 2), (0, 2, 1, 0, 2), (1, 2, 2, 0, 1)];
    for _sweep in 0..50 {
        let off_norm = off.iter().map(|x| x * x).sum::<f64>();
        let scale = diagonal.iter().map(|x| x * x).sum::<f64>();
        if off_norm <= 1e-30 * scale.max(1e-300) {
            break;
        }
        for (p, q, pq, pr, qr) in PLANES {
            let apq = off[pq];
            if apq.abs() < 1e-300 {
                continue;
            }
            let theta = (diagonal[q] - diagonal[p]) / (2.0 * apq);
            let t = if theta == 0.0 {
                1.0
            } else {
                theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
            };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            diagonal[p] -= t * apq;
            diagonal[q] += t * apq;
            off[pq] = 0.0;
            let (arp, arq) = (off[pr], off[qr]);
            off[pr] = c * arp - s * arq;
            off[qr] = s * arp + c * arq;
            for row in v.iter_mut() {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| diagonal[j].total_cmp(&diagonal[i]));
    let column = |k: usize| DVec3::new(v[0][k], v[1][k], v[2][k]).normalize();
    (
        order.map(|k| diagonal[k]),
        DMat3::from_cols(column(order[0]), column(order[1]), column(order[2])),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks that `(values, vectors)` decomposes `m`: descending values,
    /// orthonormal vectors, V·diag·Vᵀ = M to `tolerance` of M's size.
    fn assert_decomposes(m: [[f64; 3]; 3], tolerance: f64) {
        let (values, vectors) = symmetric_eigen(m);
        assert!(
            values[0] >= values[1] && values[1] >= values[2],
            "{values:?}"
        );
        let identity = vectors.transpose() * vectors - DMat3::IDENTITY;
        let largest = |d: DMat3| d.to_cols_array().iter().fold(0.0f64, |a, x| a.max(x.abs()));
        assert!(largest(identity) < 1e-12, "not orthonormal: {vectors:?}");
        let rebuilt = vectors * DMat3::from_diagonal(values.into()) * vectors.transpose();
        let given = DMat3::from_cols_array_2d(&m);
        let size = largest(given).max(f64::MIN_POSITIVE);
        assert!(
            largest(rebuilt - given) <= tolerance * size,
            "{m:?}: rebuilt {rebuilt:?}"
        );
    }

    #[test]
    fn symmetric_eigen_decomposes_hard_cases() {
        let turn = DMat3::from_quat(glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0));
        let rotated = |d: [f64; 3]| {
            (turn * DMat3::from_diagonal(d.into()) * turn.transpose()).to_cols_array_2d()
        };
        let cases = [
            // Diagonal, already sorted and not.
            [[3.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 2.0]],
            // Zero, repeated, flat (rank 1 and 2) and general, turned.
            [[0.0; 3]; 3],
            rotated([2.0, 2.0, 2.0]),
            rotated([2.0, 2.0, 1.0]),
            rotated([1.0, 0.0, 0.0]),
            rotated([1.0, 1.0, 0.0]),
            rotated([4.0, 1.5, 0.25]),
            // Scales from a Gaussian 10⁻⁵ thin beside one 1 wide, tiny and huge.
            rotated([1.0, 1e-10, 1e-10]),
            rotated([1e-20, 3e-21, 1e-22]),
            rotated([1e20, 5e19, 1e18]),
            // Negative eigenvalues sort below zero.
            rotated([1.0, -0.5, -2.0]),
        ];
        for m in cases {
            assert_decomposes(m, 1e-13);
        }
        let (values, _) = symmetric_eigen(rotated([4.0, 1.5, 0.25]));
        for (got, want) in values.iter().zip([4.0, 1.5, 0.25]) {
            assert!((got - want).abs() < 1e-14, "{values:?}");
        }
        // Many random symmetric matrices.
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        };
        for _ in 0..2000 {
            let (a, b, c, d, e, f) = (next(), next(), next(), next(), next(), next());
            assert_decomposes([[a, b, c], [b, d, e], [c, e, f]], 1e-13);
        }
    }

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
