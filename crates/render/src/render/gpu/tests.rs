//! Tests of the GPU renderer: kernels against their CPU counterparts,
//! layouts and rasterisers against each other bit for bit, failures.
/// lavapipe binds 128 MiB and the SH has two bindings: a million
/// degree-3 Gaussians (192 MB of SH) keep degree 3, 1.5 million drop to
/// degree 2, 2.7 million to degree 1; a big binding keeps all.
/// Dropping bands keeps each Gaussian's lowest coefficients in order;
/// keeping them all copies nothing.
#[test]
fn sh_up_to_a_degree_keeps_each_gaussians_low_bands() {
    let sh: Vec<f32> = (0..2 * 48).map(|k| k as f32).collect();
    let kept = super::sh_up_to_degree(&sh, 3, 1);
    let expected: Vec<f32> = (0..12).chain(48..60).map(|k| k as f32).collect();
    assert_eq!(&kept[..], &expected[..]);
    assert!(matches!(
        super::sh_up_to_degree(&sh, 3, 3),
        std::borrow::Cow::Borrowed(_)
    ));
}

#[test]
fn sh_bands_are_dropped_only_when_the_binding_is_too_small() {
    let lavapipe = 128 << 20;
    assert_eq!(super::sh_degree_that_fits(600_000, 3, lavapipe), 3);
    assert_eq!(super::sh_degree_that_fits(1_000_000, 3, lavapipe), 3);
    assert_eq!(super::sh_degree_that_fits(1_500_000, 3, lavapipe), 2);
    assert_eq!(super::sh_degree_that_fits(2_700_000, 3, lavapipe), 1);
    assert_eq!(super::sh_degree_that_fits(20_000_000, 3, lavapipe), 0);
    assert_eq!(
        super::sh_degree_that_fits(5_000_000, 3, u64::from(u32::MAX)),
        3
    );
    assert_eq!(super::sh_degree_that_fits(1_000_000, 1, lavapipe), 1);
}

use glam::{Quat, Vec3};
use rand::{Rng, SeedableRng};

use super::*;
use crate::avatar::binding::{local_to_world, triangle_frames};
use crate::avatar::gaussians::sigmoid;
use crate::scene::camera::Orbit;

/// Kernel level: `bind` places every Gaussian (f32 on the GPU) as the CPU
/// binding does, degenerate triangles and unnormalised rotations included.
/// The bind kernel runs only when the frames change: a camera move (or
/// a world scene's every frame after the first) reuses the bound
/// Gaussians, and each image equals a fresh renderer's.
/// A scene whose SH outgrows one binding is drawn from two, with every
/// band: the same image as from one binding; past two bindings, bands
/// are dropped and the renderer says so.
#[test]
fn sh_split_over_two_bindings_draws_the_same_image() {
    let scene = crate::scene::synthetic::synthetic_scene(1_000, 2);
    let camera = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap()
        .camera(64, 48);
    let settings = RenderSettings::default();
    let draw = |limit: Option<u64>| {
        let mut r = GpuRenderer::new().unwrap();
        r.sh_binding_limit = limit;
        r.set_world_scene(&scene).unwrap();
        let image = r.render(&[crate::scene::splats::IDENTITY_FRAME], &camera, &settings);
        (
            image.unwrap(),
            r.sh_notice(),
            r.scene.as_ref().unwrap().sh_split,
        )
    };
    let (whole, notice, split) = draw(None);
    assert_eq!((notice, split), (None, 1_000));
    // 192 bytes of SH a Gaussian: 600 fit one binding of 115,200 bytes.
    let (halves, notice, split) = draw(Some(115_200));
    assert_eq!((notice, split), (None, 600));
    assert!(halves == whole);
    let (_, notice, _) = draw(Some(60_000));
    assert!(notice.unwrap().contains("SH degree 2 of 3"));
}

/// Per-element kernels past [`device::MAX_GROUPS`] workgroups (20M
/// Gaussians once failed wgpu's validation) run as rows of a 2D grid;
/// a grid of 3 columns on a small scene exercises the same layout,
/// rows cut short included, and draws the one-row image bit for bit.
#[test]
fn kernels_laid_out_in_rows_draw_the_same_image() {
    assert_eq!(element_grid(20_000_000, device::MAX_GROUPS), (65_535, 2));
    assert_eq!(element_grid(0, device::MAX_GROUPS), (1, 1));
    assert_eq!(element_grid(20_000, 3), (3, 27));
    let scene = crate::scene::synthetic::synthetic_scene(20_000, 3);
    let camera = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap()
        .camera(96, 64);
    let draw = |columns: u32| {
        let mut r = GpuRenderer::new().unwrap();
        r.binning.grid_columns = columns;
        r.set_world_scene(&scene).unwrap();
        r.render(
            &[crate::scene::splats::IDENTITY_FRAME],
            &camera,
            &RenderSettings::default(),
        )
        .unwrap()
    };
    let one_row = draw(device::MAX_GROUPS);
    let rows = draw(3);
    assert!(rows == one_row);
    let reference =
        crate::render::reference::render_reference(&scene, &camera, &RenderSettings::default());
    assert!(crate::render::image::psnr_report(&rows, &reference).unwrap() > 50.0);
}

