//! The top level chosen by measurement (issue 29): the two-level scene's BVH
//! over the instances' world boxes (median split, as built; and an SAH BVH)
//! against a kd-tree over the same boxes (SAH with clipped box references,
//! traversed front to back with a mailbox per ray), on the CPU twin with the
//! same bottom levels and rays. Counted per ray: top-level nodes visited,
//! instances entered (object rays traced: each one a transform and a traversal
//! of the geometry's tree), and the nodes and triangle tests inside them.
//!
//! `cargo test --release --lib top_level_kd_against_bvh -- --ignored --nocapture`
//! prints the table of docs/EMBEDDING.md (bunny scenes are skipped when
//! scenes/bunny.obj has not been fetched).

use super::tests::{sphere, Rng};
use super::*;
use crate::kdtree::traverse::Variant;

/// A kd-tree node over instance boxes.
#[derive(Clone, Copy, Debug)]
enum KdTopNode {
    /// Children below and above `split` on `axis`.
    Inner { axis: usize, split: f32, below: u32, above: u32 },
    /// Instances `refs[first..first + count]`.
    Leaf { first: u32, count: u32 },
}

/// A kd-tree top level over a scene's placed instances.
struct KdTop {
    nodes: Vec<KdTopNode>,
    refs: Vec<u32>,
    bounds: Aabb,
    /// The largest condition number of any instance (the root's widening).
    condition: f32,
}

/// SAH costs of a top-level node step and of entering an instance.
const COST_NODE: f32 = 1.0;
const COST_INSTANCE: f32 = 20.0;

impl KdTop {
    fn build(scene: &TwoLevelScene) -> KdTop {
        let items: Vec<(u32, Aabb)> = scene
            .placed
            .iter()
            .enumerate()
            .filter(|(_, p)| !p.world_box.is_empty())
            .map(|(i, p)| (i as u32, p.world_box))
            .collect();
        let bounds = items.iter().fold(Aabb::EMPTY, |b, (_, x)| b.union(*x));
        let condition = scene.placed.iter().map(|p| p.condition).fold(0.0, f32::max);
        let mut top = KdTop { nodes: Vec::new(), refs: Vec::new(), bounds, condition };
        if !items.is_empty() {
            top.split(items, bounds, 0);
        }
        top
    }

    fn split(&mut self, items: Vec<(u32, Aabb)>, bounds: Aabb, depth: u32) -> u32 {
        let index = self.nodes.len() as u32;
        let n = items.len();
        let area = |b: &Aabb| {
            let e = b.extent();
            e.x * e.y + e.y * e.z + e.z * e.x
        };
        let leaf_cost = COST_INSTANCE * n as f32;
        let mut best: Option<(f32, usize, f32)> = None;
        if n > 1 && depth < 40 && area(&bounds) > 0.0 {
            for axis in 0..3 {
                let mut mins: Vec<f32> = items.iter().map(|(_, b)| b.min[axis]).collect();
                let mut maxs: Vec<f32> = items.iter().map(|(_, b)| b.max[axis]).collect();
                mins.sort_by(f32::total_cmp);
                maxs.sort_by(f32::total_cmp);
                for &p in mins.iter().chain(&maxs) {
                    if p <= bounds.min[axis] || p >= bounds.max[axis] {
                        continue;
                    }
                    let below = mins.partition_point(|&m| m < p);
                    let above = n - maxs.partition_point(|&m| m <= p);
                    let (mut lo, mut hi) = (bounds, bounds);
                    lo.max[axis] = p;
                    hi.min[axis] = p;
                    let bonus = if below == 0 || above == 0 { 0.8 } else { 1.0 };
                    let cost = COST_NODE
                        + bonus * COST_INSTANCE * (area(&lo) * below as f32 + area(&hi) * above as f32) / area(&bounds);
                    if best.is_none_or(|b| cost < b.0) {
                        best = Some((cost, axis, p));
                    }
                }
            }
        }
        match best {
            Some((cost, axis, split)) if cost < leaf_cost => {
                self.nodes.push(KdTopNode::Inner { axis, split, below: 0, above: 0 });
                let (mut lo, mut hi) = (bounds, bounds);
                lo.max[axis] = split;
                hi.min[axis] = split;
                let clip = |b: &Aabb, side: &Aabb| Aabb::new(b.min.max(side.min), b.max.min(side.max));
                let below: Vec<(u32, Aabb)> =
                    items.iter().filter(|(_, b)| b.min[axis] < split).map(|&(i, b)| (i, clip(&b, &lo))).collect();
                let above: Vec<(u32, Aabb)> =
                    items.iter().filter(|(_, b)| b.max[axis] > split).map(|&(i, b)| (i, clip(&b, &hi))).collect();
                drop(items);
                let b = self.split(below, lo, depth + 1);
                let a = self.split(above, hi, depth + 1);
                self.nodes[index as usize] = KdTopNode::Inner { axis, split, below: b, above: a };
            }
            _ => {
                self.nodes.push(KdTopNode::Leaf { first: self.refs.len() as u32, count: n as u32 });
                self.refs.extend(items.iter().map(|(i, _)| *i));
            }
        }
        index
    }

