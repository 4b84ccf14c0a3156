//! The study's numbers (thesis §6.3): each avatar's authenticity score (the
//! share of "no" to "Is this face edited?"), the mean per category with a
//! bootstrap confidence interval, the same after excluding implausible
//! avatars by rules, and per-region scores for edited and unedited regions
//! (Figure 6.4).
//!
//! Published scores are rounded to two decimals; where the number of answers
//! is known each share is snapped back to a whole count of answers, so means
//! come out as the authors computed them.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::results::{AvatarResult, Results};
use crate::compose::composition::{Attributes, StudyGroup};
use crate::compose::rules::{Context, Rules};
use crate::error::Result;

/// Two-sided coverage of every interval reported.
pub const CONFIDENCE: f64 = 0.95;
/// The standard normal quantile for [`CONFIDENCE`].
const Z: f64 = 1.959_963_984_540_054;

/// How to analyse.
#[derive(Clone, Debug)]
pub struct AnalysisOptions {
    /// Exclusion rules; `None` analyses every avatar only.
    pub exclude: Option<Rules>,
    /// Labels the rules test.
    pub attributes: Attributes,
    /// Bootstrap resamples per interval.
    pub resamples: usize,
    /// Seed of the bootstrap.
    pub seed: u64,
}

impl Default for AnalysisOptions {
    fn default() -> Self {
        Self {
            exclude: None,
            attributes: Attributes::default(),
            resamples: 10_000,
            seed: 1,
        }
    }
}

/// A mean with its confidence interval over the avatars behind it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Estimate {
    /// Mean score.
    pub mean: f64,
    /// Lower end of the bootstrap percentile interval.
    pub low: f64,
    /// Upper end.
    pub high: f64,
    /// Avatars averaged.
    pub avatars: usize,
}

/// One avatar's score.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AvatarScore {
    /// The avatar's number.
    pub id: u32,
    /// Its category.
    pub category: String,
    /// Share of "no" answers.
    pub authenticity: f64,
    /// Answers behind it.
    pub answers: u32,
    /// Wilson score interval of the share.
    pub low: f64,
    /// Upper end of the Wilson interval.
    pub high: f64,
    /// Reasons the exclusion rules give (empty: kept).
    pub excluded: Vec<String>,
}

/// A category's mean score.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CategoryScore {
    /// The category.
    pub category: String,
    /// Over every answered avatar.
    pub all: Option<Estimate>,
    /// Over the avatars the rules keep (when rules were given).
    pub kept: Option<Estimate>,
}

/// A region's score in one category, over avatars where it was edited and
/// where it was not.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RegionScore {
    /// The category.
    pub category: String,
    /// The region (study group).
    pub group: StudyGroup,
    /// Over avatars whose region shows another source's Gaussians.
    pub edited: Option<Estimate>,
    /// Over avatars whose region shows the base's own Gaussians.
    pub unedited: Option<Estimate>,
}

/// Everything `study analyse` reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Analysis {
    /// Per avatar, in id order.
    pub avatars: Vec<AvatarScore>,
    /// Per category, in order of first appearance.
    pub categories: Vec<CategoryScore>,
    /// Per category and region.
    pub regions: Vec<RegionScore>,
    /// Avatars nobody answered yet (left out of every mean).
    pub unanswered: Vec<u32>,
    /// Avatars left out of region scores because a source's group is unknown.
    pub unplaced: Vec<u32>,
    /// Coverage of the intervals.
    pub confidence: f64,
    /// Bootstrap resamples per interval.
    pub resamples: usize,
}

/// Snaps a rounded share back to a whole number of answers.
fn snapped(share: f64, answers: u32) -> f64 {
    if answers == 0 {
        return share;
    }
    (share * answers as f64).round() / answers as f64
}

