//! What a render builds once, before its first sample: the kernels the plan
//! needs, the scene's shading data, the ray queues, the counters and the
//! accumulation buffer, the descriptor sets and trace bindings that tie them
//! together, and the rasterizer of first hits.

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use super::abi::{
    in_order, Emitter, GpuLight, GpuMaterial, RenderParams, Surface, ACCUM_BYTES, COUNTER_BYTES, HIT_BYTES, PATH_BYTES,
    RAY_BYTES, SPAN_BYTES,
};
use super::consts::*;
use super::passes::timestamp_pairs;
use super::plan::{material_flags, RenderPlan};
use super::settings::RenderSettings;
use crate::error::{Error, Result};
use crate::gpu::{shaders, Buffer, BufferRange, BufferSet, GpuContext, Kernel, KernelDesc, Rasterizer, Timestamps};
use crate::scene::Scene;
use crate::trace::{Backend, RayOrder, TraceBinding, TraceOptions, Tracer};
use crate::traversal::Traversal;

type Ctx = std::sync::Arc<GpuContext>;

/// Bytes of push constants of every render kernel: one [`RenderParams`].
const PUSH_CONSTANT_SIZE: u32 = std::mem::size_of::<RenderParams>() as u32;

/// Bytes of device memory the shadow queue may take (rays, weights, hits).
const SHADOW_QUEUE_BYTES: u64 = 256 << 20;

/// One ray queue: rays, their paths and their hits.
pub(super) struct Queue {
    pub(super) rays: Buffer,
    pub(super) paths: Buffer,
    pub(super) hits: Buffer,
}

impl Queue {
    /// `host_visible`: the rays are read by the host (`save_rays`).
    fn new(ctx: &Ctx, capacity: u64, name: &str, host_visible: bool) -> Result<Queue> {
        // TRANSFER_SRC: the first hits may be read back (`keep_first_hits`).
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
        let location = if host_visible { MemoryLocation::GpuToCpu } else { MemoryLocation::GpuOnly };
        let make =
            |bytes: u64, what: &str| Buffer::new(ctx, capacity * bytes, usage, location, &format!("{name} {what}"));
        Ok(Queue { rays: make(RAY_BYTES, "rays")?, paths: make(PATH_BYTES, "paths")?, hits: make(HIT_BYTES, "hits")? })
    }
}

/// Samples one submission records at most.
const MAX_SAMPLES_PER_SUBMISSION: u64 = 64;

/// How the image is cut into chunks of pixels, each traced through the queues
/// in one go.
#[derive(Clone, Copy)]
pub(super) struct Chunking {
    /// Pixels of the image.
    pub(super) pixel_count: u64,
    /// Pixels per chunk: the queues hold one chunk's paths.
    pub(super) chunk: u64,
    /// Shadow rays the shadow queue holds.
    pub(super) shadow_capacity: u64,
    /// Waves of shading per sample ([`RenderPlan::waves`]).
    pub(super) waves: u32,
    /// Samples one submission records at most
    /// ([`RenderSettings::samples_per_submission`]).
    pub(super) batch: u32,
}

