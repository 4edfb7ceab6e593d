//! Any Vulkan device (issue 30): no kernel declares a 64-bit capability
//! (`Float64`, `Int64`), and a device created without `shaderFloat64` and
//! `shaderInt64` traces (robust and plain, near and far rays, GPU == CPU twin
//! bit for bit) and renders under the validation layer with no message.

mod common;

#[allow(dead_code)]
#[path = "../examples/embed.rs"]
mod embed;

use embed::Engine;
use kdtrace::gpu::shaders;
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::render::{render, RenderSettings};
use kdtrace::scene::{Camera, Scene};
use kdtrace::stress::{stress_rays, Category};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::traversal::Traversal;

/// Every SPIR-V module kdtrace builds (glsl/*.comp, the raster stages and the
/// example shaders that engines copy), as build.rs lists them.
const MODULES: &[(&str, &[u8])] = shaders::ALL;

/// The operands of every `OpCapability` of a SPIR-V module.
fn capabilities(spirv: &[u8]) -> Vec<u32> {
    assert!(spirv.len() % 4 == 0 && spirv.len() >= 20, "not a SPIR-V module");
    let words: Vec<u32> = spirv.chunks_exact(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect();
    assert_eq!(words[0], 0x0723_0203, "SPIR-V magic");
    let mut caps = Vec::new();
    let mut i = 5;
    while i < words.len() {
        let (count, opcode) = ((words[i] >> 16) as usize, words[i] & 0xffff);
        assert!(count > 0, "malformed instruction at word {i}");
        const OP_CAPABILITY: u32 = 17;
        if opcode == OP_CAPABILITY {
            caps.push(words[i + 1]);
        }
        i += count;
    }
    caps
}

#[test]
fn no_module_declares_a_64_bit_capability() {
    // Float64 = 10, Int64 = 11, Int64Atomics = 12, Int64ImageEXT = 5016.
    let forbidden = [(10, "Float64"), (11, "Int64"), (12, "Int64Atomics"), (5016, "Int64ImageEXT")];
    // The trace kernels come as one module per variant (`trace[0]` = stack, ...).
    for kernel in [
        "trace[0]",
        "trace[6]",
        "trace_twolevel[0]",
        "trace_twolevel[4]",
        "render_shade",
        "divergence_replay",
        "example_shade",
    ] {
        assert!(MODULES.iter().any(|(n, _)| *n == kernel), "{kernel} is not in shaders::ALL");
    }
    for (name, spirv) in MODULES {
        let caps = capabilities(spirv);
        // Shader = 1: the parser read the module's capabilities at all.
        assert!(caps.contains(&1), "{name}: no Shader capability found in {caps:?}");
        for (cap, cap_name) in forbidden {
            assert!(!caps.contains(&cap), "{name} declares {cap_name}");
        }
    }
}

#[test]
fn a_device_without_64_bit_features_traces_and_renders() {
    // `false`: the engine enables no core feature at all (no shaderFloat64, no shaderInt64).
    let engine = Engine::new(common::validation(), false).unwrap();
    assert_eq!(engine.enabled_features.shader_float64, 0);
    assert_eq!(engine.enabled_features.shader_int64, 0);
    let ctx = engine.kdtrace_context().unwrap();
    {
        let scene = Scene::load(&common::scene_path("teapot.obj")).unwrap();
        let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
        let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
        // Near and far rays, rays at vertices and edges: the careful passes and
        // the far-ray shift run, in float-float.
        let categories = [Category::Random, Category::ToVertex, Category::ToEdge, Category::FarOrigin1e7];
        let rays: Vec<_> = categories.iter().flat_map(|&c| stress_rays(c, &scene.triangles, &tree, 200, 5)).collect();
        let scene_ref = SceneRef::new(&tree, &scene.triangles);
        for robust in [true, false] {
            for packet_width in [1, 4] {
                let traversal = Traversal { robust, packet_width, ..Traversal::closest(Variant::Stack) };
                let options = TraceOptions::new(traversal);
                let gpu = tracer.trace(&rays, &options).unwrap();
                let hits = gpu.hits.iter().filter(|h| h.is_hit()).count();
                assert!(hits > rays.len() / 2, "robust {robust}: only {hits} hits");
                if packet_width == 1 {
                    for (ray, got) in rays.iter().zip(&gpu.hits) {
                        let (want, _) = trace_ray(&scene_ref, ray, traversal);
                        assert_eq!(
                            (want.t.to_bits(), want.prim_id, want.u.to_bits(), want.v.to_bits()),
                            (got.t.to_bits(), got.prim_id, got.u.to_bits(), got.v.to_bits()),
                            "robust {robust}: {ray:?}"
                        );
                    }
                }
            }
        }

        let scene = Scene::load(&common::scene_path("cornell_box.obj")).unwrap();
        let camera = Camera::from_cameras_json(&common::scene_path("cameras.json"), "cornell_box").unwrap().unwrap();
        let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
        let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
        let mut settings = RenderSettings::new(32, 24);
        settings.spp = 2;
        settings.bounces = 1;
        let image = render(&mut tracer, &scene, &camera, &settings, |_, _| {}).unwrap();
        assert!(image.pixels.iter().any(|p| p.max_element() > 0.0), "a black render");
    }
    drop(ctx);
    let messages = engine.shutdown().unwrap();
    assert!(messages.is_empty(), "validation messages:\n{}", messages.join("\n"));
}
