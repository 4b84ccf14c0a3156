//! Seams measured in template space (docs/method.md §7.8): where two sources
//! meet, how far each point of the surface is from the other source's
//! triangles, and how much of the other source's colour it takes. One
//! definition serves both the composite's colour seams (`smoothing = "blend"`)
//! and the ground truth's smooth seams (`visage capture --recipe --seams
//! smooth`, method §13.1), so the two cannot drift apart.

use std::collections::HashMap;

use glam::{IVec3, Vec3};

use crate::avatar::binding::triangle_frame;
use crate::avatar::gaussians::GaussianSet;

use crate::model::geometry::smoothstep;
use crate::model::head::HeadModel;

/// Width of a seam across a border, in template metres (half on each side).
pub const SEAM_WIDTH: f32 = 0.01;

/// The largest standard deviation (metres, on the composite) a Gaussian
/// within half a seam width of another source's triangles keeps under colour
/// seams (docs/method.md §7.8): a wider one reaches across the seam and paints
/// its colour onto the other source's surface, where the truth shows the other
/// source (a beard trained onto the lips' Gaussians drawn over a clean chin).
pub const SEAM_REACH: f32 = 0.4 * SEAM_WIDTH;

/// Per-vertex template distances to the triangles of each source a surface
/// shows, capped at half the seam width.
#[derive(Clone, Debug, Default)]
pub struct SeamField {
    /// The sources that show, ascending.
    sources: Vec<u32>,
    /// Per source (as `sources`), per vertex: template distance to the
    /// nearest vertex of a triangle wearing it, capped at half the seam width.
    distance: Vec<Vec<f32>>,
}

/// The other source a point blends towards and the share of its colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeamBlend {
    /// The nearest source other than the point's own.
    pub other: u32,
    /// Share of the other source's colour: ½ on the border, 0 half a seam
    /// width away, smooth between.
    pub weight: f32,
}

/// Share of the other side's colour at template distance `d` from its
/// triangles: ½ at the border, falling smoothly to 0 at half the seam width.
pub fn seam_weight(d: f32) -> f32 {
    0.5 * (1.0 - smoothstep(0.0, SEAM_WIDTH / 2.0, d))
}

/// For every vertex of a template, the vertices within half a seam width
/// of it (itself included), nearest first: all a seam field needs from the
/// geometry, which never changes with the recipe.
#[derive(Clone, Debug, Default)]
pub struct SeamNeighbours {
    /// `start[v]..start[v + 1]` indexes `near`.
    start: Vec<u32>,
    /// (vertex, template distance), ascending by distance within a row.
    near: Vec<(u32, f32)>,
}

impl SeamNeighbours {
    /// The neighbourhoods of `template`'s vertices (cells half a seam wide:
    /// every vertex within reach lies in the 27 cells around a vertex).
    pub fn new(template: &[Vec3]) -> Self {
        let half = SEAM_WIDTH / 2.0;
        let cell = |p: Vec3| (p / half).floor().as_ivec3();
        let mut grid: HashMap<IVec3, Vec<u32>> = HashMap::new();
        for (v, &p) in template.iter().enumerate() {
            if p.is_finite() {
                grid.entry(cell(p)).or_default().push(v as u32);
            }
        }
        let mut start = Vec::with_capacity(template.len() + 1);
        let mut near = Vec::new();
        start.push(0);
        let mut row = Vec::new();
        for &p in template {
            row.clear();
            if p.is_finite() {
                let c = cell(p);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            let Some(list) = grid.get(&(c + IVec3::new(dx, dy, dz))) else {
                                continue;
                            };
                            for &u in list {
                                let d = p.distance(template[u as usize]);
                                if d < half {
                                    row.push((u, d));
                                }
                            }
                        }
                    }
                }
                row.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
            }
            near.extend_from_slice(&row);
            start.push(near.len() as u32);
        }
        Self { start, near }
    }

    /// The vertices within half a seam width of `v`, nearest first.
    fn of(&self, v: usize) -> &[(u32, f32)] {
        &self.near[self.start[v] as usize..self.start[v + 1] as usize]
    }
}

impl SeamField {
    /// The field of a surface whose triangle `t` wears source `looks[t]`
    /// (one entry per triangle of `model`).
    pub fn new(model: &HeadModel, looks: &[u32]) -> Self {
        Self::with_neighbours(model, &SeamNeighbours::new(&model.template), looks)
    }

