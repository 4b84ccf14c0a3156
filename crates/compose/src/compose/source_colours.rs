//! What each source's own colours say about it, worked out once per
//! database: its skin statistics, the colours its capture's cameras saw, the
//! light baked into them, its hair's brightness and hue, and where each
//! Gaussian sits in that light — and the semantic skin transfer's rule for
//! one Gaussian (docs/method.md §7.7), which reads them.

use glam::Vec3;
use rayon::prelude::*;

use super::clothing;
use super::colour::{
    chromaticity, hair_colour, hair_display_chromaticity, lab_to_srgb, seen_colours,
};
use super::dark_features;
use super::recipe::Membership;
use super::selection::SelectionTables;
use super::shading::{source_light, vertex_exposures, BakedLight, Exposure};
use super::skin_transfer::{
    gain_by_channel_share, semantic_skin_gain_at, semantic_skin_gain_shared,
    semantic_skin_likeness, skin_stats, whole_skin_gain_shared, SkinPlace, SkinStats,
    SKIN_REFERENCE_REGIONS,
};
use crate::avatar::database::Database;
use crate::model::regions::Region;

/// Per source, what its colours say about its skin, hair and light.
pub struct SourceColours {
    /// Skin statistics per source.
    skin: Vec<Option<SkinStats>>,
    /// `[source]` → each Gaussian's colour as the capture's cameras saw it,
    /// what its skin likeness and colour transfer judge it by.
    seen: Vec<Vec<Vec3>>,
    /// The light baked into each source's colours, fitted to its skin.
    lights: Vec<Option<BakedLight>>,
    /// Per source, its hair's brightness relative to its skin tone: the
    /// darkest brows and lashes its eye regions' skin Gaussians may mix with
    /// (`dark_features`, method §7.7).
    hair_brightness: Vec<Option<f32>>,
    /// Per source, its hair's mean chromaticity in display values
    /// (`colour::hair_display_chromaticity`): what a Gaussian round the eyes
    /// is unmixed against (`dark_features::skin_shares_by_colour`); `None`
    /// where the hair's hue does not tell it from the skin tone
    /// (`dark_features::hue_tells_apart`).
    hair_hue: Vec<Option<Vec3>>,
    /// `[source]` → the exposure where each Gaussian sits on its parent
    /// triangle of the source's neutral mesh.
    exposures: Vec<Vec<Exposure>>,
}

impl SourceColours {
    /// Works out every source's colour facts: `neutrals` are the sources'
    /// neutral meshes and `placements` where each Gaussian sits on its
    /// parent triangle (barycentric), per source.
    pub fn new(
        db: &Database,
        tables: &SelectionTables,
        neutrals: &[Vec<Vec3>],
        placements: &[Vec<[f32; 3]>],
    ) -> Self {
        let sources = 0..db.sources.len();
        // Each source's Gaussians of the regions its skin is judged by.
        let skin_indices: Vec<Vec<u32>> = sources
            .clone()
            .map(|f| {
                SKIN_REFERENCE_REGIONS
                    .iter()
                    .flat_map(|&r| tables.region(Membership::Parent, f, r).iter().copied())
                    .collect()
            })
            .collect();
        // The exposure where each Gaussian sits: what its colour's baked
        // light depends on.
        let exposures: Vec<Vec<Exposure>> = sources
            .clone()
            .into_par_iter()
            .map(|f| {
                let vertex = vertex_exposures(&neutrals[f], &db.model.triangles);
                db.sources[f]
                    .gaussians
                    .binding
                    .iter()
                    .zip(&placements[f])
                    .map(|(&t, &bary)| {
                        db.model
                            .triangles
                            .get(t as usize)
                            .map_or_else(Exposure::default, |&tri| Exposure::at(&vertex, tri, bary))
                    })
                    .collect()
            })
            .collect();
        let seen: Vec<Vec<Vec3>> = db
            .sources
            .iter()
            .map(|source| seen_colours(&source.gaussians))
            .collect();
        let (hair, hair_chromaticity): (Vec<Option<Vec3>>, Vec<Option<Vec3>>) = sources
            .clone()
            .map(|f| {
                let (set, indices) = (
                    &db.sources[f].gaussians,
                    tables.region(Membership::Parent, f, Region::Hair),
                );
                (
                    hair_colour(set, &seen[f], indices),
                    hair_display_chromaticity(set, &seen[f], indices),
                )
            })
            .unzip();
        let skin: Vec<Option<SkinStats>> = sources
            .clone()
            .into_par_iter()
            .map(|f| {
                skin_stats(&db.sources[f].gaussians, &seen[f], &skin_indices[f])
                    .map(|s| s.beside_hair(hair[f].and_then(chromaticity)))
            })
            .collect();
        let hair_brightness = sources
            .clone()
            .map(|f| dark_features::hair_brightness(hair[f]?, skin[f].as_ref()?))
            .collect();
        let hair_hue = hair_chromaticity
            .iter()
            .zip(&skin)
            .map(|(&hair, skin)| {
                let tone = lab_to_srgb(skin.as_ref()?.tone);
                hair.filter(|&h| dark_features::hue_tells_apart(tone, h))
            })
            .collect();
        let lights = sources
            .into_par_iter()
            .map(|f| {
                source_light(
                    &db.sources[f].gaussians,
                    &exposures[f],
                    &skin_indices[f],
                    skin[f].as_ref(),
                )
            })
            .collect();
        Self {
            skin,
            seen,
            lights,
            hair_brightness,
            hair_hue,
            exposures,
        }
    }

