//! Lookup tables for selecting Gaussians (thesis ch. 5, docs/method.md §5): per source
//! and region, the indices of the Gaussians bound to that region's triangles, and
//! per source and triangle (for border smoothing). Built once per database.

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

    /// The items of row `r`.
    pub fn row(&self, r: usize) -> &[u32] {
        &self.items[self.start[r] as usize..self.start[r + 1] as usize]
    }
}

/// Per-source lookup tables.
#[derive(Clone, Debug)]
pub struct SelectionTables {
    /// `[source]` → rows by region of Gaussian indices.
    by_region: Vec<Csr>,
    /// `[source]` → rows by triangle of Gaussian indices.
    by_triangle: Vec<Csr>,
}

impl SelectionTables {
    /// Indexes every source of the database.
    pub fn new(db: &Database) -> Self {
        let regions = &db.model.triangle_regions;
        let triangles = db.model.triangle_count();
        let by_region = db
            .sources
            .iter()
            .map(|s| {
                let pairs = s
                    .gaussians
                    .binding
                    .iter()
                    .enumerate()
                    .map(|(i, &b)| (regions[b as usize].index(), i as u32));
                Csr::from_pairs(Region::COUNT, pairs)
            })
            .collect();
        let by_triangle = db
            .sources
            .iter()
            .map(|s| {
                let pairs = s
                    .gaussians
                    .binding
                    .iter()
                    .enumerate()
                    .map(|(i, &b)| (b as usize, i as u32));
                Csr::from_pairs(triangles, pairs)
            })
            .collect();
        Self {
            by_region,
            by_triangle,
        }
    }

    /// Gaussians of `source` bound to triangles of `region`.
    pub fn region(&self, source: usize, region: Region) -> &[u32] {
        self.by_region[source].row(region.index())
    }

    /// Gaussians of `source` bound to `triangle`.
    pub fn triangle(&self, source: usize, triangle: u32) -> &[u32] {
        self.by_triangle[source].row(triangle as usize)
    }
}

#[cfg(test)]
mod tests {
    use super::Csr;

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
