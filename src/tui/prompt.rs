//! The `:` command line, edited the way shells edit theirs: a cursor moved
//! by character or word (←/→, Home/End, ctrl-a/e, alt-b/f), killing back to
//! the start, to the end or a word (ctrl-u/k/w), history on ↑/↓ searched by
//! what was typed first (kept across sessions in the state folder), and Tab
//! completion that shows the candidates on a menu line above the prompt and
//! cycles through them on repeated Tabs.

use std::io::Write;
use std::path::PathBuf;

use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};

use crate::editor::complete::{complete, ends_word};
use crate::editor::state::Catalog;

/// Most history lines kept.
pub const HISTORY_LIMIT: usize = 1000;

/// A line of text and a cursor in it, counted in characters.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LineEditor {
    chars: Vec<char>,
    cursor: usize,
}

impl LineEditor {
    /// The text.
    pub fn text(&self) -> String {
        self.chars.iter().collect()
    }

    /// The cursor, in characters from the start.
    pub fn cursor(&self) -> usize {
        self.cursor
    }

    /// The text before the cursor.
    pub fn before_cursor(&self) -> String {
        self.chars[..self.cursor].iter().collect()
    }

    /// Replaces the whole text, the cursor at its end.
    pub fn set(&mut self, text: &str) {
        self.chars = text.chars().collect();
        self.cursor = self.chars.len();
    }

    /// Types a character at the cursor.
    pub fn insert(&mut self, c: char) {
        self.chars.insert(self.cursor, c);
        self.cursor += 1;
    }

    /// Replaces characters `start..cursor` with `text`, the cursor after it.
    pub fn replace_before_cursor(&mut self, start: usize, text: &str) {
        let start = start.min(self.cursor);
        self.chars.splice(start..self.cursor, text.chars());
        self.cursor = start + text.chars().count();
    }

    /// Deletes the character before the cursor.
    pub fn backspace(&mut self) {
        if self.cursor > 0 {
            self.cursor -= 1;
            self.chars.remove(self.cursor);
        }
    }

    /// Deletes the character under the cursor.
    pub fn delete(&mut self) {
        if self.cursor < self.chars.len() {
            self.chars.remove(self.cursor);
        }
    }

    /// Moves the cursor one character.
    pub fn left(&mut self) {
        self.cursor = self.cursor.saturating_sub(1);
    }

    /// Moves the cursor one character.
    pub fn right(&mut self) {
        self.cursor = (self.cursor + 1).min(self.chars.len());
    }

    /// To the start of the line.
    pub fn home(&mut self) {
        self.cursor = 0;
    }

    /// To the end of the line.
    pub fn end(&mut self) {
        self.cursor = self.chars.len();
    }

    /// Where the word before the cursor starts (skipping spaces first).
    fn word_start(&self) -> usize {
        let mut i = self.cursor;
        while i > 0 && self.chars[i - 1].is_whitespace() {
            i -= 1;
        }
        while i > 0 && !self.chars[i - 1].is_whitespace() {
            i -= 1;
        }
        i
    }

    /// Where the word after the cursor ends (skipping spaces first).
    fn word_end(&self) -> usize {
        let mut i = self.cursor;
        while i < self.chars.len() && self.chars[i].is_whitespace() {
            i += 1;
        }
        while i < self.chars.len() && !self.chars[i].is_whitespace() {
            i += 1;
        }
        i
    }

    /// Back one word.
    pub fn word_left(&mut self) {
        self.cursor = self.word_start();
    }

    /// Forward one word.
    pub fn word_right(&mut self) {
        self.cursor = self.word_end();
    }

    /// Deletes from the start of the line to the cursor.
    pub fn kill_to_start(&mut self) {
        self.chars.drain(..self.cursor);
        self.cursor = 0;
    }

    /// Deletes from the cursor to the end of the line.
    pub fn kill_to_end(&mut self) {
        self.chars.truncate(self.cursor);
    }

    /// Deletes the word before the cursor.
    pub fn kill_word_back(&mut self) {
        let start = self.word_start();
        self.chars.drain(start..self.cursor);
        self.cursor = start;
    }

    /// Deletes the word after the cursor.
    pub fn kill_word_forward(&mut self) {
        let end = self.word_end();
        self.chars.drain(self.cursor..end);
    }
}

/// Lines typed at the prompt, oldest first, saved one line each to a file.
#[derive(Clone, Debug, Default)]
pub struct History {
    entries: Vec<String>,
    file: Option<PathBuf>,
}

