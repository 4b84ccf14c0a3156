//! The level-of-detail hierarchy as the renderers draw it: a cut against
//! the full scene's image on a scene of mixed scales, budgets, and nodes of
//! opacity above 1 drawn alike by the CPU and GPU renderers.

use glam::{Quat, Vec3};
use visage::render::cpu::CpuRenderer;
use visage::render::image::{psnr_report, RgbImage};
use visage::render::lod::{build, Cut, LodPolicy};
use visage::render::settings::RenderSettings;
use visage::render::{Backend, SplatRenderer};
use visage::scene::camera::{Camera, UpAxis};
use visage::scene::splats::{SplatScene, IDENTITY_FRAME};
use visage::scene::synthetic::synthetic_scene;

fn render(scene: &SplatScene, camera: &Camera) -> RgbImage {
    let mut r = CpuRenderer::new();
    r.set_world_scene(scene);
    r.render(&[IDENTITY_FRAME], camera, &RenderSettings::default())
        .unwrap()
}

/// The synthetic scene plus large splats among its small ones.
fn mixed_scales(n: usize) -> SplatScene {
    let mut scene = synthetic_scene(n, 3);
    for k in 0..20 {
        let t = k as f32 / 20.0;
        scene.push(
            Vec3::new(t * 2.0 - 1.0, 0.2, -0.5),
            Quat::from_rotation_y(t * 3.0),
            Vec3::new(0.3, 0.05, 0.01),
            0.4,
            &[0.8; 48],
        );
    }
    scene
}

fn home(scene: &SplatScene, (w, h): (u32, u32)) -> Camera {
    scene
        .home_orbit(None, UpAxis::default())
        .unwrap()
        .camera(w, h)
}

#[test]
fn the_cut_with_lod_off_leaves_out_only_what_cannot_show() {
    let scene = mixed_scales(4_000);
    let tree = build(&scene);
    let camera = home(&scene, (160, 100));
    let cut = tree.cut(&camera, LodPolicy::Off);
    assert_eq!(cut.leaves, cut.nodes.len());
    assert!(
        cut.nodes.len() < tree.leaves,
        "off-screen floaters are left out"
    );
    let every_leaf = Cut {
        nodes: (0..tree.len() as u32)
            .filter(|&n| tree.links[n as usize].children == 0)
            .collect(),
        ..Cut::default()
    };
    // Same order (node order), so the same image to the bit.
    assert!(
        render(&tree.gather(&cut, &camera), &camera)
            == render(&tree.gather(&every_leaf, &camera), &camera)
    );
}

#[test]
fn the_auto_cut_draws_far_fewer_gaussians_and_stays_close_to_the_full_scene() {
    let scene = mixed_scales(60_000);
    let tree = build(&scene);
    let camera = home(&scene, (120, 80));
    let cut = tree.cut(&camera, LodPolicy::Auto);
    let exact = render(&scene, &camera);
    let psnr = psnr_report(&render(&tree.gather(&cut, &camera), &camera), &exact).unwrap();
    assert!(
        cut.nodes.len() * 2 < scene.len(),
        "{} drawn",
        cut.nodes.len()
    );
    assert!(cut.levels.0 < cut.levels.1);
    assert!(psnr >= 35.0, "{psnr} dB with {} drawn", cut.nodes.len());
    // Closer, the cut refines: more of the scene's own Gaussians.
    let mut near = camera;
    near.eye = camera.target + (camera.eye - camera.target) * 0.3;
    assert!(tree.cut(&near, LodPolicy::Auto).leaves > cut.leaves);
}

#[test]
fn a_budget_caps_the_cut_and_buys_accuracy() {
    let scene = mixed_scales(20_000);
    let tree = build(&scene);
    let camera = home(&scene, (200, 120));
    for budget in [1, 50, 2_000] {
        let cut = tree.cut(&camera, LodPolicy::Budget(budget));
        assert!(cut.nodes.len() <= budget, "{} > {budget}", cut.nodes.len());
        assert!(!cut.nodes.is_empty());
    }
    let exact = render(&scene, &camera);
    let psnr = |budget| {
        let cut = tree.cut(&camera, LodPolicy::Budget(budget));
        psnr_report(&render(&tree.gather(&cut, &camera), &camera), &exact).unwrap()
    };
    assert!(psnr(4_000) > psnr(400) + 1.0);
    let auto = tree.cut(&camera, LodPolicy::Auto);
    let roomy = tree.cut(&camera, LodPolicy::Budget(auto.nodes.len() * 2));
    assert_eq!(
        roomy.nodes, auto.nodes,
        "a budget above auto's count is auto"
    );
}

#[test]
fn nodes_above_opacity_one_draw_alike_on_cpu_and_gpu() {
    let scene = mixed_scales(30_000);
    let tree = build(&scene);
    let camera = home(&scene, (96, 64));
    let cut = tree.cut(&camera, LodPolicy::Budget(3_000));
    let drawn = tree.gather(&cut, &camera);
    assert!(drawn.opacity.iter().any(|&o| o > 1.5), "merged surfaces");
    let cpu = render(&drawn, &camera);
    let mut gpu = SplatRenderer::open(Backend::Gpu).expect("a wgpu adapter (lavapipe in CI)");
    gpu.set_world_scene(&drawn).unwrap();
    let on_gpu = gpu
        .render_world(&camera, &RenderSettings::default())
        .unwrap();
    let psnr = psnr_report(&on_gpu, &cpu).unwrap();
    assert!(psnr > 40.0, "{psnr} dB");
    // Capped at 1 the picture differs: the opacity above 1 is drawn.
    let mut capped = drawn.clone();
    capped.opacity.iter_mut().for_each(|o| *o = o.min(1.0));
    assert!(psnr_report(&render(&capped, &camera), &cpu).unwrap() < psnr - 5.0);
}
