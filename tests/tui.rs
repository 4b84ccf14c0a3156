//! The editor without a terminal: the view in a TestBackend (half-blocks),
//! sessions replayed twice, and the bytes the image encoders emit.

use std::io::Read;
use std::process::Command as Process;
use std::sync::{Mutex, OnceLock};

use base64::Engine as _;
use ratatui::backend::TestBackend;
use ratatui::style::Color;
use ratatui::Terminal;
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::engine::Engine;
use visage::editor::command::Command;
use visage::editor::replay::replay;
use visage::editor::state::{Catalog, EditorState};
use visage::editor::Editor;
use visage::model::builtin::build_head;
use visage::pipeline::workbench::{source_swatches, FrameRequest, Workbench};
use visage::render::image::{psnr, RgbImage};
use visage::render::Backend;
use visage::tui::graphics::{encode_kitty, encode_sixel, KittyTransport, Protocol};
use visage::tui::help::{draw_help, help_rows, HelpOverlay};
use visage::tui::keymap::Keymap;
use visage::tui::view::{draw, layout, InfoPanel, Screen, ViewModel};

struct Fixture {
    workbench: Workbench,
    catalog: Catalog,
    swatches: Vec<[u8; 3]>,
}

fn fixture() -> &'static Mutex<Fixture> {
    static F: OnceLock<Mutex<Fixture>> = OnceLock::new();
    F.get_or_init(|| {
        let db = builtin_database(
            build_head(),
            SyntheticOptions {
                seed: 1,
                sources: 5,
                gaussians_per_avatar: 11_000,
            },
        )
        .unwrap();
        let engine = Engine::new(db).unwrap();
        let catalog = Catalog::of(&engine);
        let swatches = source_swatches(&engine);
        Mutex::new(Fixture {
            workbench: Workbench::new(engine, Backend::Cpu).unwrap(),
            catalog,
            swatches,
        })
    })
}

/// Draws the editor for `state` into a TestBackend of the given size (half-blocks).
fn screen(state: &EditorState, width: u16, height: u16) -> ratatui::buffer::Buffer {
    screen_with(state, width, height, "", None)
}

/// [`screen`] with a status line and, optionally, the help overlay on top.
fn screen_with(
    state: &EditorState,
    width: u16,
    height: u16,
    status: &str,
    help: Option<&mut HelpOverlay>,
) -> ratatui::buffer::Buffer {
    let mut f = fixture().lock().unwrap_or_else(|e| e.into_inner());
    let keymap = Keymap::builtin();
    let mut terminal = Terminal::new(TestBackend::new(width, height)).unwrap();
    let area = ratatui::layout::Rect::new(0, 0, width, height);
    let image = layout(area, Screen::default()).map(|a| {
        let request = FrameRequest {
            recipe: state.recipe.clone(),
            debug: state.debug,
            group: state.selected_group(),
            width: a.viewport.width as u32,
            height: 2 * a.viewport.height as u32,
            exact: true,
        };
        f.workbench.render(&request).unwrap().image
    });
    let info = InfoPanel {
        gaussians: 12345,
        ..Default::default()
    };
    let catalog = f.catalog.clone();
    let swatches = f.swatches.clone();
    let vm = ViewModel {
        state,
        catalog: &catalog,
        swatches: &swatches,
        keymap: &keymap,
        info: &info,
        protocol: Protocol::Halfblocks,
        image: image.as_ref(),
        status,
        prompt: None,
        screen: Screen::default(),
        overlay: help.is_some(),
        journal: None,
    };
    let rows = help_rows(&keymap, false);
    terminal
        .draw(|frame| {
            draw(frame, &vm);
            if let Some(h) = help {
                draw_help(frame, frame.area(), h, &rows);
            }
        })
        .unwrap();
    terminal.backend().buffer().clone()
}

fn text(buf: &ratatui::buffer::Buffer) -> String {
    let mut s = String::new();
    for y in 0..buf.area.height {
        for x in 0..buf.area.width {
            s.push_str(buf[(x, y)].symbol());
        }
        s.push('\n');
    }
    s
}

fn run(state: &mut EditorState, lines: &[&str]) {
    let catalog = fixture()
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .catalog
        .clone();
    for l in lines {
        state.apply(&catalog, &Command::parse(l).unwrap()).unwrap();
    }
}

