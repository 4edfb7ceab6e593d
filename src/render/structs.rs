// The std430 structs of the renderer's push constants, scene buffers and ray
// queues, each defined once with `gpu_struct!` (src/gpu_struct.rs). build.rs
// includes this file by path and writes their GLSL declarations into the
// generated header `render_structs.glsl`, which glsl/shared/render.glsl
// includes; glsl/render_layout_probe.comp and tests/layout.rs check every field
// on the device.

use bytemuck::{Pod, Zeroable};

gpu_struct! {
    /// One path of a ray queue, beside its `Ray` (32 bytes); written and read by
    /// the kernels only, mirrored for its size. render_shade.comp moves it as
    /// two `uvec4` words in this field order (`load_path`, `store_path`).
    #[derive(Clone, Copy, Pod, Zeroable)]
    #[allow(dead_code)]
    pub struct GpuPath as Path {
        /// Radiance weight of what this ray finds.
        pub throughput: [f32; 3],
        /// Row-major pixel index.
        pub pixel: u32,
        /// `PATH_*` flags.
        pub flags: u32,
        /// Segments traced before this one (camera ray: 0).
        pub depth: u32,
        /// Diffuse bounces taken so far.
        pub diffuse: u32,
        /// `PATH_MIS`: the float bits of the bounce direction's pdf (solid angle).
        pub pad: u32,
    }
}

gpu_struct! {
    /// One triangle for shading: its vertices, the material id's bits in `v0.w`
    /// (48 bytes; render_shade.comp reads it as three `rgba32ui` texels).
    #[derive(Clone, Copy, Pod, Zeroable)]
    pub struct Surface {
        /// xyz: vertex 0; w: the material id (uint bits).
        pub v0: [f32; 4],
        /// xyz: vertex 1.
        pub v1: [f32; 4],
        /// xyz: vertex 2.
        pub v2: [f32; 4],
    }
}

gpu_struct! {
    /// A material (48 bytes; render_shade.comp reads it as three `rgba32ui` texels).
    #[derive(Clone, Copy, Pod, Zeroable)]
    pub struct GpuMaterial as Material {
        /// xyz: Kd; w: Ns.
        pub kd: [f32; 4],
        /// xyz: Ks; w: the `MAT_*` flags as uint bits.
        pub ks: [f32; 4],
        /// xyz: Ke.
        pub ke: [f32; 4],
    }
}

gpu_struct! {
    /// An emissive triangle (or a quad lamp's parallelogram of two), for
    /// next-event estimation: chosen with probability `pick` (cumulative `cdf`),
    /// proportional to area × luminance of Ke (16 bytes).
    #[derive(Clone, Copy, Debug, Pod, Zeroable)]
    pub struct Emitter {
        /// The triangle, with `EMITTER_PARALLELOGRAM` and its corner above
        /// `EMITTER_PRIM_MASK` for a parallelogram (src/render/consts.rs).
        pub prim: u32,
        /// Cumulative probability of the emitters up to this one.
        pub cdf: f32,
        /// Probability of choosing this one.
        pub pick: f32,
        /// Its area (both triangles' for a parallelogram).
        pub area: f32,
    }
}

gpu_struct! {
    /// A point light (32 bytes).
    #[derive(Clone, Copy, Pod, Zeroable)]
    pub struct GpuLight as PointLight {
        /// xyz: position.
        pub position: [f32; 4],
        /// xyz: radiant intensity (W/sr per channel).
        pub intensity: [f32; 4],
    }
}

gpu_struct! {
    /// Push constants of every render pass (128 bytes, the guaranteed
    /// `maxPushConstantsSize`).
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
        /// xyz: radiance of rays that leave the scene; w: ambient radiance (ambient occlusion).
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
}
