//! Compute kernels: a pipeline over N storage-buffer bindings with push constants
//! and specialization constants, plus GPU timestamps.

use std::sync::Arc;

use ash::vk;

use super::{Buffer, BufferRange, GpuContext};
use crate::error::{Error, Result, VkContext};

/// A compute pipeline whose set 0 holds storage buffers at bindings `0..bindings`.
/// Dropping it destroys the pipeline and its layouts (no pending work may use them).
pub struct Kernel {
    /// The compute pipeline (created with `DISPATCH_BASE`, see [`Kernel::record_dispatch`]).
    pub pipeline: vk::Pipeline,
    /// Its layout: set 0 plus the push-constant range.
    pub layout: vk::PipelineLayout,
    /// The layout of set 0: storage buffers at bindings `0..bindings`.
    pub set_layout: vk::DescriptorSetLayout,
    /// Number of bindings of set 0 (storage buffers, except `texel_buffers`).
    pub bindings: u32,
    /// Bindings that are storage texel buffers, with their view formats.
    pub texel_buffers: Vec<(u32, vk::Format)>,
    /// Bindings that are acceleration structures (ray queries).
    pub acceleration_structures: Vec<u32>,
    /// Bytes of push constants (0: none).
    pub push_constant_size: u32,
    /// The kernel's `local_size_x`.
    pub workgroup_size: u32,
    ctx: Arc<GpuContext>,
}

/// How to specialize a kernel.
#[derive(Clone, Debug, Default)]
pub struct KernelDesc<'a> {
    /// A name for error messages.
    pub name: &'a str,
    /// The SPIR-V words as bytes (e.g. a constant of [`super::shaders`]).
    pub spirv: &'a [u8],
    /// Storage-buffer bindings of set 0.
    pub bindings: u32,
    /// Bytes of push constants.
    pub push_constant_size: u32,
    /// Specialization constants with ids 0, 1, 2, ... (32-bit each; bools as 0/1).
    pub spec_constants: &'a [u32],
    /// The kernel's `local_size_x`, so `dispatch` can take thread counts.
    pub workgroup_size: u32,
    /// A required subgroup size (`VK_EXT_subgroup_size_control`, full subgroups).
    pub required_subgroup_size: Option<u32>,
    /// Subgroup operations the kernel uses; a device without them in compute
    /// shaders gets `Error::DeviceLimit` naming the missing ones.
    pub required_subgroup_operations: vk::SubgroupFeatureFlags,
    /// Bindings that are storage texel buffers (read-only `uimageBuffer` etc.) instead of
    /// storage buffers, with the format of the view a [`BufferSet`] makes for them.
    pub texel_buffers: &'a [(u32, vk::Format)],
    /// Bindings that are acceleration structures (`accelerationStructureEXT` of
    /// ray queries: the device needs the ray-query backend enabled), bound by
    /// [`BufferSet::from_bindings`] with [`Binding::AccelerationStructure`].
    pub acceleration_structures: &'a [u32],
}

