//! Eight f32 lanes, two ways: `wide`'s f32x8, which the x86-64 baseline
//! (SSE2) runs as two four-wide halves, and [`Avx`], one 256-bit AVX register,
//! for processors that have AVX2 (checked at run time: one binary serves
//! both). `wide` picks its SSE2 or AVX code when it is compiled, so a
//! function cloned for AVX2 still runs its SSE2 halves; the projection and
//! the blend's rows are therefore written once against [`Lanes`] and compiled
//! for each type. Every operation is the same IEEE operation on either (the
//! same comparisons, the same NaN rules for min and max, truncation for
//! floor), so both give the same bits (a test compares them).

use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};

use wide::{f32x8, i32x8};

/// Eight f32 lanes; comparisons give masks (all bits set where true) of
/// the same type.
pub(super) trait Lanes:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + BitAnd<Output = Self>
{
    /// Every lane `v`.
    fn splat(v: f32) -> Self;
    /// The lanes of `v`.
    fn new(v: [f32; 8]) -> Self;
    /// The lanes as an array.
    fn to_array(self) -> [f32; 8];
    /// |x| (the sign bit cleared).
    fn abs(self) -> Self;
    /// The smaller of each pair; `self` where `other` is NaN, `other` where
    /// `self` is.
    fn min(self, other: Self) -> Self;
    /// The larger of each pair, NaN as in [`Lanes::min`].
    fn max(self, other: Self) -> Self;
    /// Correctly rounded square root.
    fn sqrt(self) -> Self;
    /// Mask of the lanes that are neither infinite nor NaN.
    fn is_finite(self) -> Self;
    /// Mask of `self ≥ other` (false with NaN).
    fn simd_ge(self, other: Self) -> Self;
    /// Mask of `self ≤ other` (false with NaN).
    fn simd_le(self, other: Self) -> Self;
    /// Mask of `self > other` (false with NaN).
    fn simd_gt(self, other: Self) -> Self;
    /// Mask of `self < other` (false with NaN).
    fn simd_lt(self, other: Self) -> Self;
    /// `if_one`'s bits where the mask `self` has ones, `if_zero`'s elsewhere.
    fn bitselect(self, if_one: Self, if_zero: Self) -> Self;
    /// The lanes' sign bits (lane i in bit i).
    fn to_bitmask(self) -> u32;
    /// ⌊x⌋ for |x| < 2³¹ (callers clamp first), by truncation and one
    /// compare, as `fastmath::floor` (`wide`'s own floor calls the library
    /// per lane without SSE4.1).
    fn floor(self) -> Self;
    /// 2ⁿ in each lane for whole n in −126..=127, from its exponent bits.
    fn exp2_integer(self) -> Self;
    /// A mask with lane i set where bit i of `bits` is.
    fn lane_mask(bits: u32) -> Self;

    /// ⌈x⌉ for |x| < 2³¹, as −⌊−x⌋.
    #[inline(always)]
    fn ceil(self) -> Self {
        -(-self).floor()
    }
}

impl Lanes for f32x8 {
    #[inline(always)]
    fn splat(v: f32) -> Self {
        f32x8::splat(v)
    }
    #[inline(always)]
    fn new(v: [f32; 8]) -> Self {
        f32x8::new(v)
    }
    #[inline(always)]
    fn to_array(self) -> [f32; 8] {
        f32x8::to_array(self)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f32x8::abs(self)
    }
    #[inline(always)]
    fn min(self, other: Self) -> Self {
        f32x8::min(self, other)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        f32x8::max(self, other)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f32x8::sqrt(self)
    }
    #[inline(always)]
    fn is_finite(self) -> Self {
        f32x8::is_finite(self)
    }
    #[inline(always)]
    fn simd_ge(self, other: Self) -> Self {
        f32x8::simd_ge(self, other)
    }
    #[inline(always)]
    fn simd_le(self, other: Self) -> Self {
        f32x8::simd_le(self, other)
    }
    #[inline(always)]
    fn simd_gt(self, other: Self) -> Self {
        f32x8::simd_gt(self, other)
    }
    #[inline(always)]
    fn simd_lt(self, other: Self) -> Self {
        f32x8::simd_lt(self, other)
    }
    #[inline(always)]
    fn bitselect(self, if_one: Self, if_zero: Self) -> Self {
        f32x8::bitselect(self, if_one, if_zero)
    }
    #[inline(always)]
    fn to_bitmask(self) -> u32 {
        f32x8::to_bitmask(self)
    }
    #[inline(always)]
    fn floor(self) -> Self {
        let t = f32x8::from_i32x8(self.fast_trunc_int());
        t - t.simd_gt(self).bitselect(f32x8::ONE, f32x8::ZERO)
    }
    #[inline(always)]
    fn exp2_integer(self) -> Self {
        bytemuck::cast((self.fast_trunc_int() + i32x8::splat(127)) << 23)
    }
    #[inline(always)]
    fn lane_mask(bits: u32) -> Self {
        let lane_bits = i32x8::new([1, 2, 4, 8, 16, 32, 64, 128]);
        bytemuck::cast((i32x8::splat(bits as i32) & lane_bits).simd_eq(lane_bits))
    }
}

