//! The O(N log N) SAH sweep of Wald & Havran 2006 ("On building fast kd-trees
//! for ray tracing, and on doing that in O(N log N)", §4–5), in parallel.
//!
//! Every node carries, per axis, the sorted list of its triangles' *events*: a
//! start and an end at the two faces of the triangle's (clipped) box, or one
//! *planar* event when the box is flat on that axis. One sweep over each list
//! finds the plane of least SAH cost; splitting the node then splits each list
//! in one pass, which keeps it sorted: the events of triangles wholly on one
//! side move to that child unchanged, and only the triangles that straddle the
//! plane are clipped to each child's box ("perfect splits", see `clip.rs`) and
//! get new events, which are sorted (few) and merged in. Nothing is re-sorted
//! per node, so a level of the tree costs O(N) and the build O(N log N).
//!
//! Parallelism (rayon): the two subtrees of a large node are built as separate
//! tasks, and a large node sweeps and splits its three axes as three tasks.
//! Every decision depends only on the node's own data, and subtrees are joined
//! in depth-first order, so the tree is the same whatever the thread count.

use std::sync::atomic::{AtomicUsize, Ordering};

use glam::Vec3;

use super::clip::clip_triangle_split;
use super::{BuildConfig, BuildProgress, Builder};
use crate::geom::Aabb;
use crate::kdtree::node::{KdNode, MAX_CHILD_INDEX, MAX_NODE_FIELD};

mod binned;

// ---- Events -------------------------------------------------------------
//
// One event is one u64 that sorts in sweep order: bits 63..32 the position
// (f32 mapped to an unsigned key of the same order), bits 31..30 the type in
// Wald & Havran's order at equal positions (end < planar < start), bits 29..0
// the triangle's index in the node's own triangle list.

const END: u64 = 0;
const PLANAR: u64 = 1;
const START: u64 = 2;
const INDEX_BITS: u32 = 30;
const INDEX_MASK: u64 = (1 << INDEX_BITS) - 1;

/// Most triangles a node (the root included) may hold: local indices have 30 bits.
pub(super) const MAX_PRIMS: usize = 1 << INDEX_BITS;

/// The f32 `pos` as a u32 of the same order (−0.0 is taken as +0.0).
pub(super) fn ordered(pos: f32) -> u32 {
    let bits = (pos + 0.0).to_bits();
    if bits >> 31 == 1 {
        !bits
    } else {
        bits | (1 << 31)
    }
}

/// The inverse of [`ordered`].
pub(super) fn from_ordered(key: u32) -> f32 {
    let bits = if key >> 31 == 1 { key & !(1 << 31) } else { !key };
    f32::from_bits(bits)
}

fn event(key: u32, kind: u64, index: u32) -> u64 {
    ((key as u64) << 32) | (kind << INDEX_BITS) | index as u64
}

fn event_key(e: u64) -> u32 {
    (e >> 32) as u32
}

fn event_kind(e: u64) -> u64 {
    (e >> INDEX_BITS) & 3
}

fn event_index(e: u64) -> usize {
    (e & INDEX_MASK) as usize
}

/// Appends the events of a box on `axis` for local triangle `index`.
fn push_events(out: &mut Vec<u64>, b: &Aabb, axis: usize, index: u32) {
    let (lo, hi) = (ordered(b.min[axis]), ordered(b.max[axis]));
    if lo == hi {
        out.push(event(lo, PLANAR, index));
    } else {
        out.push(event(lo, START, index));
        out.push(event(hi, END, index));
    }
}

// ---- Build context ------------------------------------------------------

/// Nodes of at least this many triangles build their two subtrees as parallel tasks.
const PARALLEL_SUBTREE_PRIMS: usize = 2048;
/// Nodes of at least this many triangles sweep and split their three axes in parallel.
const PARALLEL_AXIS_PRIMS: usize = 32 * 1024;
/// Straddling triangles clipped in parallel when there are at least this many.
const PARALLEL_CLIP_PRIMS: usize = 4096;

/// Live and peak bytes of the scratch lists, over all threads.
#[derive(Default)]
pub(super) struct Meter {
    live: AtomicUsize,
    peak: AtomicUsize,
}

