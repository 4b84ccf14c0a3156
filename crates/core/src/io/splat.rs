//! antimatter15's `.splat`: 32 bytes a Gaussian, no header — position
//! (3 × f32), scale (3 × f32, linear), colour and opacity (4 × u8: the DC
//! colour 0.5 + C0·f_dc and sigmoid(opacity), times 255) and rotation (4 × u8:
//! the unit quaternion w x y z, 128 + 128·q), all little endian. It keeps no
//! view-dependent colour (SH degree 0) and quantises colour, opacity and
//! rotation to 8 bits; `visage convert` reports what that costs in PSNR.

use std::path::Path;

use glam::{Quat, Vec3};

use super::{read_file, write_file, FileError, Result};
use crate::avatar::gaussians::{dc_to_rgb, rgb_to_dc};
use crate::scene::splats::SplatScene;

/// Bytes per Gaussian.
pub const RECORD: usize = 32;

/// Parses `.splat` bytes into a scene (SH degree 0).
pub fn parse_splat(bytes: &[u8]) -> Result<SplatScene> {
    if bytes.len() % RECORD != 0 {
        return Err(format!(
            "{} bytes is not a whole number of 32-byte .splat records",
            bytes.len()
        )
        .into());
    }
    let mut scene = SplatScene::with_degree(0);
    for (i, r) in bytes.chunks_exact(RECORD).enumerate() {
        let f = |k: usize| f32::from_le_bytes([r[4 * k], r[4 * k + 1], r[4 * k + 2], r[4 * k + 3]]);
        let position = Vec3::new(f(0), f(1), f(2));
        let scale = Vec3::new(f(3), f(4), f(5));
        if !position.is_finite() || !scale.is_finite() {
            return Err(format!("Gaussian {i} has a NaN or infinite value").into());
        }
        if scale.min_element() < 0.0 {
            return Err(format!("Gaussian {i} has a negative scale").into());
        }
        let unit = |b: u8| (b as f32 - 128.0) / 128.0;
        let rotation = Quat::from_xyzw(unit(r[29]), unit(r[30]), unit(r[31]), unit(r[28]));
        let dc: Vec<f32> = r[24..27]
            .iter()
            .map(|&c| rgb_to_dc(c as f32 / 255.0))
            .collect();
        scene.push(position, rotation, scale, r[27] as f32 / 255.0, &dc);
    }
    Ok(scene)
}

/// Reads a `.splat` file.
pub fn read_splat(path: &Path) -> Result<SplatScene> {
    parse_splat(&read_file(path)?).map_err(|e| e.in_file(path))
}

/// A byte of 0..1, rounded to nearest (half the error of truncating).
fn byte(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Encodes a scene as `.splat` bytes, in scene order.
pub fn encode_splat(scene: &SplatScene) -> Vec<u8> {
    let mut out = Vec::with_capacity(scene.len() * RECORD);
    for i in 0..scene.len() {
        for v in [scene.position[i], scene.scale[i]] {
            for c in v.to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        let sh = scene.sh_of(i);
        for c in &sh[..3] {
            out.push(byte(dc_to_rgb(*c)));
        }
        out.push(byte(scene.opacity[i]));
        let q = crate::avatar::binding::normalize_quat(scene.rotation[i]);
        for c in [q.w, q.x, q.y, q.z] {
            out.push((c * 128.0 + 128.0).round().clamp(0.0, 255.0) as u8);
        }
    }
    out
}

/// Writes a scene as a `.splat` file.
pub fn write_splat(path: &Path, scene: &SplatScene) -> Result<()> {
    write_file(path, &encode_splat(scene))
}

/// The 3DGS scene formats visage reads and writes, by file extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SceneFormat {
    /// INRIA PLY (any SH degree).
    Ply,
    /// SuperSplat's compressed PLY (`.compressed.ply`).
    CompressedPly,
    /// antimatter15 `.splat`.
    Splat,
    /// Niantic's SPZ.
    Spz,
}

impl SceneFormat {
    /// The format a path's extension names.
    pub fn of(path: &Path) -> Result<SceneFormat> {
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name.to_ascii_lowercase().ends_with(".compressed.ply") {
            return Ok(SceneFormat::CompressedPly);
        }
        match path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            Some("ply") => Ok(SceneFormat::Ply),
            Some("splat") => Ok(SceneFormat::Splat),
            Some("spz") => Ok(SceneFormat::Spz),
            _ => Err(FileError::Malformed(format!(
                "{}: unknown scene format (use .ply, .compressed.ply, .splat or .spz)",
                path.display()
            ))),
        }
    }
}

/// Reads a 3DGS scene: a PLY by its `ply` magic and an SPZ by its `NGSP` or
/// gzip magic (whatever the extension), else a `.splat` by its extension (the
/// format has no header to recognise).
pub fn read_scene(path: &Path) -> Result<SplatScene> {
    read_scene_with(path, &|_, _| {})
}

