//! Editor state and its update function: `apply(command)` is the only way the
//! state changes, so sessions replay exactly and undo covers every edit.

use std::collections::BTreeMap;

use crate::compose::recipe::{
    Anchor, AnimationMode, ColourCorrection, Deform, Fit, GroupEdit, Membership, Recipe, Shading,
    SkinSource, Smoothing,
};
use crate::model::regions::Group;
use crate::pipeline::workbench::DebugView;
use crate::render::lod::LodPolicy;
use crate::scene::camera::Orbit;

use super::command::{Area, Command, PoseJoint};

/// Names the editor validates commands against.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Catalog {
    /// Source names, in display order.
    pub sources: Vec<String>,
    /// Motion names and frame counts.
    pub motions: Vec<(String, usize)>,
    /// The scene viewed, when the editor views a scene file instead of
    /// composing avatars (`visage view FILE`).
    pub scene: Option<SceneSummary>,
}

/// What the editor knows of a scene it views.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneSummary {
    /// The file's name.
    pub name: String,
    /// Gaussians in the file.
    pub gaussians: usize,
    /// The file's SH degree.
    pub sh_degree: u8,
    /// The framed camera it opened with.
    pub home: Orbit,
    /// How its up axis was chosen, in words.
    pub up_reason: &'static str,
    /// Drawn from its level-of-detail cache (too large to hold).
    pub from_cache: bool,
}

impl Catalog {
    /// The names a workbench offers: its database's, or its scene's summary.
    pub fn of_workbench(workbench: &crate::pipeline::workbench::Workbench) -> Self {
        match (workbench.engine(), workbench.scene()) {
            (Some(engine), _) => Catalog::of(engine),
            (None, Some(viewed)) => Catalog {
                scene: Some(SceneSummary {
                    name: viewed.name.clone(),
                    gaussians: viewed.gaussians,
                    sh_degree: viewed.sh_degree,
                    from_cache: viewed.from_cache,
                    home: viewed.home,
                    up_reason: viewed.up_reason.describe(),
                }),
                ..Catalog::default()
            },
            (None, None) => Catalog::default(),
        }
    }

    /// The camera `camera-reset` returns to.
    pub fn home(&self) -> Orbit {
        self.scene.as_ref().map_or(Orbit::default(), |s| s.home)
    }

    /// The orbit radii zoom keeps to: a head's range, or a scene's around its
    /// framing.
    fn radius_range(&self) -> (f32, f32) {
        match &self.scene {
            Some(s) => (s.home.radius * 1e-3, s.home.radius * 1e2),
            None => (0.05, 50.0),
        }
    }

    /// The names a database offers the editor.
    pub fn of(engine: &crate::compose::engine::Engine) -> Self {
        let db = engine.database();
        Self {
            sources: db
                .sources
                .iter()
                .map(|s| crate::text::printable(&s.name))
                .collect(),
            motions: db
                .motions
                .iter()
                .map(|m| (m.name.clone(), m.frames()))
                .collect(),
            scene: None,
        }
    }

    fn source(&self, name: &str) -> Result<usize, String> {
        self.sources.iter().position(|s| s == name).ok_or_else(|| {
            format!(
                "unknown source '{}' (sources: {})",
                crate::text::printable(name),
                self.sources.join(", ")
            )
        })
    }

    /// The name of the source at a cursor position.
    fn selected(&self, cursor: usize) -> Result<String, String> {
        self.sources
            .get(cursor)
            .cloned()
            .ok_or_else(|| "no sources".into())
    }

    /// The camera `camera-reset` returns to, with a chosen up axis: the
    /// framing is the same, seen the right way up.
    pub fn home_with_up(&self, up: crate::scene::camera::UpAxis) -> Orbit {
        Orbit { up, ..self.home() }
    }

    /// Frames of a motion ("rest" has one).
    pub fn frames(&self, motion: &str) -> usize {
        self.motions
            .iter()
            .find(|(m, _)| m == motion)
            .map_or(1, |(_, n)| (*n).max(1))
    }
}

/// Side effects a command asks the runtime to perform.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Effect {
    /// Write the recipe.
    SaveRecipe(String),
    /// Write the current frame as a 3DGS scene (format from the extension).
    ExportPly(String),
    /// Write the current view as a PNG, at a size or the session's render size.
    Snapshot(String, Option<(u32, u32)>),
}

/// What applying a command produced: effects for the runtime and a message
/// for the user.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Applied {
    /// Files to write.
    pub effects: Vec<Effect>,
    /// What happened, for the status line (undo says what it undid).
    pub message: Option<String>,
}

impl Applied {
    fn said(message: String) -> Self {
        Self {
            effects: Vec::new(),
            message: Some(message),
        }
    }

    fn effect(effect: Effect) -> Self {
        Self {
            effects: vec![effect],
            message: None,
        }
    }
}

