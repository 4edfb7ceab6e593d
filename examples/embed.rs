//! An "engine" that embeds kdtrace: it owns its Vulkan instance, device, queue and
//! gpu-allocator `Allocator`, and lends them to kdtrace ([`GpuContext::adopt`]).
//! One command buffer holds the whole frame:
//!
//! 1. the engine's ray generation shader (`glsl/examples/raygen.comp`) writes one
//!    camera ray per pixel into the engine's buffer;
//! 2. kdtrace's trace, recorded with [`Tracer::record_trace`], reads those rays and
//!    writes hits into another range of the same buffer;
//! 3. the engine's shading shader (`glsl/examples/shade.comp`) turns the hits into
//!    sRGB pixels,
//!
//! with the engine's barriers between the passes; then the engine submits, waits,
//! and writes the PNG. Both shaders include only kdtrace's GLSL header
//! (`kdtrace::gpu::shaders::HEADER`). The image matches `kdtrace render` of the
//! same scene and camera.
//!
//! ```sh
//! cargo run --example embed -- [OUT.png] [SCENE.obj] [WIDTH HEIGHT]
//! ```
//!
//! `tests/embed.rs` runs [`run`] on lavapipe with the validation layer and checks
//! the image and that tearing the device down reports nothing.

use std::ffi::{c_void, CStr};
use std::mem::ManuallyDrop;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{anyhow, bail, Context, Result};
use ash::vk;
use glam::{DVec3, Vec3};
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme, Allocator, AllocatorCreateDesc};
use gpu_allocator::MemoryLocation;
use kdtrace::gpu::{required_features, shaders, AdoptDesc, BufferRange, GpuContext, Validation};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::{Hit, Ray};

/// The engine's constants and structs shared with its shaders (workgroup size,
/// bindings, push constants, surfaces): `glsl/examples/abi.rs`, which build.rs
/// passes to them as `#define`s and generated GLSL declarations.
pub mod abi {
    include!(concat!(env!("CARGO_MANIFEST_DIR"), "/src/gpu_struct.rs"));
    include!(concat!(env!("CARGO_MANIFEST_DIR"), "/glsl/examples/abi.rs"));
}
use abi::*;

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let output = PathBuf::from(args.first().map(String::as_str).unwrap_or("embed.png"));
    let scene = args.get(1).map(PathBuf::from).unwrap_or_else(default_scene);
    let width = args.get(2).map(|w| w.parse()).transpose().context("WIDTH")?.unwrap_or(512);
    let height = args.get(3).map(|h| h.parse()).transpose().context("HEIGHT")?.unwrap_or(512);
    let report = run(&scene, width, height, Some(&output), Validation::IfAvailable)?;
    eprintln!(
        "{}: {width}x{height}, {} of {} pixels hit, on {}",
        output.display(),
        report.hits,
        width * height,
        report.device
    );
    Ok(())
}

/// The Cornell box of the repository.
pub fn default_scene() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes").join("cornell_box.obj")
}

/// What [`run`] made.
pub struct Report {
    /// The frame, as written to the PNG.
    pub image: image::RgbImage,
    /// The camera used (from `cameras.json` beside the scene, else framing the scene).
    pub camera: Camera,
    /// Pixels whose ray hit a triangle.
    pub hits: usize,
    /// The device's name.
    pub device: String,
}

