//! Adam (Kingma & Ba), one instance per parameter group as 3DGS keeps them:
//! its own learning rate, moment estimates per value, a step count shared by
//! the group. Densification appends fresh (zero) moments for new Gaussians
//! and pruning drops the moments of removed ones, as the reference trainer
//! does with its optimiser state. (Ten lines of arithmetic: the crates that
//! ship Adam want their own tensor types.)

use rayon::prelude::*;

/// β₁, β₂ and ε of 3DGS.
const BETA1: f64 = 0.9;
const BETA2: f64 = 0.999;
const EPSILON: f64 = 1e-15;

/// Adam's state for one group of parameters, `width` values per Gaussian.
#[derive(Clone, Debug, PartialEq)]
pub struct AdamGroup {
    /// Learning rate (a schedule may change it between steps).
    pub lr: f64,
    width: usize,
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl AdamGroup {
    /// A group of `count` Gaussians × `width` values.
    pub fn new(lr: f64, width: usize, count: usize) -> Self {
        Self {
            lr,
            width,
            m: vec![0.0; width * count],
            v: vec![0.0; width * count],
            t: 0,
        }
    }

    /// One step over the whole group: `params` and `grads` are flat, `width`
    /// values per Gaussian.
    pub fn step(&mut self, params: &mut [f64], grads: &[f64]) {
        self.t += 1;
        let c1 = 1.0 - BETA1.powi(self.t);
        let c2 = 1.0 - BETA2.powi(self.t);
        let lr = self.lr;
        // Each value's update depends on its own state only: in parallel,
        // the same bits as one at a time.
        params
            .par_iter_mut()
            .zip(grads)
            .zip(&mut self.m)
            .zip(&mut self.v)
            .for_each(|(((p, g), m), v)| {
                *m = BETA1 * *m + (1.0 - BETA1) * g;
                *v = BETA2 * *v + (1.0 - BETA2) * g * g;
                *p -= lr * (*m / c1) / ((*v / c2).sqrt() + EPSILON);
            });
    }

    /// Keeps the state of the Gaussians where `keep` is true, in order.
    pub fn retain(&mut self, keep: &[bool]) {
        let w = self.width;
        let filter = |x: &mut Vec<f64>| {
            *x = x
                .chunks(w)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(c, _)| c.iter().copied())
                .collect();
        };
        filter(&mut self.m);
        filter(&mut self.v);
    }

    /// Appends zero state for `count` new Gaussians.
    pub fn grow(&mut self, count: usize) {
        self.m.resize(self.m.len() + count * self.width, 0.0);
        self.v.resize(self.v.len() + count * self.width, 0.0);
    }

    /// The moments and the step count (for checkpoints).
    pub fn state(&self) -> (&[f64], &[f64], i32) {
        (&self.m, &self.v, self.t)
    }

    /// Restores moments and step count saved by [`AdamGroup::state`] for
    /// `count` Gaussians.
    pub fn restore(
        &mut self,
        m: Vec<f64>,
        v: Vec<f64>,
        t: i32,
        count: usize,
    ) -> Result<(), String> {
        if m.len() != v.len() || m.len() != count * self.width {
            return Err(format!(
                "optimiser state of {} and {} values does not fit groups of {}",
                m.len(),
                v.len(),
                self.width
            ));
        }
        (self.m, self.v, self.t) = (m, v, t);
        Ok(())
    }

    /// Zeroes the moments of one value (after an opacity reset, the reference
    /// trainer restarts the reset values' moments).
    pub fn reset_values(&mut self, range: std::ops::Range<usize>) {
        self.m[range.clone()].fill(0.0);
        self.v[range].fill(0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Adam walks a badly scaled quadratic to its minimum, and its first step
    /// is the learning rate in the gradient's direction.
    #[test]
    fn minimises_a_quadratic_and_keeps_state_through_pruning() {
        let mut x = vec![3.0, -2.0, 0.5, 1.0];
        let scale = [1.0, 100.0, 0.01, 5.0];
        let mut adam = AdamGroup::new(0.05, 2, 2);
        let grad =
            |x: &[f64]| -> Vec<f64> { x.iter().zip(scale).map(|(a, s)| 2.0 * s * a).collect() };
        let before = x.clone();
        let g = grad(&x);
        adam.step(&mut x, &g);
        for (a, b) in x.iter().zip(&before) {
            assert!(
                ((b - a).abs() - 0.05).abs() < 1e-9,
                "first step is lr: {a} {b}"
            );
        }
        for _ in 0..3000 {
            let g = grad(&x);
            adam.step(&mut x, &g);
        }
        assert!(x.iter().all(|a| a.abs() < 1e-2), "{x:?}");
        adam.retain(&[false, true]);
        adam.grow(1);
        assert_eq!((adam.m.len(), adam.v.len()), (4, 4));
        assert_eq!(&adam.m[2..], &[0.0, 0.0]);
    }
}