impl Chunking {
    /// Checks the image against the device's limits and sizes the chunks.
    fn new(ctx: &GpuContext, settings: &RenderSettings, plan: &RenderPlan) -> Result<Chunking> {
        let (width, height) = (settings.width, settings.height);
        let pixel_count = u64::from(width) * u64::from(height);
        let limit = ctx.info.max_storage_buffer_range;
        if pixel_count * ACCUM_BYTES > limit || pixel_count * ACCUM_BYTES > ctx.info.max_memory_allocation_size {
            return Err(Error::DeviceLimit(format!(
                "a {width}x{height} image needs {} bytes of accumulation buffer; the device allows {limit} per storage buffer",
                pixel_count * ACCUM_BYTES
            )));
        }
        let shadow_per_path = u64::from(plan.shadow_per_vertex);
        // A queue entry is a ray and a path (a shadow ray's weight takes a path slot).
        let (entry_bytes, largest) = (RAY_BYTES + PATH_BYTES, RAY_BYTES.max(PATH_BYTES));
        let chunk = pixel_count
            .min(1 << 20)
            .min(limit / largest)
            .min((SHADOW_QUEUE_BYTES / (entry_bytes * shadow_per_path)).max(1024))
            .min(limit / (largest * shadow_per_path))
            .max(1);
        let waves = plan.waves;
        let batch = match settings.samples_per_submission {
            // Several chunks, or a visibility buffer drawn per sample (its render
            // pass is not ordered against the next sample's in one submission).
            _ if chunk < pixel_count || plan.raster => 1,
            0 => (1u64 << 18).div_ceil(chunk).min(MAX_SAMPLES_PER_SUBMISSION) as u32,
            n => n.min(MAX_SAMPLES_PER_SUBMISSION as u32),
        };
        let batch = batch.clamp(1, settings.spp);
        Ok(Chunking { pixel_count, chunk, shadow_capacity: chunk * shadow_per_path, waves, batch })
    }
}

/// The compute kernels of the render passes (the resolve pass only with shadow rays).
pub(super) struct Kernels {
    pub(super) raygen: Kernel,
    pub(super) shade: Kernel,
    pub(super) resolve: Option<Kernel>,
}

impl Kernels {
    fn new(ctx: &Ctx, plan: &RenderPlan) -> Result<Kernels> {
        let raygen = Kernel::new(
            ctx,
            &KernelDesc {
                name: "render_raygen",
                spirv: shaders::RENDER_RAYGEN,
                bindings: RAYGEN_BINDINGS,
                push_constant_size: PUSH_CONSTANT_SIZE,
                spec_constants: &in_order::<_, { RAYGEN_SPECS as usize }>([(
                    RAYGEN_SPEC_JITTER,
                    match (plan.jitter, plan.raster) {
                        (false, _) => JITTER_NONE,
                        (true, false) => JITTER_PER_PIXEL,
                        (true, true) => JITTER_PER_SAMPLE,
                    },
                )]),
                workgroup_size: RENDER_WORKGROUP_SIZE,
                ..Default::default()
            },
        )?;
        let shade_constants = plan.shade_constants();
        let shade = Kernel::new(
            ctx,
            &KernelDesc {
                name: "render_shade",
                spirv: shaders::RENDER_SHADE,
                bindings: SHADE_BINDINGS,
                push_constant_size: PUSH_CONSTANT_SIZE,
                spec_constants: &shade_constants,
                workgroup_size: RENDER_WORKGROUP_SIZE,
                texel_buffers: &[
                    (SHADE_BINDING_SURFACES, vk::Format::R32G32B32A32_UINT),
                    (SHADE_BINDING_MATERIALS, vk::Format::R32G32B32A32_UINT),
                ],
                ..Default::default()
            },
        )?;
        let resolve = match plan.shadow_pass {
            true => Some(Kernel::new(
                ctx,
                &KernelDesc {
                    name: "render_resolve",
                    spirv: shaders::RENDER_RESOLVE,
                    bindings: RESOLVE_BINDINGS,
                    push_constant_size: PUSH_CONSTANT_SIZE,
                    workgroup_size: RENDER_WORKGROUP_SIZE,
                    ..Default::default()
                },
            )?),
            false => None,
        };
        Ok(Kernels { raygen, shade, resolve })
    }
}

/// The scene's shading data on the device, and the order pixels are traced in.
pub(super) struct SceneBuffers {
    pub(super) surfaces: Buffer,
    pub(super) materials: Buffer,
    pub(super) emitters: Buffer,
    pub(super) lights: Buffer,
    /// The row-major index of each pixel, in the order they are traced (Morton).
    pub(super) pixels: Buffer,
    /// The same order on the host.
    pub(super) order: Vec<u32>,
}

