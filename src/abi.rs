// The structs that cross the host/GPU boundary of the tracer and the raster
// pass, each defined once with `gpu_struct!` (src/gpu_struct.rs). build.rs
// includes this file by path and writes their GLSL declarations into the
// generated headers `ray.glsl` (`Ray`, `Hit`, `TraceParams`; the first two also
// into the users' `kdtrace.glsl`) and `raster.glsl` (`RasterView`); the library
// re-exports them from `geom`, `trace` and `gpu`. glsl/layout_probe.comp and
// tests/layout.rs check every field on the device.

use bytemuck::{Pod, Zeroable};

gpu_struct! {
    /// A ray as stored in ray files and GPU buffers (32 bytes, std430 `Ray`):
    /// the segment `origin + t * dir`, `tmin <= t <= tmax`.
    /// `dir` need not be normalized; `tmax` may be `+inf`.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
    pub struct Ray {
        /// Origin, world units.
        pub origin: [f32; 3],
        /// Start of the segment, in units of `dir` (usually 0).
        pub tmin: f32,
        /// Direction; need not be normalized, must not be zero.
        pub dir: [f32; 3],
        /// End of the segment, in units of `dir`; may be `+inf`.
        pub tmax: f32,
    }
}

gpu_struct! {
    /// A hit as stored in hit files and GPU buffers (16 bytes, std430 `Hit`).
    /// The hit point is `(1-u-v)·v0 + u·v1 + v·v2` of triangle `prim_id`;
    /// `prim_id` is `PRIM_MISS`, `PRIM_INVALID` or `PRIM_INCOMPLETE` when there
    /// is no hit.
    #[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
    pub struct Hit {
        /// Ray parameter of the hit, in units of `dir`; `+inf` for a miss, NaN for an
        /// invalid or incomplete ray.
        pub t: f32,
        /// Triangle index (scene order), or `PRIM_MISS`, `PRIM_INVALID`, `PRIM_INCOMPLETE`.
        pub prim_id: u32,
        /// Barycentric weight of `v1`; 0 without a hit.
        pub u: f32,
        /// Barycentric weight of `v2`; 0 without a hit.
        pub v: f32,
    }
}

gpu_struct! {
    /// Push constants of `trace.comp` (48 bytes).
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct TraceParams {
        /// xyz: the scene box's minimum corner (w unused).
        pub scene_min: [f32; 4],
        /// xyz: the scene box's maximum corner (w unused).
        pub scene_max: [f32; 4],
        /// Rays in this dispatch.
        pub ray_count: u32,
        /// 0: the kernel uses it as a zero its compiler cannot fold (see
        /// `shift_to_scene` in glsl/trace.comp).
        pub pad0: u32,
        /// 1: invocation `i` traces ray `order[i]` of the order binding
        /// (`RayOrder::Coherent`); 0: ray `i`.
        pub ordered: u32,
        /// Padding to 48 bytes (0).
        pub pad2: u32,
    }
}

gpu_struct! {
    /// Push constants of `raster_visibility.vert` (80 bytes): the pinhole model
    /// of the camera rays as a projection.
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct RasterView {
        /// xyz: the eye.
        pub eye: [f32; 4],
        /// xyz: the camera's scaled right vector (right × tan(fov/2) × aspect)
        /// divided by its squared length.
        pub right: [f32; 4],
        /// xyz: the camera's scaled up vector (up × tan(fov/2)) divided by its
        /// squared length.
        pub up: [f32; 4],
        /// xyz: the unit view direction.
        pub forward: [f32; 4],
        /// x: near distance; y, z: NDC shift of the sample's sub-pixel position.
        pub params: [f32; 4],
    }
}
