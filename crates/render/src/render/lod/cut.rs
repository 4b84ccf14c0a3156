//! Choosing what to draw for one camera: the coarsest nodes whose whole
//! subtree projects to at most a pixel-sized spot (so every pixel sees a
//! bounded number of Gaussians), nodes outside the view left out with
//! everything below them, and, under a budget, the largest spots refined
//! first until the budget is spent.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use glam::{Mat4, Vec3};
use rayon::prelude::*;

use super::{Hierarchy, LodTree, NodeLink};
use crate::render::projection::FRUSTUM_GUARD;
use crate::scene::camera::Camera;

/// The largest on-screen size, in pixels, of a node drawn in place of its
/// subtree under `--lod auto` (the diameter of the sphere holding every
/// Gaussian below it to three standard deviations).
pub const AUTO_PIXELS: f32 = 1.5;

/// Gaussians per pixel up to which `--lod auto` draws a scene as it is
/// ([`LodPolicy::resolve`]): at 640×480, a 1M-Gaussian scene's cut kept
/// 645k nodes and cost 153 ms a moving frame against the exact path's
/// 120 ms; at 200×120 it kept 41k and cost 7.7 ms against 102 ms.
pub const AUTO_PER_PIXEL: usize = 4;

/// How much of the hierarchy to draw.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LodPolicy {
    /// Every Gaussian of the scene (the exact path).
    #[default]
    Off,
    /// Nodes of at most [`AUTO_PIXELS`] on screen.
    Auto,
    /// As `Auto`, but never more than this many Gaussians: the largest
    /// spots are refined first.
    Budget(usize),
}

impl LodPolicy {
    /// Parses `off`, `auto` or a budget (a count, `k`/`M` allowed: `300k`).
    pub fn parse(text: &str) -> Result<LodPolicy, String> {
        match text {
            "off" => Ok(LodPolicy::Off),
            "auto" => Ok(LodPolicy::Auto),
            _ => {
                let (digits, unit) = match text.char_indices().last() {
                    Some((at, 'k' | 'K')) => (&text[..at], 1_000),
                    Some((at, 'm' | 'M')) => (&text[..at], 1_000_000),
                    _ => (text, 1),
                };
                match digits.parse::<usize>() {
                    Ok(n) if n > 0 => Ok(LodPolicy::Budget(n.saturating_mul(unit))),
                    _ => Err(format!(
                        "--lod '{}' is not off, auto or a positive number of Gaussians (e.g. 300k)",
                        crate::text::printable(text)
                    )),
                }
            }
        }
    }

    /// What the policy does for a scene of `gaussians` drawn at `pixels`:
    /// `Auto` draws the scene as it is where it holds at most
    /// [`AUTO_PER_PIXEL`] Gaussians per pixel (the exact path's cost is
    /// bounded by the image there, and a cut that keeps most of the scene
    /// costs more than it saves); a budget the scene fits is no budget.
    pub fn resolve(self, gaussians: usize, pixels: usize) -> LodPolicy {
        match self {
            LodPolicy::Auto if gaussians <= AUTO_PER_PIXEL * pixels => LodPolicy::Off,
            LodPolicy::Budget(n) if gaussians <= n => LodPolicy::Off,
            policy => policy,
        }
    }

    /// The policy as `parse` reads it.
    pub fn label(&self) -> String {
        match self {
            LodPolicy::Off => "off".into(),
            LodPolicy::Auto => "auto".into(),
            LodPolicy::Budget(n) => n.to_string(),
        }
    }
}

/// The nodes one camera draws.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cut {
    /// Node indices, in the tree's order.
    pub nodes: Vec<u32>,
    /// The shallowest and deepest level drawn (0 is the root).
    pub levels: (u16, u16),
    /// How many of the drawn nodes are the scene's own Gaussians.
    pub leaves: usize,
    /// Drawn nodes the cut would have opened had their children been at
    /// hand (a paged hierarchy's chunks not loaded yet).
    pub wanting: Vec<u32>,
}

