//! Building a scene's hierarchy without holding the scene: the cache of a
//! 3DGS PLY is built in passes over the file, in memory bounded by a budget
//! whatever the file's size. Its records (every node and link) and chunk
//! hashes are byte for byte the in-memory build's; the header's framing box
//! and ground come from a sample of at most [`SAMPLE`] Gaussians, where the
//! in-memory build looks at all of them (the same for smaller files).
//!
//! 1. One pass finds the drawable Gaussians' bounds (the octree's cube) and
//!    keeps every k-th Gaussian for framing (the bounds and ground a view
//!    opens on).
//! 2. Counting passes split the octree's cells into their eight children
//!    while a cell holds more than a group's worth of Gaussians, so that
//!    every drawable Gaussian falls in a cell that fits in memory.
//! 3. One pass spills each Gaussian into its group's scratch file; a group is
//!    a run of consecutive cells of at most a group's worth.
//! 4. Each group is read back and sorted along the curve, and each of its
//!    cells built as the whole scene's build builds it: the hierarchy merges
//!    within a cell until one node is left before anything outside it is
//!    touched, so a cell's subtree depends on the cell alone. Subtrees go to
//!    scratch files, breadth-first.
//! 5. The top of the hierarchy is built over the cells' roots, and every
//!    subtree copied level by level to its place in the breadth-first
//!    layout, its links renumbered; then the chunks are hashed.

use std::fs::{File, OpenOptions};
use std::io::{BufReader, BufWriter, Read, Write};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::Path;

use rayon::prelude::*;

use super::cache::{
    decode_records, finish_in_place, push_record, write_through_partial, Header, RecordHead,
    ScratchDir, SourceFacts, HEADER_BYTES, RECORD_HEAD,
};
use super::tree::{layout_over, layout_sorted, morton_order, usable, Grid, Layout};
use super::{Member, NodeLink};
use crate::error::{Error, Result};
use crate::io::ply_stream::PlyStream;
use crate::io::Progress;
use crate::scene::splats::SplatScene;
use crate::scene::upright::ground_up;

/// Gaussians kept for framing: every k-th, so that at most this many
/// (12 MB; the framing quantiles and the ground need far fewer).
const SAMPLE: usize = 1 << 18;
/// Levels a counting pass looks below each cell it splits.
const COUNT_LEVELS: u32 = 6;
/// Most scratch files written at once.
const OPEN_FILES: usize = 256;
/// Bytes of each scratch file's write buffer.
const SPILL_BUFFER: usize = 64 << 10;
/// Memory a group takes while built, in records of its Gaussians: the
/// group read back, then one cell's copy in curve order with its merged
/// nodes and breadth-first layout (measured: see the README's scale table).
const RECORDS_PER_GAUSSIAN: usize = 4;
/// The smallest group, however small the budget.
const MIN_GROUP: usize = 4096;
/// Records copied at a time when placing a subtree.
const COPY_RECORDS: usize = 8192;

/// What a streamed build tells its caller as it goes.
pub struct Listener<'a> {
    /// One line per stage.
    pub note: &'a dyn Fn(&str),
    /// (done, all) in bytes of the file within the current stage: read in a
    /// pass over it, or the share of its Gaussians merged.
    pub progress: Progress<'a>,
}

/// Builds the level-of-detail cache of the PLY that `stream` reads into
/// `path` within about `memory` bytes, and returns the cache's size.
/// `source` names the file; its bounds, ground and count are filled in here
/// (bounds and ground from a sample of at most 262,144 Gaussians).
pub fn build_streamed(
    stream: &mut PlyStream,
    source: SourceFacts,
    path: &Path,
    memory: usize,
    listen: &Listener<'_>,
) -> Result<u64> {
    let record = RECORD_HEAD + 4 * SplatScene::with_degree(stream.sh_degree()).sh_stride();
    // A quarter of the budget each for the counters of a counting pass and
    // the scratch files' buffers (each used while nothing else is held).
    let plan = Plan {
        group: (memory / (RECORDS_PER_GAUSSIAN * record)).max(MIN_GROUP) as u64,
        open_files: (memory / 4 / SPILL_BUFFER).clamp(8, OPEN_FILES),
        count_bytes: memory / 4,
    };
    build_planned(stream, source, path, plan, listen)
}

/// How a streamed build divides its work.
#[derive(Clone, Copy, Debug)]
struct Plan {
    /// Most Gaussians in memory at once.
    group: u64,
    /// Scratch files written in one pass.
    open_files: usize,
    /// Bytes of counters a counting pass may take.
    count_bytes: usize,
}

