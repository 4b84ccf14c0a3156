//! Composition: recipes, Gaussian selection by lookup tables, Laplacian shape
//! blending, border smoothing, colour correction, animation and state hashes.

pub mod blend;
pub mod colour;
pub mod engine;
pub mod recipe;
pub mod selection;
pub mod smoothing;

use crate::avatar::database::Database;
use recipe::ResolvedRecipe;

/// A short hash of the composite state: the database's fingerprint and the
/// resolved recipe. Identical across runs and machines for the same inputs.
pub fn state_hash(db: &Database, recipe: &ResolvedRecipe) -> String {
    let mut h = blake3::Hasher::new();
    h.update(db.fingerprint.as_bytes());
    h.update(format!("{recipe:?}").as_bytes());
    h.finalize().to_hex()[..16].to_string()
}
