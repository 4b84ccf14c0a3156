//! Keymaps: TOML files binding keys to command lines. Layers are applied in
//! order — the built-in `keymaps/default.toml`, the user's
//! `$XDG_CONFIG_HOME/visage/keymap.toml` (or `~/.config/visage/keymap.toml`), then
//! `--keymap FILE` — a later layer's binding replaces an earlier one, and `""`
//! removes it. Every error names the file and line. A file's `[keys]` table
//! binds the avatar editor's keys, its `[viewer]` table the scene viewer's
//! (built in: `keymaps/viewer.toml`, WASD free flight).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use serde::Deserialize;
use toml::Spanned;

use crate::editor::command::Command;
use crate::error::{Error, Result};

/// The built-in keymap.
pub const DEFAULT_KEYMAP: &str = include_str!("../../keymaps/default.toml");
/// The built-in keymap of the scene viewer.
pub const VIEWER_KEYMAP: &str = include_str!("../../keymaps/viewer.toml");

/// A key with modifiers, in a normalised form (letters carry shift in their case).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct KeyCombo {
    /// The key.
    pub key: Key,
    /// Control held.
    pub ctrl: bool,
    /// Alt held.
    pub alt: bool,
    /// Shift held (named keys only).
    pub shift: bool,
}

/// Keys that can be bound.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Key {
    /// A printable character.
    Char(char),
    /// Function key F1-F12.
    F(u8),
    /// A named key.
    Named(NamedKey),
}

/// Named keys.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[allow(missing_docs)]
pub enum NamedKey {
    Enter,
    Esc,
    Tab,
    Backspace,
    Space,
    Up,
    Down,
    Left,
    Right,
    Home,
    End,
    PageUp,
    PageDown,
    Delete,
    Insert,
}

const NAMED: [(&str, NamedKey); 15] = [
    ("enter", NamedKey::Enter),
    ("esc", NamedKey::Esc),
    ("tab", NamedKey::Tab),
    ("backspace", NamedKey::Backspace),
    ("space", NamedKey::Space),
    ("up", NamedKey::Up),
    ("down", NamedKey::Down),
    ("left", NamedKey::Left),
    ("right", NamedKey::Right),
    ("home", NamedKey::Home),
    ("end", NamedKey::End),
    ("pageup", NamedKey::PageUp),
    ("pagedown", NamedKey::PageDown),
    ("delete", NamedKey::Delete),
    ("insert", NamedKey::Insert),
];

impl KeyCombo {
    /// Parses a key name like `q`, `J`, `ctrl-c`, `shift-left`, `f5`, `space`, `-`.
    pub fn parse(text: &str) -> Option<KeyCombo> {
        let mut rest = text;
        let (mut ctrl, mut alt, mut shift) = (false, false, false);
        loop {
            let lower = rest.to_ascii_lowercase();
            if rest.len() > 1 && lower.starts_with("ctrl-") {
                ctrl = true;
                rest = &rest[5..];
            } else if rest.len() > 1 && lower.starts_with("alt-") {
                alt = true;
                rest = &rest[4..];
            } else if rest.len() > 1 && lower.starts_with("shift-") {
                shift = true;
                rest = &rest[6..];
            } else {
                break;
            }
        }
        let mut chars = rest.chars();
        let key = match (chars.next(), chars.next()) {
            (Some(c), None) if !c.is_control() && c != ' ' => {
                if shift {
                    return None; // letters carry shift in their case
                }
                Key::Char(if ctrl { c.to_ascii_lowercase() } else { c })
            }
            _ => {
                let lower = rest.to_ascii_lowercase();
                if let Some((_, k)) = NAMED.iter().find(|(n, _)| *n == lower) {
                    Key::Named(*k)
                } else if let Some(n) = lower.strip_prefix('f').and_then(|d| d.parse::<u8>().ok()) {
                    if !(1..=12).contains(&n) {
                        return None;
                    }
                    Key::F(n)
                } else {
                    return None;
                }
            }
        };
        Some(KeyCombo {
            key,
            ctrl,
            alt,
            shift,
        })
    }

