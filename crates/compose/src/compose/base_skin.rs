//! The base's skin under a swapped source's features (`skin = "base"`,
//! docs/method.md §7.11): how surely each Gaussian is skin, how much of each
//! triangle a source shows is skin, and how fully the base's skin takes over
//! there — so that a swapped region shows its source's lips, brows, lashes,
//! iris, hair and beard over the base's own skin where the base's shape and
//! both sides' skin allow it.

use glam::Vec3;
use rayon::prelude::*;

use super::colour::{semantic_skin_likeness, SkinStats};
use super::recipe::ResolvedRecipe;
use crate::model::geometry::smoothstep;
use crate::model::regions::Region;

/// The skin shares triangles' mean likeness must reach, on both sides, for
/// the base's skin to take over (smoothly between the two): where either
/// shows a feature (lips, brows, beard, a collar) the source keeps its own.
pub const BOTH_SKIN: (f32, f32) = (0.5, 0.9);

/// Under `skin = "base"` (docs/method.md §7.11): the share of its opacity a
/// Gaussian of a swapped region keeps. A source's Gaussian gives up the part
/// that is skin where the base's skin takes over; a base's Gaussian shows the
/// part that is skin there.
#[derive(Clone, Copy, Debug)]
pub struct SkinShare<'e> {
    /// Per Gaussian of the block's source: how surely it is skin.
    pub likeness: &'e [f32],
    /// Per triangle: how fully the base's skin takes over there.
    pub confidence: &'e [f32],
    /// Whether the block is the base's skin (else the source's Gaussians).
    pub of_base: bool,
}

/// Gaussians whose share is at most this are left out: invisible (under
/// 0.5 % opacity), they would only cost drawing.
pub const SHARE_FLOOR: f32 = 1e-3;

impl SkinShare<'_> {
    /// The share Gaussian `i`, counted for triangle `t`, keeps.
    pub fn of(&self, i: u32, t: u32) -> f32 {
        let taken = self.likeness[i as usize] * self.confidence[t as usize];
        if self.of_base {
            taken
        } else {
            1.0 - taken
        }
    }

    /// Whether Gaussian `i`, counted for triangle `t`, shows at all.
    pub fn shows(&self, i: u32, t: u32) -> bool {
        self.of(i, t) > SHARE_FLOOR
    }
}

/// Per Gaussian: how surely it is skin, by its source's skin statistics
/// `stats` and the region of the triangle it counts for (`counted`, indexing
/// `regions`), from its colour as the cameras saw it (method §7.7); all 0
/// for a source without skin statistics.
pub fn skin_likeness(
    colours: &[Vec3],
    counted: &[u32],
    regions: &[Region],
    stats: Option<&SkinStats>,
) -> Vec<f32> {
    let Some(stats) = stats else {
        return vec![0.0; colours.len()];
    };
    colours
        .par_iter()
        .zip(counted)
        .map(|(&rgb, &t)| {
            let region = regions.get(t as usize).copied();
            region
                .and_then(|r| semantic_skin_likeness(rgb, r, stats))
                .unwrap_or(0.0)
        })
        .collect()
}

/// Per triangle (of `triangles`): how much of what a source shows there is
/// skin — its Gaussians' `likeness`, weighted by `weights` (a mean colour's,
/// method §7.5); 0 where none counts.
pub fn triangle_skin(
    counted: &[u32],
    likeness: &[f32],
    weights: &[f32],
    triangles: usize,
) -> Vec<f32> {
    let (mut skin, mut total) = (vec![0.0f32; triangles], vec![0.0f32; triangles]);
    for ((&t, &k), &w) in counted.iter().zip(likeness).zip(weights) {
        if let (Some(s), Some(n)) = (skin.get_mut(t as usize), total.get_mut(t as usize)) {
            *s += k * w;
            *n += w;
        }
    }
    skin.iter()
        .zip(&total)
        .map(|(&s, &n)| if n > 0.0 { s / n } else { 0.0 })
        .collect()
}

/// Per triangle (region `regions[t]`): how fully the base's skin takes over
/// from the skin of the source the triangle's region shows — the base's
/// share of the group's shape (Gaussians fit the shape they were trained on)
/// times how surely both show skin there; 0 where the region shows the base.
/// `skin_of(s)` is source s's [`triangle_skin`].
pub fn base_skin_confidence<'a>(
    recipe: &ResolvedRecipe,
    regions: &[Region],
    skin_of: impl Fn(usize) -> &'a [f32],
) -> Vec<f32> {
    let base = skin_of(recipe.base);
    regions
        .iter()
        .enumerate()
        .map(|(t, &region)| {
            let group = region.group().index();
            let f = recipe.gaussians[group];
            if f == recipe.base {
                return 0.0;
            }
            let shape = recipe.shape[group].get(recipe.base).copied().unwrap_or(0.0) as f32;
            let both = skin_of(f)[t].min(base[t]);
            shape * smoothstep(BOTH_SKIN.0, BOTH_SKIN.1, both)
        })
        .collect()
}

