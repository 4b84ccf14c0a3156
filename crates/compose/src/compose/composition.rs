//! Who contributes the Gaussians of each part of a composite, in the terms of
//! the thesis's study (§6.2.1): the face (always the base's), the eyes, the
//! nose, the mouth, and hair + neck + ears edited together ("NHE"). Random
//! composites are drawn in these terms, and constraints and study exclusions
//! are checked on them.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use super::recipe::Recipe;
use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::model::regions::Group;

/// A part of the head as the study edits and asks about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StudyGroup {
    /// Skin of the face: the base's Gaussians, never swapped.
    Face,
    /// Eye regions, sockets and eyeballs.
    Eyes,
    /// The nose.
    Nose,
    /// Lips, mouth interior and teeth (and so facial hair around them).
    Mouth,
    /// Hair, neck and ears, always edited together.
    Nhe,
}

impl StudyGroup {
    /// Every group, the face first.
    pub const ALL: [StudyGroup; 5] = [
        StudyGroup::Face,
        StudyGroup::Eyes,
        StudyGroup::Nose,
        StudyGroup::Mouth,
        StudyGroup::Nhe,
    ];

    /// The groups a random composite may edit and a participant is asked about.
    pub const EDITABLE: [StudyGroup; 4] = [
        StudyGroup::Eyes,
        StudyGroup::Nose,
        StudyGroup::Mouth,
        StudyGroup::Nhe,
    ];

    /// The name used in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            StudyGroup::Face => "face",
            StudyGroup::Eyes => "eyes",
            StudyGroup::Nose => "nose",
            StudyGroup::Mouth => "mouth",
            StudyGroup::Nhe => "nhe",
        }
    }

    /// The name as a participant reads it.
    pub fn label(self) -> &'static str {
        match self {
            StudyGroup::Face => "face",
            StudyGroup::Eyes => "eyes",
            StudyGroup::Nose => "nose",
            StudyGroup::Mouth => "mouth",
            StudyGroup::Nhe => "hair, neck and ears",
        }
    }

    /// Parses a name written by [`StudyGroup::name`].
    pub fn from_name(name: &str) -> Result<StudyGroup> {
        StudyGroup::ALL
            .into_iter()
            .find(|g| g.name() == name)
            .ok_or_else(|| {
                Error::input(format!(
                    "unknown group '{}' (groups: {})",
                    crate::text::printable(name),
                    StudyGroup::ALL.map(StudyGroup::name).join(", ")
                ))
            })
    }

    /// The editor groups this study group edits together.
    pub fn editor_groups(self) -> &'static [Group] {
        match self {
            StudyGroup::Face => &[Group::Face],
            StudyGroup::Eyes => &[Group::Eyes],
            StudyGroup::Nose => &[Group::Nose],
            StudyGroup::Mouth => &[Group::Mouth],
            StudyGroup::Nhe => &[Group::Hair, Group::Neck, Group::Ears],
        }
    }
}

/// Whose Gaussians each part of a composite shows.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Composition {
    /// The base source; the face and every group not listed show its Gaussians.
    pub base: String,
    /// Groups whose Gaussians come from another source than the base.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub groups: BTreeMap<StudyGroup, String>,
    /// Sources that contribute Gaussians to a part not known by name (a lost
    /// table cell in published data, or hair, neck and ears not edited as one).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unplaced: Vec<String>,
}

impl Composition {
    /// The composition a recipe shows. NHE is hair's source; a neck or ears
    /// edited apart from the hair count as unplaced sources.
    pub fn of_recipe(recipe: &Recipe) -> Composition {
        let source_of = |g: Group| {
            recipe
                .groups
                .get(g.name())
                .map_or(recipe.base.as_str(), |edit| edit.gaussians.as_str())
                .to_string()
        };
        let mut composition = Composition {
            base: recipe.base.clone(),
            ..Composition::default()
        };
        for group in StudyGroup::EDITABLE {
            let first = source_of(group.editor_groups()[0]);
            for &other in &group.editor_groups()[1..] {
                let source = source_of(other);
                if source != first && !composition.unplaced.contains(&source) {
                    composition.unplaced.push(source);
                }
            }
            if first != recipe.base {
                composition.groups.insert(group, first);
            }
        }
        let face = source_of(Group::Face);
        if face != recipe.base {
            composition.unplaced.push(face);
        }
        composition
    }

