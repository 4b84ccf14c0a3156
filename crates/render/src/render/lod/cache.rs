//! The hierarchy's cache file: built once per scene and read back by chunks
//! (`paged.rs`), so a scene opens at a coarse level at once and in bounded
//! memory. One file per scene content, named by a fingerprint of the source
//! file, in the user's cache folder.
//!
//! Layout (little-endian): a 4 KiB header, then one fixed-size record per
//! node in node order (the [`NodeLink`], position, rotation x y z w, scale,
//! opacity, then the SH coefficients), then a table of one BLAKE3 hash per
//! chunk of [`CHUNK_NODES`] records. The header ends with its own hash, so a
//! truncated or damaged file is refused before anything in it is used, and
//! each chunk is checked when it is read.

use std::fs::File;
use std::io::{BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use glam::Vec3;

use super::{Layout, Member, NodeLink};
use crate::error::{Error, Result};
use crate::io::cache::{cache_root, writer_alive};
use crate::scene::camera::UpAxis;
use crate::scene::splats::SplatScene;

/// Nodes per chunk: the unit read, checked and evicted.
pub const CHUNK_NODES: usize = 8192;
/// Bytes before the first record.
pub const HEADER_BYTES: usize = 4096;
const MAGIC: &[u8; 12] = b"VISAGE-LOD\0\0";
/// Bumped whenever the layout or the hierarchy's construction changes, so
/// old caches are rebuilt rather than misread.
const VERSION: u32 = 1;
/// Bytes of the header covered by its hash (the hash follows them).
const HEADER_BODY: usize = 160;

/// Bytes of a record before its SH coefficients.
pub const RECORD_HEAD: usize = std::mem::size_of::<RecordHead>();

/// A record's fixed part, as stored.
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct RecordHead {
    /// Where the node sits.
    pub link: NodeLink,
    /// Centre.
    pub position: [f32; 3],
    /// Unit rotation, x y z w.
    pub rotation: [f32; 4],
    /// Standard deviations.
    pub scale: [f32; 3],
    /// Opacity (up to [`crate::scene::splats::MAX_OPACITY`] for merged nodes).
    pub opacity: f32,
}

impl RecordHead {
    /// The fixed part of `node`'s record with `link`.
    pub fn of(link: NodeLink, node: &Member<'_>) -> RecordHead {
        RecordHead {
            link,
            position: node.position.to_array(),
            rotation: node.rotation.to_array(),
            scale: node.scale.to_array(),
            opacity: node.opacity,
        }
    }
}

/// What identifies the source a cache was built from, and what opening the
/// scene needs without reading it.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceFacts {
    /// Hash of the source's size and 64 windows of 64 KiB spread over it
    /// (the cache's name).
    pub fingerprint: [u8; 32],
    /// Hash of all of the source's bytes.
    pub content: [u8; 32],
    /// The source's size in bytes.
    pub len: u64,
    /// The source's modification time (ns since the epoch) when built.
    pub modified_ns: u64,
    /// The scene's floater-free framing box (`SplatScene::robust_bounds`).
    pub bounds: (Vec3, Vec3),
    /// The up axis the ground suggests (`scene::upright::ground_up`).
    pub ground_up: Option<UpAxis>,
    /// The scene's Gaussians (drawable or not).
    pub gaussians: u64,
}

/// A cache file's header.
#[derive(Clone, Debug, PartialEq)]
pub struct Header {
    /// The source.
    pub source: SourceFacts,
    /// Nodes stored.
    pub nodes: u64,
    /// Of them, the scene's own Gaussians.
    pub leaves: u64,
    /// Gaussians left out as undrawable.
    pub dropped: u64,
    /// SH degree of every record.
    pub sh_degree: u8,
}

impl Header {
    /// Floats of SH per record.
    pub fn sh_stride(&self) -> usize {
        3 * crate::avatar::gaussians::sh_coefficients(self.sh_degree)
    }

    /// Bytes per record.
    pub fn record_bytes(&self) -> usize {
        RECORD_HEAD + 4 * self.sh_stride()
    }

    /// Number of chunks.
    pub fn chunks(&self) -> usize {
        (self.nodes as usize).div_ceil(CHUNK_NODES)
    }

