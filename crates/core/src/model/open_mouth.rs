//! Giving a head model whose lips end at an open rim (FLAME) the mouth cavity
//! of `cavity.rs`: the geometry appended, and every per-vertex array of the
//! model (bases, correctives, skinning) and the regions extended to it.

use glam::Vec3;

use super::cavity::{build_mouth_cavity, mouth_loop};
use super::head::HeadModel;
use super::regions::Region;

/// `model` with a mouth cavity hung from its open mouth rim (the boundary loop
/// that is mostly vertices for which `is_lip` holds), its triangles in
/// lips_inside; `model` unchanged when its mouth is closed or it already has
/// a cavity.
pub fn with_mouth_cavity(mut model: HeadModel, is_lip: impl Fn(u32) -> bool) -> HeadModel {
    if model.mouth_cavity.is_some() {
        return model;
    }
    let Some(mouth) = mouth_loop(model.vertex_count(), &model.triangles, is_lip) else {
        return model;
    };
    let added = build_mouth_cavity(&model.template, model.triangle_count(), &mouth);
    let cavity = added.cavity;
    let vertices = model.vertex_count() + added.positions.len();
    let extend = |f: &mut Vec<Vec3>| cavity.extend_field(f);
    model.shape_basis = model.shape_basis.extended(vertices, extend);
    model.expression_basis = model.expression_basis.extended(vertices, extend);
    model.pose_correctives = model.pose_correctives.map(|b| b.extended(vertices, extend));
    cavity.extend_weights(&mut model.skin_weights);
    model.template.extend(&added.positions);
    model.triangles.extend(&added.triangles);
    model.triangle_regions.extend(std::iter::repeat_n(
        Region::LipsInside,
        added.triangles.len(),
    ));
    model.mouth_cavity = Some(cavity);
    model
}

/// A head without its mouth's inside: every lips_inside triangle removed,
/// the vertices kept (unused), so the lips end at an open rim as FLAME's do
/// and per-vertex files made for `head` still fit. The built-in head turned
/// FLAME-like, for measuring what a generated cavity is worth.
pub fn open_rim(head: &HeadModel) -> HeadModel {
    let keep: Vec<bool> = head
        .triangle_regions
        .iter()
        .map(|r| *r != Region::LipsInside)
        .collect();
    let kept = |i: &usize| keep[*i];
    let mut out = head.clone();
    out.triangles = (0..keep.len())
        .filter(kept)
        .map(|i| head.triangles[i])
        .collect();
    out.triangle_regions = (0..keep.len())
        .filter(kept)
        .map(|i| head.triangle_regions[i])
        .collect();
    out
}

/// Per vertex: whether a triangle of `region` uses it.
pub fn region_vertices(head: &HeadModel, region: Region) -> Vec<bool> {
    let mut used = vec![false; head.vertex_count()];
    for (t, r) in head.triangles.iter().zip(&head.triangle_regions) {
        if *r == region {
            t.iter().for_each(|&v| used[v as usize] = true);
        }
    }
    used
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::builtin::build_head;

    #[test]
    fn every_per_vertex_array_grows_with_the_cavity() {
        let open = open_rim(&build_head());
        let lips = region_vertices(&open, Region::Lips);
        let head = with_mouth_cavity(open.clone(), |v| lips[v as usize]);
        let cavity = head
            .mouth_cavity
            .as_ref()
            .expect("the open rim gets a cavity");
        let v = head.vertex_count();
        assert_eq!(cavity.first_vertex, open.vertex_count());
        assert_eq!(head.file_vertex_count(), open.vertex_count());
        assert_eq!(head.skin_weights.len(), v);
        assert_eq!(head.shape_basis.component(0).len(), v);
        assert_eq!(head.expression_basis.component(0).len(), v);
        assert_eq!(head.triangle_regions.len(), head.triangle_count());
        assert!(head
            .skin_weights
            .iter()
            .all(|w| (w.iter().sum::<f32>() - 1.0).abs() < 1e-5));
        // Posing works on the grown model, and nothing is non-finite.
        let neutral = head.neutral(&[0.5; 4], None);
        let mut posed = Vec::new();
        let mut pose = crate::model::head::Pose::REST;
        pose.joints[2] = glam::Vec3::new(0.2, 0.0, 0.0);
        head.pose(&neutral, &[0.3; 4], &pose, &mut posed);
        assert!(posed.iter().all(|p| p.is_finite()));
        // Adding it twice changes nothing; a closed mouth gets none.
        assert_eq!(with_mouth_cavity(head.clone(), |_| true), head);
        assert!(
            with_mouth_cavity(build_head(), |v| lips.get(v as usize) == Some(&true))
                .mouth_cavity
                .is_none()
        );
    }
}
