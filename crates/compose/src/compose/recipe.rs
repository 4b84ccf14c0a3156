//! Recipes: the whole composite in one small value, stored as TOML.
//!
//! ```toml
//! base = "ada"                      # base avatar: default for every group
//!
//! [groups.nose]                     # any of mouth, eyes, ears, neck, hair, nose, face
//! gaussians = "bram"                # whose Gaussians the group shows
//! shape = { bram = 0.7, ada = 0.3 } # convex shape weights (normalised if they don't sum to 1)
//!
//! [post]
//! smoothing = "thesis"              # off | thesis | crossfade | blend
//! colour = "thesis"                 # off | thesis | skin | semantic
//!
//! [animation]
//! motion = "talk"                   # a database motion, or "rest"
//! frame = 0
//! mode = "fast"                     # fast | exact
//!
//! [camera]
//! yaw_deg = 0.0
//! pitch_deg = 0.0
//! radius = 2.5
//! fov_deg = 7.5
//! target = [0.0, -0.025, 0.0]
//! ```
//! Groups that are not listed take both Gaussians and shape from the base.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::avatar::database::Database;
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::scene::camera::Orbit;

/// Recipe file format version written by this build.
pub const RECIPE_VERSION: u32 = 1;

/// Border smoothing between regions whose Gaussians come from different sources.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Smoothing {
    /// No extra Gaussians.
    #[default]
    Off,
    /// Thesis 4.2.2: copy the neighbour's Gaussians on the bordering triangles at half opacity.
    Thesis,
    /// A cross-fade over a band of triangles that keeps coverage exact (see `smoothing`).
    Crossfade,
    /// Colours cross-blend over a centimetre of template surface (see
    /// `seams`): opacity and geometry untouched, no extra Gaussians.
    Blend,
}

/// Colour correction of regions whose Gaussians come from another source than the base.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ColourCorrection {
    /// Colours as captured.
    #[default]
    Off,
    /// Thesis 4.2.2: per-region gain c̄_base / c̄_f on weighted mean colours.
    Thesis,
    /// Skin transfer (the ratio of the sources' mean skin colours, per channel
    /// in linear RGB) on skin-coloured Gaussians only.
    Skin,
    /// The same transfer on skin only by what it is: never in regions that
    /// hold no skin (teeth, hair, eyeballs), and elsewhere only where a
    /// Gaussian's colour is close to its source's own skin — in the lips and the
    /// mouth's inside also no redder in hue (lips, brows, lashes and beards
    /// keep theirs; docs/method.md §7.7).
    Semantic,
}

/// Which Gaussians of a source count for a region (docs/method.md §5.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Membership {
    /// Thesis ch. 5: a Gaussian belongs to the region of its parent triangle,
    /// wherever training moved it.
    Parent,
    /// A Gaussian belongs to the region of the surface it sits on: its parent's
    /// unless another region's triangle is clearly nearer to its centre.
    #[default]
    Place,
}

/// How a source's Gaussians follow a triangle whose shape the blend changed
/// (docs/method.md §6.7).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Deform {
    /// GaussianAvatars and the thesis: the triangle's rotation and one
    /// scale (its size), the same along every axis, the normal included.
    #[default]
    Similarity,
    /// The triangle's whole in-plane stretch and shear, and along the normal
    /// the square root of its area's change.
    Affine,
}

/// Which triangle's reshaping moves a Gaussian (docs/method.md §6.8). A
/// Gaussian stays bound to its parent triangle either way (posing, export).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Anchor {
    /// GaussianAvatars and the thesis: its parent triangle, wherever
    /// training moved it.
    #[default]
    Parent,
    /// The triangle of its source's surface nearest its centre: a Gaussian
    /// that training moved over another triangle follows the surface it
    /// shows, not the one it was first made on.
    Nearest,
}

/// What a source's baked light does where the blend turned its triangles
/// (docs/method.md §7.10).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Shading {
    /// Colours as trained, lit as the source's own face was.
    #[default]
    Kept,
    /// Each Gaussian relit by its source's light for its triangle's new
    /// normal over the old (the light fitted to the source's skin).
    Relit,
}

/// Where a swapped region's skin comes from (docs/method.md §7.11).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkinSource {
    /// The thesis: every Gaussian of the region from its source, skin included.
    #[default]
    Source,
    /// The source's features (lips, brows, lashes, iris, hair, beard) over
    /// the base's own skin, in proportion to the base's share of the
    /// region's shape and where both show skin.
    Base,
}

