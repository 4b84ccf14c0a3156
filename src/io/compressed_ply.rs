//! SuperSplat's compressed PLY (what PlayCanvas's SuperSplat and splat-transform
//! write): a `chunk` element of bounds per 256 Gaussians, a `vertex` element of
//! four packed u32 words per Gaussian, and an optional `sh` element of one byte
//! per higher-order SH coefficient. Decoding, from the format as splat-transform
//! 3.7.0 reads it:
//!
//! - position: 11/10/11 bits (x high), each an unsigned fraction t, the value
//!   `min + (max − min)·t` of the Gaussian's chunk;
//! - rotation: the top 2 bits name the largest of (w, x, y, z); the other three
//!   in file order are 10 bits each, `(t − 0.5)·√2`; the largest is
//!   `√(1 − a² − b² − c²)`;
//! - scale: 11/10/11 bits between the chunk's min and max log scales;
//! - colour: 8 bits each of r, g, b (high to low; between the chunk's min and
//!   max colour when the chunk has them) and opacity (the low byte, already
//!   after the sigmoid); the colour is 0.5 + C0·f_dc;
//! - SH: a byte b is `(n − 0.5)·8` with n = 0, 1 or (b + 0.5)/256 for b = 0,
//!   255 or anything else.

use glam::{Quat, Vec3};

use super::ply::{read_element, Columns, Element};
use crate::avatar::gaussians::{rgb_to_dc, sh_degree_for};
use crate::scene::splats::SplatScene;

/// Gaussians per chunk of bounds.
const CHUNK: usize = 256;

/// True for a header of the compressed layout.
pub fn is_compressed(elements: &[Element]) -> bool {
    elements.iter().any(|e| e.name == "chunk")
        && elements
            .iter()
            .any(|e| e.name == "vertex" && e.properties.iter().any(|p| p.name == "packed_position"))
}

fn unorm(word: u32, shift: u32, bits: u32) -> f32 {
    let max = (1u32 << bits) - 1;
    ((word >> shift) & max) as f32 / max as f32
}

fn lerp(a: f64, b: f64, t: f32) -> f32 {
    (a * (1.0 - t as f64) + b * t as f64) as f32
}

fn columns<'a>(c: &'a Columns, names: &[&str]) -> Result<Vec<&'a [f64]>, String> {
    names.iter().map(|n| c.require(n)).collect()
}

