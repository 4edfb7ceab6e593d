//! The embedding API: kdtrace on an engine's own device, queue and allocator
//! (examples/embed.rs, whose code this test includes), traces recorded into
//! command buffers kdtrace does not submit, buffer ranges, the scene lifecycle,
//! and nothing left behind when the engine destroys its device.

mod common;

#[allow(dead_code)]
#[path = "../examples/embed.rs"]
mod embed;

use std::path::PathBuf;

use ash::vk;
use common::{assert_validation_clean, context, random_rays, scene_path, Rng};
use embed::Engine;
use engine_abi::{CameraParams, ENGINE_RAYGEN_BINDINGS, ENGINE_RAYGEN_BINDING_RAYS, ENGINE_WORKGROUP};
use gpu_allocator::MemoryLocation;
use kdtrace::consts::{
    BINDING_RAYS, COUNTERS_PER_RAY, COUNTER_DROPS, COUNTER_LEAVES, COUNTER_NODES, COUNTER_RESTARTS, COUNTER_STEPS,
    COUNTER_TRIANGLES, ORDER_BINDING_RAYS,
};
use kdtrace::gpu::{shaders, Buffer, BufferRange, BufferSet, GpuContext, Kernel, KernelDesc};
use kdtrace::kdtree::traverse::{Counters, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::render::{camera_rays, shade_headlight, to_image};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{RayOrder, TraceOptions, Tracer};
use kdtrace::traversal::Traversal;
use kdtrace::{Error, Hit, Ray};

/// The example engine's constants and structs (its raygen shader's binding and
/// push constants), from their one source.
#[allow(dead_code)]
mod engine_abi {
    include!("../src/gpu_struct.rs");
    include!("../glsl/examples/abi.rs");
}

fn out_dir() -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("embed");
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn load(name: &str) -> (Scene, KdTree) {
    let scene = Scene::load(&scene_path(name)).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    (scene, tree)
}

fn same_bits(a: &[Hit], b: &[Hit]) -> bool {
    a.len() == b.len()
        && a.iter().zip(b).all(|(a, b)| {
            (a.t.to_bits(), a.prim_id, a.u.to_bits(), a.v.to_bits())
                == (b.t.to_bits(), b.prim_id, b.u.to_bits(), b.v.to_bits())
        })
}

#[test]
fn example_renders_like_kdtrace_render() {
    let (width, height) = (96, 72);
    let path = embed::default_scene();
    let output = out_dir().join("embed.png");
    let report = embed::run(&path, width, height, Some(&output), common::validation()).expect("the embed example");
    let written = image::open(&output).expect("the example's PNG").to_rgb8();
    assert_eq!(written, report.image, "the PNG holds the rendered frame");

    // `kdtrace render` of the same scene and camera: Tracer::trace on a headless device.
    let scene = Scene::load(&path).unwrap();
    assert_eq!(report.camera, embed::scene_camera(&path, &scene).unwrap());
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let rays = camera_rays(&report.camera, width, height);
    let hits = tracer.trace(&rays, &TraceOptions::default()).unwrap().hits;
    let expected = to_image(&shade_headlight(&scene, &rays, &hits), width, height);

    // The engine's rays are made in f32 on the GPU, kdtrace's in f64 on the CPU:
    // pixels may differ where a ray grazes an edge, nowhere else.
    let diff = image::RgbImage::from_fn(width, height, |x, y| {
        let (a, b) = (written.get_pixel(x, y).0, expected.get_pixel(x, y).0);
        image::Rgb([0, 1, 2].map(|c| a[c].abs_diff(b[c])))
    });
    let different = diff.pixels().filter(|p| p.0.iter().any(|&d| d > 8)).count();
    let mean = diff.pixels().flat_map(|p| p.0).map(f64::from).sum::<f64>() / (3 * width * height) as f64;
    if different * 100 > (width * height) as usize || mean > 1.0 {
        expected.save(out_dir().join("embed-expected.png")).unwrap();
        diff.save(out_dir().join("embed-difference.png")).unwrap();
        panic!("{different} pixels differ by more than 8, mean difference {mean:.3}; see {}", out_dir().display());
    }
    let expected_hits = hits.iter().filter(|h| h.is_hit()).count();
    assert!(report.hits * 2 > (width * height) as usize, "only {} pixels hit", report.hits);
    assert!(report.hits.abs_diff(expected_hits) * 100 <= expected_hits, "{} vs {expected_hits} hits", report.hits);
    let mut colours: Vec<[u8; 3]> = written.pixels().map(|p| p.0).collect();
    colours.sort();
    colours.dedup();
    assert!(colours.len() > 20, "a Cornell box has shaded walls, boxes and a light: {} colours", colours.len());
    drop(tracer);
    assert_validation_clean(&ctx);
}

#[test]
fn tracers_on_an_adopted_device_leave_nothing_behind() {
    let engine = Engine::new(common::validation(), true).unwrap();
    let ctx = engine.kdtrace_context().unwrap();
    assert!(ctx.is_adopted() && !ctx.validation_enabled());
    let (cornell, cornell_tree) = load("cornell_box.obj");
    let (teapot, teapot_tree) = load("teapot.obj");
    let mut rng = Rng(7);
    let cornell_rays = random_rays(&mut rng, cornell.bounds.min, cornell.bounds.max, 300);
    let teapot_rays = random_rays(&mut rng, teapot.bounds.min, teapot.bounds.max, 300);
    let options = TraceOptions::variant(Variant::PushDownShortStack);
    let cornell_hits = Tracer::new(&ctx, &cornell_tree, &cornell.triangles).unwrap().trace(&cornell_rays, &options);
    let teapot_hits = Tracer::new(&ctx, &teapot_tree, &teapot.triangles).unwrap().trace(&teapot_rays, &options);
    let (cornell_hits, teapot_hits) = (cornell_hits.unwrap().hits, teapot_hits.unwrap().hits);

    // Several tracers on the one device, made, used, replaced and dropped on two threads.
    std::thread::scope(|s| {
        for thread in 0..2 {
            let ctx = &ctx;
            let (cornell, cornell_tree, teapot, teapot_tree) = (&cornell, &cornell_tree, &teapot, &teapot_tree);
            let (cornell_rays, teapot_rays, cornell_hits, teapot_hits) =
                (&cornell_rays, &teapot_rays, &cornell_hits, &teapot_hits);
            s.spawn(move || {
                for round in 0..2 {
                    let mut a = Tracer::new(ctx, cornell_tree, &cornell.triangles).unwrap();
                    let mut b = Tracer::new(ctx, teapot_tree, &teapot.triangles).unwrap();
                    let got = a.trace(cornell_rays, &options).unwrap().hits;
                    assert!(same_bits(&got, cornell_hits), "thread {thread} round {round}: cornell");
                    let got = b.trace(teapot_rays, &options).unwrap().hits;
                    assert!(same_bits(&got, teapot_hits), "thread {thread} round {round}: teapot");
                    a.replace_scene(teapot_tree, &teapot.triangles).unwrap();
                    let got = a.trace(teapot_rays, &options).unwrap().hits;
                    assert!(same_bits(&got, teapot_hits), "thread {thread} round {round}: replaced");
                }
            });
        }
    });

    // Every kdtrace allocation came from the engine's allocator and went back to it.
    let report = engine.allocator().lock().unwrap().generate_report();
    let names: Vec<&str> = report.allocations.iter().map(|a| a.name.as_str()).collect();
    assert!(names.is_empty(), "allocations left in the engine's allocator: {names:?}");
    drop(ctx);
    let messages = engine.shutdown().unwrap();
    assert!(messages.is_empty(), "validation messages up to device destruction:\n{}", messages.join("\n"));
}

#[test]
fn device_destruction_reports_what_is_left() {
    // The check above is only worth something if a leak does get reported.
    let engine = Engine::new(common::validation(), true).unwrap();
    if !engine.validation_enabled() {
        eprintln!("VK_LAYER_KHRONOS_validation is not installed: nothing to check");
        return;
    }
    let info = vk::BufferCreateInfo::default().size(64).usage(vk::BufferUsageFlags::STORAGE_BUFFER);
    // SAFETY: a valid create info; the buffer is left alive on purpose.
    let _leaked = unsafe { engine.device.create_buffer(&info, None) }.unwrap();
    let messages = engine.shutdown().unwrap();
    assert!(messages.iter().any(|m| m.contains("VkBuffer")), "no leak reported: {messages:?}");
}

#[test]
fn adopting_checks_features_and_queue() {
    // No core feature is required (the kernels use no 64-bit type): a device
    // created with none is adopted (tests/portability.rs traces and renders on one).
    let engine = Engine::new(common::validation(), false).unwrap();
    assert!(engine.kdtrace_context().is_ok(), "a device without shaderFloat64 must be accepted");
    let messages = engine.shutdown().unwrap();
    assert!(messages.is_empty(), "{messages:?}");

    let engine = Engine::new(common::validation(), true).unwrap();
    match engine.kdtrace_context_on(999) {
        Err(Error::InvalidInput(m)) => assert!(m.contains("queue family 999"), "{m}"),
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("queue family 999 does not exist"),
    }
    let messages = engine.shutdown().unwrap();
    assert!(messages.is_empty(), "{messages:?}");
}

/// Host-visible buffers with rays, hits and counters at aligned offsets of shared buffers.
struct Ranges {
    _input: Buffer,
    output: Buffer,
    rays: BufferRange,
    hits: BufferRange,
    counters: BufferRange,
}

impl Ranges {
    fn new(ctx: &std::sync::Arc<GpuContext>, rays: &[Ray]) -> Ranges {
        let align = ctx.info.min_storage_buffer_offset_alignment;
        let up = |v: u64| v.div_ceil(align) * align;
        let n = rays.len() as u64;
        let (ray_bytes, hit_bytes, counter_bytes) = (32 * n, 16 * n, 4 * u64::from(COUNTERS_PER_RAY) * n);
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        // The rays after some bytes of the engine's own, the counters after the hits.
        let ray_offset = up(100);
        let mut input = Buffer::new(ctx, ray_offset + ray_bytes, usage, MemoryLocation::CpuToGpu, "rays").unwrap();
        input.write(ray_offset as usize, bytemuck::cast_slice(rays)).unwrap();
        let counter_offset = up(hit_bytes);
        let output =
            Buffer::new(ctx, counter_offset + counter_bytes, usage, MemoryLocation::GpuToCpu, "hits+counters").unwrap();
        Ranges {
            rays: BufferRange::new(input.buffer, ray_offset, ray_bytes),
            hits: BufferRange::new(output.buffer, 0, hit_bytes),
            counters: BufferRange::new(output.buffer, counter_offset, counter_bytes),
            _input: input,
            output,
        }
    }

    fn set_hits(&mut self, hits: &[Hit]) {
        self.output.write(0, bytemuck::cast_slice(hits)).unwrap();
    }

    fn hits(&self, count: usize) -> Vec<Hit> {
        bytemuck::cast_slice(self.output.read(0, 16 * count).unwrap()).to_vec()
    }

    fn counters(&self, count: usize) -> Vec<Counters> {
        let per_ray = COUNTERS_PER_RAY as usize;
        let raw: &[u32] =
            bytemuck::cast_slice(self.output.read(self.counters.offset as usize, 4 * per_ray * count).unwrap());
        raw.chunks_exact(per_ray)
            .map(|c| Counters {
                nodes: c[COUNTER_NODES as usize],
                leaves: c[COUNTER_LEAVES as usize],
                triangles: c[COUNTER_TRIANGLES as usize],
                restarts: c[COUNTER_RESTARTS as usize],
                steps: c[COUNTER_STEPS as usize],
                drops: c[COUNTER_DROPS as usize],
            })
            .collect()
    }
}

/// Submits `record` with a barrier that makes shader writes visible to the host.
fn submit<T>(ctx: &GpuContext, record: impl FnOnce(vk::CommandBuffer) -> T) -> T {
    let mut out = None;
    ctx.submit_and_wait(|cmd| {
        out = Some(record(cmd));
        // SAFETY: `cmd` is recording.
        unsafe { ctx.record_host_read_barrier(cmd) };
    })
    .unwrap();
    out.unwrap()
}

#[test]
fn recorded_traces_equal_trace() {
    let ctx = context();
    let (scene, tree) = load("cornell_box.obj");
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), "cornell_box").unwrap().unwrap();
    let mut rays = camera_rays(&camera, 24, 16);
    rays.extend(random_rays(&mut Rng(3), scene.bounds.min, scene.bounds.max, 200));
    let n = rays.len();
    let ranges = Ranges::new(&ctx, &rays);

    // record_trace: counters off, into ranges at offsets.
    let options = TraceOptions::variant(Variant::ShortStack);
    let expected = tracer.trace(&rays, &options).unwrap();
    let binding = submit(&ctx, |cmd| {
        // SAFETY: the ranges are live storage buffers; the binding lives past the wait.
        unsafe { tracer.record_trace(cmd, ranges.rays, ranges.hits, n as u32, &options) }.unwrap()
    });
    assert!(same_bits(&ranges.hits(n), &expected.hits));
    assert_eq!(binding.capacity() as usize, n);
    drop(binding);

    // A binding with counters, made once and recorded twice.
    let options = TraceOptions { counters: true, ..TraceOptions::variant(Variant::PushDown) };
    let expected = tracer.trace(&rays, &options).unwrap();
    // SAFETY: as above.
    let binding = unsafe { tracer.bind(ranges.rays, ranges.hits, Some(ranges.counters), &options) }.unwrap();
    for count in [n / 3, n] {
        // SAFETY: the binding and its buffers outlive the waited submission.
        submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &binding, count as u32) }).unwrap();
        assert!(same_bits(&ranges.hits(count), &expected.hits[..count]), "{count} rays");
        assert_eq!(ranges.counters(count), expected.counters.as_ref().unwrap()[..count], "{count} rays");
    }

    // Side-buffer variants: recording never uploads, so prepare comes first.
    let options = TraceOptions::variant(Variant::Backtrack);
    // SAFETY: nothing is recorded when it fails.
    let refused = submit(&ctx, |cmd| unsafe { tracer.record_trace(cmd, ranges.rays, ranges.hits, n as u32, &options) });
    match refused {
        Err(Error::InvalidInput(m)) => assert!(m.contains("prepare"), "{m}"),
        other => panic!("expected a request to prepare, got {other:?}"),
    }
    tracer.prepare(&options).unwrap();
    let expected = tracer.trace(&rays, &options).unwrap();
    let binding = submit(&ctx, |cmd| {
        // SAFETY: as above.
        unsafe { tracer.record_trace(cmd, ranges.rays, ranges.hits, n as u32, &options) }.unwrap()
    });
    assert!(same_bits(&ranges.hits(n), &expected.hits));
    drop(binding);
    drop((tracer, ranges));
    assert_validation_clean(&ctx);
}