    /// The scene's answer through this top level (the same instance tests as
    /// `TwoLevelScene::trace_counted`), front to back: a closest hit ends the
    /// search once it lies within the leaf that found it.
    fn trace(
        &self,
        scene: &TwoLevelScene,
        ray: &Ray,
        mask: u8,
        traversal: Traversal,
        counts: &mut TopCounts,
    ) -> InstanceHit {
        let mut best = InstanceHit::MISS;
        if self.nodes.is_empty() || !ray.is_valid() || mask == 0 {
            return best;
        }
        let o = Vec3::from(ray.origin);
        let d = ray.traced_dir();
        let inv = (Vec3::ONE / d).clamp(Vec3::splat(-f32::MAX), Vec3::splat(f32::MAX));
        let far = o.abs().max_element() / 1_048_576.0;
        let Some((t0, t1)) = slab(&self.bounds, far * self.condition, o, d, inv, ray.tmin, ray.tmax) else {
            return best;
        };
        let mut tested: Vec<u32> = Vec::new();
        let mut incomplete = false;
        let mut stack = vec![(0u32, t0, t1)];
        while let Some((mut n, t0, mut t1)) = stack.pop() {
            if best.is_hit() && t0 > best.t {
                continue;
            }
            loop {
                counts.top_nodes += 1;
                match self.nodes[n as usize] {
                    KdTopNode::Inner { axis, split, below, above } => {
                        let t = (split - o[axis]) * inv[axis];
                        let below_first = o[axis] < split || (o[axis] == split && d[axis] <= 0.0);
                        let (near, far_child) = if below_first { (below, above) } else { (above, below) };
                        if t > t1 || t <= 0.0 || d[axis] == 0.0 {
                            n = near;
                        } else if t < t0 {
                            n = far_child;
                        } else {
                            stack.push((far_child, t, t1));
                            n = near;
                            t1 = t;
                        }
                    }
                    KdTopNode::Leaf { first, count } => {
                        // The leaf's untested instances whose own boxes the ray
                        // enters (as a BVH leaf's bounds are tested), nearest entry first.
                        let mut candidates: Vec<(f32, u32)> = Vec::new();
                        for &i in &self.refs[first as usize..(first + count) as usize] {
                            if tested.contains(&i) {
                                continue;
                            }
                            tested.push(i);
                            let placed = &scene.placed[i as usize];
                            if placed.instance.mask & mask == 0 {
                                continue;
                            }
                            let reach = best.t.min(ray.tmax);
                            if let Some((entry, _)) =
                                slab(&placed.world_box, far * placed.condition, o, d, inv, ray.tmin, reach)
                            {
                                candidates.push((entry, i));
                            }
                        }
                        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
                        for (entry, i) in candidates {
                            if best.is_hit() && entry > best.t {
                                break;
                            }
                            if scene.enter(i, ray, traversal, &mut best, &mut incomplete, counts) {
                                return best;
                            }
                        }
                        break;
                    }
                }
            }
            if best.is_hit() && best.t <= t1 {
                break;
            }
        }
        if incomplete {
            best = InstanceHit { t: f32::NAN, prim_index: crate::consts::PRIM_INCOMPLETE, ..InstanceHit::MISS };
        }
        best
    }
}

