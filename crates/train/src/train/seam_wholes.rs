//! The whole heads a seam fit's targets are drawn from (method §7.12): per
//! source, the recipe with every group's Gaussians from it — as the recipe
//! makes it, and across a seam with the source's own skin — ready to draw.

use crate::avatar::gaussians::GaussianSet;
use crate::compose::engine::{Composite, Engine};
use crate::compose::recipe::{Shading, SkinSource};
use crate::model::regions::{Group, Region};

use super::model::Trainable;
use super::seam_light::{self, KeptWhole};
use super::seam_own_shape as own_shape;

/// `set` to draw, with any Gaussian that holds a NaN or an infinity hidden
/// (opacity zero): it is not drawn, and the fit leaves it as it came — a
/// NaN is no value to step from, and a NaN pixel's gradient would reach
/// every Gaussian drawn there.
pub(super) fn drawable(set: &GaussianSet) -> Trainable {
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

/// A whole head from one source, as the recipe would make it, ready to draw.
pub(super) struct Whole {
    /// Its Gaussians as the fit draws them (non-finite ones hidden).
    pub(super) drawable: Trainable,
    /// The whole as the engine composed it.
    pub(super) composite: Composite,
    /// When the fit relights its targets per pixel (`seam_light`): the
    /// same whole with the light its Gaussians were trained under.
    pub(super) kept: Option<KeptWhole>,
    /// With `kept`: the same whole as each person's Gaussians sit on their
    /// own face (`seam_own_shape`), for the people whose face the
    /// composite's shape changed.
    pub(super) own_face: Option<KeptWhole>,
}

/// A source's whole head as each side of a seam asks for it.
pub(super) struct Wholes {
    /// As the recipe makes it: what the composite's Gaussians of this
    /// source draw, the target on the source's own side of a seam.
    pub(super) own: Whole,
    /// With the source's own skin under its features, for the target's
    /// far side where this source is the other one; `None` where that is
    /// `own` (the recipe keeps the sources' skin, or this is the base).
    pub(super) across: Option<Across>,
}

impl Wholes {
    /// Whether any of these wholes is drawn on its people's own faces too.
    pub(super) fn own_faces(&self) -> bool {
        self.own.own_face.is_some() || self.across.iter().any(|a| a.whole.own_face.is_some())
    }

    /// The sources whose Gaussians these wholes hold.
    pub(super) fn sources(&self) -> impl Iterator<Item = usize> + '_ {
        let across = self.across.iter().map(|a| &a.whole);
        std::iter::once(&self.own)
            .chain(across)
            .flat_map(|w| w.kept.iter().flat_map(|k| k.sources().iter().copied()))
    }
}

/// A source's whole head with its own skin, and how far the far side of a
/// seam may trust it.
pub(super) struct Across {
    /// The recipe's whole head from the source, with `skin = "source"`.
    pub(super) whole: Whole,
    /// Per region, the share of the far side taken from `whole` ([`trust`]).
    pub(super) trust: [f64; Region::COUNT],
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
pub(super) struct Drawn<'a> {
    /// [`Wholes::own`] drawn: RGB per pixel.
    pub(super) own: Vec<f64>,
    /// [`Wholes::across`] drawn, with its trust per region.
    pub(super) across: Option<(Vec<f64>, &'a [f64; Region::COUNT])>,
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
pub(super) fn blended(own: &Drawn, other: &Drawn, w: f64, i: usize, region: Region) -> f64 {
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
pub(super) fn wholes(engine: &Engine, composite: &Composite, source: u32) -> Wholes {
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
        let own_face = kept
            .as_ref()
            .filter(|kept| {
                kept.sources()
                    .iter()
                    .any(|&s| own_shape::reshaped(engine, &composite, s))
            })
            .map(|_| {
                let own = engine.compose(&own_shape::own_face_recipe(recipe));
                KeptWhole::new(&own, drawable(&own.gaussians))
            });
        Whole {
            drawable: drawable(&composite.gaussians),
            composite,
            kept,
            own_face,
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

#[cfg(test)]
mod tests {
    use super::*;

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
        use crate::train::seam_test_people::{name_of, ours, two_people};

        let engine = two_people(3_000);
        let (base, other) = (name_of(&engine, 0), name_of(&engine, 1));
        let mut recipe = ours(&format!(
            "base = \"{base}\"\n\
             [groups.mouth]\ngaussians = \"{other}\"\nshape = {{ {other} = 1.0 }}\n"
        ));
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
