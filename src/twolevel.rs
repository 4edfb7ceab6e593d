//! Two-level scenes: geometries with their own kd-trees, placed by instances
//! (a 3×4 transform, an instance id, an 8-bit visibility mask) over a top-level
//! BVH of the instances' world boxes, as Vulkan ray query and Embree place
//! them. Many instances of one geometry share its tree: an instance costs its
//! transform and box. Moving instances rebuilds the top level only
//! ([`TwoLevelScene::set_instances`]).
//!
//! [`TwoLevelScene::trace`] is the CPU model and twin; [`TwoLevelTracer`]
//! traces the same scene on a device (glsl/trace_twolevel.comp) with the same
//! answers bit for bit, for the single-ray variants `stack`, `restart`,
//! `push-down` and the short stacks, robust or plain, closest or any hit
//! (`backtrack`, `ropes` and packets trace two-level on the CPU only). The
//! contract both meet:
//!
//! - **The object-space ray** of instance `i` is [`TwoLevelScene::object_ray`]:
//!   origin `W·(o, 1)` and direction `W·(d, 0)`, with `W` the world-to-object
//!   transform (the inverse of the instance's transform, computed in f64 and
//!   rounded to f32 once), each component summed left to right in f32 without
//!   fused multiply-adds (the origin's translation added last, the direction's
//!   three products only); `tmin`, `tmax` unchanged (the direction is not
//!   normalized, so `t` is the world ray's parameter). Where `W` is exactly the
//!   identity, the object ray is the world ray itself, bit for bit (the sums
//!   above would turn a `-0.0` component into `+0.0`).
//! - **Each instance's answer is the robust traversal's for its object ray**:
//!   exact for that ray (the guarantees of docs/ACCURACY.md, on the geometry's
//!   own tree). Far-translated or badly conditioned transforms lose accuracy
//!   in the object ray itself, as in Vulkan; never inside the geometry.
//! - **The closest instance** is the one whose hit has the least f32 `t`;
//!   instances are searched with `tmax` cut to the best `t` so far, so two
//!   instances whose hits lie within one f32 rounding of each other may answer
//!   either (a tie).
//! - **Front face** is decided in object space, as in Vulkan: the triangle is
//!   front-facing when `dot((v1 - v0) × (v2 - v0), d_object) < 0` (its vertices
//!   appear clockwise from the origin in a left-handed frame), so a mirroring
//!   transform does not flip it. The cross product is rounded to f32 as
//!   written; the dot product's sign is exact (error-free products and an
//!   exact sum), with `d_object` as traced (denormal components as zeros).
//! - **Masks**: an instance is visible to a ray when `ray_mask & instance.mask != 0`.

use glam::{Affine3A, DAffine3, DVec3, Vec3};

use crate::consts::PRIM_MISS;
use crate::error::{Error, Result};
use crate::ff::{exact_sum8, two_prod};
use crate::geom::{Aabb, Ray};
use crate::kdtree::links::TreeLinks;
use crate::kdtree::traverse::{trace_ray, widen_near, SceneRef, Traversal, TFAR_SCALE};
use crate::kdtree::{BuildConfig, KdTree};
use crate::scene::Geometry;

/// A geometry with its own kd-tree, in its object space.
pub struct BottomLevel {
    /// The caller's geometry id.
    pub id: u32,
    /// Its triangles.
    pub triangles: Vec<[Vec3; 3]>,
    /// Its kd-tree over `triangles`.
    pub tree: KdTree,
}

impl BottomLevel {
    /// A geometry with its kd-tree built by `config`.
    pub fn new(id: u32, triangles: Vec<[Vec3; 3]>, config: &BuildConfig) -> BottomLevel {
        let tree = KdTree::build(&triangles, config);
        BottomLevel { id, triangles, tree }
    }

    /// A geometry as engines hold it ([`Geometry`]: `&[Vec3]` or strided vertex
    /// bytes, optional `u16`/`u32` indices), its id kept, its triangles checked as
    /// `Scene::from_geometries` checks them. A transform set on the geometry is
    /// applied to its vertices (Vulkan's geometry transform); place it with
    /// [`Instance`]s.
    pub fn from_geometry(geometry: &Geometry, config: &BuildConfig) -> Result<BottomLevel> {
        let mut triangles = Vec::new();
        geometry.world_triangles(&mut triangles)?;
        Ok(BottomLevel::new(geometry.id, triangles, config))
    }
}