/// [`read_scene`], telling `progress` how many bytes of the file it has read
/// (the fast PLY path reports every chunk; the other readers, which take the
/// file whole, report once at the end).
pub fn read_scene_with(path: &Path, progress: super::Progress) -> Result<SplatScene> {
    let mut magic = [0u8; 4];
    let read = std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read(&mut f, &mut magic))
        .map_err(|e| FileError::access("read", path, e))?;
    let magic = &magic[..read];
    let scene = if magic.starts_with(b"ply") {
        super::ply::read_splat_ply_with(path, progress)
    } else if magic == b"NGSP" || magic.starts_with(&[0x1f, 0x8b]) {
        super::spz::read_spz(path)
    } else if SceneFormat::of(path).ok() == Some(SceneFormat::Splat) {
        read_splat(path)
    } else {
        Err(FileError::Malformed(format!(
            "{}: neither a PLY (no 'ply' header), an SPZ (no 'NGSP' or gzip header) nor a .splat file",
            path.display()
        )))
    }?;
    if let Ok(meta) = std::fs::metadata(path) {
        progress(meta.len(), meta.len());
    }
    Ok(scene)
}

/// Writes a 3DGS scene in the format its extension names.
pub fn write_scene(path: &Path, scene: &SplatScene) -> Result<()> {
    match SceneFormat::of(path)? {
        SceneFormat::Ply => super::ply::write_splat_ply(path, scene),
        SceneFormat::CompressedPly => {
            write_file(path, &super::compressed_ply::encode_compressed_ply(scene))
        }
        SceneFormat::Splat => write_splat(path, scene),
        SceneFormat::Spz => super::spz::write_spz(path, scene),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Files made by other tools: plyfile wrote ring.ply, ply2splat 0.6.0
    /// converted it to ring.splat (tests/data/splat/make_splat.py). visage
    /// reads the .splat as the PLY within 8-bit quantisation, and writes bytes
    /// within one unit of ply2splat's (it rounds where ply2splat truncates).
    #[test]
    fn reads_and_writes_splat_like_ply2splat() {
        let ply = crate::io::ply::read_splat_ply(&crate::io::test_data("splat/ring.ply")).unwrap();
        let theirs = std::fs::read(crate::io::test_data("splat/ring.splat")).unwrap();
        let splat = parse_splat(&theirs).unwrap();
        assert_eq!((splat.len(), splat.sh_degree), (200, 0));
        for i in 0..ply.len() {
            assert_eq!(splat.position[i], ply.position[i]);
            assert!(
                (splat.scale[i] - ply.scale[i]).abs().max_element()
                    <= 1e-6 * ply.scale[i].max_element()
            );
            assert!(
                (splat.opacity[i] - ply.opacity[i]).abs() <= 1.0 / 255.0 + 1e-6,
                "{i}"
            );
            for c in 0..3 {
                let (a, b) = (
                    dc_to_rgb(splat.sh_of(i)[c]),
                    dc_to_rgb(ply.sh_of(i)[c]).clamp(0.0, 1.0),
                );
                assert!(
                    (a - b).abs() <= 1.0 / 255.0 + 1e-5,
                    "{i} colour {c}: {a} vs {b}"
                );
            }
            assert!(
                splat.rotation[i].dot(ply.rotation[i]).abs() > 0.995,
                "{i} rotation"
            );
        }
        let ours = encode_splat(&ply);
        assert_eq!(ours.len(), theirs.len());
        for (k, (a, b)) in ours.iter().zip(&theirs).enumerate() {
            if k % RECORD < 24 {
                assert_eq!(a, b, "byte {k}: floats are copied");
            } else {
                assert!(a.abs_diff(*b) <= 1, "byte {k}: {a} vs {b}");
            }
        }
        // Our own output reads back to itself: floats exactly, and the 8-bit
        // fields within one unit (a quantised quaternion is renormalised).
        let again = encode_splat(&parse_splat(&ours).unwrap());
        for (k, (a, b)) in again.iter().zip(&ours).enumerate() {
            let slack = if k % RECORD < 24 { 0 } else { 1 };
            assert!(a.abs_diff(*b) <= slack, "byte {k}: {a} vs {b}");
        }
    }

    #[test]
    fn broken_splat_files_are_named() {
        assert!(parse_splat(&[0u8; 33])
            .unwrap_err()
            .to_string()
            .contains("32-byte"));
        let mut nan = vec![128u8; 32];
        nan[..4].copy_from_slice(&f32::NAN.to_le_bytes());
        assert!(parse_splat(&nan)
            .unwrap_err()
            .to_string()
            .contains("Gaussian 0"));
        let mut negative = vec![128u8; 32];
        negative[12..16].copy_from_slice(&(-1.0f32).to_le_bytes());
        assert!(parse_splat(&negative)
            .unwrap_err()
            .to_string()
            .contains("negative scale"));
        // A zero quaternion and zero scale are read (as identity, as a point).
        let mut zero = vec![0u8; 32];
        zero[28..32].copy_from_slice(&[128; 4]);
        let s = parse_splat(&zero).unwrap();
        assert_eq!(s.rotation[0], Quat::IDENTITY);
        assert!(parse_splat(&[]).unwrap().is_empty());
        assert!(SceneFormat::of(Path::new("a.xyz")).is_err());
        assert_eq!(
            SceneFormat::of(Path::new("A.SPLAT")).unwrap(),
            SceneFormat::Splat
        );
    }
}
