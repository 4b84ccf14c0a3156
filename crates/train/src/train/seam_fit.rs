//! Seam fit (method §7.12): the colour and opacity of a composite's
//! Gaussians near a change of source, fitted to what the sources themselves
//! draw there.
//!
//! Each source draws its own border well: its Gaussians were trained beside
//! each other. A composite puts Gaussians trained beside *other* neighbours
//! side by side, and what they draw where their footprints overlap is
//! neither source's. So the fit renders, per source, the whole head from
//! that source (the recipe's shape, colour and post-processing, every
//! group's Gaussians from it; across a seam, partly with the source's own
//! skin where the recipe puts the base's skin under its features), blends
//! those renders per pixel by the seam
//! weight of the surface point the pixel shows (the cross-fade of
//! [`SeamField`], method §7.8), and fits the composite's seam Gaussians to
//! the blend with Adam — over a rig of its own cameras at the rest pose,
//! never over any ground truth. Where the recipe relights its Gaussians,
//! the wholes are relit pixel by pixel instead, and the Gaussians whose
//! light the shape moved are fitted too, in their DC colour alone
//! (`seam_light`). Positions and rotations stay, and scales
//! move only a little: the fit changes what a Gaussian shows and how far it
//! reaches, not where it sits, so animation and the region membership are
//! untouched.

use std::sync::Arc;

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{AnimationMode, Shading, SkinSource};
use crate::compose::seams::{SeamBlend, SeamField, SeamNeighbours};
use crate::error::Result;
use crate::model::head::{HeadModel, Joint, Pose};
use crate::model::regions::{Group, Region};
use crate::render::Backend;

use super::adam::AdamGroup;
use super::capture::{rasterize, rig};
use super::holes::Obscurer;
use super::model::{Render, Trainable, SH_STRIDE};
use super::project::{TrainCamera, GEOMETRY};
use super::raster::Rasterizer;
use super::seam_light::{self, KeptWhole, PixelLight};

/// Learning rate of the SH DC coefficients (3DGS's feature rate).
const LR_DC: f64 = 0.0025;
/// The higher SH bands move at a twentieth of the DC rate, as in 3DGS.
const REST_FACTOR: f64 = 1.0 / 20.0;
/// Learning rate of the opacity logits (3DGS's).
const LR_OPACITY: f64 = 0.05;
/// Learning rate of the log scales: three times 3DGS's 0.005, which gained
/// two thirds as much (method §7.12).
const LR_SCALE: f64 = 0.015;
/// Rings of triangles round those within the seam field whose Gaussians are
/// fitted too: a Gaussian a triangle or two away still reaches into the seam.
const SEAM_RINGS: usize = 2;
/// The jaw's opening in the rig's second pose, radians.
const OPEN_JAW_RAD: f32 = 0.12;
/// The look of a triangle outside the hair group in [`hair_looks`]: no
/// source's index.
const NOT_HAIR: u32 = u32::MAX - 1;

/// How the fit runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamFit {
    /// Adam steps, one view each, round the rig.
    pub iterations: usize,
    /// Width and height of the rig's images, in pixels.
    pub size: u32,
    /// Cameras of the rig (a frontal arc, as the training rig's).
    pub cameras: usize,
    /// What draws the fit's views: `cpu` (f64, the default: the same bits on
    /// every machine, and on a 16-core GPU server as fast as its GPU), `auto`
    /// a hardware GPU when there is one and the CPU otherwise, `gpu` any
    /// wgpu adapter (f32), a software one included.
    pub renderer: Backend,
}

impl Default for SeamFit {
    /// What `--pipeline ours` runs: 200 steps over 8 views at 256², on the
    /// CPU.
    fn default() -> Self {
        Self {
            iterations: 200,
            size: 256,
            cameras: 8,
            renderer: Backend::Cpu,
        }
    }
}

/// What a fit did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FitReport {
    /// Gaussians fitted: those on a seam, and (in their DC colour alone)
    /// those whose triangle's light the composite's shape moved.
    pub fitted: usize,
    /// Views of the rig.
    pub views: usize,
    /// Mean squared error per channel over the head's pixels against the
    /// blended target, over every view, before the fit.
    pub mse_before: f64,
    /// The same after it.
    pub mse_after: f64,
    /// Whether the views were drawn on a GPU (wgpu, f32) rather than the
    /// CPU (f64).
    pub on_gpu: bool,
}

