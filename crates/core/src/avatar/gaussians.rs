//! A set of triangle-bound Gaussians in structure-of-arrays form, in the
//! parameterisation GaussianAvatars stores (local position, unnormalised
//! quaternion, log-scale, opacity logit, spherical-harmonics colour).

use glam::{Quat, Vec3};

/// The zeroth-order SH constant: rgb = 0.5 + C0 · f_dc.
pub const SH_C0: f32 = 0.282_094_8;

/// Number of SH coefficients per channel for a degree (0..=3).
pub const fn sh_coefficients(degree: u8) -> usize {
    (degree as usize + 1) * (degree as usize + 1)
}

/// The SH degree for a per-channel coefficient count, if it is a square 1, 4, 9 or 16.
pub fn sh_degree_for(coefficients: usize) -> Option<u8> {
    (0u8..=3).find(|&d| sh_coefficients(d) == coefficients)
}

/// Converts a display colour channel to the DC coefficient.
pub fn rgb_to_dc(rgb: f32) -> f32 {
    (rgb - 0.5) / SH_C0
}

/// Converts a DC coefficient to a display colour channel (unclamped).
pub fn dc_to_rgb(dc: f32) -> f32 {
    0.5 + SH_C0 * dc
}

/// The SH constant of degree 1.
pub const SH_C1: f32 = 0.488_602_5;

/// Triangle-bound Gaussians. All arrays have one entry per Gaussian except `sh`,
/// which has `3 · sh_coefficients(sh_degree)` floats per Gaussian laid out
/// coefficient-major: `[coef][channel]` (coefficient 0 is the DC term).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GaussianSet {
    /// Parent triangle index.
    pub binding: Vec<u32>,
    /// Position in the parent triangle's frame (units of the triangle size).
    pub position: Vec<Vec3>,
    /// Rotation relative to the triangle frame; not necessarily normalised.
    pub rotation: Vec<Quat>,
    /// Natural log of the per-axis scale in units of the triangle size.
    pub log_scale: Vec<Vec3>,
    /// Opacity before the sigmoid.
    pub opacity_logit: Vec<f32>,
    /// SH degree 0..=3.
    pub sh_degree: u8,
    /// SH coefficients, see the type documentation.
    pub sh: Vec<f32>,
}

impl GaussianSet {
    /// An empty set with the given SH degree.
    pub fn with_degree(sh_degree: u8) -> Self {
        Self {
            sh_degree,
            ..Self::default()
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.binding.len()
    }

    /// True when there is no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.binding.is_empty()
    }

    /// Floats of SH per Gaussian.
    pub fn sh_stride(&self) -> usize {
        3 * sh_coefficients(self.sh_degree)
    }

    /// SH coefficients of Gaussian `i`.
    pub fn sh_of(&self, i: usize) -> &[f32] {
        let s = self.sh_stride();
        &self.sh[i * s..(i + 1) * s]
    }

    /// Mutable SH coefficients of Gaussian `i`.
    pub fn sh_of_mut(&mut self, i: usize) -> &mut [f32] {
        let s = self.sh_stride();
        &mut self.sh[i * s..(i + 1) * s]
    }

    /// Appends one Gaussian; `sh` must hold `sh_stride()` floats.
    pub fn push(
        &mut self,
        binding: u32,
        position: Vec3,
        rotation: Quat,
        log_scale: Vec3,
        opacity_logit: f32,
        sh: &[f32],
    ) {
        assert_eq!(sh.len(), self.sh_stride(), "SH length");
        self.binding.push(binding);
        self.position.push(position);
        self.rotation.push(rotation);
        self.log_scale.push(log_scale);
        self.opacity_logit.push(opacity_logit);
        self.sh.extend_from_slice(sh);
    }

    /// Empties the set (keeping its allocations) and sets its SH degree.
    pub fn clear(&mut self, sh_degree: u8) {
        self.binding.clear();
        self.position.clear();
        self.rotation.clear();
        self.log_scale.clear();
        self.opacity_logit.clear();
        self.sh.clear();
        self.sh_degree = sh_degree;
    }

    /// Reserves room for `additional` more Gaussians.
    pub fn reserve(&mut self, additional: usize) {
        self.binding.reserve(additional);
        self.position.reserve(additional);
        self.rotation.reserve(additional);
        self.log_scale.reserve(additional);
        self.opacity_logit.reserve(additional);
        self.sh.reserve(additional * self.sh_stride());
    }

    /// Sets the number of Gaussians to `n` with SH degree `sh_degree`, for
    /// filling through [`GaussianSet::ranges_mut`]. Gaussians kept keep
    /// their values and new ones are zero, so every one must be written;
    /// shrinking, or growing within the allocations, costs nothing per
    /// Gaussian already there.
    pub fn resize(&mut self, n: usize, sh_degree: u8) {
        if sh_degree != self.sh_degree {
            self.clear(sh_degree);
        }
        self.binding.resize(n, 0);
        self.position.resize(n, Vec3::ZERO);
        self.rotation.resize(n, Quat::IDENTITY);
        self.log_scale.resize(n, Vec3::ZERO);
        self.opacity_logit.resize(n, 0.0);
        self.sh.resize(n * self.sh_stride(), 0.0);
    }