    /// Where the chunk hash table starts.
    pub fn table_offset(&self) -> u64 {
        HEADER_BYTES as u64 + self.nodes * self.record_bytes() as u64
    }

    /// The whole file's size.
    pub fn file_len(&self) -> u64 {
        self.table_offset() + 32 * self.chunks() as u64
    }

    pub(super) fn encode(&self) -> Vec<u8> {
        let s = &self.source;
        let mut b = Vec::with_capacity(HEADER_BYTES);
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&VERSION.to_le_bytes());
        b.extend_from_slice(&s.fingerprint);
        b.extend_from_slice(&s.content);
        for v in [
            s.len,
            s.modified_ns,
            s.gaussians,
            self.nodes,
            self.leaves,
            self.dropped,
        ] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for v in s
            .bounds
            .0
            .to_array()
            .into_iter()
            .chain(s.bounds.1.to_array())
        {
            b.extend_from_slice(&v.to_le_bytes());
        }
        let up = s.ground_up.map_or("", UpAxis::name).as_bytes();
        let mut up_field = [0u8; 4];
        up_field[..up.len()].copy_from_slice(up);
        b.extend_from_slice(&up_field);
        b.push(self.sh_degree);
        b.resize(HEADER_BODY, 0);
        let hash = blake3::hash(&b);
        b.extend_from_slice(hash.as_bytes());
        b.resize(HEADER_BYTES, 0);
        b
    }

    fn decode(b: &[u8]) -> std::result::Result<Header, String> {
        if b.len() < HEADER_BODY + 32 {
            return Err("shorter than its header".into());
        }
        if &b[..12] != MAGIC {
            return Err("not a visage level-of-detail cache".into());
        }
        if blake3::hash(&b[..HEADER_BODY]).as_bytes() != &b[HEADER_BODY..HEADER_BODY + 32] {
            return Err("its header is damaged".into());
        }
        let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        let u64_at = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().unwrap());
        let f32_at = |at: usize| f32::from_le_bytes(b[at..at + 4].try_into().unwrap());
        let version = u32_at(12);
        if version != VERSION {
            return Err(format!(
                "made by another version of visage (layout {version})"
            ));
        }
        let hash_at = |at: usize| -> [u8; 32] { b[at..at + 32].try_into().unwrap() };
        let at = 80;
        let floats: Vec<f32> = (0..6).map(|k| f32_at(at + 48 + 4 * k)).collect();
        let up_bytes = &b[at + 72..at + 76];
        let up_text = String::from_utf8_lossy(up_bytes);
        let header = Header {
            source: SourceFacts {
                fingerprint: hash_at(16),
                content: hash_at(48),
                len: u64_at(at),
                modified_ns: u64_at(at + 8),
                gaussians: u64_at(at + 16),
                bounds: (
                    Vec3::new(floats[0], floats[1], floats[2]),
                    Vec3::new(floats[3], floats[4], floats[5]),
                ),
                ground_up: UpAxis::parse(up_text.trim_end_matches('\0')),
            },
            nodes: u64_at(at + 24),
            leaves: u64_at(at + 32),
            dropped: u64_at(at + 40),
            sh_degree: b[at + 76],
        };
        if header.sh_degree > 3 || header.nodes == 0 || header.nodes > u32::MAX as u64 {
            return Err("its header holds impossible counts".into());
        }
        Ok(header)
    }
}

/// A file that cannot be read: bad input (exit 2), as every reader has it.
pub fn read_error(path: &Path, error: std::io::Error) -> Error {
    crate::io::FileError::access("read", path, error).into()
}

/// The folder level-of-detail caches live in: `lod/` of visage's cache
/// folder ([`cache_root`]).
pub fn cache_dir() -> PathBuf {
    cache_root().join("lod")
}

/// The cache file of a source with this fingerprint.
pub fn cache_path(dir: &Path, fingerprint: &[u8; 32]) -> PathBuf {
    let hex: String = fingerprint[..16]
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect();
    dir.join(format!("{hex}.lod"))
}

