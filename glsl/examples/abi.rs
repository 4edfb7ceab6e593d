// The engine's side of its contract with its own shaders (glsl/examples/*.comp),
// as examples/embed.rs would keep it: build.rs includes this file by path and
// passes `EXAMPLE_SHADER_DEFINES` to those shaders as `#define NAME value`
// (beside kdtrace.glsl, the one header of kdtrace they include), and
// examples/embed.rs includes it too, so each value is written once, here.

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

/// Every constant above, as `#define`s for the example's shaders (read by build.rs).
#[allow(dead_code)]
pub const EXAMPLE_SHADER_DEFINES: &[(&str, u32)] = &[
    ("ENGINE_WORKGROUP", ENGINE_WORKGROUP),
    ("ENGINE_RAYGEN_BINDING_RAYS", ENGINE_RAYGEN_BINDING_RAYS),
    ("ENGINE_SHADE_BINDING_RAYS", ENGINE_SHADE_BINDING_RAYS),
    ("ENGINE_SHADE_BINDING_HITS", ENGINE_SHADE_BINDING_HITS),
    ("ENGINE_SHADE_BINDING_SURFACES", ENGINE_SHADE_BINDING_SURFACES),
    ("ENGINE_SHADE_BINDING_PIXELS", ENGINE_SHADE_BINDING_PIXELS),
];