/// Decodes compressed-PLY bytes into a scene.
pub fn parse_compressed_ply(bytes: &[u8]) -> Result<SplatScene, String> {
    let chunks = read_element(bytes, "chunk").map_err(|e| e.to_string())?;
    let vertex = read_element(bytes, "vertex").map_err(|e| e.to_string())?;
    let n = vertex.rows;
    if chunks.rows != n.div_ceil(CHUNK) {
        return Err(format!(
            "compressed PLY has {} chunks for {n} Gaussians (expected {})",
            chunks.rows,
            n.div_ceil(CHUNK)
        ));
    }
    let position = columns(
        &chunks,
        &["min_x", "min_y", "min_z", "max_x", "max_y", "max_z"],
    )?;
    let scale = columns(
        &chunks,
        &[
            "min_scale_x",
            "min_scale_y",
            "min_scale_z",
            "max_scale_x",
            "max_scale_y",
            "max_scale_z",
        ],
    )?;
    let colour = columns(
        &chunks,
        &["min_r", "min_g", "min_b", "max_r", "max_g", "max_b"],
    )
    .ok();
    let words = columns(
        &vertex,
        &[
            "packed_position",
            "packed_rotation",
            "packed_scale",
            "packed_color",
        ],
    )?;
    let (_, elements, _) = super::ply::parse_header(bytes).map_err(|e| e.to_string())?;
    let sh = if elements.iter().any(|e| e.name == "sh") {
        Some(read_element(bytes, "sh").map_err(|e| e.to_string())?)
    } else {
        None
    };
    let rest: Vec<&[f64]> = match &sh {
        Some(c) => (0..).map_while(|k| c.get(&format!("f_rest_{k}"))).collect(),
        None => Vec::new(),
    };
    if sh.as_ref().is_some_and(|c| c.rows != n) {
        return Err("compressed PLY's sh element does not have a row per Gaussian".into());
    }
    let degree = sh_degree_for(1 + rest.len() / 3)
        .filter(|_| rest.len() % 3 == 0)
        .ok_or_else(|| {
            format!(
                "compressed PLY has {} SH bytes a Gaussian, no SH degree 0-3",
                rest.len()
            )
        })?;
    let bounds = |cols: &[&[f64]], c: usize| -> Result<[f64; 6], String> {
        let b: [f64; 6] = std::array::from_fn(|k| cols[k][c]);
        if b.iter().all(|x| x.is_finite()) {
            Ok(b)
        } else {
            Err(format!(
                "compressed PLY chunk {c} has a NaN or infinite bound"
            ))
        }
    };
    let per_channel = rest.len() / 3;
    let mut scene = SplatScene::with_degree(degree);
    let mut coefficients = vec![0.0f32; 3 * (per_channel + 1)];
    for i in 0..n {
        let c = i / CHUNK;
        let word = |k: usize| words[k][i] as u32;
        let (p, s) = (bounds(&position, c)?, bounds(&scale, c)?);
        let pw = word(0);
        let centre = Vec3::new(
            lerp(p[0], p[3], unorm(pw, 21, 11)),
            lerp(p[1], p[4], unorm(pw, 11, 10)),
            lerp(p[2], p[5], unorm(pw, 0, 11)),
        );
        let sw = word(2);
        let log_scale = Vec3::new(
            lerp(s[0], s[3], unorm(sw, 21, 11)),
            lerp(s[1], s[4], unorm(sw, 11, 10)),
            lerp(s[2], s[5], unorm(sw, 0, 11)),
        );
        let rw = word(1);
        let small =
            [20, 10, 0].map(|shift| (unorm(rw, shift, 10) - 0.5) * std::f32::consts::SQRT_2);
        let largest = (1.0 - small.iter().map(|x| x * x).sum::<f32>())
            .max(0.0)
            .sqrt();
        let mut wxyz = [0.0f32; 4];
        let big = (rw >> 30) as usize;
        let mut rest_of = small.iter();
        for (k, slot) in wxyz.iter_mut().enumerate() {
            *slot = if k == big {
                largest
            } else {
                *rest_of.next().expect("three small components")
            };
        }
        let cw = word(3);
        let raw = [unorm(cw, 24, 8), unorm(cw, 16, 8), unorm(cw, 8, 8)];
        let rgb: [f32; 3] = match &colour {
            Some(cols) => {
                let b = bounds(cols, c)?;
                std::array::from_fn(|k| lerp(b[k], b[k + 3], raw[k]))
            }
            None => raw,
        };
        for ch in 0..3 {
            coefficients[ch] = rgb_to_dc(rgb[ch]);
            for j in 0..per_channel {
                let b = rest[ch * per_channel + j][i];
                let unit = match b as u32 {
                    0 => 0.0,
                    255 => 1.0,
                    b => (b as f32 + 0.5) / 256.0,
                };
                coefficients[(j + 1) * 3 + ch] = (unit - 0.5) * 8.0;
            }
        }
        scene.push(
            centre,
            Quat::from_xyzw(wxyz[1], wxyz[2], wxyz[3], wxyz[0]),
            log_scale.exp(),
            unorm(cw, 0, 8),
            &coefficients,
        );
    }
    Ok(scene)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::gaussians::dc_to_rgb;

    /// Files PlayCanvas's splat-transform 3.7.0 compressed from PLYs written by
    /// plyfile (tests/data/splat/make_compressed.sh): every Gaussian comes back
    /// within the format's quantisation (in whatever order the tool stored them).
    #[test]
    fn reads_what_splat_transform_writes() {
        for (name, degree) in [("ring", 0u8), ("ring3", 3)] {
            let dir = std::path::Path::new("tests/data/splat");
            let original =
                crate::io::ply::read_splat_ply(&dir.join(format!("{name}.ply"))).unwrap();
            let bytes = std::fs::read(dir.join(format!("{name}.compressed.ply"))).unwrap();
            let (_, elements, _) = crate::io::ply::parse_header(&bytes).unwrap();
            assert!(is_compressed(&elements));
            let packed = parse_compressed_ply(&bytes).unwrap();
            assert_eq!(
                (packed.len(), packed.sh_degree),
                (original.len(), degree),
                "{name}"
            );
            let mut matched = vec![false; original.len()];
            for i in 0..packed.len() {
                let (j, d) = (0..original.len())
                    .map(|j| (j, (original.position[j] - packed.position[i]).length()))
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                    .unwrap();
                assert!(
                    d < 4e-3 && !matched[j],
                    "{name} Gaussian {i}: nearest original {j} at {d}"
                );
                matched[j] = true;
                let rel = (packed.scale[i] / original.scale[j] - Vec3::ONE)
                    .abs()
                    .max_element();
                assert!(rel < 0.01, "{name} {i}: scale off by {rel}");
                assert!((packed.opacity[i] - original.opacity[j]).abs() <= 1.0 / 255.0 + 1e-6);
                assert!(
                    packed.rotation[i].dot(original.rotation[j]).abs() > 0.999,
                    "{name} {i} rotation"
                );
                for ch in 0..3 {
                    let (a, b) = (
                        dc_to_rgb(packed.sh_of(i)[ch]),
                        dc_to_rgb(original.sh_of(j)[ch]).clamp(0.0, 1.0),
                    );
                    assert!(
                        (a - b).abs() <= 1.5 / 255.0,
                        "{name} {i} colour {ch}: {a} vs {b}"
                    );
                }
                for (a, b) in packed.sh_of(i)[3..].iter().zip(&original.sh_of(j)[3..]) {
                    assert!((a - b).abs() <= 8.0 / 256.0, "{name} {i} SH: {a} vs {b}");
                }
            }
        }
    }

    #[test]
    fn broken_compressed_files_are_named() {
        let bytes = std::fs::read("tests/data/splat/ring.compressed.ply").unwrap();
        let text = String::from_utf8_lossy(&bytes[..600]).to_string();
        let lying = text.replacen("element chunk 1", "element chunk 2", 1);
        let mut broken = lying.into_bytes();
        broken.extend_from_slice(&bytes[600..]);
        assert!(parse_compressed_ply(&broken).is_err());
    }
}
