//! Wavefront OBJ export of meshes with per-vertex colours (the common `v x y z r g b`
//! extension read by Blender, MeshLab and most viewers).

use std::io::Write;
use std::path::Path;

use glam::Vec3;

use crate::model::regions::Region;

/// A distinct display colour per region (sRGB 0..255).
pub fn region_colour(region: Region) -> [u8; 3] {
    const PALETTE: [[u8; 3]; Region::COUNT] = [
        [250, 250, 235],
        [225, 225, 205],
        [210, 70, 90],
        [120, 20, 40],
        [80, 160, 230],
        [60, 120, 220],
        [150, 90, 200],
        [120, 70, 190],
        [245, 245, 255],
        [235, 235, 250],
        [240, 170, 60],
        [220, 150, 40],
        [90, 190, 120],
        [40, 120, 70],
        [110, 70, 40],
        [150, 130, 110],
        [240, 120, 160],
        [235, 200, 170],
    ];
    PALETTE[region.index()]
}

/// The region each vertex is shown in: that of the first triangle using it.
pub fn vertex_regions(
    vertex_count: usize,
    triangles: &[[u32; 3]],
    regions: &[Region],
) -> Vec<Region> {
    let mut out: Vec<Option<Region>> = vec![None; vertex_count];
    for (t, r) in triangles.iter().zip(regions) {
        for &i in t {
            out[i as usize].get_or_insert(*r);
        }
    }
    out.into_iter()
        .map(|r| r.unwrap_or(Region::Remainder))
        .collect()
}

/// Writes an OBJ with vertex colours by region.
pub fn write_obj(
    path: &Path,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    regions: &[Region],
) -> super::Result<()> {
    let colours = vertex_regions(positions.len(), triangles, regions);
    let mut out = Vec::with_capacity(positions.len() * 48 + triangles.len() * 24);
    writeln!(
        out,
        "# visage mesh: {} vertices, {} triangles",
        positions.len(),
        triangles.len()
    )
    .ok();
    for (p, r) in positions.iter().zip(&colours) {
        let [cr, cg, cb] = region_colour(*r).map(|c| c as f32 / 255.0);
        writeln!(out, "v {} {} {} {cr:.4} {cg:.4} {cb:.4}", p.x, p.y, p.z).ok();
    }
    for t in triangles {
        writeln!(out, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1).ok();
    }
    super::write_file(path, &out)
}
