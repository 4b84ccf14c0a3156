//! `visage compose`, `visage export` and `visage bench engine` as a user runs them.

mod common;
use common::visage;

const SMALL: [&str; 2] = ["--gaussians-per-avatar", "11000"];

fn compose_json(recipe: &str) -> serde_json::Value {
    compose_json_with(recipe, &[])
}

fn compose_json_with(recipe: &str, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["compose", "--recipe", recipe, "--json"];
    args.extend(extra);
    args.extend(SMALL);
    let out = visage(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn compose_reports_the_composite_and_a_stable_state_hash() {
    let a = compose_json("recipes/three-sources.toml");
    let b = compose_json("recipes/three-sources.toml");
    assert_eq!(a["state_hash"], b["state_hash"], "identical across runs");
    assert_eq!(a["regions"], b["regions"]);
    assert_eq!(a["regions"].as_array().unwrap().len(), 18);
    let nose = a["regions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["region"] == "nose")
        .unwrap();
    assert_eq!(nose["source"], "bram");
    assert!(
        a["extra_gaussians"].as_u64().unwrap() > 0,
        "crossfade adds Gaussians"
    );
    assert!(a["solve_residual"].as_f64().unwrap() <= 1e-10);
    assert_eq!(a["frame"]["finite"], true);
    let eyes = a["regions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["region"] == "left_eye_region")
        .unwrap();
    assert_ne!(
        eyes["colour_gain"][0], 1.0,
        "skin correction applied to jomo's eye region"
    );
}

/// `visage export --format ply` of the three-sources recipe with `extra`
/// arguments: the scene written and what it said on stderr.
fn export_ply(extra: &[&str]) -> (visage::scene::splats::SplatScene, String) {
    let path = std::env::temp_dir().join(format!(
        "visage-export-{}-{}.ply",
        extra.join("").replace('-', ""),
        std::process::id()
    ));
    let mut args = vec![
        "export",
        "--recipe",
        "recipes/three-sources.toml",
        "--format",
        "ply",
        "-o",
        path.to_str().unwrap(),
    ];
    args.extend(extra);
    args.extend(SMALL);
    let out = visage(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let scene = visage::io::ply::read_splat_ply(&path).unwrap();
    std::fs::remove_file(&path).ok();
    (scene, String::from_utf8_lossy(&out.stderr).into_owned())
}

#[test]
fn export_ply_writes_every_gaussian_of_the_frame() {
    let (scene, _) = export_ply(&["--frame", "12"]);
    let report = compose_json("recipes/three-sources.toml");
    assert_eq!(scene.len() as u64, report["gaussians"].as_u64().unwrap());
    assert_eq!(scene.sh_degree, 3);
    assert!(scene
        .position
        .iter()
        .all(|p| p.is_finite() && p.length() < 1.0));
}

/// `export --seam-fit` writes the same Gaussians in the same places with
/// the seams' colours, opacities and (a little) scales fitted (method
/// §7.12).
#[test]
fn export_with_a_seam_fit_changes_only_colours_opacities_and_scales() {
    let (plain, _) = export_ply(&[]);
    let (fitted, said) = export_ply(&[
        "--seam-fit",
        "20",
        "--seam-fit-size",
        "64",
        "--no-seam-fit-cache",
    ]);
    assert!(
        said.contains("fitted") && said.contains("Gaussians (at seams"),
        "{said}"
    );
    assert_eq!(plain.len(), fitted.len());
    assert_eq!(plain.position, fitted.position);
    // Scales may move a little (the fit's reach), never far.
    assert!(plain.scale.iter().zip(&fitted.scale).all(|(a, b)| a
        .to_array()
        .iter()
        .zip(b.to_array())
        .all(|(x, y)| (x.ln() - y.ln()).abs() < 1.0)));
    assert_eq!(plain.rotation, fitted.rotation);
    let stride = plain.sh.len() / plain.len();
    let recoloured = (0..plain.len())
        .filter(|&i| {
            plain.sh[i * stride..(i + 1) * stride] != fitted.sh[i * stride..(i + 1) * stride]
        })
        .count();
    assert!(
        recoloured > 0 && recoloured < plain.len() / 4,
        "{recoloured} of {} recoloured: the seams only",
        plain.len()
    );
    assert!(fitted
        .sh
        .iter()
        .chain(&fitted.opacity)
        .all(|x| x.is_finite()));
}

/// `compose` with a short seam fit (32 px views unless `extra` names a
/// size) and a cache folder of its own: the JSON report, and what it said
/// on standard error.
fn compose_cached(cache: &std::path::Path, extra: &[&str]) -> (serde_json::Value, String) {
    let mut args = vec![
        "compose",
        "--recipe",
        "recipes/three-sources.toml",
        "--json",
        "--seam-fit",
        "5",
    ];
    if !extra.contains(&"--seam-fit-size") {
        args.extend(["--seam-fit-size", "32"]);
    }
    args.extend(extra);
    args.extend(SMALL);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .env("VISAGE_CACHE_DIR", cache)
        .args(&args)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{said}");
    (serde_json::from_slice(&out.stdout).unwrap(), said)
}

fn stored_fits(cache: &std::path::Path) -> usize {
    std::fs::read_dir(cache.join("fits")).map_or(0, |d| {
        d.filter(|e| {
            e.as_ref()
                .is_ok_and(|e| e.file_name().to_string_lossy().ends_with(".fit"))
        })
        .count()
    })
}

/// A finished seam fit is kept in fits/ of the user's cache folder, and
/// the next run on the same composite reads it back instead of fitting: the
/// same composite, and it says so. `--no-seam-fit-cache` fits and keeps
/// nothing; a cache that cannot be written costs a warning, not the run.
#[test]
fn a_finished_seam_fit_is_kept_and_read_back_the_next_time() {
    let cache = std::env::temp_dir().join(format!("visage-fit-cache-{}", std::process::id()));
    std::fs::remove_dir_all(&cache).ok();
    let (first, said) = compose_cached(&cache, &[]);
    assert_eq!(first["seam_fit"]["stored"], false, "{said}");
    assert!(said.contains("fitted"), "{said}");
    assert_eq!(stored_fits(&cache), 1);
    let (again, said) = compose_cached(&cache, &[]);
    assert_eq!(again["seam_fit"]["stored"], true, "{said}");
    assert!(said.contains("read the stored seam fit"), "{said}");
    assert_eq!(again["composite_hash"], first["composite_hash"]);
    assert_eq!(again["seam_fit"]["fitted"], first["seam_fit"]["fitted"]);
    // Other fit options are another fit.
    let (bigger, _) = compose_cached(&cache, &["--seam-fit-size", "40"]);
    assert_eq!(bigger["seam_fit"]["stored"], false);
    assert_eq!(stored_fits(&cache), 2);
    // Not read, not kept.
    let elsewhere = cache.join("elsewhere");
    let (fresh, _) = compose_cached(&elsewhere, &["--no-seam-fit-cache"]);
    assert_eq!(fresh["seam_fit"]["stored"], false);
    assert_eq!(fresh["composite_hash"], first["composite_hash"]);
    assert_eq!(stored_fits(&elsewhere), 0);
    // A cache folder that is a file: the composite still comes, with a warning.
    let blocked = cache.join("blocked");
    std::fs::write(&blocked, b"not a folder").unwrap();
    let (despite, said) = compose_cached(&blocked, &[]);
    assert_eq!(despite["composite_hash"], first["composite_hash"]);
    assert!(
        said.contains("warning: the seam fit was not kept"),
        "{said}"
    );
    std::fs::remove_dir_all(&cache).ok();
}

/// A recipe's `[post] fit = "seams"` runs in `compose` (and `export`,
/// `render`) before the composite is described or written; `--seam-fit 0`
/// turns it off and gives back the unfitted composite exactly.
#[test]
fn a_recipes_seam_fit_runs_unless_turned_off() {
    let text = std::fs::read_to_string("recipes/three-sources.toml")
        .unwrap()
        .replace(
            "colour = \"skin\"\n",
            "colour = \"skin\"\nfit = \"seams\"\n",
        );
    let recipe = std::env::temp_dir().join(format!("visage-fit-{}.toml", std::process::id()));
    std::fs::write(&recipe, text).unwrap();
    let path = recipe.to_str().unwrap();
    let compose = |extra: &[&str]| compose_json_with(path, extra);
    let plain = compose_json("recipes/three-sources.toml");
    assert_eq!(plain["fit"], "off");
    assert!(plain["seam_fit"].is_null());
    // Fitted here and now, never read from the tests' shared cache.
    let fitted = compose(&[
        "--seam-fit",
        "5",
        "--seam-fit-size",
        "32",
        "--no-seam-fit-cache",
    ]);
    assert_eq!(fitted["fit"], "seams");
    assert_eq!(fitted["seam_fit"]["stored"], false);
    assert!(
        fitted["seam_fit"]["fitted"].as_u64().unwrap() > 0,
        "{}",
        fitted["seam_fit"]
    );
    assert_ne!(fitted["composite_hash"], plain["composite_hash"]);
    // On the CPU unless asked: the same composite on every machine.
    assert_eq!(fitted["seam_fit"]["renderer"], "cpu");
    let on_gpu = compose(&[
        "--seam-fit",
        "5",
        "--seam-fit-size",
        "32",
        "--seam-fit-renderer",
        "gpu",
        "--no-seam-fit-cache",
    ]);
    assert_eq!(on_gpu["seam_fit"]["renderer"], "gpu");
    assert_eq!(on_gpu["seam_fit"]["fitted"], fitted["seam_fit"]["fitted"]);
    let off = compose(&["--seam-fit", "0"]);
    assert_eq!(off["fit"], "off");
    assert_eq!(off["composite_hash"], plain["composite_hash"]);
    std::fs::remove_file(&recipe).ok();
}

#[test]
fn bad_recipes_fail_with_one_line_and_exit_2() {
    let dir = std::env::temp_dir().join(format!("visage-bad-recipes-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        ("unknown-source.toml", "base = \"zed\"\n", "unknown source"),
        (
            "bad-weight.toml",
            "base = \"ada\"\n[groups.nose]\ngaussians = \"ada\"\nshape = { ada = -1.0 }\n",
            "≥ 0",
        ),
        (
            "zero.toml",
            "base = \"ada\"\n[groups.nose]\ngaussians = \"ada\"\nshape = { ada = 0.0 }\n",
            "all zero",
        ),
        (
            "typo.toml",
            "base = \"ada\"\n[post]\nsmothing = \"thesis\"\n",
            "smothing",
        ),
    ];
    for (file, text, needle) in cases {
        let path = dir.join(file);
        std::fs::write(&path, text).unwrap();
        let out = visage(&[
            "compose",
            "--recipe",
            path.to_str().unwrap(),
            "--gaussians-per-avatar",
            "11000",
        ]);
        assert_eq!(out.status.code(), Some(2), "{file}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{file}: {err}");
        assert!(err.contains(needle), "{file}: {err}");
    }
    let out = visage(&["compose", "--recipe", "/no/such/recipe.toml"]);
    assert_eq!(out.status.code(), Some(2));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bench_engine_json_rows_carry_speed_and_error() {
    let mut args = vec![
        "bench",
        "engine",
        "--sources",
        "2,3",
        "--iterations",
        "4",
        "--warmup",
        "1",
        "--json",
    ];
    args.extend(SMALL);
    let out = visage(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = v["rows"].as_array().unwrap();
    for action in ["animate", "shape", "assign", "solve", "factor"] {
        assert!(rows.iter().any(|r| r["action"] == action), "{action}");
    }
    for r in rows {
        assert!(
            r["ms_median"].as_f64().unwrap() >= 0.0
                && r["ms_p90"].as_f64().unwrap() >= r["ms_median"].as_f64().unwrap()
        );
        assert!(r["sources"].as_u64().is_some());
    }
    let fast = rows
        .iter()
        .find(|r| r["action"] == "animate" && r["mode"] == "fast")
        .unwrap();
    let err = fast["max_vertex_error_m"].as_f64().unwrap();
    assert!(err > 0.0 && err < 0.005, "fast vs exact {err}");
    let exact = rows
        .iter()
        .find(|r| r["action"] == "animate" && r["mode"] == "exact")
        .unwrap();
    assert!(exact["max_residual"].as_f64().unwrap() <= 1e-10);
    // The solve row times a real blend (all sources mixed), not the one-hot short
    // cut, whose residual would be exactly 0.
    let solve = rows.iter().find(|r| r["action"] == "solve").unwrap();
    let residual = solve["max_residual"].as_f64().unwrap();
    assert!(
        residual > 0.0 && residual <= 1e-10,
        "solve residual {residual}"
    );
}