/// Renders `scene` at `width` × `height` as the module docs describe, writes the
/// PNG to `output` when given, and tears the engine down. Any validation message
/// (also those of device destruction, such as objects kdtrace forgot) is an error.
pub fn run(scene: &Path, width: u32, height: u32, output: Option<&Path>, validation: Validation) -> Result<Report> {
    let engine = Engine::new(validation, true)?;
    let report = render_frame(&engine, scene, width, height)?;
    let messages = engine.shutdown()?;
    if !messages.is_empty() {
        bail!("validation reported {} message(s):\n{}", messages.len(), messages.join("\n"));
    }
    if let Some(path) = output {
        report.image.save(path).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(report)
}

/// The camera `kdtrace render` would use for `scene`.
pub fn scene_camera(path: &Path, scene: &Scene) -> Result<Camera> {
    let json = path.parent().unwrap_or(Path::new(".")).join("cameras.json");
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let camera = if json.exists() { Camera::from_cameras_json(&json, &stem)? } else { None };
    Ok(camera.unwrap_or_else(|| Camera::frame(&scene.bounds)))
}

impl CameraParams {
    /// The same pinhole model as `Camera::ray`: basis in f64, scaled by the field of view.
    pub fn new(camera: &Camera, width: u32, height: u32) -> CameraParams {
        let forward = (camera.target.as_dvec3() - camera.eye.as_dvec3()).try_normalize().unwrap_or(DVec3::NEG_Z);
        let right = forward.cross(camera.up.as_dvec3()).try_normalize().unwrap_or(forward.any_orthonormal_vector());
        let up = right.cross(forward);
        let tan = (0.5 * f64::from(camera.fov_deg).clamp(1e-3, 179.0).to_radians()).tan();
        let aspect = f64::from(width) / f64::from(height);
        let v4 = |v: DVec3| [v.x as f32, v.y as f32, v.z as f32, 0.0];
        CameraParams {
            eye: v4(camera.eye.as_dvec3()),
            forward: v4(forward),
            right: v4(right * tan * aspect),
            up: v4(up * tan),
            width,
            height,
            pad0: 0,
            pad1: 0,
        }
    }
}

/// The engine's material system: geometric normal, albedo and emission per
/// triangle, shaded the way `kdtrace render` shades (mirrors as light grey).
fn surfaces(scene: &Scene) -> Vec<Surface> {
    let v4 = |v: Vec3| [v.x, v.y, v.z, 0.0];
    scene
        .triangles
        .iter()
        .enumerate()
        .map(|(i, [a, b, c])| {
            let m = scene.material(i as u32);
            let albedo = if m.illum == 3 && m.kd.max_element() < 0.05 { 0.6 * m.ks } else { m.kd };
            Surface {
                normal: v4((*b - *a).cross(*c - *a).normalize_or_zero()),
                albedo: v4(albedo),
                emission: v4(m.ke.min(Vec3::ONE)),
            }
        })
        .collect()
}

pub fn align_up(value: u64, alignment: u64) -> u64 {
    value.div_ceil(alignment) * alignment
}

/// Everything of one frame between the engine's creation and its shutdown.
fn render_frame(engine: &Engine, path: &Path, width: u32, height: u32) -> Result<Report> {
    if width == 0 || height == 0 {
        bail!("the image must have at least one pixel");
    }
    let scene = Scene::load(path)?;
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let camera = scene_camera(path, &scene)?;

    // Lend the engine's device to kdtrace and upload the scene.
    let ctx = engine.kdtrace_context()?;
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles)?;
    let options = TraceOptions::default();
    tracer.prepare(&options)?;

    // The engine's buffers: rays and hits share one device-local buffer, the hits
    // at the next offset the device allows for a storage-buffer descriptor.
    let count = width * height;
    let ray_bytes = u64::from(count) * std::mem::size_of::<Ray>() as u64;
    let hit_bytes = u64::from(count) * std::mem::size_of::<Hit>() as u64;
    let hit_offset = align_up(ray_bytes, ctx.info.min_storage_buffer_offset_alignment);
    let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let mut resources = Resources::new(engine);
    let rays_and_hits = resources.buffer(hit_offset + hit_bytes, storage, MemoryLocation::GpuOnly, "rays+hits")?;
    let rays = BufferRange::new(rays_and_hits, 0, ray_bytes);
    let hits = BufferRange::new(rays_and_hits, hit_offset, hit_bytes);
    let surface_data = surfaces(&scene);
    let surface_bytes: &[u8] = bytemuck::cast_slice(&surface_data);
    let surface_buf = resources.buffer(surface_bytes.len() as u64, storage, MemoryLocation::CpuToGpu, "surfaces")?;
    resources.write(surface_buf, surface_bytes)?;
    let pixel_bytes = u64::from(count) * std::mem::size_of::<u32>() as u64;
    let pixel_buf = resources.buffer(pixel_bytes, storage, MemoryLocation::GpuToCpu, "pixels")?;

    // The engine's pipelines and descriptor sets.
    let raygen = resources.pipeline(
        shaders::EXAMPLE_RAYGEN,
        ENGINE_RAYGEN_BINDINGS,
        std::mem::size_of::<CameraParams>() as u32,
    )?;
    let shade =
        resources.pipeline(shaders::EXAMPLE_SHADE, ENGINE_SHADE_BINDINGS, std::mem::size_of::<ShadeParams>() as u32)?;
    let [raygen_set, shade_set] = resources.descriptor_sets([raygen.set_layout, shade.set_layout])?;
    let pixels = BufferRange::new(pixel_buf, 0, pixel_bytes);
    let surfaces_range = BufferRange::new(surface_buf, 0, surface_bytes.len() as u64);
    resources.write_set(raygen_set, &[(ENGINE_RAYGEN_BINDING_RAYS, rays)]);
    resources.write_set(
        shade_set,
        &[
            (ENGINE_SHADE_BINDING_RAYS, rays),
            (ENGINE_SHADE_BINDING_HITS, hits),
            (ENGINE_SHADE_BINDING_SURFACES, surfaces_range),
            (ENGINE_SHADE_BINDING_PIXELS, pixels),
        ],
    );

    // One command buffer: raygen → barrier → kdtrace → barrier → shade → barrier → host.
    let device = &engine.device;
    let cmd = resources.command_buffer()?;
    let camera_params = CameraParams::new(&camera, width, height);
    let groups = count.div_ceil(ENGINE_WORKGROUP);
    // SAFETY: `cmd` is a fresh primary command buffer of the engine's device;
    // every object recorded lives in `resources` or `tracer` until the fence
    // below has signalled.
    let binding = unsafe {
        device.begin_command_buffer(cmd, &vk::CommandBufferBeginInfo::default()).context("vkBeginCommandBuffer")?;
        device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, raygen.pipeline);
        device.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, raygen.layout, 0, &[raygen_set], &[]);
        device.cmd_push_constants(
            cmd,
            raygen.layout,
            vk::ShaderStageFlags::COMPUTE,
            0,
            bytemuck::bytes_of(&camera_params),
        );
        device.cmd_dispatch(cmd, groups, 1, 1);
        // Before the trace: the rays written by raygen become readable by kdtrace's kernel.
        compute_barrier(device, cmd, vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE);
        let binding = tracer.record_trace(cmd, rays, hits, count, &options)?;
        // After the trace: the hits become readable by the engine's shading.
        compute_barrier(device, cmd, vk::AccessFlags::SHADER_READ);
        // kdtrace bound its own pipeline, set and push constants: bind ours again.
        device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, shade.pipeline);
        device.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, shade.layout, 0, &[shade_set], &[]);
        let shade_params = ShadeParams { count };
        device.cmd_push_constants(
            cmd,
            shade.layout,
            vk::ShaderStageFlags::COMPUTE,
            0,
            bytemuck::bytes_of(&shade_params),
        );
        device.cmd_dispatch(cmd, groups, 1, 1);
        memory_barrier(
            device,
            cmd,
            (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE),
            (vk::PipelineStageFlags::HOST, vk::AccessFlags::HOST_READ),
        );
        device.end_command_buffer(cmd).context("vkEndCommandBuffer")?;
        binding
    };
    engine.submit_and_wait(cmd)?;
    // The command buffer has completed: the descriptor set of the trace may go.
    drop(binding);

    let words: &[u32] = bytemuck::cast_slice(resources.read(pixel_buf)?);
    let image = image::RgbImage::from_fn(width, height, |x, y| {
        let [r, g, b, _] = words[(y * width + x) as usize].to_le_bytes();
        image::Rgb([r, g, b])
    });
    let background = image::Rgb([63u8, 63, 63]);
    let hit_count = image.pixels().filter(|p| **p != background).count();
    let report = Report { image, camera, hits: hit_count, device: ctx.info.name.clone() };

    // kdtrace's objects go before the engine's; the engine's device outlives them.
    drop(tracer);
    drop(ctx);
    drop(resources);
    Ok(report)
}

