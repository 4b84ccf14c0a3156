//! Text formats: recipes (TOML), session files, keymaps and command lines. The
//! first byte picks the parser; the rest is the text.
#![no_main]
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&which, rest)) = data.split_first() else { return };
    let Ok(text) = std::str::from_utf8(rest) else { return };
    match which % 4 {
        0 => {
            let _ = visage::compose::recipe::Recipe::from_toml(text);
        }
        1 => {
            let _ = visage::editor::session::Session::parse(text, "fuzz");
        }
        2 => {
            let _ = visage::tui::keymap::Keymap::builtin().merge_text(text, "fuzz");
        }
        _ => {
            for line in text.lines() {
                if let Ok(c) = visage::editor::command::Command::parse(line) {
                    assert_eq!(visage::editor::command::Command::parse(&c.to_string()).as_ref(), Ok(&c));
                }
            }
        }
    }
});
