//! The layering of docs/architecture.md, checked on every `crate::` path in
//! the sources: imports only point down, so there are no import circles, and
//! nothing below the front ends names the command line or terminal crates.

use std::path::Path;

/// Top-level modules from the bottom up; a module may use only those before it.
const LAYERS: [&str; 14] = [
    "text", "error", "model", "avatar", "scene", "io", "compose", "render", "train", "pipeline",
    "editor", "study", "tui", "cli",
];

/// Crates only the front ends (`tui`, `cli`) may use.
const FRONT_END_CRATES: [&str; 4] = ["clap", "crossterm", "ratatui", "ratatui_image"];

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The top-level module a source file belongs to (None for a crate's lib.rs
/// or main.rs): the first component after the crate's `src/`.
fn module_of(path: &Path) -> Option<String> {
    let rel: std::path::PathBuf = path
        .components()
        .skip_while(|c| c.as_os_str() != "src")
        .skip(1)
        .collect();
    let first = rel
        .components()
        .next()?
        .as_os_str()
        .to_string_lossy()
        .into_owned();
    let name = first.trim_end_matches(".rs").to_string();
    (name != "lib" && name != "main").then_some(name)
}

/// Every `crate::name` in the text (code and doc links alike).
fn crate_paths(text: &str) -> Vec<String> {
    text.match_indices("crate::")
        .filter(|(at, _)| !text[..*at].ends_with(|c: char| c.is_alphanumeric() || c == '_'))
        .map(|(at, m)| {
            text[at + m.len()..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect()
        })
        .collect()
}

#[test]
fn imports_only_point_down_and_front_end_crates_stay_in_front() {
    let mut files = Vec::new();
    rust_files(Path::new("src"), &mut files);
    for krate in std::fs::read_dir("crates").unwrap() {
        rust_files(&krate.unwrap().path().join("src"), &mut files);
    }
    let rank = |m: &str| LAYERS.iter().position(|l| *l == m);
    let mut problems = Vec::new();
    for file in &files {
        let Some(module) = module_of(file) else {
            continue;
        };
        let own = rank(&module).unwrap_or_else(|| panic!("{module} is not in LAYERS"));
        let text = std::fs::read_to_string(file).unwrap();
        for target in crate_paths(&text) {
            if let Some(r) = rank(&target) {
                if r > own {
                    problems.push(format!("{}: {module} uses crate::{target}", file.display()));
                }
            }
        }
        assert!(
            !text.contains("super::super::"),
            "{}: reaches past its module",
            file.display()
        );
        if own < rank("tui").unwrap() {
            for c in FRONT_END_CRATES {
                let uses = text.lines().any(|l| {
                    let l = l.trim_start();
                    !l.starts_with("//")
                        && (l.contains(&format!("use {c}::"))
                            || l.contains(&format!("{c}::")) && !l.contains(&format!("_{c}::")))
                });
                if uses {
                    problems.push(format!("{}: {module} uses the {c} crate", file.display()));
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "layering broken:\n{}",
        problems.join("\n")
    );
}
