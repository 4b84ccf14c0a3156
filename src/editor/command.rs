//! Every user action is a named command with arguments. Commands parse from
//! and print to one line of text — the form keymaps bind, the `:` prompt takes
//! and session files record.

use std::fmt;

use crate::compose::recipe::{AnimationMode, ColourCorrection, Smoothing};
use crate::model::regions::Group;
use crate::scene::camera::CameraOverrides;

/// A joint the animation panel can offset.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PoseJoint {
    /// The jaw.
    Jaw,
    /// The neck.
    Neck,
    /// Both eyes.
    Eyes,
}

impl PoseJoint {
    fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "jaw" => PoseJoint::Jaw,
            "neck" => PoseJoint::Neck,
            "eyes" => PoseJoint::Eyes,
            _ => return None,
        })
    }

    fn name(self) -> &'static str {
        match self {
            PoseJoint::Jaw => "jaw",
            PoseJoint::Neck => "neck",
            PoseJoint::Eyes => "eyes",
        }
    }
}

/// A named editor command.
#[derive(Clone, Debug, PartialEq)]
pub enum Command {
    /// Leave the editor.
    Quit,
    /// Undo the last edit.
    Undo,
    /// Redo the last undone edit.
    Redo,
    /// Show or hide the key help.
    Help,
    /// Open the `:` command prompt.
    Prompt,
    /// Select a group in the group list.
    SelectGroup(Group),
    /// Move the group cursor down.
    NextGroup,
    /// Move the group cursor up.
    PrevGroup,
    /// Select a source in the source strip.
    SelectSource(String),
    /// Move the source cursor right.
    NextSource,
    /// Move the source cursor left.
    PrevSource,
    /// Show the selected source's Gaussians in the selected group.
    Assign,
    /// Show a source's Gaussians in a group.
    SetGaussians(Group, String),
    /// Set a group's shape weights.
    SetShape(Group, Vec<(String, f64)>),
    /// Add to the selected source's shape weight in the selected group (others scale to keep the sum 1).
    ShapeAdd(f64),
    /// Make a source the base avatar.
    SetBase(String),
    /// Make the selected source the base avatar.
    BaseFromSelected,
    /// Set (or with `None`, cycle) border smoothing.
    Smoothing(Option<Smoothing>),
    /// Set (or with `None`, cycle) colour correction.
    Colour(Option<ColourCorrection>),
    /// Drive the composite with a motion ("rest" for none).
    Motion(String),
    /// Switch to the next motion.
    NextMotion,
    /// Start playing at 25 FPS.
    Play,
    /// Stop playing.
    Pause,
    /// Toggle playing.
    TogglePlay,
    /// Step frames (negative steps back).
    Step(i64),
    /// Go to a frame.
    Frame(usize),
    /// Set (or with `None`, toggle) the animation mode.
    Mode(Option<AnimationMode>),
    /// Add an axis-angle rotation (radians) to a joint.
    Pose(PoseJoint, [f32; 3]),
    /// Add to one of the first five expression components.
    Expression(usize, f32),
    /// Clear all pose and expression offsets.
    ResetPose,
    /// Orbit the camera (degrees of yaw and pitch).
    Orbit(f32, f32),
    /// Multiply the camera distance.
    Zoom(f32),
    /// Back to the default camera.
    CameraReset,
    /// Toggle the thesis study limits (±45° yaw, ±15° pitch, radius 2.5).
    CameraStudy,
    /// Set parts of the camera (target, radius, field of view, up axis, angles).
    SetCamera(CameraOverrides),
    /// Multiply the debug Gaussian scale.
    DebugScale(f32),
    /// Toggle the mesh overlay.
    ToggleMesh,
    /// Toggle highlighting the selected group's regions.
    ToggleHighlight,
    /// Write the recipe to a TOML file.
    SaveRecipe(String),
    /// Write the current frame as a standard 3DGS PLY.
    ExportPly(String),
    /// Write the current view as a PNG.
    Snapshot(String),
}

