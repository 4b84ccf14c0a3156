//! Maths for the CPU renderer's inner loops, scalar and eight lanes wide,
//! without calls into libm: x86-64's baseline has no rounding instruction, so
//! `f32::floor` and friends (and `wide`'s lane-wise ones) are function calls
//! there, and `f32::exp` is far more accurate than a blend of 8-bit colour
//! needs.

use super::lanes::Lanes;

/// ⌊x⌋ for |x| < 2³¹ (beyond, the result saturates there, which the
/// callers clamp to the image anyway; NaN gives 0).
#[inline]
pub fn floor(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// ⌈x⌉, on the terms of [`floor`].
#[inline]
pub fn ceil(x: f32) -> f32 {
    -floor(-x)
}

/// ln 2 in two parts (Cody and Waite): n·LN2_HI is exact for the n the
/// exponentials meet, so the reduced argument keeps its precision.
const LN2_HI: f32 = 0.693_145_75;
/// The rest of ln 2 after [`LN2_HI`].
const LN2_LO: f32 = 1.428_606_8e-6;

/// e^x for x ≤ 0, within 2·10⁻⁷ relative of the exact value: the argument is
/// split as x = n·ln 2 + r with |r| ≤ ln 2 / 2 (Cody and Waite's two-part
/// ln 2 keeps r exact), e^r is its degree-6 Taylor polynomial and 2ⁿ is put
/// into the exponent bits. Arguments below −87 give 0 (as e^x does in f32).
#[inline]
pub fn exp_nonpositive(x: f32) -> f32 {
    if x < -87.0 {
        return 0.0;
    }
    let n = floor(x * std::f32::consts::LOG2_E + 0.5);
    let r = x - n * LN2_HI - n * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (0.5
                + r * (1.0 / 6.0 + r * (1.0 / 24.0 + r * (1.0 / 120.0 + r * (1.0 / 720.0))))));
    p * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

/// [`exp_nonpositive`] in each lane, bit for bit (the same operations in
/// the same order, so a pixel blended eight at a time gets exactly the value
/// it would get alone).
#[inline(always)]
pub fn exp_nonpositive_lanes<L: Lanes>(x: L) -> L {
    let c = L::splat;
    let n = (x * c(std::f32::consts::LOG2_E) + c(0.5)).floor();
    let r = x - n * c(LN2_HI) - n * c(LN2_LO);
    let p = c(1.0)
        + r * (c(1.0)
            + r * (c(0.5)
                + r * (c(1.0 / 6.0)
                    + r * (c(1.0 / 24.0) + r * (c(1.0 / 120.0) + r * c(1.0 / 720.0))))));
    x.simd_lt(c(-87.0)).bitselect(c(0.0), p * n.exp2_integer())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// floor and ceil agree with the library's on whole numbers, halves,
    /// negatives, values a step either side of an integer, and large ones.
    #[test]
    fn floor_and_ceil_match_the_library() {
        for k in -4000..4000 {
            for x in [
                k as f32 * 0.25,
                k as f32 * 1.37e3,
                f32::from_bits((k as f32).to_bits() + 1),
                f32::from_bits((k as f32).to_bits().saturating_sub(1)),
            ] {
                assert_eq!(floor(x), x.floor(), "floor {x}");
                assert_eq!(ceil(x), x.ceil(), "ceil {x}");
            }
        }
        assert_eq!(floor(f32::NAN), 0.0);
        assert_eq!(floor(-1e12), i32::MIN as f32);
    }

    /// The polynomial exponential against f64's over the range the blend
    /// uses (down to ln(1/255), and well past it) and at the ends.
    #[test]
    fn the_fast_exponential_is_within_two_f32_steps() {
        let mut worst = 0.0f64;
        for k in 0..=200_000 {
            let x = -12.0 * k as f32 / 200_000.0;
            let exact = (x as f64).exp();
            let got = exp_nonpositive(x) as f64;
            worst = worst.max((got - exact).abs() / exact);
        }
        assert!(worst < 2.5e-7, "worst relative error {worst:e}");
        assert_eq!(exp_nonpositive(0.0), 1.0);
        assert_eq!(exp_nonpositive(-100.0), 0.0);
        assert!(exp_nonpositive(-80.0) > 0.0);
        for k in 0..25_000 {
            let lanes: [f32; 8] = std::array::from_fn(|i| -((k * 8 + i) as f32) * 5e-4);
            let got = exp_nonpositive_lanes(wide::f32x8::new(lanes)).to_array();
            assert_eq!(
                got.map(f32::to_bits),
                lanes.map(exp_nonpositive).map(f32::to_bits)
            );
        }
        let ends = [
            0.0,
            -86.9,
            -87.0,
            -87.1,
            -100.0,
            -1e30,
            f32::NEG_INFINITY,
            -0.0,
        ];
        let got = exp_nonpositive_lanes(wide::f32x8::new(ends)).to_array();
        assert_eq!(
            got.map(f32::to_bits),
            ends.map(exp_nonpositive).map(f32::to_bits)
        );
    }
}
