//! The composition engine: everything precomputed per database, composites built
//! from recipes (and rebuilt only where a recipe changed), and posed frames.

mod colour_correction;
mod posing;

use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use glam::Vec3;
use rayon::prelude::*;

use super::base_skin::{
    base_skin_confidence, showing, similarity_misfit, skin_likeness, triangle_skin, SkinShare,
    Topology,
};
use super::blend::{Blender, SparseRhs};
use super::colour::{apply_gain, colour_weight, weighted_mean_colour};
use super::copying::{copy_own, relight_sh, CopyOwn, OpacityEdit, OwnBlock};
use super::correction::{Correction, SharedGains};
use super::dark_features;
use super::membership::{footprint_triangles, placements};
use super::recipe::{
    Anchor, Deform, Membership, PostProcess, ResolvedRecipe, Shading, SkinSource, Smoothing,
};
use super::reshape::{ReshapeOptions, ReshapeSource, ReshapedSources, Reshaping, SourceAnchors};
use super::seam_colours::{SeamColours, SourceTables, VertexColours};
use super::seams::{limit_reach, SeamNeighbours};
use super::selection::{sharing_a_corner, Csr, SelectionTables};
use super::shading::{vertex_exposures, BakedLight, Exposure};
use super::smoothing::{own_share, BorderTables};
use super::source_colours::SourceColours;
use crate::avatar::binding::TriangleFrame;
use crate::avatar::database::Database;
use crate::avatar::gaussians::GaussianSet;
use crate::error::Result;
use crate::model::head::HeadModel;
use crate::model::regions::Region;

/// Precomputed tables of one database.
pub struct Engine {
    db: Database,
    tables: SelectionTables,
    borders: BorderTables,
    blender: Blender,
    neutrals: Vec<Vec<Vec3>>,
    /// `[source][region]` → Mᵀd contribution of that region's edges with weight 1.
    region_rhs: Vec<Vec<SparseRhs>>,
    /// `[source][region]` → thesis-weighted mean colour.
    mean_colour: [Vec<Vec<Option<Vec3>>>; 2],
    /// What each source's colours say about its skin, hair and light.
    colours: SourceColours,
    /// Per-Gaussian skin-transfer gains by (source, colour reference), computed on
    /// first use: the CIELAB transfer costs ~100 ns a Gaussian, applying a gain ~5.
    skin_gains: Mutex<HashMap<GainKey, SharedGains>>,
    /// Vertex → the triangles around it.
    vertex_triangles: Csr,
    /// Per triangle: whether it shares a corner with a hair triangle (where
    /// the semantic correction's likeness may take the hairline's test).
    touches_hair: Vec<bool>,
    /// `[source][membership]` → where each Gaussian sits on the triangle it
    /// counts for (barycentric), computed on first use by colour seams.
    placements: Vec<[OnceLock<Vec<[f32; 3]>>; 2]>,
    /// The template's seam neighbourhoods, computed on first use.
    seam_neighbours: OnceLock<SeamNeighbours>,
    /// `[source]` → each Gaussian's weight in a mean colour (method §7.5),
    /// computed on first use by colour seams.
    colour_weights: Vec<OnceLock<Vec<f32>>>,
    /// `[source]` → the triangles each Gaussian's footprint reaches
    /// (`footprint_triangles`), computed on first use by colour seams.
    footprints: Vec<OnceLock<Vec<[u32; 4]>>>,
    /// `[source]` → the Gaussians that follow another triangle than their
    /// parent under `anchor = "nearest"` (method §6.8), computed on first use.
    anchors: Vec<OnceLock<SourceAnchors>>,
    /// `[source][membership]` → how surely each Gaussian is skin, computed
    /// on first use by `skin = "base"`.
    skin_likeness: Vec<[OnceLock<Vec<f32>>; 2]>,
    /// `[source][membership]` → per triangle, how much of what the source
    /// shows there is skin, computed on first use by `skin = "base"`.
    triangle_skin: Vec<[OnceLock<Vec<f32>>; 2]>,
}

/// What `skin = "base"` needs while one composite is selected.
struct BaseSkin<'e> {
    engine: &'e Engine,
    membership: Membership,
    /// Per triangle: how fully the base's skin takes over.
    confidence: Vec<f32>,
}

