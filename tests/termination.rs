//! Termination and hard cases for every traversal variant: rays along and inside
//! split planes, origins on split planes, empty segments, flat (zero-extent)
//! nodes, and the driver's loop cut-off — never a hang, never a silent wrong miss.

mod common;

use common::{assert_validation_clean, context, Rng};
use glam::Vec3;
use kdtrace::consts::PRIM_INCOMPLETE;
use kdtrace::kdtree::links::TreeLinks;
use kdtrace::kdtree::traverse::{trace_ray, SceneRef, Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::Scene;
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::Ray;

fn variants() -> Vec<Traversal> {
    Variant::ALL
        .iter()
        .map(|&v| Traversal::closest(v))
        .chain([Traversal { stack_size: 1, ..Traversal::closest(Variant::ShortStack) }])
        .collect()
}

/// Rays that live on the tree's split planes: origins on a split, directions with
/// zero components (both signs), rays inside the plane, empty and point segments.
fn plane_rays(tree: &KdTree, rng: &mut Rng, count: usize) -> Vec<Ray> {
    let interior: Vec<_> = tree.nodes.iter().filter(|n| !n.is_leaf()).collect();
    let b = tree.bounds;
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    let mut rays = Vec::new();
    for i in 0..count {
        let n = interior[(rng.next_u64() % interior.len() as u64) as usize];
        let mut o = Vec3::new(rng.range(b.min.x, b.max.x), rng.range(b.min.y, b.max.y), rng.range(b.min.z, b.max.z));
        o[n.axis()] = n.split();
        let mut d = match i % 4 {
            0 => axes[(rng.next_u64() % 3) as usize] * if rng.next_f32() < 0.5 { 1.0 } else { -1.0 },
            1 => {
                // Inside the split plane.
                let mut d = rng.unit_vector();
                d[n.axis()] = if rng.next_f32() < 0.5 { 0.0 } else { -0.0 };
                d
            }
            2 => {
                let mut d = rng.unit_vector();
                d[(n.axis() + 1) % 3] = -0.0;
                d
            }
            _ => rng.unit_vector(),
        };
        if d == Vec3::ZERO {
            d = Vec3::X;
        }
        let (tmin, tmax) = match i % 7 {
            0 => (0.0, 0.0),
            1 => (5.0, 5.0),
            2 => (-1e30, f32::INFINITY),
            _ => (0.0, f32::INFINITY),
        };
        rays.push(Ray::new(o, d, tmin, tmax));
    }
    rays
}

fn check(name: &str, triangles: Vec<[Vec3; 3]>, rays_per_scene: usize) {
    let scene = Scene::from_triangles(triangles).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let links = TreeLinks::new(&tree.nodes, tree.bounds);
    let cpu = SceneRef::new(&tree, &scene.triangles).with_links(&links);
    let mut rng = Rng(0xDEAD_BEEF);
    let rays = plane_rays(&tree, &mut rng, rays_per_scene);
    let ctx = common::shared_context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let stack: Vec<_> = rays.iter().map(|r| trace_ray(&cpu, r, Variant::Stack).0).collect();
    for traversal in variants() {
        let gpu = common::trace(&mut tracer, &rays, &TraceOptions::new(traversal)).unwrap();
        let mut differ = 0;
        for (i, ray) in rays.iter().enumerate() {
            let (hit, _) = trace_ray(&cpu, ray, traversal);
            assert_ne!(hit.prim_id, PRIM_INCOMPLETE, "{name} {traversal:?} ray {i} {ray:?} did not finish");
            assert_eq!(
                gpu.hits[i].prim_id, hit.prim_id,
                "{name} {traversal:?} ray {i} {ray:?}: GPU {:?} != CPU {hit:?}",
                gpu.hits[i]
            );
            assert_eq!(gpu.hits[i].t.to_bits(), hit.t.to_bits(), "{name} {traversal:?} ray {i}: GPU != CPU");
            // Robust traversals find what the stack finds on these rays: the
            // restart-based ones follow it, backtrack and ropes fall back to exact
            // restarts where the ray lies in or starts on a split plane.
            if hit.t.to_bits() != stack[i].t.to_bits() {
                differ += 1;
                eprintln!("{name} {traversal:?} ray {i} {ray:?}: {hit:?} vs stack {:?}", stack[i]);
            }
        }
        assert_eq!(differ, 0, "{name} {traversal:?}: {differ} of {} plane rays differ from stack", rays.len());
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

fn grid(n: usize, z_jitter: bool) -> Vec<[Vec3; 3]> {
    let mut tris = Vec::new();
    let mut rng = Rng(42);
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (i as f32, j as f32);
            let z = |r: &mut Rng| if z_jitter { r.range(-0.5, 0.5) } else { 0.0 };
            let a = Vec3::new(x, y, z(&mut rng));
            let b = Vec3::new(x + 1.0, y, z(&mut rng));
            let c = Vec3::new(x, y + 1.0, z(&mut rng));
            let d = Vec3::new(x + 1.0, y + 1.0, z(&mut rng));
            tris.push([a, b, c]);
            tris.push([b, d, c]);
        }
    }
    tris
}

#[test]
fn teapot_plane_rays_finish_and_agree() {
    let scene = Scene::load(&common::scene_path("teapot.obj")).unwrap();
    check("teapot", scene.triangles, 3000);
}

#[test]
fn flat_scene_with_zero_extent_nodes() {
    // Every triangle in z = 0: the scene box and every node box have zero depth.
    check("flat grid", grid(24, false), 3000);
}

#[test]
fn axis_aligned_boxes_with_shared_planes() {
    // Unit cubes on a lattice: many triangles lie exactly in split planes.
    let mut tris = Vec::new();
    for i in 0..4 {
        for j in 0..4 {
            for k in 0..2 {
                let o = Vec3::new(2.0 * i as f32, 2.0 * j as f32, 2.0 * k as f32);
                let v = |x: f32, y: f32, z: f32| o + Vec3::new(x, y, z);
                let faces = [
                    [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)],
                    [v(0., 0., 1.), v(1., 0., 1.), v(1., 1., 1.), v(0., 1., 1.)],
                    [v(0., 0., 0.), v(1., 0., 0.), v(1., 0., 1.), v(0., 0., 1.)],
                    [v(0., 1., 0.), v(1., 1., 0.), v(1., 1., 1.), v(0., 1., 1.)],
                    [v(0., 0., 0.), v(0., 1., 0.), v(0., 1., 1.), v(0., 0., 1.)],
                    [v(1., 0., 0.), v(1., 1., 0.), v(1., 1., 1.), v(1., 0., 1.)],
                ];
                for [a, b, c, d] in faces {
                    tris.push([a, b, c]);
                    tris.push([a, c, d]);
                }
            }
        }
    }
    check("cube lattice", tris, 3000);
}

