//! The per-sample passes: one submission per sample holding every wave of
//! rays, each dispatch between barriers and timestamps ([`Pass`]). The waves
//! after the camera rays are dispatched indirectly, sized by the counters the
//! shade pass before them wrote on the device (no host round trip between
//! bounces); the host reads the counters once per sample, for the statistics.

use ash::vk;

use std::collections::HashSet;
use std::io::Write;
use std::path::Path;

use super::abi::{RenderParams, ACCUM_BYTES, COUNTER_BYTES, HIT_BYTES, RAY_BYTES};
use super::consts::{RC_ARGS, RC_BAD_RAYS, RC_NEXT, RC_OVERFLOW, RC_RASTER_EDGE, RC_SHADOW, RC_STRIDE, RC_WAVE};
use super::output::RenderStats;
use super::resources::{RasterPass, Resources};
use crate::error::{Error, Result};
use crate::geom::Hit;
use crate::gpu::{Buffer, GpuContext, Kernel, RasterView, Timestamps};
use crate::scene::Camera;
use crate::trace::Tracer;

/// Timestamp pairs a sample's submission records at most (one per timed
/// dispatch) with `waves` waves: ray generation, the camera rays' trace (or
/// the two raster passes), their shade, then four per later wave (shadow trace,
/// resolve, trace, shade) and two for the last wave's shadow rays.
pub(super) fn timestamp_pairs(waves: u32) -> u32 {
    4 + 4 * waves + 2
}

/// One sample's dispatches in a submission, each between a barrier and a pair
/// of timestamps (its `pairs` pairs from query `base` on).
pub(super) struct Pass<'a> {
    ctx: &'a GpuContext,
    timestamps: Option<&'a Timestamps>,
    pairs: u32,
    base: u32,
    kinds: Vec<Kind>,
    error: Option<Error>,
}

/// What a timed dispatch was, for the GPU time totals.
#[derive(Clone, Copy)]
pub(super) enum Kind {
    TraceCamera = 0,
    TraceShadow = 1,
    TraceSecondary = 2,
    Shade = 3,
    Raster = 4,
    Raygen = 5,
    Resolve = 6,
}

/// GPU seconds per [`Kind`].
pub(super) type KindTimes = [f64; 7];

impl<'a> Pass<'a> {
    /// The pass of the `k`-th sample of a submission.
    fn new(ctx: &'a GpuContext, timestamps: Option<&'a Timestamps>, pairs: u32, k: u32) -> Self {
        Pass { ctx, timestamps, pairs, base: 2 * pairs * k, kinds: Vec::new(), error: None }
    }

    /// Resets the timestamps (in a submission's first pass); with `counters`,
    /// sets the render counters to `reset` (a sample's start).
    unsafe fn begin(&mut self, cmd: vk::CommandBuffer, counters: Option<(&Buffer, &[u32])>) {
        if let Some(t) = self.timestamps.filter(|_| self.base == 0) {
            t.record_reset(cmd);
        }
        if let Some((buffer, reset)) = counters {
            self.ctx.device.cmd_update_buffer(cmd, buffer.buffer, 0, bytemuck::cast_slice(reset));
            compute_barrier(self.ctx, cmd);
        }
    }

    unsafe fn timed(&mut self, cmd: vk::CommandBuffer, kind: Kind, record: impl FnOnce()) {
        let index = self.kinds.len() as u32;
        if let Some(t) = self.timestamps.filter(|_| index < self.pairs) {
            t.record(cmd, self.base + 2 * index);
        }
        record();
        if let Some(t) = self.timestamps.filter(|_| index < self.pairs) {
            t.record(cmd, self.base + 2 * index + 1);
        }
        self.kinds.push(kind);
        compute_barrier(self.ctx, cmd);
    }

    unsafe fn trace(&mut self, cmd: vk::CommandBuffer, kind: Kind, record: impl FnOnce() -> Result<()>) {
        let mut result = Ok(());
        self.timed(cmd, kind, || result = record());
        if let Err(e) = result {
            self.error.get_or_insert(e);
        }
    }

    unsafe fn shade(&mut self, cmd: vk::CommandBuffer, kind: Kind, record: impl FnOnce()) {
        self.timed(cmd, kind, record);
    }

