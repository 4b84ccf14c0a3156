//! What the editor opens: an avatar database (to compose) or one 3DGS scene
//! file (to view: `visage view FILE`). Both open into a [`Workbench`]; session
//! files name the subject in their header so a replay opens the same one.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::database::DatabaseSpec;
use super::lod::{default_memory_budget, open_cached};
use super::workbench::Workbench;
use crate::compose::engine::Engine;
use crate::error::{Error, Result};
use crate::io::Progress;
use crate::render::lod::cache::read_error;
use crate::render::lod::PagedTree;
use crate::render::Backend;
use crate::scene::camera::{Orbit, UpAxis};
use crate::scene::splats::SplatScene;
use crate::scene::upright::{ground_up, nearest_up, UpReason};
use crate::train::fit_store::FitStore;

/// A scene file to view and the world axis that is up in it.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSpec {
    /// A PLY (INRIA or SuperSplat's compressed), `.splat` or SPZ file.
    pub path: PathBuf,
    /// Up on screen (`-y` for COLMAP / INRIA captures); `None`: detect it
    /// (`crate::scene::upright`).
    pub up: Option<UpAxis>,
    /// Draw the scene from its level-of-detail cache within this many
    /// bytes; None: do so for files of [`LARGE_SCENE_BYTES`] or more, with
    /// [`default_memory_budget`].
    pub memory_budget: Option<usize>,
}

/// Scene files at least this large open from their level-of-detail cache
/// rather than into memory (1 GiB, about 4M Gaussians of SH degree 3).
pub const LARGE_SCENE_BYTES: u64 = 1 << 30;

/// A scene read from its file (or opened from its level-of-detail cache),
/// with the camera it opens with.
#[derive(Debug)]
pub struct ViewedScene {
    /// The Gaussians; empty for a scene drawn from its cache.
    pub scene: SplatScene,
    /// The scene's hierarchy paged in from its cache, for a scene too large
    /// to hold (the workbench takes it over).
    pub paged: Option<PagedTree>,
    /// Whether the scene is drawn from its cache (nothing else of it is in
    /// memory: no floater filter, no export, no exact path).
    pub from_cache: bool,
    /// Gaussians in the file.
    pub gaussians: usize,
    /// The file's SH degree.
    pub sh_degree: u8,
    /// The file, where its hierarchy is cached.
    pub path: PathBuf,
    /// The file's name, for the panel and messages.
    pub name: String,
    /// The framed camera (`camera-reset` returns to it).
    pub home: Orbit,
    /// How its up axis was chosen.
    pub up_reason: UpReason,
}

impl SceneSpec {
    /// Reads and frames the scene; `progress` hears the bytes read. A large
    /// scene (or any, given a memory budget) opens from its level-of-detail
    /// cache instead, built first when missing or stale.
    pub fn load(&self, progress: Progress) -> Result<(ViewedScene, Duration)> {
        let start = Instant::now();
        let len = std::fs::metadata(&self.path)
            .map_err(|e| read_error(&self.path, e))?
            .len();
        if self.memory_budget.is_some() || len >= LARGE_SCENE_BYTES {
            return Ok((self.open_cached(progress)?, start.elapsed()));
        }
        let scene = crate::io::splat::read_scene_with(&self.path, progress)?;
        let (up, up_reason) = self.up_axis(&scene);
        let home = scene.home_orbit(None, up).ok_or_else(|| {
            Error::input(format!(
                "{} holds no Gaussian with a finite position",
                self.path.display()
            ))
        })?;
        Ok((
            ViewedScene {
                gaussians: scene.len(),
                sh_degree: scene.sh_degree,
                scene,
                paged: None,
                from_cache: false,
                path: self.path.clone(),
                name: self.display_name(),
                home,
                up_reason,
            },
            start.elapsed(),
        ))
    }

    /// The file's name, for the panel and messages.
    fn display_name(&self) -> String {
        self.path.file_name().map_or_else(
            || self.path.display().to_string(),
            |n| crate::text::printable(&n.to_string_lossy()),
        )
    }