/// Windows sampled by [`fingerprint`], and their size.
const FINGERPRINT_WINDOWS: u64 = 64;
const FINGERPRINT_WINDOW: u64 = 64 << 10;

/// The fingerprint of a source file: its size and 64 windows of 64 KiB
/// spread evenly over it (the first and last included), hashed. Reading
/// at most 4 MiB keeps opening a 5 GB scene quick; a change that alters
/// none of those bytes nor the size is caught by the modification time and
/// the full content hash ([`Freshness`]).
pub fn fingerprint(path: &Path) -> Result<[u8; 32]> {
    let mut file = File::open(path).map_err(|e| read_error(path, e))?;
    let len = file.metadata().map_err(|e| read_error(path, e))?.len();
    let mut hasher = blake3::Hasher::new();
    hasher.update(&len.to_le_bytes());
    let mut window = vec![0u8; FINGERPRINT_WINDOW as usize];
    let last_start = len.saturating_sub(FINGERPRINT_WINDOW);
    for k in 0..FINGERPRINT_WINDOWS {
        let start = last_start * k / (FINGERPRINT_WINDOWS - 1);
        let take = FINGERPRINT_WINDOW.min(len - start) as usize;
        file.seek(SeekFrom::Start(start))
            .and_then(|_| file.read_exact(&mut window[..take]))
            .map_err(|e| read_error(path, e))?;
        hasher.update(&window[..take]);
    }
    Ok(*hasher.finalize().as_bytes())
}

/// The BLAKE3 hash of a whole file, read in 8 MiB blocks each hashed on
/// every core; `progress` hears (bytes hashed, file size) after each block
/// (a 50M-Gaussian scene is 12 GB: tens of seconds).
pub fn content_hash(path: &Path, progress: crate::io::Progress<'_>) -> Result<[u8; 32]> {
    let mut file = File::open(path).map_err(|e| read_error(path, e))?;
    let len = file.metadata().map_err(|e| read_error(path, e))?.len();
    let mut hasher = blake3::Hasher::new();
    let mut block = vec![0u8; 8 << 20];
    let mut done = 0u64;
    loop {
        let n = file.read(&mut block).map_err(|e| read_error(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update_rayon(&block[..n]);
        done += n as u64;
        progress(done.min(len), len);
    }
    Ok(*hasher.finalize().as_bytes())
}

/// The source's modification time in ns since the epoch (0 when unknown).
pub fn modified_ns(path: &Path) -> u64 {
    std::fs::metadata(path)
        .and_then(|m| m.modified())
        .ok()
        .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_nanos() as u64)
}

/// Whether a cache built from some [`SourceFacts`] still describes its
/// source file.
#[derive(Clone, Debug, PartialEq)]
pub enum Freshness {
    /// Same size and modification time: it does.
    Fresh,
    /// Another size: it does not.
    Stale,
    /// Same size, another time (a copy, a touch, or a rewrite of the same
    /// length): only the content can say ([`Freshness::of_content`]).
    ContentToCompare,
}

impl Freshness {
    /// What the file at `path`'s size and time say of a cache built from
    /// `facts`.
    pub fn of(facts: &SourceFacts, path: &Path) -> Result<Self> {
        let len = std::fs::metadata(path)
            .map_err(|e| read_error(path, e))?
            .len();
        Ok(if len != facts.len {
            Self::Stale
        } else if modified_ns(path) == facts.modified_ns {
            Self::Fresh
        } else {
            Self::ContentToCompare
        })
    }

    /// Hashes the file at `path` (`progress` hears how far) and returns
    /// whether its content is the one `facts` records, and the hash, so a
    /// rebuild need not read the file for it again.
    pub fn of_content(
        facts: &SourceFacts,
        path: &Path,
        progress: crate::io::Progress<'_>,
    ) -> Result<(bool, [u8; 32])> {
        let content = content_hash(path, progress)?;
        Ok((content == facts.content, content))
    }
}

/// Writes a built hierarchy's cache to `path`, through a partial file of
/// this process (`NAME.lod.partial.PID`) renamed at the end, so a kill
/// leaves no half-written cache under the real name and two processes
/// building the same cache at once never write into one file. Returns the
/// file's size.
pub fn write_cache(tree: &Layout, source: &SourceFacts, path: &Path) -> Result<u64> {
    let header = Header {
        source: source.clone(),
        nodes: tree.len() as u64,
        leaves: tree.leaves() as u64,
        dropped: tree.dropped() as u64,
        sh_degree: tree.sh_degree(),
    };
    write_through_partial(path, |partial| write_records(tree, &header, partial))?;
    Ok(header.file_len())
}

/// Runs `write` on a partial file of this process beside `path`
/// (`NAME.lod.partial.PID`) and renames it to `path` when it succeeded;
/// removes it when it failed.
pub(super) fn write_through_partial(
    path: &Path,
    write: impl FnOnce(&Path) -> Result<()>,
) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
    }
    remove_abandoned_partials(path);
    let partial = path.with_extension(format!("lod.partial.{}", std::process::id()));
    if let Err(e) = write(&partial) {
        let _ = std::fs::remove_file(&partial);
        return Err(e);
    }
    std::fs::rename(&partial, path).map_err(|e| Error::io("write", path, e))
}

