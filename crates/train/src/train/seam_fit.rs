//! Seam fit (method §7.12): the colour, opacity and reach of a composite's
//! Gaussians near a change of source (and, where the recipe relights, of
//! those whose light the shape moved), fitted to what the sources
//! themselves draw there.
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
//! light the shape moved are fitted too (`seam_light`); away from the
//! seams, each person's part of a whole is then read from a drawing on
//! that person's own face, where its Gaussians were trained
//! (`seam_own_shape`). Positions and rotations stay, and scales
//! move only a little: the fit changes what a Gaussian shows and how far it
//! reaches, not where it sits, so animation and the region membership are
//! untouched.

use std::sync::Arc;

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{AnimationMode, SkinSource};
use crate::compose::seams::{SeamBlend, SeamField, SeamNeighbours};
use crate::error::Result;
use crate::model::head::{HeadModel, Joint, Pose};
use crate::model::regions::Group;
use crate::render::Backend;

use super::adam::AdamGroup;
use super::capture::{rasterize, rig};
use super::holes::Obscurer;
use super::model::{Render, Trainable, SH_STRIDE};
use super::project::{TrainCamera, GEOMETRY};
use super::raster::Rasterizer;
use super::seam_base_detail::{takes_base_detail, with_base_detail};
use super::seam_light::{self, PixelLight};
use super::seam_own_shape::{self as own_shape, Hit};
use super::seam_wholes::{blended, drawable, wholes, Drawn, Whole, Wholes};

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
    /// Gaussians fitted: those on a seam, and those whose triangle's light
    /// the composite's shape moved.
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

/// A whole drawn in one view: as the recipe makes it, and across a seam with
/// its source's own skin where there is such a whole (`Wholes`).
type DrawnWhole = (Vec<f64>, Option<Vec<f64>>);

