//! What the editor opens: an avatar database (to compose) or one 3DGS scene
//! file (to view: `visage view FILE`). Both open into a [`Workbench`]; session
//! files name the subject in their header so a replay opens the same one.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use super::database::DatabaseSpec;
use super::workbench::Workbench;
use crate::compose::engine::Engine;
use crate::error::{Error, Result};
use crate::io::Progress;
use crate::render::Backend;
use crate::scene::camera::{Orbit, UpAxis};
use crate::scene::splats::SplatScene;
use crate::scene::upright::{ground_up, nearest_up, UpReason};

/// A scene file to view and the world axis that is up in it.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSpec {
    /// A PLY (INRIA or SuperSplat's compressed), `.splat` or SPZ file.
    pub path: PathBuf,
    /// Up on screen (`-y` for COLMAP / INRIA captures); `None`: detect it
    /// (`crate::scene::upright`).
    pub up: Option<UpAxis>,
}

/// A scene read from its file, with the camera it opens with.
#[derive(Clone, Debug)]
pub struct ViewedScene {
    /// The Gaussians.
    pub scene: SplatScene,
    /// The file's name, for the panel and messages.
    pub name: String,
    /// The framed camera (`camera-reset` returns to it).
    pub home: Orbit,
    /// How its up axis was chosen.
    pub up_reason: UpReason,
}

impl SceneSpec {
    /// Reads and frames the scene; `progress` hears the bytes read.
    pub fn load(&self, progress: Progress) -> Result<(ViewedScene, Duration)> {
        let start = Instant::now();
        let scene = crate::io::splat::read_scene_with(&self.path, progress)?;
        let (up, up_reason) = self.up_axis(&scene);
        let home = scene.home_orbit(None, up).ok_or_else(|| {
            Error::input(format!(
                "{} holds no Gaussian with a finite position",
                self.path.display()
            ))
        })?;
        let name = self.path.file_name().map_or_else(
            || self.path.display().to_string(),
            |n| crate::text::printable(&n.to_string_lossy()),
        );
        Ok((
            ViewedScene {
                scene,
                name,
                home,
                up_reason,
            },
            start.elapsed(),
        ))
    }

    /// The up axis: as given, else from the capture's cameras, else from the
    /// ground, else +y.
    fn up_axis(&self, scene: &SplatScene) -> (UpAxis, UpReason) {
        if let Some(up) = self.up {
            return (up, UpReason::Given);
        }
        let cameras = crate::io::inria::cameras_file(&self.path)
            .and_then(|f| crate::io::inria::mean_camera_up(&f))
            .and_then(nearest_up);
        if let Some(up) = cameras {
            return (up, UpReason::Cameras);
        }
        match ground_up(scene) {
            Some(up) => (up, UpReason::Ground),
            None => (UpAxis::default(), UpReason::Default),
        }
    }

    /// The path made absolute (session headers replay from any folder).
    pub fn absolute(&self) -> SceneSpec {
        SceneSpec {
            path: std::path::absolute(&self.path).unwrap_or_else(|_| self.path.clone()),
            up: self.up,
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
                Workbench::new(Engine::new(db)?, backend)
            }
            Subject::Scene(spec) => {
                let (viewed, _) = spec.load(progress)?;
                Workbench::for_scene(viewed, backend)
            }
        }
    }
}