impl BaseSkin<'_> {
    /// The opacity share of `source`'s Gaussians, as the base's skin or as
    /// the swapped-in source.
    fn share(&self, source: usize, of_base: bool) -> SkinShare<'_> {
        SkinShare {
            likeness: self.engine.skin_likeness_of(source, self.membership),
            confidence: &self.confidence,
            of_base,
        }
    }
}

/// What a set of skin-transfer gains depends on: the source, the colour
/// reference and, for the semantic transfer, the membership its regions follow.
type GainKey = (usize, usize, Option<Membership>);

/// What one range of a composite's Gaussians is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Block {
    /// Region whose triangles the Gaussians are bound to.
    pub region: Region,
    /// Source they come from.
    pub source: usize,
    /// For border extras: the neighbouring region whose source they belong to.
    pub extra_from: Option<Region>,
    /// Range in the composite's Gaussian set.
    pub start: usize,
    /// End of the range (exclusive).
    pub end: usize,
}

/// The Gaussians of one source that cross a border into the neighbouring
/// region of another source (the thesis's smoothing and the cross-fade).
struct Crossing {
    /// The region whose source they are.
    from: Region,
    /// The region across the border.
    into: Region,
    /// Their source.
    source: usize,
    /// Each, with its opacity edit.
    extras: Vec<(u32, OpacityEdit)>,
}

/// A composite avatar: blended neutral mesh and the selected, post-processed
/// Gaussians bound to its triangles.
#[derive(Clone, Debug)]
pub struct Composite {
    /// The recipe it was built from.
    pub recipe: ResolvedRecipe,
    /// Blended neutral mesh (identity and static offsets; no expression, no pose).
    pub neutral: Vec<Vec3>,
    /// Relative residual of the neutral blend solve.
    pub residual: f64,
    /// Selected Gaussians (own regions first, then border extras), colours corrected.
    pub gaussians: GaussianSet,
    /// What each range of `gaussians` is.
    pub blocks: Vec<Block>,
    /// Each source's Gaussians reshaped to this composite's shape, as far as
    /// shown yet (`deform = "affine"`, `anchor = "nearest"`): an edit of
    /// the Gaussians alone reuses them.
    reshaped: ReshapedSources,
    /// The local colours its colour seams made so far (`smoothing =
    /// "blend"`): an edit of the Gaussians alone reuses them.
    vertex_colours: VertexColours,
    /// Mean per-channel colour gain applied per region (1 where uncorrected).
    pub colour_gains: [Vec3; Region::COUNT],
    /// Per source, the relighting gain of each of its Gaussians for this
    /// composite's shape (empty until relighting first needs it): an edit
    /// of the Gaussians alone reuses them.
    relight_gains: Vec<Vec<Vec3>>,
    /// Per triangle, how far this composite's surface is from the base's
    /// (`similarity_misfit`; empty until `skin = "base"` first needs it):
    /// an edit of the Gaussians alone reuses it.
    base_misfit: Vec<f32>,
}

/// What an update had to redo.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Changes {
    /// The neutral mesh was re-blended.
    pub shape: bool,
    /// The Gaussian selection was rebuilt.
    pub gaussians: bool,
}

/// A posed composite: vertices and triangle frames of one frame.
#[derive(Clone, Debug, Default)]
pub struct PosedMesh {
    /// Posed vertices.
    pub vertices: Vec<Vec3>,
    /// Triangle frames of the posed mesh.
    pub frames: Vec<TriangleFrame>,
    /// Blend residual of this frame (exact mode; the neutral's in fast mode).
    pub residual: f64,
}

