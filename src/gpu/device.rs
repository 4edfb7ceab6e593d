//! Finding and describing devices: [`DeviceInfo`], [`list_devices`], the
//! features and extensions kdtrace needs, and the device pick of a headless
//! context.

use std::ffi::CStr;

use ash::vk;

use crate::error::{Error, Result, VkContext};

use super::ContextOptions;

/// What the library needs to know about the device.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// `VkPhysicalDeviceProperties::deviceName`.
    pub name: String,
    /// Driver name and version string (`VkPhysicalDeviceDriverProperties`).
    pub driver: String,
    /// Discrete, integrated, virtual or CPU (lavapipe).
    pub device_type: vk::PhysicalDeviceType,
    /// The device's Vulkan version (`vk::make_api_version` encoding).
    pub api_version: u32,
    /// The default subgroup size.
    pub subgroup_size: u32,
    /// Smallest subgroup size a kernel may require (= `subgroup_size` without size control).
    pub min_subgroup_size: u32,
    /// Largest subgroup size a kernel may require (= `subgroup_size` without size control).
    pub max_subgroup_size: u32,
    /// Whether `subgroupSizeControl` and `computeFullSubgroups` are enabled on the
    /// device, so that a kernel may require a subgroup size.
    pub subgroup_size_control: bool,
    /// Subgroup operations supported in compute shaders (empty when the compute
    /// stage has no subgroup support).
    pub subgroup_operations: vk::SubgroupFeatureFlags,
    /// `maxStorageBufferRange`: the largest range one storage-buffer descriptor may bind.
    pub max_storage_buffer_range: u64,
    /// `minStorageBufferOffsetAlignment`: storage-buffer descriptor offsets must be multiples of it.
    pub min_storage_buffer_offset_alignment: u64,
    /// `maxTexelBufferElements`: the most texels one texel-buffer view may address.
    pub max_texel_buffer_elements: u64,
    /// `maxComputeWorkGroupCount[0]`.
    pub max_workgroup_count_x: u32,
    /// `maxMemoryAllocationSize` (Vulkan 1.1 maintenance3).
    pub max_memory_allocation_size: u64,
    /// Nanoseconds per timestamp tick; `None` when the queue has no timestamps.
    pub timestamp_period_ns: Option<f64>,
    /// What the device lacks of the ray-query backend's extensions and features
    /// ([`RAY_QUERY_EXTENSIONS`], `accelerationStructure`, `rayQuery`,
    /// `bufferDeviceAddress`); empty when it has them all.
    pub ray_query_missing: Vec<String>,
}

impl std::fmt::Display for DeviceInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({:?}, {}, Vulkan {}.{}.{}, subgroup {} [{}..{}])",
            self.name,
            self.device_type,
            self.driver,
            vk::api_version_major(self.api_version),
            vk::api_version_minor(self.api_version),
            vk::api_version_patch(self.api_version),
            self.subgroup_size,
            self.min_subgroup_size,
            self.max_subgroup_size
        )
    }
}

/// The core device features kdtrace's kernels need: none. The exact fallback of
/// the watertight triangle test (Woop, Benthin & Wald 2013) runs in float-float
/// arithmetic on f32 (`glsl/shared/ff.glsl`), and no kernel declares the
/// `Float64` or `Int64` capability (a test reads every SPIR-V module), so
/// devices without `shaderFloat64` or `shaderInt64` (MoltenVK, many mobile and
/// integrated GPUs) run every kernel. Kept as a function so that an engine can
/// OR it into the features it enables, should a later version need one.
pub fn required_features() -> vk::PhysicalDeviceFeatures {
    vk::PhysicalDeviceFeatures::default()
}

/// The device extensions of the ray-query backend: acceleration structures, ray
/// queries in compute shaders, and the deferred host operations that
/// `VK_KHR_acceleration_structure` requires. With them the backend needs the
/// features `accelerationStructure`, `rayQuery` and `bufferDeviceAddress`.
pub const RAY_QUERY_EXTENSIONS: [&CStr; 3] =
    [ash::khr::acceleration_structure::NAME, ash::khr::ray_query::NAME, ash::khr::deferred_host_operations::NAME];

/// The acceleration-structure functions and limits of a context whose device has
/// the ray-query backend enabled.
pub(crate) struct RayQueryDevice {
    /// `VK_KHR_acceleration_structure`'s device functions.
    pub loader: ash::khr::acceleration_structure::Device,
    /// `minAccelerationStructureScratchOffsetAlignment`.
    pub scratch_alignment: u64,
    /// `maxPrimitiveCount`: the most triangles one bottom-level structure may hold.
    pub max_primitive_count: u64,
}