fn build_planned(
    stream: &mut PlyStream,
    mut source: SourceFacts,
    path: &Path,
    plan: Plan,
    listen: &Listener<'_>,
) -> Result<u64> {
    let scratch = ScratchDir::beside(path)?;
    let survey = survey(stream, listen)?;
    let Some((lo, hi)) = survey.bounds else {
        return Err(Error::input(format!(
            "{} holds no Gaussian that can be drawn",
            stream.path().display()
        )));
    };
    source.bounds = survey.sample.robust_bounds().unwrap_or_default();
    source.ground_up = ground_up(&survey.sample);
    source.gaussians = stream.len() as u64;
    drop(survey.sample);
    // Nodes are named by u32s; a hierarchy has fewer than twice its leaves.
    if survey.drawable >= u32::MAX as u64 / 2 {
        return Err(Error::input(format!(
            "{} holds {} drawable Gaussians; a level-of-detail cache holds at most {}",
            stream.path().display(),
            survey.drawable,
            u32::MAX / 2
        )));
    }
    let grid = Grid::over(lo, hi);
    let degree = stream.sh_degree();
    let group = plan.group;

    let cells = plan_cells(stream, grid, (survey.drawable, plan), listen)?;
    let groups = group_cells(&cells, group);
    (listen.note)(&format!(
        "{} drawable Gaussians, {} octree cells, {} groups of ≤ {group}",
        survey.drawable,
        cells.len(),
        groups.len()
    ));
    spill(
        stream,
        grid,
        (&cells, &groups),
        plan.open_files,
        &scratch,
        listen,
    )?;
    let subtrees = build_groups(grid, stream, &cells, &groups, &scratch, listen)?;
    let top = top_of(&subtrees, degree);
    let nodes = top.len() as u64 - subtrees.len() as u64
        + subtrees
            .iter()
            .map(|s| s.levels.iter().sum::<u64>())
            .sum::<u64>();
    let header = Header {
        source,
        nodes,
        leaves: survey.drawable,
        dropped: stream.len() as u64 - survey.drawable,
        sh_degree: degree,
    };
    (listen.note)(&format!("{nodes} nodes built; placing them…"));
    let file_len = stream.file_len();
    write_through_partial(path, |partial| {
        let placing = Placing {
            scratch: &scratch,
            listen,
            file_len,
        };
        place(&top, &subtrees, &header, partial, &placing)
    })?;
    Ok(header.file_len())
}

/// What the first pass finds.
struct Survey {
    /// Bounds of the drawable Gaussians' means.
    bounds: Option<(glam::Vec3, glam::Vec3)>,
    /// How many are drawable.
    drawable: u64,
    /// Every k-th Gaussian (drawable or not, as the in-memory framing sees
    /// the whole scene), without colour.
    sample: SplatScene,
}

/// The first pass: bounds, the count of drawable Gaussians and a sample.
fn survey(stream: &mut PlyStream, listen: &Listener<'_>) -> Result<Survey> {
    (listen.note)(&format!(
        "reading {} Gaussians for their bounds…",
        stream.len()
    ));
    stream.rewind()?;
    let every = stream.len().div_ceil(SAMPLE).max(1);
    let mut sample = SplatScene::with_degree(0);
    let mut found = Survey {
        bounds: None,
        drawable: 0,
        sample: SplatScene::default(),
    };
    while let Some(chunk) = stream.next_chunk()? {
        let first = stream.rows_done() - chunk.len();
        let (count, bounds) = (0..chunk.len())
            .into_par_iter()
            .filter(|&i| usable(&chunk, i))
            .map(|i| (1u64, Some((chunk.position[i], chunk.position[i]))))
            .reduce(|| (0, None), |a, b| (a.0 + b.0, union(a.1, b.1)));
        found.drawable += count;
        found.bounds = union(found.bounds, bounds);
        for i in (first.next_multiple_of(every) - first..chunk.len()).step_by(every) {
            sample.position.push(chunk.position[i]);
            sample.rotation.push(chunk.rotation[i]);
            sample.scale.push(chunk.scale[i]);
            sample.opacity.push(chunk.opacity[i]);
        }
        (listen.progress)(stream.bytes_done(), stream.file_len());
    }
    let colours = 3 * sample.len();
    std::sync::Arc::make_mut(&mut sample.sh).resize(colours, 0.0);
    found.sample = sample;
    Ok(found)
}

type Bounds = Option<(glam::Vec3, glam::Vec3)>;

