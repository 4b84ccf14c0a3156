//! Selecting a composite's Gaussians and the post-processing on them:
//! incremental updates, the thesis's smoothing and colour correction,
//! cross-fades, hard meshes (near-black regions, degenerate and sliver
//! triangles, disjoint parts, far coordinates), reproducibility on any number
//! of threads, the base's skin, membership by place and a swapped mouth's
//! inside.

use super::*;

#[test]
fn selection_follows_the_assignment_and_updates_only_what_changed() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert("eyes".into(), edit(&n[2], &[]));
    // By parent triangle, so the region of each selected Gaussian is its
    // binding's (membership by place has its own test).
    r.post.membership = visage::compose::recipe::Membership::Parent;
    let resolved = resolve(e, &r);
    let mut c = e.compose(&resolved);
    let model = &e.database().model;
    for b in &c.blocks {
        assert_eq!(b.source, resolved.gaussians[b.region.group().index()]);
        for i in b.start..b.end {
            assert_eq!(
                model.triangle_regions[c.gaussians.binding[i] as usize],
                b.region
            );
        }
    }
    let expected: usize = Region::ALL
        .iter()
        .map(|&reg| {
            let f = resolved.gaussians[reg.group().index()];
            let src = &e.database().sources[f].gaussians;
            src.binding
                .iter()
                .filter(|&&t| model.triangle_regions[t as usize] == reg)
                .count()
        })
        .sum();
    assert_eq!(
        c.gaussians.len(),
        expected,
        "no smoothing: exactly the assigned Gaussians"
    );
    // A shape edit re-blends but keeps the selection; an assignment edit the reverse.
    let mut shape_edit = resolved.clone();
    shape_edit.shape[Group::Nose.index()] = vec![0.5, 0.5, 0.0, 0.0];
    let changes = e.update(&mut c, &shape_edit);
    assert!(changes.shape && !changes.gaussians);
    let mut assign_edit = shape_edit.clone();
    assign_edit.gaussians[Group::Nose.index()] = 3;
    let changes = e.update(&mut c, &assign_edit);
    assert!(!changes.shape && changes.gaussians);
    let fresh = e.compose(&assign_edit);
    assert_eq!(
        c.gaussians, fresh.gaussians,
        "incremental update equals a fresh build"
    );
    assert_eq!(c.neutral, fresh.neutral);
}

#[test]
fn thesis_smoothing_adds_half_opaque_neighbours_only_where_sources_differ() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.smoothing = Smoothing::Thesis;
    let same = e.compose(&resolve(e, &r));
    assert!(
        same.blocks.iter().all(|b| b.extra_from.is_none()),
        "one source: no extras"
    );
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    let c = e.compose(&resolve(e, &r));
    let extras: Vec<_> = c.blocks.iter().filter(|b| b.extra_from.is_some()).collect();
    assert!(!extras.is_empty());
    for b in extras {
        let from = b.extra_from.unwrap();
        assert!(from.group() == Group::Nose || b.region.group() == Group::Nose);
        let src = &e.database().sources[b.source].gaussians;
        // Every extra is a copy of a source Gaussian at half its opacity.
        for i in b.start..b.end.min(b.start + 50) {
            let alpha = sigmoid(c.gaussians.opacity_logit[i]);
            let original = (0..src.len())
                .find(|&j| {
                    src.position[j] == c.gaussians.position[i]
                        && src.binding[j] == c.gaussians.binding[i]
                })
                .expect("extra comes from its source");
            assert!((alpha - 0.5 * sigmoid(src.opacity_logit[original])).abs() < 1e-4);
        }
    }
}

#[test]
fn crossfade_keeps_coverage_exact() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.smoothing = Smoothing::Crossfade;
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    let c = e.compose(&resolve(e, &r));
    // On every border triangle, own and foreign opacity exponents sum to one: the
    // transmittance of the most opaque own/foreign pair multiplies back to the original.
    let extras = c.blocks.iter().filter(|b| b.extra_from.is_some()).count();
    assert!(extras > 0);
    let mut checked = 0;
    for b in c.blocks.iter().filter(|b| b.extra_from.is_some()) {
        for i in b.start..b.end {
            let t = c.gaussians.binding[i];
            let src = &e.database().sources[b.source].gaussians;
            let j = (0..src.len())
                .find(|&j| src.binding[j] == t && src.position[j] == c.gaussians.position[i])
                .unwrap();
            let (full, split) = (
                sigmoid(src.opacity_logit[j]),
                sigmoid(c.gaussians.opacity_logit[i]),
            );
            let exponent = (1.0 - split).ln() / (1.0 - full).ln();
            assert!(
                exponent > 0.0 && exponent <= 0.5 + 1e-4,
                "foreign share {exponent}"
            );
            checked += 1;
            if checked > 200 {
                break;
            }
        }
    }
}

