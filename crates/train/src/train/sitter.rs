//! Who sits for a capture: a built-in source, or the ideal avatar of the
//! person a recipe describes — the ground truth of a composite (method
//! §13.1). A sitter is a mesh identity, stored the way the dataset's FLAME
//! parameters reproduce it, and a surface: per triangle, whose procedural
//! appearance it wears and whose skin, and — for smooth seams — how the
//! appearances of two sources cross-fade over about a centimetre of template
//! surface across a group border.

use glam::{DVec3, Vec3};
use serde_json::{json, Value};

use crate::avatar::database::{Database, SourceAvatar};
use crate::avatar::synthetic::surface_radiance_toned;
use crate::compose::engine::Engine;
use crate::compose::recipe::{Recipe, ResolvedRecipe};
use crate::compose::seams::{SeamBlend, SeamField};
use crate::error::Result;
use crate::io::avatar::neutral_offset;
use crate::model::head::HeadModel;

/// A point of the surface as the capture shades it.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// The triangle.
    pub triangle: u32,
    /// Its vertices.
    pub vertices: [u32; 3],
    /// Barycentric coordinates in it.
    pub bary: [f32; 3],
    /// Template position (the texture coordinate of the procedural surface).
    pub texel: Vec3,
    /// Unit normal of the neutral.
    pub normal: Vec3,
    /// Ambient occlusion.
    pub occlusion: f32,
}

/// Which appearance a composite's ground truth has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tone {
    /// Every region as its source has it (the target for `colour off`).
    #[default]
    Source,
    /// The base's skin tone and skin detail, each region's source's own lips,
    /// iris, brows, hair and beard (the target for colour correction).
    Base,
}

/// How a composite's ground truth meets at a border between sources.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Seams {
    /// Each triangle wears its group's source: a hard edge.
    #[default]
    Hard,
    /// The two sources cross-blend over
    /// [`SEAM_WIDTH`](crate::compose::seams::SEAM_WIDTH) of template surface.
    Smooth,
}

/// A capture's subject.
#[derive(Clone, Debug)]
pub struct Sitter {
    /// The name the dataset records (`source` in its JSON).
    pub name: String,
    /// Shape coefficients stored in the dataset's FLAME parameters.
    pub shape: Vec<f32>,
    /// Static offset stored with them (template + shape + offset is the neutral).
    pub static_offset: Vec<DVec3>,
    /// Per triangle: the source whose appearance it wears.
    looks: Vec<u32>,
    /// Per triangle: the source whose skin it wears.
    skins: Vec<u32>,
    /// Whose skin the surface wears: each region's source's or the base's.
    tone: Tone,
    seams: Option<SeamField>,
    /// What the dataset's JSON records about a composite (nothing for a source).
    pub note: Option<Value>,
}

impl Sitter {
    /// Built-in source `index` as it is.
    pub fn source(db: &Database, index: usize) -> Sitter {
        Sitter::avatar(&db.sources[index], index, db.model.triangle_count())
    }

    /// An avatar's identity wearing built-in appearance `look` everywhere
    /// (a trained avatar of a built-in person, to draw its own ground truth).
    pub fn avatar(avatar: &SourceAvatar, look: usize, triangles: usize) -> Sitter {
        Sitter {
            name: avatar.name.clone(),
            shape: avatar.shape.clone(),
            static_offset: avatar.static_offset.clone(),
            looks: vec![look as u32; triangles],
            skins: vec![look as u32; triangles],
            tone: Tone::Source,
            seams: None,
            note: None,
        }
    }

