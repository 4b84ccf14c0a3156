//! How good is a composite? A composite of built-in people, built from
//! separately trained sources, against its ground truth (`capture --recipe`,
//! method §13): masked PSNR, SSIM and CIE76 ΔE over the head, per split, view
//! and group; the border band (pixels near a change of source) against the
//! interior; leak (the share of a pixel's colour from Gaussians of a source
//! other than the one assigned there, by rendering one-hot source colours);
//! the ceiling (each source's own trained avatar against its own ground truth
//! at the same views); and the decomposition swap → +shape → +smoothing →
//! +colour.

use std::collections::BTreeMap;

use glam::{DVec3, Vec3};
use serde::Serialize;

use super::capture::{visible_triangles, Surface};
use super::dataset::{Dataset, View};
use super::hole_metrics::lab;
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
use crate::model::regions::{Group, Region};
use crate::render::image::RgbImage;

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
}

/// Image quality over a set of pixels (every figure NaN — `null` in JSON —
/// over no pixels, e.g. the border band of a single-source composite).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Quality {
    /// PSNR in dB over the pixels (100 at most).
    pub psnr_db: f64,
    /// Mean SSIM (11×11 Gaussian window, as the training loss) over the pixels.
    pub ssim: f64,
    /// Mean CIE76 ΔE over the pixels.
    pub delta_e: f64,
    /// How many pixels.
    pub pixels: usize,
}

/// Sums that become a [`Quality`].
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    squared: f64,
    ssim: f64,
    delta_e: f64,
    pixels: usize,
}

impl Sums {
    fn add(&mut self, squared: f64, ssim: f64, delta_e: f64) {
        self.squared += squared;
        self.ssim += ssim;
        self.delta_e += delta_e;
        self.pixels += 1;
    }

    /// Mean squared error per channel (as PSNR reads it); NaN without pixels.
    fn mse(&self) -> f64 {
        self.squared / (3.0 * self.pixels as f64)
    }

    fn merge(&mut self, other: &Sums) {
        self.squared += other.squared;
        self.ssim += other.ssim;
        self.delta_e += other.delta_e;
        self.pixels += other.pixels;
    }

    fn quality(&self) -> Quality {
        if self.pixels == 0 {
            return Quality {
                psnr_db: f64::NAN,
                ssim: f64::NAN,
                delta_e: f64::NAN,
                pixels: 0,
            };
        }
        let n = self.pixels as f64;
        let mse = self.squared / (3.0 * n);
        Quality {
            psnr_db: if mse > 0.0 {
                (10.0 * (1.0 / mse).log10()).min(100.0)
            } else {
                100.0
            },
            ssim: self.ssim / n,
            delta_e: self.delta_e / n,
            pixels: self.pixels,
        }
    }
}

/// A jaw opened at least this far (degrees) counts as an open mouth: the
/// talk motion's syllables open it up to ~9°, its pauses leave it under 1°.
pub const OPEN_MOUTH_DEG: f64 = 3.0;

/// One view's figures.
#[derive(Clone, Debug, Serialize)]
pub struct ViewQuality {
    /// train, val or test.
    pub split: &'static str,
    /// The timestep.
    pub timestep: usize,
    /// The rig camera.
    pub camera: usize,
    /// The camera's yaw about the head's up axis (0 in front, + to the
    /// subject's left), degrees.
    pub yaw_deg: f64,
    /// Over the head.
    pub quality: Quality,
    /// Share of head pixels the composite covers less than half (0-1).
    pub holes: f64,
    /// The jaw's opening at this timestep, degrees.
    pub jaw_deg: f64,
}

/// One group's figures.
#[derive(Clone, Debug, Serialize)]
pub struct GroupQuality {
    /// The group.
    pub group: &'static str,
    /// Whose Gaussians it shows.
    pub source: String,
    /// Over the group's pixels.
    pub quality: Quality,
    /// Its source's own trained avatar against its own ground truth, over the
    /// pixels of this group in its own images: the best this region can be.
    pub ceiling_psnr_db: f64,
}