#[cfg(target_arch = "x86_64")]
pub(super) use avx::{avx2_enabled, Avx};

#[cfg(target_arch = "x86_64")]
mod avx {
    use std::arch::x86_64::*;
    use std::ops::{Add, BitAnd, Div, Mul, Neg, Sub};
    use std::sync::OnceLock;

    use super::Lanes;

    /// Whether this processor has AVX2 and it is not turned off with
    /// `VISAGE_SIMD=baseline` (for comparing the two on one machine).
    pub(in crate::render::cpu) fn avx2_enabled() -> bool {
        static ENABLED: OnceLock<bool> = OnceLock::new();
        *ENABLED.get_or_init(|| {
            let baseline = std::env::var("VISAGE_SIMD").is_ok_and(|v| v == "baseline");
            !baseline && std::is_x86_feature_detected!("avx2")
        })
    }

    /// Eight lanes in one AVX register.
    ///
    /// Only code that runs after [`avx2_enabled`] returned true may make or
    /// use one: its operations are AVX instructions, which other processors
    /// do not have. In practice that code is a function compiled with
    /// `#[target_feature(enable = "avx2")]`, into which these operations are
    /// inlined.
    #[derive(Clone, Copy, Debug)]
    pub(in crate::render::cpu) struct Avx(__m256);

    /// An AVX operation on lanes.
    macro_rules! avx {
        ($e:expr) => {
            // SAFETY: `Avx` exists only where the processor has AVX2
            // (see the type's documentation).
            Avx(unsafe { $e })
        };
    }

    /// An operator of `Avx` lanes as one AVX instruction.
    macro_rules! operator {
        ($trait:ident, $method:ident, $instruction:ident) => {
            impl $trait for Avx {
                type Output = Self;
                #[inline(always)]
                fn $method(self, o: Self) -> Self {
                    avx!($instruction(self.0, o.0))
                }
            }
        };
    }

    operator!(Add, add, _mm256_add_ps);
    operator!(Sub, sub, _mm256_sub_ps);
    operator!(Mul, mul, _mm256_mul_ps);
    operator!(Div, div, _mm256_div_ps);
    operator!(BitAnd, bitand, _mm256_and_ps);