/// One placement of a geometry.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    /// Index into the scene's geometries.
    pub geometry: usize,
    /// Object to world.
    pub transform: Affine3A,
    /// The caller's instance id, reported in the hit.
    pub instance_id: u32,
    /// Visible to rays whose mask shares a bit with it.
    pub mask: u8,
}

/// The closest hit of a ray in a two-level scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceHit {
    /// The world ray's parameter (infinite for a miss).
    pub t: f32,
    /// [`Instance::instance_id`] of the instance hit.
    pub instance_id: u32,
    /// [`BottomLevel::id`] of its geometry.
    pub geometry_id: u32,
    /// The triangle's index in its geometry; [`PRIM_MISS`] for a miss (or
    /// another special `PRIM_*` value as single-level traversal reports it).
    pub prim_index: u32,
    /// Barycentrics of the hit point.
    pub u: f32,
    /// See `u`.
    pub v: f32,
    /// The triangle faces the ray (see the module docs).
    pub front_face: bool,
    /// Index of the instance hit in the scene's instance list.
    pub instance_index: u32,
}

impl InstanceHit {
    /// No hit.
    pub const MISS: InstanceHit = InstanceHit {
        t: f32::INFINITY,
        instance_id: u32::MAX,
        geometry_id: u32::MAX,
        prim_index: PRIM_MISS,
        u: 0.0,
        v: 0.0,
        front_face: false,
        instance_index: u32::MAX,
    };

    /// True when a triangle was hit.
    pub fn is_hit(&self) -> bool {
        self.prim_index < crate::consts::PRIM_INCOMPLETE
    }
}

/// An instance as traversal sees it.
struct Placed {
    instance: Instance,
    /// World to object, rows of a 3×4 matrix.
    to_object: [[f32; 4]; 3],
    /// The geometry's box under the transform, widened to hold rounding.
    world_box: Aabb,
    /// ‖transform‖ · ‖inverse‖ (max-row norms): how much the object ray's
    /// rounding may move it, relative to the origin's magnitude, in world space.
    condition: f32,
}

/// A top-level BVH node: a box and either two children or a range of instances.
#[derive(Clone, Copy, Debug)]
struct BvhNode {
    bounds: Aabb,
    /// Leaf: first index into `order`; interior: the second child (the first follows).
    index: u32,
    /// Instances in the leaf; 0 for an interior node.
    count: u32,
    /// The largest `Placed::condition` below.
    condition: f32,
}

/// The work of a two-level trace: top-level nodes visited, instances entered
/// (object rays traced) and the nodes and triangle tests inside them.
#[derive(Clone, Copy, Debug, Default)]
struct TopCounts {
    top_nodes: u64,
    entries: u64,
    inner_nodes: u64,
    inner_triangles: u64,
}

impl TopCounts {
    fn add_entry(&mut self, inner: &crate::kdtree::traverse::Counters) {
        self.entries += 1;
        self.inner_nodes += inner.nodes as u64;
        self.inner_triangles += inner.triangles as u64;
    }
}

/// A two-level scene: geometries, their instances and the top level.
pub struct TwoLevelScene {
    geometries: Vec<BottomLevel>,
    /// Each geometry's side buffers (parents, node boxes, ropes) for `Backtrack` and `Ropes`.
    links: Vec<TreeLinks>,
    placed: Vec<Placed>,
    nodes: Vec<BvhNode>,
    /// Instance indices in leaf order.
    order: Vec<u32>,
}

/// Instances per top-level leaf at most.
const LEAF_INSTANCES: usize = 2;

impl TwoLevelScene {
    /// A scene of `geometries` placed by `instances`.
    ///
    /// Errors: `Error::InvalidInput` naming the geometry whose tree does not fit
    /// its triangles ([`KdTree::check`]), or the instance for a geometry index
    /// out of range, a transform that is not finite or not invertible in f32, or
    /// a world box that overflows.
    pub fn new(geometries: Vec<BottomLevel>, instances: &[Instance]) -> Result<TwoLevelScene> {
        for (i, g) in geometries.iter().enumerate() {
            g.tree.check(g.triangles.len()).map_err(|e| {
                Error::InvalidInput(format!("geometry {i} (id {}): the kd-tree does not fit its triangles: {e}", g.id))
            })?;
        }
        let links = geometries.iter().map(|g| TreeLinks::new(&g.tree.nodes, g.tree.bounds)).collect();
        let mut scene = TwoLevelScene { geometries, links, placed: Vec::new(), nodes: Vec::new(), order: Vec::new() };
        scene.set_instances(instances)?;
        Ok(scene)
    }

