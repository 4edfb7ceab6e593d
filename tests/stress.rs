//! The accuracy stress suite (issue 7) on lavapipe: hard rays of every
//! category (`kdtrace::stress`) over the shared scenes, unscaled and scaled,
//! through every traversal variant on the GPU and the CPU twin, judged against
//! the exact reference (`kdtrace::exact`); and watertightness on closed meshes.
//!
//! Asserted: no serious error anywhere (a missed interior hit, a hit far from
//! its triangle, an incomplete or wrongly flagged answer); the variants that
//! follow the stack (exact restarts) return its hits bit for bit; every other
//! variant and packet width (`backtrack`, `ropes`, the packet kernels, the stack
//! at width 8 included) names the stack's primitive or another member of the
//! exact tie set (closest hit); agreement with the exact
//! answer of at least `OVERALL_FLOOR` over all categories and `CATEGORY_FLOOR`
//! in each, for every variant (any hit: `CATEGORY_FLOOR` in each category).
//! Besides the shared scenes: trigonometric fans (coordinates 6e-17 beside 1) and
//! the Cornell box at ×1e-20, ×1e15 and ×1e17; rays leaving slanted triangles from
//! their vertices. Watertightness: no escape with any variant. The
//! tables are printed (`--nocapture`).

mod common;

use common::{assert_validation_clean, scene_path};
use glam::Vec3;
use kdtrace::exact::Exact;
use kdtrace::kdtree::links::TreeLinks;
use kdtrace::kdtree::traverse::{trace_packet_logged, trace_ray, SceneRef, Traversal, Variant};
use kdtrace::kdtree::{BuildConfig, KdTree};
use kdtrace::raygen::SplitMix64;
use kdtrace::scene::Scene;
use kdtrace::stress::{exact_answers, judge_with, stress_rays, table_header, table_row, Category, Tally};
use kdtrace::trace::{TraceOptions, Tracer};
use kdtrace::{Hit, Ray};

/// Rays per category and scene.
const RAYS: usize = 600;
/// Lowest agreement in any category, for every variant: the goal, 99.5 %. The
/// lowest measured (`--nocapture`, 2026-12-07) is 99.83 %: one bounded segment of
/// 600 on the Cornell box ×1e5, for every variant (a segment ending within
/// rounding of a surface: see docs/ACCURACY.md, Open). Split-plane origins on the
/// teapot ×1e-4 (hits 1e-15 apart in t) were the lowest before, at 99.67 %.
const CATEGORY_FLOOR: f64 = 0.995;
/// Lowest agreement over all categories of one scene and traversal.
const OVERALL_FLOOR: f64 = 0.995;

/// One category's rays, their exact answers and the stack's hits.
type Batch = (Category, Vec<Ray>, Vec<Exact>, Vec<Hit>);

/// `per_category` rays of every category the scene has (seeded), with their
/// exact answers and the GPU stack's hits.
fn batches(tracer: &mut Tracer, triangles: &[[Vec3; 3]], tree: &KdTree, per_category: usize, seed: u64) -> Vec<Batch> {
    Category::ALL
        .iter()
        .map(|&c| (c, stress_rays(c, triangles, tree, per_category, seed)))
        .filter(|(_, rays)| !rays.is_empty())
        .map(|(c, rays)| {
            let exacts = exact_answers(triangles, &rays);
            let stack = common::trace(tracer, &rays, &TraceOptions::variant(Variant::Stack)).unwrap().hits;
            (c, rays, exacts, stack)
        })
        .collect()
}

fn traversals() -> Vec<Traversal> {
    let mut all: Vec<Traversal> = Variant::ALL.iter().map(|&v| Traversal::closest(v)).collect();
    all.push(Traversal { stack_size: 1, ..Traversal::closest(Variant::PushDownShortStack) });
    // Packets as subgroup lanes (the GPU only: the CPU twins trace single rays).
    all.push(Traversal { packet_width: 4, ..Traversal::closest(Variant::Restart) });
    all.push(Traversal { packet_width: 8, ..Traversal::closest(Variant::PushDownShortStack) });
    all.push(Traversal { packet_width: 8, ..Traversal::closest(Variant::Stack) });
    all
}

/// The variant, its short-stack size and its packet width.
fn describe(t: &Traversal) -> String {
    let packet = if t.packet_width > 1 { format!(" W={}", t.packet_width) } else { String::new() };
    format!("{}({}){packet}", t.variant.name(), t.stack_size)
}

fn cpu_hits(tree: &KdTree, triangles: &[[Vec3; 3]], links: &TreeLinks, rays: &[Ray], traversal: Traversal) -> Vec<Hit> {
    let scene = SceneRef::new(tree, triangles).with_links(links);
    rays.iter().map(|r| trace_ray(&scene, r, traversal).0).collect()
}