/// Removes partial files and build folders of `path` left by processes
/// that are gone (killed during a build); a build under way in another
/// process keeps its own.
fn remove_abandoned_partials(path: &Path) {
    let (Some(dir), Some(name)) = (path.parent(), path.file_name()) else {
        return;
    };
    let name = name.to_string_lossy();
    let prefixes = [format!("{name}.partial."), format!("{name}.build.")];
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let file = entry.file_name().to_string_lossy().into_owned();
        let ours = prefixes.iter().any(|p| file.starts_with(p.as_str()));
        if !ours || writer_alive(&entry.path()) {
            continue;
        }
        if entry.path().is_dir() {
            let _ = std::fs::remove_dir_all(entry.path());
        } else {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}

/// A scratch folder of this process beside the cache `path`
/// (`NAME.lod.build.PID`), removed when dropped, and by a later build when
/// the process that made it was killed.
pub(super) struct ScratchDir(PathBuf);

impl ScratchDir {
    /// Makes the folder (and the cache folder), clearing what killed
    /// builds left.
    pub(super) fn beside(path: &Path) -> Result<ScratchDir> {
        if let Some(dir) = path.parent() {
            std::fs::create_dir_all(dir).map_err(|e| Error::io("create", dir, e))?;
        }
        remove_abandoned_partials(path);
        let name = path
            .file_name()
            .map_or_else(Default::default, |n| n.to_os_string());
        let mut own = name;
        own.push(format!(".build.{}", std::process::id()));
        let dir = path.with_file_name(own);
        std::fs::create_dir_all(&dir).map_err(|e| Error::io("create", &dir, e))?;
        Ok(ScratchDir(dir))
    }

    /// A file in it.
    pub(super) fn file(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for ScratchDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn write_records(tree: &Layout, header: &Header, path: &Path) -> Result<()> {
    let fail = |e| Error::io("write", path, e);
    let file = File::create(path).map_err(|e| Error::io("create", path, e))?;
    let mut out = BufWriter::with_capacity(4 << 20, file);
    out.write_all(&header.encode()).map_err(fail)?;
    let mut table = Vec::with_capacity(32 * header.chunks());
    let mut chunk = blake3::Hasher::new();
    let mut record = Vec::with_capacity(header.record_bytes());
    for i in 0..tree.len() {
        record.clear();
        let (link, node) = tree.node(i);
        push_record(&mut record, link, &node);
        out.write_all(&record).map_err(fail)?;
        chunk.update(&record);
        if (i + 1) % CHUNK_NODES == 0 || i + 1 == tree.len() {
            table.extend_from_slice(chunk.finalize().as_bytes());
            chunk = blake3::Hasher::new();
        }
    }
    out.write_all(&table).map_err(fail)?;
    out.flush().map_err(fail)?;
    out.get_ref().sync_all().map_err(fail)
}

/// Appends node `node` with `link` as one record.
pub(super) fn push_record(out: &mut Vec<u8>, link: NodeLink, node: &Member<'_>) {
    out.extend_from_slice(bytemuck::bytes_of(&RecordHead::of(link, node)));
    out.extend_from_slice(bytemuck::cast_slice(node.sh));
}

/// Whole records decoded: their links and their Gaussians (SH degree
/// `degree`).
pub(super) fn decode_records(bytes: &[u8], degree: u8) -> (Vec<NodeLink>, SplatScene) {
    let mut nodes = SplatScene::with_degree(degree);
    let record = RECORD_HEAD + 4 * nodes.sh_stride();
    let count = bytes.len() / record;
    let mut links = Vec::with_capacity(count);
    nodes.position.reserve(count);
    nodes.rotation.reserve(count);
    nodes.scale.reserve(count);
    nodes.opacity.reserve(count);
    let sh = std::sync::Arc::make_mut(&mut nodes.sh);
    sh.reserve(count * (record - RECORD_HEAD) / 4);
    for r in bytes.chunks_exact(record) {
        let head: RecordHead = bytemuck::pod_read_unaligned(&r[..RECORD_HEAD]);
        links.push(head.link);
        nodes.position.push(Vec3::from_array(head.position));
        nodes.rotation.push(glam::Quat::from_array(head.rotation));
        nodes.scale.push(Vec3::from_array(head.scale));
        nodes.opacity.push(head.opacity);
        sh.extend(
            r[RECORD_HEAD..]
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes(b.try_into().unwrap())),
        );
    }
    (links, nodes)
}

/// Completes a cache whose records are already at their places in `file`:
/// writes the header, then hashes the records chunk by chunk (reading them
/// back) and writes the table after them.
pub(super) fn finish_in_place(
    file: &File,
    header: &Header,
    path: &Path,
    progress: crate::io::Progress<'_>,
) -> Result<()> {
    use rayon::prelude::*;
    use std::os::unix::fs::FileExt;
    let fail = |e| Error::io("write", path, e);
    file.set_len(header.file_len()).map_err(fail)?;
    file.write_all_at(&header.encode(), 0).map_err(fail)?;
    let chunk_bytes = CHUNK_NODES * header.record_bytes();
    let records = header.nodes * header.record_bytes() as u64;
    let mut table = Vec::with_capacity(32 * header.chunks());
    // Read a few chunks (16 MB at degree 3) at a time and hash them in parallel.
    const BATCH: usize = 8;
    let mut buffer = vec![0u8; BATCH * chunk_bytes];
    let mut at = 0u64;
    while at < records {
        let take = ((records - at) as usize).min(buffer.len());
        file.read_exact_at(&mut buffer[..take], HEADER_BYTES as u64 + at)
            .map_err(|e| Error::io("read back", path, e))?;
        let hashes: Vec<[u8; 32]> = buffer[..take]
            .par_chunks(chunk_bytes)
            .map(|c| *blake3::hash(c).as_bytes())
            .collect();
        for h in hashes {
            table.extend_from_slice(&h);
        }
        at += take as u64;
        progress(at, records);
    }
    file.write_all_at(&table, header.table_offset())
        .map_err(fail)?;
    file.sync_all().map_err(fail)
}

/// Reads and checks a cache's header and chunk table; the error says in a
/// few words what is wrong with the file.
pub fn read_header(file: &mut File) -> std::result::Result<(Header, Vec<[u8; 32]>), String> {
    if cfg!(target_endian = "big") {
        return Err("level-of-detail caches are little-endian".into());
    }
    let mut head = vec![0u8; HEADER_BYTES];
    file.seek(SeekFrom::Start(0))
        .and_then(|_| file.read_exact(&mut head))
        .map_err(|_| "shorter than its header".to_string())?;
    let header = Header::decode(&head)?;
    let len = file.metadata().map_err(|e| e.to_string())?.len();
    if len != header.file_len() {
        return Err(format!(
            "{len} bytes where its header promises {} (truncated?)",
            header.file_len()
        ));
    }
    let mut table = vec![0u8; 32 * header.chunks()];
    file.seek(SeekFrom::Start(header.table_offset()))
        .and_then(|_| file.read_exact(&mut table))
        .map_err(|e| e.to_string())?;
    let table = table
        .chunks_exact(32)
        .map(|c| c.try_into().unwrap())
        .collect();
    Ok((header, table))
}
