//! `visage info` as a user runs it.

mod common;
use common::visage;

#[test]
fn info_json_describes_model_sources_and_motions() {
    let out = visage(&["info", "--json", "--gaussians-per-avatar", "40000"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON document");
    let model = &v["model"];
    let regions = model["regions"].as_array().unwrap();
    assert_eq!(regions.len(), 18);
    let groups: std::collections::HashSet<_> = regions
        .iter()
        .map(|r| r["group"].as_str().unwrap())
        .collect();
    assert_eq!(groups.len(), 7);
    let covered: u64 = regions
        .iter()
        .map(|r| r["triangles"].as_u64().unwrap())
        .sum();
    assert_eq!(
        covered,
        model["triangles"].as_u64().unwrap(),
        "regions cover every triangle once"
    );
    assert!(model["components"].as_u64().unwrap() >= 5);
    let sources = v["sources"].as_array().unwrap();
    assert_eq!(sources.len(), 14);
    for s in sources {
        assert!(s["gaussians"].as_u64().unwrap() >= 40_000);
        assert_eq!(s["sh_degree"], 3);
        assert!(!s["name"].as_str().unwrap().is_empty());
    }
    for m in v["motions"].as_array().unwrap() {
        assert!(m["frames"].as_u64().unwrap() >= 110);
    }
}

#[test]
fn export_obj_writes_one_coloured_mesh_per_source() {
    let dir = std::env::temp_dir().join(format!("visage-obj-{}", std::process::id()));
    let out = visage(&[
        "info",
        "--source-count",
        "2",
        "--gaussians-per-avatar",
        "11000",
        "--export-obj",
        dir.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("ada.obj")).unwrap();
    let vertices = text.lines().filter(|l| l.starts_with("v ")).count();
    let faces = text.lines().filter(|l| l.starts_with("f ")).count();
    assert!(vertices > 4000 && faces > 9000);
    let first_v = text.lines().find(|l| l.starts_with("v ")).unwrap();
    assert_eq!(first_v.split_whitespace().count(), 7, "position and colour");
    assert!(dir.join("bram.obj").exists());
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn bad_input_is_one_line_and_exit_code_2() {
    for args in [
        &["info", "--bogus"][..],
        &["info", "--source-count", "99"][..],
        &["info", "--gaussians-per-avatar", "0"][..],
        &["info", "--db", "/no/such/folder"][..],
        &["info", "--seed", "minus-one"][..],
    ] {
        let out = visage(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.starts_with("visage: "), "{err}");
    }
}
