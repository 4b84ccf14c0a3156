//! How good is a composite? A composite of built-in people, built from
//! separately trained sources, against its ground truth (`capture --recipe`,
//! method §13): masked PSNR, SSIM and CIE76 ΔE over the head, per split, view
//! and group; the border band (pixels near a change of source) against the
//! interior; leak (the share of a pixel's colour from Gaussians of a source
//! other than the one assigned there, by rendering one-hot source colours);
//! the ceiling (each source's own trained avatar against its own ground truth
//! at the same views); and the decomposition swap → +shape → +smoothing →
//! +colour.
//!
//! Five files: `pixels.rs` says what each pixel of a view shows, `tally.rs`
//! sums the errors view by view into a [`CompositeReport`] (`report.rs`
//! holds its types and the sums they are made from), `arrays.rs` writes a
//! view's pictures and labels for `--arrays`, and this one builds the
//! composites and walks the views.

pub mod arrays;
mod pixels;
mod report;
mod tally;

use std::collections::BTreeMap;

use glam::Vec3;

use super::capture::{visible_triangles, Surface};
use super::dataset::{Dataset, View};
use super::holes::Obscurer;
use super::loss::ssim_map;
use super::model::{Render, Trainable, SH_STRIDE};
use super::posing::{posed_vertices, timestep_params};
use super::project::TrainCamera;
use super::raster::Rasterizer;
use super::seam_fit::{fit_seams, SeamFit};
use super::sitter::Sitter;
use super::target::load_target;
use crate::avatar::database::Database;
use crate::avatar::synthetic::look_index;
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{
    AnimationMode, ColourCorrection, Fit, PostProcess, Recipe, ResolvedRecipe, SkinSource,
    Smoothing,
};
use crate::error::{Error, Result};
use crate::model::head::{HeadModel, Joint, Pose};
use pixels::{assigned_sources, labels, picture, read_mask, shown_regions};
pub use pixels::{band, is_skin};
pub use report::{
    BandBeside, CompositeReport, FitRun, GroupQuality, Leak, Pictures, Quality, RegionQuality,
    SourceCeiling, Step, ViewQuality, OPEN_MOUTH_DEG,
};
use tally::{SourceView, Tally, ViewSums};

/// What to measure.
#[derive(Clone, Debug)]
pub struct EvalOptions {
    /// Pixels within this many of a change of source are the border band.
    pub border_px: u32,
    /// Views drawn for the picture (ground truth, composite, error), at most.
    pub picture_views: usize,
    /// Fit the composite's seams (method §7.12) after the recipe: a fifth
    /// step of the decomposition, "+seam fit", and the composite measured.
    pub fit: Option<SeamFit>,
    /// A folder to write each view's pictures and labels into, one numpy
    /// `.npz` a view (`arrays.rs` lists what each holds).
    pub arrays: Option<std::path::PathBuf>,
}

/// Checks that `dataset` is the ground truth of `recipe` (its base as it is,
/// for an unedited recipe), both resolved against `trained`.
pub fn check_dataset(dataset: &Dataset, recipe: &ResolvedRecipe, trained: &Database) -> Result<()> {
    let name = |i: usize| trained.sources[i].name.clone();
    match &dataset.composite {
        Some(note) => {
            let text = note["recipe"].as_str().unwrap_or_default();
            let theirs = Recipe::from_toml(text)
                .and_then(|r| r.resolve(trained))
                .map_err(|e| {
                    Error::input(format!("{}: its recipe: {e}", dataset.root.display()))
                })?;
            let same = theirs.base == recipe.base
                && theirs.gaussians == recipe.gaussians
                && theirs
                    .shape
                    .iter()
                    .zip(&recipe.shape)
                    .all(|(a, b)| a.iter().zip(b).all(|(x, y)| (x - y).abs() < 1e-9));
            if same {
                Ok(())
            } else {
                Err(Error::input(format!(
                    "{} is the ground truth of another recipe (base {}); capture this one with visage capture --recipe",
                    dataset.root.display(),
                    name(theirs.base)
                )))
            }
        }
        None => {
            let source = dataset.builtin_source.as_deref().ok_or_else(|| {
                Error::input(format!(
                    "{} was not captured from the built-in people: there is no ground truth to compare with",
                    dataset.root.display()
                ))
            })?;
            if super::sitter::is_unedited(recipe) && name(recipe.base) == source {
                Ok(())
            } else {
                Err(Error::input(format!(
                    "{} is the ground truth of {source} unedited, not of this recipe; capture it with visage capture --recipe",
                    dataset.root.display()
                )))
            }
        }
    }
}

