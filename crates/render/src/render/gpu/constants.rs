//! Constants the Rust side and the WGSL kernels must agree on, declared once
//! here: [`wgsl_header`] writes them as WGSL `const`s ahead of every kernel,
//! so no shader repeats a number the Rust code also uses.

use crate::render::projection::{COVARIANCE_DILATION, MAX_ALPHA, MIN_ALPHA, RADIUS_SIGMAS};

/// Tile edge in pixels (the rasteriser's workgroup is TILE × TILE).
pub const TILE: u32 = 16;
/// Invocations per workgroup of the per-element kernels.
pub const GROUP: u32 = 256;
/// Elements per workgroup of the radix and scan kernels.
pub const SORT_BLOCK: u32 = 1024;
/// Elements each invocation of the radix and scan kernels handles.
pub const SORT_ITEMS: u32 = SORT_BLOCK / GROUP;
/// Digits of one radix pass (8 bits); the radix kernels give each invocation
/// of a workgroup one digit, so this equals [`GROUP`].
pub const DIGITS: u32 = 256;
const _: () = assert!(DIGITS == GROUP && SORT_BLOCK % GROUP == 0);
/// Floats of one splat's screen-space gradient in the training backward:
/// centre (2), conic (3), opacity, colour (3).
pub const SPLAT_GRAD_FLOATS: u32 = 9;
/// The training backward sums a tile's TILE² pixel gradients in two steps of
/// this many terms each (REDUCE_PARTS² = TILE²).
pub const REDUCE_PARTS: u32 = 16;
const _: () = assert!(REDUCE_PARTS * REDUCE_PARTS == TILE * TILE);

/// Where the bind kernel's opacity code stops being a logit: a code
/// above it is `OPACITY_LITERAL − 1 + opacity`, an opacity above 1 (a
/// level-of-detail node, [`crate::scene::splats::MAX_OPACITY`]). A logit
/// this large is an opacity of 1 in f32 already, so clamping files' logits
/// to it changes nothing they show.
pub const OPACITY_LITERAL: f32 = 64.0;

/// The WGSL declarations of every shared constant.
pub fn wgsl_header() -> String {
    let u = |name: &str, v: u32| format!("const {name}: u32 = {v}u;\n");
    // `{:?}` keeps a decimal point, so the literal is a float.
    let f = |name: &str, v: f64| format!("const {name}: f32 = {:?};\n", v as f32);
    [
        "// Generated from src/render/gpu/constants.rs.\n".to_string(),
        f("MAX_OPACITY", crate::scene::splats::MAX_OPACITY as f64),
        f("OPACITY_LITERAL", OPACITY_LITERAL as f64),
        u("TILE", TILE),
        u("GROUP", GROUP),
        u("SORT_BLOCK", SORT_BLOCK),
        u("SORT_ITEMS", SORT_ITEMS),
        u("DIGITS", DIGITS),
        u("SPLAT_GRAD_FLOATS", SPLAT_GRAD_FLOATS),
        u("REDUCE_PARTS", REDUCE_PARTS),
        f("DILATION", COVARIANCE_DILATION),
        f("RADIUS_SIGMAS", RADIUS_SIGMAS),
        f("MAX_ALPHA", MAX_ALPHA),
        f("MIN_ALPHA", MIN_ALPHA),
    ]
    .concat()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// No kernel defines a shared constant (or a literal workgroup size) itself.
    #[test]
    fn shaders_take_shared_constants_from_the_header() {
        let header = wgsl_header();
        assert!(
            header.contains("const MIN_ALPHA: f32 = 0.003921569;"),
            "{header}"
        );
        assert!(header.contains("const SORT_ITEMS: u32 = 4u;"));
        for entry in std::fs::read_dir("shaders").unwrap() {
            let path = entry.unwrap().path();
            let text = std::fs::read_to_string(&path).unwrap();
            for name in [
                "TILE",
                "GROUP",
                "SORT_BLOCK",
                "SORT_ITEMS",
                "DIGITS",
                "SPLAT_GRAD_FLOATS",
                "REDUCE_PARTS",
                "DILATION",
                "RADIUS_SIGMAS",
                "MAX_ALPHA",
                "MIN_ALPHA",
            ] {
                assert!(
                    !text.contains(&format!("const {name}:")),
                    "{} defines {name}",
                    path.display()
                );
            }
            assert!(
                !text.contains("@workgroup_size(2") && !text.contains("@workgroup_size(1"),
                "{} has a literal workgroup size",
                path.display()
            );
        }
    }
}