#[test]
fn device_counted_traces_equal_host_counted_ones() {
    let ctx = context();
    let (scene, tree) = load("cornell_box.obj");
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), "cornell_box").unwrap().unwrap();
    let mut rays = camera_rays(&camera, 24, 16);
    rays.extend(random_rays(&mut Rng(11), scene.bounds.min, scene.bounds.max, 300));
    let n = rays.len() as u32;
    let mut ranges = Ranges::new(&ctx, &rays);
    // The counts as a pass on the device would leave them: a third, all, more
    // than the binding holds (clamped), none; at an offset in the buffer.
    let counts_words = [7, 7, 7, 7, n / 3, n, n + 1000, 0];
    let mut counts =
        Buffer::new(&ctx, 64, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::CpuToGpu, "counts").unwrap();
    counts.write(0, bytemuck::cast_slice(&counts_words)).unwrap();
    let counts_range = BufferRange::new(counts.buffer, 16, 16);
    let unset = Hit { t: -1.0, prim_id: 0xdead, u: 0.0, v: 0.0 };
    let variants = [
        TraceOptions::default(),
        TraceOptions {
            order: RayOrder::Coherent,
            ..TraceOptions::new(Traversal { any_hit: true, ..Traversal::closest(Variant::Stack) })
        },
        TraceOptions::new(Traversal { robust: false, ..Traversal::closest(Variant::ShortStack) }),
        TraceOptions::new(Traversal { packet_width: 4, ..Traversal::closest(Variant::Stack) }),
    ];
    for options in &variants {
        let expected = tracer.trace(&rays, options).unwrap();
        // SAFETY: the ranges are live storage buffers of this device; the binding
        // and its buffers outlive every waited submission below.
        let binding = unsafe { tracer.bind_indirect(ranges.rays, ranges.hits, None, counts_range, options) }.unwrap();
        for word in 0..4 {
            let count = counts_words[word as usize + 4].min(n) as usize;
            ranges.set_hits(&vec![unset; n as usize]);
            // SAFETY: as above.
            submit(&ctx, |cmd| unsafe { tracer.record_binding_indirect(cmd, &binding, word) }).unwrap();
            let hits = ranges.hits(n as usize);
            assert!(same_bits(&hits[..count], &expected.hits[..count]), "{options:?}: count word {word}");
            assert!(hits[count..].iter().all(|h| h.prim_id == 0xdead), "{options:?}: rays past the count {count}");
        }
        // SAFETY: nothing is recorded when it fails.
        invalid(submit(&ctx, |cmd| unsafe { tracer.record_binding_indirect(cmd, &binding, 4) }), "past");
        // SAFETY: as above.
        let host_counted = unsafe { tracer.bind(ranges.rays, ranges.hits, None, options) }.unwrap();
        // SAFETY: nothing is recorded when it fails.
        invalid(submit(&ctx, |cmd| unsafe { tracer.record_binding_indirect(cmd, &host_counted, 0) }), "bind_indirect");
    }
    drop((tracer, ranges, counts));
    assert_validation_clean(&ctx);
}