#[test]
fn thesis_colour_correction_matches_region_means_to_the_base() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.colour = ColourCorrection::Thesis;
    r.groups.insert("face".into(), edit(&n[3], &[]));
    let c = e.compose(&resolve(e, &r));
    let block = c
        .blocks
        .iter()
        .find(|b| b.region == Region::Skin && b.extra_from.is_none())
        .unwrap();
    let indices: Vec<u32> = (block.start as u32..block.end as u32).collect();
    let corrected = weighted_mean_colour(&c.gaussians, &indices).unwrap();
    let base = &e.database().sources[0].gaussians;
    let base_idx: Vec<u32> = (0..base.len() as u32)
        .filter(|&i| {
            e.database().model.triangle_regions[base.binding[i as usize] as usize] == Region::Skin
        })
        .collect();
    let target = weighted_mean_colour(base, &base_idx).unwrap();
    assert!(
        corrected.abs_diff_eq(target, 2e-3),
        "{corrected} vs {target}"
    );
}

#[test]
fn near_black_regions_get_bounded_gains_and_no_nan() {
    let mut db = small_db();
    // Source 1 paints its whole face pitch black; the base keeps its colours.
    let model = db.model.clone();
    let set = &mut db.sources[1].gaussians;
    let stride = set.sh_stride();
    for i in 0..set.len() {
        if model.triangle_regions[set.binding[i] as usize] == Region::Skin {
            for k in 0..stride {
                set.sh[i * stride + k] = if k < 3 { rgb_to_dc(0.0) } else { 0.0 };
            }
        }
    }
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    for colour in [ColourCorrection::Thesis, ColourCorrection::Skin] {
        let mut r = Recipe::unedited(&n[0]);
        r.post.colour = colour;
        r.groups.insert("face".into(), edit(&n[1], &[]));
        let c = e.compose(&resolve(&e, &r));
        let g = c.colour_gains[Region::Skin.index()];
        assert!(
            g.is_finite() && g.max_element() <= GAIN_RANGE.1 && g.min_element() >= GAIN_RANGE.0,
            "{g}"
        );
        assert!(c.gaussians.sh.iter().all(|x| x.is_finite()));
        c.gaussians
            .validate(e.database().model.triangle_count())
            .unwrap();
        // Black stays dark: a bounded gain cannot make it skin-coloured.
        let block = c
            .blocks
            .iter()
            .find(|b| b.region == Region::Skin && b.extra_from.is_none())
            .unwrap();
        let stride = c.gaussians.sh_stride();
        let rgb = dc_to_rgb(c.gaussians.sh[block.start * stride]);
        assert!(rgb < 0.1, "{rgb}");
    }
}

