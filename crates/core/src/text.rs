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

/// Reads an image size written `WxH` (each side 1 to 8192 pixels), for the
/// command line and the editor's prompt alike.
pub fn parse_image_size(text: &str) -> Result<(u32, u32), String> {
    let bad = || {
        format!(
            "'{}' is not a size: write WxH, e.g. 640x480",
            printable(text)
        )
    };
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    );
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(format!("{w}x{h}: each side must be 1 to 8192 pixels"));
    }
    Ok((w, h))
}

#[cfg(test)]
mod tests {
    use super::{id_text, parse_image_size, printable};

    #[test]
    fn sizes_parse_within_limits() {
        assert_eq!(parse_image_size("640x480"), Ok((640, 480)));
        assert_eq!(parse_image_size("8X 16"), Ok((8, 16)));
        assert!(parse_image_size("0x10").unwrap_err().contains("1 to 8192"));
        assert!(parse_image_size("9000x10")
            .unwrap_err()
            .contains("1 to 8192"));
        assert!(parse_image_size("wide").unwrap_err().contains("WxH"));
        assert!(parse_image_size("\u{1b}[2Jx4")
            .unwrap_err()
            .starts_with("'[2Jx4'"));
    }

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
