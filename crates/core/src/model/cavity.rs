//! A mouth cavity for head meshes that have none (FLAME): a pocket of rings
//! hung from the lips' inner boundary loop, closed at the back, so that open
//! mouths show a surface to bind Gaussians to instead of the inside of the head.
//!
//! The pocket follows the built-in head's (`builtin/parts.rs`), with every size
//! in units of the mouth's half-width W: five rings, each one a scaled copy of
//! the lip loop pushed back by `depth · W` (further at the corners by
//! `arch · W · s²`, s = −1…1 from corner to corner) and opened vertically by
//! `± height · W · (1 − s²)^(boxiness/2)` (up for the upper lip's half, down for
//! the lower), then a fan to one vertex behind the last ring.
//!
//! Cavity vertices are weighted sums of lip-loop vertices ([`MouthCavity`]):
//! each ring vertex copies the loop vertex it hangs from, the back vertex the
//! mean of the loop. Files never see them (GaussianAvatars' FLAME has no
//! cavity): offsets read from files are extended through the anchors, and
//! exports rebind cavity Gaussians to the nearest triangle files know.

use std::collections::{HashMap, HashSet};

use glam::{DVec3, Vec3};

/// Ring shapes in units of the mouth's half-width: (width relative to the loop,
/// half-height, depth behind the loop, extra depth at the corners, boxiness).
/// The built-in head's pocket (half-width 23.5 mm) scaled to W = 1.
const RINGS: [(f32, f32, f32, f32, f32); 5] = [
    (0.93, 0.15, 0.21, 0.00, 1.0),
    (0.95, 0.53, 0.32, 0.13, 0.6),
    (0.95, 0.64, 1.02, 0.43, 0.5),
    (0.80, 0.60, 1.70, 0.43, 0.5),
    (0.50, 0.40, 2.13, 0.26, 0.6),
];

/// How far behind the last ring's centroid the closing vertex sits (units of W).
const BACK_DEPTH: f32 = 0.1;

/// The vertices and triangles a cavity adds after a model's own, and how each
/// added vertex follows the lip loop.
#[derive(Clone, Debug, PartialEq)]
pub struct MouthCavity {
    /// Index of the first cavity vertex (the model's vertex count as files have it).
    pub first_vertex: usize,
    /// Index of the first cavity triangle (the triangle count files know).
    pub first_triangle: usize,
    /// Per cavity vertex: the loop vertices it is a weighted sum of.
    pub anchors: Vec<Vec<(u32, f32)>>,
}

impl MouthCavity {
    /// Appends one value per cavity vertex to `values` (which holds the file's
    /// vertices), each `sum` of its anchors.
    fn extend_by<T: Copy>(&self, values: &mut Vec<T>, sum: impl Fn(&[T], &[(u32, f32)]) -> T) {
        for anchors in &self.anchors {
            let v = sum(values, anchors);
            values.push(v);
        }
    }

    /// Extends a displacement field (a shape, expression or pose-corrective
    /// component): the cavity moves with its anchors in full. (Fading the
    /// expressions towards the back left the cavity's floor up when the lower
    /// lip went down: 0.3 dB worse on open mouths in `visage bench mouth`.)
    pub fn extend_field(&self, field: &mut Vec<Vec3>) {
        self.extend_by(field, |f, a| {
            a.iter().map(|&(v, w)| w * f[v as usize]).sum::<Vec3>()
        });
    }

    /// Extends per-vertex offsets read from a file (static or per-frame).
    pub fn extend_offsets(&self, offsets: &mut Vec<DVec3>) {
        self.extend_by(offsets, |o, a| {
            a.iter().map(|&(v, w)| w as f64 * o[v as usize]).sum()
        });
    }

    /// Extends linear-blend skinning weights (rows stay normalised).
    pub fn extend_weights<const J: usize>(&self, weights: &mut Vec<[f32; J]>) {
        self.extend_by(weights, |ws, a| {
            let mut out = [0.0; J];
            for &(v, w) in a {
                for (o, x) in out.iter_mut().zip(ws[v as usize]) {
                    *o += w * x;
                }
            }
            out
        });
    }
}

