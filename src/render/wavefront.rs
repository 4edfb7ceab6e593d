//! The wavefront renderer: Whitted-style and path-traced images from ray queues.
//!
//! Each sample of each pixel is a path. The passes, all on the device:
//!
//! 1. `render_raygen.comp` writes one camera ray per pixel into queue A;
//! 2. the tracer traces queue A (closest hit);
//! 3. `render_shade.comp` shades the hits: it adds emission, background and the
//!    headlight to the pixel, appends shadow rays (point lights, one sample of the
//!    emissive triangles, ambient occlusion) with the radiance each brings if
//!    unoccluded, and appends the path's next ray (mirror reflection or diffuse
//!    bounce) to queue B. Appending by atomic counter compacts both queues;
//! 4. the tracer traces the shadow queue (any hit), and `render_resolve.comp` adds
//!    the unoccluded contributions to the pixels;
//! 5. queues A and B swap, and 2–4 repeat until no path is left.
//!
//! One submission per sample holds every wave: the traces and passes after the
//! camera rays are dispatched indirectly, sized by the counters the shade pass
//! before them wrote (`passes.rs`). The host reads the counters once per
//! sample, for the statistics, and the image at the end. [`RenderPlan`] decides from the scene and the settings
//! what a render needs; what it does not need is neither uploaded, compiled nor
//! dispatched (see [`RenderPlan::explain`]).//!
//! The code follows a render's life: [`RenderSettings`] (`settings.rs`) and
//! [`RenderPlan`] (`plan.rs`) decide what to do; `resources.rs` builds it once
//! (kernels, buffers, descriptor sets, trace bindings); `passes.rs` records the
//! submissions of each sample; `output.rs` reads the image back. `structs.rs` defines
//! the structs shared with the kernels (build.rs generates their GLSL), `abi.rs`
//! the sizes of the other buffer elements, `consts.rs` the shared constants, `sample.rs` the host
//! twin of its sample sequence. This file runs the sample loop.

use std::time::Instant;

use glam::Vec3;

use super::abi::RenderParams;
use super::output::{read_image, RenderOutput, RenderStats};
use super::passes::{Frame, Kind};
use super::plan::RenderPlan;
use super::resources::Resources;
use super::sample::ld2;
use super::settings::RenderSettings;
use crate::error::Result;
use crate::scene::{Camera, Scene};
use crate::trace::Tracer;

/// Renders `scene` (whose tree and triangles `tracer` holds) seen by `camera`.
/// `progress(done, total)` is called after each sample pass.
///
/// Errors: `Error::InvalidInput` for bad settings; `Error::DeviceLimit` when the
/// image or the scene exceed the device's buffer limits. Rays the tracer could
/// not finish (or invalid rays from degenerate geometry) do not fail the
/// render: they are counted in [`RenderStats::bad_rays`] and their pixels are
/// listed in [`RenderOutput::bad_pixels`].
pub fn render(
    tracer: &mut Tracer,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: impl FnMut(u64, u64),
) -> Result<RenderOutput> {
    render_progressive(tracer, scene, camera, settings, 0, progress, |_, _| Ok(()))
}