#[test]
fn degenerate_and_sliver_triangles_in_a_source_leave_no_nan() {
    let mut db = small_db();
    let model = db.model.clone();
    let src = &mut db.sources[2];
    // Collapse some nose triangles to a point and squash others into slivers.
    let mut collapsed = 0;
    for (k, (t, r)) in model
        .triangles
        .iter()
        .zip(&model.triangle_regions)
        .enumerate()
    {
        if *r == Region::Nose {
            let [a, b, c] = t.map(|i| model.template[i as usize]);
            if k % 2 == 0 {
                let centre = (a + b + c) / 3.0;
                for (&v, p) in t.iter().zip([a, b, c]) {
                    src.static_offset[v as usize] = (centre - p).as_dvec3();
                }
                collapsed += 1;
            } else {
                src.static_offset[t[2] as usize] =
                    (0.5 * (a + b) - c + Vec3::splat(1e-9)).as_dvec3();
            }
        }
    }
    assert!(collapsed > 10);
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.colour = ColourCorrection::Thesis;
    r.groups.insert("nose".into(), edit(&n[2], &[(&n[2], 1.0)]));
    r.groups
        .insert("face".into(), edit(&n[2], &[(&n[2], 0.5), (&n[0], 0.5)]));
    r.groups.insert("hair".into(), edit(&n[1], &[]));
    r.animation.motion = "talk".into();
    for smoothing in [Smoothing::Thesis, Smoothing::Blend] {
        r.post.smoothing = smoothing;
        let resolved = resolve(&e, &r);
        let c = e.compose(&resolved);
        assert!(c.residual <= 1e-10);
        assert!(
            c.gaussians.sh.iter().all(|x| x.is_finite()),
            "{smoothing:?}"
        );
        for mode in [AnimationMode::Fast, AnimationMode::Exact] {
            let mut posed = PosedMesh::default();
            let (ex, pose) = e.frame_parameters(&resolved, 40);
            e.pose_with(&c, &ex, &pose, mode, &mut posed);
            let scene = e.scene(&c, &posed);
            assert!(scene.position.iter().all(|p| p.is_finite()), "{mode:?}");
            assert!(scene.rotation.iter().all(|q| q.is_finite()));
            assert!(scene.scale.iter().all(|s| s.is_finite()));
            assert!(scene.opacity.iter().all(|o| o.is_finite()));
        }
    }
}

#[test]
fn a_disjoint_part_without_anchor_is_a_clear_error() {
    let mut model = build_head();
    let n = model.vertex_count() as u32;
    for p in [
        Vec3::new(0.3, 0.0, 0.0),
        Vec3::new(0.31, 0.0, 0.0),
        Vec3::new(0.3, 0.01, 0.0),
    ] {
        model.template.push(p);
        model.skin_weights.push([0.0, 1.0, 0.0, 0.0, 0.0]);
    }
    model.triangles.push([n, n + 1, n + 2]);
    model.triangle_regions.push(Region::Skin);
    let err = Blender::new(&model).err().expect("must fail").to_string();
    assert!(
        err.contains("not connected") && err.contains("skin"),
        "{err}"
    );
    assert!(!err.contains('\n'));
}

#[test]
fn far_from_the_origin_blending_keeps_its_relative_accuracy() {
    let near = small_db();
    let mut far = near.clone();
    let offset = Vec3::splat(1e3);
    for v in &mut far.model.template {
        *v += offset;
    }
    let (en, ef) = (Engine::new(near).unwrap(), Engine::new(far).unwrap());
    let n = names(&en);
    let mut r = Recipe::unedited(&n[0]);
    all_groups(&mut r, &n[0], &[(&n[1], 0.4), (&n[2], 0.6)]);
    let (cn, cf) = (en.compose(&resolve(&en, &r)), ef.compose(&resolve(&ef, &r)));
    assert!(cf.residual <= 1e-10, "residual {}", cf.residual);
    let shifted: Vec<Vec3> = cf.neutral.iter().map(|v| *v - offset).collect();
    // f32 storage at 1 km resolves ~6e-5 m; the solve must not lose more than that.
    let err = max_distance(&shifted, &cn.neutral);
    assert!(err < 2.5e-4, "error {err} m at 1e3 m from the origin");
}

#[test]
fn the_full_composite_has_no_nan_and_is_reproducible() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.post.smoothing = Smoothing::Crossfade;
    r.post.colour = ColourCorrection::Skin;
    r.groups
        .insert("eyes".into(), edit(&n[1], &[(&n[1], 0.5), (&n[0], 0.5)]));
    r.groups
        .insert("mouth".into(), edit(&n[2], &[(&n[2], 1.0)]));
    r.groups.insert("hair".into(), edit(&n[3], &[(&n[3], 1.0)]));
    r.animation.motion = "smile".into();
    let resolved = resolve(e, &r);
    let a = e.compose(&resolved);
    let b = e.compose(&resolved);
    assert_eq!(a.gaussians, b.gaussians);
    assert_eq!(a.neutral, b.neutral);
    a.gaussians
        .validate(e.database().model.triangle_count())
        .unwrap();
    let mut posed = PosedMesh::default();
    for frame in [0, 37, 90] {
        e.pose(&a, frame, &mut posed);
        let scene = e.scene(&a, &posed);
        assert!(scene.position.iter().all(|p| p.is_finite()));
        assert!(scene.sh.iter().all(|x| x.is_finite()));
    }
    assert_eq!(
        state_hash(e.database(), &resolved),
        state_hash(e.database(), &resolved)
    );
    let mut other = resolved.clone();
    other.frame += 1;
    assert_ne!(
        state_hash(e.database(), &resolved),
        state_hash(e.database(), &other)
    );
}

