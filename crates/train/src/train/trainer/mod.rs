//! GaussianAvatars' recipe on the differentiable renderer: one Gaussian per
//! triangle to start; Adam with per-group learning rates and the exponential
//! position schedule; (1 − 0.2)·L1 + 0.2·D-SSIM plus the local-position and
//! local-scale regularisers; SH degree raised on a schedule; densification by
//! the view-space gradient (clone small, split large, children keep their
//! parent's triangle), pruning of transparent and huge Gaussians while every
//! triangle keeps one, and opacity resets. The schedule is GaussianAvatars'
//! compressed (its 600k iterations → `iterations`), so the default capture
//! trains in minutes on two cores. Deterministic for a seed.

mod checkpoint;
mod densify;
mod export;
mod schedule;

use std::collections::BTreeMap;
use std::time::Instant;

use glam::{DVec3, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

pub use export::TRAINING_METADATA;
pub use schedule::Schedule;

use super::adam::AdamGroup;
use super::dataset::Dataset;
use super::holes::{
    interior_layer, obscuring_splat, oriented_box, view_ratios, HoleFilling, Obscurer, OrientedBox,
    TriangleSubset,
};
use super::loss::{photometric_loss, psnr};
use super::model::{Gradients, Render, Trainable, SH_STRIDE};
use super::posing::{camera_extent, pose_timesteps};
use super::project::Geometry;
use super::raster::Rasterizer;
use super::target::{load_target, Target};
use crate::avatar::binding::{triangle_frames, TriangleFrame};
use crate::avatar::gaussians::GaussianSet;
use crate::error::{Error, Result};
use crate::io::avatar::FrameParams;
use crate::model::head::HeadModel;
use crate::render::Backend;

/// How to train.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOptions {
    /// Iterations (one view each).
    pub iterations: usize,
    /// Seed of the initial colours, the view order and the splits' noise.
    pub seed: u64,
    /// Training resolution (the images are resized); None: as stored.
    pub size: Option<[u32; 2]>,
    /// Background composited behind the foreground mask.
    pub background: [f64; 3],
    /// Which rasteriser runs the forward and backward passes.
    pub renderer: Backend,
    /// The thesis's hole filling (obscuring Gaussians, back-face culling).
    pub holes: HoleFilling,
}

impl TrainOptions {
    /// What `visage train` does by default: images as stored, over black,
    /// with the interior layer behind the surface (so a region is opaque on
    /// its own and does not lean on the Gaussians behind it, which a
    /// composite may take from another source).
    pub fn recommended(iterations: usize, seed: u64, renderer: Backend) -> Self {
        Self {
            iterations,
            seed,
            size: None,
            background: [0.0; 3],
            renderer,
            holes: HoleFilling::RECOMMENDED,
        }
    }
}

/// One step's figures, for the progress bar and the curve.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct StepReport {
    /// Iteration (1-based).
    pub iteration: usize,
    /// Photometric loss.
    pub loss: f64,
    /// PSNR of the training view.
    pub psnr: f64,
    /// Gaussians.
    pub gaussians: usize,
}

/// Seconds spent in each part of the training steps so far (for `bench
/// train`: where an iteration's time goes).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageSeconds {
    /// Projection (dual numbers) and the rasteriser's forward pass.
    pub forward: f64,
    /// The photometric loss and its gradient.
    pub loss: f64,
    /// The rasteriser's backward pass and the chain rule to the parameters.
    pub backward: f64,
    /// Regularisers, densification statistics, Adam, densify and prune.
    pub update: f64,
}

