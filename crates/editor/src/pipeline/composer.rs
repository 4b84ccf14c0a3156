//! The one path from a database and a recipe to a posed composite and an
//! image. A [`Composer`] keeps a composite up to date with a recipe (only what
//! a change touches is rebuilt) and posed at a frame; a [`Painter`] draws a
//! composer's posed composite with one renderer, uploading the Gaussians only
//! when they changed. The editor's workbench, `compose`, `export`, `render`
//! and every benchmark go through these two.

use std::time::Instant;

use crate::avatar::gaussians::{dc_to_rgb, rgb_to_dc, GaussianSet};
use crate::compose::engine::{Composite, Engine, PosedMesh};
use crate::compose::recipe::{Fit, Recipe, ResolvedRecipe};
use crate::error::{Error, Result};
use crate::model::regions::Group;
use crate::render::image::RgbImage;
use crate::render::lod::LodPolicy;
use crate::render::reference::render_reference;
use crate::render::settings::RenderSettings;
use crate::render::{Backend, SplatRenderer};
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;
use crate::train::fit_store::{FitKey, FitStore};
use crate::train::seam_fit::{FitReport, SeamFit, SeamFitter};

use super::lod::LodScene;
use super::DatabaseSpec;

/// Milliseconds spent building a composite from nothing.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildTimings {
    /// Opening (or generating) the database.
    pub database: f64,
    /// Engine set-up (lookup tables, Laplacian factorisation).
    pub setup: f64,
    /// Composing the recipe.
    pub compose: f64,
    /// Posing the frame.
    pub pose: f64,
}

/// Where the recipe's finishing fit (`[post] fit`) stands.
enum FitState {
    /// The recipe asks for none: the composite shows as composed.
    None,
    /// Asked for and not done: the composite shows as composed meanwhile.
    /// The fitter starts with the first [`Composer::fit_step`].
    Pending(Option<Box<SeamFitter>>),
    /// Done: the composite holds the fitted Gaussians, and this the
    /// engine's own, put back before the engine updates the composite.
    Fitted {
        composed: GaussianSet,
        report: FitReport,
    },
}

/// How far a pending fit is, in units of work (see [`SeamFitter`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FitProgress {
    /// Units done.
    pub done: usize,
    /// Units in all (0 until the fit starts).
    pub total: usize,
}

impl FitProgress {
    fn of(fitter: &SeamFitter) -> Self {
        Self {
            done: fitter.done(),
            total: fitter.total(),
        }
    }
}

/// A composite on its engine, kept up to date with a recipe and posed.
pub struct Composer {
    engine: Engine,
    composite: Option<Composite>,
    posed: PosedMesh,
    /// Bumped whenever the composite's Gaussians change (renderers re-upload).
    generation: u64,
    fit: FitState,
    fit_options: SeamFit,
    /// Where finished fits are looked up before fitting, and kept after.
    fit_store: Option<FitStore>,
    /// The key the pending or completed fit was looked up by (and is saved
    /// under).
    fit_key: Option<FitKey>,
    /// Why the last finished fit could not be kept, until taken.
    store_error: Option<Error>,
    /// Whether the fit on show was read from the store rather than made.
    fit_from_store: bool,
}

/// How long the last [`Composer::update`] spent, in milliseconds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateTimings {
    /// Recipe → composite (blend and/or selection).
    pub compose: f64,
    /// Posing the recipe's frame.
    pub pose: f64,
    /// The composite changed (shape or Gaussians), so `compose` timed real work.
    pub recomposed: bool,
}

impl Composer {
    /// A composer on an engine (nothing composed yet).
    pub fn new(engine: Engine) -> Self {
        Self {
            engine,
            composite: None,
            posed: PosedMesh::default(),
            generation: 0,
            fit: FitState::None,
            fit_options: SeamFit::default(),
            fit_store: None,
            fit_key: None,
            store_error: None,
            fit_from_store: false,
        }
    }

