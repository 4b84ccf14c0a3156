//! Niantic's SPZ (`.spz`), read in every version and written as version 4.
//! The layout, from the format's README and reference library
//! (github.com/nianticlabs/spz):
//!
//! - version 4: a 32-byte plain header (`NGSP`, version, count, SH degree,
//!   fractional bits, flags, stream count, offset of the table of contents),
//!   optional extension records up to that offset, a table of (compressed,
//!   uncompressed) sizes, then six zstd streams;
//! - versions 2-3: one gzip stream holding a 16-byte header and the same six
//!   arrays back to back (version 1, with f16 positions, was never released
//!   and is refused).
//!
//! The arrays, per Gaussian: position as three 24-bit signed fixed-point
//! numbers (`fractional bits` of fraction), opacity as
//! sigmoid·255, the DC colour coefficient as c·(0.15·255) + 127.5, log-scales
//! as (ln s + 10)·16, rotation (versions 3-4: the three smallest quaternion
//! components as 10-bit sign-and-magnitude numbers scaled by 1/√2 and the index
//! of the largest; before: x, y, z as 128 + 127.5·q), and the higher SH
//! coefficients (coefficient-major, colour inner, as in PLY-derived order) as
//! 128 + 128·c. Coordinates are read and written as stored: the reference
//! tools (`ply_to_spz`, `spz_to_ply`) convert none by default, so a PLY
//! converted there and back keeps its axes; `visage view --up` turns scenes
//! stored y-up (RUB, as phone captures are) upright.
//!
//! visage writes every SH coefficient with all 8 bits (the reference packer
//! drops to 5 and 4 bits by default to compress better) and chooses the
//! fractional bits so the scene's largest coordinate fits (12, a quarter
//! millimetre, when it can).

use std::io::Read;
use std::path::Path;

use glam::{Quat, Vec3};

use super::{read_file, write_file, FileError, Result};
use crate::avatar::binding::normalize_quat;
use crate::avatar::gaussians::sh_coefficients;
use crate::scene::splats::SplatScene;

/// The file magic, "NGSP" in file order.
const MAGIC: u32 = 0x5053_474e;
/// The version visage writes.
const VERSION: u32 = 4;
/// Bytes of the version-4 header.
const HEADER_V4: usize = 32;
/// Bytes of the legacy (gzip) header.
const HEADER_LEGACY: usize = 16;
/// The colour scale of the DC coefficient's byte.
const COLOR_SCALE: f32 = 0.15;
/// 1/√2: the largest magnitude a quaternion's non-largest component can have.
const SQRT1_2: f32 = std::f32::consts::FRAC_1_SQRT_2;
/// Fractional bits of positions when the scene fits (¼ mm at metre scale).
const DEFAULT_FRACTIONAL_BITS: i32 = 12;

/// What the header says about the arrays that follow.
#[derive(Clone, Copy, Debug)]
struct Layout {
    version: u32,
    count: usize,
    sh_degree: u8,
    fractional_bits: u8,
}

impl Layout {
    fn sh_per_point(&self) -> usize {
        3 * (sh_coefficients(self.sh_degree) - 1)
    }

    fn rotation_bytes(&self) -> usize {
        if self.version >= 3 {
            4
        } else {
            3
        }
    }

    /// Bytes of each array, in file order: positions, alphas, colours,
    /// scales, rotations, SH.
    fn array_bytes(&self) -> [usize; 6] {
        let n = self.count;
        [
            9 * n,
            n,
            3 * n,
            3 * n,
            n * self.rotation_bytes(),
            n * self.sh_per_point(),
        ]
    }

    fn checked(self) -> Result<Self> {
        if !(2..=VERSION).contains(&self.version) {
            return Err(format!("SPZ version {} is not 2-4", self.version).into());
        }
        if self.sh_degree > 3 {
            return Err(format!(
                "SPZ SH degree {} is beyond the 3 visage renders",
                self.sh_degree
            )
            .into());
        }
        if self.fractional_bits > 23 {
            return Err(format!(
                "{} fractional bits in 24-bit positions",
                self.fractional_bits
            )
            .into());
        }
        Ok(self)
    }
}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn u64_at(bytes: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(b)
}

/// Reads at most `expected` bytes from `source` and insists on exactly that
/// many (a count in a header cannot make visage allocate beyond the data).
fn read_exactly(source: impl Read, expected: usize, what: &str) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(expected.min(1 << 26));
    source
        .take(expected as u64 + 1)
        .read_to_end(&mut out)
        .map_err(|e| FileError::Malformed(format!("SPZ {what}: {e}")))?;
    if out.len() != expected {
        return Err(format!(
            "SPZ {what} holds {} bytes where the header implies {expected}",
            out.len()
        )
        .into());
    }
    Ok(out)
}

