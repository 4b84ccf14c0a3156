//! The eigen-decomposition of a symmetric 3×3 matrix: a covariance's axes
//! and variances. `deform = "affine"` re-factors every reshaped Gaussian's
//! covariance with it (docs/method.md §6.7), LOD merging every merged pair's,
//! hole filling every patch's; the first is on the editing path, so the
//! common case is solved in closed form and cyclic Jacobi rotations take
//! the inputs where that would lose digits.

use glam::{DMat3, DVec3};

/// Eigenvalues (descending) and orthonormal eigenvectors (as columns, in
/// the same order) of a symmetric 3×3 matrix; only the upper triangle is
/// read. Accurate to rounding of the matrix's size for repeated eigenvalues
/// and flat (rank-deficient) inputs alike: the closed form answers where its
/// eigenvalues span less than ten decades, Jacobi rotations the rest (and
/// zero or non-finite input), keeping small eigenvalues of a graded matrix
/// to their own relative precision. The vectors' handedness is not fixed.
pub fn symmetric_eigen(m: [[f64; 3]; 3]) -> ([f64; 3], DMat3) {
    closed_form(m).unwrap_or_else(|| jacobi(m))
}

/// Eigenvalues below this fraction of the largest in magnitude are left to
/// the Jacobi rotations: the closed form finds each to an absolute rounding
/// of the largest, which would leave fewer than six digits of one 10¹⁰ times
/// smaller (a Gaussian flatter than 1:10⁵), where Jacobi keeps them.
const GRADED: f64 = 1e-10;

/// The decomposition in closed form (Smith's trigonometric eigenvalues, the
/// eigenvector of the one farthest from the other two as a cross product of
/// two rows of A − λI, then one Jacobi rotation in the plane orthogonal to
/// it), about 60 % of Jacobi's cost on reshaped covariances; `None` where the input is zero,
/// subnormal, not finite, graded past [`GRADED`] or leaves no cross product to use.
fn closed_form(m: [[f64; 3]; 3]) -> Option<([f64; 3], DMat3)> {
    let upper = [m[0][0], m[1][1], m[2][2], m[0][1], m[0][2], m[1][2]];
    if !upper.iter().all(|x| x.is_finite()) {
        return None;
    }
    let size = upper.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    // A subnormal size has no finite reciprocal to scale by.
    if size < f64::MIN_POSITIVE {
        return None;
    }
    // Scaled to entries of at most 1, so no product below over- or underflows.
    let unit = size.recip();
    let [a00, a11, a22, a01, a02, a12] = upper.map(|x| x * unit);
    let a = DMat3::from_cols(
        DVec3::new(a00, a01, a02),
        DVec3::new(a01, a11, a12),
        DVec3::new(a02, a12, a22),
    );
    let mean = (a00 + a11 + a22) / 3.0;
    let (k00, k11, k22) = (a00 - mean, a11 - mean, a22 - mean);
    let p = (k00 * k00 + k11 * k11 + k22 * k22 + 2.0 * (a01 * a01 + a02 * a02 + a12 * a12)) / 6.0;
    if p <= 0.0 {
        return None;
    }
    let half_det = 0.5
        * (k00 * (k11 * k22 - a12 * a12) - a01 * (a01 * k22 - a12 * a02)
            + a02 * (a01 * a12 - k11 * a02));
    let root_p = p.sqrt();
    let cosine = (half_det / (p * root_p)).clamp(-1.0, 1.0);
    let (sin, cos) = (cosine.acos() / 3.0).sin_cos();
    let largest = mean + 2.0 * root_p * cos;
    let smallest = mean - root_p * (cos + 3f64.sqrt() * sin);
    let middle = 3.0 * mean - largest - smallest;
    // The eigenvalue farthest from the other two has the best-conditioned
    // eigenvector; the other two are settled exactly in the plane left.
    let isolated = if largest - middle >= middle - smallest {
        largest
    } else {
        smallest
    };
    let rows = [
        DVec3::new(a00 - isolated, a01, a02),
        DVec3::new(a01, a11 - isolated, a12),
        DVec3::new(a02, a12, a22 - isolated),
    ];
    let crosses = [
        rows[0].cross(rows[1]),
        rows[0].cross(rows[2]),
        rows[1].cross(rows[2]),
    ];
    let best = crosses
        .into_iter()
        .max_by(|x, y| x.length_squared().total_cmp(&y.length_squared()))?;
    // Scaled by its largest component before its length is taken: the
    // cross product of two nearly zero rows (a nearly scalar matrix) can be
    // so small that its squared length would be subnormal, short of digits.
    let largest_component = best.abs().max_element();
    if !(largest_component.is_finite() && largest_component >= f64::MIN_POSITIVE) {
        return None;
    }
    let best = best * largest_component.recip();
    let v = best * best.length().recip();
    // An orthonormal pair spanning the plane orthogonal to v.
    let axis = if v.x.abs() <= v.y.abs() && v.x.abs() <= v.z.abs() {
        DVec3::X
    } else if v.y.abs() <= v.z.abs() {
        DVec3::Y
    } else {
        DVec3::Z
    };
    let u = v.cross(axis).normalize();
    let w = v.cross(u);
    let (au, aw) = (a * u, a * w);
    let (b00, b01, b11) = (u.dot(au), u.dot(aw), w.dot(aw));
    let t = if b01 == 0.0 {
        0.0
    } else {
        let theta = (b11 - b00) / (2.0 * b01);
        if theta == 0.0 {
            1.0
        } else {
            theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt())
        }
    };
    let c = 1.0 / (t * t + 1.0).sqrt();
    let s = t * c;
    let mut pairs = [
        (v.dot(a * v), v),
        (b00 - t * b01, c * u - s * w),
        (b11 + t * b01, s * u + c * w),
    ];
    pairs.sort_by(|x, y| y.0.total_cmp(&x.0));
    let top = pairs[0].0.abs().max(pairs[2].0.abs());
    if pairs.iter().any(|(value, _)| value.abs() < GRADED * top) {
        return None;
    }
    Some((
        pairs.map(|(value, _)| value * size),
        DMat3::from_cols(pairs[0].1, pairs[1].1, pairs[2].1),
    ))
}

