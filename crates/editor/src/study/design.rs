//! Study folders. `study build` turns a spec (categories, each a database,
//! post-processing and recipes or unedited sources) into a folder holding
//! `study.toml` (categories, avatars, display settings, the sources'
//! labels), one final recipe per avatar under `recipes/`, and `answers/` for
//! the participants' journals. Each participant sees the avatars in their own
//! random order, drawn from the study's seed and their ID.
//!
//! Spec:
//! ```toml
//! title = "Built-in authenticity study"
//! seed = 7
//! [display]                      # thesis §6.2.3 (these are the defaults)
//! motion = "blink"               # a looping closed-mouth motion
//! fps = 25.0
//! radius = 2.5
//! yaw_limit_deg = 45.0
//! pitch_limit_deg = 15.0
//!
//! [[category]]
//! name = "edit_smooth"
//! database = { db = "builtin", gaussians_per_avatar = 20000 }
//! post = { smoothing = "thesis" } # or a preset: "off", "thesis", "ours"
//! recipes = ["random"]           # recipe files, or folders of them
//!
//! [[category]]
//! name = "unedited"
//! unedited = ["ada", "bram"]
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rand::seq::SliceRandom;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::compose::composition::Attributes;
use crate::compose::recipe::{PostPreset, PostProcess, Recipe};
use crate::error::{Error, Result};
use crate::pipeline::DatabaseSpec;

/// Version of `study.toml` written by this build.
pub const STUDY_VERSION: u32 = 1;
/// The study description inside a study folder.
pub const STUDY_FILE: &str = "study.toml";
/// Folder of the final recipes.
pub const RECIPES_DIR: &str = "recipes";
/// Folder of the participants' journals.
pub const ANSWERS_DIR: &str = "answers";

/// How avatars are shown (thesis §6.2.3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Display {
    /// The looping motion every avatar plays (closed-mouth in the thesis).
    pub motion: String,
    /// Frames per second of the loop.
    pub fps: f64,
    /// Orbit radius, locked.
    pub radius: f32,
    /// Yaw freedom either side of the front, degrees.
    pub yaw_limit_deg: f32,
    /// Pitch freedom either side of level, degrees.
    pub pitch_limit_deg: f32,
}

impl Default for Display {
    fn default() -> Self {
        Self {
            motion: "blink".into(),
            fps: 25.0,
            radius: 2.5,
            yaw_limit_deg: 45.0,
            pitch_limit_deg: 15.0,
        }
    }
}

impl Display {
    /// Yaw and pitch held inside the limits.
    pub fn clamp(&self, yaw_deg: f32, pitch_deg: f32) -> (f32, f32) {
        (
            yaw_deg.clamp(-self.yaw_limit_deg, self.yaw_limit_deg),
            pitch_deg.clamp(-self.pitch_limit_deg, self.pitch_limit_deg),
        )
    }

    fn check(&self) -> Result<()> {
        let ok = self.fps.is_finite()
            && self.fps > 0.0
            && self.radius.is_finite()
            && self.radius > 0.0
            && (0.0..=180.0).contains(&self.yaw_limit_deg)
            && (0.0..=89.0).contains(&self.pitch_limit_deg);
        if ok {
            Ok(())
        } else {
            Err(Error::input(
                "display needs fps > 0, radius > 0, yaw_limit_deg in 0..=180 and pitch_limit_deg in 0..=89",
            ))
        }
    }
}