/// One view of the rig: what the fit draws the composite with and where it
/// aims.
struct View {
    camera: TrainCamera,
    /// The composite posed for this view.
    posed: Arc<PosedMesh>,
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

/// Per triangle: the source of its hair where it is in the hair group,
/// [`NOT_HAIR`] elsewhere — the looks whose [`SeamField`] says how near a
/// point is to another source's hair.
fn hair_looks(model: &HeadModel, looks: &[u32]) -> Vec<u32> {
    model
        .triangle_regions
        .iter()
        .zip(looks)
        .map(|(r, &look)| {
            if r.group() == Group::Hair {
                look
            } else {
                NOT_HAIR
            }
        })
        .collect()
}

/// The source the target cross-fades towards at a point wearing `own`, and
/// how far: the seam field's nearest other source and weight (`seam`, §7.8),
/// less, on a triangle outside the hair group, the part of it that
/// source's hair accounts for (`hair`, from the field of [`hair_looks`]).
/// A hair seam borders hair on skin: on the skin side the other person
/// shows skin too, which the truth gives the base's tone, so blending in
/// their transferred skin brings only the transfer's errors (and their own
/// hair's overhang, which the composite's hair Gaussians already draw).
fn cross_fade(
    seam: Option<SeamBlend>,
    hair: Option<SeamBlend>,
    own: u32,
    in_hair_group: bool,
) -> (u32, f64) {
    let Some(seam) = seam else {
        return (own, 0.0);
    };
    let hair_part = match hair {
        Some(h) if !in_hair_group && h.other == seam.other => f64::from(h.weight),
        _ => 0.0,
    };
    (seam.other, (f64::from(seam.weight) - hair_part).max(0.0))
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

fn draw(
    model: &Trainable,
    posed: &PosedMesh,
    camera: &TrainCamera,
    rasterizer: &mut Rasterizer,
) -> Result<Vec<f64>> {
    let render = Render::new(
        model,
        &posed.frames,
        camera,
        [0.0; 3],
        &Obscurer::None,
        rasterizer,
    )?;
    Ok(render.image().to_vec())
}

/// Squared error of `model` as it is against `view`, and its head pixels.
fn measure(model: &Trainable, view: &View, rasterizer: &mut Rasterizer) -> Result<(f64, usize)> {
    let image = draw(model, &view.posed, &view.camera, rasterizer)?;
    let pixels = view.head.iter().filter(|&&h| h).count();
    Ok((error(&image, view, 1.0).0, pixels))
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

/// Per triangle: whether its Gaussians are fitted — its centre lies within
/// the seam field of another source, or it is within [`SEAM_RINGS`] rings of
/// one that does.
fn near_seams(model: &HeadModel, field: &SeamField, looks: &[u32]) -> Vec<bool> {
    let mut near: Vec<bool> = model
        .triangles
        .iter()
        .zip(looks)
        .map(|(&tri, &own)| field.blend_at(tri, [1.0 / 3.0; 3], own).is_some())
        .collect();
    for _ in 0..SEAM_RINGS {
        let mut touched = vec![false; model.vertex_count()];
        for (tri, _) in model.triangles.iter().zip(&near).filter(|(_, &n)| n) {
            tri.iter().for_each(|&v| touched[v as usize] = true);
        }
        for (tri, n) in model.triangles.iter().zip(near.iter_mut()) {
            *n |= tri.iter().any(|&v| touched[v as usize]);
        }
    }
    near
}

/// A whole head from one source, as the recipe would make it, ready to draw.
struct Whole {
    drawable: Trainable,
    composite: Composite,
    /// When the fit relights its targets per pixel (`seam_light`): the
    /// same whole with the light its Gaussians were trained under.
    kept: Option<KeptWhole>,
}

/// A source's whole head as each side of a seam asks for it.
struct Wholes {
    /// As the recipe makes it: what the composite's Gaussians of this
    /// source draw, the target on the source's own side of a seam.
    own: Whole,
    /// With the source's own skin under its features, for the target's
    /// far side where this source is the other one; `None` where that is
    /// `own` (the recipe keeps the sources' skin, or this is the base).
    across: Option<Across>,
}

impl Wholes {
    /// The sources whose Gaussians these wholes hold.
    fn sources(&self) -> impl Iterator<Item = usize> + '_ {
        let across = self.across.iter().map(|a| &a.whole);
        std::iter::once(&self.own)
            .chain(across)
            .flat_map(|w| w.kept.iter().flat_map(|k| k.sources().iter().copied()))
    }
}

/// A source's whole head with its own skin, and how far the far side of a
/// seam may trust it.
struct Across {
    /// The recipe's whole head from the source, with `skin = "source"`.
    whole: Whole,
    /// Per region, the share of the far side taken from `whole` ([`trust`]).
    trust: [f64; Region::COUNT],
}

/// The share of a seam's far side taken from the other source's own skin
/// rather than from the base's skin under its features, in a region whose
/// colour transfer scaled the source's colours by `gain` (the region's mean
/// per-channel gain): 1/g, g the largest channel of `gain`, and all of it
/// where the transfer does not brighten. A gain multiplies whatever the
/// source's training got wrong (method §13.3), so mixing its skin in at a
/// share of 1/g keeps those errors at the size they had on the source; a
/// gain that is not finite trusts none of it.
fn trust(gain: glam::Vec3) -> f64 {
    if !gain.is_finite() {
        return 0.0;
    }
    let g = f64::from(gain.max_element());
    if g <= 1.0 {
        1.0
    } else {
        1.0 / g
    }
}

/// A source's whole head drawn in one view, each way [`Wholes`] holds it.
struct Drawn<'a> {
    /// [`Wholes::own`] drawn: RGB per pixel.
    own: Vec<f64>,
    /// [`Wholes::across`] drawn, with its trust per region.
    across: Option<(Vec<f64>, &'a [f64; Region::COUNT])>,
}

impl Drawn<'_> {
    /// Channel `i` of the far side of a seam at a point of region `region`:
    /// the source's own skin by its [`trust`] there, the rest as `own`.
    fn far(&self, i: usize, region: Region) -> f64 {
        match &self.across {
            Some((across, trust)) => {
                let a = trust[region.index()];
                (1.0 - a) * self.own[i] + a * across[i]
            }
            None => self.own[i],
        }
    }
}

/// Channel `i` of the target at a point of region `region` that wears the
/// source drawn as `own`, at seam weight `w` towards the source drawn as
/// `other`: the own side as the recipe makes it, the far side with the
/// other source's own skin as far as it is trusted ([`Drawn::far`]).
fn blended(own: &Drawn, other: &Drawn, w: f64, i: usize, region: Region) -> f64 {
    (1.0 - w) * own.own[i] + w * other.far(i, region)
}

/// Source `source`'s whole head: the recipe with every group's Gaussians
/// from it, and, where the recipe puts the base's skin under a swapped
/// region's features (`skin = "base"`, method §7.11), the same with the
/// source's own skin too. The far side of a seam shows that source's look
/// on the base's tone — its stubble as the source's Gaussians carry it,
/// moved by the colour transfer; the base's skin in their place (what
/// `skin = "base"` gives a head wholly swapped, wherever the likeness
/// reads light stubble as skin) drops the stubble a bearded source's mouth
/// trails into the base's face.
fn wholes(engine: &Engine, composite: &Composite, source: u32) -> Wholes {
    let mut recipe = composite.recipe.clone();
    recipe.gaussians = [source as usize; Group::COUNT];
    let whole = |recipe: &_| {
        let composite = engine.compose(recipe);
        let kept = seam_light::relights(&composite).then(|| {
            let mut kept = recipe.clone();
            kept.post.shading = Shading::Kept;
            let kept = engine.compose(&kept);
            KeptWhole::new(&kept, drawable(&kept.gaussians))
        });
        Whole {
            drawable: drawable(&composite.gaussians),
            composite,
            kept,
        }
    };
    let own = whole(&recipe);
    // The shape is the recipe's, whichever source's Gaussians it wears:
    // every whole is posed as the composite is.
    debug_assert_eq!(own.composite.neutral, composite.neutral);
    let across =
        (recipe.post.skin == SkinSource::Base && source as usize != recipe.base).then(|| {
            recipe.post.skin = SkinSource::Source;
            let whole = whole(&recipe);
            let trust = whole.composite.colour_gains.map(trust);
            Across { whole, trust }
        });
    Wholes { own, across }
}

/// A seam fit in progress, one unit of work at a time, so that a caller
/// that must stay responsive (the editor's render worker) can interleave it
/// with other work, see how far it is, and drop it when the composite
/// changes. The units: compose each source's whole head (twice for a
/// swapped source under `skin = "base"`, [`wholes`], and each again with
/// the trained light where the recipe relights), pose the rig's two
/// poses, draw each view's target (and measure the composite there), take
/// each Adam step, and measure each view again. [`fit_seams`] runs them all.
///
/// Each call takes the engine and the composite the fitter was made for;
/// the fitter keeps only what it computed from them.
pub struct SeamFitter {
    options: SeamFit,
    looks: Vec<u32>,
    field: SeamField,
    /// How near each point is to another source's hair ([`hair_looks`]).
    hair_field: SeamField,
    on_seam: Vec<bool>,
    fitted: usize,
    trainable: Trainable,
    wholes: Vec<Wholes>,
    /// Per Gaussian: fitted in its DC colour alone, for the light on its
    /// triangle (`seam_light::light_moved`) rather than for a seam.
    light_only: Vec<bool>,
    /// Made with the wholes when the targets are relit per pixel.
    light: Option<PixelLight>,
    /// The composite posed at each of the rig's poses: the wholes too, as
    /// they share its shape ([`wholes`]).
    posed: Vec<Arc<PosedMesh>>,
    cameras: Vec<TrainCamera>,
    views: Vec<View>,
    sh_steps: AdamGroup,
    opacity_steps: AdamGroup,
    scale_steps: AdamGroup,
    /// Opened at the first unit of work (opening a GPU can fail, and takes
    /// a moment a caller making a fitter should not wait for).
    rasterizer: Option<Rasterizer>,
    /// Squared error and pixels over the views, before and after.
    before: (f64, usize),
    after: (f64, usize),
    done: usize,
}

impl SeamFitter {
    /// A fit of `composite`'s seams; nothing is drawn yet.
    pub fn new(engine: &Engine, composite: &Composite, options: &SeamFit) -> SeamFitter {
        let model = &engine.database().model;
        let looks = looks(model, composite);
        let neighbours = SeamNeighbours::new(&model.template);
        let field = SeamField::with_neighbours(model, &neighbours, &looks);
        let hair_field = SeamField::with_neighbours(model, &neighbours, &hair_looks(model, &looks));
        let trainable = drawable(&composite.gaussians);
        let near = near_seams(model, &field, &looks);
        // Near a seam, and drawable: a hidden Gaussian stays as it came.
        let on_seam: Vec<bool> = composite
            .gaussians
            .binding
            .iter()
            .zip(&trainable.opacity_logit)
            .map(|(&t, &opacity)| opacity.is_finite() && near[t as usize])
            .collect();
        // Away from seams, where the targets are relit per pixel: the
        // Gaussians whose light changed, in their DC colour.
        let light_only: Vec<bool> = if seam_light::relights(composite) {
            seam_light::light_moved(engine, composite)
                .iter()
                .zip(&on_seam)
                .zip(&trainable.opacity_logit)
                .map(|((&moved, &seam), opacity)| moved && !seam && opacity.is_finite())
                .collect()
        } else {
            vec![false; on_seam.len()]
        };
        let fitted = on_seam
            .iter()
            .zip(&light_only)
            .filter(|&(&seam, &light)| seam || light)
            .count();
        let (cameras, _) = rig(options.cameras, false, [options.size; 2]);
        let n = trainable.len();
        SeamFitter {
            options: *options,
            looks,
            field,
            hair_field,
            on_seam,
            fitted,
            trainable,
            wholes: Vec::new(),
            light_only,
            light: None,
            posed: Vec::new(),
            cameras,
            views: Vec::new(),
            sh_steps: AdamGroup::new(LR_DC, SH_STRIDE, n),
            opacity_steps: AdamGroup::new(LR_OPACITY, 1, n),
            scale_steps: AdamGroup::new(LR_SCALE, 3, n),
            rasterizer: None,
            before: (0.0, 0),
            after: (0.0, 0),
            done: 0,
        }
    }