/// One region's figures, in the border band and in the interior.
#[derive(Clone, Debug, Serialize)]
pub struct RegionQuality {
    /// The region.
    pub region: &'static str,
    /// Whose Gaussians it shows.
    pub source: String,
    /// Over the region's pixels in the border band.
    pub band: Quality,
    /// Over the rest of its pixels.
    pub interior: Quality,
    /// Its source on its own ground truth, over the region's band as it lies
    /// in the source's own images.
    pub ceiling_band_psnr_db: f64,
    /// Its source on its own ground truth, over the rest of the region.
    pub ceiling_interior_psnr_db: f64,
    /// The squared error (per channel, colours 0-1) over the ceiling's, times
    /// the pixels, band and interior together: how much of the composite's
    /// error beyond what training reaches lies here. A zone the source's own
    /// images lack is told against the region's whole ceiling; a region they
    /// never show has none. Regions are listed largest first.
    pub excess: f64,
}

/// Where colour comes from another source than the one assigned.
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct Leak {
    /// Mean share of colour from other sources, at interior pixels (0-1).
    pub mean: f64,
    /// Share of interior pixels where it exceeds 5 %.
    pub over_5_percent: f64,
    /// Interior pixels measured.
    pub pixels: usize,
}

/// One step of the decomposition.
#[derive(Clone, Debug, Serialize)]
pub struct Step {
    /// swap, +shape, +smoothing or +colour.
    pub step: &'static str,
    /// Over the head.
    pub quality: Quality,
    /// Over the border band.
    pub border: Quality,
    /// Over the interior.
    pub interior: Quality,
    /// Over skin pixels (ΔE matters most here for colour correction).
    pub skin: Quality,
    /// Over the other pixels (lips, eyes, brows, hair, teeth, clothes).
    pub non_skin: Quality,
}

/// A source's ceiling over its own ground truth.
#[derive(Clone, Debug, Serialize)]
pub struct SourceCeiling {
    /// The source.
    pub source: String,
    /// Its trained avatar against its own ground truth, over the head.
    pub quality: Quality,
}

/// Everything `eval --composite` measures.
#[derive(Clone, Debug, Serialize)]
pub struct CompositeReport {
    /// Views measured (all splits).
    pub views: usize,
    /// Border band width in pixels.
    pub border_px: u32,
    /// The full recipe over the head.
    pub quality: Quality,
    /// Per split.
    pub splits: BTreeMap<&'static str, Quality>,
    /// Over the held-out views (val and test), which no source was trained
    /// on when the sources were captured with the ground truth's rig and
    /// motion (as `bench composites` does).
    pub held_out: Quality,
    /// Per view.
    pub per_view: Vec<ViewQuality>,
    /// Per group.
    pub groups: Vec<GroupQuality>,
    /// Per region shown, the largest excess over the ceiling first.
    pub regions: Vec<RegionQuality>,
    /// Over the border band.
    pub border: Quality,
    /// Over the interior (outside the band).
    pub interior: Quality,
    /// Skin pixels.
    pub skin: Quality,
    /// Non-skin pixels.
    pub non_skin: Quality,
    /// Leak at interior pixels.
    pub leak: Leak,
    /// Share of head pixels, over all views, that the composite covers less
    /// than half (holes, 0-1).
    pub holes: f64,
    /// Over the views whose jaw is open at least [`OPEN_MOUTH_DEG`].
    pub open_mouth: Quality,
    /// Over the other views.
    pub closed_mouth: Quality,
    /// The ceiling: every group as good as its source on itself, combined.
    pub ceiling: Quality,
    /// The ceiling over skin pixels: what no colour correction can beat there.
    pub ceiling_skin: Quality,
    /// The ceiling over the other pixels.
    pub ceiling_non_skin: Quality,
    /// The ceiling over the border band as it lies in each source's own
    /// images (its groups' pixels near groups the recipe gives another
    /// source): how well training alone draws those places, so the band's
    /// gap to the interior can be told from the composite's own.
    pub ceiling_border: Quality,
    /// The ceiling over the rest of the assigned groups' pixels.
    pub ceiling_interior: Quality,
    /// The ceiling per split. On the training split a source is scored on
    /// the very images it was fitted to, which no composite's new appearance
    /// was; the held-out splits tell what training reaches on views it has
    /// not seen.
    pub ceiling_splits: BTreeMap<&'static str, Quality>,
    /// The ceiling over the held-out views (val and test).
    pub ceiling_held_out: Quality,
    /// Each source's own figures.
    pub sources: Vec<SourceCeiling>,
    /// swap → +shape → +smoothing → +colour.
    pub decomposition: Vec<Step>,
    /// Milliseconds the evaluation took (the seam fit not counted).
    pub eval_ms: f64,
    /// The seam fit of the measured composite, where one ran.
    pub seam_fit: Option<FitRun>,
}

