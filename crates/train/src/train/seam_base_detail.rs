//! The base's skin detail in a seam fit's targets, pixel by pixel (method
//! §7.12, "The base's detail, pixel by pixel").
//!
//! Under `skin = "base"` a swapped region's skin should wear the base's tone
//! *and detail* (§7.11): its freckles, pores and blotches, not the source's
//! own, which the colour transfer scales together with what the source's
//! training got wrong (§13.3). The composer puts the base's Gaussians there
//! triangle by triangle, and keeps the source's wherever a feature of either
//! side stands on or beside the triangle, and where the base's Gaussians do
//! not fit the new shape — round the eyes nearly everywhere, on a swapped
//! ear. A target is drawn pixel by pixel, and there the two can be told
//! apart more finely: where the target (the swapped source's whole,
//! cross-faded across a seam with the nearest other person's) and the
//! base's whole, both drawn on the composite's shape, show the same skin up
//! to its detail,
//! the target takes the base's pixel; where they differ by more than skin
//! detail does — a brow, a lash, a lid's crease, either side's — or are
//! unlike over a patch — stubble, a blush — it keeps the source's.

use crate::model::geometry::smoothstep;
use crate::model::regions::Region;

/// Half the side of the square window whose mean difference tells a patch
/// of one side's feature from the other's skin detail: 5×5 pixels.
const WINDOW: i64 = 2;

/// Where a window's mean difference, relative to the base's mean there,
/// starts and finishes keeping the source's pixel: a patch of stubble or a
/// brow moves the mean, freckles and a source's training error (zero on
/// average) hardly do.
const PATCH: (f32, f32) = (0.06, 0.15);

/// Where one pixel's difference, relative to the base's colour, starts and
/// finishes keeping the source's pixel: a lash or a brow's hair, too thin to
/// move a window's mean.
const PIXEL: (f32, f32) = (0.3, 0.6);

/// The least base colour a relative difference divides by: near black a
/// difference is measured against 0.05, so that a few hundredths between
/// two dark pixels read as the same skin, and no division blows up.
const FLOOR: f64 = 0.05;

/// Whether a target pixel may take the base's skin detail: under `skin =
/// "base"` with the base shown (`base`, its database index, from
/// `SeamFitter`), on a point wearing another source (`own`), whether a seam
/// cross-fades it with another source's whole or not (the window tells
/// there too whether the mix shows the base's skin; since session 57), in
/// a region that may wear the base's skin: the face's skin, the nose, the
/// ears, the eyes' regions and sockets, and the remainder (the temples,
/// sideburns and nape beside the hair, skin wherever a swapped hair group's
/// hair leaves them bare; since session 57). Not the regions that hold no
/// skin (the hair itself, whose base's hair can read as alike to the
/// source's; eyeballs, teeth, the mouth's inside), nor the lips and the
/// boundary, whose skin shares are the source's features by design; not
/// the neck, where the base's own stubble and collar read as skin beside
/// the source's (jomo's black stubble on femi's neck gave way to femi's
/// grey). Method §7.12 has what each choice measured.
pub(super) fn takes_base_detail(base: Option<u32>, own: u32, region: Region) -> bool {
    base.is_some_and(|b| b != own)
        && !matches!(
            region,
            Region::Hair
                | Region::Neck
                | Region::Boundary
                | Region::Lips
                | Region::LipsInside
                | Region::TeethUpper
                | Region::TeethLower
                | Region::LeftEyeball
                | Region::RightEyeball
        )
}

