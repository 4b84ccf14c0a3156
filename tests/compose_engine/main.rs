//! The composition engine: recipes, selection, blending, post-processing and
//! animation, including the numerical hard cases.

use std::collections::BTreeMap;
use std::sync::OnceLock;

use glam::Vec3;
use visage::avatar::database::Database;
use visage::avatar::gaussians::{dc_to_rgb, rgb_to_dc, sigmoid};
use visage::avatar::synthetic::{builtin_database, SyntheticOptions};
use visage::compose::base_skin::{similarity_misfit, Topology, BASE_FIT};
use visage::compose::blend::Blender;
use visage::compose::colour::{weighted_mean_colour, GAIN_RANGE};
use visage::compose::engine::{Composite, Engine, PosedMesh};
use visage::compose::recipe::{
    Anchor, AnimationMode, ColourCorrection, Deform, GroupEdit, Membership, PostProcess, Recipe,
    ResolvedRecipe, Shading, SkinSource, Smoothing,
};
use visage::compose::selection::Csr;
use visage::compose::state_hash;
use visage::model::builtin::build_head;
use visage::model::head::{Joint, Pose};
use visage::model::regions::{Group, Region};

fn small_db() -> Database {
    builtin_database(
        build_head(),
        SyntheticOptions {
            seed: 5,
            sources: 4,
            gaussians_per_avatar: 12_000,
        },
    )
    .unwrap()
}

fn engine() -> &'static Engine {
    static ENGINE: OnceLock<Engine> = OnceLock::new();
    ENGINE.get_or_init(|| Engine::new(small_db()).unwrap())
}

fn names(e: &Engine) -> Vec<String> {
    e.database()
        .sources
        .iter()
        .map(|s| s.name.clone())
        .collect()
}

fn edit(gaussians: &str, shape: &[(&str, f64)]) -> GroupEdit {
    GroupEdit {
        gaussians: gaussians.to_string(),
        shape: shape
            .iter()
            .map(|(k, v)| (k.to_string(), *v))
            .collect::<BTreeMap<_, _>>(),
    }
}

fn resolve(e: &Engine, recipe: &Recipe) -> ResolvedRecipe {
    recipe.resolve(e.database()).unwrap()
}

/// Brings `c` up to date with `recipe` and checks it against a composite
/// composed from scratch, bit for bit: its blocks and every value of every
/// Gaussian (`label` names the step). Whether the update rebuilt the
/// Gaussians.
fn update_matches_fresh(
    e: &Engine,
    c: &mut Composite,
    recipe: &ResolvedRecipe,
    label: &str,
) -> bool {
    let rebuilt = e.update(c, recipe).gaussians;
    let fresh = e.compose(recipe);
    let (a, b) = (&c.gaussians, &fresh.gaussians);
    assert_eq!(c.blocks, fresh.blocks, "{label}");
    assert_eq!(a.binding, b.binding, "{label}");
    assert_eq!(a.position, b.position, "{label}");
    assert_eq!(a.rotation, b.rotation, "{label}");
    assert_eq!(a.log_scale, b.log_scale, "{label}");
    assert_eq!(a.opacity_logit, b.opacity_logit, "{label}");
    assert!(a.sh == b.sh, "{label}: colours differ");
    rebuilt
}

fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (*x - *y).length())
        .fold(0.0, f32::max)
}

fn all_groups(recipe: &mut Recipe, gaussians: &str, shape: &[(&str, f64)]) {
    for g in Group::ALL {
        recipe
            .groups
            .insert(g.name().into(), edit(gaussians, shape));
    }
}

/// Moves Gaussian `i` of `set` so its centre sits at `world` on the mesh
/// `vertices` (keeping its parent triangle): a trained child that drifted.
fn drift_to(
    set: &mut visage::avatar::gaussians::GaussianSet,
    i: usize,
    vertices: &[Vec3],
    triangles: &[[u32; 3]],
    world: Vec3,
) {
    let frames = visage::avatar::binding::triangle_frames(vertices, triangles);
    let f = frames[set.binding[i] as usize];
    set.position[i] = f.rotation.transpose() * (world - f.center) / f.scale;
}

mod dark_features;
mod recipes_and_shapes;
mod reshaping;
mod seams;
mod selection;
