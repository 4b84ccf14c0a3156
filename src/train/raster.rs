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

use super::raster_gpu::GpuRaster;
use crate::error::{Error, Result};
use crate::render::projection::{MAX_ALPHA, MIN_ALPHA, MIN_TRANSMITTANCE};
use crate::render::Backend;

/// Tile edge in pixels (the wgpu kernels' workgroup edge too).
pub(super) const TILE: u32 = crate::render::gpu::TILE;

/// A splat as the rasteriser sees it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Splat {
    /// Centre in pixels.
    pub center: [f64; 2],
    /// Inverse 2D covariance (a, b, c).
    pub conic: [f64; 3],
    /// Opacity in [0, 1].
    pub opacity: f64,
    /// Colour (already clamped at 0).
    pub rgb: [f64; 3],
    /// Footprint half-size in pixels.
    pub radius: f64,
    /// Sort key: distance along the viewing axis.
    pub depth: f64,
}

/// ∂loss/∂ a splat's screen quantities.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplatGrad {
    /// Centre.
    pub center: [f64; 2],
    /// Conic (a, b, c).
    pub conic: [f64; 3],
    /// Opacity.
    pub opacity: f64,
    /// Colour.
    pub rgb: [f64; 3],
}

impl SplatGrad {
    /// Adds another gradient to this one.
    pub(super) fn add(&mut self, o: &SplatGrad) {
        for i in 0..2 {
            self.center[i] += o.center[i];
        }
        for i in 0..3 {
            self.conic[i] += o.conic[i];
            self.rgb[i] += o.rgb[i];
        }
        self.opacity += o.opacity;
    }
}

/// What lies behind the splats, per pixel: a colour and the depth at which
/// it stops the walk (splats deeper than it are hidden). A uniform
/// background stops nothing; the opaque interior layer stops at the head's
/// surface plus a margin (docs/method.md §11.6).
#[derive(Clone, Debug, PartialEq)]
pub struct Backdrop {
    /// Colour per pixel.
    pub colour: Vec<[f64; 3]>,
    /// Depth per pixel beyond which splats are hidden (∞: none).
    pub stop: Vec<f64>,
}

impl Backdrop {
    /// One colour everywhere, hiding nothing.
    pub fn uniform(size: [u32; 2], colour: [f64; 3]) -> Self {
        let n = (size[0] * size[1]) as usize;
        Self {
            colour: vec![colour; n],
            stop: vec![f64::INFINITY; n],
        }
    }
}

/// The forward pass's image and what the backward pass needs.
#[derive(Clone, Debug)]
pub struct Rasterized {
    /// Width and height.
    pub size: [u32; 2],
    /// RGB, row-major, f64 (not clamped or quantised).
    pub image: Vec<f64>,
    /// What lies behind the splats.
    pub backdrop: Backdrop,
    /// Splat indices per tile, front to back.
    pub(super) lists: Vec<Vec<u32>>,
    /// Per pixel: transmittance after its last contributing splat.
    pub(super) final_t: Vec<f64>,
    /// Per pixel: how many entries of its tile's list it walked.
    pub(super) walked: Vec<u32>,
}

impl Rasterized {
    /// A forward result from its parts (the wgpu pass builds one).
    pub(super) fn from_parts(
        size: [u32; 2],
        image: Vec<f64>,
        backdrop: Backdrop,
        lists: Vec<Vec<u32>>,
        final_t: Vec<f64>,
        walked: Vec<u32>,
    ) -> Self {
        Self {
            size,
            image,
            backdrop,
            lists,
            final_t,
            walked,
        }
    }

    /// Pixels whose transmittance ended below 1 %.
    pub fn saturated_pixels(&self) -> usize {
        self.final_t.iter().filter(|&&t| t < 0.01).count()
    }
}

/// The pixels a splat's footprint covers, clamped to the image (inclusive).
fn pixel_rect(s: &Splat, size: [u32; 2]) -> Option<[u32; 4]> {
    let x0 = (s.center[0] - s.radius - 0.5).ceil().max(0.0);
    let x1 = (s.center[0] + s.radius - 0.5)
        .floor()
        .min(size[0] as f64 - 1.0);
    let y0 = (s.center[1] - s.radius - 0.5).ceil().max(0.0);
    let y1 = (s.center[1] + s.radius - 0.5)
        .floor()
        .min(size[1] as f64 - 1.0);
    (x0 <= x1 && y0 <= y1).then_some([x0 as u32, y0 as u32, x1 as u32, y1 as u32])
}

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

