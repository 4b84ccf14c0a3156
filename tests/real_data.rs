//! The real-data path end to end: fixtures in the real formats (FLAME-layout
//! pickles, GaussianAvatars folders) load, compose, render and export; exports
//! load back with the same composite hash; bad files fail with one line and exit 2.

mod common;
use common::visage;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use visage::io::fixtures::{write_fixtures, FixturePaths};

fn fixtures() -> &'static FixturePaths {
    static F: OnceLock<FixturePaths> = OnceLock::new();
    F.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("visage-fixtures-{}", std::process::id()));
        write_fixtures(&dir, 3, 11_000, 4).expect("fixtures")
    })
}

fn db_args(f: &FixturePaths) -> Vec<String> {
    vec![
        "--db".into(),
        f.avatars.display().to_string(),
        "--flame".into(),
        f.model.display().to_string(),
        "--masks".into(),
        f.masks.display().to_string(),
    ]
}

fn run(args: &[String]) -> std::process::Output {
    let refs: Vec<&str> = args.iter().map(String::as_str).collect();
    visage(&refs)
}

/// Runs visage with the fixtures database appended; the command must succeed.
fn succeed_on_fixtures(mut args: Vec<String>, f: &FixturePaths) {
    args.extend(db_args(f));
    let out = run(&args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn ok_json(args: Vec<String>) -> serde_json::Value {
    let out = run(&args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn temp(name: &str) -> std::path::PathBuf {
    common::temp_path("real", name)
}

#[test]
fn flame_fixtures_load_with_gaussian_avatars_teeth_and_all_regions() {
    let f = fixtures();
    let mut args = vec!["info".to_string(), "--json".to_string()];
    args.extend(db_args(f));
    let v = ok_json(args);
    let model = &v["model"];
    let builtin = visage::model::builtin::build_head();
    // The built-in head lost its own 120 tooth vertices and gained GaussianAvatars' 120.
    assert_eq!(
        model["vertices"].as_u64().unwrap() as usize,
        builtin.vertex_count()
    );
    let teeth_tris = builtin
        .triangle_regions
        .iter()
        .filter(|r| {
            matches!(
                r,
                visage::model::regions::Region::TeethUpper
                    | visage::model::regions::Region::TeethLower
            )
        })
        .count();
    assert_eq!(
        model["triangles"].as_u64().unwrap() as usize,
        builtin.triangle_count() - teeth_tris + 168
    );
    for r in model["regions"].as_array().unwrap() {
        assert!(
            r["triangles"].as_u64().unwrap() > 0,
            "region {} is empty",
            r["name"]
        );
    }
    let teeth: u64 = model["regions"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["name"].as_str().unwrap().starts_with("teeth"))
        .map(|r| r["triangles"].as_u64().unwrap())
        .sum();
    assert_eq!(teeth, 168);
    assert_eq!(v["sources"].as_array().unwrap().len(), 3);
    assert!(model["shape_components"].as_array().unwrap().len() == 300);
    assert!(model["pose_correctives"].as_bool().unwrap());
}

#[test]
fn compose_render_and_export_real_avatars() {
    let f = fixtures();
    let names: Vec<String> = std::fs::read_dir(&f.avatars)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    let mut names = names;
    names.sort();
    let recipe = temp("recipe.toml");
    std::fs::write(
        &recipe,
        format!(
            "base = \"{a}\"\n[groups.nose]\ngaussians = \"{b}\"\nshape = {{ {b} = 0.6, {a} = 0.4 }}\n[post]\nsmoothing = \"crossfade\"\ncolour = \"thesis\"\n[animation]\nmotion = \"{a}\"\nframe = 20\n",
            a = names[0],
            b = names[1]
        ),
    )
    .unwrap();
    let r = recipe.display().to_string();
    let mut args = vec![
        "compose".into(),
        "--recipe".into(),
        r.clone(),
        "--json".into(),
    ];
    args.extend(db_args(f));
    let report = ok_json(args);
    assert!(report["solve_residual"].as_f64().unwrap() <= 1e-10);
    assert_eq!(report["frame"]["finite"], true);
    // Our pipeline on FLAME's topology (GaussianAvatars' teeth included):
    // colour seams add nothing, affine deformation leaves nothing non-finite.
    let ours = temp("recipe-ours.toml");
    std::fs::write(
        &ours,
        std::fs::read_to_string(&recipe).unwrap().replace(
            "smoothing = \"crossfade\"\ncolour = \"thesis\"",
            "smoothing = \"blend\"\ncolour = \"semantic\"\ndeform = \"affine\"",
        ),
    )
    .unwrap();
    let mut args = vec![
        "compose".into(),
        "--recipe".into(),
        ours.display().to_string(),
        "--json".into(),
    ];
    args.extend(db_args(f));
    let ours = ok_json(args);
    assert_eq!(ours["smoothing"], "blend");
    assert_eq!(ours["deform"], "affine");
    assert_eq!(ours["extra_gaussians"], 0);
    assert_eq!(ours["frame"]["finite"], true);
    // Render a still and a two-frame sequence.
    let png = temp("still.png");
    let args = vec![
        "render".into(),
        "--recipe".into(),
        r.clone(),
        "--size".into(),
        "64x48".into(),
        "--renderer".into(),
        "cpu".into(),
        "-o".into(),
        png.display().to_string(),
    ];
    succeed_on_fixtures(args, f);
    let img = visage::render::image::RgbImage::load_png(&png).unwrap();
    assert!(
        img.pixels.iter().filter(|&&p| p > 20).count() > 500,
        "something is drawn"
    );
    let seq = temp("seq-{frame}.png");
    let args = vec![
        "render".into(),
        "--recipe".into(),
        r.clone(),
        "--size".into(),
        "32x24".into(),
        "--frames".into(),
        "3..5".into(),
        "--renderer".into(),
        "cpu".into(),
        "-o".into(),
        seq.display().to_string(),
    ];
    succeed_on_fixtures(args, f);
    for k in [3, 4] {
        let p = seq
            .display()
            .to_string()
            .replace("{frame}", &format!("{k:04}"));
        assert!(Path::new(&p).exists(), "{p}");
    }
    // Export as a GaussianAvatars folder, load it back: the same composite.
    let exported_root = temp("exported");
    let exported = exported_root.join("composite");
    let args = vec![
        "export".into(),
        "--recipe".into(),
        r.clone(),
        "--format".into(),
        "gaussian-avatars".into(),
        "-o".into(),
        exported.display().to_string(),
    ];
    succeed_on_fixtures(args, f);
    let back = temp("back.toml");
    std::fs::write(&back, "base = \"composite\"\n[post]\nsmoothing = \"off\"\n[animation]\nmotion = \"composite\"\nframe = 20\n").unwrap();
    let mut args = vec![
        "compose".into(),
        "--recipe".into(),
        back.display().to_string(),
        "--json".into(),
    ];
    args.extend(db_args(f).into_iter().skip(2));
    args.extend(["--db".into(), exported_root.display().to_string()]);
    let reloaded = ok_json(args);
    assert_eq!(
        reloaded["composite_hash"], report["composite_hash"],
        "the export loads back as the same composite"
    );
    assert_eq!(reloaded["gaussians"], report["gaussians"]);
    // And the world-space PLY of the same frame.
    let ply = temp("frame.ply");
    let mut args = vec![
        "export".into(),
        "--recipe".into(),
        r,
        "--format".into(),
        "ply".into(),
        "-o".into(),
        ply.display().to_string(),
    ];
    args.extend(db_args(f));
    assert!(run(&args).status.success());
    assert_eq!(
        visage::io::ply::read_splat_ply(&ply).unwrap().len() as u64,
        report["gaussians"].as_u64().unwrap()
    );
}

#[test]
fn builtin_composites_export_and_reload_on_the_builtin_head() {
    let out_dir = temp("builtin-export");
    let avatar = out_dir.join("three");
    let out = visage(&[
        "export",
        "--recipe",
        "recipes/three-sources.toml",
        "--gaussians-per-avatar",
        "11000",
        "--format",
        "gaussian-avatars",
        "-o",
        avatar.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let original = ok_json(
        [
            "compose",
            "--recipe",
            "recipes/three-sources.toml",
            "--gaussians-per-avatar",
            "11000",
            "--json",
        ]
        .map(String::from)
        .to_vec(),
    );
    let back = temp("three-back.toml");
    std::fs::write(
        &back,
        "base = \"three\"\n[animation]\nmotion = \"three\"\nframe = 30\n",
    )
    .unwrap();
    let reloaded = ok_json(vec![
        "compose".into(),
        "--recipe".into(),
        back.display().to_string(),
        "--db".into(),
        out_dir.display().to_string(),
        "--json".into(),
    ]);
    assert_eq!(reloaded["composite_hash"], original["composite_hash"]);

    // GaussianAvatars' loader reads the export: numpy alone, as its code does.
    let summary = gaussian_avatars_reads(&avatar.join("flame_param.npz"));
    assert_eq!(summary["frames"], 125);
    assert_eq!(summary["vertices"], 5309);
    assert!(summary["static_offset_max"].as_f64().unwrap() > 1e-4);
}

/// Runs tests/data/check_flame_param.py (numpy, the way GaussianAvatars loads
/// flame_param.npz) on a file and returns its JSON summary (under
/// [`common::python`]).
fn gaussian_avatars_reads(npz: &Path) -> serde_json::Value {
    let out = python_script("tests/data/check_flame_param.py", &[npz]);
    serde_json::from_slice(&out.stdout).unwrap()
}

/// Runs a numpy script of tests/data (under [`common::python`]); it must succeed.
fn python_script(script: &str, args: &[&Path]) -> std::process::Output {
    let python = common::python();
    let out = Command::new(&python)
        .arg(script)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{python}: {e} (bash .ci/setup installs python3-numpy)"));
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Damages a copy of an avatar folder.
type Breaker = Box<dyn Fn(&Path)>;

fn expect_one_line_exit_2(args: Vec<String>, needle: &str) {
    let out = run(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.contains(needle), "{needle:?} not in {err}");
}

#[test]
fn hostile_and_broken_files_fail_cleanly() {
    let f = fixtures();
    let bad = temp("bad");
    std::fs::create_dir_all(&bad).unwrap();
    let info = |db: &Path, model: &Path, masks: &Path| -> Vec<String> {
        vec![
            "info".into(),
            "--db".into(),
            db.display().to_string(),
            "--flame".into(),
            model.display().to_string(),
            "--masks".into(),
            masks.display().to_string(),
        ]
    };
    // A pickle that tries to run code.
    let evil = bad.join("evil.pkl");
    std::fs::write(&evil, b"cos\nsystem\n(S'echo owned'\ntR.").unwrap();
    expect_one_line_exit_2(info(&f.avatars, &evil, &f.masks), "os.system");
    // A truncated model pickle.
    let bytes = std::fs::read(&f.model).unwrap();
    let cut = bad.join("cut.pkl");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    expect_one_line_exit_2(info(&f.avatars, &cut, &f.masks), "ends early");
    // Masks pointing past the mesh.
    let masks = bad.join("masks.pkl");
    let ids = [0i64, 99_999_999];
    std::fs::write(
        &masks,
        visage::io::pickle_write::to_pickle(&visage::io::pickle_write::PyObj::Dict(vec![(
            "face",
            visage::io::pickle_write::PyObj::I64(vec![2], &ids),
        )])),
    )
    .unwrap();
    expect_one_line_exit_2(info(&f.avatars, &f.model, &masks), "refers to vertex");
    // Avatar folders with broken files: bindings out of range, NaN, truncation, wrong shapes.
    let first = std::fs::read_dir(&f.avatars)
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .path();
    let cases: Vec<(&str, Breaker, &str)> = vec![
        (
            "binding",
            Box::new(|d: &Path| {
                let mut s =
                    visage::io::avatar::read_bound_ply(&d.join("point_cloud.ply"), usize::MAX)
                        .unwrap();
                s.binding[0] = 9_999_999;
                visage::io::avatar::write_bound_ply(&d.join("point_cloud.ply"), &s).unwrap();
            }),
            "bound to triangle",
        ),
        (
            "nan",
            Box::new(|d: &Path| {
                let mut s =
                    visage::io::avatar::read_bound_ply(&d.join("point_cloud.ply"), usize::MAX)
                        .unwrap();
                s.opacity_logit[5] = f32::NAN;
                visage::io::avatar::write_bound_ply(&d.join("point_cloud.ply"), &s).unwrap();
            }),
            "NaN",
        ),
        (
            "truncated",
            Box::new(|d: &Path| {
                let b = std::fs::read(d.join("point_cloud.ply")).unwrap();
                std::fs::write(d.join("point_cloud.ply"), &b[..b.len() - 100]).unwrap();
            }),
            "more than the file",
        ),
        (
            "absurd",
            Box::new(|d: &Path| {
                let b = std::fs::read(d.join("point_cloud.ply")).unwrap();
                let text = String::from_utf8_lossy(&b[..200]).to_string();
                let n = text
                    .split("element vertex ")
                    .nth(1)
                    .unwrap()
                    .split('\n')
                    .next()
                    .unwrap()
                    .to_string();
                let mut out = b.clone();
                let at = b.windows(n.len()).position(|w| w == n.as_bytes()).unwrap();
                out.splice(at..at + n.len(), b"4000000000".iter().copied());
                std::fs::write(d.join("point_cloud.ply"), out).unwrap();
            }),
            "more than the file",
        ),
        (
            "npz",
            Box::new(|d: &Path| {
                std::fs::write(d.join("flame_param.npz"), b"PK\x03\x04not really").unwrap();
            }),
            "npz",
        ),
        (
            "shape",
            Box::new(|d: &Path| {
                use visage::io::npy::{write_npy, write_npz, NpyData};
                let arrays = vec![
                    ("expr", write_npy(&[2, 7], NpyData::F32(&[0.0; 14]))),
                    ("shape", write_npy(&[300], NpyData::F32(&[0.0; 300]))),
                ];
                write_npz(&d.join("flame_param.npz"), &arrays, false).unwrap();
            }),
            "expected (T, 100)",
        ),
        (
            "empty",
            Box::new(|d: &Path| {
                let s = visage::avatar::gaussians::GaussianSet::with_degree(0);
                visage::io::avatar::write_bound_ply(&d.join("point_cloud.ply"), &s).unwrap();
            }),
            "holds no Gaussians",
        ),
        (
            "dynamic",
            Box::new(|d: &Path| {
                use visage::io::npy::{read_npz, write_npy, write_npz, NpyData};
                let path = d.join("flame_param.npz");
                let arrays = read_npz(&path).unwrap();
                let mut encoded = Vec::new();
                for (name, a) in &arrays {
                    let mut data: Vec<f32> = a.data.iter().map(|&x| x as f32).collect();
                    if name == "dynamic_offset" {
                        data[7] = f32::NAN;
                    }
                    encoded.push((name.as_str(), write_npy(&a.shape, NpyData::F32(&data))));
                }
                write_npz(&path, &encoded, true).unwrap();
            }),
            "'dynamic_offset' has NaN or infinite values",
        ),
    ];
    for (name, break_it, needle) in cases {
        let db = bad.join(format!("db-{name}"));
        let avatar = db.join("broken");
        std::fs::create_dir_all(&avatar).unwrap();
        for file in ["point_cloud.ply", "flame_param.npz"] {
            std::fs::copy(first.join(file), avatar.join(file)).unwrap();
        }
        break_it(&avatar);
        expect_one_line_exit_2(info(&db, &f.model, &f.masks), needle);
    }
    expect_one_line_exit_2(
        info(Path::new("/no/such/db"), &f.model, &f.masks),
        "does not exist",
    );
    expect_one_line_exit_2(
        vec![
            "info".into(),
            "--db".into(),
            f.avatars.display().to_string(),
            "--flame".into(),
            f.model.display().to_string(),
        ],
        "go together",
    );
}

/// The editor's path on real data: a session recorded against a folder database
/// (with FLAME files) replays deterministically, its saved recipe composes to
/// the same state, and its snapshot shows a head.
#[test]
fn editing_sessions_on_real_avatars_replay() {
    use visage::editor::session::SessionHeader;
    use visage::tui::graphics::Protocol;
    let f = fixtures();
    let dir = temp("session");
    std::fs::create_dir_all(&dir).unwrap();
    let db = visage::pipeline::DatabaseSpec {
        db: f.avatars.display().to_string(),
        flame: Some(f.model.clone()),
        masks: Some(f.masks.clone()),
        ..Default::default()
    };
    let mut header = SessionHeader::new(&db, (100, 30), Protocol::Halfblocks);
    header.render = (96, 72);
    let session = dir.join("edit.vsg");
    std::fs::remove_file(&session).ok();
    let mut recorder = visage::editor::session::Recorder::create(&session, &header, &[]).unwrap();
    let script = [
        (0, "select-group nose"),
        (0, "select-source bram"),
        (1, "assign"),
        (2, "set-shape nose bram=0.7 ada=0.3"),
        (3, "colour skin"),
        (4, "motion cleo"),
        (5, "frame 10"),
        (6, "snapshot edit.png"),
        (6, "save-recipe edit.toml"),
    ];
    for (tick, line) in script {
        let command = visage::editor::command::Command::parse(line).unwrap();
        recorder.record(tick, &command).unwrap();
    }
    drop(recorder);
    let mut reports = Vec::new();
    for k in 0..2 {
        let out = dir.join(format!("out{k}"));
        let report = ok_json(vec![
            "replay".into(),
            session.display().to_string(),
            "--out".into(),
            out.display().to_string(),
            "--check".into(),
            "--json".into(),
        ]);
        reports.push((report, out));
    }
    let (a, out_a) = &reports[0];
    let (b, out_b) = &reports[1];
    assert_eq!(a["state_hash"], b["state_hash"]);
    assert_eq!(
        std::fs::read(out_a.join("edit.png")).unwrap(),
        std::fs::read(out_b.join("edit.png")).unwrap(),
        "replays must give byte-identical snapshots"
    );
    let img = visage::render::image::RgbImage::load_png(&out_a.join("edit.png")).unwrap();
    let lit = img
        .pixels
        .chunks(3)
        .filter(|p| p.iter().any(|&c| c > 40))
        .count();
    assert!(
        lit > img.pixels.len() / 3 / 10,
        "the snapshot shows too little: {lit} lit pixels"
    );
    // The recipe the session saved composes, from the command line, to the same state.
    let mut args = vec![
        "compose".into(),
        "--recipe".into(),
        out_a.join("edit.toml").display().to_string(),
        "--json".into(),
    ];
    args.extend(db_args(f));
    let composed = ok_json(args);
    assert_eq!(composed["state_hash"], a["state_hash"]);
}

/// Unpacks the gzip-compressed real-chumpy FLAME fixture to a temporary file.
fn real_chumpy_flame() -> PathBuf {
    use std::io::Read;
    let gz = std::fs::File::open("tests/data/chumpy/flame2023.pkl.gz").unwrap();
    let mut bytes = Vec::new();
    flate2::read::GzDecoder::new(gz)
        .read_to_end(&mut bytes)
        .unwrap();
    let path = temp("flame2023.pkl");
    std::fs::write(&path, bytes).unwrap();
    path
}

/// Writes a folder database with one avatar (a Gaussian on every triangle
/// files know) for `model`.
fn one_avatar_db(name: &str, model: &visage::model::head::HeadModel) -> PathBuf {
    let (triangles, vertices) = (model.file_triangle_count(), model.file_vertex_count());
    use visage::avatar::gaussians::GaussianSet;
    use visage::io::avatar::{write_avatar, AvatarParams, FrameParams};
    let mut set = GaussianSet::with_degree(0);
    for t in 0..triangles as u32 {
        set.push(
            t,
            glam::Vec3::ZERO,
            glam::Quat::IDENTITY,
            glam::Vec3::splat(-5.0),
            2.0,
            &[0.5, 0.2, 0.1],
        );
    }
    let root = temp(name);
    let offset = vec![glam::DVec3::ZERO; vertices];
    let frames = [FrameParams {
        expression: vec![0.0; 100],
        pose: visage::model::head::Pose::REST,
        offset: Vec::new(),
    }];
    write_avatar(
        &root.join("solo"),
        &set,
        &AvatarParams {
            shape: &[0.1, -0.2],
            static_offset: &offset,
            frames: &frames,
        },
        model,
    )
    .unwrap();
    root
}

/// FLAME models pickled by the real chumpy 0.70 under Python 2.7 (cPickle,
/// protocols 2 and 0; tests/data/chumpy/make_chumpy_flame.py) load: FLAME's
/// 5023 vertices and 9976 triangles plus GaussianAvatars' teeth.
#[test]
fn flame_models_pickled_by_real_chumpy_load() {
    let model = real_chumpy_flame();
    let masks = Path::new("tests/data/chumpy/FLAME_masks.pkl");
    let head = visage::io::flame::load_flame(&model, masks).unwrap();
    assert_eq!((head.vertex_count(), head.triangle_count()), (5143, 10144));
    assert_eq!(head.shape_basis.len(), 6);
    assert!(head.pose_correctives.is_some());

    // The same through the command line, as a user would: a folder database on it.
    let db = one_avatar_db("chumpy-db", &head);
    let v = ok_json(vec![
        "info".into(),
        "--json".into(),
        "--db".into(),
        db.display().to_string(),
        "--flame".into(),
        model.display().to_string(),
        "--masks".into(),
        masks.display().to_string(),
    ]);
    assert_eq!(v["model"]["vertices"], 5143);
    assert_eq!(v["model"]["triangles"], 10144);
    // Without the FLAME files, the error says what to pass rather than an
    // array's shape.
    expect_one_line_exit_2(
        vec!["info".into(), "--db".into(), db.display().to_string()],
        "5143 vertices (FLAME), not the built-in head's 5309: pass the FLAME model and masks",
    );

    // generic_model.pkl style: shapedirs, posedirs, J and weights all chumpy, protocol 0.
    let small = visage::io::flame::load_flame(
        Path::new("tests/data/chumpy/generic_model_p0.pkl"),
        Path::new("tests/data/chumpy/generic_masks_p0.pkl"),
    )
    .unwrap();
    assert_eq!(
        (small.vertex_count(), small.triangle_count()),
        (60 + 120, 90 + 168)
    );
    assert_eq!(small.shape_basis.len(), 4);
}

/// Without a recipe, `render` and `bench render` use the folder database's own
/// first source (no built-in names).
#[test]
fn render_and_bench_default_to_the_first_source_of_a_folder_database() {
    let f = fixtures();
    let png = temp("default.png");
    succeed_on_fixtures(
        vec![
            "render".into(),
            "--size".into(),
            "48x36".into(),
            "-o".into(),
            png.display().to_string(),
        ],
        f,
    );
    let image = visage::render::image::RgbImage::load_png(&png).unwrap();
    assert!(image.pixels.iter().any(|&v| v > 30), "the source is drawn");
    let mut args: Vec<String> = [
        "bench",
        "render",
        "--sizes",
        "32x24",
        "--renderers",
        "cpu",
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--no-knobs",
        "--json",
    ]
    .map(String::from)
    .to_vec();
    args.extend(db_args(f));
    let report = ok_json(args);
    assert!(report.to_string().contains("psnr"), "{report}");
    std::fs::remove_file(png).ok();
}

/// A FLAME-like model whose lips are open at the back, as FLAME's are, gets a
/// mouth cavity (docs/method.md §2.4): the mouth closes, the cavity opens with
/// the jaw, files never see it (exports rebind its Gaussians in place and stop
/// offsets at the file's vertices, which GaussianAvatars' loader reads), and
/// the rebound Gaussians count for the mouth's inside again once loaded.
#[test]
fn open_mouthed_flame_models_get_a_cavity_that_files_never_see() {
    use visage::io::fixtures::{write_fixtures_with, FixtureMouth};
    use visage::model::cavity::boundary_loops;
    use visage::model::regions::Region;
    let dir = temp("open-mouth");
    let open = write_fixtures_with(&dir.join("open"), 2, 9_000, 3, FixtureMouth::Open).unwrap();
    let head = visage::io::flame::load_flame(&open.model, &open.masks).unwrap();
    let closed = fixtures();
    let closed_head = visage::io::flame::load_flame(&closed.model, &closed.masks).unwrap();
    assert!(
        closed_head.mouth_cavity.is_none(),
        "a closed mouth gets none"
    );
    let cavity = head
        .mouth_cavity
        .as_ref()
        .expect("an open mouth gets a cavity");
    assert_eq!(head.file_vertex_count(), cavity.first_vertex);
    assert!(head.vertex_count() > cavity.first_vertex);
    assert!(head.triangle_regions[cavity.first_triangle..]
        .iter()
        .all(|r| *r == Region::LipsInside));
    // Closed: as many openings left as the pocketed head has (the neck's).
    let loops =
        |m: &visage::model::head::HeadModel| boundary_loops(m.vertex_count(), &m.triangles).len();
    assert_eq!(loops(&head), loops(&closed_head));

    // The jaw opens the cavity: its lower half goes down with the chin, its
    // upper half stays with the skull.
    let neutral = head.neutral(&[], None);
    let mut pose = visage::model::head::Pose::REST;
    pose.joints[2] = glam::Vec3::new(0.3, 0.0, 0.0);
    let mut posed = Vec::new();
    head.pose(&neutral, &[], &pose, &mut posed);
    let drop_of = |jaw: bool| {
        let moved: Vec<f32> = (cavity.first_vertex..head.vertex_count())
            .filter(|&v| (head.skin_weights[v][2] > 0.5) == jaw)
            .map(|v| posed[v].y - neutral[v].y)
            .collect();
        moved.iter().sum::<f32>() / moved.len() as f32
    };
    assert!(drop_of(true) < -0.004, "lower half: {}", drop_of(true));
    assert!(
        drop_of(false).abs() < 0.001,
        "upper half: {}",
        drop_of(false)
    );

    // The avatars written on it name only the triangles files know.
    for entry in std::fs::read_dir(&open.avatars).unwrap() {
        let ply = entry.unwrap().path().join("point_cloud.ply");
        let set = visage::io::avatar::read_bound_ply(&ply, head.file_triangle_count()).unwrap();
        assert!(!set.is_empty());
    }
    // Loaded back, Gaussians that sat on the cavity count for the mouth's
    // inside again by place, though their parents are now lips or teeth.
    let db =
        visage::io::folder::load_folder(&open.avatars, Some((&open.model, &open.masks))).unwrap();
    let source = &db.sources[0];
    let placed = visage::compose::membership::place_triangles(
        &head,
        &source.gaussians,
        &source.neutral(&head),
    );
    let moved_in = placed
        .iter()
        .zip(&source.gaussians.binding)
        .filter(|(p, b)| {
            **p as usize >= cavity.first_triangle && (**b as usize) < cavity.first_triangle
        })
        .count();
    assert!(
        moved_in > 50,
        "{moved_in} Gaussians count for the cavity again"
    );

    // A composite's export: GaussianAvatars' loader reads its offsets, with
    // the file's vertex count, and the export loads back.
    let exported_root = dir.join("exported");
    let avatar = exported_root.join("composite");
    let names: Vec<String> = db.sources.iter().map(|s| s.name.clone()).collect();
    let recipe = dir.join("open.toml");
    std::fs::write(
        &recipe,
        format!(
            "base = \"{a}\"\n[groups.mouth]\ngaussians = \"{b}\"\nshape = {{ {b} = 1.0 }}\n[animation]\nmotion = \"{a}\"\nframe = 10\n",
            a = names[0],
            b = names[1]
        ),
    )
    .unwrap();
    let mut args = vec![
        "export".into(),
        "--recipe".into(),
        recipe.display().to_string(),
        "--format".into(),
        "gaussian-avatars".into(),
        "-o".into(),
        avatar.display().to_string(),
    ];
    args.extend(db_args(&open));
    let out = run(&args);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = gaussian_avatars_reads(&avatar.join("flame_param.npz"));
    assert_eq!(summary["vertices"], head.file_vertex_count());
    visage::io::avatar::read_bound_ply(&avatar.join("point_cloud.ply"), head.file_triangle_count())
        .unwrap();
    let back =
        visage::io::folder::load_folder(&exported_root, Some((&open.model, &open.masks))).unwrap();
    assert_eq!(back.sources.len(), 1);
    // `info` says what was added.
    let mut args = vec!["info".into(), "--json".into()];
    args.extend(db_args(&open));
    let info = ok_json(args);
    assert_eq!(
        info["model"]["mouth_cavity"]["triangles"],
        head.triangle_count() - cavity.first_triangle
    );
}

/// Runs tests/data/dynamic_offset.py (numpy's own np.load / np.savez).
fn dynamic_offset_py(args: &[&Path]) -> std::process::Output {
    python_script("tests/data/dynamic_offset.py", args)
}

/// A tracked sequence with per-frame offsets (`dynamic_offset` (T, V, 3)
/// not zero, written by numpy as VHAP's exporter writes it) loads; each
/// frame's offsets are added to the unposed mesh before skinning (at a
/// frame at rest the posed mesh moves by exactly the offsets), the source's
/// motion carries them to a composite, and an export writes them back bit
/// for bit.
#[test]
fn per_frame_offsets_written_by_numpy_load_pose_and_export() {
    use visage::compose::engine::{Engine, PosedMesh};
    use visage::compose::recipe::Recipe;
    let f = fixtures();
    let first = std::fs::read_dir(&f.avatars)
        .unwrap()
        .map(|e| e.unwrap().path())
        .min()
        .unwrap();
    let db = temp("tracked-db");
    let avatar = db.join("tracked");
    std::fs::create_dir_all(&avatar).unwrap();
    std::fs::copy(
        first.join("point_cloud.ply"),
        avatar.join("point_cloud.ply"),
    )
    .unwrap();
    let npz = avatar.join("flame_param.npz");
    dynamic_offset_py(&[Path::new("write"), &first.join("flame_param.npz"), &npz]);

    let mut args = vec!["info".to_string(), "--json".into()];
    args.extend(db_args(f).into_iter().skip(2));
    args.extend(["--db".into(), db.display().to_string()]);
    ok_json(args);

    let loaded =
        visage::io::folder::load_folder(&db, Some((f.model.as_path(), f.masks.as_path()))).unwrap();
    let motion = loaded.motions[loaded.motion_index("tracked").unwrap()].clone();
    assert_eq!(motion.offsets.len(), motion.frames());
    let model = loaded.model.clone();
    let file_vertices = model.file_vertex_count();
    // The pattern the script wrote, at frame 1.
    let expected = |i: usize| {
        let (t, i) = (1.0f64, i as f64);
        glam::Vec3::new(
            (1e-3 * (0.7 * t + 0.013 * i).sin()) as f32,
            (5e-4 * (0.3 * t - 0.021 * i).cos()) as f32,
            (2e-4 * (t + 1.0)) as f32,
        )
    };
    for i in [0, 1, 777, file_vertices - 1] {
        assert!((motion.offsets[1][i] - expected(i)).abs().max_element() < 1e-9);
    }

    // Frame 1 is at rest: the offsets move the posed mesh by themselves.
    let neutral = loaded.sources[0].neutral(&model);
    let (expression, pose) = motion.frame(1);
    let (mut plain, mut offset) = (Vec::new(), Vec::new());
    model.pose(&neutral, expression, pose, &mut plain);
    model.pose_offset(
        &neutral,
        expression,
        pose,
        motion.frame_offset(1),
        &mut offset,
    );
    for i in 0..file_vertices {
        let moved = offset[i] - plain[i];
        assert!(
            (moved - expected(i)).abs().max_element() < 1e-6,
            "vertex {i}: {moved}"
        );
    }

    // A composite driven by the tracked motion poses with them.
    let engine = Engine::new(loaded).unwrap();
    let mut recipe = Recipe::unedited("tracked");
    recipe.animation.motion = "tracked".into();
    let composite = engine.compose(&recipe.resolve(engine.database()).unwrap());
    let mut posed = PosedMesh::default();
    engine.pose(&composite, 1, &mut posed);
    let mut without = PosedMesh::default();
    engine.pose_with(
        &composite,
        expression,
        pose,
        composite.recipe.mode,
        &mut without,
    );
    let moved = posed.vertices[777] - without.vertices[777];
    assert!(
        (moved - expected(777)).abs().max_element() < 1e-6,
        "{moved}"
    );

    // Exported as a GaussianAvatars folder, the offsets come back as written.
    let r = temp("tracked.toml");
    std::fs::write(
        &r,
        "base = \"tracked\"\n[animation]\nmotion = \"tracked\"\n",
    )
    .unwrap();
    let out = temp("tracked-export");
    let mut args = vec![
        "export".to_string(),
        "--recipe".into(),
        r.display().to_string(),
        "--format".into(),
        "gaussian-avatars".into(),
        "-o".into(),
        out.display().to_string(),
    ];
    args.extend(db_args(f).into_iter().skip(2));
    args.extend(["--db".into(), db.display().to_string()]);
    let o = run(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let exported = out.join("flame_param.npz");
    gaussian_avatars_reads(&exported);
    let compared = dynamic_offset_py(&[Path::new("compare"), &npz, &exported]);
    let summary: serde_json::Value = serde_json::from_slice(&compared.stdout).unwrap();
    assert_eq!(
        summary["vertices"].as_u64().unwrap() as usize,
        file_vertices
    );
    assert!(summary["largest"].as_f64().unwrap() > 1e-4);
}
