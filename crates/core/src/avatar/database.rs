//! Source avatars and the database of them that the editor composes from.

use std::collections::BTreeMap;

use glam::{DVec3, Vec3};

use super::gaussians::GaussianSet;
use crate::model::head::HeadModel;
use crate::model::motion::Motion;

/// One captured (or synthetic) head avatar: identity, hair/clothing offsets, its
/// own motion and its triangle-bound Gaussians.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceAvatar {
    /// Display name (control characters already stripped).
    pub name: String,
    /// Shape coefficients β.
    pub shape: Vec<f32>,
    /// Static per-vertex offset added to the shaped template (hair, clothing), in
    /// f64 so exported neutral meshes read back exactly.
    pub static_offset: Vec<DVec3>,
    /// The motion this avatar was captured with.
    pub motion: Motion,
    /// Gaussians bound to the model's triangles.
    pub gaussians: GaussianSet,
    /// Labels describing the person (for example `skin_tone = "dark"`), which
    /// random composites and study exclusions can constrain on. Empty when
    /// the database says nothing.
    pub attributes: BTreeMap<String, String>,
}

impl SourceAvatar {
    /// The avatar's neutral (identity) mesh.
    pub fn neutral(&self, model: &HeadModel) -> Vec<Vec3> {
        model.neutral(&self.shape, Some(&self.static_offset))
    }
}

/// A head model with the source avatars and motions built on it.
#[derive(Clone, Debug)]
pub struct Database {
    /// Where the database came from ("builtin" or a folder).
    pub label: String,
    /// Identifies the exact contents (generation options or file digests); part
    /// of every composite's state hash.
    pub fingerprint: String,
    /// The shared morphable model (topology, bases, skeleton).
    pub model: HeadModel,
    /// Source avatars, in display order.
    pub sources: Vec<SourceAvatar>,
    /// Driving motions available to every composite.
    pub motions: Vec<Motion>,
}

impl Database {
    /// Index of a source by name.
    pub fn source_index(&self, name: &str) -> Option<usize> {
        self.sources.iter().position(|s| s.name == name)
    }

    /// Index of a motion by name.
    pub fn motion_index(&self, name: &str) -> Option<usize> {
        self.motions.iter().position(|m| m.name == name)
    }

    /// Total number of Gaussians over all sources.
    pub fn total_gaussians(&self) -> usize {
        self.sources.iter().map(|s| s.gaussians.len()).sum()
    }
}
