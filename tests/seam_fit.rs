//! The seam fit (method §7.12): a composite's Gaussians near a change of
//! source — and, where the recipe relights, those whose light the shape
//! moved — fitted in colour, opacity and a little of their scale to what the
//! sources themselves draw there; every Gaussian's place untouched.

use std::sync::OnceLock;

use visage::avatar::gaussians::GaussianSet;
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::engine::{Composite, Engine};
use visage::compose::recipe::{Fit, PostProcess, Recipe};
use visage::model::builtin::build_head;
use visage::pipeline::composer::Composer;
use visage::render::Backend;
use visage::train::fit_store::{FitKey, FitStore};
use visage::train::seam_fit::{fit_seams, SeamFit};

fn new_engine() -> Engine {
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
}

fn engine() -> &'static Engine {
    static ENGINE: OnceLock<Engine> = OnceLock::new();
    ENGINE.get_or_init(new_engine)
}

/// A small, quick rig: enough views to see both sides of the face.
const QUICK: SeamFit = SeamFit {
    iterations: 40,
    size: 48,
    cameras: 4,
    renderer: Backend::Cpu,
};

fn recipe(groups: &[(&str, usize)]) -> Recipe {
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
    recipe
}

fn composite(groups: &[(&str, usize)]) -> Composite {
    let e = engine();
    e.compose(&recipe(groups).resolve(e.database()).unwrap())
}

/// Indices whose parameters differ between two sets of the same Gaussians.
fn changed(a: &GaussianSet, b: &GaussianSet) -> Vec<usize> {
    assert_eq!(a.len(), b.len(), "not the same Gaussians");
    let stride = a.sh_stride();
    (0..a.len())
        .filter(|&i| {
            a.opacity_logit[i].to_bits() != b.opacity_logit[i].to_bits()
                || a.log_scale[i] != b.log_scale[i]
                || a.sh[i * stride..(i + 1) * stride]
                    .iter()
                    .zip(&b.sh[i * stride..(i + 1) * stride])
                    .any(|(x, y)| x.to_bits() != y.to_bits())
        })
        .collect()
}

fn same_places(a: &GaussianSet, b: &GaussianSet) -> bool {
    a.binding == b.binding && a.position == b.position && a.rotation == b.rotation
}

#[test]
fn a_fit_draws_the_seams_closer_to_the_sources_and_moves_nothing_else() {
    let c = composite(&[("face", 1), ("hair", 2)]);
    let (fitted, report) = fit_seams(engine(), &c, &QUICK, &mut |_, _| {}).unwrap();
    assert!(report.fitted > 0, "{report:?}");
    assert_eq!(report.views, 2 * QUICK.cameras, "two poses per camera");
    // The blended renders of the sources are what the fit aims at.
    assert!(
        report.mse_after < 0.7 * report.mse_before,
        "no closer to the sources' own seams: {report:?}"
    );
    assert!(same_places(&c.gaussians, &fitted), "a fit moved a Gaussian");
    // Scales move by at most Adam's step a step: the reach changes, a little.
    let largest = (0..fitted.len())
        .map(|i| {
            (fitted.log_scale[i] - c.gaussians.log_scale[i])
                .abs()
                .max_element()
        })
        .fold(0.0f32, f32::max);
    assert!(
        largest > 0.0 && largest <= 1.1 * 0.015 * QUICK.iterations as f32,
        "log scales moved by up to {largest}"
    );
    let moved = changed(&c.gaussians, &fitted);
    assert!(
        !moved.is_empty() && moved.len() <= report.fitted,
        "{} moved",
        moved.len()
    );
    // Opacity and reach move too, not the colour alone: near a seam, and
    // where the new face and hair shapes move the light (method §7.12).
    let reshaped = (0..fitted.len())
        .filter(|&i| {
            fitted.opacity_logit[i].to_bits() != c.gaussians.opacity_logit[i].to_bits()
                || fitted.log_scale[i] != c.gaussians.log_scale[i]
        })
        .count();
    assert!(reshaped > 0, "nothing reshaped, {} moved", moved.len());
    // The rest of the head keeps its bits.
    assert!(
        moved.len() < c.gaussians.len(),
        "all {} Gaussians moved",
        moved.len()
    );
    assert!(fitted.sh.iter().all(|x| x.is_finite()));
    assert!(fitted.opacity_logit.iter().all(|x| x.is_finite()));
}

