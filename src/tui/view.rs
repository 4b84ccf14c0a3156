//! The view: state → cells. Layout: source strip on top (thumbnails on
//! graphics terminals, swatches in half-blocks; it scrolls to keep the
//! selection visible), viewport and the composite panel (groups,
//! post-processing, animation, camera, debug, info — wrapped to the panel's
//! width, headings folded in when rows are short) in the middle, and the
//! status line or the `:` prompt at the bottom, with the completion menu just
//! above it. Pure: it draws what it is given and changes nothing.

use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Paragraph, Wrap};
use ratatui::Frame;

use super::graphics::{draw_halfblocks, reserve_cells, Protocol};
use super::keymap::Keymap;
use super::prompt::Prompt;
use crate::compose::recipe::{PostPreset, Recipe};
use crate::editor::state::{Catalog, EditorState, SceneSummary};
use crate::model::regions::Group;
use crate::pipeline::composer::FitProgress;
use crate::pipeline::workbench::FrameTimings;
use crate::render::image::RgbImage;

/// Smallest terminal the full layout needs.
pub const MIN_SIZE: (u16, u16) = (50, 14);

/// Figures for the info panel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InfoPanel {
    /// Gaussians in the composite or scene.
    pub gaussians: usize,
    /// Gaussians drawn after culling, where the renderer counts them.
    pub visible: Option<usize>,
    /// The renderer's stage timings.
    pub stages: crate::render::settings::StageTimings,
    /// Border extras among them.
    pub extras: usize,
    /// Timings of the last frame.
    pub timings: FrameTimings,
    /// Milliseconds the last change of the composite took to compose (frames
    /// that change nothing compose nothing).
    pub last_compose: f64,
    /// Encoding time of the last frame (ms).
    pub encode_ms: f64,
    /// Frames shown per second.
    pub fps: f64,
    /// Size of the last rendered image.
    pub image_size: (u32, u32),
    /// What renders.
    pub renderer: String,
    /// What a scene's level of detail drew, when it drew a cut.
    pub lod: Option<crate::pipeline::lod::CutSummary>,
    /// How far the seam fit running in the background is (`None`: not
    /// running).
    pub fit: Option<FitProgress>,
}

/// What the layout depends on besides the terminal's size.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Screen {
    /// Source thumbnails shown, each this many cells (columns, rows).
    pub thumbnails: Option<(u16, u16)>,
}

/// Everything the view reads.
pub struct ViewModel<'a> {
    /// Editor state.
    pub state: &'a EditorState,
    /// Names.
    pub catalog: &'a Catalog,
    /// A colour per source (skin tone).
    pub swatches: &'a [[u8; 3]],
    /// Key bindings (for hints).
    pub keymap: &'a Keymap,
    /// Info panel figures.
    pub info: &'a InfoPanel,
    /// Graphics protocol in use.
    pub protocol: Protocol,
    /// The frame to draw as half-blocks (half-block protocol only).
    pub image: Option<&'a RgbImage>,
    /// The status line.
    pub status: &'a str,
    /// The `:` prompt, when open.
    pub prompt: Option<&'a Prompt>,
    /// Layout choices.
    pub screen: Screen,
    /// An overlay (the help) covers the screen: leave image cells to it.
    pub overlay: bool,
    /// The journal being written.
    pub journal: Option<&'a std::path::Path>,
}

/// Areas of the layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Areas {
    /// Source strip (with its border).
    pub sources: Rect,
    /// Image viewport (inside its border).
    pub viewport: Rect,
    /// Composite panel.
    pub panel: Rect,
    /// Status line.
    pub status: Rect,
}

/// Splits the terminal; `None` when it is too small for the full layout.
pub fn layout(area: Rect, screen: Screen) -> Option<Areas> {
    if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
        return None;
    }
    let strip = 2 + screen.thumbnails.map_or(1, |(_, rows)| rows + 1);
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(strip),
            Constraint::Min(8),
            Constraint::Length(1),
        ])
        .split(area);
    let panel_width = panel_width(area.width);
    let cols = Layout::default()
        .direction(Direction::Horizontal)
        .constraints([Constraint::Min(20), Constraint::Length(panel_width)])
        .split(rows[1]);
    let viewport = Block::default().borders(Borders::ALL).inner(cols[0]);
    Some(Areas {
        sources: rows[0],
        viewport,
        panel: cols[1],
        status: rows[2],
    })
}

