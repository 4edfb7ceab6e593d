//! Storage buffers allocated with gpu-allocator.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::GpuContext;
use crate::error::{Error, Result, VkContext};

/// A buffer and its memory, from the context's allocator. Host-visible buffers
/// (`CpuToGpu`, `GpuToCpu`) stay mapped. Dropping it destroys the buffer and frees
/// its allocation, so no pending GPU work may still use it then.
///
/// `Buffer` is `Send + Sync` (reads of the mapping take `&self`, writes `&mut self`).
pub struct Buffer {
    /// The Vulkan buffer.
    pub buffer: vk::Buffer,
    /// Its size in bytes.
    pub size: u64,
    usage: vk::BufferUsageFlags,
    allocation: Option<Allocation>,
    ctx: Arc<GpuContext>,
}

/// A byte range of a storage buffer, as one descriptor binds it: `range` bytes
/// from `offset` of `buffer`. `offset` must be a multiple of the device's
/// `minStorageBufferOffsetAlignment` ([`super::DeviceInfo::min_storage_buffer_offset_alignment`])
/// and `range` at most `maxStorageBufferRange`; users of a range check both and
/// report a clear error.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BufferRange {
    /// A buffer created with `vk::BufferUsageFlags::STORAGE_BUFFER`.
    pub buffer: vk::Buffer,
    /// Start of the range in bytes.
    pub offset: u64,
    /// Length of the range in bytes (not `vk::WHOLE_SIZE`).
    pub range: u64,
}

impl BufferRange {
    /// `range` bytes from `offset` of `buffer`.
    pub fn new(buffer: vk::Buffer, offset: u64, range: u64) -> Self {
        BufferRange { buffer, offset, range }
    }

    /// All of a kdtrace [`Buffer`].
    pub fn whole(buffer: &Buffer) -> Self {
        BufferRange { buffer: buffer.buffer, offset: 0, range: buffer.size }
    }

    /// One past the last byte (saturating).
    pub fn end(&self) -> u64 {
        self.offset.saturating_add(self.range)
    }

    /// True when both ranges are of the same buffer and share a byte.
    pub fn overlaps(&self, other: &BufferRange) -> bool {
        self.buffer == other.buffer && self.offset < other.end() && other.offset < self.end()
    }
}

impl Buffer {
    /// Creates a buffer of `size` bytes (at least 4) named `name` for debugging.
    pub fn new(
        ctx: &Arc<GpuContext>,
        size: u64,
        usage: vk::BufferUsageFlags,
        location: MemoryLocation,
        name: &str,
    ) -> Result<Buffer> {
        let size = size.max(4);
        if size > ctx.info.max_memory_allocation_size {
            return Err(Error::DeviceLimit(format!(
                "buffer '{name}' needs {size} bytes; the device allows {} per allocation",
                ctx.info.max_memory_allocation_size
            )));
        }
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        let device = &ctx.device;
        // SAFETY: a valid create info on a live device.
        let buffer = unsafe { device.create_buffer(&info, None) }.vk("vkCreateBuffer")?;
        // SAFETY: `buffer` was just created on this device.
        let requirements = unsafe { device.get_buffer_memory_requirements(buffer) };
        let allocation = ctx.allocator().lock().unwrap_or_else(|p| p.into_inner()).allocate(&AllocationCreateDesc {
            name,
            requirements,
            location,
            linear: true,
            allocation_scheme: AllocationScheme::GpuAllocatorManaged,
        });
        let allocation = match allocation {
            Ok(a) => a,
            Err(e) => {
                // SAFETY: the buffer is unused and unbound.
                unsafe { device.destroy_buffer(buffer, None) };
                return Err(e.into());
            }
        };
        // SAFETY: the allocation satisfies the buffer's requirements.
        if let Err(result) = unsafe { device.bind_buffer_memory(buffer, allocation.memory(), allocation.offset()) } {
            // SAFETY: the buffer is unused.
            unsafe { device.destroy_buffer(buffer, None) };
            let _ = ctx.allocator().lock().unwrap_or_else(|p| p.into_inner()).free(allocation);
            return Err(Error::Vulkan { what: "vkBindBufferMemory", result });
        }
        Ok(Buffer { buffer, size, usage, allocation: Some(allocation), ctx: ctx.clone() })
    }

