//! The per-sample passes: one submission per wave of rays, each dispatch
//! between barriers and timestamps ([`Pass`]), and the render counters read
//! back after each.

use ash::vk;

use std::collections::HashSet;
use std::io::Write;
use std::path::Path;

use super::abi::{RenderParams, ACCUM_BYTES, COUNTER_BYTES, HIT_BYTES, RAY_BYTES};
use super::consts::{RC_BAD_RAYS, RC_COUNT, RC_NEXT, RC_OVERFLOW, RC_RASTER_EDGE, RC_SHADOW};
use super::output::RenderStats;
use super::resources::{RasterPass, Resources};
use crate::error::{Error, Result};
use crate::geom::Hit;
use crate::gpu::{Buffer, GpuContext, RasterView, Timestamps};
use crate::scene::Camera;
use crate::trace::Tracer;

/// Timestamp pairs one submission records at most (one per dispatch).
pub(super) const TIMESTAMP_PAIRS: u32 = 4;

/// One submission's dispatches, each between a barrier and a pair of timestamps.
pub(super) struct Pass<'a> {
    ctx: &'a GpuContext,
    timestamps: Option<&'a Timestamps>,
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
}

/// GPU seconds per [`Kind`].
pub(super) type KindTimes = [f64; 5];

impl<'a> Pass<'a> {
    fn new(ctx: &'a GpuContext, timestamps: Option<&'a Timestamps>) -> Self {
        Pass { ctx, timestamps, kinds: Vec::new(), error: None }
    }

    /// Resets the timestamps and zeroes the counters.
    unsafe fn begin(&mut self, cmd: vk::CommandBuffer, counters: &Buffer) {
        if let Some(t) = self.timestamps {
            t.record_reset(cmd);
        }
        self.ctx.device.cmd_fill_buffer(cmd, counters.buffer, 0, vk::WHOLE_SIZE, 0);
        compute_barrier(self.ctx, cmd);
    }

    unsafe fn timed(&mut self, cmd: vk::CommandBuffer, kind: Kind, record: impl FnOnce()) {
        let index = self.kinds.len() as u32;
        if let Some(t) = self.timestamps.filter(|_| index < TIMESTAMP_PAIRS) {
            t.record(cmd, 2 * index);
        }
        record();
        if let Some(t) = self.timestamps.filter(|_| index < TIMESTAMP_PAIRS) {
            t.record(cmd, 2 * index + 1);
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

    unsafe fn shade(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce()) {
        self.timed(cmd, Kind::Shade, record);
    }

    unsafe fn raster(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce()) {
        self.timed(cmd, Kind::Raster, record);
    }

    unsafe fn end(&mut self, cmd: vk::CommandBuffer) {
        // Every query must be written before the results can be read with WAIT.
        if let Some(t) = self.timestamps {
            for index in 2 * self.kinds.len().min(TIMESTAMP_PAIRS as usize) as u32..2 * TIMESTAMP_PAIRS {
                t.record(cmd, index);
            }
        }
        self.ctx.record_host_read_barrier(cmd);
    }

    /// After the submission completed: adds its GPU times.
    fn finish(self, times: &mut KindTimes) -> Result<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if let Some(t) = self.timestamps {
            for (i, &kind) in self.kinds.iter().enumerate().take(TIMESTAMP_PAIRS as usize) {
                times[kind as usize] += t.seconds_between(2 * i as u32, 2 * i as u32 + 1)?;
            }
        }
        Ok(())
    }
}

/// Compute and transfer writes before compute, transfer and host access.
unsafe fn compute_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(
            vk::AccessFlags::SHADER_READ
                | vk::AccessFlags::SHADER_WRITE
                | vk::AccessFlags::TRANSFER_READ
                | vk::AccessFlags::TRANSFER_WRITE,
        );
    ctx.device.cmd_pipeline_barrier(
        cmd,
        vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
        vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
        vk::DependencyFlags::empty(),
        &[barrier],
        &[],
        &[],
    );
}

