//! Front-to-back blending of one tile's splats. Each splat touches only the
//! pixels whose centres lie both in its square footprint (the reference's
//! rule) and in the ellipse where α = o·e^power reaches 1/255: a row at a time,
//! the ellipse's span is solved for, so sub-pixel splats visit the handful of
//! pixels they reach rather than their whole square. The exponential is a
//! short polynomial accurate to an f32 step or two (`fastmath.rs`).

use crate::render::image::quantize;
use crate::render::projection::{MAX_ALPHA, MIN_ALPHA};

use super::fastmath::{ceil, exp_nonpositive, floor};
use super::project::Splat;

/// Tile edge of the CPU rasteriser.
pub const CPU_TILE: u32 = 16;

/// Pixels of one tile.
pub(super) const TILE_PIXELS: usize = (CPU_TILE * CPU_TILE) as usize;

/// The running state of a tile's pixels.
struct TileState {
    colour: [[f32; 3]; TILE_PIXELS],
    transmittance: [f32; TILE_PIXELS],
    /// Saturated pixels, one bit a pixel, a word a row.
    done: [u16; CPU_TILE as usize],
    /// Pixels of the tile inside the image that are not saturated.
    remaining: u32,
}

/// Blends one tile's splats (front to back); returns its pixels, row-major
/// (CPU_TILE wide).
pub(super) fn blend_tile(
    origin: (u32, u32),
    size: (u32, u32),
    splats: &[Splat],
    background: [f32; 3],
    early_stop: f32,
) -> [[u8; 3]; TILE_PIXELS] {
    let w = (size.0 - origin.0).min(CPU_TILE);
    let h = (size.1 - origin.1).min(CPU_TILE);
    let mut state = TileState {
        colour: [[0.0; 3]; TILE_PIXELS],
        transmittance: [1.0; TILE_PIXELS],
        done: [0; CPU_TILE as usize],
        remaining: w * h,
    };
    let origin_f = (origin.0 as f32, origin.1 as f32);
    for splat in splats {
        blend_splat(&mut state, splat, origin_f, (w, h), early_stop);
        if state.remaining == 0 {
            break;
        }
    }
    let mut out = [[0u8; 3]; TILE_PIXELS];
    for ly in 0..h {
        for lx in 0..w {
            let p = (ly * CPU_TILE + lx) as usize;
            out[p] = std::array::from_fn(|ch| {
                quantize(state.colour[p][ch] + state.transmittance[p] * background[ch])
            });
        }
    }
    out
}

/// Blends one splat into the tile at `origin` (of `w × h` pixels inside the image).
#[inline]
fn blend_splat(
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
        let q0 = -0.5 * c * dy * dy;
        let q1 = -b * dy;
        let done = &mut state.done[ly as usize];
        for lx in span0..=span1 as u32 {
            if *done & (1 << lx) != 0 {
                continue;
            }
            let dx = ox + lx as f32 + 0.5 - s.x;
            let power = q0 + dx * (q1 - 0.5 * a * dx);
            if power > 0.0 || power < s.cutoff {
                continue;
            }
            let alpha = (s.opacity * exp_nonpositive(power)).min(MAX_ALPHA as f32);
            if alpha < MIN_ALPHA as f32 {
                continue;
            }
            let p = (ly * CPU_TILE + lx) as usize;
            let t = state.transmittance[p];
            let next = t * (1.0 - alpha);
            if next < early_stop {
                *done |= 1 << lx;
                state.remaining -= 1;
                continue;
            }
            let weight = alpha * t;
            for (out, rgb) in state.colour[p].iter_mut().zip(s.rgb) {
                *out += rgb * weight;
            }
            state.transmittance[p] = next;
        }
    }
}
