//! The manifest of a database built on many machines: which subjects, from
//! which datasets, trained how, into which folder (TOML; README "Building a
//! database on a cluster").
//!
//! ```toml
//! output = "db"                  # the database folder, beside the manifest
//! [defaults]                     # any subject option, for every subject
//! iterations = 3000
//! size = "128x128"
//! [[subject]]
//! id = "ada"                     # the avatar's folder name in the database
//! dataset = "captures/ada"       # relative to the manifest
//! seed = 7
//! [subject.capture]              # optional: `visage capture --manifest`
//! source = "ada"                 # makes the dataset from a built-in person
//! ```

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::render::Backend;
use crate::train::holes::HoleFilling;

/// Options a subject may set, each falling back to `[defaults]` and then to
/// `visage train`'s own defaults.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct OptionTable {
    iterations: Option<usize>,
    seed: Option<u64>,
    size: Option<String>,
    white_background: Option<bool>,
    checkpoint_every: Option<usize>,
    renderer: Option<String>,
    obscuring: Option<bool>,
    interior_layer: Option<bool>,
    cull_backfaces: Option<f64>,
    flame: Option<PathBuf>,
    masks: Option<PathBuf>,
}

impl OptionTable {
    /// `self` where set, `fallback` elsewhere.
    fn or(self, fallback: &OptionTable) -> OptionTable {
        let f = fallback.clone();
        OptionTable {
            iterations: self.iterations.or(f.iterations),
            seed: self.seed.or(f.seed),
            size: self.size.or(f.size),
            white_background: self.white_background.or(f.white_background),
            checkpoint_every: self.checkpoint_every.or(f.checkpoint_every),
            renderer: self.renderer.or(f.renderer),
            obscuring: self.obscuring.or(f.obscuring),
            interior_layer: self.interior_layer.or(f.interior_layer),
            cull_backfaces: self.cull_backfaces.or(f.cull_backfaces),
            flame: self.flame.or(f.flame),
            masks: self.masks.or(f.masks),
        }
    }
}

/// How `visage capture --manifest` makes a subject's dataset from a built-in
/// person (the options of `visage capture`).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CaptureSpec {
    /// Built-in person.
    pub source: String,
    /// Seed of the built-in database.
    #[serde(default = "one")]
    pub seed: u64,
    /// Image size, `WxH`.
    #[serde(default = "capture_size")]
    pub size: String,
    /// Training cameras.
    #[serde(default = "sixteen")]
    pub cameras: usize,
    /// Timesteps.
    #[serde(default = "twenty")]
    pub frames: usize,
    /// Built-in motion.
    #[serde(default = "talk")]
    pub motion: String,
    /// A full ring of cameras instead of the frontal arc.
    #[serde(default)]
    pub ring: bool,
}

fn one() -> u64 {
    1
}
fn capture_size() -> String {
    "256x256".into()
}
fn sixteen() -> usize {
    16
}
fn twenty() -> usize {
    20
}
fn talk() -> String {
    "talk".into()
}

/// A `[[subject]]` as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SubjectTable {
    id: String,
    dataset: PathBuf,
    capture: Option<CaptureSpec>,
    #[serde(flatten)]
    options: OptionTable,
}

/// The manifest file as written.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestFile {
    output: PathBuf,
    #[serde(default)]
    defaults: OptionTable,
    #[serde(default)]
    subject: Vec<SubjectTable>,
}

/// How one subject trains: everything that decides the avatar's bytes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SubjectOptions {
    /// Iterations.
    pub iterations: usize,
    /// Training seed.
    pub seed: u64,
    /// Training resolution; None: as stored.
    pub size: Option<[u32; 2]>,
    /// Masked images over white instead of black.
    pub white_background: bool,
    /// Rasteriser (`auto`, `gpu`, `cpu`).
    pub renderer: String,
    /// Thesis's obscuring Gaussian instead of the interior layer.
    pub obscuring: bool,
    /// The interior layer behind the visible surface.
    pub interior_layer: bool,
    /// Back-face culling threshold.
    pub cull_backfaces: Option<f64>,
    /// FLAME model pickle as the manifest writes it (None: the built-in
    /// head). As written, so the fingerprint does not depend on how the
    /// manifest's path was typed; [`Subject::head_files`] resolves it.
    pub flame: Option<PathBuf>,
    /// FLAME masks pickle, as written.
    pub masks: Option<PathBuf>,
}

impl SubjectOptions {
    /// The rasteriser to train with.
    pub fn backend(&self) -> Backend {
        Backend::parse(&self.renderer).expect("checked when the manifest was read")
    }

    /// The hole filling to train with.
    pub fn holes(&self) -> HoleFilling {
        HoleFilling {
            obscuring: self.obscuring,
            interior: self.interior_layer && !self.obscuring,
            cull_below: self.cull_backfaces,
        }
    }

