//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};

use glam::Vec3;
use kdtrace::gpu::{ContextOptions, GpuContext, Validation};
use kdtrace::kdtree::KdTree;
use kdtrace::trace::{TraceOptions, TracePipelines, TraceResult, Tracer};
use kdtrace::Ray;

/// A headless context on the default device (lavapipe here) with the validation
/// layer on when installed — required when `CI` is set, so CI cannot skip it.
pub fn context() -> Arc<GpuContext> {
    try_context(false).expect("creating a Vulkan device (run tools/setup)")
}

/// The validation layer as the tests use it: required under CI, else if installed.
pub fn validation() -> Validation {
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false");
    if ci {
        Validation::Required
    } else {
        Validation::IfAvailable
    }
}

/// [`context`], with the ray-query backend's extensions enabled when `ray_query`
/// (an error naming what the device lacks otherwise).
pub fn try_context(ray_query: bool) -> kdtrace::Result<Arc<GpuContext>> {
    let options = ContextOptions { device: std::env::var("KDTRACE_DEVICE").ok(), validation: validation(), ray_query };
    GpuContext::headless(&options)
}

/// One context for every test of a test binary that asks for it, with one set
/// of trace pipelines that their tracers share ([`trace`]): under the
/// validation layer, creating a trace pipeline costs lavapipe's compile plus
/// the layer re-validating the kernel's module with its specialization
/// constants applied (one module per variant, 0.3-0.6 MB), and the tests of a
/// binary need many of the same pipelines. The tests of a binary run on parallel threads, so a
/// validation message is reported by whichever of them checks first
/// ([`assert_validation_clean`]); the binary fails either way. So it is not
/// for binaries with a test that provokes a validation message on purpose
/// (embed, gpu_context): another test would take it.
pub fn shared_context() -> Arc<GpuContext> {
    shared().0.clone()
}

fn shared() -> &'static (Arc<GpuContext>, Mutex<TracePipelines>) {
    static SHARED: OnceLock<(Arc<GpuContext>, Mutex<TracePipelines>)> = OnceLock::new();
    SHARED.get_or_init(|| {
        let ctx = context();
        let pipelines = Mutex::new(TracePipelines::new(&ctx));
        (ctx, pipelines)
    })
}

/// Gives `tracer` the trace pipelines compiled so far by the tracers of
/// [`shared_context`] (nothing for a tracer of another context).
pub fn adopt_shared(tracer: &mut Tracer) {
    let (ctx, pipelines) = shared();
    if Arc::ptr_eq(tracer.context(), ctx) {
        let known = pipelines.lock().unwrap_or_else(|p| p.into_inner()).clone();
        tracer.adopt_pipelines(known).expect("pipelines of the tracer's own context");
    }
}

/// Adds the trace pipelines `tracer` compiled to those of [`shared_context`]
/// (nothing for a tracer of another context).
pub fn share(tracer: &Tracer) {
    let (ctx, pipelines) = shared();
    if Arc::ptr_eq(tracer.context(), ctx) {
        let mut shared = pipelines.lock().unwrap_or_else(|p| p.into_inner());
        shared.merge(tracer.shared_pipelines()).expect("pipelines of the shared context");
    }
}

/// `tracer.trace(rays, options)`, sharing pipelines with the other tracers of
/// [`shared_context`] when the tracer is one of its tracers ([`adopt_shared`]
/// before, [`share`] after). Two tests that need a new pipeline at once both
/// compile it (the first one kept).
pub fn trace(tracer: &mut Tracer, rays: &[kdtrace::Ray], options: &TraceOptions) -> kdtrace::Result<TraceResult> {
    adopt_shared(tracer);
    let result = tracer.trace(rays, options);
    share(tracer);
    result
}

/// Fails the test when the validation layer reported anything.
pub fn assert_validation_clean(ctx: &GpuContext) {
    let messages = ctx.take_validation_messages();
    assert!(messages.is_empty(), "validation messages:\n{}", messages.join("\n"));
}

pub fn scene_path(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("scenes").join(name)
}

/// A scene that `tools/fetch-scenes` provides (bunny, dragon_200k): its path, or
/// None with a message when it is missing. Under `CI` a missing scene fails the
/// test: CI must not pass by skipping.
pub fn fetched_scene(name: &str) -> Option<PathBuf> {
    let path = scene_path(name);
    if path.exists() {
        return Some(path);
    }
    let ci = std::env::var("CI").is_ok_and(|v| !v.is_empty() && v != "false");
    assert!(!ci, "{name} is missing under CI: tools/fetch-scenes must provide it");
    eprintln!("skipping {name}: not in scenes/ (run tools/fetch-scenes)");
    None
}

/// The seeded generator of the tests: the library's.
pub use kdtrace::raygen::SplitMix64 as Rng;

/// Rays from random points of the box (grown by 10%) in random directions.
pub fn random_rays(rng: &mut Rng, min: Vec3, max: Vec3, count: usize) -> Vec<Ray> {
    let pad = (max - min) * 0.1;
    let (lo, hi) = (min - pad, max + pad);
    (0..count)
        .map(|_| {
            let o = Vec3::new(rng.range(lo.x, hi.x), rng.range(lo.y, hi.y), rng.range(lo.z, hi.z));
            Ray::new(o, rng.unit_vector(), 0.0, f32::INFINITY)
        })
        .collect()
}

