//! Colours of Gaussians: colour spaces (display sRGB, linear RGB, CIELAB,
//! chromaticity), the colour a source's capture cameras saw of each
//! Gaussian, mean colours of regions and of hair, and gains applied to
//! spherical harmonics — with the thesis's colour correction (thesis
//! 4.2.2, docs/method.md §7.5). The skin transfer that goes beyond it is in
//! `skin_transfer`.
//!
//! Gaussian colour is rgb = 0.5 + C0·f_dc + (view-dependent terms). An affine map
//! A·rgb + b applies to SH as f_dc' = (A·(C0·f_dc + 0.5) + b − 0.5)/C0 and
//! f_rest' = A·f_rest.
//!
//! - **thesis**: per region, gain c̄_ref / c̄_f per channel on weighted mean
//!   colours (w = α·Πs / min s). Means below `DARK_MEAN` are treated as
//!   `DARK_MEAN` and gains are clamped to `GAIN_RANGE`, so near-black regions
//!   (pupils, mouth cavity) never explode or produce NaN.

use glam::Vec3;

use rayon::prelude::*;

use crate::avatar::gaussians::{dc_to_rgb, sigmoid, GaussianSet, SH_C0};
use crate::avatar::sh::Views;

/// Means darker than this are clamped up before dividing.
pub const DARK_MEAN: f32 = 0.02;
/// Allowed per-channel gains of the thesis's correction.
pub const GAIN_RANGE: (f32, f32) = (0.25, 4.0);

/// Weighted mean DC colour of some Gaussians of a set (thesis weights).
pub fn weighted_mean_colour(set: &GaussianSet, indices: &[u32]) -> Option<Vec3> {
    let mut sum = Vec3::ZERO;
    let mut total = 0.0f32;
    let stride = set.sh_stride();
    for &i in indices {
        let i = i as usize;
        let w = colour_weight(set, i);
        if w <= 0.0 {
            continue;
        }
        let dc = &set.sh[i * stride..i * stride + 3];
        sum += w * Vec3::new(dc_to_rgb(dc[0]), dc_to_rgb(dc[1]), dc_to_rgb(dc[2]));
        total += w;
    }
    (total > 0.0 && sum.is_finite()).then(|| sum / total)
}

/// How much Gaussian `i` counts in a mean colour (thesis weights: opacity
/// times its largest cross-section, α·Πs / min s); 0 where that is not finite.
pub fn colour_weight(set: &GaussianSet, i: usize) -> f32 {
    let s = set.log_scale[i].exp();
    let w = sigmoid(set.opacity_logit[i]) * s.x * s.y * s.z / s.min_element().max(1e-30);
    if w.is_finite() && w > 0.0 {
        w
    } else {
        0.0
    }
}

/// Moves a Gaussian's displayed colour a share `w` of the way towards
/// `target` in every direction: rgb' = (1 − w)·rgb + w·target, i.e.
/// f_dc' = (1 − w)·f_dc + w·(target − 0.5)/C0 and f_rest' = (1 − w)·f_rest.
pub fn blend_towards(sh: &mut [f32], target: Vec3, w: f32) {
    for ch in 0..3 {
        sh[ch] = (1.0 - w) * sh[ch] + w * (target[ch] - 0.5) / SH_C0;
    }
    for k in sh.iter_mut().skip(3) {
        *k *= 1.0 - w;
    }
}

/// The thesis gain c̄_ref / c̄_f, guarded and clamped.
pub fn thesis_gain(reference: Vec3, source: Vec3) -> Vec3 {
    let r = reference.max(Vec3::splat(DARK_MEAN));
    let s = source.max(Vec3::splat(DARK_MEAN));
    (r / s).clamp(Vec3::splat(GAIN_RANGE.0), Vec3::splat(GAIN_RANGE.1))
}

