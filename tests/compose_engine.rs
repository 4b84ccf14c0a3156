//! The composition engine: recipes, selection, blending, post-processing and
//! animation, including the numerical hard cases.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use glam::Vec3;
use visage::avatar::database::Database;
use visage::avatar::gaussians::{dc_to_rgb, rgb_to_dc, sigmoid};
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::base_skin::{similarity_misfit, Topology, BASE_FIT};
use visage::compose::blend::Blender;
use visage::compose::colour::{weighted_mean_colour, GAIN_RANGE};
use visage::compose::engine::{Engine, PosedMesh};
use visage::compose::recipe::{
    Anchor, AnimationMode, ColourCorrection, Deform, GroupEdit, PostProcess, Recipe,
    ResolvedRecipe, Shading, SkinSource, Smoothing,
};
use visage::compose::selection::Csr;
use visage::compose::state_hash;
use visage::model::builtin::build_head;
use visage::model::head::{Joint, Pose};
use visage::model::regions::{Group, Region};

fn small_db() -> Database {
    builtin_database(
        build_head(),
        SyntheticOptions {
            seed: 5,
            sources: 4,
            gaussians_per_avatar: 12_000,
        },
    )
    .unwrap()
}

fn engine() -> &'static Engine {
    static ENGINE: OnceLock<Engine> = OnceLock::new();
    ENGINE.get_or_init(|| Engine::new(small_db()).unwrap())
}

fn names(e: &Engine) -> Vec<String> {
    e.database()
        .sources
        .iter()
        .map(|s| s.name.clone())
        .collect()
}

fn edit(gaussians: &str, shape: &[(&str, f64)]) -> GroupEdit {
    GroupEdit {
        gaussians: gaussians.to_string(),
        shape: shape
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect::<BTreeMap<_, _>>(),
    }
}

fn resolve(e: &Engine, recipe: &Recipe) -> ResolvedRecipe {
    recipe.resolve(e.database()).unwrap()
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f32::max)
}

fn all_groups(recipe: &mut Recipe, gaussians: &str, shape: &[(&str, f64)]) {
    for g in Group::ALL {
        recipe
            .groups
            .insert(g.name().into(), edit(gaussians, shape));
    }
}

#[test]
fn recipe_validation_names_the_problem() {
    let e = engine();
    let db = e.database();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.base = "nobody".into();
    assert!(r
        .resolve(db)
        .unwrap_err()
        .to_string()
        .contains("unknown source 'nobody'"));
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert("forehead".into(), edit(&n[1], &[]));
    assert!(r
        .resolve(db)
        .unwrap_err()
        .to_string()
        .contains("unknown group 'forehead'"));
    let mut r = Recipe::unedited(&n[0]);
    r.groups
        .insert("nose".into(), edit(&n[1], &[(&n[1], -0.5)]));
    assert!(r.resolve(db).unwrap_err().to_string().contains("≥ 0"));
    let mut r = Recipe::unedited(&n[0]);
    r.groups
        .insert("nose".into(), edit(&n[1], &[(&n[1], 0.0), (&n[0], 0.0)]));
    assert!(r.resolve(db).unwrap_err().to_string().contains("all zero"));
    let mut r = Recipe::unedited(&n[0]);
    r.groups
        .insert("nose".into(), edit(&n[1], &[(&n[1], f64::NAN)]));
    assert!(r.resolve(db).is_err());
    let mut r = Recipe::unedited(&n[0]);
    r.animation.motion = "dance".into();
    assert!(r
        .resolve(db)
        .unwrap_err()
        .to_string()
        .contains("unknown motion"));
    // Non-zero weights are normalised.
    let mut r = Recipe::unedited(&n[0]);
    r.groups
        .insert("nose".into(), edit(&n[1], &[(&n[1], 3.0), (&n[2], 1.0)]));
    let resolved = r.resolve(db).unwrap();
    assert_eq!(resolved.shape[Group::Nose.index()][1], 0.75);
    assert_eq!(resolved.shape[Group::Nose.index()][2], 0.25);
}

#[test]
fn recipe_files_parse_strictly() {
    let good = "base = \"ada\"\n[groups.nose]\ngaussians = \"bram\"\nshape = { bram = 1.0 }\n[post]\nsmoothing = \"thesis\"\n";
    let r = Recipe::from_toml(good).unwrap();
    assert_eq!(r.post.smoothing, Smoothing::Thesis);
    assert_eq!(
        Recipe::from_toml(&r.to_toml()).unwrap(),
        r,
        "canonical text round-trips"
    );
    // A group may give only its Gaussians: it keeps the base's shape.
    let e = engine();
    let n = names(e);
    let gaussians_only = format!(
        "base = \"{}\"\n[groups.nose]\ngaussians = \"{}\"\n",
        n[0], n[1]
    );
    let r = Recipe::from_toml(&gaussians_only).unwrap();
    let resolved = resolve(e, &r);
    assert_eq!(resolved.gaussians[Group::Nose.index()], 1);
    assert_eq!(
        resolved.shape[Group::Nose.index()],
        vec![1.0, 0.0, 0.0, 0.0]
    );
    assert_eq!(Recipe::from_toml(&r.to_toml()).unwrap(), r);
    for bad in [
        "base = \"ada\"\nsmoothing = \"thesis\"\n", // misplaced key
        "base = \"ada\"\n[post]\nsmoothing = \"blur\"\n", // unknown option
        "[groups.nose]\ngaussians = \"bram\"\nshape = {}\n", // no base
        "base = \"ada\"\nversion = 9\n",            // future version
        "base = ",                                  // not TOML
    ] {
        let err = Recipe::from_toml(bad).unwrap_err().to_string();
        assert!(!err.contains('\n'), "one line: {err}");
    }
}