/// A compute-to-compute memory barrier for `dst_access`.
///
/// # Safety
/// `cmd` is recording outside a render pass.
pub unsafe fn compute_barrier(device: &ash::Device, cmd: vk::CommandBuffer, dst_access: vk::AccessFlags) {
    let compute = vk::PipelineStageFlags::COMPUTE_SHADER;
    // SAFETY: forwarded from the caller.
    unsafe { memory_barrier(device, cmd, (compute, vk::AccessFlags::SHADER_WRITE), (compute, dst_access)) };
}

/// A global memory barrier from `src` (stages, accesses) to `dst`.
///
/// # Safety
/// `cmd` is recording outside a render pass.
pub unsafe fn memory_barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    src: (vk::PipelineStageFlags, vk::AccessFlags),
    dst: (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let barrier = vk::MemoryBarrier::default().src_access_mask(src.1).dst_access_mask(dst.1);
    // SAFETY: forwarded from the caller.
    unsafe { device.cmd_pipeline_barrier(cmd, src.0, dst.0, vk::DependencyFlags::empty(), &[barrier], &[], &[]) };
}

/// The engine's device: instance (with the validation layer when asked), one
/// compute queue, a gpu-allocator `Allocator`, a command pool.
pub struct Engine {
    _entry: ash::Entry,
    /// The engine's instance.
    pub instance: ash::Instance,
    /// Its physical device.
    pub physical_device: vk::PhysicalDevice,
    /// The engine's device.
    pub device: ash::Device,
    /// A compute queue family and its queue 0.
    pub queue_family: u32,
    /// The queue both the engine and kdtrace submit to.
    pub queue: vk::Queue,
    /// Held around every submission to `queue` (shared with kdtrace).
    pub queue_lock: Arc<Mutex<()>>,
    /// The features the device was created with.
    pub enabled_features: vk::PhysicalDeviceFeatures,
    allocator: ManuallyDrop<Arc<Mutex<Allocator>>>,
    command_pool: vk::CommandPool,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    messages: Box<Mutex<Vec<String>>>,
    alive: bool,
}

