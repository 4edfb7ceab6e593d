//! The wavefront renderer: Whitted-style and path-traced images from ray queues.
//!
//! Each sample of each pixel is a path. The passes, all on the device:
//!
//! 1. `render_raygen.comp` writes one camera ray per pixel into queue A;
//! 2. the tracer traces queue A (closest hit);
//! 3. `render_shade.comp` shades the hits: it adds emission, background and the
//!    headlight to the pixel, appends shadow rays (point lights, one sample of the
//!    emissive triangles, ambient occlusion) with the radiance each brings if
//!    unoccluded, and appends the path's next ray (mirror reflection or diffuse
//!    bounce) to queue B. Appending by atomic counter compacts both queues;
//! 4. the tracer traces the shadow queue (any hit), and `render_resolve.comp` adds
//!    the unoccluded contributions to the pixels;
//! 5. queues A and B swap, and 2–4 repeat until no path is left.
//!
//! The host reads back only the two queue counters after each shade pass, and
//! the image at the end. [`RenderPlan`] decides from the scene and the settings
//! what a render needs; what it does not need is neither uploaded, compiled nor
//! dispatched (see [`RenderPlan::explain`]).

use std::time::Instant;

use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::error::{Error, Result};
use crate::gpu::{
    shaders, Buffer, BufferRange, BufferSet, GpuContext, Kernel, KernelDesc, RasterView, Rasterizer, Timestamps,
};
use crate::kdtree::traverse::Traversal;
use crate::scene::{Camera, Scene};
use crate::trace::{TraceBinding, TraceOptions, Tracer};

/// A point light (`kdtrace render --light x,y,z[,intensity]`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointLight {
    /// Its position.
    pub position: Vec3,
    /// Radiant intensity per channel (radiance × area per steradian): a surface
    /// facing it at distance d receives irradiance `intensity / d²`.
    pub intensity: Vec3,
}

/// What to render and how.
#[derive(Clone, Debug)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Samples per pixel (1 = one ray through each pixel centre; more are
    /// jittered by a seeded, Owen-scrambled Sobol sequence).
    pub spp: u32,
    /// Ray segments per path at most (camera ray included).
    pub max_depth: u32,
    /// Diffuse bounces per path (path-traced indirect light); 0 = direct light only.
    pub bounces: u32,
    /// Ambient-occlusion rays at the first diffuse hit; 0 = none.
    pub ao_samples: u32,
    /// Length of the ambient-occlusion rays (default: a tenth of the scene's diagonal).
    pub ao_radius: Option<f32>,
    /// Ambient radiance that ambient occlusion lets through (default 1 when the
    /// scene has no other light, else 0.1).
    pub ambient: Option<f32>,
    /// Point lights.
    pub lights: Vec<PointLight>,
    /// Radiance of rays that leave the scene (default 0; with neither lights,
    /// emitters, ambient occlusion nor a background the renderer uses a headlight).
    pub background: Option<Vec3>,
    /// Seed of the sample sequence.
    pub seed: u32,
    /// The traversal for closest hits (its any-hit twin traces the shadow rays).
    pub traversal: Traversal,
    /// Skip what the scene does not need (default). Off: every shading feature
    /// compiled in, every buffer and pipeline made, the headlight's shadow rays
    /// traced: what a renderer that does not inspect the scene does, to measure
    /// the saving.
    pub skip_unneeded: bool,
    /// How the camera rays' first hits are found.
    pub primary: Primary,
    /// Keep the first hits of the first sample ([`RenderOutput::first_hits`]).
    pub keep_first_hits: bool,
}

/// How the first hits are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Primary {
    /// Trace the camera rays (closest hit).
    Trace,
    /// Rasterize a visibility buffer (a graphics pipeline: triangle number per
    /// pixel), then intersect each pixel's camera ray with its triangle alone.
    /// Sub-pixel jitter is then one offset per sample for the whole image.
    Raster,
}

impl RenderSettings {
    /// One sample per pixel, direct light only, the stack traversal.
    pub fn new(width: u32, height: u32) -> Self {
        RenderSettings {
            width,
            height,
            spp: 1,
            max_depth: 8,
            bounces: 0,
            ao_samples: 0,
            ao_radius: None,
            ambient: None,
            lights: Vec::new(),
            background: None,
            seed: 0,
            traversal: Traversal::closest(crate::kdtree::traverse::Variant::Stack),
            skip_unneeded: true,
            primary: Primary::Trace,
            keep_first_hits: false,
        }
    }

    fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidInput(m));
        if self.width == 0 || self.height == 0 || self.width > 16384 || self.height > 16384 {
            return bad(format!("image size {}x{}: width and height must be in 1..=16384", self.width, self.height));
        }
        if !(1..=1 << 20).contains(&self.spp) {
            return bad(format!("{} samples per pixel: must be in 1..=1048576", self.spp));
        }
        if !(1..=64).contains(&self.max_depth) {
            return bad(format!("max depth {}: must be in 1..=64", self.max_depth));
        }
        if self.bounces > 64 {
            return bad(format!("{} bounces: at most 64", self.bounces));
        }
        if self.ao_samples > 256 {
            return bad(format!("{} ambient-occlusion rays: at most 256", self.ao_samples));
        }
        if let Some(r) = self.ao_radius {
            if !(r.is_finite() && r > 0.0) {
                return bad(format!("ambient-occlusion radius {r}: must be finite and positive"));
            }
        }
        if let Some(a) = self.ambient {
            if !(a.is_finite() && a >= 0.0) {
                return bad(format!("ambient {a}: must be finite and not negative"));
            }
        }
        if self.lights.len() > MAX_LIGHTS as usize {
            return bad(format!("{} point lights: at most {MAX_LIGHTS}", self.lights.len()));
        }
        for l in &self.lights {
            if !l.position.is_finite() || !l.intensity.is_finite() || l.intensity.min_element() < 0.0 {
                return bad(format!(
                    "point light at {} with intensity {}: position and intensity must be finite, intensity not negative",
                    l.position, l.intensity
                ));
            }
        }
        if let Some(b) = self.background {
            if !b.is_finite() || b.min_element() < 0.0 {
                return bad(format!("background {b}: must be finite and not negative"));
            }
        }
        self.traversal.validate()
    }
}

