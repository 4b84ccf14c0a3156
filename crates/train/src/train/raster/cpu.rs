//! The tile rasteriser, forward and backward, in f64: the renderers' rules
//! (`render::projection`: a splat covers the pixel centres inside its square
//! footprint; α = min(0.99, o·exp(power)), skipped when power > 0 or α < 1/255;
//! front to back in depth order; a pixel stops before the splat that would take
//! its transmittance below 1e-4). The backward pass walks each pixel's splats
//! back to front, rebuilding the transmittance by division as 3DGS does, and
//! returns ∂loss/∂(centre, conic, opacity, colour) per splat. Tiles run in
//! parallel and their gradients are summed in a fixed order, so training is
//! deterministic.

use rayon::prelude::*;

use super::splat::{bin, pixel_rect, Backdrop, Rasterized, Splat, SplatGrad, TILE};
use crate::render::projection::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};

/// The splat's α at a pixel centre and, when it contributes and is not
/// clamped, e^power (∂α/∂opacity); None when it does not contribute.
fn alpha_at(s: &Splat, px: f64, py: f64) -> Option<(f64, f64, [f64; 2])> {
    let d = [px - s.center[0], py - s.center[1]];
    if d[0].abs() > s.radius || d[1].abs() > s.radius {
        return None;
    }
    let [a, b, c] = s.conic;
    let power = -0.5 * (a * d[0] * d[0] + c * d[1] * d[1]) - b * d[0] * d[1];
    if power > 0.0 {
        return None;
    }
    let gauss = power.exp();
    let alpha = (s.opacity * gauss).min(MAX_ALPHA);
    (alpha >= MIN_ALPHA).then_some((alpha, gauss, d))
}

/// A tile's pixel range: origin and size.
fn tile_bounds(t: usize, size: [u32; 2]) -> ([u32; 2], [u32; 2]) {
    let across = size[0].div_ceil(TILE);
    let origin = [(t as u32 % across) * TILE, (t as u32 / across) * TILE];
    let extent = [
        (size[0] - origin[0]).min(TILE),
        (size[1] - origin[1]).min(TILE),
    ];
    (origin, extent)
}

/// The pixels of `s`'s footprint inside the tile, as tile-local (x, y) ranges.
fn footprint_in_tile(
    s: &Splat,
    size: [u32; 2],
    origin: [u32; 2],
    extent: [u32; 2],
) -> Option<(std::ops::Range<u32>, std::ops::Range<u32>)> {
    let [x0, y0, x1, y1] = pixel_rect(s, size)?;
    let (lx0, ly0) = (x0.max(origin[0]), y0.max(origin[1]));
    let (lx1, ly1) = (
        x1.min(origin[0] + extent[0] - 1),
        y1.min(origin[1] + extent[1] - 1),
    );
    (lx0 <= lx1 && ly0 <= ly1).then(|| {
        (
            lx0 - origin[0]..lx1 - origin[0] + 1,
            ly0 - origin[1]..ly1 - origin[1] + 1,
        )
    })
}

/// One tile's forward result: per pixel colour, final transmittance and
/// entries walked (row-major within the tile).
struct TileForward {
    colour: Vec<[f64; 3]>,
    transmittance: Vec<f64>,
    walked: Vec<u32>,
}

/// Blends one tile front to back, splat by splat over each footprint (the
/// CPU renderer's order; per pixel the result is the same as walking the
/// pixel's list).
fn forward_tile(
    splats: &[Splat],
    list: &[u32],
    size: [u32; 2],
    stop: &[f64],
    t: usize,
) -> TileForward {
    let (origin, extent) = tile_bounds(t, size);
    let n = (extent[0] * extent[1]) as usize;
    let mut out = TileForward {
        colour: vec![[0.0; 3]; n],
        transmittance: vec![1.0; n],
        walked: vec![0; n],
    };
    let mut done = vec![false; n];
    let mut remaining = n;
    for (k, &i) in list.iter().enumerate() {
        let s = &splats[i as usize];
        let Some((xs, ys)) = footprint_in_tile(s, size, origin, extent) else {
            continue;
        };
        for ly in ys {
            let py = (origin[1] + ly) as f64 + 0.5;
            for lx in xs.clone() {
                let p = (ly * extent[0] + lx) as usize;
                if done[p] {
                    continue;
                }
                if s.depth > stop[((origin[1] + ly) * size[0] + origin[0] + lx) as usize] {
                    // Behind the backdrop, as is everything after it.
                    done[p] = true;
                    remaining -= 1;
                    continue;
                }
                let px = (origin[0] + lx) as f64 + 0.5;
                let Some((alpha, _, _)) = alpha_at(s, px, py) else {
                    continue;
                };
                let t_before = out.transmittance[p];
                let next = t_before * (1.0 - alpha);
                if next < MIN_TRANSMITTANCE {
                    done[p] = true;
                    remaining -= 1;
                    continue;
                }
                for (c, rgb) in out.colour[p].iter_mut().zip(s.rgb) {
                    *c += rgb * alpha * t_before;
                }
                out.transmittance[p] = next;
                out.walked[p] = k as u32 + 1;
            }
        }
        if remaining == 0 {
            break;
        }
    }
    out
}

