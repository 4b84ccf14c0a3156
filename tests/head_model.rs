//! The built-in head model: topology, regions, rig and bases behave as a
//! FLAME-like model must.

use std::collections::HashSet;
use std::sync::OnceLock;

use glam::Vec3;
use visage::model::builtin::build_head;
use visage::model::head::{HeadModel, Joint, Pose};
use visage::model::regions::Region;
use visage::model::topology::connected_components;

fn model() -> &'static HeadModel {
    static MODEL: OnceLock<HeadModel> = OnceLock::new();
    MODEL.get_or_init(build_head)
}

fn region_vertices(m: &HeadModel, region: Region) -> Vec<usize> {
    let mut set = HashSet::new();
    for (t, r) in m.triangles.iter().zip(&m.triangle_regions) {
        if *r == region {
            set.extend(t.iter().map(|&i| i as usize));
        }
    }
    let mut v: Vec<_> = set.into_iter().collect();
    v.sort();
    v
}

#[test]
fn size_is_flame_like() {
    let m = model();
    assert!(
        (4500..=5600).contains(&m.vertex_count()),
        "{} vertices",
        m.vertex_count()
    );
    assert!(
        (9000..=11000).contains(&m.triangle_count()),
        "{} triangles",
        m.triangle_count()
    );
    assert!(m.shape_basis.len() >= 20);
    assert!(m.expression_basis.len() >= 10);
}

#[test]
fn every_triangle_is_in_exactly_one_region_and_every_region_is_used() {
    let m = model();
    assert_eq!(m.triangle_regions.len(), m.triangle_count());
    for r in Region::ALL {
        let n = m.triangle_regions.iter().filter(|x| **x == r).count();
        assert!(n > 0, "region {} has no triangles", r.name());
    }
}

#[test]
fn surface_is_consistently_oriented_and_free_of_degenerate_triangles() {
    let m = model();
    let mut directed = HashSet::new();
    for t in &m.triangles {
        for k in 0..3 {
            assert!(
                directed.insert((t[k], t[(k + 1) % 3])),
                "edge {}->{} used twice in the same direction",
                t[k],
                t[(k + 1) % 3]
            );
        }
        let [a, b, c] = t.map(|i| m.template[i as usize]);
        assert!(
            (b - a).cross(c - a).length() > 1e-9,
            "degenerate triangle {t:?}"
        );
    }
}