    /// A device-local storage buffer holding `data`, filled through a staging buffer.
    pub fn with_data(ctx: &Arc<GpuContext>, data: &[u8], usage: vk::BufferUsageFlags, name: &str) -> Result<Buffer> {
        let size = (data.len() as u64).max(4);
        let buffer = Buffer::new(ctx, size, usage | vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuOnly, name)?;
        let mut staging =
            Buffer::new(ctx, size, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu, "staging")?;
        staging.write(0, data)?;
        ctx.submit_and_wait(|cmd| {
            let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size }];
            // SAFETY: both buffers are alive and large enough; `cmd` is recording.
            unsafe { ctx.device.cmd_copy_buffer(cmd, staging.buffer, buffer.buffer, &region) };
        })?;
        Ok(buffer)
    }

    /// A device-local buffer holding `data`, its copy from a host-visible
    /// staging buffer recorded into `cmd` (no submit, no wait). Returns the
    /// buffer and the staging buffer, which must live until `cmd` has completed.
    /// The caller records the barrier from `TRANSFER`/`TRANSFER_WRITE` to the
    /// buffer's readers.
    ///
    /// # Safety
    /// `cmd` is a command buffer of the context's device in the recording state,
    /// outside a render pass.
    pub unsafe fn with_data_recorded(
        ctx: &Arc<GpuContext>,
        cmd: vk::CommandBuffer,
        data: &[u8],
        usage: vk::BufferUsageFlags,
        name: &str,
    ) -> Result<(Buffer, Buffer)> {
        let size = (data.len() as u64).max(4);
        let buffer = Buffer::new(ctx, size, usage | vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuOnly, name)?;
        let mut staging =
            Buffer::new(ctx, size, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu, "staging")?;
        staging.write(0, data)?;
        let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size }];
        // SAFETY: both buffers are alive and large enough; the caller keeps the
        // staging buffer alive until `cmd` completes and `cmd` is recording.
        unsafe { ctx.device.cmd_copy_buffer(cmd, staging.buffer, buffer.buffer, &region) };
        Ok((buffer, staging))
    }

    /// The buffer's device address (`vkGetBufferDeviceAddress`), for acceleration
    /// structure builds. The buffer must have been created with
    /// `SHADER_DEVICE_ADDRESS` usage on a context with the ray-query backend
    /// enabled (whose allocator gives memory device addresses); else an error.
    pub fn device_address(&self) -> Result<vk::DeviceAddress> {
        self.ctx.ray_query()?;
        if !self.usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS) {
            return Err(Error::InvalidInput("a device address of a buffer without SHADER_DEVICE_ADDRESS usage".into()));
        }
        let info = vk::BufferDeviceAddressInfo::default().buffer(self.buffer);
        // SAFETY: a live buffer of this device, whose memory was allocated with the
        // device-address flag (the allocator's `buffer_device_address`).
        Ok(unsafe { self.ctx.device.get_buffer_device_address(&info) })
    }

    /// The mapped bytes of a host-visible buffer.
    pub fn mapped(&self) -> Option<&[u8]> {
        self.allocation.as_ref()?.mapped_slice()
    }

    fn mapped_mut(&mut self) -> Option<&mut [u8]> {
        self.allocation.as_mut()?.mapped_slice_mut()
    }

    /// Copies `data` into a host-visible buffer at `offset`.
    pub fn write(&mut self, offset: usize, data: &[u8]) -> Result<()> {
        let slice =
            self.mapped_mut().ok_or_else(|| Error::InvalidInput("write to a buffer that is not mapped".into()))?;
        let end = offset.checked_add(data.len()).filter(|&e| e <= slice.len());
        let end = end.ok_or_else(|| Error::InvalidInput("write past the end of a buffer".into()))?;
        slice[offset..end].copy_from_slice(data);
        Ok(())
    }

    /// Reads `len` bytes at `offset` of a host-visible buffer.
    pub fn read(&self, offset: usize, len: usize) -> Result<&[u8]> {
        let slice = self.mapped().ok_or_else(|| Error::InvalidInput("read from a buffer that is not mapped".into()))?;
        slice.get(offset..offset + len).ok_or_else(|| Error::InvalidInput("read past the end of a buffer".into()))
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: the owner guarantees no pending GPU work uses the buffer: kdtrace's
        // own submissions wait for completion, and traces recorded into a caller's
        // command buffer must complete before the tracer is dropped (trace.rs docs).
        unsafe { self.ctx.device.destroy_buffer(self.buffer, None) };
        if let Some(a) = self.allocation.take() {
            let _ = self.ctx.allocator().lock().unwrap_or_else(|p| p.into_inner()).free(a);
        }
    }
}