impl SceneBuffers {
    fn new(ctx: &Ctx, scene: &Scene, settings: &RenderSettings, plan: &RenderPlan) -> Result<SceneBuffers> {
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let limit = ctx.info.max_storage_buffer_range;
        let surfaces: Vec<Surface> = scene
            .triangles
            .iter()
            .zip(&scene.material_ids)
            .map(|(t, &m)| {
                let v = |p: Vec3, w: f32| [p.x, p.y, p.z, w];
                Surface { v0: v(t[0], f32::from_bits(m)), v1: v(t[1], 0.0), v2: v(t[2], 0.0) }
            })
            .collect();
        let surface_bytes = std::mem::size_of_val(surfaces.as_slice()) as u64;
        if surface_bytes > limit {
            return Err(Error::DeviceLimit(format!(
                "the shading data of {} triangles takes {surface_bytes} bytes; the device allows {limit} per storage buffer",
                surfaces.len()
            )));
        }
        // Storage buffers for the visibility kernel, texel buffers for the shade kernel.
        let texels = storage | vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
        let surfaces = Buffer::with_data(ctx, bytemuck::cast_slice(&surfaces), texels, "surfaces")?;
        let materials: Vec<GpuMaterial> = scene
            .materials
            .iter()
            .map(|m| GpuMaterial {
                kd: [m.kd.x, m.kd.y, m.kd.z, m.ns.clamp(0.0, 1e6)],
                ks: [m.ks.x, m.ks.y, m.ks.z, f32::from_bits(material_flags(m))],
                ke: [m.ke.x, m.ke.y, m.ke.z, 0.0],
            })
            .collect();
        let materials = Buffer::with_data(ctx, bytemuck::cast_slice(&materials), texels, "materials")?;
        let emitters = match (plan.emitters.is_empty(), plan.area_lights) {
            (false, _) => Buffer::with_data(ctx, bytemuck::cast_slice(&plan.emitters), storage, "emitters")?,
            (true, false) => unused(ctx)?,
            (true, true) => Buffer::with_data(ctx, &[0; std::mem::size_of::<Emitter>()], storage, "emitters (none)")?,
        };
        let gpu_lights: Vec<GpuLight> = settings
            .lights
            .iter()
            .map(|l| GpuLight {
                position: [l.position.x, l.position.y, l.position.z, 0.0],
                intensity: [l.intensity.x, l.intensity.y, l.intensity.z, 0.0],
            })
            .collect();
        let lights = match gpu_lights.is_empty() {
            false => Buffer::with_data(ctx, bytemuck::cast_slice(&gpu_lights), storage, "point lights")?,
            true => unused(ctx)?,
        };
        let order = super::morton_pixels(settings.width, settings.height);
        let pixels = Buffer::with_data(ctx, bytemuck::cast_slice(&order), storage, "pixel order")?;
        Ok(SceneBuffers { surfaces, materials, emitters, lights, pixels, order })
    }
}

/// A placeholder for a binding the plan does not use.
fn unused(ctx: &Ctx) -> Result<Buffer> {
    Buffer::new(ctx, 16, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::GpuOnly, "unused binding")
}

/// The ray queues (A, and B when paths continue; the shadow queue when there
/// are shadow rays), the render counters, the accumulation buffer and its
/// readback.
pub(super) struct Queues {
    pub(super) a: Queue,
    pub(super) b: Option<Queue>,
    /// Where each path's shadow rays start in the shadow queue.
    pub(super) spans: Buffer,
    pub(super) shadow: Option<Queue>,
    pub(super) counters: Buffer,
    /// The counters of each sample of a submission, copied after the sample.
    pub(super) counter_log: Buffer,
    /// Per pixel: the sum of its samples' radiance (xyz) and its bad rays (w).
    pub(super) accum: Buffer,
    pub(super) readback: Buffer,
    /// Bound where the shadow queue would be when there is none.
    pub(super) dummy: Buffer,
}

