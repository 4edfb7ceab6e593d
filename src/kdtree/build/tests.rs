//! Tests of the kd-tree builder (src/kdtree/build.rs).

use super::*;
use crate::consts::{MAX_TREE_DEPTH, PRIM_MISS};
use crate::exact::tolerant::{agrees, Agreement};
use crate::geom::{Hit, Ray, WatertightRay};
use crate::kdtree::node::{mark_empty_children, KdNode, MAX_CHILD_INDEX, MAX_NODE_FIELD};
use crate::kdtree::traverse::{trace_ray, SceneRef, Variant};
use crate::raygen::SplitMix64;
use glam::DVec3;

/// The binned builder on every node of at least 16 triangles, with few
/// bins: its paths (binning, exact classification, hand-over to the
/// sweep) on the small inputs of these tests.
const BINNED_SMALL: BuildConfig =
    BuildConfig { builder: Builder::Binned { bins: 8, min_prims: 16 }, ..BuildConfig::TUNED };

/// A point of the box `[lo, hi)³`.
fn vec3(rng: &mut SplitMix64, lo: f32, hi: f32) -> Vec3 {
    Vec3::new(rng.range(lo, hi), rng.range(lo, hi), rng.range(lo, hi))
}

/// `n` triangles in the unit cube, of sizes from tiny up to `size`.
fn soup(seed: u64, n: usize, size: f32) -> Vec<[Vec3; 3]> {
    let mut rng = SplitMix64(seed);
    (0..n)
        .map(|_| {
            let c = vec3(&mut rng, 0.0, 1.0);
            let s = size * rng.next_f32() * rng.next_f32() + 1e-4;
            [c + vec3(&mut rng, -s, s), c + vec3(&mut rng, -s, s), c + vec3(&mut rng, -s, s)]
        })
        .collect()
}

/// The triangles of an OBJ file, through the scene loader.
fn read_obj(path: &str) -> Vec<[Vec3; 3]> {
    crate::scene::Scene::load(std::path::Path::new(path)).unwrap_or_else(|e| panic!("{path}: {e}")).triangles
}

fn teapot() -> Vec<[Vec3; 3]> {
    read_obj(concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/teapot.obj"))
}

/// Tolerance for geometric checks: a few f32 ulps of the scene's scale.
fn tolerance(tree: &KdTree) -> f64 {
    let b = tree.bounds;
    if b.is_empty() {
        return 0.0;
    }
    4e-7 * (b.min.abs().max(b.max.abs()).max_element() as f64).max(1e-30)
}

/// Exact (f64) separating-axis test of a triangle against a box grown by
/// `tol` (Akenine-Möller 2001): the 3 box axes, the normal, 9 edge crosses.
fn triangle_overlaps_box(tri: &[Vec3; 3], b: &Aabb, tol: f64) -> bool {
    let (lo, hi) = (b.min.as_dvec3() - tol, b.max.as_dvec3() + tol);
    let (center, half) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
    let v = tri.map(|p| p.as_dvec3() - center);
    let edges = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    let mut axes = vec![DVec3::X, DVec3::Y, DVec3::Z, edges[0].cross(edges[1])];
    for e in edges {
        for a in [DVec3::X, DVec3::Y, DVec3::Z] {
            axes.push(a.cross(e));
        }
    }
    axes.iter().all(|a| {
        let p = v.map(|x| x.dot(*a));
        let r = half.dot(a.abs());
        let (min, max) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        // Scale-aware slack for the f64 products themselves.
        let slack = 1e-12 * (r + max.abs().max(min.abs()));
        !(min > r + slack || max < -r - slack)
    })
}

/// The leaves whose boxes, grown by `tol`, contain `p`.
fn leaves_at(tree: &KdTree, p: DVec3, tol: f64) -> Vec<u32> {
    let mut found = Vec::new();
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        let node = tree.nodes[i as usize];
        if node.is_leaf() {
            found.push(i);
            continue;
        }
        let (axis, split) = (node.axis(), node.split() as f64);
        if p[axis] <= split + tol {
            stack.push(i + 1);
        }
        if p[axis] >= split - tol {
            stack.push(node.above_child());
        }
    }
    found
}