    /// Mutable views of the consecutive ranges `0..ends[0]`, `ends[0]..ends[1]`,
    /// …, for writing disjoint parts of the set in parallel. `ends` must
    /// ascend and end at most at `len()`.
    pub fn ranges_mut(&mut self, ends: &[usize]) -> Vec<GaussianRange<'_>> {
        let stride = self.sh_stride();
        let mut rest = GaussianRange {
            start: 0,
            binding: &mut self.binding,
            position: &mut self.position,
            rotation: &mut self.rotation,
            log_scale: &mut self.log_scale,
            opacity_logit: &mut self.opacity_logit,
            sh: &mut self.sh,
            stride,
        };
        let mut ranges = Vec::with_capacity(ends.len());
        for &end in ends {
            let n = end - rest.start;
            let (head, tail) = rest.split_at(n);
            ranges.push(head);
            rest = tail;
        }
        ranges
    }

    /// Appends Gaussian `i` of `other` with a new opacity logit. SH beyond this
    /// set's degree are dropped; missing ones are zero.
    pub fn push_from(&mut self, other: &GaussianSet, i: usize, opacity_logit: f32) {
        self.binding.push(other.binding[i]);
        self.position.push(other.position[i]);
        self.rotation.push(other.rotation[i]);
        self.log_scale.push(other.log_scale[i]);
        self.opacity_logit.push(opacity_logit);
        let stride = self.sh_stride();
        let sh = other.sh_of(i);
        if sh.len() == stride {
            self.sh.extend_from_slice(sh);
        } else {
            let take = sh.len().min(stride);
            self.sh.extend_from_slice(&sh[..take]);
            self.sh.extend(std::iter::repeat_n(0.0, stride - take));
        }
    }

    /// Checks internal consistency: equal lengths, bindings below `triangles`,
    /// finite values. Returns a one-line description of the first problem.
    pub fn validate(&self, triangles: usize) -> Result<(), String> {
        let n = self.len();
        if self.position.len() != n
            || self.rotation.len() != n
            || self.log_scale.len() != n
            || self.opacity_logit.len() != n
            || self.sh.len() != n * self.sh_stride()
        {
            return Err("Gaussian attribute arrays differ in length".into());
        }
        if let Some((i, b)) = self
            .binding
            .iter()
            .enumerate()
            .find(|(_, b)| **b as usize >= triangles)
        {
            return Err(format!(
                "Gaussian {i} is bound to triangle {b}, but the mesh has {triangles} triangles"
            ));
        }
        let finite = |i: usize| {
            self.position[i].is_finite()
                && self.rotation[i].is_finite()
                && self.log_scale[i].is_finite()
                && self.opacity_logit[i].is_finite()
                && self.sh_of(i).iter().all(|x| x.is_finite())
        };
        if let Some(i) = (0..n).find(|&i| !finite(i)) {
            return Err(format!("Gaussian {i} has a NaN or infinite value"));
        }
        Ok(())
    }
}

/// A mutable view of consecutive Gaussians of a [`GaussianSet`], made by
/// [`GaussianSet::ranges_mut`]; indices are the set's own.
pub struct GaussianRange<'a> {
    start: usize,
    binding: &'a mut [u32],
    position: &'a mut [Vec3],
    rotation: &'a mut [Quat],
    log_scale: &'a mut [Vec3],
    opacity_logit: &'a mut [f32],
    sh: &'a mut [f32],
    stride: usize,
}

impl<'a> GaussianRange<'a> {
    /// The set's index of the view's first Gaussian.
    pub fn start(&self) -> usize {
        self.start
    }

    /// Number of Gaussians in the view.
    pub fn len(&self) -> usize {
        self.binding.len()
    }

    /// True when the view holds no Gaussian.
    pub fn is_empty(&self) -> bool {
        self.binding.is_empty()
    }

    /// Writes Gaussian `i` of `other` at the set's index `at` with a new
    /// opacity logit. SH beyond the set's degree are dropped; missing ones
    /// are zero.
    pub fn set_from(&mut self, at: usize, other: &GaussianSet, i: usize, opacity_logit: f32) {
        let k = at - self.start;
        self.binding[k] = other.binding[i];
        self.position[k] = other.position[i];
        self.rotation[k] = other.rotation[i];
        self.log_scale[k] = other.log_scale[i];
        self.opacity_logit[k] = opacity_logit;
        let sh = other.sh_of(i);
        let take = sh.len().min(self.stride);
        let to = self.sh_of_mut(at);
        to[..take].copy_from_slice(&sh[..take]);
        to[take..].fill(0.0);
    }

