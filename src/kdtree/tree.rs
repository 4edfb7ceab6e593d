//! The kd-tree itself ([`KdTree`]): the node array, the leaves' triangle
//! indices and the box, with the walks and the structural check every user of a
//! tree relies on, and the rule for which triangles a tree holds ([`is_skipped`]).

use glam::Vec3;

use super::node::KdNode;
use super::stats::BuildStats;
use crate::consts::MAX_TREE_DEPTH;
use crate::geom::Aabb;

/// A kd-tree over a triangle list, ready for upload.
#[derive(Clone, Debug)]
pub struct KdTree {
    /// Nodes in depth-first order; `nodes[0]` is the root.
    pub nodes: Vec<KdNode>,
    /// Triangle indices (into the `triangles` slice given to [`KdTree::build`])
    /// referenced by the leaves; a triangle may appear in several leaves.
    pub prim_indices: Vec<u32>,
    /// The box of all triangles in the tree ([`Aabb::EMPTY`] when there are none).
    pub bounds: Aabb,
    /// Statistics of the tree and its build.
    pub stats: BuildStats,
}

/// True when a triangle has a non-finite coordinate.
pub fn is_non_finite(tri: &[Vec3; 3]) -> bool {
    !tri.iter().all(|v| v.is_finite())
}

/// True when a (finite) triangle has zero area: two equal vertices or three
/// collinear ones. The cross product of the edges is evaluated in f64, where the
/// products of f32 differences are exact, so the answer is exact for all but
/// extreme exponent ranges. In exact arithmetic the edge functions of such a
/// triangle sum to zero for every ray, so the watertight test (Woop, Benthin &
/// Wald 2013) and the f64 reference never report a hit on it.
pub fn is_zero_area(tri: &[Vec3; 3]) -> bool {
    let [a, b, c] = tri.map(|v| v.as_dvec3());
    (b - a).cross(c - a) == glam::DVec3::ZERO
}

/// True when the builder leaves the triangle out: a non-finite coordinate (the
/// scene loader rejects those; this is a safety net) or zero area (never hit).
pub fn is_skipped(tri: &[Vec3; 3]) -> bool {
    is_non_finite(tri) || is_zero_area(tri)
}

impl KdTree {
    /// Visits every node in depth-first order (the order of `nodes`) with its
    /// index, its box (recomputed from the splits, starting at `bounds`) and its
    /// depth (root = 0). Iterative; expects a well-formed tree ([`KdTree::check`]).
    pub fn for_each_node(&self, mut f: impl FnMut(u32, &KdNode, Aabb, u32)) {
        let mut stack = vec![(0u32, self.bounds, 0u32)];
        while let Some((index, bounds, depth)) = stack.pop() {
            let node = &self.nodes[index as usize];
            f(index, node, bounds, depth);
            if !node.is_leaf() {
                let (axis, split) = (node.axis(), node.split());
                let mut below = bounds;
                below.max[axis] = split;
                let mut above = bounds;
                above.min[axis] = split;
                stack.push((node.above_child(), above, depth + 1));
                stack.push((index + 1, below, depth + 1));
            }
        }
    }

    /// Visits every leaf in depth-first order with its node index, the node, its
    /// recomputed box and its depth (see [`KdTree::for_each_node`]).
    pub fn for_each_leaf(&self, mut f: impl FnMut(u32, &KdNode, Aabb, u32)) {
        self.for_each_node(|index, node, bounds, depth| {
            if node.is_leaf() {
                f(index, node, bounds, depth)
            }
        });
    }

    /// The primitive indices of a leaf node.
    pub fn leaf_prims(&self, leaf: &KdNode) -> &[u32] {
        let offset = leaf.prim_offset() as usize;
        &self.prim_indices[offset..offset + leaf.prim_count() as usize]
    }

    /// Checks the structure a traversal relies on, for `triangle_count`
    /// triangles: every interior node's below child is the next node and its
    /// above child lies further on; every node is reached exactly once from the
    /// root; leaves stay within `prim_indices` and reference valid triangles;
    /// no leaf is deeper than [`MAX_TREE_DEPTH`]; split positions are finite.
    pub fn check(&self, triangle_count: usize) -> Result<(), String> {
        if self.nodes.is_empty() {
            return Err("no nodes".into());
        }
        let mut seen = vec![false; self.nodes.len()];
        let mut stack = vec![(0usize, 0u32)];
        while let Some((index, depth)) = stack.pop() {
            let Some(node) = self.nodes.get(index) else {
                return Err(format!("child index {index} out of range ({} nodes)", self.nodes.len()));
            };
            if std::mem::replace(&mut seen[index], true) {
                return Err(format!("node {index} reached twice"));
            }
            if depth > MAX_TREE_DEPTH {
                return Err(format!("node {index} at depth {depth} > {MAX_TREE_DEPTH}"));
            }
            if node.is_leaf() {
                let (offset, count) = (node.prim_offset() as usize, node.prim_count() as usize);
                let Some(prims) = self.prim_indices.get(offset..offset + count) else {
                    return Err(format!("leaf {index}: prims {offset}..{} out of range", offset + count));
                };
                if let Some(p) = prims.iter().find(|&&p| p as usize >= triangle_count) {
                    return Err(format!("leaf {index}: triangle {p} out of range ({triangle_count})"));
                }
            } else {
                let above = node.above_child() as usize;
                if above <= index + 1 {
                    return Err(format!("node {index}: above child {above} not after the below child"));
                }
                if !node.split().is_finite() {
                    return Err(format!("node {index}: split {}", node.split()));
                }
                // A set flag skips its child's triangles (stack.glsl): it must be true.
                let empty = |i: usize| self.nodes.get(i).is_some_and(|c| c.is_empty_leaf());
                if (node.below_empty() && !empty(index + 1)) || (node.above_empty() && !empty(above)) {
                    return Err(format!("node {index}: flags a child with triangles as an empty leaf"));
                }
                stack.push((above, depth + 1));
                stack.push((index + 1, depth + 1));
            }
        }
        match seen.iter().position(|s| !s) {
            Some(i) => Err(format!("node {i} unreachable")),
            None => Ok(()),
        }
    }
}