/// The four steps of the decomposition, as recipes.
fn steps(recipe: &Recipe) -> Vec<(&'static str, Recipe)> {
    let mut swap = recipe.clone();
    for edit in swap.groups.values_mut() {
        edit.shape = BTreeMap::from([(recipe.base.clone(), 1.0)]);
    }
    swap.post = PostProcess {
        smoothing: Smoothing::Off,
        colour: ColourCorrection::Off,
        membership: recipe.post.membership,
        // How Gaussians follow the blended shape belongs to the +shape step.
        deform: recipe.post.deform,
        anchor: recipe.post.anchor,
        shading: recipe.post.shading,
        // The base's skin is part of matching skin, the +colour step.
        skin: SkinSource::Source,
        // The seam fit is the decomposition's fifth step, not part of these.
        fit: Fit::Off,
    };
    let mut shape = recipe.clone();
    shape.post = swap.post;
    let mut smoothing = recipe.clone();
    smoothing.post.colour = ColourCorrection::Off;
    smoothing.post.skin = SkinSource::Source;
    vec![
        ("swap", swap),
        ("+shape", shape),
        ("+smoothing", smoothing),
        ("+colour", recipe.clone()),
    ]
}

/// Per timestep: the expression and pose, and the ground-truth posed mesh.
struct Timestep {
    expression: Vec<f32>,
    pose: Pose,
    /// The timestep's vertex offsets (`dynamic_offset`; empty: none).
    offset: Vec<Vec3>,
    truth: Vec<Vec3>,
}

fn timesteps(
    dataset: &Dataset,
    model: &HeadModel,
    views: &[&View],
) -> Result<BTreeMap<usize, Timestep>> {
    let mut out = BTreeMap::new();
    for view in views {
        if out.contains_key(&view.timestep) {
            continue;
        }
        let params = timestep_params(dataset, model, view.timestep)?;
        let truth = posed_vertices(&params, model);
        let (expression, pose) = params.motion.frame(0);
        out.insert(
            view.timestep,
            Timestep {
                expression: expression.to_vec(),
                pose: *pose,
                offset: params.motion.frame_offset(0).unwrap_or_default().to_vec(),
                truth,
            },
        );
    }
    Ok(out)
}

fn render(
    model: &Trainable,
    frames: &[crate::avatar::binding::TriangleFrame],
    camera: &TrainCamera,
) -> Vec<f64> {
    Render::new(
        model,
        frames,
        camera,
        [0.0; 3],
        &Obscurer::None,
        &mut Rasterizer::Cpu,
    )
    .expect("the CPU rasteriser does not fail")
    .image()
    .to_vec()
}

/// The composite posed at a timestep, as the composer animates it.
fn posed(engine: &Engine, composite: &Composite, t: &Timestep) -> PosedMesh {
    let mut out = PosedMesh::default();
    let offset = (!t.offset.is_empty()).then_some(t.offset.as_slice());
    let mode = AnimationMode::Fast;
    engine.pose_offset_with(composite, &t.expression, &t.pose, offset, mode, &mut out);
    out
}

/// The composite's Gaussians selected for `source` (all, for `None`) white
/// and the others black: rendered on black, a pixel's value is the share of
/// its colour that `source` gives. A region's own Gaussians count for the
/// source the region shows — the base's skin under `skin = "base"` (method
/// §7.11) is selected for it — and border extras for the source they come
/// from: a leak is colour selected for another region.
fn one_hot(model: &Trainable, composite: &Composite, source: Option<usize>) -> Trainable {
    let mut out = model.clone();
    let c0 = crate::render::sh::C0;
    for block in &composite.blocks {
        let selected_for = match block.extra_from {
            None => composite.recipe.gaussians[block.region.group().index()],
            Some(_) => block.source,
        };
        let white = source.is_none_or(|s| selected_for == s);
        let value = if white { 0.5 / c0 } else { -0.5 / c0 };
        for i in block.start..block.end {
            let sh = &mut out.sh[i * SH_STRIDE..(i + 1) * SH_STRIDE];
            sh.fill(0.0);
            sh[..3].fill(value);
        }
    }
    out.sh_degree = 0;
    out
}

/// The composites of the decomposition (swap, +shape, +smoothing, +colour),
/// the full recipe last.
pub fn decomposition(engine: &Engine, recipe: &Recipe) -> Result<Vec<(&'static str, Composite)>> {
    steps(recipe)
        .into_iter()
        .map(|(name, r)| Ok((name, engine.compose(&r.resolve(engine.database())?))))
        .collect()
}

