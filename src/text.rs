//! Text that reaches a terminal or an error message: untrusted names stripped
//! of control characters, and ids read as numbers printed as integers. The
//! bottom layer: every other module may use it.

/// Strips control characters (and the escape sequences they start) so untrusted
/// names can be printed to a terminal. Newlines become spaces.
pub fn printable(text: &str) -> String {
    text.chars()
        .map(|c| if c == '\n' || c == '\t' { ' ' } else { c })
        .filter(|c| !c.is_control())
        .collect()
}

/// An index read from a file as a number (vertex ids, triangle bindings), for
/// error messages: whole numbers print as integers however large
/// (`4294967296`, not `4.294967296e9`), anything else as it is (`2.5`, `NaN`).
pub fn id_text(x: f64) -> String {
    if x.is_finite() && x.fract() == 0.0 && x.abs() < 1e30 {
        format!("{}", x as i128)
    } else {
        format!("{x}")
    }
}

#[cfg(test)]
mod tests {
    use super::{id_text, printable};

    #[test]
    fn ids_print_as_integers() {
        assert_eq!(id_text(4_294_967_296.0), "4294967296");
        assert_eq!(id_text(-1.0), "-1");
        assert_eq!(id_text(1e20), "100000000000000000000");
        assert_eq!(id_text(2.5), "2.5");
        assert_eq!(id_text(f64::NAN), "NaN");
    }

    #[test]
    fn control_characters_are_removed() {
        assert_eq!(printable("ada\u{1b}[31m\u{7}"), "ada[31m");
        assert_eq!(printable("two\nlines"), "two lines");
        assert_eq!(printable("naïve"), "naïve");
    }
}