/// The first source with the second's eyes at half shape and the third's
/// mouth, under the best post-processing.
fn eyes_and_mouth_swapped(n: &[String]) -> Recipe {
    let mut r = Recipe::unedited(&n[0]);
    r.groups
        .insert("eyes".into(), edit(&n[1], &[(&n[1], 0.5), (&n[0], 0.5)]));
    r.groups
        .insert("mouth".into(), edit(&n[2], &[(&n[2], 1.0)]));
    r.post = PostProcess::BEST;
    r
}

#[test]
fn an_update_that_changes_how_gaussians_follow_the_shape_equals_a_fresh_build() {
    // The post-processing and the shape change together: the update must
    // reshape under the new recipe's anchor and deform, not the old one's.
    let e = engine();
    let n = names(e);
    let best = resolve(e, &eyes_and_mouth_swapped(&n));
    assert_eq!(best.post.deform, Deform::Affine, "ours stretches");
    let mut similar = best.clone();
    similar.post.deform = Deform::Similarity;
    let mut parent = best.clone();
    parent.post.anchor = visage::compose::recipe::Anchor::Parent;
    let plain = resolve(e, &Recipe::unedited(&n[0]));
    for (before, after) in [
        (&plain, &best),
        (&plain, &similar),
        (&best, &similar),
        (&similar, &best),
        (&best, &parent),
        (&parent, &best),
        (&plain, &parent),
    ] {
        let mut edited = e.compose(before);
        e.update(&mut edited, after);
        let fresh = e.compose(after);
        assert!(
            edited.gaussians == fresh.gaussians,
            "{:?} → {:?}",
            (before.post.anchor, before.post.deform),
            (after.post.anchor, after.post.deform)
        );
    }
}

#[test]
fn a_composite_is_the_same_on_any_number_of_threads_and_after_any_edit() {
    // Own Gaussians are copied in chunks on all threads, into a set whose
    // earlier contents an edit reuses: neither may show in the result.
    let e = engine();
    let n = names(e);
    let mut r = eyes_and_mouth_swapped(&n);
    r.groups.insert("hair".into(), edit(&n[3], &[(&n[3], 1.0)]));
    r.groups.insert("nose".into(), edit(&n[1], &[]));
    let best = resolve(e, &r);
    let mut other = best.clone();
    other.gaussians = [1; Group::COUNT];
    let in_pool = |threads: usize, recipe: &ResolvedRecipe| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| e.compose(recipe))
    };
    let one = in_pool(1, &best);
    let parts = one.blocks.iter().filter(|b| b.end > b.start).count();
    assert!(parts >= 5, "the recipe draws on several sources: {parts}");
    for threads in [2, 3] {
        let many = in_pool(threads, &best);
        assert_eq!(many.gaussians, one.gaussians, "{threads} threads");
        assert_eq!(many.blocks, one.blocks);
        assert_eq!(many.colour_gains, one.colour_gains);
    }
    for before in [&other, &best] {
        let mut edited = e.compose(before);
        e.update(&mut edited, &best);
        assert_eq!(edited.gaussians, one.gaussians);
        assert_eq!(edited.blocks, one.blocks);
    }
    // A shape edit alone moves where the base's skin fits (method §7.11):
    // the update re-selects even where nothing else follows the shape.
    let mut plain = best.clone();
    plain.post.anchor = Anchor::Parent;
    plain.post.shading = Shading::Kept;
    let mut reshaped = plain.clone();
    for row in reshaped.shape.iter_mut() {
        *row = (0..row.len())
            .map(|s| f64::from(u8::from(s == 3)))
            .collect();
    }
    let mut edited = e.compose(&reshaped);
    assert!(e.update(&mut edited, &plain).gaussians);
    let fresh = e.compose(&plain);
    assert_eq!(edited.gaussians, fresh.gaussians);
    assert_eq!(edited.blocks, fresh.blocks);
    // A cross-fade appends extras after the own Gaussians; back to colour
    // seams they are gone.
    let mut crossfade = best.clone();
    crossfade.post.smoothing = Smoothing::Crossfade;
    let mut edited = e.compose(&crossfade);
    assert!(edited.gaussians.len() > one.gaussians.len());
    e.update(&mut edited, &best);
    assert_eq!(edited.gaussians, one.gaussians);
}

