//! The terminal front end of the editor: the interactive runtime (`app`), its
//! render thread (`worker`), the screen (`view`), the `:` command line
//! (`prompt`), the help overlay (`help`), terminal plumbing (`terminal`),
//! graphics protocols (`graphics`), key bindings (`keymap`) and a study
//! participant's session (`study`). Everything that is not about the terminal
//! — commands, state, journals, sessions, replay — lives in [`crate::editor`].

pub mod app;
pub mod graphics;
pub mod help;
pub mod keymap;
pub mod launch;
pub mod prompt;
pub mod study;
pub mod terminal;
pub mod view;
pub mod worker;
