//! Forward-mode automatic differentiation: a value with `N` tangents. The
//! trainer pushes each Gaussian's geometry (local position, log-scale,
//! quaternion: ten numbers) through the binding and the projection in
//! `Dual<10>`, so the Jacobian of the projected splat (centre, conic, colour)
//! comes out exact with the same code that computes the values — no
//! hand-derived chain rule to get wrong. Only the rasteriser, where forward
//! mode would cost a pass per splat, is differentiated by hand (`raster.rs`).

use std::ops::{Add, Div, Mul, Neg, Sub};

/// A value and its derivatives with respect to `N` inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const N: usize> {
    /// The value.
    pub v: f64,
    /// ∂value/∂input_k.
    pub d: [f64; N],
}

impl<const N: usize> Dual<N> {
    /// A constant (no derivatives).
    pub fn constant(v: f64) -> Self {
        Self { v, d: [0.0; N] }
    }

    /// Input number `k` with value `v`.
    pub fn variable(v: f64, k: usize) -> Self {
        let mut d = [0.0; N];
        d[k] = 1.0;
        Self { v, d }
    }

    fn chain(self, v: f64, dv: f64) -> Self {
        Self {
            v,
            d: self.d.map(|x| x * dv),
        }
    }

    /// eˣ.
    pub fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }

    /// √x (x > 0).
    pub fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s)
    }

    /// x clamped to [lo, hi]; outside, a constant (zero derivative), as the
    /// clamp it models.
    pub fn clamp(self, lo: f64, hi: f64) -> Self {
        if self.v < lo {
            Self::constant(lo)
        } else if self.v > hi {
            Self::constant(hi)
        } else {
            self
        }
    }
}

impl<const N: usize> Add for Dual<N> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self {
            v: self.v + o.v,
            d: std::array::from_fn(|k| self.d[k] + o.d[k]),
        }
    }
}

impl<const N: usize> Sub for Dual<N> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self {
            v: self.v - o.v,
            d: std::array::from_fn(|k| self.d[k] - o.d[k]),
        }
    }
}

impl<const N: usize> Mul for Dual<N> {
    type Output = Self;
    #[allow(clippy::suspicious_arithmetic_impl)] // the product rule
    fn mul(self, o: Self) -> Self {
        Self {
            v: self.v * o.v,
            d: std::array::from_fn(|k| self.d[k] * o.v + self.v * o.d[k]),
        }
    }
}

impl<const N: usize> Div for Dual<N> {
    type Output = Self;
    #[allow(clippy::suspicious_arithmetic_impl)] // the quotient rule
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let v = self.v * inv;
        Self {
            v,
            d: std::array::from_fn(|k| (self.d[k] - v * o.d[k]) * inv),
        }
    }
}

impl<const N: usize> Neg for Dual<N> {
    type Output = Self;
    fn neg(self) -> Self {
        self.chain(-self.v, -1.0)
    }
}

impl<const N: usize> Add<f64> for Dual<N> {
    type Output = Self;
    fn add(self, o: f64) -> Self {
        Self {
            v: self.v + o,
            d: self.d,
        }
    }
}

impl<const N: usize> Sub<f64> for Dual<N> {
    type Output = Self;
    fn sub(self, o: f64) -> Self {
        Self {
            v: self.v - o,
            d: self.d,
        }
    }
}

impl<const N: usize> Mul<f64> for Dual<N> {
    type Output = Self;
    fn mul(self, o: f64) -> Self {
        self.chain(self.v * o, o)
    }
}

impl<const N: usize> Div<f64> for Dual<N> {
    type Output = Self;
    fn div(self, o: f64) -> Self {
        self.chain(self.v / o, 1.0 / o)
    }
}

/// A 3-vector of duals.
pub type DVec<const N: usize> = [Dual<N>; 3];

/// a · b.
pub fn dot<const N: usize>(a: &DVec<N>, b: &DVec<N>) -> Dual<N> {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// A 3×3 matrix of constants (row-major) times a dual vector.
pub fn mat_vec<const N: usize>(m: &[[f64; 3]; 3], v: &DVec<N>) -> DVec<N> {
    std::array::from_fn(|r| v[0] * m[r][0] + v[1] * m[r][1] + v[2] * m[r][2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every operation against central differences of the same expression.
    #[test]
    fn derivatives_match_finite_differences() {
        let f = |x: Dual<2>, y: Dual<2>| {
            ((x * y + 1.5).exp() / (y * y + 2.0).sqrt() - x * 3.0 + (-y) / 0.7).clamp(-50.0, 50.0)
                - (x - y) * (x / (y + 4.0))
        };
        let (x0, y0) = (0.3, -0.8);
        let out = f(Dual::variable(x0, 0), Dual::variable(y0, 1));
        let h = 1e-6;
        let value = |x: f64, y: f64| f(Dual::constant(x), Dual::constant(y)).v;
        let dx = (value(x0 + h, y0) - value(x0 - h, y0)) / (2.0 * h);
        let dy = (value(x0, y0 + h) - value(x0, y0 - h)) / (2.0 * h);
        assert!(
            (out.d[0] - dx).abs() < 1e-8 * dx.abs().max(1.0),
            "{} {dx}",
            out.d[0]
        );
        assert!(
            (out.d[1] - dy).abs() < 1e-8 * dy.abs().max(1.0),
            "{} {dy}",
            out.d[1]
        );
        // A clamp that bites has no derivative.
        let c = (Dual::<1>::variable(3.0, 0) * 2.0).clamp(0.0, 1.0);
        assert_eq!((c.v, c.d), (1.0, [0.0]));
    }
}