/// The same hit, bit for bit.
fn same_bits(a: &Hit, b: &Hit) -> bool {
    a.prim_id == b.prim_id
        && a.t.to_bits() == b.t.to_bits()
        && a.u.to_bits() == b.u.to_bits()
        && a.v.to_bits() == b.v.to_bits()
}

/// A hit of a tracer must name the stack's primitive, or one of the exact tie set.
fn same_primitive(a: &Hit, b: &Hit, exact: &Exact) -> bool {
    a.prim_id == b.prim_id
        || matches!(exact, Exact::Hit { ties, .. } if ties.contains(&a.prim_id) && ties.contains(&b.prim_id))
}

/// Each hit names the stack's primitive or another member of the exact tie set.
fn check_same_primitive(
    label: &str,
    category: &str,
    rays: &[Ray],
    hits: &[Hit],
    stack: &[Hit],
    exacts: &[Exact],
    failures: &mut Vec<String>,
) {
    assert!(rays.len() == hits.len() && hits.len() == stack.len() && stack.len() == exacts.len());
    let differ: Vec<usize> = (0..rays.len()).filter(|&i| !same_primitive(&hits[i], &stack[i], &exacts[i])).collect();
    if let Some(&i) = differ.first() {
        failures.push(format!(
            "{label} / {category}: {} hits name neither the stack's primitive nor a tie member, e.g. {:?}: {:?} vs stack {:?} (exact {:?})",
            differ.len(),
            rays[i],
            hits[i],
            stack[i],
            exacts[i]
        ));
    }
}

/// A shared scene scaled by `scale`, its tree and the tree's links.
fn scaled_scene(name: &str, scale: f32) -> (Scene, KdTree, TreeLinks) {
    let mut scene = Scene::load(&scene_path(name)).unwrap();
    for tri in scene.triangles.iter_mut() {
        *tri = tri.map(|v| v * scale);
    }
    let tree = KdTree::build(&scene.triangles, &BuildConfig::default());
    let links = TreeLinks::new(&tree.nodes, tree.bounds);
    (scene, tree, links)
}