/// Where a node's bounding sphere falls for one camera.
struct View {
    view: Mat4,
    near: f32,
    /// Tangents of the half fields of view, widened by the renderers' guard.
    tan: (f32, f32),
    /// Their plane normals' lengths, `sqrt(1 + tan²)`.
    norm: (f32, f32),
    focal: f32,
}

/// What the cut does with one node.
enum Verdict {
    /// Outside the view, with all below it.
    Skip,
    /// Small enough to draw in place of its subtree, or a leaf.
    Draw,
    /// Too large on screen: its children decide, largest first by this size.
    Open(f32),
    /// Too large, but its children are not at hand: drawn for now.
    Want,
}

impl View {
    fn new(camera: &Camera) -> Self {
        let (fx, fy) = camera.focal_px();
        let tan = (
            FRUSTUM_GUARD as f32 * 0.5 * camera.width as f32 / fx,
            FRUSTUM_GUARD as f32 * 0.5 * camera.height as f32 / fy,
        );
        Self {
            view: camera.view(),
            near: camera.near,
            tan,
            norm: ((1.0 + tan.0 * tan.0).sqrt(), (1.0 + tan.1 * tan.1).sqrt()),
            focal: fx.max(fy),
        }
    }

    fn judge<H: Hierarchy + ?Sized>(&self, tree: &H, node: u32, threshold: f32) -> Verdict {
        let Some((link, position)) = tree.node(node) else {
            return Verdict::Skip;
        };
        let p: Vec3 = self.view.transform_point3(position);
        let (depth, r) = (-p.z, link.extent);
        let beyond = |offset: f32, tan: f32, norm: f32| (offset.abs() - tan * depth) / norm > r;
        if depth + r < self.near
            || beyond(p.x, self.tan.0, self.norm.0)
            || beyond(p.y, self.tan.1, self.norm.1)
        {
            return Verdict::Skip;
        }
        if link.children == 0 {
            return Verdict::Draw;
        }
        let nearest = depth - r;
        let size = if nearest <= self.near {
            f32::INFINITY
        } else {
            2.0 * self.focal * r / nearest
        };
        if size <= threshold {
            Verdict::Draw
        } else if tree.has_children_of(link) {
            Verdict::Open(size)
        } else {
            Verdict::Want
        }
    }
}

/// A node waiting to be opened, ordered by its size on screen.
struct Pending(f32, u32);

impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}
impl Eq for Pending {}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(other.1.cmp(&self.1))
    }
}

impl LodTree {
    /// The nodes `camera` draws under `policy`; `Off` draws every leaf in
    /// view (what the exact path draws).
    pub fn cut(&self, camera: &Camera, policy: LodPolicy) -> Cut {
        cut(self, camera, policy)
    }

    /// The cut that draws nodes of at most `threshold` pixels on screen,
    /// at most `budget` of them.
    pub fn cut_at(&self, camera: &Camera, threshold: f32, budget: usize) -> Cut {
        cut_at(self, camera, threshold, budget)
    }
}

/// The nodes of `tree` that `camera` draws under `policy`.
pub fn cut<H: Hierarchy + ?Sized>(tree: &H, camera: &Camera, policy: LodPolicy) -> Cut {
    let (threshold, budget) = match policy {
        LodPolicy::Off => (0.0, usize::MAX),
        LodPolicy::Auto => (AUTO_PIXELS, usize::MAX),
        LodPolicy::Budget(n) => (AUTO_PIXELS, n.max(1)),
    };
    cut_at(tree, camera, threshold, budget)
}

/// The cut of `tree` that draws nodes of at most `threshold` pixels on
/// screen, at most `budget` of them.
pub fn cut_at<H: Hierarchy + ?Sized>(
    tree: &H,
    camera: &Camera,
    threshold: f32,
    budget: usize,
) -> Cut {
    let walk = Walk {
        tree,
        view: View::new(camera),
        threshold,
    };
    let mut cut = Cut::default();
    if tree.node(0).is_none() {
        return cut;
    }
    let (mut nodes, mut wanting) = if budget == usize::MAX {
        walk.unbounded()
    } else {
        walk.within(budget)
    };
    nodes.sort_unstable();
    wanting.sort_unstable();
    cut.nodes = nodes;
    cut.wanting = wanting;
    walk.describe(&mut cut);
    cut
}