/// The database with its paths made absolute against `dir` (the spec's
/// folder), so the built study opens from anywhere.
fn anchored(db: &DatabaseSpec, dir: &Path) -> DatabaseSpec {
    let anchor = |p: &Path| std::path::absolute(dir.join(p)).unwrap_or_else(|_| dir.join(p));
    DatabaseSpec {
        db: if db.db == "builtin" {
            db.db.clone()
        } else {
            anchor(Path::new(&db.db)).display().to_string()
        },
        flame: db.flame.as_deref().map(anchor),
        masks: db.masks.as_deref().map(anchor),
        ..db.clone()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CategorySpec {
    name: String,
    #[serde(default)]
    database: DatabaseSpec,
    #[serde(default, deserialize_with = "post_spec")]
    post: PostProcess,
    #[serde(default)]
    recipes: Vec<PathBuf>,
    #[serde(default)]
    unedited: Vec<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct StudySpec {
    #[serde(default)]
    title: String,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default)]
    display: Display,
    #[serde(rename = "category", default)]
    categories: Vec<CategorySpec>,
}

/// A category's `post`: a preset's name ("off", "thesis", "ours": what the
/// editor starts from and `bench composites --pipeline` names) or a table
/// of options as a recipe's `[post]`.
fn post_spec<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<PostProcess, D::Error> {
    struct PostVisitor;
    impl<'de> serde::de::Visitor<'de> for PostVisitor {
        type Value = PostProcess;
        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str(
                "a preset (\"off\", \"thesis\" or \"ours\") or a table of post-processing options",
            )
        }
        fn visit_str<E: serde::de::Error>(self, name: &str) -> std::result::Result<PostProcess, E> {
            PostPreset::from_name(name)
                .map(PostPreset::post)
                .ok_or_else(|| {
                    E::custom(format!(
                        "unknown preset '{}' (give \"off\", \"thesis\" or \"ours\")",
                        crate::text::printable(name)
                    ))
                })
        }
        fn visit_map<M: serde::de::MapAccess<'de>>(
            self,
            map: M,
        ) -> std::result::Result<PostProcess, M::Error> {
            PostProcess::deserialize(serde::de::value::MapAccessDeserializer::new(map))
        }
    }
    d.deserialize_any(PostVisitor)
}

fn default_seed() -> u64 {
    1
}

/// A category of a built study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Category {
    /// Its name (never shown to participants).
    pub name: String,
    /// The database its avatars come from.
    pub database: DatabaseSpec,
    /// Post-processing applied to every avatar in it.
    pub post: PostProcess,
}

/// One avatar of a built study.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StudyAvatar {
    /// Its number (1, 2, … in category order).
    pub id: u32,
    /// Its category's name.
    pub category: String,
    /// Its final recipe, relative to the study folder.
    pub recipe: PathBuf,
}

/// A built study (`study.toml`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Study {
    /// File format version.
    pub version: u32,
    /// Title shown to participants.
    pub title: String,
    /// Seed of the participants' orders.
    pub seed: u64,
    /// How avatars are shown.
    pub display: Display,
    /// The categories.
    #[serde(rename = "category")]
    pub categories: Vec<Category>,
    /// The avatars.
    #[serde(rename = "avatar")]
    pub avatars: Vec<StudyAvatar>,
    /// The sources' labels, from the databases, for exclusion rules.
    #[serde(default)]
    pub attributes: Attributes,
}

/// A study folder, opened.
#[derive(Clone, Debug)]
pub struct StudyFolder {
    /// The folder.
    pub dir: PathBuf,
    /// Its `study.toml`.
    pub study: Study,
    /// A short hash of `study.toml`, recorded in every journal so answers are
    /// never mixed with another build's.
    pub fingerprint: String,
}

