//! GPU tracing on a Vulkan device (lavapipe in CI): hits equal the CPU twin's
//! bit for bit, counters equal, and both agree with the float64 brute force.

mod common;

use std::sync::Arc;

use common::{assert_validation_clean, context, random_rays, scene_path, Rng};
use glam::Vec3;
use kdtrace::consts::{PRIM_INVALID, PRIM_MISS};
use kdtrace::exact::tolerant::{Agreement, Reference};
use kdtrace::gpu::GpuContext;
use kdtrace::kdtree::links::TreeLinks;
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::render::camera_rays;
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::{Hit, Ray};

fn same_bits(a: &Hit, b: &Hit) -> bool {
    a.t.to_bits() == b.t.to_bits()
        && a.prim_id == b.prim_id
        && a.u.to_bits() == b.u.to_bits()
        && a.v.to_bits() == b.v.to_bits()
}

/// Every traversal the kernel can be specialized to: all variants, short stacks of 1..=8.
fn all_traversals() -> Vec<Traversal> {
    let mut all = Vec::new();
    for variant in Variant::ALL {
        if variant.uses_short_stack() {
            all.extend([1, 2, 3, 5, 8].map(|stack_size| Traversal { stack_size, ..Traversal::closest(variant) }));
        } else {
            all.push(Traversal::closest(variant));
        }
    }
    // The robustness measures off (a specialization constant; its CPU twin too).
    all.extend(
        [Variant::Stack, Variant::Restart, Variant::Ropes]
            .map(|v| Traversal { robust: false, ..Traversal::closest(v) }),
    );
    all
}