    /// Moves the Gaussian at the set's index `at` to a new position,
    /// rotation and log-scales in its parent's frame.
    pub fn set_placement(
        &mut self,
        at: usize,
        (position, rotation, log_scale): (Vec3, Quat, Vec3),
    ) {
        let k = at - self.start;
        self.position[k] = position;
        self.rotation[k] = rotation;
        self.log_scale[k] = log_scale;
    }

    /// Mutable SH coefficients of the Gaussian at the set's index `at`.
    pub fn sh_of_mut(&mut self, at: usize) -> &mut [f32] {
        let k = at - self.start;
        &mut self.sh[k * self.stride..(k + 1) * self.stride]
    }

    /// The first `n` Gaussians and the rest.
    fn split_at(self, n: usize) -> (GaussianRange<'a>, GaussianRange<'a>) {
        let (b0, b1) = self.binding.split_at_mut(n);
        let (p0, p1) = self.position.split_at_mut(n);
        let (r0, r1) = self.rotation.split_at_mut(n);
        let (l0, l1) = self.log_scale.split_at_mut(n);
        let (o0, o1) = self.opacity_logit.split_at_mut(n);
        let (s0, s1) = self.sh.split_at_mut(n * self.stride);
        let head = GaussianRange {
            start: self.start,
            binding: b0,
            position: p0,
            rotation: r0,
            log_scale: l0,
            opacity_logit: o0,
            sh: s0,
            stride: self.stride,
        };
        let tail = GaussianRange {
            start: self.start + n,
            binding: b1,
            position: p1,
            rotation: r1,
            log_scale: l1,
            opacity_logit: o1,
            sh: s1,
            stride: self.stride,
        };
        (head, tail)
    }
}

/// Logistic sigmoid.
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + (-x).exp())
}

/// Inverse of the sigmoid, for probabilities strictly inside (0, 1).
pub fn logit(p: f32) -> f32 {
    let p = p.clamp(1e-6, 1.0 - 1e-6);
    (p / (1.0 - p)).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sh_degree_round_trip() {
        for d in 0..=3u8 {
            assert_eq!(sh_degree_for(sh_coefficients(d)), Some(d));
        }
        assert_eq!(sh_degree_for(5), None);
    }

    /// A set of `n` Gaussians of degree `d` whose every value tells which it is.
    fn numbered(n: usize, d: u8, base: f32) -> GaussianSet {
        let mut set = GaussianSet::with_degree(d);
        for i in 0..n {
            let x = base + i as f32;
            let sh: Vec<f32> = (0..set.sh_stride()).map(|k| x + 0.01 * k as f32).collect();
            set.push(
                i as u32,
                Vec3::splat(x),
                Quat::from_xyzw(x, 0.0, 0.0, 1.0),
                -Vec3::splat(x),
                x,
                &sh,
            );
        }
        set
    }

    #[test]
    fn ranges_written_in_any_order_equal_the_same_gaussians_pushed() {
        for (from_degree, to_degree) in [(1, 1), (3, 1), (0, 2)] {
            let source = numbered(9, from_degree, 10.0);
            let order = [4usize, 0, 8, 2, 7, 1, 5, 3, 6];
            let mut pushed = GaussianSet::with_degree(to_degree);
            for &i in &order {
                pushed.push_from(&source, i, -(i as f32));
            }
            // Reused: stale values of another degree and length first.
            let mut filled = numbered(12, 3, 100.0);
            filled.resize(order.len(), to_degree);
            let mut ranges = filled.ranges_mut(&[2, 2, 6, 9]);
            assert_eq!(
                ranges.iter().map(|r| r.len()).collect::<Vec<_>>(),
                [2, 0, 4, 3]
            );
            for range in ranges.iter_mut().rev() {
                let start = range.start();
                for (at, &i) in order.iter().enumerate().skip(start).take(range.len()) {
                    range.set_from(at, &source, i, -(i as f32));
                }
            }
            assert_eq!(filled, pushed, "degree {from_degree} into {to_degree}");
        }
    }

    #[test]
    fn validate_catches_bad_binding_and_nan() {
        let mut g = GaussianSet::with_degree(0);
        g.push(3, Vec3::ZERO, Quat::IDENTITY, Vec3::ZERO, 0.0, &[0.0; 3]);
        assert!(g.validate(4).is_ok());
        assert!(g.validate(3).unwrap_err().contains("triangle 3"));
        g.opacity_logit[0] = f32::NAN;
        assert!(g.validate(4).unwrap_err().contains("NaN"));
    }

    #[test]
    fn colour_and_opacity_conversions_invert() {
        for x in [0.0, 0.25, 0.9] {
            assert!((dc_to_rgb(rgb_to_dc(x)) - x).abs() < 1e-6);
            assert!((sigmoid(logit(x.max(0.01))) - x.max(0.01)).abs() < 1e-5);
        }
    }
}