    /// A two-level scene of engine-shaped geometries, each entry one placement:
    /// entries of one geometry id whose untransformed triangles are equal share
    /// one [`BottomLevel`] (built once, in object space); each entry becomes an
    /// instance with its transform (identity when none) and instance id, mask
    /// 0xff, in order. Also returns each entry's range in the numbering of
    /// [`crate::scene::Scene::from_geometries`] for the same list.
    ///
    /// Errors: those of `Scene::from_geometries` and [`TwoLevelScene::new`].
    pub fn from_geometries(
        geometries: &[Geometry],
        config: &BuildConfig,
    ) -> Result<(TwoLevelScene, Vec<crate::scene::GeometryRange>)> {
        let mut bottoms: Vec<BottomLevel> = Vec::new();
        let mut instances = Vec::with_capacity(geometries.len());
        let mut ranges = Vec::with_capacity(geometries.len());
        let mut first = 0u32;
        for g in geometries {
            let mut triangles = Vec::new();
            g.object_triangles(&mut triangles)?;
            let index = match bottoms.iter().position(|b| b.id == g.id && b.triangles == triangles) {
                Some(i) => i,
                None => {
                    bottoms.push(BottomLevel { id: g.id, tree: KdTree::build(&triangles, config), triangles });
                    bottoms.len() - 1
                }
            };
            let count = bottoms[index].triangles.len() as u32;
            ranges.push(crate::scene::GeometryRange {
                geometry_id: g.id,
                instance_id: g.instance_id,
                first_prim: first,
                count,
            });
            first = first
                .checked_add(count)
                .filter(|&n| n < crate::consts::PRIM_INCOMPLETE)
                .ok_or_else(|| Error::InvalidInput("too many triangles for the numbering of hits".into()))?;
            instances.push(Instance {
                geometry: index,
                transform: g.transform.unwrap_or(Affine3A::IDENTITY),
                instance_id: g.instance_id,
                mask: 0xff,
            });
        }
        if first == 0 {
            return Err(Error::InvalidInput("scene has no triangles".into()));
        }
        Ok((TwoLevelScene::new(bottoms, &instances)?, ranges))
    }

    /// Replaces geometry `index` by `geometry` (its tree built by the caller, e.g.
    /// with [`BottomLevel::new`]): every other tree is kept; the instances are
    /// placed again over the new box and the top level rebuilt. Upload with
    /// [`TwoLevelTracer::set_geometries`]. On error the scene is unchanged.
    ///
    /// Errors: an index past the geometries, a tree that does not fit its
    /// triangles, and those of [`TwoLevelScene::set_instances`].
    pub fn set_geometry(&mut self, index: usize, geometry: BottomLevel) -> Result<()> {
        if index >= self.geometries.len() {
            return Err(Error::InvalidInput(format!(
                "geometry index {index} is past the scene's {} geometries",
                self.geometries.len()
            )));
        }
        geometry.tree.check(geometry.triangles.len()).map_err(|e| {
            Error::InvalidInput(format!(
                "geometry {index} (id {}): the kd-tree does not fit its triangles: {e}",
                geometry.id
            ))
        })?;
        let links = TreeLinks::new(&geometry.tree.nodes, geometry.tree.bounds);
        let old = std::mem::replace(&mut self.geometries[index], geometry);
        let old_links = std::mem::replace(&mut self.links[index], links);
        let instances: Vec<Instance> = self.placed.iter().map(|p| p.instance).collect();
        if let Err(e) = self.set_instances(&instances) {
            self.geometries[index] = old;
            self.links[index] = old_links;
            return Err(e);
        }
        Ok(())
    }

    /// Replaces the instances and rebuilds the top level only (the geometries'
    /// trees are kept). On error the scene is unchanged.
    pub fn set_instances(&mut self, instances: &[Instance]) -> Result<()> {
        let placed =
            instances.iter().enumerate().map(|(i, inst)| self.place(i, inst)).collect::<Result<Vec<Placed>>>()?;
        let mut order: Vec<u32> = (0..placed.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * placed.len().max(1));
        if !placed.is_empty() {
            build_bvh(&placed, &mut order, 0, placed.len(), &mut nodes);
        }
        (self.placed, self.nodes, self.order) = (placed, nodes, order);
        Ok(())
    }