/// The hardware GPUs' batched rasteriser draws the plain one's image bit
/// for bit: a dense scene whose pixels saturate mid-batch, tiles cut by
/// the image's edge (70×50 is not a multiple of 16), tiles with no
/// Gaussians, lists longer than one batch; and with an early stop high
/// enough that whole tiles saturate batches before their lists end (the
/// tile's stop must wait for its last pixel). lavapipe runs both.
#[test]
fn batched_rasteriser_draws_the_plain_image() {
    let scene = crate::scene::synthetic::synthetic_scene(30_000, 4);
    let orbit = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap();
    let early = RenderSettings {
        early_stop: 0.05,
        ..RenderSettings::default()
    };
    for ((w, h), settings) in [
        ((70, 50), RenderSettings::default()),
        ((160, 120), RenderSettings::default()),
        ((70, 50), early),
        ((160, 120), early),
    ] {
        let camera = orbit.camera(w, h);
        let draw = |software: bool| {
            let mut r = GpuRenderer::new().unwrap();
            r.rasterize = TileRasterizer::for_adapter(&r.device, software);
            r.set_world_scene(&scene).unwrap();
            r.render(&[crate::scene::splats::IDENTITY_FRAME], &camera, &settings)
                .unwrap()
        };
        let (plain, batched) = (draw(true), draw(false));
        assert!(
            batched == plain,
            "{w}x{h}, early stop {}",
            settings.early_stop
        );
    }
}

/// The room for a frame's tile entries is planned from the last frame's:
/// a frame needing more (a larger image after a small one: twice the
/// entries, beyond the eighth and the floor planned over them) is drawn
/// again, the same as a fresh renderer draws it, and the frames after it
/// fit their room without a second drawing.
#[test]
fn a_frame_that_outgrows_its_planned_room_is_drawn_whole() {
    let scene = crate::scene::synthetic::synthetic_scene(30_000, 2);
    let orbit = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap();
    let settings = RenderSettings::default();
    let (small, large) = (orbit.camera(320, 240), orbit.camera(1280, 960));
    let identity = [crate::scene::splats::IDENTITY_FRAME];
    let mut reused = GpuRenderer::new().unwrap();
    reused.set_world_scene(&scene).unwrap();
    reused.render(&identity, &small, &settings).unwrap();
    assert_eq!(reused.redrawn_frames, 0);
    let after_small = reused.render(&identity, &large, &settings).unwrap();
    assert_eq!(reused.redrawn_frames, 1);
    let again = reused.render(&identity, &large, &settings).unwrap();
    assert_eq!(reused.redrawn_frames, 1);
    // After a frame outgrew its room, the next ones get half more.
    let room = &reused.binning.entry_room;
    let (room, total) = (room.given, room.settled);
    assert!(room >= total + total / 2, "room {room} for {total} entries");
    let mut fresh = GpuRenderer::new().unwrap();
    fresh.set_world_scene(&scene).unwrap();
    let expected = fresh.render(&identity, &large, &settings).unwrap();
    assert!(after_small == expected && again == expected);
}