/// The panel's width: nine twentieths of the terminal between 34 and 52
/// columns (36 at 80).
fn panel_width(terminal: u16) -> u16 {
    (terminal * 9 / 20).clamp(34, 52)
}

/// Draws the whole editor.
pub fn draw(frame: &mut Frame, vm: &ViewModel) {
    let area = frame.area();
    let Some(areas) = layout(area, vm.screen) else {
        let msg = format!(
            "visage needs at least {}x{} cells (this is {}x{}); q quits",
            MIN_SIZE.0, MIN_SIZE.1, area.width, area.height
        );
        frame.render_widget(Paragraph::new(msg).wrap(Wrap { trim: true }), area);
        return;
    };
    match &vm.catalog.scene {
        Some(scene) => {
            draw_scene_title(frame, areas.sources, scene, vm.keymap);
            draw_viewport(frame, areas, vm);
            draw_panel(frame, areas.panel, " scene ", scene_sections(scene, vm));
        }
        None => {
            draw_sources(frame, areas.sources, vm);
            draw_viewport(frame, areas, vm);
            draw_panel(frame, areas.panel, " composite ", composite_sections(vm));
        }
    }
    draw_status(frame, areas.status, vm);
    if let Some(menu) = vm.prompt.and_then(|p| p.menu.as_ref()) {
        let row = Rect::new(area.x, areas.status.y.saturating_sub(1), area.width, 1);
        draw_menu(frame, row, &menu.candidates, menu.selected);
    }
}

/// Each source's slot in the strip: its width in cells.
fn slot_width(name: &str, thumbnails: Option<(u16, u16)>) -> u16 {
    let label = name.chars().count() as u16 + 1; // the base's `*`
    match thumbnails {
        Some((cols, _)) => label.max(cols) + 1,
        None => label + 2, // swatch and a gap
    }
}

/// The sources shown in a strip `inner_width` wide so that `selected` is
/// visible: the first shown and one past the last.
fn strip_window(widths: &[u16], selected: usize, inner_width: u16) -> (usize, usize) {
    let room = inner_width.saturating_sub(2); // the ‹ › markers
    let fits = |from: usize, to: usize| {
        widths[from..to].iter().map(|w| *w as u32).sum::<u32>() <= room as u32
    };
    let selected = selected.min(widths.len().saturating_sub(1));
    let mut start = 0;
    while start < selected && !fits(start, selected + 1) {
        start += 1;
    }
    let mut end = start;
    while end < widths.len() && fits(start, end + 1) {
        end += 1;
    }
    (start, end.max((start + 1).min(widths.len())))
}

/// Where each visible source's thumbnail goes, as (source index, cells).
pub fn source_slots(
    strip: Rect,
    names: &[String],
    selected: usize,
    thumbnails: Option<(u16, u16)>,
) -> Vec<(usize, Rect)> {
    let Some((cols, rows)) = thumbnails else {
        return Vec::new();
    };
    let inner = Block::default().borders(Borders::ALL).inner(strip);
    let widths: Vec<u16> = names.iter().map(|n| slot_width(n, thumbnails)).collect();
    let (start, end) = strip_window(&widths, selected, inner.width);
    let mut x = inner.x + 1;
    let mut out = Vec::new();
    for (i, width) in widths.iter().enumerate().take(end).skip(start) {
        let cells = Rect::new(x, inner.y, cols.min(inner.width), rows.min(inner.height));
        out.push((i, cells));
        x += width;
    }
    out
}

