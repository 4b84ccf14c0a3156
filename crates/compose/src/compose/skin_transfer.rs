//! Skin: a source's skin statistics, how surely a colour is skin (by colour
//! alone, or by the region it sits in as well), and the transfer that moves
//! skin from one source's tone to another's (docs/method.md §7.6-§7.7).
//!
//! - **skin**: the ratio of the two sources' skin tones, per channel in
//!   linear RGB (another albedo under the same light), estimated on the
//!   skin-coloured Gaussians of each source's face and applied to skin-coloured
//!   Gaussians only, weighted by how skin-like they are, with gains clamped
//!   to the wider `TRANSFER_GAIN_RANGE`. Hair, brows, lips, eyes and clothing
//!   keep their colours (the thesis's neck turned green trying to match a
//!   shirt; this cannot).
//! - **semantic**: the same transfer, with the likeness chosen by the region
//!   a Gaussian counts for: none where a region holds no skin, stricter
//!   where a region is not mostly skin.

use glam::Vec3;

use super::colour::{
    chromaticity, lab_to_srgb, linear_to_srgb, srgb_to_lab, srgb_to_linear, DARK_MEAN, LINEAR_FLOOR,
};
use crate::avatar::gaussians::{sigmoid, GaussianSet};
use crate::model::geometry::smoothstep;
use crate::model::regions::Region;

/// Allowed per-channel gains of the skin transfer: wider, because moving a
/// dark skin to a light one takes more than 4 in blue (shaded skin of a dark
/// source came out tan under 4; method §7.6).
pub const TRANSFER_GAIN_RANGE: (f32, f32) = (0.125, 8.0);

/// Skin colour statistics of one source in CIELAB.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SkinStats {
    /// Weighted mean: what Gaussians are judged skin-like against.
    pub mean: Vec3,
    /// The skin's tone: the densest colour near `mean`, found by a mean
    /// shift with the strict likeness's window ([`strict_skin_likeness`]).
    /// Stubble, freckles and flushes, which the likeness lets into `mean`,
    /// pull it far less. What the transfer from one skin to another moves
    /// between (method §7.6).
    pub tone: Vec3,
    /// The chromaticity of the source's hair (linear RGB over its sum), where
    /// it has a hair region: what a hairline's skin is told apart from by
    /// colour alone, whatever its shading ([`hairline_skin_likeness`]).
    pub hair: Option<Vec3>,
}

/// How skin-like a colour is, given the source's skin statistics (1 = typical
/// skin): 1 within 12 of the skin mean, 0 beyond 26, with lightness counted
/// half ([`skin_distance`]) so that lit and shaded skin — a nose's highlight,
/// the shadow behind an ear — stays skin. The skin statistics and the semantic
/// correction's skin regions use it.
pub fn skin_likeness(lab: Vec3, stats: &SkinStats) -> f32 {
    smoothstep(26.0, 12.0, skin_distance(lab, stats.mean))
}

/// The skin mode's likeness: as [`skin_likeness`] but with lightness counted
/// fully. That mode knows no regions, so dark brows and hair must stay out by
/// colour alone (with lightness halved they came in: non-skin ΔE 3.61 → 5.77).
pub fn colour_only_skin_likeness(lab: Vec3, stats: &SkinStats) -> f32 {
    smoothstep(26.0, 12.0, (lab - stats.mean).length())
}

/// Regions whose Gaussians define a source's skin tone.
pub const SKIN_REFERENCE_REGIONS: [Region; 2] = [Region::Skin, Region::Nose];

/// Estimates skin statistics from the Gaussians `indices` of a set, each of
/// display colour `colours[i]` (as the capture's cameras saw it,
/// [`seen_colours`]): a first mean over all of them, weighted by opacity,
/// then the mean over the skin-like ones, then the tone by a mean shift
/// from there.
pub fn skin_stats(set: &GaussianSet, colours: &[Vec3], indices: &[u32]) -> Option<SkinStats> {
    let labs: Vec<(Vec3, f32)> = indices
        .iter()
        .filter_map(|&i| {
            let i = i as usize;
            Some((srgb_to_lab(*colours.get(i)?), sigmoid(set.opacity_logit[i])))
        })
        .filter(|(lab, w)| lab.is_finite() && w.is_finite())
        .collect();
    let weighted = |weight: &dyn Fn(Vec3, f32) -> f32| -> Option<Vec3> {
        let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
        for &(lab, a) in &labs {
            let w = weight(lab, a);
            sum += w * lab;
            total += w;
        }
        (total > 1e-6).then(|| sum / total)
    };
    let rough = weighted(&|_, a| a)?;
    let mean = weighted(&|lab, a| a * skin_likeness(lab, &SkinStats::at(rough))).unwrap_or(rough);
    let mut tone = mean;
    for _ in 0..TONE_STEPS {
        match weighted(&|lab, a| a * strict_skin_likeness(lab, &SkinStats::at(tone))) {
            Some(next) => tone = next,
            None => break,
        }
    }
    Some(SkinStats {
        mean,
        tone,
        hair: None,
    })
}

/// Steps of the mean shift that finds a skin's tone ([`SkinStats::tone`]):
/// it has settled by then (10 steps moved the bench by 0.002 dB).
const TONE_STEPS: usize = 5;

impl SkinStats {
    /// Statistics whose mean and tone are both `lab`.
    pub fn at(lab: Vec3) -> SkinStats {
        SkinStats {
            mean: lab,
            tone: lab,
            hair: None,
        }
    }

    /// The same statistics told the source's hair chromaticity.
    pub fn beside_hair(self, hair: Option<Vec3>) -> SkinStats {
        SkinStats { hair, ..self }
    }
}

