//! Border smoothing between regions whose Gaussians come from different sources
//! (thesis 4.2.2, docs/method.md §7).
//!
//! A triangle t borders region r iff t ∉ r and t shares a vertex with a triangle
//! of r; b(r, p) are the triangles of p that border r.
//!
//! - **thesis**: for every ordered pair (r, p) with f_r ≠ f_p, add the Gaussians of
//!   f_r bound to b(r, p) at half opacity. Two half-opaque copies over an opaque
//!   layer change colour with the sort order, and where a region's own layer is
//!   thin the pair covers only 1 − ½·½ = 0.75.
//! - **crossfade**: over a band of `BAND_RINGS` triangle rings on each side of the
//!   border, keep both sources and split each Gaussian's opacity by exponents that
//!   sum to one: α_own' = 1 − (1 − α)^t and α_other' = 1 − (1 − α)^(1−t), so the
//!   pair transmits (1 − α)^t·(1 − α)^(1−t) = 1 − α whatever the depth order —
//!   coverage stays exactly what either source alone had — while t rises from ⅔ at
//!   the border to 1 outside the band.

use std::collections::{BTreeMap, HashSet};

use crate::model::head::HeadModel;
use crate::model::regions::Region;

/// Rings of triangles on each side of a border that the cross-fade spans.
pub const BAND_RINGS: u8 = 2;

/// Own-source opacity exponent of a triangle at `ring` (1 = touching the border).
pub fn own_share(ring: u8) -> f32 {
    0.5 + 0.5 * ring as f32 / (BAND_RINGS as f32 + 1.0)
}

/// Border tables of a topology: for each ordered region pair (r, p) that touch,
/// the triangles of p within `BAND_RINGS` rings of r, with their ring number.
#[derive(Clone, Debug, Default)]
pub struct BorderTables {
    pairs: BTreeMap<(Region, Region), Vec<(u32, u8)>>,
}

impl BorderTables {
    /// Precomputes the borders of a model.
    pub fn new(model: &HeadModel) -> Self {
        let n = model.vertex_count();
        let mut vertex_triangles: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (t, tri) in model.triangles.iter().enumerate() {
            for &v in tri {
                vertex_triangles[v as usize].push(t as u32);
            }
        }
        let region = |t: u32| model.triangle_regions[t as usize];
        let neighbours = |t: u32| {
            model.triangles[t as usize]
                .iter()
                .flat_map(|&v| vertex_triangles[v as usize].iter().copied())
                .filter(move |&u| u != t)
        };
        // Ring 1: b(r, p).
        let mut first: BTreeMap<(Region, Region), Vec<u32>> = BTreeMap::new();
        for t in 0..model.triangle_count() as u32 {
            let p = region(t);
            let touching: HashSet<Region> = neighbours(t).map(region).filter(|&r| r != p).collect();
            for r in touching {
                first.entry((r, p)).or_default().push(t);
            }
        }
        // Further rings by breadth-first search inside p.
        let mut pairs = BTreeMap::new();
        for ((r, p), ring1) in first {
            let mut seen: HashSet<u32> = ring1.iter().copied().collect();
            let mut band: Vec<(u32, u8)> = ring1.iter().map(|&t| (t, 1)).collect();
            let mut frontier = ring1;
            for ring in 2..=BAND_RINGS {
                let mut next = Vec::new();
                for &t in &frontier {
                    for u in neighbours(t) {
                        if region(u) == p && seen.insert(u) {
                            next.push(u);
                        }
                    }
                }
                next.sort_unstable();
                band.extend(next.iter().map(|&t| (t, ring)));
                frontier = next;
            }
            pairs.insert((r, p), band);
        }
        Self { pairs }
    }

    /// All ordered pairs (r, p) with their bands (ring 1 first).
    pub fn pairs(&self) -> impl Iterator<Item = (&(Region, Region), &Vec<(u32, u8)>)> {
        self.pairs.iter()
    }

    /// b(r, p): the triangles of p bordering r.
    pub fn bordering(&self, r: Region, p: Region) -> impl Iterator<Item = u32> + '_ {
        self.pairs
            .get(&(r, p))
            .into_iter()
            .flatten()
            .filter(|(_, ring)| *ring == 1)
            .map(|(t, _)| *t)
    }
}

/// Opacity after splitting by an exponent: 1 − (1 − α)^e.
pub fn split_opacity(alpha: f32, exponent: f32) -> f32 {
    1.0 - (1.0 - alpha.clamp(0.0, 1.0)).powf(exponent)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_opacities_compose_to_the_original_in_any_order() {
        for alpha in [0.0f32, 0.3, 0.9, 0.99, 1.0] {
            for t in [0.0f32, 0.25, 2.0 / 3.0, 1.0] {
                let a = split_opacity(alpha, t);
                let b = split_opacity(alpha, 1.0 - t);
                let combined = 1.0 - (1.0 - a) * (1.0 - b);
                assert!(
                    (combined - alpha).abs() < 1e-5,
                    "α {alpha} t {t}: {combined}"
                );
            }
        }
    }

    #[test]
    fn own_share_rises_to_one_outside_the_band() {
        assert!((own_share(1) - 2.0 / 3.0).abs() < 1e-6);
        assert!(own_share(BAND_RINGS) < 1.0 && own_share(BAND_RINGS) > own_share(1));
    }
}