/// Checks each scene in turn: `(file, camera resolution, random rays)`. The
/// tracers share their pipelines with the other test's (`common::trace`), so each
/// of the 72 kernels compiles about once in this binary: the stack first (the
/// baseline), then one test takes the others in order and the other in reverse
/// (`reverse`), until they meet. The Stanford scenes may not be committed:
/// `tools/fetch-scenes` puts them in `scenes/` (CI runs it); without them they
/// are skipped with a message, except under CI, where that fails.
fn check_scenes(scenes: &[(&str, (u32, u32), usize)], reverse: bool) {
    let ctx = common::shared_context();
    let mut tracer = None;
    for &(name, size, random) in scenes {
        if common::fetched_scene(name).is_none() {
            continue;
        }
        check_scene(&ctx, &mut tracer, name, size, random, reverse);
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

fn check_scene(
    ctx: &Arc<GpuContext>,
    tracer: &mut Option<Tracer>,
    name: &str,
    (width, height): (u32, u32),
    random: usize,
    reverse: bool,
) {
    let path = scene_path(name);
    let scene = Scene::load(&path).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let links = TreeLinks::new(&tree.nodes, tree.bounds);
    let tracer = common::load_scene(tracer, ctx, &tree, &scene.triangles);

    let stem = path.file_stem().unwrap().to_string_lossy().to_string();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), &stem)
        .unwrap()
        .unwrap_or_else(|| Camera::frame(&scene.bounds));
    let mut rays = camera_rays(&camera, width, height);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ name.len() as u64);
    rays.extend(random_rays(&mut rng, scene.bounds.min, scene.bounds.max, random));
    // Rays that start outside the box and point away from it miss everything.
    let away = scene.bounds.max + scene.bounds.extent();
    rays.extend((0..64).map(|_| Ray::new(away, rng.unit_vector().abs() + Vec3::splat(0.01), 0.0, f32::INFINITY)));

    let cpu_scene = SceneRef::new(&tree, &scene.triangles).with_links(&links);
    // The float64 reference of each ray (brute force), for the stack and the plain kernels.
    let references: Vec<Reference> = rays.iter().map(|ray| Reference::new(&scene.triangles, ray)).collect();
    let mut baseline: Option<Vec<Hit>> = None;
    // The stack (closest hit) first: it is the baseline of the others.
    let mut traversals = all_traversals();
    assert_eq!(traversals[0], Traversal::closest(Variant::Stack));
    if reverse {
        traversals[1..].reverse();
    }
    for traversal in traversals {
        for any_hit in [false, true] {
            let traversal = Traversal { any_hit, ..traversal };
            let gpu = common::trace(tracer, &rays, &TraceOptions::counted(traversal)).unwrap();
            let gpu_counters = gpu.counters.as_ref().unwrap();
            let mut hits = 0;
            let mut grazing = 0;
            let mut disagreements = Vec::new();
            for (i, ray) in rays.iter().enumerate() {
                let (cpu_hit, cpu_counters) = trace_ray(&cpu_scene, ray, traversal);
                assert!(
                    same_bits(&gpu.hits[i], &cpu_hit),
                    "{name} {traversal:?} ray {i} {ray:?}: GPU {:?} != CPU {:?}",
                    gpu.hits[i],
                    cpu_hit
                );
                assert_eq!(gpu_counters[i], cpu_counters, "{name} {traversal:?} ray {i}: counters differ");
                hits += cpu_hit.is_hit() as usize;
                // The plain (robust: false) traversals round differently from the
                // robust stack: they are checked against the f64 reference instead.
                let stack_hit = baseline.as_ref().filter(|_| traversal.robust).map(|b| b[i]);
                match (any_hit, stack_hit) {
                    (false, None) => match references[i].agrees(&cpu_hit) {
                        Agreement::Disagree(why) => disagreements.push(format!("ray {i} {ray:?}: {why}")),
                        Agreement::Grazing => grazing += 1,
                        _ => {}
                    },
                    (false, Some(stack)) => {
                        // Same t bit for bit; a different primitive only in an exact tie.
                        assert_eq!(
                            cpu_hit.t.to_bits(),
                            stack.t.to_bits(),
                            "{name} {traversal:?} ray {i}: t differs from stack"
                        );
                        if cpu_hit.prim_id != stack.prim_id {
                            let [v0, v1, v2] = scene.triangles[stack.prim_id as usize];
                            let wr = kdtrace::geom::WatertightRay::new(ray.origin.into(), ray.dir.into());
                            let t = wr.intersect(v0, v1, v2, ray.tmin, ray.tmax).map(|h| h.0);
                            assert_eq!(t, Some(cpu_hit.t), "{name} {traversal:?} ray {i}: not a tie");
                        }
                    }
                    (true, Some(stack)) => {
                        // An occluder is reported exactly when the closest hit exists, and it is a real hit.
                        assert_eq!(cpu_hit.is_hit(), stack.is_hit(), "{name} {traversal:?} ray {i}: any-hit status");
                        if cpu_hit.is_hit() {
                            let [v0, v1, v2] = scene.triangles[cpu_hit.prim_id as usize];
                            let wr = kdtrace::geom::WatertightRay::new(ray.origin.into(), ray.dir.into());
                            assert!(wr.intersect(v0, v1, v2, ray.tmin, ray.tmax).is_some());
                        }
                    }
                    (true, None) => {
                        // Plain any-hit: a reported occluder is a real hit.
                        if cpu_hit.is_hit() {
                            let [v0, v1, v2] = scene.triangles[cpu_hit.prim_id as usize];
                            let wr = kdtrace::geom::WatertightRay::new(ray.origin.into(), ray.dir.into());
                            let plain = kdtrace::geom::WatertightRay { robust: false, ..wr };
                            assert!(plain.intersect(v0, v1, v2, ray.tmin, ray.tmax).is_some());
                        }
                    }
                }
            }
            let tail = &gpu.hits[rays.len() - 64..];
            assert!(tail.iter().all(|h| h.prim_id == PRIM_MISS), "{name}: rays pointing away must miss");
            assert!(hits > rays.len() / 10, "{name} {traversal:?}: only {hits} of {} rays hit", rays.len());
            assert!(
                disagreements.is_empty(),
                "{name} {traversal:?}: {} of {} rays disagree with the float64 reference:\n{}",
                disagreements.len(),
                rays.len(),
                disagreements.iter().take(10).cloned().collect::<Vec<_>>().join("\n")
            );
            assert!(grazing * 1000 <= rays.len(), "{name} {traversal:?}: {grazing} grazing disagreements is too many");
            if baseline.is_none() {
                eprintln!(
                    "{name} stack: {} rays, {hits} hits; float64 reference: {grazing} grazing, 0 wrong",
                    rays.len()
                );
                baseline = Some(gpu.hits.clone());
            }
        }
    }
    eprintln!("{name}: every traversal (closest and any-hit) equals its CPU twin and the stack baseline");
}