    /// The background the masked images are composited over.
    pub fn background(&self) -> [f64; 3] {
        [if self.white_background { 1.0 } else { 0.0 }; 3]
    }

    /// A short digest of the options: a finished avatar or a checkpoint made
    /// with other options is not this subject's.
    pub fn fingerprint(&self) -> String {
        let text = serde_json::to_string(self).expect("options serialise");
        blake3::hash(text.as_bytes()).to_hex()[..16].to_string()
    }
}

/// One subject of the manifest.
#[derive(Clone, Debug, PartialEq)]
pub struct Subject {
    /// Its folder name in the database.
    pub id: String,
    /// Its position in the manifest (which shard takes it).
    pub position: usize,
    /// Its dataset folder (absolute or relative to the working directory).
    pub dataset: PathBuf,
    /// How to make the dataset from a built-in person, if it is one.
    pub capture: Option<CaptureSpec>,
    /// How it trains.
    pub options: SubjectOptions,
    /// Write a checkpoint every this many iterations.
    pub checkpoint_every: usize,
    /// The FLAME model and masks files, resolved against the manifest's
    /// folder (None: the built-in head).
    pub head_files: Option<(PathBuf, PathBuf)>,
}

/// A manifest of subjects and the database folder they train into.
#[derive(Clone, Debug)]
pub struct Manifest {
    /// The manifest file.
    pub path: PathBuf,
    /// The database folder.
    pub output: PathBuf,
    /// The subjects, in the order written.
    pub subjects: Vec<Subject>,
}

/// Checkpoint interval when none is given: at 1-3 minutes per 1,500
/// iterations on two cores, a preempted subject loses under a minute.
pub const DEFAULT_CHECKPOINT_EVERY: usize = 500;

impl Manifest {
    /// Reads and checks a manifest: TOML, unique ids that are plain folder
    /// names, sizes and renderers that parse. Datasets are checked later, by
    /// the commands that need them.
    pub fn load(path: &Path) -> Result<Manifest> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::input(format!("cannot read manifest {}: {e}", path.display())))?;
        let file: ManifestFile = toml::from_str(&text)
            .map_err(|e| Error::input(format!("{}: {}", path.display(), e.message().trim())))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let bad = |what: String| Error::input(format!("{}: {what}", path.display()));
        if file.subject.is_empty() {
            return Err(bad("no [[subject]] tables".into()));
        }
        let mut seen = BTreeSet::new();
        let mut subjects = Vec::new();
        for (position, table) in file.subject.into_iter().enumerate() {
            check_id(&table.id).map_err(&bad)?;
            if !seen.insert(table.id.clone()) {
                return Err(bad(format!("subject '{}' is listed twice", table.id)));
            }
            let merged = table.options.or(&file.defaults);
            let options =
                resolve(merged.clone()).map_err(|w| bad(format!("subject '{}': {w}", table.id)))?;
            let head_files = options
                .flame
                .as_ref()
                .zip(options.masks.as_ref())
                .map(|(f, m)| (base.join(f), base.join(m)));
            if let Some(capture) = &table.capture {
                crate::text::parse_image_size(&capture.size)
                    .map_err(|w| bad(format!("subject '{}': capture size: {w}", table.id)))?;
            }
            subjects.push(Subject {
                id: table.id,
                position,
                dataset: base.join(table.dataset),
                capture: table.capture,
                options,
                checkpoint_every: merged.checkpoint_every.unwrap_or(DEFAULT_CHECKPOINT_EVERY),
                head_files,
            });
        }
        Ok(Manifest {
            path: path.to_path_buf(),
            output: base.join(file.output),
            subjects,
        })
    }

    /// The subject with this id.
    pub fn subject(&self, id: &str) -> Option<&Subject> {
        self.subjects.iter().find(|s| s.id == id)
    }
}

/// A subject id becomes a folder name: letters, digits, `-`, `_` and `.`,
/// not starting with a dot (the database's own folders do).
fn check_id(id: &str) -> std::result::Result<(), String> {
    let plain = id
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'));
    if id.eq_ignore_ascii_case(crate::io::folder::INDEX_FILE) {
        return Err(format!(
            "subject id '{id}' is the name of the database's index"
        ));
    }
    if id.is_empty() || !plain || id.starts_with('.') || id.len() > 128 {
        return Err(format!(
            "subject id '{}' is not a plain folder name (letters, digits, - _ .)",
            crate::text::printable(id)
        ));
    }
    Ok(())
}