impl Kernel {
    /// Creates the pipeline, checking the device supports what `desc` requires.
    pub fn new(ctx: &Arc<GpuContext>, desc: &KernelDesc) -> Result<Kernel> {
        let device = &ctx.device;
        let code = ash::util::read_spv(&mut std::io::Cursor::new(desc.spirv))
            .map_err(|e| Error::InvalidInput(format!("kernel {}: bad SPIR-V: {e}", desc.name)))?;
        if let Some((b, _)) = desc.texel_buffers.iter().find(|(b, _)| *b >= desc.bindings) {
            return Err(Error::InvalidInput(format!(
                "kernel {}: texel-buffer binding {b} is not below its {} bindings",
                desc.name, desc.bindings
            )));
        }
        if let Some(b) = desc.acceleration_structures.iter().find(|&&b| b >= desc.bindings) {
            return Err(Error::InvalidInput(format!(
                "kernel {}: acceleration-structure binding {b} is not below its {} bindings",
                desc.name, desc.bindings
            )));
        }
        if !desc.acceleration_structures.is_empty() {
            ctx.ray_query()?;
        }
        let bindings: Vec<vk::DescriptorSetLayoutBinding> = (0..desc.bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(descriptor_type(desc.texel_buffers, desc.acceleration_structures, b))
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        if let Some(size) = desc.required_subgroup_size {
            let info = &ctx.info;
            if !info.subgroup_size_control || size < info.min_subgroup_size || size > info.max_subgroup_size {
                return Err(Error::DeviceLimit(format!(
                    "subgroup size {size} is not available on {} (allowed: {}..{}, control: {})",
                    info.name, info.min_subgroup_size, info.max_subgroup_size, info.subgroup_size_control
                )));
            }
        }

        let missing = desc.required_subgroup_operations & !ctx.info.subgroup_operations;
        if !missing.is_empty() {
            return Err(Error::DeviceLimit(format!(
                "kernel {} needs subgroup operations {missing:?} in compute shaders, which {} lacks (it has {:?})",
                desc.name, ctx.info.name, ctx.info.subgroup_operations
            )));
        }

        // SAFETY: valid create infos on a live device; every object created here is
        // destroyed in `Drop` or on the error paths below.
        unsafe {
            let module = device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
                .vk("vkCreateShaderModule")?;
            let set_layout = device
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings), None)
                .vk("vkCreateDescriptorSetLayout");
            let set_layout = match set_layout {
                Ok(s) => s,
                Err(e) => {
                    device.destroy_shader_module(module, None);
                    return Err(e);
                }
            };
            let push_ranges = [vk::PushConstantRange::default()
                .stage_flags(vk::ShaderStageFlags::COMPUTE)
                .offset(0)
                .size(desc.push_constant_size)];
            let set_layouts = [set_layout];
            let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
            if desc.push_constant_size > 0 {
                layout_info = layout_info.push_constant_ranges(&push_ranges);
            }
            let layout = match device.create_pipeline_layout(&layout_info, None).vk("vkCreatePipelineLayout") {
                Ok(l) => l,
                Err(e) => {
                    device.destroy_descriptor_set_layout(set_layout, None);
                    device.destroy_shader_module(module, None);
                    return Err(e);
                }
            };
            let entries: Vec<vk::SpecializationMapEntry> = (0..desc.spec_constants.len())
                .map(|i| vk::SpecializationMapEntry {
                    constant_id: i as u32,
                    offset: (i * std::mem::size_of::<u32>()) as u32,
                    size: std::mem::size_of::<u32>(),
                })
                .collect();
            let data: &[u8] = bytemuck::cast_slice(desc.spec_constants);
            let spec = vk::SpecializationInfo::default().map_entries(&entries).data(data);
            let mut subgroup = vk::PipelineShaderStageRequiredSubgroupSizeCreateInfo::default()
                .required_subgroup_size(desc.required_subgroup_size.unwrap_or(0));
            let mut stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main")
                .specialization_info(&spec);
            if desc.required_subgroup_size.is_some() {
                stage =
                    stage.push_next(&mut subgroup).flags(vk::PipelineShaderStageCreateFlags::REQUIRE_FULL_SUBGROUPS);
            }
            let info = [vk::ComputePipelineCreateInfo::default()
                .flags(vk::PipelineCreateFlags::DISPATCH_BASE)
                .stage(stage)
                .layout(layout)];
            let pipeline = device.create_compute_pipelines(ctx.pipeline_cache(), &info, None);
            device.destroy_shader_module(module, None);
            let pipeline = match pipeline {
                Ok(p) => p[0],
                Err((_, result)) => {
                    device.destroy_pipeline_layout(layout, None);
                    device.destroy_descriptor_set_layout(set_layout, None);
                    return Err(Error::Vulkan { what: "vkCreateComputePipelines", result });
                }
            };
            Ok(Kernel {
                pipeline,
                layout,
                set_layout,
                bindings: desc.bindings,
                texel_buffers: desc.texel_buffers.to_vec(),
                acceleration_structures: desc.acceleration_structures.to_vec(),
                push_constant_size: desc.push_constant_size,
                workgroup_size: desc.workgroup_size.max(1),
                ctx: ctx.clone(),
            })
        }
    }

    /// Records a dispatch of `threads` invocations (rounded up to whole workgroups):
    /// binds the pipeline, `set` as set 0 and the push constants, then dispatches.
    /// More workgroups than `maxComputeWorkGroupCount[0]` go in several
    /// `vkCmdDispatchBase` calls, so `gl_GlobalInvocationID.x` still runs over
    /// `0..threads`.
    ///
    /// # Safety
    /// `cmd` must be recording, and `set` must be a descriptor set of this kernel's
    /// layout whose buffers stay alive until the command buffer completes.
    pub unsafe fn record_dispatch(&self, cmd: vk::CommandBuffer, set: vk::DescriptorSet, push: &[u8], threads: u32) {
        let device = &self.ctx.device;
        self.record_bind(cmd, set, push);
        let groups = threads.div_ceil(self.workgroup_size);
        let max = self.ctx.info.max_workgroup_count_x.max(1);
        if groups <= max {
            device.cmd_dispatch(cmd, groups, 1, 1);
        } else {
            let mut base = 0;
            while base < groups {
                let count = (groups - base).min(max);
                device.cmd_dispatch_base(cmd, base, 0, 0, count, 1, 1);
                base += count;
            }
        }
    }

    /// Records an indirect dispatch whose workgroup counts the GPU reads from
    /// `args` at `offset` (`VkDispatchIndirectCommand`): binds the pipeline, `set`
    /// as set 0 and the push constants, then dispatches.
    ///
    /// # Safety
    /// As [`Kernel::record_dispatch`]; `args` must be a live buffer with
    /// `INDIRECT_BUFFER` usage holding the three counts at `offset` when the
    /// dispatch runs (made visible to `DRAW_INDIRECT`/`INDIRECT_COMMAND_READ`), and
    /// each count at most the device's `maxComputeWorkGroupCount`.
    pub unsafe fn record_dispatch_indirect(
        &self,
        cmd: vk::CommandBuffer,
        set: vk::DescriptorSet,
        push: &[u8],
        args: vk::Buffer,
        offset: u64,
    ) {
        self.record_bind(cmd, set, push);
        self.ctx.device.cmd_dispatch_indirect(cmd, args, offset);
    }

    /// Binds the pipeline, `set` as set 0 and the push constants in `cmd`.
    unsafe fn record_bind(&self, cmd: vk::CommandBuffer, set: vk::DescriptorSet, push: &[u8]) {
        let device = &self.ctx.device;
        device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::COMPUTE, self.pipeline);
        device.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::COMPUTE, self.layout, 0, &[set], &[]);
        if !push.is_empty() {
            device.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
        }
    }
}