/// One step of the undo history: the recipe before an edit and the edit.
#[derive(Clone, Debug, PartialEq)]
struct HistoryStep {
    recipe: Recipe,
    command: String,
}

/// The editor's document and cursors: the recipe, the selection, playback,
/// the study limits, the debug view and the undo history. What the terminal
/// shows around it (prompt, help, status line) belongs to the front end.
#[derive(Clone, Debug, PartialEq)]
pub struct EditorState {
    /// The document: everything that defines the composite, camera included.
    pub recipe: Recipe,
    /// Group cursor (index into [`Group::ALL`]).
    pub group: usize,
    /// Source cursor.
    pub source: usize,
    /// Playing at 25 FPS.
    pub playing: bool,
    /// The thesis study camera limits are on.
    pub study: bool,
    /// Debug view.
    pub debug: DebugView,
    undo: Vec<HistoryStep>,
    redo: Vec<HistoryStep>,
}

/// Most undo steps kept.
const UNDO_LIMIT: usize = 500;

impl EditorState {
    /// A fresh editor on `recipe`.
    pub fn new(recipe: Recipe) -> Self {
        Self {
            recipe,
            group: 0,
            source: 0,
            playing: false,
            study: false,
            debug: DebugView::default(),
            undo: Vec::new(),
            redo: Vec::new(),
        }
    }

    /// The selected group.
    pub fn selected_group(&self) -> Group {
        Group::ALL[self.group]
    }

    /// Steps available to undo and redo.
    pub fn history(&self) -> (usize, usize) {
        (self.undo.len(), self.redo.len())
    }

    /// The Gaussian source and shape weights of a group (the base's when unedited).
    pub fn group_edit(&self, group: Group) -> GroupEdit {
        self.recipe
            .groups
            .get(group.name())
            .cloned()
            .unwrap_or_else(|| GroupEdit {
                gaussians: self.recipe.base.clone(),
                shape: BTreeMap::from([(self.recipe.base.clone(), 1.0)]),
            })
    }

    fn set_group_edit(&mut self, group: Group, mut edit: GroupEdit) {
        if edit.shape.is_empty() {
            edit.shape.insert(self.recipe.base.clone(), 1.0);
        }
        self.recipe.groups.insert(group.name().to_string(), edit);
    }

    /// Advances one logical tick (25 per second while playing).
    pub fn tick(&mut self, catalog: &Catalog) {
        if self.playing {
            let n = catalog.frames(&self.recipe.animation.motion);
            self.recipe.animation.frame = (self.recipe.animation.frame + 1) % n;
        }
    }

    /// Applies a command. Edits are recorded for undo; a failing command changes
    /// nothing and returns the reason. Front-end commands (quit, help, the
    /// prompt) change nothing here.
    pub fn apply(&mut self, catalog: &Catalog, command: &Command) -> Result<Applied, String> {
        let spec = command.spec();
        if catalog.scene.is_some() && spec.avatar {
            return Err(format!(
                "{}: a scene view has no avatars (open a database with 'visage edit')",
                spec.name
            ));
        }
        if !spec.edit {
            return self.update(catalog, command);
        }
        let before = self.clone();
        match self.update(catalog, command) {
            Ok(applied) => {
                if self.recipe != before.recipe {
                    self.undo.push(HistoryStep {
                        recipe: before.recipe,
                        command: command.to_string(),
                    });
                    if self.undo.len() > UNDO_LIMIT {
                        self.undo.remove(0);
                    }
                    self.redo.clear();
                }
                Ok(applied)
            }
            Err(e) => {
                *self = before;
                Err(e)
            }
        }
    }

    /// Routes a command to the part of the state its area owns.
    fn update(&mut self, catalog: &Catalog, command: &Command) -> Result<Applied, String> {
        match command.spec().area {
            _ if command.spec().front => Ok(Applied::default()),
            Area::Editor => self.update_history(command),
            Area::Selection => self.update_selection(catalog, command),
            Area::Shape => self.update_shape(catalog, command),
            Area::PostProcessing => self.update_post(command),
            Area::Animation => self.update_animation(catalog, command),
            Area::Camera => self.update_camera(catalog, command),
            Area::Files => self.update_files(command),
            Area::Debug => self.update_debug(catalog, command),
        }
    }

    /// Undo and redo.
    fn update_history(&mut self, command: &Command) -> Result<Applied, String> {
        let (from, to, verb) = match command {
            Command::Undo => (&mut self.undo, &mut self.redo, "undone"),
            Command::Redo => (&mut self.redo, &mut self.undo, "redone"),
            other => return Err(misrouted(other)),
        };
        let Some(step) = from.pop() else {
            return Err(format!("nothing to {}", &verb[..4]));
        };
        to.push(HistoryStep {
            recipe: self.recipe.clone(),
            command: step.command.clone(),
        });
        self.restore(step.recipe);
        Ok(Applied::said(format!("{verb}: {}", step.command)))
    }

