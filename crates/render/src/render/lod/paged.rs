//! A hierarchy read from its cache file by chunks, within a memory budget.
//! The first chunks (the coarse levels: nodes are breadth-first) are read
//! when it opens and stay; the rest are read when a cut wants the children
//! they hold, a few per frame, and the least recently drawn are dropped
//! when the budget is reached. Every chunk's hash is checked as it is read;
//! a damaged chunk is never used (the nodes above it stay drawn instead).

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use rayon::prelude::*;

use super::cache::{
    decode_records, read_error, read_header, Header, CHUNK_NODES, HEADER_BYTES, RECORD_HEAD,
};
use super::{Cut, DrawnOpacity, Hierarchy, NodeLink};
use crate::error::{Error, Result};
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;

/// One chunk's nodes, decoded.
struct Chunk {
    links: Vec<NodeLink>,
    nodes: SplatScene,
}

impl Chunk {
    fn bytes(&self) -> usize {
        self.links.len() * (RECORD_HEAD + 4 * self.nodes.sh_stride())
    }
}

/// A hierarchy paged in from its cache.
pub struct PagedTree {
    path: PathBuf,
    file: File,
    header: Header,
    table: Vec<[u8; 32]>,
    chunks: Vec<Option<Arc<Chunk>>>,
    /// The frame each chunk was last drawn from (for eviction).
    used: Vec<u64>,
    frame: u64,
    /// Chunks `0..pinned` are read at opening and never dropped.
    pinned: usize,
    budget: usize,
    resident: usize,
    /// Chunks whose hash did not match: never read again.
    damaged: Vec<usize>,
}

/// Share of the memory budget read at opening (the coarse levels).
const PINNED_SHARE: usize = 4;
/// Most bytes read per frame while refining, so a frame stays quick.
const READ_PER_FRAME: usize = 48 << 20;

impl PagedTree {
    /// Opens a cache, checking its header and reading the coarse levels
    /// (up to a quarter of `budget` bytes). The error is one line naming
    /// what is wrong with the file.
    pub fn open(path: &Path, budget: usize) -> Result<PagedTree> {
        let mut file = File::open(path).map_err(|e| read_error(path, e))?;
        let (header, table) = read_header(&mut file).map_err(|why| {
            Error::input(format!("level-of-detail cache {}: {why}", path.display()))
        })?;
        let chunks = header.chunks();
        let chunk_bytes = CHUNK_NODES * header.record_bytes();
        let pinned = (budget / PINNED_SHARE / chunk_bytes).clamp(1, chunks);
        let mut tree = PagedTree {
            path: path.to_path_buf(),
            file,
            header,
            table,
            chunks: vec![None; chunks],
            used: vec![0; chunks],
            frame: 0,
            pinned,
            budget,
            resident: 0,
            damaged: Vec::new(),
        };
        let loaded: Vec<std::result::Result<Chunk, String>> = (0..pinned)
            .into_par_iter()
            .map(|k| tree.read_chunk(k))
            .collect();
        for (k, chunk) in loaded.into_iter().enumerate() {
            let chunk = chunk.map_err(|why| {
                Error::input(format!(
                    "level-of-detail cache {}: {why}",
                    tree.path.display()
                ))
            })?;
            tree.resident += chunk.bytes();
            tree.chunks[k] = Some(Arc::new(chunk));
        }
        Ok(tree)
    }

    /// The cache's header.
    pub fn header(&self) -> &Header {
        &self.header
    }

    /// Bytes of nodes held now.
    pub fn resident_bytes(&self) -> usize {
        self.resident
    }

    /// The chunks held now.
    pub fn resident_chunks(&self) -> Vec<usize> {
        (0..self.chunks.len())
            .filter(|&k| self.chunks[k].is_some())
            .collect()
    }

    /// Chunks found damaged so far.
    pub fn damaged(&self) -> &[usize] {
        &self.damaged
    }

    /// Reads and checks chunk `k`.
    fn read_chunk(&self, k: usize) -> std::result::Result<Chunk, String> {
        use std::os::unix::fs::FileExt;
        let record = self.header.record_bytes();
        let first = k * CHUNK_NODES;
        let count = CHUNK_NODES.min(self.header.nodes as usize - first);
        let mut bytes = vec![0u8; count * record];
        let at = HEADER_BYTES as u64 + (first * record) as u64;
        self.file
            .read_exact_at(&mut bytes, at)
            .map_err(|e| format!("chunk {k} cannot be read: {e}"))?;
        if blake3::hash(&bytes).as_bytes() != &self.table[k] {
            return Err(format!("chunk {k} is damaged (its hash does not match)"));
        }
        let (links, nodes) = decode_records(&bytes, self.header.sh_degree);
        Ok(Chunk { links, nodes })
    }