/// Point lights one render takes at most.
pub const MAX_LIGHTS: u32 = 64;

/// Material flags, as `render.glsl`'s `MAT_*`.
const MAT_DIFFUSE: u32 = 1;
const MAT_GLOSSY: u32 = 2;
const MAT_MIRROR: u32 = 4;
const MAT_EMISSIVE: u32 = 8;

/// Indices of the render counters (`RC_*` in `render.glsl`).
const RC_NEXT: usize = 0;
const RC_SHADOW: usize = 1;
const RC_BAD_RAYS: usize = 2;
const RC_OVERFLOW: usize = 3;
const RC_RASTER_EDGE: usize = 4;
const RC_COUNT: usize = 5;

/// Jitter modes of `render_raygen.comp` (its specialization constant 0).
const JITTER_NONE: u32 = 0;
const JITTER_PER_PIXEL: u32 = 1;
const JITTER_PER_SAMPLE: u32 = 2;

fn hash_u32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^ (x >> 16)
}

fn owen_scramble(x: u32, seed: u32) -> u32 {
    let mut x = x.reverse_bits().wrapping_add(seed);
    for m in [0x6c50_b47c_u32, 0xb82f_1e52, 0xc7af_e638, 0x8d22_f6e6] {
        x ^= x.wrapping_mul(m);
    }
    x.reverse_bits()
}

fn sobol_second(index: u32) -> u32 {
    let (mut result, mut v, mut i) = (0u32, 1u32 << 31, index);
    while i != 0 {
        if i & 1 != 0 {
            result ^= v;
        }
        v ^= v >> 1;
        i >>= 1;
    }
    result
}

/// The host twin of `ld2` in `render.glsl` (same construction): the point of
/// the scrambled 2D Sobol set for (`pixel`, `sample`, dimension `pair`, `seed`).
/// Used for the one jitter per sample of rasterized first hits, which the host
/// passes to both the projection and the camera rays.
pub fn ld2(pixel: u32, sample: u32, pair: u32, seed: u32) -> [f32; 2] {
    let h = hash_u32(pixel.wrapping_mul(0x9e37_79b9) ^ hash_u32(pair.wrapping_mul(0x85eb_ca6b) ^ hash_u32(seed)));
    let i = owen_scramble(sample, h);
    let x = owen_scramble(i.reverse_bits(), hash_u32(h ^ 0x68bc_21eb));
    let y = owen_scramble(sobol_second(i), hash_u32(h ^ 0x02e5_be93));
    [(x >> 8) as f32 / 16_777_216.0, (y >> 8) as f32 / 16_777_216.0]
}

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

/// `Surface` of `render.glsl`: the vertices, the material id's bits in `v0.w`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct Surface {
    v: [[f32; 4]; 3],
}

/// `Material` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuMaterial {
    kd_ns: [f32; 4],
    ks_flags: [f32; 4],
    ke: [f32; 4],
}

/// `Emitter` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct Emitter {
    prim: u32,
    cdf: f32,
    pick: f32,
    area: f32,
}

/// `PointLight` of `render.glsl`.
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct GpuLight {
    position: [f32; 4],
    intensity: [f32; 4],
}

fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

fn material_flags(m: &crate::scene::Material) -> u32 {
    let mut flags = 0;
    if m.kd.max_element() > 0.0 {
        flags |= MAT_DIFFUSE;
    }
    if m.illum == 2 && m.ks.max_element() > 0.0 {
        flags |= MAT_GLOSSY;
    }
    if m.illum == 3 && m.ks.max_element() > 0.0 {
        flags |= MAT_MIRROR;
    }
    if m.ke.max_element() > 0.0 {
        flags |= MAT_EMISSIVE;
    }
    flags
}

/// What a render needs, decided from the scene and the settings before anything
/// is uploaded or compiled. Each `bool` is a specialization constant of the shade
/// pass or selects a pass or buffer.
#[derive(Clone, Debug)]
pub struct RenderPlan {
    /// Eye light: no lights, emitters, ambient occlusion or background.
    pub headlight: bool,
    /// The headlight's visibility traced as shadow rays (only without skipping:
    /// the camera ray itself proves the eye sees the point).
    pub headlight_shadows: bool,
    /// Point-light shadow rays.
    pub point_lights: bool,
    /// Next-event estimation toward emissive triangles.
    pub area_lights: bool,
    /// Mirror reflections (illum 3).
    pub mirrors: bool,
    /// Phong highlights (illum 2).
    pub glossy: bool,
    /// Ambient occlusion.
    pub ao: bool,
    /// Diffuse bounces.
    pub bounces: bool,
    /// Paths continue past their first hit (mirrors or bounces): a second queue.
    pub continue_paths: bool,
    /// Shadow rays exist: the any-hit pipeline, the shadow queue, the resolve pass.
    pub shadow_pass: bool,
    /// Camera rays jittered inside the pixel (more than one sample per pixel).
    pub jitter: bool,
    /// First hits rasterized ([`Primary::Raster`]).
    pub raster: bool,
    /// Shadow rays one path vertex may cast at most.
    pub shadow_per_vertex: u32,
    /// Background radiance.
    pub background: Vec3,
    /// Ambient radiance for ambient occlusion.
    pub ambient: f32,
    /// Ambient-occlusion ray length.
    pub ao_radius: f32,
    emitters: Vec<Emitter>,
    emitter_weight: f32,
    explain: Vec<String>,
}