impl Meter {
    /// Counts the peak of a serial subtree that started from `start` bytes and
    /// ended with none: an upper bound, as if it peaked while all else was live.
    fn add_subtree(&self, start: usize, local: &LocalMeter) {
        let extra = local.peak - start;
        self.add(extra);
        self.sub(extra + start);
    }

    fn add(&self, bytes: usize) {
        let now = self.live.fetch_add(bytes, Ordering::Relaxed) + bytes;
        self.peak.fetch_max(now, Ordering::Relaxed);
    }

    fn sub(&self, bytes: usize) {
        self.live.fetch_sub(bytes, Ordering::Relaxed);
    }

    pub(super) fn peak(&self) -> usize {
        self.peak.load(Ordering::Relaxed)
    }
}

/// The SAH constants in f64.
#[derive(Clone, Copy)]
struct Costs {
    traversal: f64,
    intersection: f64,
    /// `K_I · (1 − b)` without and with the empty bonus `b`.
    weights: [f64; 2],
}

impl Costs {
    fn new(config: &BuildConfig) -> Costs {
        let intersection = config.intersection_cost as f64;
        let weight = |bonus: f64| intersection * (1.0 - bonus);
        Costs {
            traversal: config.traversal_cost as f64,
            intersection,
            weights: [weight(0.0), weight(config.empty_bonus as f64)],
        }
    }

    /// `K_T + K_I · (1 − b) · (P_below · n_below + P_above · n_above)`, `b` the
    /// empty bonus when one side holds no triangle. (Counts convert from i64,
    /// one instruction; they are far below 2^53.)
    fn split(&self, p_below: f64, p_above: f64, n_below: usize, n_above: usize) -> f64 {
        let weight = self.weights[(n_below == 0 || n_above == 0) as usize];
        self.traversal + weight * (p_below * n_below as i64 as f64 + p_above * n_above as i64 as f64)
    }
}

/// What every node of one build shares.
pub(super) struct Ctx<'a> {
    triangles: &'a [[Vec3; 3]],
    /// Each triangle's box, by triangle index.
    boxes: &'a [Aabb],
    config: &'a BuildConfig,
    costs: Costs,
    max_depth: u32,
    pub(super) meter: Meter,
    progress: Option<&'a BuildProgress>,
}

impl<'a> Ctx<'a> {
    pub(super) fn new(
        triangles: &'a [[Vec3; 3]],
        boxes: &'a [Aabb],
        config: &'a BuildConfig,
        max_depth: u32,
        progress: Option<&'a BuildProgress>,
    ) -> Self {
        Ctx { triangles, boxes, config, costs: Costs::new(config), max_depth, meter: Meter::default(), progress }
    }

    /// Reports a finished subtree that held `share` of the build's work.
    fn finished(&self, share: u64) {
        if let Some(p) = self.progress {
            p.add_done(share);
        }
    }
}

/// The share of the build's progress units ([`BuildProgress::TOTAL`]) of each
/// child of a node that holds `share`: proportional to the child's triangles,
/// the two adding up to `share`.
fn split_share(share: u64, below: usize, above: usize) -> [u64; 2] {
    let total = (below + above).max(1) as u128;
    let b = (share as u128 * below as u128 / total) as u64;
    [b, share - b]
}

/// A node still to be built: its triangles and their sorted events per axis.
#[derive(Default)]
struct NodeData {
    /// Triangle indices (into the build's input), ascending; the events refer
    /// to positions in this list.
    prims: Vec<u32>,
    /// The sorted events of the x, then the y, then the z axis, in one
    /// allocation.
    events: Vec<u64>,
    /// Where each axis's events end in `events`.
    ends: [usize; 3],
}

impl NodeData {
    /// A node from its triangles and per-axis event lists.
    fn from_axes(prims: Vec<u32>, axes: [Vec<u64>; 3]) -> Self {
        let mut events = Vec::with_capacity(axes.iter().map(Vec::len).sum());
        let mut ends = [0; 3];
        for (end, list) in ends.iter_mut().zip(&axes) {
            events.extend_from_slice(list);
            *end = events.len();
        }
        NodeData { prims, events, ends }
    }

    /// The sorted events of one axis.
    fn axis(&self, axis: usize) -> &[u64] {
        let start = if axis == 0 { 0 } else { self.ends[axis - 1] };
        &self.events[start..self.ends[axis]]
    }