impl Drop for Kernel {
    fn drop(&mut self) {
        // SAFETY: no pending work uses the pipeline (submissions wait).
        unsafe {
            self.ctx.device.destroy_pipeline(self.pipeline, None);
            self.ctx.device.destroy_pipeline_layout(self.layout, None);
            self.ctx.device.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// The descriptor type of `binding`: a storage texel buffer when `texel_buffers`
/// names it, an acceleration structure when `structures` does, else a storage buffer.
fn descriptor_type(texel_buffers: &[(u32, vk::Format)], structures: &[u32], binding: u32) -> vk::DescriptorType {
    if texel_buffers.iter().any(|(b, _)| *b == binding) {
        vk::DescriptorType::STORAGE_TEXEL_BUFFER
    } else if structures.contains(&binding) {
        vk::DescriptorType::ACCELERATION_STRUCTURE_KHR
    } else {
        vk::DescriptorType::STORAGE_BUFFER
    }
}

/// What one binding of a [`BufferSet`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Binding {
    /// A storage or texel buffer range.
    Buffer(BufferRange),
    /// A (top-level) acceleration structure, for the kernel's
    /// [`KernelDesc::acceleration_structures`] bindings.
    AccelerationStructure(vk::AccelerationStructureKHR),
}

/// Bytes per texel of the view formats kernels use.
fn texel_bytes(format: vk::Format) -> Option<u64> {
    match format {
        vk::Format::R32_UINT | vk::Format::R32_SFLOAT => Some(4),
        vk::Format::R32G32_UINT | vk::Format::R32G32_SFLOAT => Some(8),
        vk::Format::R32G32B32A32_UINT | vk::Format::R32G32B32A32_SFLOAT => Some(16),
        _ => None,
    }
}

/// A descriptor pool holding one set of storage buffers. Dropping it destroys the
/// pool and the set, so it must outlive every command buffer that uses the set.
pub struct BufferSet {
    /// The descriptor set (set 0 of the kernel it was made for).
    pub set: vk::DescriptorSet,
    pool: vk::DescriptorPool,
    /// Views of the kernel's texel-buffer bindings.
    views: Vec<vk::BufferView>,
    ctx: Arc<GpuContext>,
}

impl BufferSet {
    /// A set for `kernel` with `buffers[i]` bound (whole) at binding `i`.
    pub fn new(ctx: &Arc<GpuContext>, kernel: &Kernel, buffers: &[&Buffer]) -> Result<BufferSet> {
        let ranges: Vec<BufferRange> = buffers.iter().map(|b| BufferRange::whole(b)).collect();
        // SAFETY: kdtrace buffers are live storage buffers of this device, and the
        // ranges cover exactly their sizes.
        unsafe { Self::from_ranges(ctx, kernel, &ranges) }
    }

    /// A set for `kernel` with `ranges[i]` bound at binding `i`. Errors: a wrong
    /// number of ranges, an empty range, an offset that is not a multiple of
    /// `minStorageBufferOffsetAlignment`, a range beyond `maxStorageBufferRange`.
    ///
    /// # Safety
    /// Each range's buffer must be a live buffer of this device created with
    /// `STORAGE_BUFFER` usage (`STORAGE_TEXEL_BUFFER` for the kernel's texel-buffer
    /// bindings) and at least `offset + range` bytes, bound to memory,
    /// and stay alive while the set is used by any command buffer.
    pub unsafe fn from_ranges(ctx: &Arc<GpuContext>, kernel: &Kernel, ranges: &[BufferRange]) -> Result<BufferSet> {
        let bindings: Vec<Binding> = ranges.iter().map(|&r| Binding::Buffer(r)).collect();
        // SAFETY: forwarded from the caller.
        unsafe { Self::from_bindings(ctx, kernel, &bindings) }
    }

    /// A set for `kernel` with `bindings[i]` bound at binding `i`: buffer ranges
    /// (checked as [`BufferSet::from_ranges`] checks them) and, at the kernel's
    /// acceleration-structure bindings, acceleration structures.
    ///
    /// # Safety
    /// As [`BufferSet::from_ranges`] for the ranges; each acceleration structure
    /// must be a live top-level acceleration structure of this device, built
    /// before the set is used and alive while any command buffer uses the set.
    pub unsafe fn from_bindings(ctx: &Arc<GpuContext>, kernel: &Kernel, bindings: &[Binding]) -> Result<BufferSet> {
        if bindings.len() as u32 != kernel.bindings {
            return Err(Error::InvalidInput(format!(
                "kernel has {} bindings, {} buffers given",
                kernel.bindings,
                bindings.len()
            )));
        }
        // Every binding of the right kind; buffer ranges checked against the limits.
        let mut ranges = Vec::with_capacity(bindings.len());
        for (binding, b) in bindings.iter().enumerate() {
            let structure = kernel.acceleration_structures.contains(&(binding as u32));
            match (b, structure) {
                (Binding::Buffer(r), false) => {
                    match kernel.texel_buffers.iter().find(|(b, _)| *b == binding as u32) {
                        Some(&(_, format)) => check_texel_range(ctx, &format!("binding {binding}"), r, format)?,
                        None => check_range(ctx, &format!("binding {binding}"), r)?,
                    }
                    ranges.push(*r);
                }
                (Binding::AccelerationStructure(a), true) if *a != vk::AccelerationStructureKHR::null() => {
                    ranges.push(BufferRange::new(vk::Buffer::null(), 0, 0));
                }
                _ => {
                    return Err(Error::InvalidInput(format!(
                        "binding {binding}: {} expected, got {b:?}",
                        if structure { "an acceleration structure" } else { "a buffer range" }
                    )))
                }
            }
        }
        let device = &ctx.device;
        let texel_count = kernel.texel_buffers.len() as u32;
        let structure_count = kernel.acceleration_structures.len() as u32;
        let sizes: Vec<vk::DescriptorPoolSize> = [
            (vk::DescriptorType::STORAGE_BUFFER, kernel.bindings - texel_count - structure_count),
            (vk::DescriptorType::STORAGE_TEXEL_BUFFER, texel_count),
            (vk::DescriptorType::ACCELERATION_STRUCTURE_KHR, structure_count),
        ]
        .into_iter()
        .filter(|&(_, n)| n > 0)
        .map(|(ty, descriptor_count)| vk::DescriptorPoolSize { ty, descriptor_count })
        .collect();
        // SAFETY: valid create/allocate infos; the views and the pool are destroyed in
        // Drop or on the error paths.
        unsafe {
            let mut views: Vec<(u32, [vk::BufferView; 1])> = Vec::new();
            for &(binding, format) in &kernel.texel_buffers {
                let r = &ranges[binding as usize];
                let info =
                    vk::BufferViewCreateInfo::default().buffer(r.buffer).format(format).offset(r.offset).range(r.range);
                match device.create_buffer_view(&info, None).vk("vkCreateBufferView") {
                    Ok(v) => views.push((binding, [v])),
                    Err(e) => {
                        for (_, [v]) in views {
                            device.destroy_buffer_view(v, None);
                        }
                        return Err(e);
                    }
                }
            }
            let destroy_views = |views: &[(u32, [vk::BufferView; 1])]| {
                for (_, [v]) in views {
                    device.destroy_buffer_view(*v, None);
                }
            };
            let pool = match device
                .create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)
                .vk("vkCreateDescriptorPool")
            {
                Ok(p) => p,
                Err(e) => {
                    destroy_views(&views);
                    return Err(e);
                }
            };
            let layouts = [kernel.set_layout];
            let set = match device
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts),
                )
                .vk("vkAllocateDescriptorSets")
            {
                Ok(s) => s[0],
                Err(e) => {
                    device.destroy_descriptor_pool(pool, None);
                    destroy_views(&views);
                    return Err(e);
                }
            };
            let infos: Vec<[vk::DescriptorBufferInfo; 1]> = ranges
                .iter()
                .map(|r| [vk::DescriptorBufferInfo { buffer: r.buffer, offset: r.offset, range: r.range }])
                .collect();
            let structures: Vec<[vk::AccelerationStructureKHR; 1]> = bindings
                .iter()
                .map(|b| match b {
                    Binding::AccelerationStructure(a) => [*a],
                    Binding::Buffer(_) => [vk::AccelerationStructureKHR::null()],
                })
                .collect();
            let mut structure_writes: Vec<vk::WriteDescriptorSetAccelerationStructureKHR> = structures
                .iter()
                .map(|a| vk::WriteDescriptorSetAccelerationStructureKHR::default().acceleration_structures(a))
                .collect();
            let writes: Vec<vk::WriteDescriptorSet> = infos
                .iter()
                .zip(structure_writes.iter_mut())
                .enumerate()
                .map(|(i, (info, structure))| {
                    let write = vk::WriteDescriptorSet::default().dst_set(set).dst_binding(i as u32);
                    if kernel.acceleration_structures.contains(&(i as u32)) {
                        return write
                            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                            .descriptor_count(1)
                            .push_next(structure);
                    }
                    match views.iter().find(|(b, _)| *b == i as u32) {
                        Some((_, view)) => {
                            write.descriptor_type(vk::DescriptorType::STORAGE_TEXEL_BUFFER).texel_buffer_view(view)
                        }
                        None => write.descriptor_type(vk::DescriptorType::STORAGE_BUFFER).buffer_info(info),
                    }
                })
                .collect();
            device.update_descriptor_sets(&writes, &[]);
            let views = views.into_iter().map(|(_, [v])| v).collect();
            Ok(BufferSet { set, pool, views, ctx: ctx.clone() })
        }
    }
}

