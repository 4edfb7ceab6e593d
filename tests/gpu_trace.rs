//! GPU tracing on a Vulkan device (lavapipe in CI): hits equal the CPU twin's
//! bit for bit, counters equal, and both agree with the float64 brute force.

mod common;

use common::{assert_validation_clean, context, random_rays, scene_path, Rng};
use glam::Vec3;
use kdtrace::consts::{PRIM_INVALID, PRIM_MISS};
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::reference::{agrees, Agreement};
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

fn check_scene(name: &str, random: usize) {
    let path = scene_path(name);
    let scene = Scene::load(&path).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();

    let stem = path.file_stem().unwrap().to_string_lossy().to_string();
    let camera = Camera::from_cameras_json(&scene_path("cameras.json"), &stem)
        .unwrap()
        .unwrap_or_else(|| Camera::frame(&scene.bounds));
    let mut rays = camera_rays(&camera, 64, 48);
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ name.len() as u64);
    rays.extend(random_rays(&mut rng, scene.bounds.min, scene.bounds.max, random));
    // Rays that start outside the box and point away from it miss everything.
    let away = scene.bounds.max + scene.bounds.extent();
    rays.extend((0..64).map(|_| Ray::new(away, rng.unit_vector().abs() + Vec3::splat(0.01), 0.0, f32::INFINITY)));

    let cpu_scene = SceneRef {
        nodes: &tree.nodes,
        prim_indices: &tree.prim_indices,
        triangles: &scene.triangles,
        bounds: tree.bounds,
    };
    for variant in Variant::ALL {
        let gpu = tracer.trace(&rays, &TraceOptions { variant, counters: true }).unwrap();
        let gpu_counters = gpu.counters.as_ref().unwrap();
        let mut hits = 0;
        let mut grazing = 0;
        let mut disagreements = Vec::new();
        for (i, ray) in rays.iter().enumerate() {
            let (cpu_hit, cpu_counters) = trace_ray(&cpu_scene, ray, variant);
            assert!(
                same_bits(&gpu.hits[i], &cpu_hit),
                "{name} {variant:?} ray {i} {ray:?}: GPU {:?} != CPU {:?}",
                gpu.hits[i],
                cpu_hit
            );
            assert_eq!(gpu_counters[i], cpu_counters, "{name} {variant:?} ray {i}: counters differ");
            hits += cpu_hit.is_hit() as usize;
            match agrees(&scene.triangles, ray, &cpu_hit) {
                Agreement::Disagree(why) => disagreements.push(format!("ray {i} {ray:?}: {why}")),
                Agreement::Grazing => grazing += 1,
                _ => {}
            }
        }
        let tail = &gpu.hits[rays.len() - 64..];
        assert!(tail.iter().all(|h| h.prim_id == PRIM_MISS), "{name}: rays pointing away must miss");
        assert!(hits > rays.len() / 10, "{name} {variant:?}: only {hits} of {} rays hit", rays.len());
        assert!(
            disagreements.is_empty(),
            "{name} {variant:?}: {} of {} rays disagree with the float64 reference:\n{}",
            disagreements.len(),
            rays.len(),
            disagreements.iter().take(10).cloned().collect::<Vec<_>>().join("\n")
        );
        assert!(grazing * 1000 <= rays.len(), "{name} {variant:?}: {grazing} grazing disagreements is too many");
        eprintln!(
            "{name} {variant:?}: {} rays, {hits} hits, GPU == CPU twin; float64 reference: {grazing} grazing, 0 wrong",
            rays.len()
        );
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

#[test]
fn cornell_box_matches_cpu_and_reference() {
    check_scene("cornell_box.obj", 2000);
}

#[test]
fn teapot_matches_cpu_and_reference() {
    check_scene("teapot.obj", 3000);
}

#[test]
fn q3_20kdm2_matches_cpu_and_reference() {
    check_scene("q3_20kdm2.obj", 3000);
}

#[test]
fn chunked_tracing_gives_the_same_hits() {
    let scene = Scene::load(&scene_path("teapot.obj")).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let rays = random_rays(&mut Rng(7), scene.bounds.min, scene.bounds.max, 5000);
    let whole = tracer.trace(&rays, &TraceOptions::default()).unwrap();
    tracer.set_chunk_size(777);
    assert_eq!(tracer.chunk_size(), 777);
    let chunked = tracer.trace(&rays, &TraceOptions::default()).unwrap();
    assert!(whole.hits.iter().zip(&chunked.hits).all(|(a, b)| same_bits(a, b)));
    assert!(whole.gpu_seconds.is_some_and(|s| s > 0.0), "lavapipe has timestamps");
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