    /// Where finished seam fits are kept (`None`, the default: nowhere).
    /// A fit about to start is first looked up there, and one that finishes
    /// is saved there.
    pub fn set_fit_store(&mut self, store: Option<FitStore>) {
        self.fit_store = store;
    }

    /// Why the last finished fit could not be saved to the store, once:
    /// a fit that shows but was not kept is no reason to stop the caller
    /// (a participant's session), so only a caller that makes fits to keep
    /// them (`study build`) asks.
    pub fn take_store_error(&mut self) -> Option<Error> {
        self.store_error.take()
    }

    /// How a recipe's seam fit runs from now on (default:
    /// [`SeamFit::default`]); a fit under other options is redone.
    pub fn set_fit_options(&mut self, options: SeamFit) {
        if options != self.fit_options {
            self.fit_options = options;
            if !matches!(self.fit, FitState::None) {
                if self.unfit().is_some() {
                    // The composed Gaussians are back on show.
                    self.generation += 1;
                }
                self.fit = FitState::Pending(None);
            }
        }
    }

    /// Opens a database, composes the recipe `choose` picks for it and poses
    /// `frame` (default: the recipe's). `file` names the recipe's file in errors.
    pub fn build(
        spec: &DatabaseSpec,
        choose: impl FnOnce(&crate::avatar::database::Database) -> Recipe,
        frame: Option<usize>,
        file: Option<&std::path::Path>,
    ) -> Result<(Composer, BuildTimings)> {
        let (db, db_time) = spec.load()?;
        let recipe = choose(&db);
        recipe.resolve(&db).map_err(|e| match file {
            Some(path) => Error::input(format!("{}: {e}", path.display())),
            None => e,
        })?;
        let t = Instant::now();
        let mut composer = Composer::new(Engine::new(db)?);
        let setup = t.elapsed().as_secs_f64() * 1e3;
        let (resolved, mut timings) = composer.update(&recipe)?;
        if let Some(k) = frame {
            composer.check_frames(k..k + 1)?;
        }
        if let Some(k) = frame.filter(|&k| k != resolved.frame) {
            timings.pose = composer.pose(k);
        }
        Ok((
            composer,
            BuildTimings {
                database: db_time.as_secs_f64() * 1e3,
                setup,
                compose: timings.compose,
                pose: timings.pose,
            },
        ))
    }

    /// Brings the composite up to date with `recipe` and poses its frame.
    /// A seam fit the recipe asks for (`[post] fit = "seams"`) is not run
    /// here: the composite shows as composed until [`Composer::fit_step`]
    /// or [`Composer::finish_fit`] completes it, and keeps a completed fit
    /// for as long as its Gaussians and shape stay.
    pub fn update(&mut self, recipe: &Recipe) -> Result<(ResolvedRecipe, UpdateTimings)> {
        let resolved = recipe.resolve(self.engine.database())?;
        let t = Instant::now();
        let fitted = self.unfit();
        let recomposed = match &mut self.composite {
            Some(c) => {
                let changes = self.engine.update(c, &resolved);
                if changes.gaussians {
                    self.generation += 1;
                }
                changes.gaussians || changes.shape
            }
            None => {
                self.composite = Some(self.engine.compose(&resolved));
                self.generation += 1;
                true
            }
        };
        self.follow_fit(resolved.post.fit, fitted, recomposed);
        let compose = t.elapsed().as_secs_f64() * 1e3;
        let pose = self.pose(resolved.frame);
        Ok((
            resolved,
            UpdateTimings {
                compose,
                pose,
                recomposed,
            },
        ))
    }

    /// Puts the engine's own Gaussians back where a fit was shown, and
    /// returns the fitted ones with their report.
    fn unfit(&mut self) -> Option<(GaussianSet, FitReport)> {
        if !matches!(self.fit, FitState::Fitted { .. }) {
            // A pending fit keeps its progress.
            return None;
        }
        let FitState::Fitted { composed, report } =
            std::mem::replace(&mut self.fit, FitState::None)
        else {
            unreachable!("matched above");
        };
        let c = self.composite.as_mut().expect("a fit is of a composite");
        Some((std::mem::replace(&mut c.gaussians, composed), report))
    }

