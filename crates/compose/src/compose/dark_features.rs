//! Dark features — brows, lashes, hair, stubble — mixed into skin Gaussians
//! (docs/method.md §7.7's last bullets and §7.11): how much of a Gaussian's
//! colour and of its area is skin, by its brightness against the source's
//! fitted light and the brightness of its hair, or, where the hair's hue
//! tells it from the skin, by the colour itself. A brightening transfer moves
//! only the skin's share round the eyes and on the hairline, a darkening one
//! round the eyes where the likeness calls a colour no skin; the base's skin
//! stands in only for the skin's area on the neck.
//!
//! A trained Gaussian on a brow's edge shows part skin, part brow. The skin
//! transfer scales its colour by the ratio of the two skins' tones, which
//! from a dark source to a light base is 2-3 per channel in display terms:
//! the brow's share of the colour is scaled with the skin's and the brow
//! comes out pale. Modelled in linear light, a colour c mixing the source's skin S
//! (a share 1 − k) with a feature F (a share k) should become
//! c + (1 − k)(S' − S) for the base's skin S': only the skin's share moves.
//! With r = c / S and h = F / S (brightnesses relative to the skin at the
//! Gaussian's place), the part of c's brightness that is skin is
//! t = (1 − k)·S / c = (r − h) / ((1 − h)·r): the transfer is taken a share
//! t of the way. A black feature (h = 0) gives t = 1 — scaling a mix of skin
//! and black by the skin's ratio is exact — and a colour as bright as skin
//! gives t = 1 too; a colour as dark as the feature gives t = 0.
//!
//! Where the hair differs from the skin in hue ([`hue_tells_apart`]), a
//! darkening transfer round the eyes reads the share per channel instead,
//! by unmixing the colour into the two ([`skin_shares_by_colour`]) in
//! display values — the space a trained Gaussian's colour mixes what it
//! covers in, which the linear model above does not follow: a light skin
//! is most of a brow's green and blue but a third of its red.

use glam::Vec3;

use super::colour::{lab_to_srgb, srgb_to_linear};
use super::shading::{BakedLight, Exposure};
use super::skin_transfer::SkinStats;
use crate::model::geometry::smoothstep;
use crate::model::regions::Region;

/// Features at most this bright relative to the skin (linear luminance) are
/// told from skin by lightness; a lighter one (grey or blond hair on a fair
/// skin) differs from skin too little in lightness for its share to be read,
/// and the transfer moves such a Gaussian in full, as before.
pub const DARK_FEATURE: f32 = 0.5;

/// Luminance (Rec. 709) of a linear colour.
fn linear_luminance(linear: Vec3) -> f32 {
    0.2126 * linear.x + 0.7152 * linear.y + 0.0722 * linear.z
}

/// Linear luminance of a display colour; NaN for a broken one.
fn luminance(display: Vec3) -> f32 {
    if !display.is_finite() {
        return f32::NAN;
    }
    linear_luminance(srgb_to_linear(display.clamp(Vec3::ZERO, Vec3::ONE)))
}

/// The regions whose skin Gaussians mix with the source's brows and lashes
/// (the hair's colour or darker): the skin round the eyes. Also where a
/// lighter base's skin stays off what lies beside a feature
/// (`base_skin::base_skin_confidence`, method §7.11).
pub fn holds_dark_features(region: Region) -> bool {
    matches!(region, Region::LeftEyeRegion | Region::RightEyeRegion)
}

/// The regions where a source's stubble — its hair's colour or darker —
/// mixes into its skin Gaussians: the neck (a beard grows over its front
/// below the jaw). There a Gaussian is skin at most by its skin share of
/// area ([`skin_share_of_area`]) when the base's skin may take over
/// (`base_skin::skin_likeness`, method §7.11, session 44): the lenient
/// likeness reads skin mixed with black stubble as skin, and a lighter
/// base's clean skin then covered jomo's stubble on random-03's neck. It
/// caps the base's own neck Gaussians too (the likeness is per source), so
/// shade under a base's jaw darker than its light predicts also reads part
/// feature there. A cap by the brightness share on the face, nose, ears and
/// eye regions measured no gain.
pub fn holds_stubble(region: Region) -> bool {
    region == Region::Neck
}