/// A cavity's geometry, in indices that continue the mesh it was built for.
pub struct CavityMesh {
    /// Positions of the added vertices.
    pub positions: Vec<Vec3>,
    /// Added triangles (indices into the whole mesh).
    pub triangles: Vec<[u32; 3]>,
    /// Anchors of the added vertices.
    pub cavity: MouthCavity,
}

/// The boundary loops of a mesh, each in the direction its edges run in their
/// one triangle. Loops through a vertex with two outgoing boundary edges
/// (non-manifold) are left out.
pub fn boundary_loops(vertex_count: usize, triangles: &[[u32; 3]]) -> Vec<Vec<u32>> {
    let edges: HashSet<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
        .collect();
    let mut next: HashMap<u32, u32> = HashMap::new();
    let mut tangled = HashSet::new();
    for &(u, v) in &edges {
        if !edges.contains(&(v, u)) && next.insert(u, v).is_some() {
            tangled.insert(u);
        }
    }
    let mut seen = vec![false; vertex_count];
    let mut starts: Vec<u32> = next.keys().copied().collect();
    starts.sort_unstable();
    let mut loops = Vec::new();
    for start in starts {
        if seen[start as usize] {
            continue;
        }
        let mut ring = vec![start];
        seen[start as usize] = true;
        let mut at = start;
        let closed = loop {
            let Some(&n) = next.get(&at) else { break false };
            if n == start {
                break true;
            }
            if seen[n as usize] {
                break false;
            }
            seen[n as usize] = true;
            ring.push(n);
            at = n;
        };
        if closed && ring.len() >= 3 && !ring.iter().any(|v| tangled.contains(v)) {
            loops.push(ring);
        }
    }
    loops
}

/// The mouth's boundary loop: of the mesh's boundary loops, the one with the
/// most vertices for which `is_lip` holds, when at least three quarters of its
/// vertices do. `None` when the mouth is already closed (no such loop).
pub fn mouth_loop(
    vertex_count: usize,
    triangles: &[[u32; 3]],
    is_lip: impl Fn(u32) -> bool,
) -> Option<Vec<u32>> {
    boundary_loops(vertex_count, triangles)
        .into_iter()
        .map(|l| (l.iter().filter(|&&v| is_lip(v)).count(), l))
        .filter(|(lips, l)| l.len() >= 6 && 4 * lips >= 3 * l.len())
        .max_by_key(|(lips, _)| *lips)
        .map(|(_, l)| l)
}

/// Builds the cavity behind `mouth` (a boundary loop of the mesh whose first
/// `positions.len()` vertices and `first_triangle` triangles it continues),
/// with the model facing +z. Triangles are wound to continue the lips' own.
pub fn build_mouth_cavity(positions: &[Vec3], first_triangle: usize, mouth: &[u32]) -> CavityMesh {
    let at = |v: u32| positions[v as usize];
    let n = mouth.len();
    let (lo, hi) = mouth.iter().fold((f32::MAX, f32::MIN), |(lo, hi), &v| {
        (lo.min(at(v).x), hi.max(at(v).x))
    });
    let half_width = (0.5 * (hi - lo)).max(1e-6);
    let cx = 0.5 * (lo + hi);
    let centre = mouth.iter().map(|&v| at(v)).sum::<Vec3>() / n as f32;
    let upper = upper_half(positions, mouth);
    let first_vertex = positions.len();
    let mut out = CavityMesh {
        positions: Vec::with_capacity(RINGS.len() * n + 1),
        triangles: Vec::with_capacity(2 * RINGS.len() * n + n),
        cavity: MouthCavity {
            first_vertex,
            first_triangle,
            anchors: Vec::new(),
        },
    };
    let mut previous: Vec<u32> = mouth.to_vec();
    for (k, &(width, height, depth, arch, boxiness)) in RINGS.iter().enumerate() {
        let t = (k + 1) as f32 / RINGS.len() as f32;
        let ring: Vec<u32> = mouth
            .iter()
            .zip(&upper)
            .map(|(&v, &side)| {
                let p = at(v);
                let s = ((p.x - cx) / half_width).clamp(-1.0, 1.0);
                let lift = side * (1.0 - s * s).max(0.0).powf(0.5 * boxiness) * height;
                let q = Vec3::new(
                    cx + width * (p.x - cx),
                    p.y + t * (centre.y - p.y) + lift * half_width,
                    p.z - half_width * (depth + arch * s * s),
                );
                out.push_vertex(q, vec![(v, 1.0)])
            })
            .collect();
        out.strip(&previous, &ring);
        previous = ring;
    }
    let back_centre = previous
        .iter()
        .map(|&v| out.positions[v as usize - first_vertex])
        .sum::<Vec3>()
        / n as f32
        - Vec3::new(0.0, 0.0, BACK_DEPTH * half_width);
    let mean = mouth.iter().map(|&v| (v, 1.0 / n as f32)).collect();
    let back = out.push_vertex(back_centre, mean);
    for j in 0..n {
        let (a, b) = (previous[j], previous[(j + 1) % n]);
        out.triangles.push([b, a, back]);
    }
    out
}