/// The Gaussians of `all` (counted for the triangles `counted`) that show
/// under `share`.
pub fn showing(share: SkinShare, all: &[u32], counted: &[u32]) -> Vec<u32> {
    all.iter()
        .copied()
        .filter(|&i| share.shows(i, counted[i as usize]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::colour::srgb_to_lab;
    use crate::model::regions::Group;

    fn stats(rgb: Vec3) -> SkinStats {
        let lab = srgb_to_lab(rgb);
        SkinStats {
            mean: lab,
            tone: lab,
            hair: None,
        }
    }

    #[test]
    fn likeness_is_skin_for_the_skin_and_none_for_lips_black_nan_or_no_stats() {
        let skin = Vec3::new(0.8, 0.6, 0.5);
        let colours = [skin, Vec3::new(0.5, 0.1, 0.12), Vec3::ZERO, Vec3::NAN, skin];
        let regions = [Region::Nose, Region::Lips];
        let counted = [0, 1, 0, 0, 7];
        let k = skin_likeness(&colours, &counted, &regions, Some(&stats(skin)));
        assert_eq!(k[0], 1.0);
        assert_eq!(k[1], 0.0, "lips are no skin");
        assert_eq!(k[2], 0.0, "black is no skin");
        assert_eq!(k[3], 0.0, "NaN is no skin");
        assert_eq!(k[4], 0.0, "a triangle past the model is no skin");
        assert_eq!(skin_likeness(&colours, &counted, &regions, None), [0.0; 5]);
    }

    #[test]
    fn triangle_skin_is_the_weighted_mean_and_zero_where_nothing_counts() {
        let counted = [0, 0, 2, 9];
        let likeness = [1.0, 0.0, 0.5, 1.0];
        let weights = [3.0, 1.0, 0.0, 1.0];
        let t = triangle_skin(&counted, &likeness, &weights, 3);
        assert_eq!(t, [0.75, 0.0, 0.0]);
    }

    #[test]
    fn the_base_takes_over_by_its_shape_weight_where_both_show_skin() {
        let mut recipe = ResolvedRecipe {
            base: 0,
            gaussians: [0; Group::COUNT],
            shape: std::array::from_fn(|_| vec![1.0, 0.0, 0.0]),
            post: Default::default(),
            motion: None,
            frame: 0,
            mode: Default::default(),
            offsets: Default::default(),
            camera: Default::default(),
        };
        let nose = Group::Nose.index();
        recipe.gaussians[nose] = 1;
        let regions = [Region::Nose, Region::Nose, Region::Skin, Region::Nose];
        let skin_of = |s: usize| -> &'static [f32] {
            match s {
                0 => &[1.0, 1.0, 1.0, 0.2],
                _ => &[1.0, 0.7, 1.0, 1.0],
            }
        };
        for (weights, expected) in [
            (
                vec![1.0, 0.0, 0.0],
                [1.0, smoothstep(0.5, 0.9, 0.7), 0.0, 0.0],
            ),
            (
                vec![0.5, 0.5, 0.0],
                [0.5, 0.5 * smoothstep(0.5, 0.9, 0.7), 0.0, 0.0],
            ),
            (vec![0.0, 1.0, 0.0], [0.0; 4]),
        ] {
            recipe.shape[nose] = weights;
            let c = base_skin_confidence(&recipe, &regions, skin_of);
            for (got, want) in c.iter().zip(expected) {
                assert!((got - want).abs() < 1e-6, "{c:?} against {expected:?}");
            }
        }
    }

    #[test]
    fn shares_split_a_skin_gaussian_between_source_and_base_and_leave_features() {
        let likeness = [1.0, 0.0, 0.25];
        let confidence = [1.0, 0.5];
        let source = SkinShare {
            likeness: &likeness,
            confidence: &confidence,
            of_base: false,
        };
        let base = SkinShare {
            of_base: true,
            ..source
        };
        assert_eq!((source.of(0, 0), base.of(0, 0)), (0.0, 1.0));
        assert_eq!((source.of(1, 0), base.of(1, 0)), (1.0, 0.0));
        assert_eq!((source.of(2, 1), base.of(2, 1)), (0.875, 0.125));
        assert_eq!(showing(source, &[0, 1, 2], &[0, 0, 1]), [1, 2]);
        assert_eq!(showing(base, &[0, 1, 2], &[0, 0, 1]), [0, 2]);
    }
}