/// Asserts `result` is `Error::InvalidInput` with `needle` in its message.
fn invalid<T>(result: kdtrace::Result<T>, needle: &str) {
    match result {
        Err(Error::InvalidInput(m)) => assert!(m.contains(needle), "{m} lacks {needle}"),
        Err(e) => panic!("unexpected error: {e}"),
        Ok(_) => panic!("expected an error about {needle}"),
    }
}

#[test]
fn bad_ranges_and_stale_bindings_are_refused() {
    let ctx = context();
    let (scene, tree) = load("cornell_box.obj");
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let rays = random_rays(&mut Rng(5), scene.bounds.min, scene.bounds.max, 64);
    let r = Ranges::new(&ctx, &rays);
    let options = TraceOptions::default();
    let n = rays.len() as u32;
    // SAFETY (every call below): the ranges' buffers are live storage buffers of
    // this device, and nothing that fails is recorded or kept.
    let bind = |tracer: &mut Tracer, rays, hits, counters, options: &TraceOptions| unsafe {
        tracer.bind(rays, hits, counters, options)
    };

    let align = ctx.info.min_storage_buffer_offset_alignment;
    if align > 1 {
        let misaligned = BufferRange { offset: r.rays.offset + align / 2, range: r.rays.range - align, ..r.rays };
        match bind(&mut tracer, misaligned, r.hits, None, &options) {
            Err(Error::DeviceLimit(m)) => assert!(m.contains("minStorageBufferOffsetAlignment"), "{m}"),
            Err(e) => panic!("unexpected error: {e}"),
            Ok(_) => panic!("a misaligned offset must be refused"),
        }
    }
    let too_long = BufferRange { range: ctx.info.max_storage_buffer_range + 16, ..r.rays };
    assert!(matches!(bind(&mut tracer, too_long, r.hits, None, &options), Err(Error::DeviceLimit(_))));
    invalid(bind(&mut tracer, r.rays, BufferRange { range: 8, ..r.hits }, None, &options), "no whole record");
    invalid(bind(&mut tracer, r.rays, BufferRange { range: 0, ..r.hits }, None, &options), "above 0");
    let overlapping = BufferRange { offset: r.hits.offset, ..r.counters };
    invalid(
        bind(&mut tracer, r.rays, r.hits, Some(overlapping), &TraceOptions { counters: true, ..options }),
        "overlaps",
    );
    invalid(bind(&mut tracer, r.rays, r.hits, None, &TraceOptions { counters: true, ..options }), "no counter range");
    invalid(bind(&mut tracer, r.rays, r.hits, Some(r.counters), &options), "counters is off");
    // SAFETY: the command buffer is recording; the error records nothing.
    let counters_refused = submit(&ctx, |cmd| unsafe {
        tracer.record_trace(cmd, r.rays, r.hits, n, &TraceOptions { counters: true, ..options })
    });
    invalid(counters_refused, "no counters");

    let binding = bind(&mut tracer, r.rays, r.hits, None, &options).unwrap();
    // SAFETY: as above.
    invalid(submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &binding, n + 1) }), "exceed");
    let mut other = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    // SAFETY: as above.
    invalid(submit(&ctx, |cmd| unsafe { other.record_binding(cmd, &binding, n) }), "another tracer");
    submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &binding, n) }).unwrap();
    let before = r.hits(n as usize);
    // The same tracer with another scene: old bindings are refused, new ones trace it.
    let (teapot, teapot_tree) = load("teapot.obj");
    tracer.replace_scene(&teapot_tree, &teapot.triangles).unwrap();
    // SAFETY: as above.
    invalid(submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &binding, n) }), "replace_scene");
    let rebound = bind(&mut tracer, r.rays, r.hits, None, &options).unwrap();
    // SAFETY: as above.
    submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &rebound, n) }).unwrap();
    let fresh = other.trace(&rays, &options).unwrap().hits;
    assert!(same_bits(&before, &fresh), "the first scene, traced by another tracer");
    other.replace_scene(&teapot_tree, &teapot.triangles).unwrap();
    assert!(same_bits(&r.hits(n as usize), &other.trace(&rays, &options).unwrap().hits), "the replaced scene");
    // A prebuilt tree that does not fit its triangles is refused, and the scene stays.
    let mut broken = teapot_tree.clone();
    broken.prim_indices.iter_mut().for_each(|p| *p += 1_000_000);
    invalid(tracer.replace_scene(&broken, &teapot.triangles).map(|_| ()), "does not fit");
    invalid(Tracer::new(&ctx, &broken, &teapot.triangles).map(|_| ()), "does not fit");
    drop((binding, rebound, tracer, other, r));
    assert_validation_clean(&ctx);
}