/// How the seam fit of a measured composite ran.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FitRun {
    /// Gaussians fitted.
    pub fitted: usize,
    /// Whether its views were drawn on a GPU (f32) rather than the CPU (f64).
    pub on_gpu: bool,
    /// Milliseconds it took, its targets included.
    pub ms: f64,
}

/// Pictures for a few views: ground truth, composite, error map.
pub type Pictures = Vec<(String, [RgbImage; 3])>;

/// Regions whose surface is skin (their pixels are "skin" for ΔE): the face,
/// nose, ears, neck and the skin around the eyes. Lips, mouth, teeth, eyes,
/// hair and the clothes' boundary are not.
pub fn is_skin(region: Region) -> bool {
    matches!(
        region,
        Region::Skin
            | Region::Nose
            | Region::LeftEar
            | Region::RightEar
            | Region::Neck
            | Region::LeftEyeRegion
            | Region::RightEyeRegion
    )
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

/// Per pixel: what the ground truth shows there.
struct Labels {
    /// The head (mask over half) with a triangle under it.
    head: Vec<bool>,
    /// The region shown.
    region: Vec<Option<Region>>,
    /// The source assigned there (`u32::MAX` off the head).
    source: Vec<u32>,
    /// Within the border band.
    band: Vec<bool>,
}

fn labels(
    truth: &[Vec3],
    model: &HeadModel,
    camera: &TrainCamera,
    mask: &[u8],
    recipe: &ResolvedRecipe,
    border_px: u32,
) -> Labels {
    let region = shown_regions(&visible_triangles(truth, &model.triangles, camera), model);
    let head: Vec<bool> = region
        .iter()
        .zip(mask)
        .map(|(r, &m)| r.is_some() && m > 127)
        .collect();
    let source = assigned_sources(&region, recipe);
    let band = band(&source, camera.size, border_px);
    Labels {
        head,
        region,
        source,
        band,
    }
}

/// Per region shown (of `sums`, [band, interior] each, against the same of
/// `ceilings`), largest excess over the ceiling first; `source_of` names the
/// source a region shows.
fn region_figures(
    sums: &[[Sums; 2]; Region::COUNT],
    ceilings: &[[Sums; 2]; Region::COUNT],
    source_of: impl Fn(Region) -> String,
) -> Vec<RegionQuality> {
    let mut regions: Vec<RegionQuality> = Region::ALL
        .iter()
        .map(|&r| (r, &sums[r.index()], &ceilings[r.index()]))
        .filter(|(_, [band, interior], _)| band.pixels + interior.pixels > 0)
        .map(|(r, zones, ceiling)| {
            // A zone the source's own images lack (its band falls elsewhere
            // there) is told against the region's whole ceiling; a region
            // the source's own images never show adds nothing.
            let mut whole = ceiling[0];
            whole.merge(&ceiling[1]);
            let excess = zones
                .iter()
                .zip(ceiling)
                .filter(|(z, _)| z.pixels > 0)
                .map(|(z, c)| {
                    let c = if c.pixels > 0 { c } else { &whole };
                    (z.mse() - c.mse()) * z.pixels as f64
                })
                .filter(|e| e.is_finite())
                .sum();
            RegionQuality {
                region: r.name(),
                source: source_of(r),
                band: zones[0].quality(),
                interior: zones[1].quality(),
                ceiling_band_psnr_db: ceiling[0].quality().psnr_db,
                ceiling_interior_psnr_db: ceiling[1].quality().psnr_db,
                excess,
            }
        })
        .collect();
    regions.sort_by(|a, b| b.excess.total_cmp(&a.excess));
    regions
}

/// Per pixel: the region of the triangle `shown` there, if any.
fn shown_regions(shown: &[Option<u32>], model: &HeadModel) -> Vec<Option<Region>> {
    shown
        .iter()
        .map(|t| t.map(|t| model.triangle_regions[t as usize]))
        .collect()
}

/// Per pixel: the source the recipe assigns the region shown there
/// (`u32::MAX` where no region is).
fn assigned_sources(region: &[Option<Region>], recipe: &ResolvedRecipe) -> Vec<u32> {
    region
        .iter()
        .map(|r| r.map_or(u32::MAX, |r| recipe.gaussians[r.group().index()] as u32))
        .collect()
}

/// Pixels within `k` pixels (a square window) of a pixel showing another
/// source (background does not count as a source).
pub fn band(source: &[u32], size: [u32; 2], k: u32) -> Vec<bool> {
    let [w, h] = [size[0] as i64, size[1] as i64];
    let k = k as i64;
    let mut out = vec![false; source.len()];
    for y in 0..h {
        for x in 0..w {
            let s = source[(y * w + x) as usize];
            if s == u32::MAX {
                continue;
            }
            'search: for dy in -k..=k {
                for dx in -k..=k {
                    let (xx, yy) = (x + dx, y + dy);
                    if xx < 0 || yy < 0 || xx >= w || yy >= h {
                        continue;
                    }
                    let o = source[(yy * w + xx) as usize];
                    if o != u32::MAX && o != s {
                        out[(y * w + x) as usize] = true;
                        break 'search;
                    }
                }
            }
        }
    }
    out
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

fn rgb(image: &[f64], p: usize) -> DVec3 {
    DVec3::new(image[3 * p], image[3 * p + 1], image[3 * p + 2])
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
    // Each used source's own trained avatar and ground truth surface.
    let own: Vec<(usize, Trainable, Sitter)> = used
        .iter()
        .map(|&s| {
            let avatar = &trained.sources[s];
            let look = look_index(&avatar.name).ok_or_else(|| {
                Error::input(format!(
                    "source '{}' is not one of the built-in people: it has no ground truth",
                    avatar.name
                ))
            })?;
            Ok((
                s,
                Trainable::from_set(&avatar.gaussians),
                Sitter::avatar(avatar, look, model.triangle_count()),
            ))
        })
        .collect::<Result<_>>()?;
    let surfaces: Vec<Surface> = own
        .iter()
        .map(|(_, _, sitter)| Surface::new(model, sitter))
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

    let mut overall = Sums::default();
    let mut splits: BTreeMap<&'static str, Sums> = BTreeMap::new();
    let mut per_view = Vec::new();
    let mut groups = [Sums::default(); Group::COUNT];
    let mut ceilings = [Sums::default(); Group::COUNT];
    // Per region, [band, interior], of the composite and of the ceiling.
    let mut region_sums = [[Sums::default(); 2]; Region::COUNT];
    let mut region_ceilings = [[Sums::default(); 2]; Region::COUNT];
    // [skin, other] pixels of the ceiling.
    let mut ceiling_parts = [Sums::default(); 2];
    // [band, interior] pixels of the ceiling.
    let mut ceiling_zones = [Sums::default(); 2];
    let mut ceiling_splits: BTreeMap<&'static str, Sums> = BTreeMap::new();
    let mut source_sums = vec![Sums::default(); own.len()];
    let mut step_sums = vec![[Sums::default(); 5]; variants.len()];
    let (mut leak_sum, mut leak_over, mut leak_pixels) = (0.0, 0usize, 0usize);
    let (mut hole_pixels, mut head_pixels) = (0usize, 0usize);
    let mut mouth_sums = [Sums::default(); 2];
    let mut pictures = Vec::new();

    for (split, view) in &views {
        let t = &times[&view.timestep];
        let target = load_target(view, None, [0.0; 3])?;
        let goal: Vec<f64> = target.pixels.iter().map(|&p| p as f64).collect();
        let camera = &target.camera;
        let [w, h] = camera.size;
        let mask = read_mask(view, (w * h) as usize)?;
        let labels = labels(&t.truth, model, camera, &mask, &resolved, options.border_px);
        let mut view_sums = Sums::default();
        for (k, ((_, composite), m)) in variants.iter().zip(&models).enumerate() {
            let pose = posed(engine, composite, t);
            let image = render(m, &pose.frames, camera);
            let ssim = ssim_map(&image, &goal, w as usize, h as usize);
            for p in (0..labels.head.len()).filter(|&p| labels.head[p]) {
                let (a, b) = (rgb(&image, p), rgb(&goal, p));
                let (sq, de) = ((a - b).length_squared(), (lab(a) - lab(b)).length());
                let s = &mut step_sums[k];
                s[0].add(sq, ssim[p], de);
                s[if labels.band[p] { 1 } else { 2 }].add(sq, ssim[p], de);
                let skin = labels.region[p].is_some_and(is_skin);
                s[if skin { 3 } else { 4 }].add(sq, ssim[p], de);
                if k == last {
                    view_sums.add(sq, ssim[p], de);
                    if let Some(r) = labels.region[p] {
                        groups[r.group().index()].add(sq, ssim[p], de);
                        region_sums[r.index()][usize::from(!labels.band[p])].add(sq, ssim[p], de);
                    }
                }
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
        // Holes: head pixels the composite's opacity leaves more than half open.
        let head: Vec<usize> = (0..labels.head.len()).filter(|&p| labels.head[p]).collect();
        let view_holes = head.iter().filter(|&&p| everything[3 * p] < 0.5).count();
        hole_pixels += view_holes;
        head_pixels += head.len();
        for p in (0..labels.head.len()).filter(|&p| labels.head[p] && !labels.band[p]) {
            let total = everything[3 * p];
            if total < 0.5 {
                continue;
            }
            let assigned = shares
                .iter()
                .find(|(s, _)| *s as u32 == labels.source[p])
                .map_or(0.0, |(_, img)| img[3 * p]);
            let leak = (1.0 - assigned / total).clamp(0.0, 1.0);
            leak_sum += leak;
            leak_over += usize::from(leak > 0.05);
            leak_pixels += 1;
        }
        // The ceiling: each used source on its own ground truth.
        let mut view_ceiling = Sums::default();
        for (k, ((s, trainable, sitter), surface)) in own.iter().zip(&surfaces).enumerate() {
            let truth = model.forward(
                &sitter.shape,
                Some(&sitter.static_offset),
                &t.expression,
                &t.pose,
            );
            let (truth_image, truth_mask) = surface.draw(&truth, camera);
            let truth_goal: Vec<f64> = truth_image
                .pixels
                .iter()
                .map(|&v| v as f64 / 255.0)
                .collect();
            let frames = crate::avatar::binding::triangle_frames(&truth, &model.triangles);
            let image = render(trainable, &frames, camera);
            let ssim = ssim_map(&image, &truth_goal, w as usize, h as usize);
            let shown = visible_triangles(&truth, &model.triangles, camera);
            // The band as it lies in the source's own image: where its groups
            // meet groups the recipe gives other sources.
            let own_band = band(
                &assigned_sources(&shown_regions(&shown, model), &resolved),
                camera.size,
                options.border_px,
            );
            for p in 0..shown.len() {
                let Some(tri) = shown[p].filter(|_| truth_mask[p] > 127) else {
                    continue;
                };
                let (a, b) = (rgb(&image, p), rgb(&truth_goal, p));
                let (sq, de) = ((a - b).length_squared(), (lab(a) - lab(b)).length());
                source_sums[k].add(sq, ssim[p], de);
                let region = model.triangle_regions[tri as usize];
                let g = region.group();
                if resolved.gaussians[g.index()] == *s {
                    ceilings[g.index()].add(sq, ssim[p], de);
                    view_ceiling.add(sq, ssim[p], de);
                    ceiling_parts[usize::from(!is_skin(region))].add(sq, ssim[p], de);
                    ceiling_zones[usize::from(!own_band[p])].add(sq, ssim[p], de);
                    region_ceilings[region.index()][usize::from(!own_band[p])].add(sq, ssim[p], de);
                }
            }
        }
        overall.merge(&view_sums);
        let jaw_deg = (t.pose.joints[Joint::Jaw as usize].length() as f64).to_degrees();
        mouth_sums[usize::from(jaw_deg >= OPEN_MOUTH_DEG)].merge(&view_sums);
        splits.entry(*split).or_default().merge(&view_sums);
        ceiling_splits
            .entry(*split)
            .or_default()
            .merge(&view_ceiling);
        per_view.push(ViewQuality {
            split,
            timestep: view.timestep,
            camera: view.camera_index,
            yaw_deg: camera.eye[0].atan2(camera.eye[2]).to_degrees(),
            quality: view_sums.quality(),
            holes: view_holes as f64 / head.len().max(1) as f64,
            jaw_deg,
        });
    }
    let mut ceiling = Sums::default();
    ceilings.iter().for_each(|c| ceiling.merge(c));
    let final_step = &step_sums[last];
    let held_out = |by_split: &BTreeMap<&'static str, Sums>| {
        let mut sums = Sums::default();
        by_split
            .iter()
            .filter(|(split, _)| **split != "train")
            .for_each(|(_, s)| sums.merge(s));
        sums.quality()
    };
    let report = CompositeReport {
        views: views.len(),
        border_px: options.border_px,
        quality: overall.quality(),
        splits: splits.iter().map(|(k, v)| (*k, v.quality())).collect(),
        held_out: held_out(&splits),
        per_view,
        groups: Group::ALL
            .iter()
            .filter(|g| groups[g.index()].pixels > 0)
            .map(|g| GroupQuality {
                group: g.name(),
                source: trained.sources[resolved.gaussians[g.index()]].name.clone(),
                quality: groups[g.index()].quality(),
                ceiling_psnr_db: ceilings[g.index()].quality().psnr_db,
            })
            .collect(),
        regions: region_figures(&region_sums, &region_ceilings, |r| {
            trained.sources[resolved.gaussians[r.group().index()]]
                .name
                .clone()
        }),
        border: final_step[1].quality(),
        interior: final_step[2].quality(),
        skin: final_step[3].quality(),
        non_skin: final_step[4].quality(),
        leak: Leak {
            mean: leak_sum / leak_pixels.max(1) as f64,
            over_5_percent: leak_over as f64 / leak_pixels.max(1) as f64,
            pixels: leak_pixels,
        },
        holes: hole_pixels as f64 / head_pixels.max(1) as f64,
        open_mouth: mouth_sums[1].quality(),
        closed_mouth: mouth_sums[0].quality(),
        ceiling: ceiling.quality(),
        ceiling_skin: ceiling_parts[0].quality(),
        ceiling_non_skin: ceiling_parts[1].quality(),
        ceiling_border: ceiling_zones[0].quality(),
        ceiling_interior: ceiling_zones[1].quality(),
        ceiling_splits: ceiling_splits
            .iter()
            .map(|(k, v)| (*k, v.quality()))
            .collect(),
        ceiling_held_out: held_out(&ceiling_splits),
        sources: own
            .iter()
            .zip(&source_sums)
            .map(|((s, _, _), sums)| SourceCeiling {
                source: trained.sources[*s].name.clone(),
                quality: sums.quality(),
            })
            .collect(),
        decomposition: variants
            .iter()
            .zip(&step_sums)
            .map(|((name, _), s)| Step {
                step: name,
                quality: s[0].quality(),
                border: s[1].quality(),
                interior: s[2].quality(),
                skin: s[3].quality(),
                non_skin: s[4].quality(),
            })
            .collect(),
        eval_ms: start.elapsed().as_secs_f64() * 1e3,
        seam_fit: None,
    };
    Ok((report, pictures))
}

/// A view's foreground mask (all foreground without one).
fn read_mask(view: &View, pixels: usize) -> Result<Vec<u8>> {
    match &view.mask {
        None => Ok(vec![255; pixels]),
        Some(path) => Ok(image::open(path)
            .map_err(|e| Error::input(format!("cannot read mask {}: {e}", path.display())))?
            .to_luma8()
            .into_raw()),
    }
}

/// Ground truth, composite and an error map (ΔE, 0 black to 20 and more
/// bright yellow) of one view.
fn picture(goal: &[f64], image: &[f64], head: &[bool], w: u32, h: u32) -> [RgbImage; 3] {
    let to_image = |v: &[f64]| RgbImage {
        width: w,
        height: h,
        pixels: v
            .iter()
            .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
    };
    let mut heat = RgbImage::new(w, h, [0, 0, 0]);
    for (p, &on) in head.iter().enumerate() {
        if !on {
            continue;
        }
        let de = (lab(rgb(image, p)) - lab(rgb(goal, p))).length();
        let t = (de / 20.0).clamp(0.0, 1.0);
        let c = [
            255.0 * (2.0 * t).min(1.0),
            255.0 * (2.0 * t - 1.0).max(0.0),
            40.0 * (1.0 - t),
        ];
        heat.pixels[3 * p..3 * p + 3].copy_from_slice(&c.map(|x| x.round() as u8));
    }
    [to_image(goal), to_image(image), heat]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_band_is_where_sources_change_and_nowhere_else() {
        // Two sources side by side over a background row.
        let m = u32::MAX;
        let source = [
            0, 0, 0, 1, 1, 1, //
            0, 0, 0, 1, 1, 1, //
            m, m, m, m, m, m,
        ];
        let b = band(&source, [6, 3], 1);
        let expect = [
            false, false, true, true, false, false, //
            false, false, true, true, false, false, //
            false, false, false, false, false, false,
        ];
        assert_eq!(b, expect);
        assert!(
            band(&[2; 9], [3, 3], 2).iter().all(|&x| !x),
            "one source has no band"
        );
    }

    #[test]
    fn sums_give_psnr_and_means() {
        let mut s = Sums::default();
        s.add(3.0 * 0.01, 0.9, 2.0);
        s.add(3.0 * 0.01, 0.7, 4.0);
        let q = s.quality();
        assert!((q.psnr_db - 20.0).abs() < 1e-9);
        assert!((q.ssim - 0.8).abs() < 1e-12 && (q.delta_e - 3.0).abs() < 1e-12);
        assert!(
            Sums::default().quality().psnr_db.is_nan(),
            "no pixels: no figure"
        );
    }
}
