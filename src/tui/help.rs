//! The help overlay: every key binding and command, grouped by area of the
//! editor (from the command table), each with its line and a one-line
//! description, the mouse gestures, scrolling (j/k, ↑/↓, PageUp/PageDown,
//! g/G) and filtering by typing. It is modal: while it is open, keys go to it
//! and never to the editor behind.

use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use ratatui::layout::Rect;
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Clear, Paragraph};
use ratatui::Frame;

use super::keymap::Keymap;
use crate::editor::command::{Area, CommandSpec, COMMANDS};

/// One line of the help.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HelpRow {
    /// A section heading (area) rather than an entry.
    pub heading: bool,
    /// The keys (or `:` for the prompt, or a mouse gesture).
    pub keys: String,
    /// The command line the keys run, or the command's usage.
    pub command: String,
    /// What it does.
    pub summary: String,
}

impl HelpRow {
    fn heading(name: &str) -> Self {
        Self {
            heading: true,
            keys: String::new(),
            command: name.to_string(),
            summary: String::new(),
        }
    }

    fn entry(keys: String, command: String, summary: &str) -> Self {
        Self {
            heading: false,
            keys,
            command,
            summary: summary.to_string(),
        }
    }

    fn matches(&self, filter: &str) -> bool {
        let filter = filter.to_lowercase();
        [&self.keys, &self.command, &self.summary]
            .iter()
            .any(|t| t.to_lowercase().contains(&filter))
    }
}

/// Mouse gestures, as `on_mouse` maps them.
const MOUSE: [(&str, &str, &str); 4] = [
    ("left drag", "orbit", "orbit about the target"),
    ("right drag", "look", "turn the camera where it stands"),
    ("middle drag", "fly", "pan: move camera and target"),
    ("wheel", "zoom", "zoom in and out"),
];

/// Every binding and command by area, then the mouse; a scene view leaves
/// out the commands it refuses.
pub fn help_rows(keymap: &Keymap, scene: bool) -> Vec<HelpRow> {
    let bindings: Vec<(String, &str)> = keymap.bindings().collect();
    let mut rows = Vec::new();
    for area in Area::ALL {
        let commands: Vec<&CommandSpec> = COMMANDS
            .iter()
            .filter(|c| c.area == area && !(scene && c.avatar))
            .collect();
        if commands.is_empty() {
            continue;
        }
        rows.push(HelpRow::heading(area.name()));
        for spec in commands {
            rows.extend(command_rows(spec, &bindings));
        }
    }
    rows.push(HelpRow::heading("mouse"));
    for (gesture, command, summary) in MOUSE {
        rows.push(HelpRow::entry(gesture.into(), command.into(), summary));
    }
    rows
}

/// A command's rows: each distinct bound line with its keys, and its usage
/// at the prompt when it takes arguments or has no key.
fn command_rows(spec: &CommandSpec, bindings: &[(String, &str)]) -> Vec<HelpRow> {
    let mut lines: Vec<(&str, Vec<&str>)> = Vec::new();
    for (key, line) in bindings {
        let name = line.split_whitespace().next().unwrap_or("");
        if CommandSpec::find(name).is_some_and(|s| s.name == spec.name) {
            match lines.iter_mut().find(|(l, _)| l == line) {
                Some((_, keys)) => keys.push(key),
                None => lines.push((line, vec![key])),
            }
        }
    }
    let mut rows: Vec<HelpRow> = lines
        .iter()
        .map(|(line, keys)| HelpRow::entry(keys.join(" "), line.to_string(), spec.summary))
        .collect();
    if rows.is_empty() || !spec.synopsis.is_empty() {
        rows.push(HelpRow::entry(":".into(), spec.usage(), spec.summary));
    }
    rows
}

/// The overlay's state: scroll position and filter.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct HelpOverlay {
    /// First row shown.
    pub scroll: usize,
    /// Rows must contain this (case-insensitive).
    pub filter: String,
    /// Typing goes to the filter.
    pub filtering: bool,
}

/// What a key did to the overlay.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HelpOutcome {
    /// The overlay stays.
    Stay,
    /// The overlay closes.
    Close,
}

impl HelpOverlay {
    /// The help opened on a filter (e.g. `help set-shape`).
    pub fn filtered(filter: &str) -> Self {
        Self {
            filter: filter.to_string(),
            ..Self::default()
        }
    }