/// `composite` with its seams fitted (method §7.12), and how the fit ran.
pub fn seam_fitted(
    engine: &Engine,
    composite: &Composite,
    fit: &SeamFit,
) -> Result<(Composite, FitRun)> {
    let start = std::time::Instant::now();
    let (gaussians, report) = fit_seams(engine, composite, fit, &mut |_, _| {})?;
    let mut fitted = composite.clone();
    fitted.gaussians = gaussians;
    let run = FitRun {
        fitted: report.fitted,
        on_gpu: report.on_gpu,
        ms: start.elapsed().as_secs_f64() * 1e3,
    };
    Ok((fitted, run))
}

/// Evaluates the composite of `recipe` over the sources of `trained` against
/// the ground truth `dataset`.
pub fn evaluate_composite(
    trained: &Database,
    recipe: &Recipe,
    dataset: &Dataset,
    options: &EvalOptions,
) -> Result<(CompositeReport, Pictures)> {
    let engine = Engine::new(trained.clone())?;
    let mut variants = decomposition(&engine, recipe)?;
    let mut run = None;
    if let Some(fit) = &options.fit {
        let (fitted, how) = seam_fitted(&engine, &variants[variants.len() - 1].1, fit)?;
        variants.push(("+seam fit", fitted));
        run = Some(how);
    }
    let (mut report, pictures) = evaluate_variants(&engine, recipe, dataset, options, &variants)?;
    report.seam_fit = run;
    Ok((report, pictures))
}