// Two tests of about equal work, so the two test threads share it.
#[test]
fn cornell_box_teapot_and_bunny_match_cpu_and_reference() {
    check_scenes(
        &[("cornell_box.obj", (64, 48), 2000), ("teapot.obj", (64, 48), 3000), ("bunny.obj", (24, 16), 400)],
        false,
    );
}

#[test]
fn q3_20kdm2_and_dragon_match_cpu_and_reference() {
    check_scenes(&[("q3_20kdm2.obj", (64, 48), 3000), ("dragon_200k.obj", (24, 16), 300)], true);
}

#[test]
fn chunked_tracing_gives_the_same_hits() {
    let scene = Scene::load(&scene_path("teapot.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    // What `kdtrace stats` reports as device_bytes is what the tracer uploaded.
    assert_eq!(tracer.device_bytes(), kdtrace::trace::scene_device_bytes(&tree));
    let rays = random_rays(&mut Rng(7), scene.bounds.min, scene.bounds.max, 5000);
    let whole = tracer.trace(&rays, &TraceOptions::default()).unwrap();
    tracer.set_chunk_size(777);
    assert_eq!(tracer.chunk_size(), 777);
    let chunked = tracer.trace(&rays, &TraceOptions::default()).unwrap();
    assert_eq!(whole.hits.len(), chunked.hits.len());
    assert!(whole.hits.iter().zip(&chunked.hits).all(|(a, b)| same_bits(a, b)));
    assert!(whole.gpu_seconds.is_some_and(|s| s > 0.0), "lavapipe has timestamps");
    drop(tracer);
    assert_validation_clean(&ctx);
}

/// `RayOrder::Coherent` traces the batch sorted on the device, yet returns the same
/// hits and counters, in ray order, for every ray: random rays, rays from outside
/// the box, invalid rays (the last bucket) and a count that fills no whole
/// workgroup; robust (two passes) and plain (one), closest and any hit; in chunks.
#[test]
fn coherent_order_gives_the_same_hits_and_counters() {
    use kdtrace::trace::RayOrder;
    let scene = Scene::load(&scene_path("teapot.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let mut rng = Rng(11);
    let mut rays = random_rays(&mut rng, scene.bounds.min, scene.bounds.max, 5000);
    let far = scene.bounds.max + 100.0 * scene.bounds.extent();
    rays.extend((0..50).map(|_| Ray::new(far, -rng.unit_vector().abs() - Vec3::splat(0.01), 0.0, f32::INFINITY)));
    rays.insert(17, Ray::new(Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 1.0), 0.0, f32::INFINITY));
    rays.insert(3000, Ray::new(Vec3::ZERO, Vec3::ZERO, 0.0, f32::INFINITY));
    rays.push(Ray::new(Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::Z, 0.0, f32::INFINITY));
    assert!(rays.len() % 256 != 0);
    for traversal in [
        Traversal::closest(Variant::Stack),
        Traversal { any_hit: true, ..Traversal::closest(Variant::Stack) },
        Traversal { robust: false, ..Traversal::closest(Variant::Stack) },
        Traversal::closest(Variant::PushDownShortStack),
    ] {
        let given = tracer.trace(&rays, &TraceOptions { traversal, counters: true, order: RayOrder::AsGiven }).unwrap();
        for chunk in [usize::MAX, 1001] {
            tracer.set_chunk_size(chunk.min(rays.len()));
            let options = TraceOptions { traversal, counters: true, order: RayOrder::Coherent };
            let ordered = tracer.trace(&rays, &options).unwrap();
            assert!(given.hits.iter().zip(&ordered.hits).all(|(a, b)| same_bits(a, b)), "{traversal:?}");
            assert_eq!(given.counters, ordered.counters, "{traversal:?}");
        }
    }
    // The order is applied: a packet's passes depend on which rays share it (its
    // lanes wait for each other), so ordered packets of random rays take fewer steps,
    // with the same hits. (Single rays' counters above cannot tell the orders apart.)
    tracer.set_chunk_size(rays.len());
    let packets = Traversal { packet_width: 4, ..Traversal::closest(Variant::Stack) };
    let mut steps = |order| {
        let out = tracer.trace(&rays, &TraceOptions { traversal: packets, counters: true, order }).unwrap();
        let steps: u64 = out.counters.unwrap().iter().map(|c| u64::from(c.steps)).sum();
        (out.hits, steps)
    };
    let (given_hits, given_steps) = steps(RayOrder::AsGiven);
    let (ordered_hits, ordered_steps) = steps(RayOrder::Coherent);
    assert!(given_hits.iter().zip(&ordered_hits).all(|(a, b)| same_bits(a, b)));
    assert!(
        (ordered_steps as f64) < 0.9 * given_steps as f64,
        "packets of 4: {ordered_steps} steps in the coherent order, {given_steps} as given"
    );
    assert_eq!(
        tracer.trace(&rays[..0], &TraceOptions { order: RayOrder::Coherent, ..Default::default() }).unwrap().hits.len(),
        0
    );
    drop(tracer);
    assert_validation_clean(&ctx);
}

#[test]
fn invalid_and_empty_rays_are_flagged_not_traced() {
    let scene = Scene::load(&scene_path("cornell_box.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let o = Vec3::new(278.0, 273.0, -800.0);
    let forward = Vec3::Z;
    let rays = [
        Ray::new(o, Vec3::new(f32::NAN, 0.0, 1.0), 0.0, f32::INFINITY),
        Ray::new(o, Vec3::ZERO, 0.0, f32::INFINITY),
        Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), forward, 0.0, f32::INFINITY),
        Ray::new(Vec3::new(f32::INFINITY, 0.0, 0.0), forward, 0.0, f32::INFINITY),
        Ray::new(o, forward, f32::NAN, f32::INFINITY),
        Ray::new(o, forward, 10.0, 5.0),          // tmin > tmax: a valid empty segment
        Ray::new(o, forward, 0.0, 1.0),           // stops before the box
        Ray::new(o, forward, 0.0, f32::INFINITY), // hits the back wall
        Ray::new(o, Vec3::new(0.0, -0.0, 1.0), 0.0, f32::INFINITY), // signed zero
    ];
    let hits = tracer.trace(&rays, &TraceOptions::default()).unwrap().hits;
    for h in &hits[..5] {
        assert_eq!(h.prim_id, PRIM_INVALID, "{h:?}");
        assert!(h.t.is_nan());
    }
    assert_eq!(hits[5].prim_id, PRIM_MISS);
    assert_eq!(hits[6].prim_id, PRIM_MISS);
    assert!(hits[7].is_hit() && hits[7].t > 800.0, "{:?}", hits[7]);
    assert!(same_bits(&hits[7], &hits[8]), "-0.0 and +0.0 direction components trace alike");
    drop(tracer);
    assert_validation_clean(&ctx);
}

/// Pipelines compiled before the scene exists (as the CLI does while the tree
/// builds) are adopted by the tracer and give the same hits; a tracer's
/// pipelines shared with another scene's tracer are the same pipelines and
/// outlive the first tracer; pipelines of another context are refused.
#[test]
fn pipelines_compiled_in_advance_are_adopted() {
    use kdtrace::trace::{Backend, TracePipelines};
    let ctx = context();
    let scene = Scene::load(&scene_path("teapot.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let rays = random_rays(&mut Rng(7), scene.bounds.min, scene.bounds.max, 500);
    let options = TraceOptions::default();
    let mut pipelines = TracePipelines::new(&ctx);
    pipelines.prepare(Backend::KdTree, &options).unwrap();
    let mut adopted = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    adopted.adopt_pipelines(pipelines).unwrap();
    let mut fresh = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let (a, b) = (adopted.trace(&rays, &options).unwrap().hits, fresh.trace(&rays, &options).unwrap().hits);
    assert_eq!(a.len(), b.len());
    assert!(a.iter().zip(&b).all(|(x, y)| same_bits(x, y)));

    // Shared, not copied: a second scene's tracer adopts the first's pipelines,
    // binds the very same pipeline and traces on after the first is gone.
    let cornell = Scene::load(&scene_path("cornell_box.obj")).unwrap();
    let cornell_tree = KdTree::build(&cornell.triangles, &BuildConfig::default());
    let mut second = Tracer::new(&ctx, &cornell_tree, &cornell.triangles).unwrap();
    second.adopt_pipelines(adopted.shared_pipelines()).unwrap();
    let range = |b: &kdtrace::gpu::Buffer| kdtrace::gpu::BufferRange::whole(b);
    let usage = ash::vk::BufferUsageFlags::STORAGE_BUFFER;
    let location = gpu_allocator::MemoryLocation::GpuOnly;
    let ray_buf = kdtrace::gpu::Buffer::new(&ctx, 32 * 64, usage, location, "rays").unwrap();
    let hit_buf = kdtrace::gpu::Buffer::new(&ctx, 16 * 64, usage, location, "hits").unwrap();
    // SAFETY: whole storage buffers of this device, alive past the bindings.
    let (first_binding, second_binding) = unsafe {
        (
            adopted.bind(range(&ray_buf), range(&hit_buf), None, &options).unwrap(),
            second.bind(range(&ray_buf), range(&hit_buf), None, &options).unwrap(),
        )
    };
    assert_eq!(first_binding.pipeline(), second_binding.pipeline(), "the shared pipeline is not compiled again");
    drop((first_binding, second_binding, ray_buf, hit_buf));
    drop(adopted);
    let cornell_rays = random_rays(&mut Rng(8), cornell.bounds.min, cornell.bounds.max, 300);
    let mut cornell_fresh = Tracer::new(&ctx, &cornell_tree, &cornell.triangles).unwrap();
    let (a, b) = (
        second.trace(&cornell_rays, &options).unwrap().hits,
        cornell_fresh.trace(&cornell_rays, &options).unwrap().hits,
    );
    assert!(a.iter().zip(&b).all(|(x, y)| same_bits(x, y)));
    drop((second, cornell_fresh));

    let other = common::context();
    assert!(!Arc::ptr_eq(&ctx, &other), "the test needs two contexts");
    let err = fresh.adopt_pipelines(TracePipelines::new(&other)).unwrap_err();
    assert!(err.to_string().contains("another Vulkan context"), "{err}");
    drop(fresh);
    assert_validation_clean(&ctx);
    assert_validation_clean(&other);
}

/// `TraceResult::careful_rays` counts the rays the robust fast pass left to the
/// careful pass: rays that start on a triangle's plane (their own surface's hit at
/// `tmin`, within rounding) are all traced again and counted; the same rays moved
/// 2^-14 of the scene's coordinates off the plane (as the renderer moves its
/// secondary rays) take the fast pass alone; `--plain`, which has no careful pass, reports none.
#[test]
fn rays_starting_on_a_surface_take_the_careful_pass_and_are_counted() {
    let quad = |z: f32| {
        let [a, b, c, d] =
            [(-100.0, -100.0), (100.0, -100.0), (100.0, 100.0), (-100.0, 100.0)].map(|(x, y)| Vec3::new(x, y, z));
        [[a, b, c], [a, c, d]]
    };
    let triangles: Vec<[Vec3; 3]> = [quad(0.0), quad(50.0)].concat();
    let tree = KdTree::build(&triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &triangles).unwrap();
    let mut rng = Rng(29);
    let starts: Vec<(Vec3, Vec3)> = (0..1000)
        .map(|_| {
            let o = Vec3::new(rng.range(-60.0, 60.0), rng.range(-60.0, 60.0), 0.0);
            (o, Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 1.0))
        })
        .collect();
    let rays = |lift: f32| -> Vec<Ray> {
        starts.iter().map(|&(o, d)| Ray::new(o + Vec3::Z * lift, d, 0.0, f32::INFINITY)).collect()
    };
    let robust = TraceOptions::default();
    let on = tracer.trace(&rays(0.0), &robust).unwrap();
    let off = tracer.trace(&rays(100.0 / 16384.0), &robust).unwrap();
    assert_eq!(on.careful_rays, Some(1000), "every ray from the floor's plane is settled carefully");
    assert_eq!(off.careful_rays, Some(0), "rays lifted off the floor need no careful pass");
    // The closed segment starts on the floor: its exact answer is the floor at
    // t = 0; lifted, the roof.
    for (a, b) in on.hits.iter().zip(&off.hits) {
        assert!(a.prim_id < 2 && a.t == 0.0, "the floor at t = 0: {a:?}");
        assert!(b.prim_id >= 2 && b.t > 49.0, "the roof: {b:?}");
    }
    let plain = TraceOptions { traversal: Traversal { robust: false, ..Traversal::closest(Variant::Stack) }, ..robust };
    assert_eq!(tracer.trace(&rays(0.0), &plain).unwrap().careful_rays, None);
    drop(tracer);
    assert_validation_clean(&ctx);
}