/// Wilson score interval of `share` over `n` answers.
fn wilson(share: f64, n: u32) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let n = n as f64;
    let z2 = Z * Z;
    let centre = (share + z2 / (2.0 * n)) / (1.0 + z2 / n);
    let half = Z * (share * (1.0 - share) / n + z2 / (4.0 * n * n)).sqrt() / (1.0 + z2 / n);
    ((centre - half).max(0.0), (centre + half).min(1.0))
}

/// The mean of `scores` with a percentile bootstrap interval (resampling
/// avatars, the unit the thesis scores).
fn estimate(scores: &[f64], options: &AnalysisOptions, stream: u64) -> Option<Estimate> {
    if scores.is_empty() {
        return None;
    }
    let n = scores.len();
    let mean = scores.iter().sum::<f64>() / n as f64;
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    rng.set_stream(stream);
    let mut means: Vec<f64> = (0..options.resamples)
        .map(|_| (0..n).map(|_| scores[rng.random_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    let at = |q: f64| {
        if means.is_empty() {
            return mean;
        }
        let i = (q * (means.len() - 1) as f64).round() as usize;
        means[i]
    };
    let tail = (1.0 - CONFIDENCE) / 2.0;
    Some(Estimate {
        mean,
        low: at(tail),
        high: at(1.0 - tail),
        avatars: n,
    })
}

/// Analyses tallied results.
pub fn analyse(results: &Results, options: &AnalysisOptions) -> Result<Analysis> {
    let mut avatars: Vec<&AvatarResult> = results.avatars.iter().collect();
    avatars.sort_by_key(|a| a.id);
    let mut scores = Vec::new();
    let mut unanswered = Vec::new();
    for a in &avatars {
        let answers = results.answers(a);
        let excluded = match &options.exclude {
            Some(rules) => rules.broken(
                &a.composition(),
                Context {
                    category: Some(&a.category),
                    avatar: Some(a.id),
                },
                &options.attributes,
            )?,
            None => Vec::new(),
        };
        if answers == 0 && a.answers.is_some() {
            unanswered.push(a.id);
        }
        let authenticity = snapped(a.authenticity, answers);
        let (low, high) = wilson(authenticity, answers);
        scores.push(AvatarScore {
            id: a.id,
            category: a.category.clone(),
            authenticity,
            answers,
            low,
            high,
            excluded,
        });
    }
    let answered = |s: &&AvatarScore| !unanswered.contains(&s.id);
    let mut names: Vec<String> = Vec::new();
    for a in &scores {
        if !names.contains(&a.category) {
            names.push(a.category.clone());
        }
    }
    let mut stream = 0;
    let mut next_stream = || {
        stream += 1;
        stream
    };
    let categories = names
        .iter()
        .map(|c| {
            let of = |keep: &dyn Fn(&AvatarScore) -> bool| -> Vec<f64> {
                scores
                    .iter()
                    .filter(answered)
                    .filter(|s| s.category == *c && keep(s))
                    .map(|s| s.authenticity)
                    .collect()
            };
            CategoryScore {
                category: c.clone(),
                all: estimate(&of(&|_| true), options, next_stream()),
                kept: options.exclude.as_ref().and_then(|_| {
                    estimate(&of(&|s| s.excluded.is_empty()), options, next_stream())
                }),
            }
        })
        .collect();
    let unplaced: Vec<u32> = avatars
        .iter()
        .filter(|a| !a.unplaced.is_empty())
        .map(|a| a.id)
        .collect();
    let mut regions = Vec::new();
    for c in &names {
        for group in StudyGroup::EDITABLE {
            let of = |edited: bool| -> Vec<f64> {
                avatars
                    .iter()
                    .filter(|a| a.category == *c && a.unplaced.is_empty())
                    .filter(|a| !unanswered.contains(&a.id))
                    .filter(|a| a.groups.contains_key(&group) == edited)
                    .filter_map(|a| {
                        let share = *a.regions.get(&group)?;
                        Some(snapped(share, results.answers(a)))
                    })
                    .collect()
            };
            regions.push(RegionScore {
                category: c.clone(),
                group,
                edited: estimate(&of(true), options, next_stream()),
                unedited: estimate(&of(false), options, next_stream()),
            });
        }
    }
    Ok(Analysis {
        avatars: scores,
        categories,
        regions,
        unanswered,
        unplaced,
        confidence: CONFIDENCE,
        resamples: options.resamples,
    })
}

impl Analysis {
    /// The report as a terminal table.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let pct = (self.confidence * 100.0).round();
        let cell = |e: &Option<Estimate>| match e {
            Some(e) => format!(
                "{:.2} [{:.2}, {:.2}] n={}",
                e.mean, e.low, e.high, e.avatars
            ),
            None => "-".to_string(),
        };
        let excluding = self.categories.iter().any(|c| c.kept.is_some());
        out.push_str(&format!(
            "authenticity per category (mean [{pct}% bootstrap CI] over avatars)\n"
        ));
        out.push_str(&format!("  {:<22} {:<30}", "category", "all avatars"));
        if excluding {
            out.push_str("after exclusion");
        }
        out.push('\n');
        for c in &self.categories {
            out.push_str(&format!("  {:<22} {:<30}", c.category, cell(&c.all)));
            if excluding {
                out.push_str(&cell(&c.kept));
            }
            out.push('\n');
        }
        out.push_str("\nper-region authenticity (edited | unedited regions)\n");
        out.push_str(&format!("  {:<22} {:<6}", "category", "region"));
        out.push_str(&format!(" {:<30} {}\n", "edited", "unedited"));
        for r in &self.regions {
            out.push_str(&format!(
                "  {:<22} {:<6} {:<30} {}\n",
                r.category,
                r.group.name(),
                cell(&r.edited),
                cell(&r.unedited)
            ));
        }
        out.push_str(&format!(
            "\nper avatar (share of \"no\" [{pct}% Wilson CI], answers)\n"
        ));
        for a in &self.avatars {
            if self.unanswered.contains(&a.id) {
                out.push_str(&format!("  {:>4} {:<22} not answered\n", a.id, a.category));
                continue;
            }
            let reasons = if a.excluded.is_empty() {
                String::new()
            } else {
                format!("  excluded: {}", a.excluded.join(", "))
            };
            out.push_str(&format!(
                "  {:>4} {:<22} {:.2} [{:.2}, {:.2}] {:>3}{reasons}\n",
                a.id, a.category, a.authenticity, a.low, a.high, a.answers
            ));
        }
        if !self.unanswered.is_empty() {
            out.push_str(&format!(
                "\nnot answered yet (left out): {:?}\n",
                self.unanswered
            ));
        }
        if !self.unplaced.is_empty() {
            out.push_str(&format!(
                "left out of region scores (a source's group is unknown): {:?}\n",
                self.unplaced
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wilson_intervals_hold_the_share_and_stay_in_range() {
        for (share, n) in [(0.0, 22), (1.0, 22), (0.5, 2), (0.41, 22)] {
            let (lo, hi) = wilson(share, n);
            assert!(0.0 <= lo && lo <= share && share <= hi && hi <= 1.0);
        }
        let (lo, hi) = wilson(0.5, 100);
        assert!((lo - 0.4038).abs() < 1e-3 && (hi - 0.5962).abs() < 1e-3);
    }

    #[test]
    fn bootstrap_intervals_bracket_the_mean_and_repeat() {
        let scores = [0.0, 0.1, 0.5, 0.9, 0.3];
        let o = AnalysisOptions::default();
        let a = estimate(&scores, &o, 1).unwrap();
        assert!(a.low < a.mean && a.mean < a.high);
        assert_eq!(estimate(&scores, &o, 1), Some(a));
        // One avatar: no spread to resample.
        let one = estimate(&[0.7], &o, 2).unwrap();
        assert_eq!((one.low, one.high), (0.7, 0.7));
        assert_eq!(snapped(0.05, 22), 1.0 / 22.0);
    }
}
