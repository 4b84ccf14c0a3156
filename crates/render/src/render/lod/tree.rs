//! Building the hierarchy: Gaussians sorted along a Morton curve and merged
//! bottom-up, cell by cell of an octree over the scene's bounds, then laid
//! out breadth-first so the coarse levels come first and every node's
//! children are neighbours.

use glam::{Quat, Vec3};
use rayon::prelude::*;

use super::merge::{mean_area, merge, Member};
use super::{LodTree, NodeLink};
use crate::render::projection::{MIN_ALPHA, RADIUS_SIGMAS};
use crate::scene::splats::SplatScene;

/// The most children a node has: one octree cell's eight, and groups of
/// Gaussians in one finest cell are merged eight at a time.
pub const MAX_CHILDREN: usize = 8;

/// Bits of the Morton code per axis (63 bits in all).
const MORTON_BITS: u32 = 21;

/// Nodes while building: the source's usable Gaussians first, then every
/// merged node in the order it was made.
struct Arena {
    scene: SplatScene,
    extent: Vec<f32>,
    /// Mass and summed opacity of the leaves below each node.
    mass: Vec<(f32, f32)>,
    /// Children of merged node `k` (node `leaves + k`).
    children: Vec<Vec<u32>>,
    leaves: usize,
}

impl Arena {
    fn member(&self, id: u32) -> Member<'_> {
        Member::of(&self.scene, id as usize)
    }

    fn children_of(&self, id: u32) -> &[u32] {
        (id as usize)
            .checked_sub(self.leaves)
            .map_or(&[], |k| &self.children[k])
    }
}

/// A node made by merging, before it joins the arena.
struct NewNode {
    position: Vec3,
    rotation: Quat,
    scale: Vec3,
    opacity: f32,
    sh: Vec<f32>,
    extent: f32,
    mass: (f32, f32),
    children: Vec<u32>,
}

impl Arena {
    /// The scene's Gaussians as the leaves, every one drawable.
    fn of_leaves(scene: SplatScene) -> Arena {
        let extent = scene
            .scale
            .iter()
            .map(|s| RADIUS_SIGMAS as f32 * s.abs().max_element())
            .collect();
        let mass = scene
            .scale
            .iter()
            .zip(&scene.opacity)
            .map(|(s, o)| ((*o as f64 * mean_area(*s)) as f32, *o))
            .collect();
        Self::of_roots(scene, extent, mass)
    }

    /// Leaves that stand for subtrees built elsewhere: their extents and
    /// (mass, summed opacity) are the subtrees'.
    fn of_roots(scene: SplatScene, extent: Vec<f32>, mass: Vec<(f32, f32)>) -> Arena {
        let leaves = scene.len();
        Arena {
            scene,
            extent,
            mass,
            children: Vec::new(),
            leaves,
        }
    }
}

/// Whether a Gaussian can ever be drawn (the renderers cull the rest).
pub(super) fn usable(scene: &SplatScene, i: usize) -> bool {
    scene.position[i].is_finite()
        && scene.scale[i].is_finite()
        && scene.rotation[i].is_finite()
        && scene.opacity[i].is_finite()
        && scene.opacity[i] as f64 >= MIN_ALPHA
        && scene.sh_of(i).iter().all(|c| c.is_finite())
}

/// Interleaves the low 21 bits of each coordinate.
fn morton(cell: [u32; 3]) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut x = v as u64 & 0x1f_ffff;
        x = (x | x << 32) & 0x1f_0000_0000_ffff;
        x = (x | x << 16) & 0x1f_0000_ff00_00ff;
        x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
        x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
        x = (x | x << 2) & 0x1249_2492_4924_9249;
        x
    }
    spread(cell[0]) | spread(cell[1]) << 1 | spread(cell[2]) << 2
}

/// The octree the hierarchy follows: the cube on the drawable Gaussians'
/// bounds, [`MORTON_BITS`] levels deep, its cells numbered along the Morton
/// curve. Level `l`'s cell of a code is its top `3 l` bits.
#[derive(Clone, Copy, Debug)]
pub(super) struct Grid {
    lo: Vec3,
    size: f32,
}