/// The per-channel gain that moves a Gaussian of display colour `rgb` from
/// `from` skin statistics towards `to`, in proportion to how skin-like it is
/// (1 when it is not skin). Expressed as a gain so view-dependent terms follow
/// (`apply_gain`).
pub fn skin_transfer_gain(rgb: Vec3, from: &SkinStats, to: &SkinStats) -> Vec3 {
    let lab = srgb_to_lab(rgb);
    if !lab.is_finite() {
        return Vec3::ONE;
    }
    transfer_gain(rgb, lab, colour_only_skin_likeness(lab, from), from, to)
}

/// Regions that hold no skin at all: the semantic correction leaves them as
/// captured whatever their colour. The eyeballs are among them again since
/// session 47: from session 18 their lid skin over the rim moved by a strict
/// likeness, but under membership by place the Gaussians drawing it count
/// for the lid now (`lids`, method §5.1), and what is left on an eyeball is
/// its white and iris (by parent, lid skin over the rim keeps its tone).
/// The mouth's inside is not (since session 27, method §7.7): a trained
/// source keeps Gaussians bound to its cavity that paint the lips and the
/// skin round them while its mouth is closed, and they carry that skin out
/// over the chin when a composite's mouth opens wider than the source's
/// did.
pub fn holds_no_skin(region: Region) -> bool {
    matches!(
        region,
        Region::TeethUpper
            | Region::TeethLower
            | Region::Hair
            | Region::LeftEyeball
            | Region::RightEyeball
    )
}

/// Distance in CIELAB with lightness counted half: skin detail (freckles,
/// shading) differs from skin mostly in lightness, lips, brows and beards in
/// hue and chroma as well.
fn skin_distance(lab: Vec3, mean: Vec3) -> f32 {
    let d = lab - mean;
    (0.25 * d.x * d.x + d.y * d.y + d.z * d.z).sqrt()
}

/// How surely a colour is skin for the semantic correction: 1 within 8 of
/// the source's skin mean (lightness counted half), 0 beyond 14.
pub fn strict_skin_likeness(lab: Vec3, stats: &SkinStats) -> f32 {
    smoothstep(14.0, 8.0, skin_distance(lab, stats.mean))
}

/// The semantic correction's gain for a Gaussian of `region` with display
/// colour `rgb`: the skin transfer from `from` to `to` where it is skin,
/// nothing where it is not (see [`semantic_skin_likeness`]).
pub fn semantic_skin_gain(rgb: Vec3, region: Region, from: &SkinStats, to: &SkinStats) -> Vec3 {
    let away = SkinPlace {
        region,
        touches_hair: false,
    };
    semantic_skin_gain_at(rgb, away, from, to)
}

/// Where a Gaussian counts, as the semantic correction reads it: its region,
/// and whether that triangle shares a corner with one of the hair region's
/// (where its colour may mix skin with hair).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkinPlace {
    /// The region it counts for.
    pub region: Region,
    /// Whether its triangle shares a corner with a hair triangle.
    pub touches_hair: bool,
}

/// Regions whose Gaussians along the hair's edge take the hairline's test
/// as well as their own likeness ([`semantic_skin_likeness_at`]): the ears
/// and the face, which meet the hair over the ears and at the forehead. A
/// Gaussian of theirs at the hair's edge is part hair, their lenient
/// likeness reads it as skin, and the whole transfer moves the hair with the
/// skin — to a lighter tone it pales the hair beside it (method §7.7,
/// session 52); to a darker one it darkens it. Over a whole ear the
/// same test misreads a dark source's shaded ear skin as its black hair; the
/// neck beside the hair measured the same with it as without.
pub fn capped_beside_hair(region: Region) -> bool {
    matches!(region, Region::LeftEar | Region::RightEar | Region::Skin)
}

/// How surely a Gaussian at `place` with display colour `rgb` is skin: as
/// [`semantic_skin_likeness`], but touching the hair in
/// [`capped_beside_hair`]'s regions at most the hairline's
/// ([`hairline_skin_likeness`]) where chromaticity tells the source's skin
/// from its hair: shade keeps the skin's chromaticity, hair mixed in moves
/// it towards the hair's. Where chromaticity cannot tell them (no hair
/// colour, hair of the skin's hue, a colour too dark) the region's own
/// likeness stands, as away from the hair. `None` for a colour with no
/// CIELAB value.
pub fn semantic_skin_likeness_at(rgb: Vec3, place: SkinPlace, stats: &SkinStats) -> Option<f32> {
    let own = semantic_skin_likeness(rgb, place.region, stats)?;
    if !(place.touches_hair && capped_beside_hair(place.region)) {
        return Some(own);
    }
    Some(hairline_reading(rgb, srgb_to_lab(rgb), stats).map_or(own, |hairline| own.min(hairline)))
}

/// The semantic correction's gain for a Gaussian at `place` with display
/// colour `rgb` ([`semantic_skin_gain`] by [`semantic_skin_likeness_at`]).
pub fn semantic_skin_gain_at(
    rgb: Vec3,
    place: SkinPlace,
    from: &SkinStats,
    to: &SkinStats,
) -> Vec3 {
    match semantic_skin_likeness_at(rgb, place, from) {
        Some(k) => transfer_gain(rgb, srgb_to_lab(rgb), k, from, to),
        None => Vec3::ONE,
    }
}

/// [`semantic_skin_gain`] taken a share `share` (0 to 1) of the way in
/// linear light, c + share·(c' − c) for the colour c and its whole transfer
/// c': the part of the colour's brightness that is skin where a dark feature
/// is mixed in (`dark_features::skin_share_of_brightness`). A share that is
/// not a number counts as the whole way.
pub fn semantic_skin_gain_shared(
    rgb: Vec3,
    region: Region,
    from: &SkinStats,
    to: &SkinStats,
    share: f32,
) -> Vec3 {
    shared_gain(rgb, semantic_skin_gain(rgb, region, from, to), share)
}