    /// The combo of a terminal key event.
    pub fn from_event(e: &KeyEvent) -> Option<KeyCombo> {
        let ctrl = e.modifiers.contains(KeyModifiers::CONTROL);
        let alt = e.modifiers.contains(KeyModifiers::ALT);
        let shift = e.modifiers.contains(KeyModifiers::SHIFT);
        let key = match e.code {
            KeyCode::Char(' ') => Key::Named(NamedKey::Space),
            KeyCode::Char(c) => {
                return Some(KeyCombo {
                    key: Key::Char(if ctrl { c.to_ascii_lowercase() } else { c }),
                    ctrl,
                    alt,
                    shift: false,
                })
            }
            KeyCode::F(n) => Key::F(n),
            KeyCode::Enter => Key::Named(NamedKey::Enter),
            KeyCode::Esc => Key::Named(NamedKey::Esc),
            KeyCode::Tab => Key::Named(NamedKey::Tab),
            KeyCode::BackTab => {
                return Some(KeyCombo {
                    key: Key::Named(NamedKey::Tab),
                    ctrl,
                    alt,
                    shift: true,
                })
            }
            KeyCode::Backspace => Key::Named(NamedKey::Backspace),
            KeyCode::Up => Key::Named(NamedKey::Up),
            KeyCode::Down => Key::Named(NamedKey::Down),
            KeyCode::Left => Key::Named(NamedKey::Left),
            KeyCode::Right => Key::Named(NamedKey::Right),
            KeyCode::Home => Key::Named(NamedKey::Home),
            KeyCode::End => Key::Named(NamedKey::End),
            KeyCode::PageUp => Key::Named(NamedKey::PageUp),
            KeyCode::PageDown => Key::Named(NamedKey::PageDown),
            KeyCode::Delete => Key::Named(NamedKey::Delete),
            KeyCode::Insert => Key::Named(NamedKey::Insert),
            _ => return None,
        };
        Some(KeyCombo {
            key,
            ctrl,
            alt,
            shift,
        })
    }
}

impl std::fmt::Display for KeyCombo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.ctrl {
            write!(f, "ctrl-")?;
        }
        if self.alt {
            write!(f, "alt-")?;
        }
        if self.shift {
            write!(f, "shift-")?;
        }
        match self.key {
            Key::Char(c) => write!(f, "{c}"),
            Key::F(n) => write!(f, "f{n}"),
            Key::Named(k) => write!(
                f,
                "{}",
                NAMED.iter().find(|(_, n)| *n == k).map_or("?", |(s, _)| *s)
            ),
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct KeymapFile {
    #[serde(default)]
    keys: BTreeMap<Spanned<String>, Spanned<String>>,
    #[serde(default)]
    viewer: BTreeMap<Spanned<String>, Spanned<String>>,
}

/// Key bindings: key → command line.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Keymap {
    bindings: BTreeMap<KeyCombo, (String, Command)>,
    /// Binds the scene viewer (files' `[viewer]` tables) rather than the editor.
    viewer: bool,
}

fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())].matches('\n').count() + 1
}

impl Keymap {
    /// The built-in keymap alone.
    pub fn builtin() -> Keymap {
        let mut k = Keymap::default();
        k.merge_text(DEFAULT_KEYMAP, "keymaps/default.toml")
            .expect("the built-in keymap is valid");
        k
    }

    /// The scene viewer's built-in keymap alone.
    pub fn builtin_viewer() -> Keymap {
        let mut k = Keymap {
            viewer: true,
            ..Keymap::default()
        };
        k.merge_text(VIEWER_KEYMAP, "keymaps/viewer.toml")
            .expect("the built-in viewer keymap is valid");
        k
    }

    /// The built-in keymap, the user's config file if present, then `extra`.
    pub fn load(extra: Option<&Path>) -> Result<Keymap> {
        Keymap::builtin().with_layers(extra)
    }

    /// The scene viewer's keymap: built in, the user's `[viewer]` table, then
    /// `extra`'s.
    pub fn load_viewer(extra: Option<&Path>) -> Result<Keymap> {
        Keymap::builtin_viewer().with_layers(extra)
    }

    fn with_layers(mut self, extra: Option<&Path>) -> Result<Keymap> {
        if let Some(user) = user_keymap_path().filter(|p| p.exists()) {
            self.merge_file(&user)?;
        }
        if let Some(path) = extra {
            self.merge_file(path)?;
        }
        Ok(self)
    }

    /// Applies a keymap file over this one.
    pub fn merge_file(&mut self, path: &Path) -> Result<()> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read keymap {}: {e}", path.display())))?;
        self.merge_text(&text, &path.display().to_string())
    }

    /// Applies keymap text over this one; `name` labels errors.
    pub fn merge_text(&mut self, text: &str, name: &str) -> Result<()> {
        let file: KeymapFile = toml::from_str(text).map_err(|e| {
            let line = e.span().map_or(1, |s| line_of(text, s.start));
            Error::input(format!("keymap {name}:{line}: {}", e.message().trim()))
        })?;
        let table = if self.viewer { file.viewer } else { file.keys };
        for (key, command) in table {
            let line = line_of(text, key.span().start);
            let combo = KeyCombo::parse(key.get_ref()).ok_or_else(|| {
                Error::input(format!(
                    "keymap {name}:{line}: unknown key '{}' (examples: q, J, ctrl-c, shift-left, f5, space)",
                    crate::text::printable(key.get_ref())
                ))
            })?;
            let line_text = command.get_ref().trim();
            if line_text.is_empty() {
                self.bindings.remove(&combo);
                continue;
            }
            let parsed = Command::parse(line_text)
                .map_err(|e| Error::input(format!("keymap {name}:{line}: {e}")))?;
            self.bindings.insert(combo, (line_text.to_string(), parsed));
        }
        Ok(())
    }

    /// The command bound to a key event, if any.
    pub fn lookup(&self, event: &KeyEvent) -> Option<&Command> {
        KeyCombo::from_event(event)
            .and_then(|k| self.bindings.get(&k))
            .map(|(_, c)| c)
    }

    /// All bindings, for the help overlay: (key, command line).
    pub fn bindings(&self) -> impl Iterator<Item = (String, &str)> {
        self.bindings
            .iter()
            .map(|(k, (text, _))| (k.to_string(), text.as_str()))
    }

    /// The shortest key bound to a command line, for hints (`q` rather
    /// than `ctrl-c`).
    pub fn key_for(&self, command_line: &str) -> Option<String> {
        self.bindings
            .iter()
            .filter(|(_, (t, _))| t == command_line)
            .map(|(k, _)| k.to_string())
            .min_by_key(|k| k.chars().count())
    }
}