#[test]
fn skin_from_the_base_takes_over_swapped_skin_only_where_the_base_shapes_or_fits_it() {
    let e = engine();
    let n = names(e);
    let (base, other) = (0, 1);
    let compose = |shape: &[(&str, f64)], skin: SkinSource| {
        let mut r = Recipe::unedited(&n[base]);
        r.post = PostProcess {
            skin,
            ..PostProcess::BEST
        };
        for group in ["nose", "mouth"] {
            r.groups.insert(group.into(), edit(&n[other], shape));
        }
        e.compose(&resolve(e, &r))
    };
    let source_gaussians = &e.database().sources[other].gaussians;
    let block = |c: &visage::compose::engine::Composite, region: Region, source: usize| {
        c.blocks
            .iter()
            .find(|b| b.region == region && b.source == source && b.extra_from.is_none())
            .copied()
    };
    // The source's own shape (the base's weight 0): the base's skin shows
    // only where the composite's surface fits the base's (method §7.11).
    let own_shape = [(n[other].as_str(), 1.0)];
    let own = compose(&own_shape, SkinSource::Base);
    let model = &e.database().model;
    let vertex_triangles = Csr::vertex_triangles(model.vertex_count(), &model.triangles);
    let topology = Topology {
        triangles: &model.triangles,
        vertex_triangles: &vertex_triangles,
    };
    let misfit = similarity_misfit(e.source_neutral(base), &own.neutral, topology);
    let mut shown = 0;
    for region in [Region::Nose, Region::Lips] {
        let Some(b) = block(&own, region, base) else {
            continue;
        };
        let fits = (b.start..b.end)
            .filter(|&i| misfit[own.gaussians.binding[i] as usize] < BASE_FIT.0)
            .count();
        assert!(
            fits * 20 >= (b.end - b.start) * 19,
            "{region:?}: {fits} of {b:?} fit"
        );
        shown += b.end - b.start;
    }
    assert!(
        shown > 0,
        "the base's skin fits somewhere on the swapped nose"
    );
    // The base's shape: the base's skin shows in the swapped regions and
    // the source's skin gives way, its lips do not.
    let base_shape = [(n[base].as_str(), 1.0)];
    let before = compose(&base_shape, SkinSource::Source);
    let after = compose(&base_shape, SkinSource::Base);
    after
        .gaussians
        .validate(e.database().model.triangle_count())
        .unwrap();
    assert!(after.gaussians.opacity_logit.iter().all(|x| x.is_finite()));
    let base_nose = block(&after, Region::Nose, base).expect("the base's skin on the nose");
    assert!(base_nose.end - base_nose.start > 20, "{base_nose:?}");
    assert!(block(&before, Region::Nose, base).is_none());
    let opacity_sum = |c: &visage::compose::engine::Composite,
                       b: visage::compose::engine::Block| {
        (b.start..b.end)
            .map(|i| sigmoid(c.gaussians.opacity_logit[i]))
            .sum::<f32>()
    };
    let nose_before = block(&before, Region::Nose, other).unwrap();
    let nose_after = block(&after, Region::Nose, other).unwrap();
    assert!(
        opacity_sum(&after, nose_after) < 0.5 * opacity_sum(&before, nose_before),
        "the source's nose skin gives way"
    );
    // Lips are no skin: the source's lip Gaussians keep their opacity (a
    // Gaussian of the source on the same triangle with the same opacity:
    // ours stretches them with the shape, so their places moved).
    let lips = block(&after, Region::Lips, other).unwrap();
    let full = (lips.start..lips.end)
        .filter(|&i| {
            let from = source_gaussians
                .opacity_logit
                .iter()
                .zip(&source_gaussians.binding)
                .any(|(&o, &t)| {
                    o == after.gaussians.opacity_logit[i] && t == after.gaussians.binding[i]
                });
            from
        })
        .count();
    assert!(
        full * 2 > lips.end - lips.start,
        "most lip Gaussians keep their opacity: {full} of {}",
        lips.end - lips.start
    );
}

