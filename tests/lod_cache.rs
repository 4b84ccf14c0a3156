//! The level-of-detail cache: built once, found again, rebuilt when the
//! scene changes or the cache is truncated or damaged, and read by chunks
//! within a memory budget that a scene larger than it respects.

mod common;

use std::path::{Path, PathBuf};

use visage::pipeline::lod::{open_cached, CacheOrigin, LodScene};
use visage::render::lod::cache::{cache_path, fingerprint};
use visage::render::lod::{build, cut, Hierarchy, LodPolicy, PagedTree};
use visage::scene::camera::{Camera, UpAxis};
use visage::scene::synthetic::synthetic_scene;

/// A fresh folder for one test's scene and caches.
fn folder(tag: &str) -> PathBuf {
    let dir = common::temp_path("lodcache", tag);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A synthetic scene of `n` Gaussians (SH degree 3) written as a PLY.
fn scene_file(dir: &Path, n: usize) -> PathBuf {
    let path = dir.join("scene.ply");
    visage::io::splat::write_scene(&path, &synthetic_scene(n, 5)).unwrap();
    path
}

fn quiet(_: &str) {}

fn origin_why(origin: &CacheOrigin) -> String {
    match origin {
        CacheOrigin::Found => "found".into(),
        CacheOrigin::Built { why, .. } => why.clone(),
    }
}

fn close_camera(tree: &PagedTree) -> Camera {
    let (lo, hi) = tree.header().source.bounds;
    let orbit = visage::scene::camera::Orbit {
        fov_deg: 40.0,
        up: UpAxis::default(),
        ..visage::scene::camera::Orbit::STUDY
    }
    .framing(lo, hi);
    let mut camera = orbit.camera(320, 240);
    camera.eye = camera.target + (camera.eye - camera.target) * 0.4;
    camera
}

#[test]
fn a_cache_is_built_once_then_found_and_draws_what_memory_draws() {
    let dir = folder("found");
    let file = scene_file(&dir, 30_000);
    let caches = dir.join("cache");
    // What a build killed in a process that is gone left behind.
    let name = cache_path(&caches, &fingerprint(&file).unwrap());
    std::fs::create_dir_all(&caches).unwrap();
    std::fs::write(name.with_extension("lod.partial.4000000000"), b"half").unwrap();
    let (tree, origin, path) =
        open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
    assert_eq!(origin_why(&origin), "there is none yet");
    assert!(path == name && path.is_file());
    let partials = std::fs::read_dir(&caches)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains("partial")
        })
        .count();
    assert_eq!(
        partials, 0,
        "this build's partial renamed, the dead one removed"
    );
    drop(tree);
    let (tree, origin, again) =
        open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
    assert_eq!((origin, &again), (CacheOrigin::Found, &path));
    // With room for all of it, the paged cut is the in-memory cut.
    let memory = build(&visage::io::splat::read_scene(&file).unwrap());
    assert_eq!(tree.header().nodes as usize, memory.len());
    let camera = close_camera(&tree);
    let mut paged = LodScene::paged(tree);
    let mut drawn = paged.gaussians_for(&camera, LodPolicy::Auto).0.clone();
    for _ in 0..20 {
        if paged.summary().chunks_read == 0 {
            break;
        }
        drawn = paged.gaussians_for(&camera, LodPolicy::Auto).0.clone();
    }
    let in_memory = memory.gather(&memory.cut(&camera, LodPolicy::Auto), &camera);
    assert_eq!(drawn, in_memory);
}

