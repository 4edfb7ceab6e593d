//! Binned SAH for the large nodes at the top of the tree (Shevtsov, Soupikov
//! & Kapustin 2007 for kd-trees; Wald 2007 for BVHs), above the exact sweep.
//!
//! A node with at least `min_prims` triangles keeps no sorted event lists:
//! only its triangles and their (clipped) boxes. Its split is chosen among
//! `bins − 1` equally spaced planes per axis, from counts of the boxes' lower
//! and upper faces per bin — one pass over the triangles instead of a sweep
//! over sorted events, and no event lists to split. The counts are estimates
//! (a face in a bin is taken to lie below that bin's upper plane); the split
//! itself classifies every triangle exactly against the chosen plane, clipping
//! straddlers to each child as the sweep does ("perfect splits"). A node below
//! the threshold sorts its events once and is handed to the exact sweep, so
//! the deep levels, where most nodes are, keep the exact SAH.
//!
//! Deterministic whatever the thread count: the counts are integer sums, and
//! every decision depends only on the node's own data.

use rayon::prelude::*;

use super::{
    build_parallel, clip_straddler, decide, leaf_part, per_axis, push_events, radix_sort_events, split_share, Ctx,
    NodeData, Part, Split, PARALLEL_AXIS_PRIMS, PARALLEL_CLIP_PRIMS, RADIX_SORT_EVENTS,
};
use crate::geom::Aabb;
use crate::kdtree::build::BuildProgress;

/// Nodes of at least this many triangles count their bins in parallel chunks.
const PARALLEL_BIN_PRIMS: usize = 16 * 1024;

/// A node above the threshold: triangle indices, ascending, and each
/// triangle's box clipped to the node.
struct RefNode {
    prims: Vec<u32>,
    boxes: Vec<Aabb>,
}

impl RefNode {
    /// Heap bytes held.
    fn bytes(&self) -> usize {
        self.prims.capacity() * 4 + self.boxes.capacity() * std::mem::size_of::<Aabb>()
    }

    /// The node's sorted event lists, for the exact sweep below the threshold.
    fn into_events(self) -> NodeData {
        let n = self.prims.len();
        let axes = per_axis(n >= PARALLEL_AXIS_PRIMS, |axis| {
            let mut events = Vec::with_capacity(2 * n);
            for (i, b) in self.boxes.iter().enumerate() {
                push_events(&mut events, b, axis, i as u32);
            }
            if events.len() >= RADIX_SORT_EVENTS {
                radix_sort_events(&mut events);
            } else {
                events.sort_unstable();
            }
            events
        });
        NodeData::from_axes(self.prims, axes)
    }
}

/// Where the lower and upper faces of the boxes fall, per axis and bin:
/// `counts[axis][bin] = [lower faces, upper faces]`.
type Counts = Vec<[[u32; 2]; 3]>;

/// The bin grid of a voxel: bin `k` of an axis spans `[lo + k·w, lo + (k+1)·w)`.
struct Grid {
    bins: usize,
    lo: [f32; 3],
    /// Bins per unit length (0 on a flat axis).
    scale: [f32; 3],
}

impl Grid {
    fn new(voxel: &Aabb, bins: usize) -> Grid {
        let extent = voxel.extent();
        let scale = [0, 1, 2].map(|a| if extent[a] > 0.0 { bins as f32 / extent[a] } else { 0.0 });
        Grid { bins, lo: voxel.min.to_array(), scale }
    }

    fn bin(&self, axis: usize, x: f32) -> usize {
        let k = (x - self.lo[axis]) * self.scale[axis];
        // `as` saturates: negatives (and NaN) to 0.
        (k as usize).min(self.bins - 1)
    }

    fn count(&self, boxes: &[Aabb]) -> Counts {
        let mut counts = vec![[[0u32; 2]; 3]; self.bins];
        for b in boxes {
            for axis in 0..3 {
                counts[self.bin(axis, b.min[axis])][axis][0] += 1;
                counts[self.bin(axis, b.max[axis])][axis][1] += 1;
            }
        }
        counts
    }
}

/// The cheapest of the `bins − 1` planes per axis, by the SAH with the
/// binned counts; ties go to the lower axis, then the lower plane.
fn find_split(ctx: &Ctx, node: &RefNode, voxel: &Aabb, bins: usize) -> Option<Split> {
    let n = node.prims.len();
    let grid = Grid::new(voxel, bins);
    let counts = if n >= PARALLEL_BIN_PRIMS {
        node.boxes.par_chunks(4096).map(|chunk| grid.count(chunk)).reduce(
            || vec![[[0u32; 2]; 3]; bins],
            |mut a, b| {
                for (x, y) in a.iter_mut().zip(&b) {
                    for axis in 0..3 {
                        x[axis][0] += y[axis][0];
                        x[axis][1] += y[axis][1];
                    }
                }
                a
            },
        )
    } else {
        grid.count(&node.boxes)
    };

    let extent = voxel.max.as_dvec3() - voxel.min.as_dvec3();
    let area = 2.0 * (extent.x * extent.y + extent.y * extent.z + extent.z * extent.x);
    let mut best: Option<Split> = None;
    for axis in 0..3 {
        let (lo, hi) = (voxel.min[axis], voxel.max[axis]);
        if lo >= hi {
            continue;
        }
        // As in the sweep: a child's relative area is cap + width·rim.
        let (e1, e2) = (extent[(axis + 1) % 3], extent[(axis + 2) % 3]);
        let (cap, rim) = (2.0 * e1 * e2 / area, 2.0 * (e1 + e2) / area);
        let width = extent[axis] / bins as f64;
        let (mut below, mut ended) = (0usize, 0usize);
        let mut last = lo;
        for k in 1..bins {
            below += counts[k - 1][axis][0] as usize;
            ended += counts[k - 1][axis][1] as usize;
            let pos = (lo as f64 + k as f64 * width) as f32;
            if pos <= last || pos >= hi {
                continue;
            }
            last = pos;
            let above = n - ended;
            let d = pos as f64 - lo as f64;
            let p_below = cap + d * rim;
            let p_above = cap + (hi as f64 - pos as f64) * rim;
            let cost = ctx.costs.split(p_below, p_above, below, above);
            if best.map_or(true, |b| cost < b.cost) {
                best = Some(Split { axis, key: super::ordered(pos), pos, cost, planar_below: true, below, above });
            }
        }
    }
    best
}

