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

/// A scene file to view and the world axis that is up in it.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSpec {
    /// A PLY (INRIA or SuperSplat's compressed) or `.splat` file.
    pub path: PathBuf,
    /// Up on screen (`-y` for COLMAP / INRIA captures).
    pub up: UpAxis,
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
}

impl SceneSpec {
    /// Reads and frames the scene; `progress` hears the bytes read.
    pub fn load(&self, progress: Progress) -> Result<(ViewedScene, Duration)> {
        let start = Instant::now();
        let scene = crate::io::splat::read_scene_with(&self.path, progress)?;
        let home = scene.home_orbit(None, self.up).ok_or_else(|| {
            Error::input(format!(
                "{} holds no Gaussian with a finite position",
                self.path.display()
            ))
        })?;
        let name = self.path.file_name().map_or_else(
            || self.path.display().to_string(),
            |n| crate::text::printable(&n.to_string_lossy()),
        );
        Ok((ViewedScene { scene, name, home }, start.elapsed()))
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

impl Subject {
    /// What the subject is, for the "opening …" line.
    pub fn describe(&self) -> String {
        match self {
            Subject::Avatars(db) => format!("the {} database", db.db),
            Subject::Scene(s) => s.path.display().to_string(),
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