unsafe extern "system" fn collect_message(
    _severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes valid callback data for the call; `user` is the
    // engine's boxed message list, which outlives the messenger.
    unsafe {
        let text = if data.is_null() || (*data).p_message.is_null() {
            "(no message)".to_string()
        } else {
            CStr::from_ptr((*data).p_message).to_string_lossy().into_owned()
        };
        eprintln!("engine: validation: {text}");
        if let Some(Ok(mut list)) = (user as *const Mutex<Vec<String>>).as_ref().map(|m| m.lock()) {
            list.push(text);
        }
    }
    vk::FALSE
}

impl Engine {
    /// Creates the engine's instance and device. `float64`: whether to enable
    /// `shaderFloat64` and `shaderInt64` besides kdtrace's [`required_features`]
    /// (kdtrace needs neither: tests run both ways).
    pub fn new(validation: Validation, float64: bool) -> Result<Engine> {
        // SAFETY: loading the system Vulkan loader.
        let entry = unsafe { ash::Entry::load() }?;
        let layer = c"VK_LAYER_KHRONOS_validation";
        // SAFETY: plain query.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }?;
        let installed = layers.iter().any(|l| l.layer_name_as_c_str() == Ok(layer));
        let with_layer = match validation {
            Validation::Off => false,
            Validation::IfAvailable => installed,
            Validation::Required if installed => true,
            Validation::Required => bail!("the validation layer is required but not installed"),
        };
        let app = vk::ApplicationInfo::default().application_name(c"embed example").api_version(vk::API_VERSION_1_2);
        let layer_names = if with_layer { vec![layer.as_ptr()] } else { vec![] };
        let mut extensions = if with_layer { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        // Synchronization validation too where the layer offers it: a missing
        // barrier between the engine's passes and kdtrace's is then reported.
        // SAFETY: a query of the loader with a valid layer name.
        let sync_validation = with_layer
            && unsafe { entry.enumerate_instance_extension_properties(Some(layer)) }
                .map(|exts| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(ash::ext::validation_features::NAME)))
                .unwrap_or(false);
        if sync_validation {
            extensions.push(ash::ext::validation_features::NAME.as_ptr());
        }
        let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
        let mut info = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&extensions);
        if sync_validation {
            info = info.push_next(&mut features);
        }
        // SAFETY: the create info and its strings outlive the call.
        let instance = unsafe { entry.create_instance(&info, None) }?;
        let messages: Box<Mutex<Vec<String>>> = Box::default();
        let debug = if with_layer {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(collect_message))
                .user_data(&*messages as *const Mutex<Vec<String>> as *mut c_void);
            // SAFETY: `messages` is boxed and outlives the messenger.
            Some((loader.clone(), unsafe { loader.create_debug_utils_messenger(&info, None) }?))
        } else {
            None
        };

        // The engine's device choice: a Vulkan 1.2 device with a compute queue,
        // discrete GPUs first.
        // SAFETY: plain queries on a live instance.
        let (physical_device, queue_family) = unsafe {
            let mut best = None;
            for pd in instance.enumerate_physical_devices()? {
                let props = instance.get_physical_device_properties(pd);
                let family = instance
                    .get_physical_device_queue_family_properties(pd)
                    .iter()
                    .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE));
                let rank = if props.device_type == vk::PhysicalDeviceType::DISCRETE_GPU { 0 } else { 1 };
                let better = match best {
                    Some((r, _, _)) => rank < r,
                    None => true,
                };
                if let (Some(family), true, true) = (family, props.api_version >= vk::API_VERSION_1_2, better) {
                    best = Some((rank, pd, family as u32));
                }
            }
            let (_, pd, family) = best.ok_or_else(|| anyhow!("no Vulkan 1.2 device with a compute queue"))?;
            (pd, family)
        };
        let enabled_features =
            if float64 { required_features().shader_float64(true).shader_int64(true) } else { required_features() };
        let priorities = [1.0];
        let queues =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let info = vk::DeviceCreateInfo::default().queue_create_infos(&queues).enabled_features(&enabled_features);
        // SAFETY: the create info outlives the call; the family exists.
        let device = unsafe { instance.create_device(physical_device, &info, None) }?;
        // SAFETY: queue 0 of the family requested above.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };
        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })?;
        let pool_info = vk::CommandPoolCreateInfo::default().queue_family_index(queue_family);
        // SAFETY: a valid create info on the new device.
        let command_pool = unsafe { device.create_command_pool(&pool_info, None) }?;
        Ok(Engine {
            _entry: entry,
            instance,
            physical_device,
            device,
            queue_family,
            queue,
            queue_lock: Arc::default(),
            enabled_features,
            allocator: ManuallyDrop::new(Arc::new(Mutex::new(allocator))),
            command_pool,
            debug,
            messages,
            alive: true,
        })
    }

    /// The engine's allocator (shared with kdtrace).
    pub fn allocator(&self) -> &Arc<Mutex<Allocator>> {
        &self.allocator
    }

    /// True when the validation layer reports into this engine.
    pub fn validation_enabled(&self) -> bool {
        self.debug.is_some()
    }

    /// A kdtrace context on the engine's device, queue and allocator.
    pub fn kdtrace_context(&self) -> kdtrace::Result<Arc<GpuContext>> {
        self.kdtrace_context_on(self.queue_family)
    }

    /// `kdtrace_context` claiming queue family `queue_family` (tests pass a wrong one).
    pub fn kdtrace_context_on(&self, queue_family: u32) -> kdtrace::Result<Arc<GpuContext>> {
        // SAFETY: the handles belong together, the device was created with
        // `enabled_features`, and the engine outlives every kdtrace object: callers
        // drop those before `shutdown` (which refuses to run otherwise).
        unsafe {
            GpuContext::adopt(AdoptDesc {
                instance: self.instance.clone(),
                physical_device: self.physical_device,
                device: self.device.clone(),
                queue_family,
                queue: self.queue,
                queue_lock: Some(self.queue_lock.clone()),
                allocator: Arc::clone(&self.allocator),
                enabled_features: self.enabled_features,
                subgroup_size_control: false,
                ray_query: false,
            })
        }
    }

    /// Submits `cmd` on the engine's queue and waits for it.
    pub fn submit_and_wait(&self, cmd: vk::CommandBuffer) -> Result<()> {
        let cmds = [cmd];
        let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
        // SAFETY: `cmd` was recorded on this device; the queue is guarded by `queue_lock`.
        unsafe {
            let fence = self.device.create_fence(&vk::FenceCreateInfo::default(), None)?;
            let submitted = {
                let _queue = self.queue_lock.lock().map_err(|_| anyhow!("queue lock poisoned"))?;
                self.device.queue_submit(self.queue, &submit, fence)
            };
            let waited = submitted.and_then(|_| self.device.wait_for_fences(&[fence], true, u64::MAX));
            self.device.destroy_fence(fence, None);
            waited?;
        }
        Ok(())
    }

    /// Tears the engine down and returns every validation message reported, the
    /// ones of device destruction included (objects left alive are reported then).
    /// Fails when kdtrace objects still hold the allocator.
    pub fn shutdown(mut self) -> Result<Vec<String>> {
        let holders = Arc::strong_count(&self.allocator);
        if holders != 1 {
            bail!("{} kdtrace context(s) still hold the allocator: drop tracers and contexts first", holders - 1);
        }
        self.destroy();
        Ok(std::mem::take(&mut *self.messages.lock().map_err(|_| anyhow!("message list poisoned"))?))
    }

    fn destroy(&mut self) {
        if !std::mem::replace(&mut self.alive, false) {
            return;
        }
        // SAFETY: no work is pending after the idle wait; the allocator is dropped
        // (freeing its memory) before the device, the messenger after the device so
        // that reports of destruction are collected.
        unsafe {
            let queue = self.queue_lock.lock();
            let _ = self.device.device_wait_idle();
            drop(queue);
            self.device.destroy_command_pool(self.command_pool, None);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((loader, messenger)) = &self.debug {
                loader.destroy_debug_utils_messenger(*messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

impl Drop for Engine {
    fn drop(&mut self) {
        if self.alive && Arc::strong_count(&self.allocator) != 1 {
            // kdtrace objects still use the device: leaking beats destroying it under them.
            eprintln!("engine: kdtrace still holds the device; leaking it");
            return;
        }
        self.destroy();
    }
}

/// A compute pipeline of the engine: storage buffers at bindings `0..n` of set 0.
#[derive(Clone, Copy)]
pub struct Pipeline {
    pub pipeline: vk::Pipeline,
    pub layout: vk::PipelineLayout,
    pub set_layout: vk::DescriptorSetLayout,
}

/// The engine's per-frame objects, destroyed together when dropped (after the
/// frame's fence, or on an error path after the queue is idle).
pub struct Resources<'a> {
    engine: &'a Engine,
    buffers: Vec<(vk::Buffer, Option<Allocation>)>,
    pipelines: Vec<Pipeline>,
    descriptor_pool: vk::DescriptorPool,
}

impl<'a> Resources<'a> {
    pub fn new(engine: &'a Engine) -> Resources<'a> {
        Resources { engine, buffers: Vec::new(), pipelines: Vec::new(), descriptor_pool: vk::DescriptorPool::null() }
    }

    pub fn buffer(
        &mut self,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        name: &str,
    ) -> Result<vk::Buffer> {
        let device = &self.engine.device;
        let info = vk::BufferCreateInfo::default().size(size).usage(usage);
        // SAFETY: a valid create info; the buffer is recorded for destruction at once.
        let buffer = unsafe { device.create_buffer(&info, None) }?;
        self.buffers.push((buffer, None));
        // SAFETY: `buffer` is a live buffer of this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
        let allocation = self.engine.allocator.lock().map_err(|_| anyhow!("allocator poisoned"))?.allocate(
            &AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            },
        )?;
        // SAFETY: the allocation satisfies the buffer's requirements.
        let bound = unsafe { device.bind_buffer_memory(buffer, allocation.memory(), allocation.offset()) };
        self.buffers.last_mut().unwrap().1 = Some(allocation);
        bound?;
        Ok(buffer)
    }

    pub fn allocation(&self, buffer: vk::Buffer) -> Result<&Allocation> {
        self.buffers
            .iter()
            .find(|(b, _)| *b == buffer)
            .and_then(|(_, a)| a.as_ref())
            .ok_or_else(|| anyhow!("no such buffer"))
    }

    pub fn write(&mut self, buffer: vk::Buffer, data: &[u8]) -> Result<()> {
        let allocation = self.buffers.iter_mut().find(|(b, _)| *b == buffer).and_then(|(_, a)| a.as_mut());
        let mapped = allocation.and_then(|a| a.mapped_slice_mut()).ok_or_else(|| anyhow!("buffer not mapped"))?;
        mapped[..data.len()].copy_from_slice(data);
        Ok(())
    }

    pub fn read(&self, buffer: vk::Buffer) -> Result<&[u8]> {
        self.allocation(buffer)?.mapped_slice().ok_or_else(|| anyhow!("buffer not mapped"))
    }

    pub fn pipeline(&mut self, spirv: &[u8], bindings: u32, push_bytes: u32) -> Result<Pipeline> {
        let device = &self.engine.device;
        let code = ash::util::read_spv(&mut std::io::Cursor::new(spirv))?;
        let layout_bindings: Vec<vk::DescriptorSetLayoutBinding> = (0..bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        // SAFETY: valid create infos; every object is recorded for destruction
        // (null handles are ignored by the destroy calls).
        unsafe {
            let mut p = Pipeline {
                pipeline: vk::Pipeline::null(),
                layout: vk::PipelineLayout::null(),
                set_layout: vk::DescriptorSetLayout::null(),
            };
            p.set_layout = device.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default().bindings(&layout_bindings),
                None,
            )?;
            self.pipelines.push(p);
            let set_layouts = [p.set_layout];
            let push = [vk::PushConstantRange::default().stage_flags(vk::ShaderStageFlags::COMPUTE).size(push_bytes)];
            p.layout = device.create_pipeline_layout(
                &vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts).push_constant_ranges(&push),
                None,
            )?;
            *self.pipelines.last_mut().unwrap() = p;
            let module = device.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let info = [vk::ComputePipelineCreateInfo::default().stage(stage).layout(p.layout)];
            let created = device.create_compute_pipelines(vk::PipelineCache::null(), &info, None);
            device.destroy_shader_module(module, None);
            p.pipeline = created.map_err(|(_, e)| e)?[0];
            *self.pipelines.last_mut().unwrap() = p;
            Ok(p)
        }
    }

    pub fn descriptor_sets<const N: usize>(
        &mut self,
        layouts: [vk::DescriptorSetLayout; N],
    ) -> Result<[vk::DescriptorSet; N]> {
        let device = &self.engine.device;
        let sizes = [vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 8 * N as u32 }];
        // SAFETY: valid create/allocate infos; the pool is destroyed in `drop`.
        unsafe {
            self.descriptor_pool = device.create_descriptor_pool(
                &vk::DescriptorPoolCreateInfo::default().max_sets(N as u32).pool_sizes(&sizes),
                None,
            )?;
            let sets = device.allocate_descriptor_sets(
                &vk::DescriptorSetAllocateInfo::default().descriptor_pool(self.descriptor_pool).set_layouts(&layouts),
            )?;
            sets.try_into().map_err(|_| anyhow!("descriptor set count"))
        }
    }

    /// Writes each `(binding, range)` into `set`.
    pub fn write_set(&self, set: vk::DescriptorSet, ranges: &[(u32, BufferRange)]) {
        let infos: Vec<(u32, [vk::DescriptorBufferInfo; 1])> = ranges
            .iter()
            .map(|&(b, r)| (b, [vk::DescriptorBufferInfo { buffer: r.buffer, offset: r.offset, range: r.range }]))
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = infos
            .iter()
            .map(|(binding, info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(*binding)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: the set is not in use yet; the buffers are live.
        unsafe { self.engine.device.update_descriptor_sets(&writes, &[]) };
    }

    pub fn command_buffer(&self) -> Result<vk::CommandBuffer> {
        let info = vk::CommandBufferAllocateInfo::default()
            .command_pool(self.engine.command_pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the engine's pool, used from this thread only; its buffers are
        // freed with the pool.
        Ok(unsafe { self.engine.device.allocate_command_buffers(&info) }?[0])
    }
}

impl Drop for Resources<'_> {
    fn drop(&mut self) {
        let device = &self.engine.device;
        // SAFETY: nothing pending uses these objects (the frame's fence was waited
        // for, or the queue is drained here on an error path).
        unsafe {
            // vkDeviceWaitIdle needs the queue externally synchronised too.
            let queue = self.engine.queue_lock.lock();
            let _ = device.device_wait_idle();
            drop(queue);
            device.destroy_descriptor_pool(self.descriptor_pool, None);
            for p in self.pipelines.drain(..) {
                device.destroy_pipeline(p.pipeline, None);
                device.destroy_pipeline_layout(p.layout, None);
                device.destroy_descriptor_set_layout(p.set_layout, None);
            }
            for (buffer, allocation) in self.buffers.drain(..) {
                device.destroy_buffer(buffer, None);
                if let (Some(a), Ok(mut allocator)) = (allocation, self.engine.allocator.lock()) {
                    let _ = allocator.free(a);
                }
            }
        }
    }
}
