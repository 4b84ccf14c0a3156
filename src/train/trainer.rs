//! GaussianAvatars' recipe on the differentiable renderer: one Gaussian per
//! triangle to start; Adam with per-group learning rates and the exponential
//! position schedule; (1 − 0.2)·L1 + 0.2·D-SSIM plus the local-position and
//! local-scale regularisers; SH degree raised on a schedule; densification by
//! the view-space gradient (clone small, split large, children keep their
//! parent's triangle), pruning of transparent and huge Gaussians while every
//! triangle keeps one, and opacity resets. The schedule is GaussianAvatars'
//! compressed (its 600k iterations → `iterations`), so the default capture
//! trains in minutes on two cores. Deterministic for a seed.

use glam::{DVec3, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::adam::AdamGroup;
use super::dataset::{Dataset, View};
use super::holes::{
    interior_layer, obscuring_splat, oriented_box, view_ratios, HoleFilling, Obscurer, OrientedBox,
    TriangleSubset,
};
use super::loss::{photometric_loss, psnr};
use super::model::{Gradients, Render, Trainable, SH_STRIDE};
use super::project::{Geometry, TrainCamera};
use super::raster::Rasterizer;
use crate::avatar::binding::{triangle_frames, TriangleFrame};
use crate::avatar::gaussians::GaussianSet;
use crate::error::{Error, Result};
use crate::io::avatar::{read_flame_params, write_avatar, AvatarParams, FlameParams, FrameParams};
use crate::model::head::HeadModel;
use crate::render::Backend;
use std::collections::BTreeMap;

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

/// Hyperparameters: GaussianAvatars' (`arguments/__init__.py`), with its
/// iteration counts scaled to `iterations`.
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    /// Position learning rate at the start and the end (× scene extent).
    pub position_lr: [f64; 2],
    /// SH DC learning rate (the rest use a twentieth).
    pub feature_lr: f64,
    /// Opacity learning rate.
    pub opacity_lr: f64,
    /// Log-scale learning rate.
    pub scaling_lr: f64,
    /// Rotation learning rate.
    pub rotation_lr: f64,
    /// SH degree up every this many iterations.
    pub sh_interval: usize,
    /// Densify every this many iterations …
    pub densify_interval: usize,
    /// … from this iteration …
    pub densify_from: usize,
    /// … until this one.
    pub densify_until: usize,
    /// Opacity reset every this many iterations.
    pub opacity_reset_interval: usize,
    /// Clone or split above this view-space gradient (NDC units).
    pub densify_grad_threshold: f64,
    /// Clone below / split above this share of the scene extent (world scale).
    pub percent_dense: f64,
    /// Weight of the local-position regulariser and its threshold.
    pub xyz: [f64; 2],
    /// Weight of the local-scale regulariser and its threshold.
    pub scale: [f64; 2],
}

impl Schedule {
    /// GaussianAvatars' schedule compressed to `iterations`.
    pub fn for_iterations(iterations: usize) -> Self {
        let at = |fraction: f64| ((iterations as f64 * fraction).round() as usize).max(1);
        Schedule {
            position_lr: [0.005, 0.00005],
            feature_lr: 0.0025,
            opacity_lr: 0.05,
            scaling_lr: 0.017,
            rotation_lr: 0.001,
            // GaussianAvatars raises it every 1000 of 600k; a short run would
            // never reach degree 3 at that rate, so every 8 %.
            sh_interval: at(0.08),
            densify_interval: at(0.04),
            densify_from: at(0.1),
            densify_until: at(0.8),
            opacity_reset_interval: at(0.3),
            densify_grad_threshold: 0.0002,
            percent_dense: 0.01,
            xyz: [0.01, 1.0],
            scale: [1.0, 0.6],
        }
    }

