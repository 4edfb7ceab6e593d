//! The Vulkan plumbing itself: device selection, validation capture, errors.

mod common;

use ash::vk;
use common::{assert_validation_clean, context};
use gpu_allocator::MemoryLocation;
use kdtrace::gpu::{Buffer, ContextOptions, GpuContext, Validation};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::trace::Tracer;
use kdtrace::Error;

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
    let options = ContextOptions { device: Some("no-such-device-xyz".into()), validation: Validation::Off };
    match GpuContext::headless(&options) {
        Err(Error::NoDevice(message)) => assert!(message.contains("no-such-device-xyz"), "{message}"),
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("a device named no-such-device-xyz should not exist"),
    }
}

#[test]
fn device_by_index_and_buffers_round_trip() {
    let options = ContextOptions { device: Some("0".into()), validation: Validation::IfAvailable };
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
