//! What the seam fit's tests share: two built-in people to compose, and
//! recipes for them post-processed as `post ours`.

use crate::avatar::synthetic::{builtin_database, SyntheticOptions};
use crate::compose::engine::{Composite, Engine};
use crate::compose::recipe::{PostProcess, Recipe, SkinSource};
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

/// The recipe (under `post ours`) of person 0 whole on person 1's face
/// shape: a head of one source on a new shape.
pub(super) fn base_on_the_others_face(engine: &Engine) -> Recipe {
    let (base, other) = (name_of(engine, 0), name_of(engine, 1));
    ours(&format!(
        "base = \"{base}\"\n[groups.face]\ngaussians = \"{base}\"\nshape = {{ {other} = 1.0 }}\n"
    ))
}

/// Two built-in people of a thousand Gaussians each and the composite of
/// person 1's `groups` on person 0 under `post ours` with `skin`.
pub(super) fn swap(groups: &[&str], skin: SkinSource) -> (Engine, Composite) {
    let engine = two_people(1_000);
    let mut text = format!("base = \"{}\"\n", name_of(&engine, 0));
    for group in groups {
        text += &format!(
            "[groups.{group}]\ngaussians = \"{}\"\n",
            name_of(&engine, 1)
        );
    }
    let mut recipe = ours(&text);
    recipe.post.skin = skin;
    let composite = engine.compose(&recipe.resolve(engine.database()).unwrap());
    (engine, composite)
}
