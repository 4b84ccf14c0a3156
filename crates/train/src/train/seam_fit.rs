//! Seam fit (method §7.12): the colour and opacity of a composite's
//! Gaussians near a change of source, fitted to what the sources themselves
//! draw there.
//!
//! Each source draws its own border well: its Gaussians were trained beside
//! each other. A composite puts Gaussians trained beside *other* neighbours
//! side by side, and what they draw where their footprints overlap is
//! neither source's. So the fit renders, per source, the whole head from
//! that source (the recipe's shape, colour and post-processing, every
//! group's Gaussians from it), blends those renders per pixel by the seam
//! weight of the surface point the pixel shows (the cross-fade of
//! [`SeamField`], method §7.8), and fits the composite's seam Gaussians to
//! the blend with Adam — over a rig of its own cameras at the rest pose,
//! never over any ground truth. Positions, scales and rotations stay: the
//! fit changes what a Gaussian shows, not where it sits, so animation and
//! the region membership are untouched.

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::AnimationMode;
use crate::compose::seams::SeamField;
use crate::error::Result;
use crate::model::head::{HeadModel, Joint, Pose};
use crate::model::regions::Group;

use super::adam::AdamGroup;
use super::capture::{rasterize, rig};
use super::holes::Obscurer;
use super::model::{Render, Trainable, SH_STRIDE};
use super::project::TrainCamera;
use super::raster::Rasterizer;

/// Learning rate of the SH DC coefficients (3DGS's feature rate).
const LR_DC: f64 = 0.0025;
/// The higher SH bands move at a twentieth of the DC rate, as in 3DGS.
const REST_FACTOR: f64 = 1.0 / 20.0;
/// Learning rate of the opacity logits (3DGS's).
const LR_OPACITY: f64 = 0.05;
/// The jaw's opening in the rig's second pose, radians.
const OPEN_JAW_RAD: f32 = 0.12;

/// How the fit runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamFit {
    /// Adam steps, one view each, round the rig.
    pub iterations: usize,
    /// Width and height of the rig's images, in pixels.
    pub size: u32,
    /// Cameras of the rig (a frontal arc, as the training rig's).
    pub cameras: usize,
}

impl Default for SeamFit {
    /// What `--pipeline ours` runs: 200 steps over 8 views at 256².
    fn default() -> Self {
        Self {
            iterations: 200,
            size: 256,
            cameras: 8,
        }
    }
}

/// What a fit did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitReport {
    /// Gaussians on a seam (the ones fitted).
    pub fitted: usize,
    /// Views of the rig.
    pub views: usize,
    /// Mean squared error per channel over the head's pixels against the
    /// blended target, over every view, before the fit.
    pub mse_before: f64,
    /// The same after it.
    pub mse_after: f64,
}

/// One view of the rig: what the fit draws the composite with and where it
/// aims.
struct View {
    camera: TrainCamera,
    /// The composite posed for this view.
    posed: std::rc::Rc<PosedMesh>,
    /// Per pixel: the blended target (RGB), meaningful where `head` is set.
    goal: Vec<f64>,
    /// Pixels that show the composite's surface.
    head: Vec<bool>,
}

/// Per triangle: the source its group's Gaussians come from.
fn looks(model: &HeadModel, composite: &Composite) -> Vec<u32> {
    model
        .triangle_regions
        .iter()
        .map(|r| composite.recipe.gaussians[r.group().index()] as u32)
        .collect()
}

/// `set` to draw, with any Gaussian that holds a NaN or an infinity hidden
/// (opacity zero): it is not drawn, and the fit leaves it as it came — a
/// NaN is no value to step from, and a NaN pixel's gradient would reach
/// every Gaussian drawn there.
fn drawable(set: &GaussianSet) -> Trainable {
    let mut out = Trainable::from_set(set);
    let stride = set.sh_stride();
    for i in 0..set.len() {
        let finite = set.position[i].is_finite()
            && set.rotation[i].is_finite()
            && set.log_scale[i].is_finite()
            && set.opacity_logit[i].is_finite()
            && set.sh[i * stride..(i + 1) * stride]
                .iter()
                .all(|x| x.is_finite());
        if !finite {
            out.opacity_logit[i] = f64::NEG_INFINITY;
        }
    }
    out
}

