//! The view: state → cells. Layout: source strip on top, viewport and the
//! composite panel (groups, post-processing, animation, camera, debug, info) in
//! the middle, status or prompt line at the bottom; a help overlay generated from
//! the keymap. Pure: it draws what it is given and changes nothing.

use ratatui::layout::{Constraint, Direction, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Borders, Clear, Paragraph, Wrap};
use ratatui::Frame;

use super::graphics::{draw_halfblocks, reserve_cells, Protocol};
use super::keymap::Keymap;
use crate::editor::state::{Catalog, EditorState, SceneSummary};
use crate::model::regions::Group;
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
    /// Encoding time of the last frame (ms).
    pub encode_ms: f64,
    /// Frames shown per second.
    pub fps: f64,
    /// Size of the last rendered image.
    pub image_size: (u32, u32),
    /// What renders.
    pub renderer: String,
}

/// Everything the view reads.
pub struct ViewModel<'a> {
    /// Editor state.
    pub state: &'a EditorState,
    /// Names.
    pub catalog: &'a Catalog,
    /// A colour per source (skin tone).
    pub swatches: &'a [[u8; 3]],
    /// Key bindings (for hints and help).
    pub keymap: &'a Keymap,
    /// Info panel figures.
    pub info: &'a InfoPanel,
    /// Graphics protocol in use.
    pub protocol: Protocol,
    /// The frame to draw as half-blocks (half-block protocol only).
    pub image: Option<&'a RgbImage>,
}

/// Areas of the layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Areas {
    /// Source strip.
    pub sources: Rect,
    /// Image viewport (inside its border).
    pub viewport: Rect,
    /// Composite panel.
    pub panel: Rect,
    /// Status line.
    pub status: Rect,
}

/// Splits the terminal; `None` when it is too small for the full layout.
pub fn layout(area: Rect) -> Option<Areas> {
    if area.width < MIN_SIZE.0 || area.height < MIN_SIZE.1 {
        return None;
    }
    let rows = Layout::default()
        .direction(Direction::Vertical)
        .constraints([
            Constraint::Length(3),
            Constraint::Min(8),
            Constraint::Length(1),
        ])
        .split(area);
    let panel_width = (area.width * 2 / 5).clamp(30, 46);
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

/// Draws the whole editor.
pub fn draw(frame: &mut Frame, vm: &ViewModel) {
    let area = frame.area();
    let Some(areas) = layout(area) else {
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
            draw_scene_panel(frame, areas.panel, scene, vm);
        }
        None => {
            draw_sources(frame, areas.sources, vm);
            draw_viewport(frame, areas, vm);
            draw_panel(frame, areas.panel, vm);
        }
    }
    draw_status(frame, areas.status, vm);
    if vm.state.help {
        draw_help(frame, area, vm.keymap, vm.catalog.scene.is_some());
    }
}

fn draw_sources(frame: &mut Frame, area: Rect, vm: &ViewModel) {
    let s = vm.state;
    let mut spans = Vec::new();
    for (i, name) in vm.catalog.sources.iter().enumerate() {
        let [r, g, b] = vm.swatches.get(i).copied().unwrap_or([128, 128, 128]);
        spans.push(Span::styled("█", Style::default().fg(Color::Rgb(r, g, b))));
        let mut style = Style::default();
        if i == s.source {
            style = style.add_modifier(Modifier::REVERSED | Modifier::BOLD);
        }
        let base = if *name == s.recipe.base { "*" } else { "" };
        spans.push(Span::styled(format!("{name}{base}"), style));
        spans.push(Span::raw(" "));
    }
    let block = Block::default()
        .borders(Borders::ALL)
        .title(" sources (←/→ select, enter assign, b base; * = base) ");
    frame.render_widget(Paragraph::new(Line::from(spans)).block(block), area);
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
        _ if vm.state.help => {}
        _ => reserve_cells(buf, areas.viewport),
    }
}

fn fmt_weights(shape: &std::collections::BTreeMap<String, f64>) -> String {
    let mut w: Vec<_> = shape.iter().filter(|(_, x)| **x > 0.0).collect();
    w.sort_by(|a, b| b.1.total_cmp(a.1));
    w.iter()
        .map(|(n, x)| format!("{} {:.2}", n, x))
        .collect::<Vec<_>>()
        .join(" ")
}