/// The whole skin transfer from `from` to `to` (whatever the colour's
/// likeness) taken a share `share` (0 to 1) of the way in linear light,
/// c + share·(c·ρ − c): the skin's share of the brightness of a colour
/// mixing skin with clothing (`clothing`). A colour with no CIELAB value
/// (NaN) is left as it is; a share that is not a number counts as the
/// whole way.
pub fn whole_skin_gain_shared(rgb: Vec3, from: &SkinStats, to: &SkinStats, share: f32) -> Vec3 {
    let lab = srgb_to_lab(rgb);
    if !lab.is_finite() {
        return Vec3::ONE;
    }
    shared_gain(rgb, transfer_gain(rgb, lab, 1.0, from, to), share)
}

/// The gain `whole` taken, per channel, the share `shares` (0 to 1) of the
/// way in display values, 1 + s·(whole − 1): the skin's part of a colour
/// that mixes skin with a feature in display values moves, the feature's
/// stays (`dark_features::skin_shares_by_colour`). Shares that are not
/// numbers count as the whole way.
pub fn gain_by_channel_share(whole: Vec3, shares: Vec3) -> Vec3 {
    let shares = Vec3::select(shares.is_nan_mask(), Vec3::ONE, shares);
    (Vec3::ONE + shares.clamp(Vec3::ZERO, Vec3::ONE) * (whole - Vec3::ONE)).clamp(
        Vec3::splat(TRANSFER_GAIN_RANGE.0),
        Vec3::splat(TRANSFER_GAIN_RANGE.1),
    )
}

/// The gain taking `rgb` a share of the way from itself to `rgb · whole` in
/// linear light (the whole gain for a share that is not a number or ≥ 1).
fn shared_gain(rgb: Vec3, whole: Vec3, share: f32) -> Vec3 {
    if share.is_nan() || share >= 1.0 || whole == Vec3::ONE {
        return whole;
    }
    let current = rgb.clamp(Vec3::ZERO, Vec3::ONE).max(Vec3::splat(DARK_MEAN));
    let (before, after) = (srgb_to_linear(current), srgb_to_linear(current * whole));
    let shared = linear_to_srgb(before.lerp(after, share.max(0.0)));
    (shared / current).clamp(
        Vec3::splat(TRANSFER_GAIN_RANGE.0),
        Vec3::splat(TRANSFER_GAIN_RANGE.1),
    )
}

/// How surely a Gaussian of `region` with display colour `rgb` is skin, by
/// the source's skin statistics `stats` (0 to 1): nothing in regions that
/// hold no skin ([`holds_no_skin`]), the skin mode's likeness in regions
/// mostly skin, a stricter one elsewhere ([`strict_skin_likeness`]). `None`
/// for a colour with no CIELAB value (NaN).
pub fn semantic_skin_likeness(rgb: Vec3, region: Region, stats: &SkinStats) -> Option<f32> {
    if holds_no_skin(region) {
        return Some(0.0);
    }
    let lab = srgb_to_lab(rgb);
    if !lab.is_finite() {
        return None;
    }
    Some(if mostly_skin(region) {
        skin_likeness(lab, stats)
    } else if region == Region::Remainder {
        hairline_skin_likeness(rgb, lab, stats)
    } else if matches!(region, Region::Lips | Region::LipsInside) {
        strict_skin_likeness(lab, stats) * not_redder_than_skin(lab, stats)
    } else {
        strict_skin_likeness(lab, stats)
    })
}

/// How surely a colour is not redder than the source's skin tone: 1 within
/// [`LIP_HUE`]'s near bound of the tone's hue angle (CIELAB h = atan2(b*,
/// a*)) or yellower, 0 past its far bound towards red. Lips are redder than
/// the skin round them at every tone (h about 20-37° against 54-64° for the
/// built-in people, 6.8 apart in the strict distance for the darkest), and
/// so is a mouth's lining; where chroma is under [`HUE_CHROMA`] hue says
/// nothing and the colour counts as not redder.
pub fn not_redder_than_skin(lab: Vec3, stats: &SkinStats) -> f32 {
    let chroma = lab.y.hypot(lab.z);
    if chroma.is_nan() || chroma < HUE_CHROMA {
        return 1.0;
    }
    let hue = |c: Vec3| c.z.atan2(c.y).to_degrees();
    let redder = (hue(stats.tone) - hue(lab) + 540.0).rem_euclid(360.0) - 180.0;
    smoothstep(LIP_HUE.0, LIP_HUE.1, redder)
}

/// How many degrees of hue redder than the skin tone a colour stops being
/// skin (far) and starts to (near) in [`not_redder_than_skin`].
pub const LIP_HUE: (f32, f32) = (14.0, 7.0);

/// Chroma under which a colour's hue is noise ([`not_redder_than_skin`]).
pub const HUE_CHROMA: f32 = 4.0;

/// How surely a colour of the hairline's region (the remainder: temples,
/// sideburns, the sides of the head) is skin: the strict likeness, or more
/// where its chromaticity lies nearer the source's skin tone's than its
/// hair's (method §7.7). Shading darkens skin there (round the ears, under
/// the hair) far enough for the strict likeness to keep part of the source's
/// tone, but leaves its chromaticity; hair differs in chromaticity unless it
/// is the skin's own hue, and then the strict likeness alone decides.
pub fn hairline_skin_likeness(rgb: Vec3, lab: Vec3, stats: &SkinStats) -> f32 {
    hairline_reading(rgb, lab, stats).unwrap_or_else(|| strict_skin_likeness(lab, stats))
}

