//! Shape blending by a mesh Laplacian solve (thesis 4.1.2, docs/method.md §6).
//!
//! Every directed triangle edge e = (i, j) of region r gets the target
//! d_e = Σ_f w_r^f (v_j^f − v_i^f); disjoint parts (eyeballs, teeth) are tied to
//! two main-surface regions by anchor edges in both directions. The blended
//! vertices solve L V' = Mᵀ d with L = MᵀM, one vertex pinned to its position in
//! the base avatar's mesh. L depends on the topology only, so it is factored once
//! (sparse Cholesky, f64, fill-reducing ordering); a weight change is a new
//! right-hand side. The pinned vertex is removed from the system.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};
use glam::{DVec3, Vec3};

use crate::error::{Error, Result};
use crate::model::head::HeadModel;
use crate::model::regions::Region;
use crate::model::topology::UnionFind;

/// One anchor edge pair between a disjoint part and a main-surface region.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Anchor {
    /// The disjoint part's region.
    pub part: Region,
    /// Anchor vertex on the part (nearest to its region's geometric median).
    pub part_vertex: u32,
    /// The main-surface region it is tied to.
    pub target: Region,
    /// Anchor vertex on that region.
    pub target_vertex: u32,
}

/// A sparse right-hand-side contribution: (vertex, vector) pairs, vertex-sorted.
pub type SparseRhs = Vec<(u32, DVec3)>;

/// The factored blend system of a topology.
pub struct Blender {
    vertex_count: usize,
    pinned: u32,
    /// Reduced index of each vertex (`u32::MAX` for the pinned one).
    reduced: Vec<u32>,
    /// Directed edges per region (anchor edges included, in their start vertex's region).
    region_edges: Vec<Vec<(u32, u32)>>,
    anchors: Vec<Anchor>,
    llt: Llt<usize, f64>,
    /// Reduced Laplacian rows (for residuals): CSR.
    row_start: Vec<usize>,
    row_entries: Vec<(u32, f64)>,
    /// Entries of the pinned vertex's column on the free rows: (reduced row, value).
    pin_column: Vec<(u32, f64)>,
}

/// Result of one blend solve.
#[derive(Clone, Debug)]
pub struct BlendSolution {
    /// Blended vertex positions.
    pub vertices: Vec<DVec3>,
    /// Relative residual ‖L x − b‖ / ‖b‖ of the reduced system (max over x, y, z).
    pub residual: f64,
}

/// Point minimising the sum of distances to `points` (Weiszfeld iterations).
pub fn geometric_median(points: &[DVec3]) -> DVec3 {
    let mut m = points.iter().sum::<DVec3>() / points.len().max(1) as f64;
    for _ in 0..200 {
        let (mut num, mut den) = (DVec3::ZERO, 0.0);
        for p in points {
            let d = (*p - m).length().max(1e-12);
            num += *p / d;
            den += 1.0 / d;
        }
        let next = num / den;
        let step = (next - m).length();
        m = next;
        if step < 1e-12 {
            break;
        }
    }
    m
}

fn nearest(vertices: &[u32], positions: &[Vec3], to: DVec3) -> u32 {
    *vertices
        .iter()
        .min_by(|&&a, &&b| {
            (positions[a as usize].as_dvec3() - to)
                .length_squared()
                .total_cmp(&(positions[b as usize].as_dvec3() - to).length_squared())
        })
        .expect("non-empty vertex set")
}

fn region_vertex_sets(model: &HeadModel) -> Vec<Vec<u32>> {
    let mut sets = vec![Vec::new(); Region::COUNT];
    for (t, r) in model.triangles.iter().zip(&model.triangle_regions) {
        sets[r.index()].extend_from_slice(t);
    }
    for s in &mut sets {
        s.sort_unstable();
        s.dedup();
    }
    sets
}

/// Anchor edges of a model: each disjoint region tied to its two anchor regions,
/// anchors being the region vertices nearest the regions' geometric medians.
pub fn anchors(model: &HeadModel) -> Vec<Anchor> {
    let sets = region_vertex_sets(model);
    let anchor_of = |r: Region| -> Option<u32> {
        let verts = &sets[r.index()];
        if verts.is_empty() {
            return None;
        }
        let pts: Vec<DVec3> = verts
            .iter()
            .map(|&v| model.template[v as usize].as_dvec3())
            .collect();
        Some(nearest(verts, &model.template, geometric_median(&pts)))
    };
    let mut out = Vec::new();
    for part in Region::ALL {
        let (Some(targets), Some(part_vertex)) = (part.anchor_regions(), anchor_of(part)) else {
            continue;
        };
        for target in targets {
            if let Some(target_vertex) = anchor_of(target) {
                out.push(Anchor {
                    part,
                    part_vertex,
                    target,
                    target_vertex,
                });
            }
        }
    }
    out
}