/// Stresses each (scene, scale) in turn on one tracer (so each kernel compiles once).
fn stress_scenes(scenes: &[(&str, f32)]) {
    let ctx = common::shared_context();
    let mut tracer = None;
    let mut failures = Vec::new();
    for &(name, scale) in scenes {
        let (scene, tree, links) = scaled_scene(name, scale);
        let label = format!("{name} ×{scale}");
        stress_triangles(&mut tracer, &label, &scene.triangles, &tree, &links, RAYS, &mut failures);
    }
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

/// Every category of hard rays through every traversal (see the top), closest
/// and any hit, on one scene.
/// Traces on the binary's shared context (`common::shared_context`).
fn stress_triangles(
    tracer: &mut Option<Tracer>,
    name: &str,
    triangles: &[[Vec3; 3]],
    tree: &KdTree,
    links: &TreeLinks,
    rays_per_category: usize,
    failures: &mut Vec<String>,
) {
    let tracer = common::load_scene(tracer, &common::shared_context(), tree, triangles);
    let batches = batches(tracer, triangles, tree, rays_per_category, 7);
    for traversal in traversals() {
        for gpu in [true, false] {
            if !gpu && traversal != Traversal::closest(Variant::Stack) && traversal.variant != Variant::Ropes {
                continue; // the CPU twins equal the GPU bit for bit (tests/gpu_trace.rs)
            }
            let label = format!("{name} {} {}", describe(&traversal), if gpu { "GPU" } else { "CPU" });
            println!("\n{label}\n{}", table_header());
            let mut all = Tally::default();
            for (category, rays, exacts, stack) in &batches {
                let hits = if gpu {
                    common::trace(tracer, rays, &TraceOptions::new(traversal)).unwrap().hits
                } else {
                    cpu_hits(tree, triangles, links, rays, traversal)
                };
                let t = judge_with(triangles, rays, &hits, exacts, false);
                println!("{}", table_row(category.name(), &t));
                if t.serious() > 0 {
                    failures.push(format!(
                        "{label} / {}: {} serious: {:?}",
                        category.name(),
                        t.serious(),
                        t.serious_examples
                    ));
                }
                if t.agreement() < CATEGORY_FLOOR {
                    failures.push(format!("{label} / {}: agreement {:.4}", category.name(), t.agreement()));
                }
                if traversal.follows_stack() {
                    // Exact restarts visit the stack's leaves in its order: its hits, bit for bit.
                    assert_eq!(hits.len(), stack.len());
                    let differ = hits.iter().zip(stack).filter(|(a, b)| !same_bits(a, b)).count();
                    if differ > 0 {
                        failures.push(format!("{label} / {}: {differ} hits differ from the stack's", category.name()));
                    }
                } else if traversal != Traversal::closest(Variant::Stack) {
                    // Every other variant and packet width: the stack's primitive, or
                    // another member of the exact tie set (the README's claim).
                    check_same_primitive(&label, category.name(), rays, &hits, stack, exacts, failures);
                }
                all.rays += t.rays;
                all.incomplete += t.incomplete;
                for (n, m) in all.counts.iter_mut().zip(t.counts) {
                    *n += m;
                }
            }
            println!("{}", table_row("all", &all));
            if all.agreement() < OVERALL_FLOOR {
                failures.push(format!("{label}: overall agreement {:.4}", all.agreement()));
            }
        }
        // Any-hit (shadow) mode on the GPU: some real occluder, or none exactly when
        // nothing is hit; a wrong occluder or a missed interior one is serious. The
        // same floor per category.
        let any = Traversal { any_hit: true, ..traversal };
        let mut shadow = Tally::default();
        for (category, rays, exacts, _) in &batches {
            let hits = common::trace(tracer, rays, &TraceOptions::new(any)).unwrap().hits;
            let t = judge_with(triangles, rays, &hits, exacts, true);
            let label = format!("{name} {} any-hit / {}", describe(&traversal), category.name());
            if t.serious() > 0 {
                failures.push(format!("{label}: {} serious: {:?}", t.serious(), t.serious_examples));
            }
            if t.agreement() < CATEGORY_FLOOR {
                failures.push(format!("{label}: agreement {:.4}", t.agreement()));
            }
            shadow.rays += t.rays;
            shadow.incomplete += t.incomplete;
            for (n, m) in shadow.counts.iter_mut().zip(t.counts) {
                *n += m;
            }
        }
        println!("{}", table_row(&format!("{} any-hit, all categories", describe(&traversal)), &shadow));
    }
}

#[test]
fn stress_shared_scenes() {
    stress_scenes(&[("cornell_box.obj", 1.0), ("teapot.obj", 1.0)]);
}

/// Deep trees of big meshes and far rays (issue 17): every category, the far
/// origins at 1e3, 1e5, 1e7 and 1e10–1e30 scene diagonals (axis-parallel from
/// 1e3–1e30) and huge finite `tmax` included,
/// on the shared meshes with the deepest trees, sampled (the exact reference is
/// brute force), through every variant and packet kernel on the GPU, closest
/// hit and any-hit. Asserted: no incomplete ray, no serious error, agreement of
/// at least `CATEGORY_FLOOR` in every category, closest and any hit. Under CI a
/// missing scene fails.
#[test]
fn stress_deep_trees_and_far_rays() {
    let ctx = common::shared_context();
    let mut tracer = None;
    let mut failures = Vec::new();
    for (name, rays_per_category) in [("bunny.obj", 48), ("q3_20kdm2.obj", 48), ("dragon_200k.obj", 24)] {
        if common::fetched_scene(name).is_none() {
            continue;
        }
        let (scene, tree, _) = scaled_scene(name, 1.0);
        let triangles = &scene.triangles;
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, triangles);
        let batches = batches(tracer, triangles, &tree, rays_per_category, 11);
        for traversal in traversals() {
            for any_hit in [false, true] {
                let traversal = Traversal { any_hit, ..traversal };
                let label = format!("{name} {}{}", describe(&traversal), if any_hit { " any-hit" } else { "" });
                println!("\n{label}\n{}", table_header());
                for (category, rays, exacts, stack) in &batches {
                    let hits = common::trace(tracer, rays, &TraceOptions::new(traversal)).unwrap().hits;
                    let t = judge_with(triangles, rays, &hits, exacts, any_hit);
                    if !any_hit && traversal != Traversal::closest(Variant::Stack) {
                        check_same_primitive(&label, category.name(), rays, &hits, stack, exacts, &mut failures);
                    }
                    println!("{}", table_row(category.name(), &t));
                    if t.incomplete > 0 || t.serious() > 0 {
                        failures.push(format!(
                            "{label} / {}: {} incomplete, {} serious: {:?}",
                            category.name(),
                            t.incomplete,
                            t.serious(),
                            t.serious_examples
                        ));
                    }
                    // Any hit too (answers agree when both occluded or both free).
                    if t.agreement() < CATEGORY_FLOOR {
                        failures.push(format!("{label} / {}: agreement {:.4}", category.name(), t.agreement()));
                    }
                }
            }
        }
    }
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

/// Flat fans of triangles whose vertices are `cos`/`sin` values (cos(π/2) =
/// 6.1e-17 beside 1.0), stacked 0.5 apart, and a seeded soup of small triangles
/// among them: the scene of `tools/fan-scene.py`. Origins built from vertex
/// coordinates lie on a fan's plane within 1e-16 of a spoke, 2^-50–2^-57 of the
/// coordinates to one side of it: below the float-float coordinates' resolution,
/// so the exact test's edge signs there come from the exact orientation
/// (`edge_sign_exact` in triangle.glsl); before it, any hit agreed on 96.67 % of
/// this test's `vertex-coord origin` rays (every kernel but `stack` W=8: 98.17 %).
fn trigonometric_fans(fans: usize, segments: usize, soup: usize, seed: u64) -> Vec<[Vec3; 3]> {
    let mut tris = Vec::new();
    for k in 0..fans {
        let z = 0.5 * k as f32;
        let rim = |i: usize| {
            let a = 2.0 * std::f64::consts::PI * (i % segments) as f64 / segments as f64;
            Vec3::new(a.cos() as f32, a.sin() as f32, z)
        };
        for i in 0..segments {
            tris.push([Vec3::new(0.0, 0.0, z), rim(i), rim(i + 1)]);
        }
    }
    let mut rng = SplitMix64(seed);
    for _ in 0..soup {
        let c = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(0.0, 2.0));
        tris.push([0; 3].map(|_| c + Vec3::new(rng.range(-0.2, 0.2), rng.range(-0.2, 0.2), rng.range(-0.2, 0.2))));
    }
    tris
}

