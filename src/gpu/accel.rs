//! The driver's acceleration structures (`VK_KHR_acceleration_structure`) over a
//! triangle soup: one bottom-level structure of opaque triangles, built for fast
//! tracing and compacted, and a top-level structure holding it once with the
//! identity transform. Ray queries (`VK_KHR_ray_query`) traverse the top level.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::{Buffer, GpuContext};
use crate::error::{Error, Result, VkContext};

/// One acceleration structure and the buffer holding it; destroyed when dropped
/// (no pending work may use it then).
struct AccelerationStructure {
    handle: vk::AccelerationStructureKHR,
    buffer: Buffer,
    ctx: Arc<GpuContext>,
}

impl AccelerationStructure {
    /// An (unbuilt) acceleration structure of `ty` in a new buffer of `size` bytes.
    fn new(ctx: &Arc<GpuContext>, ty: vk::AccelerationStructureTypeKHR, size: u64, name: &str) -> Result<Self> {
        let rq = ctx.ray_query()?;
        let usage =
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;
        let buffer = Buffer::new(ctx, size, usage, MemoryLocation::GpuOnly, name)?;
        let info = vk::AccelerationStructureCreateInfoKHR::default().buffer(buffer.buffer).size(size).ty(ty);
        // SAFETY: a valid create info over a live buffer with the storage usage,
        // at offset 0 (a multiple of 256).
        let handle =
            unsafe { rq.loader.create_acceleration_structure(&info, None) }.vk("vkCreateAccelerationStructureKHR")?;
        Ok(AccelerationStructure { handle, buffer, ctx: ctx.clone() })
    }

    /// Its device address, as instances reference it.
    fn device_address(&self) -> Result<vk::DeviceAddress> {
        let rq = self.ctx.ray_query()?;
        let info = vk::AccelerationStructureDeviceAddressInfoKHR::default().acceleration_structure(self.handle);
        // SAFETY: a live acceleration structure of this device.
        Ok(unsafe { rq.loader.get_acceleration_structure_device_address(&info) })
    }
}

impl Drop for AccelerationStructure {
    fn drop(&mut self) {
        if let Ok(rq) = self.ctx.ray_query() {
            // SAFETY: no pending work uses it (builds are waited for; tracers are
            // dropped only when their recorded traces have completed).
            unsafe { rq.loader.destroy_acceleration_structure(self.handle, None) };
        }
        // The buffer it lives in is freed after it, with the fields.
    }
}

/// A scratch buffer for a build, its device address aligned as the device asks.
fn scratch(ctx: &Arc<GpuContext>, size: u64) -> Result<(Buffer, vk::DeviceAddress)> {
    let align = ctx.ray_query()?.scratch_alignment;
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;
    let buffer = Buffer::new(ctx, size + align, usage, MemoryLocation::GpuOnly, "acceleration structure scratch")?;
    let address = buffer.device_address()?.next_multiple_of(align);
    Ok((buffer, address))
}

/// A barrier from acceleration-structure writes (builds, copies) to the
/// acceleration-structure reads of later builds, copies and queries.
///
/// # Safety
/// `cmd` must be recording outside a render pass.
unsafe fn build_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    let stage = vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR;
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR)
        .dst_access_mask(vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR);
    // SAFETY: forwarded from the caller.
    unsafe { ctx.device.cmd_pipeline_barrier(cmd, stage, stage, vk::DependencyFlags::empty(), &[barrier], &[], &[]) };
}

/// A scene of triangles in the driver's acceleration structures, ready for ray
/// queries: triangle `i` is vertices `3i..3i+3` of the soup it was built from,
/// and a query reports it as primitive index `i` with barycentrics (u, v) the
/// weights of its second and third vertex.
pub struct TriangleAccel {
    /// The top level, holding `bottom` once (identity transform, mask 0xFF).
    top: AccelerationStructure,
    /// The compacted bottom level over the triangles.
    bottom: AccelerationStructure,
}

impl TriangleAccel {
    /// Bytes of the two structures' buffers (the vertex buffer is freed after the build).
    pub fn device_bytes(&self) -> u64 {
        self.top.buffer.size + self.bottom.buffer.size
    }