/// Mesa's lavapipe 22.x ends shader loops after 65535 passes per subgroup (Mesa
/// 25 no longer does). A leaf with more triangles than that (here 70,000
/// identical ones, which no split can separate) makes the leaf loop run out: the
/// tracer must report the rays as incomplete, never return them as misses. On a
/// device without the cut-off the hits must equal the CPU's.
#[test]
fn driver_loop_cut_off_is_reported_not_silent() {
    let tri = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
    let mut triangles = vec![tri; 70_000];
    triangles.push([Vec3::new(5.0, 5.0, 1.0), Vec3::new(6.0, 5.0, 1.0), Vec3::new(5.0, 6.0, 1.0)]);
    let scene = Scene::from_triangles(triangles).unwrap();
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let ctx = context();
    let mut tracer = Tracer::new(&ctx, &tree, &scene.triangles).unwrap();
    let rays = [
        Ray::new(Vec3::new(0.25, 0.25, -1.0), Vec3::Z, 0.0, f32::INFINITY), // through the 70k stack
        Ray::new(Vec3::new(5.25, 5.25, -1.0), Vec3::Z, 0.0, f32::INFINITY), // through the lone triangle
    ];
    let lavapipe_22 = ctx.info.name.contains("llvmpipe") && ctx.info.driver.contains("Mesa 22.");
    let result = tracer.trace(&rays, &TraceOptions::default()).expect("a batch with a cut-short ray is not an error");
    let incomplete = result.incomplete();
    if incomplete.is_empty() {
        assert!(!lavapipe_22, "lavapipe 22.x cuts loops at 65535 passes: expected an incomplete ray");
        let cpu = SceneRef::new(&tree, &scene.triangles);
        assert_eq!(rays.len(), result.hits.len());
        for (ray, hit) in rays.iter().zip(&result.hits) {
            assert_eq!(*hit, trace_ray(&cpu, ray, Variant::Stack).0);
        }
    } else {
        assert_eq!(incomplete, vec![0], "only the ray through the big leaf is cut short");
        assert!(result.hits[0].t.is_nan(), "an incomplete ray has t = NaN");
        // Nothing lost: the other ray's answer is kept and right.
        let cpu = SceneRef::new(&tree, &scene.triangles);
        assert_eq!(result.hits[1], trace_ray(&cpu, &rays[1], Variant::Stack).0);
        eprintln!("{}: the loop cut-off bites and is reported", ctx.info.name);
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}
