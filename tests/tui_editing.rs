//! The editor as a new user meets it, in tmux at 80×24: journals that survive
//! a kill -9 and are offered back, quitting that asks before losing edits,
//! recording into an existing journal, the `:` prompt's completion menu and
//! history, the modal help, snapshots at the session's render size, and the
//! scene viewer's up axis and orbit pivot.

mod common;

use common::tmux::{wait_file, Tmux};

use std::path::{Path, PathBuf};
use std::time::Duration;

const LONG: Duration = Duration::from_secs(90);

fn temp(name: &str) -> PathBuf {
    common::temp_path("editing", name)
}

/// A fresh folder for the editor's state and config (journals, history),
/// so tests never meet the user's own.
fn home(name: &str) -> PathBuf {
    let dir = temp(name);
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The shell line that runs visage with `args` in `home`, writing its exit
/// code to `status` and keeping the pane open.
fn visage_line(home: &Path, args: &str, status: &Path) -> String {
    format!(
        "XDG_STATE_HOME={h}/state XDG_CONFIG_HOME={h}/config VISAGE_CACHE_DIR={h}/cache {} {args} 2>&1; echo EXIT=$? > {}; sleep 60",
        env!("CARGO_BIN_EXE_visage"),
        status.display(),
        h = home.display()
    )
}

const DB: &str =
    "--graphics halfblocks --renderer cpu --gaussians-per-avatar 11000 --source-count 4";

fn exit_code(status: &Path) -> String {
    let s = wait_file(status, LONG);
    std::fs::remove_file(status).ok();
    s.trim().to_string()
}

fn journals(home: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(home.join("state/visage/journals"))
        .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    v.sort();
    v
}

fn editor_ready(s: &str) -> bool {
    s.contains("composite") && s.contains("Gaussians")
}

#[test]
fn a_killed_session_is_offered_back_and_quitting_asks_first() {
    let home = home("recover");
    let status = temp("recover-status");
    std::fs::remove_file(&status).ok();
    let tmux = Tmux::new("recover");
    tmux.start_sized(&visage_line(&home, DB, &status), 80, 24);
    tmux.wait_for("the editor", LONG, editor_ready);
    tmux.keys(&["Down", "Right", "Enter"]);
    tmux.wait_for("the swap", LONG, |s| s.contains("▶eyes   bram"));
    tmux.keys(&[":"]);
    tmux.type_text("set-base cleo");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the base", LONG, |s| s.contains("base cleo"));
    let pid = tmux.program_pid().expect("the editor runs");
    std::process::Command::new("kill")
        .args(["-9", &pid])
        .status()
        .unwrap();
    assert_eq!(exit_code(&status), "EXIT=137");
    drop(tmux);

    // The next start asks; yes brings the composite back.
    let tmux = Tmux::new("recover2");
    tmux.start_sized(&visage_line(&home, DB, &status), 80, 24);
    // The question is a plain line, wrapped at 80 columns where the
    // journal's path (with the test's process id) puts the break: joined.
    let joined = |s: &str| s.replace('\n', "");
    let s = tmux.wait_for("the question", LONG, |s| {
        joined(s).contains("resume it? [y/n]")
    });
    assert!(joined(&s).contains("2 edits"), "{s}");
    tmux.keys(&["y", "Enter"]);
    let s = tmux.wait_for("the resumed editor", LONG, |s| {
        editor_ready(s) && s.contains("▶eyes   bram")
    });
    assert!(s.contains("base cleo"), "{s}");
    // The prompt's history came through the restart.
    tmux.keys(&[":", "Up"]);
    tmux.wait_for("the history", LONG, |s| s.contains(":set-base cleo"));
    tmux.keys(&["C-c"]);
    // q asks first; a second q quits.
    tmux.keys(&["q"]);
    tmux.wait_for("the question", LONG, |s| {
        s.contains("quit? 2 unsaved edits")
    });
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
    let all = journals(&home);
    assert_eq!(all.len(), 1, "the resumed journal goes on: {all:?}");
    let text = std::fs::read_to_string(&all[0]).unwrap();
    assert!(text.trim_end().ends_with("# closed quit"), "{text}");
    // It replays to the composite on screen.
    let o = common::visage(&["replay", all[0].to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["failures"].as_array().unwrap().len(), 0, "{report}");
    drop(tmux);

    // A closed journal is not offered again.
    let tmux = Tmux::new("recover3");
    tmux.start_sized(&visage_line(&home, DB, &status), 80, 24);
    let s = tmux.wait_for("the editor", LONG, editor_ready);
    assert!(s.contains("▶mouth  ada"), "a fresh composite: {s}");
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
}

#[test]
fn recording_into_an_existing_journal_continues_it() {
    let home = home("record");
    let status = temp("record-status");
    let journal = temp("record.vsg");
    std::fs::remove_file(&journal).ok();
    std::fs::remove_file(&status).ok();
    let args = format!("{DB} --record {}", journal.display());
    let tmux = Tmux::new("record");
    tmux.start_sized(&visage_line(&home, &args, &status), 80, 24);
    let s = tmux.wait_for("the editor", LONG, editor_ready);
    // A new session starts from the post-processing that measured best,
    // shown by its preset's name.
    assert!(s.contains("base ada post ours"), "{s}");
    tmux.keys(&[":"]);
    tmux.type_text("set-base bram");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the base", LONG, |s| s.contains("base bram"));
    tmux.keys(&["q"]);
    assert_eq!(
        exit_code(&status),
        "EXIT=0",
        "a named journal keeps the edits: no question"
    );
    drop(tmux);

    let tmux = Tmux::new("record2");
    tmux.start_sized(&visage_line(&home, &args, &status), 80, 24);
    // The status line is the last row drawn: a capture can catch the panels
    // of the first frame before it, so wait for it too.
    tmux.wait_for("the resumed journal", LONG, |s| {
        editor_ready(s) && s.contains("base bram") && s.contains("resumed 1 commands")
    });
    tmux.keys(&[":"]);
    tmux.type_text("set-gaussians nose cleo");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the swap", LONG, |s| s.contains("nose   cleo"));
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
    let text = std::fs::read_to_string(&journal).unwrap();
    assert_eq!(text.matches("visage-session 1").count(), 1, "{text}");
    // The journal replays to what was on screen: the same state as the two
    // commands from scratch.
    let expected = temp("record-expected.vsg");
    let header: String = text
        .lines()
        .take_while(|l| *l != "---")
        .map(|l| format!("{l}\n"))
        .collect();
    std::fs::write(
        &expected,
        format!("{header}---\n0 set-base bram\n0 set-gaussians nose cleo\n"),
    )
    .unwrap();
    let hash = |p: &Path| -> String {
        let o = common::visage(&["replay", p.to_str().unwrap(), "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        v["state_hash"].as_str().unwrap().to_string()
    };
    assert_eq!(hash(&journal), hash(&expected));
    // It replays from the post-processing its header names: without the
    // `post` line (as every session before it) it starts from none.
    assert!(header.contains("\npost ours\n"), "{header}");
    let unprocessed = temp("record-unprocessed.vsg");
    std::fs::write(
        &unprocessed,
        std::fs::read_to_string(&expected)
            .unwrap()
            .replace("post ours\n", ""),
    )
    .unwrap();
    assert_ne!(hash(&unprocessed), hash(&expected));
    // Resuming another session into it is refused before the terminal changes.
    let o = common::visage(&[
        "--session",
        "sessions/nose-swap.vsg",
        "--record",
        journal.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("already holds a session"), "{err}");
}

#[test]
fn the_prompt_completes_remembers_and_the_help_is_modal() {
    let home = home("prompt");
    let status = temp("prompt-status");
    std::fs::remove_file(&status).ok();
    let tmux = Tmux::new("prompt");
    tmux.start_sized(&visage_line(&home, DB, &status), 80, 24);
    tmux.wait_for("the editor", LONG, editor_ready);
    // Tab on an ambiguous source shows the candidates above the prompt, and
    // repeated Tabs cycle through them.
    tmux.keys(&[":"]);
    tmux.type_text("set-gaussians eyes ");
    tmux.keys(&["Tab"]);
    tmux.wait_for("the menu", LONG, |s| {
        s.contains(" ada  bram  cleo  dries ") && s.contains("0/4")
    });
    tmux.keys(&["Tab", "Tab"]);
    tmux.wait_for("the second candidate", LONG, |s| {
        s.contains(":set-gaussians eyes bram") && s.contains("2/4")
    });
    tmux.keys(&["Enter", "Enter"]);
    tmux.wait_for("the swap", LONG, |s| {
        s.contains("▶mouth  ada") && s.contains(" eyes   bram")
    });
    // Command names complete too, and help COMMAND gives the usage.
    tmux.keys(&[":"]);
    tmux.type_text("help set-sh");
    tmux.keys(&["Tab", "Enter"]);
    tmux.wait_for("the usage", LONG, |s| {
        s.contains("set-shape GROUP SOURCE=W")
    });
    // A typo suggests the command meant; ctrl-c leaves the prompt unrun.
    tmux.keys(&[":"]);
    tmux.type_text("smoothng thesis");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the suggestion", LONG, |s| {
        s.contains("did you mean smoothing")
    });
    tmux.keys(&[":"]);
    tmux.type_text("set-base cleo");
    tmux.keys(&["Home", "Right", "Right", "Right", "C-k"]);
    tmux.wait_for("the line edited", LONG, |s| {
        s.contains(":set") && !s.contains(":set-base")
    });
    tmux.keys(&["C-c"]);
    tmux.wait_for("the prompt closed", LONG, |s| s.contains("? help"));
    // The help is modal: a key typed in it filters and never reaches the editor.
    tmux.keys(&["?"]);
    tmux.wait_for("the help", LONG, |s| {
        s.contains("help: j/k") && s.contains("editor")
    });
    tmux.keys(&["b"]);
    tmux.wait_for("the filter", LONG, |s| s.contains("filter: b"));
    tmux.keys(&["Escape", "j", "j", "PageDown", "Escape"]);
    let s = tmux.wait_for("the editor again", LONG, |s| !s.contains("help: j/k"));
    assert!(
        s.contains("base ada"),
        "b in the help changed nothing:\n{s}"
    );
    assert!(!s.contains("0.30000"), "{s}");
    tmux.keys(&[":"]);
    tmux.type_text("quit!");
    tmux.keys(&["Enter"]);
    assert_eq!(exit_code(&status), "EXIT=0", "quit! does not ask");
    let history = std::fs::read_to_string(home.join("state/visage/history")).unwrap();
    assert!(history.contains("set-gaussians eyes bram\n"), "{history}");
}

#[test]
fn snapshots_take_the_session_render_size_live_and_in_replay() {
    let home = home("snap");
    let status = temp("snap-status");
    let journal = temp("snap.vsg");
    let dir = temp("snaps");
    for p in [&journal, &status] {
        std::fs::remove_file(p).ok();
    }
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    let args = format!("{DB} --record {}", journal.display());
    let tmux = Tmux::new("snap");
    tmux.start_sized(&visage_line(&home, &args, &status), 100, 30);
    tmux.wait_for("the editor", LONG, editor_ready);
    for (line, said) in [
        (
            format!("snapshot {}/default.png", dir.display()),
            "wrote 640x480 snapshot",
        ),
        (
            format!("snapshot {}/small.png 96x64", dir.display()),
            "wrote 96x64 snapshot",
        ),
    ] {
        tmux.keys(&[":"]);
        tmux.type_text(&line);
        tmux.keys(&["Enter"]);
        tmux.wait_for(said, LONG, |s| s.contains(said));
    }
    tmux.keys(&[":"]);
    tmux.type_text("snapshot shot.jpg");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the refusal", LONG, |s| s.contains("snapshot writes PNG"));
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
    let out = temp("snaps-replayed");
    std::fs::remove_dir_all(&out).ok();
    let o = common::visage(&[
        "replay",
        journal.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for (name, size) in [("default.png", (640, 480)), ("small.png", (96, 64))] {
        let live = std::fs::read(dir.join(name)).unwrap();
        let replayed = std::fs::read(out.join(name)).unwrap();
        assert_eq!(
            live, replayed,
            "{name}: live and replay agree byte for byte"
        );
        let image = visage::render::image::RgbImage::load_png(&dir.join(name)).unwrap();
        assert_eq!((image.width, image.height), size, "{name}");
    }
}

/// A capture in the COLMAP frame (y down), in INRIA's output layout with
/// its cameras.json, or without it.
fn y_down_capture(name: &str, with_cameras: bool) -> PathBuf {
    use glam::{Quat, Vec3};
    let root = temp(name);
    std::fs::remove_dir_all(&root).ok();
    let ply_dir = root.join("point_cloud/iteration_30000");
    std::fs::create_dir_all(&ply_dir).unwrap();
    let mut scene = visage::scene::splats::SplatScene::with_degree(0);
    let flip = Quat::from_rotation_x(std::f32::consts::PI);
    for i in 0..80 {
        for j in 0..80 {
            let p = Vec3::new(i as f32 * 0.08 - 3.2, 0.0, j as f32 * 0.08 - 3.2);
            let shade = 0.3 + 0.4 * (((i / 10 + j / 10) % 2) as f32);
            scene.push(
                flip * p,
                flip * Quat::from_rotation_arc(Vec3::Z, Vec3::Y),
                Vec3::new(0.05, 0.05, 0.003),
                0.9,
                &[shade, shade, 0.2],
            );
        }
    }
    for k in 0..3000 {
        let t = k as f32 * 0.01;
        let p = Vec3::new(
            (t * 13.0).sin() * 0.4,
            0.2 + t * 0.05,
            (t * 13.0).cos() * 0.4,
        );
        scene.push(
            flip * p,
            Quat::IDENTITY,
            Vec3::splat(0.03),
            0.9,
            &[1.0, 0.4, 0.2],
        );
    }
    let ply = ply_dir.join("point_cloud.ply");
    visage::io::ply::write_splat_ply(&ply, &scene).unwrap();
    if with_cameras {
        // Cameras level with the ground, looking at the middle: their y axes point
        // down the image, which is +y in this frame.
        let cameras: Vec<serde_json::Value> = (0..8)
            .map(|k| {
                let a = k as f32 * std::f32::consts::TAU / 8.0;
                let (s, c) = a.sin_cos();
                serde_json::json!({
                    "id": k, "img_name": format!("{k:05}"), "width": 64, "height": 48,
                    "position": [4.0 * s, -1.0, 4.0 * c],
                    "rotation": [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]],
                    "fy": 50.0, "fx": 50.0
                })
            })
            .collect();
        std::fs::write(
            root.join("cameras.json"),
            serde_json::to_string(&cameras).unwrap(),
        )
        .unwrap();
    }
    ply
}

#[test]
fn the_viewer_opens_captures_upright_flips_and_orbits_what_it_looks_at() {
    let home = home("viewer");
    let status = temp("viewer-status");
    let journal = temp("viewer.vsg");
    for p in [&journal, &status] {
        std::fs::remove_file(p).ok();
    }
    let ply = y_down_capture("colmap", true);
    let args = format!(
        "view {} --graphics halfblocks --renderer cpu --record {}",
        ply.display(),
        journal.display()
    );
    let tmux = Tmux::new("viewer");
    tmux.start_sized(&visage_line(&home, &args, &status), 100, 30);
    let s = tmux.wait_for("the viewer", LONG, |s| s.contains("drawn"));
    assert!(
        s.contains("up -y") && s.contains("from the capture's cameras"),
        "{s}"
    );
    // u flips the up axis; Home returns to the framing and keeps it.
    tmux.keys(&["u"]);
    tmux.wait_for("the flip", LONG, |s| s.contains("up +y"));
    tmux.keys(&["l", "Home"]);
    tmux.wait_for("the framing", LONG, |s| {
        s.contains("yaw 0°") && s.contains("up +y")
    });
    tmux.keys(&["u"]);
    tmux.wait_for("the flip back", LONG, |s| s.contains("up -y"));
    // Fly forward, let the view settle (the depth under the centre is
    // measured), then orbit: the target moves to what the view shows first.
    tmux.keys(&["w", "w", "w"]);
    std::thread::sleep(Duration::from_secs(3));
    tmux.keys(&["l"]);
    tmux.wait_for("the orbit", LONG, |s| s.contains("yaw 10°"));
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
    let text = std::fs::read_to_string(&journal).unwrap();
    let body: Vec<&str> = text.lines().skip_while(|l| *l != "---").skip(1).collect();
    let fly = body
        .iter()
        .rposition(|l| l.contains(" fly "))
        .expect("fly journalled");
    let orbit = body
        .iter()
        .rposition(|l| l.contains(" orbit 10 0"))
        .expect("orbit journalled");
    assert!(
        body[fly..orbit]
            .iter()
            .any(|l| l.contains(" set-camera ") && l.contains("target=") && l.contains("radius=")),
        "the pivot is journalled between the flight and the orbit:\n{text}"
    );
    assert!(
        text.contains("up=-y"),
        "the header keeps the detected axis:\n{text}"
    );
    // Without the cameras, the ground decides.
    let bare = y_down_capture("colmap-bare", false);
    let tmux = Tmux::new("viewer2");
    tmux.start_sized(
        &visage_line(
            &home,
            &format!(
                "view {} --graphics halfblocks --renderer cpu",
                bare.display()
            ),
            &status,
        ),
        100,
        30,
    );
    let s = tmux.wait_for("the viewer", LONG, |s| s.contains("drawn"));
    assert!(
        s.contains("up -y") && s.contains("guessed from the ground"),
        "{s}"
    );
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
}

/// The seam fit of a new session's "ours" post-processing runs in the
/// background after an edit: the post panel shows its progress while the
/// editor keeps answering, the status line says when it is done, and
/// `fit off` lists the options with the fit off.
#[test]
fn the_seam_fit_runs_in_the_background_and_can_be_turned_off() {
    let home = home("fit");
    let status = temp("fit-status");
    std::fs::remove_file(&status).ok();
    let tmux = Tmux::new("fit");
    tmux.start_sized(&visage_line(&home, DB, &status), 80, 24);
    tmux.wait_for("the editor", LONG, editor_ready);
    tmux.keys(&[":"]);
    tmux.type_text("set-gaussians nose bram");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the fit under way", LONG, |s| s.contains("post ours (fit "));
    // The editor answers while the fit runs.
    tmux.keys(&["Down"]);
    tmux.wait_for("the next group", LONG, |s| s.contains("▶eyes"));
    tmux.wait_for("the fit done", LONG, |s| {
        s.contains("seam fit done") && s.contains("post ours") && !s.contains("(fit ")
    });
    // A snapshot asked during a fit waits for it and shows it done.
    let still = temp("fit-still.png");
    std::fs::remove_file(&still).ok();
    tmux.keys(&[":"]);
    tmux.type_text("set-gaussians eyes bram");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the second fit", LONG, |s| s.contains("(fit "));
    tmux.keys(&[":"]);
    tmux.type_text(&format!("snapshot {}", still.display()));
    tmux.keys(&["Enter"]);
    tmux.wait_for("the still", LONG, |s| {
        s.contains("wrote") && s.contains("post ours") && !s.contains("(fit ")
    });
    assert!(still.exists());
    // Back to the first edit: its fit is read from the cache, not redone.
    tmux.keys(&[":"]);
    tmux.type_text("undo");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the stored fit", LONG, |s| {
        s.contains("seam fit done (read from the cache)")
    });
    tmux.keys(&[":"]);
    tmux.type_text("fit off");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the options listed", LONG, |s| {
        s.contains("shading relit") && s.contains("fit off")
    });
    tmux.keys(&["q"]);
    tmux.wait_for("the question", LONG, |s| s.contains("quit?"));
    tmux.keys(&["q"]);
    assert_eq!(exit_code(&status), "EXIT=0");
    // Both fits were kept in the user's cache, to show at once next time.
    let kept = std::fs::read_dir(home.join("cache/fits"))
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension() == Some("fit".as_ref()))
        .count();
    assert_eq!(kept, 2);
}
