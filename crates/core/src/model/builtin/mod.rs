//! The built-in procedural FLAME-like head: about 5,000 vertices and 10,000
//! triangles, one connected head/neck/ears surface with eye and mouth openings,
//! two disjoint eyeballs and two disjoint tooth rows, 18 regions, a 5-joint
//! skeleton, a region-local shape basis and an expression basis.

pub mod bases;
pub mod layout;
pub mod mesh;
pub mod parts;
pub mod regions;
pub mod rig;
pub mod surface;

use mesh::RawMesh;

use crate::model::head::HeadModel;

/// Builds the geometry of the built-in head (with tags) and its mouth opening.
pub fn build_raw() -> (RawMesh, surface::Hole) {
    let mut mesh = RawMesh::default();
    let surface = surface::build_surface(&mut mesh);
    parts::add_eye_sockets(&mut mesh, &surface);
    parts::add_mouth_cavity(&mut mesh, &surface);
    let lips_front = surface
        .margin(&surface.openings.mouth)
        .iter()
        .map(|&m| mesh.positions[m as usize].z)
        .fold(f32::MIN, f32::max);
    parts::add_teeth(&mut mesh, lips_front - 0.0085);
    parts::add_eyeballs(&mut mesh);
    mesh.compact();
    (mesh, surface.openings.mouth)
}

/// Builds the built-in head model. Deterministic: no randomness is involved.
pub fn build_head() -> HeadModel {
    let (mesh, mouth) = build_raw();
    HeadModel {
        triangle_regions: regions::assign_regions(&mesh),
        shape_basis: bases::shape_basis(&mesh),
        expression_basis: bases::expression_basis(&mesh),
        joint_regressor: rig::joint_regressor(&mesh),
        skin_weights: rig::skin_weights(&mesh, &mouth),
        pose_correctives: None,
        mouth_cavity: None,
        template: mesh.positions,
        triangles: mesh.triangles,
    }
}