pub(super) fn device_type_rank(t: vk::PhysicalDeviceType) -> u32 {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => 0,
        vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
        vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
        vk::PhysicalDeviceType::CPU => 3,
        _ => 4,
    }
}

/// Lists the devices with a compute queue: (index, name, type).
pub fn list_devices() -> Result<Vec<DeviceInfo>> {
    // SAFETY: loading the system loader; a throwaway instance with no layers.
    unsafe {
        let entry = ash::Entry::load().map_err(|e| Error::Loader(e.to_string()))?;
        let app_info = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
        let instance = entry
            .create_instance(&vk::InstanceCreateInfo::default().application_info(&app_info), None)
            .vk("vkCreateInstance")?;
        let result = instance.enumerate_physical_devices().vk("vkEnumeratePhysicalDevices").map(|devices| {
            devices
                .into_iter()
                .filter_map(|pd| compute_family(&instance, pd).map(|q| describe(&instance, pd, q)))
                .collect()
        });
        instance.destroy_instance(None);
        result
    }
}

pub(super) fn compute_family(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Option<u32> {
    // SAFETY: `pd` came from `instance`.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    families.iter().position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE)).map(|i| i as u32)
}

/// The device's properties as seen from queue family `family` (its timestamps).
pub(super) fn describe(instance: &ash::Instance, pd: vk::PhysicalDevice, family: u32) -> DeviceInfo {
    let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
    let mut size_control = vk::PhysicalDeviceSubgroupSizeControlProperties::default();
    let mut driver = vk::PhysicalDeviceDriverProperties::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut subgroup).push_next(&mut driver);
    // SAFETY: `pd` came from `instance`; the chained structs live on this frame.
    let base = unsafe { instance.get_physical_device_properties(pd) };
    let has_13 = base.api_version >= vk::API_VERSION_1_3;
    if has_13 {
        props2 = props2.push_next(&mut size_control);
    }
    // SAFETY: as above.
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    let props = props2.properties;
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f13);
    if has_13 {
        // SAFETY: as above.
        unsafe { instance.get_physical_device_features2(pd, &mut f2) };
    }
    let mut maint3 = vk::PhysicalDeviceMaintenance3Properties::default();
    let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut maint3);
    // SAFETY: as above.
    unsafe { instance.get_physical_device_properties2(pd, &mut p2) };
    // SAFETY: as above.
    let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
    let has_timestamps = families.get(family as usize).is_some_and(|f| f.timestamp_valid_bits > 0);
    let control = has_13 && f13.subgroup_size_control != 0 && f13.compute_full_subgroups != 0;
    DeviceInfo {
        name: props.device_name_as_c_str().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
        driver: format!(
            "{} {}",
            driver.driver_name_as_c_str().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
            driver.driver_info_as_c_str().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
        ),
        device_type: props.device_type,
        api_version: props.api_version,
        subgroup_size: subgroup.subgroup_size,
        min_subgroup_size: if control { size_control.min_subgroup_size } else { subgroup.subgroup_size },
        max_subgroup_size: if control { size_control.max_subgroup_size } else { subgroup.subgroup_size },
        subgroup_size_control: control,
        subgroup_operations: if subgroup.supported_stages.contains(vk::ShaderStageFlags::COMPUTE) {
            subgroup.supported_operations
        } else {
            vk::SubgroupFeatureFlags::empty()
        },
        max_storage_buffer_range: props.limits.max_storage_buffer_range as u64,
        max_texel_buffer_elements: props.limits.max_texel_buffer_elements as u64,
        min_storage_buffer_offset_alignment: props.limits.min_storage_buffer_offset_alignment.max(1),
        max_workgroup_count_x: props.limits.max_compute_work_group_count[0],
        max_memory_allocation_size: maint3.max_memory_allocation_size,
        timestamp_period_ns: (has_timestamps && props.limits.timestamp_compute_and_graphics != 0)
            .then_some(props.limits.timestamp_period as f64),
        ray_query_missing: ray_query_missing(instance, pd, props.api_version),
    }
}

/// The error message for a device without the ray-query backend: what it lacks.
pub(super) fn ray_query_lacking(info: &DeviceInfo) -> String {
    format!(
        "{} ({}) lacks {}, which the ray-query backend needs (lavapipe has them from Mesa 24 on; \
         on Debian 12, tools/setup installs Mesa from bookworm-backports)",
        info.name,
        info.driver,
        info.ray_query_missing.join(", ")
    )
}

