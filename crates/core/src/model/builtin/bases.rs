//! Shape (identity) and expression bases of the built-in head: smooth, local
//! displacement fields. Eyeballs and teeth move rigidly (each takes the field at
//! its own centre) so they never deform.

use glam::{Quat, Vec2, Vec3};

use super::layout::*;
use super::mesh::{RawMesh, VertexPart};
use super::surface::ear_displacement;
use crate::model::geometry::{smoothstep, Bump};
use crate::model::head::Basis;

type Field = Box<dyn Fn(Vec3) -> Vec3>;

/// A named component: a displacement field, and whether the teeth follow it.
struct Component {
    name: &'static str,
    field: Field,
    teeth: bool,
    eyeballs: bool,
}

fn bumps(list: Vec<Bump>) -> Field {
    Box::new(move |p| list.iter().map(|b| b.at(p)).sum())
}

fn v3(x: f32, y: f32, z: f32) -> Vec3 {
    Vec3::new(x, y, z)
}

fn single(center: Vec3, sigma: Vec3, displacement: Vec3) -> Field {
    bumps(vec![Bump::new(center, sigma, displacement)])
}

fn pair(center: Vec3, sigma: Vec3, displacement: Vec3) -> Field {
    bumps(vec![Bump::mirrored(center, sigma, displacement)])
}

/// How strongly a point belongs to an ear flap (0 away from the ears, 1 on them).
fn ear_mask(p: Vec3) -> f32 {
    (ear_displacement(p).x.abs() / 0.011).min(1.0)
}

fn shape_components() -> Vec<Component> {
    let eye = v3(EYE_CENTER.x, EYE_CENTER.y, 0.07);
    let eye_sigma = v3(0.016, 0.014, 0.04);
    let ear_root = move |p: Vec3| v3(p.x.signum() * 0.07, EAR_CENTER.y, EAR_CENTER.z);
    let c = |name, field, rigid: bool| Component {
        name,
        field,
        teeth: rigid,
        eyeballs: rigid,
    };
    vec![
        c(
            "nose_length",
            single(
                v3(0.0, -0.032, 0.1),
                v3(0.011, 0.013, 0.03),
                v3(0.0, -0.002, 0.008),
            ),
            false,
        ),
        c(
            "nose_width",
            pair(
                v3(0.013, -0.039, 0.09),
                v3(0.008, 0.008, 0.03),
                v3(0.004, 0.0, 0.0),
            ),
            false,
        ),
        c(
            "nose_bridge",
            single(
                v3(0.0, -0.006, 0.095),
                v3(0.007, 0.014, 0.03),
                v3(0.0, 0.0, 0.004),
            ),
            false,
        ),
        c(
            "nose_tip_lift",
            single(
                v3(0.0, -0.036, 0.105),
                v3(0.009, 0.008, 0.03),
                v3(0.0, 0.004, 0.0),
            ),
            false,
        ),
        c(
            "jaw_width",
            pair(
                v3(0.058, -0.075, 0.02),
                v3(0.016, 0.02, 0.035),
                v3(0.007, 0.0, 0.0),
            ),
            true,
        ),
        c(
            "chin_length",
            single(
                v3(0.0, -0.1, 0.07),
                v3(0.022, 0.016, 0.03),
                v3(0.0, -0.008, 0.0),
            ),
            false,
        ),
        c(
            "chin_projection",
            single(
                v3(0.0, -0.098, 0.075),
                v3(0.016, 0.014, 0.03),
                v3(0.0, 0.0, 0.007),
            ),
            false,
        ),
        c(
            "cheekbones",
            pair(
                v3(0.048, -0.014, 0.065),
                v3(0.014, 0.012, 0.03),
                v3(0.004, 0.001, 0.004),
            ),
            false,
        ),
        c(
            "cheek_fullness",
            pair(
                v3(0.046, -0.05, 0.06),
                v3(0.015, 0.015, 0.03),
                v3(0.005, 0.0, 0.002),
            ),
            false,
        ),
        c(
            "brow_ridge",
            pair(
                v3(0.028, 0.024, 0.09),
                v3(0.02, 0.007, 0.03),
                v3(0.0, 0.0, 0.004),
            ),
            false,
        ),
        c(
            "forehead_slope",
            single(
                v3(0.0, 0.06, 0.08),
                v3(0.04, 0.025, 0.03),
                v3(0.0, 0.0, 0.006),
            ),
            false,
        ),
        c(
            "eye_spacing",
            pair(eye, eye_sigma, v3(0.003, 0.0, 0.0)),
            true,
        ),
        c(
            "eye_height",
            pair(eye, eye_sigma, v3(0.0, 0.003, 0.0)),
            true,
        ),
        c(
            "eye_depth",
            pair(eye, eye_sigma, v3(0.0, 0.0, -0.003)),
            true,
        ),
        c(
            "ear_size",
            Box::new(move |p| 0.18 * ear_mask(p) * (p - ear_root(p))),
            false,
        ),
        c(
            "ear_protrusion",
            Box::new(|p| ear_mask(p) * v3(p.x.signum() * 0.006, 0.0, 0.002)),
            false,
        ),
        c(
            "ear_height",
            Box::new(|p| ear_mask(p) * v3(0.0, 0.006, 0.0)),
            false,
        ),
        c(
            "skull_height",
            single(
                v3(0.0, 0.115, -0.01),
                v3(0.06, 0.04, 0.08),
                v3(0.0, 0.008, 0.0),
            ),
            false,
        ),
        c(
            "skull_width",
            pair(
                v3(0.075, 0.04, -0.02),
                v3(0.02, 0.035, 0.05),
                v3(0.005, 0.0, 0.0),
            ),
            false,
        ),
        c(
            "skull_length",
            single(
                v3(0.0, 0.03, -0.11),
                v3(0.06, 0.05, 0.03),
                v3(0.0, 0.0, -0.008),
            ),
            false,
        ),
        c(
            "lip_fullness",
            bumps(vec![
                Bump::new(
                    v3(0.0, MOUTH_Y + 0.006, 0.09),
                    v3(0.015, 0.005, 0.03),
                    v3(0.0, 0.0015, 0.003),
                ),
                Bump::new(
                    v3(0.0, MOUTH_Y - 0.007, 0.09),
                    v3(0.014, 0.005, 0.03),
                    v3(0.0, -0.0015, 0.003),
                ),
            ]),
            false,
        ),
        c(
            "mouth_width",
            pair(
                v3(0.024, MOUTH_Y, 0.08),
                v3(0.007, 0.008, 0.03),
                v3(0.003, 0.0, -0.001),
            ),
            false,
        ),
        c(
            "neck_thickness",
            Box::new(|p| {
                let radial = v3(p.x, 0.0, p.z - NECK_CZ).normalize_or_zero();
                radial * 0.005 * smoothstep(-0.08, -0.11, p.y)
            }),
            false,
        ),
        c(
            "face_length",
            single(
                v3(0.0, -0.085, 0.05),
                v3(0.04, 0.03, 0.05),
                v3(0.0, -0.006, 0.0),
            ),
            true,
        ),
        c(
            "temple_width",
            pair(
                v3(0.07, 0.03, 0.03),
                v3(0.015, 0.02, 0.03),
                v3(0.004, 0.0, 0.0),
            ),
            false,
        ),
        c(
            "philtrum_length",
            single(
                v3(0.0, MOUTH_Y + 0.013, 0.09),
                v3(0.012, 0.006, 0.03),
                v3(0.0, 0.003, 0.0),
            ),
            false,
        ),
    ]
}

