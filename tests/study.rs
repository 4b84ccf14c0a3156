//! The study's analysis against the thesis's published numbers, and the
//! study workflow through the command line.

use std::path::Path;

use visage::compose::composition::Attributes;
use visage::compose::recipe::{Fit, PostProcess, Recipe, Smoothing};
use visage::compose::rules::Rules;
use visage::study::analysis::{analyse, Analysis, AnalysisOptions};
use visage::study::results::Results;

fn thesis(exclude: bool) -> (Results, Analysis) {
    let dir = Path::new("studies/thesis");
    let results = Results::load(&dir.join("results.toml")).unwrap();
    let options = AnalysisOptions {
        exclude: exclude.then(|| Rules::load(&dir.join("exclusions.toml")).unwrap()),
        attributes: Attributes::load(&dir.join("attributes.toml")).unwrap(),
        ..AnalysisOptions::default()
    };
    let analysis = analyse(&results, &options).unwrap();
    (results, analysis)
}

fn rounded(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

/// Figures 6.2 and 6.3: the category means before and after excluding
/// implausible composites, from the per-avatar scores of Appendix B and the
/// exclusion rules of §6.3.1.
#[test]
fn thesis_category_means_are_reproduced_before_and_after_exclusion() {
    let (_, analysis) = thesis(true);
    let table: Vec<(String, f64, Option<f64>, usize)> = analysis
        .categories
        .iter()
        .map(|c| {
            let all = c.all.unwrap();
            (
                c.category.clone(),
                rounded(all.mean),
                c.kept.map(|k| rounded(k.mean)),
                c.kept.map_or(0, |k| k.avatars),
            )
        })
        .collect();
    let expected = [
        ("unedited_original", 0.80, 0.80, 7),
        ("unedited_filling", 0.79, 0.79, 7),
        ("edit_original", 0.19, 0.26, 5),
        ("edit_filling", 0.15, 0.34, 6),
        ("edit_filling_smooth", 0.16, 0.43, 4),
    ];
    assert_eq!(table.len(), expected.len());
    for ((name, all, kept, n), (e_name, e_all, e_kept, e_n)) in table.iter().zip(expected) {
        assert_eq!(name, e_name);
        assert_eq!(*all, e_all, "{name} before exclusion");
        assert_eq!(*kept, Some(e_kept), "{name} after exclusion");
        assert_eq!(*n, e_n, "{name}: avatars kept");
    }
    for c in &analysis.categories {
        let all = c.all.unwrap();
        assert!(all.low < all.mean && all.mean < all.high, "{c:?}");
    }
}

/// The rules derive Appendix C: the same 30 avatars, for the same reasons.
#[test]
fn thesis_exclusion_rules_give_appendix_c() {
    let (results, analysis) = thesis(true);
    let mut excluded = 0;
    let mut differ = Vec::new();
    for (published, scored) in results.avatars.iter().zip(&analysis.avatars) {
        assert_eq!(published.id, scored.id);
        let mut derived = scored.excluded.clone();
        let mut listed = published.excluded.clone();
        derived.sort();
        listed.sort();
        if derived != listed {
            differ.push(format!(
                "avatar {}: rules {derived:?}, Appendix C {listed:?}",
                published.id
            ));
        }
        excluded += usize::from(!derived.is_empty());
    }
    assert!(differ.is_empty(), "{}", differ.join("\n"));
    assert_eq!(excluded, 30);
}

mod common;

use common::tmux::{wait_file, Tmux};
use common::visage;
use std::time::Duration;
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::composition::Composition;
use visage::compose::rules::Context;

fn temp(name: &str) -> std::path::PathBuf {
    let path = common::temp_path("study", name);
    std::fs::remove_dir_all(&path).ok();
    path
}

fn stdout(out: &std::process::Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

fn files(dir: &Path) -> Vec<(String, String)> {
    let mut list: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .map(|p| {
            (
                p.file_name().unwrap().to_string_lossy().into_owned(),
                std::fs::read_to_string(&p).unwrap(),
            )
        })
        .collect();
    list.sort();
    list
}

/// The README's command remakes the committed study recipes exactly, and
/// every composite meets the built-in constraints.
#[test]
fn random_composites_repeat_from_their_seed_and_meet_the_constraints() {
    let out = temp("random");
    stdout(&visage(&[
        "random",
        "--constraints",
        "studies/builtin/constraints.toml",
        "--count",
        "10",
        "--seed",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]));
    let committed = files(Path::new("studies/builtin/random"));
    assert_eq!(files(&out), committed);
    assert_eq!(committed.len(), 10);

    let db = builtin_database(
        visage::model::builtin::build_head(),
        SyntheticOptions {
            seed: 1,
            sources: 14,
            gaussians_per_avatar: 200,
        },
    )
    .unwrap();
    let labels = Attributes::of_database(&db);
    let rules = Rules::load(Path::new("studies/builtin/constraints.toml")).unwrap();
    for (name, text) in &committed {
        let recipe = Recipe::from_toml(text).unwrap();
        recipe.resolve(&db).unwrap();
        let c = Composition::of_recipe(&recipe);
        assert!(c.is_composite(), "{name}");
        assert!(c.gaussian_sources().len() >= 2, "{name}");
        let broken = rules.broken(&c, Context::default(), &labels).unwrap();
        assert!(broken.is_empty(), "{name}: {broken:?}");
    }

    // Another seed draws other composites.
    let other = temp("random-other");
    stdout(&visage(&[
        "random",
        "--count",
        "10",
        "--seed",
        "2",
        "--out",
        other.to_str().unwrap(),
    ]));
    assert_ne!(files(&other), committed);
}

#[test]
fn bad_study_input_fails_with_one_line_and_exit_2() {
    let out = temp("bad");
    let o = out.to_str().unwrap();
    let bad_rules = temp("bad-rules.toml");
    std::fs::write(&bad_rules, "[[rule]]\nreason = \"x\"\n").unwrap();
    let cases: Vec<Vec<&str>> = vec![
        vec!["random", "--sources", "ada,bram", "--out", o],
        vec!["random", "--sources", "ada,bram,zed", "--out", o],
        vec!["random", "--groups", "nhe", "--out", o],
        vec![
            "random",
            "--constraints",
            bad_rules.to_str().unwrap(),
            "--out",
            o,
        ],
        vec!["study", "build", "studies/thesis/results.toml", "--out", o],
        vec!["study", "run", "studies", "--participant", "x"],
        vec!["study", "analyse", "studies/nothing.toml"],
        vec![
            "study",
            "analyse",
            "studies/thesis/results.toml",
            "--exclude",
            "studies/thesis/attributes.toml",
        ],
    ];
    for args in cases {
        let out = visage(&args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    }
    // Rules that need a label the study lacks name it.
    let out = visage(&[
        "study",
        "analyse",
        "studies/thesis/results.toml",
        "--exclude",
        "studies/thesis/exclusions.toml",
    ]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("attribute"));
}

/// A category's `post` names a preset: "ours" gives every avatar the best
/// measured post-processing, seam fit included (what the editor starts
/// from); a preset nobody knows is one line and exit 2.
#[test]
fn a_category_post_names_a_preset() {
    let dir = temp("preset");
    std::fs::create_dir_all(&dir).unwrap();
    let spec = dir.join("spec.toml");
    let write = |post: &str| {
        std::fs::write(
            &spec,
            format!(
                "[[category]]\nname = \"edited\"\ndatabase = {{ db = \"builtin\", gaussians_per_avatar = 500 }}\npost = {post}\nunedited = [\"ada\", \"bram\"]\n"
            ),
        )
        .unwrap();
    };
    let out = dir.join("built");
    let build = || {
        visage(&[
            "study",
            "build",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
    };
    write("\"ours\"");
    stdout(&build());
    let recipe = Recipe::load(&out.join("recipes/001.toml")).unwrap();
    assert_eq!(recipe.post, PostProcess::BEST);
    assert_eq!(recipe.post.fit, Fit::Seams);
    let text = std::fs::read_to_string(out.join("recipes/001.toml")).unwrap();
    assert!(text.contains("fit = \"seams\""), "{text}");

    write("\"best\"");
    std::fs::remove_dir_all(&out).ok();
    let failed = build();
    let err = String::from_utf8_lossy(&failed.stderr);
    assert_eq!(failed.status.code(), Some(2), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains("unknown preset 'best'"), "{err}");

    // A table still works, as before.
    write("{ smoothing = \"thesis\" }");
    std::fs::remove_dir_all(&out).ok();
    stdout(&build());
    let recipe = Recipe::load(&out.join("recipes/001.toml")).unwrap();
    assert_eq!(recipe.post.smoothing, Smoothing::Thesis);
    assert_eq!(recipe.post.fit, Fit::Off);
}

/// `study build` fits each edited avatar's seams into the study's fits/
/// folder (so `study run` need not), or leaves that to the run with
/// `--seam-fit 0`.
#[test]
fn study_build_fits_the_edited_avatars_seams_into_the_folder() {
    let dir = temp("fits");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(
        dir.join("nose.toml"),
        "base = \"ada\"\n[groups.nose]\ngaussians = \"bram\"\nshape = { bram = 1.0 }\n",
    )
    .unwrap();
    let spec = dir.join("spec.toml");
    std::fs::write(
        &spec,
        "[[category]]\nname = \"edited\"\ndatabase = { db = \"builtin\", gaussians_per_avatar = 500 }\npost = \"ours\"\nrecipes = [\"nose.toml\"]\nunedited = [\"ada\"]\n",
    )
    .unwrap();
    let fits =
        |out: &Path| -> usize { std::fs::read_dir(out.join("fits")).map_or(0, |d| d.count()) };
    let build = |out: &Path, fit: &[&str]| {
        let args = [
            "study",
            "build",
            spec.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        visage(&[&args[..], fit].concat())
    };
    let out = dir.join("built");
    let o = build(&out, &["--seam-fit", "2", "--seam-fit-size", "16"]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    stdout(&o);
    assert!(err.contains("fitted the seams of 1 avatar into"), "{err}");
    // The unedited avatar has no seam: only the edited one is kept.
    assert_eq!(fits(&out), 1, "{err}");
    // Built again (a kill in the middle, say): the fit is found, not redone.
    let o = build(&out, &["--seam-fit", "2", "--seam-fit-size", "16"]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    stdout(&o);
    assert!(
        err.contains("1 of them there from an earlier build"),
        "{err}"
    );
    assert_eq!(fits(&out), 1, "{err}");
    // Under other options: the new fit replaces the one no run would use.
    let o = build(&out, &["--seam-fit", "2", "--seam-fit-size", "20"]);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    stdout(&o);
    assert!(!err.contains("earlier build"), "{err}");
    assert!(
        err.contains("removed 1 fit of no avatar of this build"),
        "{err}"
    );
    assert_eq!(fits(&out), 1, "{err}");
    let lazy = dir.join("lazy");
    stdout(&build(&lazy, &["--seam-fit", "0"]));
    assert_eq!(fits(&lazy), 0);
}

/// `study analyse` from the command line: JSON with the thesis's numbers
/// and the two plots.
#[test]
fn analyse_prints_json_and_writes_plots() {
    let plots = temp("plots");
    let out = stdout(&visage(&[
        "study",
        "analyse",
        "studies/thesis/results.toml",
        "--attributes",
        "studies/thesis/attributes.toml",
        "--exclude",
        "studies/thesis/exclusions.toml",
        "--json",
        "--resamples",
        "2000",
        "--plots",
        plots.to_str().unwrap(),
    ]));
    let json: serde_json::Value = serde_json::from_str(&out).unwrap();
    let smooth = &json["categories"][4];
    assert_eq!(smooth["category"], "edit_filling_smooth");
    assert_eq!(rounded(smooth["kept"]["mean"].as_f64().unwrap()), 0.43);
    assert_eq!(json["avatars"].as_array().unwrap().len(), 59);
    for name in ["authenticity.png", "regions.png"] {
        let img = image::open(plots.join(name)).unwrap().to_rgb8();
        assert!(img.width() >= 1000, "{name}");
        // Not blank: the bars put colour on the white canvas.
        let coloured = img.pixels().filter(|p| p.0 != [255, 255, 255]).count();
        assert!(coloured > 10_000, "{name}: {coloured}");
    }
}

/// The end-to-end run: build the built-in study (10 random
/// composites, 4 unedited sources), two participants answer in tmux — the
/// first is killed halfway and resumes — and the analysis counts both.
#[test]
fn two_participants_run_the_study_in_tmux_and_survive_a_kill() {
    let dir = temp("e2e");
    let d = dir.to_str().unwrap();
    stdout(&visage(&[
        "study",
        "build",
        "studies/builtin/spec.toml",
        "--out",
        d,
        "--seam-fit",
        "0",
    ]));
    let long = Duration::from_secs(90);
    let run = |tmux: &Tmux, who: &str, status: &Path| {
        std::fs::remove_file(status).ok();
        tmux.start(&format!(
            "{} study run {d} --participant {who} --graphics halfblocks --renderer cpu --seam-fit 0 2>/dev/null; echo EXIT=$? > {}; sleep 60",
            env!("CARGO_BIN_EXE_visage"),
            status.display()
        ));
    };
    let at = |k: usize| format!("avatar {k} of 14");

    // Alice says "not edited" to five avatars, then her terminal dies.
    let alice = Tmux::new("study-alice");
    let status = common::temp_path("study", "alice-status");
    run(&alice, "alice", &status);
    for k in 1..=5 {
        alice.wait_for(&at(k), long, |s| {
            s.contains(&at(k)) && s.contains("y = yes")
        });
        alice.keys(&["n"]);
    }
    alice.wait_for(&at(6), long, |s| s.contains(&at(6)));
    let journal = dir.join("answers/alice.jsonl");
    assert_eq!(
        std::fs::read_to_string(&journal).unwrap().lines().count(),
        6
    );
    std::process::Command::new("pkill")
        .args(["-9", "-f", "participant alice"])
        .status()
        .unwrap();
    drop(alice);

    // She starts again and goes on from the sixth.
    let alice = Tmux::new("study-alice-again");
    run(&alice, "alice", &status);
    for k in 6..=14 {
        alice.wait_for(&at(k), long, |s| {
            s.contains(&at(k)) && s.contains("y = yes")
        });
        alice.keys(&["n"]);
    }
    let s = wait_file(&status, long);
    assert_eq!(s.trim(), "EXIT=0", "{}", alice.screen());

    // Bob finds every face edited, around the eyes; at the third he goes
    // back once to the second (not final yet) and answers it again.
    let bob = Tmux::new("study-bob");
    let bob_status = common::temp_path("study", "bob-status");
    run(&bob, "bob", &bob_status);
    let mut k = 1;
    let mut went_back = false;
    while k <= 14 {
        let s = bob.wait_for(&at(k), long, |s| {
            s.contains(&at(k)) && s.contains("y = yes")
        });
        if k == 1 {
            assert!(!s.contains("b: back"), "nothing to go back to:\n{s}");
        }
        if k == 3 && !went_back {
            assert!(s.contains("b: back to the last avatar"), "{s}");
            went_back = true;
            bob.keys(&["b"]);
            k = 2;
            continue;
        }
        bob.keys(&["y"]);
        bob.wait_for("the parts", long, |s| s.contains("Which parts"));
        bob.keys(&["1", "Enter"]);
        k += 1;
    }
    assert_eq!(wait_file(&bob_status, long).trim(), "EXIT=0");

    // Carol's terminal is too small at first, then she is stopped by SIGTERM
    // before answering: exit 143, and `status` counts her with 0 s (not -0 s).
    let carol = Tmux::new("study-carol");
    let carol_status = common::temp_path("study", "carol-status");
    std::fs::remove_file(&carol_status).ok();
    carol.start_sized(
        &format!(
            "{} study run {d} --participant carol --graphics halfblocks --renderer cpu --seam-fit 0 2>/dev/null; echo EXIT=$? > {}; sleep 60",
            env!("CARGO_BIN_EXE_visage"),
            carol_status.display()
        ),
        40,
        10,
    );
    carol.wait_for("the size message", long, |s| {
        s.contains("50x14") && s.contains("40x10")
    });
    carol.resize(100, 30);
    carol.wait_for(&at(1), long, |s| s.contains(&at(1)));
    let pid = carol.program_pid().expect("the study runs");
    std::process::Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap();
    assert_eq!(wait_file(&carol_status, long).trim(), "EXIT=143");
    let status_text = stdout(&visage(&["study", "status", d]));
    assert!(status_text.contains("carol"), "{status_text}");
    assert!(!status_text.contains("-0 s"), "{status_text}");

    let answers = |who: &str| -> Vec<u64> {
        std::fs::read_to_string(dir.join(format!("answers/{who}.jsonl")))
            .unwrap()
            .lines()
            .skip(1)
            .map(|l| {
                serde_json::from_str::<serde_json::Value>(l).unwrap()["avatar"]
                    .as_u64()
                    .unwrap()
            })
            .collect()
    };
    let (a, b) = (answers("alice"), answers("bob"));
    assert_eq!(a.len(), 14, "each avatar once, the kill lost nothing");
    assert_eq!(b.len(), 15, "Bob answered his second avatar twice");
    assert_eq!(b[1], b[2], "the second answer to it follows the first");
    let mut sorted = a.clone();
    sorted.sort();
    assert_eq!(sorted, (1..=14).collect::<Vec<u64>>());
    assert_ne!(a, b, "each participant has their own order");

    let json: serde_json::Value = serde_json::from_str(&stdout(&visage(&[
        "study",
        "analyse",
        d,
        "--json",
        "--resamples",
        "500",
    ])))
    .unwrap();
    for avatar in json["avatars"].as_array().unwrap() {
        assert_eq!(avatar["answers"], 2, "{avatar} (Carol answered nothing)");
        assert_eq!(avatar["authenticity"], 0.5, "{avatar}");
    }
    for c in json["categories"].as_array().unwrap() {
        assert_eq!(c["all"]["mean"], 0.5, "{c}");
    }
    let eyes_unedited = json["regions"]
        .as_array()
        .unwrap()
        .iter()
        .find(|r| r["category"] == "unedited" && r["group"] == "eyes")
        .unwrap();
    assert_eq!(eyes_unedited["unedited"]["mean"], 0.5);
}

/// Labels from a GaussianAvatars folder's `attributes.toml` drive the
/// constraints: with one source labelled dark and "one skin tone" required,
/// its Gaussians never appear (it may still lend shape).
#[test]
fn avatar_folder_attributes_constrain_random_composites() {
    let dir = temp("fixtures");
    let d = dir.to_str().unwrap();
    stdout(&visage(&["fixtures", d, "--gaussians-per-avatar", "300"]));
    for (name, tone) in [("ada", "light"), ("bram", "light"), ("cleo", "dark")] {
        std::fs::write(
            dir.join("avatars").join(name).join("attributes.toml"),
            format!("skin_tone = \"{tone}\"\n"),
        )
        .unwrap();
    }
    let rules = temp("one-tone.toml");
    std::fs::write(
        &rules,
        "[[rule]]\nreason = \"Skin tone\"\nsame = \"skin_tone\"\n",
    )
    .unwrap();
    let out = temp("folder-random");
    let (avatars, flame, masks) = (
        dir.join("avatars"),
        dir.join("flame/model.pkl"),
        dir.join("flame/masks.pkl"),
    );
    let random = |extra: &[&str]| {
        let mut args = vec!["random", "--db", avatars.to_str().unwrap()];
        args.extend(["--flame", flame.to_str().unwrap()]);
        args.extend(["--masks", masks.to_str().unwrap()]);
        args.extend(["--out", out.to_str().unwrap()]);
        args.extend(extra);
        visage(&args)
    };
    let listing = stdout(&random(&[
        "--constraints",
        rules.to_str().unwrap(),
        "--count",
        "6",
    ]));
    assert_eq!(listing.lines().count(), 6);
    for (name, text) in files(&out) {
        let c = Composition::of_recipe(&Recipe::from_toml(&text).unwrap());
        assert!(!c.gaussian_sources().contains(&"cleo"), "{name}: {c:?}");
    }
    // A bad label file is one line and exit 2.
    std::fs::write(dir.join("avatars/cleo/attributes.toml"), "skin_tone = 3\n").unwrap();
    let bad = random(&[]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("attributes.toml"));
}
