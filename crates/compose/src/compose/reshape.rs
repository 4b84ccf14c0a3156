//! Moving a composite's Gaussians with the blend's reshaping of their
//! triangles (docs/method.md §6.7, §6.8): by their parent's local
//! deformation under `deform = "affine"`, and under `anchor = "nearest"` by
//! the triangle of their source's surface nearest them, written back in the
//! parent's frame. The similarity every Gaussian follows as stored needs
//! nothing here.
//!
//! What a source's Gaussian becomes depends only on the source, the
//! composite's shape and these two options, never on the assignment. So
//! each source's reshaped Gaussians are kept ([`ReshapedSources`]) and made
//! only as a composite first shows them: an assignment edit copies them in
//! with the rest of each Gaussian, and only a shape edit (or a change of
//! the options) starts again.

use glam::{DMat3, Quat, Vec3};
use rayon::prelude::*;

use super::deform::{apply_local_map, from_anchor, local_map, to_anchor, AnchorLocal};
use super::membership::anchor_triangles;
use crate::avatar::binding::{triangle_frame, triangle_frames};
use crate::avatar::gaussians::GaussianSet;
use crate::model::head::HeadModel;

/// The Gaussians of one source that follow another triangle than their
/// parent (`anchor = "nearest"`).
pub struct SourceAnchors {
    /// Per Gaussian, its entry in `locals`, or `u32::MAX` (it follows its parent).
    slot: Vec<u32>,
    /// Each such Gaussian in its anchor triangle's frame on the source's mesh.
    locals: Vec<AnchorLocal>,
}

impl SourceAnchors {
    /// The anchored Gaussians of `set`, a source whose neutral mesh is `neutral`.
    pub fn new(model: &HeadModel, set: &GaussianSet, neutral: &[Vec3]) -> Self {
        let frames = triangle_frames(neutral, &model.triangles);
        let anchors = anchor_triangles(model, set, neutral);
        let mut found = SourceAnchors {
            slot: vec![u32::MAX; set.len()],
            locals: Vec::new(),
        };
        for (i, (&anchor, &parent)) in anchors.iter().zip(&set.binding).enumerate() {
            if anchor == parent {
                continue;
            }
            let local = to_anchor(
                &frames[parent as usize],
                (anchor, &frames[anchor as usize]),
                set.position[i],
                set.rotation[i],
                set.log_scale[i],
            );
            if let Some(local) = local {
                found.slot[i] = found.locals.len() as u32;
                found.locals.push(local);
            }
        }
        found
    }

    /// Gaussian `i` in its anchor triangle's frame, where it follows another
    /// triangle than its parent.
    fn local(&self, i: u32) -> Option<&AnchorLocal> {
        let slot = *self.slot.get(i as usize)?;
        self.locals.get(slot as usize)
    }
}

/// One source as reshaping sees it.
pub struct ReshapeSource<'a> {
    /// Its neutral mesh.
    pub neutral: &'a [Vec3],
    /// Its Gaussians as stored.
    pub gaussians: &'a GaussianSet,
    /// Its anchored Gaussians, under `anchor = "nearest"`.
    pub anchors: Option<&'a SourceAnchors>,
}

/// The composite's side of reshaping.
pub struct Reshaping<'a> {
    /// The model's triangles.
    pub triangles: &'a [[u32; 3]],
    /// The composite's blended neutral mesh.
    pub target: &'a [Vec3],
    /// What the Gaussians follow.
    pub options: ReshapeOptions,
}

/// A slot not made yet.
const UNSEEN: u32 = u32::MAX;
/// A slot made and found to need nothing: the triangle keeps its shape up
/// to a similarity, or the Gaussian keeps its values as stored.
const KEPT: u32 = u32::MAX - 1;

/// A Gaussian's position, rotation and log-scales in its parent's frame.
pub type Placed = (Vec3, Quat, Vec3);

/// Every source's reshaped Gaussians for one composite shape and one choice
/// of `deform` and `anchor`, made as the composite first shows them.
#[derive(Clone, Debug, Default)]
pub struct ReshapedSources {
    /// The options they were made for.
    options: ReshapeOptions,
    /// Per source; `None` until the composite first shows it.
    sources: Vec<Option<ReshapedSource>>,
}

/// What a composite's reshaping follows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ReshapeOptions {
    /// Whether Gaussians follow their triangle's whole local deformation
    /// (`deform = "affine"`) rather than its similarity.
    pub affine: bool,
    /// Whether Gaussians off their parent follow the triangle under them
    /// (`anchor = "nearest"`).
    pub nearest: bool,
}

/// One source's Gaussians reshaped to a composite's shape, as far as made.
#[derive(Clone, Debug)]
struct ReshapedSource {
    /// Per triangle: [`UNSEEN`], [`KEPT`] (a similarity) or its entry in `maps`.
    map_slot: Vec<u32>,
    /// The local maps made (`deform = "affine"`).
    maps: Vec<DMat3>,
    /// Per Gaussian: [`UNSEEN`], [`KEPT`] or its entry in `moved`.
    slot: Vec<u32>,
    /// The Gaussians reshaping moved.
    moved: Vec<Placed>,
}

impl ReshapedSources {
    /// Forgets every reshaped Gaussian: the composite's shape changed.
    pub fn clear(&mut self) {
        self.sources.clear();
    }