    /// The rows the filter lets through, headings kept where their section
    /// has a match.
    pub fn visible(&self, rows: &[HelpRow]) -> Vec<HelpRow> {
        if self.filter.is_empty() {
            return rows.to_vec();
        }
        let mut out = Vec::new();
        let mut heading: Option<&HelpRow> = None;
        for row in rows {
            if row.heading {
                heading = Some(row);
            } else if row.matches(&self.filter) {
                if let Some(h) = heading.take() {
                    out.push(h.clone());
                }
                out.push(row.clone());
            }
        }
        out
    }

    /// Handles a key; `page` is the number of rows on screen.
    pub fn on_key(&mut self, key: &KeyEvent, page: usize) -> HelpOutcome {
        let ctrl = key.modifiers.contains(KeyModifiers::CONTROL);
        let page = page.max(1);
        match key.code {
            KeyCode::Down => self.scroll += 1,
            KeyCode::Up => self.scroll = self.scroll.saturating_sub(1),
            KeyCode::PageDown => self.scroll += page,
            KeyCode::PageUp => self.scroll = self.scroll.saturating_sub(page),
            KeyCode::Home => self.scroll = 0,
            KeyCode::End => self.scroll = usize::MAX,
            KeyCode::Char('c') if ctrl => return HelpOutcome::Close,
            KeyCode::Char('d') if ctrl => self.scroll += page / 2,
            KeyCode::Char('u') if ctrl => self.scroll = self.scroll.saturating_sub(page / 2),
            KeyCode::Esc if self.filtering || !self.filter.is_empty() => {
                self.filter.clear();
                self.filtering = false;
                self.scroll = 0;
            }
            KeyCode::Esc => return HelpOutcome::Close,
            KeyCode::Enter if self.filtering => self.filtering = false,
            KeyCode::Backspace if self.filtering => {
                self.filter.pop();
                self.filtering = !self.filter.is_empty();
                self.scroll = 0;
            }
            KeyCode::Char(c) if self.filtering && !ctrl && !c.is_control() => {
                self.filter.push(c);
                self.scroll = 0;
            }
            KeyCode::Char('j') => self.scroll += 1,
            KeyCode::Char('k') => self.scroll = self.scroll.saturating_sub(1),
            KeyCode::Char(' ') => self.scroll += page,
            KeyCode::Char('g') => self.scroll = 0,
            KeyCode::Char('G') => self.scroll = usize::MAX,
            KeyCode::Char('q' | '?') => return HelpOutcome::Close,
            KeyCode::Char('/') => {
                self.filtering = true;
                self.filter.clear();
            }
            KeyCode::Char(c) if !ctrl && !c.is_control() => {
                self.filtering = true;
                self.filter = c.to_string();
                self.scroll = 0;
            }
            _ => {}
        }
        HelpOutcome::Stay
    }
}

/// The rows of the overlay that fit on screen at once.
pub fn help_page(area: Rect) -> usize {
    help_area(area).height.saturating_sub(3) as usize
}

fn help_area(area: Rect) -> Rect {
    let margin_x = if area.width >= 100 { 4 } else { 1 };
    Rect {
        x: area.x + margin_x,
        y: area.y + 1,
        width: area.width.saturating_sub(2 * margin_x),
        height: area.height.saturating_sub(2),
    }
}

/// Cuts text to `width` characters, marking a cut with `…`.
fn fit(text: &str, width: usize) -> String {
    if text.chars().count() <= width {
        return format!("{text:<width$}");
    }
    let mut cut: String = text.chars().take(width.saturating_sub(1)).collect();
    cut.push('…');
    cut
}

