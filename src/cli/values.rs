//! Parsers of the command line's argument values that are not a type's own
//! (`Backend::parse`, `LodPolicy::parse` and the memory budget parse where
//! their types live): image sizes, frame ranges and study groups.

use crate::compose::composition::StudyGroup;

/// Parses "WxH" with both sides in 1..=8192 (the editor's prompt reads
/// sizes with the same parser).
pub fn parse_size(s: &str) -> Result<(u32, u32), String> {
    crate::text::parse_image_size(s)
}

/// Parses "A..B" with A < B.
pub fn parse_range(s: &str) -> Result<(usize, usize), String> {
    let (a, b) = s
        .split_once("..")
        .ok_or_else(|| format!("'{s}' is not START..END"))?;
    let a: usize = a.parse().map_err(|_| format!("'{s}' is not START..END"))?;
    let b: usize = b.parse().map_err(|_| format!("'{s}' is not START..END"))?;
    if a >= b {
        return Err(format!("'{s}' is empty: END must be greater than START"));
    }
    if b - a > 100_000 {
        return Err(format!("'{s}' has more than 100000 frames"));
    }
    Ok((a, b))
}

/// Parses a study group's name.
pub fn parse_group(s: &str) -> Result<StudyGroup, String> {
    StudyGroup::from_name(s).map_err(|e| e.to_string())
}