    /// Restores an older recipe but keeps the view: camera and frame stay.
    fn restore(&mut self, mut recipe: Recipe) {
        recipe.camera = self.recipe.camera;
        recipe.animation.frame = self.recipe.animation.frame;
        self.recipe = recipe;
    }

    /// The cursors, and which source shows its Gaussians where.
    fn update_selection(
        &mut self,
        catalog: &Catalog,
        command: &Command,
    ) -> Result<Applied, String> {
        let n_sources = catalog.sources.len().max(1);
        match command {
            Command::SelectGroup(g) => self.group = g.index(),
            Command::NextGroup => self.group = (self.group + 1) % Group::COUNT,
            Command::PrevGroup => self.group = (self.group + Group::COUNT - 1) % Group::COUNT,
            Command::SelectSource(s) => self.source = catalog.source(s)?,
            Command::NextSource => self.source = (self.source + 1) % n_sources,
            Command::PrevSource => self.source = (self.source + n_sources - 1) % n_sources,
            Command::Assign => {
                let name = catalog.selected(self.source)?;
                self.assign(self.selected_group(), name);
            }
            Command::SetGaussians(g, s) => {
                catalog.source(s)?;
                self.assign(*g, s.clone());
            }
            Command::SetBase(s) => {
                catalog.source(s)?;
                self.recipe.base = s.clone();
            }
            Command::BaseFromSelected => self.recipe.base = catalog.selected(self.source)?,
            other => return Err(misrouted(other)),
        }
        Ok(Applied::default())
    }

    /// Shape weights.
    fn update_shape(&mut self, catalog: &Catalog, command: &Command) -> Result<Applied, String> {
        let (group, shape) = match command {
            Command::SetShape(g, weights) => (*g, normalised_weights(catalog, weights)?),
            Command::ShapeAdd(delta) => {
                let source = catalog.selected(self.source)?;
                let g = self.selected_group();
                let shape = add_weight(
                    &self.group_edit(g).shape,
                    &source,
                    *delta,
                    &self.recipe.base,
                );
                (g, shape)
            }
            other => return Err(misrouted(other)),
        };
        let mut edit = self.group_edit(group);
        edit.shape = shape;
        self.set_group_edit(group, edit);
        Ok(Applied::default())
    }

    /// Border smoothing, colour correction, region membership and how
    /// Gaussians follow reshaped triangles.
    fn update_post(&mut self, command: &Command) -> Result<Applied, String> {
        let post = &mut self.recipe.post;
        match command {
            Command::Smoothing(s) => {
                post.smoothing = s.unwrap_or(match post.smoothing {
                    // The best measured first (README, ground truth).
                    Smoothing::Off => Smoothing::Blend,
                    Smoothing::Blend => Smoothing::Thesis,
                    Smoothing::Thesis => Smoothing::Crossfade,
                    Smoothing::Crossfade => Smoothing::Off,
                })
            }
            Command::Colour(c) => {
                post.colour = c.unwrap_or(match post.colour {
                    // The best measured first (README, ground truth).
                    ColourCorrection::Off => ColourCorrection::Semantic,
                    ColourCorrection::Semantic => ColourCorrection::Skin,
                    ColourCorrection::Skin => ColourCorrection::Thesis,
                    ColourCorrection::Thesis => ColourCorrection::Off,
                })
            }
            Command::Membership(m) => {
                post.membership = m.unwrap_or(match post.membership {
                    Membership::Parent => Membership::Place,
                    Membership::Place => Membership::Parent,
                })
            }
            Command::Deform(d) => {
                post.deform = d.unwrap_or(match post.deform {
                    Deform::Similarity => Deform::Affine,
                    Deform::Affine => Deform::Similarity,
                })
            }
            Command::Anchor(a) => {
                post.anchor = a.unwrap_or(match post.anchor {
                    Anchor::Parent => Anchor::Nearest,
                    Anchor::Nearest => Anchor::Parent,
                })
            }
            Command::Shading(s) => {
                post.shading = s.unwrap_or(match post.shading {
                    Shading::Kept => Shading::Relit,
                    Shading::Relit => Shading::Kept,
                })
            }
            Command::Skin(s) => {
                post.skin = s.unwrap_or(match post.skin {
                    SkinSource::Source => SkinSource::Base,
                    SkinSource::Base => SkinSource::Source,
                })
            }
            Command::Fit(f) => {
                post.fit = f.unwrap_or(match post.fit {
                    Fit::Off => Fit::Seams,
                    Fit::Seams => Fit::Off,
                })
            }
            other => return Err(misrouted(other)),
        }
        Ok(Applied::default())
    }