    /// The ideal avatar of `recipe` over the built-in people of `db`: the
    /// blended neutral of the composer's own Laplacian blend (stored as the
    /// export stores it: zero shape, the blend in the static offset), each
    /// triangle wearing the source its group's Gaussians come from, with the
    /// skin `tone` asks for and the `seams` asked for. An unedited recipe is
    /// its base as it is, so its capture equals `capture --source`.
    pub fn composite(db: &Database, recipe: &Recipe, tone: Tone, seams: Seams) -> Result<Sitter> {
        let resolved = recipe.resolve(db)?;
        if is_unedited(&resolved) {
            return Ok(Sitter::source(db, resolved.base));
        }
        let engine = Engine::new(db.clone())?;
        let (neutral, _) = engine.blend_neutral(&resolved);
        let model = &db.model;
        let looks: Vec<u32> = model
            .triangle_regions
            .iter()
            .map(|r| resolved.gaussians[r.group().index()] as u32)
            .collect();
        let skins = match tone {
            Tone::Source => looks.clone(),
            Tone::Base => vec![resolved.base as u32; looks.len()],
        };
        let seam_field = (seams == Seams::Smooth).then(|| SeamField::new(model, &looks));
        Ok(Sitter {
            name: db.sources[resolved.base].name.clone(),
            shape: vec![0.0; model.shape_basis.len()],
            static_offset: neutral_offset(&model.template, &neutral),
            looks,
            skins,
            tone,
            seams: seam_field,
            note: Some(json!({
                "recipe": recipe.to_toml(),
                "composite_hash": crate::compose::state_hash(db, &resolved),
                "tone": tone,
                "seams": seams,
            })),
        })
    }

    /// The neutral mesh the dataset's parameters give.
    pub fn neutral(&self, model: &HeadModel) -> Vec<Vec3> {
        model.neutral(&self.shape, Some(&self.static_offset))
    }

    /// The source whose appearance triangle `t` wears.
    pub fn look_of(&self, t: u32) -> u32 {
        self.looks[t as usize]
    }

    /// The lit colour of a point of the surface.
    pub fn shade(&self, model: &HeadModel, at: &SurfacePoint) -> [f32; 3] {
        let SurfacePoint {
            triangle: t,
            vertices: tri,
            bary,
            texel,
            normal,
            occlusion,
        } = *at;
        let region = model.triangle_regions[t as usize];
        let (own, skin) = (self.looks[t as usize], self.skins[t as usize]);
        let own_colour = surface_radiance_toned(
            own as usize,
            skin as usize,
            region,
            texel,
            normal,
            occlusion,
        );
        let Some(field) = &self.seams else {
            return own_colour;
        };
        let Some(SeamBlend { other, weight: w }) = field.blend_at(tri, bary, own) else {
            return own_colour;
        };
        // The other side in its own skin, or in the base's like every
        // triangle: under `Tone::Base` the base's own triangles (where the skin
        // is also the look) must not take the other source's skin.
        let other_skin = match self.tone {
            Tone::Source => other,
            Tone::Base => skin,
        };
        let other_colour = surface_radiance_toned(
            other as usize,
            other_skin as usize,
            region,
            texel,
            normal,
            occlusion,
        );
        std::array::from_fn(|c| own_colour[c] * (1.0 - w) + other_colour[c] * w)
    }
}

/// True when every group takes its Gaussians and its whole shape from the base.
pub fn is_unedited(recipe: &ResolvedRecipe) -> bool {
    let base_only = |row: &Vec<f64>| {
        row.iter()
            .enumerate()
            .all(|(f, &w)| w == if f == recipe.base { 1.0 } else { 0.0 })
    };
    recipe.gaussians.iter().all(|&g| g == recipe.base) && recipe.shape.iter().all(base_only)
}

impl Tone {
    /// Parses `source` or `base`.
    pub fn parse(text: &str) -> std::result::Result<Tone, String> {
        match text {
            "source" => Ok(Tone::Source),
            "base" => Ok(Tone::Base),
            _ => Err(format!(
                "tone '{}' is not source or base",
                crate::text::printable(text)
            )),
        }
    }
}

