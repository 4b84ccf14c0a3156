//! Composition: recipes, Gaussian selection by lookup tables, Laplacian shape
//! blending, border smoothing, colour correction, animation and state hashes.

pub mod base_skin;
pub mod blend;
pub mod clothing;
pub mod colour;
pub mod composition;
pub mod copying;
pub mod correction;
pub mod dark_features;
pub mod deform;
pub mod engine;
pub mod lids;
pub mod membership;
pub mod random;
pub mod recipe;
pub mod reshape;
pub mod rules;
pub mod seam_colours;
pub mod seams;
pub mod selection;
pub mod shading;
pub mod skin_transfer;
pub mod smoothing;
pub mod source_colours;

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

/// A hash of the composite's content: the blended neutral mesh as an export
/// stores it (template + float32 static offset, see
/// [`crate::io::avatar::neutral_as_stored`]), every selected Gaussian (after
/// post-processing) and the frame's expression and pose. Equal for composites
/// that look and move the same however they were made — e.g. a composite and
/// its GaussianAvatars export loaded back.
pub fn composite_hash(
    engine: &engine::Engine,
    composite: &engine::Composite,
    frame: usize,
) -> String {
    let mut h = blake3::Hasher::new();
    let mut floats = |xs: &mut dyn Iterator<Item = f32>| {
        for x in xs {
            h.update(&x.to_le_bytes());
        }
    };
    let model = &engine.database().model;
    let stored = crate::io::avatar::neutral_as_stored(&model.template, &composite.neutral);
    floats(&mut stored.iter().flat_map(|v| v.to_array()));
    let g = &reordered(
        &composite.gaussians,
        &canonical_order(&engine.database().model, &composite.gaussians),
    );
    floats(&mut g.binding.iter().map(|&b| b as f32));
    floats(&mut g.position.iter().flat_map(|v| v.to_array()));
    floats(&mut g.rotation.iter().flat_map(|q| q.to_array()));
    floats(&mut g.log_scale.iter().flat_map(|v| v.to_array()));
    floats(&mut g.opacity_logit.iter().copied());
    floats(&mut g.sh.iter().copied());
    let (expression, pose) = engine.frame_parameters(&composite.recipe, frame);
    let used = engine.database().model.expression_basis.len();
    floats(
        &mut expression
            .iter()
            .take(used)
            .copied()
            .chain(std::iter::repeat(0.0))
            .take(used),
    );
    floats(
        &mut pose
            .joints
            .iter()
            .flat_map(|j| j.to_array())
            .chain(pose.translation.to_array()),
    );
    h.finalize().to_hex()[..16].to_string()
}

/// The order a composite's Gaussians are hashed in and written to a
/// GaussianAvatars export in (a world-space PLY keeps the composite's
/// order): by region of their triangle (table order), then by triangle,
/// then by their parameters'
/// bits (position, rotation, log-scale, opacity, SH) — an order that depends
/// only on what the Gaussians are, not on the order a composite lists them
/// in. Membership by place (method §5.1) counts a Gaussian by where it sits
/// on a neutral mesh, and an export loaded back is placed on the
/// composite's neutral, not its source's: a Gaussian under a lid by a hair
/// may be counted for another region there, and selection, which lists a
/// composite region by region, then lists it elsewhere.
pub fn canonical_order(
    model: &crate::model::head::HeadModel,
    set: &crate::avatar::gaussians::GaussianSet,
) -> Vec<u32> {
    let region = |i: usize| {
        model
            .triangle_regions
            .get(set.binding[i] as usize)
            .map_or(usize::MAX, |r| r.index())
    };
    let bits = |i: usize| {
        let v = |v: glam::Vec3| v.to_array().map(f32::to_bits);
        (
            v(set.position[i]),
            set.rotation[i].to_array().map(f32::to_bits),
            v(set.log_scale[i]),
            set.opacity_logit[i].to_bits(),
        )
    };
    let sh = |i: usize| set.sh_of(i).iter().map(|x| x.to_bits());
    let mut order: Vec<u32> = (0..set.len() as u32).collect();
    order.sort_by(|&a, &b| {
        let (a, b) = (a as usize, b as usize);
        (region(a), set.binding[a], bits(a))
            .cmp(&(region(b), set.binding[b], bits(b)))
            .then_with(|| sh(a).cmp(sh(b)))
    });
    order
}

/// A copy of a Gaussian set in the given order.
pub fn reordered(
    set: &crate::avatar::gaussians::GaussianSet,
    order: &[u32],
) -> crate::avatar::gaussians::GaussianSet {
    let mut out = crate::avatar::gaussians::GaussianSet::with_degree(set.sh_degree);
    out.reserve(order.len());
    for &i in order {
        out.push_from(set, i as usize, set.opacity_logit[i as usize]);
    }
    out
}
