//! Level of detail: a hierarchy of Gaussians built once per scene, each
//! node the moment-matched merge of the nodes below it (`merge.rs`), built
//! bottom-up over an octree of the scene (`tree.rs`), and a per-camera cut
//! through it that draws a node in place of its subtree wherever the
//! subtree projects to a pixel or less (`cut.rs`). The cost of a frame then
//! follows the image, not the file. The cache file (`cache.rs`) of a scene
//! larger than memory is built cell by cell from the file (`streamed.rs`)
//! and read back by chunks (`paged.rs`).

pub mod cache;
mod cut;
mod merge;
mod paged;
mod streamed;
mod tree;

pub use cut::{cut, cut_at, Cut, LodPolicy, AUTO_PER_PIXEL, AUTO_PIXELS};
pub use merge::{mean_area, merge, Member, Merged};
pub use paged::PagedTree;
pub use streamed::{build_streamed, Listener};
pub use tree::{build, layout, Layout, MAX_CHILDREN};

use std::sync::Arc;

use rayon::prelude::*;

use crate::render::projection::COVARIANCE_DILATION;
use crate::scene::camera::Camera;
use crate::scene::splats::{SplatScene, MAX_OPACITY};

/// Where a node sits in the hierarchy.
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct NodeLink {
    /// Index of the first child (the children are consecutive); 0 for a leaf.
    pub first_child: u32,
    /// Number of children; 0 for a leaf (one of the scene's Gaussians).
    pub children: u32,
    /// Radius of the sphere about the node's mean that holds every
    /// Gaussian below it out to three standard deviations.
    pub extent: f32,
    /// Depth below the root (0).
    pub level: u16,
    /// Keeps the fields aligned.
    pub pad: u16,
    /// The mass of the scene's Gaussians below (opacity times
    /// [`mean_area`], summed).
    pub mass: f32,
    /// Their opacities, summed: what the renderers' dilation adds to
    /// that mass per unit of dilated area ([`LodTree::gather`]).
    pub coverage: f32,
}

/// What a cut reads of a hierarchy: in memory ([`LodTree`]) or paged in
/// from its cache file by chunks (`paged.rs`).
pub trait Hierarchy: Sync {
    /// Node `i`'s place and centre; None when it is not at hand.
    fn node(&self, i: u32) -> Option<(NodeLink, glam::Vec3)>;

    /// Whether every child of the node with `link` is at hand.
    fn has_children_of(&self, link: NodeLink) -> bool {
        link.children > 0
            && self.node(link.first_child).is_some()
            && self.node(link.first_child + link.children - 1).is_some()
    }
}

impl Hierarchy for LodTree {
    fn node(&self, i: u32) -> Option<(NodeLink, glam::Vec3)> {
        let link = *self.links.get(i as usize)?;
        Some((link, self.nodes.position[i as usize]))
    }

    fn has_children_of(&self, link: NodeLink) -> bool {
        link.children > 0
    }
}

/// A scene's hierarchy: node 0 is the root, nodes are breadth-first (so
/// coarse levels come first and a node's children are neighbours), and the
/// leaves are the scene's drawable Gaussians.
#[derive(Clone, Debug, Default)]
pub struct LodTree {
    /// Every node's Gaussian, in node order.
    pub nodes: SplatScene,
    /// Every node's place, in node order.
    pub links: Vec<NodeLink>,
    /// How many nodes are the scene's own Gaussians.
    pub leaves: usize,
    /// Gaussians of the scene left out because no renderer can draw them
    /// (non-finite values, opacity below 1/255).
    pub dropped: usize,
}

impl LodTree {
    /// Number of nodes.
    pub fn len(&self) -> usize {
        self.links.len()
    }

    /// True for the tree of a scene with nothing to draw.
    pub fn is_empty(&self) -> bool {
        self.links.is_empty()
    }

    /// Deepest level.
    pub fn depth(&self) -> u16 {
        self.links.iter().map(|l| l.level).max().unwrap_or(0)
    }

    /// The cut's nodes as a world-space scene for `camera`. A merged
    /// node's opacity is set for the pixel size where it is drawn: the
    /// renderers widen every Gaussian by [`COVARIANCE_DILATION`] px², which
    /// adds mass to each of the many sub-pixel Gaussians a node stands for
    /// but only once to the node, so the node's opacity is the mass of its
    /// leaves dilated over its own area dilated (mean areas with every
    /// variance grown by the dilation in world units at the node's depth).
    pub fn gather(&self, cut: &Cut, camera: &Camera) -> SplatScene {
        fn pick<T: Copy + Send + Sync>(values: &[T], nodes: &[u32]) -> Vec<T> {
            nodes.par_iter().map(|&n| values[n as usize]).collect()
        }
        let stride = self.nodes.sh_stride();
        let mut sh = vec![0.0; cut.nodes.len() * stride];
        if stride > 0 {
            sh.par_chunks_mut(stride)
                .zip(&cut.nodes)
                .for_each(|(out, &n)| out.copy_from_slice(self.nodes.sh_of(n as usize)));
        }
        let opacity_for = DrawnOpacity::new(camera);
        let opacity = cut
            .nodes
            .par_iter()
            .map(|&n| {
                let n = n as usize;
                let (position, scale) = (self.nodes.position[n], self.nodes.scale[n]);
                opacity_for.node(self.links[n], position, scale, self.nodes.opacity[n])
            })
            .collect();
        SplatScene {
            position: pick(&self.nodes.position, &cut.nodes),
            rotation: pick(&self.nodes.rotation, &cut.nodes),
            scale: pick(&self.nodes.scale, &cut.nodes),
            opacity,
            sh_degree: self.nodes.sh_degree,
            sh: Arc::new(sh),
        }
    }
}

/// A drawn node's opacity for one camera (see [`LodTree::gather`]).
pub struct DrawnOpacity {
    view: glam::Mat4,
    focal: f64,
    near: f64,
}

impl DrawnOpacity {
    /// For drawing from `camera`.
    pub fn new(camera: &Camera) -> Self {
        Self {
            view: camera.view(),
            focal: camera.focal_px().1.max(f32::MIN_POSITIVE) as f64,
            near: camera.near as f64,
        }
    }

    /// The opacity a node with `link` at `position` of `scale` is drawn
    /// with: a leaf's own; a merged node's, its leaves' dilated mass over
    /// its own dilated area.
    pub fn node(
        &self,
        link: NodeLink,
        position: glam::Vec3,
        scale: glam::Vec3,
        opacity: f32,
    ) -> f32 {
        if link.children == 0 {
            return opacity;
        }
        let depth = -(self.view.transform_point3(position).z as f64);
        let pixel = depth.max(self.near) / self.focal;
        let dilation = COVARIANCE_DILATION * pixel * pixel;
        let s = scale.as_dvec3();
        let grown = (s * s + glam::DVec3::splat(dilation)).map(f64::sqrt);
        let mass = link.mass as f64 + 3.0 * dilation * link.coverage as f64;
        let area = mean_area(grown.as_vec3()).max(f64::MIN_POSITIVE);
        ((mass / area) as f32).clamp(0.0, MAX_OPACITY)
    }
}

#[cfg(test)]
mod tests;
