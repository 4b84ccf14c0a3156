//! Editor state and its update function: `apply(command)` is the only way the
//! state changes, so sessions replay exactly and undo covers every edit.

use std::collections::BTreeMap;

use crate::compose::recipe::{AnimationMode, ColourCorrection, GroupEdit, Recipe, Smoothing};
use crate::model::regions::Group;
use crate::pipeline::workbench::DebugView;
use crate::scene::camera::Orbit;

use super::command::{Command, PoseJoint};

/// Names the editor validates commands against.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Catalog {
    /// Source names, in display order.
    pub sources: Vec<String>,
    /// Motion names and frame counts.
    pub motions: Vec<(String, usize)>,
}

impl Catalog {
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
    /// Write the current frame as a PLY.
    ExportPly(String),
    /// Write the current view as a PNG.
    Snapshot(String),
}

/// The whole editor state.
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
    /// Key help overlay shown.
    pub help: bool,
    /// The `:` prompt's text when open.
    pub prompt: Option<String>,
    /// Last message for the status line.
    pub status: String,
    /// The user asked to quit.
    pub quit: bool,
    undo: Vec<Recipe>,
    redo: Vec<Recipe>,
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
            help: false,
            prompt: None,
            status: String::new(),
            quit: false,
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
    /// nothing and returns the reason.
    pub fn apply(&mut self, catalog: &Catalog, command: &Command) -> Result<Vec<Effect>, String> {
        if command.is_edit() {
            let before = self.recipe.clone();
            match self.update(catalog, command) {
                Ok(effects) => {
                    if self.recipe != before {
                        self.undo.push(before);
                        if self.undo.len() > UNDO_LIMIT {
                            self.undo.remove(0);
                        }
                        self.redo.clear();
                    }
                    Ok(effects)
                }
                Err(e) => {
                    self.recipe = before;
                    Err(e)
                }
            }
        } else {
            self.update(catalog, command)
        }
    }

    /// Restores an older recipe but keeps the view: camera and frame stay.
    fn restore(&mut self, mut recipe: Recipe) {
        recipe.camera = self.recipe.camera;
        recipe.animation.frame = self.recipe.animation.frame;
        self.recipe = recipe;
    }

    fn update(&mut self, catalog: &Catalog, command: &Command) -> Result<Vec<Effect>, String> {
        let n_sources = catalog.sources.len().max(1);
        let frames = catalog.frames(&self.recipe.animation.motion);
        match command {
            Command::Quit => self.quit = true,
            Command::Undo => match self.undo.pop() {
                Some(r) => {
                    self.redo.push(self.recipe.clone());
                    self.restore(r);
                    self.status = "undone".into();
                }
                None => return Err("nothing to undo".into()),
            },
            Command::Redo => match self.redo.pop() {
                Some(r) => {
                    self.undo.push(self.recipe.clone());
                    self.restore(r);
                    self.status = "redone".into();
                }
                None => return Err("nothing to redo".into()),
            },
            Command::Help => self.help = !self.help,
            Command::Prompt => self.prompt = Some(String::new()),
            Command::SelectGroup(g) => self.group = g.index(),
            Command::NextGroup => self.group = (self.group + 1) % Group::COUNT,
            Command::PrevGroup => self.group = (self.group + Group::COUNT - 1) % Group::COUNT,
            Command::SelectSource(s) => self.source = catalog.source(s)?,
            Command::NextSource => self.source = (self.source + 1) % n_sources,
            Command::PrevSource => self.source = (self.source + n_sources - 1) % n_sources,
            Command::Assign => {
                let name = catalog
                    .sources
                    .get(self.source)
                    .cloned()
                    .ok_or("no sources")?;
                self.assign(self.selected_group(), name);
            }
            Command::SetGaussians(g, s) => {
                catalog.source(s)?;
                self.assign(*g, s.clone());
            }
            Command::SetShape(g, weights) => {
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
                shape.values_mut().for_each(|w| *w /= sum);
                let mut edit = self.group_edit(*g);
                edit.shape = shape;
                self.set_group_edit(*g, edit);
            }
            Command::ShapeAdd(delta) => {
                let source = catalog
                    .sources
                    .get(self.source)
                    .cloned()
                    .ok_or("no sources")?;
                let g = self.selected_group();
                let mut edit = self.group_edit(g);
                edit.shape = add_weight(&edit.shape, &source, *delta, &self.recipe.base);
                self.set_group_edit(g, edit);
            }
            Command::SetBase(s) => {
                catalog.source(s)?;
                self.recipe.base = s.clone();
            }
            Command::BaseFromSelected => {
                self.recipe.base = catalog
                    .sources
                    .get(self.source)
                    .cloned()
                    .ok_or("no sources")?;
            }
            Command::Smoothing(s) => {
                self.recipe.post.smoothing = s.unwrap_or(match self.recipe.post.smoothing {
                    Smoothing::Off => Smoothing::Thesis,
                    Smoothing::Thesis => Smoothing::Crossfade,
                    Smoothing::Crossfade => Smoothing::Off,
                })
            }
            Command::Colour(c) => {
                self.recipe.post.colour = c.unwrap_or(match self.recipe.post.colour {
                    ColourCorrection::Off => ColourCorrection::Thesis,
                    ColourCorrection::Thesis => ColourCorrection::Skin,
                    ColourCorrection::Skin => ColourCorrection::Off,
                })
            }
            Command::Motion(m) => {
                if m != "rest" && !catalog.motions.iter().any(|(n, _)| n == m) {
                    return Err(format!("unknown motion '{}'", crate::text::printable(m)));
                }
                self.recipe.animation.motion = m.clone();
                self.recipe.animation.frame %= catalog.frames(m);
            }
            Command::NextMotion => {
                let names: Vec<&str> = std::iter::once("rest")
                    .chain(catalog.motions.iter().map(|(n, _)| n.as_str()))
                    .collect();
                let i = names
                    .iter()
                    .position(|n| *n == self.recipe.animation.motion)
                    .unwrap_or(0);
                let next = names[(i + 1) % names.len()].to_string();
                self.recipe.animation.frame %= catalog.frames(&next);
                self.recipe.animation.motion = next;
            }
            Command::Play => self.playing = true,
            Command::Pause => self.playing = false,
            Command::TogglePlay => self.playing = !self.playing,
            Command::Step(n) => {
                let f = self.recipe.animation.frame as i64 + n;
                self.recipe.animation.frame = f.rem_euclid(frames as i64) as usize;
            }
            Command::Frame(n) => self.recipe.animation.frame = n % frames,
            Command::Mode(m) => {
                self.recipe.animation.mode = m.unwrap_or(match self.recipe.animation.mode {
                    AnimationMode::Fast => AnimationMode::Exact,
                    AnimationMode::Exact => AnimationMode::Fast,
                })
            }
            Command::Pose(joint, d) => {
                let o = &mut self.recipe.animation.offsets;
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
                let e = &mut self.recipe.animation.offsets.expression[k - 1];
                *e = (*e + d).clamp(-3.0, 3.0);
            }
            Command::ResetPose => self.recipe.animation.offsets = Default::default(),
            Command::Orbit(dy, dp) => {
                let c = &mut self.recipe.camera;
                c.yaw_deg = (c.yaw_deg + dy + 180.0).rem_euclid(360.0) - 180.0;
                c.pitch_deg = (c.pitch_deg + dp).clamp(-89.0, 89.0);
                self.clamp_study();
            }
            Command::Zoom(f) => {
                let c = &mut self.recipe.camera;
                c.radius = (c.radius * f).clamp(0.05, 50.0);
                self.clamp_study();
            }
            Command::CameraReset => {
                self.recipe.camera = Orbit::default();
                self.study = false;
            }
            Command::CameraStudy => {
                self.study = !self.study;
                if self.study {
                    self.recipe.camera = Orbit::STUDY;
                }
                self.status = format!(
                    "study camera limits {}",
                    if self.study { "on" } else { "off" }
                );
            }
            Command::SetCamera(o) => {
                self.recipe.camera = o.apply(self.recipe.camera);
                self.clamp_study();
            }
            Command::DebugScale(f) => self.debug.scale = (self.debug.scale * f).clamp(0.01, 10.0),
            Command::ToggleMesh => self.debug.mesh = !self.debug.mesh,
            Command::ToggleHighlight => self.debug.highlight = !self.debug.highlight,
            Command::SaveRecipe(p) => return Ok(vec![Effect::SaveRecipe(p.clone())]),
            Command::ExportPly(p) => return Ok(vec![Effect::ExportPly(p.clone())]),
            Command::Snapshot(p) => return Ok(vec![Effect::Snapshot(p.clone())]),
        }
        Ok(Vec::new())
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
        }
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
        ] {
            assert!(
                s.apply(&catalog(), &Command::parse(line).unwrap()).is_err(),
                "{line}"
            );
        }
        assert_eq!(s, before);
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