#[test]
fn membership_by_place_counts_a_drifted_gaussian_where_it_sits_and_keeps_borders() {
    use visage::compose::membership::place_triangles;
    use visage::compose::recipe::Membership;
    let mut db = small_db();
    let model = db.model.clone();
    let neutral = db.sources[0].neutral(&model);
    let centroid = |t: usize| {
        let [a, b, c] = model.triangles[t].map(|v| neutral[v as usize]);
        (a + b + c) / 3.0
    };
    let regions = &model.triangle_regions;
    let set = &mut db.sources[0].gaussians;
    let on_nose: Vec<usize> = (0..set.len())
        .filter(|&i| regions[set.binding[i] as usize] == Region::Nose)
        .collect();
    // A cheek triangle well away from the nose.
    let nose_tip = centroid(set.binding[on_nose[0]] as usize);
    let cheek = (0..model.triangles.len())
        .filter(|&t| regions[t] == Region::Skin)
        .find(|&t| (centroid(t) - nose_tip).length() > 0.03 && centroid(t).z > 0.0)
        .unwrap();
    let drifted = on_nose[0];
    drift_to(set, drifted, &neutral, &model.triangles, centroid(cheek));
    // Exactly on an edge the nose shares with the face: stays with its parent.
    let (border, shared) = (0..model.triangles.len())
        .filter(|&t| regions[t] == Region::Nose)
        .find_map(|t| {
            let tri = model.triangles[t];
            (0..model.triangles.len())
                .filter(|&u| regions[u] == Region::Skin)
                .find_map(|u| {
                    let common: Vec<u32> = tri
                        .iter()
                        .copied()
                        .filter(|v| model.triangles[u].contains(v))
                        .collect();
                    (common.len() == 2).then_some((t, common))
                })
        })
        .unwrap();
    let on_border = on_nose[1];
    set.binding[on_border] = border as u32;
    let midpoint = 0.5 * (neutral[shared[0] as usize] + neutral[shared[1] as usize]);
    drift_to(set, on_border, &neutral, &model.triangles, midpoint);

    let placed = place_triangles(&model, set, &neutral);
    assert_eq!(
        regions[placed[drifted] as usize],
        Region::Skin,
        "the drifted one counts where it sits"
    );
    assert_eq!(
        placed[on_border], border as u32,
        "a Gaussian on the border keeps its parent"
    );
    // Off the eyeballs (whose covered part counts for the lids:
    // an_eyeball_gaussian_under_the_lid_counts_for_the_lid_…), the built-in
    // Gaussians sit on their triangles.
    let moved = (0..set.len())
        .filter(|&i| {
            let parent = regions[set.binding[i] as usize];
            placed[i] != set.binding[i]
                && !matches!(parent, Region::LeftEyeball | Region::RightEyeball)
        })
        .count();
    assert!(
        moved < set.len() / 100,
        "built-in Gaussians sit on their triangles: {moved} moved"
    );

    // Composed: face from source 0 on base 1. By parent the drifted Gaussian
    // is left out (its nose comes from the base); by place it is taken.
    let marker = set.position[drifted];
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[1]);
    r.groups.insert("face".into(), edit(&n[0], &[]));
    let has_marker = |membership: Membership| {
        let mut r = r.clone();
        r.post.membership = membership;
        let c = e.compose(&resolve(&e, &r));
        c.gaussians.position.contains(&marker)
    };
    assert!(has_marker(Membership::Place));
    assert!(!has_marker(Membership::Parent));
}