/// A finishing step over the composed Gaussians (docs/method.md §7.12).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Fit {
    /// The Gaussians as composed.
    #[default]
    Off,
    /// The colours and opacities of the Gaussians beside a change of source
    /// fitted to what the sources themselves draw there (the seam fit), and,
    /// where the Gaussians are relit, the colours of those whose light the
    /// shape moved, to the sources relit pixel by pixel. The
    /// engine composes without it; whoever shows or writes the composite
    /// runs it (seconds, not milliseconds: the editor in the background).
    Seams,
}

/// How the composite is animated.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnimationMode {
    /// Blend the neutral meshes once, animate the composite as one head.
    #[default]
    Fast,
    /// The thesis: pose every source and blend the posed meshes every frame.
    Exact,
}

/// The Gaussian source and shape weights of one group.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupEdit {
    /// Source whose Gaussians the group shows.
    pub gaussians: String,
    /// Shape weights by source name (non-negative, not all zero). Left out
    /// (or empty), the group keeps the base's shape.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub shape: BTreeMap<String, f64>,
}

/// Post-processing toggles.
#[derive(Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PostProcess {
    /// Border smoothing.
    pub smoothing: Smoothing,
    /// Colour correction.
    pub colour: ColourCorrection,
    /// Which Gaussians count for a region.
    #[serde(skip_serializing_if = "is_default_membership")]
    pub membership: Membership,
    /// How Gaussians follow a reshaped triangle.
    #[serde(skip_serializing_if = "is_default_deform")]
    pub deform: Deform,
    /// Which triangle's reshaping a Gaussian follows.
    #[serde(skip_serializing_if = "is_default_anchor")]
    pub anchor: Anchor,
    /// Whether colours are relit for their triangles' new normals.
    #[serde(skip_serializing_if = "is_default_shading")]
    pub shading: Shading,
    /// Where a swapped region's skin comes from.
    #[serde(skip_serializing_if = "is_default_skin")]
    pub skin: SkinSource,
    /// The finishing fit over the composed Gaussians.
    #[serde(skip_serializing_if = "is_default_fit")]
    pub fit: Fit,
}

impl PostProcess {
    /// The thesis's post-processing (§4.2.2) with its membership by parent
    /// triangle: what `visage bench composites --pipeline thesis` measures.
    pub const THESIS: PostProcess = PostProcess {
        smoothing: Smoothing::Thesis,
        colour: ColourCorrection::Thesis,
        membership: Membership::Parent,
        deform: Deform::Similarity,
        anchor: Anchor::Parent,
        shading: Shading::Kept,
        skin: SkinSource::Source,
        fit: Fit::Off,
    };
    /// The post-processing that measured best against ground truth
    /// (docs/method.md §13, README): `--pipeline ours` and the study's edited
    /// category.
    pub const BEST: PostProcess = PostProcess {
        smoothing: Smoothing::Blend,
        colour: ColourCorrection::Semantic,
        membership: Membership::Place,
        deform: Deform::Affine,
        anchor: Anchor::Nearest,
        shading: Shading::Relit,
        skin: SkinSource::Base,
        fit: Fit::Seams,
    };
}

/// A named set of post-processing options: what an editor session starts
/// from (its header's `post` line).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PostPreset {
    /// [`PostProcess::default`]: the swap as selected, no correction (what
    /// sessions without a `post` line, from before session 27, start from).
    #[default]
    Off,
    /// [`PostProcess::THESIS`].
    Thesis,
    /// [`PostProcess::BEST`]: what a new editor session starts from.
    Ours,
}

impl PostPreset {
    /// Every preset, in the order of [`PostPreset::name`]s in messages.
    pub const ALL: [PostPreset; 3] = [PostPreset::Off, PostPreset::Thesis, PostPreset::Ours];

    /// The options it names.
    pub fn post(self) -> PostProcess {
        match self {
            PostPreset::Off => PostProcess::default(),
            PostPreset::Thesis => PostProcess::THESIS,
            PostPreset::Ours => PostProcess::BEST,
        }
    }

    /// Its name in session headers.
    pub fn name(self) -> &'static str {
        match self {
            PostPreset::Off => "off",
            PostPreset::Thesis => "thesis",
            PostPreset::Ours => "ours",
        }
    }

    /// The preset a name (as [`PostPreset::name`] writes it) names.
    pub fn from_name(name: &str) -> Option<PostPreset> {
        Self::ALL.into_iter().find(|p| p.name() == name)
    }
}

fn is_default_membership(m: &Membership) -> bool {
    *m == Membership::default()
}

fn is_default_deform(d: &Deform) -> bool {
    *d == Deform::default()
}

fn is_default_anchor(a: &Anchor) -> bool {
    *a == Anchor::default()
}

fn is_default_shading(s: &Shading) -> bool {
    *s == Shading::default()
}

fn is_default_skin(s: &SkinSource) -> bool {
    *s == SkinSource::default()
}

fn is_default_fit(f: &Fit) -> bool {
    *f == Fit::default()
}