impl Engine {
    /// Precomputes the tables of a database and factors its blend system.
    pub fn new(db: Database) -> Result<Self> {
        let blender = Blender::new(&db.model)?;
        let borders = BorderTables::new(&db.model);
        let neutrals: Vec<Vec<Vec3>> = db
            .sources
            .par_iter()
            .map(|s| s.neutral(&db.model))
            .collect();
        let tables = SelectionTables::new(&db, &neutrals);
        let region_rhs = neutrals
            .par_iter()
            .map(|n| {
                Region::ALL
                    .iter()
                    .map(|&r| blender.region_rhs(r, n))
                    .collect()
            })
            .collect();
        let mean_colour = [Membership::Parent, Membership::Place].map(|m| {
            (0..db.sources.len())
                .into_par_iter()
                .map(|f| {
                    Region::ALL
                        .iter()
                        .map(|&r| {
                            weighted_mean_colour(&db.sources[f].gaussians, tables.region(m, f, r))
                        })
                        .collect()
                })
                .collect()
        });
        // Where each Gaussian sits on its parent triangle: where its
        // colour's baked light is read.
        let parent_placements: Vec<Vec<[f32; 3]>> = (0..db.sources.len())
            .into_par_iter()
            .map(|f| {
                let set = &db.sources[f].gaussians;
                placements(&db.model, set, &neutrals[f], &set.binding)
            })
            .collect();
        let colours = SourceColours::new(&db, &tables, &neutrals, &parent_placements);
        let vertex_triangles = Csr::vertex_triangles(db.model.vertex_count(), &db.model.triangles);
        let hair: Vec<bool> = db
            .model
            .triangle_regions
            .iter()
            .map(|&r| r == Region::Hair)
            .collect();
        let touches_hair = sharing_a_corner(&db.model.triangles, &vertex_triangles, &hair);
        let placements = parent_placements
            .into_iter()
            .map(|parent| {
                let known: [OnceLock<Vec<[f32; 3]>>; 2] = Default::default();
                known[Membership::Parent as usize].get_or_init(|| parent);
                known
            })
            .collect();
        let source_count = db.sources.len();
        Ok(Self {
            db,
            tables,
            borders,
            blender,
            neutrals,
            region_rhs,
            mean_colour,
            colours,
            skin_gains: Mutex::new(HashMap::new()),
            vertex_triangles,
            touches_hair,
            placements,
            seam_neighbours: OnceLock::new(),
            colour_weights: (0..source_count).map(|_| OnceLock::new()).collect(),
            footprints: (0..source_count).map(|_| OnceLock::new()).collect(),
            anchors: (0..source_count).map(|_| OnceLock::new()).collect(),
            skin_likeness: (0..source_count).map(|_| Default::default()).collect(),
            triangle_skin: (0..source_count).map(|_| Default::default()).collect(),
        })
    }

    /// The database.
    pub fn database(&self) -> &Database {
        &self.db
    }

    /// The blend system.
    pub fn blender(&self) -> &Blender {
        &self.blender
    }

    /// The light baked into a source's colours, fitted to its skin (method
    /// §7.10); None where its skin could not tell one.
    pub fn light(&self, source: usize) -> Option<&BakedLight> {
        self.colours.light(source)
    }

    /// Neutral mesh of a source.
    pub fn source_neutral(&self, source: usize) -> &[Vec3] {
        &self.neutrals[source]
    }

    /// Builds a composite from scratch.
    pub fn compose(&self, recipe: &ResolvedRecipe) -> Composite {
        let (neutral, residual) = self.blend_neutral(recipe);
        let mut composite = Composite {
            recipe: recipe.clone(),
            neutral,
            residual,
            gaussians: GaussianSet::default(),
            blocks: Vec::new(),
            reshaped: ReshapedSources::default(),
            vertex_colours: VertexColours::default(),
            colour_gains: [Vec3::ONE; Region::COUNT],
            relight_gains: Vec::new(),
            base_misfit: Vec::new(),
        };
        self.select_into(recipe, &mut composite);
        composite
    }

    /// Brings a composite up to date with a new recipe, redoing only what changed:
    /// shape weights re-blend the neutral; sources, base or post-processing rebuild
    /// the selection; motion, frame and camera cost nothing here.
    pub fn update(&self, composite: &mut Composite, recipe: &ResolvedRecipe) -> Changes {
        let old = &composite.recipe;
        let shape = old.shape != recipe.shape || old.base != recipe.base;
        let changes = Changes {
            shape,
            // Gaussians that follow their triangles' reshaping depend on the shape.
            gaussians: old.gaussians != recipe.gaussians
                || old.base != recipe.base
                || old.post != recipe.post
                || (shape && Self::follows_reshaping(&recipe.post))
                || (shape && recipe.post.shading == Shading::Relit)
                // Where the base's skin fits depends on the shape.
                || (shape && recipe.post.skin == SkinSource::Base),
        };
        if changes.shape {
            let (neutral, residual) = self.blend_neutral(recipe);
            composite.neutral = neutral;
            composite.residual = residual;
            composite.relight_gains.clear();
            composite.base_misfit.clear();
            composite.reshaped.clear();
        }
        if changes.gaussians {
            self.select_into(recipe, composite);
        }
        composite.recipe = recipe.clone();
        changes
    }

