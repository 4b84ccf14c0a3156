//! Colour seams of one composite (`smoothing = "blend"`, docs/method.md
//! §7.8): every own Gaussian within half a seam width of another source's
//! triangles moves its colour towards that source's local colour there, and
//! one whose footprint lies mostly over another source takes that source's
//! colour there.
//!
//! A [`SeamColours`] is read-only and shared by the threads that copy a
//! composite's Gaussians; each thread keeps its own [`SeamCache`] of the
//! local colours it has made, so results never depend on the split. The
//! composite keeps every local colour made in its [`VertexColours`]: they
//! depend on the source, the base and the colour correction, never on the
//! assignment, so the next assignment edit looks them up instead of
//! re-making them in every thread's cache.

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use super::colour::blend_towards;
use super::correction::Correction;
use super::membership::FOOTPRINT_MAJORITY;
use super::recipe::{ColourCorrection, Membership, ResolvedRecipe};
use super::seams::{SeamField, SeamNeighbours, SEAM_WIDTH};
use crate::avatar::gaussians::GaussianSet;
use crate::model::head::HeadModel;
use crate::model::regions::Region;

/// What copying a composite's Gaussians and its colour seams read of the
/// sources: the engine's per-source tables.
pub trait SourceTables: Sync {
    /// The head model every source shares.
    fn model(&self) -> &HeadModel;
    /// The Gaussians of `source`.
    fn gaussians(&self, source: usize) -> &GaussianSet;
    /// The template's seam neighbourhoods.
    fn seam_neighbours(&self) -> &SeamNeighbours;
    /// Per Gaussian of `source`: the triangle it counts for under `membership`.
    fn counted_triangles(&self, membership: Membership, source: usize) -> &[u32];
    /// The Gaussians of `source` counted for `triangle` under `membership`.
    fn triangle_gaussians(&self, membership: Membership, source: usize, triangle: u32) -> &[u32];
    /// Per Gaussian of `source`: where it sits on the triangle it counts for
    /// (barycentric).
    fn placements(&self, membership: Membership, source: usize) -> &[[f32; 3]];
    /// Per Gaussian of `source`: the triangles its footprint reaches.
    fn footprints(&self, source: usize) -> &[[u32; 4]];
    /// Per Gaussian of `source`: its weight in a mean colour (method §7.5).
    fn colour_weights(&self, source: usize) -> &[f32];
    /// Per Gaussian of `source`: its colour as the capture's cameras saw it.
    fn seen(&self, source: usize) -> &[Vec3];
    /// The triangles around vertex `v`.
    fn triangles_around(&self, v: u32) -> &[u32];
    /// The colour correction of `source`'s Gaussians counted in `region`.
    fn correction(&self, recipe: &ResolvedRecipe, region: Region, source: usize) -> Correction;
}

/// A source's local colour at a vertex on one side of the hairline
/// ([`SeamColours::colour_at`]): none where it has no Gaussians there.
pub type LocalColour = Option<Vec3>;

/// Which local colour: (source, vertex, side of the hairline).
pub type ColourKey = (u32, u32, u8);

/// The local colours a composite's seams have made so far, kept between
/// edits: valid while its base, colour correction and membership stay
/// (what a local colour depends on besides its source and vertex) and
/// while it is updated by the engine that made it (like the composite's
/// other kept values: a composite is only ever brought up to date by its
/// own engine).
#[derive(Clone, Debug, Default)]
pub struct VertexColours {
    /// The base, colour correction and membership they were made under.
    made_for: Option<(usize, ColourCorrection, Membership)>,
    /// Per source, per vertex, per side: the colour, where made.
    colours: Vec<Vec<[Option<LocalColour>; 2]>>,
}

impl VertexColours {
    /// Forgets every colour unless they were made for `recipe`'s base,
    /// colour correction and membership.
    pub fn keep_for(&mut self, recipe: &ResolvedRecipe) {
        let key = (recipe.base, recipe.post.colour, recipe.post.membership);
        if self.made_for != Some(key) {
            self.colours.clear();
            self.made_for = Some(key);
        }
    }

    fn get(&self, (s, v, side): ColourKey) -> Option<LocalColour> {
        self.colours.get(s as usize)?.get(v as usize)?[side as usize]
    }