impl Seams {
    /// Parses `hard` or `smooth`.
    pub fn parse(text: &str) -> std::result::Result<Seams, String> {
        match text {
            "hard" => Ok(Seams::Hard),
            "smooth" => Ok(Seams::Smooth),
            _ => Err(format!(
                "seams '{}' are not hard or smooth",
                crate::text::printable(text)
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::synthetic::{builtin_database, SyntheticOptions};
    use crate::compose::seams::SEAM_WIDTH;

    fn db() -> Database {
        builtin_database(
            crate::model::builtin::build_head(),
            SyntheticOptions {
                seed: 1,
                sources: 4,
                gaussians_per_avatar: 1,
            },
        )
        .unwrap()
    }

    #[test]
    fn an_unedited_recipe_sits_as_its_base() {
        let db = db();
        let s =
            Sitter::composite(&db, &Recipe::unedited("bram"), Tone::Base, Seams::Smooth).unwrap();
        assert!(s.note.is_none());
        assert_eq!(s.shape, db.sources[1].shape);
        assert!(s.looks.iter().all(|&l| l == 1));
    }

    /// The stored parameters reproduce the composer's blend, and triangles
    /// wear their group's source; smooth seams blend half and half at the
    /// border and not at all a seam's half-width away.
    #[test]
    fn a_composite_sits_as_the_recipe_says() {
        let db = db();
        let recipe = Recipe::from_toml(
            "base = \"ada\"\n[groups.nose]\ngaussians = \"cleo\"\nshape = { cleo = 0.6, ada = 0.4 }\n",
        )
        .unwrap();
        let s = Sitter::composite(&db, &recipe, Tone::Source, Seams::Smooth).unwrap();
        let engine = Engine::new(db.clone()).unwrap();
        let (blend, _) = engine.blend_neutral(&recipe.resolve(&db).unwrap());
        let neutral = s.neutral(&db.model);
        let worst = neutral
            .iter()
            .zip(&blend)
            .map(|(a, b)| a.distance(*b))
            .fold(0.0f32, f32::max);
        assert!(worst < 1e-6, "{worst}");
        let model = &db.model;
        let nose = crate::model::regions::Region::Nose;
        for (t, r) in model.triangle_regions.iter().enumerate() {
            assert_eq!(s.look_of(t as u32), if *r == nose { 2 } else { 0 });
        }
        let field = s.seams.as_ref().unwrap();
        let (to_cleo, to_ada) = (field.distances(2).unwrap(), field.distances(0).unwrap());
        let on_border = (0..model.vertex_count())
            .find(|&v| to_cleo[v] == 0.0 && to_ada[v] == 0.0)
            .expect("a vertex on the nose's border");
        assert!(
            to_cleo.iter().any(|&d| d == SEAM_WIDTH / 2.0),
            "far vertices are capped"
        );
        // A triangle of ada's touching the border vertex: half-blended there.
        let t = (0..model.triangle_count())
            .find(|&t| model.triangles[t].contains(&(on_border as u32)) && s.looks[t] == 0)
            .unwrap() as u32;
        let tri = model.triangles[t as usize];
        let k = tri.iter().position(|&v| v as usize == on_border).unwrap();
        let mut bary = [0.0; 3];
        bary[k] = 1.0;
        let texel = model.template[on_border];
        let point = SurfacePoint {
            triangle: t,
            vertices: tri,
            bary,
            texel,
            normal: Vec3::Z,
            occlusion: 1.0,
        };
        let shaded = s.shade(model, &point);
        let region = model.triangle_regions[t as usize];
        let ada = surface_radiance_toned(0, 0, region, texel, Vec3::Z, 1.0);
        let cleo_c = surface_radiance_toned(2, 2, region, texel, Vec3::Z, 1.0);
        for c in 0..3 {
            assert!((shaded[c] - 0.5 * (ada[c] + cleo_c[c])).abs() < 1e-5);
        }
        // In the base's tone, the base's side of the seam blends towards
        // cleo's look in the base's skin, never cleo's own skin.
        let toned = Sitter::composite(&db, &recipe, Tone::Base, Seams::Smooth).unwrap();
        let shaded = toned.shade(model, &point);
        let cleo_in_ada = surface_radiance_toned(2, 0, region, texel, Vec3::Z, 1.0);
        assert!(cleo_in_ada != cleo_c, "the two skins differ here");
        for c in 0..3 {
            assert!((shaded[c] - 0.5 * (ada[c] + cleo_in_ada[c])).abs() < 1e-5);
        }
    }
}