/// Prints like a derived `Debug`, leaving `membership`, `deform`, `anchor`,
/// `shading`, `skin` and `fit` out while they are the defaults: state hashes
/// (which hash the recipe's `Debug` text) of recorded sessions stay what they
/// were before the field existed.
impl std::fmt::Debug for PostProcess {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let mut d = f.debug_struct("PostProcess");
        d.field("smoothing", &self.smoothing)
            .field("colour", &self.colour);
        if self.membership != Membership::default() {
            d.field("membership", &self.membership);
        }
        if self.deform != Deform::default() {
            d.field("deform", &self.deform);
        }
        if self.anchor != Anchor::default() {
            d.field("anchor", &self.anchor);
        }
        if self.shading != Shading::default() {
            d.field("shading", &self.shading);
        }
        if self.skin != SkinSource::default() {
            d.field("skin", &self.skin);
        }
        if self.fit != Fit::default() {
            d.field("fit", &self.fit);
        }
        d.finish()
    }
}

/// Manual adjustments added to the motion's frame (axis-angle radians and
/// expression coefficients), as set from the editor's animation panel.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PoseOffsets {
    /// Added to the jaw rotation.
    pub jaw: [f32; 3],
    /// Added to the neck rotation.
    pub neck: [f32; 3],
    /// Added to both eye rotations.
    pub eyes: [f32; 3],
    /// Added to the first expression components.
    pub expression: [f32; 5],
}

impl PoseOffsets {
    /// True when nothing is offset.
    pub fn is_zero(&self) -> bool {
        *self == PoseOffsets::default()
    }
}

/// The driving motion and frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Animation {
    /// Motion name, or "rest".
    pub motion: String,
    /// Frame index (wraps around the motion's length).
    pub frame: usize,
    /// Fast (blend once) or exact (blend every frame).
    pub mode: AnimationMode,
    /// Manual pose and expression adjustments.
    #[serde(skip_serializing_if = "PoseOffsets::is_zero")]
    pub offsets: PoseOffsets,
}

impl Default for Animation {
    fn default() -> Self {
        Self {
            motion: "rest".into(),
            frame: 0,
            mode: AnimationMode::Fast,
            offsets: PoseOffsets::default(),
        }
    }
}

/// A composite avatar described by name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recipe {
    /// File format version.
    #[serde(default = "default_version")]
    pub version: u32,
    /// The base avatar.
    pub base: String,
    /// Edited groups.
    #[serde(default)]
    pub groups: BTreeMap<String, GroupEdit>,
    /// Post-processing.
    #[serde(default)]
    pub post: PostProcess,
    /// Animation.
    #[serde(default)]
    pub animation: Animation,
    /// Camera.
    #[serde(default)]
    pub camera: Orbit,
}

fn default_version() -> u32 {
    RECIPE_VERSION
}

impl Recipe {
    /// Every source the recipe names (base, Gaussians, shape weights), sorted.
    pub fn source_names(&self) -> Vec<String> {
        let mut names: Vec<String> =
            std::iter::once(self.base.clone())
                .chain(self.groups.values().flat_map(|g| {
                    std::iter::once(g.gaussians.clone()).chain(g.shape.keys().cloned())
                }))
                .collect();
        names.sort();
        names.dedup();
        names
    }

    /// The recipe that shows `base` unedited.
    pub fn unedited(base: &str) -> Self {
        Self {
            version: RECIPE_VERSION,
            base: base.to_string(),
            groups: BTreeMap::new(),
            post: PostProcess::default(),
            animation: Animation::default(),
            camera: Orbit::default(),
        }
    }

    /// Parses a recipe from TOML text; errors name the problem in one line.
    pub fn from_toml(text: &str) -> Result<Self> {
        let recipe: Recipe = toml::from_str(text)
            .map_err(|e| Error::input(format!("invalid recipe: {}", e.message().trim())))?;
        if recipe.version != RECIPE_VERSION {
            return Err(Error::input(format!(
                "recipe version {} is not supported (this build reads version {RECIPE_VERSION})",
                recipe.version
            )));
        }
        Ok(recipe)
    }

    /// Reads a recipe file.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read recipe {}: {e}", path.display())))?;
        Self::from_toml(&text).map_err(|e| Error::input(format!("{}: {e}", path.display())))
    }

    /// The canonical TOML text (stable ordering), used for files and state hashes.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("recipes always serialise")
    }
}

