//! The main head surface: a warped latitude/longitude grid from the crown to the
//! neck cut, with elliptical openings for the eyes and the mouth, sculpted into a
//! face. One connected surface: ears are sculpted out of it, the mouth opening
//! leads into a cavity and the eye openings into socket linings (see `parts`).

use std::f32::consts::{PI, TAU};

use glam::{Vec2, Vec3};

use super::layout::*;
use super::mesh::{RawMesh, TrianglePart, VertexPart};
use crate::model::geometry::{lerp, smoothstep, Bump};

/// Azimuth (0 = front, +π/2 = subject's left) of a continuous grid column.
pub fn col_to_u(x: f32) -> f32 {
    let s = 2.0 * x / COLS as f32 - 1.0;
    PI * (COL_WARP_LINEAR * s + (1.0 - COL_WARP_LINEAR) * s * s * s)
}

/// Vertical parameter (0 = crown, 1 = neck cut) of a continuous grid row.
pub fn row_to_v(y: f32) -> f32 {
    let s = y / ROWS as f32;
    s + ROW_WARP * (TAU * s).sin() / TAU
}

/// The unsculpted head: a skull ellipsoid blended into a neck tube.
pub fn base_surface(u: f32, v: f32) -> Vec3 {
    let front = smoothstep(-0.35, 0.35, u.cos());
    let skull = {
        let theta = v / V_SKULL * SKULL_THETA;
        let (st, ct) = theta.sin_cos();
        let rz = lerp(SKULL_RZ_BACK, SKULL_RZ_FRONT, front);
        SKULL_CENTER + Vec3::new(SKULL_RX * st * u.sin(), SKULL_RY * ct, rz * st * u.cos())
    };
    let neck = {
        let t = (v - V_NECK) / (1.0 - V_NECK);
        let rz = lerp(NECK_RZ.1, NECK_RZ.0, front);
        Vec3::new(
            NECK_RX * u.sin(),
            lerp(NECK_Y.0, NECK_Y.1, t),
            NECK_CZ + rz * u.cos(),
        )
    };
    skull.lerp(neck, smoothstep(NECK_BLEND.0, NECK_BLEND.1, v))
}

/// Facial features as smooth displacements of the base surface.
const FACE_BUMPS: [Bump; 12] = [
    // Lower face brought forward and down: jaw and muzzle.
    Bump::new(
        Vec3::new(0.0, -0.075, 0.055),
        Vec3::new(0.038, 0.028, 0.045),
        Vec3::new(0.0, -0.014, 0.024),
    ),
    // Chin.
    Bump::new(
        Vec3::new(0.0, -0.100, 0.070),
        Vec3::new(0.013, 0.010, 0.03),
        Vec3::new(0.0, -0.004, 0.007),
    ),
    // Nose bridge.
    Bump::new(
        Vec3::new(0.0, -0.002, 0.085),
        Vec3::new(0.0062, 0.015, 0.03),
        Vec3::new(0.0, 0.0, 0.011),
    ),
    // Nose body and tip.
    Bump::new(
        Vec3::new(0.0, -0.030, 0.085),
        Vec3::new(0.0095, 0.011, 0.03),
        Vec3::new(0.0, -0.003, 0.022),
    ),
    // Nostril wings.
    Bump::mirrored(
        Vec3::new(0.013, -0.039, 0.082),
        Vec3::new(0.0055, 0.005, 0.03),
        Vec3::new(0.002, 0.0, 0.008),
    ),
    // Brow ridge.
    Bump::mirrored(
        Vec3::new(0.028, 0.024, 0.085),
        Vec3::new(0.020, 0.007, 0.03),
        Vec3::new(0.0, 0.0, 0.005),
    ),
    // Cheekbones.
    Bump::mirrored(
        Vec3::new(0.048, -0.014, 0.062),
        Vec3::new(0.015, 0.013, 0.03),
        Vec3::new(0.004, 0.0, 0.006),
    ),
    // Upper lip.
    Bump::new(
        Vec3::new(0.0, MOUTH_Y + 0.007, 0.08),
        Vec3::new(0.017, 0.0045, 0.03),
        Vec3::new(0.0, 0.0015, 0.0065),
    ),
    // Lower lip.
    Bump::new(
        Vec3::new(0.0, MOUTH_Y - 0.0075, 0.08),
        Vec3::new(0.015, 0.005, 0.03),
        Vec3::new(0.0, -0.001, 0.0065),
    ),
    // Groove between lower lip and chin.
    Bump::new(
        Vec3::new(0.0, MOUTH_Y - 0.017, 0.08),
        Vec3::new(0.014, 0.004, 0.03),
        Vec3::new(0.0, 0.0, -0.003),
    ),
    // Temples.
    Bump::mirrored(
        Vec3::new(0.072, 0.030, 0.030),
        Vec3::new(0.015, 0.020, 0.03),
        Vec3::new(-0.004, 0.0, 0.0),
    ),
    // Under-jaw hollow towards the neck.
    Bump::new(
        Vec3::new(0.0, -0.105, 0.02),
        Vec3::new(0.04, 0.012, 0.02),
        Vec3::new(0.0, 0.006, -0.006),
    ),
];

