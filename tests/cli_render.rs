//! `visage render` and `visage bench render` as a user runs them.

mod common;
use common::visage;

use glam::{Quat, Vec3};
use visage::io::ply::write_splat_ply;
use visage::render::image::{psnr, RgbImage};
use visage::scene::splats::SplatScene;

fn temp(name: &str) -> std::path::PathBuf {
    common::temp_path("cli-render", name)
}

fn ring_scene(degree: u8) -> SplatScene {
    let mut scene = SplatScene::with_degree(degree);
    let stride = 3 * (degree as usize + 1).pow(2);
    for k in 0..300 {
        let t = k as f32 / 300.0 * std::f32::consts::TAU;
        let mut sh = vec![0.0f32; stride];
        sh[0] = t.sin();
        sh[1] = t.cos();
        sh[2] = -0.5;
        if degree > 0 {
            sh[3] = 0.3;
        }
        scene.push(
            Vec3::new(t.cos(), t.sin(), 0.0) * 2.0,
            Quat::from_rotation_z(t),
            Vec3::new(0.08, 0.03, 0.03),
            0.9,
            &sh,
        );
    }
    scene
}

/// `render --ply` of a scene file at 80×60 with the default renderer and with
/// `--reference`.
fn render_and_reference(scene: &std::path::Path, tag: &str) -> (RgbImage, RgbImage) {
    let images = [None, Some("--reference")].map(|extra| {
        let out = temp(&format!("{tag}-{}.png", extra.is_some()));
        let mut args = vec![
            "render",
            "--ply",
            scene.to_str().unwrap(),
            "--size",
            "80x60",
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend(extra);
        let o = visage(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let image = RgbImage::load_png(&out).unwrap();
        std::fs::remove_file(out).ok();
        image
    });
    let [fast, reference] = images;
    (fast, reference)
}

#[test]
fn renders_standard_3dgs_plys_of_degree_0_and_3_like_the_reference() {
    for degree in [0u8, 3] {
        let ply = temp(&format!("ring{degree}.ply"));
        write_splat_ply(&ply, &ring_scene(degree)).unwrap();
        let (a, b) = render_and_reference(&ply, &format!("ring{degree}"));
        assert_eq!((a.width, a.height), (80, 60));
        assert!(psnr(&a, &b).unwrap() >= 40.0, "degree {degree}");
        assert!(a.pixels.iter().any(|&v| v > 30), "the ring is visible");
        std::fs::remove_file(ply).ok();
    }
}

#[test]
fn renders_a_recipe_on_every_renderer() {
    let out = temp("recipe.png");
    for renderer in ["gpu", "cpu"] {
        let o = visage(&[
            "render",
            "--recipe",
            "recipes/three-sources.toml",
            "--gaussians-per-avatar",
            "11000",
            "--size",
            "64x48",
            "--yaw",
            "-20",
            "--renderer",
            renderer,
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(
            o.status.success(),
            "{renderer}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        let img = RgbImage::load_png(&out).unwrap();
        assert_eq!((img.width, img.height), (64, 48));
    }
    std::fs::remove_file(out).ok();
}

#[test]
fn bad_input_is_one_line_and_exit_code_2() {
    let bad = temp("bad.ply");
    std::fs::write(&bad, b"ply\nformat binary_little_endian 1.0\nelement vertex 99999999\nproperty float x\nend_header\n").unwrap();
    let nan = temp("nan.ply");
    let mut scene = ring_scene(0);
    scene.position[3].x = f32::NAN;
    write_splat_ply(&nan, &scene).unwrap();
    let out = temp("never.png");
    let o = out.to_str().unwrap();
    for args in [
        vec!["render", "--ply", bad.to_str().unwrap(), "-o", o],
        vec!["render", "--ply", nan.to_str().unwrap(), "-o", o],
        vec!["render", "--ply", "/no/such.ply", "-o", o],
        vec!["render", "--size", "0x10", "-o", o],
        vec!["render", "--size", "huge", "-o", o],
    ] {
        let r = visage(&args);
        assert_eq!(r.status.code(), Some(2), "{args:?}");
        let err = String::from_utf8_lossy(&r.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
    }
    assert!(!out.exists());
    std::fs::remove_file(bad).ok();
    std::fs::remove_file(nan).ok();
}

#[test]
fn bench_render_json_rows_carry_size_speed_and_psnr() {
    let o = visage(&[
        "bench",
        "render",
        "--gaussians-per-avatar",
        "11000",
        "--sizes",
        "64x48",
        "--knob-size",
        "48x32",
        "--iterations",
        "2",
        "--warmup",
        "1",
        "--renderers",
        "cpu",
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let r = &v["renderers"][0];
    let row = &r["rows"][0];
    assert_eq!(row["width"], 64);
    assert_eq!(row["height"], 48);
    assert!(row["ms_median"].as_f64().unwrap() > 0.0);
    assert!(row["psnr_db"].as_f64().unwrap() >= 40.0);
    assert!(r["knobs"]
        .as_array()
        .unwrap()
        .iter()
        .any(|k| k["knob"] == "sh_degree"));
}

/// Signs of the 16 SH basis functions (3DGS order) under the rotation by π
/// about x, (x, y, z) → (x, −y, −z): each basis polynomial is even or odd in
/// (y, z).
const SH_SIGNS_UNDER_X_FLIP: [f32; 16] = [
    1.0, -1.0, -1.0, 1.0, -1.0, 1.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, -1.0, 1.0, -1.0, 1.0,
];

/// The scene as a COLMAP/INRIA capture would hold it: y down, z away.
fn y_down(scene: &SplatScene) -> SplatScene {
    let flip = Quat::from_rotation_x(std::f32::consts::PI);
    let mut out = SplatScene::with_degree(scene.sh_degree);
    for i in 0..scene.len() {
        let sh: Vec<f32> = scene
            .sh_of(i)
            .iter()
            .enumerate()
            .map(|(k, c)| c * SH_SIGNS_UNDER_X_FLIP[k / 3])
            .collect();
        out.push(
            flip * scene.position[i],
            flip * scene.rotation[i],
            scene.scale[i],
            scene.opacity[i],
            &sh,
        );
    }
    out
}

fn render_ply(ply: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> RgbImage {
    let mut args = vec![
        "render",
        "--ply",
        ply.to_str().unwrap(),
        "--size",
        "120x90",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend(extra);
    let o = visage(&args);
    assert!(
        o.status.success(),
        "{extra:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    RgbImage::load_png(out).unwrap()
}

/// A trained-looking scene with two floaters 24 units away renders framed on
/// the subject (as without the floaters) and matches the reference; the same
/// scene stored y-down renders the same with `--up -y`.
#[test]
fn scenes_with_floaters_render_framed_and_y_down_scenes_upright() {
    let head = temp("head.ply");
    let o = visage(&[
        "export",
        "--recipe",
        "recipes/three-sources.toml",
        "--gaussians-per-avatar",
        "11000",
        "--format",
        "ply",
        "-o",
        head.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let clean = visage::io::ply::read_splat_ply(&head).unwrap();
    let mut floaters = clean.clone();
    let sh = vec![0.2f32; floaters.sh_stride()];
    floaters.push(
        Vec3::new(24.0, 1.0, -3.0),
        Quat::IDENTITY,
        Vec3::splat(0.5),
        0.9,
        &sh,
    );
    floaters.push(
        Vec3::new(-5.0, -24.0, 2.0),
        Quat::IDENTITY,
        Vec3::splat(0.5),
        0.9,
        &sh,
    );
    let (with_floaters, flipped) = (temp("floaters.ply"), temp("y-down.ply"));
    write_splat_ply(&with_floaters, &floaters).unwrap();
    write_splat_ply(&flipped, &y_down(&floaters)).unwrap();

    let png = temp("framed.png");
    let framed = render_ply(&with_floaters, &png, &[]);
    let reference = render_ply(&with_floaters, &png, &["--reference"]);
    let without = render_ply(&head, &png, &[]);
    assert!(
        psnr(&framed, &reference).unwrap() >= 40.0,
        "matches the reference"
    );
    assert!(
        psnr(&framed, &without).unwrap() >= 40.0,
        "framed as if the floaters were not there"
    );
    let lit = framed
        .pixels
        .chunks(3)
        .filter(|p| p.iter().any(|&v| v > 20))
        .count();
    assert!(
        lit * 8 > 120 * 90,
        "the head fills the frame ({lit} pixels lit)"
    );

    let upright = render_ply(&flipped, &png, &["--up", "-y"]);
    assert!(
        psnr(&upright, &framed).unwrap() >= 40.0,
        "--up -y shows a y-down capture upright"
    );
    let upside_down = render_ply(&flipped, &png, &[]);
    assert!(
        psnr(&upside_down, &framed).unwrap() < 20.0,
        "without --up it is upside down"
    );

    // Explicit camera flags replace the framing.
    let far = render_ply(
        &with_floaters,
        &png,
        &["--radius", "30", "--target", "0,0,0", "--fov", "40"],
    );
    let far_lit = far
        .pixels
        .chunks(3)
        .filter(|p| p.iter().any(|&v| v > 20))
        .count();
    assert!(
        far_lit * 10 < lit,
        "a far camera shows a small head ({far_lit} vs {lit})"
    );
    for (flag, value, needle) in [
        ("--up", "sideways", "--up: up axis"),
        ("--radius", "-1", "--radius: radius"),
        ("--target", "1,2", "--target: target"),
        ("--fov", "0", "--fov: field of view"),
    ] {
        let o = visage(&[
            "render",
            "--ply",
            head.to_str().unwrap(),
            flag,
            value,
            "-o",
            png.to_str().unwrap(),
        ]);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {err}");
        assert!(
            err.contains(needle) && err.trim().lines().count() == 1,
            "{err}"
        );
    }
    for p in [head, with_floaters, flipped, png] {
        std::fs::remove_file(p).ok();
    }
}

/// `visage convert` between INRIA PLY and .splat: lossless where the format
/// keeps everything, the cost measured where it does not; .splat files render
/// like the reference; broken ones are one line and exit 2.
#[test]
fn convert_between_ply_and_splat_reports_the_error() {
    let (ply, splat, back) = (temp("ring.ply"), temp("ring.splat"), temp("ring-back.ply"));
    write_splat_ply(&ply, &ring_scene(3)).unwrap();
    let to_splat = json(&[
        "convert",
        ply.to_str().unwrap(),
        splat.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(to_splat["gaussians"], 300);
    assert_eq!(
        (
            to_splat["sh_degree_in"].as_u64(),
            to_splat["sh_degree_out"].as_u64()
        ),
        (Some(3), Some(0))
    );
    assert_eq!(to_splat["bytes_out"], 300 * 32);
    let lossy = to_splat["psnr_db"].as_f64().unwrap();
    assert!(
        (20.0..99.0).contains(&lossy),
        "SH 3 → 0 and 8-bit colour cost something: {lossy}"
    );
    let to_ply = json(&[
        "convert",
        splat.to_str().unwrap(),
        back.to_str().unwrap(),
        "--json",
    ]);
    assert!(
        to_ply["psnr_db"].as_f64().unwrap() >= 99.0,
        "splat → PLY keeps everything"
    );

    let (a, b) = render_and_reference(&splat, "splat");
    assert!(psnr(&a, &b).unwrap() >= 40.0);
    let fast = temp("splat.png");

    let broken = temp("broken.splat");
    std::fs::write(&broken, [0u8; 33]).unwrap();
    for args in [
        vec!["convert", broken.to_str().unwrap(), back.to_str().unwrap()],
        vec![
            "render",
            "--ply",
            broken.to_str().unwrap(),
            "-o",
            fast.to_str().unwrap(),
        ],
        vec!["convert", ply.to_str().unwrap(), "/tmp/scene.obj"],
    ] {
        let o = visage(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    for p in [ply, splat, back, fast, broken] {
        std::fs::remove_file(p).ok();
    }
}

/// Runs visage, insists it succeeds, and parses its JSON output.
fn json(args: &[&str]) -> serde_json::Value {
    let o = visage(args);
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// SPZ both ways through the command line: a PLY becomes an SPZ (SH kept,
/// quantised: lossy but close), the SPZ Niantic's tool wrote becomes a PLY
/// losslessly, and a damaged SPZ is one line and exit code 2.
#[test]
fn convert_to_and_from_spz_reports_the_error() {
    let (ply, spz, back) = (
        temp("ring-spz.ply"),
        temp("ring.spz"),
        temp("ring-spz-back.ply"),
    );
    write_splat_ply(&ply, &ring_scene(3)).unwrap();
    let to_spz = json(&[
        "convert",
        ply.to_str().unwrap(),
        spz.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(to_spz["sh_degree_out"].as_u64(), Some(3));
    let lossy = to_spz["psnr_db"].as_f64().unwrap();
    assert!(
        (35.0..99.0).contains(&lossy),
        "8-bit SPZ costs a little: {lossy}"
    );
    assert!(to_spz["bytes_out"].as_u64() < to_spz["bytes_in"].as_u64());
    let theirs = "tests/data/splat/ring3.spz";
    let from_spz = json(&["convert", theirs, back.to_str().unwrap(), "--json"]);
    assert_eq!(from_spz["gaussians"], 200);
    assert!(
        from_spz["psnr_db"].as_f64().unwrap() >= 99.0,
        "SPZ → PLY keeps everything"
    );
    let broken = temp("broken.spz");
    let bytes = std::fs::read(theirs).unwrap();
    std::fs::write(&broken, &bytes[..bytes.len() - 7]).unwrap();
    let o = visage(&["convert", broken.to_str().unwrap(), back.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(err.contains("broken.spz"), "{err}");
    for p in [ply, spz, back, broken] {
        std::fs::remove_file(p).ok();
    }
}

/// `bench render` on scenes: a synthetic one made deterministically and a
/// file, with load time and peak memory beside the usual rows. Each size's
/// exact row and the knobs draw every Gaussian even after the level of
/// detail drew a cut at the size before (they once drew the last cut).
#[test]
fn bench_render_measures_scenes() {
    let out = visage(&[
        "bench",
        "render",
        "--synthetic-scale",
        "20000",
        "--renderers",
        "cpu",
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--sizes",
        "120x80,160x120",
        "--lod",
        "3k",
        "--knob-size",
        "96x64",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["gaussians"], 20000);
    // The early-stop knobs: exact first, accuracy falling as pixels stop sooner.
    let knobs = doc["renderers"][0]["knobs"].as_array().unwrap();
    let psnr: Vec<f64> = knobs
        .iter()
        .map(|k| k["psnr_db"].as_f64().unwrap())
        .collect();
    assert_eq!(knobs.len(), 4, "{knobs:?}");
    assert!(knobs
        .iter()
        .all(|k| k["knob"] == "early_stop" && k["width"] == 96));
    assert!(psnr[0] >= 60.0 && psnr[3] < psnr[0], "{psnr:?}");
    assert!(doc["load_ms"].as_f64().unwrap() > 0.0);
    assert!(doc["peak_rss_mb"].as_f64().unwrap() > 1.0);
    let row = &doc["renderers"][0]["rows"][0];
    assert_eq!(
        (row["width"].as_u64(), row["height"].as_u64()),
        (Some(120), Some(80))
    );
    for row in doc["renderers"][0]["rows"].as_array().unwrap() {
        let exact = row["psnr_db"].as_f64().unwrap();
        let cut = row["lod_psnr_db"].as_f64().unwrap();
        assert!(exact >= 60.0 && cut < exact, "{row}");
        assert!(row["lod_drawn"].as_u64().unwrap() <= 3000, "{row}");
    }
    assert!(
        row["ms_median"].as_f64().unwrap() > 0.0 && row["stages_ms"]["project"].as_f64().is_some()
    );

    let splat = temp("bench.splat");
    visage::io::splat::write_splat(&splat, &ring_scene(0)).unwrap();
    let out = visage(&[
        "bench",
        "render",
        "--ply",
        splat.to_str().unwrap(),
        "--renderers",
        "cpu",
        "--iterations",
        "1",
        "--warmup",
        "0",
        "--sizes",
        "64x48",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["gaussians"], 300);
    for bad in [
        vec!["bench", "render", "--synthetic-scale", "0"],
        vec![
            "bench",
            "render",
            "--synthetic-scale",
            "10",
            "--recipe",
            "recipes/three-sources.toml",
        ],
        vec!["bench", "render", "--ply", "/no/such.splat"],
    ] {
        let o = visage(&bad);
        assert_eq!(
            o.status.code(),
            Some(2),
            "{bad:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    std::fs::remove_file(splat).ok();
}

/// SuperSplat's compressed PLY, as PlayCanvas's splat-transform writes it,
/// renders like the reference and converts to the other formats.
#[test]
fn compressed_plys_render_and_convert() {
    let packed = std::path::Path::new("tests/data/splat/ring3.compressed.ply");
    let (a, b) = render_and_reference(packed, "compressed");
    assert!(psnr(&a, &b).unwrap() >= 40.0);
    assert!(a.pixels.iter().any(|&v| v > 30), "the ring is visible");
    let out = temp("from-compressed.ply");
    let o = visage(&[
        "convert",
        packed.to_str().unwrap(),
        out.to_str().unwrap(),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (
            report["gaussians"].as_u64(),
            report["sh_degree_out"].as_u64()
        ),
        (Some(200), Some(3))
    );
    assert!(
        report["psnr_db"].as_f64().unwrap() >= 99.0,
        "decoded once, then lossless"
    );
    std::fs::remove_file(out).ok();
}

/// `convert --synthetic-scale N OUT` streams the synthetic scene to a PLY with
/// the very rows `write_splat_ply` writes for it in memory, writes the other
/// formats from memory, and refuses an input beside it or no output.
#[test]
fn convert_writes_the_synthetic_scene_streamed() {
    let (streamed, in_memory) = (temp("synthetic.ply"), temp("synthetic-ref.ply"));
    let report = json(&[
        "convert",
        "--synthetic-scale",
        "3000",
        "--seed",
        "5",
        streamed.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["streamed"], true);
    assert_eq!(report["gaussians"], 3000);
    write_splat_ply(
        &in_memory,
        &visage::scene::synthetic::synthetic_scene(3000, 5),
    )
    .unwrap();
    let body = |p: &std::path::Path| {
        let bytes = std::fs::read(p).unwrap();
        let end = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        bytes[end..].to_vec()
    };
    assert_eq!(body(&streamed), body(&in_memory), "the same rows");
    assert!(!streamed.with_extension("ply.partial").exists());
    let spz = temp("synthetic.spz");
    let report = json(&[
        "convert",
        "--synthetic-scale",
        "500",
        spz.to_str().unwrap(),
        "--json",
    ]);
    assert_eq!(report["streamed"], false);
    assert_eq!(visage::io::splat::read_scene(&spz).unwrap().len(), 500);
    for args in [
        vec!["convert", "--synthetic-scale", "10", "a.ply", "b.ply"],
        vec!["convert", "a.ply"],
        vec!["convert", "--synthetic-scale", "10", "out.txt"],
    ] {
        let o = visage(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    for file in [&streamed, &in_memory, &spz] {
        std::fs::remove_file(file).ok();
    }
}

/// A file that cannot be written is an I/O failure (exit 4), told apart from
/// bad input (exit 2: a file that cannot be read): one line either way.
#[test]
fn write_failures_exit_4_and_read_failures_exit_2() {
    let unwritable = "/proc/visage-no-such-dir/out";
    for (args, code, needle) in [
        (
            vec![
                "render",
                "--size",
                "16x12",
                "--renderer",
                "cpu",
                "-o",
                "/proc/visage-no-such-dir/x.png",
            ],
            4,
            "cannot write /proc/visage-no-such-dir/x.png",
        ),
        (
            vec![
                "convert",
                "--synthetic-scale",
                "10",
                "/proc/visage-no-such-dir/x.ply",
            ],
            4,
            "cannot write",
        ),
        (vec!["fixtures", unwritable], 4, "cannot create"),
        (
            vec!["clean", "/proc/visage-no-such-dir/in.ply", "/tmp/out.ply"],
            2,
            "cannot read /proc/visage-no-such-dir/in.ply",
        ),
    ] {
        let o = visage(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(code), "{args:?}: {err}");
        let last = err.trim().lines().last().unwrap_or("");
        assert!(last.contains(needle), "{args:?}: {err}");
        assert_eq!(
            err.lines()
                .filter(|l| l.starts_with("visage: cannot"))
                .count(),
            1
        );
    }
}
