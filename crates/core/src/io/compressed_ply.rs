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
//!
//! [`encode_compressed_ply`] writes the same layout (in scene order, bounds
//! per run of 256), so `visage convert` can produce it.

use glam::{Quat, Vec3};

use super::ply::{read_element, Columns, Element};
use crate::avatar::gaussians::{rgb_to_dc, sh_degree_for};
use crate::scene::splats::SplatScene;

/// Gaussians per chunk of bounds.
const CHUNK: usize = 256;

/// The `chunk` element's properties: position, log-scale and colour bounds.
const CHUNK_PROPERTIES: [&str; 18] = [
    "min_x",
    "min_y",
    "min_z",
    "max_x",
    "max_y",
    "max_z",
    "min_scale_x",
    "min_scale_y",
    "min_scale_z",
    "max_scale_x",
    "max_scale_y",
    "max_scale_z",
    "min_r",
    "min_g",
    "min_b",
    "max_r",
    "max_g",
    "max_b",
];

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
    let position = columns(&chunks, &CHUNK_PROPERTIES[0..6])?;
    let scale = columns(&chunks, &CHUNK_PROPERTIES[6..12])?;
    // Older files carry no colour bounds: the bytes are the colour itself.
    let colour = columns(&chunks, &CHUNK_PROPERTIES[12..18]).ok();
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

