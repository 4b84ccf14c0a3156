//! Colour seams (method §7.8): black against white across a border, hair
//! against hair at the hairline, and where a Gaussian paints.

use super::*;

/// Every Gaussian of `set` in one flat colour (no view-dependent terms).
fn paint(set: &mut visage::avatar::gaussians::GaussianSet, rgb: f32) {
    let stride = set.sh_stride();
    for i in 0..set.len() {
        let sh = &mut set.sh[i * stride..(i + 1) * stride];
        sh.fill(0.0);
        sh[..3].fill(rgb_to_dc(rgb));
    }
}

/// Colour seams (`smoothing = "blend"`, method §7.8) between a white base and
/// a black nose: nothing but colour changes; half and half at the border,
/// the own colour a seam's half-width away; never outside the two colours.
/// A Gaussian 2 cm wide on the nose's border is narrowed to the seam's
/// reach, one as wide far from any border keeps its size.
#[test]
fn colour_seams_blend_black_and_white_across_a_border_and_touch_nothing_else() {
    use visage::avatar::binding::triangle_frames;
    use visage::compose::membership::{footprint_triangles, FOOTPRINT_MAJORITY};
    use visage::compose::seams::{SeamField, SEAM_REACH, SEAM_WIDTH};
    let mut db = small_db();
    paint(&mut db.sources[0].gaussians, 1.0);
    paint(&mut db.sources[1].gaussians, 0.0);
    // Two huge Gaussians: one on the nose's border, one on the face far
    // from it, each 2 cm along every axis and marked by its opacity.
    let model = db.model.clone();
    let looks: Vec<u32> = model
        .triangle_regions
        .iter()
        .map(|&r| u32::from(r == Region::Nose))
        .collect();
    let field = SeamField::new(&model, &looks);
    let (to_nose, to_face) = (field.distances(1).unwrap(), field.distances(0).unwrap());
    let nearest = |d: &[f32], t: u32| {
        model.triangles[t as usize]
            .iter()
            .map(|&v| d[v as usize])
            .fold(f32::MAX, f32::min)
    };
    let frames = triangle_frames(&db.sources[0].neutral(&model), &model.triangles);
    let mut plant = |f: usize, wanted: &dyn Fn(u32) -> bool, marker: f32| {
        let set = &mut db.sources[f].gaussians;
        let i = (0..set.len()).find(|&i| wanted(set.binding[i])).unwrap();
        let k = frames[set.binding[i] as usize].scale;
        set.log_scale[i] = Vec3::splat((0.02 / k).ln());
        set.opacity_logit[i] = marker;
    };
    let regions = &model.triangle_regions;
    plant(
        1,
        &|t| regions[t as usize] == Region::Nose && nearest(to_face, t) < 1e-3,
        2.5,
    );
    // Distances are capped at half a seam width: at the cap, far from it.
    let far_from_nose = |t: u32| nearest(to_nose, t) >= SEAM_WIDTH / 2.0;
    plant(
        0,
        &|t| regions[t as usize] == Region::Skin && far_from_nose(t),
        2.75,
    );
    // Where the planted nose Gaussian paints: 2 cm either way reaches
    // well past the nose, over the face that source 0 shows.
    let nose_source = &db.sources[1];
    let footprints =
        footprint_triangles(&model, &nose_source.gaussians, &nose_source.neutral(&model));
    let planted = (0..nose_source.gaussians.len())
        .find(|&i| nose_source.gaussians.opacity_logit[i] == 2.5)
        .unwrap();
    let over_face = footprints[planted]
        .iter()
        .filter(|&&t| t != u32::MAX && looks[t as usize] == 0)
        .count();
    assert!(
        over_face >= FOOTPRINT_MAJORITY,
        "{over_face} points over the face"
    );
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    let off = e.compose(&resolve(&e, &r));
    r.post.smoothing = Smoothing::Blend;
    let blended = e.compose(&resolve(&e, &r));
    let (a, b) = (&off.gaussians, &blended.gaussians);
    // No extras, and every Gaussian keeps its place, orientation and opacity;
    // only the one too wide for its seam changes size.
    assert_eq!(off.blocks, blended.blocks);
    assert_eq!(a.binding, b.binding);
    assert_eq!(a.position, b.position);
    assert_eq!(a.rotation, b.rotation);
    assert_eq!(a.opacity_logit, b.opacity_logit);
    let marked = |m: f32| (0..a.len()).find(|&i| a.opacity_logit[i] == m).unwrap();
    let (on_border, far) = (marked(2.5), marked(2.75));
    let size = |i: usize| frames[b.binding[i] as usize].scale;
    let widest = |s: Vec3, i: usize| s.max_element().exp() * size(i);
    assert!((widest(a.log_scale[on_border], on_border) - 0.02).abs() < 1e-6);
    let narrowed = widest(b.log_scale[on_border], on_border);
    assert!(
        (narrowed - SEAM_REACH).abs() < 1e-6,
        "{narrowed} m on the border"
    );
    assert!((widest(b.log_scale[far], far) - 0.02).abs() < 1e-6);
    // Any other Gaussian resized was wider than the reach, near the other
    // source, and is now exactly as wide as the reach.
    let mut resized = 0;
    for block in &blended.blocks {
        let other = if block.source == 0 { to_nose } else { to_face };
        for i in (block.start..block.end).filter(|&i| a.log_scale[i] != b.log_scale[i]) {
            assert!(
                b.log_scale[i].cmple(a.log_scale[i]).all(),
                "Gaussian {i} grew"
            );
            assert!((widest(b.log_scale[i], i) - SEAM_REACH).abs() < 1e-6);
            // Near the other source (the triangle it counts for may be a
            // neighbour of its parent, hence a seam's width, not half).
            assert!(nearest(other, b.binding[i]) < SEAM_WIDTH);
            resized += 1;
        }
    }
    assert!(resized >= 1 && resized < a.len() / 20, "{resized} resized");
    // It paints mostly over the face, so it takes the face's white in the
    // share of its footprint there.
    let shift_of = |i: usize| dc_to_rgb(b.sh_of(i)[0]);
    let planted_shift = shift_of(on_border);
    assert!(
        (planted_shift - over_face as f32 / 4.0).abs() < 1e-4,
        "{planted_shift} with {over_face} of 4 points over the face"
    );
    // Colours: the nose's black moves towards white, the face's white towards
    // black, by at most half at its centre, or by the share of a footprint
    // that lies mostly over the other source (three or four quarters).
    let (mut moved, mut halfway, mut by_footprint) = (0, 0, 0);
    for block in &blended.blocks {
        let own_white = block.source == 0;
        for i in block.start..block.end {
            let rgb = dc_to_rgb(b.sh_of(i)[0]);
            assert!((-1e-5..=1.0 + 1e-5).contains(&rgb), "{rgb}");
            let shift = if own_white { 1.0 - rgb } else { rgb };
            if shift > 0.5 + 1e-4 {
                let share = [0.75, 1.0].iter().any(|s| (shift - s).abs() < 1e-4);
                assert!(share, "more than half, not a footprint's share: {shift}");
                by_footprint += 1;
            }
            let tri = model.triangles[b.binding[i] as usize];
            let other = if own_white { to_nose } else { to_face };
            let near = tri
                .iter()
                .map(|&v| other[v as usize])
                .fold(f32::MAX, f32::min);
            if shift > 1e-6 {
                moved += 1;
                // Only where the other source is near (the triangle a Gaussian
                // counts for may be a neighbour of its parent, hence the slack).
                assert!(near < SEAM_WIDTH, "moved {shift} at {near} m");
            }
            if shift > 0.45 {
                halfway += 1;
            }
            if near >= SEAM_WIDTH / 2.0 {
                assert_eq!(shift, 0.0, "far from the border");
            }
        }
    }
    assert!(moved > 50, "{moved} Gaussians moved");
    assert!(halfway > 5, "{halfway} Gaussians at the border");
    assert!(
        by_footprint >= 1 && by_footprint < moved / 4,
        "{by_footprint} of {moved} moved by their footprint"
    );
}

