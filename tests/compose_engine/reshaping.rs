//! Gaussians on a reshaped face: the affine deformation (§6.7), anchors on
//! the surface a Gaussian sits over (§6.8) and relighting (§7.10).

use super::*;

/// `b` holds `a`'s Gaussians — the same count, bindings, opacities and
/// colours — moved to finite places, rotations and scales.
fn assert_same_gaussians_moved_finitely(
    a: &visage::avatar::gaussians::GaussianSet,
    b: &visage::avatar::gaussians::GaussianSet,
) {
    assert_eq!(a.len(), b.len());
    assert_eq!(a.binding, b.binding, "still bound to their parents");
    assert_eq!(a.opacity_logit, b.opacity_logit);
    assert_eq!(a.sh, b.sh);
    assert!(b.position.iter().all(|p| p.is_finite()));
    assert!(b.rotation.iter().all(|q| q.is_finite()));
    assert!(b.log_scale.iter().all(|s| s.is_finite()));
}

/// `deform = "affine"` (method §6.7): Gaussians follow their triangles'
/// whole reshaping. Where no triangle changes shape nothing moves; a shape
/// weight of 1.0 on a very different face moves Gaussians but not their
/// count, opacity or colour, leaves no NaN, and a shape edit rebuilds them.
#[test]
fn affine_deformation_follows_reshaped_triangles_and_only_them() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.deform = Deform::Affine;
    let unedited = e.compose(&resolve(e, &r));
    r.post.deform = Deform::Similarity;
    let plain = e.compose(&resolve(e, &r));
    assert_eq!(unedited.gaussians.position, plain.gaussians.position);
    assert_eq!(unedited.gaussians.log_scale, plain.gaussians.log_scale);

    // The base's Gaussians on another face entirely.
    all_groups(&mut r, &n[0], &[(&n[3], 1.0)]);
    let similar = e.compose(&resolve(e, &r));
    r.post.deform = Deform::Affine;
    let affine = e.compose(&resolve(e, &r));
    let (a, b) = (&similar.gaussians, &affine.gaussians);
    assert_same_gaussians_moved_finitely(a, b);
    let moved = (0..a.len())
        .filter(|&i| a.log_scale[i] != b.log_scale[i])
        .count();
    assert!(moved > a.len() / 2, "{moved} of {} reshaped", a.len());
    // Posed, the scene stays finite.
    let mut posed = PosedMesh::default();
    e.pose(&affine, 0, &mut posed);
    assert!(e.scene(&affine, &posed).scale.iter().all(|s| s.is_finite()));

    // A shape edit rebuilds the Gaussians only when they follow the shape.
    let mut next = resolve(e, &r);
    next.shape[Group::Nose.index()] = vec![0.5, 0.0, 0.0, 0.5];
    let mut c = affine.clone();
    assert!(e.update(&mut c, &next).gaussians);
    let mut c = similar.clone();
    let mut next_similar = next.clone();
    next_similar.post.deform = Deform::Similarity;
    assert!(!e.update(&mut c, &next_similar).gaussians);
}