impl RenderPlan {
    /// Inspects `scene` and `settings`.
    pub fn new(scene: &Scene, settings: &RenderSettings) -> Result<RenderPlan> {
        settings.validate()?;
        let flags: Vec<u32> = scene.materials.iter().map(material_flags).collect();
        let count_with = |flag: u32| scene.material_ids.iter().filter(|&&m| flags[m as usize] & flag != 0).count();
        let (mirror_tris, glossy_tris) = (count_with(MAT_MIRROR), count_with(MAT_GLOSSY));

        // Emissive triangles, picked in proportion to area × luminance of Ke.
        let mut emitters = Vec::new();
        let mut total = 0.0f64;
        for (prim, tri) in scene.triangles.iter().enumerate() {
            let m = scene.material(prim as u32);
            if flags[scene.material_ids[prim] as usize] & MAT_EMISSIVE == 0 {
                continue;
            }
            let [a, b, c] = tri.map(|v| v.as_dvec3());
            let area = 0.5 * (b - a).cross(c - a).length();
            let weight = area * f64::from(luminance(m.ke)).max(1e-6);
            if area > 0.0 && weight.is_finite() {
                total += weight;
                emitters.push((prim as u32, area, weight));
            }
        }
        let mut cumulative = 0.0;
        let emitters: Vec<Emitter> = emitters
            .iter()
            .map(|&(prim, area, weight)| {
                cumulative += weight;
                Emitter { prim, cdf: (cumulative / total) as f32, pick: (weight / total) as f32, area: area as f32 }
            })
            .collect();
        let emitter_tris = emitters.len();

        let lights = !settings.lights.is_empty();
        let ao = settings.ao_samples > 0;
        let headlight = !lights && emitter_tris == 0 && !ao && settings.background.is_none();
        let skip = settings.skip_unneeded;
        let mirrors = mirror_tris > 0;
        let bounces = settings.bounces > 0 && !headlight;
        let continue_paths = settings.max_depth > 1 && (mirrors || bounces);
        let headlight_shadows = headlight && !skip;
        let shadow_per_vertex = settings.lights.len() as u32
            + u32::from(emitter_tris > 0)
            + settings.ao_samples
            + u32::from(headlight_shadows);
        let shadow_pass = shadow_per_vertex > 0;
        let diagonal = scene.bounds.extent().length();
        let ambient = settings.ambient.unwrap_or(if lights || emitter_tris > 0 { 0.1 } else { 1.0 });
        let ao_radius = settings.ao_radius.unwrap_or(0.1 * diagonal).max(f32::MIN_POSITIVE);

        let on_off = |b: bool| if b { "on" } else { "skipped" };
        let mut explain = Vec::new();
        explain.push(format!(
            "point lights: {} (--light) -> point-light shadow rays {}",
            settings.lights.len(),
            on_off(lights)
        ));
        explain.push(match emitter_tris {
            0 => "emitters: no triangle has a Ke -> area-light sampling and the emitter buffer skipped".into(),
            n => format!("emitters: {n} triangles with Ke -> next-event estimation toward them on"),
        });
        explain.push(match mirror_tris {
            0 => "mirrors: no illum-3 material with Ks -> reflection code skipped".into(),
            n => format!("mirrors: {n} triangles of illum-3 materials -> reflection rays on"),
        });
        explain.push(match glossy_tris {
            0 => "highlights: no illum-2 material with Ks -> Phong lobe skipped".into(),
            n => format!("highlights: {n} triangles of illum-2 materials -> Phong lobe on"),
        });
        explain.push(if ao {
            format!("ambient occlusion: {} rays of length {ao_radius} at the first diffuse hit", settings.ao_samples)
        } else {
            "ambient occlusion: off (--ao 0) -> skipped".into()
        });
        explain.push(if bounces {
            format!("diffuse bounces: up to {} (cosine-weighted)", settings.bounces)
        } else if settings.bounces > 0 {
            "diffuse bounces: requested, but with a headlight there is no light to bounce -> skipped".into()
        } else {
            "diffuse bounces: off (--bounces 0) -> skipped".into()
        });
        explain.push(if continue_paths {
            format!("paths continue past the first hit (up to {} segments): second ray queue on", settings.max_depth)
        } else {
            "paths end at their first hit (no mirrors, no bounces): second ray queue and its passes skipped".into()
        });
        if headlight {
            explain.push(if skip {
                "headlight: no lights, emitters, AO or background -> eye light; its shadow rays skipped, since the \
                 camera ray proves the eye sees the point"
                    .into()
            } else {
                "headlight: no lights, emitters, AO or background -> eye light, its shadow rays traced (--no-skip)"
                    .into()
            });
        }
        explain.push(if shadow_pass {
            format!("shadow rays: up to {shadow_per_vertex} per hit -> any-hit pipeline, shadow queue, resolve pass on")
        } else {
            "shadow rays: none -> the any-hit pipeline is not compiled, no shadow queue, no resolve pass".into()
        });
        explain.push(if settings.spp > 1 {
            format!(
                "samples: {} per pixel, jittered by an Owen-scrambled Sobol sequence (seed {})",
                settings.spp, settings.seed
            )
        } else {
            "samples: 1 per pixel through the pixel centres -> jitter skipped".into()
        });
        explain.push(match settings.primary {
            Primary::Trace => "first hits: traced (closest hit of the camera rays); no graphics pipeline".into(),
            Primary::Raster => "first hits: rasterized into a visibility buffer, each pixel's ray tested against \
                                its triangle alone; the camera rays' trace skipped"
                .into(),
        });
        explain.push("textures: not supported (map_Kd and other maps are not read) -> none uploaded".into());
        explain.push("normals: geometric (OBJ vn are not read) -> no normal buffer".into());
        if !skip {
            explain.push("--no-skip: every shading feature compiled in, every buffer and pipeline made anyway".into());
        }

        Ok(RenderPlan {
            headlight,
            headlight_shadows,
            point_lights: lights || !skip,
            area_lights: emitter_tris > 0 || !skip,
            mirrors: mirrors || !skip,
            glossy: glossy_tris > 0 || !skip,
            ao: ao || !skip,
            bounces: bounces || !skip,
            continue_paths: continue_paths || !skip,
            shadow_pass: shadow_pass || !skip,
            jitter: settings.spp > 1,
            raster: settings.primary == Primary::Raster,
            shadow_per_vertex: shadow_per_vertex.max(1),
            background: settings.background.unwrap_or(if headlight { Vec3::splat(0.05) } else { Vec3::ZERO }),
            ambient,
            ao_radius,
            emitters,
            emitter_weight: total as f32,
            explain,
        })
    }

