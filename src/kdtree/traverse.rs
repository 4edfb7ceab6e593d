//! CPU twins of the GPU traversal variants in `glsl/traverse/`: the same
//! decoding, decisions, order and counters, in the same f32 arithmetic, so a
//! test can compare hits and counters per ray. Change both together.

use glam::Vec3;

use super::KdNode;
use crate::consts::{MAX_STACK, MAX_TRAVERSAL_STEPS, PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};
use crate::geom::{Aabb, Hit, Ray, WatertightRay};

/// The traversal algorithms (specialization constant `VARIANT` of `trace.comp`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Variant {
    /// Full per-ray stack, front to back (pbrt-v3). The baseline.
    Stack,
    /// kd-restart (Foley & Sugerman 2005): no stack, restart at the root behind each leaf.
    Restart,
}

impl Variant {
    pub const ALL: [Variant; 2] = [Variant::Stack, Variant::Restart];

    /// The value of the `VARIANT` specialization constant.
    pub fn id(self) -> u32 {
        match self {
            Variant::Stack => crate::consts::VARIANT_STACK,
            Variant::Restart => crate::consts::VARIANT_RESTART,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Variant::Stack => "stack",
            Variant::Restart => "restart",
        }
    }
}

impl std::str::FromStr for Variant {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Variant::ALL
            .into_iter()
            .find(|v| v.name() == s)
            .ok_or_else(|| crate::Error::InvalidInput(format!("unknown traversal '{s}' (stack, restart)")))
    }
}

/// Per-ray counters, as written by the GPU when counters are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub nodes: u32,
    pub leaves: u32,
    pub triangles: u32,
    pub restarts: u32,
    pub steps: u32,
}

/// What a traversal needs: the tree, the triangles it indexes and the scene box.
#[derive(Clone, Copy)]
pub struct SceneRef<'a> {
    pub nodes: &'a [KdNode],
    pub prim_indices: &'a [u32],
    pub triangles: &'a [[Vec3; 3]],
    pub bounds: Aabb,
}

struct TraceRay {
    wr: WatertightRay,
    origin: Vec3,
    dir: Vec3,
    inv_dir: Vec3,
    tmin: f32,
    tmax: f32,
}

#[derive(PartialEq, Eq)]
enum Visit {
    Near,
    Far,
    Both,
    /// The ray lies in the split plane: both children with the same interval.
    BothSame,
}

/// Traces one ray with `variant`: the CPU twin of `trace.comp`'s `main`.
pub fn trace_ray(scene: &SceneRef, ray: &Ray, variant: Variant) -> (Hit, Counters) {
    let mut best = Hit { t: ray.tmax, prim_id: PRIM_MISS, u: 0.0, v: 0.0 };
    let mut c = Counters::default();
    if !ray.is_valid() {
        best.prim_id = PRIM_INVALID;
    } else {
        let origin = Vec3::from(ray.origin);
        let dir = Vec3::from(ray.dir);
        let r = TraceRay {
            wr: WatertightRay::new(origin, dir),
            origin,
            dir,
            inv_dir: Vec3::ONE / dir,
            tmin: ray.tmin,
            tmax: ray.tmax,
        };
        if let Some((t0, t1)) = clip_to_box(&r, &scene.bounds) {
            let finished = match variant {
                Variant::Stack => trace_stack(scene, &r, t0, t1, &mut best, &mut c),
                Variant::Restart => trace_restart(scene, &r, t0, t1, &mut best, &mut c),
            };
            if !finished {
                best.prim_id = PRIM_INCOMPLETE;
            }
        }
    }
    if best.prim_id >= PRIM_INCOMPLETE {
        best.t = if best.prim_id == PRIM_MISS { f32::INFINITY } else { f32::NAN };
        best.u = 0.0;
        best.v = 0.0;
    }
    (best, c)
}

/// 1 + 2·gamma(3) with gamma(n) = n·u / (1 - n·u), u = 2^-24, rounded up: 1 + 3·2^-23
/// (Ize 2013). Widens the far bound so rounding never clips away a hit on the box.
const TFAR_SCALE: f32 = 1.0 + 3.0 * f32::EPSILON;