    /// Nothing to fit: no Gaussian on a seam or under moved light, no steps
    /// or no cameras.
    fn idle(&self) -> bool {
        self.fitted == 0 || self.options.iterations == 0 || self.options.cameras == 0
    }

    fn view_count(&self) -> usize {
        rig_poses().len() * self.cameras.len()
    }

    /// Units of work in all.
    pub fn total(&self) -> usize {
        if self.idle() {
            return 0;
        }
        self.field.sources().len()
            + rig_poses().len()
            + 2 * self.view_count()
            + self.options.iterations
    }

    /// Units of work done.
    pub fn done(&self) -> usize {
        self.done
    }

    /// Every unit done.
    pub fn finished(&self) -> bool {
        self.done >= self.total()
    }

    /// Does the next unit of work (nothing once finished).
    pub fn step(&mut self, engine: &Engine, composite: &Composite) -> Result<()> {
        if self.finished() {
            return Ok(());
        }
        let sources = self.field.sources().len();
        let poses = rig_poses().len();
        let views = self.view_count();
        let unit = self.done;
        if self.rasterizer.is_none() {
            self.rasterizer = Some(Rasterizer::open(self.options.renderer)?);
        }
        if unit < sources {
            self.wholes
                .push(wholes(engine, composite, self.field.sources()[unit]));
        } else if unit < sources + poses {
            if unit == sources && seam_light::relights(composite) {
                let mut drawn: Vec<usize> = self.wholes.iter().flat_map(Wholes::sources).collect();
                drawn.sort_unstable();
                drawn.dedup();
                self.light = Some(PixelLight::new(engine, composite, &drawn));
            }
            let pose = rig_poses()[unit - sources];
            self.posed.push(Arc::new(posed(engine, composite, &pose)));
        } else if unit < sources + poses + views {
            let view = self.target(&engine.database().model, unit - sources - poses)?;
            let rasterizer = self.rasterizer.as_mut().expect("opened above");
            let measured = measure(&self.trainable, &view, rasterizer)?;
            self.before = add(self.before, measured);
            self.views.push(view);
            if self.views.len() == views {
                // The targets are drawn: the wholes are no longer needed.
                self.wholes = Vec::new();
                self.posed = Vec::new();
                self.light = None;
            }
        } else if unit < sources + poses + views + self.options.iterations {
            self.adam_step(unit - sources - poses - views)?;
        } else {
            let view = &self.views[unit - sources - poses - views - self.options.iterations];
            let rasterizer = self.rasterizer.as_mut().expect("opened above");
            self.after = add(self.after, measure(&self.trainable, view, rasterizer)?);
        }
        self.done += 1;
        Ok(())
    }