/// Parses SPZ bytes (any version) into a scene.
pub fn parse_spz(bytes: &[u8]) -> Result<SplatScene> {
    if bytes.len() >= 4 && u32_at(bytes, 0) == MAGIC {
        parse_v4(bytes)
    } else if bytes.starts_with(&[0x1f, 0x8b]) {
        parse_legacy(bytes)
    } else {
        Err("not an SPZ file (neither 'NGSP' nor a gzip stream)".into())
    }
}

fn parse_v4(bytes: &[u8]) -> Result<SplatScene> {
    if bytes.len() < HEADER_V4 {
        return Err("SPZ header is cut short".into());
    }
    let layout = Layout {
        version: u32_at(bytes, 4),
        count: u32_at(bytes, 8) as usize,
        sh_degree: bytes[12],
        fractional_bits: bytes[13],
    }
    .checked()?;
    if layout.version != 4 {
        return Err(format!("an uncompressed SPZ header says version {}", layout.version).into());
    }
    let streams = bytes[15] as usize;
    if streams != 6 {
        return Err(format!("SPZ has {streams} streams, not 6").into());
    }
    let toc = u32_at(bytes, 16) as usize;
    let data_start = toc
        .checked_add(streams * 16)
        .filter(|&end| toc >= HEADER_V4 && end <= bytes.len())
        .ok_or("SPZ table of contents lies outside the file")?;
    let mut arrays = Vec::with_capacity(streams);
    let mut at = data_start;
    for (k, expected) in layout.array_bytes().into_iter().enumerate() {
        let compressed = u64_at(bytes, toc + 16 * k);
        let uncompressed = u64_at(bytes, toc + 16 * k + 8);
        if uncompressed != expected as u64 {
            return Err(format!(
                "SPZ stream {k} is {uncompressed} bytes where {} Gaussians need {expected}",
                layout.count
            )
            .into());
        }
        let end = usize::try_from(compressed)
            .ok()
            .and_then(|c| at.checked_add(c))
            .filter(|&end| end <= bytes.len())
            .ok_or_else(|| {
                FileError::Malformed(format!("SPZ stream {k} runs past the end of the file"))
            })?;
        let decoder = ruzstd::decoding::StreamingDecoder::new(&bytes[at..end])
            .map_err(|e| FileError::Malformed(format!("SPZ stream {k}: {e}")))?;
        arrays.push(read_exactly(decoder, expected, &format!("stream {k}"))?);
        at = end;
    }
    if at != bytes.len() {
        return Err("SPZ has bytes after its last stream".into());
    }
    decode(layout, &arrays)
}

fn parse_legacy(bytes: &[u8]) -> Result<SplatScene> {
    let mut gz = flate2::read::GzDecoder::new(bytes);
    let mut header = [0u8; HEADER_LEGACY];
    gz.read_exact(&mut header)
        .map_err(|e| FileError::Malformed(format!("SPZ header: {e}")))?;
    if u32_at(&header, 0) != MAGIC {
        return Err("a gzip stream that is not SPZ (no 'NGSP' magic)".into());
    }
    let layout = Layout {
        version: u32_at(&header, 4),
        count: u32_at(&header, 8) as usize,
        sh_degree: header[12],
        fractional_bits: header[13],
    }
    .checked()?;
    if layout.version == 4 {
        return Err("a gzip SPZ stream says version 4".into());
    }
    let sizes = layout.array_bytes();
    let body = read_exactly(gz, sizes.iter().sum(), "data")?;
    let mut arrays = Vec::with_capacity(6);
    let mut at = 0;
    for size in sizes {
        arrays.push(body[at..at + size].to_vec());
        at += size;
    }
    decode(layout, &arrays)
}