/// Applies `rgb ↦ gain ⊙ rgb` to one Gaussian's SH (coefficient-major `[coef][rgb]`).
pub fn apply_gain(sh: &mut [f32], gain: Vec3) {
    debug_assert_eq!(sh.len() % 3, 0, "SH come in rgb triples");
    let (dc, rest) = sh.split_at_mut(3.min(sh.len()));
    for (c, g) in dc.iter_mut().zip(gain.to_array()) {
        *c = (g * (SH_C0 * *c + 0.5) - 0.5) / SH_C0;
    }
    // Coefficient by coefficient, each an [r, g, b] triple.
    for rgb in rest.chunks_exact_mut(3) {
        rgb[0] *= gain.x;
        rgb[1] *= gain.y;
        rgb[2] *= gain.z;
    }
}

/// Linear values below this count as this when dividing by them.
pub const LINEAR_FLOOR: f32 = 1e-4;

/// sRGB (display, 0..1, clamped) to linear RGB.
pub fn srgb_to_linear(rgb: Vec3) -> Vec3 {
    rgb.clamp(Vec3::ZERO, Vec3::ONE)
        .to_array()
        .map(|c| {
            if c <= 0.04045 {
                c / 12.92
            } else {
                ((c + 0.055) / 1.055).powf(2.4)
            }
        })
        .into()
}

/// Linear RGB to sRGB (negative values clamped to 0; values above 1 stay
/// above, for the caller to clamp).
pub fn linear_to_srgb(linear: Vec3) -> Vec3 {
    linear
        .to_array()
        .map(|c| {
            let c = c.max(0.0);
            if c <= 0.003_130_8 {
                12.92 * c
            } else {
                1.055 * c.powf(1.0 / 2.4) - 0.055
            }
        })
        .into()
}

/// sRGB (display, 0..1) to CIELAB (D65).
pub fn srgb_to_lab(rgb: Vec3) -> Vec3 {
    let lin = srgb_to_linear(rgb).to_array();
    let x = 0.412_456_4 * lin[0] + 0.357_576_1 * lin[1] + 0.180_437_5 * lin[2];
    let y = 0.212_672_9 * lin[0] + 0.715_152_2 * lin[1] + 0.072_175 * lin[2];
    let z = 0.019_333_9 * lin[0] + 0.119_192 * lin[1] + 0.950_304_1 * lin[2];
    let f = |t: f32| {
        if t > 0.008_856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (fx, fy, fz) = (f(x / 0.950_47), f(y), f(z / 1.088_83));
    Vec3::new(116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz))
}

/// CIELAB (D65) to sRGB (display, 0..1, clamped).
pub fn lab_to_srgb(lab: Vec3) -> Vec3 {
    let fy = (lab.x + 16.0) / 116.0;
    let fx = fy + lab.y / 500.0;
    let fz = fy - lab.z / 200.0;
    let inv = |t: f32| {
        if t > 0.206_893 {
            t * t * t
        } else {
            (t - 16.0 / 116.0) / 7.787
        }
    };
    let (x, y, z) = (inv(fx) * 0.950_47, inv(fy), inv(fz) * 1.088_83);
    let r = 3.240_454_2 * x - 1.537_138_5 * y - 0.498_531_4 * z;
    let g = -0.969_266 * x + 1.876_010_8 * y + 0.041_556 * z;
    let b = 0.055_643_4 * x - 0.204_025_9 * y + 1.057_225_2 * z;
    linear_to_srgb(Vec3::new(r, g, b))
}

/// The opacity-weighted mean colour, in linear RGB, of the Gaussians
/// `indices` of a set (a source's hair region), each of display colour
/// `colours[i]`; broken colours are left out. `None` where nothing is left
/// to weigh (an empty region). Its [`chromaticity`] tells a hairline's skin
/// from hair, its brightness a brow from skin (`dark_features`).
pub fn hair_colour(set: &GaussianSet, colours: &[Vec3], indices: &[u32]) -> Option<Vec3> {
    opacity_weighted_mean(set, colours, indices, |rgb| {
        Some(srgb_to_linear(rgb.clamp(Vec3::ZERO, Vec3::ONE)))
    })
}