/// Name, argument synopsis and summary of every command, for help and completion.
pub const COMMANDS: &[(&str, &str, &str)] = &[
    ("quit", "", "leave the editor"),
    ("undo", "", "undo the last edit"),
    ("redo", "", "redo the last undone edit"),
    ("help", "", "show or hide the key help"),
    ("prompt", "", "open the command prompt"),
    ("select-group", "GROUP", "select a group"),
    ("next-group", "", "next group"),
    ("prev-group", "", "previous group"),
    ("select-source", "SOURCE", "select a source"),
    ("next-source", "", "next source"),
    ("prev-source", "", "previous source"),
    (
        "assign",
        "",
        "show the selected source's Gaussians in the selected group",
    ),
    (
        "set-gaussians",
        "GROUP SOURCE",
        "show a source's Gaussians in a group",
    ),
    (
        "set-shape",
        "GROUP SOURCE=W ...",
        "set a group's shape weights",
    ),
    (
        "shape-add",
        "DELTA",
        "add to the selected source's shape weight in the selected group",
    ),
    ("set-base", "SOURCE", "make a source the base avatar"),
    (
        "base-from-selected",
        "",
        "make the selected source the base",
    ),
    (
        "smoothing",
        "[off|thesis|crossfade]",
        "set or cycle border smoothing",
    ),
    (
        "colour",
        "[off|thesis|skin]",
        "set or cycle colour correction",
    ),
    ("motion", "NAME|rest", "drive the composite with a motion"),
    ("next-motion", "", "next motion"),
    ("play", "", "play at 25 FPS"),
    ("pause", "", "stop playing"),
    ("toggle-play", "", "play or pause"),
    ("step", "N", "step N frames"),
    ("frame", "N", "go to frame N"),
    ("mode", "[fast|exact]", "set or toggle the animation mode"),
    (
        "pose",
        "jaw|neck|eyes X Y Z",
        "add a rotation (radians) to a joint",
    ),
    (
        "expression",
        "K DELTA",
        "add to expression component K (1-5)",
    ),
    ("reset-pose", "", "clear pose and expression offsets"),
    ("orbit", "DYAW DPITCH", "orbit the camera (degrees)"),
    ("zoom", "FACTOR", "multiply the camera distance"),
    ("camera-reset", "", "back to the default camera"),
    ("camera-study", "", "toggle the thesis study camera limits"),
    (
        "set-camera",
        "yaw=D pitch=D radius=R fov=D target=X,Y,Z up=+y|-y|+z|-z",
        "set parts of the camera",
    ),
    (
        "debug-scale",
        "FACTOR",
        "multiply the Gaussian scale (debug view)",
    ),
    ("toggle-mesh", "", "toggle the mesh overlay"),
    (
        "toggle-highlight",
        "",
        "toggle highlighting the selected group",
    ),
    ("save-recipe", "PATH", "write the recipe as TOML"),
    (
        "export-ply",
        "PATH",
        "write the current frame as a 3DGS PLY",
    ),
    ("snapshot", "PATH", "write the current view as a PNG"),
];

fn number<T: std::str::FromStr>(s: Option<&str>, what: &str) -> Result<T, String> {
    let s = s.ok_or_else(|| format!("missing {what}"))?;
    s.parse()
        .map_err(|_| format!("'{}' is not a valid {what}", crate::text::printable(s)))
}

fn finite(x: f64, what: &str) -> Result<f64, String> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("{what} must be finite"))
    }
}

fn group(s: Option<&str>) -> Result<Group, String> {
    let s = s.ok_or("missing group")?;
    Group::from_name(s).ok_or_else(|| {
        format!(
            "unknown group '{}' (groups: {})",
            crate::text::printable(s),
            Group::ALL.map(Group::name).join(", ")
        )
    })
}

fn word(s: Option<&str>, what: &str) -> Result<String, String> {
    s.map(str::to_string)
        .ok_or_else(|| format!("missing {what}"))
}

