//! Random composites by the thesis's rules (§6.2.1):
//! - three sources, one of them the base;
//! - edits apply to whole study groups (eyes, nose, mouth, and hair + neck +
//!   ears together as NHE);
//! - at least one group shows another source's Gaussians;
//! - at least one group's shape is blended over the three sources with
//!   weights from stick-breaking;
//! - NHE's shape is never blended: it follows the source of its Gaussians.
//!
//! Draws come from one ChaCha stream seeded by the caller, so a seed always
//! gives the same composites; draws breaking a constraint (or repeating an
//! earlier composite) are thrown away and drawn again.

use std::collections::BTreeMap;

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::composition::{Attributes, Composition, StudyGroup};
use super::recipe::{GroupEdit, Recipe};
use super::rules::{Context, Rules};
use crate::avatar::database::Database;
use crate::error::{Error, Result};

/// Sources in every random composite (the thesis's three).
pub const SOURCES_PER_COMPOSITE: usize = 3;

/// Draws tried per composite before giving up on the constraints.
pub const MAX_DRAWS: usize = 20_000;

/// Shape weights are written in thousandths, so recipes read cleanly.
const WEIGHT_STEPS: u32 = 1000;

/// What to draw.
#[derive(Clone, Debug)]
pub struct RandomOptions {
    /// Number of composites.
    pub count: usize,
    /// Seed of the draw.
    pub seed: u64,
    /// Sources to draw from; empty means the whole database.
    pub sources: Vec<String>,
    /// Groups that may be edited (a subset of [`StudyGroup::EDITABLE`]).
    pub groups: Vec<StudyGroup>,
    /// Constraints every composite meets.
    pub rules: Rules,
    /// Labels the constraints test.
    pub attributes: Attributes,
}

/// One drawn composite.
#[derive(Clone, Debug, PartialEq)]
pub struct RandomComposite {
    /// The recipe (default post-processing, animation and camera).
    pub recipe: Recipe,
    /// Whose Gaussians each group shows.
    pub composition: Composition,
    /// The three sources, the base first.
    pub sources: Vec<String>,
    /// Groups whose shape is blended, with their weights by source.
    pub blended: BTreeMap<StudyGroup, BTreeMap<String, f64>>,
}

/// Draws `options.count` distinct composites meeting the constraints.
pub fn random_composites(db: &Database, options: &RandomOptions) -> Result<Vec<RandomComposite>> {
    let pool = source_pool(db, &options.sources)?;
    let groups = editable_groups(&options.groups)?;
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    let mut drawn: Vec<RandomComposite> = Vec::with_capacity(options.count);
    let mut last_reason = String::new();
    while drawn.len() < options.count {
        let mut accepted = None;
        for _ in 0..MAX_DRAWS {
            let candidate = draw(&mut rng, &pool, &groups);
            let broken = options.rules.broken(
                &candidate.composition,
                Context::default(),
                &options.attributes,
            )?;
            if let Some(reason) = broken.into_iter().next() {
                last_reason = reason;
                continue;
            }
            if drawn.iter().any(|d| d.recipe == candidate.recipe) {
                last_reason = "repeats an earlier composite".into();
                continue;
            }
            accepted = Some(candidate);
            break;
        }
        let Some(candidate) = accepted else {
            return Err(Error::input(format!(
                "found only {} of {} composites meeting the constraints in {MAX_DRAWS} draws (last refusal: {last_reason}); allow more sources or relax the rules",
                drawn.len(),
                options.count
            )));
        };
        drawn.push(candidate);
    }
    Ok(drawn)
}

/// The sources to draw from, checked against the database.
fn source_pool(db: &Database, names: &[String]) -> Result<Vec<String>> {
    let pool: Vec<String> = if names.is_empty() {
        db.sources.iter().map(|s| s.name.clone()).collect()
    } else {
        for n in names {
            if db.source_index(n).is_none() {
                return Err(Error::input(format!(
                    "unknown source '{}' in --sources",
                    crate::text::printable(n)
                )));
            }
        }
        let mut unique: Vec<String> = Vec::with_capacity(names.len());
        for n in names {
            if !unique.contains(n) {
                unique.push(n.clone());
            }
        }
        unique
    };
    if pool.len() < SOURCES_PER_COMPOSITE {
        return Err(Error::input(format!(
            "random composites need at least {SOURCES_PER_COMPOSITE} sources, and {} were given",
            pool.len()
        )));
    }
    Ok(pool)
}

/// The editable groups, checked: at least one must be able to blend shape.
fn editable_groups(groups: &[StudyGroup]) -> Result<Vec<StudyGroup>> {
    let chosen: Vec<StudyGroup> = if groups.is_empty() {
        StudyGroup::EDITABLE.to_vec()
    } else {
        groups.to_vec()
    };
    if chosen.contains(&StudyGroup::Face) {
        return Err(Error::input(
            "the face always shows the base; choose --groups from eyes, nose, mouth, nhe",
        ));
    }
    if !chosen.iter().any(|&g| g != StudyGroup::Nhe) {
        return Err(Error::input(
            "--groups needs eyes, nose or mouth: NHE's shape is never blended, and every composite blends one group's shape",
        ));
    }
    Ok(chosen)
}

