//! Renderers against the f64 reference: the built-in composite and hard scenes,
//! on wgpu (lavapipe in CI) and on the CPU renderer.

use std::sync::{Mutex, OnceLock};

use glam::{Quat, Vec3};
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::engine::{Engine, PosedMesh};
use visage::compose::recipe::{ColourCorrection, GroupEdit, Recipe, Smoothing};
use visage::model::builtin::build_head;
use visage::render::image::{psnr, RgbImage};
use visage::render::reference::{render_reference, render_reference_f32};
use visage::render::settings::RenderSettings;
use visage::render::{Backend, SplatRenderer};
use visage::scene::camera::{Camera, Orbit};
use visage::scene::splats::SplatScene;

/// One wgpu renderer for the whole test binary (shader compilation is slow on lavapipe).
fn gpu() -> &'static Mutex<SplatRenderer> {
    static GPU: OnceLock<Mutex<SplatRenderer>> = OnceLock::new();
    GPU.get_or_init(|| {
        Mutex::new(SplatRenderer::open(Backend::Gpu).expect("a wgpu adapter (lavapipe in CI)"))
    })
}

fn renderers() -> Vec<(&'static str, std::sync::MutexGuard<'static, SplatRenderer>)> {
    static CPU: OnceLock<Mutex<SplatRenderer>> = OnceLock::new();
    let cpu = CPU.get_or_init(|| Mutex::new(SplatRenderer::open(Backend::Cpu).unwrap()));
    vec![
        ("gpu", gpu().lock().unwrap_or_else(|e| e.into_inner())),
        ("cpu", cpu.lock().unwrap_or_else(|e| e.into_inner())),
    ]
}

fn camera_at(eye: Vec3, target: Vec3, w: u32, h: u32, fov_deg: f32) -> Camera {
    Camera {
        eye,
        target,
        up: Vec3::Y,
        fov_y: fov_deg.to_radians(),
        width: w,
        height: h,
        near: 0.01,
        far: 100.0,
    }
}

/// Renders a world scene on every renderer and checks it against the reference.
fn check_scene(name: &str, scene: &SplatScene, camera: &Camera, min_psnr: f64) {
    let settings = RenderSettings {
        background: [0.1, 0.2, 0.3],
        ..Default::default()
    };
    let float = render_reference_f32(scene, camera, &settings);
    assert!(
        float.iter().all(|c| c.is_finite()),
        "{name}: NaN in the reference"
    );
    let reference = RgbImage::from_f32(camera.width, camera.height, &float);
    let background = RgbImage::new(camera.width, camera.height, [26, 51, 77]);
    let drawn = reference
        .pixels
        .chunks(3)
        .zip(background.pixels.chunks(3))
        .filter(|(a, b)| a != b)
        .count();
    if min_psnr < 99.0 {
        assert!(
            drawn > 0,
            "{name}: the scene draws nothing; the test would prove nothing"
        );
    } else {
        assert_eq!(drawn, 0, "{name}: expected only background");
    }
    for (backend, mut r) in renderers() {
        r.set_world_scene(scene).unwrap();
        let a = r.render_world(camera, &settings).unwrap();
        let b = r.render_world(camera, &settings).unwrap();
        assert_eq!(
            a, b,
            "{name} on {backend}: the same scene renders the same bytes"
        );
        let p = psnr(&a, &reference).unwrap();
        assert!(
            p >= min_psnr,
            "{name} on {backend}: PSNR {p:.1} dB against the reference"
        );
    }
}

fn grey_sh(degree: u8, seed: u32) -> Vec<f32> {
    let n = 3 * (degree as usize + 1).pow(2);
    (0..n)
        .map(|k| {
            let h = (k as u32)
                .wrapping_mul(2_654_435_761)
                .wrapping_add(seed.wrapping_mul(40_503));
            if k < 3 {
                ((h >> 8) % 1000) as f32 / 1000.0 * 2.0 - 0.5
            } else {
                ((h >> 8) % 1000) as f32 / 1000.0 * 0.4 - 0.2
            }
        })
        .collect()
}