    /// The position learning rate at `step` (log-linear from start to end).
    pub fn position_lr_at(&self, step: usize, iterations: usize, extent: f64) -> f64 {
        let t = (step as f64 / iterations.max(1) as f64).clamp(0.0, 1.0);
        let [a, b] = self.position_lr.map(|x| (x * extent).ln());
        ((1.0 - t) * a + t * b).exp()
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

/// A view's image at the size it is used at, composited over the background.
pub struct Target {
    /// The view.
    pub view: View,
    /// Its camera, scaled to the image's size.
    pub camera: TrainCamera,
    /// RGB, row-major.
    pub pixels: Vec<f32>,
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

/// Reads an image (and its mask) as a target at `size` (default: as stored).
pub fn load_target(view: &View, size: Option<[u32; 2]>, background: [f64; 3]) -> Result<Target> {
    let image = crate::render::image::RgbImage::load_png(&view.image).map_err(Error::input)?;
    if [image.width, image.height] != view.camera.size {
        return Err(Error::input(format!(
            "{} is {}x{}, its frame says {}x{}",
            view.image.display(),
            image.width,
            image.height,
            view.camera.size[0],
            view.camera.size[1]
        )));
    }
    let mask = match &view.mask {
        Some(path) => Some(
            image::open(path)
                .map_err(|e| Error::input(format!("cannot read mask {}: {e}", path.display())))?
                .to_luma8(),
        ),
        None => None,
    };
    let [w, h] = size.unwrap_or(view.camera.size);
    let (sx, sy) = (
        image.width as f64 / w as f64,
        image.height as f64 / h as f64,
    );
    // Box-filter down (or sample up) to the training size.
    let mut pixels = vec![0.0f32; (w * h * 3) as usize];
    for y in 0..h {
        for x in 0..w {
            let (x0, x1) = (
                (x as f64 * sx) as u32,
                (((x + 1) as f64 * sx).ceil() as u32)
                    .min(image.width)
                    .max((x as f64 * sx) as u32 + 1),
            );
            let (y0, y1) = (
                (y as f64 * sy) as u32,
                (((y + 1) as f64 * sy).ceil() as u32)
                    .min(image.height)
                    .max((y as f64 * sy) as u32 + 1),
            );
            let mut sum = [0.0f64; 3];
            let mut n = 0.0;
            for yy in y0..y1 {
                for xx in x0..x1 {
                    let p = (yy * image.width + xx) as usize;
                    let coverage = mask.as_ref().map_or(1.0, |m| m.as_raw()[p] as f64 / 255.0);
                    for ch in 0..3 {
                        // Images are premultiplied by their mask (black behind).
                        sum[ch] += image.pixels[p * 3 + ch] as f64 / 255.0
                            + (1.0 - coverage) * background[ch];
                    }
                    n += 1.0;
                }
            }
            for ch in 0..3 {
                pixels[((y * w + x) * 3) as usize + ch] = (sum[ch] / n) as f32;
            }
        }
    }
    let mut camera = view.camera;
    camera.size = [w, h];
    camera.focal = [camera.focal[0] / sx, camera.focal[1] / sy];
    camera.principal = [camera.principal[0] / sx, camera.principal[1] / sy];
    Ok(Target {
        view: view.clone(),
        camera,
        pixels,
    })
}

/// The training arc as hole metrics see it: the head posed at the first
/// training timestep and every training camera of that timestep, images
/// scaled to at most `side` pixels.
pub fn training_arc(
    dataset: &Dataset,
    head: &HeadModel,
    side: u32,
) -> Result<(Vec<Vec3>, Vec<TrainCamera>)> {
    let first = dataset
        .train
        .iter()
        .map(|v| v.timestep)
        .min()
        .ok_or_else(|| Error::input(format!("{} has no training views", dataset.root.display())))?;
    let path = dataset
        .flame_params
        .get(&first)
        .ok_or_else(|| Error::input(format!("timestep {first} has no FLAME parameters")))?;
    let posed = posed_vertices(&read_flame_params(path, "dataset", head)?, head);
    let cameras = dataset
        .train
        .iter()
        .filter(|v| v.timestep == first)
        .map(|v| super::hole_metrics::at_most(&v.camera, side))
        .collect();
    Ok((posed, cameras))
}

/// The file in an exported avatar folder that records how it was trained.
pub const TRAINING_METADATA: &str = "training.json";

/// Every timestep the dataset names, posed: vertices per timestep, the
/// identity and the FLAME parameters of each.
#[allow(clippy::type_complexity)]
fn pose_timesteps(
    dataset: &Dataset,
    head: &HeadModel,
) -> Result<(
    BTreeMap<usize, Vec<Vec3>>,
    (Vec<f32>, Vec<glam::DVec3>),
    Vec<FrameParams>,
)> {
    let mut posed = BTreeMap::new();
    let mut identity = None;
    let mut flame_frames = Vec::new();
    for (&t, path) in &dataset.flame_params {
        let params = read_flame_params(path, "dataset", head)?;
        posed.insert(t, posed_vertices(&params, head));
        let (expression, pose) = params.motion.frame(0);
        flame_frames.push(FrameParams {
            expression: expression.to_vec(),
            pose: *pose,
        });
        identity.get_or_insert((params.shape.clone(), params.static_offset.clone()));
    }
    let identity =
        identity.ok_or_else(|| Error::input("the dataset names no FLAME parameter files"))?;
    Ok((posed, identity, flame_frames))
}

/// 1.1 × the largest distance of a training camera from their mean (3DGS's
/// `cameras_extent`, the unit of the position learning rate and the
/// densification sizes).
fn camera_extent(views: &[View]) -> f64 {
    let eyes: Vec<DVec3> = views.iter().map(|v| DVec3::from(v.camera.eye)).collect();
    let mean = eyes.iter().copied().sum::<DVec3>() / eyes.len().max(1) as f64;
    1.1 * eyes
        .iter()
        .map(|e| (*e - mean).length())
        .fold(0.0, f64::max)
        .max(1e-3)
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
        let boxes: BTreeMap<usize, OrientedBox> =
            if options.holes.obscuring || options.holes.interior {
                posed
                    .iter()
                    .filter_map(|(&t, vertices)| Some((t, oriented_box(vertices)?)))
                    .collect()
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
        let targets = dataset
            .train
            .iter()
            .map(|v| load_target(v, options.size, options.background))
            .collect::<Result<Vec<_>>>()?;
        let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
        let n = subset.len();
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
        let schedule = Schedule::for_iterations(options.iterations);
        let extent = camera_extent(&dataset.train);
        let groups = Groups {
            position: AdamGroup::new(schedule.position_lr[0] * extent, 3, n),
            scale: AdamGroup::new(schedule.scaling_lr, 3, n),
            rotation: AdamGroup::new(schedule.rotation_lr, 4, n),
            opacity: AdamGroup::new(schedule.opacity_lr, 1, n),
            dc: AdamGroup::new(schedule.feature_lr, 3, n),
            rest: AdamGroup::new(schedule.feature_lr / 20.0, SH_STRIDE - 3, n),
        };
        let rasterizer = Rasterizer::open(options.renderer)?;
        Ok(Self {
            rasterizer,
            subset,
            boxes,
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
        let render = Render::new(
            &self.model,
            frames,
            &target.camera,
            self.options.background,
            &obscurer,
            &mut self.rasterizer,
        )?;
        let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
        let [w, h] = target.camera.size;
        let (loss, d_image) = photometric_loss(render.image(), &goal, w as usize, h as usize, true);
        let report = StepReport {
            iteration: it,
            loss: loss.total,
            psnr: psnr(render.image(), &goal),
            gaussians: self.model.len(),
        };
        let mut grads = render.backward(&self.model, &d_image, &mut self.rasterizer)?;
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

    fn track_densification(&mut self, render: &Render, grads: &Gradients, size: [u32; 2]) {
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

    fn apply(&mut self, grads: &Gradients) {
        let n = self.model.len();
        let gather = |f: &dyn Fn(&Geometry) -> Vec<f64>| -> Vec<f64> {
            self.model.geometry.iter().flat_map(f).collect()
        };
        let grad_of = |range: std::ops::Range<usize>| -> Vec<f64> {
            grads
                .geometry
                .iter()
                .flat_map(|g| g[range.clone()].to_vec())
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

    /// World scale of Gaussian `i` (its largest axis), on the first timestep.
    fn world_scale(&self, i: usize) -> f64 {
        let frames = self.frames.values().next().expect("a timestep");
        let face = frames[self.model.binding[i] as usize].scale as f64;
        let s = self.model.geometry[i].log_scale;
        s[0].max(s[1]).max(s[2]).exp() * face
    }

    fn densify_and_prune(&mut self) {
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

    fn reset_opacity(&mut self) {
        let cap = logit(0.01);
        for o in &mut self.model.opacity_logit {
            *o = o.min(cap);
        }
        let n = self.model.len();
        self.groups.opacity.reset_values(0..n);
        self.reset_done = true;
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

    /// Writes the avatar as a GaussianAvatars folder: the Gaussians and the
    /// dataset's identity and per-timestep FLAME parameters (its motion).
    pub fn export(&self, dir: &std::path::Path) -> Result<()> {
        let (shape, offset) = &self.identity;
        write_avatar(
            dir,
            &self.gaussians(),
            &AvatarParams {
                shape,
                static_offset: offset,
                frames: &self.flame_frames,
            },
            &self.head,
        )?;
        self.write_metadata(&dir.join(TRAINING_METADATA))
    }

    /// Records how the avatar was trained (`training.json` beside it).
    fn write_metadata(&self, path: &std::path::Path) -> Result<()> {
        let (kept, full) = self.triangles_kept();
        let doc = serde_json::json!({
            "trained_by": "visage train",
            "iterations": self.step,
            "seed": self.options.seed,
            "obscuring": self.options.holes.obscuring && !self.options.holes.interior,
            "interior_layer": self.options.holes.interior,
            "cull_backfaces": self.options.holes.cull_below,
            "triangles_trained": kept,
            "triangles": full,
            "gaussians": self.model.len(),
        });
        let text = serde_json::to_string_pretty(&doc).expect("JSON values serialise");
        std::fs::write(path, text + "\n").map_err(|e| Error::io("write", path, e))
    }

    /// Writes everything a resumed run needs to continue exactly where this
    /// one is: parameters, optimiser moments, densification statistics, the
    /// view order and the random generator's position. An `.npz` (numpy can
    /// read it), written to a temporary name and renamed, so a crash while
    /// writing leaves the previous checkpoint.
    pub fn save_checkpoint(&mut self, path: &std::path::Path) -> Result<()> {
        use crate::io::npy::{write_npy, NpyData};
        let m = &self.model;
        let n = m.len();
        let geometry: Vec<f64> = m
            .geometry
            .iter()
            .flat_map(|g| g.position.into_iter().chain(g.log_scale).chain(g.rotation))
            .collect();
        let word = self.rng.get_word_pos();
        let words =
            |x: u128, k: usize| -> Vec<u32> { (0..k).map(|i| (x >> (32 * i)) as u32).collect() };
        let order: Vec<u32> = self.order.iter().map(|&o| o as u32).collect();
        let scalars = [
            self.step as f64,
            self.options.iterations as f64,
            m.sh_degree as f64,
            self.reset_done as u8 as f64,
            self.targets.len() as f64,
        ];
        let mut arrays: Vec<(String, Vec<u8>)> = vec![
            ("binding".into(), write_npy(&[n], NpyData::U32(&m.binding))),
            (
                "geometry".into(),
                write_npy(&[n, 10], NpyData::F64(&geometry)),
            ),
            (
                "opacity_logit".into(),
                write_npy(&[n], NpyData::F64(&m.opacity_logit)),
            ),
            ("sh".into(), write_npy(&[n, SH_STRIDE], NpyData::F64(&m.sh))),
            (
                "grad_accum".into(),
                write_npy(&[n], NpyData::F64(&self.grad_accum)),
            ),
            (
                "grad_count".into(),
                write_npy(&[n], NpyData::U32(&self.grad_count)),
            ),
            (
                "max_radius".into(),
                write_npy(&[n], NpyData::F64(&self.max_radius)),
            ),
            (
                "order".into(),
                write_npy(&[order.len()], NpyData::U32(&order)),
            ),
            (
                "rng_word".into(),
                write_npy(&[4], NpyData::U32(&words(word, 4))),
            ),
            (
                "seed".into(),
                write_npy(&[2], NpyData::U32(&words(self.options.seed as u128, 2))),
            ),
            (
                "scalars".into(),
                write_npy(&[scalars.len()], NpyData::F64(&scalars)),
            ),
            (
                "triangles_kept".into(),
                write_npy(&[self.subset.len()], NpyData::U32(&self.subset.kept)),
            ),
        ];
        for (name, group) in Groups::NAMES.iter().zip(self.groups.all()) {
            let (mm, vv, t) = group.state();
            arrays.push((
                format!("adam_{name}_m"),
                write_npy(&[mm.len()], NpyData::F64(mm)),
            ));
            arrays.push((
                format!("adam_{name}_v"),
                write_npy(&[vv.len()], NpyData::F64(vv)),
            ));
            arrays.push((
                format!("adam_{name}_t"),
                write_npy(&[1], NpyData::I32(&[t])),
            ));
        }
        let named: Vec<(&str, Vec<u8>)> = arrays
            .iter()
            .map(|(k, v)| (k.as_str(), v.clone()))
            .collect();
        let partial = path.with_extension("npz.partial");
        crate::io::npy::write_npz(&partial, &named, false)?;
        std::fs::rename(&partial, path).map_err(|e| Error::io("write", path, e))
    }

    /// A trainer continuing from a checkpoint of a run on the same dataset
    /// (its seed and iteration count are the checkpoint's).
    pub fn resume(
        dataset: &Dataset,
        head: HeadModel,
        options: TrainOptions,
        path: &std::path::Path,
    ) -> Result<Self> {
        let arrays = crate::io::npy::read_npz(path)?;
        let label = |e: String| Error::input(format!("{}: {e}", path.display()));
        let get = |k: &str| -> Result<Vec<f64>> {
            arrays
                .get(k)
                .map(|a| a.data.clone())
                .ok_or_else(|| label(format!("not a visage checkpoint (no '{k}')")))
        };
        let scalars = get("scalars")?;
        let seed_words = get("seed")?;
        if scalars.len() != 5 || seed_words.len() != 2 {
            return Err(label("not a visage checkpoint (bad scalars)".into()));
        }
        let seed = seed_words[0] as u64 | (seed_words[1] as u64) << 32;
        let options = TrainOptions {
            iterations: scalars[1] as usize,
            seed,
            ..options
        };
        let mut trainer = Trainer::new(dataset, head, options)?;
        if scalars[4] as usize != trainer.targets.len() {
            return Err(label(format!(
                "was made on a dataset of {} training views, this one has {}",
                scalars[4],
                trainer.targets.len()
            )));
        }
        let binding: Vec<u32> = get("binding")?.iter().map(|&b| b as u32).collect();
        let n = binding.len();
        let kept: Vec<u32> = get("triangles_kept")?.iter().map(|&t| t as u32).collect();
        if kept != trainer.subset.kept {
            return Err(label(format!(
                "trained on {} triangles, this run keeps {}: give the same --cull-backfaces",
                kept.len(),
                trainer.subset.len()
            )));
        }
        let triangles = trainer.subset.len();
        let geometry = get("geometry")?;
        let sh = get("sh")?;
        let opacity = get("opacity_logit")?;
        let sizes_fit = geometry.len() == n * 10
            && sh.len() == n * SH_STRIDE
            && opacity.len() == n
            && binding.iter().all(|&b| (b as usize) < triangles)
            && geometry
                .iter()
                .chain(&sh)
                .chain(&opacity)
                .all(|x| x.is_finite());
        if !sizes_fit {
            return Err(label(
                "parameters do not fit together or this head model (or are not finite)".into(),
            ));
        }
        trainer.model = Trainable {
            binding,
            geometry: geometry
                .chunks(10)
                .map(|c| Geometry {
                    position: [c[0], c[1], c[2]],
                    log_scale: [c[3], c[4], c[5]],
                    rotation: [c[6], c[7], c[8], c[9]],
                })
                .collect(),
            opacity_logit: opacity,
            sh,
            sh_degree: (scalars[2] as u8).min(3),
        };
        trainer.step = scalars[0] as usize;
        trainer.reset_done = scalars[3] != 0.0;
        trainer.grad_accum = get("grad_accum")?;
        trainer.grad_count = get("grad_count")?.iter().map(|&c| c as u32).collect();
        trainer.max_radius = get("max_radius")?;
        trainer.order = get("order")?.iter().map(|&o| o as usize).collect();
        if trainer.order.iter().any(|&o| o >= trainer.targets.len())
            || [
                trainer.grad_accum.len(),
                trainer.grad_count.len(),
                trainer.max_radius.len(),
            ]
            .iter()
            .any(|&l| l != n)
        {
            return Err(label(
                "training statistics do not fit the parameters".into(),
            ));
        }
        let word = get("rng_word")?
            .iter()
            .enumerate()
            .fold(0u128, |acc, (i, &w)| acc | (w as u128) << (32 * i));
        trainer.rng.set_word_pos(word);
        for (name, group) in Groups::NAMES.iter().zip(trainer.groups.all()) {
            let t = get(&format!("adam_{name}_t"))?;
            group
                .restore(
                    get(&format!("adam_{name}_m"))?,
                    get(&format!("adam_{name}_v"))?,
                    t.first().copied().unwrap_or(0.0) as i32,
                    n,
                )
                .map_err(label)?;
        }
        Ok(trainer)
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

/// A standard normal sample (Box–Muller).
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u: f64 = rng.random::<f64>().max(1e-12);
    let v: f64 = rng.random();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Renders `model` for a target and returns the image with its PSNR and
/// SSIM against the target.
pub fn evaluate_view(
    model: &Trainable,
    frames: &[TriangleFrame],
    target: &Target,
    background: [f64; 3],
) -> (Vec<f64>, f64, f64) {
    let render = Render::new(
        model,
        frames,
        &target.camera,
        background,
        &Obscurer::None,
        &mut Rasterizer::Cpu,
    )
    .expect("the CPU rasteriser does not fail");
    let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
    let [w, h] = target.camera.size;
    let (loss, _) = photometric_loss(render.image(), &goal, w as usize, h as usize, false);
    let quality = psnr(render.image(), &goal);
    (render.image().to_vec(), quality, loss.ssim)
}

/// The posed vertices of one timestep's FLAME parameters.
fn posed_vertices(params: &FlameParams, head: &HeadModel) -> Vec<Vec3> {
    let (expression, pose) = params.motion.frame(0);
    head.forward(&params.shape, Some(&params.static_offset), expression, pose)
}

/// The triangle frames of one timestep's FLAME parameters.
fn pose(params: &FlameParams, head: &HeadModel) -> Vec<TriangleFrame> {
    triangle_frames(&posed_vertices(params, head), &head.triangles)
}

/// Triangle frames for every timestep `views` show, each read and posed once.
pub fn timestep_frames(
    dataset: &Dataset,
    head: &HeadModel,
    views: &[View],
) -> Result<std::collections::BTreeMap<usize, Vec<TriangleFrame>>> {
    let mut frames = std::collections::BTreeMap::new();
    for view in views {
        if frames.contains_key(&view.timestep) {
            continue;
        }
        let path = dataset.flame_params.get(&view.timestep).ok_or_else(|| {
            Error::input(format!(
                "timestep {} has no FLAME parameters",
                view.timestep
            ))
        })?;
        let params = read_flame_params(path, "dataset", head)?;
        frames.insert(view.timestep, pose(&params, head));
    }
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::capture::{capture, CaptureOptions};

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
