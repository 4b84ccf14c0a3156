//! Hole filling end to end: `visage train --obscuring --cull-backfaces`
//! exports an avatar bound to the full topology that loads and evaluates,
//! `visage eval --holes` reports leak and coverage, a checkpoint refuses a
//! resume with other culling, and `visage bench holes` compares the four
//! variants and draws their grid.

mod common;

use std::path::PathBuf;

use common::{temp_path, visage};

/// A small front-arc capture: 48×48, 6 cameras, 2 timesteps.
fn small_capture(name: &str) -> PathBuf {
    common::small_capture("holes", name, 48, 6, 2)
}

/// A culled, obscured run exports bindings on the full topology (none on a
/// culled triangle), records its settings, loads and evaluates with hole
/// metrics; resuming its checkpoint with other culling is refused.
#[test]
fn culled_training_maps_bindings_back_and_evaluates_with_hole_metrics() {
    use visage::train::dataset::Dataset;
    use visage::train::holes::{view_ratios, TriangleSubset};
    let dir = small_capture("cull");
    let avatar = temp_path("holes", "cull-avatar");
    std::fs::remove_dir_all(&avatar).ok();
    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        avatar.to_str().unwrap(),
        "--iterations",
        "30",
        "--size",
        "32x32",
        "--obscuring",
        "--cull-backfaces",
        "0.3",
        "--checkpoint-every",
        "10",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(avatar.join("training.json")).unwrap())
            .unwrap();
    assert_eq!(meta["obscuring"], true);
    assert_eq!(meta["interior_layer"], false);
    assert_eq!(meta["cull_backfaces"], 0.3);
    let (trained, all) = (
        meta["triangles_trained"].as_u64().unwrap() as usize,
        meta["triangles"].as_u64().unwrap() as usize,
    );
    assert!(trained < all && trained > all / 4, "{trained} of {all}");

    // The same culling computed here: every exported binding is a kept
    // full-topology triangle, and every kept triangle has a Gaussian.
    let head = visage::model::builtin::build_head();
    let dataset = Dataset::load(&dir).unwrap();
    let posed = dataset
        .flame_params
        .iter()
        .map(|(&t, path)| {
            let p = visage::io::avatar::read_flame_params(path, "dataset", &head).unwrap();
            let (expression, pose) = p.motion.frame(0);
            (
                t,
                head.forward(&p.shape, Some(&p.static_offset), expression, pose),
            )
        })
        .collect();
    let subset =
        TriangleSubset::cull(&view_ratios(&head.triangles, &posed, &dataset.train), 0.3).unwrap();
    assert_eq!(subset.len(), trained);
    let read = visage::io::avatar::read_avatar(&avatar, "avatar", &head).unwrap();
    let kept: std::collections::BTreeSet<u32> = subset.kept.iter().copied().collect();
    assert!(read.gaussians.binding.iter().all(|b| kept.contains(b)));
    let bound: std::collections::BTreeSet<u32> = read.gaussians.binding.iter().copied().collect();
    assert_eq!(bound, kept, "every kept triangle keeps a Gaussian");
    assert!(
        read.gaussians
            .binding
            .iter()
            .any(|&b| b as usize >= trained),
        "bindings are full-topology indices, not indices into the kept list"
    );

    let o = visage(&[
        "eval",
        avatar.to_str().unwrap(),
        dir.to_str().unwrap(),
        "--holes",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let holes = &r["holes"];
    let leak = holes["leak_delta_e"].as_f64().unwrap();
    assert!(leak.is_finite() && leak >= 0.0, "{r}");
    for key in ["coverage", "coverage_beyond"] {
        let c = holes[key].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&c), "{r}");
    }
    for group in ["face", "nose", "eyes", "mouth"] {
        assert!(holes["coverage_by_group"][group].is_number(), "{r}");
    }

    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        avatar.to_str().unwrap(),
        "--resume",
        avatar.join("checkpoint.npz").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(stderr.contains("--cull-backfaces"), "{stderr}");
    assert_eq!(stderr.trim().lines().count(), 1, "{stderr}");

    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        avatar.to_str().unwrap(),
        "--cull-backfaces",
        "1.5",
    ]);
    assert_eq!(o.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::remove_dir_all(&avatar).ok();
}