    /// Motions, frames, playback, poses and expressions.
    fn update_animation(
        &mut self,
        catalog: &Catalog,
        command: &Command,
    ) -> Result<Applied, String> {
        let animation = &mut self.recipe.animation;
        let frames = catalog.frames(&animation.motion);
        match command {
            Command::Motion(m) => {
                if m != "rest" && !catalog.motions.iter().any(|(n, _)| n == m) {
                    let names: Vec<&str> = std::iter::once("rest")
                        .chain(catalog.motions.iter().map(|(n, _)| n.as_str()))
                        .collect();
                    return Err(format!(
                        "unknown motion '{}' (motions: {})",
                        crate::text::printable(m),
                        names.join(", ")
                    ));
                }
                animation.motion = m.clone();
                animation.frame %= catalog.frames(m);
            }
            Command::NextMotion => {
                let names: Vec<&str> = std::iter::once("rest")
                    .chain(catalog.motions.iter().map(|(n, _)| n.as_str()))
                    .collect();
                let i = names
                    .iter()
                    .position(|n| *n == animation.motion)
                    .unwrap_or(0);
                let next = names[(i + 1) % names.len()].to_string();
                animation.frame %= catalog.frames(&next);
                animation.motion = next;
            }
            Command::Play => self.playing = true,
            Command::Pause => self.playing = false,
            Command::TogglePlay => self.playing = !self.playing,
            Command::Step(n) => {
                let f = animation.frame as i64 + n;
                animation.frame = f.rem_euclid(frames as i64) as usize;
            }
            Command::Frame(n) => {
                animation.frame = frame_in_motion(*n, &animation.motion, frames)?;
            }
            Command::Mode(m) => {
                animation.mode = m.unwrap_or(match animation.mode {
                    AnimationMode::Fast => AnimationMode::Exact,
                    AnimationMode::Exact => AnimationMode::Fast,
                })
            }
            Command::Pose(joint, d) => {
                let o = &mut animation.offsets;
                let target = match joint {
                    PoseJoint::Jaw => &mut o.jaw,
                    PoseJoint::Neck => &mut o.neck,
                    PoseJoint::Eyes => &mut o.eyes,
                };
                for (t, x) in target.iter_mut().zip(d) {
                    *t = (*t + x).clamp(-1.5, 1.5);
                }
            }
            Command::Expression(k, d) => {
                let e = &mut animation.offsets.expression[k - 1];
                *e = (*e + d).clamp(-3.0, 3.0);
            }
            Command::ResetPose => animation.offsets = Default::default(),
            other => return Err(misrouted(other)),
        }
        Ok(Applied::default())
    }

    /// The camera: orbit, zoom, free flight, the up axis and the study limits.
    fn update_camera(&mut self, catalog: &Catalog, command: &Command) -> Result<Applied, String> {
        let mut message = None;
        match command {
            Command::Orbit(dy, dp) => {
                let c = &mut self.recipe.camera;
                c.yaw_deg = (c.yaw_deg + dy + 180.0).rem_euclid(360.0) - 180.0;
                c.pitch_deg = (c.pitch_deg + dp).clamp(-89.0, 89.0);
            }
            Command::Zoom(f) => {
                let (lo, hi) = catalog.radius_range();
                let c = &mut self.recipe.camera;
                c.radius = (c.radius * f).clamp(lo, hi);
            }
            Command::CameraReset => {
                let up = self.recipe.camera.up;
                self.recipe.camera = catalog.home_with_up(up);
                self.study = false;
            }
            Command::Fly(forward, right, up) => {
                self.refuse_in_study("fly")?;
                self.recipe.camera = fly(self.recipe.camera, [*forward, *right, *up]);
            }
            Command::Look(yaw, pitch) => {
                self.refuse_in_study("look")?;
                self.recipe.camera = look(self.recipe.camera, *yaw, *pitch);
            }
            Command::CameraStudy => {
                self.study = !self.study;
                if self.study {
                    self.recipe.camera = Orbit::STUDY;
                }
                message = Some(format!(
                    "study camera limits {}",
                    if self.study { "on" } else { "off" }
                ));
            }
            Command::SetCamera(o) => self.recipe.camera = o.apply(self.recipe.camera),
            Command::FlipUp => {
                self.refuse_in_study("flip-up")?;
                let c = &mut self.recipe.camera;
                c.up = c.up.flipped();
                message = Some(format!("up axis {}", c.up.name()));
            }
            other => return Err(misrouted(other)),
        }
        self.clamp_study();
        Ok(Applied {
            effects: Vec::new(),
            message,
        })
    }

    /// Recipes, exports and snapshots: effects the runtime performs.
    fn update_files(&mut self, command: &Command) -> Result<Applied, String> {
        Ok(match command {
            Command::SaveRecipe(p) => Applied::effect(Effect::SaveRecipe(p.clone())),
            Command::ExportPly(p) => {
                crate::io::splat::SceneFormat::of(std::path::Path::new(p))
                    .map_err(|e| e.to_string())?;
                Applied::effect(Effect::ExportPly(p.clone()))
            }
            Command::Snapshot(p, size) => {
                if !p.to_ascii_lowercase().ends_with(".png") {
                    return Err(format!(
                        "snapshot writes PNG: name the file .png, not '{}'",
                        crate::text::printable(p)
                    ));
                }
                Applied::effect(Effect::Snapshot(p.clone(), *size))
            }
            other => return Err(misrouted(other)),
        })
    }