#[test]
fn a_source_with_an_empty_region_composes_by_place_with_semantic_colour() {
    use visage::avatar::gaussians::GaussianSet;
    use visage::compose::recipe::Membership;
    let mut db = small_db();
    let regions = db.model.triangle_regions.clone();
    // Source 0 loses every Gaussian of its nose and its hair.
    let old = &db.sources[0].gaussians;
    let mut kept = GaussianSet::with_degree(old.sh_degree);
    for i in 0..old.len() {
        if !matches!(
            regions[old.binding[i] as usize],
            Region::Nose | Region::Hair
        ) {
            kept.push_from(old, i, old.opacity_logit[i]);
        }
    }
    db.sources[0].gaussians = kept;
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[1]);
    all_groups(&mut r, &n[0], &[(&n[0], 1.0)]);
    r.post.colour = ColourCorrection::Semantic;
    for (membership, smoothing) in [
        (Membership::Place, Smoothing::Crossfade),
        (Membership::Parent, Smoothing::Crossfade),
        (Membership::Place, Smoothing::Blend),
    ] {
        r.post.membership = membership;
        r.post.smoothing = smoothing;
        let c = e.compose(&resolve(&e, &r));
        assert!(!c.gaussians.is_empty());
        assert!(
            c.gaussians.sh.iter().all(|x| x.is_finite()),
            "{membership:?}"
        );
        assert!(
            c.blocks
                .iter()
                .filter(|b| b.region == Region::Nose && b.extra_from.is_none())
                .all(|b| b.start == b.end),
            "an empty region stays empty ({membership:?})"
        );
    }
}

/// A swapped mouth's inside (method §7.7): Gaussians bound to the cavity
/// that show the source's skin — as training leaves them where a closed
/// mouth hides the cavity — take the base's skin; the cavity's dark lining
/// keeps its colour.
#[test]
fn skin_shown_from_a_swapped_mouths_inside_takes_the_bases_tone_and_its_lining_stays() {
    use visage::avatar::gaussians::GaussianSet;
    let (base_skin, source_skin) = (Vec3::new(0.85, 0.68, 0.58), Vec3::new(0.45, 0.30, 0.20));
    let lining = Vec3::new(0.50, 0.16, 0.17);
    let (skin_mark, lining_mark) = (3.0f32, 2.0f32);
    let mut db = small_db();
    let regions = db.model.triangle_regions.clone();
    let flat = |set: &mut GaussianSet, i: usize, rgb: Vec3| {
        let stride = set.sh_stride();
        let sh = &mut set.sh[i * stride..(i + 1) * stride];
        sh.fill(0.0);
        sh[..3].copy_from_slice(&rgb.to_array().map(rgb_to_dc));
    };
    for (f, skin) in [(0, base_skin), (1, source_skin)] {
        let set = &mut db.sources[f].gaussians;
        let mut inside = 0;
        for i in 0..set.len() {
            match regions[set.binding[i] as usize] {
                Region::Skin | Region::Nose | Region::Neck => flat(set, i, skin),
                Region::LipsInside => {
                    // Every other one paints the source's skin.
                    let (rgb, mark) = if inside % 2 == 0 {
                        (skin, skin_mark)
                    } else {
                        (lining, lining_mark)
                    };
                    flat(set, i, rgb);
                    set.opacity_logit[i] = mark;
                    inside += 1;
                }
                _ => {}
            }
        }
    }
    let e = Engine::new(db).unwrap();
    let n = names(&e);
    let mut r = Recipe::unedited(&n[0]);
    r.post = PostProcess {
        smoothing: Smoothing::Off,
        skin: SkinSource::Source,
        shading: Default::default(),
        ..PostProcess::BEST
    };
    r.groups
        .insert("mouth".into(), edit(&n[1], &[(&n[0], 1.0)]));
    let c = e.compose(&resolve(&e, &r));
    let inside = c
        .blocks
        .iter()
        .find(|b| b.region == Region::LipsInside && b.source == 1 && b.extra_from.is_none())
        .copied()
        .unwrap();
    let colour = |i: usize| {
        let sh = c.gaussians.sh_of(i);
        Vec3::new(dc_to_rgb(sh[0]), dc_to_rgb(sh[1]), dc_to_rgb(sh[2]))
    };
    let (mut skins, mut linings) = (0, 0);
    for i in inside.start..inside.end {
        let rgb = colour(i);
        if c.gaussians.opacity_logit[i] == skin_mark {
            skins += 1;
            assert!(
                rgb.distance(base_skin) < 0.03,
                "the source's skin in its mouth takes the base's: {rgb}"
            );
        } else if c.gaussians.opacity_logit[i] == lining_mark {
            linings += 1;
            assert!(rgb.distance(lining) < 1e-4, "the lining stays: {rgb}");
        }
    }
    assert!(skins > 10 && linings > 10, "{skins} skin, {linings} lining");
}

