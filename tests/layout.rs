//! Proves that the Rust structs shared with the shaders agree with the shaders'
//! view of them, field by field on the device: each layout probe kernel reads
//! its structs (a push constant block and element 1 of a buffer of each other
//! struct, so the stride counts too) and writes every field back as raw words in
//! declaration order with the `put` build.rs generates from the struct's
//! `gpu_struct!`. Each field is given distinct words, so every word must come
//! back from where the Rust struct puts it:
//! glsl/layout_probe.comp (the tracer's `Ray`, `Hit`, `TraceParams`, the kd-tree
//! node and the raster pass's `RasterView`), glsl/render_layout_probe.comp (the
//! renderer's) and glsl/examples/layout_probe.comp (the example engine's).

mod common;

#[macro_use]
#[allow(unused_macros)]
mod gpu_struct {
    include!("../src/gpu_struct.rs");
}

/// The renderer's structs (private to `kdtrace::render`), from their one source.
#[allow(dead_code)]
mod render_structs {
    include!("../src/render/structs.rs");
}

/// The renderer's constants (private to `kdtrace::render`): the probe's bindings.
#[allow(dead_code)]
mod render_consts {
    include!("../src/render/consts.rs");
}

/// The example engine's constants and structs (`examples/embed.rs`).
#[allow(dead_code)]
mod engine_abi {
    include!("../glsl/examples/abi.rs");
}

use std::mem::{offset_of, size_of};
use std::sync::Arc;

use ash::vk;
use bytemuck::Pod;
use common::{assert_validation_clean, context};
use gpu_allocator::MemoryLocation;
use kdtrace::consts::{
    PROBE_BINDINGS, PROBE_BINDING_HITS, PROBE_BINDING_NODES, PROBE_BINDING_RASTER_VIEWS, PROBE_BINDING_RAYS,
    PROBE_BINDING_WORDS,
};
use kdtrace::gpu::{shaders, Buffer, BufferSet, GpuContext, Kernel, KernelDesc, RasterView};
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
    assert_eq!(size_of::<RasterView>(), 80);
    assert_eq!(size_of::<render_structs::RenderParams>(), 128);
}

/// A `T` whose 4-byte words are all distinct (and normal floats, so that no
/// device flushes them): `0x4000_0000 | tag << 12 | index`.
fn distinct<T: Pod>(tag: u32) -> T {
    let words: Vec<u32> = (0..(size_of::<T>() / 4) as u32).map(|i| 0x4000_0000 | (tag << 12) | i).collect();
    bytemuck::pod_read_unaligned(bytemuck::cast_slice(&words))
}

fn words_of<T: Pod>(value: &T) -> Vec<u32> {
    bytemuck::bytes_of(value).chunks(4).map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]])).collect()
}

/// Buffers of `[zeroed, element]` whose element 1 the probe reads.
struct Probe {
    ctx: Arc<GpuContext>,
    /// `(binding, buffer)` of the inputs.
    inputs: Vec<(u32, Buffer)>,
    /// The words the probe must write back, in order.
    expected: Vec<u32>,
}

impl Probe {
    fn new(ctx: &Arc<GpuContext>) -> Probe {
        Probe { ctx: ctx.clone(), inputs: Vec::new(), expected: Vec::new() }
    }

    /// Binds `[zeroed, element]` at `binding`; the probe writes `element`'s fields back.
    fn element<T: Pod>(&mut self, binding: u32, element: T) {
        self.raw(binding, &[T::zeroed(), element]);
        self.expected.extend(words_of(&element));
    }

    /// Binds `data` at `binding` (what comes back is the caller's to expect).
    fn raw<T: Pod>(&mut self, binding: u32, data: &[T]) {
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let buffer = Buffer::with_data(&self.ctx, bytemuck::cast_slice(data), usage, "probe input").unwrap();
        self.inputs.push((binding, buffer));
    }