    /// The debug view.
    fn update_debug(&mut self, catalog: &Catalog, command: &Command) -> Result<Applied, String> {
        let debug = &mut self.debug;
        match command {
            Command::ShDegree(d) => {
                let top = catalog.scene.as_ref().map_or(3, |s| s.sh_degree);
                debug.sh_degree = match d {
                    Some(d) => *d,
                    None if debug.sh_degree.min(top) == 0 => top,
                    None => debug.sh_degree.min(top) - 1,
                };
                return Ok(Applied::said(format!(
                    "SH degree {} of {top}",
                    debug.sh_degree.min(top)
                )));
            }
            Command::DebugScale(f) => debug.scale = (debug.scale * f).clamp(0.01, 10.0),
            Command::ToggleMesh => debug.mesh = !debug.mesh,
            Command::ToggleHighlight => debug.highlight = !debug.highlight,
            Command::ToggleFloaters => {
                match &catalog.scene {
                    None => {
                        return Err("toggle-floaters: only a scene view (visage view FILE) has floaters to hide".into())
                    }
                    Some(s) if s.from_cache => {
                        return Err(format!("toggle-floaters: {} is drawn from its level-of-detail cache; run visage clean on the file and view what it writes", s.name))
                    }
                    Some(_) => {}
                }
                debug.hide_floaters = !debug.hide_floaters;
                let said = if debug.hide_floaters {
                    "floaters hidden (what visage clean removes)"
                } else {
                    "floaters shown"
                };
                return Ok(Applied::said(said.to_string()));
            }
            Command::Lod(policy) => {
                match &catalog.scene {
                    None => {
                        return Err(
                            "lod: only a scene view (visage view FILE) has a level of detail"
                                .into(),
                        )
                    }
                    Some(s) if s.from_cache && *policy == LodPolicy::Off => {
                        return Err(format!("lod off: {} is drawn from its level-of-detail cache; every Gaussian would not fit the memory budget", s.name))
                    }
                    Some(_) => {}
                }
                debug.lod = *policy;
                return Ok(Applied::said(format!("level of detail {}", policy.label())));
            }
            other => return Err(misrouted(other)),
        }
        Ok(Applied::default())
    }

    fn refuse_in_study(&self, name: &str) -> Result<(), String> {
        if self.study {
            return Err(format!(
                "{name}: the study camera only orbits (camera-study turns it off)"
            ));
        }
        Ok(())
    }

    fn assign(&mut self, group: Group, source: String) {
        let mut edit = self.group_edit(group);
        edit.gaussians = source;
        self.set_group_edit(group, edit);
    }

    fn clamp_study(&mut self) {
        if self.study {
            let c = &mut self.recipe.camera;
            c.yaw_deg = c
                .yaw_deg
                .clamp(-Orbit::STUDY_YAW_LIMIT, Orbit::STUDY_YAW_LIMIT);
            c.pitch_deg = c
                .pitch_deg
                .clamp(-Orbit::STUDY_PITCH_LIMIT, Orbit::STUDY_PITCH_LIMIT);
            c.radius = Orbit::STUDY.radius;
        }
    }
}

/// A command routed to an area that does not own it: a bug in the table,
/// reported as a failed command rather than a crash.
fn misrouted(command: &Command) -> String {
    format!(
        "{}: no part of the editor handles this command",
        command.spec().name
    )
}

/// Frame `n` of a motion of `frames` frames, or why there is none.
pub fn frame_in_motion(n: usize, motion: &str, frames: usize) -> Result<usize, String> {
    if n < frames {
        return Ok(n);
    }
    Err(if motion == "rest" {
        format!("frame {n}: the rest pose has only frame 0 (choose a motion first)")
    } else {
        format!(
            "frame {n} is past the end of {} (frames 0-{})",
            crate::text::printable(motion),
            frames - 1
        )
    })
}

/// `SOURCE=WEIGHT` pairs checked against the database and scaled to sum to 1.
fn normalised_weights(
    catalog: &Catalog,
    weights: &[(String, f64)],
) -> Result<BTreeMap<String, f64>, String> {
    let mut shape = BTreeMap::new();
    for (s, w) in weights {
        catalog.source(s)?;
        if *w < 0.0 {
            return Err(format!("shape weight of {s} must be ≥ 0"));
        }
        if *w > 0.0 {
            *shape.entry(s.clone()).or_insert(0.0) += *w;
        }
    }
    let sum: f64 = shape.values().sum();
    if sum <= 0.0 {
        return Err("shape weights are all zero".into());
    }
    shape.values_mut().for_each(|w| *w = tidy_weight(*w / sum));
    Ok(shape)
}