fn draw_sources(frame: &mut Frame, area: Rect, vm: &ViewModel) {
    let s = vm.state;
    let names = &vm.catalog.sources;
    let thumbs = vm.screen.thumbnails;
    let inner = Block::default().borders(Borders::ALL).inner(area);
    let widths: Vec<u16> = names.iter().map(|n| slot_width(n, thumbs)).collect();
    let (start, end) = strip_window(&widths, s.source, inner.width);
    let mut spans = vec![Span::raw(if start > 0 { "‹" } else { " " })];
    for (i, name) in names.iter().enumerate().take(end).skip(start) {
        let mut style = Style::default();
        if i == s.source {
            style = style.add_modifier(Modifier::REVERSED | Modifier::BOLD);
        }
        let base = if *name == s.recipe.base { "*" } else { "" };
        let label = format!("{name}{base}");
        if thumbs.is_none() {
            let [r, g, b] = vm.swatches.get(i).copied().unwrap_or([128, 128, 128]);
            spans.push(Span::styled("█", Style::default().fg(Color::Rgb(r, g, b))));
        }
        let pad = (widths[i] as usize)
            .saturating_sub(label.chars().count() + usize::from(thumbs.is_none()));
        spans.push(Span::styled(label, style));
        spans.push(Span::raw(" ".repeat(pad)));
    }
    if end < names.len() {
        spans.push(Span::raw("›"));
    }
    let title = if area.width >= 64 {
        " sources (←/→ select, enter assign, b base; * = base) "
    } else {
        " sources (* = base) "
    };
    let block = Block::default().borders(Borders::ALL).title(title);
    frame.render_widget(block, area);
    let name_row = Rect::new(inner.x, inner.bottom().saturating_sub(1), inner.width, 1);
    frame.render_widget(Paragraph::new(Line::from(spans)), name_row);
    if let Some((cols, rows)) = thumbs {
        if !vm.overlay {
            for (_, slot) in source_slots(area, names, s.source, Some((cols, rows))) {
                reserve_cells(frame.buffer_mut(), slot);
            }
        }
    }
}

fn draw_viewport(frame: &mut Frame, areas: Areas, vm: &ViewModel) {
    let outer = Rect {
        x: areas.viewport.x - 1,
        y: areas.viewport.y - 1,
        width: areas.viewport.width + 2,
        height: areas.viewport.height + 2,
    };
    let title = format!(
        " view {}x{} px, {} ",
        vm.info.image_size.0,
        vm.info.image_size.1,
        vm.protocol.name()
    );
    frame.render_widget(Block::default().borders(Borders::ALL).title(title), outer);
    let buf = frame.buffer_mut();
    match (vm.protocol, vm.image) {
        (Protocol::Halfblocks, Some(img)) => draw_halfblocks(buf, areas.viewport, img),
        (Protocol::Halfblocks, None) => {}
        _ if vm.overlay => {}
        _ => reserve_cells(buf, areas.viewport),
    }
}