#[test]
fn blending_one_source_reproduces_its_mesh() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[2]);
    all_groups(&mut r, &n[2], &[(&n[2], 1.0)]);
    let c = e.compose(&resolve(e, &r));
    assert!(c.residual <= 1e-10, "residual {}", c.residual);
    assert!(max_distance(&c.neutral, e.source_neutral(2)) < 1e-6);
}

#[test]
fn an_even_blend_is_the_average_mesh_translated_to_the_base_pin() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    all_groups(&mut r, &n[0], &[(&n[1], 0.5), (&n[3], 0.5)]);
    let c = e.compose(&resolve(e, &r));
    let (a, b, base) = (
        e.source_neutral(1),
        e.source_neutral(3),
        e.source_neutral(0),
    );
    let p = e.blender().pinned_vertex() as usize;
    let shift = base[p] - 0.5 * (a[p] + b[p]);
    let expected: Vec<Vec3> = a
        .iter()
        .zip(b)
        .map(|(x, y)| 0.5 * (*x + *y) + shift)
        .collect();
    assert!(max_distance(&c.neutral, &expected) < 1e-6);
    assert!(c.residual <= 1e-10);
}

#[test]
fn weights_zero_one_and_tiny() {
    let e = engine();
    let n = names(e);
    let compose = |shape: &[(&str, f64)]| {
        let mut r = Recipe::unedited(&n[0]);
        r.groups.insert("nose".into(), edit(&n[0], shape));
        e.compose(&resolve(e, &r)).neutral
    };
    let only_a = compose(&[(&n[1], 1.0)]);
    let with_zero = compose(&[(&n[1], 1.0), (&n[2], 0.0)]);
    let with_tiny = compose(&[(&n[1], 1.0), (&n[2], 1e-12)]);
    assert_eq!(only_a, with_zero, "a zero weight changes nothing");
    assert!(
        max_distance(&only_a, &with_tiny) < 1e-6,
        "1e-12 changes (almost) nothing"
    );
    let only_b = compose(&[(&n[1], 0.0), (&n[2], 1.0)]);
    assert!(
        max_distance(&only_a, &only_b) > 1e-4,
        "the weights are used"
    );
}

#[test]
fn nose_blend_stays_local() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    r.groups.insert("nose".into(), edit(&n[0], &[(&n[3], 1.0)]));
    let c = e.compose(&resolve(e, &r));
    let base = e.source_neutral(0);
    let model = &e.database().model;
    // Vertices of the hair region (far from the nose) barely move.
    let mut far = 0.0f32;
    for (t, reg) in model.triangles.iter().zip(&model.triangle_regions) {
        if *reg == Region::Hair {
            for &v in t {
                far = far.max((c.neutral[v as usize] - base[v as usize]).length());
            }
        }
    }
    assert!(far < 5e-4, "hair moved {far} m for a nose edit");
}

#[test]
fn fast_and_exact_animation_agree_at_rest_and_stay_close_when_posed() {
    let e = engine();
    let n = names(e);
    let mut r = Recipe::unedited(&n[0]);
    all_groups(&mut r, &n[0], &[(&n[1], 0.3), (&n[2], 0.7)]);
    let c = e.compose(&resolve(e, &r));
    let (mut fast, mut exact) = (PosedMesh::default(), PosedMesh::default());
    e.pose_with(&c, &[], &Pose::REST, AnimationMode::Fast, &mut fast);
    e.pose_with(&c, &[], &Pose::REST, AnimationMode::Exact, &mut exact);
    assert!(max_distance(&fast.vertices, &exact.vertices) < 1e-5);
    let mut pose = Pose::REST;
    pose.joints[Joint::Jaw as usize] = Vec3::new(0.2, 0.0, 0.0);
    pose.joints[Joint::Neck as usize] = Vec3::new(0.1, 0.4, 0.0);
    let expression = vec![0.5; e.database().model.expression_basis.len()];
    e.pose_with(&c, &expression, &pose, AnimationMode::Fast, &mut fast);
    e.pose_with(&c, &expression, &pose, AnimationMode::Exact, &mut exact);
    let d = max_distance(&fast.vertices, &exact.vertices);
    assert!(d > 0.0 && d < 0.005, "fast vs exact differ by {d} m");
    assert!(exact.residual <= 1e-10);
}

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
    let mut affine = best.clone();
    affine.post.deform = Deform::Affine;
    let plain = resolve(e, &Recipe::unedited(&n[0]));
    for (before, after) in [
        (&plain, &best),
        (&plain, &affine),
        (&best, &affine),
        (&affine, &best),
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
    // Lips are no skin: the source's lip Gaussians keep their opacity.
    let lips = block(&after, Region::Lips, other).unwrap();
    let full = (lips.start..lips.end)
        .filter(|&i| {
            let from = source_gaussians
                .opacity_logit
                .iter()
                .zip(&source_gaussians.position)
                .any(|(&o, &p)| {
                    o == after.gaussians.opacity_logit[i] && p == after.gaussians.position[i]
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

/// Moves Gaussian `i` of `set` so its centre sits at `world` on the mesh
/// `vertices` (keeping its parent triangle): a trained child that drifted.
fn drift_to(
    set: &mut visage::avatar::gaussians::GaussianSet,
    i: usize,
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    world: Vec3,
) {
    let frames = visage::avatar::binding::triangle_frames(vertices, triangles);
    let f = frames[set.binding[i] as usize];
    set.position[i] = f.rotation.transpose() * (world - f.center) / f.scale;
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
    let moved = (0..set.len())
        .filter(|&i| placed[i] != set.binding[i])
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