/// The Cornell box on a tracer, with its camera, for the synchronization tests
/// (`None`, after saying so, when the validation layer is not installed).
struct SyncCase {
    ctx: std::sync::Arc<GpuContext>,
    scene: Scene,
    tree: KdTree,
    tracer: Tracer,
    camera: Camera,
}

fn sync_case() -> Option<SyncCase> {
    let ctx = context();
    if !ctx.validation_enabled() {
        eprintln!("skipping: the validation layer is not installed");
        return None;
    }
    let (scene, tree) = load("cornell_box.obj");
    let tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), "cornell_box").unwrap().unwrap();
    Some(SyncCase { ctx, scene, tree, tracer, camera })
}

/// The barriers kdtrace records between its own passes (the fast pass, the
/// careful list's reset and the indirect careful pass) hold under
/// synchronization validation (on whenever the validation layer is): one
/// binding recorded three times into one command buffer, with only the
/// barriers the recording contract asks of the caller between the recordings,
/// is reported clean and gives the hits of `Tracer::trace`. Self-check: a
/// caller's overwrite of the hits without the contract's barrier is reported.
#[test]
fn one_command_buffer_with_several_recordings_is_hazard_free() {
    use kdtrace::stress::{stress_rays, Category};
    let Some(SyncCase { ctx, scene, tree, mut tracer, camera }) = sync_case() else { return };
    let mut rays = camera_rays(&camera, 24, 16);
    // Hard rays, so that the careful pass has rays to trace (far origins always go
    // through it: the fast pass lists them).
    for category in [Category::ToEdge, Category::FarOrigin, Category::BoundedSegment] {
        rays.extend(stress_rays(category, &scene.triangles, &tree, 100, 9));
    }
    let n = rays.len();
    let ranges = Ranges::new(&ctx, &rays);
    let options = TraceOptions::default();
    let expected = tracer.trace(&rays, &options).unwrap();
    // SAFETY: the ranges are live storage buffers; the binding outlives the waits below.
    let binding = unsafe { tracer.bind(ranges.rays, ranges.hits, None, &options) }.unwrap();
    // The contract's barrier between two recordings (the example's helper).
    // SAFETY (at each call): `cmd` is recording, outside a render pass.
    let caller_barrier = |cmd: vk::CommandBuffer| unsafe {
        embed::compute_barrier(&ctx.device, cmd, vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE)
    };
    assert!(ctx.take_validation_messages().is_empty());
    submit(&ctx, |cmd| {
        for k in 0..3 {
            if k > 0 {
                caller_barrier(cmd);
            }
            // SAFETY: as above.
            unsafe { tracer.record_binding(cmd, &binding, n as u32) }.unwrap();
        }
    });
    let messages = ctx.take_validation_messages();
    assert!(messages.is_empty(), "hazards with the contract's barriers:\n{}", messages.join("\n"));
    assert!(same_bits(&ranges.hits(n), &expected.hits));

    // Self-check: a caller that overwrites the hits right after the recording,
    // without the barrier the contract asks for, must be reported.
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::TRANSFER_DST;
    let other_hits = Buffer::new(&ctx, 16 * n as u64, usage, MemoryLocation::GpuOnly, "other hits").unwrap();
    // SAFETY: as above.
    let other = unsafe { tracer.bind(ranges.rays, BufferRange::whole(&other_hits), None, &options) }.unwrap();
    submit(&ctx, |cmd| {
        // SAFETY: as above (the hazard is on purpose; nothing reads these hits).
        unsafe {
            tracer.record_binding(cmd, &other, n as u32).unwrap();
            ctx.device.cmd_fill_buffer(cmd, other_hits.buffer, 0, vk::WHOLE_SIZE, 0);
        }
    });
    let messages = ctx.take_validation_messages();
    assert!(
        messages.iter().any(|m| m.contains("SYNC-HAZARD")),
        "synchronization validation is not on: no hazard reported for an unsynchronized overwrite ({messages:?})"
    );
    drop((binding, other, other_hits));
    drop((tracer, ranges));
    assert_validation_clean(&ctx);
}

