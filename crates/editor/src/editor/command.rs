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

use crate::compose::recipe::{
    Anchor, AnimationMode, ColourCorrection, Deform, Fit, Membership, Shading, SkinSource,
    Smoothing,
};
use crate::model::regions::Group;
use crate::render::lod::LodPolicy;
use crate::scene::camera::CameraOverrides;
use crate::text::parse_image_size;

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
    /// Handled by the front end (quitting, help, the prompt): it changes
    /// nothing in the document and is never journalled.
    pub front: bool,
    /// What each argument takes, in order (for completion); the last one
    /// repeats when it takes the rest of the line.
    pub args: &'static [ArgHint],
    /// The area of the editor it belongs to (the help overlay's sections).
    pub area: Area,
}

/// The areas of the editor, in the order the help overlay shows them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Area {
    /// Quitting, undo, help and the prompt.
    Editor,
    /// Which group and source are selected, and who shows where.
    Selection,
    /// Shape weights.
    Shape,
    /// Border smoothing and colour correction.
    PostProcessing,
    /// Motions, frames, poses and expressions.
    Animation,
    /// The camera.
    Camera,
    /// Recipes, exports and snapshots.
    Files,
    /// Debug views.
    Debug,
}

impl Area {
    /// Every area, in help order.
    pub const ALL: [Area; 8] = [
        Area::Editor,
        Area::Selection,
        Area::Shape,
        Area::PostProcessing,
        Area::Animation,
        Area::Camera,
        Area::Files,
        Area::Debug,
    ];

    /// The heading the help shows.
    pub fn name(self) -> &'static str {
        match self {
            Area::Editor => "editor",
            Area::Selection => "selection",
            Area::Shape => "shape",
            Area::PostProcessing => "post-processing",
            Area::Animation => "animation",
            Area::Camera => "camera",
            Area::Files => "files",
            Area::Debug => "debug",
        }
    }
}

/// What an argument takes: what `:` completion offers for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArgHint {
    /// A group name.
    Group,
    /// A source name.
    Source,
    /// A motion name or `rest`.
    Motion,
    /// A joint: jaw, neck or eyes.
    Joint,
    /// One of these words.
    Choice(&'static [&'static str]),
    /// A file path.
    Path,
    /// `SOURCE=WEIGHT` pairs (the rest of the line).
    Weights,
    /// `key=value` camera settings (the rest of the line).
    Camera,
    /// A command name.
    Command,
    /// An image size, `WxH`.
    Size,
    /// A number.
    Number,
}

impl ArgHint {
    /// Whether the argument takes the rest of the line (and so repeats).
    pub fn repeats(self) -> bool {
        matches!(self, ArgHint::Weights | ArgHint::Camera)
    }
}

/// The words of a command line after its name.
pub type Words<'a> = Peekable<SplitWhitespace<'a>>;