    /// Heap bytes held.
    fn bytes(&self) -> usize {
        self.prims.capacity() * 4 + self.events.capacity() * 8
    }
}

/// The scratch bytes of one serial subtree, counted without atomics.
#[derive(Default)]
struct LocalMeter {
    live: usize,
    peak: usize,
}

/// Runs `f(0)`, `f(1)`, `f(2)` in parallel when `parallel`, in order otherwise.
fn per_axis<T: Send>(parallel: bool, f: impl Fn(usize) -> T + Sync) -> [T; 3] {
    if parallel {
        let (a, (b, c)) = rayon::join(|| f(0), || rayon::join(|| f(1), || f(2)));
        [a, b, c]
    } else {
        [f(0), f(1), f(2)]
    }
}

// ---- Sweep ----------------------------------------------------------------

/// The cheapest plane of a node.
#[derive(Clone, Copy, Debug)]
struct Split {
    axis: usize,
    /// The position as an [`ordered`] key, and as an f32.
    key: u32,
    pos: f32,
    cost: f64,
    /// Where the triangles lying in the plane go: the cheaper side.
    planar_below: bool,
    /// Triangles on each side (straddlers count on both).
    below: usize,
    above: usize,
}

/// Sweeps the sorted events of one axis (Wald & Havran 2006, Algorithm 5) and
/// returns the cheapest plane strictly inside the voxel. Planes on the voxel's
/// faces are not candidates: they would cut off a flat cell, which the
/// traversals' tie rules could skip.
fn sweep(events: &[u64], n: usize, voxel: &Aabb, axis: usize, costs: &Costs) -> Option<Split> {
    let (lo, hi) = (voxel.min[axis], voxel.max[axis]);
    if lo >= hi {
        return None;
    }
    let extent = voxel.max.as_dvec3() - voxel.min.as_dvec3();
    let area = 2.0 * (extent.x * extent.y + extent.y * extent.z + extent.z * extent.x);
    // A child's relative area is 2·(e1·e2 + w·(e1 + e2)) / area for its width w
    // along `axis`: p_below = cap + (pos − lo)·rim, p_above = cap + (hi − pos)·rim.
    let (e1, e2) = (extent[(axis + 1) % 3], extent[(axis + 2) % 3]);
    let (cap, rim) = (2.0 * e1 * e2 / area, 2.0 * (e1 + e2) / area);
    let (lo_key, hi_key) = (ordered(lo), ordered(hi));
    let (lo, hi) = (lo as f64, hi as f64);
    let (mut below, mut above) = (0usize, n);
    let mut best = Split { axis, key: 0, pos: 0.0, cost: f64::INFINITY, planar_below: true, below: 0, above: 0 };
    let mut i = 0;
    while i < events.len() {
        let key = event_key(events[i]);
        // Three 21-bit counters in one register: ends, planar, starts.
        let mut counts = 0u64;
        while i < events.len() && event_key(events[i]) == key {
            counts += 1 << (21 * event_kind(events[i]));
            i += 1;
        }
        let mask = (1 << 21) - 1;
        let (ends, planar, starts) =
            ((counts & mask) as usize, ((counts >> 21) & mask) as usize, (counts >> 42) as usize);
        // Triangles ending here or lying here are not above the plane.
        above -= ends + planar;
        if key > lo_key && key < hi_key {
            let pos = from_ordered(key) as f64;
            let p_below = cap + (pos - lo) * rim;
            let p_above = cap + (hi - pos) * rim;
            let cost_below = costs.split(p_below, p_above, below + planar, above);
            let (cost, planar_below) = if planar == 0 {
                (cost_below, true)
            } else {
                let cost_above = costs.split(p_below, p_above, below, above + planar);
                if cost_above < cost_below {
                    (cost_above, false)
                } else {
                    (cost_below, true)
                }
            };
            if cost < best.cost {
                let (b, a) = if planar_below { (below + planar, above) } else { (below, above + planar) };
                best = Split { axis, key, pos: from_ordered(key), cost, planar_below, below: b, above: a };
            }
        }
        below += planar + starts;
    }
    debug_assert_eq!((below, above), (n, 0));
    (best.cost < f64::INFINITY).then_some(best)
}

