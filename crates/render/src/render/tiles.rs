//! Depth sorting and tile binning shared by the GPU and CPU renderers (the
//! GPU builds the same lists with its own kernels; this is the CPU version and
//! the GPU's reference). Each visible Gaussian is listed in every tile its
//! footprint touches, in index order, and each tile's list is then sorted by
//! the f32 depth bits (positive floats order like their bits) with a stable
//! radix sort: ties keep index order, so the lists are the same as a global
//! stable depth sort followed by binning, and deterministic. Sorting per tile
//! keeps each sort inside the cache and lets the tiles sort in parallel.

use rayon::prelude::*;

/// Sort keys of one Gaussian: depth bits, first tile (x | y << 16), last tile,
/// and 1 when visible (0 = culled).
pub type TileKey = [u32; 4];

/// Packs a tile coordinate pair.
pub fn pack_tile(x: u32, y: u32) -> u32 {
    x | (y << 16)
}

/// Reusable buffers of the tile lists.
#[derive(Default, Debug)]
pub struct TileBins {
    /// Each tile's run front to back: per entry, the depth bits (the sort
    /// key) above the Gaussian's index ([`entry_gaussian`]). One array of
    /// pairs rather than two of halves: every write and move of the binning
    /// and the sort is then one, not two.
    pub list: Vec<u64>,
    /// Per tile: start and end in `list`.
    pub ranges: Vec<[u32; 2]>,
}

impl TileBins {
    /// Lists the visible Gaussians of `keys` per tile of a `tiles.0 × tiles.1`
    /// grid, each tile's list sorted by depth on the top `sort_bits` bits
    /// (8-32, rounded up to whole bytes as the GPU's radix passes do), ties in
    /// index order. Parallel, and the same lists as a serial stable sort and
    /// binning.
    pub fn bin(&mut self, keys: &[TileKey], tiles: (u32, u32), sort_bits: u8) {
        let bits = u32::from(sort_bits.clamp(8, 32)).div_ceil(8) * 8;
        let mask = if bits == 32 {
            u32::MAX
        } else {
            !(u32::MAX >> bits)
        };
        let tile_count = (tiles.0 * tiles.1) as usize;
        let rect = |k: &TileKey| {
            (
                k[1] & 0xffff,
                k[1] >> 16,
                (k[2] & 0xffff).min(tiles.0 - 1),
                (k[2] >> 16).min(tiles.1 - 1),
            )
        };
        // Per chunk of the Gaussians, how many entries each tile gets.
        let chunk = keys
            .len()
            .div_ceil(rayon::current_num_threads() * 4)
            .max(4096);
        let chunk_counts: Vec<Vec<u32>> = keys
            .par_chunks(chunk)
            .map(|part| {
                let mut counts = vec![0u32; tile_count];
                for k in part.iter().filter(|k| k[3] != 0) {
                    count_tiles(rect(k), tiles.0, &mut counts);
                }
                counts
            })
            .collect();
        // Each tile's run starts after the tiles before it; within a tile,
        // chunk c writes after chunks 0..c (index order is kept).
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
        let total = next as usize;
        self.list.clear();
        self.list.resize(total, 0);
        let list = SharedSlice(self.list.as_mut_ptr());
        keys.par_chunks(chunk)
            .enumerate()
            .zip(starts.par_iter_mut())
            .for_each(|((c, part), at)| {
                let list = &list;
                for (j, k) in part.iter().enumerate().filter(|(_, k)| k[3] != 0) {
                    let (x0, y0, x1, y1) = rect(k);
                    for ty in y0..=y1 {
                        for tx in x0..=x1 {
                            let slot = &mut at[(ty * tiles.0 + tx) as usize];
                            // SAFETY: the slots of chunk c in tile t are
                            // starts[c][t] .. starts[c][t] + counts[c][t], disjoint
                            // from every other chunk's and tile's and inside
                            // the list, whose length is the total of all counts.
                            unsafe {
                                let depth = u64::from(k[0] & mask) << 32;
                                list.0
                                    .add(*slot as usize)
                                    .write(depth | (c * chunk + j) as u64);
                            }
                            *slot += 1;
                        }
                    }
                }
            });
        self.sort_tiles();
    }

