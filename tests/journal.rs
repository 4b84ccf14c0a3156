//! A journal always replays to what the editor showed: random command
//! sequences (valid, invalid and front-end commands, ticks passing while
//! playing) run through the journalled editor, killed at random points —
//! sometimes in the middle of writing a line — and resumed, into the same
//! journal or into a new one, as the live editor does. After every kill, the
//! resumed editor's state is exactly the state the killed one had after its
//! last journalled command, and at the end a headless replay of the final
//! journal gives the final state.

use std::io::Write;
use std::path::{Path, PathBuf};

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use visage::editor::command::Command;
use visage::editor::journal::{open_journal, JournalledEditor};
use visage::editor::replay::replay_commands;
use visage::editor::session::{Protocol, Session, SessionHeader};
use visage::editor::state::{Catalog, EditorState};
use visage::editor::Editor;
use visage::pipeline::{DatabaseSpec, Subject};

fn catalog() -> Catalog {
    Catalog {
        sources: ["ada", "bram", "cleo", "dries"].map(String::from).to_vec(),
        motions: vec![("talk".into(), 125), ("blink".into(), 40)],
        scene: None,
    }
}

fn header() -> SessionHeader {
    SessionHeader::for_subject(
        &Subject::Avatars(DatabaseSpec::default()),
        (80, 24),
        Protocol::Halfblocks,
    )
}

/// A random command line: most valid, some failing, some for the front end.
fn random_line(rng: &mut ChaCha8Rng) -> String {
    let pick = |rng: &mut ChaCha8Rng, xs: &[&str]| xs[rng.random_range(0..xs.len())].to_string();
    let group = |rng: &mut ChaCha8Rng| {
        pick(
            rng,
            &["mouth", "eyes", "ears", "neck", "hair", "nose", "face"],
        )
    };
    let source = |rng: &mut ChaCha8Rng| pick(rng, &["ada", "bram", "cleo", "dries", "zed"]);
    let x = |rng: &mut ChaCha8Rng| format!("{:.2}", rng.random_range(-1.0f32..1.0));
    match rng.random_range(0..34) {
        0 => format!("select-group {}", group(rng)),
        1 => "next-group".into(),
        2 => "prev-group".into(),
        3 => format!("select-source {}", source(rng)),
        4 => "next-source".into(),
        5 => "assign".into(),
        6 => format!("set-gaussians {} {}", group(rng), source(rng)),
        7 => format!(
            "set-shape {} {}={:.1} {}={:.1}",
            group(rng),
            source(rng),
            rng.random_range(0.0f32..1.0),
            source(rng),
            rng.random_range(0.0f32..1.0)
        ),
        8 | 9 => format!("shape-add {:.1}", rng.random_range(-0.5f32..0.5)),
        10 => format!("set-base {}", source(rng)),
        11 => "base-from-selected".into(),
        12 => pick(
            rng,
            &["smoothing", "smoothing crossfade", "colour", "colour skin"],
        ),
        13 => format!("motion {}", pick(rng, &["talk", "blink", "rest", "dance"])),
        14 => "next-motion".into(),
        15 => pick(rng, &["play", "pause", "toggle-play"]),
        16 => format!("step {}", rng.random_range(-30..30)),
        17 => format!("frame {}", rng.random_range(0..160)),
        18 => pick(rng, &["mode", "mode exact"]),
        19 => format!(
            "pose {} {} {} {}",
            pick(rng, &["jaw", "neck", "eyes"]),
            x(rng),
            x(rng),
            x(rng)
        ),
        20 => format!("expression {} {}", rng.random_range(1..6), x(rng)),
        21 => "reset-pose".into(),
        22 => format!(
            "orbit {:.0} {:.0}",
            rng.random_range(-40.0f32..40.0),
            rng.random_range(-20.0f32..20.0)
        ),
        23 => format!("zoom {:.2}", rng.random_range(0.5f32..2.0)),
        24 => pick(rng, &["camera-reset", "camera-study", "flip-up"]),
        25 => format!("fly {} {} {}", x(rng), x(rng), x(rng)),
        26 => format!(
            "look {:.0} {:.0}",
            rng.random_range(-30.0f32..30.0),
            rng.random_range(-10.0f32..10.0)
        ),
        27 | 28 => "undo".into(),
        29 => "redo".into(),
        30 => pick(rng, &["help", "quit", "prompt", "help undo"]),
        31 => pick(
            rng,
            &[
                "debug-scale 0.5",
                "toggle-mesh",
                "toggle-highlight",
                "sh-degree",
            ],
        ),
        32 => pick(
            rng,
            &["snapshot a.png", "save-recipe r.toml", "export-ply a.splat"],
        ),
        _ => "set-camera radius=3 yaw=10".into(),
    }
}

/// Resumes the journal as the live editor does: its commands replayed into
/// a fresh editor that goes on recording (into `into` when that is another file).
fn resume(journal: &Path, into: &Path) -> JournalledEditor {
    let resume_from = (journal != into).then_some(journal);
    let (recorder, session) = open_journal(into, resume_from, &header()).unwrap();
    let mut editor = Editor::new(catalog());
    if let Some(s) = &session {
        assert_eq!(
            replay_commands(s, &mut editor),
            0,
            "journalled commands all succeed"
        );
    }
    JournalledEditor::new(editor, Some(recorder))
}

fn replayed(journal: &Path) -> (u64, EditorState) {
    let session = Session::load(journal).unwrap();
    let mut editor = Editor::new(catalog());
    assert_eq!(replay_commands(&session, &mut editor), 0);
    (editor.tick(), editor.state)
}

#[test]
fn a_journal_replays_to_what_the_editor_showed_through_kills() {
    let dir = std::env::temp_dir().join(format!("visage-journal-prop-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    for case in 0..60u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(case);
        let mut path: PathBuf = dir.join(format!("case{case}-0.vsg"));
        let mut live = resume(&path, &path);
        // The state after the last journalled command, and its tick.
        let mut last: (u64, EditorState) = (0, live.editor.state.clone());
        let steps = rng.random_range(20..200);
        for step in 0..steps {
            let ticks = live.editor.tick() + rng.random_range(0..6);
            live.editor.advance_to(ticks);
            let command = Command::parse(&random_line(&mut rng)).unwrap();
            if live.run(&command).is_ok() && command.journalled() {
                last = (live.editor.tick(), live.editor.state.clone());
            }
            if rng.random_bool(0.05) || step + 1 == steps {
                // kill -9: nothing is closed; sometimes a line was half written.
                drop(live);
                if rng.random_bool(0.3) {
                    let mut f = std::fs::OpenOptions::new()
                        .append(true)
                        .open(&path)
                        .unwrap();
                    f.write_all(b"77 set-gaussians no").unwrap();
                }
                let into = if rng.random_bool(0.3) {
                    dir.join(format!("case{case}-{step}.vsg"))
                } else {
                    path.clone()
                };
                live = resume(&path, &into);
                path = into;
                assert_eq!(live.editor.tick(), last.0, "case {case} step {step}: tick");
                assert_eq!(live.editor.state, last.1, "case {case} step {step}: state");
            }
        }
        drop(live);
        assert_eq!(replayed(&path), last, "case {case}: final replay");
    }
    std::fs::remove_dir_all(&dir).ok();
}