    /// View `k` of the rig with its blended target: per pixel, the render of
    /// the head wholly from the source the surface point wears, cross-faded
    /// towards the nearest other source's (with that source's own skin as
    /// far as [`trust`] allows, [`wholes`]) by the seam weight there; each
    /// whole relit pixel by pixel where the recipe relights
    /// (`seam_light::relit_target`).
    fn target(&mut self, model: &HeadModel, k: usize) -> Result<View> {
        let rig = &self.posed[k / self.cameras.len()];
        let camera = &self.cameras[k % self.cameras.len()];
        let rasterizer = self.rasterizer.as_mut().expect("opened by step");
        let mut images = Vec::with_capacity(self.wholes.len());
        let hits = rasterize(&rig.vertices, &model.triangles, camera);
        let light = self.light.as_ref();
        let lit = |whole: &Whole, rasterizer: &mut Rasterizer| -> Result<Vec<f64>> {
            let relit = draw(&whole.drawable, rig, camera, rasterizer)?;
            let Some(light) = light else {
                return Ok(relit);
            };
            let Some(kept) = &whole.kept else {
                return Ok(relit);
            };
            let parts = kept
                .sources()
                .iter()
                .map(|&s| Ok((s, draw(&kept.part(s), rig, camera, rasterizer)?)))
                .collect::<Result<Vec<_>>>()?;
            Ok(seam_light::relit_target(
                model, light, &hits, &relit, &parts,
            ))
        };
        for whole in &self.wholes {
            let across = match &whole.across {
                Some(a) => Some((lit(&a.whole, rasterizer)?, &a.trust)),
                None => None,
            };
            let own = lit(&whole.own, rasterizer)?;
            images.push(Drawn { own, across });
        }
        let of = |s: u32| &images[self.field.sources().binary_search(&s).unwrap_or(0)];
        let mut goal = vec![0.0; 3 * hits.len()];
        let mut head = vec![false; hits.len()];
        for (p, hit) in hits.iter().enumerate() {
            let Some((tri, bary, _)) = hit else { continue };
            let t = *tri as usize;
            let own = self.looks[t];
            let corners = model.triangles[t];
            let region = model.triangle_regions[t];
            let (other, w) = cross_fade(
                self.field.blend_at(corners, *bary, own),
                self.hair_field.blend_at(corners, *bary, NOT_HAIR),
                own,
                region.group() == Group::Hair,
            );
            head[p] = true;
            for (c, goal) in goal[3 * p..3 * p + 3].iter_mut().enumerate() {
                *goal = blended(of(own), of(other), w, 3 * p + c, region);
            }
        }
        Ok(View {
            camera: *camera,
            posed: rig.clone(),
            goal,
            head,
        })
    }