    /// The same with the template's neighbourhoods computed once beforehand.
    /// A surface shows at most one source per group; sources past the 64th
    /// (never, with seven groups) are treated as far from everything.
    pub fn with_neighbours(model: &HeadModel, neighbours: &SeamNeighbours, looks: &[u32]) -> Self {
        let half = SEAM_WIDTH / 2.0;
        let mut sources: Vec<u32> = looks.to_vec();
        sources.sort_unstable();
        sources.dedup();
        let vertices = model.vertex_count();
        let mut distance = vec![vec![half; vertices]; sources.len()];
        if sources.len() < 2 {
            // One source: nothing is near another.
            return Self { sources, distance };
        }
        // Which sources wear each vertex, as bits in `sources` order.
        let mut worn = vec![0u64; vertices];
        for (tri, look) in model.triangles.iter().zip(looks) {
            let k = sources.binary_search(look).unwrap_or(usize::MAX);
            if k < 64 {
                for &v in tri {
                    worn[v as usize] |= 1 << k;
                }
            }
        }
        let all = if sources.len() >= 64 {
            u64::MAX
        } else {
            (1u64 << sources.len()) - 1
        };
        for (v, _) in worn.iter().enumerate() {
            // Nearest first: the first neighbour a source wears is its distance.
            let mut seen = 0u64;
            for &(u, d) in neighbours.of(v) {
                let mut new = worn[u as usize] & !seen;
                seen |= new;
                while new != 0 {
                    let k = new.trailing_zeros() as usize;
                    distance[k][v] = d;
                    new &= new - 1;
                }
                if seen == all {
                    break;
                }
            }
        }
        Self { sources, distance }
    }

    /// The sources that show, ascending.
    pub fn sources(&self) -> &[u32] {
        &self.sources
    }

    /// Per vertex: distance to the triangles of `source` (capped at half the
    /// seam width), or `None` for a source the surface does not show.
    pub fn distances(&self, source: u32) -> Option<&[f32]> {
        let k = self.sources.binary_search(&source).ok()?;
        Some(&self.distance[k])
    }

    /// At the point with barycentric coordinates `bary` of the triangle with
    /// vertices `tri`, wearing `own`: the nearest other source within half a
    /// seam width and its share, or `None` when none is that near.
    pub fn blend_at(&self, tri: [u32; 3], bary: [f32; 3], own: u32) -> Option<SeamBlend> {
        let half = SEAM_WIDTH / 2.0;
        self.sources
            .iter()
            .zip(&self.distance)
            .filter(|(s, _)| **s != own)
            .map(|(&s, d)| {
                let at: f32 = (0..3).map(|k| bary[k] * d[tri[k] as usize]).sum();
                (s, at)
            })
            .filter(|(_, d)| *d < half)
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(other, d)| SeamBlend {
                other,
                weight: seam_weight(d),
            })
    }
}

/// Limits the Gaussians `indices` of `set` (the composite's, bound to the
/// triangles of `mesh`) to [`SEAM_REACH`] along every axis: each axis's
/// log-scale, in its parent triangle's units, is at most ln(reach / size).
pub fn limit_reach(set: &mut GaussianSet, indices: &[u32], mesh: &[Vec3], triangles: &[[u32; 3]]) {
    // Per triangle, computed on first use: a few Gaussians share each.
    let mut limit = vec![f32::NAN; triangles.len()];
    for &g in indices {
        let g = g as usize;
        let t = set.binding[g] as usize;
        let Some(tri) = triangles.get(t) else {
            continue;
        };
        if limit[t].is_nan() {
            let [a, b, c] = tri.map(|v| mesh[v as usize]);
            limit[t] = (SEAM_REACH / triangle_frame(a, b, c).scale).ln();
        }
        if limit[t].is_finite() {
            set.log_scale[g] = set.log_scale[g].min(Vec3::splat(limit[t]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seam_weight_is_half_at_the_border_and_none_half_a_width_away() {
        assert_eq!(seam_weight(0.0), 0.5);
        assert_eq!(seam_weight(SEAM_WIDTH / 2.0), 0.0);
        assert_eq!(seam_weight(1.0), 0.0);
        let mid = seam_weight(SEAM_WIDTH / 4.0);
        assert!((mid - 0.25).abs() < 1e-6, "{mid}");
        assert!(seam_weight(SEAM_WIDTH / 8.0) > mid);
    }
}
