//! `visage cache`: the cache folder's level-of-detail caches and seam fits,
//! counted and cleared, in a cache folder of the test's own.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn folder() -> PathBuf {
    let dir = common::temp_path("cache", "root");
    std::fs::remove_dir_all(&dir).ok();
    dir
}

fn visage_in(cache: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .env("VISAGE_CACHE_DIR", cache)
        .args(args)
        .output()
        .unwrap()
}

fn succeeds(out: Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn report(cache: &Path, extra: &[&str]) -> serde_json::Value {
    let args = [&["cache", "--json"][..], extra].concat();
    serde_json::from_str(&succeeds(visage_in(cache, &args))).unwrap()
}

/// A scene's level-of-detail cache and a composite's seam fit show up with
/// their sizes, and each kind clears on its own without touching the other
/// or a file that is not the cache's.
#[test]
fn the_cache_command_counts_and_clears_each_kind() {
    let root = folder();
    let empty = report(&root, &[]);
    assert_eq!(empty["folder"], root.display().to_string());
    assert_eq!(empty["lod"]["usage"]["files"], 0);
    assert_eq!(empty["fits"]["usage"]["files"], 0);

    let scene = common::temp_path("cache", "scene.ply");
    let scene = scene.to_str().unwrap();
    succeeds(visage_in(
        &root,
        &["convert", "--synthetic-scale", "3000", scene],
    ));
    succeeds(visage_in(&root, &["lod", scene]));
    succeeds(visage_in(
        &root,
        &[
            "compose",
            "--recipe",
            "recipes/three-sources.toml",
            "--gaussians-per-avatar",
            "2000",
            "--seam-fit",
            "3",
            "--seam-fit-size",
            "24",
        ],
    ));
    std::fs::write(root.join("fits/notes.txt"), b"mine").unwrap();
    let full = report(&root, &[]);
    for kind in ["lod", "fits"] {
        assert_eq!(full[kind]["usage"]["files"], 1, "{full}");
        assert!(
            full[kind]["usage"]["bytes"].as_u64().unwrap() > 1000,
            "{full}"
        );
        assert!(full[kind]["removed"].is_null());
    }
    let text = succeeds(visage_in(&root, &["cache"]));
    assert!(text.contains("lod/") && text.contains("fits/"), "{text}");

    let cleared = report(&root, &["--clear", "fits"]);
    assert_eq!(cleared["fits"]["removed"]["files"], 1);
    assert_eq!(
        cleared["fits"]["removed"]["bytes"],
        full["fits"]["usage"]["bytes"]
    );
    assert_eq!(cleared["fits"]["usage"]["files"], 0);
    assert_eq!(cleared["lod"]["usage"]["files"], 1, "lod caches stay");
    assert!(root.join("fits/notes.txt").exists(), "not the cache's file");
    let all = report(&root, &["--clear", "all"]);
    assert_eq!(all["lod"]["removed"]["files"], 1);
    assert_eq!(all["lod"]["usage"]["files"], 0);
    // The scene opens again: its cache is made anew.
    succeeds(visage_in(&root, &["lod", scene]));
    assert_eq!(report(&root, &[])["lod"]["usage"]["files"], 1);

    let typo = visage_in(&root, &["cache", "--clear", "lods"]);
    assert_eq!(typo.status.code(), Some(2));
    let said = String::from_utf8_lossy(&typo.stderr);
    assert!(said.contains("lod") && said.contains("fits"), "{said}");
    std::fs::remove_dir_all(&root).ok();
    std::fs::remove_file(scene).ok();
}
