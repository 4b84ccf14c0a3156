//! The skin transfer round features (method §7.7, §7.11): brows and lashes
//! under brightening and darkening transfers, a collar's edge, a dark
//! source's hairline and stubble on a swapped neck.

use super::*;

/// A fair skin and a dark one (display sRGB): the tones the colour
/// transfer tests move between.
const FAIR: Vec3 = Vec3::new(0.90, 0.75, 0.65);
const DARK: Vec3 = Vec3::new(0.45, 0.30, 0.21);

/// [`linear`] on each channel of a display colour.
fn to_linear(rgb: Vec3) -> Vec3 {
    Vec3::from_array(rgb.to_array().map(linear))
}

/// [`display`] on each channel of a linear colour.
fn to_display(lin: Vec3) -> Vec3 {
    Vec3::from_array(lin.to_array().map(display))
}

/// The linear luminance (Rec. 709) of a display colour.
fn luma(rgb: Vec3) -> f32 {
    to_linear(rgb).dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// sRGB's decoding of one display value to linear light, written out here
/// apart from the code under test.
fn linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// sRGB's encoding of one linear value for display ([`linear`]'s inverse).
fn display(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// Sets Gaussian `i`'s colour to `rgb` in every view (DC only).
fn paint_one(set: &mut visage::avatar::gaussians::GaussianSet, i: usize, rgb: Vec3) {
    let stride = set.sh_stride();
    let sh = &mut set.sh[i * stride..(i + 1) * stride];
    sh.fill(0.0);
    (0..3).for_each(|c| sh[c] = rgb_to_dc(rgb[c]));
}

/// The composite of source 0 with `group`'s Gaussians from source 1,
/// corrected by `colour = "semantic"`, regions by parent triangle.
fn with_group_of_source_1(db: Database, group: &str) -> visage::compose::engine::Composite {
    use visage::compose::recipe::Membership;
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert(group.into(), edit(&n[1], &[]));
    r.post.colour = ColourCorrection::Semantic;
    r.post.membership = Membership::Parent;
    e.compose(&resolve(&e, &r))
}

/// Source 1's block of `region`'s own Gaussians in composite `c`.
fn block_of_source_1(
    c: &visage::compose::engine::Composite,
    region: Region,
) -> visage::compose::engine::Block {
    *c.blocks
        .iter()
        .find(|b| b.source == 1 && b.region == region)
        .unwrap_or_else(|| panic!("no block of source 1's {region:?}"))
}

/// The display colour (DC) of Gaussian `k` of composite `c`.
fn dc_colour(c: &visage::compose::engine::Composite, k: usize) -> Vec3 {
    let sh = c.gaussians.sh_of(k);
    Vec3::new(dc_to_rgb(sh[0]), dc_to_rgb(sh[1]), dc_to_rgb(sh[2]))
}

/// Source 1's Gaussians of `region` in composite `c`, each as its index in
/// `source` (source 1's set, regions by parent triangle `regions`) and its
/// composite colour (DC): the region's block holds them in the source's
/// order, all of them where no share leaves any out.
fn own_colours(
    c: &visage::compose::engine::Composite,
    source: &visage::avatar::gaussians::GaussianSet,
    regions: &[Region],
    region: Region,
) -> Vec<(usize, Vec3)> {
    let block = block_of_source_1(c, region);
    let own: Vec<usize> = (0..source.len())
        .filter(|&i| regions[source.binding[i] as usize] == region)
        .collect();
    assert_eq!(own.len(), block.end - block.start);
    own.into_iter()
        .zip(block.start..block.end)
        .map(|(i, k)| (i, dc_colour(c, k)))
        .collect()
}

/// Paints sources 0 and 1 of the small database with their `looks` (skin,
/// hair): hair Gaussians the hair, the eye-region Gaussians `mixed_at(f, i)`
/// picks `mix(skin, hair)`, the rest the skin; composes source 1's eyes on
/// source 0 (`with_group_of_source_1`) and returns the mean display colour
/// of source 1's plain and mixed eye-region Gaussians there.
fn eyes_of_source_1(
    looks: [(Vec3, Vec3); 2],
    mixed_at: impl Fn(usize, usize) -> bool,
    mix: impl Fn(Vec3, Vec3) -> Vec3,
) -> (Vec3, Vec3) {
    use visage::compose::dark_features::holds_dark_features;
    let mut db = small_db();
    let regions = db.model.triangle_regions.clone();
    let eyes = |set: &visage::avatar::gaussians::GaussianSet, i: usize| {
        holds_dark_features(regions[set.binding[i] as usize])
    };
    for (f, (skin, hair)) in looks.into_iter().enumerate() {
        let set = &mut db.sources[f].gaussians;
        for i in 0..set.len() {
            let rgb = if regions[set.binding[i] as usize] == Region::Hair {
                hair
            } else if eyes(set, i) && mixed_at(f, i) {
                mix(skin, hair)
            } else {
                skin
            };
            paint_one(set, i, rgb);
        }
    }
    let source = db.sources[1].gaussians.clone();
    let c = with_group_of_source_1(db, "eyes");
    let (mut plain, mut mixed) = (Vec::new(), Vec::new());
    for region in [Region::LeftEyeRegion, Region::RightEyeRegion] {
        for (i, rgb) in own_colours(&c, &source, &regions, region) {
            if mixed_at(1, i) {
                &mut mixed
            } else {
                &mut plain
            }
            .push(rgb);
        }
    }
    assert!(
        plain.len() > 20 && mixed.len() > 20,
        "{} plain, {} mixed",
        plain.len(),
        mixed.len()
    );
    let mean = |v: &[Vec3]| v.iter().sum::<Vec3>() / v.len() as f32;
    (mean(&plain), mean(&mixed))
}

/// A dark source's brow mixed into the skin Gaussians round its eyes, moved
/// to a light base (method §7.7, `dark_features`): plain skin takes the
/// base's tone in full, a half-brow Gaussian only its skin's share — near
/// half the base's skin plus half the brow in linear light, not the pale
/// brow the whole transfer makes. Moved the other way, to a darker base, the
/// same mix takes the whole transfer, as plain skin does; so does a source
/// whose hair is too light to tell from its skin by lightness.
#[test]
fn a_brow_mixed_into_eye_skin_keeps_its_share_under_a_brightening_transfer() {
    let half_and_half = |skin: Vec3, brow: Vec3| {
        Vec3::from_array(std::array::from_fn(|c| {
            display(0.5 * linear(skin[c]) + 0.5 * linear(brow[c]))
        }))
    };
    let (fair, dark) = (FAIR, DARK);
    let brown = Vec3::new(0.12, 0.07, 0.04);
    // A hair half as dark again as the skin in display terms (over half its
    // brightness in linear light): too light to be told by lightness.
    let light_brown = dark * 0.85;
    // Source 0 is the base, source 1 gives the eyes: (skin, hair) each; the
    // source's even eye-region Gaussians are half skin, half hair.
    // Returns the mean linear luminance of source 1's plain and mixed eye
    // Gaussians in the composite.
    let composed = |base: (Vec3, Vec3), eyes_of: (Vec3, Vec3)| -> (f32, f32) {
        let (plain, mixed) = eyes_of_source_1([base, eyes_of], |_, i| i % 2 == 0, half_and_half);
        (luma(plain), luma(mixed))
    };
    // Dark skin with a brown brow onto a fair base.
    let (plain, mixed) = composed((fair, brown), (dark, brown));
    assert!(
        (plain - luma(fair)).abs() < 0.03 * luma(fair),
        "plain skin at {plain}"
    );
    let ideal = luma(half_and_half(fair, brown));
    let whole = luma(half_and_half(dark, brown)) * luma(fair) / luma(dark);
    assert!(
        (mixed - ideal).abs() < 0.35 * (whole - ideal),
        "half-brow at {mixed}: the skin's share moved gives {ideal}, the whole transfer {whole}"
    );
    // The other way, and a hair too light to tell: the whole transfer, the
    // mix scaled as plain skin is.
    for (base, eyes_of) in [
        ((dark, brown), (fair, brown)),
        ((fair, brown), (dark, light_brown)),
    ] {
        let (plain, mixed) = composed(base, eyes_of);
        let ratio = luma(base.0) / luma(eyes_of.0);
        let want = luma(half_and_half(eyes_of.0, eyes_of.1)) * ratio;
        assert!(
            (plain - luma(base.0)).abs() < 0.03 * luma(base.0),
            "plain skin at {plain}"
        );
        assert!(
            (mixed - want).abs() < 0.1 * want,
            "mix at {mixed}, the whole transfer {want}"
        );
    }
}

/// A light source's brow onto a darker base (method §7.7,
/// `dark_features::darkening_gain`): a Gaussian a tenth skin and nine
/// tenths dark brow (in linear light) is no skin to the likeness, which
/// left it as it was — its tenth of light skin stayed light on the dark
/// base and the brow came out pale. Its skin share of brightness moves only
/// that tenth, near the dark skin's tenth plus the same brow; plain lid
/// skin still takes the base's tone.
#[test]
fn a_light_sources_brow_darkens_only_its_skin_share_on_a_darker_base() {
    let (fair, dark) = (FAIR, DARK);
    let brow = Vec3::new(0.12, 0.10, 0.09);
    let mixed = |skin: Vec3| to_display(0.1 * to_linear(skin) + 0.9 * to_linear(brow));
    // Source 0 is the dark base with brown hair; source 1 gives the eyes,
    // fair with hair of the brow's colour, its even eye-region Gaussians
    // brows mixed with a little skin.
    let (plain, brows) = eyes_of_source_1(
        [(dark, Vec3::new(0.12, 0.07, 0.04)), (fair, brow)],
        |f, i| f == 1 && i % 2 == 0,
        |skin, _| mixed(skin),
    );
    let (plain, brows) = (luma(plain), luma(brows));
    assert!(
        (plain - luma(dark)).abs() < 0.03 * luma(dark),
        "plain lid skin at {plain}"
    );
    let (ideal, unmoved) = (luma(mixed(dark)), luma(mixed(fair)));
    assert!(
        (brows - ideal).abs() < 0.35 * (unmoved - ideal),
        "brow at {brows}: its skin's share moved gives {ideal}, unmoved {unmoved}"
    );
}

/// An auburn brow of a fair source onto a darker base keeps its hue
/// (method §7.7, `dark_features::skin_shares_by_colour`): a Gaussian three
/// quarters hair and a quarter skin in display values — how a trained
/// Gaussian mixes what it covers — holds most of its green and blue from the
/// skin but little of its red. Unmixed into the two colours, each channel
/// moves by its own skin share: near the same mix with the dark skin. One
/// share of brightness for all three channels (session 44) moved too
/// little of the green and blue and left it a paler, less red brown.
#[test]
fn an_auburn_brow_keeps_its_hue_on_a_darker_base() {
    let (fair, dark) = (FAIR, DARK);
    let auburn = Vec3::new(0.45, 0.20, 0.10);
    let brow_on = |skin: Vec3| 0.25 * skin + 0.75 * auburn;
    let (plain, brows) = eyes_of_source_1(
        [(dark, Vec3::new(0.12, 0.07, 0.04)), (fair, auburn)],
        |f, i| f == 1 && i % 2 == 0,
        |skin, _| brow_on(skin),
    );
    assert!(
        (luma(plain) - luma(dark)).abs() < 0.03 * luma(dark),
        "plain lid skin at {plain}"
    );
    let (ideal, unmoved) = (brow_on(dark), brow_on(fair));
    for ch in 0..3 {
        assert!(
            (brows[ch] - ideal[ch]).abs() < 0.25 * (unmoved[ch] - ideal[ch]).abs(),
            "channel {ch} of the brow at {brows}: the mix with the dark skin is {ideal}, unmoved {unmoved}"
        );
    }
    let redness = |c: Vec3| c.x / c.y;
    assert!(
        (redness(brows) - redness(ideal)).abs() < 0.05 * redness(ideal),
        "the brow's red over green {} against the mix's {}",
        redness(brows),
        redness(ideal)
    );
}

/// Round the eyes a lighter base's skin stays off the triangles beside a
/// dark source's features (method §7.11): painted over the source's brows
/// and lashes it pales them, whatever the base's shape weight. Onto a darker
/// base its skin takes over there by that weight, as elsewhere: a dark skin
/// errs little beside a feature and replaces the lid skin a light source
/// would leave light.
#[test]
fn a_lighter_bases_skin_stays_off_what_lies_beside_a_dark_sources_brows() {
    use visage::compose::dark_features::holds_dark_features;
    use visage::compose::recipe::Membership;
    let (fair, dark) = (FAIR, DARK);
    let brow_black = Vec3::splat(0.03);
    // How many of the base's Gaussians show on the eye regions' triangles
    // (beside the source's brows, away from them), with base 0 in skin
    // `base` and source 1's eyes (at half the base's shape) in skin
    // `source`, a near-black brow on the top fifth of its eye regions.
    let base_shown = |base: Vec3, source: Vec3| -> (usize, usize) {
        let mut db = small_db();
        let regions = db.model.triangle_regions.clone();
        let eyes = |t: u32| holds_dark_features(regions[t as usize]);
        let height = |t: u32| {
            let corners = db.model.triangles[t as usize];
            corners
                .iter()
                .map(|&v| db.model.template[v as usize].y)
                .sum::<f32>()
                / 3.0
        };
        let mut heights: Vec<f32> = (0..regions.len() as u32)
            .filter(|&t| eyes(t))
            .map(height)
            .collect();
        heights.sort_by(f32::total_cmp);
        let brow_from = heights[heights.len() * 4 / 5];
        let brows: Vec<bool> = (0..regions.len() as u32)
            .map(|t| eyes(t) && height(t) >= brow_from)
            .collect();
        let brow = |t: u32| brows[t as usize];
        for (f, skin) in [base, source].into_iter().enumerate() {
            let set = &mut db.sources[f].gaussians;
            for i in 0..set.len() {
                let rgb = if f == 1 && brow(set.binding[i]) {
                    brow_black
                } else {
                    skin
                };
                paint_one(set, i, rgb);
            }
        }
        let e = Engine::new(db).unwrap();
        let n = names(&e);
        let mut r = Recipe::unedited(&n[0]);
        let half = [(n[0].as_str(), 0.5), (n[1].as_str(), 0.5)];
        r.groups.insert("eyes".into(), edit(&n[1], &half));
        // Counted by parent, a Gaussian's triangle is the one it is bound to.
        r.post = PostProcess {
            membership: Membership::Parent,
            ..PostProcess::BEST
        };
        let c = e.compose(&resolve(&e, &r));
        let model = &e.database().model;
        let mut brow_corner = vec![false; model.vertex_count()];
        for (t, corners) in model.triangles.iter().enumerate() {
            if brow(t as u32) {
                corners.iter().for_each(|&v| brow_corner[v as usize] = true);
            }
        }
        let beside = |t: u32| {
            model.triangles[t as usize]
                .iter()
                .any(|&v| brow_corner[v as usize])
        };
        let (mut near, mut away) = (0, 0);
        for b in c
            .blocks
            .iter()
            .filter(|b| b.source == 0 && holds_dark_features(b.region))
        {
            for i in b.start..b.end {
                if beside(c.gaussians.binding[i]) {
                    near += 1;
                } else {
                    away += 1;
                }
            }
        }
        (near, away)
    };
    let (near, away) = base_shown(fair, dark);
    assert_eq!(near, 0, "a lighter base's skin beside the brows");
    assert!(away > 20, "{away}: the base's skin away from them");
    let (near, _) = base_shown(dark, fair);
    assert!(near > 20, "{near} of a darker base's Gaussians beside them");
}

/// A dark source's neck on a fair base (method §7.7, `clothing`): plain
/// skin takes the base's tone, the shirt stays as it is, and a Gaussian on
/// the collar's edge, half skin and half shirt, comes out as bright as the
/// base's skin beside that shirt — the skin likeness alone left it as it was.
#[test]
fn a_collar_edge_moves_its_skin_share_to_the_bases_tone_and_keeps_its_shirt() {
    let (fair, dark) = (FAIR, DARK);
    let teal = Vec3::new(0.16, 0.45, 0.42);
    let edge = |skin: Vec3| to_display(0.5 * to_linear(skin) + 0.5 * to_linear(teal));
    // Source 1's neck: every third Gaussian shirt, every third half skin
    // and half shirt (the collar's edge), the rest skin; source 0 is fair.
    #[derive(Clone, Copy, PartialEq, Debug)]
    enum Kind {
        Skin,
        Edge,
        Shirt,
    }
    let mut db = small_db();
    let regions = db.model.triangle_regions.clone();
    let kind = |set: &visage::avatar::gaussians::GaussianSet, i: usize| match (
        regions[set.binding[i] as usize] == Region::Neck,
        i % 3,
    ) {
        (false, _) | (true, 2) => Kind::Skin,
        (true, 0) => Kind::Shirt,
        _ => Kind::Edge,
    };
    for (f, skin) in [fair, dark].into_iter().enumerate() {
        let set = &mut db.sources[f].gaussians;
        for i in 0..set.len() {
            let rgb = match (f, kind(set, i)) {
                (0, _) | (_, Kind::Skin) => skin,
                (_, Kind::Shirt) => teal,
                (_, Kind::Edge) => edge(skin),
            };
            paint_one(set, i, rgb);
        }
    }
    let source = db.sources[1].gaussians.clone();
    let c = with_group_of_source_1(db, "neck");
    let mut seen: BTreeMap<&str, Vec<Vec3>> = BTreeMap::new();
    for (i, rgb) in own_colours(&c, &source, &regions, Region::Neck) {
        let name = match kind(&source, i) {
            Kind::Skin => "skin",
            Kind::Edge => "edge",
            Kind::Shirt => "shirt",
        };
        seen.entry(name).or_default().push(rgb);
    }
    let mean = |v: &[Vec3]| v.iter().copied().sum::<Vec3>() / v.len() as f32;
    let (skin, edge_now, shirt) = (
        mean(&seen["skin"]),
        mean(&seen["edge"]),
        mean(&seen["shirt"]),
    );
    assert!((skin - fair).abs().max_element() < 0.03, "skin at {skin}");
    assert!(
        (shirt - teal).abs().max_element() < 1e-3,
        "shirt at {shirt}"
    );
    // The edge's brightness becomes near the fair skin's half beside the
    // same shirt's — not the dark skin's half it was, which the skin
    // likeness left unmoved. Near, not at: per channel the share also
    // scales the shirt's part by the skin's ratio (method §7.7), and the
    // edges, not skin-like enough for the likeness, count in the clothing's
    // mean and lower the share it reads (a pure teal mean reads 0.26 of the
    // unmoved error by hand, this one 0.16).
    let ideal = to_display(0.5 * to_linear(fair) + 0.5 * to_linear(teal));
    let before = edge(dark);
    let error = (luma(edge_now) - luma(ideal)).abs();
    assert!(
        error < 0.3 * (luma(before) - luma(ideal)).abs(),
        "edge at {edge_now}: ideal {ideal}, unmoved {before}"
    );
}

/// A dark source's hairline region (the remainder) on a fair base (method
/// §7.7, `dark_features::moved_by_brightness_share`): plain skin takes the base's
/// tone, shade — the source's skin darkened to 0.55 of its display values
/// (0.31 of its brightness in linear light), too dark for the strict
/// likeness — takes the transfer by its skin share of brightness (0.8 of
/// the way), and the source's hair there, of the skin's own chromaticity,
/// keeps its colour, as does a lighter strand the likeness calls no skin.
/// Before, the shade stayed near its dark tone; it still does for a source
/// whose hair is too light to tell by brightness.
#[test]
fn shade_on_a_dark_sources_hairline_takes_a_lighter_bases_tone_and_its_hair_stays() {
    let (fair, dark) = (FAIR, DARK);
    let brown = Vec3::new(0.12, 0.07, 0.04);
    // A strand lighter than the hair, of no skin's colour: part skin by its
    // brightness alone, none by the likeness.
    let strand = Vec3::new(0.15, 0.14, 0.13);
    let shade = dark * 0.55;
    // Source 1's remainder, by index mod 4: shade, its hair's colour, a
    // lighter strand, skin; its hair region wears `hair`, source 0 is fair
    // with brown hair. The mean linear luminance of each kind comes back.
    let composed = |hair: Vec3| -> [f32; 4] {
        let mut db = small_db();
        let regions = db.model.triangle_regions.clone();
        let colour_of = |f: usize, region: Region, i: usize| match (f, region, i % 4) {
            (0, Region::Hair, _) => brown,
            (_, Region::Hair, _) => hair,
            (0, _, _) => fair,
            (_, Region::Remainder, 0) => shade,
            (_, Region::Remainder, 1) => hair,
            (_, Region::Remainder, 2) => strand,
            _ => dark,
        };
        for f in 0..2 {
            let set = &mut db.sources[f].gaussians;
            for i in 0..set.len() {
                let rgb = colour_of(f, regions[set.binding[i] as usize], i);
                paint_one(set, i, rgb);
            }
        }
        let source = db.sources[1].gaussians.clone();
        let c = with_group_of_source_1(db, "hair");
        let mut seen: [Vec<f32>; 4] = Default::default();
        for (i, rgb) in own_colours(&c, &source, &regions, Region::Remainder) {
            seen[i % 4].push(luma(rgb));
        }
        assert!(seen.iter().all(|v| v.len() > 20), "too few Gaussians");
        seen.map(|v| v.iter().sum::<f32>() / v.len() as f32)
    };
    let [shaded, hair, lighter, skin] = composed(brown);
    assert!(
        (skin - luma(fair)).abs() < 0.03 * luma(fair),
        "skin at {skin}"
    );
    for (kind, now, was) in [("hair", hair, brown), ("strand", lighter, strand)] {
        assert!(
            (now - luma(was)).abs() < 0.02 * luma(was),
            "{kind} at {now}, was {}",
            luma(was)
        );
    }
    // The skin's share of the shade's brightness (r against hair at h
    // of the skin's): (r − h) / ((1 − h)·r) of the way to the whole transfer.
    let (r, h) = (luma(shade) / luma(dark), luma(brown) / luma(dark));
    let share = (r - h) / ((1.0 - h) * r);
    let whole = r * luma(fair);
    let want = r * luma(dark) + share * (whole - r * luma(dark));
    assert!(
        (shaded - want).abs() < 0.05 * want,
        "shade at {shaded}: its share moved gives {want}, the whole transfer {whole}, unmoved {}",
        r * luma(dark)
    );
    // Hair too light to tell from the skin by brightness: the likeness
    // alone, which leaves this shade near its dark tone.
    let [shaded, ..] = composed(dark * 0.85);
    assert!(
        shaded < 0.5 * want,
        "shade at {shaded} with light hair, the share would give {want}"
    );
}

/// A dark source's ears or face under grey hair, moved to a fair base
/// (method §7.7, session 52): a Gaussian of theirs half skin and half hair
/// (in linear light) whose triangle shares a corner with a hair triangle
/// brightens less than the same mix away from the hair, which the regions'
/// lenient likeness reads as skin and moves whole; plain skin beside the
/// hair takes the base's tone as everywhere else.
#[test]
fn ear_and_face_gaussians_part_hair_at_the_hairs_edge_are_paled_less_than_away_from_it() {
    // Every second ear Gaussian mixed; every eighth of the face's, where the
    // source's skin tone is read and must stay its own.
    for (group, swapped, every) in [
        ("ears", &[Region::LeftEar, Region::RightEar][..], 2),
        ("face", &[Region::Skin][..], 8),
    ] {
        let [[mix_away, mix_beside], [skin_away, skin_beside]] =
            part_hair_swapped(group, swapped, every);
        let half_grey = to_display(0.5 * to_linear(DARK) + 0.5 * to_linear(GREY));
        for (place, skin) in [("away from", skin_away), ("beside", skin_beside)] {
            assert!(
                (skin - luma(FAIR)).abs() < 0.03 * luma(FAIR),
                "{group}: skin {place} the hair at {skin}"
            );
        }
        let whole = luma(half_grey) * luma(FAIR) / luma(DARK);
        assert!(
            (mix_away - whole).abs() < 0.1 * whole,
            "{group}: the mix away from the hair at {mix_away}, the whole transfer {whole}"
        );
        assert!(
            mix_beside < luma(half_grey) + 0.5 * (whole - luma(half_grey)),
            "{group}: the mix beside the hair at {mix_beside}: unmoved {}, the whole transfer {whole}",
            luma(half_grey)
        );
    }
}

/// A grey hair, of no skin's hue.
const GREY: Vec3 = Vec3::new(0.45, 0.44, 0.43);

/// Source 1 of the small database dark with grey hair, one in `every` of its
/// `swapped` regions' Gaussians half skin and half hair (in linear light),
/// the rest skin; source 0 fair with brown hair. Composes source 1's `group`
/// on source 0 and returns the mean linear luminance of source 1's Gaussians
/// of those regions, as [[mix, skin] × [away from, touching] the hair]: a
/// triangle touches the hair when it shares a corner with a hair triangle.
fn part_hair_swapped(group: &str, swapped: &[Region], every: usize) -> [[f32; 2]; 2] {
    let brown = Vec3::new(0.12, 0.07, 0.04);
    let half_grey = to_display(0.5 * to_linear(DARK) + 0.5 * to_linear(GREY));
    let mut db = small_db();
    let model = &db.model;
    let regions = model.triangle_regions.clone();
    let corners_of_hair: std::collections::HashSet<u32> = model
        .triangles
        .iter()
        .zip(&regions)
        .filter(|(_, &r)| r == Region::Hair)
        .flat_map(|(t, _)| *t)
        .collect();
    let touches_hair: Vec<bool> = model
        .triangles
        .iter()
        .map(|t| t.iter().any(|v| corners_of_hair.contains(v)))
        .collect();
    for f in 0..2 {
        let set = &mut db.sources[f].gaussians;
        for i in 0..set.len() {
            let region = regions[set.binding[i] as usize];
            let rgb = match (f, region) {
                (0, Region::Hair) => brown,
                (_, Region::Hair) => GREY,
                (0, _) => FAIR,
                (_, r) if swapped.contains(&r) && i % every == 0 => half_grey,
                _ => DARK,
            };
            paint_one(set, i, rgb);
        }
    }
    let source = db.sources[1].gaussians.clone();
    let c = with_group_of_source_1(db, group);
    let mut seen: [[Vec<f32>; 2]; 2] = Default::default();
    for &region in swapped {
        for (i, rgb) in own_colours(&c, &source, &regions, region) {
            let touching = touches_hair[source.binding[i] as usize];
            seen[usize::from(i % every != 0)][usize::from(touching)].push(luma(rgb));
        }
    }
    assert!(
        seen.iter().flatten().all(|v| v.len() > 10),
        "{group}: too few Gaussians: {:?}",
        seen.each_ref().map(|k| k.each_ref().map(Vec::len))
    );
    seen.map(|kind| kind.map(|v| v.iter().sum::<f32>() / v.len() as f32))
}

/// Stubble on a dark-haired source's neck keeps its Gaussians where the
/// base's skin takes over (method §7.11, `dark_features::holds_stubble`):
/// with the neck in the base's shape, plain skin gives way to the base's,
/// but a Gaussian half skin and half black stubble (in linear light) is
/// skin by only half its area, so its triangle counts as the source's
/// feature and it keeps its opacity — the lenient likeness alone read it
/// as skin and let the base's clean skin cover it. A source whose hair is
/// too light to tell from its skin by brightness keeps the likeness's
/// reading.
#[test]
fn stubble_on_a_swapped_neck_keeps_its_gaussians_under_the_bases_skin() {
    use visage::compose::recipe::Membership;
    let (fair, dark) = (FAIR, DARK);
    let black = Vec3::splat(0.03);
    let stubble = to_display(0.5 * to_linear(dark) + 0.5 * to_linear(black));
    // The opacity source 1's plain and stubbled neck Gaussians (every third,
    // all at α = 0.9) keep in the composite, as a mean share of each kind's
    // (ln(1 − α') / ln(1 − α) summed over those shown, over how many the
    // source has), with its hair `hair`. Those whose share is negligible are
    // left out of the composite; the two kinds are told by their colour.
    let shares = |hair: Vec3| -> (f32, f32) {
        let mut db = small_db();
        let regions = db.model.triangle_regions.clone();
        let on_neck = |set: &visage::avatar::gaussians::GaussianSet, i: usize| {
            regions[set.binding[i] as usize] == Region::Neck
        };
        for f in 0..2 {
            let set = &mut db.sources[f].gaussians;
            for i in 0..set.len() {
                let rgb = match (f, regions[set.binding[i] as usize]) {
                    (_, Region::Hair) => [Vec3::new(0.35, 0.2, 0.1), hair][f],
                    (0, _) => fair,
                    (_, Region::Neck) if i % 3 == 0 => stubble,
                    _ => dark,
                };
                paint_one(set, i, rgb);
                set.opacity_logit[i] = (0.9f32 / 0.1).ln();
            }
        }
        let source = &db.sources[1].gaussians;
        let count = |stubbled: bool| {
            (0..source.len())
                .filter(|&i| on_neck(source, i) && (i % 3 == 0) == stubbled)
                .count() as f32
        };
        let (plain_count, mixed_count) = (count(false), count(true));
        let e = Engine::new(db).unwrap();
        let n = names(&e);
        let mut r = Recipe::unedited(&n[0]);
        r.groups
            .insert("neck".into(), edit(&n[1], &[(n[0].as_str(), 1.0)]));
        r.post = PostProcess {
            membership: Membership::Parent,
            ..PostProcess::BEST
        };
        let c = e.compose(&resolve(&e, &r));
        let block = block_of_source_1(&c, Region::Neck);
        let (mut plain, mut mixed) = (0.0, 0.0);
        for k in block.start..block.end {
            let rgb = dc_colour(&c, k);
            let alpha = sigmoid(c.gaussians.opacity_logit[k]);
            let share = (1.0 - alpha).ln() / 0.1f32.ln();
            // Plain skin comes out at the fair tone, the half-stubble near
            // half of it.
            if luma(rgb) > 0.75 * luma(fair) {
                plain += share;
            } else {
                mixed += share;
            }
        }
        (plain / plain_count, mixed / mixed_count)
    };
    let (plain, mixed) = shares(black);
    assert!(plain < 0.3, "plain skin keeps {plain} of its opacity");
    assert!(mixed > 0.8, "half-stubble keeps {mixed} of its opacity");
    // Hair a little darker than the skin: no stubble can be told by it.
    let (plain, mixed) = shares(dark * 0.85);
    assert!(plain < 0.3, "plain skin keeps {plain} of its opacity");
    assert!(
        mixed < 0.3,
        "half-stubble keeps {mixed} of its opacity with light hair"
    );
}