    fn chunk_of(&self, node: u32) -> Option<(&Chunk, usize)> {
        let k = node as usize / CHUNK_NODES;
        let chunk = self.chunks.get(k)?.as_deref()?;
        Some((chunk, node as usize % CHUNK_NODES))
    }

    /// Notes what a cut drew and reads the chunks holding the children it
    /// wanted (at most [`READ_PER_FRAME`] bytes, within the budget, dropping
    /// chunks drawn longest ago). Returns how many chunks were read: while
    /// that is not zero, the next frame draws finer.
    pub fn refine(&mut self, cut: &Cut) -> usize {
        self.frame += 1;
        for &n in &cut.nodes {
            self.used[n as usize / CHUNK_NODES] = self.frame;
        }
        let mut wanted: Vec<usize> = Vec::new();
        for &n in &cut.wanting {
            let Some((chunk, at)) = self.chunk_of(n) else {
                continue;
            };
            let link = chunk.links[at];
            let first = link.first_child as usize / CHUNK_NODES;
            let last = (link.first_child + link.children - 1) as usize / CHUNK_NODES;
            wanted.extend(first..=last);
        }
        wanted.sort_unstable();
        wanted.dedup();
        wanted.retain(|&k| self.chunks[k].is_none() && !self.damaged.contains(&k));
        let chunk_bytes = CHUNK_NODES * self.header.record_bytes();
        let mut room = (READ_PER_FRAME / chunk_bytes).max(1);
        wanted.truncate(room);
        // Whatever this frame drew stays; only older chunks make room.
        let frame = self.frame;
        while self.resident + wanted.len() * chunk_bytes > self.budget {
            let oldest = (self.pinned..self.chunks.len())
                .filter(|&k| self.chunks[k].is_some() && self.used[k] < frame)
                .min_by_key(|&k| self.used[k]);
            let Some(k) = oldest else { break };
            let chunk = self.chunks[k].take().expect("resident");
            self.resident -= chunk.bytes();
        }
        room = (self.budget.saturating_sub(self.resident) / chunk_bytes).min(wanted.len());
        wanted.truncate(room);
        let read: Vec<(usize, std::result::Result<Chunk, String>)> = wanted
            .par_iter()
            .map(|&k| (k, self.read_chunk(k)))
            .collect();
        let mut count = 0;
        for (k, chunk) in read {
            match chunk {
                Ok(chunk) => {
                    self.resident += chunk.bytes();
                    self.used[k] = frame;
                    self.chunks[k] = Some(Arc::new(chunk));
                    count += 1;
                }
                Err(_) => self.damaged.push(k),
            }
        }
        count
    }

    /// The cut's nodes as a world-space scene for `camera` (see
    /// [`super::LodTree::gather`]); every drawn node is at hand.
    pub fn gather(&self, cut: &Cut, camera: &Camera) -> SplatScene {
        let opacity_for = DrawnOpacity::new(camera);
        let picked: Vec<(&Chunk, usize)> =
            cut.nodes.iter().filter_map(|&n| self.chunk_of(n)).collect();
        fn pick<T: Send>(
            picked: &[(&Chunk, usize)],
            value: impl Fn(&Chunk, usize) -> T + Sync,
        ) -> Vec<T> {
            picked.par_iter().map(|&(c, at)| value(c, at)).collect()
        }
        let mut scene = SplatScene::with_degree(self.header.sh_degree);
        let stride = scene.sh_stride();
        let mut sh = vec![0.0; picked.len() * stride];
        if stride > 0 {
            sh.par_chunks_mut(stride)
                .zip(&picked)
                .for_each(|(out, &(c, at))| out.copy_from_slice(c.nodes.sh_of(at)));
        }
        scene.position = pick(&picked, |c, at| c.nodes.position[at]);
        scene.rotation = pick(&picked, |c, at| c.nodes.rotation[at]);
        scene.scale = pick(&picked, |c, at| c.nodes.scale[at]);
        scene.opacity = pick(&picked, |c, at| {
            let n = &c.nodes;
            opacity_for.node(c.links[at], n.position[at], n.scale[at], n.opacity[at])
        });
        scene.sh = Arc::new(sh);
        scene
    }
}

impl std::fmt::Debug for PagedTree {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PagedTree")
            .field("path", &self.path)
            .field("nodes", &self.header.nodes)
            .field("resident", &self.resident)
            .finish()
    }
}

impl Hierarchy for PagedTree {
    fn node(&self, i: u32) -> Option<(NodeLink, Vec3)> {
        let (chunk, at) = self.chunk_of(i)?;
        Some((chunk.links[at], chunk.nodes.position[at]))
    }
}
