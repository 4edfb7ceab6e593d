//! Proves that the Rust mirrors of the shared GLSL structs agree with the shader's
//! view of them: sizes and offsets on the Rust side, field by field on the GPU
//! side (glsl/layout_probe.comp reads each struct of the tracer and writes its
//! fields back; glsl/render_layout_probe.comp those of the renderer).

mod common;

use std::mem::{offset_of, size_of};

use ash::vk;
use common::{assert_validation_clean, context};
use gpu_allocator::MemoryLocation;
use kdtrace::gpu::{shaders, Buffer, BufferSet, Kernel, KernelDesc};
use kdtrace::kdtree::KdNode;
use kdtrace::trace::TraceParams;
use kdtrace::{Hit, Ray};

#[test]
fn rust_sizes_and_offsets_match_std430() {
    assert_eq!(size_of::<Ray>(), 32);
    assert_eq!(offset_of!(Ray, origin), 0);
    assert_eq!(offset_of!(Ray, tmin), 12);
    assert_eq!(offset_of!(Ray, dir), 16);
    assert_eq!(offset_of!(Ray, tmax), 28);
    assert_eq!(size_of::<Hit>(), 16);
    assert_eq!(offset_of!(Hit, t), 0);
    assert_eq!(offset_of!(Hit, prim_id), 4);
    assert_eq!(offset_of!(Hit, u), 8);
    assert_eq!(offset_of!(Hit, v), 12);
    assert_eq!(size_of::<KdNode>(), 8);
    assert_eq!(offset_of!(KdNode, word0), 0);
    assert_eq!(offset_of!(KdNode, word1), 4);
    assert_eq!(size_of::<TraceParams>(), 48);
    assert_eq!(offset_of!(TraceParams, scene_min), 0);
    assert_eq!(offset_of!(TraceParams, scene_max), 16);
    assert_eq!(offset_of!(TraceParams, ray_count), 32);
}

#[test]
fn gpu_reads_every_field_where_rust_wrote_it() {
    let ctx = context();
    let rays =
        [Ray::default(), Ray { origin: [1.5, -2.25, 3.0], tmin: 0.125, dir: [-4.0, 5.5, -6.75], tmax: f32::INFINITY }];
    let hits = [Hit::MISS, Hit { t: 7.5, prim_id: 123_456, u: 0.25, v: 0.625 }];
    let nodes = [KdNode::leaf(0, 0), KdNode::interior(2, -17.5, 98_765), KdNode::leaf(4321, 77)];
    let params = TraceParams {
        scene_min: [-1.0, -2.0, -3.0, 42.0],
        scene_max: [4.0, 5.0, 6.0, 0.0],
        ray_count: 987_654,
        pad: [11, 22, 33],
    };
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let ray_buf = Buffer::with_data(&ctx, bytemuck::cast_slice(&rays), usage, "rays").unwrap();
    let hit_buf = Buffer::with_data(&ctx, bytemuck::cast_slice(&hits), usage, "hits").unwrap();
    let node_buf = Buffer::with_data(&ctx, bytemuck::cast_slice(&nodes), usage, "nodes").unwrap();
    let out = Buffer::new(&ctx, 4 * 64, usage, MemoryLocation::GpuToCpu, "words").unwrap();
    let kernel = Kernel::new(
        &ctx,
        &KernelDesc {
            name: "layout_probe",
            spirv: shaders::LAYOUT_PROBE,
            bindings: 4,
            push_constant_size: size_of::<TraceParams>() as u32,
            workgroup_size: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let set = BufferSet::new(&ctx, &kernel, &[&ray_buf, &hit_buf, &node_buf, &out]).unwrap();
    ctx.submit_and_wait(|cmd| {
        // SAFETY: `cmd` is recording; all buffers outlive the waited submission.
        unsafe {
            kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&params), 1);
            ctx.record_host_read_barrier(cmd);
        }
    })
    .unwrap();
    let words: &[u32] = bytemuck::cast_slice(out.read(0, 4 * 25).unwrap());
    let r = rays[1];
    let h = hits[1];
    let expected: Vec<u32> = vec![
        r.origin[0].to_bits(),
        r.origin[1].to_bits(),
        r.origin[2].to_bits(),
        r.tmin.to_bits(),
        r.dir[0].to_bits(),
        r.dir[1].to_bits(),
        r.dir[2].to_bits(),
        r.tmax.to_bits(),
        h.t.to_bits(),
        h.prim_id,
        h.u.to_bits(),
        h.v.to_bits(),
        0,
        nodes[1].axis() as u32,
        nodes[1].split().to_bits(),
        nodes[1].above_child(),
        1,
        nodes[2].prim_count(),
        nodes[2].prim_offset(),
        params.scene_min[0].to_bits(),
        params.scene_min[3].to_bits(),
        params.scene_max[1].to_bits(),
        params.ray_count,
        params.pad[0],
        params.pad[2],
    ];
    assert_eq!(words, &expected[..]);
    assert_eq!((nodes[1].axis(), nodes[1].split(), nodes[1].above_child()), (2, -17.5, 98_765));
    assert_eq!((nodes[2].prim_count(), nodes[2].prim_offset()), (77, 4321));
    drop((set, kernel, ray_buf, hit_buf, node_buf, out));
    assert_validation_clean(&ctx);
}