    /// Adam step `k`, on view `k` round the rig.
    fn adam_step(&mut self, k: usize) -> Result<()> {
        let view = &self.views[k % self.views.len()];
        let per_view = self.before.1 as f64 / self.views.len() as f64;
        let rasterizer = self.rasterizer.as_mut().expect("opened by step");
        let render = Render::new(
            &self.trainable,
            &view.posed.frames,
            &view.camera,
            [0.0; 3],
            &Obscurer::None,
            rasterizer,
        )?;
        let (_, d_image) = error(render.image(), view, 3.0 * per_view.max(1.0));
        let mut grads = render.backward(&self.trainable, &d_image, rasterizer)?;
        for (i, &seam) in self.on_seam.iter().enumerate() {
            let sh = &mut grads.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
            if self.light_only[i] {
                sh[3..].fill(0.0);
                grads.opacity_logit[i] = 0.0;
            } else if seam {
                sh[3..].iter_mut().for_each(|g| *g *= REST_FACTOR);
            } else {
                // A zero gradient keeps Adam's moments at zero: no step.
                sh.fill(0.0);
                grads.opacity_logit[i] = 0.0;
            }
        }
        self.sh_steps.step(&mut self.trainable.sh, &grads.sh);
        self.opacity_steps
            .step(&mut self.trainable.opacity_logit, &grads.opacity_logit);
        self.step_scales(&grads.geometry);
        Ok(())
    }

