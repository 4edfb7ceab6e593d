//! Where a traversal's time goes: divergence, memory or arithmetic (the analysis
//! at the end of the talk the project was made from; `kdtrace divergence`).
//!
//! The talk's experiment: a dummy kernel that follows the real kernel's
//! execution paths with no memory access and no arithmetic ran as long as the
//! real one, so the GPU was bound by divergent control flow. Here:
//!
//! - [`record`]: a CPU twin of the traversal traces each ray and writes its
//!   control flow as a compact record — per leaf visit that tested triangles,
//!   the loop steps before it and the triangles it tested (one `u32`, 16 bits
//!   each), plus an offset per ray — and, apart, the index of every node it
//!   fetched. The twins take the kernels' decisions bit for bit
//!   (`tests/gpu_trace.rs`; packets: `tests/packets.rs`), so these are the GPU
//!   lanes' loop trip counts. Every variant has a single-ray twin, and every
//!   packet variant a packet twin, whose lanes' rounds are aligned: one per leaf
//!   step of the packet, the steps counted per packet step (a robust lane that
//!   finishes alone with exact restarts then adds its own rounds).
//! - [`replay`]: `glsl/divergence_replay.comp` runs those loops lane by lane —
//!   the same rounds, the same trip counts in each — with one integer
//!   multiply-add per step instead of node fetches and intersection tests; then
//!   the **memory-only** kernel, which makes the same node fetches (and the
//!   triangle fetches of the leaves a lane tested) in the same order from the
//!   fetch record, with no decision; and each record read alone (their own cost).
//! - [`simd_efficiency`]: the share of a subgroup's lanes busy in each stage
//!   when its lanes run these loops in lockstep (a subgroup's round lasts as long
//!   as its longest lane's; finished lanes idle).

use std::sync::Arc;

use ash::vk;
use glam::Vec3;
use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::geom::Ray;
use crate::gpu::{shaders, Buffer, BufferSet, GpuContext, Kernel, KernelDesc, Timestamps};
use crate::kdtree::links::TreeLinks;
use crate::kdtree::traverse::{trace_packet_logged, trace_ray_logged, FlowLog, SceneRef};
use crate::kdtree::KdTree;
use crate::traversal::{Traversal, Variant};

/// The control flow and node fetches of a batch of rays in one traversal.
#[derive(Clone, Debug, Default)]
pub struct Records {
    /// Ray i's words are `words[offsets[i]..offsets[i + 1]]`.
    pub offsets: Vec<u32>,
    /// Per leaf visit that tested triangles: loop steps before it (low 16
    /// bits) and triangles tested (high 16 bits); a last word of trailing steps.
    pub words: Vec<u32>,
    /// Ray i's fetches are `fetches[fetch_offsets[i]..fetch_offsets[i + 1]]`.
    pub fetch_offsets: Vec<u32>,
    /// Node index per fetch, [`FlowLog::TESTED`] set on a leaf whose triangles
    /// the ray tested (the memory-only kernel's input).
    pub fetches: Vec<u32>,
    /// Nodes, leaf visits (with triangles) and triangle tests, summed over the rays.
    pub nodes: u64,
    /// See `nodes`.
    pub leaves: u64,
    /// See `nodes`.
    pub triangles: u64,
    /// Packet steps summed over the lanes (packets only: a lane steps with its packet).
    pub steps: u64,
    /// Trip counts above 65,535, clamped in the record.
    pub clamped: u64,
}

impl Records {
    /// Rays recorded.
    pub fn rays(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Bytes on the device of the control-flow record: the offsets and the words.
    pub fn bytes(&self) -> u64 {
        4 * (self.offsets.len() + self.words.len()) as u64
    }

    /// Bytes on the device of the fetch record.
    pub fn fetch_bytes(&self) -> u64 {
        4 * (self.fetch_offsets.len() + self.fetches.len()) as u64
    }

    /// Ray `i`'s `(loop steps, triangles)` per round.
    pub fn rounds(&self, i: usize) -> impl Iterator<Item = (u32, u32)> + '_ {
        let (a, b) = (self.offsets[i] as usize, self.offsets[i + 1] as usize);
        self.words[a..b].iter().map(|w| (w & 0xffff, w >> 16))
    }