/// Outward flap of an ear on the side of the head (zero away from the ears).
pub fn ear_displacement(p: Vec3) -> Vec3 {
    let side = p.x.signum();
    if p.x.abs() < 0.045 {
        return Vec3::ZERO;
    }
    let c = Vec3::new(EAR_CENTER.x * side, EAR_CENTER.y, EAR_CENTER.z);
    let d = Vec2::new((p.y - c.y) / EAR_SIZE.x, (p.z - c.z) / EAR_SIZE.y);
    let q = d.length();
    let flap = smoothstep(1.05, 0.55, q);
    let rim = 0.25 * (-((q - 0.75) / 0.15).powi(2)).exp();
    let concha = 0.4 * smoothstep(0.55, 0.1, (d - Vec2::new(-0.1, 0.15)).length());
    let height = 0.014 * (flap * (0.8 + rim - concha)).max(0.0);
    Vec3::new(side * height, 0.0, -0.45 * height)
}

/// The sculpted surface at grid parameters (u, v), before the eyelids are shaped.
pub fn sculpted(u: f32, v: f32) -> Vec3 {
    let p = base_surface(u, v);
    let bumps: Vec3 = FACE_BUMPS.iter().map(|b| b.at(p)).sum();
    p + bumps + ear_displacement(p)
}

/// Distance kept between the eyelid surface and the eyeball.
pub const LID_GAP: f32 = 0.0012;
/// Half-extent (x, y) of the band around an eye within which the surface hugs the eyeball.
const LID_BAND: Vec2 = Vec2::new(0.0135, 0.0078);

/// Wraps the surface around the eyeballs near the eye openings: inside the band
/// the surface follows a sphere just outside the eyeball, blending out smoothly.
pub fn shape_eyelids(mut p: Vec3) -> Vec3 {
    for side in Side::BOTH {
        let e = side.place(EYE_CENTER);
        let d = Vec2::new(p.x - e.x, p.y - e.y);
        let w = smoothstep(2.0, 1.0, (d / LID_BAND).length());
        if w > 0.0 && p.z > e.z - 0.01 {
            let r = EYE_RADIUS + LID_GAP;
            let z_lid = e.z + (r * r - d.length_squared()).max((0.3 * r).powi(2)).sqrt();
            p.z = lerp(p.z, z_lid, w);
        }
    }
    p
}