#[test]
fn editor_view_shows_panels_and_the_composite_in_half_blocks() {
    let catalog = fixture().lock().unwrap().catalog.clone();
    let mut state = Editor::new(catalog.clone()).state;
    run(
        &mut state,
        &[
            "select-group nose",
            "select-source bram",
            "assign",
            "smoothing crossfade",
            "motion talk",
            "frame 30",
        ],
    );
    let buf = screen(&state, 110, 36);
    let t = text(&buf);
    for needle in [
        "sources",
        "ada*",
        "bram",
        "composite",
        "▶nose   bram",
        "smoothing crossfade",
        "talk 30/125",
        "12345 Gaussians",
        "? help",
    ] {
        assert!(t.contains(needle), "missing {needle:?} in\n{t}");
    }
    // The viewport is drawn in half-blocks, and the head is in it (not just background).
    let areas = layout(buf.area, Screen::default()).unwrap();
    let v = areas.viewport;
    let mut lit = 0;
    for y in v.top()..v.bottom() {
        for x in v.left()..v.right() {
            let c = &buf[(x, y)];
            assert_eq!(c.symbol(), "▀");
            if let Color::Rgb(r, g, b) = c.fg {
                if r as u32 + g as u32 + b as u32 > 60 {
                    lit += 1;
                }
            }
        }
    }
    assert!(
        lit > (v.width * v.height) as usize / 8,
        "only {lit} lit cells"
    );
}

#[test]
fn help_overlay_lists_the_keymap_by_area_and_tiny_terminals_degrade() {
    let catalog = fixture().lock().unwrap().catalog.clone();
    let state = Editor::new(catalog.clone()).state;
    let t = text(&screen_with(
        &state,
        110,
        36,
        "",
        Some(&mut HelpOverlay::default()),
    ));
    assert!(t.contains("help: j/k"), "{t}");
    assert!(
        t.contains("editor") && t.contains("quit") && t.contains("selection"),
        "{t}"
    );
    // Commands without a key come from the command table, to type at `:`.
    let mut end = HelpOverlay {
        scroll: usize::MAX,
        ..HelpOverlay::default()
    };
    let wide = text(&screen_with(&state, 200, 60, "", Some(&mut end)));
    assert!(
        wide.contains("set-camera yaw=D") && wide.contains("left drag"),
        "{wide}"
    );
    // At 80x24 the help still shows whole rows, with where it is in the list.
    let mut filtered = HelpOverlay::filtered("smoothing");
    let small = text(&screen_with(&state, 80, 24, "", Some(&mut filtered)));
    assert!(
        small.contains("post-processing") && small.contains("set or cycle border smoothing"),
        "{small}"
    );
    assert!(small.contains("filter: smoothing"), "{small}");
    let tiny = text(&screen(&Editor::new(catalog.clone()).state, 30, 8));
    assert!(tiny.contains("visage needs at least"), "{tiny}");
}

/// At 80 columns the composite panel wraps instead of cutting: the base and
/// the weights stay readable, and the source strip keeps the selection in view.
#[test]
fn the_panel_and_strip_fit_narrow_terminals() {
    let catalog = fixture().lock().unwrap().catalog.clone();
    let mut state = Editor::new(catalog.clone()).state;
    run(
        &mut state,
        &[
            "set-shape eyes ada=0.1 bram=0.2 cleo=0.7",
            "smoothing crossfade",
            "colour skin",
            "select-source elif",
            "shape-add 0.1",
            "shape-add 0.1",
            "shape-add 0.1",
        ],
    );
    let t = text(&screen(&state, 80, 24)).replace('\u{a0}', " ");
    assert!(t.contains("cleo 0.7 bram 0.2"), "{t}");
    assert!(
        t.contains("   ada 0.1"),
        "a weight wraps whole, indented:\n{t}"
    );
    assert!(t.contains("base ada"), "{t}");
    assert!(t.contains("elif 0.3"), "weights as typed:\n{t}");
    assert!(!t.contains("0.30000000000000004"), "{t}");
    assert!(t.contains("elif"), "the selected source shows:\n{t}");
}

#[test]
fn control_characters_never_reach_the_screen() {
    let catalog = fixture().lock().unwrap().catalog.clone();
    let state = Editor::new(catalog.clone()).state;
    let t = text(&screen_with(
        &state,
        110,
        36,
        "evil\u{1b}[2Jname\u{7}",
        None,
    ));
    assert!(t.contains("evil[2Jname") && !t.contains('\u{1b}') && !t.contains('\u{7}'));
}

#[test]
fn shipped_sessions_replay_deterministically_and_pass_their_checks() {
    for name in ["nose-swap", "three-sources", "animation"] {
        let path = std::path::Path::new("sessions").join(format!("{name}.vsg"));
        let dirs = [1, 2].map(|k| {
            std::env::temp_dir().join(format!("visage-replay-{}-{name}-{k}", std::process::id()))
        });
        let a = replay(&path, Some(&dirs[0])).unwrap();
        let b = replay(&path, Some(&dirs[1])).unwrap();
        assert!(a.passed(), "{name}: {:?} {:?}", a.failures, a.checks);
        assert_eq!(a.state_hash, b.state_hash, "{name}");
        assert!(!a.snapshots.is_empty());
        for (x, y) in a.snapshots.iter().zip(&b.snapshots) {
            assert_eq!(
                std::fs::read(x).unwrap(),
                std::fs::read(y).unwrap(),
                "{name}: snapshots differ"
            );
        }
        for d in dirs {
            std::fs::remove_dir_all(d).ok();
        }
    }
}

