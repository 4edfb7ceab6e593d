//! The renderer's side of its contract with its kernels: the push constants
//! and the std430 structs of the scene buffers and ray queues (`structs.rs`,
//! whose GLSL declarations build.rs generates), the sizes of the other buffer
//! elements. The
//! constants (material flags, counter indices, jitter modes, bindings) are in
//! `consts.rs`, which build.rs passes to the kernels as `#define`s.

pub use super::structs::RenderParams;
pub(super) use super::structs::{Emitter, GpuLight, GpuMaterial, GpuPath, Surface};
use crate::geom::{Hit, Ray};
pub(super) use crate::gpu::in_order;

/// Bytes of a ray of a queue (std430 `Ray`).
pub(super) const RAY_BYTES: u64 = std::mem::size_of::<Ray>() as u64;
/// Bytes of a hit of a queue (std430 `Hit`).
pub(super) const HIT_BYTES: u64 = std::mem::size_of::<Hit>() as u64;
/// Bytes of a path of a queue (`Path` of `render.glsl`, [`GpuPath`]); the shadow
/// queue keeps each shadow ray's `vec4` weight in such a slot.
pub(super) const PATH_BYTES: u64 = std::mem::size_of::<GpuPath>() as u64;
/// Bytes per pixel of the accumulation buffer (a `vec4`: radiance sum, bad rays).
pub(super) const ACCUM_BYTES: u64 = std::mem::size_of::<[f32; 4]>() as u64;
/// Bytes per path of the shadow spans (a `uvec2`).
pub(super) const SPAN_BYTES: u64 = std::mem::size_of::<[u32; 2]>() as u64;
/// Bytes of a render counter (`uint`).
pub(super) const COUNTER_BYTES: u64 = std::mem::size_of::<u32>() as u64;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constants_fit_the_guaranteed_128_bytes() {
        // Field offsets and the other sizes are std430's by construction (`gpu_struct!`).
        assert_eq!(std::mem::size_of::<RenderParams>(), 128);
    }
}