impl TwoLevelScene {
    /// Rebuilds the top-level BVH by the SAH (full sweep over the centroids'
    /// order on each axis) instead of the median split.
    fn rebuild_top_sah(&mut self) {
        let mut order: Vec<u32> =
            (0..self.placed.len() as u32).filter(|&i| !self.placed[i as usize].world_box.is_empty()).collect();
        let mut nodes = Vec::new();
        if !order.is_empty() {
            let n = order.len();
            sah_bvh(&self.placed, &mut order, 0, n, &mut nodes);
        }
        (self.nodes, self.order) = (nodes, order);
    }
}

fn sah_bvh(placed: &[Placed], order: &mut [u32], lo: usize, hi: usize, nodes: &mut Vec<BvhNode>) -> u32 {
    let bounds = order[lo..hi].iter().fold(Aabb::EMPTY, |b, &i| b.union(placed[i as usize].world_box));
    let index = nodes.len() as u32;
    let condition = order[lo..hi].iter().map(|&i| placed[i as usize].condition).fold(0.0, f32::max);
    let n = hi - lo;
    let area = |b: &Aabb| {
        let e = b.extent();
        e.x * e.y + e.y * e.z + e.z * e.x
    };
    let mut best: Option<(f32, usize, usize)> = None;
    if n > LEAF_INSTANCES {
        for axis in 0..3 {
            let slice = &mut order[lo..hi];
            slice.sort_by(|&a, &b| {
                placed[a as usize].world_box.center()[axis].total_cmp(&placed[b as usize].world_box.center()[axis])
            });
            let mut right = vec![0.0f32; n + 1];
            let mut acc = Aabb::EMPTY;
            for k in (0..n).rev() {
                acc = acc.union(placed[slice[k] as usize].world_box);
                right[k] = area(&acc);
            }
            let mut acc = Aabb::EMPTY;
            for k in 1..n {
                acc = acc.union(placed[slice[k - 1] as usize].world_box);
                let cost = area(&acc) * k as f32 + right[k] * (n - k) as f32;
                if best.is_none_or(|b| cost < b.0) {
                    best = Some((cost, axis, k));
                }
            }
        }
    }
    let Some((_, axis, k)) = best else {
        nodes.push(BvhNode { bounds, index: lo as u32, count: n as u32, condition });
        return index;
    };
    order[lo..hi].sort_by(|&a, &b| {
        placed[a as usize].world_box.center()[axis].total_cmp(&placed[b as usize].world_box.center()[axis])
    });
    nodes.push(BvhNode { bounds, index: 0, count: 0, condition });
    sah_bvh(placed, order, lo, lo + k, nodes);
    let second = sah_bvh(placed, order, lo + k, hi, nodes);
    nodes[index as usize].index = second;
    index
}

/// A random rotation (the tests' generator: the same placements as before it was shared).
fn rotation(rng: &mut Rng) -> glam::Quat {
    glam::Quat::from_axis_angle(rng.unit(), rng.next() * std::f32::consts::TAU)
}

/// Pinhole camera rays from `eye` toward `at`, `w`×`h`, field of view 50°.
fn camera(eye: Vec3, at: Vec3, w: usize, h: usize) -> Vec<Ray> {
    let forward = (at - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let s = (25f32).to_radians().tan();
    let mut rays = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let sx = (2.0 * (x as f32 + 0.5) / w as f32 - 1.0) * s * w as f32 / h as f32;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / h as f32) * s;
            rays.push(Ray::new(eye, forward + right * sx + up * sy, 0.0, f32::INFINITY));
        }
    }
    rays
}