#[test]
fn replay_cli_checks_and_reports() {
    let exe = env!("CARGO_BIN_EXE_visage");
    let out = Process::new(exe)
        .args(["replay", "sessions/nose-swap.vsg", "--check", "--json"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["checks"]
        .as_array()
        .unwrap()
        .iter()
        .all(|c| c["ok"] == true));
    // A session whose expectation fails exits 1 under --check, with one line.
    let bad = std::env::temp_dir().join(format!("visage-bad-{}.vsg", std::process::id()));
    let text: String = std::fs::read_to_string("sessions/nose-swap.vsg")
        .unwrap()
        .lines()
        .filter(|l| !l.contains("expect image"))
        .map(|l| {
            format!(
                "{}\n",
                l.replace("expect state-hash ", "expect state-hash f")
            )
        })
        .collect();
    std::fs::write(&bad, text).unwrap();
    let out = Process::new(exe)
        .args(["replay", bad.to_str().unwrap(), "--check"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr)
            .trim_end()
            .lines()
            .count(),
        1
    );
    std::fs::write(&bad, "visage-session 1\n---\n0 set-gaussians nose\n").unwrap();
    let out = Process::new(exe)
        .args(["replay", bad.to_str().unwrap()])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains(":3:"));
    std::fs::remove_file(bad).ok();
}

fn test_frame() -> RgbImage {
    let catalog = fixture().lock().unwrap().catalog.clone();
    let state = Editor::new(catalog.clone()).state;
    let mut f = fixture().lock().unwrap();
    let request = FrameRequest {
        recipe: state.recipe.clone(),
        debug: state.debug,
        group: state.selected_group(),
        width: 96,
        height: 72,
        exact: true,
    };
    f.workbench.render(&request).unwrap().image
}

/// Splits kitty escapes into (control keys, payload) pairs.
fn kitty_chunks(bytes: &[u8]) -> Vec<(String, String)> {
    let text = std::str::from_utf8(bytes).unwrap();
    text.split("\x1b\\")
        .filter(|s| !s.is_empty())
        .map(|s| {
            let body = s.strip_prefix("\x1b_G").expect("APC G");
            let (keys, payload) = body.split_once(';').unwrap();
            (keys.to_string(), payload.to_string())
        })
        .collect()
}

#[test]
fn kitty_bytes_carry_exactly_the_frame() {
    let frame = test_frame();
    for transport in [KittyTransport::Direct, KittyTransport::Zlib] {
        let chunks = kitty_chunks(&encode_kitty(&frame, (12, 9), transport).unwrap());
        assert!(chunks.len() > 1, "large frames are chunked");
        let first = &chunks[0].0;
        for key in [
            "a=T", "f=24", "s=96", "v=72", "i=7331", "p=1", "c=12", "r=9",
        ] {
            assert!(
                first.split(',').any(|k| k == key),
                "{key} missing in {first}"
            );
        }
        assert!(chunks
            .iter()
            .take(chunks.len() - 1)
            .all(|(k, _)| k.ends_with("m=1")));
        assert!(chunks.last().unwrap().0.ends_with("m=0"));
        let b64: String = chunks.iter().map(|(_, p)| p.as_str()).collect();
        let data = base64::engine::general_purpose::STANDARD
            .decode(b64)
            .unwrap();
        let pixels = if transport == KittyTransport::Zlib {
            assert!(first.contains("o=z"));
            let mut out = Vec::new();
            flate2::read::ZlibDecoder::new(&data[..])
                .read_to_end(&mut out)
                .unwrap();
            out
        } else {
            data
        };
        assert_eq!(pixels, frame.pixels);
    }
    // Local terminals get a temporary file whose path marks it for deletion.
    let chunks = kitty_chunks(&encode_kitty(&frame, (12, 9), KittyTransport::TempFile).unwrap());
    assert!(chunks[0].0.contains("t=t"));
    let path = String::from_utf8(
        base64::engine::general_purpose::STANDARD
            .decode(&chunks[0].1)
            .unwrap(),
    )
    .unwrap();
    assert!(path.contains("tty-graphics-protocol"));
    assert_eq!(std::fs::read(&path).unwrap(), frame.pixels);
    std::fs::remove_file(path).ok();
}

#[test]
fn sixel_bytes_decode_back_to_the_frame() {
    let frame = test_frame();
    let sixel = encode_sixel(&frame).unwrap();
    assert!(sixel.starts_with(b"\x1bP"), "DCS");
    let decoded = icy_sixel::SixelImage::decode(&sixel).unwrap();
    assert_eq!((decoded.width, decoded.height), (96, 72));
    let rgb: Vec<u8> = decoded
        .pixels
        .chunks(4)
        .flat_map(|p| [p[0], p[1], p[2]])
        .collect();
    let back = RgbImage {
        width: 96,
        height: 72,
        pixels: rgb,
    };
    let p = psnr(&back, &frame).unwrap();
    assert!(p >= 30.0, "sixel (256-colour palette) PSNR {p:.1}");
}
