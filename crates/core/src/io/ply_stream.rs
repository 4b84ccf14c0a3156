//! The fast path for the PLYs 3DGS trainers write: one `vertex` element of
//! float32 properties, binary little endian. The file is read in chunks of
//! whole rows and each chunk is decoded in parallel straight into the scene's
//! arrays, so a scene of a million Gaussians loads in a fraction of a second
//! and the memory it takes is the scene plus one chunk (the general reader
//! holds the whole file and every column as f64 as well). Anything else goes
//! to the general reader.

use std::io::Read;
use std::path::Path;
use std::sync::Arc;

use glam::{Quat, Vec3};
use rayon::prelude::*;

use super::ply::{parse_header, Element, PlyFormat, ScalarType, MAX_HEADER};
use super::{FileError, Progress, Result};
use crate::avatar::gaussians::{sh_coefficients, sh_degree_for, sigmoid};
use crate::scene::splats::SplatScene;

/// Bytes read (and decoded in parallel) at a time.
const CHUNK_BYTES: usize = 16 << 20;

/// Byte offsets of the properties a scene needs within one row.
struct Layout {
    row: usize,
    position: [usize; 3],
    dc: [usize; 3],
    rest: Vec<usize>,
    opacity: usize,
    scale: [usize; 3],
    rotation: [usize; 4],
}

impl Layout {
    /// The layout when the element is all float32 and has every property;
    /// None sends the file to the general reader (which names what is wrong).
    fn of(element: &Element) -> Option<Layout> {
        if element.name != "vertex"
            || element
                .properties
                .iter()
                .any(|p| p.list_count.is_some() || p.ty != ScalarType::Float)
        {
            return None;
        }
        let at = |name: &str| {
            element
                .properties
                .iter()
                .position(|p| p.name == name)
                .map(|k| 4 * k)
        };
        let rest_count = (0..)
            .take_while(|k| at(&format!("f_rest_{k}")).is_some())
            .count();
        sh_degree_for(1 + rest_count / 3).filter(|_| rest_count % 3 == 0)?;
        Some(Layout {
            row: 4 * element.properties.len(),
            position: [at("x")?, at("y")?, at("z")?],
            dc: [at("f_dc_0")?, at("f_dc_1")?, at("f_dc_2")?],
            rest: (0..rest_count)
                .map(|k| at(&format!("f_rest_{k}")))
                .collect::<Option<_>>()?,
            opacity: at("opacity")?,
            scale: [at("scale_0")?, at("scale_1")?, at("scale_2")?],
            rotation: [at("rot_0")?, at("rot_1")?, at("rot_2")?, at("rot_3")?],
        })
    }
}

fn f32_at(row: &[u8], at: usize) -> f32 {
    f32::from_le_bytes([row[at], row[at + 1], row[at + 2], row[at + 3]])
}

/// A 3DGS PLY read front to back in chunks of whole rows, each decoded in
/// parallel: what [`read_fast`] fills a whole scene from, and what a build
/// that must not hold the scene (the level-of-detail cache of a scene larger
/// than memory) reads once per pass, [`PlyStream::rewind`] starting the next.
pub struct PlyStream {
    file: std::fs::File,
    path: std::path::PathBuf,
    layout: Layout,
    rows: usize,
    /// Byte offset of the first row.
    body: usize,
    file_len: u64,
    degree: u8,
    /// Rows decoded in this pass.
    done: usize,
    /// Body bytes read but not yet decoded.
    pending: Vec<u8>,
}

impl PlyStream {
    /// Opens `path` for streaming; `Ok(None)` when the file is not of the
    /// kind the fast path handles (the general reader then names what is
    /// wrong with it, or reads it).
    pub fn open(path: &Path) -> Result<Option<PlyStream>> {
        let access = |e| FileError::access("read", path, e);
        let mut file = std::fs::File::open(path).map_err(access)?;
        // As much as the general reader accepts: a header of long comments
        // (editors record their settings there) must not send a file of
        // any size to the reader that holds it whole.
        let mut head = vec![0u8; MAX_HEADER + 2];
        let n = read_up_to(&mut file, &mut head).map_err(access)?;
        head.truncate(n);
        let Ok((PlyFormat::BinaryLittleEndian, elements, body)) = parse_header(&head) else {
            return Ok(None);
        };
        let [element] = elements.as_slice() else {
            return Ok(None);
        };
        let Some(layout) = Layout::of(element) else {
            return Ok(None);
        };
        let rows = element.count;
        let file_len = file.metadata().map_err(access)?.len();
        let need = (rows as u64)
            .checked_mul(layout.row as u64)
            .and_then(|b| b.checked_add(body as u64));
        if need.is_none_or(|need| need > file_len) {
            return Err(FileError::Malformed(format!(
                "{}: PLY header claims {rows} vertices, more than the file holds",
                path.display()
            )));
        }
        let degree = sh_degree_for(1 + layout.rest.len() / 3).expect("checked by the layout");
        Ok(Some(PlyStream {
            file,
            path: path.to_path_buf(),
            layout,
            rows,
            body,
            file_len,
            degree,
            done: 0,
            pending: head[body.min(head.len())..].to_vec(),
        }))
    }

