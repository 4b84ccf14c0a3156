//! Every user action is a named command with arguments, declared once in the
//! [`commands!`] table below: its variant and typed arguments, its name (and
//! aliases), argument synopsis, one-line summary, and whether it edits the
//! composite (undoable) or stays out of session journals (`local`). From that
//! one table come the `Command` enum, the parser, the canonical text form
//! (what keymaps bind, the `:` prompt takes and session files record), the
//! `:` completion, the help overlay's command list and the check that the
//! README lists every command. Adding a command is one entry here, its
//! behaviour in `EditorState::apply`, and a keymap line if it gets a key.

use std::fmt;
use std::iter::Peekable;
use std::str::SplitWhitespace;

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

/// What the table declares about a command.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CommandSpec {
    /// Name, as typed and recorded.
    pub name: &'static str,
    /// Other names the parser accepts.
    pub aliases: &'static [&'static str],
    /// Argument synopsis for help.
    pub synopsis: &'static str,
    /// One-line summary.
    pub summary: &'static str,
    /// Changes the composite (undoable, counted as an edit).
    pub edit: bool,
    /// Recorded in session journals (`quit`, `help` and `prompt` are not).
    pub journal: bool,
    /// Needs an avatar database (edits, groups, sources, animation, the mesh):
    /// a scene view (`visage view FILE`) refuses it.
    pub avatar: bool,
}

/// The words of a command line after its name.
pub type Words<'a> = Peekable<SplitWhitespace<'a>>;

/// How one argument reads from words and writes back to them.
trait ArgKind {
    /// The argument's value in the command.
    type Value;
    /// Reads the argument; `what` names it in messages.
    fn parse(words: &mut Words, what: &str) -> Result<Self::Value, String>;
    /// Appends the argument's words (none for an absent optional).
    fn write(value: &Self::Value, out: &mut Vec<String>);
}

fn next_word<'a>(words: &mut Words<'a>, what: &str) -> Result<&'a str, String> {
    words.next().ok_or_else(|| format!("missing {what}"))
}

fn number<T: std::str::FromStr>(word: &str, what: &str) -> Result<T, String> {
    word.parse()
        .map_err(|_| format!("'{}' is not a valid {what}", crate::text::printable(word)))
}

fn finite(word: &str, what: &str) -> Result<f64, String> {
    let x: f64 = number(word, what)?;
    if x.is_finite() {
        Ok(x)
    } else {
        Err(format!("{what} must be finite"))
    }
}

/// One word: a source, motion or path.
struct Word;
impl ArgKind for Word {
    type Value = String;
    fn parse(words: &mut Words, what: &str) -> Result<String, String> {
        next_word(words, what).map(str::to_string)
    }
    fn write(value: &String, out: &mut Vec<String>) {
        out.push(value.clone());
    }
}

/// A group name.
struct GroupName;
impl ArgKind for GroupName {
    type Value = Group;
    fn parse(words: &mut Words, _: &str) -> Result<Group, String> {
        let s = next_word(words, "group")?;
        Group::from_name(s).ok_or_else(|| {
            format!(
                "unknown group '{}' (groups: {})",
                crate::text::printable(s),
                Group::ALL.map(Group::name).join(", ")
            )
        })
    }
    fn write(value: &Group, out: &mut Vec<String>) {
        out.push(value.name().to_string());
    }
}

