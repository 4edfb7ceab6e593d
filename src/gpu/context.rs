//! The Vulkan context: instance, device, queue and allocator, either created
//! headless ([`GpuContext::headless`], for tools and tests) or adopted from an
//! engine that owns them ([`GpuContext::adopt`]).

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use crate::error::{Error, Result, VkContext};

use super::device::{
    describe, extension_names, pick_device, ray_query_device, ray_query_lacking, DeviceInfo, RayQueryDevice,
};
use super::pipeline_cache::PipelineCacheSlot;
use super::{required_features, RAY_QUERY_EXTENSIONS};

/// Whether to enable `VK_LAYER_KHRONOS_validation`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Validation {
    /// Never.
    Off,
    /// On when the layer is installed (tests use this).
    IfAvailable,
    /// On, and an error when the layer is missing.
    Required,
}

/// How to create a headless context.
#[derive(Clone, Debug)]
pub struct ContextOptions {
    /// A device index or a case-insensitive name substring; `None` picks the best device.
    pub device: Option<String>,
    /// Whether to enable the validation layer (and collect its messages).
    pub validation: Validation,
    /// Enable the ray-query backend's extensions ([`RAY_QUERY_EXTENSIONS`]) and
    /// features (`accelerationStructure`, `rayQuery`, `bufferDeviceAddress`, the
    /// allocator's device addresses): `Error::DeviceLimit` naming what the device
    /// lacks. Off, the device and allocator are created without them, exactly
    /// as without the backend, so nothing changes for the kd-tree kernels.
    pub ray_query: bool,
}

impl ContextOptions {
    /// Reads `KDTRACE_DEVICE` (index or name substring) and `KDTRACE_VALIDATION`
    /// (`1` = if available, `required`, anything else = off); the ray query off.
    pub fn from_env() -> Self {
        let validation = match std::env::var("KDTRACE_VALIDATION").as_deref() {
            Ok("1") | Ok("on") => Validation::IfAvailable,
            Ok("required") => Validation::Required,
            _ => Validation::Off,
        };
        let device = std::env::var("KDTRACE_DEVICE").ok().filter(|s| !s.is_empty());
        ContextOptions { device, validation, ray_query: false }
    }
}

struct Debug {
    loader: ash::ext::debug_utils::Instance,
    messenger: vk::DebugUtilsMessengerEXT,
    messages: Box<Mutex<Vec<String>>>,
}

/// An engine's own Vulkan objects, for [`GpuContext::adopt`]: kdtrace then runs on
/// them and never creates an instance or a device of its own.
///
/// The device must have been created with the features of [`required_features`]
/// (today none: the kernels use no 64-bit type, so neither `shaderFloat64` nor
/// `shaderInt64` is needed) from an instance created with `apiVersion` 1.2 or
/// later (the kernels are SPIR-V 1.5), and `queue_family` must support compute.
pub struct AdoptDesc {
    /// The instance `physical_device` belongs to.
    pub instance: ash::Instance,
    /// The physical device of `device`.
    pub physical_device: vk::PhysicalDevice,
    /// The engine's device.
    pub device: ash::Device,
    /// A queue family of `device` with compute support; kdtrace creates its command
    /// pool (for uploads and [`crate::trace::Tracer::trace`]) on it.
    pub queue_family: u32,
    /// A queue of `queue_family`. kdtrace submits to it only in calls that say so
    /// (scene uploads, `Tracer::trace`), never while recording into your command buffers.
    pub queue: vk::Queue,
    /// `vkQueueSubmit` needs the queue externally synchronised. kdtrace locks this
    /// mutex around each of its submissions: pass the mutex your engine holds around
    /// its own submissions to `queue`. `None`: kdtrace makes its own, and you must
    /// not use `queue` while a kdtrace call that submits is running.
    pub queue_lock: Option<Arc<Mutex<()>>>,
    /// The allocator every kdtrace buffer comes from (shared with the engine; it
    /// must have been created for this instance, physical device and device).
    pub allocator: Arc<Mutex<Allocator>>,
    /// The core features `device` was created with (`VkDeviceCreateInfo::pEnabledFeatures`,
    /// or `VkPhysicalDeviceFeatures2::features`): checked against [`required_features`].
    pub enabled_features: vk::PhysicalDeviceFeatures,
    /// Whether `subgroupSizeControl` and `computeFullSubgroups` were enabled
    /// (Vulkan 1.3 features). Only kernels that require a subgroup size need them.
    pub subgroup_size_control: bool,
    /// Whether the device was created with the ray-query backend's extensions
    /// ([`RAY_QUERY_EXTENSIONS`]) and the features `accelerationStructure`,
    /// `rayQuery` and `bufferDeviceAddress`, and the allocator with
    /// `buffer_device_address: true`. Only the ray-query backend needs them.
    pub ray_query: bool,
}

