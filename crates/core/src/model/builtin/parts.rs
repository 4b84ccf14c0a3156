//! The parts behind the openings of the main surface: eye-socket linings, the
//! mouth cavity (connected to the surface), and the disjoint eyeballs and teeth.

use std::f32::consts::{FRAC_PI_2, PI, TAU};

use glam::Vec3;

use super::layout::*;
use super::mesh::{RawMesh, TrianglePart, VertexPart};
use super::surface::{Surface, LID_GAP};

/// Rings of socket lining behind each eyelid margin.
const SOCKET_RINGS: usize = 2;

/// Lines each eye opening with rings that slide back along a sphere just outside
/// the eyeball, so no gap shows between eyelid and eye.
pub fn add_eye_sockets(mesh: &mut RawMesh, surface: &Surface) {
    for (side, hole) in Side::BOTH.into_iter().zip(&surface.openings.eyes) {
        let center = side.place(EYE_CENTER);
        let mut previous = surface.margin(hole);
        for ring in 1..=SOCKET_RINGS {
            let next: Vec<u32> = previous
                .iter()
                .map(|&m| {
                    let d = (mesh.positions[m as usize] - center).normalize_or(Vec3::Z);
                    let polar = d.z.clamp(-1.0, 1.0).acos();
                    let azimuth = d.y.atan2(d.x);
                    let target = FRAC_PI_2 + 0.25;
                    let polar = polar + (target - polar) * ring as f32 / SOCKET_RINGS as f32;
                    let r = EYE_RADIUS + 0.6 * LID_GAP;
                    let p = center
                        + r * Vec3::new(
                            polar.sin() * azimuth.cos(),
                            polar.sin() * azimuth.sin(),
                            polar.cos(),
                        );
                    mesh.add_vertex(
                        p,
                        VertexPart::EyeSocket {
                            side,
                            ring: ring as u8,
                        },
                    )
                })
                .collect();
            mesh.add_strip(&previous, &next, true, TrianglePart::EyeSocket(side));
            previous = next;
        }
    }
}

/// Latitude rings (poles excluded) and meridians of an eyeball.
const EYEBALL_RINGS: usize = 9;
const EYEBALL_MERIDIANS: usize = 16;

/// Adds the two eyeballs: closed spheres with their poles on the viewing axis (+z),
/// so the front pole is the pupil centre.
pub fn add_eyeballs(mesh: &mut RawMesh) {
    for side in Side::BOTH {
        let center = side.place(EYE_CENTER);
        let part = VertexPart::Eyeball(side);
        let front = mesh.add_vertex(center + EYE_RADIUS * Vec3::Z, part);
        let rings: Vec<Vec<u32>> = (1..=EYEBALL_RINGS)
            .map(|i| {
                let polar = PI * i as f32 / (EYEBALL_RINGS + 1) as f32;
                (0..EYEBALL_MERIDIANS)
                    .map(|j| {
                        let az = TAU * j as f32 / EYEBALL_MERIDIANS as f32;
                        let d =
                            Vec3::new(polar.sin() * az.cos(), polar.sin() * az.sin(), polar.cos());
                        mesh.add_vertex(center + EYE_RADIUS * d, part)
                    })
                    .collect()
            })
            .collect();
        let back = mesh.add_vertex(center - EYE_RADIUS * Vec3::Z, part);
        let tri_part = TrianglePart::Eyeball(side);
        let n = EYEBALL_MERIDIANS;
        let facing = |mesh: &mut RawMesh, tri: [u32; 3]| {
            let c = tri
                .iter()
                .map(|&i| mesh.positions[i as usize])
                .sum::<Vec3>()
                / 3.0;
            mesh.add_triangle_facing(tri, c - center, tri_part);
        };
        for j in 0..n {
            facing(mesh, [front, rings[0][j], rings[0][(j + 1) % n]]);
            facing(
                mesh,
                [
                    back,
                    rings[EYEBALL_RINGS - 1][j],
                    rings[EYEBALL_RINGS - 1][(j + 1) % n],
                ],
            );
        }
        for pair in rings.windows(2) {
            for j in 0..n {
                let k = (j + 1) % n;
                facing(mesh, [pair[0][j], pair[1][j], pair[1][k]]);
                facing(mesh, [pair[0][j], pair[1][k], pair[0][k]]);
            }
        }
    }
}

/// Mouth cavity rings: (half-width relative to the margin, half-height, depth
/// behind the margin, extra depth at the sides, boxiness exponent).
const POCKET_RINGS: [(f32, f32, f32, f32, f32); 5] = [
    (0.93, 0.0035, 0.0050, 0.000, 1.0),
    (0.95, 0.0125, 0.0075, 0.003, 0.6),
    (0.95, 0.0150, 0.0240, 0.010, 0.5),
    (0.80, 0.0140, 0.0400, 0.010, 0.5),
    (0.50, 0.0095, 0.0500, 0.006, 0.6),
];