/// A trainer over a dataset: the model, its optimiser and the posed meshes.
pub struct Trainer {
    /// The parameters.
    pub model: Trainable,
    options: TrainOptions,
    schedule: Schedule,
    head: HeadModel,
    /// Triangle frames per timestep.
    frames: std::collections::BTreeMap<usize, Vec<TriangleFrame>>,
    targets: Vec<Target>,
    extent: f64,
    groups: Groups,
    grad_accum: Vec<f64>,
    grad_count: Vec<u32>,
    max_radius: Vec<f64>,
    rng: ChaCha8Rng,
    order: Vec<usize>,
    step: usize,
    reset_done: bool,
    identity: (Vec<f32>, Vec<glam::DVec3>),
    flame_frames: Vec<FrameParams>,
    rasterizer: Rasterizer,
    /// The triangles trained on (all, or those back-face culling kept).
    subset: TriangleSubset,
    /// The posed head's box per timestep, when obscuring.
    boxes: BTreeMap<usize, OrientedBox>,
    /// The posed vertices per timestep, for the interior layer.
    posed: BTreeMap<usize, Vec<Vec3>>,
    /// Where the steps' time went.
    pub stage_seconds: StageSeconds,
}

/// Adam per parameter group.
struct Groups {
    position: AdamGroup,
    scale: AdamGroup,
    rotation: AdamGroup,
    opacity: AdamGroup,
    dc: AdamGroup,
    rest: AdamGroup,
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

fn logit(p: f64) -> f64 {
    (p / (1.0 - p)).ln()
}

/// One Gaussian per triangle, at its centre, a triangle in size, nearly
/// transparent, with a random near-black colour.
fn initial_model(n: usize, rng: &mut ChaCha8Rng) -> Trainable {
    let mut model = Trainable {
        binding: (0..n as u32).collect(),
        geometry: vec![
            Geometry {
                position: [0.0; 3],
                log_scale: [0.0; 3],
                rotation: [1.0, 0.0, 0.0, 0.0],
            };
            n
        ],
        opacity_logit: vec![logit(0.1); n],
        sh: vec![0.0; n * SH_STRIDE],
        sh_degree: 0,
    };
    for i in 0..n {
        for ch in 0..3 {
            model.sh[i * SH_STRIDE + ch] = rng.random::<f64>() / 255.0;
        }
    }
    model
}

/// The posed head's box per timestep (for the obscuring Gaussian and the
/// interior layer).
fn head_boxes(posed: &BTreeMap<usize, Vec<Vec3>>) -> BTreeMap<usize, OrientedBox> {
    posed
        .iter()
        .filter_map(|(&t, vertices)| Some((t, oriented_box(vertices)?)))
        .collect()
}

/// Refuses a dataset whose views name a timestep without FLAME parameters.
fn check_timesteps(dataset: &Dataset, frames: &BTreeMap<usize, Vec<TriangleFrame>>) -> Result<()> {
    for v in dataset
        .train
        .iter()
        .chain(&dataset.val)
        .chain(&dataset.test)
    {
        if !frames.contains_key(&v.timestep) {
            return Err(Error::input(format!(
                "{}: timestep {} has no FLAME parameters",
                v.image.display(),
                v.timestep
            )));
        }
    }
    Ok(())
}

impl Trainer {
    /// A trainer on `dataset` for the head model `head`: one Gaussian per
    /// triangle, grey, at the triangle's centre, a triangle in size.
    pub fn new(dataset: &Dataset, head: HeadModel, options: TrainOptions) -> Result<Self> {
        if options.iterations == 0 {
            return Err(Error::input("--iterations must be at least 1"));
        }
        let (posed, identity, flame_frames) = pose_timesteps(dataset, &head)?;
        let subset = match options.holes.cull_below {
            Some(tau) => {
                TriangleSubset::cull(&view_ratios(&head.triangles, &posed, &dataset.train), tau)?
            }
            None => TriangleSubset::all(head.triangle_count()),
        };
        let boxes = if options.holes.obscuring || options.holes.interior {
            head_boxes(&posed)
        } else {
            BTreeMap::new()
        };
        let frames: BTreeMap<usize, Vec<TriangleFrame>> = posed
            .iter()
            .map(|(&t, vertices)| {
                let full = triangle_frames(vertices, &head.triangles);
                (t, subset.restrict(&full))
            })
            .collect();
        check_timesteps(dataset, &frames)?;
        let targets = dataset
            .train
            .iter()
            .map(|v| load_target(v, options.size, options.background))
            .collect::<Result<Vec<_>>>()?;
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
        let n = subset.len();
        let model = initial_model(n, &mut rng);
        let schedule = Schedule::for_iterations(options.iterations);
        let extent = camera_extent(&dataset.train);
        let groups = Groups::new(&schedule, extent, n);
        let rasterizer = Rasterizer::open(options.renderer)?;
        Ok(Self {
            rasterizer,
            subset,
            boxes,
            stage_seconds: StageSeconds::default(),
            posed: if options.holes.interior {
                posed
            } else {
                BTreeMap::new()
            },
            model,
            schedule,
            head,
            frames,
            extent,
            groups,
            grad_accum: vec![0.0; n],
            grad_count: vec![0; n],
            max_radius: vec![0.0; n],
            rng,
            order: Vec::new(),
            step: 0,
            reset_done: false,
            targets,
            options,
            identity,
            flame_frames,
        })
    }

