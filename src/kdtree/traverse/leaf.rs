//! The leaf: its triangle tests ([`intersect_leaf`]), the closest hit they keep
//! ([`Closest`]), and the tests of whether a traversal is done. Twin of
//! `glsl/traverse/leaf.glsl`.

use super::node::Counters;
use super::segment::TraceRay;
use super::{SceneRef, State};
use crate::consts::PRIM_MISS;
use crate::ff::Ff;
use crate::geom::{Hit, TriTest, EDGE_GAMMA};
use crate::kdtree::KdNode;

/// What a traversal keeps about the closest hit so far: `Closest` in leaf.glsl,
/// less its `needs_careful` (the twins always trace as the careful pass does).
/// `hit` is in the segment frame (`t` = the segment frame's `tmax` and
/// [`PRIM_MISS`] for none); `reference` is its index of `prim_indices` ([`NO_REF`]
/// for none) and `err` a bound on the error of its `t`: [`intersect_leaf`]
/// orders hits within each other's bounds in float-float.
#[derive(Clone, Copy)]
pub(super) struct Closest {
    pub(super) hit: Hit,
    pub(super) reference: u32,
    pub(super) err: f32,
}

impl Closest {
    /// No hit yet, up to `tmax` (segment frame): `closest_none` in leaf.glsl.
    pub(super) fn none(tmax: f32) -> Closest {
        Closest { hit: Hit { t: tmax, prim_id: PRIM_MISS, u: 0.0, v: 0.0 }, reference: NO_REF, err: 0.0 }
    }
}

impl Closest {
    /// The farthest `t` at which the closest hit's exact `t` may lie (`best_reach`
    /// in leaf.glsl): cells beyond it cannot hold a closer hit.
    pub(super) fn reach(&self) -> f32 {
        self.hit.t + self.err
    }

    /// `leaf_done` in leaf.glsl: an any-hit found one, or the closest hit lies
    /// inside the leaf's segment, which ends at `t1`. Without a hit never: a leaf
    /// whose rounded exit passes the segment's end (`tmax`) has not covered it
    /// (the exit of a split plane through the hit at `tmax` may round past it);
    /// traversal ends as for a ray with `tmax = inf`, its segments clipped.
    pub(super) fn done(&self, any_hit: bool, t1: f32) -> bool {
        if any_hit {
            self.hit.prim_id != PRIM_MISS
        } else {
            self.hit.prim_id != PRIM_MISS && self.reach() <= t1
        }
    }
}

/// No reference (`NO_REF` in leaf.glsl).
pub(super) const NO_REF: u32 = u32::MAX;

impl State<'_, '_> {
    /// The farthest `t` at which the closest hit's exact `t` may lie (`best_reach`
    /// in leaf.glsl): cells beyond it cannot hold a closer hit.
    pub(super) fn reach(&self) -> f32 {
        self.best.reach()
    }

    /// `starts_behind` in leaf.glsl: a stack entry or leaf starting at `t0`
    /// cannot hold the closest hit (`t0` at or behind its reach). Robust: only
    /// once there is a hit (without one the reach is the segment's end, and an
    /// entry clamped to start there may hold a hit exactly at `tmax`).
    pub(super) fn starts_behind(&self, t0: f32) -> bool {
        let has_hit = !self.r.wr.robust || self.best.hit.prim_id != PRIM_MISS;
        has_hit && !starts_before(t0, self.reach())
    }

    /// Tests a leaf (`visit_leaf` in leaf.glsl); true when traversal is done
    /// (`leaf_done`): an any-hit found one, or the closest hit lies inside the
    /// leaf's segment (which ends at `t1`).
    pub(super) fn leaf(&mut self, n: KdNode, t1: f32) -> bool {
        self.c.leaves += 1;
        let tested = self.c.triangles;
        intersect_leaf(self.scene, self.r, n, &mut self.best, self.c);
        if let Some(log) = self.log.as_mut() {
            log.tested(self.c.triangles - tested);
        }
        self.best.done(self.r.any_hit, t1)
    }
}

/// True when a stack entry starting at `t0` can hold a hit closer than `best_t`
/// (`t0 < best_t`; false for NaN, as the shader's `!(t0 < best.t)` drops it).
pub(super) fn starts_before(t0: f32, best_t: f32) -> bool {
    t0 < best_t
}