    /// Source `f`'s skin statistics; `None` where it shows too little skin.
    pub fn skin(&self, f: usize) -> Option<&SkinStats> {
        self.skin.get(f)?.as_ref()
    }

    /// Each of source `f`'s Gaussians' colour as the capture's cameras saw it.
    pub fn seen(&self, f: usize) -> &[Vec3] {
        &self.seen[f]
    }

    /// The light baked into source `f`'s colours; `None` where none was fitted.
    pub fn light(&self, f: usize) -> Option<&BakedLight> {
        self.lights.get(f)?.as_ref()
    }

    /// The exposure where each of source `f`'s Gaussians sits on its parent
    /// triangle of the source's neutral mesh.
    pub fn exposures(&self, f: usize) -> &[Exposure] {
        &self.exposures[f]
    }

    /// Whether the skin transfer from source `from` to source `to` brightens
    /// (`dark_features::transfer_brightens`); false where either has no
    /// skin statistics.
    pub fn transfer_brightens(&self, from: usize, to: usize) -> bool {
        match (self.skin(from), self.skin(to)) {
            (Some(from), Some(to)) => dark_features::transfer_brightens(from, to),
            _ => false,
        }
    }

    /// The semantic skin transfer's gain (method §7.7) for Gaussian `i` of
    /// source `f`, counted at `place`, from `f`'s skin `from` to the base's
    /// `to`; `brightens` says whether that transfer brightens and `clothing`
    /// is the mean linear colour of `f`'s clothing in the region, if it
    /// shows any. The first rule that applies decides:
    /// - skin mixed with clothing moves by its share of skin;
    /// - brightening, on the hairline (the remainder) where a dark feature
    ///   can be told from skin, by the skin's share of brightness, gated by
    ///   the likeness (`dark_features::hairline_share`);
    /// - darkening round the eyes, where a dark feature can be told, by the
    ///   skin's share per channel where the hair's hue tells it from skin,
    ///   else by its share of brightness — blended by the likeness with the
    ///   likeness's own transfer (`dark_features::darkening_gain`);
    /// - otherwise by the region's likeness (touching the hair, at most the
    ///   hairline's in the ears and the face:
    ///   `skin_transfer::semantic_skin_likeness_at`),
    ///   taken (brightening, round the eyes) the skin's share of brightness
    ///   of the way where it can be told.
    pub fn semantic_gain(
        &self,
        f: usize,
        i: usize,
        place: SkinPlace,
        (from, to): (&SkinStats, &SkinStats),
        brightens: bool,
        clothing: Option<Vec3>,
    ) -> Vec3 {
        let region = place.region;
        let rgb = self.seen[f][i];
        if let Some(share) = clothing.and_then(|c| self.skin_share_beside(f, i, c)) {
            return whole_skin_gain_shared(rgb, from, to, share);
        }
        let likeness = || semantic_skin_likeness(rgb, region, from).unwrap_or(0.0);
        if brightens && dark_features::moved_by_brightness_share(region) {
            if let Some(share) = self.tellable_skin_share(f, i) {
                let share = dark_features::hairline_share(likeness(), share);
                return whole_skin_gain_shared(rgb, from, to, share);
            }
        }
        if !brightens && dark_features::holds_dark_features(region) {
            if let Some(share) = self.tellable_skin_share(f, i) {
                let by_share = match self.skin_shares_in_colour(f, i) {
                    // The mixed colour's own transfer measured better than
                    // that of the skin the light predicts (method §7.7,
                    // session 45).
                    Some(shares) => {
                        gain_by_channel_share(whole_skin_gain_shared(rgb, from, to, 1.0), shares)
                    }
                    None => whole_skin_gain_shared(rgb, from, to, share),
                };
                return dark_features::darkening_gain(
                    likeness(),
                    semantic_skin_gain_shared(rgb, region, from, to, 1.0),
                    by_share,
                );
            }
        }
        if !dark_features::holds_dark_features(region) {
            return semantic_skin_gain_at(rgb, place, from, to);
        }
        let share = if brightens {
            self.tellable_skin_share(f, i).unwrap_or(1.0)
        } else {
            1.0
        };
        semantic_skin_gain_shared(rgb, region, from, to, share)
    }