impl StudyFolder {
    /// Opens a built study.
    pub fn open(dir: &Path) -> Result<StudyFolder> {
        let path = dir.join(STUDY_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            Error::input(format!(
                "cannot read {} ({e}); build a study with 'visage study build SPEC --out DIR'",
                path.display()
            ))
        })?;
        let study: Study = toml::from_str(&text).map_err(|e| {
            Error::input(format!(
                "{}: invalid study: {}",
                path.display(),
                e.message().trim()
            ))
        })?;
        if study.version != STUDY_VERSION {
            return Err(Error::input(format!(
                "{}: study version {} is not supported (this build reads version {STUDY_VERSION})",
                path.display(),
                study.version
            )));
        }
        study
            .display
            .check()
            .map_err(|e| Error::input(format!("{}: {e}", path.display())))?;
        Ok(StudyFolder {
            dir: dir.to_path_buf(),
            fingerprint: blake3::hash(text.as_bytes()).to_hex()[..16].to_string(),
            study,
        })
    }

    /// An avatar's final recipe.
    pub fn recipe(&self, avatar: &StudyAvatar) -> Result<Recipe> {
        Recipe::load(&self.dir.join(&avatar.recipe))
    }

    /// An avatar's category.
    pub fn category(&self, avatar: &StudyAvatar) -> &Category {
        self.study
            .categories
            .iter()
            .find(|c| c.name == avatar.category)
            .expect("a built study names only its own categories")
    }

    /// The order a participant sees the avatars in: a shuffle seeded by the
    /// study's seed and the participant's ID, the same every time they start.
    pub fn order(&self, participant: &str) -> Vec<u32> {
        let digest = blake3::hash(format!("{}\0{participant}", self.study.seed).as_bytes());
        let seed = u64::from_le_bytes(digest.as_bytes()[..8].try_into().expect("8 bytes"));
        let mut ids: Vec<u32> = self.study.avatars.iter().map(|a| a.id).collect();
        ids.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
        ids
    }

    /// The avatar with this number.
    pub fn avatar(&self, id: u32) -> Option<&StudyAvatar> {
        self.study.avatars.iter().find(|a| a.id == id)
    }
}

/// Checks a participant ID: 1-64 letters, digits, `-` or `_` (it names a file).
pub fn check_participant(id: &str) -> Result<()> {
    let ok = !id.is_empty()
        && id.len() <= 64
        && id
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if ok {
        Ok(())
    } else {
        Err(Error::input(format!(
            "participant ID '{}' must be 1-64 letters, digits, '-' or '_'",
            crate::text::printable(id)
        )))
    }
}

/// Databases opened while building, each once.
#[derive(Default)]
pub struct Databases {
    open: Vec<(DatabaseSpec, crate::avatar::database::Database)>,
}

impl Databases {
    /// The database a spec names, opened on first use.
    pub fn get(&mut self, spec: &DatabaseSpec) -> Result<&crate::avatar::database::Database> {
        let at = match self.open.iter().position(|(s, _)| s == spec) {
            Some(at) => at,
            None => {
                let (db, _) = spec.load()?;
                self.open.push((spec.clone(), db));
                self.open.len() - 1
            }
        };
        Ok(&self.open[at].1)
    }
}