#[test]
fn builtin_composite_matches_the_reference_on_every_renderer() {
    let db = builtin_database(
        build_head(),
        SyntheticOptions {
            seed: 2,
            sources: 3,
            gaussians_per_avatar: 15_000,
        },
    )
    .unwrap();
    let engine = Engine::new(db).unwrap();
    let mut recipe = Recipe::unedited("ada");
    recipe.groups.insert(
        "nose".into(),
        GroupEdit {
            gaussians: "cleo".into(),
            shape: [("cleo".to_string(), 1.0)].into(),
        },
    );
    recipe.groups.insert(
        "eyes".into(),
        GroupEdit {
            gaussians: "bram".into(),
            shape: [("bram".to_string(), 0.5), ("ada".to_string(), 0.5)].into(),
        },
    );
    recipe.post.smoothing = Smoothing::Crossfade;
    recipe.post.colour = ColourCorrection::Thesis;
    recipe.animation.motion = "talk".into();
    let resolved = recipe.resolve(engine.database()).unwrap();
    let composite = engine.compose(&resolved);
    let mut posed = PosedMesh::default();
    engine.pose(&composite, 30, &mut posed);
    let scene = engine.scene(&composite, &posed);
    for (yaw, size) in [(0.0, (96, 128)), (35.0, (120, 90))] {
        let camera = Orbit {
            yaw_deg: yaw,
            ..Orbit::STUDY
        }
        .camera(size.0, size.1);
        let reference = render_reference(&scene, &camera, &RenderSettings::default());
        for (backend, mut r) in renderers() {
            r.set_gaussians(&composite.gaussians).unwrap();
            let image = r
                .render(&posed.frames, &camera, &RenderSettings::default())
                .unwrap();
            let p = psnr(&image, &reference).unwrap();
            assert!(
                p >= 40.0,
                "composite at yaw {yaw} on {backend}: PSNR {p:.1} dB"
            );
            // Something was drawn: the head covers a good part of the image.
            let lit = image
                .pixels
                .chunks(3)
                .filter(|c| c.iter().any(|&v| v > 10))
                .count();
            assert!(
                lit * 5 > (size.0 * size.1) as usize,
                "{backend}: only {lit} pixels drawn"
            );
        }
    }
}

#[test]
fn gaussians_behind_the_camera_and_across_the_near_plane() {
    let camera = camera_at(Vec3::ZERO, Vec3::NEG_Z, 64, 48, 60.0);
    let mut scene = SplatScene::with_degree(0);
    for (k, z) in [
        0.5f32, 0.02, 0.0101, 0.0099, 0.0, -0.005, -0.5, -0.02, -0.015,
    ]
    .iter()
    .enumerate()
    {
        let x = (k as f32 - 4.0) * 0.004 * z.abs().max(0.01) * 10.0;
        scene.push(
            Vec3::new(x, 0.0, -z),
            Quat::IDENTITY,
            Vec3::splat(0.01),
            0.8,
            &grey_sh(0, k as u32),
        );
    }
    // A big one straddling the near plane.
    scene.push(
        Vec3::new(0.0, 0.0, -0.012),
        Quat::IDENTITY,
        Vec3::splat(0.05),
        0.6,
        &grey_sh(0, 99),
    );
    check_scene("near plane", &scene, &camera, 40.0);
}

#[test]
fn huge_tiny_zero_scales_and_bad_rotations() {
    let camera = camera_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 64, 64, 40.0);
    let mut scene = SplatScene::with_degree(3);
    let cases = [
        (Vec3::new(0.0, 0.0, -2.0), Vec3::splat(1e3), 0.3), // huge, fills the view
        (Vec3::new(0.3, 0.2, 0.0), Vec3::splat(1e-7), 0.9), // tiny: only the dilation shows
        (Vec3::new(-0.3, 0.2, 0.0), Vec3::ZERO, 0.9),       // zero scale
        (Vec3::new(0.0, -0.3, 0.0), Vec3::new(0.5, 1e-6, 0.05), 0.9), // needle
        (Vec3::new(0.2, -0.2, 0.5), Vec3::new(0.02, 0.3, 0.02), 1.0),
    ];
    for (k, (p, s, o)) in cases.into_iter().enumerate() {
        scene.push(
            p,
            Quat::from_rotation_z(0.4 * k as f32),
            s,
            o,
            &grey_sh(3, k as u32),
        );
    }
    // A zero quaternion becomes the identity rotation.
    scene.push(
        Vec3::new(-0.2, -0.2, 0.2),
        Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
        Vec3::new(0.1, 0.02, 0.02),
        0.8,
        &grey_sh(3, 7),
    );
    check_scene("scales", &scene, &camera, 40.0);
}

