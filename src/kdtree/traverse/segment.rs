//! The ray as traversal sees it ([`TraceRay`]), in its segment frame, and the
//! clip of its `[tmin, tmax]` to a box. Twin of `glsl/traverse/segment.glsl`.

use glam::Vec3;

use crate::geom::{Aabb, WatertightRay};

/// The ray as traversal sees it: `TraceRay` of segment.glsl. Traversal t values
/// and hits are in the segment frame that `wr` defines (`t - wr.t_shift`, from
/// `wr.seg_origin + wr.seg_lo`); `tmin` and `tmax` in the ray's own parameter.
/// The CPU twin always traces as the careful pass does (SEGMENT_FRAME): where
/// the shader selects to save instructions, the values here are the same bits
/// (a subtraction of a zero `seg_lo`, `t_shift` or `t_err`).
#[derive(Clone)]
pub(super) struct TraceRay {
    pub(super) wr: WatertightRay,
    /// [`Traversal::robust`](crate::traversal::Traversal::robust): the widening of the split decisions.
    pub(super) eps: f32,
    /// Absolute error bound of a segment-frame plane distance (0 unless shifted).
    pub(super) t_err: f32,
    /// Flat axes (bit per axis) of a shifted ray and the band of coordinates it
    /// may occupy along them (`flat_axes`, `band` in segment.glsl).
    pub(super) flat_axes: u32,
    pub(super) band: Vec3,
    pub(super) dir: Vec3,
    pub(super) inv_dir: Vec3,
    pub(super) tmin: f32,
    pub(super) tmax: f32,
    pub(super) any_hit: bool,
}

/// 1 + 2·gamma(3) with gamma(n) = n·u / (1 - n·u), u = 2^-24, rounded up: 1 + 3·2^-23
/// (Ize 2013). Widens the far bound so rounding never clips away a hit on the box.
pub(crate) const TFAR_SCALE: f32 = 1.0 + 3.0 * f32::EPSILON;

/// The near bound widened down by the same relative amount, `|t|·3·2^-23`:
/// compared with an unwidened end (the ray's own `tmax`), a rounded entry could
/// pass it and clip away a hit on the box's face (a segment ending just past
/// it). Twin of `widen_near` in segment.glsl; also the two-level top level's boxes.
pub(crate) fn widen_near(t: f32) -> f32 {
    t - t.abs() * (3.0 * f32::EPSILON)
}

/// Distance (segment frame) to the plane `axis` = `plane`: `plane_t` in segment.glsl.
pub(super) fn plane_t(r: &TraceRay, axis: usize, plane: f32) -> f32 {
    ((plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis]) * r.inv_dir[axis]
}

/// `is_flat` in segment.glsl (only a shifted ray has flat axes).
pub(super) fn is_flat(r: &TraceRay, axis: usize) -> bool {
    (r.flat_axes >> axis) & 1 != 0
}

/// `flat_side` in segment.glsl: -1 below `plane`, +1 above, 0 within the band.
pub(super) fn flat_side(r: &TraceRay, axis: usize, plane: f32) -> i32 {
    let gap = (plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis];
    if gap > r.band[axis] {
        -1
    } else if gap < -r.band[axis] {
        1
    } else {
        0
    }
}

/// Slab clip of [tmin, tmax] to the scene box; twin of `clip_to_box` in segment.glsl.
pub(super) fn clip_to_box(r: &TraceRay, b: &Aabb) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (r.tmin - r.wr.t_shift, r.tmax - r.wr.t_shift);
    for axis in 0..3 {
        let o = r.wr.seg_origin[axis];
        if r.dir[axis] == 0.0 {
            if o < b.min[axis] || o > b.max[axis] {
                return None;
            }
            continue;
        }
        if is_flat(r, axis) {
            if flat_side(r, axis, b.min[axis]) < 0 || flat_side(r, axis, b.max[axis]) > 0 {
                return None;
            }
            continue;
        }
        let ta = plane_t(r, axis, b.min[axis]);
        let tb = plane_t(r, axis, b.max[axis]);
        let tnear = widen_near(glsl_min(ta, tb)) - r.t_err;
        let tfar = glsl_max(ta, tb) * TFAR_SCALE + r.t_err;
        t0 = glsl_max(t0, tnear);
        t1 = glsl_min(t1, tfar);
    }
    (t0 <= t1).then_some((t0, t1))
}

// GLSL's min(x, y) is `y < x ? y : x` and max(x, y) is `x < y ? y : x`.
pub(super) fn glsl_min(x: f32, y: f32) -> f32 {
    if y < x {
        y
    } else {
        x
    }
}

pub(super) fn glsl_max(x: f32, y: f32) -> f32 {
    if x < y {
        y
    } else {
        x
    }
}
