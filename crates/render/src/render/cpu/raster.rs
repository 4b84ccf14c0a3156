//! Front-to-back blending of one tile's splats. Each splat touches only the
//! pixels whose centres lie both in its square footprint (the reference's
//! rule) and in the ellipse where α = o·e^power reaches 1/255: a row at a time,
//! the ellipse's span is solved for, so sub-pixel splats visit the handful of
//! pixels they reach rather than their whole square; long spans are blended
//! eight pixels at a time in lanes, bit for bit as one by one. The
//! exponential is a short polynomial accurate to an f32 step or two
//! (`fastmath.rs`). Splats are read through the tile's list of indices and
//! fetched a few entries ahead: copying them into list order first cost a
//! pass over every entry and a second array as large as the splats, and
//! most entries are then skipped (all their pixels saturated).

use crate::render::image::quantize;
use crate::render::projection::{MAX_ALPHA, MIN_ALPHA};

use super::fastmath::{ceil, exp_nonpositive, exp_nonpositive_lanes, floor};
use super::lanes::Lanes;
use super::prefetch::prefetch;
use super::project::Splat;
use crate::render::tiles::entry_gaussian;

/// Tile edge of the CPU rasteriser.
pub const CPU_TILE: u32 = 16;

/// Pixels of one tile.
pub(super) const TILE_PIXELS: usize = (CPU_TILE * CPU_TILE) as usize;

/// Pixels blended together: a tile row is two lane groups.
const LANES: usize = 8;

/// Spans of at least this many pixels are blended a lane group at a time;
/// shorter ones (most splats of a million-Gaussian scene reach one or two
/// pixels of a row) a pixel at a time, which costs less there. Measured
/// (`visage bench render`): 3 slowed small images by 12 %, 8 gave back half
/// of what 5 gains at 640×480.
const LANE_SPAN: u32 = 5;

/// Rows of a splat's box at least this many pixels wide have their span
/// inside the ellipse solved for; narrower ones test each pixel.
const SOLVED_SPAN: u32 = 4;

/// How many entries ahead of the blend a tile's splats are fetched
/// (measured at 1M, 200×120: 8 saved 6 ms of the blend's 46, 16 saved 7;
/// once the blend grew cheaper per entry, 32 took it from 16.0 to 14.3 ms
/// against 16 and 19.5 ms for 8, with 64 no better).
const PREFETCH_AHEAD: usize = 32;

/// The running state of a tile's pixels.
struct TileState {
    /// Accumulated colour, one plane per channel (so eight pixels of a row
    /// load as one lane group).
    colour: [[f32; TILE_PIXELS]; 3],
    transmittance: [f32; TILE_PIXELS],
    /// Saturated pixels, one bit a pixel, a word a row.
    done: [u16; CPU_TILE as usize],
    /// Pixels of the tile inside the image that are not saturated.
    remaining: u32,
}

/// One tile to blend.
pub(super) struct Tile<'a> {
    /// Its top-left pixel.
    pub origin: (u32, u32),
    /// The image's size.
    pub size: (u32, u32),
    /// Its list's entries, front to back (see `tiles::entry_gaussian`).
    pub list: &'a [u64],
    /// Every splat of the frame.
    pub splats: &'a [Splat],
    /// Colour behind everything.
    pub background: [f32; 3],
    /// A pixel is saturated once its transmittance would fall below this.
    pub early_stop: f32,
}