impl Queues {
    /// `host`: the ray queues are host-visible (`save_rays`).
    fn new(ctx: &Ctx, plan: &RenderPlan, sizes: Chunking, host: bool) -> Result<Queues> {
        let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let Chunking { pixel_count, chunk, shadow_capacity, waves, batch } = sizes;
        let a = Queue::new(ctx, chunk, "queue A", host)?;
        let b = if plan.continue_paths { Some(Queue::new(ctx, chunk, "queue B", host)?) } else { None };
        let spans = Buffer::new(ctx, chunk * SPAN_BYTES, storage, MemoryLocation::GpuOnly, "shadow spans")?;
        let shadow = if plan.shadow_pass { Some(Queue::new(ctx, shadow_capacity, "shadow", host)?) } else { None };
        let counters = Buffer::new(
            ctx,
            u64::from(waves * RC_STRIDE) * COUNTER_BYTES,
            storage
                | vk::BufferUsageFlags::TRANSFER_DST
                | vk::BufferUsageFlags::TRANSFER_SRC
                | vk::BufferUsageFlags::INDIRECT_BUFFER,
            MemoryLocation::GpuToCpu,
            "render counters",
        )?;
        let counter_log = Buffer::new(
            ctx,
            u64::from(batch * waves * RC_STRIDE) * COUNTER_BYTES,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
            "render counters per sample",
        )?;
        let accum = Buffer::new(
            ctx,
            pixel_count * ACCUM_BYTES,
            storage | vk::BufferUsageFlags::TRANSFER_DST | vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::GpuOnly,
            "accumulation",
        )?;
        let readback = Buffer::new(
            ctx,
            pixel_count * ACCUM_BYTES,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
            "image",
        )?;
        let dummy = unused(ctx)?;
        Ok(Queues { a, b, spans, shadow, counters, counter_log, accum, readback, dummy })
    }

    /// Queue B, or A when paths do not continue (its sets are then never used).
    pub(super) fn b_or_a(&self) -> &Queue {
        self.b.as_ref().unwrap_or(&self.a)
    }
}

/// The descriptor sets of the passes: ray generation, and the shade and
/// resolve passes of A→B (index 0) and of B→A (index 1).
pub(super) struct Sets {
    pub(super) raygen: BufferSet,
    pub(super) shade: [BufferSet; 2],
    pub(super) resolve: Option<[BufferSet; 2]>,
}

impl Sets {
    fn new(ctx: &Ctx, kernels: &Kernels, data: &SceneBuffers, q: &Queues) -> Result<Sets> {
        let b_or_a = q.b_or_a();
        let (shadow_rays, shadow_weights, shadow_hits) = match &q.shadow {
            Some(s) => (&s.rays, &s.paths, &s.hits),
            None => (&q.dummy, &q.dummy, &q.dummy),
        };
        let raygen = BufferSet::new(
            ctx,
            &kernels.raygen,
            &in_order::<_, { RAYGEN_BINDINGS as usize }>([
                (RAYGEN_BINDING_PIXELS, &data.pixels),
                (RAYGEN_BINDING_RAYS, &q.a.rays),
                (RAYGEN_BINDING_PATHS, &q.a.paths),
            ]),
        )?;
        let shade_set = |from: &Queue, to: &Queue| {
            BufferSet::new(
                ctx,
                &kernels.shade,
                &in_order::<_, { SHADE_BINDINGS as usize }>([
                    (SHADE_BINDING_SURFACES, &data.surfaces),
                    (SHADE_BINDING_MATERIALS, &data.materials),
                    (SHADE_BINDING_EMITTERS, &data.emitters),
                    (SHADE_BINDING_LIGHTS, &data.lights),
                    (SHADE_BINDING_RAYS_IN, &from.rays),
                    (SHADE_BINDING_PATHS_IN, &from.paths),
                    (SHADE_BINDING_HITS_IN, &from.hits),
                    (SHADE_BINDING_RAYS_NEXT, &to.rays),
                    (SHADE_BINDING_PATHS_NEXT, &to.paths),
                    (SHADE_BINDING_SHADOW_RAYS, shadow_rays),
                    (SHADE_BINDING_SHADOW_WEIGHTS, shadow_weights),
                    (SHADE_BINDING_SPANS, &q.spans),
                    (SHADE_BINDING_COUNTERS, &q.counters),
                    (SHADE_BINDING_ACCUM, &q.accum),
                ]),
            )
        };
        let shade = [shade_set(&q.a, b_or_a)?, shade_set(b_or_a, &q.a)?];
        let resolve = match &kernels.resolve {
            Some(k) => {
                let set = |p: &Queue| {
                    BufferSet::new(
                        ctx,
                        k,
                        &in_order::<_, { RESOLVE_BINDINGS as usize }>([
                            (RESOLVE_BINDING_PATHS, &p.paths),
                            (RESOLVE_BINDING_SPANS, &q.spans),
                            (RESOLVE_BINDING_SHADOW_HITS, shadow_hits),
                            (RESOLVE_BINDING_SHADOW_WEIGHTS, shadow_weights),
                            (RESOLVE_BINDING_ACCUM, &q.accum),
                            (RESOLVE_BINDING_COUNTERS, &q.counters),
                        ]),
                    )
                };
                Some([set(&q.a)?, set(b_or_a)?])
            }
            None => None,
        };
        Ok(Sets { raygen, shade, resolve })
    }
}