impl Command {
    /// Parses one command line, e.g. `set-gaussians nose bram`.
    pub fn parse(line: &str) -> Result<Command, String> {
        let mut it = line.split_whitespace();
        let name = it.next().ok_or("empty command")?;
        let mut arg = || it.next();
        let cmd = match name {
            "quit" => Command::Quit,
            "undo" => Command::Undo,
            "redo" => Command::Redo,
            "help" => Command::Help,
            "prompt" => Command::Prompt,
            "select-group" => Command::SelectGroup(group(arg())?),
            "next-group" => Command::NextGroup,
            "prev-group" => Command::PrevGroup,
            "select-source" => Command::SelectSource(word(arg(), "source")?),
            "next-source" => Command::NextSource,
            "prev-source" => Command::PrevSource,
            "assign" => Command::Assign,
            "set-gaussians" => {
                let g = group(arg())?;
                Command::SetGaussians(g, word(arg(), "source")?)
            }
            "set-shape" => {
                let g = group(arg())?;
                let mut weights = Vec::new();
                for pair in it.by_ref() {
                    let (src, w) = pair.split_once('=').ok_or_else(|| {
                        format!("'{}' is not SOURCE=WEIGHT", crate::text::printable(pair))
                    })?;
                    weights.push((
                        src.to_string(),
                        finite(number(Some(w), "weight")?, "a weight")?,
                    ));
                }
                if weights.is_empty() {
                    return Err("set-shape needs at least one SOURCE=WEIGHT".into());
                }
                Command::SetShape(g, weights)
            }
            "shape-add" => {
                Command::ShapeAdd(finite(number(arg(), "weight change")?, "the change")?)
            }
            "set-base" => Command::SetBase(word(arg(), "source")?),
            "base-from-selected" => Command::BaseFromSelected,
            "smoothing" => Command::Smoothing(match arg() {
                None => None,
                Some("off") => Some(Smoothing::Off),
                Some("thesis") => Some(Smoothing::Thesis),
                Some("crossfade") => Some(Smoothing::Crossfade),
                Some(o) => {
                    return Err(format!(
                        "smoothing is off, thesis or crossfade, not '{}'",
                        crate::text::printable(o)
                    ))
                }
            }),
            "colour" | "color" => Command::Colour(match arg() {
                None => None,
                Some("off") => Some(ColourCorrection::Off),
                Some("thesis") => Some(ColourCorrection::Thesis),
                Some("skin") => Some(ColourCorrection::Skin),
                Some(o) => {
                    return Err(format!(
                        "colour is off, thesis or skin, not '{}'",
                        crate::text::printable(o)
                    ))
                }
            }),
            "motion" => Command::Motion(word(arg(), "motion")?),
            "next-motion" => Command::NextMotion,
            "play" => Command::Play,
            "pause" => Command::Pause,
            "toggle-play" => Command::TogglePlay,
            "step" => Command::Step(number(arg(), "frame count")?),
            "frame" => Command::Frame(number(arg(), "frame")?),
            "mode" => Command::Mode(match arg() {
                None => None,
                Some("fast") => Some(AnimationMode::Fast),
                Some("exact") => Some(AnimationMode::Exact),
                Some(o) => {
                    return Err(format!(
                        "mode is fast or exact, not '{}'",
                        crate::text::printable(o)
                    ))
                }
            }),
            "pose" => {
                let j = arg().ok_or("missing joint")?;
                let joint = PoseJoint::parse(j).ok_or_else(|| {
                    format!(
                        "pose takes jaw, neck or eyes, not '{}'",
                        crate::text::printable(j)
                    )
                })?;
                let mut v = [0.0f32; 3];
                for x in &mut v {
                    *x = finite(number::<f64>(arg(), "angle")?, "an angle")? as f32;
                }
                Command::Pose(joint, v)
            }
            "expression" => {
                let k: usize = number(arg(), "component")?;
                if !(1..=5).contains(&k) {
                    return Err(format!("expression components are 1 to 5, not {k}"));
                }
                Command::Expression(
                    k,
                    finite(number::<f64>(arg(), "amount")?, "the amount")? as f32,
                )
            }
            "reset-pose" => Command::ResetPose,
            "orbit" => {
                let yaw = finite(number(arg(), "yaw")?, "yaw")? as f32;
                Command::Orbit(yaw, finite(number(arg(), "pitch")?, "pitch")? as f32)
            }
            "zoom" => {
                let f: f64 = finite(number(arg(), "zoom factor")?, "the factor")?;
                if f <= 0.0 {
                    return Err("zoom factor must be positive".into());
                }
                Command::Zoom(f as f32)
            }
            "camera-reset" => Command::CameraReset,
            "camera-study" => Command::CameraStudy,
            "set-camera" => Command::SetCamera(CameraOverrides::parse(it.by_ref())?),
            "debug-scale" => {
                let f: f64 = finite(number(arg(), "scale factor")?, "the factor")?;
                if f <= 0.0 {
                    return Err("scale factor must be positive".into());
                }
                Command::DebugScale(f as f32)
            }
            "toggle-mesh" => Command::ToggleMesh,
            "toggle-highlight" => Command::ToggleHighlight,
            "save-recipe" => Command::SaveRecipe(word(arg(), "path")?),
            "export-ply" => Command::ExportPly(word(arg(), "path")?),
            "snapshot" => Command::Snapshot(word(arg(), "path")?),
            other => {
                return Err(format!(
                    "unknown command '{}' (type ? for help)",
                    crate::text::printable(other)
                ))
            }
        };
        if let Some(extra) = it.next() {
            return Err(format!(
                "{name}: unexpected argument '{}'",
                crate::text::printable(extra)
            ));
        }
        Ok(cmd)
    }