/// [`evaluate_composite`] of composites already built (the decomposition's
/// four, the full recipe last, or five with its seams fitted last) on
/// `engine`.
pub fn evaluate_variants(
    engine: &Engine,
    recipe: &Recipe,
    dataset: &Dataset,
    options: &EvalOptions,
    variants: &[(&'static str, Composite)],
) -> Result<(CompositeReport, Pictures)> {
    let start = std::time::Instant::now();
    if variants.is_empty() {
        return Err(Error::input("no composite to evaluate"));
    }
    let trained = engine.database();
    let resolved = recipe.resolve(trained)?;
    check_dataset(dataset, &resolved, trained)?;
    let model = &trained.model;
    let models: Vec<Trainable> = variants
        .iter()
        .map(|(_, c)| Trainable::from_set(&c.gaussians))
        .collect();
    let last = variants.len() - 1;
    let (full, full_model) = (&variants[last].1, &models[last]);
    let used: Vec<usize> = {
        let mut u = resolved.gaussians.to_vec();
        u.sort_unstable();
        u.dedup();
        u
    };
    let own = used
        .iter()
        .map(|&s| OwnSource::new(trained, s))
        .collect::<Result<Vec<_>>>()?;
    let surfaces: Vec<Surface> = own
        .iter()
        .map(|source| Surface::new(model, &source.sitter))
        .collect();

    let views: Vec<(&'static str, &View)> = [
        ("train", &dataset.train),
        ("val", &dataset.val),
        ("test", &dataset.test),
    ]
    .into_iter()
    .flat_map(|(name, list)| list.iter().map(move |v| (name, v)))
    .collect();
    let all: Vec<&View> = views.iter().map(|(_, v)| *v).collect();
    let times = timesteps(dataset, model, &all)?;

    if let Some(dir) = &options.arrays {
        arrays::prepare(dir)?;
    }
    let step_names = variants.iter().map(|(name, _)| *name).collect();
    let mut tally = Tally::new(&resolved, &model.triangle_regions, used.clone(), step_names);
    let mut pictures = Vec::new();
    for (split, view) in &views {
        let t = &times[&view.timestep];
        let target = load_target(view, None, [0.0; 3])?;
        let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
        let camera = &target.camera;
        let [w, h] = camera.size;
        let mask = read_mask(view, (w * h) as usize)?;
        let labels = labels(&t.truth, model, camera, &mask, &resolved, options.border_px);
        let mut sums = ViewSums::default();
        let mut measured = Vec::new();
        for (k, ((_, composite), m)) in variants.iter().zip(&models).enumerate() {
            let pose = posed(engine, composite, t);
            let image = render(m, &pose.frames, camera);
            let ssim = ssim_map(&image, &goal, w as usize, h as usize);
            tally.add_step(k, &labels, &image, &goal, &ssim, &mut sums);
            if k == last && options.arrays.is_some() {
                measured.clone_from(&image);
            }
            if k == last
                && pictures.len() < options.picture_views
                && (*split != "train" || pictures.is_empty())
            {
                pictures.push((
                    format!("{split} t{} c{}", view.timestep, view.camera_index),
                    picture(&goal, &image, &labels.head, w, h),
                ));
            }
        }
        // Leak: the colour share of each assigned source against all of it
        // (one-hot renders: a source's Gaussians white, the rest black).
        let pose = posed(engine, full, t);
        let everything = render(&one_hot(full_model, full, None), &pose.frames, camera);
        let shares: Vec<(usize, Vec<f64>)> = used
            .iter()
            .map(|&s| {
                (
                    s,
                    render(&one_hot(full_model, full, Some(s)), &pose.frames, camera),
                )
            })
            .collect();
        tally.add_leak_and_holes(&labels, &everything, &shares, &mut sums);
        // The ceiling: each used source on its own ground truth.
        let mut ceilings = Vec::with_capacity(own.len());
        for (k, (source, surface)) in own.iter().zip(&surfaces).enumerate() {
            let drawn = source.draw(surface, model, t, camera, &resolved, options.border_px);
            tally.add_ceiling(k, &drawn, &mut sums);
            ceilings.push(drawn);
        }
        if let Some(dir) = &options.arrays {
            let stem = format!("{split}_t{}_c{}", view.timestep, view.camera_index);
            let view_arrays = arrays::ViewArrays {
                size: camera.size,
                labels: &labels,
                composite: &measured,
                truth: &goal,
                ceilings: used
                    .iter()
                    .map(|&s| trained.sources[s].name.as_str())
                    .zip(&ceilings)
                    .collect(),
                triangle_regions: &model.triangle_regions,
                source_names: trained.sources.iter().map(|s| s.name.as_str()).collect(),
            };
            arrays::write(dir, &stem, &view_arrays)?;
        }
        let jaw_deg = (t.pose.joints[Joint::Jaw as usize].length() as f64).to_degrees();
        let figures = ViewQuality {
            split,
            timestep: view.timestep,
            camera: view.camera_index,
            yaw_deg: camera.eye[0].atan2(camera.eye[2]).to_degrees(),
            quality: sums.composite.quality(),
            holes: sums.hole_share(),
            jaw_deg,
        };
        tally.end_view(&sums, figures);
    }
    let eval_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok((tally.report(trained, options.border_px, eval_ms), pictures))
}

/// A used source's own trained avatar and the person it was trained on:
/// what the ceiling is drawn from.
struct OwnSource {
    /// The trained avatar, as the rasteriser draws it.
    trainable: Trainable,
    /// The built-in person's shape and look: its ground truth.
    sitter: Sitter,
}

impl OwnSource {
    /// Source `index` of `trained`; an error for one that is not a built-in
    /// person (it has no ground truth).
    fn new(trained: &Database, index: usize) -> Result<Self> {
        let avatar = &trained.sources[index];
        let look = look_index(&avatar.name).ok_or_else(|| {
            Error::input(format!(
                "source '{}' is not one of the built-in people: it has no ground truth",
                avatar.name
            ))
        })?;
        Ok(Self {
            trainable: Trainable::from_set(&avatar.gaussians),
            sitter: Sitter::avatar(avatar, look, trained.model.triangle_count()),
        })
    }

    /// The source and its ground truth (`surface`, made from its sitter) at
    /// timestep `t` from `camera`.
    fn draw(
        &self,
        surface: &Surface,
        model: &HeadModel,
        t: &Timestep,
        camera: &TrainCamera,
        recipe: &ResolvedRecipe,
        border_px: u32,
    ) -> SourceView {
        let sitter = &self.sitter;
        let truth = model.forward(
            &sitter.shape,
            Some(&sitter.static_offset),
            &t.expression,
            &t.pose,
        );
        let (truth_image, truth_mask) = surface.draw(&truth, camera);
        let goal: Vec<f64> = truth_image
            .pixels
            .iter()
            .map(|&v| v as f64 / 255.0)
            .collect();
        let frames = crate::avatar::binding::triangle_frames(&truth, &model.triangles);
        let image = render(&self.trainable, &frames, camera);
        let [w, h] = camera.size;
        let ssim = ssim_map(&image, &goal, w as usize, h as usize);
        let shown = visible_triangles(&truth, &model.triangles, camera);
        let band = band(
            &assigned_sources(&shown_regions(&shown, model), recipe),
            camera.size,
            border_px,
        );
        let shown = shown
            .iter()
            .zip(&truth_mask)
            .map(|(tri, &m)| tri.filter(|_| m > 127))
            .collect();
        SourceView {
            image,
            goal,
            ssim,
            shown,
            band,
        }
    }
}