    /// Makes the reshaped values of `wanted` (per source, Gaussians of it)
    /// not made yet, from the source's neutral mesh to the composite's as
    /// `reshaping` says; what was made under other options is forgotten.
    pub fn make(
        &mut self,
        reshaping: &Reshaping,
        sources: &[ReshapeSource],
        wanted: &[(usize, &[u32])],
    ) {
        let options = reshaping.options;
        if self.options != options || self.sources.len() != sources.len() {
            self.options = options;
            self.sources = (0..sources.len()).map(|_| None).collect();
        }
        for &(f, gaussians) in wanted {
            let source = &sources[f];
            let reshaped = self.sources[f].get_or_insert_with(|| ReshapedSource {
                map_slot: vec![UNSEEN; reshaping.triangles.len()],
                maps: Vec::new(),
                slot: vec![UNSEEN; source.gaussians.len()],
                moved: Vec::new(),
            });
            let mut missing: Vec<u32> = gaussians
                .iter()
                .copied()
                .filter(|&i| reshaped.slot.get(i as usize) == Some(&UNSEEN))
                .collect();
            if !missing.is_empty() {
                missing.sort_unstable();
                missing.dedup();
                reshaped.make(reshaping, source, &missing);
            }
        }
    }

    /// Gaussian `i` of source `f` on the composite's shape, where reshaping
    /// moved it (made by [`Self::make`]); `None` where it keeps its values
    /// as stored.
    #[inline]
    pub fn placed(&self, f: usize, i: u32) -> Option<&Placed> {
        let reshaped = self.sources.get(f)?.as_ref()?;
        let slot = *reshaped.slot.get(i as usize)?;
        reshaped.moved.get(slot as usize)
    }
}

impl Reshaping<'_> {
    fn corners(&self, mesh: &[Vec3], t: u32) -> [Vec3; 3] {
        self.triangles[t as usize].map(|v| mesh[v as usize])
    }

    /// Gaussian `i` of `source` moved by the reshaping of the triangle it
    /// follows — its parent, or for an anchored one the triangle nearest it
    /// — from the source's neutral mesh to the composite's, with the maps
    /// `made` holds; `None` where it keeps its values as stored.
    fn reshape(&self, source: &ReshapeSource, made: &ReshapedSource, i: u32) -> Option<Placed> {
        let set = source.gaussians;
        let g = i as usize;
        let parent = set.binding[g];
        let mut placed = None;
        if let Some(map) = made.map(parent) {
            let (mut p, mut q, mut s) = (set.position[g], set.rotation[g], set.log_scale[g]);
            apply_local_map(map, &mut p, &mut q, &mut s);
            placed = Some((p, q, s));
        }
        // An anchored Gaussian starts again from its source's values: the
        // parent's map is not its own.
        let Some(local) = source.anchors.and_then(|a| a.local(i)) else {
            return placed;
        };
        let unmoved = |t: u32| self.corners(source.neutral, t) == self.corners(self.target, t);
        if unmoved(parent) && unmoved(local.anchor) {
            return placed;
        }
        let frame = |t: u32| {
            let [a, b, c] = self.corners(self.target, t);
            triangle_frame(a, b, c)
        };
        let map = made.map(local.anchor);
        from_anchor(local, &frame(local.anchor), &frame(parent), map).or(placed)
    }
}

impl ReshapedSource {
    /// The local map of triangle `t`, where made and not a similarity.
    fn map(&self, t: u32) -> Option<&DMat3> {
        let slot = *self.map_slot.get(t as usize)?;
        self.maps.get(slot as usize)
    }

    /// Makes the reshaped values of `missing` (Gaussians of `source` not
    /// made yet, each once) and the maps of the triangles they follow.
    fn make(&mut self, reshaping: &Reshaping, source: &ReshapeSource, missing: &[u32]) {
        if reshaping.options.affine {
            self.make_maps(reshaping, source, missing);
        }
        // A region's worth on an assignment edit, a composite's on a shape
        // edit; under anchors alone most need nothing and cost little each.
        let found: Vec<Option<Placed>> = missing
            .par_iter()
            .with_min_len(512)
            .map(|&i| reshaping.reshape(source, self, i))
            .collect();
        for (&i, placed) in missing.iter().zip(found) {
            self.slot[i as usize] = match placed {
                Some(placed) => {
                    self.moved.push(placed);
                    (self.moved.len() - 1) as u32
                }
                None => KEPT,
            };
        }
    }

    /// Makes the local maps not made yet of the triangles `gaussians` of
    /// `source` follow: their parents and anchors.
    fn make_maps(&mut self, reshaping: &Reshaping, source: &ReshapeSource, gaussians: &[u32]) {
        let anchor_of = |i: u32| source.anchors.and_then(|a| a.local(i)).map(|l| l.anchor);
        let mut triangles: Vec<u32> = gaussians
            .iter()
            .flat_map(|&i| [Some(source.gaussians.binding[i as usize]), anchor_of(i)])
            .flatten()
            .filter(|&t| self.map_slot.get(t as usize) == Some(&UNSEEN))
            .collect();
        triangles.sort_unstable();
        triangles.dedup();
        let made: Vec<Option<DMat3>> = triangles
            .par_iter()
            .with_min_len(256)
            .map(|&t| {
                local_map(
                    reshaping.corners(source.neutral, t),
                    reshaping.corners(reshaping.target, t),
                )
            })
            .collect();
        for (t, map) in triangles.into_iter().zip(made) {
            self.map_slot[t as usize] = match map {
                Some(map) => {
                    self.maps.push(map);
                    (self.maps.len() - 1) as u32
                }
                None => KEPT,
            };
        }
    }
}