/// Splits a binned node at `s`: a triangle whose (clipped) box ends at or
/// before the plane goes below (flat ones in the plane too), one that starts
/// at or after it above, and the rest are clipped to both children.
fn split_node(ctx: &Ctx, node: RefNode, voxel: &Aabb, s: &Split) -> [(RefNode, Aabb); 2] {
    let (axis, pos) = (s.axis, s.pos);
    let mut below_box = *voxel;
    below_box.max[axis] = pos;
    let mut above_box = *voxel;
    above_box.min[axis] = pos;

    let straddles = |b: &Aabb| b.min[axis] < pos && b.max[axis] > pos;
    let straddlers: Vec<usize> = (0..node.prims.len()).filter(|&i| straddles(&node.boxes[i])).collect();
    let clip = |&i: &usize| clip_straddler(ctx, node.prims[i], voxel, &below_box, &above_box, s);
    let clipped: Vec<[Option<Aabb>; 2]> = if straddlers.len() >= PARALLEL_CLIP_PRIMS {
        straddlers.par_iter().map(clip).collect()
    } else {
        straddlers.iter().map(clip).collect()
    };

    let mut children = [s.below, s.above]
        .map(|estimate| RefNode { prims: Vec::with_capacity(estimate), boxes: Vec::with_capacity(estimate) });
    let mut next = straddlers.iter().zip(&clipped).peekable();
    for (i, (&prim, b)) in node.prims.iter().zip(&node.boxes).enumerate() {
        if next.peek().is_some_and(|(&j, _)| j == i) {
            let (_, sides) = next.next().expect("peeked");
            for (child, side) in children.iter_mut().zip(sides) {
                if let Some(side) = side {
                    child.prims.push(prim);
                    child.boxes.push(*side);
                }
            }
        } else {
            let c = if b.max[axis] <= pos { 0 } else { 1 };
            children[c].prims.push(prim);
            children[c].boxes.push(*b);
        }
    }
    let [below, above] = children;
    [(below, below_box), (above, above_box)]
}

/// The binned builder's parameters.
struct Binning {
    /// Bins per axis (at least 2).
    bins: usize,
    /// Nodes of at least this many triangles are binned.
    min_prims: usize,
}

/// Builds a subtree from a node: binned splits while the node has at least
/// `b.min_prims` triangles, the exact sweep below. `ctx.meter` counts the
/// node's bytes on entry and no longer on return; `share` is its part of the
/// build's progress units.
fn build_node(ctx: &Ctx, node: RefNode, voxel: Aabb, depth: u32, bad_refines: u32, share: u64, b: &Binning) -> Part {
    if node.prims.len() < b.min_prims {
        let bytes = node.bytes();
        let data = node.into_events();
        ctx.meter.add(data.bytes());
        ctx.meter.sub(bytes);
        return build_parallel(ctx, data, voxel, depth, bad_refines, share);
    }
    let decision = decide(ctx, node.prims.len(), depth, bad_refines, || find_split(ctx, &node, &voxel, b.bins));
    let Some((split, bad_refines)) = decision else {
        let bytes = node.bytes();
        let data = NodeData { prims: node.prims, ..NodeData::default() };
        ctx.meter.add(data.bytes());
        ctx.meter.sub(bytes);
        ctx.finished(share);
        return leaf_part(ctx, data);
    };
    let parent_bytes = node.bytes();
    let [(below, below_box), (above, above_box)] = split_node(ctx, node, &voxel, &split);
    ctx.meter.add(below.bytes() + above.bytes());
    ctx.meter.sub(parent_bytes);
    let [below_share, above_share] = split_share(share, below.prims.len(), above.prims.len());
    let (below, above) = rayon::join(
        || build_node(ctx, below, below_box, depth + 1, bad_refines, below_share, b),
        || build_node(ctx, above, above_box, depth + 1, bad_refines, above_share, b),
    );
    Part::Split { axis: split.axis, pos: split.pos, below: Box::new(below), above: Box::new(above) }
}

/// The top of the tree over `prims` (ascending, with their boxes from
/// `ctx`) inside `bounds`, binned with `bins` planes per axis on nodes of at
/// least `min_prims` triangles. `ctx.meter` must not count anything yet.
pub(super) fn build(ctx: &Ctx, prims: Vec<u32>, bounds: Aabb, bins: usize, min_prims: usize) -> Part {
    let boxes = prims.iter().map(|&p| ctx.boxes[p as usize]).collect();
    let root = RefNode { prims, boxes };
    ctx.meter.add(root.bytes());
    build_node(ctx, root, bounds, 0, 0, BuildProgress::TOTAL, &Binning { bins: bins.max(2), min_prims })
}
