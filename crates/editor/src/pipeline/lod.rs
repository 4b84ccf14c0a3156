//! A scene drawn through its level-of-detail hierarchy: the tree (in
//! memory, or paged in from its cache file), and the cut of the last camera
//! with its Gaussians gathered, kept until the camera or the policy changes
//! (a still view costs nothing to re-cut). Also where a scene file's cache
//! is found, checked, and built when missing or stale.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::error::Result;
use crate::io::ply_stream::PlyStream;
use crate::io::Progress;
use crate::render::image::RgbImage;
use crate::render::lod::cache::{
    cache_dir, cache_path, content_hash, fingerprint, modified_ns, read_error, read_header,
    write_cache, Freshness, SourceFacts,
};
use crate::render::lod::{
    build_streamed, cut, layout, Cut, Listener, LodPolicy, LodTree, PagedTree, AUTO_PIXELS,
};
use crate::render::settings::RenderSettings;
use crate::render::SplatRenderer;
use crate::scene::camera::Camera;
use crate::scene::splats::SplatScene;
use crate::scene::upright::ground_up;

/// What the last frame drew of the hierarchy.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct CutSummary {
    /// Gaussians drawn.
    pub drawn: usize,
    /// Of them, the scene's own.
    pub leaves: usize,
    /// Shallowest and deepest level drawn.
    pub levels: (u16, u16),
    /// Milliseconds choosing and gathering the cut (0 when it was kept).
    pub cut_ms: f64,
    /// Chunks of a paged hierarchy read for this frame's cut: the next
    /// frame draws finer while this is not zero.
    pub chunks_read: usize,
    /// Bytes of a paged hierarchy held in memory.
    pub resident_bytes: usize,
    /// The GPU chose the cut (so `drawn` counts what reached the screen,
    /// and the levels are not known).
    pub on_gpu: bool,
}

/// Where the hierarchy lives.
enum Tree {
    Memory(LodTree),
    Paged(Box<PagedTree>),
}

/// A hierarchy with its last cut.
pub struct LodScene {
    tree: Tree,
    /// This hierarchy's name for a GPU renderer holding it.
    name: u64,
    last: Option<(Camera, LodPolicy)>,
    drawn: SplatScene,
    summary: CutSummary,
}

impl LodScene {
    /// Keeps `tree` to draw from.
    pub fn new(tree: LodTree) -> Self {
        Self::with(Tree::Memory(tree))
    }

    /// Draws from a hierarchy paged in from its cache.
    pub fn paged(tree: PagedTree) -> Self {
        Self::with(Tree::Paged(Box::new(tree)))
    }

    fn with(tree: Tree) -> Self {
        static NAMES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        Self {
            name: NAMES.fetch_add(1, std::sync::atomic::Ordering::Relaxed),
            tree,
            last: None,
            drawn: SplatScene::default(),
            summary: CutSummary::default(),
        }
    }

    /// Number of nodes.
    pub fn nodes(&self) -> usize {
        match &self.tree {
            Tree::Memory(t) => t.len(),
            Tree::Paged(t) => t.header().nodes as usize,
        }
    }

    /// The Gaussians `camera` draws under `policy`, and whether they differ
    /// from the last call's (so a renderer must take them again). A paged
    /// hierarchy reads the chunks the cut wanted afterwards, so the next
    /// call draws finer.
    pub fn gaussians_for(&mut self, camera: &Camera, policy: LodPolicy) -> (&SplatScene, bool) {
        let key = Some((*camera, policy));
        if self.last == key {
            self.summary.cut_ms = 0.0;
            self.summary.chunks_read = 0;
            return (&self.drawn, false);
        }
        let t = Instant::now();
        let (cut, chunks_read, resident_bytes): (Cut, usize, usize) = match &mut self.tree {
            Tree::Memory(tree) => {
                let cut = tree.cut(camera, policy);
                self.drawn = tree.gather(&cut, camera);
                (cut, 0, 0)
            }
            Tree::Paged(tree) => {
                let cut = cut(tree.as_ref(), camera, policy);
                self.drawn = tree.gather(&cut, camera);
                let read = tree.refine(&cut);
                (cut, read, tree.resident_bytes())
            }
        };
        self.summary = CutSummary {
            drawn: cut.nodes.len(),
            leaves: cut.leaves,
            levels: cut.levels,
            cut_ms: t.elapsed().as_secs_f64() * 1e3,
            chunks_read,
            resident_bytes,
            on_gpu: false,
        };
        // Chunks arrived: the same camera cuts finer next time.
        self.last = if chunks_read > 0 { None } else { key };
        (&self.drawn, true)
    }