/// The entries of a descriptor set (buffers in binding order) or of a kernel's
/// specialization constants (values in id order), from `(binding or id, entry)`
/// pairs in any order; each of `0..N` exactly once.
pub fn in_order<T: Copy, const N: usize>(entries: [(u32, T); N]) -> [T; N] {
    let mut out: [Option<T>; N] = [None; N];
    for (index, entry) in entries {
        let slot = &mut out[index as usize];
        assert!(slot.replace(entry).is_none(), "binding or id {index} given twice");
    }
    out.map(|e| e.expect("every binding or id given"))
}

/// Checks a texel-buffer range (viewed as `format`) against the device's limits.
/// Texel-buffer ranges must start at offset 0 (kdtrace binds its scene buffers whole).
pub(crate) fn check_texel_range(ctx: &GpuContext, what: &str, r: &BufferRange, format: vk::Format) -> Result<()> {
    let info = &ctx.info;
    let Some(bytes) = texel_bytes(format) else {
        return Err(Error::InvalidInput(format!("{what}: unsupported texel-buffer format {format:?}")));
    };
    if r.buffer == vk::Buffer::null() {
        return Err(Error::InvalidInput(format!("{what}: the buffer is VK_NULL_HANDLE")));
    }
    // SAFETY: the physical device belongs to the context's instance.
    let props = unsafe { ctx.instance.get_physical_device_format_properties(ctx.physical_device, format) };
    if !props.buffer_features.contains(vk::FormatFeatureFlags::STORAGE_TEXEL_BUFFER) {
        return Err(Error::DeviceLimit(format!(
            "{what}: {} cannot read {format:?} as a storage texel buffer (VK_FORMAT_FEATURE_STORAGE_TEXEL_BUFFER_BIT)",
            info.name
        )));
    }
    if r.offset != 0 || r.range == 0 || r.range == vk::WHOLE_SIZE || r.range % bytes != 0 {
        return Err(Error::InvalidInput(format!(
            "{what}: a texel-buffer range must start at 0 and hold whole {bytes}-byte texels, got offset {} range {}",
            r.offset, r.range
        )));
    }
    if r.range / bytes > info.max_texel_buffer_elements {
        return Err(Error::DeviceLimit(format!(
            "{what}: {} texels exceed maxTexelBufferElements ({}) on {}",
            r.range / bytes,
            info.max_texel_buffer_elements,
            info.name
        )));
    }
    Ok(())
}

