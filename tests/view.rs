//! The scene viewer without a terminal: sessions of camera commands on a
//! scene file replay headless, show what `visage render --ply` shows for the
//! same camera, and refuse avatar commands; bad files fail cleanly.

mod common;

use std::path::{Path, PathBuf};

use common::{temp_path, visage};
use visage::render::image::{psnr, RgbImage};

/// A 20k-Gaussian SH-3 scene with floaters, written as a PLY.
fn scene_file(name: &str) -> PathBuf {
    let path = temp_path("view", name);
    let scene = visage::scene::synthetic::synthetic_scene(20_000, 8);
    visage::io::ply::write_splat_ply(&path, &scene).unwrap();
    path
}

fn write_session(name: &str, scene: &Path, body: &str) -> PathBuf {
    let path = temp_path("view", name);
    let text = format!(
        "visage-session 1\nscene \"{}\" up=+y\nrender 96x64\n---\n{body}",
        scene.display()
    );
    std::fs::write(&path, text).unwrap();
    path
}

fn png(path: &Path) -> RgbImage {
    RgbImage::load_png(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn replay_json(session: &Path, out: &Path) -> serde_json::Value {
    let o = visage(&[
        "replay",
        session.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn camera_sessions_on_a_scene_replay_like_render() {
    let scene = scene_file("garden.ply");
    let session = write_session(
        "camera.vsg",
        &scene,
        "0 snapshot home.png\n\
         0 set-camera yaw=25 pitch=-10 radius=3\n\
         0 snapshot orbit.png\n\
         0 sh-degree 0\n\
         0 snapshot dc.png\n\
         0 sh-degree 3\n\
         0 fly 0.2 0.1 0\n\
         0 look -10 5\n\
         0 snapshot flown.png\n\
         0 set-gaussians nose ada\n\
         0 debug-scale 0.5\n\
         0 snapshot thin.png\n",
    );
    let out = temp_path("view", "out");
    std::fs::create_dir_all(&out).unwrap();
    let report = replay_json(&session, &out);
    assert_eq!(report["snapshots"].as_array().unwrap().len(), 5);
    let failures = report["failures"].as_array().unwrap();
    assert_eq!(failures.len(), 1, "{failures:?}");
    assert!(failures[0].as_str().unwrap().contains("scene view"));

    // The opening view is render's framing; set-camera is render's flags.
    let reference = |name: &str, flags: &[&str]| {
        let path = out.join(name);
        let mut args = vec![
            "render",
            "--ply",
            scene.to_str().unwrap(),
            "--renderer",
            "cpu",
            "--size",
            "96x64",
            "-o",
            path.to_str().unwrap(),
        ];
        args.extend_from_slice(flags);
        let o = visage(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        png(&path)
    };
    let home = png(&out.join("home.png"));
    assert_eq!(home.pixels, reference("home-ref.png", &[]).pixels);
    let orbit = png(&out.join("orbit.png"));
    let orbit_ref = reference(
        "orbit-ref.png",
        &["--yaw", "25", "--pitch", "-10", "--radius", "3"],
    );
    assert_eq!(orbit.pixels, orbit_ref.pixels);
    // The SH degree and the scale change the picture; flying moves it.
    let changed = |a: &RgbImage, b: &RgbImage| psnr(a, b).unwrap_or(f64::INFINITY) < 45.0;
    assert!(changed(&png(&out.join("dc.png")), &orbit));
    assert!(changed(&png(&out.join("flown.png")), &orbit));
    assert!(changed(
        &png(&out.join("thin.png")),
        &png(&out.join("flown.png"))
    ));

    // Deterministic: a second replay writes the same pictures.
    let again = temp_path("view", "again");
    std::fs::create_dir_all(&again).unwrap();
    let second = replay_json(&session, &again);
    assert_eq!(second["state_hash"], report["state_hash"]);
    for name in ["flown.png", "thin.png"] {
        assert_eq!(png(&out.join(name)).pixels, png(&again.join(name)).pixels);
    }
    std::fs::remove_dir_all(&out).ok();
    std::fs::remove_dir_all(&again).ok();
    std::fs::remove_file(&scene).ok();
}

/// A y-down capture (COLMAP / INRIA convention) opened with up=-y shows what
/// `render --up -y` shows: the subject the right way up.
#[test]
fn y_down_scenes_open_upright() {
    let scene = scene_file("ydown.ply");
    let session = temp_path("view", "ydown.vsg");
    std::fs::write(
        &session,
        format!(
            "visage-session 1\nscene \"{}\" up=-y\nrender 80x60\n---\n0 snapshot v.png\n0 lod off\n0 snapshot exact.png\n",
            scene.display()
        ),
    )
    .unwrap();
    let out = temp_path("view", "ydown-out");
    std::fs::create_dir_all(&out).unwrap();
    replay_json(&session, &out);
    // What render draws with a level of detail, upright as the view is.
    let render = |name: &str, lod: &str| {
        let path = out.join(name);
        let o = visage(&[
            "render",
            "--ply",
            scene.to_str().unwrap(),
            "--renderer",
            "cpu",
            "--up",
            "-y",
            "--size",
            "80x60",
            "--lod",
            lod,
            "-o",
            path.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        path
    };
    // The view's default level of detail (this scene has more than 4
    // Gaussians a pixel at 80x60, so the view draws its hierarchy).
    let reference = render("ref.png", "auto");
    assert!(png(&out.join("v.png")).pixels == png(&reference).pixels);
    // `lod off` draws every Gaussian: what render draws by default.
    let exact = render("exact-ref.png", "off");
    let shown = png(&out.join("exact.png")).pixels;
    assert!(shown == png(&exact).pixels);
    assert!(
        shown != png(&reference).pixels,
        "the hierarchy drew something else"
    );
    std::fs::remove_dir_all(&out).ok();
    std::fs::remove_file(&scene).ok();
}

#[test]
fn bad_scene_files_fail_with_one_line_and_exit_2() {
    let garbage = temp_path("view", "garbage.ply");
    std::fs::write(
        &garbage,
        b"ply\nformat binary_little_endian 1.0\nelement vertex 5\n",
    )
    .unwrap();
    let empty_splat = temp_path("view", "odd.splat");
    std::fs::write(&empty_splat, [0u8; 33]).unwrap();
    let cut_spz = temp_path("view", "cut.spz");
    let spz = std::fs::read("tests/data/splat/ring3.spz").unwrap();
    std::fs::write(&cut_spz, &spz[..spz.len() / 2]).unwrap();
    let missing = temp_path("view", "missing.ply");
    for (file, needle) in [
        (&garbage, "garbage.ply"),
        (&empty_splat, "32-byte"),
        (&cut_spz, "cut.spz"),
        (&missing, "not a file"),
    ] {
        // Replay opens the file before any terminal is needed.
        let session = write_session("bad.vsg", file, "0 orbit 5 0\n");
        let o = visage(&["replay", session.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", file.display());
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        if file != &missing {
            assert!(err.contains(needle), "{err}");
        }
        // The viewer itself refuses before touching the terminal.
        let o = visage(&["view", file.to_str().unwrap()]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(
            err.contains(needle) || err.contains("needs a terminal"),
            "{err}"
        );
    }
    std::fs::remove_file(&garbage).ok();
    std::fs::remove_file(&empty_splat).ok();
}

/// Files other tools wrote open in the viewer and show what `render` shows:
/// plyfile's PLY, ply2splat's .splat and splat-transform's compressed PLY.
#[test]
fn files_from_other_tools_open_in_the_viewer() {
    let out = temp_path("view", "tools");
    std::fs::create_dir_all(&out).unwrap();
    for name in [
        "ring.ply",
        "ring.splat",
        "ring.compressed.ply",
        "ring3.ply",
        "ring3.spz",
        "ring.v2.spz",
    ] {
        let file = std::fs::canonicalize(Path::new("tests/data/splat").join(name)).unwrap();
        let snap = format!("{}.png", name.replace('.', "-"));
        let session = write_session(
            &format!("{name}.vsg"),
            &file,
            &format!("0 orbit 30 10\n0 snapshot {snap}\n"),
        );
        let report = replay_json(&session, &out);
        assert!(report["failures"].as_array().unwrap().is_empty(), "{name}");
        let shown = png(&out.join(&snap));
        let reference = out.join(format!("ref-{snap}"));
        let o = visage(&[
            "render",
            "--ply",
            file.to_str().unwrap(),
            "--renderer",
            "cpu",
            "--yaw",
            "30",
            "--pitch",
            "10",
            "--size",
            "96x64",
            "-o",
            reference.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        assert_eq!(shown.pixels, png(&reference).pixels, "{name}");
        assert!(
            shown.pixels.iter().any(|&p| p > 40),
            "{name} shows something"
        );
    }
    std::fs::remove_dir_all(&out).ok();
}

/// `visage clean` removes the planted floaters of a synthetic scene (one in a
/// thousand, 20-40 units out) and little else, writes the rest in the output's
/// format, says what each rule removed and how the home view changed; bad
/// options and files are one line and exit 2.
#[test]
fn clean_removes_planted_floaters_and_reports_the_view() {
    let input = scene_file("dirty.ply");
    let output = temp_path("view", "clean.spz");
    let o = visage(&[
        "clean",
        input.to_str().unwrap(),
        output.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let removed = &r["removed"];
    let isolated = removed["isolated"].as_u64().unwrap();
    let kept = removed["kept"].as_u64().unwrap();
    assert!((20..=60).contains(&isolated), "{r}");
    assert!(kept >= 19_900, "{r}");
    assert_eq!(
        visage::io::splat::read_scene(&output).unwrap().len() as u64,
        kept
    );
    // The floaters lie outside the framed subject: the view hardly changes.
    assert!(r["psnr_db"].as_f64().unwrap() > 40.0, "{r}");
    // Isolation off keeps them.
    let o = visage(&[
        "clean",
        input.to_str().unwrap(),
        output.to_str().unwrap(),
        "--isolation",
        "0",
        "--json",
    ]);
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["removed"]["isolated"], 0);
    for (args, needle) in [
        (
            vec!["--min-opacity", "2"],
            "--min-opacity takes an opacity from 0 to 1",
        ),
        (vec!["--huge", "0"], "--huge takes a positive share"),
        (
            vec!["--isolation=-1"],
            "--isolation takes a factor of 0 or more",
        ),
    ] {
        let mut all = vec!["clean", input.to_str().unwrap(), output.to_str().unwrap()];
        all.extend(args);
        let o = visage(&all);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{err}");
        assert!(
            err.contains(needle) && err.trim().lines().count() == 1,
            "{err}"
        );
    }
    let o = visage(&["clean", "/nonexistent/scene.ply", output.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
}

/// `toggle-floaters` in a scene view draws what `visage clean` writes (the
/// same pixels as rendering its output), and toggling again draws the scene
/// as it is.
#[test]
fn hidden_floaters_draw_what_clean_writes() {
    let scene = scene_file("floaters.ply");
    let cleaned = temp_path("view", "floaters-clean.ply");
    let o = visage(&["clean", scene.to_str().unwrap(), cleaned.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // From far out, the floaters are in the picture.
    let camera = "0 set-camera yaw=30 pitch=-20 radius=60\n";
    let session = write_session(
        "floaters.vsg",
        &scene,
        &format!(
            "{camera}0 snapshot shown.png\n0 toggle-floaters\n0 snapshot hidden.png\n0 toggle-floaters\n0 snapshot again.png\n"
        ),
    );
    let out = temp_path("view", "floaters-out");
    std::fs::create_dir_all(&out).unwrap();
    let report = replay_json(&session, &out);
    assert!(
        report["failures"].as_array().unwrap().is_empty(),
        "{report}"
    );
    let reference = out.join("reference.png");
    let o = visage(&[
        "render",
        "--ply",
        cleaned.to_str().unwrap(),
        "--renderer",
        "cpu",
        "--size",
        "96x64",
        "--yaw",
        "30",
        "--pitch",
        "-20",
        "--radius",
        "60",
        "-o",
        reference.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (shown, hidden) = (png(&out.join("shown.png")), png(&out.join("hidden.png")));
    assert!(shown.pixels != hidden.pixels, "the floaters were in view");
    assert_eq!(hidden.pixels, png(&reference).pixels);
    assert_eq!(png(&out.join("again.png")).pixels, shown.pixels);
    std::fs::remove_dir_all(&out).ok();
}