/// A seam fit in progress, one unit of work at a time, so that a caller
/// that must stay responsive (the editor's render worker) can interleave it
/// with other work, see how far it is, and drop it when the composite
/// changes. The units: compose each source's whole head (twice for a
/// swapped source under `skin = "base"`, [`wholes`], and each again with
/// the trained light where the recipe relights, and on its people's own
/// faces where the shape changed them), pose the rig's two poses (and each
/// such person's own face in them), draw each whole in each view (and,
/// with a view's last, blend its target and measure the composite there),
/// take each Adam step, and measure each view again. [`fit_seams`] runs them all.
///
/// Each call takes the engine and the composite the fitter was made for;
/// the fitter keeps only what it computed from them.
pub struct SeamFitter {
    options: SeamFit,
    looks: Vec<u32>,
    /// Under `skin = "base"`, the base (its database index) when the
    /// composite shows it: the whole whose skin detail the targets take
    /// where a swapped source shows skin alike (`seam_base_detail`).
    base_detail_from: Option<u32>,
    field: SeamField,
    /// How near each point is to another source's hair ([`hair_looks`]).
    hair_field: SeamField,
    /// Per Gaussian: whether the fit moves it — near a seam, or (where the
    /// recipe relights) on a triangle whose light the shape moved.
    moves: Vec<bool>,
    fitted: usize,
    trainable: Trainable,
    wholes: Vec<Wholes>,
    /// Made with the wholes when the targets are relit per pixel.
    light: Option<PixelLight>,
    /// The wholes drawn so far in the view whose target is being drawn.
    drawn: Vec<DrawnWhole>,
    /// The composite posed at each of the rig's poses: the wholes too, as
    /// they share its shape ([`wholes`]).
    posed: Vec<Arc<PosedMesh>>,
    /// Per rig pose: each person whose face the composite's shape changed,
    /// on their own face, posed alike (`seam_own_shape`).
    own_posed: Vec<Vec<(usize, PosedMesh)>>,
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
        // Where the targets are relit per pixel, the Gaussians whose light
        // the shape moved too, wherever they are.
        let moves: Vec<bool> = if seam_light::relights(composite) {
            seam_light::light_moved(engine, composite)
                .iter()
                .zip(&trainable.opacity_logit)
                .map(|(&moved, opacity)| moved && opacity.is_finite())
                .zip(on_seam)
                .map(|(light, seam)| light || seam)
                .collect()
        } else {
            on_seam
        };
        let fitted = moves.iter().filter(|&&m| m).count();
        let (cameras, _) = rig(options.cameras, false, [options.size; 2]);
        let n = trainable.len();
        let base = composite.recipe.base as u32;
        let base_detail_from = (composite.recipe.post.skin == SkinSource::Base
            && field.sources().contains(&base))
        .then_some(base);
        SeamFitter {
            options: *options,
            looks,
            base_detail_from,
            field,
            hair_field,
            moves,
            fitted,
            trainable,
            wholes: Vec::new(),
            light: None,
            drawn: Vec::new(),
            posed: Vec::new(),
            own_posed: Vec::new(),
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
        let sources = self.field.sources().len();
        sources + rig_poses().len() + (sources + 1) * self.view_count() + self.options.iterations
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
            let mut drawn: Vec<usize> = self.wholes.iter().flat_map(Wholes::sources).collect();
            drawn.sort_unstable();
            drawn.dedup();
            if unit == sources && seam_light::relights(composite) {
                self.light = Some(PixelLight::new(engine, composite, &drawn));
            }
            let pose = rig_poses()[unit - sources];
            self.posed.push(Arc::new(posed(engine, composite, &pose)));
            let own_faces = self.wholes.iter().any(Wholes::own_faces);
            self.own_posed.push(
                drawn
                    .into_iter()
                    .filter(|&s| own_faces && own_shape::reshaped(engine, composite, s))
                    .map(|s| (s, own_shape::posed_own_face(engine, s, &pose)))
                    .collect(),
            );
        } else if unit < sources + poses + sources * views {
            // One whole of one view a unit: a view's target draws each
            // whole several times over, too long for one unit of an editor
            // that must answer a key.
            let (k, j) = (
                (unit - sources - poses) / sources,
                (unit - sources - poses) % sources,
            );
            let model = &engine.database().model;
            let drawn = self.draw_whole(model, k, j)?;
            self.drawn.push(drawn);
            if j + 1 < sources {
                self.done += 1;
                return Ok(());
            }
            let drawn = std::mem::take(&mut self.drawn);
            let view = self.target(model, k, drawn);
            let rasterizer = self.rasterizer.as_mut().expect("opened above");
            let measured = measure(&self.trainable, &view, rasterizer)?;
            self.before = add(self.before, measured);
            self.views.push(view);
            if self.views.len() == views {
                // The targets are drawn: the wholes are no longer needed.
                self.wholes = Vec::new();
                self.posed = Vec::new();
                self.own_posed = Vec::new();
                self.light = None;
            }
        } else if unit < sources + poses + sources * views + self.options.iterations {
            self.adam_step(unit - sources - poses - sources * views)?;
        } else {
            let view =
                &self.views[unit - sources - poses - sources * views - self.options.iterations];
            let rasterizer = self.rasterizer.as_mut().expect("opened above");
            self.after = add(self.after, measure(&self.trainable, view, rasterizer)?);
        }
        self.done += 1;
        Ok(())
    }

    /// View `k` of the rig with its blended target, from the fit's wholes
    /// as drawn there (`drawn`, in the order of the fit's sources): per
    /// pixel, the whole from the source the surface point wears, cross-faded
    /// towards the nearest other source's (with that source's own skin as
    /// far as `seam_wholes::trust` allows, [`wholes`]) by the seam weight
    /// there; then, on a swapped source's skin, moved towards the base's
    /// whole where the two show the same skin (`seam_base_detail`).
    fn target(&self, model: &HeadModel, k: usize, drawn: Vec<DrawnWhole>) -> View {
        let rig = &self.posed[k / self.cameras.len()];
        let camera = &self.cameras[k % self.cameras.len()];
        let hits = rasterize(&rig.vertices, &model.triangles, camera);
        let images: Vec<Drawn> = drawn
            .into_iter()
            .zip(&self.wholes)
            .map(|((own, across), whole)| Drawn {
                own,
                across: across.zip(whole.across.as_ref().map(|a| &a.trust)),
            })
            .collect();
        let of = |s: u32| &images[self.field.sources().binary_search(&s).unwrap_or(0)];
        let mut goal = vec![0.0; 3 * hits.len()];
        let mut head = vec![false; hits.len()];
        // Where the target may take the base's skin detail.
        let mut base_detail = vec![false; hits.len()];
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
            base_detail[p] = takes_base_detail(self.base_detail_from, own, region);
            head[p] = true;
            for (c, goal) in goal[3 * p..3 * p + 3].iter_mut().enumerate() {
                *goal = blended(of(own), of(other), w, 3 * p + c, region);
            }
        }
        if let Some(base) = self.base_detail_from {
            with_base_detail(
                &mut goal,
                &of(base).own,
                &base_detail,
                camera.size[0] as usize,
            );
        }
        View {
            camera: *camera,
            posed: rig.clone(),
            goal,
            head,
        }
    }

    /// Whole `j` of the fit's sources drawn in view `k` as the target asks
    /// for it: as the recipe makes it, and across a seam with the source's
    /// own skin (`Wholes`); each relit pixel by pixel where the recipe
    /// relights (`seam_light::relit_target`), its people's parts read, away
    /// from the seams, from drawings on their own faces (`seam_own_shape`).
    fn draw_whole(&mut self, model: &HeadModel, k: usize, j: usize) -> Result<DrawnWhole> {
        let rig = &self.posed[k / self.cameras.len()];
        let camera = &self.cameras[k % self.cameras.len()];
        let rasterizer = self.rasterizer.as_mut().expect("opened by step");
        let hits = rasterize(&rig.vertices, &model.triangles, camera);
        // Away from every seam: there a whole's drawing holds the other
        // source's overhang, which no own face's drawing has.
        let inside: Vec<Hit> = hits
            .iter()
            .map(|hit| {
                hit.filter(|(tri, bary, _)| {
                    let t = *tri as usize;
                    let corners = model.triangles[t];
                    self.field.blend_at(corners, *bary, self.looks[t]).is_none()
                })
            })
            .collect();
        let own_faces: Vec<(usize, &PosedMesh, Vec<Hit>)> = self.own_posed[k / self.cameras.len()]
            .iter()
            .map(|(s, face)| {
                (
                    *s,
                    face,
                    rasterize(&face.vertices, &model.triangles, camera),
                )
            })
            .collect();
        let light = self.light.as_ref();
        let source = self.field.sources()[j] as usize;
        let lit = |whole: &Whole, rasterizer: &mut Rasterizer| -> Result<Vec<f64>> {
            let relit = draw(&whole.drawable, rig, camera, rasterizer)?;
            let Some(light) = light else {
                return Ok(relit);
            };
            let Some(kept) = &whole.kept else {
                return Ok(relit);
            };
            let part = |s: usize, rasterizer: &mut Rasterizer| -> Result<own_shape::Part> {
                let image = draw(&kept.part(s), rig, camera, rasterizer)?;
                let own = own_faces.iter().find(|(person, _, _)| *person == s);
                let (Some(own_face), Some((_, face, own_hits))) = (&whole.own_face, own) else {
                    return Ok(own_shape::Part {
                        person: s,
                        colour: image,
                        coverage: None,
                    });
                };
                let there = own_shape::Drawing {
                    colour: draw(&own_face.part(s), face, camera, rasterizer)?,
                    coverage: draw(&own_face.coverage(s), face, camera, rasterizer)?,
                };
                let here = own_shape::Drawing {
                    colour: image,
                    coverage: draw(&kept.coverage(s), rig, camera, rasterizer)?,
                };
                Ok(own_shape::Part {
                    person: s,
                    colour: own_shape::reprojected(
                        model,
                        camera,
                        &inside,
                        &face.vertices,
                        own_hits,
                        &there,
                        &here,
                    ),
                    coverage: Some(here.coverage),
                })
            };
            let mut parts = kept
                .sources()
                .iter()
                .map(|&s| part(s, rasterizer))
                .collect::<Result<Vec<_>>>()?;
            // At every eyeball pixel: near a seam too the base's lids hang
            // over it (dark-base-light-eyes +0.011 dB over `inside` alone).
            own_shape::eyeballs_by_their_source(model, &hits, source, &mut parts);
            Ok(seam_light::relit_target(
                model, light, &hits, &relit, &parts,
            ))
        };
        let whole = &self.wholes[j];
        let across = match &whole.across {
            Some(a) => Some(lit(&a.whole, rasterizer)?),
            None => None,
        };
        Ok((lit(&whole.own, rasterizer)?, across))
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
        for (i, &moves) in self.moves.iter().enumerate() {
            let sh = &mut grads.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
            if moves {
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

    /// An Adam step on the fitted Gaussians' log scales (the geometry
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
            .zip(&self.moves)
            .flat_map(|(g, &moves)| if moves { [g[3], g[4], g[5]] } else { [0.0; 3] })
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
        for i in (0..out.len()).filter(|&i| self.moves[i]) {
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
    use crate::model::regions::Region;
    use crate::train::seam_test_people::swap;

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
    fn targets_take_the_bases_detail_only_under_its_skin_where_it_is_shown() {
        let fitter = |groups: &[&str], skin| {
            let (engine, composite) = swap(groups, skin);
            SeamFitter::new(&engine, &composite, &SeamFit::default()).base_detail_from
        };
        assert_eq!(fitter(&["mouth"], SkinSource::Base), Some(0));
        // The thesis's meaning: the source's own skin is what is asked for.
        assert_eq!(fitter(&["mouth"], SkinSource::Source), None);
        // Every group swapped: the base is shown nowhere, so no whole of it.
        let all: Vec<&str> = Group::ALL.iter().map(|g| g.name()).collect();
        assert_eq!(fitter(&all, SkinSource::Base), None);
    }

    #[test]
    fn a_swapped_sources_skin_like_the_bases_takes_the_bases_pixels_in_a_target() {
        // Source 1's eyes (or hair) on source 0. Each whole drawn as one flat colour:
        // the base's B, source 1's 1 % lighter (the same skin up to detail)
        // or 20 % darker (a feature over every window).
        let base = [0.6, 0.5, 0.4];
        let target = |groups: &[&str], skin, scale: f64| {
            let (engine, composite) = swap(groups, skin);
            let options = SeamFit {
                size: 48,
                cameras: 1,
                ..SeamFit::default()
            };
            let mut fitter = SeamFitter::new(&engine, &composite, &options);
            // Compose the wholes and pose the rig.
            for _ in 0..fitter.field.sources().len() + rig_poses().len() {
                fitter.step(&engine, &composite).unwrap();
            }
            let pixels = (options.size * options.size) as usize;
            let flat = |rgb: [f64; 3]| -> DrawnWhole { (rgb.repeat(pixels), None) };
            let drawn = vec![flat(base), flat(base.map(|c| c * scale))];
            let model = &engine.database().model;
            let view = fitter.target(model, 0, drawn);
            let hits = rasterize(
                &fitter.posed[0].vertices,
                &model.triangles,
                &fitter.cameras[0],
            );
            // Per pixel on source 1's points: its region, the goal and
            // whether a seam cross-fades it.
            let swapped: Vec<(Region, [f64; 3], bool)> = hits
                .iter()
                .enumerate()
                .filter_map(|(p, hit)| {
                    let (t, bary, _) = (*hit)?;
                    let t = t as usize;
                    (fitter.looks[t] == 1).then(|| {
                        let g = &view.goal[3 * p..3 * p + 3];
                        let region = model.triangle_regions[t];
                        let (_, w) = cross_fade(
                            fitter.field.blend_at(model.triangles[t], bary, 1),
                            fitter
                                .hair_field
                                .blend_at(model.triangles[t], bary, NOT_HAIR),
                            1,
                            region.group() == Group::Hair,
                        );
                        (region, [g[0], g[1], g[2]], w > 0.0)
                    })
                })
                .collect();
            assert!(!swapped.is_empty());
            swapped
        };
        let eye_region = |r: &Region| matches!(r, Region::LeftEyeRegion | Region::RightEyeRegion);
        let takes_base = |pixels: &[(Region, [f64; 3], bool)]| {
            pixels
                .iter()
                .filter(|(r, g, _)| eye_region(r) && *g == base)
                .count()
        };
        let alike = target(&["eyes"], SkinSource::Base, 1.01);
        assert!(
            takes_base(&alike) > 0,
            "no eye-region pixel took the base's"
        );
        // Cross-faded towards the base's whole or not, alike skin is the
        // base's.
        assert!(alike.iter().any(|(r, _, faded)| eye_region(r) && *faded));
        assert!(alike
            .iter()
            .filter(|(r, _, _)| eye_region(r))
            .all(|(_, g, _)| *g == base));
        let eyeball = base.map(|c| c * 1.01);
        assert!(alike
            .iter()
            .filter(|(r, _, _)| matches!(r, Region::LeftEyeball | Region::RightEyeball))
            .all(|(_, g, _)| *g == eyeball));
        // A feature, or the thesis's skin: the base's pixel nowhere.
        assert_eq!(takes_base(&target(&["eyes"], SkinSource::Base, 0.8)), 0);
        assert_eq!(takes_base(&target(&["eyes"], SkinSource::Source, 1.01)), 0);
        // A swapped hair group: the bare remainder beside the hair takes the
        // base's skin, the hair stays the source's.
        let hair = target(&["hair"], SkinSource::Base, 1.01);
        let in_region = |r: Region| hair.iter().filter(move |(q, _, _)| *q == r);
        assert!(in_region(Region::Remainder).count() > 0);
        assert!(in_region(Region::Remainder).all(|(_, g, _)| *g == base));
        assert!(in_region(Region::Hair).count() > 0);
        assert!(in_region(Region::Hair).all(|(_, g, _)| *g != base));
    }
}
