//! Building a database from a manifest (`visage train --manifest`): shards
//! take each subject once, a killed run resumes its checkpoint to the same
//! bytes a plain `visage train` writes, two processes given the same shard
//! never train a subject twice, bad manifests fail in one line touching
//! nothing, and `visage db check/index/status` report and index the folder.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{same_avatar, temp_path, tiny_manifest, visage};

fn fresh(name: &str) -> PathBuf {
    let dir = temp_path("farm", name);
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn ok(o: &Output) -> String {
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "failed: {err}");
    err
}

fn run_shard(manifest: &Path, shard: &str) -> Output {
    visage(&[
        "train",
        "--manifest",
        manifest.to_str().unwrap(),
        "--shard",
        shard,
    ])
}

/// `visage train --manifest M --shard S` started in the background.
fn spawn_shard(manifest: &Path, shard: &str, stderr: Stdio) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .args([
            "train",
            "--manifest",
            manifest.to_str().unwrap(),
            "--shard",
            shard,
        ])
        .stderr(stderr)
        .spawn()
        .unwrap()
}

fn status_json(manifest: &Path) -> serde_json::Value {
    let o = visage(&["db", "status", manifest.to_str().unwrap(), "--json"]);
    serde_json::from_slice(&o.stdout).expect("db status prints JSON")
}