/// [`hairline_skin_likeness`] where chromaticity tells the source's skin
/// from its hair (the strict likeness or the skin's side, whichever is
/// more); `None` where it cannot ([`skin_side_of_hairline`]).
fn hairline_reading(rgb: Vec3, lab: Vec3, stats: &SkinStats) -> Option<f32> {
    let side = skin_side_of_hairline(rgb, stats)?;
    Some(strict_skin_likeness(lab, stats).max(side))
}

/// How surely a colour lies on the skin's side of the line from the
/// source's hair to its skin tone in chromaticity (1 on the skin's side, 0 on
/// the hair's, soft over [`HAIRLINE_MARGIN`]); `None` where chromaticity
/// cannot tell them: no hair colour, hair of the skin's own hue (within
/// [`HAIR_APART`]), a colour too dark to have a chromaticity, or broken
/// values.
fn skin_side_of_hairline(rgb: Vec3, stats: &SkinStats) -> Option<f32> {
    let skin = chromaticity(srgb_to_linear(lab_to_srgb(stats.tone)))?;
    let colour = chromaticity(srgb_to_linear(rgb.clamp(Vec3::ZERO, Vec3::ONE)))?;
    let hair = stats.hair?;
    let apart = skin.distance(hair);
    // NaN (a broken hair colour) fails this too.
    if apart.is_nan() || apart <= HAIR_APART {
        return None;
    }
    // +1 at the skin's chromaticity, −1 at the hair's, 0 half way.
    let side = (colour.distance(hair) - colour.distance(skin)) / apart;
    Some(smoothstep(-HAIRLINE_MARGIN, HAIRLINE_MARGIN, side))
}

/// How far apart (chromaticity distance) a source's skin and hair must be for
/// chromaticity to tell them apart.
const HAIR_APART: f32 = 0.02;

/// The soft margin of [`hairline_skin_likeness`]'s side, in units of the
/// skin-to-hair distance (0.2 and 0.5 measured the same as 0.3).
const HAIRLINE_MARGIN: f32 = 0.3;

/// Regions that are skin but for small details (face, nose, ears, neck, the
/// eye sockets — the lids round the eyeball — and the eye regions — lids,
/// with lashes and brows far enough from any skin tone for the likeness to
/// leave them): the likeness of the skin mode decides there; elsewhere (lips,
/// the mouth's inside, the hairline, the collar) the strict one. Until
/// session 18 the eye regions and sockets were strict (the sockets against
/// method §7.7's word): shaded lids kept part of the source's tone
/// (dark-base-light-eyes 29.39 → 30.45 dB at 128², non-skin ΔE unchanged).
fn mostly_skin(region: Region) -> bool {
    matches!(
        region,
        Region::Skin
            | Region::Nose
            | Region::LeftEar
            | Region::RightEar
            | Region::Neck
            | Region::LeftEyeSocket
            | Region::RightEyeSocket
            | Region::LeftEyeRegion
            | Region::RightEyeRegion
    )
}