impl std::fmt::Debug for AdoptDesc {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AdoptDesc")
            .field("instance", &self.instance.handle())
            .field("physical_device", &self.physical_device)
            .field("device", &self.device.handle())
            .field("queue_family", &self.queue_family)
            .field("queue", &self.queue)
            .field("queue_lock", &self.queue_lock.is_some())
            .field("enabled_features", &self.enabled_features)
            .field("subgroup_size_control", &self.subgroup_size_control)
            .field("ray_query", &self.ray_query)
            .finish_non_exhaustive()
    }
}

/// A Vulkan device with one compute queue and a shared allocator: the device
/// every kdtrace object runs on.
///
/// Created headless ([`GpuContext::headless`]: kdtrace owns the instance, device
/// and allocator and destroys them when the last `Arc` goes) or adopted from an
/// engine ([`GpuContext::adopt`]: kdtrace owns only its command pool; the
/// engine's instance, device, queue and allocator are never destroyed here).
///
/// `GpuContext` is `Send + Sync`: its command pool and queue submissions are
/// behind mutexes, the allocator behind the shared `Mutex`, so buffers and
/// tracers may be created and used from several threads at once.
pub struct GpuContext {
    /// The Vulkan loader; `None` for an adopted context.
    _entry: Option<ash::Entry>,
    /// The instance (the engine's when adopted).
    pub instance: ash::Instance,
    /// The physical device of `device`.
    pub physical_device: vk::PhysicalDevice,
    /// The device (the engine's when adopted).
    pub device: ash::Device,
    /// The queue kdtrace submits to (uploads and `Tracer::trace`).
    pub queue: vk::Queue,
    /// The family of `queue`; kdtrace's command pool belongs to it.
    pub queue_family: u32,
    /// Properties and limits of the device.
    pub info: DeviceInfo,
    /// True when this context created the instance, device and allocator (headless).
    owned: bool,
    allocator: ManuallyDrop<Arc<Mutex<Allocator>>>,
    queue_lock: Arc<Mutex<()>>,
    command_pool: Mutex<vk::CommandPool>,
    debug: Option<Debug>,
    /// A draw was recorded on this context (see [`GpuContext::timestamps_unreliable`]).
    drew: std::sync::atomic::AtomicBool,
    /// The ray-query backend's functions, when its extensions and features are enabled.
    ray_query: Option<RayQueryDevice>,
    /// The pipeline cache every pipeline is created with (null: none).
    pub(super) pipeline_cache: Mutex<PipelineCacheSlot>,
}

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    // SAFETY: the layer passes a valid callback-data pointer for the duration of
    // the call, and `user` is the `Mutex<Vec<String>>` boxed in `Debug`, which
    // outlives the messenger.
    unsafe {
        let message = if data.is_null() || (*data).p_message.is_null() {
            String::from("(no message)")
        } else {
            CStr::from_ptr((*data).p_message).to_string_lossy().into_owned()
        };
        let text = format!("[{severity:?}] {message}");
        eprintln!("kdtrace: validation: {text}");
        if let Some(messages) = (user as *const Mutex<Vec<String>>).as_ref() {
            if let Ok(mut m) = messages.lock() {
                m.push(text);
            }
        }
    }
    vk::FALSE
}

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

impl GpuContext {
    /// Creates an instance and a device on its own (no window, no surface).
    pub fn headless(options: &ContextOptions) -> Result<Arc<GpuContext>> {
        // SAFETY: loading the system Vulkan loader; its symbols are only used
        // through ash's function tables.
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::Loader(e.to_string()))?;