/// Min and max of `values` (0..0 when empty).
fn range(values: impl Iterator<Item = f32>) -> (f32, f32) {
    values.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

/// `v` as an unsigned fraction of `lo..hi` in `bits` bits, rounded.
fn quantise(v: f32, (lo, hi): (f32, f32), bits: u32) -> u32 {
    let max = ((1u32 << bits) - 1) as f32;
    let t = if hi > lo {
        ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (t * max).round() as u32
}

/// Encodes a scene in the compressed layout.
pub fn encode_compressed_ply(scene: &SplatScene) -> Vec<u8> {
    use crate::avatar::gaussians::dc_to_rgb;
    let n = scene.len();
    let rest = scene.sh_stride() - 3;
    let mut header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment SuperSplat compressed layout, written by visage\nelement chunk {}\n",
        n.div_ceil(CHUNK)
    );
    for name in CHUNK_PROPERTIES {
        header += &format!("property float {name}\n");
    }
    header += &format!("element vertex {n}\n");
    for name in [
        "packed_position",
        "packed_rotation",
        "packed_scale",
        "packed_color",
    ] {
        header += &format!("property uint {name}\n");
    }
    if rest > 0 {
        header += &format!("element sh {n}\n");
        for k in 0..rest {
            header += &format!("property uchar f_rest_{k}\n");
        }
    }
    header += "end_header\n";
    let mut out = header.into_bytes();
    let log_scale = |i: usize| scene.scale[i].max(Vec3::splat(1e-30)).ln();
    let rgb = |i: usize, ch: usize| dc_to_rgb(scene.sh_of(i)[ch]);
    let mut packed = Vec::with_capacity(n * 16);
    for start in (0..n).step_by(CHUNK) {
        let ids = start..(start + CHUNK).min(n);
        let axis = |f: &dyn Fn(usize) -> f32| range(ids.clone().map(f));
        let p: [(f32, f32); 3] = std::array::from_fn(|k| axis(&|i| scene.position[i][k]));
        let s: [(f32, f32); 3] = std::array::from_fn(|k| axis(&|i| log_scale(i)[k]));
        let c: [(f32, f32); 3] = std::array::from_fn(|k| axis(&|i| rgb(i, k)));
        for v in [
            p[0].0, p[1].0, p[2].0, p[0].1, p[1].1, p[2].1, s[0].0, s[1].0, s[2].0, s[0].1, s[1].1,
            s[2].1, c[0].0, c[1].0, c[2].0, c[0].1, c[1].1, c[2].1,
        ] {
            out.extend_from_slice(&v.to_le_bytes());
        }
        for i in ids {
            let pos = scene.position[i];
            let position = quantise(pos.x, p[0], 11) << 21
                | quantise(pos.y, p[1], 10) << 11
                | quantise(pos.z, p[2], 11);
            let q = crate::avatar::binding::normalize_quat(scene.rotation[i]);
            let mut wxyz = [q.w, q.x, q.y, q.z];
            let big = (0..4)
                .max_by(|&a, &b| wxyz[a].abs().total_cmp(&wxyz[b].abs()))
                .unwrap_or(0);
            if wxyz[big] < 0.0 {
                wxyz = wxyz.map(|c| -c);
            }
            let mut rotation = (big as u32) << 30;
            for (slot, k) in (0..4).filter(|&k| k != big).enumerate() {
                let t = (wxyz[k] / std::f32::consts::SQRT_2 + 0.5).clamp(0.0, 1.0);
                rotation |= ((t * 1023.0).round() as u32) << (20 - 10 * slot);
            }
            let ls = log_scale(i);
            let scale = quantise(ls.x, s[0], 11) << 21
                | quantise(ls.y, s[1], 10) << 11
                | quantise(ls.z, s[2], 11);
            let colour = quantise(rgb(i, 0), c[0], 8) << 24
                | quantise(rgb(i, 1), c[1], 8) << 16
                | quantise(rgb(i, 2), c[2], 8) << 8
                | (scene.opacity[i].clamp(0.0, 1.0) * 255.0).round() as u32;
            for w in [position, rotation, scale, colour] {
                packed.extend_from_slice(&w.to_le_bytes());
            }
        }
    }
    out.extend_from_slice(&packed);
    if rest > 0 {
        let per_channel = rest / 3;
        for i in 0..n {
            let sh = scene.sh_of(i);
            for ch in 0..3 {
                for j in 0..per_channel {
                    let v = sh[(j + 1) * 3 + ch];
                    out.push(((v / 8.0 + 0.5) * 256.0).floor().clamp(0.0, 255.0) as u8);
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::avatar::gaussians::dc_to_rgb;

    /// What visage writes reads back within the quantisation, SH degrees 0
    /// and 3, across chunk boundaries; degenerate input stays finite.
    #[test]
    fn round_trips_within_quantisation() {
        for degree in [0u8, 3] {
            let mut scene = crate::scene::synthetic::synthetic_scene(700, 9);
            if degree == 0 {
                let mut flat = SplatScene::with_degree(0);
                for i in 0..scene.len() {
                    flat.push(
                        scene.position[i],
                        scene.rotation[i],
                        scene.scale[i],
                        scene.opacity[i],
                        &scene.sh_of(i)[..3],
                    );
                }
                scene = flat;
            }
            // A zero scale and a zero quaternion.
            scene.scale[5] = Vec3::ZERO;
            scene.rotation[6] = Quat::from_xyzw(0.0, 0.0, 0.0, 0.0);
            let back = parse_compressed_ply(&encode_compressed_ply(&scene)).unwrap();
            assert_eq!((back.len(), back.sh_degree), (scene.len(), degree));
            for i in 0..scene.len() {
                assert!(back.position[i].is_finite() && back.scale[i].is_finite());
                if i == 5 || i == 6 {
                    continue;
                }
                let chunk =
                    &scene.position[i / CHUNK * CHUNK..((i / CHUNK + 1) * CHUNK).min(scene.len())];
                let extent = chunk.iter().fold(Vec3::ZERO, |m, p| m.max(p.abs())) * 2.0;
                assert!(
                    (back.position[i] - scene.position[i])
                        .abs()
                        .cmple(extent / 1000.0 + Vec3::splat(1e-6))
                        .all(),
                    "{i}"
                );
                assert!(
                    back.rotation[i].dot(scene.rotation[i].normalize()).abs() > 0.999,
                    "{i}"
                );
                assert!((back.opacity[i] - scene.opacity[i]).abs() <= 0.5 / 255.0 + 1e-6);
                for ch in 0..3 {
                    let (a, b) = (dc_to_rgb(back.sh_of(i)[ch]), dc_to_rgb(scene.sh_of(i)[ch]));
                    assert!((a - b).abs() <= 1.0 / 255.0, "{i} colour");
                }
                for (a, b) in back.sh_of(i)[3..].iter().zip(&scene.sh_of(i)[3..]) {
                    assert!((a - b).abs() <= 8.0 / 256.0 + 1e-6, "{i} SH");
                }
            }
        }
    }

    /// Files PlayCanvas's splat-transform 3.7.0 compressed from PLYs written by
    /// plyfile (tests/data/splat/make_compressed.sh): every Gaussian comes back
    /// within the format's quantisation (in whatever order the tool stored them).
    #[test]
    fn reads_what_splat_transform_writes() {
        for (name, degree) in [("ring", 0u8), ("ring3", 3)] {
            let dir = crate::io::test_data("splat");
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

    /// What visage writes, splat-transform 3.7.0 reads the same way
    /// (tests/data/splat/make_compressed.sh: ring3.visage.decoded.ply is the
    /// tool's decoding of visage's ring3.visage.compressed.ply).
    #[test]
    fn splat_transform_reads_what_visage_writes() {
        let dir = crate::io::test_data("splat");
        let ours = std::fs::read(dir.join("ring3.visage.compressed.ply")).unwrap();
        let original = crate::io::ply::read_splat_ply(&dir.join("ring3.ply")).unwrap();
        assert_eq!(
            ours,
            encode_compressed_ply(&original),
            "the writer still writes the committed bytes"
        );
        let mine = parse_compressed_ply(&ours).unwrap();
        let theirs = crate::io::ply::read_splat_ply(&dir.join("ring3.visage.decoded.ply")).unwrap();
        assert_eq!(
            (mine.len(), mine.sh_degree),
            (theirs.len(), theirs.sh_degree)
        );
        for i in 0..mine.len() {
            assert!(
                (mine.position[i] - theirs.position[i]).abs().max_element() < 1e-5,
                "{i} position"
            );
            assert!(
                (mine.scale[i] / theirs.scale[i] - Vec3::ONE)
                    .abs()
                    .max_element()
                    < 1e-4,
                "{i} scale"
            );
            assert!(
                mine.rotation[i].dot(theirs.rotation[i]).abs() > 1.0 - 1e-5,
                "{i} rotation"
            );
            assert!(
                (mine.opacity[i] - theirs.opacity[i]).abs() < 1e-5,
                "{i} opacity"
            );
            for (a, b) in mine.sh_of(i).iter().zip(theirs.sh_of(i)) {
                assert!((a - b).abs() < 1e-4, "{i} SH {a} vs {b}");
            }
        }
    }

    #[test]
    fn broken_compressed_files_are_named() {
        let bytes = std::fs::read(crate::io::test_data("splat/ring.compressed.ply")).unwrap();
        let text = String::from_utf8_lossy(&bytes[..600]).to_string();
        let lying = text.replacen("element chunk 1", "element chunk 2", 1);
        let mut broken = lying.into_bytes();
        broken.extend_from_slice(&bytes[600..]);
        assert!(parse_compressed_ply(&broken).is_err());
    }
}
