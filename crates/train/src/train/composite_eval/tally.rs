//! The sums an evaluation gathers view by view — the composite's steps, its
//! leak and holes, the sources' ceiling — and the report they become.

use std::collections::BTreeMap;

use super::pixels::{is_skin, rgb, Labels};
use super::report::{
    region_figures, CompositeReport, GroupQuality, Leak, Quality, SourceCeiling, Step, Sums,
    ViewQuality, OPEN_MOUTH_DEG,
};
use crate::avatar::database::Database;
use crate::compose::recipe::ResolvedRecipe;
use crate::model::regions::{Group, Region};
use crate::train::hole_metrics::lab;

/// One view's sums: the full composite over the head, and the ceiling over
/// the assigned groups' pixels in the sources' own images.
#[derive(Default)]
pub(super) struct ViewSums {
    /// The full composite, over the head.
    pub(super) composite: Sums,
    /// The sources on their own ground truth.
    ceiling: Sums,
    /// Head pixels the composite covers less than half.
    holes: usize,
    /// Head pixels.
    head_pixels: usize,
}

impl ViewSums {
    /// Share of the view's head pixels that are holes (0-1).
    pub(super) fn hole_share(&self) -> f64 {
        self.holes as f64 / self.head_pixels.max(1) as f64
    }
}

/// A used source drawn on its own ground truth at one view: what the
/// ceiling is summed from.
pub(super) struct SourceView {
    /// The source's render.
    pub(super) image: Vec<f64>,
    /// The source's ground truth.
    pub(super) goal: Vec<f64>,
    /// SSIM of the render against the truth, per pixel.
    pub(super) ssim: Vec<f64>,
    /// The triangle shown at each pixel where the truth's mask holds the head.
    pub(super) shown: Vec<Option<u32>>,
    /// The border band as it lies in the source's own image: where its
    /// groups meet groups the recipe gives other sources.
    pub(super) band: Vec<bool>,
}

/// Everything summed so far, over every view, for one recipe.
pub(super) struct Tally<'a> {
    /// The recipe measured.
    recipe: &'a ResolvedRecipe,
    /// Per triangle of the model, its region.
    regions: &'a [Region],
    /// The sources the recipe uses (database indices), in the order the
    /// ceiling's sums hold them.
    used: Vec<usize>,
    /// The decomposition's step names, in the order of the steps' sums.
    steps: Vec<&'static str>,
    overall: Sums,
    splits: BTreeMap<&'static str, Sums>,
    per_view: Vec<ViewQuality>,
    groups: [Sums; Group::COUNT],
    ceilings: [Sums; Group::COUNT],
    /// Per region, [band, interior], of the composite and of the ceiling.
    region_sums: [[Sums; 2]; Region::COUNT],
    region_ceilings: [[Sums; 2]; Region::COUNT],
    /// Per region, its band pixels by the region across the change of source.
    band_beside: [[Sums; Region::COUNT]; Region::COUNT],
    /// [skin, other] pixels of the ceiling.
    ceiling_parts: [Sums; 2],
    /// [band, interior] pixels of the ceiling.
    ceiling_zones: [Sums; 2],
    ceiling_splits: BTreeMap<&'static str, Sums>,
    /// Per used source, over its whole head in its own images.
    source_sums: Vec<Sums>,
    /// Per step of the decomposition: [head, band, interior, skin, other].
    step_sums: Vec<[Sums; 5]>,
    leak_sum: f64,
    leak_over: usize,
    leak_pixels: usize,
    hole_pixels: usize,
    head_pixels: usize,
    /// [closed, open] mouth views.
    mouth_sums: [Sums; 2],
}

/// The squared error and CIE76 ΔE between two colours.
fn errors(a: glam::DVec3, b: glam::DVec3) -> (f64, f64) {
    ((a - b).length_squared(), (lab(a) - lab(b)).length())
}