    /// Sorts each tile's run by depth, tiles in parallel.
    fn sort_tiles(&mut self) {
        let mut runs = Vec::with_capacity(self.ranges.len());
        let mut list = &mut self.list[..];
        for &[start, end] in &self.ranges {
            let (run, rest) = std::mem::take(&mut list).split_at_mut((end - start) as usize);
            runs.push(run);
            list = rest;
        }
        runs.into_par_iter()
            .for_each_init(Vec::new, |scratch, run| radix_sort_entries(run, scratch));
    }

    /// The front-to-back entries of tile `t` (see [`entry_gaussian`]).
    pub fn tile(&self, t: usize) -> &[u64] {
        &self.list[self.ranges[t][0] as usize..self.ranges[t][1] as usize]
    }
}

/// Adds one to `counts` (per tile of a grid `columns` wide) for each tile of
/// the inclusive range x0, y0, x1, y1. Ranges of up to two by two tiles are
/// counted without a branch on which tiles (a loop's length, mispredicted
/// for about half the Gaussians of a million-Gaussian frame: the count took
/// 3.1 ms, 1.4 ms without): the top-left tile and its right, lower and
/// lower-right neighbours each get 1 when covered and 0 when not (such a
/// neighbour's index may be the top-left one's).
#[inline]
fn count_tiles((x0, y0, x1, y1): (u32, u32, u32, u32), columns: u32, counts: &mut [u32]) {
    let (dx, dy) = (x1.wrapping_sub(x0), y1.wrapping_sub(y0));
    if dx > 1 || dy > 1 {
        for ty in y0..=y1 {
            for tx in x0..=x1 {
                counts[(ty * columns + tx) as usize] += 1;
            }
        }
        return;
    }
    let t = (y0 * columns + x0) as usize;
    let (right, below) = (dx as usize, (dy * columns) as usize);
    counts[t] += 1;
    counts[t + right] += dx;
    counts[t + below] += dy;
    counts[t + below + right] += dx & dy;
}

/// The Gaussian a tile-list entry lists.
#[inline]
pub fn entry_gaussian(entry: u64) -> u32 {
    entry as u32
}

/// A pointer the binning threads write disjoint slots through.
struct SharedSlice(*mut u64);
// SAFETY: every thread writes only its own slots (see `TileBins::bin`).
unsafe impl Sync for SharedSlice {}

/// Runs this short are sorted by insertion (stable), cheaper than counting.
const INSERTION_MAX: usize = 48;

/// Sorts `entries` by their upper 32 bits (stable), in place: LSD radix
/// passes of one byte, with all four histograms counted in one read and a
/// pass skipped where every entry has the same byte (depths in a narrow
/// range share their high bytes). `scratch` holds the second buffer.
pub fn radix_sort_entries(entries: &mut [u64], scratch: &mut Vec<u64>) {
    let n = entries.len();
    if n <= INSERTION_MAX {
        insertion_sort_entries(entries);
        return;
    }
    let byte_of = |e: u64, byte: usize| ((e >> (32 + 8 * byte)) & 0xff) as usize;
    let mut histograms = [[0u32; 256]; 4];
    for &e in entries.iter() {
        for (byte, h) in histograms.iter_mut().enumerate() {
            h[byte_of(e, byte)] += 1;
        }
    }
    scratch.resize(n, 0);
    // Which buffer holds the data: false = the caller's, true = scratch.
    let mut in_scratch = false;
    for (byte, counts) in histograms.iter().enumerate() {
        if counts.iter().any(|&c| c as usize == n) {
            continue;
        }
        let mut starts = [0u32; 256];
        let mut next = 0;
        for (s, &c) in starts.iter_mut().zip(counts) {
            *s = next;
            next += c;
        }
        let (from, to): (&[u64], &mut [u64]) = if in_scratch {
            (&scratch[..n], &mut *entries)
        } else {
            (&*entries, &mut scratch[..n])
        };
        for &e in from {
            let slot = &mut starts[byte_of(e, byte)];
            to[*slot as usize] = e;
            *slot += 1;
        }
        in_scratch = !in_scratch;
    }
    if in_scratch {
        entries.copy_from_slice(&scratch[..n]);
    }
}