fn union(a: Bounds, b: Bounds) -> Bounds {
    match (a, b) {
        (Some(a), Some(b)) => Some((a.0.min(b.0), a.1.max(b.1))),
        (a, None) => a,
        (None, b) => b,
    }
}

/// An octree cell: its level, its first finest-level code and how many
/// drawable Gaussians it holds.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Cell {
    level: u32,
    start: u64,
    count: u64,
}

impl Cell {
    /// Finest-level codes in a cell of `level`.
    fn span(level: u32) -> u64 {
        1u64 << (3 * (Grid::LEVELS - level))
    }

    /// One past its last code.
    fn end(&self) -> u64 {
        self.start + Self::span(self.level)
    }
}

/// The cell of `cells` (sorted, disjoint) holding `code`.
fn cell_of(cells: &[Cell], code: u64) -> Option<usize> {
    let k = cells.partition_point(|c| c.start <= code).checked_sub(1)?;
    (code < cells[k].end()).then_some(k)
}

/// Counting passes: the cells, in curve order, that every drawable Gaussian
/// falls in, each holding at most `group` Gaussians unless it is a cell of
/// the finest level (Gaussians on one spot).
fn plan_cells(
    stream: &mut PlyStream,
    grid: Grid,
    (drawable, plan): (u64, Plan),
    listen: &Listener<'_>,
) -> Result<Vec<Cell>> {
    let group = plan.group;
    let mut done = Vec::new();
    let mut open = vec![Cell {
        level: 0,
        start: 0,
        count: drawable,
    }];
    while !open.is_empty() {
        let (split, kept): (Vec<Cell>, Vec<Cell>) = open
            .into_iter()
            .partition(|c| c.count > group && c.level < Grid::LEVELS);
        done.extend(kept.into_iter().filter(|c| c.count > 0));
        open = Vec::new();
        if split.is_empty() {
            break;
        }
        (listen.note)(&format!(
            "counting Gaussians below {} octree cell(s)…",
            split.len()
        ));
        // Six levels below each cell, fewer where the counters would not
        // fit their share of the budget (one level at the least).
        let counters = |levels: u32| (split.len() * 4) << (3 * levels);
        let levels = (1..=COUNT_LEVELS)
            .rev()
            .find(|&l| counters(l) <= plan.count_bytes)
            .unwrap_or(1);
        let counts = count_below(stream, grid, (&split, levels), listen)?;
        for (cell, counts) in split.iter().zip(&counts) {
            divide(cell.level, cell.start, counts, group, &mut open, &mut done);
        }
        open.sort_by_key(|c| c.start);
    }
    done.sort_by_key(|c| c.start);
    Ok(done)
}

/// Levels a counting pass looks below `cell`: `levels`, or down to the
/// finest.
fn counted_levels(cell: &Cell, levels: u32) -> u32 {
    levels.min(Grid::LEVELS - cell.level)
}

/// One pass counting the drawable Gaussians in each descendant of each of
/// `cells` (sorted) [`counted_levels`] below it.
fn count_below(
    stream: &mut PlyStream,
    grid: Grid,
    (cells, levels): (&[Cell], u32),
    listen: &Listener<'_>,
) -> Result<Vec<Vec<u32>>> {
    let mut counts: Vec<Vec<u32>> = cells
        .iter()
        .map(|c| vec![0; 1 << (3 * counted_levels(c, levels))])
        .collect();
    stream.rewind()?;
    while let Some(chunk) = stream.next_chunk()? {
        let hits: Vec<(u32, u32)> = (0..chunk.len())
            .into_par_iter()
            .filter(|&i| usable(&chunk, i))
            .filter_map(|i| {
                let code = grid.code(chunk.position[i]);
                let k = cell_of(cells, code)?;
                let cell = cells[k];
                let shift = 3 * (Grid::LEVELS - cell.level - counted_levels(&cell, levels));
                Some((k as u32, ((code - cell.start) >> shift) as u32))
            })
            .collect();
        for (k, j) in hits {
            counts[k as usize][j as usize] += 1;
        }
        (listen.progress)(stream.bytes_done(), stream.file_len());
    }
    Ok(counts)
}

/// Splits the cell at `level` starting at `start`, whose descendants at the
/// counted depth hold `counts`: cells of at most `group` go to `done`,
/// cells at the counted depth still over it to `open` for another pass.
fn divide(
    level: u32,
    start: u64,
    counts: &[u32],
    group: u64,
    open: &mut Vec<Cell>,
    done: &mut Vec<Cell>,
) {
    let count: u64 = counts.iter().map(|&c| c as u64).sum();
    let cell = Cell {
        level,
        start,
        count,
    };
    if count == 0 {
        return;
    }
    if count <= group {
        done.push(cell);
        return;
    }
    if counts.len() == 1 {
        open.push(cell);
        return;
    }
    let eighth = counts.len() / 8;
    for (k, part) in counts.chunks(eighth).enumerate() {
        let child = start + k as u64 * Cell::span(level + 1);
        divide(level + 1, child, part, group, open, done);
    }
}