impl Blender {
    /// Builds and factors the blend system of a model. Fails with a clear message
    /// when some part of the mesh is connected neither by edges nor by anchors
    /// (the Laplacian would be singular and the part would drift).
    pub fn new(model: &HeadModel) -> Result<Self> {
        // Small systems: threads cost more than they give, and results stay reproducible.
        faer::set_global_parallelism(faer::Par::Seq);
        let n = model.vertex_count();
        if n < 2 {
            return Err(Error::input(
                "the head model needs at least two vertices to blend shapes",
            ));
        }
        let anchors = anchors(model);
        let mut region_edges = vec![Vec::new(); Region::COUNT];
        for (t, r) in model.triangles.iter().zip(&model.triangle_regions) {
            for k in 0..3 {
                region_edges[r.index()].push((t[k], t[(k + 1) % 3]));
            }
        }
        for a in &anchors {
            region_edges[a.part.index()].push((a.part_vertex, a.target_vertex));
            region_edges[a.target.index()].push((a.target_vertex, a.part_vertex));
        }
        check_connected(model, &region_edges)?;
        let all: Vec<DVec3> = model.template.iter().map(|p| p.as_dvec3()).collect();
        let every: Vec<u32> = (0..n as u32).collect();
        let pinned = nearest(&every, &model.template, geometric_median(&all));
        let mut reduced = vec![u32::MAX; n];
        let mut next = 0u32;
        for (v, slot) in reduced.iter_mut().enumerate() {
            if v as u32 != pinned {
                *slot = next;
                next += 1;
            }
        }
        // L = MᵀM: each directed edge (i, j) adds +1 at (i,i), (j,j) and −1 at (i,j), (j,i).
        let mut degree = vec![0.0f64; n];
        let mut off: std::collections::HashMap<(u32, u32), f64> = Default::default();
        for edges in &region_edges {
            for &(i, j) in edges {
                degree[i as usize] += 1.0;
                degree[j as usize] += 1.0;
                let key = (i.min(j), i.max(j));
                *off.entry(key).or_insert(0.0) -= 1.0;
            }
        }
        let m = n - 1;
        let mut triplets = Vec::with_capacity(n + 2 * off.len());
        let mut rows: Vec<Vec<(u32, f64)>> = vec![Vec::new(); m];
        let mut pin_column = Vec::new();
        for (v, &d) in degree.iter().enumerate() {
            let rv = reduced[v];
            if rv != u32::MAX {
                triplets.push(Triplet::new(rv as usize, rv as usize, d));
                rows[rv as usize].push((rv, d));
            }
        }
        let mut pairs: Vec<_> = off.into_iter().collect();
        pairs.sort_unstable_by_key(|(k, _)| *k);
        for ((a, b), w) in pairs {
            let (ra, rb) = (reduced[a as usize], reduced[b as usize]);
            match (ra != u32::MAX, rb != u32::MAX) {
                (true, true) => {
                    triplets.push(Triplet::new(ra as usize, rb as usize, w));
                    triplets.push(Triplet::new(rb as usize, ra as usize, w));
                    rows[ra as usize].push((rb, w));
                    rows[rb as usize].push((ra, w));
                }
                (true, false) => pin_column.push((ra, w)),
                (false, true) => pin_column.push((rb, w)),
                (false, false) => {}
            }
        }
        let matrix = SparseColMat::<usize, f64>::try_new_from_triplets(m, m, &triplets)
            .map_err(|e| Error::input(format!("cannot assemble the blend Laplacian: {e:?}")))?;
        let symbolic = SymbolicLlt::try_new(matrix.symbolic(), Side::Lower)
            .map_err(|e| Error::input(format!("cannot analyse the blend Laplacian: {e:?}")))?;
        let llt =
            Llt::try_new_with_symbolic(symbolic, matrix.as_ref(), Side::Lower).map_err(|e| {
                Error::input(format!(
                    "the blend Laplacian is not positive definite ({e:?}): is the mesh connected?"
                ))
            })?;
        let mut row_start = Vec::with_capacity(m + 1);
        let mut row_entries = Vec::new();
        for r in rows {
            row_start.push(row_entries.len());
            row_entries.extend(r);
        }
        row_start.push(row_entries.len());
        Ok(Self {
            vertex_count: n,
            pinned,
            reduced,
            region_edges,
            anchors,
            llt,
            row_start,
            row_entries,
            pin_column,
        })
    }

    /// The pinned vertex.
    pub fn pinned_vertex(&self) -> u32 {
        self.pinned
    }

    /// The anchor edges in use.
    pub fn anchors(&self) -> &[Anchor] {
        &self.anchors
    }

    /// Number of vertices of the topology.
    pub fn vertex_count(&self) -> usize {
        self.vertex_count
    }