/// A subject's options with `visage train`'s defaults filled in.
fn resolve(t: OptionTable) -> std::result::Result<SubjectOptions, String> {
    let size = match &t.size {
        Some(s) => {
            let (w, h) = crate::text::parse_image_size(s)?;
            Some([w, h])
        }
        None => None,
    };
    let renderer = t.renderer.unwrap_or_else(|| "auto".into());
    Backend::parse(&renderer)?;
    if let Some(tau) = t.cull_backfaces {
        if !(0.0..=1.0).contains(&tau) {
            return Err(format!(
                "cull_backfaces takes a share of views from 0 to 1, not {tau}"
            ));
        }
    }
    if t.flame.is_some() != t.masks.is_some() {
        return Err("flame and masks go together".into());
    }
    let iterations = t.iterations.unwrap_or(3000);
    if iterations == 0 {
        return Err("iterations must be at least 1".into());
    }
    let obscuring = t.obscuring.unwrap_or(false);
    Ok(SubjectOptions {
        iterations,
        seed: t.seed.unwrap_or(1),
        size,
        white_background: t.white_background.unwrap_or(false),
        renderer,
        obscuring,
        interior_layer: t.interior_layer.unwrap_or(true) && !obscuring,
        cull_backfaces: t.cull_backfaces,
        flame: t.flame,
        masks: t.masks,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads `text` as a manifest from a file of its own (tests run in
    /// parallel: two writing one name would read each other's half file).
    fn load(text: &str) -> Result<Manifest> {
        static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let dir = std::env::temp_dir().join(format!("visage-manifest-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(format!("{n}.toml"));
        std::fs::write(&path, text).unwrap();
        Manifest::load(&path)
    }

    const TWO: &str = r#"
output = "db"
[defaults]
iterations = 200
size = "64x48"
[[subject]]
id = "a"
dataset = "data/a"
[[subject]]
id = "b"
dataset = "/abs/b"
iterations = 50
seed = 9
obscuring = true
"#;

    #[test]
    fn subjects_take_defaults_and_paths_are_relative_to_the_manifest() {
        let m = load(TWO).unwrap();
        let base = m.path.parent().unwrap();
        assert_eq!(m.output, base.join("db"));
        let (a, b) = (&m.subjects[0], &m.subjects[1]);
        assert_eq!(a.dataset, base.join("data/a"));
        assert_eq!(b.dataset, PathBuf::from("/abs/b"));
        assert_eq!((a.options.iterations, a.options.seed), (200, 1));
        assert_eq!((b.options.iterations, b.options.seed), (50, 9));
        assert_eq!(a.options.size, Some([64, 48]));
        assert_eq!(a.checkpoint_every, DEFAULT_CHECKPOINT_EVERY);
        // The obscuring Gaussian replaces the interior layer, as in `visage train`.
        assert!(a.options.interior_layer && !b.options.interior_layer);
        assert!(b.options.holes().obscuring && !b.options.holes().interior);
        assert_eq!(b.position, 1);
    }

    #[test]
    fn the_fingerprint_follows_every_option_but_not_the_checkpoint_interval() {
        let m = load(TWO).unwrap();
        let a = &m.subjects[0].options;
        let mut other = a.clone();
        assert_eq!(a.fingerprint(), other.fingerprint());
        other.seed = 2;
        assert_ne!(a.fingerprint(), other.fingerprint());
        let every =
            load(&TWO.replace("iterations = 200", "iterations = 200\ncheckpoint_every = 7"))
                .unwrap();
        assert_eq!(every.subjects[0].checkpoint_every, 7);
        assert_eq!(every.subjects[0].options.fingerprint(), a.fingerprint());
    }

    #[test]
    fn bad_manifests_are_refused_with_the_reason() {
        let cases = [
            (TWO.replace("64x48", "64by48"), "not a size"),
            (TWO.replace("id = \"b\"", "id = \"a\""), "listed twice"),
            (
                TWO.replace("id = \"b\"", "id = \".b\""),
                "plain folder name",
            ),
            (
                TWO.replace("id = \"b\"", "id = \"x/y\""),
                "plain folder name",
            ),
            (
                TWO.replace("id = \"b\"", "id = \"index.json\""),
                "the database's index",
            ),
            (
                TWO.replace("seed = 9", "seed = 9\nrenderer = \"tpu\""),
                "renderer",
            ),
            (
                TWO.replace("seed = 9", "seed = 9\ncull_backfaces = 2.0"),
                "from 0 to 1",
            ),
            (
                TWO.replace("seed = 9", "seed = 9\nflame = \"f.pkl\""),
                "go together",
            ),
            (TWO.replace("seed = 9", "seed = 9\nspeed = 1"), "speed"),
            (
                TWO.replace("iterations = 50", "iterations = 0"),
                "at least 1",
            ),
            ("output = \"db\"\n".to_string(), "no [[subject]]"),
        ];
        for (text, says) in cases {
            let e = load(&text).unwrap_err();
            assert_eq!(e.exit_code(), 2);
            assert!(e.to_string().contains(says), "{says}: {e}");
        }
    }
}