impl<'a> Tally<'a> {
    /// Empty sums for `recipe` (its model's triangle regions `regions`), the
    /// sources it uses, `used`, and the composites named `steps`, the full
    /// recipe last.
    pub(super) fn new(
        recipe: &'a ResolvedRecipe,
        regions: &'a [Region],
        used: Vec<usize>,
        steps: Vec<&'static str>,
    ) -> Self {
        let (sources, step_count) = (used.len(), steps.len());
        Self {
            recipe,
            regions,
            used,
            steps,
            overall: Sums::default(),
            splits: BTreeMap::new(),
            per_view: Vec::new(),
            groups: [Sums::default(); Group::COUNT],
            ceilings: [Sums::default(); Group::COUNT],
            region_sums: [[Sums::default(); 2]; Region::COUNT],
            region_ceilings: [[Sums::default(); 2]; Region::COUNT],
            band_beside: [[Sums::default(); Region::COUNT]; Region::COUNT],
            ceiling_parts: [Sums::default(); 2],
            ceiling_zones: [Sums::default(); 2],
            ceiling_splits: BTreeMap::new(),
            source_sums: vec![Sums::default(); sources],
            step_sums: vec![[Sums::default(); 5]; step_count],
            leak_sum: 0.0,
            leak_over: 0,
            leak_pixels: 0,
            hole_pixels: 0,
            head_pixels: 0,
            mouth_sums: [Sums::default(); 2],
        }
    }

    /// Adds composite `step`'s `image` of a view against its `goal`; the
    /// last step, the full recipe, also counts per group, per region and in
    /// `view`.
    pub(super) fn add_step(
        &mut self,
        step: usize,
        labels: &Labels,
        image: &[f64],
        goal: &[f64],
        ssim: &[f64],
        view: &mut ViewSums,
    ) {
        let last = step + 1 == self.step_sums.len();
        for p in (0..labels.head.len()).filter(|&p| labels.head[p]) {
            let (sq, de) = errors(rgb(image, p), rgb(goal, p));
            let s = &mut self.step_sums[step];
            s[0].add(sq, ssim[p], de);
            s[if labels.band[p] { 1 } else { 2 }].add(sq, ssim[p], de);
            let skin = labels.region[p].is_some_and(is_skin);
            s[if skin { 3 } else { 4 }].add(sq, ssim[p], de);
            if last {
                view.composite.add(sq, ssim[p], de);
                if let Some(r) = labels.region[p] {
                    self.groups[r.group().index()].add(sq, ssim[p], de);
                    self.region_sums[r.index()][usize::from(!labels.band[p])].add(sq, ssim[p], de);
                    if let Some(n) = labels.beside[p] {
                        self.band_beside[r.index()][n.index()].add(sq, ssim[p], de);
                    }
                }
            }
        }
    }

