//! Statistics of a built kd-tree, as reported by `kdtrace stats` and compared
//! across builder settings (the figures of Wald & Havran 2006, Table 1, and of
//! pbrt-v3's `KdTreeAccel` statistics).

use super::build::{BuildConfig, KdTree};

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
            ..BuildStats::default()
        };
        let root_area = tree.bounds.area() as f64;
        let inv_root = if root_area > 0.0 { 1.0 / root_area } else { 0.0 };
        let (k_t, k_i) = (config.traversal_cost as f64, config.intersection_cost as f64);
        let mut depth_sum = 0u64;
        let mut refs = 0u64;
        tree.for_each_node(|_, node, bounds, depth| {
            let rel_area = bounds.area() as f64 * inv_root;
            if node.is_leaf() {
                let n = node.prim_count();
                s.leaves += 1;
                s.empty_leaves += (n == 0) as usize;
                s.max_depth = s.max_depth.max(depth);
                s.max_prims_per_leaf = s.max_prims_per_leaf.max(n);
                depth_sum += depth as u64;
                refs += n as u64;
                s.sah_cost += k_i * n as f64 * rel_area;
            } else {
                s.sah_cost += k_t * rel_area;
            }
        });
        let ratio = |a: u64, b: usize| if b > 0 { a as f64 / b as f64 } else { 0.0 };
        s.mean_leaf_depth = ratio(depth_sum, s.leaves);
        s.refs_per_triangle = ratio(refs, triangles);
        s.mean_prims_per_leaf = ratio(refs, s.leaves - s.empty_leaves);
        s
    }
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
