//! Real spherical-harmonics colour evaluation, degrees 0-3, in the 3D Gaussian
//! Splatting convention: rgb = max(0, 0.5 + Σ basis(d)·coef) where d is the unit
//! direction from the camera to the Gaussian. The renderers, the trainer and
//! the composition's colour statistics ([`Views::seen_rgb`]) share it.

use glam::Vec3;

use super::gaussians::dc_to_rgb;

/// Degree 0 constant.
pub const C0: f64 = 0.282_094_791_773_878_14;
/// Degree 1 constant.
pub const C1: f64 = 0.488_602_511_902_919_9;
/// Degree 2 constants.
pub const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Degree 3 constants.
pub const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Defines an SH basis function for one number type (f64 for the reference,
/// f32 for the CPU renderer, the trainer's dual numbers), or for a type
/// parameter (`name<L: Bound>, L, …`): the same polynomials, written once.
/// `$constant` turns an f64 constant into the type. The generic form is for
/// SIMD lanes and is always inlined, with no closures passed to array
/// adaptors inside: a caller compiled for wider lanes (AVX2) then compiles
/// all of it so, rather than calling out to code compiled without them.
#[macro_export]
macro_rules! sh_basis {
    ($(#[doc = $doc:expr])* $name:ident, $t:ty, $constant:expr) => {
        $crate::sh_basis!(@define [inline] $(#[doc = $doc])* $name<>, $t, $constant);
    };
    ($(#[doc = $doc:expr])* $name:ident<$($g:ident: $bound:path),*>, $t:ty, $constant:expr) => {
        $crate::sh_basis!(
            @define [inline(always)] $(#[doc = $doc])* $name<$($g: $bound),*>, $t, $constant
        );
    };
    (@define [$inline:meta] $(#[doc = $doc:expr])* $name:ident<$($g:ident: $bound:path),*>, $t:ty, $constant:expr) => {
        $(#[doc = $doc])*
        #[allow(clippy::unnecessary_cast, clippy::redundant_closure_call)]
        #[$inline]
        pub fn $name<$($g: $bound),*>(degree: u8, d: [$t; 3]) -> [$t; 16] {
            let k = $constant;
            let [x, y, z] = d;
            let (c2, c3) = ($crate::avatar::sh::C2, $crate::avatar::sh::C3);
            let c1 = k($crate::avatar::sh::C1);
            // −(c1·y) as (−c1)·y, the same bits, so that types without a
            // negation (SIMD lanes) can use the macro too.
            let minus_c1 = k(-$crate::avatar::sh::C1);
            let mut b = [k(0.0); 16];
            b[0] = k($crate::avatar::sh::C0);
            if degree >= 1 {
                b[1] = minus_c1 * y;
                b[2] = c1 * z;
                b[3] = minus_c1 * x;
            }
            if degree >= 2 {
                let (xx, yy, zz) = (x * x, y * y, z * z);
                let (two, three, four) = (k(2.0), k(3.0), k(4.0));
                b[4] = k(c2[0]) * x * y;
                b[5] = k(c2[1]) * y * z;
                b[6] = k(c2[2]) * (two * zz - xx - yy);
                b[7] = k(c2[3]) * x * z;
                b[8] = k(c2[4]) * (xx - yy);
                if degree >= 3 {
                    b[9] = k(c3[0]) * y * (three * xx - yy);
                    b[10] = k(c3[1]) * x * y * z;
                    b[11] = k(c3[2]) * y * (four * zz - xx - yy);
                    b[12] = k(c3[3]) * z * (two * zz - three * xx - three * yy);
                    b[13] = k(c3[4]) * x * (four * zz - xx - yy);
                    b[14] = k(c3[5]) * z * (xx - yy);
                    b[15] = k(c3[6]) * x * (xx - three * yy);
                }
            }
            b
        }
    };
}

sh_basis!(
    /// The SH basis functions for direction `d` (unit), up to `degree`.
    basis,
    f64,
    |c: f64| c
);
sh_basis!(
    /// [`basis`] in f32.
    basis_f32,
    f32,
    |c: f64| c as f32
);

/// Colour of a Gaussian seen along `d`, from its coefficient-major SH (`[coef][rgb]`).
/// `use_degree` may be lower than the stored degree to truncate the expansion.
pub fn eval_rgb(sh: &[f32], use_degree: u8, d: [f64; 3]) -> [f64; 3] {
    let b = basis(use_degree, d);
    let coefficients = (sh.len() / 3).min((use_degree as usize + 1).pow(2));
    let mut rgb = [0.5; 3];
    for (k, bk) in b.iter().enumerate().take(coefficients) {
        for (ch, out) in rgb.iter_mut().enumerate() {
            *out += bk * sh[k * 3 + ch] as f64;
        }
    }
    rgb.map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 })
}

/// [`eval_rgb`] in f32 (the CPU renderer's per-frame colour; its error
/// against the f64 version is measured by `visage bench render` and bounded
/// by a test).
pub fn eval_rgb_f32(sh: &[f32], use_degree: u8, d: [f32; 3]) -> [f32; 3] {
    rgb_from_basis_f32(sh, &basis_f32(use_degree, d), use_degree)
}

/// [`eval_rgb_f32`] from the basis values `b` of the view direction, for
/// callers that evaluate the basis of many Gaussians at once.
#[inline]
pub fn rgb_from_basis_f32(sh: &[f32], b: &[f32; 16], use_degree: u8) -> [f32; 3] {
    let coefficients = (use_degree as usize + 1).pow(2);
    match sh.first_chunk::<48>() {
        Some(sh) if coefficients == 16 => rgb_from_basis_degree3(sh, b),
        _ => rgb_from_basis(sh, b, coefficients),
    }
}

/// [`rgb_from_basis`] for all sixteen coefficients of degree 3, the colour
/// of every big trained scene. The sum runs as four groups of four
/// coefficients (twelve floats, three four-wide registers) added side by
/// side, so each register's chain is four adds long instead of sixteen and
/// the loop has a fixed length the compiler unrolls: the projection of a
/// million Gaussians spent 45 % of its colour time in the general loop.
#[inline]
fn rgb_from_basis_degree3(sh: &[f32; 48], b: &[f32; 16]) -> [f32; 3] {
    let mut partial = [0.0f32; 12];
    for (group, coefficients) in sh.chunks_exact(12).enumerate() {
        for (j, (sum, coef)) in partial.iter_mut().zip(coefficients).enumerate() {
            *sum += b[4 * group + j / 3] * coef;
        }
    }
    let channel =
        |ch: usize| 0.5 + ((partial[ch] + partial[3 + ch]) + (partial[6 + ch] + partial[9 + ch]));
    [channel(0), channel(1), channel(2)].map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 })
}

/// The clamped colour of coefficient-major SH `sh` under basis values `b`,
/// through the first `coefficients` coefficients.
fn rgb_from_basis(sh: &[f32], b: &[f32; 16], coefficients: usize) -> [f32; 3] {
    let mut rgb = [0.5f32; 3];
    for (coef, bk) in sh.chunks_exact(3).zip(b).take(coefficients) {
        rgb[0] += bk * coef[0];
        rgb[1] += bk * coef[1];
        rgb[2] += bk * coef[2];
    }
    rgb.map(|c| if c.is_finite() { c.max(0.0) } else { 0.0 })
}

/// A set of view directions with their SH basis values evaluated once, so
/// that the colour many Gaussians show them costs a dot product each.
pub struct Views {
    bases: Vec<[f32; 16]>,
}

impl Views {
    /// The views along `directions` (unit, camera to Gaussian).
    pub fn new(directions: &[Vec3]) -> Views {
        Views {
            bases: directions
                .iter()
                .map(|d| basis_f32(3, d.to_array()))
                .collect(),
        }
    }

    /// The display colour a Gaussian of coefficient-major SH `sh` shows on
    /// average to these views, every band it has counted and each view
    /// clamped at zero as the renderers clamp it; the DC colour when there
    /// is no view. A source trained from a frontal arc of cameras sees every
    /// view with d_z near −1, so its DC term and the low orders of the
    /// higher bands trade against one another (on a dark skin by as much as
    /// a tenth of the colour): only what those cameras saw is determined,
    /// and that is what this gives.
    pub fn seen_rgb(&self, sh: &[f32]) -> Vec3 {
        if self.bases.is_empty() {
            return Vec3::new(dc_to_rgb(sh[0]), dc_to_rgb(sh[1]), dc_to_rgb(sh[2]));
        }
        let coefficients = (sh.len() / 3).min(16);
        let sum: Vec3 = self
            .bases
            .iter()
            .map(|b| Vec3::from(rgb_from_basis(sh, b, coefficients)))
            .sum();
        sum / self.bases.len() as f32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// f32 evaluation stays within a few f32 steps of the f64 one for SH
    /// coefficients of trained-scene size, all degrees, many directions.
    #[test]
    fn f32_evaluation_matches_f64() {
        let mut worst = 0.0f64;
        for k in 0..2000u32 {
            let t = k as f64 * 0.618_033_988_75;
            let z = 1.0 - 2.0 * ((k as f64 + 0.5) / 2000.0);
            let r = (1.0 - z * z).sqrt();
            let d = [
                r * (t * std::f64::consts::TAU).cos(),
                r * (t * std::f64::consts::TAU).sin(),
                z,
            ];
            let sh: Vec<f32> = (0..48)
                .map(|j| {
                    (((j * 7 + k as usize * 13) % 97) as f32 / 97.0 - 0.5)
                        * if j < 3 { 4.0 } else { 0.6 }
                })
                .collect();
            for degree in 0..=3 {
                let a = eval_rgb(&sh, degree, d);
                let b = eval_rgb_f32(&sh, degree, d.map(|c| c as f32));
                for ch in 0..3 {
                    worst = worst.max((a[ch] - b[ch] as f64).abs());
                }
            }
        }
        assert!(worst < 1e-5, "worst difference {worst:e}");
    }

    #[test]
    fn dc_only_is_view_independent() {
        let sh = [1.0, -3.0, 0.0];
        let a = eval_rgb(&sh, 0, [0.0, 0.0, 1.0]);
        let b = eval_rgb(&sh, 0, [1.0, 0.0, 0.0]);
        assert_eq!(a, b);
        assert!((a[0] - (0.5 + C0)).abs() < 1e-12);
        assert_eq!(a[1], 0.0, "clamped at zero");
    }

    #[test]
    fn degree_one_follows_direction() {
        let mut sh = [0.0f32; 12];
        sh[6] = 1.0; // coefficient 2 (z), red channel
        let toward = eval_rgb(&sh, 1, [0.0, 0.0, 1.0]);
        let away = eval_rgb(&sh, 1, [0.0, 0.0, -1.0]);
        assert!((toward[0] - 0.5 - C1).abs() < 1e-7);
        assert!((away[0] - 0.5 + C1).abs() < 1e-7);
    }

    /// The seen colour is the mean over the cameras of what each renders
    /// (every band, each view clamped at zero as the renderers clamp it), and
    /// the DC colour where there is no camera or no higher band.
    #[test]
    fn seen_colour_is_the_mean_of_what_each_camera_sees() {
        let mut sh: Vec<f32> = (0..48)
            .map(|k| ((k * 37 % 23) as f32 - 11.0) * 0.05)
            .collect();
        // A dark red that a first band darkens below zero towards the front.
        sh[0] = ((0.05 - 0.5) / C0) as f32;
        sh[6] = 0.5;
        let directions: Vec<Vec3> = (0..7)
            .map(|k| {
                let (yaw, pitch) = (k as f32 * 0.4 - 1.2, 0.1 * k as f32 - 0.3);
                -Vec3::new(
                    yaw.sin() * pitch.cos(),
                    pitch.sin(),
                    yaw.cos() * pitch.cos(),
                )
            })
            .collect();
        let mut want = [0.0f64; 3];
        for d in &directions {
            let rgb = eval_rgb(&sh, 3, d.as_dvec3().to_array());
            for ch in 0..3 {
                want[ch] += rgb[ch] / directions.len() as f64;
            }
        }
        // One view at least is clamped, so the clamp is exercised.
        let red = |d: &Vec3| {
            let b = basis(3, d.as_dvec3().to_array());
            0.5 + (0..16).map(|k| b[k] * sh[3 * k] as f64).sum::<f64>()
        };
        assert!(directions.iter().any(|d| red(d) < 0.0));
        let got = Views::new(&directions).seen_rgb(&sh);
        for ch in 0..3 {
            assert!(
                (got[ch] as f64 - want[ch]).abs() < 1e-5,
                "{got} against {want:?}"
            );
        }
        let dc = Vec3::new(0.5, 0.5, 0.5) + C0 as f32 * Vec3::new(sh[0], sh[1], sh[2]);
        assert!((Views::new(&[]).seen_rgb(&sh) - dc).abs().max_element() < 1e-6);
        assert!(
            (Views::new(&directions).seen_rgb(&sh[..3]) - dc.max(Vec3::ZERO))
                .abs()
                .max_element()
                < 1e-6
        );
    }

    #[test]
    fn basis_is_orthonormal_on_the_sphere() {
        // Monte-Carlo-free check: a Fibonacci sphere quadrature of b_i·b_j ≈ δ_ij/(4π)·4π.
        let n = 20000;
        let mut gram = [[0.0f64; 16]; 16];
        for k in 0..n {
            let z = 1.0 - 2.0 * (k as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let phi = k as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
            let b = basis(3, [r * phi.cos(), r * phi.sin(), z]);
            for i in 0..16 {
                for j in 0..16 {
                    gram[i][j] += b[i] * b[j] * 4.0 * std::f64::consts::PI / n as f64;
                }
            }
        }
        for (i, row) in gram.iter().enumerate() {
            for (j, g) in row.iter().enumerate() {
                let want = if i == j { 1.0 } else { 0.0 };
                assert!((g - want).abs() < 2e-3, "({i},{j}) = {g}");
            }
        }
    }
}
