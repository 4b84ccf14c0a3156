//! Level of detail: a hierarchy of Gaussians built once per scene, each
//! node the moment-matched merge of the nodes below it (`merge.rs`), built
//! bottom-up over an octree of the scene (`tree.rs`), and a per-camera cut
//! through it that draws a node in place of its subtree wherever the
//! subtree projects to a pixel or less (`cut.rs`). The cost of a frame then
//! follows the image, not the file.

mod cut;
mod merge;
mod tree;

pub use cut::{Cut, LodPolicy, AUTO_PER_PIXEL, AUTO_PIXELS};
pub use merge::{mean_area, merge, Member, Merged};
pub use tree::{build, MAX_CHILDREN};

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
        let view = camera.view();
        let focal = camera.focal_px().1.max(f32::MIN_POSITIVE) as f64;
        let opacity = cut
            .nodes
            .par_iter()
            .map(|&n| {
                let (n, link) = (n as usize, self.links[n as usize]);
                if link.children == 0 {
                    return self.nodes.opacity[n];
                }
                let depth = -(view.transform_point3(self.nodes.position[n]).z as f64);
                let pixel = depth.max(camera.near as f64) / focal;
                let dilation = COVARIANCE_DILATION * pixel * pixel;
                let s = self.nodes.scale[n].as_dvec3();
                let grown = (s * s + glam::DVec3::splat(dilation)).map(f64::sqrt);
                let mass = link.mass as f64 + 3.0 * dilation * link.coverage as f64;
                let area = mean_area(grown.as_vec3()).max(f64::MIN_POSITIVE);
                ((mass / area) as f32).clamp(0.0, MAX_OPACITY)
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

#[cfg(test)]
mod tests;
