//! The real editor in a real terminal: tmux runs the binary, send-keys types,
//! capture-pane reads the screen. Needs tmux (installed by .ci/setup).

mod common;

use common::tmux::{wait_file, Tmux};

use std::path::Path;
use std::process::Command;
use std::time::Duration;

fn temp(name: &str) -> std::path::PathBuf {
    common::temp_path("tmux", name)
}

fn editor_command(extra: &str, status: &Path) -> String {
    format!(
        "XDG_STATE_HOME={} VISAGE_CACHE_DIR={} {} --graphics halfblocks --gaussians-per-avatar 11000 --source-count 4 {extra} 2>/dev/null; echo EXIT=$? > {}; sleep 60",
        temp("state").display(),
        common::test_cache_dir().display(),
        env!("CARGO_BIN_EXE_visage"),
        status.display()
    )
}

#[test]
fn edit_undo_and_quit_in_a_real_terminal() {
    let tmux = Tmux::new("edit");
    let (status, record) = (temp("status"), temp("journal.vsg"));
    std::fs::remove_file(&status).ok();
    std::fs::remove_file(&record).ok();
    tmux.start(&editor_command(
        &format!("--record {}", record.display()),
        &status,
    ));
    let long = Duration::from_secs(60);
    tmux.wait_for("the editor", long, |s| {
        s.contains("composite") && s.contains("Gaussians, ")
    });
    // Select the nose group, the second source, and assign its Gaussians.
    tmux.keys(&["Down", "Down", "Down", "Down", "Down", "Right", "Enter"]);
    let s = tmux.wait_for("the assignment", long, |s| s.contains("▶nose   bram"));
    assert!(s.contains("undo 1 redo 0") || s.contains("undo 1"), "{s}");
    // Undo it.
    tmux.keys(&["u"]);
    tmux.wait_for("the undo", long, |s| {
        s.contains("▶nose   ada") && s.contains("redo 1")
    });
    // A command through the prompt.
    tmux.keys(&[
        ":", "s", "m", "o", "o", "t", "h", "i", "n", "g", "Space", "t", "h", "e", "s", "i", "s",
        "Enter",
    ]);
    tmux.wait_for("the prompt command", long, |s| {
        s.contains("smoothing thesis")
    });
    tmux.keys(&["q"]);
    assert_eq!(wait_file(&status, long).trim(), "EXIT=0");
    let screen = tmux.screen();
    assert!(
        !screen.contains("composite"),
        "the terminal was restored:\n{screen}"
    );
    // The journal holds the commands, on ticks, and replays to the same state.
    let journal = std::fs::read_to_string(&record).unwrap();
    for c in [
        "next-group",
        "next-source",
        "assign",
        "undo",
        "smoothing thesis",
    ] {
        assert!(journal.contains(c), "{c} not journaled:\n{journal}");
    }
    let session = visage::editor::session::Session::load(&record).unwrap();
    assert!(session.lines.windows(2).all(|w| w[0].tick <= w[1].tick));
    std::fs::remove_file(&record).ok();
    std::fs::remove_file(&status).ok();
}

#[test]
fn sigterm_restores_the_terminal() {
    let tmux = Tmux::new("term");
    let (status, record) = (temp("term-status"), temp("term-journal.vsg"));
    std::fs::remove_file(&status).ok();
    std::fs::remove_file(&record).ok();
    // Camera flags start the editor there, journalled as a set-camera command.
    tmux.start(&editor_command(
        &format!(
            "--radius 3.25 --fov 9 --yaw -20 --target 0,-0.03,0 --record {}",
            record.display()
        ),
        &status,
    ));
    tmux.wait_for("the editor", Duration::from_secs(60), |s| {
        s.contains("composite") && s.contains("yaw -20° pitch 0° r 3.25 fov 9°")
    });
    let journal = wait_file(&record, Duration::from_secs(5));
    assert!(
        journal.contains("0 set-camera yaw=-20 radius=3.25 fov=9 target=0,-0.03,0"),
        "{journal}"
    );
    let shell = tmux.cmd(&["display-message", "-p", "#{pane_pid}"]);
    let children = Command::new("pgrep")
        .args(["-P", shell.trim()])
        .output()
        .unwrap();
    let pids = String::from_utf8_lossy(&children.stdout);
    let editor = pids
        .lines()
        .next()
        .expect("the editor runs under the pane's shell");
    Command::new("kill")
        .args(["-TERM", editor.trim()])
        .status()
        .unwrap();
    assert_eq!(
        wait_file(&status, Duration::from_secs(20)).trim(),
        "EXIT=143",
        "128 + SIGTERM, as shells report it"
    );
    let s = tmux.screen();
    assert!(!s.contains("composite"), "alternate screen left:\n{s}");
    std::fs::remove_file(&status).ok();
    std::fs::remove_file(&record).ok();
}