/// How one argument reads from words and writes back to them.
trait ArgKind {
    /// The argument's value in the command.
    type Value;
    /// What completion offers for it.
    const HINT: ArgHint;
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

/// Declares argument kinds that are one word taken as it is, each with what
/// completion offers for it.
macro_rules! word_kinds {
    ($($(#[doc = $doc:expr])* $kind:ident => $hint:expr;)*) => {$(
        $(#[doc = $doc])*
        struct $kind;
        impl ArgKind for $kind {
            type Value = String;
            const HINT: ArgHint = $hint;
            fn parse(words: &mut Words, what: &str) -> Result<String, String> {
                next_word(words, what).map(str::to_string)
            }
            fn write(value: &String, out: &mut Vec<String>) {
                out.push(value.clone());
            }
        }
    )*};
}

word_kinds! {
    /// A source's name (checked against the database when applied).
    SourceName => ArgHint::Source;
    /// A motion's name or `rest`.
    MotionName => ArgHint::Motion;
    /// A file path.
    PathWord => ArgHint::Path;
}

/// An optional command name (`help COMMAND`).
struct Topic;
impl ArgKind for Topic {
    type Value = Option<String>;
    const HINT: ArgHint = ArgHint::Command;
    fn parse(words: &mut Words, _: &str) -> Result<Option<String>, String> {
        Ok(words.next().map(str::to_string))
    }
    fn write(value: &Option<String>, out: &mut Vec<String>) {
        out.extend(value.clone());
    }
}

/// An optional image size, `WxH`.
struct OptionalSize;
impl ArgKind for OptionalSize {
    type Value = Option<(u32, u32)>;
    const HINT: ArgHint = ArgHint::Size;
    fn parse(words: &mut Words, _: &str) -> Result<Option<(u32, u32)>, String> {
        words.next().map(parse_image_size).transpose()
    }
    fn write(value: &Option<(u32, u32)>, out: &mut Vec<String>) {
        out.extend(value.map(|(w, h)| format!("{w}x{h}")));
    }
}

/// A group name.
struct GroupName;
impl ArgKind for GroupName {
    type Value = Group;
    const HINT: ArgHint = ArgHint::Group;
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Choice(&["1", "2", "3", "4", "5"]);
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
    const HINT: ArgHint = ArgHint::Joint;
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

/// A level-of-detail policy: off, auto, or a budget of Gaussians.
struct Lod;
impl ArgKind for Lod {
    type Value = LodPolicy;
    const HINT: ArgHint = ArgHint::Choice(&["auto", "off"]);
    fn parse(words: &mut Words, _: &str) -> Result<LodPolicy, String> {
        LodPolicy::parse(next_word(words, "level of detail")?)
            .map_err(|e| e.replacen("--lod ", "level of detail ", 1))
    }
    fn write(value: &LodPolicy, out: &mut Vec<String>) {
        out.push(value.label());
    }
}

/// An optional SH degree, 0 to 3.
struct Degree;
impl ArgKind for Degree {
    type Value = Option<u8>;
    const HINT: ArgHint = ArgHint::Choice(&["0", "1", "2", "3"]);
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
    const HINT: ArgHint = ArgHint::Number;
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
    const HINT: ArgHint = ArgHint::Weights;
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
    const HINT: ArgHint = ArgHint::Camera;
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
    /// The names alone, for completion.
    const WORDS: &'static [&'static str];
}

impl Named for Smoothing {
    const NAMES: &'static [(Self, &'static str)] = &[
        (Smoothing::Off, "off"),
        (Smoothing::Thesis, "thesis"),
        (Smoothing::Crossfade, "crossfade"),
        (Smoothing::Blend, "blend"),
    ];
    const LABEL: &'static str = "smoothing";
    const WORDS: &'static [&'static str] = &["off", "thesis", "crossfade", "blend"];
}

impl Named for ColourCorrection {
    const NAMES: &'static [(Self, &'static str)] = &[
        (ColourCorrection::Off, "off"),
        (ColourCorrection::Thesis, "thesis"),
        (ColourCorrection::Skin, "skin"),
        (ColourCorrection::Semantic, "semantic"),
    ];
    const LABEL: &'static str = "colour";
    const WORDS: &'static [&'static str] = &["off", "thesis", "skin", "semantic"];
}

impl Named for Membership {
    const NAMES: &'static [(Self, &'static str)] =
        &[(Membership::Parent, "parent"), (Membership::Place, "place")];
    const LABEL: &'static str = "membership";
    const WORDS: &'static [&'static str] = &["parent", "place"];
}

impl Named for Deform {
    const NAMES: &'static [(Self, &'static str)] = &[
        (Deform::Similarity, "similarity"),
        (Deform::Affine, "affine"),
    ];
    const LABEL: &'static str = "deform";
    const WORDS: &'static [&'static str] = &["similarity", "affine"];
}

impl Named for Anchor {
    const NAMES: &'static [(Self, &'static str)] =
        &[(Anchor::Parent, "parent"), (Anchor::Nearest, "nearest")];
    const LABEL: &'static str = "anchor";
    const WORDS: &'static [&'static str] = &["parent", "nearest"];
}

impl Named for Shading {
    const NAMES: &'static [(Self, &'static str)] =
        &[(Shading::Kept, "kept"), (Shading::Relit, "relit")];
    const LABEL: &'static str = "shading";
    const WORDS: &'static [&'static str] = &["kept", "relit"];
}

impl Named for SkinSource {
    const NAMES: &'static [(Self, &'static str)] =
        &[(SkinSource::Source, "source"), (SkinSource::Base, "base")];
    const LABEL: &'static str = "skin";
    const WORDS: &'static [&'static str] = &["source", "base"];
}

impl Named for Fit {
    const NAMES: &'static [(Self, &'static str)] = &[(Fit::Off, "off"), (Fit::Seams, "seams")];
    const LABEL: &'static str = "fit";
    const WORDS: &'static [&'static str] = &["off", "seams"];
}