    fn push(&mut self, log: &FlowLog) -> Result<()> {
        for &[d, t] in &log.rounds {
            self.clamped += u64::from(d > 0xffff) + u64::from(t > 0xffff);
            self.words.push(d.min(0xffff) | (t.min(0xffff) << 16));
        }
        self.fetches.extend_from_slice(&log.fetches);
        if self.words.len() > u32::MAX as usize || self.fetches.len() > u32::MAX as usize {
            return Err(Error::InvalidInput("too many rays for one divergence record".into()));
        }
        self.offsets.push(self.words.len() as u32);
        self.fetch_offsets.push(self.fetches.len() as u32);
        Ok(())
    }
}

/// Records the control flow of `rays` in `traversal` (its variant, robustness,
/// any-hit and packet width), as the GPU runs them
/// unordered: packet p holds rays `p·w .. p·w + w`.
pub fn record(tree: &KdTree, triangles: &[[Vec3; 3]], rays: &[Ray], traversal: Traversal) -> Result<Records> {
    let width = traversal.packet_width.max(1) as usize;
    if width > 1 && matches!(traversal.variant, Variant::Backtrack | Variant::Ropes) {
        return Err(Error::InvalidInput(format!("{:?} has no packet kernel", traversal.variant)));
    }
    let links = matches!(traversal.variant, Variant::Backtrack | Variant::Ropes)
        .then(|| TreeLinks::new(&tree.nodes, tree.bounds));
    let mut scene = SceneRef::new(tree, triangles);
    if let Some(l) = &links {
        scene = scene.with_links(l);
    }
    let logs: Vec<(FlowLog, [u64; 4])> = rays
        .par_chunks(width)
        .flat_map_iter(|packet| {
            let mut logs = vec![FlowLog::default(); packet.len()];
            let counters: Vec<_> = if width > 1 {
                let out = trace_packet_logged(&scene, packet, traversal, Some(&mut logs));
                out.expect("a packet twin of every packet variant").into_iter().map(|(_, c)| c).collect()
            } else {
                vec![trace_ray_logged(&scene, &packet[0], traversal, &mut logs[0]).1]
            };
            logs.into_iter().zip(counters).map(|(log, c)| {
                let counts = [c.nodes, c.leaves, c.triangles, c.steps].map(u64::from);
                (log, counts)
            })
        })
        .collect();
    let mut out = Records { offsets: vec![0], fetch_offsets: vec![0], ..Default::default() };
    out.offsets.reserve(rays.len());
    out.fetch_offsets.reserve(rays.len());
    for (log, [nodes, leaves, tris, steps]) in &logs {
        out.push(log)?;
        out.nodes += nodes;
        out.leaves += leaves;
        out.triangles += tris;
        out.steps += if width > 1 { *steps } else { 0 };
    }
    Ok(out)
}

/// SIMD efficiency per stage: busy lane-steps ÷ (lanes × the subgroup's steps).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Efficiency {
    /// The descent loop (interior nodes and empty leaves).
    pub descent: f64,
    /// The leaf loop (triangle tests).
    pub leaf: f64,
    /// Both stages together.
    pub overall: f64,
}

/// The efficiency of subgroups of `lanes` consecutive rays running their
/// records in lockstep: in round k every lane still tracing steps through its
/// k-th descent, then its k-th leaf; the subgroup takes as many steps as its
/// busiest lane in each stage, and the lanes that have fewer (or are done) idle.
pub fn simd_efficiency(records: &Records, lanes: usize) -> Efficiency {
    let lanes = lanes.max(1);
    let (mut busy_d, mut steps_d, mut busy_l, mut steps_l) = (0u64, 0u64, 0u64, 0u64);
    let n = records.rays();
    let mut group: Vec<Vec<(u32, u32)>> = Vec::with_capacity(lanes);
    for start in (0..n).step_by(lanes) {
        group.clear();
        group.extend((start..(start + lanes).min(n)).map(|i| records.rounds(i).collect()));
        let rounds = group.iter().map(Vec::len).max().unwrap_or(0);
        for k in 0..rounds {
            let (mut max_d, mut max_t) = (0u32, 0u32);
            for lane in &group {
                if let Some(&(d, t)) = lane.get(k) {
                    busy_d += u64::from(d);
                    busy_l += u64::from(t);
                    max_d = max_d.max(d);
                    max_t = max_t.max(t);
                }
            }
            steps_d += u64::from(max_d);
            steps_l += u64::from(max_t);
        }
    }
    let ratio = |busy: u64, steps: u64| if steps == 0 { 1.0 } else { busy as f64 / (lanes as u64 * steps) as f64 };
    Efficiency {
        descent: ratio(busy_d, steps_d),
        leaf: ratio(busy_l, steps_l),
        overall: ratio(busy_d + busy_l, steps_d + steps_l),
    }
}