    /// What the last frame drew.
    pub fn summary(&self) -> CutSummary {
        self.summary
    }

    /// The Gaussians the last frame drew.
    pub fn drawn(&self) -> &SplatScene {
        &self.drawn
    }

    /// Draws the cut of `camera` with `renderer` (uploading it when it
    /// changed). A GPU renderer holds a hierarchy in memory whole and
    /// chooses the `auto` cut itself, every frame: no cut, gather or upload
    /// on the CPU while the camera moves.
    pub fn render(
        &mut self,
        renderer: &mut SplatRenderer,
        camera: &Camera,
        policy: LodPolicy,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        if let (Tree::Memory(tree), SplatRenderer::Gpu(gpu), LodPolicy::Auto) =
            (&self.tree, &mut *renderer, policy)
        {
            if gpu.is_software() {
                // lavapipe projects and sorts the whole hierarchy slower
                // than the CPU walks to its cut and uploads it (300k
                // Gaussians at 200×120: 164 ms a frame against 135).
                return self.render_gathered(renderer, camera, policy, settings);
            }
            if gpu.lod_name() != Some(self.name) {
                gpu.set_lod_tree(tree, self.name)?;
            }
            let image = gpu.render_lod(camera, settings, AUTO_PIXELS)?;
            let (drawn, leaves) = gpu.drawn();
            self.summary = CutSummary {
                drawn: drawn as usize,
                leaves: leaves as usize,
                on_gpu: true,
                ..CutSummary::default()
            };
            // What the CPU gathered last is not what was drawn.
            self.last = None;
            return Ok(image);
        }
        self.render_gathered(renderer, camera, policy, settings)
    }

    /// Draws the cut chosen on the CPU, gathered and uploaded when it changed.
    fn render_gathered(
        &mut self,
        renderer: &mut SplatRenderer,
        camera: &Camera,
        policy: LodPolicy,
        settings: &RenderSettings,
    ) -> Result<RgbImage> {
        let (scene, changed) = self.gaussians_for(camera, policy);
        if changed {
            renderer.set_world_scene(scene)?;
        }
        renderer.render_world(camera, settings)
    }

    /// Forgets the last cut, so the next frame cuts and uploads again (for
    /// benchmarks timing the whole per-frame cost of a moving camera, and
    /// after the renderer drew something else).
    pub fn forget(&mut self) {
        self.last = None;
    }
}

/// How a scene's cache was come by.
#[derive(Clone, Debug, PartialEq)]
pub enum CacheOrigin {
    /// It was there and still matched the file.
    Found,
    /// It was built now: why, seconds it took, its size in bytes.
    Built {
        /// Why: missing, stale, or what was wrong with the old one.
        why: String,
        /// Seconds reading the scene, building and writing.
        seconds: f64,
        /// The cache file's size.
        bytes: u64,
    },
}