/// Runs of consecutive cells holding at most `group` Gaussians together
/// (a cell over it makes a group of its own).
fn group_cells(cells: &[Cell], group: u64) -> Vec<Range<usize>> {
    let mut groups = Vec::new();
    let mut first = 0;
    let mut held = 0;
    for (k, cell) in cells.iter().enumerate() {
        if k > first && held + cell.count > group {
            groups.push(first..k);
            first = k;
            held = 0;
        }
        held += cell.count;
    }
    if first < cells.len() {
        groups.push(first..cells.len());
    }
    groups
}

fn spill_name(group: usize) -> String {
    format!("spill-{group}")
}

fn built_name(group: usize) -> String {
    format!("built-{group}")
}

/// Passes writing every drawable Gaussian, in file order, to its group's
/// scratch file (at most `open_files` groups a pass).
fn spill(
    stream: &mut PlyStream,
    grid: Grid,
    (cells, groups): (&[Cell], &[Range<usize>]),
    open_files: usize,
    scratch: &ScratchDir,
    listen: &Listener<'_>,
) -> Result<()> {
    let mut group_of = vec![0u32; cells.len()];
    for (g, range) in groups.iter().enumerate() {
        group_of[range.clone()].fill(g as u32);
    }
    for batch in (0..groups.len()).step_by(open_files) {
        let batch = batch..(batch + open_files).min(groups.len());
        (listen.note)(&format!(
            "sorting Gaussians into groups {}-{} of {}…",
            batch.start + 1,
            batch.end,
            groups.len()
        ));
        let mut files = batch
            .clone()
            .map(|g| {
                let path = scratch.file(&spill_name(g));
                File::create(&path)
                    .map(|f| BufWriter::with_capacity(SPILL_BUFFER, f))
                    .map_err(|e| Error::io("create", &path, e))
            })
            .collect::<Result<Vec<_>>>()?;
        stream.rewind()?;
        let mut record = Vec::new();
        while let Some(chunk) = stream.next_chunk()? {
            let hits: Vec<(usize, usize)> = (0..chunk.len())
                .into_par_iter()
                .filter(|&i| usable(&chunk, i))
                .filter_map(|i| {
                    let cell = cell_of(cells, grid.code(chunk.position[i]))?;
                    let g = group_of[cell] as usize;
                    batch.contains(&g).then(|| (g - batch.start, i))
                })
                .collect();
            for (g, i) in hits {
                record.clear();
                push_record(&mut record, NodeLink::default(), &Member::of(&chunk, i));
                files[g].write_all(&record).map_err(|e| {
                    Error::io("write", &scratch.file(&spill_name(batch.start + g)), e)
                })?;
            }
            (listen.progress)(stream.bytes_done(), stream.file_len());
        }
        for (g, mut file) in batch.zip(files) {
            file.flush()
                .map_err(|e| Error::io("write", &scratch.file(&spill_name(g)), e))?;
        }
    }
    Ok(())
}

/// One cell's subtree, built and waiting in its group's scratch file.
struct Subtree {
    /// The curve code of its first Gaussian (what the cell's root merges
    /// under above).
    code: u64,
    /// Its group (whose scratch file holds it).
    group: usize,
    /// Nodes per level below its root (level 0: the root).
    levels: Vec<u64>,
    /// Its root's record (its link local to the subtree) and SH, as the
    /// top of the hierarchy merges it.
    root: (RecordHead, Vec<f32>),
}