    /// Iterations run so far.
    pub fn iteration(&self) -> usize {
        self.step
    }

    /// The scene extent (training cameras' spread).
    pub fn extent(&self) -> f64 {
        self.extent
    }

    /// What hole filling draws with the Gaussians for `target` at `iteration`.
    fn obscurer(&self, target: &Target, iteration: usize) -> Obscurer {
        let timestep = target.view.timestep;
        let Some(head_box) = self.boxes.get(&timestep) else {
            return Obscurer::None;
        };
        match self.posed.get(&timestep) {
            Some(posed) => interior_layer(
                posed,
                &self.head.triangles,
                head_box,
                &target.camera,
                iteration,
            ),
            None => obscuring_splat(head_box, &target.camera, iteration)
                .map_or(Obscurer::None, Obscurer::Gaussian),
        }
    }

    /// What runs the rasteriser's passes, for reports.
    pub fn rasterizer(&self) -> String {
        self.rasterizer.description()
    }

    /// Runs one iteration; returns its figures.
    pub fn step(&mut self) -> Result<StepReport> {
        self.step += 1;
        let it = self.step;
        self.groups.position.lr =
            self.schedule
                .position_lr_at(it, self.options.iterations, self.extent);
        if it % self.schedule.sh_interval == 0 && self.model.sh_degree < 3 {
            self.model.sh_degree += 1;
        }
        if self.order.is_empty() {
            self.order = (0..self.targets.len()).collect();
            for i in (1..self.order.len()).rev() {
                let j = self.rng.random_range(0..=i);
                self.order.swap(i, j);
            }
        }
        let target = &self.targets[self.order.pop().expect("refilled above")];
        let frames = &self.frames[&target.view.timestep];
        let obscurer = self.obscurer(target, it);
        let clock = Instant::now();
        let render = Render::new(
            &self.model,
            frames,
            &target.camera,
            self.options.background,
            &obscurer,
            &mut self.rasterizer,
        )?;
        let forward = clock.elapsed().as_secs_f64();
        let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
        let [w, h] = target.camera.size;
        let (loss, d_image) = photometric_loss(render.image(), &goal, w as usize, h as usize, true);
        let loss_done = clock.elapsed().as_secs_f64();
        let report = StepReport {
            iteration: it,
            loss: loss.total,
            psnr: psnr(render.image(), &goal),
            gaussians: self.model.len(),
        };
        let mut grads = render.backward(&self.model, &d_image, &mut self.rasterizer)?;
        let backward_done = clock.elapsed().as_secs_f64();
        self.regularise(&render, &mut grads);
        let camera = target.camera;
        self.track_densification(&render, &grads, camera.size);
        self.apply(&grads);
        let s = self.schedule.clone();
        if it >= s.densify_from && it < s.densify_until && it % s.densify_interval == 0 {
            self.densify_and_prune();
        }
        if it % s.opacity_reset_interval == 0 && it < self.options.iterations {
            self.reset_opacity();
        }
        let stages = &mut self.stage_seconds;
        stages.forward += forward;
        stages.loss += loss_done - forward;
        stages.backward += backward_done - loss_done;
        stages.update += clock.elapsed().as_secs_f64() - backward_done;
        Ok(report)
    }

