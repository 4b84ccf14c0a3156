//! File formats and terminal-safe text.

pub mod avatar;
pub mod fixtures;
pub mod flame;
pub mod folder;
pub mod npy;
pub mod obj;
pub mod pickle;
pub mod pickle_write;
pub mod ply;

/// Strips control characters (and the escape sequences they start) so untrusted
/// names can be printed to a terminal. Newlines become spaces.
pub fn printable(text: &str) -> String {
    text.chars()
        .map(|c| if c == '\n' || c == '\t' { ' ' } else { c })
        .filter(|c| !c.is_control())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::printable;

    #[test]
    fn control_characters_are_removed() {
        assert_eq!(printable("ada\u{1b}[31m\u{7}"), "ada[31m");
        assert_eq!(printable("two\nlines"), "two lines");
        assert_eq!(printable("naïve"), "naïve");
    }
}