impl History {
    /// The history kept in `file` (missing: empty), or in memory only.
    pub fn load(file: Option<PathBuf>) -> Self {
        let mut entries: Vec<String> = file
            .as_deref()
            .and_then(|f| std::fs::read_to_string(f).ok())
            .map(|t| t.lines().map(str::to_string).collect())
            .unwrap_or_default();
        let excess = entries.len().saturating_sub(HISTORY_LIMIT);
        entries.drain(..excess);
        Self { entries, file }
    }

    /// The lines, oldest first.
    pub fn entries(&self) -> &[String] {
        &self.entries
    }

    /// Adds a line (not a repeat of the last one) and appends it to the file;
    /// the file is rewritten when it has grown to twice the limit.
    pub fn push(&mut self, line: &str) {
        let line = line.trim();
        if line.is_empty() || line.contains('\n') || self.entries.last().is_some_and(|l| l == line)
        {
            return;
        }
        self.entries.push(line.to_string());
        let Some(file) = &self.file else { return };
        if let Some(dir) = file.parent() {
            let _ = std::fs::create_dir_all(dir);
        }
        let long = std::fs::metadata(file).map_or(0, |m| m.len()) > 200 * HISTORY_LIMIT as u64;
        if self.entries.len() > HISTORY_LIMIT || long {
            let excess = self.entries.len().saturating_sub(HISTORY_LIMIT);
            self.entries.drain(..excess);
            let _ = std::fs::write(file, self.entries.join("\n") + "\n");
        } else if let Ok(mut f) = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(file)
        {
            let _ = writeln!(f, "{line}");
        }
    }
}

/// The completion menu under way: candidates for the word starting at
/// `start` and the one chosen by repeated Tabs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Menu {
    /// Where the completed word starts, in characters.
    pub start: usize,
    /// The candidates.
    pub candidates: Vec<String>,
    /// The candidate in the line now, if Tab has chosen one.
    pub selected: Option<usize>,
}

/// Walking the history with ↑/↓: lines starting with what was typed.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Browse {
    typed: String,
    /// Index into the history of the line shown.
    at: usize,
}

/// The command line while it is open.
#[derive(Clone, Debug, Default)]
pub struct Prompt {
    /// The line being typed.
    pub line: LineEditor,
    /// The completion menu, while Tab is being pressed.
    pub menu: Option<Menu>,
    browse: Option<Browse>,
}

/// What a key did to the prompt.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PromptOutcome {
    /// Still typing.
    Editing,
    /// Closed without running anything.
    Cancelled,
    /// Enter: run this line.
    Submitted(String),
}

impl Prompt {
    /// An empty prompt.
    pub fn new() -> Self {
        Self::default()
    }

    /// Handles one key.
    pub fn on_key(
        &mut self,
        key: &KeyEvent,
        catalog: &Catalog,
        history: &History,
    ) -> PromptOutcome {
        let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
        let alt = key.modifiers.contains(KeyModifiers::ALT);
        match key.code {
            KeyCode::Tab => return self.tab(catalog, 1),
            KeyCode::BackTab => return self.tab(catalog, -1),
            _ => {}
        }
        if let Some(menu) = self.menu.take() {
            match key.code {
                // Esc leaves the menu, Enter takes the chosen candidate;
                // neither closes the prompt while a menu is open.
                KeyCode::Esc => return PromptOutcome::Editing,
                KeyCode::Enter if menu.selected.is_some() => {
                    let chosen = &menu.candidates[menu.selected.unwrap_or(0)];
                    if ends_word(chosen) {
                        self.line.insert(' ');
                    }
                    return PromptOutcome::Editing;
                }
                _ => {}
            }
        }
        let l = &mut self.line;
        let browsing = matches!(key.code, KeyCode::Up | KeyCode::Down)
            || ctrl && matches!(key.code, KeyCode::Char('p' | 'n'));
        if !browsing {
            self.browse = None;
        }
        match key.code {
            KeyCode::Esc => return PromptOutcome::Cancelled,
            KeyCode::Char('c') if ctrl => return PromptOutcome::Cancelled,
            KeyCode::Enter => return PromptOutcome::Submitted(l.text()),
            KeyCode::Backspace if l.text().is_empty() => return PromptOutcome::Cancelled,
            KeyCode::Backspace if alt => l.kill_word_back(),
            KeyCode::Backspace => l.backspace(),
            KeyCode::Delete => l.delete(),
            KeyCode::Char('d') if ctrl => l.delete(),
            KeyCode::Left if ctrl => l.word_left(),
            KeyCode::Right if ctrl => l.word_right(),
            KeyCode::Left => l.left(),
            KeyCode::Right => l.right(),
            KeyCode::Char('b') if ctrl => l.left(),
            KeyCode::Char('f') if ctrl => l.right(),
            KeyCode::Char('b') if alt => l.word_left(),
            KeyCode::Char('f') if alt => l.word_right(),
            KeyCode::Char('d') if alt => l.kill_word_forward(),
            KeyCode::Home => l.home(),
            KeyCode::End => l.end(),
            KeyCode::Char('a') if ctrl => l.home(),
            KeyCode::Char('e') if ctrl => l.end(),
            KeyCode::Char('u') if ctrl => l.kill_to_start(),
            KeyCode::Char('k') if ctrl => l.kill_to_end(),
            KeyCode::Char('w') if ctrl => l.kill_word_back(),
            KeyCode::Up => self.browse_history(history, -1),
            KeyCode::Down => self.browse_history(history, 1),
            KeyCode::Char('p') if ctrl => self.browse_history(history, -1),
            KeyCode::Char('n') if ctrl => self.browse_history(history, 1),
            KeyCode::Char(c) if !ctrl && !alt && !c.is_control() => l.insert(c),
            _ => {}
        }
        PromptOutcome::Editing
    }

