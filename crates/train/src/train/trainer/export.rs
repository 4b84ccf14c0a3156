//! The trained avatar written out: a GaussianAvatars folder (Gaussians,
//! identity and per-timestep FLAME parameters) and `training.json`, which
//! records how it was trained.

use std::path::Path;

use super::Trainer;
use crate::error::{Error, Result};
use crate::io::avatar::{write_avatar, AvatarParams};

/// The file in an exported avatar folder that records how it was trained.
pub const TRAINING_METADATA: &str = "training.json";

impl Trainer {
    /// Writes the avatar as a GaussianAvatars folder: the Gaussians and the
    /// dataset's identity and per-timestep FLAME parameters (its motion).
    pub fn export(&self, dir: &Path) -> Result<()> {
        let (shape, offset) = &self.identity;
        write_avatar(
            dir,
            &self.gaussians(),
            &AvatarParams {
                shape,
                static_offset: offset,
                frames: &self.flame_frames,
            },
            &self.head,
        )?;
        self.write_metadata(&dir.join(TRAINING_METADATA))
    }

    /// Records how the avatar was trained (`training.json` beside it).
    fn write_metadata(&self, path: &Path) -> Result<()> {
        let (kept, full) = self.triangles_kept();
        let doc = serde_json::json!({
            "trained_by": "visage train",
            "iterations": self.step,
            "seed": self.options.seed,
            "obscuring": self.options.holes.obscuring && !self.options.holes.interior,
            "interior_layer": self.options.holes.interior,
            "cull_backfaces": self.options.holes.cull_below,
            "triangles_trained": kept,
            "triangles": full,
            "gaussians": self.model.len(),
        });
        let text = serde_json::to_string_pretty(&doc).expect("JSON values serialise");
        std::fs::write(path, text + "\n").map_err(|e| Error::io("write", path, e))
    }
}