    /// The file read.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Gaussians in the file.
    pub fn len(&self) -> usize {
        self.rows
    }

    /// True for a file of no Gaussians.
    pub fn is_empty(&self) -> bool {
        self.rows == 0
    }

    /// SH degree of every Gaussian.
    pub fn sh_degree(&self) -> u8 {
        self.degree
    }

    /// The file's size in bytes.
    pub fn file_len(&self) -> u64 {
        self.file_len
    }

    /// Bytes of the file read so far in this pass (header included).
    pub fn bytes_done(&self) -> u64 {
        (self.body + self.done * self.layout.row) as u64
    }

    /// Rows decoded so far in this pass: the index of the next chunk's first.
    pub fn rows_done(&self) -> usize {
        self.done
    }

    /// Starts another pass from the first row.
    pub fn rewind(&mut self) -> Result<()> {
        use std::io::{Seek, SeekFrom};
        self.file
            .seek(SeekFrom::Start(self.body as u64))
            .map_err(|e| FileError::access("read", &self.path, e))?;
        self.pending.clear();
        self.done = 0;
        Ok(())
    }

    /// The next chunk of rows as a scene of their own; None at the end of
    /// the file.
    pub fn next_chunk(&mut self) -> Result<Option<SplatScene>> {
        let take = self.rows_per_chunk().min(self.rows - self.done);
        if take == 0 {
            return Ok(None);
        }
        let mut chunk = SplatScene::with_degree(self.degree);
        chunk.resize_zeroed(take);
        self.decode_next(&mut chunk, 0, take)?;
        Ok(Some(chunk))
    }

    fn rows_per_chunk(&self) -> usize {
        (CHUNK_BYTES / self.layout.row).max(1)
    }

    /// Decodes the next `take` rows into `scene` from row `at`.
    fn decode_next(&mut self, scene: &mut SplatScene, at: usize, take: usize) -> Result<()> {
        let bytes = take * self.layout.row;
        if self.pending.len() < bytes {
            let have = self.pending.len();
            self.pending.resize(bytes, 0);
            self.file
                .read_exact(&mut self.pending[have..])
                .map_err(|e| FileError::access("read", &self.path, e))?;
        }
        let stride = 3 * sh_coefficients(self.degree);
        let rows = Rows {
            bytes: &self.pending[..bytes],
            first_in_file: self.done,
        };
        decode_rows(&self.layout, rows, at, stride, scene)
            .map_err(|e| FileError::Malformed(format!("{}: {e}", self.path.display())))?;
        self.pending.drain(..bytes);
        self.done += take;
        Ok(())
    }
}

/// Reads a 3DGS PLY through the fast path; `Ok(None)` when the file is not of
/// the kind it handles. `progress` hears (bytes read, file size) after each chunk.
pub fn read_fast(path: &Path, progress: Progress) -> Result<Option<SplatScene>> {
    let Some(mut stream) = PlyStream::open(path)? else {
        return Ok(None);
    };
    let rows = stream.len();
    let mut scene = SplatScene::with_degree(stream.sh_degree());
    scene.resize_zeroed(rows);
    while stream.rows_done() < rows {
        let at = stream.rows_done();
        let take = stream.rows_per_chunk().min(rows - at);
        stream.decode_next(&mut scene, at, take)?;
        progress(stream.bytes_done(), stream.file_len());
    }
    Ok(Some(scene))
}

/// Whole rows of the file, and the index of the first.
struct Rows<'a> {
    bytes: &'a [u8],
    first_in_file: usize,
}

/// Fills `scene` rows `first..first + rows.bytes.len() / row` from `rows`, in parallel.
fn decode_rows(
    layout: &Layout,
    rows: Rows<'_>,
    first: usize,
    stride: usize,
    scene: &mut SplatScene,
) -> std::result::Result<(), String> {
    let Rows {
        bytes,
        first_in_file,
    } = rows;
    let count = bytes.len() / layout.row;
    let range = first..first + count;
    let per_channel = layout.rest.len() / 3;
    bytes
        .par_chunks(layout.row)
        .zip(scene.position[range.clone()].par_iter_mut())
        .zip(scene.rotation[range.clone()].par_iter_mut())
        .zip(scene.scale[range.clone()].par_iter_mut())
        .zip(scene.opacity[range.clone()].par_iter_mut())
        .zip(
            Arc::make_mut(&mut scene.sh)[first * stride..(first + count) * stride]
                .par_chunks_mut(stride),
        )
        .enumerate()
        .try_for_each(
            |(k, (((((row, position), rotation), scale), opacity), sh))| {
                let f = |at: usize| f32_at(row, at);
                let v3 = |a: [usize; 3]| Vec3::new(f(a[0]), f(a[1]), f(a[2]));
                let (p, log_scale, o) = (v3(layout.position), v3(layout.scale), f(layout.opacity));
                let q = [
                    f(layout.rotation[0]),
                    f(layout.rotation[1]),
                    f(layout.rotation[2]),
                    f(layout.rotation[3]),
                ];
                for ch in 0..3 {
                    sh[ch] = f(layout.dc[ch]);
                    for j in 0..per_channel {
                        sh[(j + 1) * 3 + ch] = f(layout.rest[ch * per_channel + j]);
                    }
                }
                let finite = p.is_finite()
                    && log_scale.is_finite()
                    && o.is_finite()
                    && q.iter().all(|x| x.is_finite())
                    && sh.iter().all(|x| x.is_finite());
                if !finite {
                    return Err(format!(
                        "Gaussian {} has a NaN or infinite value",
                        first_in_file + k
                    ));
                }
                *position = p;
                // Files store w x y z, not normalised.
                *rotation =
                    crate::avatar::binding::normalize_quat(Quat::from_xyzw(q[1], q[2], q[3], q[0]));
                *scale = log_scale.exp();
                *opacity = sigmoid(o);
                Ok(())
            },
        )
}