/// A weight rounded to 12 decimals, so that repeated steps of 0.1 read back
/// as 0.3 rather than 0.30000000000000004 (in recipes and on screen). The
/// change is at most 5·10⁻¹³, below anything a vertex can show; the blend
/// normalises the weights again.
pub fn tidy_weight(w: f64) -> f64 {
    (w * 1e12).round() / 1e12
}

/// The orbit moved with its target by `[forward, right, up]` fractions of its
/// radius, along the camera's own axes: free flight keeps the view direction.
pub fn fly(orbit: Orbit, step: [f32; 3]) -> Orbit {
    let eye = orbit.eye();
    let target = glam::Vec3::from(orbit.target);
    let forward = (target - eye).normalize_or(glam::Vec3::NEG_Z);
    let right = forward
        .cross(orbit.up.apply(glam::Vec3::Y))
        .try_normalize()
        .unwrap_or_else(|| forward.any_orthonormal_vector());
    let up = right.cross(forward);
    let delta = (step[0] * forward + step[1] * right + step[2] * up) * orbit.radius;
    Orbit {
        target: (target + delta).into(),
        ..orbit
    }
}

/// The orbit turned about its eye by `yaw` degrees to the right and `pitch`
/// up: the eye stays, the target swings round it.
pub fn look(orbit: Orbit, yaw: f32, pitch: f32) -> Orbit {
    let eye = orbit.eye();
    let turned = Orbit {
        yaw_deg: (orbit.yaw_deg - yaw + 180.0).rem_euclid(360.0) - 180.0,
        pitch_deg: (orbit.pitch_deg - pitch).clamp(-89.0, 89.0),
        ..orbit
    };
    // The same eye with the new angles: move the target by the eye's shift.
    let shift = eye - turned.eye();
    Orbit {
        target: (glam::Vec3::from(turned.target) + shift).into(),
        ..turned
    }
}

