//! The triangle of a mesh nearest to a point: a uniform grid over the
//! triangles' bounding boxes searched ring by ring (docs/method.md §5.1).
//! Used to give each Gaussian the region of the surface it actually sits on.

use glam::{IVec3, Vec3};

/// Cells per axis at most: bounds the grid's memory for huge or odd meshes.
const MAX_CELLS_PER_AXIS: i32 = 96;

/// A spatial index of one mesh's triangles for nearest-triangle queries.
#[derive(Clone, Debug)]
pub struct TriangleGrid {
    /// The triangles' corners.
    corners: Vec<[Vec3; 3]>,
    /// The triangles' bounding boxes (lower and upper corner): no point of a
    /// triangle is nearer than its box, which is cheaper to measure.
    boxes: Vec<[Vec3; 2]>,
    /// Lower corner of the grid.
    origin: Vec3,
    /// Edge length of a cell.
    cell: f32,
    /// Cells per axis.
    dims: IVec3,
    /// `start[c]..start[c+1]` indexes `items` for cell `c`.
    start: Vec<u32>,
    /// Triangle indices by cell.
    items: Vec<u32>,
}

impl TriangleGrid {
    /// Indexes the triangles of `vertices`; triangles with a non-finite corner
    /// are left out (they are never nearest).
    pub fn new(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let corners: Vec<[Vec3; 3]> = triangles
            .iter()
            .map(|t| t.map(|v| vertices.get(v as usize).copied().unwrap_or(Vec3::NAN)))
            .collect();
        let finite = |c: &[Vec3; 3]| c.iter().all(|v| v.is_finite());
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for c in corners.iter().filter(|c| finite(c)) {
            for v in c {
                lo = lo.min(*v);
                hi = hi.max(*v);
            }
        }
        if lo.x > hi.x {
            return Self::empty(corners);
        }
        let extent = (hi - lo).max_element().max(f32::MIN_POSITIVE);
        let count = corners.len().max(1) as f32;
        // About two triangles per occupied cell on a surface: cells scale
        // with the square root of the triangle count.
        let per_axis = (2.0 * count.sqrt()).clamp(1.0, MAX_CELLS_PER_AXIS as f32);
        let cell = extent / per_axis;
        let dims = (((hi - lo) / cell).floor().as_ivec3() + IVec3::ONE)
            .clamp(IVec3::ONE, IVec3::splat(MAX_CELLS_PER_AXIS));
        let boxes = bounding_boxes(&corners);
        let mut grid = Self {
            corners,
            boxes,
            origin: lo,
            cell,
            dims,
            start: Vec::new(),
            items: Vec::new(),
        };
        let spans: Vec<Option<(IVec3, IVec3)>> = grid
            .corners
            .iter()
            .map(|c| {
                finite(c).then(|| {
                    let (a, b) = (c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2]));
                    (grid.cell_of(a), grid.cell_of(b))
                })
            })
            .collect();
        let cells = (dims.x * dims.y * dims.z) as usize;
        let mut count = vec![0u32; cells + 1];
        for (a, b) in spans.iter().flatten() {
            grid.for_cells(*a, *b, |c| count[c + 1] += 1);
        }
        for c in 0..cells {
            count[c + 1] += count[c];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; count[cells] as usize];
        for (t, span) in spans.iter().enumerate() {
            if let Some((a, b)) = span {
                grid.for_cells(*a, *b, |c| {
                    items[fill[c] as usize] = t as u32;
                    fill[c] += 1;
                });
            }
        }
        grid.start = count;
        grid.items = items;
        grid
    }

    fn empty(corners: Vec<[Vec3; 3]>) -> Self {
        Self {
            boxes: bounding_boxes(&corners),
            corners,
            origin: Vec3::ZERO,
            cell: 1.0,
            dims: IVec3::ZERO,
            start: vec![0],
            items: Vec::new(),
        }
    }

    /// The cell holding `p`, clamped into the grid.
    fn cell_of(&self, p: Vec3) -> IVec3 {
        let c = ((p - self.origin) / self.cell).floor();
        // Clamp in float first: huge or infinite offsets must not wrap.
        let max = (self.dims - IVec3::ONE).as_vec3();
        c.clamp(Vec3::ZERO, max.max(Vec3::ZERO)).as_ivec3()
    }

    fn index(&self, c: IVec3) -> usize {
        ((c.z * self.dims.y + c.y) * self.dims.x + c.x) as usize
    }

    fn for_cells(&self, a: IVec3, b: IVec3, mut f: impl FnMut(usize)) {
        for z in a.z..=b.z {
            for y in a.y..=b.y {
                for x in a.x..=b.x {
                    f(self.index(IVec3::new(x, y, z)));
                }
            }
        }
    }

    /// The nearest triangle to `p` and its distance; `None` for a non-finite
    /// point or a mesh without finite triangles.
    pub fn nearest(&self, p: Vec3) -> Option<(u32, f32)> {
        self.nearest_within(p, f32::INFINITY)
    }

    /// The nearest triangle to `p` if one lies within `radius` (and perhaps
    /// one a little farther: only rings that may hold a nearer one are
    /// searched, so the cost follows the radius, not the mesh).
    pub fn nearest_within(&self, p: Vec3, radius: f32) -> Option<(u32, f32)> {
        if !p.is_finite() || self.dims.min_element() <= 0 || radius.is_nan() || radius < 0.0 {
            return None;
        }
        let home = self.cell_of(p);
        // What rounding may take off a distance: a thousandth of a cell, and
        // a few units in the last place of the coordinates, which dominate
        // for a mesh far from the origin.
        let slack = 1e-3 * self.cell
            + 8.0 * f32::EPSILON * (p.abs().max_element() + self.origin.abs().max_element());
        let mut best: Option<(u32, f32)> = None;
        // Clamped in float: an infinite or huge radius must not wrap.
        let rings = ((radius / self.cell).ceil() + 1.0).min(self.dims.max_element() as f32) as i32;
        for ring in 0..rings.max(1) {
            self.for_ring(home, ring, |cell| {
                let (s, e) = (self.start[cell] as usize, self.start[cell + 1] as usize);
                for &t in &self.items[s..e] {
                    // A triangle met in an earlier cell, or one whose box is
                    // farther than the best, cannot win; a tie can, and the
                    // margin keeps rounding from skipping one.
                    if best.is_some_and(|(_, bd)| self.box_is_farther(t, p, bd + slack)) {
                        continue;
                    }
                    let d = self.distance(t, p);
                    // Ties go to the lower index, whichever cell finds them
                    // first; a NaN distance (∞ − ∞ near f32's limits) is
                    // never nearest, not even the first met.
                    let nearer = match best {
                        None => !d.is_nan(),
                        Some((bt, bd)) => d < bd || (d == bd && t < bt),
                    };
                    if nearer {
                        best = Some((t, d));
                    }
                }
            });
            // A triangle not met yet lies wholly outside the cells searched.
            let unsearched = self.distance_past_ring(p, home, ring) - slack;
            if best.is_some_and(|(_, d)| d < unsearched) {
                break;
            }
        }
        best
    }

    /// How far `p` is from every cell farther than `ring` from `home` (its
    /// cell): the distance to the nearest face of the searched block that has
    /// cells beyond it, infinite once the block covers the grid. A point on
    /// the surface in the middle of its cell stops after its own cell, where
    /// `ring` cells alone would search the 26 around it too. The caller
    /// takes a rounding margin off, since a triangle's cells are found by
    /// rounding.
    fn distance_past_ring(&self, p: Vec3, home: IVec3, ring: i32) -> f32 {
        let mut nearest = f32::INFINITY;
        for axis in 0..3 {
            let (first, last) = (home[axis] - ring, home[axis] + ring);
            let at = |cell: i32| self.origin[axis] + cell as f32 * self.cell;
            if first > 0 {
                nearest = nearest.min(p[axis] - at(first));
            }
            if last < self.dims[axis] - 1 {
                nearest = nearest.min(at(last + 1) - p[axis]);
            }
        }
        nearest
    }

    /// Whether triangle `t`'s bounding box, no nearer to `p` than the
    /// triangle, lies farther than `reach` (the best distance and the
    /// caller's rounding margin, widened by 10⁻⁴ of itself): a cheap test
    /// before the exact distance, in squares. Where squares leave f32's
    /// normal range (a mesh 10⁻²⁰ m across) it answers no, and the exact
    /// distance decides.
    fn box_is_farther(&self, t: u32, p: Vec3, reach: f32) -> bool {
        let [lo, hi] = self.boxes[t as usize];
        let squared = ((lo - p).max(Vec3::ZERO) + (p - hi).max(Vec3::ZERO)).length_squared();
        let limit = reach * reach * (1.0 + 1e-4);
        limit.is_normal() && squared > limit
    }

    /// Distance from `p` to triangle `t`.
    pub fn distance(&self, t: u32, p: Vec3) -> f32 {
        let [a, b, c] = self.corners[t as usize];
        robust_length(closest_point_on_triangle(p, a, b, c) - p)
    }

    /// Calls `f` on every cell at Chebyshev distance `ring` from `home`:
    /// the shell's cells only (its two faces across z whole, then per row
    /// the rows across y whole and the two end cells of the others), not
    /// every cell of the cube it bounds, which a far point's many empty
    /// rings would pay for.
    fn for_ring(&self, home: IVec3, ring: i32, mut f: impl FnMut(usize)) {
        let lo = (home - IVec3::splat(ring)).max(IVec3::ZERO);
        let hi = (home + IVec3::splat(ring)).min(self.dims - IVec3::ONE);
        for z in lo.z..=hi.z {
            let z_face = (z - home.z).abs() == ring;
            for y in lo.y..=hi.y {
                // A row on a face whole; inside the shell along z and y,
                // only its two x ends (one call site keeps `f` inlined).
                let (mut x, step) = if z_face || (y - home.y).abs() == ring {
                    (lo.x, 1)
                } else {
                    (home.x - ring, 2 * ring)
                };
                while x <= hi.x {
                    if x >= lo.x {
                        f(self.index(IVec3::new(x, y, z)));
                    }
                    x += step;
                }
            }
        }
    }
}