    /// Mᵀd restricted to one region's edges of one mesh: the right-hand side that
    /// region contributes with weight 1 (precomputed per source and region).
    pub fn region_rhs(&self, region: Region, mesh: &[Vec3]) -> SparseRhs {
        let mut acc: Vec<(u32, DVec3)> =
            Vec::with_capacity(self.region_edges[region.index()].len() * 2);
        for &(i, j) in &self.region_edges[region.index()] {
            let d = (mesh[j as usize] - mesh[i as usize]).as_dvec3();
            acc.push((j, d));
            acc.push((i, -d));
        }
        acc.sort_unstable_by_key(|(v, _)| *v);
        let mut merged: SparseRhs = Vec::with_capacity(acc.len() / 3);
        for (v, d) in acc {
            match merged.last_mut() {
                Some((last, sum)) if *last == v => *sum += d,
                _ => merged.push((v, d)),
            }
        }
        merged
    }

    /// Mᵀd for meshes given per source, with per-region weights
    /// (`weights[region][source]`); sources whose mesh is `None` must have zero weight.
    pub fn rhs_from_meshes(&self, weights: &[&[f64]], meshes: &[Option<&[Vec3]>]) -> Vec<DVec3> {
        let mut b = vec![DVec3::ZERO; self.vertex_count];
        for (r, edges) in self.region_edges.iter().enumerate() {
            let active: Vec<(f64, &[Vec3])> = weights[r]
                .iter()
                .zip(meshes)
                .filter(|(w, _)| **w > 0.0)
                .map(|(w, m)| (*w, m.expect("mesh for a weighted source")))
                .collect();
            for &(i, j) in edges {
                let d = active
                    .iter()
                    .map(|(w, m)| *w * (m[j as usize] - m[i as usize]).as_dvec3())
                    .sum::<DVec3>();
                b[j as usize] += d;
                b[i as usize] -= d;
            }
        }
        b
    }

    /// Solves for the blended vertices given the full right-hand side Mᵀd and the
    /// position of the pinned vertex.
    pub fn solve(&self, rhs: &[DVec3], pinned_position: DVec3) -> BlendSolution {
        let m = self.vertex_count - 1;
        let mut b = Mat::<f64>::zeros(m, 3);
        for (v, value) in rhs.iter().enumerate() {
            let r = self.reduced[v];
            if r != u32::MAX {
                for c in 0..3 {
                    b[(r as usize, c)] = value[c];
                }
            }
        }
        for &(r, w) in &self.pin_column {
            for c in 0..3 {
                b[(r as usize, c)] -= w * pinned_position[c];
            }
        }
        let mut x = b.clone();
        self.llt.solve_in_place(x.as_mut());
        let residual = self.residual(&x, &b);
        let mut vertices = vec![pinned_position; self.vertex_count];
        for (v, out) in vertices.iter_mut().enumerate() {
            let r = self.reduced[v];
            if r != u32::MAX {
                *out = DVec3::new(x[(r as usize, 0)], x[(r as usize, 1)], x[(r as usize, 2)]);
            }
        }
        BlendSolution { vertices, residual }
    }

    fn residual(&self, x: &Mat<f64>, b: &Mat<f64>) -> f64 {
        (0..3)
            .map(|c| {
                let (mut err, mut norm) = (0.0f64, 0.0f64);
                for row in 0..self.row_start.len() - 1 {
                    let lx: f64 = self.row_entries[self.row_start[row]..self.row_start[row + 1]]
                        .iter()
                        .map(|&(col, w)| w * x[(col as usize, c)])
                        .sum();
                    err += (lx - b[(row, c)]).powi(2);
                    norm += b[(row, c)].powi(2);
                }
                if norm > 0.0 {
                    (err / norm).sqrt()
                } else {
                    err.sqrt()
                }
            })
            .fold(0.0, f64::max)
    }
}

/// Fails when the edge graph (triangle and anchor edges) has more than one part.
fn check_connected(model: &HeadModel, region_edges: &[Vec<(u32, u32)>]) -> Result<()> {
    let n = model.vertex_count();
    let mut uf = UnionFind::new(n);
    for edges in region_edges {
        for &(i, j) in edges {
            uf.union(i, j);
        }
    }
    let root = uf.find(0);
    let mut stray: Vec<u32> = (0..n as u32).filter(|&v| uf.find(v) != root).collect();
    if stray.is_empty() {
        return Ok(());
    }
    // Report the region of the smaller side so the message names the loose part.
    let main_size = n - stray.len();
    if stray.len() > main_size {
        stray = (0..n as u32).filter(|&v| uf.find(v) == root).collect();
    }
    let mut region = None;
    for (t, r) in model.triangles.iter().zip(&model.triangle_regions) {
        if t.iter().any(|v| stray.binary_search(v).is_ok()) {
            region = Some(*r);
            break;
        }
    }
    Err(Error::input(match region {
        Some(r) => format!(
            "cannot blend shapes: {} vertices of region {} are not connected to the rest of the mesh and have no anchor edge; shape blending would let them drift",
            stray.len(),
            r.name()
        ),
        None => format!(
            "cannot blend shapes: {} vertices belong to no triangle (first: {}); remove unused vertices",
            stray.len(),
            stray[0]
        ),
    }))
}