    /// Keeps colours made while copying (`vertex_count` per source).
    pub fn add(
        &mut self,
        made: impl IntoIterator<Item = (ColourKey, LocalColour)>,
        vertex_count: usize,
    ) {
        for ((s, v, side), colour) in made {
            let s = s as usize;
            if self.colours.len() <= s {
                self.colours.resize(s + 1, Vec::new());
            }
            let per_vertex = &mut self.colours[s];
            if per_vertex.is_empty() {
                *per_vertex = vec![[None; 2]; vertex_count];
            }
            per_vertex[v as usize][side as usize] = Some(colour);
        }
    }
}

/// The seams of one composite: which source each triangle wears and how
/// far each vertex is from every other source shown.
pub struct SeamColours<'a> {
    recipe: &'a ResolvedRecipe,
    /// The local colours made by earlier edits of the composite.
    kept: &'a VertexColours,
    field: SeamField,
    /// Per triangle: the source it wears.
    looks: Vec<u32>,
    /// Per triangle: whether a corner is within half a seam width of
    /// another source than the one it wears.
    near: Vec<bool>,
}

/// Which side of the hairline a triangle of `region` lies on. A seam's
/// target is the other source's colour on the Gaussian's own side: the
/// truth's cross-fade (method §13.1) mixes hair with the other source's
/// hair and skin with its skin, while a vertex on the hairline has
/// triangles of both around it.
fn side_of(region: Region) -> u8 {
    u8::from(region == Region::Hair)
}

/// One thread's memory of the local colours and corrections it made.
#[derive(Default)]
pub struct SeamCache {
    /// Local colours not kept by the composite, made on first use,
    /// corrected as the composite corrects them.
    made: HashMap<ColourKey, LocalColour>,
    /// Those made since [`SeamCache::take_made`] last took them.
    fresh: Vec<(ColourKey, LocalColour)>,
    /// Colour corrections by (source, region), made on first use.
    corrections: HashMap<(usize, Region), Correction>,
}

impl SeamCache {
    /// The local colours made since the last call, for the composite to keep.
    pub fn take_made(&mut self) -> Vec<(ColourKey, LocalColour)> {
        std::mem::take(&mut self.fresh)
    }
}

impl<'a> SeamColours<'a> {
    /// The seams of the composite `recipe` makes: triangle `t` wears
    /// `looks[t]`, the source of the group its region belongs to.
    /// `kept` holds the local colours earlier edits made (see
    /// [`VertexColours::keep_for`]).
    pub fn new(
        sources: &impl SourceTables,
        recipe: &'a ResolvedRecipe,
        looks: Vec<u32>,
        kept: &'a VertexColours,
    ) -> Self {
        let model = sources.model();
        let field = SeamField::with_neighbours(model, sources.seam_neighbours(), &looks);
        // A triangle none of whose corners is near another source is
        // untouched: the interpolated distance cannot be nearer than the
        // nearest corner.
        let near = model
            .triangles
            .par_iter()
            .zip(&looks)
            .map(|(tri, &own)| {
                field.sources().iter().filter(|&&s| s != own).any(|&s| {
                    let d = field.distances(s).unwrap_or_default();
                    tri.iter().any(|&v| d[v as usize] < SEAM_WIDTH / 2.0)
                })
            })
            .collect();
        Self {
            recipe,
            kept,
            field,
            looks,
            near,
        }
    }

    /// An empty cache for one thread.
    pub fn cache(&self) -> SeamCache {
        SeamCache::default()
    }