#[test]
fn a_changed_scene_or_a_damaged_cache_is_rebuilt() {
    let dir = folder("stale");
    // 30k Gaussians of degree 3: 7.4 MB, so the fingerprint's 64 windows
    // of 64 KiB leave gaps.
    let file = scene_file(&dir, 30_000);
    let caches = dir.join("cache");
    let (_, _, path) = open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
    // One byte changed between the first two sampled windows: the same
    // fingerprint (so the same cache name) but not the same content.
    let mut bytes = std::fs::read(&file).unwrap();
    bytes[(64 << 10) + 100] ^= 0x40;
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&file, &bytes).unwrap();
    let heard = std::sync::Mutex::new(Vec::new());
    let progress = |done, all| heard.lock().unwrap().push((done, all));
    let notes = std::sync::Mutex::new(Vec::new());
    let note = |line: &str| notes.lock().unwrap().push(line.to_string());
    let (_, origin, same) = open_cached(&file, Some(&caches), 1 << 30, &note, &progress).unwrap();
    assert_eq!(same, path);
    // The content was hashed (the time changed) with its progress shown,
    // to the file's end, once: the rebuild takes the comparison's hash.
    let size = bytes.len() as u64;
    assert!(heard.lock().unwrap().contains(&(size, size)));
    assert_eq!(
        origin_why(&origin),
        "the scene file changed since it was built"
    );
    let notes = notes.into_inner().unwrap();
    let hashing: Vec<_> = notes
        .iter()
        .filter(|n| n.starts_with("hashing") && n.contains("scene.ply"))
        .collect();
    assert_eq!(hashing.len(), 1, "{notes:?}");
    assert!(hashing[0].contains("whether it changed"), "{notes:?}");
    // Truncated: refused in one line, rebuilt.
    let len = std::fs::metadata(&path).unwrap().len();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(len - 1000)
        .unwrap();
    let refused = PagedTree::open(&path, 1 << 30).unwrap_err().to_string();
    assert!(
        refused.contains("truncated") && !refused.contains('\n'),
        "{refused}"
    );
    let notes = std::sync::Mutex::new(Vec::new());
    let note = |line: &str| notes.lock().unwrap().push(line.to_string());
    let (_, origin, _) = open_cached(&file, Some(&caches), 1 << 30, &note, &|_, _| {}).unwrap();
    assert!(origin_why(&origin).contains("truncated"));
    let notes = notes.into_inner().unwrap();
    assert!(notes[0].starts_with("hashing") && notes[0].contains("truncated"));
    assert!(notes[1].contains("building the level-of-detail cache"));
    // A damaged header, and a damaged first chunk: refused, rebuilt.
    for at in [20usize, 4096 + 50] {
        let mut cache = std::fs::read(&path).unwrap();
        cache[at] ^= 0xff;
        std::fs::write(&path, &cache).unwrap();
        let refused = PagedTree::open(&path, 1 << 30).unwrap_err().to_string();
        assert!(refused.contains("damaged"), "{refused}");
        let (_, origin, _) =
            open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
        assert!(origin_why(&origin).contains("damaged"));
    }
    // Not a cache at all.
    std::fs::write(&path, b"hello").unwrap();
    let (_, origin, _) = open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
    assert!(origin_why(&origin).contains("shorter than its header"));
}

#[test]
fn a_damaged_chunk_past_the_coarse_levels_is_never_drawn() {
    let dir = folder("chunk");
    let file = scene_file(&dir, 30_000);
    let caches = dir.join("cache");
    let (tree, _, path) = open_cached(&file, Some(&caches), 1 << 30, &quiet, &|_, _| {}).unwrap();
    let record = tree.header().record_bytes();
    drop(tree);
    // A budget that pins only the first chunk; the close view reads more.
    let budget = 4 * 8192 * record;
    let refined = |tree: &mut PagedTree| {
        let camera = close_camera(tree);
        for _ in 0..20 {
            let c = cut(&*tree, &camera, LodPolicy::Auto);
            if tree.refine(&c) == 0 {
                return c;
            }
        }
        panic!("still reading chunks after 20 frames");
    };
    let mut tree = PagedTree::open(&path, budget).unwrap();
    refined(&mut tree);
    let read = *tree.resident_chunks().last().unwrap();
    assert!(read >= 1, "a chunk past the pinned one was read");
    drop(tree);
    let mut cache = std::fs::read(&path).unwrap();
    cache[4096 + read * 8192 * record + 10] ^= 0xff;
    std::fs::write(&path, &cache).unwrap();
    let mut tree = PagedTree::open(&path, budget).unwrap();
    let c = refined(&mut tree);
    assert_eq!(tree.damaged(), &[read]);
    assert!(c.nodes.iter().all(|&n| tree.node(n).is_some()));
    assert!(c.nodes.iter().all(|&n| n as usize / 8192 != read));
}

