//! The study's analysis against the thesis's published numbers, and the
//! study workflow through the command line.

use std::path::Path;

use visage::compose::composition::Attributes;
use visage::compose::rules::Rules;
use visage::study::analysis::{analyse, Analysis, AnalysisOptions};
use visage::study::results::Results;

fn thesis(exclude: bool) -> (Results, Analysis) {
    let dir = Path::new("studies/thesis");
    let results = Results::load(&dir.join("results.toml")).unwrap();
    let options = AnalysisOptions {
        exclude: exclude.then(|| Rules::load(&dir.join("exclusions.toml")).unwrap()),
        attributes: Attributes::load(&dir.join("attributes.toml")).unwrap(),
        ..AnalysisOptions::default()
    };
    let analysis = analyse(&results, &options).unwrap();
    (results, analysis)
}

fn rounded(x: f64) -> f64 {
    (x * 100.0).round() / 100.0
}

/// Figures 6.2 and 6.3: the category means before and after excluding
/// implausible composites, from the per-avatar scores of Appendix B and the
/// exclusion rules of §6.3.1.
#[test]
fn thesis_category_means_are_reproduced_before_and_after_exclusion() {
    let (_, analysis) = thesis(true);
    let table: Vec<(String, f64, Option<f64>, usize)> = analysis
        .categories
        .iter()
        .map(|c| {
            let all = c.all.unwrap();
            (
                c.category.clone(),
                rounded(all.mean),
                c.kept.map(|k| rounded(k.mean)),
                c.kept.map_or(0, |k| k.avatars),
            )
        })
        .collect();
    let expected = [
        ("unedited_original", 0.80, 0.80, 7),
        ("unedited_filling", 0.79, 0.79, 7),
        ("edit_original", 0.19, 0.26, 5),
        ("edit_filling", 0.15, 0.34, 6),
        ("edit_filling_smooth", 0.16, 0.43, 4),
    ];
    assert_eq!(table.len(), expected.len());
    for ((name, all, kept, n), (e_name, e_all, e_kept, e_n)) in table.iter().zip(expected) {
        assert_eq!(name, e_name);
        assert_eq!(*all, e_all, "{name} before exclusion");
        assert_eq!(*kept, Some(e_kept), "{name} after exclusion");
        assert_eq!(*n, e_n, "{name}: avatars kept");
    }
    for c in &analysis.categories {
        let all = c.all.unwrap();
        assert!(all.low < all.mean && all.mean < all.high, "{c:?}");
    }
}

/// The rules derive Appendix C: the same 30 avatars, for the same reasons.
#[test]
fn thesis_exclusion_rules_give_appendix_c() {
    let (results, analysis) = thesis(true);
    let mut excluded = 0;
    let mut differ = Vec::new();
    for (published, scored) in results.avatars.iter().zip(&analysis.avatars) {
        assert_eq!(published.id, scored.id);
        let mut derived = scored.excluded.clone();
        let mut listed = published.excluded.clone();
        derived.sort();
        listed.sort();
        if derived != listed {
            differ.push(format!(
                "avatar {}: rules {derived:?}, Appendix C {listed:?}",
                published.id
            ));
        }
        excluded += usize::from(!derived.is_empty());
    }
    assert!(differ.is_empty(), "{}", differ.join("\n"));
    assert_eq!(excluded, 30);
}