        // SAFETY: plain queries on a loaded entry.
        let layers = unsafe { entry.enumerate_instance_layer_properties() }.vk("vkEnumerateInstanceLayerProperties")?;
        let has_validation = layers.iter().any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        let validation = match options.validation {
            Validation::Off => false,
            Validation::IfAvailable => has_validation,
            Validation::Required if has_validation => true,
            Validation::Required => {
                return Err(Error::NoDevice(
                    "VK_LAYER_KHRONOS_validation is required but not installed (Debian: vulkan-validationlayers)"
                        .into(),
                ))
            }
        };

        // SAFETY: plain query.
        let loader_version = unsafe { entry.try_enumerate_instance_version() }
            .vk("vkEnumerateInstanceVersion")?
            .unwrap_or(vk::API_VERSION_1_0);
        let api_version = if loader_version >= vk::API_VERSION_1_3 { vk::API_VERSION_1_3 } else { vk::API_VERSION_1_2 };
        let app_name = CString::new("kdtrace").unwrap();
        let app_info =
            vk::ApplicationInfo::default().application_name(&app_name).engine_name(&app_name).api_version(api_version);
        let layer_names: Vec<*const i8> = if validation { vec![VALIDATION_LAYER.as_ptr()] } else { vec![] };
        let mut ext_names: Vec<*const i8> =
            if validation { vec![ash::ext::debug_utils::NAME.as_ptr()] } else { vec![] };
        // Synchronization validation too, where the layer offers it: hazards between
        // kdtrace's own passes (and a caller's recordings) are then reported.
        // SAFETY: a query of the loader with a valid layer name.
        let sync_validation = validation
            && unsafe { entry.enumerate_instance_extension_properties(Some(VALIDATION_LAYER)) }
                .map(|exts| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(ash::ext::validation_features::NAME)))
                .unwrap_or(false);
        if sync_validation {
            ext_names.push(ash::ext::validation_features::NAME.as_ptr());
        }
        let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features = vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
        let mut create_info = vk::InstanceCreateInfo::default()
            .application_info(&app_info)
            .enabled_layer_names(&layer_names)
            .enabled_extension_names(&ext_names);
        if sync_validation {
            create_info = create_info.push_next(&mut features);
        }
        // SAFETY: the create info and the strings it points to live until the call returns.
        let instance = unsafe { entry.create_instance(&create_info, None) }.vk("vkCreateInstance")?;

        let debug = if validation {
            let loader = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let messages: Box<Mutex<Vec<String>>> = Box::default();
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(debug_callback))
                .user_data(&*messages as *const Mutex<Vec<String>> as *mut c_void);
            // SAFETY: `messages` is boxed and kept in `Debug` until the messenger is destroyed.
            let messenger = unsafe { loader.create_debug_utils_messenger(&info, None) };
            match messenger {
                Ok(messenger) => Some(Debug { loader, messenger, messages }),
                Err(result) => {
                    // SAFETY: nothing else was created from this instance.
                    unsafe { instance.destroy_instance(None) };
                    return Err(Error::Vulkan { what: "vkCreateDebugUtilsMessengerEXT", result });
                }
            }
        } else {
            None
        };

        match Self::create_device(entry.clone(), instance.clone(), options, debug) {
            Ok(ctx) => Ok(Arc::new(ctx)),
            Err((e, debug)) => {
                // SAFETY: the device was not created (or already destroyed); only
                // the messenger and the instance remain.
                unsafe {
                    if let Some(d) = debug {
                        d.loader.destroy_debug_utils_messenger(d.messenger, None);
                    }
                    instance.destroy_instance(None);
                }
                Err(e)
            }
        }
    }

    fn create_device(
        entry: ash::Entry,
        instance: ash::Instance,
        options: &ContextOptions,
        debug: Option<Debug>,
    ) -> std::result::Result<GpuContext, (Error, Option<Debug>)> {
        let (physical_device, queue_family, info) = match pick_device(&instance, options) {
            Ok(p) => p,
            Err(e) => return Err((e, debug)),
        };
        let enabled = required_features();
        let mut features13 = vk::PhysicalDeviceVulkan13Features::default()
            .subgroup_size_control(info.subgroup_size_control)
            .compute_full_subgroups(info.subgroup_size_control);
        // The ray-query backend's extensions and features, when asked for.
        let ray_query = options.ray_query;
        if ray_query && !info.ray_query_missing.is_empty() {
            return Err((Error::DeviceLimit(ray_query_lacking(&info)), debug));
        }
        let extensions: Vec<*const i8> =
            if ray_query { RAY_QUERY_EXTENSIONS.iter().map(|e| e.as_ptr()).collect() } else { Vec::new() };
        let mut features12 = vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true);
        let mut acceleration =
            vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true);
        let mut query = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(true);
        let priorities = [1.0f32];
        let queue_infos =
            [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let mut create_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_infos)
            .enabled_features(&enabled)
            .enabled_extension_names(&extensions);
        if info.api_version >= vk::API_VERSION_1_3 {
            create_info = create_info.push_next(&mut features13);
        }
        if ray_query {
            create_info = create_info.push_next(&mut features12).push_next(&mut acceleration).push_next(&mut query);
        }
        // SAFETY: the create info and everything it points to outlive the call.
        let device = match unsafe { instance.create_device(physical_device, &create_info, None) } {
            Ok(d) => d,
            Err(result) => return Err((Error::Vulkan { what: "vkCreateDevice", result }, debug)),
        };
        // SAFETY: queue 0 of a family requested above.
        let queue = unsafe { device.get_device_queue(queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: ray_query,
            allocation_sizes: Default::default(),
        });
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid device and create info.
        let pool = unsafe { device.create_command_pool(&pool_info, None) };
        let (allocator, pool) = match (allocator, pool) {
            (Ok(a), Ok(p)) => (a, p),
            (a, p) => {
                let err = match (a.err(), p.err()) {
                    (Some(e), _) => Error::Allocation(e),
                    (None, Some(result)) => Error::Vulkan { what: "vkCreateCommandPool", result },
                    _ => unreachable!(),
                };
                // SAFETY: nothing else was created on this device... except possibly
                // the pool; it is destroyed with the device.
                unsafe { device.destroy_device(None) };
                return Err((err, debug));
            }
        };

        let ray_query = ray_query.then(|| ray_query_device(&instance, physical_device, &device));
        Ok(GpuContext {
            _entry: Some(entry),
            instance,
            physical_device,
            device,
            queue,
            queue_family,
            info,
            owned: true,
            allocator: ManuallyDrop::new(Arc::new(Mutex::new(allocator))),
            queue_lock: Arc::default(),
            command_pool: Mutex::new(pool),
            debug,
            drew: Default::default(),
            pipeline_cache: Default::default(),
            ray_query,
        })
    }

    /// Runs kdtrace on an engine's own instance, device, queue and allocator
    /// (see [`AdoptDesc`]). Nothing of the engine's is created or destroyed here:
    /// the context makes one command pool on `queue_family` and destroys it when
    /// dropped. Validation messages are the engine's to collect (its own debug
    /// messenger); [`GpuContext::validation_enabled`] is false.
    ///
    /// Errors: `Error::DeviceLimit` naming what is missing when the device is older
    /// than Vulkan 1.2, `queue_family` has no compute support, or a feature of
    /// [`required_features`] is unsupported or was not enabled.
    ///
    /// # Safety
    /// Every handle in `desc` must be valid and belong together (the device was
    /// created from `physical_device` of `instance` with `desc.enabled_features`;
    /// `queue` is a queue of `queue_family` of `device`; the allocator was created
    /// for that device), and the instance, device and allocator must outlive the
    /// returned context and everything created from it (tracers, buffers,
    /// kernels): drop those first, then destroy your device. The queue must be
    /// externally synchronised as [`AdoptDesc::queue_lock`] describes.
    pub unsafe fn adopt(desc: AdoptDesc) -> Result<Arc<GpuContext>> {
        let AdoptDesc {
            instance,
            physical_device,
            device,
            queue_family,
            queue,
            queue_lock,
            allocator,
            enabled_features,
            subgroup_size_control,
            ray_query,
        } = desc;
        // SAFETY: the caller vouches that `physical_device` belongs to `instance`.
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let mut info = describe(&instance, physical_device, queue_family);
        if info.api_version < vk::API_VERSION_1_2 {
            return Err(Error::DeviceLimit(format!(
                "{} supports Vulkan {}.{}; kdtrace's kernels need Vulkan 1.2",
                info.name,
                vk::api_version_major(info.api_version),
                vk::api_version_minor(info.api_version)
            )));
        }
        match families.get(queue_family as usize) {
            Some(f) if f.queue_flags.contains(vk::QueueFlags::COMPUTE) => {}
            Some(f) => {
                return Err(Error::DeviceLimit(format!(
                    "queue family {queue_family} of {} has no compute support ({:?})",
                    info.name, f.queue_flags
                )))
            }
            None => {
                return Err(Error::InvalidInput(format!(
                    "queue family {queue_family} does not exist on {} ({} families)",
                    info.name,
                    families.len()
                )))
            }
        }
        // No core feature is required today (required_features); enabled_features
        // stays in AdoptDesc so that a later requirement can be checked here.
        let _ = enabled_features;
        if ray_query && !info.ray_query_missing.is_empty() {
            return Err(Error::DeviceLimit(format!(
                "AdoptDesc::ray_query is set, but {} lacks {}",
                info.name,
                info.ray_query_missing.join(", ")
            )));
        }
        // Size control counts only when the engine enabled it as well.
        if !subgroup_size_control {
            info.subgroup_size_control = false;
            info.min_subgroup_size = info.subgroup_size;
            info.max_subgroup_size = info.subgroup_size;
        }
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(queue_family)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: a valid create info on the caller's live device.
        let pool = unsafe { device.create_command_pool(&pool_info, None) }.vk("vkCreateCommandPool")?;
        let ray_query = ray_query.then(|| ray_query_device(&instance, physical_device, &device));
        Ok(Arc::new(GpuContext {
            _entry: None,
            instance,
            physical_device,
            device,
            queue,
            queue_family,
            info,
            owned: false,
            allocator: ManuallyDrop::new(allocator),
            queue_lock: queue_lock.unwrap_or_default(),
            command_pool: Mutex::new(pool),
            debug: None,
            drew: Default::default(),
            pipeline_cache: Default::default(),
            ray_query,
        }))
    }

    /// True when GPU timestamps of this context cannot be trusted: on lavapipe,
    /// once a draw has run, later timestamps no longer advance with the work
    /// (docs/RENDERING.md). Timing code reports no GPU time then.
    pub fn timestamps_unreliable(&self) -> bool {
        self.drew.load(std::sync::atomic::Ordering::Relaxed) && self.info.name.contains("llvmpipe")
    }

    /// Notes that a draw was recorded (see [`GpuContext::timestamps_unreliable`]).
    pub(crate) fn note_draw(&self) {
        self.drew.store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// True when the instance, device and allocator belong to an engine
    /// ([`GpuContext::adopt`]); false for a headless context.
    pub fn is_adopted(&self) -> bool {
        !self.owned
    }

    /// True when the ray-query backend's extensions and features are enabled on
    /// this context's device: [`ContextOptions::ray_query`] for a headless
    /// context, [`AdoptDesc::ray_query`] for an adopted one.
    pub fn ray_query_enabled(&self) -> bool {
        self.ray_query.is_some()
    }

    /// The ray-query backend's functions, or `Error::DeviceLimit` naming what the
    /// device lacks (or that an adopted device was not created with it).
    pub(crate) fn ray_query(&self) -> Result<&RayQueryDevice> {
        if let Some(rq) = &self.ray_query {
            return Ok(rq);
        }
        let info = &self.info;
        Err(Error::DeviceLimit(if info.ray_query_missing.is_empty() {
            format!(
                "the ray-query backend needs {} with accelerationStructure, rayQuery and bufferDeviceAddress \
                 enabled: {} has them, but this context was created without them \
                 (ContextOptions::ray_query, or AdoptDesc::ray_query for an adopted device)",
                extension_names(),
                info.name
            )
        } else {
            ray_query_lacking(info)
        }))
    }

    /// The mutex kdtrace holds around each submission to [`GpuContext::queue`];
    /// hold it around your own submissions to that queue from other threads.
    pub fn queue_lock(&self) -> &Arc<Mutex<()>> {
        &self.queue_lock
    }

    /// The allocator shared by every buffer on this device.
    pub fn allocator(&self) -> &Arc<Mutex<Allocator>> {
        &self.allocator
    }

    /// True when validation messages are being collected.
    pub fn validation_enabled(&self) -> bool {
        self.debug.is_some()
    }

    /// Takes the validation messages reported so far.
    pub fn take_validation_messages(&self) -> Vec<String> {
        match &self.debug {
            Some(d) => std::mem::take(&mut *d.messages.lock().unwrap_or_else(|p| p.into_inner())),
            None => Vec::new(),
        }
    }

    /// Fails with `Error::Validation` when the layer reported anything.
    pub fn check_validation(&self) -> Result<()> {
        let messages = self.take_validation_messages();
        if messages.is_empty() {
            Ok(())
        } else {
            Err(Error::Validation(messages))
        }
    }

    /// Records a barrier that makes compute-shader and transfer writes before it
    /// visible to host reads after the submission completes (readbacks).
    ///
    /// # Safety
    /// `cmd` must be a command buffer of this device in the recording state.
    pub unsafe fn record_host_read_barrier(&self, cmd: vk::CommandBuffer) {
        let barrier = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        // SAFETY: the caller's contract: `cmd` is recording on this device.
        self.device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        );
    }

    /// Records commands with `record` into a one-time command buffer, submits it
    /// on the context's queue and waits for it.
    pub fn submit_and_wait(&self, record: impl FnOnce(vk::CommandBuffer)) -> Result<()> {
        let pool = self.command_pool.lock().unwrap_or_else(|p| p.into_inner());
        let alloc_info = vk::CommandBufferAllocateInfo::default()
            .command_pool(*pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool is externally synchronised by the mutex held above.
        let cmd = unsafe { self.device.allocate_command_buffers(&alloc_info) }.vk("vkAllocateCommandBuffers")?[0];
        let result = (|| {
            let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            // SAFETY: a freshly allocated command buffer.
            unsafe { self.device.begin_command_buffer(cmd, &begin) }.vk("vkBeginCommandBuffer")?;
            record(cmd);
            // SAFETY: recording was begun above.
            unsafe { self.device.end_command_buffer(cmd) }.vk("vkEndCommandBuffer")?;
            // SAFETY: a plain fence.
            let fence =
                unsafe { self.device.create_fence(&vk::FenceCreateInfo::default(), None) }.vk("vkCreateFence")?;
            let cmds = [cmd];
            let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
            let submitted = {
                let _queue = self.queue_lock.lock().unwrap_or_else(|p| p.into_inner());
                // SAFETY: the queue is externally synchronised by `queue_lock`.
                unsafe { self.device.queue_submit(self.queue, &submit, fence) }.vk("vkQueueSubmit")
            };
            let waited = submitted.and_then(|_| {
                // SAFETY: waiting on a fence of this device.
                unsafe { self.device.wait_for_fences(&[fence], true, u64::MAX) }.vk("vkWaitForFences")
            });
            // SAFETY: the fence is no longer in use (waited, or never submitted).
            unsafe { self.device.destroy_fence(fence, None) };
            waited
        })();
        // SAFETY: the command buffer finished (or never ran); the pool is locked.
        unsafe { self.device.free_command_buffers(*pool, &[cmd]) };
        result
    }
}

