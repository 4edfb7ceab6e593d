//! The SAH kd-tree builder of Wald & Havran 2006 ("On building fast kd-trees
//! for ray tracing, and on doing that in O(N log N)", RT'06): the surface area
//! heuristic (Goldsmith & Salmon 1987; MacDonald & Booth 1990) evaluated
//! exactly at every candidate plane by sweeping split events that stay sorted
//! from the root down, with "perfect splits" (each straddling triangle clipped
//! to the child's box, Sutherland–Hodgman), planar triangles sent to the
//! cheaper side, an empty-space bonus, automatic termination when a split costs
//! more than a leaf, and pbrt-v3's depth limit. Built in parallel with rayon;
//! the tree does not depend on the thread count. See `build/sah.rs` for the
//! algorithm and docs/BUILDER.md for how the defaults were chosen.
//!
//! The result is the 8-byte node array of [`KdNode`](super::node::KdNode) in depth-first order: the
//! below child of an interior node is the next node, the above child is stored
//! in the node. Leaves own contiguous ranges of `prim_indices`.

mod clip;
mod sah;

use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::time::Instant;

use glam::Vec3;

pub use super::config::{BuildConfig, Builder};
use super::stats::BuildStats;
pub use super::tree::{is_non_finite, is_skipped, is_zero_area, KdTree};
use crate::consts::PRIM_INCOMPLETE;
use crate::geom::Aabb;

/// How far a build has got, for a progress bar: shared with the building
/// threads, read from any other (see [`KdTree::build_with_progress`]).
#[derive(Debug, Default)]
pub struct BuildProgress {
    /// Progress units of the finished subtrees, out of [`BuildProgress::TOTAL`].
    done: AtomicU64,
    /// The [`BuildStage`] as a number.
    stage: AtomicU8,
}

/// The stages of a build, in order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildStage {
    /// Not started yet.
    Waiting,
    /// Triangle boxes, skipped triangles, the first sort of the events.
    Preparing,
    /// Choosing splits and building subtrees.
    Splitting,
    /// Walking the finished tree for its statistics.
    Statistics,
    /// Done.
    Finished,
}

impl BuildProgress {
    /// The progress units of a whole tree. Each node's share is divided
    /// between its children in proportion to their triangles, and a subtree
    /// reports its share when it is finished, so the finished share grows
    /// roughly with the work done and ends at exactly `TOTAL`.
    pub const TOTAL: u64 = 1 << 40;

    /// The fraction of the tree built, in `[0, 1]`.
    pub fn fraction(&self) -> f64 {
        self.done.load(Ordering::Relaxed) as f64 / Self::TOTAL as f64
    }

    /// The stage the build is in.
    pub fn stage(&self) -> BuildStage {
        match self.stage.load(Ordering::Relaxed) {
            0 => BuildStage::Waiting,
            1 => BuildStage::Preparing,
            2 => BuildStage::Splitting,
            3 => BuildStage::Statistics,
            _ => BuildStage::Finished,
        }
    }

    fn set_stage(&self, stage: BuildStage) {
        self.stage.store(stage as u8, Ordering::Relaxed);
    }

    pub(crate) fn add_done(&self, units: u64) {
        self.done.fetch_add(units, Ordering::Relaxed);
    }
}

/// A triangle's bounding box, with -0.0 turned into +0.0 so that positions
/// compare and sort alike.
fn triangle_box(tri: &[Vec3; 3]) -> Aabb {
    let b = Aabb::from_points(tri);
    Aabb::new(b.min + Vec3::ZERO, b.max + Vec3::ZERO)
}

impl KdTree {
    /// Builds a kd-tree over `triangles` with the SAH (see the module docs), on
    /// rayon's current thread pool (`ThreadPool::install` to choose it).
    ///
    /// Triangles with a non-finite coordinate or zero area ([`is_skipped`]) are
    /// left out of the tree: no leaf references them, and they do not count in
    /// `bounds`. If no triangle is left, the tree is a single empty leaf with
    /// empty bounds (the tracer refuses such a scene itself).
    ///
    /// The build is deterministic — the same input and config give the same
    /// tree whatever the number of threads — and never creates a leaf deeper
    /// than [`BuildConfig::depth_limit`]. Within a leaf, indices are ascending.
    /// Scratch memory is a few sorted event lists per node on the current
    /// paths of the recursion (about 50 bytes per triangle reference at the
    /// root); its peak is reported in `stats.peak_scratch_bytes`.
    ///
    /// # Panics
    /// If `triangles` has 2³⁰ or more non-skipped entries or `PRIM_INCOMPLETE`
    /// (2³² − 3) or more in all, or the tree outgrows the node's fields (2²⁸ nodes, 2³⁰ primitives per leaf).
    pub fn build(triangles: &[[Vec3; 3]], config: &BuildConfig) -> KdTree {
        Self::build_with_progress(triangles, config, None)
    }

    /// [`KdTree::build`], reporting its stage and the fraction of the tree
    /// built to `progress`, which another thread may poll (a progress bar).
    pub fn build_with_progress(
        triangles: &[[Vec3; 3]],
        config: &BuildConfig,
        progress: Option<&BuildProgress>,
    ) -> KdTree {
        let start = Instant::now();
        let stage = |s| {
            if let Some(p) = progress {
                p.set_stage(s)
            }
        };
        stage(BuildStage::Preparing);
        assert!(
            triangles.len() < PRIM_INCOMPLETE as usize,
            "{} triangles: primitive ids must stay below {PRIM_INCOMPLETE:#x}",
            triangles.len()
        );
        use rayon::prelude::*;
        let boxes: Vec<Aabb> = triangles.par_iter().map(triangle_box).collect();
        let included: Vec<u32> =
            (0..triangles.len() as u32).into_par_iter().filter(|&i| !is_skipped(&triangles[i as usize])).collect();
        let bounds = included.iter().fold(Aabb::EMPTY, |b, &i| b.union(boxes[i as usize]));
        let included_count = included.len();
        let max_depth = config.depth_limit(included_count);

        let ctx = sah::Ctx::new(triangles, &boxes, config, max_depth, progress);
        stage(BuildStage::Splitting);
        let (mut nodes, prim_indices) = sah::build(&ctx, included, bounds);
        super::node::mark_empty_children(&mut nodes);
        let build_seconds = start.elapsed().as_secs_f64();
        stage(BuildStage::Statistics);
        let mut tree = KdTree { nodes, prim_indices, bounds, stats: BuildStats::default() };
        tree.stats =
            BuildStats::compute(&tree, config, included_count, triangles.len() - included_count, build_seconds);
        tree.stats.peak_scratch_bytes = ctx.meter.peak();
        tree.stats.threads = rayon::current_num_threads();
        stage(BuildStage::Finished);
        tree
    }
}

#[cfg(test)]
mod tests;
