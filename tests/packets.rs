//! Packets as subgroups: every packet traversal, at every packet width the device's
//! subgroup allows, returns the same hit as single-ray traversal (the CPU twin) for every ray
//! (the same t bit for bit; another primitive only in an exact tie). Run at the
//! device's subgroup size, and on lavapipe again at 4 lanes in a child process
//! with `LP_NATIVE_VECTOR_WIDTH=128`. The packet twins (`trace_packet_logged`)
//! give the kernels' hits and per-lane counters bit for bit.

mod common;

use common::{assert_validation_clean, context, random_rays, scene_path, Rng};
use kdtrace::geom::WatertightRay;
use kdtrace::kdtree::traverse::{trace_packet_logged, trace_ray, Counters, SceneRef, Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::render::camera_rays_morton;
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::{Hit, Ray};

const PACKET_VARIANTS: [(Variant, u32); 6] = [
    (Variant::Stack, 3),
    (Variant::Restart, 3),
    (Variant::PushDown, 3),
    (Variant::ShortStack, 1),
    (Variant::ShortStack, 3),
    (Variant::PushDownShortStack, 3),
];

fn check_scene(tracer: &mut Tracer, tree: &KdTree, scene: &Scene, rays: &[Ray], widths: &[u32], name: &str) {
    // The single-ray answers from the CPU twins, which equal the GPU's single-ray
    // kernels bit for bit (tests/gpu_trace.rs, tests/stress.rs) and cost no
    // pipeline compiles.
    let scene_ref = SceneRef::new(tree, &scene.triangles);
    for (variant, stack_size) in PACKET_VARIANTS {
        for any_hit in [false, true] {
            let single = Traversal { stack_size, any_hit, ..Traversal::closest(variant) };
            let reference: Vec<Hit> = rays.iter().map(|r| trace_ray(&scene_ref, r, single).0).collect();
            for &packet_width in widths {
                let traversal = Traversal { packet_width, ..single };
                let result = tracer.trace(rays, &TraceOptions::counted(traversal)).unwrap();
                let mut ties = 0;
                assert_eq!(result.hits.len(), reference.len());
                for (i, (p, s)) in result.hits.iter().zip(&reference).enumerate() {
                    check_hit(scene, &rays[i], p, s, any_hit, &mut ties)
                        .unwrap_or_else(|why| panic!("{name} {traversal:?} ray {i} {:?}: {why}", rays[i]));
                }
                let counters = result.counters.unwrap();
                check_packet_twin(&scene_ref, rays, traversal, &result.hits, &counters, name);
                let active: u64 = counters.iter().map(|c| c.nodes as u64).sum();
                let steps: u64 = counters.iter().map(|c| c.steps as u64).sum();
                assert!(active <= steps, "a lane is active in at most every step of its packet");
                eprintln!(
                    "{name} {}{} W={packet_width}: same hits as single rays ({ties} exact ties), SIMD efficiency {:.0}%",
                    variant,
                    if any_hit { " any-hit" } else { "" },
                    100.0 * active as f64 / steps.max(1) as f64
                );
            }
        }
    }
}

/// The packet twins (`trace_packet_logged`, the records of `kdtrace divergence`)
/// take the kernels' decisions: the same hits and per-lane counters, bit for bit.
fn check_packet_twin(
    scene: &SceneRef,
    rays: &[Ray],
    traversal: Traversal,
    hits: &[Hit],
    counters: &[Counters],
    name: &str,
) {
    let w = traversal.packet_width as usize;
    let bits = |h: &Hit| (h.t.to_bits(), h.prim_id, h.u.to_bits(), h.v.to_bits());
    let count = |c: &Counters| (c.nodes, c.leaves, c.triangles, c.steps, c.restarts, c.drops);
    for (p, chunk) in rays.chunks(w).enumerate() {
        let twin = trace_packet_logged(scene, chunk, traversal, None).unwrap();
        for (k, (hit, c)) in twin.iter().enumerate() {
            let i = p * w + k;
            assert_eq!(bits(hit), bits(&hits[i]), "{name} {traversal:?} ray {i}: twin {hit:?}, GPU {:?}", hits[i]);
            assert_eq!(count(c), count(&counters[i]), "{name} {traversal:?} ray {i}: counters");
        }
    }
}

/// The plain packet kernels (t-value restarts, no exact fallback) against their twins.
#[test]
fn packet_twins_match_the_plain_kernels() {
    let ctx = context();
    let widths: Vec<u32> = [4, 8].into_iter().filter(|&w| w <= ctx.info.subgroup_size).collect();
    let scene = Scene::load(&scene_path("teapot.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), "teapot").unwrap().unwrap();
    let (mut rays, _) = camera_rays_morton(&camera, 32, 24);
    rays.extend(random_rays(&mut Rng(5), scene.bounds.min, scene.bounds.max, 800));
    let scene_ref = SceneRef::new(&tree, &scene.triangles);
    for (variant, stack_size) in PACKET_VARIANTS {
        for &packet_width in &widths {
            let traversal = Traversal { packet_width, stack_size, robust: false, ..Traversal::closest(variant) };
            let result = tracer.trace(&rays, &TraceOptions::counted(traversal)).unwrap();
            check_packet_twin(&scene_ref, &rays, traversal, &result.hits, &result.counters.unwrap(), "teapot");
        }
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

fn check_hit(
    scene: &Scene,
    ray: &Ray,
    packet: &Hit,
    single: &Hit,
    any_hit: bool,
    ties: &mut usize,
) -> Result<(), String> {
    if any_hit {
        if packet.is_hit() != single.is_hit()
            || packet.prim_id >= kdtrace::consts::PRIM_INCOMPLETE && packet.prim_id != single.prim_id
        {
            return Err(format!("any-hit status differs: packet {packet:?}, single {single:?}"));
        }
        if packet.is_hit() {
            let [v0, v1, v2] = scene.triangles[packet.prim_id as usize];
            let wr = WatertightRay::new(ray.origin.into(), ray.dir.into());
            if wr.intersect(v0, v1, v2, ray.tmin, ray.tmax).is_none() {
                return Err(format!("any-hit occluder {} is not hit", packet.prim_id));
            }
        }
        return Ok(());
    }
    if packet.t.to_bits() != single.t.to_bits() {
        return Err(format!("t differs: packet {packet:?}, single {single:?}"));
    }
    if packet.prim_id != single.prim_id {
        let [v0, v1, v2] = scene.triangles[packet.prim_id as usize];
        let wr = WatertightRay::new(ray.origin.into(), ray.dir.into());
        if wr.intersect(v0, v1, v2, ray.tmin, ray.tmax).map(|h| h.0) != Some(single.t) {
            return Err(format!("not an exact tie: packet {packet:?}, single {single:?}"));
        }
        *ties += 1;
    }
    Ok(())
}

/// Runs at the device's own subgroup size with every packet width it allows.
#[test]
fn packets_match_single_rays_at_device_subgroup_size() {
    let ctx = context();
    let subgroup = ctx.info.subgroup_size;
    if let Ok(expected) = std::env::var("KDTRACE_EXPECT_SUBGROUP") {
        assert_eq!(subgroup.to_string(), expected, "{}", ctx.info);
    }
    let widths: Vec<u32> = [2, 4, 8, 16, 32].into_iter().filter(|&w| w <= subgroup).collect();
    assert!(!widths.is_empty(), "{} has subgroups of {subgroup}: no packets to test", ctx.info);
    // One tracer for every scene, so each packet kernel is compiled once.
    let mut tracer: Option<Tracer> = None;
    for name in ["teapot", "q3_20kdm2", "cornell_box"] {
        let path = scene_path(&format!("{name}.obj"));
        let scene = Scene::load(&path).unwrap();
        let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, &scene.triangles);
        let camera = Camera::from_cameras_json(&scene_path("cameras.json"), name).unwrap().unwrap();
        let (mut rays, _) = camera_rays_morton(&camera, 48, 40);
        rays.extend(random_rays(&mut Rng(11), scene.bounds.min, scene.bounds.max, 1500));
        check_scene(tracer, &tree, &scene, &rays, &widths, name);
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

/// lavapipe runs 4-wide subgroups with `LP_NATIVE_VECTOR_WIDTH=128`: run the test
/// above again in a child process at that size, without Mesa's shader cache (Mesa
/// 25's does not tell the vector widths apart: a kernel cached at 8 lanes and run
/// at 4 crashes).
#[test]
fn packets_match_single_rays_at_subgroup_size_4_on_lavapipe() {
    if std::env::var("KDTRACE_EXPECT_SUBGROUP").is_ok() {
        return; // the child itself
    }
    let ctx = context();
    let lavapipe = ctx.info.name.contains("llvmpipe");
    drop(ctx);
    if !lavapipe {
        eprintln!("not lavapipe: the 4-lane run applies to lavapipe only");
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "packets_match_single_rays_at_device_subgroup_size", "--nocapture"])
        .env("LP_NATIVE_VECTOR_WIDTH", "128")
        .env("MESA_SHADER_CACHE_DISABLE", "true")
        .env("KDTRACE_EXPECT_SUBGROUP", "4")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "4-lane run failed:\n{stdout}\n{stderr}");
    assert!(stdout.contains("1 passed"), "the child ran no test:\n{stdout}");
    assert!(stderr.contains("W=4"), "the child traced no 4-wide packets:\n{stderr}");
}

/// A packet wider than the subgroup is a clear error, not a wrong picture.
#[test]
fn packet_wider_than_subgroup_is_refused() {
    let ctx = context();
    let scene = Scene::load(&scene_path("cornell_box.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let too_wide = ctx.info.max_subgroup_size * 2;
    let traversal = Traversal { packet_width: too_wide, ..Traversal::closest(Variant::Stack) };
    let rays = [Ray::default()];
    match tracer.trace(&rays, &TraceOptions::new(traversal)) {
        Err(kdtrace::Error::DeviceLimit(m)) => assert!(m.contains("packet width"), "{m}"),
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("packet width {too_wide} should be refused"),
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}