/// Flat Gaussians seen almost edge-on (a trained floor or wall at a grazing
/// angle), some exactly flat: the 2D covariance is a long, thin ellipse whose
/// determinant a·c − b² cancels in f32; every renderer must still draw it as
/// the reference does.
#[test]
fn flat_gaussians_seen_edge_on() {
    let camera = camera_at(Vec3::new(0.0, 0.05, 4.0), Vec3::ZERO, 96, 72, 50.0);
    let mut scene = SplatScene::with_degree(1);
    scene.push(
        Vec3::new(0.0, 0.0, -3.0),
        Quat::IDENTITY,
        Vec3::splat(3.0),
        0.9,
        &grey_sh(1, 1),
    );
    for k in 0..12 {
        let tilt = 1.5 + 0.006 * k as f32; // the disc's normal near the view's up
        let centre = Vec3::new(
            -1.2 + 0.22 * k as f32,
            -0.2 + 0.03 * k as f32,
            1.5 - 0.4 * k as f32,
        );
        let flatness = [1e-4, 1e-6, 0.0][k % 3];
        scene.push(
            centre,
            Quat::from_rotation_x(tilt) * Quat::from_rotation_z(0.3 * k as f32),
            Vec3::new(0.6 + 0.1 * k as f32, 2.0, flatness),
            0.95,
            &grey_sh(1, k as u32 + 2),
        );
    }
    check_scene("edge-on discs", &scene, &camera, 40.0);
}

/// A tile whose list is longer than 65,535 entries, with what a pixel shows
/// at the end of it: lavapipe ends any one shader loop after 65,535
/// iterations, which once left such pixels as bare background on the GPU
/// (a dense million-Gaussian scene reaches 130,000 entries in one tile).
#[test]
fn a_tile_list_longer_than_a_driver_loop_limit() {
    let camera = camera_at(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 32, 32, 40.0);
    let mut scene = SplatScene::with_degree(0);
    // In front: 70,000 faint specks over one corner of the first tile…
    let corner = Vec3::new(-0.39, 0.39, 1.0);
    for k in 0..70_000 {
        let jitter = Vec3::new((k % 7) as f32, (k % 5) as f32, (k % 11) as f32) * 1e-4;
        scene.push(
            corner + jitter,
            Quat::IDENTITY,
            Vec3::splat(1e-5),
            0.02,
            &grey_sh(0, k),
        );
    }
    // …and behind them one large Gaussian that every pixel shows.
    scene.push(
        Vec3::new(0.0, 0.0, -1.0),
        Quat::IDENTITY,
        Vec3::splat(2.0),
        0.9,
        &grey_sh(0, 1),
    );
    let settings = RenderSettings::default();
    let reference = render_reference(&scene, &camera, &settings);
    for (backend, mut r) in renderers() {
        r.set_world_scene(&scene).unwrap();
        match r.render_world(&camera, &settings) {
            Ok(image) => {
                let p = psnr(&image, &reference).unwrap();
                assert!(p >= 40.0, "{backend}: PSNR {p:.1} dB against the reference");
            }
            // Never a wrong image: a driver that cuts the walk short is named.
            Err(e) => {
                let software = r.description().contains("llvmpipe");
                assert!(backend == "gpu" && software, "{backend}: {e}");
                assert!(e.to_string().contains("--renderer cpu"), "{e}");
            }
        }
    }
}

#[test]
fn opaque_stacks_terminate_early_without_artefacts() {
    let camera = camera_at(Vec3::new(0.0, 0.0, 2.0), Vec3::ZERO, 48, 48, 30.0);
    let mut scene = SplatScene::with_degree(1);
    for k in 0..200 {
        let z = -(k as f32) * 0.01;
        scene.push(
            Vec3::new(0.01 * (k % 7) as f32, 0.01 * (k % 5) as f32, z),
            Quat::IDENTITY,
            Vec3::new(0.2, 0.2, 0.005),
            1.0,
            &grey_sh(1, k),
        );
    }
    check_scene("opaque stack", &scene, &camera, 40.0);
}