    unsafe fn raster(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce()) {
        self.timed(cmd, Kind::Raster, record);
    }

    unsafe fn end(&mut self, cmd: vk::CommandBuffer) {
        // Every query must be written before the results can be read with WAIT.
        if let Some(t) = self.timestamps {
            for index in 2 * self.kinds.len().min(self.pairs as usize) as u32..2 * self.pairs {
                t.record(cmd, self.base + index);
            }
        }
        self.ctx.record_host_read_barrier(cmd);
    }

    /// After the submission completed: adds its GPU times (`ticks`: the
    /// submission's timestamps).
    fn finish(self, ticks: Option<&[u64]>, times: &mut KindTimes) -> Result<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if let (Some(t), Some(ticks)) = (self.timestamps, ticks) {
            for (i, &kind) in self.kinds.iter().enumerate().take(self.pairs as usize) {
                let a = self.base + 2 * i as u32;
                times[kind as usize] += t.seconds(ticks, a, a + 1);
            }
        }
        Ok(())
    }
}

/// Compute and transfer writes before compute, transfer and indirect-argument
/// access (the render counters are read as dispatch arguments).
unsafe fn compute_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(
            vk::AccessFlags::SHADER_READ
                | vk::AccessFlags::SHADER_WRITE
                | vk::AccessFlags::TRANSFER_READ
                | vk::AccessFlags::TRANSFER_WRITE
                | vk::AccessFlags::INDIRECT_COMMAND_READ,
        );
    let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
    ctx.device.cmd_pipeline_barrier(
        cmd,
        stages | vk::PipelineStageFlags::DRAW_INDIRECT,
        stages | vk::PipelineStageFlags::DRAW_INDIRECT,
        vk::DependencyFlags::empty(),
        &[barrier],
        &[],
        &[],
    );
}

/// The render counters of `waves` waves, `RC_STRIDE` words each (`RC_*`).
fn read_counters(counters: &Buffer, waves: u32) -> Result<Vec<u32>> {
    let bytes = counters.read(0, (u64::from(waves * RC_STRIDE) * COUNTER_BYTES) as usize)?;
    Ok(bytes.chunks_exact(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect())
}

/// The render counters at a sample's start: every count 0, every wave's
/// indirect dispatch (0, 1, 1).
pub(super) fn counters_reset(waves: u32) -> Vec<u32> {
    let mut words = vec![0; (waves * RC_STRIDE) as usize];
    for block in words.chunks_exact_mut(RC_STRIDE as usize) {
        block[RC_ARGS as usize + 1] = 1;
        block[RC_ARGS as usize + 2] = 1;
    }
    words
}

/// The sample loop's state: what the passes record with and what they update.
pub(super) struct Frame<'a> {
    pub(super) ctx: &'a GpuContext,
    pub(super) res: &'a Resources,
    pub(super) tracer: &'a Tracer,
    /// The push constants of the next dispatch.
    pub(super) params: RenderParams,
    pub(super) stats: RenderStats,
    /// GPU seconds per [`Kind`].
    pub(super) times: KindTimes,
    /// The first sample's hits, row-major, when asked for.
    pub(super) first_hits: Option<Vec<Hit>>,
    /// Where the first sample's rays go ([`RenderSettings::save_rays`](super::RenderSettings::save_rays)).
    pub(super) save_rays: Option<&'a Path>,
    pub(super) saved: SavedRays,
}

/// The ray files [`Frame`] has written in this render: the first chunk
/// creates a file, the next ones append to it.
#[derive(Default)]
pub(super) struct SavedRays(HashSet<String>);

impl SavedRays {
    /// Writes the first `count` rays of `rays` (host-visible) to `dir/name.rays`.
    fn save(&mut self, dir: &Path, name: &str, rays: &Buffer, count: u32) -> Result<()> {
        if count == 0 {
            return Ok(());
        }
        let bytes = rays.read(0, count as usize * RAY_BYTES as usize)?;
        let path = dir.join(format!("{name}.rays"));
        let io = |e: std::io::Error| Error::InvalidInput(format!("saving rays to {}: {e}", path.display()));
        if self.0.is_empty() {
            std::fs::create_dir_all(dir).map_err(io)?;
        }
        let mut file = std::fs::OpenOptions::new()
            .create(true)
            .write(true)
            .append(self.0.contains(name))
            .truncate(!self.0.contains(name))
            .open(&path)
            .map_err(io)?;
        file.write_all(bytes).map_err(io)?;
        self.0.insert(name.to_string());
        Ok(())
    }
}