    /// The fit state after an update: a completed fit stays while the
    /// composite is the same; a pending one keeps its progress likewise.
    fn follow_fit(
        &mut self,
        wanted: Fit,
        fitted: Option<(GaussianSet, FitReport)>,
        recomposed: bool,
    ) {
        let pending = std::mem::replace(&mut self.fit, FitState::None);
        if wanted == Fit::Off || recomposed {
            if fitted.is_some() {
                // The composed Gaussians are back on show.
                self.generation += 1;
            }
            if wanted == Fit::Seams {
                self.fit = FitState::Pending(None);
            }
            return;
        }
        self.fit = match fitted {
            Some((set, report)) => {
                let c = self.composite.as_mut().expect("updated");
                FitState::Fitted {
                    composed: std::mem::replace(&mut c.gaussians, set),
                    report,
                }
            }
            None => match pending {
                FitState::Pending(fitter) => FitState::Pending(fitter),
                _ => FitState::Pending(None),
            },
        };
    }

    /// How far the recipe's seam fit is, while it is pending (`None`: no
    /// fit asked for, or it is done).
    pub fn fit_progress(&self) -> Option<FitProgress> {
        match &self.fit {
            FitState::Pending(fitter) => Some(
                fitter
                    .as_deref()
                    .map_or_else(FitProgress::default, FitProgress::of),
            ),
            _ => None,
        }
    }

    /// Whether the completed seam fit was read from the fit store (see
    /// [`Composer::set_fit_store`]) rather than made; false while none is.
    pub fn fit_was_stored(&self) -> bool {
        self.fit_from_store && matches!(self.fit, FitState::Fitted { .. })
    }

    /// The key the completed seam fit is stored under (it was looked up by
    /// it first); `None` while none is completed or without a store.
    pub fn fit_key(&self) -> Option<FitKey> {
        self.fit_key
            .filter(|_| matches!(self.fit, FitState::Fitted { .. }))
    }

    /// The store finished fits are kept in, if any.
    pub fn fit_store(&self) -> Option<&FitStore> {
        self.fit_store.as_ref()
    }

    /// What the completed seam fit did (`None` until one completes).
    pub fn fit_report(&self) -> Option<FitReport> {
        match &self.fit {
            FitState::Fitted { report, .. } => Some(*report),
            _ => None,
        }
    }

    /// Does one unit of a pending seam fit; when that completes it, the
    /// composite shows the fitted Gaussians (the generation changes).
    /// Returns the progress, or `None` when no fit is pending.
    pub fn fit_step(&mut self) -> Result<Option<FitProgress>> {
        let FitState::Pending(fitter) = &mut self.fit else {
            return Ok(None);
        };
        let c = self.composite.as_mut().expect("a fit is of a composite");
        if fitter.is_none() {
            // The composite stays as it is while the fit is pending, so the
            // key it is looked up by is the one to save it under.
            self.fit_key = self
                .fit_store
                .as_ref()
                .map(|_| FitKey::of(&self.engine, c, &self.fit_options));
            let stored = match (&self.fit_store, &self.fit_key) {
                (Some(store), Some(key)) => store.load(key, &c.gaussians),
                _ => None,
            };
            if let Some((set, report)) = stored {
                self.fit_from_store = true;
                self.fit = FitState::Fitted {
                    composed: std::mem::replace(&mut c.gaussians, set),
                    report,
                };
                self.generation += 1;
                return Ok(Some(FitProgress { done: 1, total: 1 }));
            }
        }
        let f = fitter
            .get_or_insert_with(|| Box::new(SeamFitter::new(&self.engine, c, &self.fit_options)));
        if let Err(e) = f.step(&self.engine, c) {
            // Given up: the composite stays as composed until it changes.
            self.fit = FitState::None;
            return Err(e);
        }
        let progress = FitProgress::of(f);
        if f.finished() {
            let (set, report) = f.result(c);
            let composed = std::mem::replace(&mut c.gaussians, set);
            self.generation += 1;
            // A fit with nothing fitted has nothing worth keeping.
            if let (Some(store), Some(key)) = (&self.fit_store, &self.fit_key) {
                if report.fitted > 0 {
                    self.store_error = store.save(key, &composed, &c.gaussians, &report).err();
                }
            }
            self.fit_from_store = false;
            self.fit = FitState::Fitted { composed, report };
        }
        Ok(Some(progress))
    }

