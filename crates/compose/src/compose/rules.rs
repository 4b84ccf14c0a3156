//! Rules on compositions, written as data: the constraints random composites
//! must meet and the exclusions a study analysis applies (thesis §6.3.1). One
//! language serves both, so "no mixed skin tones" means the same thing when
//! generating and when analysing.
//!
//! ```toml
//! [[rule]]
//! reason = "Skin tone"            # shown when the rule is broken
//! same = "skin_tone"              # every Gaussian source shares this label…
//! # groups = ["face", "nhe"]      # …or only these groups' sources
//!
//! [[rule]]
//! reason = "Gender"
//! forbid = { mouth = { gender = "male" }, face = { gender = "female" } }
//!
//! [[rule]]
//! reason = "Subject 175"
//! avoid = "175"                   # no Gaussians from this source
//! categories = ["edit_filling"]   # only for avatars of these study categories
//!
//! [[rule]]
//! reason = "Gender"
//! avatars = [18, 29]              # these study avatars, by number (a published list)
//! ```

use std::collections::BTreeMap;

use serde::Deserialize;

use super::composition::{Attributes, Composition, StudyGroup};
use crate::error::{Error, Result};

/// What a rule checks.
#[derive(Clone, Debug, PartialEq)]
pub enum Test {
    /// The Gaussian sources (of `groups`, or all of them) share one value of
    /// the attribute.
    Same {
        /// The attribute compared.
        attribute: String,
        /// The groups whose sources are compared; `None` means every source
        /// that contributes Gaussians, unplaced ones included.
        groups: Option<Vec<StudyGroup>>,
    },
    /// Broken when every listed group's source carries all the listed labels.
    Forbid(Vec<(StudyGroup, BTreeMap<String, String>)>),
    /// Broken when the source contributes any Gaussians.
    Avoid(String),
    /// Broken by the study avatars with these numbers (an exclusion list
    /// published without the data to derive it).
    Listed(Vec<u32>),
}

/// Where a composition is judged: its study category and avatar number,
/// when it has them (random generation has neither).
#[derive(Clone, Copy, Debug, Default)]
pub struct Context<'a> {
    /// The study category.
    pub category: Option<&'a str>,
    /// The avatar's number in the study.
    pub avatar: Option<u32>,
}

/// One named rule.
#[derive(Clone, Debug, PartialEq)]
pub struct Rule {
    /// Why a composition breaking it is refused or excluded.
    pub reason: String,
    /// The check.
    pub test: Test,
    /// Study categories the rule applies to; `None` means all (and random
    /// generation, which has no category, applies only rules without a list).
    pub categories: Option<Vec<String>>,
}

/// An ordered list of rules.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Rules(pub Vec<Rule>);

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RuleFile {
    #[serde(default)]
    rule: Vec<RuleSpec>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RuleSpec {
    reason: String,
    same: Option<String>,
    groups: Option<Vec<String>>,
    forbid: Option<BTreeMap<String, BTreeMap<String, String>>>,
    avoid: Option<String>,
    avatars: Option<Vec<u32>>,
    categories: Option<Vec<String>>,
}

impl RuleSpec {
    fn into_rule(self) -> Result<Rule> {
        let reason = self.reason;
        let groups = self
            .groups
            .map(|names| {
                names
                    .iter()
                    .map(|n| StudyGroup::from_name(n))
                    .collect::<Result<Vec<_>>>()
            })
            .transpose()?;
        let test = match (self.same, self.forbid, self.avoid, self.avatars) {
            (Some(attribute), None, None, None) => Test::Same { attribute, groups },
            (None, Some(forbid), None, None) if groups.is_none() && !forbid.is_empty() => Test::Forbid(
                forbid
                    .into_iter()
                    .map(|(g, labels)| Ok((StudyGroup::from_name(&g)?, labels)))
                    .collect::<Result<Vec<_>>>()?,
            ),
            (None, None, Some(source), None) if groups.is_none() => Test::Avoid(source),
            (None, None, None, Some(avatars)) if groups.is_none() => Test::Listed(avatars),
            _ => {
                return Err(Error::input(format!(
                    "rule '{}' needs exactly one of same (with optional groups), forbid, avoid or avatars",
                    crate::text::printable(&reason)
                )))
            }
        };
        Ok(Rule {
            reason,
            test,
            categories: self.categories,
        })
    }
}

impl Rules {
    /// Parses `[[rule]]` tables; errors name the problem in one line.
    pub fn from_toml(text: &str) -> Result<Rules> {
        let file: RuleFile = toml::from_str(text)
            .map_err(|e| Error::input(format!("invalid rules: {}", e.message().trim())))?;
        Ok(Rules(
            file.rule
                .into_iter()
                .map(RuleSpec::into_rule)
                .collect::<Result<_>>()?,
        ))
    }

    /// Reads a rules file.
    pub fn load(path: &std::path::Path) -> Result<Rules> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read rules {}: {e}", path.display())))?;
        Self::from_toml(&text).map_err(|e| Error::input(format!("{}: {e}", path.display())))
    }

    /// The reasons of the rules `composition` breaks (each reason once, in
    /// rule order). The context's category selects the rules that apply.
    pub fn broken(
        &self,
        composition: &Composition,
        context: Context,
        attributes: &Attributes,
    ) -> Result<Vec<String>> {
        let mut reasons: Vec<String> = Vec::new();
        for rule in &self.0 {
            let applies = match (&rule.categories, context.category) {
                (None, _) => true,
                (Some(list), Some(c)) => list.iter().any(|l| l == c),
                (Some(_), None) => false,
            };
            if applies
                && rule.is_broken(composition, context, attributes)?
                && !reasons.contains(&rule.reason)
            {
                reasons.push(rule.reason.clone());
            }
        }
        Ok(reasons)
    }
}