/// Opens the level-of-detail cache of the scene file at `path` (in `dir`,
/// by default the user's cache folder), building it first when it is
/// missing, stale (the file changed) or damaged (truncated, corrupted, from
/// another version): the old one is replaced. `budget` bounds the memory of
/// the hierarchy paged in and of the build. `note` hears what is going on,
/// one line at a time, and `progress` how far each stage of a build is. A
/// 3DGS PLY is built in passes over the file within the budget, whatever
/// its size; other formats are read whole, and refused up front where the
/// machine has too little memory for that.
pub fn open_cached(
    path: &Path,
    dir: Option<&Path>,
    budget: usize,
    note: &dyn Fn(&str),
    progress: Progress,
) -> Result<(PagedTree, CacheOrigin, PathBuf)> {
    let fingerprint = fingerprint(path)?;
    let dir = dir.map_or_else(cache_dir, Path::to_path_buf);
    let cache = cache_path(&dir, &fingerprint);
    // The header decides staleness before any chunk is read; the content
    // hash a comparison needed is the rebuild's too.
    let mut content = None;
    let why = match std::fs::File::open(&cache) {
        Err(_) => "there is none yet".to_string(),
        Ok(mut file) => match read_header(&mut file) {
            Err(why) => format!("level-of-detail cache {}: {why}", cache.display()),
            Ok((header, _)) => match fresh(&header.source, path, note, progress, &mut content)? {
                false => "the scene file changed since it was built".to_string(),
                true => match PagedTree::open(&cache, budget) {
                    Ok(tree) => return Ok((tree, CacheOrigin::Found, cache)),
                    Err(e) => e.to_string(),
                },
            },
        },
    };
    let t = Instant::now();
    let build = Build {
        path,
        fingerprint,
        content,
        cache: &cache,
        why: &why,
        memory: budget,
    };
    let bytes = build.run(note, progress)?;
    let seconds = t.elapsed().as_secs_f64();
    note(&format!(
        "level-of-detail cache written: {} ({:.0} MB in {seconds:.1} s)",
        cache.display(),
        bytes as f64 / 1e6
    ));
    let tree = PagedTree::open(&cache, budget)?;
    Ok((
        tree,
        CacheOrigin::Built {
            why,
            seconds,
            bytes,
        },
        cache,
    ))
}

/// Whether a cache built from `facts` still describes the file at `path`;
/// where that takes the file's content hash (its time changed but not its
/// size), the hash is noted, shown in `progress` and left in `content`.
fn fresh(
    facts: &SourceFacts,
    path: &Path,
    note: &dyn Fn(&str),
    progress: Progress,
    content: &mut Option<[u8; 32]>,
) -> Result<bool> {
    match Freshness::of(facts, path)? {
        Freshness::Fresh => Ok(true),
        Freshness::Stale => Ok(false),
        Freshness::ContentToCompare => {
            note(&format!(
                "hashing {} to see whether it changed (its time did)…",
                path.display()
            ));
            let (same, hash) = Freshness::of_content(facts, path, progress)?;
            *content = Some(hash);
            Ok(same)
        }
    }
}

/// A cache to build.
struct Build<'a> {
    path: &'a Path,
    fingerprint: [u8; 32],
    /// The source's content hash, where the staleness check took it.
    content: Option<[u8; 32]>,
    cache: &'a Path,
    why: &'a str,
    /// Bytes of memory it may take.
    memory: usize,
}

impl Build<'_> {
    /// Builds the cache, streamed where the file allows it; returns its size.
    fn run(&self, note: &dyn Fn(&str), progress: Progress) -> Result<u64> {
        let path = self.path;
        if let Some(mut stream) = PlyStream::open(path)? {
            let facts = self.facts(note, progress)?;
            note(&format!(
                "building the level-of-detail cache of {} ({}) in passes over the file, within {} MiB…",
                path.display(),
                self.why,
                self.memory >> 20
            ));
            let listen = Listener { note, progress };
            return build_streamed(&mut stream, facts, self.cache, self.memory, &listen);
        }
        check_memory_for_build(path)?;
        self.in_memory(note, progress)
    }

    /// What the cache records of its source: the content hash (the
    /// staleness check's, or a pass over the file, noted, its progress
    /// shown), size and time; the rest is filled in by the build.
    fn facts(&self, note: &dyn Fn(&str), progress: Progress) -> Result<SourceFacts> {
        let path = self.path;
        let content = match self.content {
            Some(content) => content,
            None => {
                note(&format!(
                    "hashing {} for its level-of-detail cache ({})…",
                    path.display(),
                    self.why
                ));
                content_hash(path, progress)?
            }
        };
        Ok(SourceFacts {
            fingerprint: self.fingerprint,
            content,
            len: std::fs::metadata(path)
                .map_err(|e| read_error(path, e))?
                .len(),
            modified_ns: modified_ns(path),
            bounds: Default::default(),
            ground_up: None,
            gaussians: 0,
        })
    }

    /// Reads the whole scene, builds its hierarchy and writes the cache.
    fn in_memory(&self, note: &dyn Fn(&str), progress: Progress) -> Result<u64> {
        let path = self.path;
        // Read first, so a file that is no scene fails in one line.
        let scene = crate::io::splat::read_scene_with(path, progress)?;
        let facts = self.facts(note, progress)?;
        let t = Instant::now();
        note(&format!(
            "building the level-of-detail cache of {} ({}): merging {} Gaussians…",
            path.display(),
            self.why,
            scene.len()
        ));
        let facts = SourceFacts {
            bounds: scene.robust_bounds().unwrap_or_default(),
            ground_up: ground_up(&scene),
            gaussians: scene.len() as u64,
            ..facts
        };
        let name = path.display();
        let layout = layout(scene).ok_or_else(|| {
            crate::error::Error::input(format!("{name} holds no Gaussian that can be drawn"))
        })?;
        note(&format!(
            "{} nodes merged in {:.1} s; writing…",
            layout.len(),
            t.elapsed().as_secs_f64()
        ));
        write_cache(&layout, &facts, self.cache)
    }
}

