//! A scene drawn through its level-of-detail hierarchy: the tree, and the
//! cut of the last camera with its Gaussians gathered, kept until the camera
//! or the policy changes (a still view costs nothing to re-cut).

use std::time::Instant;

use crate::error::Result;
use crate::render::image::RgbImage;
use crate::render::lod::{Cut, LodPolicy, LodTree};
use crate::render::settings::RenderSettings;
use crate::render::SplatRenderer;
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;

/// What the last frame drew of the hierarchy.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CutSummary {
    /// Gaussians drawn.
    pub drawn: usize,
    /// Of them, the scene's own.
    pub leaves: usize,
    /// Shallowest and deepest level drawn.
    pub levels: (u16, u16),
    /// Milliseconds choosing and gathering the cut (0 when it was kept).
    pub cut_ms: f64,
}

/// A hierarchy with its last cut.
pub struct LodScene {
    tree: LodTree,
    last: Option<(Camera, LodPolicy)>,
    drawn: SplatScene,
    summary: CutSummary,
}

impl LodScene {
    /// Keeps `tree` to draw from.
    pub fn new(tree: LodTree) -> Self {
        Self {
            tree,
            last: None,
            drawn: SplatScene::default(),
            summary: CutSummary::default(),
        }
    }

    /// The hierarchy.
    pub fn tree(&self) -> &LodTree {
        &self.tree
    }

    /// The Gaussians `camera` draws under `policy`, and whether they differ
    /// from the last call's (so a renderer must take them again).
    pub fn gaussians_for(&mut self, camera: &Camera, policy: LodPolicy) -> (&SplatScene, bool) {
        let key = Some((*camera, policy));
        if self.last == key {
            self.summary.cut_ms = 0.0;
            return (&self.drawn, false);
        }
        let t = Instant::now();
        let cut: Cut = self.tree.cut(camera, policy);
        self.drawn = self.tree.gather(&cut, camera);
        self.summary = CutSummary {
            drawn: cut.nodes.len(),
            leaves: cut.leaves,
            levels: cut.levels,
            cut_ms: t.elapsed().as_secs_f64() * 1e3,
        };
        self.last = key;
        (&self.drawn, true)
    }

    /// What the last frame drew.
    pub fn summary(&self) -> CutSummary {
        self.summary
    }

    /// Draws the cut of `camera` with `renderer` (uploading it when it changed).
    pub fn render(
        &mut self,
        renderer: &mut SplatRenderer,
        camera: &Camera,
        policy: LodPolicy,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let (scene, changed) = self.gaussians_for(camera, policy);
        if changed {
            renderer.set_world_scene(scene)?;
        }
        renderer.render_world(camera, settings)
    }

    /// Forgets the last cut, so the next frame cuts and uploads again (for
    /// benchmarks timing the whole per-frame cost of a moving camera, and
    /// after the renderer drew something else).
    pub fn forget(&mut self) {
        self.last = None;
    }
}
