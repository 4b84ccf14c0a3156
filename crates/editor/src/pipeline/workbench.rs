//! The workbench turns recipes into pictures: it keeps the engine, the current
//! composite and a renderer, updates the composite incrementally from the
//! recipe (only what a change touches), poses the frame and renders it (or the
//! mesh, in the debug view). A workbench on a scene file (`visage view`) draws
//! the scene's Gaussians as they are. The editor, replay and `bench terminal`
//! draw through it.

use std::path::Path;
use std::time::Instant;

use glam::Vec3;

use super::composer::{Composer, FitProgress, Painter};
use super::lod::{CutSummary, LodScene};
use super::subject::ViewedScene;
use crate::compose::engine::Engine;
use crate::compose::recipe::Recipe;
use crate::compose::state_hash;
use crate::error::{Error, Result};
use crate::io::obj::region_colour;
use crate::model::regions::Group;
use crate::render::image::RgbImage;
use crate::render::lod::{build, LodPolicy};
use crate::render::mesh_preview::render_mesh;
use crate::render::reference::centre_depth;
use crate::render::settings::RenderSettings;
use crate::render::Backend;
use crate::scene::clean::{judge, keep, CleanOptions};
use crate::scene::splats::SplatScene;
use crate::train::fit_store::FitStore;
use crate::train::seam_fit::SeamFit;

/// Debug view toggles.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DebugView {
    /// Multiplier on every Gaussian's scale.
    pub scale: f32,
    /// Draw the mesh instead of the Gaussians.
    pub mesh: bool,
    /// Tint the selected group's regions in the mesh view.
    pub highlight: bool,
    /// Highest SH degree drawn (the file's own degree caps it).
    pub sh_degree: u8,
    /// Leave out what the floater filter removes (`scene::clean`; scene views).
    pub hide_floaters: bool,
    /// How much of a scene's level-of-detail hierarchy to draw (scene views).
    pub lod: LodPolicy,
}

impl Default for DebugView {
    fn default() -> Self {
        Self {
            scale: 1.0,
            mesh: false,
            highlight: false,
            sh_degree: 3,
            hide_floaters: false,
            lod: LodPolicy::Auto,
        }
    }
}

/// What to draw.
#[derive(Clone, Debug, PartialEq)]
pub struct FrameRequest {
    /// The document.
    pub recipe: Recipe,
    /// Debug view toggles.
    pub debug: DebugView,
    /// The selected group (highlighted in the mesh view).
    pub group: Group,
    /// Image size in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Full accuracy (stills, idle refinement) or the interactive preset.
    pub exact: bool,
}

/// Milliseconds spent per step of a frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameTimings {
    /// Recipe → composite update (blend and/or selection).
    pub compose: f64,
    /// Posing the frame.
    pub pose: f64,
    /// Rendering.
    pub render: f64,
    /// The composite changed in this frame (`compose` timed real work).
    pub recomposed: bool,
}

/// A rendered frame and what it cost.
#[derive(Clone, Debug)]
pub struct FrameResult {
    /// The picture.
    pub image: RgbImage,
    /// Timings.
    pub timings: FrameTimings,
    /// Gaussians in the composite (border extras included) or the scene.
    pub gaussians: usize,
    /// Gaussians that survived culling and were drawn (CPU renderer only).
    pub visible: Option<usize>,
    /// The renderer's stage timings.
    pub stages: crate::render::settings::StageTimings,
    /// Border-smoothing extras among them.
    pub extras: usize,
    /// What a scene's level of detail drew, when it drew a cut.
    pub lod: Option<CutSummary>,
    /// State hash of the rendered recipe.
    pub state_hash: String,
}

/// What a workbench draws.
enum Content {
    /// A composite kept up to date with the recipe.
    Composite(Box<Composer>),
    /// A scene file's Gaussians; only the recipe's camera applies.
    Scene(Box<ViewedScene>),
}

/// The editor's composer and painter: a composite kept up to date with the
/// recipe (or a scene) and drawn with one renderer.
pub struct Workbench {
    content: Content,
    painter: Painter,
    /// A scene without its floaters, made the first time they are hidden.
    cleaned: Option<SplatScene>,
    /// The hierarchy of the scene as drawn (without its floaters, when so).
    lod: Option<(bool, LodScene)>,
}

