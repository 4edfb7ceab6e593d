//! Node fetches and the per-ray counters they feed. Twin of
//! `glsl/traverse/node.glsl`.

use super::State;
use crate::kdtree::KdNode;

/// Per-ray counters, as written by the GPU when counters are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Node fetches (interior and leaf), climbs of kd-backtrack included.
    pub nodes: u32,
    /// Leaves visited (their triangles tested).
    pub leaves: u32,
    /// Ray/triangle tests; in any-hit mode, up to and including the first hit.
    pub triangles: u32,
    /// Restarts (kd-restart, push-down, short stack running empty), backtracks or rope hops.
    pub restarts: u32,
    /// Traversal loop iterations.
    pub steps: u32,
    /// Short-stack entries dropped because the stack was full.
    pub drops: u32,
}

impl State<'_, '_> {
    /// Fetches a node, counting the visit and the loop step (`fetch_node`).
    pub(super) fn fetch(&mut self, node: u32) -> KdNode {
        self.c.steps += 1;
        self.c.nodes += 1;
        if let Some(log) = self.log.as_mut() {
            log.fetched(node);
        }
        self.scene.nodes[node as usize]
    }
}