/// Every invariant the traversals and the GPU rely on, and (with perfect
/// splits) that the leaves referencing a triangle are exactly the ones it
/// touches: each one overlaps it, and points sampled on it lie in a leaf
/// that references it.
fn check_tree(tris: &[[Vec3; 3]], tree: &KdTree, config: &BuildConfig) {
    tree.check(tris.len()).unwrap();
    let included: Vec<usize> = (0..tris.len()).filter(|&i| !is_skipped(&tris[i])).collect();
    let limit = config.depth_limit(included.len());
    assert!(limit <= MAX_TREE_DEPTH);
    let bounds = included.iter().fold(Aabb::EMPTY, |b, &i| b.union(triangle_box(&tris[i])));
    assert_eq!(tree.bounds, bounds);
    if included.is_empty() {
        assert_eq!(tree.nodes, vec![KdNode::leaf(0, 0)]);
        assert!(tree.prim_indices.is_empty() && tree.bounds.is_empty());
    }
    let tol = tolerance(tree);
    // Depth-first order: a preorder walk meets the nodes in index order, and
    // below = index + 1 < above. Every split lies strictly inside its node.
    let mut order = Vec::new();
    tree.for_each_node(|i, node, b, _| {
        order.push(i);
        if !node.is_leaf() {
            assert!(node.above_child() > i + 1 && (node.above_child() as usize) < tree.nodes.len());
            let (axis, split) = (node.axis(), node.split());
            assert!(b.min[axis] < split && split < b.max[axis], "node {i}: split {split} on {axis} in {b:?}");
        }
    });
    assert_eq!(order, (0..tree.nodes.len() as u32).collect::<Vec<_>>());
    let mut referenced = vec![false; tris.len()];
    let mut refs = 0;
    let mut volume = 0.0f64;
    tree.for_each_leaf(|i, node, b, depth| {
        assert!(depth <= limit, "leaf {i} at depth {depth} > {limit}");
        if !included.is_empty() {
            assert!(!b.is_empty() && tree.bounds.contains_box(&b), "leaf {i}: {b:?} outside {:?}", tree.bounds);
        }
        volume += (b.max.as_dvec3() - b.min.as_dvec3()).max(DVec3::ZERO).element_product();
        let prims = tree.leaf_prims(node);
        assert!(prims.windows(2).all(|w| w[0] < w[1]), "leaf {i}: indices not ascending");
        for &p in prims {
            let tri = &tris[p as usize];
            assert!(!is_skipped(tri), "skipped triangle {p} in leaf {i}");
            assert!(triangle_box(tri).overlaps(&b), "triangle {p} does not touch leaf {i}");
            if config.perfect_splits {
                assert!(triangle_overlaps_box(tri, &b, tol), "triangle {p} {tri:?} misses leaf {i} {b:?}");
            }
            referenced[p as usize] = true;
        }
        refs += node.prim_count() as usize;
    });
    // The leaves tile the root box.
    let root_volume = (bounds.max.as_dvec3() - bounds.min.as_dvec3()).max(DVec3::ZERO).element_product();
    assert!((volume - root_volume).abs() <= 1e-9 * root_volume, "leaf volumes {volume} != {root_volume}");
    assert_eq!(refs, tree.prim_indices.len());
    for &i in &included {
        assert!(referenced[i], "triangle {i} in no leaf");
    }
    // Coverage: points on each triangle lie in a leaf that references it.
    let leaf_refs = |leaf: u32, p: u32| tree.leaf_prims(&tree.nodes[leaf as usize]).contains(&p);
    let step = (included.len() / 2000).max(1);
    for &i in included.iter().step_by(step) {
        let [a, b, c] = tris[i].map(|v| v.as_dvec3());
        for (u, v) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5), (0.3, 0.3), (0.1, 0.7)] {
            let p = a + (b - a) * u + (c - a) * v;
            let leaves = leaves_at(tree, p, tol);
            assert!(
                leaves.iter().any(|&l| leaf_refs(l, i as u32)),
                "triangle {i} {:?}: point {p} lies in leaves {leaves:?}, none references it",
                tris[i]
            );
        }
    }
    let s = &tree.stats;
    assert_eq!(
        (s.nodes, s.triangles, s.skipped_triangles),
        (tree.nodes.len(), included.len(), tris.len() - included.len())
    );
    assert_eq!(s.leaves, tree.nodes.iter().filter(|n| n.is_leaf()).count());
    assert_eq!((s.node_bytes, s.index_bytes), (tree.nodes.len() * 8, tree.prim_indices.len() * 4));
    assert!(s.max_depth <= limit && s.depth_limit == limit);
    assert!(s.sah_cost.is_finite() && s.sah_cost >= 0.0);
    assert!(s.threads >= 1);
    if !included.is_empty() {
        assert!(s.refs_per_triangle >= 1.0 && s.peak_scratch_bytes > 0);
    }
}

