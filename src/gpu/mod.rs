//! The only module that calls Vulkan: the device context (headless, or adopted
//! from an engine), buffers, kernels, timestamps, the rasterizer of first hits, and
//! the driver's acceleration structures for ray queries. Every `unsafe` block carries a
//! `// SAFETY:` line.
mod accel;
mod buffer;
mod context;
mod device;
mod kernel;
mod pipeline_cache;
mod raster;

pub use accel::TriangleAccel;
pub use buffer::{Buffer, BufferRange};
pub use context::{AdoptDesc, ContextOptions, GpuContext, Validation};
pub use device::{list_devices, required_features, DeviceInfo, RAY_QUERY_EXTENSIONS};
pub(crate) use kernel::check_range;
pub use kernel::{in_order, Binding, BufferSet, Kernel, KernelDesc, Timestamps};
pub use raster::{RasterView, Rasterizer};

/// SPIR-V of the kernels in `glsl/`, compiled by build.rs, and the GLSL header
/// for shader authors.
///
/// - `TRACE`, `LAYOUT_PROBE`: the library's kernels (`glsl/*.comp`).
/// - [`HEADER`](shaders::HEADER): `kdtrace.glsl`, a self-contained GLSL header with
///   the std430 `Ray` and `Hit` structs (generated from [`crate::Ray`] and [`crate::Hit`]) and the special
///   `prim_id`s and counter indices of [`crate::consts`] as `#define`s. Write it
///   into your shader include path and `#include "kdtrace.glsl"`.
/// - `EXAMPLE_*`: the shaders of `examples/embed.rs` (`glsl/examples/*.comp`),
///   compiled against `HEADER` alone as a user's shader would be. For the example
///   and its test only; not part of the tracing API.
pub mod shaders {
    include!(concat!(env!("OUT_DIR"), "/shaders.rs"));
}