/// How the caller's "raygen" writes the rays before the trace.
#[derive(Clone, Copy, Debug)]
enum Raygen {
    /// The example engine's raygen shader (`glsl/examples/raygen.comp`): `SHADER_WRITE`.
    Compute,
    /// A copy from a staging buffer (an upload): `TRANSFER_WRITE`.
    Copy,
}

/// The push constants of the example's raygen shader for `camera` (the example's
/// pinhole basis, in f32).
fn raygen_params(camera: &Camera, width: u32, height: u32) -> CameraParams {
    let forward = (camera.target - camera.eye).normalize();
    let right = forward.cross(camera.up).normalize();
    let up = right.cross(forward);
    let tan = (0.5 * camera.fov_deg.to_radians()).tan();
    let v4 = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
    CameraParams {
        eye: v4(camera.eye),
        forward: v4(forward),
        right: v4(right * tan * width as f32 / height as f32),
        up: v4(up * tan),
        width,
        height,
        pad0: 0,
        pad1: 0,
    }
}

/// The caller's writes of the rays are the caller's to synchronize, and kdtrace's
/// own barriers name only kdtrace's own buffers: an engine that records its
/// raygen and then `record_trace` without the barrier the recording contract
/// asks for is reported by synchronization validation in every mode — the
/// robust default (whose careful-list reset once was a global barrier that hid
/// the bug), plain traversal, the rays ordered on the device, a traversal with
/// side buffers — whether a compute shader or a copy wrote the rays. With the
/// contract's barriers as buffer barriers naming only the caller's ranges (the
/// rays before the trace; the hits before a second recording of the binding)
/// each is clean: kdtrace orders the reuse of its own buffers itself.
#[test]
fn a_missing_barrier_after_the_callers_raygen_is_reported() {
    let Some(SyncCase { ctx, mut tracer, camera, .. }) = sync_case() else { return };
    let (width, height) = (16, 12);
    let count = width * height;
    let rays = camera_rays(&camera, width, height);

    // The engine's buffers: rays (device-local), a staging copy of them, hits.
    let ray_bytes = (count as usize * std::mem::size_of::<Ray>()) as u64;
    let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
    let ray_buf = Buffer::new(
        &ctx,
        ray_bytes,
        usage | vk::BufferUsageFlags::TRANSFER_DST,
        MemoryLocation::GpuOnly,
        "engine rays",
    )
    .unwrap();
    let mut staging =
        Buffer::new(&ctx, ray_bytes, vk::BufferUsageFlags::TRANSFER_SRC, MemoryLocation::CpuToGpu, "engine staging")
            .unwrap();
    staging.write(0, bytemuck::cast_slice(&rays)).unwrap();
    let hit_bytes = (count as usize * std::mem::size_of::<Hit>()) as u64;
    let hit_buf = Buffer::new(&ctx, hit_bytes, usage, MemoryLocation::GpuToCpu, "engine hits").unwrap();
    let (ray_range, hit_range) = (BufferRange::whole(&ray_buf), BufferRange::whole(&hit_buf));

    // The engine's raygen: the example's shader, as a kdtrace kernel for brevity.
    let raygen = Kernel::new(
        &ctx,
        &KernelDesc {
            name: "engine raygen",
            spirv: shaders::EXAMPLE_RAYGEN,
            bindings: ENGINE_RAYGEN_BINDINGS,
            push_constant_size: std::mem::size_of::<CameraParams>() as u32,
            workgroup_size: ENGINE_WORKGROUP,
            ..Default::default()
        },
    )
    .unwrap();
    let mut raygen_ranges = [ray_range; ENGINE_RAYGEN_BINDINGS as usize];
    raygen_ranges[ENGINE_RAYGEN_BINDING_RAYS as usize] = ray_range;
    // SAFETY: the ray buffer is a live storage buffer that outlives the set.
    let raygen_set = unsafe { BufferSet::from_ranges(&ctx, &raygen, &raygen_ranges) }.unwrap();
    let params = raygen_params(&camera, width, height);

    // A barrier of the caller's naming only `buffer`, from `src` to compute-shader `dst_access`.
    // SAFETY (at each call): `cmd` is recording outside a render pass; `buffer` is live.
    let caller_barrier = |cmd, buffer, src: (vk::PipelineStageFlags, vk::AccessFlags), dst_access| unsafe {
        let barrier = vk::BufferMemoryBarrier::default()
            .src_access_mask(src.1)
            .dst_access_mask(dst_access)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(buffer)
            .offset(0)
            .size(vk::WHOLE_SIZE);
        let (dst_stage, flags) = (vk::PipelineStageFlags::COMPUTE_SHADER, vk::DependencyFlags::empty());
        ctx.device.cmd_pipeline_barrier(cmd, src.0, dst_stage, flags, &[], &[barrier], &[]);
    };

    // The default (robust: two passes), plain traversal (one), the rays ordered on
    // the device first, and a traversal with side buffers (robust and plain).
    let plain = |options: TraceOptions| TraceOptions::new(Traversal { robust: false, ..options.traversal });
    let (robust, backtrack) = (TraceOptions::default(), TraceOptions::variant(Variant::Backtrack));
    let ordered = TraceOptions { order: RayOrder::Coherent, ..robust };
    let modes = [
        ("robust", robust),
        ("plain", plain(robust)),
        ("ordered", ordered),
        ("robust backtrack", backtrack),
        ("plain backtrack", plain(backtrack)),
    ];
    for (mode, options) in modes {
        tracer.prepare(&options).unwrap();
        let expected = tracer.trace(&rays, &options).unwrap().hits;
        assert!(ctx.take_validation_messages().is_empty());
        for kind in [Raygen::Compute, Raygen::Copy] {
            for with_barrier in [true, false] {
                let binding = submit(&ctx, |cmd| {
                    // SAFETY: `cmd` is recording outside a render pass; the buffers,
                    // the set and the binding outlive the waited submission.
                    unsafe {
                        let written = match kind {
                            Raygen::Compute => {
                                raygen.record_dispatch(cmd, raygen_set.set, bytemuck::bytes_of(&params), count);
                                (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE)
                            }
                            Raygen::Copy => {
                                let region = [vk::BufferCopy { src_offset: 0, dst_offset: 0, size: ray_bytes }];
                                ctx.device.cmd_copy_buffer(cmd, staging.buffer, ray_buf.buffer, &region);
                                (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE)
                            }
                        };
                        let read_write = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
                        if with_barrier {
                            caller_barrier(cmd, ray_buf.buffer, written, read_write);
                        }
                        let binding = tracer.record_trace(cmd, ray_range, hit_range, count, &options).unwrap();
                        if with_barrier {
                            // A second recording after the contract's barrier on the hits
                            // alone: kdtrace orders the reuse of its own buffers itself.
                            let traced = (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE);
                            caller_barrier(cmd, hit_buf.buffer, traced, read_write);
                            tracer.record_binding(cmd, &binding, count).unwrap();
                        }
                        binding
                    }
                });
                drop(binding);
                let messages = ctx.take_validation_messages();
                let case = format!("{mode}, {kind:?} raygen, {} barrier", ["without", "with"][with_barrier as usize]);
                if with_barrier {
                    assert!(
                        messages.is_empty(),
                        "{case}: hazards with the contract's barrier:\n{}",
                        messages.join("\n")
                    );
                    if let Raygen::Copy = kind {
                        let hits = bytemuck::cast_slice(hit_buf.read(0, hit_bytes as usize).unwrap()).to_vec();
                        assert!(same_bits(&hits, &expected), "{case}: the hits of Tracer::trace");
                    }
                    continue;
                }
                // Reported at the ray binding of the first kernel that reads the rays.
                let ray_binding = match options.order {
                    RayOrder::AsGiven => BINDING_RAYS,
                    RayOrder::Coherent => ORDER_BINDING_RAYS,
                };
                let on_rays = format!("binding #{ray_binding} ");
                let hazard =
                    messages.iter().find(|m| m.contains("SYNC-HAZARD-READ-AFTER-WRITE") && m.contains(&on_rays));
                let hazard = hazard.unwrap_or_else(|| panic!("{case}: not reported on the rays ({messages:?})"));
                let prior = hazard.split("prior_usage: ").nth(1).and_then(|p| p.split(',').next()).unwrap_or("?");
                eprintln!("{case}: SYNC-HAZARD-READ-AFTER-WRITE at {on_rays}(prior usage {prior})");
            }
        }
    }
    drop((raygen_set, raygen, tracer, ray_buf, staging, hit_buf));
    assert_validation_clean(&ctx);
}