/// The decomposition by cyclic Jacobi rotations: exact to rounding for
/// repeated eigenvalues and flat inputs alike, and for a graded matrix
/// each eigenvalue to its own relative precision; near-diagonal inputs take
/// one or two sweeps. Only the upper triangle is read and kept: each
/// rotation updates the two diagonal entries it turns and the one
/// off-diagonal pair left (the rotated pair becomes zero).
fn jacobi(m: [[f64; 3]; 3]) -> ([f64; 3], DMat3) {
    // Scaled to entries of at most 1: the tolerances below are absolute, and
    // the squares of a 10⁻¹⁶⁰ matrix's entries would underflow to zero.
    let size = [m[0][0], m[1][1], m[2][2], m[0][1], m[0][2], m[1][2]]
        .iter()
        .fold(0.0f64, |s, x| s.max(x.abs()));
    let unit = if size > 0.0 && size.is_finite() {
        size
    } else {
        1.0
    };
    let mut diagonal = [m[0][0], m[1][1], m[2][2]].map(|x| x / unit);
    // The off-diagonal entries (0,1), (0,2), (1,2).
    let mut off = [m[0][1], m[0][2], m[1][2]].map(|x| x / unit);
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
        order.map(|k| diagonal[k] * unit),
        DMat3::from_cols(column(order[0]), column(order[1]), column(order[2])),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    type Solver = fn([[f64; 3]; 3]) -> ([f64; 3], DMat3);

    fn largest(d: DMat3) -> f64 {
        d.to_cols_array().iter().fold(0.0f64, |a, x| a.max(x.abs()))
    }

    /// Checks that `solve` decomposes `m`: descending values, orthonormal
    /// vectors, V·diag·Vᵀ = M to `tolerance` of M's size.
    fn assert_decomposes(solve: Solver, m: [[f64; 3]; 3], tolerance: f64) {
        assert_decomposition(solve(m), m, tolerance);
    }

    /// Checks that `(values, vectors)` decomposes `m` as above.
    fn assert_decomposition(
        (values, vectors): ([f64; 3], DMat3),
        m: [[f64; 3]; 3],
        tolerance: f64,
    ) {
        assert!(
            values[0] >= values[1] && values[1] >= values[2],
            "{values:?}"
        );
        let identity = vectors.transpose() * vectors - DMat3::IDENTITY;
        assert!(largest(identity) < 1e-12, "not orthonormal: {vectors:?}");
        let rebuilt = vectors * DMat3::from_diagonal(values.into()) * vectors.transpose();
        let given = DMat3::from_cols_array_2d(&m);
        let size = largest(given).max(f64::MIN_POSITIVE);
        assert!(
            largest(rebuilt - given) <= tolerance * size,
            "{m:?}: rebuilt {rebuilt:?}"
        );
    }

    /// `d` as the eigenvalues of a matrix turned off every axis.
    fn rotated(d: [f64; 3]) -> [[f64; 3]; 3] {
        let turn = DMat3::from_quat(glam::DQuat::from_euler(glam::EulerRot::XYZ, 0.3, -1.1, 2.0));
        (turn * DMat3::from_diagonal(d.into()) * turn.transpose()).to_cols_array_2d()
    }

    /// A xorshift generator of uniform numbers in [-1, 1).
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
        }
    }

    #[test]
    fn both_solvers_decompose_hard_cases() {
        let cases = [
            // Diagonal, already sorted and not.
            [[3.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]],
            [[1.0, 0.0, 0.0], [0.0, 5.0, 0.0], [0.0, 0.0, 2.0]],
            // Zero, repeated, flat (rank 1 and 2) and general, turned.
            [[0.0; 3]; 3],
            rotated([2.0, 2.0, 2.0]),
            rotated([2.0, 2.0, 1.0]),
            rotated([2.0, 1.0, 1.0]),
            rotated([1.0, 0.0, 0.0]),
            rotated([1.0, 1.0, 0.0]),
            rotated([4.0, 1.5, 0.25]),
            // Nearly repeated, where the trigonometric eigenvalues lose digits.
            rotated([1.0, 1.0 + 1e-9, 0.5]),
            rotated([1.0, 1.0 - 1e-12, 1.0 - 2e-12]),
            rotated([1.0 + 1e-15, 1.0, 1.0 - 1e-15]),
            // Scales from a Gaussian 10⁻⁵ thin beside one 1 wide, tiny and huge.
            rotated([1.0, 1e-10, 1e-10]),
            rotated([1e-20, 3e-21, 1e-22]),
            rotated([1e20, 5e19, 1e18]),
            rotated([1e-300, 3e-301, 1e-302]),
            // Negative eigenvalues sort below zero.
            rotated([1.0, -0.5, -2.0]),
            // Nearly scalar, off the diagonal by 1e-80: the rows of A − λI
            // are ~1e-80, their cross products ~1e-160 (subnormal squares).
            [[1.0, 1e-80, 0.0], [1e-80, 1.0, 0.0], [0.0, 0.0, 1.0]],
            [
                [1.0, 1e-79, 3e-80],
                [1e-79, 1.0, -2e-80],
                [3e-80, -2e-80, 1.0],
            ],
        ];
        for solve in [symmetric_eigen as Solver, jacobi] {
            for m in cases {
                assert_decomposes(solve, m, 1e-13);
            }
            let (values, _) = solve(rotated([4.0, 1.5, 0.25]));
            for (got, want) in values.iter().zip([4.0, 1.5, 0.25]) {
                assert!((got - want).abs() < 1e-14, "{values:?}");
            }
            let mut next = uniform(0x2545_f491_4f6c_dd1d);
            for _ in 0..2000 {
                let (a, b, c, d, e, f) = (next(), next(), next(), next(), next(), next());
                assert_decomposes(solve, [[a, b, c], [b, d, e], [c, e, f]], 1e-13);
            }
        }
    }

    #[test]
    fn the_closed_form_answers_reshaped_covariances_and_agrees_with_jacobi() {
        // Covariances like a reshaped Gaussian's: scales over four decades,
        // turned anywhere, through a map near a similarity.
        let mut next = uniform(0x9e37_79b9_7f4a_7c15);
        for _ in 0..5000 {
            let axes = DMat3::from_quat(
                glam::DQuat::from_xyzw(next(), next(), next(), next()).normalize(),
            );
            let scale = DVec3::new(next(), next(), next()).map(|x| (4.5 * x - 5.0).exp());
            let map = DMat3::from_diagonal(DVec3::splat(1.0 + 0.2 * next()))
                + DMat3::from_cols_array(&[(); 9].map(|_| 0.05 * next()));
            let m = map * axes * DMat3::from_diagonal(scale);
            let sigma = (m * m.transpose()).to_cols_array_2d();
            let (values, vectors) = closed_form(sigma).expect("a well-graded covariance");
            let (expected, _) = jacobi(sigma);
            for (got, want) in values.iter().zip(expected) {
                // Each variance to six digits of itself: the log-scales the
                // Gaussians store are f32.
                assert!(
                    (got - want).abs() <= 1e-6 * want,
                    "{values:?} vs {expected:?}"
                );
            }
            assert_decomposition((values, vectors), sigma, 1e-13);
        }
    }

    #[test]
    fn the_closed_form_answers_nearly_repeated_and_nearly_scalar_matrices() {
        for m in [
            rotated([1.0, 1.0 + 1e-9, 0.5]),
            rotated([1.0, 1.0 - 1e-12, 1.0 - 2e-12]),
            rotated([2.0, 2.0, 1.0]),
            [[1.0, 1e-80, 0.0], [1e-80, 1.0, 0.0], [0.0, 0.0, 1.0]],
        ] {
            let found = closed_form(m).expect("the closed form's case");
            assert_decomposition(found, m, 1e-13);
        }
    }

    #[test]
    fn graded_zero_and_non_finite_inputs_go_to_jacobi() {
        // A Gaussian 10⁶ times flatter than wide, in axes near its own (as
        // `deform` forms it): D^½·K·D^½ with K well conditioned, whose
        // smallest variance, 10⁻¹² of the largest, Jacobi keeps to its own
        // digits — seen in the product of the three, det K · Π d.
        let d = [1.0, 1e-4, 1e-12f64];
        let k = |i: usize, j: usize| if i == j { 1.0 } else { 0.1 };
        let graded: [[f64; 3]; 3] =
            std::array::from_fn(|i| std::array::from_fn(|j| k(i, j) * (d[i] * d[j]).sqrt()));
        assert!(closed_form(graded).is_none());
        let (values, _) = symmetric_eigen(graded);
        let det_k = 1.0 + 2.0 * 0.001 - 3.0 * 0.01;
        let product = values.iter().product::<f64>();
        let expected = det_k * d.iter().product::<f64>();
        assert!((product / expected - 1.0).abs() < 1e-9, "{values:?}");
        assert!(closed_form([[0.0; 3]; 3]).is_none());
        assert!(closed_form([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]]).is_none());
        let mut bad = rotated([1.0, 0.5, 0.25]);
        bad[1][2] = f64::NAN;
        assert!(closed_form(bad).is_none());
        let mut infinite = rotated([1.0, 0.5, 0.25]);
        infinite[0][0] = f64::INFINITY;
        assert!(closed_form(infinite).is_none());
        let subnormal = [[1e-310, 0.0, 0.0], [0.0, 5e-311, 0.0], [0.0, 0.0, 0.0]];
        assert!(closed_form(subnormal).is_none());
        let (values, _) = symmetric_eigen(subnormal);
        assert_eq!(values, [1e-310, 5e-311, 0.0]);
        let (values, _) = symmetric_eigen(bad);
        assert!(
            values.iter().any(|v| v.is_nan()),
            "NaN in, NaN out: {values:?}"
        );
    }
}
