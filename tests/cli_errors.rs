//! Mistakes a new user makes on the command line get one line that says
//! what to do, and exit 2 — before anything slow happens: values listed,
//! options before the subcommand understood (or named as misplaced), files
//! checked before the terminal, output formats before rendering, frames past
//! the motion refused; and the editor's own files (exports, snapshots) do
//! what their names say.

mod common;
use common::visage;

use std::path::PathBuf;

fn temp(name: &str) -> PathBuf {
    common::temp_path("cli-errors", name)
}

/// Runs visage and expects exit 2 with one line holding every needle.
fn fails(args: &[&str], needles: &[&str]) {
    let o = visage(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: {n:?} not in {err}");
    }
}

#[test]
fn usage_errors_name_the_argument_and_the_values_allowed() {
    fails(
        &["--graphics", "foo"],
        &[
            "'foo'",
            "--graphics",
            "auto, kitty, sixel, iterm2, halfblocks",
        ],
    );
    fails(&["render"], &["--output"]);
    // A typo gets the nearest command or option, as clap's tip would say.
    fails(
        &["db", "statsu", "m.toml"],
        &["'statsu'", "did you mean 'status'?"],
    );
    fails(
        &["train", "--manifst", "m.toml"],
        &["did you mean '--manifest'?"],
    );
    fails(
        &["bench", "render", "--renderers", "tpu"],
        &["'tpu'", "auto, gpu or cpu"],
    );
    // An option of the subcommand written before it works...
    let o = visage(&[
        "--source-count",
        "2",
        "--gaussians-per-avatar",
        "2000",
        "info",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["sources"].as_array().unwrap().len(), 2);
    // ...and one it does not take is named as misplaced.
    fails(
        &["--graphics", "kitty", "info"],
        &[
            "'--graphics'",
            "options before 'info' must be options of 'visage info'",
        ],
    );
}

/// `--seam-fit-size` where no seam fit runs is a mistake said in one line,
/// not a size silently ignored.
#[test]
fn a_seam_fit_size_or_renderer_without_a_fit_is_refused() {
    let out = temp("no-fit.ply");
    let o = out.to_str().unwrap();
    let recipe = "recipes/three-sources.toml";
    let says = ["--seam-fit-size", "no [post] fit"];
    fails(
        &[
            "--gaussians-per-avatar",
            "2000",
            "export",
            "--recipe",
            recipe,
            "--format",
            "ply",
            "--seam-fit-size",
            "64",
            "-o",
            o,
        ],
        &says,
    );
    let compose = [
        "--gaussians-per-avatar",
        "2000",
        "compose",
        "--recipe",
        recipe,
    ];
    for (options, flag) in [
        (
            &["--seam-fit", "0", "--seam-fit-size", "64"][..],
            "--seam-fit-size",
        ),
        (&["--seam-fit-renderer", "gpu"][..], "--seam-fit-renderer"),
        (&["--no-seam-fit-cache"][..], "--no-seam-fit-cache"),
    ] {
        fails(&[&compose[..], options].concat(), &[flag, "no [post] fit"]);
    }
    assert!(!out.exists(), "nothing written");
}

#[test]
fn the_real_problem_comes_before_needs_a_terminal() {
    // The tests run without a terminal: the named file's problem must win.
    fails(
        &["--keymap", "/no/such/keymap.toml"],
        &["--keymap", "no such file"],
    );
    fails(
        &["--session", "/no/such/session.vsg"],
        &["--session", "no such file"],
    );
    let keymap = temp("bad-keymap.toml");
    std::fs::write(&keymap, "[keys]\n\"q\" = \"soar\"\n").unwrap();
    fails(
        &["--keymap", keymap.to_str().unwrap()],
        &["keymap", ":2:", "unknown command"],
    );
    fails(
        &["--db", "/no/such/avatars"],
        &["/no/such/avatars", "does not exist"],
    );
    fails(&[], &["needs a terminal"]);
}

#[test]
fn render_checks_its_output_and_frames_before_rendering() {
    fails(&["render", "-o", "x.jpg"], &["PNG", "x.jpg"]);
    let recipe = temp("talk.toml");
    std::fs::write(&recipe, "base = \"ada\"\n[animation]\nmotion = \"talk\"\n").unwrap();
    let r = recipe.to_str().unwrap();
    let small = [
        "--gaussians-per-avatar",
        "2000",
        "--source-count",
        "2",
        "--size",
        "24x16",
    ];
    let png = temp("frame.png");
    let p = png.to_str().unwrap();
    let mut args = vec!["render", "--recipe", r, "--frame", "300", "-o", p];
    args.extend(small);
    fails(
        &args,
        &["frame 300 is past the end of the motion talk (frames 0-124)"],
    );
    let mut args = vec!["render", "--frame", "3", "-o", p];
    args.extend(small);
    fails(&args, &["at rest"]);
    // --frames makes the folder the pattern names.
    let folder = temp("shots");
    std::fs::remove_dir_all(&folder).ok();
    let pattern = folder.join("deep/f-{frame}.png");
    let mut args = vec![
        "render",
        "--recipe",
        r,
        "--frames",
        "120..125",
        "-o",
        pattern.to_str().unwrap(),
    ];
    args.extend(small);
    let o = visage(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(folder.join("deep/f-0124.png").is_file());
    let mut args = vec![
        "render",
        "--recipe",
        r,
        "--frames",
        "120..126",
        "-o",
        pattern.to_str().unwrap(),
    ];
    args.extend(small);
    fails(&args, &["frame 125 is past the end"]);
}

/// The editor's exports write what the extension says; other extensions and
/// snapshots that are not PNG are refused as commands (not journalled); the
/// highlight dims the other groups over the Gaussians.
#[test]
fn editor_files_follow_their_names_and_the_highlight_shows_over_gaussians() {
    let out = temp("replay-out");
    std::fs::remove_dir_all(&out).ok();
    let session = temp("files.vsg");
    std::fs::write(
        &session,
        "visage-session 1\ndb builtin seed=1 gaussians-per-avatar=4000 sources=3\nrender 96x96\n---\n\
         0 export-ply scene.splat\n0 export-ply scene.compressed.ply\n0 export-ply scene.jpg\n\
         0 snapshot plain.png\n0 select-group nose\n0 toggle-highlight\n0 snapshot lit.png\n\
         0 snapshot view.jpg\n",
    )
    .unwrap();
    let o = visage(&[
        "replay",
        session.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let failures = report["failures"].to_string();
    assert!(
        failures.contains("scene.jpg: unknown scene format"),
        "{failures}"
    );
    assert!(failures.contains("snapshot writes PNG"), "{failures}");
    let splat = visage::io::splat::read_scene(&out.join("scene.splat")).unwrap();
    let compressed = visage::io::splat::read_scene(&out.join("scene.compressed.ply")).unwrap();
    assert!(splat.len() > 1000 && splat.len() == compressed.len());
    let splat_bytes = std::fs::read(out.join("scene.splat")).unwrap();
    assert!(!splat_bytes.starts_with(b"ply"), "a .splat, not a PLY");
    let load = |n: &str| visage::render::image::RgbImage::load_png(&out.join(n)).unwrap();
    let (plain, lit) = (load("plain.png"), load("lit.png"));
    assert_eq!((plain.width, plain.height), (96, 96));
    let brightness =
        |i: &visage::render::image::RgbImage| i.pixels.iter().map(|&p| p as f64).sum::<f64>();
    assert!(
        brightness(&lit) < 0.6 * brightness(&plain),
        "the other groups are dimmed: {} vs {}",
        brightness(&lit),
        brightness(&plain)
    );
    // The nose itself keeps its colour: the centre of the face is as bright.
    let centre = |i: &visage::render::image::RgbImage| {
        i.pixel(48, 50).iter().map(|&c| c as i32).sum::<i32>()
    };
    assert!(
        (centre(&lit) - centre(&plain)).abs() < 40,
        "{} vs {}",
        centre(&lit),
        centre(&plain)
    );
}

/// Without a graphics adapter (no Vulkan driver found), `bench render`
/// measures the CPU and says the GPU was skipped, instead of failing.
#[test]
fn bench_render_without_a_graphics_adapter_measures_the_cpu() {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("VK_ICD_FILENAMES", "/nonexistent/icd.json")
        .env("VK_DRIVER_FILES", "/nonexistent/icd.json")
        .env("NODEVICE_SELECT", "1")
        .args([
            "bench",
            "render",
            "--sizes",
            "32x24",
            "--iterations",
            "1",
            "--warmup",
            "0",
            "--no-knobs",
            "--gaussians-per-avatar",
            "2000",
            "--source-count",
            "2",
            "--json",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("skipping the gpu renderer"), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["skipped"][0]["renderer"], "gpu", "{v}");
    let renderers = v["renderers"].as_array().unwrap();
    assert_eq!(renderers.len(), 1, "{v}");
    assert_eq!(renderers[0]["renderer"], "cpu");
    assert!(renderers[0]["rows"][0]["psnr_db"].as_f64().unwrap() > 40.0);
}