/// A finite number, kept as f32.
struct Finite;
impl ArgKind for Finite {
    type Value = f32;
    fn parse(words: &mut Words, what: &str) -> Result<f32, String> {
        Ok(finite(next_word(words, what)?, what)? as f32)
    }
    fn write(value: &f32, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// A finite number, kept as f64.
struct Finite64;
impl ArgKind for Finite64 {
    type Value = f64;
    fn parse(words: &mut Words, what: &str) -> Result<f64, String> {
        finite(next_word(words, what)?, what)
    }
    fn write(value: &f64, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// A positive finite factor.
struct Positive;
impl ArgKind for Positive {
    type Value = f32;
    fn parse(words: &mut Words, what: &str) -> Result<f32, String> {
        let x = finite(next_word(words, what)?, what)?;
        if x <= 0.0 {
            return Err(format!("{what} must be positive"));
        }
        Ok(x as f32)
    }
    fn write(value: &f32, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// A whole number of frames (negative steps back).
struct Integer;
impl ArgKind for Integer {
    type Value = i64;
    fn parse(words: &mut Words, what: &str) -> Result<i64, String> {
        number(next_word(words, what)?, what)
    }
    fn write(value: &i64, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// A frame index.
struct Index;
impl ArgKind for Index {
    type Value = usize;
    fn parse(words: &mut Words, what: &str) -> Result<usize, String> {
        number(next_word(words, what)?, what)
    }
    fn write(value: &usize, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// One of the first five expression components (1-5).
struct ExpressionSlot;
impl ArgKind for ExpressionSlot {
    type Value = usize;
    fn parse(words: &mut Words, what: &str) -> Result<usize, String> {
        let k: usize = number(next_word(words, what)?, what)?;
        if !(1..=5).contains(&k) {
            return Err(format!("expression components are 1 to 5, not {k}"));
        }
        Ok(k)
    }
    fn write(value: &usize, out: &mut Vec<String>) {
        out.push(value.to_string());
    }
}

/// A joint of the animation panel.
struct Joint;
impl ArgKind for Joint {
    type Value = PoseJoint;
    fn parse(words: &mut Words, _: &str) -> Result<PoseJoint, String> {
        let j = next_word(words, "joint")?;
        Ok(match j {
            "jaw" => PoseJoint::Jaw,
            "neck" => PoseJoint::Neck,
            "eyes" => PoseJoint::Eyes,
            _ => {
                return Err(format!(
                    "pose takes jaw, neck or eyes, not '{}'",
                    crate::text::printable(j)
                ))
            }
        })
    }
    fn write(value: &PoseJoint, out: &mut Vec<String>) {
        out.push(
            match value {
                PoseJoint::Jaw => "jaw",
                PoseJoint::Neck => "neck",
                PoseJoint::Eyes => "eyes",
            }
            .to_string(),
        );
    }
}

/// An optional SH degree, 0 to 3.
struct Degree;
impl ArgKind for Degree {
    type Value = Option<u8>;
    fn parse(words: &mut Words, what: &str) -> Result<Option<u8>, String> {
        let Some(word) = words.next() else {
            return Ok(None);
        };
        let d: u8 = number(word, what)?;
        if d > 3 {
            return Err(format!("SH degrees are 0 to 3, not {d}"));
        }
        Ok(Some(d))
    }
    fn write(value: &Option<u8>, out: &mut Vec<String>) {
        out.extend(value.map(|d| d.to_string()));
    }
}

/// Three finite angles (radians).
struct Angles;
impl ArgKind for Angles {
    type Value = [f32; 3];
    fn parse(words: &mut Words, _: &str) -> Result<[f32; 3], String> {
        let mut v = [0.0f32; 3];
        for x in &mut v {
            *x = finite(next_word(words, "angle")?, "an angle")? as f32;
        }
        Ok(v)
    }
    fn write(value: &[f32; 3], out: &mut Vec<String>) {
        out.extend(value.iter().map(f32::to_string));
    }
}

/// `SOURCE=WEIGHT` pairs: the rest of the line, at least one.
struct Weights;
impl ArgKind for Weights {
    type Value = Vec<(String, f64)>;
    fn parse(words: &mut Words, _: &str) -> Result<Vec<(String, f64)>, String> {
        let mut weights = Vec::new();
        for pair in words.by_ref() {
            let (src, w) = pair.split_once('=').ok_or_else(|| {
                format!("'{}' is not SOURCE=WEIGHT", crate::text::printable(pair))
            })?;
            weights.push((src.to_string(), finite(w, "weight")?));
        }
        if weights.is_empty() {
            return Err("set-shape needs at least one SOURCE=WEIGHT".into());
        }
        Ok(weights)
    }
    fn write(value: &Vec<(String, f64)>, out: &mut Vec<String>) {
        out.extend(value.iter().map(|(s, w)| format!("{s}={w}")));
    }
}

/// `key=value` camera settings: the rest of the line.
struct CameraSettings;
impl ArgKind for CameraSettings {
    type Value = CameraOverrides;
    fn parse(words: &mut Words, _: &str) -> Result<CameraOverrides, String> {
        CameraOverrides::parse(words.by_ref())
    }
    fn write(value: &CameraOverrides, out: &mut Vec<String>) {
        out.extend(value.to_string().split(' ').map(str::to_string));
    }
}

/// Options named by a word, for `[a|b|c]` arguments that may be left out.
trait Named: Copy + PartialEq + 'static {
    /// Every option with its name.
    const NAMES: &'static [(Self, &'static str)];
    /// What the option sets, for messages.
    const LABEL: &'static str;
}

impl Named for Smoothing {
    const NAMES: &'static [(Self, &'static str)] = &[
        (Smoothing::Off, "off"),
        (Smoothing::Thesis, "thesis"),
        (Smoothing::Crossfade, "crossfade"),
    ];
    const LABEL: &'static str = "smoothing";
}

impl Named for ColourCorrection {
    const NAMES: &'static [(Self, &'static str)] = &[
        (ColourCorrection::Off, "off"),
        (ColourCorrection::Thesis, "thesis"),
        (ColourCorrection::Skin, "skin"),
    ];
    const LABEL: &'static str = "colour";
}

impl Named for AnimationMode {
    const NAMES: &'static [(Self, &'static str)] = &[
        (AnimationMode::Fast, "fast"),
        (AnimationMode::Exact, "exact"),
    ];
    const LABEL: &'static str = "mode";
}

/// An optional named option (left out: cycle or toggle).
struct Choice<T>(std::marker::PhantomData<T>);
impl<T: Named> ArgKind for Choice<T> {
    type Value = Option<T>;
    fn parse(words: &mut Words, _: &str) -> Result<Option<T>, String> {
        let Some(word) = words.next() else {
            return Ok(None);
        };
        T::NAMES
            .iter()
            .find(|(_, n)| *n == word)
            .map(|(v, _)| Some(*v))
            .ok_or_else(|| {
                let names: Vec<&str> = T::NAMES.iter().map(|(_, n)| *n).collect();
                let (last, rest) = names.split_last().expect("options exist");
                format!(
                    "{} is {} or {last}, not '{}'",
                    T::LABEL,
                    rest.join(", "),
                    crate::text::printable(word)
                )
            })
    }
    fn write(value: &Option<T>, out: &mut Vec<String>) {
        if let Some(v) = value {
            let name = T::NAMES.iter().find(|(o, _)| o == v).map_or("", |(_, n)| n);
            out.push(name.to_string());
        }
    }
}

/// Whether a flag is among an entry's flags.
macro_rules! has_flag {
    ($want:ident) => { false };
    (edit, edit $(, $rest:ident)*) => { true };
    (local, local $(, $rest:ident)*) => { true };
    (avatar, avatar $(, $rest:ident)*) => { true };
    ($want:ident, $first:ident $(, $rest:ident)*) => { has_flag!($want $(, $rest)*) };
}

/// Declares every command once; see the module documentation.
macro_rules! commands {
    ($(
        $(#[doc = $doc:expr])*
        $variant:ident $( ( $( $field:ident : $ty:ty as $kind:ty ),+ ) )?
            => $name:literal $(| $alias:literal)*, $synopsis:literal, $summary:literal $(, $flag:ident)* ;
    )*) => {
        /// A named editor command.
        #[derive(Clone, Debug, PartialEq)]
        pub enum Command {
            $( $(#[doc = $doc])* $variant $( ( $( $ty ),+ ) )?, )*
        }

        /// Every command, in the order of the table.
        pub const COMMANDS: &[CommandSpec] = &[
            $( CommandSpec {
                name: $name,
                aliases: &[$($alias),*],
                synopsis: $synopsis,
                summary: $summary,
                edit: has_flag!(edit $(, $flag)*),
                journal: !has_flag!(local $(, $flag)*),
                avatar: has_flag!(avatar $(, $flag)*) || has_flag!(edit $(, $flag)*),
            }, )*
        ];

        impl Command {
            /// Reads the arguments of the command called `name`.
            fn parse_arguments(name: &str, words: &mut Words) -> Result<Command, String> {
                Ok(match name {
                    $( $name $(| $alias)* => Command::$variant $( ( $(
                        <$kind as ArgKind>::parse(words, stringify!($field))?
                    ),+ ) )?, )*
                    other => {
                        return Err(format!(
                            "unknown command '{}' (type ? for help)",
                            crate::text::printable(other)
                        ))
                    }
                })
            }

            /// The table entry of this command.
            pub fn spec(&self) -> &'static CommandSpec {
                let name = match self {
                    $( Command::$variant { .. } => $name, )*
                };
                COMMANDS
                    .iter()
                    .find(|s| s.name == name)
                    .expect("every variant is in the table")
            }

            /// The argument words of the canonical text form.
            fn argument_words(&self) -> Vec<String> {
                let mut out = Vec::new();
                match self {
                    $( Command::$variant $( ( $( $field ),+ ) )? => {
                        $( $( <$kind as ArgKind>::write($field, &mut out); )+ )?
                    } )*
                }
                out
            }
        }
    };
}

commands! {
    /// Leave the editor.
    Quit => "quit", "", "leave the editor", local;
    /// Undo the last edit.
    Undo => "undo", "", "undo the last edit";
    /// Redo the last undone edit.
    Redo => "redo", "", "redo the last undone edit";
    /// Show or hide the key help.
    Help => "help", "", "show or hide the key help", local;
    /// Open the `:` command prompt.
    Prompt => "prompt", "", "open the command prompt", local;
    /// Select a group in the group list.
    SelectGroup(group: Group as GroupName) => "select-group", "GROUP", "select a group", avatar;
    /// Move the group cursor down.
    NextGroup => "next-group", "", "next group", avatar;
    /// Move the group cursor up.
    PrevGroup => "prev-group", "", "previous group", avatar;
    /// Select a source in the source strip.
    SelectSource(source: String as Word) => "select-source", "SOURCE", "select a source", avatar;
    /// Move the source cursor right.
    NextSource => "next-source", "", "next source", avatar;
    /// Move the source cursor left.
    PrevSource => "prev-source", "", "previous source", avatar;
    /// Show the selected source's Gaussians in the selected group.
    Assign => "assign", "", "show the selected source's Gaussians in the selected group", edit;
    /// Show a source's Gaussians in a group.
    SetGaussians(group: Group as GroupName, source: String as Word)
        => "set-gaussians", "GROUP SOURCE", "show a source's Gaussians in a group", edit;
    /// Set a group's shape weights.
    SetShape(group: Group as GroupName, weights: Vec<(String, f64)> as Weights)
        => "set-shape", "GROUP SOURCE=W ...", "set a group's shape weights", edit;
    /// Add to the selected source's shape weight in the selected group (others scale to keep the sum 1).
    ShapeAdd(change: f64 as Finite64)
        => "shape-add", "DELTA", "add to the selected source's shape weight in the selected group", edit;
    /// Make a source the base avatar.
    SetBase(source: String as Word) => "set-base", "SOURCE", "make a source the base avatar", edit;
    /// Make the selected source the base avatar.
    BaseFromSelected => "base-from-selected", "", "make the selected source the base", edit;
    /// Set (or with `None`, cycle) border smoothing.
    Smoothing(choice: Option<Smoothing> as Choice<Smoothing>)
        => "smoothing", "[off|thesis|crossfade]", "set or cycle border smoothing", edit;
    /// Set (or with `None`, cycle) colour correction.
    Colour(choice: Option<ColourCorrection> as Choice<ColourCorrection>)
        => "colour" | "color", "[off|thesis|skin]", "set or cycle colour correction", edit;
    /// Drive the composite with a motion ("rest" for none).
    Motion(motion: String as Word) => "motion", "NAME|rest", "drive the composite with a motion", edit;
    /// Switch to the next motion.
    NextMotion => "next-motion", "", "next motion", edit;
    /// Start playing at 25 FPS.
    Play => "play", "", "play at 25 FPS", avatar;
    /// Stop playing.
    Pause => "pause", "", "pause", avatar;
    /// Toggle playing.
    TogglePlay => "toggle-play", "", "play or pause", avatar;
    /// Step frames (negative steps back).
    Step(frames: i64 as Integer) => "step", "N", "step N frames (negative: back)", avatar;
    /// Go to a frame.
    Frame(frame: usize as Index) => "frame", "N", "go to frame N", avatar;
    /// Set (or with `None`, toggle) the animation mode.
    Mode(choice: Option<AnimationMode> as Choice<AnimationMode>)
        => "mode", "[fast|exact]", "set or toggle the animation mode", edit;
    /// Add an axis-angle rotation (radians) to a joint.
    Pose(joint: PoseJoint as Joint, angles: [f32; 3] as Angles)
        => "pose", "jaw|neck|eyes X Y Z", "add a rotation (radians) to a joint", edit;
    /// Add to one of the first five expression components.
    Expression(component: usize as ExpressionSlot, amount: f32 as Finite)
        => "expression", "K DELTA", "add to expression component K (1-5)", edit;
    /// Clear all pose and expression offsets.
    ResetPose => "reset-pose", "", "clear pose and expression offsets", edit;
    /// Orbit the camera (degrees of yaw and pitch).
    Orbit(yaw: f32 as Finite, pitch: f32 as Finite) => "orbit", "DYAW DPITCH", "orbit the camera (degrees)";
    /// Multiply the camera distance.
    Zoom(factor: f32 as Positive) => "zoom", "FACTOR", "multiply the camera distance";
    /// Back to the default camera.
    CameraReset => "camera-reset", "", "back to the default camera";
    /// Toggle the thesis study limits (±45° yaw, ±15° pitch, radius 2.5).
    CameraStudy => "camera-study", "", "toggle the thesis study camera limits", avatar;
    /// Set parts of the camera (target, radius, field of view, up axis, angles).
    SetCamera(settings: CameraOverrides as CameraSettings)
        => "set-camera", "yaw=D pitch=D radius=R fov=D target=X,Y,Z up=+y|-y|+z|-z", "set parts of the camera";
    /// Move the camera and its target together (fractions of the orbit radius
    /// along the view direction, to the right and up on screen): free flight.
    Fly(forward: f32 as Finite, right: f32 as Finite, up: f32 as Finite)
        => "fly", "FORWARD RIGHT UP", "move the camera and its target (fractions of the radius)";
    /// Turn the camera where it stands (degrees; positive turns right and up).
    Look(yaw: f32 as Finite, pitch: f32 as Finite) => "look", "DYAW DPITCH", "turn the camera where it stands (degrees)";
    /// Set (or with `None`, cycle down) the highest SH degree drawn.
    ShDegree(degree: Option<u8> as Degree) => "sh-degree", "[0-3]", "set or cycle the SH degree drawn";
    /// Multiply the debug Gaussian scale.
    DebugScale(factor: f32 as Positive) => "debug-scale", "FACTOR", "multiply the Gaussian scale (debug view)";
    /// Toggle the mesh overlay.
    ToggleMesh => "toggle-mesh", "", "toggle the mesh overlay", avatar;
    /// Toggle highlighting the selected group's regions.
    ToggleHighlight => "toggle-highlight", "", "toggle highlighting the selected group", avatar;
    /// Write the recipe to a TOML file.
    SaveRecipe(path: String as Word) => "save-recipe", "PATH", "write the recipe as TOML", avatar;
    /// Write the current frame as a standard 3DGS PLY.
    ExportPly(path: String as Word) => "export-ply", "PATH", "write the current frame as a 3DGS PLY";
    /// Write the current view as a PNG.
    Snapshot(path: String as Word) => "snapshot", "PATH", "write the current view as a PNG";
}

impl Command {
    /// Parses one command line, e.g. `set-gaussians nose bram`.
    pub fn parse(line: &str) -> Result<Command, String> {
        let mut words = line.split_whitespace().peekable();
        let name = words.next().ok_or("empty command")?;
        let command = Command::parse_arguments(name, &mut words)?;
        if let Some(extra) = words.next() {
            return Err(format!(
                "{name}: unexpected argument '{}'",
                crate::text::printable(extra)
            ));
        }
        Ok(command)
    }

    /// Whether the command changes the composite (and so is undoable).
    pub fn is_edit(&self) -> bool {
        self.spec().edit
    }

    /// Whether session journals record the command.
    pub fn journalled(&self) -> bool {
        self.spec().journal
    }
}

impl fmt::Display for Command {
    /// The canonical text form; `Command::parse` reads it back.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.spec().name)?;
        for word in self.argument_words() {
            write!(f, " {word}")?;
        }
        Ok(())
    }
}

/// Command names starting with `prefix` (for prompt completion).
pub fn complete(prefix: &str) -> Vec<&'static str> {
    COMMANDS
        .iter()
        .map(|c| c.name)
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
            "fly 0.1 -0.05 0",
            "look 5 -2",
            "sh-degree",
            "sh-degree 1",
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
        for spec in COMMANDS {
            assert!(
                names.contains(spec.name),
                "{} has no round-trip sample",
                spec.name
            );
        }
    }