/// At the hairline a seam mixes hair with the other source's hair, not with
/// its skin (method §7.8, as the truth's cross-fade does, §13.1): swapped
/// grey hair beside a base with black hair and white skin darkens towards
/// black, at most half way, and only a Gaussian painting mostly over the
/// base's forehead (its footprint) takes the white skin there.
#[test]
fn a_hair_seam_blends_towards_the_other_sources_hair_not_its_skin() {
    let mut db = small_db();
    let model = db.model.clone();
    let on_hair = |t: u32| model.triangle_regions[t as usize] == Region::Hair;
    for (f, (skin, hair)) in [(1.0, 0.0), (0.0, 0.5)].into_iter().enumerate() {
        let set = &mut db.sources[f].gaussians;
        paint(set, skin);
        let stride = set.sh_stride();
        for i in (0..set.len()).filter(|&i| on_hair(set.binding[i])) {
            set.sh[i * stride..i * stride + 3].fill(rgb_to_dc(hair));
        }
    }
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert("hair".into(), edit(&n[1], &[]));
    r.post.smoothing = Smoothing::Blend;
    // Each Gaussian counts for the triangle it was painted by.
    r.post.membership = visage::compose::recipe::Membership::Parent;
    let c = e.compose(&resolve(&e, &r));
    let (mut darker, mut painters) = (0, 0);
    for block in c.blocks.iter().filter(|b| b.source == 1) {
        for i in block.start..block.end {
            if !on_hair(c.gaussians.binding[i]) {
                continue;
            }
            let rgb = dc_to_rgb(c.gaussians.sh_of(i)[0]);
            if rgb > 0.5 + 1e-4 {
                // A footprint painter takes three quarters or all of the
                // white forehead: 0.875 or 1 from its own grey, never a
                // seam's mix of hair and skin (0.63 before the sides).
                assert!(rgb >= 0.75 - 1e-4, "grey hair lightened to {rgb}");
                painters += 1;
            } else {
                assert!(rgb >= 0.25 - 1e-4, "more than half way to black: {rgb}");
                darker += usize::from(rgb < 0.5 - 1e-3);
            }
        }
    }
    assert!(
        darker > 20,
        "{darker} hair Gaussians moved towards the base's hair"
    );
    assert!(
        painters * 4 < darker,
        "{painters} painters, {darker} blended"
    );
}

