//! The colour of a projected batch: the SH basis of its eight view
//! directions at once in lanes (the polynomials of `avatar::sh`, from the
//! same macro, so every lane gets the bits the scalar basis gives), then
//! each visible Gaussian's sum over its own coefficients.

use glam::Vec3;

use super::lanes::Lanes;
use super::project::LANES;

crate::sh_basis!(
    /// The SH basis of eight unit directions at once, up to `degree`.
    basis_lanes<L: Lanes>,
    L,
    |c: f64| L::splat(c as f32)
);

/// The SH basis values of each lane's direction `from_eye` (any length;
/// normalised as `Vec3::normalize_or_zero` does, bit for bit), up to `degree`.
///
/// Written as plain loops: the array adaptors (`map`, `from_fn`) were not
/// always inlined here, and then cost more than the basis itself.
#[inline(always)]
pub(super) fn batch_bases<L: Lanes>(from_eye: &[Vec3; LANES], degree: u8) -> [[f32; 16]; LANES] {
    let mut axes = [[0.0f32; LANES]; 3];
    for (lane, v) in from_eye.iter().enumerate() {
        axes[0][lane] = v.x;
        axes[1][lane] = v.y;
        axes[2][lane] = v.z;
    }
    let [x, y, z] = [L::new(axes[0]), L::new(axes[1]), L::new(axes[2])];
    let recip = L::splat(1.0) / (x * x + y * y + z * z).sqrt();
    let usable = recip.is_finite() & recip.simd_gt(L::splat(0.0));
    let zero = L::splat(0.0);
    let unit = [
        usable.bitselect(x * recip, zero),
        usable.bitselect(y * recip, zero),
        usable.bitselect(z * recip, zero),
    ];
    let basis = basis_lanes(degree, unit);
    let mut bases = [[0.0f32; 16]; LANES];
    for (k, values) in basis.iter().enumerate() {
        for (lane, value) in values.to_array().iter().enumerate() {
            bases[lane][k] = *value;
        }
    }
    bases
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::sh::basis_f32;

    /// Lanes give the scalar basis of the normalised direction bit for bit,
    /// zero and non-finite directions included.
    #[test]
    fn lanes_match_the_scalar_basis_bit_for_bit() {
        let mut from_eye = [Vec3::ZERO; LANES];
        for round in 0..200 {
            for (lane, v) in from_eye.iter_mut().enumerate() {
                let t = (round * LANES + lane) as f32;
                *v = Vec3::new(
                    (t * 0.37).sin() * 3.0,
                    (t * 0.11).cos() * 1e3,
                    (t * 0.05).sin() - 0.4,
                );
            }
            from_eye[3] = Vec3::ZERO;
            from_eye[5] = Vec3::new(f32::NAN, 1.0, 0.0);
            for degree in 0..=3 {
                let lanes = batch_bases::<wide::f32x8>(&from_eye, degree);
                for (lane, v) in from_eye.iter().enumerate() {
                    let scalar = basis_f32(degree, v.normalize_or_zero().to_array());
                    assert_eq!(
                        lanes[lane].map(f32::to_bits),
                        scalar.map(f32::to_bits),
                        "lane {lane}"
                    );
                }
            }
        }
    }
}
