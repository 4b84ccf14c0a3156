//! Building a database on a real Slurm cluster: `.ci/slurm-up` starts a
//! single-node cluster (munged, slurmctld, slurmd; two CPU slots), and the
//! array script users copy (`deploy/slurm/visage-array.sbatch`) trains a
//! manifest of six subjects as a four-task array. One task is cancelled mid
//! training (`scancel`), the array is resubmitted, and every subject must end
//! trained exactly once, byte for byte what a single process writes.
//!
//! Needs Debian's slurm-wlm and munge (`.ci/setup` installs them).

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use common::{same_avatar, temp_path, tiny_manifest, visage, MANIFEST_PEOPLE};

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// Starts (or finds) the local cluster and returns its SLURM_CONF.
fn cluster() -> String {
    let o = Command::new(repo().join(".ci/slurm-up"))
        .output()
        .expect("bash runs .ci/slurm-up");
    assert!(
        o.status.success(),
        "the local Slurm cluster did not start (install slurm-wlm and munge: .ci/setup does): {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).trim().to_string()
}

fn slurm(conf: &str, tool: &str, args: &[&str]) -> Output {
    let o = Command::new(tool)
        .env("SLURM_CONF", conf)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{tool}: {e}"));
    assert!(
        o.status.success(),
        "{tool} {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    o
}

/// Submits the array script over `manifest` from `dir`; `wait`: block until
/// the array ends. Returns the job id.
fn submit(conf: &str, dir: &Path, manifest: &Path, wait: bool) -> String {
    let script = repo().join("deploy/slurm/visage-array.sbatch");
    let chdir = format!("--chdir={}", dir.display());
    let export = format!(
        "--export=ALL,VISAGE={},NODEVICE_SELECT=1",
        env!("CARGO_BIN_EXE_visage")
    );
    let mut args = vec!["--parsable", "--array=0-3", &chdir, &export];
    if wait {
        args.push("--wait");
    }
    let (script, manifest) = (script.to_str().unwrap(), manifest.to_str().unwrap());
    args.extend([script, manifest]);
    let o = slurm(conf, "sbatch", &args);
    let out = String::from_utf8_lossy(&o.stdout);
    out.trim().split(';').next().unwrap().to_string()
}

/// Waits until no task of `job` is queued or running.
fn wait_for(conf: &str, job: &str) {
    let start = Instant::now();
    loop {
        let o = slurm(conf, "squeue", &["-h", "-j", job, "-o", "%i"]);
        if o.stdout.iter().all(|b| b.is_ascii_whitespace()) {
            return;
        }
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "job {job} still queued after 5 minutes"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}

fn status(manifest: &Path) -> serde_json::Value {
    let o = visage(&["db", "status", manifest.to_str().unwrap(), "--json"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn subject<'a>(status: &'a serde_json::Value, id: &str) -> &'a serde_json::Value {
    status["subjects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["id"] == id)
        .unwrap()
}

fn logs(dir: &Path) -> String {
    let mut names: Vec<PathBuf> = std::fs::read_dir(dir.join("logs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    names
        .iter()
        .map(|p| std::fs::read_to_string(p).unwrap())
        .collect()
}

#[test]
fn a_cancelled_array_task_resumes_and_every_subject_is_trained_once() {
    let conf = cluster();
    let dir = temp_path("slurm", "array");
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(dir.join("logs")).unwrap();
    // ada, the subject cancelled, trains longest, so the cancellation lands
    // long before it could finish.
    let longer_ada = |path: PathBuf| {
        let text = std::fs::read_to_string(&path).unwrap();
        let text = text.replacen("seed = 1\n", "seed = 1\niterations = 300\n", 1);
        std::fs::write(&path, text).unwrap();
        path
    };
    let manifest = longer_ada(tiny_manifest(&dir, "db", 6, 100, 10));
    // The reference: the same subjects in one process.
    let reference = longer_ada(tiny_manifest(&dir, "reference", 6, 100, 10));
    let m = reference.to_str().unwrap();
    for command in ["capture", "train"] {
        let o = visage(&[command, "--manifest", m]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }

    // Task 0 holds ada then elif: cancel it once ada has a checkpoint.
    let job = submit(&conf, &dir, &manifest, false);
    let start = Instant::now();
    loop {
        let s = status(&manifest);
        let ada = subject(&s, "ada");
        if ada["state"] == "running" && ada["progress"]["checkpointed"].as_u64() > Some(0) {
            break;
        }
        assert_ne!(
            ada["state"], "done",
            "ada finished before it could be cancelled"
        );
        assert!(
            start.elapsed() < Duration::from_secs(120),
            "ada never checkpointed: {s}"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    slurm(&conf, "scancel", &[&format!("{job}_0")]);
    wait_for(&conf, &job);
    let s = status(&manifest);
    assert_eq!(subject(&s, "ada")["state"], "interrupted", "{s}");
    assert_eq!(subject(&s, "elif")["state"], "not_started", "{s}");
    for id in ["bram", "cleo", "dries", "femi"] {
        assert_eq!(subject(&s, id)["state"], "done", "{id}: {s}");
    }
    assert!(
        !dir.join("db/ada").exists(),
        "a cancelled subject publishes nothing"
    );

    // The same array again: only what is left is trained.
    let again = submit(&conf, &dir, &manifest, true);
    wait_for(&conf, &again);
    let all = logs(&dir);
    assert!(all.contains("stopped by SIGTERM"), "{all}");
    assert!(all.contains("ada: trained (resumed at iteration"), "{all}");
    for id in MANIFEST_PEOPLE {
        assert_eq!(subject(&status(&manifest), id)["state"], "done");
        let trained = all.matches(&format!("{id}: trained")).count();
        assert_eq!(trained, 1, "{id} was trained {trained} times:\n{all}");
        assert!(
            same_avatar(&dir.join("db").join(id), &dir.join("reference").join(id)),
            "{id} differs from the single-process run"
        );
    }
}