/// The opacity-weighted mean chromaticity *in display values* (each
/// colour over the sum of its channels) of the Gaussians `indices` of a
/// set (a source's hair region): the direction a Gaussian round the eyes is
/// unmixed along (`dark_features::skin_shares_by_colour`). A mean of
/// directions rather than of colours, so the hair's brightest strands and
/// the skin they let through weigh no more than the rest (session 45:
/// dark-base-light-eyes read 0.013 dB worse without the seam fit from the
/// mean colour). `None` where nothing is left to weigh.
pub fn hair_display_chromaticity(
    set: &GaussianSet,
    colours: &[Vec3],
    indices: &[u32],
) -> Option<Vec3> {
    opacity_weighted_mean(set, colours, indices, |rgb| {
        chromaticity(rgb.clamp(Vec3::ZERO, Vec3::ONE))
    })
}

/// The opacity-weighted mean of `value` over the Gaussians `indices` of a
/// set, each of display colour `colours[i]`; colours that are broken or
/// have no value are left out.
fn opacity_weighted_mean(
    set: &GaussianSet,
    colours: &[Vec3],
    indices: &[u32],
    value: impl Fn(Vec3) -> Option<Vec3>,
) -> Option<Vec3> {
    let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
    for &i in indices {
        let i = i as usize;
        let (Some(&rgb), Some(&logit)) = (colours.get(i), set.opacity_logit.get(i)) else {
            continue;
        };
        let a = sigmoid(logit);
        let Some(v) = value(rgb).filter(|v| rgb.is_finite() && v.is_finite()) else {
            continue;
        };
        if a.is_finite() {
            sum += a * v;
            total += a;
        }
    }
    (total > 1e-6).then(|| sum / total)
}

/// A linear colour over the sum of its channels: what shading (a common
/// factor) leaves alone. `None` for colours too dark or broken to have one.
/// Also taken of display colours ([`hair_display_chromaticity`]), where it
/// is only a direction: a common factor there is not shading.
pub fn chromaticity(linear: Vec3) -> Option<Vec3> {
    let sum = linear.x + linear.y + linear.z;
    (sum > CHROMATICITY_FLOOR && linear.is_finite()).then(|| linear / sum)
}

/// The least linear brightness (sum of channels) whose chromaticity is read:
/// below it, a colour is noise about black.
const CHROMATICITY_FLOOR: f32 = 3e-3;

/// Yaw and pitch (degrees) of the cameras a source is taken to have been
/// captured from: a frontal arc of ±60° yaw in two rows of pitch, as
/// NeRSemble's rig (GaussianAvatars' data) and `visage capture`'s 8-camera
/// rig are.
pub const CAPTURE_ARC: [(f32, f32); 8] = [
    (-60.0, -8.0),
    (-20.0, -8.0),
    (20.0, -8.0),
    (60.0, -8.0),
    (-60.0, 12.0),
    (-20.0, 12.0),
    (20.0, 12.0),
    (60.0, 12.0),
];

/// The view directions (camera to head, unit) of the [`CAPTURE_ARC`]
/// cameras, the head looking along +z.
pub fn capture_directions() -> Vec<Vec3> {
    CAPTURE_ARC
        .iter()
        .map(|&(yaw, pitch)| {
            let (y, p) = (yaw.to_radians(), pitch.to_radians());
            -Vec3::new(y.sin() * p.cos(), p.sin(), y.cos() * p.cos())
        })
        .collect()
}