/// Reads until `buf` is full or the file ends; returns the bytes read.
fn read_up_to(file: &mut std::fs::File, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match file.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast path reads what the general reader reads, bit for bit, on a
    /// file written by plyfile (tests/data/splat/ring.ply) and on our own
    /// SH-degree-3 output; other files fall back.
    #[test]
    fn fast_path_matches_the_general_reader() {
        let ring = &crate::io::test_data("splat/ring.ply");
        let fast = read_fast(ring, &|_, _| {})
            .unwrap()
            .expect("plyfile's float32 PLY takes the fast path");
        let general = crate::io::ply::parse_splat_ply(&std::fs::read(ring).unwrap()).unwrap();
        assert_eq!(fast, general);
        let dir = std::env::temp_dir().join(format!("visage-ply-stream-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let big = dir.join("sh3.ply");
        let scene = crate::scene::synthetic::synthetic_scene(70_000, 4);
        crate::io::ply::write_splat_ply(&big, &scene).unwrap();
        let heard = std::sync::Mutex::new(Vec::new());
        let fast = read_fast(&big, &|done, all| heard.lock().unwrap().push((done, all)))
            .unwrap()
            .unwrap();
        // Progress comes chunk by chunk, grows, and ends at the file's size.
        let heard = heard.into_inner().unwrap();
        let size = std::fs::metadata(&big).unwrap().len();
        assert!(heard.len() >= 2, "{heard:?}");
        assert!(heard.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 == size));
        assert_eq!(heard.last(), Some(&(size, size)));
        let general = crate::io::ply::parse_splat_ply(&std::fs::read(&big).unwrap()).unwrap();
        assert_eq!(fast, general);
        // Cut short: the header claims more rows than the file holds.
        let bytes = std::fs::read(&big).unwrap();
        let cut = dir.join("cut.ply");
        std::fs::write(&cut, &bytes[..bytes.len() - 10]).unwrap();
        assert!(read_fast(&cut, &|_, _| {})
            .unwrap_err()
            .to_string()
            .contains("more than the file holds"));
        // A NaN in a row is named.
        let mut nan = bytes.clone();
        let body = bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11;
        nan[body..body + 4].copy_from_slice(&f32::NAN.to_le_bytes());
        let bad = dir.join("nan.ply");
        std::fs::write(&bad, nan).unwrap();
        assert!(read_fast(&bad, &|_, _| {})
            .unwrap_err()
            .to_string()
            .contains("Gaussian 0"));
        // ASCII goes to the general reader.
        let ascii = dir.join("ascii.ply");
        std::fs::write(
            &ascii,
            b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nend_header\n",
        )
        .unwrap();
        assert!(read_fast(&ascii, &|_, _| {}).unwrap().is_none());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A header of long comments (here 300 KiB, in plyfile's ring.ply) still
    /// takes the fast path, and streams, with the same Gaussians.
    #[test]
    fn a_long_commented_header_still_streams() {
        let ring = std::fs::read(crate::io::test_data("splat/ring.ply")).unwrap();
        let after_format = ring.windows(4).position(|w| w == b"1.0\n").unwrap() + 4;
        let mut long = ring[..after_format].to_vec();
        for k in 0..3_000 {
            long.extend_from_slice(format!("comment setting {k}: {}\n", "x".repeat(80)).as_bytes());
        }
        long.extend_from_slice(&ring[after_format..]);
        assert!(long.len() > 300 << 10);
        let dir = std::env::temp_dir().join(format!("visage-ply-comments-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("commented.ply");
        std::fs::write(&path, &long).unwrap();
        let stream = PlyStream::open(&path).unwrap().expect("the fast path");
        assert_eq!(stream.len(), 200);
        let fast = read_fast(&path, &|_, _| {}).unwrap().unwrap();
        let general = crate::io::ply::parse_splat_ply(&ring).unwrap();
        assert_eq!(fast, general);
        std::fs::remove_dir_all(&dir).ok();
    }
}