/// Where a Gaussian paints: its footprint's four points lie on or beside a
/// small Gaussian's own triangle, and a Gaussian whose centre, scale
/// (overflowing included) or rotation is broken has none.
#[test]
fn a_footprint_is_found_for_sound_gaussians_and_refused_for_broken_ones() {
    use glam::Quat;
    use visage::compose::membership::footprint_triangles;
    let mut db = small_db();
    let model = db.model.clone();
    let neutral = db.sources[0].neutral(&model);
    let set = &mut db.sources[0].gaussians;
    let small = 0;
    set.log_scale[small] = Vec3::splat(-8.0);
    let (nan_scale, zero_turn, nan_place, huge) = (1, 2, 3, 4);
    set.log_scale[nan_scale] = Vec3::new(f32::NAN, 0.0, 0.0);
    set.rotation[zero_turn] = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
    set.position[nan_place] = Vec3::splat(f32::NAN);
    set.log_scale[huge] = Vec3::splat(200.0);
    let footprints = footprint_triangles(&model, set, &neutral);
    assert_eq!(footprints.len(), set.len());
    let parent = set.binding[small];
    let shares_a_corner = |t: u32| {
        let (a, b) = (
            model.triangles[t as usize],
            model.triangles[parent as usize],
        );
        a.iter().any(|v| b.contains(v))
    };
    assert!(
        footprints[small].iter().all(|&t| shares_a_corner(t)),
        "{:?}",
        footprints[small]
    );
    for broken in [nan_scale, zero_turn, nan_place, huge] {
        assert_eq!(footprints[broken], [u32::MAX; 4], "Gaussian {broken}");
    }
}

/// The seams' local colours are made once and kept between edits of the
/// Gaussians: whatever the order of edits — other sources, a source shown
/// again, another colour correction, membership or base (which the colours
/// depend on) — a composite brought up to date has the colours of one
/// composed from scratch, bit for bit.
#[test]
fn seam_colours_kept_between_edits_match_a_fresh_composite() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post = PostProcess::BEST;
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    r.groups.insert("mouth".into(), edit(&n[3], &[]));
    let mut c = e.compose(&resolve(e, &r));
    let mut steps: Vec<Recipe> = Vec::new();
    r.groups.insert("eyes".into(), edit(&n[2], &[]));
    steps.push(r.clone());
    r.groups.insert("nose".into(), edit(&n[2], &[]));
    steps.push(r.clone());
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    steps.push(r.clone());
    for colour in [
        ColourCorrection::Skin,
        ColourCorrection::Thesis,
        ColourCorrection::Off,
        ColourCorrection::Semantic,
    ] {
        r.post.colour = colour;
        steps.push(r.clone());
    }
    r.post.membership = Membership::Parent;
    steps.push(r.clone());
    r.post.membership = Membership::Place;
    steps.push(r.clone());
    r.base = n[2].clone();
    steps.push(r.clone());
    r.groups.insert("mouth".into(), edit(&n[0], &[]));
    steps.push(r.clone());
    for (k, step) in steps.iter().enumerate() {
        update_matches_fresh(e, &mut c, &resolve(e, step), &format!("step {k}"));
    }
}
