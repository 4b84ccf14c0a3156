//! Helpers the integration tests share: running the real binary and naming
//! temporary files per test process.

#![allow(dead_code)] // each test binary uses its own subset

pub mod tmux;

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs the `visage` binary with `args` (no device-selection warnings).
pub fn visage(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .env("VISAGE_CACHE_DIR", test_cache_dir())
        .args(args)
        .output()
        .unwrap()
}

/// The cache folder tests use (level-of-detail caches in `lod/`, seam
/// fits in `fits/`; never the user's): `$VISAGE_CACHE_DIR` when set
/// (`.ci/run` sets it), else a folder in the temporary folder. Shared by
/// every test and kept between runs, so a test that must watch a seam fit
/// run passes `--no-seam-fit-cache` or a folder of its own.
pub fn test_cache_dir() -> PathBuf {
    std::env::var_os("VISAGE_CACHE_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("visage-test-cache"))
}

/// A path in the temporary folder, unique to this test process and `tag`.
pub fn temp_path(tag: &str, name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("visage-{tag}-{}-{name}", std::process::id()))
}

/// The Python with numpy the format checks run under: $VISAGE_TEST_PYTHON, else
/// Debian's /usr/bin/python3 (where .ci/setup installs python3-numpy), else
/// `python3`.
pub fn python() -> String {
    std::env::var("VISAGE_TEST_PYTHON").unwrap_or_else(|_| {
        if std::path::Path::new("/usr/bin/python3").exists() {
            "/usr/bin/python3".into()
        } else {
            "python3".into()
        }
    })
}

/// A small front-arc capture of the built-in `ada` in a fresh temporary
/// folder: `size` pixels square, `cameras` cameras, `frames` timesteps.
pub fn small_capture(tag: &str, name: &str, size: u32, cameras: u32, frames: u32) -> PathBuf {
    let dir = temp_path(tag, name);
    std::fs::remove_dir_all(&dir).ok();
    let (size, cameras, frames) = (
        format!("{size}x{size}"),
        cameras.to_string(),
        frames.to_string(),
    );
    let o = visage(&[
        "capture",
        "--size",
        &size,
        "--cameras",
        &cameras,
        "--frames",
        &frames,
        "-o",
        dir.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    dir
}

/// Marks a capture as made elsewhere (not from the built-in head), so
/// training it needs FLAME files as a real dataset does.
pub fn mark_captured_elsewhere(dataset: &std::path::Path) {
    for split in ["train", "val", "test"] {
        let path = dataset.join(format!("transforms_{split}.json"));
        let text = std::fs::read_to_string(&path).unwrap();
        std::fs::write(
            &path,
            text.replace("visage_builtin_head", "captured_elsewhere"),
        )
        .unwrap();
    }
}

/// The built-in people the manifest tests train, one subject each.
pub const MANIFEST_PEOPLE: [&str; 6] = ["ada", "bram", "cleo", "dries", "elif", "femi"];

/// Writes `dir/manifest.toml`: the first `count` of [`MANIFEST_PEOPLE`] as
/// subjects captured at 48² (3 cameras, 2 timesteps) into `dir/captures/`
/// and trained for `iterations` at 32² on the CPU (checkpoint every
/// `checkpoint_every`) into `dir/<output>/`, seeds 1, 2, ….
pub fn tiny_manifest(
    dir: &std::path::Path,
    output: &str,
    count: usize,
    iterations: usize,
    checkpoint_every: usize,
) -> PathBuf {
    std::fs::create_dir_all(dir).unwrap();
    let mut text = format!(
        "output = \"{output}\"\n[defaults]\niterations = {iterations}\nsize = \"32x32\"\n\
         checkpoint_every = {checkpoint_every}\nrenderer = \"cpu\"\n"
    );
    for (i, person) in MANIFEST_PEOPLE.iter().take(count).enumerate() {
        text += &format!(
            "\n[[subject]]\nid = \"{person}\"\ndataset = \"captures/{person}\"\nseed = {}\n\
             [subject.capture]\nsource = \"{person}\"\nsize = \"48x48\"\ncameras = 3\nframes = 2\n",
            i + 1
        );
    }
    let path = dir.join(format!("{output}.toml"));
    std::fs::write(&path, text).unwrap();
    path
}

/// The files of a trained avatar that must match byte for byte between runs.
pub const AVATAR_FILES: [&str; 4] = [
    "point_cloud.ply",
    "flame_param.npz",
    "training.json",
    "subject.json",
];

/// Whether two avatar folders hold the same bytes.
pub fn same_avatar(a: &std::path::Path, b: &std::path::Path) -> bool {
    AVATAR_FILES.iter().all(|f| {
        std::fs::read(a.join(f)).ok().is_some()
            && std::fs::read(a.join(f)).ok() == std::fs::read(b.join(f)).ok()
    })
}