    /// GaussianAvatars' regularisers over the drawn Gaussians: local position
    /// beyond 1 (triangle size) and local scale beyond 0.6.
    fn regularise(&self, render: &Render, grads: &mut Gradients) {
        let drawn = render.drawn_indices();
        if drawn.is_empty() {
            return;
        }
        let count = drawn.len() as f64;
        let [xyz_weight, xyz_limit] = self.schedule.xyz;
        let [scale_weight, scale_limit] = self.schedule.scale;
        for &i in drawn {
            let g = &self.model.geometry[i as usize];
            let out = &mut grads.geometry[i as usize];
            let norm = DVec3::from(g.position).length();
            if norm > xyz_limit {
                for (o, x) in out.iter_mut().zip(g.position) {
                    *o += xyz_weight / count * x / norm;
                }
            }
            let excess: [f64; 3] = g.log_scale.map(|s| (s.exp() - scale_limit).max(0.0));
            let length = DVec3::from(excess).length();
            if length > 0.0 {
                for k in 0..3 {
                    out[3 + k] += scale_weight / count * excess[k] / length * g.log_scale[k].exp();
                }
            }
        }
    }

    fn apply(&mut self, grads: &Gradients) {
        let n = self.model.len();
        let gather = |f: &dyn Fn(&Geometry) -> Vec<f64>| -> Vec<f64> {
            self.model.geometry.iter().flat_map(f).collect()
        };
        let grad_of = |range: std::ops::Range<usize>| -> Vec<f64> {
            grads
                .geometry
                .iter()
                .flat_map(|g| g[range.clone()].iter().copied())
                .collect()
        };
        let mut position = gather(&|g| g.position.to_vec());
        let mut scale = gather(&|g| g.log_scale.to_vec());
        let mut rotation = gather(&|g| g.rotation.to_vec());
        self.groups.position.step(&mut position, &grad_of(0..3));
        self.groups.scale.step(&mut scale, &grad_of(3..6));
        self.groups.rotation.step(&mut rotation, &grad_of(6..10));
        for (i, g) in self.model.geometry.iter_mut().enumerate() {
            g.position.copy_from_slice(&position[i * 3..i * 3 + 3]);
            g.log_scale.copy_from_slice(&scale[i * 3..i * 3 + 3]);
            g.rotation.copy_from_slice(&rotation[i * 4..i * 4 + 4]);
        }
        self.groups
            .opacity
            .step(&mut self.model.opacity_logit, &grads.opacity_logit);
        let split = |v: &[f64]| -> (Vec<f64>, Vec<f64>) {
            let mut dc = Vec::with_capacity(n * 3);
            let mut rest = Vec::with_capacity(n * (SH_STRIDE - 3));
            for c in v.chunks(SH_STRIDE) {
                dc.extend_from_slice(&c[..3]);
                rest.extend_from_slice(&c[3..]);
            }
            (dc, rest)
        };
        let (mut dc, mut rest) = split(&self.model.sh);
        let (g_dc, g_rest) = split(&grads.sh);
        self.groups.dc.step(&mut dc, &g_dc);
        self.groups.rest.step(&mut rest, &g_rest);
        for i in 0..n {
            self.model.sh[i * SH_STRIDE..i * SH_STRIDE + 3].copy_from_slice(&dc[i * 3..i * 3 + 3]);
            self.model.sh[i * SH_STRIDE + 3..(i + 1) * SH_STRIDE]
                .copy_from_slice(&rest[i * (SH_STRIDE - 3)..(i + 1) * (SH_STRIDE - 3)]);
        }
    }

    /// The trained Gaussians (f32, SH degree 3), bound to the full topology.
    pub fn gaussians(&self) -> GaussianSet {
        let mut set = self.model.to_set(3);
        set.binding = self.subset.to_full(&set.binding);
        set
    }