/// The renderer's structs (`glsl/shared/render.glsl`): glsl/render_layout_probe.comp
/// writes back the `RenderParams` push constants and element 1 of each scene and
/// queue struct field by field in declaration order. `RenderParams` is filled
/// through its Rust fields; the others (private to the renderer, their sizes and
/// repr(C) field order tested in src/render/abi.rs) with distinct raw words, so
/// every field must come back from where the Rust mirror puts it.
#[test]
fn gpu_reads_every_render_field_where_rust_wrote_it() {
    use kdtrace::render::RenderParams;
    let ctx = context();
    let params = RenderParams {
        eye: [1.0, 2.0, 3.0, 4.0],
        forward: [5.0, 6.0, 7.0, 8.0],
        right: [9.0, 10.0, 11.0, 12.0],
        up: [13.0, 14.0, 15.0, 16.0],
        background: [17.0, 18.0, 19.0, 20.0],
        width: 21,
        height: 22,
        count: 23,
        sample_index: 24,
        seed: 25,
        max_depth: 26,
        bounces: 27,
        ao_samples: 28,
        ao_radius: 29.5,
        light_count: 30,
        emitter_count: 31,
        shadow_capacity: 32,
    };
    // Words per element of Surface, Material, Emitter, PointLight, Path.
    let words_per = [12usize, 12, 4, 8, 8];
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let mut expected: Vec<u32> = bytemuck::cast_slice(bytemuck::bytes_of(&params)).to_vec();
    let mut buffers = Vec::new();
    for (i, &n) in words_per.iter().enumerate() {
        // Element 0 zero, element 1 distinct words (so the stride counts too).
        let element: Vec<u32> = (0..n as u32).map(|w| 0x1000 * (i as u32 + 1) + w).collect();
        let data: Vec<u32> = std::iter::repeat_n(0, n).chain(element.iter().copied()).collect();
        expected.extend(&element);
        buffers.push(Buffer::with_data(&ctx, bytemuck::cast_slice(&data), usage, "render struct").unwrap());
    }
    let out = Buffer::new(&ctx, 4 * expected.len() as u64, usage, MemoryLocation::GpuToCpu, "words").unwrap();
    let kernel = Kernel::new(
        &ctx,
        &KernelDesc {
            name: "render_layout_probe",
            spirv: shaders::RENDER_LAYOUT_PROBE,
            bindings: 6,
            push_constant_size: size_of::<RenderParams>() as u32,
            workgroup_size: 1,
            ..Default::default()
        },
    )
    .unwrap();
    let mut bound: Vec<&Buffer> = buffers.iter().collect();
    bound.push(&out);
    let set = BufferSet::new(&ctx, &kernel, &bound).unwrap();
    ctx.submit_and_wait(|cmd| {
        // SAFETY: `cmd` is recording; all buffers outlive the waited submission.
        unsafe {
            kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&params), 1);
            ctx.record_host_read_barrier(cmd);
        }
    })
    .unwrap();
    let words: &[u32] = bytemuck::cast_slice(out.read(0, 4 * expected.len()).unwrap());
    assert_eq!(words, &expected[..]);
    drop((set, kernel, bound));
    drop((buffers, out));
    assert_validation_clean(&ctx);
}