/// Blends one tile's splats (the Gaussians of its list's entries, front to
/// back); returns its pixels, row-major (CPU_TILE wide). Long rows are
/// blended in lanes `L` (see `lanes.rs`); inlined whole into each caller, so
/// the one compiled for AVX2 compiles all of it so.
#[inline(always)]
pub(super) fn blend_tile<L: Lanes>(tile: &Tile) -> [[u8; 3]; TILE_PIXELS] {
    let Tile {
        origin,
        size,
        list,
        splats,
        background,
        early_stop,
    } = *tile;
    let w = (size.0 - origin.0).min(CPU_TILE);
    let h = (size.1 - origin.1).min(CPU_TILE);
    let mut state = TileState {
        colour: [[0.0; TILE_PIXELS]; 3],
        transmittance: [1.0; TILE_PIXELS],
        done: [0; CPU_TILE as usize],
        remaining: w * h,
    };
    let origin_f = (origin.0 as f32, origin.1 as f32);
    for (k, &entry) in list.iter().enumerate() {
        if let Some(&ahead) = list.get(k + PREFETCH_AHEAD) {
            prefetch(&splats[entry_gaussian(ahead) as usize]);
        }
        blend_splat::<L>(
            &mut state,
            &splats[entry_gaussian(entry) as usize],
            origin_f,
            (w, h),
            early_stop,
        );
        if state.remaining == 0 {
            break;
        }
    }
    let mut out = [[0u8; 3]; TILE_PIXELS];
    for ly in 0..h {
        for lx in 0..w {
            let p = (ly * CPU_TILE + lx) as usize;
            out[p] = std::array::from_fn(|ch| {
                quantize(state.colour[ch][p] + state.transmittance[p] * background[ch])
            });
        }
    }
    out
}

/// Blends one splat into the tile at `origin` (of `w × h` pixels inside the image).
#[inline(always)]
fn blend_splat<L: Lanes>(
    state: &mut TileState,
    s: &Splat,
    origin: (f32, f32),
    (w, h): (u32, u32),
    early_stop: f32,
) {
    let (ox, oy) = origin;
    // The footprint's pixels in this tile.
    let local = |lo: u16, hi: u16, from: f32, size: u32| {
        let from = from as i32;
        let lo = (i32::from(lo) - from).max(0);
        let hi = (i32::from(hi) - from).min(size as i32 - 1);
        (lo <= hi).then_some((lo as u32, hi as u32))
    };
    let [rx0, ry0, rx1, ry1] = s.rect;
    let (Some((x0, x1)), Some((y0, y1))) = (local(rx0, rx1, ox, w), local(ry0, ry1, oy, h)) else {
        return;
    };
    let row_mask = (((1u32 << (x1 - x0 + 1)) - 1) << x0) as u16;
    if (y0..=y1).all(|ly| state.done[ly as usize] & row_mask == row_mask) {
        return;
    }
    let [a, b, c] = s.conic;
    // power ≥ cutoff ⇔ a·dx² + 2b·dx·dy + c·dy² ≤ 2·reach.
    let reach2 = -2.0 * s.cutoff;
    for ly in y0..=y1 {
        if state.done[ly as usize] & row_mask == row_mask {
            continue;
        }
        let dy = oy + ly as f32 + 0.5 - s.y;
        let span = if x1 - x0 < SOLVED_SPAN {
            // A pixel or two: testing each costs less than solving.
            (x0, x1)
        } else {
            let disc = b * b * dy * dy - a * (c * dy * dy - reach2);
            if disc < 0.0 {
                continue;
            }
            let root = disc.sqrt();
            // Pixel centres ox + lx + 0.5 with dx in [(−b·dy − root)/a, (−b·dy + root)/a],
            // widened a little so rounding never drops a pixel that counts.
            let margin = 1e-3 * (1.0 + root * s.inv_a);
            let lo = (-b * dy - root) * s.inv_a - margin + s.x - ox - 0.5;
            let hi = (-b * dy + root) * s.inv_a + margin + s.x - ox - 0.5;
            let span0 = ceil(lo).max(x0 as f32) as u32;
            let span1 = floor(hi).min(x1 as f32);
            if span1 < span0 as f32 {
                continue;
            }
            (span0, span1 as u32)
        };
        let row = Row {
            ly,
            span,
            q0: -0.5 * c * dy * dy,
            q1: -b * dy,
            ox,
        };
        if row.span.1 - row.span.0 + 1 >= LANE_SPAN {
            blend_row_lanes::<L>(state, s, &row, early_stop);
        } else {
            blend_row(state, s, &row, early_stop);
        }
    }
}

