// The engine's side of its contract with its own shaders (glsl/examples/*.comp),
// as examples/embed.rs would keep it: build.rs includes this file by path,
// passes `EXAMPLE_SHADER_DEFINES` to those shaders as `#define NAME value` and
// writes the GLSL declarations of the structs below into the generated header
// `engine.glsl` (beside kdtrace.glsl, the one header of kdtrace they include);
// examples/embed.rs includes it too, so each value and struct is written once,
// here. Structs are declared with `gpu_struct!` (src/gpu_struct.rs, included
// before this file).

/// Invocations per workgroup of the engine's shaders (`local_size_x` in both).
pub const ENGINE_WORKGROUP: u32 = 64;

// Descriptor bindings of `raygen.comp` (set 0).
/// The camera rays written (kdtrace `Ray`s).
pub const ENGINE_RAYGEN_BINDING_RAYS: u32 = 0;
/// Number of bindings of `raygen.comp`.
pub const ENGINE_RAYGEN_BINDINGS: u32 = 1;

// Descriptor bindings of `shade.comp` (set 0).
/// The rays traced (kdtrace `Ray`s).
pub const ENGINE_SHADE_BINDING_RAYS: u32 = 0;
/// Their hits (kdtrace `Hit`s).
pub const ENGINE_SHADE_BINDING_HITS: u32 = 1;
/// The engine's per-triangle surfaces.
pub const ENGINE_SHADE_BINDING_SURFACES: u32 = 2;
/// The RGBA8 pixels written.
pub const ENGINE_SHADE_BINDING_PIXELS: u32 = 3;
/// Number of bindings of `shade.comp`.
pub const ENGINE_SHADE_BINDINGS: u32 = 4;

// Descriptor bindings of `engine_shade.comp` (set 0; examples/engine.rs).
/// The rays traced (kdtrace `Ray`s).
pub const ENGINE_SCENE_BINDING_RAYS: u32 = 0;
/// Their hits (kdtrace's two-level `GpuInstanceHit`s: 32 bytes, with the
/// instance id, geometry id and triangle within the geometry).
pub const ENGINE_SCENE_BINDING_HITS: u32 = 1;
/// The engine's instances (`EngineInstance`), indexed by instance id.
pub const ENGINE_SCENE_BINDING_INSTANCES: u32 = 2;
/// The engine's meshes (`EngineMesh`), indexed by geometry id.
pub const ENGINE_SCENE_BINDING_MESHES: u32 = 3;
/// The interleaved vertices of every mesh (position xyz, normal xyz: 24 bytes).
pub const ENGINE_SCENE_BINDING_VERTICES: u32 = 4;
/// The index buffer of every mesh, as 32-bit words (u16 indices two to a word).
pub const ENGINE_SCENE_BINDING_INDICES: u32 = 5;
/// The RGBA8 pixels written.
pub const ENGINE_SCENE_BINDING_PIXELS: u32 = 6;
/// Number of bindings of `engine_shade.comp`.
pub const ENGINE_SCENE_BINDINGS: u32 = 7;

// Descriptor bindings of `layout_probe.comp` (tests/layout.rs).
/// Element 1 of a `ShadeParams` buffer.
pub const ENGINE_PROBE_BINDING_SHADE_PARAMS: u32 = 0;
/// Element 1 of a `Surface` buffer.
pub const ENGINE_PROBE_BINDING_SURFACES: u32 = 1;
/// The words written back.
pub const ENGINE_PROBE_BINDING_WORDS: u32 = 2;
/// Number of bindings of `layout_probe.comp` (read by tests/layout.rs only).
#[allow(dead_code)]
pub const ENGINE_PROBE_BINDINGS: u32 = 3;

gpu_struct! {
    /// Push constants of `raygen.comp`: the camera basis, scaled so that pixel
    /// (x, y) looks along forward + sx * right + sy * up with sx, sy in [-1, 1].
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct CameraParams {
        /// xyz: the eye.
        pub eye: [f32; 4],
        /// xyz: the unit view direction.
        pub forward: [f32; 4],
        /// xyz: right * tan(fov / 2) * aspect.
        pub right: [f32; 4],
        /// xyz: up * tan(fov / 2).
        pub up: [f32; 4],
        /// Image width.
        pub width: u32,
        /// Image height.
        pub height: u32,
        /// Padding to 16 bytes (0).
        pub pad0: u32,
        /// Padding to 16 bytes (0).
        pub pad1: u32,
    }
}