    /// Whether the command changes the composite (and so is undoable).
    pub fn is_edit(&self) -> bool {
        matches!(
            self,
            Command::Assign
                | Command::SetGaussians(..)
                | Command::SetShape(..)
                | Command::ShapeAdd(_)
                | Command::SetBase(_)
                | Command::BaseFromSelected
                | Command::Smoothing(_)
                | Command::Colour(_)
                | Command::Motion(_)
                | Command::NextMotion
                | Command::Mode(_)
                | Command::Pose(..)
                | Command::Expression(..)
                | Command::ResetPose
        )
    }
}

impl fmt::Display for Command {
    /// The canonical text form; `Command::parse` reads it back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let lower = |d: &dyn fmt::Debug| format!("{d:?}").to_lowercase();
        match self {
            Command::Quit => write!(f, "quit"),
            Command::Undo => write!(f, "undo"),
            Command::Redo => write!(f, "redo"),
            Command::Help => write!(f, "help"),
            Command::Prompt => write!(f, "prompt"),
            Command::SelectGroup(g) => write!(f, "select-group {}", g.name()),
            Command::NextGroup => write!(f, "next-group"),
            Command::PrevGroup => write!(f, "prev-group"),
            Command::SelectSource(s) => write!(f, "select-source {s}"),
            Command::NextSource => write!(f, "next-source"),
            Command::PrevSource => write!(f, "prev-source"),
            Command::Assign => write!(f, "assign"),
            Command::SetGaussians(g, s) => write!(f, "set-gaussians {} {s}", g.name()),
            Command::SetShape(g, w) => {
                write!(f, "set-shape {}", g.name())?;
                for (s, x) in w {
                    write!(f, " {s}={x}")?;
                }
                Ok(())
            }
            Command::ShapeAdd(d) => write!(f, "shape-add {d}"),
            Command::SetBase(s) => write!(f, "set-base {s}"),
            Command::BaseFromSelected => write!(f, "base-from-selected"),
            Command::Smoothing(None) => write!(f, "smoothing"),
            Command::Smoothing(Some(s)) => write!(f, "smoothing {}", lower(s)),
            Command::Colour(None) => write!(f, "colour"),
            Command::Colour(Some(c)) => write!(f, "colour {}", lower(c)),
            Command::Motion(m) => write!(f, "motion {m}"),
            Command::NextMotion => write!(f, "next-motion"),
            Command::Play => write!(f, "play"),
            Command::Pause => write!(f, "pause"),
            Command::TogglePlay => write!(f, "toggle-play"),
            Command::Step(n) => write!(f, "step {n}"),
            Command::Frame(n) => write!(f, "frame {n}"),
            Command::Mode(None) => write!(f, "mode"),
            Command::Mode(Some(m)) => write!(f, "mode {}", lower(m)),
            Command::Pose(j, v) => write!(f, "pose {} {} {} {}", j.name(), v[0], v[1], v[2]),
            Command::Expression(k, d) => write!(f, "expression {k} {d}"),
            Command::ResetPose => write!(f, "reset-pose"),
            Command::Orbit(y, p) => write!(f, "orbit {y} {p}"),
            Command::Zoom(z) => write!(f, "zoom {z}"),
            Command::CameraReset => write!(f, "camera-reset"),
            Command::CameraStudy => write!(f, "camera-study"),
            Command::SetCamera(o) => write!(f, "set-camera {o}"),
            Command::DebugScale(s) => write!(f, "debug-scale {s}"),
            Command::ToggleMesh => write!(f, "toggle-mesh"),
            Command::ToggleHighlight => write!(f, "toggle-highlight"),
            Command::SaveRecipe(p) => write!(f, "save-recipe {p}"),
            Command::ExportPly(p) => write!(f, "export-ply {p}"),
            Command::Snapshot(p) => write!(f, "snapshot {p}"),
        }
    }
}