/// A weight as a person would write it: at most three decimals, no
/// trailing zeros (0.3, 0.333, 1).
pub fn weight_text(w: f64) -> String {
    let s = format!("{w:.3}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-" {
        "0".into()
    } else {
        s.to_string()
    }
}

fn fmt_weights(shape: &std::collections::BTreeMap<String, f64>) -> String {
    let mut w: Vec<_> = shape.iter().filter(|(_, x)| **x > 0.0).collect();
    w.sort_by(|a, b| b.1.total_cmp(a.1));
    w.iter()
        .map(|(n, x)| format!("{}\u{a0}{}", n, weight_text(**x)))
        .collect::<Vec<_>>()
        .join(" ")
}

/// A part of a panel: a heading and its lines (each wrapped to the width).
struct Section {
    title: String,
    lines: Vec<(String, Style)>,
}

fn section(title: &str, lines: Vec<String>) -> Section {
    Section {
        title: title.to_string(),
        lines: lines.into_iter().map(|l| (l, Style::default())).collect(),
    }
}

/// Greedy word wrap to `width` columns, keeping the text's own spacing
/// within a line; continuation lines are indented; a word longer than a
/// line is cut with `…`. Words joined by a no-break space stay together.
fn wrap(text: &str, width: usize, indent: usize) -> Vec<String> {
    let width = width.max(indent + 4);
    if text.chars().count() <= width {
        return vec![text.to_string()];
    }
    // (spaces before, word) pairs.
    let mut words: Vec<(usize, &str)> = Vec::new();
    let mut rest = text;
    while !rest.is_empty() {
        let spaces = rest.len() - rest.trim_start_matches(' ').len();
        rest = &rest[spaces..];
        let end = rest.find(' ').unwrap_or(rest.len());
        if end > 0 {
            words.push((spaces, &rest[..end]));
        }
        rest = &rest[end..];
    }
    let mut lines = Vec::new();
    let mut line = String::new();
    let mut has_word = false;
    for (spaces, word) in words {
        let word_len = word.chars().count();
        if has_word && line.chars().count() + spaces + word_len > width {
            lines.push(std::mem::replace(&mut line, " ".repeat(indent)));
            has_word = false;
        }
        if has_word || lines.is_empty() {
            line.push_str(&" ".repeat(spaces));
        }
        let room = width.saturating_sub(line.chars().count());
        if word_len > room {
            line.extend(word.chars().take(room.saturating_sub(1)));
            line.push('…');
        } else {
            line.push_str(word);
        }
        has_word = true;
    }
    if has_word {
        lines.push(line);
    }
    lines
}

/// Draws sections into a bordered panel: headings on their own lines when
/// the rows allow, left out otherwise (the lines say what they are); what
/// still does not fit is cut, with a mark.
fn draw_panel(frame: &mut Frame, area: Rect, title: &str, sections: Vec<Section>) {
    let inner = Block::default().borders(Borders::ALL).inner(area);
    let (width, height) = (inner.width as usize, inner.height as usize);
    let heading = Style::default()
        .add_modifier(Modifier::BOLD)
        .fg(Color::Cyan);
    let render = |headings: bool| -> Vec<Line<'static>> {
        let mut out = Vec::new();
        for s in &sections {
            // The groups' heading is their table's header: always shown.
            if headings || s.title.starts_with("groups") {
                out.push(Line::from(Span::styled(s.title.clone(), heading)));
            }
            for (text, style) in &s.lines {
                for part in wrap(text, width, 3) {
                    out.push(Line::from(Span::styled(part, *style)));
                }
            }
        }
        out
    };
    let mut lines = render(true);
    if lines.len() > height {
        lines = render(false);
    }
    if lines.len() > height && height > 0 {
        lines.truncate(height - 1);
        lines.push(Line::from(Span::styled(
            "… (taller terminal shows more)",
            Style::default().fg(Color::DarkGray),
        )));
    }
    let block = Block::default()
        .borders(Borders::ALL)
        .title(title.to_string());
    frame.render_widget(Paragraph::new(lines).block(block), area);
}