#[test]
fn binding_is_redone_only_when_the_frames_change() {
    let positions = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z];
    let triangles = [[0, 1, 2], [0, 2, 3]];
    let still = triangle_frames(&positions, &triangles);
    let moved = triangle_frames(&positions.map(|p| p * 1.2 + Vec3::X * 0.1), &triangles);
    let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
    for i in 0..200u32 {
        let t = i as f32 * 0.05;
        set.push(
            i % 2,
            Vec3::new(t.sin(), t.cos(), 0.1) * 0.3,
            Quat::IDENTITY,
            Vec3::splat(-3.0),
            1.0,
            &[0.5, 0.2, 0.1],
        );
    }
    let settings = RenderSettings::default();
    let fresh = |frames: &[TriangleFrame], camera: &Camera| {
        let mut r = GpuRenderer::new().unwrap();
        r.set_gaussians(&set).unwrap();
        r.render(frames, camera, &settings).unwrap()
    };
    let near = Orbit {
        radius: 2.0,
        target: [0.3, 0.3, 0.0],
        ..Orbit::STUDY
    }
    .camera(48, 40);
    let far = Orbit {
        radius: 3.0,
        ..Orbit::STUDY
    }
    .camera(48, 40);
    let mut renderer = GpuRenderer::new().unwrap();
    renderer.set_gaussians(&set).unwrap();
    let steps: [(&[TriangleFrame], &Camera, u64); 4] = [
        (&still, &near, 1),
        (&still, &far, 1),
        (&moved, &far, 2),
        (&still, &far, 3),
    ];
    for (k, (frames, camera, binds)) in steps.into_iter().enumerate() {
        let image = renderer.render(frames, camera, &settings).unwrap();
        assert_eq!(renderer.bind_dispatches, binds, "step {k}");
        assert_eq!(image, fresh(frames, camera), "step {k}");
    }
    renderer.set_gaussians(&set).unwrap();
    renderer.render(&still, &far, &settings).unwrap();
    assert_eq!(renderer.bind_dispatches, 4, "a new upload is bound again");
}

#[test]
fn bind_kernel_matches_the_cpu_binding() {
    let mut renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    let mut v = || {
        Vec3::new(
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
            rng.random_range(-1.0..1.0),
        )
    };
    let mut positions: Vec<Vec3> = (0..30).map(|_| v()).collect();
    positions.push(positions[0]); // a repeated vertex: a degenerate triangle
    let mut triangles: Vec<[u32; 3]> = (0..10).map(|t| [3 * t, 3 * t + 1, 3 * t + 2]).collect();
    triangles.push([0, 30, 1]);
    let frames = triangle_frames(&positions, &triangles);
    let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(6);
    for i in 0..700u32 {
        let mut r = || rng.random_range(-1.0f32..1.0);
        let q = Quat::from_xyzw(r(), r(), r(), r() + 1.5); // unnormalised
        set.push(
            i % triangles.len() as u32,
            Vec3::new(r(), r(), r()),
            q,
            Vec3::new(r(), r(), r()) * 3.0,
            r() * 4.0,
            &[0.5, 0.5, 0.5],
        );
    }
    renderer.set_gaussians(&set).unwrap();
    renderer
        .render(
            &frames,
            &Orbit::STUDY.camera(32, 24),
            &RenderSettings::default(),
        )
        .unwrap();
    let scene = renderer.scene.as_ref().unwrap();
    let bytes = set.len() as u64 * 48;
    let staging = renderer.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = renderer.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(&scene.world, 0, &staging, 0, bytes);
    renderer.queue.submit([encoder.finish()]);
    let world: Vec<f32> = device::read_buffer(&renderer.device, &staging, bytes).unwrap();
    for i in 0..set.len() {
        let w = &world[12 * i..12 * i + 12];
        let frame = &frames[set.binding[i] as usize];
        let cpu = local_to_world(frame, set.position[i], set.rotation[i], set.log_scale[i]);
        let close = |a: f32, b: f32, what: &str| {
            assert!(
                (a - b).abs() <= 1e-5 * (1.0 + b.abs()),
                "Gaussian {i} {what}: GPU {a}, CPU {b}"
            );
        };
        for c in 0..3 {
            close(w[c], cpu.position[c], "position");
            close(w[8 + c], cpu.scale[c], "scale");
        }
        close(w[3], sigmoid(set.opacity_logit[i]), "opacity");
        let gpu_q = Quat::from_xyzw(w[5], w[6], w[7], w[4]);
        assert!(
            gpu_q.dot(cpu.rotation).abs() > 1.0 - 1e-5,
            "Gaussian {i} rotation"
        );
    }
}

