//! The editor core, free of any terminal: named commands (`command`, declared
//! once), the state and its update function (`state`), session files
//! (`session`), headless replay (`replay`) and frame pacing (`pacing`). The
//! terminal front end (the `tui` module) and replay drive the same [`Editor`].

pub mod command;
pub mod complete;
pub mod journal;
pub mod pacing;
pub mod replay;
pub mod session;
pub mod state;

use std::path::{Path, PathBuf};

use crate::compose::engine::Engine;
use crate::compose::recipe::{PostPreset, Recipe};
use crate::error::{Error, Result};
use crate::pipeline::workbench::{FrameRequest, Workbench};
use command::Command;
use state::{Applied, Catalog, EditorState, Effect};

/// The editor's state on a clock of logical ticks: what the live editor and
/// headless replay both drive, one command at a time.
#[derive(Clone, Debug)]
pub struct Editor {
    /// The state.
    pub state: EditorState,
    /// The names commands are checked against.
    pub catalog: Catalog,
    tick: u64,
}

impl Editor {
    /// An editor on the database's first source, unedited, at tick 0 (on a
    /// scene: at the scene's framed camera, its SH degree).
    pub fn new(catalog: Catalog) -> Self {
        let first = catalog.sources.first().map_or("", String::as_str);
        let mut recipe = Recipe::unedited(first);
        recipe.camera = catalog.home();
        let mut state = EditorState::new(recipe);
        if let Some(scene) = &catalog.scene {
            state.debug.sh_degree = scene.sh_degree;
        }
        Self {
            state,
            catalog,
            tick: 0,
        }
    }

    /// Sets the post-processing the session starts from (its header's
    /// `post`), before any command: undo never goes back past it.
    pub fn start_from(&mut self, post: PostPreset) {
        self.state.recipe.post = post.post();
    }

    /// An editor for an engine's database.
    pub fn for_engine(engine: &Engine) -> Self {
        Self::new(Catalog::of(engine))
    }

    /// An editor for what a workbench holds (a database or a scene).
    pub fn for_workbench(workbench: &Workbench) -> Self {
        Self::new(Catalog::of_workbench(workbench))
    }

    /// The current tick.
    pub fn tick(&self) -> u64 {
        self.tick
    }

    /// Lets time pass up to `tick` (playback advances one frame a tick).
    pub fn advance_to(&mut self, tick: u64) {
        while self.tick < tick {
            self.state.tick(&self.catalog);
            self.tick += 1;
        }
    }

    /// Runs one command: the state's update, returning the effects it asks
    /// for and what it has to say.
    pub fn step(&mut self, command: &Command) -> std::result::Result<Applied, String> {
        self.state.apply(&self.catalog, command)
    }

    /// The frame the view shows now, at a size.
    pub fn frame_request(&self, width: u32, height: u32, exact: bool) -> FrameRequest {
        FrameRequest {
            recipe: self.state.recipe.clone(),
            debug: self.state.debug,
            group: self.state.selected_group(),
            width,
            height,
            exact,
        }
    }
}

/// What performing an effect produced.
#[derive(Clone, Debug, PartialEq)]
pub struct Performed {
    /// A line for the status bar.
    pub message: String,
    /// The file written.
    pub path: PathBuf,
}

/// Performs an effect of a command — the one executor the live editor (on its
/// render thread) and replay share. `place` maps the path the command named to
/// the file to write (replay puts everything into its `--out` folder); `view`
/// is the frame the editor shows at the session's render size, which a
/// snapshot takes unless it names its own size.
pub fn perform(
    effect: &Effect,
    recipe: &Recipe,
    view: &FrameRequest,
    workbench: &mut Workbench,
    place: &dyn Fn(&str) -> PathBuf,
) -> Result<Performed> {
    match effect {
        Effect::SaveRecipe(p) => {
            let path = place(p);
            std::fs::write(&path, recipe.to_toml()).map_err(|e| Error::io("write", &path, e))?;
            Ok(Performed {
                message: format!("saved recipe {}", path.display()),
                path,
            })
        }
        Effect::ExportPly(p) => {
            let path = place(p);
            let n = workbench.export_ply(recipe, &path)?;
            Ok(Performed {
                message: format!("wrote {n} Gaussians to {}", path.display()),
                path,
            })
        }
        Effect::Snapshot(p, size) => {
            let path = place(p);
            let (width, height) = size.unwrap_or((view.width, view.height));
            let sized = FrameRequest {
                width,
                height,
                ..view.clone()
            };
            let image = workbench.snapshot(&sized, &path)?;
            Ok(Performed {
                message: format!(
                    "wrote {}x{} snapshot {}",
                    image.width,
                    image.height,
                    path.display()
                ),
                path,
            })
        }
    }
}

/// Where replay writes a file a command named: its file name inside `dir`.
pub fn inside(dir: &Path) -> impl Fn(&str) -> PathBuf + '_ {
    move |p: &str| dir.join(Path::new(p).file_name().unwrap_or_default())
}