fn composite_sections(vm: &ViewModel) -> Vec<Section> {
    let s = vm.state;
    let r = &s.recipe;
    let source_width = Group::ALL
        .iter()
        .map(|g| s.group_edit(*g).gaussians.chars().count())
        .max()
        .unwrap_or(4)
        .max(5);
    let mut groups = Section {
        title: format!("groups  {:<source_width$} shape", "splats"),
        lines: Vec::new(),
    };
    for (i, g) in Group::ALL.iter().enumerate() {
        let edit = s.group_edit(*g);
        let selected = i == s.group;
        let marker = if selected { "▶" } else { " " };
        let style = if selected {
            Style::default().add_modifier(Modifier::BOLD)
        } else {
            Style::default()
        };
        groups.lines.push((
            format!(
                "{marker}{:<6} {:<source_width$} {}",
                g.name(),
                edit.gaussians,
                fmt_weights(&edit.shape)
            ),
            style,
        ));
    }
    let lower = |d: &dyn std::fmt::Debug| format!("{d:?}").to_lowercase();
    let frames = vm.catalog.frames(&r.animation.motion);
    let o = &r.animation.offsets;
    let c = &r.camera;
    let i = vm.info;
    let (undo, redo) = s.history();
    vec![
        groups,
        section("post", vec![post_text(r, i.fit)]),
        section(
            "animation",
            vec![
                format!(
                    " {} {} {}/{} {}",
                    if s.playing { "▶" } else { "⏸" },
                    r.animation.motion,
                    r.animation.frame,
                    frames,
                    lower(&r.animation.mode)
                ),
                format!(
                    " jaw {} neck {} eyes {} expr {}",
                    weight_text(o.jaw[0] as f64),
                    weight_text(o.neck[1] as f64),
                    weight_text(o.eyes[1] as f64),
                    if o.expression.iter().all(|e| *e == 0.0) {
                        "0".to_string()
                    } else {
                        o.expression
                            .iter()
                            .map(|e| weight_text(*e as f64))
                            .collect::<Vec<_>>()
                            .join(",")
                    }
                ),
            ],
        ),
        section(
            "camera",
            vec![format!(
                " yaw {:.0}° pitch {:.0}° r {} fov {}°{}",
                c.yaw_deg,
                c.pitch_deg,
                weight_text(c.radius as f64),
                weight_text(c.fov_deg as f64),
                if s.study { " study" } else { "" }
            )],
        ),
        section(
            "debug",
            vec![format!(
                " scale {} mesh {} highlight {}",
                weight_text(s.debug.scale as f64),
                on_off(s.debug.mesh),
                on_off(s.debug.highlight)
            )],
        ),
        section(
            "info",
            vec![
                format!(" {} Gaussians, {} border extras", i.gaussians, i.extras),
                format!(
                    " compose {:.1} pose {:.1} render {:.1} enc {:.1} ms",
                    i.last_compose, i.timings.pose, i.timings.render, i.encode_ms
                ),
                format!(" {:.1} FPS undo {undo} redo {redo}", i.fps),
                format!(" {}", i.renderer),
            ],
        ),
    ]
}

fn on_off(b: bool) -> &'static str {
    if b {
        "on"
    } else {
        "off"
    }
}

/// The scene viewer's top line: the file and the movement keys.
fn draw_scene_title(frame: &mut Frame, area: Rect, scene: &SceneSummary, keymap: &Keymap) {
    let key = |line: &str| keymap.key_for(line).unwrap_or_else(|| "-".into());
    let hint = format!(
        " {}/{}/{}/{} fly, arrows look, {} SH, {} flips up, drag: orbit (left) look (right) pan (middle) ",
        key("fly 0.05 0 0"),
        key("fly 0 -0.05 0"),
        key("fly -0.05 0 0"),
        key("fly 0 0.05 0"),
        key("sh-degree"),
        key("flip-up"),
    );
    let block = Block::default()
        .borders(Borders::ALL)
        .title(format!(" {} ", scene.name));
    frame.render_widget(Paragraph::new(hint).block(block), area);
}

/// The scene viewer's panel: the scene, the camera, appearance and figures.
fn scene_sections(scene: &SceneSummary, vm: &ViewModel) -> Vec<Section> {
    let s = vm.state;
    let c = &s.recipe.camera;
    let i = vm.info;
    let [tx, ty, tz] = c.target;
    let visible = i.visible.map_or_else(|| "-".to_string(), |v| v.to_string());
    vec![
        section(
            "scene",
            vec![format!(
                " {} Gaussians SH degree {}",
                scene.gaussians, scene.sh_degree
            )],
        ),
        section(
            "camera",
            vec![
                format!(
                    " yaw {:.0}° pitch {:.0}° fov {:.1}° up {}",
                    c.yaw_deg,
                    c.pitch_deg,
                    c.fov_deg,
                    c.up.name()
                ),
                format!(" r {:.3} target {tx:.2},{ty:.2},{tz:.2}", c.radius),
                format!(" opened {} ({})", scene.home.up.name(), scene.up_reason),
            ],
        ),
        section(
            "appearance",
            vec![format!(
                " SH {} of {} scale {:.2} floaters {}",
                s.debug.sh_degree.min(scene.sh_degree),
                scene.sh_degree,
                s.debug.scale,
                if s.debug.hide_floaters {
                    "hidden"
                } else {
                    "shown"
                }
            )],
        ),
        section(
            "info",
            vec![
                format!(" {visible} of {} drawn", i.gaussians),
                match i.lod {
                    Some(cut) if cut.on_gpu => format!(
                        " LOD {} {} nodes, cut on the GPU",
                        s.debug.lod.label(),
                        cut.drawn
                    ),
                    Some(cut) => format!(
                        " LOD {} {} nodes, levels {}-{}",
                        s.debug.lod.label(),
                        cut.drawn,
                        cut.levels.0,
                        cut.levels.1
                    ),
                    None => format!(" LOD {}: every Gaussian", s.debug.lod.label()),
                },
                format!(
                    " project {:.1} sort {:.1} raster {:.1} ms",
                    i.stages.project, i.stages.sort, i.stages.rasterize
                ),
                format!(" render {:.1} enc {:.1} ms", i.timings.render, i.encode_ms),
                format!(
                    " {:.1} FPS at {}x{} px",
                    i.fps, i.image_size.0, i.image_size.1
                ),
                format!(" {}", i.renderer),
            ],
        ),
    ]
}