fn state_of(status: &serde_json::Value, id: &str) -> String {
    status["subjects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .unwrap()["state"]
        .as_str()
        .unwrap()
        .to_string()
}

/// A manifest of `count` tiny subjects whose datasets are captured.
fn captured(dir: &Path, count: usize, iterations: usize, every: usize) -> PathBuf {
    let manifest = tiny_manifest(dir, "db", count, iterations, every);
    ok(&visage(&[
        "capture",
        "--manifest",
        manifest.to_str().unwrap(),
    ]));
    manifest
}

#[test]
fn a_killed_subject_resumes_to_the_bytes_of_a_plain_run() {
    let dir = fresh("resume");
    let manifest = captured(&dir, 2, 160, 20);
    // The same subject trained by plain `visage train`.
    let plain = dir.join("plain");
    ok(&visage(&[
        "train",
        dir.join("captures/ada").to_str().unwrap(),
        "-o",
        plain.to_str().unwrap(),
        "--iterations",
        "160",
        "--size",
        "32x32",
        "--renderer",
        "cpu",
        "--seed",
        "1",
    ]));
    // Shard 0 of 2 is ada alone: kill -9 it once a checkpoint is written.
    let mut child = spawn_shard(&manifest, "0/2", Stdio::null());
    let progress = dir.join("db/.work/ada/progress");
    let start = Instant::now();
    loop {
        let text = std::fs::read_to_string(&progress).unwrap_or_default();
        let checkpointed: usize = text
            .split_whitespace()
            .nth(2)
            .and_then(|w| w.parse().ok())
            .unwrap_or(0);
        if checkpointed > 0 {
            assert!(
                checkpointed < 160,
                "the run ended before it could be killed"
            );
            break;
        }
        assert!(
            child.try_wait().unwrap().is_none(),
            "the shard ended before a checkpoint"
        );
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "no checkpoint in 2 minutes"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    child.kill().unwrap(); // SIGKILL: no chance to clean up
    child.wait().unwrap();
    let status = status_json(&manifest);
    assert_eq!(state_of(&status, "ada"), "interrupted", "{status}");
    assert_eq!(state_of(&status, "bram"), "not_started");
    assert!(!dir.join("db/ada").exists(), "no half avatar is published");

    let err = ok(&run_shard(&manifest, "0/2"));
    assert!(err.contains("ada: trained (resumed at iteration"), "{err}");
    // subject.json is the manifest's own record; the avatar is the same.
    for f in ["point_cloud.ply", "flame_param.npz", "training.json"] {
        let (ours, theirs) = (dir.join("db/ada").join(f), plain.join(f));
        assert_eq!(
            std::fs::read(ours).unwrap(),
            std::fs::read(theirs).unwrap(),
            "{f}"
        );
    }
    assert!(!dir.join("db/.work/ada/checkpoint.npz").exists());
    let work: Vec<String> = std::fs::read_dir(dir.join("db/.work/ada"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !work.iter().any(|n| n.starts_with("avatar.partial")),
        "{work:?}"
    );
    // Finished subjects are validated and skipped.
    let err = ok(&run_shard(&manifest, "0/2"));
    assert!(err.contains("ada: finished already, skipped"), "{err}");
    assert_eq!(state_of(&status_json(&manifest), "ada"), "done");
}

#[test]
fn two_processes_given_one_shard_train_each_subject_once() {
    let dir = fresh("double");
    let manifest = captured(&dir, 3, 60, 20);
    let spawn = || spawn_shard(&manifest, "0/1", Stdio::piped());
    let (a, b) = (spawn(), spawn());
    let logs: String = [a, b]
        .into_iter()
        .map(|c| ok(&c.wait_with_output().unwrap()))
        .collect();
    assert!(
        logs.contains("being trained by host"),
        "the lock never met the other process:\n{logs}"
    );
    for id in ["ada", "bram", "cleo"] {
        let trained = logs.matches(&format!("{id}: trained")).count();
        assert_eq!(trained, 1, "{id} trained {trained} times:\n{logs}");
        assert_eq!(state_of(&status_json(&manifest), id), "done");
    }
    // The same result as one process alone: retrain into another folder.
    let again = dir.join("again.toml");
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &again,
        text.replace("output = \"db\"", "output = \"db-again\""),
    )
    .unwrap();
    ok(&run_shard(&again, "0/1"));
    for id in ["ada", "bram", "cleo"] {
        assert!(
            same_avatar(&dir.join("db").join(id), &dir.join("db-again").join(id)),
            "{id}"
        );
    }
}

#[test]
fn bad_manifests_fail_in_one_line_and_touch_no_finished_subject() {
    let dir = fresh("bad");
    let manifest = captured(&dir, 2, 30, 10);
    ok(&run_shard(&manifest, "0/1"));
    let finished = std::fs::read(dir.join("db/ada/point_cloud.ply")).unwrap();
    let text = std::fs::read_to_string(&manifest).unwrap();
    let write = |name: &str, body: String| {
        let p = dir.join(name);
        std::fs::write(&p, body).unwrap();
        p
    };
    std::fs::create_dir_all(dir.join("junk")).unwrap();
    std::fs::write(dir.join("junk/readme.txt"), "not a dataset").unwrap();
    let cases: Vec<(PathBuf, Vec<&str>, &str)> = vec![
        (
            write(
                "missing.toml",
                text.replace("captures/bram", "captures/nobody"),
            ),
            vec![],
            "captures/nobody",
        ),
        (
            write("layout.toml", text.replace("captures/bram", "junk")),
            vec![],
            "bram",
        ),
        (
            write("twice.toml", text.replace("id = \"bram\"", "id = \"ada\"")),
            vec![],
            "listed twice",
        ),
        (
            write("typo.toml", text.replace("iterations", "iteratoins")),
            vec![],
            "iteratoins",
        ),
        (
            write(
                "path.toml",
                text.replace("id = \"bram\"", "id = \"../bram\""),
            ),
            vec![],
            "plain folder name",
        ),
        (manifest.clone(), vec!["--shard", "2/2"], "I/N"),
    ];
    for (path, extra, says) in cases {
        let mut args = vec!["train", "--manifest", path.to_str().unwrap()];
        args.extend(extra);
        let o = visage(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{}: {err}", path.display());
        assert!(err.contains(says), "{}: {err}", path.display());
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    // A Slurm task outside the array's range.
    let o = Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .env("SLURM_ARRAY_TASK_ID", "5")
        .env("SLURM_ARRAY_TASK_MIN", "0")
        .env("SLURM_ARRAY_TASK_MAX", "3")
        .env("SLURM_ARRAY_TASK_COUNT", "4")
        .args(["train", "--manifest", manifest.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("SLURM_ARRAY_TASK_ID 5"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert_eq!(
        std::fs::read(dir.join("db/ada/point_cloud.ply")).unwrap(),
        finished
    );
}

#[test]
fn db_check_index_and_status_report_the_folder() {
    let dir = fresh("check");
    let manifest = captured(&dir, 3, 30, 10);
    // Train two of three: cleo stays missing.
    ok(&run_shard(&manifest, "0/3"));
    ok(&run_shard(&manifest, "1/3"));
    let db = dir.join("db");
    // A folder with no avatars in it is no database.
    let o = visage(&["db", "check", dir.join("captures").to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("holds no avatar folders"));
    let o = visage(&["db", "check", db.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    ok(&o);
    assert!(out.contains("ada") && out.contains("bram"), "{out}");
    let o = visage(&[
        "db",
        "check",
        "--manifest",
        manifest.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let status_of = |name: &str| {
        doc["avatars"]
            .as_array()
            .unwrap()
            .iter()
            .find(|a| a["name"] == name)
            .unwrap()["status"]
            .clone()
    };
    assert_eq!(status_of("ada"), "ok");
    assert_eq!(status_of("cleo"), "missing");
    let ada = doc["avatars"]
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "ada")
        .unwrap();
    assert!(ada["gaussians"].as_u64().unwrap() > 1000);
    assert_eq!(ada["iterations"], 30);
    assert!(ada["psnr_db"].as_f64().unwrap() > 5.0, "{ada}");

    // A damaged avatar is reported and left out of the index.
    let ply = db.join("bram/point_cloud.ply");
    let bytes = std::fs::read(&ply).unwrap();
    std::fs::write(&ply, &bytes[..bytes.len() / 2]).unwrap();
    let o = visage(&["db", "index", db.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("bram") && out.contains("bad"), "{out}");
    let index: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(db.join("index.json")).unwrap()).unwrap();
    let names: Vec<&str> = index["avatars"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["ada"]);
    // The editor's database loader reads the index: bram is not loaded.
    let o = visage(&["info", "--db", db.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    ok(&o);
    assert!(out.contains("sources (1)"), "{out}");
    assert!(!out.contains("bram"), "{out}");
    // An index naming a folder that went away says to index again.
    std::fs::rename(db.join("ada"), db.join("ada-moved")).unwrap();
    let o = visage(&["info", "--db", db.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("visage db index"), "{err}");
}

#[test]
fn a_subject_trained_with_other_options_is_outdated_and_replaced() {
    let dir = fresh("outdated");
    let manifest = captured(&dir, 1, 20, 10);
    ok(&run_shard(&manifest, "0/1"));
    let before = std::fs::read(dir.join("db/ada/training.json")).unwrap();
    // The manifest now asks for more iterations.
    let text = std::fs::read_to_string(&manifest).unwrap();
    std::fs::write(
        &manifest,
        text.replace("iterations = 20", "iterations = 30"),
    )
    .unwrap();
    assert_eq!(state_of(&status_json(&manifest), "ada"), "outdated");
    let o = visage(&["db", "check", "--manifest", manifest.to_str().unwrap()]);
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    assert!(out.contains("outdated"), "{out}");
    let err = ok(&run_shard(&manifest, "0/1"));
    assert!(err.contains("ada: trained"), "{err}");
    let after: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("db/ada/training.json")).unwrap()).unwrap();
    assert_eq!(after["iterations"], 30);
    assert_ne!(
        std::fs::read(dir.join("db/ada/training.json")).unwrap(),
        before
    );
    let work: Vec<String> = std::fs::read_dir(dir.join("db/.work/ada"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !work
            .iter()
            .any(|n| n.starts_with("avatar.partial") || n == "replaced"),
        "{work:?}"
    );
    assert_eq!(state_of(&status_json(&manifest), "ada"), "done");
}

/// A subject on the user's FLAME files (`flame`/`masks` in the manifest,
/// relative to it) trains, and is the same finished subject whichever way
/// the manifest's own path is typed; `db check --manifest` checks it on its
/// FLAME files.
#[test]
fn subjects_on_flame_files_train_and_stay_finished_under_any_manifest_path() {
    let dir = fresh("flame");
    let manifest = captured(&dir, 1, 10, 5);
    common::mark_captured_elsewhere(&dir.join("captures/ada"));
    ok(&visage(&[
        "fixtures",
        dir.join("fixtures").to_str().unwrap(),
        "--source-count",
        "1",
        "--gaussians-per-avatar",
        "500",
    ]));
    // Without FLAME files the dataset is refused before anything trains.
    let o = run_shard(&manifest, "0/1");
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--flame and --masks"));
    let text = std::fs::read_to_string(&manifest).unwrap();
    let text = text.replace(
        "renderer = \"cpu\"\n",
        "renderer = \"cpu\"\nflame = \"fixtures/flame/model.pkl\"\nmasks = \"fixtures/flame/masks.pkl\"\n",
    );
    std::fs::write(&manifest, text).unwrap();
    ok(&run_shard(&manifest, "0/1"));
    // The same manifest reached through another path: still finished.
    let other = dir
        .join("..")
        .join(dir.file_name().unwrap())
        .join("db.toml");
    let err = ok(&run_shard(&other, "0/1"));
    assert!(err.contains("ada: finished already"), "{err}");
    assert_eq!(state_of(&status_json(&other), "ada"), "done");
    ok(&visage(&[
        "db",
        "check",
        "--manifest",
        manifest.to_str().unwrap(),
    ]));
}

/// A capture killed midway leaves its half-written folder; the next capture
/// on the same machine removes it once its process is gone, and leaves
/// another machine's (whose writer it cannot see) alone.
#[test]
fn half_written_captures_of_dead_processes_are_removed() {
    let dir = fresh("partials");
    let manifest = tiny_manifest(&dir, "db", 1, 10, 5);
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .unwrap()
        .trim()
        .replace(['/', '-'], "_");
    let mut gone = Command::new("true").spawn().unwrap();
    let dead_pid = gone.id();
    gone.wait().unwrap();
    std::fs::create_dir_all(dir.join("captures")).unwrap();
    let dead = dir.join(format!("captures/ada.partial-{host}-{dead_pid}"));
    let elsewhere = dir.join("captures/ada.partial-othermachine-12");
    for d in [&dead, &elsewhere] {
        std::fs::create_dir_all(d).unwrap();
        std::fs::write(d.join("transforms_train.json"), "{").unwrap();
    }
    ok(&visage(&[
        "capture",
        "--manifest",
        manifest.to_str().unwrap(),
    ]));
    assert!(!dead.exists(), "the dead process's half capture is gone");
    assert!(elsewhere.exists(), "another machine's is left alone");
    assert!(dir.join("captures/ada/transforms_train.json").exists());
}