/// The cheapest plane over the three axes (the first one on ties, x before y before z).
fn find_split(ctx: &Ctx, node: &NodeData, voxel: &Aabb) -> Option<Split> {
    let n = node.prims.len();
    let candidates = per_axis(n >= PARALLEL_AXIS_PRIMS, |axis| sweep(node.axis(axis), n, voxel, axis, &ctx.costs));
    candidates.into_iter().flatten().fold(None, |best: Option<Split>, s| match best {
        Some(b) if b.cost <= s.cost => Some(b),
        _ => Some(s),
    })
}

/// Wald & Havran's automatic termination, with pbrt-v3's optional bad refines:
/// `None` makes a leaf; otherwise the split and the bad-refine count the
/// children inherit. A leaf when the node holds no triangle or at most
/// `max_leaf_prims`, at the depth limit, when no plane lies inside the node,
/// or when the best split costs more than the leaf (`K_I · n`) and either the
/// path already took `max_bad_refines` such splits or (pbrt-v3) it costs more
/// than four times the leaf with fewer than 16 triangles.
fn decide(
    ctx: &Ctx,
    n: usize,
    depth: u32,
    bad_refines: u32,
    find_split: impl FnOnce() -> Option<Split>,
) -> Option<(Split, u32)> {
    if n == 0 || n <= ctx.config.max_leaf_prims as usize || depth >= ctx.max_depth {
        return None;
    }
    let split = find_split()?;
    let leaf_cost = ctx.costs.intersection * n as f64;
    if split.cost > leaf_cost {
        let bad_refines = bad_refines + 1;
        if bad_refines > ctx.config.max_bad_refines || (split.cost > 4.0 * leaf_cost && n < 16) {
            return None;
        }
        return Some((split, bad_refines));
    }
    Some((split, bad_refines))
}

// ---- Split ----------------------------------------------------------------

// Sides of a triangle, as bits: below, above, both (straddling).
const BELOW: u8 = 1;
const ABOVE: u8 = 2;
const BOTH: u8 = 3;

/// Per-thread buffers reused from node to node.
#[derive(Default)]
struct Scratch {
    side: Vec<u8>,
    dest: Vec<u32>,
    straddlers: Vec<Straddler>,
    fresh: [[Vec<u64>; 2]; 3],
}

/// A triangle that straddles the split plane: its local index, its index in
/// each child (`u32::MAX` where absent) and its box clipped to each child.
#[derive(Clone, Copy)]
struct Straddler {
    index: u32,
    child_index: [u32; 2],
    clipped: [Option<Aabb>; 2],
}

/// How a node's triangles go to its children.
struct Plan<'s> {
    /// By local index, for triangles wholly on one side: the side (`BELOW` or
    /// `ABOVE`) in bits 31..30 and the index in that child in bits 29..0;
    /// `BOTH << 30` for straddlers.
    dest: &'s [u32],
    straddlers: &'s [Straddler],
}

/// The straddlers' new events on one axis, for each child, sorted.
fn fresh_events(axis: usize, plan: &Plan, fresh: &mut [Vec<u64>; 2]) {
    for (c, out) in fresh.iter_mut().enumerate() {
        out.clear();
        for s in plan.straddlers {
            if let Some(b) = &s.clipped[c] {
                push_events(out, b, axis, s.child_index[c]);
            }
        }
        out.sort_unstable();
    }
}