/// An icosphere of radius 1 subdivided `levels` times, optionally with every
/// vertex moved radially by up to `bump` (seeded): closed, consistently wound.
pub fn sphere(levels: u32, bump: f32, seed: u64) -> Vec<[Vec3; 3]> {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut verts: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut faces: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut mid = std::collections::HashMap::new();
        let mut midpoint = |a: usize, b: usize, verts: &mut Vec<Vec3>| {
            *mid.entry((a.min(b), a.max(b))).or_insert_with(|| {
                verts.push(((verts[a] + verts[b]) * 0.5).normalize());
                verts.len() - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let (ab, bc, ca) = (midpoint(a, b, &mut verts), midpoint(b, c, &mut verts), midpoint(c, a, &mut verts));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let mut rng = kdtrace::raygen::SplitMix64(seed);
    for v in verts.iter_mut() {
        *v *= 1.0 + bump * (rng.next_f32() - 0.5);
    }
    faces.iter().map(|f| f.map(|i| verts[i])).collect()
}

/// Puts a scene into `tracer`, creating the tracer on first use. A tracer keeps
/// its compiled pipelines across `replace_scene`, so a test that loops over scenes
/// compiles each kernel once (lavapipe has no pipeline cache, and compiling
/// dominated such tests when every scene got a new tracer).
pub fn load_scene<'a>(
    tracer: &'a mut Option<Tracer>,
    ctx: &Arc<GpuContext>,
    tree: &KdTree,
    triangles: &[[Vec3; 3]],
) -> &'a mut Tracer {
    match tracer {
        Some(t) => {
            t.replace_scene(tree, triangles).expect("replacing the tracer's scene");
            t
        }
        None => tracer.insert(Tracer::new(ctx, tree, triangles).expect("uploading the scene")),
    }
}

/// A small glTF 2.0 document over one 60-byte buffer (a quad's 4 positions, then
/// 6 u16 indices): node 0 the quad as is, node 1 the quad moved, turned and
/// scaled with node 2 (a strip mesh plus a lines primitive) as its child, node 3
/// a camera at (0, 0, 10). `buffer` is the buffer's JSON (uri or none).
pub fn gltf_json(buffer: &str, index5: u16) -> (String, Vec<u8>) {
    let positions = [[0f32, 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.]];
    let mut bin = Vec::new();
    for p in positions {
        for c in p {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    for i in [0u16, 1, 2, 0, 2, index5] {
        bin.extend_from_slice(&i.to_le_bytes());
    }
    let json = format!(
        r#"{{
  "asset": {{"version": "2.0"}},
  "extensionsUsed": ["KHR_materials_emissive_strength"],
  "scene": 0,
  "scenes": [{{"nodes": [0, 1, 3]}}],
  "nodes": [
    {{"mesh": 0}},
    {{"mesh": 0, "translation": [10, 0, 0], "rotation": [0, 0, 0.38268343, 0.92387953], "scale": [2, 2, 2], "children": [2]}},
    {{"mesh": 1, "translation": [0, 5, 0]}},
    {{"camera": 0, "translation": [0, 0, 10]}}
  ],
  "cameras": [{{"type": "perspective", "perspective": {{"yfov": 0.8, "znear": 0.1}}}}],
  "meshes": [
    {{"primitives": [{{"attributes": {{"POSITION": 0}}, "indices": 1, "material": 0}}]}},
    {{"primitives": [{{"attributes": {{"POSITION": 0}}, "mode": 5}}, {{"attributes": {{"POSITION": 0}}, "mode": 1}}]}}
  ],
  "materials": [{{"name": "lamp", "pbrMetallicRoughness": {{"baseColorFactor": [0.2, 0.4, 0.6, 1]}},
                  "emissiveFactor": [1, 0.5, 0.25],
                  "extensions": {{"KHR_materials_emissive_strength": {{"emissiveStrength": 4}}}}}}],
  "accessors": [
    {{"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}},
    {{"bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR"}}
  ],
  "bufferViews": [
    {{"buffer": 0, "byteOffset": 0, "byteLength": 48}},
    {{"buffer": 0, "byteOffset": 48, "byteLength": 12}}
  ],
  "buffers": [{buffer}]
}}"#
    );
    (json, bin)
}

pub fn base64(bytes: &[u8]) -> String {
    const A: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut s = String::new();
    for c in bytes.chunks(3) {
        let n =
            (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            s.push(if k <= c.len() { A[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    s
}

/// The GLB container: header, JSON chunk (space-padded), BIN chunk (zero-padded).
pub fn glb(json: &str, bin: &[u8]) -> Vec<u8> {
    let mut j = json.as_bytes().to_vec();
    while j.len() % 4 != 0 {
        j.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let mut out = Vec::new();
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&((12 + 8 + j.len() + 8 + b.len()) as u32).to_le_bytes());
    out.extend_from_slice(&(j.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&j);
    out.extend_from_slice(&(b.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&b);
    out
}