/// Each Gaussian's display colour as the capture's cameras saw it on
/// average ([`Views::seen_rgb`] over [`capture_directions`], every SH band): what
/// colour statistics and corrections judge a Gaussian by. Trained from a
/// frontal arc, a source's DC term and the low orders of its higher bands
/// trade against one another, so neither the DC colour nor the first band
/// alone is the colour anyone saw (method §7.6).
pub fn seen_colours(set: &GaussianSet) -> Vec<Vec3> {
    let views = Views::new(&capture_directions());
    (0..set.len())
        .into_par_iter()
        .map(|i| views.seen_rgb(set.sh_of(i)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::gaussians::rgb_to_dc;

    #[test]
    fn gain_maps_dc_colour_exactly_and_scales_rest() {
        let mut sh = vec![
            rgb_to_dc(0.4),
            rgb_to_dc(0.2),
            rgb_to_dc(0.8),
            0.1,
            0.2,
            0.3,
        ];
        apply_gain(&mut sh, Vec3::new(2.0, 0.5, 1.0));
        assert!((dc_to_rgb(sh[0]) - 0.8).abs() < 1e-5);
        assert!((dc_to_rgb(sh[1]) - 0.1).abs() < 1e-5);
        assert!((dc_to_rgb(sh[2]) - 0.8).abs() < 1e-5);
        assert!(
            (sh[3] - 0.2).abs() < 1e-6 && (sh[4] - 0.1).abs() < 1e-6 && (sh[5] - 0.3).abs() < 1e-6
        );
    }

    #[test]
    fn near_black_means_give_bounded_finite_gains() {
        for (r, s) in [
            (Vec3::splat(0.5), Vec3::ZERO),
            (Vec3::ZERO, Vec3::splat(0.5)),
            (Vec3::ZERO, Vec3::ZERO),
            (Vec3::splat(1e-9), Vec3::splat(1e-12)),
        ] {
            let g = thesis_gain(r, s);
            assert!(g.is_finite());
            assert!(
                g.min_element() >= GAIN_RANGE.0 && g.max_element() <= GAIN_RANGE.1,
                "{g}"
            );
        }
        assert_eq!(thesis_gain(Vec3::ZERO, Vec3::ZERO), Vec3::ONE);
    }

    #[test]
    fn lab_round_trip() {
        for rgb in [
            Vec3::new(0.9, 0.7, 0.6),
            Vec3::new(0.1, 0.05, 0.02),
            Vec3::ZERO,
            Vec3::ONE,
        ] {
            let back = lab_to_srgb(srgb_to_lab(rgb));
            assert!(back.abs_diff_eq(rgb, 2e-3), "{rgb} -> {back}");
        }
        let white = srgb_to_lab(Vec3::ONE);
        assert!((white.x - 100.0).abs() < 0.1 && white.y.abs() < 0.5 && white.z.abs() < 0.5);
    }

    #[test]
    fn the_hairs_display_chromaticity_weighs_each_gaussian_by_opacity_alone() {
        let mut set = GaussianSet::with_degree(0);
        // Opacities 0.5, 0.75, 0.5 and 0.5.
        for logit in [0.0, 3f32.ln(), 0.0, 0.0] {
            set.binding.push(0);
            set.position.push(Vec3::ZERO);
            set.rotation.push(glam::Quat::IDENTITY);
            set.log_scale.push(Vec3::ZERO);
            set.opacity_logit.push(logit);
            set.sh.extend([0.0; 3]);
        }
        let direction = |c: Vec3| c / (c.x + c.y + c.z);
        // A bright strand weighs no more than a dark one of the same hue; a
        // broken colour is left out.
        let (auburn, grey) = (Vec3::new(0.45, 0.20, 0.10), Vec3::splat(0.3));
        let colours = [auburn, grey, auburn * 0.2, Vec3::NAN];
        let got = hair_display_chromaticity(&set, &colours, &[0, 2, 3]).unwrap();
        assert!(
            (got - direction(auburn)).abs().max_element() < 1e-5,
            "{got}"
        );
        // Each Gaussian weighs by its opacity: 0.5 auburn, 0.75 grey.
        let got = hair_display_chromaticity(&set, &colours, &[0, 1]).unwrap();
        let want = (0.5 * direction(auburn) + 0.75 * direction(grey)) / 1.25;
        assert!((got - want).abs().max_element() < 1e-5, "{got} {want}");
        // The linear mean weighs the same way.
        let got = hair_colour(&set, &colours, &[0, 1]).unwrap();
        let want = (0.5 * srgb_to_linear(auburn) + 0.75 * srgb_to_linear(grey)) / 1.25;
        assert!((got - want).abs().max_element() < 1e-5, "{got} {want}");
        assert_eq!(hair_display_chromaticity(&set, &colours, &[]), None);
        assert_eq!(hair_display_chromaticity(&set, &colours, &[3]), None);
        assert_eq!(hair_colour(&GaussianSet::default(), &[], &[]), None);
    }
}