    /// What the render does and skips, one line per feature.
    pub fn explain(&self) -> &[String] {
        &self.explain
    }

    /// The shade pass's specialization constants (ids 0..=8 of `render_shade.comp`).
    fn shade_constants(&self) -> [u32; 9] {
        [
            self.headlight,
            self.point_lights,
            self.area_lights,
            self.mirrors,
            self.glossy,
            self.ao,
            self.bounces,
            self.continue_paths,
            self.headlight_shadows,
        ]
        .map(u32::from)
    }
}

/// What a render measured.
#[derive(Clone, Debug, Default)]
pub struct RenderStats {
    /// Camera rays (traced, or their first hits rasterized).
    pub camera_rays: u64,
    /// Reflection and bounce rays traced.
    pub secondary_rays: u64,
    /// Shadow and ambient-occlusion rays traced (any hit).
    pub shadow_rays: u64,
    /// GPU time of the trace dispatches (timestamps), when the device has them.
    pub trace_seconds: Option<f64>,
    /// GPU time of the ray generation, shade and resolve dispatches.
    pub shade_seconds: Option<f64>,
    /// Wall time of pipeline creation and uploads.
    pub setup_seconds: f64,
    /// Wall time of the sample loop (submits, waits, counter readbacks).
    pub render_seconds: f64,
    /// Queue submissions.
    pub submits: u32,
    /// Rays the tracer reported invalid or incomplete (0 unless something is wrong).
    pub bad_rays: u64,
    /// GPU time of the visibility-buffer draws and their conversion to hits.
    pub raster_seconds: Option<f64>,
    /// Rasterized first hits whose ray passes just outside their triangle (edge ties).
    pub raster_edge_pixels: u64,
    /// The first hits were rasterized ([`Primary::Raster`]).
    pub rasterized: bool,
}

impl RenderStats {
    /// All rays: camera, secondary and shadow.
    pub fn rays(&self) -> u64 {
        self.camera_rays + self.secondary_rays + self.shadow_rays
    }

    /// The rays the tracer traced: [`RenderStats::rays`] less the camera rays
    /// when their first hits were rasterized.
    pub fn traced_rays(&self) -> u64 {
        self.rays() - if self.rasterized { self.camera_rays } else { 0 }
    }
}

/// A rendered image: linear radiance, row-major from the top-left.
#[derive(Clone, Debug)]
pub struct RenderOutput {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Mean radiance of each pixel's samples.
    pub pixels: Vec<Vec3>,
    /// The plan it followed.
    pub plan: RenderPlan,
    /// The first hits of the first sample, row-major, when
    /// [`RenderSettings::keep_first_hits`] asked for them.
    pub first_hits: Option<Vec<crate::geom::Hit>>,
    /// What it measured.
    pub stats: RenderStats,
    /// Pixels (row-major indices) that had a ray the tracer marked invalid or
    /// incomplete in some sample: their value lacks that ray's light.
    pub bad_pixels: Vec<usize>,
}

/// One ray queue: rays, their paths and their hits.
struct Queue {
    rays: Buffer,
    paths: Buffer,
    hits: Buffer,
}

impl Queue {
    fn new(ctx: &std::sync::Arc<GpuContext>, capacity: u64, name: &str) -> Result<Queue> {
        // TRANSFER_SRC: the first hits may be read back (`keep_first_hits`).
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_SRC;
        let make = |bytes: u64, what: &str| {
            Buffer::new(ctx, capacity * bytes, usage, MemoryLocation::GpuOnly, &format!("{name} {what}"))
        };
        Ok(Queue { rays: make(32, "rays")?, paths: make(32, "paths")?, hits: make(16, "hits")? })
    }
}

/// Bytes of device memory the shadow queue may take (rays, weights, hits).
const SHADOW_QUEUE_BYTES: u64 = 256 << 20;

/// Renders `scene` (whose tree and triangles `tracer` holds) seen by `camera`.
/// `progress(done, total)` is called after each sample pass.
///
/// Errors: `Error::InvalidInput` for bad settings; `Error::DeviceLimit` when the
/// image or the scene exceed the device's buffer limits. Rays the tracer could
/// not finish (or invalid rays from degenerate geometry) do not fail the
/// render: they are counted in [`RenderStats::bad_rays`] and their pixels are
/// listed in [`RenderOutput::bad_pixels`].
pub fn render(
    tracer: &mut Tracer,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    progress: impl FnMut(u64, u64),
) -> Result<RenderOutput> {
    render_progressive(tracer, scene, camera, settings, 0, progress, |_, _| Ok(()))
}

