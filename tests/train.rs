//! Making a source: `visage capture` writes a dataset GaussianAvatars' reader
//! accepts, `visage train` fits an avatar to it (the loss falls, the PSNR
//! rises, the same seed gives the same avatar), `visage eval` scores it, and
//! the avatar composes beside built-in sources. Malformed datasets fail with
//! one line and exit 2.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{python, temp_path, visage};
use visage::render::Backend;
use visage::train::trainer::{StepReport, TrainOptions, Trainer};

/// A small capture: 64×64, 4 cameras, 3 timesteps.
fn small_capture(name: &str) -> PathBuf {
    common::small_capture("train", name, 64, 4, 3)
}

/// GaussianAvatars' reader takes the capture, and its camera puts a point
/// where ours does.
#[test]
fn captures_load_in_gaussian_avatars_reader_with_the_same_cameras() {
    let dir = small_capture("ga");
    let point = [0.02, -0.03, 0.05];
    let out = Command::new(python())
        .arg("tests/data/check_transforms.py")
        .arg(&dir)
        .args(point.map(|x| x.to_string()))
        .output()
        .expect("python3 with numpy (bash .ci/setup installs it)");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["train"]["frames"], 8, "{summary}");
    assert_eq!(summary["train"]["timesteps"], 2);
    assert_eq!(summary["val"]["frames"], 2);
    assert_eq!(summary["test"]["timesteps"], 1);
    let dataset = visage::train::dataset::Dataset::load(&dir).unwrap();
    assert_eq!(dataset.builtin_source.as_deref(), Some("ada"));
    let camera = dataset.train[0].camera;
    let p = glam::DVec3::from(point);
    let r = camera.rotation;
    let view: [f64; 3] = std::array::from_fn(|i| {
        r[i][0] * p.x + r[i][1] * p.y + r[i][2] * p.z + camera.translation[i]
    });
    let ours = [
        camera.principal[0] + camera.focal[0] * view[0] / -view[2],
        camera.principal[1] - camera.focal[1] * view[1] / -view[2],
    ];
    let theirs = summary["first_train_pixel"].as_array().unwrap();
    for k in 0..2 {
        let t = theirs[k].as_f64().unwrap();
        assert!((ours[k] - t).abs() < 1e-6, "{ours:?} vs {theirs:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Training lowers the loss and raises the PSNR, and a seed fixes the result.
#[test]
fn training_fits_the_capture_and_is_deterministic() {
    use visage::train::dataset::Dataset;
    let dir = small_capture("fit");
    let dataset = Dataset::load(&dir).unwrap();
    let run = || train_run(&dataset, Backend::Cpu, 120, [48, 48]);
    let (trainer, reports) = run();
    let (early, late) = (&reports[..20], &reports[reports.len() - 20..]);
    assert!(
        mean(late, |r| r.loss) < 0.7 * mean(early, |r| r.loss),
        "loss {} → {}",
        mean(early, |r| r.loss),
        mean(late, |r| r.loss)
    );
    assert!(
        mean(late, |r| r.psnr) > mean(early, |r| r.psnr) + 2.0,
        "PSNR {} → {}",
        mean(early, |r| r.psnr),
        mean(late, |r| r.psnr)
    );
    let (again, _) = run();
    assert_eq!(
        trainer.model, again.model,
        "the same seed trains the same avatar"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// The wgpu rasteriser (lavapipe in CI) trains the same run as the CPU's to
/// f32 rounding — the same loss and PSNR step by step — and repeats exactly.
#[test]
fn training_on_wgpu_follows_the_cpu_run_and_repeats() {
    use visage::train::dataset::Dataset;
    let dir = small_capture("fit-gpu");
    let dataset = Dataset::load(&dir).unwrap();
    let (cpu, cpu_reports) = train_run(&dataset, Backend::Cpu, 30, [32, 32]);
    let (gpu, gpu_reports) = train_run(&dataset, Backend::Gpu, 30, [32, 32]);
    for (c, g) in cpu_reports.iter().zip(&gpu_reports) {
        assert!(
            (c.psnr - g.psnr).abs() < 0.05 && (c.loss - g.loss).abs() < 1e-3 * c.loss,
            "iteration {}: cpu {c:?} wgpu {g:?}",
            c.iteration
        );
    }
    assert!(cpu_reports[29].loss < cpu_reports[0].loss);
    let difference = cpu.model.len().abs_diff(gpu.model.len());
    assert!(
        difference * 100 <= cpu.model.len(),
        "{} vs {}",
        cpu.model.len(),
        gpu.model.len()
    );
    let (again, _) = train_run(&dataset, Backend::Gpu, 30, [32, 32]);
    assert_eq!(
        gpu.model, again.model,
        "the same seed trains the same avatar"
    );
    std::fs::remove_dir_all(&dir).ok();
}

/// A training run with seed 3 and its per-step reports.
fn train_run(
    dataset: &visage::train::dataset::Dataset,
    renderer: Backend,
    iterations: usize,
    size: [u32; 2],
) -> (Trainer, Vec<StepReport>) {
    let options = TrainOptions {
        iterations,
        seed: 3,
        size: Some(size),
        background: [0.0; 3],
        renderer,
        holes: Default::default(),
    };
    let mut trainer = Trainer::new(dataset, visage::model::builtin::build_head(), options).unwrap();
    let reports = (0..iterations).map(|_| trainer.step().unwrap()).collect();
    (trainer, reports)
}

/// The mean of a figure over reports.
fn mean(reports: &[StepReport], figure: fn(&StepReport) -> f64) -> f64 {
    reports.iter().map(figure).sum::<f64>() / reports.len() as f64
}

/// The command line end to end: train, eval (JSON and a grid), then the
/// avatar composes beside an exported built-in source.
#[test]
fn train_eval_and_compose_from_the_command_line() {
    let dir = small_capture("cli");
    let db = temp_path("train", "db");
    std::fs::remove_dir_all(&db).ok();
    let avatar = db.join("trained");
    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        avatar.to_str().unwrap(),
        "--iterations",
        "40",
        "--size",
        "32x32",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(avatar.join("point_cloud.ply").is_file());
    let grid = temp_path("train", "grid.png");
    let o = visage(&[
        "eval",
        avatar.to_str().unwrap(),
        dir.to_str().unwrap(),
        "--json",
        "--grid",
        grid.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let splits = report["splits"].as_array().unwrap();
    assert_eq!(splits.len(), 2, "{report}");
    for s in splits {
        let psnr = s["psnr_db"].as_f64().unwrap();
        assert!(psnr > 8.0 && psnr.is_finite(), "{report}");
    }
    let picture = image::image_dimensions(&grid).unwrap();
    assert_eq!(
        picture,
        (150 + 128, 22 + 3 * 64),
        "a label column, render | truth at 64 px each under a header row, one row per view"
    );
    // A built-in source exported beside it: the folder database composes both.
    let recipe = temp_path("train", "recipe.toml");
    std::fs::write(&recipe, "base = \"bram\"\n").unwrap();
    let o = visage(&[
        "export",
        "--recipe",
        recipe.to_str().unwrap(),
        "--gaussians-per-avatar",
        "3000",
        "--format",
        "gaussian-avatars",
        "--output",
        db.join("bram").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::write(
        &recipe,
        "base = \"trained\"\n[groups.nose]\ngaussians = \"bram\"\n",
    )
    .unwrap();
    let o = visage(&[
        "compose",
        "--db",
        db.to_str().unwrap(),
        "--recipe",
        recipe.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for p in [&dir, &db] {
        std::fs::remove_dir_all(p).ok();
    }
    std::fs::remove_file(&grid).ok();
    std::fs::remove_file(&recipe).ok();
}

#[test]
fn malformed_datasets_fail_with_one_line_and_exit_2() {
    let dir = small_capture("bad");
    let original = std::fs::read_to_string(dir.join("transforms_train.json")).unwrap();
    let cases: [(&str, &str, &str); 6] = [
        (
            "\"transform_matrix\": [",
            "\"transform_matrix\": [[1,2],",
            "4x4",
        ),
        (
            "\"timestep_index\"",
            "\"timestep_indexx\"",
            "timestep_index",
        ),
        (
            "images/00000_00.png",
            "images/missing.png",
            "does not exist",
        ),
        ("\"frames\"", "\"framez\"", "no 'frames'"),
        ("\"fl_x\"", "\"fl_q\"", ""),
        ("{", "{{", "not valid JSON"),
    ];
    for (from, to, needle) in cases {
        std::fs::write(
            dir.join("transforms_train.json"),
            original.replacen(from, to, 1),
        )
        .unwrap();
        let o = visage(&[
            "train",
            dir.to_str().unwrap(),
            "-o",
            dir.join("out").to_str().unwrap(),
            "--iterations",
            "1",
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        if needle.is_empty() {
            // Without fl_x the top-level intrinsics still give the camera.
            assert!(o.status.success(), "{err}");
            continue;
        }
        assert_eq!(o.status.code(), Some(2), "{to}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(
            err.contains(needle) && err.contains("transforms_train.json"),
            "{err}"
        );
    }
    // A dataset not captured from the built-in head needs FLAME files.
    std::fs::write(
        dir.join("transforms_train.json"),
        original.replace("visage_builtin_head", "something_else"),
    )
    .unwrap();
    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        dir.join("o").to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--flame and --masks"));
    std::fs::remove_dir_all(&dir).ok();
}

/// Trains for a long time, sends `signal` after three seconds and returns
/// what the process did.
fn interrupted_run(
    dir: &Path,
    out: &Path,
    resume: Option<&Path>,
    signal: &str,
) -> std::process::Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_visage"));
    cmd.args(["train", dir.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .args([
            "--iterations",
            "1000000",
            "--size",
            "16x16",
            "--checkpoint-every",
            "0",
        ])
        .stderr(std::process::Stdio::piped());
    if let Some(r) = resume {
        cmd.arg("--resume").arg(r);
    }
    let child = cmd.spawn().unwrap();
    std::thread::sleep(std::time::Duration::from_secs(3));
    Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    child.wait_with_output().unwrap()
}

/// Ctrl-C (SIGINT) or SIGTERM stops at an iteration boundary with a
/// checkpoint and the avatar so far, and exits as shells expect (130, 143);
/// `--resume` continues from there.
#[test]
fn ctrl_c_checkpoints_and_resume_continues() {
    let dir = small_capture("sigint");
    let out = dir.join("avatar");
    let stopped_at = |resume: Option<&Path>, signal: &str, code: i32| -> usize {
        let o = interrupted_run(&dir, &out, resume, signal);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{err}");
        let line = err
            .lines()
            .find(|l| l.contains("at iteration"))
            .unwrap_or_else(|| panic!("{err}"));
        line.split_whitespace()
            .skip_while(|w| *w != "iteration")
            .nth(1)
            .unwrap()
            .parse()
            .unwrap()
    };
    let first = stopped_at(None, "-INT", 130);
    let checkpoint = out.join("checkpoint.npz");
    assert!(checkpoint.is_file() && out.join("point_cloud.ply").is_file());
    let second = stopped_at(Some(&checkpoint), "-TERM", 143);
    assert!(second > first, "resumed from {first}, stopped at {second}");
    std::fs::remove_dir_all(&dir).ok();
}

/// `visage bench train` measures a short run on a fresh capture per
/// renderer: speed, a held-out curve, the gradient error against central
/// differences, how far the wgpu gradients are from the CPU's, and the
/// loss's own time.
#[test]
fn bench_train_reports_speed_quality_and_gradient_error() {
    let o = visage(&[
        "bench",
        "train",
        "--capture-size",
        "32x32",
        "--iterations",
        "20",
        "--eval-every",
        "10",
        "--renderers",
        "cpu,gpu",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        r["gradient_max_relative_error"].as_f64().unwrap() < 1e-4,
        "{r}"
    );
    // The loss is timed at the capture's size.
    assert!(r["loss_ms"].as_f64().unwrap() > 0.0, "{r}");
    assert_eq!(r["loss_size"], serde_json::json!([32, 32]), "{r}");
    let runs = r["renderers"].as_array().unwrap();
    assert_eq!(runs.len(), 2, "{r}");
    assert_eq!(runs[0]["renderer"], "cpu");
    assert_eq!(runs[1]["renderer"], "gpu");
    assert!(
        runs[1]["device"].as_str().unwrap().starts_with("wgpu"),
        "{r}"
    );
    for run in runs {
        assert!(run["iterations_per_s"].as_f64().unwrap() > 0.0);
        // Where an iteration's time goes: every part measured.
        for part in ["forward", "loss", "backward", "update"] {
            assert!(run["stage_ms"][part].as_f64().unwrap() > 0.0, "{part}: {r}");
        }
        assert!(
            run["gradient_difference_from_cpu"].as_f64().unwrap() < 1e-4,
            "{r}"
        );
        let curve = run["curve"].as_array().unwrap();
        assert_eq!(curve.len(), 2, "{r}");
        assert!(curve
            .iter()
            .all(|row| row["held_out_psnr_db"].as_f64().unwrap() > 5.0));
    }
    assert_eq!(runs[0]["gradient_difference_from_cpu"], 0.0);
}

/// A dataset on the user's FLAME model (here the FLAME-layout pickles
/// `visage fixtures` writes for the built-in head) trains and evaluates with
/// `--flame` and `--masks`.
#[test]
fn datasets_on_flame_files_train_with_flame_and_masks() {
    let dir = small_capture("flame");
    common::mark_captured_elsewhere(&dir);
    let fixtures = temp_path("train", "fixtures");
    std::fs::remove_dir_all(&fixtures).ok();
    let o = visage(&[
        "fixtures",
        fixtures.to_str().unwrap(),
        "--source-count",
        "1",
        "--gaussians-per-avatar",
        "500",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (model, masks) = (
        fixtures.join("flame/model.pkl"),
        fixtures.join("flame/masks.pkl"),
    );
    let flame = [
        "--flame",
        model.to_str().unwrap(),
        "--masks",
        masks.to_str().unwrap(),
    ];
    let avatar = dir.join("avatar");
    let mut args = vec![
        "train",
        dir.to_str().unwrap(),
        "-o",
        avatar.to_str().unwrap(),
    ];
    args.extend(["--iterations", "5", "--size", "24x24"]);
    args.extend(flame);
    let o = visage(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mut args = vec![
        "eval",
        avatar.to_str().unwrap(),
        dir.to_str().unwrap(),
        "--json",
    ];
    args.extend(flame);
    let o = visage(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for p in [&dir, &fixtures] {
        std::fs::remove_dir_all(p).ok();
    }
}

/// After `--resume`, the progress bar's rate counts only this run's
/// iterations: it must not start at thousands of iterations a second because
/// the checkpoint's iterations appeared at once (the bar's estimator is reset
/// after the bar is moved to the checkpoint's iteration).
#[test]
fn the_progress_rate_after_a_resume_is_this_runs_own() {
    let dir = small_capture("rate");
    let out = dir.join("avatar");
    // A long run stopped by ctrl-c after a few seconds leaves a checkpoint
    // some hundreds of iterations in.
    let o = interrupted_run(&dir, &out, None, "-INT");
    assert_eq!(
        o.status.code(),
        Some(130),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let tmux = common::tmux::Tmux::new("train-rate");
    tmux.start(&format!(
        "{} train {} -o {} --iterations 1000000 --size 16x16 --resume {}; sleep 60",
        env!("CARGO_BIN_EXE_visage"),
        dir.display(),
        out.display(),
        out.join("checkpoint.npz").display()
    ));
    let rate = |s: &str| -> Option<f64> {
        let line = s.lines().find(|l| l.contains("/1000000"))?;
        // indicatif's {per_sec}: "123.4567/s" (human-formatted, commas in thousands).
        let word = line.split_whitespace().find(|w| w.ends_with("/s"))?;
        word.trim_end_matches("/s").replace(',', "").parse().ok()
    };
    let s = tmux.wait_for(
        "the progress bar",
        std::time::Duration::from_secs(60),
        |s| rate(s).is_some_and(|r| r > 0.0),
    );
    std::thread::sleep(std::time::Duration::from_secs(2));
    let s2 = tmux.screen();
    let r = rate(&s2).or(rate(&s)).unwrap();
    assert!(
        r < 1000.0,
        "{r} it/s right after resuming from iteration 300:\n{s2}"
    );
    drop(tmux);
    std::fs::remove_dir_all(&dir).ok();
}

/// A trained avatar that cannot be written is a failed write (exit 4, "cannot
/// …"), not bad input: the dataset and the arguments were fine.
#[test]
fn an_unwritable_output_is_an_io_error_not_bad_input() {
    let dir = small_capture("unwritable");
    let o = visage(&[
        "train",
        dir.to_str().unwrap(),
        "-o",
        "/proc/visage-no-such-dir/avatar",
        "--iterations",
        "2",
        "--size",
        "16x16",
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(4), "{err}");
    let last = err.trim().lines().last().unwrap_or("");
    assert!(
        last.contains("cannot") && last.contains("/proc/visage-no-such-dir"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