#[test]
fn closed_parts_face_outwards() {
    let m = model();
    for region in [
        Region::LeftEyeball,
        Region::RightEyeball,
        Region::TeethUpper,
        Region::TeethLower,
    ] {
        let volume: f32 = m
            .triangles
            .iter()
            .zip(&m.triangle_regions)
            .filter(|(_, r)| **r == region)
            .map(|(t, _)| {
                let [a, b, c] = t.map(|i| m.template[i as usize]);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        assert!(volume > 0.0, "{} has volume {volume}", region.name());
    }
}

#[test]
fn disjoint_parts_are_anchored_to_two_nearby_main_surface_regions() {
    let m = model();
    let (parts, labels) = connected_components(m.vertex_count(), &m.triangles);
    assert_eq!(parts, 5, "one surface, two eyeballs, two tooth rows");
    let mut sizes = vec![0; parts];
    for l in &labels {
        sizes[*l as usize] += 1;
    }
    let main = (0..parts).max_by_key(|&p| sizes[p]).unwrap() as u32;
    for part in (0..parts as u32).filter(|&p| p != main) {
        let regions: HashSet<Region> = m
            .triangles
            .iter()
            .zip(&m.triangle_regions)
            .filter(|(t, _)| labels[t[0] as usize] == part)
            .map(|(_, r)| *r)
            .collect();
        assert_eq!(regions.len(), 1, "a disjoint part is exactly one region");
        let region = *regions.iter().next().unwrap();
        let anchors = region
            .anchor_regions()
            .expect("disjoint region has anchors");
        let part_vertices: Vec<Vec3> = (0..m.vertex_count())
            .filter(|&v| labels[v] == part)
            .map(|v| m.template[v])
            .collect();
        let centre = part_vertices.iter().sum::<Vec3>() / part_vertices.len() as f32;
        for anchor in anchors {
            let verts = region_vertices(m, anchor);
            assert!(
                verts.iter().all(|&v| labels[v] == main),
                "{} is on the main surface",
                anchor.name()
            );
            let nearest = verts
                .iter()
                .map(|&v| (m.template[v] - centre).length())
                .fold(f32::MAX, f32::min);
            assert!(
                nearest < 0.03,
                "{} is {nearest} m from {}",
                anchor.name(),
                region.name()
            );
        }
    }
}

#[test]
fn rest_pose_is_the_identity() {
    let m = model();
    let posed = m.forward(&[], None, &[], &Pose::REST);
    for (p, t) in posed.iter().zip(&m.template) {
        assert!(p.abs_diff_eq(*t, 1e-6), "{p} vs {t}");
    }
}

#[test]
fn skin_weights_are_convex() {
    for w in &model().skin_weights {
        let sum: f32 = w.iter().sum();
        assert!(
            (sum - 1.0).abs() < 1e-5 && w.iter().all(|x| *x >= 0.0),
            "{w:?}"
        );
    }
}

#[test]
fn jaw_rotation_moves_only_jaw_weighted_vertices() {
    let m = model();
    let mut pose = Pose::REST;
    pose.joints[Joint::Jaw as usize] = Vec3::new(0.25, 0.0, 0.0);
    let posed = m.forward(&[], None, &[], &pose);
    let mut moved_strongly = 0;
    for (i, w) in m.skin_weights.iter().enumerate() {
        let d = (posed[i] - m.template[i]).length();
        if w[Joint::Jaw as usize] == 0.0 {
            assert!(d < 1e-6, "vertex {i} has no jaw weight but moved {d}");
        } else if w[Joint::Jaw as usize] > 0.9 && d > 0.002 {
            moved_strongly += 1;
        }
    }
    assert!(
        moved_strongly > 100,
        "only {moved_strongly} jaw vertices moved"
    );
    // The chin goes down when the jaw opens.
    let chin = (0..m.vertex_count())
        .filter(|&i| m.skin_weights[i][Joint::Jaw as usize] > 0.99)
        .min_by(|&a, &b| m.template[a].y.total_cmp(&m.template[b].y))
        .unwrap();
    assert!(posed[chin].y < m.template[chin].y - 0.005);
}

#[test]
fn eye_rotation_moves_only_that_eyeball_rigidly() {
    let m = model();
    let left = region_vertices(m, Region::LeftEyeball);
    let centre = left.iter().map(|&v| m.template[v]).sum::<Vec3>() / left.len() as f32;
    let mut pose = Pose::REST;
    pose.joints[Joint::LeftEye as usize] = Vec3::new(0.1, 0.3, 0.0);
    let posed = m.forward(&[], None, &[], &pose);
    let left_set: HashSet<usize> = left.iter().copied().collect();
    for (i, (p, t)) in posed.iter().zip(&m.template).enumerate() {
        let d = (*p - *t).length();
        if left_set.contains(&i) {
            let r0 = (*t - centre).length();
            let r1 = (*p - centre).length();
            assert!((r0 - r1).abs() < 1e-5, "eyeball deformed");
        } else {
            assert!(d < 1e-6, "vertex {i} outside the left eyeball moved {d}");
        }
    }
    let front = left
        .iter()
        .max_by(|&&a, &&b| m.template[a].z.total_cmp(&m.template[b].z))
        .unwrap();
    assert!(
        (posed[*front] - m.template[*front]).length() > 0.003,
        "pupil moved"
    );
}

#[test]
fn joints_follow_the_shape() {
    let m = model();
    let neutral = m.neutral(&[], None);
    let mut shape = vec![0.0; m.shape_basis.len()];
    let k = m
        .shape_basis
        .names()
        .iter()
        .position(|n| n == "eye_spacing")
        .unwrap();
    shape[k] = 1.0;
    let wider = m.neutral(&shape, None);
    let (a, b) = (m.joints(&neutral), m.joints(&wider));
    assert!(b[Joint::LeftEye as usize].x > a[Joint::LeftEye as usize].x + 0.001);
    assert!(b[Joint::RightEye as usize].x < a[Joint::RightEye as usize].x - 0.001);
}

#[test]
fn bases_are_finite_and_shape_components_are_local() {
    let m = model();
    for k in 0..m.shape_basis.len() {
        let field = m.shape_basis.component(k);
        assert!(field.iter().all(|d| d.is_finite()));
        let moved = field.iter().filter(|d| d.length() > 1e-4).count();
        assert!(moved > 0, "{} moves nothing", m.shape_basis.names()[k]);
        assert!(
            moved * 2 < m.vertex_count(),
            "{} is not local: {moved} vertices",
            m.shape_basis.names()[k]
        );
    }
    for k in 0..m.expression_basis.len() {
        let field = m.expression_basis.component(k);
        assert!(field.iter().all(|d| d.is_finite()));
        assert!(
            field.iter().any(|d| d.length() > 1e-4),
            "{} moves nothing",
            m.expression_basis.names()[k]
        );
    }
}

#[test]
fn blink_closes_the_eye_opening() {
    let m = model();
    let k = m
        .expression_basis
        .names()
        .iter()
        .position(|n| n == "blink_left")
        .unwrap();
    let mut expression = vec![0.0; m.expression_basis.len()];
    expression[k] = 1.0;
    let closed = m.forward(&[], None, &expression, &Pose::REST);
    // The lid margin: vertices shared by the socket lining and the eye region.
    let socket: HashSet<usize> = region_vertices(m, Region::LeftEyeSocket)
        .into_iter()
        .collect();
    let margin: Vec<usize> = region_vertices(m, Region::LeftEyeRegion)
        .into_iter()
        .filter(|v| socket.contains(v))
        .collect();
    assert!(margin.len() > 10);
    let cx = margin.iter().map(|&i| m.template[i].x).sum::<f32>() / margin.len() as f32;
    let central: Vec<usize> = margin
        .into_iter()
        .filter(|&i| (m.template[i].x - cx).abs() < 0.004)
        .collect();
    let gap = |v: &[Vec3]| {
        let ys = central.iter().map(|&i| v[i].y);
        ys.clone().fold(f32::MIN, f32::max) - ys.fold(f32::MAX, f32::min)
    };
    assert!(
        gap(&m.template) > 0.006,
        "open eye gap {}",
        gap(&m.template)
    );
    assert!(
        gap(&closed) < 0.2 * gap(&m.template),
        "{} vs {}",
        gap(&closed),
        gap(&m.template)
    );
}
