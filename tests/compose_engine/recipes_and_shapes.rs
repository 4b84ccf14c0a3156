//! Recipes (validation, strict files) and shape blending: one source's mesh,
//! even blends, weights at 0, 1 and tiny, a blend that stays local, and the
//! fast animation against the exact one.

use super::*;

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