/// Rasterized first hits: the visibility-buffer pipeline, the buffer it is
/// copied to, and the pass (with its set) that turns it into hits.
pub(super) struct RasterPass {
    pub(super) rasterizer: Rasterizer,
    pub(super) visibility: Buffer,
    pub(super) kernel: Kernel,
    pub(super) set: BufferSet,
}

impl RasterPass {
    fn new(ctx: &Ctx, scene: &Scene, settings: &RenderSettings, data: &SceneBuffers, q: &Queues) -> Result<Self> {
        let rasterizer = Rasterizer::new(ctx, &scene.triangles, settings.width, settings.height)?;
        let visibility = Buffer::new(
            ctx,
            rasterizer.visibility_bytes(),
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuOnly,
            "visibility",
        )?;
        let kernel = Kernel::new(
            ctx,
            &KernelDesc {
                name: "render_visibility",
                spirv: shaders::RENDER_VISIBILITY,
                bindings: VISIBILITY_BINDINGS,
                push_constant_size: PUSH_CONSTANT_SIZE,
                spec_constants: &in_order::<_, { VISIBILITY_SPECS as usize }>([(
                    VISIBILITY_SPEC_ROBUST,
                    u32::from(settings.traversal.robust),
                )]),
                workgroup_size: RENDER_WORKGROUP_SIZE,
                ..Default::default()
            },
        )?;
        let set = BufferSet::new(
            ctx,
            &kernel,
            &in_order::<_, { VISIBILITY_BINDINGS as usize }>([
                (VISIBILITY_BINDING_PIXELS, &data.pixels),
                (VISIBILITY_BINDING_VISIBILITY, &visibility),
                (VISIBILITY_BINDING_SURFACES, &data.surfaces),
                (VISIBILITY_BINDING_RAYS, &q.a.rays),
                (VISIBILITY_BINDING_HITS, &q.a.hits),
                (VISIBILITY_BINDING_COUNTERS, &q.counters),
            ]),
        )?;
        Ok(RasterPass { rasterizer, visibility, kernel, set })
    }
}

/// Everything a render builds before its first sample. Fields drop in order:
/// the trace bindings and the rasterizer first, the buffers and kernels last.
pub(super) struct Resources {
    /// The closest-hit traces of queue A (index 0) and of queue B (index 1).
    pub(super) trace_sets: [TraceBinding; 2],
    /// The any-hit traces of the shadow queue: as appended (index 0: the shadow
    /// rays of the camera hits, coherent already) and sorted on the device first
    /// (index 1: those of later path vertices, `RayOrder::Coherent`).
    pub(super) shadow_sets: Option<[TraceBinding; 2]>,
    pub(super) raster: Option<RasterPass>,
    pub(super) timestamps: Option<Timestamps>,
    /// The first sample's hits, read back per chunk when asked for.
    pub(super) hit_readback: Option<Buffer>,
    pub(super) sets: Sets,
    pub(super) queues: Queues,
    pub(super) data: SceneBuffers,
    pub(super) kernels: Kernels,
    pub(super) sizes: Chunking,
}