/// Appends the events of one axis to both children's lists: the events of the
/// triangles on one side, renumbered (the child numbering follows the
/// parent's, so the lists stay sorted), with the straddlers' `fresh` events
/// merged in on the way. `kept` counts the triangles wholly on each side.
fn split_axis(events: &[u64], plan: &Plan, kept: [usize; 2], fresh: &[Vec<u64>; 2], lists: &mut [Vec<u64>; 2]) {
    // Without branching on the side: each event is written to both lists,
    // and only its side's cursor advances (the lists have a slot of slack).
    let [below, above] = lists;
    let (start_below, start_above) = (below.len(), above.len());
    below.resize(start_below + 2 * kept[0] + fresh[0].len() + 1, 0);
    above.resize(start_above + 2 * kept[1] + fresh[1].len() + 1, 0);
    let (mut at_below, mut at_above) = (start_below, start_above);
    let [fresh_below, fresh_above] = fresh;
    let (mut next_below, mut next_above) = (0, 0);
    // The next fresh event of each side, `u64::MAX` (above every event) when none is left.
    let head = |list: &[u64], next: usize| list.get(next).copied().unwrap_or(u64::MAX);
    let (mut head_below, mut head_above) = (head(fresh_below, 0), head(fresh_above, 0));
    for &e in events {
        let dest = plan.dest[event_index(e)];
        let renumbered = (e & !INDEX_MASK) | (dest as u64 & INDEX_MASK);
        // Fresh events below this one go out first, on both sides: every
        // event still to come is above them.
        while head_below < renumbered {
            below[at_below] = head_below;
            (at_below, next_below) = (at_below + 1, next_below + 1);
            head_below = head(fresh_below, next_below);
        }
        while head_above < renumbered {
            above[at_above] = head_above;
            (at_above, next_above) = (at_above + 1, next_above + 1);
            head_above = head(fresh_above, next_above);
        }
        below[at_below] = renumbered;
        above[at_above] = renumbered;
        let side = (dest >> 30) as u8;
        at_below += (side == BELOW) as usize;
        at_above += (side == ABOVE) as usize;
    }
    for (list, at, rest) in
        [(below, at_below, &fresh_below[next_below..]), (above, at_above, &fresh_above[next_above..])]
    {
        list.truncate(at);
        list.extend_from_slice(rest);
    }
}

/// The boxes of a straddling triangle clipped to each child ("perfect splits",
/// or its box clipped to each child's box when they are off).
fn clip_straddler(ctx: &Ctx, prim: u32, voxel: &Aabb, below: &Aabb, above: &Aabb, s: &Split) -> [Option<Aabb>; 2] {
    let (tri, tri_box) = (&ctx.triangles[prim as usize], &ctx.boxes[prim as usize]);
    let boxed = [Some(tri_box.intersection(*below)), Some(tri_box.intersection(*above))];
    if !ctx.config.perfect_splits {
        return boxed;
    }
    match clip_triangle_split(tri, tri_box, voxel, s.axis, s.pos) {
        // Impossible for a triangle that reaches into the node; keep it on both
        // sides, box-clipped, should rounding ever say otherwise.
        [None, None] => boxed,
        both => both,
    }
}