fn draw_status(frame: &mut Frame, area: Rect, vm: &ViewModel) {
    let line = match vm.prompt {
        Some(prompt) => prompt_line(prompt, area.width as usize),
        None => {
            let hint = format!(
                "{} help  {} command  {} quit",
                vm.keymap.key_for("help").unwrap_or_else(|| "?".into()),
                vm.keymap.key_for("prompt").unwrap_or_else(|| ":".into()),
                vm.keymap.key_for("quit").unwrap_or_else(|| "q".into())
            );
            let status = crate::text::printable(vm.status);
            let width = area.width as usize;
            let hint = if status.chars().count() + hint.len() + 2 > width {
                String::new()
            } else {
                hint
            };
            let room = width.saturating_sub(hint.len());
            let status: String = if status.chars().count() > room {
                let mut cut: String = status.chars().take(room.saturating_sub(1)).collect();
                cut.push('…');
                cut
            } else {
                status
            };
            Line::from(vec![
                Span::raw(format!("{status:<room$}")),
                Span::styled(hint, Style::default().fg(Color::DarkGray)),
            ])
        }
    };
    frame.render_widget(Paragraph::new(line), area);
}

/// The prompt's line: `:` and the text, scrolled so the cursor shows, the
/// cursor as a reversed cell.
fn prompt_line(prompt: &Prompt, width: usize) -> Line<'static> {
    let text: Vec<char> = crate::text::printable(&prompt.line.text())
        .chars()
        .collect();
    let cursor = prompt.line.cursor().min(text.len());
    let room = width.saturating_sub(2).max(1);
    let start = (cursor + 1).saturating_sub(room);
    let shown: Vec<char> = text.iter().skip(start).take(room).copied().collect();
    let at = cursor - start;
    let before: String = shown[..at.min(shown.len())].iter().collect();
    let under: String = shown.get(at).map_or(" ".into(), |c| c.to_string());
    let after: String = shown.iter().skip(at + 1).collect();
    Line::from(vec![
        Span::styled(
            if start > 0 { "…" } else { ":" },
            Style::default().fg(Color::Yellow),
        ),
        Span::raw(before),
        Span::styled(under, Style::default().add_modifier(Modifier::REVERSED)),
        Span::raw(after),
    ])
}

/// The completion menu: the candidates on one line, the chosen one
/// reversed, scrolled so it shows, with a count when they do not all fit.
fn draw_menu(frame: &mut Frame, row: Rect, candidates: &[String], selected: Option<usize>) {
    let width = row.width as usize;
    let count = format!(" {}/{} ", selected.map_or(0, |s| s + 1), candidates.len());
    let room = width.saturating_sub(count.len());
    let widths: Vec<usize> = candidates.iter().map(|c| c.chars().count() + 2).collect();
    let target = selected.unwrap_or(0);
    let mut start = 0;
    while start < target && widths[start..=target].iter().sum::<usize>() > room {
        start += 1;
    }
    let mut spans = Vec::new();
    let mut used = 0;
    for (i, c) in candidates.iter().enumerate().skip(start) {
        if used + widths[i] > room {
            break;
        }
        used += widths[i];
        let style = if Some(i) == selected {
            Style::default().add_modifier(Modifier::REVERSED | Modifier::BOLD)
        } else {
            Style::default().fg(Color::White)
        };
        spans.push(Span::styled(format!(" {c} "), style));
    }
    spans.push(Span::raw(" ".repeat(room.saturating_sub(used))));
    spans.push(Span::styled(count, Style::default().fg(Color::DarkGray)));
    frame.render_widget(
        Paragraph::new(Line::from(spans)).style(Style::default().bg(Color::Rgb(40, 40, 48))),
        row,
    );
}