/// Checks a storage-buffer range against the device's limits; `what` names it in errors.
pub(crate) fn check_range(ctx: &GpuContext, what: &str, r: &BufferRange) -> Result<()> {
    let info = &ctx.info;
    if r.buffer == vk::Buffer::null() {
        return Err(Error::InvalidInput(format!("{what}: the buffer is VK_NULL_HANDLE")));
    }
    if r.range == 0 || r.range == vk::WHOLE_SIZE {
        return Err(Error::InvalidInput(format!("{what}: the range must be a byte count above 0, got {}", r.range)));
    }
    if r.offset % info.min_storage_buffer_offset_alignment != 0 {
        return Err(Error::DeviceLimit(format!(
            "{what}: offset {} is not a multiple of minStorageBufferOffsetAlignment ({}) on {}",
            r.offset, info.min_storage_buffer_offset_alignment, info.name
        )));
    }
    if r.range > info.max_storage_buffer_range {
        return Err(Error::DeviceLimit(format!(
            "{what}: range {} bytes exceeds maxStorageBufferRange ({}) on {}",
            r.range, info.max_storage_buffer_range, info.name
        )));
    }
    Ok(())
}

impl Drop for BufferSet {
    fn drop(&mut self) {
        // SAFETY: no pending work uses the set or its views.
        unsafe {
            self.ctx.device.destroy_descriptor_pool(self.pool, None);
            for &v in &self.views {
                self.ctx.device.destroy_buffer_view(v, None);
            }
        }
    }
}