impl Grid {
    /// Levels below the root.
    pub(super) const LEVELS: u32 = MORTON_BITS;

    /// The octree over the box `lo..hi`.
    pub(super) fn over(lo: Vec3, hi: Vec3) -> Grid {
        Grid {
            lo,
            size: (hi - lo).max_element().max(f32::MIN_POSITIVE),
        }
    }

    /// The Morton code of the finest cell holding `p`.
    pub(super) fn code(&self, p: Vec3) -> u64 {
        let cells = ((1u32 << MORTON_BITS) - 1) as f32;
        let t = ((p - self.lo) / self.size * cells).clamp(Vec3::ZERO, Vec3::splat(cells));
        morton([t.x as u32, t.y as u32, t.z as u32])
    }
}

/// Builds the hierarchy of `scene` in memory. Gaussians that can never be
/// drawn (non-finite, or below α = 1/255) are left out and counted.
pub fn build(scene: &SplatScene) -> LodTree {
    match layout(scene.clone()) {
        Some(layout) => layout.into_tree(),
        // Nothing drawable: every Gaussian was dropped.
        None => LodTree {
            nodes: SplatScene::with_degree(scene.sh_degree),
            dropped: scene.len(),
            ..LodTree::default()
        },
    }
}

/// Builds the hierarchy of `scene`, taking it over (no copy of a scene
/// whose every Gaussian is drawable); None when nothing in it is.
pub fn layout(scene: SplatScene) -> Option<Layout> {
    let total = scene.len();
    let source = if (0..total).all(|i| usable(&scene, i)) {
        scene
    } else {
        // Copied as they are (not through `push`, which renormalises the
        // rotation): the hierarchy of the drawable Gaussians does not
        // depend on what else the file held.
        let mut kept = SplatScene::with_degree(scene.sh_degree);
        let sh = std::sync::Arc::make_mut(&mut kept.sh);
        for i in (0..total).filter(|&i| usable(&scene, i)) {
            kept.position.push(scene.position[i]);
            kept.rotation.push(scene.rotation[i]);
            kept.scale.push(scene.scale[i]);
            kept.opacity.push(scene.opacity[i]);
            sh.extend_from_slice(scene.sh_of(i));
        }
        kept
    };
    let (lo, hi) = source.bounds()?;
    let order = morton_order(&source, Grid::over(lo, hi));
    let mut layout = layout_sorted(source, order);
    layout.dropped = total - layout.leaves();
    Some(layout)
}

/// The hierarchy of drawable Gaussians whose codes on the scene's grid are
/// `order` (ascending, ties by index): one octree cell's subtree when they
/// are that cell's Gaussians, exactly as the whole scene's build makes it.
pub(super) fn layout_sorted(scene: SplatScene, order: Vec<(u64, u32)>) -> Layout {
    let mut arena = Arena::of_leaves(scene);
    let root = merge_levels(&mut arena, order);
    breadth_first(arena, root, 0)
}

/// The hierarchy over subtrees built separately (`roots`, each with its
/// extent and (mass, summed opacity)), on the codes `order` of their
/// first Gaussians: the top of a hierarchy built cell by cell.
pub(super) fn layout_over(
    roots: SplatScene,
    extent: Vec<f32>,
    mass: Vec<(f32, f32)>,
    order: Vec<(u64, u32)>,
) -> Layout {
    let mut arena = Arena::of_roots(roots, extent, mass);
    let root = merge_levels(&mut arena, order);
    breadth_first(arena, root, 0)
}

/// The Gaussians' ids with their Morton codes on `grid`, in curve order
/// (ties by id).
pub(super) fn morton_order(scene: &SplatScene, grid: Grid) -> Vec<(u64, u32)> {
    let mut order: Vec<(u64, u32)> = scene
        .position
        .par_iter()
        .enumerate()
        .map(|(i, p)| (grid.code(*p), i as u32))
        .collect();
    order.par_sort_unstable();
    order
}