/// The gain of a colour round the eyes under a *darkening* transfer (a
/// lighter source onto a darker base; method §7.7, session 44): the
/// likeness's own gain `by_likeness` where the likeness calls the colour
/// skin, the whole transfer taken the colour's skin share (`by_share`: of
/// brightness, or per channel by [`skin_shares_by_colour`] since session
/// 45) where it calls it a feature, mixed by the likeness
/// `likeness` (0 to 1; NaN counts as 0) in between. A light source's brow
/// is a mix of its light skin and its hair: the likeness calls it no skin
/// and leaves it as it was, so the light skin in it stayed light on the
/// dark base (pale brows); its share of brightness moves only that skin.
/// Plain lid skin keeps the likeness's transfer, since its shade — darker
/// than the source's light predicts — would read as part feature.
pub fn darkening_gain(likeness: f32, by_likeness: Vec3, by_share: Vec3) -> Vec3 {
    let k = if likeness.is_nan() {
        0.0
    } else {
        likeness.clamp(0.0, 1.0)
    };
    by_share.lerp(by_likeness, k)
}

/// The hairline's region (the remainder: temples, sideburns, the sides of
/// the head round the ears), where under a brightening transfer a Gaussian
/// takes the *whole* transfer by its skin share of brightness rather than
/// the partial one of the region's likeness (the strict one or the
/// hairline's side, method §7.7, session 44). Shade there
/// — behind and under the ears, beneath the hair — is darker skin of the
/// skin's own chromaticity, too far in lightness for the strict likeness,
/// which kept part of a dark source's tone under a light base's; relative to
/// the fitted light it reads as skin, while the source's hair keeps its own
/// colour (a share of zero).
pub fn moved_by_brightness_share(region: Region) -> bool {
    region == Region::Remainder
}

/// How far a colour of [`moved_by_brightness_share`]'s regions moves under a
/// brightening transfer: its skin share of brightness `share`
/// ([`skin_share_of_brightness`]), but none for a colour the likeness
/// (`likeness`, 0 to 1) reads as no skin at all — lighter strands of the
/// source's hair read part skin by brightness alone and would be paled.
/// The likeness fades the share in from 0 to [`SKIN_AT_ALL`]; values that
/// are not numbers give no move.
pub fn hairline_share(likeness: f32, share: f32) -> f32 {
    let moved = share * smoothstep(0.0, SKIN_AT_ALL, likeness);
    if moved.is_nan() {
        0.0
    } else {
        moved.clamp(0.0, 1.0)
    }
}

/// The likeness over which [`hairline_share`] counts a colour as skin at
/// all (0.01 as a hard cut measured the same).
pub const SKIN_AT_ALL: f32 = 0.1;

/// Whether `feature`, a feature's brightness relative to the skin, is dark
/// enough for [`skin_share_of_brightness`] to tell it from skin
/// ([`DARK_FEATURE`]).
pub fn is_tellable(feature: f32) -> bool {
    (0.0..DARK_FEATURE).contains(&feature)
}

/// Whether the transfer from `from` to `to` brightens the skin (the base's
/// tone is lighter): only then does scaling a dark feature with the skin
/// pale it. Darkening a mix of skin and a darker feature by the skin's ratio
/// errs by the feature's share times its own brightness, small beside the
/// error of leaving a light skin's share light on a dark base. The same
/// asymmetry decides where the base's skin may cover a source's features
/// round the eyes (`base_skin::base_skin_confidence`, method §7.11).
pub fn transfer_brightens(from: &SkinStats, to: &SkinStats) -> bool {
    luminance(lab_to_srgb(to.tone)) > luminance(lab_to_srgb(from.tone))
}

