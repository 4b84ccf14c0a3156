//! What the seam fit's tests share: two built-in people to compose, and
//! recipes for them post-processed as `post ours`.

use crate::avatar::synthetic::{builtin_database, SyntheticOptions};
use crate::compose::engine::Engine;
use crate::compose::recipe::{PostProcess, Recipe};
use crate::model::builtin::build_head;

/// An engine over two built-in people (seed 5) of `gaussians` Gaussians
/// each: person 0 the base of the tests' recipes, person 1 the swapped one.
pub(super) fn two_people(gaussians: usize) -> Engine {
    let options = SyntheticOptions {
        seed: 5,
        sources: 2,
        gaussians_per_avatar: gaussians,
    };
    Engine::new(builtin_database(build_head(), options).unwrap()).unwrap()
}

/// The name of person `s` of `engine`'s database, as a recipe names it.
pub(super) fn name_of(engine: &Engine, s: usize) -> String {
    engine.database().sources[s].name.clone()
}

/// The recipe `text` (TOML) post-processed as `post ours`.
pub(super) fn ours(text: &str) -> Recipe {
    let mut recipe = Recipe::from_toml(text).unwrap();
    recipe.post = PostProcess::BEST;
    recipe
}