/// The scene from the six decompressed arrays.
fn decode(layout: Layout, arrays: &[Vec<u8>]) -> Result<SplatScene> {
    let [positions, alphas, colours, scales, rotations, sh] = arrays else {
        unreachable!("six arrays are read")
    };
    let mut scene = SplatScene::with_degree(layout.sh_degree);
    let step = 1.0 / (1u32 << layout.fractional_bits) as f32;
    let rest = layout.sh_per_point();
    let mut coefficients = vec![0.0f32; 3 + rest];
    for i in 0..layout.count {
        let p = &positions[9 * i..9 * i + 9];
        let position = Vec3::from_array(std::array::from_fn(|k| {
            let raw =
                i32::from(p[3 * k]) | i32::from(p[3 * k + 1]) << 8 | i32::from(p[3 * k + 2]) << 16;
            // Sign-extend the 24-bit number.
            ((raw << 8) >> 8) as f32 * step
        }));
        if !position.is_finite() {
            return Err(format!("Gaussian {i} has a NaN or infinite position").into());
        }
        let scale = Vec3::from_array(std::array::from_fn(|k| {
            (f32::from(scales[3 * i + k]) / 16.0 - 10.0).exp()
        }));
        let rotation = if layout.version >= 3 {
            let r = &rotations[4 * i..4 * i + 4];
            smallest_three_decode(u32::from_le_bytes([r[0], r[1], r[2], r[3]]))
        } else {
            let r = &rotations[3 * i..3 * i + 3];
            let xyz = Vec3::from_array(std::array::from_fn(|k| f32::from(r[k]) / 127.5 - 1.0));
            Quat::from_xyzw(
                xyz.x,
                xyz.y,
                xyz.z,
                (1.0 - xyz.length_squared()).max(0.0).sqrt(),
            )
        };
        for k in 0..3 {
            coefficients[k] = (f32::from(colours[3 * i + k]) / 255.0 - 0.5) / COLOR_SCALE;
        }
        for (c, &b) in coefficients[3..]
            .iter_mut()
            .zip(&sh[rest * i..rest * (i + 1)])
        {
            *c = (f32::from(b) - 128.0) / 128.0;
        }
        let opacity = f32::from(alphas[i]) / 255.0;
        scene.push(position, rotation, scale, opacity, &coefficients);
    }
    Ok(scene)
}

/// A unit quaternion from its "smallest three" encoding: bits 30-31 name the
/// largest component (x, y, z, w = 0-3), and the other three, from w down,
/// take 10 bits each from the bottom (a sign bit over 9 of magnitude).
fn smallest_three_decode(mut comp: u32) -> Quat {
    let largest = (comp >> 30) as usize;
    let mut q = [0.0f32; 4];
    let mut sum = 0.0;
    for i in (0..4).rev().filter(|&i| i != largest) {
        let magnitude = SQRT1_2 * (comp & 0x1ff) as f32 / 511.0;
        q[i] = if (comp >> 9) & 1 == 1 {
            -magnitude
        } else {
            magnitude
        };
        sum += q[i] * q[i];
        comp >>= 10;
    }
    q[largest] = (1.0 - sum).max(0.0).sqrt();
    Quat::from_xyzw(q[0], q[1], q[2], q[3])
}

/// The "smallest three" encoding of a rotation (normalised first; the sign
/// is chosen so the largest component is positive, as q and −q agree).
fn smallest_three_encode(rotation: Quat) -> u32 {
    let q = normalize_quat(rotation).to_array();
    let largest = (1..4).fold(
        0,
        |best, i| if q[i].abs() > q[best].abs() { i } else { best },
    );
    let negate = q[largest] < 0.0;
    let mut comp = largest as u32;
    for (_, &c) in q.iter().enumerate().filter(|&(i, _)| i != largest) {
        let sign = u32::from((c < 0.0) != negate);
        let magnitude = ((511.0 * c.abs() / SQRT1_2 + 0.5) as u32).min(511);
        comp = (comp << 10) | (sign << 9) | magnitude;
    }
    comp
}

/// A byte from a value meant to be in 0..=255, rounded.
fn byte(x: f32) -> u8 {
    x.round().clamp(0.0, 255.0) as u8
}

/// Fractional bits that fit the scene's largest coordinate in 24 bits.
fn fractional_bits_for(scene: &SplatScene) -> Result<u8> {
    let largest = scene
        .position
        .iter()
        .map(|p| p.abs().max_element())
        .fold(0.0f32, f32::max);
    let mut bits = DEFAULT_FRACTIONAL_BITS;
    while bits >= 0 && (largest * (1u32 << bits) as f32).round() >= (1 << 23) as f32 {
        bits -= 1;
    }
    u8::try_from(bits).map_err(|_| {
        FileError::Malformed(format!(
            "a coordinate of {largest} is beyond the ±8,388,607 SPZ's 24-bit positions hold"
        ))
    })
}