fn heading(text: &str) -> Line<'static> {
    Line::from(Span::styled(
        text.to_string(),
        Style::default()
            .add_modifier(Modifier::BOLD)
            .fg(Color::Cyan),
    ))
}

fn draw_panel(frame: &mut Frame, area: Rect, vm: &ViewModel) {
    let s = vm.state;
    let r = &s.recipe;
    let mut lines = vec![heading("groups (↑/↓)   gaussians  shape")];
    for (i, g) in Group::ALL.iter().enumerate() {
        let edit = s.group_edit(*g);
        let marker = if i == s.group { "▶" } else { " " };
        let style = if i == s.group {
            Style::default().add_modifier(Modifier::BOLD)
        } else {
            Style::default()
        };
        lines.push(Line::from(Span::styled(
            format!(
                "{marker}{:<6} {:<8} {}",
                g.name(),
                edit.gaussians,
                fmt_weights(&edit.shape)
            ),
            style,
        )));
    }
    let lower = |d: &dyn std::fmt::Debug| format!("{d:?}").to_lowercase();
    lines.push(heading("post"));
    lines.push(Line::raw(format!(
        " smoothing {}  colour {}  base {}",
        lower(&r.post.smoothing),
        lower(&r.post.colour),
        r.base
    )));
    lines.push(heading("animation"));
    let frames = vm.catalog.frames(&r.animation.motion);
    lines.push(Line::raw(format!(
        " {} {} {}/{}  {}",
        if s.playing { "▶" } else { "⏸" },
        r.animation.motion,
        r.animation.frame,
        frames,
        lower(&r.animation.mode)
    )));
    let o = &r.animation.offsets;
    lines.push(Line::raw(format!(
        " jaw {:.2} neck {:.2} eyes {:.2} expr {}",
        o.jaw[0],
        o.neck[1],
        o.eyes[1],
        o.expression
            .iter()
            .map(|e| format!("{e:.2}"))
            .collect::<Vec<_>>()
            .join(",")
    )));
    lines.push(heading("camera"));
    let c = &r.camera;
    lines.push(Line::raw(format!(
        " yaw {:.0}° pitch {:.0}° r {:.2} fov {:.1}°{}",
        c.yaw_deg,
        c.pitch_deg,
        c.radius,
        c.fov_deg,
        if s.study { " study" } else { "" }
    )));
    lines.push(heading("debug"));
    lines.push(Line::raw(format!(
        " scale {:.2}  mesh {}  highlight {}",
        s.debug.scale,
        if s.debug.mesh { "on" } else { "off" },
        if s.debug.highlight { "on" } else { "off" }
    )));
    let i = vm.info;
    lines.push(heading("info"));
    lines.push(Line::raw(format!(
        " {} Gaussians ({} border extras)",
        i.gaussians, i.extras
    )));
    lines.push(Line::raw(format!(
        " compose {:.1} pose {:.1} render {:.1} enc {:.1} ms",
        i.timings.compose, i.timings.pose, i.timings.render, i.encode_ms
    )));
    let (undo, redo) = s.history();
    lines.push(Line::raw(format!(
        " {:.1} FPS  undo {undo} redo {redo}",
        i.fps
    )));
    lines.push(Line::raw(format!(" {}", i.renderer)));
    let block = Block::default().borders(Borders::ALL).title(" composite ");
    frame.render_widget(Paragraph::new(lines).block(block), area);
}

/// The scene viewer's top line: the file and the movement keys.
fn draw_scene_title(frame: &mut Frame, area: Rect, scene: &SceneSummary, keymap: &Keymap) {
    let key = |line: &str| keymap.key_for(line).unwrap_or_else(|| "-".into());
    let hint = format!(
        " {}/{}/{}/{} fly, arrows look, {} SH, drag: orbit (left) look (right) pan (middle) ",
        key("fly 0.05 0 0"),
        key("fly 0 -0.05 0"),
        key("fly -0.05 0 0"),
        key("fly 0 0.05 0"),
        key("sh-degree"),
    );
    let block = Block::default()
        .borders(Borders::ALL)
        .title(format!(" {} ", scene.name));
    frame.render_widget(Paragraph::new(hint).block(block), area);
}