/// The render counters, `RC_*` each: next paths, shadow rays, bad rays, shadow
/// overflow, raster edge pixels.
fn read_counters(counters: &Buffer) -> Result<[u32; RC_COUNT as usize]> {
    let bytes = counters.read(0, (u64::from(RC_COUNT) * COUNTER_BYTES) as usize)?;
    let counter = |index: u32| {
        let b = &bytes[(u64::from(index) * COUNTER_BYTES) as usize..][..4];
        u32::from_le_bytes([b[0], b[1], b[2], b[3]])
    };
    Ok([RC_NEXT, RC_SHADOW, RC_BAD_RAYS, RC_OVERFLOW, RC_RASTER_EDGE].map(counter))
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
    /// Submission 1 of a sample of a chunk: its camera rays, their trace (or
    /// their hits from the visibility buffer) and shade; in the first sample,
    /// the copy of the first hits when asked for. `jitter` is the sample's one
    /// jitter of rasterized first hits, `near` the rasterizer's near plane.
    pub(super) fn camera_wave(
        &mut self,
        camera: &Camera,
        sample: u32,
        first_pixel: u64,
        chunk_pixels: u32,
        jitter: [f32; 2],
        near: f32,
    ) -> Result<()> {
        let (ctx, res, tracer) = (self.ctx, self.res, self.tracer);
        let (width, height) = (self.params.width, self.params.height);
        let params = &mut self.params;
        let device = &ctx.device;
        let mut pass = Pass::new(ctx, res.timestamps.as_ref());
        // SAFETY: the resources outlive the render's submissions, each of which
        // completes before the next.
        unsafe {
            ctx.submit_and_wait(|cmd| {
                pass.begin(cmd, &res.queues.counters);
                params.count = chunk_pixels;
                pass.shade(cmd, || {
                    res.kernels.raygen.record_dispatch(
                        cmd,
                        res.sets.raygen.set,
                        bytemuck::bytes_of(params),
                        chunk_pixels,
                    )
                });
                match &res.raster {
                    None => pass
                        .trace(cmd, Kind::TraceCamera, || tracer.record_binding(cmd, &res.trace_sets[0], chunk_pixels)),
                    Some(RasterPass { rasterizer, visibility, kernel, set }) => {
                        let view = RasterView::new(camera.pinhole(width, height), jitter, width, height, near);
                        pass.raster(cmd, || rasterizer.record(cmd, &view, visibility));
                        pass.raster(cmd, || {
                            kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(params), chunk_pixels)
                        });
                    }
                }
                pass.shade(cmd, || {
                    res.kernels.shade.record_dispatch(
                        cmd,
                        res.sets.shade[0].set,
                        bytemuck::bytes_of(params),
                        chunk_pixels,
                    )
                });
                if let (Some(readback), 0) = (&res.hit_readback, sample) {
                    let region =
                        [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: u64::from(chunk_pixels) * HIT_BYTES }];
                    device.cmd_copy_buffer(cmd, res.queues.a.hits.buffer, readback.buffer, &region);
                }
                pass.end(cmd);
            })?;
        }
        pass.finish(&mut self.times)?;
        self.stats.submits += 1;
        self.stats.camera_rays += u64::from(chunk_pixels);
        if let (Some(dir), 0) = (self.save_rays, sample) {
            self.saved.save(dir, "camera", &res.queues.a.rays, chunk_pixels)?;
        }
        if let (Some(readback), Some(first), 0) = (&res.hit_readback, &mut self.first_hits, sample) {
            let hits: &[Hit] = bytemuck::cast_slice(readback.read(0, (u64::from(chunk_pixels) * HIT_BYTES) as usize)?);
            for (i, hit) in hits.iter().enumerate() {
                first[res.data.order[first_pixel as usize + i] as usize] = *hit;
            }
        }
        Ok(())
    }

    /// The submissions after the camera wave, until no path and no shadow ray
    /// is left: each traces the shadow rays the last shade pass appended and
    /// resolves them, then traces and shades the paths' next rays.
    pub(super) fn path_waves(&mut self, sample: u32, chunk_pixels: u32) -> Result<()> {
        let (ctx, res, tracer) = (self.ctx, self.res, self.tracer);
        let params = &mut self.params;
        let mut current = 0usize; // which queue holds the paths just shaded
        let mut path_count = chunk_pixels;
        let mut wave = 0u32;
        loop {
            let [next, shadows, bad, overflow, edges] = read_counters(&res.queues.counters)?;
            self.stats.raster_edge_pixels += u64::from(edges);
            self.stats.bad_rays += u64::from(bad);
            if overflow > 0 {
                return Err(Error::InvalidInput(format!(
                    "internal: {overflow} shadow rays did not fit their queue of {}",
                    res.sizes.shadow_capacity
                )));
            }
            if next == 0 && shadows == 0 {
                break;
            }
            if let (Some(dir), 0) = (self.save_rays, sample) {
                let a_or_b = if current == 0 { res.queues.b_or_a() } else { &res.queues.a };
                self.saved.save(dir, &format!("secondary-{}", wave + 1), &a_or_b.rays, next)?;
                if let Some(q) = &res.queues.shadow {
                    self.saved.save(dir, &format!("shadow-{wave}"), &q.rays, shadows)?;
                }
            }
            let mut pass = Pass::new(ctx, res.timestamps.as_ref());
            // SAFETY: as in `camera_wave`.
            unsafe {
                ctx.submit_and_wait(|cmd| {
                    pass.begin(cmd, &res.queues.counters);
                    if shadows > 0 {
                        if let (Some(set), Some(resolve), Some(sets)) =
                            (&res.shadow_sets, &res.kernels.resolve, &res.sets.resolve)
                        {
                            // The shadow rays of later path vertices are sorted first
                            // (direction octant, origin cell): incoherent as appended,
                            // they trace faster sorted, sort included (docs/PACKETS.md,
                            // "Packets over bounces"); those of camera hits are not.
                            let set = &set[usize::from(wave > 0)];
                            pass.trace(cmd, Kind::TraceShadow, || tracer.record_binding(cmd, set, shadows));
                            params.count = path_count;
                            pass.shade(cmd, || {
                                resolve.record_dispatch(cmd, sets[current].set, bytemuck::bytes_of(params), path_count)
                            });
                        }
                    }
                    if next > 0 {
                        pass.trace(cmd, Kind::TraceSecondary, || {
                            tracer.record_binding(cmd, &res.trace_sets[1 - current], next)
                        });
                        params.count = next;
                        pass.shade(cmd, || {
                            res.kernels.shade.record_dispatch(
                                cmd,
                                res.sets.shade[1 - current].set,
                                bytemuck::bytes_of(params),
                                next,
                            )
                        });
                    }
                    pass.end(cmd);
                })?;
            }
            pass.finish(&mut self.times)?;
            self.stats.submits += 1;
            self.stats.shadow_rays += u64::from(shadows);
            self.stats.secondary_rays += u64::from(next);
            current = 1 - current;
            path_count = next;
            wave += 1;
        }
        Ok(())
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