/// Encodes a scene as SPZ version 4.
pub fn encode_spz(scene: &SplatScene) -> Result<Vec<u8>> {
    if let Some(i) = (0..scene.len()).find(|&i| !scene.position[i].is_finite()) {
        return Err(format!("Gaussian {i} has a NaN or infinite position").into());
    }
    let count = u32::try_from(scene.len())
        .map_err(|_| FileError::Malformed("too many Gaussians for SPZ".into()))?;
    let fractional_bits = fractional_bits_for(scene)?;
    let layout = Layout {
        version: VERSION,
        count: scene.len(),
        sh_degree: scene.sh_degree,
        fractional_bits,
    };
    let arrays = encode_arrays(scene, layout);
    let mut out = Vec::new();
    out.extend_from_slice(&MAGIC.to_le_bytes());
    out.extend_from_slice(&VERSION.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&[scene.sh_degree, fractional_bits, 0, 6]);
    out.extend_from_slice(&(HEADER_V4 as u32).to_le_bytes());
    out.extend_from_slice(&[0u8; 12]);
    let compressed: Vec<Vec<u8>> = arrays
        .iter()
        .map(|a| {
            ruzstd::encoding::compress_to_vec(&a[..], ruzstd::encoding::CompressionLevel::Fastest)
        })
        .collect();
    for (a, c) in arrays.iter().zip(&compressed) {
        out.extend_from_slice(&(c.len() as u64).to_le_bytes());
        out.extend_from_slice(&(a.len() as u64).to_le_bytes());
    }
    for c in compressed {
        out.extend_from_slice(&c);
    }
    Ok(out)
}

/// The six arrays of a scene, uncompressed.
fn encode_arrays(scene: &SplatScene, layout: Layout) -> [Vec<u8>; 6] {
    let [p, a, c, s, r, h] = layout.array_bytes();
    let mut arrays = [p, a, c, s, r, h].map(Vec::with_capacity);
    let [positions, alphas, colours, scales, rotations, sh] = &mut arrays;
    let unit = (1u32 << layout.fractional_bits) as f32;
    for i in 0..scene.len() {
        for x in scene.position[i].to_array() {
            let fixed = (x * unit).round() as i32;
            positions.extend_from_slice(&fixed.to_le_bytes()[..3]);
        }
        alphas.push(byte(scene.opacity[i] * 255.0));
        let coefficients = scene.sh_of(i);
        for &dc in &coefficients[..3] {
            colours.push(byte(dc * (COLOR_SCALE * 255.0) + 127.5));
        }
        for x in scene.scale[i].to_array() {
            scales.push(byte((x.max(0.0).ln() + 10.0) * 16.0));
        }
        rotations.extend_from_slice(&smallest_three_encode(scene.rotation[i]).to_le_bytes());
        sh.extend(coefficients[3..].iter().map(|&c| byte(c * 128.0 + 128.0)));
    }
    arrays
}

/// Reads an SPZ file.
pub fn read_spz(path: &Path) -> Result<SplatScene> {
    parse_spz(&read_file(path)?).map_err(|e| e.in_file(path))
}

