//! Clothing mixed into skin Gaussians at a collar's edge (docs/method.md
//! §7.7, its clothing bullet).
//!
//! A trained Gaussian on the collar's edge shows part skin, part shirt. The
//! skin likeness reads it as no skin, or half, and leaves it at or near the
//! source's tone, which leaves a line of neither along the collar: too dark
//! on a light base, too light on a dark one. Skin and shirt are two
//! materials under the same light, so in linear light such a colour is a
//! sum c = a·χ_s + b·χ_x of the skin's chromaticity χ_s (colour over the sum
//! of its channels) and the shirt's χ_x, and its own chromaticity lies on
//! the segment between the two, a share t = a / (a + b) of the way from the
//! shirt's: the share of c's brightness that is skin. The transfer then
//! takes c that share of the way towards c moved in full, c + t·(c·ρ − c),
//! as the dark features' share does round the eyes (`dark_features`).
//! Per channel that also scales the shirt's part by t·(ρ − 1); moving the
//! skin's part alone, t·(Σc)·χ_s·(ρ − 1), is exact for a linear mix but
//! measured worse on the bench (method §7.7).
//!
//! The skin's chromaticity is read where the Gaussian sits, from the source's
//! fitted light (`BakedLight::brightness`), since a coloured light tints
//! shaded skin; the shirt's is the mean of the region's Gaussians that are
//! surely not skin, where they are a fair part of the region (a few stray
//! ones, a shadow or a beard on a bare neck, are no clothing). A colour off
//! the line through the two — a grey beard's stubble on the neck, a third
//! material — is not a mix of them and keeps the skin likeness's
//! transfer; one on the line past the skin's end (a flush, redder than the
//! skin) counts as all skin.

use glam::Vec3;

use super::colour::{chromaticity, srgb_to_linear};
use crate::model::regions::Region;

/// Skin likeness under which a Gaussian counts as clothing for the
/// clothing's mean colour.
pub const NOT_SKIN: f32 = 0.05;

/// How far apart (chromaticity distance) skin and clothing must be for a
/// colour's place between them to be read.
pub const CLOTHING_APART: f32 = 0.08;

/// How far off the line through clothing and skin (chromaticity distance,
/// in units of their distance) a colour may lie and still count as a mix
/// of the two. Measured (method §7.7): 0.04, 0.15 and 0.3 moved
/// random-04's neck less, no bound lost 3.3 dB in its band.
pub const OFF_LINE: f32 = 0.08;

/// The regions where the source's clothing meets its skin: the neck, whose
/// lower edge the collar crosses. Not the boundary (the ring under it, all
/// collar in the built-in people): with it random-05 lost 0.10 dB.
pub fn holds_clothing(region: Region) -> bool {
    region == Region::Neck
}

/// The least share of a region's colour weight its Gaussians surely not
/// skin must hold to be taken for clothing. Every built-in person's collar
/// holds far more of the neck.
pub const CLOTHING_SHARE: f32 = 0.1;

/// Accumulates the mean linear colour of a region's clothing: the
/// Gaussians surely not skin.
#[derive(Clone, Copy, Debug, Default)]
pub struct ClothingMean {
    sum: Vec3,
    weight: f32,
    /// The weight of every Gaussian counted, skin or not.
    total: f32,
}

impl ClothingMean {
    /// Counts a Gaussian of display colour `seen`, skin likeness `likeness`
    /// and mean-colour weight `weight`: only if it is surely not skin.
    pub fn add(&mut self, seen: Vec3, likeness: f32, weight: f32) {
        // Clamping would turn NaN into a colour: check first.
        if !(seen.is_finite() && weight.is_finite() && weight > 0.0) {
            return;
        }
        self.total += weight;
        if likeness < NOT_SKIN {
            self.sum += weight * srgb_to_linear(seen.clamp(Vec3::ZERO, Vec3::ONE));
            self.weight += weight;
        }
    }

    /// The weighted mean linear colour of what is surely not skin, `None`
    /// where that is under [`CLOTHING_SHARE`] of the region's weight.
    /// Collar edges too little skin-like for the likeness count in it and
    /// pull it towards the skin; taking the purer half of the counted
    /// colours instead measured worse (method §7.7).
    pub fn mean(&self) -> Option<Vec3> {
        (self.weight > 0.0 && self.weight >= CLOTHING_SHARE * self.total)
            .then(|| self.sum / self.weight)
    }
}