/// The rig's poses: at rest, and with the jaw open by 7° (the built-in
/// `talk` motion opens it up to ~9°) so the lips' inner edges and the teeth
/// they uncover are fitted too.
fn rig_poses() -> [Pose; 2] {
    let mut open = Pose::REST;
    open.joints[Joint::Jaw as usize] = glam::Vec3::new(OPEN_JAW_RAD, 0.0, 0.0);
    [Pose::REST, open]
}

fn posed(engine: &Engine, composite: &Composite, pose: &Pose) -> PosedMesh {
    let mut out = PosedMesh::default();
    let expression = vec![0.0; engine.database().model.expression_basis.len()];
    engine.pose_offset_with(
        composite,
        &expression,
        pose,
        None,
        AnimationMode::Fast,
        &mut out,
    );
    out
}

fn draw(model: &Trainable, posed: &PosedMesh, camera: &TrainCamera) -> Result<Vec<f64>> {
    let render = Render::new(
        model,
        &posed.frames,
        camera,
        [0.0; 3],
        &Obscurer::None,
        &mut Rasterizer::Cpu,
    )?;
    Ok(render.image().to_vec())
}

/// The rig's views with their blended targets: per pixel, the render of the
/// head wholly from the source the surface point wears, cross-faded towards
/// the nearest other source's by the seam weight there.
fn views(
    engine: &Engine,
    composite: &Composite,
    field: &SeamField,
    looks: &[u32],
    options: &SeamFit,
) -> Result<Vec<View>> {
    let model = &engine.database().model;
    // Per source shown: the head wholly from it, as the recipe would make it.
    let wholes: Vec<(Trainable, Composite)> = field
        .sources()
        .iter()
        .map(|&s| {
            let mut recipe = composite.recipe.clone();
            recipe.gaussians = [s as usize; Group::COUNT];
            let whole = engine.compose(&recipe);
            (drawable(&whole.gaussians), whole)
        })
        .collect();
    let (cameras, _) = rig(options.cameras, false, [options.size; 2]);
    let mut out = Vec::new();
    for pose in rig_poses() {
        let posed_composite = std::rc::Rc::new(posed(engine, composite, &pose));
        let posed_wholes: Vec<PosedMesh> = wholes
            .iter()
            .map(|(_, whole)| posed(engine, whole, &pose))
            .collect();
        for camera in &cameras {
            let images: Vec<Vec<f64>> = wholes
                .iter()
                .zip(&posed_wholes)
                .map(|((m, _), p)| draw(m, p, camera))
                .collect::<Result<_>>()?;
            let of = |s: u32| {
                let k = field.sources().binary_search(&s).unwrap_or(0);
                &images[k]
            };
            let hits = rasterize(&posed_composite.vertices, &model.triangles, camera);
            let mut goal = vec![0.0; 3 * hits.len()];
            let mut head = vec![false; hits.len()];
            for (p, hit) in hits.iter().enumerate() {
                let Some((tri, bary, _)) = hit else { continue };
                let own = looks[*tri as usize];
                let (other, w) = field
                    .blend_at(model.triangles[*tri as usize], *bary, own)
                    .map_or((own, 0.0), |b| (b.other, f64::from(b.weight)));
                head[p] = true;
                for c in 0..3 {
                    goal[3 * p + c] = (1.0 - w) * of(own)[3 * p + c] + w * of(other)[3 * p + c];
                }
            }
            out.push(View {
                camera: *camera,
                posed: posed_composite.clone(),
                goal,
                head,
            });
        }
    }
    Ok(out)
}

/// Squared error per channel against a view's target, summed over its head
/// pixels, with ∂(mean)/∂image for `count` pixels over all views.
fn error(image: &[f64], view: &View, count: f64) -> (f64, Vec<f64>) {
    let mut d = vec![0.0; image.len()];
    let mut sum = 0.0;
    for p in (0..view.head.len()).filter(|&p| view.head[p]) {
        for c in 0..3 {
            let e = image[3 * p + c] - view.goal[3 * p + c];
            // A NaN left in a pixel (a NaN target) teaches nothing.
            if e.is_finite() {
                sum += e * e;
                d[3 * p + c] = 2.0 * e / count;
            }
        }
    }
    (sum, d)
}