gpu_struct! {
    /// Push constants of `shade.comp`.
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct ShadeParams {
        /// Pixels shaded.
        pub count: u32,
    }
}

gpu_struct! {
    /// The engine's per-triangle surface data, indexed by `prim_id` (`shade.comp`).
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct Surface {
        /// xyz: unit geometric normal.
        pub normal: [f32; 4],
        /// rgb: the diffuse colour.
        pub albedo: [f32; 4],
        /// rgb: the emission, clamped to 1.
        pub emission: [f32; 4],
    }
}

gpu_struct! {
    /// Push constants of `engine_shade.comp`.
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct EngineShadeParams {
        /// Pixels shaded.
        pub count: u32,
        /// Padding (0).
        pub pad: u32,
    }
}

gpu_struct! {
    /// One instance of the engine's scene graph (`engine_shade.comp`).
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct EngineInstance {
        /// Rows 0-2 (xyz) of the normal matrix: the inverse transpose of the
        /// transform's linear part.
        pub normal_x: [f32; 4],
        /// Row 1.
        pub normal_y: [f32; 4],
        /// Row 2.
        pub normal_z: [f32; 4],
        /// rgb: the instance's colour.
        pub color: [f32; 4],
    }
}

gpu_struct! {
    /// Where one mesh's data sits in the vertex and index buffers.
    #[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
    pub struct EngineMesh {
        /// Its first vertex (24-byte vertices).
        pub first_vertex: u32,
        /// Its first index word.
        pub first_word: u32,
        /// 16 or 32: the index width.
        pub index_bits: u32,
        /// Padding to 16 bytes (0).
        pub pad: u32,
    }
}

/// Every constant above, as `#define`s for the example's shaders (read by build.rs).
#[allow(dead_code)]
pub const EXAMPLE_SHADER_DEFINES: &[(&str, u32)] = &[
    ("ENGINE_WORKGROUP", ENGINE_WORKGROUP),
    ("ENGINE_RAYGEN_BINDING_RAYS", ENGINE_RAYGEN_BINDING_RAYS),
    ("ENGINE_SHADE_BINDING_RAYS", ENGINE_SHADE_BINDING_RAYS),
    ("ENGINE_SHADE_BINDING_HITS", ENGINE_SHADE_BINDING_HITS),
    ("ENGINE_SHADE_BINDING_SURFACES", ENGINE_SHADE_BINDING_SURFACES),
    ("ENGINE_SHADE_BINDING_PIXELS", ENGINE_SHADE_BINDING_PIXELS),
    ("ENGINE_SCENE_BINDING_RAYS", ENGINE_SCENE_BINDING_RAYS),
    ("ENGINE_SCENE_BINDING_HITS", ENGINE_SCENE_BINDING_HITS),
    ("ENGINE_SCENE_BINDING_INSTANCES", ENGINE_SCENE_BINDING_INSTANCES),
    ("ENGINE_SCENE_BINDING_MESHES", ENGINE_SCENE_BINDING_MESHES),
    ("ENGINE_SCENE_BINDING_VERTICES", ENGINE_SCENE_BINDING_VERTICES),
    ("ENGINE_SCENE_BINDING_INDICES", ENGINE_SCENE_BINDING_INDICES),
    ("ENGINE_SCENE_BINDING_PIXELS", ENGINE_SCENE_BINDING_PIXELS),
    ("ENGINE_PROBE_BINDING_SHADE_PARAMS", ENGINE_PROBE_BINDING_SHADE_PARAMS),
    ("ENGINE_PROBE_BINDING_SURFACES", ENGINE_PROBE_BINDING_SURFACES),
    ("ENGINE_PROBE_BINDING_WORDS", ENGINE_PROBE_BINDING_WORDS),
];