/// `anchor = "nearest"` (method §6.8): a Gaussian that training left over
/// another triangle than its parent follows that triangle when the blend
/// reshapes the face — here a nose Gaussian drifted 1.5 mm above a cheek
/// lands where the cheek's reshaping puts it, not where the nose's would —
/// while staying bound to its parent. Gaussians on their own triangle,
/// with a non-finite centre or a binding past the mesh keep their parent;
/// an unedited composite is unchanged bit for bit; a shape weight of 1.0 on
/// a very different face leaves no NaN; a shape edit rebuilds them.
#[test]
fn anchored_gaussians_follow_the_surface_they_sit_on() {
    use visage::avatar::binding::{local_to_world, triangle_frames};
    use visage::compose::membership::anchor_triangles;
    use visage::compose::recipe::Anchor;
    let mut db = small_db();
    let model = db.model.clone();
    let neutral = db.sources[0].neutral(&model);
    let frames = triangle_frames(&neutral, &model.triangles);
    let regions = &model.triangle_regions;
    let set = &mut db.sources[0].gaussians;
    let on_nose: Vec<usize> = (0..set.len())
        .filter(|&i| regions[set.binding[i] as usize] == Region::Nose)
        .collect();
    let nose_tip = frames[set.binding[on_nose[0]] as usize].center;
    let cheek = (0..model.triangles.len())
        .filter(|&t| regions[t] == Region::Skin)
        .find(|&t| {
            let c = frames[t].center;
            (c - nose_tip).length() > 0.03 && c.z > 0.0
        })
        .unwrap();
    let normal = frames[cheek].rotation.y_axis;
    let drifted = on_nose[0];
    let above_cheek = frames[cheek].center + 1.5e-3 * normal;
    drift_to(set, drifted, &neutral, &model.triangles, above_cheek);
    set.opacity_logit[drifted] = 3.125;
    let not_finite = on_nose[1];
    set.position[not_finite] = Vec3::NAN;
    let past_mesh = on_nose[2];
    set.binding[past_mesh] = model.triangles.len() as u32 + 7;

    let anchors = anchor_triangles(&model, set, &neutral);
    assert_eq!(anchors[drifted], cheek as u32, "follows the cheek under it");
    assert_eq!(anchors[not_finite], set.binding[not_finite]);
    assert_eq!(anchors[past_mesh], set.binding[past_mesh]);
    let elsewhere = (0..set.len())
        .filter(|&i| anchors[i] != set.binding[i])
        .count();
    assert!(
        elsewhere < set.len() / 50,
        "built-in Gaussians sit on their triangles: {elsewhere} elsewhere"
    );
    let source_world = local_to_world(
        &frames[set.binding[drifted] as usize],
        set.position[drifted],
        set.rotation[drifted],
        set.log_scale[drifted],
    );
    // The binding past the mesh and the NaN centre were for the anchors
    // above only: databases refuse them on loading.
    set.binding[past_mesh] = set.binding[on_nose[3]];
    set.position[not_finite] = set.position[on_nose[3]];

    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let compose = |r: &Recipe, anchor: Anchor| {
        let mut r = r.clone();
        r.post.anchor = anchor;
        e.compose(&resolve(&e, &r))
    };
    let mut r = Recipe::unedited(&n[0]);
    let (plain, anchored) = (compose(&r, Anchor::Parent), compose(&r, Anchor::Nearest));
    assert_eq!(plain.gaussians.position, anchored.gaussians.position);
    assert_eq!(plain.gaussians.rotation, anchored.gaussians.rotation);
    assert_eq!(plain.gaussians.log_scale, anchored.gaussians.log_scale);

    // Source 0's Gaussians on source 3's face.
    all_groups(&mut r, &n[0], &[(&n[3], 1.0)]);
    let (plain, anchored) = (compose(&r, Anchor::Parent), compose(&r, Anchor::Nearest));
    let (a, b) = (&plain.gaussians, &anchored.gaussians);
    assert_same_gaussians_moved_finitely(a, b);
    let moved = (0..a.len())
        .filter(|&i| a.position[i] != b.position[i])
        .count();
    assert!(
        moved > 0 && moved < a.len() / 20,
        "{moved} of {} moved",
        a.len()
    );

    let target = triangle_frames(&anchored.neutral, &model.triangles);
    let world_of = |c: &visage::compose::engine::Composite| {
        let g = &c.gaussians;
        let i = (0..g.len()).find(|&i| g.opacity_logit[i] == 3.125).unwrap();
        let w = local_to_world(
            &target[g.binding[i] as usize],
            g.position[i],
            g.rotation[i],
            g.log_scale[i],
        );
        (w, i)
    };
    let ((by_anchor, i), (by_parent, _)) = (world_of(&anchored), world_of(&plain));
    let (from, to) = (&frames[cheek], &target[cheek]);
    let expected = to.scale / from.scale
        * (to.rotation * (from.rotation.transpose() * (source_world.position - from.center)))
        + to.center;
    assert!(
        (by_anchor.position - expected).length() < 1e-6,
        "{} vs {expected}",
        by_anchor.position
    );
    let size = to.scale / from.scale;
    assert!(
        (by_anchor.scale - source_world.scale * size)
            .abs()
            .max_element()
            < 1e-6
    );
    // The surface under it, not its parent, decides where it goes: the
    // nose's reshaping would put it elsewhere.
    assert!(
        (by_parent.position - expected).length() > 1e-4,
        "parent {} anchor {expected}",
        by_parent.position
    );
    // Posed, it keeps its place relative to its parent triangle.
    let mut posed = PosedMesh::default();
    e.pose(&anchored, 0, &mut posed);
    let scene = e.scene(&anchored, &posed);
    assert!(scene.position[i].is_finite());

    // A shape edit rebuilds the Gaussians that follow the shape.
    let mut next = resolve(&e, &r);
    next.post.anchor = Anchor::Nearest;
    next.shape[Group::Nose.index()] = vec![0.5, 0.0, 0.0, 0.5];
    let mut c = anchored.clone();
    assert!(e.update(&mut c, &next).gaussians);
}