/// A small pbrt-style front-to-back stack traversal, written independently of
/// `kdtree::traverse`, using the watertight test. Returns the closest hit.
fn trace(tree: &KdTree, tris: &[[Vec3; 3]], ray: &Ray) -> Hit {
    let (o, d) = (Vec3::from(ray.origin), Vec3::from(ray.dir));
    let b = tree.bounds;
    let (mut t0, mut t1) = (ray.tmin, ray.tmax);
    for a in 0..3 {
        if d[a] == 0.0 {
            if o[a] < b.min[a] || o[a] > b.max[a] {
                return Hit::MISS;
            }
            continue;
        }
        let (mut near, mut far) = ((b.min[a] - o[a]) / d[a], (b.max[a] - o[a]) / d[a]);
        if near > far {
            std::mem::swap(&mut near, &mut far);
        }
        // pbrt's 1 + 2·gamma(3): rounding never clips a hit on the box away.
        far *= 1.0 + 6.0 * f32::EPSILON;
        t0 = t0.max(near);
        t1 = t1.min(far);
    }
    if t0 > t1 {
        return Hit::MISS;
    }
    let wr = WatertightRay::new(o, d);
    let mut best = Hit::MISS;
    let mut best_t = ray.tmax;
    let mut stack: Vec<(u32, f32, f32)> = Vec::new();
    let mut index = 0u32;
    loop {
        let node = tree.nodes[index as usize];
        if !node.is_leaf() {
            let (a, split) = (node.axis(), node.split());
            let (below, above) = (index + 1, node.above_child());
            if d[a] == 0.0 {
                index = if o[a] < split {
                    below
                } else if o[a] > split {
                    above
                } else {
                    stack.push((above, t0, t1));
                    below
                };
            } else {
                let ts = (split - o[a]) / d[a];
                let (near, far) = if d[a] > 0.0 { (below, above) } else { (above, below) };
                if ts > t1 {
                    index = near;
                } else if ts < t0 {
                    index = far;
                } else {
                    stack.push((far, ts, t1));
                    index = near;
                    t1 = ts;
                }
            }
            assert!(stack.len() <= MAX_TREE_DEPTH as usize);
            continue;
        }
        for &p in tree.leaf_prims(&node) {
            let [v0, v1, v2] = tris[p as usize];
            if let Some((t, u, v)) = wr.intersect(v0, v1, v2, ray.tmin, best_t) {
                best = Hit { t, prim_id: p, u, v };
                best_t = t;
            }
        }
        if best_t <= t1 {
            break;
        }
        match stack.pop() {
            Some((i, a, b)) => (index, t0, t1) = (i, a, b),
            None => break,
        }
    }
    best
}

/// Random rays at a scene: aimed at points on triangles, at random points of
/// the box, axis-parallel ones, origins on split planes, bounded segments.
fn random_rays(seed: u64, tris: &[[Vec3; 3]], tree: &KdTree, count: usize) -> Vec<Ray> {
    let mut rng = SplitMix64(seed);
    let b = tree.bounds;
    let (center, size) = (b.center(), b.extent().max_element().max(1e-3));
    let splits: Vec<(usize, f32)> = tree.nodes.iter().filter(|n| !n.is_leaf()).map(|n| (n.axis(), n.split())).collect();
    (0..count)
        .map(|k| {
            let mut origin = center + vec3(&mut rng, -1.0, 1.0) * size;
            let target = if k % 2 == 0 {
                let [v0, v1, v2] = tris[rng.below(tris.len())];
                let (mut u, mut v) = (rng.next_f32(), rng.next_f32());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                v0 + u * (v1 - v0) + v * (v2 - v0)
            } else {
                b.min + vec3(&mut rng, 0.0, 1.0) * b.extent()
            };
            let mut dir = target - origin;
            let (mut tmin, mut tmax) = (0.0, f32::INFINITY);
            match k % 10 {
                1 if !splits.is_empty() => {
                    let (axis, split) = splits[rng.below(splits.len())];
                    origin[axis] = split;
                    dir = target - origin;
                }
                3 => dir[rng.below(3)] = 0.0,
                5 => {
                    let keep = rng.below(3);
                    dir = Vec3::select(glam::BVec3::new(keep == 0, keep == 1, keep == 2), dir, Vec3::ZERO);
                    dir[keep] = if dir[keep] == 0.0 { 1.0 } else { dir[keep] };
                }
                7 => {
                    tmin = rng.range(0.0, 0.9);
                    tmax = rng.range(tmin, 1.5);
                }
                9 => dir = -dir,
                _ => {}
            }
            if dir == Vec3::ZERO {
                dir = Vec3::X;
            }
            if k % 4 == 0 && tmax == f32::INFINITY {
                dir = dir.normalize();
            }
            Ray::new(origin, dir, tmin, tmax)
        })
        .collect()
}