/// Merges octree cells from the finest up until one node is left; returns
/// the root's id.
fn merge_levels(arena: &mut Arena, mut current: Vec<(u64, u32)>) -> u32 {
    let mut shift = 0;
    while current.len() > 1 {
        let runs: Vec<&[(u64, u32)]> = current
            .chunk_by(|a, b| a.0 >> shift == b.0 >> shift)
            .collect();
        // Each run of one cell becomes one node: its merges are independent.
        let made: Vec<(u64, Vec<NewNode>)> = runs
            .par_iter()
            .map(|run| (run[0].0, plan_run(arena, run)))
            .collect();
        let mut next = Vec::with_capacity(made.len());
        for ((code, nodes), run) in made.into_iter().zip(&runs) {
            let id = match nodes.is_empty() {
                true => run[0].1,
                false => push_chain(arena, nodes),
            };
            next.push((code, id));
        }
        current = next;
        shift = (shift + 3).min(63);
    }
    current[0].1
}

/// The merges that turn one cell's nodes into one: nothing for a single
/// node; otherwise groups of at most [`MAX_CHILDREN`], merged again until one
/// is left. Later entries name earlier ones by `u32::MAX - position`.
fn plan_run(arena: &Arena, run: &[(u64, u32)]) -> Vec<NewNode> {
    let mut made = Vec::new();
    let mut ids: Vec<u32> = run.iter().map(|r| r.1).collect();
    while ids.len() > 1 {
        let mut next = Vec::new();
        for group in ids.chunks(MAX_CHILDREN) {
            if group.len() == 1 {
                next.push(group[0]);
                continue;
            }
            made.push(merge_group(arena, &made, group));
            next.push(u32::MAX - (made.len() - 1) as u32);
        }
        ids = next;
    }
    made
}

/// Merges one group whose ids name arena nodes or, from the top of the
/// range down, nodes planned earlier in `made`.
fn merge_group(arena: &Arena, made: &[NewNode], group: &[u32]) -> NewNode {
    let member = |id: u32| -> (Member<'_>, f32, (f32, f32)) {
        match planned(id, made.len()) {
            Some(k) => {
                let n = &made[k];
                let m = Member {
                    position: n.position,
                    rotation: n.rotation,
                    scale: n.scale,
                    opacity: n.opacity,
                    sh: &n.sh,
                };
                (m, n.extent, n.mass)
            }
            None => (
                arena.member(id),
                arena.extent[id as usize],
                arena.mass[id as usize],
            ),
        }
    };
    let members: Vec<(Member, f32, (f32, f32))> = group.iter().map(|&id| member(id)).collect();
    let plain: Vec<Member> = members.iter().map(|m| m.0).collect();
    let mut sh = vec![0.0; arena.scene.sh_stride()];
    let merged = merge(&plain, &mut sh);
    let extent = members
        .iter()
        .map(|(m, e, _)| (m.position - merged.position).length() + e)
        .fold(0.0f32, f32::max);
    let mass = members
        .iter()
        .fold((0.0, 0.0), |(m, c), (_, _, (dm, dc))| (m + dm, c + dc));
    NewNode {
        position: merged.position,
        rotation: merged.rotation,
        scale: merged.scale,
        opacity: merged.opacity,
        sh,
        extent,
        mass,
        children: group.to_vec(),
    }
}

/// The index into a run's planned nodes that `id` names, if it names one.
fn planned(id: u32, planned_so_far: usize) -> Option<usize> {
    let k = (u32::MAX - id) as usize;
    (k < planned_so_far).then_some(k)
}

