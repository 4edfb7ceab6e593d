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
        /// 1: the count is the `INDIRECT_COUNT` word of the indirect binding and
        /// the dispatch covers it in rows (`Tracer::record_binding_indirect`);
        /// 0: `ray_count`.
        pub indirect: u32,
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

// The two-level kernel's records (glsl/trace_twolevel.comp, `kdtrace::twolevel`),
// in the generated header `twolevel.glsl`.

gpu_struct! {
    /// Push constants of `trace_twolevel.comp` (16 bytes).
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct TwoLevelParams {
        /// Rays in this dispatch.
        pub ray_count: u32,
        /// The rays' 8-bit visibility mask: instance `i` is visible when `mask & instance.mask != 0`.
        pub mask: u32,
        /// Nodes of the top level (0: no instance, every ray misses).
        pub top_nodes: u32,
        /// 1: a device-counted trace (`TwoLevelTracer::record_binding_indirect`):
        /// the count and the dispatch come from the binding's arguments.
        pub indirect: u32,
    }
}

gpu_struct! {
    /// A geometry of a two-level scene on the device (48 bytes): its kd-tree's
    /// box and where its nodes and triangle references start in the shared buffers.
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct GpuGeometry {
        /// xyz: the tree's box minimum (object space).
        pub bounds_min: [f32; 4],
        /// xyz: the tree's box maximum.
        pub bounds_max: [f32; 4],
        /// Its first node in the node texels.
        pub node_base: u32,
        /// Its first triangle reference (3 texels each) in the triangle texels.
        pub texel_base: u32,
        /// The caller's geometry id.
        pub id: u32,
        /// Padding (0).
        pub pad: u32,
    }
}

gpu_struct! {
    /// An instance of a two-level scene on the device (64 bytes).
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct GpuInstance {
        /// First row of the world-to-object 3×4 matrix.
        pub row0: [f32; 4],
        /// Second row.
        pub row1: [f32; 4],
        /// Third row.
        pub row2: [f32; 4],
        /// Index of its geometry.
        pub geometry: u32,
        /// The caller's instance id.
        pub instance_id: u32,
        /// Its 8-bit visibility mask.
        pub mask: u32,
        /// 1 when the world-to-object matrix is exactly the identity (the object
        /// ray is then the world ray itself), else 0.
        pub identity: u32,
    }
}

gpu_struct! {
    /// A node of the top-level BVH over the instances (48 bytes).
    #[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
    pub struct TopNode {
        /// xyz: the box minimum (world space); w: the largest condition number of
        /// the instances below (the box widens by it times the origin's magnitude).
        pub bounds_min: [f32; 4],
        /// xyz: the box maximum.
        pub bounds_max: [f32; 4],
        /// Leaf: first entry of the instance order; interior: the second child (the first follows).
        pub index: u32,
        /// Instances in the leaf; 0 for an interior node.
        pub count: u32,
        /// Padding (0).
        pub pad0: u32,
        /// Padding (0).
        pub pad1: u32,
    }
}

gpu_struct! {
    /// A hit of the two-level kernel (32 bytes); `InstanceHit` on the host.
    #[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
    pub struct GpuInstanceHit {
        /// The world ray's parameter; +inf for a miss, NaN for an invalid or incomplete ray.
        pub t: f32,
        /// The triangle's index in its geometry, or a special `PRIM_*` value.
        pub prim_index: u32,
        /// Barycentric weight of `v1`.
        pub u: f32,
        /// Barycentric weight of `v2`.
        pub v: f32,
        /// The caller's instance id (`0xffffffff` for none).
        pub instance_id: u32,
        /// The caller's geometry id (`0xffffffff` for none).
        pub geometry_id: u32,
        /// 1 when the triangle faces the ray.
        pub front_face: u32,
        /// Index of the instance in the scene's list (`0xffffffff` for none).
        pub instance_index: u32,
    }
}
