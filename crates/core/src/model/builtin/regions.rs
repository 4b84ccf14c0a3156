//! Assigns each triangle of the built-in head to one of the 18 regions, from the
//! part it was built as and the rest position of its centroid.

use glam::{Vec2, Vec3};

use super::layout::*;
use super::mesh::{RawMesh, TrianglePart, VertexPart};
use crate::model::geometry::{lerp, smoothstep};
use crate::model::regions::Region;

/// The region of every triangle of `mesh`.
pub fn assign_regions(mesh: &RawMesh) -> Vec<Region> {
    mesh.triangles
        .iter()
        .zip(&mesh.triangle_parts)
        .map(|(tri, part)| match *part {
            TrianglePart::Pocket => Region::LipsInside,
            TrianglePart::EyeSocket(Side::Left) => Region::LeftEyeSocket,
            TrianglePart::EyeSocket(Side::Right) => Region::RightEyeSocket,
            TrianglePart::Eyeball(Side::Left) => Region::LeftEyeball,
            TrianglePart::Eyeball(Side::Right) => Region::RightEyeball,
            TrianglePart::Teeth { upper: true } => Region::TeethUpper,
            TrianglePart::Teeth { upper: false } => Region::TeethLower,
            TrianglePart::Surface => {
                let centroid = tri
                    .iter()
                    .map(|&i| mesh.positions[i as usize])
                    .sum::<Vec3>()
                    / 3.0;
                let lowest_row = tri
                    .iter()
                    .map(|&i| match mesh.vertex_parts[i as usize] {
                        VertexPart::Surface { row, .. } => row as usize,
                        _ => 0,
                    })
                    .min()
                    .unwrap_or(0);
                surface_region(centroid, lowest_row)
            }
        })
        .collect()
}

/// Rows of grid cells at the neck cut that form the `boundary` region.
const BOUNDARY_ROWS: usize = 2;

fn surface_region(c: Vec3, top_row: usize) -> Region {
    let side_left = c.x >= 0.0;
    let azimuth = c.x.atan2(c.z).abs();
    if top_row >= ROWS - BOUNDARY_ROWS {
        return Region::Boundary;
    }
    if c.y < jaw_line(c.z) {
        return Region::Neck;
    }
    if is_ear(c) {
        return if side_left {
            Region::LeftEar
        } else {
            Region::RightEar
        };
    }
    if c.z > 0.02 && is_eye_region(c) {
        return if side_left {
            Region::LeftEyeRegion
        } else {
            Region::RightEyeRegion
        };
    }
    if c.z > 0.06 && is_nose(c) {
        return Region::Nose;
    }
    if c.z > 0.04 && ((c.x / 0.029).powi(2) + ((c.y - MOUTH_Y) / 0.0135).powi(2)) < 1.0 {
        return Region::Lips;
    }
    if c.y > hairline(azimuth) {
        return Region::Hair;
    }
    if azimuth > 1.15 {
        Region::Remainder
    } else {
        Region::Skin
    }
}

/// Height below which the surface is neck: under the chin at the front, rising
/// towards the nape.
fn jaw_line(z: f32) -> f32 {
    lerp(-0.062, -0.104, smoothstep(-0.03, 0.055, z))
}

fn is_ear(c: Vec3) -> bool {
    if c.x.abs() < 0.055 {
        return false;
    }
    let d = Vec2::new(
        (c.y - EAR_CENTER.y) / EAR_SIZE.x,
        (c.z - EAR_CENTER.z) / EAR_SIZE.y,
    );
    d.length() < 1.1
}

fn is_eye_region(c: Vec3) -> bool {
    let dx = (c.x.abs() - EYE_CENTER.x) / 0.026;
    let dy = (c.y - EYE_CENTER.y - 0.005) / 0.0195;
    dx * dx + dy * dy < 1.0
}

fn is_nose(c: Vec3) -> bool {
    if !(-0.047..=0.0).contains(&c.y) {
        return false;
    }
    let half_width = lerp(0.0085, 0.021, smoothstep(-0.004, -0.040, c.y));
    c.x.abs() < half_width
}

/// Height of the hairline at an azimuth (0 = front, π = back).
fn hairline(azimuth: f32) -> f32 {
    let temples = lerp(0.072, 0.035, smoothstep(0.45, 1.3, azimuth));
    lerp(temples, -0.05, smoothstep(1.7, 2.4, azimuth))
}
