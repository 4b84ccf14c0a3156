//! A level-of-detail hierarchy on the GPU: every node uploaded once as a
//! world Gaussian, with the record the `project` kernel needs to decide on
//! its own, per frame, whether the node is in the cut (docs/method.md §8:
//! the cut needs no tree walk, because a parent's bounding sphere holds its
//! children's). A moving camera then costs one projection of the nodes
//! instead of a cut, a gather and an upload on the CPU.

use crate::error::{Error, Result};
use crate::render::lod::LodTree;

/// Set in a node's first word for the scene's own Gaussians (the leaves).
pub const LEAF_BIT: u32 = 0x8000_0000;
/// The root's parent.
pub const NO_PARENT: u32 = 0x7fff_ffff;

/// Per node, what `project.wgsl` reads from its `lod` binding: the parent's
/// index (or [`NO_PARENT`]) with [`LEAF_BIT`] for a leaf, then the bits of
/// the bounding sphere's radius, the leaves' mass and their summed opacity.
pub fn node_records(tree: &LodTree) -> Result<Vec<[u32; 4]>> {
    if tree.len() >= NO_PARENT as usize {
        return Err(Error::device(format!(
            "a hierarchy of {} nodes is more than the GPU cut indexes ({NO_PARENT}); use --renderer cpu",
            tree.len()
        )));
    }
    let mut records: Vec<[u32; 4]> = tree
        .links
        .iter()
        .map(|l| {
            let leaf = if l.children == 0 { LEAF_BIT } else { 0 };
            [
                NO_PARENT | leaf,
                l.extent.to_bits(),
                l.mass.to_bits(),
                l.coverage.to_bits(),
            ]
        })
        .collect();
    for (parent, l) in tree.links.iter().enumerate() {
        for child in l.first_child..l.first_child + l.children {
            let record = &mut records[child as usize];
            record[0] = (record[0] & LEAF_BIT) | parent as u32;
        }
    }
    Ok(records)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::synthetic::synthetic_scene;

    /// Every node names its parent (the root none), and exactly the
    /// scene's own Gaussians are marked as leaves.
    #[test]
    fn records_name_each_nodes_parent_and_mark_the_leaves() {
        let tree = crate::render::lod::build(&synthetic_scene(3_000, 5));
        let records = node_records(&tree).unwrap();
        assert_eq!(records.len(), tree.len());
        assert_eq!(records[0][0] & NO_PARENT, NO_PARENT);
        let leaves = records.iter().filter(|r| r[0] & LEAF_BIT != 0).count();
        assert_eq!(leaves, tree.leaves);
        for (i, l) in tree.links.iter().enumerate().skip(1) {
            let parent = (records[i][0] & NO_PARENT) as usize;
            let p = tree.links[parent];
            assert!((p.first_child..p.first_child + p.children).contains(&(i as u32)));
            assert_eq!(f32::from_bits(records[i][1]), l.extent);
            assert!(
                p.extent >= l.extent,
                "a parent's sphere holds its children's"
            );
        }
    }
}