/// Traces `count` random rays with the test traversal and with the CPU twins
/// of the stack and restart traversals, and compares each with the f64 brute
/// force. Returns (hits, grazing).
fn compare_with_reference(name: &str, tris: &[[Vec3; 3]], config: &BuildConfig, count: usize) -> (usize, usize) {
    let tree = KdTree::build(tris, config);
    check_tree(tris, &tree, config);
    let rays = random_rays(0xC0FFEE ^ tris.len() as u64, tris, &tree, count);
    let scene = SceneRef::new(&tree, tris);
    let (mut hits, mut grazing, mut ties) = (0, 0, 0);
    for (i, ray) in rays.iter().enumerate() {
        let hit = trace(&tree, tris, ray);
        let stack = trace_ray(&scene, ray, Variant::Stack).0;
        let restart = trace_ray(&scene, ray, Variant::Restart).0;
        for (traversal, hit) in [("test", hit), ("stack", stack), ("restart", restart)] {
            match agrees(tris, ray, &hit) {
                Agreement::Disagree(why) => panic!("{name} ({traversal}): ray {i}: {why}"),
                Agreement::Grazing => {
                    grazing += 1;
                    if std::env::var_os("KDTRACE_TEST_VERBOSE").is_some() {
                        let reference = crate::exact::tolerant::closest_hit_f64(tris, ray);
                        eprintln!("{name}: ray {i} grazing: {ray:?} tracer {hit:?} reference {reference:?}");
                    }
                }
                Agreement::Tie => ties += 1,
                _ => {}
            }
        }
        hits += (hit.prim_id != PRIM_MISS) as usize;
    }
    eprintln!("{name}: {count} rays, {hits} hits, {ties} ties, {grazing} grazing (3 traversals); {}", tree.stats);
    // Far from the origin, f32 snaps many aimed rays exactly onto vertices.
    let allowed_percent = if name.contains("far") { 5 } else { 1 };
    assert!(grazing * 100 <= 3 * count * allowed_percent, "{name}: {grazing} grazing rays");
    (hits, grazing)
}

#[test]
fn node_encoding_round_trip() {
    for (axis, split, above) in
        [(0, 0.0, 2), (1, -0.0, 7), (2, -1.5e-30, MAX_CHILD_INDEX), (0, 3.4e38, 123_456), (1, f32::MIN_POSITIVE, 5)]
    {
        let n = KdNode::interior(axis, split, above);
        assert!(!n.is_leaf());
        assert!(!n.below_empty() && !n.above_empty());
        assert_eq!((n.axis(), n.split().to_bits(), n.above_child()), (axis, split.to_bits(), above));
        // The empty-child flags sit between the axis and the child index.
        for flags in [crate::consts::NODE_BELOW_EMPTY, crate::consts::NODE_ABOVE_EMPTY] {
            let f = KdNode { word1: n.word1 | flags, ..n };
            assert_eq!((f.axis(), f.above_child(), f.is_leaf()), (axis, above, false));
            assert_eq!(
                (f.below_empty(), f.above_empty()),
                (flags == crate::consts::NODE_BELOW_EMPTY, flags == crate::consts::NODE_ABOVE_EMPTY)
            );
        }
    }
    for (offset, count) in [(0, 0), (5, 1), (u32::MAX, MAX_NODE_FIELD), (17, 1000)] {
        let n = KdNode::leaf(offset, count);
        assert!(n.is_leaf());
        assert_eq!((n.prim_offset(), n.prim_count()), (offset, count));
    }
    assert_eq!(std::mem::size_of::<KdNode>(), 8);
}

/// Every interior node of a built tree flags exactly its children that are
/// empty leaves, and marking again changes nothing.
#[test]
fn empty_children_are_flagged() {
    let tris = soup(7, 2000, 0.05);
    let tree = KdTree::build(&tris, &BuildConfig::default());
    let mut flagged = 0;
    for (i, n) in tree.nodes.iter().enumerate() {
        if n.is_leaf() {
            continue;
        }
        let below = tree.nodes[i + 1];
        let above = tree.nodes[n.above_child() as usize];
        assert_eq!(n.below_empty(), below.is_leaf() && below.prim_count() == 0, "node {i}");
        assert_eq!(n.above_empty(), above.is_leaf() && above.prim_count() == 0, "node {i}");
        flagged += n.below_empty() as usize + n.above_empty() as usize;
    }
    assert!(flagged > 0, "the test tree has no empty leaf");
    let mut again = tree.nodes.clone();
    mark_empty_children(&mut again);
    assert_eq!(again, tree.nodes);
    // A flag on a child with triangles would skip them: `check` refuses it.
    let mut bad = tree.clone();
    let i = bad.nodes.iter().position(|n| !n.is_leaf() && !n.below_empty()).unwrap();
    bad.nodes[i].word1 |= crate::consts::NODE_BELOW_EMPTY;
    assert!(tree.check(tris.len()).is_ok());
    assert!(bad.check(tris.len()).unwrap_err().contains("empty leaf"));
}