    /// Where each Gaussian of source `f` sits on the triangle it counts for
    /// under `membership` (barycentric on the source's neutral mesh).
    fn placements_of(&self, membership: Membership, f: usize) -> &[[f32; 3]] {
        self.placements[f][membership as usize].get_or_init(|| {
            let counted = self.tables.counted_triangles(membership, f);
            placements(
                &self.db.model,
                &self.db.sources[f].gaussians,
                &self.neutrals[f],
                counted,
            )
        })
    }

    /// The triangles each Gaussian of source `f`'s footprint reaches.
    fn footprints_of(&self, f: usize) -> &[[u32; 4]] {
        self.footprints[f].get_or_init(|| {
            let set = &self.db.sources[f].gaussians;
            footprint_triangles(&self.db.model, set, &self.neutrals[f])
        })
    }

    /// Each Gaussian of source `f`'s weight in a mean colour.
    fn colour_weights_of(&self, f: usize) -> &[f32] {
        self.colour_weights[f].get_or_init(|| {
            let set = &self.db.sources[f].gaussians;
            (0..set.len())
                .into_par_iter()
                .map(|i| colour_weight(set, i))
                .collect()
        })
    }

    fn source_of(recipe: &ResolvedRecipe, region: Region) -> usize {
        recipe.gaussians[region.group().index()]
    }