/// One cut under way.
struct Walk<'a, H: ?Sized> {
    tree: &'a H,
    view: View,
    threshold: f32,
}

/// Nodes drawn and, of them, those wanting their children.
type Drawn = (Vec<u32>, Vec<u32>);

impl<H: Hierarchy + ?Sized> Walk<'_, H> {
    fn link(&self, node: u32) -> NodeLink {
        self.tree.node(node).map(|(l, _)| l).unwrap_or_default()
    }
    /// Every node the threshold draws: the top of the tree is opened
    /// breadth-first until there is work for every thread, then each open
    /// subtree is walked depth-first on its own.
    fn unbounded(&self) -> Drawn {
        const PARALLEL_FRONTIER: usize = 256;
        let mut drawn = (Vec::new(), Vec::new());
        let mut frontier = vec![0u32];
        while !frontier.is_empty() && frontier.len() < PARALLEL_FRONTIER {
            let mut next = Vec::new();
            for node in frontier {
                self.visit(node, &mut drawn, &mut next);
            }
            frontier = next;
        }
        let below: Vec<Drawn> = frontier
            .par_iter()
            .map(|&node| {
                let (mut drawn, mut stack) = ((Vec::new(), Vec::new()), vec![node]);
                while let Some(node) = stack.pop() {
                    self.visit(node, &mut drawn, &mut stack);
                }
                drawn
            })
            .collect();
        for (nodes, wanting) in below {
            drawn.0.extend(nodes);
            drawn.1.extend(wanting);
        }
        drawn
    }

    /// Judges one node: drawn, skipped, or its children queued in `open`.
    fn visit(&self, node: u32, drawn: &mut Drawn, open: &mut Vec<u32>) {
        match self.view.judge(self.tree, node, self.threshold) {
            Verdict::Skip => {}
            Verdict::Draw => drawn.0.push(node),
            Verdict::Want => {
                drawn.0.push(node);
                drawn.1.push(node);
            }
            Verdict::Open(_) => {
                let link = self.link(node);
                open.extend(link.first_child..link.first_child + link.children);
            }
        }
    }

    /// The threshold's cut, refined largest spot first until `budget`.
    fn within(&self, budget: usize) -> Drawn {
        let mut drawn = (Vec::new(), Vec::new());
        let mut open = BinaryHeap::new();
        let judge = |drawn: &mut Drawn, open: &mut BinaryHeap<Pending>, node: u32| match self
            .view
            .judge(self.tree, node, self.threshold)
        {
            Verdict::Skip => {}
            Verdict::Draw => drawn.0.push(node),
            Verdict::Want => {
                drawn.0.push(node);
                drawn.1.push(node);
            }
            Verdict::Open(size) => open.push(Pending(size, node)),
        };
        judge(&mut drawn, &mut open, 0);
        // Opening a node replaces it by its children: the budget counts
        // what is drawn and what waits, as all of it would be drawn.
        while let Some(Pending(_, node)) = open.pop() {
            let link = self.link(node);
            if drawn.0.len() + open.len() + link.children as usize > budget {
                drawn.0.push(node);
                break;
            }
            for child in link.first_child..link.first_child + link.children {
                judge(&mut drawn, &mut open, child);
            }
        }
        drawn.0.extend(open.into_iter().map(|p| p.1));
        drawn
    }

    fn describe(&self, cut: &mut Cut) {
        let mut levels = (u16::MAX, 0);
        for &n in &cut.nodes {
            let link = self.link(n);
            levels = (levels.0.min(link.level), levels.1.max(link.level));
            cut.leaves += usize::from(link.children == 0);
        }
        cut.levels = if cut.nodes.is_empty() { (0, 0) } else { levels };
    }
}
