//! Completion for the `:` prompt: command names, then each argument by what
//! the command table says it takes (groups, sources, motions, options,
//! `SOURCE=` pairs, camera keys, file paths). Pure apart from listing folders
//! for paths, so the terminal front end only has to show the candidates.

use std::path::Path;

use super::command::{ArgHint, CommandSpec, COMMANDS};
use super::state::Catalog;
use crate::model::regions::Group;

/// What completing the word before the cursor offers.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Completion {
    /// Byte offset in the line where the word being completed starts.
    pub start: usize,
    /// What may replace the word, sorted, each a whole word.
    pub candidates: Vec<String>,
}

impl Completion {
    /// The longest prefix all candidates share.
    pub fn common_prefix(&self) -> String {
        let Some(first) = self.candidates.first() else {
            return String::new();
        };
        let mut end = first.len();
        for c in &self.candidates[1..] {
            end = end.min(
                first
                    .char_indices()
                    .zip(c.chars())
                    .find(|((_, a), b)| a != b)
                    .map_or(end.min(c.len()), |((i, _), _)| i),
            );
        }
        first[..end].to_string()
    }
}

/// Whether a completed word is finished (a space may follow): not a folder,
/// a `SOURCE=` or a `key=` waiting for its value.
pub fn ends_word(candidate: &str) -> bool {
    !(candidate.ends_with('/') || candidate.ends_with('='))
}

/// Completes the last word of `before_cursor` (the prompt's text up to the
/// cursor) against the command table and the catalog's names.
pub fn complete(before_cursor: &str, catalog: &Catalog) -> Completion {
    let start = before_cursor
        .char_indices()
        .rfind(|(_, c)| c.is_whitespace())
        .map_or(0, |(i, c)| i + c.len_utf8());
    let word = &before_cursor[start..];
    let earlier: Vec<&str> = before_cursor[..start].split_whitespace().collect();
    let candidates = match earlier.first() {
        None => command_names(word, catalog),
        Some(name) => match CommandSpec::find(name) {
            Some(spec) => {
                let index = earlier.len() - 1;
                let hint = spec
                    .args
                    .get(index)
                    .or_else(|| spec.args.last().filter(|h| h.repeats()));
                hint.map_or_else(Vec::new, |h| argument_words(*h, word, catalog))
            }
            None => Vec::new(),
        },
    };
    Completion { start, candidates }
}

/// Command names starting with `prefix`, without those a scene view refuses.
fn command_names(prefix: &str, catalog: &Catalog) -> Vec<String> {
    let mut names: Vec<String> = COMMANDS
        .iter()
        .filter(|c| !(catalog.scene.is_some() && c.avatar))
        .map(|c| c.name)
        .filter(|n| n.starts_with(prefix))
        .map(str::to_string)
        .collect();
    names.sort();
    names
}

/// The words an argument of kind `hint` may be that start with `word`.
fn argument_words(hint: ArgHint, word: &str, catalog: &Catalog) -> Vec<String> {
    let owned = |words: &mut dyn Iterator<Item = &str>| -> Vec<String> {
        words.map(str::to_string).collect()
    };
    let all: Vec<String> = match hint {
        ArgHint::Group => owned(&mut Group::ALL.iter().map(|g| g.name())),
        ArgHint::Source => catalog.sources.clone(),
        ArgHint::Motion => owned(
            &mut std::iter::once("rest").chain(catalog.motions.iter().map(|(n, _)| n.as_str())),
        ),
        ArgHint::Joint => owned(&mut ["jaw", "neck", "eyes"].into_iter()),
        ArgHint::Choice(words) => owned(&mut words.iter().copied()),
        ArgHint::Command => command_names("", catalog),
        ArgHint::Weights if word.contains('=') => Vec::new(),
        ArgHint::Weights => catalog.sources.iter().map(|s| format!("{s}=")).collect(),
        ArgHint::Camera => camera_words(word),
        ArgHint::Path => return path_words(word),
        ArgHint::Size | ArgHint::Number => Vec::new(),
    };
    let mut matching: Vec<String> = all.into_iter().filter(|c| c.starts_with(word)).collect();
    matching.sort();
    matching.dedup();
    matching
}

/// `key=` for each camera setting, or the values of `up=`.
fn camera_words(word: &str) -> Vec<String> {
    if word.starts_with("up=") {
        return crate::scene::camera::UpAxis::ALL
            .iter()
            .map(|(_, n)| format!("up={n}"))
            .collect();
    }
    ["yaw=", "pitch=", "radius=", "fov=", "target=", "up="]
        .iter()
        .map(|k| k.to_string())
        .collect()
}