fn mean_error(model: &Trainable, views: &[View]) -> Result<f64> {
    let (mut sum, mut count) = (0.0, 0usize);
    for view in views {
        sum += error(&draw(model, &view.posed, &view.camera)?, view, 1.0).0;
        count += view.head.iter().filter(|&&h| h).count();
    }
    Ok(sum / (3 * count.max(1)) as f64)
}

/// The composite's Gaussians with those on a seam fitted (see the module
/// documentation); unchanged where the composite shows one source.
/// `progress` hears the steps done: 0 once the targets are drawn, then
/// after each step.
pub fn fit_seams(
    engine: &Engine,
    composite: &Composite,
    options: &SeamFit,
    progress: &mut dyn FnMut(usize),
) -> Result<(GaussianSet, FitReport)> {
    let model = &engine.database().model;
    let looks = looks(model, composite);
    let field = SeamField::new(model, &looks);
    let mut trainable = drawable(&composite.gaussians);
    // Beside another source, and drawable: a hidden Gaussian stays as it came.
    let on_seam: Vec<bool> = composite
        .gaussians
        .binding
        .iter()
        .zip(&trainable.opacity_logit)
        .map(|(&t, &opacity)| {
            let tri = model.triangles[t as usize];
            opacity.is_finite()
                && field
                    .blend_at(tri, [1.0 / 3.0; 3], looks[t as usize])
                    .is_some()
        })
        .collect();
    let fitted = on_seam.iter().filter(|&&s| s).count();
    if fitted == 0 || options.iterations == 0 || options.cameras == 0 {
        return Ok((composite.gaussians.clone(), FitReport::default()));
    }
    let views = views(engine, composite, &field, &looks, options)?;
    let mse_before = mean_error(&trainable, &views)?;
    progress(0);
    let per_view = views
        .iter()
        .map(|v| v.head.iter().filter(|&&h| h).count())
        .sum::<usize>() as f64
        / views.len() as f64;
    let n = trainable.len();
    let mut sh_steps = AdamGroup::new(LR_DC, SH_STRIDE, n);
    let mut opacity_steps = AdamGroup::new(LR_OPACITY, 1, n);
    let mut rasterizer = Rasterizer::Cpu;
    for step in 0..options.iterations {
        let view = &views[step % views.len()];
        let render = Render::new(
            &trainable,
            &view.posed.frames,
            &view.camera,
            [0.0; 3],
            &Obscurer::None,
            &mut rasterizer,
        )?;
        let (_, d_image) = error(render.image(), view, 3.0 * per_view.max(1.0));
        let mut grads = render.backward(&trainable, &d_image, &mut rasterizer)?;
        for (i, &seam) in on_seam.iter().enumerate() {
            let sh = &mut grads.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
            if seam {
                sh[3..].iter_mut().for_each(|g| *g *= REST_FACTOR);
            } else {
                // A zero gradient keeps Adam's moments at zero: no step.
                sh.fill(0.0);
                grads.opacity_logit[i] = 0.0;
            }
        }
        sh_steps.step(&mut trainable.sh, &grads.sh);
        opacity_steps.step(&mut trainable.opacity_logit, &grads.opacity_logit);
        progress(step + 1);
    }
    let mse_after = mean_error(&trainable, &views)?;
    let mut out = composite.gaussians.clone();
    let stride = out.sh_stride();
    for i in (0..n).filter(|&i| on_seam[i]) {
        out.opacity_logit[i] = trainable.opacity_logit[i] as f32;
        for k in 0..stride {
            out.sh[i * stride + k] = trainable.sh[i * SH_STRIDE + k] as f32;
        }
    }
    Ok((
        out,
        FitReport {
            fitted,
            views: views.len(),
            mse_before,
            mse_after,
        },
    ))
}