    fn place(&self, i: usize, inst: &Instance) -> Result<Placed> {
        let bad = |why: String| Error::InvalidInput(format!("instance {i} (id {}): {why}", inst.instance_id));
        let geometry = self.geometries.get(inst.geometry).ok_or_else(|| {
            bad(format!("geometry index {} is past the scene's {} geometries", inst.geometry, self.geometries.len()))
        })?;
        let m = inst.transform;
        if !m.matrix3.is_finite() || !m.translation.is_finite() {
            return Err(bad(format!("the transform is not finite: {m:?}")));
        }
        let inverse = DAffine3::from_mat3_translation(m.matrix3.as_dmat3(), m.translation.as_dvec3()).inverse();
        let rows = [0, 1, 2].map(|r| {
            let row = inverse.matrix3.row(r);
            [row.x as f32, row.y as f32, row.z as f32, inverse.translation[r] as f32]
        });
        if !rows.iter().flatten().all(|x| x.is_finite()) || m.matrix3.determinant() == 0.0 {
            return Err(bad("the transform is not invertible in f32".into()));
        }
        let b = geometry.tree.bounds;
        let norm =
            |rows: [[f64; 3]; 3]| rows.iter().map(|r| r.iter().map(|x| x.abs()).sum::<f64>()).fold(0.0, f64::max);
        let forward = m.matrix3.as_dmat3().transpose().to_cols_array_2d();
        let backward = inverse.matrix3.transpose().to_cols_array_2d();
        let condition = (norm(forward) * norm(backward)) as f32;
        if b.is_empty() {
            // A geometry without a triangle that can be hit: never entered.
            return Ok(Placed { instance: *inst, to_object: rows, world_box: Aabb::EMPTY, condition });
        }
        let mut world = Aabb::EMPTY;
        for k in 0..8 {
            let corner = DVec3::new(
                if k & 1 == 0 { b.min.x } else { b.max.x } as f64,
                if k & 2 == 0 { b.min.y } else { b.max.y } as f64,
                if k & 4 == 0 { b.min.z } else { b.max.z } as f64,
            );
            let p = m.matrix3.as_dmat3() * corner + m.translation.as_dvec3();
            world = world.grow(p.as_vec3());
        }
        // Widened so that a world ray whose f32 object ray enters the object box
        // also enters the world box: 2^-16 of the box's magnitude (the object ray's
        // rounding is about 2^-22 of the coordinates' magnitude).
        let margin = (world.min.abs().max(world.max.abs()).max_element() + world.extent().max_element()) / 65536.0;
        let world_box = Aabb::new(world.min - Vec3::splat(margin), world.max + Vec3::splat(margin));
        if !world_box.min.is_finite() || !world_box.max.is_finite() {
            return Err(bad("the instance's world box overflows".into()));
        }
        Ok(Placed { instance: *inst, to_object: rows, world_box, condition })
    }

    /// The geometries.
    pub fn geometries(&self) -> &[BottomLevel] {
        &self.geometries
    }

    /// Instances placed.
    pub fn instance_count(&self) -> usize {
        self.placed.len()
    }

    /// Bytes [`TwoLevelTracer::new`] uploads for this scene: per geometry its
    /// nodes (8 bytes each) and a 48-byte triangle per leaf reference, 48 bytes
    /// of geometry record; per instance 64 bytes, two top-level nodes' room (48
    /// bytes each) and a 4-byte order entry (room for one instance at least).
    pub fn device_bytes(&self) -> u64 {
        let nodes: u64 = self.geometries.iter().map(|g| g.tree.nodes.len() as u64).sum();
        let refs: u64 = self.geometries.iter().map(|g| g.tree.prim_indices.len() as u64).sum();
        let room = self.placed.len().max(1) as u64;
        let at_least_4 = |b: u64| b.max(4);
        at_least_4(8 * nodes)
            + at_least_4(48 * refs)
            + at_least_4(48 * self.geometries.len() as u64)
            + room * (64 + 2 * 48 + 4)
    }

    /// Top-level nodes (for statistics).
    pub fn top_level_nodes(&self) -> usize {
        self.nodes.len()
    }