/// GPU seconds of the replay and memory-only kernels and of their records'
/// reads alone (medians).
#[derive(Clone, Copy, Debug)]
pub struct ReplayTimes {
    /// The control flow replayed.
    pub replay_s: f64,
    /// The control-flow records read and summed, no loops.
    pub read_s: f64,
    /// The node and triangle fetches made, no decisions.
    pub memory_s: f64,
    /// The fetch records read and summed, no fetches.
    pub memory_read_s: f64,
}

/// Runs `glsl/divergence_replay.comp` over `records` on `ctx`'s device,
/// `repeat` times after a warm-up, in its four modes; the memory-only mode
/// fetches from a copy of the tracer's node and triangle texels of `tree`.
/// Records larger than one storage buffer range run in batches of rays (the
/// sum of their medians).
/// `None` without timestamps.
pub fn replay(
    ctx: &Arc<GpuContext>,
    tree: &KdTree,
    triangles: &[[Vec3; 3]],
    records: &Records,
    repeat: usize,
) -> Result<Option<ReplayTimes>> {
    let Some(timestamps) = Timestamps::new(ctx, 2)? else { return Ok(None) };
    let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let texel = vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
    let upload = |words: &[u32], what: &str| -> Result<Buffer> {
        // A zero-sized buffer cannot be made: one word more.
        let data = if words.is_empty() { &[0u32][..] } else { words };
        Buffer::with_data(ctx, bytemuck::cast_slice(data), storage, what)
    };
    // Rays in batches whose records fit one storage buffer range each.
    let limit = (ctx.info.max_storage_buffer_range / 4).min(u64::from(u32::MAX)) as usize;
    let mut batches = Vec::new();
    let mut start = 0;
    while start < records.rays() {
        let mut end = start + 1;
        let fits = |end: usize| {
            let words = (records.offsets[end] - records.offsets[start]) as usize;
            let fetches = (records.fetch_offsets[end] - records.fetch_offsets[start]) as usize;
            words.max(fetches).max(end - start + 1) <= limit
        };
        let mut step = 1 << 16;
        while step > 0 {
            if end + step <= records.rays() && fits(end + step) {
                end += step;
            } else {
                step /= 2;
            }
        }
        let slice = |offsets: &[u32], words: &[u32], what: &str| -> Result<[Buffer; 2]> {
            let base = offsets[start];
            let rebased: Vec<u32> = offsets[start..=end].iter().map(|o| o - base).collect();
            let (lo, hi) = (base as usize, offsets[end] as usize);
            Ok([upload(&rebased, what)?, upload(&words[lo..hi], what)?])
        };
        let rounds = slice(&records.offsets, &records.words, "divergence records")?;
        let fetches = slice(&records.fetch_offsets, &records.fetches, "divergence fetches")?;
        batches.push(((end - start) as u32, rounds, fetches));
        start = end;
    }
    let nodes = Buffer::with_data(ctx, bytemuck::cast_slice(&tree.nodes), texel, "divergence nodes")?;
    let tri_texels = crate::trace::scene::triangle_texels(tree, triangles);
    let tris = Buffer::with_data(ctx, bytemuck::cast_slice(&tri_texels), texel, "divergence triangles")?;
    let most = batches.iter().map(|b| b.0).max().unwrap_or(1).max(1);
    let sink =
        Buffer::new(ctx, 4 * u64::from(most), storage, gpu_allocator::MemoryLocation::GpuOnly, "divergence sink")?;
    let median = |mode: u32| -> Result<f64> {
        let kernel = Kernel::new(
            ctx,
            &KernelDesc {
                name: "divergence_replay",
                spirv: shaders::DIVERGENCE_REPLAY,
                bindings: 5,
                texel_buffers: &[(3, vk::Format::R32G32_UINT), (4, vk::Format::R32G32B32A32_UINT)],
                push_constant_size: 4,
                spec_constants: &[mode],
                workgroup_size: 64,
                ..Default::default()
            },
        )?;
        let mut total = 0.0;
        for (n, rounds, fetches) in &batches {
            let [o, w] = if mode < 2 { rounds } else { fetches };
            let set = BufferSet::new(ctx, &kernel, &[o, w, &sink, &nodes, &tris])?;
            let mut times = Vec::new();
            for _ in 0..=repeat.max(1) {
                ctx.submit_and_wait(|cmd| {
                    // SAFETY: `cmd` is recording; the set's buffers outlive the wait.
                    unsafe {
                        timestamps.record_reset(cmd);
                        timestamps.record(cmd, 0);
                        kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(n), *n);
                        timestamps.record(cmd, 1);
                    }
                })?;
                times.push(timestamps.seconds_between(0, 1)?);
            }
            times.remove(0); // the warm-up (lavapipe compiles on the first dispatch)
            times.sort_by(f64::total_cmp);
            total += times[times.len() / 2];
        }
        Ok(total)
    };
    Ok(Some(ReplayTimes { replay_s: median(0)?, read_s: median(1)?, memory_s: median(2)?, memory_read_s: median(3)? }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kdtree::BuildConfig;

    fn records_of(words: &[&[(u32, u32)]]) -> Records {
        let mut r = Records { offsets: vec![0], ..Default::default() };
        for lane in words {
            r.words.extend(lane.iter().map(|&(d, t)| d | (t << 16)));
            r.offsets.push(r.words.len() as u32);
        }
        r
    }

    #[test]
    fn lockstep_efficiency_counts_idle_lanes() {
        // Two lanes: (3 steps, 2 tris) and (1 step, 4 tris) then (2, 0).
        let r = records_of(&[&[(3, 2)], &[(1, 4), (2, 0)]]);
        let e = simd_efficiency(&r, 2);
        // Descent: busy 3 + 1 + 2 = 6 over 2 × (3 + 2) = 10; leaf: 6 over 2 × 4 = 8.
        assert!((e.descent - 0.6).abs() < 1e-12 && (e.leaf - 0.75).abs() < 1e-12, "{e:?}");
        assert!((e.overall - 12.0 / 18.0).abs() < 1e-12);
        // One lane per subgroup: always busy.
        assert_eq!(simd_efficiency(&r, 1), Efficiency { descent: 1.0, leaf: 1.0, overall: 1.0 });
    }

    #[test]
    fn records_sum_to_the_twins_counters() {
        let tris: Vec<[Vec3; 3]> = (0..200)
            .map(|i| {
                let p = Vec3::new((i % 10) as f32, (i / 10 % 10) as f32, (i / 100) as f32 * 3.0);
                [p, p + Vec3::X, p + Vec3::Y]
            })
            .collect();
        let tree = KdTree::build(&tris, &BuildConfig::default());
        let rays = crate::raygen::random_rays(&tree.bounds, 500, 3);
        let r = record(&tree, &tris, &rays, Traversal::closest(Variant::Stack)).unwrap();
        let (mut steps, mut visits, mut tested) = (0u64, 0u64, 0u64);
        for i in 0..r.rays() {
            for (d, t) in r.rounds(i) {
                steps += u64::from(d);
                visits += u64::from(t > 0);
                tested += u64::from(t);
            }
        }
        // Every node fetched is a descent step or a leaf that tested triangles.
        assert_eq!(steps + visits, r.nodes);
        assert_eq!(tested, r.triangles);
        assert!(visits <= r.leaves && r.triangles > 0);
        // The fetch record: one word per node fetch, a tested flag per leaf visit with triangles.
        assert_eq!(r.fetches.len() as u64, r.nodes);
        assert_eq!(r.fetches.iter().filter(|&&f| f & FlowLog::TESTED != 0).count() as u64, visits);
        let packets = Traversal { packet_width: 4, ..Traversal::closest(Variant::Ropes) };
        assert!(record(&tree, &tris, &rays, packets).is_err(), "no packet kernel of ropes");
    }
}