/// The brightness of a source's hair relative to its skin tone: the linear
/// luminance of its hair's mean colour (`colour::hair_colour`, linear RGB)
/// over the tone's. Brows and lashes are the hair's colour or darker, so
/// this is the feature a skin Gaussian round the eyes may be mixed with.
/// `None` where the tone is black or the colour broken.
pub fn hair_brightness(hair: Vec3, skin: &SkinStats) -> Option<f32> {
    let tone = luminance(lab_to_srgb(skin.tone));
    let ratio = linear_luminance(hair) / tone;
    (tone > 1e-4 && ratio.is_finite()).then_some(ratio)
}

/// Per channel, the share of a Gaussian's display colour `colour` that is
/// skin, read by unmixing it into the skin's display colour at its place
/// `skin` (the source's fitted light there) and its hair's `hair`: the
/// least-squares colour ≈ a·skin + b·hair, and the share a·skin over
/// a·skin + b·hair channel by channel (method §7.7, session 45). A
/// Gaussian's colour is a mix of what it covers in *display* values, the
/// space its training and the rasteriser blend in, and a light source's
/// brow on its own head is a quarter its skin: most of its green and blue
/// but a third of its red. One share of brightness for all three left
/// ada's brows pale on nuru where the truth has them auburn. Zero where the
/// colour lies past the hair from the skin (a ≤ 0), one where it lies past
/// the skin from the hair (b < 0: skin lit brighter, a white, or a black
/// lash mixed into skin — scaling a mix of skin and black by the skin's
/// ratio is exact); `None` where skin and hair point the same way (whether
/// they are far enough apart to unmix is [`hue_tells_apart`]'s, once per
/// source) or a value is broken.
pub fn skin_shares_by_colour(colour: Vec3, skin: Vec3, hair: Vec3) -> Option<Vec3> {
    let Gram { ss, sh, hh, det } = Gram::of(skin, hair);
    // NaN fails.
    let solvable = det > 1e-6 * ss * hh;
    if !solvable || !colour.is_finite() {
        return None;
    }
    let (sc, hc) = (skin.dot(colour), hair.dot(colour));
    let a = (hh * sc - sh * hc) / det;
    let b = (ss * hc - sh * sc) / det;
    if a <= 0.0 {
        return Some(Vec3::ZERO);
    }
    if b < 0.0 {
        return Some(Vec3::ONE);
    }
    let (of_skin, fitted) = (skin * a, skin * a + hair * b);
    Some(Vec3::from_array(std::array::from_fn(|ch| {
        if fitted[ch] > 0.0 {
            (of_skin[ch] / fitted[ch]).clamp(0.0, 1.0)
        } else {
            1.0
        }
    })))
}

/// Whether a source's skin and hair differ enough in hue, as display
/// colours (its skin tone and its hair's mean display chromaticity), for
/// [`skin_shares_by_colour`] to unmix its colours into them: the squared
/// sine of their angle at least [`UNMIX_MIN_SINE2`]. Decided once per
/// source, so that its Gaussians, whose skin the light predicts each in
/// its own shade, do not flip between two rules. False for broken values.
pub fn hue_tells_apart(skin: Vec3, hair: Vec3) -> bool {
    let Gram { ss, hh, det, .. } = Gram::of(skin, hair);
    // NaN fails.
    det >= UNMIX_MIN_SINE2 * ss * hh && ss * hh > 0.0
}

/// The dot products of a skin's and a hair's colours with themselves and
/// each other, and their determinant: det / (ss·hh) is the squared sine of
/// the angle between the two.
struct Gram {
    ss: f32,
    sh: f32,
    hh: f32,
    det: f32,
}

impl Gram {
    fn of(skin: Vec3, hair: Vec3) -> Self {
        let (ss, sh, hh) = (skin.dot(skin), skin.dot(hair), hair.dot(hair));
        Self {
            ss,
            sh,
            hh,
            det: ss * hh - sh * sh,
        }
    }
}

/// The least squared sine of the angle between a skin's and a hair's
/// display colours for [`hue_tells_apart`] (about 8°): nearer, the two
/// shares trade places with noise. Ada's auburn hair lies at 0.096 from
/// her skin tone (display (0.46, 0.25, 0.16) against about (0.77, 0.67,
/// 0.60)); kemi's brown hair lies 0.044 from her skin in linear
/// chromaticity (method §7.7), far nearer.
pub const UNMIX_MIN_SINE2: f32 = 0.02;