/// `shading = "relit"` (method §7.10): an unedited composite keeps every
/// colour; the base's Gaussians on another face keep their places and
/// opacities, and where the surface under a Gaussian turned towards the
/// built-in studio key light it brightens, turned away it darkens, within
/// the gain's range — judged where each Gaussian sits, so of two Gaussians
/// on one triangle the one whose place turned more towards the light comes
/// out brighter; a shape edit rebuilds them.
#[test]
fn relighting_follows_the_turn_and_the_hollows_under_each_gaussian() {
    use visage::compose::membership::placements;
    use visage::compose::recipe::Shading;
    use visage::compose::shading::{vertex_exposures, Exposure, RELIGHT_RANGE};
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.shading = Shading::Relit;
    let unedited = e.compose(&resolve(e, &r));
    r.post.shading = Shading::Kept;
    assert_eq!(
        unedited.gaussians.sh,
        e.compose(&resolve(e, &r)).gaussians.sh
    );

    // The base's Gaussians on another face entirely.
    all_groups(&mut r, &n[0], &[(&n[3], 1.0)]);
    let kept = e.compose(&resolve(e, &r));
    r.post.shading = Shading::Relit;
    let relit = e.compose(&resolve(e, &r));
    let (a, b) = (&kept.gaussians, &relit.gaussians);
    assert_eq!(a.position, b.position);
    assert_eq!(a.opacity_logit, b.opacity_logit);
    assert!(b.sh.iter().all(|c| c.is_finite()));
    let model = &e.database().model;
    // Each Gaussian's exposure where it sits on its triangle, on the source
    // and on the composite.
    let bary = placements(model, a, e.source_neutral(0), &a.binding);
    let at = |mesh: &[Vec3]| {
        let vertex = vertex_exposures(mesh, &model.triangles);
        (0..a.len())
            .map(|i| Exposure::at(&vertex, model.triangles[a.binding[i] as usize], bary[i]))
            .collect::<Vec<_>>()
    };
    let (from, to) = (at(e.source_neutral(0)), at(&relit.neutral));
    // The built-in captures' key light (avatar/synthetic.rs).
    let key = Vec3::new(0.35, 0.55, 0.76).normalize();
    let brightness = |set: &visage::avatar::gaussians::GaussianSet, i: usize| {
        let dc = &set.sh[i * set.sh_stride()..i * set.sh_stride() + 3];
        dc.iter().map(|&c| dc_to_rgb(c)).sum::<f32>()
    };
    let (mut towards, mut away, mut changed) = ((0.0f64, 0), (0.0f64, 0), 0);
    let (mut deeper, mut shallower) = ((0.0f64, 0), (0.0f64, 0));
    let turn = |i: usize| to[i].normal.dot(key) - from[i].normal.dot(key);
    let (mut agree, mut pairs) = (0, 0);
    for i in 0..a.len() {
        let turn = turn(i);
        let (before, after) = (brightness(a, i), brightness(b, i));
        if before != after {
            changed += 1;
            let ratio = after / before;
            assert!(ratio.is_finite());
            assert!(
                (RELIGHT_RANGE.0 - 0.01..=RELIGHT_RANGE.1 + 0.01).contains(&ratio),
                "{ratio}"
            );
        }
        let ratio = (after / before.max(1e-3)) as f64;
        if turn > 0.05 {
            towards = (towards.0 + ratio, towards.1 + 1);
        } else if turn < -0.05 {
            away = (away.0 + ratio, away.1 + 1);
        } else if turn.abs() < 0.02 {
            // Facing the light as before, but in a hollow it was not in.
            let hollowing = to[i].cavity - from[i].cavity;
            if hollowing > 0.3 {
                deeper = (deeper.0 + ratio, deeper.1 + 1);
            } else if hollowing < -0.3 {
                shallower = (shallower.0 + ratio, shallower.1 + 1);
            }
        }
    }
    // Pairs of Gaussians on one triangle whose places turned differently,
    // outside hollows that changed and the gain's clamp.
    let mut on_triangle: std::collections::BTreeMap<u32, Vec<usize>> = Default::default();
    for i in 0..a.len() {
        on_triangle.entry(a.binding[i]).or_default().push(i);
    }
    let hollowing = |k: usize| (to[k].cavity - from[k].cavity).abs();
    let ratio = |k: usize| brightness(b, k) / brightness(a, k);
    let plain = |k: usize| hollowing(k) < 0.02 && (0.55..1.9).contains(&ratio(k));
    for members in on_triangle.values() {
        for (x, &i) in members.iter().enumerate() {
            for &j in &members[x + 1..] {
                if (turn(i) - turn(j)).abs() < 0.02 || !plain(i) || !plain(j) {
                    continue;
                }
                pairs += 1;
                if (ratio(i) > ratio(j)) == (turn(i) > turn(j)) {
                    agree += 1;
                }
            }
        }
    }
    assert!(pairs > 20, "{pairs} pairs");
    assert!(
        agree * 10 >= pairs * 9,
        "{agree} of {pairs} pairs brighter where their place turned towards the light"
    );
    assert!(
        deeper.1 > 20 && shallower.1 > 20,
        "{deeper:?} {shallower:?}"
    );
    assert!(
        deeper.0 / (deeper.1 as f64) < 0.97,
        "into a hollow: {deeper:?}"
    );
    assert!(
        shallower.0 / (shallower.1 as f64) > 1.03,
        "out of a hollow: {shallower:?}"
    );
    assert!(changed > a.len() / 4, "{changed} of {} relit", a.len());
    assert!(towards.1 > 50 && away.1 > 50, "{towards:?} {away:?}");
    assert!(
        towards.0 / (towards.1 as f64) > 1.01,
        "towards the light: {towards:?}"
    );
    assert!(
        away.0 / (away.1 as f64) < 0.99,
        "away from the light: {away:?}"
    );

    // A shape edit rebuilds the Gaussians only when they are relit.
    let mut next = resolve(e, &r);
    next.shape[Group::Nose.index()] = vec![0.5, 0.0, 0.0, 0.5];
    let mut c = relit.clone();
    assert!(e.update(&mut c, &next).gaussians);
    let mut c = kept.clone();
    next.post.shading = Shading::Kept;
    assert!(!e.update(&mut c, &next).gaussians);
}