/// `visage bench holes` trains the six variants with one seed and reports
/// each, and writes a grid of a row per variant and a column per turn; an
/// unknown variant is refused.
#[test]
fn bench_holes_compares_six_variants_and_draws_the_grid() {
    let grid = temp_path("holes", "grid.png");
    let o = visage(&[
        "bench",
        "holes",
        "--capture-size",
        "32x32",
        "--iterations",
        "12",
        "--cull-backfaces",
        "0.3",
        "--grid",
        grid.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = r["variants"].as_array().unwrap();
    let names: Vec<&str> = rows
        .iter()
        .map(|v| v["variant"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "plain",
            "obscuring",
            "culling",
            "both",
            "interior",
            "interior+culling"
        ]
    );
    for row in rows {
        for key in ["leak_delta_e", "coverage", "psnr_db", "train_s"] {
            assert!(row[key].as_f64().unwrap().is_finite(), "{key}: {row}");
        }
        assert!(row["gaussians"].as_u64().unwrap() > 0);
    }
    let all = rows[0]["triangles_trained"].as_u64().unwrap();
    assert!(rows[2]["triangles_trained"].as_u64().unwrap() < all);
    assert_eq!(rows[1]["triangles_trained"].as_u64().unwrap(), all);
    let image = image::open(&grid).unwrap();
    assert_eq!((image.width(), image.height()), (5 * 32, 6 * 32));
    std::fs::remove_file(&grid).ok();
    let o = visage(&["bench", "holes", "--variants", "plain,bogus"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown variant 'bogus'"));
}

/// `visage bench mouth` trains one capture on the three heads (pocket, open
/// rim, generated cavity) and scores open- and closed-mouth views; the cavity
/// head has the pocket's triangle count minus what its rim is missing.
#[test]
fn bench_mouth_trains_three_heads_and_splits_open_mouths() {
    let o = visage(&[
        "bench",
        "mouth",
        "--capture-size",
        "32x32",
        "--iterations",
        "6",
        "--renderer",
        "cpu",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let heads = r["heads"].as_array().unwrap();
    let names: Vec<&str> = heads.iter().map(|h| h["head"].as_str().unwrap()).collect();
    assert_eq!(names, ["pocket", "open", "cavity"]);
    let open_views = r["open_views"].as_u64().unwrap();
    assert!(open_views > 0 && open_views < r["held_out_views"].as_u64().unwrap());
    for h in heads {
        for key in [
            "open_psnr_db",
            "closed_psnr_db",
            "open_mouth_psnr_db",
            "closed_mouth_psnr_db",
        ] {
            assert!(h[key].as_f64().unwrap().is_finite(), "{key}: {h}");
        }
    }
    let triangles = |i: usize| heads[i]["triangles"].as_u64().unwrap();
    assert!(triangles(1) < triangles(0), "the open rim lost the pocket");
    assert!(triangles(2) > triangles(1), "the cavity closed it again");
}

/// `sessions/trained-sources.sh` trains three sources (here tiny ones) and
/// `sessions/trained-sources.vsg` composes them: every command succeeds, and
/// border smoothing with colour correction change the picture.
#[test]
fn the_trained_sources_session_composes_sources_visage_trained() {
    let db = std::path::Path::new("target").join("test-trained-sources");
    std::fs::remove_dir_all(&db).ok();
    let o = std::process::Command::new("sh")
        .args([
            "sessions/trained-sources.sh",
            db.to_str().unwrap(),
            "30",
            "48x48",
        ])
        .env("VISAGE", env!("CARGO_BIN_EXE_visage"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for source in ["ada", "bram", "jomo"] {
        assert!(
            db.join(source).join("point_cloud.ply").is_file(),
            "{source}"
        );
        assert!(!db.join(source).join("checkpoint.npz").exists());
    }
    let session: String = std::fs::read_to_string("sessions/trained-sources.vsg")
        .unwrap()
        .lines()
        .filter(|l| !l.contains("expect image"))
        .map(|l| {
            let l = l.replace("db target/trained-sources", &format!("db {}", db.display()));
            format!("{l}\n")
        })
        .collect();
    let file = temp_path("holes", "trained.vsg");
    std::fs::write(&file, session).unwrap();
    let out = temp_path("holes", "trained-out");
    std::fs::remove_dir_all(&out).ok();
    let o = visage(&[
        "replay",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--check",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(r["failures"].as_array().unwrap().is_empty(), "{r}");
    let before = image::open(out.join("trained-before.png"))
        .unwrap()
        .to_rgb8();
    let after = image::open(out.join("trained-after.png"))
        .unwrap()
        .to_rgb8();
    assert_eq!(before.dimensions(), (160, 120));
    let changed = before
        .pixels()
        .zip(after.pixels())
        .filter(|(a, b)| a.0.iter().zip(b.0).any(|(x, y)| x.abs_diff(y) > 4))
        .count();
    assert!(
        changed > 200,
        "smoothing and colour correction changed {changed} pixels"
    );
    std::fs::remove_dir_all(&db).ok();
    std::fs::remove_dir_all(&out).ok();
}