impl Workbench {
    /// A workbench on an engine with a renderer of the given kind.
    pub fn new(engine: Engine, backend: Backend) -> Result<Self> {
        Ok(Self {
            content: Content::Composite(Box::new(Composer::new(engine))),
            painter: Painter::open(backend)?,
            cleaned: None,
            lod: None,
        })
    }

    /// A workbench viewing a scene with a renderer of the given kind.
    pub fn for_scene(mut scene: ViewedScene, backend: Backend) -> Result<Self> {
        let lod = scene.paged.take().map(|t| (false, LodScene::paged(t)));
        Ok(Self {
            content: Content::Scene(Box::new(scene)),
            painter: Painter::open(backend)?,
            cleaned: None,
            lod,
        })
    }

    /// The engine, when the workbench composes avatars.
    pub fn engine(&self) -> Option<&Engine> {
        match &self.content {
            Content::Composite(c) => Some(c.engine()),
            Content::Scene(_) => None,
        }
    }

    /// The scene, when the workbench views one.
    pub fn scene(&self) -> Option<&ViewedScene> {
        match &self.content {
            Content::Scene(s) => Some(s),
            Content::Composite(_) => None,
        }
    }

    /// What renders.
    pub fn renderer_description(&self) -> String {
        self.painter.description()
    }

    /// The state hash of `recipe` on this database (nothing is composed or
    /// rendered); for a scene, of the file's name and size and the camera.
    pub fn state_hash(&self, recipe: &Recipe) -> Result<String> {
        match &self.content {
            Content::Composite(composer) => {
                let db = composer.engine().database();
                Ok(state_hash(db, &recipe.resolve(db)?))
            }
            Content::Scene(viewed) => Ok(scene_view_hash(viewed, &recipe.camera)),
        }
    }

    /// Brings the composite up to date with `recipe` and runs the seam fit
    /// it asks for to the end, so what is drawn next is the finished
    /// composite (stills, exports, a study's avatars). Nothing for a scene.
    pub fn settle(&mut self, recipe: &Recipe) -> Result<()> {
        if let Content::Composite(composer) = &mut self.content {
            composer.update(recipe)?;
            composer.finish_fit(&mut |_| {})?;
        }
        Ok(())
    }

    /// How a recipe's seam fit runs from now on (see
    /// [`Composer::set_fit_options`]).
    pub fn set_fit_options(&mut self, options: SeamFit) {
        if let Content::Composite(composer) = &mut self.content {
            composer.set_fit_options(options);
        }
    }

    /// Where finished seam fits are kept (see [`Composer::set_fit_store`]).
    pub fn set_fit_store(&mut self, store: Option<FitStore>) {
        if let Content::Composite(composer) = &mut self.content {
            composer.set_fit_store(store);
        }
    }

    /// Why the last finished seam fit could not be kept in the fit store,
    /// once (see [`Composer::take_store_error`]).
    pub fn take_store_error(&mut self) -> Option<crate::error::Error> {
        match &mut self.content {
            Content::Composite(composer) => composer.take_store_error(),
            Content::Scene(_) => None,
        }
    }

    /// Whether the seam fit on show was read from the fit store rather than
    /// made (see [`Composer::fit_was_stored`]).
    pub fn fit_was_stored(&self) -> bool {
        match &self.content {
            Content::Composite(composer) => composer.fit_was_stored(),
            Content::Scene(_) => false,
        }
    }

    /// How far the composite's seam fit is while one is pending (`None`:
    /// none asked for, or it is done).
    pub fn fit_progress(&self) -> Option<FitProgress> {
        match &self.content {
            Content::Composite(composer) => composer.fit_progress(),
            Content::Scene(_) => None,
        }
    }

    /// Does one unit of the composite's pending seam fit (see
    /// [`Composer::fit_step`]); `None` when none is pending. The editor's
    /// render worker calls it while no frame is waiting.
    pub fn fit_step(&mut self) -> Result<Option<FitProgress>> {
        match &mut self.content {
            Content::Composite(composer) => composer.fit_step(),
            Content::Scene(_) => Ok(None),
        }
    }