/// Closure of the eyelids on one side: the upper lid travels down over the eyeball
/// (rotating about the eye centre so it stays on the lid sphere), the lower lid rises a little.
fn blink(side: Side) -> Field {
    Box::new(move |p| {
        let e = side.place(EYE_CENTER);
        let d = Vec2::new(p.x - e.x, p.y - e.y);
        let half_height = EYE_OPENING.y * (1.0 - (d.x / EYE_OPENING.x).powi(2)).max(0.0).sqrt();
        let dy = if d.y >= 0.0 {
            -1.6 * half_height * smoothstep(0.016, 0.005, d.y)
        } else {
            0.4 * half_height * smoothstep(-0.012, -0.003, d.y)
        };
        if dy == 0.0 || p.z < e.z - 0.006 {
            return Vec3::ZERO;
        }
        let on_lid = smoothstep(2.0, 1.0, (d / Vec2::new(0.0135, 0.0078)).length());
        let r = p - e;
        let rotated = e + (r + dy * Vec3::Y).normalize() * r.length();
        let forward = if d.y >= 0.0 { 0.001 } else { 0.0 };
        on_lid * (rotated - p + forward * Vec3::Z) + (1.0 - on_lid) * dy * Vec3::Y
    })
}

fn expression_components() -> Vec<Component> {
    let soft = |name, field| Component {
        name,
        field,
        teeth: false,
        eyeballs: false,
    };
    let corner = v3(0.024, MOUTH_Y, 0.08);
    let corner_sigma = v3(0.01, 0.01, 0.03);
    vec![
        Component {
            name: "jaw_open",
            field: Box::new(|p| {
                // Linearised jaw rotation about the hinge, fading out above the mouth.
                let weight = smoothstep(MOUTH_Y + 0.004, MOUTH_Y - 0.014, p.y)
                    * smoothstep(-0.035, 0.02, p.z)
                    * smoothstep(-0.135, -0.1, p.y);
                let r = p - JAW_HINGE;
                weight * (Quat::from_rotation_x(0.12) * r - r)
            }),
            teeth: true,
            eyeballs: false,
        },
        soft(
            "smile",
            bumps(vec![
                Bump::mirrored(corner, corner_sigma, v3(0.004, 0.005, -0.003)),
                Bump::mirrored(
                    v3(0.04, -0.03, 0.065),
                    v3(0.015, 0.015, 0.03),
                    v3(0.001, 0.003, 0.002),
                ),
            ]),
        ),
        soft("frown", pair(corner, corner_sigma, v3(0.0, -0.004, 0.0))),
        soft("blink_left", blink(Side::Left)),
        soft("blink_right", blink(Side::Right)),
        soft(
            "brow_raise",
            pair(
                v3(0.028, 0.03, 0.085),
                v3(0.025, 0.01, 0.03),
                v3(0.0, 0.005, 0.0),
            ),
        ),
        soft(
            "brow_furrow",
            pair(
                v3(0.012, 0.022, 0.09),
                v3(0.01, 0.008, 0.03),
                v3(-0.002, -0.003, 0.001),
            ),
        ),
        soft(
            "pucker",
            bumps(vec![
                Bump::new(
                    v3(0.0, MOUTH_Y, 0.085),
                    v3(0.02, 0.012, 0.03),
                    v3(0.0, 0.0, 0.006),
                ),
                Bump::mirrored(corner, corner_sigma, v3(-0.005, 0.0, 0.0)),
            ]),
        ),
        soft(
            "cheek_puff",
            pair(
                v3(0.045, -0.055, 0.05),
                v3(0.018, 0.018, 0.03),
                v3(0.008, 0.0, 0.003),
            ),
        ),
        soft(
            "nose_wrinkle",
            bumps(vec![
                Bump::mirrored(
                    v3(0.012, -0.04, 0.085),
                    v3(0.007, 0.006, 0.03),
                    v3(0.0, 0.003, 0.0),
                ),
                Bump::new(
                    v3(0.0, MOUTH_Y + 0.007, 0.08),
                    v3(0.015, 0.005, 0.03),
                    v3(0.0, 0.002, 0.0),
                ),
            ]),
        ),
        soft(
            "mouth_left",
            single(
                v3(0.0, MOUTH_Y, 0.08),
                v3(0.03, 0.015, 0.03),
                v3(0.006, 0.0, 0.0),
            ),
        ),
        soft(
            "mouth_right",
            single(
                v3(0.0, MOUTH_Y, 0.08),
                v3(0.03, 0.015, 0.03),
                v3(-0.006, 0.0, 0.0),
            ),
        ),
        soft(
            "lip_press",
            bumps(vec![
                Bump::new(
                    v3(0.0, MOUTH_Y + 0.006, 0.085),
                    v3(0.016, 0.005, 0.03),
                    v3(0.0, -0.0015, -0.001),
                ),
                Bump::new(
                    v3(0.0, MOUTH_Y - 0.007, 0.085),
                    v3(0.015, 0.005, 0.03),
                    v3(0.0, 0.0015, -0.001),
                ),
            ]),
        ),
        soft(
            "squint",
            bumps(vec![
                Bump::mirrored(
                    v3(EYE_CENTER.x, EYE_CENTER.y - 0.006, 0.075),
                    v3(0.012, 0.004, 0.03),
                    v3(0.0, 0.0018, 0.0),
                ),
                Bump::mirrored(
                    v3(0.04, -0.02, 0.065),
                    v3(0.015, 0.01, 0.03),
                    v3(0.0, 0.002, 0.001),
                ),
            ]),
        ),
    ]
}