impl Drop for GpuContext {
    fn drop(&mut self) {
        {
            let mut slot = std::mem::take(self.pipeline_cache.get_mut().unwrap_or_else(|p| p.into_inner()));
            self.release_cache(&mut slot);
        }
        if !self.owned {
            // SAFETY: every object made from this context holds an `Arc` to it, so
            // none is alive now, and every submission from the pool was waited for.
            // The engine's device, queue and allocator are left alone (only this
            // context's clone of the allocator's `Arc` is released).
            unsafe {
                let pool = *self.command_pool.get_mut().unwrap_or_else(|p| p.into_inner());
                self.device.destroy_command_pool(pool, None);
                ManuallyDrop::drop(&mut self.allocator);
            }
            return;
        }
        // SAFETY: every object made from this context holds an `Arc` to it, so
        // none is alive now; destroy in reverse order of creation.
        unsafe {
            let _ = self.device.device_wait_idle();
            let pool = *self.command_pool.get_mut().unwrap_or_else(|p| p.into_inner());
            self.device.destroy_command_pool(pool, None);
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some(d) = &self.debug {
                let left = d.messages.lock().map(|m| m.len()).unwrap_or(0);
                if left > 0 {
                    eprintln!("kdtrace: {left} validation message(s) were not checked before the context was dropped");
                }
                d.loader.destroy_debug_utils_messenger(d.messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}