/// Kernel level: `project` (f32) culls the same Gaussians as the CPU
/// renderer's f64 projection and writes the same depth and tile rectangle,
/// but for rounding at the edges: Gaussians behind, at and just in front of
/// the camera, tiny and huge scales included.
#[test]
fn project_kernel_matches_the_cpu_projection() {
    let mut gpu = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
    let mut cpu = crate::render::cpu::CpuRenderer::new();
    let frames = triangle_frames(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut set = crate::avatar::gaussians::GaussianSet::with_degree(1);
    for k in 0..4_000 {
        let mut r = || rng.random_range(-1.0f32..1.0);
        // Spread along the view axis through and behind the camera (at z = 3).
        let position = Vec3::new(r() * 1.5, r() * 1.5, r() * 4.0);
        let log_scale = match k % 10 {
            0 => Vec3::splat(-12.0), // tiny
            1 => Vec3::splat(1.0),   // huge
            _ => Vec3::new(r(), r(), r()) * 2.0 - Vec3::splat(3.0),
        };
        let sh: Vec<f32> = (0..12).map(|_| r() * 0.5).collect();
        set.push(
            0,
            position,
            Quat::from_xyzw(r(), r(), r(), 1.0),
            log_scale,
            r() * 3.0,
            &sh,
        );
    }
    let camera = Orbit {
        radius: 3.0,
        fov_deg: 50.0,
        target: [0.0, 0.0, 0.0],
        ..Orbit::STUDY
    }
    .camera(160, 120);
    let settings = RenderSettings::default();
    gpu.set_gaussians(&set).unwrap();
    gpu.render(&frames, &camera, &settings).unwrap();
    cpu.set_gaussians(&set);
    cpu.render(&frames, &camera, &settings).unwrap();
    let scene = gpu.scene.as_ref().unwrap();
    let bytes = set.len() as u64 * 16;
    let staging = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: bytes,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(&scene.keys, 0, &staging, 0, bytes);
    gpu.queue.submit([encoder.finish()]);
    let keys: Vec<[u32; 4]> = device::read_buffer(&gpu.device, &staging, bytes).unwrap();
    let (mut visible, mut differ) = (0, 0);
    for (i, (g, c)) in keys.iter().zip(cpu.keys()).enumerate() {
        if g[3] != c[3] || g[1..3] != c[1..3] {
            differ += 1;
            continue;
        }
        if c[3] == 1 {
            visible += 1;
            let (a, b) = (f32::from_bits(g[0]), f32::from_bits(c[0]));
            assert!(
                (a - b).abs() <= 1e-5 * b.abs(),
                "Gaussian {i}: depth {a} vs {b}"
            );
        }
    }
    assert!(visible > 500, "only {visible} visible");
    assert!(
        differ * 200 <= keys.len(),
        "{differ} of {} keys differ",
        keys.len()
    );
}

/// Kernel level: `pack_rgb` keeps the RGB bytes of every RGBA pixel, in
/// order, across image sizes that do not fill whole words or workgroups.
#[test]
fn pack_rgb_kernel_matches_the_cpu_packing() {
    let mut renderer = GpuRenderer::new().expect("a wgpu adapter (lavapipe in CI)");
    let mut set = crate::avatar::gaussians::GaussianSet::with_degree(0);
    set.push(
        0,
        Vec3::ZERO,
        Quat::IDENTITY,
        Vec3::splat(-2.0),
        3.0,
        &[1.0, -0.5, 0.2],
    );
    renderer.set_gaussians(&set).unwrap();
    let frames = triangle_frames(&[Vec3::ZERO, Vec3::X, Vec3::Y], &[[0, 1, 2]]);
    for (w, h) in [(1, 1), (7, 5), (33, 17), (160, 120)] {
        let camera = Orbit {
            radius: 3.0,
            fov_deg: 60.0,
            target: [0.3, 0.3, 0.0],
            ..Orbit::STUDY
        }
        .camera(w, h);
        let image = renderer
            .render(&frames, &camera, &RenderSettings::default())
            .unwrap();
        // The RGBA image the rasteriser wrote, packed on the CPU.
        let words = (w * h) as u64;
        let staging = renderer.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: words * 4,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = renderer.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&renderer.image.buffer, 0, &staging, 0, words * 4);
        renderer.queue.submit([encoder.finish()]);
        let rgba: Vec<u32> = device::read_buffer(&renderer.device, &staging, words * 4).unwrap();
        let cpu: Vec<u8> = rgba
            .iter()
            .flat_map(|p| p.to_le_bytes()[..3].to_vec())
            .collect();
        assert_eq!(image.pixels, cpu, "{w}x{h}");
        assert!(cpu.iter().any(|&c| c > 0), "{w}x{h}: something drawn");
    }
}