    /// The object-space ray of instance `index` for the world ray `ray` (the
    /// module docs' contract).
    pub fn object_ray(&self, index: usize, ray: &Ray) -> Ray {
        let m = &self.placed[index].to_object;
        if is_identity(m) {
            return *ray;
        }
        let o = Vec3::from(ray.origin);
        let d = Vec3::from(ray.dir);
        let linear = |r: usize, v: Vec3| (m[r][0] * v.x + m[r][1] * v.y) + m[r][2] * v.z;
        let origin = Vec3::new(linear(0, o) + m[0][3], linear(1, o) + m[1][3], linear(2, o) + m[2][3]);
        let dir = Vec3::new(linear(0, d), linear(1, d), linear(2, d));
        Ray::new(origin, dir, ray.tmin, ray.tmax)
    }

    /// Traces instance `i`'s object ray for `ray`, cut at the best hit so far:
    /// `best` becomes its hit when that is no farther; a traversal cut short (or
    /// an object ray the transform made invalid) sets `incomplete`, as this
    /// instance's answer is unknown. True when an any-hit trace may stop.
    fn enter(
        &self,
        i: u32,
        ray: &Ray,
        traversal: Traversal,
        best: &mut InstanceHit,
        incomplete: &mut bool,
        counts: &mut TopCounts,
    ) -> bool {
        let placed = &self.placed[i as usize];
        let g = placed.instance.geometry;
        let geometry = &self.geometries[g];
        let mut object = self.object_ray(i as usize, ray);
        object.tmax = best.t.min(ray.tmax);
        let view = SceneRef::new(&geometry.tree, &geometry.triangles).with_links(&self.links[g]);
        let (hit, inner) = trace_ray(&view, &object, traversal);
        counts.add_entry(&inner);
        if !hit.is_hit() {
            *incomplete |= hit.prim_id != PRIM_MISS;
            return false;
        }
        if hit.t <= best.t || !best.is_hit() {
            *best = InstanceHit {
                t: hit.t,
                instance_id: placed.instance.instance_id,
                geometry_id: geometry.id,
                prim_index: hit.prim_id,
                u: hit.u,
                v: hit.v,
                front_face: faces(&geometry.triangles[hit.prim_id as usize], object.traced_dir()),
                instance_index: i,
            };
            return traversal.any_hit;
        }
        false
    }

    /// The closest hit of `ray` among the instances visible to `mask`, each
    /// traced with `traversal` (any variant, robust or plain). Any-hit
    /// traversals stop at the first instance hit. When an instance's traversal
    /// is cut short the answer is `PRIM_INCOMPLETE` (for any hit, unless another
    /// instance occludes), never a miss or a possibly farther hit.
    pub fn trace(&self, ray: &Ray, mask: u8, traversal: Traversal) -> InstanceHit {
        self.trace_counted(ray, mask, traversal, &mut TopCounts::default())
    }

    /// [`TwoLevelScene::trace`], adding its work to `counts`.
    fn trace_counted(&self, ray: &Ray, mask: u8, traversal: Traversal, counts: &mut TopCounts) -> InstanceHit {
        let mut best = InstanceHit::MISS;
        if self.nodes.is_empty() || !ray.is_valid() || mask == 0 {
            if !ray.is_valid() {
                best = InstanceHit { t: f32::NAN, prim_index: crate::consts::PRIM_INVALID, ..InstanceHit::MISS };
            }
            return best;
        }
        let o = Vec3::from(ray.origin);
        let d = ray.traced_dir();
        let inv = (Vec3::ONE / d).clamp(Vec3::splat(-f32::MAX), Vec3::splat(f32::MAX));
        // The object rays' rounding grows with the origin's magnitude: boxes are
        // widened by it, times each subtree's condition number (see `Placed`).
        let far = o.abs().max_element() / 1_048_576.0;
        let enters = |n: u32, reach: f32| {
            let node = &self.nodes[n as usize];
            slab(&node.bounds, far * node.condition, o, d, inv, ray.tmin, reach)
        };
        let mut incomplete = false;
        let mut stack = vec![0u32];
        // One instance: its world box is not tested (the object ray's clip to the
        // geometry's box decides as much), as in the kernel's one-instance pipeline.
        let one_instance = self.placed.len() == 1;
        while let Some(n) = stack.pop() {
            let node = self.nodes[n as usize];
            counts.top_nodes += 1;
            let reach = best.t.min(ray.tmax);
            if !one_instance && enters(n, reach).is_none() {
                continue;
            }
            if node.count == 0 {
                // Nearer child last (popped first).
                let (a, b) = (n + 1, node.index);
                let ta = enters(a, reach).map_or(f32::INFINITY, |t| t.0);
                let tb = enters(b, reach).map_or(f32::INFINITY, |t| t.0);
                stack.extend(if ta <= tb { [b, a] } else { [a, b] });
                continue;
            }
            for &i in &self.order[node.index as usize..(node.index + node.count) as usize] {
                if self.placed[i as usize].instance.mask & mask != 0
                    && self.enter(i, ray, traversal, &mut best, &mut incomplete, counts)
                {
                    return best;
                }
            }
        }
        // As single-level traversal: a closest hit is not claimed when an instance
        // that might hold a closer one did not finish.
        if incomplete {
            best = InstanceHit { t: f32::NAN, prim_index: crate::consts::PRIM_INCOMPLETE, ..InstanceHit::MISS };
        }
        best
    }
}