/// The scene viewer's panel: the scene, the camera, appearance and figures.
fn draw_scene_panel(frame: &mut Frame, area: Rect, scene: &SceneSummary, vm: &ViewModel) {
    let s = vm.state;
    let c = &s.recipe.camera;
    let i = vm.info;
    let [tx, ty, tz] = c.target;
    let visible = i.visible.map_or_else(|| "-".to_string(), |v| v.to_string());
    let lines = vec![
        heading("scene"),
        Line::raw(format!(" {} Gaussians", scene.gaussians)),
        Line::raw(format!(" SH degree {}", scene.sh_degree)),
        heading("camera"),
        Line::raw(format!(
            " yaw {:.0}° pitch {:.0}° fov {:.1}° up {}",
            c.yaw_deg,
            c.pitch_deg,
            c.fov_deg,
            c.up.name()
        )),
        Line::raw(format!(
            " r {:.3}  target {tx:.2},{ty:.2},{tz:.2}",
            c.radius
        )),
        heading("appearance"),
        Line::raw(format!(
            " SH {} of {}  scale {:.2}",
            s.debug.sh_degree.min(scene.sh_degree),
            scene.sh_degree,
            s.debug.scale
        )),
        heading("info"),
        Line::raw(format!(" {visible} of {} drawn", i.gaussians)),
        Line::raw(format!(
            " project {:.1} sort {:.1} raster {:.1} ms",
            i.stages.project, i.stages.sort, i.stages.rasterize
        )),
        Line::raw(format!(
            " render {:.1} enc {:.1} ms",
            i.timings.render, i.encode_ms
        )),
        Line::raw(format!(
            " {:.1} FPS at {}x{} px",
            i.fps, i.image_size.0, i.image_size.1
        )),
        Line::raw(format!(" {}", i.renderer)),
    ];
    let block = Block::default().borders(Borders::ALL).title(" scene ");
    frame.render_widget(Paragraph::new(lines).block(block), area);
}

fn draw_status(frame: &mut Frame, area: Rect, vm: &ViewModel) {
    let line = match &vm.state.prompt {
        Some(text) => Line::from(vec![
            Span::styled(":", Style::default().fg(Color::Yellow)),
            Span::raw(text.clone()),
            Span::raw("█"),
        ]),
        None => {
            let hint = format!(
                "{} help  {} command  {} quit",
                vm.keymap.key_for("help").unwrap_or_else(|| "?".into()),
                vm.keymap.key_for("prompt").unwrap_or_else(|| ":".into()),
                vm.keymap.key_for("quit").unwrap_or_else(|| "q".into())
            );
            let status = crate::text::printable(&vm.state.status);
            let room = (area.width as usize).saturating_sub(hint.len() + 2);
            let status: String = status.chars().take(room).collect();
            Line::from(vec![
                Span::raw(format!("{status:<room$}")),
                Span::styled(hint, Style::default().fg(Color::DarkGray)),
            ])
        }
    };
    frame.render_widget(Paragraph::new(line), area);
}

/// The help overlay: every binding of the keymap, in columns.
fn draw_help(frame: &mut Frame, area: Rect, keymap: &Keymap, scene: bool) {
    let popup = Rect {
        x: area.x + 2,
        y: area.y + 1,
        width: area.width.saturating_sub(4),
        height: area.height.saturating_sub(2),
    };
    let mut entries: Vec<String> = keymap
        .bindings()
        .map(|(k, c)| format!("{k:>11}  {c}"))
        .collect();
    // Commands without a key, from the command table: typed at the `:` prompt.
    let bound: Vec<&str> = keymap
        .bindings()
        .filter_map(|(_, line)| line.split_whitespace().next())
        .collect();
    entries.extend(
        crate::editor::command::COMMANDS
            .iter()
            .filter(|c| !(bound.contains(&c.name) || scene && c.avatar))
            .map(|c| format!("{:>11}  {} {}", ":", c.name, c.synopsis)),
    );
    let inner_h = popup.height.saturating_sub(2).max(1) as usize;
    let col_w = 36usize;
    let cols = ((popup.width.saturating_sub(2)) as usize / col_w).max(1);
    let mut lines = Vec::new();
    for row in 0..inner_h {
        let mut text = String::new();
        for col in 0..cols {
            if let Some(e) = entries.get(col * inner_h + row) {
                let cell: String = e.chars().take(col_w - 1).collect();
                text.push_str(&format!("{cell:<col_w$}"));
            }
        }
        lines.push(Line::raw(text));
    }
    frame.render_widget(Clear, popup);
    let block = Block::default()
        .borders(Borders::ALL)
        .title(" keys (from the keymap; ? closes, : runs any command) ");
    frame.render_widget(Paragraph::new(lines).block(block), popup);
}