/// How bright a Gaussian of display colour `seen` is relative to the
/// source's skin where it sits (`at`), by the source's fitted light: 1 for
/// skin as the light predicts it, less for a darker colour. `None` where the
/// light predicts (near) black there or the colour is broken.
pub fn relative_brightness(light: &BakedLight, at: Exposure, seen: Vec3) -> Option<f32> {
    let skin = luminance(light.brightness(at));
    let r = luminance(seen) / skin;
    (skin > 1e-3 && r.is_finite()).then_some(r)
}

/// The share of a colour's brightness that is skin, for a colour at
/// brightness `r` relative to the skin mixing skin with a feature of
/// relative brightness `feature` (module doc): (r − h) / ((1 − h)·r) in
/// [0, 1]. One where the feature is not dark enough to tell
/// ([`DARK_FEATURE`]), where the colour is at least as bright as skin, and
/// for values that are not numbers.
pub fn skin_share_of_brightness(r: f32, feature: f32) -> f32 {
    // The skin's area over the colour's brightness (module doc); whole
    // where the area share is (nothing to tell, or as bright as skin).
    let area = skin_share_of_area(r, feature);
    if area >= 1.0 {
        return 1.0;
    }
    (area / r.max(f32::MIN_POSITIVE)).min(1.0)
}