    /// Renders a request.
    pub fn render(&mut self, request: &FrameRequest) -> Result<FrameResult> {
        let settings = settings_for(request);
        let Content::Composite(composer) = &mut self.content else {
            return self.render_scene(request, &settings);
        };
        let (resolved, timings) = composer.update(&request.recipe)?;
        let camera = resolved
            .camera
            .camera(request.width.max(1), request.height.max(1));
        let t = Instant::now();
        let image = if request.debug.mesh {
            mesh_view(composer, &camera, request)
        } else if request.debug.highlight {
            self.painter
                .render_highlighted(composer, request.group, &camera, &settings)?
        } else {
            self.painter.render(composer, &camera, &settings)?
        };
        let render = t.elapsed().as_secs_f64() * 1e3;
        let composite = composer.composite();
        let extras = composite
            .blocks
            .iter()
            .filter(|b| b.extra_from.is_some())
            .map(|b| b.end - b.start)
            .sum();
        Ok(FrameResult {
            image,
            timings: FrameTimings {
                compose: timings.compose,
                pose: timings.pose,
                render,
                recomposed: timings.recomposed,
            },
            gaussians: composite.gaussians.len(),
            visible: (!request.debug.mesh)
                .then(|| self.painter.visible())
                .flatten(),
            stages: self.painter.stage_timings(),
            extras,
            lod: None,
            state_hash: state_hash(composer.engine().database(), &resolved),
        })
    }

    fn render_scene(
        &mut self,
        request: &FrameRequest,
        settings: &RenderSettings,
    ) -> Result<FrameResult> {
        let Content::Scene(viewed) = &self.content else {
            unreachable!("called for scenes only");
        };
        let camera = request
            .recipe
            .camera
            .camera(request.width.max(1), request.height.max(1));
        let t = Instant::now();
        let scene = if request.debug.hide_floaters {
            self.cleaned.get_or_insert_with(|| {
                let (verdicts, _) = judge(&viewed.scene, &CleanOptions::default());
                keep(&viewed.scene, &verdicts)
            })
        } else {
            &viewed.scene
        };
        let cleaned = request.debug.hide_floaters && !viewed.from_cache;
        let pixels = (camera.width * camera.height) as usize;
        let policy = match request.debug.lod.resolve(viewed.gaussians, pixels) {
            // Every Gaussian of a scene drawn from its cache would not fit.
            LodPolicy::Off if viewed.from_cache => LodPolicy::Auto,
            policy => policy,
        };
        let (image, lod) = match policy {
            LodPolicy::Off => (
                self.painter
                    .render_scene(scene, cleaned, &camera, settings)?,
                None,
            ),
            policy => {
                if self.lod.as_ref().is_none_or(|(c, _)| *c != cleaned) {
                    let cached = (!cleaned).then(|| cached_hierarchy(&viewed.path)).flatten();
                    let hierarchy = cached.unwrap_or_else(|| LodScene::new(build(scene)));
                    self.lod = Some((cleaned, hierarchy));
                }
                let (_, hierarchy) = self.lod.as_mut().expect("built above");
                let image = self
                    .painter
                    .render_lod(hierarchy, &camera, policy, settings)?;
                (image, Some(hierarchy.summary()))
            }
        };
        Ok(FrameResult {
            image,
            timings: FrameTimings {
                render: t.elapsed().as_secs_f64() * 1e3,
                ..FrameTimings::default()
            },
            gaussians: viewed.gaussians,
            visible: self.painter.visible(),
            stages: self.painter.stage_timings(),
            extras: 0,
            lod,
            state_hash: scene_view_hash(viewed, &request.recipe.camera),
        })
    }

    /// Writes the current frame as a standard 3DGS PLY (a scene: in the
    /// format the path's extension names).
    pub fn export_ply(&mut self, recipe: &Recipe, path: &Path) -> Result<usize> {
        // A file holds the composite the recipe makes, fit included.
        self.settle(recipe)?;
        match &self.content {
            Content::Composite(composer) => {
                let scene = composer.scene();
                crate::io::splat::write_scene(path, &scene)?;
                Ok(scene.len())
            }
            Content::Scene(viewed) if viewed.from_cache => Err(Error::input(format!(
                "export-ply: {} is drawn from its level-of-detail cache, not held in memory; convert the file itself (visage convert)",
                viewed.name
            ))),
            Content::Scene(viewed) => {
                crate::io::splat::write_scene(path, &viewed.scene)?;
                Ok(viewed.scene.len())
            }
        }
    }