    /// Triangles trained on and in the full topology.
    pub fn triangles_kept(&self) -> (usize, usize) {
        (self.subset.len(), self.subset.full)
    }

    /// The iteration count the run aims for.
    pub fn iterations(&self) -> usize {
        self.options.iterations
    }

    /// The head model trained on.
    pub fn head(&self) -> &HeadModel {
        &self.head
    }
}

impl Groups {
    /// Adam for every group at the schedule's learning rates.
    fn new(schedule: &Schedule, extent: f64, n: usize) -> Self {
        Groups {
            position: AdamGroup::new(schedule.position_lr[0] * extent, 3, n),
            scale: AdamGroup::new(schedule.scaling_lr, 3, n),
            rotation: AdamGroup::new(schedule.rotation_lr, 4, n),
            opacity: AdamGroup::new(schedule.opacity_lr, 1, n),
            dc: AdamGroup::new(schedule.feature_lr, 3, n),
            rest: AdamGroup::new(schedule.feature_lr / 20.0, SH_STRIDE - 3, n),
        }
    }

    const NAMES: [&'static str; 6] = ["position", "scale", "rotation", "opacity", "dc", "rest"];

    fn all(&mut self) -> [&mut AdamGroup; 6] {
        [
            &mut self.position,
            &mut self.scale,
            &mut self.rotation,
            &mut self.opacity,
            &mut self.dc,
            &mut self.rest,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::capture::{capture, CaptureOptions};
    use crate::train::dataset::Dataset;

    /// A run stopped at a checkpoint and resumed ends exactly where an
    /// uninterrupted run does (densification and an opacity reset included).
    #[test]
    fn a_resumed_run_matches_an_uninterrupted_one() {
        let dir = std::env::temp_dir().join(format!("visage-ckpt-{}", std::process::id()));
        let db = crate::avatar::synthetic::builtin_database(
            crate::model::builtin::build_head(),
            crate::avatar::synthetic::SyntheticOptions {
                seed: 1,
                sources: 2,
                gaussians_per_avatar: 1,
            },
        )
        .unwrap();
        let options = CaptureOptions {
            source: "ada".into(),
            size: [40, 40],
            cameras: 3,
            frames: 2,
            motion: "talk".into(),
            ring: false,
        };
        capture(&db, &options, &dir, &|_, _| {}).unwrap();
        let dataset = Dataset::load(&dir).unwrap();
        let train = TrainOptions {
            iterations: 40,
            seed: 9,
            size: Some([24, 24]),
            background: [0.0; 3],
            renderer: Backend::Cpu,
            holes: HoleFilling::default(),
        };
        let head = || crate::model::builtin::build_head();
        let mut straight = Trainer::new(&dataset, head(), train.clone()).unwrap();
        for _ in 0..40 {
            straight.step().unwrap();
        }
        let mut first = Trainer::new(&dataset, head(), train.clone()).unwrap();
        for _ in 0..17 {
            first.step().unwrap();
        }
        let ckpt = dir.join("checkpoint.npz");
        first.save_checkpoint(&ckpt).unwrap();
        let mut resumed = Trainer::resume(
            &dataset,
            head(),
            TrainOptions {
                iterations: 1,
                seed: 0,
                ..train
            },
            &ckpt,
        )
        .unwrap();
        assert_eq!((resumed.iteration(), resumed.iterations()), (17, 40));
        while resumed.iteration() < 40 {
            resumed.step().unwrap();
        }
        assert!(straight.reset_done, "the run covers an opacity reset");
        assert_eq!(resumed.model, straight.model);
        // A damaged checkpoint is refused with its name.
        std::fs::write(&ckpt, b"PK\x03\x04 not really").unwrap();
        let e = Trainer::resume(
            &dataset,
            head(),
            TrainOptions {
                iterations: 1,
                seed: 0,
                size: None,
                background: [0.0; 3],
                renderer: Backend::Cpu,
                holes: HoleFilling::default(),
            },
            &ckpt,
        )
        .err()
        .unwrap()
        .to_string();
        assert!(e.contains("checkpoint.npz"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
