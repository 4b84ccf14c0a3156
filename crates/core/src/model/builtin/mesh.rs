//! A triangle mesh under construction, with per-vertex and per-triangle tags that
//! later steps (regions, skinning, bases) read to know what each element is.

use std::collections::HashSet;

use glam::Vec3;

use super::layout::Side;

/// What a vertex belongs to.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum VertexPart {
    /// The crown pole of the main surface.
    Pole,
    /// A main-surface grid vertex at (row, column).
    Surface { row: u16, col: u16 },
    /// A ring of the eye-socket lining behind the eyelid margin.
    EyeSocket { side: Side, ring: u8 },
    /// A ring of the mouth cavity; `alpha` < 0 on the upper half, > 0 on the lower.
    Pocket { alpha: f32, ring: u8 },
    /// An eyeball vertex.
    Eyeball(Side),
    /// A tooth-row vertex.
    Teeth { upper: bool },
}

/// What a triangle belongs to (regions are assigned from this and its position).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrianglePart {
    /// The main surface grid.
    Surface,
    /// The eye-socket lining.
    EyeSocket(Side),
    /// The mouth cavity.
    Pocket,
    /// An eyeball.
    Eyeball(Side),
    /// A tooth row.
    Teeth { upper: bool },
}

/// Vertices, triangles and their tags, plus the set of directed edges used so far
/// so that strips can be oriented consistently with what already exists.
#[derive(Default)]
pub struct RawMesh {
    /// Rest positions.
    pub positions: Vec<Vec3>,
    /// Tag per vertex.
    pub vertex_parts: Vec<VertexPart>,
    /// Triangles (counter-clockwise seen from outside).
    pub triangles: Vec<[u32; 3]>,
    /// Tag per triangle.
    pub triangle_parts: Vec<TrianglePart>,
    directed_edges: HashSet<(u32, u32)>,
}

impl RawMesh {
    /// Adds a vertex and returns its index.
    pub fn add_vertex(&mut self, position: Vec3, part: VertexPart) -> u32 {
        self.positions.push(position);
        self.vertex_parts.push(part);
        (self.positions.len() - 1) as u32
    }

    /// Adds a triangle as given.
    pub fn add_triangle(&mut self, tri: [u32; 3], part: TrianglePart) {
        for k in 0..3 {
            self.directed_edges.insert((tri[k], tri[(k + 1) % 3]));
        }
        self.triangles.push(tri);
        self.triangle_parts.push(part);
    }

    /// Adds a triangle, flipped if needed so its normal points along `outward`.
    pub fn add_triangle_facing(&mut self, tri: [u32; 3], outward: Vec3, part: TrianglePart) {
        let [a, b, c] = tri.map(|i| self.positions[i as usize]);
        if (b - a).cross(c - a).dot(outward) < 0.0 {
            self.add_triangle([tri[0], tri[2], tri[1]], part);
        } else {
            self.add_triangle(tri, part);
        }
    }

    /// Connects two vertex chains of equal length with a band of triangles. The
    /// orientation is chosen so that the band traverses chain `a`'s edges opposite
    /// to any triangle already using them (keeps the surface consistently oriented).
    pub fn add_strip(&mut self, a: &[u32], b: &[u32], closed: bool, part: TrianglePart) {
        assert_eq!(a.len(), b.len(), "strip chains differ in length");
        let n = a.len();
        let segments = if closed { n } else { n - 1 };
        let flip = (0..segments).any(|i| {
            let j = (i + 1) % n;
            self.directed_edges.contains(&(a[j], a[i]))
        });
        for i in 0..segments {
            let j = (i + 1) % n;
            if flip {
                self.add_triangle([a[i], b[j], b[i]], part);
                self.add_triangle([a[i], a[j], b[j]], part);
            } else {
                self.add_triangle([a[i], b[i], b[j]], part);
                self.add_triangle([a[i], b[j], a[j]], part);
            }
        }
    }

    /// Drops vertices no triangle references and renumbers the rest.
    pub fn compact(&mut self) {
        let mut used = vec![false; self.positions.len()];
        for t in &self.triangles {
            for &i in t {
                used[i as usize] = true;
            }
        }
        let mut remap = vec![u32::MAX; self.positions.len()];
        let mut next = 0u32;
        for (i, u) in used.iter().enumerate() {
            if *u {
                remap[i] = next;
                next += 1;
            }
        }
        retain_used(&mut self.positions, &used);
        retain_used(&mut self.vertex_parts, &used);
        for t in &mut self.triangles {
            *t = t.map(|i| remap[i as usize]);
        }
        self.directed_edges = self
            .directed_edges
            .iter()
            .filter(|(a, b)| used[*a as usize] && used[*b as usize])
            .map(|(a, b)| (remap[*a as usize], remap[*b as usize]))
            .collect();
    }
}

fn retain_used<T>(items: &mut Vec<T>, used: &[bool]) {
    let mut i = 0;
    items.retain(|_| {
        i += 1;
        used[i - 1]
    });
}