    /// Runs a pending seam fit to the end; `progress` hears each unit.
    /// Returns the fit's report when one was pending.
    pub fn finish_fit(
        &mut self,
        progress: &mut dyn FnMut(FitProgress),
    ) -> Result<Option<FitReport>> {
        let mut ran = false;
        while let Some(p) = self.fit_step()? {
            ran = true;
            progress(p);
        }
        Ok(ran.then(|| self.fit_report()).flatten())
    }

    /// Fails unless the composite's motion has every frame of `frames` (the
    /// rest pose has frame 0 only): a frame past the end is an error, never a
    /// silent wrap.
    pub fn check_frames(&self, frames: std::ops::Range<usize>) -> Result<()> {
        let db = self.engine.database();
        let motion = self
            .composite
            .as_ref()
            .and_then(|c| c.recipe.motion)
            .and_then(|m| db.motions.get(m));
        let count = motion.map_or(1, |m| m.frames().max(1));
        if frames.end <= count {
            return Ok(());
        }
        let last = frames.end - 1;
        Err(Error::input(match motion {
            Some(m) => format!(
                "frame {last} is past the end of the motion {} (frames 0-{})",
                crate::text::printable(&m.name),
                count - 1
            ),
            None => {
                format!("frame {last}: the recipe is at rest (no motion), which has only frame 0")
            }
        }))
    }

    /// Poses another frame of the composite's motion; returns milliseconds spent.
    pub fn pose(&mut self, frame: usize) -> f64 {
        let t = Instant::now();
        if let Some(c) = &self.composite {
            self.engine.pose(c, frame, &mut self.posed);
        }
        t.elapsed().as_secs_f64() * 1e3
    }

    /// The engine (database, tables, blender).
    pub fn engine(&self) -> &Engine {
        &self.engine
    }

    /// The composite (after the first update).
    pub fn composite(&self) -> &Composite {
        self.composite
            .as_ref()
            .expect("a composer is updated before it is read")
    }

    /// The posed frame.
    pub fn posed(&self) -> &PosedMesh {
        &self.posed
    }

    /// The posed composite as world-space Gaussians (for PLY export and the
    /// reference renderer).
    pub fn scene(&self) -> SplatScene {
        self.engine.scene(self.composite(), &self.posed)
    }

    /// Changes whenever the composite's Gaussians do.
    pub fn generation(&self) -> u64 {
        self.generation
    }
}

/// What a painter's renderer holds.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Uploaded {
    /// A composer's Gaussians of this generation.
    Composite(u64),
    /// The same with every group but one dimmed (the region highlight).
    Highlighted(u64, Group),
    /// A world-space scene (a painter draws one scene for its lifetime), as
    /// it is or without its floaters.
    Scene {
        /// Whether this is the scene without its floaters.
        cleaned: bool,
    },
    /// A level-of-detail cut of a scene (the hierarchy knows which).
    Cut,
}

/// One renderer drawing composers' posed composites (or one scene).
pub struct Painter {
    renderer: SplatRenderer,
    uploaded: Option<Uploaded>,
}

impl Painter {
    /// A painter with a renderer of the given kind.
    pub fn open(backend: Backend) -> Result<Self> {
        Ok(Self {
            renderer: SplatRenderer::open(backend)?,
            uploaded: None,
        })
    }

    /// What renders.
    pub fn description(&self) -> String {
        self.renderer.description()
    }