/// Whether `triangle` faces the direction `d`: the exact sign of
/// `dot(n, d) < 0`, `n` the f32 cross product of its edges `v1 - v0` and
/// `v2 - v0` (products as written, no fused multiply-add). Twin of
/// `front_facing` in glsl/trace_twolevel.comp.
fn faces(triangle: &[Vec3; 3], d: Vec3) -> bool {
    let [v0, v1, v2] = *triangle;
    let (e1, e2) = (v1 - v0, v2 - v0);
    let n = [e1.y * e2.z - e2.y * e1.z, e1.z * e2.x - e2.z * e1.x, e1.x * e2.y - e2.x * e1.y];
    let [px, py, pz] = [two_prod(n[0], d.x), two_prod(n[1], d.y), two_prod(n[2], d.z)];
    exact_sum8([px.hi, px.lo, py.hi, py.lo, pz.hi, pz.lo, 0.0, 0.0]).hi < 0.0
}

/// The world ray's entry and exit of `b` widened by `widen` on every side,
/// within `[tmin, tmax]`, conservatively (the bounds widened by 3·2^-23 of their magnitude),
/// or `None`.
fn slab(b: &Aabb, widen: f32, o: Vec3, d: Vec3, inv: Vec3, tmin: f32, tmax: f32) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (tmin, tmax);
    for a in 0..3 {
        let (lo, hi) = (b.min[a] - widen, b.max[a] + widen);
        if d[a] == 0.0 {
            if o[a] < lo || o[a] > hi {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((lo - o[a]) * inv[a], (hi - o[a]) * inv[a]);
        // Both bounds widened as the scene-box clip widens them (the near one down:
        // a rounded entry compared with the ray's own tmax must not clip away a hit
        // on the box's face).
        t0 = t0.max(widen_near(ta.min(tb)));
        t1 = t1.min(ta.max(tb) * TFAR_SCALE);
    }
    (t0 <= t1).then_some((t0, t1))
}

/// Builds the BVH over `order[lo..hi]` (median split on the longest axis of
/// the centroids), appending depth-first; returns the node's index.
fn build_bvh(placed: &[Placed], order: &mut [u32], lo: usize, hi: usize, nodes: &mut Vec<BvhNode>) -> u32 {
    let bounds = order[lo..hi].iter().fold(Aabb::EMPTY, |b, &i| b.union(placed[i as usize].world_box));
    let index = nodes.len() as u32;
    let condition = order[lo..hi].iter().map(|&i| placed[i as usize].condition).fold(0.0, f32::max);
    if hi - lo <= LEAF_INSTANCES {
        nodes.push(BvhNode { bounds, index: lo as u32, count: (hi - lo) as u32, condition });
        return index;
    }
    let centroids = order[lo..hi].iter().fold(Aabb::EMPTY, |b, &i| b.grow(placed[i as usize].world_box.center()));
    let e = centroids.extent();
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let mid = (lo + hi) / 2;
    order[lo..hi].select_nth_unstable_by(mid - lo, |&a, &b| {
        let (ca, cb) = (placed[a as usize].world_box.center()[axis], placed[b as usize].world_box.center()[axis]);
        ca.total_cmp(&cb)
    });
    nodes.push(BvhNode { bounds, index: 0, count: 0, condition });
    build_bvh(placed, order, lo, mid, nodes);
    let second = build_bvh(placed, order, mid, hi, nodes);
    nodes[index as usize].index = second;
    index
}

/// Verdicts on two-level answers against the exact reference (feature `exact`).
#[cfg(any(feature = "exact", test))]
impl TwoLevelScene {
    /// The verdict on a closest-hit answer: judged ([`crate::exact::judge`]) on
    /// the object ray of the instance it names against that instance's exact
    /// answer, and a farther instance's hit (beyond 2^-20 of the nearest exact
    /// `t` over every visible instance's object ray) is a missed hit; a miss is
    /// judged against every instance (the worst verdict).
    pub fn verdict(&self, ray: &Ray, hit: &InstanceHit) -> crate::exact::Verdict {
        use crate::exact::{closest_exact, judge, Exact, Verdict};
        use crate::geom::Hit;
        let exact: Vec<(Ray, Exact)> = (0..self.instance_count())
            .map(|i| {
                let object = self.object_ray(i, ray);
                (object, closest_exact(&self.geometry_of(i).triangles, &object))
            })
            .collect();
        if !hit.is_hit() {
            if hit.prim_index != PRIM_MISS {
                return Verdict::BadAnswer;
            }
            let verdicts = exact
                .iter()
                .enumerate()
                .map(|(i, (object, e))| judge(&self.geometry_of(i).triangles, object, &Hit::MISS, e).0);
            return worst(verdicts);
        }
        let nearest = exact
            .iter()
            .filter_map(|(_, e)| match e {
                Exact::Hit { t, .. } => Some(*t),
                _ => None,
            })
            .min_by(f64::total_cmp);
        let k = hit.instance_index as usize;
        let h = Hit { t: hit.t, prim_id: hit.prim_index, u: hit.u, v: hit.v };
        let (v, _) = judge(&self.geometry_of(k).triangles, &exact[k].0, &h, &exact[k].1);
        match (&exact[k].1, nearest) {
            (Exact::Hit { t, .. }, Some(n)) if v.agrees() && *t > n * (1.0 + 1.0 / 1_048_576.0) + 1e-30 => {
                Verdict::MissedHit
            }
            _ => v,
        }
    }

    /// The verdict on an any-hit answer ([`crate::exact::judge_any`]): an
    /// occluder must really be hit by its instance's object ray within the
    /// segment; a free segment must be free for every instance.
    pub fn verdict_any(&self, ray: &Ray, hit: &InstanceHit) -> crate::exact::Verdict {
        use crate::exact::{closest_exact, judge_any, Verdict};
        use crate::geom::Hit;
        let judge_instance = |i: usize, h: &Hit| {
            let object = self.object_ray(i, ray);
            let triangles = &self.geometry_of(i).triangles;
            judge_any(triangles, &object, h, &closest_exact(triangles, &object))
        };
        if hit.is_hit() {
            let h = Hit { t: hit.t, prim_id: hit.prim_index, u: hit.u, v: hit.v };
            return judge_instance(hit.instance_index as usize, &h);
        }
        if hit.prim_index != PRIM_MISS {
            return Verdict::BadAnswer;
        }
        worst((0..self.instance_count()).map(|i| judge_instance(i, &Hit::MISS)))
    }

    fn geometry_of(&self, instance: usize) -> &BottomLevel {
        &self.geometries[self.placed[instance].instance.geometry]
    }
}

/// The worst of `verdicts`: a serious one, else the first disagreement, else agreement.
#[cfg(any(feature = "exact", test))]
fn worst(verdicts: impl Iterator<Item = crate::exact::Verdict>) -> crate::exact::Verdict {
    let mut worst = crate::exact::Verdict::BothMiss;
    for v in verdicts {
        if v.is_serious() || (!v.agrees() && worst.agrees()) {
            worst = v;
        }
    }
    worst
}

mod gpu;
mod pipelines;
pub use crate::abi::GpuInstanceHit;
pub use gpu::{TwoLevelBinding, TwoLevelTraceResult, TwoLevelTracer};
pub use pipelines::TwoLevelPipelines;

/// Whether a world-to-object matrix is exactly the identity (its object rays
/// are the world rays themselves).
pub(crate) fn is_identity(m: &[[f32; 4]; 3]) -> bool {
    *m == [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]]
}

#[cfg(test)]
mod tests;
#[cfg(test)]
mod top_kd;