/// `$XDG_CONFIG_HOME/visage/keymap.toml`, falling back to `~/.config/...`.
pub fn user_keymap_path() -> Option<PathBuf> {
    let base = std::env::var_os("XDG_CONFIG_HOME")
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".config")))?;
    Some(base.join("visage").join("keymap.toml"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(code: KeyCode, modifiers: KeyModifiers) -> KeyEvent {
        KeyEvent::new(code, modifiers)
    }

    #[test]
    fn builtin_binds_the_essentials() {
        let k = Keymap::builtin();
        assert_eq!(
            k.lookup(&key(KeyCode::Char('q'), KeyModifiers::NONE)),
            Some(&Command::Quit)
        );
        assert_eq!(
            k.lookup(&key(KeyCode::Char('c'), KeyModifiers::CONTROL)),
            Some(&Command::Quit)
        );
        assert_eq!(
            k.lookup(&key(KeyCode::Char('J'), KeyModifiers::SHIFT)),
            Some(&Command::parse("pose jaw -0.05 0 0").unwrap())
        );
        assert_eq!(
            k.lookup(&key(KeyCode::Left, KeyModifiers::SHIFT)),
            Some(&Command::Orbit(-10.0, 0.0))
        );
        assert_eq!(
            k.lookup(&key(KeyCode::Char(' '), KeyModifiers::NONE)),
            Some(&Command::TogglePlay)
        );
        assert!(k.bindings().count() > 40);
    }

    #[test]
    fn later_layers_override_and_unbind() {
        let mut k = Keymap::builtin();
        k.merge_text(
            "[keys]\n\"q\" = \"\"\n\"ctrl-q\" = \"quit\"\n\"j\" = \"next-group\"\n",
            "user",
        )
        .unwrap();
        assert_eq!(k.lookup(&key(KeyCode::Char('q'), KeyModifiers::NONE)), None);
        assert_eq!(
            k.lookup(&key(KeyCode::Char('q'), KeyModifiers::CONTROL)),
            Some(&Command::Quit)
        );
        assert_eq!(
            k.lookup(&key(KeyCode::Char('j'), KeyModifiers::NONE)),
            Some(&Command::NextGroup)
        );
        k.merge_text(include_str!("../../keymaps/vim.toml"), "vim")
            .unwrap();
        assert_eq!(
            k.lookup(&key(KeyCode::Char('l'), KeyModifiers::NONE)),
            Some(&Command::NextSource)
        );
    }

    #[test]
    fn errors_name_file_and_line() {
        let mut k = Keymap::builtin();
        let e = k
            .merge_text(
                "[keys]\n\"q\" = \"quit\"\n\"hyper-x\" = \"quit\"\n",
                "mine.toml",
            )
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("mine.toml:3") && e.contains("unknown key"),
            "{e}"
        );
        let e = k
            .merge_text("[keys]\n\n\"x\" = \"soar\"\n", "mine.toml")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("mine.toml:3") && e.contains("unknown command"),
            "{e}"
        );
        let e = k
            .merge_text("[keys]\n\"x\" = \n", "mine.toml")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("keymap mine.toml:2"), "{e}");
        let e = k
            .merge_text("[bindings]\n", "mine.toml")
            .unwrap_err()
            .to_string();
        assert!(e.contains("mine.toml:1"), "{e}");
    }

    #[test]
    fn key_names_round_trip() {
        for s in [
            "q",
            "J",
            "ctrl-c",
            "alt-x",
            "shift-left",
            "f5",
            "space",
            "-",
            "?",
            "enter",
            "ctrl-shift-up",
        ] {
            let k = KeyCombo::parse(s).unwrap_or_else(|| panic!("{s}"));
            assert_eq!(KeyCombo::parse(&k.to_string()), Some(k), "{s}");
        }
        for s in ["", "shift-a", "f13", "hyper-x", "ctrl-"] {
            assert_eq!(KeyCombo::parse(s), None, "{s}");
        }
    }
}