    /// Adds a view's holes and leak: `everything` is the full composite's
    /// one-hot render of all its Gaussians, `shares` each used source's.
    pub(super) fn add_leak_and_holes(
        &mut self,
        labels: &Labels,
        everything: &[f64],
        shares: &[(usize, Vec<f64>)],
        view: &mut ViewSums,
    ) {
        let head: Vec<usize> = (0..labels.head.len()).filter(|&p| labels.head[p]).collect();
        view.holes = head.iter().filter(|&&p| everything[3 * p] < 0.5).count();
        view.head_pixels = head.len();
        self.hole_pixels += view.holes;
        self.head_pixels += head.len();
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
            self.leak_sum += leak;
            self.leak_over += usize::from(leak > 0.05);
            self.leak_pixels += 1;
        }
    }

    /// Adds the `k`-th used source drawn on its own ground truth.
    pub(super) fn add_ceiling(&mut self, k: usize, drawn: &SourceView, view: &mut ViewSums) {
        let source = self.used[k];
        let ssim = &drawn.ssim;
        for (p, tri) in drawn.shown.iter().enumerate() {
            let Some(tri) = tri else { continue };
            let (sq, de) = errors(rgb(&drawn.image, p), rgb(&drawn.goal, p));
            self.source_sums[k].add(sq, ssim[p], de);
            let region = self.regions[*tri as usize];
            let g = region.group();
            if self.recipe.gaussians[g.index()] == source {
                let zone = usize::from(!drawn.band[p]);
                self.ceilings[g.index()].add(sq, ssim[p], de);
                view.ceiling.add(sq, ssim[p], de);
                self.ceiling_parts[usize::from(!is_skin(region))].add(sq, ssim[p], de);
                self.ceiling_zones[zone].add(sq, ssim[p], de);
                self.region_ceilings[region.index()][zone].add(sq, ssim[p], de);
            }
        }
    }

    /// Closes a view (`figures` made from `view`): its sums join the
    /// split's, the mouth's and the whole's.
    pub(super) fn end_view(&mut self, view: &ViewSums, figures: ViewQuality) {
        self.overall.merge(&view.composite);
        let open = figures.jaw_deg >= OPEN_MOUTH_DEG;
        self.mouth_sums[usize::from(open)].merge(&view.composite);
        self.splits
            .entry(figures.split)
            .or_default()
            .merge(&view.composite);
        self.ceiling_splits
            .entry(figures.split)
            .or_default()
            .merge(&view.ceiling);
        self.per_view.push(figures);
    }

    /// The report: `trained` names the sources; `eval_ms` is how long the
    /// evaluation took.
    pub(super) fn report(
        self,
        trained: &Database,
        border_px: u32,
        eval_ms: f64,
    ) -> CompositeReport {
        let name = |s: usize| trained.sources[s].name.clone();
        let mut ceiling = Sums::default();
        self.ceilings.iter().for_each(|c| ceiling.merge(c));
        let final_step = self
            .step_sums
            .last()
            .expect("a tally has at least one step: the full recipe");
        let recipe = self.recipe;
        CompositeReport {
            views: self.per_view.len(),
            border_px,
            quality: self.overall.quality(),
            splits: qualities(&self.splits),
            held_out: held_out(&self.splits),
            per_view: self.per_view,
            groups: Group::ALL
                .iter()
                .filter(|g| self.groups[g.index()].pixels > 0)
                .map(|g| GroupQuality {
                    group: g.name(),
                    source: name(recipe.gaussians[g.index()]),
                    quality: self.groups[g.index()].quality(),
                    ceiling_psnr_db: self.ceilings[g.index()].quality().psnr_db,
                })
                .collect(),
            regions: region_figures(
                &self.region_sums,
                &self.region_ceilings,
                &self.band_beside,
                |r| name(recipe.gaussians[r.group().index()]),
            ),
            border: final_step[1].quality(),
            interior: final_step[2].quality(),
            skin: final_step[3].quality(),
            non_skin: final_step[4].quality(),
            leak: Leak {
                mean: self.leak_sum / self.leak_pixels.max(1) as f64,
                over_5_percent: self.leak_over as f64 / self.leak_pixels.max(1) as f64,
                pixels: self.leak_pixels,
            },
            holes: self.hole_pixels as f64 / self.head_pixels.max(1) as f64,
            open_mouth: self.mouth_sums[1].quality(),
            closed_mouth: self.mouth_sums[0].quality(),
            ceiling: ceiling.quality(),
            ceiling_skin: self.ceiling_parts[0].quality(),
            ceiling_non_skin: self.ceiling_parts[1].quality(),
            ceiling_border: self.ceiling_zones[0].quality(),
            ceiling_interior: self.ceiling_zones[1].quality(),
            ceiling_splits: qualities(&self.ceiling_splits),
            ceiling_held_out: held_out(&self.ceiling_splits),
            sources: self
                .used
                .iter()
                .zip(&self.source_sums)
                .map(|(&s, sums)| SourceCeiling {
                    source: name(s),
                    quality: sums.quality(),
                })
                .collect(),
            decomposition: self
                .steps
                .iter()
                .zip(&self.step_sums)
                .map(|(step, s)| Step {
                    step,
                    quality: s[0].quality(),
                    border: s[1].quality(),
                    interior: s[2].quality(),
                    skin: s[3].quality(),
                    non_skin: s[4].quality(),
                })
                .collect(),
            eval_ms,
            seam_fit: None,
        }
    }
}

/// Per split, its quality.
fn qualities(by_split: &BTreeMap<&'static str, Sums>) -> BTreeMap<&'static str, Quality> {
    by_split.iter().map(|(k, v)| (*k, v.quality())).collect()
}

/// Over the held-out splits (all but train).
fn held_out(by_split: &BTreeMap<&'static str, Sums>) -> Quality {
    let mut sums = Sums::default();
    by_split
        .iter()
        .filter(|(split, _)| **split != "train")
        .for_each(|(_, s)| sums.merge(s));
    sums.quality()
}
