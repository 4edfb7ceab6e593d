//! Two-level against single-level tracing, measured: a mesh traced as one
//! kd-tree ([`Tracer`], the single-level default) and as one identity instance
//! ([`TwoLevelTracer`]), then a 4×4 grid of rotated copies traced two-level
//! (one tree, 16 instances) and flattened (one tree over 16× the triangles);
//! `SIDE` sets the grid's side (8: 64 copies).
//! Camera rays (Morton order) of a 512×384 view; GPU time by timestamps, the
//! median of 3 after a warm-up; device bytes; build times; and how many rays the
//! two answers agree on (hit or miss, and the same triangle of the same copy).
//!
//! ```sh
//! cargo run --release --example instances -- [SCENE.obj] [SIDE]   # default scenes/bunny.obj, 4
//! ```

use std::sync::Arc;
use std::time::Instant;

use glam::{Affine3A, Quat, Vec3};
use kdtrace::gpu::{ContextOptions, GpuContext};
use kdtrace::kdtree::traverse::{Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::scene::{Camera, Scene};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::twolevel::{BottomLevel, Instance, InstanceHit, TwoLevelScene, TwoLevelTracer};
use kdtrace::{Aabb, Hit, Ray};

const WIDTH: u32 = 512;
const HEIGHT: u32 = 384;
const REPEAT: usize = 3;

fn main() -> anyhow::Result<()> {
    let path = std::env::args().nth(1).unwrap_or_else(|| "scenes/bunny.obj".into());
    let side: u32 = match std::env::args().nth(2) {
        Some(s) => s.parse().map_err(|_| anyhow::anyhow!("grid side {s:?}: expected a whole number"))?,
        None => 4,
    };
    anyhow::ensure!((1..=32).contains(&side), "grid side {side}: expected 1 to 32");
    let copies = side * side;
    let mesh = Scene::load(std::path::Path::new(&path))?.triangles;
    let ctx = GpuContext::headless(&ContextOptions::from_env())?;
    println!("{path}: {} triangles, {} ({WIDTH}x{HEIGHT} camera rays, robust stack)", mesh.len(), ctx.info.name);
    println!(
        "{:<28} {:>10} {:>9} {:>8} {:>12} {:>10}",
        "configuration", "instances", "ms (GPU)", "Mrays/s", "device MiB", "build ms"
    );
    let config = BuildConfig::default();
    let bounds = mesh.iter().flatten().fold(Aabb::EMPTY, |b, &p| b.grow(p));

    // One mesh: single level against one identity instance.
    let rays = camera_rays(&bounds);
    let start = Instant::now();
    let tree = KdTree::build(&mesh, &config);
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    let single = time_single(&ctx, &tree, &mesh, &rays)?;
    report("single level", 1, single.1, rays.len(), single.2, build_ms);
    let identity = [Instance { geometry: 0, transform: Affine3A::IDENTITY, instance_id: 0, mask: 0xff }];
    let start = Instant::now();
    let scene = TwoLevelScene::new(vec![BottomLevel::new(0, mesh.clone(), &config)], &identity)?;
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    let two = time_two_level(&ctx, &scene, &rays)?;
    report("two level, identity", 1, two.1, rays.len(), two.2, build_ms);
    let same = single.0.iter().zip(&two.0).filter(|(s, t)| same_answer(s, t, 0, mesh.len())).count();
    println!("  same answer: {same} of {} rays; two level / single level time: {:.2}x", rays.len(), two.1 / single.1);

    // A side x side grid of rotated copies.
    let size = bounds.extent().max_element();
    let instances: Vec<Instance> = (0..copies)
        .map(|i| {
            let at = Vec3::new((i % side) as f32, (i / side) as f32, 0.0) * size * 1.2 - bounds.center();
            let rotation = Quat::from_rotation_y(0.4 * i as f32);
            Instance {
                geometry: 0,
                transform: Affine3A::from_rotation_translation(rotation, at),
                instance_id: i,
                mask: 0xff,
            }
        })
        .collect();
    let start = Instant::now();
    let mut flat = Vec::with_capacity(copies as usize * mesh.len());
    for inst in &instances {
        flat.extend(mesh.iter().map(|t| t.map(|p| inst.transform.transform_point3(p))));
    }
    let flat_tree = KdTree::build(&flat, &config);
    let build_ms = start.elapsed().as_secs_f64() * 1e3;
    let grid_bounds = flat.iter().flatten().fold(Aabb::EMPTY, |b, &p| b.grow(p));
    let rays = camera_rays(&grid_bounds);
    let single = time_single(&ctx, &flat_tree, &flat, &rays)?;
    report("single level, flattened", copies as usize, single.1, rays.len(), single.2, build_ms);
    let mut scene = scene;
    let start = Instant::now();
    scene.set_instances(&instances)?;
    let top_ms = start.elapsed().as_secs_f64() * 1e3;
    let two = time_two_level(&ctx, &scene, &rays)?;
    report("two level", copies as usize, two.1, rays.len(), two.2, top_ms);
    let same =
        single.0.iter().zip(&two.0).filter(|(s, t)| same_answer(s, t, t.instance_index as usize, mesh.len())).count();
    println!("  same answer: {same} of {} rays; two level / single level time: {:.2}x", rays.len(), two.1 / single.1);
    println!("  (build ms: the flattened tree's SAH build against the top level's rebuild alone)");
    Ok(())
}

/// Camera rays framing `bounds`, in Morton order.
fn camera_rays(bounds: &Aabb) -> Vec<Ray> {
    let camera = Camera::frame(bounds);
    let mut pixels: Vec<(u32, u32)> = (0..HEIGHT).flat_map(|y| (0..WIDTH).map(move |x| (x, y))).collect();
    pixels.sort_by_key(|&(x, y)| morton(x, y));
    pixels
        .iter()
        .map(|&(x, y)| {
            let (o, d) = camera.ray(x as f32 + 0.5, y as f32 + 0.5, WIDTH, HEIGHT);
            Ray::new(o, d, 0.0, f32::INFINITY)
        })
        .collect()
}

fn morton(x: u32, y: u32) -> u64 {
    (0..16).map(|b| (((x >> b) & 1) as u64) << (2 * b) | (((y >> b) & 1) as u64) << (2 * b + 1)).sum()
}

/// Hits, median GPU seconds and device bytes of the single-level default.
fn time_single(
    ctx: &Arc<GpuContext>,
    tree: &KdTree,
    tris: &[[Vec3; 3]],
    rays: &[Ray],
) -> anyhow::Result<(Vec<Hit>, f64, u64)> {
    let mut tracer = Tracer::new(ctx, tree, tris)?;
    let options = TraceOptions::default();
    let mut times = Vec::new();
    let mut hits = Vec::new();
    for _ in 0..=REPEAT {
        let result = tracer.trace(rays, &options)?;
        times.push(result.gpu_seconds.unwrap_or(f64::NAN));
        hits = result.hits;
    }
    Ok((hits, median(times), kdtrace::trace::scene_device_bytes(tree)))
}

/// Hits, median GPU seconds and device bytes of the two-level kernel.
fn time_two_level(
    ctx: &Arc<GpuContext>,
    scene: &TwoLevelScene,
    rays: &[Ray],
) -> anyhow::Result<(Vec<InstanceHit>, f64, u64)> {
    let mut tracer = TwoLevelTracer::new(ctx, scene)?;
    let mut times = Vec::new();
    let mut hits = Vec::new();
    for _ in 0..=REPEAT {
        let (h, seconds) = tracer.trace_timed(rays, 0xff, Traversal::closest(Variant::Stack))?;
        times.push(seconds.unwrap_or(f64::NAN));
        hits = h;
    }
    Ok((hits, median(times), tracer.device_bytes()))
}

/// The median after dropping the first (the driver compiles on first dispatch).
fn median(mut times: Vec<f64>) -> f64 {
    times.remove(0);
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// Both miss, or both hit triangle `prim` of copy `copy` (flattened: `copy * per_copy + prim`).
fn same_answer(single: &Hit, two: &InstanceHit, copy: usize, per_copy: usize) -> bool {
    match (single.is_hit(), two.is_hit()) {
        (false, false) => true,
        (true, true) => single.prim_id as usize == copy * per_copy + two.prim_index as usize,
        _ => false,
    }
}

fn report(what: &str, instances: usize, seconds: f64, rays: usize, bytes: u64, build_ms: f64) {
    println!(
        "{what:<28} {instances:>10} {:>9.2} {:>8.2} {:>12.2} {build_ms:>10.1}",
        seconds * 1e3,
        rays as f64 / seconds / 1e6,
        bytes as f64 / (1 << 20) as f64
    );
}