/// Files and folders whose path starts with `word` (folders end in `/`;
/// hidden entries only when the name typed starts with a dot; `~/` is the
/// home folder).
fn path_words(word: &str) -> Vec<String> {
    let (folder_typed, name_prefix) = match word.rfind('/') {
        Some(i) => (&word[..=i], &word[i + 1..]),
        None => ("", word),
    };
    let folder = match folder_typed.strip_prefix("~/") {
        Some(rest) => std::env::var_os("HOME")
            .map(|h| Path::new(&h).join(rest))
            .unwrap_or_else(|| Path::new(folder_typed).to_path_buf()),
        None if folder_typed.is_empty() => Path::new(".").to_path_buf(),
        None => Path::new(folder_typed).to_path_buf(),
    };
    let Ok(entries) = std::fs::read_dir(&folder) else {
        return Vec::new();
    };
    let mut out: Vec<String> = entries
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().into_string().ok()?;
            let shown = name.starts_with(name_prefix)
                && (!name.starts_with('.') || name_prefix.starts_with('.'))
                && !name.chars().any(|c| c.is_whitespace() || c.is_control());
            let is_dir = e.file_type().ok()?.is_dir()
                || (e.file_type().ok()?.is_symlink() && e.path().is_dir());
            shown.then(|| format!("{folder_typed}{name}{}", if is_dir { "/" } else { "" }))
        })
        .collect();
    out.sort();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn catalog() -> Catalog {
        Catalog {
            sources: ["ada", "bram", "bruno"].map(String::from).to_vec(),
            motions: vec![("talk".into(), 125), ("blink".into(), 125)],
            scene: None,
        }
    }

    fn offered(line: &str) -> Vec<String> {
        complete(line, &catalog()).candidates
    }

    #[test]
    fn commands_then_arguments_by_kind() {
        assert_eq!(offered("sna"), ["snapshot"]);
        assert!(offered("set-").len() >= 4);
        assert_eq!(offered("set-gaussians no"), ["nose"]);
        assert_eq!(offered("set-gaussians nose br"), ["bram", "bruno"]);
        assert_eq!(offered("select-source "), ["ada", "bram", "bruno"]);
        assert_eq!(offered("motion "), ["blink", "rest", "talk"]);
        assert_eq!(offered("smoothing c"), ["crossfade"]);
        assert_eq!(offered("colour "), ["off", "semantic", "skin", "thesis"]);
        assert_eq!(offered("membership p"), ["parent", "place"]);
        assert_eq!(offered("mode e"), ["exact"]);
        assert_eq!(offered("pose n"), ["neck"]);
        assert_eq!(offered("help set-s"), ["set-shape"]);
        // Weights repeat over the rest of the line.
        assert_eq!(offered("set-shape nose bram=0.5 a"), ["ada="]);
        assert!(offered("set-shape nose bram=0.").is_empty());
        assert_eq!(offered("set-camera radius=2 up=-"), ["up=-y", "up=-z"]);
        assert_eq!(offered("set-camera f"), ["fov="]);
        // Numbers and unknown commands offer nothing; too many words neither.
        assert!(offered("zoom ").is_empty());
        assert!(offered("soar ").is_empty());
        assert!(offered("undo x").is_empty());
        let c = complete("set-gaussians nose br", &catalog());
        assert_eq!(c.start, "set-gaussians nose ".len());
        assert_eq!(c.common_prefix(), "br");
    }

    #[test]
    fn a_scene_view_offers_only_its_commands() {
        let scene = Catalog {
            scene: Some(crate::editor::state::SceneSummary {
                name: "room.ply".into(),
                gaussians: 1,
                sh_degree: 0,
                home: crate::scene::camera::Orbit::default(),
                up_reason: "default",
                from_cache: false,
            }),
            ..Catalog::default()
        };
        let names = complete("s", &scene).candidates;
        assert!(names.contains(&"snapshot".to_string()), "{names:?}");
        assert!(!names.contains(&"set-gaussians".to_string()), "{names:?}");
    }

    #[test]
    fn paths_complete_from_the_file_system() {
        let dir = std::env::temp_dir().join(format!("visage-complete-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("renders")).unwrap();
        std::fs::write(dir.join("recipe.toml"), "").unwrap();
        std::fs::write(dir.join(".hidden"), "").unwrap();
        let d = dir.display();
        assert_eq!(
            offered(&format!("save-recipe {d}/re")),
            [format!("{d}/recipe.toml"), format!("{d}/renders/")]
        );
        assert_eq!(
            offered(&format!("snapshot {d}/.h")),
            [format!("{d}/.hidden")]
        );
        assert!(!offered(&format!("export-ply {d}/")).contains(&format!("{d}/.hidden")));
        assert!(ends_word("a.png") && !ends_word("renders/") && !ends_word("bram="));
        std::fs::remove_dir_all(&dir).ok();
    }
}