/// Splits `node` at `s` into its below and above children.
fn split_node(ctx: &Ctx, node: NodeData, voxel: &Aabb, s: &Split, scratch: &mut Scratch) -> [(NodeData, Aabb); 2] {
    let n = node.prims.len();
    let mut below_box = *voxel;
    below_box.max[s.axis] = s.pos;
    let mut above_box = *voxel;
    above_box.min[s.axis] = s.pos;

    // Cutting off empty space: one child gets the node's lists as they are.
    if s.below == 0 || s.above == 0 {
        let (full, empty) = (node, NodeData::default());
        return if s.below == 0 {
            [(empty, below_box), (full, above_box)]
        } else {
            [(full, below_box), (empty, above_box)]
        };
    }

    // Classify (Wald & Havran 2006, Algorithm 6): a triangle ending at or
    // before the plane is below, one starting at or after it above, one lying
    // in it on the side the sweep chose; the rest straddle it. Clearing side
    // bits, branch-free: events before the plane other than starts clear
    // ABOVE, events after it other than ends clear BELOW.
    let Scratch { side, dest, straddlers, fresh } = scratch;
    side.clear();
    side.resize(n, BOTH);
    let events = node.axis(s.axis);
    let first_at = events.partition_point(|&e| event_key(e) < s.key);
    let first_after = first_at + events[first_at..].partition_point(|&e| event_key(e) == s.key);
    for &e in &events[..first_at] {
        side[event_index(e)] &= BELOW | (((event_kind(e) == START) as u8) << 1);
    }
    for &e in &events[first_at..first_after] {
        side[event_index(e)] = match event_kind(e) {
            END => BELOW,
            START => ABOVE,
            _ if s.planar_below => BELOW,
            _ => ABOVE,
        };
    }
    for &e in &events[first_after..] {
        side[event_index(e)] &= ABOVE | (event_kind(e) == END) as u8;
    }

    // Perfect splits: clip each straddler to both children. A triangle whose
    // box straddles the plane may still miss one child's box entirely.
    straddlers.clear();
    straddlers.extend((0..n as u32).filter(|&i| side[i as usize] == BOTH).map(|index| Straddler {
        index,
        child_index: [u32::MAX; 2],
        clipped: [None; 2],
    }));
    let clip = |st: &mut Straddler| {
        st.clipped = clip_straddler(ctx, node.prims[st.index as usize], voxel, &below_box, &above_box, s);
    };
    if straddlers.len() >= PARALLEL_CLIP_PRIMS {
        use rayon::prelude::*;
        straddlers.par_iter_mut().for_each(clip);
    } else {
        straddlers.iter_mut().for_each(clip);
    }

    // Number the children's triangles in the parent's order.
    dest.clear();
    dest.resize(n, (BOTH as u32) << 30);
    let mut prims = [Vec::with_capacity(s.below), Vec::with_capacity(s.above)];
    let mut next_straddler = straddlers.iter_mut().peekable();
    for (i, (&sd, &prim)) in side.iter().zip(&node.prims).enumerate() {
        if sd != BOTH {
            let c = (sd >> 1) as usize;
            dest[i] = ((sd as u32) << 30) | prims[c].len() as u32;
            prims[c].push(prim);
        } else {
            let st = next_straddler.next().expect("straddlers in order");
            for (c, p) in prims.iter_mut().enumerate() {
                if st.clipped[c].is_some() {
                    st.child_index[c] = p.len() as u32;
                    p.push(prim);
                }
            }
        }
    }
    let mut kept = [prims[0].len(), prims[1].len()];
    for st in straddlers.iter() {
        for (c, k) in kept.iter_mut().enumerate() {
            *k -= st.clipped[c].is_some() as usize;
        }
    }

    let plan = Plan { dest, straddlers };
    let [prims_below, prims_above] = prims;
    if n >= PARALLEL_AXIS_PRIMS {
        let [x, y, z] = per_axis(true, |axis| {
            let mut fresh = Default::default();
            fresh_events(axis, &plan, &mut fresh);
            let mut lists = [0, 1].map(|c| Vec::with_capacity(2 * kept[c] + fresh[c].len() + 1));
            split_axis(node.axis(axis), &plan, kept, &fresh, &mut lists);
            lists
        });
        drop(node);
        let [[x_below, x_above], [y_below, y_above], [z_below, z_above]] = [x, y, z];
        return [
            (NodeData::from_axes(prims_below, [x_below, y_below, z_below]), below_box),
            (NodeData::from_axes(prims_above, [x_above, y_above, z_above]), above_box),
        ];
    }
    for (axis, fresh) in fresh.iter_mut().enumerate() {
        fresh_events(axis, &plan, fresh);
    }
    let mut lists =
        [0, 1].map(|c| Vec::with_capacity(6 * kept[c] + fresh.iter().map(|f| f[c].len()).sum::<usize>() + 1));
    let mut ends = [[0; 3]; 2];
    for axis in 0..3 {
        split_axis(node.axis(axis), &plan, kept, &fresh[axis], &mut lists);
        for c in 0..2 {
            ends[c][axis] = lists[c].len();
        }
    }
    drop(node);
    let [events_below, events_above] = lists;
    [
        (NodeData { prims: prims_below, events: events_below, ends: ends[0] }, below_box),
        (NodeData { prims: prims_above, events: events_above, ends: ends[1] }, above_box),
    ]
}

// ---- Recursion and assembly ---------------------------------------------

/// Part of the output: nodes in depth-first order whose child indices and
/// primitive offsets count from the start of `nodes` and `prims`.
#[derive(Default)]
struct Chunk {
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
}

/// A subtree as built: one chunk, or a split whose children were built as
/// separate tasks.
enum Part {
    Chunk(Chunk),
    Split { axis: usize, pos: f32, below: Box<Part>, above: Box<Part> },
}

