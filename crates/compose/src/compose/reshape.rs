//! Moving a composite's Gaussians with the blend's reshaping of their
//! triangles (docs/method.md §6.7, §6.8): by their parent's local
//! deformation under `deform = "affine"`, and under `anchor = "nearest"` by
//! the triangle of their source's surface nearest them, written back in the
//! parent's frame. The similarity every Gaussian follows as stored needs
//! nothing here.

use std::ops::Range;

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
}

/// A composite Gaussian that follows another triangle than its parent.
#[derive(Clone, Copy, Debug)]
pub struct Anchored {
    /// Its index in the composite.
    at: u32,
    /// Its source, and its entry in that source's [`SourceAnchors`].
    source: u32,
    slot: u32,
}

/// Notes the composite's Gaussian `at`, Gaussian `i` of source `f`, in
/// `anchored` when `anchors` (the source's, under `anchor = "nearest"`) has
/// it follow another triangle than its parent.
pub fn note_anchor(
    anchored: &mut Vec<Anchored>,
    anchors: Option<&SourceAnchors>,
    at: usize,
    f: usize,
    i: u32,
) {
    let Some(&slot) = anchors.and_then(|a| a.slot.get(i as usize)) else {
        return;
    };
    if slot != u32::MAX {
        anchored.push(Anchored {
            at: at as u32,
            source: f as u32,
            slot,
        });
    }
}

/// One source as reshaping sees it.
pub struct ReshapeSource<'a> {
    /// Its neutral mesh.
    pub neutral: &'a [Vec3],
    /// Its anchored Gaussians, where the composite follows anchors and
    /// draws on this source.
    pub anchors: Option<&'a SourceAnchors>,
}

/// The composite's side of reshaping.
pub struct Reshaping<'a> {
    /// The model's triangles.
    pub triangles: &'a [[u32; 3]],
    /// The composite's blended neutral mesh.
    pub target: &'a [Vec3],
    /// Whether Gaussians follow their triangle's whole local deformation
    /// (`deform = "affine"`) rather than its similarity.
    pub affine: bool,
}

impl Reshaping<'_> {
    fn corners(&self, mesh: &[Vec3], t: u32) -> [Vec3; 3] {
        self.triangles[t as usize].map(|v| mesh[v as usize])
    }

    /// Moves the Gaussians of `set`, each range of `blocks` from the source
    /// it names, by the reshaping of the triangle each follows — its parent,
    /// or for the `anchored` ones the triangle nearest it — from its
    /// source's neutral mesh to the composite's.
    pub fn apply(
        &self,
        sources: &[ReshapeSource],
        blocks: &[(usize, Range<usize>)],
        anchored: &[Anchored],
        set: &mut GaussianSet,
    ) {
        let mut maps: Vec<Option<Vec<Option<DMat3>>>> = (0..sources.len()).map(|_| None).collect();
        if self.affine {
            for (f, _) in blocks {
                if maps[*f].is_none() {
                    let source = sources[*f].neutral;
                    maps[*f] = Some(
                        (0..self.triangles.len() as u32)
                            .into_par_iter()
                            .map(|t| {
                                local_map(self.corners(source, t), self.corners(self.target, t))
                            })
                            .collect(),
                    );
                }
            }
        }
        let map_of = |f: usize, t: u32| {
            maps[f]
                .as_ref()
                .and_then(|m| m.get(t as usize))
                .and_then(|m| m.as_ref())
        };
        if self.affine {
            for (f, range) in blocks {
                set.position[range.clone()]
                    .par_iter_mut()
                    .zip(&mut set.rotation[range.clone()])
                    .zip(&mut set.log_scale[range.clone()])
                    .zip(&set.binding[range.clone()])
                    .for_each(|(((p, q), s), &t)| {
                        if let Some(map) = map_of(*f, t) {
                            apply_local_map(map, p, q, s);
                        }
                    });
            }
        }
        // Anchored Gaussians start again from their source's values: the
        // parent's map above is not theirs.
        let unmoved =
            |f: usize, t: u32| self.corners(sources[f].neutral, t) == self.corners(self.target, t);
        let frame = |t: u32| {
            let [a, b, c] = self.corners(self.target, t);
            triangle_frame(a, b, c)
        };
        // A few hundred on most sources: not worth waking the pool for.
        let moved: Vec<Option<(Vec3, Quat, Vec3)>> = anchored
            .par_iter()
            .with_min_len(2048)
            .map(|a| {
                let f = a.source as usize;
                let local = &sources[f].anchors?.locals[a.slot as usize];
                let parent = set.binding[a.at as usize];
                if unmoved(f, parent) && unmoved(f, local.anchor) {
                    return None;
                }
                from_anchor(
                    local,
                    &frame(local.anchor),
                    &frame(parent),
                    map_of(f, local.anchor),
                )
            })
            .collect();
        for (a, moved) in anchored.iter().zip(moved) {
            if let Some((p, q, s)) = moved {
                let g = a.at as usize;
                (set.position[g], set.rotation[g], set.log_scale[g]) = (p, q, s);
            }
        }
    }
}