/// A recipe checked against a database, with names turned into indices and shape
/// weights normalised to sum to 1.
#[derive(Clone, Debug, PartialEq)]
pub struct ResolvedRecipe {
    /// Index of the base source.
    pub base: usize,
    /// Gaussian source per group, in [`Group::ALL`] order.
    pub gaussians: [usize; Group::COUNT],
    /// Shape weights per group over all sources (each row sums to 1).
    pub shape: [Vec<f64>; Group::COUNT],
    /// Post-processing.
    pub post: PostProcess,
    /// Motion index, or `None` for the rest pose.
    pub motion: Option<usize>,
    /// Frame index.
    pub frame: usize,
    /// Animation mode.
    pub mode: AnimationMode,
    /// Manual pose and expression adjustments.
    pub offsets: PoseOffsets,
    /// Camera.
    pub camera: Orbit,
}

impl ResolvedRecipe {
    /// Sources with a non-zero shape weight in some group (always includes the base).
    pub fn shape_sources(&self) -> Vec<usize> {
        let n = self.shape[0].len();
        let mut used: Vec<usize> = (0..n)
            .filter(|&f| self.shape.iter().any(|row| row[f] > 0.0))
            .collect();
        if !used.contains(&self.base) {
            used.push(self.base);
            used.sort();
        }
        used
    }
}

/// Smallest positive weight kept after normalisation; smaller ones are dropped
/// (they cannot change a vertex by more than ~1e-12 m but would cost a source).
const NEGLIGIBLE_WEIGHT: f64 = 1e-15;

impl Recipe {
    /// Checks the recipe against a database and resolves names to indices.
    pub fn resolve(&self, db: &Database) -> Result<ResolvedRecipe> {
        let source = |name: &str, what: &str| {
            db.source_index(name).ok_or_else(|| {
                Error::input(format!(
                    "unknown source '{}' in {what} (known: {})",
                    crate::text::printable(name),
                    db.sources
                        .iter()
                        .map(|s| s.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })
        };
        let base = source(&self.base, "base")?;
        let n = db.sources.len();
        let mut gaussians = [base; Group::COUNT];
        let mut shape: [Vec<f64>; Group::COUNT] = std::array::from_fn(|_| {
            let mut row = vec![0.0; n];
            row[base] = 1.0;
            row
        });
        for (name, edit) in &self.groups {
            let group = Group::from_name(name).ok_or_else(|| {
                Error::input(format!(
                    "unknown group '{}' (groups: {})",
                    crate::text::printable(name),
                    Group::ALL.map(Group::name).join(", ")
                ))
            })?;
            let g = group.index();
            gaussians[g] = source(&edit.gaussians, &format!("groups.{name}.gaussians"))?;
            if edit.shape.is_empty() {
                continue;
            }
            let mut row = vec![0.0; n];
            for (src, &w) in &edit.shape {
                let f = source(src, &format!("groups.{name}.shape"))?;
                if !w.is_finite() || w < 0.0 {
                    return Err(Error::input(format!(
                        "shape weight {w} for '{}' in group {name} must be a finite number ≥ 0",
                        crate::text::printable(src)
                    )));
                }
                row[f] += w;
            }
            let sum: f64 = row.iter().sum();
            if sum <= 0.0 {
                return Err(Error::input(format!(
                    "the shape weights of group {name} are all zero; give at least one source a positive weight"
                )));
            }
            for w in &mut row {
                *w /= sum;
                if *w < NEGLIGIBLE_WEIGHT {
                    *w = 0.0;
                }
            }
            let sum: f64 = row.iter().sum();
            row.iter_mut().for_each(|w| *w /= sum);
            shape[g] = row;
        }
        let motion = match self.animation.motion.as_str() {
            "rest" => None,
            name => Some(db.motion_index(name).ok_or_else(|| {
                Error::input(format!(
                    "unknown motion '{}' (motions: rest, {})",
                    crate::text::printable(name),
                    db.motions
                        .iter()
                        .map(|m| m.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", ")
                ))
            })?),
        };
        let c = &self.camera;
        let o = &self.animation.offsets;
        if !o
            .jaw
            .iter()
            .chain(&o.neck)
            .chain(&o.eyes)
            .chain(&o.expression)
            .all(|x| x.is_finite())
        {
            return Err(Error::input("animation offsets must be finite numbers"));
        }
        let camera_ok = c.radius.is_finite()
            && c.radius > 0.0
            && c.fov_deg.is_finite()
            && c.fov_deg > 0.0
            && c.fov_deg < 170.0
            && c.yaw_deg.is_finite()
            && c.pitch_deg.is_finite()
            && c.target.iter().all(|x| x.is_finite());
        if !camera_ok {
            return Err(Error::input(
                "camera needs a finite radius > 0, a field of view in (0, 170) degrees and finite angles and target",
            ));
        }
        Ok(ResolvedRecipe {
            base,
            gaussians,
            shape,
            post: self.post,
            motion,
            frame: self.animation.frame,
            mode: self.animation.mode,
            offsets: self.animation.offsets,
            camera: self.camera,
        })
    }
}
