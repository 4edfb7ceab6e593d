// Constants shared by the renderer (src/render) and its kernels
// (glsl/render_*.comp, glsl/shared/render.glsl). build.rs includes this file by
// path and passes `RENDER_SHADER_DEFINES` to every kernel as `#define NAME value`,
// beside src/consts.rs's, so each value is written once, here.

/// Invocations per workgroup of the render kernels (`local_size_x`).
pub const RENDER_WORKGROUP_SIZE: u32 = 64;

// Material flags (`Material.ks.w`, as uint bits).
/// Kd > 0.
pub const MAT_DIFFUSE: u32 = 1;
/// illum 2 with Ks > 0: a normalized Phong lobe for direct light.
pub const MAT_GLOSSY: u32 = 2;
/// illum 3 with Ks > 0: perfect reflection weighted by Ks.
pub const MAT_MIRROR: u32 = 4;
/// Ke > 0.
pub const MAT_EMISSIVE: u32 = 8;

// `Emitter.prim`: the triangle's index in the low bits; a parallelogram flag
// and its corner above.
/// The triangle index bits of `Emitter.prim`.
pub const EMITTER_PRIM_MASK: u32 = (1 << 29) - 1;
/// The emitter is the parallelogram of its triangle and the triangle mirrored
/// across the edge opposite the corner `(prim >> EMITTER_CORNER_SHIFT) & 3`
/// (a quad lamp's two triangles): sampled as one, by an affine map of the square.
pub const EMITTER_PARALLELOGRAM: u32 = 1 << 31;
/// Where the corner vertex (0..=2) of a parallelogram emitter sits in `Emitter.prim`.
pub const EMITTER_CORNER_SHIFT: u32 = 29;

// The render counters buffer: one block of `RC_STRIDE` `u32` per wave of a
// sample (wave 0: the camera rays' shading; wave w: the shading of the paths
// wave w - 1 appended), indexed within the block by `RC_*`.
/// Paths appended to the next queue.
pub const RC_NEXT: u32 = 0;
/// Shadow rays appended.
pub const RC_SHADOW: u32 = 1;
/// Rays the tracer reported invalid or incomplete.
pub const RC_BAD_RAYS: u32 = 2;
/// Shadow rays dropped for want of queue space (a bug if not 0).
pub const RC_OVERFLOW: u32 = 3;
/// Rasterized first hits the ray test put just outside their triangle.
pub const RC_RASTER_EDGE: u32 = 4;
/// The indirect dispatch arguments (x, y, z; x grown by the shade pass as it
/// appends) of the render kernels over the paths appended.
pub const RC_ARGS: u32 = 5;
/// Words per wave in the render counters buffer.
pub const RC_STRIDE: u32 = 8;
/// Flag of `RenderParams::count` in the dispatches of wave w ≥ 1: the rest is w,
/// and the dispatch covers the paths counted in block w - 1 (without it, the
/// count is the dispatch's and the wave is 0).
pub const RC_WAVE: u32 = 1 << 31;

// Jitter modes of `render_raygen.comp` (its specialization constant `JITTER`).
/// One sample per pixel: through the pixel centre.
pub const JITTER_NONE: u32 = 0;
/// A jitter per pixel and sample.
pub const JITTER_PER_PIXEL: u32 = 1;
/// One jitter per sample for the whole image (rasterized first hits).
pub const JITTER_PER_SAMPLE: u32 = 2;

// Descriptor bindings of `render_raygen.comp` (set 0).
/// The row-major index of each pixel in tracing order (`u32`, read-only).
pub const RAYGEN_BINDING_PIXELS: u32 = 0;
/// The camera rays written (`Ray`s).
pub const RAYGEN_BINDING_RAYS: u32 = 1;
/// Their paths (`Path`s).
pub const RAYGEN_BINDING_PATHS: u32 = 2;
/// Number of bindings of `render_raygen.comp`.
pub const RAYGEN_BINDINGS: u32 = 3;