/// The shared scenes' floors on a scene none of them resembles (see
/// `trigonometric_fans`), every variant, closest and any hit.
#[test]
fn stress_trigonometric_fans() {
    let ctx = common::shared_context();
    let mut tracer = None;
    let mut failures = Vec::new();
    let triangles = trigonometric_fans(5, 64, 50, 5);
    let tree = KdTree::build(&triangles, &BuildConfig::default());
    let links = TreeLinks::new(&tree.nodes, tree.bounds);
    stress_triangles(&mut tracer, "trigonometric fans", &triangles, &tree, &links, RAYS, &mut failures);
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

/// Rays leaving a slanted triangle from one of its vertices (tmin = 0, the
/// origin exactly on the plane) hit that triangle at t = 0 on the GPU, as on
/// the CPU twin (bit for bit): the exact test's float-float numerator of `t`
/// can land a rounding on either side of 0, so near 0 its sign is the plane
/// side's, exactly (`plane_side_exact`). Before it, `kdtrace verify --scale 1e-5`
/// (and 1e16) of the Cornell box missed six of 1,000 rays from its corners
/// (vertex-coord origin 99.4 %). Soups of 300 triangles of random coordinates,
/// at three scales; the robust stack (one kernel, careful pass included), the
/// short stack and packets of 4.
#[test]
fn rays_leaving_a_vertex_hit_it_at_t_0() {
    let ctx = common::shared_context();
    let mut rng = SplitMix64(23);
    let mut tracer: Option<Tracer> = None;
    for scale in [1e-5f32, 1.0, 1e16] {
        let point = |rng: &mut SplitMix64| Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * scale;
        let triangles: Vec<[Vec3; 3]> = (0..300).map(|_| [point(&mut rng), point(&mut rng), point(&mut rng)]).collect();
        let mut rays = Vec::new();
        let mut expect = Vec::new();
        for (i, tri) in triangles.iter().enumerate() {
            let n = (tri[1] - tri[0]).as_dvec3().cross((tri[2] - tri[0]).as_dvec3());
            for k in [1, 2] {
                let dir = rng.unit_vector();
                if n.length() > 0.0 && n.normalize().dot(dir.as_dvec3()).abs() >= 0.05 {
                    rays.push(Ray::new(tri[k], dir, 0.0, f32::INFINITY));
                    expect.push(i as u32);
                }
            }
        }
        assert!(rays.len() > 450, "{} rays", rays.len());
        let tree = KdTree::build(&triangles, &BuildConfig::default());
        let scene = SceneRef::new(&tree, &triangles);
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, &triangles);
        let short_stack = Traversal::closest(Variant::ShortStack);
        let packets = Traversal { packet_width: 4, ..Traversal::closest(Variant::Stack) };
        for traversal in [Traversal::closest(Variant::Stack), short_stack, packets] {
            let hits = common::trace(tracer, &rays, &TraceOptions::new(traversal)).unwrap().hits;
            for ((ray, hit), &prim) in rays.iter().zip(&hits).zip(&expect) {
                assert!(
                    hit.t == 0.0 && hit.prim_id == prim,
                    "×{scale:e} {traversal:?}: {ray:?} left triangle {prim} from its vertex: {hit:?}"
                );
                if traversal.packet_width == 1 {
                    assert_eq!(*hit, trace_ray(&scene, ray, traversal).0, "×{scale:e} {traversal:?}: GPU = CPU twin");
                }
            }
        }
    }
    drop(tracer);
    assert_validation_clean(&ctx);
}

