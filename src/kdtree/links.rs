//! Side buffers for the stackless variants that need more than the 8-byte node:
//! parent links and node boxes for kd-backtrack (Foley & Sugerman 2005), leaf
//! ropes and boxes for rope traversal (Popov, Günther, Seidel & Slusallek 2007).
//! They live beside the nodes, never in the hot node itself, and are built and
//! uploaded only when a variant needs them.

use super::KdNode;
use crate::geom::Aabb;

pub use crate::consts::NO_ROPE;

/// Per-node side data, indexed by node index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TreeLinks {
    /// Parent of each node (the root's is itself, 0).
    pub parents: Vec<u32>,
    /// Box of each node: min x, y, z, max x, y, z, recomputed from the splits.
    pub boxes: Vec<[f32; 6]>,
    /// For each leaf, the node across each face: index `2·axis` is the min face,
    /// `2·axis + 1` the max face; `NO_ROPE` on the scene boundary. The rope points
    /// to the smallest node that holds the whole face (the sibling subtree the
    /// face borders), as in Popov et al. without the rope-pushing optimisation.
    /// Interior nodes hold `NO_ROPE`.
    pub ropes: Vec<[u32; 6]>,
}

impl TreeLinks {
    /// Links of the tree `nodes` whose root box is `bounds`.
    pub fn new(nodes: &[KdNode], bounds: Aabb) -> TreeLinks {
        let n = nodes.len();
        let mut links = TreeLinks { parents: vec![0; n], boxes: vec![[0.0; 6]; n], ropes: vec![[NO_ROPE; 6]; n] };
        // Boxes, ropes and parents flow top-down: a child inherits its parent's box
        // cut at the split and its parent's ropes, with the face on the split plane
        // pointing to the sibling.
        let mut stack = vec![(0u32, bounds, [NO_ROPE; 6])];
        while let Some((index, b, ropes)) = stack.pop() {
            links.boxes[index as usize] = [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
            let node = nodes[index as usize];
            if node.is_leaf() {
                links.ropes[index as usize] = ropes;
                continue;
            }
            let (below, above) = (index + 1, node.above_child());
            links.parents[below as usize] = index;
            links.parents[above as usize] = index;
            let (axis, split) = (node.axis(), node.split());
            let (mut below_box, mut above_box) = (b, b);
            below_box.max[axis] = split;
            above_box.min[axis] = split;
            let mut below_ropes = ropes;
            below_ropes[2 * axis + 1] = above;
            let mut above_ropes = ropes;
            above_ropes[2 * axis] = below;
            stack.push((above, above_box, above_ropes));
            stack.push((below, below_box, below_ropes));
        }
        links
    }

    /// Bytes of the three side buffers.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(self.parents.as_slice())
            + std::mem::size_of_val(self.boxes.as_slice())
            + std::mem::size_of_val(self.ropes.as_slice())
    }
}