#[test]
fn a_fit_drawn_on_a_gpu_lands_where_the_cpus_does() {
    let c = composite(&[("face", 1), ("hair", 2)]);
    let (on_cpu, cpu) = fit_seams(engine(), &c, &QUICK, &mut |_, _| {}).unwrap();
    let gpu_fit = SeamFit {
        renderer: Backend::Gpu,
        ..QUICK
    };
    let (on_gpu, gpu) =
        fit_seams(engine(), &c, &gpu_fit, &mut |_, _| {}).expect("a wgpu adapter (lavapipe in CI)");
    assert!(gpu.on_gpu && !cpu.on_gpu, "{gpu:?} {cpu:?}");
    assert_eq!((gpu.fitted, gpu.views), (cpu.fitted, cpu.views));
    // f32 against f64: the same targets and the same fit, to rounding.
    let close = |a: f64, b: f64| (a - b).abs() <= 0.02 * b;
    assert!(
        close(gpu.mse_before, cpu.mse_before) && close(gpu.mse_after, cpu.mse_after),
        "gpu {gpu:?} against cpu {cpu:?}"
    );
    assert!(same_places(&on_cpu, &on_gpu), "a fit moved a Gaussian");
    let dc = |set: &GaussianSet| -> Vec<f32> {
        let stride = set.sh_stride();
        (0..set.len())
            .flat_map(|i| set.sh[i * stride..i * stride + 3].to_vec())
            .collect()
    };
    let mean_gap = dc(&on_cpu)
        .iter()
        .zip(dc(&on_gpu))
        .map(|(a, b)| (a - b).abs())
        .sum::<f32>()
        / (3 * cpu.fitted) as f32;
    assert!(
        mean_gap < 0.01,
        "DC colours differ by {mean_gap} on average"
    );
}

#[test]
fn one_source_and_zero_steps_leave_the_composite_as_it_is() {
    let unedited = composite(&[]);
    let (same, report) = fit_seams(engine(), &unedited, &QUICK, &mut |_, _| {}).unwrap();
    assert_eq!(report.fitted, 0);
    assert!(changed(&unedited.gaussians, &same).is_empty());
    let edited = composite(&[("nose", 1)]);
    let none = SeamFit {
        iterations: 0,
        ..QUICK
    };
    let (same, _) = fit_seams(engine(), &edited, &none, &mut |_, _| {}).unwrap();
    assert!(changed(&edited.gaussians, &same).is_empty());
}