    /// Rebuilds the composite's Gaussian set from the lookup tables, reusing its
    /// buffers (an assignment change allocates nothing once they are large enough).
    fn select_into(&self, recipe: &ResolvedRecipe, composite: &mut Composite) {
        let degree = self
            .db
            .sources
            .iter()
            .map(|s| s.gaussians.sh_degree)
            .max()
            .unwrap_or(0);
        let smoothing = recipe.post.smoothing;
        let membership = recipe.post.membership;
        if recipe.post.shading == Shading::Relit {
            self.relight_gains(recipe, composite);
        } else {
            composite.relight_gains.clear();
        }
        // Cross-fade: own Gaussians near a border keep only part of their opacity.
        let mut own_exponent = vec![1.0f32; self.db.model.triangle_count()];
        let differs =
            |r: Region, p: Region| Self::source_of(recipe, r) != Self::source_of(recipe, p);
        if smoothing == Smoothing::Crossfade {
            for (&(r, p), band) in self.borders.pairs() {
                if differs(r, p) {
                    for &(t, ring) in band {
                        let e = &mut own_exponent[t as usize];
                        *e = e.min(own_share(ring));
                    }
                }
            }
        }
        let topology = Topology {
            triangles: &self.db.model.triangles,
            vertex_triangles: &self.vertex_triangles,
        };
        if recipe.post.skin == SkinSource::Base && composite.base_misfit.is_empty() {
            composite.base_misfit =
                similarity_misfit(&self.neutrals[recipe.base], &composite.neutral, topology);
        }
        let skin = (recipe.post.skin == SkinSource::Base).then(|| BaseSkin {
            engine: self,
            membership,
            confidence: base_skin_confidence(
                recipe,
                &self.db.model.triangle_regions,
                |s| self.triangle_skin_of(s, membership),
                Some((&composite.base_misfit, topology)),
                |s| self.colours.transfer_brightens(s, recipe.base),
            ),
        });
        // Per region, the source's Gaussians counted for it; under `skin =
        // "base"` in a swapped region, those of them that still show and
        // the base's that show there.
        let mut own = Vec::with_capacity(Region::COUNT);
        let mut own_count = 0;
        for region in Region::ALL {
            let f = Self::source_of(recipe, region);
            let parts: Vec<(usize, Cow<[u32]>, Option<SkinShare>)> =
                match skin.as_ref().filter(|_| f != recipe.base) {
                    Some(skin) => [(f, false), (recipe.base, true)]
                        .map(|(s, of_base)| {
                            let share = skin.share(s, of_base);
                            let indices = showing(
                                share,
                                self.tables.region(membership, s, region),
                                self.tables.counted_triangles(membership, s),
                            );
                            (s, Cow::Owned(indices), Some(share))
                        })
                        .into(),
                    None => vec![(
                        f,
                        Cow::Borrowed(self.tables.region(membership, f, region)),
                        None,
                    )],
                };
            for (source, indices, share) in parts {
                if indices.is_empty() && share.is_some_and(|s| s.of_base) {
                    continue;
                }
                own_count += indices.len();
                own.push(OwnBlock {
                    region,
                    source,
                    start: own_count - indices.len(),
                    indices,
                    correction: self.correction(recipe, region, source),
                    skin: share,
                });
            }
        }
        let reshaped = Self::follows_reshaping(&recipe.post);
        if reshaped {
            let wanted: Vec<(usize, &[u32])> =
                own.iter().map(|b| (b.source, &*b.indices)).collect();
            self.make_reshaped(&recipe.post, composite, &wanted);
        }
        let set = &mut composite.gaussians;
        set.resize(own_count, degree);
        set.reserve(own_count / 8);
        composite.vertex_colours.keep_for(recipe);
        let seams = (smoothing == Smoothing::Blend).then(|| {
            let looks = self
                .db
                .model
                .triangle_regions
                .iter()
                .map(|&r| Self::source_of(recipe, r) as u32)
                .collect();
            SeamColours::new(self, recipe, looks, &composite.vertex_colours)
        });
        // The copy reads these tables of every source shown from inside its
        // rayon jobs, and each is built on first use by an initialiser that
        // itself runs rayon. Built there, a job waiting on its initialiser
        // can steal another job that enters the same OnceLock: the thread
        // waits on itself (seen as a hang when two composites were made at
        // once on one engine). So they are built here, before the copy.
        let mut shown: Vec<usize> = Region::ALL
            .iter()
            .map(|&r| Self::source_of(recipe, r))
            .collect();
        shown.sort_unstable();
        shown.dedup();
        for &f in &shown {
            self.placements_of(membership, f);
            self.footprints_of(f);
            self.colour_weights_of(f);
        }
        let copying = CopyOwn {
            blocks: &own,
            membership,
            own_exponent: &own_exponent,
            seams: seams.as_ref(),
            relight: &composite.relight_gains,
            reshaped: reshaped.then_some(&composite.reshaped),
        };
        let mut copied = copy_own(self, &copying, set);
        drop(seams);
        let made = copied
            .iter_mut()
            .flat_map(|c| std::mem::take(&mut c.colours_made));
        let vertex_count = self.db.model.vertex_count();
        composite.vertex_colours.add(made, vertex_count);
        let blocks = &mut composite.blocks;
        blocks.clear();
        let gains = &mut composite.colour_gains;
        *gains = [Vec3::ONE; Region::COUNT];
        // Own Gaussians near another source's triangles: their reach is
        // limited once they sit on the composite's shape.
        let mut at_seams: Vec<u32> = Vec::new();
        let mut gain_sums = vec![Vec3::ZERO; own.len()];
        for chunk in copied {
            gain_sums[chunk.block] += chunk.gain_sum;
            at_seams.extend(chunk.at_seams);
        }
        for (block, gain_sum) in own.iter().zip(gain_sums) {
            let n = block.indices.len();
            if n > 0 && !block.skin.is_some_and(|s| s.of_base) {
                gains[block.region.index()] = gain_sum / n as f32;
            }
            blocks.push(Block {
                region: block.region,
                source: block.source,
                extra_from: None,
                start: block.start,
                end: block.start + n,
            });
        }
        if matches!(smoothing, Smoothing::Thesis | Smoothing::Crossfade) {
            self.add_border_extras(recipe, composite);
        }
        let triangles = &self.db.model.triangles;
        limit_reach(
            &mut composite.gaussians,
            &at_seams,
            &composite.neutral,
            triangles,
        );
    }

