//! What `eval --composite` reports: image quality over sets of pixels, per
//! view, group, region and source, and the sums they are made from.

use std::collections::BTreeMap;

use serde::Serialize;

use crate::model::regions::Region;
use crate::render::image::RgbImage;

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
pub(super) struct Sums {
    /// Squared colour error, summed over channels and pixels.
    squared: f64,
    /// SSIM, summed over pixels.
    ssim: f64,
    /// CIE76 ΔE, summed over pixels.
    delta_e: f64,
    /// How many pixels were added.
    pub(super) pixels: usize,
}

impl Sums {
    /// Adds one pixel's squared error (over its channels), SSIM and ΔE.
    pub(super) fn add(&mut self, squared: f64, ssim: f64, delta_e: f64) {
        self.squared += squared;
        self.ssim += ssim;
        self.delta_e += delta_e;
        self.pixels += 1;
    }

    /// Mean squared error per channel (as PSNR reads it); NaN without pixels.
    pub(super) fn mse(&self) -> f64 {
        self.squared / (3.0 * self.pixels as f64)
    }

    /// Adds another set of sums to these.
    pub(super) fn merge(&mut self, other: &Sums) {
        self.squared += other.squared;
        self.ssim += other.ssim;
        self.delta_e += other.delta_e;
        self.pixels += other.pixels;
    }

    /// The sums as PSNR, mean SSIM and mean ΔE (NaN over no pixels).
    pub(super) fn quality(&self) -> Quality {
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
    /// The band split by the region across the change of source (what each
    /// band pixel borders), the largest excess over the region's band
    /// ceiling first: which of a region's seams costs most.
    pub beside: Vec<BandBeside>,
}

/// A region's band pixels beside one other region.
#[derive(Clone, Debug, Serialize)]
pub struct BandBeside {
    /// The region across the change of source.
    pub region: &'static str,
    /// Over these pixels.
    pub quality: Quality,
    /// Their squared error over the band ceiling's (as
    /// [`RegionQuality::excess`]).
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

/// Per region shown (of `sums`, [band, interior] each, against the same of
/// `ceilings`), largest excess over the ceiling first, with its band split
/// by the region across the change of source (`beside`, per region and
/// neighbour, into [`RegionQuality::beside`]); `source_of` names the source
/// a region shows.
pub(super) fn region_figures(
    sums: &[[Sums; 2]; Region::COUNT],
    ceilings: &[[Sums; 2]; Region::COUNT],
    beside: &[[Sums; Region::COUNT]; Region::COUNT],
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
            let excess_over = |z: &Sums, c: &Sums| {
                let c = if c.pixels > 0 { c } else { &whole };
                Some((z.mse() - c.mse()) * z.pixels as f64)
                    .filter(|e| z.pixels > 0 && e.is_finite())
            };
            let excess = zones
                .iter()
                .zip(ceiling)
                .filter_map(|(z, c)| excess_over(z, c))
                .sum();
            let mut beside_parts: Vec<BandBeside> = Region::ALL
                .iter()
                .map(|n| (n, &beside[r.index()][n.index()]))
                .filter(|(_, s)| s.pixels > 0)
                .map(|(n, s)| BandBeside {
                    region: n.name(),
                    quality: s.quality(),
                    excess: excess_over(s, &ceiling[0]).unwrap_or(0.0),
                })
                .collect();
            beside_parts.sort_by(|a, b| b.excess.total_cmp(&a.excess));
            RegionQuality {
                region: r.name(),
                source: source_of(r),
                band: zones[0].quality(),
                interior: zones[1].quality(),
                ceiling_band_psnr_db: ceiling[0].quality().psnr_db,
                ceiling_interior_psnr_db: ceiling[1].quality().psnr_db,
                excess,
                beside: beside_parts,
            }
        })
        .collect();
    regions.sort_by(|a, b| b.excess.total_cmp(&a.excess));
    regions
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sums of `n` pixels each with squared error `sq` (over its channels).
    fn pixels(n: usize, sq: f64) -> Sums {
        let mut s = Sums::default();
        (0..n).for_each(|_| s.add(sq, 1.0, 0.0));
        s
    }

    #[test]
    fn a_bands_parts_beside_other_regions_add_up_to_its_excess() {
        let none = || [[Sums::default(); 2]; Region::COUNT];
        let (mut sums, mut ceilings) = (none(), none());
        let mut beside = [[Sums::default(); Region::COUNT]; Region::COUNT];
        let (hair, skin, ear, nose) = (
            Region::Hair.index(),
            Region::Skin.index(),
            Region::LeftEar.index(),
            Region::Nose.index(),
        );
        // The hair's band: 3 pixels beside the skin, 1 beside an ear, under a
        // band ceiling of squared error 0.03 a pixel.
        beside[hair][skin] = pixels(3, 0.3);
        beside[hair][ear] = pixels(1, 0.006);
        sums[hair][0] = pixels(3, 0.3);
        sums[hair][0].merge(&pixels(1, 0.006));
        ceilings[hair][0] = pixels(5, 0.03);
        // The nose's band ceiling is empty (its band falls elsewhere in its
        // source's own images): its part is told against its whole ceiling.
        beside[nose][skin] = pixels(2, 0.3);
        sums[nose][0] = pixels(2, 0.3);
        ceilings[nose][1] = pixels(4, 0.03);
        // The ear's source never shows it: no ceiling, no excess.
        beside[ear][hair] = pixels(1, 0.3);
        sums[ear][0] = pixels(1, 0.3);
        let regions = region_figures(&sums, &ceilings, &beside, |_| "x".into());
        let find = |name: &str| regions.iter().find(|r| r.region == name).unwrap();
        let hair = find("hair");
        let parts: Vec<(&str, f64)> = hair.beside.iter().map(|b| (b.region, b.excess)).collect();
        // Per pixel and channel: (0.1 − 0.01) × 3 beside the skin, (0.002 −
        // 0.01) × 1 beside the ear (better than the ceiling), costliest first.
        assert_eq!(parts[0].0, "skin");
        assert!((parts[0].1 - 0.27).abs() < 1e-12, "{parts:?}");
        assert!((parts[1].1 + 0.008).abs() < 1e-12, "{parts:?}");
        assert!((parts[0].1 + parts[1].1 - hair.excess).abs() < 1e-12);
        assert!((find("nose").beside[0].excess - 0.18).abs() < 1e-12);
        assert_eq!(find("left_ear").beside[0].excess, 0.0);
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
