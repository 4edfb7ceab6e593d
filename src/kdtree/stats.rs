//! Statistics of a built kd-tree, as reported by `kdtrace stats` and compared
//! across builder settings (the figures of Wald & Havran 2006, Table 1, and of
//! pbrt-v3's `KdTreeAccel` statistics).

use super::config::BuildConfig;
use super::node::KdNode;
use super::tree::KdTree;
use crate::geom::Aabb;

/// What a build produced. Computed once, after the build, by walking the tree.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BuildStats {
    /// Triangles in the tree (the input less the skipped ones).
    pub triangles: usize,
    /// Input triangles left out: zero area or non-finite coordinates.
    pub skipped_triangles: usize,
    /// Nodes, interior and leaves.
    pub nodes: usize,
    /// Leaves, empty ones included.
    pub leaves: usize,
    /// Leaves that reference no triangle (cut-off empty space).
    pub empty_leaves: usize,
    /// The depth limit the builder used (root = depth 0).
    pub depth_limit: u32,
    /// Depth of the deepest leaf (root = depth 0).
    pub max_depth: u32,
    /// Mean depth over all leaves, empty ones included.
    pub mean_leaf_depth: f64,
    /// Entries of `prim_indices` per triangle in the tree (≥ 1; more when
    /// triangles straddle split planes).
    pub refs_per_triangle: f64,
    /// Mean triangles per non-empty leaf.
    pub mean_prims_per_leaf: f64,
    /// Largest leaf.
    pub max_prims_per_leaf: u32,
    /// SAH cost of the whole tree: `Σ_interior K_T·A(node)/A(root) +
    /// Σ_leaves K_I·n·A(leaf)/A(root)`, with the build's `K_T` and `K_I` (no
    /// empty bonus). Only comparable between trees built with the same costs.
    pub sah_cost: f64,
    /// Wall time of the build itself (not of computing these statistics).
    pub build_seconds: f64,
    /// Bytes of the node array (`nodes.len() · 8`).
    pub node_bytes: usize,
    /// Bytes of the primitive index array (`prim_indices.len() · 4`).
    pub index_bytes: usize,
    /// Peak bytes of the builder's scratch data (sorted event lists and
    /// per-node triangle lists, summed over all threads) during the build.
    /// Depends a little on scheduling; the tree itself does not.
    pub peak_scratch_bytes: usize,
    /// Worker threads the build could use (rayon's pool size).
    pub threads: usize,
}

impl BuildStats {
    /// Walks `tree` (its `stats` field is ignored) and gathers the statistics;
    /// `triangles` and `skipped_triangles` are as counted by the builder.
    pub fn compute(
        tree: &KdTree,
        config: &BuildConfig,
        triangles: usize,
        skipped_triangles: usize,
        build_seconds: f64,
    ) -> BuildStats {
        let mut s = BuildStats {
            triangles,
            skipped_triangles,
            nodes: tree.nodes.len(),
            depth_limit: config.depth_limit(triangles),
            build_seconds,
            node_bytes: std::mem::size_of_val(tree.nodes.as_slice()),
            index_bytes: std::mem::size_of_val(tree.prim_indices.as_slice()),
            ..BuildStats::default()
        };
        let root_area = tree.bounds.area() as f64;
        let inv_root = if root_area > 0.0 { 1.0 / root_area } else { 0.0 };
        let costs = (config.traversal_cost as f64 * inv_root, config.intersection_cost as f64 * inv_root);
        let sums = Sums::gather(tree, 0, tree.bounds, 0, costs);
        s.leaves = sums.leaves;
        s.empty_leaves = sums.empty_leaves;
        s.max_depth = sums.max_depth;
        s.max_prims_per_leaf = sums.max_prims;
        s.sah_cost = sums.sah_cost;
        let (depth_sum, refs) = (sums.depth_sum, sums.refs);
        let ratio = |a: u64, b: usize| if b > 0 { a as f64 / b as f64 } else { 0.0 };
        s.mean_leaf_depth = ratio(depth_sum, s.leaves);
        s.refs_per_triangle = ratio(refs, triangles);
        s.mean_prims_per_leaf = ratio(refs, s.leaves - s.empty_leaves);
        s
    }
}

/// Sums over a subtree, gathered in parallel near the root.
#[derive(Default)]
struct Sums {
    leaves: usize,
    empty_leaves: usize,
    max_depth: u32,
    max_prims: u32,
    depth_sum: u64,
    refs: u64,
    sah_cost: f64,
}

impl Sums {
    /// Subtrees this close to the root are walked as parallel tasks; the split
    /// is fixed, so the floating-point sums do not depend on the thread count.
    const PARALLEL_DEPTH: u32 = 6;

    /// The sums over the subtree of node `index` with box `bounds` at `depth`,
    /// with `costs` = (`K_T`, `K_I`) / root area.
    fn gather(tree: &KdTree, index: u32, bounds: Aabb, depth: u32, costs: (f64, f64)) -> Sums {
        let node = tree.nodes[index as usize];
        if depth < Self::PARALLEL_DEPTH && !node.is_leaf() {
            let (below, above) = split_box(&node, bounds);
            let (a, b) = rayon::join(
                || Sums::gather(tree, index + 1, below, depth + 1, costs),
                || Sums::gather(tree, node.above_child(), above, depth + 1, costs),
            );
            return Sums {
                leaves: a.leaves + b.leaves,
                empty_leaves: a.empty_leaves + b.empty_leaves,
                max_depth: a.max_depth.max(b.max_depth),
                max_prims: a.max_prims.max(b.max_prims),
                depth_sum: a.depth_sum + b.depth_sum,
                refs: a.refs + b.refs,
                sah_cost: costs.0 * bounds.area() as f64 + a.sah_cost + b.sah_cost,
            };
        }
        let mut s = Sums::default();
        let mut stack = vec![(index, bounds, depth)];
        while let Some((index, bounds, depth)) = stack.pop() {
            let node = tree.nodes[index as usize];
            let area = bounds.area() as f64;
            if node.is_leaf() {
                let n = node.prim_count();
                s.leaves += 1;
                s.empty_leaves += (n == 0) as usize;
                s.max_depth = s.max_depth.max(depth);
                s.max_prims = s.max_prims.max(n);
                s.depth_sum += depth as u64;
                s.refs += n as u64;
                s.sah_cost += costs.1 * n as f64 * area;
            } else {
                s.sah_cost += costs.0 * area;
                let (below, above) = split_box(&node, bounds);
                stack.push((node.above_child(), above, depth + 1));
                stack.push((index + 1, below, depth + 1));
            }
        }
        s
    }
}

/// The boxes of an interior node's below and above children.
fn split_box(node: &KdNode, bounds: Aabb) -> (Aabb, Aabb) {
    let (axis, split) = (node.axis(), node.split());
    let (mut below, mut above) = (bounds, bounds);
    below.max[axis] = split;
    above.min[axis] = split;
    (below, above)
}

impl std::fmt::Display for BuildStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} triangles ({} skipped), {} nodes, {} leaves ({} empty), depth max {} (limit {}) mean {:.2}, \
             {:.3} refs/triangle, {:.2} prims/leaf (max {}), SAH cost {:.2}, built in {:.3} s",
            self.triangles,
            self.skipped_triangles,
            self.nodes,
            self.leaves,
            self.empty_leaves,
            self.max_depth,
            self.depth_limit,
            self.mean_leaf_depth,
            self.refs_per_triangle,
            self.mean_prims_per_leaf,
            self.max_prims_per_leaf,
            self.sah_cost,
            self.build_seconds
        )
    }
}