/// A rectangular block of grid cells removed to make an opening, and the ellipse
/// (in grid index space: x = column, y = row) its border is pulled onto.
#[derive(Clone, Copy, Debug)]
pub struct Hole {
    /// First and last vertex column of the rectangle.
    pub cols: (usize, usize),
    /// First and last vertex row of the rectangle.
    pub rows: (usize, usize),
    /// Ellipse centre in index space.
    pub center: Vec2,
    /// Ellipse half-axes in index space.
    pub half: Vec2,
    /// Angle (radians) the corners of the rectangle get on the ellipse.
    pub corner_angle: f32,
}

impl Hole {
    fn in_rect(&self, r: usize, c: usize) -> bool {
        (self.rows.0..=self.rows.1).contains(&r) && (self.cols.0..=self.cols.1).contains(&c)
    }

    /// True for vertices strictly inside the rectangle (they are removed).
    pub fn is_interior(&self, r: usize, c: usize) -> bool {
        r > self.rows.0 && r < self.rows.1 && c > self.cols.0 && c < self.cols.1
    }

    /// True for vertices on the rectangle's border (they form the opening's margin).
    pub fn is_margin(&self, r: usize, c: usize) -> bool {
        self.in_rect(r, c) && !self.is_interior(r, c)
    }

    /// True when the grid cell whose top-left vertex is (r, c) is removed.
    pub fn removes_cell(&self, r: usize, c: usize) -> bool {
        r >= self.rows.0 && r < self.rows.1 && c >= self.cols.0 && c < self.cols.1
    }

    /// Chebyshev distance in cells from (r, c) to the rectangle.
    fn distance(&self, r: usize, c: usize) -> usize {
        let dr = if r < self.rows.0 {
            self.rows.0 - r
        } else {
            r.saturating_sub(self.rows.1)
        };
        let dc = if c < self.cols.0 {
            self.cols.0 - c
        } else {
            c.saturating_sub(self.cols.1)
        };
        dr.max(dc)
    }

    /// The margin as (row, col) pairs in loop order: top edge left to right, right
    /// edge down, bottom edge right to left, left edge up.
    pub fn margin_loop(&self) -> Vec<(usize, usize)> {
        let (r0, r1) = self.rows;
        let (c0, c1) = self.cols;
        let mut out: Vec<_> = (c0..=c1).map(|c| (r0, c)).collect();
        out.extend((r0 + 1..r1).map(|r| (r, c1)));
        out.extend((c0..=c1).rev().map(|c| (r1, c)));
        out.extend((r0 + 1..r1).rev().map(|r| (r, c0)));
        out
    }

    /// Angle on the ellipse of a margin vertex: negative on the upper border,
    /// positive on the lower, 0 at the right (+x) end and ±π at the left.
    pub fn margin_angle(&self, r: usize, c: usize) -> f32 {
        let (r0, r1) = self.rows;
        let (c0, c1) = self.cols;
        let ac = self.corner_angle;
        if r == r0 || r == r1 {
            let f = (c - c0) as f32 / (c1 - c0) as f32;
            let uniform = ac + (PI - 2.0 * ac) * (1.0 - f);
            let by_x = (2.0 * f - 1.0).clamp(-ac.cos(), ac.cos()).acos();
            let magnitude = 0.5 * (uniform + by_x);
            if r == r0 {
                -magnitude
            } else {
                magnitude
            }
        } else {
            let t = (r - r0) as f32 / (r1 - r0) as f32;
            if c == c1 {
                lerp(-ac, ac, t)
            } else {
                PI + ac - 2.0 * ac * t
            }
        }
    }

    /// Where a margin vertex goes in index space.
    fn margin_target(&self, r: usize, c: usize) -> Vec2 {
        let a = self.margin_angle(r, c);
        self.center + self.half * Vec2::new(a.cos(), a.sin())
    }

    /// The same hole mirrored to the other side of the face.
    fn mirrored(&self) -> Hole {
        Hole {
            cols: (COLS - self.cols.1, COLS - self.cols.0),
            rows: self.rows,
            center: Vec2::new(COLS as f32 - self.center.x, self.center.y),
            half: self.half,
            corner_angle: self.corner_angle,
        }
    }
}