// Descriptor bindings of `render_shade.comp` (set 0).
/// Per-triangle `Surface`s.
pub const SHADE_BINDING_SURFACES: u32 = 0;
/// `Material`s.
pub const SHADE_BINDING_MATERIALS: u32 = 1;
/// Emissive triangles (`Emitter`s).
pub const SHADE_BINDING_EMITTERS: u32 = 2;
/// Point lights (`PointLight`s).
pub const SHADE_BINDING_LIGHTS: u32 = 3;
/// The rays of the queue shaded.
pub const SHADE_BINDING_RAYS_IN: u32 = 4;
/// Their paths.
pub const SHADE_BINDING_PATHS_IN: u32 = 5;
/// Their hits.
pub const SHADE_BINDING_HITS_IN: u32 = 6;
/// The rays of the next queue (written).
pub const SHADE_BINDING_RAYS_NEXT: u32 = 7;
/// Their paths (written).
pub const SHADE_BINDING_PATHS_NEXT: u32 = 8;
/// The shadow rays (written).
pub const SHADE_BINDING_SHADOW_RAYS: u32 = 9;
/// The shadow rays' radiance weights (`vec4`, written).
pub const SHADE_BINDING_SHADOW_WEIGHTS: u32 = 10;
/// Where each path's shadow rays start (`uvec2`, written).
pub const SHADE_BINDING_SPANS: u32 = 11;
/// The render counters (`RC_*`).
pub const SHADE_BINDING_COUNTERS: u32 = 12;
/// The accumulation buffer (`vec4` per pixel).
pub const SHADE_BINDING_ACCUM: u32 = 13;
/// Number of bindings of `render_shade.comp`.
pub const SHADE_BINDINGS: u32 = 14;

// Descriptor bindings of `render_resolve.comp` (set 0).
/// The paths of the queue shaded.
pub const RESOLVE_BINDING_PATHS: u32 = 0;
/// Where each path's shadow rays start.
pub const RESOLVE_BINDING_SPANS: u32 = 1;
/// The shadow rays' hits.
pub const RESOLVE_BINDING_SHADOW_HITS: u32 = 2;
/// The shadow rays' radiance weights.
pub const RESOLVE_BINDING_SHADOW_WEIGHTS: u32 = 3;
/// The accumulation buffer.
pub const RESOLVE_BINDING_ACCUM: u32 = 4;
/// The render counters.
pub const RESOLVE_BINDING_COUNTERS: u32 = 5;
/// Number of bindings of `render_resolve.comp`.
pub const RESOLVE_BINDINGS: u32 = 6;

// Descriptor bindings of `render_visibility.comp` (set 0).
/// The row-major index of each pixel in tracing order.
pub const VISIBILITY_BINDING_PIXELS: u32 = 0;
/// The rasterized visibility buffer (a primitive per pixel).
pub const VISIBILITY_BINDING_VISIBILITY: u32 = 1;
/// Per-triangle `Surface`s.
pub const VISIBILITY_BINDING_SURFACES: u32 = 2;
/// The camera rays written.
pub const VISIBILITY_BINDING_RAYS: u32 = 3;
/// Their hits written.
pub const VISIBILITY_BINDING_HITS: u32 = 4;
/// The render counters.
pub const VISIBILITY_BINDING_COUNTERS: u32 = 5;
/// Number of bindings of `render_visibility.comp`.
pub const VISIBILITY_BINDINGS: u32 = 6;

// Descriptor bindings of `render_layout_probe.comp` (tests only).
/// Element 1 of a `Surface` buffer.
pub const RENDER_PROBE_BINDING_SURFACES: u32 = 0;
/// Element 1 of a `Material` buffer.
pub const RENDER_PROBE_BINDING_MATERIALS: u32 = 1;
/// Element 1 of an `Emitter` buffer.
pub const RENDER_PROBE_BINDING_EMITTERS: u32 = 2;
/// Element 1 of a `PointLight` buffer.
pub const RENDER_PROBE_BINDING_LIGHTS: u32 = 3;
/// Element 1 of a `Path` buffer.
pub const RENDER_PROBE_BINDING_PATHS: u32 = 4;
/// The words written back.
pub const RENDER_PROBE_BINDING_WORDS: u32 = 5;
/// Number of bindings of `render_layout_probe.comp`.
#[allow(dead_code)]
pub const RENDER_PROBE_BINDINGS: u32 = 6;

