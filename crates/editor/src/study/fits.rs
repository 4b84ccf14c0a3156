//! The seam fits of a study's avatars, made once when the study is built and
//! kept in its folder (`fits/`), so that `study run` shows each avatar at
//! once instead of making every participant wait for its fit.

use crate::compose::engine::Engine;
use crate::compose::recipe::Fit;
use crate::error::Result;
use crate::pipeline::composer::{Composer, FitProgress};
use crate::pipeline::DatabaseSpec;
use crate::train::fit_store::FitStore;
use crate::train::seam_fit::SeamFit;

use super::design::{StudyAvatar, StudyFolder};

/// The folder of a study that holds its avatars' seam fits.
pub const FITS_DIR: &str = "fits";

/// Where a study keeps its avatars' seam fits.
pub fn fit_store(study: &StudyFolder) -> FitStore {
    FitStore::new(study.dir.join(FITS_DIR))
}

/// What [`fit_avatars`] did, counting each fit once (avatars that differ
/// in motion or camera alone share one).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FitSummary {
    /// Avatars fitted now.
    pub fitted: usize,
    /// Avatars whose fit was in the folder already (an earlier build under
    /// the same options, one a kill interrupted included).
    pub stored: usize,
    /// Fits in the folder of no avatar of this build (another spec or other
    /// fit options built into the same folder before), removed so that the
    /// folder ships only what its runs can use.
    pub removed: usize,
}

/// Fits the seams of every avatar whose post-processing asks for a fit,
/// under `options`, into the study's folder; a fit already there is kept,
/// and any other fit in the folder removed. `progress` hears the avatar's
/// position among those fitted, their count and the fit's progress. Counts
/// only avatars with Gaussians to fit (an avatar of one source on its own
/// shape has none).
pub fn fit_avatars(
    study: &StudyFolder,
    options: &SeamFit,
    progress: &mut dyn FnMut(usize, usize, FitProgress),
) -> Result<FitSummary> {
    let mut wanted: Vec<(&StudyAvatar, DatabaseSpec)> = Vec::new();
    for avatar in &study.study.avatars {
        if study.recipe(avatar)?.post.fit == Fit::Seams {
            wanted.push((avatar, study.category(avatar).database.clone()));
        }
    }
    let count = wanted.len();
    let mut done = 0;
    let mut summary = FitSummary::default();
    let mut keys = Vec::with_capacity(count);
    // One engine per database, its avatars one after another.
    while let Some((_, spec)) = wanted.first().cloned() {
        let (db, _) = spec.load()?;
        let mut composer = Composer::new(Engine::new(db)?);
        composer.set_fit_options(*options);
        composer.set_fit_store(Some(fit_store(study)));
        for (avatar, _) in wanted.iter().filter(|(_, s)| *s == spec) {
            composer.update(&study.recipe(avatar)?)?;
            composer.finish_fit(&mut |p| progress(done, count, p))?;
            if let Some(e) = composer.take_store_error() {
                return Err(e);
            }
            done += 1;
            // Avatars that differ in motion or camera alone share a fit:
            // each fit is counted once.
            let Some(key) = composer.fit_key().filter(|k| !keys.contains(k)) else {
                continue;
            };
            keys.push(key);
            if composer.fit_report().is_some_and(|r| r.fitted > 0) {
                if composer.fit_was_stored() {
                    summary.stored += 1;
                } else {
                    summary.fitted += 1;
                }
            }
        }
        wanted.retain(|(_, s)| *s != spec);
    }
    summary.removed = fit_store(study).remove_all_but(&keys)?;
    Ok(summary)
}