#[test]
fn a_scene_larger_than_the_budget_stays_within_it() {
    let dir = folder("budget");
    // 500k Gaussians of degree 3: a 124 MB file, a 210 MB cache.
    let file = dir.join("big.ply");
    let out = common::visage(&[
        "convert",
        "--synthetic-scale",
        "500000",
        file.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let caches = dir.join("cache");
    let bench = |budget: &str| {
        let out = std::process::Command::new(env!("CARGO_BIN_EXE_visage"))
            .env("NODEVICE_SELECT", "1")
            .env("VISAGE_CACHE_DIR", &caches)
            .args(["bench", "render", "--ply", file.to_str().unwrap()])
            .args([
                "--memory-budget",
                budget,
                "--renderers",
                "cpu",
                "--frames",
                "30",
            ])
            .args(["--sizes", "200x120,640x480", "--json"])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    let built = bench("16M");
    assert!(built["cache_built"]["bytes"].as_u64().unwrap() > 200_000_000);
    // The cache exists now: this process never holds the scene.
    let doc = bench("16M");
    assert!(doc["cache_built"].is_null());
    let rows = &doc["renderers"][0]["rows"];
    let read: u64 = (0..2)
        .map(|r| rows[r]["chunks_read"].as_u64().unwrap())
        .sum();
    assert!(read > 0, "{rows}");
    for r in 0..2 {
        assert!(rows[r]["resident_mb"].as_f64().unwrap() <= 16.0, "{rows}");
    }
    let peak = doc["peak_rss_mb"].as_f64().unwrap();
    let file_mb = std::fs::metadata(&file).unwrap().len() as f64 / (1 << 20) as f64;
    assert!(
        peak < file_mb,
        "peak {peak:.0} MiB for a {file_mb:.0} MiB scene"
    );
    // Nor does the build: it streams the file in groups within the budget.
    let build_peak = built["peak_rss_mb"].as_f64().unwrap();
    assert!(
        build_peak < file_mb,
        "the build peaked at {build_peak:.0} MiB for a {file_mb:.0} MiB scene"
    );
}

/// `visage lod` builds a cache ahead of viewing, finds it again (also once
/// the file's time changed, as a copy's does, by its content), and refuses
/// what is not a scene with one line and exit 2.
#[test]
fn the_lod_command_builds_and_checks_caches() {
    let dir = folder("command");
    let file = scene_file(&dir, 5_000);
    let caches = dir.join("cache");
    let lod = |file: &Path| {
        common::visage(&[
            "lod",
            file.to_str().unwrap(),
            "--cache-dir",
            caches.to_str().unwrap(),
            "--json",
        ])
    };
    let status = |out: &std::process::Output| {
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        doc["caches"][0]["status"].as_str().unwrap().to_string()
    };
    assert_eq!(status(&lod(&file)), "built");
    assert_eq!(status(&lod(&file)), "found");
    // A copy carries a new modification time: the content decides.
    let bytes = std::fs::read(&file).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    std::fs::write(&file, &bytes).unwrap();
    assert_eq!(status(&lod(&file)), "found");
    for bad in [dir.join("missing.ply"), dir.join("junk.ply")] {
        if bad.ends_with("junk.ply") {
            std::fs::write(&bad, b"not a scene at all").unwrap();
        }
        let out = lod(&bad);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
}
