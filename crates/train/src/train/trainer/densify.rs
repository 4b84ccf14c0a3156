//! Adaptive density control, GaussianAvatars' way: the view-space gradient
//! tracked per Gaussian, clones of small and splits of large ones (children
//! keep their parent's triangle), pruning of transparent and huge ones while
//! every triangle keeps one, and opacity resets.

use glam::DVec3;
use rand::Rng;
use rand_chacha::ChaCha8Rng;

use super::{logit, sigmoid, Trainer};
use crate::train::model::{Gradients, Render, SH_STRIDE};

impl Trainer {
    /// Adds this step's view-space gradient and screen radius of every drawn Gaussian.
    pub(super) fn track_densification(
        &mut self,
        render: &Render,
        grads: &Gradients,
        size: [u32; 2],
    ) {
        for (&i, radius) in render.drawn_indices().iter().zip(render.radii()) {
            let i = i as usize;
            // 3DGS's threshold is on the gradient in NDC units.
            let ndc = grads.screen_xy[i];
            let norm = (ndc[0] * 0.5 * size[0] as f64).hypot(ndc[1] * 0.5 * size[1] as f64);
            self.grad_accum[i] += norm;
            self.grad_count[i] += 1;
            self.max_radius[i] = self.max_radius[i].max(radius);
        }
    }

    /// World scale of Gaussian `i` (its largest axis), on the first timestep.
    fn world_scale(&self, i: usize) -> f64 {
        let frames = self.frames.values().next().expect("a timestep");
        let face = frames[self.model.binding[i] as usize].scale as f64;
        let s = self.model.geometry[i].log_scale;
        s[0].max(s[1]).max(s[2]).exp() * face
    }

    /// Clones small and splits large Gaussians whose mean view-space
    /// gradient passed the threshold, then prunes; the statistics restart.
    pub(super) fn densify_and_prune(&mut self) {
        let n = self.model.len();
        let threshold = self.schedule.densify_grad_threshold;
        let dense = self.schedule.percent_dense * self.extent;
        let mut clones = Vec::new();
        let mut splits = Vec::new();
        for i in 0..n {
            let grad = if self.grad_count[i] > 0 {
                self.grad_accum[i] / self.grad_count[i] as f64
            } else {
                0.0
            };
            if grad < threshold {
                continue;
            }
            if self.world_scale(i) <= dense {
                clones.push(i);
            } else {
                splits.push(i);
            }
        }
        for &i in &clones {
            self.push_copy(i, None);
        }
        for &i in &splits {
            for _ in 0..2 {
                let g = self.model.geometry[i];
                let local = g.log_scale.map(f64::exp);
                let sample = DVec3::new(
                    normal(&mut self.rng) * local[0],
                    normal(&mut self.rng) * local[1],
                    normal(&mut self.rng) * local[2],
                );
                let [w, x, y, z] = g.rotation;
                let q = glam::DQuat::from_xyzw(x, y, z, w).normalize();
                let offset = q * sample;
                self.push_copy(i, Some(offset));
            }
        }
        // Prune: transparent Gaussians, the split parents, and (after the
        // first opacity reset) huge ones — never a triangle's last one.
        let mut prune = vec![false; self.model.len()];
        for &i in &splits {
            prune[i] = true;
        }
        let max_world = 0.1 * self.extent;
        // GaussianAvatars prunes splats over 20 px at its ~800 px images.
        let max_screen = (20.0 * self.targets[0].camera.size[1] as f64 / 802.0).max(4.0);
        for (i, p) in prune.iter_mut().enumerate() {
            let transparent = sigmoid(self.model.opacity_logit[i]) < 0.005;
            let huge = self.reset_done
                && (self.max_radius.get(i).copied().unwrap_or(0.0) > max_screen
                    || self.world_scale(i) > max_world);
            *p |= transparent || huge;
        }
        let mut left = vec![0usize; self.subset.len()];
        for (i, &b) in self.model.binding.iter().enumerate() {
            if !prune[i] {
                left[b as usize] += 1;
            }
        }
        for (i, p) in prune.iter_mut().enumerate() {
            let b = self.model.binding[i] as usize;
            if *p && left[b] == 0 {
                *p = false; // keep one for the triangle
                left[b] += 1;
            }
        }
        let keep: Vec<bool> = prune.iter().map(|p| !p).collect();
        self.retain(&keep);
        let n = self.model.len();
        self.grad_accum = vec![0.0; n];
        self.grad_count = vec![0; n];
        self.max_radius = vec![0.0; n];
    }

    /// Appends a copy of Gaussian `i` (moved by `offset` and shrunk by 1.6
    /// for a split child).
    fn push_copy(&mut self, i: usize, offset: Option<DVec3>) {
        let m = &mut self.model;
        let mut g = m.geometry[i];
        if let Some(o) = offset {
            for k in 0..3 {
                g.position[k] += o[k];
                g.log_scale[k] -= 1.6f64.ln();
            }
        }
        m.binding.push(m.binding[i]);
        m.geometry.push(g);
        m.opacity_logit.push(m.opacity_logit[i]);
        let sh: Vec<f64> = m.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE].to_vec();
        m.sh.extend(sh);
        for group in self.groups.all() {
            group.grow(1);
        }
        self.max_radius.push(0.0);
    }

    /// Keeps the Gaussians (and their optimiser state) marked in `keep`.
    fn retain(&mut self, keep: &[bool]) {
        let m = &mut self.model;
        let mut k = keep.iter();
        m.binding.retain(|_| *k.next().unwrap());
        let mut k = keep.iter();
        m.geometry.retain(|_| *k.next().unwrap());
        let mut k = keep.iter();
        m.opacity_logit.retain(|_| *k.next().unwrap());
        m.sh =
            m.sh.chunks(SH_STRIDE)
                .zip(keep)
                .filter(|(_, k)| **k)
                .flat_map(|(c, _)| c.iter().copied())
                .collect();
        for group in self.groups.all() {
            group.retain(keep);
        }
    }

    /// Caps every opacity at 0.01 and clears its optimiser moments.
    pub(super) fn reset_opacity(&mut self) {
        let cap = logit(0.01);
        for o in &mut self.model.opacity_logit {
            *o = o.min(cap);
        }
        let n = self.model.len();
        self.groups.opacity.reset_values(0..n);
        self.reset_done = true;
    }
}

/// A standard normal sample (Box–Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random::<f64>().max(1e-12);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}