/// A scene replaced inside the engine's frame: one command buffer traces the
/// old scene, records the new scene's upload (`record_replace_scene`: no submit,
/// no wait) and traces the new scene with a side-buffer variant (the side
/// buffers come along in the same recording). Hazard-free under synchronization
/// validation, each trace equal to a fresh tracer's; the old scene and the
/// staging buffers stay until the caller says the frame completed.
#[test]
fn scenes_replaced_in_a_recorded_frame_are_released_after_it() {
    let Some(SyncCase { ctx, scene, tree, mut tracer, camera }) = sync_case() else { return };
    let (teapot, teapot_tree) = load("teapot.obj");
    let mut rays = camera_rays(&camera, 24, 16);
    let lo = scene.bounds.min.min(teapot.bounds.min);
    let hi = scene.bounds.max.max(teapot.bounds.max);
    rays.extend(random_rays(&mut Rng(21), lo, hi, 400));
    let n = rays.len();
    let (old_ranges, new_ranges) = (Ranges::new(&ctx, &rays), Ranges::new(&ctx, &rays));
    let options = TraceOptions::default();
    let backtrack = TraceOptions::variant(Variant::Backtrack);
    tracer.prepare(&backtrack).unwrap();
    let expected_old = tracer.trace(&rays, &options).unwrap();
    let mut fresh = Tracer::new(&ctx, &teapot_tree, &teapot.triangles).unwrap();
    fresh.prepare(&backtrack).unwrap();
    let expected_new = fresh.trace(&rays, &backtrack).unwrap();
    let fresh_bytes = fresh.device_bytes();
    drop(fresh);
    let old_bytes = tracer.device_bytes();

    // SAFETY: the ranges are live storage buffers; the bindings outlive the wait.
    let old_binding = unsafe { tracer.bind(old_ranges.rays, old_ranges.hits, None, &options) }.unwrap();
    assert!(ctx.take_validation_messages().is_empty());
    let new_binding = submit(&ctx, |cmd| {
        // SAFETY: `cmd` is recording; everything it uses outlives the wait.
        unsafe {
            tracer.record_binding(cmd, &old_binding, n as u32).unwrap();
            tracer.record_replace_scene(cmd, &teapot_tree, &teapot.triangles, 7).unwrap();
            let binding = tracer.bind(new_ranges.rays, new_ranges.hits, None, &backtrack).unwrap();
            tracer.record_binding(cmd, &binding, n as u32).unwrap();
            binding
        }
    });
    let messages = ctx.take_validation_messages();
    assert!(messages.is_empty(), "a recorded scene replacement is not hazard-free:\n{}", messages.join("\n"));
    assert!(same_bits(&old_ranges.hits(n), &expected_old.hits), "the trace before the replacement");
    assert!(same_bits(&new_ranges.hits(n), &expected_new.hits), "the trace after the replacement");
    assert_eq!(tracer.device_bytes(), fresh_bytes, "the new scene with its side buffers");
    // The old binding belongs to the old scene.
    // SAFETY: nothing is recorded when it fails.
    invalid(submit(&ctx, |cmd| unsafe { tracer.record_binding(cmd, &old_binding, n as u32) }), "scene");

    // Retired: the old scene (with its side buffers) and the staging buffers.
    assert!(tracer.retired_bytes() > old_bytes, "{} retired bytes", tracer.retired_bytes());
    assert_eq!(tracer.release_retired(6), 0, "frame 7 is not done yet");
    assert!(tracer.retired_bytes() > 0);
    assert_eq!(tracer.release_retired(7), 1);
    assert_eq!(tracer.retired_bytes(), 0);
    // The replaced scene still traces after the release.
    assert!(same_bits(&tracer.trace(&rays, &backtrack).unwrap().hits, &expected_new.hits));

    // On error nothing changes: an empty scene.
    let empty = KdTree::build(&[], &BuildConfig::default());
    // SAFETY: as above.
    invalid(submit(&ctx, |cmd| unsafe { tracer.record_replace_scene(cmd, &empty, &[], 8) }), "no triangles");
    assert_eq!(tracer.retired_bytes(), 0);
    drop((old_binding, new_binding, tracer, old_ranges, new_ranges));
    drop(tree);
    assert_validation_clean(&ctx);
}