    impl Neg for Avx {
        type Output = Self;
        #[inline(always)]
        fn neg(self) -> Self {
            avx!(_mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)))
        }
    }

    impl Avx {
        /// Mask of the lanes that are NaN.
        #[inline(always)]
        fn is_nan(self) -> Self {
            avx!(_mm256_cmp_ps::<_CMP_UNORD_Q>(self.0, self.0))
        }

        /// `if_true` where the mask `self` is set (by its sign bits), else
        /// `if_false`.
        #[inline(always)]
        fn select(self, if_true: Self, if_false: Self) -> Self {
            avx!(_mm256_blendv_ps(if_false.0, if_true.0, self.0))
        }
    }

    impl Lanes for Avx {
        #[inline(always)]
        fn splat(v: f32) -> Self {
            avx!(_mm256_set1_ps(v))
        }
        #[inline(always)]
        fn new(v: [f32; 8]) -> Self {
            avx!(_mm256_loadu_ps(v.as_ptr()))
        }
        #[inline(always)]
        fn to_array(self) -> [f32; 8] {
            let mut out = [0.0f32; 8];
            // SAFETY: as for every operation (`out` holds eight floats).
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
        #[inline(always)]
        fn abs(self) -> Self {
            avx!(_mm256_and_ps(
                self.0,
                _mm256_castsi256_ps(_mm256_set1_epi32(i32::MAX))
            ))
        }
        #[inline(always)]
        fn min(self, other: Self) -> Self {
            other
                .is_nan()
                .select(self, avx!(_mm256_min_ps(self.0, other.0)))
        }
        #[inline(always)]
        fn max(self, other: Self) -> Self {
            other
                .is_nan()
                .select(self, avx!(_mm256_max_ps(self.0, other.0)))
        }
        #[inline(always)]
        fn sqrt(self) -> Self {
            avx!(_mm256_sqrt_ps(self.0))
        }
        #[inline(always)]
        fn is_finite(self) -> Self {
            // |x| < ∞ is false exactly for ±∞ and NaN.
            self.abs().simd_lt(Self::splat(f32::INFINITY))
        }
        #[inline(always)]
        fn simd_ge(self, other: Self) -> Self {
            avx!(_mm256_cmp_ps::<_CMP_GE_OQ>(self.0, other.0))
        }
        #[inline(always)]
        fn simd_le(self, other: Self) -> Self {
            avx!(_mm256_cmp_ps::<_CMP_LE_OQ>(self.0, other.0))
        }
        #[inline(always)]
        fn simd_gt(self, other: Self) -> Self {
            avx!(_mm256_cmp_ps::<_CMP_GT_OQ>(self.0, other.0))
        }
        #[inline(always)]
        fn simd_lt(self, other: Self) -> Self {
            avx!(_mm256_cmp_ps::<_CMP_LT_OQ>(self.0, other.0))
        }
        #[inline(always)]
        fn bitselect(self, if_one: Self, if_zero: Self) -> Self {
            avx!(_mm256_or_ps(
                _mm256_and_ps(if_one.0, self.0),
                _mm256_andnot_ps(self.0, if_zero.0)
            ))
        }
        #[inline(always)]
        fn to_bitmask(self) -> u32 {
            // SAFETY: as for every operation.
            unsafe { _mm256_movemask_ps(self.0) as u32 }
        }
        #[inline(always)]
        fn floor(self) -> Self {
            let truncated = avx!(_mm256_cvtepi32_ps(_mm256_cvttps_epi32(self.0)));
            truncated
                - truncated
                    .simd_gt(self)
                    .bitselect(Self::splat(1.0), Self::splat(0.0))
        }
        #[inline(always)]
        fn exp2_integer(self) -> Self {
            avx!(_mm256_castsi256_ps(_mm256_slli_epi32::<23>(
                _mm256_add_epi32(_mm256_cvttps_epi32(self.0), _mm256_set1_epi32(127))
            )))
        }
        #[inline(always)]
        fn lane_mask(bits: u32) -> Self {
            avx!({
                let lane_bits = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
                let set = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane_bits);
                _mm256_castsi256_ps(_mm256_cmpeq_epi32(set, lane_bits))
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;

    /// Lanes of every kind an operation can meet: ordinary numbers of all
    /// sizes, ±0, ±∞, NaN, subnormals, and values at the edges of
    /// truncation to i32.
    pub(in crate::render::cpu) fn hard_lanes(rng: &mut impl Rng) -> [f32; 8] {
        const SPECIAL: [f32; 12] = [
            0.0,
            -0.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            1e-40,
            -1e-40,
            2_147_483_520.0,
            -2_147_483_648.0,
            0.5,
            -0.5,
            1.0,
        ];
        std::array::from_fn(|_| match rng.random_range(0..4) {
            0 => SPECIAL[rng.random_range(0..SPECIAL.len())],
            1 => rng.random_range(-4.0f32..4.0),
            2 => rng.random_range(-1e6f32..1e6),
            _ => f32::from_bits(rng.random()),
        })
    }

    /// Every operation of `L` on `a` and `b`, as bit patterns.
    fn all_operations<L: Lanes>(a: [f32; 8], b: [f32; 8]) -> Vec<[u32; 8]> {
        let (x, y) = (L::new(a), L::new(b));
        let bits = |v: L| v.to_array().map(f32::to_bits);
        // Floor and ceil hold for |x| < 2³¹ only (callers clamp first).
        let small = x.abs().simd_lt(L::splat(2e9)).bitselect(x, L::splat(0.0));
        vec![
            bits(x + y),
            bits(x - y),
            bits(x * y),
            bits(x / y),
            bits(-x),
            bits(x & y),
            bits(x.abs()),
            bits(x.min(y)),
            bits(x.max(y)),
            bits(x.sqrt()),
            bits(x.is_finite()),
            bits(x.simd_ge(y)),
            bits(x.simd_le(y)),
            bits(x.simd_gt(y)),
            bits(x.simd_lt(y)),
            bits(x.simd_gt(y).bitselect(x, y)),
            bits(small.floor()),
            bits(small.ceil()),
            [x.to_bitmask(), x.simd_lt(y).to_bitmask(), 0, 0, 0, 0, 0, 0],
            bits(
                small
                    .min(L::splat(127.0))
                    .max(L::splat(-126.0))
                    .exp2_integer(),
            ),
            bits(L::lane_mask(a[0].to_bits() & 0xff)),
        ]
    }

    /// [`all_operations`] on AVX lanes.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2")]
    unsafe fn all_operations_avx(a: [f32; 8], b: [f32; 8]) -> Vec<[u32; 8]> {
        all_operations::<Avx>(a, b)
    }

    /// Floor and ceil in lanes are the library's, on both kinds of lanes.
    #[test]
    fn floor_and_ceil_lanes_match_the_library() {
        for k in -500..500 {
            let lanes: [f32; 8] = std::array::from_fn(|i| (k * 8 + i as i32) as f32 * 0.37 - 0.5);
            let x = f32x8::new(lanes);
            assert_eq!(Lanes::floor(x).to_array(), lanes.map(f32::floor));
            assert_eq!(Lanes::ceil(x).to_array(), lanes.map(f32::ceil));
            let avx = all_operations_or_none(lanes, lanes);
            if let Some(avx) = avx {
                assert_eq!(avx[16], lanes.map(|v| v.floor().to_bits()));
                assert_eq!(avx[17], lanes.map(|v| v.ceil().to_bits()));
            }
        }
    }

    /// The AVX lanes' results where the processor has AVX2.
    fn all_operations_or_none(a: [f32; 8], b: [f32; 8]) -> Option<Vec<[u32; 8]>> {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2 (just checked).
            return Some(unsafe { all_operations_avx(a, b) });
        }
        let _ = (a, b);
        None
    }

    /// The operations of [`all_operations`] that compute a new number (+, −,
    /// ×, ÷ and the square root): which of two NaN operands' payloads such a
    /// result carries is left open by IEEE 754, and the compiler may swap
    /// the operands of + and × (it did in a debug build), so there only
    /// NaN-ness has to agree. Bit operations, min, max and selects keep
    /// payloads exactly and are compared bit for bit.
    const ARITHMETIC: [usize; 5] = [0, 1, 2, 3, 9];

    /// `bits` with every NaN pattern read as one quiet NaN.
    fn any_nan_alike(bits: u32) -> u32 {
        if f32::from_bits(bits).is_nan() {
            f32::NAN.to_bits()
        } else {
            bits
        }
    }

    /// One AVX register gives the bits of `wide`'s two SSE2 halves in every
    /// operation, on numbers of every kind (the projection's sameness on
    /// both rests on this). On a processor without AVX2 there is no second
    /// kind of lanes to compare, and the test says so.
    #[test]
    fn avx_lanes_give_the_bits_of_sse2_lanes() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        if all_operations_or_none([0.0; 8], [0.0; 8]).is_none() {
            eprintln!("no AVX2 on this processor: only the SSE2 lanes exist here");
            return;
        }
        for round in 0..20_000 {
            let (a, b) = (hard_lanes(&mut rng), hard_lanes(&mut rng));
            let sse = all_operations::<f32x8>(a, b);
            let avx = all_operations_or_none(a, b).expect("AVX2 was found above");
            for (op, (s, v)) in sse.iter().zip(&avx).enumerate() {
                let (s, v) = if ARITHMETIC.contains(&op) {
                    (s.map(any_nan_alike), v.map(any_nan_alike))
                } else {
                    (*s, *v)
                };
                assert_eq!(s, v, "round {round}, operation {op}: {a:?} {b:?}");
            }
        }
    }
}