/// Slab clip of [tmin, tmax] to the scene box; twin of `clip_to_box` in common.glsl.
fn clip_to_box(r: &TraceRay, b: &Aabb) -> Option<(f32, f32)> {
    let mut t0 = r.tmin;
    let mut t1 = r.tmax;
    for axis in 0..3 {
        let o = r.origin[axis];
        if r.dir[axis] == 0.0 {
            if o < b.min[axis] || o > b.max[axis] {
                return None;
            }
            continue;
        }
        let ta = (b.min[axis] - o) * r.inv_dir[axis];
        let tb = (b.max[axis] - o) * r.inv_dir[axis];
        let tnear = glsl_min(ta, tb);
        let tfar = glsl_max(ta, tb) * TFAR_SCALE;
        t0 = glsl_max(t0, tnear);
        t1 = glsl_min(t1, tfar);
    }
    (t0 <= t1).then_some((t0, t1))
}

// GLSL's min(x, y) is `y < x ? y : x` and max(x, y) is `x < y ? y : x`.
fn glsl_min(x: f32, y: f32) -> f32 {
    if y < x {
        y
    } else {
        x
    }
}

fn glsl_max(x: f32, y: f32) -> f32 {
    if x < y {
        y
    } else {
        x
    }
}

/// Twin of `decide_children` in common.glsl: (visit, near, far, t_split).
fn decide_children(r: &TraceRay, index: u32, n: KdNode, t0: f32, t1: f32, ties_go_far: bool) -> (Visit, u32, u32, f32) {
    let axis = n.axis();
    let split = n.split();
    let o = r.origin[axis];
    let d = r.dir[axis];
    let below_first = !d.is_sign_negative();
    let (below, above) = (index + 1, n.above_child());
    let (near, far) = if below_first { (below, above) } else { (above, below) };
    let ts = (split - o) * r.inv_dir[axis];
    let visit = if d == 0.0 && o == split {
        Visit::BothSame
    } else if ts > t1 {
        Visit::Near
    } else if ts < t0 || (ties_go_far && ts == t0) {
        Visit::Far
    } else {
        Visit::Both
    };
    (visit, near, far, ts)
}

/// Twin of `intersect_leaf` in common.glsl.
fn intersect_leaf(scene: &SceneRef, r: &TraceRay, n: KdNode, best: &mut Hit, c: &mut Counters) {
    let offset = n.prim_offset() as usize;
    let count = n.prim_count() as usize;
    for &prim in &scene.prim_indices[offset..offset + count] {
        let [v0, v1, v2] = scene.triangles[prim as usize];
        if let Some((t, u, v)) = r.wr.intersect(v0, v1, v2, r.tmin, best.t) {
            *best = Hit { t, prim_id: prim, u, v };
        }
    }
    c.triangles += count as u32;
}

/// Twin of `trace_stack` in glsl/traverse/stack.glsl.
fn trace_stack(scene: &SceneRef, r: &TraceRay, mut t0: f32, mut t1: f32, best: &mut Hit, c: &mut Counters) -> bool {
    let mut stack = [(0u32, 0f32, 0f32); MAX_STACK as usize];
    let mut sp = 0usize;
    let mut node = 0u32;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        c.steps += 1;
        c.nodes += 1;
        let n = scene.nodes[node as usize];
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(r, node, n, t0, t1, false);
            match visit {
                Visit::Near => node = near,
                Visit::Far => node = far,
                Visit::BothSame => {
                    stack[sp] = (far, t0, t1);
                    sp += 1;
                    node = near;
                }
                Visit::Both => {
                    stack[sp] = (far, ts, t1);
                    sp += 1;
                    node = near;
                    t1 = ts;
                }
            }
            continue;
        }
        c.leaves += 1;
        intersect_leaf(scene, r, n, best, c);
        if best.t <= t1 || sp == 0 {
            return true;
        }
        sp -= 1;
        (node, t0, t1) = stack[sp];
    }
    false
}

/// Twin of `trace_restart` in glsl/traverse/restart.glsl.
fn trace_restart(scene: &SceneRef, r: &TraceRay, mut t0: f32, t1_scene: f32, best: &mut Hit, c: &mut Counters) -> bool {
    let mut node = 0u32;
    let mut t1 = t1_scene;
    let mut first_descent = true;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        c.steps += 1;
        c.nodes += 1;
        let n = scene.nodes[node as usize];
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(r, node, n, t0, t1, !first_descent);
            match visit {
                Visit::Far => node = far,
                Visit::Both => {
                    node = near;
                    t1 = ts;
                }
                Visit::Near | Visit::BothSame => node = near,
            }
            continue;
        }
        c.leaves += 1;
        intersect_leaf(scene, r, n, best, c);
        if best.t <= t1 || t1 >= t1_scene {
            return true;
        }
        t0 = t1;
        t1 = glsl_min(t1_scene, best.t);
        node = 0;
        first_descent = false;
        c.restarts += 1;
    }
    false
}
