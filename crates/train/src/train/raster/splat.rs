//! What the training rasteriser's passes share, on the CPU and on wgpu: the
//! splat as it sees it, its gradient, the backdrop, a forward pass's result
//! and the binning of splats into depth-sorted tiles.

/// Tile edge in pixels (the wgpu kernels' workgroup edge too).
pub(in crate::train) const TILE: u32 = crate::render::gpu::TILE;

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
    pub(in crate::train) fn add(&mut self, o: &SplatGrad) {
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
    pub(in crate::train) lists: Vec<Vec<u32>>,
    /// Per pixel: transmittance after its last contributing splat.
    pub(in crate::train) final_t: Vec<f64>,
    /// Per pixel: how many entries of its tile's list it walked.
    pub(in crate::train) walked: Vec<u32>,
}

impl Rasterized {
    /// A forward result from its parts (the wgpu pass builds one).
    pub(in crate::train) fn from_parts(
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
pub(super) fn pixel_rect(s: &Splat, size: [u32; 2]) -> Option<[u32; 4]> {
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

/// Tiles of an image, and the splats (sorted by depth, then index) in each.
pub(in crate::train) fn bin(splats: &[Splat], size: [u32; 2]) -> Vec<Vec<u32>> {
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

#[cfg(test)]
/// A layer behind part of the image: its colour varies per pixel and it
/// hides the splats deeper than 1.5 over the left half.
pub(in crate::train) fn test_layered_backdrop(size: [u32; 2]) -> Backdrop {
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