/// `goal` (RGB per pixel, row by row, `width` pixels a row) moved, at each
/// pixel where `eligible`, towards `base` (the base's whole drawn in the same
/// view) by how alike the two are: the base's pixel where they show the same
/// skin, the goal's where they differ by more than skin detail does, over a
/// window of eligible pixels or at the pixel itself (the module's doc). A
/// pixel holding a value that is not finite is left as it is and counts for
/// no window.
pub(super) fn with_base_detail(goal: &mut [f64], base: &[f64], eligible: &[bool], width: usize) {
    let pixels = eligible.len().min(goal.len() / 3).min(base.len() / 3);
    let finite =
        |p: usize| (0..3).all(|c| goal[3 * p + c].is_finite() && base[3 * p + c].is_finite());
    let counts: Vec<bool> = (0..pixels).map(|p| eligible[p] && finite(p)).collect();
    let height = pixels / width.max(1);
    let mut out = goal[..3 * pixels].to_vec();
    for p in (0..pixels).filter(|&p| counts[p]) {
        let (x, y) = ((p % width) as i64, (p / width) as i64);
        let (mut difference, mut colour, mut n) = ([0.0f64; 3], [0.0f64; 3], 0.0);
        for v in (y - WINDOW).max(0)..=(y + WINDOW).min(height as i64 - 1) {
            for u in (x - WINDOW).max(0)..=(x + WINDOW).min(width as i64 - 1) {
                let q = v as usize * width + u as usize;
                if !counts[q] {
                    continue;
                }
                for c in 0..3 {
                    difference[c] += goal[3 * q + c] - base[3 * q + c];
                    colour[c] += base[3 * q + c];
                }
                n += 1.0;
            }
        }
        // Every pixel counted is finite, so are the sums and these.
        let relative = |d: f64, b: f64| d.abs() / b.max(FLOOR);
        let patch = (0..3)
            .map(|c| relative(difference[c] / n, colour[c] / n))
            .fold(0.0, f64::max);
        let pixel = (0..3)
            .map(|c| relative(goal[3 * p + c] - base[3 * p + c], base[3 * p + c]))
            .fold(0.0, f64::max);
        let keep = f64::from(smoothstep(PATCH.0, PATCH.1, patch as f32).max(smoothstep(
            PIXEL.0,
            PIXEL.1,
            pixel as f32,
        )));
        for c in 0..3 {
            let (g, b) = (goal[3 * p + c], base[3 * p + c]);
            // Exactly either side at a keep of 0 or 1.
            out[3 * p + c] = keep * g + (1.0 - keep) * b;
        }
    }
    goal[..3 * pixels].copy_from_slice(&out);
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: usize = 12;

    /// A 12×12 view of skin at `skin` everywhere, every pixel eligible.
    fn view(skin: [f64; 3]) -> (Vec<f64>, Vec<bool>) {
        (skin.repeat(W * W), vec![true; W * W])
    }

    fn at(image: &[f64], x: usize, y: usize) -> [f64; 3] {
        let p = y * W + x;
        [image[3 * p], image[3 * p + 1], image[3 * p + 2]]
    }

    fn set(image: &mut [f64], x: usize, y: usize, rgb: [f64; 3]) {
        let p = y * W + x;
        image[3 * p..3 * p + 3].copy_from_slice(&rgb);
    }

    #[test]
    fn skin_alike_up_to_its_detail_takes_the_bases_pixels() {
        // The source's skin carries its own noise (±3 %), the base's its
        // freckles: the target wears the base's.
        let (mut goal, eligible) = view([0.70, 0.55, 0.45]);
        let (mut base, _) = view([0.70, 0.55, 0.45]);
        for y in 0..W {
            for x in 0..W {
                let noise = if (x + y) % 2 == 0 { 1.03 } else { 0.97 };
                set(&mut goal, x, y, [0.70 * noise, 0.55 * noise, 0.45 * noise]);
            }
        }
        set(&mut base, 5, 5, [0.60, 0.47, 0.38]);
        set(&mut base, 8, 3, [0.62, 0.48, 0.40]);
        let expected = base.clone();
        with_base_detail(&mut goal, &base, &eligible, W);
        for (g, b) in goal.iter().zip(&expected) {
            assert!((g - b).abs() < 1e-12, "{g} against the base's {b}");
        }
    }

    #[test]
    fn a_patch_of_the_sources_feature_and_a_thin_line_stay_the_sources() {
        // A brow-like patch 20 % darker over 5×5 pixels (each pixel under the
        // single-pixel edge), and a lash: one pixel at 0.35 of the skin.
        let skin = [0.70, 0.55, 0.45];
        let (mut goal, eligible) = view(skin);
        let (base, _) = view(skin.map(|c| 0.99 * c));
        for y in 0..5 {
            for x in 0..5 {
                set(&mut goal, x, y, skin.map(|c| 0.8 * c));
            }
        }
        set(&mut goal, 9, 9, skin.map(|c| 0.35 * c));
        let before = goal.clone();
        with_base_detail(&mut goal, &base, &eligible, W);
        assert_eq!(at(&goal, 2, 2), at(&before, 2, 2), "the patch's middle");
        assert_eq!(at(&goal, 9, 9), at(&before, 9, 9), "the lash");
        // Far from both, skin alike: the base's.
        assert_eq!(at(&goal, 11, 0), at(&base, 11, 0));
    }

    #[test]
    fn pixels_not_eligible_or_not_finite_are_left_and_count_for_no_window() {
        let skin = [0.70, 0.55, 0.45];
        let (mut goal, mut eligible) = view(skin);
        let (mut base, _) = view([0.69, 0.55, 0.45]);
        // Not eligible: a dark feature the window would otherwise see.
        for y in 0..W {
            eligible[y * W + 6] = false;
            set(&mut goal, 6, y, [0.1, 0.05, 0.05]);
        }
        set(&mut base, 2, 9, [f64::NAN, 0.5, 0.4]);
        set(&mut goal, 2, 2, [f64::INFINITY, 0.5, 0.4]);
        let before = goal.clone();
        with_base_detail(&mut goal, &base, &eligible, W);
        assert_eq!(at(&goal, 6, 2), at(&before, 6, 2));
        assert_eq!(at(&goal, 2, 9), at(&before, 2, 9), "beside a NaN base");
        assert!(at(&goal, 2, 2)[0].is_infinite());
        // Their neighbours' windows leave them, the dark column and the
        // not-finite pixels, out: skin alone, the base's pixel.
        for (x, y) in [(5, 8), (7, 8), (2, 3), (3, 2), (2, 8), (3, 9)] {
            assert_eq!(at(&goal, x, y), [0.69, 0.55, 0.45], "({x}, {y})");
        }
    }

    #[test]
    fn near_black_a_few_hundredths_read_as_alike_and_more_as_a_feature() {
        // Measured against a floor of 0.05, not against the base's colour:
        // a dark pixel 0.01 off the base's dark skin shows the same skin (the
        // base's; against the base's 0.02 it would differ by half), a view
        // 0.04 above black does not (the source's), and black stays.
        let (base, eligible) = view([0.02, 0.02, 0.02]);
        let mut goal = base.clone();
        set(&mut goal, 6, 6, [0.03, 0.03, 0.03]);
        with_base_detail(&mut goal, &base, &eligible, W);
        assert_eq!(goal, base);
        let (black, _) = view([0.0; 3]);
        let (mut goal, _) = view([0.04, 0.03, 0.03]);
        let before = goal.clone();
        with_base_detail(&mut goal, &black, &eligible, W);
        assert_eq!(goal, before);
        let (mut still, _) = view([0.0; 3]);
        with_base_detail(&mut still, &black, &eligible, W);
        assert!(still.iter().all(|&g| g == 0.0));
    }

    #[test]
    fn only_a_swapped_sources_skin_takes_it() {
        let base = Some(0);
        for region in [
            Region::LeftEyeRegion,
            Region::RightEyeSocket,
            Region::Nose,
            Region::LeftEar,
            Region::Skin,
            Region::Remainder,
        ] {
            assert!(takes_base_detail(base, 1, region), "{region:?}");
            // On the base's own points, without a base whole.
            assert!(!takes_base_detail(base, 0, region), "{region:?}");
            assert!(!takes_base_detail(None, 1, region), "{region:?}");
        }
        for region in [
            Region::Hair,
            Region::Neck,
            Region::Lips,
            Region::LipsInside,
            Region::TeethLower,
            Region::LeftEyeball,
            Region::Boundary,
        ] {
            assert!(!takes_base_detail(base, 1, region), "{region:?}");
        }
    }
}