/// Draws the splats over `backdrop`.
pub fn forward(splats: &[Splat], size: [u32; 2], backdrop: &Backdrop) -> Rasterized {
    let lists = bin(splats, size);
    let pixels = (size[0] * size[1]) as usize;
    let mut image = vec![0.0; pixels * 3];
    let mut final_t = vec![1.0; pixels];
    let mut walked = vec![0u32; pixels];
    let tiles: Vec<TileForward> = lists
        .par_iter()
        .enumerate()
        .map(|(t, list)| forward_tile(splats, list, size, &backdrop.stop, t))
        .collect();
    for (t, tile) in tiles.iter().enumerate() {
        let (origin, extent) = tile_bounds(t, size);
        for ly in 0..extent[1] {
            for lx in 0..extent[0] {
                let q = (ly * extent[0] + lx) as usize;
                let p = ((origin[1] + ly) * size[0] + origin[0] + lx) as usize;
                for ch in 0..3 {
                    image[p * 3 + ch] =
                        tile.colour[q][ch] + tile.transmittance[q] * backdrop.colour[p][ch];
                }
                final_t[p] = tile.transmittance[q];
                walked[p] = tile.walked[q];
            }
        }
    }
    Rasterized {
        size,
        image,
        backdrop: backdrop.clone(),
        lists,
        final_t,
        walked,
    }
}

