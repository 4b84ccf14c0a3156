//! A swapped region's colour correction (method §7.5-§7.7): the thesis's
//! gain per region, or a skin-transfer gain per Gaussian, worked out once per
//! source and colour reference and cached in the engine.

use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;

use super::Engine;
use crate::compose::clothing::{self, ClothingMean};
use crate::compose::colour::thesis_gain;
use crate::compose::correction::{Correction, SharedGains};
use crate::compose::dark_features;
use crate::compose::recipe::{ColourCorrection, Membership, ResolvedRecipe};
use crate::compose::skin_transfer::{
    semantic_skin_likeness, skin_transfer_gain, SkinPlace, SkinStats,
};
use crate::model::regions::Region;

impl Engine {
    /// Skin-transfer gains of every Gaussian of `source` towards `reference`:
    /// by colour likeness alone (`semantic` = None) or by the region each
    /// Gaussian counts for under a membership as well (`Semantic`).
    fn skin_gains(
        &self,
        source: usize,
        reference: usize,
        semantic: Option<Membership>,
    ) -> Option<SharedGains> {
        let (from, to) = (*self.colours.skin(source)?, *self.colours.skin(reference)?);
        // Built before the pool's work below, outside any job that waits on it.
        self.colour_weights_of(source);
        let key = (source, reference, semantic);
        let cache = || self.skin_gains.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(gains) = cache().get(&key) {
            return Some(gains.clone());
        }
        // Made without the lock held: the gains are made on the thread pool,
        // and a pool thread copying another composite on this engine may be
        // waiting for the lock — held here, the two would wait on each other
        // (seen as a hang of two tests composing at once). Two threads that
        // miss together both make the same gains; the first one kept wins.
        let count = self.db.sources[source].gaussians.len();
        let regions = &self.db.model.triangle_regions;
        let colours = self.colours.seen(source);
        let brightens = dark_features::transfer_brightens(&from, &to);
        let clothing = semantic.map(|m| self.clothing_of(source, m, &from));
        let gains: Vec<Vec3> = (0..count)
            .into_par_iter()
            .map(|i| match semantic {
                Some(m) => {
                    let t = self.tables.counted_triangles(m, source)[i];
                    let region = regions[t as usize];
                    let clothing = clothing.as_ref().and_then(|c| c[region.index()]);
                    let place = SkinPlace {
                        region,
                        touches_hair: self.touches_hair[t as usize],
                    };
                    self.colours
                        .semantic_gain(source, i, place, (&from, &to), brightens, clothing)
                }
                None => skin_transfer_gain(colours[i], &from, &to),
            })
            .collect();
        Some(
            cache()
                .entry(key)
                .or_insert_with(|| Arc::new(gains))
                .clone(),
        )
    }

    /// Per region (by [`Region::index`]), the mean linear colour of source
    /// `f`'s clothing in it under membership `m`, judged skin or not by the
    /// source's skin statistics `skin`; `None` in regions that hold no
    /// clothing ([`clothing::holds_clothing`]) or show none.
    fn clothing_of(&self, f: usize, m: Membership, skin: &SkinStats) -> Vec<Option<Vec3>> {
        let mut means = vec![ClothingMean::default(); Region::COUNT];
        let (counted, colours) = (self.tables.counted_triangles(m, f), self.colours.seen(f));
        let weights = self.colour_weights_of(f);
        for (i, &t) in counted.iter().enumerate() {
            let region = self.db.model.triangle_regions[t as usize];
            if clothing::holds_clothing(region) {
                let likeness = semantic_skin_likeness(colours[i], region, skin).unwrap_or(1.0);
                means[region.index()].add(colours[i], likeness, weights[i]);
            }
        }
        means.iter().map(ClothingMean::mean).collect()
    }

    /// The colour correction of Gaussians of source `f` bound in `region`.
    pub(super) fn correction(
        &self,
        recipe: &ResolvedRecipe,
        region: Region,
        f: usize,
    ) -> Correction {
        if f == recipe.base {
            return Correction::None;
        }
        match recipe.post.colour {
            ColourCorrection::Off => Correction::None,
            ColourCorrection::Thesis => {
                let means = &self.mean_colour[recipe.post.membership as usize];
                let reference = means[recipe.base][region.index()];
                let source = means[f][region.index()];
                match (reference, source) {
                    (Some(r), Some(s)) => Correction::Gain(thesis_gain(r, s)),
                    _ => Correction::None,
                }
            }
            ColourCorrection::Skin | ColourCorrection::Semantic => {
                let semantic = (recipe.post.colour == ColourCorrection::Semantic)
                    .then_some(recipe.post.membership);
                match self.skin_gains(f, recipe.base, semantic) {
                    Some(g) => Correction::PerGaussian(g),
                    None => Correction::None,
                }
            }
        }
    }
}