/// Twin of `intersect_leaf` in leaf.glsl. Any-hit mode stops at the first hit.
/// The f32 tests first, then a second pass in float-float over the pairs they left
/// unsure and, when robust, over depth ties: hits whose f32 `t` lie within
/// rounding of the closest one's, ordered by their float-float `t` (see leaf.glsl).
pub(super) fn intersect_leaf(scene: &SceneRef, r: &TraceRay, n: KdNode, best: &mut Closest, c: &mut Counters) {
    let offset = n.prim_offset() as usize;
    let count = n.prim_count() as usize;
    let triangle = |reference: u32| {
        let prim = scene.prim_indices[reference as usize];
        (prim, scene.triangles[prim as usize])
    };
    let in_ref = best.reference;
    let mut unsure = 0usize;
    let mut first_unsure = count;
    let mut tie = false;
    for i in 0..count {
        let (prim, [v0, v1, v2]) = triangle((offset + i) as u32);
        match r.wr.intersect_f32(v0, v1, v2, r.tmin - r.wr.t_shift, best.hit.t + best.err) {
            TriTest::Hit(t, u, v, e) => {
                // [t - e, t + e] meets the closest hit's interval: order them in float-float
                // (unless it is the same triangle, met again in another leaf).
                if r.wr.robust
                    && !r.any_hit
                    && best.reference != NO_REF
                    && prim != best.hit.prim_id
                    && t + e >= best.hit.t - best.err
                {
                    tie = true;
                }
                if t <= best.hit.t {
                    *best = Closest { hit: Hit { t, prim_id: prim, u, v }, reference: (offset + i) as u32, err: e };
                    if r.any_hit {
                        c.triangles += i as u32 + 1;
                        return;
                    }
                }
            }
            TriTest::Unsure => {
                first_unsure = first_unsure.min(i);
                unsure += 1;
            }
            TriTest::Miss => {}
        }
    }
    c.triangles += count as u32;
    if unsure == 0 && !tie {
        return;
    }
    // The second pass: the closest hit on entry (after a tie), the closest after
    // the f32 pass, then the leaf's triangles; each tested again (same bits).
    let window = best.hit.t + best.err;
    let w_ref = best.reference;
    let before = [
        (tie && in_ref != NO_REF && in_ref != w_ref).then_some(in_ref),
        (!r.any_hit && w_ref != NO_REF).then_some(w_ref),
    ];
    let first = if tie { 0 } else { first_unsure };
    let mut bar = Ff::from_f32(f32::INFINITY);
    let leaf = (first..count).map(|i| ((offset + i) as u32, true));
    // (reference, whether it is one of the leaf's triangles)
    for (reference, in_leaf) in before.into_iter().flatten().map(|r| (r, false)).chain(leaf) {
        if in_leaf && !(tie || unsure > 0) {
            break;
        }
        let (prim, [v0, v1, v2]) = triangle(reference);
        let result = r.wr.intersect_f32(v0, v1, v2, r.tmin - r.wr.t_shift, window);
        let unsure_pair = result == TriTest::Unsure;
        if unsure_pair && in_leaf {
            unsure -= 1;
        }
        let (mut hit, mut e) = match result {
            TriTest::Hit(t, u, v, e) if !in_leaf || (tie && reference != w_ref) => (Hit { t, prim_id: prim, u, v }, e),
            TriTest::Unsure => (Hit { t: f32::NAN, prim_id: prim, u: 0.0, v: 0.0 }, 0.0),
            _ => continue,
        };
        let t_ff = match r.wr.intersect_exact(v0, v1, v2, r.tmin) {
            Some((t, u, v, t_ff, err)) => {
                // An unsure pair takes the exact answer; a certain f32 hit keeps its f32 values.
                if unsure_pair {
                    (hit, e) = (Hit { t, prim_id: prim, u, v }, EDGE_GAMMA * t.abs() + err);
                }
                t_ff
            }
            None if unsure_pair => continue,
            None => Ff::from_f32(hit.t), // a certain f32 hit the exact test rejects: keep its f32 t
        };
        if t_ff.le(bar) {
            bar = t_ff;
            *best = Closest { hit, reference, err: e };
            if r.any_hit {
                return;
            }
        }
    }
}