/// The share of a colour's *area* that is skin, for a colour at brightness
/// `r` relative to the skin mixing skin with a feature of relative
/// brightness `feature`: (r − h) / (1 − h) in [0, 1], the 1 − k of the
/// module doc. It says how much of a Gaussian the base's skin may stand in
/// for (`base_skin::skin_likeness`); [`skin_share_of_brightness`] says how
/// far its colour moves. One where the feature is not dark enough to tell,
/// where the colour is at least as bright as skin, and for values that are
/// not numbers.
pub fn skin_share_of_area(r: f32, feature: f32) -> f32 {
    if !is_tellable(feature) || r.is_nan() || r >= 1.0 {
        return 1.0;
    }
    ((r - feature) / (1.0 - feature)).clamp(0.0, 1.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::colour::srgb_to_lab;

    #[test]
    fn the_skin_share_is_what_moving_only_the_skin_needs() {
        // Half brow (a quarter of the skin's brightness), half skin.
        let (h, k) = (0.25, 0.5);
        let r = (1.0 - k) + k * h;
        assert!((skin_share_of_brightness(r, h) - 0.8).abs() < 1e-6);
        // Scaling the colour by 1 + t(g − 1) moves exactly the skin's share.
        let (skin, gain) = (0.2f32, 3.0f32);
        let c = r * skin;
        let t = skin_share_of_brightness(r, h);
        let want = c + (1.0 - k) * (gain * skin - skin);
        assert!((c * (1.0 + t * (gain - 1.0)) - want).abs() < 1e-6);
        // Plain skin and anything lighter move in full; pure feature not at all.
        assert_eq!(skin_share_of_brightness(1.0, h), 1.0);
        assert_eq!(skin_share_of_brightness(1.7, h), 1.0);
        assert_eq!(skin_share_of_brightness(h, h), 0.0);
        assert_eq!(skin_share_of_brightness(0.5 * h, h), 0.0);
        // A black feature: the skin's ratio is exact for any mix.
        assert_eq!(skin_share_of_brightness(0.3, 0.0), 1.0);
    }

    #[test]
    fn light_features_black_and_broken_values_leave_the_transfer_whole() {
        for h in [DARK_FEATURE, 0.8, 1.2, f32::NAN, f32::INFINITY, -0.1] {
            assert_eq!(skin_share_of_brightness(0.4, h), 1.0, "{h}");
        }
        for r in [f32::NAN, f32::INFINITY] {
            assert_eq!(skin_share_of_brightness(r, 0.3), 1.0, "{r}");
        }
        // Black: no brightness to share, the feature's.
        assert_eq!(skin_share_of_brightness(0.0, 0.3), 0.0);
        assert_eq!(skin_share_of_brightness(-0.0, 0.3), 0.0);
    }

    #[test]
    fn a_shared_transfer_goes_that_share_of_the_way_in_linear_light() {
        use crate::compose::skin_transfer::{semantic_skin_gain, semantic_skin_gain_shared};
        let at = |rgb: Vec3| SkinStats::at(srgb_to_lab(rgb));
        let (from, to) = (
            at(Vec3::new(0.45, 0.30, 0.21)),
            at(Vec3::new(0.9, 0.75, 0.65)),
        );
        let skin = Vec3::new(0.45, 0.30, 0.21);
        let region = Region::LeftEyeRegion;
        let whole = semantic_skin_gain(skin, region, &from, &to);
        assert!(whole.x > 1.5, "{whole}");
        for share in [1.0, 2.0, f32::NAN] {
            assert_eq!(
                semantic_skin_gain_shared(skin, region, &from, &to, share),
                whole
            );
        }
        for share in [0.0, -1.0] {
            let none = semantic_skin_gain_shared(skin, region, &from, &to, share);
            assert!((none - Vec3::ONE).abs().max_element() < 1e-5, "{none}");
        }
        let half = semantic_skin_gain_shared(skin, region, &from, &to, 0.5);
        let (before, after) = (srgb_to_linear(skin), srgb_to_linear(skin * whole));
        let got = srgb_to_linear(skin * half);
        assert!(
            (got - (before + after) * 0.5).abs().max_element() < 1e-4,
            "{got}"
        );
    }

    #[test]
    fn the_hairline_moves_by_brightness_what_the_likeness_calls_skin_at_all() {
        assert!(moved_by_brightness_share(Region::Remainder));
        for region in [
            Region::Hair,
            Region::Skin,
            Region::Neck,
            Region::LeftEyeRegion,
        ] {
            assert!(!moved_by_brightness_share(region), "{region:?}");
        }
        // Any likeness past SKIN_AT_ALL: the brightness decides, in full.
        for likeness in [SKIN_AT_ALL, 0.5, 1.0] {
            assert_eq!(hairline_share(likeness, 0.7), 0.7);
        }
        // None at all: the source's hair keeps its colour, whatever its
        // brightness says (a lighter strand reads part skin by it).
        assert_eq!(hairline_share(0.0, 0.7), 0.0);
        // Faded in between, never past the share.
        let half = hairline_share(0.5 * SKIN_AT_ALL, 0.7);
        assert!(half > 0.0 && half < 0.7, "{half}");
        for (likeness, share) in [(f32::NAN, 0.7), (1.0, f32::NAN), (-1.0, 0.7)] {
            assert_eq!(hairline_share(likeness, share), 0.0, "{likeness} {share}");
        }
        assert_eq!(hairline_share(1.0, 3.0), 1.0);
    }

    #[test]
    fn the_area_share_is_the_skins_part_of_the_mix() {
        // Three quarters skin, a quarter brow at a fifth of the skin's
        // brightness.
        let (h, k) = (0.2, 0.25);
        let r = (1.0 - k) + k * h;
        assert!((skin_share_of_area(r, h) - (1.0 - k)).abs() < 1e-6);
        // A black feature: the brightness is the skin's area.
        assert!((skin_share_of_area(0.4, 0.0) - 0.4).abs() < 1e-6);
        assert_eq!(skin_share_of_area(1.0, h), 1.0);
        assert_eq!(skin_share_of_area(1.3, h), 1.0);
        assert_eq!(skin_share_of_area(h, h), 0.0);
        assert_eq!(skin_share_of_area(0.0, h), 0.0);
        // Untellable features and broken values: all skin, as the
        // likeness alone reads it.
        for h in [DARK_FEATURE, 0.9, f32::NAN, -0.2] {
            assert_eq!(skin_share_of_area(0.4, h), 1.0, "{h}");
        }
        assert_eq!(skin_share_of_area(f32::NAN, 0.2), 1.0);
    }

    #[test]
    fn a_darkening_transfer_moves_by_the_likeness_where_it_calls_skin_and_by_the_share_elsewhere() {
        let (by_likeness, by_share) = (Vec3::new(0.4, 0.3, 0.2), Vec3::new(0.8, 0.7, 0.6));
        assert_eq!(darkening_gain(1.0, by_likeness, by_share), by_likeness);
        assert_eq!(darkening_gain(0.0, by_likeness, by_share), by_share);
        let half = darkening_gain(0.5, by_likeness, by_share);
        assert!((half - Vec3::new(0.6, 0.5, 0.4)).abs().max_element() < 1e-6);
        assert_eq!(darkening_gain(f32::NAN, by_likeness, by_share), by_share);
        assert_eq!(darkening_gain(2.0, by_likeness, by_share), by_likeness);
        assert_eq!(darkening_gain(-1.0, by_likeness, by_share), by_share);
    }

    #[test]
    fn stubble_is_read_on_the_neck_alone() {
        assert!(holds_stubble(Region::Neck));
        for region in [Region::Skin, Region::Remainder, Region::Boundary] {
            assert!(!holds_stubble(region), "{region:?}");
        }
    }

    #[test]
    fn only_dark_features_are_tellable() {
        for h in [0.0, 0.2, 0.49] {
            assert!(is_tellable(h), "{h}");
        }
        for h in [DARK_FEATURE, 0.8, -0.1, f32::NAN, f32::INFINITY] {
            assert!(!is_tellable(h), "{h}");
        }
    }

    #[test]
    fn only_a_lighter_base_brightens() {
        let at = |rgb: Vec3| SkinStats::at(srgb_to_lab(rgb));
        let (dark, light) = (
            at(Vec3::new(0.53, 0.36, 0.25)),
            at(Vec3::new(0.96, 0.83, 0.74)),
        );
        assert!(transfer_brightens(&dark, &light));
        assert!(!transfer_brightens(&light, &dark));
        assert!(!transfer_brightens(&light, &light));
    }

    #[test]
    fn hair_brightness_is_the_hairs_weighted_luminance_over_the_tone() {
        use crate::avatar::gaussians::GaussianSet;
        use crate::compose::colour::hair_colour;
        let mut set = GaussianSet::with_degree(0);
        for _ in 0..3 {
            set.push(
                0,
                Vec3::ZERO,
                glam::Quat::IDENTITY,
                Vec3::ZERO,
                0.0,
                &[0.0; 3],
            );
        }
        set.opacity_logit = vec![10.0, 10.0, -30.0];
        let skin = SkinStats::at(srgb_to_lab(Vec3::splat(0.8)));
        let grey = Vec3::splat(0.4);
        let colours = [grey, grey, Vec3::ONE];
        let of = |colours: &[Vec3], indices: &[u32], skin: &SkinStats| {
            hair_brightness(hair_colour(&set, colours, indices)?, skin)
        };
        let h = of(&colours, &[0, 1, 2], &skin).unwrap();
        let want = luminance(grey) / luminance(Vec3::splat(0.8));
        assert!((h - want).abs() < 1e-3, "{h} {want}");
        // No hair, a black tone, broken colours: none.
        assert_eq!(of(&colours, &[], &skin), None);
        let black = SkinStats::at(srgb_to_lab(Vec3::ZERO));
        assert_eq!(of(&colours, &[0, 1], &black), None);
        assert_eq!(of(&[Vec3::NAN; 3], &[0, 1], &skin), None);
        assert_eq!(hair_brightness(Vec3::NAN, &skin), None);
    }

    #[test]
    fn relative_brightness_reads_against_the_light_where_the_gaussian_sits() {
        let light = BakedLight::new([[0.5, 0.0, 0.2, 0.0]; 3], Vec3::ZERO);
        let up = Exposure {
            normal: Vec3::Y,
            cavity: 0.0,
        };
        let skin = light.brightness(up);
        assert!((relative_brightness(&light, up, skin).unwrap() - 1.0).abs() < 1e-5);
        let half = relative_brightness(&light, up, lab_to_srgb(srgb_to_lab(skin))).unwrap();
        assert!((half - 1.0).abs() < 1e-3);
        let darker = relative_brightness(&light, up, skin * 0.5).unwrap();
        assert!(darker < 0.5, "{darker}");
        // Where the light is black, or the colour broken: none.
        let black = BakedLight::new([[0.0; 4]; 3], Vec3::ZERO);
        assert_eq!(relative_brightness(&black, up, skin), None);
        assert_eq!(relative_brightness(&light, up, Vec3::NAN), None);
    }

    #[test]
    fn a_display_mix_of_skin_and_hair_unmixes_into_each_channels_skin_share() {
        let (skin, hair) = (Vec3::new(0.77, 0.67, 0.60), Vec3::new(0.45, 0.20, 0.10));
        // A quarter skin, three quarters hair: the skin's share of each
        // channel, most of the green and blue, a third of the red.
        let mix = 0.25 * skin + 0.75 * hair;
        let shares = skin_shares_by_colour(mix, skin, hair).unwrap();
        let want = 0.25 * skin / mix;
        assert!(
            (shares - want).abs().max_element() < 1e-4,
            "{shares} {want}"
        );
        assert!(shares.y > shares.x + 0.1 && shares.z > shares.y, "{shares}");
        // Moving each channel by its share gives the same mix with another
        // skin, whatever the light: the colours may come at any brightness.
        let dark = Vec3::new(0.26, 0.17, 0.12);
        let moved = mix + shares * (mix * (dark / skin) - mix);
        let ideal = 0.25 * dark + 0.75 * hair;
        assert!(
            (moved - ideal).abs().max_element() < 1e-4,
            "{moved} {ideal}"
        );
        let lit = skin_shares_by_colour(mix, skin * 0.5, hair * 3.0).unwrap();
        assert!((lit - want).abs().max_element() < 1e-4, "{lit}");
        // Skin in shade is all skin; hair, and darker hair, none of it.
        assert_eq!(
            skin_shares_by_colour(skin * 0.4, skin, hair),
            Some(Vec3::ONE)
        );
        for c in [hair, hair * 0.3] {
            let s = skin_shares_by_colour(c, skin, hair).unwrap();
            assert!(s.max_element() < 1e-4, "{c}: {s}");
        }
        // Past the skin from the hair (a white) counts as skin; past the hair
        // from the skin (a redder colour) as none.
        assert_eq!(
            skin_shares_by_colour(Vec3::splat(0.9), skin, hair),
            Some(Vec3::ONE)
        );
        assert_eq!(
            skin_shares_by_colour(Vec3::new(0.5, 0.1, 0.02), skin, hair),
            Some(Vec3::ZERO)
        );
    }

    #[test]
    fn hair_too_like_the_skin_or_broken_values_unmix_nothing() {
        let skin = Vec3::new(0.53, 0.36, 0.25);
        // Brown hair a darker version of the skin: nothing to tell them by.
        let brown = skin * 0.4 + Vec3::new(0.0, 0.005, 0.0);
        assert!(!hue_tells_apart(skin, brown));
        assert!(hue_tells_apart(skin, Vec3::new(0.45, 0.20, 0.10)));
        assert!(!hue_tells_apart(skin, Vec3::NAN));
        assert!(!hue_tells_apart(Vec3::ZERO, brown));
        assert_eq!(skin_shares_by_colour(skin, skin, skin), None);
        let hair = Vec3::new(0.1, 0.08, 0.08);
        assert_eq!(skin_shares_by_colour(Vec3::NAN, skin, hair), None);
        assert_eq!(skin_shares_by_colour(skin, Vec3::NAN, hair), None);
        assert_eq!(skin_shares_by_colour(skin, skin, Vec3::ZERO), None);
        assert_eq!(skin_shares_by_colour(skin, Vec3::ZERO, hair), None);
        // Huge and tiny colours unmix alike.
        let mix = 0.5 * skin + 0.5 * hair;
        let at = |k: f32| skin_shares_by_colour(mix * k, skin * k, hair * k).unwrap();
        assert!((at(1e6) - at(1.0)).abs().max_element() < 1e-3);
        assert!((at(1e-6) - at(1.0)).abs().max_element() < 1e-3);
    }
}