/// One row of a splat's span in a tile, with the row's terms of the
/// exponent: power(dx) = q0 + dx·(q1 − a·dx/2).
struct Row {
    ly: u32,
    /// First and last pixel of the span (inclusive).
    span: (u32, u32),
    q0: f32,
    q1: f32,
    /// The tile's left edge in pixels.
    ox: f32,
}

/// Blends a row's span a pixel at a time.
#[inline(always)]
fn blend_row(state: &mut TileState, s: &Splat, row: &Row, early_stop: f32) {
    let a = s.conic[0];
    let done = &mut state.done[row.ly as usize];
    for lx in row.span.0..=row.span.1 {
        if *done & (1 << lx) != 0 {
            continue;
        }
        let dx = row.ox + lx as f32 + 0.5 - s.x;
        let power = row.q0 + dx * (row.q1 - 0.5 * a * dx);
        if power > 0.0 || power < s.cutoff {
            continue;
        }
        let alpha = (s.opacity * exp_nonpositive(power)).min(MAX_ALPHA as f32);
        if alpha < MIN_ALPHA as f32 {
            continue;
        }
        let p = (row.ly * CPU_TILE + lx) as usize;
        let t = state.transmittance[p];
        let next = t * (1.0 - alpha);
        if next < early_stop {
            *done |= 1 << lx;
            state.remaining -= 1;
            continue;
        }
        let weight = alpha * t;
        for (plane, rgb) in state.colour.iter_mut().zip(s.rgb) {
            plane[p] += rgb * weight;
        }
        state.transmittance[p] = next;
    }
}

/// Blends a row's span eight pixels at a time with exactly the pixel loop's
/// arithmetic: lane masks stand in for its `continue`s, so every pixel gets
/// the bits it would get alone.
#[inline(always)]
fn blend_row_lanes<L: Lanes>(state: &mut TileState, s: &Splat, row: &Row, early_stop: f32) {
    let c = L::splat;
    let half_a = c(0.5 * s.conic[0]);
    let span_bits = (u32::MAX >> (31 - row.span.1)) & !((1u32 << row.span.0) - 1);
    for group in row.span.0 as usize / LANES..=row.span.1 as usize / LANES {
        let base = group * LANES;
        let done = &mut state.done[row.ly as usize];
        let candidates = ((span_bits & !u32::from(*done)) >> base) & 0xFF;
        if candidates == 0 {
            continue;
        }
        let columns = L::new(std::array::from_fn(|i| (base + i) as f32));
        let dx = c(row.ox) + columns + c(0.5) - c(s.x);
        let power = c(row.q0) + dx * (c(row.q1) - half_a * dx);
        let alpha = (c(s.opacity) * exp_nonpositive_lanes(power)).min(c(MAX_ALPHA as f32));
        let counts =
            power.simd_le(c(0.0)) & power.simd_ge(c(s.cutoff)) & alpha.simd_ge(c(MIN_ALPHA as f32));
        let active = candidates & counts.to_bitmask();
        if active == 0 {
            continue;
        }
        let p = row.ly as usize * CPU_TILE as usize + base;
        let t: L = load(&state.transmittance, p);
        let next = t * (c(1.0) - alpha);
        let saturated = active & next.simd_lt(c(early_stop)).to_bitmask();
        *done |= (saturated << base) as u16;
        state.remaining -= saturated.count_ones();
        let blend = L::lane_mask(active & !saturated);
        let weight = alpha * t;
        for (plane, rgb) in state.colour.iter_mut().zip(s.rgb) {
            let old = load(plane, p);
            store(plane, p, blend.bitselect(old + c(rgb) * weight, old));
        }
        store(&mut state.transmittance, p, blend.bitselect(next, t));
    }
}