/// Memory an in-memory cache build needs per byte of the scene file: the
/// scene itself (about its INRIA PLY size), the merged nodes (0.6 of the
/// Gaussians) and the layout, measured at 2.3 on a 20M-Gaussian PLY
/// (11.2 GB peak for 4.96 GB); SPZ and SuperSplat's compressed PLY hold
/// about ten and four times their size once read.
fn build_memory_per_file_byte(path: &Path) -> f64 {
    let name = path.to_string_lossy().to_ascii_lowercase();
    if name.ends_with(".spz") {
        25.0
    } else if name.ends_with(".compressed.ply") {
        10.0
    } else {
        2.5
    }
}

/// Refuses a cache build the machine's available memory cannot hold (a
/// clear error rather than the kernel killing the process half-way).
fn check_memory_for_build(path: &Path) -> Result<()> {
    let len = std::fs::metadata(path)
        .map_err(|e| read_error(path, e))?
        .len();
    let needed = len as f64 * build_memory_per_file_byte(path);
    let Some(available) = meminfo_bytes("MemAvailable:") else {
        return Ok(());
    };
    if needed > available as f64 {
        return Err(crate::error::Error::input(format!(
            "building the level-of-detail cache of {} ({:.1} GB) needs about {:.0} GB of memory, and {:.0} GB are available; build it on a larger machine and copy it into {}",
            path.display(),
            len as f64 / 1e9,
            needed / 1e9,
            available as f64 / 1e9,
            cache_dir().display()
        )));
    }
    Ok(())
}

/// A line of /proc/meminfo in bytes.
fn meminfo_bytes(key: &str) -> Option<usize> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with(key))?;
    let kb: usize = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// The default memory budget of a paged hierarchy: a quarter of the
/// machine's memory, at most 1.5 GiB (so that with the renderer's own
/// buffers a view stays under 2 GiB whatever the scene's size).
pub fn default_memory_budget() -> usize {
    const CAP: usize = 3 << 29;
    meminfo_bytes("MemTotal:").map_or(CAP, |t| (t / 4).min(CAP))
}

/// Reads a memory budget: bytes with an optional K, M or G (powers of
/// 1024), at least 16M (one chunk of a degree-3 scene is ~2 MiB).
pub fn parse_memory_budget(text: &str) -> std::result::Result<usize, String> {
    let bad = || {
        format!(
            "memory budget '{}' is not a size such as 512M or 2G",
            crate::text::printable(text)
        )
    };
    let (digits, unit) = match text.char_indices().last() {
        Some((at, 'k' | 'K')) => (&text[..at], 1usize << 10),
        Some((at, 'm' | 'M')) => (&text[..at], 1 << 20),
        Some((at, 'g' | 'G')) => (&text[..at], 1 << 30),
        _ => (text, 1),
    };
    let value: f64 = digits.parse().map_err(|_| bad())?;
    let bytes = value * unit as f64;
    if !bytes.is_finite() || bytes < (16 << 20) as f64 {
        return Err(format!(
            "memory budget '{}' is below 16M",
            crate::text::printable(text)
        ));
    }
    Ok(bytes.min(usize::MAX as f64) as usize)
}