#[test]
fn depth_limit() {
    let c = BuildConfig::default();
    assert_eq!(c.depth_limit(0), 8);
    assert_eq!(c.depth_limit(1), 8);
    assert_eq!(c.depth_limit(1024), 21);
    assert_eq!(c.depth_limit(1 << 20), 34);
    assert_eq!(c.depth_limit(usize::MAX), MAX_TREE_DEPTH);
    assert_eq!(BuildConfig { max_depth: Some(100), ..c }.depth_limit(5), MAX_TREE_DEPTH);
    assert_eq!(BuildConfig { max_depth: Some(3), ..c }.depth_limit(1 << 20), 3);
}

#[test]
fn random_soups_build_valid_trees() {
    let configs = [
        BuildConfig::PBRT_V3,
        BuildConfig::WALD_HAVRAN,
        BuildConfig::default(),
        BuildConfig { max_depth: Some(3), ..BuildConfig::PBRT_V3 },
        BuildConfig { max_leaf_prims: 8, ..BuildConfig::PBRT_V3 },
        BuildConfig { max_leaf_prims: 0, ..BuildConfig::WALD_HAVRAN },
        BuildConfig { perfect_splits: false, ..BuildConfig::WALD_HAVRAN },
        BuildConfig { empty_bonus: 0.0, traversal_cost: 0.0, ..BuildConfig::PBRT_V3 },
        BINNED_SMALL,
        BuildConfig { builder: Builder::Binned { bins: 2, min_prims: 1 }, ..BuildConfig::PBRT_V3 },
        BuildConfig { perfect_splits: false, ..BINNED_SMALL },
    ];
    for seed in 0..6 {
        let tris =
            soup(seed, [1, 2, 10, 100, 1000, 3000][seed as usize], [0.5, 0.3, 0.2, 0.2, 0.05, 0.02][seed as usize]);
        for config in &configs {
            let tree = KdTree::build(&tris, config);
            check_tree(&tris, &tree, config);
        }
    }
}

#[test]
fn perfect_splits_reference_fewer_cells() {
    let tris = soup(8, 3000, 0.1);
    let perfect = KdTree::build(&tris, &BuildConfig::WALD_HAVRAN);
    let boxed = KdTree::build(&tris, &BuildConfig { perfect_splits: false, ..BuildConfig::WALD_HAVRAN });
    eprintln!("perfect: {}\nbox-only: {}", perfect.stats, boxed.stats);
    assert!(perfect.stats.sah_cost < boxed.stats.sah_cost);
}

/// The same tree whatever the number of threads (and sizes that take the
/// parallel paths: subtree tasks, per-axis tasks, parallel clipping).
#[test]
fn deterministic_across_thread_counts() {
    let mut tris = soup(7, 40_000, 0.02);
    tris.extend(soup(9, 2_000, 0.6));
    // The binned builder with its parallel binning and clipping on the top nodes.
    let binned = BuildConfig { builder: Builder::Binned { bins: 32, min_prims: 1024 }, ..BuildConfig::default() };
    for config in [BuildConfig { builder: Builder::Sweep, ..BuildConfig::default() }, binned] {
        let build = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
            pool.install(|| KdTree::build(&tris, &config))
        };
        let one = build(1);
        assert_eq!(one.stats.threads, 1);
        for threads in [2, 3] {
            let many = build(threads);
            assert_eq!(many.stats.threads, threads);
            assert!(one.nodes == many.nodes && one.prim_indices == many.prim_indices && one.bounds == many.bounds);
            let same_run = |s: &BuildStats| BuildStats { build_seconds: 0.0, peak_scratch_bytes: 0, threads: 0, ..*s };
            assert_eq!(same_run(&one.stats), same_run(&many.stats));
        }
        let again = build(2);
        assert!(one.nodes == again.nodes && one.prim_indices == again.prim_indices);
        eprintln!("{:?}: {}", config.builder, one.stats);
    }
}

/// Progress ends at exactly the whole, with the same tree as without it.
#[test]
fn progress_reaches_the_whole() {
    let tris = soup(11, 20_000, 0.05);
    let binned = BuildConfig { builder: Builder::Binned { bins: 16, min_prims: 2048 }, ..BuildConfig::default() };
    for config in [BuildConfig::default(), binned, BuildConfig::PBRT_V3] {
        let progress = BuildProgress::default();
        assert_eq!((progress.stage(), progress.fraction()), (BuildStage::Waiting, 0.0));
        let tree = KdTree::build_with_progress(&tris, &config, Some(&progress));
        assert_eq!(progress.stage(), BuildStage::Finished);
        assert_eq!(progress.done.load(Ordering::Relaxed), BuildProgress::TOTAL, "{config:?}");
        assert!(tree.nodes == KdTree::build(&tris, &config).nodes);
    }
}

