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

/// Where level-of-detail caches built by tests go (not the user's cache):
/// `$VISAGE_CACHE_DIR` when set (`.ci/run` sets it), else a folder in the
/// temporary folder.
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