/// Tiles of an image, and the splats (sorted by depth, then index) in each.
pub(super) fn bin(splats: &[Splat], size: [u32; 2]) -> Vec<Vec<u32>> {
    let tiles = [size[0].div_ceil(TILE), size[1].div_ceil(TILE)];
    let mut order: Vec<u32> = (0..splats.len() as u32).collect();
    order.sort_by(|&i, &j| {
        splats[i as usize]
            .depth
            .total_cmp(&splats[j as usize].depth)
            .then(i.cmp(&j))
    });
    let mut lists = vec![Vec::new(); (tiles[0] * tiles[1]) as usize];
    for i in order {
        let Some([x0, y0, x1, y1]) = pixel_rect(&splats[i as usize], size) else {
            continue;
        };
        for ty in y0 / TILE..=y1 / TILE {
            for tx in x0 / TILE..=x1 / TILE {
                lists[(ty * tiles[0] + tx) as usize].push(i);
            }
        }
    }
    lists
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

/// Which rasteriser a training run uses: the f64 CPU passes above, or their
/// f32 wgpu kernels.
pub enum Rasterizer {
    /// [`forward`] and [`backward`] on rayon, f64.
    Cpu,
    /// [`GpuRaster`]: wgpu compute, f32.
    Gpu(Box<GpuRaster>),
}

impl Rasterizer {
    /// Opens the rasteriser a renderer choice names: `gpu` any wgpu adapter
    /// (lavapipe included), `cpu` the CPU, `auto` a hardware GPU when there is
    /// one and the CPU otherwise.
    pub fn open(backend: Backend) -> Result<Self> {
        Ok(match backend {
            Backend::Cpu => Rasterizer::Cpu,
            Backend::Gpu => Rasterizer::Gpu(Box::new(
                GpuRaster::open(true)?.ok_or_else(|| Error::device("no graphics adapter found"))?,
            )),
            Backend::Auto => match GpuRaster::open(false) {
                Ok(Some(gpu)) => Rasterizer::Gpu(Box::new(gpu)),
                _ => Rasterizer::Cpu,
            },
        })
    }

    /// What runs the passes, for reports.
    pub fn description(&self) -> String {
        match self {
            Rasterizer::Cpu => "cpu (f64, rayon)".to_string(),
            Rasterizer::Gpu(gpu) => format!("wgpu (f32) on {}", gpu.description()),
        }
    }

    /// Draws the splats over `backdrop`.
    pub fn forward(
        &mut self,
        splats: &[Splat],
        size: [u32; 2],
        backdrop: &Backdrop,
    ) -> Result<Rasterized> {
        match self {
            Rasterizer::Cpu => Ok(forward(splats, size, backdrop)),
            Rasterizer::Gpu(gpu) => gpu.forward(splats, size, backdrop),
        }
    }

    /// ∂loss/∂ every splat, given ∂loss/∂ the image.
    pub fn backward(
        &mut self,
        splats: &[Splat],
        raster: &Rasterized,
        d_image: &[f64],
    ) -> Result<Vec<SplatGrad>> {
        match self {
            Rasterizer::Cpu => Ok(backward(splats, raster, d_image)),
            Rasterizer::Gpu(gpu) => gpu.backward(splats, raster, d_image),
        }
    }
}

#[cfg(test)]
/// A layer behind part of the image: its colour varies per pixel and it
/// hides the splats deeper than 1.5 over the left half.
pub(super) fn test_layered_backdrop(size: [u32; 2]) -> Backdrop {
    let mut b = Backdrop::uniform(size, [0.1, 0.2, 0.3]);
    for y in 0..size[1] {
        for x in 0..size[0] / 2 {
            let p = (y * size[0] + x) as usize;
            b.colour[p] = [0.9, 0.05 * (x % 7) as f64, 0.3];
            b.stop[p] = 1.5;
        }
    }
    b
}

#[cfg(test)]
mod tests {
    use super::*;

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