/// [`render`], and every `every` samples per pixel (0: never) hands
/// `checkpoint(samples, image)` the mean of the samples so far (row-major
/// linear radiance), e.g. to write a progressive preview. Images that render in
/// several chunks (more than 2^20 pixels) get no checkpoints: their pixels do not
/// all reach a sample count at the same time.
pub fn render_progressive(
    tracer: &mut Tracer,
    scene: &Scene,
    camera: &Camera,
    settings: &RenderSettings,
    every: u32,
    mut progress: impl FnMut(u64, u64),
    mut checkpoint: impl FnMut(u32, &[Vec3]) -> Result<()>,
) -> Result<RenderOutput> {
    let setup_start = Instant::now();
    let plan = RenderPlan::new(scene, settings)?;
    let ctx = tracer.context().clone();
    if scene.triangles.len() != tracer.triangle_count() {
        return Err(Error::InvalidInput(format!(
            "the scene has {} triangles but the tracer holds {}",
            scene.triangles.len(),
            tracer.triangle_count()
        )));
    }
    let (width, height) = (settings.width, settings.height);
    let pixel_count = u64::from(width) * u64::from(height);
    let limit = ctx.info.max_storage_buffer_range;
    if pixel_count * 16 > limit || pixel_count * 16 > ctx.info.max_memory_allocation_size {
        return Err(Error::DeviceLimit(format!(
            "a {width}x{height} image needs {} bytes of accumulation buffer; the device allows {limit} per storage buffer",
            pixel_count * 16
        )));
    }
    // Pixels per chunk: the queues hold one chunk's paths.
    let shadow_per_path = u64::from(plan.shadow_per_vertex);
    let chunk = pixel_count
        .min(1 << 20)
        .min(limit / 32)
        .min((SHADOW_QUEUE_BYTES / (64 * shadow_per_path)).max(1024))
        .min(limit / (32 * shadow_per_path))
        .max(1);
    let shadow_capacity = chunk * shadow_per_path;

    // Kernels: only those the plan needs.
    let closest = TraceOptions { traversal: Traversal { any_hit: false, ..settings.traversal }, counters: false };
    let any_hit = TraceOptions { traversal: Traversal { any_hit: true, ..settings.traversal }, counters: false };
    let raygen = Kernel::new(
        &ctx,
        &KernelDesc {
            name: "render_raygen",
            spirv: shaders::RENDER_RAYGEN,
            bindings: 3,
            push_constant_size: 128,
            spec_constants: &[match (plan.jitter, plan.raster) {
                (false, _) => JITTER_NONE,
                (true, false) => JITTER_PER_PIXEL,
                (true, true) => JITTER_PER_SAMPLE,
            }],
            workgroup_size: 64,
            ..Default::default()
        },
    )?;
    let shade_constants = plan.shade_constants();
    let shade = Kernel::new(
        &ctx,
        &KernelDesc {
            name: "render_shade",
            spirv: shaders::RENDER_SHADE,
            bindings: 14,
            push_constant_size: 128,
            spec_constants: &shade_constants,
            workgroup_size: 64,
            ..Default::default()
        },
    )?;
    let resolve = match plan.shadow_pass {
        true => Some(Kernel::new(
            &ctx,
            &KernelDesc {
                name: "render_resolve",
                spirv: shaders::RENDER_RESOLVE,
                bindings: 6,
                push_constant_size: 128,
                workgroup_size: 64,
                ..Default::default()
            },
        )?),
        false => None,
    };
    tracer.prepare(&closest)?;
    if plan.shadow_pass {
        tracer.prepare(&any_hit)?;
    }

    // Scene data for shading.
    let storage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let surfaces: Vec<Surface> = scene
        .triangles
        .iter()
        .zip(&scene.material_ids)
        .map(|(t, &m)| {
            let v = |p: Vec3, w: f32| [p.x, p.y, p.z, w];
            Surface { v: [v(t[0], f32::from_bits(m)), v(t[1], 0.0), v(t[2], 0.0)] }
        })
        .collect();
    let surface_bytes = std::mem::size_of_val(surfaces.as_slice()) as u64;
    if surface_bytes > limit {
        return Err(Error::DeviceLimit(format!(
            "the shading data of {} triangles takes {surface_bytes} bytes; the device allows {limit} per storage buffer",
            surfaces.len()
        )));
    }
    let surfaces = Buffer::with_data(&ctx, bytemuck::cast_slice(&surfaces), storage, "surfaces")?;
    let materials: Vec<GpuMaterial> = scene
        .materials
        .iter()
        .map(|m| GpuMaterial {
            kd_ns: [m.kd.x, m.kd.y, m.kd.z, m.ns.clamp(0.0, 1e6)],
            ks_flags: [m.ks.x, m.ks.y, m.ks.z, f32::from_bits(material_flags(m))],
            ke: [m.ke.x, m.ke.y, m.ke.z, 0.0],
        })
        .collect();
    let materials = Buffer::with_data(&ctx, bytemuck::cast_slice(&materials), storage, "materials")?;
    let unused = || Buffer::new(&ctx, 16, storage, MemoryLocation::GpuOnly, "unused binding");
    let emitters = match (plan.emitters.is_empty(), plan.area_lights) {
        (false, _) => Buffer::with_data(&ctx, bytemuck::cast_slice(&plan.emitters), storage, "emitters")?,
        (true, false) => unused()?,
        (true, true) => Buffer::with_data(&ctx, &[0; 16], storage, "emitters (none)")?,
    };
    let gpu_lights: Vec<GpuLight> = settings
        .lights
        .iter()
        .map(|l| GpuLight {
            position: [l.position.x, l.position.y, l.position.z, 0.0],
            intensity: [l.intensity.x, l.intensity.y, l.intensity.z, 0.0],
        })
        .collect();
    let lights = match gpu_lights.is_empty() {
        false => Buffer::with_data(&ctx, bytemuck::cast_slice(&gpu_lights), storage, "point lights")?,
        true => unused()?,
    };
    let order = super::morton_pixels(width, height);
    let pixels = Buffer::with_data(&ctx, bytemuck::cast_slice(&order), storage, "pixel order")?;

    // Queues, counters and the accumulation buffer.
    let queue_a = Queue::new(&ctx, chunk, "queue A")?;
    let queue_b = if plan.continue_paths { Some(Queue::new(&ctx, chunk, "queue B")?) } else { None };
    let spans = Buffer::new(&ctx, chunk * 8, storage, MemoryLocation::GpuOnly, "shadow spans")?;
    let shadow = if plan.shadow_pass { Some(Queue::new(&ctx, shadow_capacity, "shadow")?) } else { None };
    let counters = Buffer::new(
        &ctx,
        RC_COUNT as u64 * 4,
        storage | vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuToCpu,
        "render counters",
    )?;
    let accum = Buffer::new(
        &ctx,
        pixel_count * 16,
        storage | vk::BufferUsageFlags::TRANSFER_DST | vk::BufferUsageFlags::TRANSFER_SRC,
        MemoryLocation::GpuOnly,
        "accumulation",
    )?;
    let readback =
        Buffer::new(&ctx, pixel_count * 16, vk::BufferUsageFlags::TRANSFER_DST, MemoryLocation::GpuToCpu, "image")?;
    let dummy = unused()?;

    // Descriptor sets: the shade and resolve passes of A→B and of B→A.
    let b_or_a = queue_b.as_ref().unwrap_or(&queue_a);
    let (shadow_rays, shadow_weights, shadow_hits) = match &shadow {
        Some(q) => (&q.rays, &q.paths, &q.hits),
        None => (&dummy, &dummy, &dummy),
    };
    let raygen_set = BufferSet::new(&ctx, &raygen, &[&pixels, &queue_a.rays, &queue_a.paths])?;
    let shade_set = |from: &Queue, to: &Queue| {
        BufferSet::new(
            &ctx,
            &shade,
            &[
                &surfaces,
                &materials,
                &emitters,
                &lights,
                &from.rays,
                &from.paths,
                &from.hits,
                &to.rays,
                &to.paths,
                shadow_rays,
                shadow_weights,
                &spans,
                &counters,
                &accum,
            ],
        )
    };
    let shade_sets = [shade_set(&queue_a, b_or_a)?, shade_set(b_or_a, &queue_a)?];
    let resolve_sets = match &resolve {
        Some(k) => {
            let set = |q: &Queue| {
                BufferSet::new(&ctx, k, &[&q.paths, &spans, shadow_hits, shadow_weights, &accum, &counters])
            };
            Some([set(&queue_a)?, set(b_or_a)?])
        }
        None => None,
    };
    // SAFETY: the ranges are whole storage buffers of this device, alive until
    // after the last submission below has completed.
    let trace_sets: [TraceBinding; 2] = unsafe {
        [
            tracer.bind(BufferRange::whole(&queue_a.rays), BufferRange::whole(&queue_a.hits), None, &closest)?,
            tracer.bind(BufferRange::whole(&b_or_a.rays), BufferRange::whole(&b_or_a.hits), None, &closest)?,
        ]
    };
    let shadow_set = match &shadow {
        // SAFETY: as above.
        Some(q) => {
            Some(unsafe { tracer.bind(BufferRange::whole(&q.rays), BufferRange::whole(&q.hits), None, &any_hit)? })
        }
        None => None,
    };
    // Rasterized first hits: the visibility-buffer pipeline, the buffer it is
    // copied to, and the pass that turns it into hits.
    let raster = match plan.raster {
        false => None,
        true => {
            let rasterizer = Rasterizer::new(&ctx, &scene.triangles, width, height)?;
            let visibility = Buffer::new(
                &ctx,
                rasterizer.visibility_bytes(),
                storage | vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuOnly,
                "visibility",
            )?;
            let kernel = Kernel::new(
                &ctx,
                &KernelDesc {
                    name: "render_visibility",
                    spirv: shaders::RENDER_VISIBILITY,
                    bindings: 6,
                    push_constant_size: 128,
                    spec_constants: &[u32::from(settings.traversal.robust)],
                    workgroup_size: 64,
                    ..Default::default()
                },
            )?;
            let set = BufferSet::new(
                &ctx,
                &kernel,
                &[&pixels, &visibility, &surfaces, &queue_a.rays, &queue_a.hits, &counters],
            )?;
            Some((rasterizer, visibility, kernel, set))
        }
    };
    // The first sample's hits, read back per chunk when asked for.
    let hit_readback = match settings.keep_first_hits {
        true => Some(Buffer::new(
            &ctx,
            chunk * 16,
            vk::BufferUsageFlags::TRANSFER_DST,
            MemoryLocation::GpuToCpu,
            "first hits",
        )?),
        false => None,
    };
    let mut first_hits = settings.keep_first_hits.then(|| vec![crate::geom::Hit::default(); pixel_count as usize]);
    let timestamps = Timestamps::new(&ctx, 2 * TIMESTAMP_PAIRS)?;
    let setup_seconds = setup_start.elapsed().as_secs_f64();

    // The sample loop.
    let [eye, forward, right, up] = camera.pinhole(width, height);
    // The rasterizer's near plane: geometry closer to the eye is clipped (a
    // trace would see it). A millionth of the scene's size and distance.
    let near = 1e-6 * (scene.bounds.extent().length() + (scene.bounds.center() - eye).length()).max(f32::MIN_POSITIVE);
    let v4 = |v: Vec3, w: f32| [v.x, v.y, v.z, w];
    let mut params = RenderParams {
        eye: v4(eye, 0.0),
        forward: v4(forward, plan.emitter_weight),
        right: v4(right, 0.0),
        up: v4(up, 0.0),
        background: v4(plan.background, plan.ambient),
        width,
        height,
        count: 0,
        sample_index: 0,
        seed: settings.seed,
        max_depth: settings.max_depth,
        bounces: settings.bounces,
        ao_samples: settings.ao_samples,
        ao_radius: plan.ao_radius,
        light_count: settings.lights.len() as u32,
        emitter_count: plan.emitters.len() as u32,
        shadow_capacity: shadow_capacity as u32,
    };
    let device = &ctx.device;
    let mut stats = RenderStats { setup_seconds, rasterized: raster.is_some(), ..Default::default() };
    let mut times = [0.0f64; 3]; // GPU seconds per `Kind`
    let loop_start = Instant::now();
    let chunks = pixel_count.div_ceil(chunk);
    let total = chunks * u64::from(settings.spp);
    let mut done = 0;
    // SAFETY (every block below): the buffers, sets, bindings and kernels live
    // until the end of this function, after every submission has completed.
    unsafe {
        ctx.submit_and_wait(|cmd| device.cmd_fill_buffer(cmd, accum.buffer, 0, vk::WHOLE_SIZE, 0))?;
    }
    for c in 0..chunks {
        let first_pixel = c * chunk;
        let chunk_pixels = (pixel_count - first_pixel).min(chunk) as u32;
        params.eye[3] = f32::from_bits(first_pixel as u32);
        for sample in 0..settings.spp {
            params.sample_index = sample;
            // One jitter per sample for the whole image when first hits are
            // rasterized: computed here once, for the projection and the camera rays.
            let jitter = if plan.jitter { ld2(0, sample, 0, settings.seed) } else { [0.5, 0.5] };
            params.right[3] = jitter[0];
            params.up[3] = jitter[1];
            // Submission 1: camera rays, their trace (or hits from the visibility buffer) and shade.
            let mut pass = Pass::new(&ctx, timestamps.as_ref());
            unsafe {
                ctx.submit_and_wait(|cmd| {
                    pass.begin(cmd, &counters);
                    params.count = chunk_pixels;
                    pass.shade(cmd, || {
                        raygen.record_dispatch(cmd, raygen_set.set, bytemuck::bytes_of(&params), chunk_pixels)
                    });
                    match &raster {
                        None => pass.trace(cmd, || tracer.record_binding(cmd, &trace_sets[0], chunk_pixels)),
                        Some((rasterizer, visibility, kernel, set)) => {
                            let view = RasterView::new(camera.pinhole(width, height), jitter, width, height, near);
                            pass.raster(cmd, || rasterizer.record(cmd, &view, visibility));
                            pass.raster(cmd, || {
                                kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&params), chunk_pixels)
                            });
                        }
                    }
                    pass.shade(cmd, || {
                        shade.record_dispatch(cmd, shade_sets[0].set, bytemuck::bytes_of(&params), chunk_pixels)
                    });
                    if let (Some(readback), 0) = (&hit_readback, sample) {
                        let region =
                            [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: u64::from(chunk_pixels) * 16 }];
                        device.cmd_copy_buffer(cmd, queue_a.hits.buffer, readback.buffer, &region);
                    }
                    pass.end(cmd);
                })?;
            }
            pass.finish(&mut times)?;
            stats.submits += 1;
            stats.camera_rays += u64::from(chunk_pixels);
            if let (Some(readback), Some(first), 0) = (&hit_readback, &mut first_hits, sample) {
                let hits: &[crate::geom::Hit] = bytemuck::cast_slice(readback.read(0, chunk_pixels as usize * 16)?);
                for (i, hit) in hits.iter().enumerate() {
                    first[order[first_pixel as usize + i] as usize] = *hit;
                }
            }
            let mut current = 0usize; // which queue holds the paths just shaded
            let mut path_count = chunk_pixels;
            loop {
                let [next, shadows, bad, overflow, edges] = read_counters(&counters)?;
                stats.raster_edge_pixels += u64::from(edges);
                stats.bad_rays += u64::from(bad);
                if overflow > 0 {
                    return Err(Error::InvalidInput(format!(
                        "internal: {overflow} shadow rays did not fit their queue of {shadow_capacity}"
                    )));
                }
                if next == 0 && shadows == 0 {
                    break;
                }
                let mut pass = Pass::new(&ctx, timestamps.as_ref());
                unsafe {
                    ctx.submit_and_wait(|cmd| {
                        pass.begin(cmd, &counters);
                        if shadows > 0 {
                            if let (Some(set), Some(resolve), Some(sets)) = (&shadow_set, &resolve, &resolve_sets) {
                                pass.trace(cmd, || tracer.record_binding(cmd, set, shadows));
                                params.count = path_count;
                                pass.shade(cmd, || {
                                    resolve.record_dispatch(
                                        cmd,
                                        sets[current].set,
                                        bytemuck::bytes_of(&params),
                                        path_count,
                                    )
                                });
                            }
                        }
                        if next > 0 {
                            pass.trace(cmd, || tracer.record_binding(cmd, &trace_sets[1 - current], next));
                            params.count = next;
                            pass.shade(cmd, || {
                                shade.record_dispatch(
                                    cmd,
                                    shade_sets[1 - current].set,
                                    bytemuck::bytes_of(&params),
                                    next,
                                )
                            });
                        }
                        pass.end(cmd);
                    })?;
                }
                pass.finish(&mut times)?;
                stats.submits += 1;
                stats.shadow_rays += u64::from(shadows);
                stats.secondary_rays += u64::from(next);
                current = 1 - current;
                path_count = next;
            }
            done += 1;
            progress(done, total);
            let samples = sample + 1;
            if every > 0 && chunks == 1 && samples % every == 0 && samples < settings.spp {
                // SAFETY: as above.
                unsafe {
                    ctx.submit_and_wait(|cmd| {
                        let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: pixel_count * 16 }];
                        device.cmd_copy_buffer(cmd, accum.buffer, readback.buffer, &region);
                        ctx.record_host_read_barrier(cmd);
                    })?;
                }
                let sums: &[[f32; 4]] = bytemuck::cast_slice(readback.read(0, (pixel_count * 16) as usize)?);
                let scale = 1.0 / samples as f32;
                let partial: Vec<Vec3> = sums.iter().map(|s| Vec3::new(s[0], s[1], s[2]) * scale).collect();
                checkpoint(samples, &partial)?;
            }
        }
    }
    // SAFETY: as above.
    unsafe {
        ctx.submit_and_wait(|cmd| {
            let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: pixel_count * 16 }];
            device.cmd_copy_buffer(cmd, accum.buffer, readback.buffer, &region);
            ctx.record_host_read_barrier(cmd);
        })?;
    }
    stats.render_seconds = loop_start.elapsed().as_secs_f64();
    // lavapipe's timestamps stop advancing once a draw has run (and the first
    // submission with a draw is the only one whose times hold): no GPU times then.
    if timestamps.is_some() && !ctx.timestamps_unreliable() {
        stats.trace_seconds = Some(times[Kind::Trace as usize]);
        stats.shade_seconds = Some(times[Kind::Shade as usize]);
        if raster.is_some() {
            stats.raster_seconds = Some(times[Kind::Raster as usize]);
        }
    }
    let sums: &[[f32; 4]] = bytemuck::cast_slice(readback.read(0, (pixel_count * 16) as usize)?);
    let scale = 1.0 / settings.spp as f32;
    let pixels = sums.iter().map(|s| Vec3::new(s[0], s[1], s[2]) * scale).collect();
    // The shade and resolve kernels count a pixel's bad rays in its sum's w.
    let bad_pixels = sums.iter().enumerate().filter(|(_, s)| s[3] > 0.0).map(|(i, _)| i).collect();
    ctx.check_validation()?;
    drop((trace_sets, shadow_set));
    drop(raster);
    Ok(RenderOutput { width, height, pixels, plan, stats, first_hits, bad_pixels })
}