impl Rule {
    /// True when the composition breaks this rule.
    pub fn is_broken(
        &self,
        composition: &Composition,
        context: Context,
        attributes: &Attributes,
    ) -> Result<bool> {
        match &self.test {
            Test::Same { attribute, groups } => {
                let sources: Vec<&str> = match groups {
                    None => composition.gaussian_sources(),
                    Some(gs) => gs.iter().map(|&g| composition.source(g)).collect(),
                };
                let mut values = Vec::new();
                for s in sources {
                    let v = attributes.get(s, attribute)?;
                    if !values.contains(&v) {
                        values.push(v);
                    }
                }
                Ok(values.len() > 1)
            }
            Test::Forbid(conditions) => {
                for (group, labels) in conditions {
                    let source = composition.source(*group);
                    for (key, value) in labels {
                        if attributes.get(source, key)? != value {
                            return Ok(false);
                        }
                    }
                }
                Ok(true)
            }
            Test::Avoid(source) => Ok(composition.gaussian_sources().contains(&source.as_str())),
            Test::Listed(avatars) => Ok(context.avatar.is_some_and(|a| avatars.contains(&a))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const RULES: &str = r#"
[[rule]]
reason = "Skin tone"
same = "skin_tone"

[[rule]]
reason = "Gender"
same = "gender"
groups = ["face", "nhe"]

[[rule]]
reason = "Gender"
forbid = { mouth = { gender = "male" }, face = { gender = "female" } }

[[rule]]
reason = "Subject 175"
avoid = "175"
categories = ["edit_filling"]
"#;

    const LABELS: &str = r#"
a = { skin_tone = "light", gender = "female" }
b = { skin_tone = "light", gender = "male" }
c = { skin_tone = "dark", gender = "female" }
175 = { skin_tone = "light", gender = "female" }
"#;

    fn composition(base: &str, groups: &[(StudyGroup, &str)]) -> Composition {
        Composition {
            base: base.into(),
            groups: groups.iter().map(|&(g, s)| (g, s.to_string())).collect(),
            unplaced: Vec::new(),
        }
    }

    #[test]
    fn rules_name_what_each_composition_breaks() {
        let rules = Rules::from_toml(RULES).unwrap();
        let labels = Attributes::from_toml(LABELS).unwrap();
        let broken = |c: &Composition, category| {
            let context = Context {
                category,
                avatar: None,
            };
            rules.broken(c, context, &labels).unwrap()
        };

        assert!(broken(&composition("a", &[(StudyGroup::Eyes, "175")]), None).is_empty());
        assert_eq!(
            broken(
                &composition("a", &[(StudyGroup::Eyes, "175")]),
                Some("edit_filling")
            ),
            ["Subject 175"]
        );
        assert_eq!(
            broken(&composition("a", &[(StudyGroup::Nose, "c")]), None),
            ["Skin tone"]
        );
        // A male mouth on a female face, and a male NHE on a female face:
        // one reason, given once.
        assert_eq!(
            broken(&composition("a", &[(StudyGroup::Mouth, "b")]), None),
            ["Gender"]
        );
        assert_eq!(
            broken(&composition("a", &[(StudyGroup::Nhe, "b")]), None),
            ["Gender"]
        );
        // A female mouth on a male face is allowed.
        assert!(broken(&composition("b", &[(StudyGroup::Mouth, "a")]), None).is_empty());
        // An unplaced source still counts for "every source".
        let mut c = composition("a", &[]);
        c.unplaced.push("c".into());
        assert_eq!(broken(&c, None), ["Skin tone"]);

        let listed = Rules::from_toml("[[rule]]\nreason = \"Listed\"\navatars = [4, 9]\n").unwrap();
        let at = |avatar| Context {
            category: None,
            avatar,
        };
        let c = composition("a", &[]);
        assert_eq!(listed.broken(&c, at(Some(9)), &labels).unwrap(), ["Listed"]);
        assert!(listed.broken(&c, at(Some(5)), &labels).unwrap().is_empty());
        assert!(listed.broken(&c, at(None), &labels).unwrap().is_empty());
    }

    #[test]
    fn malformed_rules_fail_with_one_line() {
        for bad in [
            "[[rule]]\nreason = \"x\"\n",
            "[[rule]]\nreason = \"x\"\nsame = \"a\"\navoid = \"b\"\n",
            "[[rule]]\nreason = \"x\"\nsame = \"a\"\ngroups = [\"chin\"]\n",
            "[[rule]]\nreason = \"x\"\nforbid = {}\n",
            "[[rule]]\nreason = \"x\"\nsame = \"a\"\ncolour = 1\n",
            "[[rule]]\nreason = \"x\"\navatars = [1]\ngroups = [\"face\"]\n",
        ] {
            let e = Rules::from_toml(bad).unwrap_err().to_string();
            assert!(!e.contains('\n'), "{e}");
        }
        let rules = Rules::from_toml("[[rule]]\nreason = \"x\"\nsame = \"height\"\n").unwrap();
        let labels = Attributes::from_toml(LABELS).unwrap();
        let e = rules
            .broken(&composition("a", &[]), Context::default(), &labels)
            .unwrap_err();
        assert!(e.to_string().contains("'height'"), "{e}");
    }
}
