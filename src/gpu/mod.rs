//! The only module that calls Vulkan: context, buffers, kernels, timestamps.
mod buffer;
mod context;
mod kernel;

pub use buffer::Buffer;
pub use context::{list_devices, ContextOptions, DeviceInfo, GpuContext, Validation};
pub use kernel::{BufferSet, Kernel, KernelDesc, Timestamps};

/// SPIR-V of the kernels in `glsl/`, compiled by build.rs.
pub mod shaders {
    include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
}