/// Adds `delta` to one source's weight (clamped to [0, 1]) and rescales the others
/// so the weights still sum to 1. When nothing else carries weight, the rest goes
/// to `fallback`.
pub fn add_weight(
    shape: &BTreeMap<String, f64>,
    source: &str,
    delta: f64,
    fallback: &str,
) -> BTreeMap<String, f64> {
    let current = shape.get(source).copied().unwrap_or(0.0);
    let target = (current + delta).clamp(0.0, 1.0);
    let others: f64 = shape
        .iter()
        .filter(|(k, _)| *k != source)
        .map(|(_, w)| w)
        .sum();
    let mut out = BTreeMap::new();
    if others > 0.0 {
        for (k, w) in shape.iter().filter(|(k, _)| *k != source) {
            out.insert(k.clone(), w / others * (1.0 - target));
        }
    } else if target < 1.0 {
        let heir = if fallback != source {
            fallback.to_string()
        } else {
            return BTreeMap::from([(source.to_string(), 1.0)]);
        };
        out.insert(heir, 1.0 - target);
    }
    out.insert(source.to_string(), target);
    out.values_mut().for_each(|w| *w = tidy_weight(*w));
    out.retain(|_, w| *w > 1e-12);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn catalog() -> Catalog {
        Catalog {
            sources: ["ada", "bram", "cleo"].map(String::from).to_vec(),
            motions: vec![("talk".into(), 125)],
            scene: None,
        }
    }

    fn scene_catalog() -> Catalog {
        Catalog {
            scene: Some(SceneSummary {
                name: "room.ply".into(),
                gaussians: 10,
                sh_degree: 2,
                home: Orbit {
                    radius: 20.0,
                    fov_deg: 40.0,
                    target: [1.0, 2.0, 3.0],
                    up: crate::scene::camera::UpAxis::NegY,
                    ..Orbit::STUDY
                },
                up_reason: "as given",
                from_cache: false,
            }),
            ..Catalog::default()
        }
    }

    fn forward(o: &Orbit) -> glam::Vec3 {
        (glam::Vec3::from(o.target) - o.eye()).normalize()
    }

    /// Free flight: `fly` moves eye and target together along the camera's
    /// own axes and keeps the view direction; `look` turns in place. Both
    /// hold for a y-down scene, whose camera frame is flipped.
    #[test]
    fn fly_and_look_move_the_camera_as_a_user_expects() {
        for up in [
            crate::scene::camera::UpAxis::PosY,
            crate::scene::camera::UpAxis::NegY,
            crate::scene::camera::UpAxis::PosZ,
        ] {
            let start = Orbit {
                yaw_deg: 30.0,
                pitch_deg: 10.0,
                up,
                ..Orbit::STUDY
            };
            let moved = fly(start, [0.5, 0.0, 0.0]);
            let step = moved.eye() - start.eye();
            assert!((step - forward(&start) * 0.5 * start.radius).length() < 1e-5);
            assert!((forward(&moved) - forward(&start)).length() < 1e-6);
            // Right is right on screen: the camera's x axis.
            let camera = start.camera(100, 100);
            let screen_right = camera.view().inverse().x_axis.truncate();
            let strafed = fly(start, [0.0, 0.2, 0.0]).eye() - start.eye();
            assert!((strafed - screen_right * 0.2 * start.radius).length() < 1e-5);
            let turned = look(start, 20.0, 0.0);
            assert!(
                (turned.eye() - start.eye()).length() < 1e-5,
                "look keeps the eye"
            );
            let level = Orbit {
                pitch_deg: 0.0,
                ..start
            };
            let angle = forward(&look(level, 20.0, 0.0))
                .angle_between(forward(&level))
                .to_degrees();
            assert!((angle - 20.0).abs() < 0.05, "{angle}");
            // Turning right brings what was right of centre towards the centre.
            assert!(forward(&turned).dot(screen_right) > 0.0);
            let up_turned = look(start, 0.0, 15.0);
            assert!(
                forward(&up_turned).dot(up.apply(glam::Vec3::Y))
                    > forward(&start).dot(up.apply(glam::Vec3::Y))
            );
        }
    }

    #[test]
    fn a_scene_view_refuses_avatar_commands_and_keeps_its_camera() {
        let catalog = scene_catalog();
        let home = catalog.home();
        let mut s = crate::editor::Editor::new(catalog.clone()).state;
        assert_eq!(s.recipe.camera, home, "opens at the framed camera");
        assert_eq!(s.debug.sh_degree, 2, "at the file's SH degree");
        for line in [
            "set-gaussians nose ada",
            "select-group eyes",
            "play",
            "toggle-mesh",
            "save-recipe r.toml",
            "camera-study",
        ] {
            let e = s
                .apply(&catalog, &Command::parse(line).unwrap())
                .unwrap_err();
            assert!(e.contains("scene view"), "{line}: {e}");
        }
        for line in ["fly 1 0 0", "look 10 5", "orbit 20 0", "zoom 0.5"] {
            s.apply(&catalog, &Command::parse(line).unwrap()).unwrap();
        }
        assert_ne!(s.recipe.camera, home);
        // Zoom keeps to the scene's scale, not a head's 0.05-50.
        for _ in 0..10 {
            s.apply(&catalog, &Command::Zoom(10.0)).unwrap();
        }
        assert_eq!(s.recipe.camera.radius, home.radius * 100.0);
        let effects = s.apply(&catalog, &Command::parse("snapshot a.png").unwrap());
        assert_eq!(
            effects.unwrap().effects,
            vec![Effect::Snapshot("a.png".into(), None)]
        );
        s.apply(&catalog, &Command::CameraReset).unwrap();
        assert_eq!(s.recipe.camera, home, "camera-reset returns to the framing");
        // sh-degree cycles down from the file's degree and wraps.
        let mut seen = Vec::new();
        for _ in 0..4 {
            s.apply(&catalog, &Command::ShDegree(None)).unwrap();
            seen.push(s.debug.sh_degree);
        }
        assert_eq!(seen, [1, 0, 2, 1]);
        s.apply(&catalog, &Command::ShDegree(Some(0))).unwrap();
        assert_eq!(s.debug.sh_degree, 0);
        // toggle-floaters hides and shows them again.
        s.apply(&catalog, &Command::ToggleFloaters).unwrap();
        assert!(s.debug.hide_floaters);
        s.apply(&catalog, &Command::ToggleFloaters).unwrap();
        assert!(!s.debug.hide_floaters);
        // lod sets the level of detail; auto is where a view starts.
        assert_eq!(s.debug.lod, LodPolicy::Auto);
        for (line, policy) in [
            ("lod off", LodPolicy::Off),
            ("lod 300k", LodPolicy::Budget(300_000)),
            ("lod auto", LodPolicy::Auto),
        ] {
            s.apply(&catalog, &Command::parse(line).unwrap()).unwrap();
            assert_eq!(s.debug.lod, policy, "{line}");
        }
        assert!(Command::parse("lod lots").is_err() && Command::parse("lod 0").is_err());
    }

    /// A scene drawn from its level-of-detail cache cannot draw every
    /// Gaussian, hide floaters (nothing else of it is in memory): it says so.
    #[test]
    fn a_scene_from_its_cache_refuses_what_needs_it_in_memory() {
        let mut catalog = scene_catalog();
        catalog.scene.as_mut().unwrap().from_cache = true;
        let mut s = crate::editor::Editor::new(catalog.clone()).state;
        for command in [Command::Lod(LodPolicy::Off), Command::ToggleFloaters] {
            let e = s.apply(&catalog, &command).unwrap_err();
            assert!(e.contains("level-of-detail cache"), "{e}");
        }
        assert_eq!(s.debug.lod, LodPolicy::Auto);
        assert!(!s.debug.hide_floaters);
        s.apply(&catalog, &Command::Lod(LodPolicy::Budget(5_000)))
            .unwrap();
        let e = EditorState::new(Recipe::unedited("ada"))
            .apply(&self::catalog(), &Command::Lod(LodPolicy::Off))
            .unwrap_err();
        assert!(e.contains("only a scene view"), "{e}");
    }

    /// An avatar editor has no floaters to hide: the command says so.
    #[test]
    fn toggle_floaters_needs_a_scene_view() {
        let mut s = EditorState::new(Recipe::unedited("ada"));
        let e = s.apply(&catalog(), &Command::ToggleFloaters).unwrap_err();
        assert!(e.contains("only a scene view"), "{e}");
        assert!(!s.debug.hide_floaters);
    }

    fn run(state: &mut EditorState, lines: &[&str]) {
        for l in lines {
            state
                .apply(&catalog(), &Command::parse(l).unwrap())
                .unwrap();
        }
    }

    #[test]
    fn assignment_and_undo_redo() {
        let mut s = EditorState::new(Recipe::unedited("ada"));
        run(
            &mut s,
            &["select-group nose", "select-source bram", "assign"],
        );
        assert_eq!(s.group_edit(Group::Nose).gaussians, "bram");
        run(&mut s, &["orbit 10 0", "undo"]);
        assert_eq!(s.group_edit(Group::Nose).gaussians, "ada");
        assert_eq!(s.recipe.camera.yaw_deg, 10.0, "undo keeps the view");
        run(&mut s, &["redo"]);
        assert_eq!(s.group_edit(Group::Nose).gaussians, "bram");
        assert_eq!(s.history(), (1, 0));
        assert!(s.apply(&catalog(), &Command::Redo).is_err());
        // Undo and redo say what they undid.
        run(&mut s, &["set-shape eyes bram=0.5 ada=0.5"]);
        let said = s.apply(&catalog(), &Command::Undo).unwrap().message;
        assert_eq!(
            said.as_deref(),
            Some("undone: set-shape eyes bram=0.5 ada=0.5")
        );
        let said = s.apply(&catalog(), &Command::Redo).unwrap().message;
        assert_eq!(
            said.as_deref(),
            Some("redone: set-shape eyes bram=0.5 ada=0.5")
        );
    }

    #[test]
    fn shape_weights_stay_convex() {
        let mut s = EditorState::new(Recipe::unedited("ada"));
        run(
            &mut s,
            &["select-source bram", "shape-add 0.3", "shape-add 0.3"],
        );
        let w = s.group_edit(Group::Mouth).shape;
        assert!((w["bram"] - 0.6).abs() < 1e-12 && (w["ada"] - 0.4).abs() < 1e-12);
        run(&mut s, &["shape-add 5"]);
        assert_eq!(
            s.group_edit(Group::Mouth).shape,
            BTreeMap::from([("bram".to_string(), 1.0)])
        );
        run(&mut s, &["shape-add -0.25"]);
        let w = s.group_edit(Group::Mouth).shape;
        assert!((w["bram"] - 0.75).abs() < 1e-12 && (w["ada"] - 0.25).abs() < 1e-12);
    }

    #[test]
    fn failing_commands_change_nothing() {
        let mut s = EditorState::new(Recipe::unedited("ada"));
        let before = s.clone();
        for line in [
            "set-gaussians nose zed",
            "set-shape nose ada=0",
            "motion dance",
            "select-source zed",
            "frame 3",
            "snapshot view.jpg",
            "export-ply scene.obj",
        ] {
            assert!(
                s.apply(&catalog(), &Command::parse(line).unwrap()).is_err(),
                "{line}"
            );
        }
        assert_eq!(s, before);
        // A frame past the motion's end is refused, not wrapped.
        run(&mut s, &["motion talk", "frame 124"]);
        let e = s.apply(&catalog(), &Command::Frame(125)).unwrap_err();
        assert!(e.contains("past the end of talk (frames 0-124)"), "{e}");
        assert_eq!(s.recipe.animation.frame, 124);
    }

    #[test]
    fn playback_wraps_and_study_limits_clamp() {
        let mut s = EditorState::new(Recipe::unedited("ada"));
        run(&mut s, &["motion talk", "frame 124", "play"]);
        s.tick(&catalog());
        assert_eq!(s.recipe.animation.frame, 0);
        run(&mut s, &["step -1"]);
        assert_eq!(s.recipe.animation.frame, 124);
        run(&mut s, &["camera-study", "orbit 100 40", "zoom 3"]);
        assert_eq!(s.recipe.camera.yaw_deg, 45.0);
        assert_eq!(s.recipe.camera.pitch_deg, 15.0);
        assert_eq!(s.recipe.camera.radius, 2.5);
    }
}