    /// Appends the border extras of the thesis's smoothing and of the
    /// cross-fade: each source's Gaussians of the border rings on the other
    /// side of a border, with part of their opacity.
    fn add_border_extras(&self, recipe: &ResolvedRecipe, composite: &mut Composite) {
        let smoothing = recipe.post.smoothing;
        let membership = recipe.post.membership;
        let mut crossings: Vec<Crossing> = Vec::new();
        for (&(r, p), band) in self.borders.pairs() {
            let f = Self::source_of(recipe, r);
            if f == Self::source_of(recipe, p) {
                continue;
            }
            let extras: Vec<(u32, OpacityEdit)> = band
                .iter()
                .filter_map(|&(t, ring)| match smoothing {
                    Smoothing::Thesis if ring == 1 => Some((t, OpacityEdit::Scale(0.5))),
                    Smoothing::Crossfade => Some((t, OpacityEdit::Split(1.0 - own_share(ring)))),
                    _ => None,
                })
                .flat_map(|(t, edit)| {
                    let counted = self.tables.triangle(membership, f, t);
                    counted.iter().map(move |&i| (i, edit))
                })
                .collect();
            if !extras.is_empty() {
                crossings.push(Crossing {
                    from: r,
                    into: p,
                    source: f,
                    extras,
                });
            }
        }
        let reshaped = Self::follows_reshaping(&recipe.post);
        if reshaped {
            let indices: Vec<(usize, Vec<u32>)> = crossings
                .iter()
                .map(|c| (c.source, c.extras.iter().map(|&(i, _)| i).collect()))
                .collect();
            let wanted: Vec<(usize, &[u32])> =
                indices.iter().map(|(f, i)| (*f, i.as_slice())).collect();
            self.make_reshaped(&recipe.post, composite, &wanted);
        }
        let kept = reshaped.then_some(&composite.reshaped);
        for Crossing {
            from: r,
            into: p,
            source: f,
            extras,
        } in crossings
        {
            let correction = self.correction(recipe, p, f);
            let set = &mut composite.gaussians;
            let start = set.len();
            for (i, edit) in extras {
                self.push_corrected(set, f, i, &correction, edit);
                let last = set.len() - 1;
                relight_sh(set.sh_of_mut(last), &composite.relight_gains, f, i);
                if let Some(&placed) = kept.and_then(|k| k.placed(f, i)) {
                    (set.position[last], set.rotation[last], set.log_scale[last]) = placed;
                }
            }
            composite.blocks.push(Block {
                region: p,
                source: f,
                extra_from: Some(r),
                start,
                end: set.len(),
            });
        }
    }

    /// Per Gaussian of `source`: how surely it is skin ([`skin_likeness`]).
    fn skin_likeness_of(&self, source: usize, membership: Membership) -> &[f32] {
        self.skin_likeness[source][membership as usize].get_or_init(|| {
            skin_likeness(
                self.colours.seen(source),
                self.tables.counted_triangles(membership, source),
                &self.db.model.triangle_regions,
                self.colours.skin(source),
                |i| {
                    self.colours
                        .brightness_against_hair(source, i)
                        .map(|(r, h)| dark_features::skin_share_of_area(r, h))
                },
            )
        })
    }

    /// Per triangle: how much of what `source` shows there is skin
    /// ([`triangle_skin`]).
    fn triangle_skin_of(&self, source: usize, membership: Membership) -> &[f32] {
        self.triangle_skin[source][membership as usize].get_or_init(|| {
            triangle_skin(
                self.tables.counted_triangles(membership, source),
                self.skin_likeness_of(source, membership),
                self.colour_weights_of(source),
                self.db.model.triangle_count(),
            )
        })
    }

    /// Whether a recipe's Gaussians depend on how the blend reshaped their
    /// triangles beyond their parent's rotation and size (method §6.7, §6.8).
    fn follows_reshaping(post: &PostProcess) -> bool {
        post.deform == Deform::Affine || post.anchor == Anchor::Nearest
    }

    /// The Gaussians of source `f` that follow another triangle than their
    /// parent under `anchor = "nearest"`, in that triangle's frame.
    fn anchors_of(&self, f: usize) -> &SourceAnchors {
        self.anchors[f].get_or_init(|| {
            SourceAnchors::new(
                &self.db.model,
                &self.db.sources[f].gaussians,
                &self.neutrals[f],
            )
        })
    }

    /// Makes the composite's reshaped values (method §6.7, §6.8) of
    /// `wanted` — per source, Gaussians of it — where not made yet for its
    /// shape, as `post` says: the recipe being applied (an update sets the
    /// composite's own recipe only after the selection, so that one is
    /// still the previous recipe's).
    fn make_reshaped(
        &self,
        post: &PostProcess,
        composite: &mut Composite,
        wanted: &[(usize, &[u32])],
    ) {
        let nearest = post.anchor == Anchor::Nearest;
        let mut used = vec![false; self.db.sources.len()];
        wanted.iter().for_each(|&(f, _)| used[f] = true);
        // Anchors are built here, before the parallel reshaping reads them
        // (see `select_into` on tables built inside rayon jobs).
        let sources: Vec<ReshapeSource> = (0..self.db.sources.len())
            .map(|f| ReshapeSource {
                neutral: &self.neutrals[f],
                gaussians: &self.db.sources[f].gaussians,
                anchors: (used[f] && nearest).then(|| self.anchors_of(f)),
            })
            .collect();
        let reshaping = Reshaping {
            triangles: &self.db.model.triangles,
            target: &composite.neutral,
            options: ReshapeOptions {
                affine: post.deform == Deform::Affine,
                nearest,
            },
        };
        composite.reshaped.make(&reshaping, &sources, wanted);
    }