/// The openings of the main surface.
#[derive(Clone, Copy, Debug)]
pub struct Openings {
    /// Left and right eye openings.
    pub eyes: [Hole; 2],
    /// The mouth slit.
    pub mouth: Hole,
}

impl Openings {
    /// All openings.
    pub fn all(&self) -> [&Hole; 3] {
        [&self.eyes[0], &self.eyes[1], &self.mouth]
    }
}

/// Grid index coordinates (column, row) of the front surface point nearest to
/// `target` in the xy-plane, found by a coarse search and a fine one.
fn locate_on_front(target: Vec2) -> Vec2 {
    let at = |x: f32, y: f32| sculpted(col_to_u(x), row_to_v(y));
    let mut best = (f32::MAX, Vec2::ZERO);
    let mut search = |x0: f32, x1: f32, y0: f32, y1: f32, step: f32| {
        let mut y = y0;
        while y <= y1 {
            let mut x = x0;
            while x <= x1 {
                let p = at(x, y);
                let d = (Vec2::new(p.x, p.y) - target).length_squared();
                if p.z > 0.0 && d < best.0 {
                    best = (d, Vec2::new(x, y));
                }
                x += step;
            }
            y += step;
        }
        best.1
    };
    let coarse = search(
        COLS as f32 * 0.3,
        COLS as f32 * 0.7,
        ROWS as f32 * 0.15,
        ROWS as f32 * 0.95,
        0.25,
    );
    search(
        coarse.x - 0.3,
        coarse.x + 0.3,
        coarse.y - 0.3,
        coarse.y + 0.3,
        0.01,
    )
}

/// Builds a hole of `cells` (columns, rows) around the surface point nearest to
/// `target`, whose ellipse has the metric half-size `half_size`.
fn hole_at(target: Vec2, half_size: Vec2, cells: (usize, usize), corner_angle: f32) -> Hole {
    let center = locate_on_front(target);
    let at = |x: f32, y: f32| sculpted(col_to_u(x), row_to_v(y));
    let per_col = (at(center.x + 0.5, center.y) - at(center.x - 0.5, center.y)).length();
    let per_row = (at(center.x, center.y + 0.5) - at(center.x, center.y - 0.5)).length();
    let c0 = (center.x - cells.0 as f32 / 2.0).round() as usize;
    let r0 = (center.y - cells.1 as f32 / 2.0).round() as usize;
    Hole {
        cols: (c0, c0 + cells.0),
        rows: (r0, r0 + cells.1),
        center,
        half: Vec2::new(half_size.x / per_col, half_size.y / per_row),
        corner_angle,
    }
}

/// Locates the eye and mouth openings on the sculpted surface.
pub fn openings() -> Openings {
    // The mouth is centred on the symmetry plane: snap its column to the middle.
    let mut mouth = hole_at(
        Vec2::new(0.0, MOUTH_Y),
        MOUTH_OPENING,
        MOUTH_HOLE_CELLS,
        0.22,
    );
    mouth.center.x = COLS as f32 / 2.0;
    let c0 = COLS / 2 - MOUTH_HOLE_CELLS.0 / 2;
    mouth.cols = (c0, c0 + MOUTH_HOLE_CELLS.0);
    let left = hole_at(
        Vec2::new(EYE_CENTER.x, EYE_CENTER.y),
        EYE_OPENING,
        EYE_HOLE_CELLS,
        0.35,
    );
    Openings {
        eyes: [left, left.mirrored()],
        mouth,
    }
}

/// Cells around an opening whose vertices are relaxed to make room for it.
const RELAX_BAND: usize = 4;