    /// The source of a group's Gaussians, when known.
    pub fn source(&self, group: StudyGroup) -> &str {
        match group {
            StudyGroup::Face => &self.base,
            g => self.groups.get(&g).unwrap_or(&self.base),
        }
    }

    /// Every source that contributes Gaussians, each once, the base first.
    pub fn gaussian_sources(&self) -> Vec<&str> {
        let mut all: Vec<&str> = vec![&self.base];
        for s in self.groups.values().chain(&self.unplaced) {
            if !all.contains(&s.as_str()) {
                all.push(s);
            }
        }
        all
    }

    /// True when some part shows another source's Gaussians than the base's.
    pub fn is_composite(&self) -> bool {
        !self.groups.is_empty() || !self.unplaced.is_empty()
    }
}

/// Labels per source (`skin_tone`, `gender`, …) that constraints and
/// exclusion rules test.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(transparent)]
pub struct Attributes(pub BTreeMap<String, BTreeMap<String, String>>);

impl Attributes {
    /// The labels the database carries for its sources.
    pub fn of_database(db: &Database) -> Attributes {
        Attributes(
            db.sources
                .iter()
                .map(|s| (s.name.clone(), s.attributes.clone()))
                .collect(),
        )
    }

    /// Parses a file of one table per source:
    /// `[ada]` then `skin_tone = "light"`.
    pub fn from_toml(text: &str) -> Result<Attributes> {
        toml::from_str(text)
            .map_err(|e| Error::input(format!("invalid attributes: {}", e.message().trim())))
    }

    /// Reads an attributes file.
    pub fn load(path: &std::path::Path) -> Result<Attributes> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read attributes {}: {e}", path.display())))?;
        Self::from_toml(&text).map_err(|e| Error::input(format!("{}: {e}", path.display())))
    }

    /// These labels with `other`'s on top (a file overriding the database).
    pub fn overlaid(mut self, other: Attributes) -> Attributes {
        for (source, labels) in other.0 {
            self.0.entry(source).or_default().extend(labels);
        }
        self
    }

    /// A source's label, or an error naming what is missing.
    pub fn get(&self, source: &str, key: &str) -> Result<&str> {
        self.0
            .get(source)
            .and_then(|labels| labels.get(key))
            .map(String::as_str)
            .ok_or_else(|| {
                Error::input(format!(
                    "source '{}' has no '{}' attribute (give it one in the database or an attributes file)",
                    crate::text::printable(source),
                    crate::text::printable(key)
                ))
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compose::recipe::GroupEdit;

    fn edit(source: &str) -> GroupEdit {
        GroupEdit {
            gaussians: source.into(),
            shape: BTreeMap::new(),
        }
    }

    #[test]
    fn a_recipe_reads_as_the_study_groups_it_edits() {
        let mut recipe = Recipe::unedited("ada");
        recipe.groups.insert("nose".into(), edit("bram"));
        recipe.groups.insert("mouth".into(), edit("ada"));
        for g in ["hair", "neck", "ears"] {
            recipe.groups.insert(g.into(), edit("cleo"));
        }
        let c = Composition::of_recipe(&recipe);
        assert_eq!(c.source(StudyGroup::Nose), "bram");
        assert_eq!(c.source(StudyGroup::Nhe), "cleo");
        assert_eq!(c.source(StudyGroup::Face), "ada");
        assert!(
            !c.groups.contains_key(&StudyGroup::Mouth),
            "the base's own mouth"
        );
        assert!(c.unplaced.is_empty());
        assert_eq!(c.gaussian_sources(), ["ada", "bram", "cleo"]);

        // Ears apart from the hair: still seen as a contributing source.
        recipe.groups.insert("ears".into(), edit("dries"));
        let c = Composition::of_recipe(&recipe);
        assert_eq!(c.unplaced, ["dries"]);
        assert!(c.gaussian_sources().contains(&"dries"));
    }

    #[test]
    fn missing_attributes_are_named() {
        let a = Attributes::from_toml("[ada]\nskin_tone = \"light\"\n").unwrap();
        assert_eq!(a.get("ada", "skin_tone").unwrap(), "light");
        let e = a.get("ada", "gender").unwrap_err().to_string();
        assert!(e.contains("'gender'") && e.contains("'ada'"), "{e}");
        assert!(Attributes::from_toml("[ada]\nskin_tone = 3\n").is_err());
    }
}