/// Centres used to move rigid parts.
struct RigidCentres {
    eyes: [Vec3; 2],
    teeth: [Vec3; 2],
}

fn rigid_centres(mesh: &RawMesh) -> RigidCentres {
    let centroid = |want: VertexPart| {
        let (sum, n) = mesh
            .positions
            .iter()
            .zip(&mesh.vertex_parts)
            .filter(|(_, p)| **p == want)
            .fold((Vec3::ZERO, 0), |(s, n), (p, _)| (s + *p, n + 1));
        sum / n.max(1) as f32
    };
    RigidCentres {
        eyes: [Side::Left, Side::Right].map(|s| centroid(VertexPart::Eyeball(s))),
        teeth: [true, false].map(|upper| centroid(VertexPart::Teeth { upper })),
    }
}

fn evaluate(mesh: &RawMesh, centres: &RigidCentres, component: &Component) -> Vec<Vec3> {
    mesh.positions
        .iter()
        .zip(&mesh.vertex_parts)
        .map(|(&p, part)| match *part {
            VertexPart::Eyeball(side) if component.eyeballs => {
                (component.field)(centres.eyes[(side == Side::Right) as usize])
            }
            VertexPart::Teeth { upper } if component.teeth => {
                (component.field)(centres.teeth[(!upper) as usize])
            }
            VertexPart::Eyeball(_) | VertexPart::Teeth { .. } => Vec3::ZERO,
            _ => (component.field)(p),
        })
        .collect()
}

fn basis(mesh: &RawMesh, components: Vec<Component>) -> Basis {
    let centres = rigid_centres(mesh);
    let mut basis = Basis::new(mesh.positions.len());
    for component in &components {
        basis.push(component.name, evaluate(mesh, &centres, component));
    }
    basis
}

/// The identity basis: region-local face, skull, ear and neck proportions.
pub fn shape_basis(mesh: &RawMesh) -> Basis {
    basis(mesh, shape_components())
}

/// The expression basis: jaw, mouth, lids, brows and cheeks.
pub fn expression_basis(mesh: &RawMesh) -> Basis {
    basis(mesh, expression_components())
}