    #[test]
    fn bad_commands_explain_themselves() {
        for (line, needle) in [
            ("", "empty"),
            ("soar", "unknown command"),
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
            ("sh-degree 4", "0 to 3"),
            ("fly 1 0", "missing up"),
        ] {
            let e = Command::parse(line).unwrap_err();
            assert!(e.contains(needle), "{line}: {e}");
        }
    }

    /// The README's command list is the table: every command is listed and
    /// everything listed is a command.
    #[test]
    fn the_readme_lists_every_command() {
        let readme = std::fs::read_to_string("README.md").unwrap();
        let section = readme
            .split("### Commands")
            .nth(1)
            .and_then(|s| s.split("\n### ").next())
            .expect("README has a Commands section");
        let paragraph = section.split("\n\n").nth(1).unwrap();
        let listed: Vec<&str> = paragraph
            .split('`')
            .skip(1)
            .step_by(2)
            .map(|item| item.split(' ').next().unwrap())
            .filter(|name| name.starts_with(|c: char| c.is_ascii_lowercase()))
            .collect();
        for spec in COMMANDS {
            assert!(
                listed.contains(&spec.name),
                "README does not list {}",
                spec.name
            );
        }
        for name in listed {
            assert!(
                COMMANDS.iter().any(|c| c.name == name),
                "README lists '{name}', which is no command"
            );
        }
    }

    #[test]
    fn completion_lists_matching_names() {
        assert_eq!(complete("sna"), vec!["snapshot"]);
        assert!(complete("set-").len() >= 3);
    }
}