    /// The depth (distance along the view axis) of what the centre pixel of
    /// the request's view shows: where the accumulated opacity reaches one
    /// half, front to back. `None` when the centre shows only background.
    pub fn centre_depth(&mut self, request: &FrameRequest) -> Result<Option<f32>> {
        let camera = request
            .recipe
            .camera
            .camera(request.width.max(1), request.height.max(1));
        let settings = settings_for(request);
        let depth = match &mut self.content {
            Content::Composite(composer) => {
                composer.update(&request.recipe)?;
                centre_depth(&composer.scene(), &camera, &settings)
            }
            // A scene drawn from its cache: what its last cut drew.
            Content::Scene(viewed) if viewed.from_cache => match &self.lod {
                Some((_, hierarchy)) => centre_depth(hierarchy.drawn(), &camera, &settings),
                None => None,
            },
            Content::Scene(viewed) => centre_depth(&viewed.scene, &camera, &settings),
        };
        Ok(depth.map(|d| d as f32))
    }

    /// Renders an exact still and writes it as PNG.
    pub fn snapshot(&mut self, request: &FrameRequest, path: &Path) -> Result<RgbImage> {
        let still = FrameRequest {
            exact: true,
            ..request.clone()
        };
        self.settle(&still.recipe)?;
        let frame = self.render(&still)?;
        frame.image.save_png(path)?;
        Ok(frame.image)
    }
}

/// The renderer settings a request asks for.
fn settings_for(request: &FrameRequest) -> RenderSettings {
    let mut settings = if request.exact {
        RenderSettings::default()
    } else {
        RenderSettings::interactive()
    };
    settings.scale_modifier = request.debug.scale;
    settings.sh_degree = request.debug.sh_degree;
    settings
}

/// The hierarchy of the scene file at `path` from its cache, built there
/// first when missing or stale, held whole (the scene is in memory anyway);
/// None where the cache cannot be had (a read-only cache folder, too little
/// memory to build it), and the caller builds it in memory instead.
fn cached_hierarchy(path: &Path) -> Option<LodScene> {
    let quiet = |_: &str| {};
    let (tree, _, _) =
        super::lod::open_cached(path, None, usize::MAX / 2, &quiet, &|_, _| {}).ok()?;
    Some(LodScene::paged(tree))
}

/// A scene view's state hash: the file's name and size and the camera (debug
/// views — SH degree, hidden floaters — are not part of it).
fn scene_view_hash(viewed: &ViewedScene, camera: &crate::scene::camera::Orbit) -> String {
    let mut h = blake3::Hasher::new();
    h.update(format!("{} {} {camera:?}", viewed.name, viewed.gaussians).as_bytes());
    h.finalize().to_hex()[..16].to_string()
}

/// The composite's mesh, coloured by region (the debug view).
fn mesh_view(
    composer: &Composer,
    camera: &crate::scene::camera::Camera,
    request: &FrameRequest,
) -> RgbImage {
    let model = &composer.engine().database().model;
    let colours: Vec<[u8; 3]> = model
        .triangle_regions
        .iter()
        .map(|r| {
            if !request.debug.highlight {
                region_colour(*r)
            } else if r.group() == request.group {
                [255, 200, 40]
            } else {
                [110, 110, 120]
            }
        })
        .collect();
    render_mesh(
        &composer.posed().vertices,
        &model.triangles,
        &colours,
        camera.view_projection(),
        camera.eye,
        camera.width,
        camera.height,
    )
}

/// The mean skin colour of each source (for the source strip's swatches).
pub fn source_swatches(engine: &Engine) -> Vec<[u8; 3]> {
    let db = engine.database();
    db.sources
        .iter()
        .map(|s| {
            let g = &s.gaussians;
            let skin: Vec<u32> = (0..g.len() as u32)
                .filter(|&i| {
                    db.model.triangle_regions[g.binding[i as usize] as usize]
                        == crate::model::regions::Region::Skin
                })
                .collect();
            let mean =
                crate::compose::colour::weighted_mean_colour(g, &skin).unwrap_or(Vec3::splat(0.5));
            [mean.x, mean.y, mean.z].map(|c| (c.clamp(0.0, 1.0) * 255.0) as u8)
        })
        .collect()
}

/// Fails when a path's folder does not exist (a clear message before any work).
pub fn check_parent(path: &Path) -> Result<()> {
    match path.parent().filter(|p| !p.as_os_str().is_empty()) {
        Some(dir) if !dir.is_dir() => Err(Error::input(format!(
            "folder {} does not exist",
            dir.display()
        ))),
        _ => Ok(()),
    }
}