/// Appends a run's planned nodes to the arena (renaming their references
/// to one another) and returns the id of the last, the run's node.
fn push_chain(arena: &mut Arena, nodes: Vec<NewNode>) -> u32 {
    let first = arena.scene.len() as u32;
    let count = nodes.len();
    for mut node in nodes {
        for child in &mut node.children {
            if let Some(k) = planned(*child, count) {
                *child = first + k as u32;
            }
        }
        arena.scene.push(
            node.position,
            node.rotation,
            node.scale,
            node.opacity,
            &node.sh,
        );
        arena.extent.push(node.extent);
        arena.mass.push(node.mass);
        arena.children.push(node.children);
    }
    arena.scene.len() as u32 - 1
}

/// A built hierarchy in node order, its Gaussians still where they were
/// made: what [`LodTree`] and the cache file are written from.
pub struct Layout {
    arena: Arena,
    /// Arena id of each node, in node order.
    order: Vec<u32>,
    links: Vec<NodeLink>,
    dropped: usize,
}

impl Layout {
    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.order.len()
    }

    /// True for no nodes (never: a layout has a root).
    pub fn is_empty(&self) -> bool {
        self.order.is_empty()
    }

    /// Of the nodes, the scene's own Gaussians.
    pub fn leaves(&self) -> usize {
        self.arena.leaves
    }

    /// Gaussians left out as undrawable.
    pub fn dropped(&self) -> usize {
        self.dropped
    }

    /// SH degree of every node.
    pub fn sh_degree(&self) -> u8 {
        self.arena.scene.sh_degree
    }

    /// Node `i`: its place and its Gaussian.
    pub fn node(&self, i: usize) -> (NodeLink, Member<'_>) {
        (self.links[i], self.arena.member(self.order[i]))
    }

    /// For a node that is one of the Gaussians the build was given, its
    /// index among them.
    pub(super) fn leaf_index(&self, i: usize) -> Option<usize> {
        let id = self.order[i] as usize;
        (id < self.arena.leaves).then_some(id)
    }

    /// The hierarchy in memory.
    pub fn into_tree(self) -> LodTree {
        let arena = &self.arena;
        let mut nodes = SplatScene::with_degree(arena.scene.sh_degree);
        let stride = nodes.sh_stride();
        let sh = std::sync::Arc::make_mut(&mut nodes.sh);
        sh.reserve(self.order.len() * stride);
        for &id in &self.order {
            let i = id as usize;
            nodes.position.push(arena.scene.position[i]);
            nodes.rotation.push(arena.scene.rotation[i]);
            nodes.scale.push(arena.scene.scale[i]);
            nodes.opacity.push(arena.scene.opacity[i]);
            sh.extend_from_slice(arena.scene.sh_of(i));
        }
        LodTree {
            nodes,
            links: self.links,
            leaves: arena.leaves,
            dropped: self.dropped,
        }
    }
}

/// The arena laid out breadth-first from `root`.
fn breadth_first(arena: Arena, root: u32, dropped: usize) -> Layout {
    let mut order = vec![root];
    let mut links = Vec::with_capacity(arena.scene.len());
    let mut level = vec![0u16];
    let mut at = 0;
    while at < order.len() {
        let id = order[at];
        let children = arena.children_of(id);
        links.push(NodeLink {
            first_child: if children.is_empty() {
                0
            } else {
                order.len() as u32
            },
            children: children.len() as u32,
            extent: arena.extent[id as usize],
            level: level[at],
            pad: 0,
            mass: arena.mass[id as usize].0,
            coverage: arena.mass[id as usize].1,
        });
        for &c in children {
            order.push(c);
            level.push(level[at] + 1);
        }
        at += 1;
    }
    Layout {
        arena,
        order,
        links,
        dropped,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn morton_interleaves_axes() {
        assert_eq!(morton([1, 0, 0]), 1);
        assert_eq!(morton([0, 1, 0]), 2);
        assert_eq!(morton([0, 0, 1]), 4);
        assert_eq!(morton([3, 0, 0]), 0b1001);
        let top = (1 << MORTON_BITS) - 1;
        assert_eq!(morton([top, top, top]), (1u64 << 63) - 1);
    }
}