// Specialization constant ids of the render kernels (32-bit each; bools as 0/1).
/// `render_raygen.comp`'s jitter mode (`JITTER_*`).
pub const RAYGEN_SPEC_JITTER: u32 = 0;
/// Number of specialization constants of `render_raygen.comp`.
pub const RAYGEN_SPECS: u32 = 1;
/// `render_shade.comp`: The eye light, no shadow rays (`bool`).
pub const SHADE_SPEC_HEADLIGHT: u32 = 0;
/// `render_shade.comp`: Point lights (`--light`).
pub const SHADE_SPEC_POINT_LIGHTS: u32 = 1;
/// `render_shade.comp`: Emissive triangles (Ke).
pub const SHADE_SPEC_AREA_LIGHTS: u32 = 2;
/// `render_shade.comp`: Mirrors (illum 3 materials).
pub const SHADE_SPEC_MIRRORS: u32 = 3;
/// `render_shade.comp`: Glossy highlights (illum 2).
pub const SHADE_SPEC_GLOSSY: u32 = 4;
/// `render_shade.comp`: Ambient occlusion (`--ao N`).
pub const SHADE_SPEC_AO: u32 = 5;
/// `render_shade.comp`: Diffuse bounces (`--bounces N`).
pub const SHADE_SPEC_BOUNCES: u32 = 6;
/// `render_shade.comp`: A next queue exists: paths continue.
pub const SHADE_SPEC_CONTINUE: u32 = 7;
/// `render_shade.comp`: Trace the eye light's visibility (`--no-skip`).
pub const SHADE_SPEC_HEADLIGHT_SHADOWS: u32 = 8;
/// Number of specialization constants of `render_shade.comp`.
pub const SHADE_SPECS: u32 = 9;
/// `render_visibility.comp`: the robust ray test of rasterized hits (`bool`).
pub const VISIBILITY_SPEC_ROBUST: u32 = 0;
/// Number of specialization constants of `render_visibility.comp`.
pub const VISIBILITY_SPECS: u32 = 1;