    /// Opens the scene from its level-of-detail cache (built first when
    /// missing or stale), framed by the bounds and ground the cache keeps.
    fn open_cached(&self, progress: Progress) -> Result<ViewedScene> {
        let budget = self.memory_budget.unwrap_or_else(default_memory_budget);
        let note = |line: &str| eprintln!("\nvisage: {line}");
        let (tree, _, _) = open_cached(&self.path, None, budget, &note, progress)?;
        let source = &tree.header().source;
        let (up, up_reason) = self.up_axis_with(|| source.ground_up);
        let (lo, hi) = source.bounds;
        let home = Orbit {
            fov_deg: 40.0,
            up,
            ..Orbit::STUDY
        }
        .framing(lo, hi);
        let sh_degree = tree.header().sh_degree;
        Ok(ViewedScene {
            scene: SplatScene::with_degree(sh_degree),
            gaussians: source.gaussians as usize,
            sh_degree,
            paged: Some(tree),
            from_cache: true,
            path: self.path.clone(),
            name: self.display_name(),
            home,
            up_reason,
        })
    }

    /// The up axis: as given, else from the capture's cameras, else from the
    /// ground, else +y.
    fn up_axis(&self, scene: &SplatScene) -> (UpAxis, UpReason) {
        self.up_axis_with(|| ground_up(scene))
    }

    fn up_axis_with(&self, ground: impl FnOnce() -> Option<UpAxis>) -> (UpAxis, UpReason) {
        if let Some(up) = self.up {
            return (up, UpReason::Given);
        }
        let cameras = crate::io::inria::cameras_file(&self.path)
            .and_then(|f| crate::io::inria::mean_camera_up(&f))
            .and_then(nearest_up);
        if let Some(up) = cameras {
            return (up, UpReason::Cameras);
        }
        match ground() {
            Some(up) => (up, UpReason::Ground),
            None => (UpAxis::default(), UpReason::Default),
        }
    }

    /// The path made absolute (session headers replay from any folder).
    pub fn absolute(&self) -> SceneSpec {
        SceneSpec {
            path: std::path::absolute(&self.path).unwrap_or_else(|_| self.path.clone()),
            up: self.up,
            memory_budget: self.memory_budget,
        }
    }
}

/// An avatar database or a scene.
#[derive(Clone, Debug, PartialEq)]
pub enum Subject {
    /// Compose avatars from a database.
    Avatars(DatabaseSpec),
    /// View one scene file.
    Scene(SceneSpec),
}

impl Default for Subject {
    /// The built-in database.
    fn default() -> Self {
        Subject::Avatars(DatabaseSpec::default())
    }
}

impl Subject {
    /// What the subject is, for the "opening …" line.
    pub fn describe(&self) -> String {
        match self {
            Subject::Avatars(db) => format!("the {} database", db.db),
            Subject::Scene(s) => s.path.display().to_string(),
        }
    }

    /// Whether a session recorded on `recorded` is about this subject: the
    /// same database, or the same scene file (and up axis, when this one
    /// names it).
    pub fn agrees_with(&self, recorded: &Subject) -> bool {
        match (self, recorded) {
            (Subject::Avatars(a), Subject::Avatars(b)) => a == b,
            (Subject::Scene(a), Subject::Scene(b)) => {
                let (a, b) = (a.absolute(), b.absolute());
                a.path == b.path && (a.up.is_none() || a.up == b.up)
            }
            _ => false,
        }
    }

    /// Opens the subject into a workbench with a renderer of the given kind.
    pub fn open(&self, backend: Backend, progress: Progress) -> Result<Workbench> {
        match self {
            Subject::Avatars(spec) => {
                let (db, _) = spec.load()?;
                let mut workbench = Workbench::new(Engine::new(db)?, backend)?;
                // A composite fitted once, here or by `compose`, shows
                // fitted at once the next time.
                workbench.set_fit_store(Some(FitStore::user()));
                Ok(workbench)
            }
            Subject::Scene(spec) => {
                let (viewed, _) = spec.load(progress)?;
                Workbench::for_scene(viewed, backend)
            }
        }
    }
}