/// Eight pixels' values from `p` on.
#[inline(always)]
fn load<L: Lanes>(plane: &[f32; TILE_PIXELS], p: usize) -> L {
    let lanes: [f32; LANES] = plane[p..p + LANES].try_into().expect("eight lanes");
    L::new(lanes)
}

/// Writes eight pixels' values from `p` on.
#[inline(always)]
fn store<L: Lanes>(plane: &mut [f32; TILE_PIXELS], p: usize, values: L) {
    plane[p..p + LANES].copy_from_slice(&values.to_array());
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    use super::*;

    fn empty_state() -> TileState {
        TileState {
            colour: [[0.0; TILE_PIXELS]; 3],
            transmittance: [1.0; TILE_PIXELS],
            done: [0; CPU_TILE as usize],
            remaining: TILE_PIXELS as u32,
        }
    }

    /// [`blend_row_lanes`] in AVX lanes.
    ///
    /// # Safety
    /// The processor must have AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2")]
    unsafe fn blend_row_lanes_avx2(state: &mut TileState, s: &Splat, row: &Row, early_stop: f32) {
        blend_row_lanes::<crate::render::cpu::lanes::Avx>(state, s, row, early_stop);
    }

    /// A row blended eight pixels at a time (in `wide`'s lanes and, where
    /// the processor has AVX2, in AVX ones) leaves exactly the bits the
    /// pixel loop leaves: colours, transmittance, saturation and the count of
    /// pixels left, over random splats (opaque ones included, so pixels
    /// saturate part-way) and spans that start and end anywhere in the row.
    #[test]
    fn lanes_blend_a_row_bit_for_bit_as_the_pixel_loop() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut one, mut eight, mut avx) = (empty_state(), empty_state(), empty_state());
        for _ in 0..4_000 {
            let opacity = if rng.random_bool(0.3) {
                0.99
            } else {
                rng.random_range(0.01..0.9)
            };
            let a = rng.random_range(0.01f32..2.0);
            let s = Splat {
                x: rng.random_range(14.0..34.0),
                y: 0.0,
                conic: [a, 0.0, 1.0],
                inv_a: 1.0 / a,
                opacity,
                cutoff: -(255.0 * opacity).ln() - 1e-6,
                rgb: [rng.random(), rng.random(), rng.random()],
                rect: [0; 4],
            };
            let first = rng.random_range(0..16u32);
            let row = Row {
                ly: rng.random_range(0..16),
                span: (first, rng.random_range(first..16)),
                q0: -rng.random_range(0.0f32..3.0),
                q1: rng.random_range(-1.0..1.0),
                ox: 16.0,
            };
            blend_row(&mut one, &s, &row, 1e-4);
            blend_row_lanes::<wide::f32x8>(&mut eight, &s, &row, 1e-4);
            #[cfg(target_arch = "x86_64")]
            if std::is_x86_feature_detected!("avx2") {
                // SAFETY: the processor has AVX2 (just checked).
                unsafe { blend_row_lanes_avx2(&mut avx, &s, &row, 1e-4) };
            }
        }
        let bits = |plane: &[f32; TILE_PIXELS]| plane.map(f32::to_bits);
        for (a, b) in one.colour.iter().zip(&eight.colour) {
            assert_eq!(bits(a), bits(b));
        }
        assert_eq!(bits(&one.transmittance), bits(&eight.transmittance));
        assert_eq!(one.done, eight.done);
        assert_eq!(one.remaining, eight.remaining);
        assert!(
            one.remaining < TILE_PIXELS as u32,
            "nothing saturated: the test proves less"
        );
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            for (a, b) in one.colour.iter().zip(&avx.colour) {
                assert_eq!(bits(a), bits(b), "AVX lanes");
            }
            assert_eq!(bits(&one.transmittance), bits(&avx.transmittance));
            assert_eq!((one.done, one.remaining), (avx.done, avx.remaining));
        }
    }
}