fn push_leaf(out: &mut Chunk, node: NodeData) {
    let offset = u32::try_from(out.prims.len()).expect("more than 2^32 primitive references");
    assert!(node.prims.len() <= MAX_NODE_FIELD as usize, "a leaf of {} triangles", node.prims.len());
    out.nodes.push(KdNode::leaf(offset, node.prims.len() as u32));
    out.prims.extend_from_slice(&node.prims);
}

/// Builds a subtree on this thread, appending it to `out` in depth-first order.
/// `meter.live` counts `node`'s bytes on entry and no longer on return.
#[allow(clippy::too_many_arguments)]
fn build_serial(
    ctx: &Ctx,
    node: NodeData,
    voxel: Aabb,
    depth: u32,
    bad_refines: u32,
    scratch: &mut Scratch,
    meter: &mut LocalMeter,
    out: &mut Chunk,
) {
    let Some((split, bad_refines)) =
        decide(ctx, node.prims.len(), depth, bad_refines, || find_split(ctx, &node, &voxel))
    else {
        meter.live -= node.bytes();
        return push_leaf(out, node);
    };
    let index = out.nodes.len();
    out.nodes.push(KdNode::interior(split.axis, split.pos, 0));
    let parent_bytes = node.bytes();
    let [(below, below_box), (above, above_box)] = split_node(ctx, node, &voxel, &split, scratch);
    let child_bytes = below.bytes() + above.bytes();
    meter.peak = meter.peak.max(meter.live + child_bytes);
    meter.live = meter.live + child_bytes - parent_bytes;
    build_serial(ctx, below, below_box, depth + 1, bad_refines, scratch, meter, out);
    let above_index = out.nodes.len();
    assert!(above_index <= MAX_CHILD_INDEX as usize, "kd-tree too large: more than {MAX_CHILD_INDEX} nodes");
    out.nodes[index] = KdNode::interior(split.axis, split.pos, above_index as u32);
    build_serial(ctx, above, above_box, depth + 1, bad_refines, scratch, meter, out);
}

/// Builds a subtree, splitting large nodes into parallel tasks. `ctx.meter`
/// counts `node`'s bytes on entry and no longer on return.
/// `share` is the node's part of the build's progress units.
fn build_parallel(ctx: &Ctx, node: NodeData, voxel: Aabb, depth: u32, bad_refines: u32, share: u64) -> Part {
    let mut scratch = Scratch::default();
    if node.prims.len() < PARALLEL_SUBTREE_PRIMS {
        let mut chunk = Chunk::default();
        let start = node.bytes();
        let mut meter = LocalMeter { live: start, peak: start };
        build_serial(ctx, node, voxel, depth, bad_refines, &mut scratch, &mut meter, &mut chunk);
        ctx.meter.add_subtree(start, &meter);
        ctx.finished(share);
        return Part::Chunk(chunk);
    }
    let Some((split, bad_refines)) =
        decide(ctx, node.prims.len(), depth, bad_refines, || find_split(ctx, &node, &voxel))
    else {
        ctx.finished(share);
        return leaf_part(ctx, node);
    };
    let parent_bytes = node.bytes();
    let [(below, below_box), (above, above_box)] = split_node(ctx, node, &voxel, &split, &mut scratch);
    ctx.meter.add(below.bytes() + above.bytes());
    ctx.meter.sub(parent_bytes);
    drop(scratch);
    let [below_share, above_share] = split_share(share, below.prims.len(), above.prims.len());
    let (below, above) = rayon::join(
        || build_parallel(ctx, below, below_box, depth + 1, bad_refines, below_share),
        || build_parallel(ctx, above, above_box, depth + 1, bad_refines, above_share),
    );
    Part::Split { axis: split.axis, pos: split.pos, below: Box::new(below), above: Box::new(above) }
}

/// A leaf of `node`'s triangles; `ctx.meter` counts its bytes on entry and
/// no longer on return.
fn leaf_part(ctx: &Ctx, node: NodeData) -> Part {
    let mut chunk = Chunk::default();
    ctx.meter.sub(node.bytes());
    push_leaf(&mut chunk, node);
    Part::Chunk(chunk)
}