/// Each triangle's bounding box (meaningless for one with a non-finite
/// corner: it is in no cell, so never measured).
fn bounding_boxes(corners: &[[Vec3; 3]]) -> Vec<[Vec3; 2]> {
    corners
        .iter()
        .map(|c| [c[0].min(c[1]).min(c[2]), c[0].max(c[1]).max(c[2])])
        .collect()
}

/// |v| without overflow for huge components.
fn robust_length(v: Vec3) -> f32 {
    let m = v.abs().max_element();
    if m == 0.0 || !m.is_finite() {
        return m;
    }
    m * (v / m).length()
}

/// The point of triangle (a, b, c) closest to `p` (by Voronoi regions of its
/// corners and edges; degenerate triangles give a point on their segments).
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    // Each edge's case asks for an edge with length (d1 − d3 = |ab|², and
    // so on): two corners in one place leave the segment to the third.
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 && d1 > d3 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 && d2 > d6 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0 && (d4 - d3) + (d5 - d6) > 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = va + vb + vc;
    if denom.abs() <= f32::MIN_POSITIVE {
        // Degenerate (collinear) triangle that fell through: the nearest corner.
        return [a, b, c]
            .into_iter()
            .min_by(|x, y| {
                (*x - p)
                    .length_squared()
                    .total_cmp(&(*y - p).length_squared())
            })
            .unwrap_or(a);
    }
    let (v, w) = (vb / denom, vc / denom);
    let q = a + ab * v + ac * w;
    if q.is_finite() {
        q
    } else {
        a
    }
}