/// A sort past the device's largest binding (its buffers grow to powers of
/// two and are bound whole) is refused in one line naming the way out, and
/// the refused frame leaves the renderer drawing the next one as a fresh
/// renderer does.
#[test]
fn a_refused_frame_leaves_the_renderer_drawing() {
    let scene = crate::scene::synthetic::synthetic_scene(20_000, 5);
    let camera = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap()
        .camera(96, 64);
    let settings = RenderSettings::default();
    let frames = [crate::scene::splats::IDENTITY_FRAME];
    let mut fresh = GpuRenderer::new().unwrap();
    fresh.set_world_scene(&scene).unwrap();
    let expected = fresh.render(&frames, &camera, &settings).unwrap();

    let mut r = GpuRenderer::new().unwrap();
    r.set_world_scene(&scene).unwrap();
    let limit = r.binning.max_binding;
    // 20,000 keys of 4 bytes grow to 128 KiB.
    r.binning.max_binding = 64 << 10;
    let refused = r.render(&frames, &camera, &settings);
    let Err(Error::Device(message)) = refused else {
        panic!("{refused:?}");
    };
    assert!(
        message.contains("--lod auto") && !message.contains('\n'),
        "{message}"
    );
    r.binning.max_binding = limit;
    assert!(r.render(&frames, &camera, &settings).unwrap() == expected);
}

/// The cut the GPU chooses node by node is the CPU's tree walk's: for a
/// far, a middle and a close camera (near plane inside the scene), the
/// same Gaussians reach the screen and the image is the image of the
/// CPU's gathered cut drawn as a scene (merged nodes' opacity computed in
/// f32 on the GPU, in f64 on the CPU). Uploading a plain scene afterwards
/// forgets the hierarchy.
#[test]
fn gpu_cut_draws_the_cpu_cut() {
    use crate::render::lod::{build, LodPolicy, AUTO_PIXELS};
    let scene = crate::scene::synthetic::synthetic_scene(20_000, 9);
    let tree = build(&scene);
    let home = scene
        .home_orbit(None, crate::scene::camera::UpAxis::default())
        .unwrap();
    let settings = RenderSettings::default();
    let mut plain = GpuRenderer::new().unwrap();
    let mut lod = GpuRenderer::new().unwrap();
    lod.set_lod_tree(&tree, 7).unwrap();
    assert_eq!(lod.lod_name(), Some(7));
    for (radius, (w, h)) in [(2.0, (48, 32)), (1.0, (120, 80)), (0.15, (96, 64))] {
        let orbit = Orbit {
            radius: home.radius * radius,
            ..home
        };
        let camera = orbit.camera(w, h);
        let cut = tree.cut(&camera, LodPolicy::Auto);
        // Close up, every node on screen is larger than the threshold.
        assert_eq!(
            cut.leaves < cut.nodes.len(),
            radius >= 1.0,
            "merged at {radius}"
        );
        plain.set_world_scene(&tree.gather(&cut, &camera)).unwrap();
        let expected = plain
            .render(&[crate::scene::splats::IDENTITY_FRAME], &camera, &settings)
            .unwrap();
        let image = lod.render_lod(&camera, &settings, AUTO_PIXELS).unwrap();
        assert_eq!(lod.drawn().0, plain.drawn().0, "drawn at {radius}");
        assert!(lod.drawn().1 <= cut.leaves as u32);
        let worst = image
            .pixels
            .iter()
            .zip(&expected.pixels)
            .map(|(a, b)| a.abs_diff(*b))
            .max()
            .unwrap();
        assert!(worst <= 2, "pixels differ by {worst} at {radius}");
    }
    // A hierarchy of one Gaussian (its root a leaf) draws it; one of a
    // scene with nothing drawable draws nothing.
    let mut one = crate::scene::splats::SplatScene::with_degree(scene.sh_degree);
    one.push(
        Vec3::from(home.target),
        scene.rotation[0],
        Vec3::splat(0.05),
        0.9,
        scene.sh_of(0),
    );
    let camera = home.camera(32, 24);
    let mut single = GpuRenderer::new().unwrap();
    single.set_lod_tree(&build(&one), 1).unwrap();
    single.render_lod(&camera, &settings, AUTO_PIXELS).unwrap();
    assert_eq!(single.drawn(), (1, 1));
    one.opacity[0] = 0.0;
    single.set_lod_tree(&build(&one), 2).unwrap();
    let blank = single.render_lod(&camera, &settings, AUTO_PIXELS).unwrap();
    assert_eq!(single.drawn(), (0, 0));
    assert!(blank.pixels.iter().all(|&p| p == 0));

    // Without a threshold the hierarchy is drawn whole: every node in view.
    lod.render(
        &[crate::scene::splats::IDENTITY_FRAME],
        &home.camera(48, 32),
        &settings,
    )
    .unwrap();
    assert!(lod.drawn().0 as usize > tree.leaves);
    plain.set_world_scene(&scene).unwrap();
    assert_eq!(plain.lod_name(), None);
    lod.set_world_scene(&scene).unwrap();
    assert_eq!(lod.lod_name(), None);
    assert!(lod
        .render_lod(&home.camera(48, 32), &settings, AUTO_PIXELS)
        .is_err());
}