impl Resources {
    /// Checks the scene and the image against the tracer and the device, then
    /// builds (and has `tracer` prepare) what `plan` needs.
    pub(super) fn new(
        tracer: &mut Tracer,
        scene: &Scene,
        settings: &RenderSettings,
        plan: &RenderPlan,
    ) -> Result<Resources> {
        let ctx = tracer.context().clone();
        if scene.triangles.len() != tracer.triangle_count() {
            return Err(Error::InvalidInput(format!(
                "the scene has {} triangles but the tracer holds {}",
                scene.triangles.len(),
                tracer.triangle_count()
            )));
        }
        let sizes = Chunking::new(&ctx, settings, plan)?;
        // Kernels: only those the plan needs.
        let (closest, any_hit) = trace_options(settings);
        let kernels = Kernels::new(&ctx, plan)?;
        tracer.prepare(&closest)?;
        if plan.shadow_pass {
            tracer.prepare(&any_hit)?;
        }
        let data = SceneBuffers::new(&ctx, scene, settings, plan)?;
        let queues = Queues::new(&ctx, plan, sizes, settings.save_rays.is_some())?;
        let sets = Sets::new(&ctx, &kernels, &data, &queues)?;
        let b_or_a = queues.b_or_a();
        // SAFETY: the ranges are whole storage buffers of this device, owned by
        // these resources, which outlive every submission of the render.
        // The traces after the camera rays are device-counted: their counts are
        // words of the render counters.
        let counts = BufferRange::whole(&queues.counters);
        let trace_sets: [TraceBinding; 2] = unsafe {
            let (a, b) = (&queues.a, b_or_a);
            [
                tracer.bind_indirect(
                    BufferRange::whole(&a.rays),
                    BufferRange::whole(&a.hits),
                    None,
                    counts,
                    &closest,
                )?,
                tracer.bind_indirect(
                    BufferRange::whole(&b.rays),
                    BufferRange::whole(&b.hits),
                    None,
                    counts,
                    &closest,
                )?,
            ]
        };
        let shadow_sets = match &queues.shadow {
            // SAFETY: as above.
            Some(q) => Some(unsafe {
                let (rays, hits) = (BufferRange::whole(&q.rays), BufferRange::whole(&q.hits));
                // Sorting is the kd-tree kernels' (the ray-query kernel traces rays as given).
                let order = if tracer.backend() == Backend::KdTree { RayOrder::Coherent } else { RayOrder::AsGiven };
                let sorted = TraceOptions { order, ..any_hit };
                [
                    tracer.bind_indirect(rays, hits, None, counts, &any_hit)?,
                    tracer.bind_indirect(rays, hits, None, counts, &sorted)?,
                ]
            }),
            None => None,
        };
        let raster = match plan.raster {
            false => None,
            true => Some(RasterPass::new(&ctx, scene, settings, &data, &queues)?),
        };
        let hit_readback = match settings.keep_first_hits {
            true => Some(Buffer::new(
                &ctx,
                sizes.chunk * HIT_BYTES,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
                "first hits",
            )?),
            false => None,
        };
        let timestamps = Timestamps::new(&ctx, 2 * timestamp_pairs(sizes.waves) * sizes.batch)?;
        Ok(Resources { trace_sets, shadow_sets, raster, timestamps, hit_readback, sets, queues, data, kernels, sizes })
    }
}

/// The trace options of the closest-hit and the any-hit traces.
pub(super) fn trace_options(settings: &RenderSettings) -> (TraceOptions, TraceOptions) {
    let closest = TraceOptions::new(Traversal { any_hit: false, ..settings.traversal });
    let any_hit = TraceOptions::new(Traversal { any_hit: true, ..settings.traversal });
    (closest, any_hit)
}