/// Writes a scene as an SPZ file (version 4).
pub fn write_spz(path: &Path, scene: &SplatScene) -> Result<()> {
    write_file(path, &encode_spz(scene).map_err(|e| e.in_file(path))?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(name: &str) -> std::path::PathBuf {
        crate::io::test_data("splat").join(name)
    }

    /// The same Gaussians within f32 rounding of the decoders' arithmetic
    /// (visage keeps opacity and scale linear where the library goes through
    /// logit and log).
    fn assert_same(ours: &SplatScene, theirs: &SplatScene, what: &str) {
        assert_eq!(
            (ours.len(), ours.sh_degree),
            (theirs.len(), theirs.sh_degree),
            "{what}"
        );
        for i in 0..ours.len() {
            assert!(
                (ours.position[i] - theirs.position[i]).abs().max_element() <= 1e-6,
                "{what}: position {i}"
            );
            assert!(
                ((ours.scale[i] - theirs.scale[i]) / theirs.scale[i])
                    .abs()
                    .max_element()
                    <= 1e-5,
                "{what}: scale {i}"
            );
            assert!(
                (ours.opacity[i] - theirs.opacity[i]).abs() <= 1e-5,
                "{what}: opacity {i}"
            );
            assert!(
                ours.rotation[i].dot(theirs.rotation[i]).abs() >= 1.0 - 1e-6,
                "{what}: rotation {i}"
            );
            for (k, (a, b)) in ours.sh_of(i).iter().zip(theirs.sh_of(i)).enumerate() {
                assert!((a - b).abs() <= 1e-5, "{what}: SH {k} of {i}: {a} vs {b}");
            }
        }
    }

    /// Files Niantic's library wrote (version 4 from `ply_to_spz`, the gzip
    /// versions 3 and 2 through `spz_version.cc`; tests/data/splat/make_spz.sh)
    /// read as the library itself decodes them (`spz_to_ply`).
    #[test]
    fn reads_spz_as_niantics_library_decodes_it() {
        let ply = |name: &str| crate::io::ply::read_splat_ply(&data(name)).unwrap();
        for (file, decoded) in [
            ("ring3.spz", "ring3.spz.decoded.ply"),
            ("ring3.v3.spz", "ring3.spz.decoded.ply"),
            ("ring.v2.spz", "ring.v2.spz.decoded.ply"),
        ] {
            assert_same(&read_spz(&data(file)).unwrap(), &ply(decoded), file);
        }
        // And close to the PLY they were made from (the library's 8-bit
        // colour, 5- and 4-bit SH).
        let source = ply("ring3.ply");
        let spz = read_spz(&data("ring3.spz")).unwrap();
        for i in 0..source.len() {
            assert!((spz.position[i] - source.position[i]).abs().max_element() <= 0.5 / 4096.0);
        }
    }

    /// What visage writes, Niantic's library reads to the values visage
    /// reads back itself (ring3.visage.spz.decoded.ply is `spz_to_ply` of
    /// visage's conversion of ring3.ply), and the writer is deterministic.
    #[test]
    fn niantics_library_reads_what_visage_writes() {
        let source = crate::io::ply::read_splat_ply(&data("ring3.ply")).unwrap();
        let bytes = encode_spz(&source).unwrap();
        assert_eq!(bytes, encode_spz(&source).unwrap());
        let ours = parse_spz(&bytes).unwrap();
        let theirs = crate::io::ply::read_splat_ply(&data("ring3.visage.spz.decoded.ply")).unwrap();
        assert_same(&ours, &theirs, "visage's SPZ");
        // 8-bit SH: within half a step of the source (clamped to ±1).
        for i in 0..source.len() {
            for (a, b) in ours.sh_of(i)[3..].iter().zip(&source.sh_of(i)[3..]) {
                assert!((a - b.clamp(-1.0, 127.0 / 128.0)).abs() <= 0.5 / 128.0 + 1e-6);
            }
        }
    }

    /// Coordinates beyond what 12 fractional bits hold take fewer, up to the
    /// 24-bit limit; beyond it, and for NaN, writing fails with a message.
    #[test]
    fn large_coordinates_trade_fraction_bits_and_overflow_is_an_error() {
        let mut scene = SplatScene::with_degree(0);
        let dc = [0.1, 0.2, 0.3];
        scene.push(
            Vec3::new(5000.0, -1.25, 0.5),
            Quat::IDENTITY,
            Vec3::splat(0.01),
            0.5,
            &dc,
        );
        let back = parse_spz(&encode_spz(&scene).unwrap()).unwrap();
        assert!((back.position[0] - scene.position[0]).abs().max_element() <= 1.0 / 1024.0);
        scene.position[0].x = 9.0e6;
        let e = encode_spz(&scene).unwrap_err().to_string();
        assert!(e.contains("24-bit"), "{e}");
        scene.position[0].x = f32::NAN;
        assert!(encode_spz(&scene).unwrap_err().to_string().contains("NaN"));
    }

    /// Cut, inflated and mislabelled files are refused with a message, never
    /// a panic or an allocation the header asks for.
    #[test]
    fn corrupted_spz_is_an_error() {
        let good = std::fs::read(data("ring3.spz")).unwrap();
        let legacy = std::fs::read(data("ring3.v3.spz")).unwrap();
        let mut huge = good.clone();
        huge[8..12].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut degree = good.clone();
        degree[12] = 4;
        let mut toc = good.clone();
        toc[16..20].copy_from_slice(&u32::MAX.to_le_bytes());
        let mut stream = good.clone();
        stream[HEADER_V4 + 96 + 4] ^= 0xff;
        for (what, bytes) in [
            ("cut", &good[..good.len() - 10]),
            ("header only", &good[..20]),
            ("count", &huge[..]),
            ("degree", &degree[..]),
            ("toc", &toc[..]),
            ("stream", &stream[..]),
            ("legacy cut", &legacy[..legacy.len() / 2]),
            ("not spz", b"hello world"),
            (
                "gzip of something else",
                &{
                    let mut e =
                        flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
                    std::io::Write::write_all(&mut e, &[7u8; 64]).unwrap();
                    e.finish().unwrap()
                }[..],
            ),
        ] {
            assert!(parse_spz(bytes).is_err(), "{what} was accepted");
        }
        // Any byte of the header and table of contents changed: an answer
        // (scene or error), never a panic.
        for at in 0..HEADER_V4 + 96 {
            for flip in [0x01, 0x80, 0xff] {
                let mut bytes = good.clone();
                bytes[at] ^= flip;
                let _ = parse_spz(&bytes);
            }
        }
    }
}