/// Command names starting with `prefix` (for prompt completion).
pub fn complete(prefix: &str) -> Vec<&'static str> {
    COMMANDS
        .iter()
        .map(|(n, _, _)| *n)
        .filter(|n| n.starts_with(prefix))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_command_round_trips_through_text() {
        let samples = [
            "quit",
            "undo",
            "redo",
            "help",
            "prompt",
            "select-group eyes",
            "next-group",
            "prev-group",
            "select-source bram",
            "next-source",
            "prev-source",
            "assign",
            "set-gaussians nose bram",
            "set-shape nose bram=0.7 ada=0.3",
            "shape-add -0.1",
            "set-base cleo",
            "base-from-selected",
            "smoothing",
            "smoothing crossfade",
            "colour skin",
            "colour",
            "motion talk",
            "next-motion",
            "play",
            "pause",
            "toggle-play",
            "step -3",
            "frame 40",
            "mode exact",
            "mode",
            "pose jaw 0.1 0 0",
            "expression 2 0.25",
            "reset-pose",
            "orbit -5 2.5",
            "zoom 0.9",
            "camera-reset",
            "camera-study",
            "set-camera target=0,0.1,-0.25 radius=3 fov=20 up=-y yaw=-30 pitch=5",
            "debug-scale 0.5",
            "toggle-mesh",
            "toggle-highlight",
            "save-recipe out.toml",
            "export-ply out.ply",
            "snapshot view.png",
        ];
        for s in samples {
            let c = Command::parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
            assert_eq!(Command::parse(&c.to_string()).unwrap(), c, "{s}");
        }
        let names: std::collections::HashSet<_> = samples
            .iter()
            .map(|s| s.split(' ').next().unwrap())
            .collect();
        for (name, _, _) in COMMANDS {
            assert!(names.contains(name), "{name} has no round-trip sample");
        }
    }

    #[test]
    fn bad_commands_explain_themselves() {
        for (line, needle) in [
            ("", "empty"),
            ("fly", "unknown command"),
            ("select-group forehead", "unknown group"),
            ("set-shape nose bram", "SOURCE=WEIGHT"),
            ("set-shape nose bram=x", "not a valid weight"),
            ("zoom -1", "positive"),
            ("expression 9 1", "1 to 5"),
            ("pose knee 0 0 0", "jaw, neck or eyes"),
            ("undo now", "unexpected argument"),
            ("shape-add NaN", "finite"),
            ("set-camera", "no camera setting"),
            ("set-camera radius=-1", "positive"),
            ("set-camera up=sideways", "+y, -y"),
        ] {
            let e = Command::parse(line).unwrap_err();
            assert!(e.contains(needle), "{line}: {e}");
        }
    }

    #[test]
    fn completion_lists_matching_names() {
        assert_eq!(complete("sna"), vec!["snapshot"]);
        assert!(complete("set-").len() >= 3);
    }
}
