//! Lookup tables for selecting Gaussians (thesis ch. 5, docs/method.md §5): per source
//! and region, the indices of the Gaussians counted for that region — by parent
//! triangle (the thesis) or by place (§5.1) — and per source and triangle (for
//! border smoothing). Built once per database.

use glam::Vec3;
use rayon::prelude::*;

use super::membership::place_triangles;
use super::recipe::Membership;
use crate::avatar::database::Database;
use crate::model::regions::Region;

/// Compressed rows: `start[t]..start[t+1]` indexes `items`.
#[derive(Clone, Debug, Default)]
pub struct Csr {
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Csr {
    /// Builds rows from (row, item) pairs; items keep their order within a row.
    pub fn from_pairs(rows: usize, pairs: impl Iterator<Item = (usize, u32)> + Clone) -> Self {
        let mut count = vec![0u32; rows + 1];
        for (r, _) in pairs.clone() {
            count[r + 1] += 1;
        }
        for i in 0..rows {
            count[i + 1] += count[i];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; count[rows] as usize];
        for (r, item) in pairs {
            items[fill[r] as usize] = item;
            fill[r] += 1;
        }
        Self {
            start: count,
            items,
        }
    }

    /// Per vertex (of `vertices`), the triangles that have it as a corner,
    /// in triangle order.
    pub fn vertex_triangles(vertices: usize, triangles: &[[u32; 3]]) -> Self {
        Self::from_pairs(
            vertices,
            triangles
                .iter()
                .enumerate()
                .flat_map(|(t, tri)| tri.map(|v| (v as usize, t as u32))),
        )
    }

    /// The items of row `r`.
    pub fn row(&self, r: usize) -> &[u32] {
        &self.items[self.start[r] as usize..self.start[r + 1] as usize]
    }
}

/// Per triangle of `triangles`: whether it shares a corner with a triangle
/// `marked` says (itself included); `vertex_triangles` is
/// [`Csr::vertex_triangles`] of the same mesh. A corner past the table or a
/// triangle past `marked` counts as unmarked.
pub fn sharing_a_corner(
    triangles: &[[u32; 3]],
    vertex_triangles: &Csr,
    marked: &[bool],
) -> Vec<bool> {
    let touches = |v: u32| {
        (v as usize + 1 < vertex_triangles.start.len())
            && vertex_triangles
                .row(v as usize)
                .iter()
                .any(|&u| marked.get(u as usize).copied().unwrap_or(false))
    };
    triangles
        .iter()
        .map(|corners| corners.iter().any(|&v| touches(v)))
        .collect()
}

/// Per-source lookup tables, for each way of counting a Gaussian for a region.
#[derive(Clone, Debug)]
pub struct SelectionTables {
    /// `[membership][source]` → rows by region of Gaussian indices.
    by_region: [Vec<Csr>; 2],
    /// `[membership][source]` → rows by triangle of Gaussian indices.
    by_triangle: [Vec<Csr>; 2],
    /// `[membership][source][gaussian]` → the triangle it counts for.
    counted: [Vec<Vec<u32>>; 2],
}

impl SelectionTables {
    /// Indexes every source of the database; `neutrals[s]` is source `s`'s
    /// neutral mesh (where its Gaussians' places are found).
    pub fn new(db: &Database, neutrals: &[Vec<Vec3>]) -> Self {
        let regions = &db.model.triangle_regions;
        let triangles = db.model.triangle_count();
        let parents: Vec<Vec<u32>> = db
            .sources
            .iter()
            .map(|s| s.gaussians.binding.clone())
            .collect();
        let places: Vec<Vec<u32>> = db
            .sources
            .par_iter()
            .zip(neutrals)
            .map(|(s, neutral)| place_triangles(&db.model, &s.gaussians, neutral))
            .collect();
        let tables = |of: &[Vec<u32>]| {
            let by_region = (0..db.sources.len())
                .map(|s| {
                    let pairs = of[s]
                        .iter()
                        .enumerate()
                        .map(|(i, &t)| (regions[t as usize].index(), i as u32));
                    Csr::from_pairs(Region::COUNT, pairs)
                })
                .collect();
            let by_triangle = (0..db.sources.len())
                .map(|s| {
                    let pairs = of[s]
                        .iter()
                        .enumerate()
                        .map(|(i, &t)| (t as usize, i as u32));
                    Csr::from_pairs(triangles, pairs)
                })
                .collect();
            (by_region, by_triangle)
        };
        let (parent_region, parent_triangle) = tables(&parents);
        let (place_region, place_triangle) = tables(&places);
        Self {
            by_region: [parent_region, place_region],
            by_triangle: [parent_triangle, place_triangle],
            counted: [parents, places],
        }
    }

    /// Gaussians of `source` counted for `region`.
    pub fn region(&self, membership: Membership, source: usize, region: Region) -> &[u32] {
        self.by_region[membership as usize][source].row(region.index())
    }

    /// The triangle each Gaussian of `source` counts for.
    pub fn counted_triangles(&self, membership: Membership, source: usize) -> &[u32] {
        &self.counted[membership as usize][source]
    }

    /// Gaussians of `source` counted for `triangle` (bound to it, or placed on it).
    pub fn triangle(&self, membership: Membership, source: usize, triangle: u32) -> &[u32] {
        self.by_triangle[membership as usize][source].row(triangle as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::{sharing_a_corner, Csr};

    #[test]
    fn triangles_sharing_a_corner_with_a_marked_one_include_it_and_its_fan() {
        // A strip 0-1-2-3 of triangles, each sharing an edge with the next,
        // and a fifth triangle off on its own; the table knows those five,
        // and a sixth asked about has a corner past it.
        let triangles = [
            [0, 1, 2],
            [1, 2, 3],
            [2, 3, 4],
            [3, 4, 5],
            [6, 7, 8],
            [0, 9, 99],
        ];
        let table = Csr::vertex_triangles(10, &triangles[..5]);
        let marked = [true, false, false, false, false, false];
        assert_eq!(
            sharing_a_corner(&triangles, &table, &marked),
            [true, true, true, false, false, true]
        );
        assert_eq!(sharing_a_corner(&triangles, &table, &[]), [false; 6]);
    }

    #[test]
    fn csr_groups_items_by_row_in_order() {
        let pairs = [(2usize, 10u32), (0, 11), (2, 12), (1, 13)];
        let csr = Csr::from_pairs(4, pairs.iter().copied());
        assert_eq!(csr.row(0), &[11]);
        assert_eq!(csr.row(1), &[13]);
        assert_eq!(csr.row(2), &[10, 12]);
        assert!(csr.row(3).is_empty());
    }
}