/// A pool of GPU timestamps.
pub struct Timestamps {
    /// The query pool.
    pub pool: vk::QueryPool,
    /// Number of timestamps.
    pub count: u32,
    period_ns: f64,
    ctx: Arc<GpuContext>,
}

impl Timestamps {
    /// `None` when the device's compute queue has no timestamps.
    pub fn new(ctx: &Arc<GpuContext>, count: u32) -> Result<Option<Timestamps>> {
        let Some(period_ns) = ctx.info.timestamp_period_ns else { return Ok(None) };
        let info = vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(count);
        // SAFETY: valid create info.
        let pool = unsafe { ctx.device.create_query_pool(&info, None) }.vk("vkCreateQueryPool")?;
        Ok(Some(Timestamps { pool, count, period_ns, ctx: ctx.clone() }))
    }

    /// Records a reset of all queries.
    ///
    /// # Safety
    /// `cmd` must be recording outside a render pass.
    pub unsafe fn record_reset(&self, cmd: vk::CommandBuffer) {
        self.ctx.device.cmd_reset_query_pool(cmd, self.pool, 0, self.count);
    }

    /// Records timestamp `index` after all prior work.
    ///
    /// # Safety
    /// `cmd` must be recording; `index < count` and reset earlier in `cmd`.
    pub unsafe fn record(&self, cmd: vk::CommandBuffer, index: u32) {
        self.ctx.device.cmd_write_timestamp(cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, self.pool, index);
    }