/// The structured inputs of the field's pitfalls.
fn structured() -> Vec<(&'static str, Vec<[Vec3; 3]>)> {
    let mut rng = SplitMix64(99);
    let mut cases = Vec::new();
    cases.push(("empty", Vec::new()));
    cases.push(("one triangle", vec![[Vec3::ZERO, Vec3::X, Vec3::Y]]));
    let axis_plane = (0..500)
        .map(|_| {
            let c = vec3(&mut rng, 0.0, 1.0);
            let p = |rng: &mut SplitMix64| Vec3::new(c.x + rng.range(-0.1, 0.1), 0.25, c.z + rng.range(-0.1, 0.1));
            [p(&mut rng), p(&mut rng), p(&mut rng)]
        })
        .collect();
    cases.push(("coplanar in y = 0.25", axis_plane));
    let (n, d) = (Vec3::new(1.0, 2.0, 3.0).normalize(), 0.3);
    let tilted = (0..500)
        .map(|_| {
            let c = vec3(&mut rng, 0.0, 1.0);
            let c = c - (c.dot(n) - d) * n;
            let e1 = n.any_orthonormal_vector();
            let e2 = n.cross(e1);
            let mut p = || c + rng.range(-0.1, 0.1) * e1 + rng.range(-0.1, 0.1) * e2;
            [p(), p(), p()]
        })
        .collect();
    cases.push(("coplanar tilted", tilted));
    let t = [Vec3::new(0.1, 0.2, 0.3), Vec3::new(0.9, 0.1, 0.5), Vec3::new(0.4, 0.8, 0.2)];
    cases.push(("1000 identical", vec![t; 1000]));
    let needles = (0..1000)
        .map(|_| {
            let a = vec3(&mut rng, 0.0, 1.0);
            let b = vec3(&mut rng, 0.0, 1.0);
            [a, b, b + vec3(&mut rng, -1e-4, 1e-4)]
        })
        .collect();
    cases.push(("needles", needles));
    let mut mixed = soup(5, 300, 0.2);
    for i in 0..300 {
        let v = vec3(&mut rng, 0.0, 1.0);
        mixed.insert(i * 2, if i % 2 == 0 { [v, v, v] } else { [v, v + Vec3::X, v + 2.0 * Vec3::X] });
    }
    mixed.push([Vec3::new(f32::NAN, 0.0, 0.0), Vec3::X, Vec3::Y]);
    mixed.push([Vec3::new(f32::INFINITY, 0.0, 0.0), Vec3::X, Vec3::Y]);
    cases.push(("zero-area and non-finite mixed in", mixed));
    let v = Vec3::new(0.3, -0.0, 0.7);
    cases.push(("100k at one point", vec![[v, v, v]; 100_000]));
    // Every triangle shares the point v: no plane separates them well.
    let tiny = (0..2_000).map(|_| [v, v + vec3(&mut rng, -1e-6, 1e-6), v + vec3(&mut rng, -1e-6, 1e-6)]).collect();
    cases.push(("2k tiny at one point", tiny));
    let mut grid = Vec::new();
    for i in 0..20 {
        for j in 0..20 {
            let (x, y) = (i as f32 * 0.05, j as f32 * 0.05);
            let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 0.0);
            grid.push([p(0.0, 0.0), p(0.05, 0.0), p(0.05, 0.05)]);
            grid.push([p(0.0, 0.0), p(0.05, 0.05), p(0.0, 0.05)]);
        }
    }
    cases.push(("grid in z = 0", grid));
    let mut cubes = Vec::new();
    for i in 0..6 {
        for j in 0..6 {
            for k in 0..6 {
                let o = Vec3::new(i as f32, j as f32, k as f32) * 0.2;
                for axis in 0..3 {
                    let (u, v) = (Vec3::AXES[(axis + 1) % 3] * 0.1, Vec3::AXES[(axis + 2) % 3] * 0.1);
                    cubes.push([o, o + u, o + u + v]);
                    cubes.push([o, o + u + v, o + v]);
                }
            }
        }
    }
    cases.push(("3D grid of axis-aligned quads", cubes));
    let far: Vec<[Vec3; 3]> = soup(11, 500, 0.1).iter().map(|t| t.map(|v| v * 10.0 + Vec3::splat(1e5))).collect();
    cases.push(("far from the origin", far));
    cases
}