/// The post panel's line: the base, and the post-processing by its
/// preset's name where it is one (the full list otherwise), with the seam
/// fit's progress while it runs.
fn post_text(r: &Recipe, fit: Option<FitProgress>) -> String {
    let lower = |d: &dyn std::fmt::Debug| format!("{d:?}").to_lowercase();
    let running = match (r.post.fit, fit) {
        (crate::compose::recipe::Fit::Seams, Some(p)) => {
            format!(" (fit {}%)", 100 * p.done / p.total.max(1))
        }
        _ => String::new(),
    };
    if let Some(preset) = PostPreset::ALL.into_iter().find(|p| p.post() == r.post) {
        return format!(" base {} post {}{running}", r.base, preset.name());
    }
    format!(
        " base {} smoothing {} colour {} regions by {} deform {} anchor {} shading {} skin {} fit {}{running}",
        r.base,
        lower(&r.post.smoothing),
        lower(&r.post.colour),
        lower(&r.post.membership),
        lower(&r.post.deform),
        lower(&r.post.anchor),
        lower(&r.post.shading),
        lower(&r.post.skin),
        lower(&r.post.fit),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_print_as_typed() {
        assert_eq!(weight_text(0.1 + 0.2), "0.3");
        assert_eq!(weight_text(1.0), "1");
        assert_eq!(weight_text(1.0 / 3.0), "0.333");
        assert_eq!(weight_text(0.0), "0");
    }

    #[test]
    fn a_running_seam_fit_keeps_the_post_line_on_one_line_at_80_columns() {
        let mut recipe = Recipe::from_toml("base = \"cleo\"").unwrap();
        recipe.post = crate::compose::recipe::PostProcess::BEST;
        let fit = FitProgress {
            done: 99,
            total: 100,
        };
        let line = post_text(&recipe, Some(fit));
        assert_eq!(line, " base cleo post ours (fit 99%)");
        // The panel's inside: its width less the two borders.
        let inside = usize::from(panel_width(80)) - 2;
        assert_eq!(wrap(&line, inside, 3), vec![line.as_str()]);
        // Done, or no fit in the recipe: no progress shown.
        assert_eq!(post_text(&recipe, None), " base cleo post ours");
    }

    #[test]
    fn wrapping_keeps_words_and_indents() {
        assert_eq!(
            wrap(" smoothing crossfade colour skin base ada", 20, 3),
            [" smoothing crossfade", "   colour skin base", "   ada"]
        );
        assert_eq!(
            wrap(" eyes   ada   cleo\u{a0}0.7 bram\u{a0}0.2", 24, 3),
            [" eyes   ada   cleo\u{a0}0.7", "   bram\u{a0}0.2"],
            "column spacing kept, pairs kept together"
        );
        assert_eq!(wrap("short", 20, 3), ["short"]);
        assert_eq!(wrap("averyveryverylongword", 10, 3), ["averyvery…"]);
    }

    #[test]
    fn the_strip_scrolls_to_keep_the_selection_visible() {
        let widths = [6u16; 14];
        assert_eq!(strip_window(&widths, 0, 40), (0, 6));
        let (start, end) = strip_window(&widths, 13, 40);
        assert!(start <= 13 && end == 14, "{start}..{end}");
        let (start, end) = strip_window(&widths, 7, 40);
        assert!(start <= 7 && 7 < end, "{start}..{end}");
        assert_eq!(strip_window(&widths, 3, 200), (0, 14));
    }
}