/// The share of a colour's brightness that is skin, for display colour
/// `seen` on a surface where the source's skin shows display colour `skin`
/// and beside clothing of mean linear colour `clothing` (module doc): its
/// chromaticity's place on the line from the clothing's (0) to the skin's
/// (1), clamped to [0, 1]. `None` where the two are too close in
/// chromaticity to tell ([`CLOTHING_APART`]), where the colour lies off the
/// line ([`OFF_LINE`]), and for colours too dark or broken to have a
/// chromaticity.
pub fn skin_share_beside_clothing(seen: Vec3, skin: Vec3, clothing: Vec3) -> Option<f32> {
    // Clamping would turn NaN and infinities into colours.
    if !(seen.is_finite() && skin.is_finite()) {
        return None;
    }
    let skin = chromaticity(srgb_to_linear(skin.clamp(Vec3::ZERO, Vec3::ONE)))?;
    let clothing = chromaticity(clothing)?;
    let colour = chromaticity(srgb_to_linear(seen.clamp(Vec3::ZERO, Vec3::ONE)))?;
    let axis = skin - clothing;
    let apart = axis.length();
    // NaN (a broken clothing colour) fails this too.
    if apart.is_nan() || apart <= CLOTHING_APART {
        return None;
    }
    let along = (colour - clothing).dot(axis) / (apart * apart);
    let off = (colour - clothing - along * axis).length();
    (off <= OFF_LINE * apart).then(|| along.clamp(0.0, 1.0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::colour::linear_to_srgb;

    const SKIN: Vec3 = Vec3::new(0.53, 0.36, 0.25);
    const TEAL: Vec3 = Vec3::new(0.16, 0.45, 0.42);

    /// A colour whose linear light is a share `skin_share` of `brightness`
    /// (channel sum) skin, the rest teal.
    fn mix_in_linear(skin_share: f32, brightness: f32) -> Vec3 {
        let unit = |c: Vec3| {
            let l = srgb_to_linear(c);
            l / l.element_sum()
        };
        linear_to_srgb(brightness * (skin_share * unit(SKIN) + (1.0 - skin_share) * unit(TEAL)))
    }

    #[test]
    fn a_collar_edge_reads_as_the_share_of_its_light_that_is_skin() {
        let teal = srgb_to_linear(TEAL);
        for share in [0.0, 0.25, 0.5, 0.9, 1.0] {
            for brightness in [0.05, 0.4, 1.2] {
                let seen = mix_in_linear(share, brightness);
                let got = skin_share_beside_clothing(seen, SKIN, teal).unwrap();
                assert!((got - share).abs() < 1e-3, "{share} of {brightness}: {got}");
            }
        }
        // Shading (a factor on linear light) leaves the share alone: skin in
        // shadow is all skin.
        let shadow = linear_to_srgb(srgb_to_linear(SKIN) * 0.1);
        let shaded = skin_share_beside_clothing(shadow, SKIN, teal).unwrap();
        assert!((shaded - 1.0).abs() < 1e-3, "{shaded}");
        // Past the skin's end clamps.
        let redder = Vec3::new(0.6, 0.3, 0.18);
        assert_eq!(skin_share_beside_clothing(redder, SKIN, teal), Some(1.0));
        // A white shirt's edge, brighter than the skin: read all the same.
        let edge = linear_to_srgb(0.5 * srgb_to_linear(SKIN) + Vec3::splat(0.5));
        let share = skin_share_beside_clothing(edge, SKIN, Vec3::ONE).unwrap();
        let skin = srgb_to_linear(SKIN).element_sum();
        let want = 0.5 * skin / (0.5 * skin + 1.5);
        assert!((share - want).abs() < 1e-3, "{share} for {want}");
    }

    #[test]
    fn a_third_material_close_colours_and_black_are_not_read() {
        let teal = srgb_to_linear(TEAL);
        // Grey stubble lies off the line through teal and brown skin.
        assert_eq!(
            skin_share_beside_clothing(Vec3::splat(0.39), SKIN, teal),
            None
        );
        // A shirt of the skin's own hue.
        let brown = srgb_to_linear(SKIN * 0.8);
        assert_eq!(skin_share_beside_clothing(SKIN * 0.9, SKIN, brown), None);
        // Black and broken colours have no chromaticity.
        for seen in [Vec3::ZERO, Vec3::NAN, Vec3::splat(f32::INFINITY)] {
            assert_eq!(skin_share_beside_clothing(seen, SKIN, teal), None);
        }
        assert_eq!(skin_share_beside_clothing(SKIN, SKIN, Vec3::NAN), None);
        assert_eq!(skin_share_beside_clothing(SKIN, Vec3::ZERO, teal), None);
        assert_eq!(skin_share_beside_clothing(SKIN, Vec3::NAN, teal), None);
    }

    #[test]
    fn the_clothing_is_the_mean_of_what_is_surely_not_skin() {
        let mut mean = ClothingMean::default();
        assert_eq!(mean.mean(), None);
        mean.add(SKIN, 0.9, 1.0);
        mean.add(SKIN, NOT_SKIN, 1.0);
        assert_eq!(mean.mean(), None);
        mean.add(TEAL, 0.0, 3.0);
        mean.add(Vec3::ONE, 0.01, 1.0);
        let bad = [f32::NAN, f32::INFINITY, 0.0, -1.0];
        for (seen, weight) in [(Vec3::NAN, 1.0)].into_iter().chain(bad.map(|w| (TEAL, w))) {
            mean.add(seen, 0.0, weight);
        }
        let want = (3.0 * srgb_to_linear(TEAL) + Vec3::ONE) / 4.0;
        assert!((mean.mean().unwrap() - want).abs().max_element() < 1e-6);
    }

    #[test]
    fn a_few_stray_colours_on_a_bare_neck_are_no_clothing() {
        let mut neck = ClothingMean::default();
        for _ in 0..95 {
            neck.add(SKIN, 1.0, 1.0);
        }
        // A shadow and some stubble: 5 % of the neck.
        for _ in 0..5 {
            neck.add(SKIN * 0.2, 0.0, 1.0);
        }
        assert_eq!(neck.mean(), None);
        // A collar over a tenth of it is.
        for _ in 0..6 {
            neck.add(TEAL, 0.0, 1.0);
        }
        assert!(neck.mean().is_some());
    }
}
