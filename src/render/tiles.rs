//! Depth sorting and tile binning shared by the GPU and CPU renderers: a stable
//! LSD radix sort on the f32 depth bits (positive floats order like their bits;
//! ties keep index order, so results are deterministic), then per-tile lists of
//! Gaussian indices in front-to-back order.

use rayon::prelude::*;

/// Sort keys of one Gaussian: depth bits, first tile (x | y << 16), last tile,
/// and 1 when visible (0 = culled).
pub type TileKey = [u32; 4];

/// Packs a tile coordinate pair.
pub fn pack_tile(x: u32, y: u32) -> u32 {
    x | (y << 16)
}

/// Reusable buffers of the sort and the tile lists.
#[derive(Default, Debug)]
pub struct TileBins {
    /// Visible Gaussians, front to back.
    pub order: Vec<u32>,
    sort_keys: Vec<u64>,
    /// Gaussian indices, each tile's run front to back.
    pub list: Vec<u32>,
    /// Per tile: start and end in `list`.
    pub ranges: Vec<[u32; 2]>,
}

impl TileBins {
    /// Sorts the visible Gaussians of `keys` by depth (on the top `sort_bits` bits,
    /// 8-32) and lists them per tile of a `tiles.0 × tiles.1` grid. Parallel,
    /// and the same lists as a serial stable sort and binning: depth ties keep
    /// index order, and each tile lists its Gaussians front to back.
    pub fn bin(&mut self, keys: &[TileKey], tiles: (u32, u32), sort_bits: u8) {
        sort_by_depth(&mut self.order, &mut self.sort_keys, keys, sort_bits);
        let tile_count = (tiles.0 * tiles.1) as usize;
        let rect = |k: &TileKey| {
            (
                k[1] & 0xffff,
                k[1] >> 16,
                (k[2] & 0xffff).min(tiles.0 - 1),
                (k[2] >> 16).min(tiles.1 - 1),
            )
        };
        // Per chunk of the depth order, how many entries each tile gets.
        let chunk = self
            .order
            .len()
            .div_ceil(rayon::current_num_threads() * 4)
            .max(4096);
        let chunk_counts: Vec<Vec<u32>> = self
            .order
            .par_chunks(chunk)
            .map(|part| {
                let mut counts = vec![0u32; tile_count];
                for &i in part {
                    let (x0, y0, x1, y1) = rect(&keys[i as usize]);
                    for ty in y0..=y1 {
                        for tx in x0..=x1 {
                            counts[(ty * tiles.0 + tx) as usize] += 1;
                        }
                    }
                }
                counts
            })
            .collect();
        // Each tile's run starts after the tiles before it; within a tile,
        // chunk c writes after chunks 0..c (depth order is kept).
        self.ranges.clear();
        let mut starts: Vec<Vec<u32>> = vec![vec![0; tile_count]; chunk_counts.len()];
        let mut next = 0u32;
        for t in 0..tile_count {
            let first = next;
            for (c, counts) in chunk_counts.iter().enumerate() {
                starts[c][t] = next;
                next += counts[t];
            }
            self.ranges.push([first, next]);
        }
        self.list.clear();
        self.list.resize(next as usize, 0);
        let list = SharedSlice(self.list.as_mut_ptr());
        self.order
            .par_chunks(chunk)
            .zip(starts.par_iter_mut())
            .for_each(|(part, at)| {
                let list = &list;
                for &i in part {
                    let (x0, y0, x1, y1) = rect(&keys[i as usize]);
                    for ty in y0..=y1 {
                        for tx in x0..=x1 {
                            let slot = &mut at[(ty * tiles.0 + tx) as usize];
                            // SAFETY: the slots of chunk c in tile t are
                            // starts[c][t] .. starts[c][t] + counts[c][t], disjoint
                            // from every other chunk's and tile's and inside
                            // `list`, whose length is the total of all counts.
                            unsafe { list.0.add(*slot as usize).write(i) };
                            *slot += 1;
                        }
                    }
                }
            });
    }

    /// The front-to-back Gaussians of tile `t`.
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.list[self.ranges[t][0] as usize..self.ranges[t][1] as usize]
    }
}

/// A pointer the binning threads write disjoint slots through.
struct SharedSlice(*mut u32);
// SAFETY: every thread writes only its own slots (see `TileBins::bin`).
unsafe impl Sync for SharedSlice {}

/// The visible Gaussians (`keys[i][3] != 0`) in depth order on the top `bits`
/// bits (8-32, rounded up to whole bytes as the GPU's radix passes do), ties in
/// index order: a parallel sort of (depth, index) pairs, which orders exactly
/// as a stable sort by depth does.
fn sort_by_depth(order: &mut Vec<u32>, pairs: &mut Vec<u64>, keys: &[TileKey], bits: u8) {
    let bits = u32::from(bits.clamp(8, 32)).div_ceil(8) * 8;
    let mask = if bits == 32 {
        u32::MAX
    } else {
        !(u32::MAX >> bits)
    };
    pairs.clear();
    pairs.par_extend(
        keys.par_iter()
            .enumerate()
            .filter(|(_, k)| k[3] != 0)
            .map(|(i, k)| (u64::from(k[0] & mask) << 32) | i as u64),
    );
    pairs.par_sort_unstable();
    order.clear();
    order.par_extend(pairs.par_iter().map(|p| *p as u32));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn binning_orders_by_depth_and_keeps_ties_in_index_order() {
        let key = |depth: f32, x0: u32, y0: u32, x1: u32, y1: u32| {
            [depth.to_bits(), pack_tile(x0, y0), pack_tile(x1, y1), 1]
        };
        let keys = vec![
            key(2.0, 0, 0, 1, 0),
            key(1.0, 1, 0, 1, 0),
            [0, 0, 0, 0], // culled
            key(2.0, 0, 0, 0, 0),
            key(0.5, 0, 0, 0, 0),
            key(300.0, 0, 0, 9, 9), // clamped to the grid
        ];
        let mut bins = TileBins::default();
        bins.bin(&keys, (2, 1), 32);
        assert_eq!(bins.tile(0), &[4, 0, 3, 5]);
        assert_eq!(bins.tile(1), &[1, 0, 5]);
    }

    #[test]
    fn coarse_keys_still_separate_distant_depths() {
        let keys: Vec<TileKey> = [3.0f32, 1.0, 2.0]
            .iter()
            .map(|d| [d.to_bits(), 0, 0, 1])
            .collect();
        let mut bins = TileBins::default();
        bins.bin(&keys, (1, 1), 16);
        assert_eq!(bins.tile(0), &[1, 2, 0]);
    }
}