/// Builds a study folder from a spec file; refuses to overwrite a folder
/// that already holds answers.
pub fn build(spec_path: &Path, out: &Path, databases: &mut Databases) -> Result<Study> {
    let text = std::fs::read_to_string(spec_path).map_err(|e| {
        Error::input(format!(
            "cannot read study spec {}: {e}",
            spec_path.display()
        ))
    })?;
    let spec: StudySpec = toml::from_str(&text).map_err(|e| {
        Error::input(format!(
            "{}: invalid study spec: {}",
            spec_path.display(),
            e.message().trim()
        ))
    })?;
    spec.display.check()?;
    if spec.categories.is_empty() {
        return Err(Error::input(format!(
            "{}: a study needs at least one [[category]]",
            spec_path.display()
        )));
    }
    let answers = out.join(ANSWERS_DIR);
    if has_entries(&answers) {
        return Err(Error::input(format!(
            "{} already holds answers; build into a new folder",
            answers.display()
        )));
    }
    let base_dir = spec_path.parent().unwrap_or(Path::new("."));
    let mut study = Study {
        version: STUDY_VERSION,
        title: spec.title.clone(),
        seed: spec.seed,
        display: spec.display.clone(),
        categories: Vec::new(),
        avatars: Vec::new(),
        attributes: Attributes::default(),
    };
    let mut recipes: Vec<(u32, Recipe)> = Vec::new();
    for c in &spec.categories {
        if study.categories.iter().any(|k| k.name == c.name) || c.name.is_empty() {
            return Err(Error::input(format!(
                "category names must be distinct and non-empty ('{}')",
                crate::text::printable(&c.name)
            )));
        }
        let database = anchored(&c.database, base_dir);
        let db = database.clone();
        let labels = Attributes::of_database(databases.get(&db)?);
        study.attributes = std::mem::take(&mut study.attributes).overlaid(labels);
        let mut list: Vec<Recipe> = c.unedited.iter().map(|s| Recipe::unedited(s)).collect();
        for path in &c.recipes {
            for file in recipe_files(&base_dir.join(path))? {
                list.push(Recipe::load(&file)?);
            }
        }
        if list.is_empty() {
            return Err(Error::input(format!(
                "category '{}' has no avatars (give recipes or unedited sources)",
                crate::text::printable(&c.name)
            )));
        }
        for mut recipe in list {
            shown_as_studied(&mut recipe, c.post, &spec.display);
            recipe.resolve(databases.get(&db)?).map_err(|e| {
                Error::input(format!(
                    "category '{}': {e}",
                    crate::text::printable(&c.name)
                ))
            })?;
            let id = recipes.len() as u32 + 1;
            study.avatars.push(StudyAvatar {
                id,
                category: c.name.clone(),
                recipe: Path::new(RECIPES_DIR).join(format!("{id:03}.toml")),
            });
            recipes.push((id, recipe));
        }
        study.categories.push(Category {
            name: c.name.clone(),
            database,
            post: c.post,
        });
    }
    write_folder(out, &study, &recipes)?;
    Ok(study)
}

/// Sets what the study fixes: the category's post-processing, the display's
/// motion from its first frame, and the locked orbit facing the avatar.
fn shown_as_studied(recipe: &mut Recipe, post: PostProcess, display: &Display) {
    recipe.post = post;
    recipe.animation.motion = display.motion.clone();
    recipe.animation.frame = 0;
    recipe.camera.radius = display.radius;
    recipe.camera.yaw_deg = 0.0;
    recipe.camera.pitch_deg = 0.0;
}

fn has_entries(dir: &Path) -> bool {
    std::fs::read_dir(dir).is_ok_and(|mut d| d.next().is_some())
}

/// A recipe file, or the `.toml` files of a folder in name order.
fn recipe_files(path: &Path) -> Result<Vec<PathBuf>> {
    if path.is_file() {
        return Ok(vec![path.to_path_buf()]);
    }
    let entries = std::fs::read_dir(path)
        .map_err(|e| Error::input(format!("cannot read recipes {}: {e}", path.display())))?;
    let mut files: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(Error::input(format!(
            "{} holds no .toml recipes",
            path.display()
        )));
    }
    Ok(files)
}

fn write_folder(out: &Path, study: &Study, recipes: &[(u32, Recipe)]) -> Result<()> {
    let io = |what: &Path, e: std::io::Error| Error::io("write", what, e);
    let recipes_dir = out.join(RECIPES_DIR);
    std::fs::create_dir_all(&recipes_dir).map_err(|e| io(&recipes_dir, e))?;
    std::fs::create_dir_all(out.join(ANSWERS_DIR)).map_err(|e| io(out, e))?;
    for (id, recipe) in recipes {
        let path = recipes_dir.join(format!("{id:03}.toml"));
        std::fs::write(&path, recipe.to_toml()).map_err(|e| io(&path, e))?;
    }
    let path = out.join(STUDY_FILE);
    let text = toml::to_string(study).expect("studies always serialise");
    std::fs::write(&path, text).map_err(|e| io(&path, e))
}

/// Per-category avatar counts, for the build summary.
pub fn category_counts(study: &Study) -> BTreeMap<&str, usize> {
    let mut counts = BTreeMap::new();
    for a in &study.avatars {
        *counts.entry(a.category.as_str()).or_insert(0) += 1;
    }
    counts
}
