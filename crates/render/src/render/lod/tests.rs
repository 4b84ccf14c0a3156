use glam::{Quat, Vec3};

use super::*;
use crate::scene::camera::Camera;
use crate::scene::synthetic::synthetic_scene;

#[test]
fn every_drawable_gaussian_is_one_leaf_below_the_root() {
    let mut scene = synthetic_scene(3_000, 3);
    scene.push(Vec3::NAN, Quat::IDENTITY, Vec3::ONE, 0.5, &[0.0; 48]);
    scene.push(Vec3::ZERO, Quat::IDENTITY, Vec3::ONE, 0.0, &[0.0; 48]);
    let tree = build(&scene);
    assert_eq!(tree.dropped, 2);
    assert_eq!(tree.leaves, scene.len() - 2);
    let mut seen_leaves = 0;
    let mut parent_of = vec![None; tree.len()];
    for (i, link) in tree.links.iter().enumerate() {
        if link.children == 0 {
            seen_leaves += 1;
            continue;
        }
        assert!(link.children >= 2 && link.children as usize <= MAX_CHILDREN);
        assert!(
            link.first_child as usize > i,
            "breadth-first: children after parents"
        );
        for c in link.first_child..link.first_child + link.children {
            assert!(parent_of[c as usize].replace(i).is_none(), "one parent");
            assert_eq!(tree.links[c as usize].level, link.level + 1);
        }
    }
    assert_eq!(seen_leaves, tree.leaves);
    assert!(parent_of[1..].iter().all(Option::is_some) && parent_of[0].is_none());
    // Every node's sphere holds its children's spheres.
    for (c, parent) in parent_of.iter().enumerate().skip(1) {
        let p = parent.unwrap();
        let gap = (tree.nodes.position[c] - tree.nodes.position[p]).length();
        let slack = 1e-4 * tree.links[p].extent.max(1.0);
        assert!(gap + tree.links[c].extent <= tree.links[p].extent + slack);
    }
}

#[test]
fn gaussians_behind_the_camera_are_not_drawn() {
    let mut scene = SplatScene::with_degree(0);
    for i in 0..200 {
        let z = if i % 2 == 0 { -5.0 } else { 5.0 };
        scene.push(
            Vec3::new(i as f32 * 0.01, 0.0, z),
            Quat::IDENTITY,
            Vec3::splat(0.01),
            0.9,
            &[1.0; 3],
        );
    }
    let tree = build(&scene);
    let camera = Camera {
        eye: Vec3::ZERO,
        target: Vec3::new(0.0, 0.0, -1.0),
        up: Vec3::Y,
        fov_y: 1.0,
        width: 64,
        height: 64,
        near: 0.01,
        far: 100.0,
    };
    for policy in [LodPolicy::Off, LodPolicy::Auto] {
        let cut = tree.cut(&camera, policy);
        assert!(!cut.nodes.is_empty());
        assert!(cut
            .nodes
            .iter()
            .all(|&n| tree.nodes.position[n as usize].z < 0.0));
    }
    // A camera inside the cloud still opens the nodes around it.
    let inside = Camera {
        eye: Vec3::new(1.0, 0.0, -5.0),
        ..camera
    };
    assert!(tree.cut(&inside, LodPolicy::Auto).leaves > 0);
}

#[test]
fn empty_and_single_scenes() {
    let empty = build(&SplatScene::with_degree(0));
    assert!(empty.is_empty());
    let camera = Camera {
        eye: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y: 1.0,
        width: 32,
        height: 32,
        near: 0.01,
        far: 100.0,
    };
    assert!(empty.cut(&camera, LodPolicy::Auto).nodes.is_empty());
    let mut one = SplatScene::with_degree(1);
    one.push(
        Vec3::ZERO,
        Quat::IDENTITY,
        Vec3::splat(0.1),
        0.7,
        &[0.3; 12],
    );
    let tree = build(&one);
    assert_eq!((tree.len(), tree.leaves), (1, 1));
    assert_eq!(tree.cut(&camera, LodPolicy::Auto).nodes, vec![0]);
    // Many Gaussians at one point still make a tree of at most eight children.
    let mut stacked = SplatScene::with_degree(0);
    for _ in 0..100 {
        stacked.push(Vec3::ONE, Quat::IDENTITY, Vec3::splat(0.1), 0.5, &[0.0; 3]);
    }
    let tree = build(&stacked);
    assert_eq!(tree.leaves, 100);
    assert!(tree
        .links
        .iter()
        .all(|l| l.children as usize <= MAX_CHILDREN));
}

#[test]
fn policies_parse() {
    assert_eq!(LodPolicy::parse("off"), Ok(LodPolicy::Off));
    assert_eq!(LodPolicy::parse("auto"), Ok(LodPolicy::Auto));
    assert_eq!(LodPolicy::parse("300k"), Ok(LodPolicy::Budget(300_000)));
    assert_eq!(LodPolicy::parse("2M"), Ok(LodPolicy::Budget(2_000_000)));
    assert_eq!(LodPolicy::parse("1500"), Ok(LodPolicy::Budget(1500)));
    for bad in ["", "0", "-3", "lots", "k", "1.5M"] {
        assert!(LodPolicy::parse(bad).is_err(), "{bad}");
    }
}