impl CavityMesh {
    fn push_vertex(&mut self, p: Vec3, anchors: Vec<(u32, f32)>) -> u32 {
        self.positions.push(p);
        self.cavity.anchors.push(anchors);
        (self.cavity.first_vertex + self.positions.len() - 1) as u32
    }

    /// Quads between two loops of equal length whose edges `a[j] → a[j+1]`
    /// already run that way in a triangle: the new triangles run them backwards,
    /// so the surface keeps one orientation.
    fn strip(&mut self, a: &[u32], b: &[u32]) {
        let n = a.len();
        for j in 0..n {
            let k = (j + 1) % n;
            self.triangles.push([a[k], a[j], b[j]]);
            self.triangles.push([a[k], b[j], b[k]]);
        }
    }
}

/// Per loop vertex: +1 on the upper lip's half, −1 on the lower, 0 at the two
/// corners (the loop's leftmost and rightmost vertices).
fn upper_half(positions: &[Vec3], mouth: &[u32]) -> Vec<f32> {
    let n = mouth.len();
    let x = |j: usize| positions[mouth[j] as usize].x;
    let left = (0..n).min_by(|&a, &b| x(a).total_cmp(&x(b))).unwrap_or(0);
    let right = (0..n).max_by(|&a, &b| x(a).total_cmp(&x(b))).unwrap_or(0);
    // The two chains from left to right, walking the loop both ways.
    let on_first = |j: usize| {
        let from_left = (j + n - left) % n;
        let to_right = (right + n - left) % n;
        from_left < to_right
    };
    let mean_y = |first: bool| {
        let ys: Vec<f32> = (0..n)
            .filter(|&j| j != left && j != right && on_first(j) == first)
            .map(|j| positions[mouth[j] as usize].y)
            .collect();
        ys.iter().sum::<f32>() / ys.len().max(1) as f32
    };
    let first_is_upper = mean_y(true) >= mean_y(false);
    (0..n)
        .map(|j| {
            if j == left || j == right {
                0.0
            } else if on_first(j) == first_is_upper {
                1.0
            } else {
                -1.0
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat face (grid in the z = 0 plane, rows 0..=4, columns 0..=8) with
    /// the quads of rows 1-2, columns 2-5 cut out: a mouth hole whose rim is
    /// 12 vertices.
    fn slit_face() -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let (rows, cols) = (5u32, 9u32);
        let id = |r: u32, c: u32| r * cols + c;
        let positions = (0..rows)
            .flat_map(|r| {
                (0..cols)
                    .map(move |c| Vec3::new(c as f32 * 0.01 - 0.04, r as f32 * 0.004 - 0.008, 0.0))
            })
            .collect();
        let mut triangles = Vec::new();
        for r in 0..rows - 1 {
            for c in 0..cols - 1 {
                if (r == 1 || r == 2) && (2..6).contains(&c) {
                    continue;
                }
                triangles.push([id(r, c), id(r, c + 1), id(r + 1, c + 1)]);
                triangles.push([id(r, c), id(r + 1, c + 1), id(r + 1, c)]);
            }
        }
        (positions, triangles)
    }

    #[test]
    fn the_mouth_loop_is_found_and_closed_by_a_consistently_wound_pocket() {
        let (positions, triangles) = slit_face();
        let lips = |v: u32| {
            let (r, c) = (v / 9, v % 9);
            (1..=3).contains(&r) && (2..=6).contains(&c)
        };
        let mouth = mouth_loop(positions.len(), &triangles, lips).expect("mouth loop");
        assert_eq!(mouth.len(), 12, "the hole's rim: 5 + 1 + 5 + 1 vertices");
        let cavity = build_mouth_cavity(&positions, triangles.len(), &mouth);
        assert_eq!(cavity.positions.len(), RINGS.len() * mouth.len() + 1);
        assert_eq!(cavity.cavity.anchors.len(), cavity.positions.len());
        let mut all = triangles.clone();
        all.extend(&cavity.triangles);
        // Closed: no boundary is left where the mouth was, only the outer rim.
        let loops = boundary_loops(positions.len() + cavity.positions.len(), &all);
        assert_eq!(loops.len(), 1, "only the face's outer edge stays open");
        // One orientation: every interior edge is used once each way.
        let mut directed = HashSet::new();
        for t in &all {
            for e in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
                assert!(directed.insert(e), "edge {e:?} runs the same way twice");
            }
        }
        // Behind the face, and opening up and down round the slit.
        assert!(cavity.positions.iter().all(|p| p.z < 0.0));
        let ys: Vec<f32> = cavity.positions.iter().map(|p| p.y).collect();
        let (min, max) = ys
            .iter()
            .fold((f32::MAX, f32::MIN), |a, &y| (a.0.min(y), a.1.max(y)));
        assert!(
            max - min > 0.02,
            "the pocket opens to hold the teeth: {min}..{max}"
        );
    }

    #[test]
    fn a_closed_mouth_has_no_loop_and_cavity_values_follow_their_anchors() {
        let (positions, mut triangles) = slit_face();
        let id = |r: u32, c: u32| r * 9 + c;
        for r in 1..3 {
            for c in 2..6 {
                triangles.push([id(r, c), id(r, c + 1), id(r + 1, c + 1)]);
                triangles.push([id(r, c), id(r + 1, c + 1), id(r + 1, c)]);
            }
        }
        // The face's outer rim is still open, but it is not lips.
        let lips = |v: u32| (1..=3).contains(&(v / 9)) && (2..=6).contains(&(v % 9));
        assert!(mouth_loop(positions.len(), &triangles, lips).is_none());
        assert_eq!(boundary_loops(positions.len(), &triangles).len(), 1);
        let cavity = MouthCavity {
            first_vertex: 3,
            first_triangle: 1,
            anchors: vec![vec![(0, 1.0)], vec![(1, 0.5), (2, 0.5)]],
        };
        let mut field = vec![Vec3::X, Vec3::Y, Vec3::Z];
        cavity.extend_field(&mut field);
        assert_eq!(field[3], Vec3::X);
        assert_eq!(field[4], Vec3::new(0.0, 0.5, 0.5));
        let mut weights = vec![[1.0, 0.0], [0.0, 1.0], [0.0, 1.0]];
        cavity.extend_weights(&mut weights);
        assert_eq!(weights[3], [1.0, 0.0]);
        assert_eq!(weights[4], [0.0, 1.0]);
        let mut offsets = vec![DVec3::X, DVec3::Y, DVec3::ZERO];
        cavity.extend_offsets(&mut offsets);
        assert_eq!(offsets[4], DVec3::new(0.0, 0.5, 0.0));
    }
}
