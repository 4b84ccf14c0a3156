//! Depth sorting and tile binning shared by the GPU and CPU renderers: a stable
//! LSD radix sort on the f32 depth bits (positive floats order like their bits;
//! ties keep index order, so results are deterministic), then per-tile lists of
//! Gaussian indices in front-to-back order.

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
    temp: Vec<u32>,
    counts: Vec<u32>,
    /// Gaussian indices, each tile's run front to back.
    pub list: Vec<u32>,
    /// Per tile: start and end in `list`.
    pub ranges: Vec<[u32; 2]>,
}

impl TileBins {
    /// Sorts the visible Gaussians of `keys` by depth (on the top `sort_bits` bits,
    /// 8-32) and lists them per tile of a `tiles.0 × tiles.1` grid.
    pub fn bin(&mut self, keys: &[TileKey], tiles: (u32, u32), sort_bits: u8) {
        self.order.clear();
        self.order.extend(
            keys.iter()
                .enumerate()
                .filter(|(_, k)| k[3] != 0)
                .map(|(i, _)| i as u32),
        );
        radix_sort_by_depth(&mut self.order, &mut self.temp, keys, sort_bits);
        let tile_count = (tiles.0 * tiles.1) as usize;
        self.counts.clear();
        self.counts.resize(tile_count + 1, 0);
        let rect = |k: &TileKey| {
            (
                k[1] & 0xffff,
                k[1] >> 16,
                (k[2] & 0xffff).min(tiles.0 - 1),
                (k[2] >> 16).min(tiles.1 - 1),
            )
        };
        for &i in &self.order {
            let (x0, y0, x1, y1) = rect(&keys[i as usize]);
            for ty in y0..=y1 {
                for tx in x0..=x1 {
                    self.counts[(ty * tiles.0 + tx) as usize + 1] += 1;
                }
            }
        }
        for t in 0..tile_count {
            self.counts[t + 1] += self.counts[t];
        }
        self.ranges.clear();
        self.ranges
            .extend((0..tile_count).map(|t| [self.counts[t], self.counts[t + 1]]));
        self.list.clear();
        self.list.resize(self.counts[tile_count] as usize, 0);
        for &i in &self.order {
            let (x0, y0, x1, y1) = rect(&keys[i as usize]);
            for ty in y0..=y1 {
                for tx in x0..=x1 {
                    let t = (ty * tiles.0 + tx) as usize;
                    self.list[self.counts[t] as usize] = i;
                    self.counts[t] += 1;
                }
            }
        }
    }

    /// The front-to-back Gaussians of tile `t`.
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.list[self.ranges[t][0] as usize..self.ranges[t][1] as usize]
    }
}

/// Stable LSD radix sort of `order` by depth bits; only the top `bits` bits of the
/// key are sorted on (fewer passes, coarser order).
fn radix_sort_by_depth(order: &mut Vec<u32>, temp: &mut Vec<u32>, keys: &[TileKey], bits: u8) {
    temp.clear();
    temp.resize(order.len(), 0);
    let passes = (bits.clamp(8, 32) as u32).div_ceil(8);
    for pass in (4 - passes)..4 {
        let shift = pass * 8;
        let mut counts = [0usize; 257];
        for &i in order.iter() {
            counts[((keys[i as usize][0] >> shift) & 0xff) as usize + 1] += 1;
        }
        if counts.contains(&order.len()) {
            continue; // every key has the same byte here
        }
        for b in 0..256 {
            counts[b + 1] += counts[b];
        }
        for &i in order.iter() {
            let b = ((keys[i as usize][0] >> shift) & 0xff) as usize;
            temp[counts[b]] = i;
            counts[b] += 1;
        }
        std::mem::swap(order, temp);
    }
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
