//! The renderer's side of its contract with `glsl/shared/render.glsl`: the push
//! constants and the std430 structs of the scene buffers. Each mirrors a
//! declaration there; the sizes are tested below. The constants (material
//! flags, counter indices, jitter modes, bindings) are in `consts.rs`, which
//! build.rs passes to the kernels as `#define`s.

use bytemuck::{Pod, Zeroable};

use crate::geom::{Hit, Ray};

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

/// Push constants of the render passes (`RenderParams` in `render.glsl`), 128 bytes.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RenderParams {
    /// xyz: the eye; w: the bits of the first pixel index of this chunk.
    pub eye: [f32; 4],
    /// xyz: unit view direction; w: the emitters' total weight (Σ area × luminance of Ke).
    pub forward: [f32; 4],
    /// xyz: right × tan(fov/2) × aspect; w: the sample's jitter x when one
    /// jitter serves the whole image (rasterized first hits).
    pub right: [f32; 4],
    /// xyz: up × tan(fov/2); w: that jitter's y.
    pub up: [f32; 4],
    /// xyz: background radiance; w: ambient radiance (ambient occlusion).
    pub background: [f32; 4],
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Paths (or pixels) in this dispatch.
    pub count: u32,
    /// Which sample of each pixel.
    pub sample_index: u32,
    /// Seed of the sample sequence.
    pub seed: u32,
    /// Ray segments per path at most.
    pub max_depth: u32,
    /// Diffuse bounces per path at most.
    pub bounces: u32,
    /// Ambient-occlusion rays per first diffuse hit.
    pub ao_samples: u32,
    /// Their length.
    pub ao_radius: f32,
    /// Point lights.
    pub light_count: u32,
    /// Emissive triangles.
    pub emitter_count: u32,
    /// Shadow rays the shadow queue holds.
    pub shadow_capacity: u32,
}

/// The entries of a descriptor set (buffers in binding order) or of a kernel's
/// specialization constants (values in id order), from `(binding or id, entry)`
/// pairs in any order; each of `0..N` exactly once.
pub(super) fn in_order<T: Copy, const N: usize>(entries: [(u32, T); N]) -> [T; N] {
    let mut out: [Option<T>; N] = [None; N];
    for (index, entry) in entries {
        let slot = &mut out[index as usize];
        assert!(slot.replace(entry).is_none(), "binding or id {index} given twice");
    }
    out.map(|e| e.expect("every binding or id given"))
}

/// `Path` of `render.glsl`: written and read by the kernels only, mirrored for its size.
#[allow(dead_code)]
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(super) struct GpuPath {
    pub(super) throughput: [f32; 3],
    pub(super) pixel: u32,
    pub(super) flags: u32,
    pub(super) depth: u32,
    pub(super) diffuse: u32,
    pub(super) pad: u32,
}

/// `Surface` of `render.glsl`: the vertices, the material id's bits in `v0.w`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(super) struct Surface {
    pub(super) v: [[f32; 4]; 3],
}

/// `Material` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(super) struct GpuMaterial {
    pub(super) kd_ns: [f32; 4],
    pub(super) ks_flags: [f32; 4],
    pub(super) ke: [f32; 4],
}

/// `Emitter` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(super) struct Emitter {
    pub(super) prim: u32,
    pub(super) cdf: f32,
    pub(super) pick: f32,
    pub(super) area: f32,
}

/// `PointLight` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(super) struct GpuLight {
    pub(super) position: [f32; 4],
    pub(super) intensity: [f32; 4],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constants_fit_the_guaranteed_128_bytes() {
        assert_eq!(std::mem::size_of::<RenderParams>(), 128);
        assert_eq!(std::mem::size_of::<GpuPath>(), 32);
        assert_eq!(std::mem::size_of::<Surface>(), 48);
        assert_eq!(std::mem::size_of::<GpuMaterial>(), 48);
        assert_eq!(std::mem::size_of::<Emitter>(), 16);
        assert_eq!(std::mem::size_of::<GpuLight>(), 32);
        // Field order as declared in render.glsl (tests/layout.rs checks the shaders' side).
        use std::mem::offset_of;
        assert_eq!(
            [offset_of!(GpuMaterial, kd_ns), offset_of!(GpuMaterial, ks_flags), offset_of!(GpuMaterial, ke)],
            [0, 16, 32]
        );
        assert_eq!(
            [offset_of!(Emitter, prim), offset_of!(Emitter, cdf), offset_of!(Emitter, pick), offset_of!(Emitter, area)],
            [0, 4, 8, 12]
        );
        assert_eq!([offset_of!(GpuLight, position), offset_of!(GpuLight, intensity)], [0, 16]);
        assert_eq!(
            [
                offset_of!(GpuPath, throughput),
                offset_of!(GpuPath, pixel),
                offset_of!(GpuPath, flags),
                offset_of!(GpuPath, depth),
                offset_of!(GpuPath, diffuse),
                offset_of!(GpuPath, pad)
            ],
            [0, 12, 16, 20, 24, 28]
        );
    }
}