/// Index-space coordinates of every grid vertex after pulling the openings'
/// margins onto their ellipses and relaxing the band around them (Jacobi
/// iterations of the grid Laplacian; margins and far vertices stay fixed).
fn relaxed_grid(openings: &Openings) -> Vec<Vec2> {
    let idx = |r: usize, c: usize| (r - 1) * COLS + c;
    let mut coords: Vec<Vec2> = (1..=ROWS)
        .flat_map(|r| (0..COLS).map(move |c| Vec2::new(c as f32, r as f32)))
        .collect();
    let mut free = Vec::new();
    for r in 1..=ROWS {
        for c in 0..COLS {
            if let Some(h) = openings.all().into_iter().find(|h| h.is_margin(r, c)) {
                coords[idx(r, c)] = h.margin_target(r, c);
            } else if openings.all().iter().any(|h| h.is_interior(r, c)) {
                continue;
            } else if r > 1
                && r < ROWS
                && openings
                    .all()
                    .iter()
                    .any(|h| h.distance(r, c) <= RELAX_BAND)
            {
                free.push((r, c));
            }
        }
    }
    for _ in 0..300 {
        let snapshot = coords.clone();
        for &(r, c) in &free {
            let left = snapshot[idx(r, (c + COLS - 1) % COLS)];
            let right = snapshot[idx(r, (c + 1) % COLS)];
            let up = snapshot[idx(r - 1, c)];
            let down = snapshot[idx(r + 1, c)];
            coords[idx(r, c)] = 0.25 * (left + right + up + down);
        }
    }
    coords
}

/// Vertex indices of the built main surface.
pub struct Surface {
    /// The openings used.
    pub openings: Openings,
    /// Mesh index of each (row, column) grid vertex; `u32::MAX` where removed.
    pub grid: Vec<u32>,
}

impl Surface {
    /// Mesh index of grid vertex (row ≥ 1, column).
    pub fn vertex(&self, r: usize, c: usize) -> u32 {
        self.grid[(r - 1) * COLS + c % COLS]
    }

    /// Mesh indices of an opening's margin, in [`Hole::margin_loop`] order.
    pub fn margin(&self, hole: &Hole) -> Vec<u32> {
        hole.margin_loop()
            .into_iter()
            .map(|(r, c)| self.vertex(r, c))
            .collect()
    }
}

/// Adds the main surface to `mesh`: crown pole, grid vertices, the crown fan and
/// the grid cells that are not part of an opening.
pub fn build_surface(mesh: &mut RawMesh) -> Surface {
    let openings = openings();
    let coords = relaxed_grid(&openings);
    let pole = mesh.add_vertex(sculpted(0.0, 0.0), VertexPart::Pole);
    let mut grid = vec![u32::MAX; ROWS * COLS];
    for r in 1..=ROWS {
        for c in 0..COLS {
            if openings.all().iter().any(|h| h.is_interior(r, c)) {
                continue;
            }
            let k = coords[(r - 1) * COLS + c];
            let p = shape_eyelids(sculpted(col_to_u(k.x), row_to_v(k.y)));
            let part = VertexPart::Surface {
                row: r as u16,
                col: c as u16,
            };
            grid[(r - 1) * COLS + c] = mesh.add_vertex(p, part);
        }
    }
    let surface = Surface { openings, grid };
    for c in 0..COLS {
        let tri = [pole, surface.vertex(1, c), surface.vertex(1, c + 1)];
        mesh.add_triangle_facing(tri, Vec3::Y, TrianglePart::Surface);
    }
    for r in 1..ROWS {
        for c in 0..COLS {
            if openings.all().iter().any(|h| h.removes_cell(r, c)) {
                continue;
            }
            let a = surface.vertex(r, c);
            let b = surface.vertex(r, c + 1);
            let cc = surface.vertex(r + 1, c + 1);
            let d = surface.vertex(r + 1, c);
            // Counter-clockwise seen from outside: down the left edge, then across.
            mesh.add_triangle([a, d, cc], TrianglePart::Surface);
            mesh.add_triangle([a, cc, b], TrianglePart::Surface);
        }
    }
    surface
}