/// Builds every cell's subtree, group by group.
fn build_groups(
    grid: Grid,
    stream: &PlyStream,
    cells: &[Cell],
    groups: &[Range<usize>],
    scratch: &ScratchDir,
    listen: &Listener<'_>,
) -> Result<Vec<Subtree>> {
    (listen.note)(&format!("merging {} groups…", groups.len()));
    let (degree, file_len) = (stream.sh_degree(), stream.file_len());
    let total: u64 = cells.iter().map(|c| c.count).sum();
    let mut built = 0u64;
    let mut subtrees = Vec::with_capacity(cells.len());
    for (g, range) in groups.iter().enumerate() {
        let spilled = scratch.file(&spill_name(g));
        let bytes = std::fs::read(&spilled).map_err(|e| Error::io("read", &spilled, e))?;
        let _ = std::fs::remove_file(&spilled);
        let (_, scene) = decode_records(&bytes, degree);
        drop(bytes);
        let order = morton_order(&scene, grid);
        let path = scratch.file(&built_name(g));
        let fail = |e| Error::io("write", &path, e);
        let mut out = BufWriter::with_capacity(4 << 20, File::create(&path).map_err(fail)?);
        let mut at = 0;
        for cell in &cells[range.clone()] {
            let end = at + order[at..].partition_point(|(code, _)| *code < cell.end());
            if (end - at) as u64 != cell.count {
                return Err(Error::input(format!(
                    "{} changed while its level-of-detail cache was being built",
                    stream.path().display()
                )));
            }
            let layout = cell_layout(&scene, &order[at..end]);
            subtrees.push(write_subtree(&layout, order[at].0, g, &mut out).map_err(fail)?);
            at = end;
        }
        out.flush().map_err(fail)?;
        built += order.len() as u64;
        let share = built as f64 / total.max(1) as f64;
        (listen.progress)((share * file_len as f64) as u64, file_len);
    }
    Ok(subtrees)
}

/// The subtree of one cell, whose Gaussians in `scene` are `members`
/// (codes ascending, ties in file order).
fn cell_layout(scene: &SplatScene, members: &[(u64, u32)]) -> Layout {
    let mut cell = SplatScene::with_degree(scene.sh_degree);
    // Room for the merged nodes, so growing never copies the cell.
    let room = 2 * members.len();
    cell.position.reserve(room);
    cell.rotation.reserve(room);
    cell.scale.reserve(room);
    cell.opacity.reserve(room);
    std::sync::Arc::make_mut(&mut cell.sh).reserve(room * scene.sh_stride());
    for &(_, i) in members {
        let m = Member::of(scene, i as usize);
        cell.position.push(m.position);
        cell.rotation.push(m.rotation);
        cell.scale.push(m.scale);
        cell.opacity.push(m.opacity);
        std::sync::Arc::make_mut(&mut cell.sh).extend_from_slice(m.sh);
    }
    let order = members
        .iter()
        .enumerate()
        .map(|(k, &(code, _))| (code, k as u32))
        .collect();
    layout_sorted(cell, order)
}

/// Appends a built subtree's records (links local to it) to `out`.
fn write_subtree(
    layout: &Layout,
    code: u64,
    group: usize,
    out: &mut impl Write,
) -> std::io::Result<Subtree> {
    let mut levels: Vec<u64> = Vec::new();
    let mut record = Vec::new();
    for i in 0..layout.len() {
        let (link, node) = layout.node(i);
        let level = link.level as usize;
        if levels.len() <= level {
            levels.resize(level + 1, 0);
        }
        levels[level] += 1;
        record.clear();
        push_record(&mut record, link, &node);
        out.write_all(&record)?;
    }
    let (link, root) = layout.node(0);
    let head = RecordHead::of(link, &root);
    Ok(Subtree {
        code,
        group,
        levels,
        root: (head, root.sh.to_vec()),
    })
}

/// The hierarchy over the subtrees' roots.
fn top_of(subtrees: &[Subtree], degree: u8) -> Layout {
    let mut roots = SplatScene::with_degree(degree);
    let mut extent = Vec::with_capacity(subtrees.len());
    let mut mass = Vec::with_capacity(subtrees.len());
    for s in subtrees {
        let (head, sh) = &s.root;
        let link = head.link;
        roots.position.push(head.position.into());
        roots.rotation.push(glam::Quat::from_array(head.rotation));
        roots.scale.push(head.scale.into());
        roots.opacity.push(head.opacity);
        std::sync::Arc::make_mut(&mut roots.sh).extend_from_slice(sh);
        extent.push(link.extent);
        mass.push((link.mass, link.coverage));
    }
    let order = subtrees
        .iter()
        .enumerate()
        .map(|(k, s)| (s.code, k as u32))
        .collect();
    layout_over(roots, extent, mass, order)
}

/// Where every node goes in the breadth-first layout of the whole
/// hierarchy.
struct Placement {
    /// Node index of each node of the top (a subtree's root: its subtree's).
    top: Vec<u64>,
    /// Per subtree, the node index of the first of its nodes at each level.
    level_starts: Vec<Vec<u64>>,
    /// Per subtree, the depth of its root in the whole hierarchy.
    depth: Vec<u16>,
}