/// Every constant above, as `#define`s for the shaders (read by build.rs).
#[allow(dead_code)]
pub const RENDER_SHADER_DEFINES: &[(&str, u32)] = &[
    ("RENDER_WORKGROUP_SIZE", RENDER_WORKGROUP_SIZE),
    ("MAT_DIFFUSE", MAT_DIFFUSE),
    ("MAT_GLOSSY", MAT_GLOSSY),
    ("MAT_MIRROR", MAT_MIRROR),
    ("MAT_EMISSIVE", MAT_EMISSIVE),
    ("EMITTER_PRIM_MASK", EMITTER_PRIM_MASK),
    ("EMITTER_PARALLELOGRAM", EMITTER_PARALLELOGRAM),
    ("EMITTER_CORNER_SHIFT", EMITTER_CORNER_SHIFT),
    ("RC_NEXT", RC_NEXT),
    ("RC_SHADOW", RC_SHADOW),
    ("RC_BAD_RAYS", RC_BAD_RAYS),
    ("RC_OVERFLOW", RC_OVERFLOW),
    ("RC_RASTER_EDGE", RC_RASTER_EDGE),
    ("RC_ARGS", RC_ARGS),
    ("RC_STRIDE", RC_STRIDE),
    ("RC_WAVE", RC_WAVE),
    ("JITTER_NONE", JITTER_NONE),
    ("JITTER_PER_PIXEL", JITTER_PER_PIXEL),
    ("JITTER_PER_SAMPLE", JITTER_PER_SAMPLE),
    ("RAYGEN_BINDING_PIXELS", RAYGEN_BINDING_PIXELS),
    ("RAYGEN_BINDING_RAYS", RAYGEN_BINDING_RAYS),
    ("RAYGEN_BINDING_PATHS", RAYGEN_BINDING_PATHS),
    ("SHADE_BINDING_SURFACES", SHADE_BINDING_SURFACES),
    ("SHADE_BINDING_MATERIALS", SHADE_BINDING_MATERIALS),
    ("SHADE_BINDING_EMITTERS", SHADE_BINDING_EMITTERS),
    ("SHADE_BINDING_LIGHTS", SHADE_BINDING_LIGHTS),
    ("SHADE_BINDING_RAYS_IN", SHADE_BINDING_RAYS_IN),
    ("SHADE_BINDING_PATHS_IN", SHADE_BINDING_PATHS_IN),
    ("SHADE_BINDING_HITS_IN", SHADE_BINDING_HITS_IN),
    ("SHADE_BINDING_RAYS_NEXT", SHADE_BINDING_RAYS_NEXT),
    ("SHADE_BINDING_PATHS_NEXT", SHADE_BINDING_PATHS_NEXT),
    ("SHADE_BINDING_SHADOW_RAYS", SHADE_BINDING_SHADOW_RAYS),
    ("SHADE_BINDING_SHADOW_WEIGHTS", SHADE_BINDING_SHADOW_WEIGHTS),
    ("SHADE_BINDING_SPANS", SHADE_BINDING_SPANS),
    ("SHADE_BINDING_COUNTERS", SHADE_BINDING_COUNTERS),
    ("SHADE_BINDING_ACCUM", SHADE_BINDING_ACCUM),
    ("RESOLVE_BINDING_PATHS", RESOLVE_BINDING_PATHS),
    ("RESOLVE_BINDING_SPANS", RESOLVE_BINDING_SPANS),
    ("RESOLVE_BINDING_SHADOW_HITS", RESOLVE_BINDING_SHADOW_HITS),
    ("RESOLVE_BINDING_SHADOW_WEIGHTS", RESOLVE_BINDING_SHADOW_WEIGHTS),
    ("RESOLVE_BINDING_ACCUM", RESOLVE_BINDING_ACCUM),
    ("RESOLVE_BINDING_COUNTERS", RESOLVE_BINDING_COUNTERS),
    ("VISIBILITY_BINDING_PIXELS", VISIBILITY_BINDING_PIXELS),
    ("VISIBILITY_BINDING_VISIBILITY", VISIBILITY_BINDING_VISIBILITY),
    ("VISIBILITY_BINDING_SURFACES", VISIBILITY_BINDING_SURFACES),
    ("VISIBILITY_BINDING_RAYS", VISIBILITY_BINDING_RAYS),
    ("VISIBILITY_BINDING_HITS", VISIBILITY_BINDING_HITS),
    ("VISIBILITY_BINDING_COUNTERS", VISIBILITY_BINDING_COUNTERS),
    ("RENDER_PROBE_BINDING_SURFACES", RENDER_PROBE_BINDING_SURFACES),
    ("RENDER_PROBE_BINDING_MATERIALS", RENDER_PROBE_BINDING_MATERIALS),
    ("RENDER_PROBE_BINDING_EMITTERS", RENDER_PROBE_BINDING_EMITTERS),
    ("RENDER_PROBE_BINDING_LIGHTS", RENDER_PROBE_BINDING_LIGHTS),
    ("RENDER_PROBE_BINDING_PATHS", RENDER_PROBE_BINDING_PATHS),
    ("RENDER_PROBE_BINDING_WORDS", RENDER_PROBE_BINDING_WORDS),
    ("RAYGEN_SPEC_JITTER", RAYGEN_SPEC_JITTER),
    ("SHADE_SPEC_HEADLIGHT", SHADE_SPEC_HEADLIGHT),
    ("SHADE_SPEC_POINT_LIGHTS", SHADE_SPEC_POINT_LIGHTS),
    ("SHADE_SPEC_AREA_LIGHTS", SHADE_SPEC_AREA_LIGHTS),
    ("SHADE_SPEC_MIRRORS", SHADE_SPEC_MIRRORS),
    ("SHADE_SPEC_GLOSSY", SHADE_SPEC_GLOSSY),
    ("SHADE_SPEC_AO", SHADE_SPEC_AO),
    ("SHADE_SPEC_BOUNCES", SHADE_SPEC_BOUNCES),
    ("SHADE_SPEC_CONTINUE", SHADE_SPEC_CONTINUE),
    ("SHADE_SPEC_HEADLIGHT_SHADOWS", SHADE_SPEC_HEADLIGHT_SHADOWS),
    ("VISIBILITY_SPEC_ROBUST", VISIBILITY_SPEC_ROBUST),
];