    /// Tab (`step` 1) or shift-Tab (-1): complete the word before the cursor,
    /// or move through the menu's candidates.
    fn tab(&mut self, catalog: &Catalog, step: isize) -> PromptOutcome {
        self.browse = None;
        if let Some(menu) = &mut self.menu {
            let n = menu.candidates.len() as isize;
            let next = match menu.selected {
                None if step > 0 => 0,
                None => n - 1,
                Some(i) => (i as isize + step).rem_euclid(n),
            } as usize;
            menu.selected = Some(next);
            let (start, chosen) = (menu.start, menu.candidates[next].clone());
            self.line.replace_before_cursor(start, &chosen);
            return PromptOutcome::Editing;
        }
        let before = self.line.before_cursor();
        let found = complete(&before, catalog);
        let start = before[..found.start].chars().count();
        match found.candidates.len() {
            0 => {}
            1 => {
                let word = &found.candidates[0];
                self.line.replace_before_cursor(start, word);
                if ends_word(word) && self.line.text().chars().nth(self.line.cursor()) != Some(' ')
                {
                    self.line.insert(' ');
                }
            }
            _ => {
                let common = found.common_prefix();
                if common.len() > before.len() - found.start {
                    self.line.replace_before_cursor(start, &common);
                }
                self.menu = Some(Menu {
                    start,
                    candidates: found.candidates,
                    selected: None,
                });
            }
        }
        PromptOutcome::Editing
    }

