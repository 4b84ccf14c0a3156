//! numpy `.npy` (format versions 1.0-3.0) and `.npz` (zip archives of `.npy`,
//! stored or deflated) reading and writing. Reads are bounded: array sizes must
//! match the bytes present, and an archive may not inflate to more than
//! [`MAX_INFLATION`] times its own size or [`MIN_INFLATION_BUDGET`], whichever
//! is larger.

use std::collections::BTreeMap;
use std::io::{Cursor, Read, Write};
use std::path::Path;

use super::pickle::{Dtype, NdArray};

/// How much larger than the archive its members may inflate (zip-bomb guard)…
pub const MAX_INFLATION: u64 = 64;
/// …beyond a floor that any archive may inflate to: GaussianAvatars'
/// `dynamic_offset` is all zeros, which deflate shrinks about 1000×, and a
/// (T, 5143, 3) float32 array of a few thousand frames is this large.
pub const MIN_INFLATION_BUDGET: u64 = 256 << 20;

const MAGIC: &[u8] = b"\x93NUMPY";

/// Parses the header dict `{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }`.
fn parse_header(text: &str) -> Result<(Dtype, bool, bool, Vec<usize>), String> {
    let text = text.trim().trim_end_matches(',');
    let body = text
        .strip_prefix('{')
        .and_then(|t| t.trim_end().trim_end_matches(',').strip_suffix('}'))
        .ok_or("npy header is not a dict")?;
    let value_of = |key: &str| -> Result<&str, String> {
        let k1 = format!("'{key}'");
        let k2 = format!("\"{key}\"");
        let at = body
            .find(&k1)
            .or_else(|| body.find(&k2))
            .ok_or_else(|| format!("npy header has no '{key}'"))?;
        let rest = body[at + k1.len()..].trim_start();
        let rest = rest
            .strip_prefix(':')
            .ok_or("npy header is malformed")?
            .trim_start();
        Ok(rest)
    };
    let descr_rest = value_of("descr")?;
    let quote = descr_rest.chars().next().ok_or("npy descr is empty")?;
    if quote != '\'' && quote != '"' {
        return Err("npy descr is not a simple type (structured arrays are not supported)".into());
    }
    let descr = &descr_rest[1..descr_rest[1..]
        .find(quote)
        .ok_or("npy descr is not closed")?
        + 1];
    let (big, code) = match descr.as_bytes().first() {
        Some(b'>') => (true, &descr[1..]),
        Some(b'<' | b'|' | b'=') => (false, &descr[1..]),
        _ => (false, descr),
    };
    let dtype = Dtype::parse(code).ok_or_else(|| {
        format!(
            "npy dtype '{}' is not supported",
            crate::text::printable(descr)
        )
    })?;
    let fortran = value_of("fortran_order")?.starts_with("True");
    let shape_rest = value_of("shape")?;
    let inner = shape_rest
        .strip_prefix('(')
        .and_then(|r| r.split_once(')'))
        .map(|(i, _)| i)
        .ok_or("npy shape is not a tuple")?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>().map_err(|_| {
                format!(
                    "npy shape entry '{}' is not a size",
                    crate::text::printable(s)
                )
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((dtype, big, fortran, shape))
}

/// Parses `.npy` bytes.
pub fn parse_npy(bytes: &[u8]) -> super::Result<NdArray> {
    if !bytes.starts_with(MAGIC) || bytes.len() < 10 {
        return Err("not a .npy array (bad magic)".into());
    }
    let major = bytes[6];
    let (header_len, start): (usize, usize) = match major {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 => {
            if bytes.len() < 12 {
                return Err("npy header is truncated".into());
            }
            (
                u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
                12,
            )
        }
        v => return Err(format!("npy format version {v} is not supported").into()),
    };
    let end = start
        .checked_add(header_len)
        .filter(|&e| e <= bytes.len())
        .ok_or("npy header is truncated")?;
    let header = std::str::from_utf8(&bytes[start..end]).map_err(|_| "npy header is not text")?;
    let (dtype, big, fortran, shape) = parse_header(header)?;
    Ok(NdArray::from_bytes(
        shape,
        dtype,
        big,
        fortran,
        &bytes[end..],
    )?)
}

/// Element data to write: f32, f64 or i32/u32 values.
#[derive(Clone, Copy, Debug)]
pub enum NpyData<'a> {
    /// float32
    F32(&'a [f32]),
    /// float64
    F64(&'a [f64]),
    /// int32
    I32(&'a [i32]),
    /// uint32
    U32(&'a [u32]),
}

/// Serialises an array as `.npy` version 1.0 (C order, little endian).
pub fn write_npy(shape: &[usize], data: NpyData) -> Vec<u8> {
    let (descr, raw): (&str, Vec<u8>) = match data {
        NpyData::F32(d) => ("<f4", d.iter().flat_map(|x| x.to_le_bytes()).collect()),
        NpyData::F64(d) => ("<f8", d.iter().flat_map(|x| x.to_le_bytes()).collect()),
        NpyData::I32(d) => ("<i4", d.iter().flat_map(|x| x.to_le_bytes()).collect()),
        NpyData::U32(d) => ("<u4", d.iter().flat_map(|x| x.to_le_bytes()).collect()),
    };
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_text}, }}");
    // Pad so the data starts on a 64-byte boundary, header ends with a newline.
    while (MAGIC.len() + 4 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = Vec::with_capacity(MAGIC.len() + 4 + header.len() + raw.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(&raw);
    out
}

/// Parses `.npz` bytes into arrays by name (without the `.npy` suffix).
pub fn parse_npz(bytes: &[u8]) -> super::Result<BTreeMap<String, NdArray>> {
    Ok(parse_npz_within(bytes, MIN_INFLATION_BUDGET)?)
}

/// [`parse_npz`] with the inflation floor given.
fn parse_npz_within(bytes: &[u8], floor: u64) -> Result<BTreeMap<String, NdArray>, String> {
    let mut archive = zip::ZipArchive::new(Cursor::new(bytes))
        .map_err(|e| format!("not a valid .npz archive: {e}"))?;
    let budget = (bytes.len() as u64)
        .saturating_mul(MAX_INFLATION)
        .max(floor);
    let mut used = 0u64;
    let mut out = BTreeMap::new();
    for i in 0..archive.len() {
        let mut file = archive
            .by_index(i)
            .map_err(|e| format!("cannot read .npz member {i}: {e}"))?;
        let name = file
            .name()
            .map_err(|e| format!("bad .npz member name: {e}"))?
            .trim_end_matches(".npy")
            .to_string();
        let mut data = Vec::new();
        // Read at most what the budget allows, whatever the header claims.
        let limit = budget - used;
        file.by_ref()
            .take(limit + 1)
            .read_to_end(&mut data)
            .map_err(|e| {
                format!(
                    "cannot inflate .npz member '{}': {e}",
                    crate::text::printable(&name)
                )
            })?;
        used += data.len() as u64;
        if used > budget {
            return Err(format!(
                ".npz inflates to more than {} MiB (and {MAX_INFLATION}× its size)",
                budget >> 20
            ));
        }
        let array =
            parse_npy(&data).map_err(|e| format!("'{}': {e}", crate::text::printable(&name)))?;
        out.insert(name, array);
    }
    Ok(out)
}

/// Reads a `.npz` file.
pub fn read_npz(path: &Path) -> super::Result<BTreeMap<String, NdArray>> {
    let bytes = super::read_file(path)?;
    parse_npz(&bytes).map_err(|e| e.in_file(path))
}

/// Writes arrays as a `.npz` archive; `compress` deflates the members (numpy's
/// `savez_compressed`), otherwise they are stored (`savez`).
pub fn write_npz(path: &Path, arrays: &[(&str, Vec<u8>)], compress: bool) -> super::Result<()> {
    let file =
        std::fs::File::create(path).map_err(|e| super::FileError::access("write", path, e))?;
    let mut zip = zip::ZipWriter::new(file);
    let method = if compress {
        zip::CompressionMethod::Deflated
    } else {
        zip::CompressionMethod::Stored
    };
    let options = zip::write::SimpleFileOptions::default()
        .compression_method(method)
        .large_file(false);
    for (name, npy) in arrays {
        zip.start_file(format!("{name}.npy"), options)
            .and_then(|_| zip.write_all(npy).map_err(Into::into))
            .map_err(|e| super::FileError::access("write", path, e))?;
    }
    zip.finish()
        .map_err(|e| super::FileError::access("write", path, e))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npy_round_trip_and_versions() {
        let bytes = write_npy(&[2, 3], NpyData::F32(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]));
        let a = parse_npy(&bytes).unwrap();
        assert_eq!(a.shape, vec![2, 3]);
        assert_eq!(a.data, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(bytes.len() % 64, 24, "data starts 64-aligned");
        // Version 2.0 header, big endian, Fortran order.
        let header = "{'descr': '>i2', 'fortran_order': True, 'shape': (2, 2), }\n";
        let mut v2 = MAGIC.to_vec();
        v2.extend_from_slice(&[2, 0]);
        v2.extend_from_slice(&(header.len() as u32).to_le_bytes());
        v2.extend_from_slice(header.as_bytes());
        for x in [1i16, 2, 3, 4] {
            v2.extend_from_slice(&x.to_be_bytes());
        }
        let b = parse_npy(&v2).unwrap();
        // Fortran [[1,3],[2,4]] in C order.
        assert_eq!(b.data, vec![1.0, 3.0, 2.0, 4.0]);
    }

    /// Deflated zeros (what GaussianAvatars' dynamic_offset is) inflate
    /// about 1000×: accepted up to the floor, refused past it.
    #[test]
    fn npz_inflation_is_bounded() {
        let zeros = vec![0.0f32; 1 << 20]; // 4 MiB
        let dir = std::env::temp_dir().join(format!("visage-npz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("zeros.npz");
        write_npz(
            &path,
            &[("z", write_npy(&[1 << 20], NpyData::F32(&zeros)))],
            true,
        )
        .unwrap();
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(
            bytes.len() * 64 < 4 << 20,
            "deflate shrinks zeros more than 64×"
        );
        assert_eq!(parse_npz(&bytes).unwrap()["z"].data.len(), 1 << 20);
        let e = parse_npz_within(&bytes, 1 << 20).unwrap_err().to_string();
        assert!(e.contains("inflates to more than 1 MiB"), "{e}");
    }

    #[test]
    fn npy_rejects_lies() {
        let mut bytes = write_npy(&[4], NpyData::F64(&[1.0, 2.0, 3.0, 4.0]));
        bytes.truncate(bytes.len() - 3);
        assert!(parse_npy(&bytes).unwrap_err().to_string().contains("needs"));
        let huge = write_npy(&[1], NpyData::F64(&[1.0]));
        let text = String::from_utf8_lossy(&huge).replace("(1,)", "(9999999999999,)");
        assert!(parse_npy(text.as_bytes()).is_err());
        assert!(parse_npy(b"\x93NUMPY\x07\x00").is_err());
        let object = "{'descr': '|O', 'fortran_order': False, 'shape': (1,), }\n";
        let mut o = MAGIC.to_vec();
        o.extend_from_slice(&[1, 0]);
        o.extend_from_slice(&(object.len() as u16).to_le_bytes());
        o.extend_from_slice(object.as_bytes());
        assert!(parse_npy(&o)
            .unwrap_err()
            .to_string()
            .contains("not supported"));
    }

    #[test]
    fn npz_stored_and_deflated() {
        for compress in [false, true] {
            let path = std::env::temp_dir()
                .join(format!("visage-npz-{}-{compress}.npz", std::process::id()));
            let a = write_npy(&[3], NpyData::F32(&[0.5, 1.5, 2.5]));
            let b = write_npy(&[2, 2], NpyData::I32(&[1, 2, 3, 4]));
            write_npz(&path, &[("expr", a), ("shape", b)], compress).unwrap();
            let arrays = read_npz(&path).unwrap();
            std::fs::remove_file(&path).ok();
            assert_eq!(arrays["expr"].data, vec![0.5, 1.5, 2.5]);
            assert_eq!(arrays["shape"].shape, vec![2, 2]);
        }
        assert!(parse_npz(b"PK\x03\x04garbage").is_err());
    }
}