/// Gaussians holding a NaN or an infinity (a file nobody cleaned) are
/// neither drawn nor fitted: they leave as they came, and every other
/// Gaussian stays finite.
#[test]
fn non_finite_gaussians_are_kept_as_they_came_and_spread_nothing() {
    let mut c = composite(&[("face", 1)]);
    let (clean, _) = fit_seams(engine(), &c, &QUICK, &mut |_, _| {}).unwrap();
    let moved = changed(&c.gaussians, &clean);
    let stride = c.gaussians.sh_stride();
    let bad = [moved[0], moved[moved.len() / 2], moved[moved.len() - 1]];
    c.gaussians.position[bad[0]].x = f32::NAN;
    c.gaussians.log_scale[bad[1]] = glam::Vec3::splat(f32::INFINITY);
    c.gaussians.sh[bad[2] * stride] = f32::NAN;
    let (fitted, report) = fit_seams(engine(), &c, &QUICK, &mut |_, _| {}).unwrap();
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

/// What the editor, `export` and a study see of a recipe's `[post] fit`:
/// the composer shows the composite as composed until the fit is run, then
/// the same fitted Gaussians as `fit_seams` makes; a new frame keeps the
/// fit, a new selection redoes it, and `fit = "off"` gives back the
/// composed Gaussians bit for bit.
#[test]
fn a_composer_runs_the_recipes_fit_keeps_it_and_gives_it_back() {
    let mut composer = Composer::new(new_engine());
    composer.set_fit_options(QUICK);
    let mut r = recipe(&[("face", 1), ("hair", 2)]);
    assert_eq!(r.post.fit, Fit::Seams, "the best post-processing fits");
    composer.update(&r).unwrap();
    let composed = composer.composite().gaussians.clone();
    let pending = composer.fit_progress().expect("a fit is pending");
    assert_eq!(pending.done, 0);
    // A pending fit keeps its progress over a new frame or camera (the
    // editor draws frames between its units).
    for _ in 0..3 {
        composer.fit_step().unwrap();
    }
    let mut turned = r.clone();
    turned.camera.yaw_deg = 30.0;
    composer.update(&turned).unwrap();
    assert_eq!(composer.fit_progress().map(|p| p.done), Some(3));
    let generation = composer.generation();
    let mut heard = Vec::new();
    let report = composer
        .finish_fit(&mut |p| heard.push((p.done, p.total)))
        .unwrap()
        .expect("the fit ran");
    assert!(report.fitted > 0 && report.mse_after < report.mse_before);
    let total = heard[heard.len() - 1].1;
    assert!(heard
        .iter()
        .enumerate()
        .all(|(k, &(d, t))| d == k + 4 && t == total));
    assert_eq!(composer.fit_progress(), None);
    assert_ne!(composer.generation(), generation, "drawers re-upload");
    let fitted = composer.composite().gaussians.clone();
    let (expected, _) = fit_seams(
        engine(),
        &composite(&[("face", 1), ("hair", 2)]),
        &QUICK,
        &mut |_, _| {},
    )
    .unwrap();
    assert!(
        changed(&expected, &fitted).is_empty(),
        "the same fit as fit_seams"
    );
    assert!(!changed(&composed, &fitted).is_empty());

    // Another frame: the fit stays, nothing to redo.
    r.animation.motion = "talk".into();
    r.animation.frame = 3;
    let generation = composer.generation();
    composer.update(&r).unwrap();
    assert_eq!(composer.fit_progress(), None);
    assert_eq!(composer.generation(), generation);
    assert!(changed(&fitted, &composer.composite().gaussians).is_empty());

    // Other fit options: the composed Gaussians are shown (drawers
    // re-upload) until the fit is done again under them.
    let generation = composer.generation();
    composer.set_fit_options(SeamFit {
        iterations: 5,
        ..QUICK
    });
    assert_ne!(composer.generation(), generation);
    assert!(changed(&composed, &composer.composite().gaussians).is_empty());
    assert!(composer.fit_progress().is_some());
    composer.set_fit_options(QUICK);
    composer.finish_fit(&mut |_| {}).unwrap();
    assert!(changed(&fitted, &composer.composite().gaussians).is_empty());

    // Fit off: the composed Gaussians, bit for bit; on again: fitted again.
    r.post.fit = Fit::Off;
    composer.update(&r).unwrap();
    assert!(changed(&composed, &composer.composite().gaussians).is_empty());
    assert_eq!(composer.fit_progress(), None);
    r.post.fit = Fit::Seams;
    composer.update(&r).unwrap();
    assert!(composer.fit_progress().is_some());
    composer.finish_fit(&mut |_| {}).unwrap();
    assert!(changed(&fitted, &composer.composite().gaussians).is_empty());

    // Another source for a group: the engine updates the composed
    // Gaussians (not the fitted ones), and the fit is pending again.
    let name = engine().database().sources[2].name.clone();
    r.groups.get_mut("face").unwrap().gaussians = name;
    composer.update(&r).unwrap();
    assert!(composer.fit_progress().is_some());
    let recomposed = composer.composite().gaussians.clone();
    let e = engine();
    let direct = e.compose(&r.resolve(e.database()).unwrap());
    assert!(changed(&direct.gaussians, &recomposed).is_empty());
}

/// The `.fit` files in a folder.
fn stored_fits(dir: &std::path::Path) -> Vec<std::path::PathBuf> {
    std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "fit"))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn a_stored_fit_is_shown_at_once_and_only_for_what_it_was_made_for() {
    let dir = std::env::temp_dir().join(format!("visage-fit-store-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let r = recipe(&[("face", 1), ("hair", 2)]);
    let fitted_by = |options: SeamFit| {
        let mut composer = Composer::new(new_engine());
        composer.set_fit_options(options);
        composer.set_fit_store(Some(FitStore::new(&dir)));
        composer.update(&r).unwrap();
        let mut units = 0;
        composer.finish_fit(&mut |_| units += 1).unwrap();
        (
            composer.composite().gaussians.clone(),
            composer.fit_report().unwrap(),
            units,
        )
    };
    let (first, report, units) = fitted_by(QUICK);
    assert!(units > QUICK.iterations, "fitted: {units} units");
    assert_eq!(stored_fits(&dir).len(), 1, "kept");
    // The same composite under the same options: no fitting, the same bits.
    let (again, stored_report, units) = fitted_by(QUICK);
    assert_eq!(units, 1, "looked up, not fitted");
    assert!(changed(&first, &again).is_empty());
    assert_eq!(stored_report, report);
    // Other options are another fit.
    let other = SeamFit {
        iterations: 5,
        ..QUICK
    };
    let (_, _, units) = fitted_by(other);
    assert!(units > 5, "fitted again: {units} units");
    assert_eq!(stored_fits(&dir).len(), 2);
    // A damaged file is passed over and replaced, never applied.
    for file in stored_fits(&dir) {
        let mut bytes = std::fs::read(&file).unwrap();
        let middle = bytes.len() / 2;
        bytes[middle] ^= 0x40;
        std::fs::write(&file, bytes).unwrap();
    }
    let (refitted, _, units) = fitted_by(QUICK);
    assert!(units > QUICK.iterations, "fitted again: {units} units");
    assert!(
        changed(&first, &refitted).is_empty(),
        "the same fit, made again"
    );
    let (_, _, units) = fitted_by(QUICK);
    assert_eq!(units, 1, "the replaced file holds");
    // A store that cannot be written: the fit still shows, and the error
    // waits for whoever asks (study build does; a participant's run not).
    let blocked = dir.join("a-file");
    std::fs::write(&blocked, b"not a folder").unwrap();
    let mut composer = Composer::new(new_engine());
    composer.set_fit_options(QUICK);
    composer.set_fit_store(Some(FitStore::new(blocked.join("fits"))));
    composer.update(&r).unwrap();
    composer.finish_fit(&mut |_| {}).unwrap();
    assert!(composer.fit_report().is_some_and(|f| f.fitted > 0));
    let error = composer.take_store_error().expect("the save failed");
    assert!(
        error.to_string().contains("cannot store the seam fit"),
        "{error}"
    );
    assert!(composer.take_store_error().is_none(), "told once");
    // A composite with nothing on a seam leaves nothing behind.
    std::fs::remove_dir_all(&dir).ok();
    let mut composer = Composer::new(new_engine());
    composer.set_fit_options(QUICK);
    composer.set_fit_store(Some(FitStore::new(&dir)));
    composer.update(&recipe(&[])).unwrap();
    composer.finish_fit(&mut |_| {}).unwrap();
    assert!(stored_fits(&dir).is_empty());
}

#[test]
fn a_fits_key_names_its_recipe_options_and_sources() {
    let e = engine();
    let c = composite(&[("face", 1), ("hair", 2)]);
    let key = FitKey::of(e, &c, &QUICK);
    assert_eq!(
        key,
        FitKey::of(e, &composite(&[("face", 1), ("hair", 2)]), &QUICK)
    );
    assert_ne!(key, FitKey::of(e, &composite(&[("face", 1)]), &QUICK));
    let on_gpu = SeamFit {
        renderer: Backend::Gpu,
        ..QUICK
    };
    assert_ne!(key, FitKey::of(e, &c, &on_gpu));
    // A source retrained (one colour changed) is another fit.
    let mut db = e.database().clone();
    db.sources[2].gaussians.sh[0] += 0.25;
    let retrained = Engine::new(db).unwrap();
    assert_ne!(key, FitKey::of(&retrained, &c, &QUICK));
}