/// Per-ray means of one top level over a ray set, and its CPU time.
fn measure(
    name: &str,
    rays: &[Ray],
    trace: impl Fn(&Ray, &mut TopCounts) -> InstanceHit,
) -> (Vec<InstanceHit>, String) {
    let mut counts = TopCounts::default();
    let start = std::time::Instant::now();
    let hits: Vec<InstanceHit> = rays.iter().map(|r| trace(r, &mut counts)).collect();
    let seconds = start.elapsed().as_secs_f64();
    let n = rays.len() as f64;
    let row = format!(
        "{name} | {:.2} | {:.3} | {:.1} | {:.1} | {:.2}",
        counts.top_nodes as f64 / n,
        counts.entries as f64 / n,
        counts.inner_nodes as f64 / n,
        counts.inner_triangles as f64 / n,
        seconds / n * 1e6
    );
    (hits, row)
}

/// A scene of the measurement: its name, geometries, instances and rays.
type Case = (String, Vec<BottomLevel>, Vec<Instance>, Vec<Ray>);

/// The measurement behind the choice of a BVH for the top level (not a test
/// of correctness beyond the answers' agreement; run by hand, see the module docs).
#[test]
#[ignore]
fn top_level_kd_against_bvh() {
    let config = BuildConfig::default();
    let bunny = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/bunny.obj");
    let bunny = bunny.exists().then(|| crate::scene::Scene::load(&bunny).unwrap().triangles);
    let mut rng = Rng(29);
    let mut cases: Vec<Case> = Vec::new();
    let place = |geometry: usize, transform: Affine3A, i: usize| Instance {
        geometry,
        transform,
        instance_id: i as u32,
        mask: 0xff,
    };
    if let Some(bunny) = &bunny {
        let b = BottomLevel::new(0, bunny.clone(), &config);
        let size = b.tree.bounds.extent().max_element();
        let centre = b.tree.bounds.center();
        // A 4x4 lattice of rotated copies (examples/instances' placement).
        let grid: Vec<Instance> = (0..16)
            .map(|i| {
                let at = Vec3::new((i % 4) as f32, 0.0, (i / 4) as f32) * 1.2 * size;
                place(
                    0,
                    Affine3A::from_rotation_translation(glam::Quat::from_rotation_y(0.4 * i as f32), at - centre),
                    i,
                )
            })
            .collect();
        let mid = Vec3::new(1.5, 0.0, 1.5) * 1.2 * size;
        let rays = camera(mid + Vec3::new(0.0, 2.0, -6.0) * size, mid, 160, 120);
        cases.push(("bunny 4x4 grid".into(), vec![b], grid, rays));
        // 64 rotated copies heaped inside two bunny sizes: boxes overlap heavily.
        let b = BottomLevel::new(0, bunny.clone(), &config);
        let heap: Vec<Instance> = (0..64)
            .map(|i| {
                let at = Vec3::new(rng.next(), rng.next(), rng.next()) * 2.0 * size;
                place(0, Affine3A::from_rotation_translation(rotation(&mut rng), at - centre), i)
            })
            .collect();
        let mid = Vec3::splat(size);
        let rays = camera(mid + Vec3::new(0.5, 1.0, -4.0) * size, mid, 160, 120);
        cases.push(("bunny heap of 64".into(), vec![b], heap, rays));
    }
    // 4,096 bumpy balls of 1,140 triangles on a 100 x 100 ground, seen from inside at eye height.
    let forest: Vec<Instance> = (0..4096)
        .map(|i| {
            let at = Vec3::new(rng.next() * 100.0, 0.0, rng.next() * 100.0);
            let s = 0.3 + rng.next();
            place(0, Affine3A::from_scale_rotation_translation(Vec3::new(s, 2.0 * s, s), rotation(&mut rng), at), i)
        })
        .collect();
    let rays = camera(Vec3::new(5.0, 1.0, 5.0), Vec3::new(60.0, 0.5, 50.0), 160, 120);
    cases.push(("forest of 4,096 balls".into(), vec![BottomLevel::new(0, sphere(20, 30), &config)], forest, rays));
    // A room (a ball of radius 50 seen from inside) holding 256 small balls:
    // one instance's box holds all the others.
    let mut room = vec![place(1, Affine3A::from_scale(Vec3::splat(50.0)), 0)];
    room.extend((1..257).map(|i| {
        let at = (Vec3::new(rng.next(), rng.next(), rng.next()) * 2.0 - Vec3::ONE) * 25.0;
        place(
            0,
            Affine3A::from_scale_rotation_translation(Vec3::splat(1.0 + 2.0 * rng.next()), rotation(&mut rng), at),
            i,
        )
    }));
    let rays = camera(Vec3::new(0.0, 0.0, -40.0), Vec3::ZERO, 160, 120);
    let geometries = vec![BottomLevel::new(0, sphere(20, 30), &config), BottomLevel::new(1, sphere(64, 96), &config)];
    cases.push(("room of 256 balls".into(), geometries, room, rays));

    eprintln!("| scene | instances | top level | top nodes | instances entered | inner nodes | inner triangles | CPU µs/ray |");
    eprintln!("|---|---|---|---|---|---|---|---|");
    for (name, geometries, instances, rays) in cases {
        let mut scene = TwoLevelScene::new(geometries, &instances).unwrap();
        let timed = |f: &mut dyn FnMut()| {
            let start = std::time::Instant::now();
            f();
            start.elapsed().as_secs_f64() * 1e3
        };
        let build_median = timed(&mut || scene.set_instances(&instances).unwrap());
        let build_kd = timed(&mut || drop(KdTop::build(&scene)));
        let traversal = Traversal::closest(Variant::Stack);
        let (median, row_median) =
            measure("BVH, median split", &rays, |r, c| scene.trace_counted(r, 0xff, traversal, c));
        let kd = KdTop::build(&scene);
        let (kd_hits, row_kd) = measure(&format!("kd-tree, SAH ({} nodes)", kd.nodes.len()), &rays, |r, c| {
            kd.trace(&scene, r, 0xff, traversal, c)
        });
        let build_sah = timed(&mut || scene.rebuild_top_sah());
        eprintln!(
            "|   | builds: median BVH {build_median:.2} ms, SAH BVH {build_sah:.2} ms, kd-tree {build_kd:.2} ms |"
        );
        let (sah, row_sah) = measure("BVH, SAH", &rays, |r, c| scene.trace_counted(r, 0xff, traversal, c));
        for row in [row_median, row_sah, row_kd] {
            eprintln!("| {name} | {} | {row} |", instances.len());
        }
        // The three top levels answer alike: a hit on the same rays, at the same
        // t within 2^-20 (two instances whose hits lie within a rounding of each
        // other may answer either, and an instance traced with tmax at another's
        // hit may settle its own by the careful test: its t and u, v an ulp off).
        let mut ulp_apart = 0;
        for (k, ((a, b), c)) in median.iter().zip(&sah).zip(&kd_hits).enumerate() {
            assert_eq!(a.is_hit(), b.is_hit(), "{name}: ray {k}: {a:?} {b:?}");
            assert_eq!(a.is_hit(), c.is_hit(), "{name}: ray {k}: {a:?} {c:?}");
            if a.is_hit() {
                for other in [b.t, c.t] {
                    assert!((a.t - other).abs() <= a.t * 1e-6, "{name}: ray {k}: {a:?} {b:?} {c:?} {:?}", rays[k]);
                }
                ulp_apart += usize::from(a.t != b.t || a.t != c.t);
            }
        }
        eprintln!("|   | {ulp_apart} of {} rays' t differ between the top levels by an ulp |", rays.len());
    }
}