/// `visage view FILE` (and `visage FILE`): a scene in a real terminal, moved
/// with the viewer's keys, journalled, snapshotted and replayed.
#[test]
fn view_a_scene_file_fly_and_replay_the_journal() {
    let tmux = Tmux::new("view");
    let scene_path = temp("scene.ply");
    let scene = visage::scene::synthetic::synthetic_scene(30_000, 5);
    visage::io::ply::write_splat_ply(&scene_path, &scene).unwrap();
    let (status, record, snap) = (
        temp("view-status"),
        temp("view-journal.vsg"),
        temp("view-snap.png"),
    );
    for f in [&status, &record, &snap] {
        std::fs::remove_file(f).ok();
    }
    tmux.start(&format!(
        "{} view {} --graphics halfblocks --renderer cpu --record {} 2>/dev/null; echo EXIT=$? > {}; sleep 60",
        env!("CARGO_BIN_EXE_visage"),
        scene_path.display(),
        record.display(),
        status.display()
    ));
    let long = Duration::from_secs(60);
    tmux.wait_for("the viewer", long, |s| {
        s.contains("scene.ply") && s.contains("30000 Gaussians")
    });
    tmux.wait_for("a first frame", long, |s| s.contains(" of 30000 drawn"));
    // Fly forward, turn, lower the SH degree; an avatar command is refused.
    tmux.keys(&["w", "w", "Right", "h"]);
    tmux.wait_for("the SH degree", long, |s| s.contains("SH 2 of 3"));
    let command = format!("snapshot {}", snap.display());
    let mut typed: Vec<String> = vec![":".into()];
    typed.extend(command.chars().map(|c| match c {
        ' ' => "Space".to_string(),
        c => c.to_string(),
    }));
    typed.push("Enter".into());
    tmux.keys(&typed.iter().map(String::as_str).collect::<Vec<_>>());
    tmux.wait_for("the snapshot", long, |s| {
        s.contains("wrote") && s.contains("snapshot")
    });
    tmux.keys(&[":", "p", "l", "a", "y", "Enter"]);
    tmux.wait_for("the refusal", long, |s| {
        s.contains("a scene view has no avatars")
    });
    tmux.keys(&["q"]);
    assert_eq!(wait_file(&status, long).trim(), "EXIT=0");
    let journal = std::fs::read_to_string(&record).unwrap();
    assert!(journal.contains("\nscene "), "{journal}");
    for c in ["fly 0.05 0 0", "look 5 0", "sh-degree", "snapshot "] {
        assert!(journal.contains(c), "{c} not journaled:\n{journal}");
    }
    // The journal replays headless and draws the same view.
    let out = temp("view-replay");
    std::fs::create_dir_all(&out).unwrap();
    let o = common::visage(&[
        "replay",
        record.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(snap.exists(), "the live snapshot was written");
    let replayed =
        visage::render::image::RgbImage::load_png(&out.join(snap.file_name().unwrap())).unwrap();
    assert!(
        replayed.pixels.iter().any(|&p| p > 30),
        "the view shows the scene"
    );

    // `visage FILE` opens the same viewer.
    std::fs::remove_file(&status).ok();
    tmux.cmd(&["kill-server"]);
    let tmux = Tmux::new("view2");
    tmux.start(&format!(
        "{} {} --graphics halfblocks --renderer cpu 2>/dev/null; echo EXIT=$? > {}; sleep 60",
        env!("CARGO_BIN_EXE_visage"),
        scene_path.display(),
        status.display()
    ));
    tmux.wait_for("the viewer", long, |s| s.contains("30000 Gaussians"));
    tmux.keys(&["q"]);
    assert_eq!(wait_file(&status, long).trim(), "EXIT=0");
    for f in [&status, &record, &snap, &scene_path] {
        std::fs::remove_file(f).ok();
    }
    std::fs::remove_dir_all(&out).ok();
}