#[test]
fn an_eyeball_gaussian_under_the_lid_counts_for_the_lid_and_one_in_the_opening_for_the_eye() {
    use visage::compose::membership::place_triangles;
    let mut db = small_db();
    let model = db.model.clone();
    let neutral = db.sources[0].neutral(&model);
    let regions = &model.triangle_regions;
    let centroid = |t: usize| {
        let [a, b, c] = model.triangles[t].map(|v| neutral[v as usize]);
        (a + b + c) / 3.0
    };
    let eyeball: Vec<usize> = (0..model.triangles.len())
        .filter(|&t| regions[t] == Region::RightEyeball)
        .collect();
    let centre = eyeball.iter().map(|&t| centroid(t)).sum::<Vec3>() / eyeball.len() as f32;
    let radius = eyeball
        .iter()
        .map(|&t| (centroid(t) - centre).length())
        .sum::<f32>()
        / eyeball.len() as f32;
    // The front of the eye shows in the opening; high on its front
    // hemisphere the upper lid covers it.
    let front = *eyeball
        .iter()
        .max_by(|&&a, &&b| centroid(a).z.total_cmp(&centroid(b).z))
        .unwrap();
    let covered = *eyeball
        .iter()
        .filter(|&&t| centroid(t).z > centre.z + 0.3 * radius)
        .max_by(|&&a, &&b| centroid(a).y.total_cmp(&centroid(b).y))
        .unwrap();
    let set = &mut db.sources[0].gaussians;
    for (i, t) in [(0, front), (1, covered), (2, covered)] {
        set.binding[i] = t as u32;
        drift_to(set, i, &neutral, &model.triangles, centroid(t));
    }
    set.position[2] = Vec3::NAN;

    let placed = place_triangles(&model, set, &neutral);
    assert_eq!(regions[placed[0] as usize], Region::RightEyeball);
    let lid = regions[placed[1] as usize];
    assert!(
        matches!(lid, Region::RightEyeRegion | Region::RightEyeSocket),
        "under the lid it counts for {lid:?}"
    );
    let lid_centre = centroid(placed[1] as usize);
    assert!(
        lid_centre.z > centroid(covered).z,
        "the lid lies in front of it"
    );
    assert_eq!(placed[2], covered as u32, "a NaN centre keeps its parent");
    let under_lids = (0..set.len())
        .filter(|&i| {
            let parent = regions[set.binding[i] as usize];
            matches!(parent, Region::LeftEyeball | Region::RightEyeball)
                && regions[placed[i] as usize].group() == parent.group()
                && regions[placed[i] as usize] != parent
        })
        .count();
    let on_eyeballs = (0..set.len())
        .filter(|&i| {
            matches!(
                regions[set.binding[i] as usize],
                Region::LeftEyeball | Region::RightEyeball
            )
        })
        .count();
    assert!(
        under_lids > 0 && under_lids < on_eyeballs * 3 / 4,
        "{under_lids} of {on_eyeballs} eyeball Gaussians lie under the lids"
    );
}

#[test]
fn the_canonical_order_depends_on_the_gaussians_not_on_how_a_composite_lists_them() {
    use visage::compose::{canonical_order, reordered};
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[1]);
    r.groups.insert("eyes".into(), edit(&n[0], &[(&n[0], 0.5)]));
    let set = e.compose(&resolve(e, &r)).gaussians;
    let model = &e.database().model;
    let mut backwards: Vec<u32> = (0..set.len() as u32).collect();
    backwards.reverse();
    let shuffled = reordered(&set, &backwards);
    let canonical = |s| reordered(s, &canonical_order(model, s));
    let (a, b) = (canonical(&set), canonical(&shuffled));
    assert_eq!(a.binding, b.binding);
    assert_eq!(a.position, b.position);
    assert_eq!(a.rotation, b.rotation);
    assert_eq!(a.log_scale, b.log_scale);
    assert_eq!(a.sh, b.sh);
    assert_eq!(a.opacity_logit, b.opacity_logit);
    // By region of the triangle first, as exports have always listed them.
    let regions: Vec<usize> = a
        .binding
        .iter()
        .map(|&t| model.triangle_regions[t as usize].index())
        .collect();
    assert!(regions.windows(2).all(|w| w[0] <= w[1]));
}