    /// Blends the SH of source `f`'s Gaussian `i` (already corrected) towards
    /// the nearest other source's local colour by the seam weight; whether
    /// it sits near another source's triangles at all.
    pub fn blend(
        &self,
        sources: &impl SourceTables,
        cache: &mut SeamCache,
        f: usize,
        i: u32,
        sh: &mut [f32],
    ) -> bool {
        let membership = self.recipe.post.membership;
        let t = sources.counted_triangles(membership, f)[i as usize];
        if !self.near[t as usize] {
            return false;
        }
        if self.blend_by_footprint(sources, cache, f, i, sh) {
            return true;
        }
        let tri = sources.model().triangles[t as usize];
        let side = side_of(sources.model().triangle_regions[t as usize]);
        let bary = sources.placements(membership, f)[i as usize];
        let Some(seam) = self.field.blend_at(tri, bary, f as u32) else {
            return true;
        };
        let mut sum = Vec3::ZERO;
        let mut total = 0.0;
        for (k, &v) in tri.iter().enumerate() {
            if let Some(c) = self.colour_at(sources, cache, seam.other as usize, v, side) {
                sum += bary[k] * c;
                total += bary[k];
            }
        }
        if total > 0.0 {
            blend_towards(sh, sum / total, seam.weight);
        }
        true
    }

    /// A Gaussian whose footprint lies mostly over one other source's
    /// triangles (at least `FOOTPRINT_MAJORITY` of its four points) paints
    /// mostly where the truth shows that source: it takes that source's
    /// colour there, in the share of its points that lie there. Whether it
    /// did.
    fn blend_by_footprint(
        &self,
        sources: &impl SourceTables,
        cache: &mut SeamCache,
        f: usize,
        i: u32,
        sh: &mut [f32],
    ) -> bool {
        let points = sources.footprints(f)[i as usize];
        let wearing = |t: u32| self.looks.get(t as usize).copied();
        let others = points.map(|t| wearing(t).filter(|&s| s != f as u32));
        let count = |s: u32| others.iter().filter(|&&o| o == Some(s)).count();
        // A majority of the four holds the first or the second point.
        let Some((other, count)) = others[..2]
            .iter()
            .flatten()
            .map(|&s| (s, count(s)))
            .find(|&(_, n)| n >= FOOTPRINT_MAJORITY)
        else {
            return false;
        };
        let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
        for (&t, o) in points.iter().zip(others) {
            if o != Some(other) {
                continue;
            }
            let side = side_of(sources.model().triangle_regions[t as usize]);
            for v in sources.model().triangles[t as usize] {
                if let Some(c) = self.colour_at(sources, cache, other as usize, v, side) {
                    sum += c;
                    total += 1.0;
                }
            }
        }
        if total == 0.0 {
            return false;
        }
        blend_towards(sh, sum / total, count as f32 / points.len() as f32);
        true
    }

    /// Source `s`'s local colour at vertex `v` on `side` of the hairline:
    /// the mean colour of its Gaussians counted for the triangles around `v`
    /// on that side, each weighted by its opacity and size (method §7.5) and
    /// by its barycentric share of `v`; none where it has no Gaussians on
    /// that side.
    fn colour_at(
        &self,
        sources: &impl SourceTables,
        cache: &mut SeamCache,
        s: usize,
        v: u32,
        side: u8,
    ) -> LocalColour {
        self.field.sources().binary_search(&(s as u32)).ok()?;
        let key = (s as u32, v, side);
        if let Some(colour) = self.kept.get(key) {
            return colour;
        }
        if let Some(&colour) = cache.made.get(&key) {
            return colour;
        }
        let model = sources.model();
        let membership = self.recipe.post.membership;
        let bary = sources.placements(membership, s);
        let weights = sources.colour_weights(s);
        let seen = sources.seen(s);
        let (mut sum, mut total) = (Vec3::ZERO, 0.0f32);
        for &t in sources.triangles_around(v) {
            let corner = model.triangles[t as usize].iter().position(|&u| u == v);
            let Some(corner) = corner else { continue };
            let region = model.triangle_regions[t as usize];
            if side_of(region) != side {
                continue;
            }
            let correction = cache
                .corrections
                .entry((s, region))
                .or_insert_with(|| sources.correction(self.recipe, region, s));
            for &j in sources.triangle_gaussians(membership, s, t) {
                let j = j as usize;
                let w = weights[j] * bary[j][corner];
                if w <= 0.0 {
                    continue;
                }
                // As the cameras saw it: the colour the seam blends
                // towards is the colour the other side shows.
                sum += w * seen[j] * correction.gain(j);
                total += w;
            }
        }
        let colour = (total > 0.0 && sum.is_finite()).then(|| sum / total);
        cache.made.insert(key, colour);
        cache.fresh.push((key, colour));
        colour
    }
}