    /// Seconds between timestamps `a` and `b` of a completed submission.
    pub fn seconds_between(&self, a: u32, b: u32) -> Result<f64> {
        let ticks = self.ticks(self.count)?;
        Ok(self.seconds(&ticks, a, b))
    }

    /// Seconds between timestamps `a` and `b` of `ticks` (from [`Timestamps::ticks`]).
    pub fn seconds(&self, ticks: &[u64], a: u32, b: u32) -> f64 {
        ticks[b as usize].wrapping_sub(ticks[a as usize]) as f64 * self.period_ns * 1e-9
    }

    /// The first `count` timestamps, in ticks, of a completed submission that
    /// wrote them all.
    pub fn ticks(&self, count: u32) -> Result<Vec<u64>> {
        let mut data = vec![0u64; count.min(self.count) as usize];
        // SAFETY: the pool has at least `data.len()` queries, and the caller waited for completion.
        unsafe {
            self.ctx
                .device
                .get_query_pool_results(
                    self.pool,
                    0,
                    &mut data,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
                .vk("vkGetQueryPoolResults")?;
        }
        Ok(data)
    }
}

impl Drop for Timestamps {
    fn drop(&mut self) {
        // SAFETY: no pending work uses the pool.
        unsafe { self.ctx.device.destroy_query_pool(self.pool, None) };
    }
}