#[test]
fn structured_inputs_build_valid_trees() {
    for (name, tris) in structured() {
        for config in [
            BuildConfig::PBRT_V3,
            BuildConfig::WALD_HAVRAN,
            BuildConfig::default(),
            BuildConfig { max_depth: Some(4), ..BuildConfig::PBRT_V3 },
            BINNED_SMALL,
        ] {
            let tree = KdTree::build(&tris, &config);
            check_tree(&tris, &tree, &config);
            eprintln!("{name}: {}", tree.stats);
        }
    }
}

#[test]
fn coplanar_triangles_are_not_duplicated() {
    let cases = structured();
    for (name, limit) in [("coplanar in y = 0.25", 50.0), ("grid in z = 0", 3.0)] {
        let tris = &cases.iter().find(|(n, _)| *n == name).unwrap().1;
        for config in [BuildConfig::PBRT_V3, BuildConfig::WALD_HAVRAN, BuildConfig::default()] {
            let perfect = KdTree::build(tris, &config);
            let boxed = KdTree::build(tris, &BuildConfig { perfect_splits: false, ..config });
            eprintln!("{name}: perfect {}\n  box-only {}", perfect.stats, boxed.stats);
            // Within a plane, triangle boxes overlap far more than the
            // triangles: clipping only the boxes duplicated references
            // wholesale (the first builder: 115 per triangle).
            assert!(perfect.stats.refs_per_triangle < limit, "{name}: {}", perfect.stats);
            assert!(perfect.stats.sah_cost <= boxed.stats.sah_cost * 1.01, "{name}");
        }
    }
}

#[test]
fn one_triangle() {
    let tris = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
    for config in
        [BuildConfig::PBRT_V3, BuildConfig::default(), BuildConfig { max_leaf_prims: 0, ..BuildConfig::default() }]
    {
        let tree = KdTree::build(&tris, &config);
        check_tree(&tris, &tree, &config);
        assert_eq!(tree.prim_indices.iter().filter(|&&p| p == 0).count() as f64, tree.stats.refs_per_triangle);
    }
    let tree = KdTree::build(&tris, &BuildConfig::default());
    assert_eq!(tree.nodes, vec![KdNode::leaf(0, 1)]);
}

#[test]
fn skipped_triangles() {
    let v = Vec3::new(0.3, 0.0, 0.7);
    let tree = KdTree::build(&[[v, v, v]; 100], &BuildConfig::default());
    assert_eq!(tree.nodes, vec![KdNode::leaf(0, 0)]);
    assert!(tree.bounds.is_empty() && tree.prim_indices.is_empty());
    assert_eq!((tree.stats.triangles, tree.stats.skipped_triangles, tree.stats.leaves), (0, 100, 1));
    assert!(is_zero_area(&[Vec3::ZERO, Vec3::ONE, Vec3::ONE * 3.0]));
    assert!(!is_zero_area(&[Vec3::ZERO, Vec3::ONE, Vec3::new(1.0, 1.0, 1.000001)]));
    assert!(is_non_finite(&[Vec3::ZERO, Vec3::ONE, Vec3::new(0.0, f32::NAN, 0.0)]));
}

#[test]
fn planar_triangles_at_a_split_go_to_one_side() {
    // Two long boxes of triangles either side of a wall (a square of two
    // triangles) in x = 2, some touching it: the SAH splits at the wall,
    // which must end up on one side only of every split in its plane.
    let squeeze = |v: Vec3, x0: f32| Vec3::new((x0 + v.x * 2.0).clamp(x0, x0 + 2.0), v.y, v.z);
    let mut tris = soup(3, 300, 0.05).iter().map(|t| t.map(|v| squeeze(v, 0.0))).collect::<Vec<_>>();
    tris.extend(soup(4, 300, 0.05).iter().map(|t| t.map(|v| squeeze(v, 2.0))));
    let wall = tris.len() as u32;
    let corner = |y: f32, z: f32| Vec3::new(2.0, y, z);
    tris.push([corner(0.0, 0.0), corner(1.0, 0.0), corner(1.0, 1.0)]);
    tris.push([corner(0.0, 0.0), corner(1.0, 1.0), corner(0.0, 1.0)]);
    for config in [BuildConfig::PBRT_V3, BuildConfig::WALD_HAVRAN, BuildConfig::default()] {
        let tree = KdTree::build(&tris, &config);
        check_tree(&tris, &tree, &config);
        // At every split in the wall's plane, each half went to one side only.
        fn references(tree: &KdTree, index: u32, prim: u32, splits_at_wall: &mut usize) -> bool {
            let node = tree.nodes[index as usize];
            if node.is_leaf() {
                return tree.leaf_prims(&node).contains(&prim);
            }
            let below = references(tree, index + 1, prim, splits_at_wall);
            let above = references(tree, node.above_child(), prim, splits_at_wall);
            if node.axis() == 0 && node.split() == 2.0 {
                assert!(!(below && above), "node {index}: triangle {prim} is on both sides of its plane");
                *splits_at_wall += usize::from(below || above);
            }
            below || above
        }
        for prim in [wall, wall + 1] {
            let mut splits_at_wall = 0;
            assert!(references(&tree, 0, prim, &mut splits_at_wall));
            assert!(splits_at_wall > 0, "{config:?}: no split in the wall's plane");
        }
        compare_with_reference("wall", &tris, &config, 300);
    }
}

