//! What each pixel of a view shows: the head, the region and its assigned
//! source, the border band; and the pictures drawn from them.

use glam::{DVec3, Vec3};

use crate::compose::recipe::ResolvedRecipe;
use crate::error::{Error, Result};
use crate::model::head::HeadModel;
use crate::model::regions::Region;
use crate::render::image::RgbImage;
use crate::train::capture::visible_triangles;
use crate::train::dataset::View;
use crate::train::hole_metrics::lab;
use crate::train::project::TrainCamera;

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

/// Per pixel: what the ground truth shows there.
pub(super) struct Labels {
    /// The head (mask over half) with a triangle under it.
    pub(super) head: Vec<bool>,
    /// The region shown.
    pub(super) region: Vec<Option<Region>>,
    /// The source assigned there (`u32::MAX` off the head).
    pub(super) source: Vec<u32>,
    /// Within the border band.
    pub(super) band: Vec<bool>,
    /// In the band: the region across the change of source (see
    /// [`band_beside`]); `None` elsewhere.
    pub(super) beside: Vec<Option<Region>>,
}

/// What each pixel of a view (`camera`, its foreground `mask`) shows of the
/// ground truth's posed mesh `truth`, and the band `border_px` wide round
/// the places where `recipe` changes source.
pub(super) fn labels(
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
    // The band is where something lies across: one scan gives both.
    let beside = band_beside(&source, &region, camera.size, border_px);
    let band = beside.iter().map(Option::is_some).collect();
    Labels {
        head,
        region,
        source,
        band,
        beside,
    }
}

/// Per pixel within `k` pixels (a square window) of a pixel showing another
/// source — the band, as [`band`] marks it, `region` showing a region
/// wherever `source` names one — the region shown most often by the pixels
/// of another source in that window, ties to the first in [`Region::ALL`]
/// order; `None` outside the band, so the band is where this is `Some`. It says what a band pixel borders — a hairline's hair borders
/// skin, a swapped ear's rim borders hair — so the band's error can be told
/// apart by the seam it lies at.
pub(super) fn band_beside(
    source: &[u32],
    region: &[Option<Region>],
    size: [u32; 2],
    k: u32,
) -> Vec<Option<Region>> {
    let [w, h] = [size[0] as i64, size[1] as i64];
    let k = k as i64;
    let mut out = vec![None; source.len()];
    for (p, slot) in out.iter_mut().enumerate() {
        if source[p] == u32::MAX {
            continue;
        }
        let (x, y) = (p as i64 % w, p as i64 / w);
        let mut counts = [0u32; Region::COUNT];
        for yy in (y - k).max(0)..=(y + k).min(h - 1) {
            for xx in (x - k).max(0)..=(x + k).min(w - 1) {
                let q = (yy * w + xx) as usize;
                if source[q] != u32::MAX && source[q] != source[p] {
                    if let Some(r) = region[q] {
                        counts[r.index()] += 1;
                    }
                }
            }
        }
        let most = counts.iter().copied().max().unwrap_or(0);
        *slot = (most > 0)
            .then(|| Region::ALL.into_iter().find(|r| counts[r.index()] == most))
            .flatten();
    }
    out
}

/// Per pixel: the region of the triangle `shown` there, if any.
pub(super) fn shown_regions(shown: &[Option<u32>], model: &HeadModel) -> Vec<Option<Region>> {
    shown
        .iter()
        .map(|t| t.map(|t| model.triangle_regions[t as usize]))
        .collect()
}

/// Per pixel: the source the recipe assigns the region shown there
/// (`u32::MAX` where no region is).
pub(super) fn assigned_sources(region: &[Option<Region>], recipe: &ResolvedRecipe) -> Vec<u32> {
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

/// The colour of pixel `p` of an interleaved RGB image.
pub(super) fn rgb(image: &[f64], p: usize) -> DVec3 {
    DVec3::new(image[3 * p], image[3 * p + 1], image[3 * p + 2])
}

/// A view's foreground mask (all foreground without one).
pub(super) fn read_mask(view: &View, pixels: usize) -> Result<Vec<u8>> {
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
pub(super) fn picture(goal: &[f64], image: &[f64], head: &[bool], w: u32, h: u32) -> [RgbImage; 3] {
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
    fn a_band_pixel_borders_the_region_most_shown_across_the_change() {
        // Source 0 shows the hair (top row); source 1 the skin and, at the
        // right, an ear; the background (last column) is no source.
        let (m, hair, skin, ear) = (u32::MAX, Region::Hair, Region::Skin, Region::LeftEar);
        let source = [
            0, 0, 0, 0, m, //
            1, 1, 1, 1, m, //
            1, 1, 1, 1, m,
        ];
        let region = [
            Some(hair),
            Some(hair),
            Some(hair),
            Some(hair),
            None, //
            Some(skin),
            Some(skin),
            Some(skin),
            Some(ear),
            None, //
            Some(skin),
            Some(skin),
            Some(skin),
            Some(ear),
            None,
        ];
        let b = band(&source, [5, 3], 1);
        let beside = band_beside(&source, &region, [5, 3], 1);
        // The band is exactly where something lies across.
        let across: Vec<bool> = beside.iter().map(Option::is_some).collect();
        assert_eq!(across, b);
        // The hair above skin borders skin; at the right end, its window
        // holds one skin and one ear pixel of the other source: the tie goes
        // to the region first in order (LeftEar before Skin).
        assert_eq!(
            &beside[..4],
            &[Some(skin), Some(skin), Some(skin), Some(ear)]
        );
        assert_eq!(&beside[5..9], &[Some(hair); 4]);
        assert!(beside[10..].iter().all(Option::is_none), "{beside:?}");
        assert_eq!(beside[4], None, "the background has no band");
    }
}