    /// The renderer (stage profiling and timings in benchmarks).
    pub fn renderer_mut(&mut self) -> &mut SplatRenderer {
        &mut self.renderer
    }

    /// Uploads the composer's Gaussians unless this painter has them already.
    pub fn upload(&mut self, composer: &Composer) -> Result<()> {
        let generation = Uploaded::Composite(composer.generation());
        if self.uploaded != Some(generation) {
            self.renderer
                .set_gaussians(&composer.composite().gaussians)?;
            self.uploaded = Some(generation);
        }
        Ok(())
    }

    /// Draws a world-space scene, uploading it when it was not the last one
    /// drawn (a painter that draws a scene draws only that scene, as it is
    /// or, `cleaned`, without its floaters).
    pub fn render_scene(
        &mut self,
        scene: &SplatScene,
        cleaned: bool,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let which = Some(Uploaded::Scene { cleaned });
        if self.uploaded != which {
            self.renderer.set_world_scene(scene)?;
            self.uploaded = which;
        }
        self.renderer.render_world(camera, settings)
    }

    /// Draws a scene through its hierarchy: the cut of `camera`, uploaded
    /// when it changed or when this painter drew something else since.
    pub fn render_lod(
        &mut self,
        hierarchy: &mut LodScene,
        camera: &Camera,
        policy: LodPolicy,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        if self.uploaded != Some(Uploaded::Cut) {
            hierarchy.forget();
            self.uploaded = Some(Uploaded::Cut);
        }
        hierarchy.render(&mut self.renderer, camera, policy, settings)
    }

    /// Gaussians drawn in the last frame, where the renderer counts them.
    pub fn visible(&self) -> Option<usize> {
        self.renderer.visible()
    }

    /// Stage timings of the last frame.
    pub fn stage_timings(&self) -> crate::render::settings::StageTimings {
        self.renderer.timings()
    }

    /// Draws the composer's posed composite with every group but `group`
    /// dimmed: the region highlight over the Gaussians (a Gaussian belongs
    /// to the group it was selected for: by place or by parent triangle, as
    /// the recipe's membership has it; border copies to the group they
    /// smooth into).
    pub fn render_highlighted(
        &mut self,
        composer: &Composer,
        group: Group,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let key = Uploaded::Highlighted(composer.generation(), group);
        if self.uploaded != Some(key) {
            let set = highlighted(composer, group);
            self.renderer.set_gaussians(&set)?;
            self.uploaded = Some(key);
        }
        self.renderer
            .render(&composer.posed().frames, camera, settings)
    }

    /// Draws the composer's posed composite.
    pub fn render(
        &mut self,
        composer: &Composer,
        camera: &Camera,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        self.upload(composer)?;
        self.renderer
            .render(&composer.posed().frames, camera, settings)
    }
}

/// Share of its colour a dimmed Gaussian keeps in the highlight.
const DIMMED: f32 = 0.3;

/// The composite's Gaussians with those outside `group` darkened towards
/// black and their view-dependent colour damped, so the group stands out.
fn highlighted(composer: &Composer, group: Group) -> GaussianSet {
    let composite = composer.composite();
    let mut set = composite.gaussians.clone();
    let stride = set.sh_stride();
    // By the block a Gaussian was selected for, so the highlight shows the
    // region membership the composite uses (by place or by parent).
    for block in composite
        .blocks
        .iter()
        .filter(|b| b.region.group() != group)
    {
        for i in block.start..block.end.min(set.len()) {
            let sh = &mut set.sh[i * stride..(i + 1) * stride];
            for dc in &mut sh[..3] {
                *dc = rgb_to_dc(dc_to_rgb(*dc) * DIMMED);
            }
            for rest in &mut sh[3..] {
                *rest *= DIMMED;
            }
        }
    }
    set
}

/// The f64 reference image of a composer's posed composite (the oracle).
pub fn reference_image(
    composer: &Composer,
    camera: &Camera,
    settings: &RenderSettings,
) -> RgbImage {
    render_reference(&composer.scene(), camera, settings)
}
