//! Per-avatar study results: the exchange format `study analyse` reads (a
//! published table such as the thesis's Appendix B) and writes (a study's
//! answers, tallied).
//!
//! ```toml
//! participants = 22                 # answers per avatar unless an avatar says
//!
//! [[avatar]]
//! id = 16
//! category = "edit_original"
//! base = "074"
//! groups = { nhe = "253", mouth = "165" }   # groups showing another source's Gaussians
//! unplaced = ["238"]                # sources whose group is unknown (optional)
//! authenticity = 0.41               # share of "no" to "Is this face edited?"
//! regions = { eyes = 0.82, mouth = 0.82, nose = 0.91, nhe = 0.59 }  # share not flagging each
//! answers = 22                      # optional, else `participants`
//! excluded = ["Skin tone"]          # exclusions as published (optional)
//! note = "…"                        # optional
//! ```

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::compose::composition::{Composition, StudyGroup};
use crate::error::{Error, Result};

/// One avatar's tallied answers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AvatarResult {
    /// The avatar's number in the study.
    pub id: u32,
    /// Its category.
    pub category: String,
    /// The base source.
    pub base: String,
    /// Groups showing another source's Gaussians.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub groups: BTreeMap<StudyGroup, String>,
    /// Contributing sources whose group is unknown.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub unplaced: Vec<String>,
    /// Share of participants answering "no" to "Is this face edited?".
    pub authenticity: f64,
    /// Per group, the share of participants who did not flag it as edited.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub regions: BTreeMap<StudyGroup, f64>,
    /// Number of participants who answered; `None` means the file's `participants`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answers: Option<u32>,
    /// Exclusions as published with the data (checked against, never applied).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub excluded: Vec<String>,
    /// Free text about the entry.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl AvatarResult {
    /// Whose Gaussians the avatar shows.
    pub fn composition(&self) -> Composition {
        Composition {
            base: self.base.clone(),
            groups: self.groups.clone(),
            unplaced: self.unplaced.clone(),
        }
    }
}

/// A study's results, avatar by avatar.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Results {
    /// Answers per avatar when an avatar does not give its own count.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub participants: Option<u32>,
    /// The avatars.
    #[serde(rename = "avatar", default)]
    pub avatars: Vec<AvatarResult>,
}

impl Results {
    /// Parses and checks a results file.
    pub fn from_toml(text: &str) -> Result<Results> {
        let results: Results = toml::from_str(text)
            .map_err(|e| Error::input(format!("invalid results: {}", e.message().trim())))?;
        results.check()?;
        Ok(results)
    }

    /// Reads a results file.
    pub fn load(path: &std::path::Path) -> Result<Results> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read results {}: {e}", path.display())))?;
        Self::from_toml(&text).map_err(|e| Error::input(format!("{}: {e}", path.display())))
    }

    /// The TOML text of these results.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("results always serialise")
    }

    /// The number of answers behind an avatar's scores.
    pub fn answers(&self, avatar: &AvatarResult) -> u32 {
        avatar.answers.or(self.participants).unwrap_or(0)
    }

    fn check(&self) -> Result<()> {
        let mut seen = std::collections::BTreeSet::new();
        for a in &self.avatars {
            if !seen.insert(a.id) {
                return Err(Error::input(format!("avatar {} is listed twice", a.id)));
            }
            let shares = std::iter::once(a.authenticity).chain(a.regions.values().copied());
            if shares.into_iter().any(|s| !(0.0..=1.0).contains(&s)) {
                return Err(Error::input(format!(
                    "avatar {}: scores must be shares between 0 and 1",
                    a.id
                )));
            }
            if a.regions.contains_key(&StudyGroup::Face) {
                return Err(Error::input(format!(
                    "avatar {}: regions are eyes, nose, mouth and nhe (the face is not asked about)",
                    a.id
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn results_round_trip_and_bad_ones_are_refused() {
        let text = r#"
participants = 4
[[avatar]]
id = 2
category = "edited"
base = "ada"
groups = { nose = "bram" }
authenticity = 0.25
regions = { nose = 0.5, eyes = 1.0 }
"#;
        let r = Results::from_toml(text).unwrap();
        assert_eq!(r.avatars[0].groups[&StudyGroup::Nose], "bram");
        assert_eq!(r.answers(&r.avatars[0]), 4);
        assert_eq!(Results::from_toml(&r.to_toml()).unwrap(), r);

        for bad in [
            text.replace("0.25", "1.5"),
            text.replace("nose = 0.5", "face = 0.5"),
            text.replace("groups = { nose", "groups = { chin"),
            format!(
                "{text}\n[[avatar]]\nid = 2\ncategory = \"x\"\nbase = \"a\"\nauthenticity = 1.0\n"
            ),
        ] {
            let e = Results::from_toml(&bad).unwrap_err().to_string();
            assert!(!e.contains('\n'), "{e}");
        }
    }
}