impl Frame<'_> {
    /// Samples `first_sample ..` of a chunk, one per jitter of `jitters` (the
    /// sample's one jitter of rasterized first hits, its jitter in the pixel
    /// otherwise): one submission, each sample's counters copied aside after
    /// it; or, with `save_rays` in the first sample (alone then), one
    /// submission per wave, the rays saved between them. Then the statistics
    /// from the counters. `near` is the rasterizer's near plane.
    pub(super) fn samples(
        &mut self,
        camera: &Camera,
        first_sample: u32,
        jitters: &[[f32; 2]],
        first_pixel: u64,
        chunk_pixels: u32,
        near: f32,
    ) -> Result<()> {
        let (ctx, res) = (self.ctx, self.res);
        let waves = res.sizes.waves;
        let pairs = timestamp_pairs(waves);
        let reset = counters_reset(waves);
        let count = jitters.len() as u32;
        if count == 0 || count > res.sizes.batch {
            return Err(Error::InvalidInput(format!(
                "internal: {count} samples in one submission (at most {})",
                res.sizes.batch
            )));
        }
        if let Some(dir) = self.save_rays.filter(|_| first_sample == 0) {
            if count != 1 {
                return Err(Error::InvalidInput("internal: the rays of a batch of samples cannot be saved".into()));
            }
            self.set_sample(0, jitters[0]);
            for w in 0..=waves {
                let mut pass = Pass::new(ctx, res.timestamps.as_ref(), pairs, 0);
                // SAFETY: the resources outlive the render's submissions, each of
                // which completes before the next.
                unsafe {
                    ctx.submit_and_wait(|cmd| {
                        pass.begin(cmd, (w == 0).then_some((&res.queues.counters, &reset[..])));
                        match w {
                            0 => self.record_camera_wave(&mut pass, cmd, camera, 0, chunk_pixels, jitters[0], near),
                            w => self.record_wave(&mut pass, cmd, w, chunk_pixels),
                        }
                        pass.end(cmd);
                    })?;
                }
                let ticks = res.timestamps.as_ref().map(|t| t.ticks(2 * pairs)).transpose()?;
                pass.finish(ticks.as_deref(), &mut self.times)?;
                self.stats.submits += 1;
                let counters = read_counters(&res.queues.counters, waves)?;
                self.save_wave_rays(dir, w, chunk_pixels, &counters)?;
            }
            let counters = read_counters(&res.queues.counters, waves)?;
            return self.count_sample(&counters, 0, first_pixel, chunk_pixels);
        }
        let block_bytes = u64::from(waves * RC_STRIDE) * COUNTER_BYTES;
        let mut passes = Vec::with_capacity(count as usize);
        // SAFETY: as above.
        unsafe {
            ctx.submit_and_wait(|cmd| {
                for (k, &jitter) in jitters.iter().enumerate() {
                    let sample = first_sample + k as u32;
                    self.set_sample(sample, jitter);
                    let mut pass = Pass::new(ctx, res.timestamps.as_ref(), pairs, k as u32);
                    pass.begin(cmd, Some((&res.queues.counters, &reset[..])));
                    self.record_camera_wave(&mut pass, cmd, camera, sample, chunk_pixels, jitter, near);
                    for w in 1..=waves {
                        self.record_wave(&mut pass, cmd, w, chunk_pixels);
                    }
                    pass.end(cmd);
                    // The sample's counters, aside; the barrier orders this read
                    // before the next sample's reset.
                    let region =
                        [vk::BufferCopy { src_offset: 0, dst_offset: k as u64 * block_bytes, size: block_bytes }];
                    ctx.device.cmd_copy_buffer(cmd, res.queues.counters.buffer, res.queues.counter_log.buffer, &region);
                    compute_barrier(ctx, cmd);
                    passes.push(pass);
                }
                ctx.record_host_read_barrier(cmd);
            })?;
        }
        let ticks = res.timestamps.as_ref().map(|t| t.ticks(2 * pairs * count)).transpose()?;
        for pass in passes {
            pass.finish(ticks.as_deref(), &mut self.times)?;
        }
        self.stats.submits += 1;
        let log = read_counters(&res.queues.counter_log, count * waves)?;
        for (k, counters) in log.chunks_exact((waves * RC_STRIDE) as usize).enumerate() {
            self.count_sample(counters, first_sample + k as u32, first_pixel, chunk_pixels)?;
        }
        Ok(())
    }

    /// The push constants' sample and jitter (`right.w`, `up.w`: the jitter the
    /// rasterizer's projection took, which the camera rays then take too).
    fn set_sample(&mut self, sample: u32, jitter: [f32; 2]) {
        self.params.sample_index = sample;
        self.params.right[3] = jitter[0];
        self.params.up[3] = jitter[1];
    }

    /// Adds one sample's counters (`waves` blocks) to the statistics; after
    /// the first sample, the first hits when asked for.
    fn count_sample(&mut self, counters: &[u32], sample: u32, first_pixel: u64, chunk_pixels: u32) -> Result<()> {
        let res = self.res;
        self.stats.camera_rays += u64::from(chunk_pixels);
        let total =
            |index: u32| counters.chunks_exact(RC_STRIDE as usize).map(|b| u64::from(b[index as usize])).sum::<u64>();
        let overflow = total(RC_OVERFLOW);
        if overflow > 0 {
            return Err(Error::InvalidInput(format!(
                "internal: {overflow} shadow rays did not fit their queue of {}",
                res.sizes.shadow_capacity
            )));
        }
        self.stats.secondary_rays += total(RC_NEXT);
        self.stats.shadow_rays += total(RC_SHADOW);
        self.stats.bad_rays += total(RC_BAD_RAYS);
        self.stats.raster_edge_pixels += total(RC_RASTER_EDGE);
        if let (Some(readback), Some(first), 0) = (&res.hit_readback, &mut self.first_hits, sample) {
            let hits: &[Hit] = bytemuck::cast_slice(readback.read(0, (u64::from(chunk_pixels) * HIT_BYTES) as usize)?);
            for (i, hit) in hits.iter().enumerate() {
                first[res.data.order[first_pixel as usize + i] as usize] = *hit;
            }
        }
        Ok(())
    }

    /// `--save-rays`, after wave `w` of the first sample: the camera rays (wave
    /// 0), the rays wave `w` appended (`secondary-{w+1}`) and its shadow rays
    /// (`shadow-{w}`).
    fn save_wave_rays(&mut self, dir: &Path, w: u32, chunk_pixels: u32, counters: &[u32]) -> Result<()> {
        let res = self.res;
        if w == 0 {
            self.saved.save(dir, "camera", &res.queues.a.rays, chunk_pixels)?;
        }
        if w == res.sizes.waves {
            return Ok(());
        }
        let block = &counters[(w * RC_STRIDE) as usize..][..RC_STRIDE as usize];
        let next_queue = if w % 2 == 0 { res.queues.b_or_a() } else { &res.queues.a };
        self.saved.save(dir, &format!("secondary-{}", w + 1), &next_queue.rays, block[RC_NEXT as usize])?;
        if let Some(q) = &res.queues.shadow {
            self.saved.save(dir, &format!("shadow-{w}"), &q.rays, block[RC_SHADOW as usize])?;
        }
        Ok(())
    }

    /// Records wave 0: the camera rays, their trace (or their hits from the
    /// visibility buffer) and shade; in the first sample, the copy of the first
    /// hits when asked for.
    #[allow(clippy::too_many_arguments)]
    unsafe fn record_camera_wave(
        &mut self,
        pass: &mut Pass,
        cmd: vk::CommandBuffer,
        camera: &Camera,
        sample: u32,
        chunk_pixels: u32,
        jitter: [f32; 2],
        near: f32,
    ) {
        let (res, tracer) = (self.res, self.tracer);
        let (width, height) = (self.params.width, self.params.height);
        let params = &mut self.params;
        params.count = chunk_pixels;
        pass.shade(cmd, Kind::Raygen, || {
            res.kernels.raygen.record_dispatch(cmd, res.sets.raygen.set, bytemuck::bytes_of(params), chunk_pixels)
        });
        match &res.raster {
            None => pass.trace(cmd, Kind::TraceCamera, || tracer.record_binding(cmd, &res.trace_sets[0], chunk_pixels)),
            Some(RasterPass { rasterizer, visibility, kernel, set }) => {
                let view = RasterView::new(camera.pinhole(width, height), jitter, width, height, near);
                pass.raster(cmd, || rasterizer.record(cmd, &view, visibility));
                pass.raster(cmd, || kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(params), chunk_pixels));
            }
        }
        pass.shade(cmd, Kind::Shade, || {
            res.kernels.shade.record_dispatch(cmd, res.sets.shade[0].set, bytemuck::bytes_of(params), chunk_pixels)
        });
        if let (Some(readback), 0) = (&res.hit_readback, sample) {
            let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: u64::from(chunk_pixels) * HIT_BYTES }];
            self.ctx.device.cmd_copy_buffer(cmd, res.queues.a.hits.buffer, readback.buffer, &region);
        }
    }

    /// Records step `w` (1..=waves): the shadow rays of wave w - 1 traced and
    /// resolved, then (below the last wave) the rays wave w - 1 appended traced
    /// and shaded as wave w. Every count comes from the counters on the device:
    /// the traces are device-counted ([`Tracer::record_binding_indirect`]), the
    /// resolve and shade passes dispatched indirectly from a wave's `RC_ARGS`.
    unsafe fn record_wave(&mut self, pass: &mut Pass, cmd: vk::CommandBuffer, w: u32, chunk_pixels: u32) {
        let (res, tracer) = (self.res, self.tracer);
        let params = &mut self.params;
        let prev = w - 1;
        let block = prev * RC_STRIDE;
        let shaded = (prev % 2) as usize; // the queue wave w - 1 shaded
        let counters = res.queues.counters.buffer;
        // A dispatch of a render kernel over the paths wave `wave` shaded: all
        // the chunk's in wave 0, else those counted in the block before.
        let over_paths = |kernel: &Kernel, set: vk::DescriptorSet, params: &mut RenderParams, wave: u32| {
            if wave == 0 {
                params.count = chunk_pixels;
                kernel.record_dispatch(cmd, set, bytemuck::bytes_of(params), chunk_pixels);
            } else {
                params.count = RC_WAVE | wave;
                let args = u64::from((wave - 1) * RC_STRIDE + RC_ARGS) * COUNTER_BYTES;
                kernel.record_dispatch_indirect(cmd, set, bytemuck::bytes_of(params), counters, args);
            }
        };
        if let (Some(set), Some(resolve), Some(sets)) = (&res.shadow_sets, &res.kernels.resolve, &res.sets.resolve) {
            // The shadow rays of later path vertices are sorted first (direction
            // octant, origin cell): incoherent as appended, they trace faster
            // sorted, sort included (docs/PACKETS.md, "Packets over bounces");
            // those of camera hits are not.
            let set = &set[usize::from(prev > 0)];
            pass.trace(cmd, Kind::TraceShadow, || tracer.record_binding_indirect(cmd, set, block + RC_SHADOW));
            pass.shade(cmd, Kind::Resolve, || over_paths(resolve, sets[shaded].set, params, prev));
        }
        if w < res.sizes.waves {
            let next = 1 - shaded;
            pass.trace(cmd, Kind::TraceSecondary, || {
                tracer.record_binding_indirect(cmd, &res.trace_sets[next], block + RC_NEXT)
            });
            pass.shade(cmd, Kind::Shade, || over_paths(&res.kernels.shade, res.sets.shade[next].set, params, w));
        }
    }

    /// Copies the accumulation buffer to its host-visible readback and waits.
    pub(super) fn copy_image(&self) -> Result<()> {
        let (ctx, q) = (self.ctx, &self.res.queues);
        let size = self.res.sizes.pixel_count * ACCUM_BYTES;
        // SAFETY: as in `camera_wave`.
        unsafe {
            ctx.submit_and_wait(|cmd| {
                let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size }];
                ctx.device.cmd_copy_buffer(cmd, q.accum.buffer, q.readback.buffer, &region);
                ctx.record_host_read_barrier(cmd);
            })
        }
    }
}