/// A run of nodes of one level of the whole hierarchy.
#[derive(Clone, Copy)]
enum Run {
    /// One node of the top that is no subtree's root.
    Top(usize),
    /// One level of a subtree.
    Level { subtree: usize, level: usize },
}

impl Placement {
    /// The whole hierarchy's levels, each the left-to-right run of the top's
    /// nodes and the subtrees' levels at that depth.
    fn of(top: &Layout, subtrees: &[Subtree]) -> Placement {
        let run_of = |i: usize| match top.leaf_index(i) {
            Some(subtree) => Run::Level { subtree, level: 0 },
            None => Run::Top(i),
        };
        let mut placed = Placement {
            top: vec![0; top.len()],
            level_starts: subtrees.iter().map(|s| vec![0; s.levels.len()]).collect(),
            depth: vec![0; subtrees.len()],
        };
        let mut runs = vec![run_of(0)];
        let mut next = 0u64;
        let mut depth = 0u16;
        while !runs.is_empty() {
            let mut below = Vec::new();
            for run in runs {
                match run {
                    Run::Top(i) => {
                        placed.top[i] = next;
                        next += 1;
                        let link = top.node(i).0;
                        let children = link.first_child..link.first_child + link.children;
                        below.extend(children.map(|c| run_of(c as usize)));
                    }
                    Run::Level { subtree, level } => {
                        if level == 0 {
                            placed.depth[subtree] = depth;
                        }
                        placed.level_starts[subtree][level] = next;
                        next += subtrees[subtree].levels[level];
                        if level + 1 < subtrees[subtree].levels.len() {
                            below.push(Run::Level {
                                subtree,
                                level: level + 1,
                            });
                        }
                    }
                }
            }
            runs = below;
            depth += 1;
        }
        for i in 0..top.len() {
            if let Some(s) = top.leaf_index(i) {
                placed.top[i] = placed.level_starts[s][0];
            }
        }
        placed
    }
}

/// Where [`place`] reads the built subtrees and whom it tells its progress
/// (as a share of the source's `file_len`, as every stage does).
#[derive(Clone, Copy)]
struct Placing<'a> {
    scratch: &'a ScratchDir,
    listen: &'a Listener<'a>,
    file_len: u64,
}