    /// The share of Gaussian `i` of source `f`'s brightness that is skin
    /// where it mixes skin with clothing of mean linear colour `clothing`
    /// (the `clothing` module), by the skin's colour the source's light
    /// shows there; `None` where the source has no light or the colour is
    /// no such mix.
    fn skin_share_beside(&self, f: usize, i: usize, clothing: Vec3) -> Option<f32> {
        let skin = self.light(f)?.brightness(self.exposures[f][i]);
        clothing::skin_share_beside_clothing(self.seen[f][i], skin, clothing)
    }

    /// Per channel, the share of Gaussian `i` of source `f`'s colour that is
    /// skin, unmixed into the skin its light predicts there and its hair
    /// (`dark_features::skin_shares_by_colour`); `None` where the source has
    /// no hair or light, or its hair's hue does not tell it from its skin.
    fn skin_shares_in_colour(&self, f: usize, i: usize) -> Option<Vec3> {
        let hair = self.hair_hue[f]?;
        let skin = self
            .light(f)?
            .brightness(self.exposures[f][i])
            .clamp(Vec3::ZERO, Vec3::ONE);
        let colour = self.seen[f][i].clamp(Vec3::ZERO, Vec3::ONE);
        dark_features::skin_shares_by_colour(colour, skin, hair)
    }

    /// The share of Gaussian `i` of source `f`'s brightness that is skin,
    /// where a brow or lash of the source's hair's brightness may be mixed
    /// in (`dark_features::skin_share_of_brightness`); `None` where that
    /// cannot be told ([`SourceColours::brightness_against_hair`]).
    fn tellable_skin_share(&self, f: usize, i: usize) -> Option<f32> {
        self.brightness_against_hair(f, i)
            .map(|(r, h)| dark_features::skin_share_of_brightness(r, h))
    }

    /// Gaussian `i` of source `f`'s brightness relative to the skin where it
    /// sits, by the source's light, and its hair's relative to its skin
    /// tone (`dark_features`); `None` where the source has no hair, hair too
    /// light to tell from its skin (`dark_features::is_tellable`), no light,
    /// or a light that predicts black at the Gaussian's place.
    pub fn brightness_against_hair(&self, f: usize, i: usize) -> Option<(f32, f32)> {
        let feature = self.hair_brightness[f].filter(|&h| dark_features::is_tellable(h))?;
        let at = self.exposures[f][i];
        let r = dark_features::relative_brightness(self.light(f)?, at, self.seen[f][i])?;
        Some((r, feature))
    }
}
