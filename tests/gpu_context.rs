//! The Vulkan plumbing itself: device selection, validation capture, errors.

mod common;

use std::sync::Arc;

use ash::vk;
use common::{assert_validation_clean, context, random_rays, scene_path, Rng};
use gpu_allocator::MemoryLocation;
use kdtrace::gpu::{Buffer, BufferSet, ContextOptions, GpuContext, Kernel, Timestamps, Validation};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::Scene;
use kdtrace::trace::{TraceBinding, TraceOptions, Tracer};
use kdtrace::Error;

/// What the docs promise: contexts, tracers and buffers may cross threads.
#[test]
fn public_types_are_send_and_sync() {
    fn send_sync<T: Send + Sync>() {}
    send_sync::<GpuContext>();
    send_sync::<Arc<GpuContext>>();
    send_sync::<Tracer>();
    send_sync::<TraceBinding>();
    send_sync::<Buffer>();
    send_sync::<BufferSet>();
    send_sync::<Kernel>();
    send_sync::<Timestamps>();
    send_sync::<kdtrace::twolevel::TwoLevelScene>();
    send_sync::<kdtrace::twolevel::TwoLevelTracer>();
    send_sync::<kdtrace::twolevel::TwoLevelBinding>();
}

#[test]
fn several_tracers_on_two_threads_release_everything() {
    let ctx = context();
    let scene = Scene::load(&scene_path("cornell_box.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let rays = random_rays(&mut Rng(11), scene.bounds.min, scene.bounds.max, 200);
    let options = TraceOptions::default();
    let expected = Tracer::new(&ctx, &tree, &scene.triangles).unwrap().trace(&rays, &options).unwrap().hits;
    // Tracers made on one thread and dropped on another, and several alive at once on each.
    let (sender, receiver) = std::sync::mpsc::channel::<Tracer>();
    std::thread::scope(|s| {
        s.spawn(|| {
            for _ in 0..3 {
                let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
                assert_eq!(tracer.trace(&rays, &options).unwrap().hits, expected);
                sender.send(tracer).unwrap();
            }
            drop(sender);
        });
        s.spawn(|| {
            let mut mine = vec![Tracer::new(&ctx, &tree, &scene.triangles).unwrap()];
            for mut tracer in receiver {
                assert_eq!(tracer.trace(&rays, &options).unwrap().hits, expected);
                mine.push(tracer);
            }
            for tracer in &mut mine {
                assert_eq!(tracer.trace(&rays, &options).unwrap().hits, expected);
            }
        });
    });
    assert_eq!(Arc::strong_count(&ctx), 1, "every tracer released its context");
    let report = ctx.allocator().lock().unwrap().generate_report();
    let names: Vec<&str> = report.allocations.iter().map(|a| a.name.as_str()).collect();
    assert!(names.is_empty(), "allocations left behind: {names:?}");
    assert_validation_clean(&ctx);
}

#[test]
fn validation_messages_are_caught() {
    let ctx = context();
    if !ctx.validation_enabled() {
        eprintln!("VK_LAYER_KHRONOS_validation is not installed: nothing to check");
        return;
    }
    // A buffer with no usage flags violates VUID-VkBufferCreateInfo-usage-requiredbitmask.
    let buffer = Buffer::new(&ctx, 64, vk::BufferUsageFlags::empty(), MemoryLocation::CpuToGpu, "invalid on purpose");
    drop(buffer);
    let messages = ctx.take_validation_messages();
    assert!(!messages.is_empty(), "the layer should have reported the invalid buffer");
    assert!(ctx.check_validation().is_ok(), "messages are taken once");
}

#[test]
fn unknown_device_is_a_clear_error() {
    let options =
        ContextOptions { device: Some("no-such-device-xyz".into()), validation: Validation::Off, ray_query: false };
    match GpuContext::headless(&options) {
        Err(Error::NoDevice(message)) => assert!(message.contains("no-such-device-xyz"), "{message}"),
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("a device named no-such-device-xyz should not exist"),
    }
}

#[test]
fn device_by_index_and_buffers_round_trip() {
    let options = ContextOptions { device: Some("0".into()), validation: Validation::IfAvailable, ray_query: false };
    let ctx = GpuContext::headless(&options).unwrap();
    let mut upload =
        Buffer::new(&ctx, 1024, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::CpuToGpu, "upload").unwrap();
    let data: Vec<u8> = (0..=255).collect();
    upload.write(100, &data).unwrap();
    assert_eq!(upload.read(100, 256).unwrap(), &data[..]);
    assert!(upload.write(1000, &data).is_err(), "writes past the end are refused");
    let device_local = Buffer::with_data(&ctx, &data, vk::BufferUsageFlags::STORAGE_BUFFER, "device").unwrap();
    assert!(device_local.size >= 256);
    drop((upload, device_local));
    assert_validation_clean(&ctx);
}

#[test]
fn empty_scene_is_refused_by_the_tracer() {
    let ctx = context();
    let tree = KdTree::build(&[], &BuildConfig::default());
    match Tracer::new(&ctx, &tree, &[]) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("no triangles"), "{m}"),
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("an empty scene must be refused"),
    }
    assert_validation_clean(&ctx);
}

/// A pipeline cache from a file (missing, garbage, or this device's), saved on
/// request and when the context is dropped; and an engine's own cache.
#[test]
fn pipeline_caches_load_save_and_adopt() {
    let dir = std::env::temp_dir().join(format!("kdtrace-pipeline-cache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let file = dir.join("sub").join("pipelines.bin");
    let scene = Scene::load(&scene_path("cornell_box.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let rays = random_rays(&mut Rng(5), scene.bounds.min, scene.bounds.max, 200);
    let options = TraceOptions::default();
    let trace =
        |ctx: &Arc<GpuContext>| Tracer::new(ctx, &tree, &scene.triangles).unwrap().trace(&rays, &options).unwrap().hits;
    let header = |bytes: &[u8]| bytes.len() >= 32 && bytes[..4] == 32u32.to_le_bytes();

    let ctx = context();
    let expected = trace(&ctx);
    ctx.load_pipeline_cache(&file).unwrap(); // no file yet: an empty cache
    assert_ne!(ctx.pipeline_cache(), vk::PipelineCache::null());
    assert_eq!(trace(&ctx), expected);
    ctx.save_pipeline_cache(&file).unwrap();
    assert!(header(&std::fs::read(&file).unwrap()), "a cache file starts with its 32-byte header");
    assert_validation_clean(&ctx);
    drop(ctx);

    // Bytes that are not this device's cache are not handed to the driver; the
    // dropped context writes its cache over them.
    std::fs::write(&file, [7u8; 100]).unwrap();
    let ctx = context();
    ctx.load_pipeline_cache(&file).unwrap();
    assert_eq!(trace(&ctx), expected);
    assert_validation_clean(&ctx);
    drop(ctx);
    assert!(header(&std::fs::read(&file).unwrap()), "saved when the context was dropped");

    // An engine's cache: used, never destroyed by kdtrace.
    let ctx = context();
    // SAFETY: the cache is destroyed below, after kdtrace stopped using it.
    unsafe {
        let cache = ctx.device.create_pipeline_cache(&vk::PipelineCacheCreateInfo::default(), None).unwrap();
        ctx.use_pipeline_cache(cache);
        assert_eq!(ctx.pipeline_cache(), cache);
        assert_eq!(trace(&ctx), expected);
        ctx.use_pipeline_cache(vk::PipelineCache::null());
        ctx.device.destroy_pipeline_cache(cache, None);
    }
    assert_validation_clean(&ctx);
    let _ = std::fs::remove_dir_all(&dir);
}