#[test]
fn stress_scaled_scenes() {
    stress_scenes(&[("teapot.obj", 1e-4), ("cornell_box.obj", 1e5)]);
}

/// The Cornell box scaled to coordinates of about 5e-18 and 5e17 (200 rays per
/// category): the f32 triangle test's products of two coordinates stay in range,
/// its `t` is the barycentric weights' sum of the vertices' distances (before
/// 2026-12-07 a product of three coordinates, which underflowed at ×1e-20: 82
/// serious errors in `kdtrace verify --scale 1e-20 --count 500`, t off by up to
/// 1.4 %; at ×1e15 it overflowed: 239 serious errors), and a bound below the
/// smallest normal f32 or an overflowed determinant sends the pair to the exact
/// test. And ×1e17 (coordinates to 5.6e19): the test for a far ray squared the
/// scene's extents, which overflowed above about 1e19, so no ray was far, none
/// was shifted to the scene, and hits 1e36 away tied in `t` (far axis-parallel
/// rays agreed on 29–32 %; ×1e16–×1e18 27–54 % in the far categories).
#[test]
fn stress_extreme_scales() {
    let ctx = common::shared_context();
    let mut tracer = None;
    let mut failures = Vec::new();
    for scale in [1e-20, 1e15, 1e17] {
        let (scene, tree, links) = scaled_scene("cornell_box.obj", scale);
        let name = format!("cornell_box.obj ×{scale:e}");
        stress_triangles(&mut tracer, &name, &scene.triangles, &tree, &links, 200, &mut failures);
    }
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

/// The GPU kernels equal their CPU twins on hard rays too, hits and counters bit
/// for bit: these rays need the f64 pass of a leaf (unsure pairs, depth ties) far
/// more often than camera and random rays (tests/gpu_trace.rs), and robust single
/// rays take it in a second, careful trace on the GPU but in one trace on the CPU.
/// The exposed faces of random unit voxels (8³ cells, a third filled): many
/// axis-aligned quads in the planes the builder splits at.
fn voxel_faces(seed: u64) -> Vec<[Vec3; 3]> {
    const N: i32 = 8;
    let mut rng = SplitMix64(seed);
    let filled: Vec<bool> = (0..N * N * N).map(|_| rng.next_f32() < 0.3).collect();
    let at = |p: [i32; 3]| p.iter().all(|&c| (0..N).contains(&c)) && filled[((p[0] * N + p[1]) * N + p[2]) as usize];
    let mut tris = Vec::new();
    for cell in 0..N * N * N {
        let p = [cell / (N * N), cell / N % N, cell % N];
        if !at(p) {
            continue;
        }
        for axis in 0..3 {
            for side in [0, 1] {
                let mut q = p;
                q[axis] += if side == 1 { 1 } else { -1 };
                if at(q) {
                    continue;
                }
                let mut c = Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
                c[axis] += side as f32;
                let (u, w) = (Vec3::AXES[(axis + 1) % 3], Vec3::AXES[(axis + 2) % 3]);
                let quad = [c, c + u, c + u + w, c + w];
                let [a, b, d, e] = if side == 1 { quad } else { [quad[0], quad[3], quad[2], quad[1]] };
                tris.push([a, b, d]);
                tris.push([a, d, e]);
            }
        }
    }
    tris
}

/// Segments that end exactly on a face lying in a split plane (`tmax` = 1 at a
/// face's centre, 3,040 rays from 16, 1e3, 1e5 and 1e6 away, where the segment
/// frame is shifted): the plane's rounded `t` may pass the segment's end, and the entry
/// beyond it, clamped to start there, must still be visited while there is no
/// hit (`starts_behind` in leaf.glsl: `stack` once ended such rays at that
/// entry, a miss; `backtrack`, `ropes` and the packet short stacks ended them at
/// the leaf before, see their GLSL). Every ray must agree with the exact
/// reference, for each robust variant on the GPU (closest and any hit) and its
/// CPU twin (the packet twin for packets).
#[test]
fn segments_ending_on_split_planes_keep_their_hit() {
    let ctx = common::shared_context();
    let triangles = voxel_faces(17);
    let tree = KdTree::build(&triangles, &BuildConfig::default());
    let links = TreeLinks::new(&tree.nodes, tree.bounds);
    let mut rng = SplitMix64(3);
    let mut rays = Vec::new();
    for t in triangles.iter().step_by(2) {
        // The quad's centre (its diagonal's midpoint), exact in f32.
        let end = (t[0] + t[2]) * 0.5;
        for reach in [16.0, 1.0e3, 1.0e5, 1.0e6] {
            // Offsets in steps of 1/8, so that origin + 1 * dir == end exactly.
            let offset = (rng.unit_vector() * reach * 8.0).round() / 8.0;
            if offset.length() < 1.0 {
                continue;
            }
            rays.push(Ray::new(end - offset, offset, 0.0, 1.0));
        }
    }
    let exacts = exact_answers(&triangles, &rays);
    let mut owned = Tracer::new(&ctx, &tree, &triangles).unwrap();
    let tracer = &mut owned;
    let scene = SceneRef::new(&tree, &triangles).with_links(&links);
    // Every variant that once ended such a ray before its hit (stack, backtrack,
    // ropes, packet short stacks), and the restart-based one that did not.
    let variants = [
        Traversal::closest(Variant::Stack),
        Traversal::closest(Variant::Backtrack),
        Traversal::closest(Variant::Ropes),
        Traversal::closest(Variant::ShortStack),
        Traversal { packet_width: 4, ..Traversal::closest(Variant::ShortStack) },
        Traversal { packet_width: 8, ..Traversal::closest(Variant::PushDownShortStack) },
    ];
    let mut failures = Vec::new();
    for closest in variants {
        let any = Traversal { any_hit: true, ..closest };
        let twin = |traversal: Traversal| -> Vec<Hit> {
            if traversal.packet_width == 1 {
                return cpu_hits(&tree, &triangles, &links, &rays, traversal);
            }
            let width = traversal.packet_width as usize;
            let packets = rays.chunks(width).map(|p| trace_packet_logged(&scene, p, traversal, None).unwrap());
            packets.flatten().map(|(hit, _)| hit).collect()
        };
        for (mode, traversal, any_hit) in [("closest", closest, false), ("any hit", any, true)] {
            let gpu = common::trace(tracer, &rays, &TraceOptions::new(traversal)).unwrap().hits;
            for (side, hits) in [("GPU", gpu), ("CPU twin", twin(traversal))] {
                let label = format!("{} {mode} {side}", describe(&traversal));
                let t = judge_with(&triangles, &rays, &hits, &exacts, any_hit);
                println!("{}\n{}", table_header(), table_row(&label, &t));
                if (t.agreeing(), t.serious()) != (rays.len(), 0) {
                    failures.push(format!(
                        "{label}: {} of {} agree, {} serious",
                        t.agreeing(),
                        rays.len(),
                        t.serious()
                    ));
                }
            }
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
    drop(owned);
    assert_validation_clean(&ctx);
}

#[test]
fn stress_rays_gpu_equals_cpu_twin() {
    let mut failures = Vec::new();
    let ctx = common::shared_context();
    let mut tracer = None;
    // Every category on the small scenes; on bunny's deep tree the categories that
    // move the ray to the box (far origins, flat axes, huge tmax, segments).
    let far = [
        Category::FarOrigin1e3,
        Category::FarOrigin,
        Category::FarOrigin1e7,
        Category::FarOrigin1e30,
        Category::FarAxisParallel,
        Category::HugeTmax,
        Category::FarGrazing,
        Category::BoundedSegment,
    ];
    let scenes: [(&str, f32, &[Category], usize); 7] = [
        // Generated (trigonometric_fans): rays 2^-50 beside an edge, exact edge signs.
        ("trigonometric fans", 1.0, &Category::ALL, 100),
        ("teapot.obj", 1.0, &Category::ALL, 300),
        ("teapot.obj", 1e5, &Category::ALL, 300),
        ("cornell_box.obj", 1.0, &Category::ALL, 300),
        // Extreme scales: exact tests of scaled inputs, far rays shifted at ×1e17.
        ("cornell_box.obj", 1e-20, &Category::ALL, 100),
        ("cornell_box.obj", 1e17, &Category::ALL, 100),
        ("bunny.obj", 1.0, &far, 100),
    ];
    for (name, scale, categories, per_category) in scenes {
        let (triangles, tree, links) = if name == "trigonometric fans" {
            let triangles = trigonometric_fans(5, 64, 50, 5);
            let tree = KdTree::build(&triangles, &BuildConfig::default());
            let links = TreeLinks::new(&tree.nodes, tree.bounds);
            (triangles, tree, links)
        } else {
            if common::fetched_scene(name).is_none() {
                continue;
            }
            let (scene, tree, links) = scaled_scene(name, scale);
            (scene.triangles, tree, links)
        };
        let triangles = &triangles;
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, triangles);
        let rays: Vec<Ray> =
            categories.iter().flat_map(|&c| stress_rays(c, triangles, &tree, per_category, 3)).collect();
        for variant in Variant::ALL {
            for any_hit in [false, true] {
                let traversal = Traversal { any_hit, ..Traversal::closest(variant) };
                let gpu = common::trace(tracer, &rays, &TraceOptions::counted(traversal)).unwrap();
                let counters = gpu.counters.unwrap();
                let scene_ref = SceneRef::new(&tree, triangles).with_links(&links);
                let mut differ = 0;
                for (i, ray) in rays.iter().enumerate() {
                    let (hit, c) = trace_ray(&scene_ref, ray, traversal);
                    if !same_bits(&hit, &gpu.hits[i]) || c != counters[i] {
                        if differ < 3 {
                            failures.push(format!(
                                "{name} ×{scale} {} any-hit {any_hit}: {ray:?}: GPU {:?} {:?}, CPU {hit:?} {c:?}",
                                describe(&traversal),
                                gpu.hits[i],
                                counters[i]
                            ));
                        }
                        differ += 1;
                    }
                }
                if differ > 0 {
                    failures.push(format!(
                        "{name} ×{scale} {} any-hit {any_hit}: {differ} of {} rays differ",
                        describe(&traversal),
                        rays.len()
                    ));
                }
            }
        }
    }
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}

// ---- Watertightness --------------------------------------------------------

/// Rays from points inside the closed mesh: toward random directions, toward
/// vertices exactly, toward edge midpoints. Every one must hit.
fn inside_rays(tris: &[[Vec3; 3]], count: usize, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64(seed);
    (0..count)
        .map(|i| {
            let origin = rng.unit_vector() * (0.5 * rng.next_f32());
            let tri = tris[(rng.next_u64() % tris.len() as u64) as usize];
            let target = match i % 3 {
                0 => origin + rng.unit_vector(),
                1 => tri[(rng.next_u64() % 3) as usize],
                _ => {
                    let k = (rng.next_u64() % 3) as usize;
                    (tri[k] + tri[(k + 1) % 3]) * 0.5
                }
            };
            Ray::new(origin, target - origin, 0.0, f32::INFINITY)
        })
        .collect()
}

#[test]
fn closed_meshes_have_no_holes() {
    let ctx = common::shared_context();
    let meshes = [
        ("icosphere 3", common::sphere(3, 0.0, 1)),
        ("icosphere 5", common::sphere(5, 0.0, 1)),
        ("perturbed sphere 4", common::sphere(4, 0.1, 2)),
        ("perturbed sphere 6", common::sphere(6, 0.05, 3)),
    ];
    let rays_per_mesh = 1_000_000 / meshes.len() + 1;
    let mut tracer = None;
    let mut total = 0usize;
    let mut failures = Vec::new();
    for (name, tris) in &meshes {
        let tree = KdTree::build(tris, &BuildConfig::default());
        let links = TreeLinks::new(&tree.nodes, tree.bounds);
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, tris);
        let rays = inside_rays(tris, rays_per_mesh, name.len() as u64);
        for traversal in traversals() {
            let hits = match common::trace(tracer, &rays, &TraceOptions::new(traversal)) {
                Ok(result) => result.hits,
                Err(e) => {
                    println!("{name}, {}: {e}", describe(&traversal));
                    failures.push(format!("{name}, {}: {e}", describe(&traversal)));
                    continue;
                }
            };
            let escapes: Vec<usize> = (0..rays.len()).filter(|&i| !hits[i].is_hit()).collect();
            let label = describe(&traversal);
            println!("{name}, {label}: {} of {} rays escaped", escapes.len(), rays.len());
            // Every variant must be watertight: the stack and the variants that
            // follow it by construction, backtrack and ropes because they finish
            // with exact restarts wherever a t value could not order the cells.
            if !escapes.is_empty() {
                failures.push(format!(
                    "{name}, {label}: {} of {} rays escaped, e.g. {:?}",
                    escapes.len(),
                    rays.len(),
                    escapes
                        .iter()
                        .take(2)
                        .map(|&i| (rays[i], hits[i], kdtrace::exact::closest_exact(tris, &rays[i])))
                        .collect::<Vec<_>>()
                ));
            }
        }
        // The CPU twin of the stack, on a sample.
        let sample: Vec<Ray> = rays.iter().step_by(20).copied().collect();
        let cpu = cpu_hits(&tree, tris, &links, &sample, Traversal::closest(Variant::Stack));
        assert!(cpu.iter().all(Hit::is_hit), "{name}: the CPU twin lets a ray escape");
        println!("{name}: {} triangles, {} rays from inside", tris.len(), rays.len());
        total += rays.len();
    }
    assert!(total >= 1_000_000);
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

// ---- The plain kernels and every short-stack size ---------------------------

/// Floors of the plain kernels (`--plain`: the papers' arithmetic, no robustness
/// measures) per category, on cornell_box and teapot: the lowest agreement
/// measured (2026-12-02, 200 rays per category, every plain variant and packet
/// kernel, both scenes, two seeds) less 10 points, which two seeds showed these
/// small samples need; 99.5 % where every kernel agreed on every ray (random
/// rays, direction scales). Lowest measured: axis-parallel 98.5 %, split-plane
/// origin 96.5, vertex-coord origin 95.5, to vertex 85.0, to edge 89.5, along
/// edge 90.0, in triangle plane 98.0, on surface 83.0, far 1e3 99.0, far 1e5
/// 63.5, far 1e7 11.5, huge tmax 87.5, far nearly axis-parallel 70.5, bounded
/// segment 90.5; and (2026-12-04, seed 13 only) far 1e10–1e30 3.5 (`restart`
/// packets of 4 on the teapot; single-ray `stack` 62 on the Cornell box), far
/// axis-parallel 1e3–1e30 13.0. Huge tmax since 2026-12-06 (its rays also aim at
/// vertices and edges, direction lengths 2^-20 … 2^40): `kdtrace verify --plain`,
/// 2,000 rays, two seeds, lowest 79.95 % (teapot; Cornell box 85.75 %), floor 65.
fn plain_floor(category: Category) -> f64 {
    match category {
        Category::Random | Category::DirectionScale => 0.995,
        Category::AxisParallel | Category::AxisPlane => 0.885,
        Category::SplitPlaneOrigin => 0.865,
        Category::FarOrigin1e3 => 0.89,
        Category::VertexCoordOrigin => 0.855,
        Category::InTrianglePlane => 0.88,
        Category::ToVertex => 0.75,
        Category::ToEdge => 0.795,
        Category::AlongEdge => 0.8,
        Category::BoundedSegment => 0.805,
        Category::HugeTmax => 0.65,
        Category::OnSurface => 0.73,
        Category::FarOrigin => 0.535,
        Category::FarGrazing => 0.605,
        Category::FarOrigin1e7 => 0.015,
        Category::FarOrigin1e30 => 0.0,
        Category::FarAxisParallel => 0.03,
    }
}

/// Every plain kernel (each variant, packets of 4 and 8, short-stack sizes 1–8)
/// against the exact reference with `plain_floor`: no incomplete ray, serious
/// errors only for rays inside a triangle's plane (at most 2 %). And every
/// robust short-stack size 1–8 (`short-stack`, `push-down-short-stack`) returns
/// the stack's hits bit for bit.
#[test]
fn plain_kernels_and_every_short_stack_size() {
    let ctx = common::shared_context();
    let mut tracer = None;
    let mut failures = Vec::new();
    for name in ["cornell_box.obj", "teapot.obj"] {
        let (scene, tree, _) = scaled_scene(name, 1.0);
        let triangles = &scene.triangles;
        let tracer = common::load_scene(&mut tracer, &ctx, &tree, triangles);
        let batches = batches(tracer, triangles, &tree, 200, 13);
        let mut plain: Vec<Traversal> = traversals();
        for size in 1..=8 {
            for variant in [Variant::ShortStack, Variant::PushDownShortStack] {
                plain.push(Traversal { stack_size: size, ..Traversal::closest(variant) });
            }
        }
        for traversal in plain {
            // Robust short stacks of every size: the stack's hits, bit for bit.
            if traversal.variant.uses_short_stack() && traversal.packet_width == 1 {
                for (category, rays, _, stack) in &batches {
                    let hits = common::trace(tracer, rays, &TraceOptions::new(traversal)).unwrap().hits;
                    assert_eq!(hits.len(), stack.len());
                    let differ = hits.iter().zip(stack).filter(|(a, b)| !same_bits(a, b)).count();
                    if differ > 0 {
                        failures.push(format!(
                            "{name} {} / {}: {differ} differ",
                            describe(&traversal),
                            category.name()
                        ));
                    }
                }
            }
            let traversal = Traversal { robust: false, ..traversal };
            let label = format!("{name} {} plain", describe(&traversal));
            for (category, rays, exacts, _) in &batches {
                let hits = common::trace(tracer, rays, &TraceOptions::new(traversal)).unwrap().hits;
                let t = judge_with(triangles, rays, &hits, exacts, false);
                let serious_allowed = if *category == Category::InTrianglePlane { t.rays / 50 } else { 0 };
                if t.incomplete > 0 || t.serious() > serious_allowed || t.agreement() < plain_floor(*category) {
                    failures.push(format!(
                        "{label} / {}: agreement {:.4} (floor {}), {} serious, {} incomplete: {:?}",
                        category.name(),
                        t.agreement(),
                        plain_floor(*category),
                        t.serious(),
                        t.incomplete,
                        t.serious_examples
                    ));
                }
            }
        }
    }
    drop(tracer);
    assert_validation_clean(&ctx);
    assert!(failures.is_empty(), "{} failures:\n{}", failures.len(), failures.join("\n"));
}