/// The gain moving `rgb` (at `lab`) a share `k` of the way along the
/// skin transfer from `from` to `to` (the linear-RGB ratio of their tones).
fn transfer_gain(rgb: Vec3, lab: Vec3, k: f32, from: &SkinStats, to: &SkinStats) -> Vec3 {
    if k <= 0.0 {
        return Vec3::ONE;
    }
    // Another skin under the same light: the albedo ratio of the two skins'
    // tones, per channel in linear RGB (shading and texture are products).
    let ratio = srgb_to_linear(lab_to_srgb(to.tone))
        / srgb_to_linear(lab_to_srgb(from.tone)).max(Vec3::splat(LINEAR_FLOOR));
    let moved = srgb_to_lab(linear_to_srgb(srgb_to_linear(rgb) * ratio));
    let target = lab_to_srgb(lab.lerp(moved, k));
    let current = rgb.clamp(Vec3::ZERO, Vec3::ONE).max(Vec3::splat(DARK_MEAN));
    (target.max(Vec3::splat(DARK_MEAN)) / current).clamp(
        Vec3::splat(TRANSFER_GAIN_RANGE.0),
        Vec3::splat(TRANSFER_GAIN_RANGE.1),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::gaussians::{dc_to_rgb, rgb_to_dc};
    use crate::avatar::sh::Views;
    use crate::compose::colour::{apply_gain, capture_directions, seen_colours, GAIN_RANGE};

    #[test]
    fn skin_transfer_moves_skin_and_leaves_hair() {
        let from = SkinStats::at(srgb_to_lab(Vec3::new(0.9, 0.75, 0.65)));
        let to = SkinStats::at(srgb_to_lab(Vec3::new(0.45, 0.3, 0.2)));
        let mut skin = vec![rgb_to_dc(0.9), rgb_to_dc(0.75), rgb_to_dc(0.65)];
        let gain = skin_transfer_gain(Vec3::new(0.9, 0.75, 0.65), &from, &to);
        apply_gain(&mut skin, gain);
        assert!(
            (dc_to_rgb(skin[0]) - 0.45).abs() < 0.02,
            "{}",
            dc_to_rgb(skin[0])
        );
        let hair = Vec3::new(0.05, 0.04, 0.03);
        assert_eq!(skin_transfer_gain(hair, &from, &to), Vec3::ONE);
    }

    /// A dark skin trained from a frontal arc, whose colour is split
    /// between a bluish, lighter DC term and a first band that takes the
    /// lift back from every camera of the arc (the trade the arc leaves
    /// free): its statistics are of the colour the cameras saw, not the DC
    /// colour, and the transfer brings that seen colour to the light skin.
    #[test]
    fn skin_is_judged_and_moved_by_the_colour_the_cameras_saw() {
        use crate::avatar::gaussians::SH_C1;
        use glam::Quat;
        let directions = capture_directions();
        assert!(directions
            .iter()
            .all(|d| (d.length() - 1.0).abs() < 1e-6 && d.z < -0.45));
        let mean_dz = directions.iter().map(|d| d.z).sum::<f32>() / directions.len() as f32;
        let seen = Vec3::new(0.45, 0.30, 0.20);
        let lift = Vec3::new(0.05, 0.06, 0.08);
        let mut set = GaussianSet::with_degree(1);
        for k in 0..20 {
            let mut sh = [0.0f32; 12];
            let wobble = 1.0 + 0.01 * (k % 5) as f32;
            for ch in 0..3 {
                sh[ch] = rgb_to_dc(seen[ch] * wobble + lift[ch]);
                sh[6 + ch] = -lift[ch] / (SH_C1 * mean_dz);
            }
            set.push(0, Vec3::ZERO, Quat::IDENTITY, Vec3::ZERO, 2.0, &sh);
        }
        let colours = seen_colours(&set);
        assert!(
            (colours[0] - seen).abs().max_element() < 1e-5,
            "{}",
            colours[0]
        );
        let indices: Vec<u32> = (0..20).collect();
        let from = skin_stats(&set, &colours, &indices).unwrap();
        assert!((lab_to_srgb(from.mean) - seen * 1.02).abs().max_element() < 0.01);
        let to = stats(Vec3::new(0.9, 0.75, 0.65));
        let mut sh = set.sh_of(0).to_vec();
        apply_gain(
            &mut sh,
            semantic_skin_gain(colours[0], Region::Skin, &from, &to),
        );
        let moved = Views::new(&directions).seen_rgb(&sh);
        let want = Vec3::new(0.9, 0.75, 0.65) / 1.02;
        assert!(
            (moved - want).abs().max_element() < 0.02,
            "{moved} against {want}"
        );
        // Judged by its DC colour the same skin would have moved too little.
        let dc = Vec3::from_array(std::array::from_fn(|ch| dc_to_rgb(set.sh_of(0)[ch])));
        assert!((dc - seen).min_element() > 0.04, "{dc}");
    }

    /// A skin with stubble on a third of it: the mean, which the likeness
    /// lets the stubble into, is pulled towards it; the tone stays with
    /// the clean skin, and so does the transfer.
    #[test]
    fn the_tone_is_the_clean_skin_that_stubble_pulls_the_mean_from() {
        use glam::Quat;
        let skin = Vec3::new(0.62, 0.46, 0.36);
        let stubble = skin.lerp(Vec3::splat(0.39), 0.7);
        let mut set = GaussianSet::with_degree(0);
        for k in 0..90 {
            let wobble = 1.0 + 0.01 * (k % 5) as f32 - 0.02;
            let rgb = if k % 3 == 0 { stubble } else { skin } * wobble;
            set.push(0, Vec3::ZERO, Quat::IDENTITY, Vec3::ZERO, 2.0, &dc(rgb));
        }
        let colours: Vec<Vec3> = (0..90)
            .map(|i| Vec3::from_array(std::array::from_fn(|ch| dc_to_rgb(set.sh_of(i)[ch]))))
            .collect();
        let indices: Vec<u32> = (0..90).collect();
        let got = skin_stats(&set, &colours, &indices).unwrap();
        let clean = srgb_to_lab(skin);
        assert!((got.mean - clean).length() > 2.0, "{} {}", got.mean, clean);
        assert!((got.tone - clean).length() < 0.5, "{} {}", got.tone, clean);
        let to = stats(Vec3::new(0.30, 0.20, 0.14));
        let moved = corrected(skin, semantic_skin_gain(skin, Region::Skin, &got, &to));
        assert!((srgb_to_lab(moved) - to.mean).length() < 1.0, "{moved}");
    }

    fn stats(rgb: Vec3) -> SkinStats {
        SkinStats::at(srgb_to_lab(rgb))
    }

    #[test]
    fn redder_than_skin_is_told_by_hue_wherever_the_tone_lies_and_not_in_greys() {
        let skin = stats(Vec3::new(0.8, 0.6, 0.5));
        let not_redder = |rgb: Vec3| not_redder_than_skin(srgb_to_lab(rgb), &skin);
        assert_eq!(not_redder(Vec3::new(0.8, 0.6, 0.5)), 1.0);
        // Yellower (a tan or a blond stubble) is no redder.
        assert_eq!(not_redder(Vec3::new(0.8, 0.7, 0.4)), 1.0);
        assert_eq!(not_redder(Vec3::new(0.7, 0.38, 0.36)), 0.0, "lips");
        // Greys and black have no hue to tell; NaN neither.
        for grey in [Vec3::splat(0.5), Vec3::ZERO] {
            assert_eq!(not_redder(grey), 1.0, "{grey}");
        }
        assert_eq!(not_redder_than_skin(Vec3::NAN, &skin), 1.0);
        // A tone whose hue angle lies across ±180° from a colour's: the
        // difference wraps. The tone's h is about −177° (183°); 177° is 6°
        // smaller, 143° is 40° smaller (towards red), −143° (217°) larger.
        let teal = SkinStats::at(Vec3::new(50.0, -20.0, -1.0));
        let not_redder = |b: f32| not_redder_than_skin(Vec3::new(50.0, -20.0, b), &teal);
        assert_eq!(not_redder(1.0), 1.0);
        assert_eq!(not_redder(15.0), 0.0);
        assert_eq!(not_redder(-15.0), 1.0);
    }

    /// A dark source's shaded skin on a light base becomes the light skin
    /// shaded alike in every channel: blue needs a gain past 4 (under the
    /// thesis's clamp such skin came out tan).
    #[test]
    fn a_dark_skin_reaches_a_light_one_in_every_channel() {
        let dark = stats(Vec3::new(0.36, 0.22, 0.15));
        let light = stats(Vec3::new(0.88, 0.72, 0.64));
        let shaded = Vec3::new(0.26, 0.155, 0.10);
        let g = semantic_skin_gain(shaded, Region::Skin, &dark, &light);
        assert!(g.z > GAIN_RANGE.1, "{g}");
        let moved = corrected(shaded, g);
        // The light skin at the shaded skin's share of the dark skin's light.
        let share = srgb_to_linear(shaded) / srgb_to_linear(lab_to_srgb(dark.tone));
        let expected = linear_to_srgb(srgb_to_linear(lab_to_srgb(light.tone)) * share);
        let off = (srgb_to_lab(moved) - srgb_to_lab(expected)).length();
        assert!(off < 1.5, "{moved} against {expected}: ΔE {off}");
    }

    fn dc(rgb: Vec3) -> [f32; 3] {
        [rgb_to_dc(rgb.x), rgb_to_dc(rgb.y), rgb_to_dc(rgb.z)]
    }

    fn corrected(rgb: Vec3, gain: Vec3) -> Vec3 {
        let mut sh = dc(rgb).to_vec();
        apply_gain(&mut sh, gain);
        Vec3::new(dc_to_rgb(sh[0]), dc_to_rgb(sh[1]), dc_to_rgb(sh[2]))
    }

    /// Another skin under the same light: lit and shaded skin of one person
    /// become the other's skin at the same light (an albedo ratio in linear
    /// RGB), and a highlight well above the mean still counts as skin.
    #[test]
    fn the_transfer_keeps_the_light_and_changes_the_albedo() {
        let (light, dark) = (Vec3::new(0.82, 0.64, 0.50), Vec3::new(0.31, 0.20, 0.14));
        let (from, to) = (stats(light), stats(dark));
        let lit =
            |albedo: Vec3, light_level: f32| linear_to_srgb(srgb_to_linear(albedo) * light_level);
        for level in [0.45, 1.0, 1.3] {
            let source = lit(light, level);
            let gain = semantic_skin_gain(source, Region::Nose, &from, &to);
            let got = corrected(source, gain);
            let want = lit(dark, level);
            assert!(
                (srgb_to_lab(got) - srgb_to_lab(want)).length() < 1.5,
                "light {level}: {got} against {want}"
            );
        }
        // A highlight 18 lighter than the mean is still skin (lightness counts half).
        let highlight = lab_to_srgb(srgb_to_lab(light) + Vec3::new(18.0, 0.0, 0.0));
        assert!(skin_likeness(srgb_to_lab(highlight), &from) > 0.99);
        assert!(colour_only_skin_likeness(srgb_to_lab(highlight), &from) < 0.7);
    }

    #[test]
    fn semantic_correction_moves_skin_and_keeps_what_is_not_skin() {
        // Light skin onto dark skin and back: both ways the skin arrives.
        let light = Vec3::new(0.9, 0.75, 0.65);
        let dark = Vec3::new(0.45, 0.3, 0.2);
        for (from, to) in [(light, dark), (dark, light)] {
            let gain = semantic_skin_gain(from, Region::Skin, &stats(from), &stats(to));
            let got = srgb_to_lab(corrected(from, gain));
            let want = srgb_to_lab(to);
            assert!((got - want).length() < 2.0, "{from} -> {got}, want {want}");
        }
        // Regions that hold no skin keep their colour even when it is skin-like.
        for region in [Region::Hair, Region::TeethUpper, Region::TeethLower] {
            let gain = semantic_skin_gain(light, region, &stats(light), &stats(dark));
            assert_eq!(gain, Vec3::ONE, "{region:?}");
        }
        // The mouth's inside moves what is its skin by the strict likeness,
        // and keeps its dark lining and the lips.
        let gain = semantic_skin_gain(light, Region::LipsInside, &stats(light), &stats(dark));
        let got = srgb_to_lab(corrected(light, gain));
        assert!((got - srgb_to_lab(dark)).length() < 2.0, "{got}");
        for lining in [Vec3::new(0.50, 0.16, 0.17), Vec3::new(0.70, 0.38, 0.36)] {
            let gain = semantic_skin_gain(lining, Region::LipsInside, &stats(light), &stats(dark));
            assert_eq!(gain, Vec3::ONE, "{lining}");
        }
        // The darkest built-in skin and its lips are 6.8 apart in the strict
        // distance: only their hue tells them apart, in the lips and the
        // mouth's inside alike.
        let (skin, lips) = (Vec3::new(0.31, 0.20, 0.14), Vec3::new(0.28, 0.15, 0.13));
        for region in [Region::Lips, Region::LipsInside] {
            let likeness = |rgb| semantic_skin_likeness(rgb, region, &stats(skin)).unwrap();
            assert_eq!(likeness(skin), 1.0, "{region:?}");
            assert_eq!(likeness(lips), 0.0, "{region:?}");
        }
        // On an eyeball nothing moves: not the white, a green or a dark
        // skin's brown iris, nor a colour like the skin's — lid skin drawn
        // over the rim counts for the lid (method §5.1).
        for region in [Region::LeftEyeball, Region::RightEyeball] {
            for eye in [
                Vec3::new(0.93, 0.91, 0.88),
                Vec3::new(0.25, 0.45, 0.3),
                Vec3::new(0.3, 0.17, 0.08),
                light,
            ] {
                let gain = semantic_skin_gain(eye, region, &stats(light), &stats(dark));
                assert_eq!(gain, Vec3::ONE, "{region:?} {eye}");
            }
        }
        // Pink lips and a dark brow in mixed regions stay as they are, while the
        // lenient skin mode half-corrects the lips.
        let lips = Vec3::new(0.82, 0.55, 0.5);
        let from = stats(light);
        let to = stats(dark);
        assert_eq!(
            semantic_skin_gain(lips, Region::Lips, &from, &to),
            Vec3::ONE
        );
        assert_ne!(skin_transfer_gain(lips, &from, &to), Vec3::ONE);
        let brow = Vec3::new(0.2, 0.14, 0.1);
        let gain = semantic_skin_gain(brow, Region::LeftEyeRegion, &from, &to);
        assert_eq!(gain, Vec3::ONE);
        // A lid in shade is skin: it takes the other skin in the same shade
        // (under the strict likeness it kept part of its own tone).
        let lid = light * 0.72;
        for region in [
            Region::LeftEyeRegion,
            Region::RightEyeRegion,
            Region::LeftEyeSocket,
            Region::RightEyeSocket,
        ] {
            let got = corrected(lid, semantic_skin_gain(lid, region, &from, &to));
            let want = srgb_to_lab(linear_to_srgb(
                srgb_to_linear(dark) * srgb_to_linear(lid) / srgb_to_linear(light),
            ));
            assert!(
                (srgb_to_lab(got) - want).length() < 1.0,
                "{region:?}: {got}"
            );
        }
        let strict = corrected(lid, semantic_skin_gain(lid, Region::Lips, &from, &to));
        assert!(
            (srgb_to_lab(strict) - srgb_to_lab(dark * 0.72)).length() > 3.0,
            "{strict}"
        );
        // Eye sockets are the lids' skin round the eyeball (FLAME's sockets
        // are every triangle within two eyeball radii): skin there moves,
        // the pink inside of a built-in socket does not.
        for region in [Region::LeftEyeSocket, Region::RightEyeSocket] {
            let got = corrected(light, semantic_skin_gain(light, region, &from, &to));
            assert!(
                (srgb_to_lab(got) - srgb_to_lab(dark)).length() < 2.0,
                "{got}"
            );
            let pink = Vec3::new(0.62, 0.30, 0.30);
            assert_eq!(semantic_skin_gain(pink, region, &from, &to), Vec3::ONE);
        }
    }

    /// femi's case (random-04): light skin under grey hair, moved to a dark
    /// skin. At the hairline, skin in shade takes the other skin in that
    /// shade (the strict likeness left part of its own tone), grey hair and a
    /// grey-streaked Gaussian keep theirs; a source whose hair is its skin's
    /// own hue, or which has none, is judged by the strict likeness alone.
    #[test]
    fn hairline_skin_is_told_from_hair_by_chromaticity() {
        let light = Vec3::new(0.82, 0.64, 0.5);
        let dark = Vec3::new(0.31, 0.2, 0.14);
        let grey = Vec3::new(0.56, 0.55, 0.54);
        let hair = |rgb: Vec3| chromaticity(srgb_to_linear(rgb));
        let from = stats(light).beside_hair(hair(grey));
        let to = stats(dark);
        let moved_in_shade = |shade: f32| {
            srgb_to_lab(linear_to_srgb(
                srgb_to_linear(dark) * srgb_to_linear(light * shade) / srgb_to_linear(light),
            ))
        };
        for shade in [1.0, 0.6, 0.4] {
            let skin = light * shade;
            let got = corrected(
                skin,
                semantic_skin_gain(skin, Region::Remainder, &from, &to),
            );
            let want = moved_in_shade(shade);
            assert!((srgb_to_lab(got) - want).length() < 1.0, "{shade}: {got}");
        }
        // Without the hair's chromaticity, deep shade kept part of the tone.
        let deep = light * 0.4;
        let strict = corrected(
            deep,
            semantic_skin_gain(deep, Region::Remainder, &stats(light), &to),
        );
        assert!(
            (srgb_to_lab(strict) - moved_in_shade(0.4)).length() > 3.0,
            "{strict}"
        );
        // Grey hair, lit or shaded, stays; so does a Gaussian more grey than skin.
        for rgb in [grey, grey * 0.5, grey.lerp(light, 0.3)] {
            let gain = semantic_skin_gain(rgb, Region::Remainder, &from, &to);
            assert_eq!(gain, Vec3::ONE, "{rgb}");
        }
        // Only the hairline's region reads chromaticity: a lip in shade does not move.
        assert_eq!(
            semantic_skin_gain(deep, Region::Lips, &from, &to),
            Vec3::ONE
        );
        // Hair of the skin's own hue, no hair, black and broken colours: the
        // strict likeness, bounded and finite.
        for hair_of in [hair(light), None, Some(Vec3::NAN)] {
            let from = stats(light).beside_hair(hair_of);
            for rgb in [
                deep,
                Vec3::ZERO,
                Vec3::splat(1e-4),
                Vec3::NAN,
                Vec3::INFINITY,
            ] {
                let gain = semantic_skin_gain(rgb, Region::Remainder, &from, &to);
                let strict = semantic_skin_gain(rgb, Region::Remainder, &stats(light), &to);
                assert!(gain.is_finite(), "{hair_of:?} {rgb}: {gain}");
                assert_eq!(gain, strict, "{hair_of:?} {rgb}");
            }
        }
    }

    /// nuru's case (every-group, session 52): dark skin under grey hair,
    /// moved to a light skin. An ear or face Gaussian whose triangle touches
    /// the hair and whose colour is part grey hair brightens less than the
    /// region's lenient likeness would have it; skin in shade there still
    /// takes the whole transfer, and away from the hair, in a region not
    /// capped, or where chromaticity cannot tell skin from hair, nothing
    /// changes.
    #[test]
    fn beside_the_hair_an_ear_gaussian_part_hair_is_moved_less_than_skin() {
        let dark = Vec3::new(0.42, 0.28, 0.2);
        let light = Vec3::new(0.82, 0.64, 0.5);
        let grey = Vec3::new(0.45, 0.44, 0.43);
        let from = stats(dark).beside_hair(chromaticity(srgb_to_linear(grey)));
        let to = stats(light);
        let at = |region, touches_hair| SkinPlace {
            region,
            touches_hair,
        };
        let edge = linear_to_srgb(srgb_to_linear(dark).lerp(srgb_to_linear(grey), 0.5));
        for region in [Region::LeftEar, Region::RightEar, Region::Skin] {
            let lenient = semantic_skin_likeness_at(edge, at(region, false), &from).unwrap();
            let beside = semantic_skin_likeness_at(edge, at(region, true), &from).unwrap();
            assert!(lenient > 0.9, "{region:?}: {lenient}");
            assert!(
                beside < 0.5 * lenient,
                "{region:?}: {beside} against {lenient}"
            );
            let (far, near) = (
                semantic_skin_gain_at(edge, at(region, false), &from, &to),
                semantic_skin_gain_at(edge, at(region, true), &from, &to),
            );
            assert!(
                near.max_element() < far.max_element(),
                "{region:?}: {near} {far}"
            );
            assert_eq!(far, semantic_skin_gain(edge, region, &from, &to));
            // Skin in shade keeps the skin's chromaticity: the whole move.
            for shade in [1.0, 0.6] {
                let skin = dark * shade;
                assert_eq!(
                    semantic_skin_likeness_at(skin, at(region, true), &from),
                    semantic_skin_likeness(skin, region, &from),
                    "{region:?} {shade}"
                );
            }
        }
        // The nose is not capped, beside the hair or not.
        assert_eq!(
            semantic_skin_gain_at(edge, at(Region::Nose, true), &from, &to),
            semantic_skin_gain(edge, Region::Nose, &from, &to)
        );
        // Where chromaticity cannot tell skin from hair — no hair colour,
        // hair of the skin's own hue, a colour too dark to have one — the
        // region's own likeness stands beside the hair too (the strict one
        // would keep part of shaded skin's tone).
        let of_skin_hue = stats(dark).beside_hair(chromaticity(srgb_to_linear(dark) * 0.5));
        for stats in [stats(dark), of_skin_hue] {
            for rgb in [edge, dark * 0.45, Vec3::ZERO, Vec3::splat(1e-4), Vec3::ONE] {
                assert_eq!(
                    semantic_skin_likeness_at(rgb, at(Region::LeftEar, true), &stats),
                    semantic_skin_likeness(rgb, Region::LeftEar, &stats),
                    "{rgb}"
                );
            }
        }
        assert_eq!(
            semantic_skin_likeness_at(Vec3::ZERO, at(Region::Skin, true), &from),
            semantic_skin_likeness(Vec3::ZERO, Region::Skin, &from)
        );
        // Broken colours: as the region's own reading, and a finite gain.
        for rgb in [Vec3::NAN, Vec3::INFINITY, Vec3::NEG_INFINITY] {
            assert_eq!(
                semantic_skin_likeness_at(rgb, at(Region::Skin, true), &from),
                semantic_skin_likeness(rgb, Region::Skin, &from),
                "{rgb}"
            );
            let gain = semantic_skin_gain_at(rgb, at(Region::Skin, true), &from, &to);
            assert!(gain.is_finite(), "{rgb}: {gain}");
        }
    }

    #[test]
    fn semantic_correction_is_bounded_for_black_white_and_broken_colours() {
        let black = stats(Vec3::splat(0.0));
        let white = stats(Vec3::splat(1.0));
        let skin = stats(Vec3::new(0.8, 0.6, 0.5));
        for (from, to) in [
            (&black, &white),
            (&white, &black),
            (&skin, &black),
            (&black, &skin),
        ] {
            for rgb in [
                Vec3::ZERO,
                Vec3::ONE,
                Vec3::new(0.8, 0.6, 0.5),
                Vec3::splat(1e-6),
            ] {
                for region in [Region::Skin, Region::Lips, Region::Nose] {
                    let g = semantic_skin_gain(rgb, region, from, to);
                    assert!(g.is_finite(), "{rgb} {region:?}: {g}");
                    let (lo, hi) = TRANSFER_GAIN_RANGE;
                    assert!(g.min_element() >= lo && g.max_element() <= hi);
                }
            }
        }
        let g = semantic_skin_gain(Vec3::new(f32::NAN, 0.0, 0.0), Region::Skin, &skin, &black);
        assert_eq!(g, Vec3::ONE);
        let g = semantic_skin_gain(Vec3::INFINITY, Region::Skin, &skin, &black);
        assert!(g.is_finite());
    }

    #[test]
    fn a_gain_taken_by_channel_moves_each_channel_its_share() {
        let whole = Vec3::new(0.4, 0.3, 0.2);
        let near = |a: Vec3, b: Vec3| (a - b).abs().max_element() < 1e-6;
        assert!(near(gain_by_channel_share(whole, Vec3::ONE), whole));
        assert_eq!(gain_by_channel_share(whole, Vec3::ZERO), Vec3::ONE);
        let got = gain_by_channel_share(whole, Vec3::new(0.5, 0.0, 1.0));
        assert!(near(got, Vec3::new(0.7, 1.0, 0.2)), "{got}");
        // A share that is not a number is the whole way; out of range, clamped.
        let nan = gain_by_channel_share(whole, Vec3::new(f32::NAN, 2.0, -1.0));
        assert!(near(nan, Vec3::new(0.4, 0.3, 1.0)), "{nan}");
        // The gain stays in the transfer's range.
        let huge = gain_by_channel_share(Vec3::splat(1e6), Vec3::ONE);
        assert_eq!(huge, Vec3::splat(TRANSFER_GAIN_RANGE.1));
    }
}