/// One draw by the thesis's rules (constraints not yet checked).
fn draw(rng: &mut ChaCha8Rng, pool: &[String], groups: &[StudyGroup]) -> RandomComposite {
    let mut picks = pool.to_vec();
    picks.shuffle(rng);
    picks.truncate(SOURCES_PER_COMPOSITE);
    let base = picks[0].clone();
    let extras = &picks[1..];

    let mut gaussians: BTreeMap<StudyGroup, String> = BTreeMap::new();
    for &g in groups {
        if rng.random_bool(0.5) {
            gaussians.insert(g, extras[rng.random_range(0..extras.len())].clone());
        }
    }
    if gaussians.is_empty() {
        let g = groups[rng.random_range(0..groups.len())];
        gaussians.insert(g, extras[rng.random_range(0..extras.len())].clone());
    }

    let blendable: Vec<StudyGroup> = groups
        .iter()
        .copied()
        .filter(|&g| g != StudyGroup::Nhe)
        .collect();
    let mut blended_groups: Vec<StudyGroup> = blendable
        .iter()
        .copied()
        .filter(|_| rng.random_bool(0.5))
        .collect();
    if blended_groups.is_empty() {
        blended_groups.push(blendable[rng.random_range(0..blendable.len())]);
    }
    let blended: BTreeMap<StudyGroup, BTreeMap<String, f64>> = blended_groups
        .into_iter()
        .map(|g| (g, stick_breaking(rng, &picks)))
        .collect();

    let mut recipe = Recipe::unedited(&base);
    for &group in groups {
        let source = gaussians.get(&group).unwrap_or(&base);
        let shape = match (group, blended.get(&group)) {
            (_, Some(weights)) => weights.clone(),
            (StudyGroup::Nhe, None) if *source != base => BTreeMap::from([(source.clone(), 1.0)]),
            _ => BTreeMap::new(),
        };
        if *source == base && shape.is_empty() {
            continue;
        }
        for g in group.editor_groups() {
            recipe.groups.insert(
                g.name().to_string(),
                GroupEdit {
                    gaussians: source.clone(),
                    shape: shape.clone(),
                },
            );
        }
    }
    RandomComposite {
        composition: Composition::of_recipe(&recipe),
        recipe,
        sources: picks,
        blended,
    }
}

/// Convex weights over `sources` by stick-breaking in a random order: each
/// source in turn takes a uniform share of what is left, the last takes the
/// rest. Rounded to thousandths that still sum to exactly 1.
fn stick_breaking(rng: &mut ChaCha8Rng, sources: &[String]) -> BTreeMap<String, f64> {
    let mut order = sources.to_vec();
    order.shuffle(rng);
    let mut left = WEIGHT_STEPS;
    let mut weights = BTreeMap::new();
    for (i, source) in order.iter().enumerate() {
        let take = if i + 1 == order.len() {
            left
        } else {
            (rng.random::<f64>() * left as f64).round() as u32
        };
        left -= take;
        weights.insert(source.clone(), take as f64 / WEIGHT_STEPS as f64);
    }
    weights
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("s{i}")).collect()
    }

    #[test]
    fn every_draw_follows_the_thesis_rules() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let pool = names(6);
        for _ in 0..500 {
            let c = draw(&mut rng, &pool, &StudyGroup::EDITABLE);
            assert_eq!(c.sources.len(), 3);
            assert_eq!(c.recipe.base, c.sources[0]);
            assert!(c.composition.is_composite(), "{:?}", c.recipe);
            for s in c.composition.gaussian_sources() {
                assert!(c.sources.iter().any(|p| p == s));
            }
            assert!(!c.blended.is_empty());
            assert!(!c.blended.contains_key(&StudyGroup::Nhe));
            for weights in c.blended.values() {
                let sum: f64 = weights.values().sum();
                assert!((sum - 1.0).abs() < 1e-12, "{weights:?}");
                assert!(weights.values().all(|&w| (0.0..=1.0).contains(&w)));
                assert_eq!(weights.len(), 3);
            }
            // NHE moves as one, and its shape follows its Gaussians.
            let hair = c.recipe.groups.get("hair");
            assert_eq!(hair, c.recipe.groups.get("neck"));
            assert_eq!(hair, c.recipe.groups.get("ears"));
            if let Some(edit) = hair {
                assert_eq!(edit.shape, BTreeMap::from([(edit.gaussians.clone(), 1.0)]));
            }
            assert!(c.composition.unplaced.is_empty());
        }
    }

    #[test]
    fn stick_breaking_weights_vary_and_stay_convex() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let pool = names(3);
        let firsts: Vec<f64> = (0..200)
            .map(|_| stick_breaking(&mut rng, &pool)["s0"])
            .collect();
        let mean = firsts.iter().sum::<f64>() / firsts.len() as f64;
        // Each source is first, second or last equally often: mean share 1/3.
        assert!((mean - 1.0 / 3.0).abs() < 0.06, "{mean}");
        assert!(firsts.iter().any(|&w| w > 0.7) && firsts.iter().any(|&w| w < 0.05));
    }

    #[test]
    fn restricted_groups_are_the_only_ones_edited() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        for _ in 0..100 {
            let c = draw(&mut rng, &names(4), &[StudyGroup::Nose]);
            let keys: Vec<&String> = c.recipe.groups.keys().collect();
            assert_eq!(keys, ["nose"]);
        }
        assert!(editable_groups(&[StudyGroup::Nhe]).is_err());
        assert!(editable_groups(&[StudyGroup::Face]).is_err());
    }
}