/// Timestamp pairs one submission records at most (one per dispatch).
const TIMESTAMP_PAIRS: u32 = 4;

/// One submission's dispatches, each between a barrier and a pair of timestamps.
struct Pass<'a> {
    ctx: &'a GpuContext,
    timestamps: Option<&'a Timestamps>,
    kinds: Vec<Kind>,
    error: Option<Error>,
}

/// What a timed dispatch was, for the GPU time totals.
#[derive(Clone, Copy)]
enum Kind {
    Trace = 0,
    Shade = 1,
    Raster = 2,
}

impl<'a> Pass<'a> {
    fn new(ctx: &'a GpuContext, timestamps: Option<&'a Timestamps>) -> Self {
        Pass { ctx, timestamps, kinds: Vec::new(), error: None }
    }

    /// Resets the timestamps and zeroes the counters.
    unsafe fn begin(&mut self, cmd: vk::CommandBuffer, counters: &Buffer) {
        if let Some(t) = self.timestamps {
            t.record_reset(cmd);
        }
        self.ctx.device.cmd_fill_buffer(cmd, counters.buffer, 0, vk::WHOLE_SIZE, 0);
        compute_barrier(self.ctx, cmd);
    }

    unsafe fn timed(&mut self, cmd: vk::CommandBuffer, kind: Kind, record: impl FnOnce()) {
        let index = self.kinds.len() as u32;
        if let Some(t) = self.timestamps.filter(|_| index < TIMESTAMP_PAIRS) {
            t.record(cmd, 2 * index);
        }
        record();
        if let Some(t) = self.timestamps.filter(|_| index < TIMESTAMP_PAIRS) {
            t.record(cmd, 2 * index + 1);
        }
        self.kinds.push(kind);
        compute_barrier(self.ctx, cmd);
    }