impl Named for AnimationMode {
    const NAMES: &'static [(Self, &'static str)] = &[
        (AnimationMode::Fast, "fast"),
        (AnimationMode::Exact, "exact"),
    ];
    const LABEL: &'static str = "mode";
    const WORDS: &'static [&'static str] = &["fast", "exact"];
}

/// An optional named option (left out: cycle or toggle).
struct Choice<T>(std::marker::PhantomData<T>);
impl<T: Named> ArgKind for Choice<T> {
    type Value = Option<T>;
    const HINT: ArgHint = ArgHint::Choice(T::WORDS);
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
    (front, front $(, $rest:ident)*) => { true };
    ($want:ident, $first:ident $(, $rest:ident)*) => { has_flag!($want $(, $rest)*) };
}

/// Declares every command once; see the module documentation.
macro_rules! commands {
    ($(
        $(#[doc = $doc:expr])*
        $variant:ident $( ( $( $field:ident : $ty:ty as $kind:ty ),+ ) )?
            => $name:literal $(| $alias:literal)*, $synopsis:literal, $summary:literal,
            $area:ident $(, $flag:ident)* ;
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
                journal: !has_flag!(local $(, $flag)*) && !has_flag!(front $(, $flag)*),
                avatar: has_flag!(avatar $(, $flag)*) || has_flag!(edit $(, $flag)*),
                front: has_flag!(front $(, $flag)*),
                args: &[$( $( <$kind as ArgKind>::HINT ),+ )?],
                area: Area::$area,
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
                        return Err(unknown_command(other))
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

/// The message for a name that is no command, with the nearest names when
/// it looks like a typo.
fn unknown_command(name: &str) -> String {
    let near = nearest_names(name);
    if near.is_empty() {
        format!(
            "unknown command '{}' (type ? for help, or Tab to complete)",
            crate::text::printable(name)
        )
    } else {
        format!(
            "unknown command '{}': did you mean {}?",
            crate::text::printable(name),
            near.join(" or ")
        )
    }
}

/// Command names within a small edit distance of `typed` (typos), or that
/// start with it, closest first, at most three.
pub fn nearest_names(typed: &str) -> Vec<&'static str> {
    let mut scored: Vec<(usize, &'static str)> = COMMANDS
        .iter()
        .flat_map(|c| std::iter::once(c.name).chain(c.aliases.iter().copied()))
        .filter_map(|name| {
            let d = edit_distance(typed, name);
            let close = d <= (typed.chars().count() / 3).max(1);
            (close || (typed.len() >= 3 && name.starts_with(typed))).then_some((d, name))
        })
        .collect();
    scored.sort();
    scored.dedup_by_key(|(_, n)| *n);
    scored.into_iter().take(3).map(|(_, n)| n).collect()
}

/// Levenshtein distance between two short strings.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diagonal = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let above = row[j + 1];
            row[j + 1] = (above + 1)
                .min(row[j] + 1)
                .min(diagonal + usize::from(ca != *cb));
            diagonal = above;
        }
    }
    row[b.len()]
}

commands! {
    /// Leave the editor (asks first when edits are unsaved).
    Quit => "quit" | "q", "", "leave the editor (asks first when edits are unsaved)", Editor, front;
    /// Leave the editor at once, whatever is unsaved.
    ForceQuit => "quit!" | "q!", "", "leave at once, discarding unsaved edits", Editor, front;
    /// Undo the last edit.
    Undo => "undo", "", "undo the last edit", Editor;
    /// Redo the last undone edit.
    Redo => "redo", "", "redo the last undone edit", Editor;
    /// Show or hide the help, or show one command's usage.
    Help(topic: Option<String> as Topic) => "help", "[COMMAND]", "show the help, or one command's usage", Editor, front;
    /// Open the `:` command prompt.
    Prompt => "prompt", "", "open the command prompt", Editor, front;
    /// Select a group in the group list.
    SelectGroup(group: Group as GroupName) => "select-group", "GROUP", "select a group", Selection, avatar;
    /// Move the group cursor down.
    NextGroup => "next-group", "", "select the next group", Selection, avatar;
    /// Move the group cursor up.
    PrevGroup => "prev-group", "", "select the previous group", Selection, avatar;
    /// Select a source in the source strip.
    SelectSource(source: String as SourceName) => "select-source", "SOURCE", "select a source", Selection, avatar;
    /// Move the source cursor right.
    NextSource => "next-source", "", "select the next source", Selection, avatar;
    /// Move the source cursor left.
    PrevSource => "prev-source", "", "select the previous source", Selection, avatar;
    /// Show the selected source's Gaussians in the selected group.
    Assign => "assign", "", "show the selected source's Gaussians in the selected group", Selection, edit;
    /// Show a source's Gaussians in a group.
    SetGaussians(group: Group as GroupName, source: String as SourceName)
        => "set-gaussians", "GROUP SOURCE", "show a source's Gaussians in a group", Selection, edit;
    /// Make a source the base avatar.
    SetBase(source: String as SourceName) => "set-base", "SOURCE", "make a source the base avatar", Selection, edit;
    /// Make the selected source the base avatar.
    BaseFromSelected => "base-from-selected", "", "make the selected source the base", Selection, edit;
    /// Set a group's shape weights.
    SetShape(group: Group as GroupName, weights: Vec<(String, f64)> as Weights)
        => "set-shape", "GROUP SOURCE=W ...", "set a group's shape weights", Shape, edit;
    /// Add to the selected source's shape weight in the selected group (others scale to keep the sum 1).
    ShapeAdd(change: f64 as Finite64)
        => "shape-add", "DELTA", "add to the selected source's weight in the selected group", Shape, edit;
    /// Set (or with `None`, cycle) border smoothing.
    Smoothing(choice: Option<Smoothing> as Choice<Smoothing>)
        => "smoothing", "[off|thesis|crossfade|blend]", "set or cycle border smoothing", PostProcessing, edit;
    /// Set (or with `None`, cycle) colour correction.
    Colour(choice: Option<ColourCorrection> as Choice<ColourCorrection>)
        => "colour" | "color", "[off|thesis|skin|semantic]", "set or cycle colour correction", PostProcessing, edit;
    /// Set (or with `None`, toggle) which Gaussians count for a region.
    Membership(choice: Option<Membership> as Choice<Membership>)
        => "membership", "[parent|place]", "count Gaussians for a region by parent triangle or by place", PostProcessing, edit;
    /// Set (or with `None`, toggle) how Gaussians follow a reshaped triangle.
    Deform(choice: Option<Deform> as Choice<Deform>)
        => "deform", "[similarity|affine]", "Gaussians follow a reshaped triangle's size or its whole stretch", PostProcessing, edit;
    /// Set (or with `None`, toggle) which triangle's reshaping a Gaussian
    /// follows: its parent's, or that of the surface nearest it.
    Anchor(choice: Option<Anchor> as Choice<Anchor>)
        => "anchor", "[parent|nearest]", "follow the parent triangle or the nearest surface when reshaped", PostProcessing, edit;
    /// Set (or with `None`, toggle) whether colours are relit for their
    /// triangles' new normals.
    Shading(choice: Option<Shading> as Choice<Shading>)
        => "shading", "[kept|relit]", "keep each source's baked light or relight it for the blended shape", PostProcessing, edit;
    /// Set (or with `None`, toggle) where a swapped region's skin comes
    /// from: its source, or the base (under the source's features).
    Skin(choice: Option<SkinSource> as Choice<SkinSource>)
        => "skin", "[source|base]", "take a swapped region's skin from its source or from the base", PostProcessing, edit;
    /// Set (or with `None`, toggle) the seam fit: colours and opacities
    /// beside a change of source fitted to what the sources draw there.
    Fit(choice: Option<Fit> as Choice<Fit>)
        => "fit", "[off|seams]", "fit the colours beside each change of source (runs in the background)", PostProcessing, edit;
    /// Drive the composite with a motion ("rest" for none).
    Motion(motion: String as MotionName) => "motion", "NAME|rest", "drive the composite with a motion", Animation, edit;
    /// Switch to the next motion.
    NextMotion => "next-motion", "", "switch to the next motion", Animation, edit;
    /// Start playing at 25 FPS.
    Play => "play", "", "play at 25 FPS", Animation, avatar;
    /// Stop playing.
    Pause => "pause", "", "pause", Animation, avatar;
    /// Toggle playing.
    TogglePlay => "toggle-play", "", "play or pause", Animation, avatar;
    /// Step frames (negative steps back; wraps around the motion).
    Step(frames: i64 as Integer) => "step", "N", "step N frames (negative: back)", Animation, avatar;
    /// Go to a frame of the motion.
    Frame(frame: usize as Index) => "frame", "N", "go to frame N of the motion", Animation, avatar;
    /// Set (or with `None`, toggle) the animation mode.
    Mode(choice: Option<AnimationMode> as Choice<AnimationMode>)
        => "mode", "[fast|exact]", "set or toggle the animation mode", Animation, edit;
    /// Add an axis-angle rotation (radians) to a joint.
    Pose(joint: PoseJoint as Joint, angles: [f32; 3] as Angles)
        => "pose", "jaw|neck|eyes X Y Z", "add a rotation (radians) to a joint", Animation, edit;
    /// Add to one of the first five expression components.
    Expression(component: usize as ExpressionSlot, amount: f32 as Finite)
        => "expression", "K DELTA", "add to expression component K (1-5)", Animation, edit;
    /// Clear all pose and expression offsets.
    ResetPose => "reset-pose", "", "clear pose and expression offsets", Animation, edit;
    /// Orbit the camera (degrees of yaw and pitch).
    Orbit(yaw: f32 as Finite, pitch: f32 as Finite) => "orbit", "DYAW DPITCH", "orbit the camera (degrees)", Camera;
    /// Multiply the camera distance.
    Zoom(factor: f32 as Positive) => "zoom", "FACTOR", "multiply the camera distance", Camera;
    /// Back to the framed camera (keeping the chosen up axis).
    CameraReset => "camera-reset", "", "back to the framed camera (keeps the up axis)", Camera;
    /// Toggle the thesis study limits (±45° yaw, ±15° pitch, radius 2.5).
    CameraStudy => "camera-study", "", "toggle the thesis study camera limits", Camera, avatar;
    /// Set parts of the camera (target, radius, field of view, up axis, angles).
    SetCamera(settings: CameraOverrides as CameraSettings)
        => "set-camera", "yaw=D pitch=D radius=R fov=D target=X,Y,Z up=+y|-y|+z|-z", "set parts of the camera", Camera;
    /// Turn the world's up axis upside down (+y and -y, +z and -z): for
    /// captures that open upside down.
    FlipUp => "flip-up", "", "turn the up axis upside down (y-down captures)", Camera;
    /// Move the camera and its target together (fractions of the orbit radius
    /// along the view direction, to the right and up on screen): free flight.
    Fly(forward: f32 as Finite, right: f32 as Finite, up: f32 as Finite)
        => "fly", "FORWARD RIGHT UP", "move the camera and its target (fractions of the radius)", Camera;
    /// Turn the camera where it stands (degrees; positive turns right and up).
    Look(yaw: f32 as Finite, pitch: f32 as Finite) => "look", "DYAW DPITCH", "turn the camera where it stands (degrees)", Camera;
    /// Set (or with `None`, cycle down) the highest SH degree drawn.
    ShDegree(degree: Option<u8> as Degree) => "sh-degree", "[0-3]", "set or cycle the SH degree drawn", Debug;
    /// Multiply the debug Gaussian scale.
    DebugScale(factor: f32 as Positive) => "debug-scale", "FACTOR", "multiply every Gaussian's scale (debug view)", Debug;
    /// Toggle the mesh overlay.
    ToggleMesh => "toggle-mesh", "", "draw the mesh instead of the Gaussians", Debug, avatar;
    /// Hide (or show again) the Gaussians the floater filter removes.
    ToggleFloaters => "toggle-floaters", "", "hide or show the floaters `visage clean` removes (scene view)", Debug;
    /// Set how much of a scene's level-of-detail hierarchy is drawn.
    Lod(policy: LodPolicy as Lod) => "lod", "auto|off|BUDGET", "level of detail of a scene view: auto, off (every Gaussian) or a budget (300k)", Debug;
    /// Toggle highlighting the selected group's regions.
    ToggleHighlight => "toggle-highlight", "", "highlight the selected group (Gaussians or mesh)", Debug, avatar;
    /// Write the recipe to a TOML file.
    SaveRecipe(path: String as PathWord) => "save-recipe", "PATH", "write the recipe as TOML", Files, avatar;
    /// Write the current frame as a 3DGS scene, in the format the path's
    /// extension names (.ply, .compressed.ply, .splat, .spz).
    ExportPly(path: String as PathWord) => "export-ply", "PATH", "write the current frame as a 3DGS scene (.ply .splat .spz …)", Files;
    /// Write the current view as a PNG, at the session's render size unless
    /// a size is given.
    Snapshot(path: String as PathWord, size: Option<(u32, u32)> as OptionalSize)
        => "snapshot", "PATH [WxH]", "write the view as a PNG (default: the session's render size)", Files;
}

impl Command {
    /// Parses one command line, e.g. `set-gaussians nose bram`.
    pub fn parse(line: &str) -> Result<Command, String> {
        let mut words = line.split_whitespace().peekable();
        let name = words.next().ok_or("empty command")?;
        let with_usage = |e: String| match CommandSpec::find(name) {
            Some(spec) => format!("{}: {e} (usage: {})", spec.name, spec.usage()),
            None => e,
        };
        let command = Command::parse_arguments(name, &mut words).map_err(with_usage)?;
        if let Some(extra) = words.next() {
            return Err(with_usage(format!(
                "unexpected argument '{}'",
                crate::text::printable(extra)
            )));
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

impl CommandSpec {
    /// The command's usage line: name and arguments.
    pub fn usage(&self) -> String {
        if self.synopsis.is_empty() {
            self.name.to_string()
        } else {
            format!("{} {}", self.name, self.synopsis)
        }
    }

    /// The table entry named `name` (or one of its aliases).
    pub fn find(name: &str) -> Option<&'static CommandSpec> {
        COMMANDS
            .iter()
            .find(|c| c.name == name || c.aliases.contains(&name))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_command_round_trips_through_text() {
        let samples = [
            "quit",
            "quit!",
            "undo",
            "redo",
            "help",
            "help set-shape",
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
            "colour semantic",
            "membership parent",
            "membership",
            "deform affine",
            "deform",
            "anchor nearest",
            "anchor",
            "shading relit",
            "shading",
            "skin base",
            "skin",
            "fit seams",
            "fit",
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
            "flip-up",
            "set-camera target=0,0.1,-0.25 radius=3 fov=20 up=-y yaw=-30 pitch=5",
            "fly 0.1 -0.05 0",
            "look 5 -2",
            "sh-degree",
            "sh-degree 1",
            "debug-scale 0.5",
            "toggle-mesh",
            "toggle-highlight",
            "toggle-floaters",
            "lod off",
            "lod 300000",
            "lod auto",
            "save-recipe out.toml",
            "export-ply out.ply",
            "snapshot view.png",
            "snapshot view.png 640x480",
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
        let readme =
            std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md"))
                .unwrap();
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
    fn typos_suggest_the_nearest_commands() {
        let e = Command::parse("smoothng thesis").unwrap_err();
        assert!(e.contains("did you mean smoothing"), "{e}");
        let e = Command::parse("snapshto a.png").unwrap_err();
        assert!(e.contains("snapshot"), "{e}");
        let e = Command::parse("xyzzy").unwrap_err();
        assert!(e.contains("type ? for help"), "{e}");
        assert_eq!(Command::parse("q").unwrap(), Command::Quit);
        assert_eq!(Command::parse("q!").unwrap(), Command::ForceQuit);
    }

    #[test]
    fn argument_errors_show_the_usage() {
        let e = Command::parse("set-gaussians nose").unwrap_err();
        assert!(
            e.contains("missing source") && e.contains("usage: set-gaussians GROUP SOURCE"),
            "{e}"
        );
        let e = Command::parse("snapshot a.png big").unwrap_err();
        assert!(e.contains("WxH"), "{e}");
        assert_eq!(parse_image_size("640x480"), Ok((640, 480)));
        assert!(parse_image_size("0x4").is_err());
    }

    #[test]
    fn every_command_has_an_area_and_argument_hints() {
        for spec in COMMANDS {
            let words = spec
                .synopsis
                .split_whitespace()
                .filter(|w| *w != "...")
                .count();
            let repeats = spec.args.last().is_some_and(|a| a.repeats());
            assert!(
                repeats || words == spec.args.len() || spec.name == "pose",
                "{}: synopsis '{}' against {} argument hints",
                spec.name,
                spec.synopsis,
                spec.args.len()
            );
            assert!(!spec.front || !spec.journal, "{}", spec.name);
        }
        for area in Area::ALL {
            assert!(
                COMMANDS.iter().any(|c| c.area == area),
                "no command in {}",
                area.name()
            );
        }
    }
}