    /// Makes the relighting gains of every source the recipe draws Gaussians
    /// from, for the composite's shape, where they are not made yet: per
    /// Gaussian, the source's light for the exposure where it sits on its
    /// parent triangle here over that on the source's own neutral (one where
    /// nothing there moved).
    fn relight_gains(&self, recipe: &ResolvedRecipe, composite: &mut Composite) {
        let gains = &mut composite.relight_gains;
        if gains.len() != self.db.sources.len() {
            *gains = vec![Vec::new(); self.db.sources.len()];
        }
        let model = &self.db.model;
        let mut target = None;
        // Under `skin = "base"` the base shows in every swapped region.
        let base = (recipe.post.skin == SkinSource::Base).then_some(recipe.base);
        for f in recipe.gaussians.iter().copied().chain(base) {
            let (Some(light), true) = (self.colours.light(f), gains[f].is_empty()) else {
                continue;
            };
            let to: &Vec<Exposure> = target
                .get_or_insert_with(|| vertex_exposures(&composite.neutral, &model.triangles));
            let bary = self.placements_of(Membership::Parent, f);
            let binding = &self.db.sources[f].gaussians.binding;
            gains[f] = self
                .colours
                .exposures(f)
                .par_iter()
                .zip(bary)
                .zip(binding)
                .map(|((&from, &bary), &t)| {
                    let Some(&tri) = model.triangles.get(t as usize) else {
                        return Vec3::ONE;
                    };
                    let to = Exposure::at(to, tri, bary);
                    // Unmoved surface (most, for a small edit) costs a compare.
                    if from != to && from.normal != Vec3::ZERO && to.normal != Vec3::ZERO {
                        light.gain(from, to)
                    } else {
                        Vec3::ONE
                    }
                })
                .collect();
        }
    }

    /// Copies Gaussian `i` of source `f` into `set` with a colour correction and an
    /// opacity edit.
    fn push_corrected(
        &self,
        set: &mut GaussianSet,
        f: usize,
        i: u32,
        correction: &Correction,
        opacity: OpacityEdit,
    ) {
        let src = &self.db.sources[f].gaussians;
        let i = i as usize;
        set.push_from(src, i, opacity.apply(src.opacity_logit[i]));
        let gain = correction.gain(i);
        if gain != Vec3::ONE {
            let last = set.len() - 1;
            apply_gain(set.sh_of_mut(last), gain);
        }
    }
}

impl SourceTables for Engine {
    fn model(&self) -> &HeadModel {
        &self.db.model
    }

    fn gaussians(&self, source: usize) -> &GaussianSet {
        &self.db.sources[source].gaussians
    }

    fn seam_neighbours(&self) -> &SeamNeighbours {
        self.seam_neighbours
            .get_or_init(|| SeamNeighbours::new(&self.db.model.template))
    }

    fn counted_triangles(&self, membership: Membership, source: usize) -> &[u32] {
        self.tables.counted_triangles(membership, source)
    }

    fn triangle_gaussians(&self, membership: Membership, source: usize, triangle: u32) -> &[u32] {
        self.tables.triangle(membership, source, triangle)
    }

    fn placements(&self, membership: Membership, source: usize) -> &[[f32; 3]] {
        self.placements_of(membership, source)
    }

    fn footprints(&self, source: usize) -> &[[u32; 4]] {
        self.footprints_of(source)
    }

    fn colour_weights(&self, source: usize) -> &[f32] {
        self.colour_weights_of(source)
    }

    fn seen(&self, source: usize) -> &[Vec3] {
        self.colours.seen(source)
    }

    fn triangles_around(&self, v: u32) -> &[u32] {
        self.vertex_triangles.row(v as usize)
    }

    fn correction(&self, recipe: &ResolvedRecipe, region: Region, source: usize) -> Correction {
        Engine::correction(self, recipe, region, source)
    }
}