/// Stable insertion sort of `entries` by their upper 32 bits.
fn insertion_sort_entries(entries: &mut [u64]) {
    for i in 1..entries.len() {
        let e = entries[i];
        let mut j = i;
        while j > 0 && entries[j - 1] >> 32 > e >> 32 {
            entries[j] = entries[j - 1];
            j -= 1;
        }
        entries[j] = e;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The Gaussians tile `t` lists, front to back.
    fn gaussians(bins: &TileBins, t: usize) -> Vec<u32> {
        bins.tile(t).iter().map(|&e| entry_gaussian(e)).collect()
    }

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
        assert_eq!(gaussians(&bins, 0), [4, 0, 3, 5]);
        assert_eq!(gaussians(&bins, 1), [1, 0, 5]);
    }

    /// Footprints of one tile, two side by side or stacked, two by two and
    /// larger, inside the grid and clamped to it, culled ones among them:
    /// the lists are those of a serial stable depth sort followed by
    /// listing each Gaussian in every tile of its range.
    #[test]
    fn binning_matches_a_serial_sort_for_every_footprint_shape() {
        let mut state = 11u64;
        let mut next = |below: u32| {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32 % below
        };
        let tiles = (7, 5);
        let keys: Vec<TileKey> = (0..20_000)
            .map(|_| {
                let (x0, y0) = (next(tiles.0), next(tiles.1));
                let reach = [0, 0, 1, 1, 2, 9][next(6) as usize];
                let (x1, y1) = (x0 + next(reach + 1), y0 + next(reach + 1));
                let depth = 1.0 + next(300) as f32 * 0.25;
                let shown = u32::from(next(10) != 0);
                [depth.to_bits(), pack_tile(x0, y0), pack_tile(x1, y1), shown]
            })
            .collect();
        let mut order: Vec<u32> = (0..keys.len() as u32).collect();
        order.sort_by_key(|&i| keys[i as usize][0]);
        let mut want = vec![Vec::new(); (tiles.0 * tiles.1) as usize];
        for &i in &order {
            let k = keys[i as usize];
            if k[3] == 0 {
                continue;
            }
            for ty in k[1] >> 16..=(k[2] >> 16).min(tiles.1 - 1) {
                for tx in k[1] & 0xffff..=(k[2] & 0xffff).min(tiles.0 - 1) {
                    want[(ty * tiles.0 + tx) as usize].push(i);
                }
            }
        }
        let mut bins = TileBins::default();
        bins.bin(&keys, tiles, 32);
        for (t, want) in want.iter().enumerate() {
            assert_eq!(gaussians(&bins, t), *want, "tile {t}");
        }
    }

    /// The radix sort orders like a stable sort by key, for lengths either
    /// side of the insertion cut-off, keys that share high bytes, and ties.
    #[test]
    fn radix_sort_matches_a_stable_sort() {
        let mut state = 7u64;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (state >> 33) as u32
        };
        let mut scratch = Vec::new();
        for (n, spread) in [
            (0, 1),
            (1, 1),
            (40, 7),
            (49, 1000),
            (5000, 50),
            (70_000, u32::MAX),
        ] {
            let keys: Vec<u32> = (0..n).map(|_| 3.0f32.to_bits() + next() % spread).collect();
            let mut want: Vec<(u32, u32)> = keys.iter().copied().zip(0..).collect();
            want.sort_by_key(|p| p.0);
            let mut entries: Vec<u64> = (keys.iter().zip(0u64..))
                .map(|(&k, i)| u64::from(k) << 32 | i)
                .collect();
            radix_sort_entries(&mut entries, &mut scratch);
            let got: Vec<(u32, u32)> = entries
                .iter()
                .map(|&e| ((e >> 32) as u32, entry_gaussian(e)))
                .collect();
            assert_eq!(got, want, "n = {n}");
        }
    }

    #[test]
    fn coarse_keys_still_separate_distant_depths() {
        let keys: Vec<TileKey> = [3.0f32, 1.0, 2.0]
            .iter()
            .map(|d| [d.to_bits(), 0, 0, 1])
            .collect();
        let mut bins = TileBins::default();
        bins.bin(&keys, (1, 1), 16);
        assert_eq!(gaussians(&bins, 0), [1, 2, 0]);
    }
}