    /// An Adam step on the seam Gaussians' log scales (the geometry
    /// gradient's entries 3-5); every other Gaussian's gradient is zero.
    fn step_scales(&mut self, geometry: &[[f64; GEOMETRY]]) {
        let mut scales: Vec<f64> = self
            .trainable
            .geometry
            .iter()
            .flat_map(|g| g.log_scale)
            .collect();
        let grads: Vec<f64> = geometry
            .iter()
            .zip(&self.on_seam)
            .flat_map(|(g, &seam)| if seam { [g[3], g[4], g[5]] } else { [0.0; 3] })
            .collect();
        self.scale_steps.step(&mut scales, &grads);
        for (g, s) in self
            .trainable
            .geometry
            .iter_mut()
            .zip(scales.chunks_exact(3))
        {
            g.log_scale = [s[0], s[1], s[2]];
        }
    }

    /// `composite`'s Gaussians with those fitted (on a seam, or under moved
    /// light) as fitted so far, and what the fit did (the error after is
    /// over the views measured again so far: complete once
    /// [`SeamFitter::finished`]).
    pub fn result(&self, composite: &Composite) -> (GaussianSet, FitReport) {
        if self.idle() {
            return (composite.gaussians.clone(), FitReport::default());
        }
        let mut out = composite.gaussians.clone();
        let stride = out.sh_stride();
        for i in (0..out.len()).filter(|&i| self.on_seam[i] || self.light_only[i]) {
            out.opacity_logit[i] = self.trainable.opacity_logit[i] as f32;
            out.log_scale[i] =
                glam::DVec3::from_array(self.trainable.geometry[i].log_scale).as_vec3();
            for k in 0..stride {
                out.sh[i * stride + k] = self.trainable.sh[i * SH_STRIDE + k] as f32;
            }
        }
        let mean = |(sum, pixels): (f64, usize)| sum / (3 * pixels.max(1)) as f64;
        (
            out,
            FitReport {
                fitted: self.fitted,
                views: self.views.len(),
                mse_before: mean(self.before),
                mse_after: mean(self.after),
                on_gpu: matches!(self.rasterizer, Some(Rasterizer::Gpu(_))),
            },
        )
    }
}

fn add(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    (a.0 + b.0, a.1 + b.1)
}

/// The composite's Gaussians with those on a seam fitted, and those whose
/// light the shape moved where the recipe relights (see the module
/// documentation); unchanged where the composite shows one source on its
/// own shape.
/// `progress` hears the units of work done and their total after each
/// (see [`SeamFitter`]).
pub fn fit_seams(
    engine: &Engine,
    composite: &Composite,
    options: &SeamFit,
    progress: &mut dyn FnMut(usize, usize),
) -> Result<(GaussianSet, FitReport)> {
    let mut fitter = SeamFitter::new(engine, composite, options);
    while !fitter.finished() {
        fitter.step(engine, composite)?;
        progress(fitter.done(), fitter.total());
    }
    Ok(fitter.result(composite))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blend(other: u32, weight: f32) -> Option<SeamBlend> {
        Some(SeamBlend { other, weight })
    }

    #[test]
    fn the_skin_side_of_a_hair_seam_keeps_its_own_source() {
        // Away from every seam: the point's own source alone.
        assert_eq!(cross_fade(None, None, 3, false), (3, 0.0));
        // Skin beside source 5's hair, nothing of 5 nearer than its hair.
        assert_eq!(cross_fade(blend(5, 0.4), blend(5, 0.4), 3, false), (5, 0.0));
        // The hair side of the same seam cross-fades as before.
        assert_eq!(
            cross_fade(blend(3, 0.4), blend(5, 0.1), 5, true),
            (3, f64::from(0.4f32))
        );
        // Another source's skin nearer than its hair: only the hair's part goes.
        let (other, w) = cross_fade(blend(5, 0.45), blend(5, 0.15), 3, false);
        assert_eq!(other, 5);
        assert!((w - 0.3).abs() < 1e-6, "{w}");
        // Hair of someone else than the nearest other source: no change.
        assert_eq!(
            cross_fade(blend(5, 0.4), blend(6, 0.4), 3, false),
            (5, f64::from(0.4f32))
        );
        // Never below zero.
        assert_eq!(cross_fade(blend(5, 0.2), blend(5, 0.3), 3, false), (5, 0.0));
    }

    #[test]
    fn a_source_s_skin_is_trusted_across_a_seam_at_the_inverse_of_its_gain() {
        use glam::Vec3;
        // Unmoved or darkened: its errors grow no larger, all of it.
        assert_eq!(trust(Vec3::ONE), 1.0);
        assert_eq!(trust(Vec3::new(0.4, 0.6, 0.9)), 1.0);
        // Brightened: the largest channel's gain decides.
        assert_eq!(trust(Vec3::new(1.5, 4.0, 2.0)), 0.25);
        assert!((trust(Vec3::splat(1.25)) - 0.8).abs() < 1e-12);
        // A gain of nothing sensible: none of it.
        assert_eq!(trust(Vec3::new(f32::NAN, 1.0, 1.0)), 0.0);
        assert_eq!(trust(Vec3::new(1.0, f32::INFINITY, 1.0)), 0.0);
    }

    #[test]
    fn the_far_side_mixes_in_the_other_source_s_own_skin_by_region() {
        let mut trusted = [1.0; Region::COUNT];
        trusted[Region::Nose.index()] = 0.25;
        let plain = |v: f64| Drawn {
            own: vec![v; 3],
            across: None,
        };
        let base = plain(0.2);
        let swapped = Drawn {
            own: vec![0.4; 3],
            across: Some((vec![0.8; 3], &trusted)),
        };
        let near = |a: f64, b: f64| (a - b).abs() < 1e-12;
        // No far-side whole: the plain cross-fade of the two.
        assert!(near(blended(&swapped, &base, 0.5, 1, Region::Nose), 0.3));
        // The swapped source's own skin on the far side, by the region's trust.
        assert!(near(swapped.far(2, Region::Nose), 0.5));
        assert!(near(swapped.far(2, Region::Skin), 0.8));
        assert!(near(blended(&base, &swapped, 0.5, 0, Region::Nose), 0.35));
        // Its own side is as the recipe makes it, and w = 0 is the own side alone.
        assert!(near(blended(&swapped, &base, 0.0, 0, Region::Skin), 0.4));
        assert!(near(blended(&base, &swapped, 0.0, 0, Region::Skin), 0.2));
    }

    /// The sources of a whole's Gaussians, block by block.
    fn sources(whole: &Whole) -> Vec<usize> {
        let mut sources: Vec<usize> = whole.composite.blocks.iter().map(|b| b.source).collect();
        sources.sort_unstable();
        sources.dedup();
        sources
    }

    #[test]
    fn across_a_seam_a_source_shows_its_own_skin() {
        use crate::avatar::synthetic::{builtin_database, SyntheticOptions};
        use crate::compose::recipe::{PostProcess, Recipe};
        use crate::model::builtin::build_head;

        let options = SyntheticOptions {
            seed: 5,
            sources: 2,
            gaussians_per_avatar: 3_000,
        };
        let engine = Engine::new(builtin_database(build_head(), options).unwrap()).unwrap();
        let names: Vec<String> = engine
            .database()
            .sources
            .iter()
            .map(|s| s.name.clone())
            .collect();
        let text = format!(
            "base = \"{}\"\n[groups.mouth]\ngaussians = \"{}\"\nshape = {{ {} = 1.0 }}\n",
            names[0], names[1], names[1]
        );
        let mut recipe = Recipe::from_toml(&text).unwrap();
        recipe.post = PostProcess::BEST;
        assert_eq!(recipe.post.skin, SkinSource::Base);
        let composite = engine.compose(&recipe.resolve(engine.database()).unwrap());

        // The swapped source's whole as the recipe makes it has the base's
        // skin under its features; across a seam it is the source alone.
        let swapped = wholes(&engine, &composite, 1);
        assert_eq!(sources(&swapped.own), [0, 1]);
        let across = swapped.across.expect("the recipe puts the base's skin in");
        assert_eq!(sources(&across.whole), [1]);
        assert_eq!(
            across.whole.composite.neutral,
            swapped.own.composite.neutral
        );
        let gains = across.whole.composite.colour_gains;
        for (trusted, gain) in across.trust.iter().zip(gains) {
            assert_eq!(*trusted, trust(gain));
        }
        // The base is lighter than this source somewhere: not all trusted.
        assert!(across.trust.iter().any(|&t| t < 1.0), "{gains:?}");

        // The base's whole, and any whole where the recipe keeps the
        // sources' skin, is the same on both sides: drawn once.
        assert!(wholes(&engine, &composite, 0).across.is_none());
        recipe.post.skin = SkinSource::Source;
        let composite = engine.compose(&recipe.resolve(engine.database()).unwrap());
        let swapped = wholes(&engine, &composite, 1);
        assert!(swapped.across.is_none());
        assert_eq!(sources(&swapped.own), [1]);
    }
}