    /// Builds the structures over `vertices` (three per triangle, none skipped:
    /// every triangle given is traceable) on the device: the bottom level opaque,
    /// `PREFER_FAST_TRACE` and compacted, then the top level. Submits on the
    /// context's queue and waits (three submissions).
    ///
    /// Errors: `Error::DeviceLimit` when the device lacks the ray-query backend
    /// (naming what it lacks) or the triangles exceed `maxPrimitiveCount`;
    /// `Error::InvalidInput` without triangles.
    ///
    /// One function of about 160 lines: the Vulkan build sequence (sizes,
    /// scratch, bottom level, compaction query and copy, top level) reads in
    /// the order the specification describes it, each step using the last's handles.
    pub fn build(ctx: &Arc<GpuContext>, vertices: &[[f32; 3]]) -> Result<TriangleAccel> {
        let rq = ctx.ray_query()?;
        let triangles = vertices.len() / 3;
        if triangles == 0 || vertices.len() % 3 != 0 {
            return Err(Error::InvalidInput(format!(
                "an acceleration structure needs whole triangles, got {} vertices",
                vertices.len()
            )));
        }
        if triangles as u64 > rq.max_primitive_count.min(u32::MAX as u64) {
            return Err(Error::DeviceLimit(format!(
                "{triangles} triangles exceed the {} one acceleration structure of {} may hold (maxPrimitiveCount)",
                rq.max_primitive_count, ctx.info.name
            )));
        }
        let input_usage = vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;

        // Bottom level: build, then read back the compacted size.
        let vertex_buffer = Buffer::with_data(ctx, bytemuck::cast_slice(vertices), input_usage, "triangle vertices")?;
        let geometry_triangles = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
            .vertex_format(vk::Format::R32G32B32_SFLOAT)
            .vertex_data(vk::DeviceOrHostAddressConstKHR { device_address: vertex_buffer.device_address()? })
            .vertex_stride(12)
            .max_vertex(vertices.len() as u32 - 1)
            .index_type(vk::IndexType::NONE_KHR);
        let geometries = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { triangles: geometry_triangles })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let bottom_info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
            .flags(
                vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
                    | vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION,
            )
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geometries);
        let bottom_sizes = build_sizes(ctx, &bottom_info, triangles as u32)?;
        let built = AccelerationStructure::new(
            ctx,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            bottom_sizes.acceleration_structure_size,
            "bottom-level acceleration structure",
        )?;
        let (scratch_buffer, scratch_address) = scratch(ctx, bottom_sizes.build_scratch_size)?;
        let query_info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR)
            .query_count(1);
        // SAFETY: a valid create info; the pool is destroyed below.
        let pool = unsafe { ctx.device.create_query_pool(&query_info, None) }.vk("vkCreateQueryPool")?;
        let compacted = (|| -> Result<u64> {
            let info = bottom_info
                .dst_acceleration_structure(built.handle)
                .scratch_data(vk::DeviceOrHostAddressKHR { device_address: scratch_address });
            let ranges = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(triangles as u32)];
            ctx.submit_and_wait(|cmd| {
                // SAFETY: `cmd` is recording; the vertex, scratch and structure
                // buffers outlive the waited submission; the pool has one query.
                unsafe {
                    ctx.device.cmd_reset_query_pool(cmd, pool, 0, 1);
                    rq.loader.cmd_build_acceleration_structures(cmd, &[info], &[&ranges]);
                    build_barrier(ctx, cmd);
                    rq.loader.cmd_write_acceleration_structures_properties(
                        cmd,
                        &[built.handle],
                        vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
                        pool,
                        0,
                    );
                }
            })?;
            let mut size = [0u64];
            // SAFETY: the submission that wrote the query was waited for.
            unsafe {
                ctx.device.get_query_pool_results(
                    pool,
                    0,
                    &mut size,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .vk("vkGetQueryPoolResults")?;
            Ok(size[0])
        })();
        // SAFETY: no pending work uses the pool (the submission was waited for or never made).
        unsafe { ctx.device.destroy_query_pool(pool, None) };
        let compacted = compacted?;
        drop(scratch_buffer);
        drop(vertex_buffer);

        // Compact it.
        let bottom = AccelerationStructure::new(
            ctx,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            compacted.clamp(1, bottom_sizes.acceleration_structure_size),
            "bottom-level acceleration structure (compacted)",
        )?;
        let copy = vk::CopyAccelerationStructureInfoKHR::default()
            .src(built.handle)
            .dst(bottom.handle)
            .mode(vk::CopyAccelerationStructureModeKHR::COMPACT);
        // SAFETY: `cmd` is recording; both structures outlive the waited submission.
        ctx.submit_and_wait(|cmd| unsafe { rq.loader.cmd_copy_acceleration_structure(cmd, &copy) })?;
        drop(built);

        // Top level: one instance of the bottom level, identity transform, no culling.
        let instance = vk::AccelerationStructureInstanceKHR {
            transform: vk::TransformMatrixKHR { matrix: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0] },
            instance_custom_index_and_mask: vk::Packed24_8::new(0, 0xFF),
            instance_shader_binding_table_record_offset_and_flags: vk::Packed24_8::new(
                0,
                vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE.as_raw() as u8,
            ),
            acceleration_structure_reference: vk::AccelerationStructureReferenceKHR {
                device_handle: bottom.device_address()?,
            },
        };
        // SAFETY: the instance is a plain `repr(C)` struct of 64 bytes without padding.
        let instance_bytes = unsafe {
            std::slice::from_raw_parts(
                (&instance as *const vk::AccelerationStructureInstanceKHR).cast::<u8>(),
                std::mem::size_of::<vk::AccelerationStructureInstanceKHR>(),
            )
        };
        let instance_buffer = Buffer::with_data(ctx, instance_bytes, input_usage, "acceleration structure instance")?;
        let instance_address = instance_buffer.device_address()?;
        if instance_address % 16 != 0 {
            return Err(Error::DeviceLimit(format!(
                "the instance buffer's device address {instance_address:#x} is not 16-byte aligned"
            )));
        }
        let instances = vk::AccelerationStructureGeometryInstancesDataKHR::default()
            .array_of_pointers(false)
            .data(vk::DeviceOrHostAddressConstKHR { device_address: instance_address });
        let top_geometries = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { instances })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let top_info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&top_geometries);
        let top_sizes = build_sizes(ctx, &top_info, 1)?;
        let top = AccelerationStructure::new(
            ctx,
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            top_sizes.acceleration_structure_size,
            "top-level acceleration structure",
        )?;
        let (scratch_buffer, scratch_address) = scratch(ctx, top_sizes.build_scratch_size)?;
        let info = top_info
            .dst_acceleration_structure(top.handle)
            .scratch_data(vk::DeviceOrHostAddressKHR { device_address: scratch_address });
        let ranges = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(1)];
        // SAFETY: `cmd` is recording; the instance, scratch and structure buffers
        // outlive the waited submission; the bottom level was compacted in an
        // earlier waited submission.
        ctx.submit_and_wait(|cmd| unsafe { rq.loader.cmd_build_acceleration_structures(cmd, &[info], &[&ranges]) })?;
        drop(scratch_buffer);
        drop(instance_buffer);
        Ok(TriangleAccel { top, bottom })
    }

    /// The top-level structure, as a kernel's `accelerationStructureEXT` binds it.
    pub fn top_level(&self) -> vk::AccelerationStructureKHR {
        self.top.handle
    }

    /// Bytes of device memory the two structures take.
    pub fn bytes(&self) -> u64 {
        self.top.buffer.size + self.bottom.buffer.size
    }
}

/// The sizes of the structure and scratch of a build of `primitives` primitives.
fn build_sizes(
    ctx: &GpuContext,
    info: &vk::AccelerationStructureBuildGeometryInfoKHR,
    primitives: u32,
) -> Result<vk::AccelerationStructureBuildSizesInfoKHR<'static>> {
    let rq = ctx.ray_query()?;
    let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
    // SAFETY: a valid build info with one geometry and one primitive count.
    unsafe {
        rq.loader.get_acceleration_structure_build_sizes(
            vk::AccelerationStructureBuildTypeKHR::DEVICE,
            info,
            &[primitives],
            &mut sizes,
        )
    };
    Ok(sizes)
}
