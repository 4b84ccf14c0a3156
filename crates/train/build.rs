//! Names the code a seam fit's result depends on, so that a fit stored by
//! one build of visage is never read back by another whose fit, composer,
//! renderers or model differ (method §9.13): the fit key hashes
//! `VISAGE_FIT_CODE`, a hash of the sources of this crate and of the crates
//! below it, shaders included. A build between two releases, or one with
//! uncommitted edits, fits afresh instead of showing a fit another version
//! of the code made.

use std::path::{Path, PathBuf};

/// The crates whose code a fit runs: the model, composer, renderers and the
/// fit itself (the editor and front ends only ask for it).
const CRATES: [&str; 4] = ["core", "render", "compose", "train"];

fn main() {
    let manifest = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    let crates = manifest.parent().expect("the crate sits in crates/");
    let mut files = Vec::new();
    for name in CRATES {
        for folder in ["src", "shaders"] {
            let dir = crates.join(name).join(folder);
            if dir.is_dir() {
                // A folder is watched whole: any file in it changing reruns this.
                println!("cargo:rerun-if-changed={}", dir.display());
                collect(&dir, &mut files);
            }
        }
    }
    files.sort();
    // FNV-1a, 64 bits: the value only has to differ when the code does.
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut feed = |bytes: &[u8]| {
        for &b in bytes {
            hash = (hash ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3);
        }
    };
    for file in &files {
        let relative = file.strip_prefix(crates).unwrap_or(file);
        feed(relative.to_string_lossy().as_bytes());
        feed(&std::fs::read(file).unwrap_or_default());
    }
    println!("cargo:rustc-env=VISAGE_FIT_CODE={hash:016x}");
}

/// Every file under `dir`, recursively.
fn collect(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect(&path, out);
        } else {
            out.push(path);
        }
    }
}