/// Draws the overlay over `area`.
pub fn draw_help(frame: &mut Frame, area: Rect, overlay: &mut HelpOverlay, rows: &[HelpRow]) {
    let popup = help_area(area);
    let shown = overlay.visible(rows);
    let page = help_page(area).max(1);
    let last_start = shown.len().saturating_sub(page);
    overlay.scroll = overlay.scroll.min(last_start);
    let inner_width = popup.width.saturating_sub(2) as usize;
    let widest = |f: fn(&HelpRow) -> usize| {
        shown
            .iter()
            .filter(|r| !r.heading)
            .map(f)
            .max()
            .unwrap_or(0)
    };
    let keys_w = widest(|r| r.keys.chars().count())
        .clamp(4, 18)
        .min(inner_width / 4);
    let command_w = widest(|r| r.command.chars().count())
        .clamp(8, 34)
        .min(inner_width * 2 / 5);
    let summary_w = inner_width.saturating_sub(keys_w + command_w + 4);
    let heading = Style::default()
        .fg(Color::Cyan)
        .add_modifier(Modifier::BOLD);
    let key_style = Style::default().fg(Color::Yellow);
    let mut lines: Vec<Line> = shown
        .iter()
        .skip(overlay.scroll)
        .take(page)
        .map(|r| {
            if r.heading {
                Line::from(Span::styled(r.command.clone(), heading))
            } else {
                Line::from(vec![
                    Span::styled(format!(" {} ", fit(&r.keys, keys_w)), key_style),
                    Span::raw(format!("{} ", fit(&r.command, command_w))),
                    Span::styled(fit(&r.summary, summary_w), Style::default().fg(Color::Gray)),
                ])
            }
        })
        .collect();
    if shown.is_empty() {
        lines.push(Line::raw(format!(" nothing matches '{}'", overlay.filter)));
    }
    let filter = if overlay.filtering {
        format!("filter: {}█", overlay.filter)
    } else if !overlay.filter.is_empty() {
        format!("filter: {} (esc clears)", overlay.filter)
    } else {
        "type to filter".to_string()
    };
    let position = format!(
        "{}-{} of {}",
        (overlay.scroll + 1).min(shown.len()),
        (overlay.scroll + page).min(shown.len()),
        shown.len()
    );
    lines.push(Line::from(Span::styled(
        fit(&format!(" {filter}   {position}"), inner_width),
        Style::default().fg(Color::DarkGray),
    )));
    frame.render_widget(Clear, popup);
    let title = if popup.width >= 60 {
        " help: j/k ↑/↓ PgUp/PgDn scroll, type to filter, esc closes "
    } else {
        " help (esc closes) "
    };
    let block = Block::default().borders(Borders::ALL).title(title);
    frame.render_widget(Paragraph::new(lines).block(block), popup);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(code: KeyCode) -> KeyEvent {
        KeyEvent::new(code, KeyModifiers::NONE)
    }

    #[test]
    fn rows_follow_the_areas_with_keys_and_usage() {
        let rows = help_rows(&Keymap::builtin(), false);
        let headings: Vec<&str> = rows
            .iter()
            .filter(|r| r.heading)
            .map(|r| r.command.as_str())
            .collect();
        assert_eq!(
            headings,
            [
                "editor",
                "selection",
                "shape",
                "post-processing",
                "animation",
                "camera",
                "files",
                "debug",
                "mouse"
            ]
        );
        let undo = rows.iter().find(|r| r.command == "undo").unwrap();
        assert!(
            undo.keys.contains('u') && undo.keys.contains("ctrl-z"),
            "{undo:?}"
        );
        assert!(rows
            .iter()
            .any(|r| r.keys == ":" && r.command == "set-shape GROUP SOURCE=W ..."));
        assert!(rows.iter().any(|r| r.keys == "left drag"));
        for spec in COMMANDS {
            assert!(
                rows.iter()
                    .any(|r| r.command.split(' ').next() == Some(spec.name)),
                "{} missing from the help",
                spec.name
            );
        }
        let scene = help_rows(&Keymap::builtin_viewer(), true);
        assert!(!scene.iter().any(|r| r.command.starts_with("set-gaussians")));
        assert!(scene.iter().any(|r| r.keys == "wheel"));
    }

    #[test]
    fn typing_filters_and_keys_scroll() {
        let rows = help_rows(&Keymap::builtin(), false);
        let mut h = HelpOverlay::default();
        for c in "smooth".chars() {
            assert_eq!(h.on_key(&key(KeyCode::Char(c)), 10), HelpOutcome::Stay);
        }
        let shown = h.visible(&rows);
        assert!(shown
            .iter()
            .any(|r| r.heading && r.command == "post-processing"));
        assert!(shown
            .iter()
            .filter(|r| !r.heading)
            .all(|r| r.matches("smooth")));
        h.on_key(&key(KeyCode::Enter), 10);
        assert_eq!(h.on_key(&key(KeyCode::Char('j')), 10), HelpOutcome::Stay);
        assert_eq!(h.scroll, 1, "j scrolls once the filter is typed");
        h.on_key(&key(KeyCode::Esc), 10);
        assert!(h.filter.is_empty());
        assert_eq!(h.on_key(&key(KeyCode::PageDown), 10), HelpOutcome::Stay);
        assert_eq!(h.scroll, 10);
        assert_eq!(h.on_key(&key(KeyCode::Esc), 10), HelpOutcome::Close);
        assert_eq!(
            HelpOverlay::default().on_key(&key(KeyCode::Char('?')), 10),
            HelpOutcome::Close
        );
    }
}