    /// ↑ (`step` -1) or ↓ (1): the previous or next history line that starts
    /// with what was typed before browsing began; past the newest, back to it.
    fn browse_history(&mut self, history: &History, step: isize) {
        let entries = history.entries();
        let browse = self.browse.get_or_insert_with(|| Browse {
            typed: self.line.text(),
            at: entries.len(),
        });
        let matches = |i: &usize| entries[*i].starts_with(&browse.typed);
        let next = if step < 0 {
            (0..browse.at)
                .rev()
                .find(|i| matches(i) && entries[*i] != self.line.text())
        } else {
            (browse.at + 1..entries.len()).find(|i| matches(i) && entries[*i] != self.line.text())
        };
        match next {
            Some(i) => {
                browse.at = i;
                self.line.set(&entries[i]);
            }
            None if step > 0 => {
                let typed = browse.typed.clone();
                self.browse = None;
                self.line.set(&typed);
            }
            None => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(code: KeyCode) -> KeyEvent {
        KeyEvent::new(code, KeyModifiers::NONE)
    }

    fn with(code: KeyCode, modifiers: KeyModifiers) -> KeyEvent {
        KeyEvent::new(code, modifiers)
    }

    fn catalog() -> Catalog {
        Catalog {
            sources: ["ada", "bram", "bruno"].map(String::from).to_vec(),
            motions: vec![("talk".into(), 125)],
            scene: None,
        }
    }

    fn typed(p: &mut Prompt, text: &str) {
        for c in text.chars() {
            p.on_key(&key(KeyCode::Char(c)), &catalog(), &History::default());
        }
    }

    #[test]
    fn editing_keys_move_and_kill_like_a_shell() {
        let mut p = Prompt::new();
        let h = History::default();
        let c = catalog();
        typed(&mut p, "set-gaussians nose bram");
        p.on_key(&with(KeyCode::Char('b'), KeyModifiers::ALT), &c, &h);
        assert_eq!(p.line.before_cursor(), "set-gaussians nose ");
        p.on_key(&with(KeyCode::Char('w'), KeyModifiers::CONTROL), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians bram");
        p.on_key(&with(KeyCode::Char('a'), KeyModifiers::CONTROL), &c, &h);
        p.on_key(&with(KeyCode::Char('f'), KeyModifiers::ALT), &c, &h);
        assert_eq!(p.line.cursor(), "set-gaussians".len());
        typed(&mut p, " eyes");
        assert_eq!(p.line.text(), "set-gaussians eyes bram");
        p.on_key(&key(KeyCode::End), &c, &h);
        p.on_key(&key(KeyCode::Left), &c, &h);
        p.on_key(&key(KeyCode::Backspace), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians eyes brm");
        p.on_key(&with(KeyCode::Char('u'), KeyModifiers::CONTROL), &c, &h);
        assert_eq!(p.line.text(), "m");
        p.on_key(&key(KeyCode::Home), &c, &h);
        p.on_key(&with(KeyCode::Char('k'), KeyModifiers::CONTROL), &c, &h);
        assert_eq!(p.line.text(), "");
        assert_eq!(
            p.on_key(&key(KeyCode::Backspace), &c, &h),
            PromptOutcome::Cancelled,
            "backspace on an empty line closes the prompt"
        );
        let mut p = Prompt::new();
        typed(&mut p, "undo");
        assert_eq!(
            p.on_key(&with(KeyCode::Char('c'), KeyModifiers::CONTROL), &c, &h),
            PromptOutcome::Cancelled
        );
        let mut p = Prompt::new();
        typed(&mut p, "undo");
        assert_eq!(
            p.on_key(&key(KeyCode::Enter), &c, &h),
            PromptOutcome::Submitted("undo".into())
        );
    }

    #[test]
    fn tab_completes_shows_a_menu_and_cycles() {
        let mut p = Prompt::new();
        let (c, h) = (catalog(), History::default());
        typed(&mut p, "set-ga");
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians ");
        typed(&mut p, "no");
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians nose ");
        typed(&mut p, "b");
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians nose br", "the common prefix");
        let menu = p.menu.clone().expect("an ambiguous Tab opens the menu");
        assert_eq!(menu.candidates, ["bram", "bruno"]);
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians nose bram");
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians nose bruno");
        p.on_key(&key(KeyCode::BackTab), &c, &h);
        assert_eq!(p.line.text(), "set-gaussians nose bram");
        assert_eq!(
            p.on_key(&key(KeyCode::Enter), &c, &h),
            PromptOutcome::Editing,
            "Enter takes the candidate"
        );
        assert!(p.menu.is_none());
        assert_eq!(p.line.text(), "set-gaussians nose bram ");
        // Typing closes the menu and goes on from the text.
        let mut p = Prompt::new();
        typed(&mut p, "set-shape eyes ");
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert!(p.menu.is_some());
        typed(&mut p, "a");
        assert!(p.menu.is_none());
        p.on_key(&key(KeyCode::Tab), &c, &h);
        assert_eq!(
            p.line.text(),
            "set-shape eyes ada=",
            "no space after SOURCE="
        );
    }

    #[test]
    fn history_browses_by_prefix_and_persists() {
        let file = std::env::temp_dir().join(format!("visage-history-{}", std::process::id()));
        std::fs::remove_file(&file).ok();
        let mut h = History::load(Some(file.clone()));
        for line in [
            "orbit 10 0",
            "set-base bram",
            "orbit 0 5",
            "orbit 0 5",
            "undo",
        ] {
            h.push(line);
        }
        let h = History::load(Some(file.clone()));
        assert_eq!(
            h.entries(),
            ["orbit 10 0", "set-base bram", "orbit 0 5", "undo"]
        );
        let c = catalog();
        let mut p = Prompt::new();
        p.on_key(&key(KeyCode::Up), &c, &h);
        assert_eq!(p.line.text(), "undo");
        let mut p = Prompt::new();
        typed(&mut p, "orb");
        p.on_key(&key(KeyCode::Up), &c, &h);
        assert_eq!(p.line.text(), "orbit 0 5");
        p.on_key(&key(KeyCode::Up), &c, &h);
        assert_eq!(p.line.text(), "orbit 10 0");
        p.on_key(&key(KeyCode::Up), &c, &h);
        assert_eq!(p.line.text(), "orbit 10 0", "no older match");
        p.on_key(&key(KeyCode::Down), &c, &h);
        assert_eq!(p.line.text(), "orbit 0 5");
        p.on_key(&key(KeyCode::Down), &c, &h);
        assert_eq!(p.line.text(), "orb", "back to what was typed");
        std::fs::remove_file(&file).ok();
    }
}