/// Reshaped Gaussians are made once per shape and kept between edits
/// (method §6.7): whatever the order of edits — assignments, a shape
/// weight, another base, the options, a source shown again — a composite
/// brought up to date equals one composed from scratch, bit for bit, under
/// the colour seams as under the thesis's and the cross-fade's border
/// extras; and the edits do reshape (against the similarity alone).
#[test]
fn reshaped_gaussians_kept_between_edits_match_a_fresh_composite() {
    use visage::compose::recipe::Anchor;
    let e = engine();
    let n = names(e);
    for smoothing in [Smoothing::Blend, Smoothing::Crossfade, Smoothing::Thesis] {
        let mut r = Recipe::unedited(&n[0]);
        r.post = PostProcess {
            smoothing,
            ..PostProcess::BEST
        };
        r.groups.insert("nose".into(), edit(&n[1], &[(&n[2], 0.7)]));
        r.groups
            .insert("mouth".into(), edit(&n[3], &[(&n[3], 0.5)]));
        let mut c = e.compose(&resolve(e, &r));
        let mut steps: Vec<Recipe> = Vec::new();
        // Another source for the eyes, then the nose's shape, then the
        // first assignment again on the new shape.
        r.groups.insert("eyes".into(), edit(&n[2], &[]));
        steps.push(r.clone());
        r.groups.insert("nose".into(), edit(&n[1], &[(&n[3], 0.9)]));
        steps.push(r.clone());
        r.groups.remove("eyes");
        steps.push(r.clone());
        // The similarity alone, the whole reshaping again, the anchors off
        // and on, and another base.
        r.post.deform = Deform::Similarity;
        steps.push(r.clone());
        r.post.deform = Deform::Affine;
        r.groups.insert("eyes".into(), edit(&n[1], &[]));
        steps.push(r.clone());
        r.post.anchor = Anchor::Parent;
        steps.push(r.clone());
        r.post.anchor = Anchor::Nearest;
        steps.push(r.clone());
        r.base = n[2].clone();
        steps.push(r.clone());
        for (k, step) in steps.iter().enumerate() {
            let next = resolve(e, step);
            let label = format!("{smoothing:?} step {k}");
            assert!(update_matches_fresh(e, &mut c, &next, &label), "{label}");
            let a = &c.gaussians;
            if step.post.deform == Deform::Affine {
                let mut plain = next.clone();
                plain.post.deform = Deform::Similarity;
                let plain = e.compose(&plain);
                let moved = (0..a.len())
                    .filter(|&i| a.log_scale[i] != plain.gaussians.log_scale[i])
                    .count();
                assert!(
                    moved > a.len() / 4,
                    "{smoothing:?} step {k}: {moved} reshaped"
                );
            }
        }
    }
}
