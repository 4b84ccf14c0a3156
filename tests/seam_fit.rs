//! The seam fit (method §7.12): a composite's Gaussians beside a change of
//! source fitted, colour and opacity only, to what the sources themselves
//! draw there; every other Gaussian and every Gaussian's place untouched.

use std::sync::OnceLock;

use visage::avatar::gaussians::GaussianSet;
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::engine::{Composite, Engine};
use visage::compose::recipe::{PostProcess, Recipe};
use visage::model::builtin::build_head;
use visage::train::seam_fit::{fit_seams, SeamFit};

fn engine() -> &'static Engine {
    static ENGINE: OnceLock<Engine> = OnceLock::new();
    ENGINE.get_or_init(|| {
        let db = builtin_database(
            build_head(),
            SyntheticOptions {
                seed: 11,
                sources: 3,
                gaussians_per_avatar: 4_000,
            },
        )
        .unwrap();
        Engine::new(db).unwrap()
    })
}

/// A small, quick rig: enough views to see both sides of the face.
const QUICK: SeamFit = SeamFit {
    iterations: 40,
    size: 48,
    cameras: 4,
};

fn composite(groups: &[(&str, usize)]) -> Composite {
    let e = engine();
    let name = |s: usize| e.database().sources[s].name.clone();
    let mut text = format!("base = \"{}\"\n", name(0));
    for (group, source) in groups {
        let source = name(*source);
        text +=
            &format!("[groups.{group}]\ngaussians = \"{source}\"\nshape = {{ {source} = 1.0 }}\n");
    }
    let mut recipe = Recipe::from_toml(&text).unwrap();
    recipe.post = PostProcess::BEST;
    e.compose(&recipe.resolve(e.database()).unwrap())
}

/// Indices whose parameters differ between two sets of the same Gaussians.
fn changed(a: &GaussianSet, b: &GaussianSet) -> Vec<usize> {
    let stride = a.sh_stride();
    (0..a.len())
        .filter(|&i| {
            a.opacity_logit[i].to_bits() != b.opacity_logit[i].to_bits()
                || a.sh[i * stride..(i + 1) * stride]
                    .iter()
                    .zip(&b.sh[i * stride..(i + 1) * stride])
                    .any(|(x, y)| x.to_bits() != y.to_bits())
        })
        .collect()
}

fn same_places(a: &GaussianSet, b: &GaussianSet) -> bool {
    a.binding == b.binding
        && a.position == b.position
        && a.rotation == b.rotation
        && a.log_scale == b.log_scale
}

#[test]
fn a_fit_draws_the_seams_closer_to_the_sources_and_moves_nothing_else() {
    let c = composite(&[("face", 1), ("hair", 2)]);
    let (fitted, report) = fit_seams(engine(), &c, &QUICK, &mut |_| {}).unwrap();
    assert!(
        report.fitted > 0 && report.fitted < c.gaussians.len() / 2,
        "{report:?}"
    );
    assert_eq!(report.views, 2 * QUICK.cameras, "two poses per camera");
    // The blended renders of the sources are what the fit aims at.
    assert!(
        report.mse_after < 0.7 * report.mse_before,
        "no closer to the sources' own seams: {report:?}"
    );
    assert!(same_places(&c.gaussians, &fitted), "a fit moved a Gaussian");
    let moved = changed(&c.gaussians, &fitted);
    assert!(
        !moved.is_empty() && moved.len() <= report.fitted,
        "{} moved",
        moved.len()
    );
    assert!(fitted.sh.iter().all(|x| x.is_finite()));
    assert!(fitted.opacity_logit.iter().all(|x| x.is_finite()));
}

#[test]
fn one_source_and_zero_steps_leave_the_composite_as_it_is() {
    let unedited = composite(&[]);
    let (same, report) = fit_seams(engine(), &unedited, &QUICK, &mut |_| {}).unwrap();
    assert_eq!(report.fitted, 0);
    assert!(changed(&unedited.gaussians, &same).is_empty());
    let edited = composite(&[("nose", 1)]);
    let none = SeamFit {
        iterations: 0,
        ..QUICK
    };
    let (same, _) = fit_seams(engine(), &edited, &none, &mut |_| {}).unwrap();
    assert!(changed(&edited.gaussians, &same).is_empty());
}

/// Gaussians holding a NaN or an infinity (a file nobody cleaned) are
/// neither drawn nor fitted: they leave as they came, and every other
/// Gaussian stays finite.
#[test]
fn non_finite_gaussians_are_kept_as_they_came_and_spread_nothing() {
    let mut c = composite(&[("face", 1)]);
    let (clean, _) = fit_seams(engine(), &c, &QUICK, &mut |_| {}).unwrap();
    let moved = changed(&c.gaussians, &clean);
    let stride = c.gaussians.sh_stride();
    let bad = [moved[0], moved[moved.len() / 2], moved[moved.len() - 1]];
    c.gaussians.position[bad[0]].x = f32::NAN;
    c.gaussians.log_scale[bad[1]] = glam::Vec3::splat(f32::INFINITY);
    c.gaussians.sh[bad[2] * stride] = f32::NAN;
    let (fitted, report) = fit_seams(engine(), &c, &QUICK, &mut |_| {}).unwrap();
    assert!(report.mse_after.is_finite(), "{report:?}");
    assert!(report.mse_after < report.mse_before, "{report:?}");
    let finite = |i: usize| {
        fitted.sh[i * stride..(i + 1) * stride]
            .iter()
            .all(|x| x.is_finite())
            && fitted.opacity_logit[i].is_finite()
    };
    assert!((0..fitted.len()).filter(|i| !bad.contains(i)).all(finite));
    for &i in &bad {
        assert_eq!(
            fitted.opacity_logit[i], c.gaussians.opacity_logit[i],
            "kept as it came"
        );
    }
}