#[test]
fn sh_degree_zero_and_three_and_camera_inside_a_gaussian() {
    for degree in [0u8, 3] {
        let camera = camera_at(Vec3::new(0.4, 0.3, 1.5), Vec3::ZERO, 64, 48, 50.0);
        let mut scene = SplatScene::with_degree(degree);
        for k in 0..400u32 {
            let t = k as f32 * 0.37;
            scene.push(
                Vec3::new(t.sin() * 0.4, (t * 1.3).cos() * 0.3, (t * 0.7).sin() * 0.3),
                Quat::from_rotation_y(t),
                Vec3::new(0.03, 0.02, 0.004),
                0.7,
                &grey_sh(degree, k),
            );
        }
        check_scene(&format!("SH degree {degree}"), &scene, &camera, 40.0);
    }
    // The camera sits inside a large Gaussian whose centre is just in front of it.
    let camera = camera_at(Vec3::ZERO, Vec3::NEG_Z, 48, 48, 70.0);
    let mut scene = SplatScene::with_degree(0);
    scene.push(
        Vec3::new(0.0, 0.0, -0.05),
        Quat::IDENTITY,
        Vec3::splat(2.0),
        0.5,
        &grey_sh(0, 1),
    );
    scene.push(
        Vec3::new(0.1, 0.0, -1.0),
        Quat::IDENTITY,
        Vec3::splat(0.1),
        0.9,
        &grey_sh(0, 2),
    );
    check_scene("camera inside", &scene, &camera, 40.0);
}

#[test]
fn empty_and_fully_culled_scenes_show_the_background() {
    let camera = camera_at(Vec3::ZERO, Vec3::NEG_Z, 32, 16, 60.0);
    let mut scene = SplatScene::with_degree(0);
    scene.push(
        Vec3::new(0.0, 0.0, 1.0),
        Quat::IDENTITY,
        Vec3::splat(0.1),
        0.9,
        &[1.0, 1.0, 1.0],
    );
    check_scene("behind only", &scene, &camera, 99.0);
}

/// Culling: a synthetic scene (floor, backdrop, subject, floaters) seen so that
/// half of it lies outside the view — left, right, below, behind the camera —
/// renders like the reference on every renderer: culling drops only what the
/// reference would not draw.
#[test]
fn a_scene_half_outside_the_frustum_renders_like_the_reference() {
    let scene = visage::scene::synthetic::synthetic_scene(30_000, 3);
    // Standing on the floor inside the scene, looking along it: much of it is
    // behind, beside or below the view.
    let camera = camera_at(
        Vec3::new(0.8, 0.4, 2.2),
        Vec3::new(2.8, 0.3, -2.4),
        96,
        72,
        40.0,
    );
    let cull = visage::render::projection::ProjectionCamera::new(&camera);
    let outside = scene
        .position
        .iter()
        .filter(|p| {
            cull.project_covariance(**p, glam::DMat3::IDENTITY * 1e-8, 1.0)
                .is_none()
        })
        .count();
    assert!(
        outside * 2 >= scene.len(),
        "only {outside} of {} outside the view",
        scene.len()
    );
    check_scene("half outside the frustum", &scene, &camera, 45.0);
}

/// Precision far from the origin: the same synthetic scene and camera moved
/// 10⁴ units away render on the CPU renderer as the reference renders them
/// there (the CPU renderer places centres in view space in f64, as the
/// reference does), and the moved image still resembles the one at the origin.
#[test]
fn a_scene_far_from_the_origin_keeps_its_precision_on_the_cpu() {
    let near_origin = visage::scene::synthetic::synthetic_scene(20_000, 5);
    let offset = Vec3::new(1.0e4, -2.0e4, 1.5e4);
    let mut far = near_origin.clone();
    for p in &mut far.position {
        *p += offset;
    }
    let eye = Vec3::new(0.5, 1.4, 4.0);
    let target = Vec3::new(0.0, 0.9, 0.0);
    let settings = RenderSettings::default();
    let mut cpu = SplatRenderer::open(Backend::Cpu).unwrap();
    let mut render = |scene: &SplatScene, camera: &Camera| {
        cpu.set_world_scene(scene).unwrap();
        let image = cpu.render_world(camera, &settings).unwrap();
        (image, render_reference(scene, camera, &settings))
    };
    let (at_origin, _) = render(&near_origin, &camera_at(eye, target, 120, 90, 45.0));
    let far_camera = camera_at(eye + offset, target + offset, 120, 90, 45.0);
    let (image, reference) = render(&far, &far_camera);
    let p = psnr(&image, &reference).unwrap();
    assert!(
        p >= 60.0,
        "far from the origin: {p:.1} dB against the reference"
    );
    let moved = psnr(&image, &at_origin).unwrap();
    assert!(
        moved >= 40.0,
        "the moved scene no longer resembles itself: {moved:.1} dB"
    );
}