#[test]
fn traversal_matches_reference_on_random_soups() {
    let mut hits = 0;
    for (seed, n, size) in [(1u64, 50, 0.5), (2, 400, 0.2), (3, 2000, 0.05)] {
        let tris = soup(seed, n, size);
        for config in [BuildConfig::PBRT_V3, BuildConfig::WALD_HAVRAN, BuildConfig::default(), BINNED_SMALL] {
            hits += compare_with_reference(&format!("soup {n}"), &tris, &config, 500).0;
        }
    }
    assert!(hits > 2000, "{hits} hits");
}

#[test]
fn traversal_matches_reference_on_structured_inputs() {
    for (name, tris) in structured() {
        if tris.iter().all(is_skipped) || tris.len() > 5000 {
            continue;
        }
        compare_with_reference(name, &tris, &BuildConfig::default(), 300);
        compare_with_reference(name, &tris, &BuildConfig::PBRT_V3, 100);
    }
}

#[test]
fn traversal_matches_reference_on_teapot() {
    let tris = teapot();
    assert_eq!(tris.len(), 992);
    let (hits, _) = compare_with_reference("teapot", &tris, &BuildConfig::default(), 2000);
    assert!(hits > 900, "{hits} hits");
    compare_with_reference("teapot (pbrt-v3)", &tris, &BuildConfig::PBRT_V3, 500);
    compare_with_reference("teapot (binned)", &tris, &BINNED_SMALL, 500);
}

/// Build times and statistics on the bundled scenes:
/// `cargo test --release --lib kdtree::build::tests::scene_stats -- --ignored --nocapture`.
#[test]
#[ignore]
fn scene_stats() {
    let root = env!("CARGO_MANIFEST_DIR");
    let shared = format!("{root}/../shared/scenes");
    for name in ["teapot.obj", "q3_20kdm2.obj", "bunny.obj", "dragon_200k.obj"] {
        let Some(path) = [format!("{root}/scenes/{name}"), format!("{shared}/{name}")]
            .into_iter()
            .find(|p| std::path::Path::new(p).exists())
        else {
            eprintln!("{name}: not found");
            continue;
        };
        let tris = read_obj(&path);
        for (label, config) in [("pbrt-v3", BuildConfig::PBRT_V3), ("Wald-Havran", BuildConfig::WALD_HAVRAN)] {
            let tree = KdTree::build(&tris, &config);
            eprintln!("{name} [{label}]: {}", tree.stats);
        }
    }
}

/// 100k tiny triangles sharing one point (every split duplicates most of
/// them), and 100k more of zero area there: a valid tree, in bounded time
/// and memory (about a minute in the test profile on 2 cores).
#[test]
fn hundred_thousand_triangles_at_one_point() {
    let mut rng = SplitMix64(5);
    let v = Vec3::new(0.3, -0.0, 0.7);
    let mut tris: Vec<[Vec3; 3]> =
        (0..100_000).map(|_| [v, v + vec3(&mut rng, -1e-6, 1e-6), v + vec3(&mut rng, -1e-6, 1e-6)]).collect();
    tris.extend(vec![[v, v, v]; 100_000]);
    // The default configuration here; `BuildConfig::PBRT_V3` takes as long again
    // (run it with `cargo test --release` when changing the builder).
    let config = BuildConfig::default();
    let tree = KdTree::build(&tris, &config);
    eprintln!("100k tiny + 100k zero-area at one point: {}", tree.stats);
    check_tree(&tris, &tree, &config);
}

/// A million triangles: no stack overflow, bounded depth (slow in debug builds).
#[test]
#[ignore]
fn million_triangles() {
    let tris = soup(42, 1_000_000, 0.01);
    let config = BuildConfig::default();
    let tree = KdTree::build(&tris, &config);
    eprintln!("1M soup: {}", tree.stats);
    check_tree(&tris, &tree, &config);
}