    unsafe fn trace(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce() -> Result<()>) {
        let mut result = Ok(());
        self.timed(cmd, Kind::Trace, || result = record());
        if let Err(e) = result {
            self.error.get_or_insert(e);
        }
    }

    unsafe fn shade(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce()) {
        self.timed(cmd, Kind::Shade, record);
    }

    unsafe fn raster(&mut self, cmd: vk::CommandBuffer, record: impl FnOnce()) {
        self.timed(cmd, Kind::Raster, record);
    }

    unsafe fn end(&mut self, cmd: vk::CommandBuffer) {
        // Every query must be written before the results can be read with WAIT.
        if let Some(t) = self.timestamps {
            for index in 2 * self.kinds.len().min(TIMESTAMP_PAIRS as usize) as u32..2 * TIMESTAMP_PAIRS {
                t.record(cmd, index);
            }
        }
        self.ctx.record_host_read_barrier(cmd);
    }

    /// After the submission completed: adds its GPU times.
    fn finish(self, times: &mut [f64; 3]) -> Result<()> {
        if let Some(e) = self.error {
            return Err(e);
        }
        if let Some(t) = self.timestamps {
            for (i, &kind) in self.kinds.iter().enumerate().take(TIMESTAMP_PAIRS as usize) {
                times[kind as usize] += t.seconds_between(2 * i as u32, 2 * i as u32 + 1)?;
            }
        }
        Ok(())
    }
}