/// Barycentric coordinates of `p` (a point on or near the triangle's plane)
/// in triangle (a, b, c), clamped into the triangle and summing to one.
/// Degenerate triangles answer their centroid.
pub fn barycentric(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> [f32; 3] {
    // In units of the longest edge from `a`, so huge coordinates do not
    // overflow the products below.
    let unit = (b - a).length().max((c - a).length());
    if unit.is_nan() || unit <= 0.0 || !unit.is_finite() {
        return [1.0 / 3.0; 3];
    }
    let (ab, ac, ap) = ((b - a) / unit, (c - a) / unit, (p - a) / unit);
    let (d00, d01, d11) = (ab.dot(ab), ab.dot(ac), ac.dot(ac));
    let (d20, d21) = (ap.dot(ab), ap.dot(ac));
    let denom = d00 * d11 - d01 * d01;
    // Relative test: a sliver whose determinant is rounding noise has no
    // meaningful coordinates.
    if denom.is_nan() || denom <= 1e-12 * d00 * d11 || !denom.is_finite() {
        return [1.0 / 3.0; 3];
    }
    let v = (d11 * d20 - d01 * d21) / denom;
    let w = (d00 * d21 - d01 * d20) / denom;
    let bary = [1.0 - v - w, v, w].map(|x| if x.is_finite() { x.max(0.0) } else { 0.0 });
    let sum: f32 = bary.iter().sum();
    if sum > 0.0 {
        bary.map(|x| x / sum)
    } else {
        [1.0 / 3.0; 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn brute(vertices: &[Vec3], triangles: &[[u32; 3]], p: Vec3) -> f32 {
        triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|v| vertices[v as usize]);
                (closest_point_on_triangle(p, a, b, c) - p).length()
            })
            .fold(f32::INFINITY, f32::min)
    }

    #[test]
    fn closest_point_covers_face_edges_and_corners() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let q = |p| closest_point_on_triangle(p, a, b, c);
        assert!((q(Vec3::new(0.2, 0.2, 1.0)) - Vec3::new(0.2, 0.2, 0.0)).length() < 1e-6);
        assert_eq!(q(Vec3::new(-1.0, -1.0, 0.0)), a);
        assert_eq!(q(Vec3::new(2.0, -0.5, 0.0)), b);
        assert_eq!(q(Vec3::new(0.5, -1.0, 3.0)), Vec3::new(0.5, 0.0, 0.0));
        assert!((q(Vec3::new(1.0, 1.0, 0.0)) - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
    }

    #[test]
    fn degenerate_triangles_give_points_on_their_segments() {
        // Collinear corners and a triangle collapsed to a point.
        let p = Vec3::new(0.5, 1.0, 0.0);
        let q = closest_point_on_triangle(p, Vec3::ZERO, Vec3::X, Vec3::X * 2.0);
        assert!((q - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6, "{q}");
        let q = closest_point_on_triangle(p, Vec3::ONE, Vec3::ONE, Vec3::ONE);
        assert_eq!(q, Vec3::ONE);
        // Two corners in one place, each pair in turn: the segment to the
        // third (this once divided 0 by 0 into a NaN point).
        let (o, x) = (Vec3::ZERO, Vec3::X);
        for (a, b, c) in [(o, o, x), (o, x, o), (x, o, o)] {
            for p in [
                Vec3::new(0.5, 1.0, 0.0),
                Vec3::new(-1.0, 0.3, 0.2),
                Vec3::new(2.0, -0.5, 0.0),
                Vec3::new(0.0, 0.0, 1.0),
            ] {
                let q = closest_point_on_triangle(p, a, b, c);
                let expected = Vec3::new(p.x.clamp(0.0, 1.0), 0.0, 0.0);
                assert!((q - expected).length() < 1e-6, "{a} {b} {c}, {p}: {q}");
            }
        }
    }

    /// An n×n grid of vertices over the unit square, waved along z by
    /// `amplitude`·sin(fx·x)·cos(fy·y), two triangles a square.
    fn wavy_sheet(n: usize, amplitude: f32, (fx, fy): (f32, f32)) -> (Vec<Vec3>, Vec<[u32; 3]>) {
        let vertices = (0..n * n)
            .map(|i| {
                let (x, y) = ((i % n) as f32 / n as f32, (i / n) as f32 / n as f32);
                Vec3::new(x, y, amplitude * (fx * x).sin() * (fy * y).cos())
            })
            .collect();
        let mut triangles = Vec::new();
        for y in 0..n - 1 {
            for x in 0..n - 1 {
                let i = (y * n + x) as u32;
                triangles.push([i, i + 1, i + n as u32]);
                triangles.push([i + 1, i + n as u32 + 1, i + n as u32]);
            }
        }
        (vertices, triangles)
    }

    #[test]
    fn grid_agrees_with_brute_force_on_a_curved_sheet_and_far_points() {
        // A wavy 30×30 sheet plus a separate small part far away.
        let (mut vertices, mut triangles) = wavy_sheet(30, 0.1, (6.0, 4.0));
        let k = vertices.len() as u32;
        vertices.extend([
            Vec3::new(5.0, 5.0, 5.0),
            Vec3::new(5.1, 5.0, 5.0),
            Vec3::new(5.0, 5.1, 5.0),
        ]);
        triangles.push([k, k + 1, k + 2]);
        let grid = TriangleGrid::new(&vertices, &triangles);
        let mut state = 12345u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        for _ in 0..500 {
            let p = Vec3::new(next() * 7.0 - 1.0, next() * 7.0 - 1.0, next() * 7.0 - 1.0);
            let (t, d) = grid.nearest(p).unwrap();
            let want = brute(&vertices, &triangles, p);
            assert!(
                (d - want).abs() <= 1e-5 * want.max(1.0),
                "{p}: {d} vs {want}"
            );
            assert!((grid.distance(t, p) - d).abs() < 1e-6);
        }
    }

    /// The nearest triangle by brute force, ties to the lower index.
    fn brute_nearest(grid: &TriangleGrid, count: usize, p: Vec3) -> (u32, f32) {
        (0..count as u32).map(|t| (t, grid.distance(t, p))).fold(
            (u32::MAX, f32::INFINITY),
            |best, (t, d)| {
                if d < best.1 {
                    (t, d)
                } else {
                    best
                }
            },
        )
    }

    #[test]
    fn grid_finds_the_very_triangle_brute_force_does_on_and_near_the_surface() {
        // A wavy sheet of shared corners (so many triangles tie at a
        // vertex), queried on it, just off it and across cell faces: the
        // early stop may never skip the nearest, nor a lower-indexed tie —
        // at a human scale, a tiny one and a huge one.
        let (vertices, triangles) = wavy_sheet(30, 0.05, (9.0, 7.0));
        for scale in [1.0, 1e-20, 1e15] {
            let vertices: Vec<Vec3> = vertices.iter().map(|&v| v * scale).collect();
            assert_grid_matches_brute_force(&vertices, &triangles);
        }
        // Far from the origin (2·10⁴ times its size), where the coordinates'
        // rounding outweighs a thousandth of a cell, and flat (one cell deep).
        let offset = Vec3::new(1e4, -2e4, 1.5e4);
        let far: Vec<Vec3> = vertices.iter().map(|&v| v + offset).collect();
        assert_grid_matches_brute_force(&far, &triangles);
        let (flat, flat_triangles) = wavy_sheet(30, 0.0, (9.0, 7.0));
        assert_grid_matches_brute_force(&flat, &flat_triangles);
    }

    /// Queries of `TriangleGrid` on `vertices`: at vertices, just off them,
    /// farther off, all as brute force answers.
    fn assert_grid_matches_brute_force(vertices: &[Vec3], triangles: &[[u32; 3]]) {
        let grid = TriangleGrid::new(vertices, triangles);
        let centre = vertices[vertices.len() / 2];
        let size = vertices
            .iter()
            .fold(0.0f32, |m, v| m.max((*v - centre).abs().max_element()));
        let mut state = 777u32;
        let mut next = || {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (state >> 8) as f32 / (1u32 << 24) as f32
        };
        let mut points: Vec<Vec3> = vertices.iter().step_by(7).copied().collect();
        // Far off the surface and outside the grid.
        for k in 0..200 {
            let offset = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            points.push(centre + offset * size * [0.5, 3.0][k % 2]);
        }
        for _ in 0..1000 {
            let v = vertices[(next() * vertices.len() as f32) as usize % vertices.len()];
            let offset = Vec3::new(next() - 0.5, next() - 0.5, next() - 0.5);
            points.push(v + offset * size * [0.0, 1e-4, 0.01, 0.05][points.len() % 4]);
        }
        for p in points {
            let found = grid.nearest(p).unwrap();
            assert!(!found.1.is_nan(), "{p}");
            assert_eq!(found, brute_nearest(&grid, triangles.len(), p), "{p}");
        }
    }

    #[test]
    fn a_bounded_search_finds_what_lies_within_its_radius() {
        let vertices = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::Y,
            Vec3::new(0.0, 0.0, 5.0),
            Vec3::new(1.0, 0.0, 5.0),
            Vec3::new(0.0, 1.0, 5.0),
        ];
        let grid = TriangleGrid::new(&vertices, &[[0, 1, 2], [3, 4, 5]]);
        let p = Vec3::new(0.2, 0.2, 0.5);
        assert_eq!(grid.nearest_within(p, 1.0), Some((0, 0.5)));
        assert_eq!(grid.nearest_within(p, 0.1).filter(|(_, d)| *d <= 0.1), None);
        assert_eq!(grid.nearest_within(p, f32::NAN), None);
        assert_eq!(
            grid.nearest_within(Vec3::new(0.2, 0.2, 4.9), f32::INFINITY)
                .map(|x| x.0),
            Some(1)
        );
    }

    #[test]
    fn bad_points_and_bad_meshes_answer_none_or_skip() {
        let vertices = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::NAN];
        let grid = TriangleGrid::new(&vertices, &[[0, 1, 2], [0, 1, 3]]);
        assert_eq!(grid.nearest(Vec3::NAN), None);
        assert_eq!(grid.nearest(Vec3::new(f32::INFINITY, 0.0, 0.0)), None);
        // The triangle with a NaN corner is never the answer.
        assert_eq!(grid.nearest(Vec3::new(0.2, 0.2, 1.0)).map(|x| x.0), Some(0));
        // Huge coordinates stay finite and correct.
        let (t, d) = grid.nearest(Vec3::new(1e30, 0.0, 0.0)).unwrap();
        assert_eq!(t, 0);
        assert!(d.is_finite() && d > 9e29);
        let empty = TriangleGrid::new(&[], &[]);
        assert_eq!(empty.nearest(Vec3::ZERO), None);
        let all_bad = TriangleGrid::new(&[Vec3::NAN; 3], &[[0, 1, 2]]);
        assert_eq!(all_bad.nearest(Vec3::ZERO), None);
    }

    #[test]
    fn barycentric_coordinates_recover_points_and_survive_degenerate_triangles() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let p = a * 0.2 + b * 0.3 + c * 0.5;
        let bary = barycentric(p, a, b, c);
        for (got, want) in bary.iter().zip([0.2, 0.3, 0.5]) {
            assert!((got - want).abs() < 1e-6, "{bary:?}");
        }
        // Off the plane: the projection's coordinates.
        let lifted = barycentric(p + Vec3::Z * 3.0, a, b, c);
        assert!((lifted[2] - 0.5).abs() < 1e-6);
        // Outside: clamped to the triangle, still summing to one.
        let outside = barycentric(Vec3::new(2.0, -1.0, 0.0), a, b, c);
        assert!(outside.iter().all(|x| *x >= 0.0));
        assert!((outside.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        // Degenerate: a point, a line, a sliver, NaN.
        for (a, b, c) in [
            (Vec3::ONE, Vec3::ONE, Vec3::ONE),
            (Vec3::ZERO, Vec3::X, Vec3::X * 2.0),
            (Vec3::ZERO, Vec3::X, Vec3::new(0.5, 1e-9, 0.0)),
            (Vec3::ZERO, Vec3::X, Vec3::NAN),
        ] {
            let bary = barycentric(Vec3::new(0.3, 0.1, 0.0), a, b, c);
            assert!(bary.iter().all(|x| x.is_finite() && *x >= 0.0), "{bary:?}");
            assert!((bary.iter().sum::<f32>() - 1.0).abs() < 1e-6);
        }
        // Huge coordinates.
        let s = 1e15;
        let bary = barycentric(p * s, a * s, b * s, c * s);
        assert!((bary[1] - 0.3).abs() < 1e-3, "{bary:?}");
    }
}
