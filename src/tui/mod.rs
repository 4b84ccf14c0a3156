//! The terminal front end of the editor: the interactive runtime (`app`), the
//! screen (`view`), terminal graphics protocols (`graphics`) and key bindings
//! (`keymap`). Everything that is not about the terminal — commands, state,
//! sessions, replay — lives in [`crate::editor`].

pub mod app;
pub mod graphics;
pub mod keymap;
pub mod study;
pub mod view;