    /// Runs `spirv` with `push` as its push constants (whose words come back
    /// first) and the output at `words_binding`; asserts every word.
    fn run<P: Pod>(mut self, name: &str, spirv: &[u8], push: P, words_binding: u32, bindings: u32) {
        let mut expected = words_of(&push);
        expected.append(&mut self.expected);
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let bytes = 4 * expected.len() as u64;
        let out = Buffer::new(&self.ctx, bytes, usage, MemoryLocation::GpuToCpu, "words").unwrap();
        let kernel = Kernel::new(
            &self.ctx,
            &KernelDesc {
                name,
                spirv,
                bindings,
                push_constant_size: size_of::<P>() as u32,
                workgroup_size: 1,
                ..Default::default()
            },
        )
        .unwrap();
        let mut bound: Vec<(u32, &Buffer)> = self.inputs.iter().map(|(b, buf)| (*b, buf)).collect();
        bound.push((words_binding, &out));
        bound.sort_by_key(|(b, _)| *b);
        assert!(bound.iter().enumerate().all(|(i, (b, _))| i as u32 == *b), "{name}: every binding once");
        let buffers: Vec<&Buffer> = bound.iter().map(|(_, buf)| *buf).collect();
        let set = BufferSet::new(&self.ctx, &kernel, &buffers).unwrap();
        self.ctx
            .submit_and_wait(|cmd| {
                // SAFETY: `cmd` is recording; all buffers outlive the waited submission.
                unsafe {
                    kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&push), 1);
                    self.ctx.record_host_read_barrier(cmd);
                }
            })
            .unwrap();
        let words: &[u32] = bytemuck::cast_slice(out.read(0, bytes as usize).unwrap());
        assert_eq!(words, &expected[..], "{name}: words written back");
        drop((set, kernel, buffers, bound));
        drop(out);
        let ctx = self.ctx.clone();
        drop(self);
        assert_validation_clean(&ctx);
    }
}

#[test]
fn gpu_reads_every_field_where_rust_wrote_it() {
    let ctx = context();
    let mut probe = Probe::new(&ctx);
    probe.element::<Ray>(PROBE_BINDING_RAYS, distinct(1));
    probe.element::<Hit>(PROBE_BINDING_HITS, distinct(2));
    // The kd-tree node is a `uvec2` decoded by kdnode.glsl: an interior node (its
    // above child flagged as an empty leaf) and a leaf.
    let mut interior = KdNode::interior(2, -17.5, 98_765);
    interior.word1 |= kdtrace::consts::NODE_ABOVE_EMPTY;
    let nodes = [KdNode::leaf(0, 0), interior, KdNode::leaf(4321, 77)];
    probe.raw(PROBE_BINDING_NODES, &nodes);
    probe.expected.extend([
        0,
        nodes[1].axis() as u32,
        nodes[1].split().to_bits(),
        nodes[1].above_child(),
        nodes[1].below_empty() as u32,
        nodes[1].above_empty() as u32,
        1,
        nodes[2].prim_count(),
        nodes[2].prim_offset(),
    ]);
    assert_eq!((nodes[1].axis(), nodes[1].split(), nodes[1].above_child()), (2, -17.5, 98_765));
    assert_eq!((nodes[1].below_empty(), nodes[1].above_empty()), (false, true));
    assert_eq!((nodes[2].prim_count(), nodes[2].prim_offset()), (77, 4321));
    probe.element::<RasterView>(PROBE_BINDING_RASTER_VIEWS, distinct(3));
    let params: TraceParams = distinct(4);
    probe.run("layout_probe", shaders::LAYOUT_PROBE, params, PROBE_BINDING_WORDS, PROBE_BINDINGS);
}

/// The renderer's structs (src/render/structs.rs).
#[test]
fn gpu_reads_every_render_field_where_rust_wrote_it() {
    use render_consts::*;
    use render_structs::*;
    let ctx = context();
    let mut probe = Probe::new(&ctx);
    probe.element::<Surface>(RENDER_PROBE_BINDING_SURFACES, distinct(1));
    probe.element::<GpuMaterial>(RENDER_PROBE_BINDING_MATERIALS, distinct(2));
    probe.element::<Emitter>(RENDER_PROBE_BINDING_EMITTERS, distinct(3));
    probe.element::<GpuLight>(RENDER_PROBE_BINDING_LIGHTS, distinct(4));
    probe.element::<GpuPath>(RENDER_PROBE_BINDING_PATHS, distinct(5));
    // The library's `RenderParams` is this one.
    let params: kdtrace::render::RenderParams = distinct(6);
    probe.run(
        "render_layout_probe",
        shaders::RENDER_LAYOUT_PROBE,
        params,
        RENDER_PROBE_BINDING_WORDS,
        RENDER_PROBE_BINDINGS,
    );
}

/// The example engine's structs (glsl/examples/abi.rs).
#[test]
fn gpu_reads_every_engine_field_where_rust_wrote_it() {
    use engine_abi::*;
    let ctx = context();
    let mut probe = Probe::new(&ctx);
    probe.element::<ShadeParams>(ENGINE_PROBE_BINDING_SHADE_PARAMS, distinct(1));
    probe.element::<Surface>(ENGINE_PROBE_BINDING_SURFACES, distinct(2));
    let camera: CameraParams = distinct(3);
    probe.run(
        "example_layout_probe",
        shaders::EXAMPLE_LAYOUT_PROBE,
        camera,
        ENGINE_PROBE_BINDING_WORDS,
        ENGINE_PROBE_BINDINGS,
    );
}