/// Compute and transfer writes before compute, transfer and host access.
unsafe fn compute_barrier(ctx: &GpuContext, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(
            vk::AccessFlags::SHADER_READ
                | vk::AccessFlags::SHADER_WRITE
                | vk::AccessFlags::TRANSFER_READ
                | vk::AccessFlags::TRANSFER_WRITE,
        );
    ctx.device.cmd_pipeline_barrier(
        cmd,
        vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
        vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
        vk::DependencyFlags::empty(),
        &[barrier],
        &[],
        &[],
    );
}

fn read_counters(counters: &Buffer) -> Result<[u32; RC_COUNT]> {
    let bytes = counters.read(0, RC_COUNT * 4)?;
    let mut out = [0u32; RC_COUNT];
    for (o, b) in out.iter_mut().zip(bytes.chunks_exact(4)) {
        *o = u32::from_le_bytes([b[0], b[1], b[2], b[3]]);
    }
    debug_assert_eq!([RC_NEXT, RC_SHADOW, RC_BAD_RAYS, RC_OVERFLOW, RC_RASTER_EDGE], [0, 1, 2, 3, 4]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn push_constants_fit_the_guaranteed_128_bytes() {
        assert_eq!(std::mem::size_of::<RenderParams>(), 128);
        assert_eq!(std::mem::size_of::<Surface>(), 48);
        assert_eq!(std::mem::size_of::<GpuMaterial>(), 48);
        assert_eq!(std::mem::size_of::<Emitter>(), 16);
        assert_eq!(std::mem::size_of::<GpuLight>(), 32);
    }
}