/// Writes the whole hierarchy into `partial`: the top's nodes, then every
/// subtree copied from its scratch file level by level, then the header and
/// the chunk hashes.
fn place(
    top: &Layout,
    subtrees: &[Subtree],
    header: &Header,
    partial: &Path,
    placing: &Placing<'_>,
) -> Result<()> {
    let Placing {
        scratch,
        listen,
        file_len,
    } = *placing;
    let fail = |e| Error::io("write", partial, e);
    let file = OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(partial)
        .map_err(fail)?;
    let record = header.record_bytes();
    let offset = |node: u64| HEADER_BYTES as u64 + node * record as u64;
    let placed = Placement::of(top, subtrees);
    let mut bytes = Vec::with_capacity(record);
    // Nodes written so far, for the progress.
    let mut written = 0u64;
    for i in 0..top.len() {
        if top.leaf_index(i).is_some() {
            continue;
        }
        let (mut link, node) = top.node(i);
        link.first_child = placed.top[link.first_child as usize] as u32;
        bytes.clear();
        push_record(&mut bytes, link, &node);
        file.write_all_at(&bytes, offset(placed.top[i]))
            .map_err(fail)?;
        written += 1;
    }
    // (done, all) of anything, told as that share of the source's size.
    let tell = |done: u64, all: u64| {
        let share = done as f64 / all.max(1) as f64;
        (listen.progress)((share * file_len as f64) as u64, file_len)
    };
    let mut reader: Option<(usize, BufReader<File>)> = None;
    let mut block = vec![0u8; COPY_RECORDS * record];
    for (s, subtree) in subtrees.iter().enumerate() {
        if reader.as_ref().is_none_or(|(g, _)| *g != subtree.group) {
            if let Some((g, _)) = reader.take() {
                let _ = std::fs::remove_file(scratch.file(&built_name(g)));
            }
            let path = scratch.file(&built_name(subtree.group));
            let file = File::open(&path).map_err(|e| Error::io("read", &path, e))?;
            reader = Some((subtree.group, BufReader::with_capacity(4 << 20, file)));
        }
        let (g, input) = reader.as_mut().expect("opened above");
        let read_fail = |e| Error::io("read", &scratch.file(&built_name(*g)), e);
        let mut local_starts = vec![0u64; subtree.levels.len()];
        for k in 1..subtree.levels.len() {
            local_starts[k] = local_starts[k - 1] + subtree.levels[k - 1];
        }
        for (level, &count) in subtree.levels.iter().enumerate() {
            let mut copied = 0u64;
            while copied < count {
                let take = (count - copied).min(COPY_RECORDS as u64) as usize;
                let bytes = &mut block[..take * record];
                input.read_exact(bytes).map_err(read_fail)?;
                for r in bytes.chunks_exact_mut(record) {
                    let mut head: RecordHead = bytemuck::pod_read_unaligned(&r[..RECORD_HEAD]);
                    head.link.level += placed.depth[s];
                    if head.link.children > 0 {
                        let local = head.link.first_child as u64 - local_starts[level + 1];
                        head.link.first_child = (placed.level_starts[s][level + 1] + local) as u32;
                    }
                    r[..RECORD_HEAD].copy_from_slice(bytemuck::bytes_of(&head));
                }
                let at = offset(placed.level_starts[s][level] + copied);
                file.write_all_at(bytes, at).map_err(fail)?;
                copied += take as u64;
                written += take as u64;
            }
        }
        tell(written, header.nodes);
    }
    drop(reader);
    (listen.note)("hashing the cache's chunks…");
    finish_in_place(&file, header, partial, &tell)
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::render::lod::cache::write_cache;
    use crate::render::lod::layout;
    use crate::scene::synthetic::synthetic_scene;

    fn facts() -> SourceFacts {
        SourceFacts {
            fingerprint: [7; 32],
            content: [9; 32],
            len: 1,
            modified_ns: 2,
            bounds: Default::default(),
            ground_up: None,
            gaussians: 0,
        }
    }

    /// The in-memory build's cache of the PLY at `ply`.
    fn in_memory(ply: &Path, out: &Path) -> Vec<u8> {
        let scene = crate::io::splat::read_scene_with(ply, &|_, _| {}).unwrap();
        let facts = SourceFacts {
            bounds: scene.robust_bounds().unwrap_or_default(),
            ground_up: ground_up(&scene),
            gaussians: scene.len() as u64,
            ..facts()
        };
        write_cache(&layout(scene).unwrap(), &facts, out).unwrap();
        std::fs::read(out).unwrap()
    }

    fn streamed(
        ply: &Path,
        out: &Path,
        plan: Plan,
        notes: &std::sync::Mutex<Vec<String>>,
    ) -> Result<Vec<u8>> {
        let mut stream = PlyStream::open(ply)?.expect("a float32 PLY streams");
        let note = |line: &str| notes.lock().unwrap().push(line.to_string());
        let heard = std::sync::Mutex::new(Vec::new());
        let progress = |done, all| heard.lock().unwrap().push((done, all));
        let listen = Listener {
            note: &note,
            progress: &progress,
        };
        build_planned(&mut stream, facts(), out, plan, &listen)?;
        // Every stage's progress is of the file's size, and the last stage
        // (hashing) ends at all of it.
        let heard = heard.into_inner().unwrap();
        let size = stream.file_len();
        let wrong = heard
            .iter()
            .find(|&&(done, all)| all != size || done > size);
        assert!(wrong.is_none(), "{wrong:?} of {size}");
        assert_eq!(heard.last(), Some(&(size, size)));
        assert!(notes.lock().unwrap().iter().any(|n| n.contains("hashing")));
        Ok(std::fs::read(out).unwrap())
    }

    fn scratch_dirs(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.contains(".build.") || n.contains(".partial."))
            .collect()
    }

    /// Built in groups far smaller than the scene, through several counting
    /// passes (of fewer levels than six, for the counters' budget) and
    /// several spill passes, the cache is byte for byte the one the whole
    /// scene's build writes (the sample for framing is the whole scene here): on a scene with a floor, a backdrop
    /// and floaters, 700 Gaussians on one spot (a cell of the finest level
    /// over the group size) and undrawable ones; and on a single Gaussian.
    #[test]
    fn a_streamed_build_writes_the_in_memory_cache_byte_for_byte() {
        let dir = std::env::temp_dir().join(format!("visage-streamed-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut scene = synthetic_scene(20_000, 11);
        for k in 0..700 {
            let sh = [0.1 * (k % 7) as f32; 48];
            scene.push(
                Vec3::new(0.3, 0.2, 0.1),
                Quat::IDENTITY,
                Vec3::splat(0.01),
                0.6,
                &sh,
            );
        }
        for k in 0..50 {
            scene.push(
                Vec3::splat(k as f32),
                Quat::IDENTITY,
                Vec3::ONE,
                1e-3,
                &[0.0; 48],
            );
        }
        let mut one = SplatScene::with_degree(0);
        one.push(
            Vec3::new(1.0, -2.0, 3.0),
            Quat::IDENTITY,
            Vec3::splat(0.2),
            0.5,
            &[0.3; 3],
        );
        // A build a kill -9 left behind, and its partial file.
        let cache = dir.join("scene.lod");
        std::fs::create_dir_all(dir.join("scene.lod.build.4000000000")).unwrap();
        std::fs::write(dir.join("scene.lod.build.4000000000/spill-0"), b"x").unwrap();
        std::fs::write(dir.join("scene.lod.partial.4000000000"), b"x").unwrap();
        let small = Plan {
            group: 300,
            open_files: 5,
            count_bytes: 40 << 10,
        };
        let default = Plan {
            group: 1 << 20,
            open_files: OPEN_FILES,
            count_bytes: 64 << 20,
        };
        // plyfile's own PLY (tests/data/splat/ring.ply, made by tests/data/splat/make_splat.py).
        let ring = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/splat/ring.ply");
        let tiny = Plan {
            group: 20,
            open_files: 3,
            count_bytes: 4 << 10,
        };
        for (name, scene, plan) in [
            ("mixed", Some(&scene), small),
            ("one", Some(&one), default),
            ("ring", None, tiny),
        ] {
            let ply = match scene {
                Some(scene) => {
                    let ply = dir.join(format!("{name}.ply"));
                    crate::io::ply::write_splat_ply(&ply, scene).unwrap();
                    ply
                }
                None => ring.clone(),
            };
            let expected = in_memory(&ply, &dir.join("memory.lod"));
            let notes = std::sync::Mutex::new(Vec::new());
            let got = streamed(&ply, &cache, plan, &notes).unwrap();
            assert!(got == expected, "{name}: the streamed cache differs");
            assert!(scratch_dirs(&dir).is_empty(), "{:?}", scratch_dirs(&dir));
            if name == "mixed" {
                let notes = notes.into_inner().unwrap();
                let passes = |what: &str| notes.iter().filter(|n| n.starts_with(what)).count();
                assert!(passes("counting") >= 2, "{notes:?}");
                assert!(passes("sorting Gaussians into groups") >= 2, "{notes:?}");
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A file rewritten between the passes (another scene of the same size)
    /// is refused in one line rather than built from two scenes at once.
    #[test]
    fn a_file_changed_during_the_build_is_refused() {
        let dir =
            std::env::temp_dir().join(format!("visage-streamed-changed-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let ply = dir.join("moving.ply");
        crate::io::ply::write_splat_ply(&ply, &synthetic_scene(3_000, 1)).unwrap();
        let other = dir.join("other.ply");
        crate::io::ply::write_splat_ply(&other, &synthetic_scene(3_000, 2)).unwrap();
        let replacement = std::fs::read(&other).unwrap();
        let mut stream = PlyStream::open(&ply).unwrap().unwrap();
        let note = |line: &str| {
            if line.starts_with("sorting") {
                std::fs::write(&ply, &replacement).unwrap();
            }
        };
        let listen = Listener {
            note: &note,
            progress: &|_, _| {},
        };
        let plan = Plan {
            group: 200,
            open_files: 64,
            count_bytes: 1 << 20,
        };
        let cache = dir.join("moving.lod");
        let err = build_planned(&mut stream, facts(), &cache, plan, &listen)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("changed while its level-of-detail cache"),
            "{err}"
        );
        assert!(!cache.exists() && scratch_dirs(&dir).is_empty());
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A file with nothing drawable is refused in one line, leaving neither
    /// a cache nor scratch behind.
    #[test]
    fn nothing_drawable_is_refused_and_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("visage-streamed-none-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut scene = SplatScene::with_degree(1);
        scene.push(Vec3::ZERO, Quat::IDENTITY, Vec3::ONE, 0.0, &[0.0; 12]);
        let ply = dir.join("faint.ply");
        crate::io::ply::write_splat_ply(&ply, &scene).unwrap();
        let cache = dir.join("faint.lod");
        let notes = std::sync::Mutex::new(Vec::new());
        let plan = Plan {
            group: 10,
            open_files: 2,
            count_bytes: 1 << 10,
        };
        let err = streamed(&ply, &cache, plan, &notes)
            .unwrap_err()
            .to_string();
        assert!(err.contains("holds no Gaussian that can be drawn"), "{err}");
        assert!(!cache.exists() && scratch_dirs(&dir).is_empty());
        std::fs::remove_dir_all(&dir).ok();
    }
}