/// The ray-query extensions as one list, for messages.
pub(super) fn extension_names() -> String {
    RAY_QUERY_EXTENSIONS.iter().map(|e| e.to_string_lossy()).collect::<Vec<_>>().join(", ")
}

/// What `pd` lacks of the ray-query backend: missing extensions, or else features.
pub(super) fn ray_query_missing(instance: &ash::Instance, pd: vk::PhysicalDevice, api_version: u32) -> Vec<String> {
    // SAFETY: `pd` came from `instance`.
    let available = unsafe { instance.enumerate_device_extension_properties(pd) }.unwrap_or_default();
    let missing: Vec<String> = RAY_QUERY_EXTENSIONS
        .iter()
        .filter(|want| !available.iter().any(|e| e.extension_name_as_c_str() == Ok(**want)))
        .map(|e| e.to_string_lossy().into_owned())
        .collect();
    if !missing.is_empty() || api_version < vk::API_VERSION_1_2 {
        return missing;
    }
    // The extensions are there, so their feature structs may be queried.
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut acceleration = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
    let mut query = vk::PhysicalDeviceRayQueryFeaturesKHR::default();
    let mut f2 =
        vk::PhysicalDeviceFeatures2::default().push_next(&mut f12).push_next(&mut acceleration).push_next(&mut query);
    // SAFETY: as above; the chained structs live on this frame.
    unsafe { instance.get_physical_device_features2(pd, &mut f2) };
    [
        ("bufferDeviceAddress", f12.buffer_device_address),
        ("accelerationStructure", acceleration.acceleration_structure),
        ("rayQuery", query.ray_query),
    ]
    .iter()
    .filter(|(_, on)| *on == vk::FALSE)
    .map(|(name, _)| name.to_string())
    .collect()
}

/// The acceleration-structure functions and limits of `device`, created with the
/// ray-query extensions from `pd`.
pub(super) fn ray_query_device(
    instance: &ash::Instance,
    pd: vk::PhysicalDevice,
    device: &ash::Device,
) -> RayQueryDevice {
    let mut props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
    let mut props2 = vk::PhysicalDeviceProperties2::default().push_next(&mut props);
    // SAFETY: `pd` came from `instance` and has the extension; the struct lives on this frame.
    unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
    RayQueryDevice {
        loader: ash::khr::acceleration_structure::Device::new(instance, device),
        scratch_alignment: u64::from(props.min_acceleration_structure_scratch_offset_alignment).max(1),
        max_primitive_count: props.max_primitive_count,
    }
}

pub(super) fn pick_device(
    instance: &ash::Instance,
    options: &ContextOptions,
) -> Result<(vk::PhysicalDevice, u32, DeviceInfo)> {
    // SAFETY: plain query on a live instance.
    let devices = unsafe { instance.enumerate_physical_devices() }.vk("vkEnumeratePhysicalDevices")?;
    let mut candidates: Vec<(usize, vk::PhysicalDevice, u32, DeviceInfo)> = devices
        .into_iter()
        .enumerate()
        .filter_map(|(i, pd)| compute_family(instance, pd).map(|q| (i, pd, q, describe(instance, pd, q))))
        .filter(|(_, _, _, info)| info.api_version >= vk::API_VERSION_1_2)
        .collect();
    if candidates.is_empty() {
        return Err(Error::NoDevice(
            "no Vulkan 1.2 device with a compute queue (install mesa-vulkan-drivers for lavapipe)".into(),
        ));
    }
    let names = || candidates.iter().map(|c| format!("{}: {}", c.0, c.3.name)).collect::<Vec<_>>().join(", ");
    let chosen = match &options.device {
        Some(want) => {
            let by_index = want.parse::<usize>().ok().and_then(|i| candidates.iter().position(|c| c.0 == i));
            let by_name = || {
                let w = want.to_lowercase();
                candidates.iter().position(|c| c.3.name.to_lowercase().contains(&w))
            };
            by_index
                .or_else(by_name)
                .ok_or_else(|| Error::NoDevice(format!("KDTRACE_DEVICE={want} matches none of [{}]", names())))?
        }
        None => {
            candidates.sort_by_key(|c| (device_type_rank(c.3.device_type), c.0));
            0
        }
    };
    let (_, pd, q, info) = candidates.swap_remove(chosen);
    Ok((pd, q, info))
}