/// Adds the mouth cavity: rings behind the mouth slit that open into a closed
/// pocket large enough to hold the teeth; the last ring is zipped shut.
pub fn add_mouth_cavity(mesh: &mut RawMesh, surface: &Surface) {
    let hole = &surface.openings.mouth;
    let margin_cells = hole.margin_loop();
    let margin = surface.margin(hole);
    let alphas: Vec<f32> = margin_cells
        .iter()
        .map(|&(r, c)| hole.margin_angle(r, c))
        .collect();
    let margin_pos: Vec<Vec3> = margin.iter().map(|&m| mesh.positions[m as usize]).collect();
    let mut previous = margin.clone();
    for (ring, &(width, height, depth, arch, boxiness)) in POCKET_RINGS.iter().enumerate() {
        let next: Vec<u32> = alphas
            .iter()
            .zip(&margin_pos)
            .map(|(&alpha, m)| {
                let s = alpha.sin();
                let lift = -s.signum() * s.abs().powf(boxiness) * height;
                let p = Vec3::new(
                    width * m.x,
                    MOUTH_Y + lift,
                    m.z - depth - arch * alpha.cos().powi(2),
                );
                mesh.add_vertex(
                    p,
                    VertexPart::Pocket {
                        alpha,
                        ring: ring as u8 + 1,
                    },
                )
            })
            .collect();
        mesh.add_strip(&previous, &next, true, TrianglePart::Pocket);
        previous = next;
    }
    // Zip the last ring: upper half (left to right) against the lower half beneath it.
    let top_len = hole.cols.1 - hole.cols.0 + 1;
    let upper = &previous[..top_len];
    let lower: Vec<u32> = previous[top_len..].iter().rev().copied().collect();
    mesh.add_strip(upper, &lower, false, TrianglePart::Pocket);
}

/// Arch stations per tooth row.
const TEETH_STATIONS: usize = 14;
/// Half-width and depth of the dental arch.
const TEETH_ARCH: (f32, f32) = (0.0165, 0.017);
/// Thickness of a tooth row.
const TEETH_THICKNESS: f32 = 0.0055;

/// Adds the upper and lower tooth rows: closed tubes of rectangular section
/// along a parabolic arch behind the lips.
pub fn add_teeth(mesh: &mut RawMesh, incisor_z: f32) {
    for upper in [true, false] {
        let (y0, y1, z0) = if upper {
            (MOUTH_Y + 0.0003, MOUTH_Y + 0.0095, incisor_z)
        } else {
            (MOUTH_Y - 0.0085, MOUTH_Y - 0.0007, incisor_z - 0.0015)
        };
        let part = VertexPart::Teeth { upper };
        let tri_part = TrianglePart::Teeth { upper };
        let mut sections = Vec::new();
        let mut centers = Vec::new();
        for i in 0..=TEETH_STATIONS {
            let s = -1.0 + 2.0 * i as f32 / TEETH_STATIONS as f32;
            let front = Vec3::new(TEETH_ARCH.0 * s, 0.0, z0 - TEETH_ARCH.1 * s * s);
            let normal = Vec3::new(2.0 * TEETH_ARCH.1 * s, 0.0, TEETH_ARCH.0).normalize();
            let back = front - TEETH_THICKNESS * normal;
            let corners = [
                front + y1 * Vec3::Y,
                front + y0 * Vec3::Y,
                back + y0 * Vec3::Y,
                back + y1 * Vec3::Y,
            ];
            centers.push(0.5 * (front + back) + 0.5 * (y0 + y1) * Vec3::Y);
            sections.push(corners.map(|p| mesh.add_vertex(p, part)));
        }
        for i in 0..TEETH_STATIONS {
            let mid = 0.5 * (centers[i] + centers[i + 1]);
            for k in 0..4 {
                let (a, b) = (sections[i][k], sections[i][(k + 1) % 4]);
                let (c, d) = (sections[i + 1][(k + 1) % 4], sections[i + 1][k]);
                let out = 0.25
                    * [a, b, c, d]
                        .iter()
                        .map(|&v| mesh.positions[v as usize])
                        .sum::<Vec3>()
                    - mid;
                mesh.add_triangle_facing([a, b, c], out, tri_part);
                mesh.add_triangle_facing([a, c, d], out, tri_part);
            }
        }
        for (section, outward) in [
            (sections[0], centers[0] - centers[1]),
            (
                sections[TEETH_STATIONS],
                centers[TEETH_STATIONS] - centers[TEETH_STATIONS - 1],
            ),
        ] {
            mesh.add_triangle_facing([section[0], section[1], section[2]], outward, tri_part);
            mesh.add_triangle_facing([section[0], section[2], section[3]], outward, tri_part);
        }
    }
}