/// [`render`], and every `every` samples per pixel (0: never) hands
/// `checkpoint(samples, image)` the mean of the samples so far (row-major
/// linear radiance), e.g. to write a progressive preview. Images that render in
/// several chunks (more than 2^20 pixels) get no checkpoints: their pixels do not
/// all reach a sample count at the same time.
pub fn render_progressive(
    tracer: &mut Tracer,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    every: u32,
    mut progress: impl FnMut(u64, u64),
    mut checkpoint: impl FnMut(u32, &[Vec3]) -> Result<()>,
) -> Result<RenderOutput> {
    let setup_start = Instant::now();
    let plan = RenderPlan::new(scene, settings)?;
    let res = Resources::new(tracer, scene, settings, &plan)?;
    let ctx = tracer.context().clone();
    let (width, height) = (settings.width, settings.height);
    let (pixel_count, chunk) = (res.sizes.pixel_count, res.sizes.chunk);
    let first_hits = settings.keep_first_hits.then(|| vec![crate::geom::Hit::default(); pixel_count as usize]);
    let setup_seconds = setup_start.elapsed().as_secs_f64();

    // The sample loop.
    let eye = camera.pinhole(width, height)[0];
    // The rasterizer's near plane: geometry closer to the eye is clipped (a
    // trace would see it). A millionth of the scene's size and distance.
    let near = 1e-6 * (scene.bounds.extent().length() + (scene.bounds.center() - eye).length()).max(f32::MIN_POSITIVE);
    let mut frame = Frame {
        ctx: &ctx,
        res: &res,
        tracer,
        params: params(camera, settings, &plan, res.sizes.shadow_capacity),
        stats: RenderStats { setup_seconds, rasterized: res.raster.is_some(), ..Default::default() },
        times: [0.0; 7],
        first_hits,
        save_rays: settings.save_rays.as_deref(),
        saved: Default::default(),
    };
    let loop_start = Instant::now();
    let chunks = pixel_count.div_ceil(chunk);
    let total = chunks * u64::from(settings.spp);
    let mut done = 0;
    // SAFETY: the accumulation buffer lives in `res`, past this submission.
    unsafe {
        ctx.submit_and_wait(|cmd| ctx.device.cmd_fill_buffer(cmd, res.queues.accum.buffer, 0, ash::vk::WHOLE_SIZE, 0))?;
    }
    for c in 0..chunks {
        let first_pixel = c * chunk;
        let chunk_pixels = (pixel_count - first_pixel).min(chunk) as u32;
        frame.params.eye[3] = f32::from_bits(first_pixel as u32);
        let mut sample = 0;
        while sample < settings.spp {
            // Up to `batch` samples per submission, ending at checkpoints; the
            // first alone when its rays are saved wave by wave.
            let mut count = res.sizes.batch.min(settings.spp - sample);
            if sample == 0 && settings.save_rays.is_some() {
                count = 1;
            }
            if every > 0 && chunks == 1 {
                count = count.min(every - sample % every);
            }
            // One jitter per sample for the whole image when first hits are
            // rasterized: computed here once, for the projection and the camera rays.
            let jitters: Vec<[f32; 2]> = (sample..sample + count)
                .map(|s| if plan.jitter { ld2(0, s, 0, settings.seed) } else { [0.5, 0.5] })
                .collect();
            frame.samples(camera, sample, &jitters, first_pixel, chunk_pixels, near)?;
            done += u64::from(count);
            progress(done, total);
            sample += count;
            if every > 0 && chunks == 1 && sample % every == 0 && sample < settings.spp {
                frame.copy_image()?;
                let (partial, _) = read_image(&res.queues.readback, pixel_count, sample)?;
                checkpoint(sample, &partial)?;
            }
        }
    }
    frame.copy_image()?;
    let Frame { mut stats, times, first_hits, .. } = frame;
    stats.render_seconds = loop_start.elapsed().as_secs_f64();
    // No GPU times where timestamps stop advancing once a draw has run
    // (`GpuContext::timestamps_unreliable`).
    if res.timestamps.is_some() && !ctx.timestamps_unreliable() {
        let [camera, shadow, secondary] =
            [Kind::TraceCamera, Kind::TraceShadow, Kind::TraceSecondary].map(|k| times[k as usize]);
        stats.trace_seconds = Some(camera + shadow + secondary);
        stats.trace_camera_seconds = (!stats.rasterized).then_some(camera);
        stats.trace_shadow_seconds = Some(shadow);
        stats.trace_secondary_seconds = Some(secondary);
        let [raygen, shade, resolve] = [Kind::Raygen, Kind::Shade, Kind::Resolve].map(|k| times[k as usize]);
        stats.shade_seconds = Some(raygen + shade + resolve);
        stats.pass_seconds = Some([raygen, shade, resolve]);
        if res.raster.is_some() {
            stats.raster_seconds = Some(times[Kind::Raster as usize]);
        }
    }
    let (pixels, bad_pixels) = read_image(&res.queues.readback, pixel_count, settings.spp)?;
    ctx.check_validation()?;
    drop(res);
    Ok(RenderOutput { width, height, pixels, plan, stats, first_hits, bad_pixels })
}

/// The push constants of the first dispatch: the camera, the plan's lighting
/// and the settings; the loop then sets the chunk, the sample and its jitter,
/// and each dispatch its count.
fn params(camera: &Camera, settings: &RenderSettings, plan: &RenderPlan, shadow_capacity: u64) -> RenderParams {
    let [eye, forward, right, up] = camera.pinhole(settings.width, settings.height);
    let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
    RenderParams {
        eye: v4(eye, 0.0),
        forward: v4(forward, plan.emitter_weight),
        right: v4(right, 0.0),
        up: v4(up, 0.0),
        background: v4(plan.background, plan.ambient),
        width: settings.width,
        height: settings.height,
        count: 0,
        sample_index: 0,
        seed: settings.seed,
        max_depth: settings.max_depth,
        bounces: settings.bounces,
        ao_samples: settings.ao_samples,
        ao_radius: plan.ao_radius,
        light_count: settings.lights.len() as u32,
        emitter_count: plan.emitters.len() as u32,
        shadow_capacity: shadow_capacity as u32,
    }
}