/// Appends `part` to the final arrays, turning chunk-relative indices absolute.
fn flatten(part: Part, nodes: &mut Vec<KdNode>, prims: &mut Vec<u32>) {
    match part {
        Part::Chunk(chunk) => {
            let (node_base, prim_base) = (nodes.len(), prims.len());
            assert!(
                node_base + chunk.nodes.len() <= MAX_CHILD_INDEX as usize + 1,
                "kd-tree too large: more than {MAX_CHILD_INDEX} nodes"
            );
            let prim_base = u32::try_from(prim_base).expect("more than 2^32 primitive references");
            nodes.extend(chunk.nodes.iter().map(|n| {
                if n.is_leaf() {
                    KdNode::leaf(n.prim_offset() + prim_base, n.prim_count())
                } else {
                    KdNode::interior(n.axis(), n.split(), n.above_child() + node_base as u32)
                }
            }));
            prims.extend_from_slice(&chunk.prims);
        }
        Part::Split { axis, pos, below, above } => {
            let index = nodes.len();
            nodes.push(KdNode::interior(axis, pos, 0));
            flatten(*below, nodes, prims);
            let above_index = nodes.len();
            assert!(above_index <= MAX_CHILD_INDEX as usize, "kd-tree too large: more than {MAX_CHILD_INDEX} nodes");
            nodes[index] = KdNode::interior(axis, pos, above_index as u32);
            flatten(*above, nodes, prims);
        }
    }
}

/// Event lists at least this long are radix-sorted.
const RADIX_SORT_EVENTS: usize = 4096;

/// Sorts events made in triangle order. A stable radix sort (least
/// significant digit first, three passes of 12 bits) on the position and type
/// only: events of equal position and type stay in triangle order, so the
/// result is the one of sorting the whole u64s.
fn radix_sort_events(events: &mut Vec<u64>) {
    const DIGIT_BITS: u32 = 12;
    let mut sorted = vec![0u64; events.len()];
    for pass in 0..3 {
        let shift = INDEX_BITS + pass * DIGIT_BITS;
        let digit = |e: u64| ((e >> shift) & ((1 << DIGIT_BITS) - 1)) as usize;
        let mut starts = vec![0usize; 1 << DIGIT_BITS];
        for &e in events.iter() {
            starts[digit(e)] += 1;
        }
        let mut sum = 0;
        for start in &mut starts {
            (*start, sum) = (sum, sum + *start);
        }
        for &e in events.iter() {
            let d = digit(e);
            sorted[starts[d]] = e;
            starts[d] += 1;
        }
        std::mem::swap(events, &mut sorted);
    }
}

/// Builds the tree over `prims` (ascending triangle indices, fewer than
/// [`MAX_PRIMS`]) inside `bounds`, the union of their boxes. Returns the
/// nodes and the primitive indices in depth-first order.
pub(super) fn build(ctx: &Ctx, prims: Vec<u32>, bounds: Aabb) -> (Vec<KdNode>, Vec<u32>) {
    assert!(prims.len() < MAX_PRIMS, "{} triangles: the builder handles fewer than 2^30", prims.len());
    let part = match ctx.config.builder {
        Builder::Binned { bins, min_prims } if prims.len() >= min_prims as usize => {
            binned::build(ctx, prims, bounds, bins as usize, min_prims as usize)
        }
        _ => build_swept(ctx, prims, bounds),
    };
    let (mut nodes, mut prim_indices) = (Vec::new(), Vec::new());
    flatten(part, &mut nodes, &mut prim_indices);
    (nodes, prim_indices)
}

/// The whole tree by the exact sweep, from one sort of all events.
fn build_swept(ctx: &Ctx, prims: Vec<u32>, bounds: Aabb) -> Part {
    // The initial sort: the only one over all events (Wald & Havran 2006, §5.1).
    let events = per_axis(prims.len() >= PARALLEL_AXIS_PRIMS, |axis| {
        let mut events = Vec::with_capacity(prims.len() * 2);
        for (i, &p) in prims.iter().enumerate() {
            push_events(&mut events, &ctx.boxes[p as usize], axis, i as u32);
        }
        if events.len() >= RADIX_SORT_EVENTS {
            radix_sort_events(&mut events);
        } else {
            events.sort_unstable();
        }
        events
    });
    let root = NodeData::from_axes(prims, events);
    ctx.meter.add(root.bytes());
    build_parallel(ctx, root, bounds, 0, 0, BuildProgress::TOTAL)
}

#[cfg(test)]
mod tests;
