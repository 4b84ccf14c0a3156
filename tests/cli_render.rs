//! `visage render` and `visage bench render` as a user runs them.

use std::process::Command;

use glam::{Quat, Vec3};
use visage::io::ply::write_splat_ply;
use visage::render::image::{psnr, RgbImage};
use visage::render::scene::SplatScene;

fn visage(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_visage"))
        .env("NODEVICE_SELECT", "1")
        .args(args)
        .output()
        .unwrap()
}

fn temp(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("visage-cli-render-{}-{name}", std::process::id()))
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

#[test]
fn renders_standard_3dgs_plys_of_degree_0_and_3_like_the_reference() {
    for degree in [0u8, 3] {
        let ply = temp(&format!("ring{degree}.ply"));
        write_splat_ply(&ply, &ring_scene(degree)).unwrap();
        let (fast, slow) = (
            temp(&format!("fast{degree}.png")),
            temp(&format!("ref{degree}.png")),
        );
        for (out, extra) in [(&fast, None), (&slow, Some("--reference"))] {
            let mut args = vec![
                "render",
                "--ply",
                ply.to_str().unwrap(),
                "--size",
                "80x60",
                "-o",
                out.to_str().unwrap(),
            ];
            args.extend(extra);
            let o = visage(&args);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
        let (a, b) = (
            RgbImage::load_png(&fast).unwrap(),
            RgbImage::load_png(&slow).unwrap(),
        );
        assert_eq!((a.width, a.height), (80, 60));
        assert!(psnr(&a, &b).unwrap() >= 40.0, "degree {degree}");
        assert!(a.pixels.iter().any(|&v| v > 30), "the ring is visible");
        for p in [ply, fast, slow] {
            std::fs::remove_file(p).ok();
        }
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