/// ∂loss/∂ every splat, given ∂loss/∂ the image (same layout as `image`).
/// Each tile walks its list back to front, splat by splat over each
/// footprint; a pixel takes part for the entries it walked forward.
pub fn backward(splats: &[Splat], raster: &Rasterized, d_image: &[f64]) -> Vec<SplatGrad> {
    let size = raster.size;
    let per_tile: Vec<Vec<(u32, SplatGrad)>> = raster
        .lists
        .par_iter()
        .enumerate()
        .map(|(t, list)| {
            let (origin, extent) = tile_bounds(t, size);
            let n = (extent[0] * extent[1]) as usize;
            let global = |lx: u32, ly: u32| ((origin[1] + ly) * size[0] + origin[0] + lx) as usize;
            let mut t_after = vec![0.0; n];
            let mut behind = vec![[0.0; 3]; n];
            let mut walked = vec![0u32; n];
            let mut d_colour = vec![[0.0; 3]; n];
            for ly in 0..extent[1] {
                for lx in 0..extent[0] {
                    let (q, p) = ((ly * extent[0] + lx) as usize, global(lx, ly));
                    t_after[q] = raster.final_t[p];
                    walked[q] = raster.walked[p];
                    behind[q] = raster.backdrop.colour[p];
                    d_colour[q] = [d_image[p * 3], d_image[p * 3 + 1], d_image[p * 3 + 2]];
                }
            }
            let mut out = Vec::new();
            for k in (0..list.len()).rev() {
                let s = &splats[list[k] as usize];
                let Some((xs, ys)) = footprint_in_tile(s, size, origin, extent) else {
                    continue;
                };
                let mut g = SplatGrad::default();
                let mut touched = false;
                for ly in ys {
                    let py = (origin[1] + ly) as f64 + 0.5;
                    for lx in xs.clone() {
                        let q = (ly * extent[0] + lx) as usize;
                        if k as u32 >= walked[q] {
                            continue;
                        }
                        let px = (origin[0] + lx) as f64 + 0.5;
                        let Some((alpha, gauss, d)) = alpha_at(s, px, py) else {
                            continue;
                        };
                        touched = true;
                        let dc = d_colour[q];
                        let t_before = t_after[q] / (1.0 - alpha);
                        let mut d_alpha = 0.0;
                        for ch in 0..3 {
                            g.rgb[ch] += dc[ch] * alpha * t_before;
                            d_alpha += dc[ch] * t_before * (s.rgb[ch] - behind[q][ch]);
                        }
                        for (ch, b) in behind[q].iter_mut().enumerate() {
                            *b = s.rgb[ch] * alpha + (1.0 - alpha) * *b;
                        }
                        t_after[q] = t_before;
                        if s.opacity * gauss > MAX_ALPHA {
                            continue; // clamped: α does not move with the splat
                        }
                        // α = o·e^power.
                        g.opacity += d_alpha * gauss;
                        let d_power = d_alpha * alpha;
                        let [a, b, c] = s.conic;
                        g.conic[0] += d_power * -0.5 * d[0] * d[0];
                        g.conic[1] += d_power * -d[0] * d[1];
                        g.conic[2] += d_power * -0.5 * d[1] * d[1];
                        // d = pixel − centre.
                        g.center[0] += d_power * (a * d[0] + b * d[1]);
                        g.center[1] += d_power * (c * d[1] + b * d[0]);
                    }
                }
                if touched {
                    out.push((list[k], g));
                }
            }
            out
        })
        .collect();
    let mut grads = vec![SplatGrad::default(); splats.len()];
    for (i, g) in per_tile.iter().flatten() {
        grads[*i as usize].add(g);
    }
    grads
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::raster::splat::test_layered_backdrop;

    fn scene() -> Vec<Splat> {
        let mut out = Vec::new();
        for i in 0..12 {
            let f = i as f64;
            out.push(Splat {
                center: [6.0 + 2.3 * f % 20.0, 5.0 + 1.7 * (f * 1.3) % 12.0],
                conic: [0.2 + 0.02 * f, 0.03 * (f - 5.0) / 5.0, 0.3 - 0.01 * f],
                opacity: 0.3 + 0.05 * f,
                rgb: [0.2 + 0.05 * f, 0.9 - 0.06 * f, 0.5],
                radius: 7.0,
                depth: 1.0 + (f * 0.37) % 1.0,
            });
        }
        out
    }

    /// The loss Σ w·image for fixed weights: its gradient is w, so the
    /// backward pass is checked against central differences of the forward
    /// — over a uniform background and over a layer that hides some splats.
    #[test]
    fn gradients_match_central_differences() {
        let size = [26, 21];
        for background in [
            Backdrop::uniform(size, [0.1, 0.2, 0.3]),
            test_layered_backdrop(size),
        ] {
            check_gradients(size, &background);
        }
    }

    fn check_gradients(size: [u32; 2], background: &Backdrop) {
        let weights: Vec<f64> = (0..(size[0] * size[1] * 3) as usize)
            .map(|i| ((i * 37) % 17) as f64 / 17.0 - 0.4)
            .collect();
        let loss = |s: &[Splat]| -> f64 {
            forward(s, size, background)
                .image
                .iter()
                .zip(&weights)
                .map(|(a, b)| a * b)
                .sum()
        };
        let splats = scene();
        let grads = backward(&splats, &forward(&splats, size, background), &weights);
        let h = 1e-6;
        let mut worst: f64 = 0.0;
        for i in 0..splats.len() {
            let mut check = |analytic: f64, set: &dyn Fn(&mut Splat, f64)| {
                let mut plus = splats.clone();
                set(&mut plus[i], h);
                let mut minus = splats.clone();
                set(&mut minus[i], -h);
                let numeric = (loss(&plus) - loss(&minus)) / (2.0 * h);
                let error = (analytic - numeric).abs() / numeric.abs().max(1e-3);
                worst = worst.max(error);
                assert!(
                    error < 1e-4,
                    "splat {i}: analytic {analytic} numeric {numeric}"
                );
            };
            let g = grads[i];
            check(g.opacity, &|s, e| s.opacity += e);
            for k in 0..2 {
                check(g.center[k], &|s, e| s.center[k] += e);
            }
            for k in 0..3 {
                check(g.conic[k], &|s, e| s.conic[k] += e);
                check(g.rgb[k], &|s, e| s.rgb[k] += e);
            }
        }
        assert!(worst < 1e-4, "{worst}");
    }
}
